//! `train`: runs the Python trainer (`python/bemcal_train`, embedded in this crate) on a dataset
//! directory and reads back the metadata it writes.
//!
//! The package files are compiled into the binary with `include_str!` and written to a temporary
//! directory at run time, so training works from any directory. The interpreter is
//! `$BEMCAL_PYTHON`, else the Python environment's (`bemcal-pyenv`).

use std::path::{Path, PathBuf};

use crate::parity::{ParityFixture, PARITY_FILE, PARITY_TOLERANCE};
use crate::surrogate::{Surrogate, SurrogateError, SurrogateMeta};

/// Variable naming the Python interpreter explicitly.
pub const PYTHON_VAR: &str = "BEMCAL_PYTHON";

/// The trainer package, `(relative path, contents)`.
pub const TRAINER_FILES: [(&str, &str); 9] = [
    (
        "bemcal_train/__init__.py",
        include_str!("../../../python/bemcal_train/__init__.py"),
    ),
    (
        "bemcal_train/__main__.py",
        include_str!("../../../python/bemcal_train/__main__.py"),
    ),
    (
        "bemcal_train/adam.py",
        include_str!("../../../python/bemcal_train/adam.py"),
    ),
    (
        "bemcal_train/data.py",
        include_str!("../../../python/bemcal_train/data.py"),
    ),
    (
        "bemcal_train/model.py",
        include_str!("../../../python/bemcal_train/model.py"),
    ),
    (
        "bemcal_train/export.py",
        include_str!("../../../python/bemcal_train/export.py"),
    ),
    (
        "bemcal_train/fused.py",
        include_str!("../../../python/bemcal_train/fused.py"),
    ),
    (
        "bemcal_train/pretrain.py",
        include_str!("../../../python/bemcal_train/pretrain.py"),
    ),
    (
        "bemcal_train/train.py",
        include_str!("../../../python/bemcal_train/train.py"),
    ),
];

/// Time-of-day inputs offered to the LSTM (the reference gives it none).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TimeFeatures {
    /// The reference's inputs only.
    #[default]
    None,
    /// sin/cos of 2 pi h / 24.
    Hour,
    /// Hour plus hour x off-day (weekend/holiday) interactions.
    HourSchedule,
}

impl TimeFeatures {
    /// Every mode, in the order an error message lists them.
    pub const ALL: [TimeFeatures; 3] = [
        TimeFeatures::None,
        TimeFeatures::Hour,
        TimeFeatures::HourSchedule,
    ];

    /// The trainer's spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            TimeFeatures::None => "none",
            TimeFeatures::Hour => "hour",
            TimeFeatures::HourSchedule => "hour+schedule",
        }
    }
}

impl std::str::FromStr for TimeFeatures {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        spelled(s, &TimeFeatures::ALL, TimeFeatures::as_str)
    }
}

/// How the learning rate moves over a training.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum LrSchedule {
    /// The same rate throughout (the reference).
    #[default]
    Constant,
    /// Annealed from the rate to 1/100 of it along a half cosine over the most epochs
    /// (Loshchilov & Hutter 2017, SGDR, eq. 5, without restarts).
    Cosine,
}

impl LrSchedule {
    /// Every schedule, in the order an error message lists them.
    pub const ALL: [LrSchedule; 2] = [LrSchedule::Constant, LrSchedule::Cosine];

    /// The trainer's spelling (the project file's too).
    pub fn as_str(self) -> &'static str {
        match self {
            LrSchedule::Constant => "constant",
            LrSchedule::Cosine => "cosine",
        }
    }
}

impl std::str::FromStr for LrSchedule {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        spelled(s, &LrSchedule::ALL, LrSchedule::as_str)
    }
}

