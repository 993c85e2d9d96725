//! Evaluation of a trained surrogate through ONNX Runtime (`ort`, dynamically loaded from the
//! Python environment's `onnxruntime` wheel).
//!
//! A surrogate directory (written by `python -m bemcal_train`) holds `surrogate.json`
//! ([`SurrogateMeta`]) and the ONNX graphs:
//!
//! * `surrogate.onnx` (plain): `x` `[batch, 3, n_features]` f32 -> `y` `[batch, n_outputs]` kWh,
//!   the LSTM of the reference (Jiang et al. 2024, Fig. 8) with the output scaling folded in.
//! * `surrogate_fast.onnx` (structured): `p` `[1, n_params]` normalised parameters and `xw`
//!   `[3, n_hours, n_hourly]` (the hourly part of every window, step-major, built once per
//!   weather year) -> `y` `[1, n_hours, n_outputs]` kWh. The parameter part of the first layer's
//!   input projection is identical for every hour and step, so it is computed once per proposal
//!   and handed to ONNX Runtime's fused LSTM kernel as its bias. Same numbers as the plain graph;
//!   this is the MCMC hot path ([`Evaluator`]).
//! * `surrogate_fused.onnx` (the default hot path when present): `p` `[1, n_params]` and `xw`
//!   `[n_chunks, chunk + 2, n_hourly]` (the hourly rows of `chunk` consecutive windows plus the
//!   two hours before them, built once per weather year by [`chunked_hourly`]) -> `y`
//!   `[n_chunks, chunk, n_outputs]` kWh. The LSTM written out per step (python/bemcal_train/
//!   fused.py): steps 1-2 of every window are shared with the neighbouring windows and computed
//!   once per hour, zero-state steps skip the recurrent product and the forget gate, layer 1's
//!   parameter projection is one bias per proposal, one Gemm + activation per gate, and the hours
//!   are processed in chunks so every intermediate stays in cache: 7.80 GFLOP per year instead
//!   of 11.5. Same numbers as the plain graph (~1e-7 relative). The [`Evaluator`] splits the
//!   chunks (and the proposals of a batch) over `threads` single-threaded sessions.
//! * `surrogate_fused_int8.onnx` (optional, [`Precision::Int8`]): the fused graph with int8
//!   per-column weights on the recurrent / layer-2 products (`MatMulIntegerToFloat`, VNNI); its
//!   error against the float graph is in the metadata (`int8`).
//! * `surrogate_fast_int8.onnx` (older surrogates): the fast graph with dynamically quantised
//!   int8 weights, used for [`Precision::Int8`] when there is no fused int8 graph.
//! * `surrogate_vjp.onnx` (optional): the fused graph's vector-Jacobian product, `p`, `xw` and a
//!   cotangent `v` on `y` -> `g = v . dy/dp` (forward pass, then the LSTM's reverse-mode
//!   derivative written out by hand; about 2.3 forward passes), for gradient-based samplers:
//!   [`Evaluator::vjp_batch`]. Checked against torch autograd by the trainer (`vjp_vs_torch`).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use bemcal_weather::HourlyFeatures;
use ndarray::{s, Array2, Array3, ArrayView2, ArrayView3};
use ort::environment::Environment;
use ort::session::builder::GraphOptimizationLevel;
use ort::session::Session;
use ort::value::{Tensor, TensorRef};
use serde::{Deserialize, Serialize};

use crate::dataset::{ParamSpec, WEATHER_FEATURES};
use crate::schedule::ScheduleInputs;

/// Name of the metadata file in a surrogate directory.
pub const METADATA_FILE: &str = "surrogate.json";
/// The `format` field every surrogate metadata file carries.
pub const FORMAT: &str = "bemcal-surrogate";
/// The metadata `format_version` this build reads.
pub const FORMAT_VERSION: u32 = 1;
/// Lookback of the LSTM windows (reference Table 3).
pub const LOOKBACK: usize = 3;
/// Variable overriding the ONNX Runtime shared library.
pub const ORT_DYLIB_VAR: &str = "ORT_DYLIB_PATH";
/// ONNX Runtime library inside the `onnxruntime` wheel.
pub const ORT_LIBRARY: &str = "capi/libonnxruntime.so.1.31.1";

