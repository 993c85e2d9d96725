//! The readings on the hour grid: each row's reading converted to kWh and added to its slot
//! ([`values_on_grid`]), sub-hourly readings summed or averaged into hours, duplicates
//! resolved, and what did not fit counted in notes.

use std::collections::HashMap;
use std::path::Path;

use chrono::NaiveDateTime;

use super::{
    excerpt, infer_year, is_missing_token, row_err, DuplicatePolicy, GridYear, MeterColumn,
    MeterSpec, NegativePolicy, Row, Table, HOURS,
};
use crate::PrecalError;

/// The meters on the hour grid, and what did not fit on it.
pub(super) struct Grid {
    /// kWh per hour of each meter column (NaN = missing).
    pub(super) values: Vec<Vec<f64>>,
    /// The first line of each slot (0: no row).
    pub(super) slot_line: Vec<u64>,
    /// Rows outside the grid year, on its 29 February, and duplicates combined.
    pub(super) outside: usize,
    pub(super) feb29: usize,
    pub(super) dups: usize,
}

/// Pass 2: each row's readings in kWh on its slot; duplicates by `spec.duplicates`; sub-hourly
/// readings combined into hours (energy summed, power averaged, a partial hour scaled).
pub(super) fn values_on_grid(
    table: &Table,
    spec: &MeterSpec,
    year: GridYear,
    per_hour: u32,
    path: &Path,
    notes: &mut Vec<String>,
) -> Result<Grid, PrecalError> {
    let n = table.columns.len();
    let mut sums = vec![vec![f64::NAN; HOURS]; n];
    let mut counts = vec![vec![0u32; HOURS]; n];
    let mut slot_line = vec![0u64; HOURS];
    let mut stamp_line: HashMap<NaiveDateTime, u64> = HashMap::new();
    let (mut outside, mut feb29, mut dups) = (0usize, 0usize, 0usize);
    for r in &table.rows {
        let Some(t) = year.slot_of(r.clock) else {
            let date = r.clock.date();
            if bemcal_weather::grid::is_leap_day(date) && year.spans(date) {
                feb29 += 1;
            } else {
                outside += 1;
            }
            continue;
        };
        // A duplicate is a second row of the same hour, or, for sub-hourly meters whose hours
        // hold several readings, of the same stamp.
        let earlier = if per_hour > 1 {
            stamp_line.insert(r.clock, r.line)
        } else {
            Some(slot_line[t]).filter(|&l| l != 0)
        };
        if let Some(first) = earlier {
            dups += 1;
            if spec.duplicates == DuplicatePolicy::Error {
                let message = duplicate_message(r.clock, first, per_hour);
                return Err(row_err(path, r.line, &table.ts_name, message));
            }
            if per_hour > 1 {
                continue;
            }
        }
        if slot_line[t] == 0 {
            slot_line[t] = r.line;
        }
        let dup = per_hour == 1 && earlier.is_some();
        for (k, (col, idx)) in table.columns.iter().enumerate() {
            let v = reading_kwh(r, col, *idx, spec.negative, path)?;
            add_reading(
                (&mut sums[k][t], &mut counts[k][t]),
                v,
                per_hour,
                dup,
                spec.duplicates,
            );
        }
    }
    finish_hours(&mut sums, &counts, table, spec, per_hour, notes);
    Ok(Grid {
        values: sums,
        slot_line,
        outside,
        feb29,
        dups,
    })
}

/// The error of a duplicated reading (sub-hourly: the same stamp) or hour, at `clock`; `first`
/// is the line that had it first.
fn duplicate_message(clock: NaiveDateTime, first: u64, per_hour: u32) -> String {
    if per_hour > 1 {
        format!(
            "duplicate reading {clock} (standard time): line {first} has the same stamp; \
             set meters.duplicates = \"first\" to keep the first"
        )
    } else {
        format!(
            "duplicate hour {clock} (hour-beginning, standard time): line {first} has the same hour; \
             set meters.duplicates = \"first\" | \"last\" | \"mean\" | \"sum\" to accept"
        )
    }
}

