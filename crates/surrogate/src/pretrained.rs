//! The pretrained surrogate as the start of one building's surrogate (issue 66).
//!
//! A network pretrained on the building family's corpus (`python -m bemcal_train.pretrain
//! train`: a folder with `card.json` and `weights.pt`) takes the building's descriptors and its
//! engineering parameters as static inputs, and the weather, the hour, the day type and the
//! schedule's value hour by hour (`--inputs conditioned`, the default; `--inputs foldable`
//! takes the schedule as a 48-hour static profile instead). For one building it *folds*
//! exactly into the runtime's surrogate shape (`pretrain.fold`): the static inputs are affine
//! in the calibrated parameters and become the parameters' part and a bias; the schedule's
//! value becomes hourly inputs (the [`crate::schedule`] table) and, for the calibrated
//! intervals, a product of an hourly indicator and the parameter that the graphs and their
//! gradient form themselves. The trainer then fine-tunes it from there (a warm start)
//! instead of from a random start; the chains and their gradient stay as they are.
//!
//! [`fold`] asks the trainer to fold; it answers with a [`FoldVerdict`]: admitted, or refused
//! with the reason (a building outside the corpus's ranges, a parameter or meter the network
//! does not know, another surrogate shape), in which case the surrogate is trained from a
//! random start as before.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::surrogate::SurrogateError;
use crate::train::{runtime, trainer_command};

/// The files of a pretrained surrogate's folder: what a fold reads, and what travels with a
/// submitted project.
pub const FILES: [&str; 2] = ["card.json", "weights.pt"];

/// The optional file of a pretrained surrogate's folder that records how far calibrations
/// started from it were off ([`Family`]); it travels with a submitted project where present.
pub const FAMILY_FILE: &str = "family.json";

/// How a project names a network shipped inside the binary: `pretrained = "bundled:NAME"`.
pub const BUNDLED_PREFIX: &str = "bundled:";

/// The networks shipped inside the binary, so that a pretrained start needs neither the
/// repository nor a network connection (a pip-installed wheel, a cluster's image): each one's
/// name and its [`FILES`] (`corpus/pretrained/NAME`, with its README and held-out error).
/// Each with its [`FAMILY_FILE`], where it has one.
#[allow(clippy::type_complexity)]
const BUNDLED: &[(&str, [&[u8]; 2], Option<&[u8]>)] = &[(
    "conditioned-200",
    [
        include_bytes!("../../../corpus/pretrained/conditioned-200/card.json"),
        include_bytes!("../../../corpus/pretrained/conditioned-200/weights.pt"),
    ],
    Some(include_bytes!(
        "../../../corpus/pretrained/conditioned-200/family.json"
    )),
)];

/// The names of the bundled networks.
pub fn bundled_names() -> Vec<&'static str> {
    BUNDLED.iter().map(|(n, ..)| *n).collect()
}

/// The bundled network's name where `reference` (a project's `pretrained`) is
/// `bundled:NAME`; None for a folder. An unknown name is an error that lists the known ones.
pub fn bundled_name(reference: &Path) -> Option<Result<&'static str, String>> {
    let name = reference.to_str()?.strip_prefix(BUNDLED_PREFIX)?;
    Some(
        BUNDLED
            .iter()
            .find(|(n, ..)| *n == name)
            .map(|(n, ..)| *n)
            .ok_or_else(|| {
                format!(
                    "no bundled pretrained network '{name}' (this binary ships: {})",
                    bundled_names().join(", ")
                )
            }),
    )
}

/// Writes the bundled network `name`'s [`FILES`] into `dir` (created), for a fold to read.
pub fn write_bundled(name: &str, dir: &Path) -> Result<(), SurrogateError> {
    let (_, files, family) = BUNDLED
        .iter()
        .find(|(n, ..)| *n == name)
        .ok_or_else(|| runtime(format!("no bundled pretrained network '{name}'")))?;
    std::fs::create_dir_all(dir)
        .map_err(|e| runtime(format!("cannot create {}: {e}", dir.display())))?;
    let family = family.map(|bytes| (FAMILY_FILE, bytes));
    for (file, bytes) in FILES
        .iter()
        .copied()
        .zip(files.iter().copied())
        .chain(family)
    {
        let path = dir.join(file);
        std::fs::write(&path, bytes)
            .map_err(|e| runtime(format!("cannot write {}: {e}", path.display())))?;
    }
    Ok(())
}

/// The file in the fold's folder that says what it decided.
pub const VERDICT_FILE: &str = "pretrained.json";

