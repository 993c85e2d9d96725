//! The whole calibration on one machine: design points -> simulations -> training set ->
//! surrogate -> chains -> diagnostics and summary -> validation. Every stage writes its results
//! under the output folder and reuses them on a rerun, so an interrupted calibration continues
//! where it stopped.

use std::path::{Path, PathBuf};
use std::time::Instant;

use bemcal_energyplus::HourlyOutputs;
use bemcal_energyplus::{Engine, Model, RunOptions, Runner};
use bemcal_precal::meters::{read_meters, MeterRole};
use bemcal_stats::chain::Chain;
use bemcal_stats::hmc::{self, HmcConfig, HmcState};
use bemcal_stats::lhs::Design;
use bemcal_stats::likelihood::{GaussianLikelihood, OutputNoise};
use bemcal_stats::mcmc::{chains_at_optima, dispersed_starts, ChainState, Draws, MhConfig};
use bemcal_stats::metrics::{g14, G14Metrics};
use bemcal_stats::optim::{maximise_batch, maximise_batch_with_gradient, BfgsConfig};
use bemcal_stats::prior::Prior;
use bemcal_stats::summary::{predictive_bands, summarize, PosteriorSummary};
use bemcal_surrogate::{Evaluator, ParamSpec, Split, Surrogate, TrainOptions, TrainingSet};
use bemcal_weather::{Calendar, Epw, Holidays, HourlyFeatures};
use ndarray::{Array2, Array3};
use serde::{Deserialize, Serialize};

use crate::design::{
    make_design, read_outcome, simulate_design, simulate_point, write_design_csv, write_outcome,
    Plan, OUTCOME_FILE,
};
use crate::posterior::{advance_chains, run_chains, Posterior, SigmaDeltaBox};
use crate::project::{
    ChainStart, Estimate, Kernel, McmcSettings, Project, Residuals, SigmaDeltaMode,
};
use crate::replacement::{Attempt, FailureGroup, Outcome, Policy};
use crate::{write_atomic, Error};

/// Loaded inputs of a calibration: model (with pre-calibration priors applied), weather,
/// measurements.
pub struct Inputs {
    pub runner: Runner,
    pub model: Model,
    pub plan: Plan,
    pub weather_path: PathBuf,
    /// How the EPW was built from `[measured_weather]` (None: the project's EPW as it is).
    pub measured_weather: Option<bemcal_weather::measured::BuildReport>,
    pub features: HourlyFeatures,
    pub year: i32,
    /// Calibration outputs (model output names) and their measured series (kWh, NaN = missing).
    pub outputs: Vec<String>,
    pub measured: Vec<Vec<f64>>,
    /// Per output, the hourly load (kWh) in its meter that the model does not have
    /// (`[[bases]]`; zeros without one): the model plus this is compared with the meter.
    pub bases: Vec<Vec<f64>>,
    /// What each base is, for the summary.
    pub base_reports: Vec<crate::bases::BaseReport>,
}

/// The priors file written by `bemcal precalibrate`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct PriorsFile {
    #[serde(default)]
    pub schedule: Option<ScheduleBounds>,
    #[serde(default, rename = "parameter")]
    pub parameters: Vec<PriorEntry>,
}

/// Schedule interval boundaries from pre-calibration.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ScheduleBounds {
    pub weekday_boundaries: Vec<u32>,
    pub weekend_boundaries: Vec<u32>,
}

/// One prior from pre-calibration.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PriorEntry {
    pub name: String,
    pub min: f64,
    pub mode: f64,
    pub max: f64,
    #[serde(default)]
    pub unit: String,
    #[serde(default)]
    pub source: String,
}

/// Resolves the project's weather reference ([`weather_reference`]).
pub fn resolve_weather(project: &Project, engine: &Engine) -> Result<PathBuf, Error> {
    weather_reference(&project.weather, &project.base, engine)
}

/// A weather reference: `bundled:FILE` from the engine's `WeatherData`, or a path (relative to
/// `base`).
pub fn weather_reference(reference: &str, base: &Path, engine: &Engine) -> Result<PathBuf, Error> {
    match reference.strip_prefix("bundled:") {
        Some(name) => engine.bundled_weather(name).ok_or_else(|| {
            Error::Config(format!(
                "weather 'bundled:{name}': no such file in {}",
                engine.root.join("WeatherData").display()
            ))
        }),
        None => Ok(base.join(reference)),
    }
}

/// The weather a calibration simulates with: the project's EPW, or with `[measured_weather]`
/// the EPW of `year` built from the measured weather onto it (written beside the project as
/// `measured-weather/YEAR.epw` with its report `YEAR.json`, rewritten only when it changes).
pub fn weather_for(
    project: &Project,
    engine: &Engine,
    year: i32,
) -> Result<(PathBuf, Option<bemcal_weather::measured::BuildReport>), Error> {
    let tmy = resolve_weather(project, engine)?;
    let Some(m) = &project.measured_weather else {
        return Ok((tmy, None));
    };
    let year = m.year.unwrap_or(year);
    let (text, report) = m.source(project).build_epw(&tmy, year, m.max_gap_h, 60)?;
    let path = project.resolve(Path::new(&format!("measured-weather/{year}.epw")));
    let report_json =
        serde_json::to_vec_pretty(&report).map_err(|e| Error::Config(e.to_string()))?;
    if std::fs::read(&path).ok().as_deref() != Some(text.as_bytes()) {
        write_atomic(&path, text.as_bytes())?;
        write_atomic(&path.with_extension("json"), &report_json)?;
    }
    Ok((path, Some(report)))
}

/// Loads the model and applies a priors file to it.
pub fn load_model(project: &Project, runner: &Runner) -> Result<Model, Error> {
    let path = project.resolve(&project.model);
    let mut model = Model::load(&path, runner.idd())?;
    if let Some(p) = &project.priors {
        let path = project.resolve(p);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let pf: PriorsFile = bemcal_energyplus::parse_toml(&text, &path).map_err(Error::from)?;
        if let Some(b) = &pf.schedule {
            let mut spec = model.spec().cloned().ok_or_else(|| Error::Input {
                path: path.clone(),
                line: 0,
                message: "[schedule] boundaries apply to generated building models only".into(),
            })?;
            spec.weekday_boundaries = b.weekday_boundaries.clone();
            spec.weekend_boundaries = b.weekend_boundaries.clone();
            spec.validate().map_err(|m| Error::Input {
                path: path.clone(),
                line: 0,
                message: m,
            })?;
            let p0 = model.path.clone();
            model = Model::generated(spec);
            model.path = p0;
        }
        for e in &pf.parameters {
            let prior =
                bemcal_energyplus::TriangularPrior::new(e.min, e.mode, e.max).map_err(|m| {
                    Error::Input {
                        path: path.clone(),
                        line: 0,
                        message: format!("parameter {}: {m}", e.name),
                    }
                })?;
            model
                .set_prior(&e.name, prior)
                .map_err(|err| Error::Input {
                    path: path.clone(),
                    line: 0,
                    message: err.to_string(),
                })?;
        }
    }
    Ok(model)
}

