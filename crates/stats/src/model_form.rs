//! Model-form diagnostics: whether a calibrated model can reach a meter at all, and where its
//! hourly residuals sit when it does not.
//!
//! The residuals are those of ASHRAE Guideline 14 ([`crate::metrics`]): `r_t = y_t - yhat_t`,
//! measured minus simulated (positive: the model is below the meter), over the hours where
//! both are present.
//!
//! - [`reach`]: the meter's total against the model's at the estimate and at posterior draws,
//!   with a [`Verdict`] by the hourly Guideline 14 criteria: reached, the level missed (and
//!   whether any posterior draw reaches it), or the level met and the hourly shape missed.
//! - [`pattern`]: the residuals grouped by one factor (hour of day, day kind, month, outdoor
//!   temperature band): group means and the correlation ratio
//!   `eta^2 = SS_between / SS_total` (Pearson 1905; the `R^2` of a one-way ANOVA), the share
//!   of the residuals' variance the grouping explains.
//! - [`quantile_bands`]: equal-count bands of a covariate (outdoor temperature) as groups.
//! - [`slope`]: the least-squares slope of the residuals on a covariate.
//! - [`additive_discrepancy`]: an additive discrepancy `delta(t) = mu + sum_f a_f[g_f(t)]`
//!   fitted to the residuals by backfitting (Hastie & Tibshirani 1990, Generalized Additive
//!   Models, Sec. 4.4), so that `yhat + delta` is the model with its systematic misfit
//!   removed. It is fitted after the calibration, to the residuals at the estimate (a modular
//!   estimate in the sense of Liu, Bayarri & Berger 2009), not jointly with the parameters:
//!   it reports the model's form error apart from the parameters, in the spirit of Kennedy &
//!   O'Hagan's (2001) `delta`, at a cost linear in the hours.
//! - [`partial_fit`]: the share of a series' variation beyond some factors (the calendar)
//!   that further factors (the weather) explain: the coefficient of partial determination of
//!   nested additive fits (Cohen et al. 2003, Applied Multiple Regression, Sec. 5.4; here with
//!   group effects fitted by backfitting). Measured on the meter and
//!   on the model alike, it tells a meter that does not follow the weather file from a model
//!   that does.
//! - [`piled_at_bound`]: a parameter whose posterior median lies against a prior bound.
//! - [`marginal_slopes`] and [`levers`]: for a meter out of reach, how far each parameter
//!   moves its total toward the meter within its prior, from first-order slopes over the
//!   EnergyPlus runs of a Latin-hypercube design (whose columns are nearly uncorrelated, so
//!   each parameter's simple regression slope estimates its first-order effect: Saltelli et
//!   al. 2008, Global Sensitivity Analysis: The Primer, Sec. 1.2.3).

use serde::{Deserialize, Serialize};

use crate::error::{Result, StatsError};
use crate::metrics::{g14, HOURLY_CV_RMSE_LIMIT, HOURLY_NMBE_LIMIT};

/// Share of a prior's range next to a bound within which a posterior median counts as piled
/// against that bound ([`piled_at_bound`]).
pub const PILE_SHARE: f64 = 0.05;

/// Backfitting sweeps of [`additive_discrepancy`] (the effects change by less than 1e-9 of
/// the residuals' scale after a handful on hourly data; a fixed count keeps it deterministic).
pub const BACKFIT_SWEEPS: usize = 25;

/// What a calibrated model makes of one meter, by the hourly Guideline 14 criteria at the
/// estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// `|NMBE| <= 10 %` and `CV-RMSE <= 30 %`.
    Reached,
    /// `|NMBE| > 10 %`: the model misses the meter's level.
    Level,
    /// The level is met (`|NMBE| <= 10 %`) but not the hourly shape (`CV-RMSE > 30 %`).
    Shape,
}

impl Verdict {
    /// Its name, as `summary.json` writes it (`reached`, `level`, `shape`).
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Reached => "reached",
            Verdict::Level => "level",
            Verdict::Shape => "shape",
        }
    }
}

/// A meter's total against the model's, over the hours where both are present.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Reach {
    /// Hours compared.
    pub hours: usize,
    /// The meter's total, kWh.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub measured_kwh: f64,
    /// The model's total at the estimate, kWh.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub estimate_kwh: f64,
    /// The smallest and largest total among the estimate and the posterior draws, kWh.
    pub draws_kwh: [f64; 2],
    /// Whether the meter's total lies within `draws_kwh`: some posterior draw reaches the level.
    pub within_draws: bool,
    /// Hourly NMBE at the estimate, per cent.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub nmbe: f64,
    /// Hourly CV-RMSE at the estimate, per cent.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub cv_rmse: f64,
    /// The verdict.
    pub verdict: Verdict,
}

