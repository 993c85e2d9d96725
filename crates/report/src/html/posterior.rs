//! The posterior: the parameter table, correlated pairs, prior vs posterior, the chains' traces,
//! and how the run got there (stage timings, refinement rounds, acceptance rates).

use std::fmt::Write as _;

use bemcal_calibrate::{ParameterReport, Summary};
use bemcal_stats::summary::{ParameterSummary, PosteriorSummary};

use super::{duration, esc, f, figure, g, legend, ESS_LIMIT, RHAT_LIMIT};
use crate::analysis;
use crate::error::ReportError;
use crate::informed::uninformed;
use crate::io::CalibrationData;
use crate::plots::{self, PriorPosterior};
use crate::recovery;

/// The estimated parameters (the reference's Table 4): prior, posterior and estimate per
/// parameter (with the surrogate error carried in, where measured), and the correlated pairs.
pub(super) fn parameters_table(s: &Summary) -> String {
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
    if let Some(t) = Some(s.temperature).filter(|t| t.value != 1.0) {
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

/// The posterior of the `k`-th prior, `name`: found by name, else by position (summaries whose
/// rows carry no names).
fn posterior_of<'a>(
    post: &'a PosteriorSummary,
    k: usize,
    name: &str,
) -> Option<&'a ParameterSummary> {
    post.parameters
        .iter()
        .find(|x| x.name == name)
        .or(post.parameters.get(k))
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
fn parameter_row(s: &Summary, k: usize, p: &ParameterReport) -> String {
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
    let Some(q) = posterior_of(&s.posterior, k, &p.name) else {
        let cols = if carried.is_some() { 8 } else { 7 };
        let _ = write!(h, "<td colspan=\"{cols}\">no posterior summary</td></tr>");
        return h;
    };
    let wr = flag(uninformed(q.width_ratio));
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
fn correlated_pairs_table(post: &PosteriorSummary) -> String {
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

/// A synthetic run's hidden truth beside the posterior ([`crate::truth`]): how many truths lie
/// inside their 90 % interval, and each miss with its reason (empty without a truth).
pub(super) fn truth_table(cal: &CalibrationData) -> String {
    let Some(r) = &cal.truth else {
        return String::new();
    };
    let mut h = String::new();
    let misses = r.rows.len() - r.inside();
    let (central_inside, central) = r.central();
    let unexplained = r.unexplained();
    let carried = r.with_surrogate_error();
    let which = if carried {
        format!(
            " with the surrogate's error carried in (the chains' own: {} of {})",
            r.inside_own(),
            r.rows.len()
        )
    } else {
        String::new()
    };
    let _ = write!(
        h,
        "<h2 id=\"truth\">Recovered against the hidden truth</h2><p class=\"sub\">The truth \
         lies inside the posterior 90 % interval for <b>{} of {}</b> parameters{which}; of the \
         {central} truths inside their prior's central 90 %, {central_inside} lie inside their \
         posterior interval. {}{}A 90 % \
         interval holds the truth 90 % of the time on average over truths drawn from the prior \
         (Talts et al. 2018); a truth in its prior's outer tails is left out where the meters say \
         little about the parameter, and a strongly correlated pair is judged by the combination \
         the meters identify.</p>",
        r.inside(),
        r.rows.len(),
        match (misses, unexplained) {
            (0, _) => String::new(),
            (1, 0) => "The one miss is explained below. ".into(),
            (m, 0) => format!("Each of the {m} misses is explained below. "),
            (m, u) => format!(
                "<span class=\"fail\">{u} of the {m} misses {} not explained.</span> ",
                if u == 1 { "is" } else { "are" }
            ),
        },
        if r.without_truth.is_empty() {
            String::new()
        } else {
            format!(
                "Not counted, without a truth in the file: {}. ",
                esc(&r.without_truth.join(", "))
            )
        }
    );
    let _ = write!(
        h,
        "<table><tr><th class=\"l\">parameter</th><th>truth</th><th>estimate</th>\
<th>posterior 90 %</th>{}<th>inside</th><th>truth's prior quantile</th><th>width ratio</th>\
<th class=\"l\">miss explained by</th></tr>",
        if carried {
            "<th>90 % with surrogate error</th>"
        } else {
            ""
        }
    );
    for row in &r.rows {
        let (inside, why) = match &row.miss {
            None => ("<td class=\"pass\">yes</td>".to_string(), String::new()),
            Some(m) => (
                format!(
                    "<td{}>no, {}</td>",
                    if m.explained() { "" } else { " class=\"fail\"" },
                    if m.outside_by.is_finite() {
                        format!("by {}", recovery::percent(m.outside_by))
                    } else {
                        "the interval has no width".into()
                    }
                ),
                esc(&m.describe()),
            ),
        };
        let with_error = match (carried, row.with_surrogate_error) {
            (false, _) => String::new(),
            (true, None) => "<td>&ndash;</td>".into(),
            (true, Some([lo, hi])) => format!("<td>{}&ndash;{}</td>", g(lo), g(hi)),
        };
        let _ = write!(
            h,
            "<tr><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}&ndash;{}</td>{with_error}\
{inside}<td>{}</td><td>{}</td><td class=\"l\">{why}</td></tr>",
            esc(&row.name),
            g(row.truth),
            row.estimate.map_or("&ndash;".into(), g),
            g(row.q5),
            g(row.q95),
            row.prior_quantile
                .map_or("&ndash;".into(), recovery::percent),
            f(row.width_ratio, 2),
        );
    }
    h.push_str(
        "</table><p class=\"sub\">A miss's size is its distance outside the interval in widths \
         of the interval; the width ratio is the posterior interval's width over the prior's \
         (near 1: the meters said little).</p>",
    );
    h
}

/// Prior vs posterior (the reference's Fig. 10): one figure per parameter.
pub(super) fn prior_vs_posterior(cal: &CalibrationData) -> Result<String, ReportError> {
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
        let q = posterior_of(post, k, &p.name);
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
pub(super) fn chain_plots(cal: &CalibrationData) -> Result<String, ReportError> {
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
            let r = posterior_of(post, k, &p.name).map_or(f64::NAN, |q| q.rhat);
            (p.name.clone(), p.unit.clone(), r)
        })
        .collect();
    for c in cal.draws.noise() {
        trace_cols.push((c.clone(), "kWh".into(), f64::NAN));
    }
    if cal.draws.columns.iter().any(|c| c == "log_posterior") {
        trace_cols.push(("log_posterior".into(), String::new(), f64::NAN));
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

/// The run: wall time per stage.
pub(super) fn run_timings(s: &Summary) -> String {
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
        ("savings simulations", t.savings_s),
    ]
    .into_iter()
    // The savings only where the calibration estimated them.
    .filter(|(name, v)| !(name.starts_with("savings") && *v == 0.0))
    {
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
pub(super) fn refinement(s: &Summary) -> String {
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
                    f(m.metrics.nmbe, 1),
                    f(m.metrics.cv_rmse, 1)
                ))
            );
        }
        h.push_str("</tr>");
    }
    h.push_str("</table>");
    h
}

/// The acceptance rate per chain.
pub(super) fn acceptance_rates(s: &Summary) -> String {
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
