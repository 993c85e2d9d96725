//! The surrogate's error carried into the posterior's intervals.
//!
//! The chains sample `p(theta | y)` with the surrogate in place of EnergyPlus. Where the
//! surrogate is wrong near the posterior, its optimum sits away from the theta EnergyPlus would
//! need, by a shift the likelihood knows nothing about: with 8,760 hours the posterior is far
//! narrower than that shift, and its intervals miss the truth (measured: 1 of 6 truths inside
//! the 90 % interval on the small model).
//!
//! **Measuring the shift.** At parameter values `theta_i` where EnergyPlus has been run (the
//! refinement points, posterior draws the surrogate did not train on), the calibration's own
//! optimiser, given EnergyPlus's outputs as if they were the meters, recovers `hat theta_i` on
//! the surrogate. `delta_i = hat theta_i - theta_i` is the error a calibration through this
//! surrogate makes where the posterior is, from surrogate error alone (EnergyPlus's outputs
//! carry no noise): an out-of-sample check in the manner of simulation-based calibration (Talts
//! et al. 2018, arXiv:1804.06788), with known inputs and the surrogate as the thing tested.
//!
//! **Carrying it.** The shift at the meters' theta is unknown; it is modelled as one more draw of
//! the same distribution, `delta ~ N(0, S)` with the uncentred second moment
//! `S = (1/m) sum_i delta_i delta_i^T` (a systematic shift common to all points counts as
//! spread, since its sign at the truth is not known). Each posterior draw gets an independent
//! `delta`, `theta + sum_i w_i delta_i / sqrt(m)` with `w_i ~ N(0, 1)`, which has exactly that
//! covariance and keeps the shifts' correlations (compensating parameters move together): the
//! draws of `theta_true = theta_posterior + delta`, whose covariance is the posterior's plus
//! `S` (law of total variance). Draws are in the unit space and clamped to the prior box.
//!
//! **Or in the likelihood** ([`temperature`]): the chains sample the power posterior
//! `p(theta) L(theta)^(1/T)` (a coarsened posterior in the sense of Miller & Dunson 2019,
//! "Robust Bayesian inference via coarsening", JASA 114, eq. 2.3), with `T` such that the
//! posterior's intervals, widened by it, hold the truth as often as they say when the truth lies
//! one measured shift away (averaged over the parameters). A posterior `T`
//! times wider than the likelihood alone allows is also one whose barriers between modes are
//! `T` times lower: what lets gradient-based chains mix on a surrogate that is rugged at the
//! scale of the untempered posterior.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::diagnostics::var;
use crate::error::{Result, StatsError};
use crate::mcmc::Draws;
use crate::normal::{norm_cdf, norm_ppf};

/// The shifts `delta_i = recovered_i - true_i` (same space, one vector per point).
///
/// # Errors
/// If the lengths do not match or a value is not finite.
pub fn shifts(truths: &[Vec<f64>], recovered: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
    if truths.len() != recovered.len() {
        return Err(StatsError::Shape(format!(
            "{} points and {} recovered values",
            truths.len(),
            recovered.len()
        )));
    }
    truths
        .iter()
        .zip(recovered)
        .map(|(t, r)| {
            if t.len() != r.len() || t.iter().chain(r).any(|v| !v.is_finite()) {
                return Err(StatsError::Invalid(
                    "a point and its recovered values must have the same length and be finite"
                        .into(),
                ));
            }
            Ok(r.iter().zip(t).map(|(r, t)| r - t).collect())
        })
        .collect()
}

/// Root mean square of each coordinate over the shifts: the standard deviation the shifts add
/// to each parameter (the diagonal of `S`).
pub fn rms(shifts: &[Vec<f64>]) -> Vec<f64> {
    let Some(d) = shifts.first().map(Vec::len) else {
        return vec![];
    };
    let m = shifts.len() as f64;
    (0..d)
        .map(|j| (shifts.iter().map(|s| s[j] * s[j]).sum::<f64>() / m).sqrt())
        .collect()
}

