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
use std::sync::Arc;

use anyhow::{Context, Result};
use async_nats::jetstream::consumer::{pull, AckPolicy, DeliverPolicy};

use super::outage::Follow;
use super::{header, wire, ClusterConfig, Mark, Nats, Watermarks};
use crate::config::Config;
use crate::core::{CoreConfig, Event};
use crate::fuse::conflict::{kinematics_at, Seen};
use crate::fuse::{
    ConflictConfig, ConflictMonitor, Output, TrackReport, TrackSource, MIN_CONFLICT_SPEED_MPS,
};
use crate::live::config::ReceiverConfig;
use crate::live::outputs::Outputs;
use crate::live::registry::Registry;
use crate::live::shutdown::Tasks;
use crate::live::stream_out;
use crate::live::web::WebPublisher;
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
    /// A fused track's view (`None` for a single-source track, or one
    /// without height).
    pub fn of(r: &TrackReport) -> Option<TrackView> {
        (r.source == TrackSource::Fused).then_some(())?;
        Some(TrackView {
            id: r.id,
            t: r.est.t,
            lat: r.est.lat,
            lon: r.est.lon,
            alt_m: r.est.alt_m?,
            vel_enu: r.est.vel_enu,
            alt_baro_ft: r.alt_baro_ft.map(f64::from),
            period_s: r.period_s,
        })
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

    pub fn on_event(&mut self, ev: &Event) {
        if let Event::Track(r) = ev {
            if let Some(view) = TrackView::of(r) {
                self.tracks.insert(r.addr, view);
            }
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
    /// Events written (alerts of the cross-partition stage included).
    pub events: u64,
    pub replayed_batches: u64,
    pub bad_batches: u64,
    /// Receivers named by an event before their declaration was read
    /// (written as "?").
    pub unknown_receivers: u64,
}

/// How long a replay's publisher waits, once every partition has ended,
/// for the clock's last receiver records.
const CLOCK_END_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

/// Where the events go: the `--output` file, the configuration's
/// `[[output]]` destinations and the HTTP server's documents, as a single
/// node has them.
struct Sinks {
    file: Box<dyn Write + Send>,
    outputs: Outputs,
    web: Option<WebPublisher>,
    registry: Arc<Registry>,
    messages: u64,
    text: Vec<u8>,
}

impl Sinks {
    async fn start(config: &Config, output: Option<PathBuf>) -> Result<(Sinks, Tasks)> {
        let file: Box<dyn Write + Send> = match &output {
            Some(p) => Box::new(std::io::BufWriter::new(
                std::fs::File::create(p).with_context(|| format!("cannot create {}", p.display()))?,
            )),
            None => Box::new(std::io::sink()),
        };
        let (streams, failed) = stream_out::start_all(&config.output, &[]).await;
        if let Some((n, e)) = failed.into_iter().next() {
            anyhow::bail!("[[output]] {n} cannot start: {e}");
        }
        let outputs = Outputs::new(&config.output, &config.service, &streams);
        let registry = Arc::new(Registry::default());
        let mut tasks = Tasks::default();
        let web = crate::live::start_http(config, &registry, &mut tasks).await?;
        let web = web.map(WebPublisher::new);
        Ok((Sinks { file, outputs, web, registry, messages: 0, text: Vec::new() }, tasks))
    }

    /// One batch of events, at data time `now`; receivers named by `ids`.
    fn send(&mut self, events: &[Event], ids: &[String], now: f64, stats: &mut PublisherStats) -> Result<()> {
        let unknown = std::cell::Cell::new(0);
        let name = |i: usize| {
            ids.get(i).map(String::as_str).unwrap_or_else(|| {
                unknown.set(unknown.get() + 1);
                "?"
            })
        };
        for ev in events {
            self.text.clear();
            write_event(&mut self.text, ev, name);
            self.file.write_all(&self.text).context("writing output")?;
        }
        stats.events += events.len() as u64;
        self.messages +=
            events.iter().filter(|e| matches!(e, Event::Position(_) | Event::Mlat(_))).count() as u64;
        self.outputs.publish(events, name, now);
        if let Some(w) = &mut self.web {
            w.observe(events, now);
            w.maybe_render(now, self.messages, &self.registry);
        }
        stats.unknown_receivers += unknown.get();
        Ok(())
    }
}

pub async fn run(
    nats: &Nats,
    cfg: &ClusterConfig,
    config: &Config,
    output: Option<PathBuf>,
) -> Result<PublisherStats> {
    let (sinks, http_tasks) = Sinks::start(config, output).await?;
    let mut p = Publisher {
        sinks,
        marks: Watermarks::new(cfg.partitions),
        cross: CrossPartition::new(&config.core),
        stats: PublisherStats::default(),
        ids: Vec::new(),
        alerts: Vec::new(),
        clock_ended: false,
    };
    // The receivers, in declaration order, for the records that name them.
    let mut declared = nats.receiver_declarations().await?;
    let name = format!("{}-publisher", cfg.name);
    let config = pull::Config {
        durable_name: Some(name.clone()),
        ack_policy: AckPolicy::None,
        deliver_policy: DeliverPolicy::All,
        ..Default::default()
    };
    let mut msgs = Follow::start(&nats.events, config, false, "the events").await?;
    loop {
        let ended = p.marks.all_ended();
        let m = tokio::select! {
            // Declarations first: an event may name a receiver only just declared.
            biased;
            d = declared.next() => {
                if let Some(d) = d {
                    // Listed on the map (its frames are the ingest's to count).
                    let d = d?;
                    p.sinks.registry.add(ReceiverConfig::declared(&d));
                    p.ids.push(d.id);
                }
                continue;
            }
            m = msgs.next() => m,
            _ = tokio::time::sleep(CLOCK_END_WAIT), if ended => {
                tracing::warn!("the clock's last receiver records did not come: ending without them");
                break;
            }
        };
        let Some(m) = m else { break };
        let m = m?;
        if p.on_message(&m)? {
            break;
        }
    }
    p.sinks.file.flush().context("writing output")?;
    http_tasks.stop(std::time::Duration::from_secs(2)).await;
    let stats = p.stats;
    println!(
        "publisher: batches={} frames={} events={} conflicts={} replayed_batches={} bad_batches={} \
         unknown_receivers={} nats_retries={} nats_disconnects={}",
        stats.batches,
        stats.frames,
        stats.events,
        p.cross.raised,
        stats.replayed_batches,
        stats.bad_batches,
        stats.unknown_receivers,
        super::outage::retries(),
        super::outage::disconnects()
    );
    Ok(stats)
}

/// The publisher's state between messages.
struct Publisher {
    sinks: Sinks,
    marks: Watermarks,
    cross: CrossPartition,
    stats: PublisherStats,
    /// The receivers' ids, in declaration order.
    ids: Vec<String>,
    alerts: Vec<Event>,
    /// A replay ends with every partition's last batch and the clock's
    /// last receiver records, which may come a little after.
    clock_ended: bool,
}

impl Publisher {
    /// One message of the events stream sent on; true when the replay has
    /// ended.
    fn on_message(&mut self, m: &async_nats::jetstream::Message) -> Result<bool> {
        let last = m.subject.rsplit('.').next().unwrap_or("");
        if last == super::CLOCK_RECORDS {
            // The network's receiver records: not a partition's, no time to mark.
            match wire::decode::<Vec<Event>>(&m.payload) {
                Ok(events) => {
                    let t = super::header_f64(&m.message, header::TIME).unwrap_or(f64::NAN);
                    self.sinks.send(&events, &self.ids, t, &mut self.stats)?;
                }
                Err(_) => self.stats.bad_batches += 1,
            }
            self.clock_ended |= super::is_end(&m.message);
            return Ok(self.marks.all_ended() && self.clock_ended);
        }
        let p = last.parse::<usize>().ok();
        let t = super::header_f64(&m.message, header::TIME);
        let events = match wire::decode::<Vec<Event>>(&m.payload) {
            Ok(events) => events,
            Err(e) => {
                self.stats.bad_batches += 1;
                tracing::warn!(error = %e, "event batch unreadable: skipped");
                return Ok(false);
            }
        };
        let (mark, now) = match (p, t) {
            (Some(p), Some(t)) => (self.marks.mark(p, t, super::is_end(&m.message)), t),
            _ => (Mark::Unknown, f64::NAN),
        };
        match mark {
            Mark::Unknown => {
                self.stats.bad_batches += 1;
                return Ok(false);
            }
            Mark::Replayed => {
                self.stats.replayed_batches += 1;
                return Ok(false);
            }
            Mark::New => self.stats.batches += 1,
        }
        self.stats.frames += super::header_f64(&m.message, header::FRAMES).unwrap_or(0.0) as u64;
        self.sinks.send(&events, &self.ids, now, &mut self.stats)?;
        for ev in &events {
            self.cross.on_event(ev);
        }
        let common = self.marks.common();
        if common.is_finite() {
            self.cross.advance(common, &mut self.alerts);
        }
        if !self.alerts.is_empty() {
            self.sinks.send(&self.alerts, &self.ids, now, &mut self.stats)?;
            self.alerts.clear();
        }
        Ok(self.marks.all_ended() && self.clock_ended)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::publish::test_report::{report, Source};

    /// Track `id` of `hex` at `t`, at 48.5 N and `lon`, 3000 m, flying east at `ve` m/s.
    fn track(hex: u32, id: u64, t: f64, lon: f64, ve: f64, source: TrackSource) -> Event {
        let mut r = report(hex, t, &[Source::Adsb]);
        (r.id, r.source, r.alt_baro_ft) = (id, source, Some(9800));
        (r.est.lat, r.est.lon, r.est.alt_m, r.est.vel_enu) = (48.5, lon, Some(3000.0), [ve, 0.0, 0.0]);
        Event::Track(Box::new(r))
    }

    #[test]
    fn two_partitions_tracks_closing_head_on_raise_one_alert_then_clear_it() {
        let mut cross = CrossPartition::new(&CoreConfig::default());
        // 12 km apart at 48.5 N, closing at 400 m/s, same level.
        cross.on_event(&track(0xAAAAAA, 1, 100.0, 2.0, 200.0, TrackSource::Fused));
        cross.on_event(&track(0xBBBBBB, 14, 100.0, 2.0 + 12_000.0 / 73_800.0, -200.0, TrackSource::Fused));
        // A single-source track and other records are not tracks to assess.
        cross.on_event(&track(0xCCCCCC, 3, 100.0, 2.08, -200.0, TrackSource::Adsb));
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

    /// A batch of events goes through the wire as it was, every field.
    #[test]
    fn events_cross_the_wire_unchanged() {
        let events = vec![
            track(0xAAAAAA, 1, 100.0, 2.0, 200.0, TrackSource::Fused),
            track(0xCCCCCC, 3, 100.5, 2.08, -200.0, TrackSource::Adsb),
        ];
        let back: Vec<Event> = wire::decode(&wire::encode(&events)).unwrap();
        assert_eq!(back, events);
        assert!(wire::decode::<Vec<Event>>(b"\x05garbage").is_err());
    }
}
