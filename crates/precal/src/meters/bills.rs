//! Utility bills (issue 69): a meter read as a table of billing periods, one row per bill, as
//! utilities and ENERGY STAR Portfolio Manager export them.
//!
//! # Rules (documented behaviour)
//!
//! * **Columns** (header names in any case): `start`, `end`, `quantity`; optional `unit`,
//!   `demand_kw` (the billed peak demand) and `estimated` (`true`/`yes`/`y`/`1`/`e`/`estimated`:
//!   an estimated read; empty or `false`/`no`/`n`/`0`/`a`/`actual`: an actual one).
//! * **Dates** `2021-01-14` or `01/14/2021`. A bill runs from the start of its `start` day to the
//!   start of the day after its `end` ([`BillEnd::Inclusive`], the default: the end date is the
//!   last day billed), or to the start of its `end` day ([`BillEnd::Exclusive`]: the end date is
//!   the next read date, the start of the next bill).
//! * **Units**: the energy units of hourly meters ([`EnergyUnit`]'s energy units: kWh, MWh,
//!   therm, kBtu, MMBtu, MJ, GJ, ...) and gas volumes ([`GasVolume`]: m3, ft3, ccf, mcf) with
//!   the gas's calorific value (`calorific_value_kwh_per_m3`, gross). A power unit (kW) is
//!   refused: a bill's quantity is energy. The `unit` column overrides the spec's unit per row.
//! * **Refused**, naming the file and line: a date or number that does not parse, an end before
//!   the start, a negative quantity, a bill overlapping the one before it (in date order), a
//!   volume without a calorific value.
//! * **Noted** (the bill is kept): a gap between two bills (days no bill covers), an estimated
//!   read.
//! * **Estimated reads** ([`EstimatedReads`], `estimated = ...` in the spec): an estimated read
//!   is the utility's guess, not a measurement. Where a read was missed and the meter kept
//!   counting, the next actual read trues it up: the estimated bill and the bill after it,
//!   together, hold what the meter measured, while each alone holds the guess and its
//!   correction. So by default ([`EstimatedReads::Merge`]) an estimated bill is joined to the
//!   bills after it up to and including the next actual one, where they follow day after day;
//!   one with no actual read after it (the last bill, or a gap next) is not compared. Where the
//!   meter itself failed (no true-up follows), [`EstimatedReads::Drop`] leaves estimated bills
//!   out; [`EstimatedReads::Fit`] takes them as measured. Every join and drop is noted.

use std::path::{Path, PathBuf};

use chrono::{Duration, NaiveDate};
use serde::{Deserialize, Serialize};

use bemcal_weather::grid::{is_leap_day, GridYear};

use super::spec::{EnergyUnit, MeterRole};
use super::{file_err, row_err};
use crate::PrecalError;

/// What a bill's end date means.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum BillEnd {
    /// The end date is the last day billed (the bill runs to the start of the next day).
    #[default]
    Inclusive,
    /// The end date is the next read date: the bill runs to the start of that day.
    Exclusive,
}

/// What an estimated read is taken for ([module rules](self)).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum EstimatedReads {
    /// A missed read that the next actual read trued up: joined to the bills after it up to and
    /// including the next actual one (not compared where none follows day after day).
    #[default]
    Merge,
    /// The meter failed and nothing trued it up: left out.
    Drop,
    /// Taken as measured.
    Fit,
}

/// A gas volume unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GasVolume {
    /// Cubic metre.
    M3,
    /// Cubic foot (0.028316846592 m3).
    Ft3,
    /// Hundred cubic feet.
    Ccf,
    /// Thousand cubic feet.
    Mcf,
}

impl GasVolume {
    /// Cubic metres in one unit.
    pub fn to_m3(self) -> f64 {
        const FT3: f64 = 0.028_316_846_592;
        match self {
            GasVolume::M3 => 1.0,
            GasVolume::Ft3 => FT3,
            GasVolume::Ccf => 100.0 * FT3,
            GasVolume::Mcf => 1000.0 * FT3,
        }
    }
}

/// The unit of a bill's quantity: energy, or a gas volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BillUnit {
    /// An energy unit (not a power unit).
    Energy(EnergyUnit),
    /// A gas volume, converted with the calorific value.
    Volume(GasVolume),
}

