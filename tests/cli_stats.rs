//! CLI tests of `bemcal diagnose` and `bemcal metrics`.

use std::io::Write;
use std::process::Command;

fn bemcal(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_bemcal"))
        .args(args)
        .output()
        .expect("run bemcal")
}

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> String {
    let p = dir.path().join(name);
    std::fs::File::create(&p)
        .unwrap()
        .write_all(text.as_bytes())
        .unwrap();
    p.to_str().unwrap().to_string()
}

#[test]
fn metrics_table_and_json() {
    let dir = tempfile::tempdir().unwrap();
    // heating: y = [10, 12, 8, 10], yhat = [9, 12, 10, 11] -> NMBE -6.67 %, CV-RMSE 14.14 %.
    // cooling: hour 2 missing in the measured file; y = [4, 6, 2], yhat = [5, 3, 2]
    //          (hours 0, 1, 3) -> NMBE 25 %, CV-RMSE 55.9 %.
    let m = write(
        &dir,
        "m.csv",
        "timestamp,heating_kwh,cooling_kwh,electricity_kwh\n\
         2021-01-01T00:00,10,4,1\n2021-01-01T01:00,12,6,1\n\
         2021-01-01T02:00,8,,1\n2021-01-01T03:00,10,2,1\n",
    );
    // Rows match by time, whatever the ISO 8601 spelling (`bemcal predict` writes seconds).
    let s = write(
        &dir,
        "s.csv",
        "timestamp,heating_kwh,cooling_kwh\n\
         2021-01-01T00:00:00,9,5\n2021-01-01 01:00,12,3\n\
         2021-01-01T02:00:00,10,NaN\n2021-01-01T03:00,11,2\n",
    );
    let out = bemcal(&["metrics", "--measured", &m, "--simulated", &s, "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = v.as_array().unwrap();
    assert_eq!(rows.len(), 2, "only outputs in both files");
    assert_eq!(rows[0]["output"], "heating_kwh");
    assert_eq!(rows[0]["n"], 4);
    assert!((rows[0]["nmbe_percent"].as_f64().unwrap() + 200.0 / 30.0).abs() < 1e-9);
    assert!((rows[0]["cv_rmse_percent"].as_f64().unwrap() - 200f64.sqrt()).abs() < 1e-9);
    assert_eq!(rows[0]["pass"], true);
    assert_eq!(rows[1]["n"], 3);
    assert!((rows[1]["nmbe_percent"].as_f64().unwrap() - 25.0).abs() < 1e-9);
    assert_eq!(rows[1]["pass"], false);

    let table = bemcal(&["metrics", "--measured", &m, "--simulated", &s]);
    assert!(table.status.success());
    let text = String::from_utf8_lossy(&table.stdout);
    assert!(text.contains("heating_kwh") && text.contains("-6.67") && text.contains("55.90"));
}

#[test]
fn metrics_bad_cell_names_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let m = write(
        &dir,
        "m.csv",
        "timestamp,heating_kwh\n2021-01-01T00:00,1\n2021-01-01T01:00,abc\n",
    );
    let s = write(
        &dir,
        "s.csv",
        "timestamp,heating_kwh\n2021-01-01T00:00,1\n2021-01-01T01:00,2\n",
    );
    let out = bemcal(&["metrics", "--measured", &m, "--simulated", &s]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("m.csv:3") && err.contains("heating_kwh") && err.contains("abc"),
        "{err}"
    );
    // A timestamp that is not a time names its file, line and column.
    let bad = write(&dir, "bad.csv", "timestamp,heating_kwh\nt0,1\n");
    let out = bemcal(&["metrics", "--measured", &bad, "--simulated", &s]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.csv:2") && err.contains("timestamp") && err.contains("t0"),
        "{err}"
    );
}

#[test]
fn diagnose_matches_library() {
    let dir = tempfile::tempdir().unwrap();
    let mut csv = String::from("chain,draw,a,b\n");
    let mut chains = vec![Vec::new(), Vec::new()];
    for (c, chain) in chains.iter_mut().enumerate() {
        for d in 0..51 {
            // Deterministic, irregular values.
            let a = (((d * 37 + c * 11) % 23) as f64).sin() + c as f64 * 0.1;
            chain.push(a);
            csv.push_str(&format!("{c},{d},{a},{}\n", 2.0 * a));
        }
    }
    let p = write(&dir, "draws.csv", &csv);
    let out = bemcal(&["diagnose", "--draws", &p, "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let want = bemcal_stats::diagnostics::diagnose(&chains).unwrap();
    assert_eq!(v[0]["parameter"], "a");
    assert!((v[0]["rhat"].as_f64().unwrap() - want.rhat).abs() < 1e-12);
    assert!((v[0]["ess_bulk"].as_f64().unwrap() - want.ess_bulk).abs() < 1e-9);
    assert!((v[1]["mean"].as_f64().unwrap() - 2.0 * want.mean).abs() < 1e-12);

    let table = bemcal(&["diagnose", "--draws", &p]);
    assert!(table.status.success());
    assert!(String::from_utf8_lossy(&table.stdout).contains("ess_tail"));

    // The same draws with chains numbered from 1, as CmdStan writes them: the same diagnosis,
    // and a note on stderr (stdout stays JSON).
    let cmdstan: String = csv
        .lines()
        .enumerate()
        .map(|(i, l)| match (i, l.split_once(',')) {
            (0, _) | (_, None) => format!("{l}\n"),
            (_, Some((c, rest))) => format!("{},{rest}\n", c.parse::<u32>().unwrap() + 1),
        })
        .collect();
    let q = write(&dir, "cmdstan.csv", &cmdstan);
    let from_one = bemcal(&["diagnose", "--draws", &q, "--json"]);
    assert!(from_one.status.success());
    assert_eq!(from_one.stdout, out.stdout);
    let err = String::from_utf8_lossy(&from_one.stderr);
    assert!(
        err.contains("numbered from 1 (as CmdStan numbers them)"),
        "{err}"
    );
}

#[test]
fn diagnose_bad_input_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "d.csv", "chain,draw,a\n0,0,1\n0,1,2\n1,0,3\n");
    let out = bemcal(&["diagnose", "--draws", &p]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("chain 1 has 1 draws"));
    let q = write(&dir, "e.csv", "chain,draw,a\n0,0,1\n0,x,2\n");
    let out = bemcal(&["diagnose", "--draws", &q]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("e.csv: line 3, column 'draw'"));
}

/// A bug (a panic) gives a short message that names the file with the details and says how to
/// report it, not Rust's raw panic text; the exit status is 101.
#[test]
fn a_panic_prints_a_short_message_and_keeps_the_details() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_bemcal"))
        .arg("--version")
        .env("BEMCAL_PANIC_TEST", "1")
        .env("XDG_STATE_HOME", dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(101));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("internal error") && err.contains("please report"),
        "{err}"
    );
    assert!(err.len() < 600 && !err.contains("RUST_BACKTRACE"), "{err}");
    let logs: Vec<_> = std::fs::read_dir(dir.path().join("bemcal"))
        .unwrap()
        .flatten()
        .collect();
    assert_eq!(logs.len(), 1);
    let details = std::fs::read_to_string(logs[0].path()).unwrap();
    assert!(err.contains(&logs[0].path().display().to_string()), "{err}");
    assert!(
        details.contains("backtrace") && details.contains("--version"),
        "{details}"
    );
}

