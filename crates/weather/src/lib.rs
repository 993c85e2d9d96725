//! EnergyPlus weather (EPW) files: the hourly features the surrogate needs and the day-type
//! calendar.
//!
//! An EPW file has eight header lines (LOCATION, DESIGN CONDITIONS, ..., DATA PERIODS) and then
//! one comma-separated row of 35 fields per hour. [`Epw::read`] parses the fields bemcal uses and
//! reports malformed input with its file, line and field. [`Calendar`] turns the rows' month/day
//! into day types (weekday, weekend, holiday) for a chosen calendar year, because typical-year
//! (TMY) files mix source years and so carry no usable weekday.
#![deny(missing_docs)]

pub mod grid;
pub mod measured;
pub mod period;
pub mod solar;
pub mod station;

use std::fmt;
use std::path::{Path, PathBuf};

use chrono::{Datelike, NaiveDate, Weekday};
use serde::{Deserialize, Serialize};

use station::excerpt;

/// Hours in a non-leap year: the length of every EPW file bemcal accepts.
pub const HOURS_PER_YEAR: usize = 8760;

/// Errors from reading a weather file.
#[derive(Debug, thiserror::Error)]
pub enum WeatherError {
    /// The file could not be read at all.
    #[error("cannot read weather file {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A line or field is not what the EPW format requires.
    #[error("{path}:{line}: {}", bemcal_excerpt::shorten(.message))]
    Malformed {
        /// The file.
        path: PathBuf,
        /// The line at fault (1-based).
        line: usize,
        /// What was expected, with a short excerpt of what was found.
        message: String,
    },
}

/// Site information from the EPW `LOCATION` header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Location {
    /// The site's city (the header's field 2).
    pub city: String,
    /// Its state or province.
    pub state: String,
    /// Its country.
    pub country: String,
    /// Latitude, degrees north.
    pub latitude_deg: f64,
    /// Longitude, degrees east (west is negative).
    pub longitude_deg: f64,
    /// Hours from UTC (standard time).
    pub time_zone_h: f64,
    /// Elevation above sea level, m.
    pub elevation_m: f64,
}

impl Location {
    /// The `LOCATION` header, the first line of EPW text (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<Location, WeatherError> {
        let err = |message: String| WeatherError::Malformed {
            path: path.to_path_buf(),
            line: 1,
            message,
        };
        let first = text
            .lines()
            .next()
            .ok_or_else(|| err("empty file; expected an EPW LOCATION header".into()))?;
        let loc: Vec<&str> = first.split(',').map(str::trim).collect();
        if loc.first() != Some(&"LOCATION") || loc.len() < 10 {
            return Err(err(
                "expected 'LOCATION,city,state,country,source,WMO,lat,lon,tz,elevation'".into(),
            ));
        }
        let num = |i: usize, what: &str| -> Result<f64, WeatherError> {
            loc[i].parse::<f64>().map_err(|_| {
                err(format!(
                    "LOCATION {what} '{}' is not a number",
                    excerpt(loc[i])
                ))
            })
        };
        // Range checks: a time zone of 99 (a missing-value code) or a latitude of 400 would
        // otherwise shift every solar position and every meter's alignment without a word.
        let ranged = |i: usize, what: &str, lo: f64, hi: f64, unit: &str| {
            let v = num(i, what)?;
            if !(lo..=hi).contains(&v) {
                return Err(err(if v.is_finite() {
                    format!("LOCATION {what} {v} is outside {lo}..{hi:+} {unit}")
                } else {
                    format!("LOCATION {what} {v} is not a finite number")
                }));
            }
            Ok(v)
        };
        Ok(Location {
            city: loc[1].to_string(),
            state: loc[2].to_string(),
            country: loc[3].to_string(),
            latitude_deg: ranged(6, "latitude", -90.0, 90.0, "degrees")?,
            longitude_deg: ranged(7, "longitude", -180.0, 180.0, "degrees")?,
            time_zone_h: ranged(8, "time zone", -12.0, 14.0, "hours from UTC")?,
            elevation_m: ranged(9, "elevation", f64::MIN, f64::MAX, "m")?,
        })
    }
}

