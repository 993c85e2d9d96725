//! What pre-calibration tells the user to change in the model file about its calendar, with
//! the evidence: where the day-type clusters (labelled by what the days look like) disagree
//! with the calendar the model runs on, and where the clusters are too weak to say.
//!
//! Pure: the clusters in, suggestions out; [`crate::io`] prints them with the lines to paste.

use chrono::{Datelike, NaiveDate, Weekday};
use serde::{Deserialize, Serialize};

use bemcal_weather::DayType;

use crate::schedule::{DayLabel, DayRecord, DayTypeClusters, LabelRule};

/// A weekday name's days are "moved" (low on a calendar weekday, working on a weekend) when at
/// least this share of its clustered days are.
pub const MOVED_SHARE: f64 = 0.4;

/// ... and at least this many.
pub const MOVED_MIN_DAYS: usize = 4;

/// Silhouettes below this make the day types weak, whatever the labels.
pub const WEAK_SILHOUETTE: f64 = 0.5;

/// A line to paste into the model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "key", content = "value")]
pub enum Paste {
    /// `day_types_file = "<pre-calibration folder>/calendar.csv"`: every date runs the schedule
    /// of the day type its cluster shows.
    DayTypesFile,
    /// `holidays = "none"`.
    NoHolidays,
    /// `holidays = [...]`: only these dates are holidays.
    Holidays(Vec<NaiveDate>),
}

