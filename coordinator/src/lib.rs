//! The bemcal coordinator: the gRPC protocol (`proto/bemcal.proto`), the SQLite state of runs,
//! stages, jobs, leases, attempts and artifacts, and the driver that walks each run through the
//! calibration stages, dispatching EnergyPlus runs, training, chain segments and validation to
//! pull-based workers and doing the cheap stages (design, training set, merge, summary) itself.
//!
//! The client side (authenticated channel, artifact upload and download, project bundles) lives
//! here too, so the worker and the CLI share it.

pub mod artifacts;
pub mod auth;
pub mod bundle;
pub mod client;
pub mod db;
pub mod driver;
pub mod portfolio;
pub mod server;
pub mod service;
pub mod states;

/// Generated protocol types, client and server (package `bemcal.v1`).
pub mod proto {
    tonic::include_proto!("bemcal.v1");
}

/// Largest gRPC message either side accepts (artifacts travel in chunks well below it).
pub const MAX_MESSAGE_BYTES: usize = 16 * 1024 * 1024;

/// Size of one artifact chunk.
pub const CHUNK_BYTES: usize = 1024 * 1024;

/// Milliseconds since the Unix epoch (lease expiry survives coordinator restarts).
pub fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// A multi-threaded async runtime for the command-line front end.
pub fn runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
}

/// Completes on SIGTERM or Ctrl-C.
pub async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = term.recv() => {}
                    _ = tokio::signal::ctrl_c() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}
