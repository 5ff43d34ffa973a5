//! Input tasks: Beast TCP client (reconnecting with capped exponential
//! backoff and jitter), Beast TCP server (senders identified by their
//! configured source address, or by readsb's receiver id or UUID frame
//! within their first seconds, unknown ones refused and counted, one
//! connection per receiver), and UDP datagrams of Beast or AVR (large
//! receive buffer, several datagrams per system call, per-receiver rate
//! limit).
//! Arrival times are the kernel's receive stamps, TCP's too. A TCP
//! connection silent for the input's idle timeout is closed; a failed
//! accept or read is counted and retried, never the end of an input.
//!
//! Every task turns bytes into frames with the feed parsers and hands them
//! to the core, a datagram's or a read's frames as one message, through a
//! queue bounded in frames, without waiting: a batch that does not fit is
//! dropped and its frames counted, so a slow core never stalls a socket and
//! one flooding receiver cannot starve the others beyond its rate limit.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Duration;

use rand::Rng;
use socket2::{Domain, Protocol, Socket, Type};
use tokio::io::Interest;
use tokio::net::{TcpListener, TcpStream, UdpSocket};

use super::admit::{Admission, Refusal};
use super::config::{BeastId, InputConfig, InputKind, ReceiverConfig};
use super::loglimit::LogGate;
use super::ToCore;
use crate::feed::{parser_for, FeedEvent, FrameParser, InputFormat, RawFrame};

/// Per-receiver counters, shared with the stats line and the metrics, and
/// the receiver's admission state. `frames` counts every frame received
/// from it; `throttled` (over its `max_rate`), `over_share` (over its fair
/// share of a busy queue) and `queue_drops` (queue full) are the parts of
/// them not handed to the core.
#[derive(Debug, Default)]
pub struct RxCounters {
    pub frames: AtomicU64,
    pub bytes: AtomicU64,
    /// Frames broken or cut off (at a datagram's end, or a connection's).
    pub input_errors: AtomicU64,
    /// Bytes between frames that belonged to none.
    pub garbage_bytes: AtomicU64,
    /// Keep-alive frames of an idle Beast port: neither frames nor errors.
    pub heartbeats: AtomicU64,
    pub queue_drops: AtomicU64,
    pub throttled: AtomicU64,
    pub over_share: AtomicU64,
    pub admission: Admission,
    /// Its connect and disconnect lines (a reconnect storm is one line in ten seconds).
    pub connection_log: LogGate,
    pub connects: AtomicU64,
    pub disconnects: AtomicU64,
}

/// The receivers known to the service: index (as the core knows them),
/// configuration and counters. Receivers are only ever added (SIGHUP), so
/// indices stay valid.
#[derive(Default)]
pub struct Registry {
    pub receivers: RwLock<Vec<(ReceiverConfig, Arc<RxCounters>)>>,
    pub unknown_senders: AtomicU64,
    pub queue_drops: AtomicU64,
    /// Frames in the core's queue, and the most it may hold
    /// (`queue_frames`, fixed at start).
    pub queued: AtomicUsize,
    pub queue_frames: usize,
    /// Failed accepts and datagram reads (out of descriptors, say): the
    /// input stays and tries again.
    pub socket_errors: AtomicU64,
    /// Bumped whenever `receivers` changes (SIGHUP), so the inputs' caches
    /// of it know to refresh.
    pub generation: AtomicU64,
    /// How many receivers `receivers` holds (for the fair share, without a lock).
    pub receiver_count: AtomicUsize,
    /// Datagrams the kernel dropped on the UDP inputs' sockets, their
    /// buffers full (`SO_RXQ_OVFL`): lost before any receiver could be named.
    pub kernel_drops: AtomicU64,
}

