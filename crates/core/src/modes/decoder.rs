//! The stateful decoder: what a receiver-side decoder must remember.
//!
//! Policy follows the careful decoders (readsb, dump1090-fa):
//! - an aircraft exists only once a frame with verifiable parity (DF11, DF17,
//!   DF18) names it; address/parity replies and corrected frames never create one;
//! - single-bit correction only for DF17/18, and only when the repaired address
//!   is already known;
//! - CPR: global decode from an even/odd pair inside a time window, else local
//!   decode against the aircraft's own reliable position or the receiver;
//!   every decoded position passes a range and a speed check, and a position is
//!   published only once a second independent decode has confirmed it (the
//!   reliability count), so a one-off decode is never presented as fact.
//! - Comm-B replies: the register is inferred (`commb`) with what is known of
//!   the aircraft (its latest altitude and velocity), kept only for aircraft
//!   established by verified frames.
//!
//! Its tests are in `decoder_tests.rs`.

use crate::FastMap;

use super::commb::{self, CommbStats, Inference};
use super::cpr::{self, CprFields};
use super::crc::SingleBitTable;
use super::message::{self, extended_body, Body, Es, FrameError, Message, Parity};
use super::nic;
use crate::feed::RawFrame;
use crate::geo::{distance_m, KT_TO_MS};

#[derive(Clone, Debug)]
pub struct DecoderConfig {
    /// Receiver position (deg): reference for surface and local decoding, and the range check.
    pub reference: Option<(f64, f64)>,
    /// Positions farther than this from the reference are rejected.
    pub max_range_m: f64,
    /// Independent decodes needed before a position is published.
    pub min_reliable: u8,
    /// Aircraft not heard for this long are forgotten.
    pub aircraft_ttl_s: f64,
}

impl Default for DecoderConfig {
    fn default() -> Self {
        DecoderConfig { reference: None, max_range_m: 600_000.0, min_reliable: 2, aircraft_ttl_s: 300.0 }
    }
}

/// How a position was resolved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CprMethod {
    Global,
    /// Local decode against the aircraft's own reliable position.
    LocalAircraft,
    /// Local decode against the receiver position.
    LocalReceiver,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionFix {
    pub lat: f64,
    pub lon: f64,
    pub surface: bool,
    pub method: CprMethod,
    /// Confirmed by enough independent decodes to be published.
    pub reliable: bool,
}

/// One frame after the stateful decoder.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decoded {
    pub msg: Message,
    /// The address belongs to an aircraft established by verified frames.
    pub known: bool,
    pub position: Option<PositionFix>,
    /// NIC of a position message (with the aircraft's supplements).
    pub nic: Option<u8>,
    /// NUCp of a position message, for version 0 transponders.
    pub nuc_p: Option<u8>,
    /// ADS-B version known for the aircraft (from its operational status).
    pub version: Option<u8>,
    /// Heading in velocity subtypes 3/4 is true, not magnetic (HRD).
    pub heading_true: bool,
    /// The aircraft's latest NACp (operational status or target state).
    pub nac_p: Option<u8>,
    /// The aircraft's latest GNSS-minus-baro altitude difference (ft).
    pub gnss_baro_diff_ft: Option<i32>,
    /// A DF20/21 reply's Comm-B register, inferred with what is known of the aircraft.
    pub commb: Option<Inference>,
    /// What is known of the aircraft beside a Comm-B reply (for Comm-B replies).
    pub commb_context: commb::ReplyContext,
}

impl Decoded {
    /// Parity verified or, for address/parity replies, address known.
    pub fn trusted(&self) -> bool {
        match self.msg.parity {
            Parity::Ok | Parity::Corrected(_) => true,
            Parity::AddressParity => self.known,
            Parity::Bad => false,
        }
    }
}