impl std::str::FromStr for BillUnit {
    type Err = String;
    fn from_str(s: &str) -> Result<BillUnit, String> {
        let key: String = s
            .chars()
            .filter(|c| !matches!(c, ' ' | '_' | '-'))
            .flat_map(char::to_lowercase)
            .collect();
        let volume = match key.as_str() {
            "m3" | "m³" | "cubicmetre" | "cubicmeter" | "cubicmetres" | "cubicmeters" => {
                Some(GasVolume::M3)
            }
            "ft3" | "cf" | "cuft" | "cubicfeet" | "cubicfoot" => Some(GasVolume::Ft3),
            "ccf" | "hcf" => Some(GasVolume::Ccf),
            "mcf" => Some(GasVolume::Mcf),
            _ => None,
        };
        if let Some(v) = volume {
            return Ok(BillUnit::Volume(v));
        }
        let energy: EnergyUnit = s.parse()?;
        if energy.is_power() {
            return Err(format!(
                "'{s}' is a power unit: a bill's quantity is energy (kWh, therm, MMBtu, GJ, ...) or a gas volume (m3, ft3, ccf, mcf)"
            ));
        }
        Ok(BillUnit::Energy(energy))
    }
}

/// A meter read as bills. Sits in the project file as `[[meters.bills]]`:
///
/// ```toml
/// [[meters.bills]]
/// file = "gas_bills.csv"
/// role = "heating"
/// unit = "ccf"
/// calorific_value_kwh_per_m3 = 10.8
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BillSpec {
    /// The bills CSV (relative paths are relative to the project file).
    pub file: PathBuf,
    /// What the bills meter.
    pub role: MeterRole,
    /// Unit of the quantities where the file has no `unit` column (or a row leaves it empty).
    #[serde(default)]
    pub unit: Option<String>,
    /// Gross calorific value of the gas, kWh per m3 (natural gas: about 10.5-11.5), for volume
    /// units.
    #[serde(default)]
    pub calorific_value_kwh_per_m3: Option<f64>,
    /// What the end date means.
    #[serde(default)]
    pub end: BillEnd,
    /// What an estimated read is taken for: `"merge"` (the default: joined with the next actual
    /// read, which trued it up), `"drop"` (the meter failed: left out) or `"fit"` (as measured).
    #[serde(default)]
    pub estimated: EstimatedReads,
}

/// One bill.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bill {
    /// 1-based line in the file (the header is line 1).
    pub line: u64,
    /// The first day billed.
    pub start: NaiveDate,
    /// The day after the last day billed (the period is `start..end`).
    pub end: NaiveDate,
    /// The quantity in kWh.
    pub kwh: f64,
    /// The billed peak demand, kW.
    pub demand_kw: Option<f64>,
    /// An estimated read.
    pub estimated: bool,
}

impl Bill {
    /// Days billed.
    pub fn days(&self) -> i64 {
        (self.end - self.start).num_days()
    }

    /// The grid's hour slots the bill covers, in time order (29 February, which the grid
    /// leaves out, gives none), or `None` where a day of the bill lies outside the year: the
    /// model simulates one year, so such a bill cannot be compared.
    pub fn hours(&self, year: GridYear) -> Option<Vec<usize>> {
        let mut out = Vec::with_capacity(24 * self.days().max(0) as usize);
        for day in self.start.iter_days().take_while(|d| *d < self.end) {
            if is_leap_day(day) && year.spans(day) {
                continue;
            }
            for h in 0..24 {
                out.push(year.slot_of(day.and_hms_opt(h, 0, 0)?)?);
            }
        }
        Some(out)
    }
}

/// A meter's bills, in date order, with what was noted reading them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BillTable {
    /// What the bills meter.
    pub role: MeterRole,
    /// The file.
    pub path: PathBuf,
    /// The bills in date order.
    pub bills: Vec<Bill>,
    /// Gaps and estimated reads.
    pub notes: Vec<String>,
}

