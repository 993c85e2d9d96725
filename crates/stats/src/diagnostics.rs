//! Convergence diagnostics of several chains of one parameter: rank-normalised split R-hat,
//! bulk and tail effective sample size, exactly as Vehtari, Gelman, Simpson, Carpenter and
//! Bürkner (2021), "Rank-normalization, folding, and localization: an improved R-hat for
//! assessing convergence of MCMC", Bayesian Analysis 16(2), and as implemented in ArviZ 0.23
//! (`az.rhat(method="rank")`, `az.ess(method="bulk")`, `az.ess(method="tail")`).
//!
//! Conventions, matching ArviZ:
//! - **Splitting**: each chain of `n` draws is split into its first `n / 2` (integer division)
//!   and its last `n / 2` draws. For an **odd** `n` the middle draw is dropped (ArviZ's
//!   `_split_chains`: `ary[:, :half]` and `ary[:, -half:]`).
//! - **Rank normalisation**: average ranks of all split draws pooled (ties share the mean rank),
//!   `z = Phi^-1((r - 3/8) / (S + 1/4))` (Blom), `S` the number of pooled draws.
//! - **R-hat** = max(bulk R-hat on the z-scores, tail R-hat on the z-scores of the draws folded
//!   about the median of the split draws). NaN with fewer than 2 chains or 4 draws.
//! - **ESS**: autocovariances by FFT (biased, divided by `n`), combined over chains as in
//!   Stan/ArviZ, truncated by Geyer's initial positive sequence and made monotone by Geyer's
//!   initial monotone sequence; `tau >= 1 / log10(S)`. Bulk ESS on the split rank-normalised
//!   draws; tail ESS = min of the ESS of the indicators `draw <= q05` and `draw <= q95`
//!   (quantiles of all draws, unsplit, linear interpolation), computed on split chains.
//! - Any NaN among the draws gives NaN, as ArviZ does.

use rustfft::{num_complex::Complex, FftPlanner};
use serde::{Deserialize, Serialize};

use crate::error::{Result, StatsError};
use crate::normal::norm_ppf;

/// Diagnostics and summary statistics of one parameter over all chains.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ParameterDiagnostics {
    /// Mean over all draws.
    pub mean: f64,
    /// Standard deviation over all draws (`ddof = 1`).
    pub sd: f64,
    /// 5 % quantile (numpy linear interpolation).
    pub q5: f64,
    /// Median.
    pub q50: f64,
    /// 95 % quantile.
    pub q95: f64,
    /// Rank-normalised split R-hat, max of bulk and tail.
    pub rhat: f64,
    /// Bulk R-hat.
    pub rhat_bulk: f64,
    /// Tail (folded) R-hat.
    pub rhat_tail: f64,
    /// Bulk effective sample size.
    pub ess_bulk: f64,
    /// Tail effective sample size.
    pub ess_tail: f64,
}

/// Check the chains form a rectangular array; returns (chains, draws per chain).
fn shape<C: AsRef<[f64]>>(chains: &[C]) -> Result<(usize, usize)> {
    let m = chains.len();
    if m == 0 {
        return Err(StatsError::NotEnoughData("no chains".into()));
    }
    let n = chains[0].as_ref().len();
    if let Some((i, c)) = chains
        .iter()
        .enumerate()
        .find(|(_, c)| c.as_ref().len() != n)
    {
        return Err(StatsError::Shape(format!(
            "chain 0 has {n} draws but chain {i} has {}",
            c.as_ref().len()
        )));
    }
    Ok((m, n))
}

fn has_nan<C: AsRef<[f64]>>(chains: &[C]) -> bool {
    chains.iter().any(|c| c.as_ref().iter().any(|v| v.is_nan()))
}

/// Split every chain into halves (middle draw dropped when odd), as ArviZ `_split_chains`.
fn split_chains<C: AsRef<[f64]>>(chains: &[C]) -> Vec<Vec<f64>> {
    let mut out = Vec::with_capacity(2 * chains.len());
    for c in chains {
        let c = c.as_ref();
        let half = c.len() / 2;
        out.push(c[..half].to_vec());
    }
    for c in chains {
        let c = c.as_ref();
        let half = c.len() / 2;
        out.push(c[c.len() - half..].to_vec());
    }
    out
}

/// Mean of a slice.
pub fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// Sample variance with `ddof` degrees of freedom removed.
pub fn var(x: &[f64], ddof: usize) -> f64 {
    let m = mean(x);
    x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (x.len() - ddof) as f64
}

