//! Stage 5, the chains: the likelihood bound to the surrogate ([`Sampler`]), chain starts,
//! segments and the rule that extends them. Their summary (stage 6) is `chain_summary`'s.

use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::chain::Chain;
use bemcal_stats::convergence::{draws_for_ess, Convergence};
use bemcal_stats::hmc::{self, HmcConfig, HmcState};
use bemcal_stats::likelihood::cells::Cells;
use bemcal_stats::likelihood::intervals::IntervalLikelihood;
use bemcal_stats::likelihood::{GaussianLikelihood, OutputNoise};
use bemcal_stats::mcmc::{chains_at_optima, dispersed_starts, ChainState, Draws, MhConfig};
use bemcal_stats::optim::{maximise_batch, maximise_batch_with_gradient, BfgsConfig, Optimum};
use bemcal_surrogate::{Evaluator, Surrogate};
use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;
use crate::error::Error;
use crate::inputs::Inputs;
use crate::metrics::OutputMetrics;
use crate::posterior::{advance_chains, ChainTemperature, Drawn, Posterior, SigmaDeltaBox};
use crate::project::{
    ChainStart, DiscrepancyTerm, Kernel, McmcSettings, Residuals, SigmaDeltaMode,
};

/// Everything the chains need: the bound surrogate, the likelihood and the noise model.
pub struct Sampler<'c> {
    /// The calibration the sampler is of.
    pub(crate) cal: &'c Calibration,
    /// The surrogate bound to the calibration's weather ([`Surrogate::bind`]).
    pub evaluator: Evaluator,
    /// The Gaussian likelihood of each meter less its base over the calibration period, given
    /// the surrogate (reference Eq. 7).
    pub likelihood: GaussianLikelihood,
    /// The bills' likelihoods of the billed outputs ([`crate::bills`]).
    pub bills: Vec<IntervalLikelihood>,
    /// Per output, the likelihood's noise sds, kWh: sigma_y and sigma_delta from `[mcmc]`'s
    /// fractions of the meter's mean and sd, sigma_eta from the surrogate.
    pub noise: Vec<OutputNoise>,
    /// Bounds of each fitted output's `ln sigma_delta`, sampled with `mcmc.sigma_delta =
    /// "sampled"`.
    pub sigma_box: SigmaDeltaBox,
    /// The surrogate's held-out RMSE per output, kWh (its part of the likelihood's noise).
    pub sigma_eta: Vec<f64>,
    /// The calendar cells of the model-form discrepancy (`mcmc.discrepancy`), if any.
    pub cells: Option<Cells>,
    /// The surrogate's held-out metrics (its metadata's `held_out`), as JSON.
    pub held_out: serde_json::Value,
    /// The likelihood's temperature of the chains this sampler runs (1 until
    /// [`Sampler::set_temperature`]; [`crate::project::Temperature`]).
    pub(crate) temperature: ChainTemperature,
}

impl Calibration {
    /// Stage 5 set-up: loads the surrogate and builds the likelihood (reference Eq. 7).
    pub fn sampler(&self) -> Result<Sampler<'_>, Error> {
        let inp = &self.inputs;
        let dir = self.surrogate_dir();
        let surrogate = Surrogate::load(&dir, self.project.surrogate.threads)?;
        let meta = surrogate.meta().clone();
        if meta.output_names() != inp.outputs {
            return Err(Error::Stage {
                stage: "surrogate",
                message: format!(
                    "surrogate in {} predicts {:?}, the calibration needs {:?}; delete it to retrain",
                    dir.display(),
                    meta.output_names(),
                    inp.outputs
                ),
            });
        }
        let sigma_eta = meta.sigma_eta_kwh();
        // The surrogate predicts the model's share of each meter (the meter less its base).
        let observed = inp.likelihood_observations();
        let stats: Vec<(f64, f64)> = (0..inp.outputs.len())
            .map(|k| mean_sd(&inp.model_share(k)))
            .collect();
        let m = &self.project.mcmc;
        let noise: Vec<OutputNoise> = stats
            .iter()
            .zip(&sigma_eta)
            .map(|((mean, sd), eta)| OutputNoise {
                sigma_y: m.sigma_y_fraction * mean.abs(),
                sigma_delta: m.sigma_delta_fraction * sd,
                sigma_eta: *eta,
            })
            .collect();
        let likelihood = GaussianLikelihood::new(&observed, &noise)?;
        let bills = inp.bill_likelihoods()?;
        if !bills.is_empty() && m.sigma_delta != SigmaDeltaMode::Marginal {
            return Err(Error::Config(
                "[[meters.bills]] needs mcmc.sigma_delta = \"marginal\" (the default): a bill's \
                 error scale is integrated out"
                    .into(),
            ));
        }
        let sd: Vec<f64> = stats.iter().map(|(_, s)| s.max(1e-9)).collect();
        Ok(Sampler {
            cal: self,
            evaluator: surrogate.bind(&inp.features)?,
            likelihood,
            bills,
            noise,
            sigma_box: SigmaDeltaBox::new(&sd, &inp.fitted),
            sigma_eta,
            cells: discrepancy_cells(self.project.mcmc.discrepancy, inp),
            held_out: serde_json::to_value(&meta.held_out).unwrap_or_default(),
            temperature: ChainTemperature::ONE,
        })
    }
}

