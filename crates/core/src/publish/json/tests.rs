use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::core::Dating;
use crate::fuse::TrackSource;
use crate::track::kf::Gaussian;
use crate::track::measurement::Source;
use crate::track::motion::Motion;
use crate::track::plane::Plane;
use crate::track::Estimate;

/// The serde derive the hand-written records replaced, kept as their
/// reference: same fields, same order, same rounding.
mod reference {
    use serde::Serialize;

    use super::super::{round, Hex};
    use crate::core::PositionReport;
    use crate::fuse::TrackReport;
    use crate::mlat::MlatFix;
    use crate::track::measurement::Source;

    #[derive(Serialize)]
    struct Mlat<'a> {
        #[serde(rename = "type")]
        kind: &'static str,
        hex: Hex,
        t: f64,
        lat: f64,
        lon: f64,
        alt_m: f64,
        cov_en: [[f64; 2]; 2],
        receivers: Vec<&'a str>,
        gdop: f64,
        chi2: f64,
        altitude_used: bool,
    }

    #[derive(Serialize)]
    struct Position<'a> {
        #[serde(rename = "type")]
        kind: &'static str,
        source: &'static str,
        hex: Hex,
        t: f64,
        lat: f64,
        lon: f64,
        #[serde(skip_serializing_if = "Option::is_none")]
        alt_m: Option<f64>,
        #[serde(skip_serializing_if = "Option::is_none")]
        alt_baro_ft: Option<i32>,
        #[serde(skip_serializing_if = "Option::is_none")]
        nac_p: Option<u8>,
        #[serde(skip_serializing_if = "Option::is_none")]
        cov_en: Option<[[f64; 2]; 2]>,
        surface: bool,
        receiver: &'a str,
    }

    #[derive(Serialize)]
    struct Track<'a> {
        #[serde(rename = "type")]
        kind: &'static str,
        id: u64,
        hex: Hex,
        t: f64,
        lat: f64,
        lon: f64,
        #[serde(skip_serializing_if = "Option::is_none")]
        alt_m: Option<f64>,
        #[serde(skip_serializing_if = "Option::is_none")]
        alt_baro_ft: Option<i32>,
        vel_enu: [f64; 3],
        cov_en: [[f64; 2]; 2],
        source: &'static str,
        sources: &'a [Source],
        #[serde(skip_serializing_if = "Option::is_none")]
        nac_p: Option<u8>,
        period_s: f64,
        motion: &'static str,
        adsb_suspect: bool,
        #[serde(skip_serializing_if = "Option::is_none")]
        flight: Option<&'a str>,
        #[serde(skip_serializing_if = "Option::is_none")]
        squawk: Option<Hex>,
        #[serde(skip_serializing_if = "Option::is_none")]
        nav_altitude_mcp: Option<u32>,
        #[serde(skip_serializing_if = "std::ops::Not::not")]
        sparse: bool,
    }

    pub fn position(p: &PositionReport, receiver: &str) -> String {
        serde_json::to_string(&Position {
            kind: "position",
            source: "adsb",
            hex: Hex::addr(p.addr),
            t: round(p.t, 1e6),
            lat: round(p.lat, 1e8),
            lon: round(p.lon, 1e8),
            alt_m: p.alt_m.map(|a| round(a, 100.0)),
            alt_baro_ft: p.alt_baro_ft,
            nac_p: p.nac_p,
            cov_en: p.sigma_m.map(|s| round(s * s, 1e3)).map(|v| [[v, 0.0], [0.0, v]]),
            surface: p.surface,
            receiver,
        })
        .unwrap()
    }

    pub fn mlat<'a>(f: &MlatFix, receiver_id: impl Fn(usize) -> &'a str) -> String {
        serde_json::to_string(&Mlat {
            kind: "mlat",
            hex: Hex::addr(f.addr),
            t: round(f.t, 1e9),
            lat: round(f.lat, 1e8),
            lon: round(f.lon, 1e8),
            alt_m: round(f.alt_m, 100.0),
            cov_en: f.cov_en.map(|r| r.map(|v| round(v, 1e3))),
            receivers: f.receivers.iter().map(|&r| receiver_id(r)).collect(),
            gdop: round(f.gdop, 1e3),
            chi2: round(f.chi2, 1e3),
            altitude_used: f.altitude_used,
        })
        .unwrap()
    }

    pub fn track(r: &TrackReport) -> String {
        let e = &r.est;
        serde_json::to_string(&Track {
            kind: "track",
            id: r.id,
            hex: Hex::addr(r.addr),
            t: round(e.t, 1e6),
            lat: round(e.lat, 1e8),
            lon: round(e.lon, 1e8),
            alt_m: e.alt_m.map(|a| round(a, 100.0)),
            alt_baro_ft: r.alt_baro_ft,
            vel_enu: e.vel_enu.map(|v| round(v, 1e3)),
            cov_en: e.cov_en().map(|row| row.map(|v| round(v, 1e3))),
            source: r.source.name(),
            sources: &r.sources,
            nac_p: r.nac_p,
            period_s: r.period_s,
            motion: r.motion.name(),
            adsb_suspect: r.adsb_suspect,
            flight: r.flight.as_deref().filter(|f| !f.is_empty()),
            squawk: r.squawk.map(|s| Hex::new(s.into(), 4)),
            nav_altitude_mcp: r.nav_altitude_ft,
            sparse: r.sparse,
        })
        .unwrap()
    }
}

