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

use serde::Deserialize;

use crate::feed::capture::{CaptureRecord, ClockKind, ReceiverDecl};
use crate::feed::RawFrame;
use crate::fuse::{Alert, FuseConfig, Fuser, Output, TrackReport};
use crate::geo::geodetic_to_ecef;
use crate::geo::{FT_TO_M, KT_TO_MS};
use crate::mlat::group::{Added, Group, GroupInfo, Grouper};
use crate::mlat::{Mlat, MlatConfig, MlatFix};
use crate::modes::nic::{nacp_epu_m, nucp_hpl_m};
use crate::modes::{Body, Decoder, DecoderConfig, Es};
use crate::track::{Measurement, Observation, Source, TrackConfig};

#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CoreConfig {
    /// How long copies of one transmission are collected after the first (s).
    pub group_wait_s: f64,
    /// Most transmissions waiting for copies at once (older ones are flushed early, counted).
    pub max_pending_groups: usize,
    /// Positions farther than this from the receiver that heard them are rejected (km).
    pub max_range_km: f64,
    /// Aircraft not heard for this long are forgotten (s).
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
    pub fn validate(&self) -> Result<(), String> {
        if !(self.group_wait_s > 0.0 && self.group_wait_s <= 5.0) {
            return Err(format!("group_wait_s = {} must be in (0, 5]", self.group_wait_s));
        }
        if self.max_pending_groups == 0 {
            return Err("max_pending_groups must be positive".into());
        }
        if !self.max_range_km.is_finite() || self.max_range_km <= 0.0 {
            return Err(format!("max_range_km = {} must be positive", self.max_range_km));
        }
        if !self.aircraft_ttl_s.is_finite() || self.aircraft_ttl_s <= 0.0 {
            return Err(format!("aircraft_ttl_s = {} must be positive", self.aircraft_ttl_s));
        }
        self.track.validate().map_err(|e| format!("[core.track] {e}"))?;
        self.fuse.validate().map_err(|e| format!("[core.fuse] {e}"))?;
        Ok(())
    }
}

/// A decoded ADS-B position report, as broadcast (not yet tracked).
#[derive(Clone, Copy, Debug, PartialEq)]
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
    /// Timed by a GPS receiver clock (else by arrival at the server).
    pub gps_timed: bool,
    pub surface: bool,
    pub rx: usize,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    Position(PositionReport),
    Mlat(MlatFix),
    Track(Box<TrackReport>),
    Alert(Alert),
}

fn event(o: Output) -> Event {
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
    pub messages: u64,
    pub positions: u64,
    pub fixes: u64,
    /// ADS-B positions without a known accuracy (no NACp or NUCp): not tracked.
    pub untracked_positions: u64,
}

struct RxState {
    decl: ReceiverDecl,
    frames: u64,
}

pub struct Core {
    receivers: Vec<RxState>,
    decoder: Decoder,
    grouper: Grouper,
    mlat: Mlat,
    fuser: Fuser,
    tracks_out: Vec<Output>,
    stats: CoreStats,
    min_sync_nacp: u8,
    baro_sigma_m: f64,
    /// Time-of-applicability sigma of ADS-B positions: GPS-timed, arrival-timed (s).
    time_sigma: (f64, f64),
    sync_inflation: f64,
}

impl Core {
    pub fn new(cfg: &CoreConfig) -> Self {
        let dcfg = DecoderConfig {
            reference: None,
            max_range_m: cfg.max_range_km * 1000.0,
            aircraft_ttl_s: cfg.aircraft_ttl_s,
            ..Default::default()
        };
        Core {
            receivers: Vec::new(),
            decoder: Decoder::new(dcfg),
            grouper: Grouper::new(cfg.group_wait_s, cfg.max_pending_groups),
            mlat: Mlat::new(cfg.mlat.clone()),
            fuser: Fuser::new(cfg.fuse.clone(), cfg.track.clone(), cfg.publish_source_tracks),
            tracks_out: Vec::new(),
            stats: CoreStats::default(),
            min_sync_nacp: cfg.mlat.min_sync_nacp,
            baro_sigma_m: cfg.mlat.baro_sigma_m,
            time_sigma: (cfg.track.adsb_time_sigma_gps_s, cfg.track.adsb_time_sigma_arrival_s),
            sync_inflation: cfg.track.mlat_sync_inflation,
        }
    }

