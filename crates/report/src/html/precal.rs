//! Pre-calibration: day types, load-profile clusters and the schedule fractions they give.

use std::fmt::Write as _;

use super::{esc, figure, legend};
use crate::analysis;
use crate::error::ReportError;
use crate::io::{PrecalData, ScheduleHour};
use crate::plots;

pub(super) fn precal_section(h: &mut String, p: &PrecalData) -> Result<(), ReportError> {
    let _ = write!(
        h,
        "<h2 id=\"precal\">Pre-calibration</h2><p class=\"sub\">{}</p>",
        esc(&p.dir.display().to_string())
    );
    let types = day_types(p);
    let whiskers = profile_clusters(h, p, &types)?;
    schedule_fractions(h, p, &types, &whiskers)?;
    merged_intervals(h, p, &types)?;
    Ok(())
}

/// The pre-calibration's day types, in order of first appearance in its schedule.
fn day_types(p: &PrecalData) -> Vec<String> {
    let mut types: Vec<String> = vec![];
    for s in &p.schedule {
        if !types.contains(&s.day_type) {
            types.push(s.day_type.clone());
        }
    }
    types
}

/// The days of each whisker's day type, kept for the box plots.
type Whiskers = std::collections::HashMap<String, Vec<Vec<f64>>>;

/// Daily profile clusters (the reference's Fig. 4): one figure per cluster, every day
/// normalised, outliers and the medoid marked; returns the non-outlier days per day type for
/// the box plots' whiskers.
fn profile_clusters(
    h: &mut String,
    p: &PrecalData,
    types: &[String],
) -> Result<Whiskers, ReportError> {
    h.push_str("<h3>Daily profile clusters</h3>");
    let first = p
        .calendar
        .first()
        .and_then(|d| chrono::NaiveDate::parse_from_str(&d.date, "%Y-%m-%d").ok());
    let profiles: Option<Vec<Option<Vec<f64>>>> = p.schedule_series.as_ref().map(|series| {
        let norm = analysis::quantile(series, 0.99);
        p.calendar
            .iter()
            .map(|d| {
                let day = chrono::NaiveDate::parse_from_str(&d.date, "%Y-%m-%d").ok()?;
                let i = usize::try_from((day - first?).num_days()).ok()?;
                let v = series.get(i * 24..i * 24 + 24)?;
                (norm > 0.0).then(|| v.iter().map(|x| x / norm).collect())
            })
            .collect()
    });
    let mut whiskers = Whiskers::default();
    match &profiles {
        None => h.push_str(
            "<p class=\"sub\">No disaggregated.csv (schedule_series_kwh): profiles not shown.</p>",
        ),
        Some(profiles) => {
            h.push_str(&legend(&[
                (plots::PALETTE[0], "day (colour of its cluster)", true),
                (plots::ESTIMATE, "outlier day", true),
                (plots::MEASURED, "medoid", true),
            ]));
            let mut clusters: Vec<usize> = p.calendar.iter().filter_map(|d| d.cluster).collect();
            clusters.sort_unstable();
            clusters.dedup();
            h.push_str("<div class=\"grid\">");
            for (ci, &c) in clusters.iter().enumerate() {
                let mut days = vec![];
                let mut out = vec![];
                let mut medoid = None;
                let mut best = f64::INFINITY;
                let mut label = String::new();
                let mut n_cal: std::collections::BTreeMap<String, usize> = Default::default();
                for (d, prof) in p.calendar.iter().zip(profiles) {
                    if d.cluster != Some(c) {
                        continue;
                    }
                    let Some(prof) = prof else { continue };
                    label = d.label.clone();
                    *n_cal.entry(d.calendar.clone()).or_default() += 1;
                    if d.medoid_distance < best {
                        best = d.medoid_distance;
                        medoid = Some(days.len());
                    }
                    if !d.outlier {
                        whiskers
                            .entry(d.label.clone())
                            .or_default()
                            .push(prof.clone());
                    }
                    days.push(prof.clone());
                    out.push(d.outlier);
                }
                let colour = types.iter().position(|t| *t == label).unwrap_or(ci);
                let svg = plots::daily_profiles(&days, &out, medoid, colour)?;
                let counts: Vec<String> = n_cal.iter().map(|(k, v)| format!("{v} {k}")).collect();
                let n_out = out.iter().filter(|x| **x).count();
                h.push_str(&figure(
                    &svg,
                    &format!(
                        "cluster {c}: <b>{}</b> &middot; {} days ({}) &middot; {n_out} outliers",
                        esc(&label),
                        days.len(),
                        esc(&counts.join(", "))
                    ),
                ));
            }
            h.push_str("</div>");
        }
    }
    Ok(whiskers)
}

