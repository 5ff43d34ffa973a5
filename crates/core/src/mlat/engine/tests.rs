//! The engine's unit tests: fixes, ambiguity, bad input, calibration, outliers, sites.

use super::*;
use crate::feed::capture::ClockKind;
use crate::feed::RawFrame;
use crate::mlat::group::{Copy, GroupInfo};
use crate::mlat::state::LearntState;

mod timing;

fn receivers() -> Vec<ReceiverDecl> {
    gps_receivers(&[(48.80, 2.30), (48.95, 2.60), (48.60, 2.70), (48.55, 2.10), (49.05, 2.05)])
}

/// GPS-timed receivers at these (lat, lon), 100 m up, named r0, r1, ...
fn gps_receivers(sites: &[(f64, f64)]) -> Vec<ReceiverDecl> {
    (sites.iter().enumerate())
        .map(|(i, &(lat, lon))| ReceiverDecl {
            id: format!("r{i}"),
            lat,
            lon,
            alt: 100.0,
            clock: ClockKind::Gps,
        })
        .collect()
}

/// A group as GPS-timed receivers would report a DF4 from `target` at `t` (Unix s).
/// Shifts a copy's timestamp by `dt` seconds.
fn delay(c: &mut Copy, dt: f64) {
    let ns = (c.timestamp >> 30) * 1_000_000_000 + (c.timestamp & 0x3FFF_FFFF) + (dt * 1e9).round() as u64;
    c.timestamp = ((ns / 1_000_000_000) << 30) | (ns % 1_000_000_000);
}

fn group(rxs: &[ReceiverDecl], target: [f64; 3], t: f64) -> Group {
    let copies = rxs
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let p = geodetic_to_ecef(r.lat, r.lon, r.alt);
            // From the second of the day: Unix time in an f64 has 240 ns steps.
            let toa = t.rem_euclid(86_400.0) + ecef_distance(p, target) / C_AIR;
            Copy { rx: i, timestamp: ClockKind::gps_timestamp(toa), arrival: t + 0.1, signal: 100 }
        })
        .collect();
    let frame = RawFrame::new(&crate::modes::encode::surveillance_reply(4, 0, 0x1C38, 0xABCDEF, None), 0, 0)
        .expect("frame");
    Group {
        frame,
        first_arrival: t + 0.1,
        emission: f64::NAN,
        copies,
        info: GroupInfo {
            decoded: true,
            df: 4,
            addr: 0xABCDEF,
            addr_known: true,
            alt_baro_ft: Some(30_000),
            ..Default::default()
        },
    }
}

fn engine() -> (Mlat, Vec<ReceiverDecl>) {
    let mut m = Mlat::new(MlatConfig::default());
    let rxs = receivers();
    for r in &rxs {
        m.add_receiver(r);
    }
    (m, rxs)
}

/// [`engine`] with a sixth receiver, counter-timed ("c", index 5), and
/// its ECEF position.
fn engine_with_counter() -> (Mlat, Vec<ReceiverDecl>, [f64; 3]) {
    let (mut m, mut rxs) = engine();
    let counter =
        ReceiverDecl { id: "c".into(), lat: 48.7, lon: 2.45, alt: 100.0, clock: ClockKind::Beast12 };
    m.add_receiver(&counter);
    rxs.push(counter.clone());
    (m, rxs, geodetic_to_ecef(counter.lat, counter.lon, counter.alt))
}

/// The counter's copy of a transmission from `target` at `t` (Unix s): its
/// count started 100 s before `t0`, and reads `step` s off.
fn counter_copy(c_ecef: [f64; 3], target: [f64; 3], t: f64, t0: f64, step: f64) -> Copy {
    let toa = t - t0 + 100.0 + ecef_distance(c_ecef, target) / C_AIR + step;
    Copy { rx: 5, timestamp: (toa * 12e6).round() as u64, arrival: t + 0.1, signal: 90 }
}

