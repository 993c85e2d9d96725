//! `bemcal submit`: bundles a project's files, uploads them and starts a run; prints its id
//! (the same project while its run still runs: that run's id, said on stderr).

use std::path::PathBuf;

use bemcal_client::bundle::Policy;

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
    /// Send files that lie outside the project's folder too (a link in the folder that points
    /// out of it included). Special files of the system (/proc, /sys, /dev), sockets and FIFOs
    /// are never sent.
    #[arg(long)]
    pub allow_outside: bool,
    /// List the files that would be uploaded, with their sizes; upload nothing.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let policy = Policy {
        allow_outside: a.allow_outside,
    };
    if a.dry_run {
        let files = bemcal_client::bundle::collect(&a.project, policy)?;
        let total: usize = files.iter().map(|(_, b)| b.len()).sum();
        for (name, bytes) in &files {
            println!("{:>12}  {name}", bytes.len());
        }
        println!("{total:>12}  in {} files (nothing uploaded)", files.len());
        return Ok(());
    }
    let connect = a.client.connect()?;
    let rt = bemcal_client::runtime()?;
    let s = rt.block_on(async {
        let mut c = connect.client()?;
        bemcal_client::client::submit_project(&mut c, &a.project, a.surrogate.as_deref(), policy)
            .await
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

#[cfg(test)]
mod tests {
    /// What the bundle sends of a pretrained surrogate's folder is what a fold reads, and what
    /// a worker checks of a submitted project.
    #[test]
    fn the_pretrained_files_that_travel_are_those_a_fold_reads() {
        assert_eq!(
            bemcal_client::bundle::PRETRAINED_FILES,
            bemcal_surrogate::pretrained::FILES
        );
        assert_eq!(
            bemcal_client::bundle::PRETRAINED_OPTIONAL,
            [bemcal_surrogate::pretrained::FAMILY_FILE]
        );
    }
}
