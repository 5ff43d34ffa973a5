//! Velocity reports against known truths: taken in steps, a report a few
//! metres per second wide leaves the cloud's velocity as spread as its
//! error, where taken at once it leaves a handful of particles; a report
//! after a turn is confirmed by the next, a misread one is not.

use nalgebra::{Matrix2, Vector2, Vector4};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::super::tests::World;
use super::super::{SparseConfig, SparseTrack};
use super::{VelocityOutcome, MAX_STEPS};

/// The cloud's velocity error (m/s) and its NEES against the truth `v`
/// (in the cloud's plane).
fn velocity_error(s: &SparseTrack, v: Vector2<f64>) -> (f64, f64) {
    let (m, cov) = s.moments();
    let err = Vector2::new(m[2], m[3]) - v;
    let p = cov.fixed_view::<2, 2>(2, 2).into_owned();
    (err.norm(), (err.transpose() * p.try_inverse().unwrap() * err)[0])
}

/// What a report did to a cloud, averaged over runs.
#[derive(Debug, Default)]
struct After {
    /// The velocity's error (m/s) and NEES just after the report.
    v_err: f64,
    v_nees: f64,
    /// The position's NEES 5 s later, and its largest sigma (m) then.
    p_nees: f64,
    p_sigma: f64,
}

/// A cloud of `sites` (2 or 3) sites' transmissions, a second apart for
/// 5 s, then a report (2 m/s per axis) taken in at most `max_steps` steps,
/// then 5 s more; over `runs` runs.
fn after_a_report(runs: u64, sites: usize, max_steps: usize) -> After {
    let w = World::new();
    let cfg = SparseConfig::default();
    let sigma_ms = 2.0;
    let cov = Matrix2::identity() * sigma_ms * sigma_ms;
    let mut a = After::default();
    let k_runs = runs as f64;
    for run in 0..runs {
        let mut noise = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(run * 17 + 3);
        let at = |t: f64, noise: &mut ChaCha8Rng| w.sites_at(t, 50e-9, noise)[..sites].to_vec();
        let mut s = SparseTrack::start(&cfg, &at(0.0, &mut noise), None, 0.0, w.h, run).unwrap();
        for k in 1..=10 {
            let t = k as f64;
            s.update(&cfg, &at(t, &mut noise), None, t, w.h);
            if k == 5 {
                let (lat, lon, _) = crate::geo::ecef_to_geodetic(w.aircraft(5.5));
                let here = crate::track::plane::Plane::new(lat, lon, w.h);
                let z: Vector2<f64> = Vector2::from_fn(|_, _| noise.sample(StandardNormal));
                let report = w.velocity_in(&here, 5.5) + z * sigma_ms;
                let outcome = s.velocity_in(&cfg, report, cov, 5.5, max_steps);
                assert!(matches!(outcome, VelocityOutcome::Taken(_)), "{outcome:?}");
                let (e, n) = velocity_error(&s, w.velocity_in(&s.gaussian().0, 5.5));
                a.v_err += e / k_runs;
                a.v_nees += n / k_runs;
            }
        }
        let (_, n) = w.error(&s, 10.0);
        let (_, cov) = s.moments();
        let sigma = cov.fixed_view::<2, 2>(0, 0).into_owned().symmetric_eigen().eigenvalues.max().sqrt();
        a.p_nees += n / k_runs;
        a.p_sigma += sigma / k_runs;
    }
    a
}

/// The cloud's velocities, spread over every airliner's, meet a report
/// far narrower. Taken in steps, the cloud's velocity ends as spread as
/// its error, and with two sites its positions stay spread along their
/// hyperbola. Taken at once, a handful of particles near the report make
/// the whole cloud: their velocities several times their spread from the
/// truth, and, with two sites, their few positions wherever along the
/// hyperbola they were, tens of kilometres off within a fraction of that.
#[test]
fn a_narrow_velocity_report_is_taken_in_steps() {
    let runs = 20;
    let [stepped3, once3, stepped2, once2] = [(3, MAX_STEPS), (3, 1), (2, MAX_STEPS), (2, 1)]
        .map(|(sites, steps)| after_a_report(runs, sites, steps));
    eprintln!("three sites: in steps {stepped3:?}\n  at once {once3:?}");
    eprintln!("two sites: in steps {stepped2:?}\n  at once {once2:?}");
    assert!(stepped3.v_err < 3.5, "{stepped3:?}");
    assert!((0.8..3.0).contains(&stepped3.v_nees), "{stepped3:?}");
    assert!(once3.v_nees > 3.0 * stepped3.v_nees, "{once3:?}");
    assert!(stepped2.v_nees < 4.0 && stepped2.p_nees < 8.0, "{stepped2:?}");
    assert!(once2.p_nees > 100.0 * stepped2.p_nees, "{once2:?}");
}

