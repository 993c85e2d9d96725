//! Dynamic time warping with a Sakoe-Chiba band.
//!
//! The distance is exactly `dtaidistance.dtw.distance(s1, s2, window=W)` (dtaidistance 2.5,
//! default settings): local cost `(a_i - b_j)^2`, accumulated with the three-way minimum
//! (match, insertion, deletion, no penalty), and the square root of the accumulated cost at the
//! end.
//!
//! **Band semantics.** [`Band::new(w)`](Band::new) allows cells with `|i - j| <= w` (for series of
//! equal length; for unequal lengths the band is widened by the length difference exactly as
//! dtaidistance does). dtaidistance's `window` counts differently: it allows `|i - j| < window`,
//! so `Band::new(w)` equals dtaidistance `window = w + 1` ([`Band::dtaidistance_window`]).
//! `Band::new(0)` is the Euclidean distance; for 24-hour profiles `w >= 23` is unconstrained.
//!
//! Cost: O(n * w) time with two rows of length `m + 1` (allocated once per call, or reused
//! through [`DtwBuffer`]); the pairwise matrix is computed over the upper triangle in parallel
//! with rayon.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::PrecalError;

/// Sakoe-Chiba band: the largest allowed warp `|i - j|`, or unconstrained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Band {
    /// Largest allowed `|i - j|`; `None` = unconstrained.
    pub max_shift: Option<usize>,
}

impl Band {
    /// A band allowing `|i - j| <= w`.
    pub fn new(w: usize) -> Band {
        Band { max_shift: Some(w) }
    }

    /// No band: every cell of the cost matrix is allowed.
    pub fn unconstrained() -> Band {
        Band { max_shift: None }
    }

    /// Validates a band width given as a signed number (e.g. from a project file): `w >= 0`.
    pub fn from_signed(w: i64) -> Result<Band, PrecalError> {
        if w < 0 {
            return Err(PrecalError::Invalid(format!(
                "DTW band width must be >= 0 (|i - j| <= w), got {w}"
            )));
        }
        Ok(Band::new(w as usize))
    }

    /// The band matching dtaidistance's `window` argument (`window >= 1`; `|i - j| < window`).
    pub fn from_dtaidistance_window(window: usize) -> Result<Band, PrecalError> {
        if window == 0 {
            return Err(PrecalError::Invalid(
                "dtaidistance window must be >= 1 (window 0 allows no cell)".into(),
            ));
        }
        Ok(Band::new(window - 1))
    }

    /// dtaidistance's `window` for series of length `n` (`None` if unconstrained).
    pub fn dtaidistance_window(self) -> Option<usize> {
        self.max_shift.map(|w| w + 1)
    }

    /// dtaidistance's internal window (`|i - j| < window`) for lengths `r`, `c`.
    fn window(self, r: usize, c: usize) -> usize {
        match self.max_shift {
            Some(w) => w.saturating_add(1),
            None => r.max(c),
        }
    }
}

/// Pairs computed together by the matrix kernel (one series against `LANES` others of equal
/// length, lane-parallel so the compiler can vectorise across pairs).
const LANES: usize = 8;

/// Reusable working memory for [`distance_with`] (two rows of the cost matrix).
#[derive(Debug, Default, Clone)]
pub struct DtwBuffer {
    prev: Vec<f64>,
    cur: Vec<f64>,
    lprev: Vec<[f64; LANES]>,
    lcur: Vec<[f64; LANES]>,
    lb: Vec<[f64; LANES]>,
}

