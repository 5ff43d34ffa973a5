//! The fusion stage's unit tests: rejection, the MLAT hold, fusion and publication;
//! the particle filter's aircraft in `tests/sparse.rs`.

mod sparse;

use super::*;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

pub(super) fn pos(t: f64, lat: f64, lon: f64) -> Measurement {
    Measurement {
        t,
        source: Source::Adsb,
        obs: Observation::Position {
            lat,
            lon,
            cov_en: Matrix2::identity() * 100.0,
            height: Some((3000.0, 100.0)),
            time_sigma_s: 0.0,
            surface: false,
            claimed: true,
            persistent: crate::track::SharedShare::default(),
            adsb_echo: 0.0,
        },
    }
}

/// Where the test flight is at `t`: east at 200 m/s from (45, 5) at 3 km,
/// from t = 100 s.
fn at(t: f64) -> (f64, f64, f64) {
    crate::geo::displace(45.0, 5.0, 3000.0, [200.0 * (t - 100.0), 0.0, 0.0])
}

/// An MLAT fix of the test flight at `t`, exact.
fn fix(t: f64) -> Measurement {
    let (lat, lon, _) = at(t);
    Measurement { source: Source::Mlat, ..pos(t, lat, lon) }
}

#[test]
fn impossible_measurements_are_rejected_and_counted() {
    let mut f = Fuser::new(FuseConfig::default(), TrackConfig::default(), false);
    let mut out = Vec::new();
    f.on_measurement(1, Some(8), pos(100.0, f64::NAN, 5.0), 100.0, &mut out);
    f.on_measurement(1, Some(8), pos(100.0, 45.0, 5.0), 200.0, &mut out);
    let fast = Measurement {
        t: 100.0,
        source: Source::Adsb,
        obs: Observation::Velocity { v_en: Vector2::new(1300.0, 0.0), cov: Matrix2::identity(), climb: None },
    };
    f.on_measurement(1, Some(8), fast, 100.0, &mut out);
    let bad_cov = Measurement {
        obs: Observation::Position {
            lat: 45.0,
            lon: 5.0,
            cov_en: -Matrix2::identity(),
            height: None,
            time_sigma_s: 0.0,
            surface: false,
            claimed: true,
            persistent: crate::track::SharedShare::default(),
            adsb_echo: 0.0,
        },
        ..pos(100.0, 45.0, 5.0)
    };
    f.on_measurement(1, Some(8), bad_cov, 100.0, &mut out);
    let s = f.stats();
    assert_eq!((s.rejected_non_finite, s.rejected_time, s.rejected_speed), (2, 1, 1));
    assert_eq!(f.tracks(), 0);
    assert!(out.is_empty());
    // Good ones make a confirmed, published track.
    for k in 0..5 {
        let t = 100.0 + k as f64;
        let (lat, lon, _) = at(t);
        f.on_measurement(1, Some(8), pos(t, lat, lon), t, &mut out);
    }
    assert!(out.iter().any(|o| matches!(o, Output::Track(r) if r.est.state.healthy())));
}

/// An aircraft flying east at 200 m/s for a minute: ADS-B positions at
/// 2 Hz on time, an MLAT fix a second (for the first `mlat_s` seconds)
/// arriving 0.5 s after its time; the core moves time forward before
/// each arrival. Returns each publication's (arrival time, track time)
/// and the stats.
fn mlat_fed_flight(hold_s: f64, mlat_s: f64) -> (Vec<(f64, f64)>, FuseStats) {
    let cfg = FuseConfig { mlat_hold_s: hold_s, ..FuseConfig::default() };
    let (published, stats) = flight(cfg, false, mlat_s);
    (published.iter().map(|(now, r)| (*now, r.est.t)).collect(), stats)
}