/// One hourly EPW record (the fields bemcal uses).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WeatherHour {
    /// Month, 1..=12.
    pub month: u32,
    /// Day of the month.
    pub day: u32,
    /// EPW hour, 1..=24, hour-ending: hour 1 covers 00:00-01:00.
    pub hour: u32,
    /// Dry-bulb air temperature, C.
    pub dry_bulb_c: f64,
    /// Dew-point temperature, C.
    pub dew_point_c: f64,
    /// Relative humidity, %.
    pub rel_humidity_pct: f64,
    /// Station atmospheric pressure, Pa.
    pub pressure_pa: f64,
    /// Global horizontal radiation, Wh/m2 over the hour.
    pub global_horizontal_wh_m2: f64,
    /// Direct normal radiation, Wh/m2 over the hour.
    pub direct_normal_wh_m2: f64,
    /// Diffuse horizontal radiation, Wh/m2 over the hour.
    pub diffuse_horizontal_wh_m2: f64,
    /// Wind direction, degrees clockwise from north (where it blows from).
    pub wind_direction_deg: f64,
    /// Wind speed, m/s.
    pub wind_speed_m_s: f64,
}

/// A parsed EPW file: its location and 8,760 hourly records in file order (Jan 1 hour 1 first).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Epw {
    /// The site, from the `LOCATION` header.
    pub location: Location,
    /// The 8,760 hourly records.
    pub hours: Vec<WeatherHour>,
}

impl Epw {
    /// Reads and validates an EPW file.
    pub fn read(path: impl AsRef<Path>) -> Result<Epw, WeatherError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| WeatherError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Epw::parse(&text, path)
    }

    /// Parses EPW text; `path` is used only in error messages.
    pub fn parse(text: &str, path: &Path) -> Result<Epw, WeatherError> {
        let err = |line: usize, message: String| WeatherError::Malformed {
            path: path.to_path_buf(),
            line,
            message,
        };
        let mut lines = text.lines().enumerate();
        let location = Location::parse(text, path)?;
        lines.next();
        // Skip the remaining header lines up to and including DATA PERIODS.
        let mut header_end = None;
        for (i, line) in lines.by_ref() {
            if line.starts_with("DATA PERIODS") {
                header_end = Some(i);
                break;
            }
        }
        if header_end.is_none() {
            return Err(err(
                2,
                "no 'DATA PERIODS' header line before the hourly data".into(),
            ));
        }
        let mut hours = Vec::with_capacity(HOURS_PER_YEAR);
        let mut seen: std::collections::HashMap<(u32, u32, u32), usize> =
            std::collections::HashMap::with_capacity(HOURS_PER_YEAR);
        for (i, line) in lines {
            let lineno = i + 1;
            if line.trim().is_empty() {
                continue;
            }
            let h = parse_hour(line, lineno, path)?;
            // A repeated month/day/hour means another hour is missing: every later row would
            // be simulated an hour off.
            if let Some(first) = seen.insert((h.month, h.day, h.hour), lineno) {
                return Err(err(
                    lineno,
                    format!(
                        "month {} day {} hour {} again: line {first} has the same hour \
                         (a duplicated hour; an EPW has each hour of the year once)",
                        h.month, h.day, h.hour
                    ),
                ));
            }
            hours.push(h);
        }
        if hours.len() != HOURS_PER_YEAR {
            return Err(err(
                text.lines().count(),
                format!(
                    "expected {HOURS_PER_YEAR} hourly rows (one non-leap year), found {}",
                    hours.len()
                ),
            ));
        }
        Ok(Epw { location, hours })
    }
}

/// One hourly row of an EPW (file line `lineno`): the fields bemcal reads, each a finite
/// number, month, day and hour in range, dry bulb and relative humidity plausible.
fn parse_hour(line: &str, lineno: usize, path: &Path) -> Result<WeatherHour, WeatherError> {
    let err = |line: usize, message: String| WeatherError::Malformed {
        path: path.to_path_buf(),
        line,
        message,
    };
    let f: Vec<&str> = line.split(',').collect();
    if f.len() < 22 {
        return Err(err(
            lineno,
            format!(
                "expected at least 22 comma-separated fields, found {}",
                f.len()
            ),
        ));
    }
    let field = |idx: usize, name: &str| -> Result<f64, WeatherError> {
        match f[idx].trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(err(
                lineno,
                format!(
                    "field {} ({name}) '{}' is not a finite number",
                    idx + 1,
                    excerpt(f[idx])
                ),
            )),
            Err(_) => Err(err(
                lineno,
                format!(
                    "field {} ({name}) '{}' is not a number",
                    idx + 1,
                    excerpt(f[idx])
                ),
            )),
        }
    };
    let int = |idx: usize, name: &str, lo: u32, hi: u32| -> Result<u32, WeatherError> {
        let v = f[idx].trim().parse::<u32>().map_err(|_| {
            err(
                lineno,
                format!(
                    "field {} ({name}) '{}' is not an integer",
                    idx + 1,
                    excerpt(f[idx])
                ),
            )
        })?;
        if v < lo || v > hi {
            return Err(err(
                lineno,
                format!("field {} ({name}) = {v}, expected {lo}..={hi}", idx + 1),
            ));
        }
        Ok(v)
    };
    let h = WeatherHour {
        month: int(1, "month", 1, 12)?,
        day: int(2, "day", 1, 31)?,
        hour: int(3, "hour", 1, 24)?,
        dry_bulb_c: field(6, "dry bulb temperature")?,
        dew_point_c: field(7, "dew point temperature")?,
        rel_humidity_pct: field(8, "relative humidity")?,
        pressure_pa: field(9, "atmospheric pressure")?,
        global_horizontal_wh_m2: field(13, "global horizontal radiation")?,
        direct_normal_wh_m2: field(14, "direct normal radiation")?,
        diffuse_horizontal_wh_m2: field(15, "diffuse horizontal radiation")?,
        wind_direction_deg: field(20, "wind direction")?,
        wind_speed_m_s: field(21, "wind speed")?,
    };
    if !(-90.0..=70.0).contains(&h.dry_bulb_c) {
        return Err(err(
            lineno,
            format!("dry bulb {} C is outside -90..70 C", h.dry_bulb_c),
        ));
    }
    if !(0.0..=110.0).contains(&h.rel_humidity_pct) {
        return Err(err(
            lineno,
            format!(
                "relative humidity {} % is outside 0..110 %",
                h.rel_humidity_pct
            ),
        ));
    }
    Ok(h)
}

