//! Aircraft heard by too few receivers for a fix (fixtures/scenarios/
//! fringe.toml, on a seed the file does not use): without the particle filter
//! the aircraft flying in from beyond the network have no track at all until
//! four receivers hear them; with it, once three hear one, its estimate is
//! published (flagged `sparse`) with a covariance that holds its error, and
//! the tracks made from fixes are the same as without.

mod common;

use fuse1090::core::CoreConfig;
use fuse1090::eval::montecarlo::run_in_memory;
use fuse1090::eval::{evaluate, Report, Truth};

fn run(capture: &[u8], truth: &Truth, sparse: bool) -> (Report, Vec<serde_json::Value>) {
    let mut cfg = CoreConfig::default();
    cfg.track.sparse.enabled = sparse;
    let out = run_in_memory(capture, &cfg).unwrap();
    let lines =
        std::str::from_utf8(&out).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    (evaluate(truth, out.as_slice()).unwrap(), lines)
}

#[test]
fn too_few_receivers_for_a_fix_still_give_an_honest_estimate() {
    let (capture, truth) = common::simulated("fringe", 65);
    let (with, lines) = run(&capture, &truth, true);
    let (without, _) = run(&capture, &truth, false);
    let row = |r: &Report, source: &str| r.overall.iter().find(|x| x.source == source).cloned();
    // The fix-based tracks are untouched.
    let (a, b) = (row(&with, "fused").unwrap(), row(&without, "fused").unwrap());
    assert_eq!((a.n, a.h_rmse_m), (b.n, b.h_rmse_m));
    assert!(row(&without, "fused:sparse").is_none());
    // Inbound aircraft (3B0000-3B0003) have no fix-based track.
    let inbound = |hex: &str| hex < "3B0004";
    assert!(without.aircraft.iter().all(|r| !inbound(&r.hex) || r.source != "fused"));
    let sparse = row(&with, "fused:sparse").expect("sparse estimates");
    let nees = sparse.nees.unwrap();
    println!(
        "sparse estimates: {} of {} aircraft, RMSE {:.0} m, NEES {:.2} (band {:?}), continuity {:.3}, within 1 km {:.3}",
        sparse.n,
        sparse.aircraft,
        sparse.h_rmse_m,
        nees,
        sparse.nees_band,
        sparse.continuity,
        sparse.continuity_1km
    );
    assert!(sparse.n >= 30, "{} sparse estimates", sparse.n);
    // Some of the time the aircraft had no estimate at all before is now covered within 1 km.
    assert!(sparse.continuity_1km > 0.02, "{}", sparse.continuity_1km);
    let band = sparse.nees_band.unwrap();
    assert!(nees > band[0] * 0.75 && nees < band[1] * 1.25, "NEES {nees} against {band:?}");
    for v in lines.iter().filter(|v| v["sparse"] == true) {
        assert!(inbound(v["hex"].as_str().unwrap()), "{v}");
        let c = &v["cov_en"];
        let (a, b, d) = (c[0][0].as_f64().unwrap(), c[0][1].as_f64().unwrap(), c[1][1].as_f64().unwrap());
        assert!(a > 0.0 && d > 0.0 && a * d - b * b > 0.0, "{v}");
        // Published only when one-peaked and within 3 km (1 sigma).
        assert!(a.max(d).sqrt() <= 3_000.0 * 1.01, "{v}");
    }
}
