//! The project file: what to calibrate, against which meters, with which settings.
//!
//! ```toml
//! name = "example-office"
//! model = "model.toml"                 # building spec or [idf] parameter map
//! weather = "bundled:USA_CO_Golden-NREL.724666_TMY3.epw"   # or a path to an EPW
//! priors = "precal/priors.toml"        # optional: written by `bemcal precalibrate`
//! calibrate = ["lighting_power_density", "shgc"]   # optional; default: every parameter
//!
//! [fixed]                              # optional: values of parameters not calibrated
//! people_area_per_person = 12.0
//!
//! [meters]                             # how to read the meters CSV (see bemcal-precal)
//! file = "meters.csv"
//! timestamp_column = "timestamp"
//! timestamp_format = "iso8601"
//! convention = "hour_beginning"
//! [[meters.columns]]
//! column = "heating_kwh"
//! role = "heating"
//! unit = "kWh"
//!
//! [outputs]                            # model output -> meter role (default: by name)
//! heating_kwh = "heating"
//!
//! [design]
//! points = 20
//! [surrogate]
//! epochs = 200
//! [mcmc]                               # defaults: HMC from optimised starts, converged
//! chains = 4                           # or extended (rhat_target 1.01, ess_target 400)
//! iterations = 500
//! burn_in = 150
//! [refine]                             # default: 2 rounds of 8 posterior draws
//! rounds = 2
//! [simulation]                         # limits of each EnergyPlus run (these: defaults)
//! timeout_s = 900
//! memory_gib = 8
//! max_output_gib = 2
//! ```
//! Relative paths are relative to the project file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use bemcal_precal::meters::MeterSpec;
use bemcal_stats::convergence::Targets;
use serde::{Deserialize, Serialize};

use crate::error::Error;

/// A calibration project.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Project {
    /// The calibration's name, for the summary and the calibrated model (default
    /// `calibration`).
    #[serde(default = "default_name")]
    pub name: String,
    /// Model file (building spec or `[idf]` parameter map).
    pub model: PathBuf,
    /// EPW path, or `bundled:FILE` for a weather file shipped with EnergyPlus. With
    /// `[measured_weather]`, the site's typical-year file that the measured weather is merged
    /// onto.
    pub weather: String,
    /// Measured weather of the metered year (ISD-lite files or a station CSV): the calibration
    /// builds its EPW (`bemcal weather`) and simulates with it.
    #[serde(default)]
    pub measured_weather: Option<MeasuredWeather>,
    /// Priors file from pre-calibration (schedule boundaries and parameter priors).
    #[serde(default)]
    pub priors: Option<PathBuf>,
    /// Parameters to calibrate; empty = all.
    #[serde(default)]
    pub calibrate: Vec<String>,
    /// Values of parameters that are not calibrated (others stay at their prior mode).
    #[serde(default)]
    pub fixed: BTreeMap<String, f64>,
    /// The meters.
    pub meters: MeterSpec,
    /// Model output name -> meter role (`heating`, `cooling`, `electricity` or a sub-meter).
    #[serde(default)]
    pub outputs: BTreeMap<String, String>,
    /// Loads in a meter that the model does not have (a data center, labs, process loads):
    /// the calibration compares the model plus these bases with the meter (`[[bases]]`).
    #[serde(default)]
    pub bases: Vec<Base>,
    /// `[design]`: the Latin hypercube and its EnergyPlus runs.
    #[serde(default)]
    pub design: DesignSettings,
    /// `[surrogate]`: its training.
    #[serde(default)]
    pub surrogate: SurrogateSettings,
    /// `[mcmc]`: the chains and the likelihood's noise.
    #[serde(default)]
    pub mcmc: McmcSettings,
    /// `[refine]`: the surrogate's refinement rounds near the posterior.
    #[serde(default)]
    pub refine: RefineSettings,
    /// `[validation]`: the estimate, the held-out period and the predictive intervals.
    #[serde(default)]
    pub validation: ValidationSettings,
    /// `[simulation]`: the limits of each EnergyPlus run (wall time, memory, output size).
    #[serde(default)]
    pub simulation: SimulationSettings,
    /// `[[measures]]`: retrofit measures whose savings `bemcal savings` estimates over the
    /// posterior draws of a finished calibration.
    #[serde(default)]
    pub measures: Vec<crate::measures::Measure>,
    /// `[savings]`: the measures' savings as the calibration's last stage.
    #[serde(default)]
    pub savings: SavingsSettings,
    /// Folder of the project file (set on load).
    #[serde(skip)]
    pub base: PathBuf,
    /// The project file itself (set on load; names it in messages).
    #[serde(skip)]
    pub path: PathBuf,
}

/// The JSON Schema of a project file, from the types that read it (`bemcal reference` writes
/// it to `docs/reference/project.schema.json`; editors complete and check TOML files against
/// it, for example through taplo's `#:schema` directive). Relative paths are relative to the
/// project file. Checks across settings (`burn_in` below `iterations`, a `[fixed]` value inside
/// its prior, ...) are the loader's: the schema says which keys and values a file may have.
pub fn project_schema() -> schemars::Schema {
    let mut s = schemars::schema_for!(Project);
    s.insert("title".into(), "bemcal project file".into());
    s
}

fn default_name() -> String {
    "calibration".into()
}

