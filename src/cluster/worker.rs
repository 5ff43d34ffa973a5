//! The worker role: claims partitions and runs one sans-IO core per
//! partition, on a thread of its own (the processing), beside the async
//! tasks that talk to NATS (claims, consumers, publications).
//!
//! A batch is processed once the worker knows every receiver it may name
//! and the clock snapshot is at most `clock_lag_s` behind it; otherwise it
//! waits in its partition's queue while other partitions' batches go on
//! (a worker blocked as a whole could hold back the very partition the
//! clock waits for). Its events and sync notes are stored before it is
//! acknowledged; their message ids are the batch's stream sequence, so a
//! batch processed twice (a takeover) is stored once.

use std::collections::{HashMap, VecDeque};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, Result};
use async_nats::jetstream::Message;
use futures_util::StreamExt;

use super::outage::{retry, Storing};
use super::wire::{self, read_batch, Checkpoint, SyncBatch};
use super::{header, headers, ClusterConfig, Nats};
use crate::core::{Core, CoreConfig, Event};
use crate::feed::capture::ReceiverDecl;
use crate::mlat::shared::SyncSnapshot;

/// One frame batch for the processing thread.
pub(super) struct Batch {
    pub(super) p: u32,
    /// Its stream sequence (0 when the message does not say).
    pub(super) seq: u64,
    pub(super) t: f64,
    pub(super) receivers: usize,
    pub(super) end: bool,
    pub(super) msg: Message,
}

pub(super) enum ToCore {
    /// A new clock snapshot.
    Clock(Arc<SyncSnapshot>),
    Receiver(ReceiverDecl),
    Take(u32, Checkpoint),
    /// A partition whose claim was lost: its core goes.
    Drop(u32),
    /// A partition handed back to a worker that joined: its core goes, its
    /// track numbers are checkpointed, and its results are stored before
    /// its claim is deleted ([`super::claims`]).
    Release(u32),
    Batch(Box<Batch>),
    /// A message on a partition's subject that is no frame batch (skipped).
    Bad,
}

enum FromCore {
    Done {
        p: u32,
        seq: u64,
        t: f64,
        end: bool,
        frames: u64,
        events: Vec<u8>,
        sync: Vec<u8>,
        msg: Box<Message>,
    },
    Checkpoint {
        p: u32,
        bytes: Vec<u8>,
    },
    /// A batch delivered again that this worker already processed (through
    /// a consumer made again): acknowledged without its results, which the
    /// first copy's store carries and precedes this in the queue of stores.
    /// Left unacknowledged, it came back after every `ack_wait`, and enough
    /// of them held the partition's consumer at its pending limit for good.
    Redelivered(Box<Message>),
    /// A partition handed back: once everything before this is stored, its
    /// claim may go.
    Released(u32),
}

/// What the processing thread counts.
#[derive(Clone, Copy, Debug, Default)]
pub struct WorkerStats {
    pub batches: u64,
    pub frames: u64,
    pub bad_batches: u64,
    /// Receiver records of a partition's core: not published (each
    /// partition sees a part of a receiver's traffic).
    pub receiver_records: u64,
    /// Clock pair updates made here: none, the clock service makes them.
    pub sync_updates: u64,
    pub sync_notes: u64,
    pub partitions_taken: u64,
    /// Partitions handed back to a worker that joined.
    pub partitions_handed_back: u64,
    /// Claims found taken by another worker (this one missed its renewals:
    /// starved, or cut off from NATS longer than a lease).
    pub partitions_lost: u64,
    /// Partitions held now.
    pub partitions_held: u64,
    /// Batches delivered again after a consumer was made again (skipped).
    pub redelivered: u64,
}

impl std::fmt::Display for WorkerStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "worker: batches={} frames={} bad_batches={} sync_updates={} sync_notes={} partitions_taken={} \
             partitions_handed_back={} partitions_lost={} partitions_held={} receiver_records_dropped={} redelivered={} nats_retries={} nats_disconnects={}",
            self.batches,
            self.frames,
            self.bad_batches,
            self.sync_updates,
            self.sync_notes,
            self.partitions_taken,
            self.partitions_handed_back,
            self.partitions_lost,
            self.partitions_held,
            self.receiver_records,
            self.redelivered,
            super::outage::retries(),
            super::outage::disconnects()
        )
    }
}

/// One partition's core and its waiting batches.
struct Partition {
    core: Core,
    queue: VecDeque<Batch>,
    started: bool,
    next_checkpoint: f64,
    /// Tracks created when the last checkpoint was made.
    checkpointed_tracks: u64,
    /// The core's pair updates already counted.
    updates_seen: u64,
    /// The stream sequence of the newest batch taken: a consumer made again
    /// delivers again what was not yet acknowledged.
    last_seq: u64,
}

