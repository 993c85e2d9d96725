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

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::mcmc::Draws;
use crate::{Result, StatsError};

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
}
