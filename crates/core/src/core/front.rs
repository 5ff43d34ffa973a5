//! The front stage of the core: receivers, grouping, decoding,
//! multilateration and the conformance monitor. It owns everything the
//! clock synchronisation depends on and hands the tracker its work as
//! [`Cmd`]s, in order.
//!
//! Why the conformance monitor lives here and not beside the tracks: its
//! verdict keeps a flagged aircraft's ADS-B out of clock synchronisation,
//! which is decided frame by frame in this stage. With the monitor here,
//! nothing flows back from the tracker, so the two stages can run on two
//! threads and still produce exactly what one thread produces.
//!
//! Within it: a group handed out (`front/groups.rs`) and what a decoded
//! frame gives the tracker (`front/to_tracker.rs`).

use crate::FastMap;

use super::back::Cmd;
use super::delay::DelayCal;
use super::lateness::Lateness;
use super::wind::WindField;
use super::ReceiverNames;
use super::{CoreConfig, CoreStats, Dating, Event, PositionReport};
use crate::feed::capture::{CaptureRecord, ClockKind, ReceiverDecl};
use crate::feed::RawFrame;
use crate::fuse::conformance::{ConformanceConfig, Monitor};
use crate::geo::geodetic_to_ecef;
use crate::geo::{FT_TO_M, KT_TO_MS};
use crate::mlat::baro::{BaroCorrection, RegionalBaro};
use crate::mlat::engine::{baro_height, GroupOutcome};
use crate::mlat::group::{Added, Group, GroupInfo, Grouper};
use crate::mlat::timing::KnownTiming;
use crate::mlat::Mlat;
use crate::modes::commb::{Inference, Register};
use crate::modes::nic::{position_sigma_m, velocity_sigmas_ms};
use crate::modes::{Body, Decoder, DecoderConfig, Es};
use crate::track::{Measurement, Observation, SharedShare, Source};

struct RxState {
    decl: ReceiverDecl,
    frames: u64,
    /// Its network delay, learnt while its reports are dated by arrival.
    delay: DelayCal,
    /// Its latest report was dated by arrival (no GPS time to be had).
    arrival_dated: bool,
    /// Its timestamps on the server's clock: how late a frame arrived.
    lateness: Lateness,
    /// Its copies that came after their transmission was processed.
    late_copies: u64,
}

/// One aircraft's conformance monitor, forgotten when the aircraft is (as
/// its track would be).
struct Watched {
    monitor: Monitor,
    last_heard: f64,
}

/// What `on_group` needs besides the group, borrowed apart from the grouper.
struct GroupCtx<'a> {
    receivers: &'a mut [RxState],
    mlat: &'a mut Mlat,
    watched: &'a mut FastMap<u32, Watched>,
    stats: &'a mut CoreStats,
    conformance: &'a ConformanceConfig,
    sync_inflation: f64,
}

/// Finest step of time the tracker is told of (s).
const ADVANCE_STEP_S: f64 = 0.001;
/// How often (data time, s) every receiver's state goes into the track stream.
pub const RECEIVER_REPORT_S: f64 = 60.0;

mod groups;
mod to_tracker;

pub struct Front {
    receivers: Vec<RxState>,
    decoder: Decoder,
    grouper: Grouper,
    mlat: Mlat,
    watched: FastMap<u32, Watched>,
    conformance: ConformanceConfig,
    drop_after_s: f64,
    /// What is remembered of an aircraft outlives its last message by this
    /// (s): the decoder's and the MLAT engine's state.
    aircraft_ttl_s: f64,
    next_sweep: f64,
    /// When the receivers' next reports are due (data time).
    next_receivers: f64,
    /// The time of the last `Cmd::Advance`.
    advanced_to: f64,
    stats: CoreStats,
    min_sync_nacp: u8,
    baro_sigma_m: f64,
    /// The region's GNSS-baro difference, for aircraft that report none.
    baro: RegionalBaro,
    /// Time-of-applicability sigma of ADS-B positions: GPS-timed, arrival-timed (s).
    time_sigma: (f64, f64),
    sync_inflation: f64,
    /// Comm-B track and turn reports feed tracks without ADS-B velocity.
    commb_velocity: bool,
    /// The wind, magnetic variation and temperature learnt, for heading
    /// reports, and whether their headings feed tracks.
    wind: WindField,
    commb_heading: bool,
    /// Receivers the configuration describes: what it says of them (its
    /// position and clock, and its timing when given) wins over their
    /// declaration in a capture.
    known: Vec<KnownReceiver>,
    /// The receivers' ids, shared with whoever writes events out.
    ids: ReceiverNames,
}

