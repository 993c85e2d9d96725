//! `bemcal metrics`: ASHRAE Guideline 14 NMBE and CV-RMSE of simulated against measured hourly
//! series (p = 1, hourly criteria |NMBE| <= 10 %, CV-RMSE <= 30 %).
//!
//! Both CSVs have a `timestamp` column and output columns such as `heating_kwh`; rows are
//! matched by timestamp, every output present in both files is compared, and an empty or
//! `NaN` cell is a missing hour.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};

/// Arguments of `bemcal metrics`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Measured hourly series (CSV with a `timestamp` column).
    #[arg(long)]
    pub measured: PathBuf,
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

/// Metrics of one output.
#[derive(Debug, serde::Serialize)]
struct Row {
    output: String,
    n: usize,
    nmbe_percent: f64,
    cv_rmse_percent: f64,
    pass: bool,
}

/// An ISO 8601 local timestamp, `YYYY-MM-DDTHH:MM[:SS]` (or with a space for `T`).
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
    let meas = Table::read(&args.measured)?;
    let sim = Table::read(&args.simulated)?;
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
    let sim_rows: HashMap<chrono::NaiveDateTime, usize> = row_times(&sim, st)?
        .into_iter()
        .enumerate()
        .map(|(k, t)| (t, k))
        .collect();
    // A measured hour written twice would be compared twice (counted twice in n, NMBE and
    // CV-RMSE), so it is refused like a simulated one.
    let meas_times = row_times(&meas, mt)?;
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
            n: m.n,
            nmbe_percent: m.nmbe,
            cv_rmse_percent: m.cv_rmse,
            pass: m.pass,
        });
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        println!(
            "{:<24} {:>7} {:>9} {:>11}  pass (|NMBE| <= 10 %, CV-RMSE <= 30 %)",
            "output", "n", "NMBE %", "CV-RMSE %"
        );
        for r in &results {
            println!(
                "{:<24} {:>7} {:>9.2} {:>11.2}  {}",
                r.output,
                r.n,
                r.nmbe_percent,
                r.cv_rmse_percent,
                if r.pass { "yes" } else { "no" }
            );
        }
    }
    Ok(())
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
            measured: m,
            simulated: s,
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
