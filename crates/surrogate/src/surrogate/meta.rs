//! The surrogate's metadata, `surrogate.json`: what was trained on what, and its checks.

use std::path::Path;

use bemcal_weather::HourlyFeatures;
use ndarray::{s, Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use super::{Result, SurrogateError, FORMAT, FORMAT_VERSION, LOOKBACK, METADATA_FILE};
use crate::dataset::{ParamSpec, WEATHER_FEATURES};
use crate::schedule::ScheduleInputs;

/// Model shape recorded in the metadata.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    /// `"lstm"`.
    pub kind: String,
    /// Window length (3).
    pub lookback: usize,
    /// LSTM layers.
    pub layers: usize,
    /// Hidden units per layer.
    pub hidden: usize,
}

/// Graph file names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GraphFiles {
    /// `x` -> `y`.
    pub plain: String,
    /// `p`, `xw` -> `y` (float).
    pub fast: String,
    /// `p`, `xw` -> `y` with int8 weights (older surrogates).
    #[serde(default)]
    pub fast_int8: Option<String>,
    /// `p`, chunked `xw` -> chunked `y` (float): the evaluator's default when present.
    #[serde(default)]
    pub fused: Option<String>,
    /// The fused graph with int8 weights.
    #[serde(default)]
    pub fused_int8: Option<String>,
    /// `p`, chunked `xw`, a cotangent `v` on chunked `y` -> `g = v . dy/dp` [1, n_params]:
    /// the fused graph's vector-Jacobian product (gradients through the surrogate).
    #[serde(default)]
    pub vjp: Option<String>,
}

/// Which fast graph the [`Evaluator`](super::Evaluator) runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    /// Float weights: equal to the trained network (to ~1e-6 relative).
    #[default]
    F32,
    /// Dynamically quantised int8 weights: faster; check [`SurrogateMeta::int8`] (its error
    /// against the float graph relative to sigma_eta) before using it for calibration.
    Int8,
}

/// Accuracy of the int8 graph, measured by the trainer on the held-out points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Int8Info {
    /// File name.
    pub file: String,
    /// RMSE of (int8 - float) predictions per output, kWh.
    pub rmse_vs_float_kwh: std::collections::BTreeMap<String, f64>,
    /// That RMSE divided by sigma_eta, per output.
    pub ratio_to_sigma_eta: std::collections::BTreeMap<String, f64>,
}

/// Weather normalisation: `(w - mean) / std` per feature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WeatherNorm {
    /// Feature names, [`WEATHER_FEATURES`].
    pub names: Vec<String>,
    /// Means over the training year.
    pub mean: Vec<f64>,
    /// Standard deviations (1 for constant features).
    pub std: Vec<f64>,
}

/// One output (meter) of the surrogate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutputInfo {
    /// Output name, e.g. `heating_kwh`.
    pub name: String,
    /// The scale folded into the graphs (the output's training maximum, kWh).
    pub scale: f64,
    /// Held-out RMSE in kWh: the surrogate error sigma_eta of the likelihood (reference Eq. 7).
    pub sigma_eta_kwh: f64,
}

/// Held-out accuracy of one output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeldOutMetric {
    /// RMSE over held-out points x hours, kWh.
    pub rmse_kwh: f64,
    /// RMSE / mean of the held-out truth, %; absent for an all-zero output.
    pub cv_rmse_pct: Option<f64>,
    /// Mean bias / mean of the held-out truth, %.
    pub nmbe_pct: Option<f64>,
    /// Mean of the held-out truth, kWh.
    pub mean_kwh: f64,
}

/// Held-out design points and per-output metrics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeldOut {
    /// Held-out design point indices.
    pub points: Vec<usize>,
    /// Metrics by output name.
    pub metrics: std::collections::BTreeMap<String, HeldOutMetric>,
}

/// Training facts recorded by the trainer (subset).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingInfo {
    /// Seed.
    pub seed: u64,
    /// Epochs run (early stopping may end before the maximum).
    pub epochs_run: usize,
    /// Epoch with the best held-out loss (the exported weights).
    pub best_epoch: usize,
    /// Wall time of training and evaluation, s.
    pub seconds: f64,
    /// torch version used.
    pub torch_version: String,
    /// `cpu` or `cuda...`.
    pub device: String,
}

