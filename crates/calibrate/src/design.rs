//! Design points: a Latin hypercube over the calibrated parameters' priors, and their
//! EnergyPlus simulations, run in parallel and resumable (a finished point is never rerun).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use bemcal_energyplus::{HourlyOutputs, Model, ParameterValues, Runner};
use bemcal_stats::lhs::{latin_hypercube, Design, LhsOptions};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::output::read_record;
use crate::plan::Plan;
use crate::replacement::{self, Attempt, Outcome, Policy, Step};
use crate::stage::Stage;
use bemcal_energyplus::errfile::failure_reason;

/// Draws the design.
pub fn make_design(
    plan: &Plan,
    model: &Model,
    points: usize,
    seed: u64,
    maximin_iterations: usize,
) -> Result<Design, Error> {
    let opts = LhsOptions {
        maximin_iterations,
        constraints: plan.pair_constraints(model),
    };
    let d = latin_hypercube(&plan.priors, points, seed, &opts)?;
    if let Some(i) = d.points.iter().position(|x| !plan.feasible(model, x)) {
        return Err(Error::Config(format!(
            "design point {i} violates a constraint with a fixed parameter; widen or move the priors"
        )));
    }
    Ok(d)
}

/// Writes a design as CSV: `point,<parameter>...`.
pub fn write_design_csv(path: &Path, plan: &Plan, design: &Design) -> Result<(), Error> {
    let mut s = format!("point,{}\n", plan.calibrated.join(","));
    for (i, x) in design.points.iter().enumerate() {
        s.push_str(&i.to_string());
        for v in x {
            s.push_str(&format!(",{v}"));
        }
        s.push('\n');
    }
    crate::error::write_atomic(path, s.as_bytes())
}

/// A design simulated to its end (see [`crate::replacement`]).
#[derive(Debug)]
pub struct SimulatedDesign {
    /// The settled slots, their points and the failures on the way.
    pub outcome: Outcome,
    /// Outputs of each settled slot, in the order of `outcome.slots`.
    pub outputs: Vec<HourlyOutputs>,
    /// Points taken from an earlier run of the same directory.
    pub reused: usize,
    /// EnergyPlus seconds per point simulated now.
    pub seconds: Vec<f64>,
}

/// Failed attempts of a design, kept in its simulations folder so that a rerun neither repeats
/// them nor chooses different replacements.
pub const FAILURES_FILE: &str = "failures.json";

/// The settled design of a simulations folder ([`Outcome`]), written when the design is done.
pub const OUTCOME_FILE: &str = "design.json";

/// Simulates a design to its end: the hypercube's points, then spares for the points
/// EnergyPlus could not simulate, as [`replacement::next_step`] says, with `parallel`
/// EnergyPlus processes. Point `i` is saved as `dir/point_iii.json` when it succeeds; failures
/// go to `dir/failures.json`; a later call reuses both (an interrupted design resumes where it
/// stopped). Errors when too few points could be simulated, with the reasons grouped.
#[allow(clippy::too_many_arguments)]
pub fn simulate_design(
    runner: &Runner,
    model: &Model,
    plan: &Plan,
    (hypercube, spares): (&Design, &Design),
    policy: Policy,
    weather: &Path,
    dir: &Path,
    parallel: usize,
    log: &(dyn Fn(&str) + Sync),
) -> Result<SimulatedDesign, Error> {
    let failures_path = dir.join(FAILURES_FILE);
    let known = read_failures(dir);
    let mut progress = Progress::default();
    loop {
        let wave = match replacement::next_step(plan, hypercube, spares, policy, &progress.attempts)
        {
            Step::Simulate(wave) => wave,
            Step::Done(outcome) => {
                write_outcome(dir, &outcome)?;
                return Ok(progress.settle(outcome));
            }
            Step::Failed(message) => {
                return Err(Error::Stage {
                    stage: Stage::Design.as_str(),
                    message,
                })
            }
        };
        let replacing = !progress.attempts.is_empty();
        let ran = simulate_wave(
            (runner, model, plan),
            &wave,
            &known,
            weather,
            dir,
            parallel,
            &|done, n| {
                if replacing {
                    log(&format!("simulations (replacements): {done}/{n}"))
                } else {
                    log(&format!("simulations: {done}/{n}"))
                }
            },
            log,
        )?;
        progress.record(&wave, ran);
        save_failures(&failures_path, &known, &progress.attempts)?;
    }
}

