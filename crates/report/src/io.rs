//! Everything the report reads from disk: the calibration folder written by
//! `bemcal calibrate --out DIR` and the optional pre-calibration folder written by
//! `bemcal precalibrate --out PDIR`. The rest of the crate is pure (data in, text out).
//!
//! `summary.json` is read through the types that write it, [`bemcal_calibrate::Summary`] and
//! what it holds: a field the writer requires is required here too, and its absence is an
//! error naming it; a field the writer marks optional (absent from older summaries) takes the
//! writer's default. The folder's files the report cannot do without are required and their
//! absence is an error naming the file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use bemcal_calibrate::Summary;

use crate::error::ReportError;

/// The prefix of the noise scales' columns in `draws.csv` (`sigma_delta_<output>`).
const NOISE_PREFIX: &str = "sigma_delta_";

/// `draws.csv`: `chain,draw,<columns>...`, grouped by chain, each chain in draw order.
///
/// The columns after `chain,draw` are, as `bemcal calibrate` writes them, the calibrated
/// parameters, then the noise (`sigma_delta_*`), the log posterior and the sampler's statistics
/// per draw (named as CmdStan names them, ending in `__`).
#[derive(Debug, Clone)]
pub struct Draws {
    /// Column names after `chain,draw`.
    pub columns: Vec<String>,
    /// `chains[c][k]` = the draws of column `k` in chain `c`, in draw order.
    pub chains: Vec<Vec<Vec<f64>>>,
    /// `numbers[c][i]` = the `draw` number of chain `c`'s `i`-th draw (increasing).
    pub numbers: Vec<Vec<u64>>,
    /// How the file numbered its chains (`chains[0]` is always the first).
    pub numbering: ChainNumbering,
}

/// How a draws file numbers its chains: bemcal and ArviZ from 0, CmdStan and R's posterior
/// package from 1. A file whose chains start at 1 (no chain 0, chains 1..=m present) is read
/// as chains 0..m and said so ([`ChainNumbering::note`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ChainNumbering {
    /// Chains 0, 1, ... (bemcal, ArviZ).
    #[default]
    FromZero,
    /// Chains 1, 2, ... (CmdStan, R's posterior package), read as 0, 1, ...
    FromOne,
}

impl ChainNumbering {
    /// The file's number of its first chain (0 or 1).
    pub fn first(self) -> usize {
        match self {
            ChainNumbering::FromZero => 0,
            ChainNumbering::FromOne => 1,
        }
    }

    /// What a reader should be told, where the file's numbering is not bemcal's.
    pub fn note(self) -> Option<&'static str> {
        match self {
            ChainNumbering::FromZero => None,
            ChainNumbering::FromOne => Some(
                "chains are numbered from 1 (as CmdStan numbers them): chain 1 is read as the \
                 first chain",
            ),
        }
    }
}

impl Draws {
    /// The draws of a column per chain, or `None` if there is no such column.
    pub fn column(&self, name: &str) -> Option<Vec<&[f64]>> {
        let k = self.columns.iter().position(|c| c == name)?;
        Some(self.chains.iter().map(|c| c[k].as_slice()).collect())
    }

    /// The noise scales' columns (`sigma_delta_<output>`), where the calibration sampled them.
    pub fn noise(&self) -> impl Iterator<Item = &String> {
        self.columns.iter().filter(|c| c.starts_with(NOISE_PREFIX))
    }

    /// Whether a column is one of the sampler's statistics per draw (`accept_stat__`, ...).
    pub fn is_sampler_statistic(name: &str) -> bool {
        name.ends_with("__")
    }

    /// The calibrated parameters' columns: those before the noise, the log posterior and the
    /// sampler's statistics.
    pub fn parameters(&self) -> &[String] {
        let n = self
            .columns
            .iter()
            .position(|c| {
                c.starts_with(NOISE_PREFIX) || c == "log_posterior" || Self::is_sampler_statistic(c)
            })
            .unwrap_or(self.columns.len());
        &self.columns[..n]
    }

    /// Draws per chain (every chain has as many).
    pub fn len(&self) -> usize {
        self.numbers.first().map_or(0, Vec::len)
    }

