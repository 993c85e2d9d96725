//! Stage 7b, hourly posterior predictive intervals from EnergyPlus: which posterior draws are
//! simulated (keys [`FIRST_PREDICTIVE_KEY`].. in `validation/`, labels `predictive_NN`), and the
//! intervals, their coverage of the measured hours (calibration period and held-out period)
//! and their width, for `summary.json` and `validation/predictive_intervals.csv`.
//!
//! The draws are EnergyPlus at evenly spaced posterior draws (with the surrogate's error
//! carried, where a refinement round measured it, so that the surrogate's bias in parameter
//! space is in the spread); each draw's noise is the error model's scale of its own
//! EnergyPlus residuals over the calibration hours (`[validation] error_model`), so that a draw
//! whose simulation sits off the meter carries the wider noise its residuals show. The
//! intervals are then recalibrated on the calibration period (the mixture's quantiles at the
//! levels the measured hours' probability integral transforms say; Kuleshov et al. 2018), so
//! that a posterior whose draws spread wider than the meters (a tempered likelihood) or sit to
//! one side of them gives intervals that hold their nominal share there (of PIT, where a meter
//! reads at its floor: [`Coverage::pit_fraction`]): the held-out period is the independent
//! check, and the posterior predictive's own coverage is reported beside it
//! (`before_recalibration`). Numerics in
//! [`bemcal_stats::predictive`]; the driver has EnergyPlus simulate [`ChainSummary::predictive_candidates`]
//! and [`crate::summary::write_summary`] reads their runs once and calls [`assess`].
//!
//! Totals over days and months ([`TotalPeriod`]) get intervals too: the draws' sums with the
//! noise of a sum of AR(1) residuals (`phi` from EnergyPlus's standardised residuals at the
//! estimate), beside the same intervals as if hours were independent, which are too narrow
//! where the residuals are autocorrelated; both are judged on whole measured days and months.

use std::ops::Range;

use bemcal_stats::predictive::{
    coverage_miss, cross_validated_coverage, intervals, lag1_autocorrelation, mean_block_miss,
    period_mixture, period_totals, pits, pooled_coverage, sharpest_within, summed_width, Coverage,
    ErrorModel, Intervals, Levels,
};
use serde::{Deserialize, Serialize};

use bemcal_energyplus::HourlyOutputs;

use crate::calibration::Calibration;
use crate::chain_summary::ChainSummary;
use crate::design::saved_outputs;
use crate::error::{write_atomic, Error};
use crate::keys::{candidate_key, predictive_label, FALLBACKS, FIRST_PREDICTIVE_KEY};
use crate::output::timestamps;
use crate::project::ErrorModelSetting;
use crate::validation::Candidate;

/// The nominal levels of the intervals.
pub const LEVELS: [f64; 2] = [0.5, 0.9];

impl ChainSummary {
    /// The posterior draws EnergyPlus simulates for the predictive intervals, with their keys
    /// and labels.
    pub fn predictive_candidates(&self) -> Vec<(Candidate, String)> {
        self.predictive
            .iter()
            .enumerate()
            .map(|(j, x)| {
                (
                    Candidate {
                        rank: 0,
                        key: FIRST_PREDICTIVE_KEY + j,
                        values: x.clone(),
                    },
                    predictive_label(j),
                )
            })
            .collect()
    }
}

/// The predictive intervals' record in `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PredictiveReport {
    /// Posterior draws EnergyPlus simulated for the intervals.
    pub draws: usize,
    /// Draws it could not simulate (left out).
    pub failed: usize,
    /// Whether the draws carry the surrogate's error (`draws_with_surrogate_error.csv`).
    pub with_surrogate_error: bool,
    /// `[validation] error_model` for the meters it does not name (each meter's error model
    /// in `validation/predictive_intervals.csv`: its `error_model`).
    pub error_model: ErrorModelSetting,
    /// The held-out period, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<String>,
    /// Each meter's intervals.
    pub outputs: Vec<OutputPredictive>,
    /// Each meter read as bills: its intervals per bill.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bills: Vec<crate::bills::BillsPredictive>,
}

