//! `bemcal metrics`: ASHRAE Guideline 14 NMBE and CV-RMSE of simulated against measured hourly
//! series (p = 1, hourly criteria |NMBE| <= 10 %, CV-RMSE <= 30 %), and against utility bills
//! (`--bills OUTPUT=FILE`: each bill's total, the monthly criteria |NMBE| <= 5 %,
//! CV-RMSE <= 15 % on the bills).
//!
//! The CSVs have a `timestamp` column and output columns such as `heating_kwh`; rows are
//! matched by timestamp, every output present in both files is compared, and an empty or
//! `NaN` cell is a missing hour. A bill is compared where the simulated file has every hour of
//! every day it covers (29 February aside, which simulations leave out).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};

/// Arguments of `bemcal metrics`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Measured hourly series (CSV with a `timestamp` column).
    #[arg(long, required_unless_present = "bills")]
    pub measured: Option<PathBuf>,
    /// Utility bills of an output, OUTPUT=FILE (`heating_kwh=gas_bills.csv`; repeatable): a
    /// CSV of `start`, `end`, `quantity` (optionally `unit`, `demand_kw`, `estimated`), as
    /// `[[meters.bills]]` reads it.
    #[arg(long, value_name = "OUTPUT=FILE")]
    pub bills: Vec<String>,
    /// Unit of the bills' quantities where the file has no `unit` column (kWh, therm, MMBtu,
    /// GJ, ..., or a gas volume: m3, ft3, ccf, mcf).
    #[arg(long)]
    pub bill_unit: Option<String>,
    /// kWh per m3 of gas, for bills in volumes.
    #[arg(long)]
    pub calorific_value: Option<f64>,
    /// The bills' end dates are read dates (the start of the next bill), not the last day
    /// billed.
    #[arg(long)]
    pub bill_end_exclusive: bool,
    /// What the bills' estimated reads are taken for: merge (joined with the next actual read,
    /// which trued them up), drop (the meter failed) or fit (as measured).
    #[arg(long, default_value = "merge", value_parser = estimated_reads)]
    pub bill_estimated: bemcal_precal::meters::EstimatedReads,
    /// Simulated hourly series (CSV with a `timestamp` column).
    #[arg(long)]
    pub simulated: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// A CSV table read as text: header and rows with their 1-based line numbers.
pub(crate) struct Table {
    pub path: PathBuf,
    pub header: Vec<String>,
    pub rows: Vec<(usize, Vec<String>)>,
}

impl Table {
    /// Read a comma-separated file with a header line (RFC 4180 quoting, fields trimmed);
    /// blank lines are skipped.
    pub fn read(path: &Path) -> anyhow::Result<Table> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        // The file's line of a record starting at `byte` (the csv crate's count and offset
        // include the blank lines it skips before a record).
        let line_at = |byte: u64| {
            let bytes = text.as_bytes();
            let mut i = (byte as usize).min(bytes.len());
            while i < bytes.len() && matches!(bytes[i], b'\n' | b'\r') {
                i += 1;
            }
            1 + bytes[..i].iter().filter(|&&b| b == b'\n').count()
        };
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let bad = |e: csv::Error| match e.position() {
            Some(p) => anyhow::anyhow!("{}:{}: {e}", path.display(), line_at(p.byte())),
            None => anyhow::anyhow!("{}: {e}", path.display()),
        };
        let header: Vec<String> = reader
            .headers()
            .map_err(bad)?
            .iter()
            .map(|h| h.trim_start_matches('\u{feff}').to_string())
            .collect();
        if header.iter().all(String::is_empty) {
            bail!("{}: empty file, expected a header line", path.display());
        }
        let mut rows = Vec::new();
        for record in reader.records() {
            let record = record.map_err(bad)?;
            let line = record.position().map_or(0, |p| line_at(p.byte()));
            rows.push((line, record.iter().map(str::to_string).collect()));
        }
        Ok(Table {
            path: path.to_path_buf(),
            header,
            rows,
        })
    }

    /// Index of a required column.
    pub fn column(&self, name: &str) -> anyhow::Result<usize> {
        self.header
            .iter()
            .position(|h| h == name)
            .with_context(|| format!("{}:1: no column `{name}`", self.path.display()))
    }

    /// A number cell; empty or `NaN` gives NaN (missing). An infinite value (`inf`, `1e999`)
    /// is an error: it would turn every mean and sum it enters into `inf`.
    pub fn number(&self, line: usize, col: usize, text: &str) -> anyhow::Result<f64> {
        if text.is_empty() || text.eq_ignore_ascii_case("nan") {
            return Ok(f64::NAN);
        }
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => bail!(
                "{}:{line}: column `{}`: `{}` is not a finite number",
                self.path.display(),
                self.header[col],
                excerpt(text)
            ),
            Err(_) => bail!(
                "{}:{line}: column `{}`: `{}` is not a number",
                self.path.display(),
                self.header[col],
                excerpt(text)
            ),
        }
    }
}

