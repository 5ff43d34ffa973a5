//! Time of applicability of ADS-B reports from counter-timed receivers: once
//! such a receiver is synchronised with a GPS-timed one, its reports are
//! dated in GPS time instead of by their arrival at the server (which is
//! tens of milliseconds late, a bias of metres along the track).
//!
//! The 8-segment flight with one GPS-timed receiver and five beast12 ones,
//! a 40 ms network delay, and a near-perfect GNSS (1 m) so that a timing
//! bias stands out: the reports' along-track error against the truth at
//! their stated time must be centred on zero, not on -speed x delay.

use fuse1090::core::{CoreConfig, Event};
use fuse1090::eval::Truth;
use fuse1090::feed::capture::ClockKind;
use fuse1090::sim::scenario::Scenario;

mod common;

#[test]
fn counter_timed_reports_are_dated_in_gps_time() {
    let mut s = Scenario::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios/fusion-8seg-1hz.toml"),
    )
    .unwrap();
    for r in s.receiver.iter_mut().skip(1) {
        r.clock = ClockKind::Beast12;
    }
    s.aircraft[0].pos_sigma_m = Some(1.0);
    let (mut cap, mut truth) = (Vec::new(), Vec::new());
    fuse1090::sim::simulate(&s, &mut cap, &mut truth).unwrap();
    let truth = Truth::read(truth.as_slice()).unwrap();
    let (_, events, rxs) = common::run_core(&cap, &CoreConfig::default());
    let (mut along, mut gps) = (Vec::new(), 0usize);
    for e in &events {
        let Event::Position(p) = e else { continue };
        if rxs[p.rx].clock != ClockKind::Beast12 || p.t < s.start_unix + 20.0 {
            continue;
        }
        gps += p.gps_timed as usize;
        let (Some(a), Some(b)) = (truth.position("3C6DD4", p.t), truth.position("3C6DD4", p.t + 0.1)) else {
            continue;
        };
        // Along-track error: the offset from the truth, on the direction of motion.
        let d = common::en(a.0, a.1, p.lat, p.lon);
        let v = common::en(a.0, a.1, b.0, b.1);
        let n = v[0].hypot(v[1]);
        along.push((d[0] * v[0] + d[1] * v[1]) / n);
    }
    let mean = along.iter().sum::<f64>() / along.len() as f64;
    eprintln!("{} beast12 reports, {gps} dated in GPS time; mean along-track error {mean:.2} m", along.len());
    assert!(along.len() > 30);
    assert_eq!(gps, along.len(), "every synchronised report dated in GPS time");
    // Dated by arrival they would sit about 120 m/s x 40 ms = 4.8 m behind.
    assert!(mean.abs() < 1.0, "mean along-track error {mean} m");
}
