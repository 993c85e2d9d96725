//! Small order statistics used throughout (NaN-aware, on slices).
//!
//! Quantiles use linear interpolation between order statistics (Hyndman & Fan type 7, the
//! default of numpy and R): for sorted `x[0..n]`, `q(p) = x[f] + (x[f+1] - x[f]) * (h - f)` with
//! `h = (n - 1) p`, `f = floor(h)`.

/// Quantile `p` in [0, 1] of the finite values of `values`; `NaN` if there are none.
pub fn quantile(values: &[f64], p: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    quantile_sorted(&v, p)
}

/// Quantile `p` of an already sorted slice of finite values; `NaN` if empty.
pub fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    let n = sorted.len();
    if n == 0 {
        return f64::NAN;
    }
    let h = (n - 1) as f64 * p.clamp(0.0, 1.0);
    let f = h.floor() as usize;
    if f + 1 >= n {
        return sorted[n - 1];
    }
    sorted[f] + (sorted[f + 1] - sorted[f]) * (h - f as f64)
}

/// Median of the finite values (`NaN` if none).
pub fn median(values: &[f64]) -> f64 {
    quantile(values, 0.5)
}

/// Mean of the finite values (`NaN` if none).
pub fn mean(values: &[f64]) -> f64 {
    let (s, n) = values
        .iter()
        .filter(|x| x.is_finite())
        .fold((0.0, 0usize), |(s, n), &x| (s + x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        s / n as f64
    }
}

/// Box-plot quartiles (Q1, median, Q3) of the finite values.
pub fn quartiles(values: &[f64]) -> (f64, f64, f64) {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    (
        quantile_sorted(&v, 0.25),
        quantile_sorted(&v, 0.5),
        quantile_sorted(&v, 0.75),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type7_quantiles() {
        let v = [4.0, 1.0, 3.0, 2.0, f64::NAN];
        assert_eq!(median(&v), 2.5);
        assert_eq!(quartiles(&v), (1.75, 2.5, 3.25));
        assert_eq!(quantile(&v, 1.0), 4.0);
        assert!(quantile(&[f64::NAN], 0.5).is_nan());
        assert_eq!(mean(&v), 2.5);
    }
}
