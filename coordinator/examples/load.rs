//! Load test of the coordinator (issue 21; a benchmark, not a test): thousands of queued jobs
//! and dozens of lightweight workers on loopback that lease, heartbeat and complete as fast as
//! they can. Prints leases per second, the p50 / p99 latency of Lease and Complete, the
//! process's peak memory and the database's size, and checks that every job was done exactly
//! once (one attempt each, nothing lost or duplicated).
//!
//! ```sh
//! cargo run --release -p bemcal-coordinator --example load -- [JOBS] [WORKERS] [RUNS]
//! ```
//!
//! The jobs are chain-segment jobs of synthetic runs with no driver behind them: what is
//! measured is the coordinator's own path (gRPC, token check, SQLite transactions), not the
//! work a job does.

use std::sync::Arc;
use std::time::{Duration, Instant};

use bemcal_calibrate::output::{DRAWS_FILE, STATES_FILE};
use bemcal_client::client::{upload, Connect};
use bemcal_client::proto::{
    job::Kind, ChainSegmentJob, CompleteRequest, FileRef, HeartbeatRequest, Job, JobResult,
    LeaseRequest, RegisterRequest,
};
use bemcal_coordinator::artifacts::ArtifactDir;
use bemcal_coordinator::auth::{CheckToken, WorkerCredentials};
use bemcal_coordinator::db::{NewJob, Store};
use bemcal_coordinator::driver::{Config, State};
use bemcal_coordinator::proto::coordinator_server::CoordinatorServer;
use bemcal_coordinator::service::Service;
use bemcal_coordinator::states::{JobKind, JobState, Stage};
use tonic::service::interceptor::InterceptedService;

const TOKEN: &str = "load-test-token-0123456789";

fn arg(i: usize, default: usize) -> usize {
    std::env::args()
        .nth(i)
        .and_then(|a| a.parse().ok())
        .unwrap_or(default)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// Peak resident memory of this process (kB), from /proc.
fn peak_rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|v| v.parse().ok()))
        })
        .unwrap_or(0)
}

