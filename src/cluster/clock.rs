//! The clock role: the network's one clock synchronisation.
//!
//! Workers send, per processed batch, their sync notes and the data time
//! their partition has reached. Notes wait here until every partition has
//! reached their time, then are applied in time order (as one node would
//! have met them), and the state is stored as the `snapshot` key of the
//! clock bucket, which the workers watch. A partition's batch at or below
//! the time it had already reached is a replay after a takeover: its notes
//! were applied once and are dropped (counted).
//!
//! [`Merger`] is the sans-IO part, tested without NATS.

use anyhow::Result;
use async_nats::jetstream::consumer::{pull, AckPolicy, DeliverPolicy};

use super::outage::{retry, Follow};
use super::wire::{self, SyncBatch};
use super::{header, ClusterConfig, Mark, Nats, Watermarks};
use crate::core::front::RECEIVER_REPORT_S;
use crate::core::Event;
use crate::mlat::clock::PairParams;
use crate::mlat::shared::{Applied, SharedClock, SyncNote, SyncSnapshot};
use crate::mlat::sync::ClockSync;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClockStats {
    pub batches: u64,
    pub notes: u64,
    pub applied: u64,
    pub replayed_batches: u64,
    pub duplicate_resets: u64,
    pub unknown_receiver: u64,
    pub bad_batches: u64,
    pub snapshots: u64,
    /// Receiver records published.
    pub receiver_records: u64,
}

/// Notes from every partition, applied in time order up to the time all have reached.
pub struct Merger {
    pub clock: SharedClock,
    marks: Watermarks,
    waiting: Vec<(f64, u32, u64, SyncNote)>,
    arrivals: u64,
    applied_to: f64,
    pub stats: ClockStats,
}

impl Merger {
    /// `self_survey`: the configuration's, for what the receiver records
    /// say of a misplaced receiver.
    pub fn new(partitions: u32, params: PairParams, self_survey: bool) -> Self {
        Merger {
            clock: SharedClock::new(ClockSync::new(params), self_survey),
            marks: Watermarks::new(partitions),
            waiting: Vec::new(),
            arrivals: 0,
            applied_to: f64::NEG_INFINITY,
            stats: ClockStats::default(),
        }
    }

    /// One worker batch; a new snapshot when the common time moved on.
    pub fn on_batch(&mut self, b: SyncBatch, end: bool) -> Option<SyncSnapshot> {
        match self.marks.mark(b.partition as usize, b.watermark, end) {
            Mark::Unknown => {
                self.stats.bad_batches += 1;
                return None;
            }
            Mark::Replayed => {
                self.stats.batches += 1;
                self.stats.replayed_batches += 1;
                return None;
            }
            Mark::New => self.stats.batches += 1,
        }
        for note in b.notes {
            self.stats.notes += 1;
            self.arrivals += 1;
            self.waiting.push((note.now(), b.partition, self.arrivals, note));
        }
        let common = self.marks.common();
        if common <= self.applied_to {
            return None;
        }
        self.waiting.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let due = self.waiting.partition_point(|w| w.0 <= common);
        for (_, _, _, note) in self.waiting.drain(..due) {
            match self.clock.apply(&note) {
                Applied::Applied => self.stats.applied += 1,
                Applied::DuplicateReset => self.stats.duplicate_resets += 1,
                Applied::UnknownReceiver => self.stats.unknown_receiver += 1,
            }
        }
        self.applied_to = common;
        self.stats.snapshots += 1;
        let t = if common.is_finite() { common } else { self.marks.newest() };
        Some(self.clock.snapshot(t))
    }

    pub fn all_ended(&self) -> bool {
        self.marks.all_ended()
    }
}