/// The processing thread's state.
struct Processor {
    cfg: ClusterConfig,
    core_cfg: CoreConfig,
    receivers: Vec<ReceiverDecl>,
    parts: HashMap<u32, Partition>,
    /// The newest clock snapshot, and the one the cores have.
    latest: Option<Arc<SyncSnapshot>>,
    loaded: Option<Arc<SyncSnapshot>>,
    out: tokio::sync::mpsc::UnboundedSender<FromCore>,
    stats: WorkerStats,
    shown: Arc<Mutex<WorkerStats>>,
}

impl Processor {
    /// The counts as the process prints them when it ends.
    fn show(&mut self) {
        self.stats.partitions_held = self.parts.len() as u64;
        *self.shown.lock().expect("stats lock") = self.stats;
    }

    fn handle(&mut self, m: ToCore) {
        match m {
            ToCore::Clock(s) => self.latest = Some(s),
            ToCore::Receiver(d) => {
                for part in self.parts.values_mut() {
                    part.core.handle_receiver(d.clone());
                }
                self.receivers.push(d);
            }
            ToCore::Take(p, cp) => {
                let mut core = Core::new(&self.core_cfg);
                core.mlat_mut().share_sync();
                core.fuser_mut().number_tracks(p as u64 + 1, self.cfg.partitions as u64);
                core.fuser_mut().keep_track_numbers(&cp.ids, cp.next_id);
                for d in &self.receivers {
                    core.handle_receiver(d.clone());
                }
                if let Some(s) = &self.loaded {
                    core.mlat_mut().load_sync(s);
                }
                tracing::info!(
                    partition = p,
                    kept_numbers = cp.ids.len(),
                    "partition taken: tracks start again"
                );
                let part = Partition {
                    core,
                    queue: VecDeque::new(),
                    started: false,
                    next_checkpoint: f64::NEG_INFINITY,
                    checkpointed_tracks: 0,
                    updates_seen: 0,
                    last_seq: 0,
                };
                self.parts.insert(p, part);
                self.stats.partitions_taken += 1;
                self.show();
            }
            ToCore::Drop(p) => {
                if self.parts.remove(&p).is_some() {
                    self.stats.partitions_lost += 1;
                    self.show();
                }
            }
            ToCore::Release(p) => {
                // Its batches still waiting go unacknowledged: the next
                // holder's consumer starts from the acknowledgement floor.
                if let Some(part) = self.parts.remove(&p) {
                    let (ids, next_id) = part.core.fuser().track_numbers();
                    let bytes = wire::encode(&Checkpoint { ids, next_id });
                    let _ = self.out.send(FromCore::Checkpoint { p, bytes });
                    self.stats.partitions_handed_back += 1;
                    self.show();
                }
                let _ = self.out.send(FromCore::Released(p));
            }
            ToCore::Bad => {
                self.stats.bad_batches += 1;
                self.show();
            }
            ToCore::Batch(b) => {
                if let Some(part) = self.parts.get_mut(&b.p) {
                    if b.seq != 0 && b.seq <= part.last_seq {
                        self.stats.redelivered += 1;
                        // Acknowledged once the first copy is done: while it
                        // waits in the queue, its own acknowledgement will do.
                        if !part.queue.iter().any(|q| q.seq == b.seq) {
                            let _ = self.out.send(FromCore::Redelivered(Box::new(b.msg)));
                        }
                        return;
                    }
                    part.last_seq = part.last_seq.max(b.seq);
                    // In time order: a batch that NATS lost and the ingest
                    // sent again comes after later ones, and a later one at
                    // the head would wait for the clock while the clock
                    // waits for the earlier one.
                    let at = part.queue.partition_point(|q| q.t <= b.t);
                    part.queue.insert(at, *b);
                }
            }
        }
    }

    /// The newest clock snapshot, loaded into every core when it changed.
    fn refresh_clock(&mut self) {
        if let Some(s) = self.latest.clone() {
            if !self.loaded.as_ref().is_some_and(|l| Arc::ptr_eq(l, &s)) {
                for part in self.parts.values_mut() {
                    part.core.mlat_mut().load_sync(&s);
                }
                self.loaded = Some(s);
            }
        }
    }

    /// Processes every batch that may go now; whether any did.
    fn step(&mut self) -> bool {
        self.refresh_clock();
        let clock_t = self.loaded.as_ref().map_or(f64::NEG_INFINITY, |s| s.t);
        let known = self.receivers.len();
        let lag = self.cfg.clock_lag_s;
        let mut ready = Vec::new();
        for (&p, part) in &mut self.parts {
            while let Some(b) = part.queue.front() {
                let clock_ok = !part.started || b.t - lag <= clock_t || b.end;
                if b.receivers > known || !clock_ok {
                    break;
                }
                let b = part.queue.pop_front().expect("front");
                part.started = true;
                ready.push((p, b));
            }
        }
        let any = !ready.is_empty();
        for (p, b) in ready {
            self.process(p, b);
        }
        any
    }

