//! `bemcal watch`: follows a run, printing per-stage progress whenever it changes.

use bemcal_client::proto::RunState;

use super::coordinator::ClientArgs;

/// Follow a run until it ends (exit status 1 if it fails or is cancelled).
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
    let t0 = std::time::Instant::now();
    let st = rt.block_on(async {
        let mut c = connect.client()?;
        let mut said = 0;
        bemcal_client::client::watch(&mut c, &a.run, |s| {
            // The driver's messages since the last change, then the stages.
            for l in s.log.iter().skip(said) {
                println!("[{:>7.1} s] {l}", t0.elapsed().as_secs_f64());
            }
            said = said.max(s.log.len());
            println!(
                "[{:>7.1} s] run {} {} (stage {})",
                t0.elapsed().as_secs_f64(),
                s.run_id,
                s.state().word(),
                s.stage().word()
            );
            for l in bemcal_client::client::progress_lines(s) {
                println!("{l}");
            }
        })
        .await
    })?;
    if st.state() != RunState::Done {
        anyhow::bail!("run {} {}: {}", st.run_id, st.state().word(), st.error);
    }
    Ok(())
}