/// At most 40 bytes of a cell, for messages (a cell can be megabytes long).
pub(crate) fn excerpt(s: &str) -> std::borrow::Cow<'_, str> {
    bemcal_excerpt::excerpt(s, 40)
}

/// Metrics of one output, hourly or on its bills.
#[derive(Debug, serde::Serialize)]
struct Row {
    output: String,
    /// `hourly` or `bills`.
    resolution: &'static str,
    /// Hours, or bills compared.
    n: usize,
    nmbe_percent: f64,
    cv_rmse_percent: f64,
    pass: bool,
    /// Each bill, with `resolution = "bills"`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    bills: Vec<BillRow>,
    /// The bills' billed peak demand against the simulation's peak hour of each bill, where
    /// two or more state one.
    #[serde(skip_serializing_if = "Option::is_none")]
    demand: Option<bemcal_calibrate::metrics::DemandMetrics>,
}

/// One bill against the simulation.
#[derive(Debug, serde::Serialize)]
struct BillRow {
    start: chrono::NaiveDate,
    /// The last day billed.
    end: chrono::NaiveDate,
    days: i64,
    measured_kwh: f64,
    /// None: the simulation lacks a day of the bill.
    simulated_kwh: Option<f64>,
    estimated: bool,
    /// The billed peak demand, kW.
    #[serde(skip_serializing_if = "Option::is_none")]
    demand_kw: Option<f64>,
    /// The simulation's peak hour over the bill's days (kWh in the hour = kW).
    #[serde(skip_serializing_if = "Option::is_none")]
    simulated_peak_kw: Option<f64>,
}

/// An ISO 8601 local timestamp, `YYYY-MM-DDTHH:MM[:SS]` (or with a space for `T`).
/// `--bill-estimated`: the project file's `estimated = "..."` words.
fn estimated_reads(s: &str) -> Result<bemcal_precal::meters::EstimatedReads, String> {
    serde_json::from_value(serde_json::Value::String(s.to_string()))
        .map_err(|_| format!("'{s}': expected merge, drop or fit"))
}

fn parse_timestamp(path: &Path, line: usize, v: &str) -> anyhow::Result<chrono::NaiveDateTime> {
    let v = v.trim();
    for f in [
        "%Y-%m-%dT%H:%M:%S",
        "%Y-%m-%dT%H:%M",
        "%Y-%m-%d %H:%M:%S",
        "%Y-%m-%d %H:%M",
    ] {
        if let Ok(t) = chrono::NaiveDateTime::parse_from_str(v, f) {
            return Ok(t);
        }
    }
    bail!(
        "{}:{line}: column 'timestamp': `{}` is not an ISO 8601 time (expected YYYY-MM-DDTHH:MM or YYYY-MM-DDTHH:MM:SS)",
        path.display(),
        excerpt(v)
    )
}

/// The time of each row of `t` (timestamp column `col`), in row order; a time given twice is
/// an error naming both lines.
fn row_times(t: &Table, col: usize) -> anyhow::Result<Vec<chrono::NaiveDateTime>> {
    let mut first_line: HashMap<chrono::NaiveDateTime, usize> = HashMap::new();
    let mut times = Vec::with_capacity(t.rows.len());
    for (line, f) in &t.rows {
        let time = parse_timestamp(&t.path, *line, &f[col])?;
        if let Some(first) = first_line.insert(time, *line) {
            bail!(
                "{}:{line}: duplicate timestamp `{}`: line {first} has the same time",
                t.path.display(),
                excerpt(&f[col])
            );
        }
        times.push(time);
    }
    Ok(times)
}

