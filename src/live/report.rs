//! What the service tells its operator about itself: the stats line in the
//! log and the Prometheus metrics, from the front stage's counters (sent
//! with each batch), the back stage's and the inputs' registry.

use super::record::RecordStats;
use crate::core::{AircraftHeld, CoreStats, Front};

/// The front stage's counters, sent with each batch for the stats line and
/// the metrics, which the back thread writes (it knows the tracks).
#[derive(Clone, Copy, Default)]
pub(super) struct FrontSnapshot {
    pub stats: CoreStats,
    pub aircraft: u64,
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
    // Copies kept out of the position surveys, their times beyond any
    // receiver's fault.
    metrics::counter!("fuse1090_mlat_survey_outliers_total").absolute(m.survey_gross);
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
    air_metrics(front);
    if let Some(r) = recording {
        record_metrics(r);
    }
}

/// What heading reports taught of the air (absent until they taught
/// anything): the magnetic variation, the wind each kilometre up, its
/// spread across the region, and the lessons and outliers counted.
fn air_metrics(front: &Front) {
    let w = front.wind();
    if w.stats.learnt == 0 {
        return;
    }
    metrics::counter!("fuse1090_air_lessons_total").absolute(w.stats.learnt);
    metrics::counter!("fuse1090_air_outliers_total").absolute(w.stats.outliers);
    metrics::counter!("fuse1090_commb_heading_velocities_total").absolute(front.stats().commb_headings);
    let (variation, sigma) = w.variation_deg();
    metrics::gauge!("fuse1090_air_magnetic_variation_deg").set(variation);
    metrics::gauge!("fuse1090_air_magnetic_variation_sigma_deg").set(sigma);
    metrics::gauge!("fuse1090_air_wind_spread_ms").set(w.scatter_ms());
    for km in 1..=15u32 {
        let (v, s) = w.wind_at(km as f64 * 1000.0);
        for (axis, name) in ["east", "north"].into_iter().enumerate() {
            let labels = [("alt_km", km.to_string()), ("component", name.to_string())];
            metrics::gauge!("fuse1090_air_wind_ms", &labels).set(v[axis]);
            metrics::gauge!("fuse1090_air_wind_sigma_ms", &labels).set(s[axis]);
        }
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
