//! The one driver of a calibration: every stage in the order the data flows, every decision
//! taken once, here, by the rules of [`crate::sequence`], [`crate::replacement`],
//! [`crate::refine`] and [`crate::validation::next_candidate`]. How the work is done is an [`Executor`]'s:
//! the local one ([`crate::local::calibrate`]) runs it in this process and answers at once; the
//! coordinator's leases it to workers as jobs and answers [`Ready::Pending`] until they are
//! done, then calls [`drive`] again.
//!
//! [`drive`] is re-entrant: it reads what is settled from the output folder (the settled
//! design `simulations/design.json`, the rounds in `refine.json`, the surrogate in place, the
//! final chains' target and summary in `chains_summary.json`) and asks the executor for the
//! rest, so a call after any interruption, on either side, goes on where the last one
//! stopped.
//!
//! ```text
//! design (waves until replacement::next_step settles it) -> training set -> surrogate
//!   -> chains of Round::Preliminary(r) -> EnergyPlus at its draws -> close_round  (refine.rounds times)
//!   -> chains of Round::Final -> summarised -> extended while short of the targets
//!   -> validation_runs (the estimate, the predictive draws) -> best_simulated (which becomes
//!      the estimate) or next_validation while EnergyPlus fails at every one -> summary
//! ```

use std::path::Path;

use bemcal_energyplus::HourlyOutputs;
use serde::{Deserialize, Serialize};

use crate::calibration::{Calibration, Log};
use crate::chain_summary::ChainSummary;
use crate::chains::Sampler;
use crate::design::{read_outcome, saved_outputs};
use crate::error::Error;
use crate::mapping::{self, MappingStep};
use crate::metrics::OutputMetrics;
use crate::output::read_record;
use crate::posterior::{ChainTemperature, Checkpoint};
use crate::project::Estimate;
use crate::refine::{close_round, refinement_points, RefineLog, RefineRound, SimulatedDraw};
use crate::replacement::{Attempt, Outcome, Step};
use crate::savings::SavingsPlan;
use crate::sequence::{
    after_final_chains, next_validation, validation_runs, AfterFinalChains, Round, Stage,
    ValidationRole, ValidationRun,
};
use crate::summary::{write_summary, Summary, Timings};
use crate::surrogate_error::chain_temperature;

/// Work done now, or not yet (an executor that leases jobs: the driver is called again when
/// they finish).
#[derive(Debug)]
pub enum Ready<T> {
    /// Done, with its result.
    Done(T),
    /// Not done yet: the driver stops here and is called again later.
    Pending,
}

/// Unwraps [`Ready::Done`], or returns [`Ready::Pending`] from the calling function.
macro_rules! ready {
    ($e:expr) => {
        match $e {
            Ready::Done(v) => v,
            Ready::Pending => return Ok(Ready::Pending),
        }
    };
}

/// One simulated point's result: its hourly outputs, or EnergyPlus's failure.
pub type PointResult = Result<HourlyOutputs, String>;

/// One validation run's result: Guideline 14 per output, or EnergyPlus's failure.
pub type ValidationResult = Result<Vec<OutputMetrics>, String>;

/// The validation's metrics: the calibrated model's, and the initial model's (empty unless
/// `validation.initial`).
struct Validated {
    calibrated: Vec<OutputMetrics>,
    initial: Vec<OutputMetrics>,
}

/// How the expensive work of a calibration is done (EnergyPlus, training, chains), and where
/// the time goes. Each method either does the work and answers [`Ready::Done`], or starts it
/// (or finds it started) and answers [`Ready::Pending`]; asked again with the same arguments
/// it answers for the same work. Results land in the calibration's output folder, as the
/// in-process executor writes them.
pub trait Executor {
    /// The driver enters `stage` (for status and [`Executor::timings`]).
    fn enter(&mut self, stage: Stage) -> Result<(), Error>;

    /// EnergyPlus at each `(key, values)` of `wave` (`round` 0: design points; `r`: posterior
    /// draws of refinement round `r`), saved under its key in `simulations/`. One result per
    /// point, in order; a failed run does not stop the others.
    fn simulate(
        &mut self,
        cal: &Calibration,
        wave: &[(usize, Vec<f64>)],
        round: u32,
    ) -> Result<Ready<Vec<PointResult>>, Error>;

    /// The surrogate trained on `dataset/` into `surrogate/` (`round`: refinement rounds
    /// finished before; `init`: the surrogate folder to warm-start from).
    fn train(
        &mut self,
        cal: &Calibration,
        round: u32,
        init: Option<&Path>,
    ) -> Result<Ready<()>, Error>;