/// Transmission `k` (every half second from `t0`) of traffic the five
/// GPS-timed receivers and the counter all hear: many aircraft (each judged
/// as a sync source on its own), every other transmission an ADS-B
/// position. With its time.
fn counter_traffic(rxs: &[ReceiverDecl], c_ecef: [f64; 3], k: usize, t0: f64, step: f64) -> (Group, f64) {
    let t = t0 + k as f64 * 0.5;
    let (lat, lon) = (48.5 + 0.02 * (k % 23) as f64, 2.1 + 0.03 * (k % 19) as f64);
    let target = geodetic_to_ecef(lat, lon, 30_000.0 * FT_TO_M);
    let mut g = group(&rxs[..5], target, t);
    g.copies.push(counter_copy(c_ecef, target, t, t0, step));
    g.info.addr = 0x400000 + (k % 40) as u32;
    if k % 2 == 0 {
        g.info.adsb_ecef = Some(target);
        g.info.adsb_sigma_m = 5.0;
    }
    (g, t)
}

#[test]
fn a_clean_group_gives_an_accurate_fix() {
    let (mut m, rxs) = engine();
    let target = geodetic_to_ecef(48.75, 2.40, 30_000.0 * FT_TO_M);
    let f = m.on_group(&group(&rxs, target, 1_700_000_000.0), 1_700_000_000.2).fix().expect("fix");
    assert!(crate::geo::distance_m(f.lat, f.lon, 48.75, 2.40) < 1.0, "{f:?}");
    assert!((f.t - 1_700_000_000.0).abs() < 1e-6, "emission time from GPS: {}", f.t);
    assert_eq!(f.receivers.len(), 5);
}

#[test]
fn the_aircraft_s_own_gnss_baro_difference_sets_the_altitude_constraint() {
    // Flying 200 ft (61 m) above its barometric altitude, outside the
    // receivers' polygon, four receivers and the altitude: taken as its
    // barometric altitude, the height error moves the fix sideways.
    let (lat, lon) = (49.10, 2.80);
    let target = geodetic_to_ecef(lat, lon, (30_000 + 200) as f64 * FT_TO_M);
    let miss = |diff: Option<i32>| {
        let (mut m, rxs) = engine();
        let t = 1_700_000_000.0;
        let mut g = group(&rxs[..4], target, t);
        g.info.baro_correction = diff.map(BaroCorrection::own);
        let f = m.on_group(&g, t + 0.2).fix().expect("fix");
        (crate::geo::distance_m(f.lat, f.lon, lat, lon), f.cov_en[0][0] + f.cov_en[1][1])
    };
    let (with, with_var) = miss(Some(200));
    let (without, without_var) = miss(None);
    assert!(with < 2.0, "{with} m off with the difference");
    assert!(without > 100.0, "{without} m off without it");
    assert!(with_var < without_var, "the known difference is the tighter constraint");
}

/// Three receivers and the altitude are as many measurements as
/// unknowns: two solutions fit exactly. Without an earlier fix the group
/// gives none (its time differences go to a track, which knows where the
/// aircraft is); after one, it gives the solution near it, and an
/// address nothing verified still none.
#[test]
fn an_exactly_determined_group_needs_an_earlier_fix_to_choose_its_solution() {
    let (mut m, rxs) = engine();
    let target = geodetic_to_ecef(48.75, 2.40, 30_000.0 * FT_TO_M);
    let t = 1_700_000_000.0;
    // No fix, but the time differences for a track that knows where it is.
    match m.on_group(&group(&rxs[..3], target, t), t + 0.2) {
        GroupOutcome::Tdoa(g) => assert_eq!(g.sites.len(), 3),
        other => panic!("{other:?}"),
    }
    assert_eq!(m.stats.rejects.get(Reject::Ambiguous), 1);
    m.on_group(&group(&rxs, target, t + 1.0), t + 1.2).fix().expect("a redundant fix");
    let f = m.on_group(&group(&rxs[..3], target, t + 2.0), t + 2.2).fix().expect("chosen by the earlier fix");
    assert_eq!(f.dof, 0);
    assert!(crate::geo::distance_m(f.lat, f.lon, 48.75, 2.40) < 1.0, "{f:?}");
    let mut g = group(&rxs[..3], target, t + 3.0);
    g.info.addr_known = false;
    assert!(m.on_group(&g, t + 3.2).fix().is_none());
    assert_eq!((m.stats.unverified_address, m.stats.fixes), (1, 2));
}