/// The meter's total against the model's at the estimate and at `draws` (hourly series of
/// the model at posterior draws), over the hours where the meter and the estimate are both
/// present (NaN: missing). Errors as [`crate::metrics::g14`] does.
pub fn reach(measured: &[f64], estimate: &[f64], draws: &[Vec<f64>]) -> Result<Reach> {
    let m = g14(measured, estimate)?;
    if let Some(d) = draws.iter().find(|d| d.len() != measured.len()) {
        return Err(StatsError::Shape(format!(
            "a draw of {} hours against {} measured",
            d.len(),
            measured.len()
        )));
    }
    let both: Vec<usize> = (0..measured.len())
        .filter(|&t| measured[t].is_finite() && estimate[t].is_finite())
        .collect();
    let total = |s: &[f64]| -> f64 { both.iter().map(|&t| s[t]).filter(|v| v.is_finite()).sum() };
    let measured_kwh = total(measured);
    let estimate_kwh = total(estimate);
    let mut range = [estimate_kwh, estimate_kwh];
    for d in draws {
        let x = total(d);
        range = [range[0].min(x), range[1].max(x)];
    }
    let verdict = if m.nmbe.abs() > HOURLY_NMBE_LIMIT {
        Verdict::Level
    } else if m.cv_rmse > HOURLY_CV_RMSE_LIMIT {
        Verdict::Shape
    } else {
        Verdict::Reached
    };
    Ok(Reach {
        hours: both.len(),
        measured_kwh,
        estimate_kwh,
        draws_kwh: range,
        within_draws: (range[0]..=range[1]).contains(&measured_kwh),
        nmbe: m.nmbe,
        cv_rmse: m.cv_rmse,
        verdict,
    })
}

/// One group of hours of a [`Pattern`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Group {
    /// What the group is (`"07"`, `"off day"`, `"Jan"`, `"-12.2..-3.9"`).
    pub label: String,
    /// Hours in the group with a residual.
    pub hours: usize,
    /// Mean residual (measured - simulated), kWh per hour.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub mean_residual: f64,
    /// Mean measured value, kWh per hour.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub mean_measured: f64,
}

/// Residuals grouped by one factor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Pattern {
    /// Correlation ratio `eta^2 = SS_between / SS_total` in [0, 1]: the share of the
    /// residuals' variance (around their mean) that the group means explain.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub eta_squared: f64,
    /// The groups, in label order; empty groups are left out.
    pub groups: Vec<Group>,
}

/// The residuals `measured - simulated` grouped by `group[t]` (an index into `labels`; hours
/// where either value is NaN are left out): group means and `eta^2`. Errors when the lengths
/// differ, a group index is out of range, or fewer than two hours remain.
pub fn pattern(
    measured: &[f64],
    simulated: &[f64],
    group: &[usize],
    labels: &[String],
) -> Result<Pattern> {
    if measured.len() != simulated.len() || group.len() != measured.len() {
        return Err(StatsError::Shape(format!(
            "{} measured, {} simulated and {} grouped hours",
            measured.len(),
            simulated.len(),
            group.len()
        )));
    }
    if let Some(g) = group.iter().find(|g| **g >= labels.len()) {
        return Err(StatsError::Invalid(format!(
            "group {g} of {} labels",
            labels.len()
        )));
    }
    let k = labels.len();
    let (mut n, mut sum_r, mut sum_y) = (vec![0usize; k], vec![0.0; k], vec![0.0; k]);
    let mut residuals = Vec::with_capacity(measured.len());
    for t in 0..measured.len() {
        let (y, s) = (measured[t], simulated[t]);
        if y.is_finite() && s.is_finite() {
            let g = group[t];
            n[g] += 1;
            sum_r[g] += y - s;
            sum_y[g] += y;
            residuals.push((g, y - s));
        }
    }
    if residuals.len() < 2 {
        return Err(StatsError::NotEnoughData(format!(
            "{} hours with both values; need 2",
            residuals.len()
        )));
    }
    let mean_of = |g: usize| sum_r[g] / n[g] as f64;
    let grand = residuals.iter().map(|(_, r)| r).sum::<f64>() / residuals.len() as f64;
    let ss_total: f64 = residuals.iter().map(|(_, r)| (r - grand).powi(2)).sum();
    let ss_between: f64 = (0..k)
        .filter(|&g| n[g] > 0)
        .map(|g| n[g] as f64 * (mean_of(g) - grand).powi(2))
        .sum();
    Ok(Pattern {
        eta_squared: if ss_total > 0.0 {
            (ss_between / ss_total).clamp(0.0, 1.0)
        } else {
            0.0
        },
        groups: (0..k)
            .filter(|&g| n[g] > 0)
            .map(|g| Group {
                label: labels[g].clone(),
                hours: n[g],
                mean_residual: mean_of(g),
                mean_measured: sum_y[g] / n[g] as f64,
            })
            .collect(),
    })
}

