//! Posterior summaries of a calibration: per parameter mean, median, 90 % interval, MAP draw,
//! R-hat and ESS, the posterior-to-prior width ratio, strongly correlated pairs, and hourly
//! posterior predictive bands.

use serde::{Deserialize, Serialize};

use crate::diagnostics::{self, quantile_sorted};
use crate::error::{Result, StatsError};
use crate::mcmc::Draws;
use crate::prior::Prior;

/// Threshold of `|rho|` above which a pair of parameters is flagged as strongly correlated.
pub const STRONG_CORRELATION: f64 = 0.8;

/// Summary of one parameter (physical units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ParameterSummary {
    /// Parameter name.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Posterior mean.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub mean: f64,
    /// Posterior standard deviation (`ddof = 1`).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub sd: f64,
    /// Posterior median.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub median: f64,
    /// 5 % quantile.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub q5: f64,
    /// 95 % quantile.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub q95: f64,
    /// Value at the MAP draw (highest log posterior among the draws).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub map: f64,
    /// Rank-normalised split R-hat.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub rhat: f64,
    /// Bulk ESS.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub ess_bulk: f64,
    /// Tail ESS.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub ess_tail: f64,
    /// Posterior 90 % interval width / prior 90 % interval width.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub width_ratio: f64,
}

/// A pair of strongly correlated parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct CorrelatedPair {
    /// First parameter.
    pub a: String,
    /// Second parameter.
    pub b: String,
    /// Pearson correlation over all draws.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub rho: f64,
}

/// Posterior summary of all parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PosteriorSummary {
    /// One entry per parameter, in prior order.
    pub parameters: Vec<ParameterSummary>,
    /// The MAP draw (physical units).
    pub map_point: Vec<f64>,
    /// Its log posterior.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub map_log_density: f64,
    /// Pairs with `|rho| > 0.8`.
    pub correlated_pairs: Vec<CorrelatedPair>,
    /// Largest R-hat over parameters.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub max_rhat: f64,
    /// Smallest bulk ESS over parameters.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub min_ess_bulk: f64,
    /// Where the chains settled in different modes, which chains and what separates them
    /// ([`crate::modes::chain_modes`]); absent where they share one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modes: Option<crate::modes::ChainModes>,
}

/// Summarise chains of unit-space draws (as [`crate::mcmc`] records them) against their
/// priors. All chains must have the same number of draws (at least one).
pub fn summarize(priors: &[Prior], chains: &[Draws]) -> Result<PosteriorSummary> {
    let d = priors.len();
    if chains.is_empty() || chains[0].is_empty() {
        return Err(StatsError::NotEnoughData("no draws".into()));
    }
    if let Some(c) = chains.iter().find(|c| c.dim != d) {
        return Err(StatsError::Shape(format!(
            "draws of dimension {} for {d} parameters",
            c.dim
        )));
    }
    // MAP draw over all chains.
    let (mut best_c, mut best_i, mut best_lp) = (0, 0, f64::NEG_INFINITY);
    for (c, ch) in chains.iter().enumerate() {
        for (i, &lp) in ch.log_density.iter().enumerate() {
            if lp > best_lp {
                (best_c, best_i, best_lp) = (c, i, lp);
            }
        }
    }
    let map_unit = chains[best_c].point(best_i);
    let map_point: Vec<f64> = priors
        .iter()
        .zip(map_unit)
        .map(|(p, &u)| p.dist.from_unit(u))
        .collect();

    let physical: Vec<Vec<Vec<f64>>> = (0..d)
        .map(|j| {
            chains
                .iter()
                .map(|ch| {
                    ch.column(j)
                        .into_iter()
                        .map(|u| priors[j].dist.from_unit(u))
                        .collect()
                })
                .collect()
        })
        .collect();
    let mut parameters = Vec::with_capacity(d);
    for (j, p) in priors.iter().enumerate() {
        let diag = diagnostics::diagnose(&physical[j])?;
        let prior_width = p.dist.quantile(0.95) - p.dist.quantile(0.05);
        parameters.push(ParameterSummary {
            name: p.name.clone(),
            unit: p.unit.clone(),
            mean: diag.mean,
            sd: diag.sd,
            median: diag.q50,
            q5: diag.q5,
            q95: diag.q95,
            map: map_point[j],
            rhat: diag.rhat,
            ess_bulk: diag.ess_bulk,
            ess_tail: diag.ess_tail,
            width_ratio: (diag.q95 - diag.q5) / prior_width,
        });
    }
    let flat: Vec<Vec<f64>> = physical
        .iter()
        .map(|cs| cs.iter().flatten().copied().collect())
        .collect();
    let mut correlated_pairs = Vec::new();
    for a in 0..d {
        for b in a + 1..d {
            let rho = correlation(&flat[a], &flat[b]);
            if rho.abs() > STRONG_CORRELATION {
                correlated_pairs.push(CorrelatedPair {
                    a: priors[a].name.clone(),
                    b: priors[b].name.clone(),
                    rho,
                });
            }
        }
    }
    let max_rhat = parameters.iter().map(|p| p.rhat).fold(f64::NAN, f64::max);
    let min_ess_bulk = parameters
        .iter()
        .map(|p| p.ess_bulk)
        .fold(f64::NAN, f64::min);
    let log_density: Vec<Vec<f64>> = chains.iter().map(|c| c.log_density.clone()).collect();
    Ok(PosteriorSummary {
        parameters,
        map_point,
        map_log_density: best_lp,
        correlated_pairs,
        max_rhat,
        min_ess_bulk,
        modes: crate::modes::chain_modes(&physical, &log_density),
    })
}

