//! Hourly posterior predictive intervals of a meter and how often they hold.
//!
//! The predictive distribution of hour `h` is the simulations at `J` posterior draws, each with
//! the error model's noise added: the equal-weight mixture `(1/J) Σ_j N(c_j(h), s_j(h)²)`
//! (Gelman et al., *Bayesian Data Analysis*, 3rd ed., §6.3: draws of the parameters, then of
//! the data given them). Its quantiles are found by bisection on the mixture's CDF. The noise
//! `s_j(h)` is the residual scale of draw `j`'s own simulation over the calibration hours (the
//! noise's conditional posterior given the draw's parameters, so that a draw whose simulation
//! sits off the meter carries the wider noise its residuals show), either one value per
//! meter ([`ErrorModel::Constant`]), one per hour of the day ([`ErrorModel::HourOfDay`]) or one
//! per level of the simulated value ([`ErrorModel::Level`]). Coverage is the share of measured hours inside an interval
//! (the check of calibrated prediction: Gneiting, Balabdaoui & Raftery 2007, JRSS B 69).
//!
//! **Recalibration.** Where the posterior's draws are spread wider (or narrower, or off to one
//! side) than the meters, the mixture's central intervals miss their nominal share. The
//! probability integral transform `F(y)` of each measured value under its mixture is uniform
//! when the predictive is calibrated (Dawid 1984; Gneiting et al. 2007); its empirical
//! distribution `R` over the calibration period says how far it is not. The recalibrated
//! interval of level `l` takes the mixture's quantiles at `R^-1(1/2 - l/2)` and
//! `R^-1(1/2 + l/2)` instead of `1/2 -+ l/2` (Kuleshov, Fenner & Ermon 2018, *Accurate
//! uncertainties for deep learning using calibrated regression*, ICML, Algorithm 1, with the
//! empirical CDF as the monotone map): its in-sample coverage is nominal by construction, and
//! a held-out period is the independent check ([`Levels::recalibrated`]).
//!
//! Where the predictive has an atom at the measured value (a draw with no noise, or a meter
//! that cannot read below 0 and reads 0), its PIT is not one value but the interval
//! `[F(y-), F(y)]` ([`Pit`]), and the reading counts as uniform over it: the non-randomised
//! PIT of Czado, Gneiting & Held (2009, *Predictive model assessment for count data*,
//! Biometrics 65), whose distribution over the readings, `F̄(u) = mean_i G_i(u)`, is uniform
//! when the predictive is calibrated. The recalibration inverts `F̄`. A closed interval holds
//! an atom's readings whole, so a meter often at its atom (a cooling meter idle in winter)
//! has more of its hours inside its intervals than their nominal share however calibrated they
//! are; its readings' share of PIT inside the interval's levels ([`Coverage::pit_fraction`])
//! is the figure that says whether they hold. (Forcing the closed intervals' share to nominal
//! instead narrows them where the meter runs: on a real building idle 68 % of the hours, the
//! 50 % intervals held 7 % of the running hours.)
//!
//! Totals over a run of hours (a day, a month: what M&V practice checks) come from the same
//! draws' sums with the noise of the sum. Hourly residuals are autocorrelated, so the noise of
//! a sum is not the sum of independent hours' noise: with standardised residuals an AR(1)
//! process of lag-one correlation `phi` (Box & Jenkins; the likelihood's residual model), the
//! sum of `e_t = s_t z_t` has variance `sum_i sum_j s_i s_j phi^|i-j|` ([`ar1_sum_variance`]).
//! Intervals of totals built from independent hours (`phi = 0`) are too narrow for that
//! reason (ASHRAE Guideline 14's autocorrelation correction of savings uncertainty; CalTRACK's
//! hourly-uncertainty discussion): [`period_mixture`] takes `phi` from the residuals
//! ([`lag1_autocorrelation`]).

use serde::{Deserialize, Serialize};

use crate::error::{Result, StatsError};
use crate::normal::norm_cdf;

pub mod readings;

/// How the noise scale of the predictive distribution is estimated from in-sample residuals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ErrorModel {
    /// One scale per meter: the root mean square residual.
    Constant,
    /// One scale per hour of the day (hour slot `h` has hour `h % 24`).
    HourOfDay,
    /// One scale per level of the simulated value: the calibration hours are cut into
    /// [`LEVEL_BINS`] bins of equal count by the simulation at the estimate, and an hour gets
    /// the scale of the bin its own simulated value falls into (heteroscedastic residuals: a
    /// cooling meter idle in winter and busy in summer).
    Level,
}

/// Bins of [`ErrorModel::Level`].
pub const LEVEL_BINS: usize = 10;

impl ErrorModel {
    /// Every error model, in the order they are reported.
    pub const ALL: [ErrorModel; 3] = [
        ErrorModel::Constant,
        ErrorModel::HourOfDay,
        ErrorModel::Level,
    ];

    /// The name a project file gives it (`hour_of_day`), the one serde reads and writes.
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorModel::Constant => "constant",
            ErrorModel::HourOfDay => "hour_of_day",
            ErrorModel::Level => "level",
        }
    }

    /// The noise scale of each hour: the root mean square of `measured - simulated` over the
    /// hours where `fit[h]` is true and both are present (per hour of the day for
    /// [`ErrorModel::HourOfDay`], falling back to the constant scale for an hour of the day
    /// with fewer than 10 such hours).
    pub fn scales(self, measured: &[f64], simulated: &[f64], fit: &[bool]) -> Result<Vec<f64>> {
        let n = measured.len();
        if simulated.len() != n || fit.len() != n {
            return Err(StatsError::Shape(format!(
                "{n} measured, {} simulated values, {} hour flags",
                simulated.len(),
                fit.len()
            )));
        }
        let mut sum = [0.0f64; 24];
        let mut count = [0usize; 24];
        for h in 0..n {
            let r = measured[h] - simulated[h];
            if fit[h] && r.is_finite() {
                sum[h % 24] += r * r;
                count[h % 24] += 1;
            }
        }
        let total: usize = count.iter().sum();
        if total < 2 {
            return Err(StatsError::NotEnoughData(format!(
                "{total} calibration hours with a measured and a simulated value"
            )));
        }
        let constant = (sum.iter().sum::<f64>() / total as f64).sqrt();
        Ok(match self {
            ErrorModel::Constant => vec![constant; n],
            ErrorModel::HourOfDay => (0..n)
                .map(|h| match count[h % 24] {
                    c if c >= 10 => (sum[h % 24] / c as f64).sqrt(),
                    _ => constant,
                })
                .collect(),
            ErrorModel::Level => level_scales(measured, simulated, fit, constant),
        })
    }
}

/// [`ErrorModel::Level`]: bin edges at the quantiles of the fitted hours' simulated values,
/// the root mean square residual of each bin (the constant scale for a bin of fewer than 10
/// hours), and each hour's scale from its own simulated value's bin.
fn level_scales(measured: &[f64], simulated: &[f64], fit: &[bool], constant: f64) -> Vec<f64> {
    let mut pairs: Vec<(f64, f64)> = (0..measured.len())
        .filter(|&h| fit[h] && (measured[h] - simulated[h]).is_finite())
        .map(|h| (simulated[h], measured[h] - simulated[h]))
        .collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Bins of about equal count; a bin grows past its count while the next value ties with its
    // largest, so that equal simulated values (a meter idle at 0) share one bin.
    let per = pairs.len().div_ceil(LEVEL_BINS).max(1);
    let mut bins: Vec<(f64, f64)> = vec![];
    let (mut sum, mut count) = (0.0, 0usize);
    for (i, &(x, r)) in pairs.iter().enumerate() {
        sum += r * r;
        count += 1;
        let tie = pairs.get(i + 1).is_some_and(|next| next.0 == x);
        if (count >= per && !tie) || i + 1 == pairs.len() {
            let rms = (sum / count as f64).sqrt();
            bins.push((x, if count >= 10 { rms } else { constant }));
            (sum, count) = (0.0, 0);
        }
    }
    simulated
        .iter()
        .map(|&x| {
            let i = bins
                .partition_point(|b| b.0 < x)
                .min(bins.len().saturating_sub(1));
            bins.get(i).map_or(constant, |b| b.1)
        })
        .collect()
}

/// The `p` quantile of the equal-weight mixture of `N(c, sd²)` over `centers`, one `sd` for
/// all ([`mixture_quantile_each`]).
pub fn mixture_quantile(centers: &[f64], sd: f64, p: f64) -> f64 {
    let components: Vec<(f64, f64)> = centers.iter().map(|&c| (c, sd)).collect();
    mixture_quantile_each(&components, p)
}

