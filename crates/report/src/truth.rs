//! A synthetic calibration's hidden truth (`bemcal synthesize --truth FILE`) beside what the
//! calibration recovered: whether each true value lies inside its posterior 90 % interval and,
//! where it does not, why (pure). The interval is the one the report says to read: with the
//! surrogate's error carried in where the calibration measured it (`summary.json`
//! `surrogate_error`), else the chains' own; the chains' own is judged beside it.
//!
//! A posterior 90 % interval holds the truth 90 % of the time *on average over truths drawn
//! from the prior* (the self-consistency that simulation-based calibration checks: Talts et al.
//! 2018, "Validating Bayesian inference algorithms with simulation-based calibration",
//! arXiv:1804.06788); one truth can be missed for a reason that says nothing against the
//! calibration. A miss is explained ([`Reason`]) when
//! - the truth lies in its prior's outer tails, below the prior's 5 % or above its 95 %
//!   quantile: where the meters say little about a parameter its posterior follows its prior,
//!   whose central 90 % leaves such a truth out whatever the sampler does (the interval's
//!   width against the prior's says how little the data said); or
//! - the parameter is strongly correlated with another (`posterior.correlated_pairs`): the
//!   meters identify a combination of the pair rather than each, and the combination is
//!   recovered when the truth's value of it lies inside the draws' 90 % interval of it (the
//!   chains' own draws: the surrogate's error is carried into each parameter's interval, not
//!   into the pair's).
//!
//! Counts are over the calibrated parameters the truth file names; those it does not name are
//! listed ([`Recovery::without_truth`]). This module judges ([`recovery`]); what it finds, the
//! rows and each miss's reasons, is [`crate::recovery`]'s, which the folder's reader and the
//! report read.

use std::collections::BTreeMap;

use bemcal_calibrate::Summary;
use bemcal_stats::diagnostics::{mean, sd};

use crate::analysis::{quantile, triangular_cdf};
use crate::io::Draws;
use crate::recovery::{in_prior_tails, Miss, Reason, Recovery, TruthRow};

/// The truth of each parameter of `summary` that `truth` names, against its posterior; the
/// pairs' combinations from `draws` (module doc).
pub fn recovery(truth: &BTreeMap<String, f64>, summary: &Summary, draws: &Draws) -> Recovery {
    let estimates: BTreeMap<&str, f64> = summary
        .calibrated_values
        .iter()
        .map(|(n, v)| (n.as_str(), *v))
        .collect();
    let rows = summary
        .posterior
        .parameters
        .iter()
        .filter_map(|p| {
            let t = *truth.get(&p.name)?;
            let prior_quantile = summary
                .parameters
                .iter()
                .find(|q| q.name == p.name)
                .map(|q| triangular_cdf(q.prior_min, q.prior_mode, q.prior_max, t));
            let with_surrogate_error = summary.surrogate_error.as_ref().and_then(|c| {
                let x = c.parameters.iter().find(|x| x.name == p.name)?;
                Some([x.q5, x.q95])
            });
            let [lo, hi] = with_surrogate_error.unwrap_or([p.q5, p.q95]);
            let miss = (!(lo <= t && t <= hi)).then(|| {
                let width = hi - lo;
                let off = if t < lo { lo - t } else { t - hi };
                let mut reasons = Vec::new();
                if let Some(q) = prior_quantile.filter(|&q| in_prior_tails(q)) {
                    reasons.push(Reason::PriorTail { quantile: q });
                }
                for pair in &summary.posterior.correlated_pairs {
                    let partner = match (&pair.a, &pair.b) {
                        (a, b) if *a == p.name => b,
                        (a, b) if *b == p.name => a,
                        _ => continue,
                    };
                    let combination_inside = truth.get(partner).and_then(|&tb| {
                        combination_inside(draws, (&p.name, t), (partner, tb), pair.rho)
                    });
                    reasons.push(Reason::Pair {
                        partner: partner.clone(),
                        rho: pair.rho,
                        combination_inside,
                    });
                }
                Miss {
                    outside_by: if width > 0.0 {
                        off / width
                    } else {
                        f64::INFINITY
                    },
                    reasons,
                }
            });
            Some(TruthRow {
                name: p.name.clone(),
                truth: t,
                estimate: estimates.get(p.name.as_str()).copied(),
                q5: p.q5,
                q95: p.q95,
                with_surrogate_error,
                inside_own: p.q5 <= t && t <= p.q95,
                prior_quantile,
                width_ratio: p.width_ratio,
                miss,
            })
        })
        .collect();
    let without_truth = (summary.posterior.parameters.iter())
        .filter(|p| !truth.contains_key(&p.name))
        .map(|p| p.name.clone())
        .collect();
    Recovery {
        rows,
        without_truth,
    }
}

/// Whether the truth's value of a correlated pair's identified combination lies inside the
/// draws' 90 % interval of it. With both parameters standardised by their posterior mean and
/// sd, the pair's posterior correlation matrix `[[1, rho], [rho, 1]]` has its small-variance
/// axis along `(1, -sign(rho))`: `z_a - sign(rho) z_b` is what the meters identify, and the
/// other axis is the ridge along which the pair trades off. `None` without the draws of both.
fn combination_inside(
    draws: &Draws,
    (a, ta): (&str, f64),
    (b, tb): (&str, f64),
    rho: f64,
) -> Option<bool> {
    let xa: Vec<f64> = draws.column(a)?.concat();
    let xb: Vec<f64> = draws.column(b)?.concat();
    if xa.len() < 2 || xa.len() != xb.len() {
        return None;
    }
    let ((ma, sa), (mb, sb)) = ((mean(&xa), sd(&xa)), (mean(&xb), sd(&xb)));
    if !(sa > 0.0 && sb > 0.0) {
        return None;
    }
    let s = rho.signum();
    let c = |va: f64, vb: f64| (va - ma) / sa - s * (vb - mb) / sb;
    let combined: Vec<f64> = xa.iter().zip(&xb).map(|(&va, &vb)| c(va, vb)).collect();
    let ct = c(ta, tb);
    Some(quantile(&combined, 0.05) <= ct && ct <= quantile(&combined, 0.95))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn draws(columns: &[(&str, Vec<f64>)]) -> Draws {
        Draws {
            columns: columns.iter().map(|(n, _)| n.to_string()).collect(),
            chains: vec![columns.iter().map(|(_, v)| v.clone()).collect()],
            numbers: vec![(0..columns[0].1.len() as u64).collect()],
            numbering: Default::default(),
        }
    }

    #[test]
    fn a_pair_on_a_ridge_is_judged_by_its_identified_combination() {
        // a + b = 1 up to small noise, each spread along the ridge: rho about -1; the identified
        // combination is z_a + z_b.
        let n = 2000;
        let a: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let b: Vec<f64> = (0..n)
            .map(|i| 1.0 - a[i] + 0.01 * ((i * 7919 % 101) as f64 / 100.0 - 0.5))
            .collect();
        let d = draws(&[("a", a), ("b", b)]);
        // A truth far along the ridge (a = 1.4, b = -0.4) keeps a + b = 1: recovered.
        assert_eq!(
            combination_inside(&d, ("a", 1.4), ("b", -0.4), -0.99),
            Some(true)
        );
        // Off the ridge (a + b = 1.3): not.
        assert_eq!(
            combination_inside(&d, ("a", 0.8), ("b", 0.5), -0.99),
            Some(false)
        );
        assert_eq!(combination_inside(&d, ("a", 0.8), ("c", 0.5), -0.99), None);
    }
}
