//! The fused picture in readsb's `aircraft.json` format, so that tar1090 and
//! other tools written for readsb can be pointed at fuse1090.
//!
//! An [`AircraftView`] is fed the core's events as they are published and
//! rendered on demand (the live service does it once a second, not per
//! request). It is sans-IO and keeps one small entry per aircraft, aged out
//! like the tracks themselves, so it is bounded by the traffic.
//!
//! A field published under one of readsb's names means what it means there,
//! in readsb's unit: `alt_baro` and `alt_geom` in feet (`"ground"` for an
//! aircraft reporting surface positions), `gs` in knots, `track` in degrees
//! true, `geom_rate` in ft/min, `seen` and `seen_pos` in seconds ago.
//! `mlat` names the fields whose value came from multilateration, as readsb
//! does. What readsb gets from messages fuse1090 does not keep per aircraft
//! (`messages`, `rssi`, `category`) is left out rather than made up; what is
//! fuse1090's own (track number, covariance, sources) sits under the one
//! key `fuse1090`.

use std::collections::HashMap;

use serde::Serialize;

use crate::core::Event;
use crate::fuse::TrackSource;
use crate::fuse::{Alert, TrackReport};
use crate::publish::json::round;
use crate::publish::readout::readout;
use crate::track::measurement::Source;

/// An aircraft leaves the view this long (s) after its fused track's last
/// publication: a track that stopped being published has ended.
pub const TRACK_TTL_S: f64 = 60.0;
/// The most aircraft the view holds; beyond it the stalest is forgotten.
pub const MAX_AIRCRAFT: usize = 100_000;

#[derive(Clone, Debug)]
struct Entry {
    track: Box<TrackReport>,
    /// Arrival-time scale of the last event about it.
    seen: f64,
    /// Its newest ADS-B position said it is on the ground.
    surface: bool,
    /// Aircraft it is in a predicted conflict with.
    conflicts: Vec<u32>,
}

/// The newest fused track of every aircraft, from the event stream.
#[derive(Default)]
pub struct AircraftView {
    aircraft: HashMap<u32, Entry>,
}

/// One aircraft as readsb writes it. Absent is `None`, never `null`.
#[derive(Serialize)]
struct Aircraft<'a> {
    hex: String,
    #[serde(rename = "type")]
    kind: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    flight: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    alt_baro: Option<serde_json::Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    alt_geom: Option<i64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    gs: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    track: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    geom_rate: Option<i64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    squawk: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    nav_altitude_mcp: Option<u32>,
    lat: f64,
    lon: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    nac_p: Option<u8>,
    seen: f64,
    seen_pos: f64,
    mlat: Vec<&'static str>,
    tisb: [&'static str; 0],
    fuse1090: Own<'a>,
}

/// fuse1090's own fields, under their one key.
#[derive(Serialize)]
struct Own<'a> {
    id: u64,
    sources: &'a [Source],
    /// Horizontal position covariance [[ee, en], [ne, nn]] (m²).
    cov_en: [[f64; 2]; 2],
    /// Radius holding the position with 95% probability (m), from `cov_en`.
    h95_m: f64,
    /// 1-sigma of each horizontal velocity component (m/s).
    vel_sigma_ms: f64,
    adsb_suspect: bool,
    motion: &'static str,
    period_s: f64,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    conflicts: Vec<String>,
    /// A particle filter's estimate: too few receivers for a fix.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    sparse: bool,
}

#[derive(Serialize)]
struct Document<'a> {
    now: f64,
    messages: u64,
    aircraft: Vec<Aircraft<'a>>,
}

impl AircraftView {
    pub fn new() -> AircraftView {
        AircraftView::default()
    }

