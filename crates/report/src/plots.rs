//! The figures, each a pure function from data to an SVG string (plotters, SVG backend).
//! Legends live in the HTML next to each figure so the small multiples stay compact.

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::series::DashedLineSeries;

use crate::analysis::{self, Window};
use crate::error::PlotError;
use crate::io::{ScheduleHour, ScheduleInterval};

type DynErr = Box<dyn std::error::Error>;
type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// Chain colours (Tableau 10), cycled.
pub const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Colour of the measured series.
pub const MEASURED: RGBColor = RGBColor(20, 20, 20);
/// Colour of the calibrated EnergyPlus run.
pub const CALIBRATED: RGBColor = RGBColor(230, 110, 0);
/// Colour of the posterior (predictive band, posterior histogram).
pub const POSTERIOR: RGBColor = RGBColor(31, 119, 180);
/// Colour of the prior.
pub const PRIOR: RGBColor = RGBColor(120, 120, 120);
/// Colour of the point estimate.
pub const ESTIMATE: RGBColor = RGBColor(200, 30, 30);
/// Shading of missing meter data.
pub const GAP: RGBColor = RGBColor(250, 215, 220);

const FONT: &str = "sans-serif";
const LIGHT_MESH: RGBColor = RGBColor(248, 248, 248);
const BOLD_MESH: RGBColor = RGBColor(228, 228, 228);

/// Draws into a fresh white `w` x `h` SVG and returns its text.
fn render(
    w: u32,
    h: u32,
    f: impl FnOnce(&Area<'_>) -> Result<(), DynErr>,
) -> Result<String, PlotError> {
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| PlotError(e.to_string()))?;
        f(&root).map_err(|e| PlotError(e.to_string()))?;
        root.present().map_err(|e| PlotError(e.to_string()))?;
    }
    Ok(s)
}

/// `(lo, hi)` widened by `frac` of the span (or by 1 / 1 % when the span is zero).
fn pad(lo: f64, hi: f64, frac: f64) -> (f64, f64) {
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span > 0.0 {
        (lo - frac * span, hi + frac * span)
    } else {
        let d = if lo.abs() > 0.0 { lo.abs() * 0.01 } else { 1.0 };
        (lo - d, hi + d)
    }
}

