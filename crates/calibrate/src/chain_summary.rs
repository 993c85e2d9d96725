//! Stage 6, the merged chains summarised ([`Sampler::summarize`] -> [`ChainSummary`]): the
//! posterior, the estimate and its fallbacks, the noise, `draws.csv` and the posterior
//! predictive; what validation and `summary.json` are built from.

use std::path::Path;

use bemcal_energyplus::Model;
use bemcal_stats::chain::Chain;
use bemcal_stats::convergence::{assess, Convergence};
use bemcal_stats::likelihood::OutputNoise;
use bemcal_stats::mcmc::{DrawStats, Draws};
use bemcal_stats::prior::Prior;
use bemcal_stats::summary::{predictive_bands, summarize, PosteriorSummary};
use bemcal_surrogate::Evaluator;
use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;
use crate::chains::{
    independence_dropped, moved_chains, surrogate_metrics_at, MovedChain, Sampler,
};
use crate::error::{write_atomic, Error};
use crate::estimate::{fallback_note, EstimateChoice};
use crate::keys::FALLBACKS;
use crate::metrics::OutputMetrics;
use crate::output::timestamps;
use crate::plan::Plan;
use crate::posterior::{ChainTemperature, Posterior, SigmaDeltaBox};
use crate::project::{Estimate, Temperature};
use crate::refine::RefineLog;
use crate::surrogate_error::{carry, SurrogateError};

impl Sampler<'_> {
    /// Stage 6: merged chains (their final `states` and `draws`) -> posterior summary, draws.csv
    /// and posterior predictive bands; with the surrogate error `refined`'s last round measured,
    /// the intervals that carry it ([`crate::surrogate_error`]).
    pub fn summarize(
        &mut self,
        states: &[Chain],
        draws: &[Draws],
        refined: &RefineLog,
    ) -> Result<ChainSummary, Error> {
        let cal = self.cal;
        let inp = &cal.inputs;
        let theta_draws = self.untempered(draws);
        let posterior = summarize(&parameter_priors(&inp.plan), &theta_draws)?;
        let sbox = self.sigma_box.clone();
        let noise = self.noise.clone();
        let (post, eval) = self.split();
        write_draws_csv(
            &cal.out.draws_csv(),
            &post,
            &inp.outputs,
            draws,
            &sbox,
            true,
        )?;
        // Seeded apart from the chains' streams.
        let seed = cal.project.mcmc.seed ^ 0x5EED_5EED_0E44_0420;
        let k = cal.project.validation.predictive_draws;
        // With the temperature measured from the surrogate's error, the chains carry it already.
        let carried = match cal.project.mcmc.temperature {
            Temperature::SurrogateError => None,
            Temperature::Fixed(_) => carry(post.plan, draws, refined, seed)?,
        };
        let (surrogate_error, predictive) = match carried {
            Some((report, shifted)) => {
                let path = cal.out.draws_with_surrogate_error_csv();
                write_draws_csv(&path, &post, &inp.outputs, &shifted, &sbox, false)?;
                (Some(report), pick(post.plan, &inp.model, &shifted, k))
            }
            None => (None, pick(post.plan, &inp.model, draws, k)),
        };
        let (sigma_delta_kwh, residual_ar1) =
            noise_summary(&post, eval, inp, &noise, draws, &posterior.map_point)?;
        let discrepancy_carried = discrepancy_carried(cal, &post, eval, &posterior.map_point)?;
        write_posterior_predictive(cal, &post, eval, &theta_draws)?;
        let estimate = point_estimate(&posterior, cal.project.validation.estimate);
        let surrogate_at_estimate = surrogate_metrics_at(inp, eval, &estimate)?;
        let surrogate_at_predictive = (predictive.iter())
            .map(|x| surrogate_metrics_at(inp, eval, x))
            .collect::<Result<_, _>>()?;
        let fallbacks: Vec<Vec<f64>> = best_draws(&theta_draws, FALLBACKS + 1)
            .iter()
            .map(|u| post.theta(u))
            .filter(|x| x != &estimate)
            .take(FALLBACKS)
            .collect();
        let convergence = assess(&posterior, &cal.project.mcmc.targets());
        Ok(ChainSummary {
            posterior,
            sigma_delta_kwh,
            residual_ar1,
            discrepancy_carried,
            estimate,
            surrogate_at_estimate,
            fallbacks,
            estimate_note: None,
            estimate_choice: None,
            surrogate_at_predictive,
            moved_chains: moved_chains(states),
            independence_dropped: independence_dropped(states),
            acceptance: states
                .iter()
                .map(|s| s.acceptance_rate_post_burn_in())
                .collect(),
            sigma_eta: self.sigma_eta.clone(),
            held_out: self.held_out.clone(),
            extensions: 0,
            convergence,
            surrogate_error,
            predictive,
            temperature: self.temperature,
        })
    }

    /// The draws' parameters, each with its log density under the untempered posterior
    /// (`ln p + T (ln pi_T - ln p)`, prior p): the estimate and its fallbacks are the best by
    /// it, where the tempered one ranks a draw T times less by its fit and T times more by its
    /// prior.
    fn untempered(&self, draws: &[Draws]) -> Vec<Draws> {
        let d = self.cal.inputs.plan.calibrated.len();
        let mut theta_draws: Vec<Draws> = draws.iter().map(|dr| sub_draws(dr, d)).collect();
        let t = self.temperature.value;
        if t != 1.0 {
            let post = self.posterior();
            for (td, dr) in theta_draws.iter_mut().zip(draws) {
                for (i, ld) in td.log_density.iter_mut().enumerate() {
                    let prior = post.ln_prior(dr.point(i));
                    *ld = prior + t * (*ld - prior);
                }
            }
        }
        theta_draws
    }
}