/// One meter's intervals.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct OutputPredictive {
    /// The calibrated output (and its meter).
    pub output: String,
    /// The error model of its intervals in `validation/predictive_intervals.csv`
    /// (`[validation] error_model`, with `auto` resolved: `cross_validation_favours`;
    /// `by_error_model`'s first). Absent from a summary written before error models per meter:
    /// the report's `error_model` then.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_model: Option<ErrorModel>,
    /// Root mean square residual of EnergyPlus at the estimate over the calibration hours (kWh).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub noise_kwh: f64,
    /// Coverage under each error model (the configured one first).
    pub by_error_model: Vec<ModelCoverage>,
    /// Lag-one autocorrelation of EnergyPlus's residuals at the estimate over the calibration
    /// hours, each standardised by the configured error model's scale.
    #[serde(default, deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub residual_phi: f64,
    /// Intervals of daily and monthly totals (the configured error model), with the AR(1)
    /// noise of a sum and as if hours were independent.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub totals: Vec<TotalsCoverage>,
    /// The error model the calibration period's months favour, each judged by intervals built
    /// without it ([`Favoured`]; `error_model = "auto"` takes it, `level` where it is
    /// absent). Absent from a summary written before it, and where no month could be judged (a
    /// calibration period of one month).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cross_validation_favours: Option<Favoured>,
    /// With a held-out period: the error model its hours favour ([`Favoured`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_favours: Option<Favoured>,
    /// A meter that cannot read below zero and reads zero in some hours: the configured error
    /// model's coverage on the hours it runs ([`RunningHours`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub running: Option<RunningHours>,
}

/// The coverage of a meter's hourly intervals on the hours it reads above zero, and how many
/// hours read zero. Where the predictive has an atom at zero (the draws idle, or `max(0, Y)`
/// of a meter that cannot read below it), a reading of zero lies inside every interval whose
/// lower bound is 0: a closed interval holds an atom's readings whole, not in its nominal
/// share, so the share of all hours inside exceeds nominal and the PIT share
/// ([`Coverage::pit_fraction`]) is the one to hold against it. These figures say how the
/// intervals do where the meter runs: near nominal where the predictive is calibrated and the
/// idle hours are foreseen (an hour the draws may find running or idle widens its interval
/// over both).
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct RunningHours {
    /// Share of the measured calibration hours that read zero.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub idle_in_sample: f64,
    /// The same over the held-out period (absent without one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub idle_held_out: Option<f64>,
    /// Coverage of the hours that read above zero, in-sample and held out.
    #[serde(flatten)]
    pub coverage: PeriodCoverage,
}

/// The share of the values of `measured` that `select` keeps (finite) that are zero; `None`
/// without such values.
fn idle_share(measured: &[f64], select: &[bool]) -> Option<f64> {
    let kept = (measured.iter().zip(select)).filter(|(y, s)| **s && y.is_finite());
    let (n, idle) = kept.fold((0usize, 0usize), |(n, i), (y, _)| {
        (n + 1, i + usize::from(*y == 0.0))
    });
    (n > 0).then(|| idle as f64 / n as f64)
}

/// The values of `measured` that `select` keeps and that are above zero.
fn running(measured: &[f64], select: &[bool]) -> Vec<bool> {
    (measured.iter().zip(select))
        .map(|(y, s)| *s && *y > 0.0)
        .collect()
}

/// [`RunningHours`] of meter `k` under intervals `iv`; `None` for a meter that can read below
/// zero or that never reads zero.
fn running_hours(
    inp: &crate::inputs::Inputs,
    k: usize,
    fit: &[bool],
    iv: &Intervals,
    non_negative: bool,
) -> Option<RunningHours> {
    if !non_negative {
        return None;
    }
    let idle_in_sample = idle_share(&inp.measured[k], fit)?;
    let idle_held_out = (inp.held_out.as_ref()).and_then(|h| idle_share(&h.measured[k], &h.hours));
    if idle_in_sample == 0.0 && idle_held_out.is_none_or(|s| s == 0.0) {
        return None;
    }
    let coverage = in_and_out(inp, k, fit, |m, hours| {
        level_coverage(iv, m, &running(m, hours))
    });
    Some(RunningHours {
        idle_in_sample,
        idle_held_out,
        coverage,
    })
}

