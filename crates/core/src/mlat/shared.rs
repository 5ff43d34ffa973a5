//! Clock synchronisation computed once for a cluster of workers.
//!
//! On one node the MLAT engine feeds its own [`ClockSync`]. In a cluster each
//! worker sees the ADS-B aircraft of its partitions only, so no worker can
//! synchronise the network alone, and all of them doing it would repeat the
//! work. Instead a worker's engine, in shared mode, turns every sync
//! transmission into a [`SyncNote`] (the same numbers `observe` would have
//! been given), judges the emitter against the filters it was last sent,
//! and leaves the filters alone; the clock service applies every worker's
//! notes to the one [`ClockSync`] in time order and sends [`SyncSnapshot`]s
//! back. Both are plain data (serde), so the transport is somebody else's
//! concern (`cluster`).
//!
//! Receiver indices are the order of the receivers' declarations, the same
//! in every process, and a counter's local seconds are counted from an
//! epoch every worker derives alike from the timestamp ([`shared_epoch`]),
//! so one worker's times mean the same as another's.

use serde::{Deserialize, Serialize};

use super::clock::PairFilter;
use super::state::SurveySnapshot;
use super::survey::Survey;
use super::sync::{ClockSync, LocalCopy, Reference, RxHealth, SyncStats};
use super::timing::{learn_residuals, Residual, TimingModel};
use crate::feed::capture::ClockKind;

/// A clock reset (a counter's restart) reported by several workers within
/// this many seconds is one reset.
const RESET_DEDUP_S: f64 = 10.0;

/// Beast counter ticks per shared epoch: 2^44 ticks at 12 MHz is about 17
/// days, so local seconds stay below 1.5e6 (a quarter of a nanosecond of
/// f64 resolution), and two workers pick different epochs only if their
/// first frames of a receiver fall either side of a 17-day boundary.
const EPOCH_TICKS: u64 = 1 << 44;

/// The epoch of a counter's local seconds in shared mode, from any of its
/// timestamps: the same in every worker.
pub fn shared_epoch(ts: u64) -> u64 {
    ts & !(EPOCH_TICKS - 1)
}

/// What a worker's engine did to the clocks that the clock service must do once.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum SyncNote {
    /// A sync transmission: the arguments of [`ClockSync::observe`].
    Observed {
        now: f64,
        addr: u32,
        /// (receiver, local seconds) per copy.
        copies: Vec<(u32, f64)>,
        ranges: Vec<f64>,
        var: Vec<f64>,
        geom: Vec<f64>,
    },
    /// A receiver's clock jumped (restart).
    ResetReceiver { now: f64, rx: u32 },
    /// A receiver's position in use changed: its pairs start again.
    ResetPairs { now: f64, rx: u32 },
    /// A fix's lessons for its receivers' timing models; `anchored` when
    /// the fix had a receiver whose timing the configuration gives.
    Timing { now: f64, residuals: Vec<Residual>, anchored: bool },
    /// An ADS-B position's lessons for its receivers' position surveys.
    Survey { now: f64, rows: Vec<SurveyRow> },
}

/// One receiver's excess range at one ADS-B position, as its survey takes it
/// ([`Survey::add`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurveyRow {
    pub rx: u32,
    pub u_enu: [f64; 3],
    pub d_m: f64,
    pub var_m2: f64,
}

impl SyncNote {
    pub fn now(&self) -> f64 {
        match self {
            SyncNote::Observed { now, .. }
            | SyncNote::ResetReceiver { now, .. }
            | SyncNote::ResetPairs { now, .. }
            | SyncNote::Timing { now, .. }
            | SyncNote::Survey { now, .. } => *now,
        }
    }
}

/// The clock service's state as a worker needs it.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct SyncSnapshot {
    /// Data time up to which every worker's notes were applied (s).
    pub t: f64,
    pub pairs: Vec<((u32, u32), PairFilter)>,
    pub health: Vec<RxHealth>,
    pub references: Vec<Reference>,
    pub stats: SyncStats,
    /// Each receiver's learnt timing.
    pub timing: Vec<TimingModel>,
    /// Each receiver's position survey, from every worker's ADS-B traffic.
    #[serde(default)]
    pub surveys: Vec<SurveySnapshot>,
}

/// How the clock service treated a note.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Applied {
    Applied,
    /// A reset another worker had already reported.
    DuplicateReset,
    /// A receiver the service has not been told of.
    UnknownReceiver,
}

