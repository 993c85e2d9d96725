//! `bemcal cancel`: cancels a run (its queued jobs are dropped, running ones ignored).

use super::coordinator::ClientArgs;
use bemcal_client::proto::RunRequest;

/// Cancel a run.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Run id (printed by `submit`).
    pub run: String,
    #[command(flatten)]
    pub client: ClientArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let connect = a.client.connect()?;
    let rt = bemcal_client::runtime()?;
    let st = rt.block_on(async {
        let mut c = connect.client()?;
        c.cancel(RunRequest {
            run_id: a.run.clone(),
        })
        .await
        .map_err(|e| anyhow::anyhow!("{}", e.message()))
    })?;
    println!("{} {}", st.get_ref().run_id, st.get_ref().state().word());
    Ok(())
}
