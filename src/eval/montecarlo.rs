//! Monte Carlo evaluation: one scenario simulated under many seeds, each run
//! through the core once per fusion method, errors pooled per source.
//!
//! Everything stays in memory (simulate into a buffer, run the core over
//! it, evaluate the event stream) and seeds are spread over threads; the
//! per-seed work is the same code `sim`, `run --capture` and `eval` run.
//!
//! Consistency is judged two ways. The pooled mean NEES over every published
//! estimate has a chi-square band that assumes independent samples; the
//! errors of one run are correlated in time, so that band is narrower than
//! the mean's real spread. The textbook Monte Carlo test (Bar-Shalom, Li and
//! Kirubarajan, 5.4) takes one sample per run at each epoch (here: each two
//! seconds of the scenario), averages over the runs, and compares that average with
//! the band of chi-square(2N)/N; about 95% of epochs should fall inside.

use std::collections::BTreeMap;

use anyhow::Result;
use serde::Serialize;

use super::{evaluate, nees_band, Truth};
use crate::core::{Core, CoreConfig};
use crate::feed::capture::CaptureReader;
use crate::fuse::Method;
use crate::publish::json::write_event;
use crate::sim::scenario::Scenario;

/// One pooled row: a source (`fused/<method>`, `adsb`, `mlat`, ...).
#[derive(Clone, Debug, Default, Serialize)]
pub struct McRow {
    pub source: String,
    pub n: usize,
    pub h_rmse_m: f64,
    pub nees: Option<f64>,
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
    nees_sum: f64,
    nees_n: usize,
    per_seed: Vec<f64>,
    /// Per epoch: sum of the runs' NEES and their number.
    epochs: BTreeMap<u32, (f64, usize)>,
}

/// Runs the core over a capture held in memory; the event stream as JSON lines.
pub fn run_in_memory(capture: &[u8], cfg: &CoreConfig) -> Result<Vec<u8>> {
    let mut reader = CaptureReader::new(capture, "capture");
    let mut core = Core::new(cfg);
    let mut events = Vec::new();
    let mut out = Vec::new();
    while let Some(rec) = reader.next_record()? {
        core.on_record(rec, &mut events);
        for ev in events.drain(..) {
            write_event(&mut out, &ev, |i| core.receiver_id(i))?;
        }
    }
    core.finish(&mut events);
    for ev in events.drain(..) {
        write_event(&mut out, &ev, |i| core.receiver_id(i))?;
    }
    Ok(out)
}

fn one_seed(scenario: &Scenario, cfg: &CoreConfig, methods: &[Method], seed: u64) -> Result<Vec<SeedRow>> {
    let mut s = scenario.clone();
    s.seed = seed;
    let (mut capture, mut truth_text) = (Vec::new(), Vec::new());
    crate::sim::simulate(&s, &mut capture, &mut truth_text)?;
    let truth = Truth::read(truth_text.as_slice())?;
    let mut rows = Vec::new();
    for (k, &method) in methods.iter().enumerate() {
        let mut c = cfg.clone();
        c.fuse.method = method;
        // Single-source rows once: they do not depend on the method.
        c.publish_source_tracks = k == 0;
        let stream = run_in_memory(&capture, &c)?;
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
    cfg: &CoreConfig,
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
                a.nees_sum += nees_sum;
                a.nees_n += nees_n;
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
                nees: (a.nees_n > 0).then(|| a.nees_sum / a.nees_n as f64),
                nees_band: (a.nees_n > 0).then(|| nees_band(a.nees_n, 2.0)),
                epochs_in_band: epochs_in_band(&a.epochs, runs),
                seeds: a.per_seed.len(),
                rmse_sd_m: var.sqrt(),
            }
        })
        .collect())
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
    use rand_distr::ChiSquared;

    /// 100 runs x 40 epochs of chi-square(2) NEES, multiplied by `scale`.
    fn epochs(scale: f64) -> BTreeMap<u32, (f64, usize)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let chi = ChiSquared::new(2.0).unwrap();
        (0..40).map(|k| (k, ((0..100).map(|_| scale * rng.sample(chi)).sum(), 100))).collect()
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