/// What [`fold`] decided.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "admitted")]
pub enum FoldVerdict {
    /// Folded: the folder holds `weights.pt`, the warm start of the building's surrogate.
    #[serde(rename = "true")]
    Admitted {
        /// The pretrained folder.
        pretrained: PathBuf,
        /// Cases of the corpus it was pretrained on.
        corpus_cases: usize,
        /// Largest difference between the folded and the pretrained network's outputs at the
        /// building's first design points, relative to the largest output (rounding only).
        fold_error: f64,
        /// The network's [`FAMILY_FILE`], where its folder has one: how far calibrations
        /// started from it were off, for the final temperature to pool with the building's own.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        family: Option<Family>,
    },
    /// Not used, and why.
    #[serde(rename = "false")]
    Refused {
        /// Why (names the descriptor, parameter, meter or setting).
        reason: String,
    },
}

/// How far calibrations of other buildings, started from the same pretrained network, were off
/// (`family.json` beside its weights): each building's shift ratios of its last refinement round,
/// the surrogate's error in units of its untempered posterior's variance, one per calibrated
/// parameter (`bemcal_stats::surrogate_error::shift_ratios`). The final temperature pools them
/// with the building's own (`bemcal_calibrate::surrogate_error`). Written by
/// `scripts/family_shifts.py` from a portfolio's results.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Family {
    /// What was run to measure them (the binary, the settings, the date).
    pub measured: String,
    /// One entry per calibrated building.
    pub buildings: Vec<FamilyBuilding>,
}

/// One building of a [`Family`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FamilyBuilding {
    /// The building's name in the portfolio.
    pub name: String,
    /// Shift ratio by calibrated parameter (finite, non-negative).
    pub ratios: std::collections::BTreeMap<String, f64>,
}

impl Family {
    /// The buildings to pool with a building named `name` that calibrates `parameters`: all
    /// but one of the same name (a rerun of a recorded building is not its own family), each
    /// with the ratios of those parameters only; buildings left with none are left out.
    pub fn for_building(&self, name: &str, parameters: &[String]) -> Family {
        let buildings = self
            .buildings
            .iter()
            .filter(|b| b.name != name)
            .map(|b| FamilyBuilding {
                name: b.name.clone(),
                ratios: b
                    .ratios
                    .iter()
                    .filter(|(p, _)| parameters.contains(p))
                    .map(|(p, r)| (p.clone(), *r))
                    .collect(),
            })
            .filter(|b| !b.ratios.is_empty())
            .collect();
        Family {
            measured: self.measured.clone(),
            buildings,
        }
    }

    /// Every building's ratios, in one list.
    pub fn ratios(&self) -> Vec<f64> {
        self.buildings
            .iter()
            .flat_map(|b| b.ratios.values().copied())
            .collect()
    }

    /// The family record in the pretrained folder `dir` ([`FAMILY_FILE`]), None where it has
    /// none.
    ///
    /// # Errors
    /// An unreadable or malformed file, or a ratio that is not finite and non-negative (named
    /// by building and parameter).
    pub fn read(dir: &Path) -> Result<Option<Family>, SurrogateError> {
        let path = dir.join(FAMILY_FILE);
        if !path.is_file() {
            return Ok(None);
        }
        let meta = |message: String| SurrogateError::Metadata {
            path: path.clone(),
            message,
        };
        let text = std::fs::read_to_string(&path).map_err(|e| meta(format!("cannot read: {e}")))?;
        let family: Family = serde_json::from_str(&text).map_err(|e| meta(e.to_string()))?;
        for b in &family.buildings {
            if let Some((p, r)) = b
                .ratios
                .iter()
                .find(|(_, r)| !(r.is_finite() && **r >= 0.0))
            {
                return Err(meta(format!(
                    "building '{}', parameter '{p}': ratio {r}, expected a finite number >= 0",
                    b.name
                )));
            }
        }
        Ok(Some(family))
    }
}

/// What [`fold`] needs of the building: its generated spec (serialised as the model file's
/// building), its floor area and the value of every parameter (the fixed ones as they stay).
#[derive(Debug, Clone, Serialize)]
pub struct Building<'a, S: Serialize> {
    /// The generator's building spec.
    pub spec: &'a S,
    /// Conditioned floor area, m2.
    pub floor_area_m2: f64,
    /// Every parameter's value (the calibrated ones are replaced by the design points').
    pub values: &'a std::collections::BTreeMap<String, f64>,
}

