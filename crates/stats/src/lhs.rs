//! Latin hypercube design points over triangular priors (McKay, Beckman & Conover 1979), with
//! an optional maximin improvement and repair of pairwise constraints.
//!
//! Sampling: for `n` points, each parameter's probability axis `[0, 1]` is cut into `n` equal
//! strata; a random permutation assigns one stratum to each row and the probability is drawn
//! uniformly inside it, `p = (stratum + U) / n`; the parameter value is the prior's inverse
//! CDF at `p`. Every column therefore has exactly one point per stratum.
//!
//! Maximin: a fixed number of random swaps of two rows' values within one column, each kept if
//! the minimum pairwise Euclidean distance in the probability ("stratum") space does not
//! decrease (Morris & Mitchell 1995, simplified to a greedy column-exchange search). Swaps
//! within a column keep the stratification; swaps that would break a constraint are refused.
//!
//! Constraints `x[i] - x[j] <= c` (e.g. heating set-point <= cooling set-point: `x_h - x_c <= 0`;
//! chilled water + 3 K <= supply air: `x_chw - x_sat <= -3`) are repaired first by swapping
//! values between rows within a column (stratification kept exactly); a row that swaps cannot
//! fix has one cell resampled inside the feasible part of its stratum, or, as a last resort,
//! anywhere in the feasible part of the prior's support. [`RepairReport`] says what changed.

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{Result, StatsError};
use crate::prior::Triangular;

/// The pairwise constraint `x[i] - x[j] <= c` on a design point (parameter indices).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PairConstraint {
    /// Index of the parameter on the left.
    pub i: usize,
    /// Index of the parameter subtracted.
    pub j: usize,
    /// Bound `c`.
    pub c: f64,
}

impl PairConstraint {
    /// `x[i] - x[j] <= c`.
    pub fn new(i: usize, j: usize, c: f64) -> Self {
        PairConstraint { i, j, c }
    }
    /// Amount by which a point violates the constraint (0 when it holds, up to rounding).
    pub fn violation(&self, x: &[f64]) -> f64 {
        let v = x[self.i] - x[self.j] - self.c;
        let tol = 1e-12 * (1.0 + self.c.abs() + x[self.i].abs() + x[self.j].abs());
        if v > tol {
            v
        } else {
            0.0
        }
    }
    /// Whether the point satisfies the constraint.
    pub fn holds(&self, x: &[f64]) -> bool {
        self.violation(x) == 0.0
    }
}

/// Options of [`latin_hypercube`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LhsOptions {
    /// Random column-swap iterations of the maximin search (0 = none).
    pub maximin_iterations: usize,
    /// Constraints every design point must satisfy.
    pub constraints: Vec<PairConstraint>,
}

/// What the constraint repair changed.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
pub struct RepairReport {
    /// Rows infeasible before repair.
    pub rows_infeasible_before: usize,
    /// Within-column swaps made.
    pub swaps: usize,
    /// Cells resampled inside their own stratum.
    pub resampled_in_stratum: usize,
    /// Cells resampled outside their stratum (stratification of that column broken).
    pub resampled_outside_stratum: usize,
}

/// A Latin hypercube design.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Design {
    /// Design points, `n` rows of `d` parameter values (physical units, prior order).
    pub points: Vec<Vec<f64>>,
    /// The same points in probability space, `p = F(x)` per parameter.
    pub probabilities: Vec<Vec<f64>>,
    /// Constraint repair report.
    pub repair: RepairReport,
    /// Accepted maximin swaps.
    pub maximin_swaps: usize,
    /// Minimum pairwise Euclidean distance in probability space.
    pub min_distance: f64,
}

/// Stratum index `floor(p n)` of a probability in a design of `n` points.
pub fn stratum(p: f64, n: usize) -> usize {
    ((p * n as f64).floor() as usize).min(n - 1)
}

struct Work<'a> {
    priors: &'a [Triangular],
    cons: &'a [PairConstraint],
    p: Vec<Vec<f64>>,
    x: Vec<Vec<f64>>,
}

