//! Stage 7, validation: EnergyPlus at the estimate against the meters (ASHRAE Guideline 14);
//! with `estimate = "best_simulated"`, which of the draws it simulated becomes the estimate
//! ([`best_simulated`]); and the rule for when it can simulate none of them: the next-best
//! posterior draws, in order, each under its own key in `validation/`.

use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::metrics::{g14, g14_monthly};
use bemcal_weather::period::months_of_hours;
use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;
use crate::chains::ChainSummary;
use crate::design::{saved_outputs, simulate_point};
use crate::error::Error;
use crate::inputs::Inputs;
use crate::keys::{candidate_key, is_mapped, CALIBRATED_LABEL};
use crate::summary::write_outputs_csv;
use crate::summary::OutputMetrics;
use crate::summary::PeriodMetrics;

/// A point to validate the calibration at: the estimate (`rank` 0) or the `rank`-th fallback.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// 0 for the estimate; `k` for the `k`-th fallback ([`ChainSummary::fallbacks`]).
    pub rank: usize,
    /// Its key in `validation/`: 0 the estimate, then `rank + 1` (1 is the initial model).
    pub key: usize,
    /// Calibrated parameter values (physical units, plan order).
    pub values: Vec<f64>,
}

/// What to validate next.
#[derive(Debug, Clone, PartialEq)]
pub enum ValidationStep {
    /// Simulate this candidate.
    Validate(Candidate),
    /// EnergyPlus failed at the estimate and at every fallback: the message says so.
    Exhausted(String),
}

/// The next candidate after `failures` (EnergyPlus failed at the first `failures.len()`
/// candidates: the estimate, then [`ChainSummary::fallbacks`] in order). The one rule both
/// drivers follow; [`ChainSummary::settle_estimate`] records which one ran.
pub fn next_candidate(chains: &ChainSummary, failures: &[String]) -> ValidationStep {
    let rank = failures.len();
    let values = match rank {
        0 => Some(&chains.estimate),
        k => chains.fallbacks.get(k - 1),
    };
    match values {
        Some(x) => ValidationStep::Validate(Candidate {
            rank,
            key: candidate_key(rank),
            values: x.clone(),
        }),
        None => ValidationStep::Exhausted(format!(
            "EnergyPlus failed at the estimate and at the next {} draws: {}",
            rank - 1,
            failures.join(" | ")
        )),
    }
}

/// What summary.json says when the estimate was replaced by the next-best draw.
pub fn fallback_note(failures: &[String]) -> String {
    format!(
        "EnergyPlus could not simulate the estimate; calibrated_values and validation are those \
         of the next-best posterior draw that it could simulate (by log posterior; {} failed: {})",
        failures.len(),
        failures.join(" | ")
    )
}

/// One posterior draw EnergyPlus simulated in validation, and how near Guideline 14's hourly
/// limits it is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulatedFit {
    /// Its validation label: `calibrated` (the MAP draw) or `predictive_NN`.
    pub label: String,
    /// [`limit_ratio`] of its run: at most 1 when every fitted meter passes hourly (`None`:
    /// its run gave no metrics).
    pub limit_ratio: Option<f64>,
    /// [`monthly_limit_ratio`] of its run: at most 1 when every fitted meter passes monthly
    /// (`None`: no monthly figures, a calibration period under two months, or an older
    /// summary).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub monthly_limit_ratio: Option<f64>,
}

/// How `estimate = "best_simulated"` chose the estimate, for `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EstimateChoice {
    /// The label of the draw that became the estimate.
    pub chosen: String,
    /// Every draw EnergyPlus simulated, in validation's order (the MAP draw first), then
    /// the points of the output space mapping, if any.
    pub candidates: Vec<SimulatedFit>,
    /// The steps of output space mapping ([`crate::mapping`]) where EnergyPlus fitted none of
    /// the posterior draws.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub mapping: Vec<crate::mapping::MappingStep>,
    /// Where a mapped point became the estimate (it is not a posterior draw): the parameters
    /// whose value there lies outside the posterior's 90 % interval.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outside_interval: Vec<String>,
}

