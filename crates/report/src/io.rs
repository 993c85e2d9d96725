//! Everything the report reads from disk: the calibration folder written by
//! `bemcal calibrate --out DIR` and the optional pre-calibration folder written by
//! `bemcal precalibrate --out PDIR`. The rest of the crate is pure (data in, text out).
//!
//! The structs mirror the files' formats (`summary.json` is `bemcal_calibrate::Summary`); they are
//! deliberately lenient (optional sections default to empty) so a report can still be written for
//! a partial folder, but the files the report cannot do without are required and their absence is
//! an error naming the file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::ReportError;

/// A parameter's triangular prior (`summary.json` `parameters[]`).
#[derive(Debug, Clone, Deserialize)]
pub struct PriorInfo {
    /// Parameter name.
    pub name: String,
    /// Unit.
    #[serde(default)]
    pub unit: String,
    /// Lower bound of the triangular prior.
    pub prior_min: f64,
    /// Mode of the triangular prior.
    pub prior_mode: f64,
    /// Upper bound of the triangular prior.
    pub prior_max: f64,
}

/// A parameter's posterior summary (`summary.json` `posterior.parameters[]`).
#[derive(Debug, Clone, Deserialize)]
pub struct PosteriorInfo {
    /// Parameter name.
    pub name: String,
    /// Posterior mean.
    pub mean: f64,
    /// Posterior standard deviation.
    pub sd: f64,
    /// Posterior median.
    pub median: f64,
    /// 5 % quantile.
    pub q5: f64,
    /// 95 % quantile.
    pub q95: f64,
    /// Value at the MAP draw.
    #[serde(default = "nan")]
    pub map: f64,
    /// Rank-normalised split R-hat.
    #[serde(default = "nan")]
    pub rhat: f64,
    /// Bulk effective sample size.
    #[serde(default = "nan")]
    pub ess_bulk: f64,
    /// Tail effective sample size.
    #[serde(default = "nan")]
    pub ess_tail: f64,
    /// Posterior 90 % interval width over the prior's (1 = the data did not inform it).
    #[serde(default = "nan")]
    pub width_ratio: f64,
}

fn nan() -> f64 {
    f64::NAN
}

/// A pair of parameters with a strong posterior correlation.
#[derive(Debug, Clone, Deserialize)]
pub struct CorrelatedPair {
    /// First parameter.
    pub a: String,
    /// Second parameter.
    pub b: String,
    /// Pearson correlation of the draws.
    pub rho: f64,
}

/// `summary.json` `posterior`.
#[derive(Debug, Clone, Deserialize)]
pub struct PosteriorBlock {
    /// Per parameter, in prior order.
    pub parameters: Vec<PosteriorInfo>,
    /// Pairs with |rho| > 0.8.
    #[serde(default)]
    pub correlated_pairs: Vec<CorrelatedPair>,
    /// Largest R-hat.
    #[serde(default = "nan")]
    pub max_rhat: f64,
    /// Smallest bulk ESS.
    #[serde(default = "nan")]
    pub min_ess_bulk: f64,
}

/// ASHRAE Guideline 14 metrics of one output.
#[derive(Debug, Clone, Deserialize)]
pub struct OutputMetrics {
    /// Output name.
    pub output: String,
    /// Hours used.
    #[serde(default)]
    pub n: usize,
    /// Mean of the measured values.
    #[serde(default = "nan")]
    pub mean_measured: f64,
    /// NMBE, %.
    pub nmbe: f64,
    /// CV-RMSE, %.
    pub cv_rmse: f64,
    /// Monthly Guideline 14 over the calibration period.
    #[serde(default)]
    pub monthly: Option<G14Block>,
    /// Guideline 14 on the held-out period.
    #[serde(default)]
    pub held_out: Option<PeriodBlock>,
}

/// Guideline 14 figures as `summary.json` writes them (`pass` by the criteria of their period).
#[derive(Debug, Clone, Deserialize)]
pub struct G14Block {
    /// Hours or months used.
    pub n: usize,
    /// NMBE, %.
    pub nmbe: f64,
    /// CV-RMSE, %.
    pub cv_rmse: f64,
    /// Whether the criteria are met.
    pub pass: bool,
}

/// Guideline 14 of one period, hourly and monthly.
#[derive(Debug, Clone, Deserialize)]
pub struct PeriodBlock {
    /// Hourly.
    pub hourly: G14Block,
    /// Monthly.
    #[serde(default)]
    pub monthly: Option<G14Block>,
}

/// `summary.json` `holdout`.
#[derive(Debug, Clone, Deserialize)]
pub struct HoldoutBlock {
    /// As the project wrote it.
    pub period: String,
    /// Hour slots held out.
    pub hours: usize,
}

/// `summary.json` `predictive`: hourly predictive intervals and their coverage.
#[derive(Debug, Clone, Deserialize)]
pub struct PredictiveBlock {
    /// EnergyPlus runs at posterior draws.
    pub draws: usize,
    /// Draws EnergyPlus failed at.
    #[serde(default)]
    pub failed: usize,
    /// Whether the draws carry the surrogate's error.
    #[serde(default)]
    pub with_surrogate_error: bool,
    /// The error model of the intervals file for the meters `[validation] error_model` does
    /// not name (each meter's is its `by_error_model`'s first).
    pub error_model: String,
    /// Per meter.
    pub outputs: Vec<OutputPredictiveBlock>,
}

/// One meter's predictive coverage.
#[derive(Debug, Clone, Deserialize)]
pub struct OutputPredictiveBlock {
    /// Meter.
    pub output: String,
    /// Under each error model, the configured one first.
    pub by_error_model: Vec<ModelCoverageBlock>,
    /// Lag-one autocorrelation of the standardised residuals at the estimate.
    #[serde(default)]
    pub residual_phi: f64,
    /// Intervals of daily and monthly totals.
    #[serde(default)]
    pub totals: Vec<TotalsBlock>,
    /// A meter that reads zero in some hours: the coverage of the hours it runs.
    #[serde(default)]
    pub running: Option<RunningBlock>,
}

