//! The live map in a real browser: the demo daemon serves it, Debian's
//! chromium (headless, driven by playwright-core from `web/`) loads it, and
//! `web/test/map.mjs` checks what it draws against the daemon's own
//! `aircraft.json` and `receivers.json`: every aircraft with a position
//! drawn, labelled and rotated to its track, every receiver drawn, a click
//! selecting an aircraft, the table sorting, nothing fetched from elsewhere.
//! The screenshot it takes is `target/map.png` (the README shows one).
//!
//! Without chromium, node or `web/node_modules` (`.ci/run` installs all
//! three) the test says so through `common::skipped`.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use common::live::{daemon, demo, exit_within, wait_for_log, with_http};

/// What the browser check needs, or why it cannot run.
fn browser() -> Result<(PathBuf, PathBuf), String> {
    let chromium = PathBuf::from(std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into()));
    if !chromium.exists() {
        return Err(format!("{} not found (Debian's chromium package)", chromium.display()));
    }
    let web = Path::new(env!("CARGO_MANIFEST_DIR")).join("web");
    if !web.join("node_modules/playwright-core").exists() {
        return Err("web/node_modules/playwright-core not found (cd web && npm ci)".into());
    }
    if Command::new("node").arg("--version").stdout(Stdio::null()).status().is_err() {
        return Err("node not found".into());
    }
    Ok((chromium, web))
}

#[test]
fn the_map_draws_what_aircraft_json_holds() {
    let (chromium, web) = match browser() {
        Ok(found) => found,
        Err(why) => return common::skipped(&why),
    };
    let work = common::scratch("live-map");
    let cfg = work.path().join("c.toml");
    let http = common::free_port();
    let text = demo(common::free_port(), 1.0, "kind = \"stdout\"\n");
    std::fs::write(&cfg, with_http(&text, http, "")).unwrap();
    let log = work.path().join("d.log");
    let mut child = daemon(&cfg, &log, None);
    wait_for_log(&log, "running");

    let shot = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/map.png");
    let mut check = Command::new("node")
        .arg(web.join("test/map.mjs"))
        .arg(format!("http://127.0.0.1:{http}"))
        .arg(&shot)
        .env("CHROMIUM", &chromium)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let status = exit_within(&mut check, Duration::from_secs(120));
    let mut seen = String::new();
    std::io::Read::read_to_string(check.stdout.as_mut().unwrap(), &mut seen).unwrap();
    let _ = child.kill();
    let _ = child.wait();
    println!("{seen}");
    assert!(status.is_some_and(|s| s.success()), "the map check failed ({status:?}): {seen}");
    let seen: serde_json::Value = serde_json::from_str(seen.trim()).unwrap();
    // The demo's eleven aircraft and eight receivers, not an empty page
    // that trivially matches an empty document.
    assert!(seen["drawn"].as_u64() >= Some(8), "{seen}");
    assert_eq!(seen["receivers"], 8, "{seen}");
    assert!(std::fs::metadata(&shot).is_ok_and(|m| m.len() > 10_000), "no screenshot at {}", shot.display());
}
