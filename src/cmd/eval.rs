//! `fuse1090 eval --truth TRUTH --tracks OUT.jsonl [--json]`.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use anyhow::{Context, Result};

use crate::eval::{evaluate, Truth};

pub fn run(truth: &Path, tracks: &Path, json: bool) -> Result<()> {
    let open =
        |p: &Path| File::open(p).map(BufReader::new).with_context(|| format!("cannot open {}", p.display()));
    let truth = Truth::read(open(truth)?)?;
    let report = evaluate(&truth, open(tracks)?)?;
    let text = if json { serde_json::to_string_pretty(&report)? + "\n" } else { report.to_string() };
    super::print_stdout(&text)
}