/// One reading `v` (kWh, NaN = missing) into its slot's running `(sum, count)`: sub-hourly
/// readings accumulate; an hourly one sets the slot, or, when it repeats an hour (`dup`), is
/// combined by `policy`.
fn add_reading(
    (s, c): (&mut f64, &mut u32),
    v: f64,
    per_hour: u32,
    dup: bool,
    policy: DuplicatePolicy,
) {
    let accumulate = |s: &mut f64, c: &mut u32| {
        if v.is_finite() {
            *s = if *c == 0 { v } else { *s + v };
            *c += 1;
        }
    };
    if per_hour > 1 {
        return accumulate(s, c);
    }
    if !dup {
        *s = v;
        *c = u32::from(v.is_finite());
        return;
    }
    match policy {
        DuplicatePolicy::Error | DuplicatePolicy::First => {}
        DuplicatePolicy::Last => {
            *s = v;
            *c = u32::from(v.is_finite());
        }
        DuplicatePolicy::Mean | DuplicatePolicy::Sum => accumulate(s, c),
    }
}

/// The slots' sums made hours: sub-hourly energy readings scaled to the hour from those
/// present (power readings averaged), or duplicated hours averaged under `mean`.
fn finish_hours(
    sums: &mut [Vec<f64>],
    counts: &[Vec<u32>],
    table: &Table,
    spec: &MeterSpec,
    per_hour: u32,
    notes: &mut Vec<String>,
) {
    if per_hour > 1 {
        let mut partial = 0usize;
        for (k, (col, _)) in table.columns.iter().enumerate() {
            let scale = if col.unit.is_power() {
                1.0
            } else {
                per_hour as f64
            };
            for t in 0..HOURS {
                let c = counts[k][t];
                if c > 0 {
                    partial += usize::from(c < per_hour);
                    sums[k][t] = sums[k][t] / c as f64 * scale;
                }
            }
        }
        if partial > 0 {
            notes.push(format!(
                "{partial} meter-hours had fewer than {per_hour} readings (scaled from those present)"
            ));
        }
    } else if spec.duplicates == DuplicatePolicy::Mean {
        for (sum, count) in sums.iter_mut().zip(counts) {
            for (s, &c) in sum.iter_mut().zip(count) {
                if c > 1 {
                    *s /= c as f64;
                }
            }
        }
    }
}

/// The reading of meter column `col` (field `idx`) of row `r` in kWh: missing tokens are NaN,
/// text and non-finite numbers are errors, negative values follow `negative`.
fn reading_kwh(
    r: &Row,
    col: &MeterColumn,
    idx: usize,
    negative: NegativePolicy,
    path: &Path,
) -> Result<f64, PrecalError> {
    let err = |message: String| row_err(path, r.line, &col.column, message);
    let raw = r.record.get(idx).ok_or_else(|| {
        err(format!(
            "the row has {} fields and ends before this column (field {}): a \
             truncated row? (an empty cell is a missing reading)",
            r.record.len(),
            idx + 1
        ))
    })?;
    if is_missing_token(raw) {
        return Ok(f64::NAN);
    }
    let v: f64 = raw
        .parse()
        .map_err(|_| err(format!("value '{}' is not a number", excerpt(raw))))?;
    let v = if !v.is_finite() {
        return Err(err(format!(
            "value '{}' is not a finite number (an empty cell or NaN is a \
             missing reading)",
            excerpt(raw)
        )));
    } else if v < 0.0 {
        match negative {
            NegativePolicy::Error => {
                return Err(err(format!(
                    "negative value {v}; set meters.negative = \"missing\" | \"zero\" | \"keep\" to accept"
                )))
            }
            NegativePolicy::Missing => f64::NAN,
            NegativePolicy::Zero => 0.0,
            NegativePolicy::Keep => v,
        }
    } else {
        v
    };
    Ok(v * col.unit.to_kwh())
}

/// Notes of the rows left out: outside the grid year (naming the year their stamps fit when it
/// is another), on 29 February, duplicates combined.
pub(super) fn dropped_notes(
    grid: &Grid,
    rows: &[Row],
    year: GridYear,
    duplicates: DuplicatePolicy,
    notes: &mut Vec<String>,
) {
    if grid.outside > 0 {
        let fits = infer_year(rows.iter().filter(|r| !r.offset).map(|r| r.clock));
        let hint = if fits != year {
            format!(
                " (their stamps fit year = \"{fits}\", {} to {})",
                fits.first_date(),
                fits.last_date()
            )
        } else {
            String::new()
        };
        notes.push(format!(
            "{} rows outside {} to {} dropped{hint}",
            grid.outside,
            year.first_date(),
            year.last_date()
        ));
    }
    if grid.feb29 > 0 {
        notes.push(format!(
            "{} rows on 29 February dropped (the grid is a non-leap year)",
            grid.feb29
        ));
    }
    if grid.dups > 0 {
        notes.push(format!(
            "{} duplicate rows combined with policy {duplicates:?}",
            grid.dups
        ));
    }
}