/// DTW of `s1` against `LANES` series of one common length at once; identical arithmetic per
/// lane to [`distance_with`].
fn distance_lanes(
    s1: &[f64],
    s2: [&[f64]; LANES],
    band: Band,
    buf: &mut DtwBuffer,
) -> [f64; LANES] {
    let (r, c) = (s1.len(), s2[0].len());
    let window = band.window(r, c);
    let extra_r = r.saturating_sub(c);
    let extra_c = c.saturating_sub(r);
    buf.lb.clear();
    buf.lb
        .extend((0..c).map(|j| std::array::from_fn(|l| s2[l][j])));
    buf.lprev.clear();
    buf.lprev.resize(c + 1, [f64::INFINITY; LANES]);
    buf.lcur.clear();
    buf.lcur.resize(c + 1, [f64::INFINITY; LANES]);
    buf.lprev[0] = [0.0; LANES];
    let b = &buf.lb[..];
    let (mut prev, mut cur) = (&mut buf.lprev, &mut buf.lcur);
    for (i, &a) in s1.iter().enumerate() {
        let j_start = (i + 1).saturating_sub(extra_r + window);
        let j_end = (i + extra_c + window).min(c);
        cur[j_start] = [f64::INFINITY; LANES];
        if j_end < c {
            cur[j_end + 1] = [f64::INFINITY; LANES];
        }
        let mut left = [f64::INFINITY; LANES];
        for j in j_start..j_end {
            let (bj, p0, p1) = (&b[j], &prev[j], &prev[j + 1]);
            let mut v = [0.0; LANES];
            for l in 0..LANES {
                let t = a - bj[l];
                let d = t * t;
                v[l] = d + p0[l].min(p1[l]).min(left[l]);
            }
            cur[j + 1] = v;
            left = v;
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    std::array::from_fn(|l| prev[c][l].sqrt())
}

/// DTW distance between `s1` and `s2` within `band` (see the module docs for the definition).
///
/// Returns `f64::INFINITY` when either series is empty.
pub fn distance(s1: &[f64], s2: &[f64], band: Band) -> f64 {
    distance_with(s1, s2, band, &mut DtwBuffer::default())
}

/// [`distance`] reusing `buf`, so repeated calls do not allocate.
pub fn distance_with(s1: &[f64], s2: &[f64], band: Band, buf: &mut DtwBuffer) -> f64 {
    let (r, c) = (s1.len(), s2.len());
    if r == 0 || c == 0 {
        return f64::INFINITY;
    }
    let window = band.window(r, c);
    let extra_r = r.saturating_sub(c);
    let extra_c = c.saturating_sub(r);
    buf.prev.clear();
    buf.prev.resize(c + 1, f64::INFINITY);
    buf.cur.clear();
    buf.cur.resize(c + 1, f64::INFINITY);
    buf.prev[0] = 0.0;
    let (mut prev, mut cur) = (&mut buf.prev, &mut buf.cur);
    for (i, &a) in s1.iter().enumerate() {
        // dtaidistance: j in [max(0, i - max(0, r - c) - window + 1), min(c, i + max(0, c - r) + window))
        let j_start = (i + 1).saturating_sub(extra_r + window);
        let j_end = (i + extra_c + window).min(c);
        cur[j_start] = f64::INFINITY;
        if j_end < c {
            cur[j_end + 1] = f64::INFINITY;
        }
        let mut left = f64::INFINITY;
        for j in j_start..j_end {
            let t = a - s2[j];
            let d = t * t;
            // Same operands as dtaidistance: d + min(diag, up, left).
            let v = d + prev[j].min(prev[j + 1]).min(left);
            cur[j + 1] = v;
            left = v;
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[c].sqrt()
}

/// A symmetric matrix of pairwise distances with a zero diagonal, stored row-major (`n * n`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DistanceMatrix {
    /// Number of series.
    pub n: usize,
    /// Row-major `n * n` values.
    pub data: Vec<f64>,
}

impl DistanceMatrix {
    /// Distance between series `i` and `j`.
    #[inline]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.data[i * self.n + j]
    }

    /// Row `i` as a slice.
    pub fn row(&self, i: usize) -> &[f64] {
        &self.data[i * self.n..(i + 1) * self.n]
    }

    /// Builds a matrix from a full row-major array (checked for shape only).
    pub fn from_full(n: usize, data: Vec<f64>) -> Result<DistanceMatrix, PrecalError> {
        if data.len() != n * n {
            return Err(PrecalError::Invalid(format!(
                "distance matrix needs {} values for n = {n}, got {}",
                n * n,
                data.len()
            )));
        }
        Ok(DistanceMatrix { n, data })
    }
}

/// Pairwise DTW distances of `series` (upper triangle computed in parallel, mirrored).
pub fn distance_matrix<S: AsRef<[f64]> + Sync>(series: &[S], band: Band) -> DistanceMatrix {
    let n = series.len();
    let rows: Vec<Vec<f64>> = (0..n)
        .into_par_iter()
        .map_init(DtwBuffer::default, |buf, i| {
            let a = series[i].as_ref();
            let mut row = Vec::with_capacity(n - i - 1);
            let mut j = i + 1;
            while j < n {
                let len = series[j].as_ref().len();
                if j + LANES <= n
                    && len > 0
                    && (j..j + LANES).all(|k| series[k].as_ref().len() == len)
                    && !a.is_empty()
                {
                    let group: [&[f64]; LANES] = std::array::from_fn(|l| series[j + l].as_ref());
                    row.extend(distance_lanes(a, group, band, buf));
                    j += LANES;
                } else {
                    row.push(distance_with(a, series[j].as_ref(), band, buf));
                    j += 1;
                }
            }
            row
        })
        .collect();
    let mut data = vec![0.0; n * n];
    for (i, row) in rows.iter().enumerate() {
        for (k, &d) in row.iter().enumerate() {
            let j = i + 1 + k;
            data[i * n + j] = d;
            data[j * n + i] = d;
        }
    }
    DistanceMatrix { n, data }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Full-matrix textbook DTW with the same band, for cross-checking.
    fn naive(s1: &[f64], s2: &[f64], w: Option<usize>) -> f64 {
        let (r, c) = (s1.len(), s2.len());
        let mut m = vec![vec![f64::INFINITY; c + 1]; r + 1];
        m[0][0] = 0.0;
        let win = w.map(|w| w + 1).unwrap_or(r.max(c));
        for i in 0..r {
            let lo = (i + 1).saturating_sub(r.saturating_sub(c) + win);
            let hi = (i + c.saturating_sub(r) + win).min(c);
            for j in lo..hi {
                let d = (s1[i] - s2[j]).powi(2);
                m[i + 1][j + 1] = d + m[i][j].min(m[i][j + 1]).min(m[i + 1][j]);
            }
        }
        m[r][c].sqrt()
    }

    #[test]
    fn band_zero_is_euclidean_and_wide_band_is_unconstrained() {
        let a = [0.0, 1.0, 2.0, 1.0, 0.0, 0.5];
        let b = [0.0, 0.0, 1.0, 2.0, 1.0, 0.0];
        let eu: f64 = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y) * (x - y))
            .sum::<f64>()
            .sqrt();
        assert!((distance(&a, &b, Band::new(0)) - eu).abs() < 1e-12);
        let un = distance(&a, &b, Band::unconstrained());
        assert_eq!(distance(&a, &b, Band::new(5)), un);
        assert_eq!(distance(&a, &b, Band::new(50)), un);
        assert!(un < eu);
        assert_eq!(distance(&a, &a, Band::new(1)), 0.0);
    }

    #[test]
    fn matches_naive_on_pseudo_random_series_including_unequal_lengths() {
        let mut x = 12345u64;
        let mut rnd = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut buf = DtwBuffer::default();
        for (r, c) in [(24, 24), (10, 13), (13, 10), (1, 5), (7, 7)] {
            let a: Vec<f64> = (0..r).map(|_| rnd()).collect();
            let b: Vec<f64> = (0..c).map(|_| rnd()).collect();
            for w in [Some(0), Some(1), Some(2), Some(5), None] {
                let band = w.map(Band::new).unwrap_or(Band::unconstrained());
                let got = distance_with(&a, &b, band, &mut buf);
                let want = naive(&a, &b, w);
                assert!(
                    (got - want).abs() < 1e-12,
                    "{r}x{c} w={w:?}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn matrix_is_symmetric_and_matches_pairwise_calls() {
        // 21 series: the lane kernel (8 at a time) and the scalar tail are both exercised.
        let s: Vec<Vec<f64>> = (0..21)
            .map(|k| (0..24).map(|h| ((h * (k + 1)) % 7) as f64 * 0.37).collect())
            .collect();
        for band in [
            Band::new(0),
            Band::new(2),
            Band::new(5),
            Band::unconstrained(),
        ] {
            let m = distance_matrix(&s, band);
            for i in 0..s.len() {
                assert_eq!(m.get(i, i), 0.0);
                for j in 0..s.len() {
                    assert_eq!(m.get(i, j), m.get(j, i));
                    if i != j {
                        assert_eq!(m.get(i, j), distance(&s[i], &s[j], band));
                    }
                }
            }
        }
    }

    #[test]
    fn band_validation() {
        assert!(Band::from_signed(-1).is_err());
        assert_eq!(Band::from_signed(3).unwrap(), Band::new(3));
        assert!(Band::from_dtaidistance_window(0).is_err());
        assert_eq!(Band::from_dtaidistance_window(3).unwrap(), Band::new(2));
        assert_eq!(Band::new(2).dtaidistance_window(), Some(3));
    }
}
