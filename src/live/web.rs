//! What the HTTP server hands out under `/data/`: readsb's `aircraft.json`
//! and `receiver.json`, and fuse1090's `receivers.json`, rendered by the
//! tracker thread once a second and kept as bytes.
//!
//! Rendering once a second, not per request, means twenty browsers polling
//! cost the core twenty reference-count increments, and a request never
//! waits for (or touches) the core: the server copies out the last bytes.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};

use hyper::body::Bytes;
use serde::Serialize;

use super::inputs::Registry;
use crate::core::Event;
use crate::publish::aircraft_json::AircraftView;
use crate::publish::json::round;

/// How often the documents are rendered (ms): readsb's `refresh`, which
/// tar1090 polls at.
pub const REFRESH_MS: u64 = 1000;

/// The latest documents, shared between the tracker thread (which renders)
/// and the HTTP server (which serves).
#[derive(Default)]
pub struct WebData {
    aircraft: Mutex<Bytes>,
    receivers: Mutex<Bytes>,
    receiver: Mutex<Bytes>,
    map: Mutex<Bytes>,
}

/// The documents the server can be asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Document {
    Aircraft,
    Receivers,
    Receiver,
    /// The map's settings (`map.json`: the tile URL and its attribution).
    Map,
}

impl WebData {
    fn slot(&self, d: Document) -> &Mutex<Bytes> {
        match d {
            Document::Aircraft => &self.aircraft,
            Document::Receivers => &self.receivers,
            Document::Receiver => &self.receiver,
            Document::Map => &self.map,
        }
    }

    /// The documents, with the map's settings from `[http]`.
    pub fn new(tiles: Option<&str>, attribution: Option<&str>) -> WebData {
        let data = WebData::default();
        let map = serde_json::json!({ "tiles": tiles, "attribution": attribution });
        data.set(Document::Map, map.to_string().into_bytes());
        data
    }

    pub fn get(&self, d: Document) -> Bytes {
        self.slot(d).lock().map(|b| b.clone()).unwrap_or_default()
    }

    fn set(&self, d: Document, bytes: Vec<u8>) {
        if let Ok(mut b) = self.slot(d).lock() {
            *b = Bytes::from(bytes);
        }
    }
}

/// The tracker thread's side: follows the published events and renders.
pub struct WebPublisher {
    data: Arc<WebData>,
    view: AircraftView,
    /// The newest `receiver` record of each receiver, by index, as the
    /// track stream writes it (less its `type` and `id`): rendered when it
    /// is published, once a minute, not at every refresh.
    reports: Vec<Option<serde_json::Value>>,
    /// Frames counted per receiver at the last render, for the rate.
    last_frames: Vec<u64>,
    last_render: f64,
}

#[derive(Serialize)]
struct ReceiverDoc {
    version: String,
    refresh: u64,
    history: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    lat: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    lon: Option<f64>,
}

#[derive(Serialize)]
struct ReceiversDoc<'a> {
    now: f64,
    receivers: Vec<ReceiverEntry<'a>>,
}

#[derive(Serialize)]
struct ReceiverEntry<'a> {
    id: &'a str,
    lat: f64,
    lon: f64,
    alt_m: f64,
    clock: &'static str,
    frames: u64,
    frames_per_s: f64,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    revoked: bool,
    /// The `receiver` record of the track stream, when one was published.
    #[serde(skip_serializing_if = "Option::is_none")]
    mlat: Option<&'a serde_json::Value>,
}

impl WebPublisher {
    pub fn new(data: Arc<WebData>) -> WebPublisher {
        WebPublisher {
            data,
            view: AircraftView::new(),
            reports: Vec::new(),
            last_frames: Vec::new(),
            last_render: f64::NEG_INFINITY,
        }
    }

    /// Follows what was just published at `now`.
    pub fn observe(&mut self, events: &[Event], now: f64) {
        self.view.observe(events, now);
        for ev in events {
            if let Event::Receiver(r) = ev {
                if self.reports.len() <= r.rx {
                    self.reports.resize(r.rx + 1, None);
                }
                self.reports[r.rx] = Some(receiver_record(ev));
            }
        }
    }