fn finite_range<'a>(series: impl IntoIterator<Item = &'a f64>) -> (f64, f64) {
    series
        .into_iter()
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

/// Splits `(x, y)` points into runs of finite `y` (a line is broken where data is missing).
fn segments(points: impl IntoIterator<Item = (f64, f64)>) -> Vec<Vec<(f64, f64)>> {
    let mut out = vec![];
    let mut cur = vec![];
    for (x, y) in points {
        if y.is_finite() {
            cur.push((x, y));
        } else if !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// A closed band polygon between `lo` and `hi`, one per run of finite values.
fn bands(x: &[f64], lo: &[f64], hi: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut out = vec![];
    let mut run: Vec<usize> = vec![];
    let flush = |run: &mut Vec<usize>, out: &mut Vec<Vec<(f64, f64)>>| {
        if run.len() >= 2 {
            let mut poly: Vec<(f64, f64)> = run.iter().map(|&i| (x[i], hi[i])).collect();
            poly.extend(run.iter().rev().map(|&i| (x[i], lo[i])));
            out.push(poly);
        }
        run.clear();
    };
    for i in 0..x.len() {
        if lo[i].is_finite() && hi[i].is_finite() {
            run.push(i);
        } else {
            flush(&mut run, &mut out);
        }
    }
    flush(&mut run, &mut out);
    out
}

fn tick(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{x:.1e}")
    } else if a >= 100.0 {
        format!("{x:.0}")
    } else if a >= 10.0 {
        format!("{x:.1}")
    } else if a >= 1.0 {
        format!("{x:.2}")
    } else {
        format!("{x:.3}")
    }
}

/// Inputs of [`prior_posterior`].
#[derive(Debug, Clone)]
pub struct PriorPosterior<'a> {
    /// Triangular prior lower bound.
    pub min: f64,
    /// Mode.
    pub mode: f64,
    /// Upper bound.
    pub max: f64,
    /// Posterior draws, all chains pooled.
    pub samples: &'a [f64],
    /// The calibrated value (marked), if any.
    pub estimate: Option<f64>,
    /// Posterior 5 % quantile (the shaded 90 % interval starts here).
    pub q5: f64,
    /// Posterior 95 % quantile.
    pub q95: f64,
    /// Axis label (unit).
    pub unit: &'a str,
}

/// Prior density (triangle), posterior histogram + KDE and the estimate on one axis
/// (the reference's Fig. 10).
pub fn prior_posterior(p: &PriorPosterior<'_>) -> Result<String, PlotError> {
    let s_lo = analysis::quantile(p.samples, 0.005);
    let s_hi = analysis::quantile(p.samples, 0.995);
    let (x_lo, x_hi) = {
        let lo = p.min.min(if s_lo.is_finite() { s_lo } else { p.min });
        let hi = p.max.max(if s_hi.is_finite() { s_hi } else { p.max });
        pad(lo, hi, 0.03)
    };
    let (h_lo, h_hi) = if s_hi > s_lo {
        (s_lo, s_hi)
    } else {
        let d = ((p.max - p.min).abs() * 0.01).max(1e-9);
        (s_lo - d, s_lo + d)
    };
    let hist = analysis::density_histogram(p.samples, h_lo, h_hi, 30);
    let mut grid: Vec<f64> = (0..=300)
        .map(|i| x_lo + (x_hi - x_lo) * i as f64 / 300.0)
        .collect();
    let (k_lo, k_hi) = pad(h_lo, h_hi, 0.25);
    grid.extend((0..=150).map(|i| k_lo + (k_hi - k_lo) * i as f64 / 150.0));
    grid.retain(|x| *x >= x_lo && *x <= x_hi);
    grid.sort_by(f64::total_cmp);
    let dens = analysis::kde(p.samples, &grid);
    let prior: Vec<(f64, f64)> = {
        let mut xs = [x_lo, p.min, p.mode, p.max, x_hi];
        xs.sort_by(f64::total_cmp);
        xs.iter()
            .map(|&x| (x, analysis::triangular_pdf(p.min, p.mode, p.max, x)))
            .collect()
    };
    let y_max = hist
        .iter()
        .map(|h| h.2)
        .chain(dens.iter().copied())
        .chain(prior.iter().map(|p| p.1))
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max)
        .max(1e-12)
        * 1.08;
    render(340, 230, |root| {
        let mut c = ChartBuilder::on(root)
            .margin(6)
            .margin_right(16)
            .x_label_area_size(34)
            .y_label_area_size(44)
            .build_cartesian_2d(x_lo..x_hi, 0.0..y_max)?;
        c.configure_mesh()
            .light_line_style(LIGHT_MESH)
            .bold_line_style(BOLD_MESH)
            .disable_x_mesh()
            .x_labels(5)
            .y_labels(4)
            .x_label_formatter(&|x| tick(*x))
            .y_label_formatter(&|y| tick(*y))
            .x_desc(p.unit)
            .y_desc("density")
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 11))
            .draw()?;
        if p.q5.is_finite() && p.q95.is_finite() {
            c.draw_series(std::iter::once(Rectangle::new(
                [(p.q5, 0.0), (p.q95, y_max)],
                POSTERIOR.mix(0.08).filled(),
            )))?;
        }
        c.draw_series(std::iter::once(Polygon::new(
            prior.clone(),
            PRIOR.mix(0.15).filled(),
        )))?;
        c.draw_series(
            hist.iter()
                .map(|&(l, r, d)| Rectangle::new([(l, 0.0), (r, d)], POSTERIOR.mix(0.35).filled())),
        )?;
        c.draw_series(LineSeries::new(prior, PRIOR.stroke_width(2)))?;
        c.draw_series(LineSeries::new(
            grid.iter().copied().zip(dens.iter().copied()),
            POSTERIOR.stroke_width(2),
        ))?;
        if let Some(e) = p.estimate.filter(|e| e.is_finite()) {
            c.draw_series(LineSeries::new(
                [(e, 0.0), (e, y_max)],
                ESTIMATE.stroke_width(2),
            ))?;
        }
        Ok(())
    })
}

