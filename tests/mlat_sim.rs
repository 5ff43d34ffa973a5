//! Multilateration against the simulator's truth: clock synchronisation of
//! free-running beast12 receivers from ADS-B, fix accuracy against the
//! Cramér-Rao bound of each fix's geometry, covariance consistency, and
//! robustness to a receiver declared 300 m off and to a receiver restart.

mod common;

use std::collections::HashMap;

use common::{en, fix_median_error, mahalanobis2, run_core};
use fuse1090::core::{Core, CoreConfig, Event};
use fuse1090::eval::Truth;
use fuse1090::feed::capture::{CaptureReader, CaptureRecord, ClockKind};
use fuse1090::geo::geodetic_to_ecef;
use fuse1090::mlat::solver::crb_en;
use fuse1090::mlat::RxState;
use fuse1090::sim::scenario::Scenario;

#[test]
fn beast12_clocks_synchronise_and_fixes_reach_the_cramer_rao_bound() {
    // The fusion-8seg flight on beast12 counters, with the 83 ns jitter.
    let mut scenario = common::scenario("fusion-8seg-selfsync");
    for r in &mut scenario.receiver {
        r.jitter_ns = 83.0;
    }
    let (capture, truth_bytes) = common::simulate(&scenario);
    let truth = Truth::read(&truth_bytes[..]).unwrap();

    // Drive the core by hand to look at the pairs 30 s in.
    let mut reader = CaptureReader::new(&capture[..], "capture");
    // The fusion scenarios multilaterate every transmission, ADS-B or not.
    let mut cfg = CoreConfig::default();
    cfg.mlat.adsb_interval_s = 0.0;
    let mut core = Core::new(&cfg);
    let mut events = Vec::new();
    let mut rxs = Vec::new();
    let mut checked_at_30 = false;
    while let Some(rec) = reader.next_record().unwrap() {
        match rec {
            CaptureRecord::Receiver(d) => {
                rxs.push(d.clone());
                core.handle_receiver(d);
            }
            CaptureRecord::Frame(f) => {
                if !checked_at_30 && f.arrival >= scenario.start_unix + 30.0 {
                    checked_at_30 = true;
                    let sync = &core.mlat().sync;
                    let valid = sync.pairs().filter(|(_, p)| p.valid(f.arrival, &sync.params)).count();
                    assert_eq!(valid, 15, "all 15 pairs of 6 receivers synchronised within 30 s");
                }
                core.handle_frame(f.arrival, f.rx, &f.frame);
                events.extend(std::iter::from_fn(|| core.poll_event()));
            }
        }
    }
    core.finish();
    events.extend(std::iter::from_fn(|| core.poll_event()));
    let sync = &core.mlat().sync;
    for (&(i, j), p) in sync.pairs() {
        let ratio = p.residual_rms() / p.expected_rms();
        eprintln!(
            "pair {}-{}: drift {:+.2} ppm, residual {:.0} ns, expected {:.0} ns, restarts {}",
            rxs[i].id,
            rxs[j].id,
            p.drift() * 1e6,
            p.residual_rms() * 1e9,
            p.expected_rms() * 1e9,
            p.restarts
        );
        assert!(ratio <= 1.2, "pair {i}-{j}: residuals {ratio:.2}x what the noise model predicts");
        assert_eq!(p.restarts, 0);
    }
    // Every fix against the truth and against its geometry's bound (true
    // timing noise: 83 ns jitter and 12 MHz quantisation).
    let sigma_true = (83e-9f64.powi(2) + (1.0 / 12e6f64).powi(2) / 12.0).sqrt();
    let positions: HashMap<&str, [f64; 3]> =
        rxs.iter().map(|r| (r.id.as_str(), geodetic_to_ecef(r.lat, r.lon, r.alt))).collect();
    let (mut se, mut crb_trace, mut nees, mut n) = (0.0, 0.0, 0.0, 0);
    let ids: Vec<String> = rxs.iter().map(|r| r.id.clone()).collect();
    // Accuracy once synchronised (the first 30 s are the convergence above).
    for e in &events {
        let Event::Mlat(f) = e else { continue };
        // The one aircraft is every clock's only reference: all of every
        // fix's synchronisation is its own.
        assert!(f.self_sync_share > 0.99, "{}", f.self_sync_share);
        if f.t < scenario.start_unix + 30.0 {
            continue;
        }
        n += 1;
        let err = row_error(&truth, f);
        se += err[0] * err[0] + err[1] * err[1];
        nees += mahalanobis2(err, f.cov_en);
        let pos: Vec<[f64; 3]> = f.receivers.iter().map(|&r| positions[ids[r].as_str()]).collect();
        let sig = vec![sigma_true; pos.len()];
        let (la, lo, h) = truth.position(&format!("{:06X}", f.addr), f.t).unwrap();
        let tp = geodetic_to_ecef(la, lo, h);
        let c = crb_en(&pos, &sig, Some(75.0), tp).unwrap();
        crb_trace += c[0][0] + c[1][1];
    }
    let rmse = (se / n as f64).sqrt();
    let crb = (crb_trace / n as f64).sqrt();
    let nees = nees / n as f64;
    eprintln!(
        "{n} fixes: RMSE {rmse:.2} m, Cramer-Rao {crb:.2} m (ratio {:.3}), mean NEES {nees:.2}",
        rmse / crb
    );
    assert!(n >= 300, "{n} fixes");
    let stats = &core.mlat().stats;
    assert_eq!(stats.self_synced_fixes, stats.fixes, "every fix counted as self-synchronised");
    assert!(rmse / crb <= 1.15, "RMSE {rmse} vs CRB {crb}");
    let band = fuse1090::eval::nees_band(n, 2.0);
    // Never over-confident; slightly conservative is tolerated (the sync
    // noise model overestimates the ADS-B position term a little).
    assert!(nees <= band[1] && nees >= band[0] * 0.85, "NEES {nees} vs {band:?}");
}