/// Loads everything a calibration needs and checks it fits together.
pub fn load_inputs(project: &Project) -> Result<Inputs, Error> {
    let engine = Engine::locate()?;
    let runner = Runner::new(engine, RunOptions::default())?;
    let model = load_model(project, &runner)?;
    let plan = Plan::new(&model, &project.calibrate, &project.fixed)?;
    let calendar = model
        .spec()
        .map(|s| s.calendar())
        .unwrap_or(Calendar::new(2021, Holidays::UsFederal));
    let (weather_path, measured_weather) = weather_for(project, runner.engine(), calendar.year)?;
    let epw = Epw::read(&weather_path)?;
    let features = HourlyFeatures::from_epw(&epw, &calendar);
    let meters_path = project.meters_file();
    let data = read_meters(
        &meters_path,
        &project.meters,
        Some(calendar.year),
        Some(epw.location.time_zone_h),
    )?;
    let mut outputs = vec![];
    let mut measured = vec![];
    let roles = project.output_roles();
    for o in model.outputs() {
        if let Some(role) = roles.get(&o.name) {
            if let Some(s) = data.get(&MeterRole::from(role.clone())) {
                outputs.push(o.name.clone());
                measured.push(s.values.clone());
            }
        }
    }
    for (name, role) in &roles {
        if !model.outputs().iter().any(|o| &o.name == name) {
            return Err(Error::Config(format!(
                "[outputs] {name} = \"{role}\": the model has no output {name} (it has {})",
                model
                    .outputs()
                    .iter()
                    .map(|o| o.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    if outputs.is_empty() {
        return Err(Error::Config(format!(
            "no model output has a meter: outputs map {:?}, meters found: {:?}",
            roles,
            data.series
                .iter()
                .map(|s| s.role.name().to_string())
                .collect::<Vec<_>>()
        )));
    }
    let (bases, base_reports) = crate::bases::bases_of(project, &outputs, &data)?;
    Ok(Inputs {
        runner,
        model,
        plan,
        weather_path,
        measured_weather,
        features,
        year: calendar.year,
        outputs,
        measured,
        bases,
        base_reports,
    })
}

/// Wall time of each stage, s.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Timings {
    pub design_s: f64,
    pub simulations_s: f64,
    pub training_s: f64,
    pub chains_s: f64,
    pub summary_s: f64,
    pub validation_s: f64,
    /// Refinement rounds: simulating posterior draws (their retraining is in `training_s`,
    /// their preliminary chains in `chains_s`).
    #[serde(default)]
    pub refinement_s: f64,
    pub total_s: f64,
}

/// Metrics of one model against the meters, per output.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct OutputMetrics {
    pub output: String,
    #[serde(flatten)]
    pub metrics: G14Metrics,
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    pub project: String,
    /// The EPW built from `[measured_weather]`: where each field came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_weather: Option<bemcal_weather::measured::BuildReport>,
    /// Loads in the meters that the model does not have, added to its outputs (`[[bases]]`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bases: Vec<crate::bases::BaseReport>,
    pub outputs: Vec<String>,
    pub parameters: Vec<ParameterReport>,
    pub posterior: PosteriorSummary,
    pub sigma_delta_kwh: Vec<(String, f64)>,
    /// AR(1) coefficient of the hourly residuals at the MAP, per output (empty with iid).
    #[serde(default)]
    pub residual_ar1: Vec<(String, f64)>,
    pub sigma_eta_kwh: Vec<(String, f64)>,
    pub acceptance_rate: Vec<f64>,
    /// Chains started in the best optimum's mode instead of their own (`mcmc.restart_below`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub moved_chains: Vec<MovedChain>,
    /// Chains whose independence kernel was switched off after burn-in (accepted under 1 %,
    /// `stats::mcmc::INDEPENDENCE_MIN_ACCEPTANCE`): their recorded draws are random-walk steps.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub independence_dropped: Vec<usize>,
    pub estimate: Estimate,
    /// Set when EnergyPlus failed at the estimate and the next-best draw was validated instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate_note: Option<String>,
    pub calibrated_values: Vec<(String, f64)>,
    pub validation: Vec<OutputMetrics>,
    pub initial: Vec<OutputMetrics>,
    /// Guideline 14 of the surrogate's prediction at the estimate against the meters: next to
    /// `validation` (EnergyPlus at the same point) it separates surrogate error from
    /// calibration error (the surrogate fitting the meters while EnergyPlus does not means the
    /// surrogate, not the posterior, is the bottleneck: more design points or training).
    #[serde(default)]
    pub surrogate_at_estimate: Vec<OutputMetrics>,
    pub converged: bool,
    pub design_points: usize,
    pub design_repair: bemcal_stats::lhs::RepairReport,
    /// What EnergyPlus made of the design: failed runs, replacements, usable warnings.
    #[serde(default)]
    pub design: DesignReport,
    pub surrogate_held_out: serde_json::Value,
    /// Surrogate refinement rounds (empty without `[refine]`).
    #[serde(default)]
    pub refinement: Vec<crate::refine::RefineRound>,
    pub timings: Timings,
}

/// The design stage's record in `summary.json`: which design points EnergyPlus could not
/// simulate and why, what replaced them, and the Severe messages accepted as usable.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct DesignReport {
    /// Hypercube points (slots).
    pub slots: usize,
    /// Slots with a simulated point (trained on).
    pub simulated: usize,
    /// Every failed EnergyPlus run: slot, values and error text.
    pub failed: Vec<Attempt>,
    /// Failures grouped by reason, largest first.
    pub reasons: Vec<FailureGroup>,
    /// Slots simulated at a spare point after failing.
    pub replaced: Vec<usize>,
    /// Slots left without a point.
    pub dropped: Vec<usize>,
    /// What a user could change (from the reasons and where the failures lie in the priors).
    pub suggestions: Vec<String>,
    /// Severe messages after which a design point's results were used, with why.
    pub notes: Vec<PointNote>,
    /// Where the chains refused proposals because EnergyPlus failed there.
    #[serde(default)]
    pub invalid_region: crate::replacement::InvalidRegion,
}

/// A Severe message accepted as usable at a design point.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PointNote {
    pub point: usize,
    pub message: String,
}

impl DesignReport {
    /// The report of a settled design; usable messages are read from the saved runs.
    pub fn new(cal: &Calibration, outcome: &Outcome) -> DesignReport {
        let dir = cal.simulations_dir();
        let plan = &cal.inputs.plan;
        DesignReport {
            slots: outcome.slot_count(),
            simulated: outcome.slots.len(),
            failed: outcome.failed.clone(),
            reasons: outcome.reasons(),
            replaced: outcome.replaced.iter().map(|r| r.0).collect(),
            dropped: outcome.dropped.clone(),
            suggestions: crate::replacement::suggestions(
                &plan.priors,
                &plan.calibrated,
                &outcome.failed,
            ),
            notes: outcome
                .slots
                .iter()
                .flat_map(|&point| {
                    crate::design::point_notes(&dir, point)
                        .into_iter()
                        .map(move |message| PointNote { point, message })
                })
                .collect(),
            invalid_region: plan.invalid.clone(),
        }
    }
}

/// A parameter's prior next to its posterior.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ParameterReport {
    pub name: String,
    pub unit: String,
    pub prior_min: f64,
    pub prior_mode: f64,
    pub prior_max: f64,
}

/// Progress messages.
pub type Log<'a> = &'a (dyn Fn(&str) + Sync);

/// Results of the chains, merged: what the summary is built from.
pub struct ChainResults {
    pub states: Vec<Chain>,
    pub draws: Vec<Draws>,
}

/// A loaded calibration: the project, its inputs and the output folder. Each stage is a method;
/// [`calibrate`] runs them in order on this machine, and the coordinator dispatches the same
/// methods to workers (simulations, training and chain segments as separate jobs).
pub struct Calibration {
    pub project: Project,
    pub inputs: Inputs,
    pub out: PathBuf,
}

/// Everything the chains need: the bound surrogate, the likelihood and the noise model.
pub struct Sampler<'c> {
    cal: &'c Calibration,
    pub evaluator: Evaluator,
    pub likelihood: GaussianLikelihood,
    pub noise: Vec<OutputNoise>,
    pub sigma_box: SigmaDeltaBox,
    pub sigma_eta: Vec<f64>,
    pub held_out: serde_json::Value,
}

impl Calibration {
    /// Loads the project's inputs; `out` is where every stage writes.
    pub fn load(project: Project, out: &Path) -> Result<Calibration, Error> {
        std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
        let inputs = load_inputs(&project)?;
        let mut cal = Calibration {
            project,
            inputs,
            out: out.to_path_buf(),
        };
        if let Some(outcome) = read_outcome(&cal.simulations_dir()) {
            cal.learn_invalid_region(&outcome);
        }
        Ok(cal)
    }

