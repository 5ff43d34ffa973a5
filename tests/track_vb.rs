//! Variational-Bayes measurement noise on the vb-noise scenario: a
//! transponder that reports NACp 9 (12.3 m per axis) while its real error
//! is that of NACp 6 (227 m). The noise scale of its ADS-B must grow
//! towards the real ratio ((227/12.25)^2 = 343) and the ADS-B track's NEES
//! must come back into the chi-square band once it has converged; without
//! VB it stays hopeless.

use fuse1090::config::Config;
use fuse1090::eval::montecarlo::run_in_memory;
use fuse1090::eval::{evaluate, Truth};
use fuse1090::sim::scenario::Scenario;
use fuse1090::track::Source;

mod common;

fn scenario() -> Scenario {
    Scenario::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios/vb-noise.toml"))
        .unwrap()
}

/// ADS-B track (RMSE, NEES over the whole run, NEES after the first 60 s
/// and its band from the spread between runs) over seeds, and the final VB
/// scales.
fn adsb_track(vb: bool, seeds: u64) -> (f64, f64, (f64, [f64; 2]), Vec<f64>) {
    let mut cfg = Config::default().core;
    cfg.track.vb = vb;
    cfg.publish_source_tracks = true;
    let (mut se, mut nees, mut n, mut scales) = (0.0, 0.0, 0usize, Vec::new());
    let mut late_runs = Vec::new();
    for seed in 1..=seeds {
        let mut s = scenario();
        s.seed = seed;
        let (mut cap, mut truth) = (Vec::new(), Vec::new());
        fuse1090::sim::simulate(&s, &mut cap, &mut truth).unwrap();
        let out = run_in_memory(&cap, &cfg).unwrap();
        let truth = Truth::read(truth.as_slice()).unwrap();
        let report = evaluate(&truth, out.as_slice()).unwrap();
        // Once the scale has had time to converge: the last 60 s.
        let late: String = String::from_utf8_lossy(&out)
            .lines()
            .filter(|l| {
                serde_json::from_str::<serde_json::Value>(l)
                    .is_ok_and(|v| v["t"].as_f64().unwrap_or(0.0) > s.start_unix + 60.0)
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
        let (core, _, _) = common::run_core(&cap, &cfg);
        scales.push(core.fuser().vb_scale(0x3C6DD4, Source::Adsb).unwrap());
    }
    (
        (se / n.max(1) as f64).sqrt(),
        nees / n.max(1) as f64,
        (
            fuse1090::eval::montecarlo::pooled_nees(&late_runs).expect("late estimates"),
            fuse1090::eval::montecarlo::runs_band(&late_runs, 2.0).expect("runs"),
        ),
        scales,
    )
}

/// Enough runs for the band from their spread to mean something.
const SEEDS: u64 = 30;

#[test]
fn vb_learns_an_overclaimed_nacp() {
    let (rmse_vb, nees_vb, (late_vb, band), scales) = adsb_track(true, SEEDS);
    let (rmse_plain, nees_plain, (late_plain, _), _) = adsb_track(false, SEEDS);
    let mut sorted = scales.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    eprintln!(
        "ADS-B track: VB {rmse_vb:.0} m NEES {nees_vb:.1}, after 60 s {late_vb:.2} (scale median {median:.0}, \
         real 343); without VB {rmse_plain:.0} m NEES {nees_plain:.1}, after 60 s {late_plain:.1}; band {band:?}"
    );
    // Converged, the track is consistent again: the pooled NEES of the last
    // 60 s against the band from the spread between runs (steps within a run
    // are correlated; the band of independent samples is far too narrow).
    assert!(band[0] <= late_vb && late_vb <= band[1], "VB NEES after convergence {late_vb}, band {band:?}");
    // Within a factor of two of the real ratio, 343 (the prior keeps a fifth
    // of the weight: about 240).
    assert!(median > 171.0 && median < 686.0, "scales {scales:?}");
    assert!(nees_plain > 50.0, "without VB the claim is believed: NEES {nees_plain}");
    assert!(nees_vb < nees_plain / 10.0, "VB NEES {nees_vb} vs {nees_plain}");
    assert!(rmse_vb < rmse_plain, "{rmse_vb} vs {rmse_plain}");
}