/// Errors loading or evaluating a surrogate.
#[derive(Debug, thiserror::Error)]
pub enum SurrogateError {
    /// ONNX Runtime could not be found or initialised.
    #[error("ONNX Runtime: {0}")]
    Runtime(String),
    /// The surrogate directory or its metadata is missing or invalid.
    #[error("{path}: {}", bemcal_excerpt::shorten(.message))]
    Metadata {
        /// The folder or file at fault.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// Arguments do not fit the surrogate (wrong number of parameters, hours, ...).
    #[error("{0}")]
    Input(String),
    /// ONNX Runtime failed while running a graph.
    #[error("ONNX Runtime run failed: {0}")]
    Ort(String),
}

type Result<T> = std::result::Result<T, SurrogateError>;

fn ort_err(e: impl std::fmt::Display) -> SurrogateError {
    SurrogateError::Ort(e.to_string())
}

/// The ONNX Runtime shared library: `$ORT_DYLIB_PATH`, else the venv's `onnxruntime` wheel.
pub fn ort_library_path() -> Result<PathBuf> {
    if let Some(p) = std::env::var_os(ORT_DYLIB_VAR) {
        let p = PathBuf::from(p);
        return if p.exists() {
            Ok(p)
        } else {
            Err(SurrogateError::Runtime(format!(
                "{ORT_DYLIB_VAR}={} does not exist",
                p.display()
            )))
        };
    }
    let venv = bemcal_pyenv::find_venv().ok_or_else(|| {
        SurrogateError::Runtime(format!(
            "no Python environment found to load {ORT_LIBRARY} from; {}",
            bemcal_pyenv::INSTALL_HINT
        ))
    })?;
    bemcal_pyenv::package_file(&venv, "onnxruntime", ORT_LIBRARY).ok_or_else(|| {
        SurrogateError::Runtime(format!(
            "onnxruntime/{ORT_LIBRARY} not found in {} (or set {ORT_DYLIB_VAR}); {}",
            venv.display(),
            bemcal_pyenv::INSTALL_HINT
        ))
    })
}

/// The process-wide ONNX Runtime environment, initialised on first use from
/// [`ort_library_path`].
pub fn ort_environment() -> Result<&'static Environment> {
    static ENV: OnceLock<std::result::Result<Environment, String>> = OnceLock::new();
    ENV.get_or_init(|| {
        let path = ort_library_path().map_err(|e| e.to_string())?;
        ort::init_from(&path)
            .map_err(|e| format!("cannot load {}: {e}", path.display()))?
            .with_name("bemcal")
            .build()
            .map_err(|e| format!("cannot initialise {}: {e}", path.display()))
    })
    .as_ref()
    .map_err(|e| SurrogateError::Runtime(e.clone()))
}

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

/// Which fast graph the [`Evaluator`] runs.
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

/// `surrogate.json`: the contract between the trainer and [`Surrogate`].
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
    /// day type != weekday), then the schedule inputs where the surrogate takes them
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
            let off = if row[4] != 0.0 { 1.0 } else { 0.0 };
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

/// One worker's runs: (proposal, first chunk, end chunk, its rows of the output).
type Runs<'a> = Vec<(usize, usize, usize, &'a mut [f32])>;

/// The flat (proposal, chunk) items `0..n_proposals * n_chunks` split into `workers` contiguous
/// ranges, each as runs `(proposal, first chunk, end chunk)` of one proposal's chunks.
fn split_runs(
    n_proposals: usize,
    n_chunks: usize,
    workers: usize,
) -> Vec<Vec<(usize, usize, usize)>> {
    let total = n_proposals * n_chunks;
    let workers = workers.min(total).max(1);
    (0..workers)
        .map(|w| {
            let (a, b) = (w * total / workers, (w + 1) * total / workers);
            let mut runs = Vec::new();
            let mut k = a;
            while k < b {
                let (i, c0) = (k / n_chunks, k % n_chunks);
                let c1 = (c0 + (b - k)).min(n_chunks);
                runs.push((i, c0, c1));
                k += c1 - c0;
            }
            runs
        })
        .collect()
}

