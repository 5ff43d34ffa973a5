//! The `decode` command's JSON line for one frame (contract: field names and
//! units as readsb's aircraft.json; a field the frame does not carry is absent).

use serde::Serialize;

pub use super::commb::CommbFields;
use super::commb::{Inference, Register};
use super::fields::{callsign_str, squawk_string};
use super::{Body, Decoded, Es, Parity};
use crate::feed::RawFrame;

#[derive(Serialize, Default, Debug)]
pub struct DecodeRecord {
    pub df: u8,
    pub hex: String,
    pub crc_ok: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tc: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub alt_baro: Option<i32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub alt_geom: Option<i32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flight: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub category: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub squawk: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gs: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub track: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ias: Option<u16>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tas: Option<u16>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mag_heading: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub true_heading: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub baro_rate: Option<i32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub geom_rate: Option<i32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nac_p: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nac_v: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nic: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sil: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub version: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cpr: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface: Option<bool>,
    /// Comm-B: the register, or "ambiguous" with the candidates.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bds: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bds_candidates: Option<Vec<&'static str>>,
    #[serde(flatten)]
    pub commb: CommbFields,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lat: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lon: Option<f64>,
    pub frame: String,
    pub ts: u64,
    pub signal: u8,
}

pub(crate) fn round(v: f64, decimals: i32) -> f64 {
    let k = 10f64.powi(decimals);
    (v * k).round() / k
}

impl DecodeRecord {
    // Over 80 lines: one field of the decoded record after another.
    pub fn new(d: &Decoded, frame: &RawFrame) -> Self {
        let m = &d.msg;
        let mut r = DecodeRecord {
            df: m.df,
            hex: format!("{:06X}", m.addr & 0xFF_FFFF),
            crc_ok: d.trusted(),
            frame: frame.hex(),
            ts: frame.timestamp,
            signal: frame.signal,
            ..Default::default()
        };
        if m.parity == Parity::Bad {
            return r;
        }
        match m.body {
            Body::AirAir { alt_ft, .. } => r.alt_baro = alt_ft,
            Body::Altitude { alt_ft, .. } => r.alt_baro = alt_ft,
            Body::Identity { squawk, .. } => r.squawk = Some(squawk_string(squawk)),
            Body::Extended(es) => {
                r.tc = Some(es.tc);
                match es.kind {
                    Es::Identification { category, callsign } => {
                        r.flight = Some(callsign_str(&callsign).to_string());
                        r.category = Some(format!("{category:02X}"));
                    }
                    Es::AirbornePosition { alt_ft, gnss, cpr, .. } => {
                        if gnss {
                            r.alt_geom = alt_ft;
                        } else {
                            r.alt_baro = alt_ft;
                        }
                        r.cpr = Some(if cpr.odd { "odd" } else { "even" });
                        r.surface = Some(false);
                    }
                    Es::SurfacePosition { movement_kt, track_deg, cpr } => {
                        r.gs = movement_kt.map(|v| round(v, 3));
                        r.track = track_deg.map(|v| round(v, 2));
                        r.cpr = Some(if cpr.odd { "odd" } else { "even" });
                        r.surface = Some(true);
                    }
                    Es::Velocity(v) => {
                        r.gs = v.gs_kt().map(|v| round(v, 1));
                        r.track = v.track_deg().map(|v| round(v, 2));
                        if let Some(speed) = v.airspeed_kt {
                            if v.airspeed_is_tas {
                                r.tas = Some(speed);
                            } else {
                                r.ias = Some(speed);
                            }
                        }
                        if d.heading_true {
                            r.true_heading = v.heading_deg.map(|h| round(h, 2));
                        } else {
                            r.mag_heading = v.heading_deg.map(|h| round(h, 2));
                        }
                        if v.vrate_baro {
                            r.baro_rate = v.vrate_fpm;
                        } else {
                            r.geom_rate = v.vrate_fpm;
                        }
                        r.nac_v = Some(v.nac_v);
                    }
                    Es::Emergency { squawk, .. } => r.squawk = Some(squawk_string(squawk)),
                    Es::TargetState(ts) => {
                        r.nac_p = Some(ts.nac_p);
                        r.sil = Some(ts.sil);
                    }
                    Es::OperationalStatus(os) => {
                        r.version = Some(os.version);
                        if os.version > 0 {
                            r.nac_p = Some(os.nac_p);
                            r.sil = Some(os.sil);
                        }
                    }
                    Es::Other => {}
                }
                r.nic = d.nic;
                if let Some(p) = d.position.filter(|p| p.reliable) {
                    r.lat = Some(p.lat);
                    r.lon = Some(p.lon);
                }
            }
            Body::AllCall { .. } | Body::Undecoded => {}
        }
        match d.commb {
            Some(Inference::Identified(reg)) => {
                r.bds = Some(reg.bds().as_str());
                match reg {
                    Register::Identification(cs) => r.flight = Some(callsign_str(&cs).to_string()),
                    Register::TrackTurn(t) => {
                        r.track = t.track_deg.map(|v| round(v, 2));
                        r.gs = t.gs_kt.map(f64::from);
                        r.tas = t.tas_kt.map(|v| v as u16);
                    }
                    Register::HeadingSpeed(h) => {
                        r.mag_heading = h.mag_heading_deg.map(|v| round(v, 2));
                        r.ias = h.ias_kt.map(|v| v as u16);
                        r.baro_rate = h.baro_rate_fpm;
                        r.geom_rate = h.inertial_rate_fpm;
                    }
                    _ => {}
                }
                r.commb = CommbFields::new(&reg);
            }
            Some(Inference::Ambiguous(c)) => {
                r.bds = Some("ambiguous");
                r.bds_candidates = Some(c.iter().map(|b| b.as_str()).collect());
            }
            Some(Inference::Contradicted(_) | Inference::NoRegister) | None => {}
        }
        r
    }
}
