//! The building family's corpus for the pretrained surrogate.
//!
//! A corpus is many EnergyPlus years of *generated* buildings: building specs drawn over the
//! spec space (storeys, footprint, floor-to-floor height, zoning, window-to-wall ratio, heating
//! source, HVAC system, occupied hours, schedule intervals) x climates x wide population draws
//! of each building's calibration parameters. A network trained on it once, conditioned on the
//! building's descriptors, is then fine-tuned per building on a few of its own simulations
//! instead of being trained from nothing (issue 66).
//!
//! The data flow reads in module order:
//! - [`manifest`]: what to draw (a TOML file and a seed); the same manifest and seed give the
//!   same cases, and a corpus of `n` cases is the first `n` of a larger one.
//! - [`draw`]: pure: the case at an index (spec, climate, parameter values).
//! - [`store`]: the corpus folder: one float16 array per finished case, an index of them and of
//!   the failures, the climates' hourly features once each.
//! - [`build`]: runs the missing cases with EnergyPlus, in parallel, resumable.
//!
//! Every case is keyed by its content and [`bemcal_energyplus::SIMULATION_REVISION`]: a rerun
//! skips what is done (and what failed: a failure is data, recorded with its reason), and a
//! change of the simulation's revision makes every case new.

#![deny(missing_docs)]

pub mod build;
pub mod draw;
pub mod manifest;
pub mod store;

use std::path::PathBuf;

/// Errors reading a manifest or writing a corpus.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The manifest is not what was expected (file, line, what).
    #[error("{}:{line}: {}", path.display(), bemcal_excerpt::shorten(.message))]
    Manifest {
        /// The manifest file.
        path: PathBuf,
        /// Its line (0: unknown).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A file of the corpus could not be read or written.
    #[error("{}: {}", path.display(), bemcal_excerpt::shorten(.message))]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// EnergyPlus or the model refused a case as a whole (not one case's failure, which is
    /// recorded as data).
    #[error(transparent)]
    EnergyPlus(#[from] bemcal_energyplus::Error),
}

pub(crate) fn io_err(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Error {
    let path = path.into();
    move |e| Error::Io {
        path,
        message: e.to_string(),
    }
}
