//! Timing baselines for the reference's computational-time comparison (Jiang et al. 2024,
//! Section 4.3, Table 6): the log-likelihoods that a *traditional* (full Kennedy-O'Hagan) and a
//! *lightweight* (GP discrepancy + linear-regression emulator) Bayesian calibration evaluate at
//! every MCMC iteration, implemented faithfully enough to time them honestly on the hourly task.
//!
//! All three approaches evaluate the Gaussian likelihood of the reference's Eq. 5,
//!
//! `ln p(z | theta, phi) = -1/2 [ N ln(2 pi) + ln|Sigma| + (z - mu)^T Sigma^-1 (z - mu) ]`,
//!
//! and differ in the covariance `Sigma` (reference Eq. 3, `Sigma = Sigma_y + Sigma_delta +
//! Sigma_eta`):
//!
//! - **Traditional** ([`KohProblem`]; Kennedy & O'Hagan 2001, J. R. Stat. Soc. B 63(3), in the
//!   joint form of Higdon et al. 2004): the `n` field observations and the `m` simulation outputs
//!   form one Gaussian vector of size `N = n + m`; `Sigma` is the `(m + n) x (m + n)` block
//!   covariance of a squared-exponential GP emulator over the inputs `[x, theta]` (5 weather
//!   features + 38 parameters), plus a GP discrepancy `delta(x)` and the observation error on the
//!   field block. A new `theta` (or new hyperparameters `phi`) changes the field rows, so every
//!   iteration rebuilds `Sigma` and factorises it: `O(N^3)`.
//! - **Lightweight** ([`LightweightProblem`]): the emulator is a linear regression in
//!   `[1, x, theta]` (no simulation rows in `Sigma`); `delta(x)` remains a GP, so every iteration
//!   still builds and factorises an `n x n` covariance: `O(n^3)`.
//! - **bemcal** (reference Eq. 7): `Sigma = sigma^2 I_n` per output, no matrix at all
//!   (`bemcal_stats::likelihood::GaussianLikelihood`); timed by this crate's bench example.
//!
//! The factorisation is a dense Cholesky `Sigma = L L^T` (faer); `ln|Sigma| = 2 sum ln L_ii`
//! and the quadratic form is `|L^-1 (z - mu)|^2`. This crate is pure numerics (no I/O); the
//! timing harness is `examples/bench_baselines.rs`.

use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::prelude::*;
use faer::{Accum, Mat, MatMut, MatRef};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

pub use faer::Par;

/// Number of weather features `x` (dry bulb, relative humidity, wind, global horizontal, day type).
pub const N_WEATHER: usize = 5;
/// Number of calibration parameters `theta` of the reference study.
pub const N_PARAMS: usize = 38;
/// Hours in the field data (`n` for the hourly task).
pub const N_HOURS: usize = 8760;
/// Design points (EnergyPlus simulations) of the reference study; with every hour a
/// simulation row this gives `m = 20 x 8,760 = 175,200`.
pub const N_DESIGN: usize = 20;

/// Errors of the baselines.
#[derive(Debug, Clone, PartialEq)]
pub enum BaselineError {
    /// The covariance matrix is not numerically positive definite (pivot index).
    NotPositiveDefinite(usize),
    /// Inconsistent sizes.
    Shape(String),
}

impl std::fmt::Display for BaselineError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BaselineError::NotPositiveDefinite(i) => {
                write!(f, "covariance is not positive definite (pivot {i})")
            }
            BaselineError::Shape(s) => write!(f, "shape mismatch: {s}"),
        }
    }
}

impl std::error::Error for BaselineError {}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, BaselineError>;

/// Squared-exponential covariance `k(a, b) = variance * exp(-sum_d beta_d (a_d - b_d)^2)`
/// (the product power-exponential kernel of Kennedy & O'Hagan 2001 with exponent 2).
#[derive(Debug, Clone, PartialEq)]
pub struct SeKernel {
    /// Marginal variance (`1 / lambda` in Higdon et al.'s notation).
    pub variance: f64,
    /// Inverse squared length scales, one per input dimension.
    pub beta: Vec<f64>,
}

