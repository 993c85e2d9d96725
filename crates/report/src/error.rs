//! The crate's errors: why a report could not be written ([`ReportError`]), and why a figure
//! could not be drawn ([`PlotError`]).

use std::path::PathBuf;

/// Why a report could not be written. Each variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A required file or folder does not exist.
    #[error("{}: missing ({what})", path.display())]
    Missing {
        /// The path looked for.
        path: PathBuf,
        /// What it should contain.
        what: String,
    },
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A file is not in the expected format.
    #[error("{}: {}", path.display(), bemcal_excerpt::shorten(.msg))]
    Parse {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A figure could not be drawn.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// A figure could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("drawing a figure: {0}")]
pub struct PlotError(pub String);
