//! Hourly schedule analysis (reference section 2.2.2, Figs 4-6): daily profiles, DTW day-type
//! clusters, box-plot quartiles per day type and hour, triangular priors, merged schedule
//! intervals.
//!
//! * **Normalisation.** The model's schedule fraction is a fraction of the peak, so every hourly
//!   value is divided by one number for the whole year: a high quantile (default the 99th
//!   percentile) of all hourly values of the schedule series. Fractions are then comparable
//!   across days (dividing each day by its own maximum would turn a quiet Sunday into a busy
//!   Monday). Values above the quantile give fractions slightly above 1; they are kept.
//! * **Days** with any missing hour are skipped and reported.
//! * **Clusters**: pairwise DTW ([`crate::dtw`]) and PAM with k chosen by silhouette
//!   ([`crate::cluster`]). Each cluster is labelled by what its days look like
//!   ([`label_clusters`]): `weekend` (the building's days off, whatever calendar days they fall
//!   on) where its days' mean level is nearer the lowest cluster's than the highest's,
//!   `weekday` otherwise, as long as the levels and the daytime rises separate working days
//!   from days off; where the profiles do not separate so, by the
//!   majority of the days' calendar types (weekends and holidays count as `weekend`; ties go to
//!   `weekday`), and [`LabelRule::Calendar`] says so. A day type pools all clusters with its
//!   label; if no cluster has a label, that day type falls back to its calendar days (noted).
//! * **Outlier days**: days whose calendar type disagrees with their cluster's label, and days
//!   whose distance to their medoid exceeds Q3 + 1.5 IQR of the distances in their cluster. They
//!   are reported but kept in the box plots (quartiles are robust to them).
//! * **Priors**: per day type and hour, Q1/median/Q3 (type 7 quantiles) of the fractions ->
//!   triangular prior (min = Q1, mode = median, max = Q3). If Q3 - Q1 is below
//!   `min_prior_width`, the prior is widened to that width around the median (min floored at 0).
//! * **Intervals**: adjacent hours are merged agglomeratively: repeatedly the adjacent pair of
//!   intervals with the smallest difference of mean medians is merged, if that difference is
//!   <= `merge_tolerance`, the spread of the member hours' medians stays <= 2 x tolerance, and the
//!   two mean IQRs overlap. With `max_intervals`, the closest pairs are then merged regardless
//!   until the count fits. An interval's prior is (mean of Q1s, mean of medians, mean of Q3s)
//!   over its hours, guarded like the hourly priors.

use chrono::NaiveDate;
use serde::{Deserialize, Serialize};

use bemcal_weather::{Calendar, DayType, Holidays};

use crate::cluster::{choose_k, pam, Clustering};
use crate::dtw::{distance_matrix, Band, DistanceMatrix};
use crate::meters::GridYear;
use crate::stats::{quantile, quantile_sorted, quartiles};
use crate::PrecalError;

/// Which series the daily profiles come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScheduleSource {
    /// Lighting + plug loads sub-meters where present, else electricity minus its base.
    #[default]
    Auto,
    /// Total electricity minus the electricity base (data center or night base).
    Electricity,
    /// Sum of the lighting and plug loads sub-meters.
    Submeters,
}

/// Options of the schedule analysis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScheduleOptions {
    /// Series for the daily profiles.
    pub source: ScheduleSource,
    /// DTW Sakoe-Chiba band: largest warp |i - j| in hours (>= 0; >= 23 is unconstrained).
    pub band: i64,
    /// Number of clusters; `None` = by silhouette over `k_min..=k_max`.
    pub k: Option<usize>,
    /// Smallest k tried.
    pub k_min: usize,
    /// Largest k tried.
    pub k_max: usize,
    /// Quantile of all hourly values used as the normalising peak.
    pub normalise_quantile: f64,
    /// Largest difference of medians for merging adjacent hours.
    pub merge_tolerance: f64,
    /// Largest number of intervals per day type.
    pub max_intervals: Option<usize>,
    /// Smallest width max - min of a triangular prior.
    pub min_prior_width: f64,
    /// Holidays of the calendar.
    pub holidays: Holidays,
}