/// The one of `all` that `spelling` spells `s`, or a message listing what was expected
/// (`'x': expected a, b or c`).
fn spelled<T: Copy>(s: &str, all: &[T], spelling: fn(T) -> &'static str) -> Result<T, String> {
    if let Some(v) = all.iter().copied().find(|v| spelling(*v) == s) {
        return Ok(v);
    }
    let names: Vec<&str> = all.iter().map(|v| spelling(*v)).collect();
    let expected = match names.split_last() {
        Some((last, [])) => last.to_string(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => String::new(),
    };
    Err(format!("'{s}': expected {expected}"))
}

/// The trained weights (PyTorch `state_dict` and output scale) in a surrogate folder, kept for
/// a later warm start; the ONNX graphs are what bemcal evaluates.
pub const WEIGHTS_FILE: &str = "weights.pt";

/// Trainer options (defaults: reference Table 3 with early stopping).
#[derive(Debug, Clone, PartialEq)]
pub struct TrainOptions {
    /// Maximum epochs (200).
    pub epochs: usize,
    /// Early-stopping patience on the held-out loss, epochs (20).
    pub patience: usize,
    /// Seed for torch and numpy (0).
    pub seed: u64,
    /// Mini-batch size (1024).
    pub batch_size: usize,
    /// Time-of-day features (none).
    pub time_features: TimeFeatures,
    /// `auto`, `cpu` or `cuda` (`cpu`).
    pub device: String,
    /// torch threads; 0 = torch's default.
    pub threads: usize,
    /// Interpreter; `None` = `$BEMCAL_PYTHON` or the venv's.
    pub python: Option<PathBuf>,
    /// Do not echo the trainer's output (it still goes into the error on failure).
    pub quiet: bool,
    /// Warm start: a previous surrogate folder holding [`WEIGHTS_FILE`] (same parameters,
    /// outputs and architecture); `None` trains from a random initialisation.
    pub init: Option<PathBuf>,
    /// Hidden units per LSTM layer (the reference's 128).
    pub hidden: usize,
    /// Adam's learning rate (1e-3), the first where it is scheduled.
    pub lr: f64,
    /// The learning rate's schedule (constant).
    pub lr_schedule: LrSchedule,
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions {
            epochs: 200,
            patience: 20,
            seed: 0,
            batch_size: 1024,
            time_features: TimeFeatures::None,
            device: "cpu".into(),
            threads: 0,
            python: None,
            quiet: false,
            init: None,
            hidden: 128,
            lr: 1e-3,
            lr_schedule: LrSchedule::Constant,
        }
    }
}

/// What training produced.
#[derive(Debug, Clone)]
pub struct TrainReport {
    /// The surrogate directory.
    pub out_dir: PathBuf,
    /// Its validated metadata (held-out metrics, sigma_eta).
    pub meta: SurrogateMeta,
    /// Wall time of the Python run, s.
    pub seconds: f64,
}

/// The interpreter: `$BEMCAL_PYTHON`, else the venv's; `None` with no environment.
pub fn find_python() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os(PYTHON_VAR) {
        return Some(PathBuf::from(p));
    }
    bemcal_pyenv::find_venv().map(|v| bemcal_pyenv::python(&v))
}

pub(crate) fn runtime(msg: String) -> SurrogateError {
    SurrogateError::Runtime(msg)
}

/// Writes the embedded trainer package under `dir` (e.g. to run it by hand).
pub fn write_trainer(dir: &Path) -> std::io::Result<()> {
    bemcal_pyenv::write_package(dir, &TRAINER_FILES)
}

/// `python -m MODULE` of the embedded trainer package (written to a temporary folder, kept
/// alive by the returned guard), with `out_dir` created: the command, the Python it runs and
/// the guard.
pub(crate) fn trainer_command(
    python: Option<PathBuf>,
    module: &str,
    out_dir: &Path,
) -> Result<(std::process::Command, PathBuf, tempfile::TempDir), SurrogateError> {
    let python = python.or_else(find_python).ok_or_else(|| {
        runtime(format!(
            "no Python environment found for training (set {PYTHON_VAR} or {}); {}",
            bemcal_pyenv::VENV_VAR,
            bemcal_pyenv::INSTALL_HINT
        ))
    })?;
    let pkg = tempfile::tempdir()
        .map_err(|e| runtime(format!("cannot create a temporary directory: {e}")))?;
    write_trainer(pkg.path())
        .map_err(|e| runtime(format!("cannot write the trainer package: {e}")))?;
    std::fs::create_dir_all(out_dir).map_err(|e| SurrogateError::Metadata {
        path: out_dir.to_path_buf(),
        message: format!("cannot create: {e}"),
    })?;
    let mut cmd = bemcal_pyenv::child_command(&python);
    cmd.arg("-m")
        .arg(module)
        .env("PYTHONPATH", pkg.path())
        .env("PYTHONDONTWRITEBYTECODE", "1");
    Ok((cmd, python, pkg))
}

