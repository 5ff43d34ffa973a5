//! The ingest role: frames onto their partitions' subjects.
//!
//! A capture is replayed as fast as JetStream stores it: every `batch_s` of
//! the capture's arrival time, each partition gets one batch (empty ones
//! too: they carry the time). Receivers are declared on their own stream
//! before any frame names them, and every batch says how many there were,
//! so a worker knows when it must read more. Publications are acknowledged
//! by the server; at most `IN_FLIGHT` wait at once (the memory bound), and
//! each has a message id, so a publication retried after a lost ack is
//! stored once.

use std::collections::VecDeque;
use std::io::BufReader;
use std::path::Path;

use anyhow::{Context, Result};
use async_nats::HeaderMap;

use super::outage::Storing;
use super::wire::{frame_address, partition_of, BatchWriter};
use super::{header, headers, ClusterConfig, Nats};
use crate::feed::capture::{CaptureFrame, CaptureReader, CaptureRecord, ReceiverDecl};

const IN_FLIGHT: usize = 256;

/// What a replay published.
#[derive(Clone, Copy, Debug, Default)]
pub struct IngestStats {
    pub frames: u64,
    pub batches: u64,
    /// Mode A/C replies: no address, no partition (a node ignores them too).
    pub no_address: u64,
}

/// Frames cut into one batch per partition, handed out a period at a time
/// (every partition's batch, empty or not, with the period's time).
struct Batcher {
    batches: Vec<BatchWriter>,
    /// Receivers declared so far: a batch may name any of them.
    receivers: usize,
    seq: u64,
    /// The run's identity in message ids: a replay started again is new data.
    run: u32,
    stats: IngestStats,
}

impl Batcher {
    fn new(partitions: u32) -> Self {
        let batches = (0..partitions).map(|_| BatchWriter::default()).collect();
        Batcher { batches, receivers: 0, seq: 0, run: std::process::id(), stats: IngestStats::default() }
    }

    fn push(&mut self, f: &CaptureFrame) {
        match frame_address(&f.frame) {
            Some(addr) => {
                let n = self.batches.len() as u32;
                self.batches[partition_of(addr, n) as usize].push(f);
                self.stats.frames += 1;
            }
            None => self.stats.no_address += 1,
        }
    }

    /// Every partition's batch, running to `t`.
    fn period(&mut self, t: f64, end: bool) -> Vec<(u32, HeaderMap, Vec<u8>)> {
        let (run, seq, receivers) = (self.run, self.seq, self.receivers as f64);
        self.seq += 1;
        self.stats.batches += self.batches.len() as u64;
        (self.batches.iter_mut().enumerate())
            .map(|(p, b)| {
                let h = headers(
                    &format!("f{run}-{p}-{seq}"),
                    end,
                    &[(header::TIME, t), (header::RECEIVERS, receivers)],
                );
                (p as u32, h, b.take())
            })
            .collect()
    }
}

struct Publisher<'a> {
    nats: &'a Nats,
    pending: VecDeque<Storing>,
}

impl Publisher<'_> {
    async fn send(&mut self, subject: String, headers: HeaderMap, payload: Vec<u8>) -> Result<()> {
        if self.pending.len() >= IN_FLIGHT {
            self.settle(IN_FLIGHT / 2).await?;
        }
        self.pending.push_back(self.nats.send(subject, headers, payload.into()).await?);
        Ok(())
    }

    /// A period's batches, one per partition.
    async fn send_all(&mut self, period: Vec<(u32, HeaderMap, Vec<u8>)>) -> Result<()> {
        for (p, h, body) in period {
            self.send(self.nats.names.frames(p), h, body).await?;
        }
        Ok(())
    }

    /// A receiver, stored before any later batch (which may name it) is sent.
    async fn declare(&mut self, d: &ReceiverDecl) -> Result<()> {
        let body = serde_json::to_vec(d)?;
        self.settle(0).await?;
        // Its id: a declaration sent again after a lost acknowledgement is
        // stored once (a second copy would shift every later index).
        let h = headers(&format!("d{}-{}", std::process::id(), d.id), false, &[]);
        self.nats.store(self.nats.names.receivers(), h, body.into(), "storing a receiver").await
    }

    async fn settle(&mut self, keep: usize) -> Result<()> {
        while self.pending.len() > keep {
            let sent = self.pending.pop_front().expect("non-empty");
            sent.stored(self.nats, "storing a frame batch").await?;
        }
        Ok(())
    }
}

