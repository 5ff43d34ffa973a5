//! The track stream's JSON lines (contract): one object per event, `type` and
//! `t` always present, absent fields left out rather than null.

use serde::Serialize;

use crate::core::{Event, PositionReport};

#[derive(Serialize)]
struct PositionRecord<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    source: &'static str,
    hex: String,
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

/// Writes one event as a JSON line; `receiver_id` names receivers by index.
pub fn write_event<'a>(
    out: &mut impl std::io::Write,
    ev: &Event,
    receiver_id: impl Fn(usize) -> &'a str,
) -> std::io::Result<()> {
    match ev {
        Event::Position(p) => {
            serde_json::to_writer(&mut *out, &position_record(p, receiver_id(p.rx)))?;
        }
    }
    out.write_all(b"\n")
}

fn position_record<'a>(p: &PositionReport, receiver: &'a str) -> PositionRecord<'a> {
    let round = |v: f64, k: f64| (v * k).round() / k;
    PositionRecord {
        // A decoded ADS-B position report, before any tracking.
        kind: "position",
        source: "adsb",
        hex: format!("{:06X}", p.addr),
        t: round(p.t, 1e6),
        lat: round(p.lat, 1e8),
        lon: round(p.lon, 1e8),
        alt_m: p.alt_m.map(|a| round(a, 100.0)),
        alt_baro_ft: p.alt_baro_ft,
        nac_p: p.nac_p,
        cov_en: p.sigma_m.map(|s| [[s * s, 0.0], [0.0, s * s]]),
        surface: p.surface,
        receiver,
    }
}