/// Everything the decoder counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DecodeStats {
    pub mode_s: u64,
    pub mode_ac: u64,
    pub wrong_length: u64,
    pub by_df: [u64; 25],
    pub parity_ok: u64,
    pub corrected: u64,
    pub parity_bad: u64,
    /// Correctable, but the repaired address was not a known aircraft.
    pub corrected_unknown: u64,
    pub address_parity_known: u64,
    pub address_parity_unknown: u64,
    pub aircraft_created: u64,
    pub aircraft_expired: u64,
    pub cpr_global: u64,
    pub cpr_local_aircraft: u64,
    pub cpr_local_receiver: u64,
    pub cpr_zone_mismatch: u64,
    pub cpr_no_reference: u64,
    pub cpr_unresolved: u64,
    pub cpr_range_reject: u64,
    pub cpr_speed_reject: u64,
    pub positions_reliable: u64,
    pub positions_unconfirmed: u64,
    pub commb: CommbStats,
}

#[derive(Clone, Copy, Debug)]
struct CprRecord {
    cpr: CprFields,
    t: f64,
    surface: bool,
}

#[derive(Clone, Copy, Debug)]
struct PosRecord {
    lat: f64,
    lon: f64,
    t: f64,
    surface: bool,
}

#[derive(Clone, Debug, Default)]
struct Aircraft {
    last_seen: f64,
    version: Option<u8>,
    nic_a: u8,
    nic_c: u8,
    hrd: u8,
    gs_kt: Option<f64>,
    nac_p: Option<u8>,
    gnss_baro_diff_ft: Option<i32>,
    even: Option<CprRecord>,
    odd: Option<CprRecord>,
    pos: Option<PosRecord>,
    reliable: u8,
    commb: commb::Memory,
}

const MAX_RELIABLE: u8 = 4;
/// Local decoding against the aircraft's own position is safe while it cannot
/// have moved half a zone; two minutes is far inside that at any speed.
const LOCAL_MAX_AGE_S: f64 = 120.0;
/// Slack for timestamp jitter and reordering in the speed check.
const SPEED_CHECK_SLACK_M: f64 = 1000.0;
const PURGE_EVERY_S: f64 = 60.0;

pub struct Decoder {
    cfg: DecoderConfig,
    aircraft: FastMap<u32, Aircraft>,
    single_bit: SingleBitTable,
    stats: DecodeStats,
    newest_t: f64,
    last_purge: f64,
}

/// Table key: non-ICAO (DF18 anonymous) addresses live apart from ICAO ones.
fn key(addr: u32, non_icao: bool) -> u32 {
    addr | if non_icao { 1 << 24 } else { 0 }
}

impl Decoder {
    pub fn new(cfg: DecoderConfig) -> Self {
        Decoder {
            cfg,
            aircraft: FastMap::default(),
            single_bit: SingleBitTable::new(),
            stats: DecodeStats::default(),
            newest_t: f64::NEG_INFINITY,
            last_purge: f64::NEG_INFINITY,
        }
    }

    pub fn stats(&self) -> &DecodeStats {
        &self.stats
    }

    pub fn aircraft_count(&self) -> usize {
        self.aircraft.len()
    }

    /// Whether an ICAO address is a known aircraft.
    pub fn is_known(&self, addr: u32) -> bool {
        self.aircraft.contains_key(&addr)
    }

    /// Decodes a frame received at time `t` (seconds, any epoch, but one
    /// clock per decoder), with the configured receiver reference.
    pub fn decode(&mut self, frame: &RawFrame, t: f64) -> Result<Decoded, FrameError> {
        self.decode_at(frame, t, self.cfg.reference)
    }

