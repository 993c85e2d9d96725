//! What the likelihood's model-form discrepancy (`mcmc.discrepancy = "hour_day_season"`)
//! carries at the MAP draw, per meter: its size against the meter, the hourly error's, and
//! the cells where it is largest (`summary.json` `discrepancy_carried`,
//! `discrepancy_cells.csv`).

use bemcal_stats::likelihood::cells::{CellSplit, Cells, SEASONS};
use serde::{Deserialize, Serialize};

use crate::error::{write_atomic, Error};
use crate::posterior::Posterior;

/// The seasons of the cells, in their order ([`Cells::hour_kind_season`]).
pub const SEASON_NAMES: [&str; SEASONS] = ["Dec-Feb", "Mar-May", "Jun-Aug", "Sep-Nov"];

/// How many cells [`Carried::largest`] names.
pub const LARGEST: usize = 3;

/// One calendar cell's discrepancy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct CellEffect {
    /// Hour of day (0-23, hour beginning).
    pub hour: usize,
    /// Whether the cell's days are off days.
    pub off_day: bool,
    /// Meteorological season (`Dec-Feb`, ...).
    pub season: String,
    /// The discrepancy, kWh per hour: the meter above the model where positive.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub kwh: f64,
}

/// What the discrepancy carries for one meter at the MAP draw.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Carried {
    /// The meter (the calibration's output).
    pub meter: String,
    /// Root mean square of the discrepancy over the observed hours, kWh per hour.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub rms_kwh: f64,
    /// Its mean over the observed hours (the level the model misses), kWh per hour.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub mean_kwh: f64,
    /// The RMS against the meter's mean (the model's share of it), %.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub rms_percent_of_mean: f64,
    /// The hourly error's standard deviation left within cells, kWh.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub within_sd_kwh: f64,
    /// The cells where the discrepancy is largest, largest first.
    pub largest: Vec<CellEffect>,
}

impl Carried {
    /// One line for the log and the report.
    pub fn finding(&self) -> String {
        let cells: Vec<String> = self
            .largest
            .iter()
            .map(|c| {
                format!(
                    "{:02}:00 {} {} {:+.2}",
                    c.hour,
                    if c.off_day {
                        "off days"
                    } else {
                        "working days"
                    },
                    c.season,
                    c.kwh
                )
            })
            .collect();
        format!(
            "{}: the model-form term carries {:.2} kWh/h RMS ({:.1} % of the meter's mean, level \
             {:+.2} kWh/h) beside an hourly error of {:.2} kWh; largest: {}",
            self.meter,
            self.rms_kwh,
            self.rms_percent_of_mean,
            self.mean_kwh,
            self.within_sd_kwh,
            cells.join(", ")
        )
    }
}

/// What the discrepancy carries per fitted meter at `predicted` (the surrogate at the MAP
/// draw, `hours x outputs`), and the per-cell table; `None` without the term.
pub fn carried(
    post: &Posterior<'_>,
    outputs: &[String],
    predicted: &[f32],
) -> Option<(Vec<Carried>, Vec<Vec<f64>>)> {
    let cells = post.cells?;
    let splits = post.likelihood.cell_splits(predicted, cells, post.ar1);
    let observed = post.likelihood.n_observed();
    let mut out = vec![];
    let mut table = vec![];
    for (k, s) in splits.iter().enumerate() {
        if observed[k] == 0 {
            continue;
        }
        let meter_mean = meter_mean(post, predicted, k, s);
        let d = s.discrepancy();
        out.push(meter_carried(&outputs[k], s, &d, meter_mean));
        table.push(d);
    }
    Some((out, table))
}

/// The mean of output `k`'s observations: the model's mean plus the residuals'.
fn meter_mean(post: &Posterior<'_>, predicted: &[f32], k: usize, s: &CellSplit) -> f64 {
    let n_out = post.likelihood.n_outputs();
    let residual_sum: f64 = s
        .mean
        .iter()
        .zip(&s.count)
        .map(|(m, &n)| m * n as f64)
        .sum();
    let mask = post.likelihood.observed_mask();
    let model_sum: f64 = (0..post.likelihood.n_hours())
        .filter(|t| mask[t * n_out + k])
        .map(|t| f64::from(predicted[t * n_out + k]))
        .sum();
    (model_sum + residual_sum) / s.hours.max(1) as f64
}

fn meter_carried(meter: &str, s: &CellSplit, d: &[f64], meter_mean: f64) -> Carried {
    let n = s.hours.max(1) as f64;
    let (sum, sq) = d.iter().zip(&s.count).fold((0.0, 0.0), |(a, b), (v, &c)| {
        (a + v * c as f64, b + v * v * c as f64)
    });
    let rms = (sq / n).sqrt();
    let mut order: Vec<usize> = (0..d.len()).filter(|&c| s.count[c] > 0).collect();
    order.sort_by(|&a, &b| d[b].abs().total_cmp(&d[a].abs()));
    Carried {
        meter: meter.to_string(),
        rms_kwh: rms,
        mean_kwh: sum / n,
        rms_percent_of_mean: 100.0 * rms / meter_mean.abs().max(1e-12),
        within_sd_kwh: s.within_variance().sqrt(),
        largest: order
            .iter()
            .take(LARGEST)
            .map(|&c| cell_effect(c, d[c]))
            .collect(),
    }
}

/// Cell `c` of [`Cells::hour_kind_season`] with its discrepancy.
fn cell_effect(c: usize, kwh: f64) -> CellEffect {
    CellEffect {
        hour: c % 24,
        off_day: (c / 24) % 2 == 1,
        season: SEASON_NAMES[c / 48].to_string(),
        kwh,
    }
}

/// `discrepancy_cells.csv`: one row per cell (hour, day kind, season), one column per fitted
/// meter, kWh per hour.
pub fn write_cells_csv(
    path: &std::path::Path,
    meters: &[Carried],
    table: &[Vec<f64>],
    cells: &Cells,
) -> Result<(), Error> {
    let mut s = String::from("hour,day_kind,season");
    for m in meters {
        s.push(',');
        s.push_str(&m.meter);
    }
    s.push('\n');
    for c in 0..cells.n_cells() {
        let e = cell_effect(c, 0.0);
        let kind = if e.off_day { "off" } else { "working" };
        s.push_str(&format!("{},{kind},{}", e.hour, e.season));
        for col in table {
            s.push_str(&format!(",{:.6}", col[c]));
        }
        s.push('\n');
    }
    write_atomic(path, s.as_bytes())
}
