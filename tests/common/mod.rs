//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

pub mod live;

use fuse1090::feed::{parser_for, FeedEvent, InputFormat, RawFrame};

/// Says that the calling test did not check what it is for, and why. The
/// test harness shows only `ok` for a test that returns early, so the line
/// also goes to the file named by `FUSE1090_SKIP_LOG` (when set), which
/// `.ci/run` prints after the test summary.
pub fn skipped(why: &str) {
    let test = std::thread::current().name().unwrap_or("?").to_string();
    eprintln!("SKIP: {test}: {why}");
    if let Ok(path) = std::env::var("FUSE1090_SKIP_LOG") {
        use std::io::Write;
        let line = format!("{test}: {why}\n");
        // One write of one short line to a file opened for appending: tests
        // that skip side by side do not interleave their lines.
        let file = std::fs::OpenOptions::new().create(true).append(true).open(path);
        if let Ok(mut f) = file {
            let _ = f.write_all(line.as_bytes());
        }
    }
}

/// A file under ../shared/data, or `None` (saying so through [`skipped`])
/// when the shared folder is absent, as it is in a user's clone.
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    if p.exists() {
        Some(p)
    } else {
        skipped(&format!("{} not found (../shared is absent)", p.display()));
        None
    }
}

/// A Python that imports `module` (`FUSE1090_PYTHON`, else the `.venv` that
/// `.ci/run` fills), or `None`, saying so through [`skipped`] with `unchecked`.
pub fn python_with(module: &str, unchecked: &str) -> Option<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let candidates =
        [std::env::var("FUSE1090_PYTHON").ok().map(PathBuf::from), Some(root.join(".venv/bin/python"))];
    for p in candidates.into_iter().flatten() {
        let ok = std::process::Command::new(&p).args(["-c", &format!("import {module}")]).output();
        if ok.is_ok_and(|o| o.status.success()) {
            return Some(p);
        }
    }
    skipped(&format!("no Python with {module} (.ci/run installs it in .venv); {unchecked}"));
    None
}

/// Decodes data blocks with asterix_decoder: (track number, address, lat, lon, time of day).
pub fn decode_asterix(
    py: &std::path::Path,
    blocks: &[Vec<u8>],
    dir: &std::path::Path,
) -> Vec<(u64, String, f64, f64, f64)> {
    let input = dir.join("blocks.hex");
    std::fs::write(
        &input,
        blocks
            .iter()
            .map(|b| b.iter().map(|x| format!("{x:02x}")).collect::<String>() + "\n")
            .collect::<String>(),
    )
    .unwrap();
    let script = r#"
import asterix, json, sys
for line in open(sys.argv[1]):
    for r in asterix.parse(bytes.fromhex(line.strip())):
        print(json.dumps([r["I040"]["TrkN"]["val"], r["I380"]["ADR"]["ADR"]["val"],
                          r["I105"]["Lat"]["val"], r["I105"]["Lon"]["val"], r["I070"]["ToT"]["val"]]))
"#;
    let out = std::process::Command::new(py).args(["-c", script]).arg(&input).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            (
                v[0].as_u64().unwrap(),
                v[1].as_str().unwrap().to_string(),
                v[2].as_f64().unwrap(),
                v[3].as_f64().unwrap(),
                v[4].as_f64().unwrap(),
            )
        })
        .collect()
}

/// A fixture scenario (`fixtures/scenarios/NAME.toml`) simulated on another
/// seed than its own (a world nothing was tuned on): its capture and truth.
pub fn simulated(name: &str, seed: u64) -> (Vec<u8>, fuse1090::eval::Truth) {
    simulated_with(name, seed, |_| {})
}

/// A fixture scenario (`fixtures/scenarios/NAME.toml`) as it is.
pub fn scenario(name: &str) -> fuse1090::sim::scenario::Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("fixtures/scenarios/{name}.toml"));
    fuse1090::sim::scenario::Scenario::load(&path).unwrap()
}

/// A scenario simulated: its capture and truth, as bytes.
pub fn simulate(s: &fuse1090::sim::scenario::Scenario) -> (Vec<u8>, Vec<u8>) {
    let (mut capture, mut truth) = (Vec::new(), Vec::new());
    fuse1090::sim::simulate(s, &mut capture, &mut truth).unwrap();
    (capture, truth)
}

/// [`simulated`] with the scenario changed by `edit` first.
pub fn simulated_with(
    name: &str,
    seed: u64,
    edit: impl FnOnce(&mut fuse1090::sim::scenario::Scenario),
) -> (Vec<u8>, fuse1090::eval::Truth) {
    let mut s = scenario(name);
    s.seed = seed;
    edit(&mut s);
    let (capture, truth) = simulate(&s);
    (capture, fuse1090::eval::Truth::read(truth.as_slice()).unwrap())
}

/// A scratch directory for one test, removed when the returned guard drops
/// (also when the test panics), so that repeated runs do not fill the disk.
pub fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new().prefix(&format!("fuse1090-{name}-")).tempdir().unwrap()
}

