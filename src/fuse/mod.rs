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

pub mod conflict;
pub mod conformance;
pub mod methods;

use crate::FastMap;
use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::{Matrix2, Vector2};
use serde::Deserialize;

use crate::track::imm::ImmSpec;
use crate::track::motion::{Fix2, Motion, MotionTest};
use crate::track::plane::Plane;
use crate::track::{Estimate, Measurement, Observation, Outcome, Source, Stage, Track, TrackConfig};
pub use conflict::ConflictConfig;
pub use conformance::ConformanceConfig;
pub use methods::{Cross, Method};

#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct FuseConfig {
    /// How the fused track is made: measurement, information, convex, ci, reweighted.
    pub method: Method,
    /// How long measurements of an aircraft that MLAT feeds wait, in time
    /// order, before they are applied and the track is published (s): about
    /// the core's group wait, so the fix of the same transmission is in it.
    pub mlat_hold_s: f64,
    /// A source fed a track "lately" within this time (s): `sources`.
    pub sources_window_s: f64,
    /// Measurements more than this far from the present are rejected (s).
    pub max_time_error_s: f64,
    pub conformance: ConformanceConfig,
    pub conflict: ConflictConfig,
}

impl Default for FuseConfig {
    fn default() -> Self {
        FuseConfig {
            method: Method::Measurement,
            mlat_hold_s: 0.6,
            sources_window_s: 10.0,
            max_time_error_s: 10.0,
            conformance: ConformanceConfig::default(),
            conflict: ConflictConfig::default(),
        }
    }
}

impl FuseConfig {
    pub fn validate(&self) -> Result<(), String> {
        let mut errs = Vec::new();
        for (name, v) in [
            ("mlat_hold_s", self.mlat_hold_s),
            ("sources_window_s", self.sources_window_s),
            ("max_time_error_s", self.max_time_error_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                errs.push(format!("{name} = {v} must be zero or positive"));
            }
        }
        if let Err(e) = self.conformance.validate() {
            errs.push(format!("[conformance] {e}"));
        }
        if let Err(e) = self.conflict.validate() {
            errs.push(format!("[conflict] {e}"));
        }
        if errs.is_empty() {
            Ok(())
        } else {
            Err(errs.join("\n"))
        }
    }
}

/// What the fusion stage emits.
#[derive(Clone, Debug, PartialEq)]
pub enum Output {
    Track(Box<TrackReport>),
    Alert(Alert),
}

/// A change worth telling subscribers (contract `type: "alert"`).
#[derive(Clone, Debug, PartialEq)]
pub enum Alert {
    /// The timing contradicts (or again confirms) an aircraft's ADS-B positions.
    AdsbSuspect { t: f64, addr: u32, id: u64, suspect: bool, offset_m: f64, nis: f64 },
    /// A predicted conflict starts (or ends) between two tracks.
    Conflict { t: f64, pair: [(u32, u64); 2], active: bool, tau_s: f64, t_cpa_s: f64, miss_m: f64, dz_m: f64 },
}

/// The sources that fed a track lately, by name; inline (a heap list per
/// published track was measurable).
pub type Sources = smallvec::SmallVec<[&'static str; 2]>;

/// A published track state (contract `type: "track"`).
#[derive(Clone, Debug, PartialEq)]
pub struct TrackReport {
    pub id: u64,
    pub addr: u32,
    pub source: &'static str,
    pub est: Estimate,
    pub alt_baro_ft: Option<i32>,
    pub sources: Sources,
    pub nac_p: Option<u8>,
    pub period_s: f64,
    pub motion: Motion,
    pub adsb_suspect: bool,
    /// Shared with the aircraft: a copy per publication was an allocation.
    pub flight: Option<Arc<str>>,
    pub squawk: Option<u16>,
    /// Age (s) of the newest ADS-B and MLAT measurement, when recent.
    pub ages_s: [Option<f64>; 2],
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FuseStats {
    pub measurements: u64,
    pub rejected_non_finite: u64,
    pub rejected_speed: u64,
    pub rejected_time: u64,
    pub too_late: u64,
    /// Measurements older than one the fused track already had, put in
    /// their place by re-running the newer ones (the MLAT hold keeps these rare).
    pub reruns: u64,
    pub gated: u64,
    pub restarts: u64,
    pub table_full: u64,
    pub tracks_created: u64,
    pub tracks_dropped: u64,
    pub published: u64,
    /// Fusion of two tracks impossible (a covariance not positive definite,
    /// or one track's newest position older than the coasting limit): the
    /// better single track published, once per publication.
    pub fusion_fallbacks: u64,
    /// Conformance flags raised (the monitor itself runs in the core's
    /// front stage, which also keeps flagged ADS-B out of clock sync).
    pub suspect_flags: u64,
    /// ADS-B measurements of flagged aircraft kept out of their fused track.
    pub suspect_excluded: u64,
    /// Groups too small for a fix given to tracks as time differences.
    pub tdoa: u64,
    pub conflicts: u64,
}

/// One line for people (the offline run's report): what came in, what was
/// turned away and why, what went out.
impl std::fmt::Display for FuseStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let rejected: Vec<String> =
            self.rejected().iter().filter(|(_, n)| *n > 0).map(|(k, n)| format!("{k}={n}")).collect();
        write!(
            f,
            "{} measurements, rejected [{}], gated {}, re-run {}; tracks {} created, {} dropped, \
             {} restarts; {} published, fusion fallbacks {}; ADS-B suspect flags {} ({} positions kept out); \
             TDOA updates {}; conflicts {}",
            self.measurements,
            rejected.join(" "),
            self.gated,
            self.reruns,
            self.tracks_created,
            self.tracks_dropped,
            self.restarts,
            self.published,
            self.fusion_fallbacks,
            self.suspect_flags,
            self.suspect_excluded,
            self.tdoa,
            self.conflicts
        )
    }
}