/// The coverage of a meter's hourly intervals on the hours it reads above zero.
#[derive(Debug, Clone, Deserialize)]
pub struct RunningBlock {
    /// Share of the measured calibration hours that read zero.
    pub idle_in_sample: f64,
    /// The same held out.
    #[serde(default)]
    pub idle_held_out: Option<f64>,
    /// Coverage of the hours above zero.
    #[serde(flatten)]
    pub coverage: PeriodCoverageBlock,
}

/// Coverage of the intervals of one kind of total.
#[derive(Debug, Clone, Deserialize)]
pub struct TotalsBlock {
    /// `day` or `month`.
    pub period: String,
    /// With the AR(1) noise of a sum (recalibrated where `before_recalibration` is present).
    pub ar1: PeriodCoverageBlock,
    /// The same before recalibration.
    #[serde(default)]
    pub before_recalibration: Option<PeriodCoverageBlock>,
    /// As if the hours' noise were independent.
    pub independent: PeriodCoverageBlock,
}

/// 50 % and 90 % coverage, in-sample and held out (of totals: `hours` counts periods).
#[derive(Debug, Clone, Deserialize)]
pub struct PeriodCoverageBlock {
    /// Over the calibration period.
    pub in_sample: Vec<CoverageBlock>,
    /// Over the held-out period (empty without).
    #[serde(default)]
    pub held_out: Vec<CoverageBlock>,
}

/// Coverage of the hourly intervals under one error model.
#[derive(Debug, Clone, Deserialize)]
pub struct ModelCoverageBlock {
    /// Its name.
    pub error_model: String,
    /// 50 % and 90 % over the calibration hours and the held-out hours (the intervals
    /// recalibrated on the calibration period, where `before_recalibration` is present).
    #[serde(flatten)]
    pub coverage: PeriodCoverageBlock,
    /// The posterior predictive's own central intervals' coverage, before recalibration
    /// (absent from a summary written before recalibration).
    #[serde(default)]
    pub before_recalibration: Option<PeriodCoverageBlock>,
    /// The calibration period judged month by month out of time (absent from a summary
    /// written before it).
    #[serde(default)]
    pub cross_validated: Option<CrossValidatedBlock>,
}

/// An error model's hourly intervals judged month by month out of time: each calibration
/// month by intervals built without it.
#[derive(Debug, Clone, Deserialize)]
pub struct CrossValidatedBlock {
    /// Months judged.
    pub months: usize,
    /// 50 % and 90 % coverage over all of them.
    pub coverage: Vec<CoverageBlock>,
    /// The mean over the months of their distance from nominal, percentage points.
    pub mean_month_miss_points: f64,
}

/// How often one interval held.
#[derive(Debug, Clone, Deserialize)]
pub struct CoverageBlock {
    /// Nominal level.
    pub nominal: f64,
    /// Hours judged.
    pub hours: usize,
    /// Share inside.
    pub fraction: f64,
    /// Share of PIT inside, where some hours read at an atom (a meter at 0 in hours the draws
    /// may find idle): the share to hold against nominal.
    #[serde(default)]
    pub pit_fraction: Option<f64>,
    /// Mean width, kWh.
    pub mean_width: f64,
}

/// `summary.json` `model_form`: whether the model reaches each meter, and what to change.
#[derive(Debug, Clone, Deserialize)]
pub struct ModelFormBlock {
    /// Per meter.
    pub meters: Vec<MeterFormBlock>,
    /// Parameters piled against a prior bound, in words.
    #[serde(default)]
    pub parameter_findings: Vec<String>,
}

/// One meter's model form.
#[derive(Debug, Clone, Deserialize)]
pub struct MeterFormBlock {
    /// Meter.
    pub output: String,
    /// Its reach: the verdict and the totals.
    pub reach: ReachBlock,
    /// The residuals grouped by each factor.
    #[serde(default)]
    pub patterns: Vec<PatternBlock>,
    /// The additive discrepancy.
    pub discrepancy: DiscrepancyBlock,
    /// In words.
    #[serde(default)]
    pub findings: Vec<String>,
}

/// A meter's reach.
#[derive(Debug, Clone, Deserialize)]
pub struct ReachBlock {
    /// Hours compared.
    #[serde(default)]
    pub hours: usize,
    /// `reached`, `level` or `shape`.
    pub verdict: String,
    /// Whether a posterior draw reaches the meter's total.
    pub within_draws: bool,
    /// The meter's total, kWh.
    pub measured_kwh: f64,
    /// The smallest and largest total of the model at the estimate and the draws, kWh.
    pub draws_kwh: [f64; 2],
}

/// Residuals grouped by one factor.
#[derive(Debug, Clone, Deserialize)]
pub struct PatternBlock {
    /// `hour_of_day`, `day_kind`, `month` or `outdoor_temperature`.
    pub factor: String,
    /// Share of the residuals' variance the grouping explains.
    pub eta_squared: f64,
    /// The groups, in order.
    #[serde(default)]
    pub groups: Vec<GroupBlock>,
}

/// One group of hours of a residual pattern.
#[derive(Debug, Clone, Deserialize)]
pub struct GroupBlock {
    /// What the group is (`"07"`, `"-12.2..-3.9"`).
    pub label: String,
    /// Mean residual (measured - model), kWh per hour.
    pub mean_residual: f64,
}

/// The additive discrepancy's effect.
#[derive(Debug, Clone, Deserialize)]
pub struct DiscrepancyBlock {
    /// Share of the misfit it removes.
    pub share: f64,
}

/// Wall time per stage, s (`summary.json` `timings`).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default)]
pub struct Timings {
    /// Latin hypercube.
    pub design_s: f64,
    /// EnergyPlus design simulations.
    pub simulations_s: f64,
    /// Surrogate training.
    pub training_s: f64,
    /// MCMC chains.
    pub chains_s: f64,
    /// Posterior summary and predictive bands.
    pub summary_s: f64,
    /// Validation simulations.
    pub validation_s: f64,
    /// Simulating refinement rounds' posterior draws.
    pub refinement_s: f64,
    /// Whole run.
    pub total_s: f64,
}