impl Default for ScheduleOptions {
    fn default() -> Self {
        ScheduleOptions {
            source: ScheduleSource::Auto,
            band: 2,
            k: None,
            k_min: 2,
            k_max: 6,
            normalise_quantile: 0.99,
            merge_tolerance: 0.05,
            max_intervals: None,
            min_prior_width: 0.02,
            holidays: Holidays::UsFederal,
        }
    }
}

/// The schedule day types of the building model: working days, days off and, where the meters
/// show them, partial days.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DayLabel {
    /// Working days.
    Weekday,
    /// Weekends and holidays.
    Weekend,
    /// Days between the two (a Saturday half-day, a term's quieter weeks): a cluster whose
    /// level lies at least [`PARTIAL_MARGIN`] of the span from both the days off's and the
    /// working days'. Only the profiles give it, never the calendar.
    Partial,
}

impl DayLabel {
    /// `weekday` / `weekend` / `partial`.
    pub fn as_str(self) -> &'static str {
        match self {
            DayLabel::Weekday => "weekday",
            DayLabel::Weekend => "weekend",
            DayLabel::Partial => "partial",
        }
    }

    /// The label a calendar day type runs on.
    pub fn of(d: DayType) -> DayLabel {
        match d {
            DayType::Weekend | DayType::Holiday => DayLabel::Weekend,
            DayType::Partial => DayLabel::Partial,
            DayType::Weekday => DayLabel::Weekday,
        }
    }
}

/// A cluster whose mean level lies at least this share of the span from both the lowest and
/// the highest cluster's is a partial day (a Saturday half-day, a term's quieter weeks).
pub const PARTIAL_MARGIN: f64 = 0.25;

/// How the clusters got their labels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LabelRule {
    /// By what the days look like: the clusters' levels and daytime rises separate working
    /// days from days off.
    #[default]
    Profile,
    /// By the calendar's majority in each cluster: the profiles do not separate working days
    /// from days off (a weak weekly pattern), so the day types are unreliable.
    Calendar,
}

/// The largest ratio of the lowest cluster's mean level to the highest's at which the clusters
/// are taken to separate working days from days off (the example office's weekends use 0.6 of
/// its weekdays' energy; a building with no weekly pattern, nearly all of it).
pub const OFF_DAY_SEPARATION: f64 = 0.85;

/// The least daytime rise (a share of the year's peak) the busiest cluster must show for the
/// profiles to tell working days at all: an office's working days rise by half the peak or
/// so; the NREL RSF's electricity less its data center, which follows the heating season,
/// by 0.07.
pub const MIN_WORKING_RISE: f64 = 0.15;

/// Hours of the occupied core (9:00-17:00) and of the night (0:00-5:00) of a daily profile.
const CORE_HOURS: std::ops::Range<usize> = 9..17;
const NIGHT_HOURS: std::ops::Range<usize> = 0..5;

/// A day's daytime rise: the mean fraction of the occupied core less the mean of the night.
/// Working days rise more than days off (a base load does not rise).
pub fn daytime_rise(p: &[f64; 24]) -> f64 {
    let mean = |r: std::ops::Range<usize>| p[r.clone()].iter().sum::<f64>() / r.len() as f64;
    mean(CORE_HOURS) - mean(NIGHT_HOURS)
}

/// A day's level: its mean fraction.
pub fn daily_level(p: &[f64; 24]) -> f64 {
    p.iter().sum::<f64>() / 24.0
}