/// `k` equal-count bands of `x` (by its empirical quantiles over the finite values): each
/// value's band index and each band's label `"lo..hi"` (the band's smallest and largest
/// value, one decimal). A non-finite value goes to band 0 (callers leave those hours out by
/// their residual). Fewer bands when `x` has fewer distinct values; ties stay in one band.
pub fn quantile_bands(x: &[f64], k: usize) -> (Vec<usize>, Vec<String>) {
    let mut sorted: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f64::total_cmp);
    if sorted.is_empty() || k == 0 {
        return (vec![0; x.len()], vec![String::from("all")]);
    }
    // Upper edges at the j/k quantiles; equal edges merge (ties in one band).
    let mut edges: Vec<f64> = (1..k)
        .map(|j| sorted[(j * sorted.len() / k).min(sorted.len() - 1)])
        .collect();
    edges.dedup();
    edges.retain(|e| *e < sorted[sorted.len() - 1]);
    let band = |v: f64| edges.partition_point(|e| v > *e);
    let index: Vec<usize> = x
        .iter()
        .map(|v| if v.is_finite() { band(*v) } else { 0 })
        .collect();
    let bands = edges.len() + 1;
    let mut lo = vec![f64::INFINITY; bands];
    let mut hi = vec![f64::NEG_INFINITY; bands];
    for v in sorted {
        let b = band(v);
        lo[b] = lo[b].min(v);
        hi[b] = hi[b].max(v);
    }
    let labels = (0..bands)
        .map(|b| format!("{:.1}..{:.1}", lo[b], hi[b]))
        .collect();
    (index, labels)
}

/// Least-squares slope of `r` on `x` over the pairs where both are finite (0 when `x` does
/// not vary or fewer than two pairs remain).
pub fn slope(x: &[f64], r: &[f64]) -> f64 {
    let pairs: Vec<(f64, f64)> = x
        .iter()
        .zip(r)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
        .collect();
    if pairs.len() < 2 {
        return 0.0;
    }
    let n = pairs.len() as f64;
    let mx = pairs.iter().map(|p| p.0).sum::<f64>() / n;
    let mr = pairs.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = pairs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxr: f64 = pairs.iter().map(|p| (p.0 - mx) * (p.1 - mr)).sum();
    if sxx > 0.0 {
        sxr / sxx
    } else {
        0.0
    }
}

/// One factor of an additive discrepancy: each hour's group and the number of groups.
#[derive(Debug, Clone, Copy)]
pub struct FactorGroups<'a> {
    /// The group of each hour (`< levels`).
    pub group: &'a [usize],
    /// Number of groups.
    pub levels: usize,
}

/// An additive discrepancy fitted to the residuals ([`additive_discrepancy`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Additive {
    /// `delta(t)` for every hour (also where the meter is missing): add it to the model.
    pub delta: Vec<f64>,
    /// Share of the residuals' mean square (around 0, so a level bias counts) that `delta`
    /// removes over the fitted hours: `1 - sum (r - delta)^2 / sum r^2`.
    pub share: f64,
}

