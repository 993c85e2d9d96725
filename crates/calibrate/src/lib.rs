//! The calibration pipeline on one machine: project files, design points, training, chains,
//! validation and the summary.
//!
//! [`pipeline::calibrate`] runs every stage in order; each stage's results are written under the
//! output folder and reused by a rerun, so an interrupted calibration resumes. The stage
//! functions ([`design`], [`posterior`]) are what a distributed runner dispatches piecewise.

pub mod bases;
pub mod design;
pub mod pipeline;
pub mod posterior;
pub mod project;
pub mod refine;
pub mod replacement;
pub mod synth;

use std::path::{Path, PathBuf};

pub use pipeline::{calibrate, Summary};
pub use project::Project;

/// Errors of the pipeline, each naming the stage, file or setting concerned.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}:{line}: {message}")]
    Input {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("cannot access {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{0}")]
    Config(String),
    #[error("{stage}: {message}")]
    Stage {
        stage: &'static str,
        message: String,
    },
    #[error(transparent)]
    Simulation(#[from] bemcal_energyplus::Error),
    #[error(transparent)]
    Stats(#[from] bemcal_stats::StatsError),
    #[error(transparent)]
    Surrogate(#[from] bemcal_surrogate::SurrogateError),
    #[error(transparent)]
    Dataset(#[from] bemcal_surrogate::DatasetError),
    #[error(transparent)]
    Weather(#[from] bemcal_weather::WeatherError),
    #[error(transparent)]
    Meters(#[from] bemcal_precal::PrecalError),
}

impl Error {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Error {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

/// Writes a file so that readers never see a partial one (temporary file + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), Error> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    }
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, bytes).map_err(|e| Error::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}