/// Three receivers nearly in a line (the other two only for a redundant
/// fix), an aircraft flying across the line between two of them: its
/// exactly determined groups have a second solution mirrored across the
/// line, which meets it at the crossing and parts from it after. No group
/// whose other solution the aircraft could also have reached since the
/// earlier fix is a fix (their time differences go to the track); taken
/// as the solution nearer the earlier fix, the fixes went on along the
/// mirror after the crossing, kilometres off.
#[test]
fn an_exactly_determined_group_whose_other_solution_is_within_reach_is_no_fix() {
    let mut m = Mlat::new(MlatConfig::default());
    let rxs = gps_receivers(&[(49.0, 2.0), (49.0, 2.6), (49.0, 3.2), (49.4, 2.6), (48.6, 2.6)]);
    for r in &rxs {
        m.add_receiver(r);
    }
    let t0 = 1_700_000_000.0;
    // North at 200 m/s from 3 km south of the line, between r1 and r2.
    let at = |s: f64| crate::geo::displace(48.973, 2.9, 30_000.0 * FT_TO_M, [0.0, 200.0 * s, 0.0]);
    let ecef = |s: f64| {
        let (lat, lon, h) = at(s);
        geodetic_to_ecef(lat, lon, h)
    };
    m.on_group(&group(&rxs, ecef(0.0), t0), t0 + 0.2).fix().expect("a redundant fix");
    let (mut fixes, mut tdoa) = (0, 0);
    for k in 1..=30 {
        let t = t0 + k as f64;
        match m.on_group(&group(&rxs[..3], ecef(k as f64), t), t + 0.2) {
            GroupOutcome::Fix(f) => {
                let (lat, lon, _) = at(k as f64);
                let off = crate::geo::distance_m(f.lat, f.lon, lat, lon);
                assert!(off < 100.0, "{k} s: a fix {off:.0} m off");
                fixes += 1;
            }
            GroupOutcome::Tdoa(_) => tdoa += 1,
            // Too close to where the solutions meet for any fix.
            GroupOutcome::NoFix(NoFix::Rejected(Reject::Gdop)) => {}
            other => panic!("{k} s: {other:?}"),
        }
    }
    assert!(tdoa >= 10, "{fixes} fixes, {tdoa} time differences");
}

/// One degree of freedom and residuals past the plain quantile: an
/// aircraft's first fix may be the equations' other solution, so it is
/// refused; once an earlier fix anchors the aircraft, the same group is
/// a fix whose covariance grows with its residuals.
#[test]
fn a_first_fix_with_one_spare_measurement_must_fit_plainly() {
    let (mut m, rxs) = engine();
    let target = geodetic_to_ecef(48.75, 2.40, 30_000.0 * FT_TO_M);
    let t = 1_700_000_000.0;
    // One copy 600 ns late: past the plain quantile, within the doubt
    // of receivers that have learnt nothing yet.
    let late = |t: f64| {
        let mut g = group(&rxs[..4], target, t);
        delay(&mut g.copies[1], 0.6e-6);
        g
    };
    assert!(m.on_group(&late(t), t + 0.2).fix().is_none());
    assert_eq!(m.stats.rejects.get(Reject::Residual), 1);
    m.on_group(&group(&rxs, target, t + 1.0), t + 1.2).fix().expect("a redundant fix");
    let f = m.on_group(&late(t + 2.0), t + 2.2).fix().expect("anchored by the earlier fix");
    let plain = super::super::solver::chi2_quantile(1, 0.999);
    eprintln!("chi2 {} against {plain}", f.chi2);
    assert!(f.dof == 1 && f.chi2 > plain, "{f:?}");
}