/// Sample standard deviation (`ddof = 1`).
pub fn sd(x: &[f64]) -> f64 {
    var(x, 1).sqrt()
}

/// Quantile of unsorted values with numpy's default (linear, R type 7) interpolation:
/// position `h = (n - 1) q`, `x[floor h] + (h - floor h) (x[floor h + 1] - x[floor h])`.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    quantile_sorted(&v, q)
}

/// [`quantile`] of already sorted values (ascending).
pub fn quantile_sorted(sorted: &[f64], q: f64) -> f64 {
    let n = sorted.len();
    if n == 0 || !(0.0..=1.0).contains(&q) {
        return f64::NAN;
    }
    let h = (n - 1) as f64 * q;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(n - 1);
    let frac = h - lo as f64;
    // numpy's _lerp: a + (b - a) t, switched to b - (b - a)(1 - t) for t >= 0.5.
    let (a, b) = (sorted[lo], sorted[hi]);
    let d = b - a;
    if frac >= 0.5 {
        b - d * (1.0 - frac)
    } else {
        a + d * frac
    }
}

/// Rank-normalise all values pooled (average ranks for ties), Blom offset 3/8.
fn z_scale(chains: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let flat: Vec<f64> = chains.iter().flatten().copied().collect();
    let s = flat.len();
    let mut idx: Vec<usize> = (0..s).collect();
    idx.sort_by(|&a, &b| flat[a].total_cmp(&flat[b]));
    let mut rank = vec![0.0; s];
    let mut i = 0;
    while i < s {
        let mut j = i;
        while j + 1 < s && flat[idx[j + 1]] == flat[idx[i]] {
            j += 1;
        }
        // Ranks are 1-based; tied values i..=j share the average rank.
        let r = (i + j) as f64 / 2.0 + 1.0;
        for &k in &idx[i..=j] {
            rank[k] = r;
        }
        i = j + 1;
    }
    let c = 3.0 / 8.0;
    let denom = s as f64 - 2.0 * c + 1.0;
    let mut out = Vec::with_capacity(chains.len());
    let mut k = 0;
    for ch in chains {
        out.push(
            (0..ch.len())
                .map(|t| norm_ppf((rank[k + t] - c) / denom))
                .collect(),
        );
        k += ch.len();
    }
    out
}

/// Classic (non-split) potential scale reduction of a rectangular array (Gelman-Rubin,
/// BDA3 Eq. 11.4), as ArviZ `_rhat`.
fn rhat_core(chains: &[Vec<f64>]) -> f64 {
    let n = chains[0].len() as f64;
    let means: Vec<f64> = chains.iter().map(|c| mean(c)).collect();
    let b = n * var(&means, 1);
    let w = mean(&chains.iter().map(|c| var(c, 1)).collect::<Vec<_>>());
    ((b / w + n - 1.0) / n).sqrt()
}

/// Bulk and tail rank-normalised split R-hat; `(NaN, NaN)` with fewer than 2 chains or fewer
/// than 4 draws per chain, or any NaN draw.
pub fn rhat_bulk_tail<C: AsRef<[f64]>>(chains: &[C]) -> Result<(f64, f64)> {
    let (m, n) = shape(chains)?;
    if m < 2 || n < 4 || has_nan(chains) {
        return Ok((f64::NAN, f64::NAN));
    }
    let split = split_chains(chains);
    let bulk = rhat_core(&z_scale(&split));
    let flat: Vec<f64> = split.iter().flatten().copied().collect();
    let med = quantile(&flat, 0.5);
    let folded: Vec<Vec<f64>> = split
        .iter()
        .map(|c| c.iter().map(|v| (v - med).abs()).collect())
        .collect();
    let tail = rhat_core(&z_scale(&folded));
    Ok((bulk, tail))
}

/// Rank-normalised split R-hat, `max(bulk, tail)` (Vehtari et al. 2021, Section 4.2;
/// `az.rhat(method="rank")`).
pub fn rhat<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64> {
    let (b, t) = rhat_bulk_tail(chains)?;
    Ok(if b.is_nan() || t.is_nan() {
        f64::NAN
    } else {
        b.max(t)
    })
}

