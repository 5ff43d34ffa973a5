//! Aircraft heard by too few receivers for a fix (fixtures/scenarios/
//! fringe.toml, on a seed the file does not use): without the particle filter
//! the aircraft flying in from beyond the network have no track at all until
//! four receivers hear them; with it, once three hear one, its estimate is
//! published (flagged `sparse`) with a covariance that holds its error
//! (NEES in its band); once
//! its cloud has one mode the Gaussian tracks take over, closer to the truth
//! than the cloud alone and still honest; and the tracks of the aircraft
//! flying out are the same as without.

mod common;

use fuse1090::core::{Core, CoreConfig};
use fuse1090::eval::{evaluate, Report, Truth};
use fuse1090::feed::capture::CaptureReader;
use fuse1090::fuse::SparseStats;
use fuse1090::publish::json::write_event;

fn run(
    capture: &[u8],
    truth: &Truth,
    sparse: bool,
    handover_after: u32,
) -> (Report, Vec<serde_json::Value>, SparseStats) {
    let mut cfg = CoreConfig::default();
    cfg.track.sparse.enabled = sparse;
    cfg.track.sparse.handover_after = handover_after;
    let mut core = Core::new(&cfg);
    let mut reader = CaptureReader::new(capture, "capture");
    let mut out = Vec::new();
    let mut drain = |core: &mut Core| {
        while let Some(ev) = core.poll_event() {
            write_event(&mut out, &ev, |i| core.receiver_id(i));
        }
    };
    while let Some(rec) = reader.next_record().unwrap() {
        core.handle_record(rec);
        drain(&mut core);
    }
    core.finish();
    drain(&mut core);
    let stats = core.fuser().stats().sparse;
    let lines =
        std::str::from_utf8(&out).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    (evaluate(truth, out.as_slice()).unwrap(), lines, stats)
}

#[test]
fn too_few_receivers_for_a_fix_still_give_an_honest_estimate() {
    let (capture, truth) = common::simulated("fringe", 65);
    let (with, lines, stats) = run(&capture, &truth, true, 3);
    let (cloud_only, _, cloud_stats) = run(&capture, &truth, true, 0);
    let (without, _, _) = run(&capture, &truth, false, 3);
    let row = |r: &Report, source: &str| r.overall.iter().find(|x| x.source == source).cloned();
    // The tracks of the aircraft flying out (3B0004-3B0007) are untouched.
    let outbound = |r: &Report| -> Vec<(String, usize, f64)> {
        let rows = r.aircraft.iter().filter(|x| x.source == "fused" && x.hex.as_str() >= "3B0004");
        rows.map(|x| (x.hex.clone(), x.n, x.h_rmse_m)).collect()
    };
    assert_eq!(outbound(&with), outbound(&without));
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
    // The Gaussian tracks took over from a one-peaked cloud, and did better
    // than the cloud alone (which gave its aircraft up only at a fix).
    let cloud = row(&cloud_only, "fused:sparse").expect("the cloud's estimates");
    println!(
        "the cloud alone: {} estimates, RMSE {:.0} m, NEES {:.2}; handed over: {stats:?}",
        cloud.n,
        cloud.h_rmse_m,
        cloud.nees.unwrap()
    );
    assert!(stats.handed_over_one_mode >= 1 && cloud_stats.handed_over_one_mode == 0, "{stats:?}");
    assert!(sparse.h_rmse_m < 0.7 * cloud.h_rmse_m, "{} against {}", sparse.h_rmse_m, cloud.h_rmse_m);
    // Some of the time the aircraft had no estimate at all before is now covered within 1 km.
    assert!(sparse.continuity_1km > 0.02, "{}", sparse.continuity_1km);
    // Honest, the cloud and the tracks after it alike: the receivers'
    // persistent timing errors counted as often as each remembers them
    // (counted once for every transmission, both were far too unsure).
    for (what, r) in [("with the tracks", &sparse), ("the cloud alone", &cloud)] {
        let (nees, band) = (r.nees.unwrap(), r.nees_band.unwrap());
        assert!(nees > band[0] && nees < band[1], "{what}: NEES {nees} against {band:?}");
    }
    for v in lines.iter().filter(|v| v["sparse"] == true) {
        assert!(inbound(v["hex"].as_str().unwrap()), "{v}");
        let c = &v["cov_en"];
        let (a, b, d) = (c[0][0].as_f64().unwrap(), c[0][1].as_f64().unwrap(), c[1][1].as_f64().unwrap());
        assert!(a > 0.0 && d > 0.0 && a * d - b * b > 0.0, "{v}");
        // Published only when one-peaked and within 3 km (1 sigma), the
        // cloud's; the tracks that take over only grow surer after.
        assert!(a.max(d).sqrt() <= 3_000.0 * 1.01, "{v}");
    }
}