/// The least float above `x` (finite `x`; `f64::next_up` is newer than
/// the crate's minimum Rust).
fn next_up(x: f64) -> f64 {
    match x {
        0.0 => f64::from_bits(1),
        x if x > 0.0 => f64::from_bits(x.to_bits() + 1),
        x => f64::from_bits(x.to_bits() - 1),
    }
}

/// A receiver as the configuration describes it.
#[derive(Clone, Debug)]
pub struct KnownReceiver {
    pub decl: ReceiverDecl,
    pub timing: Option<KnownTiming>,
}

impl Front {
    pub fn new(cfg: &CoreConfig) -> Self {
        let dcfg = DecoderConfig {
            reference: None,
            max_range_m: cfg.max_range_km * 1000.0,
            aircraft_ttl_s: cfg.aircraft_ttl_s,
            ..Default::default()
        };
        Front {
            receivers: Vec::new(),
            decoder: Decoder::new(dcfg),
            grouper: Grouper::new(cfg.group_wait_s, cfg.max_pending_groups),
            mlat: {
                let mut m = Mlat::new(cfg.mlat.clone());
                if cfg.track.sparse.enabled {
                    m.learn_coverage();
                }
                m
            },
            watched: FastMap::default(),
            conformance: cfg.fuse.conformance.clone(),
            drop_after_s: cfg.track.drop_after_s,
            aircraft_ttl_s: cfg.aircraft_ttl_s,
            next_sweep: f64::NEG_INFINITY,
            next_receivers: f64::NAN,
            advanced_to: f64::NEG_INFINITY,
            stats: CoreStats::default(),
            min_sync_nacp: cfg.mlat.min_sync_nacp,
            baro_sigma_m: cfg.mlat.baro_sigma_m,
            baro: RegionalBaro::default(),
            time_sigma: (cfg.track.adsb_time_sigma_gps_s, cfg.track.adsb_time_sigma_arrival_s),
            sync_inflation: cfg.track.mlat_sync_inflation,
            commb_velocity: cfg.track.commb_velocity,
            wind: WindField::default(),
            commb_heading: cfg.track.commb_heading,
            known: Vec::new(),
            ids: ReceiverNames::default(),
        }
    }

    /// Receivers the configuration describes, for those added after.
    pub fn know(&mut self, known: Vec<KnownReceiver>) {
        self.known = known;
    }

    pub fn add_receiver(&mut self, mut decl: ReceiverDecl) -> usize {
        let known = self.known.iter().find(|k| k.decl.id == decl.id);
        if let Some(k) = known {
            decl = k.decl.clone();
        }
        self.mlat.add_receiver(&decl);
        if let Some(t) = known.and_then(|k| k.timing.as_ref()) {
            self.mlat.set_known_timing(self.receivers.len(), t);
        }
        self.ids.push(&decl.id);
        self.receivers.push(RxState {
            decl,
            frames: 0,
            delay: DelayCal::default(),
            arrival_dated: false,
            lateness: Lateness::default(),
            late_copies: 0,
        });
        self.receivers.len() - 1
    }

    /// A handle to the receivers' ids, for naming events on another
    /// thread (see [`ReceiverNames`]).
    pub fn receiver_names(&self) -> ReceiverNames {
        self.ids.clone()
    }

