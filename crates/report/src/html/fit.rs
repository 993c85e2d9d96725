//! How well the calibrated model fits the meters: Guideline 14 hourly, monthly and held out, the
//! predictive intervals' coverage, the model-form analysis of the residuals, the hourly and
//! monthly plots, and the surrogate on its held-out design points.

use std::fmt::Write as _;

use bemcal_calibrate::model_form::{Factor, ModelFormReport};
use bemcal_calibrate::predictive::{PeriodCoverage, PredictiveReport};
use bemcal_calibrate::{OutputMetrics, Summary};
use bemcal_stats::metrics::G14Metrics;
use bemcal_stats::model_form::Verdict;
use bemcal_stats::predictive::Coverage;

use super::{esc, f, figure, g, legend, G14_CV_RMSE_LIMIT, G14_NMBE_LIMIT};
use crate::analysis;
use crate::error::ReportError;
use crate::io::{CalibrationData, Hourly};
use crate::plots::{self, HourlyView};

pub(super) fn g14_pass(m: &OutputMetrics) -> bool {
    m.metrics.nmbe.abs() <= G14_NMBE_LIMIT && m.metrics.cv_rmse <= G14_CV_RMSE_LIMIT
}

fn pass_cell(m: Option<&OutputMetrics>) -> String {
    match m {
        None => "<td>&ndash;</td><td>&ndash;</td><td>&ndash;</td>".into(),
        Some(o) => {
            let m = &o.metrics;
            let nm = if m.nmbe.abs() <= G14_NMBE_LIMIT {
                ""
            } else {
                " class=\"flag\""
            };
            let cv = if m.cv_rmse <= G14_CV_RMSE_LIMIT {
                ""
            } else {
                " class=\"flag\""
            };
            let p = if g14_pass(o) {
                "<td class=\"pass\">pass</td>"
            } else {
                "<td class=\"fail\">fail</td>"
            };
            format!(
                "<td{nm}>{}</td><td{cv}>{}</td>{p}",
                f(m.nmbe, 1),
                f(m.cv_rmse, 1)
            )
        }
    }
}

/// Guideline 14 cells of one block: NMBE, CV-RMSE and pass/fail by its own period's criteria.
fn block_cells(b: Option<&G14Metrics>) -> String {
    match b {
        None => "<td>&ndash;</td><td>&ndash;</td><td>&ndash;</td>".into(),
        Some(b) => format!(
            "<td>{}</td><td>{}</td>{}",
            f(b.nmbe, 1),
            f(b.cv_rmse, 1),
            if b.pass {
                "<td class=\"pass\">pass</td>"
            } else {
                "<td class=\"fail\">fail</td>"
            }
        ),
    }
}

