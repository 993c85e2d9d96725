//! `bemcal report DIR [--precal PDIR] [--truth FILE]`: writes `DIR/report.html`, a
//! self-contained HTML report of a calibration (and of its pre-calibration, if given); with a
//! synthetic run's hidden truth it also prints the truth beside the posterior, each miss
//! explained. See the `bemcal-report` crate.

use std::path::PathBuf;

use anyhow::Context;
use bemcal_report::recovery::{percent, Recovery};

/// Arguments of `bemcal report`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Calibration output folder (`bemcal calibrate PROJECT --out DIR`).
    pub dir: PathBuf,
    /// Pre-calibration folder (`bemcal precalibrate --out PDIR`): adds the day-type and
    /// schedule figures.
    #[arg(long)]
    pub precal: Option<PathBuf>,
    /// A synthetic run's hidden true values (`bemcal synthesize --truth FILE`): the report and
    /// the terminal show each truth against its posterior 90 % interval, each miss explained.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Print the report's path (and the truth's counts) as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Run `bemcal report`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let written = bemcal_report::write_report_with_truth(
        &args.dir,
        args.precal.as_deref(),
        args.truth.as_deref(),
    )
    .with_context(|| format!("writing the report of {}", args.dir.display()))?;
    let path = &written.path;
    if args.json {
        let truth = written.recovery.as_ref().map(|r| {
            let (central_inside, central) = r.central();
            serde_json::json!({
                "parameters": r.rows.len(),
                "inside": r.inside(),
                "with_surrogate_error": r.with_surrogate_error(),
                "inside_own": r.inside_own(),
                "central": central,
                "central_inside": central_inside,
                "unexplained": r.unexplained(),
                "without_truth": r.without_truth,
            })
        });
        println!("{}", serde_json::json!({ "report": path, "truth": truth }));
    } else {
        if let Some(r) = &written.recovery {
            print_recovery(r);
        }
        let kb = std::fs::metadata(path).map_or(0, |m| m.len() / 1024);
        println!("{} ({kb} KiB)", path.display());
    }
    Ok(())
}

/// The truth beside the posterior: one line per parameter, the count, each miss's reasons.
fn print_recovery(r: &Recovery) {
    let carried = r.with_surrogate_error();
    println!(
        "\n{:30} {:>10} {:>10} {:>10} {:>10}  in 90 %{}",
        "parameter",
        "truth",
        "estimate",
        "q5",
        "q95",
        if carried {
            "   with surrogate error: q5, q95, in"
        } else {
            ""
        }
    );
    let yes = |inside: bool| if inside { "yes" } else { "no" };
    for row in &r.rows {
        let with_error = match (carried, row.with_surrogate_error) {
            (true, Some([lo, hi])) => {
                format!("   {lo:>10.4} {hi:>10.4}  {}", yes(row.miss.is_none()))
            }
            _ => String::new(),
        };
        println!(
            "{:30} {:>10.4} {:>10} {:>10.4} {:>10.4}  {:7}{with_error}",
            row.name,
            row.truth,
            row.estimate.map_or("-".into(), |e| format!("{e:.4}")),
            row.q5,
            row.q95,
            yes(row.inside_own)
        );
    }
    let (central_inside, central) = r.central();
    let (with, own) = if carried {
        (
            " with the surrogate's error",
            format!(
                "; {} of {} inside the chains' own",
                r.inside_own(),
                r.rows.len()
            ),
        )
    } else {
        ("", String::new())
    };
    println!(
        "\ntruth inside the 90 % interval{with} for {} of {} parameters ({central_inside} of \
         the {central} truths inside their prior's central 90 %{own})",
        r.inside(),
        r.rows.len()
    );
    for row in &r.rows {
        let Some(m) = &row.miss else { continue };
        println!(
            "  miss {}: outside {}, the truth at its prior's {} quantile, the chains' interval \
             {} of the prior's width; explained by: {}{}",
            row.name,
            m.distance(),
            row.prior_quantile.map_or("?".into(), percent),
            percent(row.width_ratio),
            m.describe(),
            if m.explained() {
                ""
            } else {
                " (NOT EXPLAINED)"
            }
        );
    }
    if !r.without_truth.is_empty() {
        println!(
            "  not counted, without a truth in the file: {}",
            r.without_truth.join(", ")
        );
    }
}