/// Each calibrated parameter's name, unit and prior, as the posterior summary reports them.
fn parameter_priors(plan: &Plan) -> Vec<Prior> {
    plan.calibrated
        .iter()
        .zip(&plan.priors)
        .zip(&plan.units)
        .map(|((n, p), u)| Prior::new(n.clone(), u.clone(), *p))
        .collect()
}

/// The point the project asks for as its estimate: the MAP draw (also where EnergyPlus will
/// choose among simulated draws), or the posterior mean or median of each parameter.
fn point_estimate(posterior: &PosteriorSummary, kind: Estimate) -> Vec<f64> {
    match kind {
        Estimate::Map | Estimate::BestSimulated => posterior.map_point.clone(),
        Estimate::Mean => posterior.parameters.iter().map(|p| p.mean).collect(),
        Estimate::Median => posterior.parameters.iter().map(|p| p.median).collect(),
    }
}

/// One value per output, named.
type PerOutput = Vec<(String, f64)>;

/// The noise the summary reports: sigma_delta per output in kWh (the median of the sampled
/// ones; with the variance integrated out, the posterior mean of sigma^2 at the MAP point,
/// SSR / (n - 2), less sigma_y^2 and sigma_eta^2; else the fixed value) and, with AR(1)
/// residuals, each output's profile phi at the MAP point; the fitted outputs only.
fn noise_summary(
    post: &Posterior<'_>,
    eval: &mut Evaluator,
    inp: &crate::inputs::Inputs,
    noise: &[OutputNoise],
    draws: &[Draws],
    map_point: &[f64],
) -> Result<(PerOutput, PerOutput), Error> {
    let d = inp.plan.calibrated.len();
    let mut residual_ar1: Vec<(String, f64)> = vec![];
    let sigma_delta_kwh: Vec<(String, f64)> = match post.sigma_box {
        Some(b) => (b.outputs.iter().enumerate())
            .map(|(j, &k)| {
                let mut v: Vec<f64> = draws
                    .iter()
                    .flat_map(|dr| dr.column(d + j))
                    .map(|u| b.sigma(j, u))
                    .collect();
                v.sort_by(f64::total_cmp);
                (inp.outputs[k].clone(), v[v.len() / 2])
            })
            .collect(),
        None if post.marginal => {
            // Posterior mean of sigma_k^2 given the MAP parameters, InvGamma(n/2, SSR/2):
            // SSR / (n - 2); sigma_delta is what is left after sigma_y and sigma_eta.
            let y = eval.evaluate(map_point)?;
            let flat = y.as_slice().expect("contiguous prediction");
            let ssr = post.likelihood.residual_sum_of_squares(flat);
            if post.ar1 {
                residual_ar1 = inp
                    .outputs
                    .iter()
                    .cloned()
                    .zip(post.likelihood.ar1_coefficients(flat))
                    .collect();
            }
            let n_obs = post.likelihood.n_observed();
            inp.outputs
                .iter()
                .enumerate()
                .map(|(k, name)| {
                    let total = ssr[k] / (n_obs[k] as f64 - 2.0).max(1.0);
                    let z = &noise[k];
                    let rest = total - z.sigma_y * z.sigma_y - z.sigma_eta * z.sigma_eta;
                    (name.clone(), rest.max(0.0).sqrt())
                })
                .collect()
        }
        None => inp
            .outputs
            .iter()
            .zip(noise)
            .map(|(n, z)| (n.clone(), z.sigma_delta))
            .collect(),
    };
    // A meter the likelihood leaves out (`fit = false`) has no noise estimate.
    let not_fitted = inp.not_fitted();
    let fitted = |v: PerOutput| -> PerOutput {
        v.into_iter()
            .filter(|(o, _)| !not_fitted.contains(o))
            .collect()
    };
    Ok((fitted(sigma_delta_kwh), fitted(residual_ar1)))
}

