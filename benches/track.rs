//! Tracking costs: one IMM step (3 models: CV and a left/right coordinated
//! turn; and 4 with constant acceleration) with a position update; one
//! track update with the time differences of a transmission three receivers
//! heard (the augmented unscented transform, default IMM); and the whole
//! per-aircraft tracker (default configuration: IMM with VB noise, in-order
//! history, publication) over 1,000 aircraft, as measurements and tracks per
//! second.
//!
//! Run: `cargo bench --bench track`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use fuse1090::track::{Gaussian, Imm, MotionModel, PosMeasurement};
use nalgebra::{Matrix2, Matrix6, Vector2, Vector6};

fn imm(n: usize) -> Imm {
    let w = 3f64.to_radians();
    let mut models = vec![
        MotionModel::ConstantVelocity { q: 0.05 },
        MotionModel::CoordinatedTurn { omega: w, q: 0.05 },
        MotionModel::CoordinatedTurn { omega: -w, q: 0.05 },
        MotionModel::ConstantAcceleration { q: 0.5 },
    ];
    models.truncate(n);
    let init = Gaussian {
        x: Vector6::new(0.0, 0.0, 100.0, 50.0, 0.0, 0.0),
        p: Matrix6::from_diagonal(&Vector6::new(500.0, 500.0, 100.0, 100.0, 9.0, 9.0)),
    };
    Imm::new(models, Imm::sticky(n, 0.9), init)
}

/// A position at 9 km, 20 m per axis, from a GPS-timed report.
fn position(lat: f64, lon: f64) -> fuse1090::track::Observation {
    fuse1090::track::Observation::Position {
        lat,
        lon,
        cov_en: Matrix2::identity() * 400.0,
        height: Some((9000.0, 64.0)),
        time_sigma_s: 0.01,
        surface: false,
        claimed: true,
        persistent: fuse1090::track::SharedShare::default(),
        adsb_echo: 0.0,
    }
}

