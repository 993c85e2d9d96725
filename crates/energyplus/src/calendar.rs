//! The calendar a model simulates, for both forms of model file: its year, holidays and observed
//! day types, and the EnergyPlus run period written from them.
//!
//! The calibration gives the surrogate each hour's day type from this calendar and reads the
//! meters onto its year, so EnergyPlus must simulate the same dates: bemcal writes the
//! `RunPeriod` and `RunPeriodControl:SpecialDays` itself, for a generated building and for a
//! user's IDF alike (whose own run periods and special days it replaces).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use bemcal_weather::grid::GridYear;
use bemcal_weather::{Calendar, DayType, Holidays};
use chrono::{Datelike, NaiveDate};

use crate::idf::Idf;
use crate::Error;

/// The year a model file simulates when it names none.
pub fn default_year() -> GridYear {
    GridYear::calendar(2021)
}

/// The calendar files a model file names (`holidays_file`, `day_types_file`, relative to the
/// model file), read: the holidays that replace the `holidays` key, and the observed day types.
/// `text` is the model file's text, for the line of a key at fault.
pub(crate) fn read_calendar_files(
    text: &str,
    path: &Path,
    holidays_file: Option<&PathBuf>,
    day_types_file: Option<&PathBuf>,
) -> Result<(Option<Holidays>, BTreeMap<NaiveDate, DayType>), Error> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let at = |key: &str, e: String| Error::Input {
        path: path.to_path_buf(),
        line: crate::toml_line(text, &[key]),
        message: format!("{key}: {e}"),
    };
    let holidays = holidays_file
        .map(|f| bemcal_weather::read_holiday_list(&dir.join(f)).map(Holidays::Dates))
        .transpose()
        .map_err(|e| at("holidays_file", e.to_string()))?;
    let observed = day_types_file
        .map(|f| bemcal_weather::read_day_type_calendar(&dir.join(f)))
        .transpose()
        .map_err(|e| at("day_types_file", e.to_string()))?
        .unwrap_or_default();
    Ok((holidays, observed))
}

/// Replaces `m`'s run periods and special days with those of `calendar`
/// ([`add_run_period`]); the user's other objects are kept as they are.
pub(crate) fn set_run_period(m: &mut Idf, calendar: &Calendar) {
    m.objects.retain(|o| {
        !o.class.eq_ignore_ascii_case("RunPeriod")
            && !o.class.eq_ignore_ascii_case("RunPeriodControl:SpecialDays")
    });
    add_run_period(m, calendar);
}

/// The run period of `calendar`'s year (across the year end for a year from another month) and
/// its special days (`RunPeriodControl:SpecialDays`).
///
/// EnergyPlus counts weekdays on from the run period's first day and simulates no 29 February
/// when the weather file has none, so after a leap day its weekdays run one day behind the real
/// calendar (1 March 2020, a Sunday, simulates as a Saturday). Each date's schedule is therefore
/// set against the weekday EnergyPlus will give it: a working day it counts as a weekend is
/// `CustomDay1` (the weekday schedule), an off day it counts as a weekday is a `Holiday` (the
/// weekend schedule), and a partial day is `CustomDay2` whatever its weekday (a generated
/// building's partial-day schedule; an own IDF's schedules run it on their `CustomDay2` lines, or
/// `AllOtherDays` where they have none).
pub(crate) fn add_run_period(m: &mut Idf, calendar: &Calendar) {
    let year = calendar.year;
    let (first, last) = (year.first_date(), year.last_date());
    m.add(
        "RunPeriod",
        &[
            "Year".to_string(),
            first.month().to_string(),
            first.day().to_string(),
            first.year().to_string(),
            last.month().to_string(),
            last.day().to_string(),
            last.year().to_string(),
            bemcal_weather::grid::weekday_name(first.weekday()).into(),
            "No".into(),
            "No".into(),
            "No".into(),
            "Yes".into(),
            "Yes".into(),
        ],
    );
    let mut special = 0;
    let simulated = first
        .iter_days()
        .take_while(|d| *d <= last)
        .filter(|d| year.covers(*d));
    for (k, date) in simulated.enumerate() {
        let t = calendar
            .day_type(date.month(), date.day())
            .expect("a date of the year");
        let energyplus_weekday = first.weekday().num_days_from_monday() as usize + k;
        let weekend = energyplus_weekday % 7 >= 5;
        let kind = match (t, t.is_off_day(), weekend) {
            (bemcal_weather::DayType::Partial, _, _) => "CustomDay2",
            (_, true, false) => "Holiday",
            (_, false, true) => "CustomDay1",
            _ => continue,
        };
        special += 1;
        m.add(
            "RunPeriodControl:SpecialDays",
            &[
                format!("Special Day {special}"),
                format!("{}/{}", date.month(), date.day()),
                "1".into(),
                kind.into(),
            ],
        );
    }
}
