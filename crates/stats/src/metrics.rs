//! ASHRAE Guideline 14 goodness-of-fit of a calibrated model (reference Eqs. 7 and 8 of
//! Section 2.3.4), with `p = 1`:
//!
//! - `CV-RMSE = sqrt( sum_i (y_i - yhat_i)^2 / (n - p) ) / ybar * 100`
//! - `NMBE = sum_i (y_i - yhat_i) / ((n - p) ybar) * 100`
//!
//! `y` measured, `yhat` simulated, residual = measured - simulated (positive NMBE: the model
//! underestimates), `ybar` the mean of the measured values, `n` the hours where both are
//! present. Hours where either value is NaN (or not finite) are excluded. Hourly calibration
//! criteria: `|NMBE| <= 10 %` and `CV-RMSE <= 30 %`.

use serde::{Deserialize, Serialize};

use crate::error::{Result, StatsError};

/// Number of adjustable model parameters `p` in the Guideline 14 denominators.
pub const P: usize = 1;
/// Hourly NMBE criterion, per cent (absolute value).
pub const HOURLY_NMBE_LIMIT: f64 = 10.0;
/// Hourly CV-RMSE criterion, per cent.
pub const HOURLY_CV_RMSE_LIMIT: f64 = 30.0;
/// Monthly NMBE criterion, per cent (absolute value).
pub const MONTHLY_NMBE_LIMIT: f64 = 5.0;
/// Monthly CV-RMSE criterion, per cent.
pub const MONTHLY_CV_RMSE_LIMIT: f64 = 15.0;

/// Guideline 14 metrics of one output.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct G14Metrics {
    /// Hours used (both values present).
    pub n: usize,
    /// Mean of the measured values over those hours.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub mean_measured: f64,
    /// NMBE, per cent.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub nmbe: f64,
    /// CV-RMSE, per cent.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub cv_rmse: f64,
    /// Whether both hourly criteria are met.
    pub pass: bool,
}

impl G14Metrics {
    /// How near the hourly criteria these metrics are: the larger of `|NMBE| / 10 %` and
    /// `CV-RMSE / 30 %`, so at most 1 exactly when both hourly criteria are met; infinite
    /// when either is not a number.
    pub fn hourly_limit_ratio(&self) -> f64 {
        self.limit_ratio(HOURLY_NMBE_LIMIT, HOURLY_CV_RMSE_LIMIT)
    }

    /// [`Self::hourly_limit_ratio`] for metrics of monthly totals ([`g14_monthly`]): the
    /// larger of `|NMBE| / 5 %` and `CV-RMSE / 15 %`.
    pub fn monthly_limit_ratio(&self) -> f64 {
        self.limit_ratio(MONTHLY_NMBE_LIMIT, MONTHLY_CV_RMSE_LIMIT)
    }

    /// The larger of `|NMBE| / nmbe_limit` and `CV-RMSE / cv_limit`; infinite when either is
    /// not a number.
    fn limit_ratio(&self, nmbe_limit: f64, cv_limit: f64) -> f64 {
        let r = (self.nmbe.abs() / nmbe_limit, self.cv_rmse / cv_limit);
        if r.0.is_nan() || r.1.is_nan() {
            return f64::INFINITY;
        }
        r.0.max(r.1)
    }
}

/// NMBE and CV-RMSE of simulated against measured hourly values; NaN marks a missing hour.
/// Errors if the lengths differ, fewer than `p + 1` hours are usable, or the measured mean
/// is zero.
pub fn g14(measured: &[f64], simulated: &[f64]) -> Result<G14Metrics> {
    if measured.len() != simulated.len() {
        return Err(StatsError::Shape(format!(
            "{} measured but {} simulated values",
            measured.len(),
            simulated.len()
        )));
    }
    let (mut n, mut sum_y, mut sum_r, mut sum_r2) = (0usize, 0.0, 0.0, 0.0);
    for (&y, &s) in measured.iter().zip(simulated) {
        if y.is_finite() && s.is_finite() {
            let r = y - s;
            n += 1;
            sum_y += y;
            sum_r += r;
            sum_r2 += r * r;
        }
    }
    from_sums(n, sum_y, sum_r, sum_r2)
}

