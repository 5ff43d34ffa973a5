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

mod config;
mod outcome;
mod placement;
mod receivers;
pub use receivers::{gps_mean_offset, timing_report};
mod robust;
mod shared_mode;
mod stats;

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

/// Height above the ellipsoid (m) of a barometric altitude, and its 1-sigma
/// (m): corrected by the aircraft's own GNSS-baro difference when it reports
/// one, or the region's (`baro`), else taken as is with the configured
/// `baro_sigma_m`. One rule for the MLAT solver's altitude constraint and
/// the tracker's heights.
pub fn baro_height(alt_ft: i32, correction: Option<BaroCorrection>, baro_sigma_m: f64) -> (f64, f64) {
    match correction {
        Some(c) => ((alt_ft as f64 + c.diff_ft) * FT_TO_M, c.sigma_m),
        None => (alt_ft as f64 * FT_TO_M, baro_sigma_m),
    }
}

/// The receivers of one measurement (more than one when they stand too close
/// to be separate sites).
type Site = smallvec::SmallVec<[usize; 2]>;

/// Whether `after` lies within `before`'s uncertainty (99.9%, 3-D).
fn near(before: &super::solver::Fix, after: &super::solver::Fix) -> bool {
    let c = nalgebra::Matrix3::from_fn(|r, k| before.cov_ecef[r][k]);
    let d = nalgebra::Vector3::from_fn(|r, _| after.ecef[r] - before.ecef[r]);
    c.try_inverse().is_some_and(|inv| (d.transpose() * inv * d)[0] <= 16.27)
}

/// Copies left out of a fix as outliers: measurement, site, sync variance (s^2).
type Dropped = GroupVec<(Measurement, Site, f64)>;

/// A fix's copies judged under their receivers' timing models: the
/// problem linearised at the fix, and each copy's verdict (none for a
/// merged site, whose time is no single receiver's).
struct Judged {
    at: AtFix,
    verdicts: GroupVec<Option<Verdict>>,
}

impl Judged {
    /// From every copy's verdict under its (first) receiver's model.
    fn new(at: AtFix, all: &[Verdict], sites: &[Site]) -> Judged {
        let verdicts = all.iter().zip(sites).map(|(v, site)| (site.len() == 1).then_some(*v)).collect();
        Judged { at, verdicts }
    }

    fn p_late(&self, k: usize) -> f64 {
        self.verdicts[k].map_or(0.0, |v| v.p_late)
    }
}

/// A barometric altitude recent enough to constrain a fix: feet, its
/// variance (m^2: the 25 ft steps and the climb since), and its correction
/// to the ellipsoid as known when it was reported.
#[derive(Clone, Copy)]
struct Baro {
    ft: i32,
    var_m2: f64,
    correction: Option<BaroCorrection>,
}

struct Rx {
    /// Its configured id, for the log.
    id: String,
    ecef: [f64; 3],
    clock: ClockKind,
    /// Configured jitter (s): the prior for the learnt noise.
    sigma_t: f64,
    beast_epoch: Option<u64>,
    /// Last (local time, arrival time) seen, to notice clock jumps.
    last_seen: Option<(f64, f64)>,
    timing: TimingModel,
    /// Its timing given by the configuration: not learnt.
    timing_known: bool,
    /// Found misplaced by its survey (without `self_survey`): out of fixes.
    misplaced: bool,
    /// Where the traffic says its antenna is, and its east-north-up frame.
    survey: Survey,
    enu: [[f64; 3]; 3],
    /// Its declared position (geodetic and ECEF; `ecef` is the one in use),
    /// and the surveyed offset in use instead (east, north m), if any.
    declared: (f64, f64, f64),
    declared_ecef: [f64; 3],
    surveyed: Option<[f64; 2]>,
    /// The surveyed position's uncertainty as a timing variance (s^2): its
    /// horizontal variance per axis, and the distance to the survey's
    /// latest estimate, which it follows only once that moves beyond it.
    surveyed_var_s2: f64,
    /// The GPS-timed receiver its clock is best synchronised with, and when
    /// that was last chosen (arrival time).
    gps_partner: Option<(usize, f64)>,
    /// Recent share of its copies whose time jumped (a counter that
    /// restarted, a GPS time off by whole seconds from the others').
    jumps: f64,
}

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
/// How long an aircraft's MLAT state outlives its last use, and a banned
/// sync source's (a spoofer that pauses does not become honest).
pub const AIRCRAFT_TTL_S: f64 = 600.0;
pub const BANNED_TTL_S: f64 = 86_400.0;
/// With `self_survey`, a receiver's survey is looked at every this many measurements.
const SURVEY_CHECK_EVERY: u64 = 200;
/// Mean normalised innovation beyond which an aircraft is no longer a sync
/// source (honest ones average about 1).
const SYNC_SOURCE_MAX_NIS: f64 = 6.0;
impl Rx {
    /// Timing sigma (s) to weight this receiver with: its learnt core
    /// (which starts from the configured jitter), never better than a third
    /// of the configured one.
    fn sigma(&self) -> f64 {
        self.timing.sigma().max(self.sigma_t / 3.0)
    }

