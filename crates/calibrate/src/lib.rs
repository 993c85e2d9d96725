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
#![deny(missing_docs)]

pub mod bases;
mod calibration;
mod chain_summary;
mod chains;
pub mod crossval;
pub mod design;
pub mod driver;
mod error;
pub mod estimate;
pub mod examples;
mod inputs;
pub mod keys;
mod local;
pub mod mapping;
pub mod metrics;
pub mod model_form;
pub use bemcal_named as named;
pub mod output;
pub mod plan;
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
pub use project::Project;
pub use summary::{
    write_calibrated_model, write_summary, DesignReport, HoldoutReport, ParameterReport, PointNote,
    Summary, Timings, NOT_CONVERGED_EXIT,
};
pub use validation::{next_candidate, Candidate, ValidationStep};
