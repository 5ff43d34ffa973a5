//! What the cluster test checks in a run's output against one node's: the
//! evaluation's rows, the receiver records, track numbers, conflict alerts,
//! partitions held; and the live test's datagrams, documents and fixes.

use std::collections::{BTreeMap, BTreeSet};
use std::io::BufRead;
use std::path::Path;
use std::time::Duration;

use fuse1090::eval::{evaluate, Report, Row, Truth};

use crate::common;

pub fn row<'a>(r: &'a Report, source: &str) -> &'a Row {
    r.overall.iter().find(|x| x.source == source).unwrap_or_else(|| panic!("no {source} row"))
}

pub fn report(truth: &Truth, path: &Path) -> Report {
    evaluate(truth, std::io::BufReader::new(std::fs::File::open(path).unwrap())).unwrap()
}

/// The records of a track stream whose line holds `needle` (all with ""), parsed.
pub fn records(path: &Path, needle: &str) -> Vec<serde_json::Value> {
    (std::io::BufReader::new(std::fs::File::open(path).unwrap()).lines())
        .map(Result::unwrap)
        .filter(|l| l.contains(needle))
        .map(|l| serde_json::from_str(&l).unwrap())
        .collect()
}

/// The clock's receiver records: once a minute of data time and at the end,
/// every receiver, as one node's; the final ones' learnt timing (sigma,
/// late share) close to one node's, and the same receivers in use (but
/// those one node left out as misplaced: the survey is each worker's).
pub fn receivers_reported(single: &Path, cluster: &Path, name: &str) {
    let last = |path: &Path| -> BTreeMap<String, serde_json::Value> {
        records(path, "\"type\":\"receiver\"")
            .into_iter()
            .map(|v| (v["id"].as_str().unwrap().to_string(), v))
            .collect()
    };
    let count = |path: &Path| records(path, "\"type\":\"receiver\"").len();
    let (one, many) = (last(single), last(cluster));
    assert_eq!(one.keys().collect::<Vec<_>>(), many.keys().collect::<Vec<_>>(), "{name}: receivers reported");
    let (n1, n) = (count(single), count(cluster));
    assert!(n.abs_diff(n1) <= one.len(), "{name}: {n} receiver records, one node {n1}");
    for (id, a) in &one {
        let b = &many[id];
        eprintln!(
            "{name} {id}: one node {}/{:?}/{:?}, cluster {}/{:?}/{:?}",
            a["state"], a["sigma_ns"], a["outlier_rate"], b["state"], b["sigma_ns"], b["outlier_rate"]
        );
        assert_eq!((&a["state"], &a["reason"]), (&b["state"], &b["reason"]), "{name} {id}");
        // The position survey, one for the network from every worker's
        // traffic: where one node finds the receiver, within a few of its
        // sigmas.
        let offset = |v: &serde_json::Value| {
            let en = v["position_offset_en_m"].as_array()?;
            Some(([en[0].as_f64()?, en[1].as_f64()?], v["position_offset_sigma_m"].as_f64()?))
        };
        match (offset(a), offset(b)) {
            (Some((e1, s1)), Some((e, s))) => {
                let apart = (e[0] - e1[0]).hypot(e[1] - e1[1]);
                eprintln!("{name} {id}: surveyed {e1:.1?} ±{s1:.1} m, cluster {e:.1?} ±{s:.1} m");
                assert!(
                    apart <= (4.0 * s1.hypot(s)).max(5.0),
                    "{name} {id}: surveyed {apart:.1} m from one node's"
                );
            }
            // Surveyed by one and not yet by the other, at the survey's
            // threshold of traffic; never a misplaced receiver.
            (one, many) => {
                eprintln!("{name} {id}: surveyed {one:?} by one node, {many:?} by the cluster");
                assert!(a["reason"] != "misplaced", "{name} {id}: offsets {one:?} and {many:?}")
            }
        }
        if a["reason"] == "misplaced" {
            continue;
        }
        let (s1, s) = (a["sigma_ns"].as_f64().unwrap(), b["sigma_ns"].as_f64().unwrap());
        assert!((s / s1 - 1.0).abs() <= 0.25, "{name} {id}: sigma {s} ns, one node {s1} ns");
    }
}

/// (hex, track id) of every fused track record, with its times.
pub fn track_ids(path: &Path) -> BTreeMap<String, Vec<(f64, u64)>> {
    let mut ids: BTreeMap<String, Vec<(f64, u64)>> = BTreeMap::new();
    for v in records(path, "\"type\":\"track\"") {
        if v["source"] == "fused" {
            ids.entry(v["hex"].as_str().unwrap().to_string())
                .or_default()
                .push((v["t"].as_f64().unwrap(), v["id"].as_u64().unwrap()));
        }
    }
    ids
}

