//! What the service tells its operator about itself: the stats line in the
//! log and the Prometheus metrics, from the front stage's counters (sent
//! with each batch), the back stage's and the inputs' registry.

use std::sync::atomic::Ordering;

use super::outputs::Outputs;
use super::record::RecordStats;
use super::registry::Registry;
use crate::core::{AircraftHeld, Back, CoreStats, Front};

/// The front stage's counters, sent with each batch for the stats line and
/// the metrics, which the back thread writes (it knows the tracks).
#[derive(Clone, Copy, Default)]
pub(super) struct FrontSnapshot {
    pub stats: CoreStats,
    pub aircraft: u64,
    pub mlat_fixes: u64,
    pub self_synced_fixes: u64,
    pub dispatched: u64,
    /// The front's per-aircraft tables' sizes (the tracker's is the back's).
    pub held: AircraftHeld,
}

/// The front thread's metrics, once a second: per receiver its network
/// delay (logged once when learnt), late copies and MLAT state, and the
/// recording's counts.
pub(super) fn front_metrics(
    front: &Front,
    recording: Option<&RecordStats>,
    announced: &mut std::collections::HashSet<String>,
) {
    delay_metrics(front, announced);
    for (id, n) in front.late_copies() {
        metrics::counter!("fuse1090_receiver_late_copies_total", "receiver" => id.to_string()).absolute(n);
    }
    // Copies of a transmission left out of its fix: late ones (multipath)
    // and GPS times off by seconds from the others'.
    let m = &front.mlat().stats;
    metrics::counter!("fuse1090_mlat_outliers_dropped_total").absolute(m.outliers_dropped);
    // Fixes whose first search for outliers left out a copy that came out
    // early at its fix, solved again with each copy left out in turn.
    metrics::counter!("fuse1090_mlat_refixed_total").absolute(m.refixed);
    metrics::counter!("fuse1090_mlat_gps_time_jumps_total").absolute(m.time_jumps);
    // Transmissions that gave no fix, per reason (every reason, zeros too,
    // so that a dashboard has each series from the start).
    for (why, n) in m.rejects.iter() {
        metrics::counter!("fuse1090_mlat_rejects_total", "reason" => why.name()).absolute(n);
    }
    for (rx, (id, h)) in front.mlat_health().enumerate() {
        // MLAT exclusion is a state, not a sentence: an excluded receiver
        // is still synchronised and comes back (gauge 1 while it is out).
        metrics::gauge!("fuse1090_receiver_mlat_excluded", "receiver" => id.to_string())
            .set(h.excluded as u8 as f64);
        let counts = [
            ("fuse1090_receiver_mlat_exclusions_total", h.exclusions),
            ("fuse1090_receiver_clock_resets_total", h.clock_resets),
        ];
        for (name, n) in counts {
            metrics::counter!(name, "receiver" => id.to_string()).absolute(n);
        }
        // What multilateration has learnt of its timing (absent until
        // known, as in the track stream's receiver records).
        let r = front.mlat().receiver_report(rx, 0.0);
        let gauges = [
            ("fuse1090_receiver_sync_outlier_rate", Some(h.outlier_rate)),
            ("fuse1090_receiver_timing_sigma_ns", r.sigma_ns),
            ("fuse1090_receiver_timing_offset_ns", r.offset_ns),
            ("fuse1090_receiver_outlier_rate", r.outlier_rate),
        ];
        for (name, v) in gauges {
            if let Some(v) = v {
                metrics::gauge!(name, "receiver" => id.to_string()).set(v);
            }
        }
    }
    if let Some(r) = recording {
        record_metrics(r);
    }
}

/// What the recording wrote and could not write.
fn record_metrics(s: &RecordStats) {
    metrics::counter!("fuse1090_record_frames_total").absolute(s.frames);
    metrics::counter!("fuse1090_record_dropped_frames_total").absolute(s.dropped);
    metrics::counter!("fuse1090_record_write_errors_total").absolute(s.write_errors);
    metrics::counter!("fuse1090_record_rotations_total").absolute(s.rotations);
}

