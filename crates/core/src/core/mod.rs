//! The sans-IO processing core: frames in, events out, time passed in.
//!
//! The live daemon and `run --capture` drive this same code; the only
//! difference is where frames come from and what time it is (the system clock
//! live, the data's arrival times offline). Nothing here reads a clock, a
//! socket or a file, so every stage is testable against truth and
//! benchmarkable without I/O.
//!
//! Flow per frame: receiver bookkeeping -> grouping (the first copy of a
//! transmission is decoded at once for low latency; later copies from other
//! receivers join its group for multilateration) -> decoding -> events.
//!
//! Two stages: [`front`] (receivers, decoding, grouping, multilateration,
//! conformance) turns frames into commands for [`back`] (tracking, fusion,
//! alerts). Nothing flows back, so `Core` applies the commands at once on
//! one thread, and `run --capture` runs the stages on two threads with the
//! same output byte for byte.

pub mod back;
pub mod commb;
pub mod delay;
pub mod front;
pub mod lateness;
pub mod receiver_names;
pub mod wind;

use std::collections::VecDeque;

use serde::Deserialize;

pub use back::{Back, Cmd};
pub use front::Front;
pub use receiver_names::ReceiverNames;

use crate::feed::capture::{CaptureRecord, ReceiverDecl};
use crate::feed::RawFrame;
use crate::fuse::{Alert, FuseConfig, Fuser, Output, TrackReport};
use crate::mlat::group::Grouper;
use crate::mlat::{Mlat, MlatConfig, MlatFix};
use crate::modes::Decoder;
use crate::problem::{positive, Problem};
use crate::track::TrackConfig;

#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CoreConfig {
    /// How long copies of one transmission are collected after the first (s).
    pub group_wait_s: f64,
    /// Most transmissions waiting for copies at once (older ones are flushed early, counted).
    pub max_pending_groups: usize,
    /// Positions farther than this from the receiver that heard them are rejected (km).
    pub max_range_km: f64,
    /// What is remembered of an aircraft (decoding and multilateration
    /// state) is forgotten this long after its last message (s); its track
    /// ends with `track.drop_after_s`. See [`AircraftHeld`].
    pub aircraft_ttl_s: f64,
    pub mlat: MlatConfig,
    pub track: TrackConfig,
    pub fuse: FuseConfig,
    /// Publish per-source (adsb, mlat) tracks beside the fused ones.
    #[serde(skip)]
    pub publish_source_tracks: bool,
}

impl Default for CoreConfig {
    fn default() -> Self {
        CoreConfig {
            group_wait_s: 0.5,
            max_pending_groups: 200_000,
            max_range_km: 600.0,
            aircraft_ttl_s: 300.0,
            mlat: MlatConfig::default(),
            track: TrackConfig::default(),
            fuse: FuseConfig::default(),
            publish_source_tracks: false,
        }
    }
}

impl CoreConfig {
    /// Every problem of `[core]` and its sub-tables at once, each naming
    /// its table.
    pub fn validate(&self) -> Result<(), Vec<Problem>> {
        let mut out = Vec::new();
        if !(self.group_wait_s > 0.0 && self.group_wait_s <= 5.0) {
            out.push(Problem::at("core", format!("group_wait_s = {} must be in (0, 5]", self.group_wait_s)));
        }
        // A pending group is about 400 bytes: ten million is 4 GB, and the
        // grouper's index numbers pending groups in 32 bits.
        if !(1..=10_000_000).contains(&self.max_pending_groups) {
            let message = format!("max_pending_groups = {} must be in 1..=10000000", self.max_pending_groups);
            out.push(Problem::at("core", message));
        }
        positive(
            "core",
            &[("max_range_km", self.max_range_km), ("aircraft_ttl_s", self.aircraft_ttl_s)],
            &mut out,
        );
        self.mlat.validate("core.mlat", &mut out);
        self.track.validate("core.track", &mut out);
        self.fuse.validate("core.fuse", &mut out);
        if out.is_empty() {
            Ok(())
        } else {
            Err(out)
        }
    }
}