impl Sampler<'_> {
    /// The calibration's outputs, in the order the surrogate predicts them.
    pub fn outputs(&self) -> &[String] {
        &self.cal.inputs.outputs
    }

    /// Sets the likelihood's temperature of the chains to come (at least 1; the driver's
    /// [`crate::surrogate_error::chain_temperature`] for the round).
    pub fn set_temperature(&mut self, temperature: ChainTemperature) {
        debug_assert!(temperature.value >= 1.0, "temperature {temperature:?}");
        self.temperature = temperature;
    }

    /// The likelihood's temperature of the chains this sampler runs.
    pub fn temperature(&self) -> f64 {
        self.temperature.value
    }

    /// How far a refinement round's points are moved from the chains' mean (`refine.spread`).
    pub fn spread(&self) -> f64 {
        self.cal.project.refine.spread
    }

    /// The posterior over the unit space.
    pub fn posterior(&self) -> Posterior<'_> {
        let m = &self.cal.project.mcmc;
        Posterior {
            plan: &self.cal.inputs.plan,
            model: &self.cal.inputs.model,
            likelihood: &self.likelihood,
            bills: &self.bills,
            sigma_box: (m.sigma_delta == SigmaDeltaMode::Sampled).then_some(&self.sigma_box),
            marginal: m.sigma_delta == SigmaDeltaMode::Marginal,
            ar1: m.residuals == Residuals::Ar1,
            cells: self.cells.as_ref(),
            temperature: self.temperature.value,
        }
    }

    /// MH settings of the chains on the surrogate of refinement round `round` (0 = the
    /// hypercube's): the last round's are the project's `[mcmc]`; earlier (preliminary) rounds
    /// use `[refine]`'s shorter burn-in.
    pub fn config_for(&self, round: u32) -> MhConfig {
        let m = &self.cal.project.mcmc;
        let burn_in = if round < self.cal.project.refine.rounds {
            self.cal.project.refine.burn_in
        } else {
            m.burn_in
        };
        MhConfig {
            burn_in,
            adapt_start: match m.start {
                // Keep the Laplace covariance of the optimum: in 40 dimensions a burn-in's AM
                // estimate is far worse (proposal sds 0.07-0.6 of the truth's vs 0.37 = the
                // optimal 2.38 / sqrt(d) with the Laplace one; crates/stats tests/mcmc_peaked.rs).
                ChainStart::Optimised => burn_in,
                // Adapt the covariance from the second half of burn-in only: the first half is
                // the transient from dispersed starts (measured on peaked 10-D/40-D targets).
                ChainStart::Prior => (burn_in / 2).max(100).min(burn_in),
            },
            initial_sd: m.initial_sd,
            independence: m.independence,
            ..MhConfig::default()
        }
    }

    /// HMC settings of round `round` (`mcmc.kernel = "hmc"`): burn-in as [`Self::config_for`].
    pub fn hmc_config_for(&self, round: u32) -> HmcConfig {
        HmcConfig {
            burn_in: self.config_for(round).burn_in,
            integration_time: self.cal.project.mcmc.hmc_integration_time,
            ..HmcConfig::default()
        }
    }

    /// MCMC settings of round `round`: a round's chains get their own random streams (the
    /// last round of a project without refinement keeps the project's seed); a preliminary
    /// round's kernel is `refine.kernel` when set.
    pub fn settings_for(&self, round: u32) -> McmcSettings {
        settings_for(&self.cal.project, round)
    }

    /// Dispersed, feasible starting points (unit space), one per chain.
    pub fn starts(&self) -> Vec<Vec<f64>> {
        let cal = self.cal;
        let plan = &cal.inputs.plan;
        let post = self.posterior();
        let mut starts =
            dispersed_starts(&plan.priors, cal.project.mcmc.chains, cal.project.mcmc.seed);
        let modes: Vec<f64> = plan.priors.iter().map(|p| p.to_unit(p.mode())).collect();
        for s in &mut starts {
            let mut tries = 0;
            let ok = |s: &[f64]| {
                let x = post.theta(s);
                plan.feasible(&cal.inputs.model, &x) && plan.refused(&x).is_none()
            };
            while !ok(s) && tries < 50 {
                for (u, m) in s.iter_mut().zip(&modes) {
                    *u = 0.5 * (*u + m);
                }
                tries += 1;
            }
            if let Some(b) = post.sigma_box {
                s.extend(std::iter::repeat_n(0.6, b.len()));
            }
        }
        starts
    }

    /// The posterior and the evaluator, borrowed together.
    pub fn split(&mut self) -> (Posterior<'_>, &mut Evaluator) {
        let m = &self.cal.project.mcmc;
        let post = Posterior {
            plan: &self.cal.inputs.plan,
            model: &self.cal.inputs.model,
            likelihood: &self.likelihood,
            bills: &self.bills,
            sigma_box: (m.sigma_delta == SigmaDeltaMode::Sampled).then_some(&self.sigma_box),
            marginal: m.sigma_delta == SigmaDeltaMode::Marginal,
            ar1: m.residuals == Residuals::Ar1,
            cells: self.cells.as_ref(),
            temperature: self.temperature.value,
        };
        (post, &mut self.evaluator)
    }

    /// New chain states at `starts` for the chains of round `round` (see [`Self::config_for`]);
    /// chain `c` gets random stream `first_chain + c`.
    pub fn new_chains(
        &mut self,
        starts: &[Vec<f64>],
        first_chain: u64,
        round: u32,
    ) -> Result<Vec<Chain>, Error> {
        let config = self.config_for(round);
        let hmc = self.hmc_config_for(round);
        let m = self.settings_for(round);
        let (post, eval) = self.split();
        chains_at(&post, eval, starts, config, &hmc, &m, first_chain)
    }

    /// The surrogate's hourly outputs at `points` (physical calibrated values):
    /// `[point][output][hour]`.
    pub fn predict(&mut self, points: &[Vec<f64>]) -> Result<Vec<Vec<Vec<f64>>>, Error> {
        let (n_h, n_out) = (
            self.cal.inputs.features.len(),
            self.cal.inputs.outputs.len(),
        );
        let mut out = vec![];
        for chunk in points.chunks(8) {
            let y = self.evaluator.evaluate_batch(chunk)?;
            for b in 0..chunk.len() {
                out.push(
                    (0..n_out)
                        .map(|k| (0..n_h).map(|h| f64::from(y[[b, h, k]])).collect())
                        .collect(),
                );
            }
        }
        Ok(out)
    }

    /// What a calibration through this surrogate recovers from EnergyPlus's `outputs` at known
    /// `points` (physical calibrated values): the posterior's mode with those outputs in place
    /// of the meters (the same missing hours and error model), by BFGS from the point itself
    /// to convergence.
    /// The difference to the point is the surrogate's error in parameter space there, from
    /// surrogate error alone ([`bemcal_stats::surrogate_error`]).
    pub fn recover(
        &mut self,
        points: &[Vec<f64>],
        outputs: &[HourlyOutputs],
    ) -> Result<Vec<Vec<f64>>, Error> {
        let names = self.outputs().to_vec();
        let n_h = self.cal.inputs.features.len();
        let mut recovered = vec![];
        for (i, (x, o)) in points.iter().zip(outputs).enumerate() {
            let mut observed = vec![f64::NAN; n_h * names.len()];
            for (k, name) in names.iter().enumerate() {
                let series = hourly_output(o, name, n_h).ok_or_else(|| Error::Stage {
                    stage: "refinement",
                    message: format!("point {i}: no {n_h}-hour output {name}"),
                })?;
                for (h, v) in series.iter().enumerate() {
                    observed[h * names.len() + k] = *v;
                }
            }
            let bills = self.bills_with_totals(|b| b.sums(&observed));
            recovered.push(self.untempered_mode(&observed, bills, x)?);
        }
        Ok(recovered)
    }

    /// One step of output space mapping (Bandler et al., "Space mapping: the state of the
    /// art", IEEE Trans. Microwave Theory Tech. 52 (2004), section on output space mapping;
    /// the zeroth-order correction of Alexandrov et al. 1998): the surrogate is corrected by
    /// EnergyPlus's hourly difference from it at `anchor` (physical calibrated values),
    /// `E(anchor) - S(anchor)`, which is the same as calibrating the surrogate against the
    /// meters less that difference; returns that calibration's untempered posterior mode, by
    /// BFGS from the anchor. `eplus`: EnergyPlus's outputs at the anchor (the model's share,
    /// without bases, as the surrogate predicts it). At the anchor the corrected surrogate
    /// agrees with EnergyPlus, and near it as far as the surrogate's error changes slowly;
    /// far from it, not: the driver simulates points on the line to the mode, not only the
    /// mode.
    pub fn mapped_mode(
        &mut self,
        anchor: &[f64],
        eplus: &HourlyOutputs,
    ) -> Result<Vec<f64>, Error> {
        let names = self.outputs().to_vec();
        let n_h = self.cal.inputs.features.len();
        let surrogate = self.predict(&[anchor.to_vec()])?.remove(0);
        let mut observed = self.cal.inputs.likelihood_observations();
        let mut shift = vec![0.0; observed.len()];
        for (k, name) in names.iter().enumerate() {
            let e = hourly_output(eplus, name, n_h).ok_or_else(|| Error::Stage {
                stage: "validation",
                message: format!("the anchor's run has no {n_h}-hour output {name}"),
            })?;
            for h in 0..n_h {
                shift[h * names.len() + k] = e[h] - surrogate[k][h];
            }
        }
        for (o, d) in observed.iter_mut().zip(&shift) {
            *o -= d;
        }
        let bills = self.bills_with_totals(|b| {
            let totals = b.readings().iter().map(|r| r.total);
            totals.zip(b.sums(&shift)).map(|(t, d)| t - d).collect()
        });
        self.untempered_mode(&observed, bills, anchor)
    }

    /// The bills' likelihoods with each bill's total replaced by `totals(bill likelihood)`.
    fn bills_with_totals(
        &self,
        totals: impl Fn(&IntervalLikelihood) -> Vec<f64>,
    ) -> Vec<IntervalLikelihood> {
        self.bills
            .iter()
            .map(|b| b.with_totals(&totals(b)))
            .collect()
    }

    /// The posterior's mode at temperature 1 with `observed` (hours x outputs, row-major) in
    /// place of the meters (the same missing hours and error model), by BFGS from `start`
    /// (physical calibrated values) until it converges ([`MODE_ITERATIONS`]).
    fn untempered_mode(
        &mut self,
        observed: &[f64],
        bills: Vec<IntervalLikelihood>,
        start: &[f64],
    ) -> Result<Vec<f64>, Error> {
        let cfg = BfgsConfig {
            max_iterations: MODE_ITERATIONS.max(self.cal.project.mcmc.optimiser_iterations),
            hessian: false,
            ..BfgsConfig::default()
        };
        let likelihood = self.likelihood.with_observed(observed)?;
        let (post, eval) = self.split();
        let post = Posterior {
            likelihood: &likelihood,
            bills: &bills,
            temperature: 1.0,
            ..post
        };
        let mut u: Vec<f64> = (post.plan.priors.iter().zip(start))
            .map(|(p, v)| p.to_unit(*v))
            .collect();
        if let Some(b) = post.sigma_box {
            u.extend(std::iter::repeat_n(0.6, b.len()));
        }
        let starts = [u];
        let lps = post.ln_posterior_batch(eval, &starts);
        let best = optimise(&post, eval, &starts, &lps, &cfg)?;
        Ok(post.theta(&best[0].point))
    }

    /// Guideline 14 of the surrogate against the meters at `x` (physical calibrated values).
    pub fn surrogate_metrics(&mut self, x: &[f64]) -> Result<Vec<OutputMetrics>, Error> {
        surrogate_metrics_at(&self.cal.inputs, &mut self.evaluator, x)
    }

    /// Stage 5, one job: advances chains by `n` iterations; returns this segment's draws.
    pub fn advance(&mut self, states: &mut [Chain], n: u64) -> Result<Vec<Draws>, Error> {
        let (post, eval) = self.split();
        advance_chains(&post, eval, states, n)
    }
}

