//! The first training's start from the building family's pretrained surrogate (`[surrogate]
//! pretrained`, issue 66): the network folded onto this building
//! ([`bemcal_surrogate::pretrained`]) is the warm start the trainer fine-tunes, or, where it
//! cannot be (an own IDF, a building outside the corpus's ranges, a parameter or meter it does
//! not know, another surrogate shape), the surrogate starts from random weights as before and
//! the reason is recorded. The verdict lives in the output folder's `pretrained/pretrained.json`
//! (`OutputDir::pretrained`); [`read_start`] gives it to the summary.

use std::path::{Path, PathBuf};

use bemcal_surrogate::pretrained::{self as fold, Building, FoldVerdict};
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::inputs::Inputs;
use crate::project::SurrogateSettings;

/// How the surrogate's first training started, where `[surrogate] pretrained` names a
/// pretrained network (`summary.json`'s `surrogate_start`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case", tag = "from")]
pub enum SurrogateStart {
    /// The pretrained network folded onto the building, then fine-tuned on its design points.
    Pretrained {
        /// The pretrained folder.
        pretrained: String,
        /// Cases of the corpus it was pretrained on.
        corpus_cases: usize,
    },
    /// Random weights: the pretrained network could not start this building's surrogate.
    Scratch {
        /// Why.
        reason: String,
    },
}

/// The folder of the pretrained network `reference` (`[surrogate] pretrained`) names: a
/// folder, relative to the project file, or a network shipped in the binary (`bundled:NAME`),
/// written into `out/network` for the fold to read.
pub fn source(project: &crate::Project, reference: &Path, out: &Path) -> Result<PathBuf, Error> {
    match fold::bundled_name(reference) {
        None => Ok(project.resolve(reference)),
        Some(Err(e)) => Err(Error::Config(format!("surrogate.pretrained: {e}"))),
        Some(Ok(name)) => {
            let dir = out.join("network");
            fold::write_bundled(name, &dir)?;
            Ok(dir)
        }
    }
}

/// Folds the pretrained network of `settings.pretrained` (its folder found by the caller,
/// [`source`]: `dir`)
/// onto the building of `inp`, whose training set is `dataset`, into `out`: the warm start's
/// folder, or None when it cannot start this building's surrogate (the reason written there).
pub fn start(
    inp: &Inputs,
    settings: &SurrogateSettings,
    dir: &Path,
    dataset: &Path,
    out: &Path,
) -> Result<Option<PathBuf>, Error> {
    let verdict = match inp.model.spec() {
        None => {
            let v = FoldVerdict::Refused {
                reason: "the model is an own IDF; the pretrained network knows the generated \
                         building family only"
                    .into(),
            };
            fold::write_verdict(out, &v)?;
            v
        }
        Some(spec) if spec.has_partial_days() => {
            let v = FoldVerdict::Refused {
                reason: "the calendar has partial days (day_types_file); the pretrained network \
                         knows working days and days off only"
                    .into(),
            };
            fold::write_verdict(out, &v)?;
            v
        }
        Some(spec) => {
            // Every parameter's value: the fixed ones as the plan keeps them, the calibrated
            // at their prior modes (the design points replace them in the fold).
            let mut values = inp.plan.fixed.clone();
            for (name, prior) in inp.plan.calibrated.iter().zip(&inp.plan.priors) {
                values.insert(name.clone(), prior.mode());
            }
            let building = Building {
                spec,
                floor_area_m2: spec.floor_area_m2(),
                values: &values,
            };
            let time_features = &settings.time_features;
            fold::fold(
                dir,
                dataset,
                &building,
                settings.hidden,
                time_features,
                out,
                None,
            )?
        }
    };
    // A bundled network is recorded by its name, not the folder it was written to.
    if let (FoldVerdict::Admitted { .. }, Some(reference)) = (&verdict, &settings.pretrained) {
        if fold::bundled_name(reference).is_some() {
            fold::relabel_verdict(out, reference)?;
        }
    }
    Ok(match verdict {
        FoldVerdict::Admitted { .. } => Some(out.to_path_buf()),
        FoldVerdict::Refused { .. } => None,
    })
}

/// Copies the start's verdict from the folder `from` (the fold's, or the surrogate a
/// retraining warm-starts from) into the surrogate folder `to`, so that it travels with the
/// surrogate (from a worker, and through the refinement rounds) to the summary; removes a stale
/// one where there is none to carry.
pub fn carry(from: Option<&Path>, to: &Path) -> Result<(), Error> {
    let target = to.join(fold::VERDICT_FILE);
    match from
        .map(|d| d.join(fold::VERDICT_FILE))
        .filter(|f| f.is_file())
    {
        Some(source) => std::fs::copy(&source, &target)
            .map(|_| ())
            .map_err(|e| Error::io(&source, e)),
        None if target.is_file() => {
            std::fs::remove_file(&target).map_err(|e| Error::io(&target, e))
        }
        None => Ok(()),
    }
}

/// The verdict of the fold, in the first of `dirs` that has one: the fold's folder
/// (`OutputDir::pretrained`) or a surrogate's folder it was carried into ([`carry`]).
fn first_verdict(dirs: &[&Path]) -> Option<FoldVerdict> {
    dirs.iter().find_map(|d| fold::read_verdict(d).ok())
}

/// The family record ([`bemcal_surrogate::pretrained::Family`]) the fold found beside the
/// pretrained network, as recorded in the first verdict of `dirs` ([`first_verdict`]). None
/// for a building whose surrogate did not start from a network with one.
pub fn family(dirs: &[&Path]) -> Option<fold::Family> {
    match first_verdict(dirs)? {
        FoldVerdict::Admitted { family, .. } => family,
        FoldVerdict::Refused { .. } => None,
    }
}

/// The start recorded in the first verdict of `dirs` ([`first_verdict`]), if a pretrained
/// network was asked for.
pub fn read_start(dirs: &[&Path]) -> Option<SurrogateStart> {
    Some(match first_verdict(dirs)? {
        FoldVerdict::Admitted {
            pretrained,
            corpus_cases,
            ..
        } => SurrogateStart::Pretrained {
            pretrained: pretrained.display().to_string(),
            corpus_cases,
        },
        FoldVerdict::Refused { reason } => SurrogateStart::Scratch { reason },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The family record is read from the first folder with a verdict; a refused start, or
    /// none, has no family.
    #[test]
    fn the_family_comes_from_the_first_verdict_found() {
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        assert_eq!(family(&[a.path(), b.path()]), None);
        let rec = fold::Family {
            measured: "m".into(),
            buildings: vec![fold::FamilyBuilding {
                name: "x".into(),
                ratios: [("p".to_string(), 2.0)].into(),
            }],
        };
        let admitted = FoldVerdict::Admitted {
            pretrained: "/p".into(),
            corpus_cases: 1,
            fold_error: 0.0,
            family: Some(rec.clone()),
        };
        fold::write_verdict(b.path(), &admitted).unwrap();
        assert_eq!(family(&[a.path(), b.path()]), Some(rec));
        let refused = FoldVerdict::Refused { reason: "r".into() };
        fold::write_verdict(a.path(), &refused).unwrap();
        assert_eq!(family(&[a.path(), b.path()]), None);
    }
}
