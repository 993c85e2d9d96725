//! `bemcal submit`: bundles a project's files, uploads them and starts a run; prints its id
//! (the same project while its run still runs: that run's id, said on stderr).

use std::path::PathBuf;

use super::coordinator::ClientArgs;

/// Submit a calibration project to a coordinator (the files are validated there).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Project file (TOML).
    pub project: PathBuf,
    #[command(flatten)]
    pub client: ClientArgs,
    /// A trained surrogate folder to use instead of training one.
    #[arg(long)]
    pub surrogate: Option<PathBuf>,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let connect = a.client.connect()?;
    let rt = bemcal_client::runtime()?;
    let s = rt.block_on(async {
        let mut c = connect.client()?;
        bemcal_client::client::submit_project(&mut c, &a.project, a.surrogate.as_deref()).await
    })?;
    if s.resumed {
        eprintln!(
            "the same project is still running as run {}: that run goes on (its finished jobs are kept)",
            s.run_id
        );
    }
    println!("{}", s.run_id);
    Ok(())
}