/// Trace plot (left, chains coloured, thinned to at most 600 points per chain) and rank
/// histograms per chain (right; flat = well mixed) of one parameter.
pub fn trace_rank(chains: &[&[f64]], unit: &str) -> Result<String, PlotError> {
    let n = chains.iter().map(|c| c.len()).max().unwrap_or(0).max(2);
    let (lo, hi) = finite_range(chains.iter().flat_map(|c| c.iter()));
    let (lo, hi) = pad(lo, hi, 0.05);
    let bins = 20usize;
    let ranks = analysis::rank_histograms(chains, bins);
    let r_max = ranks.iter().flatten().copied().max().unwrap_or(1) as f64 * 1.15;
    render(720, 200, |root| {
        let (left, right) = root.split_horizontally(460);
        let mut c = ChartBuilder::on(&left)
            .margin(6)
            .margin_right(16)
            .x_label_area_size(30)
            .y_label_area_size(52)
            .build_cartesian_2d(0.0..(n - 1) as f64, lo..hi)?;
        c.configure_mesh()
            .light_line_style(LIGHT_MESH)
            .bold_line_style(BOLD_MESH)
            .disable_x_mesh()
            .x_labels(6)
            .y_labels(5)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| tick(*y))
            .x_desc("draw")
            .y_desc(unit)
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 11))
            .draw()?;
        for (k, ch) in chains.iter().enumerate() {
            let col = PALETTE[k % PALETTE.len()];
            let idx = analysis::thin_indices(ch.len(), 600);
            c.draw_series(LineSeries::new(
                idx.iter().map(|&i| (i as f64, ch[i])),
                col.mix(0.8).stroke_width(1),
            ))?;
        }
        let mut r = ChartBuilder::on(&right)
            .margin(6)
            .margin_right(16)
            .x_label_area_size(30)
            .y_label_area_size(40)
            .build_cartesian_2d(0.0..bins as f64, 0.0..r_max)?;
        r.configure_mesh()
            .light_line_style(LIGHT_MESH)
            .bold_line_style(BOLD_MESH)
            .disable_mesh()
            .x_labels(3)
            .y_labels(4)
            .x_label_formatter(&|x| format!("{:.0}%", 100.0 * x / bins as f64))
            .y_label_formatter(&|y| format!("{y:.0}"))
            .x_desc("rank (pooled)")
            .y_desc("count")
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 11))
            .draw()?;
        for (k, h) in ranks.iter().enumerate() {
            let col = PALETTE[k % PALETTE.len()];
            let pts: Vec<(f64, f64)> = h
                .iter()
                .enumerate()
                .flat_map(|(b, &v)| [(b as f64, v as f64), (b as f64 + 1.0, v as f64)])
                .collect();
            r.draw_series(LineSeries::new(pts, col.stroke_width(2)))?;
            let expect = chains[k].len() as f64 / bins as f64;
            r.draw_series(DashedLineSeries::new(
                [(0.0, expect), (bins as f64, expect)],
                4,
                4,
                col.mix(0.5).stroke_width(1),
            ))?;
        }
        Ok(())
    })
}

/// One output's hourly series, aligned (8,760 or 8,784 slots).
#[derive(Debug, Clone)]
pub struct HourlyView<'a> {
    /// `YYYY-MM-DDTHH:MM` per hour.
    pub timestamps: &'a [String],
    /// Meter (NaN where missing).
    pub measured: &'a [f64],
    /// Posterior predictive 5 % quantile.
    pub q5: &'a [f64],
    /// Posterior predictive median.
    pub q50: &'a [f64],
    /// Posterior predictive 95 % quantile.
    pub q95: &'a [f64],
    /// EnergyPlus at the calibrated parameters, if validated.
    pub calibrated: Option<&'a [f64]>,
    /// Axis label.
    pub unit: &'a str,
}

fn date_label(ts: &[String], hour: f64, fmt: &str) -> String {
    let i = hour.round().max(0.0) as usize;
    ts.get(i.min(ts.len().saturating_sub(1)))
        .and_then(|t| chrono::NaiveDateTime::parse_from_str(t, "%Y-%m-%dT%H:%M").ok())
        .map_or_else(
            || format!("{:.0}", hour / 24.0),
            |d| d.format(fmt).to_string(),
        )
}