/// Each cluster's label from its mean level and daytime rise. The clusters separate working
/// days from days off where the busiest rises by at least [`MIN_WORKING_RISE`], the lowest
/// level is at most [`OFF_DAY_SEPARATION`] of the highest, and the lowest-level cluster rises
/// less than the highest-level one: then a cluster is `weekend` (days off) where its level is
/// nearer the lowest than the highest, `partial` where it lies at least [`PARTIAL_MARGIN`] of
/// the span from both. Elsewhere by the calendar `counts` (working, off days) of each cluster,
/// and [`LabelRule::Calendar`] says so.
pub fn label_clusters(
    levels: &[f64],
    rises: &[f64],
    counts: &[(usize, usize)],
) -> (Vec<DayLabel>, LabelRule) {
    let arg = |better: fn(f64, f64) -> bool| {
        (0..levels.len()).fold(0, |b, i| if better(levels[i], levels[b]) { i } else { b })
    };
    let (lo, hi) = (arg(|a, b| a < b), arg(|a, b| a > b));
    let max_rise = rises.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let separated = levels.len() >= 2
        && max_rise >= MIN_WORKING_RISE
        && levels[lo] <= OFF_DAY_SEPARATION * levels[hi]
        && rises[lo] < rises[hi];
    if separated {
        let (l0, l1) = (levels[lo], levels[hi]);
        let labels = levels
            .iter()
            .map(|&l| {
                let at = (l - l0) / (l1 - l0);
                if (PARTIAL_MARGIN..=1.0 - PARTIAL_MARGIN).contains(&at) {
                    DayLabel::Partial
                } else if l - l0 < l1 - l {
                    DayLabel::Weekend
                } else {
                    DayLabel::Weekday
                }
            })
            .collect();
        return (labels, LabelRule::Profile);
    }
    let labels = counts
        .iter()
        .map(|&(wd, off)| match off > wd {
            true => DayLabel::Weekend,
            false => DayLabel::Weekday,
        })
        .collect();
    (labels, LabelRule::Calendar)
}

/// Normalised daily profiles of one year.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DailyProfiles {
    /// Day index (0..365, without 29 February) of each profile.
    pub days: Vec<usize>,
    /// 24 fractions per day.
    pub profiles: Vec<[f64; 24]>,
    /// Days skipped for missing hours.
    pub skipped_days: Vec<usize>,
    /// The normalising value (kWh per hour).
    pub scale: f64,
    /// How `scale` was obtained.
    pub scale_method: String,
}

/// Daily profiles of an hourly series divided by its `q` quantile (see the module docs).
pub fn daily_profiles(hourly: &[f64], q: f64) -> Result<DailyProfiles, PrecalError> {
    let scale = quantile(hourly, q);
    if !(scale.is_finite() && scale > 0.0) {
        return Err(PrecalError::Invalid(format!(
            "schedule series has no positive {:.0} % quantile (all zero or missing?)",
            q * 100.0
        )));
    }
    let mut out = DailyProfiles {
        days: Vec::new(),
        profiles: Vec::new(),
        skipped_days: Vec::new(),
        scale,
        scale_method: format!(
            "divided by the {:.0} % quantile of all hourly values ({scale:.3} kWh)",
            q * 100.0
        ),
    };
    for (d, day) in hourly.chunks_exact(24).enumerate() {
        if day.iter().all(|v| v.is_finite()) {
            out.days.push(d);
            out.profiles.push(std::array::from_fn(|h| day[h] / scale));
        } else {
            out.skipped_days.push(d);
        }
    }
    Ok(out)
}

/// One day in the day-type calendar.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DayRecord {
    /// Day index (0..365).
    pub day: usize,
    /// The date.
    pub date: NaiveDate,
    /// Calendar day type.
    pub calendar: DayType,
    /// Cluster (None if the day was skipped).
    pub cluster: Option<usize>,
    /// The cluster's label.
    pub label: Option<DayLabel>,
    /// DTW distance to its medoid.
    pub medoid_distance: f64,
    /// Why the day is an outlier, if it is.
    pub outlier: Option<String>,
}

/// Day-type clusters of a year.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DayTypeClusters {
    /// The chosen clustering (indices into the profiles).
    pub clustering: Clustering,
    /// (k, silhouette) for every k tried.
    pub silhouettes: Vec<(usize, f64)>,
    /// Label of each cluster.
    pub cluster_labels: Vec<DayLabel>,
    /// How the labels were given.
    #[serde(default)]
    pub label_rule: LabelRule,
    /// Each cluster's mean daytime rise ([`daytime_rise`]).
    #[serde(default)]
    pub cluster_rises: Vec<f64>,
    /// Each cluster's mean level ([`daily_level`]).
    #[serde(default)]
    pub cluster_levels: Vec<f64>,
    /// (calendar weekdays, calendar weekends + holidays) per cluster.
    pub cluster_counts: Vec<(usize, usize)>,
    /// Every day of the year, in order.
    pub days: Vec<DayRecord>,
    /// The DTW band used.
    pub band: Band,
}