/// `summary.json` `convergence`: the targets, the worst figures, the parameters short.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct ConvergenceBlock {
    /// The targets (`rhat`, `ess`).
    #[serde(default)]
    pub targets: ConvergenceTargets,
    /// Largest R-hat (null when it could not be computed).
    #[serde(default)]
    pub max_rhat: Option<f64>,
    /// Smallest bulk ESS.
    #[serde(default)]
    pub min_ess_bulk: Option<f64>,
    /// Smallest tail ESS.
    #[serde(default)]
    pub min_ess_tail: Option<f64>,
    /// The parameters short of a target, worst R-hat first.
    #[serde(default)]
    pub shortfalls: Vec<Shortfall>,
}

/// Convergence targets.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct ConvergenceTargets {
    /// Largest acceptable R-hat.
    pub rhat: f64,
    /// Smallest acceptable bulk and tail ESS.
    pub ess: f64,
}

/// A parameter short of a convergence target.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct Shortfall {
    /// Parameter name.
    pub parameter: String,
    /// Its R-hat (null when it could not be computed).
    pub rhat: Option<f64>,
    /// Its bulk ESS.
    pub ess_bulk: Option<f64>,
    /// Its tail ESS.
    pub ess_tail: Option<f64>,
}

/// `summary.json` `design`: the design points EnergyPlus could not simulate.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct DesignBlock {
    /// Hypercube points.
    #[serde(default)]
    pub slots: usize,
    /// Failed runs: slot, values (calibration order) and error text.
    #[serde(default)]
    pub failed: Vec<FailedRun>,
    /// Failures grouped by reason.
    #[serde(default)]
    pub reasons: Vec<FailureGroup>,
    /// Slots simulated at a spare point.
    #[serde(default)]
    pub replaced: Vec<usize>,
    /// Slots left without a point.
    #[serde(default)]
    pub dropped: Vec<usize>,
    /// What a user could change.
    #[serde(default)]
    pub suggestions: Vec<String>,
    /// Severe messages accepted as usable.
    #[serde(default)]
    pub notes: Vec<PointNote>,
}

/// A failed EnergyPlus run of the design.
#[derive(Debug, Clone, Deserialize)]
pub struct FailedRun {
    /// The design slot it was run for.
    pub slot: usize,
    /// The parameter values EnergyPlus was given.
    pub values: Vec<f64>,
    /// EnergyPlus's error lines.
    #[serde(default)]
    pub error: Option<String>,
}

/// Failures of one reason.
#[derive(Debug, Clone, Deserialize)]
pub struct FailureGroup {
    /// The reason, as EnergyPlus's messages are classified.
    pub reason: String,
    /// Failed runs with it.
    pub count: usize,
    /// Their design points.
    pub points: Vec<usize>,
}

/// A usable Severe message of a design point.
#[derive(Debug, Clone, Deserialize)]
pub struct PointNote {
    /// The design point.
    pub point: usize,
    /// EnergyPlus's message.
    pub message: String,
}

impl PosteriorBlock {
    /// The posterior of the `k`-th prior, `name`: found by name, else by position (summaries
    /// whose rows carry no names).
    pub fn of(&self, k: usize, name: &str) -> Option<&PosteriorInfo> {
        self.parameters
            .iter()
            .find(|x| x.name == name)
            .or(self.parameters.get(k))
    }
}

/// `summary.json` `temperature`: the chains sampled `p(theta) L(theta)^(1/T)`.
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Temperature {
    /// `T`.
    pub value: f64,
    /// The refinement round whose surrogate error measured it, if measured.
    #[serde(default)]
    pub measured_at_round: Option<u32>,
}

/// How `estimate = "best_simulated"` chose the estimate.
#[derive(Debug, Clone, Deserialize)]
pub struct EstimateChoice {
    /// The label of the point chosen (`calibrated`: the MAP draw; `predictive_NN`; `mapped_NN`,
    /// a point of the output space mapping).
    pub chosen: String,
    /// Every draw simulated, with its ratio to the limits.
    #[serde(default)]
    pub candidates: Vec<SimulatedFit>,
}

impl EstimateChoice {
    /// Whether the point chosen is one of the output space mapping's (`mapped_NN`), not a
    /// posterior draw.
    pub fn chose_mapped(&self) -> bool {
        self.chosen.starts_with("mapped_")
    }
}

/// One draw EnergyPlus simulated in validation.
#[derive(Debug, Clone, Deserialize)]
pub struct SimulatedFit {
    /// Its validation label.
    pub label: String,
    /// Its worst fitted meter's ratio to Guideline 14's hourly limits (`None`: no metrics).
    #[serde(default)]
    pub limit_ratio: Option<f64>,
    /// The same for the monthly limits (`None`: no monthly figures, or an older summary).
    #[serde(default)]
    pub monthly_limit_ratio: Option<f64>,
}

