//! The Prometheus endpoint (`[service] metrics_listen`): `GET /metrics`
//! answered with the exporter's text, over hyper.
//!
//! Bounded, because anyone who reaches the port can open connections: at
//! most [`MAX_CONNECTIONS`] at once (more are closed at accept and
//! counted), a request's headers within [`HEADER_TIMEOUT`], and a
//! connection's whole life within [`LIFETIME`] (a keep-alive scraper simply
//! reconnects). A failed accept (no descriptors left) is counted, logged at
//! powers of two and retried after a growing pause, never in a spin that
//! logs millions of lines.

use std::convert::Infallible;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use http_body_util::Full;
use hyper::body::{Bytes, Incoming};
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::{TokioIo, TokioTimer};
use metrics_exporter_prometheus::PrometheusHandle;
use tokio::net::TcpListener;

/// Connections served at once.
pub const MAX_CONNECTIONS: usize = 32;
/// Time for a request's headers to arrive (also between two requests).
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(5);
/// The longest a connection is kept.
pub const LIFETIME: Duration = Duration::from_secs(60);

/// What the endpoint turned away, for its own metrics.
#[derive(Default)]
pub struct HttpCounters {
    pub refused: AtomicU64,
    pub accept_errors: AtomicU64,
    pub timed_out: AtomicU64,
}

async fn answer(
    req: Request<Incoming>,
    handle: PrometheusHandle,
) -> Result<Response<Full<Bytes>>, Infallible> {
    let (status, body) = match (req.method(), req.uri().path()) {
        (&Method::GET, "/metrics") => (StatusCode::OK, handle.render()),
        (&Method::GET, _) => (StatusCode::NOT_FOUND, "not found: try /metrics\n".into()),
        _ => (StatusCode::METHOD_NOT_ALLOWED, "GET only\n".into()),
    };
    let mut resp = Response::new(Full::new(Bytes::from(body)));
    *resp.status_mut() = status;
    resp.headers_mut()
        .insert(hyper::header::CONTENT_TYPE, "text/plain; version=0.0.4".parse().expect("ascii"));
    Ok(resp)
}

/// Serves until the task is dropped.
pub async fn serve(listener: TcpListener, handle: PrometheusHandle, counters: Arc<HttpCounters>) {
    let active = Arc::new(AtomicUsize::new(0));
    let mut in_a_row = 0u32;
    loop {
        let sock = match listener.accept().await {
            Ok((sock, _)) => sock,
            Err(e) => {
                let n = counters.accept_errors.fetch_add(1, Ordering::Relaxed) + 1;
                if n.is_power_of_two() {
                    tracing::warn!(errors = n, "metrics endpoint: accept failed: {e}; trying again");
                }
                in_a_row += 1;
                tokio::time::sleep(Duration::from_millis((10u64 << in_a_row.min(7)).min(1000))).await;
                continue;
            }
        };
        in_a_row = 0;
        if active.load(Ordering::Relaxed) >= MAX_CONNECTIONS {
            counters.refused.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        active.fetch_add(1, Ordering::Relaxed);
        let (handle, active, counters) = (handle.clone(), active.clone(), counters.clone());
        tokio::spawn(async move {
            if tokio::time::timeout(LIFETIME, connection(sock, handle)).await.is_err() {
                counters.timed_out.fetch_add(1, Ordering::Relaxed);
            }
            active.fetch_sub(1, Ordering::Relaxed);
        });
    }
}

/// Serves one connection (any byte stream: the fuzz target hands it one in
/// memory) until it ends; malformed requests get hyper's 400 and the end.
pub async fn connection<S>(io: S, handle: PrometheusHandle)
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send + 'static,
{
    let service = hyper::service::service_fn(move |req| answer(req, handle.clone()));
    let _ = hyper::server::conn::http1::Builder::new()
        .timer(TokioTimer::new())
        .header_read_timeout(HEADER_TIMEOUT)
        .max_buf_size(16 * 1024)
        .serve_connection(TokioIo::new(io), service)
        .await;
}