/// `[[bases]]`: a load in a meter that the model does not simulate, added to the model's output
/// before it is compared with the meter (in the likelihood, the posterior predictive and
/// Guideline 14 validation), so the meter is used whole and the model is not bent to reach a
/// load it cannot have. Fixed, not calibrated: a measured sub-meter is data, and a constant
/// from pre-calibration (its base-load estimates) is the user's stated knowledge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Base {
    /// The model output whose meter holds the load (`electricity_kwh`).
    pub output: String,
    /// A sub-meter of the meters file measuring the load, hour by hour (`data_center`).
    #[serde(default)]
    pub submeter: Option<String>,
    /// Or a constant load, kWh per hour (kW).
    #[serde(default)]
    pub kwh_per_hour: Option<f64>,
}

/// `[measured_weather]`: the observations an EPW of the metered year is built from
/// (`bemcal_weather::measured`), either NOAA ISD-lite files or a CSV with a column map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MeasuredWeather {
    /// NOAA ISD-lite station-year files (UTC; gzipped or not).
    #[serde(default)]
    pub isd_lite: Vec<PathBuf>,
    /// A CSV of measured weather, read with `timestamp_column`, `time_zone`, `stamp` and
    /// `columns`.
    #[serde(default)]
    pub csv: Option<PathBuf>,
    /// Header of the CSV's time-stamp column (default `timestamp`).
    #[serde(default = "default_weather_timestamp")]
    pub timestamp_column: String,
    /// A chrono format of the CSV's time stamps (`%m/%d/%Y %H:%M`); by default ISO 8601.
    #[serde(default)]
    pub timestamp_format: Option<String>,
    /// `utc`, `local_standard` or an IANA zone (`America/Denver`).
    #[serde(default = "default_weather_zone")]
    pub time_zone: bemcal_weather::station::TimeBasis,
    /// What a CSV time stamp means (an instant, or the end or start of an averaging interval).
    #[serde(default)]
    pub stamp: bemcal_weather::measured::Stamp,
    /// The CSV's measured columns: header, the weather field it measures, its unit.
    #[serde(default)]
    pub columns: Vec<bemcal_weather::station::CsvColumn>,
    /// The year to build (`2017`, or `"2017-04"` for twelve months from April 2017); by
    /// default the model's year.
    #[serde(default)]
    pub year: Option<bemcal_weather::grid::GridYear>,
    /// Gaps up to this many hours are interpolated; longer ones come from the TMY file.
    #[serde(default = "default_max_gap")]
    pub max_gap_h: usize,
}

fn default_weather_timestamp() -> String {
    "timestamp".into()
}

fn default_weather_zone() -> bemcal_weather::station::TimeBasis {
    bemcal_weather::station::TimeBasis::Utc
}

fn default_max_gap() -> usize {
    6
}

impl MeasuredWeather {
    /// The observations' source, with paths resolved against the project's folder.
    pub fn source(&self, project: &Project) -> bemcal_weather::station::Source {
        use bemcal_weather::station::{CsvSpec, Source};
        match &self.csv {
            Some(file) => Source::Csv {
                file: project.resolve(file),
                spec: CsvSpec {
                    timestamp_column: self.timestamp_column.clone(),
                    timestamp_format: self.timestamp_format.clone(),
                    time_zone: self.time_zone,
                    stamp: self.stamp,
                    columns: self.columns.clone(),
                },
            },
            None => Source::IsdLite(self.isd_lite.iter().map(|p| project.resolve(p)).collect()),
        }
    }

    fn validate(&self) -> Result<(), String> {
        match (&self.csv, self.isd_lite.is_empty()) {
            (Some(_), false) => {
                Err("[measured_weather]: give isd_lite or csv, not both".into())
            }
            (None, true) => Err(
                "[measured_weather]: give isd_lite = [\"FILE.gz\"] or csv = \"FILE\" with columns"
                    .into(),
            ),
            (Some(_), true) if self.columns.is_empty() => Err(
                "[measured_weather] csv: give columns = [{ column = \"...\", field = \"dry_bulb\", unit = \"C\" }, ...]"
                    .into(),
            ),
            _ => Ok(()),
        }
    }
}

/// Design points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DesignSettings {
    /// Number of Latin hypercube points (reference: 20).
    pub points: usize,
    /// Seed of the hypercube (and, derived from it, of the spare one).
    pub seed: u64,
    /// Maximin column-swap iterations.
    pub maximin_iterations: usize,
    /// EnergyPlus runs at once (one core each).
    pub parallel: usize,
    /// A design point EnergyPlus cannot simulate is replaced by a spare hypercube point up to
    /// this many times (`crate::replacement`); then it is dropped.
    pub replacements: usize,
    /// The calibration goes on only if at least this share of the design points could be
    /// simulated (after replacements); otherwise it stops with the failures grouped by reason.
    pub min_success: f64,
}

impl Default for DesignSettings {
    fn default() -> Self {
        DesignSettings {
            points: 20,
            seed: 1,
            maximin_iterations: 1000,
            parallel: 2,
            replacements: 2,
            min_success: 0.8,
        }
    }
}

/// `[simulation]`: the limits of every EnergyPlus process the calibration starts (design
/// points, refinement draws, the estimate's, the validation's and the predictive runs), on
/// this machine and on a coordinator's workers alike (they read the submitted project file).
/// A run past a limit is a failed simulation whose reason names the limit, and the failed
/// points take it from there: the design point is replaced by a spare (`[design]
/// replacements`), a refinement draw is left out.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SimulationSettings {
    /// Wall-clock limit of one EnergyPlus run, s (default 900; its ExpandObjects gets at most
    /// 120 of them). BuildStockBatch added the same per-model limit after whole jobs timed out
    /// on a few slow models.
    pub timeout_s: f64,
    /// Address-space limit of one run, GiB (default 8; the example's 20-zone building maps
    /// under 1).
    pub memory_gib: f64,
    /// Largest file one run may write, GiB (default 2; the 20-zone building writes about 30
    /// MB in all).
    pub max_output_gib: f64,
}