/// Runs `job` for each worker's runs on its own session, the first on this thread and the rest
/// on scoped threads; results in worker order.
fn run_on_sessions<J: Send, T: Send>(
    sessions: &mut [Session],
    jobs: Vec<J>,
    job: impl Fn(&mut Session, J) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    let mut pairs = sessions.iter_mut().zip(jobs);
    let first = pairs.next();
    let job = &job;
    std::thread::scope(|scope| {
        let handles: Vec<_> = pairs
            .map(|(session, runs)| scope.spawn(move || job(session, runs)))
            .collect();
        let mine = first.map(|(session, runs)| job(session, runs));
        mine.into_iter()
            .chain(
                handles
                    .into_iter()
                    .map(|h| h.join().expect("evaluator worker panicked")),
            )
            .collect()
    })
}

/// The fused graph: one single-threaded session per worker thread.
struct Fused {
    sessions: Vec<Session>,
    /// Windows per chunk.
    chunk: usize,
    file: String,
}

/// A loaded surrogate: metadata and its ONNX Runtime sessions.
pub struct Surrogate {
    meta: SurrogateMeta,
    dir: PathBuf,
    plain: Session,
    fast: Session,
    fused: Option<Fused>,
    /// The VJP graph, when the surrogate has one (same threading as `fused`).
    vjp: Option<Fused>,
}

impl std::fmt::Debug for Surrogate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Surrogate")
            .field("dir", &self.dir)
            .field("outputs", &self.meta.output_names())
            .finish()
    }
}

fn session(dir: &Path, file: &str, threads: usize) -> Result<Session> {
    session_with(dir, file, threads, true)
}

fn session_with(dir: &Path, file: &str, threads: usize, spin: bool) -> Result<Session> {
    let path = dir.join(file);
    if !path.exists() {
        return Err(SurrogateError::Metadata {
            path,
            message: "graph file missing".into(),
        });
    }
    let env = ort_environment()?;
    let fail = |e: String| SurrogateError::Metadata {
        path: path.clone(),
        message: format!("cannot load ONNX graph: {e}"),
    };
    Session::builder(env)
        .map_err(|e| fail(e.to_string()))?
        .with_optimization_level(GraphOptimizationLevel::Level3)
        .map_err(|e| fail(e.to_string()))?
        .with_intra_threads(threads.max(1))
        .map_err(|e| fail(e.to_string()))?
        .with_inter_threads(1)
        .map_err(|e| fail(e.to_string()))?
        .with_intra_op_spinning(spin)
        .map_err(|e| fail(e.to_string()))?
        .commit_from_file(&path)
        .map_err(|e| fail(e.to_string()))
}

/// Checks a session's input or output `name` has rank `dims.len()` and the fixed sizes given
/// (`None` = dynamic/any).
fn check_io(s: &Session, file: &Path, input: bool, name: &str, dims: &[Option<i64>]) -> Result<()> {
    let list = if input { s.inputs() } else { s.outputs() };
    let what = if input { "input" } else { "output" };
    let bad = |message: String| SurrogateError::Metadata {
        path: file.to_path_buf(),
        message,
    };
    let o = list
        .iter()
        .find(|o| o.name() == name)
        .ok_or_else(|| bad(format!("graph has no {what} '{name}'")))?;
    let shape = o
        .dtype()
        .tensor_shape()
        .ok_or_else(|| bad(format!("{what} '{name}' is not a tensor")))?;
    let got: Vec<i64> = shape.iter().copied().collect();
    if got.len() != dims.len() {
        return Err(bad(format!(
            "{what} '{name}' has rank {}, expected {}",
            got.len(),
            dims.len()
        )));
    }
    for (i, (g, d)) in got.iter().zip(dims).enumerate() {
        if let Some(d) = d {
            if g != d {
                return Err(bad(format!(
                    "{what} '{name}' dimension {i} is {g}, metadata says {d} (graph and surrogate.json do not match)"
                )));
            }
        }
    }
    Ok(())
}

/// The graphs' dimensions the metadata fixes: parameters, features of the plain graph,
/// outputs, and hourly features of the windowed graphs.
#[derive(Clone, Copy)]
struct GraphDims {
    params: i64,
    features: i64,
    outputs: i64,
    hourly: i64,
}

