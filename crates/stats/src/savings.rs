//! Savings of a retrofit measure as a posterior predictive (issue 70): for each posterior draw
//! the model's energy without the measure minus with it, and the distribution of those
//! differences. Pure: the simulations that give the per-draw totals are the caller's.
//!
//! A draw's saving is `baseline - measure` (positive when the measure saves). The credible
//! intervals are read off the draws' savings as order statistics chosen for their coverage
//! ([`interval_rank`]): with tens of EnergyPlus draws, not hundreds, the 5 % and 95 % sample
//! quantiles hold a further posterior draw (and so a truth the posterior is right about) less
//! often than 90 % (79 % at 16 draws), the `k`-th smallest and largest at least as often as
//! stated where `n` allows it. The percentage is per draw against that draw's own baseline, so
//! that a draw with a higher baseline is not divided by another's. What drives the width is
//! the share of the savings' variance each parameter explains alone across the draws: the squared
//! Pearson correlation (a first-order sensitivity, Saltelli et al. 2008, "Global Sensitivity
//! Analysis", Sec. 1.2.5: for a linear response the shares of independent inputs sum to 1).
//!
//! Where a surrogate gives the savings at many draws and EnergyPlus at a few, EnergyPlus's are
//! regressed on the surrogate's at the few ([`Correction`], the regression form of control
//! variates: Glasserman 2004, "Monte Carlo Methods in Financial Engineering", Sec. 4.1), and
//! the many are mapped through the fit with the fit's residuals added back in turn
//! ([`corrected`]): the spread keeps what the surrogate misses at EnergyPlus's draws.

use serde::{Deserialize, Serialize};

use crate::diagnostics::quantile;
use crate::summary::correlation;

/// The distribution of a saving over posterior draws.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Spread {
    /// The draws' median.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub median: f64,
    /// Central 50 % interval (25 % and 75 % quantiles).
    #[serde(deserialize_with = "crate::nan::null_as_nan_pair")]
    #[schemars(with = "crate::nan::PairOfNumberOrNull")]
    pub interval_50: [f64; 2],
    /// Central 90 % interval (5 % and 95 % quantiles).
    #[serde(deserialize_with = "crate::nan::null_as_nan_pair")]
    #[schemars(with = "crate::nan::PairOfNumberOrNull")]
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

/// The median and central 50 % and 90 % intervals of `values` ([`interval_rank`]'s order
/// statistics), NaN left out; `None` when no value is finite.
pub fn spread(values: &[f64]) -> Option<Spread> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    let median = quantile(&v, 0.5);
    v.sort_by(f64::total_cmp);
    let interval = |level: f64| {
        let (k, _) = interval_rank(v.len(), level);
        [v[k - 1], v[v.len() - k]]
    };
    Some(Spread {
        median,
        interval_50: interval(0.5),
        interval_90: interval(0.9),
    })
}

/// The rank `k` whose order statistics `[x_(k), x_(n+1-k)]` of `n` draws make a central
/// interval of `level`, and the probability that a further draw of the same distribution falls
/// inside, `(n + 1 - 2k) / (n + 1)` (a distribution-free prediction interval: Wilks 1941,
/// "Determination of sample sizes for setting tolerance limits", Ann. Math. Stat. 12; Hahn and
/// Meeker 1991, "Statistical Intervals", Sec. 5.2). `k` is the largest with that probability at
/// least `level`; where even the smallest and largest fall short (`n + 1 < 2 / (1 - level)`:
/// under 19 draws for 90 %), `k = 1` and the probability says by how much.
pub fn interval_rank(n: usize, level: f64) -> (usize, f64) {
    // (1 - 0.9) / 2 is 0.04999...: the 1e-9 keeps 0.05 x 100 at 5.
    let k = (((1.0 - level) / 2.0 * (n + 1) as f64 + 1e-9).floor() as usize).max(1);
    let k = k.min(n.div_ceil(2)).max(1);
    let inside = (n + 1).saturating_sub(2 * k) as f64 / (n + 1) as f64;
    (k, inside)
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

/// A straight line from the surrogate's savings to EnergyPlus's at the same draws.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Correction {
    /// EnergyPlus at a surrogate saving of 0 (kWh).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub intercept: f64,
    /// EnergyPlus per unit of the surrogate's saving.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub slope: f64,
    /// The share of EnergyPlus's variance over the draws the line explains (NaN where
    /// EnergyPlus's savings do not vary).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub r2: f64,
}

/// The least-squares line of `energyplus` on `surrogate` (the same draws). Under four draws,
/// or where the surrogate's savings do not vary, the slope is 1 and the line a shift by the
/// mean difference.
pub fn correction(surrogate: &[f64], energyplus: &[f64]) -> Correction {
    let n = surrogate.len().min(energyplus.len());
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len().max(1) as f64;
    let (s, e) = (&surrogate[..n], &energyplus[..n]);
    let (ms, me) = (mean(s), mean(e));
    let sxx: f64 = s.iter().map(|x| (x - ms) * (x - ms)).sum();
    let sxy: f64 = s.iter().zip(e).map(|(x, y)| (x - ms) * (y - me)).sum();
    let syy: f64 = e.iter().map(|y| (y - me) * (y - me)).sum();
    let scale = ms.abs().max(me.abs()).max(1e-12);
    let slope = if n >= 4 && sxx > (1e-12 * scale).powi(2) * n as f64 {
        sxy / sxx
    } else {
        1.0
    };
    let intercept = me - slope * ms;
    let rss: f64 = s
        .iter()
        .zip(e)
        .map(|(x, y)| (y - intercept - slope * x).powi(2))
        .sum();
    Correction {
        intercept,
        slope,
        r2: if syy > 0.0 { 1.0 - rss / syy } else { f64::NAN },
    }
}

