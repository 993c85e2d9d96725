//! Cross-validation by month: each calendar month held out in turn (`[validation] holdout`),
//! so that every month is judged by a calibration that never saw it; the held-out months
//! together give Guideline 14 and predictive coverage out of sample, for a record too short to
//! spare a held-out season.
//!
//! Twelve folds would be twelve calibrations. What does not depend on the meters is shared:
//! the design points' EnergyPlus runs and the first surrogate (trained on those runs alone:
//! no meter enters it) come from one calibration on every month (`all/`), whose folder seeds
//! each fold's (`fold_MM/`); each fold runs its own chains, refinement rounds (their draws come
//! from the fold's posterior) and validation runs. A fold costs its chains and a few
//! EnergyPlus runs instead of a calibration. The priors are the project's: priors from a
//! pre-calibration of the whole record have seen each fold's month (pre-calibrate per fold for
//! a strict check).

use std::path::{Path, PathBuf};

use bemcal_stats::metrics::{g14_of_totals, g14_pooled, G14Metrics};
use bemcal_stats::predictive::{pooled_coverage, Coverage};
use serde::{Deserialize, Serialize};

use crate::calibration::Log;
use crate::error::Error;
use crate::local::calibrate;
use crate::output::OutputDir;
use crate::project::Project;
use crate::summary::Summary;

/// The months' names as a held-out period takes them.
pub const MONTHS: [&str; 12] = [
    "jan", "feb", "mar", "apr", "may", "jun", "jul", "aug", "sep", "oct", "nov", "dec",
];

/// `crossval.json` in the cross-validation's folder.
pub const CROSSVAL_FILE: &str = "crossval.json";

/// One fold: a month held out, and how the calibration without it did there.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Fold {
    /// The month held out, 1-12.
    pub month: u32,
    /// Why the fold's calibration failed (its outputs are then empty).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Whether its chains met the convergence targets.
    pub converged: bool,
    /// Its calibration's wall time (s).
    pub seconds: f64,
    /// Per meter, on the held-out month.
    pub outputs: Vec<FoldOutput>,
}

/// One meter on a fold's held-out month.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FoldOutput {
    /// The calibrated output (and its meter).
    pub output: String,
    /// Hourly Guideline 14 of EnergyPlus at the fold's estimate (none where the month has
    /// no measured hour of this meter, or their mean is zero).
    pub held_out: Option<G14Metrics>,
    /// Coverage of the hourly 50 % and 90 % predictive intervals (the project's error model);
    /// empty without predictive draws.
    pub coverage: Vec<Coverage>,
}

/// One meter over every held-out month.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PooledOutput {
    /// The calibrated output (and its meter).
    pub output: String,
    /// Hourly Guideline 14 of the calibration on every month, in sample, for comparison.
    pub in_sample: Option<G14Metrics>,
    /// Hourly Guideline 14 over the held-out hours of every fold.
    pub hourly: Option<G14Metrics>,
    /// Guideline 14 of the held-out months' totals (monthly criteria).
    pub monthly: Option<G14Metrics>,
    /// Predictive coverage over the held-out hours of every fold, per level.
    pub coverage: Vec<Coverage>,
    /// The calibrations fitted this meter (false: `fit = false`, held out and compared only).
    #[serde(default = "fitted")]
    pub fitted: bool,
    /// Months whose fold ran but gave this meter no Guideline 14 (no measured hour, or a zero
    /// measured mean): the pooled Guideline 14 leaves them out.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub months_without_figures: Vec<u32>,
}

fn fitted() -> bool {
    true
}

/// `crossval.json`: the folds and their pooled figures.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CrossValidation {
    /// The calibration on every month (`all/`): its wall time (s), whose design and first
    /// surrogate every fold reuses.
    pub shared_seconds: f64,
    /// Design points simulated once for all folds.
    pub design_points: usize,
    /// The folds, by month.
    pub folds: Vec<Fold>,
    /// Per meter, over every fold.
    pub pooled: Vec<PooledOutput>,
}

