//! `bemcal savings PROJECT --out DIR`: what retrofit measures save, with credible intervals
//! from the posterior of a finished calibration (issue 70). See
//! `bemcal_calibrate::savings`.

use std::path::PathBuf;

use anyhow::Context;
use bemcal_calibrate::measures::{Measure, SavingsReport};
use bemcal_calibrate::{Calibration, Project};

/// Arguments of `bemcal savings`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The calibration's project file (its `[[measures]]` are the measures, unless
    /// --measures names others).
    pub project: PathBuf,
    /// The finished calibration's output folder (`bemcal calibrate PROJECT --out DIR`); the
    /// savings' runs are cached under DIR/savings and the figures written into
    /// DIR/summary.json (`savings`).
    #[arg(long)]
    pub out: PathBuf,
    /// A TOML file of `[[measures]]` to estimate instead of the project's.
    #[arg(long)]
    pub measures: Option<PathBuf>,
    /// Posterior draws to simulate, evenly spaced over the chains (each costs two EnergyPlus
    /// runs per measure and weather, one of them shared by every measure).
    #[arg(long, default_value_t = 30)]
    pub draws: usize,
    /// Posterior draws the surrogate evaluates, corrected onto EnergyPlus's at --draws (the
    /// metered outputs of measures inside the surrogate's training range; 0, the default:
    /// EnergyPlus alone; the surrogate route is new and its coverage not yet measured).
    #[arg(long, default_value_t = 0)]
    pub surrogate_draws: usize,
    /// Two parameters the posterior ties together (the meters constrain a combination of
    /// them): `priors` draws each draw's split between them again from their priors along
    /// that combination, so that a saving resting on one carries that uncertainty; `chains`
    /// keeps the chains' split (which a surrogate's small errors can pin too tightly).
    #[arg(long, value_enum, default_value_t = SplitArg::Priors)]
    pub split: SplitArg,
    /// EnergyPlus processes at once (default: the project's `[design] parallel`).
    #[arg(long)]
    pub parallel: Option<usize>,
    /// Print the savings as JSON (summary.json's `savings`) instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// `--split`: how two parameters the posterior ties together are split at each draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SplitArg {
    /// Drawn again from their priors along the combination the meters constrain.
    Priors,
    /// The chains' draws as they are.
    Chains,
}

/// Run `bemcal savings`.
pub fn run(a: Args) -> anyhow::Result<()> {
    bemcal_calibrate::savings::check_draws(a.draws)
        .map_err(|e| anyhow::anyhow!("--draws {}: {e}", a.draws))?;
    let project = Project::load(&a.project)?;
    let measures = match &a.measures {
        Some(path) => read_measures(path)?,
        None => project.measures.clone(),
    };
    let parallel = a.parallel.unwrap_or(project.design.parallel);
    let t0 = std::time::Instant::now();
    let log = move |m: &str| eprintln!("[{:>7.1} s] {m}", t0.elapsed().as_secs_f64());
    let cal = Calibration::load(project, &a.out)?;
    let opts = bemcal_calibrate::savings::SavingsOptions {
        draws: a.draws,
        surrogate_draws: a.surrogate_draws,
        parallel,
        split: match a.split {
            SplitArg::Priors => bemcal_calibrate::savings::Split::Priors,
            SplitArg::Chains => bemcal_calibrate::savings::Split::Chains,
        },
    };
    let report = bemcal_calibrate::savings::estimate_savings(&cal, &measures, opts, &log)?;
    super::calibrate::write_report(&cal.project, &a.out);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&report);
        println!(
            "written: {} (savings)",
            a.out.join("summary.json").display()
        );
    }
    Ok(())
}

/// `[[measures]]` from a TOML file of their own.
fn read_measures(path: &std::path::Path) -> anyhow::Result<Vec<Measure>> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct File {
        measures: Vec<Measure>,
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let file: File = bemcal_energyplus::parse_toml(&text, path)?;
    for m in &file.measures {
        m.check()
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    }
    Ok(file.measures)
}

/// The savings as a table: a block per measure, a row per weather and output.
pub(super) fn print_table(r: &SavingsReport) {
    println!(
        "savings over {} posterior draws ({}):",
        r.draws, r.draws_file
    );
    for m in &r.measures {
        println!("\n{}: {}", m.measure, m.edits.join(", "));
        println!("  {}", m.method_note);
        for n in &m.notes {
            println!("  note: {n}");
        }
        println!(
            "  {:<18} {:<11} {:>12} {:>11} {:>23} {:>8} {:>11}  driven by",
            "output", "weather", "baseline kWh", "saves kWh", "90 % interval", "%", "at estimate"
        );
        for o in &m.outputs {
            let s = &o.savings_kwh;
            let driver = o.drivers.first().map_or("-".to_string(), |d| {
                format!("{} ({:.0} %)", d.parameter, 100.0 * d.share)
            });
            println!(
                "  {:<18} {:<11} {:>12.0} {:>11.0} {:>23} {:>7.1}% {:>11.0}  {driver}",
                o.output,
                o.weather.as_str(),
                o.baseline_kwh,
                s.median,
                format!("[{:.0}, {:.0}]", s.interval_90[0], s.interval_90[1]),
                o.savings_percent.median,
                o.at_estimate_kwh,
            );
            if let Some(w) = &o.warning {
                println!("  {:<18} warning: {w}", "");
            }
        }
        for d in (m.outputs.iter().flat_map(|o| &o.drivers))
            .filter(|d| d.width_ratio > 0.5)
            .map(|d| {
                format!(
                    "{} (90 % interval {:.2} of its prior): {}",
                    d.parameter, d.width_ratio, d.would_narrow
                )
            })
            .collect::<std::collections::BTreeSet<_>>()
        {
            println!("  would narrow it: {d}");
        }
        for f in m.failed.iter().take(5) {
            println!("  failed: {f}");
        }
        if m.failed.len() > 5 {
            println!("  ... {} more failed runs", m.failed.len() - 5);
        }
    }
    for n in &r.notes {
        println!("\nnote: {n}");
    }
}