/// `bemcal metrics --bills`: each bill against the simulation's total over its days, Guideline
/// 14's monthly criteria on the bills; a bill the simulation does not cover is listed, not
/// compared; a bad bills file names its line.
#[test]
fn metrics_on_bills() {
    let dir = tempfile::tempdir().unwrap();
    // 1 kWh of heating an hour from 1 January to 31 March 2021.
    let mut sim = String::from("timestamp,heating_kwh\n");
    let start = chrono::NaiveDate::from_ymd_opt(2021, 1, 1)
        .unwrap()
        .and_hms_opt(0, 0, 0)
        .unwrap();
    for h in 0..90 * 24 {
        let t = start + chrono::Duration::hours(h);
        sim.push_str(&format!("{},1\n", t.format("%Y-%m-%dT%H:%M")));
    }
    let s = write(&dir, "s.csv", &sim);
    // 30 days (720 kWh simulated), 33 days (792), and a bill past the simulation's end.
    let b = write(
        &dir,
        "gas.csv",
        "start,end,quantity,unit,estimated,demand_kw\n\
         2021-01-05,2021-02-03,700,kWh,,1.5\n\
         2021-02-04,2021-03-08,800,kWh,E,1.2\n\
         2021-03-09,2021-04-06,500,kWh,,\n",
    );
    let out = bemcal(&[
        "metrics",
        "--simulated",
        &s,
        "--bills",
        &format!("heating_kwh={b}"),
        // The figures by hand take the estimated read as measured (the default joins it to
        // the next read: precal's unit tests).
        "--bill-estimated",
        "fit",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("estimated reads: 2021-02-04"));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let row = &v[0];
    assert_eq!(row["resolution"], "bills");
    assert_eq!(row["n"], 2);
    // Residuals -20 and +8 kWh on a mean of 750: NMBE -12 / 750, CV-RMSE sqrt(464) / 750.
    assert!(
        (row["nmbe_percent"].as_f64().unwrap() + 1.6).abs() < 1e-9,
        "{row}"
    );
    assert!(
        (row["cv_rmse_percent"].as_f64().unwrap() - 464f64.sqrt() / 7.5).abs() < 1e-9,
        "{row}"
    );
    assert_eq!(row["pass"], true);
    assert_eq!(row["bills"][1]["simulated_kwh"], 792.0);
    assert_eq!(row["bills"][1]["days"], 33);
    assert!(row["bills"][2]["simulated_kwh"].is_null());
    // Billed demand against the simulation's peak hour (1 kWh): residuals 0.5 and 0.2 on a
    // mean of 1.35.
    assert_eq!(row["bills"][0]["simulated_peak_kw"], 1.0);
    assert_eq!(row["demand"]["bills"], 2, "{row}");
    assert!(
        (row["demand"]["nmbe"].as_f64().unwrap() - 0.7 / 1.35 * 100.0).abs() < 1e-9,
        "{row}"
    );

    let overlap = write(
        &dir,
        "bad.csv",
        "start,end,quantity\n2021-01-05,2021-02-03,700\n2021-02-01,2021-03-08,800\n",
    );
    let out = bemcal(&[
        "metrics",
        "--simulated",
        &s,
        "--bills",
        &format!("heating_kwh={overlap}"),
        "--bill-unit",
        "therm",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("bad.csv:3") && err.contains("overlaps the bill of line 2"),
        "{err}"
    );
}
