//! Bases: loads in a meter that the model does not have (`[[bases]]`: a data center, labs,
//! process loads), taken as an hourly series from a sub-meter or as a constant. The likelihood
//! compares the surrogate with the meter less its base ([`Inputs::model_share`]); every
//! comparison of a model output with a meter adds the base back ([`Inputs::with_base`]).

use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;
use crate::error::{write_atomic, Error};
use crate::inputs::Inputs;
use crate::output::timestamps;
use crate::project::Project;

/// A base load in `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BaseReport {
    /// The calibrated output (and its meter) the base is part of.
    pub output: String,
    /// `submeter data_center` or `constant 102 kWh/h`.
    pub source: String,
    /// Over the hours it is known, kWh.
    pub annual_kwh: f64,
    /// Hours the meter is compared without it (a sub-meter gap): those hours count as missing.
    pub missing_hours: usize,
}

impl Inputs {
    /// The part of meter `k` the model simulates: the meter less its base (NaN where either is
    /// missing). The likelihood compares the surrogate with this.
    pub fn model_share(&self, k: usize) -> Vec<f64> {
        self.measured[k]
            .iter()
            .zip(&self.bases[k])
            .map(|(m, b)| m - b)
            .collect()
    }

    /// The likelihood's observations (the reference's y, Eq. 5), row-major `hours x outputs`:
    /// each fitted meter's model share; NaN where it is missing or held out, and at every hour
    /// of a meter with `fit = false` (the likelihood leaves it out).
    pub fn likelihood_observations(&self) -> Vec<f64> {
        let (n_h, n_out) = (self.features.len(), self.outputs.len());
        let mut observed = vec![f64::NAN; n_h * n_out];
        for k in (0..n_out).filter(|&k| self.fitted[k]) {
            for (h, v) in self.model_share(k).iter().enumerate() {
                observed[h * n_out + k] = *v;
            }
        }
        observed
    }

    /// True when output `k` has a base (`[[bases]]`).
    pub fn has_base(&self, k: usize) -> bool {
        self.base_reports
            .iter()
            .any(|b| b.output == self.outputs[k])
    }

    /// A model output `sim` of output `k` with its base added: what the meter is compared with.
    pub fn with_base(&self, k: usize, sim: &[f64]) -> Vec<f64> {
        sim.iter().zip(&self.bases[k]).map(|(s, b)| s + b).collect()
    }
}

/// The hourly bases of `outputs` from the project's `[[bases]]` and the meters.
pub(crate) fn bases_of(
    project: &Project,
    outputs: &[String],
    data: &bemcal_precal::meters::MeterData,
) -> Result<(Vec<Vec<f64>>, Vec<BaseReport>), Error> {
    let hours = data.series.first().map_or(0, |s| s.values.len());
    let mut bases = vec![vec![0.0; hours]; outputs.len()];
    let mut reports = vec![];
    for b in &project.bases {
        let k = outputs.iter().position(|o| o == &b.output).ok_or_else(|| {
            Error::Config(format!(
                "[[bases]] output = \"{}\": not a calibrated output (outputs: {outputs:?})",
                b.output
            ))
        })?;
        let (series, source): (Vec<f64>, String) = match (&b.submeter, b.kwh_per_hour) {
            (Some(name), _) => {
                let s = data.submeter(name).ok_or_else(|| {
                    Error::Config(format!(
                        "[[bases]] submeter = \"{name}\": the meters have no such sub-meter (they have: {})",
                        data.series.iter().map(|s| s.role.name().to_string()).collect::<Vec<_>>().join(", ")
                    ))
                })?;
                (s.values.clone(), format!("submeter {name}"))
            }
            (None, Some(v)) => (vec![v; hours], format!("constant {v} kWh/h")),
            (None, None) => unreachable!("validated"),
        };
        for (acc, v) in bases[k].iter_mut().zip(&series) {
            *acc += v;
        }
        reports.push(BaseReport {
            output: b.output.clone(),
            source,
            annual_kwh: series.iter().filter(|v| v.is_finite()).sum(),
            missing_hours: series.iter().filter(|v| !v.is_finite()).count(),
        });
    }
    Ok((bases, reports))
}

/// `validation/bases.csv`: the hourly bases of the outputs that have one (`[[bases]]`), which
/// the report adds to the EnergyPlus runs before drawing them against the meters.
pub(crate) fn write_bases_csv(cal: &Calibration) -> Result<(), Error> {
    let inp = &cal.inputs;
    let with: Vec<usize> = (0..inp.outputs.len())
        .filter(|&k| inp.has_base(k))
        .collect();
    if with.is_empty() {
        return Ok(());
    }
    let mut s = String::from("timestamp");
    for &k in &with {
        s.push_str(&format!(",{}", inp.outputs[k]));
    }
    s.push('\n');
    for (t, ts) in timestamps(inp.year, inp.bases[0].len()) {
        s.push_str(&ts);
        for &k in &with {
            let b = inp.bases[k][t];
            s.push_str(&if b.is_finite() {
                format!(",{b:.6}")
            } else {
                ",".into()
            });
        }
        s.push('\n');
    }
    write_atomic(&cal.out.bases_csv(), s.as_bytes())
}