    /// Takes in published events; `now` is the time they were published.
    pub fn observe(&mut self, events: &[Event], now: f64) {
        for ev in events {
            match ev {
                Event::Track(r) if r.source == TrackSource::Fused => self.track(r, now),
                Event::Position(p) => {
                    if let Some(e) = self.aircraft.get_mut(&p.addr) {
                        e.surface = p.surface;
                        e.seen = now;
                    }
                }
                Event::Mlat(f) => {
                    if let Some(e) = self.aircraft.get_mut(&f.addr) {
                        e.seen = now;
                    }
                }
                Event::Alert(Alert::Conflict { pair: [(a, _), (b, _)], active, .. }) => {
                    self.conflict(*a, *b, *active);
                    self.conflict(*b, *a, *active);
                }
                _ => {}
            }
        }
    }

    fn track(&mut self, r: &TrackReport, now: f64) {
        if !self.aircraft.contains_key(&r.addr) && self.aircraft.len() >= MAX_AIRCRAFT {
            self.forget_stalest();
        }
        match self.aircraft.get_mut(&r.addr) {
            Some(e) => {
                (*e.track).clone_from(r);
                e.seen = now;
            }
            None => {
                let e =
                    Entry { track: Box::new(r.clone()), seen: now, surface: false, conflicts: Vec::new() };
                self.aircraft.insert(r.addr, e);
            }
        }
    }

    fn conflict(&mut self, addr: u32, other: u32, active: bool) {
        if let Some(e) = self.aircraft.get_mut(&addr) {
            e.conflicts.retain(|&o| o != other);
            if active {
                e.conflicts.push(other);
            }
        }
    }

    fn forget_stalest(&mut self) {
        if let Some((&addr, _)) =
            self.aircraft.iter().min_by(|a, b| a.1.track.est.t.total_cmp(&b.1.track.est.t))
        {
            self.aircraft.remove(&addr);
        }
    }

    /// Forgets aircraft whose track has not been published for [`TRACK_TTL_S`]
    /// (by the newest estimate's time: ADS-B reports or fixes that no
    /// longer reach a track must not keep its last position on show).
    pub fn expire(&mut self, now: f64) {
        self.aircraft.retain(|_, e| now - e.track.est.t <= TRACK_TTL_S);
    }

    pub fn len(&self) -> usize {
        self.aircraft.len()
    }

    pub fn is_empty(&self) -> bool {
        self.aircraft.is_empty()
    }

    /// The document readsb serves at `/data/aircraft.json`, at `now`;
    /// `messages` is the total of Mode S messages received.
    pub fn render(&self, now: f64, messages: u64) -> Vec<u8> {
        let mut list: Vec<(&u32, &Entry)> = self.aircraft.iter().collect();
        list.sort_unstable_by_key(|(a, _)| **a);
        let aircraft = list.into_iter().map(|(_, e)| aircraft(e, now)).collect();
        let doc = Document { now: round(now, 10.0), messages, aircraft };
        // Into memory: cannot fail.
        serde_json::to_vec(&doc).unwrap_or_default()
    }
}

fn aircraft(e: &Entry, now: f64) -> Aircraft<'_> {
    let r = &e.track;
    let est = &r.est;
    let ro = readout(r);
    let adsb = ro.adsb;
    // What multilateration alone gave, readsb's way of saying a field is not
    // the aircraft's own report.
    let mlat = if adsb { Vec::new() } else { vec!["lat", "lon", "gs", "track", "geom_rate", "alt_geom"] };
    let cov = est.cov_en();
    Aircraft {
        hex: format!("{:06x}", r.addr),
        kind: if adsb { "adsb_icao" } else { "mlat" },
        flight: r.flight.as_deref().filter(|f| !f.is_empty()).map(|f| format!("{f:<8}")),
        alt_baro: if e.surface {
            Some(serde_json::Value::from("ground"))
        } else {
            r.alt_baro_ft.map(serde_json::Value::from)
        },
        alt_geom: ro.alt_geom_ft,
        gs: ro.gs_kt().map(|v| round(v, 10.0)),
        track: ro.track_deg.map(|v| round(v, 100.0)),
        geom_rate: ro.geom_rate_fpm,
        squawk: r.squawk.map(|s| format!("{s:04x}")),
        nav_altitude_mcp: r.nav_altitude_ft,
        lat: round(est.lat, 1e6),
        lon: round(est.lon, 1e6),
        nac_p: r.nac_p,
        seen: round((now - e.seen).max(0.0), 10.0),
        seen_pos: round((now - est.t).max(0.0), 1000.0),
        mlat,
        tisb: [],
        fuse1090: Own {
            id: r.id,
            sources: &r.sources,
            cov_en: cov.map(|row| row.map(|v| round(v, 10.0))),
            h95_m: round(h95(cov), 10.0),
            vel_sigma_ms: round(ro.vel_sigma_ms, 100.0),
            adsb_suspect: r.adsb_suspect,
            motion: r.motion.name(),
            period_s: r.period_s,
            conflicts: e.conflicts.iter().map(|a| format!("{a:06x}")).collect(),
            sparse: r.sparse,
        },
    }
}

