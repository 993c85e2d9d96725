//! A small synthetic calibration, end to end, with real EnergyPlus, PyTorch and ONNX Runtime:
//! meters come from EnergyPlus at known "true" parameters (plus noise and a month-long gap);
//! `bemcal calibrate` must recover them within the posterior interval and pass ASHRAE
//! Guideline 14. Skipped (with a message) when the Python environment is missing.

use std::path::Path;
use std::process::Command;

mod common;
use common::{bemcal, finished, golden_epw, have_engine, repo, run_ok};

/// The Golden TMY3 file as projects and commands name it, from EnergyPlus's WeatherData.
const GOLDEN_BUNDLED: &str = "bundled:USA_CO_Golden-NREL.724666_TMY3.epw";

const TRUTH: [(&str, f64); 2] = [
    ("lighting_power_density", 12.5),
    ("cooling_setpoint_occupied", 22.5),
];

fn write_project(dir: &Path) {
    std::fs::write(dir.join("model.toml"), common::small_model()).unwrap();
    let mut project = std::fs::read_to_string(repo().join("examples/office/project.toml")).unwrap();
    // Small settings for CI: two parameters, ten design points, short chains.
    let cut = project.find("[design]").unwrap();
    project.truncate(cut);
    project = project.replace(
        "weather = \"bundled:USA_CO_Golden-NREL.724666_TMY3.epw\"",
        "weather = \"bundled:USA_CO_Golden-NREL.724666_TMY3.epw\"\ncalibrate = [\"lighting_power_density\", \"cooling_setpoint_occupied\"]",
    );
    project.push_str(
        "[design]\npoints = 10\nparallel = 2\n[surrogate]\nepochs = 25\npatience = 6\nthreads = 2\nhidden = 64\n[mcmc]\nchains = 2\niterations = 600\nburn_in = 200\nsegment = 500\nkernel = \"mh\"\nstart = \"prior\"\nmax_extensions = 0\n[refine]\nrounds = 0\n\
         [validation]\nholdout = \"last 2 months\"\npredictive_draws = 4\n\
         error_model = { heating_kwh = \"hour_of_day\" }\n",
    );
    std::fs::write(dir.join("project.toml"), project).unwrap();
}