/// What the likelihood's discrepancy carries at the MAP point `map_point` (physical values), per
/// fitted meter, with `discrepancy_cells.csv` written; empty without the term.
fn discrepancy_carried(
    cal: &Calibration,
    post: &Posterior<'_>,
    eval: &mut Evaluator,
    map_point: &[f64],
) -> Result<Vec<crate::carried::Carried>, Error> {
    let Some(cells) = post.cells else {
        return Ok(vec![]);
    };
    let y = eval.evaluate(map_point)?;
    let flat = y.as_slice().expect("contiguous prediction");
    let Some((meters, table)) = crate::carried::carried(post, &cal.inputs.outputs, flat) else {
        return Ok(vec![]);
    };
    crate::carried::write_cells_csv(&cal.out.discrepancy_cells_csv(), &meters, &table, cells)?;
    Ok(meters)
}

/// `posterior_predictive.csv`: the surrogate's 5 / 50 / 95 % bands (plus the bases) from
/// `mcmc.predictive_draws` draws spread over all chains, beside the meters.
fn write_posterior_predictive(
    cal: &Calibration,
    post: &Posterior<'_>,
    eval: &mut Evaluator,
    theta_draws: &[Draws],
) -> Result<(), Error> {
    let inp = &cal.inputs;
    let (n_h, n_out) = (inp.features.len(), inp.outputs.len());
    let all: Vec<Vec<f64>> = theta_draws
        .iter()
        .flat_map(|dr| (0..dr.len()).map(move |i| dr.point(i).to_vec()))
        .collect();
    let want = cal.project.mcmc.predictive_draws.max(1);
    let step = (all.len() / want).max(1);
    let picks: Vec<Vec<f64>> = all.iter().step_by(step).map(|u| post.theta(u)).collect();
    let mut pred = vec![Vec::<f32>::with_capacity(picks.len() * n_h); n_out];
    for chunk in picks.chunks(8) {
        let y = eval.evaluate_batch(chunk)?;
        for b in 0..chunk.len() {
            for (k, p) in pred.iter_mut().enumerate() {
                p.extend((0..n_h).map(|h| y[[b, h, k]]));
            }
        }
    }
    let mut bands = vec![];
    for (k, p) in pred.iter().enumerate() {
        let mut b = predictive_bands(p, picks.len(), n_h)?;
        for q in [&mut b.q5, &mut b.q50, &mut b.q95] {
            *q = inp.with_base(k, q);
        }
        bands.push(b);
    }
    write_bands_csv(
        &cal.out.posterior_predictive_csv(),
        inp.year,
        &inp.outputs,
        &(0..n_out).map(|k| inp.meter(k)).collect::<Vec<_>>(),
        &bands,
    )
}

