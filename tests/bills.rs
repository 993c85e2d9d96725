//! Issue 69: a meter read as utility bills beside hourly meters. The small model's heating is
//! given as twelve bills of irregular periods (28 to 34 days, in therms, one an estimated read),
//! summed from the same noisy synthetic hours as the hourly cooling and electricity meters; the
//! heating set-point, which the heating meter carries, is identified from the bills. Real
//! EnergyPlus, PyTorch and ONNX Runtime; skipped (with a message) when the Python environment is
//! missing.

use std::path::Path;

mod common;
use common::have_engine;

const TRUTH: [(&str, f64); 2] = [
    ("lighting_power_density", 12.5),
    ("heating_setpoint_occupied", 22.5),
];

/// Days of each bill from 1 January 2021: read dates a month apart, give or take.
const BILL_DAYS: [i64; 12] = [30, 33, 29, 31, 32, 28, 30, 34, 29, 31, 30, 28];

/// The hourly meters without the `billed` columns, each of those as bills (`FILE_bills.csv`,
/// in `unit` = kWh / `per_unit`), one an estimated read.
fn to_bills(dir: &Path, billed: &[(&str, &str, f64)]) {
    let text = std::fs::read_to_string(dir.join("meters.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let cols: Vec<usize> = (billed.iter())
        .map(|(c, _, _)| header.iter().position(|h| h == c).unwrap())
        .collect();
    let keep = |r: &[&str]| -> String {
        (r.iter().enumerate())
            .filter(|(i, _)| !cols.contains(i))
            .map(|(_, v)| *v)
            .collect::<Vec<_>>()
            .join(",")
    };
    let mut hourly = keep(&header) + "\n";
    // Per billed column and day: the total and the peak hour (kWh).
    let mut daily: Vec<std::collections::BTreeMap<String, (f64, f64)>> =
        vec![Default::default(); cols.len()];
    for l in lines {
        let r: Vec<&str> = l.split(',').collect();
        hourly += &(keep(&r) + "\n");
        for (d, &c) in daily.iter_mut().zip(&cols) {
            let v = r[c].parse::<f64>().unwrap();
            let day = d.entry(r[0][..10].to_string()).or_default();
            *day = (day.0 + v, day.1.max(v));
        }
    }
    std::fs::write(dir.join("meters.csv"), hourly).unwrap();
    for ((column, unit, per_unit), daily) in billed.iter().zip(&daily) {
        let mut bills = String::from("start,end,quantity,unit,estimated,demand_kw\n");
        let mut start = chrono::NaiveDate::from_ymd_opt(2021, 1, 1).unwrap();
        for (i, days) in BILL_DAYS.iter().enumerate() {
            let end = start + chrono::Duration::days(*days - 1);
            let (kwh, peak) = (start.iter_days().take(*days as usize))
                .map(|d| daily[&d.to_string()])
                .fold((0.0, 0.0), |(t, p): (f64, f64), (dt, dp)| {
                    (t + dt, p.max(dp))
                });
            let estimated = if i == 2 { "E" } else { "" };
            bills += &format!(
                "{start},{end},{:.3},{unit},{estimated},{peak:.2}\n",
                kwh / per_unit
            );
            start = end + chrono::Duration::days(1);
        }
        std::fs::write(dir.join(format!("{column}_bills.csv")), bills).unwrap();
    }
}

fn project() -> String {
    let text = common::small_project("bills", 10)
        .replace(
            "calibrate = [\"lighting_power_density\", \"cooling_setpoint_occupied\"]",
            "calibrate = [\"lighting_power_density\", \"heating_setpoint_occupied\"]",
        )
        .replace(
            "[[meters.columns]]\ncolumn = \"heating_kwh\"\nrole = \"heating\"\nunit = \"kWh\"\n",
            "",
        )
        .replace(
            "[surrogate]\nepochs = 3\nthreads = 1\nhidden = 32\n",
            "[surrogate]\nepochs = 25\npatience = 6\nthreads = 2\nhidden = 64\n",
        )
        .replace(
            "[mcmc]\nchains = 2\niterations = 300\nburn_in = 100\nsegment = 100\n",
            "[mcmc]\nchains = 2\niterations = 600\nburn_in = 200\nsegment = 500\n",
        )
        .replace(
            "[validation]\n",
            "[validation]\nholdout = \"last 2 months\"\n",
        )
        .replace("predictive_draws = 0", "predictive_draws = 4")
        .replace(
            "[refine]\nrounds = 0\n",
            "[refine]\nrounds = 1\npoints = 4\niterations = 40\nburn_in = 20\n",
        )
        .replace("[mcmc]\n", "[mcmc]\ntemperature = \"surrogate_error\"\n");
    assert!(!text.contains("column = \"heating_kwh\"") && text.contains("heating_setpoint"));
    // The estimated read here is the meters' own sum (as exact as the others): taken as
    // measured (`"fit"`); bills alone below take the default, joined to the next read. With it
    // joined here the temperature measured through 8 bills came out at 48.6 (121.7 with 9) and
    // the heating set-point's interval, [19.45, 22.18], missed 22.5: the 10-point surrogate's
    // monthly bias, which T must carry, is measured at 4 refinement points only.
    text + "[[meters.bills]]\nfile = \"heating_kwh_bills.csv\"\nrole = \"heating\"\nestimated = \"fit\"\n"
}

#[test]
fn bills_beside_hourly_meters_identify_what_the_heating_carries() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let _machine = common::whole_machine();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("model.toml"), common::small_model()).unwrap();
    std::fs::write(dir.join("project.toml"), project()).unwrap();
    common::synthesize(dir, &TRUTH, &["--gap", "0:0"]);
    to_bills(dir, &[("heating_kwh", "therm", 29.307_107)]);

    let out = dir.join("out");
    let (log, summary) = common::calibrate(dir, &out);
    // The estimated read is noted; the bills of November and December are held out whole,
    // with the one of 4 October - 3 November that reaches into them: 9 bills fit, 3 check.
    let notes = summary["meter_notes"].to_string();
    assert!(
        notes.contains("heating_kwh_bills.csv: estimated reads: 2021-03-05 to 2021-04-02 (line 4)"),
        "{notes}"
    );
    let heating = summary["validation"]
        .as_array()
        .unwrap()
        .iter()
        .find(|v| v["output"] == "heating_kwh")
        .unwrap_or_else(|| panic!("{}", summary["validation"]));
    assert_eq!(heating["resolution"], "bills", "{heating}");
    assert_eq!(heating["n"], 9, "{heating}");
    // The billed peak demand (here the meters' own peak hour) against the model's.
    assert_eq!(heating["demand"]["bills"], 9, "{heating}");
    assert!(
        heating["demand"]["cv_rmse"].as_f64().unwrap().is_finite(),
        "{heating}"
    );
    assert_eq!(heating["held_out"]["hourly"]["n"], 3, "{heating}");
    eprintln!("heating on its bills at the estimate: {heating}");
    // The surrogate of ten design points over-predicts the monthly heating near the truth by
    // about 5 % (EnergyPlus at the untempered posterior's set-point of 21.5 C matched the bills),
    // which bills, unlike hours, cannot tell from a lower set-point: the refinement round's
    // EnergyPlus recoveries (through the bills' likelihood) measure that error and temper the
    // likelihood, so the intervals hold the truth (measured: heating set-point [19.18, 22.87],
    // 0.61 of the prior; untempered [20.93, 22.04] missed it; hourly heating [22.54, 22.61]).
    // The 3 % allowance as in tests/calibrate.rs.
    for (name, truth, narrower_than) in
        [(TRUTH[0].0, TRUTH[0].1, 0.5), (TRUTH[1].0, TRUTH[1].1, 0.9)]
    {
        let (lo, hi) = common::interval(&summary, name);
        let range = common::prior_range(&summary, name);
        let slack = 0.03 * range;
        eprintln!(
            "{name}: truth {truth}, 90 % [{lo:.3}, {hi:.3}], width {:.2} of the prior's",
            (hi - lo) / range
        );
        assert!(
            lo - slack <= truth && truth <= hi + slack,
            "{name}: truth {truth} outside [{lo}, {hi}] +- {slack}\n{log}"
        );
        assert!(
            (hi - lo) < narrower_than * range,
            "{name}: [{lo}, {hi}] of {range}\n{log}"
        );
    }
    let t = &summary["temperature"];
    eprintln!("temperature: {t}");
    // Predictive intervals per bill: the 9 fitted bills and the 3 held out, each bill's
    // interval around its own measured total's neighbourhood.
    let p = &summary["predictive"]["bills"][0];
    eprintln!(
        "bills' predictive: in sample {}, held out {}",
        p["in_sample"], p["held_out"]
    );
    assert_eq!(p["output"], "heating_kwh", "{p}");
    assert_eq!(p["bills"].as_array().unwrap().len(), 12, "{p}");
    let shares = p["in_sample"].as_array().unwrap();
    assert!(
        shares.iter().all(|s| s.as_f64().unwrap().is_finite()),
        "{p}"
    );
    assert!(p["held_out"].is_array(), "{p}");
    for b in p["bills"].as_array().unwrap() {
        let q: Vec<f64> = (b["quantiles"].as_array().unwrap().iter())
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert!(q.windows(2).all(|w| w[0] <= w[1]) && q[0] < q[4], "{b}");
    }
    // The hourly meters are judged hourly as before.
    let electricity = summary["validation"]
        .as_array()
        .unwrap()
        .iter()
        .find(|v| v["output"] == "electricity_kwh")
        .unwrap();
    assert!(electricity.get("resolution").is_none(), "{electricity}");
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        report.contains("heating_kwh (bills"),
        "the report names the bills"
    );
    assert!(
        report.contains("heating_kwh: billed peak demand over 9 bills"),
        "the report gives the billed demand"
    );
}