#[test]
fn small_synthetic_calibration_recovers_truth_and_passes_g14() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let _machine = common::whole_machine();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_project(dir);
    common::synthesize(dir, &TRUTH, &[]);

    let out = dir.join("out");
    let (log, summary) = common::calibrate(dir, &out);

    // Recovery: the estimate lies within 5 % of the prior range of the truth, and the truth lies
    // in the 90 % posterior interval widened by 3 % of the prior range. The widening is the
    // surrogate's systematic error: the likelihood (iid or AR(1)) conditions on the surrogate, so
    // the posterior interval does not include the surrogate's own bias (measured here: up to
    // ~2 % of the range with 8 design points and the simple water-coil analysis; with the
    // detailed one (issue 17) the cooling set-point's reached 3.2 % at 8 points, within 3 %
    // at 10).
    for (name, truth) in TRUTH {
        let p = summary["posterior"]["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .unwrap();
        let (range, estimate) = range_and_estimate(&summary, name);
        let (q5, q95) = (p["q5"].as_f64().unwrap(), p["q95"].as_f64().unwrap());
        eprintln!("{name}: truth {truth}, estimate {estimate:.4}, 90 % [{q5:.4}, {q95:.4}]");
        assert!(
            (estimate - truth).abs() <= 0.05 * range,
            "{name}: estimate {estimate} too far from truth {truth}\n{log}"
        );
        let slack = 0.03 * range;
        assert!(
            q5 - slack <= truth && truth <= q95 + slack,
            "{name}: truth {truth} outside [{q5}, {q95}] +- {slack}\n{log}"
        );
        assert!(
            p["width_ratio"].as_f64().unwrap() < 0.5,
            "{name} not learned: {p}"
        );
    }
    for v in summary["validation"].as_array().unwrap() {
        assert!(v["pass"].as_bool().unwrap(), "G14 failed: {v}\n{log}");
    }
    // The estimate is the MAP draw where EnergyPlus passes Guideline 14 there, hourly and
    // monthly, else by the rule of bemcal_calibrate::best_simulated over the points validation
    // simulated (the MAP draw, the 4 predictive draws, up to two steps of output space mapping
    // of up to two points each where no draw passes hourly), recorded per point in the
    // summary; calibrated_model_reproduces_the_validation below checks that calibrated.csv,
    // .toml and .idf are the chosen draw's.
    assert_eq!(summary["estimate"], "best_simulated");
    let choice = &summary["estimate_choice"];
    let fits = choice["candidates"].as_array().unwrap();
    assert!((2..=9).contains(&fits.len()), "{choice}");
    let label = |f: &serde_json::Value| f["label"].as_str().unwrap().to_string();
    let recorded: Vec<bemcal_calibrate::Fit> = fits
        .iter()
        .map(|f| bemcal_calibrate::Fit {
            hourly: f["limit_ratio"].as_f64().unwrap_or(f64::INFINITY),
            monthly: f["monthly_limit_ratio"].as_f64(),
        })
        .collect();
    // A year of meters: every point has monthly figures.
    assert!(recorded.iter().all(|f| f.monthly.is_some()), "{choice}");
    let first_mapped = (fits.iter())
        .position(|f| bemcal_calibrate::keys::is_mapped(&label(f)))
        .unwrap_or(fits.len());
    let map_ran = label(&fits[0]) == "calibrated";
    let b = bemcal_calibrate::best_simulated(&recorded, map_ran, first_mapped).unwrap();
    assert_eq!(choice["chosen"], fits[b]["label"], "{choice}");
    for f in [
        "draws.csv",
        "posterior_predictive.csv",
        "validation/calibrated.csv",
        "surrogate/surrogate.json",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    surrogate_matches_torch_on_real_output(&out.join("surrogate"));
    calibrated_model_reproduces_the_validation(dir, &out);
    held_out_period_is_judged_and_never_fitted(dir, &out, &summary);
    output_space_mapping_moves_towards_the_meters(dir, &out);

    // The initial model (prior modes) is reported beside the calibrated one.
    assert_eq!(summary["initial"].as_array().unwrap().len(), 3);
    // So is the surrogate at the estimate: on this well-learned small problem it fits the meters
    // as EnergyPlus does (both pass), which tells a user the surrogate is not the bottleneck.
    let sur = summary["surrogate_at_estimate"].as_array().unwrap();
    assert_eq!(sur.len(), 3);
    for v in sur {
        assert!(v["nmbe"].as_f64().unwrap().is_finite(), "{v}");
        assert!(
            v["pass"].as_bool().unwrap(),
            "surrogate at the estimate: {v}"
        );
    }

    // A rerun reuses every finished stage: no EnergyPlus design run, no training.
    let again = bemcal()
        .arg("calibrate")
        .arg(dir.join("project.toml"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let log2 = String::from_utf8_lossy(&again.stderr);
    assert!(finished(again.status), "{log2}");
    assert!(
        log2.contains("0 run") && log2.contains("10 reused"),
        "{log2}"
    );
    assert!(log2.contains("reusing the one trained earlier"), "{log2}");
    // The report is where the README says: written by `bemcal calibrate` itself.
    assert!(out.join("report.html").is_file(), "{log2}");
    // ... but not chains fitted with another held-out period: they saw other hours.
    let e = refused_rerun(dir, &out, &["--holdout", "last 1 month"]);
    assert!(
        e.contains("chains fitted to other data (holdout last 2 months (1464 hours)")
            && e.contains("this run's (holdout last 1 month (744 hours), every meter fitted)"),
        "{e}"
    );

    // ... nor chains fitted to other readings: a meter file edited since.
    let meters = std::fs::read_to_string(dir.join("meters.csv")).unwrap();
    let mut lines: Vec<String> = meters.lines().map(String::from).collect();
    let mut cells: Vec<String> = lines[1].split(',').map(String::from).collect();
    cells[1] = format!("{}", cells[1].parse::<f64>().unwrap_or(0.0) * 3.0 + 1.0);
    lines[1] = cells.join(",");
    std::fs::write(dir.join("meters.csv"), lines.join("\n") + "\n").unwrap();
    let recorded = std::fs::read_to_string(out.join("holdout.txt")).unwrap();
    let e = refused_rerun(dir, &out, &[]);
    assert!(e.contains("chains fitted to other meter readings"), "{e}");
    let after = std::fs::read_to_string(out.join("holdout.txt")).unwrap();
    assert_eq!(recorded, after, "a refused rerun rewrote holdout.txt");
    std::fs::write(dir.join("meters.csv"), meters).unwrap();

    cross_validation_by_month(dir, &out);

    // The same posterior with HMC (gradients through the surrogate's VJP graph), from optimised
    // starts, and the heating meter compared but not fitted (`fit = false`: the two parameters
    // are the electricity's and the cooling's): short chains, the same recovery and Guideline
    // 14, heating's included.
    let project = std::fs::read_to_string(dir.join("project.toml"))
        .unwrap()
        .replace(
        "iterations = 600\nburn_in = 200\nsegment = 500\nkernel = \"mh\"\nstart = \"prior\"\n",
        "iterations = 80\nburn_in = 30\nsegment = 500\nkernel = \"hmc\"\nstart = \"optimised\"\n",
    )
        .replace(
            "role = \"heating\"\n",
            "role = \"heating\"\nfit = false\n",
        );
    std::fs::write(dir.join("project.toml"), project).unwrap();
    // The folder's chains fitted heating: refused until they are removed.
    let e = refused_rerun(dir, &out, &[]);
    assert!(
        e.contains("every meter fitted) than this run's") && e.contains("not fitted: heating_kwh)"),
        "{e}"
    );
    std::fs::remove_file(out.join("chains.json")).unwrap();
    let (log3, summary) = common::calibrate(dir, &out);
    // Dual averaging aims at 0.7 over a 30-iteration burn-in; 50 draws after it scatter around
    // that (0.48-0.84 seen on one machine): a broken kernel sits near 0.
    for a in summary["acceptance_rate"].as_array().unwrap() {
        assert!(a.as_f64().unwrap() > 0.3, "HMC acceptance {a}\n{log3}");
    }
    for (name, truth) in TRUTH {
        let (range, estimate) = range_and_estimate(&summary, name);
        eprintln!("HMC {name}: truth {truth}, estimate {estimate:.4}");
        assert!(
            (estimate - truth).abs() <= 0.05 * range,
            "HMC {name}: estimate {estimate} too far from truth {truth}\n{log3}"
        );
    }
    for v in summary["validation"].as_array().unwrap() {
        assert!(v["pass"].as_bool().unwrap(), "HMC: G14 failed: {v}\n{log3}");
    }
    assert_eq!(summary["validation"].as_array().unwrap().len(), 3);
    assert_eq!(summary["not_fitted"], serde_json::json!(["heating_kwh"]));
    assert!(summary["sigma_delta_kwh"].get("heating_kwh").is_none());
    results_load_in_python_as_arviz(&out, &dir.join("project.toml"));
    model_form_tells_reached_from_out_of_reach(dir, &out, &summary);
}

/// Issue 19: the model form of this synthetic building (EnergyPlus plus noise) reaches every
/// meter, and the same EnergyPlus runs against a meter holding a load the model lacks (a
/// constant 3x the electricity's mean added) say that meter is out of reach, mostly a constant
/// offset, with the lighting density at its prior's bound named as the largest lever (too
/// small to reach it), while the other meters stay reached.
fn model_form_tells_reached_from_out_of_reach(dir: &Path, out: &Path, summary: &serde_json::Value) {
    let f = &summary["model_form"];
    let meters = f["meters"].as_array().unwrap();
    assert_eq!(meters.len(), 3, "{f}");
    for m in meters {
        assert_eq!(m["reach"]["verdict"], "reached", "{m}");
        assert_eq!(m["patterns"].as_array().unwrap().len(), 4, "{m}");
        assert!(
            m["findings"][0].as_str().unwrap().starts_with("reached"),
            "{m}"
        );
    }
    let csv = std::fs::read_to_string(out.join("validation/discrepancy.csv")).unwrap();
    assert_eq!(csv.lines().count(), 8761);
    assert_eq!(csv.lines().next().unwrap().split(',').count(), 1 + 3 * 3);

    let altered = tempfile::tempdir().unwrap();
    for f in ["model.toml", "project.toml"] {
        std::fs::copy(dir.join(f), altered.path().join(f)).unwrap();
    }
    let meters = std::fs::read_to_string(dir.join("meters.csv")).unwrap();
    let header: Vec<&str> = meters.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "electricity_kwh").unwrap();
    // The gap is written as NaN: it stays missing.
    let values: Vec<f64> = meters
        .lines()
        .skip(1)
        .filter_map(|l| l.split(',').nth(col)?.parse::<f64>().ok())
        .filter(|v| v.is_finite())
        .collect();
    let offset = 3.0 * values.iter().sum::<f64>() / values.len() as f64;
    let mut text = String::new();
    for (i, line) in meters.lines().enumerate() {
        let mut cells: Vec<String> = line.split(',').map(String::from).collect();
        match cells[col].parse::<f64>() {
            Ok(v) if i > 0 && v.is_finite() => cells[col] = format!("{}", v + offset),
            _ => {}
        }
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    std::fs::write(altered.path().join("meters.csv"), text).unwrap();
    let project = bemcal_calibrate::Project::load(&altered.path().join("project.toml")).unwrap();
    let cal = bemcal_calibrate::Calibration::load(project, out).unwrap();
    let run = |label: &str| -> bemcal_energyplus::HourlyOutputs {
        let text = std::fs::read_to_string(out.join("validation").join(label)).unwrap();
        let saved: serde_json::Value = serde_json::from_str(&text).unwrap();
        serde_json::from_value(saved["outputs"].clone()).unwrap()
    };
    let posterior = serde_json::from_value(summary["posterior"].clone()).unwrap();
    let draws: Vec<_> = (10..14)
        .map(|k| run(&format!("point_{k:03}.json")))
        .collect();
    let report =
        bemcal_calibrate::model_form::report(&cal, &run("point_000.json"), &draws, &posterior)
            .unwrap();
    for m in &report.meters {
        let verdict = m.reach.verdict;
        if m.output == "electricity_kwh" {
            assert_eq!(verdict, bemcal_stats::model_form::Verdict::Level, "{m:?}");
            assert!(!m.reach.within_draws, "{m:?}");
            assert!(
                m.findings[0].starts_with("out of reach"),
                "{:?}",
                m.findings
            );
            assert!(
                m.findings[1].contains("constant offset"),
                "{:?}",
                m.findings
            );
            assert!(
                m.findings[1].contains("below the meter"),
                "{:?}",
                m.findings
            );
            // What the calibrated parameters could do about it, from the design's EnergyPlus
            // runs: the lighting density at its prior's maximum raises the electricity, by
            // far less than the load the model lacks.
            let levers = m.levers.as_ref().expect("levers of a meter out of reach");
            eprintln!("levers: {}", levers.finding());
            assert_eq!(levers.parameters[0].parameter, "lighting_power_density");
            assert_eq!(
                levers.parameters[0].bound,
                bemcal_stats::model_form::Bound::Upper
            );
            assert!(levers.parameters[0].moves_kwh > 0.0 && levers.gap_kwh > 0.0);
            assert!(
                (m.findings.iter()).any(|f| f.contains("no setting inside these priors")),
                "{:?}",
                m.findings
            );
        } else {
            assert_eq!(verdict, bemcal_stats::model_form::Verdict::Reached, "{m:?}");
        }
    }
}

/// Issue 22: `bemcal.load` (python/bemcal) reads the output folder as an ArviZ InferenceData
/// whose groups, dimensions and values match draws.csv and summary.json, `arviz.summary` on it
/// agrees with `bemcal diagnose` to 1e-6, and `bemcal export` writes the same InferenceData as
/// netCDF, and `bemcal.calibrate` streams a (reused) calibration's lines and loads its folder
/// (tests/python/check_load.py makes the comparisons).
fn results_load_in_python_as_arviz(out: &Path, project: &Path) {
    let diagnose = run_ok(
        bemcal()
            .arg("diagnose")
            .arg("--draws")
            .arg(out.join("draws.csv"))
            .arg("--json"),
    );
    let diagnose_file = out.join("diagnose.json");
    std::fs::write(&diagnose_file, &diagnose.stdout).unwrap();
    let nc = out.join("posterior.nc");
    let export = run_ok(bemcal().arg("export").arg(out).arg("--to").arg(&nc));
    assert!(
        String::from_utf8_lossy(&export.stdout).contains("groups posterior"),
        "{}",
        String::from_utf8_lossy(&export.stdout)
    );
    let check = run_ok(
        Command::new(repo().join(".venv/bin/python"))
            .arg(repo().join("tests/python/check_load.py"))
            .arg(out)
            .arg(&diagnose_file)
            .arg(&nc)
            .arg(project)
            .env("PYTHONPATH", repo().join("python"))
            .env("BEMCAL_BIN", env!("CARGO_BIN_EXE_bemcal")),
    );
    eprintln!("{}", String::from_utf8_lossy(&check.stdout).trim());
}

/// The last two months are held out (`[validation] holdout`): summary.json judges the model
/// on them (Guideline 14, predictive coverage), and they never enter the likelihood: with the
/// held-out meters tripled the same seeds give bit-identical chains, while tripling a month of
/// the calibration period changes them.
fn held_out_period_is_judged_and_never_fitted(dir: &Path, out: &Path, summary: &serde_json::Value) {
    let h = &summary["holdout"];
    assert_eq!(h["period"], "last 2 months", "{h}");
    assert_eq!(h["hours"].as_u64(), Some((30 + 31) * 24), "{h}");
    for v in summary["validation"].as_array().unwrap() {
        let held = &v["held_out"];
        assert!(held["hourly"]["n"].as_u64().unwrap() > 1000, "{v}");
        assert!(held["hourly"]["pass"].as_bool().unwrap(), "held out: {v}");
        assert_eq!(held["monthly"]["n"].as_u64(), Some(2), "{v}");
        assert!(v["monthly"]["n"].as_u64().unwrap() >= 9, "{v}");
    }
    // Predictive intervals from EnergyPlus at 4 posterior draws: every coverage is a share,
    // and the 90 % interval holds most of the calibration hours of this synthetic building
    // (its meters are EnergyPlus plus noise: the error model is right by construction).
    let p = &summary["predictive"];
    assert_eq!(p["draws"].as_u64(), Some(4), "{p}");
    // The heating's intervals take its own error model (`error_model = { heating_kwh = ... }`),
    // the other meters the one their calibration months favour (the default, "auto"), each
    // judged on the months of the calibration period by intervals built without it.
    assert_eq!(p["error_model"], "auto", "{p}");
    for o in p["outputs"].as_array().unwrap() {
        let favoured = &o["cross_validation_favours"]["error_model"];
        let own = if o["output"] == "heating_kwh" {
            "hour_of_day"
        } else {
            favoured.as_str().unwrap()
        };
        for m in o["by_error_model"].as_array().unwrap() {
            let cv = &m["cross_validated"];
            // Ten calibration months (a month the gap empties is not judged).
            assert!((9..=10).contains(&cv["months"].as_u64().unwrap()), "{o}");
            assert!(cv["mean_month_miss_points"]
                .as_f64()
                .is_some_and(f64::is_finite));
        }
        assert_eq!(o["error_model"], own, "{o}");
        assert_eq!(o["by_error_model"][0]["error_model"], own, "{o}");
        for m in o["by_error_model"].as_array().unwrap() {
            for c in m["in_sample"]
                .as_array()
                .unwrap()
                .iter()
                .chain(m["held_out"].as_array().unwrap())
            {
                let f = c["fraction"].as_f64().unwrap();
                assert!(
                    (0.0..=1.0).contains(&f) && c["mean_width"].as_f64().unwrap() > 0.0,
                    "{c}"
                );
            }
            let in90 = m["in_sample"][1]["fraction"].as_f64().unwrap();
            assert!((0.75..=1.0).contains(&in90), "{o}");
            // In-sample the share to hold against nominal is nominal by construction: the PIT
            // share where some hour reads at an atom (0, where a draw finds the meter idle),
            // else the share of hours inside.
            for c in m["in_sample"].as_array().unwrap() {
                let share = (c.get("pit_fraction").and_then(|v| v.as_f64()))
                    .unwrap_or_else(|| c["fraction"].as_f64().unwrap());
                let nominal = c["nominal"].as_f64().unwrap();
                assert!((share - nominal).abs() < 0.01, "{c}");
            }
            assert_eq!(m["held_out"].as_array().unwrap().len(), 2, "{o}");
            // Recalibrated on the calibration hours: nested levels inside (0, 1), and the
            // posterior's own intervals' coverage kept beside.
            let levels = m["levels"].as_array().unwrap();
            let (l50, l90) = (&levels[0], &levels[1]);
            let at = |l: &serde_json::Value, i: usize| l[i].as_f64().unwrap();
            assert!(0.0 <= at(l90, 0) && at(l90, 0) <= at(l50, 0), "{o}");
            assert!(at(l50, 0) < at(l50, 1) && at(l50, 1) <= at(l90, 1) && at(l90, 1) <= 1.0);
            let before = &m["before_recalibration"];
            for c in before["in_sample"]
                .as_array()
                .unwrap()
                .iter()
                .chain(before["held_out"].as_array().unwrap())
            {
                assert!(
                    (0.0..=1.0).contains(&c["fraction"].as_f64().unwrap()),
                    "{o}"
                );
            }
        }
    }
    // Intervals of daily and monthly totals (issue 24), with the AR(1) noise of a sum and as if
    // hours were independent: shares of whole measured days and months, in-sample and held out
    // (November and December), the AR(1) intervals before recalibration no narrower where
    // phi > 0.
    for o in p["outputs"].as_array().unwrap() {
        let phi = o["residual_phi"].as_f64().unwrap();
        assert!((-1.0..1.0).contains(&phi), "{o}");
        let totals = o["totals"].as_array().unwrap();
        assert_eq!(totals.len(), 2, "{o}");
        for t in totals {
            let held = t["ar1"]["held_out"].as_array().unwrap();
            assert_eq!(held.len(), 2, "{t}");
            let periods = if t["period"] == "day" { 61 } else { 2 };
            assert_eq!(held[0]["hours"].as_u64(), Some(periods), "{t}");
            for kind in ["ar1", "before_recalibration", "independent"] {
                for c in t[kind]["in_sample"].as_array().unwrap() {
                    assert!(
                        (0.0..=1.0).contains(&c["fraction"].as_f64().unwrap()),
                        "{t}"
                    );
                }
            }
            // Before recalibration, the AR(1) noise of a sum is no narrower than independent
            // hours' (the recalibrated `ar1` may be either).
            let width = |kind: &str| t[kind]["in_sample"][1]["mean_width"].as_f64().unwrap();
            if phi > 0.0 {
                assert!(width("before_recalibration") >= width("independent"), "{t}");
            }
        }
    }
    let csv = std::fs::read_to_string(out.join("validation/predictive_intervals.csv")).unwrap();
    assert_eq!(csv.lines().count(), 8761);
    assert!(
        csv.lines().last().unwrap().split(',').nth(1) == Some("1"),
        "Dec 31 is held out"
    );

    // The same chains from the same seeds, on meters altered in the held-out months or not.
    // (The project's own output folder gives the surrogate.)
    let chains_on = |months: &[&str]| -> (String, bemcal_calibrate::FittedData) {
        let altered = tempfile::tempdir().unwrap();
        for f in ["model.toml", "project.toml"] {
            std::fs::copy(dir.join(f), altered.path().join(f)).unwrap();
        }
        let meters = std::fs::read_to_string(dir.join("meters.csv")).unwrap();
        let mut text = String::new();
        for (i, line) in meters.lines().enumerate() {
            let mut cells: Vec<String> = line.split(',').map(String::from).collect();
            if i > 0 && months.iter().any(|m| cells[0][5..7] == **m) {
                for c in cells.iter_mut().skip(1).filter(|c| !c.is_empty()) {
                    *c = format!("{}", c.parse::<f64>().unwrap() * 3.0);
                }
            }
            text.push_str(&cells.join(","));
            text.push('\n');
        }
        std::fs::write(altered.path().join("meters.csv"), text).unwrap();
        let project =
            bemcal_calibrate::Project::load(&altered.path().join("project.toml")).unwrap();
        let cal = bemcal_calibrate::Calibration::load(project, out).unwrap();
        let mut sampler = cal.sampler().unwrap();
        let starts = sampler.starts();
        let mut states = sampler.new_chains(&starts, 0, 0).unwrap();
        // 60 iterations of burn-in: the chains' whole states (positions, log posteriors,
        // adaptation, random streams) decide every later draw.
        sampler.advance(&mut states, 60).unwrap();
        (serde_json::to_string(&states).unwrap(), cal.fitted_data())
    };
    let original = chains_on(&[]);
    // The readings' fingerprint follows the fitted hours only, as the chains do.
    assert_eq!(
        original,
        chains_on(&["11", "12"]),
        "held-out meters changed the chains or the fitted readings"
    );
    let (chains_06, fitted_06) = chains_on(&["06"]);
    assert_ne!(original.1, fitted_06, "June altered, same fingerprint");
    assert_ne!(
        original.0, chains_06,
        "a calibration month must change the chains"
    );

    // Chains saved in another space (here without the sampled ln sigma_delta of each meter)
    // are refused, never read as this posterior's coordinates.
    let mut project = bemcal_calibrate::Project::load(&dir.join("project.toml")).unwrap();
    let cal = bemcal_calibrate::Calibration::load(project.clone(), out).unwrap();
    let mut sampler = cal.sampler().unwrap();
    let mut saved = sampler.new_chains(&sampler.starts(), 0, 0).unwrap();
    project.mcmc.sigma_delta = bemcal_calibrate::project::SigmaDeltaMode::Sampled;
    let cal = bemcal_calibrate::Calibration::load(project, out).unwrap();
    let e = cal.sampler().unwrap().advance(&mut saved, 1).unwrap_err();
    assert!(
        e.to_string()
            .contains("saved chains have 2 dimensions, this run samples 5"),
        "{e}"
    );
}

/// One step of output space mapping (`Sampler::mapped_mode`, what validation runs where
/// EnergyPlus fits no posterior draw), from the initial model (the prior modes, simulated by
/// validation): EnergyPlus at the mapped point fits the meters better than at the anchor and
/// passes Guideline 14 hourly, and the point moves towards the truth.
fn output_space_mapping_moves_towards_the_meters(dir: &Path, out: &Path) {
    use bemcal_calibrate::{limit_ratio, Calibration, Project, INITIAL_KEY};
    let project = Project::load(&dir.join("project.toml")).unwrap();
    let cal = Calibration::load(project, out).unwrap();
    let inp = &cal.inputs;
    let anchor = cal.initial_point();
    let vdir = out.join("validation");
    let eplus =
        bemcal_calibrate::design::saved_outputs(&vdir, INITIAL_KEY, &inp.plan.values(&anchor))
            .expect("validation saved the initial model's run");
    let mode = cal.sampler().unwrap().mapped_mode(&anchor, &eplus).unwrap();
    let at_anchor = limit_ratio(
        &cal.validate(INITIAL_KEY, "initial", &anchor).unwrap(),
        &inp.fitted,
    );
    // Key 9 lies between the fallbacks' and the predictive draws' (validation.rs, predictive.rs).
    let at_mode = limit_ratio(&cal.validate(9, "mapped_test", &mode).unwrap(), &inp.fitted);
    eprintln!("mapping from the prior modes {anchor:?} -> {mode:?}: worst meter {at_anchor:.2} -> {at_mode:.2} of the limits");
    assert!(
        at_mode < at_anchor && at_mode <= 1.0,
        "{at_anchor} -> {at_mode}"
    );
    for (k, name) in inp.plan.calibrated.iter().enumerate() {
        let truth = TRUTH.iter().find(|(n, _)| n == name).unwrap().1;
        assert!(
            (mode[k] - truth).abs() < (anchor[k] - truth).abs(),
            "{name}: {} -> {} against the truth {truth}",
            anchor[k],
            mode[k]
        );
    }
    for f in ["point_009.json", "mapped_test.csv"] {
        std::fs::remove_file(vdir.join(f)).unwrap();
    }
}

/// `bemcal calibrate DIR/project.toml ARGS --out OUT`, which must be refused (exit status 1)
/// before it runs anything: its error output.
fn refused_rerun(dir: &Path, out: &Path, args: &[&str]) -> String {
    let run = bemcal()
        .arg("calibrate")
        .arg(dir.join("project.toml"))
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&run.stderr).into_owned();
    assert_eq!(run.status.code(), Some(1), "{e}");
    e
}

/// A parameter's prior range and its calibrated value in summary.json.
fn range_and_estimate(summary: &serde_json::Value, name: &str) -> (f64, f64) {
    let range = common::prior_range(summary, name);
    let estimate = summary["calibrated_values"][name]
        .as_f64()
        .unwrap_or_else(|| panic!("no calibrated value of {name}"));
    (range, estimate)
}

#[test]
fn bad_project_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("project.toml");
    std::fs::write(&p, "name = \"x\"\nmodel = \"m.toml\"\nweather = \"w.epw\"\n[meters]\nfile = \"m.csv\"\n[mcmc]\nchains = 2\niterations = 100\nburn_in = 200\n").unwrap();
    let o = bemcal()
        .arg("calibrate")
        .arg(&p)
        .arg("--out")
        .arg(tmp.path().join("o"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("project.toml") && e.contains("burn_in = 200"),
        "{e}"
    );
    std::fs::write(&p, "name = \"x\"\nmodel = \"m.toml\"\nweather = \"w.epw\"\n[meters]\nfile = \"m.csv\"\n[mcmc]\nchainz = 2\n").unwrap();
    let o = bemcal()
        .arg("calibrate")
        .arg(&p)
        .arg("--out")
        .arg(tmp.path().join("o"))
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("project.toml:7") && e.contains("chainz"),
        "{e}"
    );
}

/// `bemcal check` loads the project and everything it names and says what a calibration would
/// use, running nothing; a broken meters file is refused naming it, with a non-zero exit.
#[test]
fn check_loads_everything_and_runs_nothing() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_project(dir);
    common::synthesize(dir, &[], &[]);
    let before: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    let o = run_ok(bemcal().arg("check").arg(dir.join("project.toml")));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains(": OK"), "{text}");
    assert!(
        text.contains("2 calibrated (lighting_power_density, cooling_setpoint_occupied)"),
        "{text}"
    );
    // The synthetic meters miss 15 July - 15 August (744 h); November and December (1,464 h)
    // are held out.
    assert!(
        text.contains("meter for heating_kwh: 6552 of 8760 hours measured (calibration period)"),
        "{text}"
    );
    assert!(
        text.contains("held out: last 2 months (1464 hours"),
        "{text}"
    );
    assert!(text.contains("Mh from Prior starts"), "{text}");
    let after: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(before, after, "check wrote nothing");

    let meters = std::fs::read_to_string(dir.join("meters.csv")).unwrap();
    std::fs::write(
        dir.join("meters.csv"),
        meters.replace("cooling_kwh", "cooling"),
    )
    .unwrap();
    let o = bemcal()
        .arg("check")
        .arg(dir.join("project.toml"))
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("meters.csv") && e.contains("cooling_kwh"), "{e}");
}