    pub fn receiver_id(&self, rx: usize) -> &str {
        self.receivers.get(rx).map_or("?", |r| r.decl.id.as_str())
    }

    pub fn receivers(&self) -> impl Iterator<Item = (&ReceiverDecl, u64)> {
        self.receivers.iter().map(|r| (&r.decl, r.frames))
    }

    pub fn stats(&self) -> &CoreStats {
        &self.stats
    }

    pub fn decoder(&self) -> &Decoder {
        &self.decoder
    }

    pub fn grouper(&self) -> &Grouper {
        &self.grouper
    }

    pub fn mlat(&self) -> &Mlat {
        &self.mlat
    }

    /// For taking up what a previous run learnt (the service, at start).
    pub fn mlat_mut(&mut self) -> &mut Mlat {
        &mut self.mlat
    }

    /// How many aircraft the front's tables hold (the tracker's is the back's).
    pub fn aircraft_held(&self) -> super::AircraftHeld {
        super::AircraftHeld {
            decoder: self.decoder.aircraft_count(),
            mlat: self.mlat.aircraft_count(),
            conformance: self.watched.len(),
            tracker: 0,
        }
    }

    /// Whether the conformance monitor distrusts an aircraft's ADS-B.
    pub fn is_suspect(&self, addr: u32) -> bool {
        self.watched.get(&addr).is_some_and(|w| w.monitor.suspect)
    }

    fn ctx(&mut self) -> (&mut Grouper, GroupCtx<'_>) {
        (
            &mut self.grouper,
            GroupCtx {
                receivers: &mut self.receivers,
                mlat: &mut self.mlat,
                watched: &mut self.watched,
                stats: &mut self.stats,
                conformance: &self.conformance,
                sync_inflation: self.sync_inflation,
            },
        )
    }

    /// Moves time forward to `now` (arrival-time scale): groups whose wait
    /// ran out are processed; the tracker is told the time.
    pub fn advance(&mut self, now: f64, cmds: &mut Vec<Cmd>) {
        let (grouper, mut ctx) = self.ctx();
        grouper.advance(now, &mut |g: &Group| ctx.on_group(g, now, cmds));
        if now >= self.next_sweep {
            self.next_sweep = now + 1.0;
            let drop = self.drop_after_s;
            self.watched.retain(|_, w| now - w.last_heard <= drop);
            self.decoder.advance(now);
            self.mlat.prune(now, self.aircraft_ttl_s);
            // Checked with the sweep, once a second: not with every frame.
            if self.next_receivers.is_nan() {
                self.next_receivers = now + RECEIVER_REPORT_S;
            } else if now >= self.next_receivers {
                self.next_receivers = now + RECEIVER_REPORT_S;
                self.report_receivers(now, cmds);
            }
        }
        // The tracker is told the time at most once a millisecond (and with
        // every measurement, which carries its own): frames arrive a hundred
        // a millisecond at scale, and a command per frame cost more than the
        // tracker's work; a publication falls due at most this much late.
        if now < self.advanced_to || now - self.advanced_to >= ADVANCE_STEP_S {
            self.advanced_to = now;
            cmds.push(Cmd::Advance(now));
        }
    }

    /// When `advance` next has work of its own: the oldest pending group's
    /// wait runs out, or the once-a-second sweep (aircraft forgotten, the
    /// receivers' reports) falls due. `None` before it was given a time.
    pub fn poll_timeout(&self) -> Option<f64> {
        let sweep = self.next_sweep.is_finite().then_some(self.next_sweep);
        [self.grouper.next_deadline(), sweep].into_iter().flatten().reduce(f64::min)
    }