/// The year at daily resolution: daily mean of the meter with its daily min-max envelope,
/// the daily mean of the predictive 5-95 % bounds, the calibrated model's daily mean, and the
/// meter's gaps shaded (the reference's Fig. 11).
pub fn hourly_year(v: &HourlyView<'_>) -> Result<String, PlotError> {
    let m = analysis::daily(v.measured, 12);
    let lo = analysis::daily(v.q5, 1);
    let hi = analysis::daily(v.q95, 1);
    let cal = v.calibrated.map(|c| analysis::daily(c, 1));
    let days = m.mean.len();
    let x: Vec<f64> = (0..days).map(|d| d as f64 + 0.5).collect();
    let (y0, y1) = finite_range(
        m.min
            .iter()
            .chain(m.max.iter())
            .chain(lo.mean.iter())
            .chain(hi.mean.iter())
            .chain(cal.iter().flat_map(|c| c.mean.iter())),
    );
    let (y0, y1) = pad(y0.min(0.0), y1, 0.04);
    let gaps = analysis::missing_runs(v.measured);
    render(1100, 300, |root| {
        let mut c = ChartBuilder::on(root)
            .margin(8)
            .margin_right(22)
            .x_label_area_size(30)
            .y_label_area_size(56)
            .build_cartesian_2d(0.0..days as f64, y0..y1)?;
        let ts = v.timestamps;
        c.configure_mesh()
            .light_line_style(LIGHT_MESH)
            .bold_line_style(BOLD_MESH)
            .disable_x_mesh()
            .x_labels(13)
            .y_labels(6)
            .x_label_formatter(&|d| date_label(ts, d * 24.0, "%b %d"))
            .y_label_formatter(&|y| tick(*y))
            .y_desc(v.unit)
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 11))
            .draw()?;
        c.draw_series(gaps.iter().map(|&(s, e)| {
            Rectangle::new([(s as f64 / 24.0, y0), (e as f64 / 24.0, y1)], GAP.filled())
        }))?;
        for poly in bands(&x, &m.min, &m.max) {
            c.draw_series(std::iter::once(Polygon::new(
                poly,
                MEASURED.mix(0.12).filled(),
            )))?;
        }
        for poly in bands(&x, &lo.mean, &hi.mean) {
            c.draw_series(std::iter::once(Polygon::new(
                poly,
                POSTERIOR.mix(0.3).filled(),
            )))?;
        }
        for seg in segments(x.iter().copied().zip(m.mean.iter().copied())) {
            c.draw_series(LineSeries::new(seg, MEASURED.stroke_width(1)))?;
        }
        if let Some(cal) = &cal {
            for seg in segments(x.iter().copied().zip(cal.mean.iter().copied())) {
                c.draw_series(LineSeries::new(seg, CALIBRATED.stroke_width(1)))?;
            }
        }
        Ok(())
    })
}

/// A window (usually a week) at full hourly resolution: meter, predictive 5-95 % band and
/// median, calibrated model, gaps shaded.
pub fn hourly_window(v: &HourlyView<'_>, w: &Window) -> Result<String, PlotError> {
    let (s, e) = (w.start.min(v.measured.len()), w.end.min(v.measured.len()));
    let hours: Vec<usize> = (s..e).collect();
    let x: Vec<f64> = hours.iter().map(|&h| h as f64 / 24.0).collect();
    let pick = |a: &[f64]| -> Vec<f64> {
        hours
            .iter()
            .map(|&h| a.get(h).copied().unwrap_or(f64::NAN))
            .collect()
    };
    let meas = pick(v.measured);
    let lo = pick(v.q5);
    let hi = pick(v.q95);
    let med = pick(v.q50);
    let cal = v.calibrated.map(pick);
    let (y0, y1) = finite_range(
        meas.iter()
            .chain(lo.iter())
            .chain(hi.iter())
            .chain(cal.iter().flatten()),
    );
    let (y0, y1) = pad(y0.min(0.0), y1, 0.05);
    let (x0, x1) = (s as f64 / 24.0, (e.max(s + 1)) as f64 / 24.0);
    let gaps = analysis::missing_runs(&meas);
    render(540, 230, |root| {
        let mut c = ChartBuilder::on(root)
            .margin(8)
            .margin_right(22)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        let ts = v.timestamps;
        c.configure_mesh()
            .light_line_style(LIGHT_MESH)
            .bold_line_style(BOLD_MESH)
            .disable_x_mesh()
            .x_labels(8)
            .y_labels(5)
            .x_label_formatter(&|d| date_label(ts, d * 24.0, "%a %d"))
            .y_label_formatter(&|y| tick(*y))
            .y_desc(v.unit)
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 11))
            .draw()?;
        c.draw_series(gaps.iter().map(|&(a, b)| {
            Rectangle::new(
                [((s + a) as f64 / 24.0, y0), ((s + b) as f64 / 24.0, y1)],
                GAP.filled(),
            )
        }))?;
        for poly in bands(&x, &lo, &hi) {
            c.draw_series(std::iter::once(Polygon::new(
                poly,
                POSTERIOR.mix(0.3).filled(),
            )))?;
        }
        for seg in segments(x.iter().copied().zip(med.iter().copied())) {
            c.draw_series(LineSeries::new(seg, POSTERIOR.stroke_width(1)))?;
        }
        if let Some(cal) = &cal {
            for seg in segments(x.iter().copied().zip(cal.iter().copied())) {
                c.draw_series(LineSeries::new(seg, CALIBRATED.stroke_width(2)))?;
            }
        }
        for seg in segments(x.iter().copied().zip(meas.iter().copied())) {
            c.draw_series(LineSeries::new(seg, MEASURED.stroke_width(1)))?;
        }
        Ok(())
    })
}

