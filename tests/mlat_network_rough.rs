//! Multilateration on network-rough (fixtures/scenarios/network-rough.toml):
//! receivers of mixed quality whose timing is learnt from the data, one of
//! them declared 150 m from its antenna and found from the traffic, against
//! an oracle told every receiver's truth.

mod common;

use std::collections::HashMap;

use common::{fix_median_error, fix_nees, run_core, run_core_knowing};
use fuse1090::core::{CoreConfig, Event};
use fuse1090::eval::Truth;
use fuse1090::mlat::RxState;

/// network-rough: the GPS-timed receiver declared 150 m from its antenna is
/// found from the ADS-B traffic (where it is, with an honest sigma), and no
/// other, GPS-timed or counter, is said to be misplaced. The receiver
/// records carry it.
#[test]
fn a_misplaced_gps_receiver_is_surveyed_from_the_traffic() {
    let s = common::scenario("network-rough");
    let (capture, truth_bytes) = common::simulate(&s);
    let truth = Truth::read(&truth_bytes[..]).unwrap();
    let (core, events, rxs) = run_core(&capture, &CoreConfig::default());
    let last: HashMap<usize, &fuse1090::mlat::ReceiverReport> = events
        .iter()
        .filter_map(|e| if let Event::Receiver(r) = e { Some((r.rx, &**r)) } else { None })
        .collect();
    for (k, t) in truth.receivers.iter().enumerate() {
        assert_eq!(rxs[k].id, t.id);
        let r = last[&k];
        match (r.position_offset_en_m, r.position_offset_sigma_m) {
            (Some([e, n]), Some(sigma)) => {
                let [te, tn] = t.position_offset_en_m;
                let miss = (e - te).hypot(n - tn);
                eprintln!("{}: found {e:+.1},{n:+.1} m +-{sigma:.1}, true {te:+.0},{tn:+.0}", t.id);
                assert!(miss < 30.0, "{}: {miss:.1} m from its true offset", t.id);
                // Honest: within four of its sigmas (per axis, so x sqrt 2).
                assert!(
                    miss < 4.0 * sigma * std::f64::consts::SQRT_2 + 5.0,
                    "{}: {miss:.1} m, sigma {sigma:.1}",
                    t.id
                );
            }
            _ => panic!("{}: not surveyed: {r:?}", t.id),
        }
    }
    let report = core.mlat().report(s.start_unix + s.duration_s, &|k| rxs[k].id.clone());
    let misplaced = report.split("misplaced [").nth(1).unwrap().split(']').next().unwrap();
    assert!(misplaced.starts_with("n06 declared") && !misplaced.contains(';'), "{report}");
    let (nees, inside, wild) = fix_nees(&events, &truth);
    eprintln!(
        "fix NEES {nees:.2}, {:.1}% inside their 95% ellipse, {:.3}% beyond NEES 50; {} fixes solved again",
        100.0 * inside,
        100.0 * wild,
        core.mlat().stats.refixed
    );
    assert!((1.8..2.2).contains(&nees) && inside >= 0.93, "NEES {nees}, inside {inside}");
    // Fixes wrong by many of their sigmas (a Gaussian puts 1e-11 of them
    // beyond 50): a late copy of a precise receiver that misled the search
    // for outliers into leaving out good copies made twice as many.
    assert!(wild <= 0.0005, "{:.3}% of fixes beyond NEES 50", 100.0 * wild);
    assert!(core.mlat().stats.refixed > 0);
    // Every receiver but the misplaced one in use, and each one's timing
    // learnt from the data, the Gaussian core apart from the late copies,
    // within a quarter of the truth (a counter-timed receiver's truth is
    // its jitter and its 12 MHz counter's resolution).
    for (k, t) in truth.receivers.iter().enumerate() {
        let r = last[&k];
        if t.id == "n06" {
            assert_eq!(r.reason, Some(fuse1090::mlat::Exclusion::Misplaced), "{r:?}");
            // What it learnt, it learnt against its wrong position: not reported.
            assert_eq!((r.sigma_ns, r.offset_ns, r.outlier_rate), (None, None, None), "{r:?}");
            continue;
        }
        assert_eq!(r.state, RxState::Ok, "{}: {r:?}", t.id);
        let learnt = r.sigma_ns.expect("a sigma learnt");
        let truth_ns = t.timing_sigma_ns();
        eprintln!(
            "{}: sigma {learnt:.0} ns, true {truth_ns:.0} ns; late {:?}, true {}",
            t.id, r.outlier_rate, t.multipath_prob
        );
        assert!(
            (learnt / truth_ns - 1.0).abs() <= 0.25,
            "{}: sigma {learnt:.0} ns, true {truth_ns:.0} ns",
            t.id
        );
        // The late share: found where multipath is common enough to be told
        // from the core's tail (at least half of it), and no more than a few
        // per cent made up: another receiver's late copy that could not be
        // left out moves every residual of its fix, and the tightest
        // receivers see that as lateness of their own.
        let late = r.outlier_rate.expect("a late share learnt");
        if t.multipath_prob >= 0.05 && t.multipath_delay_ns >= 3.0 * truth_ns {
            assert!(late >= 0.5 * t.multipath_prob, "{}: late {late}, true {}", t.id, t.multipath_prob);
        }
        assert!(late <= t.multipath_prob + 0.06, "{}: late {late}, true {}", t.id, t.multipath_prob);
    }
}

