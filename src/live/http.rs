//! The service's HTTP: `[http] listen` serves the live map at `/` (its
//! files embedded, see [`super::map_assets`]), its data under `/data/`
//! (readsb's `aircraft.json` and `receiver.json`, fuse1090's
//! `receivers.json` and the map's `map.json`, see [`super::web`]) and
//! `/metrics`; `[service] metrics_listen` serves `/metrics` alone. Both
//! over hyper, by the same code.
//!
//! Bounded, because anyone who reaches the port can open connections: at
//! most `max_connections` at once (more are closed at accept and counted),
//! a request's headers within [`HEADER_TIMEOUT`] and 16 KiB, and a
//! connection's whole life within [`LIFETIME`] (a browser or a scraper
//! simply reconnects). A failed accept (no descriptors left) is counted,
//! logged at powers of two and retried after a growing pause, never in a
//! spin that logs millions of lines. A request never reaches the core: it is
//! answered from bytes the tracker thread rendered.

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

use super::map_assets;
use super::web::{Document, WebData};

/// Connections the Prometheus endpoint serves at once.
pub const METRICS_CONNECTIONS: usize = 32;
/// Time for a request's headers to arrive (also between two requests).
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(5);
/// The longest a connection is kept.
pub const LIFETIME: Duration = Duration::from_secs(60);

/// What a server answers: `/metrics` when it has the exporter's handle,
/// `/data/*` when it has the rendered documents.
#[derive(Clone, Default)]
pub struct Routes {
    pub metrics: Option<PrometheusHandle>,
    pub web: Option<Arc<WebData>>,
}

/// What a server turned away, for its own metrics.
#[derive(Default)]
pub struct HttpCounters {
    pub refused: AtomicU64,
    pub accept_errors: AtomicU64,
    pub timed_out: AtomicU64,
}

async fn answer(req: Request<Incoming>, routes: Arc<Routes>) -> Result<Response<Full<Bytes>>, Infallible> {
    const JSON: &str = "application/json";
    const TEXT: &str = "text/plain; charset=utf-8";
    let document = |d| routes.web.as_ref().map(|w| (StatusCode::OK, JSON, w.get(d)));
    let found = match (req.method(), req.uri().path()) {
        (&Method::GET, "/metrics") => routes
            .metrics
            .as_ref()
            .map(|h| (StatusCode::OK, "text/plain; version=0.0.4", Bytes::from(h.render()))),
        (&Method::GET, "/data/aircraft.json") => document(Document::Aircraft),
        (&Method::GET, "/data/receivers.json") => document(Document::Receivers),
        (&Method::GET, "/data/receiver.json") => document(Document::Receiver),
        (&Method::GET, "/data/map.json") => document(Document::Map),
        (&Method::GET, path) if routes.web.is_some() => {
            map_assets::find(path).map(|a| (StatusCode::OK, a.content_type, Bytes::from_static(a.bytes)))
        }
        (&Method::GET, _) => None,
        _ => Some((StatusCode::METHOD_NOT_ALLOWED, TEXT, Bytes::from_static(b"GET only\n"))),
    };
    let (status, kind, body) =
        found.unwrap_or((StatusCode::NOT_FOUND, TEXT, Bytes::from_static(b"not found\n")));
    let mut resp = Response::new(Full::new(body));
    *resp.status_mut() = status;
    let headers = resp.headers_mut();
    headers.insert(hyper::header::CONTENT_TYPE, hyper::header::HeaderValue::from_static(kind));
    // Every document is the state of the moment: never served from a cache.
    headers.insert(hyper::header::CACHE_CONTROL, hyper::header::HeaderValue::from_static("no-cache"));
    Ok(resp)
}

/// Serves until the task is dropped.
pub async fn serve(
    listener: TcpListener,
    routes: Routes,
    counters: Arc<HttpCounters>,
    max_connections: usize,
) {
    let routes = Arc::new(routes);
    let active = Arc::new(AtomicUsize::new(0));
    let mut in_a_row = 0u32;
    loop {
        let sock = match listener.accept().await {
            Ok((sock, _)) => sock,
            Err(e) => {
                accept_failed(&counters.accept_errors, &mut in_a_row, "HTTP", &e).await;
                continue;
            }
        };
        in_a_row = 0;
        if active.load(Ordering::Relaxed) >= max_connections {
            counters.refused.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        active.fetch_add(1, Ordering::Relaxed);
        let (routes, active, counters) = (routes.clone(), active.clone(), counters.clone());
        tokio::spawn(async move {
            if tokio::time::timeout(LIFETIME, connection(sock, routes)).await.is_err() {
                counters.timed_out.fetch_add(1, Ordering::Relaxed);
            }
            active.fetch_sub(1, Ordering::Relaxed);
        });
    }
}

/// After a failed accept (out of descriptors, most likely): counted, said
/// at powers of two, and a pause that grows with the failures in a row, so
/// that a listener never spins logging millions of lines.
pub(super) async fn accept_failed(errors: &AtomicU64, in_a_row: &mut u32, what: &str, e: &std::io::Error) {
    let n = errors.fetch_add(1, Ordering::Relaxed) + 1;
    if n.is_power_of_two() {
        tracing::warn!(errors = n, "{what}: accept failed: {e}; trying again");
    }
    *in_a_row += 1;
    tokio::time::sleep(Duration::from_millis((10u64 << (*in_a_row).min(7)).min(1000))).await;
}

/// Serves one connection (any byte stream: the fuzz target hands it one in
/// memory) until it ends; malformed requests get hyper's 400 and the end.
pub async fn connection<S>(io: S, routes: Arc<Routes>)
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send + 'static,
{
    let service = hyper::service::service_fn(move |req| answer(req, routes.clone()));
    let _ = hyper::server::conn::http1::Builder::new()
        .timer(TokioTimer::new())
        .header_read_timeout(HEADER_TIMEOUT)
        .max_buf_size(16 * 1024)
        .serve_connection(TokioIo::new(io), service)
        .await;
}