/// Goodness of fit (the reference's Table 5): Guideline 14 hourly metrics per output, initial,
/// calibrated and surrogate at the estimate, with the discrepancy and surrogate error.
pub(super) fn goodness_of_fit(s: &Summary) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<h2 id=\"metrics\">Goodness of fit (ASHRAE Guideline 14, hourly)</h2>\
<p class=\"sub\">Limits: |NMBE| &le; {G14_NMBE_LIMIT:.0} %, CV-RMSE &le; {G14_CV_RMSE_LIMIT:.0} %. \
Initial = EnergyPlus at the prior modes; calibrated = EnergyPlus at the estimate; surrogate = the \
LSTM at the estimate (where it fits the meters and EnergyPlus does not, the surrogate is the bottleneck).</p>\
<table><tr><th class=\"l\" rowspan=\"2\">output</th><th rowspan=\"2\">hours</th><th colspan=\"3\">initial</th>\
<th colspan=\"3\">calibrated</th><th colspan=\"3\">surrogate at estimate</th><th rowspan=\"2\">&sigma;<sub>&delta;</sub> kWh</th><th rowspan=\"2\">&sigma;<sub>&eta;</sub> kWh</th></tr>\
<tr><th>NMBE %</th><th>CV-RMSE %</th><th>G14</th><th>NMBE %</th><th>CV-RMSE %</th><th>G14</th><th>NMBE %</th><th>CV-RMSE %</th><th>G14</th></tr>"
    );
    let lookup =
        |v: &[(String, f64)], o: &str| v.iter().find(|x| x.0 == o).map_or(f64::NAN, |x| x.1);
    for o in &s.outputs {
        let i = s.initial.iter().find(|m| &m.output == o);
        let c = s.validation.iter().find(|m| &m.output == o);
        let sur = s.surrogate_at_estimate.iter().find(|m| &m.output == o);
        let n = c.or(i).map_or(0, |m| m.metrics.n);
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}{}</td><td>{n}</td>{}{}{}<td>{}</td><td>{}</td></tr>",
            esc(o),
            match (s.not_fitted.contains(o), c.map(|c| c.resolution)) {
                (true, _) => " (not fitted)",
                (false, Some(bemcal_calibrate::metrics::Resolution::Bills)) => {
                    " (bills: n counts bills, judged by the monthly limits)"
                }
                _ => "",
            },
            pass_cell(i),
            pass_cell(c),
            pass_cell(sur),
            g(lookup(&s.sigma_delta_kwh, o)),
            g(lookup(&s.sigma_eta_kwh, o)),
        );
    }
    h.push_str("</table><p class=\"sub\">&sigma;<sub>&delta;</sub>: estimated model discrepancy (posterior); &sigma;<sub>&eta;</sub>: surrogate error on held-out design points; not fitted: a meter the likelihood left out (<code>fit = false</code>), compared only.</p>\n");
    h
}

/// The calibrated model monthly, and on the held-out period (hours that fitted nothing).
pub(super) fn monthly_and_held_out(s: &Summary) -> String {
    let mut h = String::new();
    let held = s.holdout.as_ref();
    let _ = write!(
        h,
        "<h3 id=\"held-out\">Monthly{}</h3><p class=\"sub\">Monthly limits: |NMBE| &le; 5 %, \
         CV-RMSE &le; 15 %. {}</p><table><tr><th class=\"l\" rowspan=\"2\">output</th>\
         <th colspan=\"3\">calibration period, monthly</th><th colspan=\"3\">held out, hourly</th>\
         <th colspan=\"3\">held out, monthly</th></tr><tr>{}</tr>",
        if held.is_some() { " and held out" } else { "" },
        match held {
            Some(p) => format!(
                "Held out: <b>{}</b> ({} hours): these hours entered neither the likelihood nor \
                 pre-calibration; EnergyPlus at the estimate is judged on them.",
                esc(&p.period),
                p.hours
            ),
            None => "No held-out period (<code>[validation] holdout</code>): every figure here is in-sample.".into(),
        },
        "<th>NMBE %</th><th>CV-RMSE %</th><th>G14</th>".repeat(3)
    );
    for m in &s.validation {
        let p = m.held_out.as_ref();
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}</td>{}{}{}</tr>",
            esc(&m.label()),
            block_cells(m.monthly.as_ref()),
            block_cells(p.map(|p| &p.hourly)),
            block_cells(p.and_then(|p| p.monthly.as_ref()))
        );
    }
    h.push_str("</table>\n");
    for (m, d) in (s.validation.iter()).filter_map(|m| Some((m, m.demand.as_ref()?))) {
        let _ = writeln!(h, "<p class=\"sub\">{}</p>", esc(&d.sentence(&m.output)));
    }
    h
}