/// The `p` quantile of the equal-weight mixture of `N(c, sd²)` over `components` `(c, sd)`
/// (bisection on the mixture CDF to 1e-9 of the bracket). A component with `sd <= 0` is its
/// center alone (a point mass).
pub fn mixture_quantile_each(components: &[(f64, f64)], p: f64) -> f64 {
    let (lo, hi) =
        components
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &(c, sd)| {
                let sd = sd.max(0.0);
                (a.min(c - 9.0 * sd), b.max(c + 9.0 * sd))
            });
    if components.is_empty() || !lo.is_finite() {
        return f64::NAN;
    }
    let tiny = 1e-12 * (1.0 + lo.abs().max(hi.abs()));
    let cdf = |x: f64| {
        components
            .iter()
            .map(|&(c, sd)| norm_cdf((x - c) / if sd > 0.0 { sd } else { tiny }))
            .sum::<f64>()
            / components.len() as f64
    };
    let (mut a, mut b) = (lo - 9.0 * tiny, hi + 9.0 * tiny);
    let tol = 1e-9 * (b - a);
    // At most 100 halvings (a bracket of any width reaches 1e-9 of itself in 30); stop early
    // where floating point cannot split the bracket any more.
    for _ in 0..100 {
        let m = 0.5 * (a + b);
        if b - a <= tol || m <= a || m >= b {
            break;
        }
        if cdf(m) < p {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

/// Fewest values (hours, days) of the calibration period a recalibration takes: with fewer its
/// empirical quantiles at 5 % and 95 % rest on a handful of values, and the levels stay central.
pub const MIN_RECALIBRATION_VALUES: usize = 30;

/// Which probability levels of the mixture bound each nominal interval.
#[derive(Debug, Clone, PartialEq)]
pub struct Levels {
    /// The nominal levels (0.5, 0.9).
    pub nominal: Vec<f64>,
    /// Per nominal level, the mixture's probability levels of its lower and upper bound.
    pub bounds: Vec<(f64, f64)>,
    /// The mixture's probability level of the reported median.
    pub median: f64,
}

impl Levels {
    /// The central intervals: `1/2 -+ l/2`, the median at 1/2.
    pub fn central(nominal: &[f64]) -> Result<Levels> {
        if nominal.iter().any(|l| !(0.0..1.0).contains(l) || *l == 0.0) {
            return Err(StatsError::Invalid(format!(
                "levels {nominal:?} must lie strictly between 0 and 1"
            )));
        }
        Ok(Levels {
            nominal: nominal.to_vec(),
            bounds: nominal
                .iter()
                .map(|l| (0.5 - l / 2.0, 0.5 + l / 2.0))
                .collect(),
            median: 0.5,
        })
    }

    /// The levels recalibrated on `pits`, the probability integral transforms of the
    /// calibration period's measured values under their mixtures ([`pits`]): each central
    /// level `p` becomes `R^-1(p)`, `R` the distribution of the PITs (Kuleshov et al. 2018,
    /// Algorithm 1), a reading at an atom uniform over its PIT interval (Czado et al. 2009:
    /// [`pit_quantile`]). Central where fewer than [`MIN_RECALIBRATION_VALUES`] values are
    /// given.
    pub fn recalibrated(nominal: &[f64], pits: &[Pit]) -> Result<Levels> {
        let central = Levels::central(nominal)?;
        let pits: Vec<Pit> = pits.iter().copied().filter(Pit::is_finite).collect();
        if pits.len() < MIN_RECALIBRATION_VALUES {
            return Ok(central);
        }
        let q = |p: f64| pit_quantile(&pits, p);
        Ok(Levels {
            bounds: (central.bounds.iter())
                .map(|&(lo, hi)| (q(lo), q(hi)))
                .collect(),
            median: q(central.median),
            nominal: central.nominal,
        })
    }
}

/// The probability integral transform of one measured value `y` under its predictive `F`:
/// the interval `[F(y-), F(y)]`, a single value (`below == at`) unless `F` has an atom at `y`
/// (Czado, Gneiting & Held 2009).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pit {
    /// `F(y-)`, the probability of reading less than `y`.
    pub below: f64,
    /// `F(y)`, the probability of reading at most `y`.
    pub at: f64,
}

impl Pit {
    /// Whether both ends are finite.
    pub fn is_finite(&self) -> bool {
        self.below.is_finite() && self.at.is_finite()
    }

    /// Whether the reading sits at an atom of its predictive (`below < at`).
    pub fn at_atom(&self) -> bool {
        self.below < self.at
    }

    /// The non-randomised PIT's distribution function at `u` (Czado et al. 2009, Eq. 2): the
    /// share of `[below, at]` at or below `u`; for a single value, whether it is at most `u`.
    pub fn cdf(&self, u: f64) -> f64 {
        if self.at_atom() {
            ((u - self.below) / (self.at - self.below)).clamp(0.0, 1.0)
        } else {
            f64::from(u8::from(self.at <= u))
        }
    }

    /// The share of the PIT inside `[lo, hi]`: `cdf(hi) - cdf(lo)`, and for a single value
    /// whether it lies inside (bounds included).
    pub fn share_within(&self, lo: f64, hi: f64) -> f64 {
        if self.at_atom() {
            (self.cdf(hi) - self.cdf(lo)).max(0.0)
        } else {
            f64::from(u8::from(lo <= self.at && self.at <= hi))
        }
    }
}

/// The `p` quantile of the PITs `pits` (finite), each reading at an atom uniform over its
/// interval: `inf { u : F̄(u) >= p }`, `F̄ = mean_i Pit::cdf` (Czado et al. 2009), by
/// bisection on `[0, 1]` to 1e-12. Without atoms it is the empirical quantile. NaN without
/// PITs.
pub fn pit_quantile(pits: &[Pit], p: f64) -> f64 {
    if pits.is_empty() {
        return f64::NAN;
    }
    let n = pits.len() as f64;
    let cdf = |u: f64| pits.iter().map(|x| x.cdf(u)).sum::<f64>() / n;
    let (mut a, mut b) = (0.0f64, 1.0f64);
    if cdf(a) >= p {
        return a;
    }
    while b - a > 1e-12 {
        let m = 0.5 * (a + b);
        if cdf(m) >= p {
            b = m;
        } else {
            a = m;
        }
    }
    b
}

/// The share of the PITs `pits` inside the probability levels `[lo, hi]`, each reading at an
/// atom counted by the share of its interval inside (Czado et al. 2009): the coverage of a
/// calibrated predictive's interval at those levels is nominal in this sense, atoms included.
/// NaN without PITs.
pub fn pit_coverage(pits: &[Pit], (lo, hi): (f64, f64)) -> f64 {
    pits.iter().map(|p| p.share_within(lo, hi)).sum::<f64>() / pits.len() as f64
}

/// The CDF at `x` of the equal-weight mixture of `N(c, sd²)` over `components` `(c, sd)` (a
/// component with `sd <= 0` is a point mass at its center), and its limit from below: `(F(x-),
/// F(x))`, equal unless a point mass sits at `x`.
pub fn mixture_cdf_each(components: &[(f64, f64)], x: f64) -> (f64, f64) {
    if components.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let (mut below, mut at) = (0.0, 0.0);
    for &(c, sd) in components {
        if sd > 0.0 {
            let f = norm_cdf((x - c) / sd);
            below += f;
            at += f;
        } else {
            below += f64::from(u8::from(x > c));
            at += f64::from(u8::from(x >= c));
        }
    }
    let n = components.len() as f64;
    (below / n, at / n)
}

/// The probability integral transform of each value of `measured` that `select` keeps (finite,
/// with at least one draw's value) under its mixture of the draws `sims` with their noise
/// `noise` ([`intervals`]' mixture): `F_h(y_h)`, uniform on (0, 1) where the predictive is
/// calibrated (Dawid 1984), an interval where it has an atom at `y_h` ([`Pit`]). A meter that
/// cannot read below `floor` reads `max(floor, Y)`: the same CDF above `floor`, and an atom of
/// `F(floor)` at it, so that a reading at the floor has the PIT `[0, F(floor)]`.
pub fn pits(
    sims: &[Vec<f64>],
    noise: &[Vec<f64>],
    measured: &[f64],
    select: &[bool],
    floor: Option<f64>,
) -> Vec<Pit> {
    let n = sims.first().map_or(0, Vec::len);
    if !fits(noise, sims.len(), n) {
        return vec![];
    }
    let mut c = Vec::with_capacity(sims.len());
    (0..n.min(measured.len()).min(select.len()))
        .filter(|&h| select[h] && measured[h].is_finite())
        .filter_map(|h| {
            components_at(sims, noise, h, &mut c);
            (!c.is_empty()).then(|| {
                let y = measured[h];
                let (below, at) = mixture_cdf_each(&c, y);
                let at_floor = floor.is_some_and(|f| y <= f);
                Pit {
                    below: if at_floor { 0.0 } else { below },
                    at,
                }
            })
        })
        .collect()
}

/// Value `h`'s mixture components `(center, scale)` into `out`: each draw with a finite value
/// there, with its own noise scale.
fn components_at(sims: &[Vec<f64>], noise: &[Vec<f64>], h: usize, out: &mut Vec<(f64, f64)>) {
    out.clear();
    out.extend(
        (sims.iter().enumerate())
            .filter(|(_, s)| s[h].is_finite())
            .map(|(j, s)| (s[h], noise[j][h])),
    );
}

/// Predictive intervals of every hour at the nominal levels (e.g. 0.5 and 0.9), central or
/// recalibrated ([`Levels`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Intervals {
    /// The nominal levels, as given.
    pub levels: Vec<f64>,
    /// Per level, the lower bound of each hour.
    pub lower: Vec<Vec<f64>>,
    /// Per level, the upper bound of each hour.
    pub upper: Vec<Vec<f64>>,
    /// The mixture's median of each hour.
    pub median: Vec<f64>,
}

