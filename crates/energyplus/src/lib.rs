//! EnergyPlus 25.2: engine discovery, isolated runs, hourly meter output, and parametric building
//! models with named calibration parameters.
//!
//! - [`engine::Engine`] finds the `energyplus` executable (bemcal's `.venv` or `$BEMCAL_ENERGYPLUS`).
//! - [`model::Model`] is what gets calibrated: a generated building ([`building::BuildingSpec`]) or
//!   a user's IDF with a parameter map ([`model::ParameterMap`]); it lists its parameters with
//!   priors and turns a set of values into an IDF, refusing physically impossible combinations.
//! - [`runner::Runner`] runs one simulation in its own directory, treats `** Severe` / `** Fatal`
//!   in `eplusout.err` as failure whatever the exit code, and returns hourly outputs in kWh.

pub mod building;
pub mod engine;
pub mod errfile;
pub mod idd;
pub mod idf;
pub mod meters;
pub mod model;
pub mod params;
pub mod runner;

use std::path::PathBuf;

pub use building::BuildingSpec;
pub use engine::Engine;
pub use meters::{HourlyOutputs, OutputSpec};
pub use model::Model;
pub use params::{ParameterDef, ParameterValues, TriangularPrior};
pub use runner::{RunOptions, Runner};

/// Revision of what the runner and the model generator make of a given spec and parameter
/// values. Caches of simulation results key on it: bump it whenever the same inputs would now
/// simulate differently.
pub const SIMULATION_REVISION: u32 = 2;

/// Errors of the simulation layer. Each names the file, line, parameter or run directory
/// concerned.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// EnergyPlus could not be found.
    #[error("EnergyPlus not found: {0}")]
    EngineNotFound(String),
    /// A file could not be read or written.
    #[error("cannot access {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A model, spec or parameter-map file is malformed.
    #[error("{path}:{line}: {}", bemcal_excerpt::shorten(.message))]
    Input {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// A parameter is unknown, missing, out of range or violates a constraint.
    #[error("parameter {}: {}", bemcal_excerpt::excerpt(.name, 80), bemcal_excerpt::shorten(.message))]
    Parameter { name: String, message: String },
    /// EnergyPlus ran but failed (severe/fatal errors, missing output).
    #[error("EnergyPlus failed in {dir}: {message}\n{}", .details.join("\n"))]
    Simulation {
        dir: PathBuf,
        message: String,
        details: Vec<String>,
    },
    /// EnergyPlus exceeded its time limit and was killed.
    #[error("EnergyPlus exceeded its time limit of {seconds} s in {dir}")]
    Timeout { dir: PathBuf, seconds: u64 },
}

/// Parses TOML text into `T`; an error names the file and the line of the offending key.
pub fn parse_toml<T: serde::de::DeserializeOwned>(
    text: &str,
    path: &std::path::Path,
) -> Result<T, Error> {
    toml::from_str(text).map_err(|e| Error::Input {
        path: path.to_path_buf(),
        line: e
            .span()
            .map(|s| text[..s.start].matches('\n').count() + 1)
            .unwrap_or(0),
        message: e.message().to_string(),
    })
}

pub(crate) fn io_err(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Error {
    let path = path.into();
    move |source| Error::Io { path, source }
}