    /// The chains of `round` run to `iterations` per chain (burn-in included), starting at
    /// `starts` (`None`: the sampler's starts), their draws in order. `sampler` is the
    /// round's, for an executor that runs them here.
    fn chains(
        &mut self,
        cal: &Calibration,
        round: Round,
        iterations: u64,
        starts: Option<&[Vec<f64>]>,
        sampler: &mut LazySampler<'_>,
    ) -> Result<Ready<Checkpoint>, Error>;

    /// EnergyPlus at each validation run, saved as `validation/<label>.csv`, with Guideline
    /// 14 against the meters; a run's failure as its message (fatal only where the driver
    /// says so: [`ValidationRun::tolerates_failure`]).
    fn validate(
        &mut self,
        cal: &Calibration,
        runs: &[ValidationRun],
    ) -> Result<Ready<Vec<ValidationResult>>, Error>;

    /// EnergyPlus at each run of the measures' savings ([`SavingsPlan::runs`]), saved under
    /// its folder of `savings/` ([`SavingsPlan::run_rel`]); one result per run, in order, a
    /// failed run its reason (it does not stop the others).
    fn savings(
        &mut self,
        cal: &Calibration,
        plan: &SavingsPlan,
    ) -> Result<Ready<Vec<PointResult>>, Error>;

    /// The time spent per stage so far, and in all.
    fn timings(&self) -> Timings;

    /// Whether a call of [`drive`] is a start or restart of the calibration, so that what it
    /// finds settled is worth saying (the local executor: a rerun reuses the folder's work);
    /// not where the driver is called again after every finished job (the coordinator's).
    fn announces_reuse(&self) -> bool {
        true
    }
}

/// The sampler of a round, loaded when first needed (a driver call that finds the round's
/// work pending never loads the surrogate).
pub struct LazySampler<'c> {
    cal: &'c Calibration,
    temperature: ChainTemperature,
    sampler: Option<Sampler<'c>>,
}

impl<'c> LazySampler<'c> {
    /// Nothing loaded yet; the round's chains at `temperature`.
    pub fn new(cal: &'c Calibration, temperature: ChainTemperature) -> LazySampler<'c> {
        LazySampler {
            cal,
            temperature,
            sampler: None,
        }
    }

    /// The likelihood's temperature of the round's chains.
    pub fn temperature(&self) -> ChainTemperature {
        self.temperature
    }

    /// The sampler, loaded on the first call.
    pub fn get(&mut self) -> Result<&mut Sampler<'c>, Error> {
        if self.sampler.is_none() {
            let mut sampler = self.cal.sampler()?;
            sampler.set_temperature(self.temperature);
            self.sampler = Some(sampler);
        }
        Ok(self.sampler.as_mut().expect("loaded above"))
    }
}

/// Drives the calibration as far as `exec` lets it go now: [`Ready::Done`] with the summary
/// written, or [`Ready::Pending`] where the executor's work is not done yet.
pub fn drive(
    cal: &mut Calibration,
    exec: &mut dyn Executor,
    log: Log<'_>,
) -> Result<Ready<Summary>, Error> {
    // What the folder's chains are fitted to, for a later rerun into it (local or fetched);
    // written when it changes, not on every call (the coordinator calls once per job).
    let fitted = cal.fitted_data().to_text();
    if std::fs::read_to_string(cal.out.holdout_txt()).ok() != Some(fitted.clone()) {
        crate::error::write_atomic(&cal.out.holdout_txt(), fitted.as_bytes())?;
    }
    match read_outcome(&cal.simulations_dir()) {
        // Settled before this call: `Calibration::load` learnt its invalid region.
        Some(o) => {
            if exec.announces_reuse() {
                log(&format!(
                    "design: settled earlier (simulations/design.json): 0 run, {} reused",
                    o.slots.len()
                ));
            }
        }
        None => {
            let outcome = ready!(design_points(cal, exec, log)?);
            cal.learn_invalid_region(&outcome);
        }
    }
    let cal: &Calibration = cal;
    let mut refined = cal.refine_log()?;
    let finished = loop {
        let round = Round::after(&cal.project, refined.rounds.len() as u32);
        ready!(surrogate(cal, exec, &refined, log)?);
        // The final chains pool the family's recoveries where the surrogate started from a
        // pretrained network that records them (crate::surrogate_error::FAMILY_WEIGHT).
        let family = round
            .is_final()
            .then(|| crate::pretrained::family(&[&cal.out.pretrained(), &cal.surrogate_dir()]))
            .flatten()
            .map(|f| f.for_building(&cal.project.name, &cal.inputs.plan.calibrated));
        let temperature = chain_temperature(
            cal.project.mcmc.temperature,
            &cal.inputs.plan,
            &refined,
            family.as_ref(),
        )?;
        let mut sampler = LazySampler::new(cal, temperature);
        let starts = refined
            .rounds
            .last()
            .filter(|r| !r.starts.is_empty())
            .map(|r| r.starts.clone());
        if round.is_final() {
            break ready!(final_chains(
                cal,
                exec,
                &mut sampler,
                &refined,
                starts,
                log
            )?);
        }
        exec.enter(Stage::Chains)?;
        let iterations = round.iterations(&cal.project);
        let ck = ready!(exec.chains(cal, round, iterations, starts.as_deref(), &mut sampler)?);
        exec.enter(Stage::Refine)?;
        let closed = ready!(refine_round(cal, exec, &mut sampler, &ck, &refined, log)?);
        drop(sampler);
        cal.record_round(&mut refined, closed)?;
    };
    let mut chains = finished;
    let validated = ready!(validate(cal, exec, &mut chains, log)?);
    exec.enter(Stage::Summary)?;
    let (_, design) = cal.settled_design()?;
    let (calibrated, initial) = (validated.calibrated, validated.initial);
    let summary = write_summary(cal, &design, &chains, calibrated, initial, exec.timings())?;
    let summary = ready!(savings(cal, exec, summary, log)?);
    exec.enter(Stage::Done)?;
    Ok(Ready::Done(summary))
}