/// Predictive intervals of each hour from `sims` (one hourly series per posterior draw, meter
/// units) and `noise[j][h]`, the noise scale of draw `j` at hour `h`, bounded at the mixture's
/// probability `levels`. An hour where no draw has a value is NaN.
pub fn intervals(sims: &[Vec<f64>], noise: &[Vec<f64>], levels: &Levels) -> Result<Intervals> {
    intervals_on(sims, noise, levels, None)
}

/// [`intervals`] of the hours `select` keeps (all with `None`); NaN at the others.
fn intervals_on(
    sims: &[Vec<f64>],
    noise: &[Vec<f64>],
    levels: &Levels,
    select: Option<&[bool]>,
) -> Result<Intervals> {
    let n = sims.first().map_or(0, Vec::len);
    if sims.is_empty() || sims.iter().any(|s| s.len() != n) || !fits(noise, sims.len(), n) {
        return Err(StatsError::Shape(format!(
            "{} simulations and their noise scales for {n} hours (each must have {n} values)",
            sims.len()
        )));
    }
    let k = levels.nominal.len();
    let mut out = Intervals {
        levels: levels.nominal.clone(),
        lower: vec![Vec::with_capacity(n); k],
        upper: vec![Vec::with_capacity(n); k],
        median: Vec::with_capacity(n),
    };
    let mut c = Vec::with_capacity(sims.len());
    for h in 0..n {
        if select.is_some_and(|s| !s.get(h).copied().unwrap_or(false)) {
            c.clear();
        } else {
            components_at(sims, noise, h, &mut c);
        }
        out.median.push(mixture_quantile_each(&c, levels.median));
        for (i, &(lo, hi)) in levels.bounds.iter().enumerate() {
            out.lower[i].push(mixture_quantile_each(&c, lo));
            out.upper[i].push(mixture_quantile_each(&c, hi));
        }
    }
    Ok(out)
}

impl Intervals {
    /// Their [`coverage`] at each level on the values of `measured` that `select` keeps, each
    /// reading counted whole; `None` at a level where no value is judged.
    pub fn level_coverage(&self, measured: &[f64], select: &[bool]) -> Vec<Option<Coverage>> {
        (self.levels.iter().enumerate())
            .map(|(i, &l)| coverage(l, measured, &self.lower[i], &self.upper[i], select))
            .collect()
    }

    /// [`Intervals::level_coverage`], with the share of `pits` (the PITs of the same values)
    /// inside `levels`' bounds where some reading sits at an atom ([`Coverage::with_pits`]).
    pub fn coverage(
        &self,
        levels: &Levels,
        measured: &[f64],
        select: &[bool],
        pits: &[Pit],
    ) -> Vec<Coverage> {
        (self.level_coverage(measured, select).into_iter())
            .zip(&levels.bounds)
            .filter_map(|(c, &bounds)| Some(c?.with_pits(pits, bounds)))
            .collect()
    }

    /// Raises every bound and median below `floor` to it: the intervals of `max(floor, Y)`
    /// (quantiles commute with a monotone map), for a meter that cannot read below `floor`.
    pub fn clamp_below(&mut self, floor: f64) {
        for v in self
            .lower
            .iter_mut()
            .chain(self.upper.iter_mut())
            .chain(std::iter::once(&mut self.median))
        {
            for x in v.iter_mut().filter(|x| **x < floor) {
                *x = floor;
            }
        }
    }
}

/// An error model's recalibrated intervals judged out of time, by blocked cross-validation
/// over the calibration period (Roberts et al. 2017, *Cross-validation strategies for data
/// with temporal, spatial, hierarchical, or phylogenetic structure*, Ecography 40, 913-929:
/// blocks long against the residuals' autocorrelation): for each block of `folds` (calendar
/// months), the draws' noise scales ([`ErrorModel::scales`]) and the recalibrated levels
/// ([`Levels::recalibrated`]) are taken from the other blocks' calibration hours alone
/// (`fit`), and the intervals so built are judged on the block's own. Recalibrated intervals
/// hold their nominal share (of PIT) of the hours they were recalibrated on by construction,
/// which says nothing of an error model; this says how they hold on a month they did not see,
/// without a held-out period. The intervals of `max(floor, Y)` where `floor` is given (as
/// [`pits`]). Per block judged (those with a measured calibration hour, and at least
/// [`MIN_RECALIBRATION_VALUES`] in the other blocks), one [`Coverage`] per `nominal` level,
/// with its PIT share where a reading sits at an atom ([`Coverage::with_pits`]).
pub fn cross_validated_coverage(
    sims: &[Vec<f64>],
    measured: &[f64],
    fit: &[bool],
    folds: &[std::ops::Range<usize>],
    model: ErrorModel,
    nominal: &[f64],
    floor: Option<f64>,
) -> Result<Vec<Vec<Coverage>>> {
    let n = fit.len();
    if measured.len() != n || sims.iter().any(|s| s.len() != n) || folds.iter().any(|f| f.end > n) {
        return Err(StatsError::Shape(format!(
            "{} simulations, {} measured values, {n} hour flags and folds up to hour {} \
             (each must have {n} values)",
            sims.len(),
            measured.len(),
            folds.iter().map(|f| f.end).max().unwrap_or(0)
        )));
    }
    let mut judged = vec![];
    for fold in folds {
        // The block's measured calibration hours.
        let block: Vec<bool> = (0..n)
            .map(|h| fold.contains(&h) && fit[h] && measured[h].is_finite())
            .collect();
        if !block.contains(&true) {
            continue;
        }
        let mut train = fit.to_vec();
        train[fold.clone()].iter_mut().for_each(|t| *t = false);
        let trained = (0..n)
            .filter(|&h| train[h] && measured[h].is_finite())
            .count();
        if trained < MIN_RECALIBRATION_VALUES {
            continue;
        }
        let noise = (sims.iter())
            .map(|s| model.scales(measured, s, &train))
            .collect::<Result<Vec<_>>>()?;
        let levels = Levels::recalibrated(nominal, &pits(sims, &noise, measured, &train, floor))?;
        let mut iv = intervals_on(sims, &noise, &levels, Some(&block))?;
        if let Some(f) = floor {
            iv.clamp_below(f);
        }
        let block_pits = pits(sims, &noise, measured, &block, floor);
        judged.push(iv.coverage(&levels, measured, &block, &block_pits));
    }
    Ok(judged)
}

/// The mean over blocks of their intervals' distance from nominal ([`coverage_miss`]),
/// weighted by the hours each judged: how far from calibrated the intervals are within a
/// block, not only over them all (intervals too wide in winter and too narrow in summer can
/// hold their nominal share over a year and in no month; a held-out season sees one side).
/// NaN without a block judged.
pub fn mean_block_miss(blocks: &[Vec<Coverage>]) -> f64 {
    let (mut sum, mut hours) = (0.0, 0usize);
    for b in blocks {
        let (m, n) = (coverage_miss(b), b.first().map_or(0, |c| c.hours));
        if m.is_finite() {
            sum += m * n as f64;
            hours += n;
        }
    }
    if hours == 0 {
        f64::NAN
    } else {
        sum / hours as f64
    }
}