/// Two error models whose coverage is within this many percentage points of each other
/// (summed over the 50 % and 90 % levels) count as equal: the narrower one is favoured.
pub const TIE_POINTS: f64 = 2.0;

/// The error model whose hourly intervals hold nearest nominal on a set of hours, the
/// narrower of those within [`TIE_POINTS`]
/// ([`bemcal_stats::predictive::sharpest_within`]): on the calibration period's months judged
/// out of time (`cross_validation_favours`, what `error_model = "auto"` takes), or on the
/// held-out hours (`held_out_favours`: a check of that choice, not a choice, since a model
/// chosen on them leaves their coverage no independent check).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Favoured {
    /// The favoured error model.
    pub error_model: ErrorModel,
    /// Its distance from nominal, percentage points over both levels (by cross-validation: the
    /// mean over the months, [`bemcal_stats::predictive::mean_block_miss`]).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub miss_points: f64,
    /// The same for the meter's configured error model (`auto`'s: its choice); `None` where
    /// it was not judged.
    pub configured_miss_points: Option<f64>,
}

/// [`Favoured`] of `candidates` `(error model, miss, summed width)`, with the miss of the one
/// `configured` names; `None` where none was judged.
fn favoured(
    candidates: impl Iterator<Item = (ErrorModel, f64, f64)>,
    configured: ErrorModelSetting,
) -> Option<Favoured> {
    let (models, (misses, widths)): (Vec<ErrorModel>, (Vec<f64>, Vec<f64>)) =
        candidates.map(|(m, miss, w)| (m, (miss, w))).unzip();
    let i = sharpest_within(&misses, &widths, TIE_POINTS)?;
    let configured = match configured {
        ErrorModelSetting::Fixed(m) => models.iter().position(|c| *c == m),
        ErrorModelSetting::Auto => Some(i),
    };
    Some(Favoured {
        error_model: models[i],
        miss_points: misses[i],
        configured_miss_points: configured.map(|c| misses[c]).filter(|m| m.is_finite()),
    })
}

/// An error model's hourly intervals judged month by month out of time: each month of the
/// calibration period by intervals whose noise scales and recalibration never saw it
/// ([`bemcal_stats::predictive::cross_validated_coverage`]).
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct CrossValidated {
    /// Months judged.
    pub months: usize,
    /// Coverage over all of them, one per level.
    pub coverage: Vec<Coverage>,
    /// The mean over the months of their coverage's distance from nominal, percentage points
    /// over both levels ([`bemcal_stats::predictive::mean_block_miss`]): what
    /// `error_model = "auto"` minimises.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub mean_month_miss_points: f64,
}

impl CrossValidated {
    /// The record of months judged `blocks` (one coverage per level each); `None` without one.
    pub fn of(blocks: &[Vec<Coverage>]) -> Option<CrossValidated> {
        let coverage: Vec<Coverage> = (0..blocks.first()?.len())
            .filter_map(|i| {
                let parts: Vec<Coverage> =
                    blocks.iter().filter_map(|b| b.get(i).copied()).collect();
                pooled_coverage(&parts)
            })
            .collect();
        Some(CrossValidated {
            months: blocks.len(),
            coverage,
            mean_month_miss_points: mean_block_miss(blocks),
        })
    }
}

/// What a total is taken over.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum TotalPeriod {
    /// Each day's total (24 hour slots).
    Day,
    /// Each calendar month's total.
    Month,
}