/// The kind of day, as the surrogate and the schedules see it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DayType {
    /// A working day.
    Weekday,
    /// Saturday or Sunday (or a day the meters show as such).
    Weekend,
    /// A holiday of the calendar's list.
    Holiday,
}

impl DayType {
    /// The numeric code used as a surrogate input: weekday 0, weekend 1, holiday 2.
    pub fn code(self) -> f64 {
        match self {
            DayType::Weekday => 0.0,
            DayType::Weekend => 1.0,
            DayType::Holiday => 2.0,
        }
    }

    /// True for days that run the weekend schedule in the building model (weekends and holidays).
    pub fn is_off_day(self) -> bool {
        !matches!(self, DayType::Weekday)
    }
}

impl fmt::Display for DayType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DayType::Weekday => "weekday",
            DayType::Weekend => "weekend",
            DayType::Holiday => "holiday",
        })
    }
}

/// Which public holidays count as holidays.
///
/// In a building spec: `holidays = "us_federal"` (the default), `"uk"` (England and Wales bank
/// holidays), `"none"`, or a list of dates `["2017-01-02", "2017-04-14", ...]` (a school's
/// breaks, a company's closures); `holidays_file` names a file of dates ([`read_holiday_list`]).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Holidays {
    /// No holidays: every Monday-Friday is a weekday.
    None,
    /// The US federal holidays, with the observed-day rule (Saturday -> Friday, Sunday -> Monday).
    #[default]
    UsFederal,
    /// England and Wales bank holidays with their substitute days ([`uk_bank_holidays`]).
    UkEnglandWales,
    /// The listed dates.
    Dates(Vec<NaiveDate>),
}

impl Holidays {
    /// The holidays that fall in `year`.
    pub fn dates(&self, year: i32) -> Vec<NaiveDate> {
        match self {
            Holidays::None => vec![],
            Holidays::UsFederal => us_federal_holidays(year),
            Holidays::UkEnglandWales => uk_bank_holidays(year),
            Holidays::Dates(d) => d.iter().copied().filter(|d| d.year() == year).collect(),
        }
    }
}

#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum HolidaysRepr {
    Name(String),
    Dates(Vec<NaiveDate>),
}

