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

use crate::feed::capture::{ClockKind, ReceiverDecl};
use crate::feed::RawFrame;
use crate::geo::geodetic_to_ecef;
use crate::geo::FT_TO_M;
use crate::mlat::group::{Added, Group, GroupInfo, Grouper};
use crate::mlat::{Mlat, MlatConfig, MlatFix};
use crate::modes::nic::{nacp_epu_m, nucp_hpl_m};
use crate::modes::{Body, Decoder, DecoderConfig, Es};

#[derive(Clone, Debug, Deserialize)]
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
}

impl Default for CoreConfig {
    fn default() -> Self {
        CoreConfig {
            group_wait_s: 0.5,
            max_pending_groups: 200_000,
            max_range_km: 600.0,
            aircraft_ttl_s: 300.0,
            mlat: MlatConfig::default(),
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
    pub nac_p: Option<u8>,
    /// 1-sigma horizontal error per axis (m) implied by NACp (or NUCp).
    pub sigma_m: Option<f64>,
    pub surface: bool,
    pub rx: usize,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    Position(PositionReport),
    Mlat(MlatFix),
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
    stats: CoreStats,
    min_sync_nacp: u8,
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
            stats: CoreStats::default(),
            min_sync_nacp: cfg.mlat.min_sync_nacp,
        }
    }

    pub fn add_receiver(&mut self, decl: ReceiverDecl) -> usize {
        self.mlat.add_receiver(&decl);
        self.receivers.push(RxState { decl, frames: 0 });
        self.receivers.len() - 1
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

    /// Moves time forward to `now` (arrival-time scale): groups whose wait ran out are processed.
    pub fn advance(&mut self, now: f64, out: &mut Vec<Event>) {
        let (mlat, stats) = (&mut self.mlat, &mut self.stats);
        self.grouper.advance(now, &mut |g: Group| Self::on_group(mlat, stats, &g, now, out));
    }

    /// End of input: everything pending is processed.
    pub fn finish(&mut self, out: &mut Vec<Event>) {
        let (mlat, stats) = (&mut self.mlat, &mut self.stats);
        self.grouper.flush(&mut |g: Group| {
            let now = g.first_arrival;
            Self::on_group(mlat, stats, &g, now, out)
        });
    }

    fn on_group(mlat: &mut Mlat, stats: &mut CoreStats, g: &Group, now: f64, out: &mut Vec<Event>) {
        if let Some(fix) = mlat.on_group(g, now) {
            stats.fixes += 1;
            out.push(Event::Mlat(fix));
        }
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
        let (mlat, stats) = (&mut self.mlat, &mut self.stats);
        match self
            .grouper
            .add(rx, arrival, frame, &mut |g: Group| Self::on_group(mlat, stats, &g, arrival, out))
        {
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
        let report = self.position_report(rx, arrival, frame, &d);
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
        if let Some(p) = report {
            self.stats.positions += 1;
            out.push(Event::Position(p));
        }
    }

    /// The ADS-B position report of a decoded frame, if it has a published position.
    fn position_report(
        &self,
        rx: usize,
        arrival: f64,
        frame: &RawFrame,
        d: &crate::modes::Decoded,
    ) -> Option<PositionReport> {
        let decl = &self.receivers[rx].decl;
        let (Some(p), Body::Extended(es)) = (d.position.filter(|p| p.reliable), d.msg.body) else {
            return None;
        };
        let t = match decl.clock {
            ClockKind::Gps if frame.has_timing() => ClockKind::gps_unix(frame.timestamp, arrival),
            _ => arrival,
        };
        let (alt_m, alt_baro_ft) = match es.kind {
            Es::AirbornePosition { alt_ft: Some(a), gnss: true, .. } => (Some(a as f64 * FT_TO_M), None),
            Es::AirbornePosition { alt_ft: Some(a), gnss: false, .. } => {
                (Some((a + d.gnss_baro_diff_ft.unwrap_or(0)) as f64 * FT_TO_M), Some(a))
            }
            _ => (None, None),
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
            nac_p: d.nac_p,
            sigma_m: epu.map(|e| e / 2.448),
            surface: p.surface,
            rx,
        })
    }
}
