//! A discrepancy with structure: the model's form error as a random effect per calendar cell
//! (hour of day x day kind x season), integrated out, so that the parameters are not bent to
//! fit what the model cannot represent (Brynjarsdottir & O'Hagan 2014, "Learning about
//! physical parameters: the importance of model discrepancy").
//!
//! Per output, the residuals `r_t = y_t - f_t(theta)` are modelled as
//! `r_t = b_c(t) + e_t`: `b_c` the discrepancy of the hour's cell `c` and `e_t` the hourly
//! error (independent or AR(1), as [`GaussianLikelihood::log_marginal_sigma`] and
//! [`GaussianLikelihood::log_marginal_sigma_ar1`]). The residuals split into cell means
//! `m_c` and within-cell deviations `w_t = r_t - m_c(t)`; in the one-way random-effects
//! ANOVA (Searle, Casella & McCulloch 1992, Variance Components, Sec. 3.5) these are
//! independent, the within part with scale `sigma_e^2` on `n - C` degrees of freedom and the
//! between part `sqrt(n_c) m_c` with scale `sigma_B^2 = sigma_e^2 + n_c tau^2` on `C`.
//! Each scale is integrated out under its own Jeffreys prior, as the marginal likelihoods
//! already do:
//!
//! `ln p = ln Γ((n-C)/2) - (n-C)/2 ln(π S_W) [+ R/2 ln(1 - phi^2)] + ln Γ(C/2) - C/2 ln(π SS_B)`
//!
//! with `S_W` the within deviations' sum of squares (AR(1): `S(phi)` at the profile `phi`)
//! and `SS_B = sum_c n_c m_c^2`. Where the model is the building, `sigma_B^2` comes out near
//! the hourly error's and the cell means weigh as the hours they average; where the model
//! misses systematically by cell, `sigma_B^2` is large, the cell means weigh little, and the
//! parameters learn from what varies within cells (the weather's day-to-day swings). The
//! scale is measured from the residuals at each point, never assumed. Nothing here is `n x n`:
//! O(n) per evaluation, gradient included. (Treating within and between as independent is
//! exact for independent errors; with AR(1) errors it neglects the correlation between cell
//! means of adjacent hours, which enters only the between part's scale.)
//!
//! The pooled term still prefers parameters that shrink the cell means: a misfit shaped like a
//! parameter's own effect (a working-hours block on the electricity, like the equipment
//! density's) bends that parameter as much as without the term (measured, docs/benchmarks.md).
//! [`Cells::free_levels`] drops the between part: each cell's level is free (a fixed effect,
//! the limit `tau -> infinity`), and the parameters learn only from what varies within cells,
//! which a cell-shaped misfit cannot reach: `ln p = ln Γ((n-C)/2) - (n-C)/2 ln(π S_W)`.

use super::{Ar1Sums, GaussianLikelihood};
use crate::error::{Result, StatsError};

/// Meteorological seasons (DJF, MAM, JJA, SON) of the cells.
pub const SEASONS: usize = 4;

/// The calendar cell of every hour of the likelihood's hours.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cells {
    cell: Vec<usize>,
    n_cells: usize,
    free: bool,
}

impl Cells {
    /// Cells given per hour (`cell[t] < n_cells`).
    ///
    /// # Errors
    /// A cell index out of range.
    pub fn new(cell: Vec<usize>, n_cells: usize) -> Result<Cells> {
        if let Some((t, c)) = cell.iter().enumerate().find(|(_, &c)| c >= n_cells) {
            return Err(StatsError::Invalid(format!(
                "hour {t}: cell {c} of {n_cells}"
            )));
        }
        Ok(Cells {
            cell,
            n_cells,
            free: false,
        })
    }

    /// Hour of day x day kind (working or off) x meteorological season, 192 cells, for hour
    /// slots starting at midnight: `off_day[t]` and `month[t]` (1-12) per hour.
    ///
    /// # Panics
    /// If the lengths differ or a month is not 1-12.
    pub fn hour_kind_season(off_day: &[bool], month: &[u32]) -> Cells {
        assert_eq!(off_day.len(), month.len(), "one month per hour");
        let cell = (0..off_day.len())
            .map(|t| {
                assert!((1..=12).contains(&month[t]), "month {}", month[t]);
                let season = (month[t] as usize % 12) / 3;
                t % 24 + 24 * usize::from(off_day[t]) + 48 * season
            })
            .collect();
        Cells {
            cell,
            n_cells: 48 * SEASONS,
            free: false,
        }
    }