/// Lag-one autocorrelation of `z` over the consecutive pairs where both values are finite:
/// `sum z_t z_(t-1) / sum z_t^2` (the sum of squares over the same values; 0 without a pair),
/// clamped to `[-0.999, 0.999]` so that an AR(1) built on it is stationary.
pub fn lag1_autocorrelation(z: &[f64]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for w in z.windows(2) {
        if w[0].is_finite() && w[1].is_finite() {
            num += w[0] * w[1];
            den += 0.5 * (w[0] * w[0] + w[1] * w[1]);
        }
    }
    if den > 0.0 {
        (num / den).clamp(-0.999, 0.999)
    } else {
        0.0
    }
}

/// Variance of `sum_t s_t z_t` where `z` is a unit-variance AR(1) process with coefficient
/// `phi` (`corr(z_i, z_j) = phi^|i-j|`): `sum_i s_i^2 + 2 sum_i s_i a_i` with
/// `a_i = sum_(j<i) s_j phi^(i-j) = phi (a_(i-1) + s_(i-1))`, in O(n).
pub fn ar1_sum_variance(scales: &[f64], phi: f64) -> f64 {
    let (mut a, mut prev, mut var) = (0.0, 0.0, 0.0);
    for (i, &s) in scales.iter().enumerate() {
        if i > 0 {
            a = phi * (a + prev);
        }
        var += s * s + 2.0 * s * a;
        prev = s;
    }
    var
}

/// The mixture of the totals over `periods` (runs of hours: days, months): each draw's sum
/// over a period is a center, and its scale that of the sum of the draw's hourly noise
/// `noise[j]` with AR(1) coefficient `phi` ([`ar1_sum_variance`]; `phi = 0`: independent
/// hours), for [`intervals`] and [`pits`]; a period in which a draw lacks a value has a NaN
/// center.
pub fn period_mixture(
    sims: &[Vec<f64>],
    noise: &[Vec<f64>],
    phi: f64,
    periods: &[std::ops::Range<usize>],
) -> Result<Mixture> {
    let n = sims.first().map_or(0, Vec::len);
    if !fits(noise, sims.len(), n) {
        return Err(StatsError::Shape(format!(
            "noise scales that do not match {} simulations of {n} hours",
            sims.len()
        )));
    }
    if let Some(p) = periods.iter().find(|p| p.end > n) {
        return Err(StatsError::Shape(format!("period {p:?} past {n} hours")));
    }
    let sums: Vec<Vec<f64>> = sims
        .iter()
        .map(|s| periods.iter().map(|p| s[p.clone()].iter().sum()).collect())
        .collect();
    let sds: Vec<Vec<f64>> = (noise.iter())
        .map(|scales| {
            (periods.iter())
                .map(|p| ar1_sum_variance(&scales[p.clone()], phi).max(0.0).sqrt())
                .collect()
        })
        .collect();
    Ok(Mixture {
        centers: sums,
        scales: sds,
    })
}

/// Per draw, the centers and noise scales of a series of values (hours, periods): value `h`'s
/// predictive is the equal-weight mixture of `N(centers[j][h], scales[j][h]²)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Mixture {
    /// Per draw, the center of each value.
    pub centers: Vec<Vec<f64>>,
    /// Per draw, the noise scale of each value.
    pub scales: Vec<Vec<f64>>,
}

/// Whether `noise` holds one scale series of `n` hours for each of `draws` draws.
fn fits(noise: &[Vec<f64>], draws: usize, n: usize) -> bool {
    noise.len() == draws && noise.iter().all(|s| s.len() == n)
}

/// The measured total of each period where every hour of it is measured and selected (NaN
/// elsewhere), and whether the period counts (all its hours selected).
pub fn period_totals(
    measured: &[f64],
    select: &[bool],
    periods: &[std::ops::Range<usize>],
) -> (Vec<f64>, Vec<bool>) {
    periods
        .iter()
        .map(|p| {
            let all = p.clone().all(|t| select.get(t).copied().unwrap_or(false));
            let whole = p
                .clone()
                .all(|t| measured.get(t).is_some_and(|v| v.is_finite()));
            let total = if whole {
                measured[p.clone()].iter().sum()
            } else {
                f64::NAN
            };
            (total, all)
        })
        .unzip()
}

/// How far a set of intervals' coverage is from nominal: the sum over its levels of
/// `|fraction - nominal|` ([`Coverage::calibration_fraction`]), in percentage points (NaN
/// with no level judged): how far from calibrated the intervals are, in the sense of
/// Gneiting, Balabdaoui & Raftery (2007, JRSS B 69), who ask for sharpness subject to
/// calibration.
pub fn coverage_miss(coverage: &[Coverage]) -> f64 {
    if coverage.is_empty() || coverage.iter().any(|c| c.hours == 0) {
        return f64::NAN;
    }
    coverage
        .iter()
        .map(|c| 100.0 * (c.calibration_fraction() - c.nominal).abs())
        .sum()
}

/// The summed mean width of a set of intervals over their levels (meter units): the
/// sharpness [`sharpest_within`] weighs.
pub fn summed_width(coverage: &[Coverage]) -> f64 {
    coverage.iter().map(|c| c.mean_width).sum()
}

/// Of candidates with a distance from nominal `misses` (percentage points; NaN: not judged)
/// and a `widths` (summed over the levels, [`summed_width`]), the index of the smallest miss,
/// or among those within `tie_points` of it the narrowest: sharpness subject to calibration
/// (Gneiting et al. 2007). `None` where no candidate was judged.
pub fn sharpest_within(misses: &[f64], widths: &[f64], tie_points: f64) -> Option<usize> {
    let best = misses
        .iter()
        .copied()
        .filter(|m| m.is_finite())
        .min_by(f64::total_cmp)?;
    (0..misses.len().min(widths.len()))
        .filter(|&i| misses[i].is_finite() && misses[i] <= best + tie_points)
        .min_by(|&a, &b| widths[a].total_cmp(&widths[b]))
}

/// How often one interval level held on a set of hours.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Coverage {
    /// Nominal level (0.9 for a 90 % interval).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub nominal: f64,
    /// Measured hours judged.
    pub hours: usize,
    /// Share of them inside the interval (bounds included).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub fraction: f64,
    /// Mean width of the interval over those hours (meter units).
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub mean_width: f64,
    /// Mean width over the mean measured value of those hours (absent where that mean is 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_width: Option<f64>,
    /// Where some of the hours read at an atom of their predictive (a meter at its floor of
    /// 0 where draws simulate it idle): the share of their PITs inside the interval's
    /// probability levels, a reading at the atom counted by the share of its PIT interval
    /// inside ([`pit_coverage`]). A closed interval holds such a reading whole, so `fraction`
    /// exceeds nominal however calibrated the intervals are; this is nominal when they are.
    /// Absent where no hour reads at an atom (`fraction` says it then).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pit_fraction: Option<f64>,
}

impl Coverage {
    /// The coverage with [`Coverage::pit_fraction`] from `pits`, the PITs of the same hours,
    /// and the interval's probability levels `bounds`, where some reading sits at an atom.
    pub fn with_pits(self, pits: &[Pit], bounds: (f64, f64)) -> Coverage {
        Coverage {
            pit_fraction: pits
                .iter()
                .any(Pit::at_atom)
                .then(|| pit_coverage(pits, bounds)),
            ..self
        }
    }

    /// The share to hold against nominal: [`Coverage::pit_fraction`] where there is one, else
    /// `fraction`.
    pub fn calibration_fraction(&self) -> f64 {
        self.pit_fraction.unwrap_or(self.fraction)
    }
}

/// Coverage of `lower..=upper` on the hours where `select[h]` is true and `measured[h]` and
/// both bounds are finite; None where there is no such hour.
pub fn coverage(
    nominal: f64,
    measured: &[f64],
    lower: &[f64],
    upper: &[f64],
    select: &[bool],
) -> Option<Coverage> {
    let (mut n, mut inside, mut width, mut level) = (0usize, 0usize, 0.0, 0.0);
    for h in 0..measured
        .len()
        .min(lower.len())
        .min(upper.len())
        .min(select.len())
    {
        let (y, a, b) = (measured[h], lower[h], upper[h]);
        if select[h] && y.is_finite() && a.is_finite() && b.is_finite() {
            n += 1;
            inside += usize::from(a <= y && y <= b);
            width += b - a;
            level += y;
        }
    }
    if n == 0 {
        return None;
    }
    let nf = n as f64;
    Some(Coverage {
        nominal,
        hours: n,
        fraction: inside as f64 / nf,
        mean_width: width / nf,
        relative_width: (level != 0.0).then(|| width / level),
        pit_fraction: None,
    })
}