impl GraphDims {
    fn of(meta: &SurrogateMeta) -> GraphDims {
        GraphDims {
            params: meta.params.len() as i64,
            features: meta.n_features as i64,
            outputs: meta.outputs.len() as i64,
            hourly: meta.n_hourly() as i64,
        }
    }
}

/// The hot path's graph files at `precision`: the windowed graph and the fused one (when
/// the metadata lists it); `Int8` without an int8 graph is an error.
fn graph_files(
    meta: &SurrogateMeta,
    precision: Precision,
    dir: &Path,
) -> Result<(String, Option<String>)> {
    Ok(match precision {
        Precision::F32 => (meta.files.fast.clone(), meta.files.fused.clone()),
        Precision::Int8 => match (&meta.files.fused_int8, &meta.files.fast_int8) {
            (Some(f), _) => (meta.files.fast.clone(), Some(f.clone())),
            (None, Some(f)) => (f.clone(), None),
            (None, None) => {
                return Err(SurrogateError::Metadata {
                    path: dir.join(METADATA_FILE),
                    message: "no int8 graph (files.fused_int8); retrain with `bemcal train`".into(),
                })
            }
        },
    })
}

/// The fused graph `file` as `threads` single-threaded sessions, its inputs and outputs
/// checked; its chunk length is read from the graph's fixed `xw` shape.
fn load_fused(dir: &Path, file: String, threads: usize, d: GraphDims) -> Result<Fused> {
    let sessions = (0..threads.max(1))
        .map(|_| session_with(dir, &file, 1, false))
        .collect::<Result<Vec<_>>>()?;
    let s0 = &sessions[0];
    let path = dir.join(&file);
    check_io(s0, &path, true, "p", &[Some(1), Some(d.params)])?;
    check_io(s0, &path, true, "xw", &[None, None, Some(d.hourly)])?;
    let rows = s0
        .inputs()
        .iter()
        .find(|o| o.name() == "xw")
        .and_then(|o| o.dtype().tensor_shape().map(|s| s[1]))
        .unwrap_or(-1);
    if rows < LOOKBACK as i64 {
        return Err(SurrogateError::Metadata {
            path,
            message: format!("input 'xw' needs a fixed chunk length, has {rows}"),
        });
    }
    let chunk = rows as usize - (LOOKBACK - 1);
    check_io(
        s0,
        &path,
        false,
        "y",
        &[None, Some(chunk as i64), Some(d.outputs)],
    )?;
    Ok(Fused {
        sessions,
        chunk,
        file,
    })
}

/// The fused graph's reverse-mode derivative `file` (`v . dy/dtheta`) as `threads`
/// single-threaded sessions over the fused graph's `chunk`, its inputs and outputs checked.
fn load_vjp(dir: &Path, file: &str, chunk: usize, threads: usize, d: GraphDims) -> Result<Fused> {
    let sessions = (0..threads.max(1))
        .map(|_| session_with(dir, file, 1, false))
        .collect::<Result<Vec<_>>>()?;
    let path = dir.join(file);
    let s0 = &sessions[0];
    check_io(s0, &path, true, "p", &[Some(1), Some(d.params)])?;
    check_io(
        s0,
        &path,
        true,
        "xw",
        &[None, Some((chunk + LOOKBACK - 1) as i64), Some(d.hourly)],
    )?;
    check_io(
        s0,
        &path,
        true,
        "v",
        &[None, Some(chunk as i64), Some(d.outputs)],
    )?;
    check_io(s0, &path, false, "g", &[Some(1), Some(d.params)])?;
    Ok(Fused {
        sessions,
        chunk,
        file: file.to_string(),
    })
}

impl Surrogate {
    /// Loads `dir/surrogate.json` (validated) and its graphs, with `threads` intra-op threads
    /// per session and graph optimisation level 3. Checks every graph's inputs and outputs
    /// against the metadata.
    pub fn load(dir: impl AsRef<Path>, threads: usize) -> Result<Surrogate> {
        Surrogate::load_with(dir, threads, Precision::F32)
    }

