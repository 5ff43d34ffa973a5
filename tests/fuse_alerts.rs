//! Alerts against truth: conflict prediction on a scripted encounter, and
//! the conformance monitor on spoofers (2 km and 300 m offsets in a small
//! world, and the two spoofers of tma-busy among 148 honest aircraft).

mod common;

use common::scenario;
use fuse1090::config::Config;
use fuse1090::eval::montecarlo::run_in_memory;
use fuse1090::sim::scenario::Scenario;
use serde_json::Value;

/// Simulates and runs the default pipeline: (track stream, truth), as written.
fn simulate_and_run(s: &Scenario) -> (Vec<u8>, Vec<u8>) {
    let (capture, truth) = common::simulate(s);
    (run_in_memory(&capture, &Config::default().core).unwrap(), truth)
}

fn parse(b: &[u8]) -> Vec<Value> {
    String::from_utf8_lossy(b).lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// Simulates and runs the default pipeline: (records, truth lines).
fn run(s: &Scenario) -> (Vec<Value>, Vec<Value>) {
    let (out, truth) = simulate_and_run(s);
    (parse(&out), parse(&truth))
}

fn alerts<'a>(records: &'a [Value], kind: &str) -> Vec<&'a Value> {
    records.iter().filter(|r| r["type"] == "alert" && r["kind"] == kind).collect()
}

#[test]
fn head_on_at_fl350_alerts_48_to_35_s_ahead_and_a_5_nm_pass_stays_quiet() {
    let s = scenario("encounter");
    let (records, _) = run(&s);
    let cpa = s.start_unix + 100.0;
    let conflicts = alerts(&records, "conflict");
    let started: Vec<_> = conflicts.iter().filter(|a| a["active"] == true).collect();
    assert_eq!(started.len(), 1, "{conflicts:?}");
    let a = started[0];
    assert_eq!(a["pair"].as_array().unwrap().len(), 2);
    let mut pair: Vec<&str> = a["pair"].as_array().unwrap().iter().map(|h| h.as_str().unwrap()).collect();
    pair.sort();
    assert_eq!(pair, ["4B0001", "4B0002"]);
    let ahead = cpa - a["t"].as_f64().unwrap();
    assert!((35.0..=48.0).contains(&ahead), "alert {ahead:.1} s before closest approach");
    // While in conflict both tracks go out at the densest period.
    let t0 = a["t"].as_f64().unwrap();
    let dense = records
        .iter()
        .filter(|r| r["type"] == "track" && r["hex"] == "4B0001")
        .filter(|r| (t0 + 2.0..cpa).contains(&r["t"].as_f64().unwrap()))
        .all(|r| r["period_s"] == 0.6);
    assert!(dense);
    let quiet =
        records.iter().filter(|r| r["type"] == "track" && r["hex"] == "4B0003").all(|r| r["period_s"] == 0.8);
    assert!(quiet, "NACp 9: 0.8 s outside conflicts");
}

/// The head-on pair of the encounter passing just inside the 1 NM
/// miss-distance limit (1,840 m apart): the predicted miss, from tracks
/// with metres of noise, crosses the limit back and forth; the alert is
/// raised once and held until the aircraft have passed, not raised and
/// cleared with each crossing.
#[test]
fn a_pair_passing_at_the_miss_limit_raises_one_alert() {
    let mut s = scenario("encounter");
    s.aircraft[1].start.lat += 1_840.0 / 111_195.0;
    let (records, _) = run(&s);
    let conflicts = alerts(&records, "conflict");
    let pair = |a: &&&Value| a["pair"].as_array().unwrap().iter().any(|h| h == "4B0002");
    let raised = conflicts.iter().filter(pair).filter(|a| a["active"] == true).count();
    assert_eq!(raised, 1, "{conflicts:?}");
}

/// The 8-segment world with its aircraft broadcasting positions offset by `offset`.
fn spoofed(offset: Option<[f64; 2]>) -> (Vec<Value>, f64) {
    let mut s = scenario("fusion-8seg-1hz");
    s.aircraft[0].spoof_offset_m = offset;
    let (records, _) = run(&s);
    let first_fix = records.iter().find(|r| r["type"] == "mlat").unwrap()["t"].as_f64().unwrap();
    (records, first_fix)
}