/// The BFGS budget of a mode that is itself the result ([`Sampler::recover`], output space
/// mapping), where the chains' starts stop at `mcmc.optimiser_iterations` (60: the chains
/// burn in from there). The recovered shifts are the surrogate's error the temperature rule
/// carries, so their search must end at the mode, by its tolerance, not by a budget. Measured
/// on the demo building's final surrogate (issue 66, `examples/recovery_check.rs`): at 60
/// iterations the searches stopped short along the schedule-and-equipment ridge, the weekday
/// schedule intervals' rms shifts 0.010-0.031 of their prior widths; to convergence
/// 0.018-0.049 (1.6 times), the envelope's unchanged; 400 and 1,000 iterations gave the same
/// shifts (the tolerance ended every search), at 1.4 times the recovery's time.
const MODE_ITERATIONS: usize = 1000;

/// The discrepancy's calendar cells over the calibration's hour slots: hour of day x the
/// day's kind (the calendar the model runs) x meteorological season.
pub fn discrepancy_cells(discrepancy: DiscrepancyTerm, inp: &Inputs) -> Option<Cells> {
    let free = discrepancy.free_levels()?;
    let off: Vec<bool> = inp
        .features
        .day_type
        .iter()
        .map(|d| d.is_off_day())
        .collect();
    let month: Vec<u32> = (0..off.len())
        .map(bemcal_weather::grid::slot_month)
        .collect();
    let cells = Cells::hour_kind_season(&off, &month);
    Some(if free { cells.free_levels() } else { cells })
}