    pub fn add_receiver(&mut self, decl: ReceiverDecl) -> usize {
        self.mlat.add_receiver(&decl);
        self.receivers.push(RxState { decl, frames: 0 });
        self.receivers.len() - 1
    }

    /// One record of a capture: a receiver declared, or a frame.
    pub fn on_record(&mut self, rec: CaptureRecord, out: &mut Vec<Event>) {
        match rec {
            CaptureRecord::Receiver(d) => {
                self.add_receiver(d);
            }
            CaptureRecord::Frame(f) => self.on_frame(f.rx, f.arrival, &f.frame, out),
        }
    }

    /// The id of receiver `rx` (as declared), for the records that name it.
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

    pub fn fuser(&self) -> &Fuser {
        &self.fuser
    }

    /// Moves time forward to `now` (arrival-time scale): groups whose wait
    /// ran out are processed, held track publications released.
    pub fn advance(&mut self, now: f64, out: &mut Vec<Event>) {
        let (mlat, fuser, stats, sync_inflation) =
            (&mut self.mlat, &mut self.fuser, &mut self.stats, self.sync_inflation);
        self.grouper
            .advance(now, &mut |g: Group| Self::on_group(mlat, fuser, stats, sync_inflation, &g, now, out));
        self.fuser.advance(now, &mut self.tracks_out);
        out.extend(self.tracks_out.drain(..).map(event));
    }

    /// End of input: everything pending is processed.
    pub fn finish(&mut self, out: &mut Vec<Event>) {
        let (mlat, fuser, stats, sync_inflation) =
            (&mut self.mlat, &mut self.fuser, &mut self.stats, self.sync_inflation);
        self.grouper.flush(&mut |g: Group| {
            let now = g.first_arrival;
            Self::on_group(mlat, fuser, stats, sync_inflation, &g, now, out)
        });
        self.fuser.finish(&mut self.tracks_out);
        out.extend(self.tracks_out.drain(..).map(event));
    }

    fn on_group(
        mlat: &mut Mlat,
        fuser: &mut Fuser,
        stats: &mut CoreStats,
        sync_inflation: f64,
        g: &Group,
        now: f64,
        out: &mut Vec<Event>,
    ) {
        let Some(fix) = mlat.on_group(g, now) else {
            if let Some(t) = mlat.take_tdoa() {
                let mut reports = Vec::new();
                fuser.on_tdoa(&t, now, &mut reports);
                out.extend(reports.into_iter().map(event));
            }
            return;
        };
        stats.fixes += 1;
        let c = fix.cov_en;
        // Synchronisation errors persist from fix to fix; a filter that took
        // them as white would average them away and claim too much.
        let inflation = 1.0 + fix.sync_share * (sync_inflation - 1.0);
        let m = Measurement {
            t: fix.t,
            source: Source::Mlat,
            obs: Observation::Position {
                lat: fix.lat,
                lon: fix.lon,
                cov_en: nalgebra::Matrix2::new(c[0][0], c[0][1], c[1][0], c[1][1]) * inflation,
                // Heights come from altitude reports: a fix's own height is
                // either the barometric one it was given, or (without one)
                // so poorly determined that its linearised sigma cannot be
                // trusted (hundreds of metres off at 20 m sigma on the surface).
                height: None,
                time_sigma_s: 0.0,
                surface: false,
            },
        };
        let mut reports = Vec::new();
        if let (Some((lat, lon, sigma)), true) = (g.info.report, fix.dof >= 1 && fix.chi2 <= 3.0) {
            // The same transmission's ADS-B position against its fix.
            let p = crate::track::plane::Plane::new(lat, lon, 0.0);
            let d = p.to_en(fix.lat, fix.lon);
            let v = sigma * sigma;
            let s = [
                [v + c[0][0] * inflation, c[0][1] * inflation],
                [c[1][0] * inflation, v + c[1][1] * inflation],
            ];
            fuser.on_conformance(fix.addr, fix.t, d, s, &mut reports);
        }
        fuser.on_measurement(fix.addr, None, m, now, &mut reports);
        out.push(Event::Mlat(fix));
        out.extend(reports.into_iter().map(event));
    }