/// `summary.json` as written by `bemcal calibrate`.
#[derive(Debug, Clone, Deserialize)]
pub struct Summary {
    /// Project name.
    #[serde(default)]
    pub project: String,
    /// Calibrated outputs (meters).
    pub outputs: Vec<String>,
    /// Outputs whose meters were compared but not fitted (`fit = false`).
    #[serde(default)]
    pub not_fitted: Vec<String>,
    /// Priors, in calibration order.
    pub parameters: Vec<PriorInfo>,
    /// Posterior summary.
    pub posterior: PosteriorBlock,
    /// Estimated model-discrepancy sd per output, kWh.
    #[serde(default, deserialize_with = "bemcal_named::deserialize")]
    pub sigma_delta_kwh: Vec<(String, f64)>,
    /// Surrogate error sd per output, kWh.
    #[serde(default, deserialize_with = "bemcal_named::deserialize")]
    pub sigma_eta_kwh: Vec<(String, f64)>,
    /// Acceptance rate per chain.
    #[serde(default)]
    pub acceptance_rate: Vec<f64>,
    /// Which point estimate was validated (`best_simulated`, `map`, `mean`, `median`).
    #[serde(default)]
    pub estimate: serde_json::Value,
    /// Why the estimate is not the statistic's own point, if it is not.
    #[serde(default)]
    pub estimate_note: Option<String>,
    /// With `best_simulated`: the draw chosen (`estimate_choice.chosen`) among those simulated.
    #[serde(default)]
    pub estimate_choice: Option<EstimateChoice>,
    /// The calibrated parameter values.
    #[serde(default, deserialize_with = "bemcal_named::deserialize")]
    pub calibrated_values: Vec<(String, f64)>,
    /// G14 metrics of the calibrated model.
    #[serde(default)]
    pub validation: Vec<OutputMetrics>,
    /// G14 metrics of the initial model (prior modes).
    #[serde(default)]
    pub initial: Vec<OutputMetrics>,
    /// G14 metrics of the surrogate's prediction at the estimate.
    #[serde(default)]
    pub surrogate_at_estimate: Vec<OutputMetrics>,
    /// The held-out period, if any.
    #[serde(default)]
    pub holdout: Option<HoldoutBlock>,
    /// Hourly predictive intervals from EnergyPlus at posterior draws.
    #[serde(default)]
    pub predictive: Option<PredictiveBlock>,
    /// Whether the model reaches each meter.
    #[serde(default)]
    pub model_form: Option<ModelFormBlock>,
    /// Whether every R-hat and ESS criterion was met.
    #[serde(default)]
    pub converged: bool,
    /// The verdict behind `converged` (absent in summaries written before it existed).
    #[serde(default)]
    pub convergence: Option<ConvergenceBlock>,
    /// Number of design points.
    #[serde(default)]
    pub design_points: usize,
    /// What EnergyPlus made of the design (failed runs, replacements, usable warnings).
    #[serde(default)]
    pub design: DesignBlock,
    /// Surrogate held-out metrics (free form).
    #[serde(default)]
    pub surrogate_held_out: serde_json::Value,
    /// Surrogate refinement rounds.
    #[serde(default)]
    pub refinement: Vec<RefineRound>,
    /// The intervals with the surrogate's error (absent without a refinement round).
    #[serde(default)]
    pub surrogate_error: Option<SurrogateErrorBlock>,
    /// The likelihood's temperature of the final chains (`mcmc.temperature`), if tempered.
    #[serde(default)]
    pub temperature: Option<Temperature>,
    /// Stage timings.
    #[serde(default)]
    pub timings: Timings,
}

/// `summary.json` `surrogate_error`: the intervals with the surrogate's error carried in.
#[derive(Debug, Clone, Deserialize)]
pub struct SurrogateErrorBlock {
    /// The refinement round whose points measured it.
    pub round: u32,
    /// EnergyPlus points recovered.
    pub points: usize,
    /// Per parameter.
    pub parameters: Vec<CarriedInterval>,
}

/// One parameter's interval with the surrogate's error.
#[derive(Debug, Clone, Deserialize)]
pub struct CarriedInterval {
    /// Parameter name.
    pub name: String,
    /// 5 % quantile.
    pub q5: f64,
    /// 95 % quantile.
    pub q95: f64,
}

/// A surrogate refinement round (`summary.json` `refinement`).
#[derive(Debug, Clone, Deserialize)]
pub struct RefineRound {
    /// 1-based.
    pub round: u32,
    /// Posterior draws added to the training set (free form: index, values).
    #[serde(default)]
    pub points: Vec<serde_json::Value>,
    /// Posterior draws EnergyPlus failed on.
    #[serde(default)]
    pub failed: Vec<serde_json::Value>,
    /// The round's surrogate against EnergyPlus at the added draws.
    #[serde(default)]
    pub surrogate_error: Vec<OutputMetrics>,
}

/// The prefix of the noise scales' columns in `draws.csv` (`sigma_delta_<output>`).
const NOISE_PREFIX: &str = "sigma_delta_";

/// `draws.csv`: `chain,draw,<columns>...`, grouped by chain, each chain in draw order.
///
/// The columns after `chain,draw` are, as `bemcal calibrate` writes them, the calibrated
/// parameters, then the noise (`sigma_delta_*`), the log posterior and the sampler's statistics
/// per draw (named as CmdStan names them, ending in `__`).
#[derive(Debug, Clone)]
pub struct Draws {
    /// Column names after `chain,draw`.
    pub columns: Vec<String>,
    /// `chains[c][k]` = the draws of column `k` in chain `c`, in draw order.
    pub chains: Vec<Vec<Vec<f64>>>,
    /// `numbers[c][i]` = the `draw` number of chain `c`'s `i`-th draw (increasing).
    pub numbers: Vec<Vec<u64>>,
}

impl Draws {
    /// The draws of a column per chain, or `None` if there is no such column.
    pub fn column(&self, name: &str) -> Option<Vec<&[f64]>> {
        let k = self.columns.iter().position(|c| c == name)?;
        Some(self.chains.iter().map(|c| c[k].as_slice()).collect())
    }

    /// The noise scales' columns (`sigma_delta_<output>`), where the calibration sampled them.
    pub fn noise(&self) -> impl Iterator<Item = &String> {
        self.columns.iter().filter(|c| c.starts_with(NOISE_PREFIX))
    }

    /// Whether a column is one of the sampler's statistics per draw (`accept_stat__`, ...).
    pub fn is_sampler_statistic(name: &str) -> bool {
        name.ends_with("__")
    }

    /// The calibrated parameters' columns: those before the noise, the log posterior and the
    /// sampler's statistics.
    pub fn parameters(&self) -> &[String] {
        let n = self
            .columns
            .iter()
            .position(|c| {
                c.starts_with(NOISE_PREFIX) || c == "log_posterior" || Self::is_sampler_statistic(c)
            })
            .unwrap_or(self.columns.len());
        &self.columns[..n]
    }