impl EstimateChoice {
    /// The choice in a sentence, for the log and (where a predictive draw became the
    /// estimate) `estimate_note`. `map_failure`: why EnergyPlus could not simulate the MAP
    /// draw, if it could not.
    pub fn describe(&self, map_failure: Option<&str>) -> String {
        let ratio = |label: &str| self.ratio_of(label);
        let map = shown(ratio(CALIBRATED_LABEL));
        let n = self.candidates.len();
        let map_passes_hourly = ratio(CALIBRATED_LABEL).is_some_and(|r| r <= 1.0);
        let map_monthly = self.monthly_of(CALIBRATED_LABEL);
        let map_misses_monthly = map_passes_hourly && map_monthly.is_some_and(|r| r > 1.0);
        let monthly_miss = || {
            format!(
                "passes Guideline 14 hourly at the MAP draw (worst meter at {map} of the hourly \
                 limits) but misses its monthly criteria (worst meter at {} of the monthly \
                 limits)",
                shown(map_monthly)
            )
        };
        if self.chosen == CALIBRATED_LABEL {
            return if map_misses_monthly {
                format!(
                    "EnergyPlus {}, and no other of the {n} points it simulated passes both: it \
                     is the estimate",
                    monthly_miss()
                )
            } else if map_passes_hourly {
                format!(
                    "EnergyPlus passes Guideline 14 hourly at the MAP draw (worst meter at {map} \
                     of the limits): it is the estimate"
                )
            } else {
                format!(
                    "EnergyPlus fails Guideline 14 hourly at the MAP draw (worst meter at {map} of \
                     the limits), and no other of the {n} points it simulated fits better: it is \
                     the estimate"
                )
            };
        }
        if is_mapped(&self.chosen) {
            return self.describe_mapped(map_failure, &map);
        }
        if map_misses_monthly {
            return format!(
                "EnergyPlus {}; at posterior draw {} it passes both (worst meter at {} of the \
                 hourly and {} of the monthly limits), of {n} points simulated: it is the \
                 estimate",
                monthly_miss(),
                self.chosen,
                shown(ratio(&self.chosen)),
                shown(self.monthly_of(&self.chosen)),
            );
        }
        let (than, map_ratio) = match map_failure {
            None => (
                "better than the MAP draw, which fails there".to_string(),
                format!(", the MAP draw's at {map}"),
            ),
            Some(e) => (
                format!("best (EnergyPlus could not simulate the MAP draw: {e})"),
                String::new(),
            ),
        };
        let monthly = match self.monthly_of(&self.chosen) {
            Some(r) if r <= 1.0 => format!(
                "; it passes the monthly criteria too (worst meter at {r:.2} of their limits)"
            ),
            _ => String::new(),
        };
        format!(
            "EnergyPlus at posterior draw {} fits the meters {than} by Guideline 14's hourly \
             criteria (its worst meter at {} of the limits{map_ratio}), of {n} points \
             simulated{monthly}: it is the estimate",
            self.chosen,
            shown(ratio(&self.chosen)),
        )
    }

