//! Monte Carlo evaluation: one scenario simulated under many seeds, each run
//! through the core once per fusion method, errors pooled per source.
//!
//! Everything stays in memory (simulate into a buffer, run the core over
//! it, evaluate the event stream) and seeds are spread over threads; the
//! per-seed work is the same code `sim`, `run --capture` and `eval` run.
//!
//! Consistency is judged two ways. The pooled mean NEES over every published
//! estimate is compared with a band around 2 whose width comes from the runs
//! themselves: the runs are independent but one run's errors are correlated
//! in time, so the chi-square band of that many independent samples is far
//! narrower than the mean's real spread (on fusion-8seg a consistent filter's
//! pooled mean moves by about 0.1 from one set of 100 seeds to the next,
//! ten times that band's half-width). The pooled mean is a ratio of per-run
//! sums, and its standard error is the one of a ratio estimator over
//! independent clusters (batch means). The textbook Monte Carlo test
//! (Bar-Shalom, Li and Kirubarajan, 5.4) takes one sample per run at each
//! epoch (here: each two seconds of the scenario), averages over the runs,
//! and compares that average with the band of chi-square(2N)/N; about 95% of
//! epochs should fall inside.

use std::collections::BTreeMap;

use anyhow::Result;
use serde::Serialize;
use statrs::distribution::{ContinuousCDF, StudentsT};

use super::{evaluate, nees_band, Truth};
use crate::sim::scenario::Scenario;
use fuse1090_core::core::front::KnownReceiver;
use fuse1090_core::core::{Core, CoreConfig};
use fuse1090_core::feed::capture::CaptureReader;
use fuse1090_core::fuse::Method;
use fuse1090_core::publish::json::write_event;

/// One pooled row: a source (`fused/<method>`, `adsb`, `mlat`, ...).
#[derive(Clone, Debug, Default, Serialize)]
pub struct McRow {
    pub source: String,
    pub n: usize,
    pub h_rmse_m: f64,
    pub nees: Option<f64>,
    /// 95% band of the pooled mean NEES of a consistent filter, from the
    /// spread between the runs (see the module's doc).
    pub nees_band: Option<[f64; 2]>,
    /// Share of the epochs (two-second spans of the scenario seen by at
    /// least 90% of the runs) whose mean NEES over the runs is inside its N-run band.
    pub epochs_in_band: Option<f64>,
    /// Seeds whose own RMSE was computed for this source, and the spread of those RMSEs.
    pub seeds: usize,
    pub rmse_sd_m: f64,
}

/// Epochs of the per-epoch test (s): tracks publish about once a second at
/// times of their own, so two seconds hold a sample of nearly every run.
const EPOCH_S: f64 = 2.0;

/// Per seed and source: (source, squared-error sum, n, NEES sum, NEES n,
/// the first NEES of each epoch of the scenario).
type SeedRow = (String, f64, usize, f64, usize, BTreeMap<u32, f64>);

#[derive(Default)]
struct Acc {
    sse: f64,
    n: usize,
    per_seed: Vec<f64>,
    /// Per run: NEES sum and number of samples.
    nees_per_seed: Vec<(f64, usize)>,
    /// Per epoch: sum of the runs' NEES and their number.
    epochs: BTreeMap<u32, (f64, usize)>,
}

/// Runs the core over a capture held in memory; the event stream as JSON lines.
pub fn run_in_memory(capture: &[u8], cfg: &CoreConfig) -> Result<Vec<u8>> {
    run_in_memory_knowing(capture, cfg, &[])
}

/// [`run_in_memory`] with receivers described by the configuration
/// (`[[receiver]]`: their positions and, where given, their timing), as
/// `run --capture` takes them.
pub fn run_in_memory_knowing(capture: &[u8], cfg: &CoreConfig, known: &[KnownReceiver]) -> Result<Vec<u8>> {
    let mut reader = CaptureReader::new(capture, "capture");
    let mut core = Core::new(cfg);
    core.know(known.to_vec());
    let mut out = Vec::new();
    let mut write = |core: &mut Core| {
        while let Some(ev) = core.poll_event() {
            write_event(&mut out, &ev, |i| core.receiver_id(i));
        }
    };
    while let Some(rec) = reader.next_record()? {
        core.handle_record(rec);
        write(&mut core);
    }
    core.finish();
    write(&mut core);
    Ok(out)
}

/// What every run of a Monte Carlo is given: the core's configuration and
/// the receivers the configuration describes.
#[derive(Clone, Copy)]
pub struct RunConfig<'a> {
    pub core: &'a CoreConfig,
    pub known: &'a [KnownReceiver],
}

