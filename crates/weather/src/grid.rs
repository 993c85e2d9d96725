//! The hour grid every hourly series inside bemcal lives on: 8,760 hour-beginning slots of local
//! standard time in calendar position from 1 January 00:00, without 29 February (as EPW files
//! and EnergyPlus's output files), so that slot `t` is the same month, day and hour in every
//! year; a [`GridYear`] says which year each month's dates belong to.

use std::fmt;
use std::str::FromStr;

use chrono::{Datelike, NaiveDate, NaiveDateTime, Timelike};
use serde::{Deserialize, Serialize};

/// Days before each month, and 365, in a year without 29 February.
pub const CUM_DAYS: [usize; 13] = [0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334, 365];

/// The twelve months an hour grid covers: a calendar year (`2017`) or a year that starts on the
/// first day of another month (`2017-04`: 1 April 2017 to 31 March 2018, as meters exported for
/// "the last 12 months" or a fiscal year are).
///
/// Slots keep their calendar position (slot `t` is always the same month, day and hour, in the
/// order of EPW files and of EnergyPlus's output files, which list the hours of a run period
/// that crosses a year end by month and day); the grid year says which year each month's dates
/// fall in: months before `first_month` belong to the next year. [`GridYear::chronological`]
/// gives the slots in time order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "YearText", into = "YearText")]
pub struct GridYear {
    year: i32,
    first_month: u32,
}

impl GridYear {
    /// The calendar year `year`.
    pub const fn calendar(year: i32) -> GridYear {
        GridYear {
            year,
            first_month: 1,
        }
    }

    /// Twelve months from the first day of `first_month` (1..=12) of `year`.
    pub fn starting(year: i32, first_month: u32) -> Result<GridYear, String> {
        if !(1..=12).contains(&first_month) {
            return Err(format!("month {first_month}: expected 1..=12"));
        }
        Ok(GridYear { year, first_month })
    }

    /// The year of the first month.
    pub fn first_year(self) -> i32 {
        self.year
    }

    /// The month (1..=12) the grid year starts with.
    pub fn first_month(self) -> u32 {
        self.first_month
    }

    /// True for a calendar year (starting in January).
    pub fn is_calendar(self) -> bool {
        self.first_month == 1
    }

    /// The year whose `month` (1..=12) the grid covers.
    pub fn year_of_month(self, month: u32) -> i32 {
        if month >= self.first_month {
            self.year
        } else {
            self.year + 1
        }
    }

    /// The first date covered.
    pub fn first_date(self) -> NaiveDate {
        NaiveDate::from_ymd_opt(self.year, self.first_month, 1).expect("a valid month")
    }

    /// The last date covered.
    pub fn last_date(self) -> NaiveDate {
        let next = NaiveDate::from_ymd_opt(self.year + 1, self.first_month, 1).expect("valid");
        next.pred_opt().expect("a date before")
    }

    /// True when `date` falls in the twelve months, 29 February included.
    pub fn spans(self, date: NaiveDate) -> bool {
        date >= self.first_date() && date <= self.last_date()
    }

    /// True when `date` is one of the grid's days (29 February never is).
    pub fn covers(self, date: NaiveDate) -> bool {
        self.spans(date) && !is_leap_day(date)
    }

    /// True when the twelve months include a 29 February (which the grid leaves out).
    pub fn spans_leap_day(self) -> bool {
        (self.year..=self.year + 1)
            .any(|y| NaiveDate::from_ymd_opt(y, 2, 29).is_some_and(|d| self.spans(d)))
    }

    /// Index of a (non-29-February) hour-beginning time of the grid year.
    pub fn slot_of(self, t: NaiveDateTime) -> Option<usize> {
        if !self.covers(t.date()) {
            return None;
        }
        let day = CUM_DAYS[t.month0() as usize] + t.day0() as usize;
        Some(day * 24 + t.hour() as usize)
    }