    /// When `advance` will pass the time on to the tracker, whose own work
    /// is due at `tracker`: it is told at most once per `ADVANCE_STEP_S`.
    pub fn tracker_timeout(&self, tracker: Option<f64>) -> Option<f64> {
        let mut at = tracker?.max(self.advanced_to + ADVANCE_STEP_S);
        // The step is tested as a difference, which can round below it at
        // the sum: the first time the test passes, or a caller woken at
        // the sum would find nothing done and be woken again at once.
        while at.is_finite() && at - self.advanced_to < ADVANCE_STEP_S {
            at = next_up(at);
        }
        Some(at)
    }

    /// End of input: everything pending is processed.
    pub fn finish(&mut self, cmds: &mut Vec<Cmd>) {
        let (grouper, mut ctx) = self.ctx();
        grouper.flush(&mut |g: &Group| {
            let now = g.first_arrival;
            ctx.on_group(g, now, cmds)
        });
        if self.advanced_to.is_finite() {
            self.report_receivers(self.advanced_to, cmds);
        }
        cmds.push(Cmd::Finish);
    }

    /// Every receiver's multilateration state, as the track stream's
    /// `receiver` records.
    fn report_receivers(&self, now: f64, cmds: &mut Vec<Cmd>) {
        for rx in 0..self.mlat.receiver_count() {
            cmds.push(Cmd::Event(Event::Receiver(Box::new(self.mlat.receiver_report(rx, now)))));
        }
    }

    /// One record of a capture: a receiver declared, or a frame.
    pub fn on_record(&mut self, rec: CaptureRecord, cmds: &mut Vec<Cmd>) {
        match rec {
            CaptureRecord::Receiver(d) => {
                self.add_receiver(d);
            }
            CaptureRecord::Frame(f) => self.on_frame(f.rx, f.arrival, &f.frame, cmds),
        }
    }

    /// One frame from receiver `rx`, arrived at `arrival` (Unix s).
    // Over 80 lines, kept whole: the per-frame path (see the decoding
    // below for what splitting it out cost).
    pub fn on_frame(&mut self, rx: usize, arrival: f64, frame: &RawFrame, cmds: &mut Vec<Cmd>) {
        self.stats.frames += 1;
        let Some(r) = self.receivers.get_mut(rx) else {
            self.stats.unknown_receiver += 1;
            return;
        };
        if !arrival.is_finite() {
            self.stats.bad_time += 1;
            return;
        }
        r.frames += 1;
        if frame.is_mode_ac() {
            self.stats.mode_ac += 1;
            return;
        }
        // A GPS receiver's seconds of the day start again at midnight: its
        // offset from the server's clock jumps as a restarted counter's does.
        let emission = if frame.has_timing() {
            r.lateness.emission(r.decl.clock.seconds(frame.timestamp), arrival)
        } else {
            f64::NAN
        };
        self.advance(arrival, cmds);
        let (grouper, mut ctx) = self.ctx();
        let new = match grouper
            .add(rx, arrival, frame, emission, &mut |g: &Group| ctx.on_group(g, arrival, cmds))
        {
            Added::New(new) => new,
            Added::Joined => return,
            Added::Duplicate => {
                self.stats.duplicates += 1;
                return;
            }
            Added::Late => {
                self.stats.late_copies += 1;
                self.receivers[rx].late_copies += 1;
                return;
            }
        };
        // The group is started below with what its first copy teaches. The
        // copy is decoded here, in place: returning the decoded message and
        // its group's information from a function of their own copied them,
        // a measurable cost on every new transmission.
        let decl = &self.receivers[rx].decl;
        let Ok(d) = self.decoder.decode_at(frame, arrival, Some((decl.lat, decl.lon))) else {
            self.grouper.start(new, GroupInfo::default());
            return;
        };
        self.stats.messages += 1;
        let mut info = GroupInfo {
            decoded: true,
            df: d.msg.df,
            addr: d.msg.addr,
            addr_known: d.trusted(),
            ..Default::default()
        };
        match d.msg.body {
            Body::AirAir { alt_ft, .. } | Body::Altitude { alt_ft, .. } => info.alt_baro_ft = alt_ft,
            Body::Extended(es) => {
                if let Es::AirbornePosition { alt_ft, gnss: false, .. } = es.kind {
                    info.alt_baro_ft = alt_ft;
                    // An ADS-B aircraft's altitude with its own difference:
                    // what the region's is learnt from.
                    if let (Some(a), Some(diff), true) = (alt_ft, d.gnss_baro_diff_ft, d.trusted()) {
                        self.baro.observe(a, diff, arrival);
                    }
                }
            }
            _ => {}
        }
        info.baro_correction = info.alt_baro_ft.and_then(|a| self.baro.correction(d.gnss_baro_diff_ft, a));
        // Only extended squitters (positions, velocities) need their time of
        // applicability: worked out once, and only for them.
        let timing = matches!(d.msg.body, Body::Extended(_)).then(|| self.frame_time(rx, arrival, frame));
        let report = timing.and_then(|timing| self.position_report(rx, timing, &d, info.baro_correction));
        // A monitored aircraft is heard: it stays monitored (as its track stays).
        info.suspect = match (self.watched.get_mut(&d.msg.addr), d.trusted()) {
            (Some(w), true) => {
                w.last_heard = arrival;
                w.monitor.suspect
            }
            (w, _) => w.is_some_and(|w| w.monitor.suspect),
        };
        info.report = report.as_ref().and_then(|p| Some((p.lat, p.lon, p.sigma_m?)));
        if let Some(p) = &report {
            // This transmission's own position: a clock synchronisation source.
            if let (Some(alt), Some(sigma), false) = (p.alt_m, p.sigma_m, p.surface) {
                if p.nac_p.unwrap_or(0) >= self.min_sync_nacp {
                    info.adsb_ecef = Some(geodetic_to_ecef(p.lat, p.lon, alt));
                    info.adsb_sigma_m = sigma;
                }
            }
        }
        self.grouper.start(new, info);
        if let Some(p) = report {
            // The report goes out before what the tracker makes of it.
            self.stats.positions += 1;
            cmds.push(Cmd::Event(Event::Position(p)));
        }
        self.feed_tracker(cmds, arrival, timing, &d, report.as_ref(), info.baro_correction);
    }

