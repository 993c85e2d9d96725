//! Gaussian likelihood of the reference, Eqs. 5 and 7, with a diagonal covariance per output.
//!
//! For each output `k` (heating, cooling, electricity, ...) the observations are
//! `y_kt ~ N(f_kt(x, theta), sigma_k^2)`, independent over hours, with
//! `sigma_k^2 = sigma_y,k^2 + sigma_delta,k^2 + sigma_eta,k^2` (measurement error, model
//! inadequacy, surrogate error; reference Eq. 7). Hence
//!
//! `ln L = sum_k [ -n_k / 2 ln(2 pi sigma_k^2) - sum_t (y_kt - f_kt)^2 / (2 sigma_k^2) ]`
//!
//! over the `n_k` hours where output `k` was observed (missing hours are masked out).
//!
//! **Units.** Each output's residuals are computed in that output's own units (e.g. kWh of
//! heating, kWh of electricity); no rescaling is applied. Every term is divided by its own
//! `sigma_k^2`, so each output contributes a dimensionless sum of squared standardised
//! residuals: outputs on very different scales are commensurate, and an output's weight is
//! set by its noise level rather than by its magnitude.
//!
//! **Hyperparameter mode.** `sigma_delta,k` may be sampled with the calibration parameters,
//! on the log scale, with a weakly informative prior ([`ln_prior_log_sigma_delta`]: half-normal
//! or half-Cauchy on `sigma_delta,k` with a scale such as the output's measured standard
//! deviation, [`GaussianLikelihood::measured_sd`]). The pipeline decides which mode is used.

use serde::{Deserialize, Serialize};

pub mod cells;
pub mod intervals;

use crate::error::{Result, StatsError};

/// Noise standard deviations of one output, in that output's units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OutputNoise {
    /// Measurement error `sigma_y`.
    pub sigma_y: f64,
    /// Model inadequacy `sigma_delta` (used when it is not sampled).
    pub sigma_delta: f64,
    /// Surrogate error `sigma_eta` (the surrogate's RMSE, reference Eq. 6).
    pub sigma_eta: f64,
}

impl OutputNoise {
    /// `sigma^2 = sigma_y^2 + sigma_delta^2 + sigma_eta^2` (reference Eq. 7).
    pub fn variance(&self) -> f64 {
        self.sigma_y * self.sigma_y
            + self.sigma_delta * self.sigma_delta
            + self.sigma_eta * self.sigma_eta
    }
}

/// Gaussian log likelihood of hourly observations of several outputs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GaussianLikelihood {
    n_hours: usize,
    n_outputs: usize,
    /// Observations, row-major `hours x outputs`.
    observed: Vec<f64>,
    /// Whether each observation is present, row-major `hours x outputs`.
    present: Vec<bool>,
    /// Observed hours per output.
    n_obs: Vec<usize>,
    noise: Vec<OutputNoise>,
}

impl GaussianLikelihood {
    /// Observations row-major `hours x outputs` (`observed.len() = hours * noise.len()`),
    /// NaN marking a missing hour; one [`OutputNoise`] per output.
    pub fn new(observed: &[f64], noise: &[OutputNoise]) -> Result<Self> {
        let mask: Vec<bool> = observed.iter().map(|v| v.is_finite()).collect();
        Self::with_mask(observed, &mask, noise)
    }

    /// As [`GaussianLikelihood::new`] with an explicit mask (`true` = observed); a masked-in
    /// value that is not finite is an error.
    pub fn with_mask(observed: &[f64], mask: &[bool], noise: &[OutputNoise]) -> Result<Self> {
        let k = noise.len();
        if k == 0 {
            return Err(StatsError::Invalid("no outputs".into()));
        }
        if !observed.len().is_multiple_of(k) || mask.len() != observed.len() {
            return Err(StatsError::Shape(format!(
                "{} observations and {} mask entries for {k} outputs",
                observed.len(),
                mask.len()
            )));
        }
        for (i, nz) in noise.iter().enumerate() {
            let ok = [nz.sigma_y, nz.sigma_delta, nz.sigma_eta]
                .iter()
                .all(|s| s.is_finite() && *s >= 0.0);
            if !ok || nz.variance() <= 0.0 {
                return Err(StatsError::Invalid(format!(
                    "output {i}: noise standard deviations must be finite, non-negative and not all zero"
                )));
            }
        }
        let n_hours = observed.len() / k;
        let mut n_obs = vec![0; k];
        for (i, (&v, &m)) in observed.iter().zip(mask).enumerate() {
            if m {
                if !v.is_finite() {
                    return Err(StatsError::Invalid(format!(
                        "hour {}, output {}: observed value {v} is not finite",
                        i / k,
                        i % k
                    )));
                }
                n_obs[i % k] += 1;
            }
        }
        Ok(GaussianLikelihood {
            n_hours,
            n_outputs: k,
            observed: observed.to_vec(),
            present: mask.to_vec(),
            n_obs,
            noise: noise.to_vec(),
        })
    }