impl Registry {
    /// Adds a receiver (at start or on SIGHUP); returns its index.
    pub fn add(&self, r: ReceiverConfig) -> usize {
        let c = RxCounters::default();
        c.admission.set_rate(r.max_rate);
        let mut w = self.receivers.write().expect("registry");
        w.push((r, Arc::new(c)));
        self.receiver_count.store(w.len(), Ordering::Relaxed);
        w.len() - 1
    }

    /// New settings (source, rate, ...) for a known receiver, same index.
    pub fn update(&self, r: &ReceiverConfig) {
        let mut w = self.receivers.write().expect("registry");
        if let Some(e) = w.iter_mut().find(|(c, _)| c.id == r.id) {
            e.1.admission.set_rate(r.max_rate);
            e.0 = r.clone();
        }
    }

    pub fn index_of(&self, id: &str) -> Option<usize> {
        self.receivers.read().expect("registry").iter().position(|(r, _)| r.id == id)
    }

    /// The receiver sending from `ip`, if this input takes it.
    fn by_source(&self, ip: IpAddr, input: &InputConfig) -> Option<usize> {
        self.receivers
            .read()
            .expect("registry")
            .iter()
            .position(|(r, _)| r.source == Some(ip) && input.takes(r))
    }

    /// The receiver a readsb receiver id or UUID frame names, if this input takes it.
    fn by_beast_id(&self, id: BeastId, input: &InputConfig) -> Option<usize> {
        self.receivers
            .read()
            .expect("registry")
            .iter()
            .position(|(r, _)| r.beast_name() == Some(id) && input.takes(r))
    }

    /// Whether a sender this input does not know by address may still name
    /// itself (a receiver it takes has a `beast_id`).
    fn names_itself(&self, input: &InputConfig) -> bool {
        self.receivers.read().expect("registry").iter().any(|(r, _)| r.beast_id.is_some() && input.takes(r))
    }

    fn counters(&self, rx: usize) -> Arc<RxCounters> {
        self.receivers.read().expect("registry")[rx].1.clone()
    }

    /// A receiver's configured id, for the log.
    fn id(&self, rx: usize) -> String {
        self.receivers.read().expect("registry")[rx].0.id.clone()
    }

    /// Counts a failed accept or read, logs it (the first of each power of
    /// two), and waits before the next try: an error that persists (no file
    /// descriptors left while receivers hold connections open) must not
    /// spin, and must not end the input either, or every receiver that
    /// connects after it would be refused for good.
    async fn socket_error(&self, input: &InputConfig, what: &str, e: std::io::Error, in_a_row: &mut u32) {
        let n = self.socket_errors.fetch_add(1, Ordering::Relaxed) + 1;
        if n.is_power_of_two() {
            tracing::warn!(address = %input.address, errors = n, "{what} failed: {e}; trying again");
        }
        *in_a_row += 1;
        let wait_ms = (10u64 << (*in_a_row).min(7)).min(1000);
        tokio::time::sleep(Duration::from_millis(wait_ms)).await;
    }
}

/// The frames of one datagram or one read (they arrived together, at
/// `arrival`) to the core as one message: one queue operation and at most
/// one wake-up of the core thread for all of them, not one per frame (at
/// 1 M frames/s the per-frame sends were the largest item of the input
/// thread's own time). First the receiver's rate limit, then its fair share
/// of the queue (see [`admit`](super::admit)); the queue is bounded in
/// frames, not messages: a batch that does not fit is dropped whole and
/// every frame of it counted.
fn forward(
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

/// The frames a parser made of a read's bytes or a whole datagram (or, with
/// no bytes and not a datagram, what the end of a stream leaves: a frame
/// cut off is an error), its errors, garbage and heartbeats counted.
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
    } else if bytes.is_empty() {
        parser.finish(&mut sink);
    } else {
        parser.push(bytes, &mut sink);
    }
    let after = parser.stats();
    c.input_errors.fetch_add(after.input_errors() - before.input_errors(), Ordering::Relaxed);
    c.garbage_bytes.fetch_add(after.garbage_bytes - before.garbage_bytes, Ordering::Relaxed);
    c.heartbeats.fetch_add(after.heartbeats - before.heartbeats, Ordering::Relaxed);
    frames
}