    /// Renders the documents if [`REFRESH_MS`] has passed since the last time.
    pub fn maybe_render(&mut self, now: f64, messages: u64, registry: &Registry) {
        let dt = now - self.last_render;
        if dt * 1000.0 < REFRESH_MS as f64 {
            return;
        }
        self.view.expire(now);
        self.data.set(Document::Aircraft, self.view.render(now, messages));
        let (receivers, receiver) = self.render_receivers(now, dt, registry);
        self.data.set(Document::Receivers, receivers);
        self.data.set(Document::Receiver, receiver);
        self.last_render = now;
    }

    fn render_receivers(&mut self, now: f64, dt: f64, registry: &Registry) -> (Vec<u8>, Vec<u8>) {
        let Ok(list) = registry.receivers.read() else { return Default::default() };
        self.last_frames.resize(list.len(), 0);
        let mut entries = Vec::with_capacity(list.len());
        let (mut lat, mut lon, mut n) = (0.0, 0.0, 0usize);
        for (i, (cfg, counters)) in list.iter().enumerate() {
            let frames = counters.frames.load(Ordering::Relaxed);
            let rate = if dt.is_finite() && dt > 0.0 {
                frames.saturating_sub(self.last_frames[i]) as f64 / dt
            } else {
                0.0
            };
            self.last_frames[i] = frames;
            let revoked = counters.revoked.load(Ordering::Relaxed);
            if !revoked {
                (lat, lon, n) = (lat + cfg.lat, lon + cfg.lon, n + 1);
            }
            entries.push(ReceiverEntry {
                id: &cfg.id,
                lat: cfg.lat,
                lon: cfg.lon,
                alt_m: cfg.alt_m,
                clock: cfg.clock.name(),
                frames,
                frames_per_s: round(rate, 10.0),
                revoked,
                mlat: self.reports.get(i).and_then(Option::as_ref),
            });
        }
        let receivers = serde_json::to_vec(&ReceiversDoc { now: round(now, 10.0), receivers: entries });
        // The network's centre: where tar1090 centres its map and measures
        // distances from (readsb gives its one receiver's position).
        let centre = (n > 0).then(|| (lat / n as f64, lon / n as f64));
        let receiver = serde_json::to_vec(&ReceiverDoc {
            version: format!("fuse1090 {}", env!("CARGO_PKG_VERSION")),
            refresh: REFRESH_MS,
            history: 0,
            lat: centre.map(|c| round(c.0, 1e6)),
            lon: centre.map(|c| round(c.1, 1e6)),
        });
        (receivers.unwrap_or_default(), receiver.unwrap_or_default())
    }
}

/// A `receiver` event as the track stream writes it, without the `type` and
/// `id` that `receivers.json` has around it.
fn receiver_record(ev: &Event) -> serde_json::Value {
    let mut line = Vec::new();
    crate::publish::json::write_event(&mut line, ev, |_| "");
    let mut v: serde_json::Value = serde_json::from_slice(&line).unwrap_or_default();
    if let Some(o) = v.as_object_mut() {
        o.remove("type");
        o.remove("id");
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlat::report::{ReceiverReport, RxState};

    #[test]
    fn the_maps_settings_are_served_as_configured() {
        let map = |d: WebData| serde_json::from_slice::<serde_json::Value>(&d.get(Document::Map)).unwrap();
        let url = "https://t.example/{z}/{x}/{y}.png";
        assert_eq!(
            map(WebData::new(Some(url), Some("© someone"))),
            serde_json::json!({"tiles": url, "attribution": "© someone"})
        );
        assert_eq!(map(WebData::new(None, None)), serde_json::json!({"tiles": null, "attribution": null}));
    }

    #[test]
    fn a_receivers_learnt_timing_is_kept_as_the_track_stream_writes_it() {
        let mut web = WebPublisher::new(Arc::default());
        let report = ReceiverReport {
            t: 5.0,
            rx: 2,
            state: RxState::Ok,
            reason: None,
            sigma_ns: Some(42.04),
            offset_ns: None,
            outlier_rate: Some(0.01),
            late_delay_ns: None,
            position_offset_en_m: None,
            position_offset_sigma_m: None,
        };
        web.observe(&[Event::Receiver(Box::new(report))], 5.0);
        assert!(web.reports[..2].iter().all(Option::is_none));
        let kept = web.reports[2].as_ref().unwrap();
        assert_eq!(
            kept,
            &serde_json::json!({"t": 5.0, "state": "ok", "sigma_ns": 42.0, "outlier_rate": 0.01})
        );
    }
}