/// Folds the pretrained network in `pretrained` onto the building of the training set in
/// `dataset_dir` (described by `building`), for a surrogate of `hidden` units a layer and
/// `time_features`, into `out_dir`; the verdict is also written there ([`VERDICT_FILE`]).
pub fn fold<S: Serialize>(
    pretrained: &Path,
    dataset_dir: &Path,
    building: &Building<'_, S>,
    hidden: usize,
    time_features: &str,
    out_dir: &Path,
    python: Option<PathBuf>,
) -> Result<FoldVerdict, SurrogateError> {
    let (mut cmd, python, _pkg) = trainer_command(python, "bemcal_train.pretrain", out_dir)?;
    let building_file = out_dir.join("building.json");
    let json = serde_json::to_string_pretty(building)
        .map_err(|e| runtime(format!("cannot write the building for the fold: {e}")))?;
    std::fs::write(&building_file, json)
        .map_err(|e| runtime(format!("cannot write {}: {e}", building_file.display())))?;
    let _ = std::fs::remove_file(out_dir.join(VERDICT_FILE));
    cmd.arg("fold")
        .arg("--pretrained")
        .arg(pretrained)
        .arg("--dataset")
        .arg(dataset_dir)
        .arg("--building")
        .arg(&building_file)
        .args(["--hidden", &hidden.to_string()])
        .args(["--time-features", time_features])
        .arg("--out")
        .arg(out_dir);
    let out = cmd
        .output()
        .map_err(|e| runtime(format!("cannot start {}: {e}", python.display())))?;
    if !out.status.success() {
        let log = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = log.lines().rev().take(20).collect();
        return Err(runtime(format!(
            "folding the pretrained surrogate in {} failed:\n{}",
            pretrained.display(),
            tail.into_iter().rev().collect::<Vec<_>>().join("\n")
        )));
    }
    let mut verdict = read_verdict(out_dir)?;
    // Read only where the network is used: a bad record then stops the run with its file and
    // building named, before the first training (rerun after fixing it; the design stays).
    if let FoldVerdict::Admitted { family, .. } = &mut verdict {
        if let Some(record) = Family::read(pretrained)? {
            let value = serde_json::to_value(&record).map_err(|e| runtime(e.to_string()))?;
            set_verdict_field(out_dir, "family", value)?;
            *family = Some(record);
        }
    }
    Ok(verdict)
}

/// Writes `verdict` into `dir` as the trainer does (for a verdict reached without it).
pub fn write_verdict(dir: &Path, verdict: &FoldVerdict) -> Result<(), SurrogateError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| runtime(format!("cannot create {}: {e}", dir.display())))?;
    let mut value = serde_json::to_value(verdict).map_err(|e| runtime(e.to_string()))?;
    value["admitted"] = serde_json::Value::Bool(matches!(verdict, FoldVerdict::Admitted { .. }));
    let path = dir.join(VERDICT_FILE);
    std::fs::write(&path, value.to_string())
        .map_err(|e| runtime(format!("cannot write {}: {e}", path.display())))
}

/// Records in `dir`'s verdict that the network came from `pretrained` (a bundled network's
/// `bundled:NAME`, not the folder it was written to); the trainer's other fields stay.
pub fn relabel_verdict(dir: &Path, pretrained: &Path) -> Result<(), SurrogateError> {
    set_verdict_field(dir, "pretrained", pretrained.display().to_string().into())
}

/// Sets `key` of `dir`'s verdict to `value`; the trainer's other fields stay.
fn set_verdict_field(
    dir: &Path,
    key: &str,
    value: serde_json::Value,
) -> Result<(), SurrogateError> {
    let path = dir.join(VERDICT_FILE);
    let meta = |message: String| SurrogateError::Metadata {
        path: path.clone(),
        message,
    };
    let text = std::fs::read_to_string(&path).map_err(|e| meta(format!("cannot read: {e}")))?;
    let mut verdict: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| meta(e.to_string()))?;
    verdict[key] = value;
    std::fs::write(&path, verdict.to_string()).map_err(|e| meta(format!("cannot write: {e}")))
}

