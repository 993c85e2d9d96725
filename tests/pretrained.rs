//! The pretrained surrogate's path through `bemcal calibrate` (issue 66), with real
//! EnergyPlus, PyTorch and ONNX Runtime: a tiny corpus of the small model's family built by
//! `bemcal corpus`, a tiny network pretrained on it (`bemcal_train.pretrain train`, the
//! schedule's value hour by hour among its inputs), then the small calibration with
//! `[surrogate] pretrained` and a schedule interval among its parameters: folded onto the
//! building (the schedule as hourly inputs, the graphs and their gradient checked against
//! PyTorch) and fine-tuned where the building is inside the corpus's ranges, and trained from
//! random weights, with the reason, where it is not.

mod common;

use std::path::Path;

use common::{bemcal, finished, golden_epw, have_engine, repo, run_ok, small_model, small_project};

/// The small model's family as a corpus manifest: its one-storey 20 x 15 m box, its
/// envelope, system and occupied hours fixed, every parameter drawn over its widened prior.
const MANIFEST: &str = r#"
name = "small-family"
seed = 3
cases = 6
points_per_building = 1
timesteps_per_hour = 1
[spec]
storeys = [1, 1]
length_m = [20.0, 20.0]
aspect = [1.3333333333333333, 1.3333333333333333]
floor_to_floor_m = [3.96, 3.96]
window_to_wall = [0.33, 0.33]
zoning = ["one_per_floor"]
heating_source = ["boiler"]
hvac = ["vav_reheat"]
occupied_start = [7, 7]
occupied_end = [19, 19]
merge_boundaries = 0.0
[[climates]]
name = "Golden"
weather = "bundled:USA_CO_Golden-NREL.724666_TMY3.epw"
"#;

/// A project folder for the small calibration with `pretrained = "../pretrained"` and
/// `model` as its model, a schedule interval among its parameters where `schedule`; meters
/// synthesised at known values.
fn project(dir: &Path, model: &str, schedule: bool) -> std::path::PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("model.toml"), model).unwrap();
    let mut text = small_project("pretrained-start", 6).replace(
        "hidden = 32\n",
        "hidden = 32\npretrained = \"../pretrained\"\n",
    );
    if schedule {
        text = text.replace(
            "\"cooling_setpoint_occupied\"]",
            "\"cooling_setpoint_occupied\", \"schedule_weekday_06\"]",
        );
    }
    assert!(text.contains("pretrained = ") && text.contains("schedule_weekday_06") == schedule);
    std::fs::write(dir.join("project.toml"), text).unwrap();
    run_ok(
        bemcal()
            .args(["synthesize", "--model"])
            .arg(dir.join("model.toml"))
            .arg("--weather")
            .arg(golden_epw())
            .args(["--set", "lighting_power_density=12.5"])
            .args(["--set", "cooling_setpoint_occupied=22.5"])
            .arg("--out")
            .arg(dir.join("meters.csv")),
    );
    dir.join("project.toml")
}