/// Output `name` of `o` when it has `n_h` hours.
fn hourly_output<'o>(o: &'o HourlyOutputs, name: &str, n_h: usize) -> Option<&'o [f64]> {
    o.get(name).filter(|s| s.len() == n_h)
}

/// Chain states at `starts` (chain `c` gets random stream `first_chain + c`): optimised first
/// with `start = "optimised"` (see [`ChainStart`]); Metropolis-Hastings or HMC by `m.kernel`.
pub fn chains_at(
    post: &Posterior<'_>,
    eval: &mut Evaluator,
    starts: &[Vec<f64>],
    config: MhConfig,
    hmc_config: &HmcConfig,
    m: &McmcSettings,
    first_chain: u64,
) -> Result<Vec<Chain>, Error> {
    if m.kernel == Kernel::Hmc && !eval.has_gradient() {
        return Err(Error::Config(format!(
            "mcmc.kernel = \"hmc\" needs the surrogate's gradient graph, and {} has none \
             (trained before it existed): retrain, or add it with `python -m bemcal_train \
             --add-vjp {}`",
            eval.surrogate().dir().display(),
            eval.surrogate().dir().display()
        )));
    }
    if m.kernel == Kernel::Hmc && m.start == ChainStart::Prior {
        // The gradient call gives the starts' log posteriors too.
        let values = post.ln_posterior_grad_batch(eval, starts)?;
        return starts
            .iter()
            .zip(values)
            .enumerate()
            .map(|(c, (s, (lp, g)))| {
                Ok(Chain::from(HmcState::new(
                    hmc_config.clone(),
                    s,
                    None,
                    lp,
                    &g,
                    m.seed,
                    first_chain + c as u64,
                )?))
            })
            .collect();
    }
    let lps = post.ln_posterior_batch(eval, starts);
    if m.start == ChainStart::Optimised {
        let cfg = BfgsConfig {
            max_iterations: m.optimiser_iterations,
            ..BfgsConfig::default()
        };
        let optima = optimise(post, eval, starts, &lps, &cfg)?;
        return Ok(match m.kernel {
            Kernel::Mh => chains_at_optima(&config, optima, m.seed, first_chain, m.restart_below)?
                .into_iter()
                .map(Chain::from)
                .collect(),
            Kernel::Hmc => {
                let mut failed = None;
                let states = hmc::chains_at_optima(
                    hmc_config,
                    optima,
                    m.seed,
                    first_chain,
                    m.restart_below,
                    &mut |us: &[Vec<f64>]| post.ln_posterior_grad_or_reject(eval, us, &mut failed),
                );
                if let Some(e) = failed {
                    return Err(e);
                }
                states?.into_iter().map(Chain::from).collect()
            }
        });
    }
    starts
        .iter()
        .zip(lps)
        .enumerate()
        .map(|(c, (s, lp))| {
            Ok(Chain::from(ChainState::new(
                config.clone(),
                s.clone(),
                lp,
                m.seed,
                first_chain + c as u64,
            )?))
        })
        .collect()
}

