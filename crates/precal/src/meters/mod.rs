//! Meter ingestion: a CSV of timestamped meter readings -> kWh per hour on the 8,760
//! hour-beginning slots of one year, in local standard time.
//!
//! # Rules (documented behaviour)
//!
//! * **Timestamps** are parsed with a chrono format string ([`MeterSpec::timestamp_format`],
//!   default `auto`: ISO 8601, else `%m/%d/%Y %H:%M`; single-digit months/days/hours such as `1/13/2011 0:00` parse
//!   too) or `iso8601` (`2011-01-13T05:00`, `2011-01-13 05:00:00`, or RFC 3339 with a UTC offset,
//!   which is converted to local standard time with the site's standard offset). A time of
//!   `24:00` means 00:00 of the next day.
//! * **Hour convention**: hour-ending stamps (`01:00` = the hour 00:00-01:00) are shifted back one
//!   hour. `auto` picks hour-ending when a `24:00` stamp occurs, or the earliest stamp of the file
//!   is 01:00 on the first of a month (January 1 for a calendar year), or the latest is 00:00 on
//!   the first of a month at least 360 days after the earliest; otherwise hour-beginning.
//! * **Year**: a calendar year, or twelve months from the first of another month
//!   ([`GridYear`], `2017-04`); given, or inferred from the stamps ([`infer_year`]).
//! * **Daylight saving**: `none` = the file is in local standard time all year. `us` = the clock
//!   follows US DST (second Sunday of March to first Sunday of November, since 2007): stamps
//!   inside DST are moved back one hour; in the autumn the first occurrence of the repeated
//!   01:00 hour is DST and the second standard time. `auto` (default) chooses `us` when the
//!   spring-forward hour (02:00 on the second Sunday of March) is absent while its neighbours are
//!   present, or the autumn 01:00 hour occurs twice; otherwise `none`.
//! * **Grid**: slot `t` is hour `t mod 24` of day `t / 24` counted from 1 January without 29
//!   February, so the grid lines up with a non-leap EPW file (a year from April has January to
//!   March of the next year in slots 0..2160). Rows on 29 February and rows outside the year are
//!   dropped and counted in [`MeterData::notes`]. A slot without a row is
//!   missing (NaN).
//! * **Duplicates** (two rows in one slot that are not a DST repeat): [`DuplicatePolicy`]
//!   (default: error naming both lines).
//! * **Values**: empty, `NA`, `N/A`, `NaN`, `null`, `-` and `--` are missing (NaN). Other text is
//!   an error naming the file, line and column. Negative values: [`NegativePolicy`] (default:
//!   error).
//! * **Units** ([`EnergyUnit`]): power units are hourly means (kW over an hour = kWh), energy
//!   units are converted to kWh.
//! * **Sub-hourly meters** (15-minute AMI, or any interval dividing the hour): the interval is the
//!   most common step between stamps. Hour-ending means interval-ending (a stamp is shifted back
//!   one interval, and `auto` recognises the first stamp at 00:15 on January 1); daylight saving
//!   is undone per stamp (the first occurrence of a stamp in the repeated hour is daylight
//!   time); the readings of an hour are summed for energy units and averaged for power units,
//!   and an hour with missing readings is the mean of those present scaled to the hour (counted
//!   in the notes). An exact repeat of a stamp is the duplicate: an error, or with any other
//!   policy the first reading is kept.
//!
//! This file reads the table and finds its columns ([`read_meters`], [`parse_meters`]);
//! `clock.rs` turns its stamps into standard-time hours (format, year, hour convention,
//! daylight saving); `grid.rs` puts the readings on the hour grid; `spec.rs` the settings,
//! `quality.rs` the checks of the result, [`bills`] the bill tables.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use chrono::{Duration, NaiveDateTime};
use serde::{Deserialize, Serialize};

use crate::PrecalError;

pub mod bills;
mod clock;
mod dialect;
mod grid;
mod quality;
mod spec;

pub use clock::infer_year;
use clock::{hour_convention, parse_timestamp, us_daylight_saving, zone_daylight_saving};
use dialect::{decimal_points, sniff_delimiter};
use grid::{dropped_notes, values_on_grid};

pub use bills::{
    bill_peaks, bill_totals, read_bills, Bill, BillEnd, BillSpec, BillTable, EstimatedReads,
};
pub use quality::{
    quality, run_hours, zero_run_in_off_season, FlatRun, Gap, MeterQuality, ZERO_RUN_MIN_HOURS,
};
pub use spec::{
    DstHandling, DuplicatePolicy, EnergyUnit, HourConvention, MeterColumn, MeterRole, MeterSpec,
    NegativePolicy,
};

/// Hours in the (non-leap) meter year.
pub const HOURS: usize = 8760;

pub use bemcal_weather::grid::{slot_month, GridYear, CUM_DAYS};

/// Default timestamp format: `auto` = ISO 8601, else US `%m/%d/%Y %H:%M` (`01/13/2011 05:00`).
pub const DEFAULT_TIMESTAMP_FORMAT: &str = "auto";

/// The US month/day/year form tried by `auto` after ISO 8601.
pub const US_TIMESTAMP_FORMAT: &str = "%m/%d/%Y %H:%M";
/// One meter on the hourly grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeterSeries {
    /// What it measures.
    pub role: MeterRole,
    /// The CSV column it came from.
    pub column: String,
    /// The unit the CSV used.
    pub unit: EnergyUnit,
    /// kWh per hour, 8,760 hour-beginning slots, NaN = missing.
    pub values: Vec<f64>,
}