/// Reads a bills CSV ([module rules](self)).
pub fn read_bills(path: &Path, spec: &BillSpec) -> Result<BillTable, PrecalError> {
    let text = std::fs::read_to_string(path).map_err(|source| PrecalError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_bills(&text, path, spec)
}

/// Each bill's total of a daily series (`daily`: a date's total, None where the series lacks
/// the day): the sum over the bill's days, 29 February left out as the grid leaves it; None
/// where a day of the bill is lacking, so that no bill is compared over part of its period.
pub fn bill_totals(bills: &[Bill], daily: impl Fn(NaiveDate) -> Option<f64>) -> Vec<Option<f64>> {
    (bills.iter())
        .map(|b| grid_days(b).map(&daily).sum())
        .collect()
}

/// Each bill's peak of a daily series of peaks (`daily_peak`: a date's highest hour, None where
/// the series lacks the day), over the same days as [`bill_totals`]: None where a day is
/// lacking.
pub fn bill_peaks(
    bills: &[Bill],
    daily_peak: impl Fn(NaiveDate) -> Option<f64>,
) -> Vec<Option<f64>> {
    (bills.iter())
        .map(|b| {
            grid_days(b)
                .map(&daily_peak)
                .try_fold(f64::NEG_INFINITY, |a, p| p.map(|p| a.max(p)))
        })
        .collect()
}

/// A bill's days as the grid counts them: 29 February left out.
fn grid_days(b: &Bill) -> impl Iterator<Item = NaiveDate> + '_ {
    (b.start.iter_days())
        .take_while(|d| *d < b.end)
        .filter(|d| !is_leap_day(*d))
}

/// The column indices of the bills table.
struct Columns {
    start: usize,
    end: usize,
    quantity: usize,
    unit: Option<usize>,
    demand: Option<usize>,
    estimated: Option<usize>,
}

fn columns(headers: &csv::StringRecord, path: &Path) -> Result<Columns, PrecalError> {
    let find = |name: &str| {
        headers
            .iter()
            .position(|h| h.trim().eq_ignore_ascii_case(name))
    };
    let need = |name: &str| {
        find(name).ok_or_else(|| {
            file_err(
                path,
                format!(
                    "no '{name}' column: a bills file has the columns start, end, quantity (and optionally unit, demand_kw, estimated); the header is: {}",
                    bemcal_excerpt::excerpt(&headers.iter().collect::<Vec<_>>().join(","), 120)
                ),
            )
        })
    };
    Ok(Columns {
        start: need("start")?,
        end: need("end")?,
        quantity: need("quantity")?,
        unit: find("unit"),
        demand: find("demand_kw"),
        estimated: find("estimated"),
    })
}

fn parse_date(s: &str) -> Option<NaiveDate> {
    NaiveDate::parse_from_str(s, "%Y-%m-%d")
        .or_else(|_| NaiveDate::parse_from_str(s, "%m/%d/%Y"))
        .ok()
}

fn parse_flag(s: &str) -> Option<bool> {
    match s.to_ascii_lowercase().as_str() {
        "true" | "yes" | "y" | "1" | "e" | "estimated" => Some(true),
        "" | "false" | "no" | "n" | "0" | "a" | "actual" => Some(false),
        _ => None,
    }
}

/// kWh per unit of `unit`, with the spec's calorific value for a volume.
fn kwh_per_unit(unit: BillUnit, spec: &BillSpec) -> Result<f64, String> {
    match unit {
        BillUnit::Energy(e) => Ok(e.to_kwh()),
        BillUnit::Volume(v) => match spec.calorific_value_kwh_per_m3 {
            Some(cv) if cv.is_finite() && cv > 0.0 => Ok(v.to_m3() * cv),
            Some(cv) => Err(format!("calorific_value_kwh_per_m3 = {cv}: expected a positive number")),
            None => Err(
                "a gas volume needs the gas's calorific value: set calorific_value_kwh_per_m3 (natural gas: about 10.5-11.5 kWh per m3) in [[meters.bills]]"
                    .into(),
            ),
        },
    }
}