#[test]
fn bad_input_is_dropped_and_counted_never_a_fix() {
    let (mut m, rxs) = engine();
    let target = geodetic_to_ecef(48.75, 2.40, 9_000.0);
    let t = 1_700_000_000.0;
    // Unknown receiver, zero and MLAT-magic timestamps: dropped, counted.
    let mut g = group(&rxs, target, t);
    g.copies[0].rx = 99;
    g.copies[1].timestamp = 0;
    g.copies[2].timestamp = crate::feed::MLAT_MAGIC_TIMESTAMP;
    assert!(m.on_group(&g, t).fix().is_none());
    assert_eq!((m.stats.unknown_receiver, m.stats.no_timing), (1, 2));
    // Inconsistent geometry: one copy 3 microseconds late is rejected, not fixed.
    let mut g = group(&rxs, target, t + 1.0);
    g.copies[3].timestamp = ClockKind::gps_timestamp(ClockKind::gps_unix(g.copies[3].timestamp, t) + 3e-6);
    assert!(m.on_group(&g, t + 1.0).fix().is_none());
    assert_eq!(m.stats.rejects.get(Reject::Residual), 1);
    // An address nothing verified, exactly determined: no fix (with no
    // earlier fix to choose its solution, it is ambiguous first).
    let mut g = group(&rxs[..3], target, t + 2.0);
    g.info.addr_known = false;
    assert!(m.on_group(&g, t + 2.0).fix().is_none());
    assert_eq!(m.stats.rejects.get(Reject::Ambiguous), 1);
    // Two copies only: too few.
    let g = group(&rxs[..2], target, t + 3.0);
    assert!(m.on_group(&g, t + 3.0).fix().is_none());
    assert!(m.stats.too_few_receivers >= 1);
    assert_eq!(m.stats.fixes, 0);
}

#[test]
fn one_bad_copy_among_many_is_dropped_and_the_rest_fixed() {
    let mut m = Mlat::new(MlatConfig::default());
    let mut rxs = receivers();
    for (i, &(lat, lon)) in [(49.2, 2.3), (48.4, 2.4)].iter().enumerate() {
        rxs.push(ReceiverDecl { id: format!("x{i}"), lat, lon, alt: 100.0, clock: ClockKind::Gps });
    }
    for r in &rxs {
        m.add_receiver(r);
    }
    let target = geodetic_to_ecef(48.75, 2.40, 30_000.0 * FT_TO_M);
    let t = 1_700_000_000.0;
    let mut g = group(&rxs, target, t);
    delay(&mut g.copies[3], 3e-6);
    let f = m.on_group(&g, t).fix().expect("fix from the six good copies");
    assert_eq!(m.stats.outliers_dropped, 1);
    assert!(!f.receivers.contains(&3), "the bad copy is not in the fix");
    assert!(crate::geo::distance_m(f.lat, f.lon, 48.75, 2.40) < 5.0);
}

/// The engine of `engine()` plus a sixth receiver `north_m` north of r0.
fn with_neighbour(north_m: f64) -> (Mlat, Vec<ReceiverDecl>) {
    let (mut m, mut rxs) = engine();
    let twin = ReceiverDecl {
        id: "twin".into(),
        lat: rxs[0].lat + north_m / 111_200.0,
        lon: rxs[0].lon,
        alt: 100.0,
        clock: ClockKind::Gps,
    };
    m.add_receiver(&twin);
    rxs.push(twin);
    (m, rxs)
}

#[test]
fn receivers_at_one_site_count_once() {
    let (mut m, rxs) = with_neighbour(5.0);
    let target = geodetic_to_ecef(48.75, 2.40, 30_000.0 * FT_TO_M);
    let f = m.on_group(&group(&rxs, target, 1_700_000_000.0), 1_700_000_000.2).fix().expect("fix");
    assert_eq!(m.stats.close_receivers, 1);
    assert_eq!(f.receivers.len(), 6, "both receivers of the site are credited");
    assert_eq!(f.dof, 2, "but they make one measurement: 5 sites + altitude - 4 unknowns");
}