/// Pearson correlation of two equally long series (NaN if either is constant).
pub fn correlation(x: &[f64], y: &[f64]) -> f64 {
    let (sxx, syy, sxy) = centred_sums(x, y);
    sxy / (sxx * syy).sqrt()
}

/// The centred sums of squares and products of two equally long series: `(sum (x - mean
/// x)^2, sum (y - mean y)^2, sum (x - mean x)(y - mean y))`, their covariance matrix times n.
pub fn centred_sums(x: &[f64], y: &[f64]) -> (f64, f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    (sxx, syy, sxy)
}

/// Hourly posterior predictive bands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PredictiveBands {
    /// 5 % quantile per hour.
    pub q5: Vec<f64>,
    /// Median per hour.
    pub q50: Vec<f64>,
    /// 95 % quantile per hour.
    pub q95: Vec<f64>,
}

/// 5 / 50 / 95 % bands per hour of predicted series, `predicted` row-major `draws x hours`
/// (numpy linear-interpolation quantiles; NaN predictions are skipped, an hour with none is
/// NaN).
pub fn predictive_bands(
    predicted: &[f32],
    n_draws: usize,
    n_hours: usize,
) -> Result<PredictiveBands> {
    if predicted.len() != n_draws * n_hours || n_draws == 0 {
        return Err(StatsError::Shape(format!(
            "{} predictions for {n_draws} draws x {n_hours} hours",
            predicted.len()
        )));
    }
    let mut bands = PredictiveBands {
        q5: Vec::with_capacity(n_hours),
        q50: Vec::with_capacity(n_hours),
        q95: Vec::with_capacity(n_hours),
    };
    let mut col = Vec::with_capacity(n_draws);
    for h in 0..n_hours {
        col.clear();
        col.extend(
            (0..n_draws)
                .map(|i| predicted[i * n_hours + h] as f64)
                .filter(|v| !v.is_nan()),
        );
        col.sort_by(f64::total_cmp);
        bands.q5.push(quantile_sorted(&col, 0.05));
        bands.q50.push(quantile_sorted(&col, 0.5));
        bands.q95.push(quantile_sorted(&col, 0.95));
    }
    Ok(bands)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prior::Triangular;

    #[test]
    fn summary_of_known_draws() {
        let priors = vec![
            Prior::new("a", "W/m2", Triangular::new(0.0, 5.0, 10.0).unwrap()),
            Prior::new("b", "C", Triangular::new(20.0, 22.0, 24.0).unwrap()),
            Prior::new("c", "-", Triangular::new(0.0, 0.5, 1.0).unwrap()),
        ];
        // Two chains, 50 draws; b is a linear function of a (rho = 1), c alternates.
        let mut chains = Vec::new();
        for ch in 0..2 {
            let mut d = Draws::new(3);
            for i in 0..50 {
                let u = 0.4 + 0.004 * ((i * 7 + ch * 3) % 50) as f64;
                let c = if i % 2 == 0 { 0.3 } else { 0.7 };
                d.points.extend_from_slice(&[u, u, c]);
                d.log_density.push(-(u - 0.5) * (u - 0.5));
            }
            chains.push(d);
        }
        let s = summarize(&priors, &chains).unwrap();
        assert_eq!(s.correlated_pairs.len(), 1);
        assert_eq!(
            (
                s.correlated_pairs[0].a.as_str(),
                s.correlated_pairs[0].b.as_str()
            ),
            ("a", "b")
        );
        assert!((s.correlated_pairs[0].rho - 1.0).abs() < 1e-12);
        // MAP: u closest to 0.5 -> a = 5, b = 22.
        assert!((s.map_point[0] - 5.0).abs() < 1e-12 && (s.map_point[1] - 22.0).abs() < 1e-12);
        let a = &s.parameters[0];
        assert!(
            (a.median
                - diagnostics::quantile(
                    &chains
                        .iter()
                        .flat_map(|c| c.column(0))
                        .map(|u| 10.0 * u)
                        .collect::<Vec<_>>(),
                    0.5
                ))
            .abs()
                < 1e-12
        );
        // Prior 90 % width of T(0, 5, 10): 2 (10 - sqrt(0.05 * 50)).
        let prior_w = 2.0 * (10.0 - (0.05f64 * 50.0).sqrt()) - 10.0;
        assert!((a.width_ratio - (a.q95 - a.q5) / prior_w).abs() < 1e-12);
        assert!(s.max_rhat.is_finite());
    }

    #[test]
    fn bands_per_hour() {
        // 5 draws x 2 hours; hour 0 = 1..5, hour 1 = 10, 20, NaN, 30, 40.
        let p = [1.0f32, 10.0, 2.0, 20.0, 3.0, f32::NAN, 4.0, 30.0, 5.0, 40.0];
        let b = predictive_bands(&p, 5, 2).unwrap();
        // np.quantile([1..5], [.05, .5, .95]) = [1.2, 3, 4.8]; [10, 20, 30, 40] -> [11.5, 25, 38.5].
        assert!((b.q5[0] - 1.2).abs() < 1e-12 && b.q50[0] == 3.0 && (b.q95[0] - 4.8).abs() < 1e-12);
        assert!(
            (b.q5[1] - 11.5).abs() < 1e-12 && b.q50[1] == 25.0 && (b.q95[1] - 38.5).abs() < 1e-12
        );
        assert!(predictive_bands(&p, 3, 2).is_err());
    }
}
