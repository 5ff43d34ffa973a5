//! Monte Carlo evaluation: one scenario simulated under many seeds, each run
//! through the core once per fusion method, errors pooled per source.
//!
//! Everything stays in memory (simulate into a buffer, run the core over
//! it, evaluate the event stream) and seeds are spread over threads; the
//! per-seed work is the same code `sim`, `run --capture` and `eval` run.

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
    /// Seeds whose own RMSE was computed for this source, and the spread of those RMSEs.
    pub seeds: usize,
    pub rmse_sd_m: f64,
}

/// Per seed and source: (source, squared-error sum, n, NEES sum, NEES n).
type SeedRow = (String, f64, usize, f64, usize);

#[derive(Default)]
struct Acc {
    sse: f64,
    n: usize,
    nees_sum: f64,
    nees_n: usize,
    per_seed: Vec<f64>,
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
            rows.push((
                name,
                r.h_rmse_m * r.h_rmse_m * r.n as f64,
                r.n,
                r.nees.unwrap_or(0.0) * nees_n as f64,
                nees_n,
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
            for (name, sse, n, nees_sum, nees_n) in seed_rows {
                let a = accs.entry(name).or_default();
                a.sse += sse;
                a.n += n;
                a.nees_sum += nees_sum;
                a.nees_n += nees_n;
                if n > 0 {
                    a.per_seed.push((sse / n as f64).sqrt());
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
                seeds: a.per_seed.len(),
                rmse_sd_m: var.sqrt(),
            }
        })
        .collect())
}

/// The table printed by `eval --scenario FILE --seeds N`.
pub fn table(rows: &[McRow]) -> String {
    let mut s = format!(
        "{:<22} {:>8} {:>9} {:>11} {:>8} {:>17} {:>6}\n",
        "source", "n", "h_rmse_m", "(seed sd)", "nees", "nees_95%", "seeds"
    );
    for r in rows {
        s += &format!(
            "{:<22} {:>8} {:>9.2} {:>11} {:>8} {:>17} {:>6}\n",
            r.source,
            r.n,
            r.h_rmse_m,
            format!("({:.2})", r.rmse_sd_m),
            r.nees.map_or("-".into(), |x| format!("{x:.2}")),
            r.nees_band.map_or("-".into(), |b| format!("[{:.2}, {:.2}]", b[0], b[1])),
            r.seeds
        );
    }
    s
}
