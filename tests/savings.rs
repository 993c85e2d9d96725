//! Issue 70: retrofit savings with credible intervals from a finished calibration
//! (`bemcal savings`). The small model's two-parameter calibration, then five measures over its
//! posterior draws with EnergyPlus: a cooling set-point raised 1 K (against EnergyPlus at the
//! hidden truth), a set-point beyond the prior (the surrogate's training range), LED lighting,
//! an economizer (a building edit) and the AHUs' fan pressure (an edit of the IDF's objects),
//! then the surrogate's route for the measures inside its range; bad measures refused with the
//! file and the reason. Real EnergyPlus, PyTorch and
//! ONNX Runtime; skipped (with a message) when the Python environment is missing.

use std::path::Path;

mod common;
use common::{bemcal, have_engine, run_ok};

const TRUTH: [(&str, f64); 2] = [
    ("lighting_power_density", 12.5),
    ("cooling_setpoint_occupied", 22.5),
];

const MEASURES: &str = r#"
[[measures]]
name = "cooling set-point +1 K"
offset = { cooling_setpoint_occupied = 1.0 }
[[measures]]
name = "cooling set-point 27 C"
set = { cooling_setpoint_occupied = 27.0 }
[[measures]]
name = "LED lighting"
scale = { lighting_power_density = 0.6 }
[[measures]]
name = "air-side economizer"
building = { economizer = true }
[[measures]]
name = "low-pressure ductwork"
idf = [{ class = "HVACTemplate:System:VAV", field = "Supply Fan Delta Pressure", edit = "scale", value = 0.7 }]
"#;

fn project() -> String {
    common::small_project("savings", 10) + MEASURES
}

/// The annual totals of EnergyPlus at the truth, with `set` on top.
fn at_truth(dir: &Path, set: &[(&str, f64)]) -> serde_json::Value {
    let mut cmd = bemcal();
    cmd.args(["simulate", "--model"])
        .arg(dir.join("model.toml"))
        .args([
            "--weather",
            "bundled:USA_CO_Golden-NREL.724666_TMY3.epw",
            "--json",
        ])
        .arg("--out")
        .arg(dir.join("truth.csv"));
    let mut values: Vec<(&str, f64)> = TRUTH.to_vec();
    values.extend_from_slice(set);
    for (k, v) in values {
        cmd.arg("--set").arg(format!("{k}={v}"));
    }
    let out = run_ok(&mut cmd);
    serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["annual_kwh"].clone()
}

/// Measure `name` in `savings`.
fn measure<'a>(savings: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    (savings["measures"].as_array().unwrap().iter())
        .find(|m| m["measure"] == name)
        .unwrap_or_else(|| panic!("no measure {name}: {savings}"))
}

/// The output `output` under the calibration's weather of measure `name` in `savings`.
fn row<'a>(savings: &'a serde_json::Value, name: &str, output: &str) -> &'a serde_json::Value {
    let m = measure(savings, name);
    (m["outputs"].as_array().unwrap().iter())
        .find(|o| o["output"] == output && o["weather"] == "calibration")
        .unwrap_or_else(|| panic!("no {output} in {m}"))
}