/// The surrogate trained on real EnergyPlus output: held-out error reported per output, and
/// Rust/ort agrees with PyTorch to 1e-4 relative on the trainer's parity windows.
fn surrogate_matches_torch_on_real_output(dir: &Path) {
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("surrogate.json")).unwrap()).unwrap();
    for o in ["heating_kwh", "cooling_kwh", "electricity_kwh"] {
        let m = &meta["held_out"]["metrics"][o];
        let rmse = m["rmse_kwh"].as_f64().unwrap_or(f64::NAN);
        assert!(rmse.is_finite() && rmse > 0.0, "held-out RMSE of {o}: {m}");
        assert!(
            m["cv_rmse_pct"].as_f64().is_some(),
            "held-out CV-RMSE of {o}: {m}"
        );
    }
    let parity = bemcal_surrogate::ParityFixture::read(dir).unwrap();
    let e = bemcal_surrogate::Surrogate::load(dir, 1)
        .unwrap()
        .parity_error(&parity)
        .unwrap();
    assert!(e < 1e-4, "ort vs torch relative error {e:.2e}");
}

/// The calibrated model a user takes away: `calibrated.idf` runs in EnergyPlus as it is (HVAC
/// templates already expanded), and `bemcal simulate --values calibrated.toml` reproduces the
/// validation run at the estimate hour by hour.
fn calibrated_model_reproduces_the_validation(dir: &Path, out: &Path) {
    let text = std::fs::read_to_string(out.join("calibrated.idf")).unwrap();
    let idf = bemcal_energyplus::idf::Idf::parse(&text, &out.join("calibrated.idf")).unwrap();
    assert!(
        !idf.has_class_prefix("HVACTemplate:"),
        "calibrated.idf still has HVAC templates"
    );
    let engine = bemcal_energyplus::Engine::locate().unwrap();
    let run_dir = dir.join("calibrated-run");
    let e = std::process::Command::new(&engine.executable)
        .arg("-w")
        .arg(golden_epw())
        .arg("-d")
        .arg(&run_dir)
        .arg(out.join("calibrated.idf"))
        .output()
        .unwrap();
    let err = std::fs::read_to_string(run_dir.join("eplusout.err")).unwrap_or_default();
    assert!(
        e.status.success() && err.contains("Completed Successfully") && !err.contains("** Severe"),
        "EnergyPlus on calibrated.idf:\n{}",
        err.lines().rev().take(10).collect::<Vec<_>>().join("\n")
    );
    let again = dir.join("again.csv");
    run_ok(
        bemcal()
            .args(["simulate", "--model"])
            .arg(dir.join("model.toml"))
            .arg("--weather")
            .arg(golden_epw())
            .arg("--values")
            .arg(out.join("calibrated.toml"))
            .arg("--out")
            .arg(&again),
    );
    let read = |p: &Path| -> Vec<Vec<f64>> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').skip(1).map(|v| v.parse().unwrap()).collect())
            .collect()
    };
    let (a, b) = (read(&out.join("validation/calibrated.csv")), read(&again));
    assert_eq!(a.len(), 8760);
    assert_eq!(
        a, b,
        "simulate --values calibrated.toml differs from the validation run"
    );
    // As calibrated.toml says: from the project's folder, the project's model and weather.
    let toml = std::fs::read_to_string(out.join("calibrated.toml")).unwrap();
    assert!(
        toml.contains("bemcal simulate --project project.toml --values calibrated.toml"),
        "{toml}"
    );
    let by_project = dir.join("again-project.csv");
    run_ok(
        bemcal()
            .current_dir(dir)
            .args(["simulate", "--project", "project.toml", "--values"])
            .arg(out.join("calibrated.toml"))
            .arg("--out")
            .arg(&by_project),
    );
    assert_eq!(
        a,
        read(&by_project),
        "simulate --project --values calibrated.toml differs from the validation run"
    );
}

