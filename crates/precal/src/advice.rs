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

/// A run of days off holding at least this many calendar weekdays (none of a weekday name
/// already moved) is a break: a school's holidays, a closure between Christmas and New Year.
pub const BREAK_MIN_WEEKDAYS: usize = 3;

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
    let moved_names: Vec<Weekday> = WEEK
        .into_iter()
        .filter(|&wd| low_weekdays.iter().any(|m| m.starts_with(weekday_name(wd))))
        .collect();
    out.extend(breaks(&clustered, &moved_names));
    out.extend(holidays(&clustered));
    out.extend(partial_days(c, &clustered));
    out
}

/// The days of the week, Monday first.
const WEEK: [Weekday; 7] = [
    Weekday::Mon,
    Weekday::Tue,
    Weekday::Wed,
    Weekday::Thu,
    Weekday::Fri,
    Weekday::Sat,
    Weekday::Sun,
];

/// Runs of consecutive days off holding at least [`BREAK_MIN_WEEKDAYS`] calendar weekdays (a
/// school's breaks, a Christmas closure), which no weekday name explains: weekdays named in
/// `moved` (already said) neither count nor end a run; a working day, a skipped day or a gap in
/// the dates ends it.
fn breaks(days: &[&DayRecord], moved: &[Weekday]) -> Option<Suggestion> {
    let mut sorted: Vec<&DayRecord> = days.to_vec();
    sorted.sort_by_key(|d| d.date);
    let mut runs: Vec<(NaiveDate, NaiveDate, usize)> = vec![];
    let mut run: Option<(NaiveDate, NaiveDate, usize)> = None;
    let mut close = |run: &mut Option<(NaiveDate, NaiveDate, usize)>| {
        if let Some(r) = run.take().filter(|r| r.2 >= BREAK_MIN_WEEKDAYS) {
            runs.push(r);
        }
    };
    for d in sorted {
        let contiguous = run.is_some_and(|r| r.1.succ_opt() == Some(d.date));
        if !contiguous || d.label != Some(DayLabel::Weekend) {
            close(&mut run);
        }
        if d.label != Some(DayLabel::Weekend) {
            continue;
        }
        let counts = d.calendar == DayType::Weekday && !moved.contains(&d.date.weekday());
        let r = run.get_or_insert((d.date, d.date, 0));
        r.1 = d.date;
        r.2 += usize::from(counts);
    }
    close(&mut run);
    if runs.is_empty() {
        return None;
    }
    let listed: Vec<String> = runs
        .iter()
        .map(|(a, b, n)| format!("{a} to {b} ({n} weekdays)"))
        .collect();
    Some(Suggestion {
        evidence: format!(
            "days off in runs of calendar weekdays (breaks or closures): {}",
            listed.join(", ")
        ),
        paste: Some(Paste::DayTypesFile),
    })
}

/// Clusters labelled partial days ([`DayLabel::Partial`]: a level between the working days'
/// and the days off's, a Saturday half-day): the model runs them on their own schedule
/// intervals where the day-type file labels them, else on the weekday/weekend rule.
fn partial_days(c: &DayTypeClusters, days: &[&DayRecord]) -> Vec<Suggestion> {
    let levels = &c.cluster_levels;
    let (lo, hi) = levels
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &l| {
            (a.min(l), b.max(l))
        });
    let mut out = vec![];
    for (k, &level) in levels.iter().enumerate() {
        if c.cluster_labels.get(k) != Some(&DayLabel::Partial) {
            continue;
        }
        let members: Vec<&DayRecord> = days
            .iter()
            .copied()
            .filter(|d| d.cluster == Some(k))
            .collect();
        let names = weekday_shares(days, |_| true, |d| d.cluster == Some(k));
        let which = match (names.is_empty(), members.first(), members.last()) {
            (false, _, _) => names.join(", "),
            (true, Some(a), Some(b)) => format!("from {} to {}", a.date, b.date),
            _ => continue,
        };
        out.push(Suggestion {
            evidence: format!(
                "partial days: cluster {k}, {} days ({which}), at a level of {level:.2} between \
                 the days off's {lo:.2} and the working days' {hi:.2}: with the day-type file they \
                 run their own schedule intervals (schedule_partial_*, priors from this cluster)",
                members.len(),
            ),
            paste: Some(Paste::DayTypesFile),
        });
    }
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
    weekday_shares(days, of_kind, |d| d.label == Some(label))
}

