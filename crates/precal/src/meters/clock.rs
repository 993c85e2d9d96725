//! The meter file's clock: timestamps parsed ([`parse_timestamp`]), the year they cover
//! ([`infer_year`]), the hour convention, and daylight saving undone (US rule or a time zone).
//! The rules are in the meters module's documentation.

use chrono::{Datelike, Duration, NaiveDate, NaiveDateTime, Offset, TimeZone, Timelike, Weekday};

use std::collections::HashMap;
use std::path::Path;

use super::{file_err, row_err, DstHandling, GridYear, HourConvention, Row, US_TIMESTAMP_FORMAT};
use crate::PrecalError;

/// Parses one timestamp. Returns the naive local time and whether it carried a UTC offset
/// (already converted with `std_offset_h`).
pub(super) fn parse_timestamp(
    s: &str,
    format: &str,
    std_offset_h: Option<f64>,
) -> Result<(NaiveDateTime, bool), String> {
    let s = s.trim();
    // 24:00 = midnight at the end of the day.
    let (text, plus_day) = match s.find("24:00") {
        Some(i) if i > 0 && matches!(s.as_bytes()[i - 1], b' ' | b'T') => {
            (format!("{}00:00{}", &s[..i], &s[i + 5..]), true)
        }
        _ => (s.to_string(), false),
    };
    if format.eq_ignore_ascii_case("auto") {
        return parse_timestamp(s, "iso8601", std_offset_h)
            .or_else(|_| parse_timestamp(s, US_TIMESTAMP_FORMAT, std_offset_h))
            .map_err(|_| {
                format!(
                    "timestamp '{s}' is neither ISO 8601 (2011-01-13T05:00) nor {US_TIMESTAMP_FORMAT} (01/13/2011 05:00); set timestamp_format"
                )
            });
    }
    let mut offset = false;
    let dt = if format.eq_ignore_ascii_case("iso8601") || format.eq_ignore_ascii_case("iso") {
        if let Ok(dt) = chrono::DateTime::parse_from_rfc3339(&text) {
            let off = std_offset_h.ok_or_else(|| {
                format!(
                    "timestamp '{s}' has a UTC offset but the site's standard time zone is unknown"
                )
            })?;
            offset = true;
            dt.naive_utc() + Duration::minutes((off * 60.0).round() as i64)
        } else {
            const F: [&str; 5] = [
                "%Y-%m-%dT%H:%M:%S",
                "%Y-%m-%d %H:%M:%S",
                "%Y-%m-%dT%H:%M",
                "%Y-%m-%d %H:%M",
                "%Y-%m-%dT%H:%M:%S%.f",
            ];
            F.iter()
                .find_map(|f| NaiveDateTime::parse_from_str(&text, f).ok())
                .ok_or_else(|| format!("timestamp '{s}' is not ISO 8601 (e.g. 2011-01-13T05:00)"))?
        }
    } else {
        NaiveDateTime::parse_from_str(&text, format)
            .map_err(|e| format!("timestamp '{s}' does not match format '{format}': {e}"))?
    };
    Ok((if plus_day { dt + Duration::days(1) } else { dt }, offset))
}