/// The radius of the circle holding the position with 95% probability:
/// from the larger eigenvalue, a slight overstatement for an elongated
/// ellipse, which a map's circle should rather be than an understatement.
fn h95(c: [[f64; 2]; 2]) -> f64 {
    let (a, b, d) = (c[0][0], c[0][1], c[1][1]);
    let big = 0.5 * (a + d) + (0.25 * (a - d).powi(2) + b * b).sqrt();
    // 2-D chi-square 95% quantile: 5.991.
    (5.991 * big.max(0.0)).sqrt()
}

#[cfg(test)]
mod tests {

    use serde_json::Value;

    use super::*;
    use crate::publish::readout::MAX_VEL_SIGMA_MS;
    use crate::publish::test_report::{position, report, Source};

    fn rendered(view: &AircraftView, now: f64) -> Value {
        serde_json::from_slice(&view.render(now, 42)).unwrap()
    }

    #[test]
    fn readsb_names_carry_readsb_units() {
        let mut view = AircraftView::new();
        view.observe(
            &[Event::Track(Box::new(report(0x3C6DD4, 100.0, &[Source::Adsb, Source::Mlat])))],
            100.5,
        );
        let doc = rendered(&view, 101.0);
        assert_eq!(doc["now"], 101.0);
        assert_eq!(doc["messages"], 42);
        let a = &doc["aircraft"][0];
        assert_eq!(a["hex"], "3c6dd4");
        assert_eq!(a["type"], "adsb_icao");
        assert_eq!(a["flight"], "AFR12   ");
        assert_eq!(a["squawk"], "7001");
        assert_eq!(a["alt_baro"], 3200);
        // 1000 m = 3280.8 ft; 100 m/s = 194.4 kt; 5 m/s = 984.3 ft/min.
        assert_eq!(a["alt_geom"], 3281);
        assert_eq!(a["gs"], 194.4);
        assert_eq!(a["track"], 45.0);
        assert_eq!(a["geom_rate"], 984);
        assert_eq!(a["seen"], 0.5);
        assert_eq!(a["seen_pos"], 1.0);
        assert_eq!(a["mlat"], serde_json::json!([]));
        assert_eq!(a["nac_p"], 9);
        let own = &a["fuse1090"];
        assert_eq!(own["id"], 7);
        // 95% of a 10 m by 5 m ellipse: within sqrt(5.991) x 10 m.
        assert_eq!(own["h95_m"], 24.5);
        assert!(a.get("rssi").is_none() && a.get("category").is_none(), "not kept: left out, not made up");
    }

    #[test]
    fn a_velocity_not_known_yet_is_left_out() {
        let mut r = report(1, 10.0, &[Source::Adsb]);
        r.est.state.p *= (MAX_VEL_SIGMA_MS + 0.1).powi(2);
        let mut view = AircraftView::new();
        view.observe(&[Event::Track(Box::new(r.clone()))], 10.0);
        let a = &rendered(&view, 10.0)["aircraft"][0];
        assert!(a.get("gs").is_none() && a.get("track").is_none(), "{a}");
        // Known well enough, but slower than three sigmas: a speed, no direction.
        r.est.state.p = nalgebra::Matrix6::identity() * 9.0;
        r.est.vel_enu = [5.0, 5.0, 0.0];
        view.observe(&[Event::Track(Box::new(r))], 11.0);
        let a = &rendered(&view, 11.0)["aircraft"][0];
        assert!(a.get("gs").is_some() && a.get("track").is_none(), "{a}");
    }