    /// Whether there are no draws (never, for a file [`read_draws`] accepted).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The calibrated parameters' values (name, value) of draw number `draw` of chain `chain`,
    /// as the file numbers them; `None` if the file has no such draw.
    pub fn parameters_at(&self, chain: usize, draw: u64) -> Option<Vec<(String, f64)>> {
        let i = self.numbers.get(chain)?.binary_search(&draw).ok()?;
        Some(
            self.parameters()
                .iter()
                .enumerate()
                .map(|(k, name)| (name.clone(), self.chains[chain][k][i]))
                .collect(),
        )
    }
}

/// An hourly table `timestamp,<column>...`; empty cells are NaN.
#[derive(Debug, Clone)]
pub struct Hourly {
    /// Timestamps as written (`YYYY-MM-DDTHH:MM`).
    pub timestamps: Vec<String>,
    /// Column names after `timestamp`.
    pub columns: Vec<String>,
    /// `values[k]` = the series of column `k`.
    pub values: Vec<Vec<f64>>,
}

impl Hourly {
    /// A column's series, if present.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        let k = self.columns.iter().position(|c| c == name)?;
        Some(&self.values[k])
    }
}

/// Everything read from a calibration folder.
#[derive(Debug, Clone)]
pub struct CalibrationData {
    /// The folder.
    pub dir: PathBuf,
    /// `summary.json`.
    pub summary: Summary,
    /// `draws.csv`.
    pub draws: Draws,
    /// `posterior_predictive.csv`.
    pub predictive: Hourly,
    /// `validation/calibrated.csv`, if the validation ran.
    pub calibrated: Option<Hourly>,
    /// `validation/initial.csv`, if the initial model was simulated.
    pub initial: Option<Hourly>,
    /// `validation/predictive_intervals.csv` (EnergyPlus at posterior draws plus noise), if
    /// written.
    pub intervals: Option<Hourly>,
    /// A synthetic run's hidden truth against the posterior ([`read_truth`],
    /// `truth::recovery`), if given.
    pub truth: Option<crate::recovery::Recovery>,
}

/// One row of `calendar.csv`.
#[derive(Debug, Clone)]
pub struct CalendarDay {
    /// `YYYY-MM-DD`.
    pub date: String,
    /// Calendar day type (weekday, weekend, holiday).
    pub calendar: String,
    /// Cluster index (None when the day was skipped).
    pub cluster: Option<usize>,
    /// Day-type label of the cluster (`skipped` when not clustered).
    pub label: String,
    /// Flagged as an outlier.
    pub outlier: bool,
    /// DTW distance to the cluster medoid.
    pub medoid_distance: f64,
}

/// One row of `schedule_priors.csv`.
#[derive(Debug, Clone)]
pub struct ScheduleHour {
    /// Day type.
    pub day_type: String,
    /// Hour of day 0..23.
    pub hour: usize,
    /// Days used.
    pub n_days: usize,
    /// First quartile of the schedule fraction.
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
}

/// One row of `intervals.csv`.
#[derive(Debug, Clone)]
pub struct ScheduleInterval {
    /// Day type.
    pub day_type: String,
    /// First hour (inclusive).
    pub start_hour: usize,
    /// Last hour (exclusive).
    pub end_hour: usize,
    /// Triangular prior lower bound.
    pub min: f64,
    /// Mode.
    pub mode: f64,
    /// Upper bound.
    pub max: f64,
}

/// Everything read from a pre-calibration folder.
#[derive(Debug, Clone)]
pub struct PrecalData {
    /// The folder.
    pub dir: PathBuf,
    /// `calendar.csv`.
    pub calendar: Vec<CalendarDay>,
    /// `schedule_priors.csv`.
    pub schedule: Vec<ScheduleHour>,
    /// `intervals.csv`.
    pub intervals: Vec<ScheduleInterval>,
    /// The clustered series from `disaggregated.csv` (`schedule_series_kwh`), if present.
    pub schedule_series: Option<Vec<f64>>,
    /// `summary.txt`, if present.
    pub summary_text: Option<String>,
}

fn require(path: &Path, what: &str) -> Result<(), ReportError> {
    if path.is_file() {
        Ok(())
    } else {
        Err(ReportError::Missing {
            path: path.to_path_buf(),
            what: what.to_string(),
        })
    }
}