/// Measured against calibrated, hour by hour: a 2-D histogram (cells shaded by how many hours
/// fall in them) with the 1:1 line; the way an engineer checks a calibration at a glance
/// (points on the line: the model follows the meter; a fan or a bend: it does not).
pub fn measured_vs_calibrated(
    measured: &[f64],
    calibrated: &[f64],
    unit: &str,
) -> Result<String, PlotError> {
    const BINS: usize = 60;
    let (min, max) = finite_range(measured.iter().chain(calibrated));
    let lo = min.min(0.0);
    let (lo, hi) = pad(lo, max.max(lo + 1e-9), 0.03);
    let cells = analysis::binned_pairs(measured, calibrated, lo, hi, BINS);
    let most = cells.iter().map(|c| c.2).max().unwrap_or(1) as f64;
    let w = (hi - lo) / BINS as f64;
    render(340, 320, |root| {
        let mut c = ChartBuilder::on(root)
            .margin(8)
            .margin_right(16)
            .x_label_area_size(36)
            .y_label_area_size(50)
            .build_cartesian_2d(lo..hi, lo..hi)?;
        c.configure_mesh()
            .light_line_style(LIGHT_MESH)
            .bold_line_style(BOLD_MESH)
            .x_labels(5)
            .y_labels(5)
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .x_desc(format!("measured, {unit}"))
            .y_desc(format!("calibrated, {unit}"))
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 11))
            .draw()?;
        c.draw_series(cells.iter().map(|&(i, j, n)| {
            // Shade on a log scale: a handful of hours stays visible beside thousands.
            let a = 0.15 + 0.85 * ((n as f64).ln_1p() / most.ln_1p());
            let (x0, y0) = (lo + i as f64 * w, lo + j as f64 * w);
            Rectangle::new([(x0, y0), (x0 + w, y0 + w)], POSTERIOR.mix(a).filled())
        }))?;
        c.draw_series(LineSeries::new(
            [(lo, lo), (hi, hi)],
            CALIBRATED.stroke_width(1),
        ))?;
        Ok(())
    })
}

