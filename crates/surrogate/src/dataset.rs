//! Training sets for the surrogate: design points x hours of the year, written as `.npy` arrays
//! plus a `dataset.json` description that the Python trainer (`python/bemcal_train`) reads.
//!
//! # On-disk format (a directory)
//!
//! | file            | dtype | shape                               | content                                   |
//! |-----------------|-------|-------------------------------------|-------------------------------------------|
//! | `params.npy`    | f64   | `[n_points, n_params]`              | raw parameter values of each design point |
//! | `weather.npy`   | f64   | `[n_hours, 5]`                      | raw hourly weather, [`WEATHER_FEATURES`]  |
//! | `outputs.npy`   | f64   | `[n_points, n_hours, n_outputs]`    | simulated meters, kWh per hour            |
//! | `dataset.json`  |       |                                     | [`DatasetMeta`]                           |
//!
//! The set is stored compactly: parameters once per design point and the weather once per year,
//! not the per-hour repeated input matrix. The *logical* input of the surrogate at
//! `(point, hour)` is
//!
//! ```text
//! [ (p - min) / (max - min) for each parameter,          n_params values in [0, 1]
//!   (w(hour) - mean_w) / std_w for each weather feature, 5 values (mean/std fitted by the trainer)
//!   optional time-of-day features of hour ]              0, 2 or 4 values (see the trainer)
//! ```
//!
//! and a sample is the window of the three inputs at hours `t-2, t-1, t` (lookback 3, hours
//! before 0 repeat hour 0) with target `outputs[point, t, :]`, as in the reference (Jiang et al.
//! 2024, section 2.3.2: parameters and weather in, hourly meters out).
//!
//! The held-out split is **by design point** (seeded), never by hour, so the held-out error measures
//! generalisation to unseen parameter vectors, which is what calibration needs.

use std::path::{Path, PathBuf};

use bemcal_weather::HourlyFeatures;
use ndarray::{Array2, Array3};
use ndarray_npy::{read_npy, write_npy};
use serde::{Deserialize, Serialize};

/// Format version written to `dataset.json`; the trainer refuses other versions.
pub const DATASET_FORMAT_VERSION: u32 = 1;

/// Names of the weather columns of `weather.npy` (the reference's five inputs).
pub const WEATHER_FEATURES: [&str; 5] = HourlyFeatures::NAMES;

/// Units of [`WEATHER_FEATURES`], same order.
pub const WEATHER_UNITS: [&str; 5] = [
    "C",
    "%",
    "m/s",
    "Wh/m2",
    "code 0=weekday,1=weekend,2=holiday",
];

/// Errors building, writing or reading a training set.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// Shapes or values are inconsistent.
    #[error("invalid training set: {0}")]
    Invalid(String),
    /// A file could not be read or written.
    #[error("{path}: {}", bemcal_excerpt::shorten(.message))]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

fn invalid(msg: impl Into<String>) -> DatasetError {
    DatasetError::Invalid(msg.into())
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> DatasetError {
    DatasetError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// One model parameter as the surrogate sees it: its name, the normalisation bounds (the prior's
/// minimum and maximum: values are scaled to [0, 1] by them) and the prior mode (the default used
/// by `bemcal predict` for parameters that are not set).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamSpec {
    /// Parameter name, unique.
    pub name: String,
    /// Prior minimum (maps to 0).
    pub min: f64,
    /// Prior maximum (maps to 1).
    pub max: f64,
    /// Prior mode (a triangular prior's peak), within `[min, max]`.
    pub mode: f64,
}

impl ParamSpec {
    /// A parameter with bounds and mode.
    pub fn new(name: impl Into<String>, min: f64, max: f64, mode: f64) -> ParamSpec {
        ParamSpec {
            name: name.into(),
            min,
            max,
            mode,
        }
    }

    /// `(value - min) / (max - min)`.
    pub fn normalise(&self, value: f64) -> f64 {
        (value - self.min) / (self.max - self.min)
    }
}

/// The held-out split: indices of design points (not hours).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Split {
    /// Seed of the shuffle that produced the split.
    pub seed: u64,
    /// Design points used for fitting.
    pub train: Vec<usize>,
    /// Design points held out for early stopping and the reported error (sigma_eta).
    pub held_out: Vec<usize>,
}