impl Paste {
    /// The model-file line, with the pre-calibration folder `dir` as the user named it.
    pub fn line(&self, dir: &str) -> String {
        match self {
            Paste::DayTypesFile => format!("day_types_file = \"{dir}/calendar.csv\""),
            Paste::NoHolidays => "holidays = \"none\"".into(),
            Paste::Holidays(d) => format!(
                "holidays = [{}]",
                d.iter()
                    .map(|d| format!("\"{d}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// One suggestion: what the meters show, and what to paste (if anything).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Suggestion {
    /// The evidence, in words.
    pub evidence: String,
    /// What to change in the model file (none: what it means, nothing to paste).
    pub paste: Option<Paste>,
}

/// The suggestions about the calendar, in the order to read them.
pub fn calendar_advice(c: &DayTypeClusters) -> Vec<Suggestion> {
    let mut out = weak(c);
    if c.label_rule == LabelRule::Calendar {
        // The labels are the calendar's own: nothing to set against it.
        return out;
    }
    let clustered: Vec<&DayRecord> = c.days.iter().filter(|d| d.label.is_some()).collect();
    let low_weekdays = moved(&clustered, DayLabel::Weekend, |d| {
        d.calendar == DayType::Weekday
    });
    if !low_weekdays.is_empty() {
        out.push(Suggestion {
            evidence: format!(
                "days off on calendar weekdays: {}: the building's days off are not Saturday and Sunday",
                low_weekdays.join(", ")
            ),
            paste: Some(Paste::DayTypesFile),
        });
    }
    let worked_weekends = moved(&clustered, DayLabel::Weekday, |d| {
        d.calendar == DayType::Weekend
    });
    if !worked_weekends.is_empty() {
        out.push(Suggestion {
            evidence: format!(
                "working days on calendar weekends: {}",
                worked_weekends.join(", ")
            ),
            paste: Some(Paste::DayTypesFile),
        });
    }
    out.extend(holidays(&clustered));
    out
}

/// Where the clusters are too weak to trust: the rule fell back to the calendar, or the
/// silhouette is low.
fn weak(c: &DayTypeClusters) -> Vec<Suggestion> {
    let listed = |v: &[f64]| {
        v.iter()
            .map(|r| format!("{r:.2}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let (levels, rises) = (listed(&c.cluster_levels), listed(&c.cluster_rises));
    let s = c.clustering.silhouette;
    let why = match (c.label_rule, s < WEAK_SILHOUETTE) {
        (LabelRule::Calendar, _) => format!(
            "the clusters' levels ({levels}) and daytime rises ({rises}, of the year's peak) do not separate working days from days off"
        ),
        (LabelRule::Profile, true) => format!("the clusters overlap (silhouette {s:.2})"),
        (LabelRule::Profile, false) => return vec![],
    };
    vec![Suggestion {
        evidence: format!(
            "weak day types: {why}, so the labels follow the calendar's majority and the schedule \
             priors pool unlike days: widen them, or keep the model's default schedule priors (remove \
             the schedule_* entries from priors.toml) unless the building has a weekly pattern"
        ),
        paste: None,
    }]
}

/// Per weekday name, the calendar days `of_kind` whose cluster is labelled `label`, where they
/// are at least [`MOVED_SHARE`] of that weekday's clustered days of that kind and at least
/// [`MOVED_MIN_DAYS`]: `"Thursday 50 of 52"`.
fn moved(
    days: &[&DayRecord],
    label: DayLabel,
    of_kind: impl Fn(&DayRecord) -> bool,
) -> Vec<String> {
    let mut out = vec![];
    for wd in [
        Weekday::Mon,
        Weekday::Tue,
        Weekday::Wed,
        Weekday::Thu,
        Weekday::Fri,
        Weekday::Sat,
        Weekday::Sun,
    ] {
        let these: Vec<_> = days
            .iter()
            .filter(|d| d.date.weekday() == wd && of_kind(d))
            .collect();
        let n = these.iter().filter(|d| d.label == Some(label)).count();
        if n >= MOVED_MIN_DAYS && n as f64 >= MOVED_SHARE * these.len() as f64 {
            out.push(format!("{} {n} of {}", weekday_name(wd), these.len()));
        }
    }
    out
}

/// Calendar holidays the building works: where at least half of them look like working days,
/// `holidays = "none"` (all of them) or the list of those that look like days off.
fn holidays(days: &[&DayRecord]) -> Option<Suggestion> {
    let hol: Vec<&&DayRecord> = days
        .iter()
        .filter(|d| d.calendar == DayType::Holiday)
        .collect();
    let worked: Vec<NaiveDate> = hol
        .iter()
        .filter(|d| d.label == Some(DayLabel::Weekday))
        .map(|d| d.date)
        .collect();
    if hol.len() < 3 || 2 * worked.len() < hol.len() {
        return None;
    }
    let off: Vec<NaiveDate> = hol
        .iter()
        .filter(|d| d.label == Some(DayLabel::Weekend))
        .map(|d| d.date)
        .collect();
    let listed = |d: &[NaiveDate]| {
        d.iter()
            .map(NaiveDate::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    };
    Some(Suggestion {
        evidence: format!(
            "holidays worked: {} of {} calendar holidays look like working days ({})",
            worked.len(),
            hol.len(),
            listed(&worked)
        ),
        paste: Some(match off.is_empty() {
            true => Paste::NoHolidays,
            false => Paste::Holidays(off),
        }),
    })
}

fn weekday_name(d: Weekday) -> &'static str {
    match d {
        Weekday::Mon => "Monday",
        Weekday::Tue => "Tuesday",
        Weekday::Wed => "Wednesday",
        Weekday::Thu => "Thursday",
        Weekday::Fri => "Friday",
        Weekday::Sat => "Saturday",
        Weekday::Sun => "Sunday",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schedule::{cluster_days, DailyProfiles, ScheduleOptions};
    use bemcal_weather::grid::GridYear;
    use bemcal_weather::{Calendar, Holidays};

    /// A working day's profile (rises to `peak` from 08:00 to 18:00) and a day off's (flat).
    fn profile(working: bool, peak: f64, wobble: f64) -> [f64; 24] {
        let mut p = [0.2 + wobble; 24];
        if working {
            for h in p.iter_mut().take(18).skip(8) {
                *h = peak + wobble;
            }
        }
        p
    }

    /// A year of profiles of 2021 where `works(date, calendar day type)` says which days work.
    fn year(works: impl Fn(NaiveDate, DayType) -> bool) -> DayTypeClusters {
        let y = GridYear::calendar(2021);
        let cal = Calendar::new(y, Holidays::UsFederal);
        let mut profiles = vec![];
        for d in 0..365 {
            let date = y.day_date(d);
            let t = cal.day_type(date.month(), date.day()).unwrap();
            let wobble = 0.01 * ((d * 7919) % 5) as f64;
            profiles.push(profile(works(date, t), 0.9, wobble));
        }
        let p = DailyProfiles {
            days: (0..365).collect(),
            profiles,
            skipped_days: vec![],
            scale: 1.0,
            scale_method: "test".into(),
        };
        let opts = ScheduleOptions {
            k: Some(2),
            ..ScheduleOptions::default()
        };
        cluster_days(&p, y, &opts).unwrap().0
    }

    #[test]
    fn low_days_on_thursday_and_friday_are_the_days_off() {
        let c = year(|d, _| !matches!(d.weekday(), Weekday::Thu | Weekday::Fri));
        assert_eq!(c.label_rule, LabelRule::Profile);
        // The low cluster is the days off although nearly all its days are calendar weekdays.
        let thursday = c
            .days
            .iter()
            .find(|d| d.date.weekday() == Weekday::Thu)
            .unwrap();
        let saturday = c
            .days
            .iter()
            .find(|d| d.date.weekday() == Weekday::Sat)
            .unwrap();
        assert_eq!(thursday.label, Some(DayLabel::Weekend));
        assert_eq!(saturday.label, Some(DayLabel::Weekday));
        let advice = calendar_advice(&c);
        let text: Vec<&str> = advice.iter().map(|s| s.evidence.as_str()).collect();
        assert!(
            advice
                .iter()
                .any(|s| s.evidence.contains("Thursday 50 of 50")
                    && s.evidence.contains("Friday 49 of 49")
                    && s.paste == Some(Paste::DayTypesFile)),
            "{text:?}"
        );
        assert!(text
            .iter()
            .any(|t| t.contains("working days on calendar weekends: Saturday")));
        assert_eq!(
            Paste::DayTypesFile.line("precal"),
            "day_types_file = \"precal/calendar.csv\""
        );
    }

    #[test]
    fn an_ordinary_office_gets_no_advice() {
        let c = year(|_, t| t == DayType::Weekday);
        assert_eq!(c.label_rule, LabelRule::Profile);
        assert!(calendar_advice(&c).is_empty(), "{:?}", calendar_advice(&c));
    }

    #[test]
    fn holidays_worked_suggest_dropping_them() {
        let c = year(|_, t| t != DayType::Weekend);
        let advice = calendar_advice(&c);
        let h = advice
            .iter()
            .find(|s| s.evidence.starts_with("holidays worked"))
            .expect("a holiday suggestion");
        // 2021's twelve US federal holidays as observed (Juneteenth on 18 June; Christmas and New
        // Year's Day on the Fridays before).
        assert!(h.evidence.contains("12 of 12"), "{}", h.evidence);
        assert_eq!(h.paste, Some(Paste::NoHolidays));
        // With holidays = "none", those dates are weekdays of the model's calendar.
        let cal = Calendar::new(GridYear::calendar(2021), Holidays::None);
        assert_eq!(cal.day_type(7, 5), Some(DayType::Weekday));
    }

    #[test]
    fn no_weekly_pattern_is_weak_and_says_so() {
        // Every day alike but for small noise: nothing separates.
        let c = year(|d, _| d.ordinal() % 2 == 0);
        let flat = DayTypeClusters {
            cluster_rises: vec![0.5, 0.45],
            cluster_levels: vec![0.5, 0.48],
            label_rule: LabelRule::Calendar,
            ..c
        };
        let advice = calendar_advice(&flat);
        assert!(
            advice[0].evidence.starts_with("weak day types"),
            "{advice:?}"
        );
        assert!(advice[0].paste.is_none());
    }
}
