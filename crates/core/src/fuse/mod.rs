//! Fusion stage: per aircraft, an ADS-B track, an MLAT track and a fused
//! track, and when to publish them.
//!
//! The fused track is produced by the configured [`Method`]: `measurement`
//! feeds one IMM with both kinds of measurement; the others combine the two
//! single-source tracks at a common time ([`methods`]). Publication follows
//! the track's sampling period (NACp table, densest while in conflict).
//!
//! Why measurements of an MLAT-fed aircraft wait: its fixes arrive half a
//! second after the ADS-B of the same moment (the group wait), so applied at
//! once they would land behind newer ADS-B and make the track re-run every
//! measurement since (a third of all filter steps on a busy world). Instead
//! such an aircraft's measurements wait `mlat_hold_s` in time order and are
//! applied together, the late fix among them in its place; the track goes out
//! right after. Publication waited that long anyway so the fix is in it, and
//! ADS-B-only aircraft are applied and published at once.
//!
//! Measurements are checked before any filter sees them (non-finite values,
//! speeds beyond 1,200 m/s, times far from now): rejected and counted.
//!
//! Here: the aircraft table and the [`Fuser`] that feeds, fuses and
//! publishes; beside it an aircraft of the table and how it starts
//! (`aircraft.rs`), the checks a measurement passes first (`intake.rs`), one
//! measurement into an aircraft's tracks (`tracks.rs`), a publication made
//! (`publication.rs`), the configuration (`config.rs`), what is published
//! (`records.rs`), the MLAT hold's queue (`hold.rs`), the particle filter's
//! aircraft (`sparse.rs`), the fusion methods ([`methods`]), conflict
//! prediction ([`conflict`]) and the ADS-B conformance monitor
//! ([`conformance`]).

mod aircraft;
mod config;
pub mod conflict;
pub mod conformance;
mod hold;
mod intake;
pub mod methods;
pub mod monitor;
mod publication;
mod records;
mod sparse;
#[cfg(test)]
mod tests;
mod tracks;

use crate::FastMap;
use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::{Matrix2, Vector2};

use crate::mlat::engine::TdoaGroup;
use crate::track::imm::ImmSpec;
use crate::track::motion::{Fix2, Motion, MotionTest};
use crate::track::particle::VelocityOutcome;
use crate::track::plane::Plane;
use crate::track::{Estimate, Measurement, Observation, Outcome, Persistent, Source, Track, TrackConfig};
use aircraft::{fresh_tracks, Aircraft};
pub use config::FuseConfig;
pub use conflict::ConflictConfig;
pub use conformance::ConformanceConfig;
use hold::MAX_WAITING;
pub use methods::{Cross, Method};
pub use monitor::ConflictMonitor;
pub use records::{Alert, FuseStats, Output, Sources, SparseStats, TrackReport, TrackSource};

/// Slower tracks (taxiing, parked) are left out of conflict prediction (m/s).
pub const MIN_CONFLICT_SPEED_MPS: f64 = 30.0;

/// An aircraft's time differences are counted over about this long (s):
/// about the memory of a track made of them (a constant-velocity filter's,
/// sqrt(2) (R / (r q))^(1/4), is 20 to 40 s for a time difference's
/// hundreds of metres to a kilometre along the range, at two a second and
/// a white acceleration of 1 m/s^2), so the span over which an error they
/// share (a receiver's learnt offset) adds up in its estimate.
const TDOA_SPAN_S: f64 = 30.0;

/// Speed no aircraft reaches (m/s).
pub const MAX_SPEED_MPS: f64 = 1_200.0;

