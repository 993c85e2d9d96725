//! The posterior the chains sample: triangular priors x the Gaussian likelihood of the meters
//! given the surrogate (reference Eqs. 4-7), in the unit space the sampler works in.
//!
//! Coordinates `0..d` are the calibrated parameters, `u_i = (theta_i - min_i) / (max_i - min_i)`.
//! In hyperparameter mode, coordinates `d..d+K` are the outputs' model-inadequacy sds on the log
//! scale: `ln sigma_delta,k = a_k + u (b_k - a_k)` with `a_k = ln(1e-3 s_k)`, `b_k = ln(2 s_k)`
//! (`s_k` the measured sd), under a half-Cauchy prior of scale `s_k` (Gelman 2006).

use std::path::Path;

use bemcal_stats::chain::Chain;
use bemcal_stats::likelihood::cells::Cells;
use bemcal_stats::likelihood::intervals::IntervalLikelihood;
use bemcal_stats::likelihood::{ln_prior_log_sigma_delta, GaussianLikelihood, SigmaPrior};
use bemcal_stats::mcmc::{run_segment_batch, ChainState, Draws};
use bemcal_surrogate::Evaluator;
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::output::read_record;
use crate::plan::Plan;
use crate::stage::Stage;
use bemcal_energyplus::Model;

/// Bounds of `ln sigma_delta` in hyperparameter mode: one sampled dimension per fitted
/// output (a meter with `fit = false` is not in the likelihood, so it has no dimension).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SigmaDeltaBox {
    /// The output each sampled dimension belongs to (indices into the calibration's outputs).
    pub outputs: Vec<usize>,
    /// Lower bounds, `ln(0.001 s_k)` (`s_k` the measured sd, kWh).
    pub lo: Vec<f64>,
    /// Upper bounds, `ln(2 s_k)`.
    pub hi: Vec<f64>,
    /// Half-Cauchy scales (measured sds).
    pub scale: Vec<f64>,
}

impl SigmaDeltaBox {
    /// The box for the outputs' measured sds `s`, with a dimension for each output `fitted`.
    pub fn new(measured_sd: &[f64], fitted: &[bool]) -> SigmaDeltaBox {
        assert_eq!(
            measured_sd.len(),
            fitted.len(),
            "one fitted flag per output"
        );
        let outputs: Vec<usize> = (0..measured_sd.len()).filter(|&k| fitted[k]).collect();
        let sd = |k: &usize| measured_sd[*k];
        SigmaDeltaBox {
            lo: outputs.iter().map(|k| (1e-3 * sd(k)).ln()).collect(),
            hi: outputs.iter().map(|k| (2.0 * sd(k)).ln()).collect(),
            scale: outputs.iter().map(sd).collect(),
            outputs,
        }
    }

    /// Number of sampled dimensions.
    pub fn len(&self) -> usize {
        self.outputs.len()
    }

    /// Whether no output is sampled.
    pub fn is_empty(&self) -> bool {
        self.outputs.is_empty()
    }

    /// `sigma_delta` of sampled dimension `j` (output `outputs[j]`) at unit coordinate `u`.
    pub fn sigma(&self, j: usize, u: f64) -> f64 {
        (self.lo[j] + u * (self.hi[j] - self.lo[j])).exp()
    }

    /// `sigma_delta` per output (`n_outputs` long) at the sampled coordinates `u` (one per
    /// dimension); an output without a dimension gets 1, which the likelihood never reads
    /// (it has no observed hour).
    pub fn per_output(&self, n_outputs: usize, u: &[f64]) -> Vec<f64> {
        let mut sd = vec![1.0; n_outputs];
        for (j, &k) in self.outputs.iter().enumerate() {
            sd[k] = self.sigma(j, u[j]);
        }
        sd
    }
}

/// Everything the log posterior needs.
pub struct Posterior<'a> {
    /// The calibrated parameters, their priors and the region the chains refuse.
    pub plan: &'a Plan,
    /// The model, whose constraints between parameters a point must satisfy.
    pub model: &'a Model,
    /// The meters' likelihood given the surrogate's prediction.
    pub likelihood: &'a GaussianLikelihood,
    /// The bills' likelihoods, one per billed output ([`crate::bills`]), added to it.
    pub bills: &'a [IntervalLikelihood],
    /// Sampled `ln sigma_delta` dimensions (hyperparameter mode).
    pub sigma_box: Option<&'a SigmaDeltaBox>,
    /// Integrate each output's variance out (Jeffreys prior) instead of fixing it.
    pub marginal: bool,
    /// With `marginal`: AR(1) residuals (phi profiled) instead of independent ones.
    pub ar1: bool,
    /// With `marginal`: the calendar cells of a model-form discrepancy integrated out
    /// ([`bemcal_stats::likelihood::cells`]).
    pub cells: Option<&'a Cells>,
    /// The likelihood's temperature `T >= 1` ([`crate::project::Temperature`]): `ln L / T`.
    pub temperature: f64,
}

