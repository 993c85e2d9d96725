//! Two parameters the meters constrain together, not apart, and their split drawn again from
//! the priors (issue 70). Where the posterior of two parameters is a ridge (lighting and
//! equipment density on one electricity meter, the same schedule: the meter sees their sum),
//! the meters fix a combination and say little about where along the line of that combination
//! each one lies. A surrogate's small errors can still pin that split, tightly and wrongly: a
//! saving that rests on one of the two (LED lighting) then misses the truth with a narrow
//! interval. [`redraw_on_line`] keeps each draw's combination and draws its place on the line
//! from the two priors' density there, discarding whatever the chains learned along it: the
//! conditional of the priors given the combination, what the posterior would be if the meters
//! carried no information along the line (conservative where they carry some).
//!
//! The line is the major axis of the two parameters' posterior covariance ([`ridge_direction`]):
//! the first principal component (Jolliffe 2002, "Principal Component Analysis", Sec. 1.1).
//! Pure: no I/O.

use crate::prior::Triangular;
use crate::summary::centred_sums;

/// Grid points along the line on which the priors' density is summed (inverse-CDF sampling
/// of a discretised density).
pub const LINE_GRID: usize = 512;

/// The unit vector along which the draws `(a[d], b[d])` spread most (the major axis of their
/// 2 x 2 covariance, in the parameters' own units), oriented with a positive first component;
/// `None` where either does not vary.
pub fn ridge_direction(a: &[f64], b: &[f64]) -> Option<[f64; 2]> {
    let (saa, sbb, sab) = centred_sums(a, b);
    // Both vary and all is finite: where their correlation is a number.
    if !(saa > 0.0 && sbb > 0.0 && (sab / (saa * sbb).sqrt()).is_finite()) {
        return None;
    }
    // The larger eigenvalue of [[saa, sab], [sab, sbb]] and its eigenvector.
    let half = (saa - sbb) / 2.0;
    let lambda = (saa + sbb) / 2.0 + (half * half + sab * sab).sqrt();
    let v = if sab.abs() > 0.0 {
        [sab, lambda - saa]
    } else if saa >= sbb {
        [1.0, 0.0]
    } else {
        [0.0, 1.0]
    };
    let norm = (v[0] * v[0] + v[1] * v[1]).sqrt();
    let sign = if v[0] < 0.0 { -1.0 } else { 1.0 };
    Some([sign * v[0] / norm, sign * v[1] / norm])
}

/// The point `(xa, xb) + t * direction` with `t` drawn from the two priors' joint density on
/// that line inside both supports: `u` in `[0, 1)` picks it by the inverse of the density's
/// cumulative sum over [`LINE_GRID`] cells, linear inside a cell. The point itself where the
/// line misses a support or the density is 0 all along it.
pub fn redraw_on_line(
    (xa, xb): (f64, f64),
    direction: [f64; 2],
    (pa, pb): (&Triangular, &Triangular),
    u: f64,
) -> (f64, f64) {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for (x, d, p) in [(xa, direction[0], pa), (xb, direction[1], pb)] {
        if d.abs() < 1e-12 {
            if !p.contains(x) {
                return (xa, xb);
            }
            continue;
        }
        let (lo, hi) = ((p.min() - x) / d, (p.max() - x) / d);
        t0 = t0.max(lo.min(hi));
        t1 = t1.min(lo.max(hi));
    }
    if !(t0.is_finite() && t1.is_finite() && t0 < t1) {
        return (xa, xb);
    }
    let cell = (t1 - t0) / LINE_GRID as f64;
    let at = |t: f64| (xa + t * direction[0], xb + t * direction[1]);
    let mut cumulative = Vec::with_capacity(LINE_GRID);
    let mut total = 0.0;
    for i in 0..LINE_GRID {
        let (a, b) = at(t0 + (i as f64 + 0.5) * cell);
        total += pa.pdf(a) * pb.pdf(b);
        cumulative.push(total);
    }
    if total.is_nan() || total <= 0.0 {
        return (xa, xb);
    }
    let target = u.clamp(0.0, 1.0) * total;
    let i = cumulative
        .partition_point(|&c| c < target)
        .min(LINE_GRID - 1);
    let before = if i == 0 { 0.0 } else { cumulative[i - 1] };
    let within = (target - before) / (cumulative[i] - before).max(f64::MIN_POSITIVE);
    at(t0 + (i as f64 + within.clamp(0.0, 1.0)) * cell)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ridge_of_a_sum_runs_across_it() {
        // a + b fixed up to a little noise: the draws spread along (1, -1).
        let a: Vec<f64> = (0..50).map(|i| 5.0 + 0.1 * i as f64).collect();
        let b: Vec<f64> = a
            .iter()
            .enumerate()
            .map(|(i, x)| 30.0 - x + 0.01 * (i % 3) as f64)
            .collect();
        let v = ridge_direction(&a, &b).unwrap();
        let r = std::f64::consts::FRAC_1_SQRT_2;
        assert!((v[0] - r).abs() < 1e-3 && (v[1] + r).abs() < 1e-3, "{v:?}");
        assert_eq!(ridge_direction(&a, &vec![1.0; 50]), None);
    }

    /// Redrawn along the line a + b = 25 the sum is kept, and the split follows the priors'
    /// conditional density: its quantiles against a direct integration of that density.
    #[test]
    fn a_split_redrawn_keeps_the_sum_and_follows_the_priors() {
        let pa = Triangular::new(5.0, 10.0, 15.0).unwrap();
        let pb = Triangular::new(10.0, 17.5, 25.0).unwrap();
        let r = std::f64::consts::FRAC_1_SQRT_2;
        let draws: Vec<(f64, f64)> = (0..2000)
            .map(|i| redraw_on_line((12.0, 13.0), [r, -r], (&pa, &pb), (i as f64 + 0.5) / 2000.0))
            .collect();
        for (a, b) in &draws {
            assert!((a + b - 25.0).abs() < 1e-9 && pa.contains(*a) && pb.contains(*b));
        }
        // The conditional density of a given a + b = 25: pa(a) pb(25 - a) on a in [5, 15].
        let grid: Vec<f64> = (0..100_000)
            .map(|i| 5.0 + 10.0 * (i as f64 + 0.5) / 100_000.0)
            .collect();
        let w: Vec<f64> = grid.iter().map(|a| pa.pdf(*a) * pb.pdf(25.0 - a)).collect();
        let total: f64 = w.iter().sum();
        let quantile = |q: f64| {
            let mut c = 0.0;
            for (a, wi) in grid.iter().zip(&w) {
                c += wi;
                if c >= q * total {
                    return *a;
                }
            }
            15.0
        };
        let mut a: Vec<f64> = draws.iter().map(|d| d.0).collect();
        a.sort_by(f64::total_cmp);
        for q in [0.05, 0.5, 0.95] {
            let got = a[(q * a.len() as f64) as usize];
            assert!(
                (got - quantile(q)).abs() < 0.05,
                "{q}: {got} against {}",
                quantile(q)
            );
        }
        // Outside a support: unchanged.
        assert_eq!(
            redraw_on_line((30.0, 13.0), [r, -r], (&pa, &pb), 0.5),
            (30.0, 13.0)
        );
    }
}