pub struct Fuser {
    cfg: FuseConfig,
    tcfg: Arc<TrackConfig>,
    spec: Arc<ImmSpec>,
    /// The spec of aircraft not (yet) heard in ADS-B.
    spec_mlat_only: Arc<ImmSpec>,
    /// The static/moving test every new aircraft starts with: its threshold,
    /// a numerical chi-square inverse, is computed once.
    motion: MotionTest,
    /// Boxed: an aircraft is 7 KB, and inline the table was 21 MB on the
    /// scale world, each lookup's probe a cache miss and each growth a move
    /// of every entry; boxed, the probes stay in a table of 16-byte slots.
    aircraft: FastMap<u32, Box<Aircraft>>,
    /// (release time, addr) of each waiting measurement, in release order.
    held: VecDeque<(f64, u32)>,
    next_id: u64,
    /// Track numbers advance by this much (a cluster's partitions number
    /// theirs apart: `first + k * step`).
    id_step: u64,
    /// Numbers a taken-over aircraft keeps (a cluster's checkpoint), and
    /// since when (data time; NaN until the first sweep after the take-over
    /// sees it): kept for a track's drop time, as a track unheard that long
    /// on one node starts again under a new number.
    reserved_ids: FastMap<u32, (u64, f64)>,
    next_sweep: f64,
    monitor: ConflictMonitor,
    pub publish_source_tracks: bool,
    /// Single-source tracks are kept (track-to-track fusion, or published).
    singles: bool,
    /// Particle filters alive (bounded by `sparse.max_filters`).
    sparse_active: usize,
    stats: FuseStats,
}

impl Fuser {
    pub fn new(cfg: FuseConfig, tcfg: TrackConfig, publish_source_tracks: bool) -> Fuser {
        let singles = cfg.method != Method::Measurement || publish_source_tracks;
        let spec = tcfg.imm_spec();
        Fuser {
            spec_mlat_only: tcfg.imm_spec_mlat_only(&spec),
            cfg,
            motion: MotionTest::new(tcfg.motion_window, tcfg.motion_false_alarm),
            tcfg: Arc::new(tcfg),
            spec,
            aircraft: FastMap::default(),
            held: VecDeque::new(),
            next_id: 1,
            id_step: 1,
            reserved_ids: FastMap::default(),
            next_sweep: f64::NEG_INFINITY,
            monitor: ConflictMonitor::new(),
            singles,
            publish_source_tracks,
            sparse_active: 0,
            stats: FuseStats::default(),
        }
    }

    /// Track numbers `first`, `first + step`, ... (a cluster's partition
    /// `p` of `n` takes `p + 1` and `n`, so no two partitions share one).
    pub fn number_tracks(&mut self, first: u64, step: u64) {
        self.next_id = first.max(1);
        self.id_step = step.max(1);
    }

    /// Each aircraft's track number, for a checkpoint; and the next number
    /// this fuser would give.
    pub fn track_numbers(&self) -> (Vec<(u32, u64)>, u64) {
        let mut ids: Vec<(u32, u64)> = self.aircraft.iter().map(|(&addr, a)| (addr, a.id)).collect();
        ids.extend(self.reserved_ids.iter().map(|(&a, &(i, _))| (a, i)));
        ids.sort_unstable();
        (ids, self.next_id)
    }

    /// Takes a checkpoint's numbers: these aircraft keep theirs when their
    /// tracks start here, and new ones continue after `next`.
    pub fn keep_track_numbers(&mut self, ids: &[(u32, u64)], next: u64) {
        self.reserved_ids.extend(ids.iter().map(|&(a, i)| (a, (i, f64::NAN))));
        self.next_id = self.next_id.max(next);
    }

    pub fn stats(&self) -> &FuseStats {
        &self.stats
    }

    pub fn tracks(&self) -> usize {
        self.aircraft.len()
    }

    /// Track numbers a cluster's checkpoint reserved, not yet taken up or
    /// forgotten.
    pub fn reserved_numbers(&self) -> usize {
        self.reserved_ids.len()
    }

    /// Identity and state from messages that carry no position.
    pub fn set_flight(&mut self, addr: u32, flight: String) {
        if let Some(a) = self.aircraft.get_mut(&addr) {
            if a.flight.as_deref() != Some(flight.as_str()) {
                a.flight = Some(flight.into());
            }
        }
    }

    pub fn set_squawk(&mut self, addr: u32, squawk: u16) {
        if let Some(a) = self.aircraft.get_mut(&addr) {
            a.squawk = Some(squawk);
        }
    }

    pub fn set_nav_altitude(&mut self, addr: u32, alt_ft: u32) {
        if let Some(a) = self.aircraft.get_mut(&addr) {
            a.nav_altitude_ft = Some(alt_ft);
        }
    }

    pub fn set_alt_baro(&mut self, addr: u32, alt_ft: i32) {
        if let Some(a) = self.aircraft.get_mut(&addr) {
            a.alt_baro_ft = Some(alt_ft);
        }
    }