/// The flight of [`mlat_fed_flight`] through a fuser of `cfg`: every
/// track record with its arrival time, and the stats.
fn flight(cfg: FuseConfig, source_tracks: bool, mlat_s: f64) -> (Vec<(f64, TrackReport)>, FuseStats) {
    let mut f = Fuser::new(cfg, TrackConfig::default(), source_tracks);
    let mut arrivals: Vec<(f64, Measurement)> = Vec::new();
    for k in 0..120 {
        let t = 100.0 + 0.5 * k as f64;
        let (lat, lon, _) = at(t);
        arrivals.push((t, pos(t, lat, lon)));
        if k % 2 == 1 && t < 100.0 + mlat_s {
            let tf = t + 0.25;
            let (lat, lon, _) = at(tf);
            arrivals.push((tf + 0.5, Measurement { source: Source::Mlat, ..pos(tf, lat, lon) }));
        }
    }
    arrivals.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut out, mut published) = (Vec::new(), Vec::new());
    let mut collect = |out: &mut Vec<Output>, now: f64| {
        for o in out.drain(..) {
            if let Output::Track(r) = o {
                published.push((now, *r));
            }
        }
    };
    for (now, m) in arrivals {
        f.advance(now, &mut out);
        f.on_measurement(1, Some(8), m, now, &mut out);
        collect(&mut out, now);
    }
    f.finish(&mut out);
    collect(&mut out, f64::INFINITY);
    (published, *f.stats())
}

/// The fused records of an aircraft flying straight (east at 200 m/s)
/// for five minutes, multilaterated as by a sparse network: 150 m per
/// axis every 0.7 s, each fix arriving 0.5 s after its time; with one
/// ADS-B position first when `adsb_first`, its ADS-B then flagged as
/// suspect when `suspect`.
fn multilaterated(mlat_only: bool, seed: u64, adsb_first: bool, suspect: bool) -> Vec<TrackReport> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut tcfg = TrackConfig::default();
    tcfg.mlat_only.enabled = mlat_only;
    let mut f = Fuser::new(FuseConfig::default(), tcfg, false);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 150.0).expect("sigma");
    let mut out = Vec::new();
    if adsb_first {
        let (lat, lon, _) = at(100.0);
        f.on_measurement(1, Some(8), pos(100.0, lat, lon), 100.0, &mut out);
        if suspect {
            f.set_suspect(1, 100.0, true, Some(2000.0), 100.0, &mut out);
        }
    }
    for k in 1..430 {
        let t = 100.0 + 0.7 * k as f64;
        let e = [noise.sample(&mut rng), noise.sample(&mut rng), 0.0];
        let (lat, lon, h) = at(t);
        let (lat, lon, _) = crate::geo::displace(lat, lon, h, e);
        let m = Measurement {
            source: Source::Mlat,
            obs: Observation::Position {
                lat,
                lon,
                cov_en: Matrix2::identity() * 150.0f64.powi(2),
                height: Some((3000.0, 100.0)),
                time_sigma_s: 0.0,
                surface: false,
                claimed: true,
                persistent: crate::track::SharedShare::default(),
                adsb_echo: 0.0,
            },
            ..pos(t, lat, lon)
        };
        f.advance(t + 0.5, &mut out);
        f.on_measurement(1, None, m, t + 0.5, &mut out);
    }
    f.finish(&mut out);
    out.into_iter()
        .filter_map(|o| match o {
            Output::Track(r) if r.source == TrackSource::Fused => Some(*r),
            _ => None,
        })
        .collect()
}

