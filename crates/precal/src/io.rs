//! File I/O of the pre-calibration: the project file's `[meters]` / `[precalibration]` tables and
//! the output directory.
//!
//! Outputs of [`write_outputs`]:
//! `disaggregated.csv` (timestamp + every meter and derived series, kWh per hour),
//! `calendar.csv` (date, calendar day type, cluster, label, outlier flag and reason),
//! `schedule_priors.csv` (day type, hour, n, q1, median, q3, triangular min/mode/max),
//! `intervals.csv` (day type, interval, start/end hour, quartile means, prior),
//! `priors.toml` (the file the calibration reads), `quality.json`, `summary.txt`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::meters::{run_hours, zero_run_in_off_season, GridYear, MeterSpec, HOURS};
use crate::pipeline::{PrecalOptions, Precalibration, PriorsFile};
use crate::PrecalError;

/// The parts of a project file the pre-calibration reads; other tables are ignored.
///
/// ```toml
/// year = 2011                 # optional
/// [meters]                    # a MeterSpec
/// file = "meters.csv"
/// [precalibration.schedule]   # PrecalOptions
/// band = 2
/// ```
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PrecalProject {
    /// Grid year: `2017`, or `"2017-04"` for twelve months from April 2017.
    #[serde(default)]
    pub year: Option<GridYear>,
    /// How to read the meters.
    #[serde(default)]
    pub meters: Option<MeterSpec>,
    /// Options.
    #[serde(default)]
    pub precalibration: PrecalOptions,
    /// `[validation]`: only its `holdout` matters here.
    #[serde(default)]
    pub validation: PrecalValidation,
}

/// The part of a project's `[validation]` that pre-calibration reads.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PrecalValidation {
    /// Hours never used to fit anything, pre-calibration's priors included.
    #[serde(default)]
    pub holdout: Option<bemcal_weather::period::Holdout>,
}

impl PrecalProject {
    /// Reads a project file. A relative `meters.file` is resolved against the file's folder.
    pub fn read(path: &Path) -> Result<PrecalProject, PrecalError> {
        let text = std::fs::read_to_string(path).map_err(|source| PrecalError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut p: PrecalProject = toml::from_str(&text)
            .map_err(|e| PrecalError::Invalid(format!("{}: {e}", path.display())))?;
        if let Some(m) = p.meters.as_mut() {
            if let Some(f) = m.file.as_mut() {
                if f.is_relative() {
                    *f = path.parent().unwrap_or(Path::new(".")).join(&*f);
                }
            }
        }
        Ok(p)
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> PrecalError + '_ {
    move |source| PrecalError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v}")
    } else {
        String::new()
    }
}

/// Serialises `priors.toml` (with a header comment).
pub fn priors_toml(p: &PriorsFile) -> Result<String, PrecalError> {
    let body = toml::to_string(p).map_err(|e| PrecalError::Invalid(format!("priors.toml: {e}")))?;
    Ok(format!(
        "# Written by bemcal precalibrate. Schedule boundaries: the hour (1..=24) at which each\n\
         # interval ends. Parameters: triangular priors (min, mode, max).\n{body}"
    ))
}

/// Reads a `priors.toml`.
pub fn read_priors(path: &Path) -> Result<PriorsFile, PrecalError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    toml::from_str(&text).map_err(|e| PrecalError::Invalid(format!("{}: {e}", path.display())))
}

/// The human-readable summary; `dir` is the pre-calibration folder as the user named it (the
/// model-file lines it suggests name files in it).
pub fn summary_text(r: &Precalibration, dir: &str) -> String {
    let mut s = String::new();
    write_meters(&mut s, r);
    write_bases(&mut s, r);
    write_day_types(&mut s, r);
    write_calendar_advice(&mut s, r, dir);
    write_schedules(&mut s, r);
    write_priors(&mut s, r);
    s
}

