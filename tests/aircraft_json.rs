//! `/data/aircraft.json` against the truth of simulated worlds: every field
//! published under one of readsb's names must mean what it means in readsb,
//! in readsb's unit. The committed captures are run through the core as the
//! daemon runs them, the view rendered every two seconds of their time, and
//! each aircraft's position, heights, ground speed, track and climb compared
//! with the simulation's truth at the time the document says its position is
//! of (`now - seen_pos`). A field in the wrong unit (metres for feet, m/s for
//! knots, radians, a heading counted from east) is off by far more than the
//! tolerances.

mod common;

use fuse1090::core::{Core, CoreConfig};
use fuse1090::eval::Truth;
use fuse1090::feed::capture::{CaptureReader, CaptureRecord};
use fuse1090::publish::aircraft_json::AircraftView;
use serde_json::Value;

/// readsb's aircraft keys that fuse1090 may publish, with what they are.
const READSB_KEYS: &[(&str, &str)] = &[
    ("hex", "ICAO address, 6 lower-case hex digits"),
    ("type", "the best source of the current data"),
    ("flight", "callsign, 8 characters"),
    ("alt_baro", "barometric altitude, ft, or \"ground\""),
    ("alt_geom", "geometric altitude above the WGS-84 ellipsoid, ft"),
    ("gs", "ground speed, kt"),
    ("track", "true track over ground, degrees"),
    ("geom_rate", "rate of geometric altitude, ft/min"),
    ("squawk", "Mode A code, 4 octal digits"),
    ("lat", "degrees"),
    ("lon", "degrees"),
    ("nac_p", "navigation accuracy category, position"),
    ("seen", "s since the last message"),
    ("seen_pos", "s since the position was last updated"),
    ("mlat", "fields derived from multilateration"),
    ("tisb", "fields derived from TIS-B"),
];

const FT: f64 = 0.3048;
const KT: f64 = 1852.0 / 3600.0;

struct Checked {
    aircraft: usize,
    /// Documents giving a ground speed and a track.
    moving: usize,
    mlat: usize,
    worst_h_m: f64,
}

fn check(name: &str, h_tol_m: f64) -> Checked {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/captures").join(name);
    let capture = std::fs::read(dir.join("capture.txt")).unwrap();
    let truth =
        Truth::read(std::fs::File::open(dir.join("truth.jsonl")).map(std::io::BufReader::new).unwrap())
            .unwrap();
    let mut reader = CaptureReader::new(&capture[..], name);
    let mut core = Core::new(&CoreConfig::default());
    let mut view = AircraftView::new();
    let (mut events, mut next_render) = (Vec::new(), f64::NEG_INFINITY);
    let mut checked = Checked { aircraft: 0, moving: 0, mlat: 0, worst_h_m: 0.0 };
    while let Some(rec) = reader.next_record().unwrap() {
        let now = match &rec {
            CaptureRecord::Frame(f) => Some(f.arrival),
            CaptureRecord::Receiver(_) => None,
        };
        core.handle_record(rec);
        events.extend(std::iter::from_fn(|| core.poll_event()));
        let Some(now) = now else { continue };
        view.observe(&events, now);
        events.clear();
        if now < next_render {
            continue;
        }
        next_render = now + 2.0;
        let doc: Value = serde_json::from_slice(&view.render(now, 0)).unwrap();
        for a in doc["aircraft"].as_array().unwrap() {
            let c = compare(name, a, &truth, now, h_tol_m);
            checked.aircraft += 1;
            checked.moving += usize::from(a["gs"].is_number() && a["track"].is_number());
            checked.mlat += usize::from(a["type"] == "mlat");
            checked.worst_h_m = checked.worst_h_m.max(c);
        }
    }
    checked
}

