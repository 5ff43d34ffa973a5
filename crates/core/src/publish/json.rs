//! The track stream's JSON lines (contract): one object per event, `type` and
//! `t` always present, absent fields left out rather than null.
//!
//! Position, MLAT and track records are written by hand into the caller's
//! buffer. Through serde's derive every key and string went through
//! serde_json's escaping loop, byte by byte, and every field through its
//! generic machinery: a tenth of all the instructions of `run --capture`,
//! for records whose keys are our own constants. The bytes are still
//! serde_json's: numbers are formatted by the crates it uses (zmij for
//! floats, itoa for integers), non-finite floats are `null` as it writes
//! them, and a string that needs escaping is handed to it. The tests compare
//! every record with the derived serialisation this replaced. Alerts are rare
//! and stay `serde_json::json!`.

use serde::{Serialize, Serializer};

use crate::core::{Event, PositionReport};
use crate::fuse::{Alert, TrackReport};
use crate::mlat::{MlatFix, ReceiverReport};

/// A JSON object being written, its `type` first. Keys are field names of
/// this module: plain ASCII, never escaped. The methods are inlined into
/// the record writers so that a key is copied as bytes known at compile
/// time: as calls, each key and value was a call to `memcpy` for a few
/// bytes (a third of what writing by hand saved).
struct Obj<'o>(&'o mut Vec<u8>);

impl<'o> Obj<'o> {
    fn start(out: &'o mut Vec<u8>, kind: &str) -> Obj<'o> {
        out.extend_from_slice(b"{\"type\":");
        string(out, kind);
        Obj(out)
    }

    /// `,"key":`, ready for the value.
    #[inline(always)]
    fn key(&mut self, key: &str) -> &mut Vec<u8> {
        debug_assert!(key.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_'), "key {key}");
        self.0.extend_from_slice(b",\"");
        self.0.extend_from_slice(key.as_bytes());
        self.0.extend_from_slice(b"\":");
        self.0
    }

    #[inline(always)]
    fn f64(&mut self, key: &str, v: f64) {
        float(self.key(key), v);
    }

    #[inline(always)]
    fn int(&mut self, key: &str, v: impl itoa::Integer) {
        self.key(key).extend_from_slice(itoa::Buffer::new().format(v).as_bytes());
    }

    #[inline(always)]
    fn str(&mut self, key: &str, s: &str) {
        string(self.key(key), s);
    }

    #[inline(always)]
    fn hex(&mut self, key: &str, h: Hex) {
        let out = self.key(key);
        out.push(b'"');
        out.extend_from_slice(h.as_bytes());
        out.push(b'"');
    }

    #[inline(always)]
    fn bool(&mut self, key: &str, v: bool) {
        self.key(key).extend_from_slice(if v { b"true" } else { b"false" });
    }

    #[inline(always)]
    fn floats(&mut self, key: &str, vs: &[f64]) {
        array(self.key(key), vs.iter().copied(), float);
    }

    #[inline(always)]
    fn cov(&mut self, key: &str, m: [[f64; 2]; 2]) {
        array(self.key(key), m, |out, row| array(out, row, float));
    }

    #[inline(always)]
    fn strs<'s>(&mut self, key: &str, ss: impl IntoIterator<Item = &'s str>) {
        array(self.key(key), ss, string);
    }

    /// The address, time, position and heights (when known) of a position
    /// or track record, in their order and rounding.
    #[inline(always)]
    fn place(&mut self, addr: u32, t: f64, lat: f64, lon: f64, alt_m: Option<f64>, alt_baro_ft: Option<i32>) {
        self.hex("hex", Hex::addr(addr));
        self.f64("t", round(t, 1e6));
        self.f64("lat", round(lat, 1e8));
        self.f64("lon", round(lon, 1e8));
        if let Some(a) = alt_m {
            self.f64("alt_m", round(a, 100.0));
        }
        if let Some(a) = alt_baro_ft {
            self.int("alt_baro_ft", a);
        }
    }

    fn end(self) {
        self.0.push(b'}');
    }
}

/// A finite number as serde_json writes it, anything else as `null`.
#[inline(always)]
fn float(out: &mut Vec<u8>, v: f64) {
    if v.is_finite() {
        out.extend_from_slice(zmij::Buffer::new().format_finite(v).as_bytes());
    } else {
        out.extend_from_slice(b"null");
    }
}

#[inline(always)]
fn array<T>(out: &mut Vec<u8>, items: impl IntoIterator<Item = T>, mut each: impl FnMut(&mut Vec<u8>, T)) {
    out.push(b'[');
    for (i, item) in items.into_iter().enumerate() {
        if i > 0 {
            out.push(b',');
        }
        each(out, item);
    }
    out.push(b']');
}

/// A quoted string. What JSON must escape (controls, quote, backslash) is
/// rare in ours (receiver names come from the operator), so such a string
/// goes through serde_json, which escapes as it always has.
#[inline(always)]
fn string(out: &mut Vec<u8>, s: &str) {
    if s.bytes().any(|b| b < 0x20 || b == b'"' || b == b'\\') {
        // Into memory: cannot fail.
        let _ = serde_json::to_writer(&mut *out, s);
    } else {
        out.push(b'"');
        out.extend_from_slice(s.as_bytes());
        out.push(b'"');
    }
}

/// A number as upper-case hex digits, at least `width` of them (what
/// `format!("{:06X}")` writes), from the stack: a heap string per record and
/// per address was a tenth of writing it.
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

