//! Readings over intervals of hours: utility bills, daily reads (issue 69). A reading is the
//! total of one output over its hours, so the model's value is the sum of its hourly
//! predictions there, and the error of that sum is the sum of the hourly errors.
//!
//! **Model.** For the readings `b = 1..B` of one output, `y_b = sum_(t in b) f_t + e_b`, where
//! the hourly errors follow the AR(1) process of the hourly likelihood
//! ([`super::GaussianLikelihood::log_marginal_sigma_ar1`]) with coefficient `phi` and innovation
//! scale `sigma`: `e_b ~ N(0, sigma^2 w_b)` with `w_b = sum_(i,j in b) phi^|i-j|`
//! ([`crate::predictive::ar1_sum_variance`]; `n_b (1 + phi) / (1 - phi)` for long intervals,
//! against `n_b` for independent hours: a sum of autocorrelated errors is wider than sqrt(n)
//! says). Readings are independent of each other (a month apart, hourly correlations of 0.9
//! leave nothing).
//!
//! **sigma integrated out** under the Jeffreys prior `p(sigma^2) ∝ sigma^-2`, as the hourly
//! likelihood does (Gelman et al., Bayesian Data Analysis, 3rd ed., sec. 3.2):
//!
//! `ln p = ln Γ(B/2) - B/2 ln(π Q) - 1/2 sum_b ln w_b`, `Q = sum_b r_b^2 / w_b`,
//! `r_b = y_b - sum_(t in b) f_t`.
//!
//! The scale of the bills' error is then learned from the bills themselves (their residuals'
//! spread), not carried from the hours: `phi` sets only the bills' relative weights, which for
//! bills of 28 to 34 days hardly differ. A fixed error model for bills is no better founded:
//! the hourly noise scale does not say how a model's monthly totals miss.

use super::ln_gamma;
use crate::error::{Result, StatsError};
use crate::predictive::ar1_sum_variance;

/// One reading over an interval: the hours it totals (indices into the likelihood's hours) and
/// the measured total, in the output's units.
#[derive(Debug, Clone, PartialEq)]
pub struct IntervalReading {
    /// The hours the reading totals.
    pub hours: Vec<usize>,
    /// The measured total over those hours.
    pub total: f64,
}

/// `w_b`: the variance of the sum of `hours` consecutive errors of an AR(1) process with
/// coefficient `phi` and unit innovation scale, in units of `sigma^2` (module docs).
pub fn sum_weight(hours: usize, phi: f64) -> f64 {
    ar1_sum_variance(&vec![1.0; hours], phi)
}

/// The likelihood of one output's interval readings given hourly predictions laid out as the
/// hourly likelihood's (`hours x outputs`, row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct IntervalLikelihood {
    output: usize,
    n_outputs: usize,
    n_hours: usize,
    readings: Vec<IntervalReading>,
    /// `w_b`: the variance of reading b's summed error in units of `sigma^2`.
    weights: Vec<f64>,
}

impl IntervalLikelihood {
    /// Readings of output `output` of `n_outputs`, over `n_hours` hours, with hourly errors of
    /// AR(1) coefficient `phi` (0: independent hours). Refuses a reading with no hour, an hour
    /// out of range or counted twice (within or across readings: intervals do not overlap), a
    /// total that is not finite, and `phi` outside `(-1, 1)`.
    pub fn new(
        output: usize,
        n_outputs: usize,
        n_hours: usize,
        readings: Vec<IntervalReading>,
        phi: f64,
    ) -> Result<IntervalLikelihood> {
        if output >= n_outputs {
            return Err(StatsError::Shape(format!(
                "output {output} of {n_outputs} outputs"
            )));
        }
        if phi.is_nan() || phi.abs() >= 1.0 {
            return Err(StatsError::Invalid(format!(
                "AR(1) coefficient {phi} outside (-1, 1)"
            )));
        }
        let mut seen = vec![false; n_hours];
        for (b, r) in readings.iter().enumerate() {
            if r.hours.is_empty() || !r.total.is_finite() {
                return Err(StatsError::Invalid(format!(
                    "reading {b}: {} hours, total {}",
                    r.hours.len(),
                    r.total
                )));
            }
            for &t in &r.hours {
                match seen.get_mut(t) {
                    None => {
                        return Err(StatsError::Shape(format!(
                            "reading {b}: hour {t} of {n_hours}"
                        )))
                    }
                    Some(true) => {
                        return Err(StatsError::Invalid(format!(
                            "reading {b}: hour {t} is in an earlier interval"
                        )))
                    }
                    Some(s) => *s = true,
                }
            }
        }
        let weights = readings
            .iter()
            .map(|r| sum_weight(r.hours.len(), phi))
            .collect();
        Ok(IntervalLikelihood {
            output,
            n_outputs,
            n_hours,
            readings,
            weights,
        })
    }

