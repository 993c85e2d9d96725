//! The calibration: its inputs, stages and rules, and the one driver that runs them in order.
//!
//! One file per stage, in the order the data flows: [`inputs`](load_inputs) (model, weather,
//! meters, bases) -> [`design`] (Latin hypercube, EnergyPlus runs, [`replacement`] of failed
//! points) -> training set and surrogate ([`Calibration`]) -> chains ([`Sampler`], [`posterior`])
//! -> [`refine`]ment rounds -> the [`surrogate_error`] carried into the intervals -> validation
//! -> [`predictive`] intervals and [`model_form`] (can the model reach each meter) -> summary
//! ([`write_summary`]). One [`driver`] sequences the stages and takes every decision; an
//! [`driver::Executor`] does the work: [`calibrate`] in this process, the coordinator as jobs
//! leased to workers. Each stage's results are written under the output folder and reused by
//! a rerun, so an interrupted calibration resumes.
//!
//! The modules stand in three layers. A module imports only from the layers below its own and
//! from the modules listed before it in its layer, by module path (this file's re-exports are
//! the crate's API for the CLI, the coordinator and the worker, not for the modules):
//!
//! 1. Settings, records and rules, no stage's work: `error` ([`Error`]), [`keys`] (every
//!    EnergyPlus run's key), [`output`] (the folder's layout and the one reader of what a run
//!    settled, [`output::read_record`]), [`project`], [`submitted`], [`plan`], [`metrics`]
//!    (Guideline 14 and [`best_simulated`]), [`mapping`], [`estimate`], [`replacement`],
//!    [`bases`], [`stage`] (the stages' names), [`measures`] (retrofit measures and their
//!    savings' records).
//! 2. The stages' work, in the order the data flows: `inputs`, [`design`], `pretrained`,
//!    `calibration`,
//!    [`posterior`], `chains`, [`refine`], [`surrogate_error`], `chain_summary`, `validation`,
//!    [`predictive`], [`model_form`], `summary`, and after a finished calibration
//!    [`savings`] (retrofit measures' savings over posterior draws).
//! 3. The driver: [`sequence`] (its rules), [`driver`], `local` (the in-process executor),
//!    [`crossval`].
//!
//! [`examples`] and [`synth`] stand apart.

#![deny(missing_docs)]

// 1. Settings, records and rules.
pub mod bases;
pub mod bills;
pub mod carried;
mod error;
pub mod estimate;
pub mod keys;
pub mod mapping;
pub mod measures;
pub mod metrics;
pub mod output;
pub mod plan;
pub mod project;
pub mod replacement;
pub mod stage;
pub mod submitted;

// 2. The stages' work.
mod calibration;
mod chain_summary;
mod chains;
pub mod design;
mod inputs;
pub mod model_form;
pub mod posterior;
pub mod predictive;
mod pretrained;
pub mod refine;
pub mod savings;
mod summary;
pub mod surrogate_error;
mod validation;

// 3. The driver.
pub mod crossval;
pub mod driver;
mod local;
pub mod sequence;

// Apart: the bundled examples and synthetic meters.
pub mod examples;
pub mod synth;

pub use bemcal_named as named;
pub use calibration::{Calibration, FittedData, Log};
pub use chain_summary::ChainSummary;
pub use chains::{
    chains_at, extended_target, independence_dropped, moved_chains, MovedChain, Sampler,
};
pub use driver::log_design_outcome;
pub use error::{write_atomic, Error};
pub use estimate::{fallback_note, EstimateChoice, SimulatedFit};
pub use inputs::{
    load_inputs, load_model, resolve_weather, weather_for, weather_reference, HeldOut, Inputs,
};
pub use keys::{FALLBACKS, INITIAL_KEY};
pub use local::{calibrate, stage_seconds};
pub use metrics::{
    best_simulated, limit_ratio, monthly_limit_ratio, Fit, OutputMetrics, PeriodMetrics,
};
pub use output::{write_outputs_csv, OutputDir};
pub use posterior::Drawn;
pub use pretrained::SurrogateStart;
pub use project::{project_schema, Project};
pub use summary::{
    summary_schema, write_calibrated_model, write_summary, DesignReport, HoldoutReport,
    MeasuredHours, ParameterReport, PointNote, Summary, Timings, NOT_CONVERGED_EXIT,
};
pub use validation::{next_candidate, Candidate, ValidationStep};