    /// Takes the region where EnergyPlus failed from a settled design into the plan, so that
    /// the chains refuse proposals there (see [`crate::replacement::InvalidRegion`]).
    pub fn learn_invalid_region(&mut self, outcome: &Outcome) {
        self.inputs.plan.invalid =
            crate::replacement::InvalidRegion::from_outcome(outcome, &self.inputs.plan.priors);
    }

    /// Stage 1: the design (deterministic for the project's seed); writes `design.csv`.
    pub fn design(&self) -> Result<Design, Error> {
        let p = &self.project.design;
        let d = make_design(
            &self.inputs.plan,
            &self.inputs.model,
            p.points,
            p.seed,
            p.maximin_iterations,
        )?;
        write_design_csv(&self.out.join("design.csv"), &self.inputs.plan, &d)?;
        Ok(d)
    }

    /// The spare hypercube that replaces design points EnergyPlus cannot simulate
    /// ([`crate::replacement`]; deterministic for the project's seed).
    pub fn spares(&self) -> Result<Design, Error> {
        let p = &self.project.design;
        make_design(
            &self.inputs.plan,
            &self.inputs.model,
            p.points,
            crate::replacement::spare_seed(p.seed),
            p.maximin_iterations,
        )
    }

    /// What to do about design points that fail (`[design]` replacements and floor).
    pub fn design_policy(&self) -> Policy {
        Policy {
            replacements: self.project.design.replacements,
            min_success: self.project.design.min_success,
        }
    }

    /// The next step of the design after `attempts` (the one rule both drivers follow).
    pub fn design_step(
        &self,
        hypercube: &Design,
        spares: &Design,
        attempts: &[Attempt],
    ) -> crate::replacement::Step {
        crate::replacement::next_step(
            &self.inputs.plan,
            hypercube,
            spares,
            self.design_policy(),
            attempts,
        )
    }

    /// Records the settled design in the simulations folder (`design.json`).
    pub fn record_outcome(&self, outcome: &Outcome) -> Result<(), Error> {
        write_outcome(&self.simulations_dir(), outcome)
    }

    /// The settled design (after replacements) and the points trained on: errors if the
    /// design stage has not finished.
    pub fn settled_design(&self) -> Result<(Outcome, Design), Error> {
        let outcome = read_outcome(&self.simulations_dir()).ok_or_else(|| Error::Stage {
            stage: "design",
            message: format!(
                "no settled design in {}",
                self.simulations_dir().join(OUTCOME_FILE).display()
            ),
        })?;
        let design = outcome.design(&self.design()?, &self.inputs.plan.priors);
        Ok((outcome, design))
    }

    /// The simulation key of the first posterior draw of the next refinement round, after the
    /// rounds in `log`: after every hypercube slot and every earlier round's draws (a dropped
    /// design point keeps its slot, so keys never collide).
    pub fn next_refine_key(&self, log: &crate::refine::RefineLog) -> usize {
        self.project.design.points + log.points().count()
    }

    /// Folder of the design-point simulations.
    pub fn simulations_dir(&self) -> PathBuf {
        self.out.join("simulations")
    }

    /// Stage 2, one job: simulates design point `i` (or reloads it if already done).
    pub fn simulate_point(
        &self,
        i: usize,
        x: &[f64],
    ) -> Result<(HourlyOutputs, Option<f64>), Error> {
        let dir = self.simulations_dir();
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        simulate_point(
            &self.inputs.runner,
            &self.inputs.model,
            &self.inputs.plan.values(x),
            &self.inputs.weather_path,
            &dir,
            i,
        )
    }

    /// Stage 3: the training set from the design and its simulated outputs; writes `dataset/`.
    /// The first `base` points are the settled design's, the rest refinement draws.
    pub fn training_set(
        &self,
        base: usize,
        design: &Design,
        sims: &[HourlyOutputs],
    ) -> Result<PathBuf, Error> {
        let inp = &self.inputs;
        let n_pts = design.points.len();
        let (n_h, n_out) = (inp.features.len(), inp.outputs.len());
        let mut points = Array2::zeros((n_pts, inp.plan.calibrated.len()));
        let mut y = Array3::zeros((n_pts, n_h, n_out));
        for (i, (x, o)) in design.points.iter().zip(sims).enumerate() {
            for (j, v) in x.iter().enumerate() {
                points[[i, j]] = *v;
            }
            for (k, name) in inp.outputs.iter().enumerate() {
                let s = o.get(name).ok_or_else(|| Error::Stage {
                    stage: "training set",
                    message: format!("design point {i} has no output {name}"),
                })?;
                for (h, v) in s.iter().enumerate() {
                    y[[i, h, k]] = *v;
                }
            }
        }
        let params: Vec<ParamSpec> = inp
            .plan
            .calibrated
            .iter()
            .zip(&inp.plan.priors)
            .map(|(n, p)| ParamSpec::new(n.clone(), p.min(), p.max(), p.mode()))
            .collect();
        let sp = &self.project.surrogate;
        // Nested over refinement rounds (see `Split::nested`): the hypercube's points split as
        // always, each appended draw keeps its side in every later round.
        let split = Split::nested(base.min(n_pts), n_pts, sp.held_out_fraction, sp.seed)?;
        let set = TrainingSet::new(params, points, &inp.features, inp.outputs.clone(), y, 0)?
            .with_split(split)?;
        let dir = self.out.join("dataset");
        set.write(&dir)?;
        Ok(dir)
    }

    /// Folder of the trained surrogate.
    pub fn surrogate_dir(&self) -> PathBuf {
        self.out.join("surrogate")
    }

    /// True once a valid surrogate is in place.
    pub fn has_surrogate(&self) -> bool {
        bemcal_surrogate::SurrogateMeta::read(&self.surrogate_dir()).is_ok()
    }

    /// Stage 4, one job: trains the surrogate on `dataset/` into `surrogate/`, starting from
    /// the weights in the surrogate folder `init` when given (a refinement round's warm start,
    /// see [`Calibration::warm_start`]).
    pub fn train(&self, init: Option<&Path>) -> Result<(), Error> {
        let sp = &self.project.surrogate;
        let opts = TrainOptions {
            epochs: sp.epochs,
            patience: sp.patience,
            seed: sp.seed,
            batch_size: sp.batch_size,
            time_features: sp.time_features.parse().map_err(Error::Config)?,
            threads: sp.threads,
            quiet: true,
            init: init.map(Path::to_path_buf),
            ..TrainOptions::default()
        };
        bemcal_surrogate::train(&self.out.join("dataset"), &self.surrogate_dir(), &opts)?;
        Ok(())
    }

