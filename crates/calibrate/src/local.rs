//! The local executor: the whole calibration on this machine, through the one driver
//! ([`crate::driver::drive`]). EnergyPlus runs in parallel here, the surrogate is trained
//! here, the chains run here checkpointed after every segment; every result is written under
//! the output folder and reused by a rerun, so an interrupted calibration continues where it
//! stopped.

use std::path::Path;
use std::time::Instant;

use bemcal_energyplus::confine::{limit_raised, Limits};
use bemcal_energyplus::errfile::failure_reason;
use rayon::prelude::*;

use crate::calibration::{Calibration, FittedData, Log};
use crate::chains::chains_at;
use crate::design::{read_failures, save_failures, simulate_wave, FAILURES_FILE};
use crate::driver::{drive, Executor, LazySampler, PointResult, Ready, ValidationResult};
use crate::error::Error;
use crate::output::read_record;
use crate::posterior::{run_chains, Checkpoint};
use crate::project::Project;
use crate::replacement::Attempt;
use crate::savings::SavingsPlan;
use crate::sequence::{Round, Stage, ValidationRun};
use crate::summary::{Summary, Timings};

/// Runs the whole calibration of `project` into `out` on this machine: each stage in the
/// order the data flows, every decision taken by the one driver.
pub fn calibrate(project: &Project, out: &Path, log: Log<'_>) -> Result<Summary, Error> {
    let mut exec = InProcess::new(log);
    let mut cal = Calibration::load(project.clone(), out)?;
    same_data_as_before(&cal, log)?;
    let inp = &cal.inputs;
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
    match drive(&mut cal, &mut exec, log)? {
        Ready::Done(summary) => Ok(summary),
        Ready::Pending => Err(Error::Config(
            "the local executor left work pending (a bug: it does all work at once)".into(),
        )),
    }
}

/// A rerun reuses the folder's chains and refinement rounds: refuses when they were fitted
/// to other data than this run's ([`Calibration::fitted_data`]: another held-out period, other
/// meters fitted, or other readings); the driver then records this run's in `holdout.txt`.
fn same_data_as_before(cal: &Calibration, log: Log<'_>) -> Result<(), Error> {
    let fitted = [
        cal.out.chains_checkpoint(),
        cal.out.join(crate::refine::REFINE_FILE),
    ]
    .iter()
    .any(|p| p.exists());
    if !fitted {
        return Ok(());
    }
    let text = std::fs::read_to_string(cal.out.holdout_txt()).unwrap_or_default();
    let before = FittedData::parse(&text, || summary_not_fitted(cal));
    let mut now = cal.fitted_data();
    // Written before the readings were fingerprinted: what it records is all that is compared.
    if before.readings.is_none() {
        now.readings = None;
        log(&format!(
            "{} predates the readings' fingerprint: the chains are reused without checking \
             that the meters are the ones they were fitted to",
            cal.out.holdout_txt().display()
        ));
    }
    if before == now {
        return Ok(());
    }
    let what = match before.describe() == now.describe() {
        true => format!(
            "other meter readings (fingerprint {}) than this run's (fingerprint {}): a meter \
             file, an `exclude` period or a base changed since, for instance",
            before.readings.unwrap_or_default(),
            now.readings.unwrap_or_default()
        ),
        false => format!(
            "other data ({}) than this run's ({})",
            before.describe(),
            now.describe()
        ),
    };
    Err(Error::Config(format!(
        "{} holds chains fitted to {what}. Use a new --out, or delete chains.json, \
         chains_summary.json, refine.json and refine/ there (simulations and the first \
         surrogate are kept)",
        cal.out.display(),
    )))
}

/// The meters the folder's `summary.json` says were not fitted (none without one).
fn summary_not_fitted(cal: &Calibration) -> Vec<String> {
    #[derive(serde::Deserialize)]
    struct NotFitted {
        #[serde(default)]
        not_fitted: Vec<String>,
    }
    (read_record::<NotFitted>(&cal.out.summary_json())
        .ok()
        .flatten())
    .map(|n| n.not_fitted)
    .unwrap_or_default()
}

/// The executor of `bemcal calibrate` without workers: all work in this process, at once.
struct InProcess<'l> {
    log: Log<'l>,
    started: Instant,
    timings: Timings,
    /// The stage entered last, and when.
    stage: Option<(Stage, Instant)>,
}

impl<'l> InProcess<'l> {
    fn new(log: Log<'l>) -> InProcess<'l> {
        InProcess {
            log,
            started: Instant::now(),
            timings: Timings::default(),
            stage: None,
        }
    }

    /// The thread pool of `design.parallel` EnergyPlus processes.
    fn pool(cal: &Calibration) -> Result<rayon::ThreadPool, Error> {
        rayon::ThreadPoolBuilder::new()
            .num_threads(cal.project.design.parallel.max(1))
            .build()
            .map_err(|e| Error::Config(format!("thread pool: {e}")))
    }
}

/// The bucket of [`Timings`] a stage's seconds go to (the coordinator's mapping too).
pub fn stage_seconds(t: &mut Timings, stage: Stage) -> Option<&mut f64> {
    match stage {
        Stage::Design => Some(&mut t.design_s),
        Stage::Simulate => Some(&mut t.simulations_s),
        Stage::Train => Some(&mut t.training_s),
        Stage::Chains => Some(&mut t.chains_s),
        Stage::Merge => Some(&mut t.summary_s),
        Stage::Refine => Some(&mut t.refinement_s),
        Stage::Validate => Some(&mut t.validation_s),
        Stage::Savings => Some(&mut t.savings_s),
        Stage::Summary | Stage::Done => None,
    }
}

/// The failures of an earlier run of the folder that still hold: one that stopped at a limit
/// the project has raised since (`[simulation]`; [`limit_raised`]) is left out, so that its
/// point is simulated again.
fn still_failed(known: Vec<Attempt>, limits: &Limits, log: Log<'_>) -> Vec<Attempt> {
    let (raised, kept): (Vec<Attempt>, Vec<Attempt>) = known
        .into_iter()
        .partition(|a| limit_raised(a.error.as_deref().unwrap_or_default(), limits));
    for a in &raised {
        log(&format!(
            "design point {}: failed in an earlier run at a lower limit ({}), simulated again",
            a.slot,
            failure_reason(a.error.as_deref().unwrap_or_default())
        ));
    }
    kept
}

impl Executor for InProcess<'_> {
    fn enter(&mut self, stage: Stage) -> Result<(), Error> {
        if let Some((s, t)) = self.stage.take() {
            if let Some(b) = stage_seconds(&mut self.timings, s) {
                *b += t.elapsed().as_secs_f64();
            }
        }
        self.stage = Some((stage, Instant::now()));
        Ok(())
    }