/// Per cluster, how many of its days the calendar calls working days and how many off days.
fn calendar_counts(
    clustering: &Clustering,
    days: &[usize],
    cal_type: impl Fn(usize) -> DayType,
) -> Vec<(usize, usize)> {
    let mut counts = vec![(0usize, 0usize); clustering.k];
    for (i, &d) in days.iter().enumerate() {
        let c = &mut counts[clustering.labels[i]];
        if cal_type(d).is_off_day() {
            c.1 += 1;
        } else {
            c.0 += 1;
        }
    }
    counts
}

/// Per cluster, the mean of `f` over its days' profiles.
fn cluster_means(
    clustering: &Clustering,
    profiles: &[[f64; 24]],
    f: fn(&[f64; 24]) -> f64,
) -> Vec<f64> {
    let mut sum = vec![(0.0, 0usize); clustering.k];
    for (p, &c) in profiles.iter().zip(&clustering.labels) {
        sum[c].0 += f(p);
        sum[c].1 += 1;
    }
    sum.iter().map(|&(s, n)| s / n.max(1) as f64).collect()
}

/// Per cluster, the distance to its medoid beyond which a day is an outlier: Tukey's fence,
/// Q3 + 1.5 IQR of its days' distances (`med_dist`, one per profile).
fn outlier_limits(clustering: &Clustering, med_dist: &[f64]) -> Vec<f64> {
    (0..clustering.k)
        .map(|c| {
            let mut v: Vec<f64> = med_dist
                .iter()
                .zip(&clustering.labels)
                .filter(|&(_, &l)| l == c)
                .map(|(&m, _)| m)
                .collect();
            v.sort_by(f64::total_cmp);
            let (q1, q3) = (quantile_sorted(&v, 0.25), quantile_sorted(&v, 0.75));
            q3 + 1.5 * (q3 - q1)
        })
        .collect()
}

impl DayTypeClusters {
    /// Indices (into the profiles) of the days of day type `label`.
    pub fn members(&self, profiles: &DailyProfiles, label: DayLabel) -> Vec<usize> {
        profiles
            .days
            .iter()
            .enumerate()
            .filter(|(_, &d)| self.days[d].label == Some(label))
            .map(|(i, _)| i)
            .collect()
    }
}

/// Clusters the profiles with DTW + PAM and labels the clusters ([`label_clusters`]).
pub fn cluster_days(
    profiles: &DailyProfiles,
    year: GridYear,
    opts: &ScheduleOptions,
) -> Result<(DayTypeClusters, DistanceMatrix), PrecalError> {
    let band = Band::from_signed(opts.band)?;
    let n = profiles.profiles.len();
    if n < 4 {
        return Err(PrecalError::Invalid(format!(
            "only {n} complete days of the schedule series; need at least 4 to cluster"
        )));
    }
    let dm = distance_matrix(&profiles.profiles, band);
    let (clustering, silhouettes) = match opts.k {
        Some(k) => {
            let c = pam(&dm, k)?;
            let s = c.silhouette;
            (c, vec![(k, s)])
        }
        None => choose_k(&dm, opts.k_min.max(2)..=opts.k_max.max(2))?,
    };
    let cal = Calendar::new(year, opts.holidays.clone());
    let cal_type = |d: usize| {
        let date = year.day_date(d);
        use chrono::Datelike;
        cal.day_type(date.month(), date.day())
            .unwrap_or(DayType::Weekday)
    };
    let counts = calendar_counts(&clustering, &profiles.days, cal_type);
    let rises = cluster_means(&clustering, &profiles.profiles, daytime_rise);
    let levels = cluster_means(&clustering, &profiles.profiles, daily_level);
    let (cluster_labels, label_rule) = label_clusters(&levels, &rises, &counts);
    // Distances to medoids and the per-cluster outlier limit.
    let med_dist: Vec<f64> = (0..n)
        .map(|i| dm.get(i, clustering.medoids[clustering.labels[i]]))
        .collect();
    let limits = outlier_limits(&clustering, &med_dist);
    let mut days: Vec<DayRecord> = (0..365)
        .map(|d| DayRecord {
            day: d,
            date: year.day_date(d),
            calendar: cal_type(d),
            cluster: None,
            label: None,
            medoid_distance: f64::NAN,
            outlier: None,
        })
        .collect();
    for (i, &d) in profiles.days.iter().enumerate() {
        let c = clustering.labels[i];
        let rec = &mut days[d];
        rec.cluster = Some(c);
        rec.label = Some(cluster_labels[c]);
        rec.medoid_distance = med_dist[i];
        let mut why = Vec::new();
        // The calendar has no partial days: a partial cluster's days are no mismatch.
        if cluster_labels[c] != DayLabel::Partial && DayLabel::of(rec.calendar) != cluster_labels[c]
        {
            why.push(format!(
                "calendar {} in a '{}' cluster",
                rec.calendar,
                cluster_labels[c].as_str()
            ));
        }
        if med_dist[i] > limits[c] {
            why.push(format!(
                "far from its medoid (DTW {:.3} > Q3 + 1.5 IQR = {:.3})",
                med_dist[i], limits[c]
            ));
        }
        if !why.is_empty() {
            rec.outlier = Some(why.join("; "));
        }
    }
    Ok((
        DayTypeClusters {
            clustering,
            silhouettes,
            cluster_labels,
            label_rule,
            cluster_rises: rises,
            cluster_levels: levels,
            cluster_counts: counts,
            days,
            band,
        },
        dm,
    ))
}

