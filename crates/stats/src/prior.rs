//! Triangular priors of the calibration parameters (reference Section 2.2: engineering-based
//! parameter ranges and schedule priors from box-plot quartiles), and the map between a
//! parameter's physical value and the unit space `u = (x - min) / (max - min)` in which the
//! chains move.

use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::error::{Result, StatsError};

/// A triangular distribution on `[min, max]` with its peak at `mode`.
///
/// Invariants (checked by [`Triangular::new`] and on deserialisation): all finite,
/// `min <= mode <= max` and `min < max`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "TriangularSpec", into = "TriangularSpec")]
pub struct Triangular {
    min: f64,
    mode: f64,
    max: f64,
}

#[derive(Serialize, Deserialize)]
struct TriangularSpec {
    min: f64,
    mode: f64,
    max: f64,
}

impl TryFrom<TriangularSpec> for Triangular {
    type Error = StatsError;
    fn try_from(s: TriangularSpec) -> Result<Self> {
        Triangular::new(s.min, s.mode, s.max)
    }
}

impl From<Triangular> for TriangularSpec {
    fn from(t: Triangular) -> Self {
        TriangularSpec {
            min: t.min,
            mode: t.mode,
            max: t.max,
        }
    }
}

impl Triangular {
    /// A triangular prior; errors unless all are finite, `min <= mode <= max` and `min < max`.
    pub fn new(min: f64, mode: f64, max: f64) -> Result<Self> {
        let err = |reason| {
            Err(StatsError::InvalidTriangular {
                min,
                mode,
                max,
                reason,
            })
        };
        if !(min.is_finite() && mode.is_finite() && max.is_finite()) {
            return err("bounds and mode must be finite");
        }
        if min >= max {
            return err("min must be strictly less than max");
        }
        if mode < min || mode > max {
            return err("mode must lie within [min, max]");
        }
        Ok(Triangular { min, mode, max })
    }

    /// Lower bound of the support.
    pub fn min(&self) -> f64 {
        self.min
    }
    /// Most probable value.
    pub fn mode(&self) -> f64 {
        self.mode
    }
    /// Upper bound of the support.
    pub fn max(&self) -> f64 {
        self.max
    }
    /// `max - min`.
    pub fn width(&self) -> f64 {
        self.max - self.min
    }
    /// Whether `x` lies in the support `[min, max]`.
    pub fn contains(&self, x: f64) -> bool {
        x >= self.min && x <= self.max
    }

    /// Probability density at `x` (0 outside the support).
    pub fn pdf(&self, x: f64) -> f64 {
        let (a, c, b) = (self.min, self.mode, self.max);
        if !(x >= a && x <= b) {
            0.0
        } else if x < c {
            2.0 * (x - a) / ((b - a) * (c - a))
        } else if x == c {
            2.0 / (b - a)
        } else {
            2.0 * (b - x) / ((b - a) * (b - c))
        }
    }

    /// Natural log of the density (`-inf` outside the support and at a zero-density bound).
    pub fn ln_pdf(&self, x: f64) -> f64 {
        self.pdf(x).ln()
    }

    /// `d ln pdf / dx` inside the support (`1 / (x - min)` below the mode, `-1 / (max - x)`
    /// above it; at the mode the side the density continues on); 0 outside.
    pub fn d_ln_pdf(&self, x: f64) -> f64 {
        let (a, c, b) = (self.min, self.mode, self.max);
        if !(a < x && x < b) {
            0.0
        } else if x < c || (x == c && c == b) {
            1.0 / (x - a)
        } else {
            -1.0 / (b - x)
        }
    }

    /// `d ln pdf(from_unit(u)) / du`: [`Triangular::d_ln_pdf`] times the width.
    pub fn d_ln_pdf_unit(&self, u: f64) -> f64 {
        self.d_ln_pdf(self.from_unit(u)) * self.width()
    }

    /// Cumulative distribution function.
    pub fn cdf(&self, x: f64) -> f64 {
        let (a, c, b) = (self.min, self.mode, self.max);
        if x.is_nan() {
            f64::NAN
        } else if x <= a {
            0.0
        } else if x >= b {
            1.0
        } else if x <= c {
            (x - a) * (x - a) / ((b - a) * (c - a))
        } else {
            1.0 - (b - x) * (b - x) / ((b - a) * (b - c))
        }
    }