/// Per weekday name, the days among those `of_kind` that are `member`s, where they are at least
/// [`MOVED_SHARE`] of that weekday's days of that kind and at least [`MOVED_MIN_DAYS`].
fn weekday_shares(
    days: &[&DayRecord],
    of_kind: impl Fn(&DayRecord) -> bool,
    member: impl Fn(&DayRecord) -> bool,
) -> Vec<String> {
    let mut out = vec![];
    for wd in WEEK {
        let these: Vec<&DayRecord> = days
            .iter()
            .copied()
            .filter(|d| d.date.weekday() == wd && of_kind(d))
            .collect();
        let n = these.iter().filter(|d| member(d)).count();
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
        year_of_peaks(|d, t| works(d, t).then_some(0.9), Some(2))
    }

    /// A year of profiles of 2021 where `peak(date, calendar day type)` gives each day's daytime
    /// level (None: a flat day off), clustered into `k` (None: by silhouette).
    fn year_of_peaks(
        peak: impl Fn(NaiveDate, DayType) -> Option<f64>,
        k: Option<usize>,
    ) -> DayTypeClusters {
        let y = GridYear::calendar(2021);
        let cal = Calendar::new(y, Holidays::UsFederal);
        let mut profiles = vec![];
        for d in 0..365 {
            let date = y.day_date(d);
            let t = cal.day_type(date.month(), date.day()).unwrap();
            let wobble = 0.01 * ((d * 7919) % 5) as f64;
            let p = peak(date, t);
            profiles.push(profile(p.is_some(), p.unwrap_or(0.0), wobble));
        }
        let p = DailyProfiles {
            days: (0..365).collect(),
            profiles,
            skipped_days: vec![],
            scale: 1.0,
            scale_method: "test".into(),
        };
        let opts = ScheduleOptions {
            k,
            ..ScheduleOptions::default()
        };
        cluster_days(&p, y, &opts).unwrap().0
    }

    #[test]
    fn a_schools_break_is_said() {
        // An ordinary office, closed from 14 June to 27 August (a school's summer) and from 27 to
        // 31 December.
        let break_ = |d: NaiveDate| {
            let md = (d.month(), d.day());
            ((6, 14)..=(8, 27)).contains(&md) || ((12, 27)..=(12, 31)).contains(&md)
        };
        let c = year(|d, t| t == DayType::Weekday && !break_(d));
        assert_eq!(c.label_rule, LabelRule::Profile);
        let advice = calendar_advice(&c);
        let text: Vec<&str> = advice.iter().map(|s| s.evidence.as_str()).collect();
        // No weekday name holds the breaks (Monday 11 of 51): a run of days off does. The summer
        // runs from the Saturday before to the Sunday after, its 55 weekdays less Juneteenth
        // (observed on Friday 18 June) and Independence Day (Monday 5 July), holidays already;
        // the winter from Christmas (observed on Friday 24 December) to the year's end (New
        // Year's Day observed on Friday 31 December).
        let b = advice
            .iter()
            .find(|s| {
                s.evidence
                    .starts_with("days off in runs of calendar weekdays")
            })
            .unwrap_or_else(|| panic!("{text:?}"));
        assert!(
            b.evidence.ends_with(
                "2021-06-12 to 2021-08-29 (53 weekdays), 2021-12-24 to 2021-12-31 (4 weekdays)"
            ),
            "{}",
            b.evidence
        );
        assert_eq!(b.paste, Some(Paste::DayTypesFile));
        assert!(
            !text
                .iter()
                .any(|t| t.contains("days off on calendar weekdays:")),
            "{text:?}"
        );
    }

    #[test]
    fn a_saturday_half_day_is_a_partial_day() {
        // Working weekdays at 0.9, Saturdays at 0.6, Sundays and holidays off: the silhouette
        // finds the three kinds, and the Saturdays are partial days with their own schedule.
        let c = year_of_peaks(
            |d, t| match (t, d.weekday()) {
                (DayType::Weekday, _) => Some(0.9),
                (DayType::Weekend, Weekday::Sat) => Some(0.6),
                _ => None,
            },
            None,
        );
        assert_eq!(c.clustering.k, 3, "{:?}", c.silhouettes);
        let advice = calendar_advice(&c);
        let text: Vec<&str> = advice.iter().map(|s| s.evidence.as_str()).collect();
        let partial = advice
            .iter()
            .find(|s| s.evidence.starts_with("partial days"))
            .unwrap_or_else(|| panic!("{text:?}"));
        assert!(
            partial.evidence.contains("Saturday 5")
                && partial.evidence.contains("schedule_partial"),
            "{}",
            partial.evidence
        );
        assert_eq!(partial.paste, Some(Paste::DayTypesFile));
        let saturday = c
            .days
            .iter()
            .find(|d| d.date.weekday() == Weekday::Sat && d.calendar == DayType::Weekend)
            .unwrap();
        assert_eq!(saturday.label, Some(DayLabel::Partial));
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