/// Reads a Beast stream until it ends, or brings nothing for the input's
/// `idle_timeout_s`; returns why.
async fn stream(
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
                frames_of(parser.as_mut(), &[], false, &c);
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
pub fn spawn(
    input: InputConfig,
    bound: Bound,
    tx: SyncSender<ToCore>,
    reg: Arc<Registry>,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let r = match bound {
            Bound::Client => tcp_client(&input, &tx, &reg).await,
            Bound::Listener(l) => tcp_server(&input, l, tx, reg.clone()).await,
            Bound::Udp(sock) => udp(&input, sock, &tx, &reg).await,
        };
        if let Err(e) = r {
            tracing::error!(address = %input.address, "input stopped: {e}");
        }
    })
}

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

/// A connection that lasted this long (s) was a success: the client's
/// backoff starts again from its shortest.
const LASTING_S: u64 = 10;

async fn tcp_server(
    input: &InputConfig,
    listener: TcpListener,
    tx: SyncSender<ToCore>,
    reg: Arc<Registry>,
) -> std::io::Result<()> {
    let fixed = input.receiver.as_deref().and_then(|id| reg.index_of(id));
    let mut in_a_row = 0;
    // Each receiver's newest connection, and how to close it: one
    // connection per receiver, as mlat-server does. A receiver reconnects
    // when it thinks its connection died; the old one may be half open for
    // hours (a NAT that forgot it), holding a descriptor, and two live ones
    // would interleave one device's timestamps twice. Bounded by the
    // receivers; shared with the connections, which name their receiver
    // themselves when their address does not.
    let newest: Arc<Mutex<HashMap<usize, Arc<tokio::sync::Notify>>>> = Arc::default();
    // Connections still to name their receiver: each may hold NAME_BYTES
    // and its frames for NAME_WAIT_S, so a crowd of strangers is bounded.
    let naming = Arc::new(AtomicUsize::new(0));
    loop {
        let (sock, peer) = match listener.accept().await {
            Ok(a) => a,
            Err(e) => {
                reg.socket_error(input, "accept", e, &mut in_a_row).await;
                continue;
            }
        };
        in_a_row = 0;
        let known = fixed.or_else(|| reg.by_source(peer.ip(), input));
        if known.is_none() && !reg.names_itself(input) {
            refuse(&reg, peer, "unknown sender refused");
            continue;
        }
        if known.is_none() && naming.load(Ordering::Relaxed) >= NAMING_AT_ONCE {
            refuse(&reg, peer, "unknown sender refused: too many connections naming themselves at once");
            continue;
        }
        let (tx, reg, input, newest, naming) =
            (tx.clone(), reg.clone(), input.clone(), newest.clone(), naming.clone());
        tokio::spawn(async move {
            let mut parser = parser_for(InputFormat::Beast);
            let (rx, early) = match known {
                Some(rx) => (rx, None),
                None => {
                    naming.fetch_add(1, Ordering::Relaxed);
                    let named = identify(&sock, parser.as_mut(), &input, &reg).await;
                    naming.fetch_sub(1, Ordering::Relaxed);
                    match named {
                        Ok((rx, frames, arrival, bytes)) => (rx, Some((frames, arrival, bytes))),
                        Err(why) => {
                            refuse(&reg, peer, &format!("unknown sender refused: {why}"));
                            return;
                        }
                    }
                }
            };
            let stop = Arc::new(tokio::sync::Notify::new());
            if let Some(older) = newest.lock().expect("connections").insert(rx, stop.clone()) {
                // A permit is stored if that task is not waiting yet; if it has
                // ended, nobody reads it.
                older.notify_one();
            }
            let (c, id) = (reg.counters(rx), reg.id(rx));
            c.connects.fetch_add(1, Ordering::Relaxed);
            if let Some(held) = c.connection_log.pass(super::unix_now()) {
                tracing::info!(peer = %peer, receiver = id, held_back = held, "receiver connected");
            }
            if let Some((frames, arrival, bytes)) = early {
                let st = parser.stats();
                c.bytes.fetch_add(bytes as u64, Ordering::Relaxed);
                c.input_errors.fetch_add(st.input_errors(), Ordering::Relaxed);
                c.garbage_bytes.fetch_add(st.garbage_bytes, Ordering::Relaxed);
                c.heartbeats.fetch_add(st.heartbeats, Ordering::Relaxed);
                forward(&tx, &reg, &c, rx, arrival, frames);
            }
            let r = tokio::select! {
                r = stream(sock, parser, &input, &tx, &reg, rx) => r,
                _ = stop.notified() => Err(std::io::Error::other("closed: the receiver connected again")),
            };
            c.disconnects.fetch_add(1, Ordering::Relaxed);
            if let Some(held) = c.connection_log.pass(super::unix_now()) {
                let why = r.err().map_or("end of stream".into(), |e| e.to_string());
                tracing::warn!(peer = %peer, receiver = id, held_back = held, "receiver disconnected: {why}");
            }
        });
    }
}