impl SeKernel {
    /// `k(a, b)` evaluated directly (reference implementation for tests).
    pub fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        let d2: f64 = self
            .beta
            .iter()
            .zip(a.iter().zip(b))
            .map(|(w, (x, y))| w * (x - y) * (x - y))
            .sum();
        self.variance * (-d2).exp()
    }
}

/// Lower triangle (diagonal included) of the Gram matrix `K_ij = k(w_i, w_j)` of the rows `w_i`
/// of `inputs` (`N x D`), written into `out` (`N x N`) or added to it when `add` is true. The
/// strict upper triangle of `out` is left unspecified when `add` is false (only the lower
/// triangle is read by the Cholesky factorisation).
///
/// Squared distances come from one GEMM, `|a - b|_B^2 = |a|_B^2 + |b|_B^2 - 2 a^T B b` with
/// `B = diag(beta)`, then an elementwise exponential in parallel over columns.
pub fn se_gram_lower(
    mut out: MatMut<'_, f64>,
    inputs: MatRef<'_, f64>,
    kernel: &SeKernel,
    add: bool,
    par: Par,
) -> Result<()> {
    let (n, d) = (inputs.nrows(), inputs.ncols());
    if kernel.beta.len() != d || out.nrows() != n || out.ncols() != n {
        return Err(BaselineError::Shape(format!(
            "{n} x {d} inputs, {} betas, {} x {} output",
            kernel.beta.len(),
            out.nrows(),
            out.ncols()
        )));
    }
    let scaled = Mat::from_fn(n, d, |i, j| inputs[(i, j)] * kernel.beta[j].sqrt());
    let sq: Vec<f64> = (0..n)
        .map(|i| (0..d).map(|j| scaled[(i, j)] * scaled[(i, j)]).sum())
        .collect();
    let var = kernel.variance;
    // In place: the column holds the Gram entries `g_ij` (or the kernel is added from `gram`).
    let gram = if add {
        let mut g = Mat::<f64>::zeros(n, n);
        matmul(
            g.as_mut(),
            Accum::Replace,
            scaled.as_ref(),
            scaled.transpose(),
            1.0,
            par,
        );
        Some(g)
    } else {
        matmul(
            out.rb_mut(),
            Accum::Replace,
            scaled.as_ref(),
            scaled.transpose(),
            1.0,
            par,
        );
        None
    };
    out.par_col_iter_mut().enumerate().for_each(|(j, o)| {
        let o = o
            .try_as_col_major_mut()
            .expect("owned matrices are column-major")
            .as_slice_mut();
        match &gram {
            Some(g) => {
                let g = g
                    .col(j)
                    .try_as_col_major()
                    .expect("column-major")
                    .as_slice();
                for i in j..n {
                    let d2 = (sq[i] + sq[j] - 2.0 * g[i]).max(0.0);
                    o[i] += var * (-d2).exp();
                }
            }
            None => {
                for i in j..n {
                    let d2 = (sq[i] + sq[j] - 2.0 * o[i]).max(0.0);
                    o[i] = var * (-d2).exp();
                }
            }
        }
    });
    Ok(())
}

/// The two data-dependent terms of the Gaussian log-likelihood (reference Eq. 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussianTerms {
    /// Size `N` of the Gaussian vector.
    pub n: usize,
    /// `ln |Sigma|`.
    pub log_det: f64,
    /// `(z - mu)^T Sigma^-1 (z - mu)`.
    pub quad: f64,
}

impl GaussianTerms {
    /// `-1/2 [N ln(2 pi) + ln|Sigma| + quad]` (reference Eq. 5, normalised).
    pub fn log_likelihood(&self) -> f64 {
        -0.5 * (self.n as f64 * (2.0 * std::f64::consts::PI).ln() + self.log_det + self.quad)
    }
}

