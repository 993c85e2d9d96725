//! `bemcal watch`: follows a run, printing per-stage progress whenever it changes.

use bemcal_client::proto::RunState;

use super::coordinator::ClientArgs;
use super::progress::{Progress, ProgressFormat, Sink};

/// Follow a run until it ends (exit status 1 if it fails or is cancelled).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Run id (printed by `submit`).
    pub run: String,
    #[command(flatten)]
    pub client: ClientArgs,
    /// How progress is written on standard output: `text` for people, `json` for programs (one
    /// object a line).
    #[arg(long, value_enum, default_value_t)]
    pub progress: ProgressFormat,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let connect = a.client.connect()?;
    let rt = bemcal_client::runtime()?;
    let progress = Progress::new(a.progress, Sink::Stdout);
    let st = rt.block_on(async {
        let mut c = connect.client()?;
        let mut said = 0;
        bemcal_client::client::watch(&mut c, &a.run, |s| {
            // The driver's messages since the last change, then the stages.
            for l in s.log.iter().skip(said) {
                progress.log(l);
            }
            said = said.max(s.log.len());
            progress.run(s);
        })
        .await
    });
    progress.finish();
    let st = st?;
    if st.state() != RunState::Done {
        anyhow::bail!("run {} {}: {}", st.run_id, st.state().word(), st.error);
    }
    Ok(())
}