fn read_text(path: &Path) -> Result<String, ReportError> {
    std::fs::read_to_string(path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn parse_err(path: &Path, msg: impl Into<String>) -> ReportError {
    ReportError::Parse {
        path: path.to_path_buf(),
        msg: msg.into(),
    }
}

fn num(path: &Path, line: usize, col: &str, s: &str) -> Result<f64, ReportError> {
    let s = s.trim();
    if s.is_empty() || s.eq_ignore_ascii_case("nan") {
        return Ok(f64::NAN);
    }
    s.parse::<f64>().map_err(|_| {
        parse_err(
            path,
            format!(
                "line {line}, column '{col}': not a number: {:?}",
                bemcal_excerpt::excerpt(s, 40)
            ),
        )
    })
}

fn csv_reader(path: &Path) -> Result<csv::Reader<std::fs::File>, ReportError> {
    csv::ReaderBuilder::new()
        .flexible(false)
        .from_path(path)
        .map_err(|e| parse_err(path, e.to_string()))
}

fn headers(path: &Path, r: &mut csv::Reader<std::fs::File>) -> Result<Vec<String>, ReportError> {
    Ok(r.headers()
        .map_err(|e| parse_err(path, e.to_string()))?
        .iter()
        .map(|s| s.trim().to_string())
        .collect())
}

fn col_index(path: &Path, h: &[String], name: &str) -> Result<usize, ReportError> {
    h.iter().position(|c| c == name).ok_or_else(|| {
        parse_err(
            path,
            format!("missing column '{name}' (header: {})", h.join(",")),
        )
    })
}

/// Reads `summary.json`.
pub fn read_summary(path: &Path) -> Result<Summary, ReportError> {
    require(
        path,
        "the calibration summary written by `bemcal calibrate`",
    )?;
    let text = read_text(path)?;
    serde_json::from_str(&text).map_err(|e| {
        parse_err(
            path,
            format!("{e} (not a summary.json as this bemcal's `bemcal calibrate` writes it)"),
        )
    })
}

/// Reads a synthetic run's hidden true values, as `bemcal synthesize --truth FILE` writes them:
/// a JSON object of parameter name to true value.
pub fn read_truth(path: &Path) -> Result<BTreeMap<String, f64>, ReportError> {
    require(
        path,
        "the hidden true values written by `bemcal synthesize --truth`",
    )?;
    let text = read_text(path)?;
    serde_json::from_str(&text).map_err(|e| {
        parse_err(
            path,
            format!("{e}; the file should be a JSON object of parameter name to number"),
        )
    })
}

/// Reads `draws.csv` (or any draws file with `chain,draw,<column>...`), strictly: chains are
/// numbered 0, 1, ... (or 1, 2, ... as CmdStan numbers them: [`ChainNumbering`]) and equally long, each chain's draw numbers appear once, and every value is
/// a finite number (a missing or infinite draw would print as a mean beside an R-hat computed from
/// ranks as if nothing were wrong). Errors name the line and column and quote an excerpt.
pub fn read_draws(path: &Path) -> Result<Draws, ReportError> {
    require(path, "the MCMC draws written by `bemcal calibrate`")?;
    let mut r = csv_reader(path)?;
    let h = headers(path, &mut r)?;
    let ci = col_index(path, &h, "chain")?;
    let di = col_index(path, &h, "draw")?;
    let cols: Vec<usize> = (0..h.len()).filter(|&k| k != ci && k != di).collect();
    if cols.is_empty() {
        return Err(parse_err(path, "no columns besides chain and draw"));
    }
    // chain -> (draw number, values by column)
    let mut rows: Vec<Vec<(u64, Vec<f64>)>> = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let line = i + 2;
        let rec = rec.map_err(|e| parse_err(path, e.to_string()))?;
        let index = |k: usize| {
            rec[k].trim().parse::<u64>().map_err(|_| {
                parse_err(
                    path,
                    format!(
                        "line {line}, column '{}': expected a whole number, found {:?}",
                        h[k],
                        bemcal_excerpt::excerpt(rec[k].trim(), 40)
                    ),
                )
            })
        };
        let (c, d) = (index(ci)?, index(di)?);
        let c = usize::try_from(c)
            .ok()
            .filter(|&c| c < 1 << 16)
            .ok_or_else(|| {
                parse_err(
                    path,
                    format!("line {line}: chain {c} is not a chain number"),
                )
            })?;
        let mut values = Vec::with_capacity(cols.len());
        for &k in &cols {
            let v = num(path, line, &h[k], &rec[k])?;
            if !v.is_finite() {
                let cell = rec[k].trim();
                let what = if v.is_nan() {
                    "a missing value"
                } else {
                    "an infinite value"
                };
                return Err(parse_err(
                    path,
                    format!(
                        "line {line}, column '{}': {what} ({:?}); every draw must be a finite number",
                        h[k],
                        bemcal_excerpt::excerpt(cell, 40)
                    ),
                ));
            }
            values.push(v);
        }
        if rows.len() <= c {
            rows.resize_with(c + 1, Vec::new);
        }
        rows[c].push((d, values));
    }
    in_draw_order(path, rows, cols.iter().map(|&k| h[k].clone()).collect())
}

/// The rows of `draws.csv` by chain (`rows[c]` = (draw number, values by column)) as
/// [`Draws`] of `columns`: chains numbered from 0, equally long, each draw number once, in
/// draw order.
fn in_draw_order(
    path: &Path,
    mut rows: Vec<Vec<(u64, Vec<f64>)>>,
    columns: Vec<String>,
) -> Result<Draws, ReportError> {
    if rows.is_empty() {
        return Err(parse_err(path, "no draws: the file has a header only"));
    }
    let numbering = if rows.len() > 1 && rows[0].is_empty() && !rows[1].is_empty() {
        rows.remove(0);
        ChainNumbering::FromOne
    } else {
        ChainNumbering::FromZero
    };
    let first = numbering.first();
    if rows[0].is_empty() {
        return Err(parse_err(
            path,
            "chain 0 has no draws: chains are numbered from 0 (as bemcal and ArviZ number them) \
             or from 1 (as CmdStan does)",
        ));
    }
    let len = rows.iter().map(Vec::len).max().unwrap_or(0);
    let mut chains = Vec::with_capacity(rows.len());
    let mut numbers = Vec::with_capacity(rows.len());
    for (c, mut chain) in rows.into_iter().enumerate() {
        if chain.len() != len {
            return Err(parse_err(
                path,
                format!(
                    "chain {} has {} draws, another {len}; chains must be numbered {first}, \
                     {}, ... and equally long",
                    c + first,
                    chain.len(),
                    first + 1
                ),
            ));
        }
        chain.sort_by_key(|(d, _)| *d);
        if let Some(w) = chain.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(parse_err(
                path,
                format!("chain {} has draw {} twice", c + first, w[0].0),
            ));
        }
        numbers.push(chain.iter().map(|(d, _)| *d).collect());
        chains.push(
            (0..columns.len())
                .map(|k| chain.iter().map(|(_, v)| v[k]).collect())
                .collect(),
        );
    }
    Ok(Draws {
        columns,
        chains,
        numbers,
        numbering,
    })
}

