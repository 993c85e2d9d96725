//! Pre-calibration (reference section 2.2): meter ingestion, base-load disaggregation, DTW
//! day-type clustering and informative schedule priors.
//!
//! Stages, each a module of pure functions on slices (I/O only in [`io`]):
//!
//! 1. [`meters`]: a meters CSV + [`meters::MeterSpec`] -> [`meters::MeterData`], kWh per hour on
//!    the 8,760 hour-beginning slots of one year (local standard time), with a quality summary.
//! 2. [`disaggregate`]: heating base (domestic hot water), cooling base (labs, mechanical rooms)
//!    and electricity base (data center / night base), each an estimate with a `method` string.
//! 3. [`schedule`] + [`dtw`] + [`cluster`]: normalised daily electricity profiles, pairwise DTW
//!    with a Sakoe-Chiba band, k-medoids (PAM) day-type clusters labelled by what their days look
//!    like (the calendar where the profiles do not tell; [`advice`] says what to change),
//!    per day type and hour box-plot quartiles -> triangular priors -> merged schedule intervals.
//! 4. [`pipeline::run`] ties them together; [`io`] writes `priors.toml` and the reports.
#![deny(missing_docs)]

pub mod advice;
pub mod cluster;
pub mod disaggregate;
pub mod dtw;
pub mod io;
pub mod meters;
pub mod pipeline;
pub mod schedule;
pub mod stats;

use std::path::PathBuf;

/// Errors of the pre-calibration stage. Input errors name the file, line and column.
#[derive(Debug, thiserror::Error)]
pub enum PrecalError {
    /// A file could not be read or written (the operating system's reason is the source,
    /// which the error's chain prints after this).
    #[error("cannot access {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A meters CSV row or field is unusable.
    #[error("{path}:{line}: column '{}': {}", bemcal_excerpt::excerpt(.column, 80), bemcal_excerpt::shorten(.message))]
    Meter {
        /// The meters file.
        path: PathBuf,
        /// 1-based line number in the file (the header is line 1).
        line: u64,
        /// The column name.
        column: String,
        /// What is wrong.
        message: String,
    },
    /// A meters CSV or spec problem not tied to one row (missing column, no data, ...).
    #[error("{path}: {}", bemcal_excerpt::shorten(.message))]
    MeterFile {
        /// The meters file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Invalid options or inconsistent inputs.
    #[error("{}", bemcal_excerpt::shorten(.0))]
    Invalid(String),
}