impl Default for SimulationSettings {
    fn default() -> Self {
        let l = bemcal_energyplus::confine::Limits::default();
        SimulationSettings {
            timeout_s: l.wall.as_secs_f64(),
            memory_gib: l.memory_bytes.map_or(8.0, |b| b as f64 / GIB),
            max_output_gib: l.output_bytes.map_or(2.0, |b| b as f64 / GIB),
        }
    }
}

/// Bytes in a GiB.
const GIB: f64 = (1u64 << 30) as f64;

/// `[savings]`: the `[[measures]]`' savings estimated by the calibration itself, after its
/// summary (`summary.json` `savings`), as `bemcal savings` would estimate them from the
/// finished folder: on a coordinator each measure's EnergyPlus runs are jobs like the design's,
/// cached and resumed with the run. Off by default: each draw costs two EnergyPlus runs per
/// measure and weather, one of them shared by every measure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SavingsSettings {
    /// Estimate the measures' savings at the end of the calibration (needs `[[measures]]`).
    pub with_calibration: bool,
    /// Posterior draws EnergyPlus simulates with and without each measure (`bemcal savings
    /// --draws`).
    pub draws: usize,
    /// How two parameters the posterior ties together are split at each draw: `"priors"`
    /// (drawn again from their priors along the line the meters constrain) or `"chains"`
    /// (`bemcal savings --split`).
    pub split: crate::savings::Split,
}

impl Default for SavingsSettings {
    fn default() -> Self {
        SavingsSettings {
            with_calibration: false,
            draws: 30,
            split: crate::savings::Split::Priors,
        }
    }
}

impl SimulationSettings {
    /// Longest wall-time limit accepted, s (a week).
    pub const MAX_TIMEOUT_S: f64 = 7.0 * 24.0 * 3600.0;
    /// Largest memory or output limit accepted, GiB.
    pub const MAX_GIB: f64 = 1024.0 * 1024.0;

    /// Checks the `[simulation]` settings: each limit positive, finite and at most a week
    /// ([`Self::MAX_TIMEOUT_S`]) or [`Self::MAX_GIB`].
    pub fn check(&self) -> Result<(), String> {
        for (key, v, most, unit) in [
            ("timeout_s", self.timeout_s, Self::MAX_TIMEOUT_S, "s"),
            ("memory_gib", self.memory_gib, Self::MAX_GIB, "GiB"),
            ("max_output_gib", self.max_output_gib, Self::MAX_GIB, "GiB"),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= most) {
                return Err(format!(
                    "simulation.{key} = {v}: expected a positive, finite limit of at most \
                     {most} {unit}"
                ));
            }
        }
        Ok(())
    }

    /// The limits of one EnergyPlus process (checked settings: [`Self::check`]).
    pub fn limits(&self) -> bemcal_energyplus::confine::Limits {
        bemcal_energyplus::confine::Limits {
            wall: std::time::Duration::from_secs_f64(self.timeout_s),
            memory_bytes: Some((self.memory_gib * GIB) as u64),
            output_bytes: Some((self.max_output_gib * GIB) as u64),
        }
    }
}

/// Surrogate training.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SurrogateSettings {
    /// Maximum epochs (reference: 200), with early stopping.
    pub epochs: usize,
    /// Early stopping: training ends after this many epochs without a better held-out loss.
    pub patience: usize,
    /// Seed of the training (torch and numpy) and of the held-out split.
    pub seed: u64,
    /// Training mini-batch size, in (design point, hour) samples.
    pub batch_size: usize,
    /// `hour+schedule` (default), `hour`, or `none` (the reference: the LSTM must infer the
    /// schedule hour from the weather). Measured on an 8-point design of the small model, held-out
    /// CV-RMSE heating / cooling / electricity: none 34 / 18 / 10 %, hour 23 / 20 / 4 %,
    /// hour+schedule 18 / 13 / 4 %.
    #[schemars(extend("enum" = ["hour+schedule", "hour", "none"]))]
    pub time_features: String,
    /// Threads for training and evaluation.
    pub threads: usize,
    /// Fraction of design points held out (split by design point).
    pub held_out_fraction: f64,
    /// A refinement round's retraining starts from the previous round's weights (default
    /// true) instead of a random initialisation. The held-out split is nested across rounds,
    /// so the held-out error stays out-of-sample either way.
    pub warm_start: bool,
    /// Most epochs of a warm-started retraining (default 60): it starts from weights that
    /// already fit all but a refinement round's few new points, so it needs a fraction of a
    /// first training (measured on the demo: a warm retraining of 27 points still running
    /// after 11 minutes under the first training's 200 epochs).
    pub warm_epochs: usize,
    /// Hidden units in each of the LSTM's two layers (reference: 128, the default). Training
    /// and every surrogate evaluation cost about hidden^2: a small model or a test may take 32
    /// (measured on the 6-point small model: see docs/benchmarks.md), at some accuracy.
    pub hidden: usize,
    /// Adam's learning rate (default 1e-3), the first where it is scheduled.
    pub lr: f64,
    /// `constant` (the reference) or `cosine`: the learning rate annealed from `lr` to 1/100
    /// of it over `epochs` (over `warm_epochs` in a warm-started retraining). Measured on the
    /// demo's 60-point design (docs/benchmarks.md): cosine from 3e-3 reaches in 30 epochs the
    /// held-out loss the constant 1e-3 reaches in about 60, 1.28 times its best after 180.
    pub lr_schedule: bemcal_surrogate::LrSchedule,
    /// The building family's pretrained surrogate: a folder with `card.json` and `weights.pt`
    /// (`python -m bemcal_train.pretrain train`), relative to the project file, or
    /// `"bundled:conditioned-200"`, the network shipped inside the binary
    /// (`corpus/pretrained/conditioned-200`: 200 cases of the family, hidden = 64). The first training then starts from it, folded onto this building, and
    /// fine-tunes for at most `warm_epochs` instead of `epochs` from random weights. A
    /// building it cannot start (an own IDF, outside its corpus's ranges, a parameter or meter
    /// it does not know, a `hidden` other than its own) trains from random weights as without
    /// it; `summary.json`'s `surrogate_start` says which, and why.
    pub pretrained: Option<PathBuf>,
}