fn main() -> anyhow::Result<()> {
    let (jobs, workers, runs) = (arg(1, 5_000), arg(2, 48), arg(3, 10));
    let dir = tempfile::tempdir()?;
    let store = Store::open(&dir.path().join("coordinator.db")).map_err(anyhow::Error::msg)?;
    for r in 0..runs {
        let id = format!("load{r}");
        store
            .create_run(&id, &id, &[], &[])
            .map_err(anyhow::Error::msg)?;
        let n = jobs / runs + usize::from(r < jobs % runs);
        let new = (0..n)
            .map(|i| NewJob {
                stage: Stage::Chains,
                kind: JobKind::Chains,
                label: format!("segment {i}"),
                spec: Job {
                    kind: Some(Kind::Chains(ChainSegmentJob {
                        first_chain: 0,
                        chains: 1,
                        iterations: 100,
                        segment: i as u32,
                        round: 0,
                        temperature: 1.0,
                        target: 100,
                    })),
                    ..Default::default()
                },
                cache_key: None,
            })
            .collect();
        store
            .set_stage(&id, Stage::Chains, new)
            .map_err(anyhow::Error::msg)?;
    }
    let (kick, mut kicked) = tokio::sync::mpsc::unbounded_channel();
    let st = Arc::new(State {
        store,
        artifacts: ArtifactDir::new(&dir.path().join("artifacts"))?,
        data: dir.path().into(),
        config: Config::default(),
        kick,
        uploads: tokio::sync::Semaphore::new(16),
        credentials: WorkerCredentials::default(),
    });
    let rt = bemcal_client::runtime()?;
    rt.block_on(async move {
        // No driver: the runs are synthetic; completions only ask for one.
        tokio::spawn(async move { while kicked.recv().await.is_some() {} });
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let url = format!("http://{}", listener.local_addr()?);
        let svc = InterceptedService::new(
            CoordinatorServer::new(Service { st: st.clone() }),
            CheckToken::new(TOKEN, st.credentials.clone()),
        );
        tokio::spawn(
            tonic::transport::Server::builder()
                .add_service(svc)
                .serve_with_incoming(tokio_stream::wrappers::TcpListenerStream::new(listener)),
        );
        let connect = Connect {
            url,
            token: TOKEN.into(),
            tls_ca: None,
        };
        // A chain segment hands over its states and draws: the same two small files for every
        // job, uploaded once.
        let mut c = connect.client()?;
        let mut outputs = vec![];
        for name in [STATES_FILE, DRAWS_FILE] {
            let bytes = b"[]".to_vec();
            outputs.push(FileRef {
                path: name.into(),
                size: bytes.len() as u64,
                sha256: upload(&mut c, bytes).await?,
            });
        }
        let t0 = Instant::now();
        let mut tasks = vec![];
        for w in 0..workers {
            // Each worker registers (the one token enrolls) and calls with its own credential.
            let me = connect
                .client()?
                .register(RegisterRequest {
                    name: format!("w{w}"),
                    protocol: bemcal_client::PROTOCOL,
                })
                .await?
                .into_inner();
            let id = me.worker_id;
            let mut c = Connect {
                token: me.credential,
                ..connect.clone()
            }
            .client()?;
            let outputs = outputs.clone();
            tasks.push(tokio::spawn(async move {
                let (mut lease_ms, mut complete_ms) = (vec![], vec![]);
                loop {
                    let t = Instant::now();
                    let job = c
                        .lease(LeaseRequest {
                            worker_id: id.clone(),
                            free_slots: 1,
                            protocol: bemcal_client::PROTOCOL,
                        })
                        .await?
                        .into_inner()
                        .job;
                    lease_ms.push(t.elapsed().as_secs_f64() * 1e3);
                    let Some(job) = job else { break };
                    let hb = HeartbeatRequest {
                        worker_id: id.clone(),
                        lease_id: job.lease_id,
                    };
                    anyhow::ensure!(c.heartbeat(hb).await?.into_inner().ok, "lease lost");
                    let t = Instant::now();
                    c.complete(CompleteRequest {
                        worker_id: id.clone(),
                        lease_id: job.lease_id,
                        outputs: outputs.clone(),
                        result: Some(JobResult::chains(100)),
                    })
                    .await?;
                    complete_ms.push(t.elapsed().as_secs_f64() * 1e3);
                }
                Ok::<_, anyhow::Error>((lease_ms, complete_ms))
            }));
        }
        let (mut lease_ms, mut complete_ms) = (vec![], vec![]);
        for t in tasks {
            let (l, c) = t.await??;
            lease_ms.extend(l);
            complete_ms.extend(c);
        }
        let wall = t0.elapsed().as_secs_f64();
        // Every job done, each by one attempt.
        let (mut done, mut attempts) = (0, 0);
        for r in 0..runs {
            let id = format!("load{r}");
            let js = st.store.jobs(&id, None).map_err(anyhow::Error::msg)?;
            done += js.iter().filter(|j| j.state == JobState::Done).count();
            attempts += st.store.attempts(&id).map_err(anyhow::Error::msg)?;
        }
        lease_ms.sort_by(f64::total_cmp);
        complete_ms.sort_by(f64::total_cmp);
        let db: u64 = std::fs::read_dir(dir.path())?
            .filter_map(|e| e.ok())
            .filter(|e| {
                e.file_name()
                    .to_string_lossy()
                    .starts_with("coordinator.db")
            })
            .filter_map(|e| e.metadata().ok().map(|m| m.len()))
            .sum();
        println!("jobs {jobs} in {runs} runs, {workers} workers on loopback");
        println!(
            "done {done} of {jobs}, attempts {attempts} (lost or duplicated: {})",
            jobs as i64 - done as i64 + (attempts as i64 - jobs as i64)
        );
        println!("wall {wall:.2} s: {:.0} leases/s", jobs as f64 / wall);
        println!(
            "Lease    p50 {:.2} ms  p99 {:.2} ms ({} calls incl. empty)",
            percentile(&lease_ms, 0.5),
            percentile(&lease_ms, 0.99),
            lease_ms.len()
        );
        println!(
            "Complete p50 {:.2} ms  p99 {:.2} ms",
            percentile(&complete_ms, 0.5),
            percentile(&complete_ms, 0.99)
        );
        println!(
            "peak RSS {:.1} MB, database {:.1} MB",
            peak_rss_kb() as f64 / 1024.0,
            db as f64 / 1e6
        );
        anyhow::ensure!(
            done == jobs && attempts as usize == jobs,
            "jobs lost or duplicated"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
        Ok(())
    })
}
