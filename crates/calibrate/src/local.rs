//! The local driver: the whole calibration on this machine, stage after stage. Every stage
//! writes its results under the output folder and reuses them on a rerun, so an interrupted
//! calibration continues where it stopped.

use std::path::Path;
use std::time::Instant;

use bemcal_stats::chain::Chain;

use crate::design::simulate_design;
use crate::posterior::run_chains;
use crate::posterior::Checkpoint;
use crate::project::Project;
use crate::refine::{close_round, SimulatedDraw};
use crate::refine::{RefineLog, RefineRound};
use crate::replacement::Outcome;
use crate::sequence::{
    after_final_chains, next_validation, validation_runs, AfterFinalChains, Round, ValidationRole,
    ValidationRun,
};
use crate::{
    chains_at, write_summary, Calibration, ChainSummary, Error, Log, OutputMetrics, Sampler,
    Summary, Timings,
};
use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::lhs::Design;

/// Runs the whole calibration of `project` into `out` on this machine: each stage in the
/// order the data flows, every decision taken by the rules both drivers share.
pub fn calibrate(project: &Project, out: &Path, log: Log<'_>) -> Result<Summary, Error> {
    let t_all = Instant::now();
    let mut timings = Timings::default();
    let mut cal = Calibration::load(project.clone(), out)?;
    same_hours_as_before(&cal)?;
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
    let (design, mut outputs) = design_stage(&mut cal, log, &mut timings)?;
    let cal = cal;

    // Refinement points of rounds finished earlier (a rerun): their saved simulations.
    let mut refined = cal.refine_log()?;
    for p in refined.points() {
        outputs.push(cal.simulate_point(p.index, &p.values)?.0);
    }
    let (mut sampler, ck) = loop {
        let round = Round::after(project, refined.rounds.len() as u32);
        let mut sampler = surrogate_stage(&cal, &design, &refined, &outputs, log, &mut timings)?;
        let ck = round_chains(&cal, &mut sampler, round, &refined, log, &mut timings)?;
        if round.is_final() {
            break (sampler, ck);
        }
        let t = Instant::now();
        let (closed, new_outputs) = refine_round(&cal, sampler, &ck, &refined, log)?;
        timings.refinement_s += t.elapsed().as_secs_f64();
        outputs.extend(new_outputs);
        cal.record_round(&mut refined, closed)?;
    };
    let (mut chains, ck) = final_chains(&cal, &mut sampler, ck, &refined, log, &mut timings)?;
    log_chains(&chains, &ck, log);

    let t = Instant::now();
    let (validation, initial) = validate_stage(&cal, &mut chains, log)?;
    timings.validation_s = t.elapsed().as_secs_f64();
    timings.total_s = t_all.elapsed().as_secs_f64();
    write_summary(&cal, &design, &chains, validation, initial, timings)
}

/// A rerun reuses the folder's chains and refinement rounds: refuses when they were fitted
/// with another held-out period (they saw other hours), then records this run's in
/// `holdout.txt`.
fn same_hours_as_before(cal: &Calibration) -> Result<(), Error> {
    let now = match &cal.inputs.held_out {
        Some(h) => format!("{} ({} hours)", h.period, h.hour_count()),
        None => "none".into(),
    };
    let path = cal.out.holdout_txt();
    let before = std::fs::read_to_string(&path).unwrap_or_else(|_| "none".into());
    let fitted = [
        cal.out.chains_checkpoint(),
        cal.out.join(crate::refine::REFINE_FILE),
    ]
    .iter()
    .any(|p| p.exists());
    if fitted && before.trim() != now {
        return Err(Error::Config(format!(
            "{} holds chains fitted with holdout {}, and this run holds out {now}: they saw \
             other hours. Use a new --out, or delete chains.json, refine.json and refine/ there \
             (simulations and the first surrogate are kept)",
            cal.out.display(),
            before.trim()
        )));
    }
    crate::write_atomic(&path, now.as_bytes())
}

/// The design: the hypercube and its spares, EnergyPlus at the points with failed ones
/// replaced (`replacement::next_step` via `simulate_design`); the region EnergyPlus refused
/// is learnt. Returns the settled design and its simulated outputs.
fn design_stage(
    cal: &mut Calibration,
    log: Log<'_>,
    timings: &mut Timings,
) -> Result<(Design, Vec<HourlyOutputs>), Error> {
    let inp = &cal.inputs;
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
        cal.project.design.parallel,
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
    cal.learn_invalid_region(&sims.outcome);
    let invalid = cal.inputs.plan.invalid.balls.len();
    if invalid > 0 {
        log(&format!(
            "chains: proposals near the {invalid} design point(s) EnergyPlus could not simulate are \
             refused (summary.json design.invalid_region)"
        ));
    }
    Ok((design, sims.outputs))
}