/// Counts a refused sender and logs the first of each power of two.
fn refuse(reg: &Registry, peer: std::net::SocketAddr, why: &str) {
    let n = reg.unknown_senders.fetch_add(1, Ordering::Relaxed) + 1;
    if n.is_power_of_two() {
        tracing::warn!(peer = %peer, refused = n, "{why}");
    }
}

/// How long a sender whose address names no receiver has to name itself,
/// how much it may send before it does, and how many may be at it at once:
/// together they bound what strangers can make the service hold.
const NAME_WAIT_S: f64 = 10.0;
const NAME_BYTES: usize = 256 << 10;
const NAMING_AT_ONCE: usize = 64;

/// Reads a connection from an address no receiver has until the sender
/// names itself with readsb's receiver id (0xe3) or UUID (0xe4) frame, and
/// looks the receiver up by its `beast_id`. Returns it with the frames read
/// meanwhile (the connection is one receiver's, before its name too), the
/// last read's arrival and the bytes read. The first name holds for the
/// connection: later ones are not looked at.
async fn identify(
    sock: &TcpStream,
    parser: &mut (dyn FrameParser + Send),
    input: &InputConfig,
    reg: &Registry,
) -> Result<(usize, Vec<RawFrame>, f64, usize), String> {
    let _ = super::stamp::enable(sock);
    let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(NAME_WAIT_S);
    let mut buf = vec![0u8; 16 * 1024];
    let (mut frames, mut bytes, mut named) = (Vec::new(), 0usize, None);
    loop {
        let read = sock.async_io(Interest::READABLE, || super::stamp::recv(sock, &mut buf));
        let (n, _, arrival) = tokio::time::timeout_at(deadline, read)
            .await
            .map_err(|_| format!("no receiver named within {NAME_WAIT_S} s"))?
            .map_err(|e| e.to_string())?;
        if n == 0 {
            return Err("closed before naming a receiver".into());
        }
        bytes += n;
        parser.push(&buf[..n], &mut |ev| match ev {
            FeedEvent::Frame(f) => frames.push(f),
            other => named = named.or(BeastId::of(&other)),
        });
        if let Some(id) = named {
            return reg
                .by_beast_id(id, input)
                .map(|rx| (rx, frames, arrival, bytes))
                .ok_or_else(|| format!("it names receiver {id}, which this input does not take"));
        }
        if bytes > NAME_BYTES {
            return Err(format!("{bytes} bytes without naming a receiver"));
        }
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
    let format = if input.format == "avr" { InputFormat::Avr } else { InputFormat::Beast };
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
    use std::sync::mpsc::sync_channel;

    fn frames(n: usize) -> Vec<RawFrame> {
        (0..n)
            .map(|i| RawFrame::new(&[0x5d, 0x4b, 0x1a, 0x2b, 0, 0, i as u8], i as u64, 0).unwrap())
            .collect()
    }

    /// A Beast TCP server takes a sender its address does not name once it
    /// names itself (readsb's receiver id or UUID frame), with the frames it
    /// sent before its name too, and refuses and counts one that names an
    /// unknown receiver or nobody.
    #[test]
    fn a_tcp_sender_is_known_by_the_receiver_id_or_uuid_it_sends() {
        use tokio::io::AsyncWriteExt;
        let uuid = *b"0f1e2d3c-4b5a-6978-8796-a5b4c3d2e1f0";
        let receiver = |id: &str, beast_id: Option<&str>| ReceiverConfig {
            id: id.into(),
            lat: 0.0,
            lon: 0.0,
            alt_m: 0.0,
            clock: "beast12".into(),
            source: None,
            beast_id: beast_id.map(Into::into),
            max_rate: 0.0,
        };
        let reg = Arc::new(Registry { queue_frames: 1000, ..Default::default() });
        for r in [
            receiver("a", Some("0102030405060708")),
            receiver("b", Some("0F1E2D3C-4B5A-6978-8796-A5B4C3D2E1F0")),
            receiver("c", None),
        ] {
            reg.add(r);
        }
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let address: std::net::SocketAddr = ([127, 0, 0, 1], port).into();
        let input = InputConfig {
            kind: InputKind::BeastTcpServer,
            address,
            receiver: None,
            receivers: Vec::new(),
            format: "beast".into(),
            idle_timeout_s: 0.0,
        };
        let beast = |frames: &[RawFrame]| {
            let mut out = Vec::new();
            for f in frames {
                crate::feed::beast::encode(f, &mut out);
            }
            out
        };
        let (tx, core) = sync_channel(100);
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        rt.block_on(async {
            let bound = bind(&input).await.unwrap();
            let task = spawn(input, bound, tx, reg.clone());
            tokio::time::sleep(Duration::from_millis(50)).await;
            let mut id = Vec::new();
            crate::feed::beast::encode_receiver_id(0x0102_0304_0506_0708, &mut id);
            let mut named_uuid = Vec::new();
            crate::feed::beast::encode_receiver_uuid(&uuid, &mut named_uuid);
            let mut unknown = Vec::new();
            crate::feed::beast::encode_receiver_id(0xdead_beef, &mut unknown);
            let sessions = [
                [beast(&frames(1)), named_uuid, beast(&frames(2))].concat(),
                [id, beast(&frames(3))].concat(),
                [unknown, beast(&frames(4))].concat(),
                beast(&frames(5)),
            ];
            for bytes in sessions {
                let mut s = TcpStream::connect(address).await.unwrap();
                s.write_all(&bytes).await.unwrap();
                s.shutdown().await.unwrap();
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            task.abort();
        });
        let mut got: Vec<(usize, usize)> = Vec::new();
        for m in core.try_iter() {
            if let ToCore::Frames { rx, frames, .. } = m {
                match got.last_mut() {
                    Some((last, n)) if *last == rx => *n += frames.len(),
                    _ => got.push((rx, frames.len())),
                }
            }
        }
        assert_eq!(got, vec![(1, 3), (0, 3)]);
        assert_eq!(reg.unknown_senders.load(Ordering::Relaxed), 2);
        assert_eq!(reg.counters(1).connects.load(Ordering::Relaxed), 1);
    }

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
        let receiver = |id: &str| ReceiverConfig {
            id: id.into(),
            lat: 0.0,
            lon: 0.0,
            alt_m: 0.0,
            clock: "beast12".into(),
            source: None,
            beast_id: None,
            max_rate: 0.0,
        };
        for id in ["flood", "a", "b", "c"] {
            reg.add(receiver(id));
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