/// Fits `delta(t) = mu + sum_f a_f[g_f(t)]` to the residuals `measured - simulated` over the
/// hours where both are present, by backfitting ([`BACKFIT_SWEEPS`] sweeps; each sweep sets
/// every factor's effects to the group means of the residuals less the other terms, centred
/// so that `mu` carries the mean), and evaluates it at every hour. Errors when the lengths
/// differ, a group is out of range, or fewer than two hours have both values.
pub fn additive_discrepancy(
    measured: &[f64],
    simulated: &[f64],
    factors: &[FactorGroups<'_>],
) -> Result<Additive> {
    let n = measured.len();
    if simulated.len() != n || factors.iter().any(|f| f.group.len() != n) {
        return Err(StatsError::Shape(format!(
            "{n} measured hours against {} simulated or a factor of another length",
            simulated.len()
        )));
    }
    if factors
        .iter()
        .any(|f| f.group.iter().any(|g| *g >= f.levels))
    {
        return Err(StatsError::Invalid(
            "a group index past its factor's levels".into(),
        ));
    }
    let fit: Vec<usize> = (0..n)
        .filter(|&t| measured[t].is_finite() && simulated[t].is_finite())
        .collect();
    if fit.len() < 2 {
        return Err(StatsError::NotEnoughData(format!(
            "{} hours with both values; need 2",
            fit.len()
        )));
    }
    let r: Vec<f64> = fit.iter().map(|&t| measured[t] - simulated[t]).collect();
    let mu = r.iter().sum::<f64>() / r.len() as f64;
    let mut effects: Vec<Vec<f64>> = factors.iter().map(|f| vec![0.0; f.levels]).collect();
    let term = |effects: &[Vec<f64>], t: usize, skip: usize| -> f64 {
        factors
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != skip)
            .map(|(j, f)| effects[j][f.group[t]])
            .sum()
    };
    for _ in 0..BACKFIT_SWEEPS {
        for (j, f) in factors.iter().enumerate() {
            let (mut sum, mut count) = (vec![0.0; f.levels], vec![0usize; f.levels]);
            for (i, &t) in fit.iter().enumerate() {
                let g = f.group[t];
                sum[g] += r[i] - mu - term(&effects, t, j);
                count[g] += 1;
            }
            let means: Vec<f64> = (0..f.levels)
                .map(|g| {
                    if count[g] > 0 {
                        sum[g] / count[g] as f64
                    } else {
                        0.0
                    }
                })
                .collect();
            // Centre on the fitted hours so that mu keeps the mean.
            let centre = fit.iter().map(|&t| means[f.group[t]]).sum::<f64>() / fit.len() as f64;
            effects[j] = means.iter().map(|m| m - centre).collect();
        }
    }
    let delta: Vec<f64> = (0..n).map(|t| mu + term(&effects, t, usize::MAX)).collect();
    let ss: f64 = r.iter().map(|x| x * x).sum();
    let ss_left: f64 = fit
        .iter()
        .zip(&r)
        .map(|(&t, x)| (x - delta[t]).powi(2))
        .sum();
    Ok(Additive {
        share: if ss > 0.0 { 1.0 - ss_left / ss } else { 0.0 },
        delta,
    })
}

/// What further factors explain of a series beyond some base factors ([`partial_fit`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PartialFit {
    /// The coefficient of partial determination: the share of what the base factors leave
    /// that the further factors remove (0..1).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub share: f64,
    /// What the further factors remove, as a root mean square over the fitted hours
    /// (`sqrt((SSE_base - SSE_all) / n)`, the series' unit): the size of the variation they
    /// explain, which a noisy series' share understates.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub explained_rms: f64,
    /// What the base factors leave, as a root mean square (`sqrt(SSE_base / n)`): 0 for a
    /// series the base factors explain entirely (a flat or dead meter).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub base_rms: f64,
    /// The series' mean over the fitted hours.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub mean: f64,
}

impl PartialFit {
    /// [`PartialFit::explained_rms`] relative to the series' mean (NaN unless the mean is
    /// positive): the size of the explained variation, free of the series' level.
    pub fn relative_explained(&self) -> f64 {
        if self.mean > 0.0 {
            self.explained_rms / self.mean
        } else {
            f64::NAN
        }
    }
}

/// The coefficient of partial determination of `extra` over `base` (Cohen et al. 2003,
/// Applied Multiple Regression, Sec. 5.4): the share of `y`'s sum of squares left by an
/// additive fit of the `base` factors (`y ~ mu + sum a_f[g_f]`) that adding the `extra`
/// factors removes, `1 - SSE(base + extra) / SSE(base)`, with the sizes behind it, over the
/// hours where `y` is finite (both fits by [`additive_discrepancy`] against a zero model). A
/// share of 0 where the base factors leave nothing to explain. Errors as
/// [`additive_discrepancy`].
pub fn partial_fit(
    y: &[f64],
    base: &[FactorGroups<'_>],
    extra: &[FactorGroups<'_>],
) -> Result<PartialFit> {
    let zero = vec![0.0; y.len()];
    let fitted: Vec<usize> = (0..y.len()).filter(|&t| y[t].is_finite()).collect();
    let n = fitted.len().max(1) as f64;
    let sse = |factors: &[FactorGroups<'_>]| -> Result<f64> {
        let delta = additive_discrepancy(y, &zero, factors)?.delta;
        Ok(fitted.iter().map(|&t| (y[t] - delta[t]).powi(2)).sum())
    };
    let all: Vec<FactorGroups<'_>> = base.iter().chain(extra).copied().collect();
    let (before, after) = (sse(base)?, sse(&all)?);
    let removed = (before - after).max(0.0);
    let mean = fitted.iter().map(|&t| y[t]).sum::<f64>() / n;
    // Rounding leaves about 1e-16 of the mean square where the base factors explain all.
    let nothing_left = before <= 1e-12 * fitted.iter().map(|&t| y[t] * y[t]).sum::<f64>();
    Ok(if nothing_left {
        PartialFit {
            share: 0.0,
            explained_rms: 0.0,
            base_rms: 0.0,
            mean,
        }
    } else {
        PartialFit {
            share: (removed / before).min(1.0),
            explained_rms: (removed / n).sqrt(),
            base_rms: (before / n).sqrt(),
            mean,
        }
    })
}

/// Which bound of its prior a parameter is piled against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    /// The prior's minimum.
    Lower,
    /// The prior's maximum.
    Upper,
}

impl Bound {
    /// `lower` or `upper`, as a sentence says it.
    pub fn as_str(self) -> &'static str {
        match self {
            Bound::Lower => "lower",
            Bound::Upper => "upper",
        }
    }
}

