//! The fuser's particle filters: bounded in number, handing over to tracks
//! once their cloud has one peak, and taking back tracks that the time
//! differences do not hold.

use super::*;

#[test]
fn particle_filters_are_bounded_and_give_way_to_a_fix() {
    let mut tcfg = TrackConfig::default();
    tcfg.sparse.enabled = true;
    tcfg.sparse.max_filters = 1;
    // A filter starts once an aircraft's groups have been too small for a fix for 1 s.
    tcfg.sparse.start_after_s = 1.0;
    // Given up at a fix only (the one-mode handover is the next test's).
    tcfg.sparse.handover_after = 0;
    let mut f = Fuser::new(FuseConfig::default(), tcfg, false);
    let mut out = Vec::new();
    for t in [99.0, 100.0, 101.0, 102.0] {
        for addr in [1, 2] {
            f.on_measurement(addr, None, height(t), t, &mut out);
            f.on_tdoa(&tdoa(addr, t), t, &mut out);
        }
    }
    let s = f.stats().sparse;
    assert_eq!((s.started, s.updates, s.refused), (1, 2, 3), "{s:?}");
    // A fix gives aircraft 1 a track: its filter goes at once (no more time
    // differences need come), and aircraft 2 may have one.
    f.on_measurement(1, None, fix(103.0), 103.0, &mut out);
    f.on_tdoa(&tdoa(2, 103.5), 103.5, &mut out);
    let s = f.stats().sparse;
    assert_eq!((s.handed_over, s.started), (1, 2), "{s:?}");
}

/// A fuser whose particle filters start after 1 s of groups too small for a fix.
fn sparse_fuser() -> Fuser {
    let mut tcfg = TrackConfig::default();
    tcfg.sparse.enabled = true;
    tcfg.sparse.start_after_s = 1.0;
    Fuser::new(FuseConfig::default(), tcfg, false)
}

/// Feeds aircraft `addr`'s heights and time differences from `t` until its
/// cloud is the `n`th handed to Gaussian tracks; returns the time reached.
fn until_handed_over(f: &mut Fuser, addr: u32, n: u64, mut t: f64, out: &mut Vec<Output>) -> f64 {
    while f.stats().sparse.handed_over_one_mode < n && t < 140.0 {
        f.on_measurement(addr, None, height(t), t, out);
        f.on_tdoa(&tdoa(addr, t), t, out);
        t += 0.5;
    }
    assert_eq!(f.stats().sparse.handed_over_one_mode, n);
    t
}

/// A cloud with one mode for three estimates in a row: the Gaussian tracks
/// start from it, take the time differences, are confirmed by them and
/// published flagged `sparse`, until a fix; time differences that keep
/// missing a track started from a cloud send the aircraft back to a new one.
#[test]
fn a_one_peaked_cloud_hands_over_and_a_wrong_start_is_given_back() {
    let mut f = sparse_fuser();
    let mut out = Vec::new();
    let mut t = 99.0;
    while t < 130.0 {
        f.on_measurement(1, None, height(t), t, &mut out);
        f.on_tdoa(&tdoa(1, t), t, &mut out);
        f.advance(t, &mut out);
        t += 0.5;
    }
    let s = f.stats().sparse;
    assert_eq!((s.handed_over_one_mode, s.given_back, s.mirrored), (1, 0, 0), "{s:?}");
    let sparse_tracks = |out: &[Output]| -> Vec<(f64, f64)> {
        (out.iter())
            .filter_map(|o| match o {
                Output::Track(r) if r.sparse => Some((r.est.t, r.est.lat)),
                _ => None,
            })
            .collect()
    };
    // Published through the handover and after, from the Gaussian track.
    let published = sparse_tracks(&out);
    assert!(published.iter().filter(|(t, _)| *t > 115.0).count() >= 10, "{published:?}");
    // A fix: the track is no longer a sparse-geometry one.
    out.clear();
    f.on_measurement(1, None, fix(130.0), 130.0, &mut out);
    for k in 1..6 {
        let t = 130.0 + k as f64;
        f.on_tdoa(&tdoa(1, t), t, &mut out);
        f.on_measurement(1, None, fix(t), t, &mut out);
        f.advance(t, &mut out);
    }
    assert!(sparse_tracks(&out).is_empty());
    assert!(out.iter().any(|o| matches!(o, Output::Track(r) if !r.sparse)));

    // Aircraft 2 is handed over, then its time differences jump 30 km away
    // (as if the cloud had taken the wrong side): given back.
    let mut out = Vec::new();
    let mut t = until_handed_over(&mut f, 2, 2, 99.0, &mut out);
    for _ in 0..20 {
        f.on_measurement(2, None, height(t), t, &mut out);
        f.on_tdoa(&tdoa_from(2, t, at(t + 150.0)), t, &mut out);
        t += 0.5;
    }
    let s = f.stats().sparse;
    assert_eq!((s.given_back, s.mirrored), (1, 0), "{s:?}");
}

