//! The multilateration engine: complete groups in, fixes out.
//!
//! Per group: receivers known, healthy and with usable timestamps; copies from
//! receivers within 1 km of one already used are dropped (they add no
//! geometry); DF17 positions feed clock synchronisation; all copies go onto
//! one time base; an altitude constraint comes from the message or the
//! aircraft's recent altitude; the solver does the rest. Addresses that
//! nothing verified are only trusted when an over-determined fix is
//! consistent (identical copies at geometrically consistent times).
//!
//! Here: the engine's state and the per-group path ([`Mlat::on_group`]);
//! beside it its configuration (`config.rs`), results (`outcome.rs`) and
//! counters (`stats.rs`), the robust solve and timing calibration
//! (`robust.rs`), the receivers' placement survey (`placement.rs`), the
//! receivers' table (`receivers.rs`) and the tests (`tests.rs`).

use super::survey::{enu_basis, Survey};
use super::timing::{KnownTiming, Lessons, Residual, TimingModel, TimingModels, Verdict};
use crate::FastMap;

use super::clock::PairParams;
use super::group::{Group, GroupInfo};
use super::shared::{shared_epoch, SyncNote, SyncSnapshot};
use super::solver::{solve, AltitudeConstraint, AtFix, Measurement, Reject, SolverLimits, C_AIR};
use super::sync::{ClockSync, GroupVec, LocalCopy};
use crate::feed::capture::{ClockKind, ReceiverDecl};
use crate::geo::{ecef_distance, geodetic_to_ecef, FT_TO_M};

use super::baro::{BaroCorrection, GeometricBaros};
use super::coverage::Coverage;

mod altitude;
mod config;
mod copies;
mod outcome;
mod placement;
mod receivers;
pub use receivers::{gps_mean_offset, timing_report};
mod robust;
mod rx;
use robust::Dropped;
use rx::Rx;
mod shared_mode;
mod stats;
mod sync_source;

pub use altitude::baro_height;
use altitude::Baro;
pub use config::MlatConfig;
pub use outcome::{GroupOutcome, MlatFix, NoFix, TdoaGroup};
use shared_mode::jitter_ns;
pub use shared_mode::{pair_params, timing_prior};
pub use stats::{MlatStats, RejectCounts};

/// A group's measurements, one per site (see [`Mlat::measurements`]): each
/// site's receivers and clock synchronisation variance (s^2, not the
/// receivers' own), and the sync variance summed over the copies, the share
/// of it from the aircraft's own ADS-B, and all the copies' variance.
struct Measured {
    /// The measurements, sites and sync variances (none left out yet).
    g: robust::GroupCopies,
    sync_var: f64,
    self_var: f64,
    all_var: f64,
}

/// The receivers of one measurement (more than one when they stand too close
/// to be separate sites).
type Site = smallvec::SmallVec<[usize; 2]>;

/// GPS-timed copies of one transmission further apart than this (s) cannot
/// be: light crosses any network in a few milliseconds.
const GPS_AGREE_S: f64 = 0.01;
/// Weight of each copy in a receiver's recent share of time jumps, and the
/// share beyond which it is left out of fixes (back once it falls).
const JUMP_MEMORY: f64 = 0.03;
const JUMPS_EXCLUDE: f64 = 0.2;
/// A receiver clock that disagrees with the server's clock by more than this
/// (s) between two frames has jumped. Network delays vary by far less.
const CLOCK_JUMP_S: f64 = 5.0;
/// One aircraft's fixes give the barometric difference a look this often
/// at most (s): its successive fixes share its geometry and its errors, so
/// that looks taken at every fix would count one aircraft hundreds of times
/// and make the difference look surer than it is.
const BARO_LOOK_EVERY_S: f64 = 10.0;
/// How long a banned sync source is remembered (a spoofer that pauses does
/// not become honest); other aircraft live the core's `aircraft_ttl_s`.
pub const BANNED_TTL_S: f64 = 86_400.0;
/// A receiver's survey is looked at every this many measurements: until a
/// misplaced receiver is found, every fix it is in is pulled all one way
/// (and a track taking those fixes cannot average that away), so it is
/// looked at soon after its survey can say anything. A look is a 4x4
/// inversion.
const SURVEY_CHECK_EVERY: u64 = 25;
/// Fastest an aircraft is taken to fly (m/s, above any airliner's ground
/// speed), and what a fix without redundancy may be off by besides (m).
const MAX_SPEED_MPS: f64 = 600.0;
const UNCHECKED_FIX_SLACK_M: f64 = 3_000.0;

