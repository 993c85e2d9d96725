//! One module per subcommand. Each exposes an `Args` struct (clap) and `run(args)`.

use clap::{Parser, Subcommand};

/// Bayesian calibration of EnergyPlus building energy models against hourly meters.
#[derive(Debug, Parser)]
#[command(name = "bemcal", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {}
}