fn one_seed(scenario: &Scenario, cfg: RunConfig, methods: &[Method], seed: u64) -> Result<Vec<SeedRow>> {
    let mut s = scenario.clone();
    s.seed = seed;
    let (mut capture, mut truth_text) = (Vec::new(), Vec::new());
    crate::sim::simulate(&s, &mut capture, &mut truth_text)?;
    let truth = Truth::read(truth_text.as_slice())?;
    let mut rows = Vec::new();
    for (k, &method) in methods.iter().enumerate() {
        let mut c = cfg.core.clone();
        c.fuse.method = method;
        // Single-source rows once: they do not depend on the method.
        c.publish_source_tracks = k == 0;
        let stream = run_in_memory_knowing(&capture, &c, cfg.known)?;
        let report = evaluate(&truth, stream.as_slice())?;
        for r in report.overall {
            if k > 0 && r.source != "fused" {
                continue;
            }
            let name =
                if r.source == "fused" { format!("fused/{}", method.name()) } else { r.source.clone() };
            let nees_n = if r.nees.is_some() { r.n } else { 0 };
            let mut epochs = BTreeMap::new();
            for &(t, nees) in &r.nees_samples {
                let k = ((t - s.start_unix).max(0.0) / EPOCH_S) as u32;
                epochs.entry(k).or_insert(nees);
            }
            rows.push((
                name,
                r.h_rmse_m * r.h_rmse_m * r.n as f64,
                r.n,
                r.nees.unwrap_or(0.0) * nees_n as f64,
                nees_n,
                epochs,
            ));
        }
    }
    Ok(rows)
}

/// Pools `seeds` runs of the scenario for each method.
pub fn monte_carlo(
    scenario: &Scenario,
    cfg: RunConfig,
    methods: &[Method],
    seeds: std::ops::Range<u64>,
) -> Result<Vec<McRow>> {
    let seeds: Vec<u64> = seeds.collect();
    let runs = seeds.len();
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get()).min(seeds.len().max(1));
    let chunks: Vec<Vec<u64>> =
        (0..threads).map(|t| seeds.iter().copied().skip(t).step_by(threads).collect()).collect();
    let results: Vec<Result<Vec<Vec<SeedRow>>>> = std::thread::scope(|scope| {
        let handles: Vec<_> = chunks
            .iter()
            .map(|chunk| {
                scope.spawn(move || chunk.iter().map(|&s| one_seed(scenario, cfg, methods, s)).collect())
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("Monte Carlo worker panicked")).collect()
    });
    let mut accs: BTreeMap<String, Acc> = BTreeMap::new();
    for chunk in results {
        for seed_rows in chunk? {
            for (name, sse, n, nees_sum, nees_n, epochs) in seed_rows {
                let a = accs.entry(name).or_default();
                a.sse += sse;
                a.n += n;
                if nees_n > 0 {
                    a.nees_per_seed.push((nees_sum, nees_n));
                }
                if n > 0 {
                    a.per_seed.push((sse / n as f64).sqrt());
                }
                for (k, nees) in epochs {
                    let e = a.epochs.entry(k).or_default();
                    e.0 += nees;
                    e.1 += 1;
                }
            }
        }
    }
    Ok(accs
        .into_iter()
        .map(|(source, a)| {
            let mean = a.per_seed.iter().sum::<f64>() / a.per_seed.len().max(1) as f64;
            let var = a.per_seed.iter().map(|x| (x - mean).powi(2)).sum::<f64>()
                / (a.per_seed.len().max(2) - 1) as f64;
            McRow {
                source,
                n: a.n,
                h_rmse_m: (a.sse / a.n.max(1) as f64).sqrt(),
                nees: pooled_nees(&a.nees_per_seed),
                nees_band: runs_band(&a.nees_per_seed, 2.0),
                epochs_in_band: epochs_in_band(&a.epochs, runs),
                seeds: a.per_seed.len(),
                rmse_sd_m: var.sqrt(),
            }
        })
        .collect())
}

/// Pooled mean NEES (`sum of sums / sum of counts`) of runs given as each
/// run's NEES sum and count; `None` without any sample.
pub fn pooled_nees(per_run: &[(f64, usize)]) -> Option<f64> {
    let (sum, n) = per_run.iter().fold((0.0, 0), |(s, k), r| (s + r.0, k + r.1));
    (n > 0).then(|| sum / n as f64)
}

/// 95% band of the pooled mean NEES (`sum of sums / sum of counts`) of a
/// consistent filter with `dof` degrees of freedom, given each run's NEES
/// sum and count: `dof` plus or minus Student's t times the ratio
/// estimator's standard error over the runs (from 0 at the least). `None`
/// with fewer than two runs.
pub fn runs_band(per_run: &[(f64, usize)], dof: f64) -> Option<[f64; 2]> {
    let runs = per_run.len();
    let total: usize = per_run.iter().map(|r| r.1).sum();
    if runs < 2 || total == 0 {
        return None;
    }
    let mean = per_run.iter().map(|r| r.0).sum::<f64>() / total as f64;
    let ss: f64 = per_run.iter().map(|&(sum, n)| (sum - mean * n as f64).powi(2)).sum();
    let se = (ss * runs as f64 / (runs - 1) as f64).sqrt() / total as f64;
    let t = StudentsT::new(0.0, 1.0, (runs - 1) as f64).ok()?.inverse_cdf(0.975);
    // A NEES is never negative: a band reaching below zero has no lower limit.
    Some([(dof - t * se).max(0.0), dof + t * se])
}