/// One aircraft against the truth; returns its horizontal error (m).
fn compare(name: &str, a: &Value, truth: &Truth, now: f64, h_tol_m: f64) -> f64 {
    let obj = a.as_object().unwrap();
    for k in obj.keys().filter(|k| *k != "fuse1090") {
        assert!(READSB_KEYS.iter().any(|(r, _)| r == k), "{name}: {k} is not one of readsb's keys");
    }
    let hex = a["hex"].as_str().unwrap();
    assert!(hex.len() == 6 && hex.chars().all(|c| c.is_ascii_digit() || ('a'..='f').contains(&c)), "{hex}");
    let upper = hex.to_uppercase();
    let t = now - a["seen_pos"].as_f64().unwrap();
    let what = format!("{name} {hex} at {t:.1}");
    let (lat, lon, alt_m) = truth.position(&upper, t).unwrap_or_else(|| panic!("{what}: no truth"));
    let h = common::en(lat, lon, a["lat"].as_f64().unwrap(), a["lon"].as_f64().unwrap());
    let h_err = h[0].hypot(h[1]);
    assert!(h_err < h_tol_m, "{what}: {h_err:.0} m from the truth");
    if let Some(geom) = a["alt_geom"].as_f64() {
        assert!((geom * FT - alt_m).abs() < 30.0, "{what}: alt_geom {geom} ft, truth {alt_m:.0} m");
    }
    match &a["alt_baro"] {
        Value::String(s) => assert_eq!(s, "ground", "{what}"),
        Value::Number(n) => {
            // Barometric and geometric heights differ by the weather, never by 3.28x.
            let baro_m = n.as_f64().unwrap() * FT;
            assert!((baro_m - alt_m).abs() < 150.0, "{what}: alt_baro {n} ft, truth {alt_m:.0} m");
        }
        Value::Null => {}
        v => panic!("{what}: alt_baro {v}"),
    }
    // The truth's velocity over a second around t.
    let (before, after) = (truth.position(&upper, t - 0.5), truth.position(&upper, t + 0.5));
    if let (Some(p0), Some(p1)) = (before, after) {
        let v = common::en(p0.0, p0.1, p1.0, p1.1);
        let (gs_kt, climb) = (v[0].hypot(v[1]) / KT, p1.2 - p0.2);
        // Within four of its own sigmas (per axis, so the speed's), and
        // published only when known.
        let sigma_kt = a["fuse1090"]["vel_sigma_ms"].as_f64().unwrap() / KT;
        if let Some(gs) = a["gs"].as_f64() {
            assert!(
                (gs - gs_kt).abs() < 1.0 + 4.0 * sigma_kt,
                "{what}: gs {gs} kt, truth {gs_kt:.1} ±{sigma_kt:.1} kt"
            );
        }
        if gs_kt > 60.0 && a["track"].is_number() {
            let track = v[0].atan2(v[1]).to_degrees().rem_euclid(360.0);
            let off = (a["track"].as_f64().unwrap() - track + 540.0).rem_euclid(360.0) - 180.0;
            assert!(off.abs() < 5.0, "{what}: track {} against {track:.1} deg", a["track"]);
        }
        if let Some(rate) = a["geom_rate"].as_f64() {
            let truth_rate = climb / FT * 60.0;
            assert!(
                (rate - truth_rate).abs() < 400.0,
                "{what}: geom_rate {rate} ft/min, truth {truth_rate:.0}"
            );
        }
    }
    let mlat: Vec<&str> = a["mlat"].as_array().unwrap().iter().filter_map(Value::as_str).collect();
    assert_eq!(a["type"] == "mlat", mlat.contains(&"lat"), "{what}: type and mlat[] disagree");
    if let Some(s) = a["squawk"].as_str() {
        assert!(s.len() == 4 && s.chars().all(|c| ('0'..='7').contains(&c)), "{what}: squawk {s}");
    }
    if let Some(f) = a["flight"].as_str() {
        assert_eq!(f.len(), 8, "{what}: flight {f:?}");
    }
    h_err
}

#[test]
fn an_airborne_aircraft_means_what_readsb_means() {
    let c = check("fusion-8seg", 100.0);
    assert!(c.aircraft > 30, "{} aircraft documents checked", c.aircraft);
    assert!(c.moving + 3 > c.aircraft, "speed and track in {} of {}", c.moving, c.aircraft);
    assert!(c.worst_h_m > 0.0, "positions compared");
}

#[test]
fn surface_traffic_and_a_multilaterated_aircraft_mean_what_readsb_means() {
    let c = check("surface", 50.0);
    assert!(c.aircraft > 200, "{} aircraft documents checked", c.aircraft);
    assert!(c.mlat > 10, "the Mode S-only aircraft shown as mlat ({} times)", c.mlat);
}