impl Work<'_> {
    fn set(&mut self, r: usize, k: usize, p: f64) {
        self.p[r][k] = p;
        self.x[r][k] = self.priors[k].quantile(p);
    }
    fn viol(&self, r: usize) -> f64 {
        self.cons.iter().map(|c| c.violation(&self.x[r])).sum()
    }
    fn swap(&mut self, a: usize, b: usize, k: usize) {
        let (pa, pb) = (self.p[a][k], self.p[b][k]);
        let (xa, xb) = (self.x[a][k], self.x[b][k]);
        self.p[a][k] = pb;
        self.p[b][k] = pa;
        self.x[a][k] = xb;
        self.x[b][k] = xa;
    }
    /// Columns in a constraint that row `r` violates.
    fn violated_columns(&self, r: usize) -> Vec<usize> {
        let mut cols = Vec::new();
        for c in self.cons.iter().filter(|c| !c.holds(&self.x[r])) {
            for k in [c.i, c.j] {
                if !cols.contains(&k) {
                    cols.push(k);
                }
            }
        }
        cols
    }
    /// Feasible interval of `x[r][k]` given the row's other values.
    fn feasible_interval(&self, r: usize, k: usize) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        let x = &self.x[r];
        for c in self.cons {
            if c.i == k && c.j != k {
                hi = hi.min(c.c + x[c.j]);
            } else if c.j == k && c.i != k {
                lo = lo.max(x[c.i] - c.c);
            }
        }
        (lo, hi)
    }
}

fn min_distance(d2: &[Vec<f64>]) -> f64 {
    let mut m = f64::INFINITY;
    for (a, row) in d2.iter().enumerate() {
        for &v in &row[a + 1..] {
            m = m.min(v);
        }
    }
    m.sqrt()
}

/// The candidate farthest from every point of `existing` (maximin: the largest distance to its
/// nearest neighbour), all in probability space `p = F(x)`, where the hypercube's own maximin
/// criterion works (Morris & Mitchell 1995); `None` when there is no candidate. Ties go to the
/// first. Used to replace a design point that could not be simulated while keeping the design
/// space-filling.
pub fn farthest_candidate(existing: &[Vec<f64>], candidates: &[Vec<f64>]) -> Option<usize> {
    let nearest = |c: &[f64]| {
        existing
            .iter()
            .map(|e| e.iter().zip(c).map(|(a, b)| (a - b) * (a - b)).sum::<f64>())
            .fold(f64::INFINITY, f64::min)
    };
    let mut best: Option<(usize, f64)> = None;
    for (i, c) in candidates.iter().enumerate() {
        let d = nearest(c);
        if best.is_none_or(|(_, b)| d > b) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| i)
}