/// How far from an earlier fix an aircraft can be `dt` seconds on.
fn reach_m(dt: f64) -> f64 {
    MAX_SPEED_MPS * dt.abs() + UNCHECKED_FIX_SLACK_M
}
/// Mean clipped normalised innovation (each pair's clipped at
/// [`super::sync::JUDGE_NIS_CLIP`]) beyond which an aircraft is no longer a sync
/// source. An honest one averages about 1 plus 8 times the share of its
/// pairs a late copy spoils: 4 is over a third of its pairs inconsistent,
/// more than multipath does to receivers late on up to a sixth of their
/// receptions; a position offset of a few hundred metres spoils about half.
const SYNC_SOURCE_MAX_NIS: f64 = 4.0;

#[derive(Clone, Copy, Default)]
struct AcState {
    /// Latest barometric altitude (ft), when (s), and the GNSS-baro
    /// difference known then (ft).
    alt_ft: Option<(i32, f64, Option<BaroCorrection>)>,
    /// Newest fix with redundancy (ECEF, server time): the solver's start.
    /// One without redundancy could be the wrong of its two solutions: taken
    /// as the next one's start, each led a chain of them down that branch
    /// (on the scale world 3.7% of such fixes were more than 1 km off, mean
    /// NEES 1,300; started from fixes with redundancy, 2.6% and 2.1).
    last_fix: Option<([f64; 3], f64)>,
    /// When this aircraft's newest fix of any kind was made, or its newest
    /// group found ambiguous (server time): an ADS-B aircraft is
    /// multilaterated about once an `adsb_interval_s` from then. (Counted
    /// from fixes with redundancy only, an aircraft that three sites heard
    /// was tried at every transmission, and its time differences cost the
    /// tracker a third more updates on the scale world.)
    last_tried: Option<f64>,
    /// Last time an ADS-B position of this aircraft was seen.
    last_adsb: Option<f64>,
    /// When its fixes last gave the barometric difference a look.
    last_baro_look: Option<f64>,
    /// Recent mean normalised innovation of the sync measurements its ADS-B
    /// positions made: an aircraft whose positions disagree with the timing
    /// (bad GPS, spoofing) stops being a sync source.
    sync_nis: f64,
    sync_uses: u32,
    sync_banned: bool,
}

pub struct Mlat {
    cfg: MlatConfig,
    limits: SolverLimits,
    rxs: Vec<Rx>,
    pub sync: ClockSync,
    aircraft: FastMap<u32, AcState>,
    /// Nanoseconds since the Unix epoch of the GPS time base's zero.
    gps_epoch_ns: Option<i64>,
    /// The barometric altitudes' difference from the ellipsoid height as
    /// the fixes' geometry sees it, for aircraft without a better one.
    geometric_baro: GeometricBaros,
    pub stats: MlatStats,
    /// In a cluster: what this engine did to the clocks, for the clock
    /// service to do once (`None` on a single node, which syncs itself).
    shared: Option<Vec<SyncNote>>,
    /// Where each receiver hears: who heard a transmission too few heard,
    /// and who did not, places it too.
    coverage: Coverage,
}