    fn bias(&self) -> f64 {
        self.timing.offset()
    }
}

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

    /// One line of MLAT state: valid pairs, sync residual per receiver (ns),
    /// fixes, rejects by reason, excluded receivers.
    pub fn report(&self, now: f64, names: &dyn Fn(usize) -> String) -> String {
        let params = &self.sync.params;
        let mut per_rx: Vec<(f64, usize)> = vec![(0.0, 0); self.rxs.len()];
        let mut valid = 0;
        let mut total = 0;
        for (&(i, j), p) in self.sync.pairs() {
            total += 1;
            if p.valid(now, params) {
                valid += 1;
                for k in [i, j] {
                    per_rx[k].0 += p.residual_rms();
                    per_rx[k].1 += 1;
                }
            }
        }
        let residuals: Vec<String> = per_rx
            .iter()
            .enumerate()
            .filter(|(_, (_, n))| *n > 0)
            .map(|(k, (s, n))| format!("{}={:.0}", names(k), s / *n as f64 * 1e9))
            .collect();
        let excluded: Vec<String> =
            self.sync.health.iter().enumerate().filter(|(_, h)| h.excluded).map(|(k, _)| names(k)).collect();
        let mut rejects: Vec<String> = (self.stats.rejects.iter())
            .filter(|&(_, n)| n > 0)
            .map(|(why, n)| format!("{}={n}", why.name()))
            .collect();
        rejects.sort();
        // Receivers whose declared position the traffic contradicts.
        let misplaced: Vec<String> = (self.rxs.iter().enumerate())
            .filter_map(|(k, r)| {
                let o = r.survey.offset().filter(|o| o.misplaced())?;
                Some(format!(
                    "{} declared {:.0} m off: {:+.0} m east, {:+.0} m north, +-{:.0} m",
                    names(k),
                    o.horizontal_m(),
                    o.enu_m[0],
                    o.enu_m[1],
                    o.sigma_m
                ))
            })
            .collect();
        format!(
            "mlat: {} fixes from {} groups; pairs {valid}/{total} valid; sync residual ns [{}]; rejects [{}]; \
             excluded [{}]; misplaced [{}]; sync messages {}, pair updates {}, outliers {}, restarts {}; \
             GPS time jumps {}; self-synchronised fixes {}",
            self.stats.fixes,
            self.stats.groups,
            residuals.join(" "),
            rejects.join(" "),
            excluded.join(" "),
            misplaced.join("; "),
            self.stats.sync_messages,
            self.sync.stats.updates,
            self.sync.stats.outliers,
            self.sync.stats.restarts,
            self.stats.time_jumps,
            self.stats.self_synced_fixes
        )
    }

    /// A receiver's timestamp in its local seconds (small numbers, full
    /// precision), referred to the start of the frame's preamble.
    fn local_time(&mut self, rx: usize, ts: u64, arrival: f64) -> f64 {
        let refer = match self.rxs[rx].clock {
            ClockKind::Beast12 => self.cfg.timestamp_offset_beast12_ns,
            ClockKind::Gps => self.cfg.timestamp_offset_gps_ns,
        } * 1e-9;
        self.raw_local_time(rx, ts, arrival) - refer
    }

    fn raw_local_time(&mut self, rx: usize, ts: u64, arrival: f64) -> f64 {
        match self.rxs[rx].clock {
            ClockKind::Gps => {
                let sod_ns = (ts >> 30) as i64 * 1_000_000_000 + (ts & 0x3FFF_FFFF) as i64;
                let day = (arrival / 86_400.0).floor() as i64;
                let mut ns = day * 86_400_000_000_000 + sod_ns;
                let arr_ns = (arrival * 1e9) as i64;
                if ns - arr_ns > 43_200_000_000_000 {
                    ns -= 86_400_000_000_000;
                } else if arr_ns - ns > 43_200_000_000_000 {
                    ns += 86_400_000_000_000;
                }
                let epoch = *self.gps_epoch_ns.get_or_insert(day * 86_400_000_000_000);
                (ns - epoch) as f64 * 1e-9
            }
            ClockKind::Beast12 => {
                let shared = self.shared.is_some();
                let epoch_of = |ts: u64| if shared { shared_epoch(ts) } else { ts };
                let epoch = *self.rxs[rx].beast_epoch.get_or_insert_with(|| epoch_of(ts));
                let local = (ts as i64 - epoch as i64) as f64 / 12e6;
                // A counter that moved seconds more or less than the server's
                // clock restarted (or jumped): new epoch, its pairs start again.
                if let Some((l0, a0)) = self.rxs[rx].last_seen {
                    if ((local - l0) - (arrival - a0)).abs() > CLOCK_JUMP_S {
                        self.sync.reset_receiver(rx);
                        self.note_sync(SyncNote::ResetReceiver { now: arrival, rx: rx as u32 });
                        let epoch = epoch_of(ts);
                        let local = (ts - epoch) as f64 / 12e6;
                        self.rxs[rx].beast_epoch = Some(epoch);
                        self.rxs[rx].last_seen = Some((local, arrival));
                        // A receiver whose clock jumps all the time must not
                        // flood the log: its first jumps, then each power of
                        // two (all of them in the metric).
                        let n = self.sync.health[rx].clock_resets;
                        if n.is_power_of_two() {
                            tracing::info!(receiver = %self.rxs[rx].id, jumps = n, "clock jump: receiver restarted");
                        }
                        return local;
                    }
                }
                self.rxs[rx].last_seen = Some((local, arrival));
                local
            }
        }
    }

    fn reject(&mut self, why: Reject) {
        self.stats.rejects.add(why);
    }

    /// Forgets aircraft not heard of for [`AIRCRAFT_TTL_S`] (a banned sync
    /// source for [`BANNED_TTL_S`]): over weeks the table would otherwise
    /// hold every address ever heard. Nothing older than a few minutes is
    /// used anyway (altitudes, fixes and attempts are read within seconds).
    pub fn prune(&mut self, now: f64) {
        self.geometric_baro.prune(now);
        self.aircraft.retain(|_, a| {
            let newest = [a.alt_ft.map(|x| x.1), a.last_fix.map(|x| x.1), a.last_tried, a.last_adsb]
                .into_iter()
                .flatten()
                .fold(f64::NEG_INFINITY, f64::max);
            let ttl = if a.sync_banned { BANNED_TTL_S } else { AIRCRAFT_TTL_S };
            now - newest <= ttl
        });
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
    pub fn on_group(&mut self, g: &Group, now: f64) -> GroupOutcome {
        self.stats.groups += 1;
        let info = g.info;
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
        let (times, root) = self.sync.common_time(&copies, now);
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
        let guess = ac.last_fix.filter(|(_, t)| (now - t).abs() < 30.0).map(|(p, _)| p);
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
            return self.short_of_fix(&info, &g.ms, &arrivals, too_few, now);
        }
        let solved = self.solve_robust(&mut g, alt, guess);
        let (fix, judged) = match solved {
            Ok(f) => f,
            Err(why) => {
                self.reject(why);
                return GroupOutcome::NoFix(NoFix::Rejected(why));
            }
        };
        // Hedged against late copies, judged at the fix (as the robust
        // solve already did when its last round found no outlier).
        let judged =
            judged.or_else(|| (fix.dof > 0).then(|| self.judge(&g.ms, &g.sites, alt, &fix)).flatten());
        let fix = match &judged {
            Some(j) => super::solver::hedge(&fix, &j.at, |k| j.p_late(k)),
            None => fix,
        };
        let used: smallvec::SmallVec<[usize; 8]> = g.sites.iter().flatten().copied().collect();
        if !info.addr_known && fix.dof == 0 {
            // Nothing checks an unverified address: no fix from it.
            self.stats.unverified_address += 1;
            return GroupOutcome::NoFix(NoFix::UnverifiedAddress);
        }
        if let Some(j) = judged.as_ref().filter(|_| self.cfg.calibrate && fix.dof >= 1) {
            self.learn(j, &fix, &g.sites, &g.sync_vars, &g.dropped, now);
        }
        self.remember_fix(info.addr, &fix, judged.as_ref().map(|j| &j.at), (alt, baro), now);
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
        ms: &[Measurement],
        arrivals: &[f64],
        too_few: bool,
        now: f64,
    ) -> GroupOutcome {
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

    /// The aircraft's barometric altitude when recent enough to constrain a
    /// fix, and the constraint it makes: its height above the ellipsoid and
    /// sigma.
    fn altitude_constraint(&self, ac: &AcState, now: f64) -> (Option<Baro>, Option<AltitudeConstraint>) {
        // The barometric altitude's own height and variance (25 ft steps,
        // climb since), apart from its correction to the ellipsoid, when
        // recent enough to constrain the fix.
        let baro = ac.alt_ft.and_then(|(ft, t, diff)| {
            let age = (now - t).abs();
            let quant = 25.0 * FT_TO_M / 12f64.sqrt();
            let var = quant.powi(2) + (age * self.cfg.alt_growth_mps).powi(2);
            (age <= self.cfg.max_alt_age_s).then_some(Baro { ft, var_m2: var, correction: diff })
        });
        let alt = baro.map(|Baro { ft, var_m2: var, correction: diff }| {
            // The correction is the aircraft's own when its ADS-B reports
            // one (GNSS minus baro, in 25 ft steps), else the region's from
            // the ADS-B traffic, else from the fixes' geometry: taken as zero
            // instead, an error the same for every fix of the flight (45 m
            // on tma-busy, 90 m on LocaRDS) moved its fixes off the same way
            // for minutes, which a track fed by them could not average away.
            let diff = diff.or_else(|| {
                let (lat, lon, _) = crate::geo::ecef_to_geodetic(ac.last_fix?.0);
                self.geometric_baro.correction(lat, lon, ft, self.cfg.baro_sigma_m)
            });
            let (h_m, correction) = baro_height(ft, diff, self.cfg.baro_sigma_m);
            AltitudeConstraint { h_m, sigma_m: (var + correction.powi(2)).sqrt() }
        });
        (baro, alt)
    }

    /// A group's usable copies on their receivers' local time, with their
    /// arrivals: known receiver, timing, no GPS time off by seconds.
    // Inlined: its result, inline vectors, would otherwise be copied out.
    #[inline(always)]
    fn usable_copies(&mut self, g: &Group) -> (GroupVec<LocalCopy>, GroupVec<f64>) {
        // Usable copies: known receiver, timing. An excluded receiver's are
        // read (its clock jumps seen) and synchronise it, so that it comes
        // back once its sync holds; they stay out of the fix.
        let mut copies: GroupVec<LocalCopy> = GroupVec::new();
        let mut arrivals: GroupVec<f64> = GroupVec::new();
        for c in &g.copies {
            if c.rx >= self.rxs.len() {
                self.stats.unknown_receiver += 1;
                continue;
            }
            if !crate::feed::has_timing(c.timestamp) {
                self.stats.no_timing += 1;
                continue;
            }
            let resets = self.sync.health[c.rx].clock_resets;
            let t = self.local_time(c.rx, c.timestamp, c.arrival);
            // A counter's jump is its restart; a GPS time's is judged
            // against the others' (below).
            if self.rxs[c.rx].clock == ClockKind::Beast12 {
                let jumped = self.sync.health[c.rx].clock_resets != resets;
                self.note_jump(c.rx, jumped);
            }
            copies.push(LocalCopy { rx: c.rx, t });
            arrivals.push(c.arrival);
        }
        self.drop_gps_time_jumps(&mut copies, &mut arrivals);
        (copies, arrivals)
    }

    /// The copies' synchronised times as the solver's measurements, one per
    /// site, with the sync variances the fix's report and calibration need.
    // Inlined: its result, inline vectors, would otherwise be copied out.
    #[inline(always)]
    fn measurements(&mut self, copies: &[LocalCopy], times: &[Option<(f64, f64)>], addr: u32) -> Measured {
        // One measurement per site: receivers closer than the minimum
        // separation add no geometry, so their times are averaged (inverse
        // variance) into one measurement with a smaller sigma.
        let mut ms: GroupVec<Measurement> = GroupVec::new();
        let mut sites: GroupVec<Site> = GroupVec::new();
        // Each measurement's clock synchronisation variance (s^2): not the receiver's own.
        let mut sync_vars: GroupVec<f64> = GroupVec::new();
        let (mut sync_var, mut self_var, mut all_var) = (0.0, 0.0, 0.0);
        for (c, t) in copies.iter().zip(times) {
            let Some((t, var)) = t else { continue };
            sync_var += var;
            self_var += var * self.sync.references[c.rx].share_of(addr);
            all_var += var + self.rxs[c.rx].sigma().powi(2);
            let rx = &self.rxs[c.rx];
            // A GPS receiver's offset came off in the common time base.
            let offset = if rx.clock == ClockKind::Gps { 0.0 } else { rx.bias() };
            let own = rx.sigma().powi(2) + rx.surveyed_var_s2;
            let m = Measurement { pos: rx.ecef, t: *t - offset, sigma_t: (own + var).sqrt() };
            match ms.iter().position(|o| ecef_distance(o.pos, m.pos) < self.cfg.min_separation_m) {
                Some(k) => {
                    self.stats.close_receivers += 1;
                    let (w1, w2) = (1.0 / ms[k].sigma_t.powi(2), 1.0 / m.sigma_t.powi(2));
                    ms[k].t = (ms[k].t * w1 + m.t * w2) / (w1 + w2);
                    ms[k].sigma_t = (1.0 / (w1 + w2)).sqrt();
                    sync_vars[k] = sync_vars[k].min(*var);
                    sites[k].push(c.rx);
                }
                None => {
                    ms.push(m);
                    sites.push(smallvec::smallvec![c.rx]);
                    sync_vars.push(*var);
                }
            }
        }
        Measured {
            g: robust::GroupCopies { ms, sites, sync_vars, dropped: Dropped::new() },
            sync_var,
            self_var,
            all_var,
        }
    }

    fn note_jump(&mut self, rx: usize, jumped: bool) {
        let r = &mut self.rxs[rx];
        r.jumps += JUMP_MEMORY * (jumped as u8 as f64 - r.jumps);
    }

    /// GPS-timed copies of one transmission agree to milliseconds (the
    /// time light takes across any network): one off by more is a GPS time
    /// that jumped (by whole seconds, typically), and would fail the fix,
    /// the clock pairs and every GPS receiver's survey with it. Among three
    /// or more the majority tells which; of two, the one that jumps more
    /// often, or both when neither does.
    fn drop_gps_time_jumps(&mut self, copies: &mut GroupVec<LocalCopy>, arrivals: &mut GroupVec<f64>) {
        let gps: GroupVec<usize> =
            (0..copies.len()).filter(|&k| self.rxs[copies[k].rx].clock == ClockKind::Gps).collect();
        if gps.len() < 2 {
            return;
        }
        // Nearly always they agree, and no median is needed to say so.
        let (lo, hi) = (gps.iter()).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &k| {
            (lo.min(copies[k].t), hi.max(copies[k].t))
        });
        if hi - lo <= GPS_AGREE_S {
            for &k in &gps {
                self.note_jump(copies[k].rx, false);
            }
            return;
        }
        let mut times: GroupVec<f64> = gps.iter().map(|&k| copies[k].t).collect();
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        let mut off: GroupVec<usize> =
            gps.iter().copied().filter(|&k| (copies[k].t - median).abs() > GPS_AGREE_S).collect();
        if gps.len() == 2 && !off.is_empty() {
            let (a, b) = (gps[0], gps[1]);
            let (ja, jb) = (self.rxs[copies[a].rx].jumps, self.rxs[copies[b].rx].jumps);
            off = if ja > jb {
                smallvec::smallvec![a]
            } else if jb > ja {
                smallvec::smallvec![b]
            } else {
                smallvec::smallvec![a, b]
            };
        }
        for &k in &gps {
            self.note_jump(copies[k].rx, off.contains(&k));
        }
        self.stats.time_jumps += off.len() as u64;
        for &k in off.iter().rev() {
            copies.remove(k);
            arrivals.remove(k);
        }
    }

    /// A receiver whose copies stay out of fixes: excluded by its sync's
    /// health, found misplaced, or its time jumping.
    fn out_of_fixes(&self, rx: usize) -> bool {
        self.sync.health[rx].excluded || self.rxs[rx].misplaced || self.rxs[rx].jumps > JUMPS_EXCLUDE
    }

    /// Aircraft health: the mean normalised innovation of a source's sync
    /// measurements against converged pairs is about 1 for an honest
    /// aircraft (less, as the noise model is a little generous); a position
    /// offset shows as a consistent bias and drives it far up. Past the
    /// threshold the aircraft is no longer a sync source (for good: a
    /// spoofer does not become honest).
    fn judge_sync_source(&mut self, addr: u32, nis_sum: f64, judged: u32) {
        if judged == 0 {
            return;
        }
        let a = self.aircraft.entry(addr).or_default();
        let mean = nis_sum / judged as f64;
        a.sync_uses += 1;
        a.sync_nis += (mean - a.sync_nis) / (a.sync_uses.min(20) as f64);
        if !a.sync_banned && a.sync_uses >= 10 && a.sync_nis > SYNC_SOURCE_MAX_NIS {
            a.sync_banned = true;
            self.stats.sync_banned_aircraft += 1;
            tracing::warn!(
                aircraft = format!("{addr:06X}"),
                "ADS-B positions disagree with the timing: not used for sync"
            );
        }
    }

    /// Recent mean normalised innovation of an aircraft's sync measurements.
    pub fn sync_nis(&self, addr: u32) -> Option<f64> {
        self.aircraft.get(&addr).filter(|a| a.sync_uses > 0).map(|a| a.sync_nis)
    }

    /// Whether an aircraft's ADS-B positions are refused as sync sources.
    pub fn sync_banned(&self, addr: u32) -> bool {
        self.aircraft.get(&addr).is_some_and(|a| a.sync_banned)
    }

    fn sync_from(
        &mut self,
        copies: &[LocalCopy],
        p: [f64; 3],
        addr: u32,
        sigma_pos: f64,
        now: f64,
    ) -> (f64, u32) {
        self.stats.sync_messages += 1;
        let n = copies.len();
        // On the stack: a sync message's dozen heap lists cost as much as
        // its clock filters' updates.
        let ranges: GroupVec<f64> = copies.iter().map(|c| ecef_distance(self.rxs[c.rx].ecef, p)).collect();
        let var: GroupVec<f64> = copies.iter().map(|c| self.rxs[c.rx].sigma().powi(2)).collect();
        // The emitter's position error moves the two ranges differently: by
        // the difference of the unit vectors towards the receivers.
        let units: GroupVec<[f64; 3]> = copies
            .iter()
            .zip(&ranges)
            .map(|(c, r)| {
                let e = self.rxs[c.rx].ecef;
                [(e[0] - p[0]) / r, (e[1] - p[1]) / r, (e[2] - p[2]) / r]
            })
            .collect();
        // Only the pairs `observe` reads (a before b).
        let mut geom: smallvec::SmallVec<[f64; 64]> = smallvec::smallvec![0.0; n * n];
        for a in 0..n {
            for b in a + 1..n {
                let d2: f64 = (0..3).map(|k| (units[a][k] - units[b][k]).powi(2)).sum();
                geom[a * n + b] = sigma_pos * sigma_pos * d2 / (C_AIR * C_AIR);
            }
        }
        match &mut self.shared {
            None => {
                let judged = self.sync.observe(copies, &ranges, &var, &geom, now);
                self.sync.note_reference(copies, addr);
                judged
            }
            Some(notes) => {
                notes.push(SyncNote::Observed {
                    now,
                    addr,
                    copies: copies.iter().map(|c| (c.rx as u32, c.t)).collect(),
                    ranges: ranges.to_vec(),
                    var: var.to_vec(),
                    geom: geom.to_vec(),
                });
                self.sync.judge(copies, &ranges, &var, &geom)
            }
        }
    }
}

#[cfg(test)]
mod tests;
