//! The hour grid every hourly series inside bemcal lives on: 8,760 hour-beginning slots of local
//! standard time from 1 January 00:00, without 29 February (as EPW files and EnergyPlus's annual
//! runs), so that slot `t` is the same date in every year.

use chrono::{Datelike, NaiveDate, NaiveDateTime, Timelike};

/// Days before each month, and 365, in a year without 29 February.
pub const CUM_DAYS: [usize; 13] = [0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334, 365];

/// Index of a (non-29-February) hour-beginning time of `year` on the 8,760-slot grid.
pub fn slot_of(year: i32, t: NaiveDateTime) -> Option<usize> {
    if t.year() != year || (t.month() == 2 && t.day() == 29) {
        return None;
    }
    let day = CUM_DAYS[t.month0() as usize] + t.day0() as usize;
    Some(day * 24 + t.hour() as usize)
}

/// Date of day `d` (0..365, counted without 29 February) of `year`.
pub fn day_date(year: i32, d: usize) -> NaiveDate {
    let m = CUM_DAYS.iter().rposition(|&c| c <= d).unwrap_or(0).min(11);
    NaiveDate::from_ymd_opt(year, m as u32 + 1, (d - CUM_DAYS[m]) as u32 + 1)
        .expect("valid day of year")
}

/// Hour-beginning local standard time of slot `t` of `year`.
pub fn slot_time(year: i32, t: usize) -> NaiveDateTime {
    day_date(year, t / 24)
        .and_hms_opt((t % 24) as u32, 0, 0)
        .expect("valid hour")
}

/// Month (1..=12) of slot `t`.
pub fn slot_month(t: usize) -> u32 {
    let d = t / 24;
    CUM_DAYS.iter().rposition(|&c| c <= d).unwrap_or(0).min(11) as u32 + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_leap_year_skips_29_february() {
        // Slot 59 * 24 is 1 March in every year, 2020 included.
        assert_eq!(
            slot_time(2020, 59 * 24).date(),
            NaiveDate::from_ymd_opt(2020, 3, 1).unwrap()
        );
        assert_eq!(
            slot_time(2020, 8759).date(),
            NaiveDate::from_ymd_opt(2020, 12, 31).unwrap()
        );
        assert_eq!(slot_month(8759), 12);
        let t = NaiveDate::from_ymd_opt(2020, 2, 29)
            .unwrap()
            .and_hms_opt(5, 0, 0)
            .unwrap();
        assert_eq!(slot_of(2020, t), None);
        assert_eq!(slot_of(2021, slot_time(2021, 4321)), Some(4321));
    }
}