/// Factorises `cov` in place (its lower triangle holds `Sigma`; on return it holds `L`,
/// `Sigma = L L^T`) and returns `ln|Sigma| = 2 sum ln L_ii` and `r^T Sigma^-1 r = |L^-1 r|^2`
/// for the residual `r = z - mu`.
pub fn gaussian_terms_in_place(
    mut cov: MatMut<'_, f64>,
    residual: &[f64],
    par: Par,
) -> Result<GaussianTerms> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::cholesky::llt::factor;
    let n = cov.nrows();
    if cov.ncols() != n || residual.len() != n {
        return Err(BaselineError::Shape(format!(
            "{} x {} covariance, {} residuals",
            n,
            cov.ncols(),
            residual.len()
        )));
    }
    let mut mem = MemBuffer::new(factor::cholesky_in_place_scratch::<f64>(n, par, default()));
    factor::cholesky_in_place(
        cov.rb_mut(),
        default(),
        par,
        MemStack::new(&mut mem),
        default(),
    )
    .map_err(|e| match e {
        faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index } => {
            BaselineError::NotPositiveDefinite(index)
        }
    })?;
    let log_det = 2.0 * (0..n).map(|i| cov[(i, i)].ln()).sum::<f64>();
    let mut v = Mat::from_fn(n, 1, |i, _| residual[i]);
    solve_lower_triangular_in_place(cov.rb(), v.as_mut(), par);
    let quad = (0..n).map(|i| v[(i, 0)] * v[(i, 0)]).sum();
    Ok(GaussianTerms { n, log_det, quad })
}

/// Fills the strict upper triangle from the lower one (for inspection and tests; the
/// likelihood itself reads only the lower triangle).
pub fn symmetrise_from_lower(mut m: MatMut<'_, f64>) {
    let n = m.nrows();
    for j in 0..n {
        for i in 0..j {
            m[(i, j)] = m[(j, i)];
        }
    }
}

/// Hyperparameters `phi` of the full KOH model (Kennedy & O'Hagan 2001, Section 4; Higdon et
/// al. 2004): emulator GP over `[x, theta]`, discrepancy GP over `x`, observation and
/// simulation nuggets. The MCMC samples these together with `theta`.
#[derive(Debug, Clone, PartialEq)]
pub struct KohHyper {
    /// Emulator `eta(x, theta)` kernel over `N_WEATHER + N_PARAMS` inputs.
    pub eta: SeKernel,
    /// Discrepancy `delta(x)` kernel over `N_WEATHER` inputs.
    pub delta: SeKernel,
    /// Observation error variance `sigma_y^2` (field block diagonal).
    pub sigma_y2: f64,
    /// Simulation nugget (numerical jitter / emulator noise on the simulation block diagonal).
    pub sim_nugget: f64,
}

/// Seeded hyperparameters of plausible magnitude (inputs scaled to `[0, 1]`, outputs
/// standardised): the timing does not depend on their values.
pub fn sample_koh_hyper(rng: &mut impl Rng) -> KohHyper {
    let d = N_WEATHER + N_PARAMS;
    KohHyper {
        eta: SeKernel {
            variance: 1.0 + 0.1 * rng.random::<f64>(),
            beta: (0..d).map(|_| 0.05 + 0.5 * rng.random::<f64>()).collect(),
        },
        delta: SeKernel {
            variance: 0.1 + 0.05 * rng.random::<f64>(),
            beta: (0..N_WEATHER)
                .map(|_| 0.5 + 2.0 * rng.random::<f64>())
                .collect(),
        },
        sigma_y2: 0.05 + 0.01 * rng.random::<f64>(),
        sim_nugget: 1e-2,
    }
}

/// Data of the full Kennedy-O'Hagan calibration: `n` field rows (weather `x_i`, observation
/// `y_i`) and `m` simulation rows (weather `x*_j`, design parameters `t_j`, output `eta_j`).
/// Inputs are scaled to `[0, 1]`, outputs standardised (zero-mean GP).
#[derive(Debug, Clone)]
pub struct KohProblem {
    /// Field weather, `n x N_WEATHER`.
    pub x_field: Mat<f64>,
    /// Field observations, length `n`.
    pub y: Vec<f64>,
    /// Simulation inputs `[x*, t]`, `m x (N_WEATHER + N_PARAMS)`.
    pub w_sim: Mat<f64>,
    /// Simulation outputs, length `m`.
    pub eta: Vec<f64>,
}