    /// Draws per chain (every chain has as many).
    pub fn len(&self) -> usize {
        self.numbers.first().map_or(0, Vec::len)
    }

    /// Whether there are no draws (never, for a file [`read_draws`] accepted).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The calibrated parameters' values (name, value) of draw number `draw` of chain `chain`,
    /// as the file numbers them; `None` if the file has no such draw.
    pub fn parameters_at(&self, chain: usize, draw: u64) -> Option<Vec<(String, f64)>> {
        let i = self.numbers.get(chain)?.binary_search(&draw).ok()?;
        Some(
            self.parameters()
                .iter()
                .enumerate()
                .map(|(k, name)| (name.clone(), self.chains[chain][k][i]))
                .collect(),
        )
    }
}

/// An hourly table `timestamp,<column>...`; empty cells are NaN.
#[derive(Debug, Clone)]
pub struct Hourly {
    /// Timestamps as written (`YYYY-MM-DDTHH:MM`).
    pub timestamps: Vec<String>,
    /// Column names after `timestamp`.
    pub columns: Vec<String>,
    /// `values[k]` = the series of column `k`.
    pub values: Vec<Vec<f64>>,
}

impl Hourly {
    /// A column's series, if present.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        let k = self.columns.iter().position(|c| c == name)?;
        Some(&self.values[k])
    }
}

/// Everything read from a calibration folder.
#[derive(Debug, Clone)]
pub struct CalibrationData {
    /// The folder.
    pub dir: PathBuf,
    /// `summary.json`.
    pub summary: Summary,
    /// `draws.csv`.
    pub draws: Draws,
    /// `posterior_predictive.csv`.
    pub predictive: Hourly,
    /// `validation/calibrated.csv`, if the validation ran.
    pub calibrated: Option<Hourly>,
    /// `validation/initial.csv`, if the initial model was simulated.
    pub initial: Option<Hourly>,
    /// `validation/predictive_intervals.csv` (EnergyPlus at posterior draws plus noise), if
    /// written.
    pub intervals: Option<Hourly>,
    /// A synthetic run's hidden truth against the posterior ([`read_truth`],
    /// `truth::recovery`), if given.
    pub truth: Option<crate::recovery::Recovery>,
}

/// One row of `calendar.csv`.
#[derive(Debug, Clone)]
pub struct CalendarDay {
    /// `YYYY-MM-DD`.
    pub date: String,
    /// Calendar day type (weekday, weekend, holiday).
    pub calendar: String,
    /// Cluster index (None when the day was skipped).
    pub cluster: Option<usize>,
    /// Day-type label of the cluster (`skipped` when not clustered).
    pub label: String,
    /// Flagged as an outlier.
    pub outlier: bool,
    /// DTW distance to the cluster medoid.
    pub medoid_distance: f64,
}

/// One row of `schedule_priors.csv`.
#[derive(Debug, Clone)]
pub struct ScheduleHour {
    /// Day type.
    pub day_type: String,
    /// Hour of day 0..23.
    pub hour: usize,
    /// Days used.
    pub n_days: usize,
    /// First quartile of the schedule fraction.
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
}

/// One row of `intervals.csv`.
#[derive(Debug, Clone)]
pub struct ScheduleInterval {
    /// Day type.
    pub day_type: String,
    /// First hour (inclusive).
    pub start_hour: usize,
    /// Last hour (exclusive).
    pub end_hour: usize,
    /// Triangular prior lower bound.
    pub min: f64,
    /// Mode.
    pub mode: f64,
    /// Upper bound.
    pub max: f64,
}

/// Everything read from a pre-calibration folder.
#[derive(Debug, Clone)]
pub struct PrecalData {
    /// The folder.
    pub dir: PathBuf,
    /// `calendar.csv`.
    pub calendar: Vec<CalendarDay>,
    /// `schedule_priors.csv`.
    pub schedule: Vec<ScheduleHour>,
    /// `intervals.csv`.
    pub intervals: Vec<ScheduleInterval>,
    /// The clustered series from `disaggregated.csv` (`schedule_series_kwh`), if present.
    pub schedule_series: Option<Vec<f64>>,
    /// `summary.txt`, if present.
    pub summary_text: Option<String>,
}

fn require(path: &Path, what: &str) -> Result<(), ReportError> {
    if path.is_file() {
        Ok(())
    } else {
        Err(ReportError::Missing {
            path: path.to_path_buf(),
            what: what.to_string(),
        })
    }
}

