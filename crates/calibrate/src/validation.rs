//! Stage 7, validation: EnergyPlus at the estimate against the meters (ASHRAE Guideline 14);
//! with `estimate = "best_simulated"`, which of the draws it simulated becomes the estimate
//! ([`crate::metrics::best_simulated`]); and the rule for when it can simulate none of them: the next-best
//! posterior draws, in order, each under its own key in `validation/`.

use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::metrics::{g14, g14_monthly};
use bemcal_weather::period::months_of_hours;

use crate::calibration::Calibration;
use crate::chains::ChainSummary;
use crate::design::{saved_outputs, simulate_point};
use crate::error::Error;
use crate::inputs::Inputs;
use crate::keys::candidate_key;
use crate::metrics::{OutputMetrics, PeriodMetrics};
use crate::output::write_outputs_csv;

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
    use crate::estimate::tests::choice;
    use crate::estimate::EstimateChoice;
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
            temperature: crate::posterior::ChainTemperature::ONE,
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
}