/// Pre-calibration's hourly schedule statistics of one day type.
fn day_type_hours(p: &PrecalData, day_type: &str) -> Vec<ScheduleHour> {
    p.schedule
        .iter()
        .filter(|s| s.day_type == day_type)
        .cloned()
        .collect()
}

/// Hourly schedule fractions per day type (the reference's Fig. 5): quartile boxes, medians and
/// whiskers within 1.5 IQR.
fn schedule_fractions(
    h: &mut String,
    p: &PrecalData,
    types: &[String],
    whiskers: &Whiskers,
) -> Result<(), ReportError> {
    h.push_str("<h3>Hourly schedule fractions per day type</h3><p class=\"sub\">Box: quartiles over the day type's days; line: median; whiskers: range within 1.5 IQR. The quartiles become the triangular priors.</p><div class=\"grid\">");
    for (k, t) in types.iter().enumerate() {
        let hours = day_type_hours(p, t);
        let wh: Option<Vec<(f64, f64)>> = whiskers.get(t).map(|days| {
            hours
                .iter()
                .map(|hr| {
                    let iqr = hr.q3 - hr.q1;
                    let vals: Vec<f64> = days
                        .iter()
                        .filter_map(|d| d.get(hr.hour).copied())
                        .filter(|x| x.is_finite())
                        .collect();
                    let lo = vals
                        .iter()
                        .copied()
                        .filter(|&x| x >= hr.q1 - 1.5 * iqr)
                        .fold(f64::INFINITY, f64::min);
                    let hi = vals
                        .iter()
                        .copied()
                        .filter(|&x| x <= hr.q3 + 1.5 * iqr)
                        .fold(f64::NEG_INFINITY, f64::max);
                    (lo.min(hr.q1), hi.max(hr.q3))
                })
                .collect()
        });
        let svg = plots::schedule_boxes(&hours, wh.as_deref(), k)?;
        let n = hours.iter().map(|x| x.n_days).max().unwrap_or(0);
        h.push_str(&figure(
            &svg,
            &format!("<b>{}</b> &middot; {n} days", esc(t)),
        ));
    }
    h.push_str("</div>");
    Ok(())
}

/// Merged schedule intervals (the reference's Fig. 6) with their priors' table, and
/// pre-calibration's summary.txt.
fn merged_intervals(h: &mut String, p: &PrecalData, types: &[String]) -> Result<(), ReportError> {
    h.push_str("<h3>Merged schedule intervals</h3><p class=\"sub\">Adjacent hours with similar quartiles merge into one calibrated schedule value; shaded: its triangular prior min&ndash;max, thick line: mode; dots: hourly medians.</p><div class=\"grid\">");
    for (k, t) in types.iter().enumerate() {
        let hours = day_type_hours(p, t);
        let ivs: Vec<_> = p
            .intervals
            .iter()
            .filter(|s| &s.day_type == t)
            .cloned()
            .collect();
        let svg = plots::schedule_intervals(&hours, &ivs, k)?;
        h.push_str(&figure(
            &svg,
            &format!("<b>{}</b> &middot; {} intervals", esc(t), ivs.len()),
        ));
    }
    h.push_str("</div>");
    h.push_str("<table><tr><th class=\"l\">day type</th><th>hours</th><th>min</th><th>mode</th><th>max</th></tr>");
    for iv in &p.intervals {
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}</td><td>{:02}&ndash;{:02}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td></tr>",
            esc(&iv.day_type),
            iv.start_hour,
            iv.end_hour,
            iv.min,
            iv.mode,
            iv.max
        );
    }
    h.push_str("</table>");
    if let Some(t) = &p.summary_text {
        let _ = write!(
            h,
            "<details><summary>summary.txt</summary><pre>{}</pre></details>",
            esc(t)
        );
    }
    Ok(())
}
