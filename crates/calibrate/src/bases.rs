//! Bases: loads in a meter that the model does not have (`[[bases]]`: a data center, labs,
//! process loads), taken as an hourly series from a sub-meter or as a constant. The likelihood
//! compares the surrogate with the meter less its base (`Inputs::model_share`); every
//! comparison of a model output with a meter adds the base back (`Inputs::with_base`).

use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::project::Project;

/// A base load in `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct BaseReport {
    /// The calibrated output (and its meter) the base is part of.
    pub output: String,
    /// `submeter data_center` or `constant 102 kWh/h`.
    pub source: String,
    /// Over the hours it is known, kWh.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub annual_kwh: f64,
    /// Hours the meter is compared without it (a sub-meter gap): those hours count as missing.
    pub missing_hours: usize,
}

/// The hourly bases of `outputs` from the project's `[[bases]]` and the meters.
pub(crate) fn bases_of(
    project: &Project,
    outputs: &[String],
    data: &bemcal_precal::meters::MeterData,
) -> Result<(Vec<Vec<f64>>, Vec<BaseReport>), Error> {
    // The grid's hours (every hour of the year for a project of bills alone).
    let hours = data
        .series
        .first()
        .map_or(bemcal_precal::meters::HOURS, |s| s.values.len());
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
