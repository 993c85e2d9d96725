//! The calibration: its inputs, stages and rules, and the local driver that runs them in order.
//!
//! One file per stage, in the order the data flows: [`inputs`](load_inputs) (model, weather,
//! meters, bases) -> [`design`] (Latin hypercube, EnergyPlus runs, [`replacement`] of failed
//! points) -> training set and surrogate ([`Calibration`]) -> chains ([`Sampler`], [`posterior`])
//! -> [`refine`]ment rounds -> the [`surrogate_error`] carried into the intervals -> validation
//! -> [`predictive`] intervals and [`model_form`] (can the model reach each meter) -> summary
//! ([`write_summary`]). [`calibrate`] runs
//! every stage on this machine; the coordinator runs the same stage methods as jobs. Each stage's
//! results are written under the output folder and reused by a rerun, so an interrupted
//! calibration resumes.

pub mod bases;
mod calibration;
mod chains;
pub mod design;
pub mod examples;
mod inputs;
mod local;
pub mod model_form;
pub use bemcal_named as named;
pub mod output;
pub mod posterior;
pub mod predictive;
pub mod project;
pub mod refine;
pub mod replacement;
pub mod sequence;
pub mod submitted;
mod summary;
pub mod surrogate_error;
pub mod synth;
mod validation;

use std::path::{Path, PathBuf};

pub use calibration::{Calibration, Log};
pub use chains::{
    chains_at, extended_target, independence_dropped, moved_chains, ChainSummary, MovedChain,
    Sampler,
};
pub use inputs::{
    load_inputs, load_model, resolve_weather, weather_for, weather_reference, HeldOut, Inputs,
};
pub use local::{calibrate, log_design_outcome};
pub use output::OutputDir;
pub use project::Project;
pub use summary::{
    write_calibrated_model, write_outputs_csv, write_summary, DesignReport, HoldoutReport,
    OutputMetrics, ParameterReport, PeriodMetrics, PointNote, Summary, Timings, NOT_CONVERGED_EXIT,
};
pub use validation::{
    fallback_note, next_candidate, Candidate, ValidationStep, FALLBACKS, INITIAL_KEY,
};

/// Errors of the pipeline, each naming the stage, file or setting concerned.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}:{line}: {}", bemcal_excerpt::shorten(.message))]
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
    #[error("{}", bemcal_excerpt::shorten(.0))]
    Config(String),
    #[error("{stage}: {}", bemcal_excerpt::shorten(.message))]
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

/// Writes a file so that readers never see a partial one, durably ([`bemcal_durable`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), Error> {
    bemcal_durable::write_atomic(path, bytes).map_err(|e| Error::io(path, e))
}