impl Serialize for Holidays {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Holidays::None => s.serialize_str("none"),
            Holidays::UsFederal => s.serialize_str("us_federal"),
            Holidays::UkEnglandWales => s.serialize_str("uk"),
            Holidays::Dates(d) => d.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for Holidays {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Holidays, D::Error> {
        match HolidaysRepr::deserialize(d).map_err(|_| {
            serde::de::Error::custom(
                "holidays: expected \"us_federal\", \"uk\", \"none\" or a list of dates \"YYYY-MM-DD\"",
            )
        })? {
            HolidaysRepr::Dates(d) => Ok(Holidays::Dates(d)),
            HolidaysRepr::Name(n) => match n.as_str() {
                "none" => Ok(Holidays::None),
                "us_federal" => Ok(Holidays::UsFederal),
                "uk" | "uk_england_wales" => Ok(Holidays::UkEnglandWales),
                other => Err(serde::de::Error::custom(format!(
                    "holidays = \"{other}\": expected \"us_federal\", \"uk\", \"none\" or a list of dates"
                ))),
            },
        }
    }
}

/// Reads a day-type calendar: a CSV with a `date` column (`YYYY-MM-DD`) and a `label` column
/// (`weekday` or `weekend`, as pre-calibration's `calendar.csv` writes them from the meters'
/// day-type clusters); other labels (`skipped`) leave the date to the calendar's rule.
pub fn read_day_type_calendar(
    path: &Path,
) -> Result<std::collections::BTreeMap<NaiveDate, DayType>, WeatherError> {
    let text = std::fs::read_to_string(path).map_err(|source| WeatherError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let err = |line: usize, message: String| WeatherError::Malformed {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut reader = csv::Reader::from_reader(text.as_bytes());
    let headers = reader
        .headers()
        .map_err(|e| err(1, format!("cannot read the header: {e}")))?
        .clone();
    let col = |name: &str| {
        headers
            .iter()
            .position(|h| h.trim() == name)
            .ok_or_else(|| {
                err(
                    1,
                    format!("no '{name}' column (expected date and label, as in calendar.csv)"),
                )
            })
    };
    let (di, li) = (col("date")?, col("label")?);
    let mut out = std::collections::BTreeMap::new();
    for (i, record) in reader.records().enumerate() {
        let line = i + 2;
        let record = record.map_err(|e| err(line, e.to_string()))?;
        let raw = record.get(di).unwrap_or("").trim();
        let date = NaiveDate::parse_from_str(raw, "%Y-%m-%d").map_err(|_| {
            err(
                line,
                format!(
                    "date '{}' is not YYYY-MM-DD",
                    bemcal_excerpt::excerpt(raw, 30)
                ),
            )
        })?;
        match record.get(li).unwrap_or("").trim() {
            "weekday" => out.insert(date, DayType::Weekday),
            "weekend" => out.insert(date, DayType::Weekend),
            _ => None,
        };
    }
    Ok(out)
}

/// Reads a holiday list: one date `YYYY-MM-DD` per line, optionally followed by a comma and a
/// name; blank lines and lines starting with `#` are skipped, as is a header line `date,...`.
pub fn read_holiday_list(path: &Path) -> Result<Vec<NaiveDate>, WeatherError> {
    let text = std::fs::read_to_string(path).map_err(|source| WeatherError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut dates = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let field = line.split(',').next().unwrap_or("").trim();
        if field.is_empty()
            || field.starts_with('#')
            || (i == 0 && field.eq_ignore_ascii_case("date"))
        {
            continue;
        }
        let d =
            NaiveDate::parse_from_str(field, "%Y-%m-%d").map_err(|_| WeatherError::Malformed {
                path: path.to_path_buf(),
                line: i + 1,
                message: format!(
                    "'{}' is not a date: expected YYYY-MM-DD (optionally ',name')",
                    bemcal_excerpt::excerpt(field, 40)
                ),
            })?;
        dates.push(d);
    }
    dates.sort();
    dates.dedup();
    Ok(dates)
}

/// Maps the dates of one grid year ([`grid::GridYear`]: a calendar year or twelve months from
/// another month) to day types.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Calendar {
    /// The grid year its dates are in.
    pub year: grid::GridYear,
    /// Which dates are holidays.
    #[serde(default)]
    pub holidays: Holidays,
    /// Dates whose day type is known from the meters (pre-calibration's day-type clusters,
    /// `calendar.csv`): they override the weekday/weekend/holiday rule.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub observed: std::collections::BTreeMap<NaiveDate, DayType>,
}

impl Calendar {
    /// The calendar of `year` with `holidays` and no observed day types.
    pub fn new(year: impl Into<grid::GridYear>, holidays: Holidays) -> Calendar {
        Calendar {
            year: year.into(),
            holidays,
            observed: Default::default(),
        }
    }

    /// Day type of a month's day in this calendar's grid year (the year [`grid::GridYear`]
    /// gives the month); `None` for an impossible date (e.g. 2/30).
    pub fn day_type(&self, month: u32, day: u32) -> Option<DayType> {
        let date = NaiveDate::from_ymd_opt(self.year.year_of_month(month), month, day)?;
        if let Some(t) = self.observed.get(&date) {
            return Some(*t);
        }
        self.rule_day_type(date)
    }

    /// Day type of `date` by the weekday/weekend/holiday rule alone.
    pub fn rule_day_type(&self, date: NaiveDate) -> Option<DayType> {
        if self.is_holiday(date) {
            return Some(DayType::Holiday);
        }
        Some(match date.weekday() {
            Weekday::Sat | Weekday::Sun => DayType::Weekend,
            _ => DayType::Weekday,
        })
    }

    /// Day types for every hour of an EPW file.
    pub fn hourly_day_types(&self, epw: &Epw) -> Vec<DayType> {
        epw.hours
            .iter()
            .map(|h| self.day_type(h.month, h.day).unwrap_or(DayType::Weekday))
            .collect()
    }

    fn is_holiday(&self, date: NaiveDate) -> bool {
        // A holiday of the next year may be observed on 31 December (New Year's Day on a
        // Saturday).
        let y = date.year();
        self.holidays.dates(y).contains(&date) || self.holidays.dates(y + 1).contains(&date)
    }
}

/// US federal holidays of a year as observed (fixed-date holidays falling on a weekend move to
/// the nearest weekday).
pub fn us_federal_holidays(year: i32) -> Vec<NaiveDate> {
    let fixed = |m, d| observed(NaiveDate::from_ymd_opt(year, m, d).expect("valid date"));
    let nth = |m, wd, n| NaiveDate::from_weekday_of_month_opt(year, m, wd, n).expect("valid date");
    let last_monday_may = (1..=5)
        .rev()
        .find_map(|n| NaiveDate::from_weekday_of_month_opt(year, 5, Weekday::Mon, n))
        .expect("May has a Monday");
    vec![
        fixed(1, 1),
        nth(1, Weekday::Mon, 3),
        nth(2, Weekday::Mon, 3),
        last_monday_may,
        fixed(6, 19),
        fixed(7, 4),
        nth(9, Weekday::Mon, 1),
        nth(10, Weekday::Mon, 2),
        fixed(11, 11),
        nth(11, Weekday::Thu, 4),
        fixed(12, 25),
    ]
}

/// England and Wales bank holidays of a year (gov.uk): New Year's Day, Good Friday, Easter
/// Monday, the first and last Mondays of May, the last Monday of August, Christmas and Boxing
/// Day, with substitute weekdays when they fall on a weekend. One-off changes by proclamation
/// (2012, 2020, 2022, 2023) are not in the rule: list those years' dates instead.
pub fn uk_bank_holidays(year: i32) -> Vec<NaiveDate> {
    let date = |m, d| NaiveDate::from_ymd_opt(year, m, d).expect("valid date");
    let next_weekday = |d: NaiveDate| match d.weekday() {
        Weekday::Sat => d + chrono::Duration::days(2),
        Weekday::Sun => d + chrono::Duration::days(1),
        _ => d,
    };
    let last_monday = |m| {
        (1..=5)
            .rev()
            .find_map(|n| NaiveDate::from_weekday_of_month_opt(year, m, Weekday::Mon, n))
            .expect("a month has a Monday")
    };
    let easter = easter_sunday(year);
    let christmas = date(12, 25);
    // Christmas on a weekend moves to the 27th; Boxing Day then to the next free weekday.
    let (xmas, boxing) = match christmas.weekday() {
        Weekday::Fri => (christmas, date(12, 28)),
        Weekday::Sat => (date(12, 27), date(12, 28)),
        Weekday::Sun => (date(12, 27), date(12, 26)),
        _ => (christmas, date(12, 26)),
    };
    let mut days = vec![
        next_weekday(date(1, 1)),
        easter - chrono::Duration::days(2),
        easter + chrono::Duration::days(1),
        NaiveDate::from_weekday_of_month_opt(year, 5, Weekday::Mon, 1).expect("May has a Monday"),
        last_monday(5),
        last_monday(8),
        xmas,
        boxing,
    ];
    days.sort();
    days
}

/// Easter Sunday of the Gregorian calendar (the anonymous algorithm of 1876, as in Meeus,
/// *Astronomical Algorithms*, ch. 8).
pub fn easter_sunday(year: i32) -> NaiveDate {
    let a = year % 19;
    let b = year / 100;
    let c = year % 100;
    let d = b / 4;
    let e = b % 4;
    let f = (b + 8) / 25;
    let g = (b - f + 1) / 3;
    let h = (19 * a + b - d - g + 15) % 30;
    let i = c / 4;
    let k = c % 4;
    let l = (32 + 2 * e + 2 * i - h - k) % 7;
    let m = (a + 11 * h + 22 * l) / 451;
    let month = (h + l - 7 * m + 114) / 31;
    let day = (h + l - 7 * m + 114) % 31 + 1;
    NaiveDate::from_ymd_opt(year, month as u32, day as u32).expect("Easter is a date")
}

fn observed(d: NaiveDate) -> NaiveDate {
    match d.weekday() {
        Weekday::Sat => d.pred_opt().expect("date"),
        Weekday::Sun => d.succ_opt().expect("date"),
        _ => d,
    }
}

/// The hourly weather features the surrogate takes (the reference's five: dry bulb, humidity,
/// wind speed, solar radiation, day type), one value per hour of the year.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HourlyFeatures {
    /// Dry-bulb air temperature, C.
    pub dry_bulb_c: Vec<f64>,
    /// Relative humidity, %.
    pub rel_humidity_pct: Vec<f64>,
    /// Wind speed, m/s.
    pub wind_speed_m_s: Vec<f64>,
    /// Global horizontal radiation, Wh/m2.
    pub global_horizontal_wh_m2: Vec<f64>,
    /// The day type of the hour's date.
    pub day_type: Vec<DayType>,
}

impl HourlyFeatures {
    /// Names of the features in the order of [`HourlyFeatures::row`].
    pub const NAMES: [&'static str; 5] = [
        "dry_bulb_c",
        "rel_humidity_pct",
        "wind_speed_m_s",
        "global_horizontal_wh_m2",
        "day_type",
    ];

