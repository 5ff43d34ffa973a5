//! Input tasks: Beast TCP client (reconnecting with capped exponential
//! backoff and jitter), Beast TCP server (see [`server`](super::server)),
//! and UDP datagrams of Beast or AVR (large receive buffer, several
//! datagrams per system call, the kernel's drops counted).
//! Arrival times are the kernel's receive stamps, TCP's too. A TCP
//! connection silent for the input's idle timeout is closed; a failed
//! accept or read is counted and retried, never the end of an input.
//!
//! Every task turns bytes into frames with the feed parsers and hands them
//! to the core, a datagram's or a read's frames as one message, through a
//! queue bounded in frames, without waiting: a batch that does not fit is
//! dropped and its frames counted, so a slow core never stalls a socket,
//! and each receiver's rate limit and fair share of the queue apply
//! whatever input it comes through (see [`admit`](super::admit)).

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::Arc;
use std::time::Duration;

use rand::Rng;
use socket2::{Domain, Protocol, Socket, Type};
use tokio::io::Interest;
use tokio::net::{TcpListener, TcpStream, UdpSocket};

use super::admit::Refusal;
use super::config::{InputConfig, InputKind};
pub use super::registry::{Registry, RxCounters};
use super::ToCore;
use crate::feed::{parser_for, FeedEvent, FeedStats, FrameParser, InputFormat, RawFrame};

/// The frames of one datagram or one read (they arrived together, at
/// `arrival`) to the core as one message: one queue operation and at most
/// one wake-up of the core thread for all of them, not one per frame (at
/// 1 M frames/s the per-frame sends were the largest item of the input
/// thread's own time). First the receiver's rate limit, then its fair share
/// of the queue (see [`admit`](super::admit)); the queue is bounded in
/// frames, not messages: a batch that does not fit is dropped whole and
/// every frame of it counted.
pub(super) fn forward(
    tx: &SyncSender<ToCore>,
    reg: &Registry,
    c: &Arc<RxCounters>,
    rx: usize,
    arrival: f64,
    mut frames: Vec<RawFrame>,
) {
    let n = frames.len();
    if n == 0 {
        return;
    }
    c.frames.fetch_add(n as u64, Ordering::Relaxed);
    let admitted = c.admission.within_rate(n, arrival);
    if admitted < n {
        c.throttled.fetch_add((n - admitted) as u64, Ordering::Relaxed);
        frames.truncate(admitted);
    }
    let n = admitted;
    if n == 0 {
        return;
    }
    let before = reg.queued.fetch_add(n, Ordering::Relaxed);
    let fits = c.admission.fits(n, before, reg.queue_frames, reg.receiver_count.load(Ordering::Relaxed));
    let refused = match fits {
        Err(why) => Some(why),
        Ok(()) => {
            c.admission.queued.fetch_add(n, Ordering::Relaxed);
            match tx.try_send(ToCore::Frames { rx, arrival, frames, from: c.clone() }) {
                Ok(()) => None,
                Err(TrySendError::Full(_)) => {
                    c.admission.queued.fetch_sub(n, Ordering::Relaxed);
                    Some(Refusal::Full)
                }
                Err(TrySendError::Disconnected(_)) => return,
            }
        }
    };
    if let Some(why) = refused {
        reg.queued.fetch_sub(n, Ordering::Relaxed);
        if why == Refusal::Share {
            c.over_share.fetch_add(n as u64, Ordering::Relaxed);
        } else {
            c.queue_drops.fetch_add(n as u64, Ordering::Relaxed);
            reg.queue_drops.fetch_add(n as u64, Ordering::Relaxed);
        }
    }
}