/// The draws with the surrogate's error added (see the module docs): every draw of every
/// chain plus `sum_i w_i delta_i / sqrt(m)`, `w_i ~ N(0, 1)` from `seed`, clamped to the unit
/// box. Coordinates past the shifts' length (sampled hyperparameters) are kept as they are.
///
/// # Errors
/// If there are no shifts, or they are longer than the draws.
pub fn add_to_draws(chains: &[Draws], shifts: &[Vec<f64>], seed: u64) -> Result<Vec<Draws>> {
    let Some(d) = shifts.first().map(Vec::len) else {
        return Err(StatsError::NotEnoughData("no shifts".into()));
    };
    if shifts.iter().any(|s| s.len() != d) || chains.iter().any(|c| c.dim < d) {
        return Err(StatsError::Shape(format!(
            "shifts of {d} coordinates for draws of {:?}",
            chains.iter().map(|c| c.dim).collect::<Vec<_>>()
        )));
    }
    let scale = 1.0 / (shifts.len() as f64).sqrt();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(chains.len());
    for c in chains {
        let mut shifted = c.clone();
        for i in 0..c.len() {
            let w: Vec<f64> = (0..shifts.len())
                .map(|_| StandardNormal.sample(&mut rng))
                .collect();
            let x = &mut shifted.points[i * c.dim..i * c.dim + d];
            for (j, v) in x.iter_mut().enumerate() {
                let delta: f64 = shifts.iter().zip(&w).map(|(s, w)| s[j] * w).sum();
                *v = (*v + scale * delta).clamp(0.0, 1.0);
            }
        }
        out.push(shifted);
    }
    Ok(out)
}

/// The likelihood's temperature that carries the surrogate's error: the smallest `T >= 1` at
/// which the posterior's central `level` intervals are expected to hold the truth for a fraction
/// `level` of the parameters,
///
/// `(1/d) sum_j [2 Phi(z sqrt(T / (1 + r_j))) - 1] = level`, `z = Phi^-1((1 + level) / 2)`,
///
/// with `r_j` the shift's variance in units of the untempered posterior's ([`shift_ratios`]).
/// Why: the truth lies a shift `N(0, S_jj)` from where the untempered posterior centres, so
/// `N(0, v_j (1 + r_j))` from its centre (law of total variance, as in the module docs), while
/// the tempered posterior's interval is `+- z sqrt(T v_j)`: parameter `j`'s interval holds the
/// truth with the probability in the sum. One `T` serves every parameter, so the sum averages
/// over them (all `r_j` equal give `T = 1 + r`): a parameter whose shift is many posterior
/// widths costs at most `1/d` of the coverage, so with `d (1 - level) > 1` (more than 10
/// parameters at 90 %) it does not set `T` alone; with fewer, the farthest shift sets it,
/// since then every interval must hold. At least 1 (no shift: 1).
///
/// # Errors
/// As [`shift_ratios`]; `level` outside (0, 1).
pub fn temperature(
    shifts: &[Vec<f64>],
    points: &[Vec<f64>],
    round_temperature: f64,
    spread: f64,
    level: f64,
) -> Result<f64> {
    let ratios = shift_ratios(shifts, points, round_temperature, spread)?;
    pooled_temperature(&[(&ratios, 1.0)], level)
}

/// Each parameter's shift variance in units of the untempered posterior variance,
/// `r_j = T_r s^2 S_jj / V_j`: `S_jj` the shifts' second moment ([`rms`] squared), `V_j` the
/// sample variance of the points they were measured at, posterior draws of chains that ran at
/// temperature `T_r`, moved `s` = `spread` times farther from their mean, so that
/// `V_j / (T_r s^2)` is the untempered posterior variance. Dimensionless, so ratios of
/// different buildings can be pooled ([`pooled_temperature`]). Coordinates whose points have no
/// spread are left out.
///
/// # Errors
/// With fewer than two points, shifts and points of other shapes, a non-finite value, `T_r`
/// below 1, `spread` not positive, or no coordinate with any spread.
pub fn shift_ratios(
    shifts: &[Vec<f64>],
    points: &[Vec<f64>],
    round_temperature: f64,
    spread: f64,
) -> Result<Vec<f64>> {
    let m = points.len();
    if m < 2 || shifts.len() != m {
        return Err(StatsError::NotEnoughData(format!(
            "{} shifts at {m} points (at least two points, one shift each)",
            shifts.len()
        )));
    }
    let d = points[0].len();
    if shifts.iter().chain(points).any(|v| v.len() != d) {
        return Err(StatsError::Shape(
            "shifts and points of different lengths".into(),
        ));
    }
    if !(round_temperature.is_finite() && round_temperature >= 1.0 && spread > 0.0) {
        return Err(StatsError::Invalid(format!(
            "round temperature {round_temperature} (at least 1) and spread {spread} (positive)"
        )));
    }
    let second_moment = rms(shifts);
    let ratios: Vec<f64> = (0..d)
        .filter_map(|j| {
            let column: Vec<f64> = points.iter().map(|p| p[j]).collect();
            let v = var(&column, 1);
            (v > 0.0).then(|| round_temperature * spread * spread * second_moment[j].powi(2) / v)
        })
        .collect();
    if ratios.iter().any(|r| !r.is_finite()) {
        return Err(StatsError::Invalid("a shift or point is not finite".into()));
    }
    if ratios.is_empty() {
        return Err(StatsError::NotEnoughData(
            "the points have no spread".into(),
        ));
    }
    Ok(ratios)
}