    #[test]
    fn multilateration_alone_is_said_field_by_field() {
        let mut view = AircraftView::new();
        view.observe(&[Event::Track(Box::new(report(1, 10.0, &[Source::Mlat])))], 10.0);
        let a = &rendered(&view, 10.0)["aircraft"][0];
        assert_eq!(a["type"], "mlat");
        let fields: Vec<&str> = a["mlat"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
        for f in ["lat", "lon", "gs", "track"] {
            assert!(fields.contains(&f), "{f} missing from {fields:?}");
        }
    }

    #[test]
    fn single_source_tracks_are_not_shown_and_surface_aircraft_are_on_the_ground() {
        let mut view = AircraftView::new();
        let mut adsb_only = report(2, 10.0, &[Source::Adsb]);
        adsb_only.source = TrackSource::Adsb;
        view.observe(&[Event::Track(Box::new(adsb_only))], 10.0);
        assert!(view.is_empty(), "the fused track is the aircraft's; per-source ones are not");
        view.observe(&[Event::Track(Box::new(report(2, 10.0, &[Source::Adsb])))], 10.0);
        view.observe(&[Event::Position(position(2, 10.0, true))], 10.2);
        assert_eq!(rendered(&view, 10.5)["aircraft"][0]["alt_baro"], "ground");
    }

    #[test]
    fn conflicts_are_listed_while_active_and_aircraft_age_out() {
        let mut view = AircraftView::new();
        view.observe(&[Event::Track(Box::new(report(1, 0.0, &[Source::Adsb])))], 0.0);
        view.observe(&[Event::Track(Box::new(report(2, 0.0, &[Source::Adsb])))], 0.0);
        let conflict = |active| Alert::Conflict {
            t: 1.0,
            pair: [(1, 10), (2, 20)],
            active,
            tau_s: 60.0,
            t_cpa_s: 61.0,
            miss_m: 900.0,
            dz_m: 100.0,
        };
        view.observe(&[Event::Alert(conflict(true))], 1.0);
        let doc = rendered(&view, 1.0);
        assert_eq!(doc["aircraft"][0]["fuse1090"]["conflicts"], serde_json::json!(["000002"]));
        assert_eq!(doc["aircraft"][1]["fuse1090"]["conflicts"], serde_json::json!(["000001"]));
        view.observe(&[Event::Alert(conflict(false))], 2.0);
        assert!(rendered(&view, 2.0)["aircraft"][0]["fuse1090"].get("conflicts").is_none());
        view.observe(&[Event::Track(Box::new(report(2, 50.0, &[Source::Adsb])))], 50.0);
        view.expire(TRACK_TTL_S + 1.0);
        assert_eq!(view.len(), 1, "aircraft 1, not published for longer than the TTL, is gone");
    }

    #[test]
    fn reports_that_reach_no_track_do_not_keep_an_aircraft() {
        let mut view = AircraftView::new();
        view.observe(&[Event::Track(Box::new(report(1, 0.0, &[Source::Adsb])))], 0.0);
        for t in 1..=70 {
            view.observe(&[Event::Position(position(1, t as f64, false))], t as f64);
        }
        view.expire(70.0);
        assert!(view.is_empty(), "a track last published 70 s ago is gone, its reports still coming or not");
    }

    #[test]
    fn the_view_is_bounded() {
        let mut view = AircraftView::new();
        for a in 0..MAX_AIRCRAFT as u32 + 10 {
            view.observe(&[Event::Track(Box::new(report(a, a as f64, &[Source::Adsb])))], a as f64);
        }
        assert_eq!(view.len(), MAX_AIRCRAFT);
        let doc = rendered(&view, 1e6);
        assert_eq!(doc["aircraft"][0]["hex"], "00000a", "the stalest went first");
    }
}