/// Reads an hourly table `timestamp,<column>...`.
pub fn read_hourly(path: &Path, what: &str) -> Result<Hourly, ReportError> {
    require(path, what)?;
    let mut r = csv_reader(path)?;
    let h = headers(path, &mut r)?;
    let ti = col_index(path, &h, "timestamp")?;
    let cols: Vec<usize> = (0..h.len()).filter(|&k| k != ti).collect();
    let mut timestamps = Vec::new();
    let mut values = vec![Vec::new(); cols.len()];
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| parse_err(path, e.to_string()))?;
        timestamps.push(rec[ti].trim().to_string());
        for (j, &k) in cols.iter().enumerate() {
            values[j].push(num(path, i + 2, &h[k], &rec[k])?);
        }
    }
    if timestamps.is_empty() {
        return Err(parse_err(path, "no rows"));
    }
    Ok(Hourly {
        timestamps,
        columns: cols.iter().map(|&k| h[k].clone()).collect(),
        values,
    })
}

/// Adds `validation/bases.csv` (the hourly loads in the meters that the model does not have,
/// one column per output) to the same columns of an EnergyPlus run's outputs.
fn add_bases(h: &mut Hourly, bases: &Hourly) {
    for (name, base) in bases.columns.iter().zip(&bases.values) {
        if let Some(k) = h.columns.iter().position(|c| c == name) {
            for (v, b) in h.values[k].iter_mut().zip(base) {
                *v += b;
            }
        }
    }
}

