//! The output folder of a calibration: where each stage writes, named once. The driver,
//! the coordinator's run folder (`DATA/runs/<id>/out`), a worker's job folder and the report all
//! use this layout, as paths ([`OutputDir`]) or as the folder-relative names jobs carry
//! ([`OutputDir::point_rel`], [`STATES_FILE`], ...).

use bemcal_weather::grid::GridYear;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

use crate::error::{write_atomic, Error};

/// A chain-segment job's chain states at its end (and the next segment's input).
pub const STATES_FILE: &str = "states.json";
/// A chain-segment job's draws.
pub const DRAWS_FILE: &str = "draws.json";
/// Where a refinement round's first chain segment starts (unit space, one row per chain).
pub const WARM_FILE: &str = "warm.json";

/// The file name of point `i` (a design point, a refinement draw or a validation run) in its
/// folder; its EnergyPlus run directory is the same name without `.json`.
pub fn point_file(i: usize) -> String {
    format!("point_{i:03}.json")
}

/// Reads a record that a finished stage left in the output folder as JSON: the settled design
/// (`simulations/design.json`) and its failed attempts (`simulations/failures.json`), the
/// refinement rounds (`refine.json`), the final chains' record (`chains_summary.json`), the
/// chains' checkpoints, the steps of output space mapping (`validation/mapping.json`) and
/// `summary.json`. `Ok(None)` where the file cannot be read (not written yet); the parse error
/// where it does not parse, which each caller turns into what an unreadable record means for
/// it. The one reader of what a run already settled, so that a rerun or the coordinator's next
/// call goes on from it.
pub fn read_record<T: DeserializeOwned>(path: &Path) -> Result<Option<T>, serde_json::Error> {
    match std::fs::read(path) {
        Ok(bytes) => serde_json::from_slice(&bytes).map(Some),
        Err(_) => Ok(None),
    }
}

/// The output folder of one calibration. It dereferences to its root path.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputDir {
    root: PathBuf,
}

impl std::ops::Deref for OutputDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.root
    }
}

impl AsRef<Path> for OutputDir {
    fn as_ref(&self) -> &Path {
        &self.root
    }
}

impl OutputDir {
    /// The folder at `root`.
    pub fn new(root: impl Into<PathBuf>) -> OutputDir {
        OutputDir { root: root.into() }
    }

    /// `design.csv`: the Latin hypercube.
    pub fn design_csv(&self) -> PathBuf {
        self.root.join("design.csv")
    }

    /// `simulations/`: EnergyPlus at design points and refinement draws.
    pub fn simulations(&self) -> PathBuf {
        self.root.join("simulations")
    }

    /// `simulations/point_NNN.json`, relative to the folder (as jobs name it).
    pub fn point_rel(i: usize) -> String {
        format!("simulations/{}", point_file(i))
    }

    /// `validation/point_NNN.json`, relative to the folder (as jobs name it).
    pub fn validation_point_rel(i: usize) -> String {
        format!("validation/{}", point_file(i))
    }

    /// `dataset/`: the training set.
    pub fn dataset(&self) -> PathBuf {
        self.root.join("dataset")
    }

    /// `surrogate/`: the current surrogate.
    pub fn surrogate(&self) -> PathBuf {
        self.root.join("surrogate")
    }

    /// Folder of the pretrained surrogate folded onto this building, and the verdict
    /// (`[surrogate] pretrained`; [`crate::pretrained`]).
    pub fn pretrained(&self) -> PathBuf {
        self.root.join("pretrained")
    }

    /// `refine/round_R/` (1-based): a refinement round's chains and the surrogate they used.
    pub fn refine_round(&self, round: u32) -> PathBuf {
        self.root.join("refine").join(format!("round_{round}"))
    }

    /// `chains.json`: the final chains' checkpoint.
    pub fn chains_checkpoint(&self) -> PathBuf {
        self.root.join("chains.json")
    }

    /// `chains_summary.json`: the final chains' target (raised by each extension) and their
    /// summary at it, the driver's record of the extensions.
    pub fn chains_summary(&self) -> PathBuf {
        self.root.join("chains_summary.json")
    }

    /// `draws.csv`: the final chains' draws after burn-in.
    pub fn draws_csv(&self) -> PathBuf {
        self.root.join("draws.csv")
    }

    /// `discrepancy_cells.csv`: the likelihood's model-form discrepancy per calendar cell at
    /// the MAP draw (`mcmc.discrepancy`; [`crate::carried`]).
    pub fn discrepancy_cells_csv(&self) -> PathBuf {
        self.root.join("discrepancy_cells.csv")
    }

    /// `draws_with_surrogate_error.csv`: the draws with the surrogate's error added
    /// ([`crate::surrogate_error`]).
    pub fn draws_with_surrogate_error_csv(&self) -> PathBuf {
        self.root.join("draws_with_surrogate_error.csv")
    }

    /// `posterior_predictive.csv`: hourly bands with the meters.
    pub fn posterior_predictive_csv(&self) -> PathBuf {
        self.root.join("posterior_predictive.csv")
    }

    /// `validation/`: EnergyPlus at the estimate and the initial model.
    pub fn validation(&self) -> PathBuf {
        self.root.join("validation")
    }

    /// `validation/bases.csv`: the loads in the meters the model does not have.
    pub fn bases_csv(&self) -> PathBuf {
        self.validation().join("bases.csv")
    }

    /// `holdout.txt`: the held-out period the folder's chains were fitted without (`none`),
    /// a `not fitted:` line naming the meters they left out (`fit = false`), and a `fitted
    /// readings:` fingerprint of the series they fitted.
    pub fn holdout_txt(&self) -> PathBuf {
        self.root.join("holdout.txt")
    }

    /// `summary.json`.
    pub fn summary_json(&self) -> PathBuf {
        self.root.join("summary.json")
    }

    /// `calibrated.idf`: the model at the estimate, as EnergyPlus ran it.
    pub fn calibrated_idf(&self) -> PathBuf {
        self.root.join("calibrated.idf")
    }

    /// `calibrated.toml`: every parameter's value at the estimate.
    pub fn calibrated_toml(&self) -> PathBuf {
        self.root.join("calibrated.toml")
    }
}

/// The first `n` hour slots of `year` in time order, each with its hour-beginning stamp
/// (`YYYY-MM-DDTHH:MM`; the grid has no 29 February, [`bemcal_weather::grid`]): the rows of
/// every hourly CSV in the folder, which list a year from April from April on.
pub(crate) fn timestamps(year: GridYear, n: usize) -> Vec<(usize, String)> {
    year.chronological(n)
        .map(|t| (t, year.slot_time(t).format("%Y-%m-%dT%H:%M").to_string()))
        .collect()
}

/// Writes hourly outputs as `timestamp,<output>...`.
pub fn write_outputs_csv(
    path: &Path,
    year: bemcal_weather::grid::GridYear,
    o: &bemcal_energyplus::HourlyOutputs,
) -> Result<(), Error> {
    let mut s = format!("timestamp,{}\n", o.names.join(","));
    for (t, ts) in timestamps(year, o.hours()) {
        s.push_str(&ts);
        for series in &o.series {
            s.push_str(&format!(",{:.6}", series[t]));
        }
        s.push('\n');
    }
    write_atomic(path, s.as_bytes())
}