/// An aircraft heard only through MLAT, hundreds of metres per fix, flying
/// straight: with the matrix that keeps to constant velocity its track
/// is closer to the truth than with the matrix of ADS-B aircraft, whose
/// manoeuvre models then keep three quarters of the weight, and its
/// covariance still covers the error (straight flight is where an IMM
/// is most conservative: both are). So does one whose ADS-B is kept out
/// as suspect; an aircraft heard in ADS-B switches like any other.
#[test]
fn an_aircraft_heard_only_by_mlat_keeps_to_constant_velocity() {
    // RMS error and mean NEES after the first 30 s, over 20 runs.
    let score = |mlat_only: bool, suspect: bool| {
        let (mut se, mut nees, mut n) = (0.0, 0.0, 0usize);
        for seed in 1..=20 {
            let records = multilaterated(mlat_only, seed, suspect, suspect);
            for r in records.iter().filter(|r| r.est.t > 130.0) {
                let (lat, lon, _) = at(r.est.t);
                let plane = Plane::new(lat, lon, 3000.0);
                let d = Vector2::from(plane.to_en(r.est.lat, r.est.lon));
                let c = Matrix2::from_fn(|i, j| r.est.cov_local[i][j]);
                se += d.norm_squared();
                nees += d.dot(&(c.try_inverse().expect("covariance") * d));
                n += 1;
            }
        }
        ((se / n as f64).sqrt(), nees / n as f64)
    };
    let (rmse_home, nees_home) = score(true, false);
    let (rmse_sticky, nees_sticky) = score(false, false);
    eprintln!("MLAT only: {rmse_home:.1} m NEES {nees_home:.2}; as ADS-B aircraft: {rmse_sticky:.1} m NEES {nees_sticky:.2}");
    assert!(rmse_home < 0.8 * rmse_sticky, "{rmse_home} against {rmse_sticky}");
    assert!(nees_home > 1.2 && nees_home < 2.0, "{nees_home}");
    let (rmse_suspect, _) = score(true, true);
    let (rmse_suspect_sticky, _) = score(false, true);
    eprintln!("flagged as suspect: {rmse_suspect:.1} m; as ADS-B aircraft: {rmse_suspect_sticky:.1} m");
    assert!(rmse_suspect < 0.8 * rmse_suspect_sticky, "{rmse_suspect} against {rmse_suspect_sticky}");
    // Heard in ADS-B first: the same records whichever matrix MLAT-only
    // aircraft would have.
    assert_eq!(multilaterated(true, 1, true, false), multilaterated(false, 1, true, false));
}

/// Track-to-track fusion of a pair too far apart in time: once the MLAT
/// track's newest fix is older than the coasting limit, the fresh ADS-B
/// track goes out as it is, and each such publication is counted until
/// the MLAT source leaves the sources window.
#[test]
fn a_pair_too_far_apart_to_align_is_not_fused_and_is_counted() {
    let cfg = FuseConfig { method: Method::Convex, ..FuseConfig::default() };
    let (coast, window) = (TrackConfig::default().coast_after_s, cfg.sources_window_s);
    let (published, stats) = flight(cfg, true, 20.0);
    let last_fix = 100.0 + 19.5 + 0.25;
    // Fused and ADS-B records of the same publication, by track time.
    let pairs: Vec<(f64, &TrackReport, &TrackReport)> = published
        .iter()
        .filter(|(_, r)| r.source == TrackSource::Fused)
        .filter_map(|(_, fused)| {
            let adsb =
                published.iter().find(|(_, r)| r.source == TrackSource::Adsb && r.est.t == fused.est.t)?;
            Some((fused.est.t - last_fix, fused, &adsb.1))
        })
        .collect();
    let same =
        |a: &TrackReport, b: &TrackReport| a.est.state.x == b.est.state.x && a.est.state.p == b.est.state.p;
    // Fused while both are fresh, once the MLAT track is confirmed (its
    // third fix, at about 102.75).
    let fused_while_both = pairs.iter().filter(|(age, ..)| (-15.0..0.0).contains(age)).collect::<Vec<_>>();
    assert!(fused_while_both.len() > 20 && fused_while_both.iter().all(|(_, f, a)| !same(f, a)));
    let unaligned: Vec<_> = pairs.iter().filter(|(age, ..)| *age > coast && *age <= window).collect();
    assert!(unaligned.len() >= 10 && unaligned.iter().all(|(_, f, a)| same(f, a)), "{}", unaligned.len());
    assert_eq!(stats.fusion_fallbacks, unaligned.len() as u64, "{stats:?}");
}