/// Run `bemcal metrics`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let sim = Table::read(&args.simulated)?;
    let st = sim.column("timestamp")?;
    let sim_times = row_times(&sim, st)?;
    let mut results = match &args.measured {
        Some(m) => hourly(&Table::read(m)?, &sim, &sim_times)?,
        None => vec![],
    };
    for b in &args.bills {
        results.push(on_bills(&args, b, &sim, &sim_times)?);
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        print_table(&results);
    }
    Ok(())
}

fn print_table(results: &[Row]) {
    for (resolution, limits) in [
        ("hourly", "|NMBE| <= 10 %, CV-RMSE <= 30 %"),
        ("bills", "on the bills: |NMBE| <= 5 %, CV-RMSE <= 15 %"),
    ] {
        let rows: Vec<&Row> = results
            .iter()
            .filter(|r| r.resolution == resolution)
            .collect();
        if rows.is_empty() {
            continue;
        }
        println!(
            "{:<24} {:>7} {:>9} {:>11}  pass ({limits})",
            "output",
            if resolution == "hourly" { "n" } else { "bills" },
            "NMBE %",
            "CV-RMSE %"
        );
        for r in rows {
            println!(
                "{:<24} {:>7} {:>9.2} {:>11.2}  {}",
                r.output,
                r.n,
                r.nmbe_percent,
                r.cv_rmse_percent,
                if r.pass { "yes" } else { "no" }
            );
            if let Some(d) = &r.demand {
                println!("  {}", d.sentence(&r.output));
            }
            for b in &r.bills {
                println!(
                    "  {} to {} ({:>2} days{}): measured {:>10.1} kWh, simulated {}",
                    b.start,
                    b.end,
                    b.days,
                    if b.estimated { ", estimated" } else { "" },
                    b.measured_kwh,
                    b.simulated_kwh.map_or(
                        "(the simulation lacks a day of it)".into(),
                        |s| format!(
                            "{s:>10.1} kWh ({:+.1} %)",
                            100.0 * (s - b.measured_kwh) / b.measured_kwh
                        )
                    )
                );
            }
        }
    }
}

/// Guideline 14 of every output both files have, hour by hour.
fn hourly(
    meas: &Table,
    sim: &Table,
    sim_times: &[chrono::NaiveDateTime],
) -> anyhow::Result<Vec<Row>> {
    let (mt, st) = (meas.column("timestamp")?, sim.column("timestamp")?);
    let outputs: Vec<(usize, usize)> = meas
        .header
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != mt)
        .filter_map(|(i, h)| sim.header.iter().position(|s| s == h).map(|j| (i, j)))
        .filter(|&(_, j)| j != st)
        .collect();
    if outputs.is_empty() {
        bail!(
            "{} and {} have no output column in common",
            meas.path.display(),
            sim.path.display()
        );
    }
    // Rows are matched by time, not by text: `2021-01-01T00:00` (EnergyPlus validation CSVs)
    // and `2021-01-01T00:00:00` (`bemcal predict`) are the same hour.
    let sim_rows: HashMap<chrono::NaiveDateTime, usize> =
        sim_times.iter().enumerate().map(|(k, t)| (*t, k)).collect();
    // A measured hour written twice would be compared twice (counted twice in n, NMBE and
    // CV-RMSE), so it is refused like a simulated one.
    let meas_times = row_times(meas, mt)?;
    // Hours only one file has are left out of every figure: say how many, so that files of
    // different years (a calendar year against twelve months from April) are not compared
    // over a part of the year unnoticed.
    let unmatched: Vec<&chrono::NaiveDateTime> = meas_times
        .iter()
        .filter(|t| !sim_rows.contains_key(*t))
        .collect();
    if let (Some(first), Some(last)) = (unmatched.iter().min(), unmatched.iter().max()) {
        eprintln!(
            "note: {} of {} measured rows ({first} to {last}) have no simulated row at the same \
             time; the figures compare the other {}",
            unmatched.len(),
            meas_times.len(),
            meas_times.len() - unmatched.len()
        );
    }
    let mut results = Vec::new();
    for &(i, j) in &outputs {
        let (mut y, mut yhat) = (Vec::new(), Vec::new());
        for ((line, f), t) in meas.rows.iter().zip(&meas_times) {
            let Some(&k) = sim_rows.get(t) else {
                continue;
            };
            let (sline, sf) = &sim.rows[k];
            y.push(meas.number(*line, i, &f[i])?);
            yhat.push(sim.number(*sline, j, &sf[j])?);
        }
        let name = meas.header[i].clone();
        let m = bemcal_stats::metrics::g14(&y, &yhat).with_context(|| {
            format!(
                "output `{name}` of {} vs {}",
                meas.path.display(),
                sim.path.display()
            )
        })?;
        results.push(Row {
            output: name,
            resolution: "hourly",
            n: m.n,
            nmbe_percent: m.nmbe,
            cv_rmse_percent: m.cv_rmse,
            pass: m.pass,
            bills: vec![],
            demand: None,
        });
    }
    Ok(results)
}