/// Box-plot quartiles of one hour of one day type.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HourStats {
    /// Hour of day (0..24, hour-beginning).
    pub hour: usize,
    /// Days pooled.
    pub n: usize,
    /// First quartile.
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
}

/// A triangular prior.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Triangular {
    /// Lower bound.
    pub min: f64,
    /// Mode.
    pub mode: f64,
    /// Upper bound.
    pub max: f64,
}

/// Triangular prior from quartiles: (Q1, median, Q3), widened to `min_width` around the median
/// when narrower (min floored at 0), mode clamped into [min, max].
pub fn triangular_from_quartiles(q1: f64, median: f64, q3: f64, min_width: f64) -> Triangular {
    let (mut lo, mut hi) = (q1.min(q3), q1.max(q3));
    if hi - lo < min_width {
        lo = (median - min_width / 2.0).max(0.0);
        hi = lo + min_width;
    }
    Triangular {
        min: lo,
        mode: median.clamp(lo, hi),
        max: hi,
    }
}

/// Quartiles per hour over the given profiles.
pub fn hourly_stats(profiles: &[&[f64; 24]]) -> Vec<HourStats> {
    (0..24)
        .map(|h| {
            let v: Vec<f64> = profiles.iter().map(|p| p[h]).collect();
            let (q1, median, q3) = quartiles(&v);
            HourStats {
                hour: h,
                n: v.len(),
                q1,
                median,
                q3,
            }
        })
        .collect()
}

/// A schedule interval: hours `start_hour..end_hour` with one prior.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScheduleInterval {
    /// First hour (0..24).
    pub start_hour: usize,
    /// Hour at which the interval ends (1..=24, exclusive).
    pub end_hour: usize,
    /// Mean of the hours' Q1s.
    pub q1: f64,
    /// Mean of the hours' medians.
    pub median: f64,
    /// Mean of the hours' Q3s.
    pub q3: f64,
    /// The guarded triangular prior.
    pub prior: Triangular,
}

#[derive(Clone, Copy)]
struct Acc {
    start: usize,
    end: usize,
    q1: f64,
    med: f64,
    q3: f64,
    lo_med: f64,
    hi_med: f64,
}

impl Acc {
    fn n(&self) -> f64 {
        (self.end - self.start) as f64
    }
    fn mean(&self) -> (f64, f64, f64) {
        let n = self.n();
        (self.q1 / n, self.med / n, self.q3 / n)
    }
    fn join(&self, o: &Acc) -> Acc {
        Acc {
            start: self.start,
            end: o.end,
            q1: self.q1 + o.q1,
            med: self.med + o.med,
            q3: self.q3 + o.q3,
            lo_med: self.lo_med.min(o.lo_med),
            hi_med: self.hi_med.max(o.hi_med),
        }
    }
}

