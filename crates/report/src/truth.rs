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
//! listed ([`Recovery::without_truth`]).

use std::collections::BTreeMap;

use crate::analysis::{mean_sd, quantile, triangular_cdf};
use crate::io::{Draws, Summary};

/// The prior quantiles outside which a truth counts as in its prior's outer tails.
pub const PRIOR_TAILS: (f64, f64) = (0.05, 0.95);

/// One parameter's truth against its posterior.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthRow {
    /// Parameter name.
    pub name: String,
    /// The hidden true value.
    pub truth: f64,
    /// The calibrated value (`calibrated_values`), if written.
    pub estimate: Option<f64>,
    /// Posterior 5 % quantile (the chains' own).
    pub q5: f64,
    /// Posterior 95 % quantile (the chains' own).
    pub q95: f64,
    /// The 90 % interval with the surrogate's error carried in, where measured.
    pub with_surrogate_error: Option<[f64; 2]>,
    /// Whether the truth lies inside the chains' own `[q5, q95]`.
    pub inside_own: bool,
    /// The truth's quantile in its (triangular) prior, if the prior is known.
    pub prior_quantile: Option<f64>,
    /// Posterior 90 % interval width over the prior's.
    pub width_ratio: f64,
    /// `None` when the truth lies inside the interval to read ([`TruthRow::interval`]).
    pub miss: Option<Miss>,
}

impl TruthRow {
    /// The interval the truth is judged by: with the surrogate's error where measured, else
    /// the chains' own.
    pub fn interval(&self) -> [f64; 2] {
        self.with_surrogate_error.unwrap_or([self.q5, self.q95])
    }
}

/// A truth outside its posterior 90 % interval.
#[derive(Debug, Clone, PartialEq)]
pub struct Miss {
    /// How far outside, in widths of the interval.
    pub outside_by: f64,
    /// Why; empty when nothing explains it.
    pub reasons: Vec<Reason>,
}

/// Why a truth may lie outside its interval (module doc).
#[derive(Debug, Clone, PartialEq)]
pub enum Reason {
    /// The truth lies in its prior's outer tails ([`PRIOR_TAILS`]).
    PriorTail {
        /// The truth's prior quantile.
        quantile: f64,
    },
    /// The parameter is strongly correlated with `partner`.
    Pair {
        /// The other parameter.
        partner: String,
        /// Their posterior correlation.
        rho: f64,
        /// Whether the truth's value of the pair's identified combination lies inside the
        /// draws' 90 % interval of it (`None` without the partner's truth or draws).
        combination_inside: Option<bool>,
    },
}

impl std::fmt::Display for Reason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Reason::PriorTail { quantile } => write!(
                f,
                "the truth in its prior's outer tails (its {} quantile)",
                percent(*quantile)
            ),
            Reason::Pair {
                partner,
                rho,
                combination_inside,
            } => write!(
                f,
                "correlated with {partner} (r {rho:+.2}): the pair's identified combination {}",
                match combination_inside {
                    Some(true) => "is recovered",
                    Some(false) => "is not recovered",
                    None => "cannot be judged (no truth or draws of the partner)",
                }
            ),
        }
    }
}

impl Miss {
    /// How far outside, in words: "by 13 % of its interval's width", or of a zero-width
    /// interval.
    pub fn distance(&self) -> String {
        if self.outside_by.is_finite() {
            format!("by {} of its interval's width", percent(self.outside_by))
        } else {
            "of a zero-width interval".into()
        }
    }

    /// The reasons in words, or why none applies.
    pub fn describe(&self) -> String {
        if self.reasons.is_empty() {
            return "nothing: not in its prior's tails, no strongly correlated partner".into();
        }
        let words: Vec<String> = self.reasons.iter().map(ToString::to_string).collect();
        words.join("; ")
    }

    /// Whether some [`Reason`] explains the miss: the truth in its prior's tails, or a pair
    /// whose identified combination is recovered.
    pub fn explained(&self) -> bool {
        self.reasons.iter().any(|r| match r {
            Reason::PriorTail { .. } => true,
            Reason::Pair {
                combination_inside, ..
            } => *combination_inside == Some(true),
        })
    }
}

