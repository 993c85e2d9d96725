//! k-medoids clustering (PAM: BUILD + SWAP, Kaufman & Rousseeuw 1990) on a precomputed distance
//! matrix, and the silhouette for choosing k.
//!
//! PAM is used rather than k-means because DTW gives only pairwise distances (there is no DTW
//! mean to update); medoids are actual days, and the result is deterministic (no random start).
//! The silhouette of point i is `(b - a) / max(a, b)` with `a` its mean distance to its own
//! cluster and `b` the smallest mean distance to another cluster (0 for singletons); the score of
//! a clustering is the mean over points.

use serde::{Deserialize, Serialize};

use crate::dtw::DistanceMatrix;
use crate::PrecalError;

/// A k-medoids clustering.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Clustering {
    /// Number of clusters.
    pub k: usize,
    /// Medoid (point index) of each cluster.
    pub medoids: Vec<usize>,
    /// Cluster (0..k) of each point.
    pub labels: Vec<usize>,
    /// Sum of distances of points to their medoid.
    pub cost: f64,
    /// Mean silhouette.
    pub silhouette: f64,
}

/// PAM with `k` clusters on `d`. Errors when `k` is 0 or larger than the number of points.
pub fn pam(d: &DistanceMatrix, k: usize) -> Result<Clustering, PrecalError> {
    let n = d.n;
    if k == 0 || k > n {
        return Err(PrecalError::Invalid(format!(
            "k-medoids needs 1 <= k <= n points; k = {k}, n = {n}"
        )));
    }
    // BUILD: greedy medoids minimising the total cost.
    let mut medoids: Vec<usize> = Vec::with_capacity(k);
    let mut nearest = vec![f64::INFINITY; n];
    for _ in 0..k {
        let mut best = (f64::INFINITY, usize::MAX);
        for c in 0..n {
            if medoids.contains(&c) {
                continue;
            }
            let cost: f64 = (0..n).map(|i| nearest[i].min(d.get(i, c))).sum();
            if cost < best.0 {
                best = (cost, c);
            }
        }
        medoids.push(best.1);
        for (i, nr) in nearest.iter_mut().enumerate() {
            *nr = nr.min(d.get(i, best.1));
        }
    }
    // SWAP: best improving (medoid, non-medoid) exchange until none improves.
    let mut cost = total_cost(d, &medoids);
    for _ in 0..100 {
        let (dn, ds, near_idx) = nearest_two(d, &medoids);
        let mut best = (0.0, 0usize, 0usize);
        for (mi, _) in medoids.iter().enumerate() {
            for h in 0..n {
                if medoids.contains(&h) {
                    continue;
                }
                let mut delta = 0.0;
                for j in 0..n {
                    let djh = d.get(j, h);
                    if near_idx[j] == mi {
                        delta += djh.min(ds[j]) - dn[j];
                    } else if djh < dn[j] {
                        delta += djh - dn[j];
                    }
                }
                if delta < best.0 - 1e-12 {
                    best = (delta, mi, h);
                }
            }
        }
        if best.0 >= -1e-12 {
            break;
        }
        medoids[best.1] = best.2;
        cost = total_cost(d, &medoids);
    }
    let labels = assign(d, &medoids);
    let silhouette = silhouette(d, &labels, k);
    Ok(Clustering {
        k,
        medoids,
        labels,
        cost,
        silhouette,
    })
}

fn nearest_two(d: &DistanceMatrix, medoids: &[usize]) -> (Vec<f64>, Vec<f64>, Vec<usize>) {
    let n = d.n;
    let mut dn = vec![f64::INFINITY; n];
    let mut ds = vec![f64::INFINITY; n];
    let mut idx = vec![0; n];
    for j in 0..n {
        for (mi, &m) in medoids.iter().enumerate() {
            let v = d.get(j, m);
            if v < dn[j] {
                ds[j] = dn[j];
                dn[j] = v;
                idx[j] = mi;
            } else if v < ds[j] {
                ds[j] = v;
            }
        }
    }
    (dn, ds, idx)
}

