//! The daemon's HTTP server over real loopback sockets: the demo serves
//! readsb's documents and the metrics on one port, the aircraft in
//! `/data/aircraft.json` are the fused tracks the daemon publishes, and
//! malformed requests, huge headers and idle connections are bounded and
//! counted without keeping an honest client out.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::io::{Read, Write};
use std::net::{TcpStream, UdpSocket};
use std::time::{Duration, Instant};

use common::live::{daemon, demo, exit_within, signal, wait_for_log, with_http};
use serde_json::Value;

/// A plain HTTP/1.0 request; the status code and the body.
fn get(port: u16, request: &[u8]) -> (u16, String) {
    let Ok(mut s) = TcpStream::connect(("127.0.0.1", port)) else { return (0, String::new()) };
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let _ = s.write_all(request);
    let mut text = Vec::new();
    let _ = s.read_to_end(&mut text);
    let text = String::from_utf8_lossy(&text).to_string();
    let status = text.split(' ').nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    let body = text.split_once("\r\n\r\n").map(|(_, b)| b.to_string()).unwrap_or_default();
    (status, body)
}

fn document(port: u16, path: &str) -> Value {
    let (status, body) = get(port, format!("GET {path} HTTP/1.0\r\nHost: x\r\n\r\n").as_bytes());
    assert_eq!(status, 200, "{path}: {body}");
    serde_json::from_str(&body).unwrap_or_else(|e| panic!("{path}: {e}: {body}"))
}

/// The demo with its HTTP server on `http` and its tracks sent to `sink`.
fn start(name: &str, http: u16, sink: &UdpSocket, extra: &str) -> (tempfile::TempDir, std::process::Child) {
    let work = common::scratch(name);
    let cfg = work.path().join("c.toml");
    let out = format!("kind = \"udp\"\naddress = \"{}\"\n", sink.local_addr().unwrap());
    let text = demo(common::free_port(), 2.0, &out);
    let text = with_http(&text, http, extra);
    std::fs::write(&cfg, text).unwrap();
    let log = work.path().join("d.log");
    let child = daemon(&cfg, &log, None);
    wait_for_log(&log, "running");
    (work, child)
}