/// The network delays learnt for receivers whose reports are dated by
/// arrival (see `core::delay`): a gauge each, and a log line when a
/// receiver's is first learnt.
fn delay_metrics(front: &Front, announced: &mut std::collections::HashSet<String>) {
    for (id, mean_s, spread_s) in front.learnt_delays() {
        metrics::gauge!("fuse1090_receiver_network_delay_seconds", "receiver" => id.to_string()).set(mean_s);
        if !announced.contains(id) {
            announced.insert(id.to_string());
            tracing::info!(
                receiver = id,
                delay_ms = format!("{:.1}", mean_s * 1e3),
                spread_ms = format!("{:.1}", spread_s * 1e3),
                "reports dated by arrival: network delay learnt"
            );
        }
    }
}

/// The log's stats line; `(fixes, span_s)`: the fixes made since the last
/// one and the time since.
pub(super) fn stats_line(
    front: &FrontSnapshot,
    back: &Back,
    reg: &Registry,
    outputs: &Outputs,
    recent: (u64, f64),
) {
    let s = &front.stats;
    let f = back.fuser().stats();
    let per_rx: Vec<String> = reg
        .receivers
        .read()
        .expect("registry")
        .iter()
        .map(|(r, c)| {
            format!(
                "{}={}/{}err/{}drop/{}thr/{}share",
                r.id,
                c.frames.load(Ordering::Relaxed),
                c.input_errors.load(Ordering::Relaxed),
                c.queue_drops.load(Ordering::Relaxed),
                c.throttled.load(Ordering::Relaxed),
                c.over_share.load(Ordering::Relaxed)
            )
        })
        .collect();
    let out_err: u64 = outputs.dests.iter().map(|d| d.errors()).sum();
    let out_dropped: u64 = outputs.dests.iter().map(|d| d.dropped()).sum();
    tracing::info!(
        "stats: frames {} [{}], messages {}, aircraft {}, tracks {}, fixes {} ({:.1}/s), suspects {}, conflicts {}, \
         rejected measurements {}, fusion fallbacks {}, unknown senders {}, socket errors {}, queue drops {}, \
         kernel drops {}, output errors {}, output drops {}, mlat {} (self-synchronised {}), late copies {}",
        s.frames,
        per_rx.join(" "),
        s.messages,
        front.aircraft,
        back.fuser().tracks(),
        s.fixes,
        recent.0 as f64 / recent.1.max(1e-9),
        f.suspect_flags,
        f.conflicts,
        f.rejected().iter().map(|(_, n)| n).sum::<u64>(),
        f.fusion_fallbacks,
        reg.unknown_senders.load(Ordering::Relaxed),
        reg.socket_errors.load(Ordering::Relaxed),
        reg.queue_drops.load(Ordering::Relaxed),
        reg.kernel_drops.load(Ordering::Relaxed),
        out_err,
        out_dropped,
        front.mlat_fixes,
        front.self_synced_fixes,
        s.late_copies,
    );
}