impl Default for SurrogateSettings {
    fn default() -> Self {
        SurrogateSettings {
            epochs: 200,
            patience: 20,
            seed: 0,
            batch_size: 1024,
            time_features: "hour+schedule".into(),
            threads: 2,
            held_out_fraction: 0.2,
            warm_start: true,
            warm_epochs: 60,
            hidden: 128,
            lr: 1e-3,
            lr_schedule: bemcal_surrogate::LrSchedule::Constant,
            pretrained: None,
        }
    }
}

/// How the model-inadequacy variance is treated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SigmaDeltaMode {
    /// The default. Each output's total variance sigma_k^2 is unknown and integrated out
    /// analytically under the Jeffreys prior 1/sigma^2 (conjugate), so the chains sample the
    /// parameters only. Why: with 8,760 hours the residuals are dominated by model inadequacy of
    /// unknown size (fixing it too small makes the posterior overconfident, too large washes the
    /// information out), and sampling it as extra dimensions costs the chains dearly: its
    /// posterior is so narrow (relative sd ~ 1/sqrt(2n)) that adaptive Metropolis spends its
    /// burn-in learning it. The posterior mean of sigma_delta at the estimate is reported.
    Marginal,
    /// Sampled per fitted output on the log scale with a half-Cauchy prior (scale = the
    /// output's measured sd), as extra chain dimensions.
    Sampled,
    /// Fixed at `sigma_delta_fraction` x the output's measured sd.
    Fixed,
}

/// Hourly residual model (with `sigma_delta = "marginal"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Residuals {
    /// AR(1) residuals per output, phi profiled (the default). Hourly residuals of a building
    /// model are strongly autocorrelated (a mis-set schedule or set-point errs for hours on end);
    /// treating 8,760 of them as independent overstates their information by about
    /// (1 + phi) / (1 - phi) and gives posteriors that exclude the truth (seen in tests/calibrate.rs
    /// with iid: a 90 % interval of width 0.2 W/m2 that missed the true lighting density by 0.6).
    Ar1,
    /// Independent residuals: the reference's y ~ N(f, sigma^2 I).
    Iid,
}

/// A model-form discrepancy in the likelihood (with `sigma_delta = "marginal"`).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum DiscrepancyTerm {
    /// None (the default): the residuals are the hourly error alone.
    #[default]
    None,
    /// A random effect per meter and calendar cell (hour of day x working or off day x
    /// meteorological season, 192 cells), its scale measured from the residuals and
    /// integrated out ([`bemcal_stats::likelihood::cells`]): what the model misses by hour,
    /// day kind and season is carried there instead of bending the parameters.
    HourDaySeason,
    /// The same cells with each cell's level free (a fixed effect): the parameters learn only
    /// from what varies within the cells (the weather's day-to-day swings), which a misfit by
    /// hour, day kind and season cannot reach; wider intervals, and the meters' levels by cell
    /// no longer inform the parameters ([`bemcal_stats::likelihood::cells::Cells::free_levels`]).
    HourDaySeasonFree,
}

impl DiscrepancyTerm {
    /// `None` without a term; with one, whether its cells' levels are free.
    pub fn free_levels(self) -> Option<bool> {
        match self {
            DiscrepancyTerm::None => None,
            DiscrepancyTerm::HourDaySeason => Some(false),
            DiscrepancyTerm::HourDaySeasonFree => Some(true),
        }
    }
}

