//! Assembles the report: tables and inline SVG figures in one HTML string (pure). [`build`]
//! writes the page in its order, one module per part: the header and shared helpers here, then
//! [`first_screen`] (banners, warnings, failed design points), [`fit`] (Guideline 14, predictive
//! coverage, model form, plots of the fit), [`posterior`] (parameters, chains, how the run got
//! there) and [`precal`] (pre-calibration).

use std::fmt::Write as _;

use crate::error::ReportError;
use bemcal_calibrate::Summary;

use crate::io::{CalibrationData, PrecalData};

mod first_screen;
mod fit;
mod posterior;
mod precal;
mod savings;

use crate::informed::how_much_learned;
use first_screen::{design_failures, not_converged_banner, out_of_reach_banner, warnings};
use fit::{
    discrepancy_carried, goodness_of_fit, held_out_weeks, hourly_fit, model_form,
    monthly_and_held_out, predictive_coverage, surrogate_on_held_out,
};
use posterior::{
    acceptance_rates, chain_plots, parameters_table, prior_vs_posterior, refinement, run_timings,
    truth_table,
};
use precal::precal_section;
use savings::savings_section;

/// ASHRAE Guideline 14 hourly NMBE limit, % (absolute value).
pub const G14_NMBE_LIMIT: f64 = 10.0;
/// ASHRAE Guideline 14 hourly CV-RMSE limit, %.
pub const G14_CV_RMSE_LIMIT: f64 = 30.0;
/// R-hat above this is flagged (chains have not mixed).
pub const RHAT_LIMIT: f64 = 1.01;
/// Bulk ESS below this is flagged.
pub const ESS_LIMIT: f64 = 400.0;

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

/// The whole report as one self-contained HTML document.
pub fn build(cal: &CalibrationData, precal: Option<&PrecalData>) -> Result<String, ReportError> {
    let s = &cal.summary;
    let mut h = String::with_capacity(1 << 20);
    h.push_str(&header(cal));
    if !s.converged {
        h.push_str(&not_converged_banner(s));
    }
    h.push_str(&out_of_reach_banner(s));
    h.push_str(&nav(
        precal.is_some(),
        cal.truth.is_some(),
        s.savings.is_some(),
    ));
    h.push_str(&warnings(s));
    h.push_str(&design_failures(s));
    h.push_str(&goodness_of_fit(s));
    h.push_str(&monthly_and_held_out(s));
    h.push_str(&predictive_coverage(s));
    h.push_str(&model_form(s)?);
    h.push_str(&discrepancy_carried(s));
    h.push_str(&held_out_weeks(cal)?);
    h.push_str(&parameters_table(s));
    h.push_str(&truth_table(cal));
    h.push_str(&savings_section(s)?);
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
        esc(&estimate_label(s))
    );
    let ratios: Vec<f64> = (s.posterior.parameters.iter())
        .map(|p| p.width_ratio)
        .collect();
    let _ = writeln!(
        h,
        "<p class=\"sub\" id=\"learned\">How much it learned: {}.</p>",
        esc(&how_much_learned(
            &ratios,
            s.temperature.value,
            s.temperature.pooled_with_buildings
        ))
    );
    h
}

/// Which point the estimate is: the setting, and with `best_simulated` which draw and why.
fn estimate_label(s: &Summary) -> String {
    let setting = s.estimate.as_str().to_string();
    let Some(c) = &s.estimate_choice else {
        return setting;
    };
    let n = c.candidates.len();
    let map = c.candidates.first().filter(|f| f.label == "calibrated");
    let map_passes = map.and_then(|f| f.limit_ratio).is_some_and(|r| r <= 1.0);
    let map_misses_monthly = map_passes
        && map
            .and_then(|f| f.monthly_limit_ratio)
            .is_some_and(|r| r > 1.0);
    let why = match (c.chosen == "calibrated", map, map_passes) {
        (true, _, true) if map_misses_monthly => format!(
            "the MAP draw: EnergyPlus passes Guideline 14 hourly there and misses its monthly \
             criteria, and passes both at none of the other {} points it simulated",
            n - 1
        ),
        (false, Some(_), true) => format!(
            "{}: EnergyPlus passes Guideline 14 hourly at the MAP draw but misses its monthly \
             criteria there, and passes both at this one ({n} points simulated)",
            c.chosen
        ),
        _ if c.chose_mapped() => format!(
            "{}: a point found by output space mapping, not a posterior draw: EnergyPlus fails \
             Guideline 14 hourly at every posterior draw it simulated and passes at this one \
             ({n} points simulated)",
            c.chosen
        ),
        (true, _, true) => "the MAP draw: EnergyPlus passes Guideline 14 hourly there".to_string(),
        (true, _, false) => format!(
            "the MAP draw: it fails Guideline 14 hourly, and no other of the {n} points \
             EnergyPlus simulated fits better"
        ),
        (false, Some(_), _) => format!(
            "{}: EnergyPlus fails Guideline 14 hourly at the MAP draw and fits this one best of \
             {n} draws",
            c.chosen
        ),
        (false, None, _) => format!(
            "{}: EnergyPlus could not simulate the MAP draw and fits this one best of the {n} \
             draws it simulated",
            c.chosen
        ),
    };
    format!("{setting} ({why})")
}

/// The navigation bar: a link to each section (the truth's, the savings' and the
/// pre-calibration's where there are).
fn nav(with_precal: bool, with_truth: bool, with_savings: bool) -> String {
    let mut h = String::new();
    h.push_str(
        "<nav><a href=\"#warnings\">Warnings</a><a href=\"#metrics\">Goodness of fit</a>\
<a href=\"#parameters\">Parameters</a>",
    );
    if with_truth {
        h.push_str("<a href=\"#truth\">Truth</a>");
    }
    if with_savings {
        h.push_str("<a href=\"#savings\">Savings</a>");
    }
    h.push_str(
        "<a href=\"#prior-posterior\">Prior vs posterior</a>\
<a href=\"#chains\">Chains</a><a href=\"#fit\">Measured vs calibrated</a><a href=\"#run\">Run</a>",
    );
    if with_precal {
        h.push_str("<a href=\"#precal\">Pre-calibration</a>");
    }
    h.push_str("</nav>\n");
    h
}