fn read_text(path: &Path) -> Result<String, ReportError> {
    std::fs::read_to_string(path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn parse_err(path: &Path, msg: impl Into<String>) -> ReportError {
    ReportError::Parse {
        path: path.to_path_buf(),
        msg: msg.into(),
    }
}

fn num(path: &Path, line: usize, col: &str, s: &str) -> Result<f64, ReportError> {
    let s = s.trim();
    if s.is_empty() || s.eq_ignore_ascii_case("nan") {
        return Ok(f64::NAN);
    }
    s.parse::<f64>().map_err(|_| {
        parse_err(
            path,
            format!(
                "line {line}, column '{col}': not a number: {:?}",
                bemcal_excerpt::excerpt(s, 40)
            ),
        )
    })
}

fn csv_reader(path: &Path) -> Result<csv::Reader<std::fs::File>, ReportError> {
    csv::ReaderBuilder::new()
        .flexible(false)
        .from_path(path)
        .map_err(|e| parse_err(path, e.to_string()))
}

fn headers(path: &Path, r: &mut csv::Reader<std::fs::File>) -> Result<Vec<String>, ReportError> {
    Ok(r.headers()
        .map_err(|e| parse_err(path, e.to_string()))?
        .iter()
        .map(|s| s.trim().to_string())
        .collect())
}

fn col_index(path: &Path, h: &[String], name: &str) -> Result<usize, ReportError> {
    h.iter().position(|c| c == name).ok_or_else(|| {
        parse_err(
            path,
            format!("missing column '{name}' (header: {})", h.join(",")),
        )
    })
}

/// Reads `summary.json`.
pub fn read_summary(path: &Path) -> Result<Summary, ReportError> {
    require(
        path,
        "the calibration summary written by `bemcal calibrate`",
    )?;
    let text = read_text(path)?;
    serde_json::from_str(&text).map_err(|e| parse_err(path, e.to_string()))
}

/// Reads a synthetic run's hidden true values, as `bemcal synthesize --truth FILE` writes them:
/// a JSON object of parameter name to true value.
pub fn read_truth(path: &Path) -> Result<BTreeMap<String, f64>, ReportError> {
    require(
        path,
        "the hidden true values written by `bemcal synthesize --truth`",
    )?;
    let text = read_text(path)?;
    serde_json::from_str(&text).map_err(|e| {
        parse_err(
            path,
            format!("{e}; the file should be a JSON object of parameter name to number"),
        )
    })
}

/// Reads `draws.csv` (or any draws file with `chain,draw,<column>...`), strictly: chains are
/// numbered 0, 1, ... and equally long, each chain's draw numbers appear once, and every value is
/// a finite number (a missing or infinite draw would print as a mean beside an R-hat computed from
/// ranks as if nothing were wrong). Errors name the line and column and quote an excerpt.
pub fn read_draws(path: &Path) -> Result<Draws, ReportError> {
    require(path, "the MCMC draws written by `bemcal calibrate`")?;
    let mut r = csv_reader(path)?;
    let h = headers(path, &mut r)?;
    let ci = col_index(path, &h, "chain")?;
    let di = col_index(path, &h, "draw")?;
    let cols: Vec<usize> = (0..h.len()).filter(|&k| k != ci && k != di).collect();
    if cols.is_empty() {
        return Err(parse_err(path, "no columns besides chain and draw"));
    }
    // chain -> (draw number, values by column)
    let mut rows: Vec<Vec<(u64, Vec<f64>)>> = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let line = i + 2;
        let rec = rec.map_err(|e| parse_err(path, e.to_string()))?;
        let index = |k: usize| {
            rec[k].trim().parse::<u64>().map_err(|_| {
                parse_err(
                    path,
                    format!(
                        "line {line}, column '{}': expected a whole number, found {:?}",
                        h[k],
                        bemcal_excerpt::excerpt(rec[k].trim(), 40)
                    ),
                )
            })
        };
        let (c, d) = (index(ci)?, index(di)?);
        let c = usize::try_from(c)
            .ok()
            .filter(|&c| c < 1 << 16)
            .ok_or_else(|| {
                parse_err(
                    path,
                    format!("line {line}: chain {c} is not a chain number"),
                )
            })?;
        let mut values = Vec::with_capacity(cols.len());
        for &k in &cols {
            let v = num(path, line, &h[k], &rec[k])?;
            if !v.is_finite() {
                let cell = rec[k].trim();
                let what = if v.is_nan() {
                    "a missing value"
                } else {
                    "an infinite value"
                };
                return Err(parse_err(
                    path,
                    format!(
                        "line {line}, column '{}': {what} ({:?}); every draw must be a finite number",
                        h[k],
                        bemcal_excerpt::excerpt(cell, 40)
                    ),
                ));
            }
            values.push(v);
        }
        if rows.len() <= c {
            rows.resize_with(c + 1, Vec::new);
        }
        rows[c].push((d, values));
    }
    in_draw_order(path, rows, cols.iter().map(|&k| h[k].clone()).collect())
}

/// The rows of `draws.csv` by chain (`rows[c]` = (draw number, values by column)) as
/// [`Draws`] of `columns`: chains numbered from 0, equally long, each draw number once, in
/// draw order.
fn in_draw_order(
    path: &Path,
    rows: Vec<Vec<(u64, Vec<f64>)>>,
    columns: Vec<String>,
) -> Result<Draws, ReportError> {
    if rows.is_empty() {
        return Err(parse_err(path, "no draws: the file has a header only"));
    }
    if rows[0].is_empty() {
        return Err(parse_err(
            path,
            "chain 0 has no draws: chains are numbered from 0 (as bemcal and ArviZ number them)",
        ));
    }
    let len = rows.iter().map(Vec::len).max().unwrap_or(0);
    let mut chains = Vec::with_capacity(rows.len());
    let mut numbers = Vec::with_capacity(rows.len());
    for (c, mut chain) in rows.into_iter().enumerate() {
        if chain.len() != len {
            return Err(parse_err(
                path,
                format!(
                    "chain {c} has {} draws, another {len}; chains must be numbered 0, 1, ... \
                     and equally long",
                    chain.len()
                ),
            ));
        }
        chain.sort_by_key(|(d, _)| *d);
        if let Some(w) = chain.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(parse_err(
                path,
                format!("chain {c} has draw {} twice", w[0].0),
            ));
        }
        numbers.push(chain.iter().map(|(d, _)| *d).collect());
        chains.push(
            (0..columns.len())
                .map(|k| chain.iter().map(|(_, v)| v[k]).collect())
                .collect(),
        );
    }
    Ok(Draws {
        columns,
        chains,
        numbers,
    })
}

/// Reads an hourly table `timestamp,<column>...`.
pub fn read_hourly(path: &Path, what: &str) -> Result<Hourly, ReportError> {
    require(path, what)?;
    let mut r = csv_reader(path)?;
    let h = headers(path, &mut r)?;
    let ti = col_index(path, &h, "timestamp")?;
    let cols: Vec<usize> = (0..h.len()).filter(|&k| k != ti).collect();
    let mut timestamps = Vec::new();
    let mut values = vec![Vec::new(); cols.len()];
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| parse_err(path, e.to_string()))?;
        timestamps.push(rec[ti].trim().to_string());
        for (j, &k) in cols.iter().enumerate() {
            values[j].push(num(path, i + 2, &h[k], &rec[k])?);
        }
    }
    if timestamps.is_empty() {
        return Err(parse_err(path, "no rows"));
    }
    Ok(Hourly {
        timestamps,
        columns: cols.iter().map(|&k| h[k].clone()).collect(),
        values,
    })
}