/// A design's attempts so far, and the outputs of the points that simulated.
#[derive(Default)]
struct Progress {
    attempts: Vec<Attempt>,
    outputs: std::collections::BTreeMap<usize, HourlyOutputs>,
    reused: usize,
    seconds: Vec<f64>,
}

impl Progress {
    /// Records a simulated wave, its results in the wave's order.
    fn record(&mut self, wave: &[(usize, Vec<f64>)], ran: WaveRun) {
        self.seconds.extend(ran.seconds);
        self.reused += ran.reused;
        for ((slot, values), r) in wave.iter().zip(ran.results) {
            let error = match r {
                Ok(o) => {
                    self.outputs.insert(*slot, o);
                    None
                }
                Err(e) => Some(e),
            };
            self.attempts.push(Attempt {
                slot: *slot,
                values: values.clone(),
                error,
            });
        }
    }

    /// The settled design: each settled slot's outputs in the outcome's order.
    fn settle(mut self, outcome: Outcome) -> SimulatedDesign {
        let outputs = outcome
            .slots
            .iter()
            .map(|s| self.outputs.remove(s).expect("a settled slot has outputs"))
            .collect();
        SimulatedDesign {
            outcome,
            outputs,
            reused: self.reused,
            seconds: self.seconds,
        }
    }
}

/// A wave of points simulated ([`simulate_wave`]).
pub(crate) struct WaveRun {
    /// Per point, in the wave's order: its outputs, or EnergyPlus's failure (now or in an
    /// earlier run of the folder).
    pub results: Vec<Result<HourlyOutputs, String>>,
    /// EnergyPlus seconds per point simulated now.
    pub seconds: Vec<f64>,
    /// Points reloaded from an earlier run of the folder.
    pub reused: usize,
    /// Points that failed in an earlier run of the folder and were not run again.
    pub not_repeated: usize,
}

/// Simulates (or reloads) the points `(key, values)` of `wave` in `dir`, with `parallel`
/// EnergyPlus processes, except those that failed in an earlier run of the folder (`known`,
/// from `failures.json`): they keep that failure and are not run again. The one wave step of
/// [`simulate_design`] and of the calibration's in-process executor.
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate_wave(
    (runner, model, plan): (&Runner, &Model, &Plan),
    wave: &[(usize, Vec<f64>)],
    known: &[Attempt],
    weather: &Path,
    dir: &Path,
    parallel: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
    log: &(dyn Fn(&str) + Sync),
) -> Result<WaveRun, Error> {
    let to_run: Vec<(usize, Vec<f64>)> = wave
        .iter()
        .filter(|p| failed_before(known, p).is_none())
        .cloned()
        .collect();
    let mut ran = simulate_points(
        runner, model, plan, &to_run, weather, dir, parallel, progress,
    )?
    .into_iter();
    let mut run = WaveRun {
        results: vec![],
        seconds: vec![],
        reused: 0,
        not_repeated: wave.len() - to_run.len(),
    };
    for p in wave {
        let r = match failed_before(known, p) {
            Some(a) => {
                let e = a.error.clone().unwrap_or_default();
                log(&format!(
                    "design point {}: failed in an earlier run ({}), not repeated",
                    p.0,
                    failure_reason(&e)
                ));
                Err(e)
            }
            None => match ran.next().expect("one result per point run") {
                Ok((o, secs)) => {
                    match secs {
                        Some(s) => run.seconds.push(s),
                        None => run.reused += 1,
                    }
                    Ok(o)
                }
                Err(e) => {
                    let e = e.to_string();
                    log(&format!(
                        "point {}: EnergyPlus failed ({})",
                        p.0,
                        failure_reason(&e)
                    ));
                    Err(e)
                }
            },
        };
        run.results.push(r);
    }
    Ok(run)
}

/// The failed attempts of earlier runs of simulations folder `dir` (`failures.json`).
pub(crate) fn read_failures(dir: &Path) -> Vec<Attempt> {
    (read_record(&dir.join(FAILURES_FILE)).ok().flatten()).unwrap_or_default()
}

/// The failed attempt at this slot and point in an earlier run of the folder, if any.
fn failed_before<'a>(known: &'a [Attempt], (s, x): &(usize, Vec<f64>)) -> Option<&'a Attempt> {
    known
        .iter()
        .find(|a| a.slot == *s && &a.values == x && a.error.is_some())
}