/// `k` draws evenly spaced through the merged chains (unit space; the middle of each of `k`
/// equal stretches) among those EnergyPlus can be asked to simulate (every model constraint
/// met, outside the region it refused), in physical units.
pub fn pick(plan: &Plan, model: &Model, draws: &[Draws], k: usize) -> Vec<Vec<f64>> {
    let feasible: Vec<Vec<f64>> = draws
        .iter()
        .flat_map(|d| (0..d.len()).map(move |i| d.point(i)))
        .map(|u| {
            plan.priors
                .iter()
                .zip(u)
                .map(|(p, u)| p.from_unit(*u))
                .collect::<Vec<f64>>()
        })
        .filter(|x| plan.feasible(model, x) && plan.refused(x).is_none())
        .collect();
    evenly(&feasible, k)
}

/// `k` items evenly spaced through `all`, the middle of each of `k` equal stretches.
fn evenly<T: Clone>(all: &[T], k: usize) -> Vec<T> {
    let k = k.min(all.len());
    (0..k)
        .map(|j| all[(2 * j + 1) * all.len() / (2 * k)].clone())
        .collect()
}

/// `draws.csv` (or, without `log_posterior`, the draws with the surrogate's error): each
/// draw's parameters (physical units), sampled sigma_delta, and with `log_posterior` its log
/// density and the sampler's statistics.
fn write_draws_csv(
    path: &Path,
    post: &Posterior<'_>,
    outputs: &[String],
    draws: &[Draws],
    sbox: &SigmaDeltaBox,
    log_posterior: bool,
) -> Result<(), Error> {
    let d = post.plan.calibrated.len();
    let mut s = format!("chain,draw,{}", post.plan.calibrated.join(","));
    if post.sigma_box.is_some() {
        for &k in &sbox.outputs {
            s.push_str(&format!(",sigma_delta_{}", outputs[k]));
        }
    }
    if log_posterior {
        s.push_str(",log_posterior");
    }
    // The sampler's statistics per draw, named as CmdStan names them, when every chain has them.
    let stats: Option<Vec<&[DrawStats]>> = match log_posterior {
        true => draws.iter().map(Draws::stats).collect(),
        false => None,
    };
    if stats.is_some() {
        s.push_str(",accept_stat__,stepsize__,n_leapfrog__,divergent__");
    }
    s.push('\n');
    for (c, dr) in draws.iter().enumerate() {
        for i in 0..dr.len() {
            let u = dr.point(i);
            s.push_str(&format!("{c},{i}"));
            for x in post.theta(u) {
                s.push_str(&format!(",{x}"));
            }
            if post.sigma_box.is_some() {
                for j in 0..sbox.len() {
                    s.push_str(&format!(",{}", sbox.sigma(j, u[d + j])));
                }
            }
            if log_posterior {
                s.push_str(&format!(",{}", dr.log_density[i]));
            }
            if let Some(st) = stats.as_ref().map(|all| all[c][i]) {
                let divergent = u8::from(st.divergent);
                s.push_str(&format!(
                    ",{},{},{},{divergent}",
                    st.accept_stat, st.step_size, st.n_leapfrog
                ));
            }
            s.push('\n');
        }
    }
    write_atomic(path, s.as_bytes())
}

/// `posterior_predictive.csv`'s rows: per hour, each output's meter and its 5 / 50 / 95 % bands.
fn write_bands_csv(
    path: &Path,
    year: bemcal_weather::grid::GridYear,
    outputs: &[String],
    measured: &[Vec<f64>],
    bands: &[bemcal_stats::summary::PredictiveBands],
) -> Result<(), Error> {
    let mut s = String::from("timestamp");
    for o in outputs {
        s.push_str(&format!(",{o}_measured,{o}_q5,{o}_q50,{o}_q95"));
    }
    s.push('\n');
    let n = bands.first().map_or(0, |b| b.q50.len());
    for (t, ts) in timestamps(year, n) {
        s.push_str(&ts);
        for (k, b) in bands.iter().enumerate() {
            let m = measured[k][t];
            let m = if m.is_finite() {
                format!("{m:.4}")
            } else {
                String::new()
            };
            s.push_str(&format!(
                ",{m},{:.4},{:.4},{:.4}",
                b.q5[t], b.q50[t], b.q95[t]
            ));
        }
        s.push('\n');
    }
    write_atomic(path, s.as_bytes())
}

