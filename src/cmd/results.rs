//! `bemcal results`: downloads a finished run's files (the local `calibrate` layout).

use std::path::PathBuf;

use super::coordinator::ClientArgs;

/// Download summary.json, draws.csv, posterior_predictive.csv, surrogate/, validation/, ...
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Run id (printed by `submit`).
    pub run: String,
    /// Folder to write the run's files into.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub client: ClientArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let connect = a.client.connect()?;
    let rt = bemcal_client::runtime()?;
    let n = rt.block_on(async {
        let mut c = connect.client()?;
        bemcal_client::client::fetch_results(&mut c, &a.run, &a.out).await
    })?;
    println!("{n} files written to {}", a.out.display());
    Ok(())
}
