//! Serving Prometheus metrics: `GET /metrics` over plain HTTP, without a token (Kubernetes and
//! Prometheus scrape this way), shared by the coordinator and the workers. Each process renders
//! its own text; this module only serves it.

use std::future::Future;
use std::net::SocketAddr;

/// The exposition format's content type (OpenMetrics text, as `prometheus-client` encodes).
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// Where `/metrics` is served, as the CLI prints it.
pub fn url(addr: SocketAddr) -> String {
    format!("http://{addr}/metrics")
}

/// Serves `GET /metrics` on `listener` until `shutdown` completes; each request calls `render`,
/// whose error becomes a 503 with its text (the state behind the figures could not be read).
pub async fn serve<F, Fut>(
    listener: tokio::net::TcpListener,
    render: F,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()>
where
    F: Fn() -> Fut + Clone + Send + Sync + 'static,
    Fut: Future<Output = Result<String, String>> + Send + 'static,
{
    use axum::http::{header, StatusCode};
    use axum::response::IntoResponse;

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
    axum::serve(listener, app)
        .with_graceful_shutdown(shutdown)
        .await?;
    Ok(())
}