/// The textbook N-run test over the epochs most runs saw.
fn epochs_in_band(epochs: &BTreeMap<u32, (f64, usize)>, runs: usize) -> Option<f64> {
    let full: Vec<_> = epochs.values().filter(|(_, n)| *n * 10 >= runs * 9).collect();
    let inside = full
        .iter()
        .filter(|(sum, n)| {
            let b = nees_band(*n, 2.0);
            (b[0]..=b[1]).contains(&(sum / *n as f64))
        })
        .count();
    (!full.is_empty()).then(|| inside as f64 / full.len() as f64)
}

/// The table printed by `eval --scenario FILE --seeds N`.
pub fn table(rows: &[McRow]) -> String {
    let mut s = format!(
        "{:<22} {:>8} {:>9} {:>11} {:>8} {:>17} {:>10} {:>6}\n",
        "source", "n", "h_rmse_m", "(seed sd)", "nees", "nees_95%", "epochs_in", "seeds"
    );
    for r in rows {
        s += &format!(
            "{:<22} {:>8} {:>9.2} {:>11} {:>8} {:>17} {:>10} {:>6}\n",
            r.source,
            r.n,
            r.h_rmse_m,
            format!("({:.2})", r.rmse_sd_m),
            r.nees.map_or("-".into(), |x| format!("{x:.2}")),
            r.nees_band.map_or("-".into(), |b| format!("[{:.2}, {:.2}]", b[0], b[1])),
            r.epochs_in_band.map_or("-".into(), |x| format!("{:.0}%", 100.0 * x)),
            r.seeds
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{ChiSquared, StandardNormal};

    /// 100 runs x 40 epochs of chi-square(2) NEES, multiplied by `scale`.
    fn epochs(scale: f64) -> BTreeMap<u32, (f64, usize)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let chi = ChiSquared::new(2.0).unwrap();
        (0..40).map(|k| (k, ((0..100).map(|_| scale * rng.sample(chi)).sum(), 100))).collect()
    }

    /// How often each band holds the pooled mean of 100 runs x 60 epochs of
    /// 2-D errors that are AR(1) in time (correlation 0.9 from one epoch to
    /// the next, like a track's), with covariance `scale` times the claimed
    /// one: (runs band, chi-square band of independent samples).
    fn coverage(scale: f64, repetitions: u64) -> (f64, f64) {
        let (mut runs_in, mut naive_in) = (0, 0);
        for rep in 0..repetitions {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(rep);
            let rho: f64 = 0.9;
            let per_run: Vec<(f64, usize)> = (0..100)
                .map(|_| {
                    let mut e = [rng.sample::<f64, _>(StandardNormal), rng.sample(StandardNormal)];
                    let mut sum = 0.0;
                    for _ in 0..60 {
                        for x in &mut e {
                            *x = rho * *x + (1.0 - rho * rho).sqrt() * rng.sample::<f64, _>(StandardNormal);
                        }
                        sum += scale * (e[0] * e[0] + e[1] * e[1]);
                    }
                    (sum, 60)
                })
                .collect();
            let mean = per_run.iter().map(|r| r.0).sum::<f64>() / 6000.0;
            let b = runs_band(&per_run, 2.0).unwrap();
            runs_in += (b[0]..=b[1]).contains(&mean) as u32;
            let b = nees_band(6000, 2.0);
            naive_in += (b[0]..=b[1]).contains(&mean) as u32;
        }
        (runs_in as f64 / repetitions as f64, naive_in as f64 / repetitions as f64)
    }

    #[test]
    fn the_runs_band_holds_a_consistent_filter_with_correlated_errors_and_rejects_a_miscalibrated_one() {
        let (runs, naive) = coverage(1.0, 300);
        assert!(runs >= 0.9, "a consistent filter inside its runs band in {runs} of the repetitions");
        assert!(naive < 0.75, "the independence band should be too narrow here: {naive}");
        let (over, _) = coverage(1.2, 100);
        assert!(over < 0.1, "20% overconfident inside the runs band in {over} of the repetitions");
        let (under, _) = coverage(0.8, 100);
        println!("runs band holds: consistent {runs}, 1.2x {over}, 0.8x {under}; independence band: {naive}");
        assert!(under < 0.1, "20% conservative inside the runs band in {under} of the repetitions");
        assert_eq!(runs_band(&[(4.0, 2)], 2.0), None);
    }

    #[test]
    fn the_per_epoch_test_passes_a_consistent_filter_and_fails_a_miscalibrated_one() {
        let consistent = epochs_in_band(&epochs(1.0), 100).unwrap();
        assert!(consistent >= 0.85, "{consistent}");
        // 30% over- or under-confidence leaves most epochs outside.
        assert!(epochs_in_band(&epochs(1.3), 100).unwrap() < 0.5);
        assert!(epochs_in_band(&epochs(0.7), 100).unwrap() < 0.5);
        // Epochs most runs did not reach are left out.
        let mut sparse = epochs(1.0);
        sparse.insert(99, (1000.0, 3));
        assert_eq!(epochs_in_band(&sparse, 100), Some(consistent));
    }
}