/// Monthly totals, measured beside calibrated (bars per month; `months`: `(month 1-12,
/// measured, calibrated)` from [`analysis::monthly_totals`]), twelve places from `first_month`
/// (the grid year's first month: January, or April for a year from April).
pub fn monthly_totals(
    months: &[(u32, f64, f64)],
    first_month: u32,
    unit: &str,
) -> Result<String, PlotError> {
    // The place (1..=12) of month `k` in the year from `first_month`, and back.
    let place = |k: u32| ((k + 12 - first_month.clamp(1, 12)) % 12 + 1) as f64;
    let month_at = |p: usize| (p + first_month.clamp(1, 12) as usize - 2) % 12;
    const NAMES: [&str; 12] = [
        "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
    ];
    let top = months
        .iter()
        .flat_map(|m| [m.1, m.2])
        .filter(|v| v.is_finite())
        .fold(1e-9, f64::max);
    let (_, hi) = pad(0.0, top, 0.06);
    render(540, 260, |root| {
        let mut c = ChartBuilder::on(root)
            .margin(8)
            .margin_right(16)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0.5..12.5, 0.0..hi)?;
        c.configure_mesh()
            .light_line_style(LIGHT_MESH)
            .bold_line_style(BOLD_MESH)
            .disable_x_mesh()
            .x_labels(12)
            .y_labels(5)
            .x_label_formatter(&|v: &f64| {
                let p = v.round() as usize;
                if (1..=12).contains(&p) {
                    NAMES[month_at(p)].to_string()
                } else {
                    String::new()
                }
            })
            .y_label_formatter(&|v| tick(*v))
            .y_desc(unit)
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 11))
            .draw()?;
        c.draw_series(months.iter().map(|&(k, m, _)| {
            let x = place(k);
            Rectangle::new([(x - 0.38, 0.0), (x, m)], MEASURED.mix(0.75).filled())
        }))?;
        c.draw_series(months.iter().map(|&(k, _, s)| {
            let x = place(k);
            Rectangle::new([(x, 0.0), (x + 0.38, s)], CALIBRATED.filled())
        }))?;
        Ok(())
    })
}

/// A measure's monthly savings (`months`: January to December, each the median and the ends of
/// the 50 % and 90 % credible intervals over posterior draws): a bar at the median, a thick
/// whisker over the 50 % interval and a thin one over the 90 %; the zero line.
pub fn monthly_savings(
    months: &[bemcal_stats::savings::Spread],
    unit: &str,
) -> Result<String, PlotError> {
    const NAMES: [&str; 12] = [
        "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
    ];
    let ends = months
        .iter()
        .flat_map(|m| [m.interval_90[0], m.interval_90[1], 0.0])
        .filter(|v| v.is_finite());
    let (lo, hi) = ends.fold((0.0f64, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    let (lo, hi) = pad(lo, hi.max(lo + 1e-9), 0.08);
    render(540, 240, |root| {
        let mut c = ChartBuilder::on(root)
            .margin(8)
            .margin_right(16)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0.5..12.5, lo..hi)?;
        c.configure_mesh()
            .light_line_style(LIGHT_MESH)
            .bold_line_style(BOLD_MESH)
            .disable_x_mesh()
            .x_labels(12)
            .y_labels(5)
            .x_label_formatter(&|v: &f64| {
                let p = v.round() as usize;
                if (1..=12).contains(&p) {
                    NAMES[p - 1].to_string()
                } else {
                    String::new()
                }
            })
            .y_label_formatter(&|v| tick(*v))
            .y_desc(unit)
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 11))
            .draw()?;
        c.draw_series(months.iter().enumerate().map(|(k, m)| {
            let x = k as f64 + 1.0;
            Rectangle::new(
                [(x - 0.3, 0.0), (x + 0.3, m.median)],
                POSTERIOR.mix(0.45).filled(),
            )
        }))?;
        for (k, m) in months.iter().enumerate() {
            let x = k as f64 + 1.0;
            c.draw_series(LineSeries::new(
                [(x, m.interval_90[0]), (x, m.interval_90[1])],
                MEASURED.stroke_width(1),
            ))?;
            c.draw_series(LineSeries::new(
                [(x, m.interval_50[0]), (x, m.interval_50[1])],
                MEASURED.stroke_width(4),
            ))?;
        }
        c.draw_series(LineSeries::new(
            [(0.5, 0.0), (12.5, 0.0)],
            PRIOR.stroke_width(1),
        ))?;
        Ok(())
    })
}