    /// Design points: a point that failed in an earlier run of the folder
    /// (`simulations/failures.json`) is not run again, and failures are added there.
    fn simulate(
        &mut self,
        cal: &Calibration,
        wave: &[(usize, Vec<f64>)],
        round: u32,
    ) -> Result<Ready<Vec<PointResult>>, Error> {
        let log = self.log;
        let dir = cal.simulations_dir();
        // A failed design point is remembered; a failed refinement draw is only left out.
        let known = match round {
            0 => still_failed(read_failures(&dir), cal.inputs.runner.limits(), log),
            _ => vec![],
        };
        let progress = |done: usize, n: usize| match round {
            0 => log(&format!("simulations: {done}/{n}")),
            r => log(&format!("refinement round {r}: {done}/{n} simulations")),
        };
        let inp = &cal.inputs;
        let ran = simulate_wave(
            (&inp.runner, &inp.model, &inp.plan),
            wave,
            &known,
            &inp.weather_path,
            &dir,
            cal.project.design.parallel,
            &progress,
            log,
        )?;
        if round == 0 {
            let attempts: Vec<Attempt> = wave
                .iter()
                .zip(&ran.results)
                .map(|((slot, values), r)| Attempt {
                    slot: *slot,
                    values: values.clone(),
                    error: r.as_ref().err().cloned(),
                })
                .collect();
            save_failures(&dir.join(FAILURES_FILE), &known, &attempts)?;
        }
        log(&format!(
            "{}simulations: {} run ({:.1} s each on average), {} reused, {} failed before and not repeated",
            match round {
                0 => String::new(),
                r => format!("refinement round {r}: "),
            },
            ran.seconds.len(),
            // (An empty f64 sum is -0.0: "0 run (-0.0 s each)" otherwise.)
            ran.seconds.iter().sum::<f64>().max(0.0) / ran.seconds.len().max(1) as f64,
            ran.reused,
            ran.not_repeated
        ));
        Ok(Ready::Done(ran.results))
    }

    fn savings(
        &mut self,
        cal: &Calibration,
        plan: &SavingsPlan,
    ) -> Result<Ready<Vec<PointResult>>, Error> {
        let parallel = cal.project.design.parallel;
        Ok(Ready::Done(crate::savings::simulate_all(
            cal, plan, parallel, self.log,
        )?))
    }

    fn train(
        &mut self,
        cal: &Calibration,
        _round: u32,
        init: Option<&Path>,
    ) -> Result<Ready<()>, Error> {
        cal.train(init)?;
        Ok(Ready::Done(()))
    }

    fn chains(
        &mut self,
        cal: &Calibration,
        round: Round,
        iterations: u64,
        starts: Option<&[Vec<f64>]>,
        sampler: &mut LazySampler<'_>,
    ) -> Result<Ready<Checkpoint>, Error> {
        let log = self.log;
        let sampler = sampler.get()?;
        let starts = match starts {
            Some(s) => s.to_vec(),
            None => sampler.starts(),
        };
        let config = sampler.config_for(round.index());
        let hmc_config = sampler.hmc_config_for(round.index());
        let settings = sampler.settings_for(round.index());
        let path = cal.chains_path(round.index());
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
        let label = round.label();
        let (post, eval) = sampler.split();
        let ck = run_chains(
            &post,
            eval,
            |post, eval| chains_at(post, eval, &starts, config, &hmc_config, &settings, 0),
            iterations,
            cal.project.mcmc.segment,
            &path,
            &|done, n| log(&format!("{label}: {done}/{n} iterations")),
        )?;
        Ok(Ready::Done(ck))
    }

    /// Every run in parallel (`design.parallel` EnergyPlus processes).
    fn validate(
        &mut self,
        cal: &Calibration,
        runs: &[ValidationRun],
    ) -> Result<Ready<Vec<ValidationResult>>, Error> {
        (self.log)(&format!(
            "validation: EnergyPlus at {}",
            runs.iter()
                .map(|r| r.label.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ));
        let results = Self::pool(cal)?.install(|| {
            runs.par_iter()
                .map(|r| {
                    cal.validate(r.key, &r.label, &r.values)
                        .map_err(|e| e.to_string())
                })
                .collect()
        });
        Ok(Ready::Done(results))
    }

    fn timings(&self) -> Timings {
        let mut t = self.timings.clone();
        if let Some((s, at)) = self.stage {
            if let Some(b) = stage_seconds(&mut t, s) {
                *b += at.elapsed().as_secs_f64();
            }
        }
        t.total_s = self.started.elapsed().as_secs_f64();
        t
    }
}