    /// Stage 5 set-up: loads the surrogate and builds the likelihood (reference Eq. 7).
    pub fn sampler(&self) -> Result<Sampler<'_>, Error> {
        let inp = &self.inputs;
        let dir = self.surrogate_dir();
        let surrogate = Surrogate::load(&dir, self.project.surrogate.threads)?;
        let meta = surrogate.meta().clone();
        if meta.output_names() != inp.outputs {
            return Err(Error::Stage {
                stage: "surrogate",
                message: format!(
                    "surrogate in {} predicts {:?}, the calibration needs {:?}; delete it to retrain",
                    dir.display(),
                    meta.output_names(),
                    inp.outputs
                ),
            });
        }
        let sigma_eta = meta.sigma_eta_kwh();
        let (n_h, n_out) = (inp.features.len(), inp.outputs.len());
        let mut observed = vec![f64::NAN; n_h * n_out];
        // The surrogate predicts the model's share of each meter (the meter less its base).
        let shares: Vec<Vec<f64>> = (0..n_out).map(|k| inp.model_share(k)).collect();
        for (k, s) in shares.iter().enumerate() {
            for (h, v) in s.iter().enumerate() {
                observed[h * n_out + k] = *v;
            }
        }
        let stats: Vec<(f64, f64)> = shares.iter().map(|s| mean_sd(s)).collect();
        let m = &self.project.mcmc;
        let noise: Vec<OutputNoise> = stats
            .iter()
            .zip(&sigma_eta)
            .map(|((mean, sd), eta)| OutputNoise {
                sigma_y: m.sigma_y_fraction * mean.abs(),
                sigma_delta: m.sigma_delta_fraction * sd,
                sigma_eta: *eta,
            })
            .collect();
        let likelihood = GaussianLikelihood::new(&observed, &noise)?;
        let sd: Vec<f64> = stats.iter().map(|(_, s)| s.max(1e-9)).collect();
        Ok(Sampler {
            cal: self,
            evaluator: surrogate.bind(&inp.features)?,
            likelihood,
            noise,
            sigma_box: SigmaDeltaBox::new(&sd),
            sigma_eta,
            held_out: serde_json::to_value(&meta.held_out).unwrap_or_default(),
        })
    }

    /// Stage 7, one job per run: EnergyPlus at `values` (key `i` in `validation/`) against the
    /// meters, ASHRAE Guideline 14 per output.
    pub fn validate(&self, i: usize, label: &str, x: &[f64]) -> Result<Vec<OutputMetrics>, Error> {
        let inp = &self.inputs;
        let vdir = self.out.join("validation");
        std::fs::create_dir_all(&vdir).map_err(|e| Error::io(&vdir, e))?;
        let (o, _) = simulate_point(
            &inp.runner,
            &inp.model,
            &inp.plan.values(x),
            &inp.weather_path,
            &vdir,
            i,
        )?;
        write_outputs_csv(&vdir.join(format!("{label}.csv")), inp.year, &o)?;
        let mut m = vec![];
        for (k, name) in inp.outputs.iter().enumerate() {
            let sim = o.get(name).expect("model output");
            m.push(OutputMetrics {
                output: name.clone(),
                metrics: g14(&inp.measured[k], &inp.with_base(k, sim))?,
            });
        }
        Ok(m)
    }

    /// The prior modes of the calibrated parameters (the initial model).
    pub fn initial_point(&self) -> Vec<f64> {
        self.inputs.plan.priors.iter().map(|p| p.mode()).collect()
    }
}

impl Sampler<'_> {
    /// The posterior over the unit space.
    pub fn posterior(&self) -> Posterior<'_> {
        Posterior {
            plan: &self.cal.inputs.plan,
            model: &self.cal.inputs.model,
            likelihood: &self.likelihood,
            sigma_box: (self.cal.project.mcmc.sigma_delta == SigmaDeltaMode::Sampled)
                .then_some(&self.sigma_box),
            marginal: self.cal.project.mcmc.sigma_delta == SigmaDeltaMode::Marginal,
            ar1: self.cal.project.mcmc.residuals == Residuals::Ar1,
        }
    }

    /// MH settings of the chains on the surrogate of refinement round `round` (0 = the
    /// hypercube's): the last round's are the project's `[mcmc]`; earlier (preliminary) rounds
    /// use `[refine]`'s shorter burn-in.
    pub fn config_for(&self, round: u32) -> MhConfig {
        let m = &self.cal.project.mcmc;
        let burn_in = if round < self.cal.project.refine.rounds {
            self.cal.project.refine.burn_in
        } else {
            m.burn_in
        };
        MhConfig {
            burn_in,
            adapt_start: match m.start {
                // Keep the Laplace covariance of the optimum: in 40 dimensions a burn-in's AM
                // estimate is far worse (proposal sds 0.07-0.6 of the truth's vs 0.37 = the
                // optimal 2.38 / sqrt(d) with the Laplace one; crates/stats tests/mcmc_peaked.rs).
                ChainStart::Optimised => burn_in,
                // Adapt the covariance from the second half of burn-in only: the first half is
                // the transient from dispersed starts (measured on peaked 10-D/40-D targets).
                ChainStart::Prior => (burn_in / 2).max(100).min(burn_in),
            },
            initial_sd: m.initial_sd,
            independence: m.independence,
            ..MhConfig::default()
        }
    }

    /// HMC settings of round `round` (`mcmc.kernel = "hmc"`): burn-in as [`Self::config_for`].
    pub fn hmc_config_for(&self, round: u32) -> HmcConfig {
        HmcConfig {
            burn_in: self.config_for(round).burn_in,
            integration_time: self.cal.project.mcmc.hmc_integration_time,
            ..HmcConfig::default()
        }
    }

    /// MCMC settings of round `round`: a round's chains get their own random streams (the
    /// last round of a project without refinement keeps the project's seed).
    pub fn settings_for(&self, round: u32) -> McmcSettings {
        let mut m = self.cal.project.mcmc.clone();
        if round > 0 {
            m.seed = m
                .seed
                .wrapping_add(0x9E37_79B9_7F4A_7C15_u64.wrapping_mul(u64::from(round)));
        }
        m
    }

    /// Dispersed, feasible starting points (unit space), one per chain.
    pub fn starts(&self) -> Vec<Vec<f64>> {
        let cal = self.cal;
        let plan = &cal.inputs.plan;
        let post = self.posterior();
        let mut starts =
            dispersed_starts(&plan.priors, cal.project.mcmc.chains, cal.project.mcmc.seed);
        let modes: Vec<f64> = plan.priors.iter().map(|p| p.to_unit(p.mode())).collect();
        for s in &mut starts {
            let mut tries = 0;
            let ok = |s: &[f64]| {
                let x = post.theta(s);
                plan.feasible(&cal.inputs.model, &x) && plan.refused(&x).is_none()
            };
            while !ok(s) && tries < 50 {
                for (u, m) in s.iter_mut().zip(&modes) {
                    *u = 0.5 * (*u + m);
                }
                tries += 1;
            }
            if post.sigma_box.is_some() {
                s.extend(std::iter::repeat_n(0.6, cal.inputs.outputs.len()));
            }
        }
        starts
    }

    /// The posterior and the evaluator, borrowed together.
    pub fn split(&mut self) -> (Posterior<'_>, &mut Evaluator) {
        let mode = self.cal.project.mcmc.sigma_delta;
        let post = Posterior {
            plan: &self.cal.inputs.plan,
            model: &self.cal.inputs.model,
            likelihood: &self.likelihood,
            sigma_box: (mode == SigmaDeltaMode::Sampled).then_some(&self.sigma_box),
            marginal: mode == SigmaDeltaMode::Marginal,
            ar1: self.cal.project.mcmc.residuals == Residuals::Ar1,
        };
        (post, &mut self.evaluator)
    }

    /// New chain states at `starts` for the chains of round `round` (see [`Self::config_for`]);
    /// chain `c` gets random stream `first_chain + c`.
    pub fn new_chains(
        &mut self,
        starts: &[Vec<f64>],
        first_chain: u64,
        round: u32,
    ) -> Result<Vec<Chain>, Error> {
        let config = self.config_for(round);
        let hmc = self.hmc_config_for(round);
        let m = self.settings_for(round);
        let (post, eval) = self.split();
        chains_at(&post, eval, starts, config, &hmc, &m, first_chain)
    }

    /// The surrogate's hourly outputs at `points` (physical calibrated values):
    /// `[point][output][hour]`.
    pub fn predict(&mut self, points: &[Vec<f64>]) -> Result<Vec<Vec<Vec<f64>>>, Error> {
        let (n_h, n_out) = (
            self.cal.inputs.features.len(),
            self.cal.inputs.outputs.len(),
        );
        let mut out = vec![];
        for chunk in points.chunks(8) {
            let y = self.evaluator.evaluate_batch(chunk)?;
            for b in 0..chunk.len() {
                out.push(
                    (0..n_out)
                        .map(|k| (0..n_h).map(|h| f64::from(y[[b, h, k]])).collect())
                        .collect(),
                );
            }
        }
        Ok(out)
    }

    /// Stage 5, one job: advances chains by `n` iterations; returns this segment's draws.
    pub fn advance(&mut self, states: &mut [Chain], n: u64) -> Result<Vec<Draws>, Error> {
        let (post, eval) = self.split();
        advance_chains(&post, eval, states, n)
    }

    /// Stage 6: merged chains (their final `states` and `draws`) -> posterior summary, draws.csv
    /// and posterior predictive bands.
    pub fn summarize(&mut self, states: &[Chain], draws: &[Draws]) -> Result<ChainSummary, Error> {
        let cal = self.cal;
        let inp = &cal.inputs;
        let d = inp.plan.calibrated.len();
        let (n_h, n_out) = (inp.features.len(), inp.outputs.len());
        let theta_draws: Vec<Draws> = draws.iter().map(|dr| sub_draws(dr, d)).collect();
        let priors: Vec<Prior> = inp
            .plan
            .calibrated
            .iter()
            .zip(&inp.plan.priors)
            .zip(&inp.plan.units)
            .map(|((n, p), u)| Prior::new(n.clone(), u.clone(), *p))
            .collect();
        let posterior = summarize(&priors, &theta_draws)?;
        let sbox = self.sigma_box.clone();
        let noise = self.noise.clone();
        let (post, eval) = self.split();
        write_draws_csv(
            &cal.out.join("draws.csv"),
            &post,
            &inp.outputs,
            draws,
            &sbox,
        )?;
        let mut residual_ar1: Vec<(String, f64)> = vec![];
        let sigma_delta_kwh: Vec<(String, f64)> = match post.sigma_box {
            Some(b) => (0..n_out)
                .map(|k| {
                    let mut v: Vec<f64> = draws
                        .iter()
                        .flat_map(|dr| dr.column(d + k))
                        .map(|u| b.sigma(k, u))
                        .collect();
                    v.sort_by(f64::total_cmp);
                    (inp.outputs[k].clone(), v[v.len() / 2])
                })
                .collect(),
            None if post.marginal => {
                // Posterior mean of sigma_k^2 given the MAP parameters, InvGamma(n/2, SSR/2):
                // SSR / (n - 2); sigma_delta is what is left after sigma_y and sigma_eta.
                let y = eval.evaluate(&posterior.map_point)?;
                let flat = y.as_slice().expect("contiguous prediction");
                let ssr = post.likelihood.residual_sum_of_squares(flat);
                if post.ar1 {
                    residual_ar1 = inp
                        .outputs
                        .iter()
                        .cloned()
                        .zip(post.likelihood.ar1_coefficients(flat))
                        .collect();
                }
                let n_obs = post.likelihood.n_observed();
                inp.outputs
                    .iter()
                    .enumerate()
                    .map(|(k, name)| {
                        let total = ssr[k] / (n_obs[k] as f64 - 2.0).max(1.0);
                        let z = &noise[k];
                        let rest = total - z.sigma_y * z.sigma_y - z.sigma_eta * z.sigma_eta;
                        (name.clone(), rest.max(0.0).sqrt())
                    })
                    .collect()
            }
            None => inp
                .outputs
                .iter()
                .zip(&noise)
                .map(|(n, z)| (n.clone(), z.sigma_delta))
                .collect(),
        };
        // Posterior predictive bands from draws spread over all chains.
        let all: Vec<Vec<f64>> = theta_draws
            .iter()
            .flat_map(|dr| (0..dr.len()).map(move |i| dr.point(i).to_vec()))
            .collect();
        let want = cal.project.mcmc.predictive_draws.max(1);
        let step = (all.len() / want).max(1);
        let picks: Vec<Vec<f64>> = all.iter().step_by(step).map(|u| post.theta(u)).collect();
        let mut pred = vec![Vec::<f32>::with_capacity(picks.len() * n_h); n_out];
        for chunk in picks.chunks(8) {
            let y = eval.evaluate_batch(chunk)?;
            for b in 0..chunk.len() {
                for (k, p) in pred.iter_mut().enumerate() {
                    p.extend((0..n_h).map(|h| y[[b, h, k]]));
                }
            }
        }
        let mut bands = vec![];
        for (k, p) in pred.iter().enumerate() {
            let mut b = predictive_bands(p, picks.len(), n_h)?;
            for q in [&mut b.q5, &mut b.q50, &mut b.q95] {
                *q = inp.with_base(k, q);
            }
            bands.push(b);
        }
        write_bands_csv(
            &cal.out.join("posterior_predictive.csv"),
            inp.year,
            &inp.outputs,
            &inp.measured,
            &bands,
        )?;
        let estimate: Vec<f64> = match cal.project.validation.estimate {
            Estimate::Map => posterior.map_point.clone(),
            Estimate::Mean => posterior.parameters.iter().map(|p| p.mean).collect(),
            Estimate::Median => posterior.parameters.iter().map(|p| p.median).collect(),
        };
        let y = eval.evaluate(&estimate)?;
        let mut surrogate_at_estimate = vec![];
        for (k, name) in inp.outputs.iter().enumerate() {
            let pred: Vec<f64> = (0..n_h).map(|h| f64::from(y[[h, k]])).collect();
            surrogate_at_estimate.push(OutputMetrics {
                output: name.clone(),
                metrics: g14(&inp.measured[k], &inp.with_base(k, &pred))?,
            });
        }
        let fallbacks: Vec<Vec<f64>> = best_draws(&theta_draws, FALLBACKS + 1)
            .iter()
            .map(|u| post.theta(u))
            .filter(|x| x != &estimate)
            .take(FALLBACKS)
            .collect();
        Ok(ChainSummary {
            posterior,
            sigma_delta_kwh,
            residual_ar1,
            estimate,
            surrogate_at_estimate,
            fallbacks,
            estimate_note: None,
            moved_chains: moved_chains(states),
            independence_dropped: independence_dropped(states),
        })
    }
}

