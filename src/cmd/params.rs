//! `bemcal params`: the calibration parameters of a model with their priors.

use std::path::PathBuf;

use super::common;

/// List a model's calibration parameters, units and triangular priors.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file: a building spec (TOML) or an `[idf]` parameter map.
    #[arg(long)]
    pub model: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (model, _) = common::load_model(&a.model)?;
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "parameters": model.parameters(),
                "constraints": model.constraints(),
                "outputs": model.outputs(),
            }))?
        );
        return Ok(());
    }
    println!(
        "{:<30} {:>10} {:>10} {:>10}  {:<10} description",
        "parameter", "min", "mode", "max", "unit"
    );
    for p in model.parameters() {
        println!(
            "{:<30} {:>10} {:>10} {:>10}  {:<10} {}",
            p.name,
            fmt(p.prior.min),
            fmt(p.prior.mode),
            fmt(p.prior.max),
            p.unit,
            p.description
        );
    }
    println!("\nconstraints:");
    for c in model.constraints() {
        println!(
            "  {} + {} <= {}  ({})",
            c.lower, c.margin, c.upper, c.reason
        );
    }
    println!("\noutputs:");
    for o in model.outputs() {
        println!("  {:<18} = {}", o.name, o.meters.join(" + "));
    }
    Ok(())
}

fn fmt(x: f64) -> String {
    format!("{x:.6}")
        .trim_end_matches('0')
        .trim_end_matches('.')
        .to_string()
}
