//! Pure numerics of Bayesian calibration: triangular priors, Latin hypercube designs,
//! Metropolis-Hastings chains, convergence diagnostics and ASHRAE Guideline 14 metrics.
//!
//! Method: Jiang et al., Energy & Buildings 323 (2024) 114755 ("the reference").
//! This crate does no I/O, has no globals and starts no threads; all randomness comes from
//! explicit seeds (`rand_chacha::ChaCha8Rng`).
//!
//! Modules:
//! - [`prior`]: triangular priors per named parameter, unit-space mapping.
//! - [`lhs`]: Latin hypercube design points with maximin improvement and constraint repair.
//! - [`mcmc`]: random-walk Metropolis-Hastings (reference Algorithm 1) with adaptive covariance
//!   during burn-in, checkpointable chain state, single-chain and batched stepping.
//! - [`chain`]: one chain of either kernel (what the pipeline checkpoints and merges).
//! - [`hmc`]: Hamiltonian Monte Carlo in the logit of the unit space (gradients through the
//!   surrogate's VJP graph), dual-averaging step size, checkpointable, batched over chains.
//! - [`optim`]: posterior mode search (BFGS, finite differences) for the chains' starts.
//! - [`diagnostics`]: rank-normalised split R-hat, bulk and tail ESS (Vehtari et al. 2021).
//! - [`convergence`]: the verdict on merged chains against R-hat and ESS targets.
//! - [`summary`]: posterior summaries, width ratios, correlated pairs, predictive bands.
//! - [`surrogate_error`]: the surrogate's error near the posterior, measured at EnergyPlus
//!   points by recovering their known values, added to the draws.
//! - [`likelihood`]: the Gaussian likelihood of reference Eqs. 5 and 7.
//! - [`metrics`]: ASHRAE Guideline 14 NMBE and CV-RMSE.
//! - [`modes`]: chains settled in different modes of the posterior, and what separates them.
//! - [`model_form`]: whether a model can reach a meter, residual patterns, an additive
//!   discrepancy, parameters piled against a prior bound.
//! - [`savings`]: a retrofit measure's savings over posterior draws, their intervals and what
//!   drives their width.
//! - [`split`]: two parameters the meters constrain together, and their split drawn again
//!   from the priors.
//! - [`nan`]: NaN in JSON records (written as `null`, read back as NaN).

#![deny(missing_docs)]

pub mod chain;
pub mod convergence;
pub mod diagnostics;
mod error;
pub mod hmc;
pub mod lhs;
pub mod likelihood;
pub mod mcmc;
pub mod metrics;
pub mod model_form;
pub mod modes;
pub mod nan;
pub mod optim;
pub mod predictive;
pub mod prior;
pub mod savings;
pub mod split;
pub mod summary;
pub mod surrogate_error;

mod normal;

pub use error::{Result, StatsError};
pub use prior::{Prior, Triangular};
