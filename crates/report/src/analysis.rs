//! Small pure computations behind the figures: densities, ranks, daily aggregation, gaps and
//! the weeks shown at full resolution.

/// Density of the triangular distribution `(min, mode, max)` at `x`.
pub fn triangular_pdf(min: f64, mode: f64, max: f64, x: f64) -> f64 {
    if max.is_nan() || min.is_nan() || max <= min || x < min || x > max {
        return 0.0;
    }
    let h = 2.0 / (max - min);
    if x < mode {
        if mode > min {
            h * (x - min) / (mode - min)
        } else {
            h
        }
    } else if max > mode {
        h * (max - x) / (max - mode)
    } else {
        h
    }
}

/// Quantile `p` of the triangular distribution `(min, mode, max)`.
pub fn triangular_quantile(min: f64, mode: f64, max: f64, p: f64) -> f64 {
    if max.is_nan() || min.is_nan() || max <= min {
        return min;
    }
    let p = p.clamp(0.0, 1.0);
    let fc = (mode - min) / (max - min);
    if p < fc {
        min + (p * (max - min) * (mode - min)).sqrt()
    } else {
        max - ((1.0 - p) * (max - min) * (max - mode)).sqrt()
    }
}

/// CDF of the triangular distribution `(min, mode, max)` at `x` (as `bemcal_stats::prior::
/// Triangular::cdf`: this crate reads output folders and does not depend on the sampler's).
pub fn triangular_cdf(min: f64, mode: f64, max: f64, x: f64) -> f64 {
    if x.is_nan() || min.is_nan() || max.is_nan() || max <= min {
        return f64::NAN;
    }
    if x <= min {
        0.0
    } else if x >= max {
        1.0
    } else if x <= mode {
        (x - min).powi(2) / ((max - min) * (mode - min))
    } else {
        1.0 - (max - x).powi(2) / ((max - min) * (max - mode))
    }
}

/// Quantile `q` in [0, 1] of the finite values of `values` by the calibration's one rule,
/// [`bemcal_stats::diagnostics::quantile`] (numpy's linear interpolation); NaN if there are
/// none, or for `q` outside [0, 1].
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let finite: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    bemcal_stats::diagnostics::quantile(&finite, q)
}

/// Histogram of `values` on `bins` equal bins over `[lo, hi]`, normalised to a density
/// (area 1 over the values inside). Returns `(left edge, right edge, density)` per bin.
pub fn density_histogram(values: &[f64], lo: f64, hi: f64, bins: usize) -> Vec<(f64, f64, f64)> {
    if hi.is_nan() || lo.is_nan() || hi <= lo || bins == 0 {
        return vec![];
    }
    let w = (hi - lo) / bins as f64;
    let mut counts = vec![0usize; bins];
    let mut n = 0usize;
    for &x in values {
        if x.is_finite() && x >= lo && x <= hi {
            let k = (((x - lo) / w) as usize).min(bins - 1);
            counts[k] += 1;
            n += 1;
        }
    }
    (0..bins)
        .map(|k| {
            let d = if n > 0 {
                counts[k] as f64 / (n as f64 * w)
            } else {
                0.0
            };
            (lo + k as f64 * w, lo + (k + 1) as f64 * w, d)
        })
        .collect()
}

/// Gaussian kernel density estimate (Silverman's bandwidth) at `grid`. At most 4,000 values
/// are used (evenly thinned).
pub fn kde(values: &[f64], grid: &[f64]) -> Vec<f64> {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.len() < 2 {
        return vec![0.0; grid.len()];
    }
    let step = v.len().div_ceil(4000);
    let v: Vec<f64> = v.iter().step_by(step).copied().collect();
    let n = v.len() as f64;
    let sd = bemcal_stats::diagnostics::sd(&v);
    let iqr = quantile(&v, 0.75) - quantile(&v, 0.25);
    let spread = if iqr > 0.0 { sd.min(iqr / 1.34) } else { sd };
    let h = 0.9 * spread * n.powf(-0.2);
    if h.is_nan() || h <= 0.0 {
        return vec![0.0; grid.len()];
    }
    let c = 1.0 / (n * h * (2.0 * std::f64::consts::PI).sqrt());
    grid.iter()
        .map(|&g| {
            c * v
                .iter()
                .map(|&x| {
                    let z = (g - x) / h;
                    if z.abs() > 8.0 {
                        0.0
                    } else {
                        (-0.5 * z * z).exp()
                    }
                })
                .sum::<f64>()
        })
        .collect()
}