/// Raised conflict alerts: (time, the pair).
pub fn raised(path: &Path) -> Vec<(f64, (String, String))> {
    (records(path, "\"kind\":\"conflict\"").into_iter())
        .filter(|v| v["active"].as_bool().unwrap())
        .map(|v| {
            let pair =
                (v["pair"][0].as_str().unwrap().to_string(), v["pair"][1].as_str().unwrap().to_string());
            (v["t"].as_f64().unwrap(), pair)
        })
        .collect()
}

/// Whether every conflict one node raised has its pair alerted by the
/// cluster too, raised within 5 s of it (or already up).
pub fn alerts_covered(single: &Path, cluster: &Path) {
    let theirs = raised(cluster);
    for (t, pair) in raised(single) {
        assert!(
            theirs.iter().any(|(u, p)| *p == pair && *u <= t + 5.0),
            "the cluster did not alert {pair:?} (raised by one node at {t})"
        );
    }
}

/// The partitions each worker held when it was stopped, after checking its
/// counts add up: what it took, less what it handed back or lost.
///
/// How often partitions moved on the way depends on the scheduling: a
/// worker that starts late, or is starved past its lease on two busy
/// cores, has the others share and share again. Where they end does not.
pub fn held(workers: &[BTreeMap<String, u64>]) -> Vec<u64> {
    for w in workers {
        let moved = w["partitions_handed_back"] + w["partitions_lost"];
        assert_eq!(w["partitions_taken"], w["partitions_held"] + moved, "{w:?}");
    }
    workers.iter().map(|w| w["partitions_held"]).collect()
}

pub fn within(a: f64, b: f64, share: f64) -> bool {
    (a - b).abs() <= share * b
}

/// Datagrams received on a loopback UDP socket, by a thread of their own.
pub struct Datagrams {
    pub addr: std::net::SocketAddr,
    pub stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    pub thread: std::thread::JoinHandle<Vec<Vec<u8>>>,
}

impl Datagrams {
    pub fn listen() -> Datagrams {
        let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        socket.set_read_timeout(Some(Duration::from_millis(100))).unwrap();
        let addr = socket.local_addr().unwrap();
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let stopped = stop.clone();
        let thread = std::thread::spawn(move || {
            let (mut got, mut buf) = (Vec::new(), vec![0u8; 65_536]);
            while !stopped.load(std::sync::atomic::Ordering::Relaxed) {
                if let Ok(n) = socket.recv(&mut buf) {
                    got.push(buf[..n].to_vec());
                }
            }
            got
        });
        Datagrams { addr, stop, thread }
    }

    /// What arrived, once the sender has stopped.
    pub fn stop(self) -> Vec<Vec<u8>> {
        std::thread::sleep(Duration::from_millis(300));
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

/// One of the publisher's documents under `/data/`.
pub fn document(port: u16, name: &str) -> serde_json::Value {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).expect("the publisher serves HTTP");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(format!("GET /data/{name} HTTP/1.0\r\nHost: x\r\n\r\n").as_bytes()).unwrap();
    let mut text = String::new();
    let _ = s.read_to_string(&mut text);
    let body = text.split_once("\r\n\r\n").map(|(_, b)| b).unwrap_or_default();
    serde_json::from_str(body).unwrap_or_else(|e| panic!("{name}: {e}: {text}"))
}

/// The addresses with a fused track.
pub fn tracked(path: &Path) -> BTreeSet<String> {
    track_ids(path).into_keys().collect()
}

/// The median distance (m) from each MLAT fix to the same aircraft's ADS-B
/// position nearest in time (within 0.5 s), and how many fixes had one.
pub fn fix_against_adsb(path: &Path) -> (f64, usize) {
    // (hex, t, lat, lon) of each fix; (t, lat, lon) of each aircraft's positions.
    let mut fixes: Vec<(String, f64, f64, f64)> = Vec::new();
    let mut adsb: BTreeMap<String, Vec<(f64, f64, f64)>> = BTreeMap::new();
    for v in records(path, "") {
        let (Some(t), Some(lat), Some(lon)) = (v["t"].as_f64(), v["lat"].as_f64(), v["lon"].as_f64()) else {
            continue;
        };
        let hex = v["hex"].as_str().unwrap_or("").to_string();
        match v["type"].as_str() {
            Some("mlat") => fixes.push((hex, t, lat, lon)),
            Some("position") => adsb.entry(hex).or_default().push((t, lat, lon)),
            _ => {}
        }
    }
    let mut d: Vec<f64> = fixes
        .iter()
        .filter_map(|(hex, t, lat, lon)| {
            let near = adsb.get(hex)?.iter().min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))?;
            ((near.0 - t).abs() <= 0.5).then(|| {
                let en = common::en(near.1, near.2, *lat, *lon);
                en[0].hypot(en[1])
            })
        })
        .collect();
    d.sort_by(f64::total_cmp);
    (d.get(d.len() / 2).copied().unwrap_or(f64::INFINITY), d.len())
}