/// Adds to a receiver's counters what its parser counted between two of
/// its snapshots: broken frames, garbage bytes, heartbeats.
pub(super) fn count_parsed(c: &RxCounters, before: &FeedStats, after: &FeedStats) {
    c.input_errors.fetch_add(after.input_errors() - before.input_errors(), Ordering::Relaxed);
    c.garbage_bytes.fetch_add(after.garbage_bytes - before.garbage_bytes, Ordering::Relaxed);
    c.heartbeats.fetch_add(after.heartbeats - before.heartbeats, Ordering::Relaxed);
}

/// The frames a parser made of a read's bytes or a whole datagram, its
/// errors, garbage and heartbeats counted.
fn frames_of(parser: &mut dyn FrameParser, bytes: &[u8], datagram: bool, c: &RxCounters) -> Vec<RawFrame> {
    let mut frames = Vec::new();
    let before = *parser.stats();
    let mut sink = |ev| {
        if let FeedEvent::Frame(f) = ev {
            frames.push(f)
        }
    };
    if datagram {
        parser.push_datagram(bytes, &mut sink);
    } else {
        parser.push(bytes, &mut sink);
    }
    count_parsed(c, &before, parser.stats());
    frames
}

/// Reads a Beast stream until it ends, or brings nothing for the input's
/// `idle_timeout_s`; returns why.
pub(super) async fn stream(
    sock: TcpStream,
    mut parser: Box<dyn FrameParser + Send>,
    input: &InputConfig,
    tx: &SyncSender<ToCore>,
    reg: &Registry,
    rx: usize,
) -> std::io::Result<()> {
    // Keepalive probes find a peer that is gone within about a minute even
    // when the idle timeout is off.
    let keepalive = socket2::TcpKeepalive::new()
        .with_time(Duration::from_secs(30))
        .with_interval(Duration::from_secs(10))
        .with_retries(3);
    let _ = socket2::SockRef::from(&sock).set_tcp_keepalive(&keepalive);
    // A read's arrival is when the kernel received its newest bytes, as for
    // datagrams (see `stamp`); without the option, the clock after the read.
    let _ = super::stamp::enable(&sock);
    let idle = (input.idle_timeout_s > 0.0).then(|| Duration::from_secs_f64(input.idle_timeout_s));
    let c = reg.counters(rx);
    let mut buf = vec![0u8; 64 * 1024];
    loop {
        let read = sock.async_io(Interest::READABLE, || super::stamp::recv(&sock, &mut buf));
        let got = match idle {
            Some(idle) => tokio::time::timeout(idle, read).await.unwrap_or_else(|_| {
                c.idle_timeouts.fetch_add(1, Ordering::Relaxed);
                Err(std::io::Error::new(
                    std::io::ErrorKind::TimedOut,
                    format!("nothing received for {} s", input.idle_timeout_s),
                ))
            }),
            None => read.await,
        };
        let (n, arrival) = match got {
            Ok((n, _, arrival)) if n > 0 => (n, arrival),
            end => {
                // The end, by either side: a frame it cut off is an error.
                let before = *parser.stats();
                parser.finish(&mut |_| {});
                count_parsed(&c, &before, parser.stats());
                return end.map(drop);
            }
        };
        c.bytes.fetch_add(n as u64, Ordering::Relaxed);
        let frames = frames_of(parser.as_mut(), &buf[..n], false, &c);
        forward(tx, reg, &c, rx, arrival, frames);
    }
}

/// An input's socket, bound before its task starts: a daemon that cannot
/// have its ports says so at start-up (and fails there) instead of running
/// deaf to an input; a TCP client has nothing to bind.
pub enum Bound {
    Client,
    Listener(TcpListener),
    Udp(UdpSocket),
}

/// Binds one input's socket.
pub async fn bind(input: &InputConfig) -> std::io::Result<Bound> {
    Ok(match input.kind {
        InputKind::BeastTcpClient => Bound::Client,
        InputKind::BeastTcpServer => Bound::Listener(TcpListener::bind(input.address).await?),
        InputKind::Udp => Bound::Udp(bind_udp(input)?),
    })
}

