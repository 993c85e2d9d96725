//! The posterior the chains sample: triangular priors x the Gaussian likelihood of the meters
//! given the surrogate (reference Eqs. 4-7), in the unit space the sampler works in.
//!
//! Coordinates `0..d` are the calibrated parameters, `u_i = (theta_i - min_i) / (max_i - min_i)`.
//! In hyperparameter mode, coordinates `d..d+K` are the outputs' model-inadequacy sds on the log
//! scale: `ln sigma_delta,k = a_k + u (b_k - a_k)` with `a_k = ln(1e-3 s_k)`, `b_k = ln(2 s_k)`
//! (`s_k` the measured sd), under a half-Cauchy prior of scale `s_k` (Gelman 2006).

use std::path::Path;

use bemcal_stats::likelihood::{ln_prior_log_sigma_delta, GaussianLikelihood, SigmaPrior};
use bemcal_stats::mcmc::{run_segment_batch, ChainState, Draws};
use bemcal_surrogate::Evaluator;
use serde::{Deserialize, Serialize};

use crate::design::Plan;
use crate::Error;
use bemcal_energyplus::Model;

/// Bounds of `ln sigma_delta` per output in hyperparameter mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SigmaDeltaBox {
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
    /// Half-Cauchy scales (measured sds).
    pub scale: Vec<f64>,
}

impl SigmaDeltaBox {
    /// The box for measured sds `s`.
    pub fn new(measured_sd: &[f64]) -> SigmaDeltaBox {
        SigmaDeltaBox {
            lo: measured_sd.iter().map(|s| (1e-3 * s).ln()).collect(),
            hi: measured_sd.iter().map(|s| (2.0 * s).ln()).collect(),
            scale: measured_sd.to_vec(),
        }
    }

    /// `sigma_delta,k` at unit coordinate `u`.
    pub fn sigma(&self, k: usize, u: f64) -> f64 {
        (self.lo[k] + u * (self.hi[k] - self.lo[k])).exp()
    }
}

/// Everything the log posterior needs.
pub struct Posterior<'a> {
    pub plan: &'a Plan,
    pub model: &'a Model,
    pub likelihood: &'a GaussianLikelihood,
    /// Sampled `ln sigma_delta` dimensions (hyperparameter mode).
    pub sigma_box: Option<&'a SigmaDeltaBox>,
    /// Integrate each output's variance out (Jeffreys prior) instead of fixing it.
    pub marginal: bool,
    /// With `marginal`: AR(1) residuals (phi profiled) instead of independent ones.
    pub ar1: bool,
}

impl Posterior<'_> {
    /// Dimension of the sampled space.
    pub fn dim(&self) -> usize {
        self.plan.calibrated.len() + self.sigma_box.map_or(0, |b| b.lo.len())
    }

    /// Physical parameter values of a unit-space point (calibrated ones only).
    pub fn theta(&self, u: &[f64]) -> Vec<f64> {
        self.plan
            .priors
            .iter()
            .zip(u)
            .map(|(p, u)| p.from_unit(*u))
            .collect()
    }

    /// ln prior of a unit-space point (constant Jacobians dropped); -inf if a constraint fails.
    pub fn ln_prior(&self, u: &[f64]) -> f64 {
        let theta = self.theta(u);
        if !self.plan.feasible(self.model, &theta) {
            return f64::NEG_INFINITY;
        }
        let mut lp: f64 = self
            .plan
            .priors
            .iter()
            .zip(&theta)
            .map(|(p, x)| p.ln_pdf(*x))
            .sum();
        if let Some(b) = self.sigma_box {
            let d = self.plan.calibrated.len();
            for k in 0..b.lo.len() {
                let ln_s = b.lo[k] + u[d + k] * (b.hi[k] - b.lo[k]);
                lp += ln_prior_log_sigma_delta(ln_s, b.scale[k], SigmaPrior::HalfCauchy);
            }
        }
        lp
    }

    /// ln likelihood given the surrogate's prediction (`hours x outputs`) for `u`.
    pub fn ln_likelihood(&self, u: &[f64], predicted: &[f32]) -> f64 {
        match self.sigma_box {
            None if self.marginal && self.ar1 => self.likelihood.log_marginal_sigma_ar1(predicted),
            None if self.marginal => self.likelihood.log_marginal_sigma(predicted),
            None => self.likelihood.log_likelihood(predicted),
            Some(b) => {
                let d = self.plan.calibrated.len();
                let sd: Vec<f64> = (0..b.lo.len()).map(|k| b.sigma(k, u[d + k])).collect();
                self.likelihood.log_likelihood_with_delta(predicted, &sd)
            }
        }
    }

    /// Log posterior of several unit-space points with one batched surrogate call.
    pub fn ln_posterior_batch(&self, eval: &mut Evaluator, us: &[Vec<f64>]) -> Vec<f64> {
        let priors: Vec<f64> = us.iter().map(|u| self.ln_prior(u)).collect();
        let live: Vec<usize> = (0..us.len()).filter(|&i| priors[i].is_finite()).collect();
        let mut out = vec![f64::NEG_INFINITY; us.len()];
        if live.is_empty() {
            return out;
        }
        let thetas: Vec<Vec<f64>> = live.iter().map(|&i| self.theta(&us[i])).collect();
        match eval.evaluate_batch(&thetas) {
            Ok(pred) => {
                for (b, &i) in live.iter().enumerate() {
                    let slice = pred.index_axis(ndarray::Axis(0), b);
                    let flat = slice.as_slice().expect("contiguous prediction");
                    out[i] = priors[i] + self.ln_likelihood(&us[i], flat);
                }
            }
            Err(_) => {
                // A failed evaluation rejects the proposals (never silently accepted).
            }
        }
        out
    }
}

/// Checkpoint of all chains: states and the draws so far.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Checkpoint {
    pub states: Vec<ChainState>,
    pub draws: Vec<Draws>,
}

/// Runs the chains to `iterations`, checkpointing to `path` after every `segment` iterations;
/// resumes from `path` when it exists, else starts from the states `initial` builds.
pub fn run_chains(
    post: &Posterior<'_>,
    eval: &mut Evaluator,
    initial: impl FnOnce(&Posterior<'_>, &mut Evaluator) -> Result<Vec<ChainState>, Error>,
    iterations: u64,
    segment: u64,
    path: &Path,
    progress: &dyn Fn(u64, u64),
) -> Result<Checkpoint, Error> {
    let mut ck = match std::fs::read(path) {
        Ok(bytes) => serde_json::from_slice::<Checkpoint>(&bytes).map_err(|e| Error::Stage {
            stage: "chains",
            message: format!("checkpoint {} is unreadable: {e}", path.display()),
        })?,
        Err(_) => {
            let states = initial(post, eval)?;
            Checkpoint {
                draws: states.iter().map(|s| Draws::new(s.dim())).collect(),
                states,
            }
        }
    };
    loop {
        let done = ck.states[0].iteration();
        progress(done, iterations);
        if done >= iterations {
            break;
        }
        let n = segment.min(iterations - done);
        let seg = run_segment_batch(&mut ck.states, n, |us: &[Vec<f64>]| {
            post.ln_posterior_batch(eval, us)
        })?;
        for (d, s) in ck.draws.iter_mut().zip(&seg) {
            d.extend(s);
        }
        let bytes = serde_json::to_vec(&ck).map_err(|e| Error::Config(e.to_string()))?;
        crate::write_atomic(path, &bytes)?;
    }
    Ok(ck)
}