/// EnergyPlus's savings less the line at the same draws.
pub fn residuals(c: &Correction, surrogate: &[f64], energyplus: &[f64]) -> Vec<f64> {
    surrogate
        .iter()
        .zip(energyplus)
        .map(|(x, y)| y - c.intercept - c.slope * x)
        .collect()
}

/// The surrogate's savings at many draws through the line, draw `d` with residual
/// `d mod residuals.len()` added (none where there are none).
pub fn corrected(c: &Correction, surrogate: &[f64], residuals: &[f64]) -> Vec<f64> {
    surrogate
        .iter()
        .enumerate()
        .map(|(d, x)| {
            let r = if residuals.is_empty() {
                0.0
            } else {
                residuals[d % residuals.len()]
            };
            c.intercept + c.slope * x + r
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
    fn spread_is_order_statistics_of_the_stated_coverage_and_ignores_nan() {
        // 99 draws: k = floor(0.05 x 100) = 5 and floor(0.25 x 100) = 25, a further draw
        // inside with probability 90/100 and 50/100.
        let mut v: Vec<f64> = (1..=99).rev().map(f64::from).collect();
        v.push(f64::NAN);
        let s = spread(&v).unwrap();
        assert_eq!(s.median, 50.0);
        assert_eq!(s.interval_90, [5.0, 95.0]);
        assert_eq!(s.interval_50, [25.0, 75.0]);
        assert_eq!(interval_rank(99, 0.9), (5, 0.9));
        assert!(spread(&[f64::NAN]).is_none());
        // 16 draws: the smallest and largest, inside 15 times in 17 (numpy's 5 % and 95 %
        // quantiles, between the 1st and 2nd and the 15th and 16th, about 13.5 in 17).
        let (k, inside) = interval_rank(16, 0.9);
        assert_eq!(k, 1);
        assert!((inside - 15.0 / 17.0).abs() < 1e-12);
        let s = spread(&(1..=16).map(f64::from).collect::<Vec<_>>()).unwrap();
        assert_eq!(s.interval_90, [1.0, 16.0]);
        // One draw: the interval is the draw.
        assert_eq!(spread(&[3.0]).unwrap().interval_90, [3.0, 3.0]);
        assert_eq!(interval_rank(1, 0.9), (1, 0.0));
    }

    /// The coverage the rank claims, checked by drawing: uniform draws and a further draw.
    #[test]
    fn a_further_draw_falls_inside_as_often_as_the_rank_says() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for n in [9usize, 16, 30, 60] {
            let (trials, mut inside) = (20_000, 0usize);
            for _ in 0..trials {
                let v: Vec<f64> = (0..n).map(|_| rng.random::<f64>()).collect();
                let s = spread(&v).unwrap();
                inside += usize::from(covers(s.interval_90, rng.random::<f64>()));
            }
            let (_, p) = interval_rank(n, 0.9);
            let share = inside as f64 / trials as f64;
            assert!((share - p).abs() < 0.01, "n = {n}: {share} against {p}");
        }
    }

    #[test]
    fn a_measure_with_no_effect_has_a_zero_interval() {
        let s = spread(&savings(&[5.0, 7.0, 9.0], &[5.0, 7.0, 9.0])).unwrap();
        assert_eq!((s.median, s.interval_90), (0.0, [0.0, 0.0]));
        assert!(covers(s.interval_90, 0.0));
    }

    #[test]
    fn a_surrogate_that_is_off_by_a_line_is_corrected_onto_energyplus() {
        // EnergyPlus = 100 + 0.8 x surrogate, with residuals +-1 at the few draws.
        let s_few = [10.0, 20.0, 30.0, 40.0, 50.0, 60.0];
        let e_few: Vec<f64> = (s_few.iter().enumerate())
            .map(|(i, x)| 100.0 + 0.8 * x + if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let c = correction(&s_few, &e_few);
        assert!(
            (c.slope - 0.8).abs() < 0.05 && (c.intercept - 100.0).abs() < 2.5,
            "{c:?}"
        );
        assert!(c.r2 > 0.99, "{c:?}");
        let r = residuals(&c, &s_few, &e_few);
        assert!(r.iter().sum::<f64>().abs() < 1e-9);
        let many: Vec<f64> = (0..100).map(|d| 10.0 + 0.5 * f64::from(d)).collect();
        let fixed = corrected(&c, &many, &r);
        assert!((fixed[0] - (c.intercept + c.slope * 10.0 + r[0])).abs() < 1e-12);
        assert!((fixed[7] - (c.intercept + c.slope * many[7] + r[1])).abs() < 1e-12);
        // Too few draws, or a constant surrogate: a shift by the mean difference.
        let shift = correction(&[5.0, 5.0, 5.0, 5.0], &[7.0, 8.0, 9.0, 8.0]);
        assert_eq!((shift.slope, shift.intercept), (1.0, 3.0));
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
