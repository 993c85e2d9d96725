//! Predictive intervals of readings over intervals of hours: utility bills, daily reads
//! (issue 69).
//!
//! **Model.** At posterior draw `d`, reading `b` is `N(s_db, sigma_d^2 w_b l_db^2)`: `s_db` the
//! draw's total over the reading's hours, `w_b` the variance of a sum of AR(1) hours in units of
//! `sigma^2` ([`crate::likelihood::intervals`]), and `l_db` the reading's error scale
//! ([`ReadingScale`]): 1 for every reading, or one that follows the draw's level over the
//! reading. `sigma_d^2 = Q_d / (B - 2)`, `Q_d = sum_b r_db^2 / (w_b l_db^2)` over the `B` fitted
//! readings, is the posterior mean of the scale under Jeffreys' prior given the draw's own
//! residuals (Gelman et al., Bayesian Data Analysis, 3rd ed., sec. 3.2: the scaled
//! inverse-chi^2 posterior), as the bills' likelihood integrates it out. The quantiles are those
//! of the equal-weight mixture over draws.
//!
//! **Why a scale that follows the level.** A building model's monthly totals miss in proportion
//! to what they total: a heating meter's January bill by tens of MWh, its July bill by a few. One
//! scale for every bill makes the summer's intervals as wide as January's and the winter's 50 %
//! intervals too narrow for their misses (the NREL RSF 2011's heating bills: 3 of 10 inside their
//! 50 % intervals, 10 of 10 inside the 90 % ones, [31, 342] MWh in January and [0, 233] MWh on a
//! summer bill of 0). The level scale is `l_db = m_db + c mean_b(m_db)`, `m_db = |s_db| / n_b`
//! the draw's mean hourly value over reading `b` of `n_b` hours: a relative error, floored at the
//! share `c` of the meter's mean level so that a bill the model puts at zero keeps an error
//! (the hourly meters' `level` error model, by bins of the simulated value, is the same idea
//! where there are thousands of readings, not ten).
//!
//! **Which scale.** With ten or twelve bills the scale cannot be judged by cross-validation as
//! the hourly meters' is; [`choose_scale`] takes the one under which the fitted readings are most
//! probable, their evidence with `sigma` integrated out averaged over the draws, the level
//! scale's floor, chosen from [`LEVEL_FLOORS`], charged as one more parameter (Schwarz 1978,
//! *Estimating the dimension of a model*, Ann. Statist. 6: `ln(B) / 2`).

use serde::{Deserialize, Serialize};

use super::mixture_quantile_each;
use crate::likelihood::ln_gamma;

/// How the error of a reading scales with the reading (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum ReadingScale {
    /// One scale for every reading (its length's AR(1) weight aside).
    Constant,
    /// The scale proportional to the draw's mean hourly value over the reading plus `floor`
    /// times its mean over the fitted readings.
    Level {
        /// The floor, a share of the meter's mean level.
        #[serde(deserialize_with = "crate::nan::null_as_nan")]
        #[schemars(with = "crate::nan::NumberOrNull")]
        floor: f64,
    },
}

/// The floors [`choose_scale`] tries for [`ReadingScale::Level`]: from nearly relative (a
/// bill the model puts at zero keeps a tenth of the mean level's error) to half constant.
pub const LEVEL_FLOORS: [f64; 4] = [0.1, 0.25, 0.5, 1.0];

impl ReadingScale {
    /// Its name in a sentence: `constant`, or `level (floor 0.25)`.
    pub fn describe(self) -> String {
        match self {
            ReadingScale::Constant => "constant".into(),
            ReadingScale::Level { floor } => format!("level (floor {floor})"),
        }
    }

    /// `l_b` of each reading for one draw's `totals` over readings of `hours` hours, the
    /// level's mean taken over the `fitted` readings (all ones where that mean is not
    /// positive).
    pub fn factors(self, totals: &[f64], hours: &[usize], fitted: &[bool]) -> Vec<f64> {
        let ReadingScale::Level { floor } = self else {
            return vec![1.0; totals.len()];
        };
        let level: Vec<f64> = (totals.iter().zip(hours))
            .map(|(s, &n)| s.abs() / n.max(1) as f64)
            .collect();
        let (sum, count) = (level.iter().zip(fitted))
            .filter(|(m, f)| **f && m.is_finite())
            .fold((0.0, 0usize), |(s, c), (m, _)| (s + m, c + 1));
        let mean = sum / count.max(1) as f64;
        if mean.is_nan() || mean <= 0.0 {
            return vec![1.0; totals.len()];
        }
        level.iter().map(|m| m + floor * mean).collect()
    }
}

/// One draw's fitted readings: `Q = sum_b r_b^2 / (w_b l_b^2)` over the `fitted` ones and
/// their count.
fn weighted_ssr(
    totals: &[f64],
    measured: &[f64],
    weights: &[f64],
    factors: &[f64],
    fitted: &[bool],
) -> (f64, usize) {
    (0..measured.len())
        .filter(|&b| fitted[b])
        .fold((0.0, 0), |(q, n), b| {
            let r = measured[b] - totals[b];
            (q + r * r / (weights[b] * factors[b] * factors[b]), n + 1)
        })
}