impl KohProblem {
    /// `n` field rows and `m` simulation rows of seeded synthetic data. `weather`, if given,
    /// supplies the weather rows (`n_w x N_WEATHER`, scaled to `[0, 1]`; cycled as needed).
    pub fn synthetic(n: usize, m: usize, weather: Option<MatRef<'_, f64>>, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let wx = |rng: &mut ChaCha8Rng, i: usize, j: usize| match weather {
            Some(w) if w.nrows() > 0 => w[(i % w.nrows(), j)],
            _ => rng.random::<f64>(),
        };
        let x_field = Mat::from_fn(n, N_WEATHER, |i, j| wx(&mut rng, i, j));
        let mut w_sim = Mat::<f64>::zeros(m, N_WEATHER + N_PARAMS);
        for i in 0..m {
            for j in 0..N_WEATHER + N_PARAMS {
                w_sim[(i, j)] = if j < N_WEATHER {
                    wx(&mut rng, i, j)
                } else {
                    rng.random::<f64>()
                };
            }
        }
        let y = (0..n).map(|_| rng.sample(StandardNormal)).collect();
        let eta = (0..m).map(|_| rng.sample(StandardNormal)).collect();
        KohProblem {
            x_field,
            y,
            w_sim,
            eta,
        }
    }

    /// Field rows `n`.
    pub fn n(&self) -> usize {
        self.y.len()
    }
    /// Simulation rows `m`.
    pub fn m(&self) -> usize {
        self.eta.len()
    }
    /// `N = n + m`.
    pub fn size(&self) -> usize {
        self.n() + self.m()
    }

    /// Lower triangle of the `(n + m) x (n + m)` block covariance of `z = [y; eta]`
    /// (reference Eq. 3 with `Sigma_eta` of size `m + n`; Kennedy & O'Hagan 2001):
    ///
    /// ```text
    /// Sigma = K_eta([x, theta; x*, t]) + [ K_delta(x) + sigma_y^2 I_n      0          ]
    ///                                    [        0                  nugget I_m ]
    /// ```
    ///
    /// The field rows' emulator inputs are `[x_i, theta]`: a new `theta` changes the
    /// field-field and field-simulation blocks, new `phi` changes everything.
    pub fn covariance_lower(
        &self,
        theta: &[f64],
        hyper: &KohHyper,
        mut out: MatMut<'_, f64>,
        par: Par,
    ) -> Result<()> {
        let (n, m) = (self.n(), self.m());
        if theta.len() != N_PARAMS {
            return Err(BaselineError::Shape(format!("{} parameters", theta.len())));
        }
        let d = N_WEATHER + N_PARAMS;
        let w = Mat::from_fn(n + m, d, |i, j| {
            if i < n {
                if j < N_WEATHER {
                    self.x_field[(i, j)]
                } else {
                    theta[j - N_WEATHER]
                }
            } else {
                self.w_sim[(i - n, j)]
            }
        });
        se_gram_lower(out.rb_mut(), w.as_ref(), &hyper.eta, false, par)?;
        se_gram_lower(
            out.rb_mut().submatrix_mut(0, 0, n, n),
            self.x_field.as_ref(),
            &hyper.delta,
            true,
            par,
        )?;
        for i in 0..n + m {
            out[(i, i)] += if i < n {
                hyper.sigma_y2
            } else {
                hyper.sim_nugget
            };
        }
        Ok(())
    }

    /// One MCMC iteration's log-likelihood `ln p(z | theta, phi)` (reference Eq. 5): build the
    /// block covariance in `work` (`N x N`, reused between iterations), factorise, log
    /// determinant and quadratic form. The GP mean is zero (standardised outputs).
    pub fn log_likelihood(
        &self,
        theta: &[f64],
        hyper: &KohHyper,
        work: MatMut<'_, f64>,
        par: Par,
    ) -> Result<GaussianTerms> {
        let mut work = work;
        self.covariance_lower(theta, hyper, work.rb_mut(), par)?;
        let z: Vec<f64> = self.y.iter().chain(&self.eta).copied().collect();
        gaussian_terms_in_place(work, &z, par)
    }
}

/// Hyperparameters of the lightweight approach: discrepancy GP over `x`, observation
/// variance and the linear-regression emulator's residual variance (its `sigma_eta^2`).
#[derive(Debug, Clone, PartialEq)]
pub struct LightweightHyper {
    /// Discrepancy `delta(x)` kernel over `N_WEATHER` inputs.
    pub delta: SeKernel,
    /// `sigma_y^2`.
    pub sigma_y2: f64,
    /// Emulator residual variance `sigma_eta^2`.
    pub sigma_eta2: f64,
}