#[test]
fn spoofers_2_km_and_300_m_off_are_flagged_within_seconds_and_kept_out() {
    for offset in [[2000.0, 0.0], [0.0, 300.0]] {
        let (records, first_fix) = spoofed(Some(offset));
        let flags = alerts(&records, "adsb_suspect");
        let first = flags.first().unwrap_or_else(|| panic!("{offset:?}: not flagged"));
        assert_eq!(first["suspect"], true);
        let delay = first["t"].as_f64().unwrap() - first_fix;
        assert!(delay < 10.0, "{offset:?}: flagged {delay:.1} s after the first fix");
        // Published tracks after the flag say so, and follow the truth
        // (MLAT), not the broadcast.
        let t_flag = first["t"].as_f64().unwrap();
        let after: Vec<_> = records
            .iter()
            .filter(|r| r["type"] == "track" && r["t"].as_f64().unwrap() > t_flag + 2.0)
            .collect();
        assert!(!after.is_empty() && after.iter().all(|r| r["adsb_suspect"] == true));
        assert!(after.iter().all(|r| r["sources"].as_array().unwrap().contains(&Value::from("mlat"))));
    }
    let (honest, _) = spoofed(None);
    assert!(alerts(&honest, "adsb_suspect").is_empty());
}

/// Heard by three receivers only (three sites and the altitude: two
/// solutions, never a fix), a spoofer is caught by its time differences
/// against the position it reports, and an honest aircraft is not.
#[test]
fn spoofers_heard_by_three_receivers_only_are_flagged_by_their_time_differences() {
    let three = |offset: Option<[f64; 2]>| {
        let mut s = scenario("fusion-8seg-1hz");
        s.receiver.truncate(3);
        s.aircraft[0].spoof_offset_m = offset;
        run(&s).0
    };
    for offset in [[2000.0, 0.0], [0.0, -500.0]] {
        let records = three(Some(offset));
        assert!(!records.iter().any(|r| r["type"] == "mlat"), "three sites gave a fix");
        let flags = alerts(&records, "adsb_suspect");
        let first = flags.first().unwrap_or_else(|| panic!("{offset:?}: not flagged"));
        assert_eq!(first["suspect"], true);
        // No fix, so no offset to report.
        assert!(first.get("offset_m").is_none(), "{first}");
        let start = records.iter().find_map(|r| r["t"].as_f64()).unwrap();
        let delay = first["t"].as_f64().unwrap() - start;
        assert!(delay < 10.0, "{offset:?}: flagged {delay:.1} s into the run");
        assert!(flags.iter().all(|f| f["suspect"] == true), "{offset:?}: cleared: {flags:?}");
    }
    let honest = three(None);
    assert!(alerts(&honest, "adsb_suspect").is_empty(), "{:?}", alerts(&honest, "adsb_suspect"));
}

#[test]
fn tma_busy_both_spoofers_flagged_and_no_honest_aircraft() {
    let mut s = scenario("tma-busy");
    s.duration_s = 60.0;
    let (records, truth) = run(&s);
    let spoofers: Vec<&str> =
        truth.iter().filter(|t| t["type"] == "spoof").map(|t| t["hex"].as_str().unwrap()).collect();
    assert_eq!(spoofers.len(), 2);
    let flags = alerts(&records, "adsb_suspect");
    for f in &flags {
        assert!(spoofers.contains(&f["hex"].as_str().unwrap()), "honest aircraft flagged: {f}");
    }
    for hex in &spoofers {
        let first_fix = records
            .iter()
            .find(|r| r["type"] == "mlat" && r["hex"] == *hex)
            .unwrap_or_else(|| panic!("{hex}: never multilaterated"))["t"]
            .as_f64()
            .unwrap();
        let flag = flags.iter().find(|f| f["hex"] == *hex && f["suspect"] == true);
        let t = flag.unwrap_or_else(|| panic!("{hex}: not flagged"))["t"].as_f64().unwrap();
        assert!(t - first_fix < 10.0, "{hex}: flagged {:.1} s after its first fix", t - first_fix);
    }
}

/// tma-busy on seed 1, the whole ten minutes: its 300 m spoofer flies to the
/// edge of coverage, where fixes of hundreds of metres hold 300 m. Both
/// spoofers stay flagged to the end, and the 300 m one's fused track stays
/// consistent with the truth (it was cleared after 170 s, its spoofed
/// positions then fused: 185 m RMS, NEES 377).
#[test]
fn a_spoofer_at_the_edge_of_coverage_stays_flagged() {
    let mut s = scenario("tma-busy");
    s.seed = 1;
    let (out, truth) = simulate_and_run(&s);
    let truth = fuse1090::eval::Truth::read(truth.as_slice()).unwrap();
    let records = parse(&out);
    let flags = alerts(&records, "adsb_suspect");
    for hex in ["390094", "390095"] {
        let changes: Vec<bool> =
            flags.iter().filter(|f| f["hex"] == hex).map(|f| f["suspect"].as_bool().unwrap()).collect();
        assert_eq!(changes, [true], "{hex}: flag changes");
    }
    let report = fuse1090::eval::evaluate(&truth, out.as_slice()).unwrap();
    let row = report.aircraft.iter().find(|r| r.source == "fused" && r.hex == "390095").unwrap();
    let nees = row.nees.unwrap();
    assert!(nees < 3.0 && row.h_rmse_m < 130.0, "fused: {:.1} m, NEES {nees:.2}", row.h_rmse_m);
}