    /// [`Surrogate::load`] choosing the hot path's [`Precision`]; `Int8` on a surrogate
    /// without an int8 graph is an error. The fused graph (when the metadata lists it) is loaded
    /// as `threads` single-threaded sessions, which the [`Evaluator`] runs side by side.
    pub fn load_with(
        dir: impl AsRef<Path>,
        threads: usize,
        precision: Precision,
    ) -> Result<Surrogate> {
        let dir = dir.as_ref().to_path_buf();
        let meta = SurrogateMeta::read(&dir)?;
        let plain = session(&dir, &meta.files.plain, threads)?;
        let (fast_file, fused_file) = graph_files(&meta, precision, &dir)?;
        let fast = session(&dir, &fast_file, threads)?;
        let d = GraphDims::of(&meta);
        let f = |n: &str| dir.join(n);
        let lb = Some(LOOKBACK as i64);
        check_io(
            &plain,
            &f(&meta.files.plain),
            true,
            "x",
            &[None, lb, Some(d.features)],
        )?;
        check_io(
            &plain,
            &f(&meta.files.plain),
            false,
            "y",
            &[None, Some(d.outputs)],
        )?;
        check_io(&fast, &f(&fast_file), true, "p", &[Some(1), Some(d.params)])?;
        check_io(
            &fast,
            &f(&fast_file),
            true,
            "xw",
            &[lb, None, Some(d.hourly)],
        )?;
        check_io(
            &fast,
            &f(&fast_file),
            false,
            "y",
            &[Some(1), None, Some(d.outputs)],
        )?;
        let fused = fused_file
            .map(|file| load_fused(&dir, file, threads, d))
            .transpose()?;
        let vjp = match (&meta.files.vjp, &fused) {
            (Some(file), Some(fz)) => Some(load_vjp(&dir, file, fz.chunk, threads, d)?),
            _ => None,
        };
        Ok(Surrogate {
            meta,
            dir,
            plain,
            fast,
            fused,
            vjp,
        })
    }

    /// The validated metadata.
    pub fn meta(&self) -> &SurrogateMeta {
        &self.meta
    }

    /// The graph file the [`Evaluator`] runs (the fused graph when the surrogate has one).
    pub fn hot_path_file(&self) -> &str {
        match &self.fused {
            Some(f) => &f.file,
            None => &self.meta.files.fast,
        }
    }

    /// The directory the surrogate was loaded from.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Runs the plain graph on explicit windows `x` `[batch, 3, n_features]` (normalised
    /// inputs) -> `[batch, n_outputs]` kWh. For checks and tools; the hot path is [`Evaluator`].
    pub fn run_windows(&mut self, x: ArrayView3<'_, f32>) -> Result<Array2<f32>> {
        let (b, l, f) = x.dim();
        if l != LOOKBACK || f != self.meta.n_features {
            return Err(SurrogateError::Input(format!(
                "windows have shape [{b}, {l}, {f}], expected [batch, {LOOKBACK}, {}]",
                self.meta.n_features
            )));
        }
        let x = x.as_standard_layout();
        let out = self
            .plain
            .run(ort::inputs!["x" => TensorRef::from_array_view(x.view()).map_err(ort_err)?])
            .map_err(ort_err)?;
        let y = out["y"].try_extract_array::<f32>().map_err(ort_err)?;
        y.into_dimensionality::<ndarray::Ix2>()
            .map(|v| v.to_owned())
            .map_err(ort_err)
    }

    /// Binds the surrogate to a weather year: builds the normalised hourly part of every
    /// window once (`xw`, `[3, n_hours, n_hourly]`, hour `max(t - 2 + s, 0)` at step `s`) and
    /// keeps it for every later evaluation.
    pub fn bind(self, weather: &HourlyFeatures) -> Result<Evaluator> {
        let hourly = self.meta.hourly_inputs(weather);
        self.bind_hourly(hourly)
    }