    /// Date of day `d` (0..365: calendar position, counted without 29 February).
    pub fn day_date(self, d: usize) -> NaiveDate {
        let m = CUM_DAYS.iter().rposition(|&c| c <= d).unwrap_or(0).min(11);
        let month = m as u32 + 1;
        NaiveDate::from_ymd_opt(
            self.year_of_month(month),
            month,
            (d - CUM_DAYS[m]) as u32 + 1,
        )
        .expect("valid day of year")
    }

    /// Hour-beginning local standard time of slot `t`.
    pub fn slot_time(self, t: usize) -> NaiveDateTime {
        self.day_date(t / 24)
            .and_hms_opt((t % 24) as u32, 0, 0)
            .expect("valid hour")
    }

    /// The `n` slots (a multiple of 24, at most 8,760) in time order: from the first month to
    /// December, then January to the month before the first.
    pub fn chronological(self, n: usize) -> impl Iterator<Item = usize> {
        let first = (CUM_DAYS[self.first_month as usize - 1] * 24).min(n);
        (first..n).chain(0..first)
    }

    /// The months (1..=12) in time order.
    pub fn months(self) -> impl Iterator<Item = u32> {
        (0..12).map(move |k| (self.first_month - 1 + k) % 12 + 1)
    }
}

impl From<i32> for GridYear {
    fn from(year: i32) -> GridYear {
        GridYear::calendar(year)
    }
}

/// `2017` for a calendar year, `2017-04` for twelve months from April 2017.
impl fmt::Display for GridYear {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_calendar() {
            write!(f, "{}", self.year)
        } else {
            write!(f, "{}-{:02}", self.year, self.first_month)
        }
    }
}

impl FromStr for GridYear {
    type Err = String;
    fn from_str(s: &str) -> Result<GridYear, String> {
        let s = s.trim();
        let bad = || {
            format!(
                "'{}' is not a year: expected YYYY (a calendar year) or YYYY-MM (twelve months from that month)",
                bemcal_excerpt::excerpt(s, 20)
            )
        };
        let (y, m) = match s.split_once('-') {
            Some((y, m)) => (y, Some(m)),
            None => (s, None),
        };
        let year: i32 = y.parse().map_err(|_| bad())?;
        match m {
            None => Ok(GridYear::calendar(year)),
            Some(m) => {
                let month: u32 = m.parse().map_err(|_| bad())?;
                GridYear::starting(year, month).map_err(|e| format!("{}: {e}", bad()))
            }
        }
    }
}

/// A grid year as written in files: a number (`2017`) or text (`"2017-04"`).
#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum YearText {
    Number(i32),
    Text(String),
}

impl TryFrom<YearText> for GridYear {
    type Error = String;
    fn try_from(y: YearText) -> Result<GridYear, String> {
        match y {
            YearText::Number(y) => Ok(GridYear::calendar(y)),
            YearText::Text(s) => s.parse(),
        }
    }
}

impl From<GridYear> for YearText {
    fn from(y: GridYear) -> YearText {
        if y.is_calendar() {
            YearText::Number(y.year)
        } else {
            YearText::Text(y.to_string())
        }
    }
}

/// True for 29 February.
pub fn is_leap_day(date: NaiveDate) -> bool {
    date.month() == 2 && date.day() == 29
}

/// A day of the week as EPW headers and EnergyPlus's run periods spell it.
pub fn weekday_name(d: chrono::Weekday) -> &'static str {
    use chrono::Weekday::*;
    match d {
        Mon => "Monday",
        Tue => "Tuesday",
        Wed => "Wednesday",
        Thu => "Thursday",
        Fri => "Friday",
        Sat => "Saturday",
        Sun => "Sunday",
    }
}

/// Month (1..=12) of slot `t`.
pub fn slot_month(t: usize) -> u32 {
    let d = t / 24;
    CUM_DAYS.iter().rposition(|&c| c <= d).unwrap_or(0).min(11) as u32 + 1
}

impl schemars::JsonSchema for GridYear {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "GridYear".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "The twelve months simulated: a calendar year (2017) or twelve months from the first of another month (\"2017-04\").",
            "oneOf": [
                {"type": "integer", "minimum": 1900, "maximum": 2100},
                {"type": "string", "pattern": "^[0-9]{4}-(0[1-9]|1[0-2])$"}
            ]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn date(y: i32, m: u32, d: u32) -> NaiveDate {
        NaiveDate::from_ymd_opt(y, m, d).unwrap()
    }