    /// [`Self::describe`] where a point of the output space mapping became the estimate.
    fn describe_mapped(&self, map_failure: Option<&str>, map: &str) -> String {
        let draws: Vec<&SimulatedFit> = (self.candidates.iter())
            .filter(|c| !is_mapped(&c.label))
            .collect();
        let drawn = draws.len();
        let nearest = |r: fn(&SimulatedFit) -> Option<f64>| {
            shown(draws.iter().filter_map(|c| r(c)).reduce(f64::min))
        };
        let (step, point) = (self.mapping.iter())
            .find_map(|s| Some((s, s.points.iter().find(|p| p.label == self.chosen)?)))
            .map_or(("?".to_string(), 1.0), |(s, p)| {
                (s.anchor.clone(), p.fraction)
            });
        let map = match map_failure {
            None => format!("the MAP draw at {map}"),
            Some(e) => format!("EnergyPlus could not simulate the MAP draw: {e}"),
        };
        let drawn_fit = if draws
            .iter()
            .any(|c| c.limit_ratio.is_some_and(|r| r <= 1.0))
        {
            format!(
                "EnergyPlus passes Guideline 14 hourly at some of the {drawn} posterior draws it \
                 simulated and misses its monthly criteria at each of those (the nearest inside \
                 the monthly limits at {}; {map} of the hourly ones)",
                nearest(|c| (c.limit_ratio? <= 1.0).then_some(c.monthly_limit_ratio?)),
            )
        } else {
            format!(
                "EnergyPlus fails Guideline 14 hourly at every one of the {drawn} posterior draws \
                 it simulated (the best at {} of the limits; {map})",
                nearest(|c| c.limit_ratio)
            )
        };
        let hourly = shown(self.ratio_of(&self.chosen));
        let fit = match self.monthly_of(&self.chosen) {
            Some(m) if m <= 1.0 => {
                format!("{hourly} of the hourly limits and {m:.2} of the monthly ones")
            }
            Some(m) => format!("{hourly} of the hourly limits (the monthly ones at {m:.2})"),
            None => format!("{hourly} of the limits"),
        };
        let d = self.outside_interval.len();
        let outside = if d == 0 {
            "every parameter lies inside the posterior's 90 % interval".to_string()
        } else {
            format!(
                "{d} parameter(s) lie outside the posterior's 90 % interval ({})",
                self.outside_interval.join(", ")
            )
        };
        format!(
            "{drawn_fit}; output space mapping from {step} (the surrogate corrected by \
             EnergyPlus's hourly difference there) found {}, {point:.2} of the way to the \
             corrected surrogate's mode, where EnergyPlus's worst meter is at {fit}: it is the \
             estimate. It is not a posterior draw: {outside}",
            self.chosen,
        )
    }

    /// The hourly limit ratio of the candidate labelled `label`, if it ran with metrics.
    fn ratio_of(&self, label: &str) -> Option<f64> {
        self.fit_of(label).and_then(|c| c.limit_ratio)
    }

    /// The monthly limit ratio of the candidate labelled `label`, if it ran with monthly
    /// figures.
    fn monthly_of(&self, label: &str) -> Option<f64> {
        self.fit_of(label).and_then(|c| c.monthly_limit_ratio)
    }

    /// The candidate labelled `label`.
    fn fit_of(&self, label: &str) -> Option<&SimulatedFit> {
        self.candidates.iter().find(|c| c.label == label)
    }
}

/// A limit ratio as the sentences show it: two decimals, `?` where there is none.
fn shown(r: Option<f64>) -> String {
    r.map_or("?".to_string(), |r| format!("{r:.2}"))
}

/// How near one EnergyPlus run is to Guideline 14's hourly limits: its worst fitted meter's
/// [`bemcal_stats::metrics::G14Metrics::hourly_limit_ratio`] over the calibration period
/// (`fitted[k]`: output `k`'s meter is in the likelihood; infinite with none).
pub fn limit_ratio(metrics: &[OutputMetrics], fitted: &[bool]) -> f64 {
    (metrics.iter().zip(fitted))
        .filter(|(_, f)| **f)
        .map(|(m, _)| m.metrics.hourly_limit_ratio())
        .reduce(f64::max)
        .unwrap_or(f64::INFINITY)
}

/// The worst fitted meter's [`bemcal_stats::metrics::G14Metrics::monthly_limit_ratio`] of one
/// EnergyPlus run over the calibration period: at most 1 when every fitted meter passes
/// Guideline 14's monthly criteria; `None` when no fitted meter has monthly figures (a
/// calibration period under two months: the monthly criteria do not judge it).
pub fn monthly_limit_ratio(metrics: &[OutputMetrics], fitted: &[bool]) -> Option<f64> {
    (metrics.iter().zip(fitted))
        .filter(|(_, f)| **f)
        .filter_map(|(m, _)| m.monthly.map(|g| g.monthly_limit_ratio()))
        .reduce(f64::max)
}