/// The clock service's side: the one [`ClockSync`], the receivers' timing
/// models and position surveys, and when each receiver was last reset.
pub struct SharedClock {
    pub sync: ClockSync,
    pub timing: Vec<TimingModel>,
    pub surveys: Vec<Survey>,
    /// Misplaced receivers are used where their surveys put them
    /// (`self_survey`), not left out.
    self_survey: bool,
    last_reset: Vec<f64>,
}

impl SharedClock {
    pub fn new(sync: ClockSync, self_survey: bool) -> Self {
        SharedClock { sync, timing: Vec::new(), surveys: Vec::new(), self_survey, last_reset: Vec::new() }
    }

    /// A receiver, its timing model starting from `prior` (the configured jitter's).
    pub fn add_receiver(&mut self, clock: ClockKind, id: &str, prior: TimingModel) {
        self.sync.add_receiver(clock, id);
        self.timing.push(prior);
        self.surveys.push(Survey::default());
        self.last_reset.push(f64::NEG_INFINITY);
    }

    /// Every receiver's report at `t` as the whole network's clock, timing
    /// models and position surveys say (a receiver whose time jumps is
    /// each worker's to see: its copies never leave the worker).
    pub fn receiver_reports(&self, t: f64) -> Vec<crate::mlat::ReceiverReport> {
        use crate::mlat::engine::{gps_mean_offset, timing_report};
        use crate::mlat::Exclusion;
        let gps_mean = gps_mean_offset(self.sync.clocks.iter().copied().zip(&self.timing));
        (0..self.receivers())
            .map(|rx| {
                let h = &self.sync.health[rx];
                let offset = self.surveys[rx].offset();
                let misplaced = !self.self_survey && offset.is_some_and(|o| o.misplaced());
                let reason = if misplaced {
                    Some(Exclusion::Misplaced)
                } else {
                    h.excluded.then_some(Exclusion::SyncFailing)
                };
                let mut report =
                    timing_report(rx, t, reason, h, self.sync.clocks[rx], &self.timing[rx], gps_mean);
                report.position_offset_en_m = offset.map(|o| [o.enu_m[0], o.enu_m[1]]);
                report.position_offset_sigma_m = offset.map(|o| o.sigma_m);
                report
            })
            .collect()
    }

    pub fn receivers(&self) -> usize {
        self.last_reset.len()
    }

    pub fn apply(&mut self, note: &SyncNote) -> Applied {
        let n = self.receivers();
        match note {
            SyncNote::Observed { now, addr, copies, ranges, var, geom } => {
                if copies.iter().any(|&(rx, _)| rx as usize >= n) {
                    return Applied::UnknownReceiver;
                }
                let local: Vec<LocalCopy> =
                    copies.iter().map(|&(rx, t)| LocalCopy { rx: rx as usize, t }).collect();
                self.sync.observe(&local, ranges, var, geom, *now);
                self.sync.note_reference(&local, *addr);
                Applied::Applied
            }
            SyncNote::Timing { residuals, anchored, .. } => {
                if residuals.iter().any(|r| r.rx() >= n) {
                    return Applied::UnknownReceiver;
                }
                for rx in learn_residuals(residuals, *anchored, &mut self.timing) {
                    self.sync.set_gps_bias(rx, self.timing[rx].offset());
                }
                Applied::Applied
            }
            SyncNote::Survey { now, rows } => {
                if rows.iter().any(|r| r.rx as usize >= n) {
                    return Applied::UnknownReceiver;
                }
                for r in rows {
                    self.surveys[r.rx as usize].add(r.u_enu, r.d_m, r.var_m2, *now);
                }
                Applied::Applied
            }
            SyncNote::ResetReceiver { now, rx } | SyncNote::ResetPairs { now, rx } => {
                let rx = *rx as usize;
                if rx >= n {
                    return Applied::UnknownReceiver;
                }
                if (now - self.last_reset[rx]).abs() < RESET_DEDUP_S {
                    return Applied::DuplicateReset;
                }
                self.last_reset[rx] = *now;
                match note {
                    SyncNote::ResetReceiver { .. } => self.sync.reset_receiver(rx),
                    _ => self.sync.reset_pairs(rx),
                }
                Applied::Applied
            }
        }
    }

