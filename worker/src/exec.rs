//! Running one job with bemcal-calibrate, in the job's folder: the same stage methods as the
//! single-process pipeline, so the files written are the same.

use std::path::{Path, PathBuf};

use bemcal_calibrate::output::{OutputDir, DRAWS_FILE, STATES_FILE, WARM_FILE};
use bemcal_calibrate::posterior::ChainTemperature;
use bemcal_calibrate::savings::{parse_run, run_file, SavingsRunInputs};
use bemcal_calibrate::Calibration;
use bemcal_calibrate::Project;
use bemcal_client::artifacts::safe_relative;
use bemcal_client::client::walk;
use bemcal_client::proto::{self, job::Kind};
use bemcal_energyplus::params::ParameterValues;
use bemcal_stats::chain::Chain;

/// Output files (`relative path`, file) and the job's result.
pub type Outputs = (Vec<(String, PathBuf)>, proto::JobResult);

/// An error and its sources, `a: b: c`, as the CLI prints them (anyhow's `{:#}`; an I/O
/// error's reason is a source, not part of the message).
fn err<E: std::error::Error + Send + Sync + 'static>(e: E) -> String {
    format!("{:#}", anyhow::Error::new(e))
}

/// Runs `job` with the project at `project_file`, in `work`.
pub fn execute(job: &proto::Job, project_file: &Path, work: &Path) -> Result<Outputs, String> {
    let project = Project::load_submitted(project_file).map_err(err)?;
    let cal = Calibration::load(project, work).map_err(err)?;
    match &job.kind {
        Some(Kind::Simulate(s)) => simulate(&cal, s, work),
        Some(Kind::Train(t)) => train(&cal, t, work),
        Some(Kind::Chains(c)) => chains(&cal, c, work),
        Some(Kind::Validate(v)) => validate(&cal, v, work),
        Some(Kind::Measure(m)) => measure(&cal, m, work),
        None => Err("job without a kind (a newer coordinator?)".into()),
    }
}

/// A design point or refinement draw simulated by EnergyPlus.
fn simulate(cal: &Calibration, s: &proto::SimulateJob, work: &Path) -> Result<Outputs, String> {
    let i = s.point as usize;
    // An EnergyPlus failure is the job's result, not a failed job: the driver replaces
    // the design point (or leaves the refinement draw out) with the reason recorded.
    let secs = match cal.simulate_point(i, &s.values) {
        Ok((_, secs)) => secs,
        Err(e) => return Ok((vec![], proto::JobResult::energyplus_failed(e.to_string()))),
    };
    let rel = OutputDir::point_rel(i);
    Ok((
        vec![(rel.clone(), work.join(&rel))],
        proto::JobResult::simulated(secs),
    ))
}

/// The surrogate trained (warm-started from `init` when given); its folder's files.
fn train(cal: &Calibration, t: &proto::TrainJob, work: &Path) -> Result<Outputs, String> {
    let init = match t.init.as_str() {
        "" => None,
        rel => Some(work.join(safe_relative(rel)?)),
    };
    cal.train(init.as_deref()).map_err(err)?;
    let dir = cal.surrogate_dir();
    let mut files = vec![];
    for p in walk(&dir).map_err(err)? {
        let rel = p.strip_prefix(work).map_err(err)?;
        files.push((rel.to_string_lossy().replace('\\', "/"), p));
    }
    Ok((files, proto::JobResult::trained()))
}