/// US daylight saving (2007 rules) of a meters file: detected (`auto`: a spring hour absent or
/// an autumn hour repeated, in either year a grid year from another month touches) or named
/// (`us`); rows inside it (by their own year's dates) move back one hour.
pub(super) fn us_daylight_saving(
    rows: &mut [Row],
    dst: DstHandling,
    year: GridYear,
    per_hour: u32,
    notes: &mut Vec<String>,
) -> Result<(), String> {
    // The years whose months the grid covers: one, or two for a year from another month.
    let dst_days: Vec<(NaiveDate, NaiveDate)> = (year.first_year()..=year.year_of_month(1))
        .filter_map(us_dst_days)
        .collect();
    let dst = match dst {
        DstHandling::Auto if !dst_days.is_empty() => {
            let count = |d: NaiveDate, h: u32| {
                rows.iter()
                    .filter(|r| !r.offset && r.clock.date() == d && r.clock.hour() == h)
                    .count()
            };
            let skipped = dst_days.iter().any(|&(spring, _)| {
                year.spans(spring)
                    && count(spring, 2) == 0
                    && count(spring, 1) > 0
                    && count(spring, 3) > 0
            });
            let repeated = dst_days
                .iter()
                .any(|&(_, fall)| year.spans(fall) && count(fall, 1) > per_hour as usize);
            let us = skipped || repeated;
            notes.push(format!(
                "daylight saving detected: {} (spring 02:00 {}, autumn 01:00 {})",
                if us {
                    "US DST clock"
                } else {
                    "none (standard time)"
                },
                if skipped { "absent" } else { "not absent" },
                if repeated { "repeated" } else { "not repeated" }
            ));
            if us {
                DstHandling::Us
            } else {
                DstHandling::None
            }
        }
        DstHandling::Auto => DstHandling::None,
        d => d,
    };
    if dst == DstHandling::Us {
        if dst_days.is_empty() {
            return Err("no DST dates".to_string());
        }
        let mut seen_repeat = std::collections::HashSet::new();
        let mut moved = 0usize;
        for r in rows.iter_mut() {
            if r.offset {
                continue;
            }
            let Some((spring, fall)) = us_dst_days(r.clock.year()) else {
                continue;
            };
            let start = spring.and_hms_opt(3, 0, 0).expect("time");
            let end = fall.and_hms_opt(1, 0, 0).expect("time");
            let in_dst = if r.clock >= start && r.clock < end {
                true
            } else if r.clock >= end && r.clock < end + Duration::hours(1) {
                // First occurrence of a stamp in the repeated hour is still DST.
                seen_repeat.insert(r.clock)
            } else {
                false
            };
            if in_dst {
                r.clock -= Duration::hours(1);
                moved += 1;
            }
        }
        notes.push(format!(
            "{moved} rows inside daylight saving time moved back one hour to local standard time"
        ));
    }
    Ok(())
}

/// The grid year of meters with these timestamps: the calendar year when they lie in one;
/// twelve months from the first day of the first stamp's month when they fit in those
/// (meters exported for "the last 12 months" or a fiscal year); for a longer record, its
/// latest twelve whole months (as a baseline period is chosen in M&V: the twelve months
/// before the end of the data), or, when it holds no twelve whole months, the calendar year
/// holding most stamps. Stamps are clock times, before daylight saving is undone.
pub fn infer_year(stamps: impl Iterator<Item = NaiveDateTime>) -> GridYear {
    let mut counts: HashMap<i32, usize> = HashMap::new();
    let (mut min, mut max) = (NaiveDateTime::MAX, NaiveDateTime::MIN);
    for t in stamps {
        *counts.entry(t.year()).or_default() += 1;
        min = min.min(t);
        max = max.max(t);
    }
    let most = counts
        .into_iter()
        .max_by_key(|&(y, n)| (n, -y))
        .map_or(min.year(), |(y, _)| y);
    if min.year() == max.year() {
        return GridYear::calendar(most);
    }
    // Two hours of slack: a daylight-saving clock runs an hour past the last standard hour,
    // and an hour-ending export's last stamp is midnight after its last day.
    let last = (max - Duration::hours(2)).date();
    match GridYear::starting(min.year(), min.month()) {
        Ok(w) if last <= w.last_date() => w,
        _ => latest_whole_year(min.date(), last).unwrap_or(GridYear::calendar(most)),
    }
}

/// The twelve whole months that end last in a record from `first` to `last` (dates): ending
/// with `last`'s month when `last` is its month's last day, else with the month before; `None`
/// when they would start before `first`.
fn latest_whole_year(first: NaiveDate, last: NaiveDate) -> Option<GridYear> {
    let month_ends = last.succ_opt().is_some_and(|d| d.day() == 1);
    let end = if month_ends {
        last
    } else {
        last.with_day(1)?.pred_opt()?
    };
    // The window starts on the first of the month after `end`'s, a year earlier.
    let next = end.succ_opt()?;
    let start = next.with_year(next.year() - 1)?;
    let w = GridYear::starting(start.year(), start.month()).ok()?;
    (w.first_date() >= first).then_some(w)
}

/// The standard UTC offset of `tz` in `year`: the smaller of its January and July offsets
/// (daylight saving adds time, in either hemisphere).
fn standard_offset(tz: chrono_tz::Tz, year: i32) -> Duration {
    let at = |m: u32| {
        let t = NaiveDate::from_ymd_opt(year, m, 1)
            .and_then(|d| d.and_hms_opt(12, 0, 0))
            .expect("valid date");
        Duration::seconds(i64::from(
            tz.offset_from_utc_datetime(&t).fix().local_minus_utc(),
        ))
    };
    at(1).min(at(7))
}

