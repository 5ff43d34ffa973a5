//! The daemon learns the air from live Comm-B: two minutes of
//! network-rough-ehs (a windy day; ADS-B aircraft that also answer with
//! heading reports) replayed into its Beast server, each receiver from its
//! own loopback address, and the magnetic variation and wind it learnt on the
//! Prometheus endpoint, against the scenario's; kept in the state file and
//! taken up by the next run.

mod common;

use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

use common::live::{daemon, exit_within, scrape, signal, wait_for_log};
use fuse1090::sim::scenario::Scenario;

/// A metric's value in a scrape.
fn metric(text: &str, name: &str) -> Option<f64> {
    text.lines().find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse().ok())
}

/// Scrapes the metrics until `done` says so or `limit` runs out; the last scrape.
fn scrape_until(addr: std::net::SocketAddr, limit: Duration, done: impl Fn(&str) -> bool) -> String {
    let t0 = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(300));
        let text = scrape(addr);
        if done(&text) || t0.elapsed() > limit {
            return text;
        }
    }
}

#[test]
fn the_daemon_learns_the_air_from_heading_reports() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut scenario = Scenario::load(&root.join("fixtures/scenarios/network-rough-ehs.toml")).unwrap();
    scenario.seed = 43;
    scenario.duration_s = 120.0;
    let work = common::scratch("live-air");
    let (mut capture, mut truth) = (Vec::new(), Vec::new());
    fuse1090::sim::simulate(&scenario, &mut capture, &mut truth).unwrap();
    let capture_path = work.path().join("capture.txt");
    std::fs::write(&capture_path, capture).unwrap();

    let metrics = std::net::SocketAddr::from(([127, 0, 0, 1], common::free_port()));
    let state = work.path().join("state.json");
    let mut cfg = format!(
        "[service]\ndemo_capture = \"{}\"\ndemo_speed = 8.0\nstats_interval_s = 1.0\nmetrics_listen = \"{metrics}\"\n\
         state_file = \"{}\"\n\n",
        capture_path.display(),
        state.display()
    );
    for (k, r) in scenario.receiver.iter().enumerate() {
        let clock = serde_json::to_value(r.clock).unwrap();
        writeln!(
            cfg,
            "[[receiver]]\nid = \"{}\"\nlat = {}\nlon = {}\nalt_m = {}\nclock = {clock}\nsource = \"127.0.0.{}\"\n",
            r.id,
            r.lat,
            r.lon,
            r.alt_m,
            11 + k
        )
        .unwrap();
    }
    write!(cfg, "[[input]]\nkind = \"beast_tcp_server\"\naddress = \"127.0.0.1:{}\"\n", common::free_port())
        .unwrap();
    let cfg_path = work.path().join("air.toml");
    std::fs::write(&cfg_path, cfg).unwrap();
    let log = work.path().join("air.log");
    let mut child = daemon(&cfg_path, &log, None);
    wait_for_log(&log, "running");

    // Two minutes at eight times: 15 s, and the metrics once a second.
    let text = scrape_until(metrics, Duration::from_secs(40), |t| {
        metric(t, "fuse1090_air_lessons_total").is_some_and(|n| n >= 200.0)
    });
    signal(&child, "TERM");
    assert!(exit_within(&mut child, Duration::from_secs(10)).is_some());
    let lessons = metric(&text, "fuse1090_air_lessons_total").unwrap_or(0.0);
    assert!(lessons >= 200.0, "{lessons} lessons:\n{}", std::fs::read_to_string(&log).unwrap());
    let variation = metric(&text, "fuse1090_air_magnetic_variation_deg").unwrap();
    let sigma = metric(&text, "fuse1090_air_magnetic_variation_sigma_deg").unwrap();
    let truth = scenario.air.magnetic_variation_deg;
    assert!((variation - truth).abs() < (4.0 * sigma).max(0.5), "{variation} +- {sigma} against {truth}");
    // The jet's level: 10 km, where the wind learnt must be the scenario's.
    let wind = |c: &str| metric(&text, &format!("fuse1090_air_wind_ms{{alt_km=\"10\",component=\"{c}\"}}"));
    let sigma =
        |c: &str| metric(&text, &format!("fuse1090_air_wind_sigma_ms{{alt_km=\"10\",component=\"{c}\"}}"));
    let true_wind = scenario.air.wind_at(10_000.0);
    for (axis, c) in ["east", "north"].into_iter().enumerate() {
        let (w, s) = (wind(c).unwrap(), sigma(c).unwrap());
        assert!((w - true_wind[axis]).abs() < (4.0 * s).max(2.0), "{c}: {w} +- {s} against {true_wind:?}");
    }
    assert!(metric(&text, "fuse1090_commb_heading_velocities_total").is_some_and(|n| n > 0.0), "{text}");

    // Kept, and taken up by a run that has heard nothing yet.
    let saved: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&state).unwrap()).unwrap();
    let x = saved["air"]["x"].as_array().expect("the air kept");
    // (Learnt on until the daemon stopped: the saved variation is the last.)
    let (p, q) = (x[0].as_f64().unwrap(), x[1].as_f64().unwrap());
    let variation = q.atan2(p).to_degrees();
    assert!((variation - truth).abs() < 0.5, "{variation}");
    let cfg = std::fs::read_to_string(&cfg_path).unwrap();
    let quiet = cfg.lines().filter(|l| !l.starts_with("demo_")).collect::<Vec<_>>().join("\n");
    std::fs::write(&cfg_path, quiet).unwrap();
    let log = work.path().join("again.log");
    let mut child = daemon(&cfg_path, &log, None);
    wait_for_log(&log, "learnt state taken up");
    let again = scrape_until(metrics, Duration::from_secs(10), |t| {
        metric(t, "fuse1090_air_magnetic_variation_deg").is_some()
    });
    signal(&child, "TERM");
    assert!(exit_within(&mut child, Duration::from_secs(10)).is_some());
    let restored = metric(&again, "fuse1090_air_magnetic_variation_deg");
    assert!(
        restored.is_some_and(|v| (v - variation).abs() < 1e-6),
        "{restored:?} against {variation}:\n{again}"
    );
}
