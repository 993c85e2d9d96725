//! The calendar of a calibration year: day types (weekday, weekend, holiday, and the partial
//! days a building's meters show), holiday lists
//! (US federal, UK bank holidays, a listed file) and the day types the meters show
//! (pre-calibration's calendar file). Typical-year (TMY) weather files mix source years and so
//! carry no usable weekday: the calendar gives each date of the chosen year its day type.

use std::fmt;
use std::path::Path;

use chrono::{Datelike, NaiveDate, Weekday};
use serde::{Deserialize, Serialize};

use crate::{grid, Epw, WeatherError};

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
    /// A day of partial operation the meters show (a Saturday half-day, a term's quieter
    /// weeks): only from a day-type file (label `partial`), run on its own schedule.
    Partial,
}

impl DayType {
    /// The numeric code used as a surrogate input: weekday 0, weekend 1, holiday 2, and a
    /// partial day 0.5, between a working day and a day off.
    pub fn code(self) -> f64 {
        match self {
            DayType::Weekday => 0.0,
            DayType::Weekend => 1.0,
            DayType::Holiday => 2.0,
            DayType::Partial => 0.5,
        }
    }

    /// True for days that run the weekend schedule in the building model (weekends and holidays).
    pub fn is_off_day(self) -> bool {
        matches!(self, DayType::Weekend | DayType::Holiday)
    }
}

impl fmt::Display for DayType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DayType::Weekday => "weekday",
            DayType::Weekend => "weekend",
            DayType::Holiday => "holiday",
            DayType::Partial => "partial",
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
/// (`weekday`, `weekend` or `partial`, as pre-calibration's `calendar.csv` writes them from the
/// meters' day-type clusters); other labels (`skipped`) leave the date to the calendar's rule.
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
            "partial" => out.insert(date, DayType::Partial),
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

impl schemars::JsonSchema for Holidays {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "Holidays".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "Holidays, run on the weekend schedule: \"us_federal\", \"uk\" (England and Wales), \"none\", or a list of dates.",
            "oneOf": [
                {"type": "string", "enum": ["us_federal", "uk", "uk_england_wales", "none"]},
                {"type": "array", "items": {"type": "string", "format": "date"}}
            ]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
