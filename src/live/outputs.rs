//! Output destinations: UDP (unicast or multicast) in JSON or ASTERIX
//! CAT062, JSON lines on stdout, and TCP streams (JSON lines, Beast, SBS;
//! their sockets are [`super::stream_out`]'s). Nothing here may block the core:
//! sockets are non-blocking, and stdout (a pipe nobody reads blocks its
//! writer for good) is written by a thread of its own behind a bounded
//! queue, whose overflow is dropped and counted. Every error is counted:
//! a destination that is unreachable never blocks or stops the others, and
//! nothing is sent anywhere but the configured addresses. UDP sockets are
//! connected to their destination, so that the kernel reports a refusal
//! (ICMP port unreachable) as an error of the next send.

use std::io::Write;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, SyncSender, TrySendError};
use std::sync::{Arc, OnceLock};

use socket2::{Domain, Protocol, Socket, Type};

use hyper::body::Bytes;

use super::config::{OutputConfig, OutputFormat, OutputKind, ServiceConfig};
use super::stream_out::Stream;
use crate::core::Event;
use crate::feed::RawFrame;
use crate::fuse::TrackSource;
use crate::publish::sbs::SbsWriter;
use crate::publish::{asterix, beast, json, readout};

pub struct Destination {
    pub cfg: OutputConfig,
    socket: Option<UdpSocket>,
    /// A TCP output's subscribers.
    stream: Option<Arc<Stream>>,
    /// An SBS output's memory of what it said.
    sbs: Option<SbsWriter>,
    pub sent: u64,
    errors: u64,
    /// Lines a stdout output could not queue (its reader too slow).
    dropped: u64,
    last_error_log: f64,
}

impl Destination {
    /// Sends that failed (for stdout, the writer's failed writes, which
    /// every stdout output shares; for TCP, failed connects and accepts,
    /// broken connections and subscribers refused over `max_clients`).
    pub fn errors(&self) -> u64 {
        let stream = self.stream.as_ref().map_or(0, |s| {
            s.counters.errors.load(Ordering::Relaxed) + s.counters.refused.load(Ordering::Relaxed)
        });
        match self.cfg.kind {
            OutputKind::Stdout => self.errors + stdout_writer().errors.load(Ordering::Relaxed),
            OutputKind::Udp | OutputKind::TcpServer | OutputKind::TcpConnect => self.errors + stream,
        }
    }

    /// What a slow reader cost: stdout lines not queued, TCP subscribers
    /// dropped for falling behind, batches a pushed connection missed.
    pub fn dropped(&self) -> u64 {
        self.dropped
            + self.stream.as_ref().map_or(0, |s| {
                s.counters.slow_dropped.load(Ordering::Relaxed) + s.counters.missed.load(Ordering::Relaxed)
            })
    }

    /// Hands a batch to a TCP output's subscribers.
    fn stream_send(&mut self, bytes: Bytes) {
        if bytes.is_empty() {
            return;
        }
        match &self.stream {
            Some(s) => {
                s.send(bytes);
                self.sent += 1;
            }
            // It could not bind at a reload: what it misses is counted.
            None => self.errors += 1,
        }
    }

    /// Bytes written to TCP subscribers.
    pub fn stream_bytes(&self) -> u64 {
        self.stream.as_ref().map_or(0, |s| s.counters.bytes.load(Ordering::Relaxed))
    }

    /// Subscribers connected now (TCP outputs).
    pub fn clients(&self) -> u64 {
        self.stream.as_ref().map_or(0, |s| s.counters.clients.load(Ordering::Relaxed))
    }
}

fn udp_socket(cfg: &OutputConfig, addr: SocketAddr) -> std::io::Result<UdpSocket> {
    let domain = if addr.is_ipv4() { Domain::IPV4 } else { Domain::IPV6 };
    let s = Socket::new(domain, Type::DGRAM, Some(Protocol::UDP))?;
    if addr.ip().is_multicast() {
        if let SocketAddr::V4(_) = addr {
            s.set_multicast_ttl_v4(cfg.multicast_ttl)?;
            if let Some(ifa) = cfg.multicast_interface {
                s.set_multicast_if_v4(&ifa)?;
            }
        }
    }
    // No bind: connect picks the local port, so the unit's SocketBindDeny
    // (see `fuse1090 unit-limits`) need not allow any.
    s.connect(&addr.into())?;
    s.set_nonblocking(true)?;
    Ok(s.into())
}

/// Lines for stdout, waiting for its writer thread: at most this many; a
/// reader that stops reading costs lines, never the core.
const STDOUT_QUEUE: usize = 4096;