/// Writes every failed attempt, earlier runs' first, to the folder's failures file (when
/// there is any).
pub(crate) fn save_failures(
    path: &Path,
    known: &[Attempt],
    attempts: &[Attempt],
) -> Result<(), Error> {
    let mut failures: Vec<Attempt> = known.to_vec();
    for a in attempts.iter().filter(|a| a.error.is_some()) {
        if !failures.contains(a) {
            failures.push(a.clone());
        }
    }
    if !failures.is_empty() {
        let json =
            serde_json::to_vec_pretty(&failures).map_err(|e| Error::Config(e.to_string()))?;
        crate::error::write_atomic(path, &json)?;
    }
    Ok(())
}

/// The settled design of simulations folder `dir` (written by [`simulate_design`] or a
/// coordinator when the design was done), if any.
pub fn read_outcome(dir: &Path) -> Option<Outcome> {
    read_record(&dir.join(OUTCOME_FILE)).ok().flatten()
}

/// Writes the settled design of simulations folder `dir` (`design.json`).
pub fn write_outcome(dir: &Path, outcome: &Outcome) -> Result<(), Error> {
    let json = serde_json::to_vec_pretty(outcome).map_err(|e| Error::Config(e.to_string()))?;
    crate::error::write_atomic(&dir.join(OUTCOME_FILE), &json)
}

/// Severe messages EnergyPlus wrote in the saved run of point `i` that left its results usable
/// (see `bemcal_energyplus::errfile`), for the summary.
pub fn point_notes(dir: &Path, i: usize) -> Vec<String> {
    std::fs::read_to_string(dir.join(crate::output::point_file(i)))
        .ok()
        .and_then(|t| serde_json::from_str::<SavedRun>(&t).ok())
        .map(|r| r.notes)
        .unwrap_or_default()
}

/// One point's simulation: its hourly outputs and the EnergyPlus wall time (`None`: reloaded).
pub type PointRun = Result<(HourlyOutputs, Option<f64>), Error>;

/// Simulates (or reloads) the points `(i, x)`, under the keys `i` in `dir`, with `parallel`
/// EnergyPlus processes; one result per point, in order (a failed run does not stop the others).
#[allow(clippy::too_many_arguments)]
pub fn simulate_points(
    runner: &Runner,
    model: &Model,
    plan: &Plan,
    points: &[(usize, Vec<f64>)],
    weather: &Path,
    dir: &Path,
    parallel: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<PointRun>, Error> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(parallel)
        .build()
        .map_err(|e| Error::Config(format!("thread pool: {e}")))?;
    let done = AtomicUsize::new(0);
    let n = points.len();
    Ok(pool.install(|| {
        points
            .par_iter()
            .map(|(i, x)| {
                let r = simulate_point(runner, model, &plan.values(x), weather, dir, *i);
                progress(done.fetch_add(1, Ordering::SeqCst) + 1, n);
                r
            })
            .collect()
    }))
}

/// Runs (or reloads) one parameter set in `dir`, under the key `i`.
pub fn simulate_point(
    runner: &Runner,
    model: &Model,
    values: &ParameterValues,
    weather: &Path,
    dir: &Path,
    i: usize,
) -> PointRun {
    let saved = dir.join(crate::output::point_file(i));
    if let Ok(text) = std::fs::read_to_string(&saved) {
        if let Ok(o) = serde_json::from_str::<SavedRun>(&text) {
            if &o.values == values {
                return Ok((o.outputs, None));
            }
        }
    }
    let run_dir: PathBuf = saved.with_extension("");
    if run_dir.exists() {
        // An interrupted run: start it again from scratch.
        std::fs::remove_dir_all(&run_dir).map_err(|e| Error::io(&run_dir, e))?;
    }
    let idf = model.instantiate(values, runner.idd())?;
    let r = runner.run(&idf, weather, model.outputs(), &run_dir)?;
    let json = serde_json::to_vec(&SavedRun {
        values: values.clone(),
        outputs: r.outputs.clone(),
        notes: r.notes.clone(),
    })
    .map_err(|e| Error::Config(e.to_string()))?;
    crate::error::write_atomic(&saved, &json)?;
    let _ = std::fs::remove_dir_all(&run_dir);
    Ok((r.outputs, Some(r.seconds)))
}