    /// The same likelihood (missing hours, noise) for other observations of the same hours,
    /// `hours x outputs`: what the calibration would see if `observed` were the meters (used to
    /// calibrate against EnergyPlus's outputs at known parameters). A value at an observed hour
    /// that is not finite is an error.
    pub fn with_observed(&self, observed: &[f64]) -> Result<Self> {
        if observed.len() != self.observed.len() {
            return Err(StatsError::Shape(format!(
                "{} observations for {} hours x {} outputs",
                observed.len(),
                self.n_hours,
                self.n_outputs
            )));
        }
        Self::with_mask(observed, &self.present, &self.noise)
    }

    /// Number of hours.
    pub fn n_hours(&self) -> usize {
        self.n_hours
    }
    /// Number of outputs.
    pub fn n_outputs(&self) -> usize {
        self.n_outputs
    }
    /// Whether each observation is present, row-major `hours x outputs`.
    pub fn observed_mask(&self) -> &[bool] {
        &self.present
    }

    /// Observed (unmasked) hours per output.
    pub fn n_observed(&self) -> &[usize] {
        &self.n_obs
    }
    /// The noise of each output.
    pub fn noise(&self) -> &[OutputNoise] {
        &self.noise
    }

    /// Sample standard deviation (`ddof = 1`) of each output's observed values: a natural
    /// scale for the prior on `sigma_delta` in hyperparameter mode.
    pub fn measured_sd(&self) -> Vec<f64> {
        let k = self.n_outputs;
        (0..k)
            .map(|j| {
                let vals = self.column(j);
                let n = vals.len() as f64;
                let m = vals.iter().sum::<f64>() / n;
                (vals.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (n - 1.0)).sqrt()
            })
            .collect()
    }

    fn column(&self, j: usize) -> Vec<f64> {
        (0..self.n_hours)
            .filter(|t| self.present[t * self.n_outputs + j])
            .map(|t| self.observed[t * self.n_outputs + j])
            .collect()
    }

    /// Sum of squared residuals `sum_t (y_kt - f_kt)^2` of output `k` over its observed hours.
    #[inline]
    fn ssr(&self, predicted: &[f32], k: usize) -> f64 {
        let stride = self.n_outputs;
        let mut s = 0.0;
        let mut t = k;
        while t < self.observed.len() {
            if self.present[t] {
                let r = self.observed[t] - predicted[t] as f64;
                s += r * r;
            }
            t += stride;
        }
        s
    }

    fn check_len(&self, predicted: &[f32]) {
        assert_eq!(
            predicted.len(),
            self.observed.len(),
            "predictions must be hours x outputs = {} x {}",
            self.n_hours,
            self.n_outputs
        );
    }

    /// `ln L` with each output's fixed `sigma_delta` (reference Eqs. 5 and 7). `predicted` is
    /// row-major `hours x outputs`, as the surrogate returns it. No allocation.
    ///
    /// # Panics
    /// If `predicted` does not have `hours x outputs` values.
    pub fn log_likelihood(&self, predicted: &[f32]) -> f64 {
        self.check_len(predicted);
        (0..self.n_outputs)
            .map(|k| self.term(predicted, k, self.noise[k].variance()))
            .sum()
    }

    /// `ln L` with `sigma_delta,k` given per output (hyperparameter mode). No allocation.
    ///
    /// # Panics
    /// If the lengths do not match.
    pub fn log_likelihood_with_delta(&self, predicted: &[f32], sigma_delta: &[f64]) -> f64 {
        self.check_len(predicted);
        assert_eq!(
            sigma_delta.len(),
            self.n_outputs,
            "one sigma_delta per output"
        );
        (0..self.n_outputs)
            .map(|k| {
                let nz = &self.noise[k];
                let var = nz.sigma_y * nz.sigma_y
                    + sigma_delta[k] * sigma_delta[k]
                    + nz.sigma_eta * nz.sigma_eta;
                self.term(predicted, k, var)
            })
            .sum()
    }