#[test]
fn an_mlat_fed_track_takes_late_fixes_in_order_and_keeps_its_period() {
    let (held, stats) = mlat_fed_flight(0.6, 60.0);
    // Only the very first fix (before the aircraft counts as MLAT-fed)
    // lands behind newer ADS-B; without the hold every fix does.
    assert!(stats.reruns <= 1, "{stats:?}");
    assert!(mlat_fed_flight(0.0, 60.0).1.reruns >= 50);
    // NACp 8: one publication per 0.6 s over the ~57 s after confirmation,
    // each at a newer time than the last, about the hold after its time.
    assert!((90..=100).contains(&held.len()), "{}", held.len());
    assert!(held.windows(2).all(|w| w[1].1 > w[0].1));
    let gaps = held.windows(2).map(|w| w[1].1 - w[0].1).sum::<f64>() / (held.len() - 1) as f64;
    assert!((gaps - 0.6).abs() < 0.05, "mean gap {gaps}");
    assert!(held[5..held.len() - 1].iter().all(|(now, t)| (0.5..=1.0).contains(&(now - t))), "{held:?}");
}

#[test]
fn a_flood_of_one_mlat_fed_aircraft_is_applied_early_not_queued_without_bound() {
    let mut f = Fuser::new(FuseConfig::default(), TrackConfig::default(), false);
    let mut out = Vec::new();
    f.on_measurement(1, None, fix(100.0), 100.0, &mut out);
    // 1,000 positions within a millisecond of arrival time (a replay
    // looping fast): none is lost, none waits beyond the bound.
    for k in 0..1000 {
        let t = 100.0 + 0.001 * k as f64;
        f.on_measurement(1, None, fix(t), 100.5, &mut out);
        assert!(f.aircraft[&1].waiting.len() <= MAX_WAITING);
    }
    assert_eq!(f.stats().measurements, 1001);
    f.finish(&mut out);
    assert!(f.aircraft[&1].waiting.is_empty());
    assert_eq!(f.aircraft[&1].fused.t(), 100.999);
}

/// A release that moves the tracks on by more than their reorder window
/// after the publication time (a burst delivered at once: a stalled
/// input catching up, the end of a capture) still publishes at that
/// time, where the tracks' history no longer reaches back to it: the
/// fused track by measurement fusion, and the single-source tracks, by
/// themselves and fused track to track.
#[test]
fn a_release_longer_than_the_reorder_window_still_publishes() {
    for (method, source_tracks) in
        [(Method::Measurement, false), (Method::Measurement, true), (Method::Convex, true)]
    {
        let cfg = FuseConfig { method, ..FuseConfig::default() };
        let mut f = Fuser::new(cfg, TrackConfig::default(), source_tracks);
        let mut out = Vec::new();
        // A confirmed MLAT-fed track, each fix released after the hold.
        for k in 0..10 {
            let t = 100.0 + 0.5 * k as f64;
            f.advance(t, &mut out);
            f.on_measurement(1, None, fix(t), t, &mut out);
        }
        f.advance(105.0, &mut out);
        out.clear();
        // A fix due for publication, then five seconds of Mode S
        // altitudes (they move the tracks on, and publish nothing), all
        // held together and released at the end of the input.
        let burst = 106.0;
        f.on_measurement(1, None, fix(burst), burst, &mut out);
        for k in 1..=10 {
            let t = burst + 0.5 * k as f64;
            f.on_measurement(1, None, height(t), burst, &mut out);
        }
        assert!(out.is_empty(), "held");
        f.finish(&mut out);
        let published: Vec<(&str, f64)> = out
            .iter()
            .filter_map(|o| if let Output::Track(r) = o { Some((r.source.name(), r.est.t)) } else { None })
            .collect();
        let expected =
            if source_tracks { vec![("fused", burst), ("mlat", burst)] } else { vec![("fused", burst)] };
        assert_eq!(published, expected, "{method:?}");
        let reorder = TrackConfig::default().reorder_window_s;
        assert!(f.aircraft[&1].fused.t() > burst + reorder);
        assert!(!source_tracks || f.aircraft[&1].single[Source::Mlat as usize].t() > burst + reorder);
    }
}

#[test]
fn a_track_mlat_stops_feeding_goes_out_at_once_again() {
    // MLAT for the first 20 s; 10 s later (the sources window) the
    // track is ADS-B only and each publication leaves on arrival.
    let (published, _) = mlat_fed_flight(0.6, 20.0);
    let late: Vec<&(f64, f64)> = published.iter().filter(|(_, t)| *t > 132.0).collect();
    assert!(late.len() > 40);
    assert!(late.iter().all(|(now, t)| now == t), "{late:?}");
}