/// East/north error of a fix against the truth interpolated at its time.
fn row_error(truth: &Truth, f: &fuse1090::mlat::MlatFix) -> [f64; 2] {
    let p = truth.position(&format!("{:06X}", f.addr), f.t).expect("truth covers the fix");
    en(p.0, p.1, f.lat, f.lon)
}

/// tma-busy's receivers (rx05 declared 300 m off), none restarting, with
/// fewer aircraft for a shorter time.
fn tma_busy_cut(duration_s: f64, aircraft: usize, mode_s_only: usize, spoofers: usize) -> Scenario {
    let mut s = common::scenario("tma-busy");
    s.duration_s = duration_s;
    let t = &mut s.traffic[0];
    (t.count, t.mode_s_only, t.spoofers) = (aircraft, mode_s_only, spoofers);
    for r in &mut s.receiver {
        r.resets_s.clear();
    }
    s
}

/// The scenario with no receiver's link delaying frames in bursts.
fn without_delay_bursts(mut s: Scenario) -> Scenario {
    for r in &mut s.receiver {
        r.burst_per_min = 0.0;
    }
    s
}

#[test]
fn a_misplaced_counter_is_surveyed_and_left_out_and_a_restart_does_not_break_mlat() {
    // 40 aircraft for 150 s, two of them spoofers (2 km and 300 m off: the
    // last two); rx08 restarts at 60 s.
    let mut s = without_delay_bursts(tma_busy_cut(150.0, 40, 10, 2));
    s.receiver[7].resets_s = vec![60.0];
    let (capture, truth_bytes) = common::simulate(&s);
    let truth = Truth::read(&truth_bytes[..]).unwrap();
    let (core, events, rxs) = run_core(&capture, &CoreConfig::default());
    let mlat = core.mlat();
    let health = &mlat.sync.health;
    assert!(health[7].clock_resets >= 1, "rx08's restart is seen in its timestamps");
    eprintln!(
        "health: {:?}",
        health.iter().map(|h| (h.outlier_rate * 100.0).round() / 100.0).collect::<Vec<_>>()
    );
    assert_eq!(rxs[4].id, "rx05");
    eprintln!("{}", mlat.receivers_line(0.0, &|k| rxs[k].id.clone()));
    // The counter-timed receiver declared 300 m off is found where it is
    // (its clock pairs run on the network's time, so they do not absorb its
    // position error) and left out of the fixes for it; no other receiver
    // is thought misplaced.
    let end = s.start_unix + s.duration_s;
    for (k, t) in truth.receivers.iter().enumerate() {
        let r = mlat.receiver_report(k, end);
        let [te, tn] = t.position_offset_en_m;
        let ([e, n], sigma) = (r.position_offset_en_m.expect("surveyed"), r.position_offset_sigma_m.unwrap());
        eprintln!("{}: found {e:+.1},{n:+.1} m +-{sigma:.1}, true {te:+.0},{tn:+.0}", t.id);
        assert!((e - te).hypot(n - tn) < 30.0, "{}: found {e:+.1},{n:+.1} m", t.id);
        let misplaced = r.reason == Some(fuse1090::mlat::Exclusion::Misplaced);
        assert_eq!(misplaced, k == 4, "{}: {r:?}", t.id);
    }
    for (k, h) in health.iter().enumerate() {
        if k != 4 {
            assert!(!h.excluded, "{} wrongly excluded", rxs[k].id);
        }
    }
    // MLAT goes on: fixes after the restart use rx08 again and stay accurate.
    let mut late_with_rx08 = 0;
    let mut errs = Vec::new();
    // Heights of the Mode S-only aircraft's fixes (their altitude replies
    // made heights with the region's GNSS-baro difference: 45 m here).
    let mut mode_s_dh = Vec::new();
    for e in &events {
        let Event::Mlat(f) = e else { continue };
        if f.t > s.start_unix + 100.0 && f.receivers.contains(&7) {
            late_with_rx08 += 1;
        }
        if let Some(p) = truth.position(&format!("{:06X}", f.addr), f.t) {
            let d = en(p.0, p.1, f.lat, f.lon);
            errs.push(d[0].hypot(d[1]));
            if f.addr - s.traffic[0].first_hex < 10 && f.altitude_used && f.t > s.start_unix + 30.0 {
                mode_s_dh.push((f.alt_m - p.2).abs());
            }
        }
    }
    mode_s_dh.sort_by(f64::total_cmp);
    let dh = mode_s_dh[mode_s_dh.len() / 2];
    eprintln!("Mode S-only fixes: median height error {dh:.1} m over {}", mode_s_dh.len());
    assert!(dh < 15.0, "Mode S-only fixes' median height error {dh} m");
    errs.sort_by(f64::total_cmp);
    let median = errs[errs.len() / 2];
    eprintln!(
        "{} fixes, median error {median:.1} m, {late_with_rx08} late fixes with rx08; {:?}",
        errs.len(),
        mlat.stats
    );
    assert!(late_with_rx08 > 100);
    assert!(median < 60.0, "median {median}");
    // Forty aircraft to synchronise on: hardly any fix rests on its own
    // aircraft's ADS-B.
    assert!(mlat.stats.self_synced_fixes * 100 < mlat.stats.fixes, "{:?}", mlat.stats);
    // The spoofers' positions disagree with the timing and stop being sync
    // sources (refused by the clock synchronisation's own check, or flagged
    // first by the conformance monitor, which keeps them out); no honest
    // aircraft is refused either way.
    let first = s.traffic[0].first_hex;
    let rates: Vec<(u32, f64)> =
        (0..40).filter_map(|i| mlat.sync_nis(first + i).map(|r| (i, (r * 100.0).round() / 100.0))).collect();
    eprintln!("sync source mean NIS: {rates:?}");
    let refused: Vec<u32> =
        (0..40).map(|i| first + i).filter(|&a| mlat.sync_banned(a) || core.is_suspect(a)).collect();
    assert_eq!(refused, vec![first + 38, first + 39], "sync sources refused");
}