/// Coverage of the hourly predictive intervals, per meter and error model.
pub(super) fn predictive_coverage(s: &Summary) -> String {
    let Some(p) = &s.predictive else {
        return String::new();
    };
    let mut h = String::new();
    let _ = write!(
        h,
        "<h3 id=\"predictive\">Hourly predictive intervals</h3><p class=\"sub\">EnergyPlus at {} \
         posterior draws{} ({} failed), each plus the error model's noise at the scale of its own residuals: share of the measured \
         hours inside the 50 % and 90 % intervals, and their mean width. The intervals are \
         recalibrated on the calibration period (the mixture's quantiles at the levels its \
         hours' probability integral transforms give; Kuleshov et al. 2018), so that they hold \
         about 50 % and 90 % of its hours by construction: the held-out hours are the check, \
         and the posterior's own intervals, before recalibration, show how far its spread is \
         from the meters'. A meter that reads 0 in hours the draws may find idle has more of its hours \
         inside than nominal however calibrated the intervals are (an interval from 0 holds \
         every such reading); its share of PIT, each such reading counted by its share of \
         probability inside (Czado et al. 2009), is given beside it and is the one to hold \
         against nominal. Each month of the calibration period is also judged out of time, by \
         intervals built without it (their coverage over the months, and how far from nominal \
         a month's is on average). The first error model is the one in \
         <code>validation/predictive_intervals.csv</code> (<code>[validation] error_model</code>; \
         <code>\"auto\"</code>, the default, takes the one nearest nominal month by month).</p>\
         <table><tr><th class=\"l\">output</th><th class=\"l\">error model</th>\
         <th>in-sample 50 %</th><th>in-sample 90 %</th><th>held out 50 %</th><th>held out 90 %</th>\
         <th>90 % width, kWh</th><th>months out of time: 50 / 90 % (points a month)</th>\
         <th>before recalibration: in-sample 50 / 90 %</th>\
         <th>held out 50 / 90 %</th></tr>",
        p.draws,
        if p.with_surrogate_error {
            " (with the surrogate's error)"
        } else {
            ""
        },
        p.failed
    );
    let pct = |c: Option<&Coverage>| {
        c.map_or("&ndash;".to_string(), |c| match c.pit_fraction {
            Some(pit) => format!("{:.1} % (PIT {:.1} %)", c.fraction * 100.0, pit * 100.0),
            None => format!("{:.1} %", c.fraction * 100.0),
        })
    };
    for o in &p.outputs {
        for m in &o.by_error_model {
            let before = |of: fn(&PeriodCoverage) -> &Vec<Coverage>| {
                m.before_recalibration
                    .as_ref()
                    .map_or("&ndash;".into(), |b| {
                        format!("{} / {}", pct(of(b).first()), pct(of(b).get(1)))
                    })
            };
            let _ = write!(
                h,
                "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                esc(&o.output),
                esc(m.error_model.as_str()),
                pct(m.coverage.in_sample.first()),
                pct(m.coverage.in_sample.get(1)),
                pct(m.coverage.held_out.first()),
                pct(m.coverage.held_out.get(1)),
                m.coverage
                    .in_sample
                    .get(1)
                    .map_or("&ndash;".into(), |c| g(c.mean_width)),
                m.cross_validated.as_ref().map_or("&ndash;".into(), |c| format!(
                    "{} / {} ({:.1})",
                    pct(c.coverage.first()),
                    pct(c.coverage.get(1)),
                    c.mean_month_miss_points
                )),
                before(|b| &b.in_sample),
                before(|b| &b.held_out),
            );
        }
        if let Some(r) = &o.running {
            let idle =
                |s: Option<f64>| s.map_or("&ndash;".into(), |s| format!("{:.1} %", s * 100.0));
            let _ = write!(
                h,
                "<tr><td class=\"l\">{}</td><td class=\"l\">{} on the hours it reads above 0</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>&ndash;</td><td>&ndash;</td><td colspan=\"2\" class=\"l\">hours that read 0: {} in-sample, {} held out; a reading of 0 lies inside every interval that starts at 0</td></tr>",
                esc(&o.output),
                esc(o.by_error_model.first().map_or("", |m| m.error_model.as_str())),
                pct(r.coverage.in_sample.first()),
                pct(r.coverage.in_sample.get(1)),
                pct(r.coverage.held_out.first()),
                pct(r.coverage.held_out.get(1)),
                idle(Some(r.idle_in_sample)),
                idle(r.idle_held_out),
            );
        }
    }
    h.push_str("</table>\n");
    for b in &p.bills {
        let _ = writeln!(h, "<p class=\"sub\">{}</p>", esc(&b.sentence()));
    }
    h.push_str(&totals_coverage(p, &pct));
    h
}

