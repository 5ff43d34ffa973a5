//! `fuse1090 eval --truth TRUTH --tracks OUT.jsonl [--scenario FILE] [--json]`.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use anyhow::{Context, Result};

use crate::eval::{evaluate_with, Geometry, Truth};
use crate::fuse::Method;
use crate::mlat::MlatConfig;
use crate::sim::scenario::Scenario;

pub fn run(truth: &Path, tracks: &Path, scenario: Option<&Path>, json: bool) -> Result<()> {
    let open =
        |p: &Path| File::open(p).map(BufReader::new).with_context(|| format!("cannot open {}", p.display()));
    let truth = Truth::read(open(truth)?)?;
    // The bound uses the altitude sigma the solver applies to a fresh altitude.
    let geometry = match scenario {
        Some(p) => Some(Geometry::from_scenario(&Scenario::load(p)?, MlatConfig::default().baro_sigma_m)),
        None => None,
    };
    let report = evaluate_with(&truth, open(tracks)?, geometry.as_ref())?;
    let text = if json { serde_json::to_string_pretty(&report)? + "\n" } else { report.to_string() };
    super::print_stdout(&text)
}

/// `eval --scenario FILE --seeds N [--first-seed S] [--method M] [--config FILE]`.
pub struct MonteCarloArgs<'a> {
    pub scenario: Option<&'a Path>,
    pub seeds: std::ops::Range<u64>,
    /// One fusion method, or all of them.
    pub method: Option<Method>,
    pub config: Option<&'a Path>,
    pub json: bool,
}

/// The fusion methods (or one) over the seeds.
pub fn monte_carlo(args: MonteCarloArgs) -> Result<()> {
    anyhow::ensure!(!args.seeds.is_empty(), "--seeds must be at least 1");
    let scenario = Scenario::load(args.scenario.context("--seeds needs --scenario")?)?;
    let cfg = match args.config {
        Some(p) => crate::config::Config::load(p)?,
        None => crate::config::Config::default(),
    };
    let methods = match args.method {
        Some(m) => vec![m],
        None => Method::ALL.to_vec(),
    };
    // Receivers the configuration describes (an oracle's timing, say) are
    // known to every run, as `run --config` makes them known.
    let known = cfg.known_receivers();
    let run = crate::eval::montecarlo::RunConfig { core: &cfg.core, known: &known };
    let rows = crate::eval::montecarlo::monte_carlo(&scenario, run, &methods, args.seeds)?;
    let text = if args.json {
        serde_json::to_string_pretty(&rows)? + "\n"
    } else {
        crate::eval::montecarlo::table(&rows)
    };
    super::print_stdout(&text)
}
