//! A bemcal worker: pulls jobs from the coordinator and runs them (EnergyPlus design points,
//! surrogate training, chain segments, validation), with a heartbeat per job. Inputs arrive as
//! content-addressed artifacts, fetched once into the cache folder; outputs go back as
//! artifacts before the job is reported complete.
//!
//! At start the worker registers with the coordinator (the token it is given is the enrollment
//! token) and gets an id and a credential of its own: every later call carries that credential,
//! so its leases are its own (docs/cluster.md, "Identities and credentials").
//!
//! On shutdown (SIGTERM) the worker leases nothing more, lets running jobs finish for up to
//! `drain` and gives back the leases of those still running after that.
#![deny(missing_docs)]

pub mod cache;
pub mod exec;
pub mod metrics;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bemcal_client::client::{upload_file, Client, Connect};
use bemcal_client::proto::{
    self, CompleteRequest, FailRequest, HeartbeatRequest, LeaseRequest, RegisterRequest,
};
use tokio::sync::Semaphore;

use crate::cache::Cache;
use crate::metrics::{Metrics, Outcome};

/// How to run a worker.
#[derive(Debug, Clone)]
pub struct Options {
    /// The coordinator: its URL, the enrollment token (the coordinator's worker token) and TLS
    /// trust.
    pub connect: Connect,
    /// Jobs at once.
    pub slots: usize,
    /// Artifact cache and job folders.
    pub cache: PathBuf,
    /// The name this worker registers under; the coordinator's id for it is this name and a
    /// random suffix (its leases belong to that id).
    pub worker_id: String,
    /// How long running jobs may take to finish after a shutdown request.
    pub drain: Duration,
    /// Where to serve this worker's Prometheus metrics (`GET /metrics`); `None`: not.
    pub metrics: Option<SocketAddr>,
}