pub(super) fn metrics(front: &FrontSnapshot, back: &Back, reg: &Registry, outputs: &Outputs) {
    let s = &front.stats;
    metrics::counter!("fuse1090_frames_total").absolute(s.frames);
    metrics::counter!("fuse1090_frames_dispatched_total").absolute(front.dispatched);
    metrics::counter!("fuse1090_messages_total").absolute(s.messages);
    metrics::counter!("fuse1090_mlat_fixes_total").absolute(s.fixes);
    metrics::counter!("fuse1090_mlat_self_synced_fixes_total").absolute(front.self_synced_fixes);
    // Copies a link delivered after their transmission was processed.
    metrics::counter!("fuse1090_late_copies_total").absolute(s.late_copies);
    metrics::gauge!("fuse1090_tracks").set(back.fuser().tracks() as f64);
    let held = AircraftHeld { tracker: back.fuser().tracks(), ..front.held };
    for (table, n) in [
        ("decoder", held.decoder),
        ("mlat", held.mlat),
        ("conformance", held.conformance),
        ("tracker", held.tracker),
    ] {
        metrics::gauge!("fuse1090_aircraft_held", "table" => table).set(n as f64);
    }
    metrics::counter!("fuse1090_unknown_senders_total").absolute(reg.unknown_senders.load(Ordering::Relaxed));
    metrics::counter!("fuse1090_socket_errors_total").absolute(reg.socket_errors.load(Ordering::Relaxed));
    metrics::counter!("fuse1090_queue_drops_total").absolute(reg.queue_drops.load(Ordering::Relaxed));
    for (name, http) in [("metrics_http", &reg.metrics_http), ("http", &reg.http)] {
        let counts = [
            ("refused", &http.refused),
            ("timed_out", &http.timed_out),
            ("accept_errors", &http.accept_errors),
        ];
        for (what, n) in counts {
            metrics::counter!(format!("fuse1090_{name}_{what}_total")).absolute(n.load(Ordering::Relaxed));
        }
    }
    // Datagrams lost in the kernel, the UDP inputs' buffers full.
    metrics::counter!("fuse1090_udp_kernel_drops_total").absolute(reg.kernel_drops.load(Ordering::Relaxed));
    // Frames waiting for the core: it fills before anything is dropped.
    metrics::gauge!("fuse1090_queue_frames").set(reg.queued.load(Ordering::Relaxed) as f64);
    for (r, c) in reg.receivers.read().expect("registry").iter() {
        let counts = [
            ("fuse1090_receiver_frames_total", &c.frames),
            ("fuse1090_receiver_input_errors_total", &c.input_errors),
            ("fuse1090_receiver_garbage_bytes_total", &c.garbage_bytes),
            ("fuse1090_receiver_heartbeats_total", &c.heartbeats),
            ("fuse1090_receiver_throttled_total", &c.throttled),
            ("fuse1090_receiver_over_share_total", &c.over_share),
            ("fuse1090_receiver_queue_drops_total", &c.queue_drops),
        ];
        for (name, n) in counts {
            metrics::counter!(name, "receiver" => r.id.clone()).absolute(n.load(Ordering::Relaxed));
        }
    }
    let f = back.fuser().stats();
    metrics::counter!("fuse1090_tracks_published_total").absolute(f.published);
    metrics::counter!("fuse1090_adsb_suspect_flags_total").absolute(f.suspect_flags);
    // What the tracker turned away or could not do, each by its reason:
    // the counted skips of bad input, where a user looks first.
    for (reason, n) in f.rejected() {
        metrics::counter!("fuse1090_measurements_rejected_total", "reason" => reason).absolute(n);
    }
    // Outside a track's gate: the outliers of normal operation, not bad input.
    metrics::counter!("fuse1090_measurements_gated_total").absolute(f.gated);
    metrics::counter!("fuse1090_track_restarts_total").absolute(f.restarts);
    metrics::counter!("fuse1090_fusion_fallbacks_total").absolute(f.fusion_fallbacks);
    metrics::counter!("fuse1090_output_errors_total")
        .absolute(outputs.dests.iter().map(|d| d.errors()).sum());
    // What slow readers cost: stdout lines, TCP subscribers dropped, batches
    // a pushed connection missed.
    metrics::counter!("fuse1090_output_drops_total")
        .absolute(outputs.dests.iter().map(|d| d.dropped()).sum());
    metrics::gauge!("fuse1090_output_clients")
        .set(outputs.dests.iter().map(|d| d.clients()).sum::<u64>() as f64);
    metrics::counter!("fuse1090_output_stream_bytes_total")
        .absolute(outputs.dests.iter().map(|d| d.stream_bytes()).sum());
}