/// BFGS from each of `starts` (their log posteriors `lps`) to the posterior's mode. With the
/// surrogate's gradient graph (and no sampled sigma_delta), exact gradients: one VJP call
/// (about 3.3 evaluations) instead of d + 1 evaluations.
fn optimise(
    post: &Posterior<'_>,
    eval: &mut Evaluator,
    starts: &[Vec<f64>],
    lps: &[f64],
    cfg: &BfgsConfig,
) -> Result<Vec<Optimum>, Error> {
    if !(eval.has_gradient() && post.sigma_box.is_none()) {
        return Ok(maximise_batch(starts, lps, cfg, |us: &[Vec<f64>]| {
            post.ln_posterior_batch(eval, us)
        }));
    }
    let cell = std::cell::RefCell::new(&mut *eval);
    let mut failed = None;
    let optima = maximise_batch_with_gradient(
        starts,
        lps,
        cfg,
        |us: &[Vec<f64>]| post.ln_posterior_batch(&mut cell.borrow_mut(), us),
        &mut |us: &[Vec<f64>]| {
            post.ln_posterior_grad_or_reject(&mut cell.borrow_mut(), us, &mut failed)
        },
    );
    match failed {
        Some(e) => Err(e),
        None => Ok(optima),
    }
}

/// [`Sampler::settings_for`]: the project's `[mcmc]` for round `round`, with the round's own
/// random stream and, in a preliminary round, `refine.kernel` when set.
fn settings_for(project: &crate::project::Project, round: u32) -> McmcSettings {
    let mut m = project.mcmc.clone();
    if round > 0 {
        m.seed = m
            .seed
            .wrapping_add(0x9E37_79B9_7F4A_7C15_u64.wrapping_mul(u64::from(round)));
    }
    if round < project.refine.rounds {
        if let Some(k) = project.refine.kernel {
            m.kernel = k;
        }
    }
    m
}