    /// As [`Self::decode`], for a frame heard by a receiver at `reference`
    /// (several receivers share one decoder in the processing core).
    // Over 80 lines, kept whole: the decoder's per-frame pass, whose steps
    // share the parsed frame and the aircraft's entry, looked up once.
    pub fn decode_at(
        &mut self,
        frame: &RawFrame,
        t: f64,
        reference: Option<(f64, f64)>,
    ) -> Result<Decoded, FrameError> {
        if frame.is_mode_ac() {
            self.stats.mode_ac += 1;
            return Err(FrameError::NotModeS);
        }
        let mut msg = match message::decode(frame.bytes()) {
            Ok(m) => m,
            Err(e) => {
                self.stats.wrong_length += 1;
                return Err(e);
            }
        };
        self.stats.mode_s += 1;
        self.stats.by_df[msg.df as usize] += 1;
        self.advance(t);

        if msg.parity == Parity::Bad && matches!(msg.df, 17 | 18) {
            self.try_correct(frame.bytes(), &mut msg);
        }
        let non_icao = matches!(msg.body, Body::Extended(e) if e.non_icao);
        let k = key(msg.addr, non_icao);
        let known = match msg.parity {
            Parity::Ok => {
                self.stats.parity_ok += 1;
                if !self.aircraft.contains_key(&k) {
                    self.stats.aircraft_created += 1;
                }
                self.aircraft.entry(k).or_default();
                true
            }
            Parity::Corrected(_) => true,
            Parity::Bad => {
                self.stats.parity_bad += 1;
                false
            }
            Parity::AddressParity => {
                let known = self.aircraft.contains_key(&k);
                if known {
                    self.stats.address_parity_known += 1;
                } else {
                    self.stats.address_parity_unknown += 1;
                }
                known
            }
        };
        let mut out = Decoded {
            msg,
            known,
            position: None,
            nic: None,
            nuc_p: None,
            version: None,
            heading_true: false,
            nac_p: None,
            gnss_baro_diff_ft: None,
            commb: None,
            commb_context: Default::default(),
        };
        let (own_alt_ft, mb) = match msg.body {
            Body::Altitude { alt_ft, mb, .. } => (alt_ft, mb),
            Body::Identity { mb, .. } => (None, mb),
            _ => (None, None),
        };
        if !known {
            if let Some(mb) = mb {
                // Of an aircraft not known, only the reply's own altitude is.
                let inference = commb::infer(mb, &commb::Memory::default().known(t, own_alt_ft));
                self.stats.commb.count(&inference);
                out.commb = Some(inference);
            }
            return Ok(out);
        }
        let min_reliable = self.cfg.min_reliable;
        let max_range = self.cfg.max_range_m;
        let ac = self.aircraft.get_mut(&k).expect("known aircraft");
        ac.last_seen = t;
        if let Body::AirAir { alt_ft: Some(alt), .. } | Body::Altitude { alt_ft: Some(alt), .. } = msg.body {
            ac.commb.note_altitude(alt, t);
        }
        if let Some(mb) = mb {
            let inference = commb::infer(mb, &ac.commb.known(t, own_alt_ft));
            ac.commb.note(&inference, t);
            self.stats.commb.count(&inference);
            out.commb = Some(inference);
            out.commb_context = ac.commb.context(t, own_alt_ft);
            return Ok(out);
        }
        if let Body::Extended(es) = msg.body {
            match es.kind {
                Es::OperationalStatus(os) => {
                    ac.version = Some(os.version);
                    ac.nic_a = os.nic_a;
                    if os.subtype == 1 {
                        ac.nic_c = os.nic_c;
                    }
                    ac.hrd = os.hrd;
                    if os.version > 0 {
                        ac.nac_p = Some(os.nac_p);
                    }
                }
                Es::TargetState(ts) => ac.nac_p = Some(ts.nac_p),
                Es::Velocity(v) => {
                    if let Some(gs) = v.gs_kt() {
                        ac.gs_kt = Some(gs);
                    }
                    if let (Some(gs), Some(track)) = (v.gs_kt(), v.track_deg()) {
                        ac.commb.note_adsb_velocity(track, gs, t);
                    }
                    if v.gnss_baro_diff_ft.is_some() {
                        ac.gnss_baro_diff_ft = v.gnss_baro_diff_ft;
                    }
                }
                Es::AirbornePosition { cpr, nic_b, alt_ft, gnss, .. } => {
                    if let (Some(alt), false) = (alt_ft, gnss) {
                        ac.commb.note_altitude(alt, t);
                    }
                    out.position =
                        resolve(ac, &mut self.stats, cpr, false, t, reference, max_range, min_reliable);
                    out.nic = nic::nic(es.tc, ac.version.unwrap_or(0), ac.nic_a, nic_b, 0);
                    out.nuc_p = nic::nuc_p(es.tc);
                }
                Es::SurfacePosition { cpr, movement_kt, .. } => {
                    if let Some(gs) = movement_kt {
                        ac.gs_kt = Some(gs);
                    }
                    out.position =
                        resolve(ac, &mut self.stats, cpr, true, t, reference, max_range, min_reliable);
                    out.nic = nic::nic(es.tc, ac.version.unwrap_or(0), ac.nic_a, 0, ac.nic_c);
                    out.nuc_p = nic::nuc_p(es.tc);
                }
                _ => {}
            }
            out.version = ac.version;
            out.nac_p = ac.nac_p;
            out.gnss_baro_diff_ft = ac.gnss_baro_diff_ft;
            out.heading_true = ac.version.unwrap_or(0) >= 1 && ac.hrd == 0;
        }
        if let Some(p) = out.position {
            if p.reliable {
                self.stats.positions_reliable += 1;
            } else {
                self.stats.positions_unconfirmed += 1;
            }
        }
        Ok(out)
    }

