//! Data quality of the meters on the grid: coverage, gaps, flat runs and runs of zeros (an
//! outage that reads zero in the meter's own season is flagged for `exclude`).

use chrono::{Datelike, NaiveDateTime};
use serde::{Deserialize, Serialize};

use super::{GridYear, MeterRole, HOURS};

/// A run of missing hours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Gap {
    /// Length in hours.
    pub hours: usize,
    /// First missing slot.
    pub start_slot: usize,
    /// First missing hour (hour-beginning, local standard time).
    pub start: String,
}

/// A run of identical non-zero values (a stuck meter, or an estimated fill).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FlatRun {
    /// Length in hours.
    pub hours: usize,
    /// First slot.
    pub start_slot: usize,
    /// First hour (hour-beginning, local standard time).
    pub start: String,
    /// The repeated value (kWh).
    pub value: f64,
}

/// Data quality of one meter series.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeterQuality {
    /// The meter's role name.
    pub meter: String,
    /// Share of the 8,760 hours with a value, %.
    pub coverage_pct: f64,
    /// Hours without a value.
    pub missing_hours: usize,
    /// The longest run of missing hours, if any.
    pub longest_gap: Option<Gap>,
    /// Runs of the same non-zero value lasting at least `flat_run_min_hours` (longest first, at
    /// most 10 listed).
    pub flat_runs: Vec<FlatRun>,
    /// Number of such runs.
    pub flat_run_count: usize,
    /// The threshold used for flat runs.
    pub flat_run_min_hours: usize,
    /// Hours with exactly zero.
    pub zero_hours: usize,
    /// Runs of zero readings lasting a week or more ([`ZERO_RUN_MIN_HOURS`]), in time order
    /// (a missing hour ends a run; each [`Gap`] here is a run of zeros, not of missing hours).
    /// A heating meter's summer is one; a week of zeros where the meter is otherwise active is
    /// usually an outage, to be excluded (`[[meters.columns]] exclude`) rather than fitted.
    #[serde(default)]
    pub zero_runs: Vec<Gap>,
    /// Hours with a negative value (kept by policy).
    pub negative_hours: usize,
    /// Sum of the values, kWh.
    pub total_kwh: f64,
    /// Mean of the values, kWh per hour.
    pub mean_kwh: f64,
    /// Largest value, kWh per hour.
    pub max_kwh: f64,
}

/// The maximal runs of consecutive `values` that are `member`s, a run going on while `same`
/// holds between its first value and the next: (first index, length), in order.
fn runs(
    values: &[f64],
    member: impl Fn(f64) -> bool,
    same: impl Fn(f64, f64) -> bool,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut t = 0;
    while t < values.len() {
        let s = t;
        t += 1;
        if !member(values[s]) {
            continue;
        }
        while t < values.len() && member(values[t]) && same(values[s], values[t]) {
            t += 1;
        }
        out.push((s, t - s));
    }
    out
}

/// Whether a run of zero readings lies in the season when its meter is expected to read zero:
/// a heating meter's in the non-heating months, a cooling meter's in the heating (cold) months
/// (pre-calibration's [`crate::disaggregate::Disaggregation`] `non_heating_months` and
/// `heating_months`); at least half its hours there. `None` for the other meters, whose zeros
/// have no season, and when that season is unknown (an empty list).
pub fn zero_run_in_off_season(
    role: &MeterRole,
    run: &Gap,
    year: GridYear,
    non_heating_months: &[u32],
    heating_months: &[u32],
) -> Option<bool> {
    let off_months = match role {
        MeterRole::Heating => non_heating_months,
        MeterRole::Cooling => heating_months,
        _ => return None,
    };
    if off_months.is_empty() {
        return None;
    }
    let off = run_hours(run, year)
        .filter(|t| off_months.contains(&t.month()))
        .count();
    Some(2 * off >= run.hours)
}

/// The hours of a run on the grid, in time order (a year from another month runs on across
/// the year end; the grid has no 29 February).
pub fn run_hours(run: &Gap, year: GridYear) -> impl Iterator<Item = NaiveDateTime> + '_ {
    (0..run.hours).map(move |k| year.slot_time((run.start_slot + k) % HOURS))
}

/// The shortest run of zero readings that [`MeterQuality::zero_runs`] lists: a week.
pub const ZERO_RUN_MIN_HOURS: usize = 7 * 24;