/// Time differences of the test flight at `t` at three sites 30 km around its start.
fn tdoa(addr: u32, t: f64) -> crate::mlat::engine::TdoaGroup {
    tdoa_from(addr, t, at(t))
}

/// Time differences at `t` of an aircraft at `(lat, lon, h)`, from three
/// sites around the flight's middle.
fn tdoa_from(addr: u32, t: f64, at: (f64, f64, f64)) -> crate::mlat::engine::TdoaGroup {
    tdoa_at_sites(addr, t, at, [[0.0, 30_000.0], [26_000.0, -15_000.0], [-26_000.0, -15_000.0]])
}

/// Time differences at `t` of an aircraft at `(lat, lon, h)`, from sites
/// east and north (m) of the flight's middle.
fn tdoa_at_sites(
    addr: u32,
    t: f64,
    (lat, lon, h): (f64, f64, f64),
    sites: [[f64; 2]; 3],
) -> crate::mlat::engine::TdoaGroup {
    let p = crate::geo::geodetic_to_ecef(lat, lon, h);
    let sites = sites.map(|[e, n]| {
        let (la, lo, ha) = crate::geo::displace(45.0, 5.0, 100.0, [e, n, 0.0]);
        let s = crate::geo::geodetic_to_ecef(la, lo, ha);
        (s, t + crate::geo::ecef_distance(p, s) / crate::mlat::solver::C_AIR, 50e-9)
    });
    crate::mlat::engine::TdoaGroup {
        addr,
        t,
        sites: sites.to_vec(),
        persistent: vec![(0.0, 0.0); sites.len()],
        sync_var: vec![0.0; sites.len()],
        unheard: None,
    }
}

/// A published estimate's horizontal NEES against the truth at `(lat, lon, h)`.
fn nees(r: &TrackReport, (lat, lon, h): (f64, f64, f64)) -> f64 {
    let x = r.est.plane.ecef_to_local(crate::geo::geodetic_to_ecef(lat, lon, h));
    let d = nalgebra::Vector2::new(x[0] - r.est.state.x[0], x[1] - r.est.state.x[1]);
    let p = r.est.state.p.fixed_view::<2, 2>(0, 0).into_owned();
    (d.transpose() * p.try_inverse().unwrap() * d)[0]
}

/// The test flight's reported height at `t`.
fn height(t: f64) -> Measurement {
    Measurement { t, source: Source::Mlat, obs: Observation::Height { h: 3000.0, var: 100.0 } }
}

/// A cluster's checkpoint reserves track numbers: an aircraft whose track
/// starts again within the track's drop time keeps its number, and the
/// numbers of aircraft not heard again are forgotten after it.
#[test]
fn reserved_track_numbers_are_taken_up_or_forgotten() {
    let tcfg = TrackConfig::default();
    let drop = tcfg.drop_after_s;
    let mut f = Fuser::new(FuseConfig::default(), tcfg, false);
    f.keep_track_numbers(&[(1, 41), (2, 42)], 50);
    let mut out = Vec::new();
    f.advance(100.0, &mut out);
    for k in 0..5 {
        let t = 100.0 + k as f64;
        let (lat, lon, _) = at(t);
        f.on_measurement(1, Some(8), pos(t, lat, lon), t, &mut out);
    }
    let id = out.iter().find_map(|o| match o {
        Output::Track(r) => Some(r.id),
        _ => None,
    });
    assert_eq!(id, Some(41), "aircraft 1 kept its number");
    assert_eq!(f.reserved_numbers(), 1);
    f.advance(100.0 + drop - 1.0, &mut out);
    assert_eq!(f.reserved_numbers(), 1, "within the drop time");
    f.advance(100.0 + drop + 1.5, &mut out);
    assert_eq!(f.reserved_numbers(), 0, "aircraft 2's number forgotten");
    assert_eq!(f.track_numbers().1, 50, "new numbers still continue after the checkpoint's");
}

