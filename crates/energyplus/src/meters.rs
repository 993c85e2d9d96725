//! Hourly meter output: which EnergyPlus meters make up each calibration output, and reading
//! EnergyPlus's own meter CSV into kWh series.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::{io_err, Error};

/// Joules per kWh: EnergyPlus meters report J per reporting interval.
pub const J_PER_KWH: f64 = 3.6e6;

/// A calibration output (e.g. `heating_kwh`) as the sum of EnergyPlus meters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct OutputSpec {
    /// The output's name (`heating_kwh`).
    pub name: String,
    /// The EnergyPlus meters summed into it (`DistrictHeatingWater:Facility`).
    pub meters: Vec<String>,
}

impl OutputSpec {
    /// An output from a name and meter names.
    pub fn new(name: &str, meters: &[&str]) -> OutputSpec {
        OutputSpec {
            name: name.into(),
            meters: meters.iter().map(|m| m.to_string()).collect(),
        }
    }
}

/// Hourly outputs of one simulation, kWh per hour, in file order (hour-beginning, 8,760 rows).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HourlyOutputs {
    /// The outputs' names, in the order of `series`.
    pub names: Vec<String>,
    /// `series[k][t]`: output k at hour t.
    pub series: Vec<Vec<f64>>,
}

impl HourlyOutputs {
    /// Number of hours.
    pub fn hours(&self) -> usize {
        self.series.first().map_or(0, Vec::len)
    }

    /// The series of an output by name.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.series[i].as_slice())
    }

    /// Annual total of each output, kWh.
    pub fn totals(&self) -> Vec<(String, f64)> {
        self.names
            .iter()
            .zip(&self.series)
            .map(|(n, s)| (n.clone(), s.iter().sum()))
            .collect()
    }
}

/// Reads `eplusmtr.csv` (written by EnergyPlus with `OutputControl:Files` CSV = Yes) and sums
/// meters into outputs. A meter absent from the file counts as zero (EnergyPlus omits meters with
/// no connected equipment) unless no meter of the output exists, which is an error.
pub fn read_meter_csv(path: &Path, outputs: &[OutputSpec]) -> Result<HourlyOutputs, Error> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    let mut lines = text.lines();
    let header = lines.next().ok_or_else(|| Error::Input {
        path: path.into(),
        line: 1,
        message: "empty meter file".into(),
    })?;
    // Columns look like "Electricity:Facility [J](Hourly)".
    let mut columns: BTreeMap<String, usize> = BTreeMap::new();
    for (i, h) in header.split(',').enumerate().skip(1) {
        if !h.contains("(Hourly)") {
            continue;
        }
        let name = h.split(" [").next().unwrap_or(h).trim().to_string();
        columns.insert(name.to_ascii_lowercase(), i);
    }
    let mut idx: Vec<Vec<usize>> = Vec::new();
    for o in outputs {
        let found: Vec<usize> = o
            .meters
            .iter()
            .filter_map(|m| columns.get(&m.to_ascii_lowercase()).copied())
            .collect();
        if found.is_empty() {
            return Err(Error::Input {
                path: path.into(),
                line: 1,
                message: format!(
                    "output {}: none of the meters {:?} is in the file (hourly meters present: {:?})",
                    o.name,
                    o.meters,
                    columns.keys().collect::<Vec<_>>()
                ),
            });
        }
        idx.push(found);
    }
    let mut series = vec![Vec::with_capacity(8760); outputs.len()];
    for (ln, line) in lines.enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        // Only hourly rows: sizing-period and summary rows have other stamps; hourly rows of the
        // run period have every hourly column filled.
        let first = idx.first().and_then(|c| c.first()).copied().unwrap_or(1);
        if f.get(first).is_none_or(|v| v.trim().is_empty()) {
            continue;
        }
        for (k, cols) in idx.iter().enumerate() {
            let mut sum = 0.0;
            for &c in cols {
                let v = f.get(c).map(|s| s.trim()).unwrap_or("");
                let x: f64 = v.parse().map_err(|_| Error::Input {
                    path: path.into(),
                    line: ln + 2,
                    message: format!("column {} value '{v}' is not a number", c + 1),
                })?;
                sum += x / J_PER_KWH;
            }
            series[k].push(sum);
        }
    }
    Ok(HourlyOutputs {
        names: outputs.iter().map(|o| o.name.clone()).collect(),
        series,
    })
}