impl Destination {
    /// Each payload a line for the stdout writer; what its queue cannot
    /// take is dropped and counted (a slow reader must not stall the core).
    fn send_stdout(&mut self, payloads: &[Vec<u8>], now: f64) {
        let writer = stdout_writer();
        for p in payloads {
            writer.pending.fetch_add(1, Ordering::AcqRel);
            let sent = writer.tx.try_send(p.clone());
            if sent.is_err() {
                writer.pending.fetch_sub(1, Ordering::AcqRel);
            }
            match sent {
                Ok(()) => self.sent += 1,
                Err(TrySendError::Full(_)) => self.dropped += 1,
                Err(TrySendError::Disconnected(_)) => self.errors += 1,
            }
        }
        if self.dropped > 0 && now - self.last_error_log > 10.0 {
            self.last_error_log = now;
            tracing::warn!(
                dropped = self.dropped,
                "stdout output: its reader keeps up too slowly; lines dropped"
            );
        }
    }

    /// Each payload a datagram; failures counted, logged at most every 10 s.
    fn send_udp(&mut self, payloads: &[Vec<u8>], now: f64) {
        let (Some(sock), Some(addr)) = (&self.socket, self.cfg.address) else {
            self.errors += payloads.len() as u64;
            return;
        };
        for p in payloads {
            match sock.send(p) {
                Ok(_) => self.sent += 1,
                Err(e) => {
                    self.errors += 1;
                    if now - self.last_error_log > 10.0 {
                        self.last_error_log = now;
                        tracing::warn!(address = %addr, errors = self.errors, "output: {e}");
                    }
                }
            }
        }
    }
}

/// The process's one stdout writer (every stdout output of every
/// configuration shares it): a queue and the count of lines its writes failed.
struct Stdout {
    tx: SyncSender<Vec<u8>>,
    errors: Arc<AtomicU64>,
    /// Lines queued and not yet written.
    pending: Arc<AtomicU64>,
}