/// Tracks started from a cloud, then heard by two receivers only while the
/// aircraft turns (2 degrees a second, left, from the test flight's heading
/// east): one time difference places it on a curve, and where along it
/// only the track's motion says. Its published estimates stay within
/// their covariance, which grows with what a turn could have done unseen,
/// and once that is wider than a cloud may be to be published, the
/// aircraft goes back to a cloud. (Before, the track flew on straight,
/// kilometres off, with a covariance of a few hundred metres.)
#[test]
fn a_track_one_time_difference_cannot_hold_goes_back_to_a_cloud() {
    let mut f = sparse_fuser();
    let mut out = Vec::new();
    let mut t = until_handed_over(&mut f, 1, 1, 99.0, &mut out);
    let (t0, rate) = (t, 2f64.to_radians());
    let radius = 200.0 / rate;
    let turning = |t: f64| {
        let a = rate * (t - t0);
        let (e, n) = (200.0 * (t0 - 100.0) + radius * a.sin(), radius * (1.0 - a.cos()));
        crate::geo::displace(45.0, 5.0, 3000.0, [e, n, 0.0])
    };
    let two = [[0.0, 30_000.0], [26_000.0, -15_000.0], [26_000.0, -15_000.0]];
    out.clear();
    let mut worst: f64 = 0.0;
    while t < t0 + 90.0 && f.stats().sparse.spread == 0 {
        f.on_measurement(1, None, height(t), t, &mut out);
        let mut g = tdoa_at_sites(1, t, turning(t), two);
        g.sites.truncate(2);
        g.persistent.truncate(2);
        f.on_tdoa(&g, t, &mut out);
        f.advance(t, &mut out);
        for o in out.drain(..) {
            let Output::Track(r) = o else { continue };
            worst = worst.max(nees(&r, turning(r.est.t)));
        }
        t += 0.5;
    }
    let s = f.stats().sparse;
    assert_eq!((s.spread, s.given_back, s.mirrored), (1, 0, 0), "{s:?} at {:.0} s", t - t0);
    assert!(worst < 20.0, "worst NEES {worst:.1}");
}

/// Tracks started from a cloud, then heard by three receivers in a line: a
/// transmission's second solution, mirrored across the line, that nothing
/// rules out (no coverage known) sends the aircraft back to a cloud, and
/// nothing is published while the two cannot be told apart.
#[test]
fn a_mirror_nothing_rules_out_gives_tracks_from_a_cloud_back() {
    let mut f = sparse_fuser();
    let mut out = Vec::new();
    let mut t = until_handed_over(&mut f, 1, 1, 99.0, &mut out);
    // Sites on a north-south line 40 km west of the flight's middle.
    let line = [[-40_000.0, 60_000.0], [-40_000.0, 0.0], [-40_000.0, -60_000.0]];
    out.clear();
    let until = t + 20.0;
    while t < until {
        f.on_measurement(1, None, height(t), t, &mut out);
        f.on_tdoa(&tdoa_at_sites(1, t, at(t), line), t, &mut out);
        f.advance(t, &mut out);
        t += 0.5;
    }
    let s = f.stats().sparse;
    assert_eq!((s.mirrored, s.given_back), (1, 0), "{s:?}");
    let published_after: Vec<f64> = (out.iter())
        .filter_map(|o| match o {
            Output::Track(r) if r.sparse => Some(r.est.t),
            _ => None,
        })
        .collect();
    // At most the estimate of the first line transmission's moment, before it was judged.
    assert!(published_after.len() <= 1, "{published_after:?}");
}