    /// Inverse CDF (quantile) for `p` in `[0, 1]`; NaN outside.
    pub fn quantile(&self, p: f64) -> f64 {
        if !(0.0..=1.0).contains(&p) {
            return f64::NAN;
        }
        let (a, c, b) = (self.min, self.mode, self.max);
        let fc = (c - a) / (b - a);
        let x = if p < fc {
            a + (p * (b - a) * (c - a)).sqrt()
        } else {
            b - ((1.0 - p) * (b - a) * (b - c)).sqrt()
        };
        x.clamp(a, b)
    }

    /// Mean `(min + mode + max) / 3`.
    pub fn mean(&self) -> f64 {
        (self.min + self.mode + self.max) / 3.0
    }

    /// Variance `(a^2 + b^2 + c^2 - ab - ac - bc) / 18`.
    pub fn variance(&self) -> f64 {
        let (a, c, b) = (self.min, self.mode, self.max);
        (a * a + b * b + c * c - a * b - a * c - b * c) / 18.0
    }

    /// Standard deviation.
    pub fn sd(&self) -> f64 {
        self.variance().sqrt()
    }

    /// Map a physical value to the unit space: `u = (x - min) / (max - min)`.
    pub fn to_unit(&self, x: f64) -> f64 {
        (x - self.min) / (self.max - self.min)
    }

    /// Map a unit-space coordinate back to the physical value: `x = min + u (max - min)`.
    pub fn from_unit(&self, u: f64) -> f64 {
        self.min + u * (self.max - self.min)
    }

    /// Log density of the unit-space coordinate `u` (the prior pushed through the linear map:
    /// `ln p(x(u)) + ln(max - min)`).
    pub fn ln_pdf_unit(&self, u: f64) -> f64 {
        self.ln_pdf(self.from_unit(u)) + self.width().ln()
    }

    /// One draw from the prior by inverse-CDF sampling.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        self.quantile(rng.random::<f64>())
    }
}

/// The prior of one named calibration parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Prior {
    /// Parameter name (unique within a model).
    pub name: String,
    /// Physical unit, e.g. `"W/m2"` or `"C"`.
    pub unit: String,
    /// The triangular prior distribution.
    pub dist: Triangular,
}

impl Prior {
    /// A named prior.
    pub fn new(name: impl Into<String>, unit: impl Into<String>, dist: Triangular) -> Self {
        Prior {
            name: name.into(),
            unit: unit.into(),
            dist,
        }
    }
}

/// Joint log prior density of a unit-space point (independent parameters):
/// `sum_i ln p_i(u_i)`. `-inf` outside `[0, 1]^d`.
pub fn ln_prior_unit(dists: &[Triangular], u: &[f64]) -> f64 {
    debug_assert_eq!(dists.len(), u.len());
    dists
        .iter()
        .zip(u)
        .map(|(d, &ui)| {
            if (0.0..=1.0).contains(&ui) {
                d.ln_pdf_unit(ui)
            } else {
                f64::NEG_INFINITY
            }
        })
        .sum()
}

