//! One module per subcommand. Each exposes an `Args` struct (clap) and `run(args)`.

use clap::{Parser, Subcommand};

pub mod calibrate;
pub mod cancel;
pub mod check;
mod common;
pub mod completions;
pub mod coordinator;
pub mod corpus;
pub mod crossval;
pub mod design;
pub mod diagnose;
pub mod doctor;
pub mod example;
pub mod export;
mod logging;
pub mod metrics;
pub mod params;
pub mod portfolio;
pub mod precalibrate;
pub mod predict;
mod progress;
pub mod reference;
pub mod report;
pub mod results;
pub mod savings;
pub mod simulate;
pub mod status;
pub mod submit;
pub mod synthesize;
pub mod train;
pub mod watch;
pub mod weather;
pub mod worker;

/// Bayesian calibration of EnergyPlus building energy models against hourly meters.
#[derive(Debug, Parser)]
#[command(name = "bemcal", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run EnergyPlus once for a model at given parameter values.
    Simulate(simulate::Args),
    /// List a model's calibration parameters and priors.
    Params(params::Args),
    /// Where bemcal finds Python, EnergyPlus, ONNX Runtime and PyTorch, each tried for real.
    Doctor(doctor::Args),
    /// Write a bundled example building (model and project files) into a folder.
    Example(example::Args),
    /// An EPW of the metered year from measured weather (ISD-lite or a station CSV) and a TMY.
    Weather(weather::Args),
    /// Pre-calibration: meters -> bases, day types, schedule priors (priors.toml).
    Precalibrate(precalibrate::Args),
    /// Design points: a Latin hypercube over the priors, optionally simulated.
    Design(design::Args),
    /// Simulate the building family's corpus for the pretrained surrogate (resumable).
    Corpus(corpus::Args),
    /// Train the LSTM surrogate on a training set and export it to ONNX.
    Train(train::Args),
    /// Predict hourly meters with a trained surrogate.
    Predict(predict::Args),
    /// Convergence diagnostics (R-hat, bulk/tail ESS) of MCMC draws from a CSV.
    Diagnose(diagnose::Args),
    /// Load and validate a project and everything it names, without running anything.
    Check(check::Args),
    /// The whole calibration on this machine: design, training, chains, validation.
    Calibrate(calibrate::Args),
    /// Cross-validation by month: each month held out in turn, design and surrogate shared.
    Crossval(crossval::Args),
    /// Synthetic meters: EnergyPlus at hidden true parameters, with noise and a gap.
    Synthesize(synthesize::Args),
    /// ASHRAE Guideline 14 NMBE and CV-RMSE of simulated vs measured hourly CSVs.
    Metrics(metrics::Args),
    /// A self-contained HTML report of a calibration folder (DIR/report.html).
    Report(report::Args),
    /// Retrofit measures' savings with credible intervals, from a finished calibration.
    Savings(savings::Args),
    /// Serve calibration runs to gRPC workers (state in SQLite).
    Coordinator(coordinator::Args),
    /// Pull and run jobs from a coordinator.
    Worker(worker::Args),
    /// Submit a project to a coordinator; prints the run id.
    Submit(submit::Args),
    /// Runs on a coordinator and their progress per stage.
    Status(status::Args),
    /// Follow a run's progress until it ends.
    Watch(watch::Args),
    /// Download a finished run's files.
    Results(results::Args),
    /// Cancel a run.
    Cancel(cancel::Args),
    /// A calibration's posterior as an ArviZ InferenceData file (netCDF).
    Export(export::Args),
    /// A shell completion script (bash, zsh, fish, elvish, powershell) on stdout.
    Completions(completions::Args),
    /// Many buildings calibrated together: submit, run locally, status, results.
    Portfolio(portfolio::Args),
    /// Write the reference pages generated from the code (docs/reference: the CLI's, and the
    /// JSON Schemas of the project file, the model file and summary.json).
    Reference(reference::Args),
}

impl Command {
    /// Whether the command is (or hosts) a long-running server: the coordinator, a worker, or
    /// a calibration or portfolio that starts them locally. Those must outlive a peer that
    /// hangs up, so they never die of SIGPIPE.
    pub fn serves(&self) -> bool {
        matches!(
            self,
            Command::Coordinator(_)
                | Command::Worker(_)
                | Command::Calibrate(_)
                | Command::Portfolio(_)
        )
    }
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Simulate(a) => simulate::run(a),
        Command::Params(a) => params::run(a),
        Command::Example(a) => example::run(a),
        Command::Doctor(a) => doctor::run(a),
        Command::Weather(a) => weather::run(a),
        Command::Precalibrate(a) => precalibrate::run(a),
        Command::Corpus(a) => corpus::run(a),
        Command::Train(a) => train::run(a),
        Command::Predict(a) => predict::run(a),
        Command::Diagnose(a) => diagnose::run(a),
        Command::Metrics(a) => metrics::run(a),
        Command::Report(a) => report::run(a),
        Command::Savings(a) => savings::run(a),
        Command::Design(a) => design::run(a),
        Command::Check(a) => check::run(a),
        Command::Calibrate(a) => calibrate::run(a),
        Command::Crossval(a) => crossval::run(a),
        Command::Synthesize(a) => synthesize::run(a),
        Command::Coordinator(a) => coordinator::run(a),
        Command::Worker(a) => worker::run(a),
        Command::Submit(a) => submit::run(a),
        Command::Status(a) => status::run(a),
        Command::Watch(a) => watch::run(a),
        Command::Results(a) => results::run(a),
        Command::Cancel(a) => cancel::run(a),
        Command::Export(a) => export::run(a),
        Command::Completions(a) => completions::run(a),
        Command::Portfolio(a) => portfolio::run(a),
        Command::Reference(a) => reference::run(a),
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    use super::Cli;

    /// Every subcommand, flag and positional argument says what it is in `--help`.
    #[test]
    fn every_flag_has_help() {
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            let path = format!("{path} {}", cmd.get_name());
            if cmd.get_about().is_none() {
                missing.push(format!("{path}: no about"));
            }
            for arg in cmd.get_arguments() {
                let id = arg.get_id().as_str();
                if id == "help" || id == "version" {
                    continue;
                }
                if arg.get_help().is_none() && arg.get_long_help().is_none() {
                    missing.push(format!("{path} {id}"));
                }
            }
            for sub in cmd.get_subcommands() {
                walk(sub, &path, missing);
            }
        }
        let mut missing = vec![];
        walk(&Cli::command(), "", &mut missing);
        assert!(missing.is_empty(), "without help text: {missing:#?}");
    }

    /// docs/reference/ holds what `bemcal reference` writes from today's definitions.
    #[test]
    fn the_generated_references_are_current() {
        for (name, text) in super::reference::pages() {
            let path = format!("{}/docs/reference/{name}", env!("CARGO_MANIFEST_DIR"));
            let committed = std::fs::read_to_string(&path).unwrap_or_default();
            assert!(
                committed == text,
                "docs/reference/{name} is out of date: run `bemcal reference` (target/release/bemcal reference) and commit it"
            );
        }
    }

    #[test]
    fn completions_name_every_subcommand() {
        let mut out = Vec::new();
        clap_complete::generate(
            clap_complete::Shell::Bash,
            &mut Cli::command(),
            "bemcal",
            &mut out,
        );
        let script = String::from_utf8(out).unwrap();
        for sub in Cli::command().get_subcommands() {
            assert!(script.contains(sub.get_name()), "{}", sub.get_name());
        }
    }
}
