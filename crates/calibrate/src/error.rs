//! The crate's one error type ([`Error`]: each names the stage, file or setting concerned) and
//! its atomic, durable file write ([`write_atomic`]).

use std::path::{Path, PathBuf};

/// Errors of the pipeline, each naming the stage, file or setting concerned.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file (the project, priors, a saved result) is unreadable or malformed, or a setting in
    /// it does not fit the model or the meters.
    #[error("{path}:{line}: {}", bemcal_excerpt::shorten(.message))]
    Input {
        /// The file.
        path: PathBuf,
        /// The line at fault (0: the file as a whole).
        line: usize,
        /// What was expected, with a short excerpt of what was found.
        message: String,
    },
    /// A file or folder could not be read or written.
    #[error("cannot access {path}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// Settings that do not fit the inputs, the model or the output folder's earlier results;
    /// also failures tied to no file (the thread pool, encoding JSON).
    #[error("{}", bemcal_excerpt::shorten(.0))]
    Config(String),
    /// A stage could not go on with what the earlier stages left.
    #[error("{stage}: {}", bemcal_excerpt::shorten(.message))]
    Stage {
        /// The stage: a [`crate::stage::Stage`]'s name (`Stage::Design.as_str()`,
        /// `Stage::Chains.as_str()`) or a finer step's ("training set", "surrogate",
        /// "refinement", "validation").
        stage: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The executor could not start or read back its work (the coordinator's store, an
    /// artifact, a worker's result that does not answer its job).
    #[error("{}", bemcal_excerpt::shorten(.0))]
    Executor(String),
    /// From the simulation layer: EnergyPlus, the model and parameters, TOML files.
    #[error(transparent)]
    Simulation(#[from] bemcal_energyplus::Error),
    /// From the numerics (priors, statistics, designs).
    #[error(transparent)]
    Stats(#[from] bemcal_stats::StatsError),
    /// From loading or evaluating the surrogate.
    #[error(transparent)]
    Surrogate(#[from] bemcal_surrogate::SurrogateError),
    /// From building, writing or reading the training set.
    #[error(transparent)]
    Dataset(#[from] bemcal_surrogate::DatasetError),
    /// From reading the weather files.
    #[error(transparent)]
    Weather(#[from] bemcal_weather::WeatherError),
    /// From reading the meters (the pre-calibration stage).
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

/// Writes a file so that readers never see a partial one, durably ([`bemcal_durable`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), Error> {
    bemcal_durable::write_atomic(path, bytes).map_err(|e| Error::io(path, e))
}