impl TotalPeriod {
    /// Its name, as `summary.json` writes it (`day`, `month`).
    pub fn as_str(self) -> &'static str {
        match self {
            TotalPeriod::Day => "day",
            TotalPeriod::Month => "month",
        }
    }

    /// The hour slots of every day or month of the grid.
    pub fn periods(self, hours: usize) -> Vec<Range<usize>> {
        match self {
            TotalPeriod::Day => (0..hours / 24).map(|d| 24 * d..24 * d + 24).collect(),
            TotalPeriod::Month => bemcal_weather::grid::CUM_DAYS
                .windows(2)
                .map(|w| 24 * w[0]..24 * w[1])
                .filter(|r| r.end <= hours)
                .collect(),
        }
    }
}

/// Coverage of the intervals of one kind of total (`hours` of each [`Coverage`] counts the
/// periods judged: those whose every hour is measured and in the period judged).
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TotalsCoverage {
    /// What the totals are taken over.
    pub period: TotalPeriod,
    /// With the AR(1) noise of a sum (`residual_phi`), recalibrated on the calibration
    /// period's whole days or months where it has
    /// [`bemcal_stats::predictive::MIN_RECALIBRATION_VALUES`] of them (the
    /// hourly intervals' rule; a year's months never do): the intervals to read.
    pub ar1: PeriodCoverage,
    /// The same before recalibration: the posterior predictive's own intervals. Absent from a
    /// summary written before recalibration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub before_recalibration: Option<PeriodCoverage>,
    /// As if the hours' noise were independent (`phi = 0`), not recalibrated: for comparison
    /// with `before_recalibration`.
    pub independent: PeriodCoverage,
}

/// 50 % and 90 % coverage, in-sample and held out.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PeriodCoverage {
    /// Over the calibration period, one per level.
    pub in_sample: Vec<Coverage>,
    /// Empty without a held-out period.
    pub held_out: Vec<Coverage>,
}

/// Coverage of the 50 % and 90 % hourly intervals under one error model.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ModelCoverage {
    /// The error model the intervals use.
    pub error_model: ErrorModel,
    /// Their coverage, in-sample and held out (the recalibrated intervals: in-sample about
    /// nominal by construction).
    #[serde(flatten)]
    pub coverage: PeriodCoverage,
    /// The mixture's probability levels of each interval's lower and upper bound, recalibrated
    /// on the calibration period (`[0.25, 0.75]` and `[0.05, 0.95]` where it had too few
    /// hours). Empty in a summary written before recalibration.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub levels: Vec<[f64; 2]>,
    /// Coverage of the posterior predictive's own central intervals, before recalibration:
    /// how far the posterior's spread is from the meters'.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub before_recalibration: Option<PeriodCoverage>,
    /// The calibration period judged month by month out of time ([`CrossValidated`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cross_validated: Option<CrossValidated>,
}

/// EnergyPlus at the predictive draws, as validation saved them (draws it could not simulate
/// are left out).
pub fn draw_runs(cal: &Calibration, chains: &ChainSummary) -> Vec<HourlyOutputs> {
    let vdir = cal.out.validation();
    chains
        .predictive_candidates()
        .iter()
        .filter_map(|(c, _)| saved_outputs(&vdir, c.key, &cal.inputs.plan.values(&c.values)))
        .collect()
}

/// EnergyPlus at the estimate, as validation saved it. The estimate was settled on one of the
/// validation candidates (a fallback where EnergyPlus failed at the MAP, a predictive draw or
/// a mapped point where `estimate = "best_simulated"` chose one): the run whose values are
/// the estimate's.
pub fn run_at_estimate(cal: &Calibration, chains: &ChainSummary) -> Option<HourlyOutputs> {
    let vdir = cal.out.validation();
    let values = cal.inputs.plan.values(&chains.estimate);
    let predictive = chains
        .predictive_candidates()
        .into_iter()
        .map(|(c, _)| c.key);
    let mapped = (chains.estimate_choice.iter())
        .flat_map(|c| &c.mapping)
        .flat_map(|s| s.points.iter().map(|p| p.key))
        .collect::<Vec<_>>();
    (0..=FALLBACKS)
        .map(candidate_key)
        .chain(predictive)
        .chain(mapped)
        .find_map(|key| saved_outputs(&vdir, key, &values))
}

