//! The back thread's counters and gauges, read once a tick into one list:
//! the stats line in the log and the Prometheus endpoint are both made from
//! it, so they cannot disagree, and a number added here reaches both.
//!
//! A reading has its Prometheus name (and label, for a per-receiver or
//! per-reason series) and, when the stats line shows it, its words there.
//! The per-receiver series are shown on the stats line compactly, in one
//! bracket after the frames; the per-reason ones by their sum.

use std::sync::atomic::Ordering;

use super::outputs::Outputs;
use super::registry::Registry;
use super::report::FrontSnapshot;
use crate::core::{AircraftHeld, Back};

/// Whether Prometheus sees a reading as a counter or a gauge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Counter,
    Gauge,
}

/// One number the service reports.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Reading {
    /// Prometheus's name (`None`: the stats line's alone, a sum of labelled series).
    pub metric: Option<&'static str>,
    pub label: Option<(&'static str, String)>,
    pub kind: Kind,
    pub value: u64,
    /// Its words on the stats line (`None`: Prometheus only).
    pub line: Option<&'static str>,
}

impl Reading {
    fn new(metric: &'static str, kind: Kind, value: u64, line: Option<&'static str>) -> Reading {
        Reading { metric: Some(metric), label: None, kind, value, line }
    }

    fn labelled(metric: &'static str, label: (&'static str, String), value: u64) -> Reading {
        Reading { metric: Some(metric), label: Some(label), kind: Kind::Counter, value, line: None }
    }

    /// Sent to the Prometheus recorder.
    pub fn export(&self) {
        let Some(name) = self.metric else { return };
        match (self.kind, &self.label) {
            (Kind::Counter, None) => metrics::counter!(name).absolute(self.value),
            (Kind::Counter, Some((k, v))) => metrics::counter!(name, *k => v.clone()).absolute(self.value),
            (Kind::Gauge, None) => metrics::gauge!(name).set(self.value as f64),
            (Kind::Gauge, Some((k, v))) => metrics::gauge!(name, *k => v.clone()).set(self.value as f64),
        }
    }
}

use Kind::{Counter, Gauge};

/// Every reading of this tick: the totals in the stats line's order, then
/// the labelled series.
pub(super) fn readings(
    front: &FrontSnapshot,
    back: &Back,
    reg: &Registry,
    outputs: &Outputs,
) -> Vec<Reading> {
    let s = &front.stats;
    let f = back.fuser().stats();
    let load = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
    let sum = |g: fn(&super::outputs::Destination) -> u64| outputs.dests.iter().map(g).sum::<u64>();
    let mut r = vec![
        Reading::new("fuse1090_frames_total", Counter, s.frames, Some("frames")),
        Reading::new("fuse1090_frames_dispatched_total", Counter, front.dispatched, None),
        Reading::new("fuse1090_messages_total", Counter, s.messages, Some("messages")),
        Reading::new("fuse1090_aircraft_total", Counter, front.aircraft, Some("aircraft")),
        Reading::new("fuse1090_tracks", Gauge, back.fuser().tracks() as u64, Some("tracks")),
        Reading::new("fuse1090_mlat_fixes_total", Counter, s.fixes, Some("fixes")),
        Reading::new("fuse1090_adsb_suspect_flags_total", Counter, f.suspect_flags, Some("suspects")),
        Reading::new("fuse1090_conflicts_total", Counter, f.conflicts, Some("conflicts")),
        Reading {
            metric: None,
            label: None,
            kind: Counter,
            value: f.rejected().iter().map(|(_, n)| n).sum(),
            line: Some("rejected measurements"),
        },
        Reading::new(
            "fuse1090_fusion_fallbacks_total",
            Counter,
            f.fusion_fallbacks,
            Some("fusion fallbacks"),
        ),
        Reading::new(
            "fuse1090_unknown_senders_total",
            Counter,
            load(&reg.unknown_senders),
            Some("unknown senders"),
        ),
        Reading::new(
            "fuse1090_socket_errors_total",
            Counter,
            load(&reg.socket_errors),
            Some("socket errors"),
        ),
        Reading::new("fuse1090_queue_drops_total", Counter, load(&reg.queue_drops), Some("queue drops")),
        // Datagrams lost in the kernel, the UDP inputs' buffers full.
        Reading::new(
            "fuse1090_udp_kernel_drops_total",
            Counter,
            load(&reg.kernel_drops),
            Some("kernel drops"),
        ),
        Reading::new("fuse1090_output_errors_total", Counter, sum(|d| d.errors()), Some("output errors")),
        // What slow readers cost: stdout lines, TCP subscribers dropped,
        // batches a pushed connection missed.
        Reading::new("fuse1090_output_drops_total", Counter, sum(|d| d.dropped()), Some("output drops")),
        Reading::new(
            "fuse1090_mlat_self_synced_fixes_total",
            Counter,
            front.self_synced_fixes,
            Some("self-synchronised fixes"),
        ),
        // Copies a link delivered after their transmission was processed.
        Reading::new("fuse1090_late_copies_total", Counter, s.late_copies, Some("late copies")),
        // Frames waiting for the core: it fills before anything is dropped.
        Reading::new("fuse1090_queue_frames", Gauge, reg.queued.load(Ordering::Relaxed) as u64, None),
        Reading::new("fuse1090_tracks_published_total", Counter, f.published, None),
        Reading::new("fuse1090_tracks_withheld_spread_total", Counter, f.withheld_spread, None),
        // Outside a track's gate: the outliers of normal operation, not bad input.
        Reading::new("fuse1090_measurements_gated_total", Counter, f.gated, None),
        Reading::new("fuse1090_track_restarts_total", Counter, f.restarts, None),
        Reading::new("fuse1090_output_clients", Gauge, sum(|d| d.clients()), None),
        Reading::new("fuse1090_output_stream_bytes_total", Counter, sum(|d| d.stream_bytes()), None),
    ];
    series(front, back, reg, &mut r);
    r
}

