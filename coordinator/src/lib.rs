//! The bemcal coordinator: the SQLite state of runs, stages, jobs, leases, attempts and
//! artifacts, and the driver that walks each run through the calibration stages, dispatching
//! EnergyPlus runs, training, chain segments and validation to pull-based workers and doing the
//! cheap stages (design, training set, merge, summary) itself.
//!
//! The protocol and the client side (channel, artifacts, bundles) are `bemcal-client`,
//! re-exported here under their old paths.
#![deny(missing_docs)]

pub mod audit;
pub mod db;
pub mod driver;
pub mod metrics;
pub mod portfolio;
pub mod server;
pub mod service;
pub mod states;

pub use bemcal_client::{
    artifacts, auth, bundle, client, excerpt, now_ms, proto, runtime, shutdown_signal, CHUNK_BYTES,
    MAX_ERROR_BYTES, MAX_MESSAGE_BYTES,
};