/// Seeded hyperparameters of the lightweight approach.
pub fn sample_lightweight_hyper(rng: &mut impl Rng) -> LightweightHyper {
    LightweightHyper {
        delta: SeKernel {
            variance: 0.1 + 0.05 * rng.random::<f64>(),
            beta: (0..N_WEATHER)
                .map(|_| 0.5 + 2.0 * rng.random::<f64>())
                .collect(),
        },
        sigma_y2: 0.05 + 0.01 * rng.random::<f64>(),
        sigma_eta2: 0.02,
    }
}

/// Data of the lightweight calibration: `n` field rows and a fitted linear-regression
/// emulator `eta(x, theta) = b_0 + b_x^T x + b_theta^T theta`.
#[derive(Debug, Clone)]
pub struct LightweightProblem {
    /// Field weather, `n x N_WEATHER`, scaled to `[0, 1]`.
    pub x_field: Mat<f64>,
    /// Field observations (standardised), length `n`.
    pub y: Vec<f64>,
    /// Emulator coefficients `[b_0, b_x (N_WEATHER), b_theta (N_PARAMS)]`.
    pub coef: Vec<f64>,
}

impl LightweightProblem {
    /// `n` field rows of seeded synthetic data (`weather` as in [`KohProblem::synthetic`]).
    pub fn synthetic(n: usize, weather: Option<MatRef<'_, f64>>, seed: u64) -> Self {
        let koh = KohProblem::synthetic(n, 0, weather, seed);
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
        let coef = (0..1 + N_WEATHER + N_PARAMS)
            .map(|_| 0.1 * rng.sample::<f64, _>(StandardNormal))
            .collect();
        LightweightProblem {
            x_field: koh.x_field,
            y: koh.y,
            coef,
        }
    }

    /// Field rows `n`.
    pub fn n(&self) -> usize {
        self.y.len()
    }

    /// Emulator mean `mu_i = eta(x_i, theta)` of the field rows.
    pub fn mean(&self, theta: &[f64]) -> Vec<f64> {
        let c = &self.coef;
        let base = c[0]
            + theta
                .iter()
                .zip(&c[1 + N_WEATHER..])
                .map(|(t, b)| t * b)
                .sum::<f64>();
        (0..self.n())
            .map(|i| {
                base + (0..N_WEATHER)
                    .map(|j| c[1 + j] * self.x_field[(i, j)])
                    .sum::<f64>()
            })
            .collect()
    }

    /// Lower triangle of `Sigma = K_delta(x) + (sigma_y^2 + sigma_eta^2) I_n` (reference Eq. 3
    /// with an `n x n` `Sigma_delta`).
    pub fn covariance_lower(
        &self,
        hyper: &LightweightHyper,
        mut out: MatMut<'_, f64>,
        par: Par,
    ) -> Result<()> {
        se_gram_lower(
            out.rb_mut(),
            self.x_field.as_ref(),
            &hyper.delta,
            false,
            par,
        )?;
        for i in 0..self.n() {
            out[(i, i)] += hyper.sigma_y2 + hyper.sigma_eta2;
        }
        Ok(())
    }

    /// One MCMC iteration's log-likelihood (reference Eq. 5): emulator mean, `n x n`
    /// covariance in `work`, Cholesky, log determinant and quadratic form.
    pub fn log_likelihood(
        &self,
        theta: &[f64],
        hyper: &LightweightHyper,
        work: MatMut<'_, f64>,
        par: Par,
    ) -> Result<GaussianTerms> {
        if theta.len() != N_PARAMS {
            return Err(BaselineError::Shape(format!("{} parameters", theta.len())));
        }
        let mut work = work;
        self.covariance_lower(hyper, work.rb_mut(), par)?;
        let r: Vec<f64> = self
            .y
            .iter()
            .zip(self.mean(theta))
            .map(|(y, mu)| y - mu)
            .collect();
        gaussian_terms_in_place(work, &r, par)
    }
}