/// The labelled series: per reason, per table, per HTTP server, per receiver.
fn series(front: &FrontSnapshot, back: &Back, reg: &Registry, r: &mut Vec<Reading>) {
    let f = back.fuser().stats();
    let load = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
    // What the tracker turned away or could not do, each by its reason:
    // the counted skips of bad input, where a user looks first.
    for (reason, n) in f.rejected() {
        r.push(Reading::labelled("fuse1090_measurements_rejected_total", ("reason", reason.to_string()), n));
    }
    // The particle filters of aircraft heard by too few receivers for a fix.
    let sp = &f.sparse;
    for (what, n) in [
        ("started", sp.started),
        ("refused", sp.refused),
        ("restarted", sp.restarts),
        ("handed_over_at_a_fix", sp.handed_over),
        ("handed_over_at_one_mode", sp.handed_over_one_mode),
        ("given_back", sp.given_back + sp.mirrored + sp.spread),
    ] {
        r.push(Reading::labelled("fuse1090_sparse_filters_total", ("event", what.to_string()), n));
    }
    r.push(Reading::new("fuse1090_sparse_published_total", Counter, sp.published, None));
    for (outcome, n) in [
        ("taken", sp.velocities),
        ("contradicting", sp.velocities_contradicting),
        ("confirming_a_change", sp.velocities_redrawn),
    ] {
        r.push(Reading::labelled(
            "fuse1090_sparse_velocity_reports_total",
            ("outcome", outcome.to_string()),
            n,
        ));
    }
    let held = AircraftHeld { tracker: back.fuser().tracks(), ..front.held };
    for (table, n) in [
        ("decoder", held.decoder),
        ("mlat", held.mlat),
        ("conformance", held.conformance),
        ("tracker", held.tracker),
    ] {
        let mut g = Reading::labelled("fuse1090_aircraft_held", ("table", table.to_string()), n as u64);
        g.kind = Gauge;
        r.push(g);
    }
    // What the Prometheus endpoint and the HTTP server turned away.
    let http = [
        (
            &reg.metrics_http,
            [
                "fuse1090_metrics_http_refused_total",
                "fuse1090_metrics_http_timed_out_total",
                "fuse1090_metrics_http_accept_errors_total",
            ],
        ),
        (
            &reg.http,
            [
                "fuse1090_http_refused_total",
                "fuse1090_http_timed_out_total",
                "fuse1090_http_accept_errors_total",
            ],
        ),
    ];
    for (h, names) in http {
        for (n, name) in [&h.refused, &h.timed_out, &h.accept_errors].into_iter().zip(names) {
            r.push(Reading::new(name, Counter, load(n), None));
        }
    }
    for (rx, c) in reg.receivers.read().expect("registry").iter() {
        let counts = [
            ("fuse1090_receiver_frames_total", &c.frames),
            ("fuse1090_receiver_input_errors_total", &c.input_errors),
            ("fuse1090_receiver_garbage_bytes_total", &c.garbage_bytes),
            ("fuse1090_receiver_heartbeats_total", &c.heartbeats),
            ("fuse1090_receiver_throttled_total", &c.throttled),
            ("fuse1090_receiver_over_share_total", &c.over_share),
            ("fuse1090_receiver_queue_drops_total", &c.queue_drops),
            ("fuse1090_receiver_connects_total", &c.connects),
            ("fuse1090_receiver_disconnects_total", &c.disconnects),
            ("fuse1090_receiver_idle_timeouts_total", &c.idle_timeouts),
        ];
        for (name, n) in counts {
            r.push(Reading::labelled(name, ("receiver", rx.id.clone()), load(n)));
        }
    }
}