/// Adds `validation/bases.csv` (the hourly loads in the meters that the model does not have,
/// one column per output) to the same columns of an EnergyPlus run's outputs.
fn add_bases(h: &mut Hourly, bases: &Hourly) {
    for (name, base) in bases.columns.iter().zip(&bases.values) {
        if let Some(k) = h.columns.iter().position(|c| c == name) {
            for (v, b) in h.values[k].iter_mut().zip(base) {
                *v += b;
            }
        }
    }
}

/// Reads a calibration folder: `summary.json`, `draws.csv` and `posterior_predictive.csv` are
/// required; `validation/calibrated.csv` and `validation/initial.csv` are optional, and
/// `validation/bases.csv`, when present, is added to both.
pub fn read_calibration(dir: &Path) -> Result<CalibrationData, ReportError> {
    if !dir.is_dir() {
        return Err(ReportError::Missing {
            path: dir.to_path_buf(),
            what: "the calibration output folder (`bemcal calibrate PROJECT --out DIR`)".into(),
        });
    }
    let summary = read_summary(&dir.join("summary.json"))?;
    let draws = read_draws(&dir.join("draws.csv"))?;
    let pp = dir.join("posterior_predictive.csv");
    let predictive = read_hourly(
        &pp,
        "the posterior predictive bands written by `bemcal calibrate`",
    )?;
    for o in &summary.outputs {
        for suffix in ["measured", "q5", "q50", "q95"] {
            let c = format!("{o}_{suffix}");
            if predictive.get(&c).is_none() {
                return Err(parse_err(
                    &pp,
                    format!("missing column '{c}' for output '{o}' named in summary.json"),
                ));
            }
        }
    }
    let opt = |name: &str| -> Result<Option<Hourly>, ReportError> {
        let p = dir.join("validation").join(name);
        if p.is_file() {
            read_hourly(&p, "validation outputs").map(Some)
        } else {
            Ok(None)
        }
    };
    // EnergyPlus runs hold the model alone; the meters are compared with model + bases.
    let bases = opt("bases.csv")?;
    let with_bases = |h: Option<Hourly>| {
        h.map(|mut h| {
            if let Some(b) = &bases {
                add_bases(&mut h, b);
            }
            h
        })
    };
    Ok(CalibrationData {
        dir: dir.to_path_buf(),
        calibrated: with_bases(opt("calibrated.csv")?),
        initial: with_bases(opt("initial.csv")?),
        intervals: opt("predictive_intervals.csv")?,
        truth: None,
        summary,
        draws,
        predictive,
    })
}

/// Reads a pre-calibration folder: `calendar.csv`, `schedule_priors.csv` and `intervals.csv`
/// are required; `disaggregated.csv` (for the daily profiles) and `summary.txt` are optional.
pub fn read_precal(dir: &Path) -> Result<PrecalData, ReportError> {
    if !dir.is_dir() {
        return Err(ReportError::Missing {
            path: dir.to_path_buf(),
            what: "the pre-calibration folder (`bemcal precalibrate --out PDIR`)".into(),
        });
    }
    let calendar = read_day_types(&dir.join("calendar.csv"))?;
    let schedule = read_schedule_quartiles(&dir.join("schedule_priors.csv"))?;
    let intervals = read_schedule_intervals(&dir.join("intervals.csv"))?;
    let p = dir.join("disaggregated.csv");
    let schedule_series = if p.is_file() {
        let t = read_hourly(&p, "the disaggregated meters")?;
        t.get("schedule_series_kwh").map(<[f64]>::to_vec)
    } else {
        None
    };
    let p = dir.join("summary.txt");
    let summary_text = if p.is_file() {
        Some(read_text(&p)?)
    } else {
        None
    };
    Ok(PrecalData {
        dir: dir.to_path_buf(),
        calendar,
        schedule,
        intervals,
        schedule_series,
        summary_text,
    })
}

/// What pre-calibration's files are, for messages.
const PRECAL_WRITTEN: &str = "written by `bemcal precalibrate`";

/// Pre-calibration's `calendar.csv`: each day's calendar day type, cluster, label and outlier.
fn read_day_types(p: &Path) -> Result<Vec<CalendarDay>, ReportError> {
    require(p, &format!("the day-type calendar {PRECAL_WRITTEN}"))?;
    let mut r = csv_reader(p)?;
    let h = headers(p, &mut r)?;
    let [d, c, cl, l, o, m] = [
        "date",
        "calendar_day_type",
        "cluster",
        "label",
        "outlier",
        "medoid_distance",
    ]
    .map(|n| col_index(p, &h, n));
    let (d, c, cl, l, o, m) = (d?, c?, cl?, l?, o?, m?);
    let mut calendar = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| parse_err(p, e.to_string()))?;
        calendar.push(CalendarDay {
            date: rec[d].to_string(),
            calendar: rec[c].to_string(),
            cluster: rec[cl].trim().parse().ok(),
            label: rec[l].to_string(),
            outlier: rec[o].trim() == "true",
            medoid_distance: num(p, i + 2, "medoid_distance", &rec[m])?,
        });
    }
    Ok(calendar)
}

/// Pre-calibration's `schedule_priors.csv`: per day type and hour, the box-plot quartiles.
fn read_schedule_quartiles(p: &Path) -> Result<Vec<ScheduleHour>, ReportError> {
    require(
        p,
        &format!("the per-hour schedule quartiles {PRECAL_WRITTEN}"),
    )?;
    let mut r = csv_reader(p)?;
    let h = headers(p, &mut r)?;
    let idx: Vec<usize> = ["day_type", "hour", "n_days", "q1", "median", "q3"]
        .iter()
        .map(|n| col_index(p, &h, n))
        .collect::<Result<_, _>>()?;
    let mut schedule = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| parse_err(p, e.to_string()))?;
        let line = i + 2;
        schedule.push(ScheduleHour {
            day_type: rec[idx[0]].to_string(),
            hour: num(p, line, "hour", &rec[idx[1]])? as usize,
            n_days: num(p, line, "n_days", &rec[idx[2]])? as usize,
            q1: num(p, line, "q1", &rec[idx[3]])?,
            median: num(p, line, "median", &rec[idx[4]])?,
            q3: num(p, line, "q3", &rec[idx[5]])?,
        });
    }
    Ok(schedule)
}