impl FuseStats {
    /// The measurements turned away as bad input, by reason: what the
    /// service exports and sums in its stats line.
    pub fn rejected(&self) -> [(&'static str, u64); 5] {
        [
            ("non_finite", self.rejected_non_finite),
            ("speed", self.rejected_speed),
            ("time", self.rejected_time),
            ("too_late", self.too_late),
            ("table_full", self.table_full),
        ]
    }
}

/// Most measurements of one aircraft waiting for the MLAT hold (about seven
/// a second arrive): a flood is applied early rather than grown without bound.
const MAX_WAITING: usize = 32;

/// One aircraft's measurements waiting for the MLAT hold, in time order.
/// Their times and release times are kept apart from the measurements
/// (152 bytes each) because the search for a late fix's place and the scan
/// for what is due read only those, and with thousands of aircraft the
/// lists are cold: searching the measurements themselves, a cache miss a
/// step, was 8% of the live tracker thread's time at 973 k frames/s.
/// Double-ended: what is due leaves from the front without moving the
/// rest up.
#[derive(Default)]
struct Waiting {
    /// (time of applicability, release time) of each measurement.
    keys: VecDeque<(f64, f64)>,
    ms: VecDeque<Measurement>,
}

impl Waiting {
    fn len(&self) -> usize {
        self.keys.len()
    }

    fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    fn insert(&mut self, release: f64, m: Measurement) {
        // Most come in time order; a late MLAT fix is searched for.
        let i = match self.keys.back() {
            Some(&(t, _)) if t > m.t => self.keys.partition_point(|&(t, _)| t <= m.t),
            _ => self.keys.len(),
        };
        self.keys.insert(i, (m.t, release));
        self.ms.insert(i, m);
    }

    /// How many, from the oldest, go in at `now`: up to the newest whose
    /// wait is over (older ones that came late go in with it).
    fn due(&self, now: f64) -> usize {
        let newest = self.keys.iter().filter(|&&(_, r)| r <= now).map(|&(t, _)| t).reduce(f64::max);
        newest.map_or(0, |upto| self.keys.partition_point(|&(t, _)| t <= upto))
    }

    /// The oldest `n`, taken out in time order.
    fn take(&mut self, n: usize) -> std::collections::vec_deque::Drain<'_, Measurement> {
        self.keys.drain(..n);
        self.ms.drain(..n)
    }
}

/// An active conflict's alert stays up to this many times the predicted miss
/// distance that raises it.
const HOLD_MISS_FACTOR: f64 = 1.25;

/// Slower tracks (taxiing, parked) are left out of conflict prediction (m/s).
const MIN_CONFLICT_SPEED_MPS: f64 = 30.0;

/// Speed no aircraft reaches (m/s).
pub const MAX_SPEED_MPS: f64 = 1_200.0;

/// Estimates taken at the publication time (fused; ADS-B, MLAT).
#[derive(Default)]
struct Taken {
    fused: Option<Estimate>,
    single: [Option<Estimate>; 2],
}