/// The measures' savings as the calibration's last stage where `[savings] with_calibration`
/// asks for them (as `bemcal savings` would estimate them from the finished folder, EnergyPlus
/// alone): the plan ([`SavingsPlan::new`]), its runs by the executor, and the savings added
/// to `summary`, which is written again with them.
fn savings(
    cal: &Calibration,
    exec: &mut dyn Executor,
    summary: Summary,
    log: Log<'_>,
) -> Result<Ready<Summary>, Error> {
    let settings = &cal.project.savings;
    if !settings.with_calibration {
        return Ok(Ready::Done(summary));
    }
    exec.enter(Stage::Savings)?;
    let estimated =
        match SavingsPlan::new(cal, &cal.project.measures, settings.draws, settings.split) {
            Ok(plan) => {
                log(&plan.describe());
                let runs = ready!(exec.savings(cal, &plan)?);
                // The savings' time closed into the timings the summary is written again with.
                exec.enter(Stage::Done)?;
                plan.finish(cal, runs, 0, Some(exec.timings()), log)
            }
            Err(e) => Err(e),
        };
    // The calibration is finished and written: savings that cannot be estimated are said, and
    // leave it standing.
    match estimated {
        Ok(report) => Ok(Ready::Done(Summary {
            savings: Some(report),
            ..summary
        })),
        Err(e) => {
            log(&format!(
                "savings: not estimated: {e} (the calibration stands; `bemcal savings` on its \
                 folder estimates them once that is mended)"
            ));
            Ok(Ready::Done(summary))
        }
    }
}

/// The design: the hypercube's points simulated in waves, a failed point replaced by a spare
/// or dropped as [`crate::replacement::next_step`] says, until the design is settled
/// (recorded as `simulations/design.json`) or too few points are left.
fn design_points(
    cal: &Calibration,
    exec: &mut dyn Executor,
    log: Log<'_>,
) -> Result<Ready<Outcome>, Error> {
    exec.enter(Stage::Design)?;
    let hypercube = cal.design()?;
    let spares = cal.spares()?;
    log(&format!(
        "design: {} points over {} parameters (constraint repair: {} swaps, {} cells resampled)",
        hypercube.points.len(),
        cal.inputs.plan.calibrated.len(),
        hypercube.repair.swaps,
        hypercube.repair.resampled_in_stratum + hypercube.repair.resampled_outside_stratum
    ));
    exec.enter(Stage::Simulate)?;
    let mut attempts: Vec<Attempt> = vec![];
    loop {
        match cal.design_step(&hypercube, &spares, &attempts) {
            Step::Simulate(wave) => {
                let results = ready!(exec.simulate(cal, &wave, 0)?);
                for ((slot, values), r) in wave.into_iter().zip(results) {
                    attempts.push(Attempt {
                        slot,
                        values,
                        error: r.err(),
                    });
                }
            }
            Step::Failed(message) => {
                return Err(Error::Stage {
                    stage: Stage::Design.as_str(),
                    message,
                })
            }
            Step::Done(outcome) => {
                cal.record_outcome(&outcome)?;
                log_design_outcome(&outcome, log);
                if !outcome.failed.is_empty() {
                    log(
                        "chains: proposals near the design points EnergyPlus could not simulate \
                         are refused (summary.json design.invalid_region)",
                    );
                }
                return Ok(Ready::Done(outcome));
            }
        }
    }
}