    /// `ln p(y | f)` with each output's total variance `sigma_k^2` integrated out under the
    /// Jeffreys prior `p(sigma_k^2) ∝ 1 / sigma_k^2` (conjugate; Gelman et al., Bayesian Data
    /// Analysis, 3rd ed., sec. 3.2):
    /// `∫ N(y | f, sigma^2 I) sigma^-2 dsigma^2 = Γ(n/2) (π SSR)^(-n/2)`, so
    /// `ln p = sum_k [ ln Γ(n_k/2) - n_k/2 ln(π SSR_k) ]`.
    /// Exact Bayesian treatment of an unknown noise level with no extra sampled dimension. An
    /// output with no observed hour contributes nothing (`p(∅) = 1`). No allocation.
    ///
    /// # Panics
    /// If `predicted` does not have `hours x outputs` values.
    pub fn log_marginal_sigma(&self, predicted: &[f32]) -> f64 {
        self.check_len(predicted);
        (0..self.n_outputs)
            .filter(|&k| self.n_obs[k] > 0)
            .map(|k| {
                let n = self.n_obs[k] as f64;
                let ssr = self.ssr(predicted, k).max(f64::MIN_POSITIVE);
                ln_gamma(0.5 * n) - 0.5 * n * (std::f64::consts::PI * ssr).ln()
            })
            .sum()
    }

    /// As [`GaussianLikelihood::log_marginal_sigma`], with AR(1) residuals per output:
    /// `r_t = phi r_(t-1) + e_t`, `e_t ~ N(0, sigma^2)`, each run of consecutive observed hours
    /// starting from the stationary distribution `N(0, sigma^2 / (1 - phi^2))`. Then
    /// `p(r | sigma, phi) = (2 pi sigma^2)^(-n/2) (1 - phi^2)^(R/2) exp(-S(phi) / (2 sigma^2))`
    /// (R runs, `S = sum (r_t - phi r_(t-1))^2 + (1 - phi^2) sum r_first^2`); sigma^2 is
    /// integrated out under the Jeffreys prior as before, and `phi` is set to its profile value
    /// `argmin S = B / (C - F)` (clamped to |phi| <= 0.999): its posterior has sd O(n^-1/2), so
    /// this is the Laplace approximation of integrating it out, less a slowly varying curvature
    /// term. Hourly residuals of building models are strongly autocorrelated; an iid likelihood
    /// overstates their information by about (1 + phi) / (1 - phi). O(n), no allocation.
    ///
    /// # Panics
    /// If `predicted` does not have `hours x outputs` values.
    pub fn log_marginal_sigma_ar1(&self, predicted: &[f32]) -> f64 {
        self.check_len(predicted);
        (0..self.n_outputs)
            .filter(|&k| self.n_obs[k] > 0)
            .map(|k| {
                let a = self.ar1_sums(predicted, k);
                let phi = a.profile_phi();
                let n = self.n_obs[k] as f64;
                let ss = a.s(phi).max(f64::MIN_POSITIVE);
                ln_gamma(0.5 * n) - 0.5 * n * (std::f64::consts::PI * ss).ln()
                    + 0.5 * a.runs * (1.0 - phi * phi).ln()
            })
            .sum()
    }

    /// The profile AR(1) coefficient of each output's residuals (see
    /// [`GaussianLikelihood::log_marginal_sigma_ar1`]).
    pub fn ar1_coefficients(&self, predicted: &[f32]) -> Vec<f64> {
        self.check_len(predicted);
        (0..self.n_outputs)
            .map(|k| self.ar1_sums(predicted, k).profile_phi())
            .collect()
    }

    fn ar1_sums(&self, predicted: &[f32], k: usize) -> Ar1Sums {
        let stride = self.n_outputs;
        let mut a = Ar1Sums::default();
        let mut prev: Option<f64> = None;
        let mut t = k;
        while t < self.observed.len() {
            if self.present[t] {
                let r = self.observed[t] - predicted[t] as f64;
                match prev {
                    Some(p) => {
                        a.rr += r * r;
                        a.rp += r * p;
                        a.pp += p * p;
                    }
                    None => {
                        a.first += r * r;
                        a.runs += 1.0;
                    }
                }
                prev = Some(r);
            } else {
                prev = None;
            }
            t += stride;
        }
        a
    }

    /// [`GaussianLikelihood::log_likelihood`] and its gradient with respect to the predictions,
    /// written into `grad` (`hours x outputs`, 0 at missing hours): `d ln L / d f_kt = r_kt /
    /// sigma_k^2`.
    ///
    /// # Panics
    /// If `predicted` or `grad` does not have `hours x outputs` values.
    pub fn log_likelihood_gradient(&self, predicted: &[f32], grad: &mut [f32]) -> f64 {
        self.check_len(predicted);
        self.check_len(grad);
        let var: Vec<f64> = self.noise.iter().map(OutputNoise::variance).collect();
        self.residual_gradient(predicted, grad, |k, r| r / var[k]);
        self.log_likelihood(predicted)
    }

