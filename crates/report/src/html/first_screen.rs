//! The report's first screen after its header: the banners (not converged, out of reach), the
//! warnings and the design points EnergyPlus could not simulate.

use std::fmt::Write as _;

use bemcal_calibrate::Summary;
use bemcal_stats::model_form::Verdict;

use super::{esc, fit::g14_pass, g, ESS_LIMIT, RHAT_LIMIT};
use crate::informed::{uninformed, what_bills_say, why_uninformed};

/// A banner on the first screen naming the meters no posterior draw of the model reaches.
pub(super) fn out_of_reach_banner(s: &Summary) -> String {
    let out: Vec<&str> = s
        .model_form
        .iter()
        .flat_map(|m| &m.meters)
        .filter(|o| o.reach.verdict == Verdict::Level && !o.reach.within_draws)
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
pub(super) fn not_converged_banner(s: &Summary) -> String {
    let num = |x: f64, d: usize| {
        if x.is_nan() {
            "n/a".to_string()
        } else {
            format!("{x:.d$}")
        }
    };
    let c = &s.convergence;
    // A verdict that missed its targets names a parameter short of them; none: a summary
    // written before the verdict was recorded (the writer's default).
    let detail = if c.shortfalls.is_empty() {
        format!("max R-hat {:.3}.", s.posterior.max_rhat)
    } else {
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
    };
    format!(
        "<div class=\"banner\" id=\"not-converged\"><b>Not converged.</b> {detail} The chains \
         have not mixed: the estimate, the intervals and the validation below are not a \
         calibration yet. Run longer chains (<code>[mcmc] iterations</code> or \
         <code>max_extensions</code>; they continue from their checkpoint in the same output \
         folder).</div>\n"
    )
}

/// The chains' modes ([`crate::modes::modes_sentence`]) as a sentence of the warnings.
fn modes_warning(post: &bemcal_stats::summary::PosteriorSummary) -> Option<String> {
    let sentence = crate::modes::modes_sentence(post.modes.as_ref()?, &post.parameters);
    let mut chars = sentence.chars();
    let first: String = (chars.next())
        .map(|c| c.to_uppercase().collect())
        .unwrap_or_default();
    Some(esc(&format!("{first}{}.", chars.as_str())))
}

/// Warnings: R-hat, bulk ESS, uninformed parameters, correlated pairs, acceptance rates,
/// Guideline 14 failures and design runs EnergyPlus could not simulate.
pub(super) fn warnings(s: &Summary) -> String {
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
    let barely: Vec<String> = post
        .parameters
        .iter()
        .filter(|p| uninformed(p.width_ratio))
        .map(|p| format!("<b>{}</b> ({:.0} %)", esc(&p.name), 100.0 * p.width_ratio))
        .collect();
    if !barely.is_empty() {
        let t = s.temperature.value;
        warn.push(format!(
            "{} Their intervals against the prior's: {}.",
            esc(&why_uninformed(barely.len(), post.parameters.len(), t)),
            barely.join(", ")
        ));
    }
    if let Some(note) = what_bills_say(&s.billed_outputs()) {
        warn.push(esc(&note));
    }
    warn.extend(modes_warning(post));
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
                m.metrics.nmbe,
                m.metrics.cv_rmse
            ));
        }
    }
    if let Some(note) = mapped_estimate_note(s) {
        warn.push(esc(note));
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

/// Where a point of the output space mapping became the estimate (not a posterior draw), the
/// note that says so and which parameters lie outside the posterior's intervals there.
fn mapped_estimate_note(s: &Summary) -> Option<&str> {
    s.estimate_choice.as_ref()?.chose_mapped().then_some(())?;
    s.estimate_note.as_deref()
}

/// The design points EnergyPlus could not simulate (where the model is not valid), the
/// suggestions and the Severe messages accepted; nothing when there are none.
pub(super) fn design_failures(s: &Summary) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The fixture summary with the estimate `chosen` by `best_simulated`.
    fn summary(chosen: &str) -> Summary {
        let mut s = crate::io::fixture::summary();
        s.estimate_note = Some(
            "output space mapping from predictive_04 found mapped_02 ... It is not a posterior \
             draw: 12 parameter(s) lie outside"
                .into(),
        );
        s.estimate_choice.as_mut().unwrap().chosen = chosen.into();
        s
    }

    #[test]
    fn a_mapped_estimate_is_a_warning_and_a_posterior_draw_is_not() {
        let w = warnings(&summary("mapped_02"));
        assert!(
            w.contains("It is not a posterior draw: 12 parameter(s)"),
            "{w}"
        );
        let w = warnings(&summary("predictive_04"));
        assert!(!w.contains("not a posterior draw"), "{w}");
    }
}