/// A loopback port free a moment ago for TCP and UDP (the daemons under test
/// bind it), and never handed to another test of this process: the kernel
/// may give a freed port out again, and two live tests running side by side
/// once got the same one (their daemons, then with SO_REUSEADDR, split its
/// datagrams; now the second would fail to bind).
pub fn free_port() -> u16 {
    static GIVEN: std::sync::Mutex<std::collections::BTreeSet<u16>> =
        std::sync::Mutex::new(std::collections::BTreeSet::new());
    loop {
        let tcp = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = tcp.local_addr().unwrap().port();
        let udp_free = std::net::UdpSocket::bind(("127.0.0.1", port)).is_ok();
        if udp_free && GIVEN.lock().unwrap().insert(port) {
            return port;
        }
    }
}

/// Every frame of an input, with the arrival time (if the format carries one).
pub fn frames(bytes: &[u8], format: InputFormat) -> Vec<(Option<f64>, RawFrame)> {
    let mut parser = parser_for(format);
    let mut out = Vec::new();
    let mut t = None;
    let mut sink = |e| match e {
        FeedEvent::ArrivalTime(x) => t = Some(x),
        FeedEvent::Frame(f) => out.push((t, f)),
        _ => {}
    };
    parser.push(bytes, &mut sink);
    parser.finish(&mut sink);
    out
}

/// Upper-case hex to bytes.
pub fn unhex(s: &str) -> Vec<u8> {
    (0..s.len()).step_by(2).map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap()).collect()
}

use fuse1090::core::{Core, CoreConfig, Event};
use fuse1090::feed::capture::{CaptureReader, CaptureRecord, ReceiverDecl};

/// Runs a capture through a core in-process; returns the core (for its
/// statistics), every event, and the receivers in declaration order.
pub fn run_core(capture: &[u8], cfg: &CoreConfig) -> (Core, Vec<Event>, Vec<ReceiverDecl>) {
    run_core_knowing(capture, cfg, Vec::new())
}

/// [`run_core`] with receivers described as a configuration would.
pub fn run_core_knowing(
    capture: &[u8],
    cfg: &CoreConfig,
    known: Vec<fuse1090::core::front::KnownReceiver>,
) -> (Core, Vec<Event>, Vec<ReceiverDecl>) {
    let mut reader = CaptureReader::new(capture, "capture");
    let mut core = Core::new(cfg);
    core.know(known);
    let mut events = Vec::new();
    let mut rxs = Vec::new();
    while let Some(rec) = reader.next_record().unwrap() {
        if let CaptureRecord::Receiver(d) = &rec {
            rxs.push(d.clone());
        }
        core.handle_record(rec);
        events.extend(std::iter::from_fn(|| core.poll_event()));
    }
    core.finish();
    events.extend(std::iter::from_fn(|| core.poll_event()));
    (core, events, rxs)
}

/// East/north offset (m) of `b` from `a` on the mean sphere (fine for metres to kilometres).
pub fn en(a_lat: f64, a_lon: f64, b_lat: f64, b_lon: f64) -> [f64; 2] {
    let r = 6_371_008.8;
    [(b_lon - a_lon).to_radians() * r * a_lat.to_radians().cos(), (b_lat - a_lat).to_radians() * r]
}

/// Squared Mahalanobis distance of an east/north error under a covariance.
pub fn mahalanobis2(e: [f64; 2], c: [[f64; 2]; 2]) -> f64 {
    let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
    (c[1][1] * e[0] * e[0] - (c[0][1] + c[1][0]) * e[0] * e[1] + c[0][0] * e[1] * e[1]) / det
}

/// Mean horizontal NEES of the MLAT fixes against the truth, the share
/// inside their 95% ellipse and the share beyond NEES 50. The eval's 95% band around 2 is for
/// independent fixes, a hundredth wide at this count; fixes in a row share
/// their clock synchronisation and geometry, so a tenth is asked.
pub fn fix_nees(events: &[Event], truth: &fuse1090::eval::Truth) -> (f64, f64, f64) {
    let (mut sum, mut inside, mut wild, mut n) = (0.0, 0, 0, 0);
    for e in events {
        let Event::Mlat(f) = e else { continue };
        let Some((lat, lon, _)) = truth.position(&format!("{:06X}", f.addr), f.t) else { continue };
        let d2 = mahalanobis2(en(lat, lon, f.lat, f.lon), f.cov_en);
        sum += d2;
        inside += (d2 <= 5.991) as usize;
        wild += (d2 > 50.0) as usize;
        n += 1;
    }
    (sum / n as f64, inside as f64 / n as f64, wild as f64 / n as f64)
}

/// Median horizontal error (m) of the MLAT fixes against the truth.
pub fn fix_median_error(events: &[Event], truth: &fuse1090::eval::Truth) -> f64 {
    let mut errs: Vec<f64> = (events.iter())
        .filter_map(|e| if let Event::Mlat(f) = e { Some(f) } else { None })
        .filter_map(|f| {
            let (lat, lon, _) = truth.position(&format!("{:06X}", f.addr), f.t)?;
            let e = en(lat, lon, f.lat, f.lon);
            Some(e[0].hypot(e[1]))
        })
        .collect();
    errs.sort_by(f64::total_cmp);
    errs[errs.len() / 2]
}
