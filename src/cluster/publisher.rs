//! The publisher role: every partition's events out, and the stage that
//! needs all of them: conflict prediction across partitions.
//!
//! Events arrive per partition in order, partitions interleaved. Conflicts
//! are assessed at the time every partition has reached (its batches carry
//! it), on the newest published fused track of each aircraft moved to that
//! time, with the same monitor a single node runs ([`ConflictMonitor`]).
//! A partition's batch at or below the time it had reached is a replay
//! after a takeover (beyond JetStream's duplicate window): dropped, counted.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use async_nats::jetstream::consumer::{pull, AckPolicy, DeliverPolicy};
use futures_util::StreamExt;

use super::{header, ClusterConfig, Mark, Nats, Watermarks};
use crate::core::{CoreConfig, Event};
use crate::fuse::conflict::{kinematics_at, Seen};
use crate::fuse::{ConflictConfig, ConflictMonitor, Output, MIN_CONFLICT_SPEED_MPS};
use crate::publish::json::write_event;
use crate::FastMap;

/// The newest published fused track of an aircraft, as conflict prediction reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackView {
    pub id: u64,
    pub t: f64,
    pub lat: f64,
    pub lon: f64,
    pub alt_m: f64,
    pub vel_enu: [f64; 3],
    pub alt_baro_ft: Option<f64>,
    pub period_s: f64,
}

impl TrackView {
    /// A fused track record's view (`None` for anything else, or a track without height or velocity).
    pub fn parse(line: &[u8]) -> Option<(u32, TrackView)> {
        // Most lines are not fused tracks: told apart without parsing them
        // (the track stream writes these fields exactly so, docs/formats.md).
        let has = |s: &[u8]| memchr::memmem::find(line, s).is_some();
        if !has(b"\"type\":\"track\"") || !has(b"\"source\":\"fused\"") {
            return None;
        }
        let v: serde_json::Value = serde_json::from_slice(line).ok()?;
        if v["type"] != "track" || v["source"] != "fused" {
            return None;
        }
        let f = |k: &str| v[k].as_f64();
        let vel = v["vel_enu"].as_array()?;
        let view = TrackView {
            id: v["id"].as_u64()?,
            t: f("t")?,
            lat: f("lat")?,
            lon: f("lon")?,
            alt_m: f("alt_m")?,
            vel_enu: [vel.first()?.as_f64()?, vel.get(1)?.as_f64()?, vel.get(2)?.as_f64()?],
            alt_baro_ft: f("alt_baro_ft"),
            period_s: f("period_s").unwrap_or(1.0),
        };
        Some((u32::from_str_radix(v["hex"].as_str()?, 16).ok()?, view))
    }
}

/// Conflict prediction over every partition's tracks (sans-IO).
pub struct CrossPartition {
    cfg: ConflictConfig,
    coast_after_s: f64,
    monitor: ConflictMonitor,
    tracks: FastMap<u32, TrackView>,
    pub raised: u64,
}

impl CrossPartition {
    pub fn new(core: &CoreConfig) -> Self {
        CrossPartition {
            cfg: core.fuse.conflict.clone(),
            coast_after_s: core.track.coast_after_s,
            monitor: ConflictMonitor::new(),
            tracks: FastMap::default(),
            raised: 0,
        }
    }

    pub fn on_line(&mut self, line: &[u8]) {
        if let Some((addr, view)) = TrackView::parse(line) {
            self.tracks.insert(addr, view);
        }
    }