#[test]
fn receivers_hundreds_of_metres_apart_are_two_sites() {
    // 700 m apart: their times differ by up to 2.3 us, which averaging
    // at one of them would turn into hundreds of metres of error.
    let (mut m, rxs) = with_neighbour(700.0);
    let target = geodetic_to_ecef(48.75, 2.40, 30_000.0 * FT_TO_M);
    let f = m.on_group(&group(&rxs, target, 1_700_000_000.0), 1_700_000_000.2).fix().expect("fix");
    assert_eq!(m.stats.close_receivers, 0);
    assert_eq!(f.dof, 3, "6 sites + altitude - 4 unknowns");
    assert!(crate::geo::distance_m(f.lat, f.lon, 48.75, 2.40) < 5.0);
}

/// A counter-timed receiver whose timestamps go wild for 100 s (off by
/// microseconds each, a failing oscillator) is excluded while its pairs
/// fail, keeps synchronising while out, and is readmitted once its sync
/// holds again: exclusion is never for good. (A single step of its
/// clock is not exclusion: its pairs restart, see the sync's tests.)
#[test]
fn an_excluded_receiver_is_readmitted_when_its_sync_holds_again() {
    let (mut m, rxs, c_ecef) = engine_with_counter();
    let t0 = 1_700_000_000.0;
    let (mut excluded_at, mut readmitted_at) = (None, None);
    let mut last_fix_used_it = false;
    for k in 0..1200 {
        let step = if (200..400).contains(&k) { ((k * 7919) % 13) as f64 * 1e-6 - 6e-6 } else { 0.0 };
        let (g, t) = counter_traffic(&rxs, c_ecef, k, t0, step);
        let fix = m.on_group(&g, t + 0.2);
        let out = m.sync.health[5].excluded;
        if out && excluded_at.is_none() {
            excluded_at = Some(k);
        }
        if !out && excluded_at.is_some() && readmitted_at.is_none() {
            readmitted_at = Some(k);
        }
        if let Some(f) = fix.fix() {
            last_fix_used_it = f.receivers.contains(&5);
        }
    }
    let out = excluded_at.expect("excluded after the step");
    assert!((200..260).contains(&out), "excluded at {out}");
    let back = readmitted_at.expect("readmitted");
    assert!(back < out + 400, "readmitted at {back}");
    assert!(m.stats.excluded_receiver_copies > 0);
    assert!(last_fix_used_it, "back in the fixes");
}

/// A counter-timed receiver's time reaches the network through its pair
/// filters, whose estimate's error stays for many transmissions: its time
/// differences say how much of its sigma that error is, for the tracks to
/// count it as persistent (see the fuser's tests).
#[test]
fn a_counter_s_time_differences_say_its_sync_variance() {
    let (mut m, rxs, c_ecef) = engine_with_counter();
    let t0 = 1_700_000_000.0;
    for k in 0..200 {
        let (g, t) = counter_traffic(&rxs, c_ecef, k, t0, 0.0);
        m.on_group(&g, t + 0.2);
    }
    // Two GPS-timed receivers and the counter, an aircraft never fixed.
    let t = t0 + 100.0;
    let target = geodetic_to_ecef(48.75, 2.40, 30_000.0 * FT_TO_M);
    let mut g = group(&rxs[..2], target, t);
    g.copies.push(counter_copy(c_ecef, target, t, t0, 0.0));
    let GroupOutcome::Tdoa(g) = m.on_group(&g, t + 0.2) else {
        panic!("time differences expected");
    };
    assert_eq!(g.sites.len(), 3);
    let rx = &m.rxs[5];
    let own = rx.sigma().powi(2) + rx.surveyed_var_s2;
    let sync = g.sync_var[2];
    assert!(sync.sqrt() > 1e-9, "the counter's sync sigma: {} ns", sync.sqrt() * 1e9);
    assert!((g.sites[2].2.powi(2) - own - sync).abs() < 1e-3 * own, "its sigma is its own and its sync's");
    assert_eq!(&g.sync_var[..2], &[0.0, 0.0], "GPS-timed receivers need no sync");
}