/// The test flight's ADS-B position at `t`, 38 m sigma per axis drawn and
/// declared (NACp 8).
fn noisy_adsb(t: f64, noise: &mut rand::rngs::StdRng) -> Measurement {
    const ADSB_M: f64 = 38.0;
    let (lat, lon, _) = at(t);
    let (e, n): (f64, f64) = (noise.sample(StandardNormal), noise.sample(StandardNormal));
    let (lat, lon, _) = crate::geo::displace(lat, lon, 3000.0, [ADSB_M * e, ADSB_M * n, 0.0]);
    let mut m = pos(t, lat, lon);
    if let Observation::Position { cov_en, .. } = &mut m.obs {
        *cov_en = Matrix2::identity() * ADSB_M * ADSB_M;
    }
    m
}

/// An MLAT fix of the test flight at `t`, `bias` (east, north m) plus
/// `fresh_m` per axis drawn off, declared `sigma_m` per axis.
fn fix_off(
    t: f64,
    bias: [f64; 2],
    fresh_m: f64,
    sigma_m: f64,
    noise: &mut rand::rngs::StdRng,
) -> Measurement {
    let (lat0, lon0, _) = at(t);
    let (e, n): (f64, f64) = (noise.sample(StandardNormal), noise.sample(StandardNormal));
    let d = [bias[0] + fresh_m * e, bias[1] + fresh_m * n, 0.0];
    let (lat, lon, _) = crate::geo::displace(lat0, lon0, 3000.0, d);
    let mut m = Measurement { source: Source::Mlat, ..pos(t, lat, lon) };
    if let Observation::Position { cov_en, .. } = &mut m.obs {
        *cov_en = Matrix2::identity() * sigma_m * sigma_m;
    }
    m
}

/// An ADS-B aircraft (NACp 8) whose transmissions three receivers hear as
/// time differences, one of them reaching the network through pair filters
/// whose estimate is 150 ns off (45 m) for the whole flight, as its sync
/// variance says it may be. Taken as each transmission's own error, the
/// track averaged it away over hundreds of transmissions, and its
/// estimates' mean NEES was about twice what it should be; counted as
/// persistent, they stay within their covariance.
#[test]
fn a_sync_error_that_stays_is_not_averaged_away_by_a_track() {
    let mut f = Fuser::new(FuseConfig::default(), TrackConfig::default(), false);
    let mut out = Vec::new();
    let (own_s, sync_s) = (50e-9, 150e-9);
    let mut noise = rand::rngs::StdRng::seed_from_u64(7);
    let mut nees_all = Vec::new();
    for k in 0..240 {
        let t = 100.0 + 0.5 * k as f64;
        if k % 2 == 0 {
            f.on_measurement(1, Some(8), noisy_adsb(t, &mut noise), t, &mut out);
        }
        let mut g = tdoa(1, t);
        for (i, s) in g.sites.iter_mut().enumerate() {
            let fresh: f64 = noise.sample(StandardNormal);
            s.1 += own_s * fresh + if i == 2 { sync_s } else { 0.0 };
            s.2 = if i == 2 { own_s.hypot(sync_s) } else { own_s };
        }
        g.sync_var = vec![0.0, 0.0, sync_s * sync_s];
        f.on_tdoa(&g, t, &mut out);
        f.advance(t, &mut out);
        for o in out.drain(..) {
            let Output::Track(r) = o else { continue };
            if r.est.t < 130.0 {
                continue;
            }
            nees_all.push(nees(&r, at(r.est.t)));
        }
    }
    assert!(f.stats().tdoa > 200, "{:?}", f.stats());
    assert!(nees_all.len() > 100, "{} estimates", nees_all.len());
    let mean = nees_all.iter().sum::<f64>() / nees_all.len() as f64;
    assert!(mean < 2.5, "mean NEES {mean:.1} over {}", nees_all.len());
}

