//! One module per subcommand. Each exposes an `Args` struct (clap) and `run(args)`.

use clap::{Parser, Subcommand};

pub mod predict;
pub mod train;

/// Bayesian calibration of EnergyPlus building energy models against hourly meters.
#[derive(Debug, Parser)]
#[command(name = "bemcal", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Train the LSTM surrogate on a training set and export it to ONNX.
    Train(train::Args),
    /// Predict hourly meters with a trained surrogate.
    Predict(predict::Args),
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Train(a) => train::run(a),
        Command::Predict(a) => predict::run(a),
    }
}