/// A segment of chains advanced from their saved states (or new chains from the
/// coordinator's starts, or prior draws); their states and draws.
fn chains(cal: &Calibration, c: &proto::ChainSegmentJob, work: &Path) -> Result<Outputs, String> {
    let mut sampler = cal.sampler().map_err(err)?;
    sampler.set_temperature(ChainTemperature {
        value: c.likelihood_temperature()?,
        measured_at_round: None,
        pooled_with_buildings: None,
    });
    let states_path = work.join(STATES_FILE);
    let mut states: Vec<Chain> = if states_path.is_file() {
        let bytes = std::fs::read(&states_path).map_err(err)?;
        serde_json::from_slice(&bytes).map_err(|e| format!("states.json: {e}"))?
    } else {
        let (a, n) = (c.first_chain as usize, c.chains as usize);
        // A refinement round's chains start where the coordinator says (`warm.json`:
        // where the previous round's ended, or restarted); round 0 at prior draws.
        let warm_path = work.join(WARM_FILE);
        let mine: Vec<Vec<f64>> = if warm_path.is_file() {
            let bytes = std::fs::read(&warm_path).map_err(err)?;
            serde_json::from_slice(&bytes).map_err(|e| format!("warm.json: {e}"))?
        } else {
            let starts = sampler.starts();
            starts
                .get(a..a + n)
                .ok_or_else(|| format!("chains {a}..{} of {}", a + n, starts.len()))?
                .to_vec()
        };
        if mine.len() != n {
            return Err(format!("{} starting points for {n} chains", mine.len()));
        }
        sampler.new_chains(&mine, a as u64, c.round).map_err(err)?
    };
    let draws = sampler.advance(&mut states, c.iterations).map_err(err)?;
    let out_states = work.join("out").join(STATES_FILE);
    let out_draws = work.join("out").join(DRAWS_FILE);
    bemcal_calibrate::write_atomic(&out_states, &serde_json::to_vec(&states).map_err(err)?)
        .map_err(err)?;
    bemcal_calibrate::write_atomic(&out_draws, &serde_json::to_vec(&draws).map_err(err)?)
        .map_err(err)?;
    Ok((
        vec![
            (STATES_FILE.into(), out_states),
            (DRAWS_FILE.into(), out_draws),
        ],
        proto::JobResult::chains(states.first().map_or(0, |s| s.iteration())),
    ))
}

/// EnergyPlus at a validation point (the estimate, the initial model or a predictive draw);
/// a tolerated failure is the job's result.
fn validate(cal: &Calibration, v: &proto::ValidateJob, work: &Path) -> Result<Outputs, String> {
    if !v
        .label
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '_')
        || v.label.is_empty()
    {
        return Err(format!("bad validation label {:?}", v.label));
    }
    let i = v.index as usize;
    // The metrics computed here are the coordinator's to compute again from the files: what
    // a worker says about its own run is not taken on trust.
    match cal.validate(i, &v.label, &v.values) {
        Ok(_) => {}
        Err(e) if v.tolerate_failure => {
            return Ok((vec![], proto::JobResult::energyplus_failed(e.to_string())))
        }
        Err(e) => return Err(e.to_string()),
    }
    let a = OutputDir::validation_point_rel(i);
    let b = format!("validation/{}.csv", v.label);
    Ok((
        vec![(a.clone(), work.join(&a)), (b.clone(), work.join(&b))],
        proto::JobResult::validated(),
    ))
}

/// A savings run: EnergyPlus at a posterior draw (or the estimate) with a measure or without
/// one; an EnergyPlus failure is the job's result (the savings leave that draw out).
fn measure(cal: &Calibration, m: &proto::MeasureJob, work: &Path) -> Result<Outputs, String> {
    let (weather, measure) = parse_run(&m.weather, &m.measure_json)?;
    let values: ParameterValues =
        serde_json::from_str(&m.values_json).map_err(|e| format!("measure job's values: {e}"))?;
    let i = m.point as usize;
    // What the run needs is the job's to have (an error, retried, never cached); only the run
    // itself may fail as EnergyPlus's failure, which is cached with the job's inputs.
    let run = SavingsRunInputs::of(cal, weather, measure.as_ref()).map_err(err)?;
    let secs = match run.simulate(cal, i, &values) {
        Ok((_, secs)) => secs,
        Err(e) => return Ok((vec![], proto::JobResult::energyplus_failed(e.to_string()))),
    };
    let rel = run_file(weather, measure.as_ref(), i);
    Ok((
        vec![(rel.clone(), work.join(&rel))],
        proto::JobResult::simulated(secs),
    ))
}