/// Biased autocovariance (divided by `n`) of one chain, lags `0..n`, via zero-padded FFT.
fn autocov(x: &[f64], planner: &mut FftPlanner<f64>) -> Vec<f64> {
    let n = x.len();
    let m = (2 * n).next_power_of_two();
    let mu = mean(x);
    let mut buf: Vec<Complex<f64>> = x
        .iter()
        .map(|&v| Complex::new(v - mu, 0.0))
        .chain(std::iter::repeat(Complex::new(0.0, 0.0)))
        .take(m)
        .collect();
    planner.plan_fft_forward(m).process(&mut buf);
    for c in buf.iter_mut() {
        *c = Complex::new(c.norm_sqr(), 0.0);
    }
    planner.plan_fft_inverse(m).process(&mut buf);
    // rustfft's inverse is unnormalised: divide by m, then by n for the biased estimate.
    buf[..n]
        .iter()
        .map(|c| c.re / m as f64 / n as f64)
        .collect()
}

/// Effective sample size of a rectangular array (no splitting), ArviZ `_ess`: Geyer's initial
/// positive then initial monotone sequence on the multi-chain autocorrelation (Vehtari et al.
/// 2021, Eq. 10; Stan reference manual, "Effective sample size").
fn ess_core(chains: &[Vec<f64>]) -> f64 {
    let m = chains.len();
    let n = chains[0].len();
    let size = (m * n) as f64;
    let (lo, hi) = chains
        .iter()
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    // numpy's finfo(float).resolution.
    if hi - lo < 1e-15 {
        return size;
    }
    let mut planner = FftPlanner::new();
    let acov: Vec<Vec<f64>> = chains.iter().map(|c| autocov(c, &mut planner)).collect();
    let mean_acov = |t: usize| acov.iter().map(|a| a[t]).sum::<f64>() / m as f64;
    let chain_mean: Vec<f64> = chains.iter().map(|c| mean(c)).collect();
    let nf = n as f64;
    let mean_var = mean_acov(0) * nf / (nf - 1.0);
    let mut var_plus = mean_var * (nf - 1.0) / nf;
    if m > 1 {
        var_plus += var(&chain_mean, 1);
    }

    let mut rho = vec![0.0; n];
    let mut rho_even = 1.0;
    rho[0] = rho_even;
    let mut rho_odd = 1.0 - (mean_var - mean_acov(1)) / var_plus;
    rho[1] = rho_odd;

    // Geyer's initial positive sequence.
    let mut t = 1usize;
    while t + 3 < n && rho_even + rho_odd > 0.0 {
        rho_even = 1.0 - (mean_var - mean_acov(t + 1)) / var_plus;
        rho_odd = 1.0 - (mean_var - mean_acov(t + 2)) / var_plus;
        if rho_even + rho_odd >= 0.0 {
            rho[t + 1] = rho_even;
            rho[t + 2] = rho_odd;
        }
        t += 2;
    }
    // max_t = t - 2 (t >= 1, so max_t >= -1; with ArviZ's indexing max_t + 1 >= 0).
    let max_t = t as isize - 2;
    if rho_even > 0.0 {
        rho[(max_t + 1) as usize] = rho_even;
    }
    // Geyer's initial monotone sequence.
    let mut t = 1isize;
    while t <= max_t - 2 {
        let tu = t as usize;
        if rho[tu + 1] + rho[tu + 2] > rho[tu - 1] + rho[tu] {
            rho[tu + 1] = (rho[tu - 1] + rho[tu]) / 2.0;
            rho[tu + 2] = rho[tu + 1];
        }
        t += 2;
    }
    // numpy slices: rho[:max_t + 1] and rho[max_t + 1 : max_t + 2].
    let head_end = (max_t + 1).max(0) as usize;
    let head: f64 = if max_t + 1 < 0 {
        // rho[:0] with max_t = -1 is empty.
        0.0
    } else {
        rho[..head_end].iter().sum()
    };
    let tail: f64 = rho[head_end..(head_end + 1).min(n)].iter().sum();
    let mut tau = -1.0 + 2.0 * head + tail;
    tau = tau.max(1.0 / size.log10());
    if rho.iter().any(|r| r.is_nan()) {
        return f64::NAN;
    }
    size / tau
}

/// Bulk effective sample size: ESS of the split, rank-normalised draws
/// (Vehtari et al. 2021, Section 4.3; `az.ess(method="bulk")`). NaN with fewer than 4 draws
/// per chain or any NaN draw.
pub fn ess_bulk<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64> {
    let (_, n) = shape(chains)?;
    if n < 4 || has_nan(chains) {
        return Ok(f64::NAN);
    }
    Ok(ess_core(&z_scale(&split_chains(chains))))
}