/// The evidence of the fitted readings under one draw and one scale, `sigma` integrated out
/// under Jeffreys' prior: `ln Γ(B/2) - B/2 ln(π Q) - 1/2 sum_b ln(w_b l_b^2)`, the bills'
/// likelihood ([`crate::likelihood::intervals`]) with `w_b l_b^2` for `w_b`.
pub fn log_evidence(
    totals: &[f64],
    measured: &[f64],
    weights: &[f64],
    factors: &[f64],
    fitted: &[bool],
) -> f64 {
    let (q, n) = weighted_ssr(totals, measured, weights, factors, fitted);
    let b = n as f64;
    let ln_det: f64 = (0..measured.len())
        .filter(|&i| fitted[i])
        .map(|i| (weights[i] * factors[i] * factors[i]).ln())
        .sum();
    ln_gamma(0.5 * b)
        - 0.5 * b * (std::f64::consts::PI * q.max(f64::MIN_POSITIVE)).ln()
        - 0.5 * ln_det
}

/// The scale among `candidates` under which the fitted readings are most probable: the mean
/// over draws of [`log_evidence`], less `ln(B) / 2` for a level scale's floor (module docs).
/// `totals[d][b]`; readings of `hours` hours with AR(1) weights `weights`. The first candidate
/// where none scores (no draw, no fitted reading).
pub fn choose_scale(
    candidates: &[ReadingScale],
    totals: &[Vec<f64>],
    measured: &[f64],
    weights: &[f64],
    hours: &[usize],
    fitted: &[bool],
) -> ReadingScale {
    let n_fit = fitted.iter().filter(|f| **f).count().max(1) as f64;
    let score = |scale: ReadingScale| {
        let evidence: f64 = (totals.iter())
            .map(|s| {
                let l = scale.factors(s, hours, fitted);
                log_evidence(s, measured, weights, &l, fitted)
            })
            .sum::<f64>()
            / totals.len().max(1) as f64;
        match scale {
            ReadingScale::Constant => evidence,
            ReadingScale::Level { .. } => evidence - 0.5 * n_fit.ln(),
        }
    };
    (candidates.iter().copied())
        .map(|c| (c, score(c)))
        .filter(|(_, s)| s.is_finite())
        .fold(
            None,
            |best: Option<(ReadingScale, f64)>, (c, s)| match best {
                Some((_, b)) if b >= s => best,
                _ => Some((c, s)),
            },
        )
        .map_or(candidates[0], |(c, _)| c)
}