/// The merged chains, summarised ([`Sampler::summarize`]): what validation and `summary.json`
/// are built from. Both drivers keep it between those stages (the coordinator in its database),
/// so every field is serialisable.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ChainSummary {
    /// Posterior draws (physical units) EnergyPlus simulates for the predictive intervals
    /// ([`crate::predictive`]).
    #[serde(default)]
    pub predictive: Vec<Vec<f64>>,
    /// The calibrated parameters' posterior (physical units): per-parameter statistics, the
    /// MAP draw, correlated pairs, R-hat and ESS.
    pub posterior: PosteriorSummary,
    /// Model inadequacy sigma_delta per output, kWh: the sampled ones' median; with the variance
    /// integrated out, what the MAP's residual variance leaves after sigma_y and sigma_eta;
    /// else the fixed value.
    pub sigma_delta_kwh: Vec<(String, f64)>,
    /// Profile AR(1) coefficient of each output's residuals at the MAP (AR(1) mode).
    #[serde(default)]
    pub residual_ar1: Vec<(String, f64)>,
    /// What the likelihood's model-form discrepancy carries at the MAP, per fitted meter
    /// (`mcmc.discrepancy`; empty without it).
    #[serde(default)]
    pub discrepancy_carried: Vec<crate::carried::Carried>,
    /// The calibrated estimate (calibrated parameters, physical units).
    pub estimate: Vec<f64>,
    /// Guideline 14 of the surrogate at the estimate against the meters.
    #[serde(default)]
    pub surrogate_at_estimate: Vec<OutputMetrics>,
    /// Where EnergyPlus cannot simulate the estimate, the draws validated instead, best first:
    /// the next distinct draws by log posterior (physical units).
    #[serde(default)]
    pub fallbacks: Vec<Vec<f64>>,
    /// Set when a fallback draw ([`ChainSummary::settle_estimate`]) or a predictive draw
    /// ([`ChainSummary::adopt_best_simulated`]) replaced the estimate: why.
    #[serde(default)]
    pub estimate_note: Option<String>,
    /// With `estimate = "best_simulated"`: the draws EnergyPlus simulated and which became the
    /// estimate ([`ChainSummary::adopt_best_simulated`]).
    #[serde(default)]
    pub estimate_choice: Option<EstimateChoice>,
    /// Guideline 14 of the surrogate at each predictive draw (`predictive`'s order): what
    /// `surrogate_at_estimate` becomes where one of them is adopted as the estimate.
    #[serde(default)]
    pub surrogate_at_predictive: Vec<Vec<OutputMetrics>>,
    /// Chains started in the best optimum's mode ([`moved_chains`] of the states).
    #[serde(default)]
    pub moved_chains: Vec<MovedChain>,
    /// Chains whose independence kernel was switched off after burn-in
    /// ([`independence_dropped`] of the states).
    #[serde(default)]
    pub independence_dropped: Vec<usize>,
    /// Acceptance rate after burn-in, per chain.
    pub acceptance: Vec<f64>,
    /// The surrogate's held-out RMSE per output, kWh (its part of the likelihood's noise).
    pub sigma_eta: Vec<f64>,
    /// The surrogate's held-out metrics.
    pub held_out: serde_json::Value,
    /// Times the final chains were extended because a convergence target was missed.
    #[serde(default)]
    pub extensions: u32,
    /// The verdict on these chains against `mcmc.rhat_target` and `mcmc.ess_target`.
    #[serde(default)]
    pub convergence: Convergence,
    /// The intervals with the surrogate's error ([`crate::surrogate_error`]); `None` without a
    /// refinement round that measured it, and with `mcmc.temperature = "surrogate_error"`
    /// (the chains' own intervals carry it then).
    #[serde(default)]
    pub surrogate_error: Option<SurrogateError>,
    /// The likelihood's temperature the chains ran at.
    #[serde(default = "ChainTemperature::one")]
    pub temperature: ChainTemperature,
}

impl ChainSummary {
    /// Makes the validated candidate the estimate: after `failures` (EnergyPlus failed at the
    /// estimate and at the fallbacks before the one that ran, in [`crate::validation::next_candidate`]'s
    /// order), that fallback's values, with a note saying why.
    pub fn settle_estimate(&mut self, failures: &[String]) {
        if let Some(x) = failures
            .len()
            .checked_sub(1)
            .and_then(|k| self.fallbacks.get(k))
        {
            self.estimate = x.clone();
            self.estimate_note = Some(fallback_note(failures));
        }
    }