#[test]
fn aircraft_are_forgotten_once_unheard_for_their_time_to_live() {
    let (mut m, rxs) = engine();
    let target = geodetic_to_ecef(48.75, 2.40, 30_000.0 * FT_TO_M);
    let t = 1_700_000_000.0;
    for k in 0..50u32 {
        let mut g = group(&rxs, target, t + k as f64);
        g.info.addr = 0x100000 + k;
        m.on_group(&g, t + k as f64);
    }
    assert_eq!(m.aircraft_count(), 50);
    let ttl = 300.0;
    m.prune(t + 49.0 + ttl - 9.5, ttl);
    assert_eq!(m.aircraft_count(), 10, "the last ten heard within the time to live");
    m.aircraft.get_mut(&0x100031).unwrap().sync_banned = true;
    m.prune(t + 49.0 + ttl + 1.0, ttl);
    assert_eq!(m.aircraft_count(), 1, "a banned sync source is remembered longer");
    m.prune(t + 49.0 + BANNED_TTL_S + 1.0, ttl);
    assert_eq!(m.aircraft_count(), 0);
}

/// What one engine learnt, saved and taken up by another (a restart),
/// gives the same receiver reports; a receiver since moved is not
/// taken up.
#[test]
fn learnt_state_survives_a_restart_but_not_a_move() {
    let (mut m, rxs) = engine();
    let t0 = 1_700_000_000.0;
    for k in 0..300 {
        let (lat, lon) = (48.5 + 0.03 * (k % 17) as f64, 2.1 + 0.04 * (k % 13) as f64);
        let mut g = group(&rxs, geodetic_to_ecef(lat, lon, 30_000.0 * FT_TO_M), t0 + k as f64);
        delay(&mut g.copies[2], 120e-9);
        m.on_group(&g, t0 + k as f64 + 0.2);
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("state.json");
    m.learnt(t0).save(&path).unwrap();
    let state = LearntState::load(&path).unwrap().unwrap();
    let (mut fresh, _) = engine();
    assert_eq!(fresh.restore(&state), 5);
    // The same timing (to the JSON's last bit; the outlier counts are this run's).
    let close = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) => (a - b).abs() <= 1e-9 * a.abs().max(1.0),
        (a, b) => a == b,
    };
    for rx in 0..5 {
        let (a, b) = (fresh.receiver_report(rx, t0), m.receiver_report(rx, t0));
        assert_eq!(a.state, b.state, "receiver {rx}");
        assert!(close(a.sigma_ns, b.sigma_ns) && close(a.offset_ns, b.offset_ns), "{a:?} {b:?}");
    }
    assert!(m.receiver_report(2, t0).sigma_ns.is_some());
    // Moved 50 m: learnt afresh.
    let mut moved = Mlat::new(MlatConfig::default());
    for (k, r) in rxs.iter().enumerate() {
        let mut d = r.clone();
        if k == 2 {
            d.lat += 50.0 / 111_200.0;
        }
        moved.add_receiver(&d);
    }
    assert_eq!(moved.restore(&state), 4);
    assert_eq!(moved.receiver_report(2, t0).sigma_ns, None);
    // No file yet, and a file of another version.
    assert_eq!(LearntState::load(&dir.path().join("none.json")), Ok(None));
    std::fs::write(&path, r#"{"version":99,"saved_unix":0,"receivers":[]}"#).unwrap();
    assert!(LearntState::load(&path).unwrap_err().contains("version 99"));
}