    fn process(&mut self, p: u32, b: Batch) {
        let part = self.parts.get_mut(&p).expect("a queued partition");
        let frames_before = self.stats.frames;
        let mut events = Vec::new();
        let core = &mut part.core;
        match read_batch(&b.msg.payload, |f| core.handle_frame(f.arrival, f.rx, &f.frame)) {
            Ok(n) => self.stats.frames += n as u64,
            Err(e) => {
                self.stats.bad_batches += 1;
                tracing::warn!(partition = p, error = %e, "frame batch skipped (the frames before the fault were used)");
            }
        }
        part.core.handle_timeout(b.t);
        if b.end {
            part.core.finish();
        }
        events.extend(std::iter::from_fn(|| part.core.poll_event()));
        self.stats.batches += 1;
        // A partition's receiver records would speak for its share of the
        // traffic only: not published. The rest go to the publisher as
        // they are.
        let before = events.len();
        events.retain(|ev| !matches!(ev, Event::Receiver(_)));
        self.stats.receiver_records += (before - events.len()) as u64;
        let events = wire::encode(&events);
        let notes = part.core.mlat_mut().take_sync_notes();
        self.stats.sync_notes += notes.len() as u64;
        // This core's pair updates since the last batch (none, in shared mode).
        let updates = part.core.mlat().sync.stats.updates;
        self.stats.sync_updates += updates - part.updates_seen;
        part.updates_seen = updates;
        let sync = wire::encode(&SyncBatch { partition: p, watermark: b.t, notes });
        // Stored before the batch is acknowledged (one task stores both, in
        // order), and whenever a track was numbered: a worker taking the
        // partition over knows every number given before its floor.
        let created = part.core.fuser().stats().tracks_created;
        if b.t >= part.next_checkpoint || b.end || created != part.checkpointed_tracks {
            part.next_checkpoint = b.t + self.cfg.checkpoint_s;
            part.checkpointed_tracks = created;
            let (ids, next_id) = part.core.fuser().track_numbers();
            let bytes = wire::encode(&Checkpoint { ids, next_id });
            let _ = self.out.send(FromCore::Checkpoint { p, bytes });
        }
        let frames = self.stats.frames - frames_before;
        let done =
            FromCore::Done { p, seq: b.seq, t: b.t, end: b.end, frames, events, sync, msg: Box::new(b.msg) };
        let _ = self.out.send(done);
        self.show();
    }

    fn run(mut self, input: mpsc::Receiver<ToCore>) {
        // Whatever lets a waiting batch go (a snapshot, a receiver, a
        // batch) comes on this channel: no polling.
        while let Ok(m) = input.recv() {
            self.handle(m);
            while let Ok(m) = input.try_recv() {
                self.handle(m);
            }
            while self.step() {}
        }
        tracing::info!(
            batches = self.stats.batches,
            frames = self.stats.frames,
            bad = self.stats.bad_batches,
            "worker: processing ended"
        );
    }
}

/// The worker role until the process ends; `shown` holds its counts.
pub async fn run(
    nats: Arc<Nats>,
    cfg: ClusterConfig,
    mut core_cfg: CoreConfig,
    shown: Arc<Mutex<WorkerStats>>,
) -> Result<()> {
    // Conflicts span partitions: the publisher predicts them.
    core_cfg.fuse.conflict.enabled = false;
    let id = cfg.worker_id.clone().unwrap_or_else(|| {
        let host = std::fs::read_to_string("/etc/hostname").unwrap_or_default();
        format!("{}-{}", host.trim(), std::process::id())
    });
    let (to_core, core_rx) = mpsc::channel::<ToCore>();
    let (out_tx, out_rx) = tokio::sync::mpsc::unbounded_channel::<FromCore>();
    let processor = Processor {
        cfg: cfg.clone(),
        core_cfg,
        receivers: Vec::new(),
        parts: HashMap::new(),
        latest: None,
        loaded: None,
        out: out_tx,
        stats: WorkerStats::default(),
        shown,
    };
    std::thread::Builder::new()
        .name("worker-core".into())
        .spawn(move || processor.run(core_rx))
        .context("cannot start the worker's processing thread")?;
    let mut tasks = tokio::task::JoinSet::new();
    tasks.spawn(watch_clock(nats.clone(), to_core.clone()));
    tasks.spawn(follow_receivers(nats.clone(), to_core.clone()));
    let (handed_tx, handed_rx) = tokio::sync::mpsc::unbounded_channel::<u32>();
    tasks.spawn(store_results(nats.clone(), out_rx, handed_tx));
    tasks.spawn(super::claims::claim_partitions(nats, cfg, id, to_core, handed_rx));
    match tasks.join_next().await {
        Some(Ok(r)) => r,
        Some(Err(e)) => Err(anyhow::anyhow!("a worker task failed: {e}")),
        None => Ok(()),
    }
}