/// The stats line: each reading it shows as `words value`, the receivers'
/// frames, errors, drops, throttled and over-share frames in a bracket
/// after the frames, and the fix rate over `recent` (fixes, seconds).
pub(super) fn stats_line(readings: &[Reading], recent: (u64, f64)) -> String {
    let per_rx = |metric: &'static str| {
        readings.iter().filter(move |r| r.metric == Some(metric)).map(|r| (r.label.as_ref(), r.value))
    };
    let mut rx: Vec<String> = per_rx("fuse1090_receiver_frames_total")
        .map(|(label, frames)| format!("{}={frames}", label.map_or("?", |l| l.1.as_str())))
        .collect();
    for (suffix, metric) in [
        ("err", "fuse1090_receiver_input_errors_total"),
        ("drop", "fuse1090_receiver_queue_drops_total"),
        ("thr", "fuse1090_receiver_throttled_total"),
        ("share", "fuse1090_receiver_over_share_total"),
    ] {
        for (part, (_, n)) in rx.iter_mut().zip(per_rx(metric)) {
            part.push_str(&format!("/{n}{suffix}"));
        }
    }
    let mut parts = Vec::new();
    for r in readings {
        let Some(words) = r.line else { continue };
        if words == "frames" {
            parts.push(format!("frames {} [{}]", r.value, rx.join(" ")));
        } else if words == "fixes" {
            parts.push(format!("fixes {} ({:.1}/s)", r.value, recent.0 as f64 / recent.1.max(1e-9)));
        } else {
            parts.push(format!("{words} {}", r.value));
        }
    }
    format!("stats: {}", parts.join(", "))
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::Ordering;

    use super::*;
    use crate::core::{Core, CoreConfig};
    use crate::live::config::{ReceiverConfig, ServiceConfig};

    #[test]
    fn the_stats_line_and_prometheus_read_the_same_numbers() {
        let reg = Registry::default();
        for (id, frames) in [("a", 3), ("b", 2)] {
            let k = reg.add(ReceiverConfig::for_test(id, None));
            reg.receivers.read().unwrap()[k].1.frames.store(frames, Ordering::Relaxed);
        }
        reg.socket_errors.store(4, Ordering::Relaxed);
        let (_, back) = Core::stages(&CoreConfig::default());
        let outputs = Outputs::new(&[], &ServiceConfig::default(), &[]);
        let mut front = FrontSnapshot { aircraft: 7, ..FrontSnapshot::default() };
        front.stats.frames = 5;
        front.stats.fixes = 30;
        let readings = readings(&front, &back, &reg, &outputs);
        let line = stats_line(&readings, (30, 10.0));
        assert!(
            line.starts_with("stats: frames 5 [a=3/0err/0drop/0thr/0share b=2/0err/0drop/0thr/0share], messages 0, aircraft 7"),
            "{line}"
        );
        assert!(line.contains("fixes 30 (3.0/s)") && line.contains("socket errors 4"), "{line}");
        // Every number the line shows under a Prometheus name is that series'.
        for r in readings.iter().filter(|r| r.line.is_some() && r.metric.is_some()) {
            let shown = format!("{} {}", r.line.unwrap(), r.value);
            assert!(line.contains(&shown), "{shown:?} not in {line}");
        }
        let per_rx = readings.iter().filter(|r| r.metric == Some("fuse1090_receiver_frames_total"));
        assert_eq!(per_rx.map(|r| r.value).collect::<Vec<_>>(), [3, 2]);
    }
}
