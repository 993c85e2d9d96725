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
//!
//! This file loads the graphs into sessions and checks their inputs ([`Surrogate::load`]);
//! `meta.rs` holds `surrogate.json` and its checks ([`SurrogateMeta`]); `evaluator.rs` the hot
//! path over one weather year ([`Evaluator`]).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use bemcal_weather::HourlyFeatures;
use ndarray::{Array2, Array3, ArrayView2, ArrayView3};
use ort::environment::Environment;
use ort::session::builder::GraphOptimizationLevel;
use ort::session::Session;
use ort::value::{Tensor, TensorRef};

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

mod evaluator;
mod meta;

pub use evaluator::Evaluator;
pub use meta::{
    GraphFiles, HeldOut, HeldOutMetric, Int8Info, ModelInfo, OutputInfo, Precision, SurrogateMeta,
    TrainingInfo, WeatherNorm,
};

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
