//! `bemcal diagnose`: convergence diagnostics of MCMC draws (rank-normalised split R-hat, bulk
//! and tail ESS as ArviZ computes them) and summary statistics per parameter.
//!
//! DRAWS.csv has columns `chain,draw,<parameter>...`; each chain's rows are ordered by `draw`
//! and all chains must have the same number of draws.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{bail, Context};
use bemcal_stats::diagnostics::{self, ParameterDiagnostics};

use super::metrics::Table;

/// Arguments of `bemcal diagnose`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Draws CSV with columns `chain,draw,<parameter>...`.
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
    let t = Table::read(&args.draws)?;
    let (ci, di) = (t.column("chain")?, t.column("draw")?);
    let params: Vec<usize> = (0..t.header.len())
        .filter(|&k| k != ci && k != di)
        .collect();
    if params.is_empty() {
        bail!(
            "{}:1: no parameter columns besides chain and draw",
            t.path.display()
        );
    }
    // chain -> [(draw, values)]
    let mut chains: BTreeMap<String, Vec<(i64, Vec<f64>)>> = BTreeMap::new();
    for (line, f) in &t.rows {
        let draw: i64 = f[di].parse().map_err(|_| {
            anyhow::anyhow!(
                "{}:{line}: column `draw`: `{}` is not an integer",
                t.path.display(),
                f[di]
            )
        })?;
        let mut vals = Vec::with_capacity(params.len());
        for &k in &params {
            let v = t.number(*line, k, &f[k])?;
            if v.is_nan() {
                bail!(
                    "{}:{line}: column `{}`: missing value",
                    t.path.display(),
                    t.header[k]
                );
            }
            vals.push(v);
        }
        chains.entry(f[ci].clone()).or_default().push((draw, vals));
    }
    if chains.is_empty() {
        bail!("{}: no draws", t.path.display());
    }
    let len = chains.values().next().map_or(0, |c| c.len());
    for (name, c) in chains.iter_mut() {
        if c.len() != len {
            bail!(
                "{}: chain `{name}` has {} draws, others {len}; chains must be equally long",
                t.path.display(),
                c.len()
            );
        }
        c.sort_by_key(|(d, _)| *d);
    }
    let mut rows = Vec::new();
    for (p, &k) in params.iter().enumerate() {
        let per_chain: Vec<Vec<f64>> = chains
            .values()
            .map(|c| c.iter().map(|(_, v)| v[p]).collect())
            .collect();
        let d = diagnostics::diagnose(&per_chain)
            .with_context(|| format!("parameter `{}`", t.header[k]))?;
        rows.push(Row {
            parameter: &t.header[k],
            d,
        });
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        println!("{} chains x {len} draws", chains.len());
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