/// The predictive intervals of a finished validation from EnergyPlus at the estimate and at
/// the predictive draws (`run_at_estimate`, `draw_runs`): writes
/// `validation/predictive_intervals.csv` and returns the report (None when no draw or the
/// estimate's run is missing).
pub fn assess(
    cal: &Calibration,
    chains: &ChainSummary,
    at_estimate: Option<&HourlyOutputs>,
    runs: &[HourlyOutputs],
) -> Result<Option<PredictiveReport>, Error> {
    let inp = &cal.inputs;
    let candidates = chains.predictive_candidates();
    let Some(at_estimate) = at_estimate.filter(|_| !runs.is_empty()) else {
        return Ok(None);
    };
    let fit = inp.calibration_hours();
    let mut outputs = vec![];
    let mut bills = vec![];
    let mut columns: Vec<(String, Vec<f64>)> = vec![];
    let error_models = &cal.project.validation.error_model;
    let months = TotalPeriod::Month.periods(fit.len());
    for (k, name) in inp.outputs.iter().enumerate() {
        if let Some(b) = &inp.bills[k] {
            // Hourly intervals need hourly readings: a meter read as bills has its bills'.
            let sims: Vec<Vec<f64>> = (runs.iter())
                .map(|o| inp.with_base(k, o.get(name).expect("model output")))
                .collect();
            bills.extend(b.predictive(name, &sims, error_models.of(name)));
            continue;
        }
        let setting = error_models.of(name);
        let series = |o: &HourlyOutputs| inp.with_base(k, o.get(name).expect("model output"));
        let sims: Vec<Vec<f64>> = runs.iter().map(series).collect();
        let estimate = series(at_estimate);
        // An energy meter does not read below zero: its intervals are those of max(0, Y).
        let meter = inp.meter(k);
        let non_negative = !meter.iter().any(|v| *v < 0.0);
        let mut judged = judge_error_models(inp, k, &sims, &fit, &months, non_negative)?;
        let cross_validation_favours = favoured(
            (judged.iter().map(|j| &j.0)).map(|m| {
                let cv = m.cross_validated.as_ref();
                let miss = cv.map_or(f64::NAN, |c| c.mean_month_miss_points);
                (
                    m.error_model,
                    miss,
                    cv.map_or(f64::NAN, |c| summed_width(&c.coverage)),
                )
            }),
            setting,
        );
        let configured = match setting {
            ErrorModelSetting::Fixed(m) => m,
            ErrorModelSetting::Auto => {
                cross_validation_favours.map_or(ErrorModel::Level, |f| f.error_model)
            }
        };
        // The configured error model's first.
        judged.sort_by_key(|j| j.0.error_model != configured);
        let mut judged = judged.into_iter();
        let (first, configured_noise, iv) = judged.next().expect("three error models");
        let by_error_model: Vec<ModelCoverage> =
            std::iter::once(first).chain(judged.map(|j| j.0)).collect();
        columns.push((format!("{name}_measured"), meter.clone()));
        columns.push((format!("{name}_q5"), iv.lower[1].clone()));
        columns.push((format!("{name}_q25"), iv.lower[0].clone()));
        columns.push((format!("{name}_q50"), iv.median.clone()));
        columns.push((format!("{name}_q75"), iv.upper[0].clone()));
        columns.push((format!("{name}_q95"), iv.upper[1].clone()));
        let running = running_hours(inp, k, &fit, &iv, non_negative);
        // The estimate's residual scales: its root mean square residual, and the standardised
        // residuals whose autocorrelation the totals' noise takes.
        let estimate_scales = |m: ErrorModel| m.scales(&inp.measured[k], &estimate, &fit);
        let noise_kwh =
            (estimate_scales(ErrorModel::Constant)?.first().copied()).unwrap_or(f64::NAN);
        let scales = estimate_scales(configured)?;
        let standardised: Vec<f64> = (0..fit.len())
            .map(|t| match fit[t] {
                true => (inp.measured[k][t] - estimate[t]) / scales[t],
                false => f64::NAN,
            })
            .collect();
        let residual_phi = lag1_autocorrelation(&standardised);
        let noise = &configured_noise;
        let totals = totals_coverage(inp, k, &fit, &sims, noise, residual_phi, non_negative)?;
        let held_out_favours = favoured(
            by_error_model.iter().map(|m| {
                let held = &m.coverage.held_out;
                (m.error_model, coverage_miss(held), summed_width(held))
            }),
            ErrorModelSetting::Fixed(configured),
        );
        outputs.push(OutputPredictive {
            output: name.clone(),
            error_model: Some(configured),
            noise_kwh,
            by_error_model,
            residual_phi,
            totals,
            cross_validation_favours,
            held_out_favours,
            running,
        });
    }
    write_intervals_csv(cal, &fit, &columns)?;
    Ok(Some(PredictiveReport {
        draws: runs.len(),
        failed: candidates.len() - runs.len(),
        with_surrogate_error: chains.surrogate_error.is_some(),
        error_model: error_models.default,
        held_out: inp.held_out.as_ref().map(|h| h.period.clone()),
        outputs,
        bills,
    }))
}