/// Gradient of [`ln_prior_unit`] with respect to the unit-space point (0 outside the supports).
pub fn grad_ln_prior_unit(dists: &[Triangular], u: &[f64]) -> Vec<f64> {
    dists
        .iter()
        .zip(u)
        .map(|(p, &v)| p.d_ln_pdf_unit(v))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn d_ln_pdf_matches_central_differences() {
        for t in [
            Triangular::new(1.0, 2.0, 5.0).unwrap(),
            Triangular::new(0.0, 0.0, 1.0).unwrap(),
            Triangular::new(0.0, 1.0, 1.0).unwrap(),
        ] {
            for x in [0.3, 0.7, 1.5, 2.5, 4.9] {
                if !(t.min() < x - 1e-4 && x + 1e-4 < t.max()) || (x - t.mode()).abs() < 1e-3 {
                    continue;
                }
                let fd = (t.ln_pdf(x + 1e-6) - t.ln_pdf(x - 1e-6)) / 2e-6;
                assert!(
                    (t.d_ln_pdf(x) - fd).abs() < 1e-5 * fd.abs().max(1.0),
                    "{t:?} at {x}"
                );
            }
            assert_eq!(t.d_ln_pdf(t.max() + 1.0), 0.0);
        }
    }

    use rand::SeedableRng;

    #[test]
    fn validation() {
        assert!(Triangular::new(0.0, 1.0, 2.0).is_ok());
        assert!(Triangular::new(0.0, 0.0, 2.0).is_ok());
        assert!(Triangular::new(0.0, 2.0, 2.0).is_ok());
        let e = Triangular::new(1.0, 1.0, 1.0).unwrap_err();
        assert!(e.to_string().contains("strictly less"), "{e}");
        assert!(Triangular::new(0.0, 3.0, 2.0).is_err());
        assert!(Triangular::new(0.0, f64::NAN, 2.0).is_err());
        let bad: std::result::Result<Triangular, _> =
            serde_json::from_str(r#"{"min": 2.0, "mode": 1.0, "max": 3.0}"#);
        assert!(bad.is_err());
        let ok: Triangular = serde_json::from_str(r#"{"min": 0, "mode": 1, "max": 3}"#).unwrap();
        assert_eq!(ok.mode(), 1.0);
    }

    #[test]
    fn moments_and_shape() {
        // Hand-computed: T(0, 1, 3): mean 4/3, variance (0 + 9 + 1 - 0 - 0 - 3)/18 = 7/18.
        let t = Triangular::new(0.0, 1.0, 3.0).unwrap();
        assert!((t.mean() - 4.0 / 3.0).abs() < 1e-15);
        assert!((t.variance() - 7.0 / 18.0).abs() < 1e-15);
        assert!((t.pdf(1.0) - 2.0 / 3.0).abs() < 1e-15);
        assert!((t.pdf(0.5) - 1.0 / 3.0).abs() < 1e-15);
        assert!((t.pdf(2.0) - 1.0 / 3.0).abs() < 1e-15);
        assert_eq!(t.pdf(-0.1), 0.0);
        assert_eq!(t.pdf(3.1), 0.0);
        assert!((t.cdf(1.0) - 1.0 / 3.0).abs() < 1e-15);
        assert!((t.cdf(2.0) - (1.0 - 1.0 / 6.0)).abs() < 1e-15);
        assert!((t.ln_pdf(0.5) - (1.0f64 / 3.0).ln()).abs() < 1e-15);
        // Mode at a bound.
        let r = Triangular::new(0.0, 0.0, 1.0).unwrap();
        assert!((r.pdf(0.0) - 2.0).abs() < 1e-15);
        assert!((r.cdf(0.5) - 0.75).abs() < 1e-15);
        assert!((r.quantile(0.75) - 0.5).abs() < 1e-15);
    }

    #[test]
    fn quantile_inverts_cdf_and_unit_map() {
        let t = Triangular::new(18.0, 21.0, 24.5).unwrap();
        for i in 0..=100 {
            let p = i as f64 / 100.0;
            let x = t.quantile(p);
            assert!((t.cdf(x) - p).abs() < 1e-12, "p {p}");
        }
        assert_eq!(t.quantile(0.0), 18.0);
        assert_eq!(t.quantile(1.0), 24.5);
        assert!(t.quantile(1.1).is_nan());
        assert!((t.from_unit(t.to_unit(22.3)) - 22.3).abs() < 1e-12);
        // The unit-space density integrates to one (midpoint rule).
        let n = 20000;
        let s: f64 = (0..n)
            .map(|i| t.ln_pdf_unit((i as f64 + 0.5) / n as f64).exp() / n as f64)
            .sum();
        assert!((s - 1.0).abs() < 1e-6);
    }

    #[test]
    fn sampling_matches_moments() {
        let t = Triangular::new(-1.0, 2.0, 3.0).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let n = 200_000;
        let xs: Vec<f64> = (0..n).map(|_| t.sample(&mut rng)).collect();
        let m = xs.iter().sum::<f64>() / n as f64;
        let v = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1) as f64;
        assert!((m - t.mean()).abs() < 5.0 * t.sd() / (n as f64).sqrt());
        assert!((v / t.variance() - 1.0).abs() < 0.02);
    }
}
