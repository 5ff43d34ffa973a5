//! `fuse1090 eval --truth TRUTH --tracks OUT.jsonl [--scenario FILE] [--json]`.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use anyhow::{Context, Result};

use crate::eval::{evaluate_with, Geometry, Truth};
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

/// `eval --scenario FILE --seeds N [--config FILE]`: every fusion method over N seeds.
pub fn monte_carlo(scenario: Option<&Path>, seeds: u64, config: Option<&Path>, json: bool) -> Result<()> {
    let scenario = Scenario::load(scenario.context("--seeds needs --scenario")?)?;
    let cfg = match config {
        Some(p) => crate::config::Config::load(p)?,
        None => crate::config::Config::default(),
    };
    let rows =
        crate::eval::montecarlo::monte_carlo(&scenario, &cfg.core, &crate::fuse::Method::ALL, 1..seeds + 1)?;
    let text = if json {
        serde_json::to_string_pretty(&rows)? + "\n"
    } else {
        crate::eval::montecarlo::table(&rows)
    };
    super::print_stdout(&text)
}