/// Parses a bills CSV's text ([module rules](self)); `path` names the file in errors.
pub fn parse_bills(text: &str, path: &Path, spec: &BillSpec) -> Result<BillTable, PrecalError> {
    let default_unit = spec
        .unit
        .as_deref()
        .map(|u| u.parse::<BillUnit>())
        .transpose()
        .map_err(|m| file_err(path, format!("[[meters.bills]] unit: {m}")))?;
    // A semicolon- or tab-separated file writes decimal commas (super::dialect::sniff_delimiter).
    let delimiter = super::dialect::sniff_delimiter(text);
    let mut rdr = csv::ReaderBuilder::new()
        .flexible(true)
        .trim(csv::Trim::All)
        .delimiter(delimiter)
        .from_reader(text.as_bytes());
    let headers = rdr
        .headers()
        .map_err(|e| file_err(path, format!("cannot read the header line: {e}")))?;
    let col = columns(headers, path)?;
    let mut bills = vec![];
    for rec in rdr.records() {
        let rec = rec.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            row_err(path, line, "", format!("malformed CSV: {e}"))
        })?;
        let rec = match delimiter {
            b',' => rec,
            _ => super::dialect::decimal_points(&rec, usize::MAX),
        };
        if !rec.iter().all(str::is_empty) {
            bills.push(parse_row(&rec, &col, spec, default_unit, path)?);
        }
    }
    if bills.is_empty() {
        return Err(file_err(
            path,
            "no bills: the file has a header and no rows".into(),
        ));
    }
    bills.sort_by_key(|b| b.start);
    let mut notes = check_periods(&bills, path)?;
    let bills = match spec.estimated {
        EstimatedReads::Fit => bills,
        rule => {
            let (bills, said) = settle_estimated(bills, rule);
            notes.extend(said);
            bills
        }
    };
    if bills.is_empty() {
        return Err(file_err(
            path,
            "no bills left: every bill is an estimated read without an actual read after it \
             (`estimated = \"fit\"` takes estimated reads as measured)"
                .into(),
        ));
    }
    Ok(BillTable {
        role: spec.role.clone(),
        path: path.to_path_buf(),
        bills,
        notes,
    })
}

/// One row of the bills table: a bill in kWh.
fn parse_row(
    rec: &csv::StringRecord,
    col: &Columns,
    spec: &BillSpec,
    default_unit: Option<BillUnit>,
    path: &Path,
) -> Result<Bill, PrecalError> {
    let line = rec.position().map_or(0, |p| p.line());
    let err = |column: &str, message: String| row_err(path, line, column, message);
    let field = |i: usize| rec.get(i).unwrap_or("");
    let quoted = |s: &str| bemcal_excerpt::excerpt(s, 40).into_owned();
    let date = |i: usize, name: &str| {
        parse_date(field(i)).ok_or_else(|| {
            err(
                name,
                format!(
                    "'{}' is not a date (expected 2021-01-14 or 01/14/2021)",
                    quoted(field(i))
                ),
            )
        })
    };
    let start = date(col.start, "start")?;
    let last = date(col.end, "end")?;
    let end = match spec.end {
        BillEnd::Inclusive => last + Duration::days(1),
        BillEnd::Exclusive => last,
    };
    if end <= start {
        return Err(err(
            "end",
            format!("the bill ends ({last}) before it starts ({start})"),
        ));
    }
    let quantity: f64 = field(col.quantity).parse().map_err(|_| {
        err(
            "quantity",
            format!("'{}' is not a number", quoted(field(col.quantity))),
        )
    })?;
    if !(quantity.is_finite() && quantity >= 0.0) {
        return Err(err(
            "quantity",
            format!("{quantity}: expected a quantity of 0 or more"),
        ));
    }
    let unit = match col.unit.map(field).filter(|u| !u.is_empty()) {
        Some(u) => u.parse::<BillUnit>().map_err(|m| err("unit", m))?,
        None => default_unit.ok_or_else(|| {
            err(
                "unit",
                "no unit: give a unit column or unit = \"...\" in [[meters.bills]]".into(),
            )
        })?,
    };
    let factor = kwh_per_unit(unit, spec).map_err(|m| err("unit", m))?;
    let demand_kw = match col.demand.map(field).filter(|d| !d.is_empty()) {
        None => None,
        Some(d) => Some(
            d.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| {
                    err(
                        "demand_kw",
                        format!("'{}' is not a demand in kW", quoted(d)),
                    )
                })?,
        ),
    };
    let estimated = match col.estimated.map(field) {
        None => false,
        Some(e) => parse_flag(e).ok_or_else(|| {
            err(
                "estimated",
                format!(
                    "'{}': expected true/false, yes/no, E/A (estimated/actual)",
                    quoted(e)
                ),
            )
        })?,
    };
    Ok(Bill {
        line,
        start,
        end,
        kwh: quantity * factor,
        demand_kw,
        estimated,
    })
}