    /// Makes `adopted` (its values and the surrogate's metrics there) the estimate where
    /// `estimate = "best_simulated"` chose a point other than the MAP draw (`choice`); `None`
    /// keeps the MAP draw. Records the choice either way. `map_failure`: why EnergyPlus could
    /// not simulate the MAP draw, if it could not.
    pub fn adopt_best_simulated(
        &mut self,
        adopted: Option<(Vec<f64>, Vec<OutputMetrics>)>,
        choice: EstimateChoice,
        map_failure: Option<&str>,
    ) {
        if let Some((x, surrogate)) = adopted {
            self.estimate_note = Some(choice.describe(map_failure));
            self.estimate = x;
            self.surrogate_at_estimate = surrogate;
        }
        self.estimate_choice = Some(choice);
    }

    /// Predictive draw `j` and the surrogate's metrics there, as
    /// [`Self::adopt_best_simulated`] takes them.
    pub fn predictive_point(&self, j: usize) -> Option<(Vec<f64>, Vec<OutputMetrics>)> {
        let x = self.predictive.get(j)?.clone();
        Some((
            x,
            self.surrogate_at_predictive
                .get(j)
                .cloned()
                .unwrap_or_default(),
        ))
    }

    /// The calibrated parameters whose value in `x` lies outside the posterior's 90 %
    /// interval.
    pub fn outside_interval(&self, x: &[f64]) -> Vec<String> {
        (self.posterior.parameters.iter().zip(x))
            .filter(|(p, v)| **v < p.q5 || **v > p.q95)
            .map(|(p, _)| p.name.clone())
            .collect()
    }
}

/// Up to `k` distinct draws (unit space) in decreasing log posterior.
fn best_draws(draws: &[Draws], k: usize) -> Vec<Vec<f64>> {
    let mut all: Vec<(f64, &[f64])> = draws
        .iter()
        .flat_map(|d| (0..d.len()).map(move |i| (d.log_density[i], d.point(i))))
        .collect();
    all.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut out: Vec<Vec<f64>> = vec![];
    for (_, p) in all {
        if out.len() >= k {
            break;
        }
        if !out.iter().any(|q| q.as_slice() == p) {
            out.push(p.to_vec());
        }
    }
    out
}