/// Straight east at 200 m/s, reported so; then reports of a northbound
/// aircraft: the first is left out, the second confirms the turn and the
/// cloud's velocities follow. A single misread report is left out and the
/// next true one taken.
#[test]
fn a_turn_is_confirmed_by_the_next_report_and_a_misread_is_not() {
    let w = World::new();
    let cfg = SparseConfig::default();
    let cov = Matrix2::identity() * 4.0;
    let mut noise = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(11);
    let mut s = SparseTrack::start(&cfg, &w.sites_at(0.0, 50e-9, &mut noise), None, 0.0, w.h, 5).unwrap();
    let east = |t: f64| {
        let (lat, lon, _) = crate::geo::ecef_to_geodetic(w.aircraft(t));
        w.velocity_in(&crate::track::plane::Plane::new(lat, lon, w.h), t)
    };
    for k in 1..=5 {
        let t = k as f64;
        s.update(&cfg, &w.sites_at(t, 50e-9, &mut noise), None, t, w.h);
        assert!(matches!(s.velocity(&cfg, east(t), cov, t), VelocityOutcome::Taken(_)));
    }
    let misread = Vector2::new(-200.0, 0.0);
    assert_eq!(s.velocity(&cfg, misread, cov, 5.5), VelocityOutcome::Contradicts);
    assert!(matches!(s.velocity(&cfg, east(6.0), cov, 6.0), VelocityOutcome::Taken(_)));
    let (e, _) = velocity_error(&s, w.velocity_in(&s.gaussian().0, 6.0));
    assert!(e < 5.0, "{e} m/s off after a misread report");
    let north = Vector2::new(0.0, 200.0);
    assert_eq!(s.velocity(&cfg, north, cov, 8.0), VelocityOutcome::Contradicts);
    assert_eq!(s.velocity(&cfg, north, cov, 10.0), VelocityOutcome::Redrawn);
    let (m, _) = s.moments();
    assert!((Vector2::new(m[2], m[3]) - north).norm() < 10.0, "{m:?}");
}

/// The turn of the local east/north taken linear around the cloud's mean
/// against the exact one, out to 300 km from it: within a tenth of a
/// degree (0.35 m/s at 200 m/s), and the turn itself a few degrees there.
#[test]
fn the_meridians_convergence_is_linear_enough_across_a_cloud() {
    let w = World::new();
    let cfg = SparseConfig::default();
    let mut noise = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(2);
    let s = SparseTrack::start(&cfg, &w.sites_at(0.0, 50e-9, &mut noise), None, 0.0, w.h, 1).unwrap();
    let turn = s.convergence();
    let plane = s.gaussian().0;
    let (mut worst, mut largest) = (0.0f64, 0.0f64);
    for (de, dn) in
        [(300e3, 0.0), (-300e3, 0.0), (0.0, 300e3), (0.0, -300e3), (210e3, 210e3), (-210e3, -210e3)]
    {
        let x = Vector4::new(turn.origin[0] + de, turn.origin[1] + dn, 0.0, 0.0);
        let (lat, lon) = plane.to_geodetic(x[0], x[1]);
        let r = plane.from_local(lat, lon);
        let exact = r[(1, 0)].atan2(r[(0, 0)]);
        worst = worst.max((turn.at(&x) - exact).abs());
        largest = largest.max(exact.abs());
    }
    eprintln!(
        "convergence: up to {:.2} deg, linear within {:.4} deg",
        largest.to_degrees(),
        worst.to_degrees()
    );
    assert!(largest.to_degrees() > 1.0, "{}", largest.to_degrees());
    assert!(worst.to_degrees() < 0.1, "{}", worst.to_degrees());
}