/// The chains. The defaults are the sampler that converges on the paper-size problem: HMC
/// through the surrogate's gradient from BFGS optima (`kernel = "hmc"`, `start =
/// "optimised"`, 4 x 500 iterations with 150 burn-in), judged against R-hat <= 1.01 and bulk
/// and tail ESS >= 400 and extended while short of them. The reference's random-walk
/// Metropolis stays available (`kernel = "mh"`, `start = "prior"`, with `iterations` in
/// thousands: the reference used 10,000 and 2,000 burn-in).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct McmcSettings {
    /// Number of chains (default 4).
    pub chains: usize,
    /// Iterations per chain including burn-in (default 500, for HMC; the reference's
    /// random walk: 10,000).
    pub iterations: u64,
    /// Burn-in (reference: 2,000); the proposal adapts only during burn-in, and HMC chains
    /// again in an undrawn window when the final chains are extended
    /// ([`bemcal_stats::chain::readapt`]).
    pub burn_in: u64,
    /// Seed of the chains' starts and random streams (each refinement round derives its own).
    pub seed: u64,
    /// How the model-inadequacy sd sigma_delta is treated: `marginal` (default), `sampled` or
    /// `fixed`.
    pub sigma_delta: SigmaDeltaMode,
    /// Residual model of the marginal likelihood: `ar1` (default) or `iid` (the reference).
    pub residuals: Residuals,
    /// A model-form discrepancy with structure: `none` (default), `hour_day_season` (pooled
    /// cell effects) or `hour_day_season_free` (free cell levels).
    pub discrepancy: DiscrepancyTerm,
    /// `sigma_delta` as a fraction of the measured sd when fixed.
    pub sigma_delta_fraction: f64,
    /// Measurement error `sigma_y` as a fraction of each output's measured mean.
    pub sigma_y_fraction: f64,
    /// Initial proposal sd in the unit space.
    pub initial_sd: f64,
    /// Iterations per checkpointed segment.
    pub segment: u64,
    /// Posterior draws evaluated for the predictive bands.
    pub predictive_draws: usize,
    /// Where chains start: `optimised` (default) or `prior`.
    pub start: ChainStart,
    /// BFGS iterations per chain before sampling (`start = "optimised"`).
    pub optimiser_iterations: usize,
    /// Probability of an independence step (0, the default: random walk only, the reference's
    /// Algorithm 1). With `start = "optimised"` the independence proposal is the Laplace
    /// Gaussian of the optimum (0.5 is what the 40-D test uses); otherwise the AM estimate.
    /// A chain whose independence steps are accepted less than 1 % of the time during burn-in
    /// takes random-walk steps only afterwards (`stats::mcmc::INDEPENDENCE_MIN_ACCEPTANCE`).
    pub independence: f64,
    /// With `start = "optimised"`: a chain whose optimum is more than this many nats below
    /// the best chain's starts in the best one's mode instead (such a mode holds about
    /// e^-restart_below of the best one's mass; the summary lists the chains moved, and R-hat
    /// then measures mixing within the best mode). A large value keeps every chain at its own
    /// optimum. Through the coordinator the chains compared are those of one chain job: all of
    /// them unless `--chains-per-job` splits them.
    pub restart_below: f64,
    /// The transition kernel: `hmc` (default) or `mh` (random-walk Metropolis-Hastings, the reference's
    /// Algorithm 1, with the adaptive and independence variants above) or `hmc` (Hamiltonian
    /// Monte Carlo with gradients through the surrogate's VJP graph, `stats::hmc`; needs
    /// `sigma_delta = "marginal"` or `"fixed"`). An HMC iteration is a whole trajectory
    /// (`ceil(hmc_integration_time / step)` gradients, 10 to 14 at paper size, each costing
    /// about 3.3 surrogate evaluations), so set `iterations` and `burn_in` for it in hundreds,
    /// not thousands (e.g. 400 and 150). With `start = "optimised"` the Laplace covariance is
    /// its initial metric.
    pub kernel: Kernel,
    /// HMC trajectory length in the whitened space (`kernel = "hmc"`).
    pub hmc_integration_time: f64,
    /// Convergence target: every parameter's rank-normalised split R-hat at or below this
    /// (Vehtari et al. 2021: 1.01). The final chains are extended while a target is missed
    /// ([`crate::chains::extended_target`]), and a calibration that ends short of one says so
    /// (`summary.json` `converged` and `convergence`, the report's banner, exit status 3).
    pub rhat_target: f64,
    /// Convergence target: every parameter's bulk and tail ESS, all chains together, at or
    /// above this (Vehtari et al. 2021: 100 per chain, 400 for four).
    pub ess_target: f64,
    /// At most this many extensions of the final chains while a target is missed (0: judge
    /// and report only). Each adds at least `iterations - burn_in` draws per chain, more when
    /// the ESS shortfall asks for it (at most 4x that), except HMC's first, which adds that
    /// step: it re-adapts the chains, whose ESS per draw then changes. HMC chains run an
    /// undrawn re-adaptation window on top ([`crate::chains::extended_target`]).
    pub max_extensions: u32,
    /// The likelihood's temperature `T`: the chains sample `p(theta) L(theta)^(1/T)`
    /// ([`Temperature`]; default 1, the posterior itself).
    pub temperature: Temperature,
}

/// The likelihood's temperature `T >= 1`: the chains sample the power posterior `p(theta)
/// L(theta)^(1/T)`, `T` times wider than the likelihood alone makes it, with barriers between
/// its modes `T` times lower (a coarsened posterior, Miller & Dunson 2019, JASA 114). In the
/// project: a number, or `"surrogate_error"`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Temperature {
    /// This `T` for every round's chains (1: the posterior itself, the default).
    Fixed(f64),
    /// Measured for each round's chains from the last refinement round's recoveries: the `T`
    /// at which the 90 % intervals are expected to hold the truth for 90 % of the parameters
    /// when it lies one measured shift from the posterior
    /// ([`bemcal_stats::surrogate_error::temperature`]); the first round's chains
    /// run at 1. The intervals then carry that error themselves: no shifts are added to the
    /// draws (`draws_with_surrogate_error.csv` is not written). Needs `refine.rounds >= 1`.
    SurrogateError,
}

impl Default for Temperature {
    fn default() -> Self {
        Temperature::Fixed(1.0)
    }
}

