//! `bemcal report DIR [--precal PDIR]`: writes `DIR/report.html`, a self-contained HTML report
//! of a calibration (and of its pre-calibration, if given); see the `bemcal-report` crate.

use std::path::PathBuf;

use anyhow::Context;

/// Arguments of `bemcal report`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Calibration output folder (`bemcal calibrate PROJECT --out DIR`).
    pub dir: PathBuf,
    /// Pre-calibration folder (`bemcal precalibrate --out PDIR`): adds the day-type and
    /// schedule figures.
    #[arg(long)]
    pub precal: Option<PathBuf>,
    /// Print the report's path as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Run `bemcal report`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let path = bemcal_report::write_report(&args.dir, args.precal.as_deref())
        .with_context(|| format!("writing the report of {}", args.dir.display()))?;
    if args.json {
        println!("{}", serde_json::json!({ "report": path }));
    } else {
        let kb = std::fs::metadata(&path).map_or(0, |m| m.len() / 1024);
        println!("{} ({kb} KiB)", path.display());
    }
    Ok(())
}