/// The meters' source and year, each meter's quality, ingestion's notes.
fn write_meters(s: &mut String, r: &Precalibration) {
    let m = &r.meters;
    let _ = writeln!(
        s,
        "bemcal pre-calibration: {} (year {})",
        m.source.display(),
        m.year
    );
    let _ = writeln!(
        s,
        "\nMeters (kWh per hour, hour-beginning, local standard time):"
    );
    for (series, q) in m.series.iter().zip(&r.quality) {
        let gap = q
            .longest_gap
            .as_ref()
            .map(|g| format!("{} h from {}", g.hours, g.start))
            .unwrap_or_else(|| "none".into());
        let _ = writeln!(
            s,
            "  {:<12} '{}' [{}]: coverage {:.2} %, mean {:.1}, max {:.1}, zeros {} h, longest gap {}, flat runs >= {} h: {}",
            q.meter,
            series.column,
            series.unit.as_str(),
            q.coverage_pct,
            q.mean_kwh,
            q.max_kwh,
            q.zero_hours,
            gap,
            q.flat_run_min_hours,
            q.flat_run_count
        );
        let d = &r.disaggregation;
        for z in &q.zero_runs {
            let mut hours = run_hours(z, m.year);
            let (first, last) = (hours.next().unwrap_or_default(), hours.last());
            let last = last.unwrap_or(first);
            let season = zero_run_in_off_season(
                &series.role,
                z,
                m.year,
                &d.non_heating_months,
                &d.heating_months,
            );
            let outage = format!(
                "an outage? if the meter was active then, `exclude = \"{}..{}\"` in its \
                 [[meters.columns]]",
                first.date(),
                last.date(),
            );
            let hint = match season {
                Some(true) => "in its meter's off season: expected".to_string(),
                Some(false) => format!("in its meter's season: {outage}"),
                None => outage,
            };
            let _ = writeln!(
                s,
                "    zero for {:.0} days, {} to {} ({hint})",
                z.hours as f64 / 24.0,
                first.format("%Y-%m-%d %H:%M"),
                last.format("%Y-%m-%d %H:%M"),
            );
        }
    }
    for n in &m.notes {
        let _ = writeln!(s, "  note: {n}");
    }
}

/// The base loads and derived series.
fn write_bases(s: &mut String, r: &Precalibration) {
    let _ = writeln!(s, "\nBases (disaggregation):");
    for e in &r.disaggregation.estimates {
        let _ = writeln!(
            s,
            "  {} = {:.6} {}  [{}]",
            e.name, e.value, e.unit, e.method
        );
    }
    for d in &r.disaggregation.series {
        let _ = writeln!(s, "  series {}: {}", d.name, d.method);
    }
    let suggested = r.suggested_bases();
    if suggested.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "\nSuggested [[bases]] (loads in the meters that a model usually lacks; add them to the \
         project file where yours lacks them, with the output your [outputs] maps to that meter):"
    );
    for b in &suggested {
        let _ = writeln!(s, "  # {}", b.why);
        let _ = writeln!(s, "  [[bases]]\n  output = \"{}\"", b.output);
        if let Some(sub) = &b.submeter {
            let _ = writeln!(s, "  submeter = \"{sub}\"");
        }
        if let Some(k) = b.kwh_per_hour {
            let _ = writeln!(s, "  kwh_per_hour = {k:.3}");
        }
    }
}