/// With `self_survey`, the misplaced receiver is used where the traffic
/// says it is: the fixes' median error falls (the median: one aircraft's
/// fixes can still follow a wrong solution, which is the solver's, not the
/// survey's, to fix), to within a fifth of an oracle's, a run told every
/// receiver's true position and timing through the configuration; and the
/// fixes stay honest.
#[test]
fn self_survey_puts_the_misplaced_receiver_where_it_is_and_learning_nears_the_oracle() {
    let s = common::scenario("network-rough");
    let (capture, truth_bytes) = common::simulate(&s);
    let truth = Truth::read(&truth_bytes[..]).unwrap();
    let run = |self_survey: bool, known| {
        let mut cfg = CoreConfig::default();
        cfg.mlat.self_survey = self_survey;
        let (core, events, _) = run_core_knowing(&capture, &cfg, known);
        // Every ADS-B aircraft here is honest: multipath on the receivers
        // that hear some of them must not make them look like spoofers (it
        // did, to a quarter of them, while one late pair counted a hundred).
        assert_eq!(core.mlat().stats.sync_banned_aircraft, 0, "honest aircraft refused as sync sources");
        (fix_median_error(&events, &truth), fix_nees(&events, &truth).0)
    };
    let oracle = fuse1090::config::Config::parse(&fuse1090::sim::oracle_config(&s), "oracle").unwrap();
    assert_eq!(oracle.receiver.len(), truth.receivers.len());
    assert!(oracle.receiver.iter().all(|r| r.timing.is_some()));
    let ((declared, _), (surveyed, nees)) = (run(false, Vec::new()), run(true, Vec::new()));
    let (known, _) = run(false, oracle.known_receivers());
    eprintln!(
        "fixes' median error: {declared:.1} m declared, {surveyed:.1} m surveyed (NEES {nees:.2}), {known:.1} m oracle"
    );
    assert!(surveyed < 0.9 * declared, "{declared:.1} m declared, {surveyed:.1} m surveyed");
    assert!(surveyed <= 1.2 * known, "{surveyed:.1} m surveyed, {known:.1} m oracle");
    // Honest with the surveyed position in use: its uncertainty is in the
    // copies' variance (without it, the position in use metres off pulled
    // every fix with the receiver the same way, unaccounted for).
    assert!((1.85..2.1).contains(&nees), "surveyed fixes' NEES {nees:.2}");
    // The oracle's own use of what it is told: not worse than learning.
    assert!(known < surveyed, "{surveyed:.1} m surveyed, {known:.1} m oracle");
}

/// An operator who calibrated every receiver but one (network-rough's
/// oracle configuration without n01's timing): the given offsets are
/// absolute, so n01's is learnt against them, its 250 ns GPS bias found,
/// and its fixes as good as the oracle's. (Learnt as if only differences
/// mattered, its offset stayed where it started, and the fixes it was in
/// carried its whole bias.)
#[test]
fn a_receiver_whose_timing_is_not_given_learns_it_against_those_given() {
    let s = common::scenario("network-rough");
    let (capture, truth_bytes) = common::simulate(&s);
    let truth = Truth::read(&truth_bytes[..]).unwrap();
    let oracle = fuse1090::config::Config::parse(&fuse1090::sim::oracle_config(&s), "oracle").unwrap();
    let known = |all: bool| -> Vec<_> {
        (oracle.receiver.iter())
            .map(|r| r.known())
            .map(|mut k| {
                if !all && k.decl.id == "n01" {
                    k.timing = None;
                }
                k
            })
            .collect()
    };
    let (core, events, rxs) = run_core_knowing(&capture, &CoreConfig::default(), known(false));
    assert_eq!(rxs[0].id, "n01");
    let (t, m) = (&truth.receivers[0], core.mlat().timing(0));
    let (offset_ns, sigma_ns) = (m.offset() * 1e9, m.sigma() * 1e9);
    let (one_learnt, all_given) = (
        fix_median_error(&events, &truth),
        fix_median_error(&run_core_knowing(&capture, &CoreConfig::default(), known(true)).1, &truth),
    );
    eprintln!(
        "n01 learnt {offset_ns:+.0} ns / {sigma_ns:.0} ns (true {:+.0} / {:.0}); fixes' median {one_learnt:.1} m, {all_given:.1} m all given",
        t.offset_ns,
        t.timing_sigma_ns()
    );
    assert!(
        (offset_ns - t.offset_ns).abs() < 15.0,
        "n01 offset {offset_ns:+.0} ns, true {:+.0}",
        t.offset_ns
    );
    assert!((sigma_ns / t.timing_sigma_ns() - 1.0).abs() < 0.25, "n01 sigma {sigma_ns:.0} ns");
    assert!(one_learnt < 1.1 * all_given, "{one_learnt:.1} m against {all_given:.1} m");
}