/// The project of the fold holding out `month` (1-12).
pub fn fold_project(project: &Project, month: u32) -> Result<Project, Error> {
    let name = MONTHS
        .get(month.wrapping_sub(1) as usize)
        .ok_or_else(|| Error::Config(format!("month {month}: expected 1 to 12")))?;
    let mut p = project.clone();
    p.validation.holdout = Some(name.parse().map_err(Error::Config)?);
    Ok(p)
}

/// A fold's figures from its summary (pure).
pub fn fold_of(month: u32, s: &Summary) -> Fold {
    let outputs = s
        .validation
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let held_out = m.held_out.as_ref().map(|h| h.hourly);
            let coverage = s
                .predictive
                .as_ref()
                .and_then(|p| p.outputs.get(k))
                .and_then(|o| o.by_error_model.first())
                .map(|c| c.coverage.held_out.clone())
                .unwrap_or_default();
            FoldOutput {
                output: m.output.clone(),
                held_out,
                coverage,
            }
        })
        .collect();
    Fold {
        month,
        error: None,
        converged: s.converged,
        seconds: s.timings.total_s,
        outputs,
    }
}

/// Per meter, the folds pooled (pure): Guideline 14 of every held-out hour, of the held-out
/// months' totals, and the predictive coverage of every held-out hour per level.
pub fn pool(all: &Summary, folds: &[Fold]) -> Vec<PooledOutput> {
    all.outputs
        .iter()
        .map(|name| {
            let mine: Vec<&FoldOutput> = folds
                .iter()
                .flat_map(|f| f.outputs.iter().filter(|o| &o.output == name))
                .collect();
            let parts: Vec<G14Metrics> = mine.iter().filter_map(|o| o.held_out).collect();
            let months_without_figures = folds
                .iter()
                .filter(|f| f.error.is_none())
                .filter(|f| {
                    f.outputs
                        .iter()
                        .any(|o| &o.output == name && o.held_out.is_none())
                })
                .map(|f| f.month)
                .collect();
            let levels: Vec<f64> = mine
                .first()
                .map(|o| o.coverage.iter().map(|c| c.nominal).collect())
                .unwrap_or_default();
            let coverage = levels
                .iter()
                .filter_map(|l| {
                    let at: Vec<Coverage> = mine
                        .iter()
                        .flat_map(|o| o.coverage.iter().filter(|c| c.nominal == *l).copied())
                        .collect();
                    pooled_coverage(&at)
                })
                .collect();
            PooledOutput {
                output: name.clone(),
                in_sample: all
                    .validation
                    .iter()
                    .find(|m| &m.output == name)
                    .map(|m| m.metrics),
                hourly: g14_pooled(&parts).ok(),
                monthly: g14_of_totals(&parts).ok(),
                coverage,
                fitted: !all.not_fitted.contains(name),
                months_without_figures,
            }
        })
        .collect()
}

/// Cross-validates `project` by month into `out`: the calibration on every month in
/// `out/all`, then one fold per month of `months` in `out/fold_MM` (seeded from `all/`), then
/// `out/crossval.json`. A fold whose calibration fails is recorded with its reason and the
/// others go on. A rerun reuses every finished fold.
pub fn cross_validate(
    project: &Project,
    out: &Path,
    months: &[u32],
    log: Log<'_>,
) -> Result<CrossValidation, Error> {
    if let Some(h) = &project.validation.holdout {
        return Err(Error::Config(format!(
            "cross-validation holds out each month in turn: remove `holdout = \"{h}\"` from \
             [validation]"
        )));
    }
    if !project.meters.bills.is_empty() {
        return Err(Error::Config(
            "cross-validation by month judges hourly meters month by month: a project with \
             [[meters.bills]] is not cross-validated yet (hold bills out with [validation] \
             holdout instead)"
                .into(),
        ));
    }
    let base = out.join("all");
    log("cross-validation: the calibration on every month (all/)");
    let all = calibrate(project, &base, log)?;
    let mut months = months.to_vec();
    months.sort_unstable();
    months.dedup();
    let mut folds = vec![];
    for &month in &months {
        let fold_project = fold_project(project, month)?;
        let dir = out.join(format!("fold_{month:02}"));
        let name = MONTHS[month as usize - 1];
        seed_fold(&OutputDir::new(&base), &OutputDir::new(&dir))?;
        let fold_log = |m: &str| log(&format!("fold {name}: {m}"));
        let fold = match calibrate(&fold_project, &dir, &fold_log) {
            Ok(s) => fold_of(month, &s),
            Err(e) => {
                log(&format!("fold {name}: failed: {e}"));
                Fold {
                    month,
                    error: Some(e.to_string()),
                    converged: false,
                    seconds: 0.0,
                    outputs: vec![],
                }
            }
        };
        folds.push(fold);
    }
    let cv = CrossValidation {
        shared_seconds: all.timings.total_s,
        design_points: all.design.simulated,
        pooled: pool(&all, &folds),
        folds,
    };
    let json = serde_json::to_vec_pretty(&cv).map_err(|e| Error::Config(e.to_string()))?;
    crate::error::write_atomic(&out.join(CROSSVAL_FILE), &json)?;
    Ok(cv)
}