/// Meters of one building-year on the hourly grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeterData {
    /// The grid's year: a calendar year, or twelve months from another month.
    pub year: GridYear,
    /// The source file.
    pub source: PathBuf,
    /// The meters, in spec order.
    pub series: Vec<MeterSeries>,
    /// What ingestion decided or dropped (convention, DST, rows outside the year, ...).
    pub notes: Vec<String>,
}

impl MeterData {
    /// The first meter with `role`.
    pub fn get(&self, role: &MeterRole) -> Option<&MeterSeries> {
        self.series.iter().find(|s| &s.role == role)
    }

    /// The hour slots of a held-out period (`[validation] holdout`) on this grid: an hour is
    /// measured when any series has a value there (every hour, without a series). Pre-calibration and the calibration both
    /// ask this, so that `last N months` names the same months for both.
    pub fn held_out_hours(
        &self,
        holdout: &bemcal_weather::period::Holdout,
    ) -> Result<Vec<bool>, String> {
        // Without a series (a project of bills alone) every hour of the year counts.
        let n = self.series.first().map_or(HOURS, |s| s.values.len());
        let present = |h: usize| {
            self.series.is_empty() || self.series.iter().any(|s| s.values[h].is_finite())
        };
        holdout.hours(self.year, n, &present)
    }

    /// Leaves the held-out period out: its hours become missing in every series, so that
    /// pre-calibration sees only the calibration period, and a note says so. Returns the hour
    /// slots held out.
    pub fn hold_out(&mut self, holdout: &bemcal_weather::period::Holdout) -> Result<usize, String> {
        let hours = self.held_out_hours(holdout)?;
        for s in &mut self.series {
            set_missing(&mut s.values, &hours);
        }
        let count = hours.iter().filter(|o| **o).count();
        self.notes.push(format!(
            "held out {holdout} ({count} hours): pre-calibration sees only the calibration period"
        ));
        Ok(count)
    }

    /// The sub-meter named `name`.
    pub fn submeter(&self, name: &str) -> Option<&MeterSeries> {
        self.get(&MeterRole::Submeter(name.to_string()))
    }
}

/// Detects meter columns from headers (case-insensitive): heating, cooling, electricity
/// (`electric`, `total building`, `whole building`, `building`, `main`), and the sub-meters
/// `lighting`, `plug_loads`, `data_center`, `mechanical`. Columns mentioning `net`, `pv`,
/// `solar` or `generation` are skipped. A unit in parentheses or brackets (`(kW)`, `[kWh]`) is
/// used, otherwise kW. The first column per role wins.
pub fn detect_columns(headers: &[&str], timestamp_column: Option<&str>) -> Vec<MeterColumn> {
    let mut out: Vec<MeterColumn> = Vec::new();
    for h in headers {
        let h = h.trim();
        if h.is_empty() || Some(h) == timestamp_column {
            continue;
        }
        let l = h.to_ascii_lowercase();
        let words: Vec<&str> = l
            .split(|c: char| !c.is_ascii_alphanumeric())
            .filter(|w| !w.is_empty())
            .collect();
        let has = |w: &str| words.contains(&w);
        if has("net") || has("pv") || has("solar") || has("generation") {
            continue;
        }
        let role = if l.contains("heating") || has("heat") {
            MeterRole::Heating
        } else if l.contains("cooling") || l.contains("chilled") {
            MeterRole::Cooling
        } else if l.contains("data center") || l.contains("datacenter") || l.contains("server") {
            MeterRole::Submeter("data_center".into())
        } else if l.contains("lighting") || has("lights") {
            MeterRole::Submeter("lighting".into())
        } else if l.contains("plug") {
            MeterRole::Submeter("plug_loads".into())
        } else if l.contains("mechanical") || has("hvac") {
            MeterRole::Submeter("mechanical".into())
        } else if l.contains("electric") || l.contains("building") || has("main") {
            MeterRole::Electricity
        } else {
            continue;
        };
        if out.iter().any(|c| c.role == role) {
            continue;
        }
        let unit = unit_in_header(h).unwrap_or_default();
        out.push(MeterColumn {
            column: h.to_string(),
            role,
            unit,
            exclude: None,
            fit: true,
        });
    }
    out
}

fn unit_in_header(h: &str) -> Option<EnergyUnit> {
    let open = h.rfind(['(', '['])?;
    let close = h[open..].find([')', ']'])? + open;
    h[open + 1..close].parse().ok()
}

/// At most 40 bytes of a cell, for messages (a cell can be megabytes long).
fn excerpt(s: &str) -> std::borrow::Cow<'_, str> {
    bemcal_excerpt::excerpt(s, 40)
}

fn is_missing_token(s: &str) -> bool {
    matches!(
        s.to_ascii_lowercase().as_str(),
        "" | "na" | "n/a" | "nan" | "null" | "none" | "-" | "--"
    )
}