/// A building closed on Thursdays and Fridays (meters from EnergyPlus with that calendar):
/// pre-calibration labels the low days as the days off by what they look like (a calendar
/// majority called them working days), suggests `day_types_file`, and with it pointing at its
/// calendar.csv the calibration recovers the weekend schedule and passes Guideline 14; with the
/// usual Saturday-Sunday rule, EnergyPlus fails Guideline 14 for heating and cooling even at the
/// true values (a calibration with the rule, when this test still ran one, missed the weekend
/// fraction by 0.10 and failed the same two meters; two calibrations were too slow for CI).
#[test]
fn the_meters_day_type_calendar_recovers_a_moved_weekend() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let _machine = common::whole_machine();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // Meters of twelve months from April 2021 (an AMI export's "last 12 months"): the model runs
    // across the year end, pre-calibration infers that year from the meters' stamps and its
    // day-type calendar spans it.
    let mut calendar = String::from("date,label\n");
    let mut d = chrono::NaiveDate::from_ymd_opt(2021, 4, 1).unwrap();
    let end = chrono::NaiveDate::from_ymd_opt(2022, 4, 1).unwrap();
    while d < end {
        let off = matches!(
            chrono::Datelike::weekday(&d),
            chrono::Weekday::Thu | chrono::Weekday::Fri
        );
        calendar.push_str(&format!(
            "{d},{}\n",
            if off { "weekend" } else { "weekday" }
        ));
        d = d.succ_opt().unwrap();
    }
    std::fs::write(dir.join("true_calendar.csv"), calendar).unwrap();
    let small = common::small_model() + "\nyear = \"2021-04\"\n";
    std::fs::write(
        dir.join("truth.toml"),
        format!("{small}\nday_types_file = \"true_calendar.csv\"\n"),
    )
    .unwrap();
    let (weekday_05, weekend_06) = (0.75, 0.35);
    // EnergyPlus at the true values: `command` (synthesize or simulate) of `model` into `out`.
    let epw = golden_epw();
    // The true values as `--set` arguments.
    let truth_set = [
        "--set".to_string(),
        format!("schedule_weekday_05={weekday_05}"),
        "--set".to_string(),
        format!("schedule_weekend_06={weekend_06}"),
    ];
    let at_truth = |command: &str, model: &str, out: &str| {
        run_ok(
            bemcal()
                .args([command, "--model"])
                .arg(dir.join(model))
                .arg("--weather")
                .arg(&epw)
                .args(&truth_set)
                .arg("--out")
                .arg(dir.join(out)),
        )
    };
    at_truth("synthesize", "truth.toml", "meters.csv");
    run_ok(
        bemcal()
            .args(["precalibrate", "--meters"])
            .arg(dir.join("meters.csv"))
            .arg("--weather")
            .arg(GOLDEN_BUNDLED)
            .arg("--out")
            .arg(dir.join("precal")),
    );
    // The settings of the small synthetic calibration above, for the two schedule parameters
    // (`write_project` writes the small model as it is: the year is added after).
    write_project(dir);
    std::fs::write(dir.join("model.toml"), &small).unwrap();
    std::fs::write(
        dir.join("model_cal.toml"),
        format!("{small}\nday_types_file = \"precal/calendar.csv\"\n"),
    )
    .unwrap();
    let mut project = std::fs::read_to_string(dir.join("project.toml"))
        .unwrap()
        .replace(
            "calibrate = [\"lighting_power_density\", \"cooling_setpoint_occupied\"]",
            "calibrate = [\"schedule_weekday_05\", \"schedule_weekend_06\"]",
        );
    assert!(project.contains("schedule_weekend_06"));
    // Chains of 800 iterations (300 of them burn-in), as its tolerance below was measured with:
    // two schedule fractions are well identified by a year of meters.
    // No predictive draws: this test checks the calendar, the test above the intervals.
    project = project
        .replace(
            "iterations = 600\nburn_in = 200\n",
            "iterations = 800\nburn_in = 300\n",
        )
        .replace("predictive_draws = 4\n", "predictive_draws = 0\n");
    assert!(project.contains("iterations = 800") && project.contains("predictive_draws = 0\n"));
    project = project.replace("model = \"model.toml\"", "model = \"model_cal.toml\"");
    // The 8-point design its tolerance below was measured with (10 points, the recovery test's,
    // gave weekend_06 0.387 against 0.35).
    project = project.replace("points = 10\n", "points = 8\n");
    assert!(project.contains("points = 8\n"));
    std::fs::write(dir.join("project.toml"), &project).unwrap();
    let (log, cal) = common::calibrate(dir, &dir.join("out-cal"));
    // The year from April, as pre-calibration inferred it and as the outputs list it.
    let quality: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("precal/quality.json")).unwrap()).unwrap();
    assert_eq!(quality["year"], "2021-04", "{}", quality["notes"]);
    let first_and_last = |path: &Path| {
        let text = std::fs::read_to_string(path).unwrap();
        let stamp = |l: &str| l.split(',').next().unwrap().to_string();
        let rows: Vec<&str> = text.lines().skip(1).filter(|l| !l.is_empty()).collect();
        (stamp(rows[0]), stamp(rows[rows.len() - 1]))
    };
    // Pre-calibration labels the low days as the days off by what they look like (their
    // calendar says weekday: a majority rule called them working days) and says what to paste.
    let calendar = std::fs::read_to_string(dir.join("precal/calendar.csv")).unwrap();
    let thursday = calendar
        .lines()
        .find(|l| l.starts_with("2021-04-08,"))
        .unwrap();
    assert!(thursday.contains(",weekend,"), "{thursday}");
    let precal_summary = std::fs::read_to_string(dir.join("precal/summary.txt")).unwrap();
    assert!(
        precal_summary.contains("days off on calendar weekdays: Thursday")
            && precal_summary.contains("calendar.csv\""),
        "{precal_summary}"
    );
    let (first, last) = first_and_last(&dir.join("precal/calendar.csv"));
    assert_eq!(
        (first.as_str(), last.as_str()),
        ("2021-04-01", "2022-03-31")
    );
    let (first, last) = first_and_last(&dir.join("out-cal/posterior_predictive.csv"));
    assert_eq!(
        (first.as_str(), last.as_str()),
        ("2021-04-01T00:00", "2022-03-31T23:00")
    );
    // `last 2 months` in time order: February and March 2022.
    assert_eq!(
        cal["holdout"]["hours"],
        (28 + 31) * 24,
        "{}",
        cal["holdout"]
    );
    // The Saturday-Sunday rule at the true values.
    at_truth("simulate", "model.toml", "rule.csv");
    let out = run_ok(
        bemcal()
            .args(["metrics", "--json", "--measured"])
            .arg(dir.join("meters.csv"))
            .arg("--simulated")
            .arg(dir.join("rule.csv")),
    );
    let rule: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rule_pass = |name: &str| {
        rule.as_array()
            .unwrap()
            .iter()
            .find(|m| m["output"] == name)
            .unwrap_or_else(|| panic!("no {name} in {rule}"))["pass"]
            .as_bool()
            .unwrap()
    };

    let estimate = |s: &serde_json::Value, n: &str| range_and_estimate(s, n).1;
    let passes = |s: &serde_json::Value| {
        s["validation"]
            .as_array()
            .unwrap()
            .iter()
            .all(|v| v["pass"].as_bool().unwrap())
    };
    eprintln!(
        "weekend_06 truth {weekend_06}: with the calendar {:.3}; weekday_05 truth {weekday_05}: {:.3}; the rule at the truth: {rule}",
        estimate(&cal, "schedule_weekend_06"),
        estimate(&cal, "schedule_weekday_05"),
    );
    // Within 0.03 of the truth, as the weekday fraction: the surrogate of 8 design points and 25
    // epochs carries a systematic error of that size (measured on this model with the
    // reference's 128 hidden units: weekend_06 0.3455 over calendar year 2021 with
    // November-December held out, 0.339 with February-March held out, 0.328 over April 2021 -
    // March 2022 (weekday_05 0.733, 160 s); with the 64 units used here 0.377 and 0.746, 93 s;
    // EnergyPlus at the truth fits the meters of either year alike, CV-RMSE 5.7-9.5 % against
    // 5 % noise).
    assert!(
        (estimate(&cal, "schedule_weekend_06") - weekend_06).abs() < 0.03,
        "{log}"
    );
    assert!(
        (estimate(&cal, "schedule_weekday_05") - weekday_05).abs() < 0.03,
        "{log}"
    );
    assert!(passes(&cal), "with the calendar: {}", cal["validation"]);
    assert!(
        !rule_pass("heating_kwh") && !rule_pass("cooling_kwh"),
        "with the rule at the truth: {rule}"
    );

    // `bemcal predict --model` takes the model's calendar (its `day_types_file`), as the
    // calibration did: the surrogate at the truth then puts Fridays where the meters have them
    // (off days), where `--year` alone (the Saturday-Sunday rule) makes them working days.
    let fridays = |path: &Path| -> f64 {
        let text = std::fs::read_to_string(path).unwrap();
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = header.iter().position(|h| *h == "electricity_kwh").unwrap();
        lines
            .map(|l| l.split(',').collect::<Vec<&str>>())
            .filter(|r| {
                let d = chrono::NaiveDate::parse_from_str(&r[0][..10], "%Y-%m-%d").unwrap();
                chrono::Datelike::weekday(&d) == chrono::Weekday::Fri
            })
            .filter_map(|r| r[col].parse::<f64>().ok())
            .filter(|v| v.is_finite())
            .sum()
    };
    let predict = |calendar: &[&str], out: &str| {
        run_ok(
            bemcal()
                .args(["predict", "--surrogate"])
                .arg(dir.join("out-cal/surrogate"))
                .arg("--weather")
                .arg(&epw)
                .args(calendar)
                .args(&truth_set)
                .arg("--out")
                .arg(dir.join(out)),
        );
        fridays(&dir.join(out))
    };
    let model_cal = dir.join("model_cal.toml");
    let with_calendar = predict(
        &["--model", model_cal.to_str().unwrap()],
        "predict_model.csv",
    );
    let with_rule = predict(&["--year", "2021-04"], "predict_rule.csv");
    let measured = fridays(&dir.join("meters.csv"));
    eprintln!("Friday electricity, kWh: meters {measured:.0}, predict --model {with_calendar:.0}, --year {with_rule:.0}");
    assert!(
        with_calendar < with_rule
            && (with_calendar - measured).abs() < (with_rule - measured).abs(),
        "Friday electricity, kWh: meters {measured:.0}, predict --model {with_calendar:.0}, --year {with_rule:.0}"
    );
}