    /// Time of applicability of a frame: exact for GPS-timed receivers, and
    /// for counter-timed ones synchronised with a GPS-timed one (within a
    /// microsecond); otherwise the arrival time, less the receiver's network
    /// delay once learnt ([`DelayCal`]).
    fn frame_time(&mut self, rx: usize, arrival: f64, frame: &RawFrame) -> (f64, Dating) {
        let exact = match self.receivers[rx].decl.clock {
            ClockKind::Gps if frame.has_timing() => Some(ClockKind::gps_unix(frame.timestamp, arrival)),
            ClockKind::Beast12 if frame.has_timing() => {
                match self.mlat.gps_time_of(rx, frame.timestamp, arrival) {
                    // Sane only: within a second of the arrival, converted to a microsecond.
                    Some((t, var)) if var < 1e-12 && (arrival - t).abs() < 1.0 => Some(t),
                    _ => None,
                }
            }
            _ => None,
        };
        let r = &mut self.receivers[rx];
        r.arrival_dated = exact.is_none();
        match (exact, r.delay.estimate()) {
            (Some(t), _) => (t, Dating::Gps),
            (None, Some((mean, spread))) => (arrival - mean, Dating::Calibrated(spread)),
            (None, None) => (arrival, Dating::Arrival),
        }
    }

    /// (id, mean, spread) of each network delay learnt (s).
    pub fn learnt_delays(&self) -> impl Iterator<Item = (&str, f64, f64)> {
        self.learnt().map(|(r, m, s)| (r.decl.id.as_str(), m, s))
    }

    /// (id, MLAT health) of every receiver: whether it is excluded from
    /// fixes now, how often it was, its recent sync outlier rate.
    pub fn mlat_health(&self) -> impl Iterator<Item = (&str, &crate::mlat::sync::RxHealth)> {
        self.receivers.iter().zip(&self.mlat.sync.health).map(|(r, h)| (r.decl.id.as_str(), h))
    }