/// Receivers whose links delay their frames by 0.8 s in bursts (far past
/// the 0.5 s group wait), one GPS-timed and one a free-running counter:
/// their late copies are recognised by when they were sent and not decoded
/// again. Before, each started a transmission of its own: on tma-busy 6%
/// more position reports than position frames heard (152,976 against
/// 144,001 distinct), every one of them a measurement its aircraft's tracks
/// took twice.
#[test]
fn late_copies_of_a_delayed_link_are_not_decoded_again() {
    let mut s = tma_busy_cut(120.0, 30, 5, 0);
    for (id, clock) in [("rx10", ClockKind::Gps), ("rx11", ClockKind::Beast12)] {
        let r = s.receiver.iter_mut().find(|r| r.id == id).unwrap();
        assert_eq!(r.clock, clock);
        (r.burst_per_min, r.burst_s, r.burst_ms) = (6.0, 2.0, 800.0);
    }
    let (capture, _) = common::simulate(&s);
    // Every airborne position transmission heard, by its bytes (a moving
    // aircraft's CPR bytes never repeat within the run).
    let mut heard = std::collections::HashSet::new();
    let mut reader = CaptureReader::new(&capture[..], "capture");
    while let Some(rec) = reader.next_record().unwrap() {
        if let CaptureRecord::Frame(f) = rec {
            let b = f.frame.bytes();
            if b.len() == 14 && b[0] >> 3 == 17 && (9..=18).contains(&(b[4] >> 3)) {
                heard.insert(b.to_vec());
            }
        }
    }
    let (core, events, _) = run_core(&capture, &CoreConfig::default());
    let reports = events.iter().filter(|e| matches!(e, Event::Position(_))).count();
    let late = core.stats().late_copies;
    eprintln!(
        "{reports} position reports of {} position transmissions heard; {late} late copies",
        heard.len()
    );
    assert!(late > 5000, "the bursts deliver late copies: {late}");
    let mut by_rx: Vec<&str> = core.late_copies().iter().map(|&(id, _)| id).collect();
    by_rx.sort();
    assert_eq!(by_rx, ["rx10", "rx11"], "only the bursty links deliver late copies");
    assert!(reports <= heard.len(), "a transmission reported twice: {reports} of {}", heard.len());
    // Nothing lost with them: only the first positions of each aircraft
    // (waiting for a CPR pair) go unreported.
    assert!(reports as f64 >= 0.985 * heard.len() as f64, "{reports} of {}", heard.len());
}