/// Binds every input, or says which one cannot be bound and why.
pub async fn bind_all(inputs: &[InputConfig]) -> Result<Vec<Bound>, String> {
    let mut bound = Vec::with_capacity(inputs.len());
    for (i, input) in inputs.iter().enumerate() {
        let b = bind(input).await.map_err(|e| {
            format!("input {} ({}) cannot bind {}: {e}", i + 1, input.kind.name(), input.address)
        })?;
        bound.push(b);
    }
    Ok(bound)
}

/// Spawns the task of one input on its bound socket.
/// It ends when `shutdown` fires (a TCP server's connections with it).
pub fn spawn(
    input: InputConfig,
    bound: Bound,
    tx: SyncSender<ToCore>,
    reg: Arc<Registry>,
    shutdown: &super::shutdown::Shutdown,
) -> tokio::task::JoinHandle<()> {
    shutdown.spawn(async move {
        let r = match bound {
            Bound::Client => tcp_client(&input, &tx, &reg).await,
            Bound::Listener(l) => super::server::tcp_server(&input, l, tx, reg.clone()).await,
            Bound::Udp(sock) => udp(&input, sock, &tx, &reg).await,
        };
        if let Err(e) = r {
            tracing::error!(address = %input.address, "input stopped: {e}");
        }
    })
}

/// A connection that lasted this long (s) was a success: the client's
/// backoff starts again from its shortest.
const LASTING_S: u64 = 10;

async fn tcp_client(input: &InputConfig, tx: &SyncSender<ToCore>, reg: &Registry) -> std::io::Result<()> {
    let id = input.receiver.as_deref().unwrap_or_default();
    let Some(rx) = reg.index_of(id) else {
        return Err(std::io::Error::other(format!("receiver {id} unknown")));
    };
    let c = reg.counters(rx);
    let mut failures = 0u32;
    loop {
        match tokio::time::timeout(Duration::from_secs(5), TcpStream::connect(input.address)).await {
            Ok(Ok(sock)) => {
                c.connects.fetch_add(1, Ordering::Relaxed);
                let since = std::time::Instant::now();
                if let Some(held) = c.connection_log.pass(super::unix_now()) {
                    tracing::info!(receiver = id, address = %input.address, held_back = held, "connected");
                }
                let r = stream(sock, parser_for(InputFormat::Beast), input, tx, reg, rx).await;
                c.disconnects.fetch_add(1, Ordering::Relaxed);
                // A peer that accepts and closes at once is a failure too:
                // backing off only from failed connects, a client would
                // reconnect to it twice a second for ever.
                failures = if since.elapsed() >= Duration::from_secs(LASTING_S) { 0 } else { failures + 1 };
                if let Some(held) = c.connection_log.pass(super::unix_now()) {
                    tracing::warn!(
                        receiver = id,
                        held_back = held,
                        "disconnected: {}",
                        r.err().map_or("end of stream".into(), |e| e.to_string())
                    );
                }
            }
            Ok(Err(e)) => {
                if failures == 0 {
                    tracing::warn!(receiver = id, address = %input.address, "cannot connect: {e}");
                }
                failures += 1;
            }
            Err(_) => failures += 1,
        }
        // Capped exponential backoff with +-25% jitter.
        let base = (0.5 * 2f64.powi(failures.min(6) as i32)).min(30.0);
        let wait = base * rand::thread_rng().gen_range(0.75..1.25);
        tokio::time::sleep(Duration::from_secs_f64(wait)).await;
    }
}

/// Datagrams taken from the socket per system call, at most.
const DATAGRAMS_PER_READ: usize = 32;

