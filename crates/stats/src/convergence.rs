//! Whether merged chains have converged: every parameter's rank-normalised split R-hat at or
//! below a target and its bulk and tail ESS at or above one, the thresholds of Vehtari,
//! Gelman, Simpson, Carpenter and Bürkner (2021), "Rank-normalization, folding, and
//! localization: an improved R-hat for assessing convergence of MCMC", Bayesian Analysis
//! 16(2), 667-718, section 4: R-hat < 1.01, and ESS > 100 per chain (400 for four chains).
//!
//! One verdict ([`assess`]) that every consumer reads: the drivers (extend the chains or
//! stop), `summary.json`, the CLI's exit status and the report's banner.

use serde::{Deserialize, Serialize};

use crate::summary::PosteriorSummary;

/// The targets a converged posterior meets (Vehtari et al. 2021, section 4).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Targets {
    /// Largest acceptable R-hat (1.01).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub rhat: f64,
    /// Smallest acceptable bulk and tail ESS over all chains together (400).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub ess: f64,
}

impl Default for Targets {
    fn default() -> Self {
        Targets {
            rhat: 1.01,
            ess: 400.0,
        }
    }
}

/// A parameter that misses at least one target, with its figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Shortfall {
    /// Parameter name.
    pub parameter: String,
    /// Its R-hat.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub rhat: f64,
    /// Its bulk ESS.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub ess_bulk: f64,
    /// Its tail ESS.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub ess_tail: f64,
}

/// The verdict on a set of merged chains.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Convergence {
    /// Every parameter meets every target.
    pub converged: bool,
    /// The targets judged against.
    pub targets: Targets,
    /// Largest R-hat over parameters (NaN counts as not converged).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub max_rhat: f64,
    /// Smallest bulk ESS over parameters.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub min_ess_bulk: f64,
    /// Smallest tail ESS over parameters.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub min_ess_tail: f64,
    /// The parameters that miss a target, worst R-hat first.
    pub shortfalls: Vec<Shortfall>,
}

impl Default for Convergence {
    /// The verdict before any chain has run: not converged.
    fn default() -> Self {
        Convergence {
            converged: false,
            targets: Targets::default(),
            max_rhat: f64::NAN,
            min_ess_bulk: f64::NAN,
            min_ess_tail: f64::NAN,
            shortfalls: Vec::new(),
        }
    }
}

impl std::fmt::Display for Convergence {
    /// `max R-hat 1.234 (target <= 1.01), min bulk / tail ESS 45 / 30 (target >= 400): not
    /// converged, 3 parameters short (a, b, c)`, at most five names.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "max R-hat {:.3} (target <= {}), min bulk / tail ESS {:.0} / {:.0} (target >= {})",
            self.max_rhat,
            self.targets.rhat,
            self.min_ess_bulk,
            self.min_ess_tail,
            self.targets.ess
        )?;
        if self.converged {
            return write!(f, ": converged");
        }
        let names: Vec<&str> = self
            .shortfalls
            .iter()
            .take(5)
            .map(|s| s.parameter.as_str())
            .collect();
        let more = if self.shortfalls.len() > 5 {
            ", ..."
        } else {
            ""
        };
        write!(
            f,
            ": not converged, {} parameter(s) short ({}{more})",
            self.shortfalls.len(),
            names.join(", ")
        )
    }
}

/// Judges `summary` against `targets`. A statistic that could not be computed (NaN: too few
/// draws, a constant chain) misses its target.
pub fn assess(summary: &PosteriorSummary, targets: &Targets) -> Convergence {
    let misses = |p: &crate::summary::ParameterSummary| {
        !(p.rhat <= targets.rhat && p.ess_bulk >= targets.ess && p.ess_tail >= targets.ess)
    };
    let mut shortfalls: Vec<Shortfall> = summary
        .parameters
        .iter()
        .filter(|p| misses(p))
        .map(|p| Shortfall {
            parameter: p.name.clone(),
            rhat: p.rhat,
            ess_bulk: p.ess_bulk,
            ess_tail: p.ess_tail,
        })
        .collect();
    shortfalls.sort_by(|a, b| b.rhat.total_cmp(&a.rhat));
    let ps = &summary.parameters;
    Convergence {
        converged: !ps.is_empty() && shortfalls.is_empty(),
        targets: *targets,
        max_rhat: extreme(ps.iter().map(|p| p.rhat), f64::max),
        min_ess_bulk: extreme(ps.iter().map(|p| p.ess_bulk), f64::min),
        min_ess_tail: extreme(ps.iter().map(|p| p.ess_tail), f64::min),
        shortfalls,
    }
}