fn sub_draws(d: &Draws, dim: usize) -> Draws {
    let mut out = Draws::new(dim);
    for i in 0..d.len() {
        out.points.extend_from_slice(&d.point(i)[..dim]);
    }
    out.log_density = d.log_density.clone();
    out.stats = d.stats.clone();
    out
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::estimate::tests::choice;
    use crate::metrics::tests::metrics;

    /// Merged chains with the estimate `[0.0]` and fallbacks `[1.0]`, `[2.0]`, ...
    pub(crate) fn chains(fallbacks: usize) -> ChainSummary {
        ChainSummary {
            posterior: serde_json::from_value(serde_json::json!({
                "parameters": [], "map_point": [], "map_log_density": 0.0,
                "correlated_pairs": [], "max_rhat": 1.0, "min_ess_bulk": 100.0
            }))
            .unwrap_or_else(|e| panic!("{e}")),
            sigma_delta_kwh: vec![],
            residual_ar1: vec![],
            discrepancy_carried: vec![],
            estimate: vec![0.0],
            surrogate_at_estimate: vec![],
            fallbacks: (1..=fallbacks).map(|k| vec![k as f64]).collect(),
            estimate_note: None,
            estimate_choice: None,
            surrogate_at_predictive: vec![],
            moved_chains: vec![],
            independence_dropped: vec![],
            acceptance: vec![],
            sigma_eta: vec![],
            held_out: serde_json::Value::Null,
            extensions: 0,
            convergence: Default::default(),
            surrogate_error: None,
            temperature: ChainTemperature::ONE,
            predictive: vec![],
        }
    }

    #[test]
    fn a_fallback_that_ran_becomes_the_estimate_with_a_note() {
        let mut c = chains(2);
        c.settle_estimate(&[]);
        assert_eq!(
            (c.estimate.clone(), c.estimate_note.is_none()),
            (vec![0.0], true)
        );
        c.settle_estimate(&["a".into(), "b".into()]);
        assert_eq!(c.estimate, vec![2.0]);
        assert!(c.estimate_note.unwrap().contains("2 failed: a | b"));
    }

    #[test]
    fn a_predictive_draw_fitted_best_becomes_the_estimate_with_its_surrogate_metrics() {
        let metrics = |nmbe: f64| vec![metrics("heating", nmbe, 10.0)];
        let mut c = chains(1);
        c.predictive = vec![vec![5.0], vec![6.0]];
        c.surrogate_at_estimate = metrics(0.0);
        c.surrogate_at_predictive = vec![metrics(5.0), metrics(6.0)];

        let mut passing = choice("calibrated");
        passing.candidates[0].limit_ratio = Some(0.5);
        assert!(passing
            .describe(None)
            .contains("passes Guideline 14 hourly at the MAP draw (worst meter at 0.50"));
        assert!(choice("calibrated")
            .describe(None)
            .contains("fails Guideline 14 hourly at the MAP draw (worst meter at 1.60"));

        let mut kept = c.clone();
        kept.adopt_best_simulated(None, choice("calibrated"), None);
        assert_eq!(kept.estimate, vec![0.0]);
        assert!(kept.estimate_note.is_none());
        assert_eq!(kept.estimate_choice.unwrap().chosen, "calibrated");

        c.adopt_best_simulated(c.predictive_point(1), choice("predictive_01"), None);
        assert_eq!(c.estimate, vec![6.0]);
        assert_eq!(c.surrogate_at_estimate[0].metrics.nmbe, 6.0);
        let note = c.estimate_note.clone().unwrap();
        assert!(
            note.contains("predictive_01 fits the meters better than the MAP draw, which fails")
                && note.contains("worst meter at 0.70 of the limits, the MAP draw's at 1.60")
                && note.contains("of 3 points"),
            "{note}"
        );

        // The MAP draw passes hourly and misses monthly; predictive_01 passes both.
        let monthly = |c: &mut EstimateChoice| {
            c.candidates[0].limit_ratio = Some(0.56);
            for (f, m) in c.candidates.iter_mut().zip([1.22, 1.1, 0.72]) {
                f.monthly_limit_ratio = Some(m);
            }
        };
        let mut both = choice("predictive_01");
        monthly(&mut both);
        let note = both.describe(None);
        assert!(
            note.contains("passes Guideline 14 hourly at the MAP draw (worst meter at 0.56")
                && note.contains("misses its monthly criteria (worst meter at 1.22")
                && note.contains("at posterior draw predictive_01 it passes both")
                && note.contains("0.70 of the hourly and 0.72 of the monthly limits"),
            "{note}"
        );
        let mut kept_map = choice("calibrated");
        monthly(&mut kept_map);
        assert!(kept_map
            .describe(None)
            .contains("no other of the 3 points it simulated passes both"));

        // The MAP draw fails hourly; the chosen draw passes monthly as well: said.
        let mut monthly_too = choice("predictive_01");
        monthly_too.candidates[2].monthly_limit_ratio = Some(0.8);
        let note = monthly_too.describe(None);
        assert!(
            note.contains(
                "of 3 points simulated; it passes the monthly criteria too (worst \
                           meter at 0.80 of their limits): it is the estimate"
            ),
            "{note}"
        );

        let mut failed = chains(1);
        failed.predictive = vec![vec![5.0]];
        failed.adopt_best_simulated(
            failed.predictive_point(0),
            choice("predictive_00"),
            Some("Fatal: no"),
        );
        assert_eq!(failed.estimate, vec![5.0]);
        assert!(failed
            .estimate_note
            .unwrap()
            .contains("could not simulate the MAP draw: Fatal: no"));
    }

    #[test]
    fn picks_spread_evenly() {
        let all: Vec<usize> = (0..20).collect();
        assert_eq!(evenly(&all, 4), vec![2, 7, 12, 17]);
        assert_eq!(evenly(&all, 0), Vec::<usize>::new());
        assert_eq!(evenly(&all[..10], 50).len(), 10);
    }
}