    pub fn snapshot(&self, t: f64) -> SyncSnapshot {
        let mut pairs: Vec<((u32, u32), PairFilter)> =
            self.sync.pairs.iter().map(|(&(i, j), f)| ((i as u32, j as u32), f.clone())).collect();
        // In key order, so equal states give equal bytes.
        pairs.sort_unstable_by_key(|p| p.0);
        SyncSnapshot {
            t,
            pairs,
            health: self.sync.health.clone(),
            references: self.sync.references.clone(),
            stats: self.sync.stats,
            timing: self.timing.clone(),
            surveys: self.surveys.iter().map(Survey::snapshot).collect(),
        }
    }
}

impl ClockSync {
    /// Takes the clock service's filters and receiver health in place of
    /// this one's, keeping what is this node's own: the receivers it knows
    /// (a snapshot may know more or fewer) and the GPS receivers' learnt
    /// biases (each worker learns them from its fixes).
    pub fn load_snapshot(&mut self, s: &SyncSnapshot) {
        let n = self.clocks.len();
        self.pairs.clear();
        for peers in &mut self.gps_peers {
            peers.clear();
        }
        for &((i, j), ref f) in &s.pairs {
            let (i, j) = (i as usize, j as usize);
            if i >= n || j >= n {
                continue;
            }
            self.pairs.insert((i, j), f.clone());
            for (a, b) in [(i, j), (j, i)] {
                if self.clocks[b] == ClockKind::Gps {
                    self.gps_peers[a].push(b);
                }
            }
        }
        for peers in &mut self.gps_peers {
            peers.sort_unstable();
            peers.dedup();
        }
        for rx in 0..n {
            // Counted locally: resets a worker saw itself stay in its own tally.
            let resets = self.health[rx].clock_resets;
            self.health[rx] = s.health.get(rx).copied().unwrap_or_default();
            self.health[rx].clock_resets = resets;
            self.references[rx] = s.references.get(rx).copied().unwrap_or_default();
        }
        // The statistics stay this node's own: what it did, not the service.
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlat::clock::PairParams;

    fn network() -> (ClockSync, SharedClock) {
        let mut local = ClockSync::new(PairParams::default());
        let mut service = SharedClock::new(ClockSync::new(PairParams::default()), false);
        for (k, kind) in [ClockKind::Gps, ClockKind::Beast12, ClockKind::Beast12].into_iter().enumerate() {
            local.add_receiver(kind, &format!("r{k}"));
            service.add_receiver(kind, &format!("r{k}"), TimingModel::prior(50e-9));
        }
        (local, service)
    }

    /// A transmission every 0.1 s heard by all three: receiver 1 runs 3 ms
    /// ahead drifting 1 ppm, receiver 2 1 ms behind.
    fn note(k: usize) -> SyncNote {
        let t = k as f64 * 0.1;
        let ranges = vec![30e3, 40e3, 50e3];
        let c = super::super::solver::C_AIR;
        let copies = vec![
            (0, t + ranges[0] / c),
            (1, t + 3e-3 + 1e-6 * t + ranges[1] / c),
            (2, t - 1e-3 + ranges[2] / c),
        ];
        SyncNote::Observed {
            now: 1000.0 + t,
            addr: 0xABCDEF,
            copies,
            ranges,
            var: vec![(50e-9f64).powi(2); 3],
            geom: vec![0.0; 9],
        }
    }

    #[test]
    fn a_node_given_the_services_snapshot_converts_times_as_the_service_does() {
        let (mut local, mut service) = network();
        for k in 0..100 {
            assert_eq!(service.apply(&note(k)), Applied::Applied);
        }
        local.load_snapshot(&service.snapshot(1010.0));
        let copies =
            [LocalCopy { rx: 0, t: 10.0 }, LocalCopy { rx: 1, t: 10.003 }, LocalCopy { rx: 2, t: 9.999 }];
        let (ours, root) = local.common_time(&copies, 1010.0);
        let (theirs, root2) = service.sync.common_time(&copies, 1010.0);
        assert_eq!((&ours, root), (&theirs, root2));
        assert!(ours.iter().all(|t| t.is_some()), "every copy reached: {ours:?}");
        assert_eq!(local.gps_peers(1), &[0]);
        assert_eq!(local.stats.updates, 0, "the node updated no filter itself");
        // The emitter judged against the snapshot: an honest one is about 1
        // per converged pair, one 3 km off disagrees on every pair (each
        // counted at the clip).
        let SyncNote::Observed { copies, ranges, var, geom, .. } = note(100) else { unreachable!() };
        let lc: Vec<LocalCopy> = copies.iter().map(|&(rx, t)| LocalCopy { rx: rx as usize, t }).collect();
        let (nis, judged) = local.judge(&lc, &ranges, &var, &geom);
        assert_eq!(judged, 3);
        assert!(nis / 3.0 < 2.0, "honest emitter: {nis}");
        let off: Vec<f64> = ranges.iter().enumerate().map(|(k, r)| r + [3000.0, -3000.0, 0.0][k]).collect();
        let (bad, _) = local.judge(&lc, &off, &var, &geom);
        assert_eq!(bad, 3.0 * super::super::sync::JUDGE_NIS_CLIP, "offset emitter");
    }

    #[test]
    fn a_reset_reported_by_several_workers_is_applied_once() {
        let (_, mut service) = network();
        for k in 0..20 {
            service.apply(&note(k));
        }
        let pairs = service.sync.pairs().count();
        assert_eq!(pairs, 3);
        assert_eq!(service.apply(&SyncNote::ResetReceiver { now: 1002.0, rx: 1 }), Applied::Applied);
        assert_eq!(service.apply(&SyncNote::ResetReceiver { now: 1002.4, rx: 1 }), Applied::DuplicateReset);
        assert_eq!(service.sync.pairs().count(), 1, "only the pair without receiver 1 is left");
        assert_eq!(service.sync.health[1].clock_resets, 1);
        assert_eq!(service.apply(&SyncNote::ResetPairs { now: 1003.0, rx: 7 }), Applied::UnknownReceiver);
    }

    /// A receiver 150 m east and 90 m south of where it is declared, heard
    /// with aircraft all round: the excess ranges its survey takes.
    fn survey_rows(k: usize) -> Vec<SurveyRow> {
        let (az, el) = ((k as f64 * 0.7).sin_cos(), (k as f64 * 0.3).sin().abs() * 0.2);
        let u_enu = [az.0 * (1.0 - el * el).sqrt(), az.1 * (1.0 - el * el).sqrt(), -el];
        let d_m = 150.0 * u_enu[0] - 90.0 * u_enu[1] + 40.0 + [3.0, -3.0][k % 2];
        vec![SurveyRow { rx: 2, u_enu, d_m, var_m2: 100.0 }]
    }

    #[test]
    fn the_services_survey_of_every_workers_traffic_places_a_misplaced_receiver() {
        for self_survey in [false, true] {
            let mut service = SharedClock::new(ClockSync::new(PairParams::default()), self_survey);
            for k in 0..3 {
                service.add_receiver(ClockKind::Gps, &format!("r{k}"), TimingModel::prior(50e-9));
            }
            let mut one = Survey::default();
            for k in 0..600 {
                // Two workers' notes, each with part of the traffic.
                let note = SyncNote::Survey { now: 1000.0 + k as f64, rows: survey_rows(k) };
                assert_eq!(service.apply(&note), Applied::Applied);
                for r in survey_rows(k) {
                    one.add(r.u_enu, r.d_m, r.var_m2, 1000.0 + k as f64);
                }
            }
            assert_eq!(service.surveys[2], one, "one survey of all the notes");
            let report = &service.receiver_reports(1600.0)[2];
            let [e, n] = report.position_offset_en_m.expect("surveyed");
            assert!((e - 150.0).abs() < 2.0 && (n + 90.0).abs() < 2.0, "{e} {n}");
            // Left out as one node leaves it out, or used where it is.
            let want = (!self_survey).then_some(crate::mlat::Exclusion::Misplaced);
            assert_eq!(report.reason, want);
            assert_eq!(service.receiver_reports(1600.0)[1].position_offset_en_m, None, "never heard");
            let snapshot = service.snapshot(1600.0);
            assert_eq!(Survey::from_snapshot(&snapshot.surveys[2]).as_ref(), Some(&one));
        }
        let mut service = SharedClock::new(ClockSync::new(PairParams::default()), false);
        service.add_receiver(ClockKind::Gps, "r0", TimingModel::prior(50e-9));
        let note = SyncNote::Survey { now: 1.0, rows: survey_rows(0) };
        assert_eq!(service.apply(&note), Applied::UnknownReceiver);
    }

    #[test]
    fn shared_epochs_agree_between_timestamps_of_one_run() {
        let ts = 0x0123_4567_89AB;
        assert_eq!(shared_epoch(ts), shared_epoch(ts + 12_000_000 * 3600));
        assert!(ts - shared_epoch(ts) < EPOCH_TICKS);
    }
}