fn calibrate(project: &Path, out: &Path) -> serde_json::Value {
    let o = bemcal()
        .arg("calibrate")
        .arg(project)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(finished(o.status), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn a_pretrained_network_starts_the_surrogate_inside_its_family_and_not_outside() {
    if !have_engine() {
        eprintln!("skipping: no Python environment (make setup)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    std::fs::write(root.join("family.toml"), MANIFEST).unwrap();
    run_ok(
        bemcal()
            .arg("corpus")
            .arg(root.join("family.toml"))
            .arg("--out")
            .arg(root.join("corpus"))
            .args(["--parallel", "2"]),
    );
    let pretrain = std::process::Command::new(repo().join(".venv/bin/python"))
        .args(["-m", "bemcal_train.pretrain", "train"])
        .arg("--corpus")
        .arg(root.join("corpus"))
        .args(["--cases", "6", "--epochs", "3", "--hours-per-case", "500"])
        .args(["--hidden", "32", "--threads", "1", "--out"])
        .arg(root.join("pretrained"))
        .env("PYTHONPATH", repo().join("python"))
        .output()
        .unwrap();
    assert!(
        pretrain.status.success(),
        "{}",
        String::from_utf8_lossy(&pretrain.stderr)
    );

    // A family record beside the network (how far calibrations started from it were off)
    // goes into the verdict, for the final temperature to pool.
    std::fs::write(
        root.join("pretrained").join(bemcal_surrogate::pretrained::FAMILY_FILE),
        r#"{"measured": "test", "buildings": [{"name": "other", "ratios": {"lighting_power_density": 40.0}}]}"#,
    )
    .unwrap();

    // Inside the family: folded (exactly, up to rounding), then fine-tuned by the trainer.
    let inside = project(&root.join("inside"), &small_model(), true);
    let summary = calibrate(&inside, &root.join("inside/out"));
    assert_eq!(
        summary["surrogate_start"]["from"], "pretrained",
        "{summary}"
    );
    assert_eq!(summary["surrogate_start"]["corpus_cases"], 6);
    let verdict: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root.join("inside/out/pretrained/pretrained.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(verdict["admitted"], true, "{verdict}");
    assert!(verdict["fold_error"].as_f64().unwrap() < 1e-3, "{verdict}");
    assert_eq!(verdict["inputs"], "conditioned", "{verdict}");
    assert_eq!(
        verdict["family"]["buildings"][0]["name"], "other",
        "{verdict}"
    );
    // The verdict travels with the surrogate (from a worker, through the refinement rounds),
    // the family record in it.
    let carried =
        bemcal_surrogate::pretrained::read_verdict(&root.join("inside/out/surrogate")).unwrap();
    assert!(
        matches!(&carried, bemcal_surrogate::pretrained::FoldVerdict::Admitted { family: Some(f), .. } if f.buildings.len() == 1),
        "{carried:?}"
    );
    // The schedule interval the calibration varies is an hourly input of the folded surrogate,
    // and its graphs (the fused one and its gradient) agree with PyTorch.
    let meta: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root.join("inside/out/surrogate/surrogate.json")).unwrap(),
    )
    .unwrap();
    let params: Vec<&str> = meta["params"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    let k = params
        .iter()
        .position(|&p| p == "schedule_weekday_06")
        .unwrap();
    assert_eq!(
        meta["schedule_inputs"]["params"],
        serde_json::json!([k]),
        "{meta}"
    );
    for check in ["fused_vs_torch", "vjp_vs_torch"] {
        let err = meta["onnxruntime_check"][check].as_f64().unwrap();
        assert!(err < 1e-4, "{check} {err}");
    }
    assert!(summary["sigma_eta_kwh"]["heating_kwh"]
        .as_f64()
        .unwrap()
        .is_finite());

    // Inside, no schedule interval calibrated: the folded surrogate's schedule term is 0 and
    // its weight column unused, and its graphs still agree with PyTorch (the exported graphs
    // once kept that column and ONNX Runtime refused them: the quick example on this path).
    let fixed_schedule = project(&root.join("fixed-schedule"), &small_model(), false);
    let summary = calibrate(&fixed_schedule, &root.join("fixed-schedule/out"));
    assert_eq!(
        summary["surrogate_start"]["from"], "pretrained",
        "{summary}"
    );
    let meta: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root.join("fixed-schedule/out/surrogate/surrogate.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(
        meta["schedule_inputs"]["params"],
        serde_json::json!([]),
        "{meta}"
    );
    for check in ["fused_vs_torch", "vjp_vs_torch"] {
        let err = meta["onnxruntime_check"][check].as_f64().unwrap();
        assert!(err < 1e-4, "{check} {err}");
    }

    // Outside it (a longer footprint than any the corpus holds): from random weights, and why.
    let longer = small_model().replace("footprint_m = [20.0, 15.0]", "footprint_m = [30.0, 15.0]");
    assert_ne!(longer, small_model());
    let outside = project(&root.join("outside"), &longer, false);
    let summary = calibrate(&outside, &root.join("outside/out"));
    assert_eq!(summary["surrogate_start"]["from"], "scratch", "{summary}");
    let reason = summary["surrogate_start"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("length_m 30 is outside the corpus's 20 to 20"),
        "{reason}"
    );
}