/// The surrogate of the current round: the training set (the settled design, then every
/// finished round's draws), trained unless one is in place (warm-started after a round), and
/// bound to the likelihood.
fn surrogate_stage<'c>(
    cal: &'c Calibration,
    design: &Design,
    refined: &RefineLog,
    outputs: &[HourlyOutputs],
    log: Log<'_>,
    timings: &mut Timings,
) -> Result<Sampler<'c>, Error> {
    let full = cal.full_design(design, refined);
    let t = Instant::now();
    cal.training_set(design.points.len(), &full, outputs)?;
    if cal.has_surrogate() {
        log("surrogate: reusing the one trained earlier");
    } else {
        log(&format!(
            "training the surrogate (PyTorch) on {} points...",
            full.points.len()
        ));
        let init = cal.warm_start(refined);
        if let Some(dir) = &init {
            log(&format!("  warm start from {}", dir.display()));
        }
        cal.train(init.as_deref())?;
    }
    let sampler = cal.sampler()?;
    timings.training_s += t.elapsed().as_secs_f64();
    log(&format!(
        "surrogate: held-out RMSE (sigma_eta) {}",
        cal.inputs
            .outputs
            .iter()
            .zip(&sampler.sigma_eta)
            .map(|(n, s)| format!("{n} {s:.2} kWh"))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    Ok(sampler)
}

/// The chains of `round` (a preliminary round's `refine.iterations`, or the final
/// `mcmc.iterations`: [`Round::iterations`]), checkpointed after every segment and resumed from
/// their checkpoint.
fn round_chains(
    cal: &Calibration,
    sampler: &mut Sampler<'_>,
    round: Round,
    refined: &RefineLog,
    log: Log<'_>,
    timings: &mut Timings,
) -> Result<Checkpoint, Error> {
    let t = Instant::now();
    // Round 0 starts at dispersed prior draws; later rounds where the previous ended.
    // (A log from before starts were recorded gives prior draws again.)
    let starts = match refined.rounds.last() {
        Some(r) if !r.starts.is_empty() => r.starts.clone(),
        _ => sampler.starts(),
    };
    let config = sampler.config_for(round.index());
    let hmc_config = sampler.hmc_config_for(round.index());
    let settings = sampler.settings_for(round.index());
    let iterations = round.iterations(&cal.project);
    let path = cal.chains_path(round.index());
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let label = round.label();
    let ck = {
        let (post, eval) = sampler.split();
        run_chains(
            &post,
            eval,
            |post, eval| chains_at(post, eval, &starts, config, &hmc_config, &settings, 0),
            iterations,
            cal.project.mcmc.segment,
            &path,
            &|done, n| log(&format!("{label}: {done}/{n} iterations")),
        )?
    };
    timings.chains_s += t.elapsed().as_secs_f64();
    Ok(ck)
}

/// A refinement round after its chains: posterior draws picked (`refine::refinement_points`),
/// simulated by EnergyPlus, and the round closed by the shared rule (`refine::close_round`).
/// Returns the round and the new points' outputs; takes the round's sampler, so that it is
/// gone (and its surrogate folder free to move) when the round is recorded.
fn refine_round(
    cal: &Calibration,
    mut sampler: Sampler<'_>,
    ck: &Checkpoint,
    refined: &RefineLog,
    log: Log<'_>,
) -> Result<(RefineRound, Vec<HourlyOutputs>), Error> {
    let (project, inp) = (&cal.project, &cal.inputs);
    let round = refined.rounds.len() as u32;
    let post = sampler.posterior();
    let picks: Vec<Vec<f64>> = crate::refine::refinement_points(
        &ck.draws,
        project.refine.points,
        project.refine.spread,
        |u| post.ln_prior(u).is_finite(),
    )
    .iter()
    .map(|u| post.theta(u))
    .collect();
    let first = cal.next_refine_key(refined);
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
    let simulated = indexed
        .into_iter()
        .zip(results)
        .map(|((index, values), r)| SimulatedDraw {
            index,
            values,
            outputs: r.map(|(o, _)| o).map_err(|e| {
                log(&format!(
                    "refinement: posterior draw left out, EnergyPlus failed: {e}"
                ));
                e.to_string()
            }),
        })
        .collect();
    let last: Vec<Vec<f64>> = ck.states.iter().map(|s| s.position().to_vec()).collect();
    let (closed, new_outputs) = close_round(
        round + 1,
        simulated,
        &mut sampler,
        &ck.draws,
        &last,
        project.refine.restart_below,
    )?;
    log(&format!(
        "refinement round {}: {} posterior draws simulated ({} failed); surrogate vs EnergyPlus there: {}",
        round + 1,
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
    for (c, gap) in &closed.restarted {
        log(&format!(
            "refinement round {}: chain {c} ended {gap:.0} nats below the best: restarts in its mode",
            round + 1
        ));
    }
    Ok((closed, new_outputs))
}

/// The final chains summarised, and extended from their checkpoint while they miss a
/// convergence target (`mcmc.rhat_target`, `mcmc.ess_target`; the sequence's rule
/// [`after_final_chains`], as the coordinator does).
fn final_chains(
    cal: &Calibration,
    sampler: &mut Sampler<'_>,
    mut ck: Checkpoint,
    refined: &RefineLog,
    log: Log<'_>,
    timings: &mut Timings,
) -> Result<(ChainSummary, Checkpoint), Error> {
    let project = &cal.project;
    let rounds = project.refine.rounds;
    let t = Instant::now();
    let mut chains = sampler.summarize(&ck.states, &ck.draws, refined)?;
    timings.summary_s = t.elapsed().as_secs_f64();
    let m = &project.mcmc;
    let mut target = m.iterations;
    while let AfterFinalChains::Extend { iterations: next } = after_final_chains(m, &chains, target)
    {
        log(&format!(
            "chains: {}: extending to {next} iterations (extension {} of at most {})",
            chains.convergence,
            chains.extensions + 1,
            m.max_extensions
        ));
        let t = Instant::now();
        let (post, eval) = sampler.split();
        ck = run_chains(
            &post,
            eval,
            |_, _| unreachable!("the final chains' checkpoint exists"),
            next,
            m.segment,
            &cal.chains_path(rounds),
            &|done, n| log(&format!("chains: {done}/{n} iterations")),
        )?;
        timings.chains_s += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let extensions = chains.extensions + 1;
        chains = sampler.summarize(&ck.states, &ck.draws, refined)?;
        chains.extensions = extensions;
        timings.summary_s += t.elapsed().as_secs_f64();
        target = next;
    }
    Ok((chains, ck))
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
        .map(Chain::divergent_post_burn_in)
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
    log(&format!("posterior: {}", chains.convergence));
}

/// The validation runs of the sequence ([`validation_runs`]): EnergyPlus at the estimate, or
/// at the next-best draws while it fails there ([`next_validation`]; the estimate settled with
/// `settle_estimate`), at the initial model, and at the predictive draws (in parallel; a draw
/// EnergyPlus cannot simulate is left out, `crate::predictive::assess` counts it).
fn validate_stage(
    cal: &Calibration,
    chains: &mut ChainSummary,
    log: Log<'_>,
) -> Result<(Vec<OutputMetrics>, Vec<OutputMetrics>), Error> {
    let initial = cal.project.validation.initial.then(|| cal.initial_point());
    let runs = validation_runs(chains, initial);
    log("validation: EnergyPlus at the calibrated parameters");
    let mut failures: Vec<String> = vec![];
    let mut run = runs
        .iter()
        .find(|r| matches!(r.role, ValidationRole::Calibrated { .. }))
        .cloned();
    let validation = loop {
        let c = match run {
            Some(c) => c,
            None => match next_validation(chains, &failures) {
                Ok(c) => c,
                Err(message) => {
                    return Err(Error::Stage {
                        stage: "validation",
                        message,
                    })
                }
            },
        };
        match cal.validate(c.key, &c.label, &c.values) {
            Ok(m) => break m,
            Err(e) => {
                log(&format!(
                    "validation: EnergyPlus failed at candidate {}: {e}",
                    failures.len()
                ));
                failures.push(e.to_string());
                run = None;
            }
        }
    };
    chains.settle_estimate(&failures);
    let mut initial = vec![];
    if let Some(r) = runs.iter().find(|r| r.role == ValidationRole::Initial) {
        log("validation: EnergyPlus at the initial parameters (prior modes)");
        initial = cal.validate(r.key, &r.label, &r.values)?;
    }
    let predictive: Vec<&ValidationRun> = runs
        .iter()
        .filter(|r| r.role == ValidationRole::Predictive)
        .collect();
    predictive_stage(cal, &predictive, log)?;
    Ok((validation, initial))
}

/// EnergyPlus at the posterior draws of the predictive intervals, in parallel; a draw it
/// cannot simulate is left out (`crate::predictive::assess` counts it).
fn predictive_stage(cal: &Calibration, runs: &[&ValidationRun], log: Log<'_>) -> Result<(), Error> {
    use rayon::prelude::*;
    if runs.is_empty() {
        return Ok(());
    }
    log(&format!(
        "validation: EnergyPlus at {} posterior draws for the predictive intervals",
        runs.len()
    ));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(cal.project.design.parallel.max(1))
        .build()
        .map_err(|e| Error::Config(format!("thread pool: {e}")))?;
    let failed: Vec<String> = pool.install(|| {
        runs.par_iter()
            .filter_map(|r| cal.validate(r.key, &r.label, &r.values).err())
            .map(|e| e.to_string())
            .collect()
    });
    for e in failed {
        log(&format!(
            "validation: a predictive draw failed in EnergyPlus: {e}"
        ));
    }
    Ok(())
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