/// The iteration target after one more extension of the final chains, which ran to `target`
/// iterations per chain and stand at `drawn`, or `None` when they stop: `convergence` meets
/// its targets, or `m.max_extensions` are done. An extension adds `iterations - burn_in` draws
/// per chain (as many again as the first run), or what the smallest ESS says the ESS target
/// needs ([`bemcal_stats::convergence::draws_for_ess`]), at most four times that. HMC chains
/// not yet re-adapted are re-adapted at the extension ([`bemcal_stats::chain::readapt`]; the
/// executor tries again at the next one where the draws gave no metric) and run its window on
/// top ([`bemcal_stats::hmc::readapt_window`], not drawn); that extension adds one step,
/// because the ESS per draw of the metric burn-in estimated says little of the one re-adapted
/// from the draws (measured on the demo: 4 to 8 times more bulk ESS per draw after it). One
/// rule, the driver's.
pub fn extended_target(
    m: &McmcSettings,
    convergence: &Convergence,
    extensions: u32,
    target: u64,
    drawn: Drawn,
) -> Option<u64> {
    if convergence.converged || extensions >= m.max_extensions {
        return None;
    }
    let opens = match m.kernel {
        Kernel::Hmc if !drawn.readapted => bemcal_stats::hmc::readapt_window(m.burn_in),
        _ => 0,
    };
    let step = m.iterations - m.burn_in;
    let draws = drawn.draws.max(1);
    let min_ess = convergence.min_ess_bulk.min(convergence.min_ess_tail);
    let for_ess = match opens {
        0 => draws_for_ess(draws, min_ess, convergence.targets.ess)
            .map_or(0, |n| n.saturating_sub(draws)),
        _ => step,
    };
    Some(target + opens + for_ess.clamp(step, 4 * step))
}