    /// The readings.
    pub fn readings(&self) -> &[IntervalReading] {
        &self.readings
    }

    /// Each reading's modelled total: the sum of the output's predictions over its hours.
    ///
    /// # Panics
    /// If `predicted` does not have `hours x outputs` values.
    pub fn totals(&self, predicted: &[f32]) -> Vec<f64> {
        assert_eq!(
            predicted.len(),
            self.n_hours * self.n_outputs,
            "predictions of {} hours x {} outputs",
            self.n_hours,
            self.n_outputs
        );
        self.readings
            .iter()
            .map(|r| {
                r.hours
                    .iter()
                    .map(|&t| predicted[t * self.n_outputs + self.output] as f64)
                    .sum()
            })
            .collect()
    }

    /// Each reading's sum of the output's column of `values` (`hours x outputs`, row-major, as
    /// the predictions): EnergyPlus's totals over the readings' hours, or a correction's.
    pub fn sums(&self, values: &[f64]) -> Vec<f64> {
        self.readings
            .iter()
            .map(|r| {
                r.hours
                    .iter()
                    .map(|&t| values[t * self.n_outputs + self.output])
                    .sum()
            })
            .collect()
    }

    /// The same readings and weights with other totals (one per reading, in order).
    ///
    /// # Panics
    /// If `totals` does not have one value per reading.
    pub fn with_totals(&self, totals: &[f64]) -> IntervalLikelihood {
        assert_eq!(totals.len(), self.readings.len(), "one total per reading");
        let mut out = self.clone();
        for (r, &t) in out.readings.iter_mut().zip(totals) {
            r.total = t;
        }
        out
    }

    /// `Q = sum_b r_b^2 / w_b` and the residuals.
    fn weighted_ssr(&self, predicted: &[f32]) -> (f64, Vec<f64>) {
        let r: Vec<f64> = self
            .readings
            .iter()
            .zip(self.totals(predicted))
            .map(|(b, s)| b.total - s)
            .collect();
        let q = r.iter().zip(&self.weights).map(|(r, w)| r * r / w).sum();
        (q, r)
    }

    /// The log-likelihood with the error scale integrated out (module docs). No reading: 0.
    pub fn log_marginal_sigma(&self, predicted: &[f32]) -> f64 {
        if self.readings.is_empty() {
            return 0.0;
        }
        let b = self.readings.len() as f64;
        let (q, _) = self.weighted_ssr(predicted);
        let q = q.max(f64::MIN_POSITIVE);
        ln_gamma(0.5 * b)
            - 0.5 * b * (std::f64::consts::PI * q).ln()
            - 0.5 * self.weights.iter().map(|w| w.ln()).sum::<f64>()
    }