/// Reads a calibration folder: `summary.json`, `draws.csv` and `posterior_predictive.csv` are
/// required; `validation/calibrated.csv` and `validation/initial.csv` are optional, and
/// `validation/bases.csv`, when present, is added to both.
pub fn read_calibration(dir: &Path) -> Result<CalibrationData, ReportError> {
    if !dir.is_dir() {
        return Err(ReportError::Missing {
            path: dir.to_path_buf(),
            what: "the calibration output folder (`bemcal calibrate PROJECT --out DIR`)".into(),
        });
    }
    let summary = read_summary(&dir.join("summary.json"))?;
    let draws = read_draws(&dir.join("draws.csv"))?;
    let pp = dir.join("posterior_predictive.csv");
    let predictive = read_hourly(
        &pp,
        "the posterior predictive bands written by `bemcal calibrate`",
    )?;
    for o in &summary.outputs {
        for suffix in ["measured", "q5", "q50", "q95"] {
            let c = format!("{o}_{suffix}");
            if predictive.get(&c).is_none() {
                return Err(parse_err(
                    &pp,
                    format!("missing column '{c}' for output '{o}' named in summary.json"),
                ));
            }
        }
    }
    let opt = |name: &str| -> Result<Option<Hourly>, ReportError> {
        let p = dir.join("validation").join(name);
        if p.is_file() {
            read_hourly(&p, "validation outputs").map(Some)
        } else {
            Ok(None)
        }
    };
    // EnergyPlus runs hold the model alone; the meters are compared with model + bases.
    let bases = opt("bases.csv")?;
    let with_bases = |h: Option<Hourly>| {
        h.map(|mut h| {
            if let Some(b) = &bases {
                add_bases(&mut h, b);
            }
            h
        })
    };
    Ok(CalibrationData {
        dir: dir.to_path_buf(),
        calibrated: with_bases(opt("calibrated.csv")?),
        initial: with_bases(opt("initial.csv")?),
        intervals: opt("predictive_intervals.csv")?,
        truth: None,
        summary,
        draws,
        predictive,
    })
}

/// Reads a pre-calibration folder: `calendar.csv`, `schedule_priors.csv` and `intervals.csv`
/// are required; `disaggregated.csv` (for the daily profiles) and `summary.txt` are optional.
pub fn read_precal(dir: &Path) -> Result<PrecalData, ReportError> {
    if !dir.is_dir() {
        return Err(ReportError::Missing {
            path: dir.to_path_buf(),
            what: "the pre-calibration folder (`bemcal precalibrate --out PDIR`)".into(),
        });
    }
    let calendar = read_day_types(&dir.join("calendar.csv"))?;
    let schedule = read_schedule_quartiles(&dir.join("schedule_priors.csv"))?;
    let intervals = read_schedule_intervals(&dir.join("intervals.csv"))?;
    let p = dir.join("disaggregated.csv");
    let schedule_series = if p.is_file() {
        let t = read_hourly(&p, "the disaggregated meters")?;
        t.get("schedule_series_kwh").map(<[f64]>::to_vec)
    } else {
        None
    };
    let p = dir.join("summary.txt");
    let summary_text = if p.is_file() {
        Some(read_text(&p)?)
    } else {
        None
    };
    Ok(PrecalData {
        dir: dir.to_path_buf(),
        calendar,
        schedule,
        intervals,
        schedule_series,
        summary_text,
    })
}

/// What pre-calibration's files are, for messages.
const PRECAL_WRITTEN: &str = "written by `bemcal precalibrate`";