impl Split {
    /// Seeded split of `n_points` design points with `held_out_fraction` of them (at least one,
    /// and at least one left for training) held out. Pure; deterministic in `seed`.
    pub fn by_design_point(
        n_points: usize,
        held_out_fraction: f64,
        seed: u64,
    ) -> Result<Split, DatasetError> {
        if n_points < 2 {
            return Err(invalid(format!(
                "need at least 2 design points to hold one out, have {n_points}"
            )));
        }
        if !(0.0..1.0).contains(&held_out_fraction) {
            return Err(invalid(format!(
                "held-out fraction {held_out_fraction} must be in [0, 1)"
            )));
        }
        let n_held =
            ((n_points as f64 * held_out_fraction).round() as usize).clamp(1, n_points - 1);
        let mut idx: Vec<usize> = (0..n_points).collect();
        // Fisher-Yates with splitmix64: no dependency, stable across platforms and versions.
        let mut state = seed;
        for i in (1..n_points).rev() {
            let j = (splitmix64(&mut state) % (i as u64 + 1)) as usize;
            idx.swap(i, j);
        }
        let mut held_out = idx[..n_held].to_vec();
        let mut train = idx[n_held..].to_vec();
        held_out.sort_unstable();
        train.sort_unstable();
        Ok(Split {
            seed,
            train,
            held_out,
        })
    }

    /// The split of a training set that grows by appended points (surrogate refinement): the
    /// first `n_base` points (the Latin hypercube) split as [`Split::by_design_point`], each
    /// later point `i` held out by its own seeded coin (probability `held_out_fraction`). Nested:
    /// a point's side never changes as points are added, so a surrogate warm-started from an
    /// earlier round's weights has never trained on a point now held out (its held-out error,
    /// sigma_eta, stays out-of-sample). Pure; deterministic in `seed`.
    pub fn nested(
        n_base: usize,
        n_points: usize,
        held_out_fraction: f64,
        seed: u64,
    ) -> Result<Split, DatasetError> {
        if n_base > n_points {
            return Err(invalid(format!(
                "{n_base} base points but only {n_points} in all"
            )));
        }
        let mut split = Split::by_design_point(n_base, held_out_fraction, seed)?;
        for i in n_base..n_points {
            let mut state = seed ^ (i as u64).wrapping_mul(0xD1B5_4A32_D192_ED03);
            let u = (splitmix64(&mut state) >> 11) as f64 / (1u64 << 53) as f64;
            if u < held_out_fraction {
                split.held_out.push(i);
            } else {
                split.train.push(i);
            }
        }
        Ok(split)
    }
}

fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `dataset.json`: everything but the arrays.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetMeta {
    /// [`DATASET_FORMAT_VERSION`].
    pub format_version: u32,
    /// Number of design points.
    pub n_points: usize,
    /// Number of hours (8,760 for a year).
    pub n_hours: usize,
    /// Parameters in column order of `params.npy`.
    pub params: Vec<ParamSpec>,
    /// Weather columns of `weather.npy`.
    pub weather_features: Vec<String>,
    /// Units of `weather_features`.
    pub weather_units: Vec<String>,
    /// Output (meter) names in the last axis of `outputs.npy`.
    pub output_names: Vec<String>,
    /// Unit of every output.
    pub output_unit: String,
    /// Held-out split by design point.
    pub split: Split,
    /// The files and the logical input layout, for humans.
    pub layout: String,
}

/// A training set in memory: design points, the year's weather and the simulated outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainingSet {
    /// Parameter specs (names, bounds, modes), in column order.
    pub params: Vec<ParamSpec>,
    /// Raw parameter values, `[n_points, n_params]`.
    pub points: Array2<f64>,
    /// Raw hourly weather, `[n_hours, 5]` in [`WEATHER_FEATURES`] order.
    pub weather: Array2<f64>,
    /// Output names.
    pub output_names: Vec<String>,
    /// Outputs in kWh, `[n_points, n_hours, n_outputs]`.
    pub outputs: Array3<f64>,
    /// Held-out split by design point.
    pub split: Split,
}

/// Default fraction of design points held out (20 points -> 4 held out).
pub const DEFAULT_HELD_OUT_FRACTION: f64 = 0.2;

impl TrainingSet {
    /// Builds and validates a training set. `points` is `[n_points, n_params]` (raw values, in
    /// `params` order), `outputs` is `[n_points, n_hours, n_outputs]` in kWh with `n_hours` equal to
    /// `weather.len()`. The held-out split takes [`DEFAULT_HELD_OUT_FRACTION`] of the points,
    /// seeded by `split_seed`.
    pub fn new(
        params: Vec<ParamSpec>,
        points: Array2<f64>,
        weather: &HourlyFeatures,
        output_names: Vec<String>,
        outputs: Array3<f64>,
        split_seed: u64,
    ) -> Result<TrainingSet, DatasetError> {
        let n_points = points.nrows();
        let split = Split::by_design_point(n_points, DEFAULT_HELD_OUT_FRACTION, split_seed)?;
        let set = TrainingSet {
            params,
            points,
            weather: weather_matrix(weather)?,
            output_names,
            outputs,
            split,
        };
        set.validate()?;
        Ok(set)
    }