/// A counter-timed receiver whose timestamps step by 2 s (a glitch, not a
/// restart: under the 5 s that restarts its clock): its pairs see it fail,
/// start again, and it is back in the fixes within a minute; the aircraft
/// are not blamed. (Its pairs' failures were once counted against every
/// receiver in them, which excluded it for minutes; before that, for good.)
#[test]
fn a_receiver_whose_timestamps_step_is_resynchronised_and_stays_in_use() {
    use fuse1090::feed::capture::CaptureWriter;
    let s = without_delay_bursts(tma_busy_cut(300.0, 40, 10, 0));
    let (capture, _) = common::simulate(&s);
    // rx02 (a beast12 counter) steps by 2 s at 60 s.
    let step_at = s.start_unix + 60.0;
    let mut reader = CaptureReader::new(&capture[..], "capture");
    let mut w = CaptureWriter::new(Vec::new(), "stepped").unwrap();
    while let Some(rec) = reader.next_record().unwrap() {
        match rec {
            CaptureRecord::Receiver(d) => {
                w.receiver(&d).unwrap();
            }
            CaptureRecord::Frame(mut f) => {
                if f.rx == 1 && f.arrival >= step_at && f.frame.has_timing() {
                    f.frame.timestamp += 24_000_000;
                }
                w.frame(f.arrival, f.rx, &f.frame).unwrap();
            }
        }
    }
    let stepped = w.into_inner();
    assert_eq!(reader.receivers()[1].clock, ClockKind::Beast12);
    let (core, events, _) = run_core(&stepped, &CoreConfig::default());
    let h = core.mlat().sync.health[1];
    eprintln!("rx02 after the step: {h:?}; banned sync sources {}", core.mlat().stats.sync_banned_aircraft);
    assert!(h.sync_outliers >= 1, "the step went unseen: {h:?}");
    let restarted: u64 =
        (core.mlat().sync.pairs()).filter(|((i, j), _)| *i == 1 || *j == 1).map(|(_, p)| p.restarts).sum();
    assert!(restarted >= 1, "rx02's pairs did not start again");
    // Its pairs' outliers are the receiver's fault, not the aircraft's.
    assert_eq!(core.mlat().stats.sync_banned_aircraft, 0, "honest aircraft banned as sync sources");
    assert!(!h.excluded, "still excluded at the end: {h:?}");
    let fixes_with_it = |from: f64, to: f64| {
        (events.iter())
            .filter_map(|e| if let Event::Mlat(f) = e { Some(f) } else { None })
            .filter(|f| (s.start_unix + from..s.start_unix + to).contains(&f.t) && f.receivers.contains(&1))
            .count()
    };
    let (before, after) = (fixes_with_it(0.0, 60.0), fixes_with_it(120.0, 180.0));
    assert!(after * 2 > before, "rx02 in {before} fixes before the step and {after} after it");
    // The track stream's receiver records: every receiver once a minute and
    // at the end; rx02's say it was out for a while and is back.
    let records: Vec<&fuse1090::mlat::ReceiverReport> =
        events.iter().filter_map(|e| if let Event::Receiver(r) = e { Some(&**r) } else { None }).collect();
    // At 60, 120, 180 and 240 s (and at 300 s if the data reaches it by a
    // second's sweep) and at the end, for 12 receivers.
    assert!(records.len() % 12 == 0 && (5..=6).contains(&(records.len() / 12)), "{} records", records.len());
    let rx02: Vec<RxState> = records.iter().filter(|r| r.rx == 1).map(|r| r.state).collect();
    assert!(rx02.iter().all(|s| *s == RxState::Ok), "{rx02:?}");
    let last = records.iter().rev().find(|r| r.rx == 1).unwrap();
    assert!(last.sigma_ns.is_some_and(|s| s > 0.0) && last.offset_ns.is_none(), "{last:?}");
}