/// The hourly metrics of `n` hours from their sums: measured values, residuals and squared
/// residuals (the definitions above).
fn from_sums(n: usize, sum_y: f64, sum_r: f64, sum_r2: f64) -> Result<G14Metrics> {
    if n <= P {
        return Err(StatsError::NotEnoughData(format!(
            "{n} hours with both measured and simulated values; need more than {P}"
        )));
    }
    let ybar = sum_y / n as f64;
    if ybar == 0.0 {
        return Err(StatsError::Invalid(
            "mean of the measured values is zero; NMBE and CV-RMSE are undefined".into(),
        ));
    }
    let dof = (n - P) as f64;
    let nmbe = sum_r / (dof * ybar) * 100.0;
    let cv_rmse = (sum_r2 / dof).sqrt() / ybar * 100.0;
    Ok(G14Metrics {
        n,
        mean_measured: ybar,
        nmbe,
        cv_rmse,
        pass: nmbe.abs() <= HOURLY_NMBE_LIMIT && cv_rmse <= HOURLY_CV_RMSE_LIMIT,
    })
}

/// Monthly Guideline 14: the same NMBE and CV-RMSE on monthly totals (`n` = months, `p` = 1),
/// criteria `|NMBE| <= 5 %` and `CV-RMSE <= 15 %`. `months[h]` is the calendar month of hour
/// `h`; a month's totals sum the hours where both values are present, so a missing hour drops
/// out of the measured and the simulated total alike.
pub fn g14_monthly(measured: &[f64], simulated: &[f64], months: &[u32]) -> Result<G14Metrics> {
    if measured.len() != simulated.len() || months.len() != measured.len() {
        return Err(StatsError::Shape(format!(
            "{} measured, {} simulated values and {} months",
            measured.len(),
            simulated.len(),
            months.len()
        )));
    }
    let mut totals: std::collections::BTreeMap<u32, (f64, f64)> = Default::default();
    for ((&y, &s), &m) in measured.iter().zip(simulated).zip(months) {
        if y.is_finite() && s.is_finite() {
            let t = totals.entry(m).or_default();
            t.0 += y;
            t.1 += s;
        }
    }
    let (y, s): (Vec<f64>, Vec<f64>) = totals.into_values().unzip();
    g14_totals(&y, &s)
}

/// Guideline 14 of totals over periods of about a month (monthly totals, utility bills): the
/// same NMBE and CV-RMSE (`n` = periods, `p` = 1), judged by the monthly criteria
/// (`|NMBE| <= 5 %`, `CV-RMSE <= 15 %`).
pub fn g14_totals(measured: &[f64], simulated: &[f64]) -> Result<G14Metrics> {
    let m = g14(measured, simulated)?;
    Ok(G14Metrics {
        pass: m.nmbe.abs() <= MONTHLY_NMBE_LIMIT && m.cv_rmse <= MONTHLY_CV_RMSE_LIMIT,
        ..m
    })
}

/// The sums behind a set of hours' metrics: (measured total, residual total, sum of squared
/// residuals), recovered exactly from `n`, `ybar`, NMBE and CV-RMSE (the definitions above).
fn sums(m: &G14Metrics) -> (f64, f64, f64) {
    let dof = (m.n - P) as f64;
    let sum_y = m.n as f64 * m.mean_measured;
    let sum_r = m.nmbe / 100.0 * dof * m.mean_measured;
    let sum_r2 = (m.cv_rmse / 100.0 * m.mean_measured).powi(2) * dof;
    (sum_y, sum_r, sum_r2)
}