/// Guideline 14 of one output's bills (`OUTPUT=FILE`) against the simulation's totals over
/// each bill's days.
fn on_bills(
    args: &Args,
    arg: &str,
    sim: &Table,
    sim_times: &[chrono::NaiveDateTime],
) -> anyhow::Result<Row> {
    use bemcal_precal::meters::{
        bill_peaks, bill_totals, read_bills, BillEnd, BillSpec, MeterRole,
    };
    let (output, file) = arg
        .split_once('=')
        .with_context(|| format!("--bills {}: expected OUTPUT=FILE", excerpt(arg)))?;
    let j = sim.column(output)?;
    let spec = BillSpec {
        file: file.into(),
        role: MeterRole::from(output.trim_end_matches("_kwh").to_string()),
        unit: args.bill_unit.clone(),
        calorific_value_kwh_per_m3: args.calorific_value,
        end: match args.bill_end_exclusive {
            true => BillEnd::Exclusive,
            false => BillEnd::Inclusive,
        },
        estimated: args.bill_estimated,
    };
    let table = read_bills(std::path::Path::new(file), &spec)?;
    for n in &table.notes {
        eprintln!("note: {file}: {n}");
    }
    // Each day's simulated total and peak hour, where the simulation has its 24 hours.
    let mut days: HashMap<chrono::NaiveDate, (f64, usize, f64)> = HashMap::new();
    for ((line, f), t) in sim.rows.iter().zip(sim_times) {
        let v = sim.number(*line, j, &f[j])?;
        if v.is_finite() {
            let d = days.entry(t.date()).or_insert((0.0, 0, f64::NEG_INFINITY));
            d.0 += v;
            d.1 += 1;
            d.2 = d.2.max(v);
        }
    }
    let whole = |d: chrono::NaiveDate| days.get(&d).filter(|(_, n, _)| *n == 24);
    let totals = bill_totals(&table.bills, |d| whole(d).map(|(s, _, _)| *s));
    let peaks = bill_peaks(&table.bills, |d| whole(d).map(|(_, _, p)| *p));
    let (billed, peak): (Vec<f64>, Vec<f64>) = (table.bills.iter().zip(&peaks))
        .filter_map(|(b, p)| Some((b.demand_kw?, (*p)?)))
        .unzip();
    let (y, yhat): (Vec<f64>, Vec<f64>) = table
        .bills
        .iter()
        .zip(&totals)
        .filter_map(|(b, s)| s.map(|s| (b.kwh, s)))
        .unzip();
    let m = bemcal_stats::metrics::g14_totals(&y, &yhat).with_context(|| {
        format!(
            "{output}: {} of {} bills in {file} lie inside {}'s days",
            y.len(),
            table.bills.len(),
            sim.path.display()
        )
    })?;
    Ok(Row {
        output: output.to_string(),
        resolution: "bills",
        n: m.n,
        nmbe_percent: m.nmbe,
        cv_rmse_percent: m.cv_rmse,
        pass: m.pass,
        bills: (table.bills.iter().zip(totals).zip(peaks))
            .map(|((b, s), p)| BillRow {
                start: b.start,
                end: b.end - chrono::Duration::days(1),
                days: b.days(),
                measured_kwh: b.kwh,
                simulated_kwh: s,
                estimated: b.estimated,
                demand_kw: b.demand_kw,
                simulated_peak_kw: p.filter(|_| b.demand_kw.is_some()),
            })
            .collect(),
        demand: bemcal_calibrate::metrics::DemandMetrics::of(&billed, &peak),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoted_headers_and_cells_are_read_as_csv() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.csv");
        std::fs::write(
            &p,
            "\u{feff}timestamp,\"heating, gas (kWh)\",cooling_kwh\n\n\"2021-01-01T00:00\", 1.5 ,\"2\"\n",
        )
        .unwrap();
        let t = Table::read(&p).unwrap();
        assert_eq!(t.header, ["timestamp", "heating, gas (kWh)", "cooling_kwh"]);
        assert_eq!(t.column("heating, gas (kWh)").unwrap(), 1);
        assert_eq!(
            t.rows,
            [(3, vec!["2021-01-01T00:00".into(), "1.5".into(), "2".into()])]
        );

        std::fs::write(&p, "timestamp,a\n2021-01-01T00:00,1,2\n").unwrap();
        let e = Table::read(&p).err().unwrap().to_string();
        assert!(e.starts_with(&format!("{}:2: ", p.display())), "{e}");
    }

    /// `run` on measured and simulated CSV text; the error with the folder written as `DIR`.
    fn metrics(measured: &str, simulated: &str) -> Result<(), String> {
        let dir = tempfile::tempdir().unwrap();
        let (m, s) = (dir.path().join("m.csv"), dir.path().join("s.csv"));
        std::fs::write(&m, measured).unwrap();
        std::fs::write(&s, simulated).unwrap();
        run(Args {
            measured: Some(m),
            simulated: s,
            bills: vec![],
            bill_unit: None,
            calorific_value: None,
            bill_end_exclusive: false,
            bill_estimated: Default::default(),
            json: true,
        })
        .map_err(|e| {
            e.to_string()
                .replace(&dir.path().display().to_string(), "DIR")
        })
    }

    #[test]
    fn a_duplicated_measured_hour_is_refused_naming_both_lines() {
        let mut sim = String::from("timestamp,heating_kwh\n");
        let mut meas = sim.clone();
        for h in 0..24 {
            sim.push_str(&format!("2021-01-01T{h:02}:00:00,{}\n", 10 + h % 5));
            meas.push_str(&format!("2021-01-01T{h:02}:00,{}\n", 11 + h % 4));
        }
        metrics(&meas, &sim).unwrap();
        // Line 8 (hour 6) repeated as line 9, written differently: the same hour.
        let mut lines: Vec<&str> = meas.lines().collect();
        lines.insert(8, "2021-01-01 06:00:00,99");
        let dup = lines.join("\n") + "\n";
        assert_eq!(
            metrics(&dup, &sim).unwrap_err(),
            "DIR/m.csv:9: duplicate timestamp `2021-01-01 06:00:00`: line 8 has the same time"
        );
        // Simulated duplicates name both lines too.
        let mut lines: Vec<&str> = sim.lines().collect();
        lines.insert(3, lines[2]);
        let dup = lines.join("\n") + "\n";
        assert_eq!(
            metrics(&meas, &dup).unwrap_err(),
            "DIR/s.csv:4: duplicate timestamp `2021-01-01T01:00:00`: line 3 has the same time"
        );
        // An infinite reading is refused like a non-number.
        let bad = meas.replacen("2021-01-01T03:00,14\n", "2021-01-01T03:00,inf\n", 1);
        assert_eq!(
            metrics(&bad, &sim).unwrap_err(),
            "DIR/m.csv:5: column `heating_kwh`: `inf` is not a finite number"
        );
    }
}