/// A counter-timed receiver declared 300 m off (tma-busy's rx05), with
/// `self_survey`: used where the traffic says it is, its learnt sigma that
/// of an honest counter, and the fixes' median error below that of the
/// run that leaves it out.
#[test]
fn self_survey_moves_a_misplaced_counter_where_it_is() {
    let s = without_delay_bursts(tma_busy_cut(300.0, 40, 10, 0));
    let (capture, truth_bytes) = common::simulate(&s);
    let truth = Truth::read(&truth_bytes[..]).unwrap();
    let run = |self_survey: bool| {
        let mut cfg = CoreConfig::default();
        cfg.mlat.self_survey = self_survey;
        let (core, events, rxs) = run_core(&capture, &cfg);
        assert_eq!(rxs[4].id, "rx05");
        let r = core.mlat().receiver_report(4, s.start_unix + s.duration_s);
        (r, core.mlat().timing(4).sigma(), fix_median_error(&events, &truth))
    };
    let (left_out, _, declared) = run(false);
    let (used, sigma, surveyed) = run(true);
    eprintln!(
        "rx05: {used:?}, sigma {:.0} ns; fixes' median {declared:.1} m left out, {surveyed:.1} m surveyed",
        sigma * 1e9
    );
    assert_eq!(left_out.reason, Some(fuse1090::mlat::Exclusion::Misplaced));
    assert_eq!((used.state, used.reason), (RxState::Ok, None));
    let ([e, n], [te, tn]) = (used.position_offset_en_m.unwrap(), truth.receivers[4].position_offset_en_m);
    assert!((e - te).hypot(n - tn) < 30.0, "found {e:+.1},{n:+.1} m, true {te:+.0},{tn:+.0}");
    // Its jitter is 83 ns: a position error still in its copies would show
    // as hundreds.
    assert!(sigma < 150e-9, "rx05 learnt {:.0} ns", sigma * 1e9);
    assert!(surveyed < declared, "{declared:.1} m left out, {surveyed:.1} m surveyed");
}

/// network-rough's capture with hostile receivers: n08 sending random
/// timestamps, n03 (GPS) whose time jumps a second ahead for 100 s and
/// again for 20 s, n12 declared at 0,0. Without them (n08 and n12 left out
/// of the capture) is the reference.
fn hostile(capture: &[u8], start_unix: f64) -> (Vec<u8>, Vec<u8>) {
    let text = std::str::from_utf8(capture).unwrap();
    let (mut bad, mut reference) = (String::new(), String::new());
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    for l in text.lines() {
        let f: Vec<&str> = l.split(' ').collect();
        let rx = f.get(1).copied().unwrap_or("");
        if rx != "n08" && rx != "n12" {
            reference += l;
            reference.push('\n');
        }
        let line = match (rx, l.starts_with("receiver")) {
            ("n12", true) => "receiver n12 lat=0.00000000 lon=0.00000000 alt=0.00 clock=beast12".to_string(),
            ("n08", false) => {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                format!("{} n08 <{:012X}{}", f[0], state & 0xFFFF_FFFF_FFFF, &f[2][13..])
            }
            ("n03", false) => {
                let t = f[0].parse::<f64>().unwrap() - start_unix;
                if (200.0..300.0).contains(&t) || (400.0..420.0).contains(&t) {
                    let ts = u64::from_str_radix(&f[2][1..13], 16).unwrap() + (1 << 30);
                    format!("{} n03 <{ts:012X}{}", f[0], &f[2][13..])
                } else {
                    l.to_string()
                }
            }
            _ => l.to_string(),
        };
        bad += &line;
        bad.push('\n');
    }
    (bad.into_bytes(), reference.into_bytes())
}