/// Coverage of the intervals of daily and monthly totals: with the AR(1) noise of a sum, and
/// as if hours were independent (too narrow where residuals are autocorrelated).
fn totals_coverage(p: &PredictiveReport, pct: &dyn Fn(Option<&Coverage>) -> String) -> String {
    if p.outputs.iter().all(|o| o.totals.is_empty()) {
        return String::new();
    }
    let mut h = String::from(
        "<p class=\"sub\">Intervals of daily and monthly totals (the first error model): share \
         of the whole measured days or months inside, with the noise of a sum of AR(1) \
         residuals (&phi;: their lag-one autocorrelation at the estimate), recalibrated on the \
         calibration period's days as the hours are (months are too few: they stay as the \
         posterior gives them), and before recalibration; for comparison, as if the hours were \
         independent (not recalibrated).</p><table><tr><th class=\"l\">output</th>\
         <th class=\"l\">total</th><th>&phi;</th><th>in-sample 50 %</th><th>in-sample 90 %</th>\
         <th>held out 50 %</th><th>held out 90 %</th><th>before recalibration: in-sample 90 %</th>\
         <th>held out 90 %</th><th>independent: in-sample 90 %</th>\
         <th>held out 90 %</th><th>90 % width, kWh</th></tr>",
    );
    for o in &p.outputs {
        for t in &o.totals {
            let _ = write!(
                h,
                "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td>\
                 <td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                esc(&o.output),
                esc(t.period.as_str()),
                f(o.residual_phi, 2),
                pct(t.ar1.in_sample.first()),
                pct(t.ar1.in_sample.get(1)),
                pct(t.ar1.held_out.first()),
                pct(t.ar1.held_out.get(1)),
                pct(t.before_recalibration.as_ref().and_then(|b| b.in_sample.get(1))),
                pct(t.before_recalibration.as_ref().and_then(|b| b.held_out.get(1))),
                pct(t.independent.in_sample.get(1)),
                pct(t.independent.held_out.get(1)),
                t.ar1.in_sample.get(1).map_or("&ndash;".into(), |c| g(c.mean_width)),
            );
        }
    }
    h.push_str("</table>\n");
    h
}

/// Whether the calibrated model reaches each meter: the verdict, the share of the residuals'
/// variance each grouping explains, and the findings in words (`summary.json` `model_form`).
pub(super) fn model_form(s: &Summary) -> Result<String, ReportError> {
    let Some(m) = &s.model_form else {
        return Ok(String::new());
    };
    let mut h = String::from(
        "<h3 id=\"model-form\">Can the model reach each meter?</h3><p class=\"sub\">EnergyPlus at \
         the estimate against the meter over the calibration hours: the verdict by Guideline 14 \
         (level: |NMBE| over 10 %; shape: CV-RMSE over 30 %), the meter's total against the \
         model's at the estimate and posterior draws, the share of the residuals' variance \
         (&eta;&sup2;) explained by the hour of day, working or off day, month and outdoor \
         temperature, and the share of the misfit an additive discrepancy removes \
         (<code>validation/discrepancy.csv</code>).</p><table><tr><th class=\"l\">output</th>\
         <th class=\"l\">verdict</th><th>meter, MWh</th><th>model, MWh</th><th>hour</th>\
         <th>day kind</th><th>month</th><th>outdoor T</th><th>discrepancy removes</th></tr>",
    );
    for o in &m.meters {
        let eta = |factor: Factor| {
            o.patterns
                .iter()
                .find(|p| p.factor == factor)
                .map_or("&ndash;".to_string(), |p| f(p.pattern.eta_squared, 2))
        };
        let verdict = match (o.reach.verdict, o.reach.within_draws) {
            (Verdict::Reached, _) => "<span class=\"pass\">reached</span>".to_string(),
            (Verdict::Level, false) => "<span class=\"fail\">out of reach</span>".to_string(),
            (v, _) => format!("<span class=\"fail\">{} missed</span>", esc(v.as_str())),
        };
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}</td><td class=\"l\">{verdict}</td><td>{}</td><td>{}..{}</td>\
             <td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.0} %</td></tr>",
            esc(&o.output),
            g(o.reach.measured_kwh / 1000.0),
            g(o.reach.draws_kwh[0] / 1000.0),
            g(o.reach.draws_kwh[1] / 1000.0),
            eta(Factor::HourOfDay),
            eta(Factor::DayKind),
            eta(Factor::Month),
            eta(Factor::OutdoorTemperature),
            100.0 * o.discrepancy.share,
        );
    }
    h.push_str("</table><ul class=\"findings\">");
    for o in &m.meters {
        for line in &o.findings {
            let _ = write!(h, "<li><b>{}</b>: {}</li>", esc(&o.output), esc(line));
        }
    }
    for line in &m.parameter_findings {
        let _ = write!(h, "<li>{}</li>", esc(line));
    }
    h.push_str("</ul>\n");
    h.push_str(&residual_figures(m)?);
    Ok(h)
}

