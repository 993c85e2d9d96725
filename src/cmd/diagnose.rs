//! `bemcal diagnose`: convergence diagnostics of MCMC draws (rank-normalised split R-hat, bulk
//! and tail ESS as ArviZ computes them) and summary statistics per parameter.
//!
//! DRAWS.csv has columns `chain,draw,<parameter>...`, read by the one reader of draws files
//! ([`bemcal_report::io::read_draws`]): chains numbered from 0 and equally long, each draw number
//! once (rows in any order), every value a finite number. Columns ending in `__` (the sampler's
//! statistics, as CmdStan names them) are skipped.

use std::path::PathBuf;

use anyhow::{bail, Context};
use bemcal_report::io::Draws;
use bemcal_stats::diagnostics::{self, ParameterDiagnostics};

/// Arguments of `bemcal diagnose`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Draws CSV with columns `chain,draw,<parameter>...` (chains numbered from 0, equally long;
    /// finite values).
    #[arg(long)]
    pub draws: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(serde::Serialize)]
struct Row<'a> {
    parameter: &'a str,
    #[serde(flatten)]
    d: ParameterDiagnostics,
}

/// Run `bemcal diagnose`.
pub fn run(args: Args) -> anyhow::Result<()> {
    // One reader of draws files for diagnose, simulate --draw and the report: strict about
    // missing and infinite draws, chain numbering and equal lengths.
    let draws = bemcal_report::io::read_draws(&args.draws)?;
    if let Some(note) = draws.numbering.note() {
        eprintln!("note: {}: {note}", args.draws.display());
    }
    let len = draws.len();
    let mut rows = Vec::new();
    for (k, name) in draws.columns.iter().enumerate() {
        // Columns ending in `__` are the sampler's statistics per draw (CmdStan's convention:
        // accept_stat__, stepsize__, ...), not quantities to diagnose.
        if Draws::is_sampler_statistic(name) {
            continue;
        }
        let per_chain: Vec<Vec<f64>> = draws.chains.iter().map(|c| c[k].clone()).collect();
        let d = diagnostics::diagnose(&per_chain).with_context(|| format!("parameter `{name}`"))?;
        rows.push(Row { parameter: name, d });
    }
    if rows.is_empty() {
        bail!(
            "{}: no parameter columns besides chain, draw and the sampler's statistics",
            args.draws.display()
        );
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        println!("{} chains x {len} draws", draws.chains.len());
        println!(
            "{:<28} {:>12} {:>12} {:>12} {:>12} {:>12} {:>7} {:>9} {:>9}",
            "parameter", "mean", "sd", "q5", "q50", "q95", "rhat", "ess_bulk", "ess_tail"
        );
        for r in &rows {
            let d = &r.d;
            println!(
                "{:<28} {:>12.6} {:>12.6} {:>12.6} {:>12.6} {:>12.6} {:>7.4} {:>9.1} {:>9.1}",
                r.parameter, d.mean, d.sd, d.q5, d.q50, d.q95, d.rhat, d.ess_bulk, d.ess_tail
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `run` on draws.csv text; the error with the temporary folder written as `DIR`.
    fn diagnose(text: &str) -> Result<(), String> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("draws.csv");
        std::fs::write(&p, text).unwrap();
        run(Args {
            draws: p,
            json: true,
        })
        .map_err(|e| {
            e.to_string()
                .replace(&dir.path().display().to_string(), "DIR")
        })
    }

    #[test]
    fn non_finite_draws_are_refused_naming_line_and_column() {
        let mut lines = vec!["chain,draw,shgc,lighting_power_density".to_string()];
        for c in 0..2 {
            for d in 0..50 {
                let shgc = 0.5 + 0.001 * ((d * 7 + c * 3) % 11) as f64;
                let lpd = 10.0 + 0.01 * ((d * 5 + c) % 13) as f64;
                lines.push(format!("{c},{d},{shgc},{lpd}"));
            }
        }
        let with_shgc = |cell: &str| {
            let mut l = lines.clone();
            // Line 4: chain 0, draw 2.
            l[3] = format!("0,2,{cell},10.0");
            l.join("\n") + "\n"
        };
        diagnose(&with_shgc("0.5")).unwrap();
        for cell in ["inf", "-inf", "1e999"] {
            assert_eq!(
                diagnose(&with_shgc(cell)).unwrap_err(),
                format!(
                    "DIR/draws.csv: line 4, column 'shgc': an infinite value ({cell:?}); \
                     every draw must be a finite number"
                )
            );
        }
        for cell in ["NaN", ""] {
            assert_eq!(
                diagnose(&with_shgc(cell)).unwrap_err(),
                format!(
                    "DIR/draws.csv: line 4, column 'shgc': a missing value ({cell:?}); \
                     every draw must be a finite number"
                )
            );
        }
        let e = diagnose(&with_shgc(&("9".repeat(400) + "x"))).unwrap_err();
        assert!(
            e.starts_with("DIR/draws.csv: line 4, column 'shgc': not a number: \"9999"),
            "{e}"
        );
        assert!(e.len() < 120, "the message quotes an excerpt: {e}");
    }
}