/// The same for a fix: an ADS-B aircraft's fixes whose clock synchronisation
/// error stays (here half their variance, a bias of one sigma of it) are
/// counted by its track's memory, the fuser saying how many share it; taken
/// as fresh, the track averages them with its ADS-B and sits off.
#[test]
fn a_fixs_sync_error_that_stays_is_not_averaged_away_by_a_track() {
    let (fix_m, share): (f64, f64) = (20.0, 0.5);
    let mean_nees = |counted: bool| {
        let mut f = Fuser::new(FuseConfig::default(), TrackConfig::default(), false);
        let mut out = Vec::new();
        let mut noise = rand::rngs::StdRng::seed_from_u64(11);
        let bias = [fix_m * share.sqrt(), -fix_m * share.sqrt()];
        let fresh_m = fix_m * (1.0 - share).sqrt();
        let mut nees_all = Vec::new();
        for k in 0..240 {
            let t = 100.0 + 0.5 * k as f64;
            f.on_measurement(1, Some(8), noisy_adsb(t, &mut noise), t, &mut out);
            if k % 2 == 1 {
                let mut m = fix_off(t, bias, fresh_m, fix_m, &mut noise);
                if let Observation::Position { persistent, .. } = &mut m.obs {
                    // The fuser fills in how many fixes share it.
                    persistent.share = if counted { share } else { 0.0 };
                }
                f.on_measurement(1, None, m, t, &mut out);
            }
            f.advance(t, &mut out);
            for o in out.drain(..) {
                let Output::Track(r) = o else { continue };
                if r.est.t >= 130.0 {
                    nees_all.push(nees(&r, at(r.est.t)));
                }
            }
        }
        assert!(nees_all.len() > 100, "{} estimates", nees_all.len());
        nees_all.iter().sum::<f64>() / nees_all.len() as f64
    };
    let (counted, fresh) = (mean_nees(true), mean_nees(false));
    eprintln!("a fix's lasting sync error: mean NEES counted {counted:.2}, taken as fresh {fresh:.2}");
    assert!(counted < 3.0, "counted: mean NEES {counted:.2}");
    assert!(fresh > 1.5 * counted, "taken as fresh: mean NEES {fresh:.2} against {counted:.2}");
}

/// An ADS-B aircraft's fixes from clocks synchronised on its own ADS-B
/// (`adsb_echo` 0.9): the fused track, which has that ADS-B, counts only
/// the tenth that is news; its MLAT-only track, which has no ADS-B, takes
/// each fix at its covariance. Inflated there too, that track's NEES was a
/// fraction of its 2 (the MLAT-only tracks of every world underconfident,
/// most on the sparse networks, where each aircraft's ADS-B synchronises
/// its own receivers' clocks).
#[test]
fn a_fix_echoing_its_aircrafts_adsb_is_news_to_the_mlat_only_track() {
    let fix_m = 60.0;
    let mut f = Fuser::new(FuseConfig::default(), TrackConfig::default(), true);
    let (mut out, mut noise) = (Vec::new(), rand::rngs::StdRng::seed_from_u64(13));
    let mut nees_by: [Vec<f64>; 3] = Default::default();
    for k in 0..360 {
        let t = 100.0 + 0.5 * k as f64;
        f.on_measurement(1, Some(8), noisy_adsb(t, &mut noise), t, &mut out);
        if k % 2 == 1 {
            let mut m = fix_off(t, [0.0, 0.0], fix_m, fix_m, &mut noise);
            if let Observation::Position { adsb_echo, .. } = &mut m.obs {
                *adsb_echo = 0.9;
            }
            f.on_measurement(1, None, m, t, &mut out);
        }
        f.advance(t, &mut out);
        for o in out.drain(..) {
            let Output::Track(r) = o else { continue };
            if r.est.t >= 130.0 {
                nees_by[r.source as usize].push(nees(&r, at(r.est.t)));
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let mlat = &nees_by[TrackSource::Mlat as usize];
    assert!(mlat.len() > 100, "{} MLAT-only estimates", mlat.len());
    let (mlat_nees, fused_nees) = (mean(mlat), mean(&nees_by[TrackSource::Fused as usize]));
    assert!((1.4..2.8).contains(&mlat_nees), "MLAT-only track: mean NEES {mlat_nees:.2}");
    assert!(fused_nees < 2.8, "fused track: mean NEES {fused_nees:.2}");
}
