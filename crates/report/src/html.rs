//! Assembles the report: tables and inline SVG figures in one HTML string (pure).

use std::fmt::Write as _;

use crate::analysis;
use crate::io::{CalibrationData, Hourly, OutputMetrics, PrecalData};
use crate::plots::{self, HourlyView, PriorPosterior};
use crate::ReportError;

/// ASHRAE Guideline 14 hourly NMBE limit, % (absolute value).
pub const G14_NMBE_LIMIT: f64 = 10.0;
/// ASHRAE Guideline 14 hourly CV-RMSE limit, %.
pub const G14_CV_RMSE_LIMIT: f64 = 30.0;
/// R-hat above this is flagged (chains have not mixed).
pub const RHAT_LIMIT: f64 = 1.01;
/// Bulk ESS below this is flagged.
pub const ESS_LIMIT: f64 = 400.0;
/// Width ratio (posterior 90 % interval / prior's) above this: the data barely informed it.
pub const WIDTH_RATIO_LIMIT: f64 = 0.9;

const CSS: &str = "
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,Helvetica,Arial,sans-serif;margin:0;color:#222;background:#fafafa}
main{max-width:1160px;margin:0 auto;padding:16px 24px 48px;background:#fff}
h1{font-size:24px;margin:8px 0 4px}h2{font-size:19px;margin:28px 0 8px;border-bottom:1px solid #ddd;padding-bottom:4px}
h3{font-size:15px;margin:16px 0 6px}
p.sub{color:#666;margin:0 0 12px}
table{border-collapse:collapse;font-size:13px;margin:6px 0 10px}
th,td{border:1px solid #ddd;padding:3px 7px;text-align:right;white-space:nowrap}th{background:#f2f2f2;white-space:normal}
td.l,th.l{text-align:left}
.pass{color:#1a7f37;font-weight:600}.fail{color:#c62828;font-weight:600}
.flag{background:#fdecea}
.badge{display:inline-block;padding:2px 8px;border-radius:10px;font-size:13px;font-weight:600}
.ok{background:#e6f4ea;color:#1a7f37}.bad{background:#fdecea;color:#c62828}
ul.warn li{margin:2px 0}
.banner{margin:10px 0;padding:10px 14px;border-left:6px solid #c62828;background:#fdecea;color:#5f1010}
.grid{display:flex;flex-wrap:wrap;gap:10px}
figure{margin:4px 0;padding:0}figcaption{font-size:12.5px;color:#333;margin:2px 0 0}
.legend{font-size:12.5px;margin:4px 0}.legend span{margin-right:14px;white-space:nowrap}
.sw{display:inline-block;width:14px;height:10px;margin-right:4px;vertical-align:middle}
.ln{display:inline-block;width:18px;height:0;border-top:2px solid;margin-right:4px;vertical-align:middle}
svg{display:block}
pre{font-size:11.5px;background:#f6f6f6;padding:8px;overflow-x:auto}
nav a{margin-right:12px;font-size:13px}
";

/// Escapes text for HTML.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn f(x: f64, digits: usize) -> String {
    if x.is_finite() {
        format!("{x:.digits$}")
    } else {
        "&ndash;".into()
    }
}

/// A value with about four significant digits.
fn g(x: f64) -> String {
    if !x.is_finite() {
        return "&ndash;".into();
    }
    let a = x.abs();
    let d = if a >= 1000.0 {
        0
    } else if a >= 100.0 {
        1
    } else if a >= 10.0 {
        2
    } else if a >= 1.0 {
        3
    } else {
        4
    };
    format!("{x:.d$}")
}

fn duration(s: f64) -> String {
    if !s.is_finite() {
        "&ndash;".into()
    } else if s < 1.0 {
        format!("{:.0} ms", s * 1000.0)
    } else if s < 120.0 {
        format!("{s:.1} s")
    } else if s < 7200.0 {
        format!("{:.1} min", s / 60.0)
    } else {
        format!("{:.2} h", s / 3600.0)
    }
}

fn rgb(c: plotters::style::RGBColor) -> String {
    format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
}

fn legend(items: &[(plotters::style::RGBColor, &str, bool)]) -> String {
    let mut s = String::from("<div class=\"legend\">");
    for (c, label, line) in items {
        if *line {
            let _ = write!(
                s,
                "<span><i class=\"ln\" style=\"border-color:{}\"></i>{}</span>",
                rgb(*c),
                label
            );
        } else {
            let _ = write!(
                s,
                "<span><i class=\"sw\" style=\"background:{}\"></i>{}</span>",
                rgb(*c),
                label
            );
        }
    }
    s.push_str("</div>");
    s
}

/// A figure: the SVG inline (its namespace attribute dropped: HTML needs none, and the report
/// then holds no URL at all) and a caption.
fn figure(svg: &str, caption: &str) -> String {
    let svg = svg.replacen(" xmlns=\"http://www.w3.org/2000/svg\"", "", 1);
    format!("<figure>{svg}<figcaption>{caption}</figcaption></figure>")
}

fn g14_pass(m: &OutputMetrics) -> bool {
    m.nmbe.abs() <= G14_NMBE_LIMIT && m.cv_rmse <= G14_CV_RMSE_LIMIT
}

fn pass_cell(m: Option<&OutputMetrics>) -> String {
    match m {
        None => "<td>&ndash;</td><td>&ndash;</td><td>&ndash;</td>".into(),
        Some(m) => {
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
            let p = if g14_pass(m) {
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
fn block_cells(b: Option<&crate::io::G14Block>) -> String {
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

/// The calibrated model monthly, and on the held-out period (hours that fitted nothing).
fn monthly_and_held_out(s: &crate::io::Summary) -> String {
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
            esc(&m.output),
            block_cells(m.monthly.as_ref()),
            block_cells(p.map(|p| &p.hourly)),
            block_cells(p.and_then(|p| p.monthly.as_ref()))
        );
    }
    h.push_str("</table>\n");
    h
}

/// Coverage of the hourly predictive intervals, per meter and error model.
fn predictive_coverage(s: &crate::io::Summary) -> String {
    let Some(p) = &s.predictive else {
        return String::new();
    };
    let mut h = String::new();
    let _ = write!(
        h,
        "<h3 id=\"predictive\">Hourly predictive intervals</h3><p class=\"sub\">EnergyPlus at {} \
         posterior draws{} ({} failed), plus noise of the error model: share of the measured \
         hours inside the 50 % and 90 % intervals, and their mean width. Intervals that hold \
         read about 50 % and 90 %; the first error model is the one in \
         <code>validation/predictive_intervals.csv</code> (<code>[validation] error_model</code>).</p>\
         <table><tr><th class=\"l\">output</th><th class=\"l\">error model</th>\
         <th>in-sample 50 %</th><th>in-sample 90 %</th><th>held out 50 %</th><th>held out 90 %</th>\
         <th>90 % width, kWh</th></tr>",
        p.draws,
        if p.with_surrogate_error {
            " (with the surrogate's error)"
        } else {
            ""
        },
        p.failed
    );
    let pct = |c: Option<&crate::io::CoverageBlock>| {
        c.map_or("&ndash;".to_string(), |c| {
            format!("{:.1} %", c.fraction * 100.0)
        })
    };
    for o in &p.outputs {
        for m in &o.by_error_model {
            let _ = write!(
                h,
                "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                esc(&o.output),
                esc(&m.error_model),
                pct(m.coverage.in_sample.first()),
                pct(m.coverage.in_sample.get(1)),
                pct(m.coverage.held_out.first()),
                pct(m.coverage.held_out.get(1)),
                m.coverage
                    .in_sample
                    .get(1)
                    .map_or("&ndash;".into(), |c| g(c.mean_width)),
            );
        }
    }
    h.push_str("</table>\n");
    h.push_str(&totals_coverage(p, &pct));
    h
}

/// Coverage of the intervals of daily and monthly totals: with the AR(1) noise of a sum, and
/// as if hours were independent (too narrow where residuals are autocorrelated).
fn totals_coverage(
    p: &crate::io::PredictiveBlock,
    pct: &dyn Fn(Option<&crate::io::CoverageBlock>) -> String,
) -> String {
    if p.outputs.iter().all(|o| o.totals.is_empty()) {
        return String::new();
    }
    let mut h = String::from(
        "<p class=\"sub\">Intervals of daily and monthly totals (the first error model): share \
         of the whole measured days or months inside, with the noise of a sum of AR(1) \
         residuals (&phi;: their lag-one autocorrelation at the estimate) and, for comparison, \
         as if the hours were independent.</p><table><tr><th class=\"l\">output</th>\
         <th class=\"l\">total</th><th>&phi;</th><th>in-sample 50 %</th><th>in-sample 90 %</th>\
         <th>held out 50 %</th><th>held out 90 %</th><th>independent: in-sample 90 %</th>\
         <th>held out 90 %</th><th>90 % width, kWh</th></tr>",
    );
    for o in &p.outputs {
        for t in &o.totals {
            let _ = write!(
                h,
                "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td>\
                 <td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                esc(&o.output),
                esc(&t.period),
                f(o.residual_phi, 2),
                pct(t.ar1.in_sample.first()),
                pct(t.ar1.in_sample.get(1)),
                pct(t.ar1.held_out.first()),
                pct(t.ar1.held_out.get(1)),
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
fn model_form(s: &crate::io::Summary) -> Result<String, ReportError> {
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
        let eta = |factor: &str| {
            o.patterns
                .iter()
                .find(|p| p.factor == factor)
                .map_or("&ndash;".to_string(), |p| f(p.eta_squared, 2))
        };
        let verdict = match (o.reach.verdict.as_str(), o.reach.within_draws) {
            ("reached", _) => "<span class=\"pass\">reached</span>".to_string(),
            ("level", false) => "<span class=\"fail\">out of reach</span>".to_string(),
            (v, _) => format!("<span class=\"fail\">{} missed</span>", esc(v)),
        };
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}</td><td class=\"l\">{verdict}</td><td>{}</td><td>{}..{}</td>\
             <td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.0} %</td></tr>",
            esc(&o.output),
            g(o.reach.measured_kwh / 1000.0),
            g(o.reach.draws_kwh[0] / 1000.0),
            g(o.reach.draws_kwh[1] / 1000.0),
            eta("hour_of_day"),
            eta("day_kind"),
            eta("month"),
            eta("outdoor_temperature"),
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

/// The residual patterns by hour of day and by outdoor temperature band, every meter in % of
/// its mean (a group's x: its hour, or its band's middle).
fn residual_figures(m: &crate::io::ModelFormBlock) -> Result<String, ReportError> {
    let x_of = |label: &str| -> Option<f64> {
        match label.split_once("..") {
            Some((lo, hi)) => Some(0.5 * (lo.parse::<f64>().ok()? + hi.parse::<f64>().ok()?)),
            None => label.parse().ok(),
        }
    };
    let lines = |factor: &str| -> Vec<(&str, Vec<(f64, f64)>)> {
        m.meters
            .iter()
            .filter_map(|o| {
                let mean = o.reach.measured_kwh / o.reach.hours.max(1) as f64;
                let p = o.patterns.iter().find(|p| p.factor == factor)?;
                let pts = p
                    .groups
                    .iter()
                    .filter_map(|g| Some((x_of(&g.label)?, 100.0 * g.mean_residual / mean)))
                    .filter(|(_, y)| y.is_finite())
                    .collect::<Vec<_>>();
                (mean > 0.0 && !pts.is_empty()).then_some((o.output.as_str(), pts))
            })
            .collect()
    };
    let (by_hour, by_temperature) = (lines("hour_of_day"), lines("outdoor_temperature"));
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
fn held_out_weeks(cal: &CalibrationData) -> Result<String, ReportError> {
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
         predictive median and 5&ndash;95 % interval of EnergyPlus at posterior draws plus the \
         error model's noise, and EnergyPlus at the estimate.</p><div class=\"grid\">",
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

/// A banner on the first screen naming the meters no posterior draw of the model reaches.
fn out_of_reach_banner(s: &crate::io::Summary) -> String {
    let out: Vec<&str> = s
        .model_form
        .iter()
        .flat_map(|m| &m.meters)
        .filter(|o| o.reach.verdict == "level" && !o.reach.within_draws)
        .map(|o| o.output.as_str())
        .collect();
    if out.is_empty() {
        return String::new();
    }
    format!(
        "<div class=\"banner\" id=\"out-of-reach\"><b>Out of the model's reach: {}.</b> No \
         posterior draw of the model reaches the level of {}: the parameters below are the \
         model's best compromise, not the building's values. <a href=\"#model-form\">What the \
         residuals point to</a>.</div>\n",
        esc(&out.join(", ")),
        if out.len() == 1 {
            "this meter"
        } else {
            "these meters"
        }
    )
}

/// The first screen's banner of a calibration whose chains missed a convergence target.
fn not_converged_banner(s: &crate::io::Summary) -> String {
    let num = |x: Option<f64>, d: usize| x.map_or("n/a".to_string(), |v| format!("{v:.d$}"));
    let detail = match &s.convergence {
        Some(c) => {
            let short: Vec<String> = c
                .shortfalls
                .iter()
                .take(8)
                .map(|p| {
                    format!(
                        "{} (R-hat {}, ESS {} / {})",
                        esc(&p.parameter),
                        num(p.rhat, 3),
                        num(p.ess_bulk, 0),
                        num(p.ess_tail, 0)
                    )
                })
                .collect();
            format!(
                "max R-hat {} (target &le; {}), min bulk / tail ESS {} / {} (target &ge; {}); \
                 {} parameter(s) short: {}{}.",
                num(c.max_rhat, 3),
                c.targets.rhat,
                num(c.min_ess_bulk, 0),
                num(c.min_ess_tail, 0),
                c.targets.ess,
                c.shortfalls.len(),
                short.join(", "),
                if c.shortfalls.len() > 8 {
                    ", &hellip;"
                } else {
                    ""
                }
            )
        }
        None => format!("max R-hat {:.3}.", s.posterior.max_rhat),
    };
    format!(
        "<div class=\"banner\" id=\"not-converged\"><b>Not converged.</b> {detail} The chains \
         have not mixed: the estimate, the intervals and the validation below are not a \
         calibration yet. Run longer chains (<code>[mcmc] iterations</code> or \
         <code>max_extensions</code>; they continue from their checkpoint in the same output \
         folder).</div>\n"
    )
}

/// The whole report as one self-contained HTML document.
pub fn build(cal: &CalibrationData, precal: Option<&PrecalData>) -> Result<String, ReportError> {
    let s = &cal.summary;
    let mut h = String::with_capacity(1 << 20);
    h.push_str(&header(cal));
    if !s.converged {
        h.push_str(&not_converged_banner(s));
    }
    h.push_str(&out_of_reach_banner(s));
    h.push_str(&nav(precal.is_some()));
    h.push_str(&warnings(s));
    h.push_str(&design_failures(s));
    h.push_str(&goodness_of_fit(s));
    h.push_str(&monthly_and_held_out(s));
    h.push_str(&predictive_coverage(s));
    h.push_str(&model_form(s)?);
    h.push_str(&held_out_weeks(cal)?);
    h.push_str(&parameters_table(s));
    h.push_str(&prior_vs_posterior(cal)?);
    h.push_str(&chain_plots(cal)?);
    h.push_str(&hourly_fit(cal)?);
    h.push_str(&run_timings(s));
    h.push_str(&refinement(s));
    h.push_str(&acceptance_rates(s));
    h.push_str(&surrogate_on_held_out(s));
    if let Some(p) = precal {
        precal_section(&mut h, p)?;
    }
    h.push_str("<p class=\"sub\" style=\"margin-top:32px\">Written by bemcal report.</p></main></body></html>\n");
    Ok(h)
}

/// The page's head (title, style) and first line: the project, the convergence badge, the folder,
/// outputs, parameters, chains, draws, design points and estimate.
fn header(cal: &CalibrationData) -> String {
    let s = &cal.summary;
    let mut h = String::new();
    let title = if s.project.is_empty() {
        "calibration".to_string()
    } else {
        s.project.clone()
    };
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
<meta name=\"viewport\" content=\"width=device-width,initial-scale=1\">\
<title>bemcal report: {}</title><style>{CSS}</style></head><body><main>\n",
        esc(&title)
    );
    let n_chains = cal.draws.chains.len();
    let n_draws = cal
        .draws
        .chains
        .first()
        .and_then(|c| c.first())
        .map_or(0, Vec::len);
    let conv = if s.converged {
        "<span class=\"badge ok\">converged</span>"
    } else {
        "<span class=\"badge bad\">not converged</span>"
    };
    let _ = writeln!(
        h,
        "<h1>Calibration report: {} {conv}</h1><p class=\"sub\">{} &middot; outputs: {} &middot; \
{} parameters &middot; {} chains &times; {} draws &middot; {} design points &middot; estimate: {}</p>",
        esc(&title),
        esc(&cal.dir.display().to_string()),
        esc(&s.outputs.join(", ")),
        s.parameters.len(),
        n_chains,
        n_draws,
        s.design_points,
        esc(&match &s.estimate {
            serde_json::Value::String(x) => x.clone(),
            serde_json::Value::Null => "?".into(),
            v => v.to_string(),
        })
    );
    h
}

/// The navigation bar: a link to each section (the pre-calibration's where there is one).
fn nav(with_precal: bool) -> String {
    let mut h = String::new();
    h.push_str(
        "<nav><a href=\"#warnings\">Warnings</a><a href=\"#metrics\">Goodness of fit</a>\
<a href=\"#parameters\">Parameters</a><a href=\"#prior-posterior\">Prior vs posterior</a>\
<a href=\"#chains\">Chains</a><a href=\"#fit\">Measured vs calibrated</a><a href=\"#run\">Run</a>",
    );
    if with_precal {
        h.push_str("<a href=\"#precal\">Pre-calibration</a>");
    }
    h.push_str("</nav>\n");
    h
}

/// Warnings: R-hat, bulk ESS, uninformed parameters, correlated pairs, acceptance rates,
/// Guideline 14 failures and design runs EnergyPlus could not simulate.
fn warnings(s: &crate::io::Summary) -> String {
    let post = &s.posterior;
    let mut h = String::new();
    let mut warn: Vec<String> = vec![];
    for p in &post.parameters {
        if p.rhat > RHAT_LIMIT {
            warn.push(format!(
                "<b>{}</b>: R-hat {:.3} &gt; {RHAT_LIMIT} &mdash; the chains disagree; run longer or check the trace plots.",
                esc(&p.name),
                p.rhat
            ));
        }
    }
    let low_ess: Vec<String> = post
        .parameters
        .iter()
        .filter(|p| p.ess_bulk < ESS_LIMIT)
        .map(|p| format!("{} ({:.0})", esc(&p.name), p.ess_bulk))
        .collect();
    if !low_ess.is_empty() {
        warn.push(format!(
            "Bulk ESS below {ESS_LIMIT:.0}: {} &mdash; posterior summaries are imprecise.",
            low_ess.join(", ")
        ));
    }
    for p in &post.parameters {
        if p.width_ratio > WIDTH_RATIO_LIMIT {
            warn.push(format!(
                "<b>{}</b>: posterior 90 % interval is {:.0} % of the prior's &mdash; the meters did not inform it (not identifiable from these data).",
                esc(&p.name),
                100.0 * p.width_ratio
            ));
        }
    }
    for c in &post.correlated_pairs {
        warn.push(format!(
            "<b>{}</b> and <b>{}</b> are strongly correlated in the posterior (&rho; = {:+.2}): the data constrain a combination, not each one.",
            esc(&c.a),
            esc(&c.b),
            c.rho
        ));
    }
    for (k, a) in s.acceptance_rate.iter().enumerate() {
        if !(0.05..=0.8).contains(a) {
            warn.push(format!(
                "Chain {k}: acceptance rate {:.1} % (outside 5&ndash;80 %): the proposal is badly scaled.",
                100.0 * a
            ));
        }
    }
    for m in &s.validation {
        if !g14_pass(m) {
            let not_fitted = if s.not_fitted.contains(&m.output) {
                " It was not fitted (<code>fit = false</code>): compared, not calibrated."
            } else {
                ""
            };
            warn.push(format!(
                "Output <b>{}</b>: the calibrated model fails ASHRAE Guideline 14 (NMBE {:.1} %, CV-RMSE {:.1} %).{not_fitted}",
                esc(&m.output),
                m.nmbe,
                m.cv_rmse
            ));
        }
    }
    let d = &s.design;
    if !d.failed.is_empty() {
        warn.push(format!(
            "EnergyPlus could not simulate {} design run(s): {} point(s) replaced by spare \
             hypercube points, {} dropped (<a href=\"#design\">design</a>).",
            d.failed.len(),
            d.replaced.len(),
            d.dropped.len()
        ));
    }
    h.push_str("<h2 id=\"warnings\">Warnings</h2>");
    if warn.is_empty() {
        h.push_str("<p class=\"pass\">None: chains mixed, every parameter informed, every output passes.</p>");
    } else {
        h.push_str("<ul class=\"warn\">");
        for w in &warn {
            let _ = write!(h, "<li>{w}</li>");
        }
        h.push_str("</ul>");
    }
    h
}

/// The design points EnergyPlus could not simulate (where the model is not valid), the
/// suggestions and the Severe messages accepted; nothing when there are none.
fn design_failures(s: &crate::io::Summary) -> String {
    let d = &s.design;
    if d.failed.is_empty() && d.notes.is_empty() {
        return String::new();
    }
    let mut h = String::new();
    h.push_str(
        "<h2 id=\"design\">Design points EnergyPlus could not simulate</h2>\
<p class=\"sub\">Each failed run was replaced by the spare hypercube point farthest from every \
point tried; the chains refuse proposals near the points where EnergyPlus failed. Values in \
calibration order.</p>",
    );
    if !d.failed.is_empty() {
        h.push_str("<table><tr><th>point</th><th class=\"l\">values</th><th class=\"l\">EnergyPlus</th></tr>");
        for f in &d.failed {
            let values: Vec<String> = s
                .parameters
                .iter()
                .zip(&f.values)
                .map(|(p, v)| format!("{} {}", esc(&p.name), g(*v)))
                .collect();
            let first = f
                .error
                .as_deref()
                .unwrap_or_default()
                .lines()
                .find(|l| l.contains("Severe") || l.contains("Fatal"))
                .unwrap_or_default();
            let _ = write!(
                h,
                "<tr><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td></tr>",
                f.slot,
                values.join(", "),
                esc(first)
            );
        }
        h.push_str("</table>");
    }
    if !d.suggestions.is_empty() {
        h.push_str("<ul>");
        for sg in &d.suggestions {
            let _ = write!(h, "<li>{}</li>", esc(sg));
        }
        h.push_str("</ul>");
    }
    if !d.notes.is_empty() {
        h.push_str("<p class=\"sub\">Severe messages after which the results were used:</p><ul>");
        for n in &d.notes {
            let _ = write!(h, "<li>point {}: {}</li>", n.point, esc(&n.message));
        }
        h.push_str("</ul>");
    }
    h
}

/// Goodness of fit (the reference's Table 5): Guideline 14 hourly metrics per output, initial,
/// calibrated and surrogate at the estimate, with the discrepancy and surrogate error.
fn goodness_of_fit(s: &crate::io::Summary) -> String {
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
        let n = c.or(i).map_or(0, |m| m.n);
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}{}</td><td>{n}</td>{}{}{}<td>{}</td><td>{}</td></tr>",
            esc(o),
            if s.not_fitted.contains(o) {
                " (not fitted)"
            } else {
                ""
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

/// The estimated parameters (the reference's Table 4): prior, posterior and estimate per
/// parameter (with the surrogate error carried in, where measured), and the correlated pairs.
fn parameters_table(s: &crate::io::Summary) -> String {
    let mut h = String::new();
    h.push_str("<h2 id=\"parameters\">Estimated parameters</h2>");
    let carried = s.surrogate_error.as_ref();
    if let Some(c) = carried {
        let _ = write!(
            h,
            "<p class=\"sub\">With surrogate error: the 90 % interval once the surrogate's error \
             in parameter space is added, as measured at the {} EnergyPlus points of refinement \
             round {} (what a calibration through that surrogate recovered from their outputs, \
             against their known values). The chains' own interval is narrower by that error; \
             read this one.</p>",
            c.points, c.round
        );
    }
    if let Some(t) = s.temperature.filter(|t| t.value != 1.0) {
        let why = match t.measured_at_round {
            Some(r) => format!(
                "measured from the surrogate's error at the EnergyPlus points of refinement \
                 round {r}, so that the 90 % intervals are expected to hold the truth for 90 % \
                 of the parameters when it lies that error away"
            ),
            None => "set in the project (<code>mcmc.temperature</code>)".into(),
        };
        let _ = write!(
            h,
            "<p class=\"sub\">Tempered likelihood: the chains sampled p(&theta;) \
             L(&theta;)<sup>1/T</sup> with T = {:.1}, {why}.</p>",
            t.value
        );
    }
    let _ = write!(
        h,
        "<table><tr><th class=\"l\">parameter</th><th class=\"l\">unit</th><th>prior min</th><th>mode</th><th>max</th>\
<th>prior 90 %</th><th>posterior mean &plusmn; sd</th><th>posterior 90 %</th>{}<th>estimate</th>\
<th>width ratio</th><th>R-hat</th><th>ESS bulk</th><th>ESS tail</th></tr>",
        if carried.is_some() {
            "<th>90 % with surrogate error</th>"
        } else {
            ""
        }
    );
    for (k, p) in s.parameters.iter().enumerate() {
        h.push_str(&parameter_row(s, k, p));
    }
    h.push_str("</table>");
    h.push_str(&correlated_pairs_table(&s.posterior));
    h
}

/// ` class="flag"` where a diagnostic misses its limit.
fn flag(missed: bool) -> &'static str {
    if missed {
        " class=\"flag\""
    } else {
        ""
    }
}

/// One row of the parameters table: the prior, the posterior's summary and diagnostics (each
/// flagged past its limit), the interval with the surrogate's error where it is carried, and
/// the estimate.
fn parameter_row(s: &crate::io::Summary, k: usize, p: &crate::io::PriorInfo) -> String {
    let mut h = String::new();
    let carried = s.surrogate_error.as_ref();
    let est = s
        .calibrated_values
        .iter()
        .find(|x| x.0 == p.name)
        .map_or(f64::NAN, |x| x.1);
    let p5 = analysis::triangular_quantile(p.prior_min, p.prior_mode, p.prior_max, 0.05);
    let p95 = analysis::triangular_quantile(p.prior_min, p.prior_mode, p.prior_max, 0.95);
    let _ = write!(
        h,
        "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}&ndash;{}</td>",
        esc(&p.name),
        esc(&p.unit),
        g(p.prior_min),
        g(p.prior_mode),
        g(p.prior_max),
        g(p5),
        g(p95)
    );
    let Some(q) = s.posterior.of(k, &p.name) else {
        let cols = if carried.is_some() { 8 } else { 7 };
        let _ = write!(h, "<td colspan=\"{cols}\">no posterior summary</td></tr>");
        return h;
    };
    let wr = flag(q.width_ratio > WIDTH_RATIO_LIMIT);
    let rh = flag(q.rhat > RHAT_LIMIT);
    let es = flag(q.ess_bulk < ESS_LIMIT);
    let with_error = carried.map_or(String::new(), |c| {
        c.parameters
            .iter()
            .find(|x| x.name == p.name)
            .map_or("<td>&ndash;</td>".into(), |x| {
                format!("<td>{}&ndash;{}</td>", g(x.q5), g(x.q95))
            })
    });
    let _ = write!(
        h,
        "<td>{} &plusmn; {}</td><td>{}&ndash;{}</td>{with_error}<td><b>{}</b></td><td{wr}>{}</td><td{rh}>{}</td><td{es}>{}</td><td>{}</td></tr>",
        g(q.mean),
        g(q.sd),
        g(q.q5),
        g(q.q95),
        g(est),
        f(q.width_ratio, 2),
        f(q.rhat, 3),
        f(q.ess_bulk, 0),
        f(q.ess_tail, 0)
    );
    h
}

/// The pairs of parameters whose posterior correlation exceeds 0.8 in magnitude (empty when
/// there are none).
fn correlated_pairs_table(post: &crate::io::PosteriorBlock) -> String {
    let mut h = String::new();
    if post.correlated_pairs.is_empty() {
        return h;
    }
    h.push_str("<h3>Correlated pairs (|&rho;| &gt; 0.8)</h3><table><tr><th class=\"l\">a</th><th class=\"l\">b</th><th>&rho;</th></tr>");
    for c in &post.correlated_pairs {
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{:+.3}</td></tr>",
            esc(&c.a),
            esc(&c.b),
            c.rho
        );
    }
    h.push_str("</table>");
    h
}

/// Prior vs posterior (the reference's Fig. 10): one figure per parameter.
fn prior_vs_posterior(cal: &CalibrationData) -> Result<String, ReportError> {
    let s = &cal.summary;
    let post = &s.posterior;
    let mut h = String::new();
    h.push_str("<h2 id=\"prior-posterior\">Prior vs posterior</h2>");
    h.push_str(&legend(&[
        (plots::PRIOR, "triangular prior", true),
        (
            plots::POSTERIOR,
            "posterior (histogram + KDE, all chains)",
            true,
        ),
        (plots::ESTIMATE, "estimate", true),
    ]));
    h.push_str(
        "<p class=\"sub\">Light blue band: posterior 90 % interval.</p><div class=\"grid\">",
    );
    for (k, p) in s.parameters.iter().enumerate() {
        let q = post.of(k, &p.name);
        let chains = cal
            .draws
            .column(&p.name)
            .ok_or_else(|| ReportError::Parse {
                path: cal.dir.join("draws.csv"),
                msg: format!("no column for parameter '{}' named in summary.json", p.name),
            })?;
        let pooled: Vec<f64> = chains.iter().flat_map(|c| c.iter().copied()).collect();
        let est = s
            .calibrated_values
            .iter()
            .find(|x| x.0 == p.name)
            .map(|x| x.1);
        let svg = plots::prior_posterior(&PriorPosterior {
            min: p.prior_min,
            mode: p.prior_mode,
            max: p.prior_max,
            samples: &pooled,
            estimate: est,
            q5: q.map_or(f64::NAN, |q| q.q5),
            q95: q.map_or(f64::NAN, |q| q.q95),
            unit: &p.unit,
        })?;
        let cap = format!(
            "<b>{}</b> &middot; estimate {} {}",
            esc(&p.name),
            est.map_or("&ndash;".into(), g),
            esc(&p.unit)
        );
        h.push_str(&figure(&svg, &cap));
    }
    h.push_str("</div>\n");
    Ok(h)
}

/// Chains: trace and rank plots per parameter, discrepancy and log posterior, with the
/// acceptance rates and R-hat flags.
fn chain_plots(cal: &CalibrationData) -> Result<String, ReportError> {
    let s = &cal.summary;
    let post = &s.posterior;
    let n_chains = cal.draws.chains.len();
    let mut h = String::new();
    h.push_str("<h2 id=\"chains\">Chains: trace and rank plots</h2>");
    let chain_items: Vec<(plotters::style::RGBColor, String)> = (0..n_chains)
        .map(|k| {
            (
                plots::PALETTE[k % plots::PALETTE.len()],
                format!("chain {k}"),
            )
        })
        .collect();
    let items: Vec<(plotters::style::RGBColor, &str, bool)> = chain_items
        .iter()
        .map(|(c, l)| (*c, l.as_str(), true))
        .collect();
    h.push_str(&legend(&items));
    let acc: Vec<String> = s
        .acceptance_rate
        .iter()
        .enumerate()
        .map(|(k, a)| format!("chain {k}: {:.1} %", 100.0 * a))
        .collect();
    let _ = write!(
        h,
        "<p class=\"sub\">Well-mixed chains overlap in the trace and have flat rank histograms \
(dashed: uniform). R-hat &gt; {RHAT_LIMIT} is flagged. Max R-hat {}, min bulk ESS {}. Acceptance: {}.</p>",
        f(post.max_rhat, 3),
        f(post.min_ess_bulk, 0),
        if acc.is_empty() { "&ndash;".into() } else { acc.join(", ") }
    );
    let mut trace_cols: Vec<(String, String, f64)> = s
        .parameters
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let r = post.of(k, &p.name).map_or(f64::NAN, |q| q.rhat);
            (p.name.clone(), p.unit.clone(), r)
        })
        .collect();
    for c in &cal.draws.columns {
        if c.starts_with("sigma_delta_") {
            trace_cols.push((c.clone(), "kWh".into(), f64::NAN));
        } else if c == "log_posterior" {
            trace_cols.push((c.clone(), String::new(), f64::NAN));
        }
    }
    for (name, unit, rhat) in &trace_cols {
        let Some(chains) = cal.draws.column(name) else {
            continue;
        };
        let svg = plots::trace_rank(&chains, unit)?;
        let flag = if rhat.is_finite() {
            if *rhat > RHAT_LIMIT {
                format!(" &middot; <span class=\"fail\">R-hat {rhat:.3} &gt; {RHAT_LIMIT}</span>")
            } else {
                format!(" &middot; <span class=\"pass\">R-hat {rhat:.3}</span>")
            }
        } else {
            String::new()
        };
        h.push_str(&figure(&svg, &format!("<b>{}</b>{flag}", esc(name))));
    }
    Ok(h)
}

/// Hourly measured vs calibrated (the reference's Fig. 11) per output: the year, daily; every
/// hour against the calibrated model; monthly totals; and the zoomed weeks.
fn hourly_fit(cal: &CalibrationData) -> Result<String, ReportError> {
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
                m.nmbe,
                m.cv_rmse,
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

/// The run: wall time per stage.
fn run_timings(s: &crate::io::Summary) -> String {
    let mut h = String::new();
    let t = &s.timings;
    h.push_str("<h2 id=\"run\">Run</h2><h3>Timings per stage</h3><table><tr><th class=\"l\">stage</th><th>wall time</th><th>share</th></tr>");
    for (name, v) in [
        ("design (Latin hypercube)", t.design_s),
        ("EnergyPlus design simulations", t.simulations_s),
        ("surrogate training", t.training_s),
        ("MCMC chains", t.chains_s),
        ("refinement simulations", t.refinement_s),
        ("posterior summary", t.summary_s),
        ("validation simulations", t.validation_s),
    ] {
        let share = if t.total_s > 0.0 {
            100.0 * v / t.total_s
        } else {
            f64::NAN
        };
        let _ = write!(
            h,
            "<tr><td class=\"l\">{name}</td><td>{}</td><td>{} %</td></tr>",
            duration(v),
            f(share, 1)
        );
    }
    let _ = write!(
        h,
        "<tr><th class=\"l\">total</th><th>{}</th><th></th></tr></table>",
        duration(t.total_s)
    );
    h
}

/// Surrogate refinement: each round's surrogate against EnergyPlus at the draws it added;
/// nothing without refinement rounds.
fn refinement(s: &crate::io::Summary) -> String {
    if s.refinement.is_empty() {
        return String::new();
    }
    let mut h = String::new();
    h.push_str(
        "<h3>Surrogate refinement</h3><p class=\"sub\">Each round simulates posterior \
draws in EnergyPlus, adds them to the training set and retrains; shown is the round's surrogate \
(before retraining) against EnergyPlus at those draws, their hours pooled.</p>\
<table><tr><th>round</th><th>draws added</th><th>failed</th>",
    );
    for o in &s.outputs {
        let _ = write!(h, "<th>{} NMBE / CV-RMSE %</th>", esc(o));
    }
    h.push_str("</tr>");
    for r in &s.refinement {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td>",
            r.round,
            r.points.len(),
            r.failed.len()
        );
        for o in &s.outputs {
            let m = r.surrogate_error.iter().find(|m| &m.output == o);
            let _ = write!(
                h,
                "<td>{}</td>",
                m.map_or("-".to_string(), |m| format!(
                    "{} / {}",
                    f(m.nmbe, 1),
                    f(m.cv_rmse, 1)
                ))
            );
        }
        h.push_str("</tr>");
    }
    h.push_str("</table>");
    h
}

/// The acceptance rate per chain.
fn acceptance_rates(s: &crate::io::Summary) -> String {
    let mut h = String::new();
    h.push_str("<h3>Acceptance rate per chain</h3><table><tr>");
    for k in 0..s.acceptance_rate.len() {
        let _ = write!(h, "<th>chain {k}</th>");
    }
    h.push_str("</tr><tr>");
    for a in &s.acceptance_rate {
        let _ = write!(h, "<td>{:.1} %</td>", 100.0 * a);
    }
    h.push_str("</tr></table>");
    h
}

/// The surrogate on held-out design points; nothing when summary.json has no metrics.
fn surrogate_on_held_out(s: &crate::io::Summary) -> String {
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

fn precal_section(h: &mut String, p: &PrecalData) -> Result<(), ReportError> {
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
        let hours: Vec<_> = p
            .schedule
            .iter()
            .filter(|s| &s.day_type == t)
            .cloned()
            .collect();
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
        let hours: Vec<_> = p
            .schedule
            .iter()
            .filter(|s| &s.day_type == t)
            .cloned()
            .collect();
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