/// US DST start/end (clock, hour-beginning): second Sunday of March 02:00 (absent hour), first
/// Sunday of November 01:00 (repeated hour).
pub(super) fn us_dst_days(year: i32) -> Option<(NaiveDate, NaiveDate)> {
    Some((
        NaiveDate::from_weekday_of_month_opt(year, 3, Weekday::Sun, 2)?,
        NaiveDate::from_weekday_of_month_opt(year, 11, Weekday::Sun, 1)?,
    ))
}

/// The hour convention: as given, or (`auto`) hour-ending when a `24:00` stamp occurs or the
/// stamps run from one interval after midnight on the first of a month (or to midnight on the
/// first of a month, a year on); the decision is noted.
pub(super) fn hour_convention(
    given: HourConvention,
    rows: &[Row],
    interval_min: u32,
    saw_24: bool,
    notes: &mut Vec<String>,
) -> HourConvention {
    if given != HourConvention::Auto {
        return given;
    }
    let min = rows.iter().map(|r| r.clock).min().expect("rows");
    let max = rows.iter().map(|r| r.clock).max().expect("rows");
    // A year (calendar or from another month) of hour-ending stamps starts one interval
    // after midnight on the first of a month and ends at midnight on the first of one.
    let first_of_month = |t: NaiveDateTime, m: u32| t.day() == 1 && t.hour() * 60 + t.minute() == m;
    let ending = saw_24
        || first_of_month(min, interval_min)
        || (first_of_month(max, 0) && max - min >= Duration::days(360));
    notes.push(format!(
        "hour convention detected: {} (earliest stamp {min}, latest {max})",
        if ending {
            "hour-ending"
        } else {
            "hour-beginning"
        }
    ));
    if ending {
        HourConvention::HourEnding
    } else {
        HourConvention::HourBeginning
    }
}

/// Daylight saving by an IANA zone's rules (`meters.time_zone`): each row's clock time to UTC
/// and on to the zone's standard time (`TimeBasis::to_utc`, as for a weather station's CSV: in
/// the hour repeated when clocks go back, daylight time until the rows have passed it).
#[allow(clippy::too_many_arguments)]
pub(super) fn zone_daylight_saving(
    rows: &mut [Row],
    name: &str,
    dst: DstHandling,
    year: GridYear,
    std_offset_h: Option<f64>,
    path: &Path,
    ts_name: &str,
    notes: &mut Vec<String>,
) -> Result<(), PrecalError> {
    if dst != DstHandling::Auto {
        return Err(file_err(
            path,
            format!(
                "meters.time_zone = \"{name}\" gives the daylight saving rules: leave meters.dst \
                 out (it is {dst:?})"
            ),
        ));
    }
    let tz: chrono_tz::Tz = name.parse().map_err(|_| {
        file_err(
            path,
            format!(
                "meters.time_zone = \"{name}\": not an IANA time zone (e.g. \"Europe/Berlin\", \
                 \"America/Chicago\")"
            ),
        )
    })?;
    let standard = standard_offset(tz, year.first_year());
    let zone_h = standard.num_minutes() as f64 / 60.0;
    if let Some(site_h) = std_offset_h.filter(|h| (h - zone_h).abs() > 1e-6) {
        return Err(file_err(
            path,
            format!(
                "meters.time_zone = \"{name}\" keeps standard time UTC{zone_h:+.1} h, but the \
                 weather file's site is at UTC{site_h:+.1} h: meters and weather must be one place"
            ),
        ));
    }
    let basis = bemcal_weather::station::TimeBasis::Zone(tz);
    let mut previous = None;
    let mut moved = 0usize;
    for r in rows.iter_mut() {
        if r.offset {
            continue;
        }
        let utc = basis.to_utc(r.clock, zone_h, previous).ok_or_else(|| {
            row_err(
                path,
                r.line,
                ts_name,
                format!(
                    "{}: no such clock time in {name} (the hour skipped when clocks go \
                     forward)",
                    r.clock
                ),
            )
        })?;
        previous = Some(utc);
        let lst = utc + standard;
        moved += usize::from(lst != r.clock);
        r.clock = lst;
    }
    notes.push(format!(
        "time zone {name}: standard time UTC{zone_h:+.1} h; {moved} rows in daylight saving \
         time moved back to local standard time"
    ));
    Ok(())
}