/// Reads a meters CSV with `spec`. `year`: the grid year (default: inferred from the timestamps,
/// [`infer_year`]). `std_offset_h`: the site's standard UTC offset, used only for ISO
/// timestamps that carry an offset (e.g. from the EPW `LOCATION` time zone).
pub fn read_meters(
    path: &Path,
    spec: &MeterSpec,
    year: Option<GridYear>,
    std_offset_h: Option<f64>,
) -> Result<MeterData, PrecalError> {
    let text = std::fs::read_to_string(path).map_err(|source| PrecalError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_meters(&text, path, spec, year, std_offset_h)
}

/// The meter's reading interval in minutes: the most common step between consecutive distinct
/// stamps, when it divides the hour (5, 10, 15, 20, 30 min); 60 otherwise.
fn reading_interval_min(rows: &[Row]) -> u32 {
    let mut stamps: Vec<NaiveDateTime> =
        rows.iter().filter(|r| !r.offset).map(|r| r.clock).collect();
    stamps.sort();
    stamps.dedup();
    let mut counts: HashMap<i64, usize> = HashMap::new();
    for w in stamps.windows(2) {
        *counts.entry((w[1] - w[0]).num_minutes()).or_default() += 1;
    }
    let mode = counts
        .into_iter()
        .max_by_key(|&(m, n)| (n, -m))
        .map(|(m, _)| m)
        .unwrap_or(60);
    if (1..60).contains(&mode) && 60 % mode == 0 {
        mode as u32
    } else {
        60
    }
}

struct Row {
    line: u64,
    clock: NaiveDateTime,
    offset: bool,
    record: csv::StringRecord,
}

/// An error of the meters file as a whole.
fn file_err(path: &Path, message: String) -> PrecalError {
    PrecalError::MeterFile {
        path: path.to_path_buf(),
        message,
    }
}

/// An error at a line and column of the meters file.
fn row_err(path: &Path, line: u64, column: &str, message: String) -> PrecalError {
    PrecalError::Meter {
        path: path.to_path_buf(),
        line,
        column: column.to_string(),
        message,
    }
}

/// [`read_meters`] on text already in memory; `path` is used in messages. The stages, in the
/// order the rows go through them: the table (`read_table`), the reading interval, the hour
/// convention (`hour_convention`), the grid year, daylight saving (`zone_daylight_saving`
/// or `us_daylight_saving`), and the values on the grid (`values_on_grid`).
pub fn parse_meters(
    text: &str,
    path: &Path,
    spec: &MeterSpec,
    year: Option<GridYear>,
    std_offset_h: Option<f64>,
) -> Result<MeterData, PrecalError> {
    let mut notes = Vec::new();
    let mut table = read_table(text, path, spec, std_offset_h, &mut notes)?;
    let rows = &mut table.rows;

    // Reading interval: sub-hourly meters (15-minute AMI) are aggregated to hours.
    let interval_min = reading_interval_min(rows);
    let per_hour = 60 / interval_min;
    if per_hour > 1 {
        notes.push(aggregation_note(interval_min, per_hour));
    }

    let convention = hour_convention(
        spec.convention,
        rows,
        interval_min,
        table.saw_24,
        &mut notes,
    );
    if convention == HourConvention::HourEnding {
        // A stamp ends its interval: an hour for hourly meters, 15 minutes for 15-minute ones.
        for r in rows.iter_mut() {
            r.clock -= Duration::minutes(interval_min as i64);
        }
    }

    let year = match year {
        Some(y) => y,
        None => {
            let y = infer_year(rows.iter().filter(|r| !r.offset).map(|r| r.clock));
            notes.push(format!(
                "year inferred from the timestamps: {y} ({} to {})",
                y.first_date(),
                y.last_date()
            ));
            y
        }
    };

    // Daylight saving: the zone's rules, or US rules (detected or named), or none.
    if let Some(name) = &spec.time_zone {
        zone_daylight_saving(
            rows,
            name,
            spec.dst,
            year,
            std_offset_h,
            path,
            &table.ts_name,
            &mut notes,
        )?;
    } else {
        us_daylight_saving(rows, spec.dst, year, per_hour, &mut notes)
            .map_err(|m| file_err(path, m))?;
    }

    let grid = values_on_grid(&table, spec, year, per_hour, path, &mut notes)?;
    dropped_notes(&grid, &table.rows, year, spec.duplicates, &mut notes);
    if grid.slot_line.iter().all(|&l| l == 0) {
        return Err(no_rows_in_year(&table.rows, year, path));
    }
    let mut series = Vec::new();
    for ((c, _), mut values) in table.columns.into_iter().zip(grid.values) {
        if let Some(period) = &c.exclude {
            exclude_period(&mut values, period, year, &c.column, &mut notes)
                .map_err(|m| file_err(path, m))?;
        }
        series.push(MeterSeries {
            role: c.role,
            column: c.column,
            unit: c.unit,
            values,
        });
    }
    Ok(MeterData {
        year,
        source: path.to_path_buf(),
        series,
        notes,
    })
}

/// Marks a meter's excluded `period` missing (`[[meters.columns]] exclude`) and notes how many
/// readings that removed.
fn exclude_period(
    values: &mut [f64],
    period: &bemcal_weather::period::Holdout,
    year: GridYear,
    column: &str,
    notes: &mut Vec<String>,
) -> Result<(), String> {
    let present = |h: usize| values[h].is_finite();
    let hours = period.hours(year, values.len(), &present).map_err(|m| {
        let m = m.strip_prefix("holdout ").unwrap_or(&m);
        format!("column '{column}', exclude {m}")
    })?;
    let removed = set_missing(values, &hours);
    notes.push(format!(
        "column '{column}': {removed} readings in {period} excluded as the project says \
         (`exclude`): missing for this meter"
    ));
    Ok(())
}

/// Marks the hours flagged in `hours` missing; returns how many readings that removed.
fn set_missing(values: &mut [f64], hours: &[bool]) -> usize {
    let mut removed = 0;
    for (v, &out) in values.iter_mut().zip(hours) {
        if out {
            removed += usize::from(v.is_finite());
            *v = f64::NAN;
        }
    }
    removed
}

/// The note of sub-hourly readings aggregated to hours.
fn aggregation_note(interval_min: u32, per_hour: u32) -> String {
    format!(
        "readings every {interval_min} min: {per_hour} per hour aggregated to hourly kWh \
         (energy units summed, power units averaged; an hour with missing readings is the \
         mean of those present, scaled to the hour)"
    )
}

/// The error of meters none of whose rows falls in the grid `year`: the span the timestamps
/// run and the `year` that would hold them.
fn no_rows_in_year(rows: &[Row], year: GridYear, path: &Path) -> PrecalError {
    let clocks = rows.iter().filter(|r| !r.offset).map(|r| r.clock);
    let span = match (clocks.clone().min(), clocks.clone().max()) {
        (Some(a), Some(b)) => format!(
            "; the timestamps run {} to {}: set the model's `year` to the meters' year \
             (year = \"{}\")",
            a.date(),
            b.date(),
            infer_year(clocks)
        ),
        _ => String::new(),
    };
    file_err(
        path,
        format!(
            "no rows fall in {} to {} (the grid year {year}){span}",
            year.first_date(),
            year.last_date()
        ),
    )
}

/// A meters file read as rows: the timestamp column's name, the meter columns with their field
/// index, and every non-blank row with its stamp as written (clock time).
struct Table {
    ts_name: String,
    columns: Vec<(MeterColumn, usize)>,
    rows: Vec<Row>,
    /// A `24:00` stamp occurred (an hour-ending file).
    saw_24: bool,
}

/// The header (the timestamp column, the meter columns: listed in `spec` or detected from the
/// names) and the rows with their parsed stamps.
fn read_table(
    text: &str,
    path: &Path,
    spec: &MeterSpec,
    std_offset_h: Option<f64>,
    notes: &mut Vec<String>,
) -> Result<Table, PrecalError> {
    let delimiter = sniff_delimiter(text);
    if delimiter != b',' {
        notes.push(format!(
            "fields separated by '{}' (no comma in the header line), decimal commas read as points",
            if delimiter == b'\t' { "\\t" } else { ";" }
        ));
    }
    let mut rdr = csv::ReaderBuilder::new()
        .flexible(true)
        .trim(csv::Trim::All)
        .delimiter(delimiter)
        .from_reader(text.as_bytes());
    let headers: Vec<String> = rdr
        .headers()
        .map_err(|e| file_err(path, format!("cannot read the header line: {e}")))?
        .iter()
        .map(str::to_string)
        .collect();
    let (ts_idx, columns) = locate_columns(&headers, spec, path, notes)?;
    let ts_name = headers[ts_idx].clone();
    let mut rows: Vec<Row> = Vec::new();
    let mut saw_24 = false;
    for rec in rdr.records() {
        let record = rec.map_err(|e| {
            let line = e.position().map(|p| p.line()).unwrap_or(0);
            row_err(path, line, "", format!("malformed CSV: {e}"))
        })?;
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        if record.iter().all(str::is_empty) {
            continue;
        }
        let record = match delimiter {
            b',' => record,
            _ => decimal_points(&record, ts_idx),
        };
        let raw = record.get(ts_idx).unwrap_or("");
        if raw.is_empty() {
            return Err(row_err(path, line, &ts_name, "empty timestamp".into()));
        }
        saw_24 |= raw.contains("24:00");
        let (clock, offset) = parse_timestamp(raw, &spec.timestamp_format, std_offset_h)
            .map_err(|m| row_err(path, line, &ts_name, m))?;
        rows.push(Row {
            line,
            clock,
            offset,
            record,
        });
    }
    if rows.is_empty() {
        return Err(file_err(path, "no data rows".into()));
    }
    Ok(Table {
        ts_name,
        columns,
        rows,
        saw_24,
    })
}

/// The timestamp column's index (`spec.timestamp_column`, else the first header naming a time
/// or date, else the first) and each meter column with its index.
fn locate_columns(
    headers: &[String],
    spec: &MeterSpec,
    path: &Path,
    notes: &mut Vec<String>,
) -> Result<(usize, Vec<(MeterColumn, usize)>), PrecalError> {
    if headers.iter().all(String::is_empty) {
        return Err(file_err(
            path,
            "empty file: expected a header line naming a timestamp column and the meters".into(),
        ));
    }
    let find = |name: &str| -> Option<usize> {
        headers.iter().position(|h| h == name.trim()).or_else(|| {
            headers
                .iter()
                .position(|h| h.eq_ignore_ascii_case(name.trim()))
        })
    };
    let ts_idx = match &spec.timestamp_column {
        Some(c) => find(c).ok_or_else(|| {
            file_err(
                path,
                format!("timestamp column '{c}' not found; headers: {headers:?}"),
            )
        })?,
        None => headers
            .iter()
            .position(|h| {
                let l = h.to_ascii_lowercase();
                l.contains("time") || l.contains("date")
            })
            .unwrap_or(0),
    };
    let columns = if spec.columns.is_empty() {
        let hs: Vec<&str> = headers.iter().map(String::as_str).collect();
        let c = detect_columns(&hs, Some(&headers[ts_idx]));
        if c.is_empty() {
            return Err(file_err(
                path,
                format!(
                    "no meter column recognised among headers {headers:?}; list them in [meters] columns"
                ),
            ));
        }
        notes.push(format!(
            "columns detected from headers: {}",
            c.iter()
                .map(|c| format!("'{}' -> {} [{}]", c.column, c.role, c.unit.as_str()))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        c
    } else {
        spec.columns.clone()
    };
    let columns = columns
        .into_iter()
        .map(|c| match find(&c.column) {
            Some(i) => Ok((c, i)),
            None => Err(file_err(
                path,
                format!(
                    "meter column '{}' not found; headers: {headers:?}",
                    c.column
                ),
            )),
        })
        .collect::<Result<_, _>>()?;
    Ok((ts_idx, columns))
}

#[cfg(test)]
mod tests {
    use super::clock::us_dst_days;
    use super::*;
    use chrono::{Datelike, NaiveDate, Timelike};

    fn spec() -> MeterSpec {
        MeterSpec {
            columns: vec![MeterColumn {
                column: "Heat".into(),
                role: MeterRole::Heating,
                unit: EnergyUnit::KWh,
                exclude: None,
                fit: true,
            }],
            ..MeterSpec::default()
        }
    }

    #[test]
    fn slots_and_dates() {
        let t = NaiveDate::from_ymd_opt(2011, 3, 1)
            .unwrap()
            .and_hms_opt(5, 0, 0)
            .unwrap();
        let y = GridYear::calendar(2011);
        assert_eq!(y.slot_of(t), Some(59 * 24 + 5));
        assert_eq!(y.slot_time(59 * 24 + 5), t);
        assert_eq!(
            GridYear::calendar(2016)
                .slot_time(59 * 24)
                .date()
                .to_string(),
            "2016-03-01"
        );
        assert_eq!(slot_month(8759), 12);
        assert_eq!(y.day_date(364).to_string(), "2011-12-31");
    }

    #[test]
    fn hour_ending_and_units_and_missing() {
        let text = "Time,Heat,Gas (therm)\n01/01/2011 01:00,5,1\n01/01/2011 02:00,,2\n1/1/2011 3:00,NA,x\n";
        let mut s = spec();
        s.columns.push(MeterColumn {
            column: "Gas (therm)".into(),
            role: MeterRole::Submeter("gas".into()),
            unit: EnergyUnit::Therm,
            exclude: None,
            fit: true,
        });
        let e = parse_meters(text, Path::new("m.csv"), &s, None, None).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("m.csv:4: column 'Gas (therm)'"), "{msg}");
        let text = text.replace(",x\n", ",3\n");
        let d = parse_meters(&text, Path::new("m.csv"), &s, None, None).unwrap();
        assert_eq!(d.year, GridYear::calendar(2011));
        assert_eq!(d.series[0].values[0], 5.0);
        assert!(d.series[0].values[1].is_nan());
        assert!((d.series[1].values[1] - 2.0 * 29.307107).abs() < 1e-9);
        assert!(
            d.notes.iter().any(|n| n.contains("hour-ending")),
            "{:?}",
            d.notes
        );
    }

    #[test]
    fn semicolons_and_decimal_commas_as_a_european_spreadsheet_writes_them() {
        let comma = "timestamp,Heat\n2011-01-01 00:00,1.5\n2011-01-01 01:00,2\n";
        let semicolon = "timestamp;Heat\n2011-01-01 00:00;1,5\n2011-01-01 01:00;2\n";
        let tab = "timestamp\tHeat\n2011-01-01 00:00\t1,5\n2011-01-01 01:00\t2\n";
        let mut s = spec();
        s.timestamp_format = "iso8601".into();
        let read = |t: &str| parse_meters(t, Path::new("m.csv"), &s, None, None).unwrap();
        let base = read(comma);
        assert!(!base.notes.iter().any(|n| n.contains("separated")));
        for t in [semicolon, tab] {
            let d = read(t);
            assert_eq!(&d.series[0].values[..2], &[1.5, 2.0]);
            assert!(
                d.notes.iter().any(|n| n.contains("decimal commas")),
                "{:?}",
                d.notes
            );
        }
        // A comma-separated file's quoted "1,5" stays an error (a thousands separator or a
        // decimal comma: not guessed), named with its line.
        let quoted = "timestamp,Heat\n2011-01-01 00:00,\"1,5\"\n";
        let e = parse_meters(quoted, Path::new("m.csv"), &s, None, None).unwrap_err();
        assert!(e.to_string().contains("m.csv:2:"), "{e}");
    }

    #[test]
    fn duplicates_negative_and_24h() {
        let text = "timestamp,Heat\n2011-01-01 00:00,1\n2011-01-01 01:00,2\n2011-01-01 01:00,4\n";
        let mut s = spec();
        s.timestamp_format = "iso8601".into();
        let e = parse_meters(text, Path::new("m.csv"), &s, None, None).unwrap_err();
        assert!(e.to_string().contains("m.csv:4:"), "{e}");
        assert!(e.to_string().contains("line 3"), "{e}");
        s.duplicates = DuplicatePolicy::Mean;
        let d = parse_meters(text, Path::new("m.csv"), &s, None, None).unwrap();
        assert_eq!(d.series[0].values[1], 3.0);
        let neg = "timestamp,Heat\n2011-01-01 00:00,-1\n";
        let e = parse_meters(neg, Path::new("m.csv"), &s, None, None).unwrap_err();
        assert!(
            e.to_string().contains("m.csv:2: column 'Heat': negative"),
            "{e}"
        );
        s.negative = NegativePolicy::Zero;
        let d = parse_meters(neg, Path::new("m.csv"), &s, None, None).unwrap();
        assert_eq!(d.series[0].values[0], 0.0);
        // 24:00 hour-ending = last hour of the day.
        let mut s = spec();
        s.convention = HourConvention::HourEnding;
        let t = "Time,Heat\n01/01/2011 24:00,7\n";
        let d = parse_meters(t, Path::new("m.csv"), &s, None, None).unwrap();
        assert_eq!(d.series[0].values[23], 7.0);
    }

    #[test]
    fn a_repeated_stamp_of_a_sub_hourly_meter_is_the_duplicate() {
        let text = "timestamp,Heat\n2011-01-01 00:00,1\n2011-01-01 00:15,1\n2011-01-01 00:30,1\n\
                    2011-01-01 00:30,9\n2011-01-01 00:45,1\n2011-01-01 01:00,2\n";
        let mut s = spec();
        s.timestamp_format = "iso8601".into();
        s.convention = HourConvention::HourBeginning;
        let e = parse_meters(text, Path::new("m.csv"), &s, None, None).unwrap_err();
        assert!(
            e.to_string().contains("m.csv:5:")
                && e.to_string().contains("line 4 has the same stamp"),
            "{e}"
        );
        s.duplicates = DuplicatePolicy::First;
        let d = parse_meters(text, Path::new("m.csv"), &s, None, None).unwrap();
        // Energy readings summed over the hour, the first 00:30 reading kept (9 dropped).
        assert_eq!(d.series[0].values[0], 4.0);
    }

    #[test]
    fn us_dst_repeats_and_skips() {
        // Clock time, hour-beginning, 2011: spring forward 13 March, fall back 6 November.
        let mut text = String::from("Time,Heat\n");
        let mut t = NaiveDate::from_ymd_opt(2011, 3, 12)
            .unwrap()
            .and_hms_opt(0, 0, 0)
            .unwrap();
        let end = NaiveDate::from_ymd_opt(2011, 3, 14)
            .unwrap()
            .and_hms_opt(0, 0, 0)
            .unwrap();
        while t < end {
            if !(t.date().day() == 13 && t.hour() == 2) {
                text += &format!("{},{}\n", t.format("%m/%d/%Y %H:%M"), t.hour());
            }
            t += Duration::hours(1);
        }
        // Autumn: 01:00 appears twice.
        for (h, v) in [(0, 100), (1, 101), (1, 102), (2, 103)] {
            text += &format!("11/06/2011 {h:02}:00,{v}\n");
        }
        let mut s = spec();
        s.convention = HourConvention::HourBeginning;
        let d = parse_meters(
            &text,
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2011)),
            None,
        )
        .unwrap();
        assert!(
            d.notes.iter().any(|n| n.contains("US DST")),
            "{:?}",
            d.notes
        );
        let v = &d.series[0].values;
        let mar13 = (CUM_DAYS[2] + 12) * 24;
        // Before the switch: unchanged; clock 03:00 (DST) = 02:00 standard.
        assert_eq!(v[mar13 + 1], 1.0);
        assert_eq!(v[mar13 + 2], 3.0);
        // Clock 23:00 = 22:00 standard; standard 23:00 would be clock 00:00 on 14 March,
        // which is not in the file.
        assert_eq!(v[mar13 + 22], 23.0);
        assert!(v[mar13 + 23].is_nan());
        let nov6 = (CUM_DAYS[10] + 5) * 24;
        // Clock 00:00 DST = 23:00 standard on 5 Nov; first 01:00 = 00:00; second 01:00 = 01:00.
        assert_eq!(v[nov6 - 1], 100.0);
        assert_eq!(v[nov6], 101.0);
        assert_eq!(v[nov6 + 1], 102.0);
        assert_eq!(v[nov6 + 2], 103.0);
    }

    #[test]
    fn twelve_months_from_april_fill_the_grid_with_the_next_years_first_quarter() {
        // An AMI export of April 2017 - March 2018 on a US DST clock, 15-minute readings: the
        // grid year is inferred as 2017-04, every hour is filled, and daylight saving is
        // undone in both years (November 2017 and March 2018).
        let at = |y, m, h| {
            NaiveDate::from_ymd_opt(y, m, 1)
                .unwrap()
                .and_hms_opt(h, 0, 0)
                .unwrap()
        };
        let mut text = String::from("Time,Heat\n");
        let mut t = at(2017, 4, 0);
        let end = at(2018, 4, 0);
        let clock = |t: NaiveDateTime| {
            let dst = |y| us_dst_days(y).unwrap();
            let (spring, fall) = dst(t.year());
            let in_dst =
                t >= spring.and_hms_opt(2, 0, 0).unwrap() && t < fall.and_hms_opt(1, 0, 0).unwrap();
            if in_dst {
                t + Duration::hours(1)
            } else {
                t
            }
        };
        while t < end {
            // A quarter-hour reading of 0.25 kWh, 1.0 kWh an hour; the day of month in January.
            let v = if t.month() == 1 {
                t.day() as f64 / 4.0
            } else {
                0.25
            };
            text += &format!("{},{v}\n", clock(t).format("%Y-%m-%d %H:%M"));
            t += Duration::minutes(15);
        }
        let mut s = spec();
        s.convention = HourConvention::HourBeginning;
        let d = parse_meters(&text, Path::new("m.csv"), &s, None, None).unwrap();
        assert_eq!(d.year, "2017-04".parse().unwrap(), "{:?}", d.notes);
        assert!(
            d.notes
                .iter()
                .any(|n| n.contains("2017-04-01 to 2018-03-31")),
            "{:?}",
            d.notes
        );
        assert!(
            d.notes.iter().any(|n| n.contains("US DST")),
            "{:?}",
            d.notes
        );
        let v = &d.series[0].values;
        assert_eq!(
            v.iter().filter(|x| x.is_finite()).count(),
            HOURS,
            "{:?}",
            d.notes
        );
        // Slot 0 is 1 January 2018; 15 January reads 15/4 kWh every quarter hour.
        assert_eq!(
            d.year.slot_time(0).date(),
            NaiveDate::from_ymd_opt(2018, 1, 1).unwrap()
        );
        assert!((v[14 * 24 + 5] - 15.0).abs() < 1e-9);
        assert!(v
            .iter()
            .enumerate()
            .filter(|(t, _)| slot_month(*t) != 1)
            .all(|(_, &x)| (x - 1.0).abs() < 1e-9));
        // The same file read as calendar year 2017 keeps April-December only, and says so.
        let y17 = parse_meters(
            &text,
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2017)),
            None,
        )
        .unwrap();
        assert_eq!(
            y17.series[0]
                .values
                .iter()
                .filter(|x| x.is_finite())
                .count(),
            HOURS - 90 * 24
        );
        assert!(
            y17.notes.iter().any(|n| n.contains(
                "outside 2017-01-01 to 2017-12-31 dropped (their stamps fit year = \"2017-04\""
            )),
            "{:?}",
            y17.notes
        );
        // Read as 2021 (a model whose `year` was left at its default), nothing is left: the
        // message says which year the stamps fit.
        let e = parse_meters(
            &text,
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2021)),
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("no rows fall in 2021-01-01 to 2021-12-31")
                && e.contains("the timestamps run 2017-04-01 to 2018-04-01")
                && e.contains("set the model's `year` to the meters' year (year = \"2017-04\")"),
            "{e}"
        );
        // The same year as an hourly, hour-ending export (01:00 on 1 April 2017 to 00:00 on
        // 1 April 2018, standard time): recognised as hour-ending, every hour filled.
        let mut text = String::from("Time,Heat\n");
        let mut t = at(2017, 4, 1);
        while t <= end {
            text += &format!("{},1\n", t.format("%Y-%m-%d %H:%M"));
            t += Duration::hours(1);
        }
        let mut s = spec();
        s.dst = DstHandling::None;
        let d = parse_meters(&text, Path::new("m.csv"), &s, None, None).unwrap();
        assert!(
            d.notes.iter().any(|n| n.contains("hour-ending")),
            "{:?}",
            d.notes
        );
        assert_eq!(d.year, "2017-04".parse().unwrap(), "{:?}", d.notes);
        assert!(
            d.series[0].values.iter().all(|v| *v == 1.0),
            "{:?}",
            d.notes
        );
        // Thirteen months or more: the latest twelve whole months.
        let stamps = |a: (i32, u32), b: (i32, u32)| [at(a.0, a.1, 0), at(b.0, b.1, 0)].into_iter();
        assert_eq!(
            infer_year(stamps((2017, 4), (2018, 3))),
            "2017-04".parse().unwrap()
        );
        assert_eq!(
            infer_year(stamps((2017, 4), (2018, 5))),
            "2017-05".parse().unwrap(),
            "1 April 2017 to 1 May 2018 00:00: May 2017 to April 2018"
        );
        // An AMI export of 17 months ending mid-month: the twelve whole months before.
        let hourly = |a: NaiveDateTime, b: NaiveDateTime| {
            (0..=(b - a).num_hours()).map(move |h| a + Duration::hours(h))
        };
        let t = |y, m, d, h| {
            NaiveDate::from_ymd_opt(y, m, d)
                .unwrap()
                .and_hms_opt(h, 0, 0)
                .unwrap()
        };
        assert_eq!(
            infer_year(hourly(t(2023, 6, 15, 0), t(2024, 11, 20, 13))),
            "2023-11".parse().unwrap()
        );
        // Ending with a year: that calendar year, not the one the record starts in.
        assert_eq!(
            infer_year(hourly(t(2023, 7, 1, 0), t(2024, 12, 31, 23))),
            GridYear::calendar(2024)
        );
        assert_eq!(
            infer_year(stamps((2017, 1), (2017, 12))),
            GridYear::calendar(2017)
        );
    }

    #[test]
    fn a_named_time_zone_gives_its_own_daylight_saving_in_either_hemisphere() {
        // Berlin, 2021: clocks forward 28 March 02:00 -> 03:00, back 31 October 03:00 -> 02:00.
        let mut text = String::from("Time,Heat\n");
        for h in [0, 1, 3, 4] {
            text += &format!("03/28/2021 {h:02}:00,{h}\n");
        }
        for (h, v) in [(1, 101), (2, 102), (2, 103), (3, 104)] {
            text += &format!("10/31/2021 {h:02}:00,{v}\n");
        }
        text += "07/01/2021 12:00,7\n";
        let mut s = spec();
        s.convention = HourConvention::HourBeginning;
        s.time_zone = Some("Europe/Berlin".into());
        let d = parse_meters(
            &text,
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2021)),
            None,
        )
        .unwrap();
        assert!(
            d.notes
                .iter()
                .any(|n| n.contains("time zone Europe/Berlin: standard time UTC+1.0 h")),
            "{:?}",
            d.notes
        );
        let v = &d.series[0].values;
        let mar28 = (CUM_DAYS[2] + 27) * 24;
        // Standard time before the switch; clock 03:00 (summer time) is 02:00 standard.
        assert_eq!(
            (v[mar28], v[mar28 + 1], v[mar28 + 2], v[mar28 + 3]),
            (0.0, 1.0, 3.0, 4.0)
        );
        let oct31 = (CUM_DAYS[9] + 30) * 24;
        // Clock 01:00 summer = 00:00; the first 02:00 is summer (01:00), the second standard.
        assert_eq!(
            (v[oct31], v[oct31 + 1], v[oct31 + 2], v[oct31 + 3]),
            (101.0, 102.0, 103.0, 104.0)
        );
        assert_eq!(
            v[(CUM_DAYS[6]) * 24 + 11],
            7.0,
            "July noon is 11:00 standard"
        );

        // Sydney: daylight saving in January (the southern summer), standard UTC+10 in July.
        let text = "Time,Heat\n01/15/2021 12:00,1\n07/15/2021 12:00,2\n";
        s.time_zone = Some("Australia/Sydney".into());
        let d = parse_meters(
            text,
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2021)),
            None,
        )
        .unwrap();
        let v = &d.series[0].values;
        assert_eq!(v[14 * 24 + 11], 1.0);
        assert_eq!(v[(CUM_DAYS[6] + 14) * 24 + 12], 2.0);

        // A clock time that does not exist there, and a zone that does not exist.
        s.time_zone = Some("Europe/Berlin".into());
        let e = parse_meters(
            "Time,Heat\n03/28/2021 02:00,1\n",
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2021)),
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("m.csv:2") && e.contains("no such clock time in Europe/Berlin"),
            "{e}"
        );
        s.time_zone = Some("Europe/Atlantis".into());
        let e = parse_meters(
            text,
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2021)),
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("not an IANA time zone"), "{e}");
        s.time_zone = Some("Europe/Berlin".into());
        s.dst = DstHandling::Us;
        let e = parse_meters(
            text,
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2021)),
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("leave meters.dst out"), "{e}");
        s.dst = DstHandling::Auto;
        let e = parse_meters(
            text,
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2021)),
            Some(-7.0),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("weather file's site is at UTC-7.0 h"), "{e}");
    }

    #[test]
    fn empty_files_short_rows_and_infinite_values_are_errors_naming_the_line() {
        let s = spec();
        let read = |text: &str| match parse_meters(
            text,
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2021)),
            None,
        ) {
            Ok(_) => "read without an error".to_string(),
            Err(e) => e.to_string(),
        };
        assert!(read("").contains("m.csv: empty file"), "{}", read(""));
        let head = "Time,Heat\n01/01/2021 00:00,1\n";
        for (row, want) in [
            ("01/01/2021 01:00", "m.csv:3"),
            ("01/01/2021 01:00,inf", "'inf' is not a finite number"),
            ("01/01/2021 01:00,1e999", "'1e999' is not a finite number"),
        ] {
            let e = read(&format!("{head}{row}\n"));
            assert!(e.contains(want), "{row}: {e}");
        }
        let long = "9".repeat(5000) + "x";
        let e = read(&format!("{head}01/01/2021 01:00,{long}\n"));
        assert!(
            e.len() < 300,
            "the message quotes an excerpt, not the cell: {} bytes",
            e.len()
        );
        // Missing readings stay missing.
        let d = parse_meters(
            &format!("{head}01/01/2021 01:00,\n01/01/2021 02:00,NaN\n"),
            Path::new("m.csv"),
            &s,
            Some(GridYear::calendar(2021)),
            None,
        )
        .unwrap();
        assert!(d.series[0].values[1].is_nan() && d.series[0].values[2].is_nan());
    }

    #[test]
    fn detects_rsf_columns() {
        let h = [
            "Day of Week",
            "Date and Time",
            "Total Cooling (kW)",
            "Total Heating (kW)",
            "Total Mechanical (kW)",
            "Total Lighting (kW)",
            "Total Plug Loads (kW)",
            "Total Data Center (kW)",
            "Total Building (kW)",
            "PV (kW)",
            "Building Net (kW)",
            "",
        ];
        let c = detect_columns(&h, Some("Date and Time"));
        let roles: Vec<&str> = c.iter().map(|c| c.role.name()).collect();
        assert_eq!(
            roles,
            [
                "cooling",
                "heating",
                "mechanical",
                "lighting",
                "plug_loads",
                "data_center",
                "electricity"
            ]
        );
        assert!(c.iter().all(|c| c.unit == EnergyUnit::KW));
    }

    #[test]
    fn spec_round_trips_through_toml_friendly_serde() {
        let s: MeterSpec = serde_json::from_str(
            r#"{"file":"m.csv","convention":"hour_ending","dst":"none",
                "columns":[{"column":"Total Data Center (kW)","role":"data center","unit":"kW"},
                           {"column":"Gas","role":"heating","unit":"MMBtu"}]}"#,
        )
        .unwrap();
        assert_eq!(s.columns[0].role, MeterRole::Submeter("data_center".into()));
        assert_eq!(s.columns[1].unit, EnergyUnit::MMBtu);
        assert_eq!(s.timestamp_format, DEFAULT_TIMESTAMP_FORMAT);
        let j = serde_json::to_string(&s).unwrap();
        assert!(j.contains("\"role\":\"data_center\""), "{j}");
    }

    #[test]
    fn an_excluded_period_is_missing_for_its_meter_alone() {
        // Three days of two meters; the heating meter read zero through an outage on the 2nd.
        let mut text = String::from("Time,Heat,Elec\n");
        for d in 1..=3 {
            for h in 0..24 {
                let heat = if d == 2 { 0.0 } else { 5.0 };
                text.push_str(&format!("2011-01-0{d}T{h:02}:00,{heat},7\n"));
            }
        }
        let mut s: MeterSpec = toml::from_str(
            r#"
timestamp_format = "iso8601"
convention = "hour_beginning"
[[columns]]
column = "Heat"
role = "heating"
unit = "kWh"
exclude = "2011-01-02..2011-01-02"
[[columns]]
column = "Elec"
role = "electricity"
unit = "kWh"
"#,
        )
        .unwrap();
        let d = parse_meters(&text, Path::new("m.csv"), &s, None, None).unwrap();
        let heat = &d.series[0].values;
        assert!(heat[..24].iter().all(|v| *v == 5.0));
        assert!(heat[24..48].iter().all(|v| v.is_nan()));
        assert!(heat[48..72].iter().all(|v| *v == 5.0));
        assert!(d.series[1].values[..72].iter().all(|v| *v == 7.0));
        let note = d.notes.iter().find(|n| n.contains("exclude")).unwrap();
        assert!(
            note.starts_with("column 'Heat': 24 readings in 2011-01-02..2011-01-02"),
            "{note}"
        );
        // A period outside the meters' year is a clear error naming the column.
        s.columns[0].exclude = Some("2012-03".parse().unwrap());
        let e = parse_meters(&text, Path::new("m.csv"), &s, None, None).unwrap_err();
        assert!(
            e.to_string()
                .contains("column 'Heat', exclude 2012-03: the meters cover"),
            "{e}"
        );
    }
}