/// A chart with `f64` axes on an SVG area.
type XyChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The hour-of-day axes of the day-type figures (the reference's Figs. 4-6): x from 0 to `x1`
/// h, y from 0 to `y1` labelled `y_desc`; vertical grid lines only with `x_mesh`.
fn hour_of_day_axes<'a, 'b>(
    root: &'a Area<'b>,
    x1: f64,
    y1: f64,
    y_desc: &str,
    x_mesh: bool,
) -> Result<XyChart<'a, 'b>, DynErr> {
    let mut c = ChartBuilder::on(root)
        .margin(8)
        .margin_right(22)
        .x_label_area_size(30)
        .y_label_area_size(44)
        .build_cartesian_2d(0.0..x1, 0.0..y1)?;
    let mut mesh = c.configure_mesh();
    mesh.light_line_style(LIGHT_MESH)
        .bold_line_style(BOLD_MESH)
        .x_labels(7)
        .y_labels(6)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.1}"))
        .x_desc("hour of day")
        .y_desc(y_desc)
        .label_style((FONT, 11))
        .axis_desc_style((FONT, 11));
    if !x_mesh {
        mesh.disable_x_mesh();
    }
    mesh.draw()?;
    Ok(c)
}

/// Mean residuals (measured - model) by group, one line per meter (`lines`: name and
/// `(x, residual in % of the meter's mean)` points), with the zero line: the model form's
/// residual patterns by hour of day or outdoor temperature (x labels with `x_decimals`).
pub fn residual_profile(
    lines: &[(&str, Vec<(f64, f64)>)],
    x_desc: &str,
    x_decimals: usize,
) -> Result<String, PlotError> {
    let points = || lines.iter().flat_map(|l| l.1.iter());
    let (xlo, xhi) = finite_range(points().map(|p| &p.0));
    let (x0, x1) = pad(xlo, xhi, 0.0);
    let (ylo, yhi) = finite_range(points().map(|p| &p.1));
    let (y0, y1) = pad(ylo.min(0.0), yhi.max(0.0), 0.08);
    render(420, 260, |root| {
        let mut c = ChartBuilder::on(root)
            .margin(8)
            .margin_right(22)
            .x_label_area_size(30)
            .y_label_area_size(44)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        c.configure_mesh()
            .light_line_style(LIGHT_MESH)
            .bold_line_style(BOLD_MESH)
            .x_labels(7)
            .y_labels(6)
            .x_label_formatter(&|x| format!("{x:.x_decimals$}"))
            .y_label_formatter(&|y| format!("{y:.0}"))
            .x_desc(x_desc)
            .y_desc("residual, % of the meter's mean")
            .label_style((FONT, 11))
            .axis_desc_style((FONT, 11))
            .draw()?;
        c.draw_series(LineSeries::new(
            [(x0, 0.0), (x1, 0.0)],
            PRIOR.stroke_width(1),
        ))?;
        for (i, (_, pts)) in lines.iter().enumerate() {
            let col = PALETTE[i % PALETTE.len()];
            for seg in segments(pts.iter().copied()) {
                c.draw_series(LineSeries::new(seg, col.stroke_width(2)))?;
            }
        }
        Ok(())
    })
}

/// One day type's normalised daily profiles (the reference's Fig. 4): every day thin, outlier
/// days red, the medoid thick.
pub fn daily_profiles(
    days: &[Vec<f64>],
    outliers: &[bool],
    medoid: Option<usize>,
    colour: usize,
) -> Result<String, PlotError> {
    let y1 = days
        .iter()
        .flatten()
        .copied()
        .filter(|x| x.is_finite())
        .fold(1.0, f64::max)
        * 1.05;
    let col = PALETTE[colour % PALETTE.len()];
    render(420, 260, |root| {
        let mut c = hour_of_day_axes(root, 23.0, y1, "normalised load", true)?;
        for (d, prof) in days.iter().enumerate() {
            let out = outliers.get(d).copied().unwrap_or(false);
            let style = if out {
                ESTIMATE.mix(0.45).stroke_width(1)
            } else {
                col.mix(0.15).stroke_width(1)
            };
            for seg in segments(prof.iter().enumerate().map(|(h, &y)| (h as f64, y))) {
                c.draw_series(LineSeries::new(seg, style))?;
            }
        }
        if let Some(prof) = medoid.and_then(|m| days.get(m)) {
            for seg in segments(prof.iter().enumerate().map(|(h, &y)| (h as f64, y))) {
                c.draw_series(LineSeries::new(seg, MEASURED.stroke_width(3)))?;
            }
        }
        Ok(())
    })
}