/// ESS of the indicator `draw <= quantile(prob)` on split chains (ArviZ `_ess_quantile`).
fn ess_quantile<C: AsRef<[f64]>>(chains: &[C], prob: f64) -> f64 {
    let flat: Vec<f64> = chains.iter().flat_map(|c| c.as_ref()).copied().collect();
    let q = quantile(&flat, prob);
    let ind: Vec<Vec<f64>> = chains
        .iter()
        .map(|c| {
            c.as_ref()
                .iter()
                .map(|&v| if v <= q { 1.0 } else { 0.0 })
                .collect()
        })
        .collect();
    ess_core(&split_chains(&ind))
}

/// Tail effective sample size: min of the ESS of the 5 % and 95 % quantile indicators
/// (Vehtari et al. 2021, Section 4.3; `az.ess(method="tail")`).
pub fn ess_tail<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64> {
    let (_, n) = shape(chains)?;
    if n < 4 || has_nan(chains) {
        return Ok(f64::NAN);
    }
    Ok(ess_quantile(chains, 0.05).min(ess_quantile(chains, 0.95)))
}

/// All diagnostics and summary statistics of one parameter's chains.
pub fn diagnose<C: AsRef<[f64]>>(chains: &[C]) -> Result<ParameterDiagnostics> {
    let (_, n) = shape(chains)?;
    if n == 0 {
        return Err(StatsError::NotEnoughData("chains have no draws".into()));
    }
    let mut flat: Vec<f64> = chains.iter().flat_map(|c| c.as_ref()).copied().collect();
    let mean_all = mean(&flat);
    let sd_all = if flat.len() > 1 { sd(&flat) } else { f64::NAN };
    flat.sort_by(f64::total_cmp);
    let (rhat_bulk, rhat_tail) = rhat_bulk_tail(chains)?;
    Ok(ParameterDiagnostics {
        mean: mean_all,
        sd: sd_all,
        q5: quantile_sorted(&flat, 0.05),
        q50: quantile_sorted(&flat, 0.5),
        q95: quantile_sorted(&flat, 0.95),
        rhat: if rhat_bulk.is_nan() || rhat_tail.is_nan() {
            f64::NAN
        } else {
            rhat_bulk.max(rhat_tail)
        },
        rhat_bulk,
        rhat_tail,
        ess_bulk: ess_bulk(chains)?,
        ess_tail: ess_tail(chains)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_drops_middle_of_odd_chain() {
        let s = split_chains(&[vec![1.0, 2.0, 3.0, 4.0, 5.0]]);
        assert_eq!(s, vec![vec![1.0, 2.0], vec![4.0, 5.0]]);
    }

    #[test]
    fn quantile_matches_numpy_linear() {
        // np.quantile([3, 1, 4, 1, 5], [0.05, 0.5, 0.95, 0.3]) = [1.0, 3.0, 4.8, 1.4]
        let v = [3.0, 1.0, 4.0, 1.0, 5.0];
        assert!((quantile(&v, 0.05) - 1.0).abs() < 1e-15);
        assert!((quantile(&v, 0.5) - 3.0).abs() < 1e-15);
        assert!((quantile(&v, 0.95) - 4.8).abs() < 1e-12);
        assert!((quantile(&v, 0.3) - 1.4).abs() < 1e-12);
    }

    #[test]
    fn autocov_matches_direct() {
        let x: Vec<f64> = (0..37).map(|i| ((i * 7919) % 31) as f64 * 0.1).collect();
        let mut p = FftPlanner::new();
        let a = autocov(&x, &mut p);
        let mu = mean(&x);
        for lag in [0, 1, 5, 36] {
            let d: f64 = (0..x.len() - lag)
                .map(|t| (x[t] - mu) * (x[t + lag] - mu))
                .sum::<f64>()
                / x.len() as f64;
            assert!((a[lag] - d).abs() < 1e-12, "lag {lag}");
        }
    }

    #[test]
    fn ragged_and_degenerate() {
        assert!(rhat(&[vec![1.0, 2.0, 3.0, 4.0], vec![1.0]]).is_err());
        assert!(rhat(&[vec![1.0, 2.0, 3.0, 4.0]]).unwrap().is_nan());
        assert!(ess_bulk(&[vec![1.0, 2.0, 3.0]]).unwrap().is_nan());
        // Constant draws: ArviZ returns the number of draws for the ESS.
        assert_eq!(ess_tail(&[vec![2.0; 10], vec![2.0; 10]]).unwrap(), 20.0);
    }
}