/// Every error model's intervals for output `k`, in the order of [`ErrorModel::ALL`]: its
/// coverage (recalibrated, before recalibration, cross-validated by month), the noise scales of
/// each draw (`sims`) and the recalibrated intervals.
#[allow(clippy::type_complexity)]
fn judge_error_models(
    inp: &crate::inputs::Inputs,
    k: usize,
    sims: &[Vec<f64>],
    fit: &[bool],
    months: &[Range<usize>],
    non_negative: bool,
) -> Result<Vec<(ModelCoverage, Vec<Vec<f64>>, Intervals)>, Error> {
    let floor = non_negative.then_some(0.0);
    let mut judged = vec![];
    for model in ErrorModel::ALL {
        // Each draw's noise is the error model's scale of its own residuals.
        let noise = (sims.iter())
            .map(|s| model.scales(&inp.measured[k], s, fit))
            .collect::<Result<Vec<_>, _>>()?;
        let (posterior, central) = bounded(sims, &noise, None, non_negative)?;
        let calibration = Some((inp.measured[k].as_slice(), fit));
        let (iv, levels) = bounded(sims, &noise, calibration, non_negative)?;
        let recalibrated = Judge {
            iv: &iv,
            levels: &levels,
            centers: sims,
            scales: &noise,
            floor,
        };
        let own = Judge {
            iv: &posterior,
            levels: &central,
            ..recalibrated
        };
        let blocks =
            cross_validated_coverage(sims, &inp.measured[k], fit, months, model, &LEVELS, floor)?;
        let coverage = ModelCoverage {
            error_model: model,
            coverage: in_and_out(inp, k, fit, |m, hours| recalibrated.coverage(m, hours)),
            levels: levels.bounds.iter().map(|&(lo, hi)| [lo, hi]).collect(),
            before_recalibration: Some(in_and_out(inp, k, fit, |m, hours| own.coverage(m, hours))),
            cross_validated: CrossValidated::of(&blocks),
        };
        judged.push((coverage, noise, iv));
    }
    Ok(judged)
}

/// The intervals at [`LEVELS`] of the mixture of `centers` with their noise `scales` (per
/// draw, per value), with the levels they were taken at: central, or recalibrated on the
/// values of `calibration`'s measured series that its selection keeps (their PITs,
/// [`Levels::recalibrated`]); raised to 0 for a meter that cannot read below it.
fn bounded(
    centers: &[Vec<f64>],
    scales: &[Vec<f64>],
    calibration: Option<(&[f64], &[bool])>,
    non_negative: bool,
) -> Result<(Intervals, Levels), Error> {
    let levels = match calibration {
        Some((measured, select)) => {
            let floor = non_negative.then_some(0.0);
            Levels::recalibrated(&LEVELS, &pits(centers, scales, measured, select, floor))?
        }
        None => Levels::central(&LEVELS)?,
    };
    let mut iv = intervals(centers, scales, &levels)?;
    if non_negative {
        iv.clamp_below(0.0);
    }
    Ok((iv, levels))
}