/// The `k`th of a stream of ADS-B aircraft's transmissions, one a second
/// from `t0`, from all around the receivers: what their surveys learn from.
fn adsb_group_around(rxs: &[ReceiverDecl], k: usize, t0: f64) -> Group {
    let (lat, lon) = (48.45 + 0.04 * (k % 17) as f64, 1.95 + 0.05 * (k % 19) as f64);
    let target = geodetic_to_ecef(lat, lon, 30_000.0 * FT_TO_M);
    let mut g = group(rxs, target, t0 + k as f64);
    g.info.adsb_ecef = Some(target);
    g.info.adsb_sigma_m = 10.0;
    g
}

/// Workers of a cluster each see part of the ADS-B traffic; the clock
/// service surveys the receivers from all of it, and every worker places a
/// misplaced one as one node would (here r2, 200 m east of where it is
/// declared): left out, or with `self_survey` used where it is.
#[test]
fn workers_place_a_misplaced_receiver_by_the_services_survey() {
    for self_survey in [false, true] {
        let declared = receivers();
        let mut actual = declared.clone();
        actual[2].lon += 200.0 / (111_320.0 * 48.6f64.to_radians().cos());
        let mut workers: Vec<Mlat> = (0..2)
            .map(|_| {
                let mut m = Mlat::new(MlatConfig { self_survey, ..MlatConfig::default() });
                for r in &declared {
                    m.add_receiver(r);
                }
                m.share_sync();
                m
            })
            .collect();
        let mut service =
            crate::mlat::shared::SharedClock::new(ClockSync::new(PairParams::default()), self_survey);
        for r in &declared {
            service.add_receiver(r.clock, &r.id, TimingModel::prior(50e-9));
        }
        let t0 = 1_700_000_000.0;
        for k in 0..1200 {
            let g = adsb_group_around(&actual, k, t0);
            let w = &mut workers[k % 2];
            w.on_group(&g, t0 + k as f64 + 0.2);
            for note in w.take_sync_notes() {
                service.apply(&note);
            }
            if k % 50 == 49 {
                let snapshot = service.snapshot(t0 + k as f64);
                for w in &mut workers {
                    w.load_sync(&snapshot);
                }
            }
        }
        let t = t0 + 1200.0;
        let surveyed = service.receiver_reports(t)[2].position_offset_en_m;
        let [e, n] = surveyed.expect("surveyed by the service");
        assert!((e - 200.0).abs() < 10.0 && n.abs() < 10.0, "surveyed {e:.1} east, {n:.1} north");
        for (k, w) in workers.iter().enumerate() {
            let report = w.receiver_report(2, t);
            let want = (!self_survey).then_some(crate::mlat::Exclusion::Misplaced);
            assert_eq!(report.reason, want, "worker {k}: {report:?}");
            assert_eq!(report.position_offset_en_m, surveyed, "worker {k}");
            // Used, it is where the survey puts it.
            let moved = ecef_distance(w.rxs[2].ecef, w.rxs[2].declared_ecef);
            assert!(if self_survey { (moved - 200.0).abs() < 10.0 } else { moved == 0.0 }, "{moved} m");
            assert_eq!(w.receiver_report(1, t).reason, None, "worker {k}");
        }
    }
}

/// A copy whose time is milliseconds off the others' (more than light takes
/// across any receiver's range) is no position error: kept out of every
/// receiver's survey, and counted, so the honest ones stay where declared.
#[test]
fn a_copy_milliseconds_off_is_kept_out_of_the_surveys() {
    let (mut m, rxs) = engine();
    let t0 = 1_700_000_000.0;
    for k in 0..600 {
        let mut g = adsb_group_around(&rxs, k, t0);
        if k % 10 == 0 {
            delay(&mut g.copies[3], 5e-3);
        }
        m.on_group(&g, t0 + k as f64 + 0.2);
    }
    assert_eq!(m.stats.survey_gross, 60);
    for rx in 0..rxs.len() {
        let r = m.receiver_report(rx, t0 + 600.0);
        let [e, n] = r.position_offset_en_m.expect("surveyed");
        assert!(e.hypot(n) < 5.0, "rx {rx}: {e:.1} east, {n:.1} north");
        assert_eq!(r.reason, None, "rx {rx}");
    }
}