/// [`temperature`] over groups of ratios ([`shift_ratios`]) with weights: the smallest
/// `T >= 1` whose expected coverage, each group's average over its parameters weighted by the
/// group's weight (normalised), reaches `level`. One group is [`temperature`]; a building's own
/// recoveries and those of other buildings that share its surrogate's pretrained network,
/// weighted half each, is partial pooling of the surrogate's error over the family (complete
/// pooling would be one group of all).
///
/// # Errors
/// `level` outside (0, 1); no group with ratios and a positive weight; a ratio not finite and
/// non-negative or a weight not finite and non-negative.
pub fn pooled_temperature(groups: &[(&[f64], f64)], level: f64) -> Result<f64> {
    if !(level > 0.0 && level < 1.0) {
        return Err(StatsError::Invalid(format!(
            "level {level} (between 0 and 1)"
        )));
    }
    let bad = groups.iter().any(|(r, w)| {
        !(w.is_finite() && *w >= 0.0) || r.iter().any(|x| !(x.is_finite() && *x >= 0.0))
    });
    if bad {
        return Err(StatsError::Invalid(
            "a ratio or weight is not finite and non-negative".into(),
        ));
    }
    let used: Vec<(&[f64], f64)> = groups
        .iter()
        .filter(|(r, w)| !r.is_empty() && *w > 0.0)
        .copied()
        .collect();
    let total: f64 = used.iter().map(|(_, w)| w).sum();
    if used.is_empty() {
        return Err(StatsError::NotEnoughData(
            "no group of ratios with a positive weight".into(),
        ));
    }
    let coverage = |t: f64| -> f64 {
        used.iter()
            .map(|(r, w)| w / total * expected_coverage(r, level, t))
            .sum()
    };
    let largest = used
        .iter()
        .flat_map(|(r, _)| r.iter())
        .fold(0.0_f64, |a, &r| a.max(r));
    Ok(temperature_for_coverage(coverage, largest, level))
}

/// The expected coverage of central `level` intervals `T` times wider in variance than the
/// posterior, averaged over parameters whose truths lie `N(0, (1 + r_j) v_j)` from the centre.
fn expected_coverage(ratios: &[f64], level: f64, t: f64) -> f64 {
    let z = norm_ppf(0.5 + level / 2.0);
    let held: f64 = ratios
        .iter()
        .map(|r| 2.0 * norm_cdf(z * (t / (1.0 + r)).sqrt()) - 1.0)
        .sum();
    held / ratios.len() as f64
}