/// Merges adjacent hours into schedule intervals (see the module docs).
pub fn merge_intervals(
    hours: &[HourStats],
    tolerance: f64,
    max_intervals: Option<usize>,
    min_width: f64,
) -> Vec<ScheduleInterval> {
    let mut acc: Vec<Acc> = hours
        .iter()
        .map(|h| Acc {
            start: h.hour,
            end: h.hour + 1,
            q1: h.q1,
            med: h.median,
            q3: h.q3,
            lo_med: h.median,
            hi_med: h.median,
        })
        .collect();
    let diff = |a: &Acc, b: &Acc| (a.mean().1 - b.mean().1).abs();
    let ok = |a: &Acc, b: &Acc| {
        let (aq1, _, aq3) = a.mean();
        let (bq1, _, bq3) = b.mean();
        let u = a.join(b);
        diff(a, b) <= tolerance
            && u.hi_med - u.lo_med <= 2.0 * tolerance
            && aq1.max(bq1) <= aq3.min(bq3)
    };
    loop {
        let best = (0..acc.len().saturating_sub(1))
            .filter(|&i| ok(&acc[i], &acc[i + 1]))
            .min_by(|&i, &j| diff(&acc[i], &acc[i + 1]).total_cmp(&diff(&acc[j], &acc[j + 1])));
        let Some(i) = best else { break };
        acc[i] = acc[i].join(&acc[i + 1]);
        acc.remove(i + 1);
    }
    if let Some(m) = max_intervals {
        while acc.len() > m.max(1) {
            let i = (0..acc.len() - 1)
                .min_by(|&i, &j| diff(&acc[i], &acc[i + 1]).total_cmp(&diff(&acc[j], &acc[j + 1])))
                .expect("two intervals");
            acc[i] = acc[i].join(&acc[i + 1]);
            acc.remove(i + 1);
        }
    }
    acc.iter()
        .map(|a| {
            let (q1, median, q3) = a.mean();
            ScheduleInterval {
                start_hour: a.start,
                end_hour: a.end,
                q1,
                median,
                q3,
                prior: triangular_from_quartiles(q1, median, q3, min_width),
            }
        })
        .collect()
}

/// Hourly quartiles and merged intervals of one day type.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DayTypeSchedule {
    /// The day type.
    pub label: DayLabel,
    /// Days pooled.
    pub n_days: usize,
    /// How the days were chosen.
    pub source: String,
    /// 24 hourly quartiles.
    pub hours: Vec<HourStats>,
    /// Merged intervals.
    pub intervals: Vec<ScheduleInterval>,
}

impl DayTypeSchedule {
    /// Hour (1..=24) at which each interval ends.
    pub fn boundaries(&self) -> Vec<usize> {
        self.intervals.iter().map(|i| i.end_hour).collect()
    }
}