/// Retries an RPC while the coordinator is unreachable (it may be restarting), for up to
/// `patience`; other errors are returned at once.
async fn retry<T, F, Fut>(patience: Duration, mut f: F) -> Result<T, tonic::Status>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<T, tonic::Status>>,
{
    let t0 = std::time::Instant::now();
    loop {
        match f().await {
            Ok(v) => return Ok(v),
            Err(e)
                if matches!(
                    e.code(),
                    tonic::Code::Unavailable | tonic::Code::Unknown | tonic::Code::Cancelled
                ) && t0.elapsed() < patience =>
            {
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
            Err(e) => return Err(e),
        }
    }
}

/// Registers with the coordinator as `name` (with the enrollment token of `connect`), retrying
/// while it is unreachable, until `stopping`: the worker's id and a client that carries its own
/// credential; `None` when stopped first.
async fn register(
    connect: &Connect,
    name: &str,
    stopping: &AtomicBool,
) -> anyhow::Result<Option<(String, Client)>> {
    let mut enroll = connect.client()?;
    let mut said = false;
    while !stopping.load(Ordering::SeqCst) {
        let r = enroll
            .register(RegisterRequest {
                name: name.to_string(),
                protocol: bemcal_client::PROTOCOL,
            })
            .await;
        let reply = match r {
            Ok(r) => r.into_inner(),
            Err(e) if e.code() == tonic::Code::Unimplemented => anyhow::bail!(
                "the coordinator does not register workers (a release older than this worker's,                  bemcal {}): run workers of the coordinator's release",
                env!("CARGO_PKG_VERSION")
            ),
            Err(e)
                if matches!(
                    e.code(),
                    tonic::Code::Unavailable | tonic::Code::Unknown | tonic::Code::Cancelled
                ) =>
            {
                if !said {
                    tracing::warn!(worker = %name, "waiting for the coordinator: {}", e.message());
                    said = true;
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
                continue;
            }
            Err(e) => anyhow::bail!("the coordinator refused to register this worker: {}", e.message()),
        };
        let own = Connect {
            token: reply.credential,
            ..connect.clone()
        };
        tracing::info!(worker = %name, "registered as {}", reply.worker_id);
        return Ok(Some((reply.worker_id, own.client()?)));
    }
    Ok(None)
}

/// Runs the worker until `shutdown` completes (then drains); `ready` gets the bound address of
/// the metrics, if served (port 0 = ephemeral).
pub async fn run(
    opts: Options,
    ready: impl FnOnce(Option<SocketAddr>),
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let metrics = Metrics::new(opts.slots.max(1));
    let bound = match opts.metrics {
        None => None,
        Some(addr) => {
            let m = metrics.clone();
            let scrape = move || {
                let m = m.clone();
                async move { Ok(m.render()) }
            };
            // Served until the process ends: a draining worker still answers scrapes.
            Some(bemcal_client::metrics::spawn(addr, scrape, std::future::pending()).await?)
        }
    };
    ready(bound);
    let cache = Arc::new(Cache::new(&opts.cache)?);
    let stopping = Arc::new(AtomicBool::new(false));
    let slots = Arc::new(Semaphore::new(opts.slots.max(1)));
    let give_back = Arc::new(AtomicBool::new(false));
    {
        let stopping = stopping.clone();
        tokio::spawn(async move {
            shutdown.await;
            stopping.store(true, Ordering::SeqCst);
        });
    }
    let Some((worker_id, client)) = register(&opts.connect, &opts.worker_id, &stopping).await?
    else {
        return Ok(());
    };
    let mut tasks = tokio::task::JoinSet::new();
    while !stopping.load(Ordering::SeqCst) {
        let permit = tokio::select! {
            p = slots.clone().acquire_owned() => p?,
            _ = tokio::time::sleep(Duration::from_millis(200)) => continue,
        };
        let mut c = client.clone();
        let reply = c
            .lease(LeaseRequest {
                worker_id: worker_id.clone(),
                free_slots: (slots.available_permits() + 1) as u32,
                protocol: bemcal_client::PROTOCOL,
            })
            .await;
        let job = match reply {
            Ok(r) => r.into_inner().job,
            // A revoked credential, or a coordinator that no longer knows it (its database was
            // replaced): the worker stops rather than register itself again.
            Err(e) if e.code() == tonic::Code::Unauthenticated => {
                anyhow::bail!(
                    "the coordinator refused this worker's credential: {}",
                    e.message()
                )
            }
            Err(e) if e.code() == tonic::Code::FailedPrecondition => {
                anyhow::bail!("the coordinator refused this worker: {}", e.message())
            }
            Err(e) => {
                tracing::warn!(worker = %worker_id, "lease: {}", e.message());
                tokio::time::sleep(Duration::from_secs(1)).await;
                continue;
            }
        };
        let Some(job) = job else {
            drop(permit);
            tokio::time::sleep(Duration::from_millis(300)).await;
            continue;
        };
        let (client, cache, id, give_back, metrics) = (
            client.clone(),
            cache.clone(),
            worker_id.clone(),
            give_back.clone(),
            metrics.clone(),
        );
        tasks.spawn(async move {
            let kind = crate::metrics::kind_name(&job);
            let t0 = std::time::Instant::now();
            metrics.started();
            let outcome = handle(client, cache, id, job, give_back).await;
            metrics.ended(kind, outcome, t0.elapsed());
            drop(permit);
        });
        while tasks.try_join_next().is_some() {}
    }
    drain(tasks, opts.drain, &give_back).await;
    Ok(())
}

/// Draining: lets running jobs finish for up to `patience`, then gives back what is left.
async fn drain(mut tasks: tokio::task::JoinSet<()>, patience: Duration, give_back: &AtomicBool) {
    let drained = tokio::time::timeout(patience, async {
        while tasks.join_next().await.is_some() {}
    })
    .await;
    if drained.is_err() {
        give_back.store(true, Ordering::SeqCst);
        let _ = tokio::time::timeout(Duration::from_secs(10), async {
            while tasks.join_next().await.is_some() {}
        })
        .await;
    }
}

/// Runs one job: heartbeats while it runs, then uploads its outputs and reports; returns how
/// it ended.
async fn handle(
    mut client: Client,
    cache: Arc<Cache>,
    worker: String,
    job: proto::Job,
    give_back: Arc<AtomicBool>,
) -> Outcome {
    let lease = job.lease_id;
    let ttl = Duration::from_millis(job.lease_ttl_ms.max(1000) as u64);
    let beat = heartbeat(client.clone(), worker.clone(), lease, ttl);
    let work = {
        let (cache, client, job) = (cache.clone(), client.clone(), job.clone());
        async move {
            let (bundle, dir) = cache.prepare(client, &job).await?;
            let job2 = job.clone();
            let d2 = dir.clone();
            let out = tokio::task::spawn_blocking(move || exec::execute(&job2, &bundle, &d2))
                .await
                .map_err(|e| format!("job panicked: {e}"))??;
            Ok::<_, String>((dir, out))
        }
    };
    let outcome = tokio::select! {
        r = work => Some(r),
        _ = given_back(&give_back) => None,
    };
    let ended = match outcome {
        None => {
            let _ = client
                .fail(FailRequest {
                    worker_id: worker,
                    lease_id: lease,
                    error: "worker shutting down".into(),
                    requeue: true,
                })
                .await;
            Outcome::Returned
        }
        Some(Ok((dir, (files, result)))) => {
            let ended = report_outputs(&client, &worker, &job, files, result).await;
            let _ = std::fs::remove_dir_all(&dir);
            ended
        }
        Some(Err(e)) => {
            let _ = report_failure(&client, &worker, lease, e).await;
            Outcome::Failed
        }
    };
    beat.abort();
    ended
}

/// How long a worker keeps retrying an upload or a report while the coordinator is away.
const REPORT_PATIENCE: Duration = Duration::from_secs(600);

/// Heartbeats the lease every third of its time to live until the coordinator no longer knows
/// it (or the task is aborted).
fn heartbeat(
    mut client: Client,
    worker: String,
    lease: u64,
    ttl: Duration,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        loop {
            tokio::time::sleep(ttl / 3).await;
            let r = client
                .heartbeat(HeartbeatRequest {
                    worker_id: worker.clone(),
                    lease_id: lease,
                })
                .await;
            if let Ok(r) = r {
                if !r.into_inner().ok {
                    return;
                }
            }
        }
    })
}