/// Overlaps refused; gaps and estimated reads noted. `bills` in date order.
fn check_periods(bills: &[Bill], path: &Path) -> Result<Vec<String>, PrecalError> {
    let mut notes = vec![];
    for w in bills.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if b.start < a.end {
            return Err(row_err(
                path,
                b.line,
                "start",
                format!(
                    "the bill from {} overlaps the bill of line {} ({} to {}): each day belongs to one bill",
                    b.start,
                    a.line,
                    a.start,
                    a.end - Duration::days(1)
                ),
            ));
        }
        if b.start > a.end {
            notes.push(format!(
                "no bill covers {} to {} ({} days, between lines {} and {})",
                a.end,
                b.start - Duration::days(1),
                (b.start - a.end).num_days(),
                a.line,
                b.line
            ));
        }
    }
    let estimated: Vec<String> = bills
        .iter()
        .filter(|b| b.estimated)
        .map(|b| {
            format!(
                "{} to {} (line {})",
                b.start,
                b.end - Duration::days(1),
                b.line
            )
        })
        .collect();
    if !estimated.is_empty() {
        notes.push(format!("estimated reads: {}", estimated.join(", ")));
    }
    Ok(notes)
}

/// The estimated reads of `bills` (date order, no overlaps) joined to the next actual read
/// ([`EstimatedReads::Merge`]) or left out ([`EstimatedReads::Drop`]), with a note of each.
/// A joined bill keeps the first bill's line, sums the quantities and takes the larger demand.
fn settle_estimated(bills: Vec<Bill>, rule: EstimatedReads) -> (Vec<Bill>, Vec<String>) {
    let lines = |run: &[Bill]| {
        let list: Vec<String> = run.iter().map(|b| b.line.to_string()).collect();
        match list.len() {
            1 => format!("line {}", list[0]),
            _ => format!("lines {}", list.join(", ")),
        }
    };
    let mut out: Vec<Bill> = Vec::with_capacity(bills.len());
    let mut notes = vec![];
    // Estimated bills waiting, day after day, for the actual read that trues them up.
    let mut run: Vec<Bill> = vec![];
    let mut dropped: Vec<String> = vec![];
    for b in bills {
        if run.last().is_some_and(|last| last.end != b.start) {
            dropped.push(format!("{} (a gap follows)", lines(&run)));
            run.clear();
        }
        if b.estimated && rule == EstimatedReads::Drop {
            dropped.push(lines(std::slice::from_ref(&b)));
        } else if b.estimated {
            run.push(b);
        } else if run.is_empty() {
            out.push(b);
        } else {
            run.push(b);
            let first = &run[0];
            let joined = Bill {
                line: first.line,
                start: first.start,
                end: run[run.len() - 1].end,
                kwh: run.iter().map(|b| b.kwh).sum(),
                demand_kw: run.iter().filter_map(|b| b.demand_kw).reduce(f64::max),
                estimated: false,
            };
            notes.push(format!(
                "estimated reads joined to the actual read after them: {} as one bill, {} to {}",
                lines(&run),
                joined.start,
                joined.end - Duration::days(1)
            ));
            run.clear();
            out.push(joined);
        }
    }
    if !run.is_empty() {
        dropped.push(format!("{} (no actual read after it)", lines(&run)));
    }
    if !dropped.is_empty() {
        notes.push(format!(
            "estimated reads not compared: {}",
            dropped.join("; ")
        ));
    }
    (out, notes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bemcal_weather::grid::CUM_DAYS;

    fn spec(unit: Option<&str>) -> BillSpec {
        BillSpec {
            file: "bills.csv".into(),
            role: MeterRole::Heating,
            unit: unit.map(str::to_string),
            calorific_value_kwh_per_m3: None,
            end: BillEnd::Inclusive,
            estimated: EstimatedReads::Fit,
        }
    }

    fn parse(text: &str, spec: &BillSpec) -> Result<BillTable, PrecalError> {
        parse_bills(text, Path::new("bills.csv"), spec)
    }

    #[test]
    fn irregular_periods_in_any_energy_unit() {
        let t = parse(
            "Start,End,Quantity,Unit,Estimated\n\
             2021-01-05,2021-02-03,120,therm,\n\
             2021-02-04,2021-03-08,3.2,MMBtu,E\n\
             03/09/2021,04/06/2021,2500,kWh,no\n",
            &spec(None),
        )
        .unwrap();
        assert_eq!(t.bills.len(), 3);
        assert_eq!(t.bills[0].days(), 30);
        assert_eq!(t.bills[1].days(), 33);
        assert!((t.bills[0].kwh - 120.0 * 29.307_107).abs() < 1e-6);
        assert!((t.bills[1].kwh - 3.2 * 293.071_07).abs() < 1e-6);
        assert_eq!(
            t.bills[2].start,
            NaiveDate::from_ymd_opt(2021, 3, 9).unwrap()
        );
        assert!(t.bills[1].estimated && !t.bills[2].estimated);
        assert_eq!(
            t.notes,
            vec!["estimated reads: 2021-02-04 to 2021-03-08 (line 3)".to_string()]
        );
    }

    #[test]
    fn semicolon_separated_bills_with_decimal_commas() {
        let t = parse(
            "Start;End;Quantity;Unit;Estimated\n\
             2021-01-05;2021-02-03;120,5;therm;\n\
             2021-02-04;2021-03-08;3,2;MMBtu;E\n",
            &spec(None),
        )
        .unwrap();
        assert!((t.bills[0].kwh - 120.5 * 29.307_107).abs() < 1e-6);
        assert!((t.bills[1].kwh - 3.2 * 293.071_07).abs() < 1e-6);
        // The line an error names is the file's.
        assert_eq!(
            t.notes,
            vec!["estimated reads: 2021-02-04 to 2021-03-08 (line 3)".to_string()]
        );
    }

    /// A missed read trued up at the next actual read: only the two together are measured.
    #[test]
    fn estimated_reads_are_joined_to_the_actual_read_after_them_or_dropped() {
        let text = "start,end,quantity,demand_kw,estimated\n\
                    2021-01-05,2021-02-03,100,40,\n\
                    2021-02-04,2021-03-08,90,35,E\n\
                    2021-03-09,2021-04-06,130,50,E\n\
                    2021-04-07,2021-05-05,80,30,\n\
                    2021-05-06,2021-06-04,60,20,E\n\
                    2021-06-10,2021-07-08,70,25,\n\
                    2021-07-09,2021-08-06,75,25,E\n";
        let mut s = spec(Some("kWh"));
        s.estimated = EstimatedReads::Merge;
        let t = parse(text, &s).unwrap();
        let got: Vec<(u64, i64, f64, Option<f64>, bool)> = t
            .bills
            .iter()
            .map(|b| (b.line, b.days(), b.kwh, b.demand_kw, b.estimated))
            .collect();
        // Lines 3-5 are one bill of 33 + 29 + 29 days; line 6 has a gap after it, line 8 no
        // read after it: neither is compared.
        assert_eq!(
            got,
            vec![
                (2, 30, 100.0, Some(40.0), false),
                (3, 91, 300.0, Some(50.0), false),
                (7, 29, 70.0, Some(25.0), false),
            ]
        );
        assert_eq!(
            t.notes[2..],
            [
                "estimated reads joined to the actual read after them: lines 3, 4, 5 as one bill, 2021-02-04 to 2021-05-05".to_string(),
                "estimated reads not compared: line 6 (a gap follows); line 8 (no actual read after it)".to_string(),
            ],
            "{:?}",
            t.notes
        );
        s.estimated = EstimatedReads::Drop;
        let t = parse(text, &s).unwrap();
        let lines: Vec<u64> = t.bills.iter().map(|b| b.line).collect();
        assert_eq!(lines, vec![2, 5, 7]);
        assert_eq!(
            t.notes.last().unwrap(),
            "estimated reads not compared: line 3; line 4; line 6; line 8"
        );
        // Only estimated reads, nothing after them: refused, with the way out.
        let e = parse(
            "start,end,quantity,estimated\n2021-01-05,2021-02-03,100,E\n",
            &{
                let mut s = spec(Some("kWh"));
                s.estimated = EstimatedReads::Merge;
                s
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("estimated = \"fit\""), "{e}");
        // The spec's form.
        let s: BillSpec =
            toml::from_str("file = \"b.csv\"\nrole = \"heating\"\nestimated = \"drop\"\n").unwrap();
        assert_eq!(s.estimated, EstimatedReads::Drop);
    }

    #[test]
    fn a_bill_covers_the_grid_hours_of_its_days() {
        let t = parse(
            "start,end,quantity\n2024-02-20,2024-03-05,1\n2021-12-20,2022-01-19,1\n2022-03-20,2022-04-10,1\n",
            &spec(Some("kWh")),
        )
        .unwrap();
        // 15 days across 29 February 2024: the grid has 14 of them.
        let leap = t.bills[2].hours(GridYear::calendar(2024)).unwrap();
        assert_eq!(leap.len(), 14 * 24);
        // A year from April 2021: a bill across the year end is whole, in time order (slots of
        // late December, then of January), and one past the year's end cannot be compared.
        let y = GridYear::starting(2021, 4).unwrap();
        let winter = t.bills[0].hours(y).unwrap();
        assert_eq!(winter.len(), 31 * 24);
        assert_eq!(winter[0], (CUM_DAYS[11] + 19) * 24);
        assert_eq!(winter[12 * 24], 0);
        assert_eq!(t.bills[1].hours(y), None);
        assert_eq!(
            t.bills[1].hours(GridYear::calendar(2022)).map(|h| h.len()),
            Some(22 * 24)
        );
    }

    #[test]
    fn a_bills_total_needs_every_day() {
        let t = parse(
            "start,end,quantity\n2024-02-20,2024-03-05,1\n2024-03-06,2024-03-10,1\n",
            &spec(Some("kWh")),
        )
        .unwrap();
        let daily =
            |d: NaiveDate| (d < NaiveDate::from_ymd_opt(2024, 3, 8).unwrap()).then_some(2.0);
        // 15 days less 29 February; the second bill lacks 8 to 10 March.
        assert_eq!(bill_totals(&t.bills, daily), vec![Some(28.0), None]);
    }

    #[test]
    fn gas_volumes_need_a_calorific_value() {
        let text = "start,end,quantity\n2021-01-05,2021-02-03,100\n";
        let e = parse(text, &spec(Some("ccf"))).unwrap_err().to_string();
        assert!(
            e.contains("bills.csv:2") && e.contains("calorific_value_kwh_per_m3"),
            "{e}"
        );
        let mut s = spec(Some("ccf"));
        s.calorific_value_kwh_per_m3 = Some(10.5);
        let t = parse(text, &s).unwrap();
        // 100 ccf = 283.17 m3 = 2,973.3 kWh at 10.5 kWh/m3.
        assert!(
            (t.bills[0].kwh - 2973.27).abs() < 0.01,
            "{}",
            t.bills[0].kwh
        );
        let e = parse(text, &spec(Some("kW"))).unwrap_err().to_string();
        assert!(e.contains("power unit"), "{e}");
    }

    #[test]
    fn overlaps_are_refused_and_gaps_noted_with_their_lines() {
        let e = parse(
            "start,end,quantity\n2021-01-05,2021-02-03,1\n2021-02-01,2021-03-02,1\n",
            &spec(Some("kWh")),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("bills.csv:3") && e.contains("overlaps the bill of line 2"),
            "{e}"
        );
        let t = parse(
            "start,end,quantity\n2021-01-05,2021-02-03,1\n2021-02-10,2021-03-02,1\n",
            &spec(Some("kWh")),
        )
        .unwrap();
        assert_eq!(
            t.notes,
            vec![
                "no bill covers 2021-02-04 to 2021-02-09 (6 days, between lines 2 and 3)"
                    .to_string()
            ]
        );
        // Read dates (exclusive ends): each bill ends where the next starts, no gap.
        let mut s = spec(Some("kWh"));
        s.end = BillEnd::Exclusive;
        let t = parse(
            "start,end,quantity\n2021-01-05,2021-02-04,1\n2021-02-04,2021-03-05,1\n",
            &s,
        )
        .unwrap();
        assert!(t.notes.is_empty() && t.bills[0].days() == 30);
    }

    #[test]
    fn bad_fields_name_line_and_column() {
        let cases = [
            ("2021-13-05,2021-02-03,1", "column 'start'", "not a date"),
            (
                "2021-01-05,2021-01-03,1",
                "column 'end'",
                "before it starts",
            ),
            ("2021-01-05,2021-02-03,-4", "column 'quantity'", "0 or more"),
            (
                "2021-01-05,2021-02-03,lots",
                "column 'quantity'",
                "not a number",
            ),
        ];
        for (row, column, what) in cases {
            let e = parse(&format!("start,end,quantity\n{row}\n"), &spec(Some("kWh")))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("bills.csv:2") && e.contains(column) && e.contains(what),
                "{row}: {e}"
            );
        }
        let e = parse("from,to,usage\n", &spec(Some("kWh")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("no 'start' column"), "{e}");
    }
}
