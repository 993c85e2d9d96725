//! `bemcal crossval`: cross-validation by month on this machine.

use std::path::PathBuf;

use bemcal_calibrate::crossval::{cross_validate, CrossValidation, MONTHS};
use bemcal_calibrate::Project;
use bemcal_stats::metrics::G14Metrics;

/// Hold out each month in turn: the calibration on every month (OUT/all), then one fold per
/// month (OUT/fold_MM) reusing its design and first surrogate; Guideline 14 and predictive
/// coverage of every held-out hour in OUT/crossval.json.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Project file (TOML), without `[validation] holdout`.
    pub project: PathBuf,
    /// Output folder (reused: finished folds are not redone).
    #[arg(long)]
    pub out: PathBuf,
    /// The months to hold out, by name or number: `jan,apr,jul,oct` (default: all twelve).
    #[arg(long, value_delimiter = ',', value_parser = month)]
    pub months: Vec<u32>,
}

/// A month by name (`jan`) or number (1-12).
fn month(s: &str) -> Result<u32, String> {
    let t = s.trim().to_ascii_lowercase();
    if let Some(i) = MONTHS.iter().position(|m| t.starts_with(m)) {
        return Ok(i as u32 + 1);
    }
    match t.parse::<u32>() {
        Ok(m) if (1..=12).contains(&m) => Ok(m),
        _ => Err(format!("{s:?}: expected a month, jan..dec or 1..12")),
    }
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let project = Project::load(&a.project)?;
    let months: Vec<u32> = match a.months.is_empty() {
        true => (1..=12).collect(),
        false => a.months.clone(),
    };
    let t0 = std::time::Instant::now();
    let log = move |m: &str| eprintln!("[{:>7.1} s] {m}", t0.elapsed().as_secs_f64());
    let cv = cross_validate(&project, &a.out, &months, &log)?;
    print(&cv);
    println!(
        "\nwrote {}",
        a.out
            .join(bemcal_calibrate::crossval::CROSSVAL_FILE)
            .display()
    );
    Ok(())
}

/// `NMBE / CV-RMSE` with the verdict, or `-`.
fn g14(m: &Option<G14Metrics>) -> String {
    match m {
        Some(m) => format!(
            "{:>6.1} % / {:>5.1} % {}",
            m.nmbe,
            m.cv_rmse,
            if m.pass { "pass" } else { "FAIL" }
        ),
        None => "-".into(),
    }
}

/// The pooled figures per meter, then the folds.
fn print(cv: &CrossValidation) {
    let fold_s: Vec<f64> = cv.folds.iter().map(|f| f.seconds).collect();
    println!(
        "\ncross-validation by month: {} folds; the design ({} points) and the first surrogate \
         shared (their calibration {:.0} s), each fold {:.0} s on average",
        cv.folds.len(),
        cv.design_points,
        cv.shared_seconds,
        fold_s.iter().sum::<f64>() / fold_s.len().max(1) as f64
    );
    println!(
        "{:<30} {:<26} {:<26} {:<26} predictive coverage, held out (mean width)",
        "output", "in-sample hourly", "held out, hourly", "held-out months' totals"
    );
    for p in &cv.pooled {
        let cov: Vec<String> = p
            .coverage
            .iter()
            .map(|c| {
                format!(
                    "{:.0} %: {:5.1} % ({:.2} kWh)",
                    c.nominal * 100.0,
                    c.fraction * 100.0,
                    c.mean_width
                )
            })
            .collect();
        println!(
            "{:<30} {:<26} {:<26} {:<26} {}",
            if p.fitted {
                p.output.clone()
            } else {
                format!("{} (not fitted)", p.output)
            },
            g14(&p.in_sample),
            g14(&p.hourly),
            g14(&p.monthly),
            cov.join(", ")
        );
    }
    for p in cv
        .pooled
        .iter()
        .filter(|p| !p.months_without_figures.is_empty())
    {
        let names: Vec<&str> = p
            .months_without_figures
            .iter()
            .map(|m| MONTHS[*m as usize - 1])
            .collect();
        println!(
            "  {}: no Guideline 14 for {} (no measured hour, or a zero measured mean): the pooled \
             figures leave those months out",
            p.output,
            names.join(", ")
        );
    }
    println!("\nper fold (hourly, held-out month):");
    for f in &cv.folds {
        let name = MONTHS[f.month as usize - 1];
        if let Some(e) = &f.error {
            println!("  {name}: failed: {e}");
            continue;
        }
        let cells: Vec<String> = f
            .outputs
            .iter()
            .map(|o| format!("{} {}", o.output, g14(&o.held_out)))
            .collect();
        let conv = if f.converged { "" } else { " (not converged)" };
        println!("  {name}{conv}: {}", cells.join("; "));
    }
}