/// `surrogate.json`: the contract between the trainer and [`Surrogate`](super::Surrogate).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurrogateMeta {
    /// [`FORMAT`].
    pub format: String,
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Network shape.
    pub model: ModelInfo,
    /// Graph file names.
    pub files: GraphFiles,
    /// Features per window step: params + weather + time features.
    pub n_features: usize,
    /// Feature names in input order.
    pub feature_names: Vec<String>,
    /// Parameters (names, bounds for the [0, 1] scaling, prior modes), input order.
    pub params: Vec<ParamSpec>,
    /// Weather normalisation.
    pub weather: WeatherNorm,
    /// `none`, `hour` or `hour+schedule`.
    pub time_features: String,
    /// Names of the time features.
    pub time_feature_names: Vec<String>,
    /// Outputs, graph order.
    pub outputs: Vec<OutputInfo>,
    /// Whether the graphs clamp outputs at 0.
    pub nonnegative: bool,
    /// Held-out accuracy.
    pub held_out: HeldOut,
    /// Training facts.
    pub training: TrainingInfo,
    /// Accuracy of the int8 graph, when there is one.
    #[serde(default)]
    pub int8: Option<Int8Info>,
    /// The building's schedule as hourly inputs, after the time features: a surrogate folded
    /// from the family's pretrained network ([`crate::schedule`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule_inputs: Option<ScheduleInputs>,
}

