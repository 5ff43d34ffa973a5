//! The simulated world's truth as `sim` writes it: each aircraft's path
//! (interpolated at any time), the receivers' true timing and position
//! errors, the spoofers and who broadcasts ADS-B.

use std::collections::{HashMap, HashSet};
use std::io::BufRead;

use anyhow::{Context, Result};
use serde_json::Value;

use super::{east_north, receivers};

#[derive(Clone, Copy, Debug)]
pub(super) struct TruthPoint {
    pub(super) t: f64,
    pub(super) lat: f64,
    pub(super) lon: f64,
    pub(super) alt: f64,
    /// East and north velocity (m/s), where the truth gives it.
    pub(super) vel: Option<[f64; 2]>,
}

#[derive(Default)]
pub struct Truth {
    pub(super) tracks: HashMap<String, Vec<TruthPoint>>,
    /// The receivers as simulated (their true timing and position errors).
    pub receivers: Vec<receivers::TrueReceiver>,
    pub spoofers: HashSet<String>,
    pub adsb: HashMap<String, bool>,
}

impl Truth {
    pub fn read(input: impl BufRead) -> Result<Truth> {
        let mut truth = Truth::default();
        for (i, line) in input.lines().enumerate() {
            let line = line?;
            if line.trim().is_empty() {
                continue;
            }
            let v: Value = serde_json::from_str(&line).with_context(|| format!("truth line {}", i + 1))?;
            let hex = v["hex"].as_str().unwrap_or_default().to_uppercase();
            match v["type"].as_str() {
                Some("truth") => {
                    let f = |k: &str| v[k].as_f64().with_context(|| format!("truth line {}: no {k}", i + 1));
                    truth.tracks.entry(hex).or_default().push(TruthPoint {
                        t: f("t")?,
                        lat: f("lat")?,
                        lon: f("lon")?,
                        alt: f("alt_m")?,
                        vel: east_north(&v["vel_enu"]),
                    });
                }
                Some("spoof") => {
                    truth.spoofers.insert(hex);
                }
                Some("equipage") => {
                    truth.adsb.insert(hex, v["adsb"].as_bool().unwrap_or(true));
                }
                Some("receiver") => truth.receivers.push(
                    serde_json::from_value(v).with_context(|| format!("truth line {}: receiver", i + 1))?,
                ),
                _ => {}
            }
        }
        for pts in truth.tracks.values_mut() {
            pts.sort_by(|a, b| a.t.total_cmp(&b.t));
        }
        Ok(truth)
    }

    pub(super) fn at(&self, hex: &str, t: f64) -> Option<TruthPoint> {
        let pts = self.tracks.get(hex)?;
        let i = pts.partition_point(|p| p.t <= t);
        if i == 0 || i == pts.len() {
            return pts.get(i.min(pts.len() - 1)).filter(|p| (p.t - t).abs() < 1e-6).copied();
        }
        let (a, b) = (pts[i - 1], pts[i]);
        let f = (t - a.t) / (b.t - a.t);
        Some(TruthPoint {
            t,
            lat: a.lat + (b.lat - a.lat) * f,
            lon: a.lon + (b.lon - a.lon) * f,
            alt: a.alt + (b.alt - a.alt) * f,
            vel: a.vel.zip(b.vel).map(|(u, w)| [u[0] + (w[0] - u[0]) * f, u[1] + (w[1] - u[1]) * f]),
        })
    }

    /// Interpolated truth (lat, lon, alt_m) of an aircraft at `t`.
    pub fn position(&self, hex: &str, t: f64) -> Option<(f64, f64, f64)> {
        self.at(hex, t).map(|p| (p.lat, p.lon, p.alt))
    }

    pub(super) fn span(&self, hex: &str) -> Option<(f64, f64)> {
        let pts = self.tracks.get(hex)?;
        Some((pts.first()?.t, pts.last()?.t))
    }
}

/// East/north offset (m) of (lat, lon) from a point.
pub(super) fn en_offset(from: &TruthPoint, lat: f64, lon: f64) -> [f64; 2] {
    let p = from.lat.to_radians();
    let (m, n) = fuse1090_core::geo::radii(p);
    let dlon = ((lon - from.lon + 540.0).rem_euclid(360.0)) - 180.0;
    [dlon.to_radians() * (n + from.alt) * p.cos(), (lat - from.lat).to_radians() * (m + from.alt)]
}
