//! Multilateration costs: solver fixes/s for 4, 6 and 10 receivers (with an
//! altitude constraint, from a guess as the engine does for tracked
//! aircraft, and cold from Bancroft), and clock-pair filter updates/s.
//!
//! Run: `cargo bench --bench mlat`.

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fuse1090::geo::geodetic_to_ecef;
use fuse1090::mlat::clock::{PairFilter, PairParams};
use fuse1090::mlat::solver::{solve, AltitudeConstraint, Measurement, SolverLimits, C_AIR};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

fn groups(n_rx: usize, count: usize) -> Vec<(Vec<Measurement>, [f64; 3])> {
    let mut rng = ChaCha8Rng::seed_from_u64(n_rx as u64);
    let noise = Normal::new(0.0, 83e-9).unwrap();
    let rx: Vec<[f64; 3]> = (0..n_rx)
        .map(|k| {
            let a = k as f64 / n_rx as f64 * std::f64::consts::TAU;
            geodetic_to_ecef(48.8 + 0.5 * a.cos(), 2.3 + 0.7 * a.sin(), 100.0 + 10.0 * k as f64)
        })
        .collect();
    (0..count)
        .map(|i| {
            let t = geodetic_to_ecef(48.6 + 0.001 * i as f64, 2.1 + 0.0007 * i as f64, 9000.0);
            let ms = rx
                .iter()
                .map(|&r| {
                    let d = ((t[0] - r[0]).powi(2) + (t[1] - r[1]).powi(2) + (t[2] - r[2]).powi(2)).sqrt();
                    Measurement { pos: r, t: 100.0 + d / C_AIR + noise.sample(&mut rng), sigma_t: 83e-9 }
                })
                .collect();
            let guess = geodetic_to_ecef(48.6 + 0.001 * i as f64 + 0.002, 2.1 + 0.0007 * i as f64, 9000.0);
            (ms, guess)
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let limits = SolverLimits::default();
    let alt = Some(AltitudeConstraint { h_m: 9000.0, sigma_m: 75.0 });
    let mut g = c.benchmark_group("solver");
    for n in [4usize, 6, 10] {
        let gs = groups(n, 1000);
        g.throughput(Throughput::Elements(gs.len() as u64));
        g.bench_with_input(BenchmarkId::new("tracked", n), &gs, |b, gs| {
            b.iter(|| {
                gs.iter()
                    .filter(|(ms, guess)| solve(black_box(ms), alt, Some(*guess), &limits).is_ok())
                    .count()
            })
        });
        g.bench_with_input(BenchmarkId::new("cold", n), &gs, |b, gs| {
            b.iter(|| gs.iter().filter(|(ms, _)| solve(black_box(ms), alt, None, &limits).is_ok()).count())
        });
    }
    g.finish();

    let params = PairParams::default();
    let mut g = c.benchmark_group("clock_sync");
    g.throughput(Throughput::Elements(10_000));
    g.bench_function("pair_update", |b| {
        b.iter(|| {
            let mut f = PairFilter::new(10.0, 1e-14, 0.0, 0.0, &params);
            for k in 1..10_000 {
                let t = k as f64 * 0.05;
                f.update(black_box(10.0 + 20e-6 * t), 1e-14, t, t, &params);
            }
            f.drift()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