    /// (id, count) of each receiver that delivered late copies, the most
    /// first: the links with delay bursts.
    pub fn late_copies(&self) -> Vec<(&str, u64)> {
        let mut late: Vec<(&str, u64)> = self
            .receivers
            .iter()
            .filter(|r| r.late_copies > 0)
            .map(|r| (r.decl.id.as_str(), r.late_copies))
            .collect();
        late.sort_by_key(|&(_, n)| std::cmp::Reverse(n));
        late
    }

    /// The receivers whose network delay is learnt, with its mean and spread (s).
    fn learnt(&self) -> impl Iterator<Item = (&RxState, f64, f64)> {
        self.receivers.iter().filter_map(|r| r.delay.estimate().map(|(m, s)| (r, m, s)))
    }

    /// What is learnt of the air from heading reports.
    pub fn wind(&self) -> &WindField {
        &self.wind
    }

    /// What was learnt to keep across a restart (`[service] state_file`):
    /// each receiver's timing and survey, and the air.
    pub fn learnt_state(&self, saved_unix: f64) -> crate::mlat::state::LearntState {
        let mut state = self.mlat.learnt(saved_unix);
        state.air = self.wind.snapshot();
        state
    }

    /// Takes up what a previous run learnt at `now` (Unix s): how many
    /// receivers' timing, and whether the air's.
    pub fn restore(&mut self, state: &crate::mlat::state::LearntState, now: f64) -> (usize, bool) {
        let receivers = self.mlat.restore(state);
        let air = state.air.as_ref().is_some_and(|a| self.wind.restore(a, now));
        (receivers, air)
    }

    /// One line on the air learnt from heading reports (`None` if nothing
    /// was): the magnetic variation, the wind at a few heights, its spread.
    pub fn air_report(&self) -> Option<String> {
        let w = &self.wind;
        if w.stats.learnt == 0 {
            return None;
        }
        let (var, var_sigma) = w.variation_deg();
        let winds: Vec<String> = [1_000.0, 5_000.0, 10_000.0]
            .iter()
            .map(|&h| {
                let (v, s) = w.wind_at(h);
                format!("{:.0} km {:+.0}/{:+.0} m/s +-{:.0}", h / 1000.0, v[0], v[1], s.max())
            })
            .collect();
        Some(format!(
            "air: learnt from {} heading reports ({} outliers): magnetic variation {var:+.1} +-{var_sigma:.1} deg; \
             wind east/north {}; spread {:.1} m/s; {} heading reports given to tracks as velocities",
            w.stats.learnt,
            w.stats.outliers,
            winds.join(", "),
            w.scatter_ms(),
            self.stats.commb_headings
        ))
    }

    /// One line on the network delays learnt (`None` if none was): the
    /// receivers learnt from most first, at most `SHOWN`.
    pub fn delay_report(&self) -> Option<String> {
        const SHOWN: usize = 6;
        let mut learnt: Vec<(&RxState, f64, f64)> = self.learnt().collect();
        if learnt.is_empty() {
            return None;
        }
        learnt.sort_by_key(|(r, ..)| std::cmp::Reverse(r.delay.samples()));
        let shown: Vec<String> = learnt
            .iter()
            .take(SHOWN)
            .map(|(r, mean, spread)| {
                format!(
                    "{} {:.1} ms (spread {:.1} ms, {} transmissions, {} bursts left out)",
                    r.decl.id,
                    mean * 1e3,
                    spread * 1e3,
                    r.delay.samples(),
                    r.delay.bursts
                )
            })
            .collect();
        let more = learnt.len().saturating_sub(SHOWN);
        let more = if more > 0 { format!("; and {more} more") } else { String::new() };
        Some(format!("network delay learnt for reports dated by arrival: {}{more}", shown.join("; ")))
    }
}