impl Mlat {
    /// The GPS time (Unix s) at which receiver `rx` (a free-running counter)
    /// received a frame stamped `ts`, through its synchronisation with a
    /// GPS-timed receiver, and the variance of that conversion; `None` when
    /// it is not synchronised with one. This dates ADS-B reports decoded from
    /// counter-timed receivers exactly instead of by their arrival at the
    /// server (tens of milliseconds late).
    pub fn gps_time_of(&mut self, rx: usize, ts: u64, now: f64) -> Option<(f64, f64)> {
        let r = self.rxs.get(rx)?;
        if r.clock != ClockKind::Beast12 || r.last_seen.is_none() {
            return None;
        }
        let epoch_ns = self.gps_epoch_ns?;
        let local =
            (ts as i64 - r.beast_epoch? as i64) as f64 / 12e6 - self.cfg.timestamp_offset_beast12_ns * 1e-9;
        // Choose the partner every few seconds: the best-synchronised GPS receiver.
        let partner = match r.gps_partner {
            Some((g, at)) if now - at < 10.0 => Some(g),
            _ => {
                let best = self
                    .sync
                    .gps_peers(rx)
                    .iter()
                    .filter_map(|&g| self.sync.edge(rx, g, local, now).map(|(_, v)| (g, v)))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(g, _)| g);
                self.rxs[rx].gps_partner = best.map(|g| (g, now));
                best
            }
        }?;
        let (off, var) = self.sync.edge(rx, partner, local, now)?;
        // In the GPS clock's local seconds, then Unix time (the GPS stamps'
        // own reference offset is removed as in `local_time`).
        let t = local + off + self.cfg.timestamp_offset_gps_ns * 1e-9 - self.sync.gps_bias(partner);
        Some((epoch_ns as f64 * 1e-9 + t, var))
    }

    /// What calibration learnt about receiver `rx`.
    pub fn timing(&self, rx: usize) -> TimingModel {
        self.rxs[rx].timing
    }

    pub fn new(cfg: MlatConfig) -> Self {
        let pair = pair_params(&cfg);
        Mlat {
            cfg,
            limits: SolverLimits::default(),
            rxs: Vec::new(),
            sync: ClockSync::new(pair),
            aircraft: FastMap::default(),
            gps_epoch_ns: None,
            geometric_baro: GeometricBaros::default(),
            stats: MlatStats::default(),
            shared: None,
            coverage: Coverage::default(),
        }
    }

    pub fn add_receiver(&mut self, d: &ReceiverDecl) {
        let jitter = jitter_ns(&self.cfg, d.clock);
        self.rxs.push(Rx {
            id: d.id.clone(),
            ecef: geodetic_to_ecef(d.lat, d.lon, d.alt),
            clock: d.clock,
            sigma_t: jitter * 1e-9,
            beast_epoch: None,
            last_seen: None,
            gps_partner: None,
            jumps: 0.0,
            offset_learnt_t: None,
            lesson_interval_s: 1.0,
            timing: TimingModel::prior(jitter * 1e-9),
            timing_known: false,
            misplaced: false,
            survey: Survey::default(),
            enu: enu_basis(d.lat, d.lon),
            declared: (d.lat, d.lon, d.alt),
            declared_ecef: geodetic_to_ecef(d.lat, d.lon, d.alt),
            surveyed: None,
            surveyed_var_s2: 0.0,
        });
        self.sync.add_receiver(d.clock, &d.id);
        self.coverage.add_receiver(d.lat, d.lon, d.alt);
    }

    /// Takes receiver `rx`'s timing as given, from now on, instead of
    /// learning it.
    pub fn set_known_timing(&mut self, rx: usize, known: &KnownTiming) {
        let r = &mut self.rxs[rx];
        r.timing = known.model();
        r.sigma_t = r.timing.sigma();
        r.timing_known = true;
        self.sync.set_gps_bias(rx, self.rxs[rx].bias());
    }

    /// An altitude heard from an aircraft (any message), for later
    /// constraints, with the aircraft's GNSS-baro difference when known.
    pub fn note_altitude(&mut self, addr: u32, alt_ft: i32, correction: Option<BaroCorrection>, now: f64) {
        self.aircraft.entry(addr).or_default().alt_ft = Some((alt_ft, now, correction));
    }

    fn reject(&mut self, why: Reject) {
        self.stats.rejects.add(why);
    }

    /// Forgets aircraft not heard of for `ttl_s` (the core's
    /// `aircraft_ttl_s`, as the decoder; a banned sync source for
    /// [`BANNED_TTL_S`]): over weeks the table would otherwise hold every
    /// address ever heard. Nothing older than a few minutes is used anyway
    /// (altitudes, fixes and attempts are read within seconds).
    pub fn prune(&mut self, now: f64, ttl_s: f64) {
        self.geometric_baro.prune(now);
        self.coverage.prune(now, ttl_s);
        self.aircraft.retain(|_, a| {
            let newest = [a.alt_ft.map(|x| x.1), a.last_fix.map(|x| x.1), a.last_tried, a.last_adsb]
                .into_iter()
                .flatten()
                .fold(f64::NEG_INFINITY, f64::max);
            let ttl = if a.sync_banned { BANNED_TTL_S.max(ttl_s) } else { ttl_s };
            now - newest <= ttl
        });
    }

    /// Learns where each receiver hears, for the particle filter's
    /// weighing by who heard a transmission (learnt only where used).
    pub fn learn_coverage(&mut self) {
        self.coverage = Coverage::enabled();
        for r in &self.rxs {
            self.coverage.add_receiver(r.declared.0, r.declared.1, r.declared.2);
        }
    }

    /// Receivers known.
    pub fn receiver_count(&self) -> usize {
        self.rxs.len()
    }

    /// Aircraft in the table (for tests and the soak check).
    pub fn aircraft_count(&self) -> usize {
        self.aircraft.len()
    }

    /// A complete group at server time `now`: a fix, time differences for
    /// the tracker, or why neither.
    // Over 80 lines: the per-group path's sequence, each step a function of
    // its own; what is left is the order and the early returns.
    pub fn on_group(&mut self, g: &Group, now: f64) -> GroupOutcome {
        self.stats.groups += 1;
        let info = g.info;
        let heard = &g.copies;
        self.coverage.on_group(g, now);
        if !info.decoded || g.copies.len() < 2 {
            self.stats.too_few_receivers += (g.copies.len() < 2) as u64;
            return GroupOutcome::NoFix(NoFix::TooFewReceivers);
        }
        // Filled in place: returned, the copies (about a kilobyte inline)
        // were moved once more per group, 1% of the pipeline's instructions.
        let (mut copies, mut arrivals) = self.usable_copies(g);
        let all_copies = match self.fit_for_fix(&info, &mut copies, &mut arrivals, now) {
            Ok(all) => all,
            Err(why) => return GroupOutcome::NoFix(why),
        };
        let ac = match self.note_aircraft(&info, now) {
            Ok(ac) => ac,
            Err(why) => return GroupOutcome::NoFix(why),
        };
        let super::sync::CommonTime { times, root, anchors: anchor_copies } =
            self.sync.common_time_anchored(&copies, now);
        if let (Some(a), false) = (info.adsb_ecef, info.suspect) {
            match &all_copies {
                None => self.survey_from(&copies, &times, a, info.adsb_sigma_m, now),
                Some(all) => {
                    let (all_times, _) = self.sync.common_time(all, now);
                    self.survey_from(all, &all_times, a, info.adsb_sigma_m, now)
                }
            }
        }
        let Measured { mut g, sync_var, self_var, all_var } = self.measurements(&copies, &times, info.addr);
        let (baro, alt) = self.altitude_constraint(&ac, now);
        let last_fix = ac.last_fix.filter(|(_, t)| (now - t).abs() < 30.0);
        let guess = last_fix.map(|(p, _)| p);
        let too_few = g.ms.len() < 3 || (g.ms.len() < 4 && alt.is_none());
        // Exactly as many measurements as unknowns: the equations have two
        // solutions (hyperboloids and the altitude's shell meet twice), both
        // fitting perfectly, and only an earlier fix with redundancy tells
        // which is the aircraft. Taken blindly, a fifth of the scale world's
        // three-site fixes were the other one, kilometres off with a
        // covariance of metres (NEES in the hundreds of thousands), and so
        // were most of tma-busy's in its first seconds (only its GPS-timed
        // receivers synchronised yet).
        let ambiguous = !too_few && g.ms.len() + alt.is_some() as usize == 4 && guess.is_none();
        if too_few || ambiguous {
            return self.short_of_fix(&info, &g, &arrivals, heard, too_few, now);
        }
        let solved = self.solve_robust(&mut g, alt, guess);
        let (fix, judged) = match solved {
            Ok(f) => f,
            Err(why) => {
                self.reject(why);
                return GroupOutcome::NoFix(NoFix::Rejected(why));
            }
        };
        // Started from the earlier fix, a group with one degree of freedom
        // or none can still land on its other solution, where the noise
        // leaves none near the aircraft: one further than it could have
        // flown is that, and the group is ambiguous.
        // Nor is an exactly determined group whose other solution the
        // aircraft could have reached as well: the one nearer the earlier
        // fix is not the aircraft for that reason alone, and a fix that
        // followed the wrong one past the point where the two meet went
        // on along it, kilometres off, for as long as the earlier fix
        // counted.
        let reached = |p: [f64; 3]| last_fix.map(|(q, t)| ecef_distance(q, p) <= reach_m(now - t));
        if fix.dof <= 1 && (reached(fix.ecef) == Some(false) || fix.mirror.and_then(reached) == Some(true)) {
            return self.short_of_fix(&info, &g, &arrivals, heard, false, now);
        }
        // Hedged against late copies, judged at the fix (as the robust
        // solve already did when its last round found no outlier).
        let judged =
            judged.or_else(|| (fix.dof > 0).then(|| self.judge(&g.ms, &g.sites, alt, &fix)).flatten());
        // Its covariance for the variances its receivers are believed to
        // have, where the weights were held at their floor.
        let believed = |k: usize| self.believed_var(&g, k);
        let fix = match &judged {
            Some(j) => super::solver::hedge(&j.at.sandwich(&fix, believed), &j.at, |k| j.p_late(k)),
            None if (0..g.ms.len()).any(|k| believed(k).is_some()) => {
                super::solver::AtFix::new(&g.ms, alt, &fix).map_or(fix, |at| at.sandwich(&fix, believed))
            }
            None => fix,
        };
        let used: smallvec::SmallVec<[usize; 8]> = g.sites.iter().flatten().copied().collect();
        if !info.addr_known && fix.dof == 0 {
            // Nothing checks an unverified address: no fix from it.
            self.stats.unverified_address += 1;
            return GroupOutcome::NoFix(NoFix::UnverifiedAddress);
        }
        if let Some(j) = judged.as_ref().filter(|_| self.cfg.calibrate && fix.dof >= 1) {
            let anchors: GroupVec<(usize, Option<usize>)> =
                (copies.iter().zip(&anchor_copies)).map(|(c, a)| (c.rx, a.map(|a| copies[a].rx))).collect();
            self.learn(j, &fix, &g, &anchors, now);
        }
        self.remember_fix(info.addr, &fix, judged.as_ref().map(|j| &j.at), (alt, baro), now);
        if fix.dof >= 1 {
            // Where no aircraft reports its position, the fixes with
            // redundancy (not one of two solutions) teach the coverage.
            self.coverage.observe(info.addr, fix.ecef, heard.iter().map(|c| c.rx), now);
        }
        self.stats.fixes += 1;
        let t = self.emission_time(copies[root].rx, &fix, &arrivals, &g.ms);
        let self_sync_share = if sync_var > 0.0 { self_var / sync_var } else { 0.0 };
        self.stats.self_synced_fixes += (self_sync_share > 0.5) as u64;
        GroupOutcome::Fix(Box::new(MlatFix {
            addr: info.addr,
            t,
            lat: fix.lat,
            lon: fix.lon,
            alt_m: fix.h_m,
            cov_en: fix.cov_en,
            cov_ecef: fix.cov_ecef,
            receivers: used,
            gdop: fix.gdop,
            chi2: if fix.dof > 0 { fix.chi2 / fix.dof as f64 } else { 0.0 },
            dof: fix.dof,
            altitude_used: alt.is_some(),
            sync_share: if all_var > 0.0 { sync_var / all_var } else { 0.0 },
            self_sync_share,
            df: info.df,
        }))
    }

    /// Notes the group's altitude and ADS-B in the aircraft's state; its
    /// state then, or `AdsbRecent` for an ADS-B aircraft tried less than
    /// about `adsb_interval_s` ago (transponders dither their squitters by
    /// +/-20%, so a quarter early is allowed).
    fn note_aircraft(&mut self, info: &GroupInfo, now: f64) -> Result<AcState, NoFix> {
        if let Some(a) = info.alt_baro_ft {
            self.note_altitude(info.addr, a, info.baro_correction, now);
        }
        if info.adsb_ecef.is_some() {
            self.aircraft.entry(info.addr).or_default().last_adsb = Some(now);
        }
        let ac = self.aircraft.get(&info.addr).copied().unwrap_or_default();
        let adsb = self.cfg.adsb_interval_s > 0.0 && ac.last_adsb.is_some_and(|t| now - t < 10.0);
        if adsb && ac.last_tried.is_some_and(|t| now - t < 0.75 * self.cfg.adsb_interval_s) {
            self.stats.adsb_skipped += 1;
            return Err(NoFix::AdsbRecent);
        }
        Ok(ac)
    }

    /// Too few measurements for a fix (`too_few`), or too few to choose
    /// between its two solutions: counted, and the synchronised times handed
    /// to the tracker as time differences when a track that already knows
    /// where the aircraft is can use them.
    fn short_of_fix(
        &mut self,
        info: &GroupInfo,
        g: &robust::GroupCopies,
        arrivals: &[f64],
        heard: &[super::group::Copy],
        too_few: bool,
        now: f64,
    ) -> GroupOutcome {
        let ms = &g.ms;
        let why = if too_few {
            self.stats.too_few_receivers += 1;
            NoFix::TooFewReceivers
        } else {
            self.reject(Reject::Ambiguous);
            self.aircraft.entry(info.addr).or_default().last_tried = Some(now);
            NoFix::Rejected(Reject::Ambiguous)
        };
        if (2..=3).contains(&ms.len()) && info.addr_known {
            let first = arrivals.iter().cloned().fold(f64::INFINITY, f64::min);
            return GroupOutcome::Tdoa(TdoaGroup {
                addr: info.addr,
                t: first,
                sites: ms.iter().map(|m| (m.pos, m.t, m.sigma_t)).collect(),
                // A merged site's is its first receiver's (the others' are alike).
                persistent: (g.sites.iter())
                    .map(|site| self.rxs[site[0]].offset_error(now).unwrap_or((0.0, 0.0)))
                    .collect(),
                sync_var: g.sync_vars.to_vec(),
                unheard: self.coverage.unheard(heard, now),
            });
        }
        GroupOutcome::NoFix(why)
    }

    /// What a fix leaves in its aircraft's state: when it was tried, where
    /// it was (with redundancy), and, now and then, what its geometry says
    /// of the barometric altitude's difference from the ellipsoid height
    /// (see [`GeometricBaros`]; the hedge moved neither the fix nor its
    /// linearisation, `at`).
    fn remember_fix(
        &mut self,
        addr: u32,
        fix: &super::solver::Fix,
        at: Option<&AtFix>,
        (alt, baro): (Option<AltitudeConstraint>, Option<Baro>),
        now: f64,
    ) {
        let ac = self.aircraft.entry(addr).or_default();
        let look_due = ac.last_baro_look.is_none_or(|t| (now - t).abs() >= BARO_LOOK_EVERY_S);
        if let (Some(a), Some(Baro { ft, var_m2, .. }), Some(at), true) = (alt, baro, at, look_due) {
            if let Some((geom_m, geom_var)) = at.height_apart(fix, a) {
                ac.last_baro_look = Some(now);
                self.geometric_baro.observe(fix.lat, fix.lon, (geom_m, geom_var), ft, var_m2, now);
            }
        }
        ac.last_tried = Some(now);
        if fix.dof >= 1 {
            ac.last_fix = Some((fix.ecef, now));
        }
    }

    /// When the fix's transmission left the aircraft (Unix s): from the
    /// solution itself on a GPS-timed root, else the first arrival less the
    /// flight time to the nearest site.
    fn emission_time(
        &self,
        root_rx: usize,
        fix: &super::solver::Fix,
        arrivals: &[f64],
        ms: &[Measurement],
    ) -> f64 {
        match (self.rxs[root_rx].clock, self.gps_epoch_ns) {
            (ClockKind::Gps, Some(epoch)) => epoch as f64 * 1e-9 + fix.t_emit,
            _ => {
                let first = arrivals.iter().cloned().fold(f64::INFINITY, f64::min);
                let nearest = ms.iter().map(|m| ecef_distance(m.pos, fix.ecef)).fold(f64::INFINITY, f64::min);
                first - nearest / C_AIR
            }
        }
    }

    /// A group's usable copies (on their receivers' local time, with their
    /// arrivals) made fit for a fix: at least two, the clocks synchronised
    /// from its ADS-B position when it has one, the excluded receivers'
    /// copies left out. Returns every copy, excluded receivers' too, when one
    /// was left out and the group has ADS-B to survey it with (boxed: rare).
    fn fit_for_fix(
        &mut self,
        info: &GroupInfo,
        copies: &mut GroupVec<LocalCopy>,
        arrivals: &mut GroupVec<f64>,
        now: f64,
    ) -> Result<Option<Box<GroupVec<LocalCopy>>>, NoFix> {
        if copies.len() < 2 {
            self.stats.too_few_receivers += 1;
            return Err(NoFix::TooFewReceivers);
        }
        if let (Some(p), false) = (info.adsb_ecef, info.suspect) {
            if self.aircraft.get(&info.addr).is_some_and(|a| a.sync_banned) {
                self.stats.sync_refused += 1;
            } else {
                let (nis_sum, judged) = self.sync_from(copies, p, info.addr, info.adsb_sigma_m, now);
                self.judge_sync_source(info.addr, nis_sum, judged);
            }
        }
        // The survey looks at every receiver, excluded ones too (a misplaced
        // receiver is excluded, and is the one to find).
        let mut all_copies = None;
        if copies.iter().any(|c| self.out_of_fixes(c.rx)) {
            if info.adsb_ecef.is_some() && !info.suspect {
                all_copies = Some(Box::new(copies.clone()));
            }
            let before = copies.len();
            for k in (0..copies.len()).rev() {
                if self.out_of_fixes(copies[k].rx) {
                    copies.remove(k);
                    arrivals.remove(k);
                }
            }
            self.stats.excluded_receiver_copies += (before - copies.len()) as u64;
        }
        Ok(all_copies)
    }
}

#[cfg(test)]
mod tests;