/// As the project writes it: the number, or `"surrogate_error"`.
impl Serialize for Temperature {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Temperature::Fixed(t) => s.serialize_f64(*t),
            Temperature::SurrogateError => s.serialize_str("surrogate_error"),
        }
    }
}

impl<'de> Deserialize<'de> for Temperature {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Number(f64),
            Name(String),
        }
        let expected = "a number >= 1 or \"surrogate_error\"";
        match Raw::deserialize(d) {
            Ok(Raw::Number(t)) => Ok(Temperature::Fixed(t)),
            Ok(Raw::Name(n)) if n == "surrogate_error" => Ok(Temperature::SurrogateError),
            Ok(Raw::Name(n)) => Err(serde::de::Error::custom(format!(
                "unknown temperature {n:?}: expected {expected}"
            ))),
            Err(_) => Err(serde::de::Error::custom(format!("expected {expected}"))),
        }
    }
}

impl schemars::JsonSchema for Temperature {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "Temperature".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "The likelihood's temperature T >= 1: the chains sample p(theta) L(theta)^(1/T). A number (1: the posterior itself, the default), or \"surrogate_error\": measured for each round's chains from the last refinement round's recoveries (needs refine.rounds >= 1 and refine.points >= 2).",
            "anyOf": [
                {"type": "number", "minimum": 1},
                {"type": "string", "const": "surrogate_error"}
            ]
        })
    }
}

impl McmcSettings {
    /// The form of the likelihood these settings sample ([`crate::posterior::likelihood_form`],
    /// what a chains checkpoint records).
    pub fn likelihood_form(&self) -> String {
        crate::posterior::likelihood_form(
            self.sigma_delta == SigmaDeltaMode::Sampled,
            self.sigma_delta == SigmaDeltaMode::Marginal,
            self.residuals == Residuals::Ar1,
            self.discrepancy.free_levels(),
        )
    }

    /// The convergence targets ([`bemcal_stats::convergence`]).
    pub fn targets(&self) -> Targets {
        Targets {
            rhat: self.rhat_target,
            ess: self.ess_target,
        }
    }
}

/// The chains' transition kernel.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Kernel {
    /// Random-walk (and independence) Metropolis-Hastings (the reference's Algorithm 1).
    Mh,
    /// Hamiltonian Monte Carlo (the default).
    #[default]
    Hmc,
}

/// Where chains start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ChainStart {
    /// Each chain's prior draw is first optimised (BFGS, finite differences through the
    /// surrogate) and the chain starts at that optimum with the Laplace covariance as its
    /// proposal shape (Pathfinder-style initialisation). On a smooth, peaked 40-D posterior
    /// this turns R-hat 4 / bulk ESS 4 into R-hat <= 1.005 / bulk ESS >= 2,300 with 4 x 8,000
    /// draws (crates/stats tests/mcmc_peaked.rs); with exact-gradient BFGS and HMC it reached
    /// R-hat 1.009 / bulk ESS 581 at the paper size (docs/benchmarks.md). The default. (With
    /// finite-difference BFGS on a rugged 20-point surrogate it once stopped in poorer local
    /// optima; `mcmc.restart_below` moves such chains to the best one's mode.)
    Optimised,
    /// Chains start at prior draws and learn their proposal by adaptive Metropolis during
    /// burn-in (the reference's procedure).
    Prior,
}

impl Default for McmcSettings {
    fn default() -> Self {
        McmcSettings {
            chains: 4,
            iterations: 500,
            burn_in: 150,
            seed: 7,
            sigma_delta: SigmaDeltaMode::Marginal,
            residuals: Residuals::Ar1,
            discrepancy: DiscrepancyTerm::None,
            sigma_delta_fraction: 0.2,
            sigma_y_fraction: 0.02,
            initial_sd: 0.02,
            segment: 500,
            predictive_draws: 100,
            start: ChainStart::Optimised,
            optimiser_iterations: 60,
            independence: 0.0,
            restart_below: 20.0,
            kernel: Kernel::Hmc,
            hmc_integration_time: 2.0,
            rhat_target: 1.01,
            ess_target: 400.0,
            max_extensions: 3,
            temperature: Temperature::default(),
        }
    }
}

/// Surrogate refinement near the posterior (sequential design): after the chains of round `r`,
/// `points` posterior draws are simulated in EnergyPlus, added to the training set, the
/// surrogate is retrained and the chains run again from where they ended. The surrogate is
/// accurate on average over the prior (the Latin hypercube), not where the posterior is: on the
/// demo, the 20-point surrogate differed from EnergyPlus at the MAP by +24.7 / -9.7 / -8.1 %
/// (heating / cooling / electricity); 7 posterior draws added and one retraining brought that
/// to -4.0 / -0.7 / -1.2 %.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RefineSettings {
    /// Refinement rounds (default 2; 0: the reference's one-shot design).
    pub rounds: u32,
    /// Posterior draws simulated per round.
    pub points: usize,
    /// Iterations per chain of a round's (preliminary) chains, burn-in included.
    pub iterations: u64,
    /// Burn-in of the preliminary chains.
    pub burn_in: u64,
    /// A chain whose best log posterior in a round is more than this many nats below the best
    /// chain's restarts the next round in the best chain's mode (such a mode holds under
    /// e^-restart_below of the posterior mass; on the demo, chains stuck 100-250 nats apart
    /// kept R-hat near 4). A large value keeps every chain where it ended.
    pub restart_below: f64,
    /// The transition kernel of the preliminary rounds' chains (unset: `mcmc.kernel`). Those
    /// chains only have to find where the posterior is, for the draws EnergyPlus simulates
    /// next; on the early, rugged surrogates HMC's trajectories run to their step cap (the
    /// demo's first preliminary round: 100 HMC iterations in 860 s), where `"mh"` from the same
    /// BFGS optima with the Laplace proposal costs one evaluation per iteration (give it
    /// `iterations` in thousands).
    pub kernel: Option<Kernel>,
    /// How far the simulated draws are moved from the chains' mean, as a multiple of their
    /// distance (default 1: the draws themselves; the highest-posterior draw is never moved):
    /// the surrogate then learns EnergyPlus's response over a wider neighbourhood than the
    /// posterior's own width ([`crate::refine::refinement_points`]).
    pub spread: f64,
}