/// The day-type clustering: series, band, k and silhouettes, clusters, outlier days.
fn write_day_types(s: &mut String, r: &Precalibration) {
    let c = &r.clusters;
    let _ = writeln!(s, "\nDay types:");
    let _ = writeln!(s, "  schedule series: {}", r.schedule_series.method);
    let _ = writeln!(s, "  normalisation: {}", r.profiles.scale_method);
    let _ = writeln!(
        s,
        "  days clustered: {} (skipped for missing hours: {})",
        r.profiles.days.len(),
        r.profiles.skipped_days.len()
    );
    let _ = writeln!(
        s,
        "  DTW band: |i - j| <= {} h (dtaidistance window {})",
        c.band.max_shift.map_or("none".into(), |w| w.to_string()),
        c.band
            .dtaidistance_window()
            .map_or("none".into(), |w| w.to_string())
    );
    let sil: Vec<String> = c
        .silhouettes
        .iter()
        .map(|(k, v)| format!("k={k}: {v:.3}"))
        .collect();
    let _ = writeln!(
        s,
        "  k = {} (silhouette {:.3}; {})",
        c.clustering.k,
        c.clustering.silhouette,
        sil.join(", ")
    );
    let _ = writeln!(
        s,
        "  labels: {}",
        match c.label_rule {
            crate::schedule::LabelRule::Profile =>
                "by what the days look like (their level and daytime rise above the night)",
            crate::schedule::LabelRule::Calendar =>
                "by the calendar's majority (the profiles do not separate working days from days off)",
        }
    );
    for (k, (lab, (wd, off))) in c.cluster_labels.iter().zip(&c.cluster_counts).enumerate() {
        let rise = match (c.cluster_levels.get(k), c.cluster_rises.get(k)) {
            (Some(l), Some(r)) => format!(", level {l:.2}, daytime rise {r:.2}"),
            _ => String::new(),
        };
        let _ = writeln!(
            s,
            "  cluster {k}: label {}, {wd} calendar weekdays, {off} weekend/holiday days{rise}, medoid {}",
            lab.as_str(),
            c.days[r.profiles.days[c.clustering.medoids[k]]].date
        );
    }
    let outliers: Vec<_> = c.days.iter().filter(|d| d.outlier.is_some()).collect();
    let _ = writeln!(s, "  outlier days: {}", outliers.len());
    for d in outliers.iter().take(30) {
        let _ = writeln!(
            s,
            "    {} ({}): {}",
            d.date,
            d.calendar,
            d.outlier.as_deref().unwrap_or("")
        );
    }
}

/// What the day types say about the model's calendar, with the lines to paste.
fn write_calendar_advice(s: &mut String, r: &Precalibration, dir: &str) {
    if r.advice.is_empty() {
        let _ = writeln!(
            s,
            "\nCalendar: the day types agree with the model's calendar (weekends and holidays off)."
        );
        return;
    }
    let _ = writeln!(
        s,
        "\nCalendar (what the day types say about the model's calendar; lines for the model file):"
    );
    let mut pasted: Vec<String> = vec![];
    for a in &r.advice {
        let _ = writeln!(s, "  # {}", a.evidence);
        match a.paste.as_ref().map(|p| p.line(dir)) {
            Some(line) if pasted.contains(&line) => {
                let _ = writeln!(s, "  # (the line above: {line})");
            }
            Some(line) => {
                let _ = writeln!(s, "  {line}");
                pasted.push(line);
            }
            None => {}
        }
    }
}

/// The schedule intervals of each day type.
fn write_schedules(s: &mut String, r: &Precalibration) {
    let (before, after) = r.reduction();
    let _ = writeln!(
        s,
        "\nSchedule intervals: {before} hourly fractions -> {after} interval fractions"
    );
    for sch in &r.schedules {
        let _ = writeln!(
            s,
            "  {} ({} days, {}): {} intervals ending at {:?}",
            sch.label.as_str(),
            sch.n_days,
            sch.source,
            sch.intervals.len(),
            sch.boundaries()
        );
    }
}

/// The priors written to priors.toml, and the pipeline's notes.
fn write_priors(s: &mut String, r: &Precalibration) {
    let _ = writeln!(s, "\nPriors (priors.toml):");
    for p in &r.priors.parameter {
        let _ = writeln!(
            s,
            "  {:<22} min {:.4} mode {:.4} max {:.4} {}",
            p.name, p.min, p.mode, p.max, p.unit
        );
    }
    for n in &r.notes {
        let _ = writeln!(s, "note: {n}");
    }
}

/// Writes all outputs into `dir` (created if needed); returns the paths written.
pub fn write_outputs(dir: &Path, r: &Precalibration) -> Result<Vec<PathBuf>, PrecalError> {
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    let mut written = Vec::new();
    let mut put = |name: &str, text: String| -> Result<(), PrecalError> {
        let p = dir.join(name);
        bemcal_durable::write_atomic(&p, text.as_bytes()).map_err(io_err(&p))?;
        written.push(p);
        Ok(())
    };
    put("disaggregated.csv", disaggregated_csv(r))?;
    put("calendar.csv", calendar_csv(r))?;
    put("schedule_priors.csv", schedule_priors_csv(r))?;
    put("intervals.csv", intervals_csv(r))?;
    put("priors.toml", priors_toml(&r.priors)?)?;
    put("quality.json", quality_json(r)?)?;
    put("summary.txt", summary_text(r, &dir.display().to_string()))?;
    Ok(written)
}