/// Ranks (0-based, ties by order) of every draw pooled over chains, returned per chain.
pub fn pooled_ranks(chains: &[&[f64]]) -> Vec<Vec<usize>> {
    let mut all: Vec<(f64, usize, usize)> = Vec::new();
    for (c, ch) in chains.iter().enumerate() {
        for (i, &x) in ch.iter().enumerate() {
            all.push((x, c, i));
        }
    }
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out: Vec<Vec<usize>> = chains.iter().map(|c| vec![0; c.len()]).collect();
    for (r, &(_, c, i)) in all.iter().enumerate() {
        out[c][i] = r;
    }
    out
}

/// Rank histogram per chain: counts of each chain's pooled ranks in `bins` equal bins.
pub fn rank_histograms(chains: &[&[f64]], bins: usize) -> Vec<Vec<usize>> {
    let ranks = pooled_ranks(chains);
    let total: usize = chains.iter().map(|c| c.len()).sum();
    ranks
        .iter()
        .map(|r| {
            let mut h = vec![0usize; bins];
            for &x in r {
                h[(x * bins / total.max(1)).min(bins - 1)] += 1;
            }
            h
        })
        .collect()
}

/// Every `step`-th index so that at most `max` points remain (always keeps the last).
pub fn thin_indices(n: usize, max: usize) -> Vec<usize> {
    if n <= max || max < 2 {
        return (0..n).collect();
    }
    let step = n.div_ceil(max);
    let mut v: Vec<usize> = (0..n).step_by(step).collect();
    if *v.last().unwrap() != n - 1 {
        v.push(n - 1);
    }
    v
}

/// Daily mean, min and max of an hourly series (24 slots a day); a day with fewer than
/// `min_hours` finite values is NaN.
#[derive(Debug, Clone, PartialEq)]
pub struct Daily {
    /// Daily mean.
    pub mean: Vec<f64>,
    /// Daily minimum.
    pub min: Vec<f64>,
    /// Daily maximum.
    pub max: Vec<f64>,
}

/// Aggregates an hourly series into days (see [`Daily`]).
pub fn daily(values: &[f64], min_hours: usize) -> Daily {
    let days = values.len().div_ceil(24);
    let mut d = Daily {
        mean: Vec::with_capacity(days),
        min: Vec::with_capacity(days),
        max: Vec::with_capacity(days),
    };
    for chunk in values.chunks(24) {
        let f: Vec<f64> = chunk.iter().copied().filter(|x| x.is_finite()).collect();
        if f.len() < min_hours.max(1) {
            d.mean.push(f64::NAN);
            d.min.push(f64::NAN);
            d.max.push(f64::NAN);
        } else {
            d.mean.push(f.iter().sum::<f64>() / f.len() as f64);
            d.min.push(f.iter().copied().fold(f64::INFINITY, f64::min));
            d.max
                .push(f.iter().copied().fold(f64::NEG_INFINITY, f64::max));
        }
    }
    d
}