/// Numbers of every kind the records can hold: ordinary values at every
/// scale, both zeros, and what JSON cannot hold (written `null`).
fn number(rng: &mut ChaCha8Rng) -> f64 {
    match rng.gen_range(0..12) {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => f64::NEG_INFINITY,
        3 => -0.0,
        4 => 0.0,
        5 => f64::MAX,
        6 => f64::MIN_POSITIVE,
        7 => rng.gen_range(-1.0..1.0) * 10f64.powi(rng.gen_range(-12..20)),
        8 => rng.gen_range(-90.0..90.0),
        9 => 1.7e9 + rng.gen_range(0.0..1e6),
        _ => rng.gen_range(-1e4..1e4),
    }
}

/// Names as an operator might give them, including what JSON escapes.
fn name(rng: &mut ChaCha8Rng) -> String {
    const PIECES: [&str; 12] =
        ["r1", "rx-05", "", " ", "\"", "\\", "\n", "\u{1}", "\u{7f}", "é", "日本", "a\tb"];
    (0..rng.gen_range(0..4)).map(|_| PIECES[rng.gen_range(0..PIECES.len())]).collect()
}

fn maybe<T>(rng: &mut ChaCha8Rng, value: impl FnOnce(&mut ChaCha8Rng) -> T) -> Option<T> {
    rng.gen_bool(0.7).then(|| value(rng))
}

fn line(ev: &Event, names: &[String]) -> String {
    let mut out = Vec::new();
    write_event(&mut out, ev, |i| names[i].as_str());
    String::from_utf8(out).unwrap()
}