/// Coverage of the intervals of daily and monthly totals of meter `k` (EnergyPlus at the draws
/// `sims`, with their hourly `noise`), with the residuals' lag-1 autocorrelation `phi` in the
/// noise of a sum and as if hours were independent.
fn totals_coverage(
    inp: &crate::inputs::Inputs,
    k: usize,
    fit: &[bool],
    sims: &[Vec<f64>],
    noise: &[Vec<f64>],
    phi: f64,
    non_negative: bool,
) -> Result<Vec<TotalsCoverage>, Error> {
    [TotalPeriod::Day, TotalPeriod::Month]
        .into_iter()
        .map(|period| {
            let periods = period.periods(fit.len());
            let judge = |phi: f64, recalibrate: bool| -> Result<PeriodCoverage, Error> {
                let m = period_mixture(sims, noise, phi, &periods)?;
                let totals = recalibrate.then(|| period_totals(&inp.measured[k], fit, &periods));
                let calibration =
                    (totals.as_ref()).map(|(t, whole)| (t.as_slice(), whole.as_slice()));
                let (iv, levels) = bounded(&m.centers, &m.scales, calibration, non_negative)?;
                let judge = Judge {
                    iv: &iv,
                    levels: &levels,
                    centers: &m.centers,
                    scales: &m.scales,
                    floor: non_negative.then_some(0.0),
                };
                Ok(in_and_out(inp, k, fit, |m, hours| {
                    let (totals, whole) = period_totals(m, hours, &periods);
                    judge.coverage(&totals, &whole)
                }))
            };
            Ok(TotalsCoverage {
                period,
                ar1: judge(phi, true)?,
                before_recalibration: Some(judge(phi, false)?),
                independent: judge(0.0, false)?,
            })
        })
        .collect()
}

/// Coverage of the intervals `iv` at each of their levels on the values of `measured` that
/// `select` keeps, each counted whole ([`Intervals::level_coverage`], levels without a value
/// left out).
fn level_coverage(iv: &Intervals, measured: &[f64], select: &[bool]) -> Vec<Coverage> {
    iv.level_coverage(measured, select)
        .into_iter()
        .flatten()
        .collect()
}

/// Intervals with the mixture they were taken from, to judge them by.
struct Judge<'a> {
    iv: &'a Intervals,
    levels: &'a Levels,
    /// Each draw's values.
    centers: &'a [Vec<f64>],
    /// Each draw's noise scales.
    scales: &'a [Vec<f64>],
    /// The meter's floor (0 for one that cannot read below it).
    floor: Option<f64>,
}

impl Judge<'_> {
    /// The coverage of the values of `measured` that `select` keeps, with the PIT share where
    /// some of them read at an atom ([`Intervals::coverage`]).
    fn coverage(&self, measured: &[f64], select: &[bool]) -> Vec<Coverage> {
        let pits = pits(self.centers, self.scales, measured, select, self.floor);
        self.iv.coverage(self.levels, measured, select, &pits)
    }
}

/// `cover` of meter `k` over the calibration period (`fit`) and, where one is held out, over
/// the held-out period.
fn in_and_out(
    inp: &crate::inputs::Inputs,
    k: usize,
    fit: &[bool],
    cover: impl Fn(&[f64], &[bool]) -> Vec<Coverage>,
) -> PeriodCoverage {
    PeriodCoverage {
        in_sample: cover(&inp.measured[k], fit),
        held_out: inp
            .held_out
            .as_ref()
            .map_or(vec![], |h| cover(&h.measured[k], &h.hours)),
    }
}