/// Runs of consecutive non-finite values: `(start, end exclusive)`.
pub fn missing_runs(values: &[f64]) -> Vec<(usize, usize)> {
    let mut runs = vec![];
    let mut start = None;
    for (i, x) in values.iter().enumerate() {
        match (x.is_finite(), start) {
            (false, None) => start = Some(i),
            (true, Some(s)) => {
                runs.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        runs.push((s, values.len()));
    }
    runs
}

/// A week shown at hourly resolution.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    /// Title, e.g. `Winter week` or `Gap`.
    pub title: String,
    /// First hour.
    pub start: usize,
    /// One past the last hour.
    pub end: usize,
}

fn date_of(ts: &str) -> Option<chrono::NaiveDate> {
    chrono::NaiveDate::parse_from_str(ts.get(..10)?, "%Y-%m-%d").ok()
}

/// One week per season (starting on the first Monday on or after 15 January, April, July
/// and October, midnight) plus, when the measured series has a gap, a week around the
/// longest gap. `timestamps` are `YYYY-MM-DDTHH:MM` hourly in time order (a year from April
/// finds its winter week in the next January).
pub fn zoom_windows(timestamps: &[String], measured: &[f64]) -> Vec<Window> {
    use chrono::Datelike;
    let n = timestamps.len();
    let mut out = vec![];
    for (month, name) in [(1, "Winter"), (4, "Spring"), (7, "Summer"), (10, "Autumn")] {
        let monday = timestamps.iter().position(|t| {
            date_of(t).is_some_and(|d| {
                d.month() == month && d.day() >= 15 && d.weekday() == chrono::Weekday::Mon
            }) && t.get(11..13) == Some("00")
        });
        // No parsable dates: spread the weeks evenly over the series.
        let start = monday.unwrap_or((month as usize - 1) * n / 12);
        // A week mostly without meter data says little: move on a week at a time (up to 8).
        let mut start = start;
        for _ in 0..8 {
            let end = (start + 168).min(n);
            let missing = measured
                .get(start..end)
                .map_or(0, |w| w.iter().filter(|x| !x.is_finite()).count());
            if end <= start || 2 * missing <= end - start {
                break;
            }
            start += 168;
        }
        if start + 24 < n {
            let from = timestamps
                .get(start)
                .and_then(|t| t.get(..10))
                .unwrap_or("?");
            out.push(Window {
                title: format!("{name} week from {from}"),
                start,
                end: (start + 168).min(n),
            });
        }
    }
    if let Some(&(s, e)) = missing_runs(measured)
        .iter()
        .filter(|(s, e)| e - s >= 2)
        .max_by_key(|(s, e)| e - s)
    {
        let len = e - s;
        let (start, end) = if len + 48 <= 168 {
            let start = s.saturating_sub((168 - len) / 2);
            (start, (start + 168).min(n))
        } else {
            let start = s.saturating_sub(48);
            (start, (start + 168).min(n))
        };
        let from = timestamps.get(s).map_or("?", |t| t.as_str());
        let to = timestamps.get(e - 1).map_or("?", |t| t.as_str());
        out.push(Window {
            title: format!("Gap in the meter: {len} h missing, {from} to {to}"),
            start,
            end,
        });
    }
    out
}

/// Monthly totals of a measured and a simulated hourly series over the hours both have (the
/// hours Guideline 14's monthly figures compare): `(month 1-12, measured, simulated)` for each
/// month with at least one such hour, in the order the months come in `timestamps` (a year
/// from April lists April first). The month of hour `i` is read from `timestamps[i]`
/// (`YYYY-MM-...`).
pub fn monthly_totals(
    timestamps: &[String],
    measured: &[f64],
    simulated: &[f64],
) -> Vec<(u32, f64, f64)> {
    let mut sums = [(0.0, 0.0, 0usize); 12];
    let mut order: Vec<u32> = Vec::with_capacity(12);
    for ((t, &m), &s) in timestamps.iter().zip(measured).zip(simulated) {
        let month = t.get(5..7).and_then(|x| x.parse::<usize>().ok());
        if let (Some(k @ 1..=12), true) = (month, m.is_finite() && s.is_finite()) {
            sums[k - 1].0 += m;
            sums[k - 1].1 += s;
            sums[k - 1].2 += 1;
            if !order.contains(&(k as u32)) {
                order.push(k as u32);
            }
        }
    }
    order
        .into_iter()
        .map(|k| (k, sums[k as usize - 1].0, sums[k as usize - 1].1))
        .collect()
}

/// A 2-D histogram of `(x, y)` pairs on a `bins` x `bins` grid over `[lo, hi]` on both axes
/// (a scatter of 8,760 hours drawn as at most `bins^2` cells): `(x bin, y bin, count)` for the
/// non-empty cells. Pairs with a non-finite value or outside the range are left out.
pub fn binned_pairs(
    x: &[f64],
    y: &[f64],
    lo: f64,
    hi: f64,
    bins: usize,
) -> Vec<(usize, usize, usize)> {
    let mut counts = std::collections::BTreeMap::new();
    let width = (hi - lo) / bins as f64;
    if width.is_nan() || width <= 0.0 {
        return vec![];
    }
    for (&a, &b) in x.iter().zip(y) {
        if !(a.is_finite() && b.is_finite() && (lo..=hi).contains(&a) && (lo..=hi).contains(&b)) {
            continue;
        }
        let cell = |v: f64| (((v - lo) / width) as usize).min(bins - 1);
        *counts.entry((cell(a), cell(b))).or_insert(0) += 1;
    }
    counts.into_iter().map(|((i, j), n)| (i, j, n)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangular_cdf_matches_its_quantile() {
        let (lo, mode, hi) = (0.03, 0.04, 0.06);
        for p in [0.0, 0.01, 0.2, 1.0 / 3.0, 0.5, 0.9, 0.99, 1.0] {
            let x = triangular_quantile(lo, mode, hi, p);
            assert!((triangular_cdf(lo, mode, hi, x) - p).abs() < 1e-12, "{p}");
        }
        assert_eq!(triangular_cdf(lo, mode, hi, 0.0), 0.0);
        assert_eq!(triangular_cdf(lo, mode, hi, 1.0), 1.0);
    }

    #[test]
    fn monthly_totals_use_the_hours_both_series_have() {
        let ts: Vec<String> = [
            "2021-01-01T00:00",
            "2021-01-31T23:00",
            "2021-02-01T00:00",
            "2021-03-01T00:00",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let measured = [1.0, 2.0, f64::NAN, 4.0];
        let simulated = [1.5, 2.5, 9.0, f64::NAN];
        assert_eq!(
            monthly_totals(&ts, &measured, &simulated),
            vec![(1, 3.0, 4.0)]
        );
    }

    #[test]
    fn binned_pairs_count_each_cell_and_skip_missing() {
        let x = [0.0, 0.1, 9.9, 10.0, f64::NAN, 11.0];
        let y = [0.0, 0.2, 9.9, 10.0, 1.0, 1.0];
        // 10 bins of width 1: (0, 0) twice, the top cell (9, 9) twice (10.0 is kept in it).
        assert_eq!(
            binned_pairs(&x, &y, 0.0, 10.0, 10),
            vec![(0, 0, 2), (9, 9, 2)]
        );
        assert!(binned_pairs(&x, &y, 1.0, 1.0, 10).is_empty());
    }

    #[test]
    fn triangular_integrates_to_one() {
        let (a, m, b) = (2.0, 3.0, 7.0);
        let n = 10_000;
        let w = (b - a) / n as f64;
        let s: f64 = (0..n)
            .map(|i| triangular_pdf(a, m, b, a + (i as f64 + 0.5) * w) * w)
            .sum();
        assert!((s - 1.0).abs() < 1e-6);
        assert_eq!(triangular_pdf(a, m, b, 1.0), 0.0);
        assert!((triangular_pdf(a, m, b, 3.0) - 0.4).abs() < 1e-12);
        assert!((triangular_quantile(a, m, b, 0.2) - 3.0).abs() < 1e-12);
        assert_eq!(triangular_quantile(0.0, 0.0, 1.0, 1.0), 1.0);
    }

    #[test]
    fn histogram_is_a_density() {
        let v: Vec<f64> = (0..1000).map(|i| i as f64 / 1000.0).collect();
        let h = density_histogram(&v, 0.0, 1.0, 10);
        let area: f64 = h.iter().map(|(l, r, d)| (r - l) * d).sum();
        assert!((area - 1.0).abs() < 1e-12);
    }

    #[test]
    fn kde_peaks_near_the_mean() {
        let v: Vec<f64> = (0..500)
            .map(|i| 5.0 + ((i as f64) * 0.61803).fract() - 0.5)
            .collect();
        let grid: Vec<f64> = (0..101).map(|i| 4.0 + i as f64 * 0.02).collect();
        let d = kde(&v, &grid);
        let imax = (0..d.len()).max_by(|&a, &b| d[a].total_cmp(&d[b])).unwrap();
        assert!((grid[imax] - 5.0).abs() < 0.3);
    }

    #[test]
    fn ranks_are_uniform_for_interleaved_chains() {
        let a: Vec<f64> = (0..100).map(|i| (2 * i) as f64).collect();
        let b: Vec<f64> = (0..100).map(|i| (2 * i + 1) as f64).collect();
        let h = rank_histograms(&[&a, &b], 10);
        assert!(h.iter().all(|c| c.iter().all(|&x| x == 10)));
    }

    #[test]
    fn daily_and_gaps() {
        let mut v = vec![1.0; 72];
        for x in &mut v[30..60] {
            *x = f64::NAN;
        }
        let d = daily(&v, 12);
        assert_eq!(d.mean[0], 1.0);
        assert!(d.mean[1].is_nan());
        assert_eq!(d.mean[2], 1.0);
        assert_eq!(missing_runs(&v), vec![(30, 60)]);
        assert_eq!(thin_indices(10, 4), vec![0, 3, 6, 9]);
    }

    #[test]
    fn seasonal_weeks_start_on_mondays() {
        let start = chrono::NaiveDate::from_ymd_opt(2021, 1, 1)
            .unwrap()
            .and_hms_opt(0, 0, 0)
            .unwrap();
        let ts: Vec<String> = (0..8760)
            .map(|h| {
                (start + chrono::Duration::hours(h))
                    .format("%Y-%m-%dT%H:%M")
                    .to_string()
            })
            .collect();
        let mut m = vec![1.0; 8760];
        for x in &mut m[5000..5100] {
            *x = f64::NAN;
        }
        let w = zoom_windows(&ts, &m);
        assert_eq!(w.len(), 5);
        // 2021-01-18 is the first Monday on or after 15 January.
        assert_eq!(ts[w[0].start], "2021-01-18T00:00");
        assert!(w[4].start <= 5000 && w[4].end >= 5100);
        // A seasonal week inside a long gap moves past it.
        let mut m = vec![1.0; 8760];
        for x in &mut m[4000..4800] {
            *x = f64::NAN;
        }
        let w = zoom_windows(&ts, &m);
        assert!(w[2].start >= 4800 - 84, "{:?}", w[2]);
    }
}
