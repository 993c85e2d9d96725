//! A held-out period of a metered year: the hours that check a calibration and never fit it
//! (measurement and verification's reporting period beside its baseline period; CalTRACK /
//! OpenDSM, IPMVP Option D).
//!
//! Written as one string or a list of strings, each of which may hold several comma-separated
//! parts, their union:
//!
//! - `last 3 months`: the three calendar months that end with the last month (in time order)
//!   holding a measured hour;
//! - `2017-10` or `oct` / `october`: a calendar month;
//! - `2017-06-01..2017-08-31`: a range of dates, both ends included.
//!
//! Hours are the 8,760 hour-beginning slots of the grid year ([`crate::grid`]: in calendar
//! position from 1 January 00:00, without 29 February; a year from April holds January-March of
//! the next year).

use std::fmt;

use chrono::NaiveDate;

use crate::grid;
use serde::{Deserialize, Serialize};

/// One part of a held-out period.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HoldoutPart {
    /// The `n` calendar months that end with the last month holding a measured hour.
    LastMonths(u32),
    /// A calendar month (1-12), of the grid year or of the year given.
    Month {
        /// The year (`None`: the grid year's).
        year: Option<i32>,
        /// The month, 1..=12.
        month: u32,
    },
    /// Dates, both ends included.
    Dates(NaiveDate, NaiveDate),
}

/// A held-out period: the union of its parts.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(try_from = "HoldoutText", into = "HoldoutText")]
pub struct Holdout {
    /// The parts, in the order written.
    pub parts: Vec<HoldoutPart>,
    text: Vec<String>,
}

/// How a held-out period is written in a project: one string or a list of strings.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum HoldoutText {
    /// `holdout = "last 3 months"`.
    One(String),
    /// `holdout = ["jan", "2021-06-01..2021-06-30"]`.
    Many(Vec<String>),
}

impl TryFrom<HoldoutText> for Holdout {
    type Error = String;
    fn try_from(t: HoldoutText) -> Result<Holdout, String> {
        match t {
            HoldoutText::One(s) => s.parse(),
            HoldoutText::Many(v) => v.join(",").parse(),
        }
    }
}

impl From<Holdout> for HoldoutText {
    fn from(h: Holdout) -> HoldoutText {
        HoldoutText::Many(h.text)
    }
}

impl fmt::Display for Holdout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text.join(", "))
    }
}

const MONTHS: [&str; 12] = [
    "january",
    "february",
    "march",
    "april",
    "may",
    "june",
    "july",
    "august",
    "september",
    "october",
    "november",
    "december",
];

/// What a part may look like, for messages.
const SYNTAX: &str = "expected 'last N months', a month ('2017-10' or 'oct'), or dates \
                      ('2017-06-01..2017-08-31'), comma-separated";

impl std::str::FromStr for Holdout {
    type Err = String;
    fn from_str(s: &str) -> Result<Holdout, String> {
        let mut parts = vec![];
        let mut text = vec![];
        for raw in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            parts.push(parse_part(raw).map_err(|m| {
                format!(
                    "holdout '{}': {m}; {SYNTAX}",
                    bemcal_excerpt::excerpt(raw, 40)
                )
            })?);
            text.push(raw.to_string());
        }
        if parts.is_empty() {
            return Err(format!("holdout is empty; {SYNTAX}"));
        }
        Ok(Holdout { parts, text })
    }
}

fn parse_part(p: &str) -> Result<HoldoutPart, String> {
    let lower = p.to_ascii_lowercase();
    let words: Vec<&str> = lower.split_whitespace().collect();
    if let ["last", n, unit] = words.as_slice() {
        if !matches!(*unit, "month" | "months") {
            return Err(format!("unit '{unit}' is not months"));
        }
        let n: u32 = n.parse().map_err(|_| format!("'{n}' is not a number"))?;
        if !(1..=11).contains(&n) {
            return Err(format!(
                "{n} months: between 1 and 11 months can be held out"
            ));
        }
        return Ok(HoldoutPart::LastMonths(n));
    }
    if let Some((a, b)) = lower.split_once("..") {
        let date = |s: &str| {
            NaiveDate::parse_from_str(s.trim(), "%Y-%m-%d")
                .map_err(|_| format!("'{}' is not a date YYYY-MM-DD", s.trim()))
        };
        let (a, b) = (date(a)?, date(b)?);
        if b < a {
            return Err(format!("{b} is before {a}"));
        }
        return Ok(HoldoutPart::Dates(a, b));
    }
    if let Some((y, m)) = lower.split_once('-') {
        let year: i32 = y.parse().map_err(|_| format!("'{y}' is not a year"))?;
        let month: u32 = m.parse().map_err(|_| format!("'{m}' is not a month"))?;
        if !(1..=12).contains(&month) {
            return Err(format!("month {month} is not 1-12"));
        }
        return Ok(HoldoutPart::Month {
            year: Some(year),
            month,
        });
    }
    if lower.len() >= 3 {
        if let Some(i) = MONTHS.iter().position(|m| m.starts_with(lower.as_str())) {
            return Ok(HoldoutPart::Month {
                year: None,
                month: i as u32 + 1,
            });
        }
    }
    Err("not understood".into())
}

