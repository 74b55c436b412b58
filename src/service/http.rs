//! The operations endpoint of `serve` (`[http] listen`, `--http`):
//! `GET /metrics` (OpenMetrics text, see [`super::telemetry`]) and
//! `GET /healthz` (JSON; 200 when every instance steps and publishes, 503
//! naming the ones that do not). Plain HTTP without authentication: it
//! listens on loopback unless configured otherwise.

use std::net::SocketAddr;
use std::sync::Arc;

use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::IntoResponse;
use axum::routing::get;
use axum::Router;
use prometheus_client::registry::Registry;
use tokio::net::TcpListener;

use super::{telemetry, Context, ServiceError};

/// The OpenMetrics text format's content type.
pub const OPENMETRICS: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// Bind `addr` (before anything else starts, so a taken port fails the
/// start with the address in the error).
pub(super) async fn bind(addr: SocketAddr) -> Result<TcpListener, ServiceError> {
    let listener = TcpListener::bind(addr)
        .await
        .map_err(|source| ServiceError::Http { addr, source })?;
    if !addr.ip().is_loopback() {
        tracing::warn!(%addr, "/metrics and /healthz are served without authentication beyond loopback");
    }
    Ok(listener)
}

struct Shared {
    ctx: Arc<Context>,
    registry: Registry,
}

/// Serve until the task is aborted (at shutdown).
pub(super) async fn serve(listener: TcpListener, ctx: Arc<Context>) {
    let addr = listener.local_addr().ok();
    let shared = Arc::new(Shared {
        registry: telemetry::registry(ctx.clone()),
        ctx,
    });
    let app = Router::new()
        .route("/metrics", get(metrics))
        .route("/healthz", get(healthz))
        .with_state(shared);
    if let Some(a) = addr {
        tracing::info!("operations endpoint: http://{a}/metrics, http://{a}/healthz");
    }
    if let Err(e) = axum::serve(listener, app).await {
        tracing::error!("operations endpoint stopped: {e}");
    }
}

async fn metrics(State(s): State<Arc<Shared>>) -> impl IntoResponse {
    let mut text = String::with_capacity(16 * 1024);
    match prometheus_client::encoding::text::encode(&mut text, &s.registry) {
        Ok(()) => (StatusCode::OK, [(header::CONTENT_TYPE, OPENMETRICS)], text),
        Err(e) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
            format!("encoding the metrics: {e}"),
        ),
    }
}

async fn healthz(State(s): State<Arc<Shared>>) -> impl IntoResponse {
    let h = telemetry::health(&s.ctx);
    let code = if h.status == "ok" {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    (code, axum::Json(h))
}
