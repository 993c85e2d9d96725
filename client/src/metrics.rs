//! Serving Prometheus metrics: `GET /metrics` over plain HTTP, without a token (Kubernetes and
//! Prometheus scrape this way), shared by the coordinator and the workers. Each process renders
//! its own text; this module only serves it.

use std::future::Future;
use std::net::SocketAddr;

/// The exposition format's content type (OpenMetrics text, as `prometheus-client` encodes).
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// Upper bounds of the job-duration histograms, s (the coordinator's and each worker's):
/// EnergyPlus runs take seconds to minutes, training and chain segments minutes to an hour.
pub const DURATION_BUCKETS: [f64; 12] = [
    0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0,
];

/// Where `/metrics` is served, as the CLI prints it.
pub fn url(addr: SocketAddr) -> String {
    format!("http://{addr}/metrics")
}

/// Binds `addr` and serves `GET /metrics` there in the background until `shutdown`
/// completes; returns the bound address (port 0 = ephemeral). Each request calls `render`,
/// whose error becomes a 503 with its text (the state behind the figures could not be read).
pub async fn spawn<F, Fut>(
    addr: SocketAddr,
    render: F,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<SocketAddr>
where
    F: Fn() -> Fut + Clone + Send + Sync + 'static,
    Fut: Future<Output = Result<String, String>> + Send + 'static,
{
    use axum::http::{header, StatusCode};
    use axum::response::IntoResponse;

    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .map_err(|e| anyhow::anyhow!("metrics address {addr}: {e}"))?;
    let bound = listener.local_addr()?;
    let app = axum::Router::new().route(
        "/metrics",
        axum::routing::get(move || {
            let render = render.clone();
            async move {
                match render().await {
                    Ok(text) => (StatusCode::OK, [(header::CONTENT_TYPE, CONTENT_TYPE)], text)
                        .into_response(),
                    Err(e) => (StatusCode::SERVICE_UNAVAILABLE, format!("{e}\n")).into_response(),
                }
            }
        }),
    );
    tokio::spawn(async move {
        let _ = axum::serve(listener, app)
            .with_graceful_shutdown(shutdown)
            .await;
    });
    Ok(bound)
}
