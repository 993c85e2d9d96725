//! What the surrogate-error recovery measures, against the truth it should stand for (issue 66):
//! on a finished calibration of synthetic meters, recovers the last refinement round's points
//! and the hidden truth (EnergyPlus's noise-free year there) through the final surrogate, with
//! the shipped BFGS budget and a larger one, and prints each parameter's shifts in prior
//! widths.
//!
//! `cargo run --release -p bemcal-calibrate --example recovery_check -- PROJECT OUT TRUTH.json
//! [ITERATIONS]` (a copy of the run folder: the truth's run is written under `simulations/` as
//! key 999).

use std::collections::BTreeMap;
use std::path::PathBuf;

use bemcal_calibrate::{refine::RefineLog, Calibration, Project};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let project = Project::load(&PathBuf::from(&args[1]))?;
    let out = PathBuf::from(&args[2]);
    let truth: BTreeMap<String, f64> = serde_json::from_str(&std::fs::read_to_string(&args[3])?)?;
    let more: usize = args.get(4).map_or(400, |s| s.parse().unwrap());
    let mut cal = Calibration::load(project, &out)?;
    let names = cal.inputs.plan.calibrated.clone();
    let widths: Vec<f64> = cal
        .inputs
        .plan
        .priors
        .iter()
        .map(|p| p.max() - p.min())
        .collect();
    let t: Vec<f64> = names.iter().map(|n| truth[n]).collect();
    let (truth_out, _) = cal.simulate_point(999, &t)?;
    let log: RefineLog = serde_json::from_str(&std::fs::read_to_string(out.join("refine.json"))?)?;
    let round = log.rounds.last().expect("a refinement round");
    let xs: Vec<Vec<f64>> = round.points.iter().map(|p| p.values.clone()).collect();
    let outs: Vec<_> = round
        .points
        .iter()
        .map(|p| cal.simulate_point(p.index, &p.values).map(|r| r.0))
        .collect::<Result<_, _>>()?;
    let report = |label: &str, cal: &Calibration| -> Result<(), Box<dyn std::error::Error>> {
        let mut s = cal.sampler()?;
        let started = std::time::Instant::now();
        let rec = s.recover(&xs, &outs)?;
        let rec_t = s.recover(std::slice::from_ref(&t), std::slice::from_ref(&truth_out))?;
        println!("== {label}: {:.1} s", started.elapsed().as_secs_f64());
        for (j, n) in names.iter().enumerate() {
            let rms = (rec
                .iter()
                .zip(&xs)
                .map(|(r, x)| ((r[j] - x[j]) / widths[j]).powi(2))
                .sum::<f64>()
                / xs.len() as f64)
                .sqrt();
            println!(
                "{n:34} rms_shift/w {rms:.4}  truth_shift/w {:+.4}",
                (rec_t[0][j] - t[j]) / widths[j]
            );
        }
        Ok(())
    };
    report("shipped optimiser budget", &cal)?;
    cal.project.mcmc.optimiser_iterations = more;
    report(&format!("{more} iterations"), &cal)?;
    Ok(())
}