/// How a report's time of applicability was found.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Dating {
    /// A GPS-timed receiver's timestamp, or a counter synchronised with one
    /// (within a microsecond).
    Gps,
    /// The arrival at the server less the receiver's learnt network delay
    /// ([`delay`]); the delay's spread (s).
    Calibrated(f64),
    /// The arrival at the server.
    Arrival,
}

/// A decoded ADS-B position report, as broadcast (not yet tracked).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PositionReport {
    pub addr: u32,
    /// Time of applicability (Unix s): exact for GPS-timed receivers, the
    /// arrival time otherwise (until clock synchronisation refines it).
    pub t: f64,
    pub lat: f64,
    pub lon: f64,
    /// WGS-84 height (m), from GNSS height or baro altitude corrected by the
    /// reported GNSS-baro difference when known.
    pub alt_m: Option<f64>,
    pub alt_baro_ft: Option<i32>,
    /// 1-sigma error of `alt_m` as a WGS-84 height (m).
    pub alt_sigma_m: Option<f64>,
    pub nac_p: Option<u8>,
    /// 1-sigma horizontal error per axis (m) implied by NACp (or NUCp).
    pub sigma_m: Option<f64>,
    /// How its time of applicability was found.
    pub dating: Dating,
    pub surface: bool,
    pub rx: usize,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Event {
    Position(PositionReport),
    Mlat(Box<MlatFix>),
    Track(Box<TrackReport>),
    Alert(Alert),
    /// A receiver's multilateration state, once a minute and at the end.
    Receiver(Box<crate::mlat::ReceiverReport>),
}