/// Checks a simulated point's file (`simulations/point_NNN.json`) as a worker uploads it,
/// before a coordinator records or shares it: it parses, has one series per named output,
/// every series a year of hours (the 8,760 slots EnergyPlus simulates), every value finite and
/// plausible (an hour's kWh of a meter, non-negative and below 1e9). Whether it answers the
/// job's parameter values is checked when the driver reads it back.
pub fn check_point_file(bytes: &[u8]) -> Result<(), String> {
    let run: SavedRun =
        serde_json::from_slice(bytes).map_err(|e| format!("not a simulated point's file: {e}"))?;
    let o = &run.outputs;
    if o.names.is_empty() || o.names.len() != o.series.len() {
        return Err(format!(
            "{} output names for {} series",
            o.names.len(),
            o.series.len()
        ));
    }
    let hours = bemcal_weather::HOURS_PER_YEAR;
    if o.hours() != hours {
        return Err(format!("{} hours simulated, not {hours}", o.hours()));
    }
    for (name, s) in o.names.iter().zip(&o.series) {
        if s.len() != hours {
            return Err(format!("output {name:?}: {} hours, not {hours}", s.len()));
        }
        if let Some(t) = s.iter().position(|v| !v.is_finite()) {
            return Err(format!("output {name:?}: hour {t} is not a finite number"));
        }
        if let Some(t) = s.iter().position(|v| !(-1e-6..1e9).contains(v)) {
            return Err(format!(
                "output {name:?}: hour {t} holds {} kWh, outside [0, 1e9)",
                s[t]
            ));
        }
    }
    if let Some(v) = run.values.values().find(|v| !v.is_finite()) {
        return Err(format!("a parameter value is not finite ({v})"));
    }
    Ok(())
}

/// The outputs saved under key `i` in `dir` if they were simulated at `values`.
pub fn saved_outputs(dir: &Path, i: usize, values: &ParameterValues) -> Option<HourlyOutputs> {
    let text = std::fs::read_to_string(dir.join(crate::output::point_file(i))).ok()?;
    let run: SavedRun = serde_json::from_str(&text).ok()?;
    (&run.values == values).then_some(run.outputs)
}

#[derive(Serialize, Deserialize)]
struct SavedRun {
    values: ParameterValues,
    outputs: HourlyOutputs,
    /// Usable Severe messages of the run (`RunResult::notes`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    notes: Vec<String>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use bemcal_energyplus::BuildingSpec;

    #[test]
    fn constraint_with_a_fixed_parameter_restricts_the_prior() {
        let model = Model::generated(BuildingSpec::default());
        // Heating set-point fixed at its mode (21 C): cooling may not go below it.
        let plan = Plan::new(
            &model,
            &["cooling_setpoint_occupied".into()],
            &Default::default(),
        )
        .unwrap();
        let p = plan.priors[0];
        assert_eq!((p.min(), p.mode(), p.max()), (21.0, 24.0, 26.0));
        assert_eq!(plan.restricted.len(), 1, "{:?}", plan.restricted);
        let d = make_design(&plan, &model, 30, 3, 0).unwrap();
        assert!(d.points.iter().all(|x| x[0] >= 21.0));

        // Supply air calibrated, chilled water fixed at 6 C: supply air >= 9 C (prior 10-18 is
        // already feasible, nothing changes).
        let plan = Plan::new(&model, &["supply_air_temp".into()], &Default::default()).unwrap();
        assert!(plan.restricted.is_empty());

        // No feasible value at all is an error that says why.
        let fixed: ParameterValues = [("heating_setpoint_occupied".to_string(), 27.0)].into();
        let e = Plan::new(&model, &["cooling_setpoint_occupied".into()], &fixed).unwrap_err();
        assert!(e.to_string().contains("lies entirely outside"), "{e}");

        // Two values that are not calibrated (one fixed, one at its prior mode, 21 C) that break
        // a constraint are refused before any design point.
        let fixed: ParameterValues = [("cooling_setpoint_occupied".to_string(), 20.0)].into();
        let e = Plan::new(&model, &["shgc".into()], &fixed).unwrap_err();
        assert_eq!(
            e.to_string(),
            "parameter heating_setpoint_occupied / cooling_setpoint_occupied: \
             heating_setpoint_occupied = 21 and cooling_setpoint_occupied = 20 violate \
             heating_setpoint_occupied + 0 <= cooling_setpoint_occupied: a heating set-point \
             above the cooling set-point is fatal in EnergyPlus (DualSetPointWithDeadband) \
             (a parameter not calibrated is at its [fixed] value, else at its prior's mode)"
        );
    }
}