pub async fn run(nats: &Nats, cfg: &ClusterConfig, mlat: &crate::mlat::MlatConfig) -> Result<ClockStats> {
    let mut merger = Merger::new(cfg.partitions, crate::mlat::engine::pair_params(mlat), mlat.self_survey);
    // The receivers, in declaration order, before notes name them.
    let mut declared = nats.receiver_declarations().await?;
    let name = format!("{}-clock", cfg.name);
    // Started again, the clock relearns (`fresh`): its notes from the start
    // are long gone or stale.
    let config = pull::Config {
        durable_name: Some(name),
        ack_policy: AckPolicy::None,
        // From the first: the workers wait for what a late clock would skip.
        deliver_policy: DeliverPolicy::All,
        ..Default::default()
    };
    let mut msgs = Follow::start(&nats.sync, config, true, "the sync notes").await?;
    // Receiver records once a minute of data time, as one node's, and at the end.
    let (mut next_records, mut last_t) = (f64::NAN, f64::NAN);
    loop {
        tokio::select! {
            // Declarations first: a note may name a receiver only just declared.
            biased;
            d = declared.next() => {
                let Some(d) = d else { break };
                let d = d?;
                merger.clock.add_receiver(d.clock, &d.id, crate::mlat::engine::timing_prior(mlat, d.clock));
            }
            m = msgs.next() => {
                let Some(m) = m else { break };
                let m = m?;
                let end = super::is_end(&m.message);
                let batch = match wire::decode::<SyncBatch>(&m.payload) {
                    Ok(b) => b,
                    Err(e) => {
                        merger.stats.bad_batches += 1;
                        tracing::warn!(error = %e, "sync batch unreadable: skipped");
                        continue;
                    }
                };
                if let Some(s) = merger.on_batch(batch, end) {
                    let snapshot = bytes::Bytes::from(wire::encode(&s));
                    retry("storing the clock snapshot", || nats.clock.put("snapshot", snapshot.clone())).await?;
                    if s.t.is_finite() {
                        last_t = s.t;
                        if next_records.is_nan() {
                            next_records = s.t + RECEIVER_REPORT_S;
                        } else if s.t >= next_records {
                            next_records = s.t + RECEIVER_REPORT_S;
                            publish_records(nats, &mut merger, s.t, false).await?;
                        }
                    }
                }
                if merger.all_ended() {
                    publish_records(nats, &mut merger, last_t, true).await?;
                    break;
                }
            }
        }
    }
    let s = merger.stats;
    println!(
        "clock: batches={} notes={} applied={} sync_updates={} replayed_batches={} duplicate_resets={} \
         unknown_receiver={} bad_batches={} snapshots={} receiver_records={} nats_retries={} nats_disconnects={}",
        s.batches,
        s.notes,
        s.applied,
        merger.clock.sync.stats.updates,
        s.replayed_batches,
        s.duplicate_resets,
        s.unknown_receiver,
        s.bad_batches,
        s.snapshots,
        s.receiver_records,
        super::outage::retries(),
        super::outage::disconnects()
    );
    Ok(s)
}

/// Every receiver's record at `t` (the network's: the clock has every
/// receiver's synchronisation and timing), on the events stream's `clock`
/// subject, for the publisher; `end` marks the last.
async fn publish_records(nats: &Nats, merger: &mut Merger, t: f64, end: bool) -> Result<()> {
    let events: Vec<Event> =
        merger.clock.receiver_reports(t).into_iter().map(|r| Event::Receiver(Box::new(r))).collect();
    merger.stats.receiver_records += events.len() as u64;
    let h = super::headers(&format!("r{t}-{end}"), end, &[(header::TIME, t)]);
    nats.store(nats.names.clock_records(), h, wire::encode(&events).into(), "storing the receiver records")
        .await
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::feed::capture::ClockKind;

    fn note(now: f64) -> SyncNote {
        SyncNote::Observed {
            now,
            addr: 1,
            copies: vec![(0, now), (1, now + 1e-3)],
            ranges: vec![1e4, 1e4],
            var: vec![1e-16; 2],
            geom: vec![0.0; 4],
        }
    }

    #[test]
    fn notes_wait_for_every_partition_and_apply_in_time_order_once() {
        let mut m = Merger::new(2, PairParams::default(), false);
        let prior = crate::mlat::timing::TimingModel::prior(50e-9);
        m.clock.add_receiver(ClockKind::Gps, "a", prior);
        m.clock.add_receiver(ClockKind::Beast12, "b", prior);
        let b = |p, w, notes| SyncBatch { partition: p, watermark: w, notes };
        assert!(
            m.on_batch(b(0, 1.0, vec![note(0.5), note(0.9)]), false).is_none(),
            "partition 1 not heard yet"
        );
        let s = m.on_batch(b(1, 0.8, vec![note(0.7)]), false).expect("common time 0.8");
        assert_eq!(s.t, 0.8);
        assert_eq!(m.stats.applied, 2, "0.5 and 0.7; 0.9 waits");
        // A replay of a batch already seen (a takeover) is dropped.
        assert!(m.on_batch(b(1, 0.8, vec![note(0.7)]), false).is_none());
        assert_eq!(m.stats.replayed_batches, 1);
        let s = m.on_batch(b(1, 1.2, vec![]), true).expect("common time 1.0");
        assert_eq!((s.t, m.stats.applied), (1.0, 3));
        assert_eq!(m.clock.sync.stats.updates, 3);
        assert!(!m.all_ended());
        m.on_batch(b(0, 1.3, vec![]), true);
        assert!(m.all_ended());
        assert!(m.on_batch(b(9, 2.0, vec![]), false).is_none());
        assert_eq!(m.stats.bad_batches, 1);
    }
}
