//! Savings of a retrofit measure as a posterior predictive (issue 70): for each posterior draw
//! the model's energy without the measure minus with it, and the distribution of those
//! differences. Pure: the simulations that give the per-draw totals are the caller's.
//!
//! A draw's saving is `baseline - measure` (positive when the measure saves). The credible
//! intervals are the central intervals of the draws' savings (type-7 quantiles, as
//! [`crate::diagnostics::quantile`]), the percentage per draw against that draw's own baseline
//! so that a draw with a higher baseline is not divided by another's. What drives the width is
//! the share of the savings' variance each parameter explains alone across the draws: the squared
//! Pearson correlation (a first-order sensitivity, Saltelli et al. 2008, "Global Sensitivity
//! Analysis", Sec. 1.2.5: for a linear response the shares of independent inputs sum to 1).

use serde::{Deserialize, Serialize};

use crate::diagnostics::quantile;
use crate::summary::correlation;

/// The distribution of a saving over posterior draws.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Spread {
    /// The draws' median.
    pub median: f64,
    /// Central 50 % interval (25 % and 75 % quantiles).
    pub interval_50: [f64; 2],
    /// Central 90 % interval (5 % and 95 % quantiles).
    pub interval_90: [f64; 2],
}

/// Each draw's saving, `baseline[d] - measure[d]`.
pub fn savings(baseline: &[f64], measure: &[f64]) -> Vec<f64> {
    baseline.iter().zip(measure).map(|(b, m)| b - m).collect()
}

/// Each draw's saving in percent of its own baseline (NaN where the baseline is zero).
pub fn savings_percent(baseline: &[f64], measure: &[f64]) -> Vec<f64> {
    baseline
        .iter()
        .zip(measure)
        .map(|(b, m)| {
            if *b == 0.0 {
                f64::NAN
            } else {
                100.0 * (b - m) / b
            }
        })
        .collect()
}

/// The median and central 50 % and 90 % intervals of `values`, NaN left out; `None` when no
/// value is finite.
pub fn spread(values: &[f64]) -> Option<Spread> {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    Some(Spread {
        median: quantile(&v, 0.5),
        interval_50: [quantile(&v, 0.25), quantile(&v, 0.75)],
        interval_90: [quantile(&v, 0.05), quantile(&v, 0.95)],
    })
}

/// The share of the savings' variance over the draws that each parameter explains alone: the
/// squared correlation of the parameter's draws (`parameters[k][d]`: parameter k, draw d) with
/// the savings; 0 where either is constant across the draws.
pub fn variance_shares(parameters: &[Vec<f64>], savings: &[f64]) -> Vec<f64> {
    parameters
        .iter()
        .map(|p| {
            let r = correlation(p, savings);
            if r.is_finite() {
                r * r
            } else {
                0.0
            }
        })
        .collect()
}

/// Whether `truth` lies inside `interval` (both ends included).
pub fn covers(interval: [f64; 2], truth: f64) -> bool {
    interval[0] <= truth && truth <= interval[1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn savings_are_baseline_minus_measure_and_percent_of_each_draws_baseline() {
        assert_eq!(savings(&[100.0, 80.0], &[90.0, 60.0]), vec![10.0, 20.0]);
        let p = savings_percent(&[100.0, 80.0, 0.0], &[90.0, 60.0, 0.0]);
        assert_eq!(&p[..2], &[10.0, 25.0]);
        assert!(p[2].is_nan());
    }

    #[test]
    fn spread_is_numpys_quantiles_and_ignores_nan() {
        // numpy.percentile(range(1, 102), [5, 25, 50, 75, 95]) = 6, 26, 51, 76, 96.
        let mut v: Vec<f64> = (1..=101).map(f64::from).collect();
        v.push(f64::NAN);
        let s = spread(&v).unwrap();
        assert_eq!(s.median, 51.0);
        assert_eq!(s.interval_50, [26.0, 76.0]);
        assert_eq!(s.interval_90, [6.0, 96.0]);
        assert!(spread(&[f64::NAN]).is_none());
    }

    #[test]
    fn a_measure_with_no_effect_has_a_zero_interval() {
        let s = spread(&savings(&[5.0, 7.0, 9.0], &[5.0, 7.0, 9.0])).unwrap();
        assert_eq!((s.median, s.interval_90), (0.0, [0.0, 0.0]));
        assert!(covers(s.interval_90, 0.0));
    }

    #[test]
    fn the_parameter_the_savings_follow_explains_their_variance() {
        let a: Vec<f64> = (0..50).map(|d| f64::from(d) / 50.0).collect();
        let b: Vec<f64> = (0..50).map(|d| f64::from((d * 37) % 50) / 50.0).collect();
        let s: Vec<f64> = a.iter().map(|x| 3.0 * x + 1.0).collect();
        let shares = variance_shares(&[a, b, vec![1.0; 50]], &s);
        assert!((shares[0] - 1.0).abs() < 1e-12, "{shares:?}");
        assert!(shares[1] < 0.1, "{shares:?}");
        assert_eq!(shares[2], 0.0);
    }
}
