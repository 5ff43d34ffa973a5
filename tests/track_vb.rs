//! Variational-Bayes measurement noise: a transponder that reports NACp 9
//! (12.3 m per axis) while its real error is that of NACp 6 (227 m). The
//! noise scale of its ADS-B must grow to the real ratio ((227/12.25)^2 =
//! 343) and the ADS-B track's NEES come back to the chi-square band once
//! it has converged; without VB it stays hopeless. Two flights: vb-noise
//! (the 1 Hz benchmark's, positions only) and vb-noise-real-rates
//! (positions and velocity at ~2 Hz, then a long straight).

use fuse1090::config::Config;
use fuse1090::eval::montecarlo::{pooled_nees, runs_band};
use fuse1090::eval::{evaluate, Truth};
use fuse1090::publish::json::write_event;
use fuse1090::sim::scenario::Scenario;
use fuse1090::track::Source;

mod common;

/// The ADS-B track over seeds.
struct Runs {
    rmse_m: f64,
    /// Pooled NEES over the whole run.
    nees: f64,
    /// Pooled NEES after `late_after_s`, and its band from the spread
    /// between runs (steps within a run are correlated; the band of
    /// independent samples is far too narrow).
    late: f64,
    late_band: [f64; 2],
    /// Final noise scales, sorted.
    scales: Vec<f64>,
}

impl Runs {
    fn median_scale(&self) -> f64 {
        self.scales[self.scales.len() / 2]
    }
}

fn adsb_track(scenario: &str, vb: bool, seeds: u64, late_after_s: f64) -> Runs {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios").join(scenario);
    let scenario = Scenario::load(&path).unwrap();
    let mut cfg = Config::default().core;
    cfg.track.vb = vb;
    cfg.publish_source_tracks = true;
    let (mut se, mut nees, mut n, mut scales) = (0.0, 0.0, 0usize, Vec::new());
    let mut late_runs = Vec::new();
    for seed in 1..=seeds {
        let mut s = scenario.clone();
        s.seed = seed;
        let (mut cap, mut truth) = (Vec::new(), Vec::new());
        fuse1090::sim::simulate(&s, &mut cap, &mut truth).unwrap();
        // One run gives both the records and the final scale.
        let (core, events, _) = common::run_core(&cap, &cfg);
        let mut out = Vec::new();
        for ev in &events {
            write_event(&mut out, ev, |i| core.receiver_id(i));
        }
        let truth = Truth::read(truth.as_slice()).unwrap();
        let report = evaluate(&truth, out.as_slice()).unwrap();
        let late: String = String::from_utf8_lossy(&out)
            .lines()
            .filter(|l| {
                serde_json::from_str::<serde_json::Value>(l)
                    .is_ok_and(|v| v["t"].as_f64().unwrap_or(0.0) > s.start_unix + late_after_s)
            })
            .map(|l| format!("{l}\n"))
            .collect();
        if let Some(r) =
            evaluate(&truth, late.as_bytes()).unwrap().overall.iter().find(|r| r.source == "adsb")
        {
            late_runs.push((r.nees.unwrap_or(0.0) * r.n as f64, r.n));
        }
        if let Some(r) = report.overall.iter().find(|r| r.source == "adsb") {
            se += r.h_rmse_m.powi(2) * r.n as f64;
            nees += r.nees.unwrap_or(0.0) * r.n as f64;
            n += r.n;
        }
        scales.push(core.fuser().vb_scale(0x3C6DD4, Source::Adsb).unwrap());
    }
    scales.sort_by(f64::total_cmp);
    Runs {
        rmse_m: (se / n.max(1) as f64).sqrt(),
        nees: nees / n.max(1) as f64,
        late: pooled_nees(&late_runs).expect("late estimates"),
        late_band: runs_band(&late_runs, 2.0).expect("runs"),
        scales,
    }
}

/// Enough runs for the band from their spread to mean something.
const SEEDS: u64 = 30;
const REAL_RATIO: f64 = 343.0;

fn report(what: &str, vb: &Runs, plain: &Runs) {
    eprintln!(
        "{what}: VB {:.0} m NEES {:.1}, late {:.2} in {:.2?} (scale median {:.0}, real {REAL_RATIO}); \
         without VB {:.0} m NEES {:.1}, late {:.1}",
        vb.rmse_m,
        vb.nees,
        vb.late,
        vb.late_band,
        vb.median_scale(),
        plain.rmse_m,
        plain.nees,
        plain.late
    );
}

/// Shared by both flights: the scale finds the real ratio within 10% (344
/// and 331; with ADS-B's prior as heavy as MLAT's, 310 and 307), and
/// without VB the claim is believed.
fn learns_the_ratio(vb: &Runs, plain: &Runs) {
    let m = vb.median_scale();
    assert!((0.9 * REAL_RATIO..1.1 * REAL_RATIO).contains(&m), "scales {:?}", vb.scales);
    assert!(plain.nees > 50.0, "without VB the claim is believed: NEES {}", plain.nees);
    assert!(vb.nees < plain.nees / 10.0, "VB NEES {} vs {}", vb.nees, plain.nees);
}

#[test]
fn vb_learns_an_overclaimed_nacp() {
    // The last 60 s: 20 s of manoeuvres, 40 s straight.
    let vb = adsb_track("vb-noise.toml", true, SEEDS, 60.0);
    let plain = adsb_track("vb-noise.toml", false, SEEDS, 60.0);
    report("1 Hz, positions only", &vb, &plain);
    learns_the_ratio(&vb, &plain);
    // Not overconfident once converged. It is conservative, below the band:
    // with positions this coarse and no velocity reports the likelihoods
    // cannot tell the models apart, and in straight flight the manoeuvre
    // models' share widens the covariance (the same flight with its true
    // noise claimed honestly: 1.6; here 1.38; docs/tracking.md).
    assert!(1.3 < vb.late && vb.late <= vb.late_band[1], "late NEES {} band {:?}", vb.late, vb.late_band);
    assert!(vb.rmse_m < plain.rmse_m / 2.0, "{} vs {}", vb.rmse_m, plain.rmse_m);
}

#[test]
fn vb_at_real_rates_widens_the_track_as_the_scale_grows() {
    // After 180 s: the last 120 s of the long straight.
    let vb = adsb_track("vb-noise-real-rates.toml", true, SEEDS, 180.0);
    let plain = adsb_track("vb-noise-real-rates.toml", false, SEEDS, 180.0);
    report("~2 Hz, positions and velocity", &vb, &plain);
    learns_the_ratio(&vb, &plain);
    // Converged, consistent: the covariance grew with the scale (without
    // that, velocity reports keep it at the claim's size, the positions'
    // gain stays small and the pooled NEES stays near 300).
    assert!(
        vb.late_band[0] <= vb.late && vb.late <= vb.late_band[1],
        "late NEES {} band {:?}",
        vb.late,
        vb.late_band
    );
    assert!(vb.rmse_m < plain.rmse_m / 3.0, "{} vs {}", vb.rmse_m, plain.rmse_m);
}
