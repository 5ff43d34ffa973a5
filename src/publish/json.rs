//! The track stream's JSON lines (contract): one object per event, `type` and
//! `t` always present, absent fields left out rather than null.

use serde::{Serialize, Serializer};

use crate::core::{Event, PositionReport};
use crate::fuse::{Alert, TrackReport};
use crate::mlat::MlatFix;

#[derive(Serialize)]
#[serde(bound = "")]
struct MlatRecord<'r, 'a, F: Fn(usize) -> &'a str> {
    #[serde(rename = "type")]
    kind: &'static str,
    hex: Hex,
    t: f64,
    lat: f64,
    lon: f64,
    alt_m: f64,
    cov_en: [[f64; 2]; 2],
    receivers: Names<'r, 'a, F>,
    gdop: f64,
    chi2: f64,
    altitude_used: bool,
}

/// Receivers by index, serialised as their ids without collecting them:
/// a vector of names per MLAT record was an allocation per fix.
struct Names<'r, 'a, F: Fn(usize) -> &'a str>(&'r [usize], &'r F);

impl<'a, F: Fn(usize) -> &'a str> Serialize for Names<'_, 'a, F> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.0.iter().map(|&r| (self.1)(r)))
    }
}

#[derive(Serialize)]
struct PositionRecord<'a> {
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

/// A number as upper-case hex digits, at least `width` of them (what
/// `format!("{:06X}")` writes), serialised as a string from the stack: a
/// heap string per record and per address was a tenth of writing it.
#[derive(Clone, Copy)]
struct Hex {
    digits: [u8; 8],
    len: u8,
}

impl Hex {
    fn new(v: u32, width: usize) -> Hex {
        let len = width.max((32 - v.leading_zeros() as usize).div_ceil(4)).min(8);
        let mut digits = [0u8; 8];
        for (i, d) in digits[..len].iter_mut().enumerate() {
            *d = b"0123456789ABCDEF"[((v >> (4 * (len - 1 - i))) & 0xF) as usize];
        }
        Hex { digits, len: len as u8 }
    }

    fn addr(addr: u32) -> Hex {
        Hex::new(addr, 6)
    }
}

impl Serialize for Hex {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(std::str::from_utf8(&self.digits[..self.len as usize]).expect("hex digits are ASCII"))
    }
}

#[derive(Serialize)]
pub struct TrackRecord<'a> {
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
    sources: &'a [&'static str],
    #[serde(skip_serializing_if = "Option::is_none")]
    nac_p: Option<u8>,
    period_s: f64,
    motion: &'static str,
    adsb_suspect: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    flight: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    squawk: Option<Hex>,
}

pub fn track_record(r: &TrackReport) -> TrackRecord<'_> {
    let e = &r.est;
    TrackRecord {
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
        source: r.source,
        sources: &r.sources,
        nac_p: r.nac_p,
        period_s: r.period_s,
        motion: r.motion.name(),
        adsb_suspect: r.adsb_suspect,
        flight: r.flight.as_deref().filter(|f| !f.is_empty()),
        squawk: r.squawk.map(|s| Hex::new(s.into(), 4)),
    }
}

/// `type: "alert"` records: `kind` says which.
pub fn alert_record(a: &Alert) -> serde_json::Value {
    let hex = Hex::addr;
    match *a {
        Alert::AdsbSuspect { t, addr, id, suspect, offset_m, nis } => serde_json::json!({
            "type": "alert", "kind": "adsb_suspect", "t": round(t, 1e6), "hex": hex(addr), "id": id,
            "suspect": suspect, "offset_m": round(offset_m, 10.0), "nis": round(nis, 100.0),
        }),
        Alert::Conflict { t, pair, active, tau_s, t_cpa_s, miss_m, dz_m } => serde_json::json!({
            "type": "alert", "kind": "conflict", "t": round(t, 1e6),
            "pair": [hex(pair[0].0), hex(pair[1].0)], "ids": [pair[0].1, pair[1].1], "active": active,
            "tau_s": round(tau_s, 10.0), "t_cpa_s": round(t_cpa_s, 10.0), "miss_m": round(miss_m, 10.0),
            "dz_m": round(dz_m, 10.0),
        }),
    }
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
        Event::Mlat(f) => {
            serde_json::to_writer(&mut *out, &mlat_record(f, &receiver_id))?;
        }
        Event::Track(r) => {
            serde_json::to_writer(&mut *out, &track_record(r))?;
        }
        Event::Alert(a) => {
            serde_json::to_writer(&mut *out, &alert_record(a))?;
        }
    }
    out.write_all(b"\n")
}

fn position_record<'a>(p: &PositionReport, receiver: &'a str) -> PositionRecord<'a> {
    PositionRecord {
        // A decoded ADS-B position report, before any tracking.
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
    }
}

fn round(v: f64, k: f64) -> f64 {
    (v * k).round() / k
}

fn mlat_record<'r, 'a, F: Fn(usize) -> &'a str>(f: &'r MlatFix, receiver_id: &'r F) -> MlatRecord<'r, 'a, F> {
    MlatRecord {
        kind: "mlat",
        hex: Hex::addr(f.addr),
        t: round(f.t, 1e9),
        lat: round(f.lat, 1e8),
        lon: round(f.lon, 1e8),
        alt_m: round(f.alt_m, 100.0),
        cov_en: f.cov_en.map(|r| r.map(|v| round(v, 1e3))),
        receivers: Names(&f.receivers, receiver_id),
        gdop: round(f.gdop, 1e3),
        chi2: round(f.chi2, 1e3),
        altitude_used: f.altitude_used,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_writes_what_the_standard_formatter_writes() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let edges = [0, 1, 0xF, 0x10, 0xFFF, 0xFFFF, 0x1_0000, 0xFF_FFFF, 0x100_0000, u32::MAX];
        for v in edges.into_iter().chain((0..20_000).map(|_| rng.gen::<u32>() >> rng.gen_range(0..32))) {
            let json = |h: Hex| serde_json::to_string(&h).unwrap();
            assert_eq!(json(Hex::addr(v)), format!("\"{v:06X}\""));
            assert_eq!(json(Hex::new(v, 4)), format!("\"{v:04X}\""));
        }
    }
}