    /// [`Surrogate::bind`] to hourly inputs already built ([`SurrogateMeta::hourly_inputs`],
    /// [`SurrogateMeta::hourly_inputs_raw`]), `[n_hours, n_hourly]`.
    pub fn bind_hourly(self, hourly: Array2<f32>) -> Result<Evaluator> {
        let n_hours = hourly.nrows();
        if n_hours < LOOKBACK {
            return Err(SurrogateError::Input(format!(
                "{n_hours} weather hours; need at least {LOOKBACK}"
            )));
        }
        if hourly.ncols() != self.meta.n_hourly() {
            return Err(SurrogateError::Input(format!(
                "{} hourly inputs; the surrogate takes {}",
                hourly.ncols(),
                self.meta.n_hourly()
            )));
        }
        let xc = self
            .fused
            .as_ref()
            .map(|f| chunked_hourly(hourly.view(), f.chunk));
        let xw = Tensor::from_array(windows_step_major(hourly.view())).map_err(ort_err)?;
        let n_out = self.meta.outputs.len();
        Ok(Evaluator {
            p: vec![0.0; self.meta.params.len()],
            out: Array3::zeros((1, n_hours, n_out)),
            xw,
            xc,
            n_hours,
            surrogate: self,
        })
    }
}

/// `[3, n_hours, k]` step-major windows of hourly rows: step `s` of the window ending at hour `t`
/// is row `max(t - 2 + s, 0)`. Pure.
pub fn windows_step_major(hourly: ArrayView2<'_, f32>) -> Array3<f32> {
    let (n, k) = hourly.dim();
    Array3::from_shape_fn((LOOKBACK, n, k), |(s, t, j)| {
        hourly[[(t + s).saturating_sub(LOOKBACK - 1), j]]
    })
}

/// `[n_chunks, chunk + 2, k]` hourly rows of `chunk` consecutive windows each: chunk `c` holds
/// hours `c * chunk - 2 ..= (c + 1) * chunk - 1`, clamped to `[0, n - 1]` (the fused graph's `xw`;
/// the rows past the last hour only fill the last chunk). Pure.
pub fn chunked_hourly(hourly: ArrayView2<'_, f32>, chunk: usize) -> Array3<f32> {
    let (n, k) = hourly.dim();
    let chunks = n.div_ceil(chunk);
    let rows = chunk + LOOKBACK - 1;
    Array3::from_shape_fn((chunks, rows, k), |(c, r, j)| {
        let u = (c * chunk + r).saturating_sub(LOOKBACK - 1).min(n - 1);
        hourly[[u, j]]
    })
}

/// A surrogate bound to one weather year ([`Surrogate::bind`]): each evaluation only writes the
/// normalised parameters; the weather part stays in `gw`.
pub struct Evaluator {
    surrogate: Surrogate,
    xw: Tensor<f32>,
    /// Chunked hourly rows for the fused graph.
    xc: Option<Array3<f32>>,
    n_hours: usize,
    p: Vec<f32>,
    out: Array3<f32>,
}

impl Evaluator {
    /// The surrogate (metadata).
    pub fn surrogate(&self) -> &Surrogate {
        &self.surrogate
    }

    /// Releases the surrogate (e.g. to bind another weather year).
    pub fn into_surrogate(self) -> Surrogate {
        self.surrogate
    }

    /// Hours of the bound weather.
    pub fn n_hours(&self) -> usize {
        self.n_hours
    }