/// Chain states at `starts` (chain `c` gets random stream `first_chain + c`): optimised first
/// with `start = "optimised"` (see [`ChainStart`]); Metropolis-Hastings or HMC by `m.kernel`.
pub fn chains_at(
    post: &Posterior<'_>,
    eval: &mut Evaluator,
    starts: &[Vec<f64>],
    config: MhConfig,
    hmc_config: &HmcConfig,
    m: &McmcSettings,
    first_chain: u64,
) -> Result<Vec<Chain>, Error> {
    if m.kernel == Kernel::Hmc && !eval.has_gradient() {
        return Err(Error::Config(format!(
            "mcmc.kernel = \"hmc\" needs the surrogate's gradient graph, and {} has none \
             (trained before it existed): retrain, or add it with `python -m bemcal_train \
             --add-vjp {}`",
            eval.surrogate().dir().display(),
            eval.surrogate().dir().display()
        )));
    }
    if m.kernel == Kernel::Hmc && m.start == ChainStart::Prior {
        // The gradient call gives the starts' log posteriors too.
        let values = post.ln_posterior_grad_batch(eval, starts)?;
        return starts
            .iter()
            .zip(values)
            .enumerate()
            .map(|(c, (s, (lp, g)))| {
                Ok(Chain::from(HmcState::new(
                    hmc_config.clone(),
                    s,
                    None,
                    lp,
                    &g,
                    m.seed,
                    first_chain + c as u64,
                )?))
            })
            .collect();
    }
    let lps = post.ln_posterior_batch(eval, starts);
    if m.start == ChainStart::Optimised {
        let cfg = BfgsConfig {
            max_iterations: m.optimiser_iterations,
            ..BfgsConfig::default()
        };
        // With the surrogate's gradient graph (and no sampled sigma_delta), BFGS uses exact
        // gradients: one VJP call (about 3.3 evaluations) instead of d + 1 evaluations.
        let optima = if eval.has_gradient() && post.sigma_box.is_none() {
            let cell = std::cell::RefCell::new(&mut *eval);
            let mut failed = None;
            let optima = maximise_batch_with_gradient(
                starts,
                &lps,
                &cfg,
                |us: &[Vec<f64>]| post.ln_posterior_batch(&mut cell.borrow_mut(), us),
                &mut |us: &[Vec<f64>]| {
                    post.ln_posterior_grad_or_reject(&mut cell.borrow_mut(), us, &mut failed)
                },
            );
            if let Some(e) = failed {
                return Err(e);
            }
            optima
        } else {
            maximise_batch(starts, &lps, &cfg, |us: &[Vec<f64>]| {
                post.ln_posterior_batch(eval, us)
            })
        };
        return Ok(match m.kernel {
            Kernel::Mh => chains_at_optima(&config, optima, m.seed, first_chain, m.restart_below)?
                .into_iter()
                .map(Chain::from)
                .collect(),
            Kernel::Hmc => {
                let mut failed = None;
                let states = hmc::chains_at_optima(
                    hmc_config,
                    optima,
                    m.seed,
                    first_chain,
                    m.restart_below,
                    &mut |us: &[Vec<f64>]| post.ln_posterior_grad_or_reject(eval, us, &mut failed),
                );
                if let Some(e) = failed {
                    return Err(e);
                }
                states?.into_iter().map(Chain::from).collect()
            }
        });
    }
    starts
        .iter()
        .zip(lps)
        .enumerate()
        .map(|(c, (s, lp))| {
            Ok(Chain::from(ChainState::new(
                config.clone(),
                s.clone(),
                lp,
                m.seed,
                first_chain + c as u64,
            )?))
        })
        .collect()
}