fn bind_udp(input: &InputConfig) -> std::io::Result<UdpSocket> {
    let domain = if input.address.is_ipv4() { Domain::IPV4 } else { Domain::IPV6 };
    let s = Socket::new(domain, Type::DGRAM, Some(Protocol::UDP))?;
    // Bursts of many receivers at once: a large buffer (the kernel caps it).
    let _ = s.set_recv_buffer_size(8 << 20);
    // No SO_REUSEADDR: with it a second daemon on the same port would bind
    // too and silently take part of the datagrams. A SIGHUP waits for the
    // old input to close before binding anew.
    s.bind(&input.address.into())?;
    s.set_nonblocking(true)?;
    if let Err(e) = super::stamp::enable(&s) {
        tracing::warn!(input = %input.address, "no kernel receive timestamps ({e}): arrival read from the clock");
    }
    if let Err(e) = super::stamp::count_drops(&s) {
        tracing::warn!(input = %input.address, "the kernel's drops on this socket cannot be counted ({e})");
    }
    UdpSocket::from_std(s.into())
}

async fn udp(
    input: &InputConfig,
    sock: UdpSocket,
    tx: &SyncSender<ToCore>,
    reg: &Registry,
) -> std::io::Result<()> {
    let format = input.format;
    let fixed = input.receiver.as_deref().and_then(|id| reg.index_of(id));
    let mut parsers: HashMap<usize, Box<dyn FrameParser + Send>> = HashMap::new();
    // Known senders' receiver, counters and rate: a datagram costs no scan
    // of the registry and no lock (with a clock reading per frame, a seventh
    // of this task's time with 200 receivers at 1 M frames/s). Only known
    // senders are kept, so it is bounded by the receivers; refreshed when
    // the registry changes.
    let mut senders: HashMap<IpAddr, (usize, Arc<RxCounters>)> = HashMap::new();
    let mut generation = reg.generation.load(Ordering::Relaxed);
    // Any datagram fits (65,507 bytes is UDP's most over IPv4).
    let mut datagrams = super::stamp::Datagrams::new(DATAGRAMS_PER_READ, 65_536);
    let mut in_a_row = 0;
    // The socket's count of kernel drops as last seen (it counts from 0 when bound).
    let mut kernel_drops = 0u32;
    loop {
        let read = match sock.async_io(Interest::READABLE, || datagrams.recv(&sock)).await {
            Ok(n) => n,
            Err(e) => {
                reg.socket_error(input, "datagram read", e, &mut in_a_row).await;
                continue;
            }
        };
        in_a_row = 0;
        if let Some(n) = datagrams.kernel_drops() {
            let new = n.wrapping_sub(kernel_drops);
            kernel_drops = n;
            reg.kernel_drops.fetch_add(new as u64, Ordering::Relaxed);
        }
        let now_generation = reg.generation.load(Ordering::Relaxed);
        if now_generation != generation {
            senders.clear();
            generation = now_generation;
        }
        for i in 0..read {
            let (bytes, peer, arrival) = datagrams.get(i);
            // A UDP datagram always has a sender; one without could not be
            // attributed to a receiver anyway.
            let Some(peer) = peer else { continue };
            // A socket of one receiver takes any sender: keyed by that
            // receiver, not by address, or a spray of source addresses
            // would grow it.
            let key = if fixed.is_some() { IpAddr::from([0, 0, 0, 0]) } else { peer.ip() };
            let sender = match senders.get(&key) {
                Some(s) => Some(s.clone()),
                None => fixed.or_else(|| reg.by_source(peer.ip(), input)).map(|rx| {
                    let s = (rx, reg.counters(rx));
                    senders.insert(key, s.clone());
                    s
                }),
            };
            let Some((rx, c)) = sender else {
                let k = reg.unknown_senders.fetch_add(1, Ordering::Relaxed) + 1;
                if k.is_power_of_two() {
                    tracing::warn!(peer = %peer, refused = k, "datagram from an unknown sender dropped");
                }
                continue;
            };
            c.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
            let parser = parsers.entry(rx).or_insert_with(|| parser_for(format));
            let frames = frames_of(parser.as_mut(), bytes, true, &c);
            forward(tx, reg, &c, rx, arrival, frames);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::live::config::ReceiverConfig;
    use std::sync::mpsc::sync_channel;

    use crate::feed::test_frames as frames;

    #[test]
    fn the_queue_is_bounded_in_frames_and_a_batch_that_does_not_fit_is_counted_whole() {
        let reg = Registry { queue_frames: 10, ..Default::default() };
        let c = Arc::new(RxCounters::default());
        // Room for many messages: the bound that bites is the frames'.
        let (tx, rx) = sync_channel(100);
        forward(&tx, &reg, &c, 3, 1.0, frames(6));
        forward(&tx, &reg, &c, 3, 2.0, frames(5));
        forward(&tx, &reg, &c, 3, 3.0, frames(4));
        assert_eq!(reg.queued.load(Ordering::Relaxed), 10);
        assert_eq!(c.frames.load(Ordering::Relaxed), 15);
        assert_eq!(c.queue_drops.load(Ordering::Relaxed), 5);
        assert_eq!(reg.queue_drops.load(Ordering::Relaxed), 5);
        let got: Vec<(usize, f64, usize)> = rx
            .try_iter()
            .map(|m| match m {
                ToCore::Frames { rx, arrival, frames, .. } => (rx, arrival, frames.len()),
                _ => panic!("not frames"),
            })
            .collect();
        assert_eq!(got, vec![(3, 1.0, 6), (3, 3.0, 4)]);
        // A full channel drops too, and gives the frames' room back.
        let (tx, _rx) = sync_channel(1);
        let reg = Registry { queue_frames: 100, ..Default::default() };
        forward(&tx, &reg, &c, 0, 4.0, frames(2));
        forward(&tx, &reg, &c, 0, 5.0, frames(3));
        assert_eq!(reg.queued.load(Ordering::Relaxed), 2);
        assert_eq!(reg.queue_drops.load(Ordering::Relaxed), 3);
    }

    /// A receiver flooding a core that does not keep up takes no more than
    /// half the queue and its share; the others' frames all get in, and the
    /// flood's are counted as over its share, not as queue drops.
    #[test]
    fn a_flooding_receiver_cannot_crowd_the_others_out_of_the_queue() {
        let reg = Registry { queue_frames: 1000, ..Default::default() };
        for id in ["flood", "a", "b", "c"] {
            reg.add(ReceiverConfig::for_test(id, None));
        }
        let (tx, core) = sync_channel(100_000);
        let (flood, a) = (reg.counters(0), reg.counters(1));
        // The core takes 50 frames per round; the flood brings 500, `a` 10.
        for round in 0..200 {
            let t = round as f64 * 0.01;
            forward(&tx, &reg, &flood, 0, t, frames(100));
            forward(&tx, &reg, &flood, 0, t, frames(100));
            forward(&tx, &reg, &flood, 0, t, frames(100));
            forward(&tx, &reg, &flood, 0, t, frames(100));
            forward(&tx, &reg, &flood, 0, t, frames(100));
            forward(&tx, &reg, &a, 1, t, frames(10));
            let mut taken = 0;
            while taken < 50 {
                let Ok(ToCore::Frames { frames, from, .. }) = core.try_recv() else { break };
                taken += frames.len();
                reg.queued.fetch_sub(frames.len(), Ordering::Relaxed);
                from.admission.queued.fetch_sub(frames.len(), Ordering::Relaxed);
            }
            assert!(flood.admission.queued.load(Ordering::Relaxed) <= 500 + 250);
        }
        assert_eq!(a.frames.load(Ordering::Relaxed), 2000);
        assert_eq!(a.queue_drops.load(Ordering::Relaxed) + a.over_share.load(Ordering::Relaxed), 0);
        // What the core took (at most a message past 50 a round) and what
        // may still wait were all it admitted of the flood's 100,000.
        assert!(flood.over_share.load(Ordering::Relaxed) >= 100_000 - 200 * 100 - 750);
        assert_eq!(reg.queue_drops.load(Ordering::Relaxed), 0);
    }
}