/// Resolves once the worker is asked to give its jobs back.
async fn given_back(give_back: &AtomicBool) {
    while !give_back.load(Ordering::SeqCst) {
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// Uploads a finished job's output files and completes its lease (or fails it, when an upload
/// failed); done only when both went through.
async fn report_outputs(
    client: &Client,
    worker: &str,
    job: &proto::Job,
    files: Vec<(String, std::path::PathBuf)>,
    result: proto::JobResult,
) -> Outcome {
    let lease = job.lease_id;
    let mut outputs = vec![];
    let mut upload_err = None;
    for (rel, path) in files {
        let r = retry(REPORT_PATIENCE, || {
            let (path, rel, mut c) = (path.clone(), rel.clone(), client.clone());
            async move {
                upload_file(&mut c, &path, &rel)
                    .await
                    .map_err(|e| tonic::Status::unavailable(e.to_string()))
            }
        })
        .await;
        match r {
            Ok(f) => outputs.push(proto::FileRef::from(&f)),
            Err(e) => upload_err = Some(e.message().to_string()),
        }
    }
    let uploaded = upload_err.is_none();
    let r = match upload_err {
        Some(e) => report_failure(client, worker, lease, format!("uploading outputs: {e}")).await,
        None => retry(REPORT_PATIENCE, || {
            let mut c = client.clone();
            let req = CompleteRequest {
                worker_id: worker.to_string(),
                lease_id: lease,
                outputs: outputs.clone(),
                result: Some(result.clone()),
            };
            async move { c.complete(req).await }
        })
        .await
        .map(|_| ()),
    };
    let reported = r.is_ok();
    if let Err(e) = r {
        tracing::warn!(worker = %worker, job = job.job_id, "reporting the job: {}", e.message());
    }
    match uploaded && reported {
        true => Outcome::Done,
        false => Outcome::Failed,
    }
}

/// Fails a job's lease with its error (not requeued: the job itself failed), retried while the
/// coordinator is away.
async fn report_failure(
    client: &Client,
    worker: &str,
    lease: u64,
    error: String,
) -> Result<(), tonic::Status> {
    retry(REPORT_PATIENCE, || {
        let mut c = client.clone();
        let req = FailRequest {
            worker_id: worker.to_string(),
            lease_id: lease,
            error: error.clone(),
            requeue: false,
        };
        async move { c.fail(req).await }
    })
    .await
    .map(|_| ())
}