fn total_cost(d: &DistanceMatrix, medoids: &[usize]) -> f64 {
    (0..d.n)
        .map(|i| {
            medoids
                .iter()
                .map(|&m| d.get(i, m))
                .fold(f64::INFINITY, f64::min)
        })
        .sum()
}

/// Cluster of each point: index of its nearest medoid (ties: the first).
pub fn assign(d: &DistanceMatrix, medoids: &[usize]) -> Vec<usize> {
    (0..d.n)
        .map(|i| {
            let mut best = (f64::INFINITY, 0);
            for (c, &m) in medoids.iter().enumerate() {
                let v = d.get(i, m);
                if v < best.0 {
                    best = (v, c);
                }
            }
            best.1
        })
        .collect()
}

/// Mean silhouette of `labels` (clusters 0..k).
pub fn silhouette(d: &DistanceMatrix, labels: &[usize], k: usize) -> f64 {
    let n = d.n;
    if n == 0 || k < 2 {
        return 0.0;
    }
    let mut size = vec![0usize; k];
    for &l in labels {
        size[l] += 1;
    }
    let mut total = 0.0;
    let mut sums = vec![0.0; k];
    for i in 0..n {
        sums.iter_mut().for_each(|s| *s = 0.0);
        for j in 0..n {
            sums[labels[j]] += d.get(i, j);
        }
        let li = labels[i];
        if size[li] <= 1 {
            continue;
        }
        let a = sums[li] / (size[li] - 1) as f64;
        let b = (0..k)
            .filter(|&c| c != li && size[c] > 0)
            .map(|c| sums[c] / size[c] as f64)
            .fold(f64::INFINITY, f64::min);
        let s = if !b.is_finite() || a.max(b) == 0.0 {
            0.0
        } else {
            (b - a) / a.max(b)
        };
        total += s;
    }
    total / n as f64
}

/// PAM for each k in `ks` (skipping k > n); returns the clustering with the best silhouette
/// (ties: the smaller k) and the (k, silhouette) table.
pub fn choose_k(
    d: &DistanceMatrix,
    ks: std::ops::RangeInclusive<usize>,
) -> Result<(Clustering, Vec<(usize, f64)>), PrecalError> {
    let mut best: Option<Clustering> = None;
    let mut table = Vec::new();
    for k in ks {
        if k < 2 || k > d.n {
            continue;
        }
        let c = pam(d, k)?;
        table.push((k, c.silhouette));
        if best
            .as_ref()
            .is_none_or(|b| c.silhouette > b.silhouette + 1e-12)
        {
            best = Some(c);
        }
    }
    best.map(|b| (b, table))
        .ok_or_else(|| PrecalError::Invalid(format!("too few days ({}) to cluster", d.n)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line_matrix(x: &[f64]) -> DistanceMatrix {
        let n = x.len();
        let data = (0..n * n).map(|k| (x[k / n] - x[k % n]).abs()).collect();
        DistanceMatrix::from_full(n, data).unwrap()
    }

    #[test]
    fn two_groups_found_with_high_silhouette() {
        let x = [0.0, 0.1, 0.2, 0.15, 5.0, 5.1, 5.3, 4.9, 5.05];
        let d = line_matrix(&x);
        let (c, table) = choose_k(&d, 2..=6).unwrap();
        assert_eq!(c.k, 2);
        assert_eq!(table.len(), 5);
        assert!(c.silhouette > 0.9);
        assert!(c.labels[..4].iter().all(|&l| l == c.labels[0]));
        assert!(c.labels[4..].iter().all(|&l| l == c.labels[4]));
        assert_ne!(c.labels[0], c.labels[4]);
        assert!(x[c.medoids[c.labels[0]]] < 1.0);
    }

    #[test]
    fn pam_finds_optimum_on_small_case() {
        let x = [0.0, 1.0, 2.0, 10.0, 11.0, 30.0];
        let d = line_matrix(&x);
        let c = pam(&d, 3).unwrap();
        // Optimal: {0,1,2} medoid 1 (cost 2), {10,11} (cost 1), {30} (0).
        assert!((c.cost - 3.0).abs() < 1e-12, "{c:?}");
        assert!(pam(&d, 0).is_err());
        assert!(pam(&d, 7).is_err());
    }
}