/// Pre-calibration's `calendar.csv`: each day's calendar day type, cluster, label and outlier.
fn read_day_types(p: &Path) -> Result<Vec<CalendarDay>, ReportError> {
    require(p, &format!("the day-type calendar {PRECAL_WRITTEN}"))?;
    let mut r = csv_reader(p)?;
    let h = headers(p, &mut r)?;
    let [d, c, cl, l, o, m] = [
        "date",
        "calendar_day_type",
        "cluster",
        "label",
        "outlier",
        "medoid_distance",
    ]
    .map(|n| col_index(p, &h, n));
    let (d, c, cl, l, o, m) = (d?, c?, cl?, l?, o?, m?);
    let mut calendar = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| parse_err(p, e.to_string()))?;
        calendar.push(CalendarDay {
            date: rec[d].to_string(),
            calendar: rec[c].to_string(),
            cluster: rec[cl].trim().parse().ok(),
            label: rec[l].to_string(),
            outlier: rec[o].trim() == "true",
            medoid_distance: num(p, i + 2, "medoid_distance", &rec[m])?,
        });
    }
    Ok(calendar)
}

/// Pre-calibration's `schedule_priors.csv`: per day type and hour, the box-plot quartiles.
fn read_schedule_quartiles(p: &Path) -> Result<Vec<ScheduleHour>, ReportError> {
    require(
        p,
        &format!("the per-hour schedule quartiles {PRECAL_WRITTEN}"),
    )?;
    let mut r = csv_reader(p)?;
    let h = headers(p, &mut r)?;
    let idx: Vec<usize> = ["day_type", "hour", "n_days", "q1", "median", "q3"]
        .iter()
        .map(|n| col_index(p, &h, n))
        .collect::<Result<_, _>>()?;
    let mut schedule = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| parse_err(p, e.to_string()))?;
        let line = i + 2;
        schedule.push(ScheduleHour {
            day_type: rec[idx[0]].to_string(),
            hour: num(p, line, "hour", &rec[idx[1]])? as usize,
            n_days: num(p, line, "n_days", &rec[idx[2]])? as usize,
            q1: num(p, line, "q1", &rec[idx[3]])?,
            median: num(p, line, "median", &rec[idx[4]])?,
            q3: num(p, line, "q3", &rec[idx[5]])?,
        });
    }
    Ok(schedule)
}

/// Pre-calibration's `intervals.csv`: the merged schedule intervals and their triangular priors.
fn read_schedule_intervals(p: &Path) -> Result<Vec<ScheduleInterval>, ReportError> {
    require(
        p,
        &format!("the merged schedule intervals {PRECAL_WRITTEN}"),
    )?;
    let mut r = csv_reader(p)?;
    let h = headers(p, &mut r)?;
    let idx: Vec<usize> = ["day_type", "start_hour", "end_hour", "min", "mode", "max"]
        .iter()
        .map(|n| col_index(p, &h, n))
        .collect::<Result<_, _>>()?;
    let mut intervals = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| parse_err(p, e.to_string()))?;
        let line = i + 2;
        intervals.push(ScheduleInterval {
            day_type: rec[idx[0]].to_string(),
            start_hour: num(p, line, "start_hour", &rec[idx[1]])? as usize,
            end_hour: num(p, line, "end_hour", &rec[idx[2]])? as usize,
            min: num(p, line, "min", &rec[idx[3]])?,
            mode: num(p, line, "mode", &rec[idx[4]])?,
            max: num(p, line, "max", &rec[idx[5]])?,
        });
    }
    Ok(intervals)
}

/// Writes the report atomically (temporary file + rename).
pub fn write_html(path: &Path, html: &str) -> Result<(), ReportError> {
    write_atomic(path, html.as_bytes())
}

/// Writes a file atomically and durably ([`bemcal_durable`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    bemcal_durable::write_atomic(path, bytes).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The crate's fixture `summary.json` (`tests/fixtures/summary.json`): every section filled,
/// as `bemcal calibrate` writes it.
#[cfg(test)]
pub(crate) mod fixture {
    /// Its text.
    pub const SUMMARY: &str = include_str!("../tests/fixtures/summary.json");

    /// Read through the writer's types.
    pub fn summary() -> bemcal_calibrate::Summary {
        serde_json::from_str(SUMMARY).unwrap_or_else(|e| panic!("the fixture summary: {e}"))
    }
}

#[cfg(test)]
mod summary_tests {
    use super::*;