    fn try_correct(&mut self, bytes: &[u8], msg: &mut Message) {
        if bytes.len() != 14 {
            return;
        }
        let Some(bit) = self.single_bit.lookup(msg.syndrome) else {
            return;
        };
        let mut fixed = [0u8; 14];
        fixed.copy_from_slice(bytes);
        fixed[(bit / 8) as usize] ^= 0x80 >> (bit % 8);
        let addr = ((fixed[1] as u32) << 16) | ((fixed[2] as u32) << 8) | fixed[3] as u32;
        let body = extended_body(&fixed);
        let non_icao = matches!(body, Body::Extended(e) if e.non_icao);
        if self.aircraft.contains_key(&key(addr, non_icao)) {
            self.stats.corrected += 1;
            *msg = Message { df: msg.df, addr, parity: Parity::Corrected(bit), syndrome: msg.syndrome, body };
        } else {
            self.stats.corrected_unknown += 1;
        }
    }

    /// Time moved on to `t` (s, the frames' time scale): aircraft not heard
    /// for the time to live are forgotten, checked once a minute. A frame
    /// moves it too; told the time, an idle decoder forgets as well.
    pub fn advance(&mut self, t: f64) {
        if t.is_finite() && t > self.newest_t {
            self.newest_t = t;
        }
        self.maybe_purge();
    }

    fn maybe_purge(&mut self) {
        let now = self.newest_t;
        if now - self.last_purge < PURGE_EVERY_S {
            return;
        }
        self.last_purge = now;
        let ttl = self.cfg.aircraft_ttl_s;
        let before = self.aircraft.len();
        self.aircraft.retain(|_, a| (now - a.last_seen).abs() <= ttl);
        self.stats.aircraft_expired += (before - self.aircraft.len()) as u64;
    }
}

/// Longest gap between the frames of a pair: about 10 s in the air (longer when
/// slow, so the pair spans a similar distance), 25-50 s on the surface.
fn pair_window_s(surface: bool, gs_kt: Option<f64>) -> f64 {
    match (surface, gs_kt) {
        (true, Some(gs)) if gs < 25.0 => 50.0,
        (true, _) => 25.0,
        (false, Some(gs)) => (1.5 / gs.max(1.0) * 3600.0).clamp(10.0, 30.0),
        (false, None) => 10.0,
    }
}

/// Fastest plausible ground speed (kt) for the speed check.
fn max_speed_kt(surface: bool, gs_kt: Option<f64>) -> f64 {
    match (surface, gs_kt) {
        (true, Some(gs)) => gs * 1.5 + 50.0,
        (true, None) => 200.0,
        (false, Some(gs)) => gs * 1.25 + 100.0,
        (false, None) => 1200.0,
    }
}

