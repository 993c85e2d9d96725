//! Starting the coordinator: the database, the driver, the lease reaper (which also applies
//! workers' revocations) and the gRPC server (named client tokens, the enrollment token workers
//! register with, and the registered workers' own credentials; TLS when a certificate and key
//! are given).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Identity, Server, ServerTlsConfig};

use crate::artifacts::ArtifactDir;
use crate::audit::Event;
use crate::auth::{CheckToken, Refusal, WorkerCredentials};
use crate::db::Store;
use crate::driver::{spawn_driver, Config, State};
use crate::proto::coordinator_server::CoordinatorServer;
use crate::service::Service;
use crate::MAX_MESSAGE_BYTES;

/// How to run a coordinator.
#[derive(Debug, Clone)]
pub struct Options {
    /// Where to serve gRPC (port 0: any free port).
    pub listen: SocketAddr,
    /// State: `coordinator.db`, `artifacts/`, `runs/`.
    pub data: PathBuf,
    /// The clients' tokens, by name (`(name, token)`); each run records its client's name.
    pub clients: Vec<(String, String)>,
    /// The enrollment token: workers register with it and get credentials of their own. It may
    /// be a client's token (one token for everything: that client also registers workers).
    pub enroll: String,
    /// Requests a second one client may make on average, in bursts of up to ten seconds'
    /// worth (0: no limit; workers are not limited).
    pub client_rate: f64,
    /// PEM certificate and key: serve TLS.
    pub tls: Option<(PathBuf, PathBuf)>,
    /// Where to serve Prometheus metrics (`GET /metrics`, plain HTTP, no token); `None`: not.
    pub metrics: Option<SocketAddr>,
    /// Settings that shape runs.
    pub config: Config,
}

/// Serves until `shutdown` completes; `ready` gets the bound addresses (port 0 = ephemeral) of
/// the gRPC service and of the metrics.
pub async fn serve(
    opts: Options,
    ready: impl FnOnce(SocketAddr, Option<SocketAddr>),
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(&opts.data)?;
    let store = Store::open(&opts.data.join("coordinator.db"))?;
    // Workers could not heartbeat while we were down: give their leases a fresh TTL.
    store.refresh_leases(opts.config.lease_ttl_ms)?;
    let credentials = WorkerCredentials::default();
    for (sha, id, revoked) in store.worker_credentials()? {
        credentials.add(&sha, &id, revoked);
    }
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    let st = Arc::new(State {
        store,
        artifacts: ArtifactDir::new(&opts.data.join("artifacts"))?,
        data: opts.data.clone(),
        config: opts.config.clone(),
        kick: tx,
        uploads: tokio::sync::Semaphore::new(opts.config.max_uploads.max(1)),
        credentials: credentials.clone(),
    });
    for r in st.store.running_runs()? {
        let _ = st.kick.send(r);
    }
    spawn_driver(st.clone(), rx);
    spawn_reaper(st.clone());
    spawn_artifact_collector(st.clone());
    let health_svc = spawn_health(st.clone());

    let listener = tokio::net::TcpListener::bind(opts.listen).await?;
    let (stop_metrics, metrics_stopped) = tokio::sync::oneshot::channel::<()>();
    let metrics_addr = match opts.metrics {
        None => None,
        Some(addr) => Some(
            crate::metrics::spawn(st.clone(), addr, async move {
                let _ = metrics_stopped.await;
            })
            .await?,
        ),
    };
    ready(listener.local_addr()?, metrics_addr);
    let check = CheckToken::with_clients(&opts.clients, Some(&opts.enroll), credentials)
        .rate_limited(opts.client_rate, opts.client_rate * 10.0)
        .on_refusal(refusals(st.clone()));
    let svc = CoordinatorServer::new(Service { st })
        .max_decoding_message_size(MAX_MESSAGE_BYTES)
        .max_encoding_message_size(MAX_MESSAGE_BYTES);
    let svc = InterceptedService::new(svc, check);
    builder(opts.tls.as_ref())?
        .add_service(health_svc)
        .add_service(svc)
        .serve_with_incoming_shutdown(
            tokio_stream::wrappers::TcpListenerStream::new(listener),
            shutdown,
        )
        .await?;
    let _ = stop_metrics.send(());
    Ok(())
}