    /// Replaces the split (e.g. another fraction); validated.
    pub fn with_split(mut self, split: Split) -> Result<TrainingSet, DatasetError> {
        self.split = split;
        self.validate()?;
        Ok(self)
    }

    /// Number of design points.
    pub fn n_points(&self) -> usize {
        self.points.nrows()
    }

    /// Number of hours.
    pub fn n_hours(&self) -> usize {
        self.weather.nrows()
    }

    /// Checks every shape, name and value; the error says which.
    pub fn validate(&self) -> Result<(), DatasetError> {
        let (n_points, n_params) = self.points.dim();
        if n_points == 0 {
            return Err(invalid("no design points"));
        }
        if n_params != self.params.len() {
            return Err(invalid(format!(
                "parameter matrix has {n_params} columns but {} parameters are named",
                self.params.len()
            )));
        }
        let mut names = std::collections::HashSet::new();
        for p in &self.params {
            if !names.insert(p.name.as_str()) {
                return Err(invalid(format!("parameter '{}' is named twice", p.name)));
            }
            if !(p.min.is_finite() && p.max.is_finite() && p.max > p.min) {
                return Err(invalid(format!(
                    "parameter '{}': bounds [{}, {}] must be finite with max > min",
                    p.name, p.min, p.max
                )));
            }
            if !(p.min..=p.max).contains(&p.mode) {
                return Err(invalid(format!(
                    "parameter '{}': mode {} outside [{}, {}]",
                    p.name, p.mode, p.min, p.max
                )));
            }
        }
        if let Some(((i, j), v)) = self.points.indexed_iter().find(|(_, v)| !v.is_finite()) {
            return Err(invalid(format!(
                "design point {i}, parameter '{}' is {v}",
                self.params[j].name
            )));
        }
        let n_hours = self.weather.nrows();
        if self.weather.ncols() != WEATHER_FEATURES.len() {
            return Err(invalid(format!(
                "weather has {} columns, expected {}",
                self.weather.ncols(),
                WEATHER_FEATURES.len()
            )));
        }
        if n_hours < 3 {
            return Err(invalid(format!(
                "{n_hours} hours; need at least 3 (lookback 3)"
            )));
        }
        if let Some(((t, j), v)) = self.weather.indexed_iter().find(|(_, v)| !v.is_finite()) {
            return Err(invalid(format!(
                "weather hour {t}, {} is {v}",
                WEATHER_FEATURES[j]
            )));
        }
        if self.output_names.is_empty() {
            return Err(invalid("no outputs named"));
        }
        let (op, oh, oo) = self.outputs.dim();
        if (op, oh, oo) != (n_points, n_hours, self.output_names.len()) {
            return Err(invalid(format!(
                "outputs have shape [{op}, {oh}, {oo}], expected [n_points={n_points}, n_hours={n_hours}, n_outputs={}]",
                self.output_names.len()
            )));
        }
        if let Some(((i, t, k), v)) = self.outputs.indexed_iter().find(|(_, v)| !v.is_finite()) {
            return Err(invalid(format!(
                "output '{}' of design point {i} at hour {t} is {v}",
                self.output_names[k]
            )));
        }
        let mut all: Vec<usize> = self
            .split
            .train
            .iter()
            .chain(&self.split.held_out)
            .copied()
            .collect();
        all.sort_unstable();
        if all != (0..n_points).collect::<Vec<_>>() {
            return Err(invalid(
                "split must list every design point exactly once (train + held_out)",
            ));
        }
        if self.split.train.is_empty() || self.split.held_out.is_empty() {
            return Err(invalid(
                "split needs at least one training and one held-out point",
            ));
        }
        Ok(())
    }

    /// The `dataset.json` content.
    pub fn meta(&self) -> DatasetMeta {
        DatasetMeta {
            format_version: DATASET_FORMAT_VERSION,
            n_points: self.n_points(),
            n_hours: self.n_hours(),
            params: self.params.clone(),
            weather_features: WEATHER_FEATURES.iter().map(|s| s.to_string()).collect(),
            weather_units: WEATHER_UNITS.iter().map(|s| s.to_string()).collect(),
            output_names: self.output_names.clone(),
            output_unit: "kWh".into(),
            split: self.split.clone(),
            layout: "params.npy f64 [n_points, n_params] raw values; weather.npy f64 [n_hours, 5] raw; \
                     outputs.npy f64 [n_points, n_hours, n_outputs] kWh. Logical input at (point, hour) = \
                     [(p - min)/(max - min), (w(hour) - mean)/std, optional time-of-day features(hour)]; \
                     a sample is the window of hours t-2, t-1, t (hours < 0 repeat hour 0)."
                .into(),
        }
    }

