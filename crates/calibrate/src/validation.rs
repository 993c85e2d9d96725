//! Stage 7, validation: EnergyPlus at the estimate against the meters (ASHRAE Guideline 14),
//! and the rule for when it cannot simulate the estimate: the next-best posterior draws, in
//! order, each under its own key in `validation/`.

use bemcal_stats::metrics::{g14, g14_monthly};
use bemcal_weather::period::months_of_hours;

use crate::design::simulate_point;
use crate::summary::write_outputs_csv;
use crate::summary::PeriodMetrics;
use crate::{Calibration, ChainSummary, Error, Inputs, OutputMetrics};

/// Draws tried, in order, when EnergyPlus fails at the estimate.
pub const FALLBACKS: usize = 3;

/// Key of the initial model (the prior modes) in `validation/`.
pub const INITIAL_KEY: usize = 1;

/// The key in `validation/` of the `rank`-th candidate: 0 the estimate, then `rank + 1` (1 is
/// the initial model).
pub fn candidate_key(rank: usize) -> usize {
    if rank == 0 {
        0
    } else {
        rank + 1
    }
}

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
        let mut m = vec![];
        for (k, name) in inp.outputs.iter().enumerate() {
            m.push(inp.metrics(k, name, o.get(name).expect("model output"))?);
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
}