/// Predictive quantiles of readings over intervals of hours at `levels`, `[reading][level]`
/// (module docs): `totals[d][b]` the draw's total over reading `b` of `hours[b]` hours, `weights`
/// its AR(1) weight, `scale` how its error follows its level. None under three fitted readings.
pub fn reading_quantiles(
    totals: &[Vec<f64>],
    measured: &[f64],
    weights: &[f64],
    hours: &[usize],
    fitted: &[bool],
    scale: ReadingScale,
    levels: &[f64],
) -> Option<Vec<Vec<f64>>> {
    let n_fit = fitted.iter().filter(|f| **f).count();
    if n_fit < 3 || totals.is_empty() {
        return None;
    }
    // Per draw: each reading's standard deviation.
    let sds: Vec<Vec<f64>> = totals
        .iter()
        .map(|s| {
            let l = scale.factors(s, hours, fitted);
            let (q, _) = weighted_ssr(s, measured, weights, &l, fitted);
            let variance = q / (n_fit - 2) as f64;
            (weights.iter().zip(&l))
                .map(|(w, l)| (variance * w).sqrt() * l)
                .collect()
        })
        .collect();
    Some(
        (0..measured.len())
            .map(|b| {
                let components: Vec<(f64, f64)> = (totals.iter().zip(&sds))
                    .map(|(s, sd)| (s[b], sd[b]))
                    .collect();
                (levels.iter())
                    .map(|&p| mixture_quantile_each(&components, p))
                    .collect()
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    const Z95: f64 = 1.644_853_626_951_472_2;

    /// One draw, a constant scale: the reading is N(s_b, Q / (B - 2) w_b) (Q the weighted
    /// residuals' squares).
    #[test]
    fn a_readings_interval_is_its_draws_total_and_the_scale_of_its_residuals() {
        let totals = vec![vec![10.0, 20.0, 30.0, 40.0]];
        let measured = [11.0, 18.0, 32.0, 100.0];
        let weights = [1.0, 4.0, 1.0, 2.0];
        let hours = [10, 10, 10, 10];
        // The fourth reading is held out: Q = 1 + 4 / 4 + 4 = 6 over 3 readings, sigma^2 = 6.
        let fitted = [true, true, true, false];
        let q = |fitted: &[bool], levels: &[f64]| {
            let c = ReadingScale::Constant;
            reading_quantiles(&totals, &measured, &weights, &hours, fitted, c, levels)
        };
        let q95 = q(&fitted, &[0.5, 0.95]).unwrap();
        assert!((q95[3][0] - 40.0).abs() < 1e-6);
        assert!((q95[3][1] - (40.0 + Z95 * 12.0_f64.sqrt())).abs() < 1e-6);
        assert!((q95[1][1] - (20.0 + Z95 * 24.0_f64.sqrt())).abs() < 1e-6);
        assert!(q(&[true, true, false, false], &[0.5]).is_none());
    }

    /// The level scale by hand: levels 1, 2, 3 kWh an hour (mean 2), floor 0.5: factors 2, 3,
    /// 4; each interval's half-width is its factor times the scale of the standardised
    /// residuals.
    #[test]
    fn a_level_scale_widens_a_readings_interval_with_its_level() {
        let totals = vec![vec![10.0, 20.0, 30.0]];
        let hours = [10, 10, 10];
        let fitted = [true; 3];
        let scale = ReadingScale::Level { floor: 0.5 };
        assert_eq!(
            scale.factors(&totals[0], &hours, &fitted),
            vec![2.0, 3.0, 4.0]
        );
        let measured = [12.0, 17.0, 34.0];
        let weights = [1.0; 3];
        // Q = (2/2)^2 + (3/3)^2 + (4/4)^2 = 3 over 1 degree of freedom.
        let q = reading_quantiles(
            &totals,
            &measured,
            &weights,
            &hours,
            &fitted,
            scale,
            &[0.95],
        )
        .unwrap();
        for (b, l) in [2.0, 3.0, 4.0].iter().enumerate() {
            let want = totals[0][b] + Z95 * 3.0_f64.sqrt() * l;
            assert!((q[b][0] - want).abs() < 1e-6, "{q:?}");
        }
        // A meter the model puts at zero everywhere: one scale.
        assert_eq!(scale.factors(&[0.0; 3], &hours, &fitted), vec![1.0; 3]);
    }

    /// Twelve readings whose errors are 20 % of their level (a heating meter's year): the
    /// level scale is chosen; errors of one size whatever the level: the constant one.
    #[test]
    fn the_scale_the_readings_follow_is_chosen() {
        let level: Vec<f64> = (0..12)
            .map(|m| 100.0 + 900.0 * (std::f64::consts::PI * m as f64 / 11.0).cos().powi(2))
            .collect();
        let hours = [720; 12];
        let weights = [1.0; 12];
        let fitted = [true; 12];
        let sign = |m: usize| if m.is_multiple_of(2) { 1.0 } else { -1.0 };
        let relative: Vec<f64> = (0..12).map(|m| level[m] * (1.0 + 0.2 * sign(m))).collect();
        let constant: Vec<f64> = (0..12).map(|m| level[m] + 80.0 * sign(m)).collect();
        let mut candidates = vec![ReadingScale::Constant];
        candidates.extend(LEVEL_FLOORS.map(|floor| ReadingScale::Level { floor }));
        let draws = vec![level.clone()];
        let chosen = |measured: &[f64]| {
            choose_scale(&candidates, &draws, measured, &weights, &hours, &fitted)
        };
        assert_eq!(chosen(&relative), ReadingScale::Level { floor: 0.1 });
        assert_eq!(chosen(&constant), ReadingScale::Constant);
    }

    /// With a constant scale the evidence is the bills' likelihood itself.
    #[test]
    fn the_constant_scales_evidence_is_the_bills_likelihood() {
        use crate::likelihood::intervals::{sum_weight, IntervalLikelihood, IntervalReading};
        let predicted: Vec<f32> = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
        let readings: Vec<IntervalReading> = [(0..3, 7.0), (3..5, 8.5), (5..9, 31.0)]
            .into_iter()
            .map(|(h, total)| IntervalReading {
                hours: h.collect(),
                total,
            })
            .collect();
        let hours: Vec<usize> = readings.iter().map(|r| r.hours.len()).collect();
        let weights: Vec<f64> = hours.iter().map(|&n| sum_weight(n, 0.9)).collect();
        let measured: Vec<f64> = readings.iter().map(|r| r.total).collect();
        let likelihood = IntervalLikelihood::new(0, 1, 9, readings, 0.9).unwrap();
        let totals = likelihood.totals(&predicted);
        let fitted = [true; 3];
        let ones = ReadingScale::Constant.factors(&totals, &hours, &fitted);
        let evidence = log_evidence(&totals, &measured, &weights, &ones, &fitted);
        let direct = likelihood.log_marginal_sigma(&predicted);
        assert!(
            (evidence - direct).abs() < 1e-9,
            "{evidence} against {direct}"
        );
    }
}