    /// [`GaussianLikelihood::log_marginal_sigma`] and its gradient with respect to the
    /// predictions: `d ln p / d f_kt = n_k r_kt / SSR_k`.
    ///
    /// # Panics
    /// As [`GaussianLikelihood::log_likelihood_gradient`].
    pub fn log_marginal_sigma_gradient(&self, predicted: &[f32], grad: &mut [f32]) -> f64 {
        self.check_len(predicted);
        self.check_len(grad);
        let w: Vec<f64> = (0..self.n_outputs)
            .map(|k| self.n_obs[k] as f64 / self.ssr(predicted, k).max(f64::MIN_POSITIVE))
            .collect();
        self.residual_gradient(predicted, grad, |k, r| w[k] * r);
        self.log_marginal_sigma(predicted)
    }

    /// `grad[t] = g(k, r_t)` at observed hours (r = y - f), 0 elsewhere.
    fn residual_gradient(
        &self,
        predicted: &[f32],
        grad: &mut [f32],
        g: impl Fn(usize, f64) -> f64,
    ) {
        for (t, o) in grad.iter_mut().enumerate() {
            *o = if self.present[t] {
                g(
                    t % self.n_outputs,
                    self.observed[t] - f64::from(predicted[t]),
                ) as f32
            } else {
                0.0
            };
        }
    }

    /// [`GaussianLikelihood::log_marginal_sigma_ar1`] and its gradient with respect to the
    /// predictions, phi's dependence on them included. With `r = y - f`, `e_t = r_t - phi
    /// r_(t-1)` and `D = pp - first` (so `phi = rp / D`, where `dS / dphi = 0`):
    /// `d ln p / d r_t = -n / (2 S) dS/dr_t - R phi / (1 - phi^2) dphi/dr_t`, `dS/dr_t = 2 e_t`
    /// (within a run) `- 2 phi e_(t+1)` (when `t + 1` continues the run) `+ 2 (1 - phi^2) r_t`
    /// (first of a run), `dphi/dr_t = (d rp/dr_t - phi dD/dr_t) / D`; a clamped or zero phi is
    /// constant. O(n).
    ///
    /// # Panics
    /// As [`GaussianLikelihood::log_likelihood_gradient`].
    pub fn log_marginal_sigma_ar1_gradient(&self, predicted: &[f32], grad: &mut [f32]) -> f64 {
        self.check_len(predicted);
        self.check_len(grad);
        let stride = self.n_outputs;
        let mut r = vec![None::<f64>; self.n_hours];
        for k in 0..self.n_outputs {
            let a = self.ar1_sums(predicted, k);
            let den = a.pp - a.first;
            let phi = a.profile_phi();
            let free = den > 0.0 && phi.abs() < 0.999;
            let n = self.n_obs[k] as f64;
            let ss = a.s(phi).max(f64::MIN_POSITIVE);
            for (t, v) in r.iter_mut().enumerate() {
                let i = t * stride + k;
                *v = self.present[i].then(|| self.observed[i] - f64::from(predicted[i]));
            }
            for t in 0..self.n_hours {
                let Some(rt) = r[t] else {
                    grad[t * stride + k] = 0.0;
                    continue;
                };
                let (ds, drp, dd) = ar1_partials(&r, t, rt, phi);
                let mut dl = -0.5 * n / ss * ds;
                if free {
                    let dphi = (drp - phi * dd) / den;
                    dl -= a.runs * phi / (1.0 - phi * phi) * dphi;
                }
                // d / d f = -d / d r
                grad[t * stride + k] = (-dl) as f32;
            }
        }
        self.log_marginal_sigma_ar1(predicted)
    }

    /// Sum of squared residuals per output over the observed hours.
    pub fn residual_sum_of_squares(&self, predicted: &[f32]) -> Vec<f64> {
        self.check_len(predicted);
        (0..self.n_outputs)
            .map(|k| self.ssr(predicted, k))
            .collect()
    }

    #[inline]
    fn term(&self, predicted: &[f32], k: usize, var: f64) -> f64 {
        let n = self.n_obs[k] as f64;
        -0.5 * n * (2.0 * std::f64::consts::PI * var).ln() - self.ssr(predicted, k) / (2.0 * var)
    }
}

/// Sufficient sums of AR(1) residuals: pairs (r_t, r_(t-1)) within runs and the runs' first
/// values.
#[derive(Debug, Default, Clone, Copy)]
struct Ar1Sums {
    /// sum r_t^2 over pairs
    rr: f64,
    /// sum r_t r_(t-1)
    rp: f64,
    /// sum r_(t-1)^2
    pp: f64,
    /// sum of squared first residuals of runs
    first: f64,
    runs: f64,
}

