use super::*;

/// Aircraft ABC123 at 45 N, 1,000 m, every 0.1 s from t = 1000 for
/// `steps`, its longitude from 5 E growing by `lon_step` a step.
fn truth(steps: usize, lon_step: f64) -> Truth {
    let mut text = String::new();
    for k in 0..=steps {
        text += &format!(
            "{{\"type\":\"truth\",\"hex\":\"ABC123\",\"t\":{},\"lat\":45.0,\"lon\":{},\"alt_m\":1000.0}}\n",
            1000.0 + k as f64 * 0.1,
            5.0 + k as f64 * lon_step
        );
    }
    Truth::read(text.as_bytes()).unwrap()
}

#[test]
fn the_fused_track_is_compared_over_the_span_all_three_tracks_cover() {
    let truth = truth(200, 0.0);
    let north = |m: f64| 45.0 + m / 111_131.7;
    let mut recs = String::new();
    let mut track = |source: &str, t: f64, off_m: f64| {
        recs += &format!(
            "{{\"type\":\"track\",\"source\":\"{source}\",\"hex\":\"ABC123\",\"t\":{t},\"lat\":{},\"lon\":5.0}}\n",
            north(off_m)
        );
    };
    // The fused track starts a second early on a fix 300 m off, then 5 m;
    // the ADS-B track 8 m, the MLAT track 50 m, both from t = 1001.
    track("fused", 1000.0, 300.0);
    for k in 1..=10 {
        let t = 1000.0 + k as f64;
        track("fused", t, 5.0);
        track("adsb", t, 8.0);
        track("mlat", t, 50.0);
    }
    let r = evaluate(&truth, recs.as_bytes()).unwrap();
    let rmse = |s: &str| r.aircraft.iter().find(|row| row.source == s).unwrap().h_rmse_m;
    assert!(rmse("fused") > rmse("adsb"), "over their lives the early fix decides");
    let c = r.fusion.clone().expect("all three tracks");
    assert_eq!((c.aircraft, c.fused_best), (1, 1), "{:?}", c.others);
    assert!(r.to_string().contains("lowest RMSE for 1 of 1 aircraft"));
    // Without an MLAT track there is nothing to compare.
    let adsb_only: String = recs.lines().filter(|l| !l.contains("mlat")).map(|l| format!("{l}\n")).collect();
    assert!(evaluate(&truth, adsb_only.as_bytes()).unwrap().fusion.is_none());
}

#[test]
fn band_matches_the_chi_square_table() {
    // One NEES value of 2 dof: the 2.5% and 97.5% points are 0.0506 and 7.378.
    let b = nees_band(1, 2.0);
    assert!((b[0] - 0.0506).abs() < 1e-3 && (b[1] - 7.378).abs() < 1e-3, "{b:?}");
    // Many: the band tightens around 2.
    let b = nees_band(10_000, 2.0);
    assert!(b[0] > 1.9 && b[1] < 2.1);
}

#[test]
fn errors_nees_and_continuity_against_a_known_offset() {
    let truth = truth(100, 1e-4);
    // Records 100 m north of the truth, claiming a 100 m sigma: NEES = 1 each.
    let dlat = 100.0 / 111_131.7;
    let mut recs = String::new();
    for k in 0..=10 {
        let t = 1000.0 + k as f64;
        recs += &format!(
            "{{\"type\":\"position\",\"hex\":\"abc123\",\"t\":{t},\"lat\":{},\"lon\":{},\"alt_m\":1010.0,\
             \"cov_en\":[[10000,0],[0,10000]]}}\n",
            45.0 + dlat,
            5.0 + k as f64 * 1e-3
        );
    }
    recs += "{\"type\":\"position\",\"hex\":\"FFFFFF\",\"t\":1000,\"lat\":0,\"lon\":0}\n";
    let r = evaluate(&truth, recs.as_bytes()).unwrap();
    let row = &r.overall[0];
    assert_eq!((row.source.as_str(), row.n), ("adsb-report", 11));
    assert!((row.h_rmse_m - 100.0).abs() < 0.5, "{}", row.h_rmse_m);
    assert!((row.v_rmse_m.unwrap() - 10.0).abs() < 1e-6);
    assert!((row.nees.unwrap() - 1.0).abs() < 0.01);
    assert!((row.continuity - 1.0).abs() < 1e-9);
    // 100 m off: all within 1 km.
    assert!((row.continuity_1km - 1.0).abs() < 1e-9);
    assert_eq!(r.unknown_records, 1);
}

/// A track's velocity against the truth's (interpolated between its
/// points); records without one, and a truth without one, count nothing.
#[test]
fn velocity_errors_against_the_truths_velocity() {
    let mut text = String::new();
    for k in 0..=10 {
        text += &format!(
            "{{\"type\":\"truth\",\"hex\":\"ABC123\",\"t\":{},\"lat\":45.0,\"lon\":5.0,\"alt_m\":1000.0,\
             \"vel_enu\":[{},0.0,0.0]}}\n",
            1000.0 + k as f64,
            100.0 + k as f64 * 10.0
        );
    }
    let truth = Truth::read(text.as_bytes()).unwrap();
    // At 1004.5 the truth flies east at 145 m/s: reported 148 east, 4 north, 5 m/s off.
    let rec = |vel: &str| {
        format!("{{\"type\":\"track\",\"hex\":\"ABC123\",\"t\":1004.5,\"lat\":45.0,\"lon\":5.0{vel},\"source\":\"fused\"}}\n")
    };
    let recs = rec(",\"vel_enu\":[148.0,4.0,0.0]") + &rec("");
    let row = evaluate(&truth, recs.as_bytes()).unwrap().overall[0].clone();
    assert_eq!(row.n, 2);
    assert!((row.vel_rmse_ms.unwrap() - 5.0).abs() < 1e-9, "{:?}", row.vel_rmse_ms);
    let without = self::truth(100, 1e-4);
    let row = evaluate(&without, rec(",\"vel_enu\":[148.0,4.0,0.0]").as_bytes()).unwrap().overall[0].clone();
    assert_eq!(row.vel_rmse_ms, None);
}