/// `disaggregated.csv`: the meters, the derived series and the schedule series, hour by hour
/// in time order.
fn disaggregated_csv(r: &Precalibration) -> String {
    let mut cols: Vec<(&str, &[f64])> = r
        .meters
        .series
        .iter()
        .map(|s| (s.role.name(), s.values.as_slice()))
        .collect();
    for d in &r.disaggregation.series {
        cols.push((&d.name, &d.values));
    }
    cols.push((&r.schedule_series.name, &r.schedule_series.values));
    let mut t = String::from("timestamp");
    for (n, _) in &cols {
        let _ = write!(t, ",{n}_kwh");
    }
    t.push('\n');
    for h in r.meters.year.chronological(HOURS) {
        let _ = write!(t, "{}", r.meters.year.slot_time(h).format("%Y-%m-%dT%H:%M"));
        for (_, v) in &cols {
            let _ = write!(t, ",{}", num(v[h]));
        }
        t.push('\n');
    }
    t
}

/// `calendar.csv`: each day's calendar type, cluster, label and outlier reason.
fn calendar_csv(r: &Precalibration) -> String {
    let mut t =
        String::from("date,calendar_day_type,cluster,label,outlier,reason,medoid_distance\n");
    // In time order (a year from April lists April first).
    let mut days: Vec<_> = r.clusters.days.iter().collect();
    days.sort_by_key(|d| d.date);
    for d in days {
        let _ = writeln!(
            t,
            "{},{},{},{},{},\"{}\",{}",
            d.date,
            d.calendar,
            d.cluster.map_or(String::new(), |c| c.to_string()),
            d.label.map_or("skipped", |l| l.as_str()),
            d.outlier.is_some(),
            d.outlier.as_deref().unwrap_or("").replace('"', "'"),
            num(d.medoid_distance)
        );
    }
    t
}

/// `schedule_priors.csv`: each day type's hourly quartiles.
fn schedule_priors_csv(r: &Precalibration) -> String {
    let mut t = String::from("day_type,hour,n_days,q1,median,q3\n");
    for s in &r.schedules {
        for h in &s.hours {
            let _ = writeln!(
                t,
                "{},{},{},{},{},{}",
                s.label.as_str(),
                h.hour,
                h.n,
                h.q1,
                h.median,
                h.q3
            );
        }
    }
    t
}

/// `intervals.csv`: each day type's schedule intervals and their priors.
fn intervals_csv(r: &Precalibration) -> String {
    let mut t = String::from(
        "day_type,interval,start_hour,end_hour,q1_mean,median_mean,q3_mean,min,mode,max\n",
    );
    for s in &r.schedules {
        for (i, iv) in s.intervals.iter().enumerate() {
            let _ = writeln!(
                t,
                "{},{},{},{},{},{},{},{},{},{}",
                s.label.as_str(),
                i + 1,
                iv.start_hour,
                iv.end_hour,
                iv.q1,
                iv.median,
                iv.q3,
                iv.prior.min,
                iv.prior.mode,
                iv.prior.max
            );
        }
    }
    t
}

/// `quality.json`: the meters' quality, the bases and the clustering's figures.
fn quality_json(r: &Precalibration) -> Result<String, PrecalError> {
    let q = serde_json::json!({
        "year": r.meters.year,
        "source": r.meters.source,
        "notes": r.meters.notes,
        "meters": r.quality,
        "estimates": r.disaggregation.estimates,
        "non_heating_months": r.disaggregation.non_heating_months,
        "heating_months": r.disaggregation.heating_months,
        "schedule_days_skipped": r.profiles.skipped_days.len(),
        "silhouettes": r.clusters.silhouettes,
        "k": r.clusters.clustering.k,
    });
    let qtext = serde_json::to_string_pretty(&q)
        .map_err(|e| PrecalError::Invalid(format!("quality.json: {e}")))?;
    Ok(qtext)
}