/// The fuser's output as the core's event.
pub fn event(o: Output) -> Event {
    match o {
        Output::Track(r) => Event::Track(r),
        Output::Alert(a) => Event::Alert(a),
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CoreStats {
    pub frames: u64,
    pub mode_ac: u64,
    pub unknown_receiver: u64,
    pub bad_time: u64,
    pub duplicates: u64,
    /// Copies that arrived after their transmission was processed (a link's
    /// delay burst): dropped, not decoded again.
    pub late_copies: u64,
    pub messages: u64,
    pub positions: u64,
    pub fixes: u64,
    /// ADS-B/MLAT pairs of one transmission judged by the conformance monitor.
    pub conformance_checks: u64,
    /// ADS-B positions without a known accuracy (no NACp or NUCp): not tracked.
    pub untracked_positions: u64,
    /// Comm-B track and turn reports given to tracks as velocities.
    pub commb_velocities: u64,
    /// Comm-B vertical rates (heading and speed reports) given to tracks.
    pub commb_climbs: u64,
    /// Comm-B headings and airspeeds given to tracks as velocities.
    pub commb_headings: u64,
}

/// Both stages on one thread, driven as quinn-proto drives a connection:
/// `handle_*` calls give it what happened and when, `poll_event` hands out
/// what it made, in order, and `poll_timeout` says when it next has work of
/// its own (a group's wait running out, a held publication, the sweep), for
/// `handle_timeout` then. It never reads a clock; the caller's `now` is the
/// arrival-time scale of its frames.
pub struct Core {
    front: Front,
    back: Back,
    cmds: Vec<Cmd>,
    events: VecDeque<Event>,
}

impl Core {
    pub fn new(cfg: &CoreConfig) -> Self {
        let (front, back) = Core::stages(cfg);
        Core { front, back, cmds: Vec::new(), events: VecDeque::new() }
    }

    /// The two stages, for a caller that runs them on two threads.
    pub fn stages(cfg: &CoreConfig) -> (Front, Back) {
        let fuser = Fuser::new(cfg.fuse.clone(), cfg.track.clone(), cfg.publish_source_tracks);
        (Front::new(cfg), Back::new(fuser))
    }

    fn run(&mut self) {
        self.back.apply(self.cmds.drain(..), &mut self.events);
    }

    /// Receivers the configuration describes (see [`Front::know`]).
    pub fn know(&mut self, known: Vec<front::KnownReceiver>) {
        self.front.know(known);
    }

    /// A receiver declared; its index names it in frames.
    pub fn handle_receiver(&mut self, decl: ReceiverDecl) -> usize {
        let rx = self.front.add_receiver(decl);
        self.run();
        rx
    }

    /// One record of a capture: a receiver declared, or a frame.
    pub fn handle_record(&mut self, rec: CaptureRecord) {
        self.front.on_record(rec, &mut self.cmds);
        self.run();
    }

    /// One frame from receiver `rx`, arrived at `now` (Unix s).
    pub fn handle_frame(&mut self, now: f64, rx: usize, frame: &RawFrame) {
        self.front.on_frame(rx, now, frame, &mut self.cmds);
        self.run();
    }

    /// Time moved on to `now` without a frame: groups whose wait ran out are
    /// processed, held track publications released.
    pub fn handle_timeout(&mut self, now: f64) {
        self.front.advance(now, &mut self.cmds);
        self.run();
    }

    /// End of input: everything pending is processed.
    pub fn finish(&mut self) {
        self.front.finish(&mut self.cmds);
        self.run();
    }

    /// The next event made, in the order a single thread makes them.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// When `handle_timeout` next has work (`None`: not until something
    /// happens).
    pub fn poll_timeout(&self) -> Option<f64> {
        let tracker = self.front.tracker_timeout(self.back.poll_timeout());
        [self.front.poll_timeout(), tracker].into_iter().flatten().reduce(f64::min)
    }

    /// The id of receiver `rx` (as declared), for the records that name it.
    pub fn receiver_id(&self, rx: usize) -> &str {
        self.front.receiver_id(rx)
    }

    pub fn receivers(&self) -> impl Iterator<Item = (&ReceiverDecl, u64)> {
        self.front.receivers()
    }

    pub fn stats(&self) -> &CoreStats {
        self.front.stats()
    }

    /// (id, count) of each receiver that delivered late copies, the most first.
    pub fn late_copies(&self) -> Vec<(&str, u64)> {
        self.front.late_copies()
    }

    pub fn decoder(&self) -> &Decoder {
        self.front.decoder()
    }

    pub fn grouper(&self) -> &Grouper {
        self.front.grouper()
    }

    pub fn mlat(&self) -> &Mlat {
        self.front.mlat()
    }

    /// What is learnt of the air (wind, magnetic variation) from heading reports.
    pub fn wind(&self) -> &wind::WindField {
        self.front.wind()
    }

    pub fn fuser(&self) -> &Fuser {
        self.back.fuser()
    }

    pub fn fuser_mut(&mut self) -> &mut Fuser {
        self.back.fuser_mut()
    }

    pub fn mlat_mut(&mut self) -> &mut Mlat {
        self.front.mlat_mut()
    }

    /// Whether the conformance monitor distrusts an aircraft's ADS-B.
    pub fn is_suspect(&self, addr: u32) -> bool {
        self.front.is_suspect(addr)
    }

    /// How many aircraft each of the core's per-aircraft tables holds.
    pub fn aircraft_held(&self) -> AircraftHeld {
        AircraftHeld { tracker: self.back.fuser().tracks(), ..self.front.aircraft_held() }
    }
}

/// How many aircraft each per-aircraft table holds. Every one ages out, on
/// one of two lifetimes: what is remembered of an aircraft (its decoding
/// and multilateration state) lives `aircraft_ttl_s` after its last
/// message; its track, and the conformance monitor's watch over it, end
/// with the track (`[core.track] drop_after_s`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AircraftHeld {
    pub decoder: usize,
    pub mlat: usize,
    pub conformance: usize,
    pub tracker: usize,
}