/// What the likelihood's model-form discrepancy (`[mcmc] discrepancy`) carried at the MAP draw,
/// per meter: its size against the meter, the level it adds, the hourly error left within its
/// cells and the cells where it is largest (`summary.json` `discrepancy_carried`).
pub(super) fn discrepancy_carried(s: &Summary) -> String {
    if s.discrepancy_carried.is_empty() {
        return String::new();
    }
    let mut h = String::from(
        "<h3 id=\"discrepancy\">What the model cannot be: the discrepancy the chains carried</h3>\
         <p class=\"sub\">The likelihood's model-form term (<code>[mcmc] discrepancy = \
         \"hour_day_season\"</code>): per meter, an effect for each hour of day &times; working \
         or off day &times; season, shrunk towards zero by a scale the meters estimate, so that \
         the parameters are not bent to fit what the model cannot represent. At the MAP draw; \
         <code>discrepancy_cells.csv</code> has every cell.</p><table><tr>\
         <th class=\"l\">meter</th><th>carried, kWh/h RMS</th><th>% of the meter's mean</th>\
         <th>level, kWh/h</th><th>hourly error left, kWh</th><th class=\"l\">largest cells</th></tr>",
    );
    for c in &s.discrepancy_carried {
        let cells: Vec<String> = c
            .largest
            .iter()
            .map(|e| {
                let kind = if e.off_day { "off" } else { "working" };
                format!("{:02}:00 {kind} {} {:+.2}", e.hour, esc(&e.season), e.kwh)
            })
            .collect();
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}</td><td>{}</td><td>{:.1} %</td><td>{:+.2}</td><td>{}</td>\
             <td class=\"l\">{}</td></tr>",
            esc(&c.meter),
            g(c.rms_kwh),
            c.rms_percent_of_mean,
            c.mean_kwh,
            g(c.within_sd_kwh),
            cells.join(", ")
        );
    }
    h.push_str("</table>\n");
    h
}

/// The residual patterns by hour of day and by outdoor temperature band, every meter in % of
/// its mean (a group's x: its hour, or its band's middle).
fn residual_figures(m: &ModelFormReport) -> Result<String, ReportError> {
    let x_of = |label: &str| -> Option<f64> {
        match label.split_once("..") {
            Some((lo, hi)) => Some(0.5 * (lo.parse::<f64>().ok()? + hi.parse::<f64>().ok()?)),
            None => label.parse().ok(),
        }
    };
    let lines = |factor: Factor| -> Vec<(&str, Vec<(f64, f64)>)> {
        m.meters
            .iter()
            .filter_map(|o| {
                let mean = o.reach.measured_kwh / o.reach.hours.max(1) as f64;
                let p = o.patterns.iter().find(|p| p.factor == factor)?;
                let pts = p
                    .pattern
                    .groups
                    .iter()
                    .filter_map(|g| Some((x_of(&g.label)?, 100.0 * g.mean_residual / mean)))
                    .filter(|(_, y)| y.is_finite())
                    .collect::<Vec<_>>();
                (mean > 0.0 && !pts.is_empty()).then_some((o.output.as_str(), pts))
            })
            .collect()
    };
    let (by_hour, by_temperature) = (lines(Factor::HourOfDay), lines(Factor::OutdoorTemperature));
    if by_hour.is_empty() {
        return Ok(String::new());
    }
    let items: Vec<_> = by_hour
        .iter()
        .enumerate()
        .map(|(i, l)| (plots::PALETTE[i % plots::PALETTE.len()], l.0, true))
        .collect();
    let mut h = legend(&items);
    h.push_str("<div class=\"grid\">");
    let figures = [
        (
            by_hour,
            "hour of day",
            "Mean residual (measured &minus; model) by hour of the day, in % of each meter's \
             mean: a shape the schedules do not make.",
        ),
        (
            by_temperature,
            "outdoor dry bulb, C (band middle)",
            "Mean residual by outdoor temperature band (tenths of the hours): a slope points to \
             the envelope, outdoor air or the plant.",
        ),
    ];
    for (lines, x_desc, caption) in figures.iter().filter(|f| !f.0.is_empty()) {
        h.push_str(&figure(
            &plots::residual_profile(lines, x_desc, 0)?,
            caption,
        ));
    }
    h.push_str("</div>\n");
    Ok(h)
}