/// A building with bills alone (no hourly meter at all: no `[meters] file`), in three units:
/// the calibration runs to its end and judges each meter on its bills.
#[test]
fn a_project_of_bills_alone_calibrates() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("model.toml"), common::small_model()).unwrap();
    let head = common::small_project("bills-alone", 8);
    let (head, tail) = head.split_once("[meters]\n").unwrap();
    let tail = &tail[tail.find("[design]").unwrap()..];
    let mut project = format!("{head}{tail}");
    for (role, unit) in [
        ("heating", "MMBtu"),
        ("cooling", "kWh"),
        ("electricity", "MWh"),
    ] {
        project += &format!(
            "[[meters.bills]]\nfile = \"{role}_kwh_bills.csv\"\nrole = \"{role}\"\nunit = \"{unit}\"\n"
        );
    }
    std::fs::write(dir.join("project.toml"), &project).unwrap();
    common::synthesize(dir, &[("lighting_power_density", 12.5)], &["--gap", "0:0"]);
    to_bills(
        dir,
        &[
            ("heating_kwh", "MMBtu", 293.071_07),
            ("cooling_kwh", "kWh", 1.0),
            ("electricity_kwh", "MWh", 1000.0),
        ],
    );
    std::fs::remove_file(dir.join("meters.csv")).unwrap();
    let (log, summary) = common::calibrate(dir, &dir.join("out"));
    let validation = summary["validation"].as_array().unwrap();
    assert_eq!(validation.len(), 3, "{log}");
    for v in validation {
        assert_eq!(v["resolution"], "bills", "{v}");
        // Twelve bills, the estimated one joined to the next (the default, "merge").
        assert_eq!(v["n"], 11, "{v}");
    }
    let notes = summary["meter_notes"].to_string();
    assert!(
        notes.contains("heating_kwh_bills.csv: estimated reads joined to the actual read after them: lines 4, 5 as one bill, 2021-03-05 to 2021-05-03"),
        "{notes}"
    );
    eprintln!("{}", summary["validation"]);
}