/// Cross-validation by month (issue 24) on two months: the calibration on every month reuses
/// this test's design and surrogate (laid into `cv/all` as a fold's folder is seeded), each
/// fold reuses them again (no EnergyPlus design run, no training), and each fold's held-out
/// Guideline 14, and the pooled figures, are those of EnergyPlus at the fold's estimate
/// (`validation/calibrated.csv`) against the meters on the held-out month, recomputed here.
fn cross_validation_by_month(dir: &Path, out: &Path) {
    // Each fold is a calibration of its own: short chains (120 iterations, 60 of them burn-in),
    // two predictive draws and no output space mapping keep the three calibrations' cost down
    // (this checks the folds' bookkeeping and figures; the recovery is checked above). At 300
    // iterations the chains were 70 of this check's 101 s on 2 cores.
    let project = std::fs::read_to_string(dir.join("project.toml"))
        .unwrap()
        .replace("holdout = \"last 2 months\"\n", "")
        .replace(
            "iterations = 600\nburn_in = 200\n",
            "iterations = 120\nburn_in = 60\n",
        )
        .replace(
            "predictive_draws = 4\n",
            "predictive_draws = 2\nmapping_steps = 0\n",
        );
    assert!(project.contains("iterations = 120") && project.contains("mapping_steps = 0"));
    std::fs::write(dir.join("project_cv.toml"), project).unwrap();
    let cv = dir.join("cv");
    let all = cv.join("all");
    std::fs::create_dir_all(all.join("simulations")).unwrap();
    std::fs::copy(out.join("design.csv"), all.join("design.csv")).unwrap();
    for e in std::fs::read_dir(out.join("simulations")).unwrap() {
        let p = e.unwrap().path();
        if p.is_file() {
            std::fs::copy(&p, all.join("simulations").join(p.file_name().unwrap())).unwrap();
        }
    }
    common::copy_dir(&out.join("surrogate"), &all.join("surrogate"));
    let r = bemcal()
        .arg("crossval")
        .arg(dir.join("project_cv.toml"))
        .arg("--out")
        .arg(&cv)
        .args(["--months", "jan,jul"])
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{log}");
    for fold in ["fold jan", "fold jul"] {
        assert!(
            log.contains(&format!("{fold}: design: settled earlier"))
                && log.contains(&format!(
                    "{fold}: surrogate: reusing the one trained earlier"
                )),
            "{log}"
        );
    }
    assert!(!log.contains("simulations: 1/"), "{log}");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(cv.join("crossval.json")).unwrap()).unwrap();
    let folds = json["folds"].as_array().unwrap();
    assert_eq!(folds.len(), 2, "{json}");

    // Guideline 14 recomputed from the CSV files: residual = meter - model, p = 1.
    let read = |p: &Path| -> Vec<Vec<String>> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .map(|l| l.split(',').map(String::from).collect())
            .collect()
    };
    let meters = read(&dir.join("meters.csv"));
    let mut pooled: std::collections::BTreeMap<String, (usize, f64, f64, f64)> = Default::default();
    for (f, month) in folds.iter().zip(["01", "07"]) {
        let fold = cv.join(format!("fold_{month}"));
        let model = read(&fold.join("validation/calibrated.csv"));
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(fold.join("summary.json")).unwrap()).unwrap();
        assert_eq!(
            summary["holdout"]["period"],
            ["jan", "jul"][(month == "07") as usize]
        );
        for o in f["outputs"].as_array().unwrap() {
            let name = o["output"].as_str().unwrap();
            if o["held_out"].is_null() {
                // No Guideline 14 for this meter in this month (a zero measured mean): the
                // pooled figures say so and leave the month out.
                let p = json["pooled"].as_array().unwrap();
                let p = p.iter().find(|p| p["output"] == name).unwrap();
                let m: u64 = month.parse().unwrap();
                assert!(
                    p["months_without_figures"]
                        .as_array()
                        .is_some_and(|v| v.iter().any(|x| x.as_u64() == Some(m))),
                    "{p}"
                );
                continue;
            }
            let col = meters[0].iter().position(|c| c == name).unwrap();
            let mcol = model[0].iter().position(|c| c == name).unwrap();
            let (mut n, mut y, mut r, mut r2) = (0usize, 0.0, 0.0, 0.0);
            for (a, b) in meters[1..].iter().zip(&model[1..]) {
                assert_eq!(a[0], b[0]);
                if &a[0][5..7] != month {
                    continue;
                }
                let (Ok(m), Ok(s)) = (a[col].parse::<f64>(), b[mcol].parse::<f64>()) else {
                    continue;
                };
                if m.is_finite() && s.is_finite() {
                    n += 1;
                    y += m;
                    r += m - s;
                    r2 += (m - s) * (m - s);
                }
            }
            let held = &o["held_out"];
            let ybar = y / n as f64;
            let nmbe = r / ((n - 1) as f64 * ybar) * 100.0;
            let cv_rmse = (r2 / (n - 1) as f64).sqrt() / ybar * 100.0;
            assert_eq!(held["n"].as_u64(), Some(n as u64), "{name} {month}: {held}");
            assert!(
                (held["nmbe"].as_f64().unwrap() - nmbe).abs() < 1e-3,
                "{name} {month}: {held} vs {nmbe}"
            );
            assert!(
                (held["cv_rmse"].as_f64().unwrap() - cv_rmse).abs() < 1e-3,
                "{name} {month}: {held} vs {cv_rmse}"
            );
            let p = pooled.entry(name.to_string()).or_default();
            *p = (p.0 + n, p.1 + y, p.2 + r, p.3 + r2);
        }
    }
    for p in json["pooled"].as_array().unwrap() {
        let name = p["output"].as_str().unwrap();
        let Some(&(n, y, r, r2)) = pooled.get(name) else {
            continue;
        };
        let ybar = y / n as f64;
        let h = &p["hourly"];
        assert_eq!(h["n"].as_u64(), Some(n as u64), "{p}");
        assert!(
            (h["nmbe"].as_f64().unwrap() - r / ((n - 1) as f64 * ybar) * 100.0).abs() < 1e-3,
            "{p}"
        );
        assert!(
            (h["cv_rmse"].as_f64().unwrap() - (r2 / (n - 1) as f64).sqrt() / ybar * 100.0).abs()
                < 1e-3,
            "{p}"
        );
        for c in p["coverage"].as_array().unwrap() {
            assert!(
                (0.0..=1.0).contains(&c["fraction"].as_f64().unwrap()),
                "{p}"
            );
        }
    }
}