/// The calendar month (1-12) of each of the first `n` hour slots of the grid
/// ([`crate::grid`]).
pub fn months_of_hours(n: usize) -> Vec<u32> {
    (0..n).map(grid::slot_month).collect()
}

impl Holdout {
    /// Which of the `n` hour slots of `year` are held out; `measured(h)` tells whether hour `h`
    /// holds a measurement (for `last N months`, counted in time order). Errors when a part
    /// names a month or dates the grid year does not cover, or when the period holds out no
    /// measured hour or every one.
    pub fn hours(
        &self,
        year: grid::GridYear,
        n: usize,
        measured: &dyn Fn(usize) -> bool,
    ) -> Result<Vec<bool>, String> {
        let months = months_of_hours(n);
        let mut out = vec![false; n];
        for part in &self.parts {
            match *part {
                HoldoutPart::LastMonths(k) => {
                    let last = year
                        .chronological(n)
                        .filter(|&h| measured(h))
                        .last()
                        .ok_or_else(|| {
                            "holdout 'last months': the meters hold no measured hour".to_string()
                        })?;
                    let order: Vec<u32> = year.months().collect();
                    let end = order.iter().position(|&m| m == months[last]).unwrap_or(11);
                    let held = &order[(end + 1).saturating_sub(k as usize)..=end];
                    for (h, m) in months.iter().enumerate() {
                        out[h] |= held.contains(m);
                    }
                }
                HoldoutPart::Month { year: y, month } => {
                    if let Some(y) = y.filter(|&y| y != year.year_of_month(month)) {
                        return Err(format!(
                            "holdout {y}-{month:02}: the meters cover {}..{}",
                            year.first_date(),
                            year.last_date()
                        ));
                    }
                    for (h, m) in months.iter().enumerate() {
                        out[h] |= *m == month;
                    }
                }
                HoldoutPart::Dates(a, b) => {
                    if a < year.first_date() || b > year.last_date() {
                        return Err(format!(
                            "holdout {a}..{b}: the meters cover {}..{}",
                            year.first_date(),
                            year.last_date()
                        ));
                    }
                    for (h, o) in out.iter_mut().enumerate() {
                        let d = year.slot_time(h).date();
                        *o |= a <= d && d <= b;
                    }
                }
            }
        }
        let held = (0..n).filter(|&h| out[h] && measured(h)).count();
        let kept = (0..n).filter(|&h| !out[h] && measured(h)).count();
        if held == 0 {
            return Err(format!(
                "holdout '{self}' holds out no measured hour of {year}"
            ));
        }
        if kept == 0 {
            return Err(format!(
                "holdout '{self}' holds out every measured hour of {year}: nothing is left to calibrate with"
            ));
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(_: usize) -> bool {
        true
    }

    #[test]
    fn parses_each_form_and_their_union() {
        let h: Holdout = "last 3 months".parse().unwrap();
        assert_eq!(h.parts, vec![HoldoutPart::LastMonths(3)]);
        let h: Holdout = "2017-10, Nov,december".parse().unwrap();
        assert_eq!(
            h.parts,
            vec![
                HoldoutPart::Month {
                    year: Some(2017),
                    month: 10
                },
                HoldoutPart::Month {
                    year: None,
                    month: 11
                },
                HoldoutPart::Month {
                    year: None,
                    month: 12
                }
            ]
        );
        let h: Holdout = "2017-06-01..2017-08-31".parse().unwrap();
        assert_eq!(
            h.parts,
            vec![HoldoutPart::Dates(
                NaiveDate::from_ymd_opt(2017, 6, 1).unwrap(),
                NaiveDate::from_ymd_opt(2017, 8, 31).unwrap()
            )]
        );
        assert_eq!(h.to_string(), "2017-06-01..2017-08-31");
    }

    #[test]
    fn bad_parts_say_what_is_expected() {
        for (bad, why) in [
            ("", "empty"),
            ("last 3 weeks", "not months"),
            ("last 12 months", "between 1 and 11"),
            ("2017-13", "not 1-12"),
            ("2017-08-31..2017-06-01", "is before"),
            ("ma", "not understood"),
            ("2017-06-31..2017-07-01", "not a date"),
        ] {
            let e = bad.parse::<Holdout>().unwrap_err();
            assert!(e.contains(why), "{bad}: {e}");
            if !bad.is_empty() {
                assert!(e.contains("expected 'last N months'"), "{e}");
            }
        }
    }

    #[test]
    fn months_and_dates_select_their_hours() {
        let n = 8760;
        let h: Holdout = "oct,2017-11,2017-12-01..2017-12-31".parse().unwrap();
        let m = h.hours(2017.into(), n, &all).unwrap();
        // October 1 00:00 is day 273 of a non-leap year.
        assert_eq!(m.iter().position(|&x| x), Some(273 * 24));
        assert_eq!(m.iter().filter(|&&x| x).count(), (31 + 30 + 31) * 24);
        assert!(m[n - 1]);
        let e = "2016-10"
            .parse::<Holdout>()
            .unwrap()
            .hours(2017.into(), n, &all);
        assert!(e
            .unwrap_err()
            .contains("meters cover 2017-01-01..2017-12-31"));
    }

    #[test]
    fn a_leap_year_keeps_months_on_their_dates() {
        // 2020: 1 December is slot 334 * 24 on the grid, as in every year.
        let m = "dec"
            .parse::<Holdout>()
            .unwrap()
            .hours(2020.into(), 8760, &all)
            .unwrap();
        assert_eq!(m.iter().position(|&x| x), Some(334 * 24));
        assert_eq!(m.iter().filter(|&&x| x).count(), 31 * 24);
    }

    #[test]
    fn last_months_follow_the_last_measured_hour() {
        // Meters that end on 30 September: the last two months are August and September.
        let n = 8760;
        let end = (273 * 24) as usize;
        let h: Holdout = "last 2 months".parse().unwrap();
        let m = h.hours(2017.into(), n, &|i| i < end).unwrap();
        let first = m.iter().position(|&x| x).unwrap();
        assert_eq!(
            grid::GridYear::calendar(2017).slot_time(first).date(),
            NaiveDate::from_ymd_opt(2017, 8, 1).unwrap()
        );
        assert!(m[end - 1] && !m[first - 1]);
        // Nothing measured inside, or everything: errors.
        let none = "jan"
            .parse::<Holdout>()
            .unwrap()
            .hours(2017.into(), n, &|i| i > 24 * 40);
        assert!(none.unwrap_err().contains("no measured hour"));
        let every = "jan"
            .parse::<Holdout>()
            .unwrap()
            .hours(2017.into(), n, &|i| i < 24 * 31);
        assert!(every.unwrap_err().contains("every measured hour"));
    }

    #[test]
    fn a_year_from_april_holds_out_its_last_months_in_time_order() {
        let year: grid::GridYear = "2017-04".parse().unwrap();
        let n = 8760;
        // The last three months of April 2017 - March 2018 are January-March 2018.
        let m = "last 3 months"
            .parse::<Holdout>()
            .unwrap()
            .hours(year, n, &all)
            .unwrap();
        assert_eq!(m.iter().filter(|&&x| x).count(), (31 + 28 + 31) * 24);
        assert!(m[0] && m[90 * 24 - 1] && !m[90 * 24]);
        // Dates and months across the year end; a month of the wrong year is an error.
        let d = "2017-12-15..2018-01-14"
            .parse::<Holdout>()
            .unwrap()
            .hours(year, n, &all)
            .unwrap();
        assert_eq!(d.iter().filter(|&&x| x).count(), 31 * 24);
        assert!(d[0] && d[8759] && !d[14 * 24]);
        assert!("2018-02"
            .parse::<Holdout>()
            .unwrap()
            .hours(year, n, &all)
            .is_ok());
        let e = "2017-02"
            .parse::<Holdout>()
            .unwrap()
            .hours(year, n, &all)
            .unwrap_err();
        assert!(e.contains("meters cover 2017-04-01..2018-03-31"), "{e}");
    }

    #[test]
    fn a_project_writes_one_string_or_a_list() {
        #[derive(Deserialize)]
        struct V {
            holdout: Holdout,
        }
        let a: V = serde_json::from_str(r#"{"holdout": "last 3 months"}"#).unwrap();
        let b: V = serde_json::from_str(r#"{"holdout": ["oct", "nov"]}"#).unwrap();
        assert_eq!(a.holdout.parts, vec![HoldoutPart::LastMonths(3)]);
        assert_eq!(b.holdout.parts.len(), 2);
        assert!(serde_json::from_str::<V>(r#"{"holdout": "last 3 weeks"}"#).is_err());
    }
}