/// A chain started in the best optimum's mode instead of its own, which was `nats_below` lower
/// (`mcmc.restart_below`, [`bemcal_stats::optim::keep_best_modes`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct MovedChain {
    /// The chain's index.
    pub chain: usize,
    /// How far its own optimum's log posterior was below the best one's, nats.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub nats_below: f64,
}

/// The chains of `states` that were moved to the best optimum's mode.
pub fn moved_chains(states: &[Chain]) -> Vec<MovedChain> {
    states
        .iter()
        .enumerate()
        .filter_map(|(chain, s)| {
            s.moved_from_mode()
                .map(|nats_below| MovedChain { chain, nats_below })
        })
        .collect()
}

/// The chains of `states` whose independence kernel was switched off at the end of burn-in.
pub fn independence_dropped(states: &[Chain]) -> Vec<usize> {
    (0..states.len())
        .filter(|&c| states[c].independence_dropped())
        .collect()
}

/// Guideline 14 of the surrogate at `estimate` against the meters, per output.
pub(crate) fn surrogate_metrics_at(
    inp: &Inputs,
    eval: &mut Evaluator,
    estimate: &[f64],
) -> Result<Vec<OutputMetrics>, Error> {
    let n_h = inp.features.len();
    let y = eval.evaluate(estimate)?;
    let mut metrics = vec![];
    for (k, name) in inp.outputs.iter().enumerate() {
        let pred: Vec<f64> = (0..n_h).map(|h| f64::from(y[[h, k]])).collect();
        metrics.push(inp.metrics(k, name, &pred)?);
    }
    Ok(metrics)
}

