//! Stream outputs over TCP: `tcp_server` (subscribers connect, as to
//! readsb's Beast port 30005 or its SBS port 30003) and `tcp_connect` (we
//! push to one address, as mlat-client pushes its results to a Beast input,
//! reconnecting when the connection drops).
//!
//! The tracker thread hands each batch's bytes to a broadcast channel and
//! never waits: every connection has its own task reading the channel and
//! writing its socket. The channel holds [`BACKLOG`] batches; a subscriber
//! that falls further behind, or whose socket takes longer than
//! [`WRITE_TIMEOUT`] to accept a write (a client that never reads), is
//! dropped and counted: it costs itself data, never the core or the others.
//! A pushed connection that falls behind loses the batches it missed
//! (counted) and stays: it is the one destination there is.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use hyper::body::Bytes;
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::broadcast::{self, error::RecvError};
use tokio::task::JoinHandle;

use super::config::{OutputConfig, OutputKind};

/// Batches a subscriber may be behind before it is dropped (the tracker
/// publishes a batch every few milliseconds under load).
pub const BACKLOG: usize = 4096;
/// The longest one write may wait for a subscriber's socket.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// A pushed connection is retried after this, doubling up to [`RETRY_MAX`].
const RETRY_MIN: Duration = Duration::from_millis(500);
const RETRY_MAX: Duration = Duration::from_secs(30);

/// What a stream output did, for the stats line and Prometheus.
#[derive(Debug, Default)]
pub struct StreamCounters {
    /// Subscribers connected now (0 or 1 for `tcp_connect`).
    pub clients: AtomicU64,
    pub bytes: AtomicU64,
    /// Subscribers dropped for falling behind or not reading.
    pub slow_dropped: AtomicU64,
    /// Connections refused over `max_clients`.
    pub refused: AtomicU64,
    /// Batches a pushed connection missed (behind, or not connected).
    pub missed: AtomicU64,
    /// Failed connects and accepts, and broken connections.
    pub errors: AtomicU64,
}

/// One running stream output; stopping or dropping it stops its listener
/// or connector (its subscribers' tasks end when the channel closes).
pub struct Stream {
    pub cfg: OutputConfig,
    tx: broadcast::Sender<Bytes>,
    pub counters: Arc<StreamCounters>,
    task: Mutex<Option<JoinHandle<()>>>,
}

impl Drop for Stream {
    fn drop(&mut self) {
        if let Some(t) = self.task.get_mut().ok().and_then(Option::take) {
            t.abort();
        }
    }
}

impl Stream {
    /// Binds (`tcp_server`) or starts connecting (`tcp_connect`).
    pub async fn start(cfg: &OutputConfig) -> std::io::Result<Stream> {
        let addr = cfg.address.ok_or_else(|| std::io::Error::other("no address"))?;
        let (tx, _) = broadcast::channel(BACKLOG);
        let counters = Arc::new(StreamCounters::default());
        let task = match cfg.kind {
            OutputKind::TcpServer => {
                let listener = TcpListener::bind(addr).await?;
                tokio::spawn(serve(listener, tx.clone(), counters.clone(), cfg.max_clients))
            }
            _ => tokio::spawn(push(addr, tx.clone(), counters.clone())),
        };
        Ok(Stream { cfg: cfg.clone(), tx, counters, task: Mutex::new(Some(task)) })
    }

    /// Stops the listener or connector and waits until it is gone, so that
    /// its port is free again (a reload that changes an output on the same
    /// port binds it anew).
    pub async fn stop(&self) {
        let task = self.task.lock().ok().and_then(|mut t| t.take());
        if let Some(t) = task {
            t.abort();
            let _ = t.await;
        }
    }