/// A Latin hypercube of `n` design points over `priors`, seeded by `seed` (`ChaCha8Rng`).
///
/// Errors if `n == 0`, there are no priors, a constraint names a missing parameter, or some
/// rows violate the constraints after repair ([`StatsError::InfeasibleDesign`]).
pub fn latin_hypercube(
    priors: &[Triangular],
    n: usize,
    seed: u64,
    options: &LhsOptions,
) -> Result<Design> {
    let d = priors.len();
    if n == 0 || d == 0 {
        return Err(StatsError::Invalid(
            "a design needs at least one point and one parameter".into(),
        ));
    }
    for c in &options.constraints {
        if c.i >= d || c.j >= d || c.i == c.j || !c.c.is_finite() {
            return Err(StatsError::Invalid(format!(
                "constraint x[{}] - x[{}] <= {} does not fit {d} parameters",
                c.i, c.j, c.c
            )));
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut p = vec![vec![0.0; d]; n];
    let mut perm: Vec<usize> = (0..n).collect();
    for k in 0..d {
        perm.shuffle(&mut rng);
        for (row, &s) in p.iter_mut().zip(&perm) {
            let u: f64 = rng.random();
            row[k] = (s as f64 + u) / n as f64;
        }
    }
    let x = p
        .iter()
        .map(|row| {
            row.iter()
                .zip(priors)
                .map(|(&pk, t)| t.quantile(pk))
                .collect()
        })
        .collect();
    let mut w = Work {
        priors,
        cons: &options.constraints,
        p,
        x,
    };
    let repair = repair(&mut w, &mut rng)?;
    let (maximin_swaps, min_dist) = maximin(&mut w, &mut rng, options.maximin_iterations);
    Ok(Design {
        points: w.x,
        probabilities: w.p,
        repair,
        maximin_swaps,
        min_distance: min_dist,
    })
}

fn repair(w: &mut Work, rng: &mut ChaCha8Rng) -> Result<RepairReport> {
    let n = w.p.len();
    let mut report = RepairReport::default();
    if w.cons.is_empty() {
        return Ok(report);
    }
    report.rows_infeasible_before = (0..n).filter(|&r| w.viol(r) > 0.0).count();
    repair_by_swaps(w, rng, &mut report);
    let still = repair_by_resampling(w, rng, &mut report);
    if !still.is_empty() {
        return Err(StatsError::InfeasibleDesign { rows: still });
    }
    Ok(report)
}

/// Repair, step 1: swaps of a cell between rows within its column, which keep every
/// column's strata, until no row is infeasible or a pass makes no progress.
fn repair_by_swaps(w: &mut Work, rng: &mut ChaCha8Rng, report: &mut RepairReport) {
    let n = w.p.len();
    for _pass in 0..(4 * n).max(16) {
        let bad: Vec<usize> = (0..n).filter(|&r| w.viol(r) > 0.0).collect();
        if bad.is_empty() {
            break;
        }
        let mut progress = false;
        for &r in &bad {
            let vr = w.viol(r);
            if vr == 0.0 {
                continue;
            }
            let offset = rng.random_range(0..n);
            let best = best_swap(w, r, vr, offset);
            if let Some((_, s, k)) = best {
                w.swap(r, s, k);
                report.swaps += 1;
                progress = true;
            }
        }
        if !progress {
            break;
        }
    }
}

/// The swap (gain, other row, column) that best repairs infeasible row `r` (violation `vr`),
/// trying rows from `offset` on: the first that makes `r` feasible without breaking a
/// feasible row (gain -inf), else the largest fall of the two rows' total violation.
fn best_swap(w: &mut Work, r: usize, vr: f64, offset: usize) -> Option<(f64, usize, usize)> {
    let n = w.p.len();
    let mut best: Option<(f64, usize, usize)> = None;
    'search: for k in w.violated_columns(r) {
        for t in 0..n {
            let s = (offset + t) % n;
            if s == r {
                continue;
            }
            let vs = w.viol(s);
            w.swap(r, s, k);
            let (nr, ns) = (w.viol(r), w.viol(s));
            w.swap(r, s, k);
            // A swap that fixes r without breaking a feasible s is taken at once.
            if nr == 0.0 && (ns == 0.0 || vs > 0.0 && ns < vs) {
                best = Some((f64::NEG_INFINITY, s, k));
                break 'search;
            }
            let gain = (nr + ns) - (vr + vs);
            if gain < 0.0 && (vs > 0.0 || ns == 0.0) && best.is_none_or(|b| gain < b.0) {
                best = Some((gain, s, k));
            }
        }
    }
    best
}

/// Repair, step 2: a cell of each row still infeasible resampled inside its stratum, else
/// anywhere in its prior. Returns the rows that stay infeasible.
fn repair_by_resampling(
    w: &mut Work,
    rng: &mut ChaCha8Rng,
    report: &mut RepairReport,
) -> Vec<usize> {
    let n = w.p.len();
    let mut still = Vec::new();
    for r in 0..n {
        for outside in [false, true] {
            let mut tries = 0;
            while w.viol(r) > 0.0 && tries < 2 * w.p[r].len() {
                tries += 1;
                let mut fixed = false;
                for k in w.violated_columns(r) {
                    let t = &w.priors[k];
                    let (lo, hi) = w.feasible_interval(r, k);
                    let (slo, shi) = if outside {
                        (t.min(), t.max())
                    } else {
                        let s = stratum(w.p[r][k], n);
                        (
                            t.quantile(s as f64 / n as f64),
                            t.quantile((s + 1) as f64 / n as f64),
                        )
                    };
                    let (a, b) = (lo.max(slo), hi.min(shi));
                    if a > b {
                        continue;
                    }
                    let (pa, pb) = (t.cdf(a), t.cdf(b));
                    let u: f64 = rng.random();
                    let old = w.p[r][k];
                    w.set(r, k, pa + u * (pb - pa));
                    if w.x[r][k] > b || w.x[r][k] < a {
                        // Guard against inverse-CDF rounding at the interval's ends.
                        w.set(r, k, old);
                        continue;
                    }
                    if outside {
                        report.resampled_outside_stratum += 1;
                    } else {
                        report.resampled_in_stratum += 1;
                    }
                    fixed = true;
                    break;
                }
                if !fixed && outside {
                    // No single cell can fix the row: move x[j] of a violated constraint to
                    // where some x[i] in its support satisfies it (x[j] >= min_i - c); the
                    // next round then places x[i].
                    let first = w.cons.iter().find(|c| !c.holds(&w.x[r])).copied();
                    if let Some(c) = first {
                        let (ti, tj) = (w.priors[c.i], w.priors[c.j]);
                        let (a, b) = ((ti.min() - c.c).max(tj.min()), tj.max());
                        if a <= b {
                            let (pa, pb) = (tj.cdf(a), tj.cdf(b));
                            let u: f64 = rng.random();
                            w.set(r, c.j, pa + u * (pb - pa));
                            report.resampled_outside_stratum += 1;
                            fixed = true;
                        }
                    }
                }
                if !fixed {
                    break;
                }
            }
        }
        if w.viol(r) > 0.0 {
            still.push(r);
        }
    }
    still
}

// Symmetric updates of the distance matrix read clearest with indices.
#[allow(clippy::needless_range_loop)]
fn maximin(w: &mut Work, rng: &mut ChaCha8Rng, iterations: usize) -> (usize, f64) {
    let n = w.p.len();
    let d = w.p[0].len();
    let dist2 = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    let mut d2: Vec<Vec<f64>> = (0..n)
        .map(|a| (0..n).map(|b| dist2(&w.p[a], &w.p[b])).collect())
        .collect();
    let mut best = min_distance(&d2);
    let mut accepted = 0;
    if n < 3 {
        return (0, best);
    }
    for _ in 0..iterations {
        let k = rng.random_range(0..d);
        let a = rng.random_range(0..n);
        let mut b = rng.random_range(0..n - 1);
        if b >= a {
            b += 1;
        }
        w.swap(a, b, k);
        if !w.cons.is_empty() && (w.viol(a) > 0.0 || w.viol(b) > 0.0) {
            w.swap(a, b, k);
            continue;
        }
        let old_a = d2[a].clone();
        let old_b = d2[b].clone();
        for m in 0..n {
            let da = dist2(&w.p[a], &w.p[m]);
            let db = dist2(&w.p[b], &w.p[m]);
            d2[a][m] = da;
            d2[m][a] = da;
            d2[b][m] = db;
            d2[m][b] = db;
        }
        let cand = min_distance(&d2);
        if cand >= best {
            best = cand;
            accepted += 1;
        } else {
            w.swap(a, b, k);
            for (m, (&va, &vb)) in old_a.iter().zip(&old_b).enumerate() {
                d2[a][m] = va;
                d2[m][a] = va;
                d2[b][m] = vb;
                d2[m][b] = vb;
            }
        }
    }
    (accepted, best)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn farthest_candidate_is_the_maximin_one() {
        let existing = vec![vec![0.1, 0.1], vec![0.9, 0.9]];
        let candidates = vec![vec![0.2, 0.2], vec![0.9, 0.1], vec![0.5, 0.5]];
        assert_eq!(farthest_candidate(&existing, &candidates), Some(1));
        assert_eq!(farthest_candidate(&existing, &[]), None);
        assert_eq!(farthest_candidate(&[], &candidates), Some(0));
    }
}