    /// [`read_summary`] of `value` written as a file; an error with the folder written as `DIR`.
    fn read(value: &serde_json::Value) -> Result<Summary, String> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("summary.json");
        std::fs::write(&p, serde_json::to_string_pretty(value).unwrap()).unwrap();
        read_summary(&p).map_err(|e| {
            e.to_string()
                .replace(&dir.path().display().to_string(), "DIR")
        })
    }

    fn fixture_value() -> serde_json::Value {
        serde_json::from_str(fixture::SUMMARY).unwrap()
    }

    /// The fixture without the field at `path` (object keys and array indices).
    fn without(path: &[&str]) -> serde_json::Value {
        let mut v = fixture_value();
        let (last, parents) = path.split_last().unwrap();
        let mut at = &mut v;
        for k in parents {
            at = match k.parse::<usize>() {
                Ok(i) => &mut at[i],
                Err(_) => &mut at[*k],
            };
        }
        let removed = at.as_object_mut().unwrap().remove(*last);
        assert!(removed.is_some(), "the fixture has no {path:?}");
        v
    }

    #[test]
    fn the_fixture_round_trips_through_the_writers_types() {
        let v = fixture_value();
        let s = read(&v).unwrap();
        assert_eq!(serde_json::to_value(&s).unwrap(), v);
    }

    #[test]
    fn a_required_field_missing_is_refused_with_its_name() {
        for path in [
            &["outputs"][..],
            &["posterior", "parameters", "1", "rhat"],
            &["validation", "0", "cv_rmse"],
            &["predictive", "outputs", "0", "noise_kwh"],
            &["model_form", "meters", "0", "reach", "verdict"],
            &["design_repair", "swaps"],
            &["timings", "total_s"],
        ] {
            let e = read(&without(path)).unwrap_err();
            let field = path.last().unwrap();
            assert!(
                e.starts_with("DIR/summary.json: ")
                    && e.contains(&format!("missing field `{field}`")),
                "{path:?}: {e}"
            );
        }
    }

    #[test]
    fn a_field_the_writer_marks_optional_may_be_missing() {
        for path in [
            &["holdout"][..],
            &["predictive"],
            &["convergence"],
            &["timings", "refinement_s"],
            &["predictive", "outputs", "0", "running"],
            &["estimate_choice", "candidates", "0", "monthly_limit_ratio"],
        ] {
            let s = read(&without(path)).unwrap_or_else(|e| panic!("{path:?}: {e}"));
            assert_eq!(s.outputs, ["heating_kwh", "electricity_kwh"]);
        }
        let s = read(&without(&["temperature"])).unwrap();
        assert_eq!(s.temperature.value, 1.0, "the writer's default");
    }

    #[test]
    fn a_statistic_that_could_not_be_computed_reads_back_as_nan() {
        let mut v = fixture_value();
        v["posterior"]["parameters"][0]["rhat"] = serde_json::Value::Null;
        v["validation"][1]["nmbe"] = serde_json::Value::Null;
        let s = read(&v).unwrap();
        assert!(s.posterior.parameters[0].rhat.is_nan());
        assert!(s.validation[1].metrics.nmbe.is_nan());
        assert_eq!(serde_json::to_value(&s).unwrap(), v);
    }
}

#[cfg(test)]
mod bases_tests {
    use super::*;

    #[test]
    fn bases_are_added_to_the_runs_outputs_by_column() {
        let hourly = |columns: &[&str], values: Vec<Vec<f64>>| Hourly {
            timestamps: vec!["2021-01-01T00:00".into(), "2021-01-01T01:00".into()],
            columns: columns.iter().map(|c| c.to_string()).collect(),
            values,
        };
        let mut run = hourly(
            &["heating_kwh", "electricity_kwh"],
            vec![vec![1.0, 2.0], vec![3.0, 4.0]],
        );
        let bases = hourly(&["electricity_kwh"], vec![vec![10.0, f64::NAN]]);
        add_bases(&mut run, &bases);
        assert_eq!(run.values[0], vec![1.0, 2.0]);
        assert_eq!(run.values[1][0], 13.0);
        assert!(run.values[1][1].is_nan(), "a missing base hour is missing");
    }
}