impl Default for RefineSettings {
    fn default() -> Self {
        RefineSettings {
            rounds: 2,
            points: 8,
            iterations: 120,
            burn_in: 60,
            restart_below: 20.0,
            kernel: None,
            spread: 1.0,
        }
    }
}

/// Which posterior statistic becomes the calibrated estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Estimate {
    /// The draw with the highest log posterior: a joint point, so it satisfies every
    /// constraint, and it is what the reference marks at the posterior peak (its Fig. 10).
    Map,
    /// The MAP draw where EnergyPlus passes Guideline 14 there, hourly and monthly; where it
    /// misses either, of the posterior draws EnergyPlus simulates anyway (the MAP draw and the
    /// predictive draws, `predictive_draws`), one that passes both, else the MAP draw if it
    /// passes hourly, else the one whose worst meter is nearest inside the hourly limits
    /// (default; [`crate::metrics::best_simulated`]): the MAP is the surrogate's best, and where the
    /// surrogate is wrong near it, another draw of the posterior can fit the meters better in
    /// EnergyPlus. Where it passes both at none of them, up to `mapping_steps` steps of
    /// output space mapping look for a point it passes at ([`crate::mapping`]).
    BestSimulated,
    /// Per-parameter posterior mean.
    Mean,
    /// Per-parameter posterior median.
    Median,
}

impl Estimate {
    /// Its name, as the project file and `summary.json` write it (`best_simulated`).
    pub fn as_str(self) -> &'static str {
        match self {
            Estimate::Map => "map",
            Estimate::BestSimulated => "best_simulated",
            Estimate::Mean => "mean",
            Estimate::Median => "median",
        }
    }
}

/// Validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ValidationSettings {
    /// Which posterior point becomes the calibrated estimate: `best_simulated` (default),
    /// `map`, `mean` or `median`.
    pub estimate: Estimate,
    /// Also simulate the initial model (prior modes), as the reference's Table 5.
    pub initial: bool,
    /// Hours that check the calibration and never fit it (`"last 3 months"`, `["oct", "nov"]`,
    /// `"2017-06-01..2017-08-31"`; [`bemcal_weather::period`]): they are left out of the
    /// likelihood like missing hours, and Guideline 14 and the predictive intervals are
    /// reported on them beside the calibration period.
    pub holdout: Option<bemcal_weather::period::Holdout>,
    /// EnergyPlus runs at posterior draws for the hourly predictive intervals (0: none).
    pub predictive_draws: usize,
    /// The noise the predictive intervals add to those runs
    /// ([`bemcal_stats::predictive::ErrorModel`]): one for every meter, or one per output
    /// ([`ErrorModels`]).
    pub error_model: ErrorModels,
    /// With `estimate = "best_simulated"`, where EnergyPlus passes Guideline 14 hourly and
    /// monthly at none of the posterior draws it simulated: at most this many steps of output
    /// space mapping from the best of them ([`crate::mapping`]; each step one optimisation on
    /// the surrogate and at most two EnergyPlus runs); 0: none.
    pub mapping_steps: usize,
}

/// `[validation] error_model`: one setting for every meter (`"level"`, `"auto"`), or a table
/// by output with an optional `default` (`{ default = "auto", heating_kwh = "hour_of_day" }`):
/// the meters of one building may favour different ones. `default` is the key of the others,
/// not an output's name. A meter read as bills takes its setting too: `constant` and
/// `hour_of_day` give its bills one error scale, `level` one that follows each bill's level,
/// `auto` whichever its bills favour ([`crate::bills::BillsPredictive::error_scale`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorModels {
    /// The setting of an output the table does not name: `auto` unless set (docs/benchmarks.md,
    /// issue 24, error models chosen by cross-validation: on twelve meters with three months
    /// held out, `auto` chose the error model the held-out hours favour for eleven).
    pub default: ErrorModelSetting,
    /// Outputs with their own setting.
    pub by_output: BTreeMap<String, ErrorModelSetting>,
}

/// One output's `[validation] error_model`: an error model by name, or the one the
/// calibration period's months favour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorModelSetting {
    /// `"auto"`: the error model whose intervals hold nearest nominal month by month when each
    /// month of the calibration period is judged by intervals built without it
    /// (`summary.json` `predictive.outputs[].cross_validation_favours`;
    /// [`bemcal_stats::predictive::cross_validated_coverage`]; `level` where no month can be
    /// judged, a calibration period of one month). A held-out period never chooses, so its
    /// coverage stays an independent check.
    Auto,
    /// This error model.
    Fixed(bemcal_stats::predictive::ErrorModel),
}