#[test]
fn savings_come_with_intervals_from_the_posterior() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let _machine = common::whole_machine();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("model.toml"), common::small_model()).unwrap();
    std::fs::write(dir.join("project.toml"), project()).unwrap();
    common::synthesize(dir, &TRUTH, &[]);
    let out = dir.join("out");
    common::calibrate(dir, &out);

    let run = run_ok(
        bemcal()
            .arg("savings")
            .arg(dir.join("project.toml"))
            .arg("--out")
            .arg(&out)
            .args(["--draws", "6", "--json"]),
    );
    let savings: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    eprintln!("{}", String::from_utf8_lossy(&run.stderr));

    // The cooling set-point +1 K saves cooling; the true saving (EnergyPlus at the hidden
    // truth) is near the posterior's, whose draws all raise the same set-point by 1 K.
    let cooling = row(&savings, "cooling set-point +1 K", "cooling_kwh");
    let base = at_truth(dir, &[]);
    let raised = at_truth(dir, &[("cooling_setpoint_occupied", 23.5)]);
    let truth = base["cooling_kwh"].as_f64().unwrap() - raised["cooling_kwh"].as_f64().unwrap();
    let median = cooling["savings_kwh"]["median"].as_f64().unwrap();
    let [lo, hi] = [0, 1].map(|i| cooling["savings_kwh"]["interval_90"][i].as_f64().unwrap());
    eprintln!("cooling +1 K: true saving {truth:.0} kWh, posterior {median:.0} [{lo:.0}, {hi:.0}]");
    assert!(
        truth > 0.0 && median > 0.0 && lo <= median && median <= hi,
        "{cooling}"
    );
    assert!(
        (median - truth).abs() < 0.2 * truth,
        "{truth} against {cooling}"
    );
    assert_eq!(cooling["n"], 6, "{cooling}");
    assert_eq!(cooling["monthly_kwh"].as_array().unwrap().len(), 12);
    // A measure with no effect on a meter: the lighting's interval is zero at both ends.
    let lights = row(&savings, "cooling set-point +1 K", "lighting_kwh");
    assert_eq!(
        lights["savings_kwh"]["interval_90"],
        serde_json::json!([0.0, 0.0]),
        "{lights}"
    );
    assert!(
        lights["warning"].as_str().unwrap().contains("no meter"),
        "{lights}"
    );

    // Beyond the prior, the surrogate's training range: EnergyPlus, and said.
    let beyond = measure(&savings, "cooling set-point 27 C");
    assert_eq!(beyond["method"], "energyplus", "{beyond}");
    assert_eq!(
        beyond["beyond_prior"],
        serde_json::json!(["cooling_setpoint_occupied"])
    );
    assert!(beyond["method_note"]
        .as_str()
        .unwrap()
        .contains("outside its prior"));
    // An economizer, a building edit: EnergyPlus simulates it, and it saves cooling (Golden's
    // dry air cools for free much of the year) but no lighting.
    let economizer = measure(&savings, "air-side economizer");
    assert_eq!(economizer["method"], "energyplus", "{economizer}");
    assert_eq!(
        economizer["edits"],
        serde_json::json!(["economizer = true"])
    );
    assert!(
        (economizer["method_note"].as_str().unwrap()).contains("edits the building"),
        "{economizer}"
    );
    let free = row(&savings, "air-side economizer", "cooling_kwh");
    let [lo, hi] = [0, 1].map(|i| free["savings_kwh"]["interval_90"][i].as_f64().unwrap());
    eprintln!("economizer: cooling saving [{lo:.0}, {hi:.0}] kWh");
    assert!(lo > 0.0 && lo <= hi, "{free}");
    let lights = row(&savings, "air-side economizer", "lighting_kwh");
    assert_eq!(
        lights["savings_kwh"]["interval_90"],
        serde_json::json!([0.0, 0.0])
    );
    // An edit of the IDF's objects that no parameter reaches (the AHUs' fan pressure x 0.7):
    // EnergyPlus simulates it, and it saves electricity (the fans) at every draw, no lighting.
    let ducts = measure(&savings, "low-pressure ductwork");
    assert_eq!(ducts["method"], "energyplus", "{ducts}");
    assert_eq!(
        ducts["edits"],
        serde_json::json!(["HVACTemplate:System:VAV Supply Fan Delta Pressure x 0.7"])
    );
    assert!(
        (ducts["method_note"].as_str().unwrap()).contains("edits the IDF"),
        "{ducts}"
    );
    let fans = row(&savings, "low-pressure ductwork", "electricity_kwh");
    let [lo, hi] = [0, 1].map(|i| fans["savings_kwh"]["interval_90"][i].as_f64().unwrap());
    eprintln!("fan pressure x 0.7: electricity saving [{lo:.0}, {hi:.0}] kWh");
    assert!(lo > 0.0 && lo <= hi, "{fans}");
    let lights = row(&savings, "low-pressure ductwork", "lighting_kwh");
    assert_eq!(
        lights["savings_kwh"]["interval_90"],
        serde_json::json!([0.0, 0.0])
    );
    // LED lighting x 0.6 saves 40 % of the lighting at every draw.
    let led = row(&savings, "LED lighting", "lighting_kwh");
    let pct = led["savings_percent"]["median"].as_f64().unwrap();
    assert!((pct - 40.0).abs() < 0.5, "{led}");

    // summary.json holds what the command printed, and reads back through its writer's types.
    let bytes = std::fs::read(out.join("summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    assert_eq!(summary["savings"], savings);
    let typed: bemcal_calibrate::Summary = serde_json::from_slice(&bytes).unwrap();
    assert_eq!(serde_json::to_value(&typed).unwrap(), summary);
    // And Python's `bemcal.load(...).savings`.
    let py = run_ok(
        std::process::Command::new(common::repo().join(".venv/bin/python"))
            .arg("-c")
            .arg(
                "import sys, bemcal.results as r; c = r.load(sys.argv[1]); s = c.savings; \
                 y = s[(s.measure == 'LED lighting') & (s.output == 'lighting_kwh') & s.month.isna()]; \
                 d = s[s.measure == 'low-pressure ductwork'].iloc[0]; \
                 print(len(s), round(float(y.median_pct.iloc[0]), 1), d.method, d.edits.split()[0])",
            )
            .arg(&out)
            .env("PYTHONPATH", common::repo().join("python")),
    );
    let text = String::from_utf8_lossy(&py.stdout);
    let fields: Vec<&str> = text.split_whitespace().collect();
    let [rows, pct, method, edited] = fields[..] else {
        panic!("{text}")
    };
    assert_eq!((method, edited), ("energyplus", "HVACTemplate:System:VAV"));
    // 5 measures x 5 outputs x (the year + 12 months).
    assert_eq!(rows, "325", "{text}");
    assert_eq!(pct, "40.0", "{text}");

    // The surrogate route: 40 draws of the surrogate corrected onto EnergyPlus at the 6 it
    // already ran (cached: no new EnergyPlus run but the estimate's), for the measures inside
    // its training range; the set-point beyond the prior stays with EnergyPlus.
    let run = run_ok(
        bemcal()
            .arg("savings")
            .arg(dir.join("project.toml"))
            .arg("--out")
            .arg(&out)
            .args(["--draws", "6", "--surrogate-draws", "40", "--json"]),
    );
    let savings: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let method = |name: &str| {
        let m = measure(&savings, name);
        (m["method"].clone(), m["surrogate_draws"].clone())
    };
    assert_eq!(
        method("cooling set-point +1 K"),
        ("surrogate_corrected".into(), 40.into())
    );
    assert_eq!(
        method("cooling set-point 27 C"),
        ("energyplus".into(), 0.into())
    );
    assert_eq!(
        method("air-side economizer"),
        ("energyplus".into(), 0.into())
    );
    assert_eq!(
        method("low-pressure ductwork"),
        ("energyplus".into(), 0.into())
    );
    let cooling = row(&savings, "cooling set-point +1 K", "cooling_kwh");
    let median = cooling["savings_kwh"]["median"].as_f64().unwrap();
    let [lo, hi] = [0, 1].map(|i| cooling["savings_kwh"]["interval_90"][i].as_f64().unwrap());
    eprintln!("cooling +1 K by the surrogate: {median:.0} [{lo:.0}, {hi:.0}]");
    assert_eq!(cooling["n"], 40, "{cooling}");
    assert!(cooling["correction"]["slope"].is_number(), "{cooling}");
    assert!(
        (median - truth).abs() < 0.2 * truth && lo <= median && median <= hi,
        "{truth} against {cooling}"
    );
    // Outputs without a meter are EnergyPlus's alone: the lighting still saves nothing.
    let lights = row(&savings, "cooling set-point +1 K", "lighting_kwh");
    assert_eq!(
        lights["savings_kwh"]["interval_90"],
        serde_json::json!([0.0, 0.0])
    );
}

#[test]
fn bad_measures_are_refused_with_the_file_and_the_reason() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("model.toml"), common::small_model()).unwrap();
    let base = common::small_project("savings", 10);
    for (measure, expected) in [
        (
            "[[measures]]\nname = \"nothing\"\n",
            "measure 'nothing' names nothing",
        ),
        (
            "[[measures]]\nname = \"x\"\nscale = { lighting_power_density = 1.0 }\n",
            "changes nothing: lighting_power_density's factor 1",
        ),
        (
            "[[measures]]\nname = \"x\"\nscale = { lighting_density = 0.6 }\n",
            "the model has no parameter 'lighting_density'",
        ),
        (
            "[[measures]]\nname = \"LED\"\nscale = { lighting_power_density = 0.6 }\n\
             [[measures]]\nname = \"led\"\nscale = { lighting_power_density = 0.5 }\n",
            "another measure has the same name",
        ),
        (
            "[[measures]]\nname = \"taller\"\nbuilding = { storeys = 2 }\n",
            "building.storeys: not a field a measure may edit",
        ),
        (
            "[[measures]]\nname = \"doas\"\nbuilding = { hvac = \"doas_fan_coil\" }\n",
            "the edits change the model's parameters",
        ),
        (
            "[[measures]]\nname = \"fans\"\nidf = [{ class = \"HVACTemplate:System:VAV\", \
             field = \"Fan Pressure\", value = 500.0 }]\n",
            "class 'HVACTemplate:System:VAV' has no field 'Fan Pressure'",
        ),
        (
            "[[measures]]\nname = \"fans\"\nidf = [{ class = \"HVACTemplate:System:VAV\", \
             object = \"AHU9\", field = \"Supply Fan Delta Pressure\", value = 500.0 }]\n",
            "the IDF each draw simulates has no object AHU9",
        ),
        (
            "[[measures]]\nname = \"fans\"\nidf = [{ class = \"HVACTemplate:System:VAV\", \
             field = \"Supply Fan Total Efficiency\", value = 0.7 }]\n",
            "changes nothing: the fields already hold what it writes",
        ),
    ] {
        std::fs::write(dir.join("project.toml"), base.clone() + measure).unwrap();
        let out = bemcal()
            .arg("check")
            .arg(dir.join("project.toml"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{measure} passed");
        assert!(
            err.contains("project.toml") && err.contains(expected),
            "{measure}: {err}"
        );
    }
    // A set of a parameter the calibration held fixed, to the value it held: refused before
    // any run (the plan knows the fixed values), and without a calibration, said so.
    std::fs::write(dir.join("project.toml"), base).unwrap();
    common::synthesize(dir, &TRUTH, &[]);
    std::fs::write(
        dir.join("measures.toml"),
        "[[measures]]\nname = \"same\"\nset = { heating_setpoint_occupied = 21.0 }\n",
    )
    .unwrap();
    let savings = |measures: &str| {
        bemcal()
            .arg("savings")
            .arg(dir.join("project.toml"))
            .arg("--out")
            .arg(dir.join("none"))
            .arg("--measures")
            .arg(dir.join(measures))
            .output()
            .unwrap()
    };
    let out = savings("measures.toml");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("changes nothing") && err.contains("held it at"),
        "{err}"
    );
    std::fs::write(
        dir.join("led.toml"),
        "[[measures]]\nname = \"LED\"\nscale = { lighting_power_density = 0.6 }\n",
    )
    .unwrap();
    let out = savings("led.toml");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("no finished calibration"), "{err}");
}