/// How near one EnergyPlus run is to Guideline 14's limits, hourly and monthly, as
/// [`best_simulated`] weighs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// [`limit_ratio`]: infinite where the run gave no metrics.
    pub hourly: f64,
    /// [`monthly_limit_ratio`].
    pub monthly: Option<f64>,
}

impl Fit {
    /// The fit of a run's metrics (`fitted[k]`: output `k`'s meter is in the likelihood).
    pub fn of(metrics: &[OutputMetrics], fitted: &[bool]) -> Fit {
        Fit {
            hourly: limit_ratio(metrics, fitted),
            monthly: monthly_limit_ratio(metrics, fitted),
        }
    }

    /// Every fitted meter passes Guideline 14 hourly.
    pub fn passes_hourly(&self) -> bool {
        self.hourly <= 1.0
    }

    /// Every fitted meter passes Guideline 14 hourly and, where the period has monthly
    /// figures, monthly.
    pub fn passes_both(&self) -> bool {
        self.passes_hourly() && self.monthly.is_none_or(|m| m <= 1.0)
    }

    /// The nearer of the two sets of limits: the larger ratio (the hourly one without monthly
    /// figures; NaN where either is).
    pub fn worst(&self) -> f64 {
        let monthly = self.monthly.unwrap_or(self.hourly);
        if self.hourly.is_nan() || monthly.is_nan() {
            return f64::NAN;
        }
        self.hourly.max(monthly)
    }
}

/// The rule of `estimate = "best_simulated"`, over the [`Fit`]s of the points EnergyPlus
/// simulated: the posterior draws first (the MAP draw's first where it ran, `map_ran`), then,
/// from index `first_mapped` on, the points of the output space mapping in the order the
/// search ran them ([`crate::mapping`]). In order:
///
/// 1. The MAP draw while EnergyPlus passes Guideline 14 there, hourly and monthly, since it is
///    the posterior's best point and a draw a little nearer the limits' centre is no better an
///    estimate (on the quick example one was, by 0.328 against 0.323, and lay outside the
///    chains' 90 % interval).
/// 2. Where the MAP draw misses either, the draw that passes both, nearest inside their limits
///    (the smallest of its two ratios' larger, the first on a tie): Guideline 14 calibrates a
///    model with monthly or hourly data, and a user with hourly meters is judged by both (on
///    the full-year demo at 60 design points the MAP draw passed hourly at 0.56 and missed
///    the monthly NMBE by a point, while a predictive draw passed both).
/// 3. The mapped point that passes both, nearest inside their limits (the search runs only
///    where no draw passes both, and stops at the step that finds one): no posterior draw,
///    and the model a user is judged by.
/// 4. The MAP draw where it passes hourly and no point passes both.
/// 5. The mapped point that passes hourly nearest inside both sets of limits (the search goes
///    on past one that misses the monthly criteria: on the held-out 20-point demo its second
///    step found a point at 0.80 of the hourly limits and 1.80 of the monthly ones, against
///    the first's 0.97 and 2.19).
/// 6. The draw whose worst meter is nearest inside the hourly limits (the smallest ratio, the
///    first on a tie): a mapped point that fails as well is no better an estimate than a draw
///    of the posterior (on the RSF, whose heating no point reaches, one was by 5.476 against
///    5.480).
///
/// `None` when no draw's hourly ratio is finite. Every draw is one of the posterior the
/// calibration reports (with the surrogate's error carried where it is, as the predictive
/// draws are: `ChainSummary::predictive`): where the surrogate misled the MAP, this takes the
/// model a user can take away by the criteria they judge it with. The calibration period only:
/// a held-out period never chooses.
pub fn best_simulated(fits: &[Fit], map_ran: bool, first_mapped: usize) -> Option<usize> {
    let map = fits.first().filter(|_| map_ran);
    if map.is_some_and(Fit::passes_both) {
        return Some(0);
    }
    let draws = &fits[..first_mapped.min(fits.len())];
    let both: Vec<f64> = (draws.iter())
        .map(|f| {
            if f.passes_both() {
                f.worst()
            } else {
                f64::INFINITY
            }
        })
        .collect();
    if let Some(i) = smallest_finite(&both) {
        return Some(i);
    }
    // The mapped point that `passes`, nearest inside both sets of limits (the first on a tie).
    let mapped_that = |passes: fn(&Fit) -> bool| {
        let worst: Vec<f64> = (fits.iter().enumerate())
            .map(|(i, f)| match i >= first_mapped && passes(f) {
                true => f.worst(),
                false => f64::INFINITY,
            })
            .collect();
        smallest_finite(&worst)
    };
    if let Some(m) = mapped_that(Fit::passes_both) {
        return Some(m);
    }
    if map.is_some_and(Fit::passes_hourly) {
        return Some(0);
    }
    if let Some(m) = mapped_that(Fit::passes_hourly) {
        return Some(m);
    }
    smallest_finite(&draws.iter().map(|f| f.hourly).collect::<Vec<_>>())
}