impl SurrogateMeta {
    /// Reads and validates `dir/surrogate.json`.
    pub fn read(dir: &Path) -> Result<SurrogateMeta> {
        let path = dir.join(METADATA_FILE);
        let bad = |message: String| SurrogateError::Metadata {
            path: path.clone(),
            message,
        };
        let text = std::fs::read_to_string(&path).map_err(|e| {
            bad(format!(
                "cannot read ({e}); is this a surrogate directory written by `bemcal train`?"
            ))
        })?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| bad(format!("not JSON: {e}")))?;
        if value.get("format").and_then(|v| v.as_str()) != Some(FORMAT) {
            return Err(bad(format!("'format' is not \"{FORMAT}\"")));
        }
        let version = value.get("format_version").and_then(|v| v.as_u64());
        if version != Some(FORMAT_VERSION as u64) {
            return Err(bad(format!(
                "format_version {version:?} is not supported by this bemcal (reads {FORMAT_VERSION}); retrain with `bemcal train`"
            )));
        }
        let meta: SurrogateMeta = serde_json::from_value(value)
            .map_err(|e| bad(format!("missing or invalid field: {e}")))?;
        meta.validate().map_err(bad)?;
        Ok(meta)
    }

    /// Consistency checks; the message names the field.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if self.model.lookback != LOOKBACK {
            return Err(format!(
                "model.lookback {} is not {LOOKBACK}",
                self.model.lookback
            ));
        }
        if self.weather.names != WEATHER_FEATURES {
            return Err(format!(
                "weather.names {:?} are not {:?}",
                self.weather.names, WEATHER_FEATURES
            ));
        }
        if self.weather.mean.len() != 5 || self.weather.std.len() != 5 {
            return Err("weather.mean and weather.std need 5 values".into());
        }
        if self
            .weather
            .std
            .iter()
            .any(|s| !(s.is_finite() && *s > 0.0))
            || self.weather.mean.iter().any(|m| !m.is_finite())
        {
            return Err("weather.mean must be finite and weather.std finite and > 0".into());
        }
        let expect: &[&str] = match self.time_features.as_str() {
            "none" => &[],
            "hour" => &["hour_sin", "hour_cos"],
            "hour+schedule" => &["hour_sin", "hour_cos", "offday_hour_sin", "offday_hour_cos"],
            other => {
                return Err(format!(
                    "time_features '{other}' is not none, hour or hour+schedule"
                ))
            }
        };
        if self.time_feature_names != expect {
            return Err(format!(
                "time_feature_names {:?} do not match time_features '{}'",
                self.time_feature_names, self.time_features
            ));
        }
        if let Some(s) = &self.schedule_inputs {
            s.validate(self.params.len())?;
        }
        if self.n_features != self.params.len() + self.n_hourly() {
            return Err(format!(
                "n_features {} != {} params + {} weather + {} time features + {} schedule inputs",
                self.n_features,
                self.params.len(),
                self.weather.names.len(),
                self.time_feature_names.len(),
                self.schedule_inputs
                    .as_ref()
                    .map_or(0, ScheduleInputs::n_columns)
            ));
        }
        if self.feature_names.len() != self.n_features {
            return Err("feature_names length differs from n_features".into());
        }
        for p in &self.params {
            if !(p.min.is_finite()
                && p.max.is_finite()
                && p.max > p.min
                && (p.min..=p.max).contains(&p.mode))
            {
                return Err(format!(
                    "parameter '{}': need finite min < max and min <= mode <= max",
                    p.name
                ));
            }
        }
        if self.outputs.is_empty() {
            return Err("no outputs".into());
        }
        for o in &self.outputs {
            if !(o.scale.is_finite()
                && o.scale > 0.0
                && o.sigma_eta_kwh.is_finite()
                && o.sigma_eta_kwh >= 0.0)
            {
                return Err(format!(
                    "output '{}': scale must be > 0 and sigma_eta_kwh >= 0",
                    o.name
                ));
            }
        }
        Ok(())
    }

    /// Per-hour features: weather + time features + schedule inputs.
    pub fn n_hourly(&self) -> usize {
        self.weather.names.len()
            + self.time_feature_names.len()
            + self
                .schedule_inputs
                .as_ref()
                .map_or(0, ScheduleInputs::n_columns)
    }

    /// Output names in graph order.
    pub fn output_names(&self) -> Vec<String> {
        self.outputs.iter().map(|o| o.name.clone()).collect()
    }

    /// sigma_eta (kWh) per output, graph order.
    pub fn sigma_eta_kwh(&self) -> Vec<f64> {
        self.outputs.iter().map(|o| o.sigma_eta_kwh).collect()
    }

    /// Prior modes of the parameters, input order.
    pub fn param_modes(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.mode).collect()
    }

    /// Writes the normalised parameters `(p - min) / (max - min)` into `out`. Pure.
    pub fn normalise_params(&self, params: &[f64], out: &mut [f32]) -> Result<()> {
        if params.len() != self.params.len() || out.len() != self.params.len() {
            return Err(SurrogateError::Input(format!(
                "{} parameter values given; the surrogate takes {} ({})",
                params.len(),
                self.params.len(),
                self.params
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        for ((o, v), spec) in out.iter_mut().zip(params).zip(&self.params) {
            if !v.is_finite() {
                return Err(SurrogateError::Input(format!(
                    "parameter '{}' is {v}",
                    spec.name
                )));
            }
            *o = spec.normalise(*v) as f32;
        }
        Ok(())
    }

    /// The per-hour part of the input, `[n_hours, n_hourly]`: `(w - mean) / std` for the five
    /// weather features, then the time features (hour of day `h = t mod 24`, hour beginning:
    /// `sin, cos(2 pi h / 24)`, and for `hour+schedule` the same two times the off-day flag,
    /// the day type's code clamped to 0..1: 1 on days off, 0.5 on partial days), then the schedule inputs where the surrogate takes them
    /// ([`ScheduleInputs::fill`]). Pure; identical to the trainer's `data.hourly_features`
    /// (and `data.schedule_columns`).
    pub fn hourly_inputs(&self, weather: &HourlyFeatures) -> Array2<f32> {
        self.hourly_rows(weather.len(), |t| weather.row(t))
    }

    /// [`SurrogateMeta::hourly_inputs`] of a raw weather matrix `[n_hours, 5]` (a training
    /// set's `weather.npy`, day types as their codes). Pure.
    pub fn hourly_inputs_raw(&self, weather: ArrayView2<'_, f64>) -> Array2<f32> {
        self.hourly_rows(weather.nrows(), |t| {
            [0, 1, 2, 3, 4].map(|j| weather[[t, j]])
        })
    }

    fn hourly_rows(&self, n: usize, weather: impl Fn(usize) -> [f64; 5]) -> Array2<f32> {
        let times = 5 + self.time_feature_names.len();
        let k = self.n_hourly();
        let mut m = Array2::zeros((n, k));
        for t in 0..n {
            let row = weather(t);
            for j in 0..5 {
                m[[t, j]] = ((row[j] - self.weather.mean[j]) / self.weather.std[j]) as f32;
            }
            let ang = 2.0 * std::f64::consts::PI * ((t % 24) as f64) / 24.0;
            // Off days (weekend 1, holiday 2) 1, working days 0, a partial day its 0.5.
            let off = row[4].clamp(0.0, 1.0);
            let extra = [ang.sin(), ang.cos(), off * ang.sin(), off * ang.cos()];
            for (j, v) in extra.iter().take(self.time_feature_names.len()).enumerate() {
                m[[t, 5 + j]] = *v as f32;
            }
            if let Some(sched) = &self.schedule_inputs {
                let mut out = m.slice_mut(s![t, times..]);
                let out = out
                    .as_slice_mut()
                    .expect("a row of a standard-layout array");
                sched.fill(t, row[4], out);
            }
        }
        m
    }
}