    /// Adds the gradient of [`IntervalLikelihood::log_marginal_sigma`] with respect to the
    /// predictions into `grad` (same layout): every hour of reading b gets `B r_b / (w_b Q)`.
    pub fn add_log_marginal_sigma_gradient(&self, predicted: &[f32], grad: &mut [f32]) {
        assert_eq!(
            grad.len(),
            predicted.len(),
            "gradient and predictions differ"
        );
        if self.readings.is_empty() {
            return;
        }
        let b = self.readings.len() as f64;
        let (q, r) = self.weighted_ssr(predicted);
        let q = q.max(f64::MIN_POSITIVE);
        for ((reading, r), w) in self.readings.iter().zip(r).zip(&self.weights) {
            let g = (b * r / (w * q)) as f32;
            for &t in &reading.hours {
                grad[t * self.n_outputs + self.output] += g;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three readings of output 1 of 2 over 12 hours, one hour left out (a gap between bills).
    fn example(phi: f64) -> (IntervalLikelihood, Vec<f32>) {
        let readings = vec![
            IntervalReading {
                hours: vec![0, 1, 2, 3],
                total: 10.0,
            },
            IntervalReading {
                hours: vec![4, 5, 6],
                total: 8.5,
            },
            IntervalReading {
                hours: vec![8, 9, 10, 11],
                total: 9.0,
            },
        ];
        let predicted: Vec<f32> = (0..24).map(|i| 1.0 + 0.37 * i as f32 % 2.1).collect();
        (
            IntervalLikelihood::new(1, 2, 12, readings, phi).unwrap(),
            predicted,
        )
    }

    /// The likelihood written out directly: each reading's model total summed hour by hour,
    /// its weight from the AR(1) correlations pair by pair, the Jeffreys marginal by formula.
    fn direct(predicted: &[f32], phi: f64) -> f64 {
        let bills: [(&[usize], f64); 3] = [
            (&[0, 1, 2, 3], 10.0),
            (&[4, 5, 6], 8.5),
            (&[8, 9, 10, 11], 9.0),
        ];
        let (mut q, mut ln_w) = (0.0, 0.0);
        for (hours, total) in bills {
            let s: f64 = hours.iter().map(|&t| predicted[2 * t + 1] as f64).sum();
            let w: f64 = hours
                .iter()
                .flat_map(|&i| {
                    hours
                        .iter()
                        .map(move |&j| phi.powi((i as i32 - j as i32).abs()))
                })
                .sum();
            q += (total - s).powi(2) / w;
            ln_w += w.ln();
        }
        ln_gamma(1.5) - 1.5 * (std::f64::consts::PI * q).ln() - 0.5 * ln_w
    }

    #[test]
    fn matches_the_likelihood_written_out() {
        for phi in [0.0, 0.6, 0.95] {
            let (l, p) = example(phi);
            let (a, b) = (l.log_marginal_sigma(&p), direct(&p, phi));
            assert!((a - b).abs() < 1e-9, "phi {phi}: {a} against {b}");
        }
    }

    #[test]
    fn autocorrelated_hours_widen_a_sum() {
        let w = sum_weight;
        assert_eq!(w(720, 0.0), 720.0);
        // A 30-day bill of hours correlated 0.9: about (1 + phi) / (1 - phi) = 19 times.
        let ratio = w(720, 0.9) / w(720, 0.0);
        assert!((ratio - 19.0).abs() < 0.3, "{ratio}");
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let (l, p) = example(0.7);
        let mut grad = vec![0f32; p.len()];
        l.add_log_marginal_sigma_gradient(&p, &mut grad);
        for i in 0..p.len() {
            let h = 1e-2f32;
            let (mut up, mut down) = (p.clone(), p.clone());
            up[i] += h;
            down[i] -= h;
            let fd = (direct(&up, 0.7) - direct(&down, 0.7)) / (2.0 * h as f64);
            assert!(
                (fd - grad[i] as f64).abs() < 1e-3 * (1.0 + fd.abs()),
                "value {i}: {} against {fd}",
                grad[i]
            );
        }
        // Output 0 and the hour between bills do not enter.
        assert_eq!(grad[0], 0.0);
        assert_eq!(grad[2 * 7 + 1], 0.0);
    }

    #[test]
    fn refuses_overlaps_and_hours_out_of_range() {
        let r = |hours: Vec<usize>| IntervalReading { hours, total: 1.0 };
        let e = IntervalLikelihood::new(0, 1, 10, vec![r(vec![0, 1, 2]), r(vec![2, 3])], 0.5);
        assert!(format!("{}", e.unwrap_err()).contains("hour 2 is in an earlier interval"));
        let e = IntervalLikelihood::new(0, 1, 10, vec![r(vec![9, 10])], 0.5);
        assert!(format!("{}", e.unwrap_err()).contains("hour 10 of 10"));
        assert!(IntervalLikelihood::new(0, 1, 10, vec![r(vec![])], 0.5).is_err());
        assert!(IntervalLikelihood::new(0, 1, 10, vec![r(vec![1])], 1.0).is_err());
    }
}