    fn as_bytes(&self) -> &[u8] {
        &self.digits[..self.len as usize]
    }
}

impl Serialize for Hex {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(std::str::from_utf8(self.as_bytes()).expect("hex digits are ASCII"))
    }
}

/// Writes one event as a JSON line into `out`; `receiver_id` names
/// receivers by index.
pub fn write_event<'a>(out: &mut Vec<u8>, ev: &Event, receiver_id: impl Fn(usize) -> &'a str) {
    match ev {
        Event::Position(p) => position(out, p, receiver_id(p.rx)),
        Event::Mlat(f) => mlat(out, f, receiver_id),
        Event::Track(r) => track(out, r),
        Event::Alert(a) => {
            // Into memory: cannot fail.
            let _ = serde_json::to_writer(&mut *out, &alert_record(a));
        }
        Event::Receiver(r) => receiver(out, r, receiver_id(r.rx)),
    }
    out.push(b'\n');
}

/// A receiver's multilateration state; what is not known yet is absent.
fn receiver(out: &mut Vec<u8>, r: &ReceiverReport, id: &str) {
    let mut o = Obj::start(out, "receiver");
    o.f64("t", round(r.t, 1e6));
    o.str("id", id);
    o.str("state", r.state.name());
    if let Some(why) = r.reason {
        o.str("reason", why.name());
    }
    let fields = [
        ("sigma_ns", r.sigma_ns, 10.0),
        ("offset_ns", r.offset_ns, 10.0),
        ("outlier_rate", r.outlier_rate, 1e4),
        ("late_delay_ns", r.late_delay_ns, 1.0),
    ];
    for (name, v, scale) in fields {
        if let Some(v) = v {
            o.f64(name, round(v, scale));
        }
    }
    if let Some([e, n]) = r.position_offset_en_m {
        o.floats("position_offset_en_m", &[round(e, 10.0), round(n, 10.0)]);
    }
    if let Some(s) = r.position_offset_sigma_m {
        o.f64("position_offset_sigma_m", round(s, 10.0));
    }
    o.end();
}