    /// A measurement of aircraft `addr`, at arrival time `now`.
    pub fn on_measurement(
        &mut self,
        addr: u32,
        nac_p: Option<u8>,
        mut m: Measurement,
        now: f64,
        out: &mut Vec<Output>,
    ) {
        self.stats.measurements += 1;
        if !intake::valid(&m, now, self.cfg.max_time_error_s, &mut self.stats) {
            return;
        }
        if !self.aircraft.contains_key(&addr) {
            if self.aircraft.len() >= self.tcfg.max_tracks {
                self.stats.table_full += 1;
                return;
            }
            let id = self.reserved_ids.remove(&addr).map(|(id, _)| id).unwrap_or_else(|| {
                self.next_id += self.id_step;
                self.next_id - self.id_step
            });
            let tracks = fresh_tracks(&self.tcfg, &self.spec_mlat_only, self.cfg.method);
            self.stats.tracks_created += 1;
            self.aircraft.insert(addr, Box::new(Aircraft::new(id, tracks, now, self.motion.clone())));
        }
        let a = self.aircraft.get_mut(&addr).expect("inserted");
        a.last_heard = now;
        if let Observation::Position { persistent, .. } = &mut m.obs {
            if persistent.share > 0.0 {
                // A pair filter's error lasts beyond the span: every recent
                // fix of the aircraft shares it, as the time differences'
                // sync errors are.
                let recent = a.fix_recent.add(m.t, TDOA_SPAN_S);
                persistent.shared_by = TdoaGroup::shared_by(recent, f64::INFINITY, TDOA_SPAN_S);
            }
        }
        if let Observation::Height { h, .. } = m.obs {
            a.height = Some((h, m.t));
        }
        if let (Observation::Velocity { v_en, cov, .. }, Some(s)) = (m.obs, a.sparse.as_mut()) {
            // The cloud takes it as it comes (a velocity does not wait for
            // fixes), and the tracks too, should they take over.
            match s.velocity(&self.tcfg.sparse, v_en, cov, m.t) {
                VelocityOutcome::Taken(_) => self.stats.sparse.velocities += 1,
                VelocityOutcome::Contradicts => self.stats.sparse.velocities_contradicting += 1,
                VelocityOutcome::Redrawn => self.stats.sparse.velocities_redrawn += 1,
                VelocityOutcome::Unusable => {}
            }
        }
        if nac_p.is_some() && m.source == Source::Adsb {
            a.nac_p = nac_p;
        }
        let hold = self.cfg.mlat_hold_s;
        let mlat_fed = m.t - a.last_source_t[Source::Mlat as usize] < self.cfg.sources_window_s;
        let waiting = !a.waiting.is_empty();
        if hold > 0.0 && mlat_fed {
            if a.waiting.len() >= MAX_WAITING {
                // A flood of one aircraft: what waits goes in now, not lost.
                self.release(addr, f64::INFINITY, out);
            }
            let a = self.aircraft.get_mut(&addr).expect("present");
            a.waiting.insert(now + hold, m);
            self.held.push_back((now + hold, addr));
            return;
        }
        if waiting {
            // MLAT stopped feeding it: what still waits goes in first, in order.
            self.release(addr, f64::INFINITY, out);
        }
        self.apply(addr, m);
        self.publish(addr, out);
    }

    /// Applies what waited for the hold until `now`: every waiting
    /// measurement up to the newest whose wait is over (older ones that came
    /// late go in with it, in order), then publishes.
    fn release(&mut self, addr: u32, now: f64, out: &mut Vec<Output>) {
        let Some(a) = self.aircraft.get_mut(&addr) else {
            return;
        };
        let n = a.waiting.due(now);
        if n == 0 {
            return;
        }
        // Applied straight from the queue, lent out while `apply` borrows the
        // fuser (it never touches the queue): no copy into a new vector.
        let mut waiting = std::mem::take(&mut a.waiting);
        for m in waiting.take(n) {
            self.apply(addr, m);
        }
        if let Some(a) = self.aircraft.get_mut(&addr) {
            a.waiting = waiting;
        }
        self.publish(addr, out);
    }