/// Lays what the folds share into a fold's folder (once): the design (`design.csv`,
/// `simulations/`, hard-linked where the file system allows) and the first surrogate (the
/// design's: `refine/round_1/surrogate` when refinement moved it there).
fn seed_fold(base: &OutputDir, fold: &OutputDir) -> Result<(), Error> {
    let sims = fold.simulations();
    std::fs::create_dir_all(&sims).map_err(|e| Error::io(&sims, e))?;
    let from = base.simulations();
    for entry in std::fs::read_dir(&from).map_err(|e| Error::io(&from, e))? {
        let path = entry.map_err(|e| Error::io(&from, e))?.path();
        let to = sims.join(path.file_name().unwrap_or_default());
        if path.is_file() && !to.exists() {
            link_or_copy(&path, &to)?;
        }
    }
    let csv = fold.design_csv();
    if !csv.exists() {
        link_or_copy(&base.design_csv(), &csv)?;
    }
    // The design's surrogate: where a refinement round ran in `all/` (now or in an earlier
    // run of the folder), the one it moved aside; the folder's last surrogate saw draws of a
    // posterior fitted on every month.
    let moved = base.refine_round(1).join("surrogate");
    let first = match moved.is_dir() {
        true => moved,
        false => base.surrogate(),
    };
    let to = fold.surrogate();
    let fitted =
        fold.chains_checkpoint().exists() || fold.join(crate::refine::REFINE_FILE).exists();
    if !to.exists() && !fitted {
        // Copied aside and renamed whole: an interrupted copy is never taken for a surrogate.
        let partial = to.with_extension("partial");
        if partial.exists() {
            std::fs::remove_dir_all(&partial).map_err(|e| Error::io(&partial, e))?;
        }
        copy_dir(&first, &partial)?;
        std::fs::rename(&partial, &to).map_err(|e| Error::io(&to, e))?;
    }
    Ok(())
}

/// A hard link of `from` at `to`, or a copy where links are refused.
fn link_or_copy(from: &Path, to: &Path) -> Result<(), Error> {
    if std::fs::hard_link(from, to).is_err() {
        std::fs::copy(from, to).map_err(|e| Error::io(to, e))?;
    }
    Ok(())
}

/// A copy of folder `from` (files and sub-folders) at `to`.
fn copy_dir(from: &Path, to: &Path) -> Result<(), Error> {
    std::fs::create_dir_all(to).map_err(|e| Error::io(to, e))?;
    for entry in std::fs::read_dir(from).map_err(|e| Error::io(from, e))? {
        let path: PathBuf = entry.map_err(|e| Error::io(from, e))?.path();
        let dest = to.join(path.file_name().unwrap_or_default());
        if path.is_dir() {
            copy_dir(&path, &dest)?;
        } else {
            std::fs::copy(&path, &dest).map_err(|e| Error::io(&dest, e))?;
        }
    }
    Ok(())
}