    /// Extracts the features from an EPW file with day types from `calendar`.
    pub fn from_epw(epw: &Epw, calendar: &Calendar) -> HourlyFeatures {
        HourlyFeatures {
            dry_bulb_c: epw.hours.iter().map(|h| h.dry_bulb_c).collect(),
            rel_humidity_pct: epw.hours.iter().map(|h| h.rel_humidity_pct).collect(),
            wind_speed_m_s: epw.hours.iter().map(|h| h.wind_speed_m_s).collect(),
            global_horizontal_wh_m2: epw
                .hours
                .iter()
                .map(|h| h.global_horizontal_wh_m2)
                .collect(),
            day_type: calendar.hourly_day_types(epw),
        }
    }

    /// A smooth synthetic year of `n` hours (seasonal dry bulb, daily humidity and sun, a
    /// weekly wind pattern, Saturdays and Sundays as weekends from hour 0 a Monday), for
    /// benchmarks that time the surrogate and need no real climate.
    pub fn synthetic(n: usize) -> HourlyFeatures {
        let tau = std::f64::consts::TAU;
        HourlyFeatures {
            dry_bulb_c: (0..n)
                .map(|t| 10.0 - 12.0 * (tau * t as f64 / 8760.0).cos())
                .collect(),
            rel_humidity_pct: (0..n)
                .map(|t| 60.0 + 20.0 * (tau * t as f64 / 24.0).cos())
                .collect(),
            wind_speed_m_s: (0..n).map(|t| 3.0 + (t % 7) as f64 * 0.3).collect(),
            global_horizontal_wh_m2: (0..n)
                .map(|t| (600.0 * (tau * ((t % 24) as f64 - 6.0) / 24.0).sin()).max(0.0))
                .collect(),
            day_type: (0..n)
                .map(|t| match (t / 24) % 7 {
                    5 | 6 => DayType::Weekend,
                    _ => DayType::Weekday,
                })
                .collect(),
        }
    }