    /// The same cells with each cell's level free (module docs): the between-cell part leaves
    /// the likelihood and the discrepancy is each cell's mean residual, unshrunk.
    pub fn free_levels(mut self) -> Cells {
        self.free = true;
        self
    }

    /// Whether each cell's level is free ([`Cells::free_levels`]).
    pub fn is_free(&self) -> bool {
        self.free
    }

    /// Number of hours.
    pub fn len(&self) -> usize {
        self.cell.len()
    }

    /// Whether there is no hour.
    pub fn is_empty(&self) -> bool {
        self.cell.is_empty()
    }

    /// Number of cells (some may hold no observed hour).
    pub fn n_cells(&self) -> usize {
        self.n_cells
    }

    /// The cell of hour `t`.
    pub fn cell(&self, t: usize) -> usize {
        self.cell[t]
    }
}

/// One output's residuals split by cell (the sufficient statistics of [`Cells`]'s model).
#[derive(Debug, Clone, PartialEq)]
pub struct CellSplit {
    /// Observed hours per cell.
    pub count: Vec<usize>,
    /// Mean residual per cell `m_c` (0 where a cell holds no hour), in the output's units.
    pub mean: Vec<f64>,
    /// Cells holding an observed hour, `C`.
    pub cells: usize,
    /// Observed hours, `n`.
    pub hours: usize,
    /// `SS_B = sum_c n_c m_c^2`.
    pub between_ss: f64,
    /// Within-cell sum of squares `S_W` (AR(1): innovations', at `phi`).
    pub within_ss: f64,
    /// The within deviations' AR(1) coefficient (0 with independent errors).
    pub phi: f64,
    /// Whether each cell's level is free ([`Cells::free_levels`]): no between part.
    pub free: bool,
}

impl CellSplit {
    /// Within-cell degrees of freedom `n - C`.
    pub fn within_df(&self) -> usize {
        self.hours - self.cells
    }

    /// The hourly error's stationary variance, `S_W / (n - C) / (1 - phi^2)`.
    pub fn within_variance(&self) -> f64 {
        self.within_ss / self.within_df().max(1) as f64 / (1.0 - self.phi * self.phi)
    }

    /// `sigma_B^2 = SS_B / C`, the between part's scale.
    pub fn between_variance(&self) -> f64 {
        self.between_ss / self.cells.max(1) as f64
    }

    /// The discrepancy's variance per cell, `tau^2 = max(0, (sigma_B^2 - sigma_e^2) / n_bar)`
    /// (the ANOVA estimator; `n_bar` the mean hours per cell).
    pub fn discrepancy_variance(&self) -> f64 {
        let n_bar = self.hours as f64 / self.cells.max(1) as f64;
        ((self.between_variance() - self.within_variance()) / n_bar).max(0.0)
    }