/// What [`Sampler::summarize`] returns.
pub struct ChainSummary {
    pub posterior: PosteriorSummary,
    pub sigma_delta_kwh: Vec<(String, f64)>,
    /// Profile AR(1) coefficient of each output's residuals at the MAP (AR(1) mode).
    pub residual_ar1: Vec<(String, f64)>,
    /// The calibrated estimate (calibrated parameters, physical units).
    pub estimate: Vec<f64>,
    /// Guideline 14 of the surrogate at the estimate against the meters.
    pub surrogate_at_estimate: Vec<OutputMetrics>,
    /// Where EnergyPlus cannot simulate the estimate, the draws validated instead, best first:
    /// the next distinct draws by log posterior (physical units).
    pub fallbacks: Vec<Vec<f64>>,
    /// Set when a fallback draw replaced the estimate (why).
    pub estimate_note: Option<String>,
    /// Chains started in the best optimum's mode ([`moved_chains`] of the states).
    pub moved_chains: Vec<MovedChain>,
    /// Chains whose independence kernel was switched off after burn-in
    /// ([`independence_dropped`] of the states).
    pub independence_dropped: Vec<usize>,
}

/// A chain started in the best optimum's mode instead of its own, which was `nats_below` lower
/// (`mcmc.restart_below`, [`bemcal_stats::optim::keep_best_modes`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MovedChain {
    pub chain: usize,
    pub nats_below: f64,
}

/// The chains of `states` that were moved to the best optimum's mode.
pub fn moved_chains(states: &[Chain]) -> Vec<MovedChain> {
    states
        .iter()
        .enumerate()
        .filter_map(|(chain, s)| {
            s.moved_from_mode()
                .map(|nats_below| MovedChain { chain, nats_below })
        })
        .collect()
}

/// The chains of `states` whose independence kernel was switched off at the end of burn-in.
pub fn independence_dropped(states: &[Chain]) -> Vec<usize> {
    (0..states.len())
        .filter(|&c| states[c].independence_dropped())
        .collect()
}

/// What summary.json says when the estimate was replaced by the next-best draw.
pub fn fallback_note(failures: &[String]) -> String {
    format!(
        "EnergyPlus could not simulate the estimate; calibrated_values and validation are those \
         of the next-best posterior draw that it could simulate (by log posterior; {} failed: {})",
        failures.len(),
        failures.join(" | ")
    )
}

/// Assembles `summary.json` from the stages' results and writes it.
#[allow(clippy::too_many_arguments)]
pub fn write_summary(
    cal: &Calibration,
    design: &Design,
    chains: &ChainSummary,
    sampler_info: (&[f64], &serde_json::Value),
    acceptance: Vec<f64>,
    validation: Vec<OutputMetrics>,
    initial: Vec<OutputMetrics>,
    timings: Timings,
) -> Result<Summary, Error> {
    let inp = &cal.inputs;
    let summary = Summary {
        project: cal.project.name.clone(),
        measured_weather: inp.measured_weather.clone(),
        bases: inp.base_reports.clone(),
        outputs: inp.outputs.clone(),
        parameters: inp
            .plan
            .calibrated
            .iter()
            .zip(&inp.plan.priors)
            .zip(&inp.plan.units)
            .map(|((n, p), u)| ParameterReport {
                name: n.clone(),
                unit: u.clone(),
                prior_min: p.min(),
                prior_mode: p.mode(),
                prior_max: p.max(),
            })
            .collect(),
        converged: chains.posterior.max_rhat <= 1.01,
        posterior: chains.posterior.clone(),
        sigma_delta_kwh: chains.sigma_delta_kwh.clone(),
        residual_ar1: chains.residual_ar1.clone(),
        sigma_eta_kwh: inp
            .outputs
            .iter()
            .cloned()
            .zip(sampler_info.0.iter().copied())
            .collect(),
        acceptance_rate: acceptance,
        estimate: cal.project.validation.estimate,
        estimate_note: chains.estimate_note.clone(),
        moved_chains: chains.moved_chains.clone(),
        independence_dropped: chains.independence_dropped.clone(),
        calibrated_values: inp
            .plan
            .calibrated
            .iter()
            .cloned()
            .zip(chains.estimate.clone())
            .collect(),
        validation,
        initial,
        surrogate_at_estimate: chains.surrogate_at_estimate.clone(),
        design_points: design.points.len(),
        design_repair: design.repair,
        design: read_outcome(&cal.simulations_dir())
            .map(|o| DesignReport::new(cal, &o))
            .unwrap_or_default(),
        surrogate_held_out: sampler_info.1.clone(),
        refinement: cal.refine_log()?.rounds,
        timings,
    };
    write_calibrated_model(cal, &chains.estimate)?;
    crate::bases::write_bases_csv(cal)?;
    let json = serde_json::to_vec_pretty(&summary).map_err(|e| Error::Config(e.to_string()))?;
    write_atomic(&cal.out.join("summary.json"), &json)?;
    Ok(summary)
}

/// The calibrated model a user takes away: `calibrated.idf` (the model at `estimate`, the
/// validated calibrated values, with the fixed values) and `calibrated.toml` (every parameter
/// value, readable by `bemcal simulate --values`).
pub fn write_calibrated_model(cal: &Calibration, estimate: &[f64]) -> Result<(), Error> {
    let inp = &cal.inputs;
    let values = inp.plan.values(estimate);
    let idf = inp.model.instantiate(&values, inp.runner.idd())?;
    let scratch = cal.out.join("calibrated.expand");
    let _ = std::fs::remove_dir_all(&scratch);
    let simulated = inp.runner.simulated_input(&idf, &scratch)?;
    let _ = std::fs::remove_dir_all(&scratch);
    write_atomic(
        &cal.out.join("calibrated.idf"),
        simulated.to_text().as_bytes(),
    )?;
    let mut toml = format!(
        "# Parameter values of the calibrated model of '{}' (estimate: {}; calibrated and fixed).\n\
         # Simulate it: bemcal simulate --model {} --weather {} --values calibrated.toml --out hourly.csv\n\
         # or run EnergyPlus on calibrated.idf (HVAC templates expanded) with that weather file.\n",
        cal.project.name,
        format!("{:?}", cal.project.validation.estimate).to_lowercase(),
        inp.model.path.display(),
        inp.weather_path.display()
    );
    for (name, v) in &values {
        toml.push_str(&format!("{name} = {v}\n"));
    }
    write_atomic(&cal.out.join("calibrated.toml"), toml.as_bytes())
}