    /// Number of hours.
    pub fn len(&self) -> usize {
        self.dry_bulb_c.len()
    }

    /// True when there are no hours.
    pub fn is_empty(&self) -> bool {
        self.dry_bulb_c.is_empty()
    }

    /// The five features of hour `t`, in [`HourlyFeatures::NAMES`] order.
    pub fn row(&self, t: usize) -> [f64; 5] {
        [
            self.dry_bulb_c[t],
            self.rel_humidity_pct[t],
            self.wind_speed_m_s[t],
            self.global_horizontal_wh_m2[t],
            self.day_type[t].code(),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn synthetic_year_has_weekends_and_its_cycles() {
        let f = HourlyFeatures::synthetic(8760);
        assert_eq!(f.len(), 8760);
        let day = |d: usize| f.day_type[d * 24 + 12];
        assert_eq!(
            (day(4), day(5), day(6), day(7)),
            (
                DayType::Weekday,
                DayType::Weekend,
                DayType::Weekend,
                DayType::Weekday
            )
        );
        assert!(f.dry_bulb_c[0] < -1.9 && f.dry_bulb_c[4380] > 21.9);
        assert_eq!(f.global_horizontal_wh_m2[0], 0.0);
        assert!(f.global_horizontal_wh_m2[12] > 599.0);
    }

    fn shared_epw(name: &str) -> Option<PathBuf> {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/epw")
            .join(name);
        p.exists().then_some(p)
    }

    #[test]
    fn reads_real_tmy3_file() {
        let Some(p) = shared_epw("USA_CO_Golden-NREL.724666_TMY3.epw") else {
            eprintln!("shared data not present; skipping");
            return;
        };
        let epw = Epw::read(&p).unwrap();
        assert_eq!(epw.hours.len(), HOURS_PER_YEAR);
        assert!((epw.location.latitude_deg - 39.74).abs() < 0.1);
        assert_eq!(epw.location.time_zone_h, -7.0);
        let (m, d, h) = (epw.hours[0].month, epw.hours[0].day, epw.hours[0].hour);
        assert_eq!((m, d, h), (1, 1, 1));
        let mean_t: f64 = epw.hours.iter().map(|h| h.dry_bulb_c).sum::<f64>() / 8760.0;
        assert!((5.0..15.0).contains(&mean_t), "Golden annual mean {mean_t}");
        let jul: f64 = epw.hours[4344..5088]
            .iter()
            .map(|h| h.dry_bulb_c)
            .sum::<f64>()
            / 744.0;
        assert!(jul > 18.0, "July mean {jul}");
    }

    /// A minimal valid EPW (constant weather, 2021's calendar, no leap day) as lines.
    fn tiny_epw_lines(time_zone: &str) -> Vec<String> {
        let mut lines = vec![
            format!("LOCATION,Golden,CO,USA,TMY3,724666,39.74,-105.18,{time_zone},1829.0"),
            "DESIGN CONDITIONS,0".into(),
            "TYPICAL/EXTREME PERIODS,0".into(),
            "GROUND TEMPERATURES,0".into(),
            "HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0".into(),
            "COMMENTS 1,synthetic".into(),
            "COMMENTS 2,synthetic".into(),
            "DATA PERIODS,1,1,Data,Friday, 1/ 1,12/31".into(),
        ];
        let mut day = NaiveDate::from_ymd_opt(2021, 1, 1).unwrap();
        while day.year() == 2021 {
            for hour in 1..=24 {
                lines.push(format!(
                    "2021,{},{},{hour},0,?,10.0,2.0,50,83000,0,0,300,0,0,0,0,0,0,0,180,3.0",
                    day.month(),
                    day.day()
                ));
            }
            day = day.succ_opt().unwrap();
        }
        lines
    }

    #[test]
    fn a_duplicated_hour_or_an_impossible_time_zone_is_refused_naming_the_line() {
        let lines = tiny_epw_lines("-7.0");
        let epw = Epw::parse(&lines.join("\n"), Path::new("x.epw")).unwrap();
        assert_eq!(epw.hours.len(), HOURS_PER_YEAR);

        // Hour 3 of January 2 (line 8 + 24 + 3 = 35) written as hour 2 again.
        let mut dup = lines.clone();
        assert!(dup[34].starts_with("2021,1,2,3,"), "{}", dup[34]);
        dup[34] = dup[34].replacen("2021,1,2,3,", "2021,1,2,2,", 1);
        let e = Epw::parse(&dup.join("\n"), Path::new("x.epw"))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "x.epw:35: month 1 day 2 hour 2 again: line 34 has the same hour \
             (a duplicated hour; an EPW has each hour of the year once)"
        );

        for (tz, what) in [
            ("99", "time zone 99 is outside -12..+14 hours from UTC"),
            (
                "-12.5",
                "time zone -12.5 is outside -12..+14 hours from UTC",
            ),
            ("inf", "time zone inf is not a finite number"),
        ] {
            let e = Epw::parse(&tiny_epw_lines(tz).join("\n"), Path::new("x.epw"))
                .unwrap_err()
                .to_string();
            assert_eq!(e, format!("x.epw:1: LOCATION {what}"));
        }
        for tz in ["-12", "14", "5.5", "-3.5"] {
            Epw::parse(&tiny_epw_lines(tz).join("\n"), Path::new("x.epw")).unwrap();
        }

        // A non-finite reading, and a long bad cell quoted as an excerpt.
        let mut bad = lines.clone();
        bad[20] = bad[20].replacen(",83000,", ",inf,", 1);
        let e = Epw::parse(&bad.join("\n"), Path::new("x.epw"))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "x.epw:21: field 10 (atmospheric pressure) 'inf' is not a finite number"
        );
        let mut bad = lines.clone();
        bad[20] = bad[20].replacen(",83000,", &format!(",{},", "9".repeat(5000) + "x"), 1);
        let e = Epw::parse(&bad.join("\n"), Path::new("x.epw"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("x.epw:21: field 10 (atmospheric pressure) '999"),
            "{e}"
        );
        assert!(
            e.len() < 200,
            "the message quotes an excerpt: {} bytes",
            e.len()
        );
    }

    #[test]
    fn malformed_row_names_line_and_field() {
        let Some(p) = shared_epw("USA_CO_Golden-NREL.724666_TMY3.epw") else {
            return;
        };
        let text = std::fs::read_to_string(&p).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let mut f: Vec<String> = lines[20].split(',').map(String::from).collect();
        f[6] = "warm".into();
        lines[20] = f.join(",");
        let e = Epw::parse(&lines.join("\n"), Path::new("x.epw")).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("x.epw:21:"), "{msg}");
        assert!(msg.contains("dry bulb"), "{msg}");
        let short: Vec<&str> = text.lines().take(100).collect();
        let short = short.join("\n");
        let e = Epw::parse(&short, Path::new("x.epw")).unwrap_err();
        assert!(e.to_string().contains("expected 8760 hourly rows"), "{e}");
    }