    /// Applies one measurement to the aircraft's tracks and marks the track
    /// for publication when it is due. The estimates to publish are taken as
    /// the tracks pass the publication time: asked for later, once newer
    /// measurements of the same release (a velocity after the last position,
    /// say) had moved a track on, each was re-run from the track's history,
    /// which was half of the publications and two thirds of their cost, and
    /// nothing once a release moved a track on by more than its history
    /// reaches back (its reorder window: a stalled input catching up, the end
    /// of a capture), which lost those publications. Measurements go in in
    /// time order from here to the publication, so nothing older than it
    /// comes after; one of the same time takes them again.
    fn apply(&mut self, addr: u32, m: Measurement) {
        let t = m.t;
        self.apply_to_tracks(addr, m);
        let Some(a) = self.aircraft.get_mut(&addr) else {
            return;
        };
        if a.pending != Some(t) {
            return;
        }
        if self.cfg.method == Method::Measurement {
            a.taken.fused = a.fused.estimate_at(t);
        }
        if self.singles {
            a.taken.single = [0, 1].map(|s| a.single[s].estimate_at(t));
        }
    }

    /// The variational-Bayes noise scale of a source's measurements of an
    /// aircraft (1: as good as they claim): from its single-source track when
    /// those are kept, else from the fused track.
    pub fn vb_scale(&self, addr: u32, source: Source) -> Option<f64> {
        let a = self.aircraft.get(&addr)?;
        Some(if self.singles { a.single[source as usize].vb_scale(source) } else { a.fused.vb_scale(source) })
    }

    /// A transmission too few receivers heard for a fix: its time differences
    /// go into the tracks of an aircraft already tracked (they cannot start one).
    pub fn on_tdoa(&mut self, g: &TdoaGroup, now: f64, out: &mut Vec<Output>) {
        if !(2..=3).contains(&g.sites.len()) {
            return;
        }
        let Some(a) = self.aircraft.get_mut(&g.addr) else { return };
        let recent = a.tdoa_recent.add(g.t, TDOA_SPAN_S);
        let n = g.sites.len();
        let mut persistent = [Persistent::default(); 3];
        for (d, &(var_s2, lasts)) in persistent.iter_mut().zip(&g.persistent) {
            *d = Persistent { var_s2, shared_by: TdoaGroup::shared_by(recent, lasts, TDOA_SPAN_S) };
        }
        if !a.fused.has_position() || self.sparse_mirrored(g, &persistent[..n]) {
            return self.sparse_tdoa(g, &persistent[..n], now, out);
        }
        self.release_cloud(g.addr);
        // A track's sites' synchronisation errors go with the persistent
        // ones: taken as each transmission's own, a track that knows the
        // aircraft to metres (its ADS-B) averaged them away and sat several
        // of its sigmas off for minutes where only two or three receivers
        // heard it. (A cloud, whose spread is its geometry's
        // hundreds of metres, takes them as fresh: counted as persistent,
        // its estimates were worse and no more honest.)
        let mut sites = [([0.0; 3], 0.0, 0.0); 3];
        for (k, (d, s)) in sites.iter_mut().zip(&g.sites).enumerate() {
            *d = *s;
            // Part of the site's sigma, which keeps some of its own.
            if let Some(sync) = g.sync_var.get(k).copied().filter(|&v| v > 0.0 && v < s.2 * s.2) {
                d.2 = (s.2 * s.2 - sync).sqrt();
                let p = &mut persistent[k];
                // Lasting beyond the span, it is shared by every recent
                // transmission (as the learnt offset's error mostly is).
                p.var_s2 += sync;
                p.shared_by = TdoaGroup::shared_by(recent, f64::INFINITY, TDOA_SPAN_S);
            }
        }
        let m = Measurement {
            t: g.t,
            source: Source::Mlat,
            obs: Observation::Tdoa { n: n as u8, sites, persistent },
        };
        self.stats.tdoa += 1;
        self.on_measurement(g.addr, None, m, now, out);
    }

    /// The conformance monitor's verdict on an aircraft's ADS-B changed
    /// (`offset_m`, `nis`: the pair that changed it): its ADS-B is kept out
    /// of (or let back into) the fused track, and an alert goes out.
    pub fn set_suspect(
        &mut self,
        addr: u32,
        t: f64,
        suspect: bool,
        offset_m: Option<f64>,
        nis: f64,
        out: &mut Vec<Output>,
    ) {
        let Some(a) = self.aircraft.get_mut(&addr) else {
            return;
        };
        a.adsb_suspect = suspect;
        // Its ADS-B kept out, the fused track is fed by MLAT alone.
        a.fused.set_spec(t, if suspect { &self.spec_mlat_only } else { &self.spec }.clone());
        self.stats.suspect_flags += suspect as u64;
        if suspect {
            tracing::warn!(hex = format!("{addr:06X}"), ?offset_m, "ADS-B position contradicted by timing");
        }
        out.push(Output::Alert(Alert::AdsbSuspect { t, addr, id: a.id, suspect, offset_m, nis }));
    }