/// `pick` over `values`; NaN if any is NaN (or there are none).
fn extreme(values: impl Iterator<Item = f64>, pick: fn(f64, f64) -> f64) -> f64 {
    values
        .reduce(|a, b| {
            if a.is_nan() || b.is_nan() {
                f64::NAN
            } else {
                pick(a, b)
            }
        })
        .unwrap_or(f64::NAN)
}

/// Draws per chain that should reach the ESS target, from the draws per chain that gave
/// `min_ess` (ESS grows in proportion to the draws of a chain that has reached its stationary
/// distribution), with 10 % to spare. `None` when `min_ess` is not a positive number.
pub fn draws_for_ess(draws_per_chain: u64, min_ess: f64, target: f64) -> Option<u64> {
    (min_ess > 0.0 && min_ess.is_finite())
        .then(|| (draws_per_chain as f64 * 1.1 * target / min_ess).ceil() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::summary::ParameterSummary;

    fn param(name: &str, rhat: f64, ess_bulk: f64, ess_tail: f64) -> ParameterSummary {
        ParameterSummary {
            name: name.into(),
            unit: String::new(),
            mean: 0.0,
            sd: 1.0,
            median: 0.0,
            q5: -1.0,
            q95: 1.0,
            map: 0.0,
            rhat,
            ess_bulk,
            ess_tail,
            width_ratio: 0.5,
        }
    }

    fn summary(ps: Vec<ParameterSummary>) -> PosteriorSummary {
        PosteriorSummary {
            parameters: ps,
            map_point: vec![],
            map_log_density: 0.0,
            correlated_pairs: vec![],
            max_rhat: f64::NAN,
            min_ess_bulk: f64::NAN,
            modes: None,
        }
    }

    #[test]
    fn every_parameter_must_meet_every_target() {
        let t = Targets::default();
        let ok = summary(vec![
            param("a", 1.005, 900.0, 700.0),
            param("b", 1.01, 400.0, 400.0),
        ]);
        let c = assess(&ok, &t);
        assert!(c.converged, "{c:?}");
        assert_eq!(
            (c.max_rhat, c.min_ess_bulk, c.min_ess_tail),
            (1.01, 400.0, 400.0)
        );

        // One parameter short of tail ESS only.
        let tail = summary(vec![
            param("a", 1.005, 900.0, 700.0),
            param("b", 1.002, 800.0, 399.0),
        ]);
        let c = assess(&tail, &t);
        assert!(!c.converged);
        assert_eq!(c.shortfalls.len(), 1);
        assert_eq!(c.shortfalls[0].parameter, "b");

        // Worst R-hat first.
        let bad = summary(vec![
            param("a", 1.2, 30.0, 40.0),
            param("b", 3.9, 4.0, 10.0),
            param("c", 1.0, 500.0, 500.0),
        ]);
        let c = assess(&bad, &t);
        let names: Vec<_> = c.shortfalls.iter().map(|s| s.parameter.as_str()).collect();
        assert_eq!(names, ["b", "a"]);
        assert_eq!((c.max_rhat, c.min_ess_bulk), (3.9, 4.0));
    }

    #[test]
    fn a_statistic_that_could_not_be_computed_is_not_converged() {
        let c = assess(
            &summary(vec![param("a", f64::NAN, 900.0, 900.0)]),
            &Targets::default(),
        );
        assert!(!c.converged);
        assert!(c.max_rhat.is_nan());
        assert!(!assess(&summary(vec![]), &Targets::default()).converged);
        // Through JSON (NaN is written as null) and back.
        let back: Convergence = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
        assert!(back.max_rhat.is_nan() && back.shortfalls[0].rhat.is_nan());
    }

    #[test]
    fn draws_for_ess_scales_with_the_shortfall() {
        assert_eq!(draws_for_ess(500, 200.0, 400.0), Some(1100));
        assert_eq!(draws_for_ess(500, 0.0, 400.0), None);
        assert_eq!(draws_for_ess(500, f64::NAN, 400.0), None);
    }
}