/// Quality summary of one kWh-per-hour series on the grid of `year`.
pub fn quality(
    name: &str,
    values: &[f64],
    year: GridYear,
    flat_run_min_hours: usize,
) -> MeterQuality {
    // Gaps and flat runs are runs in time: the slots in time order, each run's start mapped back.
    let order: Vec<usize> = year.chronological(values.len()).collect();
    let values: Vec<f64> = order.iter().map(|&t| values[t]).collect();
    let values = &values[..];
    let n = values.len();
    let present = values.iter().filter(|v| v.is_finite()).count();
    let gap = |&(s, hours): &(usize, usize)| Gap {
        hours,
        start_slot: order[s],
        start: year.slot_time(order[s]).to_string(),
    };
    // The first of the longest runs of missing hours.
    let longest = runs(values, |v| !v.is_finite(), |_, _| true)
        .into_iter()
        .rev()
        .max_by_key(|&(_, h)| h);
    let min_h = flat_run_min_hours.max(2);
    let mut flats: Vec<FlatRun> = runs(values, |v| v.is_finite() && v != 0.0, |a, b| a == b)
        .into_iter()
        .filter(|&(_, h)| h >= min_h)
        .map(|(s, hours)| FlatRun {
            hours,
            start_slot: order[s],
            start: year.slot_time(order[s]).to_string(),
            value: values[s],
        })
        .collect();
    let zero_runs: Vec<Gap> = runs(values, |v| v == 0.0, |_, _| true)
        .iter()
        .filter(|&&(_, h)| h >= ZERO_RUN_MIN_HOURS)
        .map(gap)
        .collect();
    let flat_run_count = flats.len();
    flats.sort_by(|a, b| b.hours.cmp(&a.hours).then(a.start_slot.cmp(&b.start_slot)));
    flats.truncate(10);
    let finite = values.iter().copied().filter(|v| v.is_finite());
    let total: f64 = finite.clone().sum();
    MeterQuality {
        meter: name.to_string(),
        coverage_pct: if n == 0 {
            0.0
        } else {
            100.0 * present as f64 / n as f64
        },
        missing_hours: n - present,
        longest_gap: longest.as_ref().map(gap),
        flat_runs: flats,
        flat_run_count,
        flat_run_min_hours: min_h,
        zero_hours: values.iter().filter(|&&v| v == 0.0).count(),
        zero_runs,
        negative_hours: values.iter().filter(|&&v| v < 0.0).count(),
        total_kwh: total,
        mean_kwh: if present == 0 {
            f64::NAN
        } else {
            total / present as f64
        },
        max_kwh: finite.fold(f64::NAN, f64::max),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quality_summary() {
        let mut v = vec![1.0; 100];
        v[10..15].fill(f64::NAN);
        v[50..52].fill(f64::NAN);
        v[60..70].fill(0.0);
        for (i, x) in v.iter_mut().enumerate().take(50).skip(20) {
            *x = i as f64;
        }
        let q = quality("heating", &v, GridYear::calendar(2011), 24);
        assert_eq!(q.missing_hours, 7);
        assert_eq!(q.longest_gap.as_ref().unwrap().hours, 5);
        assert_eq!(q.longest_gap.as_ref().unwrap().start_slot, 10);
        assert_eq!(q.zero_hours, 10);
        // 70..100 = 30 hours of 1.0.
        assert_eq!(q.flat_run_count, 1);
        assert_eq!(q.flat_runs[0].hours, 30);
        // Ten zero hours are no zero run; a week is, and two equal gaps report the first.
        assert!(q.zero_runs.is_empty());
        let mut v = vec![1.0; 400];
        v[5..8].fill(f64::NAN);
        v[20..23].fill(f64::NAN);
        v[100..268].fill(0.0);
        let q = quality("heating", &v, GridYear::calendar(2011), 24);
        assert_eq!(q.longest_gap.as_ref().unwrap().start_slot, 5);
        assert_eq!(q.zero_runs.len(), 1);
        assert_eq!(
            (q.zero_runs[0].start_slot, q.zero_runs[0].hours),
            (100, 168)
        );
        assert_eq!(q.zero_runs[0].start, "2011-01-05 04:00:00");
        // In January a cooling meter's zeros are its season's; a heating meter's are not.
        let y = GridYear::calendar(2011);
        let (summer, cold) = ([6, 7, 8, 9], [1, 2, 3, 11, 12]);
        let run = &q.zero_runs[0];
        let judge = |role| zero_run_in_off_season(&role, run, y, &summer, &cold);
        assert_eq!(judge(MeterRole::Cooling), Some(true));
        assert_eq!(judge(MeterRole::Heating), Some(false));
        assert_eq!(judge(MeterRole::Electricity), None);
        let unknown = zero_run_in_off_season(&MeterRole::Cooling, run, y, &summer, &[]);
        assert_eq!(unknown, None);
        // A run across 28 February in a leap year: the grid has no 29 February.
        let feb = Gap {
            hours: 48,
            start_slot: 58 * 24,
            start: String::new(),
        };
        let last = run_hours(&feb, GridYear::calendar(2016)).last().unwrap();
        assert_eq!(last.to_string(), "2016-03-01 23:00:00");
    }
}
