//! What a synthetic run's truth against the posterior found ([`Recovery`], judged by
//! `truth::recovery`): one row per parameter with a truth ([`TruthRow`]), each miss
//! and its reasons ([`Miss`], [`Reason`]), and how the report and the CLI word them. Pure.

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
}
