//! `bemcal worker`: pulls jobs from a coordinator and runs them.

use std::path::PathBuf;
use std::time::Duration;

use super::coordinator::ClientArgs;

/// Run EnergyPlus design points, surrogate training, chain segments and validations for a
/// coordinator; SIGTERM stops leasing, lets running jobs finish (or gives them back).
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub client: ClientArgs,
    /// Jobs at once (one core each for EnergyPlus).
    #[arg(long, default_value_t = 1)]
    pub slots: usize,
    /// Artifact cache and job folders.
    #[arg(long, default_value = "bemcal-worker-cache")]
    pub cache: PathBuf,
    /// Worker name (default: host-pid).
    #[arg(long)]
    pub id: Option<String>,
    /// Seconds running jobs may take to finish after SIGTERM before their leases are returned.
    #[arg(long, default_value_t = 60)]
    pub drain: u64,
    /// Serve this worker's Prometheus metrics (`GET /metrics`: jobs by kind and outcome, job
    /// durations, busy slots) on this address (port 0: any free port; the address is printed).
    #[arg(long, env = "BEMCAL_WORKER_METRICS_LISTEN")]
    pub metrics_listen: Option<std::net::SocketAddr>,
    #[command(flatten)]
    pub log: super::logging::LogArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    a.log.init();
    let host = std::fs::read_to_string("/etc/hostname")
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|_| "worker".into());
    let opts = bemcal_worker::Options {
        connect: a.client.connect()?,
        slots: a.slots.max(1),
        cache: a.cache,
        worker_id: a
            .id
            .unwrap_or_else(|| format!("{host}-{}", std::process::id())),
        drain: Duration::from_secs(a.drain),
        metrics: a.metrics_listen,
    };
    let rt = bemcal_client::runtime()?;
    let ran = rt.block_on(bemcal_worker::run(
        opts,
        |metrics| {
            if let Some(m) = metrics {
                println!("metrics on {}", bemcal_client::metrics::url(m));
                let _ = std::io::Write::flush(&mut std::io::stdout());
            }
        },
        bemcal_client::shutdown_signal(),
    ));
    // The drain has bounded the wait for running jobs and given back their leases: a job
    // still running on a blocking thread (EnergyPlus, a chain segment) must not hold the
    // process, as dropping the runtime would (it waits for blocking tasks without limit).
    rt.shutdown_timeout(Duration::from_secs(1));
    ran
}