/// A decoded ADS-B position report, before any tracking.
fn position(out: &mut Vec<u8>, p: &PositionReport, receiver: &str) {
    let mut o = Obj::start(out, "position");
    o.str("source", "adsb");
    o.place(p.addr, p.t, p.lat, p.lon, p.alt_m, p.alt_baro_ft);
    if let Some(n) = p.nac_p {
        o.int("nac_p", n);
    }
    if let Some(s) = p.sigma_m {
        let v = round(s * s, 1e3);
        o.cov("cov_en", [[v, 0.0], [0.0, v]]);
    }
    o.bool("surface", p.surface);
    o.str("receiver", receiver);
    o.end();
}

fn mlat<'a>(out: &mut Vec<u8>, f: &MlatFix, receiver_id: impl Fn(usize) -> &'a str) {
    let mut o = Obj::start(out, "mlat");
    o.hex("hex", Hex::addr(f.addr));
    o.f64("t", round(f.t, 1e9));
    o.f64("lat", round(f.lat, 1e8));
    o.f64("lon", round(f.lon, 1e8));
    o.f64("alt_m", round(f.alt_m, 100.0));
    o.cov("cov_en", f.cov_en.map(|r| r.map(|v| round(v, 1e3))));
    o.strs("receivers", f.receivers.iter().map(|&r| receiver_id(r)));
    o.f64("gdop", round(f.gdop, 1e3));
    o.f64("chi2", round(f.chi2, 1e3));
    o.bool("altitude_used", f.altitude_used);
    o.end();
}

fn track(out: &mut Vec<u8>, r: &TrackReport) {
    let e = &r.est;
    let mut o = Obj::start(out, "track");
    o.int("id", r.id);
    o.place(r.addr, e.t, e.lat, e.lon, e.alt_m, r.alt_baro_ft);
    o.floats("vel_enu", &e.vel_enu.map(|v| round(v, 1e3)));
    o.cov("cov_en", e.cov_en().map(|row| row.map(|v| round(v, 1e3))));
    o.str("source", r.source.name());
    o.strs("sources", r.sources.iter().map(|s| s.name()));
    if let Some(n) = r.nac_p {
        o.int("nac_p", n);
    }
    o.f64("period_s", r.period_s);
    o.str("motion", r.motion.name());
    o.bool("adsb_suspect", r.adsb_suspect);
    if let Some(f) = r.flight.as_deref().filter(|f| !f.is_empty()) {
        o.str("flight", f);
    }
    if let Some(s) = r.squawk {
        o.hex("squawk", Hex::new(s.into(), 4));
    }
    if let Some(a) = r.nav_altitude_ft {
        o.int("nav_altitude_mcp", a);
    }
    if r.sparse {
        o.bool("sparse", true);
    }
    o.end();
}

/// `type: "alert"` records: `kind` says which.
pub fn alert_record(a: &Alert) -> serde_json::Value {
    let hex = Hex::addr;
    match *a {
        Alert::AdsbSuspect { t, addr, id, suspect, offset_m, nis } => {
            let mut r = serde_json::json!({
                "type": "alert", "kind": "adsb_suspect", "t": round(t, 1e6), "hex": hex(addr), "id": id,
                "suspect": suspect, "nis": round(nis, 100.0),
            });
            if let Some(o) = offset_m {
                r["offset_m"] = serde_json::json!(round(o, 10.0));
            }
            r
        }
        Alert::Conflict { t, pair, active, tau_s, t_cpa_s, miss_m, dz_m } => serde_json::json!({
            "type": "alert", "kind": "conflict", "t": round(t, 1e6),
            "pair": [hex(pair[0].0), hex(pair[1].0)], "ids": [pair[0].1, pair[1].1], "active": active,
            "tau_s": round(tau_s, 10.0), "t_cpa_s": round(t_cpa_s, 10.0), "miss_m": round(miss_m, 10.0),
            "dz_m": round(dz_m, 10.0),
        }),
    }
}

/// `v` rounded to a multiple of `1 / k`: what a published number can mean.
pub fn round(v: f64, k: f64) -> f64 {
    (v * k).round() / k
}

#[cfg(test)]
mod tests;