impl Posterior<'_> {
    /// The likelihood's form in words (its error model and discrepancy term; not its
    /// temperature, which checkpoints record apart): what chains resumed from a checkpoint
    /// must have sampled.
    pub fn form(&self) -> String {
        likelihood_form(
            self.sigma_box.is_some(),
            self.marginal,
            self.ar1,
            self.cells.map(Cells::is_free),
        )
    }

    /// Dimension of the sampled space.
    pub fn dim(&self) -> usize {
        self.plan.calibrated.len() + self.sigma_box.map_or(0, SigmaDeltaBox::len)
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
        if !self.plan.feasible(self.model, &theta) || self.plan.refused(&theta).is_some() {
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
            for j in 0..b.len() {
                let ln_s = b.lo[j] + u[d + j] * (b.hi[j] - b.lo[j]);
                lp += ln_prior_log_sigma_delta(ln_s, b.scale[j], SigmaPrior::HalfCauchy);
            }
        }
        lp
    }

    /// ln likelihood given the surrogate's prediction (`hours x outputs`) for `u`, divided by
    /// the temperature.
    pub fn ln_likelihood(&self, u: &[f64], predicted: &[f32]) -> f64 {
        let ln_l = match self.sigma_box {
            None if self.marginal && self.cells.is_some() => {
                let cells = self.cells.expect("checked");
                self.likelihood
                    .log_marginal_cells(predicted, cells, self.ar1)
            }
            None if self.marginal && self.ar1 => self.likelihood.log_marginal_sigma_ar1(predicted),
            None if self.marginal => self.likelihood.log_marginal_sigma(predicted),
            None => self.likelihood.log_likelihood(predicted),
            Some(b) => {
                let d = self.plan.calibrated.len();
                let sd = b.per_output(self.likelihood.n_outputs(), &u[d..]);
                self.likelihood.log_likelihood_with_delta(predicted, &sd)
            }
        };
        let bills: f64 = self
            .bills
            .iter()
            .map(|b| b.log_marginal_sigma(predicted))
            .sum();
        (ln_l + bills) / self.temperature
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

impl Posterior<'_> {
    /// Log posterior and its unit-space gradient of several points: one batched surrogate call,
    /// the likelihood's gradient with respect to the predictions (`fixed`, `marginal`, AR(1)),
    /// and one batched VJP call through the surrogate (`d theta / d u = max - min`). Points
    /// outside the box or failing a constraint get `-inf`.
    ///
    /// # Errors
    /// With sampled `sigma_delta` (no gradient for those coordinates), or a surrogate without
    /// its VJP graph.
    pub fn ln_posterior_grad_batch(
        &self,
        eval: &mut Evaluator,
        us: &[Vec<f64>],
    ) -> Result<Vec<(f64, Vec<f64>)>, Error> {
        if self.sigma_box.is_some() {
            return Err(Error::Config(
                "mcmc.sampler = \"hmc\" needs mcmc.sigma_delta = \"marginal\" or \"fixed\" \
                 (sampled sigma_delta coordinates have no gradient)"
                    .into(),
            ));
        }
        let priors = &self.plan.priors;
        let mut out: Vec<(f64, Vec<f64>)> = us
            .iter()
            .map(|u| {
                let inside = u.iter().all(|v| (0.0..=1.0).contains(v));
                let lp = if inside {
                    self.ln_prior(u)
                } else {
                    f64::NEG_INFINITY
                };
                let g = bemcal_stats::prior::grad_ln_prior_unit(priors, u);
                (lp, g)
            })
            .collect();
        let live: Vec<usize> = (0..us.len()).filter(|&i| out[i].0.is_finite()).collect();
        if live.is_empty() {
            return Ok(out);
        }
        let thetas: Vec<Vec<f64>> = live.iter().map(|&i| self.theta(&us[i])).collect();
        let pred = eval.evaluate_batch(&thetas)?;
        let mut cot = ndarray::Array3::<f32>::zeros(pred.dim());
        let per = pred.len() / thetas.len();
        {
            let flat = pred.as_slice().expect("contiguous prediction");
            let cflat = cot.as_slice_mut().expect("contiguous");
            for (b, &i) in live.iter().enumerate() {
                let (y, g) = (
                    &flat[b * per..(b + 1) * per],
                    &mut cflat[b * per..(b + 1) * per],
                );
                let ln_l = match (self.marginal, self.ar1) {
                    (true, ar1) if self.cells.is_some() => {
                        let cells = self.cells.expect("checked");
                        self.likelihood
                            .log_marginal_cells_gradient(y, cells, ar1, g)
                    }
                    (true, true) => self.likelihood.log_marginal_sigma_ar1_gradient(y, g),
                    (true, false) => self.likelihood.log_marginal_sigma_gradient(y, g),
                    (false, _) => self.likelihood.log_likelihood_gradient(y, g),
                };
                let mut bills = 0.0;
                for b in self.bills {
                    bills += b.log_marginal_sigma(y);
                    b.add_log_marginal_sigma_gradient(y, g);
                }
                out[i].0 += (ln_l + bills) / self.temperature;
                if self.temperature != 1.0 {
                    let w = (1.0 / self.temperature) as f32;
                    g.iter_mut().for_each(|v| *v *= w);
                }
            }
        }
        let grads = eval.vjp_batch(&thetas, cot.view())?;
        for (g, &i) in grads.iter().zip(&live) {
            for ((o, gj), p) in out[i].1.iter_mut().zip(g).zip(priors) {
                *o += gj * p.width();
            }
        }
        Ok(out)
    }
}