impl ErrorModelSetting {
    /// The name a project file gives it.
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorModelSetting::Auto => "auto",
            ErrorModelSetting::Fixed(m) => m.as_str(),
        }
    }
}

impl std::str::FromStr for ErrorModelSetting {
    type Err = String;
    fn from_str(v: &str) -> Result<Self, String> {
        use bemcal_stats::predictive::ErrorModel;
        if v == "auto" {
            return Ok(ErrorModelSetting::Auto);
        }
        (ErrorModel::ALL.into_iter())
            .find(|m| m.as_str() == v)
            .map(ErrorModelSetting::Fixed)
            .ok_or_else(|| {
                let names: Vec<&str> = ErrorModel::ALL.iter().map(|m| m.as_str()).collect();
                format!(
                    "unknown error model \"{}\": expected \"auto\" or one of {}",
                    excerpt(v),
                    names.join(", ")
                )
            })
    }
}

impl Serialize for ErrorModelSetting {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for ErrorModelSetting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = String::deserialize(d)?;
        v.parse().map_err(serde::de::Error::custom)
    }
}

impl schemars::JsonSchema for ErrorModelSetting {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "ErrorModelSetting".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        use bemcal_stats::predictive::ErrorModel;
        let names: Vec<&str> = std::iter::once("auto")
            .chain(ErrorModel::ALL.iter().map(|m| m.as_str()))
            .collect();
        schemars::json_schema!({
            "description": "An error model by name, or \"auto\": the one the calibration period's months favour.",
            "type": "string",
            "enum": names
        })
    }
}

impl schemars::JsonSchema for ErrorModels {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "ErrorModels".into()
    }

    fn json_schema(g: &mut schemars::SchemaGenerator) -> schemars::Schema {
        let one = g.subschema_for::<ErrorModelSetting>();
        schemars::json_schema!({
            "description": "One error model for every meter (\"level\", \"auto\"), or a table by output with an optional `default`, the setting of the outputs it does not name (`{ default = \"auto\", heating_kwh = \"hour_of_day\" }`; default \"auto\").",
            "anyOf": [
                one,
                {
                    "type": "object",
                    "properties": {"default": one},
                    "additionalProperties": one
                }
            ]
        })
    }
}

impl Default for ErrorModels {
    fn default() -> Self {
        ErrorModels {
            default: ErrorModelSetting::Auto,
            by_output: BTreeMap::new(),
        }
    }
}

impl ErrorModels {
    /// The setting of `output`'s intervals.
    pub fn of(&self, output: &str) -> ErrorModelSetting {
        self.by_output.get(output).copied().unwrap_or(self.default)
    }
}

impl Serialize for ErrorModels {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        if self.by_output.is_empty() {
            return self.default.serialize(s);
        }
        let mut m = s.serialize_map(Some(self.by_output.len() + 1))?;
        m.serialize_entry("default", &self.default)?;
        for (k, v) in &self.by_output {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

impl<'de> Deserialize<'de> for ErrorModels {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = ErrorModels;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                write!(
                    f,
                    "an error model (\"auto\", \"constant\", \"hour_of_day\", \"level\"), or a \
                     table of them by output with an optional default"
                )
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<ErrorModels, E> {
                Ok(ErrorModels {
                    default: v.parse().map_err(E::custom)?,
                    by_output: BTreeMap::new(),
                })
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<ErrorModels, A::Error> {
                let mut models = ErrorModels::default();
                while let Some(key) = map.next_key::<String>()? {
                    let model = map.next_value()?;
                    match key.as_str() {
                        "default" => models.default = model,
                        _ => {
                            models.by_output.insert(key, model);
                        }
                    }
                }
                Ok(models)
            }
        }
        d.deserialize_any(Visitor)
    }
}

impl Default for ValidationSettings {
    fn default() -> Self {
        ValidationSettings {
            estimate: Estimate::BestSimulated,
            initial: true,
            holdout: None,
            predictive_draws: 8,
            error_model: ErrorModels::default(),
            mapping_steps: 4,
        }
    }
}

impl Project {
    /// Whether the calibration fits the meter of `role`: not when its column says
    /// `fit = false`.
    pub(crate) fn fits(&self, role: &bemcal_precal::meters::MeterRole) -> bool {
        !self
            .meters
            .columns
            .iter()
            .any(|c| &c.role == role && !c.fit)
    }

    /// A path from the project file, resolved against its folder.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.into()
        } else {
            self.base.join(p)
        }
    }

    /// The meters CSV.
    pub fn meters_file(&self) -> Option<PathBuf> {
        self.meters.file.as_deref().map(|f| self.resolve(f))
    }

    /// The meters file as messages name it (`the bills` for a project of bills alone).
    pub(crate) fn meters_name(&self) -> String {
        self.meters_file()
            .map_or("the bills".into(), |p| p.display().to_string())
    }

    /// Model output -> meter role, with the defaults for the three main outputs.
    pub fn output_roles(&self) -> BTreeMap<String, String> {
        let mut m: BTreeMap<String, String> = [
            ("heating_kwh", "heating"),
            ("cooling_kwh", "cooling"),
            ("electricity_kwh", "electricity"),
        ]
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
        if !self.outputs.is_empty() {
            m = self.outputs.clone();
        }
        m
    }
}

/// At most 40 bytes of a name from the file, for messages.
pub(crate) fn excerpt(s: &str) -> std::borrow::Cow<'_, str> {
    bemcal_excerpt::excerpt(s, 40)
}

mod validate;

#[cfg(test)]
mod tests;