/// Waits, up to `limit`, for the stdout writer to have written every line
/// queued (at shutdown: a reader that reads gets everything, one that does
/// not holds the exit back by `limit` only).
pub fn flush_stdout(limit: std::time::Duration) {
    let Some(w) = STDOUT.get() else { return };
    let t0 = std::time::Instant::now();
    while w.pending.load(Ordering::Acquire) > 0 && t0.elapsed() < limit {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

static STDOUT: OnceLock<Stdout> = OnceLock::new();

fn stdout_writer() -> &'static Stdout {
    STDOUT.get_or_init(|| {
        let (tx, rx) = sync_channel::<Vec<u8>>(STDOUT_QUEUE);
        let (errors, pending) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
        let (errs, left) = (errors.clone(), pending.clone());
        // Never joined: at shutdown it may be blocked in a write for good.
        let spawned = std::thread::Builder::new().name("stdout".into()).spawn(move || {
            let mut out = std::io::stdout().lock();
            while let Ok(first) = rx.recv() {
                // What waits goes out together, flushed once, so that a
                // reader sees each batch at once.
                let mut n = 0;
                for mut line in std::iter::once(first).chain(std::iter::from_fn(|| rx.try_recv().ok())) {
                    line.push(b'\n');
                    if out.write_all(&line).is_err() {
                        errs.fetch_add(1, Ordering::Relaxed);
                    }
                    n += 1;
                }
                if out.flush().is_err() {
                    errs.fetch_add(1, Ordering::Relaxed);
                }
                left.fetch_sub(n, Ordering::Release);
            }
        });
        if let Err(e) = spawned {
            tracing::error!("cannot start the stdout writer: {e}");
        }
        Stdout { tx, errors, pending }
    })
}

pub struct Outputs {
    pub dests: Vec<Destination>,
    source: asterix::Source,
    max_bytes: usize,
}

impl Outputs {
    /// The destinations of `cfgs`; the TCP ones are among `streams`
    /// (started by [`super::stream_out::start_all`]), and one missing there
    /// (it could not bind) counts every batch as an error.
    pub fn new(cfgs: &[OutputConfig], service: &ServiceConfig, streams: &[Arc<Stream>]) -> Outputs {
        let dests = cfgs
            .iter()
            .map(|c| {
                let socket = match (c.kind, c.address) {
                    (OutputKind::Udp, Some(a)) => match udp_socket(c, a) {
                        Ok(s) => Some(s),
                        Err(e) => {
                            tracing::error!(address = %a, "output socket: {e}");
                            None
                        }
                    },
                    _ => None,
                };
                Destination {
                    cfg: c.clone(),
                    socket,
                    stream: streams.iter().find(|s| s.cfg == *c).cloned(),
                    sbs: (c.format == OutputFormat::Sbs).then(SbsWriter::new),
                    sent: 0,
                    errors: 0,
                    dropped: 0,
                    last_error_log: f64::NEG_INFINITY,
                }
            })
            .collect();
        Outputs {
            dests,
            source: asterix::Source { sac: service.sac, sic: service.sic, service: service.service_id },
            max_bytes: service.max_datagram_bytes,
        }
    }

    /// The forwarding of received frames these outputs ask for.
    pub fn frame_forward(&self) -> FrameForward {
        let streams =
            self.dests.iter().filter(|d| d.cfg.forward_frames).filter_map(|d| d.stream.clone()).collect();
        FrameForward { streams, wire: Vec::new() }
    }

    /// Sends a batch of events to every destination; `name` gives receivers'
    /// ids for the JSON records, `now` is for rate-limited logs.
    pub fn publish<'a>(&mut self, events: &[Event], name: impl Fn(usize) -> &'a str, now: f64) {
        if events.is_empty() || self.dests.is_empty() {
            return;
        }
        let mut lines: Option<Vec<Vec<u8>>> = None;
        let mut blocks: Option<Vec<Vec<u8>>> = None;
        let mut mlat_frames: Option<Bytes> = None;
        for d in &mut self.dests {
            if d.cfg.kind.is_tcp() {
                let bytes = match (d.cfg.format, &mut d.sbs) {
                    (OutputFormat::Sbs, Some(w)) => {
                        let mut text = String::new();
                        w.write(events, now, &mut text);
                        Bytes::from(text)
                    }
                    (OutputFormat::Beast, _) => {
                        mlat_frames.get_or_insert_with(|| beast_frames(events)).clone()
                    }
                    _ => newline_joined(lines.get_or_insert_with(|| json_lines(events, &name))),
                };
                d.stream_send(bytes);
                continue;
            }
            let payloads = match d.cfg.format {
                OutputFormat::Json | OutputFormat::Beast | OutputFormat::Sbs => {
                    lines.get_or_insert_with(|| json_lines(events, &name))
                }
                OutputFormat::Asterix062 => blocks.get_or_insert_with(|| {
                    let records: Vec<Vec<u8>> = events
                        .iter()
                        .filter_map(|e| match e {
                            Event::Track(r) if r.source == TrackSource::Fused => {
                                Some(asterix::record(self.source, r, r.ages_s))
                            }
                            _ => None,
                        })
                        .collect();
                    asterix::blocks(&records, self.max_bytes)
                }),
            };
            if d.cfg.kind == OutputKind::Stdout {
                d.send_stdout(payloads, now);
            } else {
                d.send_udp(payloads, now);
            }
        }
    }
}

/// Each event of the track stream as one JSON object, without its newline.
fn json_lines<'a>(events: &[Event], name: &impl Fn(usize) -> &'a str) -> Vec<Vec<u8>> {
    events
        .iter()
        .filter(|e| !matches!(e, Event::Position(_)))
        .map(|e| {
            let mut b = Vec::new();
            json::write_event(&mut b, e, name);
            b.pop(); // the newline: one object per datagram
            b
        })
        .collect()
}

/// The Beast frames of the multilateration results among `events`.
fn beast_frames(events: &[Event]) -> Bytes {
    let mut out = Vec::new();
    for e in events {
        if let Event::Track(r) = e {
            beast::mlat_result(r, &readout::readout(r), &mut out);
        }
    }
    Bytes::from(out)
}

/// JSON objects as lines, for a byte stream.
fn newline_joined(lines: &[Vec<u8>]) -> Bytes {
    Bytes::from(lines.iter().flat_map(|l| l.iter().chain(b"\n")).copied().collect::<Vec<u8>>())
}

/// The received frames for the Beast outputs that forward them
/// (`forward_frames`): collected by the core's front thread as they arrive
/// and handed over once per batch.
#[derive(Default)]
pub struct FrameForward {
    streams: Vec<Arc<Stream>>,
    wire: Vec<u8>,
}

impl FrameForward {
    pub fn push(&mut self, frame: &RawFrame) {
        if !self.streams.is_empty() {
            crate::feed::beast::encode(frame, &mut self.wire);
        }
    }

    /// Sends what was collected since the last call.
    pub fn flush(&mut self) {
        if self.wire.is_empty() {
            return;
        }
        let bytes = Bytes::from(std::mem::take(&mut self.wire));
        for s in &self.streams {
            s.send(bytes.clone());
        }
    }
}