impl Posterior<'_> {
    /// [`Posterior::ln_posterior_grad_batch`] for a sampler's callback: an evaluation error
    /// rejects the points (`-inf`, as [`Posterior::ln_posterior_batch`] does) and is kept in
    /// `failed` (the first one) for the caller to return.
    pub fn ln_posterior_grad_or_reject(
        &self,
        eval: &mut Evaluator,
        us: &[Vec<f64>],
        failed: &mut Option<Error>,
    ) -> Vec<(f64, Vec<f64>)> {
        match self.ln_posterior_grad_batch(eval, us) {
            Ok(v) => v,
            Err(e) => {
                failed.get_or_insert(e);
                us.iter()
                    .map(|u| (f64::NEG_INFINITY, vec![0.0; u.len()]))
                    .collect()
            }
        }
    }
}

/// The likelihood's form in words ([`Posterior::form`]): `sigma_delta` sampled, marginal or
/// fixed; AR(1) or independent residuals (with marginal); the discrepancy's cells, `Some(free)`
/// ([`crate::project::McmcSettings::likelihood_form`] gives it from the settings).
pub fn likelihood_form(sampled: bool, marginal: bool, ar1: bool, cells: Option<bool>) -> String {
    let errors = match (sampled, marginal, ar1) {
        (true, _, _) => "sigma_delta sampled",
        (false, true, true) => "sigma_delta marginal, AR(1) residuals",
        (false, true, false) => "sigma_delta marginal, independent residuals",
        (false, false, _) => "sigma_delta fixed",
    };
    match cells {
        Some(true) => format!("{errors}, hour x day kind x season free levels"),
        Some(false) => format!("{errors}, hour x day kind x season discrepancy"),
        None => errors.to_string(),
    }
}

/// Checkpoint of all chains: states and the draws so far.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Checkpoint {
    /// Each chain's complete state, to resume it from.
    pub states: Vec<Chain>,
    /// Each chain's post-burn-in draws so far (unit space) and their log densities.
    pub draws: Vec<Draws>,
    /// The likelihood's temperature the chains ran at (1 in checkpoints written before it
    /// existed): chains are resumed only at the same one.
    #[serde(default = "untempered")]
    pub temperature: f64,
    /// The iterations per chain the chains were last asked to run to; 0 in checkpoints written
    /// before it was kept. Asked for more once there, they are extended: re-adapted first
    /// ([`bemcal_stats::chain::readapt`]).
    #[serde(default)]
    pub target: u64,
    /// The likelihood's form the chains sampled ([`Posterior::form`]): chains are resumed only
    /// under the same one. `None` in checkpoints written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub likelihood: Option<String>,
}

impl Checkpoint {
    /// Where the chains stand for the extension rule (`chains::extended_target`).
    pub fn drawn(&self) -> Drawn {
        Drawn {
            draws: self.draws.iter().map(|d| d.len() as u64).min().unwrap_or(0),
            readapted: self.states.iter().any(Chain::was_readapted),
        }
    }
}

/// Where the final chains stand when they are judged: what the extension rule
/// (`chains::extended_target`) counts from, read off the chains themselves
/// ([`Checkpoint::drawn`]) rather than worked out from the iterations asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Drawn {
    /// Draws per chain so far (the fewest of any chain): after burn-in, outside
    /// re-adaptation windows.
    pub draws: u64,
    /// Whether the chains were re-adapted ([`bemcal_stats::chain::readapt`]: once).
    pub readapted: bool,
}

