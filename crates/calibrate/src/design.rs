//! Design points: a Latin hypercube over the calibrated parameters' priors, and their
//! EnergyPlus simulations, run in parallel and resumable (a finished point is never rerun).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use bemcal_energyplus::{HourlyOutputs, Model, ParameterValues, Runner};
use bemcal_stats::lhs::{latin_hypercube, Design, LhsOptions, PairConstraint};
use bemcal_stats::prior::Triangular;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::Error;

/// Which parameters are calibrated and the values of the others.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Calibrated parameter names, in model order.
    pub calibrated: Vec<String>,
    /// Their priors.
    pub priors: Vec<Triangular>,
    pub units: Vec<String>,
    /// Values of every parameter that is not calibrated.
    pub fixed: ParameterValues,
    /// Priors restricted by a constraint with a fixed parameter, as messages for the log.
    pub restricted: Vec<String>,
}

impl Plan {
    /// Builds the plan: `calibrate` empty = all parameters; `fixed` values for the rest
    /// (others at their prior mode).
    pub fn new(
        model: &Model,
        calibrate: &[String],
        fixed: &ParameterValues,
    ) -> Result<Plan, Error> {
        let names: Vec<&str> = model.parameters().iter().map(|p| p.name.as_str()).collect();
        for n in calibrate.iter().chain(fixed.keys()) {
            if !names.contains(&n.as_str()) {
                return Err(Error::Config(format!(
                    "unknown parameter '{n}'; the model has: {}",
                    names.join(", ")
                )));
            }
        }
        if let Some(n) = calibrate.iter().find(|n| fixed.contains_key(*n)) {
            return Err(Error::Config(format!(
                "parameter '{n}' is both calibrated and fixed"
            )));
        }
        let mut plan = Plan {
            calibrated: vec![],
            priors: vec![],
            units: vec![],
            fixed: ParameterValues::new(),
            restricted: vec![],
        };
        for p in model.parameters() {
            let cal = if calibrate.is_empty() {
                !fixed.contains_key(&p.name)
            } else {
                calibrate.contains(&p.name)
            };
            if cal {
                let t = Triangular::new(p.prior.min, p.prior.mode, p.prior.max)
                    .map_err(|e| Error::Config(format!("prior of {}: {e}", p.name)))?;
                plan.calibrated.push(p.name.clone());
                plan.priors.push(t);
                plan.units.push(p.unit.clone());
            } else {
                let v = fixed.get(&p.name).copied().unwrap_or(p.prior.mode);
                plan.fixed.insert(p.name.clone(), v);
            }
        }
        if plan.calibrated.is_empty() {
            return Err(Error::Config("no parameter left to calibrate".into()));
        }
        plan.restrict_to_fixed(model)?;
        Ok(plan)
    }

    /// A constraint between a calibrated and a fixed parameter is a bound on the calibrated
    /// one: its prior is restricted to the feasible range (a triangular prior on
    /// [max(min, bound), max] or [min, min(max, bound)], mode clamped into it), so neither the
    /// design nor the chains propose values EnergyPlus would refuse.
    fn restrict_to_fixed(&mut self, model: &Model) -> Result<(), Error> {
        for c in model.constraints() {
            let lo_cal = self.calibrated.iter().position(|n| *n == c.lower);
            let hi_cal = self.calibrated.iter().position(|n| *n == c.upper);
            let (i, new_min, new_max) = match (lo_cal, hi_cal) {
                (Some(i), None) => {
                    let bound = self.fixed[&c.upper] - c.margin;
                    (i, self.priors[i].min(), self.priors[i].max().min(bound))
                }
                (None, Some(j)) => {
                    let bound = self.fixed[&c.lower] + c.margin;
                    (j, self.priors[j].min().max(bound), self.priors[j].max())
                }
                _ => continue,
            };
            let p = self.priors[i];
            if new_min == p.min() && new_max == p.max() {
                continue;
            }
            if new_min >= new_max {
                return Err(Error::Config(format!(
                    "{} cannot satisfy '{} + {} <= {}' with the fixed value: its prior [{}, {}] lies entirely outside; {}",
                    self.calibrated[i], c.lower, c.margin, c.upper, p.min(), p.max(), c.reason
                )));
            }
            let mode = p.mode().clamp(new_min, new_max);
            self.priors[i] = Triangular::new(new_min, mode, new_max).map_err(|e| {
                Error::Config(format!("restricted prior of {}: {e}", self.calibrated[i]))
            })?;
            self.restricted.push(format!(
                "prior of {} restricted to [{new_min}, {new_max}] (mode {mode}) by '{} + {} <= {}' with the fixed value",
                self.calibrated[i], c.lower, c.margin, c.upper
            ));
        }
        Ok(())
    }

