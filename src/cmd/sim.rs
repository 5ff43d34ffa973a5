//! `fuse1090 sim --scenario FILE --out DIR`: writes DIR/capture.txt,
//! DIR/truth.jsonl and DIR/oracle.toml (every receiver's true position and
//! timing, as a configuration for an oracle run).

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use anyhow::{Context, Result};

use crate::sim::scenario::Scenario;
use crate::sim::simulate;

pub fn run(scenario: &Path, out: &Path) -> Result<()> {
    let s = Scenario::load(scenario)?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let create = |name: &str| -> Result<BufWriter<File>> {
        let p = out.join(name);
        Ok(BufWriter::with_capacity(
            1 << 20,
            File::create(&p).with_context(|| format!("cannot create {}", p.display()))?,
        ))
    };
    let stats = simulate(&s, create("capture.txt")?, create("truth.jsonl")?)?;
    let oracle = out.join("oracle.toml");
    std::fs::write(&oracle, crate::sim::oracle_config(&s))
        .with_context(|| format!("cannot write {}", oracle.display()))?;
    super::print_stdout(&format!(
        "sim: {} receivers, {} aircraft, {} transmissions, {} receptions, {} truth lines -> {}\n",
        stats.receivers,
        stats.aircraft,
        stats.transmissions,
        stats.receptions,
        stats.truth_lines,
        out.display()
    ))
}