/// The likelihood's temperature of a round's chains (`summary.json` `temperature`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ChainTemperature {
    /// `T`: the chains sample `p(theta) L(theta)^(1/T)`.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub value: f64,
    /// The refinement round whose recoveries measured it (`mcmc.temperature =
    /// "surrogate_error"`); `None` for a fixed temperature, or before any round.
    pub measured_at_round: Option<u32>,
    /// Buildings of the pretrained network's family whose recoveries were pooled with this
    /// building's own (`crate::surrogate_error::FAMILY_WEIGHT`); `None` where none were.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pooled_with_buildings: Option<u32>,
}

impl ChainTemperature {
    /// The posterior itself.
    pub const ONE: ChainTemperature = ChainTemperature {
        value: 1.0,
        measured_at_round: None,
        pooled_with_buildings: None,
    };

    /// [`ChainTemperature::ONE`], for serde's defaults.
    pub fn one() -> ChainTemperature {
        ChainTemperature::ONE
    }
}

/// Whether chains recorded at temperature `a` may go on at `b`: equal to [`SAME_TEMPERATURE`].
/// A measured temperature is found by bisection to a relative 1e-9, so the same rounds give
/// temperatures that differ in their last digits across builds (another summation order):
/// exact equality refused a checkpoint a rebuilt binary measured 1.4e-10 apart.
pub fn same_temperature(a: f64, b: f64) -> bool {
    (a - b).abs() <= SAME_TEMPERATURE * a.abs().max(b.abs())
}

/// The relative difference below which two temperatures are the same ([`same_temperature`]):
/// far above the bisection's 1e-9, far below what moves a chain (T is measured to per cents).
pub const SAME_TEMPERATURE: f64 = 1e-6;

/// The likelihood's temperature of a record written before it had one: 1 (serde's default for
/// [`Checkpoint::temperature`] and `RefineRound::temperature`).
pub(crate) fn untempered() -> f64 {
    1.0
}