struct Aircraft {
    id: u64,
    fused: Track,
    single: [Track; 2],
    /// Data time of the newest measurement from each source.
    last_source_t: [f64; 2],
    /// Arrival time the aircraft was last heard.
    last_heard: f64,
    next_due: f64,
    /// Time of applicability waiting to be published.
    pending: Option<f64>,
    /// The tracks' estimates at `pending`, taken when they stood there
    /// (see [`Fuser::apply`]).
    taken: Taken,
    /// Measurements waiting for the MLAT hold.
    waiting: Waiting,
    nac_p: Option<u8>,
    alt_baro_ft: Option<i32>,
    flight: Option<Arc<str>>,
    squawk: Option<u16>,
    motion: MotionTest,
    motion_plane: Option<Plane>,
    motion_state: Motion,
    motion_t: f64,
    in_conflict: bool,
    /// An ADS-B measurement has been taken: the tracks use `Fuser::spec`.
    adsb_heard: bool,
    adsb_suspect: bool,
    surface: bool,
    cross: Cross,
}

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
    next_sweep: f64,
    next_conflict: f64,
    /// Active conflicts: the latest assessment and when the pair last met the test.
    conflicts: FastMap<(u32, u32), (conflict::Conflict, f64)>,
    pub publish_source_tracks: bool,
    /// Single-source tracks are kept (track-to-track fusion, or published).
    singles: bool,
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
            next_sweep: f64::NEG_INFINITY,
            next_conflict: f64::NEG_INFINITY,
            conflicts: FastMap::default(),
            singles,
            publish_source_tracks,
            stats: FuseStats::default(),
        }
    }

    pub fn stats(&self) -> &FuseStats {
        &self.stats
    }

    pub fn tracks(&self) -> usize {
        self.aircraft.len()
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

    pub fn set_alt_baro(&mut self, addr: u32, alt_ft: i32) {
        if let Some(a) = self.aircraft.get_mut(&addr) {
            a.alt_baro_ft = Some(alt_ft);
        }
    }

    fn valid(&mut self, m: &Measurement, now: f64) -> bool {
        let finite = m.t.is_finite()
            && match m.obs {
                Observation::Position { lat, lon, cov_en, height, time_sigma_s, .. } => {
                    lat.is_finite()
                        && lon.is_finite()
                        && lat.abs() <= 90.0
                        && cov_en.iter().all(|v| v.is_finite())
                        && cov_en.cholesky().is_some()
                        && height.is_none_or(|(h, v)| h.is_finite() && v > 0.0 && v.is_finite())
                        && time_sigma_s.is_finite()
                }
                Observation::Velocity { v_en, cov, climb } => {
                    v_en.iter().all(|v| v.is_finite())
                        && cov.cholesky().is_some()
                        && climb.is_none_or(|(c, v)| c.is_finite() && v > 0.0 && v.is_finite())
                }
                Observation::Height { h, var } => h.is_finite() && var > 0.0 && var.is_finite(),
                Observation::Tdoa { n, sites } => {
                    (2..=3).contains(&n)
                        && sites[..n as usize].iter().all(|(p, t, s)| {
                            p.iter().all(|v| v.is_finite()) && t.is_finite() && *s > 0.0 && s.is_finite()
                        })
                }
            };
        if !finite {
            self.stats.rejected_non_finite += 1;
            return false;
        }
        if (m.t - now).abs() > self.cfg.max_time_error_s {
            self.stats.rejected_time += 1;
            return false;
        }
        if let Observation::Velocity { v_en, .. } = m.obs {
            if v_en.norm() > MAX_SPEED_MPS {
                self.stats.rejected_speed += 1;
                return false;
            }
        }
        true
    }

    /// A measurement of aircraft `addr`, at arrival time `now`.
    pub fn on_measurement(
        &mut self,
        addr: u32,
        nac_p: Option<u8>,
        m: Measurement,
        now: f64,
        out: &mut Vec<Output>,
    ) {
        self.stats.measurements += 1;
        if !self.valid(&m, now) {
            return;
        }
        if !self.aircraft.contains_key(&addr) {
            if self.aircraft.len() >= self.tcfg.max_tracks {
                self.stats.table_full += 1;
                return;
            }
            let track = Track::new(self.tcfg.clone(), self.spec_mlat_only.clone());
            let mut single = track.clone();
            single.keep_gain = self.cfg.method == Method::Information;
            self.stats.tracks_created += 1;
            self.aircraft.insert(
                addr,
                Box::new(Aircraft {
                    id: self.next_id,
                    fused: track.clone(),
                    single: [single.clone(), single],
                    last_source_t: [f64::NEG_INFINITY; 2],
                    last_heard: now,
                    next_due: f64::NEG_INFINITY,
                    pending: None,
                    taken: Taken::default(),
                    waiting: Waiting::default(),
                    nac_p: None,
                    alt_baro_ft: None,
                    flight: None,
                    squawk: None,
                    motion: self.motion.clone(),
                    motion_plane: None,
                    motion_state: Motion::Unknown,
                    motion_t: f64::NEG_INFINITY,
                    in_conflict: false,
                    adsb_heard: false,
                    adsb_suspect: false,
                    surface: false,
                    cross: Cross::new(),
                }),
            );
            self.next_id += 1;
        }
        let a = self.aircraft.get_mut(&addr).expect("inserted");
        a.last_heard = now;
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

    fn apply_to_tracks(&mut self, addr: u32, m: Measurement) {
        let Some(a) = self.aircraft.get_mut(&addr) else {
            return;
        };
        if m.source == Source::Adsb && !a.adsb_heard {
            // From its first ADS-B on, in time order: a late measurement
            // re-run from the history switches as it did the first time. A
            // fused track whose ADS-B was flagged before any was applied (it
            // waited for the MLAT hold) stays fed by MLAT alone.
            a.adsb_heard = true;
            let fused = (!a.adsb_suspect).then_some(&mut a.fused);
            for track in fused.into_iter().chain(&mut a.single) {
                track.set_spec(m.t, self.spec.clone());
            }
        }
        // A flagged aircraft's ADS-B stays out of the fused track.
        let into_fused = !(a.adsb_suspect && m.source == Source::Adsb);
        let outcome = if into_fused {
            self.stats.reruns += (m.t < a.fused.t()) as u64;
            a.fused.apply(m)
        } else {
            self.stats.suspect_excluded += 1;
            Outcome::Early
        };
        // Single-source tracks cost as much as the fused one: run only when
        // a track-to-track method or their publication needs them.
        let single = if self.singles {
            a.single[m.source as usize].apply(m)
        } else if into_fused {
            outcome
        } else {
            Outcome::Applied { nis: 0.0 }
        };
        if self.singles && a.single[0].keep_gain {
            let model = self.spec.models[0];
            let f_q = |dt: f64| model.transition(dt);
            match (single, a.single[m.source as usize].gain) {
                (Outcome::Restarted, _) => a.cross = Cross::new(),
                (Outcome::Applied { .. }, Some((t, g))) if t == m.t => {
                    a.cross.update(t, m.source == Source::Adsb, &g, f_q)
                }
                _ => {}
            }
        }
        match outcome {
            Outcome::TooLate => self.stats.too_late += 1,
            Outcome::Gated => self.stats.gated += 1,
            Outcome::Restarted => self.stats.restarts += 1,
            _ => {}
        }
        if !matches!(m.obs, Observation::Position { .. } | Observation::Tdoa { .. }) {
            return;
        }
        if matches!(single, Outcome::Applied { .. } | Outcome::Restarted) {
            a.last_source_t[m.source as usize] = a.last_source_t[m.source as usize].max(m.t);
        }
        if let Observation::Position { lat, lon, cov_en, surface, .. } = m.obs {
            a.surface = surface;
            if m.t - a.motion_t >= self.tcfg.motion_interval_s {
                a.motion_t = m.t;
                Self::motion(a, lat, lon, cov_en);
            }
        }
        if !matches!(outcome, Outcome::Applied { .. }) || a.fused.stage != Stage::Confirmed {
            return;
        }
        // Due already in this batch: it goes out at its newest measurement
        // (the ADS-B a moment after its own transmission's fix, say).
        if let Some(p) = a.pending {
            a.pending = Some(p.max(m.t));
            return;
        }
        if m.t < a.next_due {
            return;
        }
        let period = a.period_s(&self.tcfg);
        if !a.next_due.is_finite() {
            a.next_due = m.t;
        }
        while a.next_due <= m.t {
            a.next_due += period;
        }
        a.pending = Some(m.t);
    }

    /// The static/moving test over the aircraft's recent position
    /// measurements; an airborne aircraft faster than a taxiing one moves
    /// without the test (which costs a small matrix factorisation).
    fn motion(a: &mut Aircraft, lat: f64, lon: f64, cov: Matrix2<f64>) {
        if !a.surface && a.fused.speed().is_some_and(|v| v > 30.0) {
            a.motion_state = Motion::Moving;
            return;
        }
        let plane = match a.motion_plane {
            Some(p) if crate::geo::distance_m(p.lat, p.lon, lat, lon) < 5_000.0 => p,
            _ => {
                let p = Plane::new(lat, lon, 0.0);
                a.motion_plane = Some(p);
                a.motion.restart();
                p
            }
        };
        let en = plane.to_en(lat, lon);
        a.motion_state = a.motion.push(Fix2 { pos: Vector2::new(en[0], en[1]), cov });
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
    pub fn on_tdoa(&mut self, g: &crate::mlat::engine::TdoaGroup, now: f64, out: &mut Vec<Output>) {
        if !self.aircraft.get(&g.addr).is_some_and(|a| a.fused.has_position())
            || !(2..=3).contains(&g.sites.len())
        {
            return;
        }
        let mut sites = [([0.0; 3], 0.0, 0.0); 3];
        for (d, s) in sites.iter_mut().zip(&g.sites) {
            *d = *s;
        }
        let m = Measurement {
            t: g.t,
            source: Source::Mlat,
            obs: Observation::Tdoa { n: g.sites.len() as u8, sites },
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
        offset_m: f64,
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
            tracing::warn!(hex = format!("{addr:06X}"), offset_m, "ADS-B position contradicted by timing");
        }
        out.push(Output::Alert(Alert::AdsbSuspect { t, addr, id: a.id, suspect, offset_m, nis }));
    }

    /// Pairs of confirmed tracks in predicted conflict; alerts on changes.
    fn conflicts(&mut self, now: f64, out: &mut Vec<Output>) {
        // Each track's latest mean (no covariance: this scans thousands of
        // tracks each time), moved to now along its velocity, then in
        // address order: the frame's origin (and so every figure) must not
        // depend on the hash map's order, or runs would differ.
        let mut seen: Vec<(u32, f64, f64, crate::track::track::Kinematics)> =
            Vec::with_capacity(self.aircraft.len());
        for (&addr, a) in &self.aircraft {
            // Airborne traffic only: surface movements are not TCAS encounters.
            if a.fused.stage != Stage::Confirmed
                || now - a.fused.last_position_t > self.tcfg.coast_after_s
                || a.surface
            {
                continue;
            }
            let Some(k) = a.fused.kinematics() else {
                continue;
            };
            let Some(alt) = k.alt_m else {
                continue;
            };
            if k.vel_enu[0].hypot(k.vel_enu[1]) < MIN_CONFLICT_SPEED_MPS {
                continue;
            }
            let alt_ft = a.alt_baro_ft.map_or(alt / crate::geo::FT_TO_M, f64::from);
            seen.push((addr, alt, alt_ft, k));
        }
        seen.sort_unstable_by_key(|s| s.0);
        let kin: Vec<conflict::Kinematics> = match seen.first() {
            None => Vec::new(),
            Some(first) => {
                let origin = Plane::new(first.3.lat, first.3.lon, 0.0);
                seen.iter()
                    .map(|&(addr, alt, alt_ft, k)| {
                        let en = origin.to_en(k.lat, k.lon);
                        let (v, dt) = (k.vel_enu, (now - k.t).max(0.0));
                        let pos = [en[0] + v[0] * dt, en[1] + v[1] * dt, alt + v[2] * dt];
                        conflict::Kinematics { addr, pos, vel: v, alt_ft }
                    })
                    .collect()
            }
        };
        // An active pair keeps its alert up to a predicted miss a quarter
        // larger than the one that raises it, and until it has failed the
        // test for `clear_after_s`: pairs passing about the limit apart
        // raised and cleared alerts every few seconds.
        let cfg = &self.cfg.conflict;
        let raise_m = cfg.max_miss_nm * conflict::NM;
        let relaxed =
            conflict::ConflictConfig { max_miss_nm: cfg.max_miss_nm * HOLD_MISS_FACTOR, ..cfg.clone() };
        let mut found: FastMap<(u32, u32), (conflict::Conflict, f64)> = conflict::find(&relaxed, &kin)
            .into_iter()
            .map(|c| ((c.a.min(c.b), c.a.max(c.b)), (c, now)))
            .filter(|(k, (c, _))| c.miss_m < raise_m || self.conflicts.contains_key(k))
            .collect();
        let hold = cfg.clear_after_s;
        for (k, &(c, met)) in &self.conflicts {
            if !found.contains_key(k) && now - met < hold {
                found.insert(*k, (c, met));
            }
        }
        for a in self.aircraft.values_mut() {
            a.in_conflict = false;
        }
        for &(x, y) in found.keys() {
            for addr in [x, y] {
                if let Some(a) = self.aircraft.get_mut(&addr) {
                    a.in_conflict = true;
                }
            }
        }
        let id = |aircraft: &FastMap<u32, Box<Aircraft>>, addr: u32| aircraft.get(&addr).map_or(0, |a| a.id);
        let mut changes: Vec<(bool, conflict::Conflict)> = found
            .iter()
            .filter(|(k, _)| !self.conflicts.contains_key(k))
            .map(|(_, (c, _))| (true, *c))
            .chain(
                self.conflicts.iter().filter(|(k, _)| !found.contains_key(k)).map(|(_, (c, _))| (false, *c)),
            )
            .collect();
        changes.sort_by_key(|(active, c)| (!active, c.a.min(c.b), c.a.max(c.b)));
        for (active, c) in changes {
            self.stats.conflicts += active as u64;
            out.push(Output::Alert(Alert::Conflict {
                t: now,
                pair: [(c.a, id(&self.aircraft, c.a)), (c.b, id(&self.aircraft, c.b))],
                active,
                tau_s: c.tau_s,
                t_cpa_s: c.t_cpa_s,
                miss_m: c.miss_m,
                dz_m: c.dz_m,
            }));
        }
        self.conflicts = found;
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
        if self.cfg.conflict.enabled && now >= self.next_conflict {
            self.next_conflict = now + self.cfg.conflict.interval_s;
            self.conflicts(now, out);
        }
        if now >= self.next_sweep {
            self.next_sweep = now + 1.0;
            let drop = self.tcfg.drop_after_s;
            let before = self.aircraft.len();
            self.aircraft.retain(|_, a| now - a.last_heard <= drop);
            self.stats.tracks_dropped += (before - self.aircraft.len()) as u64;
        }
    }

    /// Everything waiting is applied and published (end of input).
    pub fn finish(&mut self, out: &mut Vec<Output>) {
        while let Some((_, addr)) = self.held.pop_front() {
            self.release(addr, f64::INFINITY, out);
        }
    }

    fn publish(&mut self, addr: u32, out: &mut Vec<Output>) {
        let Some(a) = self.aircraft.get_mut(&addr) else {
            return;
        };
        let Some(t) = a.pending.take() else {
            return;
        };
        let period = a.period_s(&self.tcfg);
        let window = self.cfg.sources_window_s;
        // Time since the source's newest position.
        let age = |s: Source| t - a.last_source_t[s as usize];
        let sources = [Source::Adsb, Source::Mlat]
            .into_iter()
            .filter(|&s| age(s) <= window)
            .map(Source::name)
            .collect();
        // A coasting single-source track (no position lately) is not fused.
        let coast = self.tcfg.coast_after_s;
        let confirmed = |s: Source| a.single[s as usize].stage == Stage::Confirmed;
        let taken = std::mem::take(&mut a.taken);
        // Asked now, a track answers as it did at `t` from its history, or
        // nothing once its history no longer reaches back that far.
        let as_taken = |track: &Track, est: Option<Estimate>| {
            debug_assert!(track.estimate_at(t).is_none_or(|now| Some(now) == est), "estimate at {t}");
            est
        };
        let single = |s: Source| {
            let est = as_taken(&a.single[s as usize], taken.single[s as usize]);
            est.filter(|_| age(s) <= coast && confirmed(s))
        };
        let (adsb, mlat) = (single(Source::Adsb), single(Source::Mlat));
        // A confirmed track whose source is still heard of (within the
        // sources window) but whose newest position is older than the
        // coasting limit: predicting it that far is not aligning it.
        let stale = |s: Source| confirmed(s) && age(s) > coast && age(s) <= window;
        let fused = match self.cfg.method {
            Method::Measurement => as_taken(&a.fused, taken.fused),
            method => match (adsb.filter(|_| !a.adsb_suspect), mlat) {
                (Some(x), Some(y)) => match methods::fuse(
                    method,
                    &x,
                    &y,
                    Some(&a.cross.at(t, |dt| self.spec.models[0].transition(dt))),
                ) {
                    Some(f) => Some(f),
                    None => {
                        self.stats.fusion_fallbacks += 1;
                        Some(methods::better(&x, &y))
                    }
                },
                (x, y) => {
                    // (ADS-B left out as suspect is left out on purpose.)
                    let missing = if x.is_none() { Source::Adsb } else { Source::Mlat };
                    let suspect = missing == Source::Adsb && a.adsb_suspect;
                    if x.is_some() != y.is_some() && stale(missing) && !suspect {
                        self.stats.fusion_fallbacks += 1;
                    }
                    x.or(y)
                }
            },
        };
        let report = |source: &'static str, est: Estimate, sources: Sources| TrackReport {
            id: a.id,
            addr,
            source,
            est,
            alt_baro_ft: a.alt_baro_ft,
            sources,
            nac_p: a.nac_p,
            period_s: period,
            motion: a.motion_state,
            adsb_suspect: a.adsb_suspect,
            flight: a.flight.clone(),
            squawk: a.squawk,
            ages_s: [Source::Adsb, Source::Mlat].map(|s| Some(age(s).max(0.0)).filter(|age| *age <= window)),
        };
        if let Some(est) = fused {
            out.push(Output::Track(Box::new(report("fused", est, sources))));
            self.stats.published += 1;
        }
        if self.publish_source_tracks {
            for (s, est) in [(Source::Adsb, adsb), (Source::Mlat, mlat)] {
                if let Some(est) = est {
                    out.push(Output::Track(Box::new(report(s.name(), est, smallvec::smallvec![s.name()]))));
                }
            }
        }
    }
}

impl Aircraft {
    /// The sampling period in force: the NACp table's, the densest in conflict.
    fn period_s(&self, cfg: &TrackConfig) -> f64 {
        if self.in_conflict {
            cfg.densest_period_s()
        } else {
            cfg.period_s(self.nac_p)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pos(t: f64, lat: f64, lon: f64) -> Measurement {
        Measurement {
            t,
            source: Source::Adsb,
            obs: Observation::Position {
                lat,
                lon,
                cov_en: Matrix2::identity() * 100.0,
                height: Some((3000.0, 100.0)),
                time_sigma_s: 0.0,
                surface: false,
                claimed: true,
            },
        }
    }

    /// Where the test flight is at `t`: east at 200 m/s from (45, 5) at 3 km,
    /// from t = 100 s.
    fn at(t: f64) -> (f64, f64, f64) {
        crate::geo::displace(45.0, 5.0, 3000.0, [200.0 * (t - 100.0), 0.0, 0.0])
    }

    /// An MLAT fix of the test flight at `t`, exact.
    fn fix(t: f64) -> Measurement {
        let (lat, lon, _) = at(t);
        Measurement { source: Source::Mlat, ..pos(t, lat, lon) }
    }

    #[test]
    fn impossible_measurements_are_rejected_and_counted() {
        let mut f = Fuser::new(FuseConfig::default(), TrackConfig::default(), false);
        let mut out = Vec::new();
        f.on_measurement(1, Some(8), pos(100.0, f64::NAN, 5.0), 100.0, &mut out);
        f.on_measurement(1, Some(8), pos(100.0, 45.0, 5.0), 200.0, &mut out);
        let fast = Measurement {
            t: 100.0,
            source: Source::Adsb,
            obs: Observation::Velocity {
                v_en: Vector2::new(1300.0, 0.0),
                cov: Matrix2::identity(),
                climb: None,
            },
        };
        f.on_measurement(1, Some(8), fast, 100.0, &mut out);
        let bad_cov = Measurement {
            obs: Observation::Position {
                lat: 45.0,
                lon: 5.0,
                cov_en: -Matrix2::identity(),
                height: None,
                time_sigma_s: 0.0,
                surface: false,
                claimed: true,
            },
            ..pos(100.0, 45.0, 5.0)
        };
        f.on_measurement(1, Some(8), bad_cov, 100.0, &mut out);
        let s = f.stats();
        assert_eq!((s.rejected_non_finite, s.rejected_time, s.rejected_speed), (2, 1, 1));
        assert_eq!(f.tracks(), 0);
        assert!(out.is_empty());
        // Good ones make a confirmed, published track.
        for k in 0..5 {
            let t = 100.0 + k as f64;
            let (lat, lon, _) = at(t);
            f.on_measurement(1, Some(8), pos(t, lat, lon), t, &mut out);
        }
        assert!(out.iter().any(|o| matches!(o, Output::Track(r) if r.est.state.healthy())));
    }

    /// An aircraft flying east at 200 m/s for a minute: ADS-B positions at
    /// 2 Hz on time, an MLAT fix a second (for the first `mlat_s` seconds)
    /// arriving 0.5 s after its time; the core moves time forward before
    /// each arrival. Returns each publication's (arrival time, track time)
    /// and the stats.
    fn mlat_fed_flight(hold_s: f64, mlat_s: f64) -> (Vec<(f64, f64)>, FuseStats) {
        let cfg = FuseConfig { mlat_hold_s: hold_s, ..FuseConfig::default() };
        let (published, stats) = flight(cfg, false, mlat_s);
        (published.iter().map(|(now, r)| (*now, r.est.t)).collect(), stats)
    }

    /// The flight of [`mlat_fed_flight`] through a fuser of `cfg`: every
    /// track record with its arrival time, and the stats.
    fn flight(cfg: FuseConfig, source_tracks: bool, mlat_s: f64) -> (Vec<(f64, TrackReport)>, FuseStats) {
        let mut f = Fuser::new(cfg, TrackConfig::default(), source_tracks);
        let mut arrivals: Vec<(f64, Measurement)> = Vec::new();
        for k in 0..120 {
            let t = 100.0 + 0.5 * k as f64;
            let (lat, lon, _) = at(t);
            arrivals.push((t, pos(t, lat, lon)));
            if k % 2 == 1 && t < 100.0 + mlat_s {
                let tf = t + 0.25;
                let (lat, lon, _) = at(tf);
                arrivals.push((tf + 0.5, Measurement { source: Source::Mlat, ..pos(tf, lat, lon) }));
            }
        }
        arrivals.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut out, mut published) = (Vec::new(), Vec::new());
        let mut collect = |out: &mut Vec<Output>, now: f64| {
            for o in out.drain(..) {
                if let Output::Track(r) = o {
                    published.push((now, *r));
                }
            }
        };
        for (now, m) in arrivals {
            f.advance(now, &mut out);
            f.on_measurement(1, Some(8), m, now, &mut out);
            collect(&mut out, now);
        }
        f.finish(&mut out);
        collect(&mut out, f64::INFINITY);
        (published, *f.stats())
    }

    /// The fused records of an aircraft flying straight (east at 200 m/s)
    /// for five minutes, multilaterated as by a sparse network: 150 m per
    /// axis every 0.7 s, each fix arriving 0.5 s after its time; with one
    /// ADS-B position first when `adsb_first`, its ADS-B then flagged as
    /// suspect when `suspect`.
    fn multilaterated(mlat_only: bool, seed: u64, adsb_first: bool, suspect: bool) -> Vec<TrackReport> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut tcfg = TrackConfig::default();
        tcfg.mlat_only.enabled = mlat_only;
        let mut f = Fuser::new(FuseConfig::default(), tcfg, false);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, 150.0).expect("sigma");
        let mut out = Vec::new();
        if adsb_first {
            let (lat, lon, _) = at(100.0);
            f.on_measurement(1, Some(8), pos(100.0, lat, lon), 100.0, &mut out);
            if suspect {
                f.set_suspect(1, 100.0, true, 2000.0, 100.0, &mut out);
            }
        }
        for k in 1..430 {
            let t = 100.0 + 0.7 * k as f64;
            let e = [noise.sample(&mut rng), noise.sample(&mut rng), 0.0];
            let (lat, lon, h) = at(t);
            let (lat, lon, _) = crate::geo::displace(lat, lon, h, e);
            let m = Measurement {
                source: Source::Mlat,
                obs: Observation::Position {
                    lat,
                    lon,
                    cov_en: Matrix2::identity() * 150.0f64.powi(2),
                    height: Some((3000.0, 100.0)),
                    time_sigma_s: 0.0,
                    surface: false,
                    claimed: true,
                },
                ..pos(t, lat, lon)
            };
            f.advance(t + 0.5, &mut out);
            f.on_measurement(1, None, m, t + 0.5, &mut out);
        }
        f.finish(&mut out);
        out.into_iter()
            .filter_map(|o| match o {
                Output::Track(r) if r.source == "fused" => Some(*r),
                _ => None,
            })
            .collect()
    }

    /// An aircraft heard only through MLAT, hundreds of metres per fix, flying
    /// straight: with the matrix that keeps to constant velocity its track
    /// is closer to the truth than with the matrix of ADS-B aircraft, whose
    /// manoeuvre models then keep three quarters of the weight, and its
    /// covariance still covers the error (straight flight is where an IMM
    /// is most conservative: both are). So does one whose ADS-B is kept out
    /// as suspect; an aircraft heard in ADS-B switches like any other.
    #[test]
    fn an_aircraft_heard_only_by_mlat_keeps_to_constant_velocity() {
        // RMS error and mean NEES after the first 30 s, over 20 runs.
        let score = |mlat_only: bool, suspect: bool| {
            let (mut se, mut nees, mut n) = (0.0, 0.0, 0usize);
            for seed in 1..=20 {
                let records = multilaterated(mlat_only, seed, suspect, suspect);
                for r in records.iter().filter(|r| r.est.t > 130.0) {
                    let (lat, lon, _) = at(r.est.t);
                    let plane = Plane::new(lat, lon, 3000.0);
                    let d = Vector2::from(plane.to_en(r.est.lat, r.est.lon));
                    let c = Matrix2::from_fn(|i, j| r.est.cov_local[i][j]);
                    se += d.norm_squared();
                    nees += d.dot(&(c.try_inverse().expect("covariance") * d));
                    n += 1;
                }
            }
            ((se / n as f64).sqrt(), nees / n as f64)
        };
        let (rmse_home, nees_home) = score(true, false);
        let (rmse_sticky, nees_sticky) = score(false, false);
        eprintln!("MLAT only: {rmse_home:.1} m NEES {nees_home:.2}; as ADS-B aircraft: {rmse_sticky:.1} m NEES {nees_sticky:.2}");
        assert!(rmse_home < 0.8 * rmse_sticky, "{rmse_home} against {rmse_sticky}");
        assert!(nees_home > 1.2 && nees_home < 2.0, "{nees_home}");
        let (rmse_suspect, _) = score(true, true);
        let (rmse_suspect_sticky, _) = score(false, true);
        eprintln!("flagged as suspect: {rmse_suspect:.1} m; as ADS-B aircraft: {rmse_suspect_sticky:.1} m");
        assert!(rmse_suspect < 0.8 * rmse_suspect_sticky, "{rmse_suspect} against {rmse_suspect_sticky}");
        // Heard in ADS-B first: the same records whichever matrix MLAT-only
        // aircraft would have.
        assert_eq!(multilaterated(true, 1, true, false), multilaterated(false, 1, true, false));
    }

    /// Track-to-track fusion of a pair too far apart in time: once the MLAT
    /// track's newest fix is older than the coasting limit, the fresh ADS-B
    /// track goes out as it is, and each such publication is counted until
    /// the MLAT source leaves the sources window.
    #[test]
    fn a_pair_too_far_apart_to_align_is_not_fused_and_is_counted() {
        let cfg = FuseConfig { method: Method::Convex, ..FuseConfig::default() };
        let (coast, window) = (TrackConfig::default().coast_after_s, cfg.sources_window_s);
        let (published, stats) = flight(cfg, true, 20.0);
        let last_fix = 100.0 + 19.5 + 0.25;
        // Fused and ADS-B records of the same publication, by track time.
        let pairs: Vec<(f64, &TrackReport, &TrackReport)> = published
            .iter()
            .filter(|(_, r)| r.source == "fused")
            .filter_map(|(_, fused)| {
                let adsb = published.iter().find(|(_, r)| r.source == "adsb" && r.est.t == fused.est.t)?;
                Some((fused.est.t - last_fix, fused, &adsb.1))
            })
            .collect();
        let same = |a: &TrackReport, b: &TrackReport| {
            a.est.state.x == b.est.state.x && a.est.state.p == b.est.state.p
        };
        // Fused while both are fresh, once the MLAT track is confirmed (its
        // third fix, at about 102.75).
        let fused_while_both =
            pairs.iter().filter(|(age, ..)| (-15.0..0.0).contains(age)).collect::<Vec<_>>();
        assert!(fused_while_both.len() > 20 && fused_while_both.iter().all(|(_, f, a)| !same(f, a)));
        let unaligned: Vec<_> = pairs.iter().filter(|(age, ..)| *age > coast && *age <= window).collect();
        assert!(unaligned.len() >= 10 && unaligned.iter().all(|(_, f, a)| same(f, a)), "{}", unaligned.len());
        assert_eq!(stats.fusion_fallbacks, unaligned.len() as u64, "{stats:?}");
    }

    #[test]
    fn an_mlat_fed_track_takes_late_fixes_in_order_and_keeps_its_period() {
        let (held, stats) = mlat_fed_flight(0.6, 60.0);
        // Only the very first fix (before the aircraft counts as MLAT-fed)
        // lands behind newer ADS-B; without the hold every fix does.
        assert!(stats.reruns <= 1, "{stats:?}");
        assert!(mlat_fed_flight(0.0, 60.0).1.reruns >= 50);
        // NACp 8: one publication per 0.6 s over the ~57 s after confirmation,
        // each at a newer time than the last, about the hold after its time.
        assert!((90..=100).contains(&held.len()), "{}", held.len());
        assert!(held.windows(2).all(|w| w[1].1 > w[0].1));
        let gaps = held.windows(2).map(|w| w[1].1 - w[0].1).sum::<f64>() / (held.len() - 1) as f64;
        assert!((gaps - 0.6).abs() < 0.05, "mean gap {gaps}");
        assert!(held[5..held.len() - 1].iter().all(|(now, t)| (0.5..=1.0).contains(&(now - t))), "{held:?}");
    }

    #[test]
    fn the_hold_keeps_measurements_in_time_order_and_releases_up_to_the_newest_due() {
        let mut w = Waiting::default();
        // (time, release): a late fix (t 10.2) arrives after newer ADS-B.
        for (t, r) in [(10.0, 10.6), (10.4, 11.0), (10.6, 11.2), (10.2, 11.3), (10.8, 11.4)] {
            w.insert(r, pos(t, 45.0, 5.0));
        }
        let times = |w: &Waiting| w.ms.iter().map(|m| m.t).collect::<Vec<_>>();
        assert_eq!(times(&w), [10.0, 10.2, 10.4, 10.6, 10.8]);
        assert_eq!(w.due(10.5), 0);
        // At 11.2 the newest due is 10.6: the late 10.2 goes with it.
        assert_eq!(w.due(11.2), 4);
        let out: Vec<f64> = w.take(4).map(|m| m.t).collect();
        assert_eq!(out, [10.0, 10.2, 10.4, 10.6]);
        assert_eq!((w.len(), times(&w)), (1, vec![10.8]));
        assert_eq!(w.keys.len(), w.ms.len());
    }

    #[test]
    fn a_flood_of_one_mlat_fed_aircraft_is_applied_early_not_queued_without_bound() {
        let mut f = Fuser::new(FuseConfig::default(), TrackConfig::default(), false);
        let mut out = Vec::new();
        f.on_measurement(1, None, fix(100.0), 100.0, &mut out);
        // 1,000 positions within a millisecond of arrival time (a replay
        // looping fast): none is lost, none waits beyond the bound.
        for k in 0..1000 {
            let t = 100.0 + 0.001 * k as f64;
            f.on_measurement(1, None, fix(t), 100.5, &mut out);
            assert!(f.aircraft[&1].waiting.len() <= MAX_WAITING);
        }
        assert_eq!(f.stats().measurements, 1001);
        f.finish(&mut out);
        assert!(f.aircraft[&1].waiting.is_empty());
        assert_eq!(f.aircraft[&1].fused.t(), 100.999);
    }

    /// A release that moves the tracks on by more than their reorder window
    /// after the publication time (a burst delivered at once: a stalled
    /// input catching up, the end of a capture) still publishes at that
    /// time, where the tracks' history no longer reaches back to it: the
    /// fused track by measurement fusion, and the single-source tracks, by
    /// themselves and fused track to track.
    #[test]
    fn a_release_longer_than_the_reorder_window_still_publishes() {
        for (method, source_tracks) in
            [(Method::Measurement, false), (Method::Measurement, true), (Method::Convex, true)]
        {
            let cfg = FuseConfig { method, ..FuseConfig::default() };
            let mut f = Fuser::new(cfg, TrackConfig::default(), source_tracks);
            let mut out = Vec::new();
            // A confirmed MLAT-fed track, each fix released after the hold.
            for k in 0..10 {
                let t = 100.0 + 0.5 * k as f64;
                f.advance(t, &mut out);
                f.on_measurement(1, None, fix(t), t, &mut out);
            }
            f.advance(105.0, &mut out);
            out.clear();
            // A fix due for publication, then five seconds of Mode S
            // altitudes (they move the tracks on, and publish nothing), all
            // held together and released at the end of the input.
            let burst = 106.0;
            f.on_measurement(1, None, fix(burst), burst, &mut out);
            for k in 1..=10 {
                let t = burst + 0.5 * k as f64;
                let height = Measurement {
                    t,
                    source: Source::Mlat,
                    obs: Observation::Height { h: 3000.0, var: 100.0 },
                };
                f.on_measurement(1, None, height, burst, &mut out);
            }
            assert!(out.is_empty(), "held");
            f.finish(&mut out);
            let published: Vec<(&str, f64)> = out
                .iter()
                .filter_map(|o| if let Output::Track(r) = o { Some((r.source, r.est.t)) } else { None })
                .collect();
            let expected =
                if source_tracks { vec![("fused", burst), ("mlat", burst)] } else { vec![("fused", burst)] };
            assert_eq!(published, expected, "{method:?}");
            let reorder = TrackConfig::default().reorder_window_s;
            assert!(f.aircraft[&1].fused.t() > burst + reorder);
            assert!(!source_tracks || f.aircraft[&1].single[Source::Mlat as usize].t() > burst + reorder);
        }
    }

    #[test]
    fn a_track_mlat_stops_feeding_goes_out_at_once_again() {
        // MLAT for the first 20 s; 10 s later (the sources window) the
        // track is ADS-B only and each publication leaves on arrival.
        let (published, _) = mlat_fed_flight(0.6, 20.0);
        let late: Vec<&(f64, f64)> = published.iter().filter(|(_, t)| *t > 132.0).collect();
        assert!(late.len() > 40);
        assert!(late.iter().all(|(now, t)| now == t), "{late:?}");
    }
}