/// The surrogate of the current round, unless one is in place: the training set (the settled
/// design, then every finished round's draws) written, then trained (warm-started from the
/// last round's surrogate where `surrogate.warm_start` allows).
fn surrogate(
    cal: &Calibration,
    exec: &mut dyn Executor,
    refined: &RefineLog,
    log: Log<'_>,
) -> Result<Ready<()>, Error> {
    if cal.has_surrogate() {
        if exec.announces_reuse() {
            log("surrogate: reusing the one trained earlier");
        }
        return Ok(Ready::Done(()));
    }
    exec.enter(Stage::Train)?;
    let (full, outputs) = cal.simulated_points(refined)?;
    let designed = full.points.len() - refined.points().count();
    cal.training_set(designed, &full, &outputs)?;
    let init = cal.warm_start(refined);
    log(&format!(
        "training the surrogate (PyTorch) on {} points{}",
        full.points.len(),
        init.as_ref().map_or(String::new(), |d| format!(
            ", warm start from {}",
            d.display()
        ))
    ));
    ready!(exec.train(cal, refined.rounds.len() as u32, init.as_deref())?);
    if !cal.has_surrogate() {
        return Err(Error::Stage {
            stage: "surrogate",
            message: format!(
                "training left no valid surrogate in {}",
                cal.surrogate_dir().display()
            ),
        });
    }
    if let Ok(meta) = bemcal_surrogate::SurrogateMeta::read(&cal.surrogate_dir()) {
        log(&format!(
            "surrogate: held-out RMSE (sigma_eta) {}",
            cal.inputs
                .outputs
                .iter()
                .zip(meta.sigma_eta_kwh())
                .map(|(n, s)| format!("{n} {s:.2} kWh"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    Ok(Ready::Done(()))
}

/// A refinement round after its chains: posterior draws picked
/// ([`refinement_points`]), simulated by EnergyPlus, and the round closed by
/// [`close_round`] (the surrogate's error there, the next round's starts).
fn refine_round(
    cal: &Calibration,
    exec: &mut dyn Executor,
    sampler: &mut LazySampler<'_>,
    ck: &Checkpoint,
    refined: &RefineLog,
    log: Log<'_>,
) -> Result<Ready<RefineRound>, Error> {
    let round = refined.rounds.len() as u32 + 1;
    let refine = &cal.project.refine;
    let first = cal.next_refine_key(refined);
    let wave: Vec<(usize, Vec<f64>)> = {
        let post = sampler.get()?.posterior();
        refinement_points(&ck.draws, refine.points, refine.spread, |u| {
            post.ln_prior(u).is_finite()
        })
        .iter()
        .enumerate()
        .map(|(j, u)| (first + j, post.theta(u)))
        .collect()
    };
    let results = ready!(exec.simulate(cal, &wave, round)?);
    let simulated = wave
        .into_iter()
        .zip(results)
        .map(|((index, values), outputs)| {
            if let Err(e) = &outputs {
                log(&format!(
                    "refinement: posterior draw left out, EnergyPlus failed: {e}"
                ));
            }
            SimulatedDraw {
                index,
                values,
                outputs,
            }
        })
        .collect();
    let last: Vec<Vec<f64>> = ck.states.iter().map(|s| s.position().to_vec()).collect();
    let (closed, _) = close_round(
        round,
        simulated,
        sampler.get()?,
        &ck.draws,
        &last,
        refine.restart_below,
    )?;
    log_round(&closed, log);
    Ok(Ready::Done(closed))
}

/// The final chains' target and their summary at it (`chains_summary.json`): the state of
/// the extensions, so that a later call neither summarises the same chains again nor loses
/// an extension. It holds only for the settings it was written under (`mcmc`, the refinement
/// rounds before the chains, `validation.estimate`, the temperature), and a summary only for
/// the chains it summarised (each chain's last position): a rerun with other settings, or
/// after `chains.json` was deleted and the chains ran again differently, starts it afresh.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct FinalChains {
    /// The settings it holds for.
    settings: String,
    /// The likelihood's temperature it holds for (the same up to
    /// [`crate::posterior::same_temperature`]).
    #[serde(default = "crate::posterior::untempered")]
    temperature: f64,
    /// Iterations per chain the final chains run to (raised by each extension).
    target: u64,
    /// Extensions so far.
    extensions: u32,
    /// The chains summarised at `target`, once they got there, with each chain's last
    /// position then.
    summary: Option<(Vec<Vec<f64>>, ChainSummary)>,
}

impl FinalChains {
    /// The record of the folder's final chains under the current settings, or a fresh one.
    fn read(cal: &Calibration, rounds: usize, temperature: f64) -> FinalChains {
        let (mcmc, estimate) = (&cal.project.mcmc, cal.project.validation.estimate);
        let settings = format!("{mcmc:?} after {rounds} refinement rounds, estimate {estimate:?}");
        let legacy = format!("{mcmc:?} after {rounds} refinement rounds at temperature ");
        let saved = read_record::<FinalChains>(&cal.out.chains_summary())
            .ok()
            .flatten();
        saved
            .filter(|f| f.holds_for(&settings, &legacy, temperature))
            .unwrap_or(FinalChains {
                settings,
                temperature,
                target: cal.project.mcmc.iterations,
                extensions: 0,
                summary: None,
            })
    }

    /// Whether this record holds for `settings` at `temperature` (the same up to
    /// [`crate::posterior::same_temperature`]). A record written before the temperature
    /// had its own field ended its settings with `legacy` and the temperature, and said nothing
    /// of the estimate: it holds at the same temperature, so that chains extended before an
    /// upgrade keep their extensions.
    fn holds_for(&self, settings: &str, legacy: &str, temperature: f64) -> bool {
        use crate::posterior::same_temperature;
        if self.settings == settings {
            return same_temperature(self.temperature, temperature);
        }
        (self.settings.strip_prefix(legacy))
            .and_then(|t| t.parse::<f64>().ok())
            .is_some_and(|t| same_temperature(t, temperature))
    }

    /// The summary of chains that ended at `last`, if it is theirs.
    fn summary_of(&self, last: &[Vec<f64>]) -> Option<ChainSummary> {
        match &self.summary {
            Some((at, s)) if at.as_slice() == last => Some(s.clone()),
            _ => None,
        }
    }

    fn write(&self, cal: &Calibration) -> Result<(), Error> {
        let json = serde_json::to_vec(self).map_err(|e| Error::Config(e.to_string()))?;
        crate::error::write_atomic(&cal.out.chains_summary(), &json)
    }
}

/// The final chains, summarised, and extended while they miss a convergence target
/// ([`after_final_chains`]).
fn final_chains(
    cal: &Calibration,
    exec: &mut dyn Executor,
    sampler: &mut LazySampler<'_>,
    refined: &RefineLog,
    starts: Option<Vec<Vec<f64>>>,
    log: Log<'_>,
) -> Result<Ready<ChainSummary>, Error> {
    let m = &cal.project.mcmc;
    let round = Round::after(&cal.project, refined.rounds.len() as u32);
    let mut state = FinalChains::read(cal, refined.rounds.len(), sampler.temperature().value);
    loop {
        exec.enter(Stage::Chains)?;
        let ck = ready!(exec.chains(cal, round, state.target, starts.as_deref(), sampler)?);
        let last: Vec<Vec<f64>> = ck.states.iter().map(|s| s.position()).collect();
        let chains = match state.summary_of(&last) {
            Some(c) => c,
            None => {
                exec.enter(Stage::Merge)?;
                let mut c = sampler.get()?.summarize(&ck.states, &ck.draws, refined)?;
                c.extensions = state.extensions;
                log_chains(&c, &ck, log);
                state.summary = Some((last, c.clone()));
                state.write(cal)?;
                c
            }
        };
        match after_final_chains(m, &chains, state.target, ck.drawn()) {
            AfterFinalChains::Extend { iterations } => {
                log(&format!(
                    "chains: {}: extending to {iterations} iterations (extension {} of at most {})",
                    chains.convergence,
                    chains.extensions + 1,
                    m.max_extensions
                ));
                state.target = iterations;
                state.extensions += 1;
                state.summary = None;
                state.write(cal)?;
            }
            AfterFinalChains::Validate => return Ok(Ready::Done(chains)),
        }
    }
}

/// The validation runs of the sequence ([`validation_runs`]): EnergyPlus at the estimate, the
/// initial model and the predictive draws; while EnergyPlus fails at the calibrated model, at
/// the next-best draw ([`next_validation`]), the estimate then settled on the draw that ran.
/// With `estimate = "best_simulated"` the MAP draw or a predictive draw that ran is chosen
/// first ([`adopt_best_simulated`]); the next-best draws only where none ran. A predictive
/// draw EnergyPlus cannot simulate is left out of the intervals.
fn validate(
    cal: &Calibration,
    exec: &mut dyn Executor,
    chains: &mut ChainSummary,
    log: Log<'_>,
) -> Result<Ready<Validated>, Error> {
    exec.enter(Stage::Validate)?;
    let initial_point = cal.project.validation.initial.then(|| cal.initial_point());
    let runs = validation_runs(chains, initial_point);
    let results = ready!(exec.validate(cal, &runs)?);
    let (mut calibrated, mut initial, mut failures) = (None, vec![], vec![]);
    // The MAP draw and the predictive draws EnergyPlus simulated, with their metrics.
    let mut simulated: Vec<(ValidationRun, Vec<OutputMetrics>)> = vec![];
    for (run, r) in runs.iter().zip(results) {
        match (run.role, r) {
            (ValidationRole::Calibrated { .. }, Ok(m)) => {
                simulated.push((run.clone(), m.clone()));
                calibrated = Some(m);
            }
            (ValidationRole::Calibrated { .. }, Err(e)) => failures.push(e),
            (ValidationRole::Initial, Ok(m)) => initial = m,
            (ValidationRole::Initial, Err(message)) => {
                return Err(Error::Stage {
                    stage: "validation",
                    message: format!("EnergyPlus at the initial model: {message}"),
                })
            }
            (ValidationRole::Predictive | ValidationRole::Mapped, Ok(m)) => {
                simulated.push((run.clone(), m))
            }
            (ValidationRole::Predictive | ValidationRole::Mapped, Err(e)) => log(&format!(
                "validation: EnergyPlus failed at {}, left out: {e}",
                run.label
            )),
        }
    }
    if cal.project.validation.estimate == Estimate::BestSimulated {
        // One surrogate for the mapping's optimisations and the chosen point's metrics,
        // loaded only if either needs it.
        let mut sampler = LazySampler::new(cal, ChainTemperature::ONE);
        let steps = ready!(map_estimate(cal, exec, &mut sampler, &mut simulated, log)?);
        let map_failure = failures.first();
        if let Some(m) = adopt_best_simulated(
            cal,
            chains,
            &mut sampler,
            &simulated,
            steps,
            map_failure,
            log,
        )? {
            return Ok(Ready::Done(Validated {
                calibrated: m,
                initial,
            }));
        }
    }
    let validation = loop {
        if let Some(m) = calibrated.take() {
            break m;
        }
        if let Some(e) = failures.last() {
            log(&format!(
                "validation: EnergyPlus failed at candidate {}: {e}",
                failures.len() - 1
            ));
        }
        let run = next_validation(chains, &failures).map_err(|message| Error::Stage {
            stage: "validation",
            message,
        })?;
        let mut r = ready!(exec.validate(cal, std::slice::from_ref(&run))?);
        match r.pop() {
            Some(Ok(m)) => calibrated = Some(m),
            Some(Err(e)) => failures.push(e),
            None => {
                return Err(Error::Stage {
                    stage: "validation",
                    message: "the executor returned no result".into(),
                })
            }
        }
    };
    chains.settle_estimate(&failures);
    Ok(Ready::Done(Validated {
        calibrated: validation,
        initial,
    }))
}

/// `estimate = "best_simulated"`, where EnergyPlus fits none of the points it `simulated`
/// (the MAP draw and the predictive draws; appended to as it goes): output space mapping
/// ([`crate::mapping`]), at most `validation.mapping_steps` steps while no point passes
/// Guideline 14 hourly and monthly, each from the best point so far ([`mapping::next_step`]), its points
/// simulated as one validation wave. The steps are recorded in `validation/mapping.json`, so
/// that a later call of the driver asks for the same points (and says so only when it computes
/// a step); a step's mapped points EnergyPlus cannot simulate, or that the model's
/// constraints or the region where EnergyPlus failed refuse, are left out.
fn map_estimate(
    cal: &Calibration,
    exec: &mut dyn Executor,
    sampler: &mut LazySampler<'_>,
    simulated: &mut Vec<(ValidationRun, Vec<OutputMetrics>)>,
    log: Log<'_>,
) -> Result<Ready<Vec<MappingStep>>, Error> {
    let (inp, vdir) = (&cal.inputs, cal.out.validation());
    let mut record = mapping::read(&vdir);
    let (mut steps, mut anchors) = (vec![], vec![]);
    loop {
        let fits: Vec<crate::metrics::Fit> = (simulated.iter())
            .map(|(_, m)| crate::metrics::Fit::of(m, &inp.fitted))
            .collect();
        let max = cal.project.validation.mapping_steps;
        let Some((a, fractions)) = mapping::next_step(&fits, &anchors, max) else {
            break;
        };
        anchors.push(a);
        let anchor = simulated[a].0.clone();
        let first = 1 + steps
            .iter()
            .map(|s: &MappingStep| s.points.len())
            .sum::<usize>();
        let step = match record.get(steps.len()) {
            Some(s) if s.starts_at(&anchor.label, &anchor.values) && s.at(&fractions) => s.clone(),
            _ => {
                // An anchor used before has the same correction and so the same mode.
                let earlier = (steps.iter()).find(|s| s.starts_at(&anchor.label, &anchor.values));
                let mode = match earlier {
                    Some(s) => s.mode.clone(),
                    None => {
                        let eplus = saved_run(cal, &anchor)?;
                        sampler.get()?.mapped_mode(&anchor.values, &eplus)?
                    }
                };
                let label = (&anchor.label[..], &anchor.values[..]);
                let step = MappingStep::new(label, mode, &fractions, first);
                record.truncate(steps.len());
                record.push(step.clone());
                mapping::write(&vdir, &record)?;
                let monthly = (fits[a].monthly).map_or(String::new(), |m| {
                    format!(" and {m:.2} of its monthly ones")
                });
                log(&format!(
                    "validation: EnergyPlus fits none of the {} points simulated by Guideline \
                     14's hourly and monthly criteria (the nearest, {}, at {:.2} of its hourly \
                     limits{monthly}): output space mapping step {} from it, EnergyPlus at {} \
                     of the way to the corrected surrogate's mode",
                    simulated.len(),
                    anchor.label,
                    fits[a].hourly,
                    steps.len() + 1,
                    (fractions.iter().map(|f| format!("{f:.3}")))
                        .collect::<Vec<_>>()
                        .join(" and ")
                ));
                step
            }
        };
        let runs: Vec<ValidationRun> = (step.points.iter())
            .filter(|p| {
                inp.plan.feasible(&inp.model, &p.values) && inp.plan.refused(&p.values).is_none()
            })
            .map(|p| ValidationRun {
                role: ValidationRole::Mapped,
                key: p.key,
                label: p.label.clone(),
                values: p.values.clone(),
            })
            .collect();
        let results = ready!(exec.validate(cal, &runs)?);
        for (run, r) in runs.into_iter().zip(results) {
            match r {
                Ok(m) => simulated.push((run, m)),
                Err(e) => log(&format!(
                    "validation: EnergyPlus failed at {}, left out: {e}",
                    run.label
                )),
            }
        }
        steps.push(step);
    }
    // Steps of an earlier, longer search (other settings) are not this one's.
    if record.len() > steps.len() {
        mapping::write(&vdir, &steps)?;
    }
    Ok(Ready::Done(steps))
}

/// `estimate = "best_simulated"`: of the points EnergyPlus `simulated` (the MAP draw first,
/// then the predictive draws and the `steps` of output space mapping), makes the one the rule
/// [`crate::metrics::best_simulated`] chooses by Guideline 14's criteria the estimate, its run
/// `validation/calibrated.csv`; its metrics, or `None`
/// when none ran (the fallbacks are tried then). `map_failure`: why EnergyPlus could not
/// simulate the MAP draw, if it could not.
fn adopt_best_simulated(
    cal: &Calibration,
    chains: &mut ChainSummary,
    sampler: &mut LazySampler<'_>,
    simulated: &[(ValidationRun, Vec<OutputMetrics>)],
    steps: Vec<MappingStep>,
    map_failure: Option<&String>,
    log: Log<'_>,
) -> Result<Option<Vec<OutputMetrics>>, Error> {
    let fits: Vec<crate::metrics::Fit> = (simulated.iter())
        .map(|(_, m)| crate::metrics::Fit::of(m, &cal.inputs.fitted))
        .collect();
    let map_ran = simulated
        .first()
        .is_some_and(|(r, _)| matches!(r.role, ValidationRole::Calibrated { .. }));
    let first_mapped = (simulated.iter())
        .position(|(r, _)| r.role == ValidationRole::Mapped)
        .unwrap_or(simulated.len());
    let Some(b) = crate::metrics::best_simulated(&fits, map_ran, first_mapped) else {
        return Ok(None);
    };
    let (run, metrics) = &simulated[b];
    let adopted = match run.role {
        ValidationRole::Predictive => {
            crate::keys::draw_of_key(run.key).and_then(|j| chains.predictive_point(j))
        }
        ValidationRole::Mapped => {
            let surrogate = sampler.get()?.surrogate_metrics(&run.values)?;
            Some((run.values.clone(), surrogate))
        }
        ValidationRole::Calibrated { .. } | ValidationRole::Initial => None,
    };
    let choice = crate::estimate::EstimateChoice {
        chosen: run.label.clone(),
        candidates: (simulated.iter().zip(&fits))
            .map(|((r, _), fit)| crate::estimate::SimulatedFit {
                label: r.label.clone(),
                limit_ratio: fit.hourly.is_finite().then_some(fit.hourly),
                monthly_limit_ratio: fit.monthly,
            })
            .collect(),
        outside_interval: match run.role {
            ValidationRole::Mapped => chains.outside_interval(&run.values),
            _ => vec![],
        },
        mapping: steps,
    };
    if adopted.is_some() {
        let o = saved_run(cal, run)?;
        let calibrated = cal.out.validation().join("calibrated.csv");
        crate::output::write_outputs_csv(&calibrated, cal.inputs.year, &o)?;
    }
    let map_failure = map_failure.map(String::as_str);
    log(&format!("validation: {}", choice.describe(map_failure)));
    chains.adopt_best_simulated(adopted, choice, map_failure);
    Ok(Some(metrics.clone()))
}

/// EnergyPlus's outputs of validation run `run`, as `validation/` saved them.
fn saved_run(cal: &Calibration, run: &ValidationRun) -> Result<HourlyOutputs, Error> {
    let vdir = cal.out.validation();
    saved_outputs(&vdir, run.key, &cal.inputs.plan.values(&run.values)).ok_or_else(|| {
        Error::Stage {
            stage: "validation",
            message: format!("the run of {} is not in {}", run.label, vdir.display()),
        }
    })
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

/// What a refinement round found: the surrogate against EnergyPlus at its draws, the chains
/// restarted in the best mode.
fn log_round(closed: &RefineRound, log: Log<'_>) {
    log(&format!(
        "refinement round {}: {} posterior draws simulated ({} failed); surrogate vs EnergyPlus there: {}",
        closed.round,
        closed.points.len(),
        closed.failed.len(),
        closed
            .surrogate_error
            .iter()
            .map(|m| format!(
                "{} NMBE {:.1} % CV-RMSE {:.1} %",
                m.output, m.metrics.nmbe, m.metrics.cv_rmse
            ))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    if closed.temperature != 1.0 {
        log(&format!(
            "refinement round {}: its chains ran at likelihood temperature {:.1}",
            closed.round, closed.temperature
        ));
    }
    for (c, gap) in &closed.restarted {
        log(&format!(
            "refinement round {}: chain {c} ended {gap:.0} nats below the best: restarts in its mode",
            closed.round
        ));
    }
}

/// What the final chains did: acceptance, HMC trajectories stopped, chains moved to the best
/// mode, independence steps switched off, R-hat and ESS.
fn log_chains(chains: &ChainSummary, ck: &Checkpoint, log: Log<'_>) {
    log(&format!(
        "chains: acceptance after burn-in {:.3?}",
        chains.acceptance
    ));
    let divergent: Vec<u64> = ck
        .states
        .iter()
        .map(bemcal_stats::chain::Chain::divergent_post_burn_in)
        .collect();
    if divergent.iter().any(|&n| n > 0) {
        log(&format!(
            "chains: HMC trajectories stopped after burn-in (divergent or against a constraint; \
             rejected) per chain: {divergent:?}"
        ));
    }
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
    let t = chains.temperature;
    if t.value != 1.0 {
        let from = match (t.measured_at_round, t.pooled_with_buildings) {
            (Some(r), None) => format!(
                "measured from the surrogate's error at refinement round {r}'s points, so that \
                 the intervals carry it"
            ),
            (Some(r), Some(n)) => format!(
                "measured from the surrogate's error at refinement round {r}'s points, pooled \
                 half and half with {n} buildings calibrated from the same pretrained network, \
                 so that the intervals carry it"
            ),
            (None, _) => "mcmc.temperature".into(),
        };
        log(&format!(
            "chains: likelihood temperature {:.1} ({from}): the chains sample p(theta) L(theta)^(1/T)",
            t.value
        ));
    }
    for c in &chains.discrepancy_carried {
        log(&format!("chains: {}", c.finding()));
    }
    log(&format!("posterior: {}", chains.convergence));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(settings: &str, temperature: f64) -> FinalChains {
        FinalChains {
            settings: settings.into(),
            temperature,
            target: 350,
            extensions: 1,
            summary: None,
        }
    }

    #[test]
    fn a_final_chains_record_holds_at_its_settings_and_temperature_and_reads_the_old_form() {
        let (now, legacy) = (
            "M after 2 refinement rounds, estimate BestSimulated",
            "M after 2 refinement rounds at temperature ",
        );
        let r = record(now, 294.3081622329743);
        assert!(r.holds_for(now, legacy, 294.30816227335754));
        assert!(!r.holds_for(now, legacy, 141.0));
        assert!(!r.holds_for(
            "M after 2 refinement rounds, estimate Median",
            legacy,
            294.3
        ));
        // Written before the temperature had its own field (serde's default, 1, in `temperature`).
        let old = record(
            "M after 2 refinement rounds at temperature 294.3081622329743",
            1.0,
        );
        assert!(old.holds_for(now, legacy, 294.30816227335754));
        assert!(!old.holds_for(now, legacy, 1.0));
        assert!(!old.holds_for(
            now,
            "M after 1 refinement rounds at temperature ",
            294.3081622329743
        ));
    }
}