/// Random timestamps, a GPS time jumping by a second, a receiver declared
/// at 0,0: each found and reported, and the others' fixes as good as
/// without those receivers at all (no other receiver thought misplaced, no
/// clock pairs thrown off, the median within 5%).
#[test]
fn hostile_receivers_are_found_and_do_not_degrade_the_others() {
    let s = common::scenario("network-rough");
    let (capture, truth_bytes) = common::simulate(&s);
    let truth = Truth::read(&truth_bytes[..]).unwrap();
    let (bad, reference) = hostile(&capture, s.start_unix);
    let (core, events, rxs) = run_core(&bad, &CoreConfig::default());
    let (_, ref_events, _) = run_core(&reference, &CoreConfig::default());
    let report = core.mlat().report(s.start_unix + s.duration_s, &|k| rxs[k].id.clone());
    let last: HashMap<String, &fuse1090::mlat::ReceiverReport> = (events.iter())
        .filter_map(|e| if let Event::Receiver(r) = e { Some((rxs[r.rx].id.clone(), &**r)) } else { None })
        .collect();
    use fuse1090::mlat::Exclusion;
    assert_eq!((last["n08"].state, last["n08"].reason), (RxState::Excluded, Some(Exclusion::TimeJumps)));
    assert_eq!(last["n12"].state, RxState::Excluded, "{:?}", last["n12"]);
    assert_eq!(last["n03"].state, RxState::Ok, "n03 back once its time holds: {:?}", last["n03"]);
    assert!(core.mlat().stats.time_jumps > 1000, "{:?}", core.mlat().stats);
    let misplaced = report.split("misplaced [").nth(1).unwrap().split(']').next().unwrap();
    assert!(misplaced.starts_with("n06 declared") && !misplaced.contains(';'), "{report}");
    let (hostile_m, clean_m) = (fix_median_error(&events, &truth), fix_median_error(&ref_events, &truth));
    eprintln!("fix median {hostile_m:.1} m with the hostile receivers, {clean_m:.1} m without them");
    assert!(hostile_m <= 1.05 * clean_m, "{hostile_m} against {clean_m}");
}

/// Mode S-only traffic (no ADS-B aircraft to report the difference between
/// barometric altitude and height above the ellipsoid) whose barometric
/// altitudes stand 100 m above their heights: the fixes' geometry learns
/// the difference, so that the fixes' heights come out right and their
/// horizontal error is as in a world with no difference at all.
#[test]
fn the_barometric_difference_is_learnt_from_the_fixes_where_no_aircraft_reports_it() {
    let world = |baro_offset_m: f64| {
        let mut s = tma_busy_cut(300.0, 30, 30, 0);
        s.baro_offset_m = baro_offset_m;
        for r in &mut s.receiver {
            r.clock = ClockKind::Gps;
            r.drift_ppm = 0.0;
            r.drift_walk_ppm = 0.0;
            r.position_error_m = [0.0; 3];
        }
        let (capture, truth_bytes) = common::simulate(&s);
        let truth = Truth::read(&truth_bytes[..]).unwrap();
        let (_, events, _) = run_core(&capture, &CoreConfig::default());
        // Over the second half, once learnt.
        let late: Vec<Event> = (events.into_iter())
            .filter(|e| matches!(e, Event::Mlat(f) if f.altitude_used && f.t >= s.start_unix + 150.0))
            .collect();
        let dz: Vec<f64> = (late.iter())
            .filter_map(|e| if let Event::Mlat(f) = e { Some(f) } else { None })
            .filter_map(|f| Some(f.alt_m - truth.position(&format!("{:06X}", f.addr), f.t)?.2))
            .collect();
        (dz.iter().sum::<f64>() / dz.len() as f64, fix_median_error(&late, &truth), dz.len())
    };
    let (dz_none, median_none, _) = world(0.0);
    let (dz, median, n) = world(-100.0);
    eprintln!(
        "{n} fixes: height error {dz:+.1} m (world without a difference {dz_none:+.1} m), \
         median {median:.1} m ({median_none:.1} m)"
    );
    assert!(n > 1000, "{n} fixes");
    assert!((dz - dz_none).abs() < 30.0, "height error {dz:+.1} m against {dz_none:+.1} m");
    assert!(median < 1.15 * median_none, "median {median:.1} m against {median_none:.1} m");
}