/// A simulation past its wall-time limit (`[simulation] timeout_s`) is a recorded failure
/// whose reason names the limit, and the failed-points machinery takes it from there, through
/// `bemcal calibrate` on the local path. Deterministic: at 0.05 s no EnergyPlus run of the
/// small model can finish (one takes about 1.5 s), so every run fails. (1) The 3 design points
/// and the spares tried for them are each killed at the limit: every failure is recorded in
/// `simulations/failures.json` with the limit in it, and the calibration ends (exit status 1)
/// with the design error grouping them all under the limit and naming the setting. (2) Run
/// again, nothing is simulated again: the failures are kept and give the same error. (3) With
/// the limit back at its default the failures at the lower limit no longer hold: the 3 points
/// are simulated again and the calibration runs to its end with all 3.
#[test]
fn a_simulation_past_its_time_limit_is_a_recorded_failure() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (dir, out) = (tmp.path(), tmp.path().join("out"));
    std::fs::write(dir.join("model.toml"), common::small_model()).unwrap();
    common::synthesize(dir, &[], &[]);
    let project = common::small_project("time-limited", 3);
    std::fs::write(
        dir.join("project.toml"),
        format!("{project}[simulation]\ntimeout_s = 0.05\n"),
    )
    .unwrap();
    let stopped = |what: &str| {
        let run = bemcal()
            .arg("calibrate")
            .arg(dir.join("project.toml"))
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let log = String::from_utf8_lossy(&run.stderr).into_owned();
        assert_eq!(run.status.code(), Some(1), "{what}:\n{log}");
        let failures: Vec<serde_json::Value> =
            serde_json::from_slice(&std::fs::read(out.join("simulations/failures.json")).unwrap())
                .unwrap();
        let n = failures.len();
        for words in [
            "only 0 of 3 design points could be simulated".to_string(),
            format!("; {n} EnergyPlus run(s) failed"),
            format!("{n} x EnergyPlus time limit of 0.05 s ([simulation] timeout_s)"),
            "a longer limit ([simulation] timeout_s, default 900 s)".to_string(),
        ] {
            assert!(log.contains(&words), "{what}: no '{words}' in:\n{log}");
        }
        (log, failures)
    };

    let (log, failures) = stopped("the first run");
    let n = failures.len();
    for f in &failures {
        let e = f["error"].as_str().unwrap();
        assert!(e.contains("exceeded its time limit of 0.05 s"), "{e}");
    }
    let slots: std::collections::BTreeSet<u64> = failures
        .iter()
        .map(|f| f["slot"].as_u64().unwrap())
        .collect();
    assert_eq!(slots.len(), 3, "every slot failed: {failures:?}");
    assert!(n > 3, "spares were tried: {failures:?}");
    let failed_now = "EnergyPlus failed (EnergyPlus time limit of 0.05 s";
    assert_eq!(log.matches(failed_now).count(), n, "{log}");

    let (log, again) = stopped("the rerun");
    assert_eq!(again, failures);
    assert!(
        !log.contains("EnergyPlus failed ("),
        "simulated again:\n{log}"
    );
    let kept = "failed in an earlier run (EnergyPlus time limit of 0.05 s";
    assert_eq!(log.matches(kept).count(), n, "{log}");

    std::fs::write(dir.join("project.toml"), &project).unwrap();
    let (log, summary) = common::calibrate(dir, &out);
    let retried = "failed in an earlier run at a lower limit (EnergyPlus time limit of 0.05 s";
    assert_eq!(log.matches(retried).count(), n, "{log}");
    assert!(!log.contains("), not repeated"), "{log}");
    assert!(log.contains("simulations: 3 run ("), "{log}");
    assert_eq!(summary["design"]["simulated"], 3, "{}", summary["design"]);
    assert_eq!(summary["design"]["failed"], serde_json::json!([]));
}