/// Least-squares fit of `t = c N^p` on the log scale: returns `(p, ln c)`.
pub fn fit_power_law(sizes: &[f64], times: &[f64]) -> (f64, f64) {
    let k = sizes.len() as f64;
    let lx: Vec<f64> = sizes.iter().map(|x| x.ln()).collect();
    let ly: Vec<f64> = times.iter().map(|y| y.ln()).collect();
    let mx = lx.iter().sum::<f64>() / k;
    let my = ly.iter().sum::<f64>() / k;
    let sxy: f64 = lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = lx.iter().map(|x| (x - mx) * (x - mx)).sum();
    let p = sxy / sxx;
    (p, my - p * mx)
}

/// Seeded parameter vector in `[0, 1]^N_PARAMS` (an MCMC proposal).
pub fn random_theta(rng: &mut impl Rng) -> Vec<f64> {
    (0..N_PARAMS).map(|_| rng.random::<f64>()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `ln|A|` and `A^-1` by Gauss-Jordan elimination with partial pivoting (row-major).
    fn direct_inverse_logdet(a: &[f64], n: usize) -> (Vec<f64>, f64) {
        let mut m = a.to_vec();
        let mut inv = vec![0.0; n * n];
        for i in 0..n {
            inv[i * n + i] = 1.0;
        }
        let mut log_det = 0.0;
        for c in 0..n {
            let p = (c..n)
                .max_by(|&i, &j| m[i * n + c].abs().total_cmp(&m[j * n + c].abs()))
                .unwrap();
            if p != c {
                for k in 0..n {
                    m.swap(p * n + k, c * n + k);
                    inv.swap(p * n + k, c * n + k);
                }
            }
            let piv = m[c * n + c];
            assert!(
                piv > 0.0 || p != c,
                "determinant sign tracking not needed for SPD"
            );
            log_det += piv.abs().ln();
            for k in 0..n {
                m[c * n + k] /= piv;
                inv[c * n + k] /= piv;
            }
            for r in 0..n {
                if r != c {
                    let f = m[r * n + c];
                    if f != 0.0 {
                        for k in 0..n {
                            m[r * n + k] -= f * m[c * n + k];
                            inv[r * n + k] -= f * inv[c * n + k];
                        }
                    }
                }
            }
        }
        (inv, log_det)
    }

    fn full(m: MatRef<'_, f64>) -> Vec<f64> {
        let n = m.nrows();
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = m[(i.max(j), i.min(j))];
            }
        }
        a
    }

    #[test]
    fn cholesky_log_likelihood_equals_direct() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (n, m) = (12, 30);
        let koh = KohProblem::synthetic(n, m, None, 9);
        let theta = random_theta(&mut rng);
        let hyper = sample_koh_hyper(&mut rng);
        let mut cov = Mat::<f64>::zeros(n + m, n + m);
        koh.covariance_lower(&theta, &hyper, cov.as_mut(), Par::Seq)
            .unwrap();
        let a = full(cov.as_ref());
        let z: Vec<f64> = koh.y.iter().chain(&koh.eta).copied().collect();
        let (inv, log_det) = direct_inverse_logdet(&a, n + m);
        let quad: f64 = (0..n + m)
            .map(|i| z[i] * (0..n + m).map(|j| inv[i * (n + m) + j] * z[j]).sum::<f64>())
            .sum();
        let direct = GaussianTerms {
            n: n + m,
            log_det,
            quad,
        };
        let mut work = Mat::<f64>::zeros(n + m, n + m);
        let terms = koh
            .log_likelihood(&theta, &hyper, work.as_mut(), Par::Seq)
            .unwrap();
        assert!(
            (terms.log_det - log_det).abs() < 1e-9,
            "{terms:?} vs {direct:?}"
        );
        assert!((terms.quad - quad).abs() < 1e-9, "{terms:?} vs {direct:?}");
        assert!((terms.log_likelihood() - direct.log_likelihood()).abs() < 1e-9);
        // Each entry of the GEMM-built kernel equals the direct kernel formula.
        let w = |i: usize| -> Vec<f64> {
            if i < n {
                (0..N_WEATHER)
                    .map(|j| koh.x_field[(i, j)])
                    .chain(theta.iter().copied())
                    .collect()
            } else {
                (0..N_WEATHER + N_PARAMS)
                    .map(|j| koh.w_sim[(i - n, j)])
                    .collect()
            }
        };
        for i in 0..n + m {
            for j in 0..=i {
                let mut want = hyper.eta.eval(&w(i), &w(j));
                if i < n && j < n {
                    want += hyper.delta.eval(&w(i)[..N_WEATHER], &w(j)[..N_WEATHER]);
                }
                if i == j {
                    want += if i < n {
                        hyper.sigma_y2
                    } else {
                        hyper.sim_nugget
                    };
                }
                assert!((a[i * (n + m) + j] - want).abs() < 1e-12, "({i}, {j})");
            }
        }
    }

    #[test]
    fn lightweight_log_likelihood_equals_direct() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let n = 25;
        let lw = LightweightProblem::synthetic(n, None, 5);
        let theta = random_theta(&mut rng);
        let hyper = sample_lightweight_hyper(&mut rng);
        let mut cov = Mat::<f64>::zeros(n, n);
        lw.covariance_lower(&hyper, cov.as_mut(), Par::Seq).unwrap();
        let a = full(cov.as_ref());
        let r: Vec<f64> =
            lw.y.iter()
                .zip(lw.mean(&theta))
                .map(|(y, m)| y - m)
                .collect();
        let (inv, log_det) = direct_inverse_logdet(&a, n);
        let quad: f64 = (0..n)
            .map(|i| r[i] * (0..n).map(|j| inv[i * n + j] * r[j]).sum::<f64>())
            .sum();
        let want = GaussianTerms { n, log_det, quad }.log_likelihood();
        let got = lw
            .log_likelihood(&theta, &hyper, cov.as_mut(), Par::Seq)
            .unwrap()
            .log_likelihood();
        assert!((got - want).abs() < 1e-9, "{got} vs {want}");
    }

    #[test]
    fn koh_block_covariance_is_symmetric_positive_definite() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let (n, m) = (40, 160);
        let koh = KohProblem::synthetic(n, m, None, 7);
        let theta = random_theta(&mut rng);
        let hyper = sample_koh_hyper(&mut rng);
        let mut cov = Mat::<f64>::zeros(n + m, n + m);
        koh.covariance_lower(&theta, &hyper, cov.as_mut(), Par::rayon(2))
            .unwrap();
        symmetrise_from_lower(cov.as_mut());
        for i in 0..n + m {
            for j in 0..n + m {
                assert_eq!(cov[(i, j)], cov[(j, i)]);
            }
        }
        let eig = cov.self_adjoint_eigenvalues(faer::Side::Lower).unwrap();
        assert!(eig[0] > 0.0, "smallest eigenvalue {}", eig[0]);
        // The Cholesky factorisation succeeds and reproduces Sigma.
        let mut work = cov.clone();
        let r = vec![0.0; n + m];
        gaussian_terms_in_place(work.as_mut(), &r, Par::Seq).unwrap();
        let mut l = work.clone();
        for j in 0..n + m {
            for i in 0..j {
                l[(i, j)] = 0.0;
            }
        }
        let llt = &l * l.transpose();
        for i in 0..n + m {
            for j in 0..n + m {
                assert!((llt[(i, j)] - cov[(i, j)]).abs() < 1e-10);
            }
        }
    }

    #[test]
    fn not_positive_definite_is_an_error() {
        let mut a = Mat::<f64>::zeros(2, 2);
        a[(0, 0)] = 1.0;
        a[(1, 0)] = 2.0;
        a[(1, 1)] = 1.0;
        assert!(matches!(
            gaussian_terms_in_place(a.as_mut(), &[0.0, 0.0], Par::Seq),
            Err(BaselineError::NotPositiveDefinite(_))
        ));
    }

    #[test]
    fn power_law_fit_recovers_exponent() {
        let ns = [1000.0, 2000.0, 4000.0, 8000.0];
        let ts: Vec<f64> = ns.iter().map(|n: &f64| 3e-10 * n.powf(2.9)).collect();
        let (p, c) = fit_power_law(&ns, &ts);
        assert!((p - 2.9).abs() < 1e-12 && (c - 3e-10f64.ln()).abs() < 1e-9);
    }
}
