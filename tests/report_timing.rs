//! Time of applicability of ADS-B reports from counter-timed receivers: once
//! such a receiver is synchronised with a GPS-timed one, its reports are
//! dated in GPS time instead of by their arrival at the server (which is
//! tens of milliseconds late, a bias of metres along the track).
//!
//! The 8-segment flight with one GPS-timed receiver and five beast12 ones,
//! a 40 ms network delay, and a near-perfect GNSS (1 m) so that a timing
//! bias stands out: the reports' along-track error against the truth at
//! their stated time must be centred on zero, not on -speed x delay.

use fuse1090::core::{CoreConfig, Dating, Event, PositionReport};
use fuse1090::eval::Truth;
use fuse1090::feed::capture::ClockKind;
use fuse1090::sim::scenario::Scenario;

mod common;

/// The 1 Hz fusion benchmark's flight, the scenario both tests change.
fn benchmark() -> Scenario {
    Scenario::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios/fusion-8seg-1hz.toml"),
    )
    .unwrap()
}

/// A report's along-track error (m): its offset from the truth at its stated
/// time, on the direction of motion; `None` where the truth does not reach.
fn along_track(truth: &Truth, p: &PositionReport) -> Option<f64> {
    let (a, b) = (truth.position("3C6DD4", p.t)?, truth.position("3C6DD4", p.t + 0.1)?);
    let d = common::en(a.0, a.1, p.lat, p.lon);
    let v = common::en(a.0, a.1, b.0, b.1);
    Some((d[0] * v[0] + d[1] * v[1]) / v[0].hypot(v[1]))
}

#[test]
fn counter_timed_reports_are_dated_in_gps_time() {
    let mut s = benchmark();
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
        gps += (p.dating == Dating::Gps) as usize;
        along.extend(along_track(&truth, p));
    }
    let mean = along.iter().sum::<f64>() / along.len() as f64;
    eprintln!("{} beast12 reports, {gps} dated in GPS time; mean along-track error {mean:.2} m", along.len());
    assert!(along.len() > 30);
    assert_eq!(gps, along.len(), "every synchronised report dated in GPS time");
    // Dated by arrival they would sit about 120 m/s x 40 ms = 4.8 m behind.
    assert!(mean.abs() < 1.0, "mean along-track error {mean} m");
}

/// A counter-timed receiver that cannot be synchronised (no ADS-B position
/// is taken for clock synchronisation here; on tma-busy it was a receiver
/// multilateration excluded) and whose copies arrive first: its reports can
/// only be dated by their arrival, 40 ms late. Once
/// its network delay is learnt from the transmissions GPS-timed receivers
/// also heard, they are dated by arrival less that delay, and their
/// along-track error is centred on zero again instead of on -speed x delay
/// (about -5 m).
#[test]
fn reports_dated_by_arrival_lose_the_learnt_network_delay() {
    let mut s = benchmark();
    for r in s.receiver.iter_mut() {
        r.delay_ms = 100.0;
    }
    let r = &mut s.receiver[0];
    (r.clock, r.delay_ms, r.delay_spread_ms) = (ClockKind::Beast12, 40.0, 5.0);
    s.aircraft[0].pos_sigma_m = Some(1.0);
    let (mut cap, mut truth) = (Vec::new(), Vec::new());
    fuse1090::sim::simulate(&s, &mut cap, &mut truth).unwrap();
    let truth = Truth::read(truth.as_slice()).unwrap();
    let mut cfg = CoreConfig::default();
    cfg.mlat.min_sync_nacp = 12;
    let (_, events, _) = common::run_core(&cap, &cfg);
    let (mut along, mut calibrated) = (Vec::new(), 0usize);
    for e in &events {
        let Event::Position(p) = e else { continue };
        if p.rx != 0 || p.t < s.start_unix + 20.0 {
            continue;
        }
        calibrated += matches!(p.dating, Dating::Calibrated(spread) if spread < 0.01) as usize;
        along.extend(along_track(&truth, p));
    }
    let mean = along.iter().sum::<f64>() / along.len() as f64;
    eprintln!("{} reports of the unsynchronised receiver, {calibrated} dated by its learnt delay; mean along-track error {mean:.2} m", along.len());
    assert!(along.len() > 30);
    assert_eq!(calibrated, along.len());
    assert!(mean.abs() < 1.0, "mean along-track error {mean} m");
}