    /// Hands a batch to every subscriber; never waits. With no subscriber
    /// it goes nowhere (a pushed connection that is down counts it missed).
    pub fn send(&self, bytes: Bytes) {
        if self.tx.send(bytes).is_err() && self.cfg.kind == OutputKind::TcpConnect {
            self.counters.missed.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Starts every stream output of `outputs`; `running` are those started
/// before (a reload): reused where their configuration is unchanged, the
/// others stopped first. One that cannot bind is returned as an error with
/// its number.
pub async fn start_all(
    outputs: &[OutputConfig],
    running: &[Arc<Stream>],
) -> (Vec<Arc<Stream>>, Vec<(usize, std::io::Error)>) {
    let (mut streams, mut failed) = (Vec::new(), Vec::new());
    let kept: Vec<&Arc<Stream>> = running.iter().filter(|s| outputs.contains(&s.cfg)).collect();
    for s in running.iter().filter(|s| !outputs.contains(&s.cfg)) {
        s.stop().await;
    }
    for (i, cfg) in outputs.iter().enumerate() {
        if !matches!(cfg.kind, OutputKind::TcpServer | OutputKind::TcpConnect) {
            continue;
        }
        if let Some(s) = kept.iter().find(|s| s.cfg == *cfg) {
            streams.push(Arc::clone(s));
            continue;
        }
        match Stream::start(cfg).await {
            Ok(s) => streams.push(Arc::new(s)),
            Err(e) => failed.push((i + 1, e)),
        }
    }
    (streams, failed)
}

async fn serve(listener: TcpListener, tx: broadcast::Sender<Bytes>, c: Arc<StreamCounters>, max: usize) {
    let mut in_a_row = 0u32;
    loop {
        let sock = match listener.accept().await {
            Ok((sock, _)) => sock,
            Err(e) => {
                super::http::accept_failed(&c.errors, &mut in_a_row, "output", &e).await;
                continue;
            }
        };
        in_a_row = 0;
        if c.clients.load(Ordering::Relaxed) >= max as u64 {
            c.refused.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        c.clients.fetch_add(1, Ordering::Relaxed);
        let (rx, c) = (tx.subscribe(), c.clone());
        tokio::spawn(async move {
            let _ = sock.set_nodelay(true);
            if feed(sock, rx, &c, true).await == End::Slow {
                c.slow_dropped.fetch_add(1, Ordering::Relaxed);
            }
            c.clients.fetch_sub(1, Ordering::Relaxed);
        });
    }
}

async fn push(addr: SocketAddr, tx: broadcast::Sender<Bytes>, c: Arc<StreamCounters>) {
    let mut pause = RETRY_MIN;
    let mut logged_down = false;
    loop {
        match tokio::time::timeout(WRITE_TIMEOUT, TcpStream::connect(addr)).await {
            Ok(Ok(sock)) => {
                tracing::info!(address = %addr, "output: connected");
                (pause, logged_down) = (RETRY_MIN, false);
                let _ = sock.set_nodelay(true);
                c.clients.store(1, Ordering::Relaxed);
                let end = feed(sock, tx.subscribe(), &c, false).await;
                c.clients.store(0, Ordering::Relaxed);
                if end == End::Closed {
                    return;
                }
                c.errors.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(address = %addr, "output: connection lost; reconnecting");
            }
            Ok(Err(_)) | Err(_) => {
                c.errors.fetch_add(1, Ordering::Relaxed);
                if !logged_down {
                    tracing::warn!(address = %addr, "output: cannot connect; retrying every {}s at most", RETRY_MAX.as_secs());
                    logged_down = true;
                }
            }
        }
        tokio::time::sleep(pause).await;
        pause = (pause * 2).min(RETRY_MAX);
    }
}

/// Why a connection's feed ended.
#[derive(Debug, PartialEq, Eq)]
enum End {
    /// The subscriber fell behind or stopped reading.
    Slow,
    /// The peer closed, or a write failed.
    Broken,
    /// The output was removed.
    Closed,
}

/// Writes what the channel brings until the connection or the output
/// ends. A subscriber that falls behind is dropped (`drop_behind`); the
/// pushed connection counts the batches it missed and goes on.
async fn feed(
    mut sock: TcpStream,
    mut rx: broadcast::Receiver<Bytes>,
    c: &StreamCounters,
    drop_behind: bool,
) -> End {
    loop {
        let bytes = match rx.recv().await {
            Ok(b) => b,
            Err(RecvError::Closed) => return End::Closed,
            Err(RecvError::Lagged(_)) if drop_behind => return End::Slow,
            Err(RecvError::Lagged(n)) => {
                c.missed.fetch_add(n, Ordering::Relaxed);
                continue;
            }
        };
        match tokio::time::timeout(WRITE_TIMEOUT, sock.write_all(&bytes)).await {
            Ok(Ok(())) => {
                c.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
            }
            Ok(Err(_)) => return End::Broken,
            Err(_) => return End::Slow,
        }
    }
}

#[cfg(test)]
mod tests {
    use tokio::io::AsyncReadExt;

    use super::*;
    use crate::live::config::OutputFormat;

    fn server_cfg(max_clients: usize) -> OutputConfig {
        OutputConfig {
            kind: OutputKind::TcpServer,
            address: Some("127.0.0.1:0".parse().unwrap()),
            format: OutputFormat::Sbs,
            multicast_ttl: 1,
            multicast_interface: None,
            max_clients,
            forward_frames: false,
        }
    }

    /// A subscriber that never reads is dropped and counted; one that reads
    /// gets every byte; one over `max_clients` is refused; and the sender
    /// never waits for any of them.
    #[tokio::test]
    async fn a_subscriber_that_never_reads_is_dropped_and_the_others_served() {
        // Port 0 to bind: then the listener's own address to connect to.
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let (tx, _) = broadcast::channel(BACKLOG);
        let counters = Arc::new(StreamCounters::default());
        let task = tokio::spawn(serve(listener, tx.clone(), counters.clone(), 2));
        let stream =
            Stream { cfg: server_cfg(2), tx, counters: counters.clone(), task: Mutex::new(Some(task)) };

        let sleeper = {
            let s = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
            s.set_recv_buffer_size(4096).unwrap();
            s.connect(&addr.into()).unwrap();
            s
        };
        let mut honest = TcpStream::connect(addr).await.unwrap();
        while counters.clients.load(Ordering::Relaxed) < 2 {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        let mut third = TcpStream::connect(addr).await.unwrap();
        let mut nothing = [0u8; 1];
        assert_eq!(third.read(&mut nothing).await.unwrap(), 0, "over max_clients: closed at accept");
        assert_eq!(counters.refused.load(Ordering::Relaxed), 1);

        // 64 MiB in 16 KiB batches, far beyond what the sleeper's socket
        // buffers hold, paced so that the honest reader keeps up.
        let (batches, size) = (4096usize, 16 * 1024);
        let reader = tokio::spawn(async move {
            let (mut got, mut buf) = (0usize, vec![0u8; 1 << 16]);
            while got < batches * size {
                match honest.read(&mut buf).await {
                    Ok(0) | Err(_) => break,
                    Ok(n) => got += n,
                }
            }
            got
        });
        let t0 = std::time::Instant::now();
        for i in 0..batches {
            stream.send(Bytes::from(vec![(i % 251) as u8; size]));
            if i % 64 == 0 {
                tokio::time::sleep(Duration::from_millis(1)).await;
            }
        }
        let sending = t0.elapsed();
        assert_eq!(reader.await.unwrap(), batches * size, "the honest subscriber lost bytes");
        // The sleeper's write times out and it is dropped.
        let t0 = std::time::Instant::now();
        while counters.slow_dropped.load(Ordering::Relaxed) == 0 {
            assert!(t0.elapsed() < WRITE_TIMEOUT * 3, "the sleeper was never dropped");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        assert_eq!(counters.clients.load(Ordering::Relaxed), 1, "{counters:?}");
        // Sending 64 MiB took no write's time: it never waited for a socket.
        assert!(sending < WRITE_TIMEOUT, "{sending:?}");
        drop(sleeper);
        stream.stop().await;
    }
}