/// `fuse1090_http_refused_total` in a scrape (0 when absent).
fn refused_count(metrics: &str) -> f64 {
    metrics
        .lines()
        .find_map(|l| l.strip_prefix("fuse1090_http_refused_total "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(0.0)
}

#[test]
fn the_demo_serves_its_fused_tracks_as_readsb_json() {
    let sink = UdpSocket::bind("127.0.0.1:0").unwrap();
    sink.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
    let http = common::free_port();
    let (_work, mut child) = start("http-demo", http, &sink, "");
    // Four seconds of the demo at twice real time: eight of its seconds.
    // Each fused track published: its number and when it was first seen.
    let (mut tracks, t0) = (BTreeMap::<String, (u64, Instant)>::new(), Instant::now());
    let mut buf = [0u8; 65536];
    while t0.elapsed() < Duration::from_secs(4) {
        if let Ok(n) = sink.recv(&mut buf) {
            let v: Value = serde_json::from_slice(&buf[..n]).unwrap();
            if v["type"] == "track" && v["source"] == "fused" {
                let id = v["id"].as_u64().unwrap();
                tracks.entry(v["hex"].as_str().unwrap().to_lowercase()).or_insert((id, Instant::now()));
            }
        }
    }
    let (doc, asked) = (document(http, "/data/aircraft.json"), Instant::now());
    // The map's page and the files it loads are served beside the data.
    let (status, page) = get(http, b"GET / HTTP/1.0\r\n\r\n");
    assert!(status == 200 && page.contains("<script src=\"app.js\">"), "{status}: {page}");
    for file in ["/app.js", "/leaflet.js", "/style.css", "/leaflet.css", "/world.json"] {
        let (status, body) = get(http, format!("GET {file} HTTP/1.0\r\n\r\n").as_bytes());
        assert!(status == 200 && body.len() > 1000, "{file}: {status}");
    }
    signal(&child, "TERM");
    assert!(exit_within(&mut child, Duration::from_secs(5)).is_some());
    let served: BTreeMap<String, u64> = doc["aircraft"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| (a["hex"].as_str().unwrap().to_string(), a["fuse1090"]["id"].as_u64().unwrap()))
        .collect();
    assert!(served.len() >= 8, "{doc}");
    // Every aircraft served is a fused track the daemon published, under the
    // same track number; every one published more than the document's
    // refresh before it was asked for is served.
    for (hex, id) in &served {
        assert_eq!(tracks.get(hex).map(|t| t.0), Some(*id), "{hex} served but not published so");
    }
    let due: Vec<&String> = tracks
        .iter()
        .filter(|(_, (_, at))| asked - *at > Duration::from_millis(1500))
        .map(|(h, _)| h)
        .collect();
    assert!(due.len() >= 8, "{tracks:?}");
    for hex in due {
        assert!(served.contains_key(hex), "{hex} published but not served: {doc}");
    }
    assert!(doc["messages"].as_u64().unwrap() > 100 && doc["now"].as_f64().unwrap() > 1.7e9, "{doc}");
}

#[test]
fn receivers_metrics_and_bad_clients() {
    let sink = UdpSocket::bind("127.0.0.1:0").unwrap();
    let http = common::free_port();
    let (_work, mut child) = start("http-bad", http, &sink, "max_connections = 8\n");
    std::thread::sleep(Duration::from_millis(1500));

    let receiver = document(http, "/data/receiver.json");
    assert_eq!(receiver["refresh"], 1000);
    // The demo's eight receivers are around Paris-CDG.
    let (lat, lon) = (receiver["lat"].as_f64().unwrap(), receiver["lon"].as_f64().unwrap());
    assert!((lat - 49.005).abs() < 0.02 && (lon - 2.55).abs() < 0.03, "{receiver}");
    let receivers = document(http, "/data/receivers.json");
    let list = receivers["receivers"].as_array().unwrap();
    let ids: BTreeSet<&str> = list.iter().map(|r| r["id"].as_str().unwrap()).collect();
    assert_eq!(
        ids,
        (1..=8).map(|i| format!("s{i}")).collect::<BTreeSet<_>>().iter().map(String::as_str).collect()
    );
    assert!(list.iter().all(|r| r["frames"].as_u64().unwrap() > 0 && r["clock"] == "gps"), "{receivers}");

    // Malformed and oversized requests: refused, and the server goes on.
    let (status, _) = get(http, b"NONSENSE\r\n\r\n");
    assert_eq!(status, 400);
    let huge = format!("GET /data/aircraft.json HTTP/1.1\r\nX: {}\r\n\r\n", "a".repeat(64 * 1024));
    let (status, _) = get(http, huge.as_bytes());
    assert!(status == 431 || status == 400 || status == 0, "huge header: {status}");
    let (status, _) = get(http, b"POST /data/aircraft.json HTTP/1.0\r\n\r\n");
    assert_eq!(status, 405);
    let (status, _) = get(http, b"GET /nowhere HTTP/1.0\r\n\r\n");
    assert_eq!(status, 404);

    // Idle connections beyond the limit are closed at once and counted;
    // those within it time out; then an honest client is served again.
    let idle: Vec<TcpStream> = (0..40).filter_map(|_| TcpStream::connect(("127.0.0.1", http)).ok()).collect();
    assert_eq!(idle.len(), 40);
    std::thread::sleep(Duration::from_millis(300));
    let t0 = Instant::now();
    let metrics = loop {
        let (status, body) = get(http, b"GET /metrics HTTP/1.0\r\n\r\n");
        if status == 200 {
            break body;
        }
        assert!(t0.elapsed() < Duration::from_secs(15), "never served again after the idle flood");
        std::thread::sleep(Duration::from_millis(200));
    };
    // Counted once a second: wait for the count to include the flood.
    let mut refused = refused_count(&metrics);
    if refused == 0.0 {
        std::thread::sleep(Duration::from_millis(1200));
        refused = refused_count(&get(http, b"GET /metrics HTTP/1.0\r\n\r\n").1);
    }
    assert!(refused >= 30.0, "refused {refused}:\n{metrics}");
    drop(idle);
    signal(&child, "TERM");
    assert!(exit_within(&mut child, Duration::from_secs(5)).is_some());
}