/// Trains a surrogate on `dataset_dir` (written by [`crate::TrainingSet::write`]) into
/// `out_dir` by running `python -m bemcal_train`; returns the validated metadata.
pub fn train(
    dataset_dir: &Path,
    out_dir: &Path,
    opts: &TrainOptions,
) -> Result<TrainReport, SurrogateError> {
    let (mut cmd, python, _pkg) = trainer_command(opts.python.clone(), "bemcal_train", out_dir)?;
    cmd.arg("--dataset")
        .arg(dataset_dir)
        .arg("--out")
        .arg(out_dir)
        .args(["--epochs", &opts.epochs.to_string()])
        .args(["--patience", &opts.patience.to_string()])
        .args(["--seed", &opts.seed.to_string()])
        .args(["--batch-size", &opts.batch_size.to_string()])
        .args(["--time-features", opts.time_features.as_str()])
        .args(["--device", &opts.device])
        .args(["--threads", &opts.threads.to_string()])
        .args(["--hidden", &opts.hidden.to_string()])
        .args(["--lr", &opts.lr.to_string()])
        .args(["--lr-schedule", opts.lr_schedule.as_str()]);
    if let Some(init) = &opts.init {
        cmd.arg("--init").arg(init);
    }
    // PyTorch's OpenMP (libgomp, in its Linux wheels) threads spin about 300,000 times at
    // each barrier before they sleep: two trainings on one host with more threads than cores
    // then burn their time slices waiting on each other. Two 8-epoch trainings of 2 threads
    // at once on 2 cores: 568 s with the default, 142 s with a spin count of 10,000, 69 s
    // with OMP_WAIT_POLICY=PASSIVE (single runs); alone, neither setting differed from the
    // default beyond the noise of 3 pairs (docs/benchmarks.md). A user's own setting wins.
    if std::env::var_os("OMP_WAIT_POLICY").is_none() && std::env::var_os("GOMP_SPINCOUNT").is_none()
    {
        cmd.env("GOMP_SPINCOUNT", "10000");
    }
    let start = std::time::Instant::now();
    let (ok, log) = if opts.quiet {
        let out = cmd
            .output()
            .map_err(|e| runtime(format!("cannot start {}: {e}", python.display())))?;
        let mut log = String::from_utf8_lossy(&out.stdout).into_owned();
        log.push_str(&String::from_utf8_lossy(&out.stderr));
        (out.status.success(), log)
    } else {
        let status = cmd
            .status()
            .map_err(|e| runtime(format!("cannot start {}: {e}", python.display())))?;
        (status.success(), String::from("(output above)"))
    };
    if !ok {
        let tail: String = log
            .lines()
            .rev()
            .take(30)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect::<Vec<_>>()
            .join("\n");
        return Err(runtime(format!(
            "the trainer ({} -m bemcal_train) failed:\n{tail}",
            python.display()
        )));
    }
    let seconds = start.elapsed().as_secs_f64();
    let meta = SurrogateMeta::read(out_dir)?;
    // The graphs as ONNX Runtime runs them here, on the hourly inputs this runtime builds,
    // must reproduce the PyTorch network: on the fixture's windows and over its year.
    let fixture = ParityFixture::read(out_dir)?;
    let mut surrogate = Surrogate::load(out_dir, 1)?;
    let windows = surrogate.parity_error(&fixture)?;
    let weather_file = dataset_dir.join("weather.npy");
    let weather: ndarray::Array2<f64> = ndarray_npy::read_npy(&weather_file)
        .map_err(|e| runtime(format!("cannot read {}: {e}", weather_file.display())))?;
    let year = surrogate.year_parity_error(&fixture, weather.view())?;
    let error = if windows.is_nan() || year.is_nan() {
        f64::NAN
    } else {
        windows.max(year)
    };
    if error.is_nan() || error > PARITY_TOLERANCE {
        return Err(SurrogateError::Metadata {
            path: out_dir.join(PARITY_FILE),
            message: format!(
                "ONNX Runtime here disagrees with PyTorch on the exported network: relative error \
                 {error:.2e} > {PARITY_TOLERANCE:.0e} (is the ONNX Runtime library the pinned one?)"
            ),
        });
    }
    Ok(TrainReport {
        out_dir: out_dir.to_path_buf(),
        meta,
        seconds,
    })
}

#[cfg(test)]
mod tests {
    use super::{LrSchedule, TimeFeatures, TRAINER_FILES};

    /// A module added to `python/bemcal_train` and not to `TRAINER_FILES` imports in a checkout
    /// and fails in every training the binary runs.
    #[test]
    fn every_module_of_the_trainer_is_embedded() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../python/bemcal_train");
        bemcal_pyenv::check_embedded(std::path::Path::new(dir), "bemcal_train", &TRAINER_FILES)
            .unwrap();
    }

    #[test]
    fn each_spelling_reads_back_and_a_wrong_one_lists_the_right_ones() {
        for t in TimeFeatures::ALL {
            assert_eq!(t.as_str().parse::<TimeFeatures>(), Ok(t));
        }
        for l in LrSchedule::ALL {
            assert_eq!(l.as_str().parse::<LrSchedule>(), Ok(l));
        }
        assert_eq!(
            "day".parse::<TimeFeatures>(),
            Err("'day': expected none, hour or hour+schedule".to_string())
        );
        assert_eq!(
            "step".parse::<LrSchedule>(),
            Err("'step': expected constant or cosine".to_string())
        );
    }
}