    /// One parameter vector (raw values, the surrogate's parameter order) -> `[n_hours,
    /// n_outputs]` kWh, a view of a buffer reused by the next call.
    pub fn evaluate(&mut self, params: &[f64]) -> Result<ArrayView2<'_, f32>> {
        let y = self.evaluate_batch(std::slice::from_ref(&params))?;
        Ok(y.index_axis_move(ndarray::Axis(0), 0))
    }

    /// Several parameter vectors -> `[n_proposals, n_hours, n_outputs]` kWh, a view of a buffer
    /// reused by the next call. Fused graph: the (proposal, chunk) pairs are split into
    /// `threads` contiguous runs, each run on its own single-threaded session on its own thread
    /// (no intra-op synchronisation; every intermediate of a chunk stays in that core's cache).
    /// Without a fused graph: one fast-graph run per proposal.
    pub fn evaluate_batch<P: AsRef<[f64]>>(&mut self, params: &[P]) -> Result<ArrayView3<'_, f32>> {
        let n = params.len();
        if n == 0 {
            return Err(SurrogateError::Input(
                "no parameter vectors to evaluate".into(),
            ));
        }
        let n_out = self.surrogate.meta.outputs.len();
        if self.out.dim().0 != n {
            self.out = Array3::zeros((n, self.n_hours, n_out));
        }
        if self.surrogate.fused.is_some() {
            self.evaluate_fused(params)?;
            return Ok(self.out.slice(s![.., .., ..]));
        }
        let np = self.p.len();
        for (i, p) in params.iter().enumerate() {
            self.surrogate
                .meta
                .normalise_params(p.as_ref(), &mut self.p)?;
            let outputs = self
                .surrogate
                .fast
                .run(ort::inputs![
                    "p" => TensorRef::from_array_view(([1usize, np], &self.p[..])).map_err(ort_err)?,
                    "xw" => &self.xw,
                ])
                .map_err(ort_err)?;
            let y = outputs["y"].try_extract_array::<f32>().map_err(ort_err)?;
            if y.shape() != [1, self.n_hours, n_out] {
                return Err(SurrogateError::Ort(format!(
                    "fast graph returned shape {:?}, expected [1, {}, {n_out}]",
                    y.shape(),
                    self.n_hours
                )));
            }
            let src = y
                .as_slice()
                .ok_or_else(|| SurrogateError::Ort("non-contiguous output".into()))?;
            self.out
                .index_axis_mut(ndarray::Axis(0), i)
                .as_slice_mut()
                .expect("standard layout")
                .copy_from_slice(src);
        }
        Ok(self.out.slice(s![.., .., ..]))
    }

    fn evaluate_fused<P: AsRef<[f64]>>(&mut self, params: &[P]) -> Result<()> {
        let meta = &self.surrogate.meta;
        let np = meta.params.len();
        let mut ps = vec![0f32; params.len() * np];
        for (p, row) in params.iter().zip(ps.chunks_mut(np)) {
            meta.normalise_params(p.as_ref(), row)?;
        }
        let fused = self.surrogate.fused.as_mut().expect("fused graph");
        let xc = self.xc.as_ref().expect("bound with the fused graph");
        let (n_chunks, n_hours, chunk) = (xc.dim().0, self.n_hours, fused.chunk);
        let n_out = self.out.dim().2;
        // Worker w takes the flat (proposal, chunk) items [w * total / workers, ...): contiguous
        // runs of one proposal's chunks, written to disjoint rows of `out`.
        let mut outs: Vec<_> = self
            .out
            .outer_iter_mut()
            .map(|o| Some(o.into_slice().expect("standard layout")))
            .collect();
        let jobs: Vec<Runs<'_>> = split_runs(params.len(), n_chunks, fused.sessions.len())
            .into_iter()
            .map(|runs| {
                runs.into_iter()
                    .map(|(i, c0, c1)| {
                        let rows = (c1 * chunk).min(n_hours) - c0 * chunk;
                        let rest = outs[i].take().expect("disjoint runs");
                        let (mine, tail) = rest.split_at_mut(rows * n_out);
                        outs[i] = Some(tail);
                        (i, c0, c1, mine)
                    })
                    .collect()
            })
            .collect();
        let ps = &ps;
        run_on_sessions(&mut fused.sessions, jobs, |session, runs: Runs<'_>| {
            for (i, c0, c1, dst) in runs {
                let x = xc.slice(s![c0..c1, .., ..]);
                let outputs = session
                    .run(ort::inputs![
                        "p" => TensorRef::from_array_view(([1usize, np], &ps[i * np..(i + 1) * np]))
                            .map_err(ort_err)?,
                        "xw" => TensorRef::from_array_view(x).map_err(ort_err)?,
                    ])
                    .map_err(ort_err)?;
                let y = outputs["y"].try_extract_array::<f32>().map_err(ort_err)?;
                if y.shape() != [c1 - c0, chunk, n_out] {
                    return Err(SurrogateError::Ort(format!(
                        "fused graph returned shape {:?}, expected [{}, {chunk}, {n_out}]",
                        y.shape(),
                        c1 - c0
                    )));
                }
                let src = y
                    .as_slice()
                    .ok_or_else(|| SurrogateError::Ort("non-contiguous output".into()))?;
                dst.copy_from_slice(&src[..dst.len()]);
            }
            Ok(())
        })
        .map(|_| ())
    }

    /// Whether the surrogate has the VJP graph ([`Evaluator::vjp_batch`]).
    pub fn has_gradient(&self) -> bool {
        self.surrogate.vjp.is_some()
    }

    /// Vector-Jacobian products: for each parameter vector `params[i]` (raw values) and its
    /// cotangent `cotangents[i]` (`[n_hours, n_outputs]`, e.g. `d ln L / d y` in 1 / kWh), the
    /// gradient `sum_(t, k) v_tk dy_tk / d theta_j` with respect to the raw parameters. The
    /// (proposal, chunk) pairs are split over the threads as in [`Evaluator::evaluate_batch`]
    /// and the partial sums added. About 2.3 forward evaluations of arithmetic.
    ///
    /// # Errors
    /// Without a VJP graph (surrogates trained before it existed: `python -m bemcal_train
    /// --add-vjp DIR` adds it), or on shape mismatches.
    pub fn vjp_batch<P: AsRef<[f64]>>(
        &mut self,
        params: &[P],
        cotangents: ArrayView3<'_, f32>,
    ) -> Result<Vec<Vec<f64>>> {
        let meta = &self.surrogate.meta;
        let np = meta.params.len();
        let n_out = meta.outputs.len();
        let Some(vjp) = self.surrogate.vjp.as_mut() else {
            return Err(SurrogateError::Metadata {
                path: self.surrogate.dir.join(METADATA_FILE),
                message: "no gradient graph (files.vjp): retrain, or add it with \
                          `python -m bemcal_train --add-vjp DIR`"
                    .into(),
            });
        };
        if cotangents.dim() != (params.len(), self.n_hours, n_out) {
            return Err(SurrogateError::Input(format!(
                "cotangents have shape {:?}, expected [{}, {}, {n_out}]",
                cotangents.dim(),
                params.len(),
                self.n_hours
            )));
        }
        let mut ps = vec![0f32; params.len() * np];
        for (p, row) in params.iter().zip(ps.chunks_mut(np)) {
            meta.normalise_params(p.as_ref(), row)?;
        }
        let xc = self.xc.as_ref().expect("bound with the fused graph");
        let (n_chunks, chunk) = (xc.dim().0, vjp.chunk);
        // Chunked cotangents, zero on the rows past the last hour.
        let mut vc = Array3::<f32>::zeros((params.len() * n_chunks, chunk, n_out));
        for i in 0..params.len() {
            for t in 0..self.n_hours {
                for k in 0..n_out {
                    vc[[i * n_chunks + t / chunk, t % chunk, k]] = cotangents[[i, t, k]];
                }
            }
        }
        let (ps, vc) = (&ps, &vc);
        let jobs = split_runs(params.len(), n_chunks, vjp.sessions.len());
        let parts = run_on_sessions(&mut vjp.sessions, jobs, |session, runs| {
            let mut part = Vec::new();
            for (i, c0, c1) in runs {
                let outputs = session
                    .run(ort::inputs![
                        "p" => TensorRef::from_array_view(([1usize, np], &ps[i * np..(i + 1) * np]))
                            .map_err(ort_err)?,
                        "xw" => TensorRef::from_array_view(xc.slice(s![c0..c1, .., ..])).map_err(ort_err)?,
                        "v" => TensorRef::from_array_view(
                            vc.slice(s![i * n_chunks + c0..i * n_chunks + c1, .., ..])
                        ).map_err(ort_err)?,
                    ])
                    .map_err(ort_err)?;
                let g = outputs["g"].try_extract_array::<f32>().map_err(ort_err)?;
                if g.shape() != [1, np] {
                    return Err(SurrogateError::Ort(format!(
                        "gradient graph returned shape {:?}, expected [1, {np}]",
                        g.shape()
                    )));
                }
                part.push((i, g.iter().map(|&v| f64::from(v)).collect::<Vec<f64>>()));
            }
            Ok(part)
        })?;
        // d p_norm / d theta = 1 / (max - min).
        let mut grads = vec![vec![0.0; np]; params.len()];
        for (i, g) in parts.into_iter().flatten() {
            for ((o, v), spec) in grads[i].iter_mut().zip(g).zip(&meta.params) {
                *o += v / (spec.max - spec.min);
            }
        }
        Ok(grads)
    }
}
