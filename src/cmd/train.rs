//! `bemcal train`: trains the LSTM surrogate on a training set (runs the embedded Python trainer).

use std::path::PathBuf;

use bemcal_surrogate::{LrSchedule, TimeFeatures, TrainOptions};

/// Train the LSTM surrogate on a training-set directory and export it to ONNX.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Training-set directory (params.npy, weather.npy, outputs.npy, dataset.json).
    #[arg(long)]
    pub dataset: PathBuf,
    /// Output directory for the ONNX graphs and surrogate.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Maximum epochs.
    #[arg(long, default_value_t = 200)]
    pub epochs: usize,
    /// Early-stopping patience on the held-out loss, epochs.
    #[arg(long, default_value_t = 20)]
    pub patience: usize,
    /// Seed (torch and numpy).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Mini-batch size.
    #[arg(long, default_value_t = 1024)]
    pub batch_size: usize,
    /// Time-of-day inputs: none (the reference), hour, hour+schedule.
    #[arg(long, default_value = "none")]
    pub time_features: TimeFeatures,
    /// auto, cpu or cuda.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// torch threads (0: torch's default).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Adam's learning rate (the first where it is scheduled).
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// The learning rate's schedule: constant, or cosine (annealed to 1/100 over the epochs).
    #[arg(long, default_value = "constant")]
    pub lr_schedule: LrSchedule,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let opts = TrainOptions {
        epochs: args.epochs,
        patience: args.patience,
        seed: args.seed,
        batch_size: args.batch_size,
        time_features: args.time_features,
        device: args.device,
        threads: args.threads,
        lr: args.lr,
        lr_schedule: args.lr_schedule,
        ..TrainOptions::default()
    };
    let report = bemcal_surrogate::train(&args.dataset, &args.out, &opts)?;
    println!(
        "surrogate in {} ({} epochs, best {}, {:.1} s)",
        report.out_dir.display(),
        report.meta.training.epochs_run,
        report.meta.training.best_epoch,
        report.seconds
    );
    for o in &report.meta.outputs {
        let cv = report
            .meta
            .held_out
            .metrics
            .get(&o.name)
            .and_then(|m| m.cv_rmse_pct);
        match cv {
            Some(cv) => println!(
                "  {}: sigma_eta {:.4} kWh, held-out CV-RMSE {cv:.2} %",
                o.name, o.sigma_eta_kwh
            ),
            None => println!("  {}: sigma_eta {:.4} kWh", o.name, o.sigma_eta_kwh),
        }
    }
    Ok(())
}