    #[test]
    fn a_leap_year_skips_29_february() {
        let y = GridYear::calendar(2020);
        // Slot 59 * 24 is 1 March in every year, 2020 included.
        assert_eq!(y.slot_time(59 * 24).date(), date(2020, 3, 1));
        assert_eq!(y.slot_time(8759).date(), date(2020, 12, 31));
        assert_eq!(slot_month(8759), 12);
        assert_eq!(
            y.slot_of(date(2020, 2, 29).and_hms_opt(5, 0, 0).unwrap()),
            None
        );
        assert!(y.spans_leap_day() && !GridYear::calendar(2021).spans_leap_day());
        let y = GridYear::calendar(2021);
        assert_eq!(y.slot_of(y.slot_time(4321)), Some(4321));
    }

    #[test]
    fn a_year_from_april_keeps_calendar_slots_with_next_year_dates() {
        let y: GridYear = "2019-04".parse().unwrap();
        assert_eq!(
            (y.first_date(), y.last_date()),
            (date(2019, 4, 1), date(2020, 3, 31))
        );
        assert!(y.spans_leap_day());
        // January-March are of 2020, April-December of 2019, in their calendar slots.
        assert_eq!(
            y.slot_time(0),
            date(2020, 1, 1).and_hms_opt(0, 0, 0).unwrap()
        );
        assert_eq!(y.day_date(CUM_DAYS[3]), date(2019, 4, 1));
        assert_eq!(
            y.slot_of(date(2019, 1, 5).and_hms_opt(0, 0, 0).unwrap()),
            None
        );
        assert_eq!(
            y.slot_of(date(2020, 1, 5).and_hms_opt(1, 0, 0).unwrap()),
            Some(4 * 24 + 1)
        );
        assert_eq!(
            y.slot_of(date(2020, 4, 1).and_hms_opt(0, 0, 0).unwrap()),
            None
        );
        for t in [0, 2159, 2160, 8759] {
            assert_eq!(y.slot_of(y.slot_time(t)), Some(t));
        }
        // In time order: April 2019 first, March 2020 last, every slot once.
        let order: Vec<usize> = y.chronological(8760).collect();
        assert_eq!(
            (order[0], order[8759]),
            (CUM_DAYS[3] * 24, CUM_DAYS[3] * 24 - 1)
        );
        let times: Vec<NaiveDateTime> = order.iter().map(|&t| y.slot_time(t)).collect();
        assert!(times.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(
            y.months().collect::<Vec<_>>(),
            [4, 5, 6, 7, 8, 9, 10, 11, 12, 1, 2, 3]
        );
        assert_eq!(
            GridYear::calendar(2021)
                .chronological(48)
                .collect::<Vec<_>>(),
            (0..48).collect::<Vec<_>>()
        );
    }

    #[test]
    fn grid_years_read_and_write_as_numbers_or_year_month() {
        assert_eq!("2017".parse::<GridYear>(), Ok(GridYear::calendar(2017)));
        assert_eq!(
            "2017-04".parse::<GridYear>().unwrap().to_string(),
            "2017-04"
        );
        assert_eq!("2017-01".parse::<GridYear>().unwrap().to_string(), "2017");
        for bad in ["2017-13", "2017-0", "April", "2017-04-01"] {
            let e = bad.parse::<GridYear>().unwrap_err();
            assert!(e.contains("expected YYYY"), "{bad}: {e}");
        }
        let json = |y: GridYear| serde_json::to_string(&y).unwrap();
        assert_eq!(json(GridYear::calendar(2017)), "2017");
        assert_eq!(json("2017-04".parse().unwrap()), "\"2017-04\"");
        let back: GridYear = serde_json::from_str("\"2017-04\"").unwrap();
        assert_eq!(back.first_month(), 4);
        assert_eq!(
            serde_json::from_str::<GridYear>("2017").unwrap(),
            GridYear::calendar(2017)
        );
    }
}
