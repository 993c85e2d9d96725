//! One module per subcommand. Each exposes an `Args` struct (clap) and `run(args)`.

use clap::{Parser, Subcommand};

pub mod diagnose;
pub mod metrics;
pub mod precalibrate;
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
    /// Pre-calibration: meters -> bases, day types, schedule priors (priors.toml).
    Precalibrate(precalibrate::Args),
    /// Train the LSTM surrogate on a training set and export it to ONNX.
    Train(train::Args),
    /// Predict hourly meters with a trained surrogate.
    Predict(predict::Args),
    /// Convergence diagnostics (R-hat, bulk/tail ESS) of MCMC draws from a CSV.
    Diagnose(diagnose::Args),
    /// ASHRAE Guideline 14 NMBE and CV-RMSE of simulated vs measured hourly CSVs.
    Metrics(metrics::Args),
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Precalibrate(a) => precalibrate::run(a),
        Command::Train(a) => train::run(a),
        Command::Predict(a) => predict::run(a),
        Command::Diagnose(a) => diagnose::run(a),
        Command::Metrics(a) => metrics::run(a),
    }
}
