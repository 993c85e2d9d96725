//! `bemcal status`: runs and their progress per stage.

use super::coordinator::ClientArgs;
use bemcal_client::proto::{HealthRequest, ListRunsRequest, RunRequest, RunStatus};

/// Show one run (or all runs) with per-stage progress.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Run id (default: every run).
    pub run: Option<String>,
    #[command(flatten)]
    pub client: ClientArgs,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
    /// Only check that the coordinator answers (any valid token, a worker's too): prints its
    /// version and queue depth. What a worker's readiness probe runs.
    #[arg(long, conflicts_with = "run")]
    pub health: bool,
}

/// A run's status as JSON.
pub fn to_json(s: &RunStatus) -> serde_json::Value {
    serde_json::json!({
        "run": s.run_id,
        "name": s.name,
        "state": s.state().word(),
        "stage": s.stage().word(),
        "error": s.error,
        "jobs_total": s.jobs_total,
        "attempts_total": s.attempts_total,
        "created_ms": s.created_ms,
        "finished_ms": s.finished_ms,
        "stages": super::progress::stages_json(s),
        "jobs": s.jobs.iter().map(|j| serde_json::json!({
            "id": j.job_id, "stage": j.stage().word(), "label": j.label, "state": j.state().word(),
            "attempts": j.attempts, "worker": j.worker, "cached": j.cached,
            "result": serde_json::from_str::<serde_json::Value>(&j.result_json).unwrap_or_default(),
        })).collect::<Vec<_>>(),
        "results": s.results.iter().map(|f| serde_json::json!({
            "path": f.path, "sha256": f.sha256, "size": f.size,
        })).collect::<Vec<_>>(),
    })
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let connect = a.client.connect()?;
    let rt = bemcal_client::runtime()?;
    if a.health {
        let h = rt
            .block_on(async {
                connect
                    .client()?
                    .health(HealthRequest {})
                    .await
                    .map_err(anyhow::Error::from)
            })
            .map_err(|e| anyhow::anyhow!("{}: {e:#}", a.client.coordinator))?
            .into_inner();
        println!(
            "coordinator {} (bemcal {}): {} jobs queued, {} leased",
            a.client.coordinator, h.version, h.queued_jobs, h.leased_jobs
        );
        return Ok(());
    }
    let runs = rt
        .block_on(async {
            let mut c = connect.client()?;
            let runs = match &a.run {
                Some(id) => vec![c
                    .get_run(RunRequest { run_id: id.clone() })
                    .await
                    .map_err(|e| anyhow::anyhow!("{}", e.message()))?
                    .into_inner()],
                None => {
                    c.list_runs(ListRunsRequest::default())
                        .await
                        .map_err(|e| anyhow::anyhow!("{}", e.message()))?
                        .into_inner()
                        .runs
                }
            };
            Ok::<_, anyhow::Error>(runs)
        })
        // Which coordinator did not answer, as --health says it.
        .map_err(|e| anyhow::anyhow!("coordinator {}: {e:#}", a.client.coordinator))?;
    if a.json {
        let v: Vec<_> = runs.iter().map(to_json).collect();
        let v = if a.run.is_some() {
            v.into_iter().next().unwrap_or_default()
        } else {
            serde_json::Value::Array(v)
        };
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    for s in &runs {
        println!(
            "{}  {:<24} {:<9} stage {:<9} jobs {:>3} attempts {:>3}{}",
            s.run_id,
            s.name,
            s.state().word(),
            s.stage().word(),
            s.jobs_total,
            s.attempts_total,
            if s.error.is_empty() {
                String::new()
            } else {
                format!("\n  error: {}", s.error)
            }
        );
        if a.run.is_some() {
            for l in bemcal_client::client::progress_lines(s) {
                println!("{l}");
            }
        }
    }
    Ok(())
}