/// The index of the smallest finite ratio, the first on a tie; `None` when none is finite.
pub fn smallest_finite(limit_ratios: &[f64]) -> Option<usize> {
    let mut best: Option<usize> = None;
    for (i, r) in limit_ratios.iter().enumerate() {
        if r.is_finite() && best.is_none_or(|b| *r < limit_ratios[b]) {
            best = Some(i);
        }
    }
    best
}

impl Calibration {
    /// One job per point: EnergyPlus at `values` (key `i` in `validation/`) against the
    /// meters, ASHRAE Guideline 14 per output.
    pub fn validate(&self, i: usize, label: &str, x: &[f64]) -> Result<Vec<OutputMetrics>, Error> {
        let inp = &self.inputs;
        let vdir = self.out.validation();
        std::fs::create_dir_all(&vdir).map_err(|e| Error::io(&vdir, e))?;
        let (o, _) = simulate_point(
            &inp.runner,
            &inp.model,
            &inp.plan.values(x),
            &inp.weather_path,
            &vdir,
            i,
        )?;
        write_outputs_csv(&vdir.join(format!("{label}.csv")), inp.year, &o)?;
        self.validation_metrics(&o)
    }

    /// Guideline 14 of the validation run saved under key `i` at `x` in `validation/` (a
    /// worker's on the distributed path: its figures are computed here again, from its file).
    pub fn validated(&self, i: usize, x: &[f64]) -> Result<Vec<OutputMetrics>, Error> {
        let o = saved_outputs(&self.out.validation(), i, &self.inputs.plan.values(x)).ok_or_else(
            || {
                Error::Config(format!(
                    "validation run {i}: no simulation saved at its parameter values"
                ))
            },
        )?;
        self.validation_metrics(&o)
    }

    /// Guideline 14 per output of a validation run's outputs against the meters.
    fn validation_metrics(&self, o: &HourlyOutputs) -> Result<Vec<OutputMetrics>, Error> {
        let inp = &self.inputs;
        let mut m = vec![];
        for (k, name) in inp.outputs.iter().enumerate() {
            let sim = o.get(name).ok_or_else(|| {
                Error::Config(format!("validation run: no output {name:?} simulated"))
            })?;
            m.push(inp.metrics(k, name, sim)?);
        }
        Ok(m)
    }

    /// The prior modes of the calibrated parameters (the initial model).
    pub fn initial_point(&self) -> Vec<f64> {
        self.inputs.plan.priors.iter().map(|p| p.mode()).collect()
    }
}