    /// The discrepancy per cell: the cell means shrunk towards 0 by
    /// `n_c tau^2 / (sigma_e^2 + n_c tau^2)` (the best linear unbiased predictor of a random
    /// effect; Searle et al. 1992, Sec. 3.9).
    pub fn discrepancy(&self) -> Vec<f64> {
        if self.free {
            return self.mean.clone();
        }
        let (tau2, s2) = (self.discrepancy_variance(), self.within_variance());
        self.mean
            .iter()
            .zip(&self.count)
            .map(|(m, &n)| {
                let nt = n as f64 * tau2;
                if nt + s2 > 0.0 {
                    m * nt / (nt + s2)
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// `ln p` of the split (module docs).
    fn log_marginal(&self, runs: f64) -> f64 {
        let ln_scale = |df: f64, ss: f64| {
            if df <= 0.0 {
                0.0
            } else {
                super::ln_gamma(0.5 * df)
                    - 0.5 * df * (std::f64::consts::PI * ss.max(f64::MIN_POSITIVE)).ln()
            }
        };
        let within = ln_scale(self.within_df() as f64, self.within_ss)
            + 0.5 * runs * (1.0 - self.phi * self.phi).ln();
        match self.free {
            true => within,
            false => within + ln_scale(self.cells as f64, self.between_ss),
        }
    }
}

impl GaussianLikelihood {
    /// `ln p(y | f)` with the cell discrepancy of `cells` integrated out (module docs of
    /// [`crate::likelihood::cells`]), the hourly errors AR(1) when `ar1`, else independent.
    /// O(hours).
    ///
    /// # Panics
    /// If `predicted` does not have `hours x outputs` values or `cells` is not `hours` long.
    pub fn log_marginal_cells(&self, predicted: &[f32], cells: &Cells, ar1: bool) -> f64 {
        self.check_len(predicted);
        assert_eq!(cells.len(), self.n_hours, "one cell per hour");
        (0..self.n_outputs)
            .filter(|&k| self.n_obs[k] > 0)
            .map(|k| {
                let r = self.residual_series(predicted, k);
                let (split, runs) = split(&r, cells, ar1);
                split.log_marginal(runs)
            })
            .sum()
    }

    /// Each output's residuals split by cell at `predicted` (what the discrepancy carries).
    pub fn cell_splits(&self, predicted: &[f32], cells: &Cells, ar1: bool) -> Vec<CellSplit> {
        self.check_len(predicted);
        (0..self.n_outputs)
            .map(|k| split(&self.residual_series(predicted, k), cells, ar1).0)
            .collect()
    }

    /// [`GaussianLikelihood::log_marginal_cells`] and its gradient with respect to the
    /// predictions (`hours x outputs`, 0 at missing hours). With `g_W = d ln p_W / d w` (the
    /// AR(1) or independent marginal's, `phi`'s dependence included, on `n - C` degrees of
    /// freedom): `d ln p / d r_t = g_W,t - mean_c(t)(g_W) - C m_c(t) / SS_B`, and
    /// `d / d f = -d / d r`. O(hours).
    ///
    /// # Panics
    /// As [`GaussianLikelihood::log_marginal_cells`], or if `grad` has the wrong length.
    pub fn log_marginal_cells_gradient(
        &self,
        predicted: &[f32],
        cells: &Cells,
        ar1: bool,
        grad: &mut [f32],
    ) -> f64 {
        self.check_len(predicted);
        self.check_len(grad);
        assert_eq!(cells.len(), self.n_hours, "one cell per hour");
        let stride = self.n_outputs;
        let mut total = 0.0;
        for k in 0..self.n_outputs {
            let r = self.residual_series(predicted, k);
            if self.n_obs[k] == 0 {
                (0..self.n_hours).for_each(|t| grad[t * stride + k] = 0.0);
                continue;
            }
            let (s, runs) = split(&r, cells, ar1);
            total += s.log_marginal(runs);
            let w = within(&r, cells, &s.mean);
            let g_w = within_gradient(&w, &s, runs, ar1);
            let mut g_mean = vec![0.0; cells.n_cells()];
            for (t, g) in g_w.iter().enumerate() {
                if r[t].is_some() {
                    g_mean[cells.cell(t)] += g;
                }
            }
            for (c, g) in g_mean.iter_mut().enumerate() {
                if s.count[c] > 0 {
                    *g /= s.count[c] as f64;
                }
            }
            let b = match s.free {
                true => 0.0,
                false => s.cells as f64 / s.between_ss.max(f64::MIN_POSITIVE),
            };
            for t in 0..self.n_hours {
                let c = cells.cell(t);
                let d_r = match r[t] {
                    Some(_) => g_w[t] - g_mean[c] - b * s.mean[c],
                    None => 0.0,
                };
                grad[t * stride + k] = (-d_r) as f32;
            }
        }
        total
    }

    /// Output `k`'s residuals `y - f` per hour, `None` where unobserved.
    fn residual_series(&self, predicted: &[f32], k: usize) -> Vec<Option<f64>> {
        (0..self.n_hours)
            .map(|t| {
                let i = t * self.n_outputs + k;
                self.present[i].then(|| self.observed[i] - f64::from(predicted[i]))
            })
            .collect()
    }
}

/// The split of residuals `r` by `cells` and the number of AR(1) runs of the within
/// deviations.
fn split(r: &[Option<f64>], cells: &Cells, ar1: bool) -> (CellSplit, f64) {
    let mut count = vec![0usize; cells.n_cells()];
    let mut sum = vec![0.0; cells.n_cells()];
    for (t, v) in r.iter().enumerate() {
        if let Some(v) = v {
            count[cells.cell(t)] += 1;
            sum[cells.cell(t)] += v;
        }
    }
    let mean: Vec<f64> = sum
        .iter()
        .zip(&count)
        .map(|(s, &n)| if n > 0 { s / n as f64 } else { 0.0 })
        .collect();
    let between_ss = mean
        .iter()
        .zip(&count)
        .map(|(m, &n)| n as f64 * m * m)
        .sum();
    let w = within(r, cells, &mean);
    let (within_ss, phi, runs) = if ar1 {
        let a = Ar1Sums::of(&w);
        let phi = a.profile_phi();
        (a.s(phi), phi, a.runs)
    } else {
        (w.iter().flatten().map(|v| v * v).sum(), 0.0, 0.0)
    };
    let split = CellSplit {
        cells: count.iter().filter(|&&n| n > 0).count(),
        hours: count.iter().sum(),
        count,
        mean,
        between_ss,
        within_ss,
        phi,
        free: cells.is_free(),
    };
    (split, runs)
}

/// The within-cell deviations `w_t = r_t - m_c(t)`.
fn within(r: &[Option<f64>], cells: &Cells, mean: &[f64]) -> Vec<Option<f64>> {
    r.iter()
        .enumerate()
        .map(|(t, v)| v.map(|v| v - mean[cells.cell(t)]))
        .collect()
}

/// `d ln p_W / d w_t` of the within part on `n - C` degrees of freedom: independent,
/// `-(n - C) w_t / S_W`; AR(1), as [`GaussianLikelihood::log_marginal_sigma_ar1_gradient`]
/// derives it (phi's dependence on `w` included).
fn within_gradient(w: &[Option<f64>], s: &CellSplit, runs: f64, ar1: bool) -> Vec<f64> {
    let df = s.within_df() as f64;
    let ss = s.within_ss.max(f64::MIN_POSITIVE);
    if df <= 0.0 {
        return vec![0.0; w.len()];
    }
    if !ar1 {
        return w.iter().map(|v| v.map_or(0.0, |v| -df * v / ss)).collect();
    }
    let a = Ar1Sums::of(w);
    let den = a.pp - a.first;
    let phi = s.phi;
    let free = den > 0.0 && phi.abs() < 0.999;
    (0..w.len())
        .map(|t| {
            let Some(wt) = w[t] else { return 0.0 };
            let (ds, drp, dd) = super::ar1_partials(w, t, wt, phi);
            let mut dl = -0.5 * df / ss * ds;
            if free {
                dl -= runs * phi / (1.0 - phi * phi) * (drp - phi * dd) / den;
            }
            dl
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::likelihood::OutputNoise;

    const NOISE: OutputNoise = OutputNoise {
        sigma_y: 1.0,
        sigma_delta: 0.0,
        sigma_eta: 0.0,
    };

    /// 60 days of hours in January-March, two outputs, a residual with an hour-of-day
    /// pattern on output 0 and AR(1)-like wiggle on both.
    fn case() -> (GaussianLikelihood, Vec<f32>, Cells) {
        let n = 24 * 60;
        let mut obs = vec![0.0; 2 * n];
        let mut pred = vec![0f32; 2 * n];
        let mut e = 0.0;
        for t in 0..n {
            e = 0.8 * e + ((t * 7919 % 101) as f64 / 101.0 - 0.5);
            obs[2 * t] = 10.0 + (t % 24) as f64 * 0.3 + e;
            obs[2 * t + 1] = 5.0 - e;
            pred[2 * t] = 9.5 + 0.1 * (t % 5) as f32;
            pred[2 * t + 1] = 5.2;
        }
        obs[2 * 100 + 1] = f64::NAN;
        obs[2 * 500] = f64::NAN;
        let lik = GaussianLikelihood::new(&obs, &[NOISE, NOISE]).unwrap();
        let off: Vec<bool> = (0..n).map(|t| (t / 24) % 7 >= 5).collect();
        let month: Vec<u32> = (0..n).map(|t| 1 + (t / 24 / 25) as u32).collect();
        (lik, pred, Cells::hour_kind_season(&off, &month))
    }

    #[test]
    fn the_gradient_matches_finite_differences_for_both_error_models() {
        let (lik, pred, pooled) = case();
        for (cells, ar1) in [(pooled.clone(), false), (pooled.clone(), true)]
            .into_iter()
            .chain([
                (pooled.clone().free_levels(), false),
                (pooled.free_levels(), true),
            ])
        {
            let cells = &cells;
            let mut grad = vec![0f32; pred.len()];
            let lp = lik.log_marginal_cells_gradient(&pred, cells, ar1, &mut grad);
            assert!((lp - lik.log_marginal_cells(&pred, cells, ar1)).abs() < 1e-9);
            for i in [0, 1, 47, 200, 201, 999, 1001, 2 * 500 + 1, 2 * 100] {
                let h = 1e-2f32;
                let mut up = pred.clone();
                up[i] += h;
                let mut dn = pred.clone();
                dn[i] -= h;
                let fd = (lik.log_marginal_cells(&up, cells, ar1)
                    - lik.log_marginal_cells(&dn, cells, ar1))
                    / (2.0 * f64::from(h));
                let g = f64::from(grad[i]);
                assert!(
                    (fd - g).abs() <= 1e-3 * (1.0 + g.abs()),
                    "free {}, ar1 {ar1}, entry {i}: analytic {g}, finite difference {fd}",
                    cells.is_free()
                );
            }
        }
    }

    #[test]
    fn a_pattern_by_cell_is_carried_by_the_discrepancy_not_the_level() {
        // Meters = model + a known hour-of-day pattern + noise: the split recovers the
        // pattern, and the likelihood barely prefers bending the model towards it (an
        // offset of the whole model by the pattern's mean) over the true model.
        let n = 24 * 90;
        let pattern = |t: usize| {
            if (8..18).contains(&(t % 24)) {
                3.0
            } else {
                -1.0
            }
        };
        let mut e = 0.0;
        let obs: Vec<f64> = (0..n)
            .map(|t| {
                e = 0.5 * e + ((t * 7919 % 101) as f64 / 101.0 - 0.5);
                20.0 + pattern(t) + e
            })
            .collect();
        let lik = GaussianLikelihood::new(&obs, &[NOISE]).unwrap();
        let off = vec![false; n];
        let month: Vec<u32> = (0..n).map(|t| 1 + (t / 24 / 31).min(2) as u32).collect();
        let cells = Cells::hour_kind_season(&off, &month);
        let truth = vec![20f32; n];
        let s = &lik.cell_splits(&truth, &cells, true)[0];
        let d = s.discrepancy();
        for (t, _) in obs.iter().enumerate().take(48) {
            assert!(
                (d[cells.cell(t)] - pattern(t)).abs() < 0.25,
                "hour {t}: {} against {}",
                d[cells.cell(t)],
                pattern(t)
            );
        }
        // A zero-mean discrepancy cannot tell the pattern's mean from the model's level, so
        // both forms prefer a level bent by it (+0.67); with the term the pull is a fraction
        // of what it is without (C cells weigh, not n hours).
        let bent = vec![20.0 + 10.0 * 3.0 / 24.0 - 14.0 / 24.0; n];
        let pull_hourly = lik.log_marginal_sigma_ar1(&bent) - lik.log_marginal_sigma_ar1(&truth);
        let pull_cells = lik.log_marginal_cells(&bent, &cells, true)
            - lik.log_marginal_cells(&truth, &cells, true);
        assert!(pull_hourly > 0.0, "{pull_hourly}");
        assert!(
            pull_cells < 0.5 * pull_hourly,
            "with cells {pull_cells}, without {pull_hourly}"
        );
    }

    #[test]
    fn cells_follow_hour_day_kind_and_season() {
        let c = Cells::hour_kind_season(&[false, true, false], &[12, 1, 7]);
        assert_eq!(c.cell(0), 0);
        assert_eq!(c.cell(1), 1 + 24);
        assert_eq!(c.cell(2), 2 + 48 * 2);
        assert!(Cells::new(vec![0, 3], 3).is_err());
    }
}