/// The verdict a fold left in `dir`.
pub fn read_verdict(dir: &Path) -> Result<FoldVerdict, SurrogateError> {
    let path = dir.join(VERDICT_FILE);
    let text = std::fs::read_to_string(&path).map_err(|e| SurrogateError::Metadata {
        path: path.clone(),
        message: format!("cannot read: {e}"),
    })?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| SurrogateError::Metadata {
            path: path.clone(),
            message: e.to_string(),
        })?;
    // The trainer writes `admitted` as a JSON boolean; the tag reads strings.
    let mut value = value;
    if let Some(b) = value.get("admitted").and_then(serde_json::Value::as_bool) {
        value["admitted"] = serde_json::Value::String(b.to_string());
    }
    serde_json::from_value(value).map_err(|e| SurrogateError::Metadata {
        path,
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `bundled:NAME` names a shipped network, written out as the folder it was built in;
    /// anything else is a folder, and an unknown name says which ones there are.
    #[test]
    fn a_bundled_network_is_written_as_its_folder() {
        let name = bundled_name(Path::new("bundled:conditioned-200"))
            .unwrap()
            .unwrap();
        let dir = tempfile::tempdir().unwrap();
        write_bundled(name, dir.path()).unwrap();
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../corpus/pretrained")
            .join(name);
        for f in FILES.into_iter().chain([FAMILY_FILE]) {
            assert_eq!(
                std::fs::read(dir.path().join(f)).unwrap(),
                std::fs::read(shipped.join(f)).unwrap(),
                "{f}"
            );
        }
        let card: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("card.json")).unwrap()).unwrap();
        assert!(card.is_object());
        assert!(bundled_name(Path::new("../pretrained")).is_none());
        let e = bundled_name(Path::new("bundled:nope"))
            .unwrap()
            .unwrap_err();
        assert!(e.contains("conditioned-200"), "{e}");
    }

    #[test]
    fn both_verdicts_read_as_the_trainer_writes_them() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join(VERDICT_FILE),
            r#"{"admitted": false, "reason": "the building's storeys 9 is outside the corpus's 1 to 6"}"#,
        )
        .unwrap();
        assert_eq!(
            read_verdict(dir.path()).unwrap(),
            FoldVerdict::Refused {
                reason: "the building's storeys 9 is outside the corpus's 1 to 6".into()
            }
        );
        std::fs::write(
            dir.path().join(VERDICT_FILE),
            r#"{"admitted": true, "pretrained": "/p", "corpus_cases": 200, "fold_error": 1e-7}"#,
        )
        .unwrap();
        let admitted = FoldVerdict::Admitted {
            pretrained: "/p".into(),
            corpus_cases: 200,
            fold_error: 1e-7,
            family: None,
        };
        assert_eq!(read_verdict(dir.path()).unwrap(), admitted);
        let refused = FoldVerdict::Refused {
            reason: "an own IDF".into(),
        };
        write_verdict(dir.path(), &refused).unwrap();
        assert_eq!(read_verdict(dir.path()).unwrap(), refused);
        write_verdict(dir.path(), &admitted).unwrap();
        assert_eq!(read_verdict(dir.path()).unwrap(), admitted);
    }

    /// The shipped family record reads; one with a negative ratio is refused by building and
    /// parameter; a folder without one has none.
    #[test]
    fn a_family_record_reads_and_a_bad_ratio_is_named() {
        let shipped =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../corpus/pretrained/conditioned-200");
        let family = Family::read(&shipped).unwrap().unwrap();
        assert!(family.buildings.len() >= 4 && family.ratios().len() >= 4 * 38);
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(Family::read(dir.path()).unwrap(), None);
        std::fs::write(
            dir.path().join(FAMILY_FILE),
            r#"{"measured": "m", "buildings": [{"name": "B", "ratios": {"a": 1.0, "b": -2.0}}]}"#,
        )
        .unwrap();
        let e = Family::read(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("building 'B', parameter 'b'") && e.contains("-2"),
            "{e}"
        );
    }

    /// A building is pooled with the others, on the parameters it calibrates.
    #[test]
    fn a_building_is_pooled_with_the_others_on_its_own_parameters() {
        let b = |name: &str, ratios: &[(&str, f64)]| FamilyBuilding {
            name: name.into(),
            ratios: ratios.iter().map(|(p, r)| (p.to_string(), *r)).collect(),
        };
        let family = Family {
            measured: "m".into(),
            buildings: vec![
                b("A", &[("x", 1.0), ("y", 2.0)]),
                b("B", &[("x", 3.0)]),
                b("C", &[("z", 4.0)]),
            ],
        };
        let pooled = family.for_building("B", &["x".into(), "y".into()]);
        assert_eq!(pooled.buildings, vec![b("A", &[("x", 1.0), ("y", 2.0)])]);
        assert_eq!(pooled.ratios(), vec![1.0, 2.0]);
        assert!(family.for_building("D", &["w".into()]).buildings.is_empty());
    }
}
