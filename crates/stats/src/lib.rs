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
//! - [`model_form`]: whether a model can reach a meter, residual patterns, an additive
//!   discrepancy, parameters piled against a prior bound.

#![deny(missing_docs)]

pub mod chain;
pub mod convergence;
pub mod diagnostics;
pub mod hmc;
pub mod lhs;
pub mod likelihood;
pub mod mcmc;
pub mod metrics;
pub mod model_form;
pub mod optim;
pub mod predictive;
pub mod prior;
pub mod summary;
pub mod surrogate_error;

mod normal;

pub use prior::{Prior, Triangular};

/// Errors of the numerics: invalid inputs, shapes that do not match, infeasible designs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StatsError {
    /// A triangular prior whose bounds are out of order.
    #[error("invalid triangular prior (min {min}, mode {mode}, max {max}): {reason}")]
    InvalidTriangular {
        /// Lower bound.
        min: f64,
        /// Mode.
        mode: f64,
        /// Upper bound.
        max: f64,
        /// What is out of order.
        reason: &'static str,
    },
    /// Inputs whose lengths or shapes do not fit together.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// An argument outside its valid range.
    #[error("invalid argument: {0}")]
    Invalid(String),
    /// Design rows that still violate constraints after repair.
    #[error("constraint repair failed: design rows {rows:?} still violate the constraints")]
    InfeasibleDesign {
        /// The rows (design points) still infeasible.
        rows: Vec<usize>,
    },
    /// Too few valid values for a statistic.
    #[error("not enough data: {0}")]
    NotEnoughData(String),
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, StatsError>;