/// Hourly Guideline 14 over the union of disjoint sets of hours, from each set's metrics: the
/// same figures [`g14`] gives on the hours pooled (cross-validation: each month judged by the
/// model that did not fit it, all months together).
pub fn g14_pooled(parts: &[G14Metrics]) -> Result<G14Metrics> {
    let (mut n, mut sum_y, mut sum_r, mut sum_r2) = (0usize, 0.0, 0.0, 0.0);
    for m in parts {
        let (y, r, r2) = sums(m);
        n += m.n;
        sum_y += y;
        sum_r += r;
        sum_r2 += r2;
    }
    from_sums(n, sum_y, sum_r, sum_r2)
}

/// Guideline 14 of totals, one per set of hours (a held-out month each): each set's measured
/// and residual totals, from its hourly metrics, are one point, judged by the monthly criteria
/// as [`g14_monthly`] judges months (the same figures when each set is one month's measured
/// hours).
pub fn g14_of_totals(parts: &[G14Metrics]) -> Result<G14Metrics> {
    let totals: Vec<(f64, f64)> = parts
        .iter()
        .map(|m| {
            let (y, r, _) = sums(m);
            (y, y - r)
        })
        .collect();
    let y: Vec<f64> = totals.iter().map(|t| t.0).collect();
    let s: Vec<f64> = totals.iter().map(|t| t.1).collect();
    g14_totals(&y, &s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed() {
        // y = [10, 12, 8, 10], yhat = [9, 12, 10, 11]: r = [1, 0, -2, -1], n = 4, ybar = 10.
        // NMBE = -2 / (3 * 10) * 100 = -6.666..%; CV-RMSE = sqrt(6 / 3) / 10 * 100 = 14.142..%.
        let m = g14(&[10.0, 12.0, 8.0, 10.0], &[9.0, 12.0, 10.0, 11.0]).unwrap();
        assert_eq!(m.n, 4);
        assert!((m.nmbe + 200.0 / 30.0).abs() < 1e-12);
        assert!((m.cv_rmse - 2f64.sqrt() * 10.0).abs() < 1e-12);
        assert!(m.pass);
    }

    #[test]
    fn missing_hours_excluded() {
        // Hours 1 (measured missing) and 3 (simulated missing) dropped:
        // y = [4, 6, 2], yhat = [5, 3, 2]: r = [-1, 3, 0], n = 3, ybar = 4.
        // NMBE = 2 / (2 * 4) * 100 = 25 %; CV-RMSE = sqrt(10 / 2) / 4 * 100 = 55.90..%.
        let y = [4.0, f64::NAN, 6.0, 7.0, 2.0];
        let s = [5.0, 1.0, 3.0, f64::NAN, 2.0];
        let m = g14(&y, &s).unwrap();
        assert_eq!(m.n, 3);
        assert!((m.nmbe - 25.0).abs() < 1e-12);
        assert!((m.cv_rmse - 5f64.sqrt() * 25.0).abs() < 1e-12);
        assert!(!m.pass);
    }

    #[test]
    fn monthly_totals_hand_computed() {
        // Two hours in each of three months: totals y = [10, 20, 30], yhat = [11, 18, 30]:
        // r = [-1, 2, 0], n = 3, ybar = 20: NMBE = 1 / (2 * 20) * 100 = 2.5 %,
        // CV-RMSE = sqrt(5 / 2) / 20 * 100 = 7.9057 %. A missing hour drops from both totals.
        let y = [4.0, 6.0, 10.0, 10.0, 15.0, 15.0, f64::NAN];
        let s = [5.0, 6.0, 9.0, 9.0, 15.0, 15.0, 100.0];
        let m = g14_monthly(&y, &s, &[1, 1, 2, 2, 3, 3, 3]).unwrap();
        assert_eq!(m.n, 3);
        assert!((m.nmbe - 2.5).abs() < 1e-12);
        assert!((m.cv_rmse - 2.5f64.sqrt() * 5.0).abs() < 1e-12);
        assert!(m.pass);
        // 6 % bias passes hourly but not monthly.
        let m = g14_monthly(&[10.0; 3], &[9.4; 3], &[1, 2, 3]).unwrap();
        assert!(!m.pass && g14(&[10.0; 3], &[9.4; 3]).unwrap().pass);
        assert!(g14_monthly(&[1.0], &[1.0], &[]).is_err());
    }

    #[test]
    fn criteria_boundaries_and_errors() {
        // r = [1, -1] around ybar = 10 with p = 1: NMBE 0, CV-RMSE sqrt(2)/10*100 = 14.1 %.
        assert!(g14(&[10.0, 10.0], &[9.0, 11.0]).unwrap().pass);
        // Bias 1 over ybar 10 with n = 11: NMBE = 11 / (10 * 10) * 100 = 11 % > 10 %.
        let m = g14(&[10.0; 11], &[9.0; 11]).unwrap();
        assert!((m.nmbe - 11.0).abs() < 1e-12 && !m.pass);
        assert!(g14(&[1.0], &[1.0]).is_err());
        assert!(g14(&[1.0, 2.0], &[1.0]).is_err());
        assert!(g14(&[1.0, -1.0], &[0.0, 0.0]).is_err());
        assert!(g14(&[f64::NAN, 1.0, 2.0], &[1.0, f64::NAN, 2.0]).is_err());
    }

    #[test]
    fn pooled_sets_give_the_metrics_of_all_their_hours() {
        let y: Vec<f64> = (0..48)
            .map(|h| 10.0 + (h as f64 * 0.7).sin() * 3.0)
            .collect();
        let s: Vec<f64> = (0..48)
            .map(|h| 9.5 + (h as f64 * 0.9).cos() * 2.0)
            .collect();
        let parts = [
            g14(&y[..20], &s[..20]).unwrap(),
            g14(&y[20..], &s[20..]).unwrap(),
        ];
        let all = g14(&y, &s).unwrap();
        let pooled = g14_pooled(&parts).unwrap();
        assert_eq!(pooled.n, 48);
        assert!((pooled.mean_measured - all.mean_measured).abs() < 1e-12);
        assert!((pooled.nmbe - all.nmbe).abs() < 1e-9);
        assert!((pooled.cv_rmse - all.cv_rmse).abs() < 1e-9);
        // Each set a month: the totals' metrics are the monthly metrics of all the hours.
        let months: Vec<u32> = (0..48).map(|h| if h < 20 { 1 } else { 2 }).collect();
        let monthly = g14_monthly(&y, &s, &months).unwrap();
        let totals = g14_of_totals(&parts).unwrap();
        assert_eq!(totals.n, 2);
        assert!((totals.nmbe - monthly.nmbe).abs() < 1e-9);
        assert!((totals.cv_rmse - monthly.cv_rmse).abs() < 1e-9);
        assert_eq!(totals.pass, monthly.pass);
        assert!(g14_pooled(&[]).is_err());
    }

    #[test]
    fn the_hourly_limit_ratio_is_the_nearer_criterion_and_one_at_the_limit() {
        let m = |nmbe: f64, cv_rmse: f64| G14Metrics {
            n: 8760,
            mean_measured: 1.0,
            nmbe,
            cv_rmse,
            pass: nmbe.abs() <= HOURLY_NMBE_LIMIT && cv_rmse <= HOURLY_CV_RMSE_LIMIT,
        };
        assert_eq!(m(-5.0, 9.0).hourly_limit_ratio(), 0.5);
        assert_eq!(m(2.0, 15.0).hourly_limit_ratio(), 0.5);
        assert_eq!(m(10.0, 30.0).hourly_limit_ratio(), 1.0);
        for (nmbe, cv) in [(-12.0, 20.0), (3.0, 31.0), (0.0, 50.0)] {
            assert!(m(nmbe, cv).hourly_limit_ratio() > 1.0 && !m(nmbe, cv).pass);
        }
        assert_eq!(m(f64::NAN, 1.0).hourly_limit_ratio(), f64::INFINITY);
        // Monthly totals: half the hourly limits.
        assert_eq!(m(-2.5, 4.5).monthly_limit_ratio(), 0.5);
        assert_eq!(m(5.0, 15.0).monthly_limit_ratio(), 1.0);
        assert_eq!(m(6.0, 9.0).monthly_limit_ratio(), 1.2);
    }
}