    /// Writes the set into `dir` (created if needed): `params.npy`, `weather.npy`,
    /// `outputs.npy`, `dataset.json`.
    pub fn write(&self, dir: impl AsRef<Path>) -> Result<(), DatasetError> {
        self.validate()?;
        let dir = dir.as_ref();
        std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
        let p = dir.join("params.npy");
        write_npy(&p, &self.points).map_err(|e| io_err(&p, e))?;
        let p = dir.join("weather.npy");
        write_npy(&p, &self.weather).map_err(|e| io_err(&p, e))?;
        let p = dir.join("outputs.npy");
        write_npy(&p, &self.outputs).map_err(|e| io_err(&p, e))?;
        let p = dir.join("dataset.json");
        let json = serde_json::to_string_pretty(&self.meta()).map_err(|e| io_err(&p, e))?;
        // Written last and atomically: a dataset folder with its dataset.json is whole.
        bemcal_durable::write_atomic(&p, json.as_bytes()).map_err(|e| io_err(&p, e))?;
        Ok(())
    }

    /// Reads a set written by [`TrainingSet::write`]; validated.
    pub fn read(dir: impl AsRef<Path>) -> Result<TrainingSet, DatasetError> {
        let dir = dir.as_ref();
        let p = dir.join("dataset.json");
        let text = std::fs::read_to_string(&p).map_err(|e| io_err(&p, e))?;
        let meta: DatasetMeta = serde_json::from_str(&text).map_err(|e| io_err(&p, e))?;
        if meta.format_version != DATASET_FORMAT_VERSION {
            return Err(io_err(
                &p,
                format!(
                    "format_version {} is not supported (expected {DATASET_FORMAT_VERSION})",
                    meta.format_version
                ),
            ));
        }
        let p = dir.join("params.npy");
        let points: Array2<f64> = read_npy(&p).map_err(|e| io_err(&p, e))?;
        let p = dir.join("weather.npy");
        let weather: Array2<f64> = read_npy(&p).map_err(|e| io_err(&p, e))?;
        let p = dir.join("outputs.npy");
        let outputs: Array3<f64> = read_npy(&p).map_err(|e| io_err(&p, e))?;
        let set = TrainingSet {
            params: meta.params,
            points,
            weather,
            output_names: meta.output_names,
            outputs,
            split: meta.split,
        };
        set.validate()?;
        Ok(set)
    }
}

/// The `[n_hours, 5]` raw weather matrix of `features` in [`WEATHER_FEATURES`] order.
pub fn weather_matrix(features: &HourlyFeatures) -> Result<Array2<f64>, DatasetError> {
    let n = features.len();
    let lens = [
        features.rel_humidity_pct.len(),
        features.wind_speed_m_s.len(),
        features.global_horizontal_wh_m2.len(),
        features.day_type.len(),
    ];
    if lens.iter().any(|&l| l != n) {
        return Err(invalid(format!(
            "hourly features have unequal lengths: dry bulb {n}, others {lens:?}"
        )));
    }
    let mut m = Array2::zeros((n, WEATHER_FEATURES.len()));
    for t in 0..n {
        for (j, v) in features.row(t).into_iter().enumerate() {
            m[[t, j]] = v;
        }
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_is_by_point_seeded_and_complete() {
        let a = Split::by_design_point(20, 0.2, 7).unwrap();
        let b = Split::by_design_point(20, 0.2, 7).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.held_out.len(), 4);
        assert_eq!(a.train.len(), 16);
        let c = Split::by_design_point(20, 0.2, 8).unwrap();
        assert_ne!(a.held_out, c.held_out);
        assert!(Split::by_design_point(1, 0.2, 0).is_err());
        // Nested: the base split is by_design_point's, and growing never moves a point.
        let base = Split::by_design_point(20, 0.2, 7).unwrap();
        let n28 = Split::nested(20, 28, 0.2, 7).unwrap();
        let n44 = Split::nested(20, 44, 0.2, 7).unwrap();
        assert_eq!(Split::nested(20, 20, 0.2, 7).unwrap(), base);
        assert!(n28.held_out.iter().all(|i| n44.held_out.contains(i)));
        assert!(n28.train.iter().all(|i| n44.train.contains(i)));
        assert_eq!(n44.train.len() + n44.held_out.len(), 44);
        let extra_held = n44.held_out.iter().filter(|&&i| i >= 20).count();
        assert!(
            (1..=12).contains(&extra_held),
            "{extra_held} of 24 appended points held out"
        );
        assert!(Split::nested(21, 20, 0.2, 7).is_err());
        assert_eq!(
            Split::by_design_point(2, 0.01, 0).unwrap().held_out.len(),
            1
        );
    }
}