    #[test]
    fn easter_and_uk_bank_holidays_match_gov_uk() {
        let d = |y, m, d| NaiveDate::from_ymd_opt(y, m, d).unwrap();
        for (y, m, day) in [
            (2017, 4, 16),
            (2019, 4, 21),
            (2024, 3, 31),
            (2025, 4, 20),
            (2038, 4, 25),
        ] {
            assert_eq!(easter_sunday(y), d(y, m, day));
        }
        // gov.uk/bank-holidays, England and Wales. 2017: New Year's Day on a Sunday (substitute
        // Monday 2 January); 2021: Christmas on a Saturday, Boxing Day on a Sunday (27 and 28).
        let y2017 = [
            (1, 2),
            (4, 14),
            (4, 17),
            (5, 1),
            (5, 29),
            (8, 28),
            (12, 25),
            (12, 26),
        ];
        assert_eq!(
            uk_bank_holidays(2017),
            y2017.map(|(m, x)| d(2017, m, x)).to_vec()
        );
        let y2021 = [
            (1, 1),
            (4, 2),
            (4, 5),
            (5, 3),
            (5, 31),
            (8, 30),
            (12, 27),
            (12, 28),
        ];
        assert_eq!(
            uk_bank_holidays(2021),
            y2021.map(|(m, x)| d(2021, m, x)).to_vec()
        );
        // 2016: Christmas on a Sunday, Boxing Day on the Monday, Christmas substitute Tuesday 27.
        let y2016 = uk_bank_holidays(2016);
        assert!(y2016.contains(&d(2016, 12, 26)) && y2016.contains(&d(2016, 12, 27)));
        let cal = Calendar::new(2017, Holidays::UkEnglandWales);
        assert_eq!(cal.day_type(1, 2), Some(DayType::Holiday));
        assert_eq!(cal.day_type(7, 4), Some(DayType::Weekday));
    }