#[test]
fn records_are_the_bytes_serde_json_wrote_for_them() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..3_000 {
        let names: Vec<String> = (0..9).map(|_| name(&mut rng)).collect();
        let p = PositionReport {
            addr: rng.gen::<u32>() >> rng.gen_range(0..32),
            t: number(&mut rng),
            lat: number(&mut rng),
            lon: number(&mut rng),
            alt_m: maybe(&mut rng, number),
            alt_baro_ft: maybe(&mut rng, |r| r.gen()),
            alt_sigma_m: None,
            nac_p: maybe(&mut rng, |r| r.gen()),
            sigma_m: maybe(&mut rng, number),
            dating: Dating::Gps,
            surface: rng.gen(),
            rx: rng.gen_range(0..names.len()),
        };
        let expected = reference::position(&p, &names[p.rx]) + "\n";
        assert_eq!(line(&Event::Position(p), &names), expected);

        let f = MlatFix {
            addr: rng.gen(),
            t: number(&mut rng),
            lat: number(&mut rng),
            lon: number(&mut rng),
            alt_m: number(&mut rng),
            cov_en: [[number(&mut rng), number(&mut rng)], [number(&mut rng), number(&mut rng)]],
            cov_ecef: [[0.0; 3]; 3],
            receivers: (0..rng.gen_range(0..12)).map(|_| rng.gen_range(0..names.len())).collect(),
            gdop: number(&mut rng),
            chi2: number(&mut rng),
            dof: 1,
            altitude_used: rng.gen(),
            sync_share: 0.0,
            self_sync_share: 0.0,
            df: 17,
        };
        let expected = reference::mlat(&f, |i| names[i].as_str()) + "\n";
        assert_eq!(line(&Event::Mlat(Box::new(f)), &names), expected);

        let plane = Plane::new(rng.gen_range(-80.0..80.0), rng.gen_range(-180.0..180.0), 0.0);
        let est = Estimate {
            t: number(&mut rng),
            lat: number(&mut rng),
            lon: number(&mut rng),
            alt_m: maybe(&mut rng, number),
            vel_enu: [number(&mut rng), number(&mut rng), number(&mut rng)],
            cov_local: [[number(&mut rng), number(&mut rng)], [number(&mut rng), number(&mut rng)]],
            plane,
            state: Gaussian { x: Default::default(), p: Default::default() },
        };
        const SOURCES: [TrackSource; 3] = [TrackSource::Adsb, TrackSource::Mlat, TrackSource::Fused];
        const FEEDS: [Source; 2] = [Source::Adsb, Source::Mlat];
        let r = TrackReport {
            id: rng.gen(),
            addr: rng.gen(),
            source: SOURCES[rng.gen_range(0..3)],
            est,
            alt_baro_ft: maybe(&mut rng, |r| r.gen()),
            sources: (0..rng.gen_range(0..3)).map(|_| FEEDS[rng.gen_range(0..2)]).collect(),
            nac_p: maybe(&mut rng, |r| r.gen()),
            period_s: number(&mut rng),
            motion: [Motion::Unknown, Motion::Static, Motion::Moving][rng.gen_range(0..3)],
            adsb_suspect: rng.gen(),
            flight: maybe(&mut rng, |r| name(r).into()),
            squawk: maybe(&mut rng, |r| r.gen()),
            nav_altitude_ft: maybe(&mut rng, |r| r.gen()),
            sparse: rng.gen(),
            ages_s: [None, None],
        };
        let expected = reference::track(&r) + "\n";
        assert_eq!(line(&Event::Track(Box::new(r)), &names), expected);
    }
}

#[test]
fn hex_writes_what_the_standard_formatter_writes() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let edges = [0, 1, 0xF, 0x10, 0xFFF, 0xFFFF, 0x1_0000, 0xFF_FFFF, 0x100_0000, u32::MAX];
    for v in edges.into_iter().chain((0..20_000).map(|_| rng.gen::<u32>() >> rng.gen_range(0..32))) {
        let json = |h: Hex| serde_json::to_string(&h).unwrap();
        assert_eq!(json(Hex::addr(v)), format!("\"{v:06X}\""));
        assert_eq!(json(Hex::new(v, 4)), format!("\"{v:04X}\""));
    }
}

/// A receiver record: what is known, nothing absent written as null.
#[test]
fn a_receiver_record_has_what_is_known_and_nothing_else() {
    use crate::mlat::{Exclusion, ReceiverReport, RxState};
    let mut r = ReceiverReport {
        t: 1_700_000_060.5,
        rx: 1,
        state: RxState::Excluded,
        reason: Some(Exclusion::SyncFailing),
        sigma_ns: Some(75.44),
        offset_ns: Some(-47.52),
        outlier_rate: Some(0.08991),
        late_delay_ns: Some(412.4),
        position_offset_en_m: Some([120.04, -89.96]),
        position_offset_sigma_m: Some(12.0),
    };
    let names = ["a".to_string(), "n03".to_string()];
    let v: serde_json::Value =
        serde_json::from_str(&line(&Event::Receiver(Box::new(r.clone())), &names)).unwrap();
    assert_eq!(
        v,
        serde_json::json!({"type":"receiver","t":1_700_000_060.5,"id":"n03","state":"excluded",
            "reason":"sync_failing","sigma_ns":75.4,"offset_ns":-47.5,
            "outlier_rate":0.0899,"late_delay_ns":412.0,"position_offset_en_m":[120.0,-90.0],"position_offset_sigma_m":12.0})
    );
    r = ReceiverReport {
        state: RxState::Learning,
        reason: None,
        sigma_ns: None,
        offset_ns: None,
        outlier_rate: None,
        late_delay_ns: None,
        position_offset_en_m: None,
        position_offset_sigma_m: None,
        ..r
    };
    let text = line(&Event::Receiver(Box::new(r)), &names);
    assert_eq!(text.trim_end(), r#"{"type":"receiver","t":1700000060.5,"id":"n03","state":"learning"}"#);
}