/// Hourly quartiles and intervals for weekday and weekend from the clusters, and for partial
/// days where a cluster holds them.
pub fn day_type_schedules(
    profiles: &DailyProfiles,
    clusters: &DayTypeClusters,
    opts: &ScheduleOptions,
) -> Result<Vec<DayTypeSchedule>, PrecalError> {
    let partial = clusters.cluster_labels.contains(&DayLabel::Partial);
    [DayLabel::Weekday, DayLabel::Weekend]
        .into_iter()
        .chain(partial.then_some(DayLabel::Partial))
        .map(|label| {
            let mut idx = clusters.members(profiles, label);
            let mut source = format!(
                "DTW day-type cluster '{}' (clusters {})",
                label.as_str(),
                clusters
                    .cluster_labels
                    .iter()
                    .enumerate()
                    .filter(|(_, &l)| l == label)
                    .map(|(c, _)| c.to_string())
                    .collect::<Vec<_>>()
                    .join(",")
            );
            if idx.is_empty() {
                idx = profiles
                    .days
                    .iter()
                    .enumerate()
                    .filter(|(_, &d)| DayLabel::of(clusters.days[d].calendar) == label)
                    .map(|(i, _)| i)
                    .collect();
                source = format!(
                    "calendar {} days (no cluster labelled '{}')",
                    label.as_str(),
                    label.as_str()
                );
            }
            if idx.is_empty() {
                return Err(PrecalError::Invalid(format!(
                    "no complete {} days for the schedule priors",
                    label.as_str()
                )));
            }
            let sel: Vec<&[f64; 24]> = idx.iter().map(|&i| &profiles.profiles[i]).collect();
            let hours = hourly_stats(&sel);
            let intervals = merge_intervals(
                &hours,
                opts.merge_tolerance,
                opts.max_intervals,
                opts.min_prior_width,
            );
            Ok(DayTypeSchedule {
                label,
                n_days: idx.len(),
                source,
                hours,
                intervals,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hs(meds: &[f64]) -> Vec<HourStats> {
        meds.iter()
            .enumerate()
            .map(|(h, &m)| HourStats {
                hour: h,
                n: 10,
                q1: m - 0.05,
                median: m,
                q3: m + 0.05,
            })
            .collect()
    }

    #[test]
    fn merges_flat_night_and_keeps_steps() {
        let mut m = vec![0.2; 6];
        m.extend([0.5, 0.8]);
        m.extend(vec![0.9; 9]);
        m.extend([0.6, 0.4]);
        m.extend(vec![0.2; 5]);
        let h = hs(&m);
        let iv = merge_intervals(&h, 0.05, None, 0.02);
        let b: Vec<usize> = iv.iter().map(|i| i.end_hour).collect();
        assert_eq!(b, vec![6, 7, 8, 17, 18, 19, 24]);
        assert!((iv[0].median - 0.2).abs() < 1e-12);
        assert_eq!(iv[0].prior.min, 0.15000000000000002);
        let iv = merge_intervals(&h, 0.05, Some(4), 0.02);
        assert_eq!(iv.len(), 4);
        assert_eq!(iv.last().unwrap().end_hour, 24);
    }

    #[test]
    fn triangular_guard() {
        let t = triangular_from_quartiles(0.3, 0.3, 0.3, 0.02);
        assert!((t.min - 0.29).abs() < 1e-12 && (t.max - 0.31).abs() < 1e-12 && t.mode == 0.3);
        let t = triangular_from_quartiles(0.0, 0.0, 0.0, 0.02);
        assert_eq!((t.min, t.mode, t.max), (0.0, 0.0, 0.02));
        let t = triangular_from_quartiles(0.1, 0.2, 0.4, 0.02);
        assert_eq!((t.min, t.mode, t.max), (0.1, 0.2, 0.4));
    }

    #[test]
    fn synthetic_office_year_clusters_into_weekday_and_weekend() {
        let year = GridYear::calendar(2011);
        let cal = Calendar::new(year, Holidays::UsFederal);
        let mut hourly = Vec::with_capacity(8760);
        let mut x = 7u64;
        for d in 0..365 {
            let date = year.day_date(d);
            use chrono::Datelike;
            let off = cal.day_type(date.month(), date.day()).unwrap().is_off_day();
            for h in 0..24 {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let noise = ((x >> 33) as f64 / (1u64 << 31) as f64 - 0.5) * 4.0;
                let occ = !off && (8..18).contains(&h);
                hourly.push(if occ { 90.0 } else { 30.0 } + noise);
            }
        }
        hourly[100] = f64::NAN;
        let p = daily_profiles(&hourly, 0.99).unwrap();
        assert_eq!(p.skipped_days, vec![4]);
        let opts = ScheduleOptions::default();
        let (c, _) = cluster_days(&p, year, &opts).unwrap();
        assert_eq!(c.clustering.k, 2);
        let s = day_type_schedules(&p, &c, &opts).unwrap();
        assert_eq!(s[0].label, DayLabel::Weekday);
        assert_eq!(s[0].boundaries(), vec![8, 18, 24]);
        assert_eq!(s[1].boundaries(), vec![24]);
        assert!(c.days.iter().all(|d| d.outlier.is_none() || d.day == 4));
    }
}