pub async fn replay(nats: &Nats, cfg: &ClusterConfig, capture: &Path) -> Result<IngestStats> {
    let file = std::fs::File::open(capture).with_context(|| format!("cannot open {}", capture.display()))?;
    let mut reader =
        CaptureReader::new(BufReader::with_capacity(1 << 20, file), capture.display().to_string());
    let mut batcher = Batcher::new(cfg.partitions);
    let mut out = Publisher { nats, pending: VecDeque::new() };
    let mut tick = None::<f64>;
    while let Some(rec) = reader.next_record().context("reading the capture")? {
        match rec {
            CaptureRecord::Receiver(d) => {
                out.declare(&d).await?;
                batcher.receivers += 1;
            }
            CaptureRecord::Frame(f) => {
                let mut t = *tick.get_or_insert(f.arrival + cfg.batch_s);
                // Batches end on the tick before this frame (several, empty, over a gap).
                while f.arrival >= t {
                    out.send_all(batcher.period(t, false)).await?;
                    t += cfg.batch_s;
                }
                tick = Some(t);
                batcher.push(&f);
            }
        }
    }
    out.send_all(batcher.period(tick.unwrap_or(0.0), true)).await?;
    out.settle(0).await?;
    let stats = batcher.stats;
    tracing::info!(
        frames = stats.frames,
        batches = stats.batches,
        no_address = stats.no_address,
        skipped_lines = reader.skipped,
        "ingest: capture replayed"
    );
    println!(
        "ingest: frames={} batches={} no_address={} nats_retries={} nats_disconnects={}",
        stats.frames,
        stats.batches,
        stats.no_address,
        super::outage::retries(),
        super::outage::disconnects()
    );
    Ok(stats)
}

/// What the live ingest's thread hands the publishing task, in order.
pub enum Outgoing {
    Receiver(ReceiverDecl),
    /// One period's batch for every partition.
    Batches(Vec<(u32, HeaderMap, Vec<u8>)>),
}

/// The live ingest: the daemon's inputs (admission, rate limits, receiver
/// recognition: all as one node's) feed this thread instead of a core. It
/// cuts the frames into partition batches every `batch_s` of the system
/// clock and hands them to [`publish_live`]; the channel between them is
/// bounded, so a NATS that cannot keep up fills the inputs' queue, whose
/// drops are counted as one node's are.
pub fn live_sink(
    rx: std::sync::mpsc::Receiver<crate::live::ToCore>,
    registry: std::sync::Arc<crate::live::registry::Registry>,
    out: tokio::sync::mpsc::Sender<Outgoing>,
    cfg: ClusterConfig,
) {
    use crate::live::ToCore;
    use std::sync::atomic::Ordering;
    let mut batcher = Batcher::new(cfg.partitions);
    let mut latest = f64::NEG_INFINITY;
    let mut tick = crate::live::unix_now() + cfg.batch_s;
    let wait = std::time::Duration::from_secs_f64(cfg.batch_s / 4.0);
    loop {
        match rx.recv_timeout(wait) {
            Ok(ToCore::Frames { rx: r, arrival, frames, from }) => {
                from.admission.queued.fetch_sub(frames.len(), Ordering::Relaxed);
                registry.queued.fetch_sub(frames.len(), Ordering::Relaxed);
                latest = latest.max(arrival);
                for frame in frames {
                    batcher.push(&CaptureFrame { arrival, rx: r, frame });
                }
            }
            Ok(ToCore::AddReceiver(d)) => {
                batcher.receivers += 1;
                if out.blocking_send(Outgoing::Receiver(d)).is_err() {
                    return;
                }
            }
            Ok(ToCore::Outputs(_)) => {}
            Ok(ToCore::Shutdown) | Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
        }
        let now = crate::live::unix_now();
        if now < tick {
            continue;
        }
        // The batch runs to the tick, or to its newest frame when the
        // system clock's tick came before an input's stamp.
        let period = batcher.period(tick.max(latest), false);
        tick = (tick + cfg.batch_s).max(now);
        if out.blocking_send(Outgoing::Batches(period)).is_err() {
            return;
        }
    }
}

/// Stores the live ingest's receivers and batches, in order.
pub async fn publish_live(nats: &Nats, mut rx: tokio::sync::mpsc::Receiver<Outgoing>) -> Result<()> {
    let mut out = Publisher { nats, pending: VecDeque::new() };
    while let Some(o) = rx.recv().await {
        match o {
            Outgoing::Receiver(d) => out.declare(&d).await?,
            Outgoing::Batches(period) => out.send_all(period).await?,
        }
    }
    out.settle(0).await
}