impl Inputs {
    /// Guideline 14 of model output `sim` (without its base) of output `k` against its meter:
    /// hourly and monthly over the calibration period, and over the held-out period if any.
    pub fn metrics(&self, k: usize, name: &str, sim: &[f64]) -> Result<OutputMetrics, Error> {
        let sim = self.with_base(k, sim);
        let months = months_of_hours(sim.len());
        let monthly = |meter: &[f64]| g14_monthly(meter, &sim, &months).ok();
        Ok(OutputMetrics {
            output: name.to_string(),
            metrics: g14(&self.measured[k], &sim)?,
            monthly: monthly(&self.measured[k]),
            held_out: self.held_out.as_ref().and_then(|h| {
                Some(PeriodMetrics {
                    hourly: g14(&h.measured[k], &sim).ok()?,
                    monthly: monthly(&h.measured[k]),
                })
            }),
        })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

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
            temperature: crate::surrogate_error::ChainTemperature::ONE,
            predictive: vec![],
        }
    }

    #[test]
    fn the_estimate_then_each_fallback_under_its_own_key_then_exhausted() {
        let c = chains(2);
        let step = |n: usize| next_candidate(&c, &vec!["EnergyPlus failed".to_string(); n]);
        assert_eq!(
            step(0),
            ValidationStep::Validate(Candidate {
                rank: 0,
                key: 0,
                values: vec![0.0]
            })
        );
        // Key 1 is the initial model's.
        assert_eq!(
            step(1),
            ValidationStep::Validate(Candidate {
                rank: 1,
                key: 2,
                values: vec![1.0]
            })
        );
        assert_eq!(
            step(2),
            ValidationStep::Validate(Candidate {
                rank: 2,
                key: 3,
                values: vec![2.0]
            })
        );
        let ValidationStep::Exhausted(m) = step(3) else {
            panic!("three failures with two fallbacks must end the validation");
        };
        assert!(m.contains("at the estimate and at the next 2 draws"), "{m}");
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
    fn the_map_draw_while_it_passes_else_the_smallest_finite_limit_ratio() {
        // Hourly ratios only (no monthly figures).
        let fits = |r: &[f64]| {
            (r.iter())
                .map(|&hourly| Fit {
                    hourly,
                    monthly: None,
                })
                .collect::<Vec<_>>()
        };
        let best_simulated =
            |r: &[f64], map_ran: bool, first: usize| best_simulated(&fits(r), map_ran, first);
        // The MAP draw passes: it stays, however much nearer the centre another draw is.
        let draws = |r: &[f64], map_ran: bool| best_simulated(r, map_ran, r.len());
        assert_eq!(draws(&[0.9, 0.3, 0.5], true), Some(0));
        assert_eq!(draws(&[1.0, 0.3], true), Some(0));
        // It fails: the draw nearest inside, passing or not; the first on a tie.
        assert_eq!(draws(&[1.6, 0.7, 0.9], true), Some(1));
        assert_eq!(draws(&[2.3, 1.2, 1.1], true), Some(2));
        assert_eq!(draws(&[1.6, 0.7, 0.7], true), Some(1));
        assert_eq!(draws(&[1.6, 1.9], true), Some(0));
        // EnergyPlus could not simulate the MAP draw: the first ratio is a predictive draw's.
        assert_eq!(draws(&[0.9, 0.3], false), Some(1));
        // A run without metrics is never chosen.
        assert_eq!(draws(&[f64::INFINITY, f64::NAN, 2.0], true), Some(2));
        assert_eq!(draws(&[f64::INFINITY, f64::NAN], true), None);
        assert_eq!(draws(&[], false), None);
        // Mapped points (from index 3): the one that passes nearest inside; none passes: the
        // best draw, though a mapped point fits a little better.
        assert_eq!(
            best_simulated(&[2.8, 1.9, 2.4, 0.98, 0.6], true, 3),
            Some(4)
        );
        assert_eq!(
            best_simulated(&[2.8, 1.9, 2.4, 1.35, 0.94], true, 3),
            Some(4)
        );
        assert_eq!(best_simulated(&[2.8, 1.9, 2.4, 2.2, 1.5], true, 3), Some(1));
    }

    #[test]
    fn a_draw_passing_hourly_and_monthly_is_preferred_to_a_map_draw_missing_monthly() {
        let fit = |hourly: f64, monthly: f64| Fit {
            hourly,
            monthly: Some(monthly),
        };
        // The MAP draw passes both: it stays.
        assert_eq!(
            best_simulated(&[fit(0.56, 0.9), fit(0.3, 0.2)], true, 2),
            Some(0)
        );
        // It misses monthly (the full-year demo at 60 points: 6.1 % NMBE against 5 %): the
        // draw passing both nearest inside their limits, though another is nearer hourly.
        let demo = [
            fit(0.56, 1.22),
            fit(0.51, 0.72),
            fit(0.40, 1.1),
            fit(0.6, 0.65),
        ];
        assert_eq!(best_simulated(&demo, true, 4), Some(3));
        // No draw passes both: the MAP draw, which passes hourly.
        assert_eq!(
            best_simulated(&[fit(0.56, 1.22), fit(0.4, 1.1), fit(1.2, 0.5)], true, 3),
            Some(0)
        );
        // The MAP draw fails hourly: a draw passing both before one passing only hourly.
        assert_eq!(
            best_simulated(&[fit(1.3, 0.5), fit(0.5, 1.4), fit(0.9, 0.8)], true, 3),
            Some(2)
        );
        // EnergyPlus could not simulate the MAP draw: the first fit is a predictive draw's.
        assert_eq!(
            best_simulated(&[fit(0.5, 1.4), fit(0.9, 0.8)], false, 2),
            Some(1)
        );
        // Mapped points (from index 2): the first passing hourly where none passes both.
        assert_eq!(
            best_simulated(&[fit(1.6, 0.5), fit(1.4, 0.6), fit(0.9, 1.3)], true, 2),
            Some(2)
        );
        // The one passing both nearest inside, before one passing hourly only and before a
        // MAP draw passing hourly only.
        let mapped = [
            fit(1.6, 0.5),
            fit(1.4, 0.6),
            fit(0.5, 2.19),
            fit(0.9, 0.95),
            fit(0.7, 0.6),
        ];
        assert_eq!(best_simulated(&mapped, true, 2), Some(4));
        // None passes both: of those passing hourly, the nearest inside both (the held-out
        // 20-point demo: 0.80 / 1.80 against 0.97 / 2.19, though the first ran first).
        let demo = [
            fit(2.65, 5.95),
            fit(1.71, 3.84),
            fit(0.97, 2.19),
            fit(1.43, 3.22),
            fit(0.80, 1.80),
        ];
        assert_eq!(best_simulated(&demo, true, 2), Some(4));
        let map_hourly = [fit(0.8, 1.3), fit(1.4, 0.6), fit(0.9, 0.95)];
        assert_eq!(best_simulated(&map_hourly, true, 2), Some(2));
        let none_both = [fit(0.8, 1.3), fit(1.4, 0.6), fit(0.9, 1.2)];
        assert_eq!(best_simulated(&none_both, true, 2), Some(0));
    }

    #[test]
    fn the_monthly_limit_ratio_is_the_worst_fitted_meters_where_there_are_months() {
        let monthly = |nmbe: f64, cv_rmse: f64| {
            let mut m = metrics("heating", 0.0, 10.0);
            m.monthly = Some(bemcal_stats::metrics::G14Metrics {
                n: 12,
                nmbe,
                cv_rmse,
                ..m.metrics
            });
            m
        };
        let run = [monthly(6.0, 9.0), monthly(-2.0, 12.0), monthly(40.0, 90.0)];
        assert_eq!(monthly_limit_ratio(&run, &[true, true, false]), Some(1.2));
        assert_eq!(monthly_limit_ratio(&run[1..2], &[true]), Some(0.8));
        let hourly_only = [metrics("heating", 0.0, 10.0)];
        assert_eq!(monthly_limit_ratio(&hourly_only, &[true]), None);
        let f = Fit::of(&run[..2], &[true, true]);
        assert!(f.passes_hourly() && !f.passes_both());
        assert!(Fit::of(&hourly_only, &[true]).passes_both());
    }

    #[test]
    fn the_limit_ratio_is_the_worst_fitted_meters() {
        let m = |nmbe: f64, cv: f64| metrics("heating", nmbe, cv);
        let run = [m(5.0, 9.0), m(-2.0, 24.0), m(40.0, 90.0)];
        assert_eq!(limit_ratio(&run, &[true, true, false]), 0.8);
        assert_eq!(limit_ratio(&run, &[true, true, true]), 4.0);
        assert_eq!(limit_ratio(&run, &[false; 3]), f64::INFINITY);
    }

    fn metrics(output: &str, nmbe: f64, cv_rmse: f64) -> OutputMetrics {
        OutputMetrics {
            output: output.into(),
            metrics: bemcal_stats::metrics::G14Metrics {
                n: 8760,
                mean_measured: 1.0,
                nmbe,
                cv_rmse,
                pass: nmbe.abs() <= 10.0 && cv_rmse <= 30.0,
            },
            monthly: None,
            held_out: None,
        }
    }

    fn choice(chosen: &str) -> EstimateChoice {
        EstimateChoice {
            chosen: chosen.into(),
            candidates: [
                ("calibrated", 1.6),
                ("predictive_00", 0.9),
                ("predictive_01", 0.7),
            ]
            .iter()
            .map(|(l, r)| SimulatedFit {
                label: l.to_string(),
                limit_ratio: Some(*r),
                monthly_limit_ratio: None,
            })
            .collect(),
            mapping: vec![],
            outside_interval: vec![],
        }
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
    fn a_mapped_point_that_fits_best_is_described_as_no_posterior_draw() {
        let mut c = choice("mapped_02");
        c.candidates[1].limit_ratio = Some(1.9);
        c.candidates[2].limit_ratio = Some(2.1);
        c.candidates.push(SimulatedFit {
            label: "mapped_01".into(),
            limit_ratio: Some(1.3),
            monthly_limit_ratio: None,
        });
        c.candidates.push(SimulatedFit {
            label: "mapped_02".into(),
            limit_ratio: Some(0.85),
            monthly_limit_ratio: None,
        });
        c.mapping = vec![crate::mapping::MappingStep::new(
            ("predictive_00", &[1.0]),
            vec![2.0],
            &[0.5, 1.0],
            1,
        )];
        c.outside_interval = vec!["shgc".into()];
        let text = c.describe(None);
        assert!(
            text.contains("at every one of the 3 posterior draws it simulated (the best at 1.60")
                && text.contains("the MAP draw at 1.60")
                && text.contains("from predictive_00")
                && text.contains("found mapped_02, 1.00 of the way")
                && text.contains("worst meter is at 0.85 of the limits")
                && text.contains("1 parameter(s) lie outside the posterior's 90 % interval (shgc)"),
            "{text}"
        );
        // The MAP draw passes hourly and misses monthly, as every draw does: the mapped point
        // that passes both.
        for (label, hourly, monthly) in [
            ("calibrated", 0.8, 1.3),
            ("mapped_01", 0.97, 2.19),
            ("mapped_02", 0.85, 0.9),
        ] {
            let f = c.candidates.iter_mut().find(|f| f.label == label).unwrap();
            (f.limit_ratio, f.monthly_limit_ratio) = (Some(hourly), Some(monthly));
        }
        let text = c.describe(None);
        assert!(
            text.contains(
                "passes Guideline 14 hourly at some of the 3 posterior draws it simulated and \
                 misses its monthly criteria at each of those (the nearest inside the monthly \
                 limits at 1.30; the MAP draw at 0.80 of the hourly ones)"
            ) && text.contains(
                "worst meter is at 0.85 of the hourly limits and 0.90 of the monthly ones"
            ),
            "{text}"
        );
    }
}
