//! `bemcal design`: a Latin hypercube over a model's priors, optionally simulated.

use std::path::PathBuf;

use bemcal_calibrate::design::{make_design, simulate_design, write_design_csv};
use bemcal_calibrate::plan::Plan;

use super::common;

/// Draw design points (Latin hypercube over the priors, constraints repaired) and optionally
/// simulate them with EnergyPlus.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file: a building spec (TOML) or an `[idf]` parameter map.
    #[arg(long)]
    pub model: PathBuf,
    /// Number of design points.
    #[arg(long, default_value_t = 20)]
    pub points: usize,
    /// Seed of the Latin hypercube.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Maximin column-swap iterations.
    #[arg(long, default_value_t = 1000)]
    pub maximin: usize,
    /// Parameters to vary (comma-separated); default all.
    #[arg(long, value_delimiter = ',')]
    pub params: Vec<String>,
    /// Design CSV: point,<parameter>...
    #[arg(long)]
    pub out: PathBuf,
    /// Simulate every point with this weather file (outputs under --runs), a path or
    /// `bundled:FILE` from EnergyPlus's WeatherData folder.
    #[arg(long)]
    pub weather: Option<String>,
    /// Folder for the simulations (default: next to --out).
    #[arg(long)]
    pub runs: Option<PathBuf>,
    /// EnergyPlus runs at once.
    #[arg(long, default_value_t = 2)]
    pub parallel: usize,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (model, runner) = common::load_model(&a.model)?;
    let plan = Plan::new(&model, &a.params, &Default::default())?;
    let design = make_design(&plan, &model, a.points, a.seed, a.maximin)?;
    write_design_csv(&a.out, &plan, &design)?;
    let r = &design.repair;
    println!(
        "{} points x {} parameters -> {} (min distance {:.3}; maximin swaps {}; constraint repair: {} rows infeasible, {} swaps, {} resampled in stratum, {} outside)",
        design.points.len(),
        plan.calibrated.len(),
        a.out.display(),
        design.min_distance,
        design.maximin_swaps,
        r.rows_infeasible_before,
        r.swaps,
        r.resampled_in_stratum,
        r.resampled_outside_stratum
    );
    if let Some(w) = &a.weather {
        let w = &common::resolve_weather_ref(w)?;
        let runs = a
            .runs
            .clone()
            .unwrap_or_else(|| a.out.with_extension("runs"));
        let t0 = std::time::Instant::now();
        // Points EnergyPlus cannot simulate are replaced as in a calibration, with the
        // project defaults (`[design] replacements`, `min_success`).
        let defaults = bemcal_calibrate::project::DesignSettings::default();
        let spares = make_design(
            &plan,
            &model,
            a.points,
            bemcal_calibrate::replacement::spare_seed(a.seed),
            a.maximin,
        )?;
        let policy = bemcal_calibrate::replacement::Policy {
            replacements: defaults.replacements,
            min_success: defaults.min_success,
        };
        let sims = simulate_design(
            &runner,
            &model,
            &plan,
            (&design, &spares),
            policy,
            w,
            &runs,
            a.parallel,
            &|m: &str| eprintln!("{m}"),
        )?;
        bemcal_calibrate::log_design_outcome(&sims.outcome, &|m: &str| eprintln!("{m}"));
        for &slot in &sims.outcome.slots {
            for note in bemcal_calibrate::design::point_notes(&runs, slot) {
                eprintln!("design point {slot}: used despite: {note}");
            }
        }
        let wall = t0.elapsed().as_secs_f64();
        println!(
            "simulated {} points ({} reused) in {:.1} s wall, {:.1} s EnergyPlus per point, {:.0} points/hour; outputs in {}",
            sims.outputs.len(),
            sims.reused,
            wall,
            sims.seconds.iter().sum::<f64>() / sims.seconds.len().max(1) as f64,
            sims.seconds.len() as f64 / wall * 3600.0,
            runs.display()
        );
    }
    Ok(())
}