impl Ar1Sums {
    /// The sums of a residual series, `None` at unobserved hours (which end a run).
    fn of(r: &[Option<f64>]) -> Ar1Sums {
        let mut a = Ar1Sums::default();
        let mut prev: Option<f64> = None;
        for v in r {
            match (v, prev) {
                (Some(v), Some(p)) => {
                    a.rr += v * v;
                    a.rp += v * p;
                    a.pp += p * p;
                }
                (Some(v), None) => {
                    a.first += v * v;
                    a.runs += 1.0;
                }
                (None, _) => {}
            }
            prev = *v;
        }
        a
    }

    /// `S(phi) = rr - 2 phi rp + phi^2 pp + (1 - phi^2) first`.
    fn s(&self, phi: f64) -> f64 {
        self.rr - 2.0 * phi * self.rp + phi * phi * self.pp + (1.0 - phi * phi) * self.first
    }

    /// `argmin S = rp / (pp - first)`, clamped to [-0.999, 0.999].
    fn profile_phi(&self) -> f64 {
        let den = self.pp - self.first;
        if den <= 0.0 {
            return 0.0;
        }
        (self.rp / den).clamp(-0.999, 0.999)
    }
}

/// `ln Γ(x)` for `x > 0` (Lanczos approximation, g = 7, n = 9; relative error < 1e-13).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x) Γ(1 - x) = π / sin(π x).
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Weakly informative prior families for `sigma_delta` in hyperparameter mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SigmaPrior {
    /// Half-normal: `p(s) = 2 / (scale sqrt(2 pi)) exp(-s^2 / (2 scale^2))`, `s >= 0`.
    HalfNormal,
    /// Half-Cauchy: `p(s) = 2 / (pi scale (1 + (s / scale)^2))`, `s >= 0` (Gelman 2006).
    HalfCauchy,
}

/// Log prior density of `eta = ln sigma_delta` when `sigma_delta` has a half-normal or
/// half-Cauchy prior of the given `scale`: `ln p(sigma) + eta` (the Jacobian of
/// `sigma = exp(eta)`). Normalised.
pub fn ln_prior_log_sigma_delta(log_sigma: f64, scale: f64, family: SigmaPrior) -> f64 {
    let s = log_sigma.exp();
    let z = s / scale;
    let ln_p_sigma = match family {
        SigmaPrior::HalfNormal => {
            (2.0f64).ln() - scale.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln() - 0.5 * z * z
        }
        SigmaPrior::HalfCauchy => (2.0 / std::f64::consts::PI).ln() - scale.ln() - (z * z).ln_1p(),
    };
    ln_p_sigma + log_sigma
}