/// Runs the whole calibration of `project` into `out` on this machine.
pub fn calibrate(project: &Project, out: &Path, log: Log<'_>) -> Result<Summary, Error> {
    let t_all = Instant::now();
    let mut cal = Calibration::load(project.clone(), out)?;
    let inp = &cal.inputs;
    let mut timings = Timings::default();
    log(&format!(
        "model {}: {} parameters, {} calibrated; outputs {:?}; weather {}",
        inp.model.path.display(),
        inp.model.parameters().len(),
        inp.plan.calibrated.len(),
        inp.outputs,
        inp.weather_path.display()
    ));

    for note in &inp.plan.restricted {
        log(note);
    }
    let t = Instant::now();
    let hypercube = cal.design()?;
    let spares = cal.spares()?;
    timings.design_s = t.elapsed().as_secs_f64();
    log(&format!(
        "design: {} points over {} parameters (constraint repair: {} swaps, {} cells resampled)",
        hypercube.points.len(),
        inp.plan.calibrated.len(),
        hypercube.repair.swaps,
        hypercube.repair.resampled_in_stratum + hypercube.repair.resampled_outside_stratum
    ));

    let t = Instant::now();
    let sims = simulate_design(
        &inp.runner,
        &inp.model,
        &inp.plan,
        (&hypercube, &spares),
        cal.design_policy(),
        &inp.weather_path,
        &cal.simulations_dir(),
        project.design.parallel,
        log,
    )?;
    timings.simulations_s = t.elapsed().as_secs_f64();
    log(&format!(
        "simulations: {} run ({:.1} s each on average), {} reused",
        sims.seconds.len(),
        sims.seconds.iter().sum::<f64>() / sims.seconds.len().max(1) as f64,
        sims.reused
    ));
    log_design_outcome(&sims.outcome, log);
    let design = sims.outcome.design(&hypercube, &inp.plan.priors);
    let base = design.points.len();
    cal.learn_invalid_region(&sims.outcome);
    let cal = cal;
    let inp = &cal.inputs;
    if !inp.plan.invalid.balls.is_empty() {
        log(&format!(
            "chains: proposals near the {} design point(s) EnergyPlus could not simulate are \
             refused (summary.json design.invalid_region)",
            inp.plan.invalid.balls.len()
        ));
    }

    // Refinement points of rounds finished earlier (a rerun): their saved simulations.
    let mut refined = cal.refine_log()?;
    let mut outputs = sims.outputs;
    for p in refined.points() {
        outputs.push(cal.simulate_point(p.index, &p.values)?.0);
    }
    let rounds = project.refine.rounds;
    let (mut sampler, ck) = loop {
        let round = refined.rounds.len() as u32;
        let full = cal.full_design(&design, &refined);
        let t = Instant::now();
        cal.training_set(base, &full, &outputs)?;
        if cal.has_surrogate() {
            log("surrogate: reusing the one trained earlier");
        } else {
            log(&format!(
                "training the surrogate (PyTorch) on {} points...",
                full.points.len()
            ));
            let init = cal.warm_start(&refined);
            if let Some(dir) = &init {
                log(&format!("  warm start from {}", dir.display()));
            }
            cal.train(init.as_deref())?;
        }
        let mut sampler = cal.sampler()?;
        timings.training_s += t.elapsed().as_secs_f64();
        log(&format!(
            "surrogate: held-out RMSE (sigma_eta) {}",
            inp.outputs
                .iter()
                .zip(&sampler.sigma_eta)
                .map(|(n, s)| format!("{n} {s:.2} kWh"))
                .collect::<Vec<_>>()
                .join(", ")
        ));

        let t = Instant::now();
        // Round 0 starts at dispersed prior draws; later rounds where the previous ended.
        // (A log from before starts were recorded gives prior draws again.)
        let starts = match refined.rounds.last() {
            Some(r) if !r.starts.is_empty() => r.starts.clone(),
            _ => sampler.starts(),
        };
        let config = sampler.config_for(round);
        let hmc_config = sampler.hmc_config_for(round);
        let settings = sampler.settings_for(round);
        let last = round >= rounds;
        let iterations = if last {
            project.mcmc.iterations
        } else {
            project.refine.iterations
        };
        let path = cal.chains_path(round);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
        let label = if last {
            "chains".to_string()
        } else {
            format!("refinement round {} chains", round + 1)
        };
        let ck = {
            let (post, eval) = sampler.split();
            run_chains(
                &post,
                eval,
                |post, eval| chains_at(post, eval, &starts, config, &hmc_config, &settings, 0),
                iterations,
                project.mcmc.segment,
                &path,
                &|done, n| log(&format!("{label}: {done}/{n} iterations")),
            )?
        };
        timings.chains_s += t.elapsed().as_secs_f64();
        if last {
            break (sampler, ck);
        }

        // Refinement round `round + 1`: simulate posterior draws, record, retrain.
        let t = Instant::now();
        let post = sampler.posterior();
        let picks: Vec<Vec<f64>> = crate::refine::pick_draws(&ck.draws, project.refine.points)
            .iter()
            .map(|u| post.theta(u))
            .collect();
        let first = cal.next_refine_key(&refined);
        let indexed: Vec<(usize, Vec<f64>)> = picks
            .iter()
            .enumerate()
            .map(|(j, x)| (first + j, x.clone()))
            .collect();
        let results = crate::design::simulate_points(
            &inp.runner,
            &inp.model,
            &inp.plan,
            &indexed,
            &inp.weather_path,
            &cal.simulations_dir(),
            project.design.parallel,
            &|done, n| {
                log(&format!(
                    "refinement round {}: {done}/{n} simulations",
                    round + 1
                ))
            },
        )?;
        let mut points = vec![];
        let mut failed = vec![];
        let mut new_outputs = vec![];
        for ((i, x), r) in indexed.into_iter().zip(results) {
            match r {
                Ok((o, _)) => {
                    points.push(crate::refine::RefinePoint {
                        index: i,
                        values: x,
                    });
                    new_outputs.push(o);
                }
                Err(e) => {
                    log(&format!(
                        "refinement: posterior draw left out, EnergyPlus failed: {e}"
                    ));
                    failed.push(crate::refine::FailedPoint {
                        values: x,
                        error: e.to_string(),
                    });
                }
            }
        }
        let xs: Vec<Vec<f64>> = points.iter().map(|p| p.values.clone()).collect();
        let predicted = sampler.predict(&xs)?;
        let surrogate_error = crate::refine::pooled_error(&inp.outputs, &new_outputs, &predicted)?;
        log(&format!(
            "refinement round {}: {} posterior draws simulated ({} failed); surrogate vs EnergyPlus there: {}",
            round + 1,
            points.len(),
            failed.len(),
            surrogate_error
                .iter()
                .map(|m| format!(
                    "{} NMBE {:.1} % CV-RMSE {:.1} %",
                    m.output, m.metrics.nmbe, m.metrics.cv_rmse
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        drop(sampler);
        let last: Vec<Vec<f64>> = ck.states.iter().map(|s| s.position().to_vec()).collect();
        let (starts, restarted) =
            crate::refine::next_starts(&ck.draws, &last, project.refine.restart_below);
        for (c, gap) in &restarted {
            log(&format!(
                "refinement round {}: chain {c} ended {gap:.0} nats below the best: restarts in its mode",
                round + 1
            ));
        }
        timings.refinement_s += t.elapsed().as_secs_f64();
        outputs.extend(new_outputs);
        cal.record_round(
            &mut refined,
            crate::refine::RefineRound {
                round: round + 1,
                points,
                failed,
                surrogate_error,
                starts,
                restarted,
            },
        )?;
    };
    let acceptance: Vec<f64> = ck
        .states
        .iter()
        .map(|s| s.acceptance_rate_post_burn_in())
        .collect();
    log(&format!(
        "chains: acceptance after burn-in {acceptance:.3?}"
    ));
    let divergent: Vec<u64> = ck
        .states
        .iter()
        .map(Chain::divergent_post_burn_in)
        .collect();
    if divergent.iter().any(|&n| n > 0) {
        log(&format!(
            "chains: HMC trajectories stopped after burn-in (divergent or against a constraint; \
             rejected) per chain: {divergent:?}"
        ));
    }

    let t = Instant::now();
    let mut chains = sampler.summarize(&ck.states, &ck.draws)?;
    for m in &chains.moved_chains {
        log(&format!(
            "chains: chain {} started in the best optimum's mode (its own was {:.0} nats lower)",
            m.chain, m.nats_below
        ));
    }
    if !chains.independence_dropped.is_empty() {
        log(&format!(
            "chains: independence steps switched off after burn-in (accepted under {} %) in chains {:?}",
            bemcal_stats::mcmc::INDEPENDENCE_MIN_ACCEPTANCE * 100.0,
            chains.independence_dropped
        ));
    }
    timings.summary_s = t.elapsed().as_secs_f64();
    log(&format!(
        "posterior: max R-hat {:.3}, min bulk ESS {:.0}",
        chains.posterior.max_rhat, chains.posterior.min_ess_bulk
    ));

    let t = Instant::now();
    log("validation: EnergyPlus at the calibrated parameters");
    let mut failures: Vec<String> = vec![];
    let candidates: Vec<Vec<f64>> = std::iter::once(chains.estimate.clone())
        .chain(chains.fallbacks.iter().cloned())
        .collect();
    let mut validation = None;
    for (k, x) in candidates.iter().enumerate() {
        // Keys: 0 the estimate, 1 the initial model, 2.. the fallback draws.
        let i = if k == 0 { 0 } else { k + 1 };
        match cal.validate(i, "calibrated", x) {
            Ok(m) => {
                if k > 0 {
                    chains.estimate_note = Some(fallback_note(&failures));
                    chains.estimate = x.clone();
                }
                validation = Some(m);
                break;
            }
            Err(e) => {
                log(&format!(
                    "validation: EnergyPlus failed at candidate {k}: {e}"
                ));
                failures.push(e.to_string());
            }
        }
    }
    let validation = validation.ok_or_else(|| Error::Stage {
        stage: "validation",
        message: format!(
            "EnergyPlus failed at the estimate and at the next {} draws: {}",
            candidates.len() - 1,
            failures.join(" | ")
        ),
    })?;
    let initial = if project.validation.initial {
        log("validation: EnergyPlus at the initial parameters (prior modes)");
        cal.validate(1, "initial", &cal.initial_point())?
    } else {
        vec![]
    };
    timings.validation_s = t.elapsed().as_secs_f64();
    timings.total_s = t_all.elapsed().as_secs_f64();
    let info = (sampler.sigma_eta.clone(), sampler.held_out.clone());
    write_summary(
        &cal,
        &design,
        &chains,
        (&info.0, &info.1),
        acceptance,
        validation,
        initial,
        timings,
    )
}

/// Logs what became of the design points EnergyPlus could not simulate.
pub fn log_design_outcome(outcome: &Outcome, log: Log<'_>) {
    if outcome.failed.is_empty() {
        return;
    }
    log(&format!(
        "design: {} EnergyPlus run(s) failed; {} point(s) replaced by spare hypercube points, \
         {} dropped ({} of {} design points simulated)",
        outcome.failed.len(),
        outcome.replaced.len(),
        outcome.dropped.len(),
        outcome.slots.len(),
        outcome.slot_count()
    ));
    for g in outcome.reasons() {
        log(&format!(
            "design:   {} x {} (design points {:?})",
            g.count, g.reason, g.points
        ));
    }
}

/// Draws tried, in order, when EnergyPlus fails at the estimate.
pub const FALLBACKS: usize = 3;

/// Up to `k` distinct draws (unit space) in decreasing log posterior.
fn best_draws(draws: &[Draws], k: usize) -> Vec<Vec<f64>> {
    let mut all: Vec<(f64, &[f64])> = draws
        .iter()
        .flat_map(|d| (0..d.len()).map(move |i| (d.log_density[i], d.point(i))))
        .collect();
    all.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut out: Vec<Vec<f64>> = vec![];
    for (_, p) in all {
        if out.len() >= k {
            break;
        }
        if !out.iter().any(|q| q.as_slice() == p) {
            out.push(p.to_vec());
        }
    }
    out
}

fn mean_sd(s: &[f64]) -> (f64, f64) {
    let v: Vec<f64> = s.iter().copied().filter(|x| x.is_finite()).collect();
    let n = v.len().max(1) as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0).max(1.0);
    (m, var.sqrt())
}

fn sub_draws(d: &Draws, dim: usize) -> Draws {
    let mut out = Draws::new(dim);
    for i in 0..d.len() {
        out.points.extend_from_slice(&d.point(i)[..dim]);
    }
    out.log_density = d.log_density.clone();
    out
}

fn write_draws_csv(
    path: &Path,
    post: &Posterior<'_>,
    outputs: &[String],
    draws: &[Draws],
    sbox: &SigmaDeltaBox,
) -> Result<(), Error> {
    let d = post.plan.calibrated.len();
    let mut s = format!("chain,draw,{}", post.plan.calibrated.join(","));
    if post.sigma_box.is_some() {
        for o in outputs {
            s.push_str(&format!(",sigma_delta_{o}"));
        }
    }
    s.push_str(",log_posterior\n");
    for (c, dr) in draws.iter().enumerate() {
        for i in 0..dr.len() {
            let u = dr.point(i);
            s.push_str(&format!("{c},{i}"));
            for x in post.theta(u) {
                s.push_str(&format!(",{x}"));
            }
            if post.sigma_box.is_some() {
                for k in 0..outputs.len() {
                    s.push_str(&format!(",{}", sbox.sigma(k, u[d + k])));
                }
            }
            s.push_str(&format!(",{}\n", dr.log_density[i]));
        }
    }
    write_atomic(path, s.as_bytes())
}

pub(crate) fn timestamps(year: i32, n: usize) -> Vec<String> {
    let start = chrono::NaiveDate::from_ymd_opt(year, 1, 1)
        .and_then(|d| d.and_hms_opt(0, 0, 0))
        .expect("valid year");
    (0..n)
        .map(|t| {
            (start + chrono::Duration::hours(t as i64))
                .format("%Y-%m-%dT%H:%M")
                .to_string()
        })
        .collect()
}

/// Writes hourly outputs as `timestamp,<output>...`.
pub fn write_outputs_csv(
    path: &Path,
    year: i32,
    o: &bemcal_energyplus::HourlyOutputs,
) -> Result<(), Error> {
    let mut s = format!("timestamp,{}\n", o.names.join(","));
    for (t, ts) in timestamps(year, o.hours()).iter().enumerate() {
        s.push_str(ts);
        for series in &o.series {
            s.push_str(&format!(",{:.6}", series[t]));
        }
        s.push('\n');
    }
    write_atomic(path, s.as_bytes())
}

fn write_bands_csv(
    path: &Path,
    year: i32,
    outputs: &[String],
    measured: &[Vec<f64>],
    bands: &[bemcal_stats::summary::PredictiveBands],
) -> Result<(), Error> {
    let mut s = String::from("timestamp");
    for o in outputs {
        s.push_str(&format!(",{o}_measured,{o}_q5,{o}_q50,{o}_q95"));
    }
    s.push('\n');
    let n = bands.first().map_or(0, |b| b.q50.len());
    for (t, ts) in timestamps(year, n).iter().enumerate() {
        s.push_str(ts);
        for (k, b) in bands.iter().enumerate() {
            let m = measured[k][t];
            let m = if m.is_finite() {
                format!("{m:.4}")
            } else {
                String::new()
            };
            s.push_str(&format!(
                ",{m},{:.4},{:.4},{:.4}",
                b.q5[t], b.q50[t], b.q95[t]
            ));
        }
        s.push('\n');
    }
    write_atomic(path, s.as_bytes())
}