/// The smallest `T >= 1` with `coverage(T)` at least `level`. The coverage grows with `T`,
/// and at `T = 1 + largest` (the largest ratio) every parameter's interval holds at least
/// `level`, so bisection in `ln T` between 1 and that finds it (to a relative 1e-9).
fn temperature_for_coverage(coverage: impl Fn(f64) -> f64, largest: f64, level: f64) -> f64 {
    // 1e-12 below: all ratios 0 give exactly `level` at T = 1, up to rounding.
    let enough = |t: f64| coverage(t) >= level - 1e-12;
    let (mut lo, mut hi) = (0.0_f64, (1.0 + largest).ln());
    if enough(1.0) {
        return 1.0;
    }
    while hi - lo > 1e-9 {
        let mid = 0.5 * (lo + hi);
        if enough(mid.exp()) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi.exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_chain(points: &[[f64; 2]]) -> Draws {
        let mut d = Draws::new(2);
        for p in points {
            d.points.extend_from_slice(p);
            d.log_density.push(0.0);
        }
        d
    }

    #[test]
    fn shifts_are_recovered_less_true_and_rms_is_per_coordinate() {
        let s = shifts(
            &[vec![0.5, 0.5], vec![0.2, 0.4]],
            &[vec![0.53, 0.5], vec![0.16, 0.4]],
        )
        .unwrap();
        assert!((s[0][0] - 0.03).abs() < 1e-12 && (s[1][0] + 0.04).abs() < 1e-12);
        let r = rms(&s);
        assert!(
            (r[0] - (0.0025_f64 / 2.0 * 1.0).sqrt()).abs() < 1e-12,
            "{r:?}"
        );
        assert_eq!(r[1], 0.0);
        assert!(shifts(&[vec![0.5]], &[]).is_err());
        assert!(shifts(&[vec![0.5]], &[vec![f64::NAN]]).is_err());
    }

    #[test]
    fn added_error_has_the_shifts_second_moment_and_keeps_their_correlation() {
        // A point mass at (0.5, 0.5) and two shifts that move both coordinates together.
        let chain = one_chain(&[[0.5, 0.5]; 20_000]);
        let s = vec![vec![0.04, 0.02], vec![-0.02, -0.01]];
        let out = add_to_draws(&[chain], &s, 7).unwrap();
        let (x, y) = (out[0].column(0), out[0].column(1));
        let n = x.len() as f64;
        let mean = |v: &[f64]| v.iter().sum::<f64>() / n;
        let (mx, my) = (mean(&x), mean(&y));
        let var_x = x.iter().map(|v| (v - mx) * (v - mx)).sum::<f64>() / n;
        let cov = x
            .iter()
            .zip(&y)
            .map(|(a, b)| (a - mx) * (b - my))
            .sum::<f64>()
            / n;
        // S = (1/2)(0.04^2 + 0.02^2) = 0.001 for x; x and y perfectly correlated (y = x / 2).
        assert!((var_x - 0.001).abs() < 0.00005, "{var_x}");
        assert!((cov - 0.0005).abs() < 0.00003, "{cov}");
        assert!((mx - 0.5).abs() < 0.001);
        for (a, b) in x.iter().zip(&y) {
            assert!(((a - 0.5) / 2.0 - (b - 0.5)).abs() < 1e-12);
        }
    }

    #[test]
    fn zero_shifts_leave_the_draws_and_large_ones_stay_in_the_box() {
        let chain = one_chain(&[[0.1, 0.9], [0.3, 0.7]]);
        let same = add_to_draws(std::slice::from_ref(&chain), &[vec![0.0, 0.0]], 1).unwrap();
        assert_eq!(same[0], chain);
        let wide = add_to_draws(&[chain], &[vec![5.0, -5.0]], 1).unwrap();
        assert!(wide[0].points.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(add_to_draws(&[wide[0].clone()], &[], 1).is_err());
        assert!(add_to_draws(&[wide[0].clone()], &[vec![0.0; 3]], 1).is_err());
    }

    #[test]
    fn temperature_makes_the_intervals_hold_the_shifted_truth() {
        // Points with variance 1 per coordinate (two points at +-1/sqrt(2): sample variance of
        // (-a, a) is 2 a^2); shifts with second moment 9 in every coordinate: T = 1 + 9 at any
        // level, since each interval then holds N(0, 1 + 9) exactly as often as it says.
        let a = 0.5_f64.sqrt();
        let points = vec![vec![-a, -a, -a], vec![a, a, a]];
        let equal = vec![vec![3.0, 3.0, -3.0], vec![-3.0, 3.0, 3.0]];
        for level in [0.5, 0.9] {
            let t = temperature(&equal, &points, 1.0, 1.0, level).unwrap();
            assert!((t - 10.0).abs() < 1e-6, "{t}");
        }
        // Chains that ran at T_r = 5 were sqrt(5) times wider: the untempered variance is 1/5.
        let t5 = temperature(&equal, &points, 5.0, 1.0, 0.9).unwrap();
        assert!((t5 - 46.0).abs() < 1e-6, "{t5}");
        // Points moved twice as far from their mean: their variance is 4 times the chains'.
        let t2 = temperature(&equal, &points, 1.0, 2.0, 0.9).unwrap();
        assert!((t2 - 37.0).abs() < 1e-6, "{t2}");
        // Unequal shifts (second moments 4, 9, 1e6): T makes the average coverage the level;
        // at 60 % the far one holds almost nothing and does not set T, the others hold more.
        let mixed = vec![vec![2.0, 3.0, 1e3], vec![-2.0, 3.0, -1e3]];
        let t = temperature(&mixed, &points, 1.0, 1.0, 0.6).unwrap();
        let ratios = [4.0, 9.0, 1e6];
        assert!((expected_coverage(&ratios, 0.6, t) - 0.6).abs() < 1e-9);
        assert!(t > 10.0 && t < 100.0, "{t}");
        assert!(expected_coverage(&ratios[2..], 0.6, t) < 0.01);
        // No shift: no tempering.
        let zero = vec![vec![0.0; 3]; 2];
        assert_eq!(temperature(&zero, &points, 1.0, 1.0, 0.9).unwrap(), 1.0);
        // A coordinate without spread is left out; one point, or none with spread, is an error.
        let flat = vec![vec![-a, 0.3, -a], vec![a, 0.3, a]];
        let t = temperature(&mixed, &flat, 1.0, 1.0, 0.9).unwrap();
        assert!((expected_coverage(&[4.0, 1e6], 0.9, t) - 0.9).abs() < 1e-9);
        assert!(temperature(&mixed[..1], &points[..1], 1.0, 1.0, 0.9).is_err());
        assert!(temperature(&mixed, &[vec![0.1; 3], vec![0.1; 3]], 1.0, 1.0, 0.9).is_err());
        assert!(temperature(&mixed, &points, 0.5, 1.0, 0.9).is_err());
        assert!(temperature(&mixed, &points, 1.0, 1.0, 1.0).is_err());
        assert!(temperature(&mixed, &points, 1.0, 0.0, 0.9).is_err());
        // Ratios near the largest finite number still end, at a finite T.
        let t = pooled_temperature(&[(&[1e300, 0.0], 1.0)], 0.9).unwrap();
        assert!(t.is_finite() && t > 1e299, "{t}");
    }

    #[test]
    fn pooled_temperature_weighs_each_group_s_coverage() {
        // One group is the single-building rule: all ratios 9 give T = 10.
        let own = [9.0; 4];
        let t = pooled_temperature(&[(&own, 1.0)], 0.9).unwrap();
        assert!((t - 10.0).abs() < 1e-6, "{t}");
        // A building that measured no shift, pooled half and half with a family whose shifts
        // are 99 posterior variances: T between its own (1) and the family's (100), where the
        // two coverages average to the level (its own above it, the family's below).
        let none = [0.0; 4];
        let family = [99.0; 12];
        let t = pooled_temperature(&[(&none, 0.5), (&family, 0.5)], 0.9).unwrap();
        assert!(t > 1.0 && t < 100.0, "{t}");
        let avg = 0.5 * expected_coverage(&none, 0.9, t) + 0.5 * expected_coverage(&family, 0.9, t);
        assert!((avg - 0.9).abs() < 1e-9, "{avg}");
        assert!(expected_coverage(&family, 0.9, t) < 0.9);
        // Weights are normalised; a group without ratios or weight is left out.
        let same = pooled_temperature(&[(&none, 2.0), (&family, 2.0), (&[], 1.0)], 0.9).unwrap();
        assert!((same - t).abs() < 1e-9 * t);
        let alone = pooled_temperature(&[(&own, 1.0), (&family, 0.0)], 0.9).unwrap();
        assert!((alone - 10.0).abs() < 1e-6);
        // Nothing to pool, a negative ratio or weight, a level outside (0, 1): errors.
        assert!(pooled_temperature(&[(&[], 1.0)], 0.9).is_err());
        assert!(pooled_temperature(&[(&[-1.0], 1.0)], 0.9).is_err());
        assert!(pooled_temperature(&[(&own, -1.0)], 0.9).is_err());
        assert!(pooled_temperature(&[(&own, 1.0)], 1.0).is_err());
    }
}