/// `validation/predictive_intervals.csv`: per hour, whether it is held out, then per meter the
/// measured value and the 5/25/50/75/95 % predictive quantiles.
fn write_intervals_csv(
    cal: &Calibration,
    fit: &[bool],
    columns: &[(String, Vec<f64>)],
) -> Result<(), Error> {
    let inp = &cal.inputs;
    let mut s = String::from("timestamp,held_out");
    for (name, _) in columns {
        s.push(',');
        s.push_str(name);
    }
    s.push('\n');
    for (h, ts) in timestamps(inp.year, fit.len()) {
        s.push_str(&ts);
        s.push_str(if fit[h] { ",0" } else { ",1" });
        for (_, v) in columns {
            let x = v[h];
            if x.is_finite() {
                s.push_str(&format!(",{x:.4}"));
            } else {
                s.push(',');
            }
        }
        s.push('\n');
    }
    write_atomic(
        &cal.out.validation().join("predictive_intervals.csv"),
        s.as_bytes(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_favoured_error_model_is_nearest_nominal_and_auto_reports_its_own_miss() {
        let cov = |f50: f64, f90: f64, hours: usize| {
            vec![
                Coverage {
                    nominal: 0.5,
                    hours,
                    fraction: f50,
                    mean_width: 1.0,
                    relative_width: None,
                    pit_fraction: None,
                },
                Coverage {
                    nominal: 0.9,
                    hours,
                    fraction: f90,
                    mean_width: 3.0,
                    relative_width: None,
                    pit_fraction: None,
                },
            ]
        };
        // Two months: 4 and 2 points from nominal over 100 and 300 hours, 2.5 on average.
        let cv = CrossValidated::of(&[cov(0.52, 0.92, 100), cov(0.49, 0.91, 300)]).unwrap();
        assert_eq!(cv.months, 2);
        assert!((cv.mean_month_miss_points - 2.5).abs() < 1e-9);
        assert!((cv.coverage[0].fraction - 0.4975).abs() < 1e-12);
        assert_eq!(cv.coverage[1].hours, 400);
        assert!(CrossValidated::of(&[]).is_none());
        let candidates = [
            (ErrorModel::Constant, 9.0, 4.0),
            (ErrorModel::HourOfDay, 3.0, 5.0),
            (ErrorModel::Level, 4.5, 4.5),
        ];
        // Within 2 points of the nearest, the narrower.
        let fixed = favoured(
            candidates.into_iter(),
            ErrorModelSetting::Fixed(ErrorModel::Constant),
        );
        assert_eq!(
            fixed,
            Some(Favoured {
                error_model: ErrorModel::Level,
                miss_points: 4.5,
                configured_miss_points: Some(9.0),
            })
        );
        let auto = favoured(candidates.into_iter(), ErrorModelSetting::Auto).unwrap();
        assert_eq!(auto.configured_miss_points, Some(4.5));
        let none = [(ErrorModel::Level, f64::NAN, 1.0)];
        assert_eq!(favoured(none.into_iter(), ErrorModelSetting::Auto), None);
    }

    #[test]
    fn running_hours_leave_out_the_readings_at_zero() {
        let measured = [0.0, 0.0, 5.0, f64::NAN, 7.0, 0.0];
        let select = [true, true, true, true, true, false];
        assert_eq!(idle_share(&measured, &select), Some(0.5));
        assert_eq!(idle_share(&measured, &[false; 6]), None);
        let kept = running(&measured, &select);
        assert_eq!(kept, [false, false, true, false, true, false]);
        // The idle hours sit inside the interval from 0; of the running hours one of two.
        let iv = Intervals {
            levels: LEVELS.to_vec(),
            lower: vec![vec![0.0; 6]; 2],
            upper: vec![vec![6.0; 6]; 2],
            median: vec![3.0; 6],
        };
        let all = level_coverage(&iv, &measured, &select);
        let runs = level_coverage(&iv, &measured, &kept);
        assert_eq!((all[0].hours, all[0].fraction), (4, 0.75));
        assert_eq!((runs[0].hours, runs[0].fraction), (2, 0.5));
    }
}