    /// Assesses at `now` when due; alerts out.
    pub fn advance(&mut self, now: f64, out: &mut Vec<Event>) {
        if !self.monitor.due(&self.cfg, now) {
            return;
        }
        let coast = self.coast_after_s;
        self.tracks.retain(|_, v| now - v.t <= coast + v.period_s + 60.0);
        let seen: Vec<Seen> = (self.tracks.iter())
            .filter(|(_, v)| now - v.t <= coast + v.period_s)
            .filter(|(_, v)| v.vel_enu[0].hypot(v.vel_enu[1]) >= MIN_CONFLICT_SPEED_MPS)
            .map(|(&addr, v)| Seen {
                addr,
                t: v.t,
                lat: v.lat,
                lon: v.lon,
                alt_m: v.alt_m,
                vel_enu: v.vel_enu,
                alt_ft: v.alt_baro_ft.unwrap_or(v.alt_m / crate::geo::FT_TO_M),
            })
            .collect();
        let kin = kinematics_at(now, seen);
        let tracks = &self.tracks;
        let mut alerts = Vec::new();
        let id = |a: u32| tracks.get(&a).map_or(0, |v| v.id);
        self.raised += self.monitor.assess(&self.cfg, now, &kin, id, &mut alerts);
        out.extend(alerts.into_iter().map(|a| crate::core::event(Output::Alert(a))));
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub struct PublisherStats {
    pub batches: u64,
    /// Frames the workers processed for the batches written (each batch once).
    pub frames: u64,
    pub lines: u64,
    pub replayed_batches: u64,
    pub bad_batches: u64,
}

pub async fn run(
    nats: &Nats,
    cfg: &ClusterConfig,
    core: &CoreConfig,
    output: Option<PathBuf>,
) -> Result<PublisherStats> {
    let mut out: Box<dyn Write + Send> = match &output {
        Some(p) => Box::new(std::io::BufWriter::new(
            std::fs::File::create(p).with_context(|| format!("cannot create {}", p.display()))?,
        )),
        None => Box::new(std::io::sink()),
    };
    let mut marks = Watermarks::new(cfg.partitions);
    let mut cross = CrossPartition::new(core);
    let mut stats = PublisherStats::default();
    let name = format!("{}-publisher", cfg.name);
    let consumer = nats
        .events
        .get_or_create_consumer(
            &name,
            pull::Config {
                durable_name: Some(name.clone()),
                ack_policy: AckPolicy::None,
                deliver_policy: DeliverPolicy::All,
                ..Default::default()
            },
        )
        .await
        .context("cannot consume the events")?;
    let mut msgs = consumer.messages().await?;
    let (mut alerts, mut text) = (Vec::new(), Vec::new());
    while let Some(m) = msgs.next().await {
        let m = m.map_err(|e| anyhow::anyhow!("event stream: {e}"))?;
        let p = m.subject.rsplit('.').next().and_then(|s| s.parse::<usize>().ok());
        let t = super::header_f64(&m.message, header::TIME);
        let mark = match (p, t) {
            (Some(p), Some(t)) => marks.mark(p, t, super::is_end(&m.message)),
            _ => Mark::Unknown,
        };
        match mark {
            Mark::Unknown => {
                stats.bad_batches += 1;
                continue;
            }
            Mark::Replayed => {
                stats.replayed_batches += 1;
                continue;
            }
            Mark::New => stats.batches += 1,
        }
        stats.frames += super::header_f64(&m.message, header::FRAMES).unwrap_or(0.0) as u64;
        out.write_all(&m.payload).context("writing output")?;
        for line in m.payload.split(|&b| b == b'\n').filter(|l| !l.is_empty()) {
            stats.lines += 1;
            cross.on_line(line);
        }
        let common = marks.common();
        if common.is_finite() {
            cross.advance(common, &mut alerts);
        }
        for ev in alerts.drain(..) {
            text.clear();
            write_event(&mut text, &ev, |_| "?");
            out.write_all(&text).context("writing output")?;
        }
        if marks.all_ended() {
            break;
        }
    }
    out.flush().context("writing output")?;
    println!(
        "publisher: batches={} frames={} lines={} conflicts={} replayed_batches={} bad_batches={}",
        stats.batches, stats.frames, stats.lines, cross.raised, stats.replayed_batches, stats.bad_batches
    );
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(hex: &str, id: u64, t: f64, lon: f64, ve: f64, source: &str) -> String {
        format!(
            r#"{{"type":"track","id":{id},"hex":"{hex}","t":{t},"lat":48.5,"lon":{lon},"alt_m":3000.0,"alt_baro_ft":9800,"vel_enu":[{ve},0.0,0.0],"cov_en":[[100.0,0.0],[0.0,100.0]],"source":"{source}","sources":["adsb"],"period_s":1.0,"motion":"moving","adsb_suspect":false}}"#
        )
    }

    #[test]
    fn two_partitions_tracks_closing_head_on_raise_one_alert_then_clear_it() {
        let mut cross = CrossPartition::new(&CoreConfig::default());
        // 12 km apart at 48.5 N, closing at 400 m/s, same level.
        cross.on_line(line("AAAAAA", 1, 100.0, 2.0, 200.0, "fused").as_bytes());
        cross.on_line(line("BBBBBB", 14, 100.0, 2.0 + 12_000.0 / 73_800.0, -200.0, "fused").as_bytes());
        // A single-source track and other records are not tracks to assess.
        cross.on_line(line("CCCCCC", 3, 100.0, 2.08, -200.0, "adsb").as_bytes());
        cross.on_line(br#"{"type":"mlat","hex":"DDDDDD","t":100.0}"#);
        let mut out = Vec::new();
        cross.advance(100.5, &mut out);
        assert_eq!(out.len(), 1, "{out:?}");
        let Event::Alert(crate::fuse::Alert::Conflict { pair, active, .. }) = &out[0] else {
            panic!("{out:?}")
        };
        assert!(*active);
        assert_eq!(*pair, [(0xAAAAAA, 1), (0xBBBBBB, 14)]);
        // Tracks no longer published are no longer assessed: the alert clears.
        out.clear();
        cross.advance(200.0, &mut out);
        assert!(
            matches!(&out[..], [Event::Alert(crate::fuse::Alert::Conflict { active: false, .. })]),
            "{out:?}"
        );
    }
}