/// A slope whose t statistic is below this is not told from noise ([`marginal_slopes`]).
pub const SLOPE_T: f64 = 2.0;

/// Each parameter's least-squares slope of `y` (one total per simulated point) on `x` (points
/// x parameters), the change of the total per unit of the parameter to first order: the
/// multiple regression's where the points allow it ([`regression_slopes`]), else each column's
/// own `cov(x_j, y) / var(x_j)` (near the same for a Latin hypercube's near-orthogonal columns); NaN where the parameter does not vary, where the slope's
/// t statistic (against the simple regression's residual variance) is under [`SLOPE_T`] (a
/// parameter with no effect would otherwise get a random one), or where fewer than three
/// points have a finite total.
pub fn marginal_slopes(x: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
    let p = x.first().map_or(0, Vec::len);
    let rows: Vec<(&Vec<f64>, f64)> = (x.iter().zip(y.iter().copied()))
        .filter(|(r, v)| v.is_finite() && r.len() == p && r.iter().all(|a| a.is_finite()))
        .collect();
    if rows.len() < 3 {
        return vec![f64::NAN; p];
    }
    if let Some(b) = regression_slopes(&rows, p) {
        return b;
    }
    let n = rows.len() as f64;
    let y_mean = rows.iter().map(|(_, v)| v).sum::<f64>() / n;
    let syy: f64 = rows.iter().map(|(_, v)| (v - y_mean).powi(2)).sum();
    (0..p)
        .map(|j| {
            let x_mean = rows.iter().map(|(r, _)| r[j]).sum::<f64>() / n;
            let (mut sxy, mut sxx) = (0.0, 0.0);
            for (r, v) in &rows {
                sxy += (r[j] - x_mean) * (v - y_mean);
                sxx += (r[j] - x_mean).powi(2);
            }
            if sxx.is_nan() || sxx <= 0.0 {
                return f64::NAN;
            }
            let b = sxy / sxx;
            // The residual variance of the simple regression, and the slope's standard error.
            let s2 = ((syy - b * sxy) / (n - 2.0)).max(0.0);
            let se = (s2 / sxx).sqrt();
            if se == 0.0 || (b / se).abs() >= SLOPE_T {
                b
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// The multiple least-squares slopes (with an intercept) where the points outnumber the
/// parameters by two or more and the normal equations are positive definite, each NaN where
/// its t statistic is under [`SLOPE_T`]: each slope with the others held, so parameters that
/// the refinement rounds' draws tie together do not borrow each other's effect. `None`
/// otherwise ([`marginal_slopes`] then takes one parameter at a time).
fn regression_slopes(rows: &[(&Vec<f64>, f64)], p: usize) -> Option<Vec<f64>> {
    use faer::linalg::solvers::DenseSolveCore;
    let n = rows.len();
    if p == 0 || n < p + 3 {
        return None;
    }
    let nf = n as f64;
    let x_mean: Vec<f64> = (0..p)
        .map(|j| rows.iter().map(|(r, _)| r[j]).sum::<f64>() / nf)
        .collect();
    let y_mean = rows.iter().map(|(_, v)| v).sum::<f64>() / nf;
    let xtx = faer::Mat::<f64>::from_fn(p, p, |a, b| {
        (rows.iter())
            .map(|(r, _)| (r[a] - x_mean[a]) * (r[b] - x_mean[b]))
            .sum()
    });
    let xty: Vec<f64> = (0..p)
        .map(|a| {
            rows.iter()
                .map(|(r, v)| (r[a] - x_mean[a]) * (v - y_mean))
                .sum()
        })
        .collect();
    let inv = xtx.llt(faer::Side::Lower).ok()?.inverse();
    let b: Vec<f64> = (0..p)
        .map(|a| (0..p).map(|c| inv[(a, c)] * xty[c]).sum())
        .collect();
    let syy: f64 = rows.iter().map(|(_, v)| (v - y_mean).powi(2)).sum();
    let rss = (syy - b.iter().zip(&xty).map(|(bi, t)| bi * t).sum::<f64>()).max(0.0);
    let s2 = rss / (n - p - 1) as f64;
    Some(
        (0..p)
            .map(|j| {
                let se = (s2 * inv[(j, j)]).max(0.0).sqrt();
                if !b[j].is_finite() || (se > 0.0 && (b[j] / se).abs() < SLOPE_T) {
                    f64::NAN
                } else {
                    b[j]
                }
            })
            .collect(),
    )
}

/// How one parameter moves a meter's total toward the meter, to first order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lever {
    /// The parameter's index.
    pub index: usize,
    /// The prior bound toward which it moves the total toward the meter.
    pub bound: f64,
    /// The total's change, kWh, from the parameter's value to that bound (the gap's sign).
    pub moves_kwh: f64,
    /// The value the parameter alone would need to close the gap (beyond `bound` where the
    /// prior cannot).
    pub alone_needs: f64,
}

/// The parameters that move a total toward the meter, largest first: for each, with slope
/// `slopes[j]` ([`marginal_slopes`]) at `values[j]` inside `bounds[j]` (min, max), the total's
/// change from there to the bound on the side that closes `gap` (meter minus model, kWh), and
/// the value that would close it alone. Parameters without a finite slope, or already at
/// that bound, are left out.
pub fn levers(gap: f64, values: &[f64], slopes: &[f64], bounds: &[(f64, f64)]) -> Vec<Lever> {
    let mut out: Vec<Lever> = (0..values.len().min(slopes.len()).min(bounds.len()))
        .filter_map(|j| {
            let (b, x) = (slopes[j], values[j]);
            if !(b.is_finite() && b != 0.0 && x.is_finite() && gap.is_finite()) {
                return None;
            }
            let bound = if b * gap > 0.0 {
                bounds[j].1
            } else {
                bounds[j].0
            };
            let moves_kwh = b * (bound - x);
            (moves_kwh * gap > 0.0).then_some(Lever {
                index: j,
                bound,
                moves_kwh,
                alone_needs: x + gap / b,
            })
        })
        .collect();
    out.sort_by(|a, b| b.moves_kwh.abs().total_cmp(&a.moves_kwh.abs()));
    out
}

/// The bound a posterior median lies against: within [`PILE_SHARE`] of the prior's range
/// from it (None inside, or for a degenerate range). A posterior pressed against a bound
/// says the data want a value the prior does not allow, or that the parameter compensates
/// for something the model lacks.
pub fn piled_at_bound(min: f64, max: f64, median: f64) -> Option<Bound> {
    let range = max - min;
    if range.is_nan() || range <= 0.0 || !median.is_finite() {
        return None;
    }
    if median - min <= PILE_SHARE * range {
        Some(Bound::Lower)
    } else if max - median <= PILE_SHARE * range {
        Some(Bound::Upper)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels(k: usize) -> Vec<String> {
        (0..k).map(|g| g.to_string()).collect()
    }

    #[test]
    fn verdicts_are_named_as_serde_names_them() {
        for v in [Verdict::Reached, Verdict::Level, Verdict::Shape] {
            assert_eq!(serde_json::to_value(v).unwrap(), v.as_str());
        }
    }

    #[test]
    fn partial_fit_tells_a_series_that_follows_the_weather_from_one_that_does_not() {
        // Hours of 4 "weeks": a calendar factor (hour slot, 6 levels) and a weather factor
        // (3 bands) that the calendar does not explain.
        let n = 240;
        let slot: Vec<usize> = (0..n).map(|t| t % 6).collect();
        let band: Vec<usize> = (0..n).map(|t| (t / 7) % 3).collect();
        let base = [FactorGroups {
            group: &slot,
            levels: 6,
        }];
        let extra = [FactorGroups {
            group: &band,
            levels: 3,
        }];
        let calendar = |t: usize| 10.0 + slot[t] as f64;
        let follows: Vec<f64> = (0..n).map(|t| calendar(t) + 5.0 * band[t] as f64).collect();
        let fit = partial_fit(&follows, &base, &extra).unwrap();
        assert!((fit.share - 1.0).abs() < 1e-9, "{fit:?}");
        // The bands' effects are -5, 0, +5 around their mean, in near-equal thirds: RMS ~4.08.
        assert!(
            (fit.explained_rms - (50.0f64 / 3.0).sqrt()).abs() < 0.05,
            "{fit:?}"
        );
        // The same calendar with a noise unrelated to the bands: hardly any share.
        let noise: Vec<f64> = (0..n)
            .map(|t| calendar(t) + if (t * 7919) % 13 < 6 { 1.0 } else { -1.0 })
            .collect();
        let fit = partial_fit(&noise, &base, &extra).unwrap();
        assert!(fit.share < 0.1 && fit.explained_rms < 0.5, "{fit:?}");
        // Half of each: in between; missing hours are left out.
        let mut half: Vec<f64> = (0..n)
            .map(|t| follows[t] + 2.0 * (noise[t] - calendar(t)))
            .collect();
        half[3] = f64::NAN;
        let fit = partial_fit(&half, &base, &extra).unwrap();
        assert!(fit.share > 0.5 && fit.share < 0.99, "{fit:?}");
        // Nothing left after the calendar: 0.
        let flat: Vec<f64> = (0..n).map(calendar).collect();
        let fit = partial_fit(&flat, &base, &extra).unwrap();
        assert_eq!(
            (fit.share, fit.explained_rms, fit.base_rms),
            (0.0, 0.0, 0.0)
        );
        assert!((fit.mean - 12.5).abs() < 1e-12, "{fit:?}");
        // The sizes: the bands' effects around a mean of 17.5.
        let fit = partial_fit(&follows, &base, &extra).unwrap();
        assert!((fit.base_rms - fit.explained_rms).abs() < 1e-9, "{fit:?}");
        assert!(
            (fit.relative_explained() - fit.explained_rms / 17.5).abs() < 0.01,
            "{fit:?}"
        );
    }

    #[test]
    fn reach_judges_level_shape_and_reached() {
        let measured: Vec<f64> = (0..48).map(|t| 10.0 + (t % 24) as f64).collect();
        // 30 % below everywhere: the level is missed; a draw at the meter's total reaches it.
        let low: Vec<f64> = measured.iter().map(|y| 0.7 * y).collect();
        let r = reach(&measured, &low, std::slice::from_ref(&measured)).unwrap();
        assert_eq!(r.verdict, Verdict::Level);
        assert!(r.within_draws);
        assert!((r.estimate_kwh - 0.7 * r.measured_kwh).abs() < 1e-9);
        let r = reach(&measured, &low, std::slice::from_ref(&low)).unwrap();
        assert!(!r.within_draws);
        assert_eq!(r.draws_kwh, [r.estimate_kwh, r.estimate_kwh]);
        // The right level at the wrong hours: the shape is missed.
        let flat = vec![measured.iter().sum::<f64>() / 48.0; 48];
        let mut swapped = measured.clone();
        swapped.rotate_left(12);
        let r = reach(&measured, &swapped, &[flat]).unwrap();
        assert_eq!(r.verdict, Verdict::Shape, "{r:?}");
        // Missing hours are left out of every total.
        let mut gappy = measured.clone();
        gappy[0] = f64::NAN;
        let r = reach(&gappy, &measured, &[]).unwrap();
        assert_eq!((r.hours, r.verdict), (47, Verdict::Reached));
        assert!((r.measured_kwh - r.estimate_kwh).abs() < 1e-9);
        assert!(reach(&measured, &measured, &[vec![1.0; 3]]).is_err());
    }

    #[test]
    fn pattern_means_and_eta_squared_by_hand() {
        // Two groups, residuals 1, 3 | 5, 7: grand mean 4, SS_total 20, SS_between 16.
        let measured = [2.0, 4.0, 6.0, 8.0, f64::NAN];
        let simulated = [1.0; 5];
        let p = pattern(&measured, &simulated, &[0, 0, 1, 1, 1], &labels(3)).unwrap();
        assert!((p.eta_squared - 0.8).abs() < 1e-12);
        assert_eq!(p.groups.len(), 2, "the empty group is left out");
        assert_eq!((p.groups[0].hours, p.groups[0].mean_residual), (2, 2.0));
        assert_eq!((p.groups[1].hours, p.groups[1].mean_residual), (2, 6.0));
        assert_eq!(p.groups[1].mean_measured, 7.0);
        // Residuals that do not depend on the group: eta^2 = 0.
        let p = pattern(&[1.0, 2.0, 1.0, 2.0], &[0.0; 4], &[0, 0, 1, 1], &labels(2)).unwrap();
        assert!(p.eta_squared.abs() < 1e-12);
        assert!(pattern(&[1.0], &[1.0], &[0], &labels(1)).is_err());
        assert!(pattern(&[1.0, 2.0], &[1.0, 1.0], &[0, 5], &labels(2)).is_err());
    }

    #[test]
    fn quantile_bands_split_by_count_and_keep_ties_together() {
        let x: Vec<f64> = (0..100).map(f64::from).collect();
        let (band, labels) = quantile_bands(&x, 4);
        // Upper edges at the quartiles, inclusive.
        assert_eq!(
            labels,
            ["0.0..25.0", "26.0..50.0", "51.0..75.0", "76.0..99.0"]
        );
        assert_eq!((band[0], band[25], band[26], band[99]), (0, 0, 1, 3));
        let ties = [1.0, 1.0, 1.0, 1.0, 2.0, f64::NAN];
        let (band, labels) = quantile_bands(&ties, 4);
        assert_eq!(labels.len(), 2);
        assert_eq!(band, [0, 0, 0, 0, 1, 0]);
    }

    #[test]
    fn slope_of_a_line() {
        let x: Vec<f64> = (0..10).map(f64::from).collect();
        let r: Vec<f64> = x.iter().map(|v| 3.0 - 0.5 * v).collect();
        assert!((slope(&x, &r) + 0.5).abs() < 1e-12);
        assert_eq!(slope(&[1.0, 1.0], &[0.0, 5.0]), 0.0);
    }

    #[test]
    fn additive_discrepancy_recovers_an_additive_misfit() {
        // Residual = 2 + hour effect + temperature-band effect, exactly additive: the fit
        // removes all of it, also at an hour where the meter is missing.
        let n = 24 * 20;
        let hour: Vec<usize> = (0..n).map(|t| t % 24).collect();
        let band: Vec<usize> = (0..n).map(|t| (t / 24) % 3).collect();
        let truth: Vec<f64> = (0..n)
            .map(|t| 2.0 + (hour[t] as f64 - 11.5) * 0.1 + [-1.0, 0.5, 0.5][band[t]])
            .collect();
        let simulated = vec![10.0; n];
        let mut measured: Vec<f64> = truth.iter().map(|d| 10.0 + d).collect();
        measured[30] = f64::NAN;
        let factors = [
            FactorGroups {
                group: &hour,
                levels: 24,
            },
            FactorGroups {
                group: &band,
                levels: 3,
            },
        ];
        let a = additive_discrepancy(&measured, &simulated, &factors).unwrap();
        assert!((a.share - 1.0).abs() < 1e-9, "{}", a.share);
        for (t, (d, want)) in a.delta.iter().zip(&truth).enumerate() {
            assert!((d - want).abs() < 1e-6, "hour {t}");
        }
        // Noise with no structure: little of it is removed.
        let noise: Vec<f64> = (0..n)
            .map(|t| if t % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let a = additive_discrepancy(&noise, &vec![0.0; n], &factors[1..]).unwrap();
        assert!(a.share < 0.01, "{}", a.share);
    }

    #[test]
    fn piled_at_a_bound_within_five_per_cent_of_the_range() {
        assert_eq!(piled_at_bound(0.0, 10.0, 0.4), Some(Bound::Lower));
        assert_eq!(piled_at_bound(0.0, 10.0, 9.6), Some(Bound::Upper));
        assert_eq!(piled_at_bound(0.0, 10.0, 5.0), None);
        assert_eq!(piled_at_bound(1.0, 1.0, 1.0), None);
    }

    #[test]
    fn slopes_of_a_linear_total_over_an_orthogonal_design_are_its_coefficients() {
        // y = 100 + 3 a - 2 b (+ a little noise) over a 3 x 3 grid, c varying without effect.
        let mut x = vec![];
        let mut y = vec![];
        for (i, a) in [0.0, 1.0, 2.0].into_iter().enumerate() {
            for (k, b) in [10.0, 20.0, 30.0].into_iter().enumerate() {
                x.push(vec![a, b, ((i + 2 * k) % 3) as f64]);
                y.push(100.0 + 3.0 * a - 2.0 * b + 0.01 * ((i * 3 + k) % 4) as f64);
            }
        }
        let s = marginal_slopes(&x, &y);
        assert!(
            (s[0] - 3.0).abs() < 0.02 && (s[1] + 2.0).abs() < 0.01,
            "{s:?}"
        );
        assert!(s[2].is_nan(), "no effect, no slope: {s:?}");
        // A constant column: the regression cannot be solved, and that column has no slope.
        let flat: Vec<Vec<f64>> = x.iter().map(|r| vec![r[0], r[1], 5.0]).collect();
        assert!(marginal_slopes(&flat, &y)[2].is_nan());
        assert!(marginal_slopes(&x[..2], &y[..2])[0].is_nan());
    }

    #[test]
    fn levers_move_the_total_toward_the_meter_largest_first() {
        // The meter is 50 kWh above the model. a (slope 3, at 1 in [0, 2]) moves +3 toward
        // its max and alone would need 1 + 50 / 3; b (slope -2, at 20 in [10, 30]) moves +20
        // toward its min; c does not vary.
        let l = levers(
            50.0,
            &[1.0, 20.0, 5.0],
            &[3.0, -2.0, f64::NAN],
            &[(0.0, 2.0), (10.0, 30.0), (0.0, 10.0)],
        );
        assert_eq!(l.len(), 2);
        assert_eq!((l[0].index, l[0].bound, l[0].moves_kwh), (1, 10.0, 20.0));
        assert_eq!((l[1].index, l[1].bound, l[1].moves_kwh), (0, 2.0, 3.0));
        assert!((l[1].alone_needs - (1.0 + 50.0 / 3.0)).abs() < 1e-12);
        assert_eq!(l[0].alone_needs, -5.0);
        // Already at the bound that would help: no lever.
        assert!(levers(50.0, &[2.0], &[3.0], &[(0.0, 2.0)]).is_empty());
    }
}