/// Keeps the newest clock snapshot at hand for the processing thread; a
/// watch that fails or ends (NATS away) is made again, and gives the
/// newest snapshot first.
async fn watch_clock(nats: Arc<Nats>, to_core: mpsc::Sender<ToCore>) -> Result<()> {
    loop {
        let mut watch =
            retry("watching the clock snapshot", || nats.clock.watch_with_history("snapshot")).await?;
        while let Some(entry) = watch.next().await {
            let entry = match entry {
                Ok(e) => e,
                Err(e) => {
                    tracing::warn!(error = %e, "clock snapshot watch failed: watching again");
                    break;
                }
            };
            match wire::decode::<SyncSnapshot>(&entry.value) {
                Ok(s) => {
                    if to_core.send(ToCore::Clock(Arc::new(s))).is_err() {
                        return Ok(());
                    }
                }
                Err(e) => tracing::warn!(error = %e, "clock snapshot unreadable: skipped"),
            }
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Every receiver declared, in order, from the first.
async fn follow_receivers(nats: Arc<Nats>, to_core: mpsc::Sender<ToCore>) -> Result<()> {
    let mut declared = nats.receiver_declarations().await?;
    while let Some(d) = declared.next().await {
        if to_core.send(ToCore::Receiver(d?)).is_err() {
            break;
        }
    }
    Ok(())
}

/// Batches whose results may be in flight at once (stored, not yet confirmed).
const IN_FLIGHT: usize = 64;

/// A batch's results sent, waiting for JetStream to confirm them (none
/// for a batch delivered again).
struct Results {
    stores: Option<(Storing, Storing)>,
    msg: Box<Message>,
}

impl Results {
    /// Confirmed stored: the batch is acknowledged (in order, so a
    /// consumer's floor never passes a batch whose results are not stored).
    /// An acknowledgement lost with NATS is not tried again: the batch
    /// comes again after `ack_wait`, and its sequence says it was done.
    async fn settle(self, nats: &Nats) -> Result<()> {
        if let Some((events, sync)) = self.stores {
            events.stored(nats, "storing events").await?;
            sync.stored(nats, "storing sync notes").await?;
        }
        if let Err(e) = self.msg.ack().await {
            tracing::warn!(error = %e, "a frame batch's acknowledgement failed: it will come again");
        }
        Ok(())
    }
}

/// Stores each processed batch's events and sync notes, then acknowledges
/// it; up to [`IN_FLIGHT`] batches' stores overlap.
async fn store_results(
    nats: Arc<Nats>,
    mut rx: tokio::sync::mpsc::UnboundedReceiver<FromCore>,
    handed: tokio::sync::mpsc::UnboundedSender<u32>,
) -> Result<()> {
    let mut pending: VecDeque<Results> = VecDeque::new();
    loop {
        let r = if pending.is_empty() {
            rx.recv().await
        } else {
            match rx.try_recv() {
                Ok(r) => Some(r),
                Err(tokio::sync::mpsc::error::TryRecvError::Empty) => {
                    pending.pop_front().expect("non-empty").settle(&nats).await?;
                    continue;
                }
                Err(tokio::sync::mpsc::error::TryRecvError::Disconnected) => None,
            }
        };
        let Some(r) = r else { break };
        match r {
            FromCore::Done { p, seq, t, end, frames, events, sync, msg } => {
                let h = headers(
                    &format!("e{p}-{seq}"),
                    end,
                    &[(header::TIME, t), (header::FRAMES, frames as f64)],
                );
                let events = nats.send(nats.names.events(p), h, events.into()).await?;
                let h = headers(&format!("s{p}-{seq}"), end, &[]);
                let sync = nats.send(nats.names.sync(p), h, sync.into()).await?;
                pending.push_back(Results { stores: Some((events, sync)), msg });
                if pending.len() >= IN_FLIGHT {
                    pending.pop_front().expect("non-empty").settle(&nats).await?;
                }
            }
            FromCore::Redelivered(msg) => pending.push_back(Results { stores: None, msg }),
            FromCore::Checkpoint { p, bytes } => {
                let bytes = bytes::Bytes::from(bytes);
                retry("storing a checkpoint", || nats.checkpoints.put(p.to_string(), bytes.clone())).await?;
            }
            FromCore::Released(p) => {
                // Everything before it stored and acknowledged, so the next
                // holder starts where this one stopped.
                for r in pending.drain(..) {
                    r.settle(&nats).await?;
                }
                let _ = handed.send(p);
            }
        }
    }
    for s in pending {
        s.settle(&nats).await?;
    }
    Ok(())
}