/// Every parameter with a truth, in calibration order.
#[derive(Debug, Clone, PartialEq)]
pub struct Recovery {
    /// One row per parameter that has a true value.
    pub rows: Vec<TruthRow>,
    /// Calibrated parameters the truth file does not name (not counted).
    pub without_truth: Vec<String>,
}

impl Recovery {
    /// Truths inside their posterior 90 % interval (the one to read).
    pub fn inside(&self) -> usize {
        self.rows.iter().filter(|r| r.miss.is_none()).count()
    }

    /// Whether the intervals judged carry the surrogate's error.
    pub fn with_surrogate_error(&self) -> bool {
        self.rows.iter().any(|r| r.with_surrogate_error.is_some())
    }

    /// Truths inside the chains' own 90 % interval.
    pub fn inside_own(&self) -> usize {
        self.rows.iter().filter(|r| r.inside_own).count()
    }

    /// Misses that nothing explains.
    pub fn unexplained(&self) -> usize {
        self.rows
            .iter()
            .filter(|r| r.miss.as_ref().is_some_and(|m| !m.explained()))
            .count()
    }

    /// `(inside, of)`: of the truths inside their prior's central 90 %, those inside the
    /// posterior's 90 % interval (the truths the prior gave a fair chance).
    pub fn central(&self) -> (usize, usize) {
        let central: Vec<&TruthRow> = self
            .rows
            .iter()
            .filter(|r| {
                r.prior_quantile
                    .is_some_and(|q| (PRIOR_TAILS.0..=PRIOR_TAILS.1).contains(&q))
            })
            .collect();
        (
            central.iter().filter(|r| r.miss.is_none()).count(),
            central.len(),
        )
    }
}

/// Whether a prior quantile lies in the prior's outer tails ([`PRIOR_TAILS`]; not for NaN).
pub fn in_prior_tails(q: f64) -> bool {
    q.is_finite() && !(PRIOR_TAILS.0..=PRIOR_TAILS.1).contains(&q)
}

/// A share as a percentage, to one decimal below 1 % and between 99 and 100 % (rounded down
/// there, so that it never reads 100 short of it), else whole.
pub fn percent(share: f64) -> String {
    let pct = 100.0 * share;
    if pct > 99.0 && pct < 100.0 {
        format!("{:.1} %", (pct * 10.0).floor() / 10.0)
    } else if pct < 1.0 {
        format!("{pct:.1} %")
    } else {
        format!("{pct:.0} %")
    }
}

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
    let ((ma, sa), (mb, sb)) = (mean_sd(&xa), mean_sd(&xb));
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

    #[test]
    fn tails_and_percentages() {
        assert!(in_prior_tails(0.01) && in_prior_tails(0.97));
        assert!(!in_prior_tails(0.05) && !in_prior_tails(0.5) && !in_prior_tails(f64::NAN));
        assert_eq!(percent(0.002), "0.2 %");
        assert_eq!(percent(0.13), "13 %");
        assert_eq!(percent(0.9996), "99.9 %");
        assert_eq!(percent(1.46), "146 %");
        let far = Miss {
            outside_by: f64::INFINITY,
            reasons: vec![],
        };
        assert_eq!(far.distance(), "of a zero-width interval");
        assert!(!far.explained());
        let tail = Miss {
            outside_by: 0.13,
            reasons: vec![Reason::PriorTail { quantile: 0.001 }],
        };
        assert_eq!(tail.distance(), "by 13 % of its interval's width");
        assert!(tail.explained());
    }

    fn draws(columns: &[(&str, Vec<f64>)]) -> Draws {
        Draws {
            columns: columns.iter().map(|(n, _)| n.to_string()).collect(),
            chains: vec![columns.iter().map(|(_, v)| v.clone()).collect()],
            numbers: vec![(0..columns[0].1.len() as u64).collect()],
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