/// Per-hour box plots of the schedule fraction for one day type (the reference's Fig. 5):
/// the box spans the quartiles, the line is the median, whiskers (when given) the range of
/// the days within 1.5 IQR.
pub fn schedule_boxes(
    hours: &[ScheduleHour],
    whiskers: Option<&[(f64, f64)]>,
    colour: usize,
) -> Result<String, PlotError> {
    let col = PALETTE[colour % PALETTE.len()];
    let y1 = hours
        .iter()
        .map(|h| h.q3)
        .chain(whiskers.iter().flat_map(|w| w.iter().map(|x| x.1)))
        .filter(|x| x.is_finite())
        .fold(1.0, f64::max)
        * 1.05;
    render(420, 260, |root| {
        let mut c = hour_of_day_axes(root, 24.0, y1, "schedule fraction", false)?;
        for (i, h) in hours.iter().enumerate() {
            let xc = h.hour as f64 + 0.5;
            if let Some((lo, hi)) = whiskers.and_then(|w| w.get(i)).copied() {
                if lo.is_finite() && hi.is_finite() {
                    c.draw_series(std::iter::once(PathElement::new(
                        vec![(xc, lo), (xc, h.q1)],
                        MEASURED.stroke_width(1),
                    )))?;
                    c.draw_series(std::iter::once(PathElement::new(
                        vec![(xc, h.q3), (xc, hi)],
                        MEASURED.stroke_width(1),
                    )))?;
                }
            }
            c.draw_series(std::iter::once(Rectangle::new(
                [(xc - 0.35, h.q1), (xc + 0.35, h.q3)],
                col.mix(0.45).filled(),
            )))?;
            c.draw_series(std::iter::once(Rectangle::new(
                [(xc - 0.35, h.q1), (xc + 0.35, h.q3)],
                col.stroke_width(1),
            )))?;
            c.draw_series(std::iter::once(PathElement::new(
                vec![(xc - 0.35, h.median), (xc + 0.35, h.median)],
                MEASURED.stroke_width(2),
            )))?;
        }
        Ok(())
    })
}

/// Merged schedule intervals of one day type (the reference's Fig. 6): each interval's
/// triangular prior range (shaded) and mode (thick), over the hourly medians (dots).
pub fn schedule_intervals(
    hours: &[ScheduleHour],
    intervals: &[ScheduleInterval],
    colour: usize,
) -> Result<String, PlotError> {
    let col = PALETTE[colour % PALETTE.len()];
    let y1 = hours
        .iter()
        .map(|h| h.q3)
        .chain(intervals.iter().map(|i| i.max))
        .filter(|x| x.is_finite())
        .fold(1.0, f64::max)
        * 1.05;
    render(420, 260, |root| {
        let mut c = hour_of_day_axes(root, 24.0, y1, "schedule fraction", false)?;
        for iv in intervals {
            let (a, b) = (
                iv.start_hour as f64,
                iv.end_hour.max(iv.start_hour + 1) as f64,
            );
            c.draw_series(std::iter::once(Rectangle::new(
                [(a, iv.min), (b, iv.max)],
                col.mix(0.3).filled(),
            )))?;
            c.draw_series(std::iter::once(PathElement::new(
                vec![(a, iv.mode), (b, iv.mode)],
                col.stroke_width(3),
            )))?;
            c.draw_series(std::iter::once(PathElement::new(
                vec![(b, 0.0), (b, y1)],
                PRIOR.mix(0.4).stroke_width(1),
            )))?;
        }
        c.draw_series(
            hours
                .iter()
                .map(|h| Circle::new((h.hour as f64 + 0.5, h.median), 3, MEASURED.filled())),
        )?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prior_posterior_is_svg() {
        let s: Vec<f64> = (0..1000)
            .map(|i| 5.0 + (i as f64 * 0.618).fract())
            .collect();
        let svg = prior_posterior(&PriorPosterior {
            min: 2.0,
            mode: 5.0,
            max: 9.0,
            samples: &s,
            estimate: Some(5.4),
            q5: 5.05,
            q95: 5.95,
            unit: "W/m2",
        })
        .unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..100]);
        assert!(svg.contains("</svg>"));
    }

    #[test]
    fn constant_chains_still_draw() {
        let a = vec![1.0; 50];
        let b = vec![1.0; 50];
        let svg = trace_rank(&[&a, &b], "C").unwrap();
        assert!(svg.contains("<svg"));
    }
}