/// The partial derivatives, in the hour `t` whose residual is `rt`, of the AR(1) innovation sum
/// of squares at a fixed phi, of the lag-1 cross product and of the end-point correction of
/// phi's profile estimate (the sums behind [`Ar1Sums`]); gaps end a run.
pub(crate) fn ar1_partials(r: &[Option<f64>], t: usize, rt: f64, phi: f64) -> (f64, f64, f64) {
    let prev = if t > 0 { r[t - 1] } else { None };
    let next = r.get(t + 1).copied().flatten();
    let (mut ds, mut drp, mut dd) = (0.0, 0.0, 0.0);
    match prev {
        Some(p) => {
            ds += 2.0 * (rt - phi * p);
            drp += p;
        }
        None => {
            ds += 2.0 * (1.0 - phi * phi) * rt;
            dd -= 2.0 * rt;
        }
    }
    if let Some(q) = next {
        ds -= 2.0 * phi * (q - phi * rt);
        drp += q;
        dd += 2.0 * rt;
    }
    (ds, drp, dd)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn other_observations_keep_the_missing_hours_and_the_noise() {
        let noise = [OutputNoise {
            sigma_y: 0.1,
            sigma_delta: 0.2,
            sigma_eta: 0.3,
        }];
        let lik = GaussianLikelihood::new(&[1.0, f64::NAN, 3.0, 4.0], &noise).unwrap();
        // The second hour stays missing, whatever the new value there.
        let other = lik.with_observed(&[2.0, 99.0, 3.0, 5.0]).unwrap();
        assert_eq!(other.n_observed(), &[3]);
        assert_eq!(other.noise(), lik.noise());
        let pred = [2.0f32, 0.0, 3.0, 5.0];
        let perfect = other.log_likelihood(&pred);
        let moved = GaussianLikelihood::new(&[2.0, f64::NAN, 3.0, 5.0], &noise).unwrap();
        assert_eq!(perfect, moved.log_likelihood(&pred));
        assert!(lik.with_observed(&[1.0; 3]).is_err());
        assert!(lik.with_observed(&[f64::NAN, 0.0, 0.0, 0.0]).is_err());
    }

    #[test]
    fn gradients_match_central_differences() {
        // Two outputs, 60 hours, gaps (a run boundary and a lone hour), AR(1)-like residuals so
        // phi is free; central differences at f32-exact steps of 1/64.
        let (n_h, n_out) = (60, 2);
        let mut obs = vec![0.0; n_h * n_out];
        let mut pred = vec![0f32; n_h * n_out];
        let mut mask = vec![true; n_h * n_out];
        let mut e = 0.0f64;
        for t in 0..n_h {
            e = 0.6 * e + ((t * 7919 % 23) as f64 / 23.0 - 0.5);
            for k in 0..n_out {
                pred[t * n_out + k] = 5.0 + (t as f32 * 0.3 + k as f32).sin();
                obs[t * n_out + k] = f64::from(pred[t * n_out + k]) + e * (1.0 + k as f64);
            }
        }
        for t in [10, 11, 12, 30, 59] {
            mask[t * n_out] = false;
        }
        mask[41 * n_out + 1] = false;
        let noise = vec![
            OutputNoise {
                sigma_y: 0.1,
                sigma_delta: 0.3,
                sigma_eta: 0.2
            };
            n_out
        ];
        let lik = GaussianLikelihood::with_mask(&obs, &mask, &noise).unwrap();
        type Grad = fn(&GaussianLikelihood, &[f32], &mut [f32]) -> f64;
        type Value = fn(&GaussianLikelihood, &[f32]) -> f64;
        let cases: [(&str, Grad, Value); 3] = [
            (
                "fixed",
                GaussianLikelihood::log_likelihood_gradient,
                GaussianLikelihood::log_likelihood,
            ),
            (
                "marginal",
                GaussianLikelihood::log_marginal_sigma_gradient,
                GaussianLikelihood::log_marginal_sigma,
            ),
            (
                "ar1",
                GaussianLikelihood::log_marginal_sigma_ar1_gradient,
                GaussianLikelihood::log_marginal_sigma_ar1,
            ),
        ];
        let phi = lik.ar1_coefficients(&pred);
        assert!(
            phi.iter().all(|p| p.abs() > 0.1 && p.abs() < 0.99),
            "{phi:?}"
        );
        for (name, grad_fn, value_fn) in cases {
            let mut g = vec![0f32; pred.len()];
            let v = grad_fn(&lik, &pred, &mut g);
            assert_eq!(v, value_fn(&lik, &pred), "{name}: value");
            let h = 1.0 / 64.0;
            let scale = g.iter().fold(0f32, |m, x| m.max(x.abs())) as f64;
            for i in 0..pred.len() {
                let (mut up, mut dn) = (pred.clone(), pred.clone());
                up[i] += h;
                dn[i] -= h;
                let fd = (value_fn(&lik, &up) - value_fn(&lik, &dn)) / (2.0 * h as f64);
                assert!(
                    (f64::from(g[i]) - fd).abs() < 2e-3 * scale,
                    "{name} at {i}: gradient {} vs central difference {fd}",
                    g[i]
                );
                if !mask[i] {
                    assert_eq!(g[i], 0.0);
                }
            }
        }
    }

    #[test]
    fn ln_gamma_matches_known_values() {
        // Γ(n) = (n-1)!, Γ(1/2) = sqrt(π); other values from Python's math.lgamma.
        assert!((ln_gamma(1.0)).abs() < 1e-13);
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-12);
        assert!((ln_gamma(0.5) - 0.5 * std::f64::consts::PI.ln()).abs() < 1e-12);
        for (x, want) in [
            (4380.0, 32342.16809032015),
            (0.1, 2.2527126517342055),
            (123.456, 469.60554712992956),
        ] {
            assert!(
                (ln_gamma(x) - want).abs() < 1e-12 * want.abs().max(1.0),
                "ln_gamma({x})"
            );
        }
    }

    #[test]
    fn ar1_profile_recovers_phi_and_matches_direct_formula() {
        // Residuals from a known AR(1) (phi 0.8) with a gap; the profile phi recovers it and the
        // log marginal equals the formula evaluated directly.
        let n = 4000;
        let mut r = vec![0.0f64; n];
        let mut state = 12345u64;
        let mut normal = || {
            // Box-Muller from a 64-bit LCG (deterministic test noise).
            let mut u = || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (u(), u());
            (-2.0 * a.ln()).sqrt() * (2.0 * PI * b).cos()
        };
        for t in 1..n {
            r[t] = 0.8 * r[t - 1] + normal();
        }
        let mut observed: Vec<f64> = r.iter().map(|x| 10.0 + x).collect();
        for v in &mut observed[1000..1100] {
            *v = f64::NAN;
        }
        let predicted = vec![10.0f32; n];
        let noise = [OutputNoise {
            sigma_y: 0.0,
            sigma_delta: 1.0,
            sigma_eta: 0.0,
        }];
        let lik = GaussianLikelihood::new(&observed, &noise).unwrap();
        let phi = lik.ar1_coefficients(&predicted)[0];
        assert!((phi - 0.8).abs() < 0.03, "phi {phi}");
        // Direct: two runs, S(phi) summed explicitly.
        let res: Vec<Option<f64>> = observed
            .iter()
            .map(|y| y.is_finite().then(|| y - 10.0))
            .collect();
        let (mut s, mut runs, mut m) = (0.0, 0.0, 0.0);
        for t in 0..n {
            let Some(x) = res[t] else { continue };
            m += 1.0;
            match if t > 0 { res[t - 1] } else { None } {
                Some(p) => s += (x - phi * p).powi(2),
                None => {
                    s += (1.0 - phi * phi) * x * x;
                    runs += 1.0;
                }
            }
        }
        let want =
            ln_gamma(m / 2.0) - m / 2.0 * (PI * s).ln() + runs / 2.0 * (1.0 - phi * phi).ln();
        let got = lik.log_marginal_sigma_ar1(&predicted);
        assert!((got - want).abs() < 1e-6 * want.abs(), "{got} vs {want}");
        // The iid marginal treats the same residuals as far more informative about a shift.
        let shifted = vec![10.3f32; n];
        let d_iid = lik.log_marginal_sigma(&predicted) - lik.log_marginal_sigma(&shifted);
        let d_ar1 = lik.log_marginal_sigma_ar1(&predicted) - lik.log_marginal_sigma_ar1(&shifted);
        assert!(d_iid > 3.0 * d_ar1.abs(), "iid {d_iid} vs ar1 {d_ar1}");
    }

    #[test]
    fn marginal_sigma_equals_numerical_integral() {
        // y = f + residuals; integrate N(y | f, s2) / s2 over s2 numerically (log grid).
        let observed = [1.0, 2.5, f64::NAN, 4.0, 3.0];
        let predicted = [1.2f32, 2.0, 0.0, 4.5, 2.6];
        let noise = [OutputNoise {
            sigma_y: 0.0,
            sigma_delta: 1.0,
            sigma_eta: 0.0,
        }];
        let lik = GaussianLikelihood::new(&observed, &noise).unwrap();
        let ssr: f64 = [0.2f64, 0.5, 0.5, 0.4].iter().map(|r| r * r).sum();
        // Predictions are f32: residuals agree to f32 precision.
        assert!((lik.residual_sum_of_squares(&predicted)[0] - ssr).abs() < 1e-6);
        let n = 4.0;
        let mut integral = 0.0;
        let (lo, hi, steps) = (-12.0f64, 8.0f64, 200_000);
        let h = (hi - lo) / steps as f64;
        for i in 0..steps {
            let ln_s2 = lo + (i as f64 + 0.5) * h;
            let s2 = ln_s2.exp();
            // d s2 / s2 = d ln s2
            integral += (-(n / 2.0) * (2.0 * PI * s2).ln() - ssr / (2.0 * s2)).exp() * h;
        }
        let got = lik.log_marginal_sigma(&predicted);
        assert!(
            (got - integral.ln()).abs() < 1e-6,
            "{got} vs {}",
            integral.ln()
        );
    }
    use std::f64::consts::PI;

    fn noise(sy: f64, sd: f64, se: f64) -> OutputNoise {
        OutputNoise {
            sigma_y: sy,
            sigma_delta: sd,
            sigma_eta: se,
        }
    }

    #[test]
    fn hand_computed_with_missing_hours() {
        // Two outputs, three hours; output 1 misses hour 1.
        let obs = [1.0, 10.0, 2.0, f64::NAN, 3.0, 30.0];
        let pred = [1.5f32, 12.0, 2.0, 999.0, 2.0, 27.0];
        // Output 0: sigma^2 = 0.3^2 + 0.4^2 + 0 = 0.25, residuals -0.5, 0, 1 -> SSR 1.25, n 3.
        // Output 1: sigma^2 = 1 + 4 + 4 = 9, residuals -2, 3 -> SSR 13, n 2.
        let lik =
            GaussianLikelihood::new(&obs, &[noise(0.3, 0.4, 0.0), noise(1.0, 2.0, 2.0)]).unwrap();
        assert_eq!(lik.n_observed(), &[3, 2]);
        let want = -1.5 * (2.0 * PI * 0.25).ln() - 1.25 / 0.5 - (2.0 * PI * 9.0).ln() - 13.0 / 18.0;
        assert!((lik.log_likelihood(&pred) - want).abs() < 1e-12);
        // Hyperparameter mode with the same sigma_delta gives the same value.
        assert!((lik.log_likelihood_with_delta(&pred, &[0.4, 2.0]) - want).abs() < 1e-12);
        // An explicit mask equals NaN marking.
        let obs2 = [1.0, 10.0, 2.0, 0.0, 3.0, 30.0];
        let mask = [true, true, true, false, true, true];
        let lik2 = GaussianLikelihood::with_mask(
            &obs2,
            &mask,
            &[noise(0.3, 0.4, 0.0), noise(1.0, 2.0, 2.0)],
        )
        .unwrap();
        assert_eq!(lik2.log_likelihood(&pred), lik.log_likelihood(&pred));
    }

    #[test]
    fn an_output_with_no_observed_hour_contributes_nothing() {
        // A meter the calibration does not fit (`fit = false`): output 1 missing at every hour.
        let one = [1.0, 2.0, 4.0, 3.0];
        let both = [1.0, f64::NAN, 2.0, f64::NAN, 4.0, f64::NAN, 3.0, f64::NAN];
        let pred1 = [1.5f32, 2.0, 3.0, 3.5];
        let pred2 = [1.5f32, 7.0, 2.0, 7.0, 3.0, 7.0, 3.5, 7.0];
        let nz = noise(0.5, 0.0, 0.0);
        let l1 = GaussianLikelihood::new(&one, &[nz]).unwrap();
        let l2 = GaussianLikelihood::new(&both, &[nz, nz]).unwrap();
        assert_eq!(l2.n_observed(), &[4, 0]);
        type Value = fn(&GaussianLikelihood, &[f32]) -> f64;
        let values: [Value; 3] = [
            GaussianLikelihood::log_likelihood,
            GaussianLikelihood::log_marginal_sigma,
            GaussianLikelihood::log_marginal_sigma_ar1,
        ];
        for f in values {
            let (a, b) = (f(&l1, &pred1), f(&l2, &pred2));
            assert!(b.is_finite() && (a - b).abs() < 1e-12, "{a} vs {b}");
        }
        type Gradient = fn(&GaussianLikelihood, &[f32], &mut [f32]) -> f64;
        let gradients: [Gradient; 3] = [
            GaussianLikelihood::log_likelihood_gradient,
            GaussianLikelihood::log_marginal_sigma_gradient,
            GaussianLikelihood::log_marginal_sigma_ar1_gradient,
        ];
        for g in gradients {
            let (mut g1, mut g2) = ([0f32; 4], [1f32; 8]);
            let (a, b) = (g(&l1, &pred1, &mut g1), g(&l2, &pred2, &mut g2));
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
            for t in 0..4 {
                assert_eq!((g2[2 * t], g2[2 * t + 1]), (g1[t], 0.0));
            }
        }
    }

    #[test]
    fn rejects_bad_shapes_and_noise() {
        assert!(GaussianLikelihood::new(&[1.0, 2.0, 3.0], &[noise(1.0, 0.0, 0.0); 2]).is_err());
        assert!(GaussianLikelihood::new(&[1.0, 2.0], &[noise(0.0, 0.0, 0.0); 2]).is_err());
        assert!(GaussianLikelihood::new(&[1.0, 2.0], &[noise(-1.0, 0.0, 0.0); 2]).is_err());
    }

    #[test]
    fn sigma_priors_normalise_on_log_scale() {
        for family in [SigmaPrior::HalfNormal, SigmaPrior::HalfCauchy] {
            // Integrate exp(ln p(eta)) over eta in [-30, 30] (half-Cauchy tail beyond is ~1e-13).
            let (lo, hi, n) = (-30.0, 30.0, 600_000);
            let h = (hi - lo) / n as f64;
            let total: f64 = (0..n)
                .map(|i| ln_prior_log_sigma_delta(lo + (i as f64 + 0.5) * h, 2.5, family).exp() * h)
                .sum();
            assert!((total - 1.0).abs() < 1e-6, "{family:?}: {total}");
        }
        // Hand value: half-normal, scale 1, sigma = 1: ln(2 / sqrt(2 pi)) - 1/2 + ln 1.
        let v = ln_prior_log_sigma_delta(0.0, 1.0, SigmaPrior::HalfNormal);
        assert!((v - ((2.0 / (2.0 * PI).sqrt()).ln() - 0.5)).abs() < 1e-14);
    }

    #[test]
    fn measured_sd_skips_missing() {
        let obs = [1.0, f64::NAN, 3.0, 5.0];
        let lik = GaussianLikelihood::new(&obs, &[noise(1.0, 0.0, 0.0)]).unwrap();
        // sd of [1, 3, 5] = 2.
        assert!((lik.measured_sd()[0] - 2.0).abs() < 1e-15);
    }
}