    /// One frame from receiver `rx`, arrived at `arrival` (Unix s).
    pub fn on_frame(&mut self, rx: usize, arrival: f64, frame: &RawFrame, out: &mut Vec<Event>) {
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
        self.advance(arrival, out);
        let (mlat, fuser, stats, sync_inflation) =
            (&mut self.mlat, &mut self.fuser, &mut self.stats, self.sync_inflation);
        match self.grouper.add(rx, arrival, frame, &mut |g: Group| {
            Self::on_group(mlat, fuser, stats, sync_inflation, &g, arrival, out)
        }) {
            Added::New => {}
            Added::Joined => return,
            Added::Duplicate => {
                self.stats.duplicates += 1;
                return;
            }
        }
        let decl = &self.receivers[rx].decl;
        let Ok(d) = self.decoder.decode_at(frame, arrival, Some((decl.lat, decl.lon))) else {
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
                }
            }
            _ => {}
        }
        // Only extended squitters (positions, velocities) need their time of
        // applicability: worked out once, and only for them.
        let timing = matches!(d.msg.body, Body::Extended(_)).then(|| self.frame_time(rx, arrival, frame));
        let report = timing.and_then(|timing| self.position_report(rx, timing, &d));
        info.suspect = self.fuser.is_suspect(d.msg.addr);
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
        self.grouper.set_newest_info(info);
        self.feed_tracker(arrival, timing, &d, report.as_ref());
        if let Some(p) = report {
            self.stats.positions += 1;
            out.push(Event::Position(p));
        }
        out.extend(self.tracks_out.drain(..).map(event));
    }

    /// Time of applicability of a frame: exact for GPS-timed receivers, and
    /// for counter-timed ones synchronised with a GPS-timed one (within a
    /// microsecond); the arrival time otherwise.
    fn frame_time(&mut self, rx: usize, arrival: f64, frame: &RawFrame) -> (f64, bool) {
        match self.receivers[rx].decl.clock {
            ClockKind::Gps if frame.has_timing() => (ClockKind::gps_unix(frame.timestamp, arrival), true),
            ClockKind::Beast12 if frame.has_timing() => {
                match self.mlat.gps_time_of(rx, frame.timestamp, arrival) {
                    // Sane only: within a second of the arrival, converted to a microsecond.
                    Some((t, var)) if var < 1e-12 && (arrival - t).abs() < 1.0 => (t, true),
                    _ => (arrival, false),
                }
            }
            _ => (arrival, false),
        }
    }

    /// What a decoded frame tells the tracker: positions, velocities,
    /// altitudes, and identity.
    /// `timing`: the frame's time of applicability, for extended squitters.
    fn feed_tracker(
        &mut self,
        arrival: f64,
        timing: Option<(f64, bool)>,
        d: &crate::modes::Decoded,
        report: Option<&PositionReport>,
    ) {
        if !d.trusted() {
            return;
        }
        let addr = d.msg.addr;
        let tcfg = self.time_sigma;
        let baro_sigma_m = self.baro_sigma_m;
        let out = &mut self.tracks_out;
        if let Some(p) = report {
            let Some(sigma) = p.sigma_m else {
                self.stats.untracked_positions += 1;
                return;
            };
            let time_sigma_s = if p.gps_timed { tcfg.0 } else { tcfg.1 };
            let m = Measurement {
                t: p.t,
                source: Source::Adsb,
                obs: Observation::Position {
                    lat: p.lat,
                    lon: p.lon,
                    cov_en: nalgebra::Matrix2::identity() * sigma * sigma,
                    height: p.alt_m.zip(p.alt_sigma_m.map(|s| s * s)),
                    time_sigma_s,
                    surface: p.surface,
                },
            };
            self.fuser.on_measurement(addr, p.nac_p, m, arrival, out);
            if let Some(a) = p.alt_baro_ft {
                self.fuser.set_alt_baro(addr, a);
            }
            return;
        }
        let baro_height = |alt_ft: i32| {
            let diff = d.gnss_baro_diff_ft;
            let sigma = if diff.is_some() { 8.0 } else { baro_sigma_m };
            ((alt_ft + diff.unwrap_or(0)) as f64 * FT_TO_M, sigma * sigma)
        };
        match d.msg.body {
            Body::AirAir { alt_ft: Some(a), .. } | Body::Altitude { alt_ft: Some(a), .. } => {
                let (h, var) = baro_height(a);
                let m = Measurement { t: arrival, source: Source::Mlat, obs: Observation::Height { h, var } };
                self.fuser.on_measurement(addr, None, m, arrival, out);
                self.fuser.set_alt_baro(addr, a);
            }
            Body::Identity { squawk, .. } => self.fuser.set_squawk(addr, squawk),
            Body::Extended(es) => match es.kind {
                Es::Identification { callsign, .. } => {
                    self.fuser.set_flight(addr, crate::modes::fields::callsign_str(&callsign).to_string())
                }
                Es::Emergency { squawk, .. } => self.fuser.set_squawk(addr, squawk),
                Es::Velocity(v) => {
                    let (Some(ve), Some(vn), Some((t_frame, _))) = (v.ve_kt, v.vn_kt, timing) else {
                        return;
                    };
                    // NACv: 95% bounds of horizontal (m/s) and vertical (ft/s) velocity error.
                    let (h95, v95_fps) = match v.nac_v {
                        4 => (0.3, 1.5),
                        3 => (1.0, 5.0),
                        2 => (3.0, 15.0),
                        1 => (10.0, 50.0),
                        _ => (30.0, 100.0),
                    };
                    // Plus the 1 kt (or 4 kt supersonic) and 64 ft/min resolution.
                    let step = if v.subtype == 2 { 4.0 } else { 1.0 } * KT_TO_MS;
                    let hv = (h95 / 2.448f64).powi(2) + step * step / 12.0;
                    let climb = v.vrate_fpm.map(|r| {
                        let s = v95_fps * FT_TO_M / 1.96;
                        (r as f64 * FT_TO_M / 60.0, s * s + (64.0 * FT_TO_M / 60.0).powi(2) / 12.0)
                    });
                    let m = Measurement {
                        t: t_frame,
                        source: Source::Adsb,
                        obs: Observation::Velocity {
                            v_en: nalgebra::Vector2::new(ve * KT_TO_MS, vn * KT_TO_MS),
                            cov: nalgebra::Matrix2::identity() * hv,
                            climb,
                        },
                    };
                    self.fuser.on_measurement(addr, None, m, arrival, out);
                }
                Es::AirbornePosition { alt_ft: Some(a), gnss: false, .. } => self.fuser.set_alt_baro(addr, a),
                _ => {}
            },
            _ => {}
        }
    }

    /// The ADS-B position report of a decoded frame, if it has a published position.
    fn position_report(
        &self,
        rx: usize,
        (t, gps_timed): (f64, bool),
        d: &crate::modes::Decoded,
    ) -> Option<PositionReport> {
        let (Some(p), Body::Extended(es)) = (d.position.filter(|p| p.reliable), d.msg.body) else {
            return None;
        };
        let (alt_m, alt_baro_ft, alt_sigma_m) = match es.kind {
            Es::AirbornePosition { alt_ft: Some(a), gnss: true, .. } => {
                (Some(a as f64 * FT_TO_M), None, Some(15.0))
            }
            Es::AirbornePosition { alt_ft: Some(a), gnss: false, .. } => (
                Some((a + d.gnss_baro_diff_ft.unwrap_or(0)) as f64 * FT_TO_M),
                Some(a),
                Some(if d.gnss_baro_diff_ft.is_some() { 8.0 } else { self.baro_sigma_m }),
            ),
            _ => (None, None, None),
        };
        // EPU is a 95% radius: per-axis sigma = EPU / 2.448. Version 0 reports
        // NUCp, whose 95% accuracy bound is about half its protection limit.
        let epu = match d.nac_p.filter(|&n| n > 0) {
            Some(n) => nacp_epu_m(n),
            None => d.nuc_p.and_then(nucp_hpl_m).map(|h| h / 2.0),
        };
        Some(PositionReport {
            addr: d.msg.addr,
            t,
            lat: p.lat,
            lon: p.lon,
            alt_m,
            alt_baro_ft,
            alt_sigma_m,
            nac_p: d.nac_p,
            sigma_m: epu.map(|e| e / 2.448),
            gps_timed,
            surface: p.surface,
            rx,
        })
    }
}