/// Output `o` of an hourly bands file (columns `{o}_measured`, `{o}_q5`, `{o}_q50`, `{o}_q95`:
/// `posterior_predictive.csv`, `validation/predictive_intervals.csv`) beside the calibrated
/// model's run, cut to the file's hours.
fn hourly_view<'a>(bands: &'a Hourly, o: &str, calibrated: Option<&'a Hourly>) -> HourlyView<'a> {
    let col = |suf: &str| bands.get(&format!("{o}_{suf}")).unwrap_or(&[]);
    HourlyView {
        timestamps: &bands.timestamps,
        measured: col("measured"),
        q5: col("q5"),
        q50: col("q50"),
        q95: col("q95"),
        calibrated: calibrated
            .and_then(|c| c.get(o))
            .map(|v| &v[..v.len().min(bands.timestamps.len())]),
        unit: "kWh per hour",
    }
}

/// The first and the last week of the held-out period, hour by hour: the meter against the
/// EnergyPlus-based predictive median and 5-95 % interval (`validation/predictive_intervals.csv`)
/// and the calibrated model.
pub(super) fn held_out_weeks(cal: &CalibrationData) -> Result<String, ReportError> {
    let Some(iv) = &cal.intervals else {
        return Ok(String::new());
    };
    let held: Vec<usize> = iv
        .get("held_out")
        .unwrap_or(&[])
        .iter()
        .enumerate()
        .filter(|(_, v)| **v == 1.0)
        .map(|(h, _)| h)
        .collect();
    let (Some(&first), Some(&last)) = (held.first(), held.last()) else {
        return Ok(String::new());
    };
    let week = 7 * 24;
    let mut windows = vec![analysis::Window {
        title: "first held-out week".into(),
        start: first,
        end: (first + week).min(last + 1),
    }];
    if last + 1 >= first + 2 * week {
        windows.push(analysis::Window {
            title: "last held-out week".into(),
            start: last + 1 - week,
            end: last + 1,
        });
    }
    let mut h = String::from(
        "<p class=\"sub\">Held-out weeks: the meter (hours that fitted nothing) against the \
         predictive median and 5&ndash;95 % interval of EnergyPlus at posterior draws, each plus \
         the error model's noise at the scale of its own residuals, and EnergyPlus at the estimate.</p><div class=\"grid\">",
    );
    for o in &cal.summary.outputs {
        let view = hourly_view(iv, o, cal.calibrated.as_ref());
        for w in &windows {
            let svg = plots::hourly_window(&view, w)?;
            h.push_str(&figure(&svg, &format!("{}: {}", esc(o), esc(&w.title))));
        }
    }
    h.push_str("</div>\n");
    Ok(h)
}