/// What the token check refuses: a revoked worker's call is recorded in the audit trail; a
/// client over its rate and an unknown token are logged only (an unauthenticated caller could
/// otherwise fill the database).
fn refusals(st: Arc<State>) -> crate::auth::OnRefusal {
    Arc::new(move |r: &Refusal| match r {
        Refusal::Revoked { worker } => {
            let ev = Event::new(format!("worker:{worker}"), "refuse-revoked")
                .detail("a call with the revoked worker's credential");
            if let Err(e) = st.store.audit(&ev) {
                tracing::error!(target: "bemcal::audit", "audit trail not written: {e}: {}", ev.text());
            }
        }
        Refusal::RateLimited { client } => crate::audit::emit(
            &Event::new(format!("client:{client}"), "refuse-rate")
                .detail("over its request rate (--client-rate)"),
        ),
        Refusal::Unknown => crate::audit::emit(
            &Event::new("unknown", "refuse-token").detail("no token, or a wrong one"),
        ),
    })
}

/// Every 500 ms: expired leases (their jobs go back to the queue, or fail after
/// `max_failures`), and workers revoked since the last look (`bemcal coordinator
/// revoke-worker` writes to the database): their credentials are refused from then on and
/// their leases given back. The runs that changed are woken.
fn spawn_reaper(reaper: Arc<State>) {
    tokio::spawn(async move {
        let mut seen = std::collections::HashSet::new();
        let mut since = 0;
        loop {
            tokio::time::sleep(Duration::from_millis(500)).await;
            let st = reaper.clone();
            let revoked: Vec<(String, u64)> = st
                .store
                .revoked_since(since)
                .unwrap_or_default()
                .into_iter()
                .filter(|(id, _)| !seen.contains(id))
                .collect();
            for (id, ms) in &revoked {
                st.credentials.revoke(id);
                since = since.max(*ms);
                seen.insert(id.clone());
            }
            let runs = tokio::task::spawn_blocking(move || {
                let mut runs = st.store.expire(st.config.max_failures)?;
                for (id, _) in revoked {
                    runs.extend(st.store.return_leases_of(&id, st.config.max_failures)?);
                }
                Ok::<_, crate::db::DbError>(runs)
            })
            .await
            .ok()
            .and_then(|r| r.ok())
            .unwrap_or_default();
            for r in runs {
                let _ = reaper.kick.send(r);
            }
        }
    });
}

/// Artifacts nothing refers to, past their grace period: collected at start, then hourly.
fn spawn_artifact_collector(collector: Arc<State>) {
    tokio::spawn(async move {
        loop {
            let st = collector.clone();
            let _ = tokio::task::spawn_blocking(move || st.collect_artifacts()).await;
            tokio::time::sleep(Duration::from_secs(3600)).await;
        }
    });
}

/// Standard gRPC health (grpc.health.v1, no token: Kubernetes probes cannot send one):
/// SERVING while the database answers the query behind the Health RPC, checked every 5 s.
fn spawn_health(
    probe: Arc<State>,
) -> tonic_health::pb::health_server::HealthServer<impl tonic_health::pb::health_server::Health> {
    let (health, health_svc) = tonic_health::server::health_reporter();
    tokio::spawn(async move {
        loop {
            let st = probe.clone();
            let ok = tokio::task::spawn_blocking(move || st.store.queue_depth().is_ok())
                .await
                .unwrap_or(false);
            let status = match ok {
                true => tonic_health::ServingStatus::Serving,
                false => tonic_health::ServingStatus::NotServing,
            };
            health.set_service_status("", status).await;
            health
                .set_service_status("bemcal.v1.Coordinator", status)
                .await;
            tokio::time::sleep(Duration::from_secs(5)).await;
        }
    });
    health_svc
}

/// The server, serving TLS with `tls` (PEM certificate and key files) when given.
fn builder(tls: Option<&(PathBuf, PathBuf)>) -> anyhow::Result<Server> {
    let mut builder = Server::builder();
    if let Some((cert, key)) = tls {
        let cert = std::fs::read(cert)
            .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", cert.display()))?;
        let key = std::fs::read(key)
            .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", key.display()))?;
        builder =
            builder.tls_config(ServerTlsConfig::new().identity(Identity::from_pem(cert, key)))?;
    }
    Ok(builder)
}
