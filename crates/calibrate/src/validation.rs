//! Stage 7, validation: EnergyPlus at the estimate against the meters (ASHRAE Guideline 14);
//! with `estimate = "best_simulated"`, which of the draws it simulated becomes the estimate
//! ([`crate::metrics::best_simulated`]); and the rule for when it can simulate none of them: the next-best
//! posterior draws, in order, each under its own key in `validation/`.

use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::metrics::{g14, g14_monthly};
use bemcal_weather::period::months_of_hours;

use crate::calibration::Calibration;
use crate::chain_summary::ChainSummary;
use crate::design::{saved_outputs, simulate_point};
use crate::error::Error;
use crate::inputs::Inputs;
use crate::keys::candidate_key;
use crate::metrics::{OutputMetrics, PeriodMetrics, Resolution};
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
        if let Some(b) = &self.bills[k] {
            // The bills are the meter's own resolution: its figures, monthly too.
            let on_bills = b.metrics(&sim, false).ok_or_else(|| {
                Error::Config(format!(
                    "{name}: Guideline 14 on bills needs two bills in the calibration period, it has {}",
                    b.calibration_bills()
                ))
            })?;
            return Ok(OutputMetrics {
                output: name.to_string(),
                resolution: Resolution::Bills,
                metrics: on_bills,
                monthly: Some(on_bills),
                held_out: b.metrics(&sim, true).map(|m| PeriodMetrics {
                    hourly: m,
                    monthly: Some(m),
                }),
                demand: b.demand(&sim),
            });
        }
        let months = months_of_hours(sim.len());
        let monthly = |meter: &[f64]| g14_monthly(meter, &sim, &months).ok();
        Ok(OutputMetrics {
            output: name.to_string(),
            resolution: Resolution::Hourly,
            metrics: g14(&self.measured[k], &sim)?,
            monthly: monthly(&self.measured[k]),
            held_out: self.held_out.as_ref().and_then(|h| {
                Some(PeriodMetrics {
                    hourly: g14(&h.measured[k], &sim).ok()?,
                    monthly: monthly(&h.measured[k]),
                })
            }),
            demand: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chain_summary::tests::chains;

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
}
