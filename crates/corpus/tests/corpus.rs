//! A corpus built with real EnergyPlus, resumed, and learned from by the pretraining script
//! (PyTorch): the pretrained network evaluated zero-shot and fine-tuned on a held-out building.
//! Skipped (with a message) when no EnergyPlus or Python environment is installed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use bemcal_corpus::build::{build, Settings};
use bemcal_corpus::manifest::Manifest;
use bemcal_corpus::store::{read_lines, Finished};
use bemcal_energyplus::{Engine, RunOptions, Runner};

/// One-storey boxes at one time step per hour: about 1.5 s an EnergyPlus year.
fn manifest(seed: u64, cases: usize, points: usize) -> Manifest {
    let text = format!(
        r#"
name = "test"
seed = {seed}
cases = {cases}
points_per_building = {points}
timesteps_per_hour = 1
[spec]
storeys = [1, 1]
length_m = [15.0, 22.0]
aspect = [1.0, 1.5]
floor_to_floor_m = [3.0, 4.0]
window_to_wall = [0.2, 0.5]
zoning = ["one_per_floor"]
heating_source = ["boiler", "district"]
hvac = ["vav_reheat", "doas_fan_coil"]
occupied_start = [6, 8]
occupied_end = [17, 20]
merge_boundaries = 0.3
[[climates]]
name = "Golden"
weather = "bundled:USA_CO_Golden-NREL.724666_TMY3.epw"
"#
    );
    Manifest::parse(&text, Path::new("test.toml")).unwrap()
}

fn setup() -> Option<(Runner, BTreeMap<String, PathBuf>)> {
    let engine = match Engine::locate() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("skipping: {e}");
            return None;
        }
    };
    let golden = engine
        .bundled_weather("USA_CO_Golden-NREL.724666_TMY3.epw")
        .expect("the engine ships Golden's weather");
    let runner = Runner::new(engine, RunOptions::default()).unwrap();
    Some((runner, BTreeMap::from([("Golden".to_string(), golden)])))
}

fn npy_shape(path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap();
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    String::from_utf8_lossy(&bytes[10..10 + len]).to_string()
}

#[test]
fn a_corpus_resumes_and_a_pretrained_network_fine_tunes_on_a_held_out_building() {
    let Some((runner, weather)) = setup() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let family = dir.path().join("family");
    let quiet = |_: &str| {};
    let m = manifest(1, 4, 1);
    let first = build(
        &m,
        &weather,
        &runner,
        &family,
        &Settings {
            cases: 2,
            parallel: 2,
        },
        &quiet,
    )
    .unwrap();
    assert_eq!(
        (first.finished, first.failed, first.settled_before),
        (2, 0, 0)
    );
    // A rerun of more cases simulates only the missing ones.
    let all = build(
        &m,
        &weather,
        &runner,
        &family,
        &Settings {
            cases: 4,
            parallel: 2,
        },
        &quiet,
    )
    .unwrap();
    assert_eq!(all.settled_before, 2);
    assert_eq!(all.finished + all.failed, 2);
    let done: Vec<Finished> = read_lines(&family.join("index.jsonl")).unwrap();
    assert_eq!(done.len(), all.finished + 2);
    for f in &done {
        let header = npy_shape(&family.join("cases").join(format!("{}.npy", f.key)));
        assert!(
            header.contains("'<f2'") && header.contains("(8760, 5)"),
            "{header}"
        );
        assert!(f.floor_area_m2 > 100.0 && f.seconds > 0.0);
    }
    assert!(npy_shape(&family.join("weather/Golden.npy")).contains("(8760, 5)"));

    // The held-out building: 7 points, 5 to fine-tune on and 2 to test.
    let heldout = dir.path().join("heldout");
    let h = manifest(2, 7, 7);
    build(
        &h,
        &weather,
        &runner,
        &heldout,
        &Settings {
            cases: 7,
            parallel: 2,
        },
        &quiet,
    )
    .unwrap();
    let Some(venv) = bemcal_pyenv::find_venv() else {
        eprintln!("skipping the pretraining: no Python environment");
        return;
    };
    let python_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../python");
    let out = dir.path().join("curve");
    let status = std::process::Command::new(bemcal_pyenv::python(&venv))
        .env("PYTHONPATH", &python_dir)
        .args(["-m", "bemcal_train.pretrain", "curve", "--corpus"])
        .arg(&family)
        .arg("--heldout")
        .arg(&heldout)
        .args([
            "--sizes",
            "4",
            "--test",
            "2",
            "--epochs",
            "3",
            "--hours-per-case",
            "500",
        ])
        .args([
            "--finetune-epochs",
            "8",
            "--hidden",
            "16",
            "--threads",
            "1",
            "--out",
        ])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let curve: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("curve.json")).unwrap()).unwrap();
    let b = &curve["sizes"]["4"]["buildings"]["0"];
    for how in ["zero_shot", "finetuned_5"] {
        for meter in ["heating_kwh", "cooling_kwh", "electricity_kwh"] {
            let cv = b[how][meter]["cv_rmse_pct"].as_f64().unwrap();
            assert!(cv.is_finite() && cv > 0.0, "{how} {meter}: {cv}");
        }
    }
    // The model card names the corpus it came from.
    let card = &curve["sizes"]["4"]["card"];
    assert_eq!(card["corpus"]["cases"], 4);
    assert_eq!(card["corpus"]["climates"][0], "Golden");
}
