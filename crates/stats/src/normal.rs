//! The standard normal distribution: its CDF and quantile function (inverse CDF).

/// Standard normal CDF, through `erfc` (no cancellation in the lower tail).
pub(crate) fn norm_cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z / std::f64::consts::SQRT_2)
}

/// Standard normal quantile, Wichura's algorithm AS 241 (PPND16, Applied Statistics 37, 1988),
/// relative accuracy about 1e-16. Returns -inf / +inf at 0 / 1 and NaN outside [0, 1].
// The published AS 241 coefficients are kept verbatim.
#[allow(clippy::excessive_precision)]
pub(crate) fn norm_ppf(p: f64) -> f64 {
    if p.is_nan() || !(0.0..=1.0).contains(&p) {
        return f64::NAN;
    }
    if p == 0.0 {
        return f64::NEG_INFINITY;
    }
    if p == 1.0 {
        return f64::INFINITY;
    }
    let q = p - 0.5;
    if q.abs() <= 0.425 {
        let r = 0.180625 - q * q;
        return q
            * (((((((r * 2509.0809287301227 + 33430.575583588128) * r + 67265.770927008700)
                * r
                + 45921.953931549871)
                * r
                + 13731.693765509461)
                * r
                + 1971.5909503065513)
                * r
                + 133.14166789178438)
                * r
                + 3.3871328727963665)
            / (((((((r * 5226.4952788525454 + 28729.085735721942) * r + 39307.895800092710)
                * r
                + 21213.794301586595)
                * r
                + 5394.1960214247511)
                * r
                + 687.18700749205791)
                * r
                + 42.313330701600911)
                * r
                + 1.0);
    }
    let mut r = if q < 0.0 { p } else { 1.0 - p };
    r = (-r.ln()).sqrt();
    let val = if r <= 5.0 {
        let r = r - 1.6;
        (((((((r * 7.7454501427834141e-4 + 0.022723844989269184) * r + 0.24178072517745061) * r
            + 1.2704582524523684)
            * r
            + 3.6478483247632045)
            * r
            + 5.7694972214606914)
            * r
            + 4.6303378461565453)
            * r
            + 1.4234371107496835)
            / (((((((r * 1.0507500716444169e-9 + 5.4759380849953449e-4) * r
                + 0.015198666563616457)
                * r
                + 0.14810397642748007)
                * r
                + 0.68976733498510005)
                * r
                + 1.6763848301838038)
                * r
                + 2.0531916266377588)
                * r
                + 1.0)
    } else {
        let r = r - 5.0;
        (((((((r * 2.0103343992922881e-7 + 2.7115555687434876e-5) * r + 0.0012426609473880784)
            * r
            + 0.026532189526576123)
            * r
            + 0.29656057182850489)
            * r
            + 1.7848265399172913)
            * r
            + 5.4637849111641144)
            * r
            + 6.6579046435011038)
            / (((((((r * 2.0442631033899397e-15 + 1.421511758316446e-7) * r
                + 1.8463183175100547e-5)
                * r
                + 7.8686913114561326e-4)
                * r
                + 0.014875361290850615)
                * r
                + 0.1369298809227358)
                * r
                + 0.5998322065558879)
                * r
                + 1.0)
    };
    if q < 0.0 {
        -val
    } else {
        val
    }
}

#[cfg(test)]
mod tests {
    use super::norm_ppf;

    #[test]
    fn known_quantiles() {
        // Values from scipy.stats.norm.ppf.
        assert!((norm_ppf(0.5)).abs() < 1e-15);
        assert!((norm_ppf(0.975) - 1.959963984540054).abs() < 1e-14);
        assert!((norm_ppf(0.05) + 1.6448536269514722).abs() < 1e-14);
        assert!((norm_ppf(1e-10) + 6.361340902404056).abs() < 1e-12);
        assert!(norm_ppf(0.0).is_infinite() && norm_ppf(1.0).is_infinite());
        assert!(norm_ppf(1.5).is_nan());
    }
}