/// Pre-calibration's `intervals.csv`: the merged schedule intervals and their triangular priors.
fn read_schedule_intervals(p: &Path) -> Result<Vec<ScheduleInterval>, ReportError> {
    require(
        p,
        &format!("the merged schedule intervals {PRECAL_WRITTEN}"),
    )?;
    let mut r = csv_reader(p)?;
    let h = headers(p, &mut r)?;
    let idx: Vec<usize> = ["day_type", "start_hour", "end_hour", "min", "mode", "max"]
        .iter()
        .map(|n| col_index(p, &h, n))
        .collect::<Result<_, _>>()?;
    let mut intervals = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| parse_err(p, e.to_string()))?;
        let line = i + 2;
        intervals.push(ScheduleInterval {
            day_type: rec[idx[0]].to_string(),
            start_hour: num(p, line, "start_hour", &rec[idx[1]])? as usize,
            end_hour: num(p, line, "end_hour", &rec[idx[2]])? as usize,
            min: num(p, line, "min", &rec[idx[3]])?,
            mode: num(p, line, "mode", &rec[idx[4]])?,
            max: num(p, line, "max", &rec[idx[5]])?,
        });
    }
    Ok(intervals)
}

/// Writes the report atomically (temporary file + rename).
pub fn write_html(path: &Path, html: &str) -> Result<(), ReportError> {
    write_atomic(path, html.as_bytes())
}

/// Writes a file atomically and durably ([`bemcal_durable`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    bemcal_durable::write_atomic(path, bytes).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod bases_tests {
    use super::*;

    #[test]
    fn bases_are_added_to_the_runs_outputs_by_column() {
        let hourly = |columns: &[&str], values: Vec<Vec<f64>>| Hourly {
            timestamps: vec!["2021-01-01T00:00".into(), "2021-01-01T01:00".into()],
            columns: columns.iter().map(|c| c.to_string()).collect(),
            values,
        };
        let mut run = hourly(
            &["heating_kwh", "electricity_kwh"],
            vec![vec![1.0, 2.0], vec![3.0, 4.0]],
        );
        let bases = hourly(&["electricity_kwh"], vec![vec![10.0, f64::NAN]]);
        add_bases(&mut run, &bases);
        assert_eq!(run.values[0], vec![1.0, 2.0]);
        assert_eq!(run.values[1][0], 13.0);
        assert!(run.values[1][1].is_nan(), "a missing base hour is missing");
    }
}

#[cfg(test)]
mod draws_tests {
    use super::*;

    /// `read_draws` of a file's text; an error with the folder written as `DIR`.
    fn read(text: &str) -> Result<Draws, String> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("draws.csv");
        std::fs::write(&p, text).unwrap();
        read_draws(&p).map_err(|e| {
            e.to_string()
                .replace(&dir.path().display().to_string(), "DIR")
        })
    }

    #[test]
    fn draws_are_grouped_by_chain_in_draw_order_and_columns_classified() {
        let d = read(
            "chain,draw,shgc,sigma_delta_heating_kwh,log_posterior,accept_stat__\n\
             1,1,0.4,2.0,-10.0,0.9\n0,1,0.2,2.0,-10.0,0.9\n0,0,0.1,2.0,-10.0,0.9\n\
             1,0,0.3,2.0,-10.0,0.9\n",
        )
        .unwrap();
        assert_eq!(d.chains[0][0], vec![0.1, 0.2]);
        assert_eq!(d.chains[1][0], vec![0.3, 0.4]);
        assert_eq!(d.numbers, vec![vec![0, 1], vec![0, 1]]);
        assert_eq!(d.len(), 2);
        assert_eq!(d.parameters(), ["shgc"]);
        assert_eq!(d.parameters_at(1, 1), Some(vec![("shgc".to_string(), 0.4)]));
        assert_eq!(d.parameters_at(2, 0), None);
        assert!(Draws::is_sampler_statistic("accept_stat__"));
    }

    #[test]
    fn draws_files_that_would_mislead_a_diagnosis_are_refused() {
        let refused = |text: &str, want: &str| {
            let e = read(text).unwrap_err();
            assert!(e.contains(want), "{text:?}: {e}");
            assert!(e.len() < 300, "{e}");
        };
        refused(
            "chain,draw,a\n0,0,1\n0,1,2\n2,0,3\n2,1,4\n",
            "chain 1 has 0 draws, another 2",
        );
        refused("chain,draw,a\n0,0,1\n0,1,2\n1,0,3\n", "chain 1 has 1 draws");
        refused("chain,draw,a\n0,0,1\n0,0,2\n", "chain 0 has draw 0 twice");
        refused(
            "chain,draw,a\n0,0,1\n0,1,\n",
            "line 3, column 'a': a missing value",
        );
        refused(
            "chain,draw,a\n0,0,1\n0,1,1e999\n",
            "line 3, column 'a': an infinite value",
        );
        refused(
            &format!("chain,draw,a\n0,0,{}\n", "7".repeat(5000) + "x"),
            "line 2, column 'a': not a number",
        );
        refused(
            "chain,draw,a\n-1,0,1\n",
            "line 2, column 'chain': expected a whole number",
        );
        refused(
            "chain,draw,a\n1,0,1\n2,0,1\n",
            "chain 0 has no draws: chains are numbered from 0",
        );
        refused("chain,draw,a\n", "no draws: the file has a header only");
        refused("chain,draw\n0,0\n", "no columns besides chain and draw");
    }
}