    /// Full parameter values for a vector of calibrated values.
    pub fn values(&self, x: &[f64]) -> ParameterValues {
        let mut v = self.fixed.clone();
        for (n, x) in self.calibrated.iter().zip(x) {
            v.insert(n.clone(), *x);
        }
        v
    }

    /// The model's pairwise constraints between calibrated parameters, as LHS constraints.
    pub fn pair_constraints(&self, model: &Model) -> Vec<PairConstraint> {
        model
            .constraints()
            .iter()
            .filter_map(|c| {
                let i = self.calibrated.iter().position(|n| *n == c.lower)?;
                let j = self.calibrated.iter().position(|n| *n == c.upper)?;
                // lower + margin <= upper  <=>  x_i - x_j <= -margin
                Some(PairConstraint::new(i, j, -c.margin))
            })
            .collect()
    }

    /// True if the full parameter set satisfies every model constraint.
    pub fn feasible(&self, model: &Model, x: &[f64]) -> bool {
        let v = self.values(x);
        model.constraints().iter().all(|c| c.check(&v).is_ok())
    }
}

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
    crate::write_atomic(path, s.as_bytes())
}

/// Result of simulating a design.
#[derive(Debug)]
pub struct SimulatedDesign {
    pub outputs: Vec<HourlyOutputs>,
    /// Points taken from an earlier run of the same directory.
    pub reused: usize,
    /// EnergyPlus seconds per point simulated now.
    pub seconds: Vec<f64>,
}

#[allow(clippy::too_many_arguments)]
/// Simulates every design point with `parallel` EnergyPlus processes. Point `i` runs in
/// `dir/point_iii/`; its outputs are saved to `dir/point_iii.json` when it succeeds, and a later
/// call finds them there (so an interrupted design resumes where it stopped).
pub fn simulate_design(
    runner: &Runner,
    model: &Model,
    plan: &Plan,
    design: &Design,
    weather: &Path,
    dir: &Path,
    parallel: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SimulatedDesign, Error> {
    let indexed: Vec<(usize, Vec<f64>)> = design.points.iter().cloned().enumerate().collect();
    let results = simulate_points(
        runner, model, plan, &indexed, weather, dir, parallel, progress,
    )?;
    let mut out = SimulatedDesign {
        outputs: Vec::with_capacity(indexed.len()),
        reused: 0,
        seconds: vec![],
    };
    for (i, r) in results.into_iter().enumerate() {
        let (o, secs) = r.map_err(|e| Error::Stage {
            stage: "design",
            message: format!("design point {i}: {e}"),
        })?;
        match secs {
            Some(s) => out.seconds.push(s),
            None => out.reused += 1,
        }
        out.outputs.push(o);
    }
    Ok(out)
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
    let saved = dir.join(format!("point_{i:03}.json"));
    if let Ok(text) = std::fs::read_to_string(&saved) {
        if let Ok(o) = serde_json::from_str::<SavedRun>(&text) {
            if &o.values == values {
                return Ok((o.outputs, None));
            }
        }
    }
    let run_dir: PathBuf = dir.join(format!("point_{i:03}"));
    if run_dir.exists() {
        // An interrupted run: start it again from scratch.
        std::fs::remove_dir_all(&run_dir).map_err(|e| Error::io(&run_dir, e))?;
    }
    let idf = model.instantiate(values, runner.idd())?;
    let r = runner.run(&idf, weather, model.outputs(), &run_dir)?;
    let json = serde_json::to_vec(&SavedRun {
        values: values.clone(),
        outputs: r.outputs.clone(),
    })
    .map_err(|e| Error::Config(e.to_string()))?;
    crate::write_atomic(&saved, &json)?;
    let _ = std::fs::remove_dir_all(&run_dir);
    Ok((r.outputs, Some(r.seconds)))
}

#[derive(Serialize, Deserialize)]
struct SavedRun {
    values: ParameterValues,
    outputs: HourlyOutputs,
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
    }

    #[test]
    fn unknown_or_doubly_assigned_parameters_are_refused() {
        let model = Model::generated(BuildingSpec::default());
        let e = Plan::new(&model, &["lighting".into()], &Default::default()).unwrap_err();
        assert!(
            e.to_string().contains("unknown parameter 'lighting'"),
            "{e}"
        );
        let fixed: ParameterValues = [("shgc".to_string(), 0.4)].into();
        let e = Plan::new(&model, &["shgc".into()], &fixed).unwrap_err();
        assert!(e.to_string().contains("both calibrated and fixed"), "{e}");
    }
}