    #[test]
    fn holidays_in_a_spec_and_in_a_list_file() {
        #[derive(Deserialize)]
        struct Spec {
            holidays: Holidays,
        }
        let parse = |t: &str| serde_json::from_str::<Spec>(t).map(|s| s.holidays);
        assert_eq!(
            parse(r#"{"holidays": "uk"}"#).unwrap(),
            Holidays::UkEnglandWales
        );
        assert_eq!(parse(r#"{"holidays": "none"}"#).unwrap(), Holidays::None);
        let listed = parse(r#"{"holidays": ["2017-12-27", "2017-12-28"]}"#).unwrap();
        assert_eq!(listed.dates(2017).len(), 2);
        assert!(parse(r#"{"holidays": "mars"}"#)
            .unwrap_err()
            .to_string()
            .contains("us_federal"));
        let dir = std::env::temp_dir().join(format!("bemcal-holidays-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("h.csv");
        std::fs::write(
            &f,
            "date,name\n# school breaks\n2017-10-23,half term\n\n2017-10-24\n",
        )
        .unwrap();
        let dates = read_holiday_list(&f).unwrap();
        assert_eq!(dates.len(), 2);
        std::fs::write(&f, "2017-10-23\n23/10/2017\n").unwrap();
        let e = read_holiday_list(&f).unwrap_err().to_string();
        assert!(e.contains("h.csv:2:") && e.contains("YYYY-MM-DD"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn calendar_day_types() {
        let cal = Calendar::new(2021, Holidays::UsFederal);
        // 2021-01-01 was a Friday and New Year's Day.
        assert_eq!(cal.day_type(1, 1), Some(DayType::Holiday));
        assert_eq!(cal.day_type(1, 2), Some(DayType::Weekend));
        assert_eq!(cal.day_type(1, 4), Some(DayType::Weekday));
        // July 4 2021 was a Sunday: observed Monday July 5.
        assert_eq!(cal.day_type(7, 5), Some(DayType::Holiday));
        // Thanksgiving 2021: Nov 25.
        assert_eq!(cal.day_type(11, 25), Some(DayType::Holiday));
        let none = Calendar::new(2021, Holidays::None);
        let listed = Calendar::new(
            2021,
            Holidays::Dates(vec![NaiveDate::from_ymd_opt(2021, 3, 3).unwrap()]),
        );
        assert_eq!(listed.day_type(3, 3), Some(DayType::Holiday));
        assert_eq!(listed.day_type(1, 1), Some(DayType::Weekday));
        assert_eq!(none.day_type(1, 1), Some(DayType::Weekday));
        assert_eq!(cal.day_type(2, 30), None);
    }
}