    /// Pairs of confirmed tracks in predicted conflict; alerts on changes.
    fn conflicts(&mut self, now: f64, out: &mut Vec<Output>) {
        let kin = self.conflict_kinematics(now);
        let mut alerts = Vec::new();
        let aircraft = &self.aircraft;
        let id = |addr: u32| aircraft.get(&addr).map_or(0, |a| a.id);
        self.stats.conflicts += self.monitor.assess(&self.cfg.conflict, now, &kin, id, &mut alerts);
        for a in self.aircraft.values_mut() {
            a.in_conflict = false;
        }
        for addr in self.monitor.involved() {
            if let Some(a) = self.aircraft.get_mut(&addr) {
                a.in_conflict = true;
            }
        }
        out.extend(alerts.into_iter().map(Output::Alert));
    }

    /// What conflict prediction looks at: each airborne confirmed track's
    /// latest mean (no covariance: this scans thousands of tracks each
    /// time), moved to now along its velocity ([`conflict::kinematics_at`]).
    fn conflict_kinematics(&self, now: f64) -> Vec<conflict::Kinematics> {
        let mut seen: Vec<conflict::Seen> = Vec::with_capacity(self.aircraft.len());
        for (&addr, a) in &self.aircraft {
            // Airborne traffic only: surface movements are not TCAS encounters.
            if !a.fused.confirmed() || a.fused.coasting_at(now, self.tcfg.coast_after_s) || a.surface {
                continue;
            }
            let Some(k) = a.fused.kinematics() else {
                continue;
            };
            let Some(alt_m) = k.alt_m else {
                continue;
            };
            if k.vel_enu[0].hypot(k.vel_enu[1]) < MIN_CONFLICT_SPEED_MPS {
                continue;
            }
            let alt_ft = a.alt_baro_ft.map_or(alt_m / crate::geo::FT_TO_M, f64::from);
            seen.push(conflict::Seen {
                addr,
                t: k.t,
                lat: k.lat,
                lon: k.lon,
                alt_m,
                vel_enu: k.vel_enu,
                alt_ft,
            });
        }
        conflict::kinematics_at(now, seen)
    }

    /// Moves time to `now`: measurements whose wait is over are applied and
    /// their tracks published, and aircraft not heard for the drop time are
    /// forgotten.
    pub fn advance(&mut self, now: f64, out: &mut Vec<Output>) {
        while let Some(&(release, addr)) = self.held.front() {
            if release > now {
                break;
            }
            self.held.pop_front();
            self.release(addr, now, out);
        }
        if self.monitor.due(&self.cfg.conflict, now) {
            self.conflicts(now, out);
        }
        if now >= self.next_sweep {
            self.next_sweep = now + 1.0;
            let drop = self.tcfg.drop_after_s;
            let before = self.aircraft.len();
            let mut filters_dropped = 0;
            self.aircraft.retain(|_, a| {
                let keep = now - a.last_heard <= drop;
                filters_dropped += (!keep && a.sparse.is_some()) as usize;
                keep
            });
            self.sparse_active -= filters_dropped;
            self.reserved_ids.retain(|_, (_, since)| {
                if since.is_nan() {
                    *since = now;
                }
                now - *since <= drop
            });
            self.stats.tracks_dropped += (before - self.aircraft.len()) as u64;
        }
    }

    /// When `advance` next has work: a held publication's release, the
    /// conflict assessment, the once-a-second sweep of aircraft no longer
    /// heard (`None` while there is no aircraft and nothing held).
    pub fn poll_timeout(&self) -> Option<f64> {
        let held = self.held.front().map(|&(release, _)| release);
        if self.aircraft.is_empty() {
            return held;
        }
        [held, self.monitor.next_due(&self.cfg.conflict), Some(self.next_sweep)]
            .into_iter()
            .flatten()
            .reduce(f64::min)
    }

    /// Everything waiting is applied and published (end of input).
    pub fn finish(&mut self, out: &mut Vec<Output>) {
        while let Some((_, addr)) = self.held.pop_front() {
            self.release(addr, f64::INFINITY, out);
        }
    }
}
