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
use async_nats::jetstream::context::PublishAckFuture;
use async_nats::HeaderMap;

use super::wire::{frame_address, partition_of, BatchWriter};
use super::{header, ClusterConfig, Nats};
use crate::feed::capture::{CaptureReader, CaptureRecord, ReceiverDecl};

const IN_FLIGHT: usize = 256;

/// What a replay published.
#[derive(Clone, Copy, Debug, Default)]
pub struct IngestStats {
    pub frames: u64,
    pub batches: u64,
    /// Mode A/C replies: no address, no partition (a node ignores them too).
    pub no_address: u64,
}

struct Publisher<'a> {
    nats: &'a Nats,
    pending: VecDeque<PublishAckFuture>,
}

impl Publisher<'_> {
    async fn send(&mut self, subject: String, headers: HeaderMap, payload: Vec<u8>) -> Result<()> {
        if self.pending.len() >= IN_FLIGHT {
            self.settle(IN_FLIGHT / 2).await?;
        }
        let ack = self.nats.js.publish_with_headers(subject, headers, payload.into()).await?;
        self.pending.push_back(ack);
        Ok(())
    }

    /// A receiver, stored before any later batch (which may name it) is sent.
    async fn declare(&mut self, d: &ReceiverDecl) -> Result<()> {
        let body = serde_json::to_vec(&super::worker::ReceiverMsg::from(d))?;
        self.settle(0).await?;
        let ack = self.nats.js.publish(self.nats.names.receivers(), body.into()).await?;
        ack.await.context("JetStream did not store a receiver")?;
        Ok(())
    }

    async fn settle(&mut self, keep: usize) -> Result<()> {
        while self.pending.len() > keep {
            let ack = self.pending.pop_front().expect("non-empty");
            ack.await.context("JetStream did not store a frame batch")?;
        }
        Ok(())
    }
}

pub async fn replay(nats: &Nats, cfg: &ClusterConfig, capture: &Path) -> Result<IngestStats> {
    let file = std::fs::File::open(capture).with_context(|| format!("cannot open {}", capture.display()))?;
    let mut reader =
        CaptureReader::new(BufReader::with_capacity(1 << 20, file), capture.display().to_string());
    let n = cfg.partitions;
    let mut batches: Vec<BatchWriter> = (0..n).map(|_| BatchWriter::default()).collect();
    let mut out = Publisher { nats, pending: VecDeque::new() };
    let mut stats = IngestStats::default();
    let (mut receivers, mut tick, mut seq) = (0usize, None::<f64>, 0u64);
    // The run's identity in message ids: a replay started again is new data.
    let run = std::process::id();
    let flush = |batches: &mut Vec<BatchWriter>, t: f64, seq: u64, receivers: usize, end: bool| {
        batches
            .iter_mut()
            .enumerate()
            .map(|(p, b)| {
                (p as u32, batch_headers(t, receivers, &format!("f{run}-{p}-{seq}"), end), b.take())
            })
            .collect::<Vec<_>>()
    };
    while let Some(rec) = reader.next_record().context("reading the capture")? {
        match rec {
            CaptureRecord::Receiver(d) => {
                out.declare(&d).await?;
                receivers += 1;
            }
            CaptureRecord::Frame(f) => {
                let t0 = *tick.get_or_insert(f.arrival + cfg.batch_s);
                if f.arrival >= t0 {
                    // Batches end on the tick before this frame (several, empty, over a gap).
                    let mut t = t0;
                    while f.arrival >= t {
                        for (p, h, body) in flush(&mut batches, t, seq, receivers, false) {
                            out.send(nats.names.frames(p), h, body).await?;
                        }
                        stats.batches += n as u64;
                        seq += 1;
                        t += cfg.batch_s;
                    }
                    tick = Some(t);
                }
                match frame_address(&f.frame) {
                    Some(addr) => {
                        batches[partition_of(addr, n) as usize].push(&f);
                        stats.frames += 1;
                    }
                    None => stats.no_address += 1,
                }
            }
        }
    }
    let t = tick.unwrap_or(0.0);
    for (p, h, body) in flush(&mut batches, t, seq, receivers, true) {
        out.send(nats.names.frames(p), h, body).await?;
    }
    stats.batches += n as u64;
    out.settle(0).await?;
    tracing::info!(
        frames = stats.frames,
        batches = stats.batches,
        no_address = stats.no_address,
        skipped_lines = reader.skipped,
        "ingest: capture replayed"
    );
    println!("ingest: frames={} batches={} no_address={}", stats.frames, stats.batches, stats.no_address);
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
    let n = cfg.partitions;
    let mut batches: Vec<BatchWriter> = (0..n).map(|_| BatchWriter::default()).collect();
    let (mut receivers, mut seq, mut latest) = (0usize, 0u64, f64::NEG_INFINITY);
    let run = std::process::id();
    let mut tick = crate::live::unix_now() + cfg.batch_s;
    let wait = std::time::Duration::from_secs_f64(cfg.batch_s / 4.0);
    loop {
        match rx.recv_timeout(wait) {
            Ok(ToCore::Frames { rx: r, arrival, frames, from }) => {
                from.admission.queued.fetch_sub(frames.len(), Ordering::Relaxed);
                registry.queued.fetch_sub(frames.len(), Ordering::Relaxed);
                latest = latest.max(arrival);
                for frame in frames {
                    if let Some(addr) = frame_address(&frame) {
                        let f = crate::feed::capture::CaptureFrame { arrival, rx: r, frame };
                        batches[partition_of(addr, n) as usize].push(&f);
                    }
                }
            }
            Ok(ToCore::AddReceiver(d)) => {
                receivers += 1;
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
        let t = tick.max(latest);
        let period: Vec<(u32, HeaderMap, Vec<u8>)> = (batches.iter_mut().enumerate())
            .map(|(p, b)| {
                (p as u32, batch_headers(t, receivers, &format!("f{run}-{p}-{seq}"), false), b.take())
            })
            .collect();
        seq += 1;
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
            Outgoing::Batches(period) => {
                for (p, h, body) in period {
                    out.send(nats.names.frames(p), h, body).await?;
                }
            }
        }
    }
    out.settle(0).await
}

/// A frame batch's headers.
fn batch_headers(t: f64, receivers: usize, id: &str, end: bool) -> HeaderMap {
    let mut h = HeaderMap::new();
    h.insert(header::TIME, t.to_string().as_str());
    h.insert(header::RECEIVERS, receivers.to_string().as_str());
    h.insert("Nats-Msg-Id", id);
    if end {
        h.insert(header::END, "1");
    }
    h
}