/// Runs the chains to `iterations`, checkpointing to `path` after every `segment` iterations;
/// resumes from `path` when it exists, else starts from the states `initial` builds. Chains
/// that reached the target they were last asked for and are asked for more (an extension)
/// are re-adapted first: HMC chains take the metric their draws give and adapt their step
/// size again over a window that is not drawn ([`bemcal_stats::chain::readapt`]).
pub fn run_chains(
    post: &Posterior<'_>,
    eval: &mut Evaluator,
    initial: impl FnOnce(&Posterior<'_>, &mut Evaluator) -> Result<Vec<Chain>, Error>,
    iterations: u64,
    segment: u64,
    path: &Path,
    progress: &dyn Fn(u64, u64),
) -> Result<Checkpoint, Error> {
    let saved = read_record::<Checkpoint>(path).map_err(|e| Error::Stage {
        stage: Stage::Chains.as_str(),
        message: format!("checkpoint {} is unreadable: {e}", path.display()),
    })?;
    let form = post.form();
    let mut ck = match saved {
        Some(ck) => ck,
        None => {
            let states = initial(post, eval)?;
            Checkpoint {
                draws: states.iter().map(|s| Draws::new(s.dim())).collect(),
                states,
                temperature: post.temperature,
                target: iterations,
                likelihood: Some(form.clone()),
            }
        }
    };
    if let Some(saved) = ck.likelihood.as_ref().filter(|f| **f != form) {
        return Err(Error::Stage {
            stage: Stage::Chains.as_str(),
            message: format!(
                "{} holds chains that sampled another likelihood ({saved}) than this run's \
                 ({form}; mcmc.sigma_delta, residuals or discrepancy changed): delete it and \
                 chains_summary.json to start the chains again",
                path.display(),
            ),
        });
    }
    if !same_temperature(ck.temperature, post.temperature) {
        return Err(Error::Stage {
            stage: Stage::Chains.as_str(),
            message: format!(
                "{} holds chains that sampled the likelihood at temperature {}, this run's is {} \
                 (mcmc.temperature, the refinement rounds or the rule that measures it \
                 changed): delete it and chains_summary.json to start the chains again",
                path.display(),
                ck.temperature,
                post.temperature
            ),
        });
    }
    let done = ck.states[0].iteration();
    if ck.target > 0 && done >= ck.target && iterations > ck.target {
        // An extension (not a resumed run): the metric from the draws so far.
        bemcal_stats::chain::readapt(&mut ck.states, &ck.draws);
    }
    ck.target = ck.target.max(iterations);
    loop {
        let done = ck.states[0].iteration();
        progress(done, iterations);
        if done >= iterations {
            break;
        }
        let n = segment.min(iterations - done);
        let seg = advance_chains(post, eval, &mut ck.states, n)?;
        for (d, s) in ck.draws.iter_mut().zip(&seg) {
            d.extend(s);
        }
        let bytes = serde_json::to_vec(&ck).map_err(|e| Error::Config(e.to_string()))?;
        crate::error::write_atomic(path, &bytes)?;
    }
    Ok(ck)
}

/// Chains saved by a run that sampled another space (another `mcmc.sigma_delta` mode, other
/// meters fitted, other parameters calibrated) cannot be resumed here: their coordinates would
/// be read as this posterior's.
fn same_space(post: &Posterior<'_>, states: &[Chain]) -> Result<(), Error> {
    match states.iter().find(|s| s.dim() != post.dim()) {
        None => Ok(()),
        Some(s) => Err(Error::Stage {
            stage: Stage::Chains.as_str(),
            message: format!(
                "saved chains have {} dimensions, this run samples {} (mcmc.sigma_delta, the \
                 meters fitted or the parameters calibrated changed): delete chains.json and \
                 chains_summary.json to start them again",
                s.dim(),
                post.dim()
            ),
        }),
    }
}

/// Advances chains of one kernel by `n` iterations with batched targets: log posteriors for
/// Metropolis-Hastings, log posteriors and gradients for HMC. Returns this segment's draws.
///
/// # Errors
/// Chains of both kernels in one call; an HMC chain whose gradient evaluation failed (the
/// states are left as they were before the failing iteration's end, draws of earlier
/// iterations are lost to the caller: rerun from the last checkpoint).
pub fn advance_chains(
    post: &Posterior<'_>,
    eval: &mut Evaluator,
    states: &mut [Chain],
    n: u64,
) -> Result<Vec<Draws>, Error> {
    same_space(post, states)?;
    let mh: Option<Vec<ChainState>> = states
        .iter()
        .map(|c| match c {
            Chain::Mh(s) => Some(s.clone()),
            Chain::Hmc(_) => None,
        })
        .collect();
    if let Some(mut mh) = mh {
        let draws = run_segment_batch(&mut mh, n, |us: &[Vec<f64>]| {
            post.ln_posterior_batch(eval, us)
        })?;
        for (c, s) in states.iter_mut().zip(mh) {
            *c = Chain::Mh(s);
        }
        return Ok(draws);
    }
    let hmc: Option<Vec<bemcal_stats::hmc::HmcState>> = states
        .iter()
        .map(|c| match c {
            Chain::Hmc(s) => Some(s.clone()),
            Chain::Mh(_) => None,
        })
        .collect();
    let Some(mut hmc) = hmc else {
        return Err(Error::Config(
            "chains of both kernels (mh and hmc) in one checkpoint".into(),
        ));
    };
    let mut failed = None;
    let draws = bemcal_stats::hmc::run_segment_batch(&mut hmc, n, &mut |us: &[Vec<f64>]| {
        post.ln_posterior_grad_or_reject(eval, us, &mut failed)
    })?;
    if let Some(e) = failed {
        return Err(e);
    }
    for (c, s) in states.iter_mut().zip(hmc) {
        *c = Chain::Hmc(s);
    }
    Ok(draws)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temperatures_apart_by_rounding_are_the_same_and_measurably_different_ones_are_not() {
        // Two builds measured these from the same refinement rounds.
        assert!(same_temperature(294.3081622329743, 294.30816227335754));
        assert!(same_temperature(1.0, 1.0));
        assert!(!same_temperature(294.3, 294.4));
        assert!(!same_temperature(1.0, 141.0));
    }

    #[test]
    fn a_meter_not_fitted_gets_no_sampled_sigma_delta() {
        // Three outputs, the second with `fit = false`: two sampled dimensions, for 0 and 2.
        let b = SigmaDeltaBox::new(&[10.0, 20.0, 30.0], &[true, false, true]);
        assert_eq!((b.len(), b.outputs.as_slice()), (2, &[0, 2][..]));
        assert_eq!(b.scale, [10.0, 30.0]);
        let sd = b.per_output(3, &[0.0, 1.0]);
        assert!(
            (sd[0] - 0.01).abs() < 1e-12,
            "ln(0.001 s) at u = 0: {}",
            sd[0]
        );
        assert_eq!(sd[1], 1.0);
        assert!((sd[2] - 60.0).abs() < 1e-9, "ln(2 s) at u = 1: {}", sd[2]);
    }
}