/// One interval level's coverage over the union of disjoint sets of hours, from each set's
/// (hours, share inside and mean width weighted by hours; the relative width where every set
/// has one; the PIT share where some set has one, the others' `fraction` standing in). None
/// without hours.
pub fn pooled_coverage(parts: &[Coverage]) -> Option<Coverage> {
    let n: usize = parts.iter().map(|c| c.hours).sum();
    if n == 0 {
        return None;
    }
    let nf = n as f64;
    let inside: f64 = parts.iter().map(|c| c.fraction * c.hours as f64).sum();
    let width: f64 = parts.iter().map(|c| c.mean_width * c.hours as f64).sum();
    let level: Option<f64> = parts
        .iter()
        .map(|c| c.relative_width.map(|r| c.mean_width * c.hours as f64 / r))
        .sum();
    let pit = (parts.iter().any(|c| c.pit_fraction.is_some())).then(|| {
        let held: f64 = parts
            .iter()
            .map(|c| c.calibration_fraction() * c.hours as f64)
            .sum();
        held / nf
    });
    Some(Coverage {
        nominal: parts[0].nominal,
        hours: n,
        fraction: inside / nf,
        mean_width: width / nf,
        relative_width: level.filter(|l| *l != 0.0).map(|l| width / l),
        pit_fraction: pit,
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn each_error_model_is_named_as_serde_names_it() {
        for m in ErrorModel::ALL {
            let json = serde_json::to_string(&m).unwrap();
            assert_eq!(json, format!("\"{}\"", m.as_str()));
            assert_eq!(serde_json::from_str::<ErrorModel>(&json).unwrap(), m);
        }
    }

    #[test]
    fn the_candidate_nearest_nominal_wins_and_a_tie_goes_to_the_sharper() {
        let cov = |f50: f64, f90: f64, w: f64| {
            vec![
                Coverage {
                    nominal: 0.5,
                    hours: 2000,
                    fraction: f50,
                    mean_width: w,
                    relative_width: None,
                    pit_fraction: None,
                },
                Coverage {
                    nominal: 0.9,
                    hours: 2000,
                    fraction: f90,
                    mean_width: 2.0 * w,
                    relative_width: None,
                    pit_fraction: None,
                },
            ]
        };
        // The RSF's heating held out (level, constant, hour of day): 18.4, 9.9, 5.0 points.
        let (level, constant, hour) = (
            cov(0.602, 0.982, 248.0),
            cov(0.587, 0.912, 197.0),
            cov(0.547, 0.903, 191.0),
        );
        assert!((coverage_miss(&level) - 18.4).abs() < 1e-9);
        let nearest_nominal = |candidates: &[&[Coverage]], tie: f64| {
            let misses: Vec<f64> = candidates.iter().map(|c| coverage_miss(c)).collect();
            let widths: Vec<f64> = candidates.iter().map(|c| summed_width(c)).collect();
            sharpest_within(&misses, &widths, tie)
        };
        assert_eq!(nearest_nominal(&[&level, &constant, &hour], 1.0), Some(2));
        // Within the tie margin, the narrower intervals.
        let wide = cov(0.50, 0.90, 300.0);
        let narrow = cov(0.505, 0.905, 100.0);
        assert_eq!(summed_width(&wide), 900.0);
        assert_eq!(nearest_nominal(&[&wide, &narrow], 0.5), Some(0));
        assert_eq!(nearest_nominal(&[&wide, &narrow], 1.5), Some(1));
        // Nothing judged.
        assert_eq!(nearest_nominal(&[&[][..]], 1.0), None);
        assert!(coverage_miss(&[]).is_nan());
    }

    #[test]
    fn cross_validation_by_block_finds_the_error_model_that_holds_in_every_season() {
        // A meter whose level runs from 1 in winter to 10 in summer, its noise 10 % of the
        // level: four draws on the level (1 % apart), twelve 720-hour months, the last one
        // not calibrated. The constant scale's recalibrated intervals hold their share over
        // the year and in no month (too wide in winter, too narrow in summer); the level's
        // hold in each month, judged on months they did not see.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let n = 12 * 720;
        let level: Vec<f64> = (0..n)
            .map(|t| 1.0 + 9.0 * (0.5 - 0.5 * (std::f64::consts::TAU * t as f64 / n as f64).cos()))
            .collect();
        let measured: Vec<f64> = (level.iter())
            .map(|m| m + 0.1 * m * rng.sample::<f64, _>(StandardNormal))
            .collect();
        let sims: Vec<Vec<f64>> = (0..4)
            .map(|j| {
                level
                    .iter()
                    .map(|m| m * (1.0 + 0.01 * (j as f64 - 1.5)))
                    .collect()
            })
            .collect();
        let mut fit = vec![true; n];
        fit[11 * 720..].iter_mut().for_each(|f| *f = false);
        let folds: Vec<_> = (0..12).map(|m| 720 * m..720 * (m + 1)).collect();
        let judge = |model| {
            cross_validated_coverage(&sims, &measured, &fit, &folds, model, &[0.5, 0.9], None)
                .unwrap()
        };
        let (constant, by_level) = (judge(ErrorModel::Constant), judge(ErrorModel::Level));
        assert_eq!((constant.len(), by_level.len()), (11, 11));
        assert!(by_level.iter().all(|b| b.len() == 2 && b[0].hours == 720));
        let pooled = |blocks: &[Vec<Coverage>], i: usize| {
            let parts: Vec<Coverage> = blocks.iter().map(|b| b[i]).collect();
            pooled_coverage(&parts).unwrap().fraction
        };
        // Over the year both hold about their share; month by month only the level's.
        for blocks in [&constant, &by_level] {
            assert!(
                (pooled(blocks, 1) - 0.9).abs() < 0.03,
                "{}",
                pooled(blocks, 1)
            );
        }
        let (c, l) = (mean_block_miss(&constant), mean_block_miss(&by_level));
        assert!(l < 8.0 && c > 25.0, "level {l}, constant {c}");
        let w = |b: &[Vec<Coverage>]| b[0][1].mean_width;
        assert!(w(&by_level) < w(&constant), "narrower in winter");
        // The choice: the smallest miss; within the tie margin, the narrower.
        assert_eq!(sharpest_within(&[c, l], &[1.0, 2.0], 2.0), Some(1));
        assert_eq!(sharpest_within(&[3.0, 2.0], &[1.0, 2.0], 2.0), Some(0));
        assert_eq!(sharpest_within(&[f64::NAN], &[1.0], 2.0), None);
        // A calibration period of one month: no other month to build its intervals from.
        let mut one = vec![false; n];
        one[..720].iter_mut().for_each(|f| *f = true);
        let alone = cross_validated_coverage(
            &sims,
            &measured,
            &one,
            &folds,
            ErrorModel::Level,
            &[0.5],
            None,
        );
        assert_eq!(alone.unwrap().len(), 0);
        // Shapes are checked.
        assert!(cross_validated_coverage(
            &sims,
            &measured[1..],
            &fit,
            &folds,
            ErrorModel::Level,
            &[0.5],
            None
        )
        .is_err());
        assert!(mean_block_miss(&[]).is_nan());
    }

    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    fn central(nominal: &[f64]) -> Levels {
        Levels::central(nominal).unwrap()
    }

    #[test]
    fn recalibration_narrows_an_over_dispersed_predictive_to_its_nominal_share() {
        // Data N(1, 1); the predictive N(0, 2²) is too wide and off centre: its central 90 %
        // interval [-3.29, 3.29] holds 98.9 % of fresh data. Recalibrated on 4,000 values
        // (their PITs Phi(y / 2)), the 90 % interval is N(1, 1)'s own [1 -+ 1.645]: it holds
        // 90 % (and the 50 % one 50 %) of 4,000 other values within sampling error.
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut z = move || rng.sample::<f64, _>(StandardNormal);
        let n = 4000;
        let sims = vec![vec![0.0; n]];
        let noise = vec![vec![2.0; n]];
        let fit: Vec<f64> = (0..n).map(|_| 1.0 + z()).collect();
        let fresh: Vec<f64> = (0..n).map(|_| 1.0 + z()).collect();
        let pit = pits(&sims, &noise, &fit, &vec![true; n], None);
        assert_eq!(pit.len(), n);
        let levels = Levels::recalibrated(&[0.5, 0.9], &pit).unwrap();
        assert_ne!(levels, central(&[0.5, 0.9]));
        let (lo, hi) = levels.bounds[1];
        let q = |p: f64| mixture_quantile(&[0.0], 2.0, p);
        assert!((q(lo) - (1.0 - 1.645)).abs() < 0.1, "{}", q(lo));
        assert!((q(hi) - (1.0 + 1.645)).abs() < 0.1, "{}", q(hi));
        let all = vec![true; n];
        let raw = intervals(&sims, &noise, &central(&[0.9])).unwrap();
        let before = coverage(0.9, &fresh, &raw.lower[0], &raw.upper[0], &all).unwrap();
        assert!(before.fraction > 0.97, "{before:?}");
        let iv = intervals(&sims, &noise, &levels).unwrap();
        for (i, nominal) in [0.5, 0.9].into_iter().enumerate() {
            let c = coverage(nominal, &fresh, &iv.lower[i], &iv.upper[i], &all).unwrap();
            assert!((c.fraction - nominal).abs() < 0.025, "{nominal}: {c:?}");
            assert!(c.mean_width < before.mean_width, "{c:?}");
        }
        assert!((mixture_quantile(&[0.0], 2.0, levels.median) - 1.0).abs() < 0.1);
    }

    #[test]
    fn calibrated_pits_leave_the_levels_nearly_central_and_few_leave_them_central() {
        // Uniform PITs: the recalibrated levels are the central ones within sampling error.
        let pit: Vec<Pit> = (0..1000)
            .map(|i| (i as f64 + 0.5) / 1000.0)
            .map(|u| Pit { below: u, at: u })
            .collect();
        let levels = Levels::recalibrated(&[0.5, 0.9], &pit).unwrap();
        for (got, want) in levels.bounds.iter().zip(&central(&[0.5, 0.9]).bounds) {
            assert!((got.0 - want.0).abs() < 1e-3 && (got.1 - want.1).abs() < 1e-3);
        }
        let few = Levels::recalibrated(&[0.9], &pit[..MIN_RECALIBRATION_VALUES - 1]).unwrap();
        assert_eq!(few, central(&[0.9]));
        assert!(Levels::central(&[1.0]).is_err());
        // A point mass: the CDF steps at its center; an unselected or missing value has no PIT.
        assert_eq!(mixture_cdf_each(&[(1.0, 0.0)], 1.0), (0.0, 1.0));
        assert_eq!(mixture_cdf_each(&[(1.0, 0.0), (3.0, 0.0)], 2.0), (0.5, 0.5));
        let p = pits(
            &[vec![0.0, 0.0, 0.0]],
            &[vec![1.0; 3]],
            &[0.0, f64::NAN, 5.0],
            &[true, true, false],
            None,
        );
        assert_eq!(
            p,
            vec![Pit {
                below: 0.5,
                at: 0.5
            }]
        );
    }

    #[test]
    fn readings_at_an_atom_count_by_their_share_and_the_running_hours_keep_theirs() {
        // A meter idle 30 % of the hours: the draws simulate 0 with no noise there and the
        // meter reads 0 (PIT [0, 1]); busy hours read N(10, 1) under a predictive N(10, 1.5²).
        // Recalibrated on F̄(u) = 0.3 u + 0.7 G(u), G(u) = Phi(1.5 Phi^-1(u)) the busy hours'
        // PIT distribution, the levels are [0.3075, 0.6925] and [0.1013, 0.8987] (solved with
        // scipy), so on fresh hours the PIT share is nominal, the busy hours hold G(b) - G(a)
        // = 54.9 % and 94.4 %, and the closed intervals, which hold every idle hour, 0.3 +
        // 0.7 (G(b) - G(a)) = 68.5 % and 96.1 %. (Forcing the closed share to nominal would
        // leave the busy hours (50 % - 30 %) / 70 % = 28.6 % of the 50 % interval.)
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut z = move || rng.sample::<f64, _>(StandardNormal);
        let n = 8000;
        let idle = |h: usize| h % 10 < 3;
        let sims = vec![(0..n)
            .map(|h| if idle(h) { 0.0 } else { 10.0 })
            .collect::<Vec<_>>()];
        let noise = vec![(0..n)
            .map(|h| if idle(h) { 0.0 } else { 1.5 })
            .collect::<Vec<_>>()];
        let mut meter = |h: usize| if idle(h) { 0.0 } else { 10.0 + z() };
        let fit: Vec<f64> = (0..n).map(&mut meter).collect();
        let fresh: Vec<f64> = (0..n).map(&mut meter).collect();
        let pit = pits(&sims, &noise, &fit, &vec![true; n], None);
        assert_eq!(
            pit[0],
            Pit {
                below: 0.0,
                at: 1.0
            }
        );
        let levels = Levels::recalibrated(&[0.5, 0.9], &pit).unwrap();
        let want = [(0.3075, 0.6925), (0.1013, 0.8987)];
        for (got, want) in levels.bounds.iter().zip(want) {
            assert!((got.0 - want.0).abs() < 0.01 && (got.1 - want.1).abs() < 0.01);
        }
        let iv = intervals(&sims, &noise, &levels).unwrap();
        let all = vec![true; n];
        let busy: Vec<bool> = (0..n).map(|h| !idle(h)).collect();
        let fresh_pits = pits(&sims, &noise, &fresh, &all, None);
        let expected = [(0.549, 0.685), (0.944, 0.961)];
        for (i, nominal) in [0.5, 0.9].into_iter().enumerate() {
            let c = coverage(nominal, &fresh, &iv.lower[i], &iv.upper[i], &all).unwrap();
            let c = c.with_pits(&fresh_pits, levels.bounds[i]);
            let pit_share = c.pit_fraction.expect("idle readings sit at an atom");
            assert!((pit_share - nominal).abs() < 0.02, "{nominal}: {c:?}");
            assert_eq!(c.calibration_fraction(), pit_share);
            assert!(
                (c.fraction - expected[i].1).abs() < 0.02,
                "{nominal}: {c:?}"
            );
            let running = coverage(nominal, &fresh, &iv.lower[i], &iv.upper[i], &busy).unwrap();
            assert!(
                (running.fraction - expected[i].0).abs() < 0.02,
                "{running:?}"
            );
            // Without a reading at an atom there is no PIT share: the fraction says it.
            let busy_pits = pits(&sims, &noise, &fresh, &busy, None);
            assert_eq!(
                running.with_pits(&busy_pits, levels.bounds[i]).pit_fraction,
                None
            );
        }
        // A meter that cannot read below 0 reads max(0, Y): a reading of 0 under N(0, 1) has
        // the PIT [0, 1/2], a positive one its CDF alone.
        let floor = pits(
            &[vec![0.0, 0.0]],
            &[vec![1.0; 2]],
            &[0.0, 1.0],
            &[true; 2],
            Some(0.0),
        );
        assert_eq!(
            floor[0],
            Pit {
                below: 0.0,
                at: 0.5
            }
        );
        assert!((floor[1].below - 0.841_344_746).abs() < 1e-6 && floor[1].below == floor[1].at);
    }

    #[test]
    fn a_model_above_a_mostly_idle_meter_gets_low_levels_that_hold_their_share() {
        // The RSF's cooling: idle 80 % of the hours where the model gives F(0) = 0.6, running
        // hours far below the model (PIT 0.01). F̄(u) = 0.8 min(u / 0.6, 1) + 0.2 [u >= 0.01]:
        // the 50 % levels are F̄^-1(0.25) = 0.0375 and F̄^-1(0.75) = 0.4125, and the readings'
        // PIT share inside them is 50 %.
        let pits: Vec<Pit> = (0..100)
            .map(|h| match h % 10 < 8 {
                true => Pit {
                    below: 0.0,
                    at: 0.6,
                },
                false => Pit {
                    below: 0.01,
                    at: 0.01,
                },
            })
            .collect();
        let levels = Levels::recalibrated(&[0.5], &pits).unwrap();
        let (lo, hi) = levels.bounds[0];
        assert!(
            (lo - 0.0375).abs() < 1e-9 && (hi - 0.4125).abs() < 1e-9,
            "{lo} {hi}"
        );
        assert!((pit_coverage(&pits, (lo, hi)) - 0.5).abs() < 1e-9);
        // Without atoms the quantile is the smallest PIT with at least the share at or below.
        let points: Vec<Pit> = [0.4, 0.1, 0.3, 0.2]
            .map(|u| Pit { below: u, at: u })
            .to_vec();
        assert!((pit_quantile(&points, 0.5) - 0.2).abs() < 1e-9);
        assert!((pit_quantile(&points, 0.51) - 0.3).abs() < 1e-9);
        assert_eq!(pit_quantile(&points, 0.0), 0.0);
        assert!(pit_quantile(&[], 0.5).is_nan());
    }

    #[test]
    fn one_center_gives_the_normal_quantiles() {
        // N(10, 2²): the 5 % and 95 % quantiles are 10 -+ 1.644854 * 2.
        let q = mixture_quantile(&[10.0], 2.0, 0.95);
        assert!((q - (10.0 + 2.0 * 1.6448536269514722)).abs() < 1e-6, "{q}");
        assert!((mixture_quantile(&[10.0], 2.0, 0.5) - 10.0).abs() < 1e-6);
        // Two far-apart centers: the median lies between them, each tail follows its center.
        let q = mixture_quantile(&[0.0, 100.0], 1.0, 0.25);
        assert!((q - (-0.0)).abs() < 1e-6, "{q}");
        // No noise: the centers' own quantile.
        let q = mixture_quantile(&[1.0, 2.0, 3.0, 4.0], 0.0, 0.6);
        assert!((q - 3.0).abs() < 1e-6, "{q}");
    }

    #[test]
    fn each_draw_carries_its_own_noise() {
        // Two draws at 0 with scales 1 and 3: the 95 % quantile q solves
        // (Phi(q) + Phi(q / 3)) / 2 = 0.95.
        let (one, three) = (vec![1.0; 2], vec![3.0; 2]);
        let per = [one.clone(), three];
        let iv = intervals(&[vec![0.0; 2], vec![0.0; 2]], &per, &central(&[0.9])).unwrap();
        let q = iv.upper[0][0];
        assert!(
            ((norm_cdf(q) + norm_cdf(q / 3.0)) / 2.0 - 0.95).abs() < 1e-8,
            "{q}"
        );
        assert!((iv.lower[0][1] + q).abs() < 1e-6 && iv.median[0].abs() < 1e-6);
        // Equal scales per draw are the mixture of one scale.
        let sims = [vec![1.0, 2.0], vec![4.0, -1.0]];
        let each = intervals(&sims, &[one.clone(), one.clone()], &central(&[0.5, 0.9])).unwrap();
        for (h, centers) in [[1.0, 4.0], [2.0, -1.0]].iter().enumerate() {
            assert_eq!(each.median[h], mixture_quantile(centers, 1.0, 0.5));
            assert_eq!(each.upper[1][h], mixture_quantile(centers, 1.0, 0.95));
        }
        // A draw's series of the wrong length, or a scale series per draw missing, is refused.
        assert!(intervals(&sims, std::slice::from_ref(&one), &central(&[0.9])).is_err());
        assert!(intervals(&sims, &[vec![1.0], vec![1.0]], &central(&[0.9])).is_err());
    }

    #[test]
    fn per_draw_noise_holds_where_the_draws_sit_off_the_meter() {
        // The meter is truth + N(0, 0.5²); the four draws all sit 1.0 above it (a model bias
        // the draws share), the estimate at the truth. The estimate's residual scale (0.5)
        // around the biased draws holds far fewer hours than nominal; each draw's own residual
        // scale (sqrt(0.25 + 1) = 1.118, the bias in its residuals) holds at least nominal:
        // P(|1 - 0.5 z| < 1.645 * 1.118) = 95.3 % at 90 %.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let n = 4000;
        let mut z = move || rng.sample::<f64, _>(StandardNormal);
        let truth: Vec<f64> = (0..n).map(|h| 10.0 + (h as f64 / 24.0).sin()).collect();
        let y: Vec<f64> = truth.iter().map(|t| t + 0.5 * z()).collect();
        let sims: Vec<Vec<f64>> = (0..4)
            .map(|_| truth.iter().map(|t| t + 1.0).collect())
            .collect();
        let all = vec![true; n];
        let at_estimate = ErrorModel::Constant.scales(&y, &truth, &all).unwrap();
        let each: Vec<Vec<f64>> = (sims.iter())
            .map(|s| ErrorModel::Constant.scales(&y, s, &all).unwrap())
            .collect();
        let cover = |noise: &[Vec<f64>]| {
            let iv = intervals(&sims, noise, &central(&[0.9])).unwrap();
            coverage(0.9, &y, &iv.lower[0], &iv.upper[0], &all).unwrap()
        };
        let shared = cover(&vec![at_estimate; sims.len()]);
        let own = cover(&each);
        // P(|1 - 0.5 z| < 0.822) = Phi(-0.356) - Phi(-3.644) = 36.1 %.
        assert!((shared.fraction - 0.361).abs() < 0.025, "{shared:?}");
        assert!((own.fraction - 0.953).abs() < 0.015, "{own:?}");
    }

    #[test]
    fn ar1_sum_variance_is_the_double_sum() {
        let s = [1.0, 2.0, 0.5, 3.0, 1.5];
        for phi in [0.0, 0.5, 0.9, -0.3] {
            let mut brute = 0.0;
            for i in 0..s.len() {
                for j in 0..s.len() {
                    brute += s[i] * s[j] * f64::powi(phi, (i as i32 - j as i32).abs());
                }
            }
            assert!(
                (ar1_sum_variance(&s, phi) - brute).abs() < 1e-12,
                "phi {phi}"
            );
        }
        // Independent hours: the sum of variances.
        assert_eq!(ar1_sum_variance(&s, 0.0), 1.0 + 4.0 + 0.25 + 9.0 + 2.25);
    }

    #[test]
    fn daily_totals_of_autocorrelated_residuals_need_the_ar1_noise() {
        // Data = truth + AR(1) noise (phi 0.9, sd 1) over 1,000 days; one draw at the truth.
        // Daily totals' 90 % intervals hold about 90 % of the days with the AR(1) noise of the
        // sum (sd about 17 for 24 hours at phi 0.9), and far fewer as if hours were independent
        // (sd sqrt(24) = 4.9).
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut z = move || rng.sample::<f64, _>(StandardNormal);
        let (days, phi) = (1000, 0.9f64);
        let n = 24 * days;
        let truth: Vec<f64> = (0..n)
            .map(|h| 20.0 + 5.0 * ((h % 24) as f64 / 4.0).sin())
            .collect();
        let mut e = z();
        let y: Vec<f64> = truth
            .iter()
            .map(|t| {
                e = phi * e + (1.0 - phi * phi).sqrt() * z();
                t + e
            })
            .collect();
        let scales = vec![1.0; n];
        let z_hat: Vec<f64> = y.iter().zip(&truth).map(|(y, t)| y - t).collect();
        let phi_hat = lag1_autocorrelation(&z_hat);
        assert!((phi_hat - phi).abs() < 0.01, "{phi_hat}");
        let periods: Vec<std::ops::Range<usize>> = (0..days).map(|d| 24 * d..24 * d + 24).collect();
        let (totals, all) = period_totals(&y, &vec![true; n], &periods);
        let judge = |phi: f64| {
            let m = period_mixture(
                std::slice::from_ref(&truth),
                std::slice::from_ref(&scales),
                phi,
                &periods,
            )
            .unwrap();
            let iv = intervals(&m.centers, &m.scales, &central(&[0.9])).unwrap();
            coverage(0.9, &totals, &iv.lower[0], &iv.upper[0], &all).unwrap()
        };
        let (ar1, independent) = (judge(phi_hat), judge(0.0));
        assert_eq!(ar1.hours, days);
        assert!((ar1.fraction - 0.9).abs() < 0.03, "AR(1): {ar1:?}");
        assert!(independent.fraction < 0.5, "independent: {independent:?}");
        // A day with a missing hour is no total; a day outside the selection does not count.
        let mut gappy = y.clone();
        gappy[5] = f64::NAN;
        let mut select = vec![true; n];
        select[30] = false;
        let (t, a) = period_totals(&gappy, &select, &periods[..3]);
        assert!(t[0].is_nan() && t[1].is_finite() && t[2].is_finite());
        assert_eq!(a, [true, false, true]);
    }

    #[test]
    fn coverage_counts_known_hours() {
        let y = [1.0, 2.0, 3.0, f64::NAN, 5.0];
        let lo = [0.0, 2.5, 3.0, 0.0, 4.0];
        let hi = [2.0, 3.0, 4.0, 9.0, 4.5];
        let c = coverage(0.9, &y, &lo, &hi, &[true, true, true, true, false]).unwrap();
        // Hours 0 and 2 inside (a bound counts), 1 outside, 3 missing, 4 not selected.
        assert_eq!(c.hours, 3);
        assert!((c.fraction - 2.0 / 3.0).abs() < 1e-12);
        assert!((c.mean_width - (2.0 + 0.5 + 1.0) / 3.0).abs() < 1e-12);
        assert!((c.relative_width.unwrap() - 3.5 / 6.0).abs() < 1e-12);
        assert!(coverage(0.9, &y, &lo, &hi, &[false; 5]).is_none());
        // All measured values 0: no relative width.
        let zero = coverage(0.5, &[0.0], &[0.0], &[1.0], &[true]).unwrap();
        assert!(zero.relative_width.is_none());
    }

    #[test]
    fn intervals_of_a_known_model_cover_their_nominal_share() {
        // Data = truth + N(0, 0.3²) (what the parameters leave uncertain) + N(0, 0.5²) (noise);
        // the draws scatter the truth by N(0, 0.3²) and the noise scale is 0.5: the predictive
        // is the data's own distribution, so the 50 % and 90 % intervals hold 50 % and 90 % of
        // the hours within sampling error (4,000 hours: +-2.5 points is over 3 sd).
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = 4000;
        let mut z = move || rng.sample::<f64, _>(StandardNormal);
        let truth: Vec<f64> = (0..n).map(|h| 10.0 + (h as f64 / 24.0).sin()).collect();
        let y: Vec<f64> = truth.iter().map(|t| t + 0.3 * z() + 0.5 * z()).collect();
        let sims: Vec<Vec<f64>> = (0..100)
            .map(|_| truth.iter().map(|t| t + 0.3 * z()).collect())
            .collect();
        let s = vec![0.5; n];
        let iv = intervals(&sims, &vec![s.clone(); sims.len()], &central(&[0.5, 0.9])).unwrap();
        for (i, nominal) in [0.5, 0.9].into_iter().enumerate() {
            let c = coverage(nominal, &y, &iv.lower[i], &iv.upper[i], &vec![true; n]).unwrap();
            assert!((c.fraction - nominal).abs() < 0.025, "{nominal}: {c:?}");
        }
        // Without the draws' spread (the truth alone), the 90 % interval is too narrow:
        // P(|N(0, 0.34)| < 1.645 * 0.5) = 84.1 %.
        let one = intervals(
            std::slice::from_ref(&truth),
            std::slice::from_ref(&s),
            &central(&[0.9]),
        );
        let one = one.unwrap();
        let c = coverage(0.9, &y, &one.lower[0], &one.upper[0], &vec![true; n]).unwrap();
        assert!((c.fraction - 0.841).abs() < 0.02, "{c:?}");
        // The constant scale of the residuals at the truth is their root mean square.
        let r = ErrorModel::Constant
            .scales(&y, &truth, &vec![true; n])
            .unwrap();
        assert!((r[0] - 0.34f64.sqrt()).abs() < 0.02, "{}", r[0]);
    }

    #[test]
    fn level_scales_follow_the_size_of_the_simulated_value() {
        // Idle hours (simulated 0, residual 0.1) and busy hours (simulated 10, residual 2):
        // each gets its own bin's scale, also for hours that were not fitted.
        let n = 1000;
        let sim: Vec<f64> = (0..n)
            .map(|h| if h % 2 == 0 { 0.0 } else { 10.0 })
            .collect();
        let y: Vec<f64> = (0..n)
            .map(|h| {
                sim[h] + if h % 2 == 0 { 0.1 } else { 2.0 } * if h % 4 < 2 { 1.0 } else { -1.0 }
            })
            .collect();
        let fit: Vec<bool> = (0..n).map(|h| h < 800).collect();
        let s = ErrorModel::Level.scales(&y, &sim, &fit).unwrap();
        assert!(
            (s[0] - 0.1).abs() < 1e-12 && (s[1] - 2.0).abs() < 1e-12,
            "{:?}",
            &s[..2]
        );
        assert!((s[998] - 0.1).abs() < 1e-12 && (s[999] - 2.0).abs() < 1e-12);
        // A value above every fitted one (an unfitted hour) takes the top bin's scale.
        let mut high = sim.clone();
        high[999] = 50.0;
        let s = ErrorModel::Level.scales(&y, &high, &fit).unwrap();
        assert!((s[999] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn tied_simulated_values_share_one_level_bin() {
        // 60 % of the hours idle at exactly 0 (residual 0.1 or 0.3 alternating through the
        // year), 40 % busy: every idle hour gets the scale of all idle hours together.
        let n = 1000;
        let sim: Vec<f64> = (0..n)
            .map(|h| if h < 600 { 0.0 } else { h as f64 })
            .collect();
        let y: Vec<f64> = (0..n)
            .map(|h| sim[h] + if h < 600 { [0.1, 0.3][h % 2] } else { 1.0 })
            .collect();
        let s = ErrorModel::Level.scales(&y, &sim, &vec![true; n]).unwrap();
        let idle = (0.5f64 * (0.01 + 0.09)).sqrt();
        assert!(
            (s[0] - idle).abs() < 1e-12 && (s[599] - idle).abs() < 1e-12,
            "{}",
            s[0]
        );
        assert!((s[700] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_zero_scale_far_from_zero_terminates() {
        let q = mixture_quantile(&[12345.678; 3], 0.0, 0.05);
        assert!((q - 12345.678).abs() < 1e-6, "{q}");
    }

    #[test]
    fn clamping_raises_bounds_below_the_floor() {
        let mut iv = intervals(&[vec![0.0, 5.0]], &[vec![1.0, 1.0]], &central(&[0.9])).unwrap();
        iv.clamp_below(0.0);
        assert_eq!(iv.lower[0][0], 0.0);
        assert!((iv.upper[0][0] - 1.6448536).abs() < 1e-6);
        assert!((iv.lower[0][1] - (5.0 - 1.6448536)).abs() < 1e-6);
    }

    #[test]
    fn hour_of_day_scales_follow_the_residuals_of_each_hour() {
        // Residuals of size 2 at 14:00 and 0 elsewhere, except one hour: the constant scale
        // is sqrt(mean r²), the hour-of-day scale 2 at 14:00.
        let n = 24 * 20;
        let y: Vec<f64> = (0..n)
            .map(|h| if h % 24 == 14 { 2.0 } else { 0.0 })
            .collect();
        let s = ErrorModel::HourOfDay
            .scales(&y, &vec![0.0; n], &vec![true; n])
            .unwrap();
        assert!((s[14] - 2.0).abs() < 1e-12 && s[13] == 0.0);
        let c = ErrorModel::Constant
            .scales(&y, &vec![0.0; n], &vec![true; n])
            .unwrap();
        assert!((c[0] - (4.0f64 / 24.0).sqrt()).abs() < 1e-12);
        // Hours not fitted do not count.
        let fit: Vec<bool> = (0..n).map(|h| h % 24 != 14).collect();
        let c = ErrorModel::Constant
            .scales(&y, &vec![0.0; n], &fit)
            .unwrap();
        assert_eq!(c[0], 0.0);
    }

    #[test]
    fn pooled_coverage_is_the_coverage_of_all_the_hours() {
        let y = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
        let lo = [0.5, 2.5, 2.0, 3.0, 5.5, 5.0, 6.0];
        let hi = [1.5, 3.5, 4.0, 5.0, 6.5, 8.0, 9.0];
        let sel =
            |r: std::ops::Range<usize>| -> Vec<bool> { (0..7).map(|h| r.contains(&h)).collect() };
        let all = coverage(0.9, &y, &lo, &hi, &[true; 7]).unwrap();
        let parts = [
            coverage(0.9, &y, &lo, &hi, &sel(0..3)).unwrap(),
            coverage(0.9, &y, &lo, &hi, &sel(3..7)).unwrap(),
        ];
        let pooled = pooled_coverage(&parts).unwrap();
        assert_eq!(pooled.hours, 7);
        assert!((pooled.fraction - all.fraction).abs() < 1e-12);
        assert!((pooled.mean_width - all.mean_width).abs() < 1e-12);
        assert!((pooled.relative_width.unwrap() - all.relative_width.unwrap()).abs() < 1e-12);
        assert!(pooled_coverage(&[]).is_none());
    }
}
