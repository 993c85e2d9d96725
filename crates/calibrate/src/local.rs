//! The local driver: the whole calibration on this machine, stage after stage. Every stage
//! writes its results under the output folder and reuses them on a rerun, so an interrupted
//! calibration continues where it stopped.

use std::path::Path;
use std::time::Instant;

use bemcal_stats::chain::Chain;

use crate::design::simulate_design;
use crate::posterior::run_chains;
use crate::project::Project;
use crate::refine::{close_round, SimulatedDraw};
use crate::replacement::Outcome;
use crate::Error;
use crate::{
    chains_at, extended_target, next_candidate, write_summary, Calibration, Log, Summary, Timings,
    ValidationStep, INITIAL_KEY,
};

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
    let (mut sampler, mut ck) = loop {
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
        drop(sampler);
        for (c, gap) in &closed.restarted {
            log(&format!(
                "refinement round {}: chain {c} ended {gap:.0} nats below the best: restarts in its mode",
                round + 1
            ));
        }
        timings.refinement_s += t.elapsed().as_secs_f64();
        outputs.extend(new_outputs);
        cal.record_round(&mut refined, closed)?;
    };
    let t = Instant::now();
    let mut chains = sampler.summarize(&ck.states, &ck.draws)?;
    timings.summary_s = t.elapsed().as_secs_f64();
    // Extend the final chains while R-hat is above its target (the rule: `extended_target`),
    // from their checkpoint, as the coordinator does.
    let m = &project.mcmc;
    let mut target = m.iterations;
    while let Some(next) = extended_target(m, chains.posterior.max_rhat, chains.extensions, target)
    {
        log(&format!(
            "chains: max R-hat {:.3} above the target {}: extending to {next} iterations \
             (extension {} of at most {})",
            chains.posterior.max_rhat,
            m.rhat_target.unwrap_or(f64::NAN),
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
        chains = sampler.summarize(&ck.states, &ck.draws)?;
        chains.extensions = extensions;
        timings.summary_s += t.elapsed().as_secs_f64();
        target = next;
    }
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
    log(&format!(
        "posterior: max R-hat {:.3}, min bulk ESS {:.0}",
        chains.posterior.max_rhat, chains.posterior.min_ess_bulk
    ));

    let t = Instant::now();
    log("validation: EnergyPlus at the calibrated parameters");
    // The estimate, then the next-best draws while EnergyPlus fails (`next_candidate`).
    let mut failures: Vec<String> = vec![];
    let validation = loop {
        let c = match next_candidate(&chains, &failures) {
            ValidationStep::Validate(c) => c,
            ValidationStep::Exhausted(message) => {
                return Err(Error::Stage {
                    stage: "validation",
                    message,
                })
            }
        };
        match cal.validate(c.key, "calibrated", &c.values) {
            Ok(m) => break m,
            Err(e) => {
                log(&format!(
                    "validation: EnergyPlus failed at candidate {}: {e}",
                    c.rank
                ));
                failures.push(e.to_string());
            }
        }
    };
    chains.settle_estimate(&failures);
    let initial = if project.validation.initial {
        log("validation: EnergyPlus at the initial parameters (prior modes)");
        cal.validate(INITIAL_KEY, "initial", &cal.initial_point())?
    } else {
        vec![]
    };
    timings.validation_s = t.elapsed().as_secs_f64();
    timings.total_s = t_all.elapsed().as_secs_f64();
    write_summary(&cal, &design, &chains, validation, initial, timings)
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