#[cfg(test)]
mod draws_tests {
    use super::*;

    /// `read_draws` of a file's text; an error with the folder written as `DIR`.
    fn read(text: &str) -> Result<Draws, String> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("draws.csv");
        std::fs::write(&p, text).unwrap();
        read_draws(&p).map_err(|e| {
            e.to_string()
                .replace(&dir.path().display().to_string(), "DIR")
        })
    }

    #[test]
    fn draws_are_grouped_by_chain_in_draw_order_and_columns_classified() {
        let d = read(
            "chain,draw,shgc,sigma_delta_heating_kwh,log_posterior,accept_stat__\n\
             1,1,0.4,2.0,-10.0,0.9\n0,1,0.2,2.0,-10.0,0.9\n0,0,0.1,2.0,-10.0,0.9\n\
             1,0,0.3,2.0,-10.0,0.9\n",
        )
        .unwrap();
        assert_eq!(d.chains[0][0], vec![0.1, 0.2]);
        assert_eq!(d.chains[1][0], vec![0.3, 0.4]);
        assert_eq!(d.numbers, vec![vec![0, 1], vec![0, 1]]);
        assert_eq!(d.len(), 2);
        assert_eq!(d.parameters(), ["shgc"]);
        assert_eq!(d.parameters_at(1, 1), Some(vec![("shgc".to_string(), 0.4)]));
        assert_eq!(d.parameters_at(2, 0), None);
        assert!(Draws::is_sampler_statistic("accept_stat__"));
    }

    /// CmdStan and R's posterior package number chains from 1: read as the same chains, said.
    #[test]
    fn chains_numbered_from_one_are_read_as_the_same_chains() {
        let from_one = read("chain,draw,a\n1,1,0.1\n1,2,0.2\n2,1,0.3\n2,2,0.4\n").unwrap();
        let from_zero = read("chain,draw,a\n0,1,0.1\n0,2,0.2\n1,1,0.3\n1,2,0.4\n").unwrap();
        assert_eq!(from_one.chains, from_zero.chains);
        assert_eq!(from_one.numbers, from_zero.numbers);
        assert_eq!(from_one.numbering, ChainNumbering::FromOne);
        assert_eq!(from_zero.numbering, ChainNumbering::FromZero);
        assert!(from_one.numbering.note().unwrap().contains("CmdStan"));
        assert_eq!(from_zero.numbering.note(), None);
    }

    #[test]
    fn draws_files_that_would_mislead_a_diagnosis_are_refused() {
        let refused = |text: &str, want: &str| {
            let e = read(text).unwrap_err();
            assert!(e.contains(want), "{text:?}: {e}");
            assert!(e.len() < 300, "{e}");
        };
        refused(
            "chain,draw,a\n0,0,1\n0,1,2\n2,0,3\n2,1,4\n",
            "chain 1 has 0 draws, another 2",
        );
        refused("chain,draw,a\n0,0,1\n0,1,2\n1,0,3\n", "chain 1 has 1 draws");
        refused("chain,draw,a\n0,0,1\n0,0,2\n", "chain 0 has draw 0 twice");
        refused(
            "chain,draw,a\n0,0,1\n0,1,\n",
            "line 3, column 'a': a missing value",
        );
        refused(
            "chain,draw,a\n0,0,1\n0,1,1e999\n",
            "line 3, column 'a': an infinite value",
        );
        refused(
            &format!("chain,draw,a\n0,0,{}\n", "7".repeat(5000) + "x"),
            "line 2, column 'a': not a number",
        );
        refused(
            "chain,draw,a\n-1,0,1\n",
            "line 2, column 'chain': expected a whole number",
        );
        refused(
            "chain,draw,a\n2,0,1\n3,0,1\n",
            "chain 0 has no draws: chains are numbered from 0",
        );
        // Numbered from 1, one chain short: named as the file numbers it.
        refused(
            "chain,draw,a\n1,0,1\n1,1,2\n3,0,3\n3,1,4\n",
            "chain 2 has 0 draws, another 2; chains must be numbered 1, 2, ...",
        );
        refused("chain,draw,a\n", "no draws: the file has a header only");
        refused("chain,draw\n0,0\n", "no columns besides chain and draw");
    }
}