/// Hourly measured vs calibrated (the reference's Fig. 11) per output: the year, daily; every
/// hour against the calibrated model; monthly totals; and the zoomed weeks.
pub(super) fn hourly_fit(cal: &CalibrationData) -> Result<String, ReportError> {
    let s = &cal.summary;
    let mut h = String::new();
    h.push_str("<h2 id=\"fit\">Hourly measured vs calibrated</h2>");
    if cal.calibrated.is_none() {
        h.push_str("<p class=\"fail\">No validation/calibrated.csv: the calibrated EnergyPlus run is not shown.</p>");
    }
    h.push_str(&legend(&[
        (plots::MEASURED, "measured", true),
        (
            plots::CALIBRATED,
            "calibrated (EnergyPlus at the estimate)",
            true,
        ),
        (plots::POSTERIOR, "posterior predictive median", true),
        (plots::POSTERIOR, "predictive 5&ndash;95 %", false),
        (plots::GAP, "meter missing", false),
    ]));
    h.push_str("<p class=\"sub\">Year view: daily means (grey envelope: measured daily min&ndash;max; band: daily mean of the hourly 5 % and 95 % bounds). Weeks: every hour.</p>");
    let pp = &cal.predictive;
    for o in &s.outputs {
        let view = hourly_view(pp, o, cal.calibrated.as_ref());
        let missing = view.measured.iter().filter(|x| !x.is_finite()).count();
        let m = s.validation.iter().find(|m| &m.output == o);
        let _ = write!(
            h,
            "<h3>{}</h3><p class=\"sub\">{} h missing in the meter{}</p>",
            esc(o),
            missing,
            m.map_or(String::new(), |m| format!(
                " &middot; calibrated NMBE {:.1} %, CV-RMSE {:.1} % ({})",
                m.metrics.nmbe,
                m.metrics.cv_rmse,
                if g14_pass(m) {
                    "<span class=\"pass\">pass</span>"
                } else {
                    "<span class=\"fail\">fail</span>"
                }
            ))
        );
        h.push_str(&figure(
            &plots::hourly_year(&view)?,
            &format!("{}: the year, daily", esc(o)),
        ));
        if let Some(calibrated) = view.calibrated {
            let months = analysis::monthly_totals(&pp.timestamps, view.measured, calibrated);
            h.push_str("<div class=\"grid\">");
            h.push_str(&figure(
                &plots::measured_vs_calibrated(view.measured, calibrated, "kWh")?,
                &format!("{}: every hour, measured against calibrated (shade: hours per cell; line: 1:1)", esc(o)),
            ));
            h.push_str(&figure(
                &plots::monthly_totals(&months, first_month(&pp.timestamps), "kWh per month")?,
                &format!(
                    "{}: monthly totals over the hours the meter has (dark: measured; orange: calibrated)",
                    esc(o)
                ),
            ));
            h.push_str("</div>\n");
        }
        h.push_str("<div class=\"grid\">");
        for w in analysis::zoom_windows(&pp.timestamps, view.measured) {
            let svg = plots::hourly_window(&view, &w)?;
            h.push_str(&figure(&svg, &format!("{}: {}", esc(o), esc(&w.title))));
        }
        h.push_str("</div>\n");
    }
    Ok(h)
}

/// The surrogate on held-out design points; nothing when summary.json has no metrics.
pub(super) fn surrogate_on_held_out(s: &Summary) -> String {
    let Some(ms) = s
        .surrogate_held_out
        .get("metrics")
        .and_then(|m| m.as_object())
    else {
        return String::new();
    };
    let mut h = String::new();
    h.push_str("<h3>Surrogate on held-out design points</h3><table><tr><th class=\"l\">output</th><th>NMBE %</th><th>CV-RMSE %</th><th>RMSE kWh</th></tr>");
    for (o, m) in ms {
        let v = |k: &str| m.get(k).and_then(|x| x.as_f64()).unwrap_or(f64::NAN);
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(o),
            f(v("nmbe_pct"), 1),
            f(v("cv_rmse_pct"), 1),
            g(v("rmse_kwh"))
        );
    }
    h.push_str("</table>");
    h
}

/// The month (1..=12) of the first of `timestamps` (`YYYY-MM-...`): the grid year's first month;
/// January when there is none.
fn first_month(timestamps: &[String]) -> u32 {
    timestamps
        .first()
        .and_then(|t| t.get(5..7))
        .and_then(|m| m.parse().ok())
        .filter(|m| (1..=12).contains(m))
        .unwrap_or(1)
}
