//! The receivers the service knows, each with its counters and admission
//! state, shared by every input, the core thread (for the stats line and
//! the metrics) and SIGHUP, which adds, updates and revokes receivers.

use std::net::IpAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, RwLock};
use std::time::Duration;

use super::admit::Admission;
use super::config::{BeastId, InputConfig, ReceiverConfig};
use super::loglimit::LogGate;

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
    /// Connections closed for silence (its input's `idle_timeout_s`).
    pub idle_timeouts: AtomicU64,
    /// Removed from the configuration (SIGHUP): not taken on any input, its
    /// connections closed (see [`Registry::reconfigure`]).
    pub revoked: AtomicBool,
    /// Woken when it is revoked: its connections end.
    pub revoke: tokio::sync::Notify,
}

/// The receivers known to the service: index (as the core knows them),
/// configuration and counters. Receivers are only ever added (SIGHUP), so
/// indices stay valid; one removed from the configuration is revoked: no
/// input takes it and its connections are closed, until a later
/// configuration names it again.
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
    /// How many receivers are configured (not revoked), for the fair share without a lock.
    pub receiver_count: AtomicUsize,
    /// Datagrams the kernel dropped on the UDP inputs' sockets, their
    /// buffers full (`SO_RXQ_OVFL`): lost before any receiver could be named.
    pub kernel_drops: AtomicU64,
    /// What the Prometheus endpoint (`metrics_listen`) turned away.
    pub metrics_http: Arc<super::http::HttpCounters>,
    /// What the HTTP server (`[http] listen`) turned away.
    pub http: Arc<super::http::HttpCounters>,
}

/// A receiver and new counters, its rate limit set.
fn push(w: &mut Vec<(ReceiverConfig, Arc<RxCounters>)>, r: ReceiverConfig) {
    let c = RxCounters::default();
    c.admission.set_rate(r.max_rate);
    w.push((r, Arc::new(c)));
}

impl Registry {
    /// Adds a receiver (at start or on SIGHUP); returns its index.
    pub fn add(&self, r: ReceiverConfig) -> usize {
        let mut w = self.receivers.write().expect("registry");
        push(&mut w, r);
        self.count_configured(&w);
        w.len() - 1
    }

    /// The fair share is of the receivers configured now, revoked ones left out.
    fn count_configured(&self, w: &[(ReceiverConfig, Arc<RxCounters>)]) {
        let n = w.iter().filter(|(_, c)| !c.revoked.load(Ordering::Relaxed)).count();
        self.receiver_count.store(n, Ordering::Relaxed);
    }

    /// A new configuration's receivers (SIGHUP): new ones added (returned,
    /// for the core), known ones updated in place (same index), and those
    /// it no longer names revoked, their connections closed at once.
    pub fn reconfigure(&self, new: &[ReceiverConfig]) -> Vec<ReceiverConfig> {
        let mut w = self.receivers.write().expect("registry");
        for (cfg, c) in w.iter_mut() {
            match new.iter().find(|r| r.id == cfg.id) {
                Some(r) => {
                    c.admission.set_rate(r.max_rate);
                    c.revoked.store(false, Ordering::Relaxed);
                    *cfg = r.clone();
                }
                None => {
                    if !c.revoked.swap(true, Ordering::Relaxed) {
                        tracing::info!(receiver = cfg.id, "SIGHUP: receiver removed; its connections closed");
                    }
                    c.revoke.notify_waiters();
                }
            }
        }
        let added: Vec<ReceiverConfig> =
            new.iter().filter(|r| !w.iter().any(|(c, _)| c.id == r.id)).cloned().collect();
        for r in &added {
            push(&mut w, r.clone());
        }
        self.count_configured(&w);
        self.generation.fetch_add(1, Ordering::Relaxed);
        added
    }

    /// The index of a receiver of the current configuration.
    pub fn index_of(&self, id: &str) -> Option<usize> {
        self.find(|r| r.id == id)
    }

    /// The counters of a receiver of the current configuration.
    pub fn counters_of(&self, id: &str) -> Option<Arc<RxCounters>> {
        self.index_of(id).map(|at| self.counters(at))
    }

    /// The first receiver of the current configuration (not revoked) that `pred` accepts.
    fn find(&self, pred: impl Fn(&ReceiverConfig) -> bool) -> Option<usize> {
        self.receivers
            .read()
            .expect("registry")
            .iter()
            .position(|(r, c)| !c.revoked.load(Ordering::Relaxed) && pred(r))
    }

    /// The receiver sending from `ip`, if this input takes it.
    pub(super) fn by_source(&self, ip: IpAddr, input: &InputConfig) -> Option<usize> {
        self.find(|r| r.source == Some(ip) && input.takes(r))
    }

    /// The receiver a readsb receiver id or UUID frame names, if this input takes it.
    pub(super) fn by_beast_id(&self, id: BeastId, input: &InputConfig) -> Option<usize> {
        self.find(|r| r.beast_name() == Some(id) && input.takes(r))
    }

    /// Whether a sender this input does not know by address may still name
    /// itself (a receiver it takes has a `beast_id`).
    pub(super) fn names_itself(&self, input: &InputConfig) -> bool {
        self.find(|r| r.beast_id.is_some() && input.takes(r)).is_some()
    }

    /// Its configuration (as of now) and counters.
    pub(super) fn get(&self, rx: usize) -> (ReceiverConfig, Arc<RxCounters>) {
        self.receivers.read().expect("registry")[rx].clone()
    }

    pub(super) fn counters(&self, rx: usize) -> Arc<RxCounters> {
        self.receivers.read().expect("registry")[rx].1.clone()
    }

    /// Counts a failed accept or read, logs it (the first of each power of
    /// two), and waits before the next try: an error that persists (no file
    /// descriptors left while receivers hold connections open) must not
    /// spin, and must not end the input either, or every receiver that
    /// connects after it would be refused for good.
    pub(super) async fn socket_error(
        &self,
        input: &InputConfig,
        what: &str,
        e: std::io::Error,
        in_a_row: &mut u32,
    ) {
        let n = self.socket_errors.fetch_add(1, Ordering::Relaxed) + 1;
        if n.is_power_of_two() {
            tracing::warn!(address = %input.address, errors = n, "{what} failed: {e}; trying again");
        }
        *in_a_row += 1;
        let wait_ms = (10u64 << (*in_a_row).min(7)).min(1000);
        tokio::time::sleep(Duration::from_millis(wait_ms)).await;
    }
}