fn bench(c: &mut Criterion) {
    let r = Matrix2::identity() * 500.0;
    let mut g = c.benchmark_group("imm");
    g.throughput(Throughput::Elements(1000));
    for n in [3usize, 4] {
        g.bench_function(format!("update_{n}_models"), |b| {
            b.iter_batched(
                || imm(n),
                |mut f| {
                    for k in 1..=1000 {
                        let t = k as f64 * 0.5;
                        let z = Vector2::new(100.0 * t, 50.0 * t);
                        black_box(f.step(0.5, &PosMeasurement { z, r }));
                    }
                    f
                },
                criterion::BatchSize::SmallInput,
            )
        });
    }
    g.finish();

    // Time differences from three receivers into a default track, 1,000 in a row.
    use fuse1090::geo::{displace, geodetic_to_ecef};
    use fuse1090::track::{Measurement, Observation, Source, Track, TrackConfig};
    let cfg = std::sync::Arc::new(TrackConfig::default());
    let sites = [(44.0, 1.0), (44.3, 1.5), (43.8, 1.6)].map(|(lat, lon)| geodetic_to_ecef(lat, lon, 100.0));
    let at = |t: f64| displace(44.0, 1.2, 9000.0, [100.0 * t, 50.0 * t, 0.0]);
    let started = || {
        let mut tr = Track::new(cfg.clone(), cfg.imm_spec());
        for k in 0..4 {
            let t = k as f64 * 0.5;
            let (lat, lon, _) = at(t);
            tr.apply(Measurement { t, source: Source::Mlat, obs: position(lat, lon) });
        }
        tr
    };
    let mut g = c.benchmark_group("tdoa");
    g.throughput(Throughput::Elements(1000));
    g.bench_function("three_receivers", |b| {
        b.iter_batched(
            started,
            |mut tr| {
                for k in 0..1000 {
                    let t = 2.0 + k as f64 * 0.5;
                    let (lat, lon, h) = at(t);
                    let p = geodetic_to_ecef(lat, lon, h);
                    let toa =
                        |s: [f64; 3]| t + fuse1090::geo::ecef_distance(p, s) / fuse1090::mlat::solver::C_AIR;
                    let sites = sites.map(|s| (s, toa(s), 50e-9));
                    let o = tr.apply(Measurement {
                        t,
                        source: Source::Mlat,
                        obs: Observation::Tdoa { n: 3, sites, persistent: Default::default() },
                    });
                    // Applied, not gated: the bench measures the update.
                    assert!(matches!(o, fuse1090::track::Outcome::Applied { .. }), "{o:?}");
                }
                tr
            },
            criterion::BatchSize::SmallInput,
        )
    });
    g.finish();

    // The particle filter of an aircraft heard by too few receivers: one
    // update (move, weigh, resample when due) of its default 1,000 particles
    // by the same three sites' time differences.
    use fuse1090::track::particle::{SparseConfig, SparseTrack};
    let pcfg = SparseConfig::default();
    let toas = |t: f64| {
        let (lat, lon, h) = at(t);
        let p = geodetic_to_ecef(lat, lon, h);
        sites.map(|s| (s, t + fuse1090::geo::ecef_distance(p, s) / fuse1090::mlat::solver::C_AIR, 50e-9))
    };
    let mut g = c.benchmark_group("particle");
    g.throughput(Throughput::Elements(100));
    g.bench_function("update_1000_particles", |b| {
        b.iter_batched(
            || SparseTrack::start(&pcfg, &toas(0.0), None, 0.0, 9000.0, 1).expect("placed"),
            |mut s| {
                for k in 1..=100 {
                    let t = k as f64 * 0.5;
                    black_box(s.update(&pcfg, &toas(t), None, t, 9000.0));
                }
                s
            },
            criterion::BatchSize::SmallInput,
        )
    });
    // A Comm-B velocity report (2 m/s per axis): the first, which the
    // cloud, its velocities spread over every airliner's, takes in steps,
    // and the next ones, each one step.
    let (v_en, v_cov) = (nalgebra::Vector2::new(100.0, 50.0), nalgebra::Matrix2::identity() * 4.0);
    let tracked = || {
        let mut s = SparseTrack::start(&pcfg, &toas(0.0), None, 0.0, 9000.0, 1).expect("placed");
        for k in 1..=10 {
            let t = k as f64 * 0.5;
            s.update(&pcfg, &toas(t), None, t, 9000.0);
        }
        s
    };
    g.throughput(Throughput::Elements(1));
    g.bench_function("first_velocity_report_1000_particles", |b| {
        b.iter_batched(
            tracked,
            |mut s| {
                black_box(s.velocity(&pcfg, v_en, v_cov, 5.0));
                s
            },
            criterion::BatchSize::SmallInput,
        )
    });
    g.throughput(Throughput::Elements(100));
    g.bench_function("velocity_reports_1000_particles", |b| {
        b.iter_batched(
            || {
                let mut s = tracked();
                s.velocity(&pcfg, v_en, v_cov, 5.0);
                s
            },
            |mut s| {
                for k in 1..=100 {
                    black_box(s.velocity(&pcfg, v_en, v_cov, 5.0 + k as f64 * 0.01));
                }
                s
            },
            criterion::BatchSize::SmallInput,
        )
    });
    g.finish();

    // The full tracker: 1,000 aircraft, one ADS-B position each per step.
    use fuse1090::fuse::{FuseConfig, Fuser};
    let mut g = c.benchmark_group("fuser");
    let aircraft = 1000u32;
    let steps = 20;
    g.throughput(Throughput::Elements((aircraft * steps) as u64));
    g.bench_function("adsb_positions_1000_aircraft", |b| {
        b.iter_batched(
            || Fuser::new(FuseConfig::default(), TrackConfig::default(), false),
            |mut f| {
                let mut out = Vec::new();
                for k in 0..steps {
                    let t = 1000.0 + k as f64 * 0.5;
                    for a in 0..aircraft {
                        let (lat, lon, _) = fuse1090::geo::displace(
                            40.0 + (a % 40) as f64 * 0.1,
                            (a / 40) as f64 * 0.1,
                            9000.0,
                            [100.0 * t, 50.0 * t, 0.0],
                        );
                        let m = Measurement { t, source: Source::Adsb, obs: position(lat, lon) };
                        f.on_measurement(0x400000 + a, Some(8), m, t, &mut out);
                    }
                    out.clear();
                }
                f
            },
            criterion::BatchSize::SmallInput,
        )
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
