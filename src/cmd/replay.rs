//! `fuse1090 replay CAPTURE --config FILE [--speed X]`.

use std::path::Path;

use anyhow::{bail, Result};

use crate::config::Config;

pub fn run(capture: &Path, config: &Path, speed: f64) -> Result<()> {
    if !(speed > 0.0 && speed.is_finite()) {
        bail!("--speed {speed}: must be positive");
    }
    let cfg = Config::load(config)?;
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let sent = rt.block_on(crate::live::replay::replay(capture, &cfg, speed))?;
    eprintln!("replay: {sent} frames sent");
    Ok(())
}