/// Mean and sample standard deviation of the finite values of `s` by stats's rule
/// ([`bemcal_stats::diagnostics::mean`], [`sd`](bemcal_stats::diagnostics::sd)); without
/// values the empty sum (-0) for both, and `(x, 0)` with one, which the noise scales take as
/// they are.
fn mean_sd(s: &[f64]) -> (f64, f64) {
    let v: Vec<f64> = s.iter().copied().filter(|x| x.is_finite()).collect();
    match v[..] {
        [] => (-0.0, -0.0),
        [x] => (x, 0.0),
        _ => (
            bemcal_stats::diagnostics::mean(&v),
            bemcal_stats::diagnostics::sd(&v),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_noise_scales_take_stats_mean_and_sd_bit_for_bit() {
        // What this file computed before it called stats's mean and sd (issue 67): the
        // likelihood's noise scales, and so the draws, must not move.
        fn before(s: &[f64]) -> (f64, f64) {
            let v: Vec<f64> = s.iter().copied().filter(|x| x.is_finite()).collect();
            let n = v.len().max(1) as f64;
            let m = v.iter().sum::<f64>() / n;
            let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0).max(1.0);
            (m, var.sqrt())
        }
        let series: Vec<f64> = (0..5000u64)
            .map(|i| match i % 97 {
                13 => f64::NAN,
                41 => f64::INFINITY,
                _ => ((i * 2654435761) % 1000003) as f64 / 7919.0 - 40.0,
            })
            .collect();
        let bits = |(m, s): (f64, f64)| (m.to_bits(), s.to_bits());
        for n in [0, 1, 2, 3, 14, 97, 1000, 5000] {
            assert_eq!(
                bits(mean_sd(&series[..n])),
                bits(before(&series[..n])),
                "{n}"
            );
        }
        assert_eq!(mean_sd(&[f64::NAN, 2.5]), (2.5, 0.0));
        assert_eq!(mean_sd(&[]), (0.0, 0.0), "-0 == 0");
    }

    #[test]
    fn preliminary_rounds_take_the_refine_kernel_and_the_final_round_the_mcmc_one() {
        let mut p: crate::project::Project = toml::from_str(
            "name = \"x\"\nmodel = \"m.toml\"\nweather = \"w.epw\"\n[meters]\nfile = \"m.csv\"\n",
        )
        .unwrap();
        p.refine.rounds = 2;
        assert_eq!(
            settings_for(&p, 0).kernel,
            Kernel::Hmc,
            "unset: mcmc.kernel"
        );
        p.refine.kernel = Some(Kernel::Mh);
        let kernels: Vec<Kernel> = (0..=2).map(|r| settings_for(&p, r).kernel).collect();
        assert_eq!(kernels, [Kernel::Mh, Kernel::Mh, Kernel::Hmc]);
        assert_eq!(settings_for(&p, 0).seed, p.mcmc.seed);
        assert_ne!(settings_for(&p, 1).seed, p.mcmc.seed);
    }

    fn verdict(converged: bool, ess_bulk: f64, ess_tail: f64) -> Convergence {
        Convergence {
            converged,
            min_ess_bulk: ess_bulk,
            min_ess_tail: ess_tail,
            ..Convergence::default()
        }
    }

    fn drawn(draws: u64, readapted: bool) -> Drawn {
        Drawn { draws, readapted }
    }

    #[test]
    fn chains_are_extended_while_a_target_is_missed_up_to_the_limit() {
        let m = McmcSettings {
            iterations: 1000,
            burn_in: 400,
            max_extensions: 2,
            kernel: Kernel::Mh,
            ..McmcSettings::default()
        };
        let at = |draws| drawn(draws, false);
        // ESS already large (R-hat missed): one step of iterations - burn_in.
        let rhat_only = verdict(false, 2000.0, 2000.0);
        assert_eq!(
            extended_target(&m, &rhat_only, 0, 1000, at(600)),
            Some(1600)
        );
        assert_eq!(
            extended_target(&m, &rhat_only, 1, 1600, at(1200)),
            Some(2200)
        );
        assert_eq!(
            extended_target(&m, &rhat_only, 2, 2200, at(1800)),
            None,
            "at most max_extensions"
        );
        assert_eq!(
            extended_target(&m, &verdict(true, 2000.0, 2000.0), 0, 1000, at(600)),
            None,
            "converged"
        );
        // 600 draws gave tail ESS 200: 600 x 1.1 x 2 = 1,320 draws, 720 more.
        assert_eq!(
            extended_target(&m, &verdict(false, 900.0, 200.0), 0, 1000, at(600)),
            Some(1720)
        );
        // A tiny ESS asks for at most 4 steps; an ESS that could not be computed for one.
        assert_eq!(
            extended_target(&m, &verdict(false, 3.0, 3.0), 0, 1000, at(600)),
            Some(3400)
        );
        assert_eq!(
            extended_target(&m, &verdict(false, f64::NAN, f64::NAN), 0, 1000, at(600)),
            Some(1600)
        );
        let report_only = McmcSettings {
            max_extensions: 0,
            ..m
        };
        assert_eq!(
            extended_target(&report_only, &rhat_only, 0, 1000, at(600)),
            None
        );
    }

    #[test]
    fn the_hmc_extension_that_readapts_adds_the_window_undrawn() {
        let m = McmcSettings {
            iterations: 1000,
            burn_in: 400,
            max_extensions: 3,
            kernel: Kernel::Hmc,
            ..McmcSettings::default()
        };
        let window = bemcal_stats::hmc::readapt_window(400);
        assert_eq!(window, 200);
        let rhat_only = verdict(false, 2000.0, 2000.0);
        assert_eq!(
            extended_target(&m, &rhat_only, 0, 1000, drawn(600, false)),
            Some(1800)
        );
        // 1,800 iterations: 400 burn-in, 200 in the window, 1,200 draws; 600 more, and no
        // window (the chains are re-adapted once).
        assert_eq!(
            extended_target(&m, &rhat_only, 1, 1800, drawn(1200, true)),
            Some(2400)
        );
        // The extension that re-adapts adds one step whatever the ESS (the metric changes
        // with it).
        assert_eq!(
            extended_target(&m, &verdict(false, 900.0, 50.0), 0, 1000, drawn(600, false)),
            Some(1800)
        );
        // Later ones count the chains' draws: 1,200 at tail ESS 200 ask 2,640.
        assert_eq!(
            extended_target(
                &m,
                &verdict(false, 900.0, 200.0),
                1,
                1800,
                drawn(1200, true)
            ),
            Some(1800 + 1440)
        );
        // Where the draws gave no metric at the first extension, the chains were not
        // re-adapted and the window's 200 iterations were drawn (1,400 draws): the next
        // extension re-adapts them, with its window (the executor tries again), and adds one
        // step.
        assert_eq!(
            extended_target(
                &m,
                &verdict(false, 900.0, 200.0),
                1,
                1800,
                drawn(1400, false)
            ),
            Some(1800 + 200 + 600)
        );
    }
}