#[allow(clippy::too_many_arguments)]
// Over 80 lines, kept whole: one decision (which CPR pair, which
// reference, which check) whose branches read the same candidates.
fn resolve(
    ac: &mut Aircraft,
    stats: &mut DecodeStats,
    cpr: CprFields,
    surface: bool,
    t: f64,
    reference: Option<(f64, f64)>,
    max_range_m: f64,
    min_reliable: u8,
) -> Option<PositionFix> {
    let rec = CprRecord { cpr, t, surface };
    let other = if cpr.odd { ac.even } else { ac.odd };
    if cpr.odd {
        ac.odd = Some(rec);
    } else {
        ac.even = Some(rec);
    }
    let own_ref = ac.pos.filter(|p| p.surface == surface);
    let window = pair_window_s(surface, ac.gs_kt);

    let mut found = None;
    if let Some(o) = other.filter(|o| o.surface == surface && (t - o.t).abs() <= window) {
        let (even, odd) = if cpr.odd { (o.cpr, cpr) } else { (cpr, o.cpr) };
        let g = if surface {
            match own_ref.map(|p| (p.lat, p.lon)).or(reference) {
                Some((rlat, rlon)) => cpr::global_surface(even, odd, cpr.odd, rlat, rlon),
                None => {
                    stats.cpr_no_reference += 1;
                    None
                }
            }
        } else {
            let g = cpr::global_airborne(even, odd, cpr.odd);
            if g.is_none() {
                stats.cpr_zone_mismatch += 1;
            }
            g
        };
        found = g.map(|p| (p, CprMethod::Global));
    }
    if found.is_none() {
        if let Some(p) = own_ref.filter(|p| ac.reliable >= min_reliable && (t - p.t).abs() <= LOCAL_MAX_AGE_S)
        {
            found = Some((cpr::local(cpr, surface, p.lat, p.lon), CprMethod::LocalAircraft));
        } else if let Some((rlat, rlon)) = reference {
            found = Some((cpr::local(cpr, surface, rlat, rlon), CprMethod::LocalReceiver));
        }
    }
    let Some(((lat, lon), method)) = found else {
        stats.cpr_unresolved += 1;
        return None;
    };
    if let Some((rlat, rlon)) = reference {
        // Local decoding against the receiver is only unambiguous inside half a zone.
        let limit = if method == CprMethod::LocalReceiver {
            max_range_m.min(if surface { 45.0 * 1852.0 } else { 180.0 * 1852.0 })
        } else {
            max_range_m
        };
        if distance_m(lat, lon, rlat, rlon) > limit {
            stats.cpr_range_reject += 1;
            return None;
        }
    }
    match method {
        CprMethod::Global => stats.cpr_global += 1,
        CprMethod::LocalAircraft => stats.cpr_local_aircraft += 1,
        CprMethod::LocalReceiver => stats.cpr_local_receiver += 1,
    }
    let new = PosRecord { lat, lon, t, surface };
    // Only a global decode is independent evidence: a local decode always lands
    // near its reference, so an aircraft beyond half a zone from the receiver
    // aliases into a plausible spot. Local decodes extend a confirmed track or
    // seed a candidate, never confirm one.
    let independent = method == CprMethod::Global;
    if let Some(prev) = ac.pos {
        let dt = (t - prev.t).abs();
        let allowed = SPEED_CHECK_SLACK_M + max_speed_kt(surface, ac.gs_kt) * KT_TO_MS * dt;
        if prev.surface == surface && distance_m(lat, lon, prev.lat, prev.lon) > allowed {
            stats.cpr_speed_reject += 1;
            ac.reliable = ac.reliable.saturating_sub(1);
            if ac.reliable > 0 || !independent {
                return None;
            }
            // The old position has lost all credit: start again from this one.
            ac.pos = Some(new);
            ac.reliable = 1;
            return Some(PositionFix { lat, lon, surface, method, reliable: 1 >= min_reliable });
        }
    }
    if independent {
        ac.reliable = (ac.reliable + 1).min(MAX_RELIABLE);
    }
    ac.pos = Some(new);
    Some(PositionFix { lat, lon, surface, method, reliable: ac.reliable >= min_reliable })
}

#[cfg(test)]
#[path = "decoder_tests.rs"]
mod tests;
