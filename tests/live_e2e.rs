//! The service end to end over real loopback sockets: the daemon as a child
//! process, a shortened tma-busy replayed into it through all three input
//! kinds (four receivers each: Beast TCP client, Beast TCP server, UDP), two
//! subscribers (JSON and ASTERIX CAT062), and the faults an operator meets:
//! an unknown sender, garbage and a half frame on a socket, an unreachable
//! subscriber, a receiver whose stream ends (and the client reconnecting),
//! SIGHUP with a changed output list, SIGTERM; and, on daemons of their
//! own, what only a process shows: a port taken by another daemon, running
//! out of file descriptors, a burst in one read seen by the stats line and
//! Prometheus, the learnt state across a restart. What a test can see in
//! the counters runs in-process (`live_inprocess.rs`).
//!
//! The ASTERIX output is decoded by an independent decoder (the
//! `asterix_decoder` Python package, which `.ci/run` installs in `.venv`)
//! and compared with the JSON output: same positions, addresses and track
//! numbers.

use std::collections::{HashMap, HashSet};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream, UdpSocket};
use std::path::PathBuf;
use std::process::Stdio;
use std::time::{Duration, Instant};

use fuse1090::feed::capture::{CaptureReader, ClockKind};
use fuse1090::sim::scenario::Scenario;
use serde_json::Value;

mod common;
use common::live::*;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Waits up to 5 s for the daemon to close its end of `sock`.
fn closed_by_the_daemon(sock: &mut TcpStream) -> Result<(), String> {
    sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    match sock.read(&mut [0u8; 1]) {
        Ok(0) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => Ok(()),
        other => Err(format!("{other:?}")),
    }
}

/// Datagrams received on a socket until `until`.
fn collect(sock: &UdpSocket, until: Instant, out: &mut Vec<Vec<u8>>) {
    let mut buf = vec![0u8; 65_536];
    while Instant::now() < until {
        sock.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
        if let Ok((n, _)) = sock.recv_from(&mut buf) {
            out.push(buf[..n].to_vec());
        }
    }
}

struct World {
    dir: tempfile::TempDir,
    capture: PathBuf,
    truth: Vec<Value>,
    receivers: Vec<(String, f64, f64, f64, ClockKind)>,
}

fn world() -> World {
    let dir = common::scratch("e2e");
    let mut s = Scenario::load(&root().join("fixtures/scenarios/tma-busy.toml")).unwrap();
    s.duration_s = 30.0;
    // The restarting receiver (rx08, a TCP-server sender here) restarts 12 s in.
    for r in &mut s.receiver {
        if !r.resets_s.is_empty() {
            r.resets_s = vec![12.0];
        }
    }
    let (mut cap, mut truth) = (Vec::new(), Vec::new());
    fuse1090::sim::simulate(&s, &mut cap, &mut truth).unwrap();
    let capture = dir.path().join("capture.txt");
    std::fs::write(&capture, &cap).unwrap();
    let mut reader = CaptureReader::new(cap.as_slice(), "capture");
    while reader.next_record().unwrap().is_some() {}
    let receivers = reader.receivers().iter().map(|r| (r.id.clone(), r.lat, r.lon, r.alt, r.clock)).collect();
    let truth = String::from_utf8(truth).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    World { dir, capture, truth, receivers }
}

/// The daemon's configuration: receivers 0-3 by TCP client, 4-7 pushing to
/// the TCP server from 127.0.1.x (but 6, from 127.0.0.1, known by the
/// receiver id frame it sends first), the rest by UDP from 127.0.2.x.
fn config(w: &World, ports: &[u16], outputs: &[(u16, &str)]) -> String {
    let (server, udp) = (ports[0], ports[1]);
    let mut c = format!(
        "[service]\nstats_interval_s = 1.0\nrecord = \"{}\"\n\n",
        w.dir.path().join("recorded.txt").display()
    );
    for (i, (id, lat, lon, alt, clock)) in w.receivers.iter().enumerate() {
        let clock = if *clock == ClockKind::Gps { "gps" } else { "beast12" };
        c += &format!(
            "[[receiver]]\nid = \"{id}\"\nlat = {lat}\nlon = {lon}\nalt_m = {alt}\nclock = \"{clock}\"\n"
        );
        match i {
            0..=3 => {}
            6 => c += &format!("beast_id = \"{:016x}\"\n", 0xfe10_9000 + i),
            4..=7 => c += &format!("source = \"127.0.1.{i}\"\n"),
            _ => c += &format!("source = \"127.0.2.{i}\"\n"),
        }
        c += "\n";
    }
    for (i, (id, ..)) in w.receivers.iter().enumerate().take(4) {
        c += &format!(
            "[[input]]\nkind = \"beast_tcp_client\"\naddress = \"127.0.0.1:{}\"\nreceiver = \"{id}\"\n\n",
            ports[2 + i]
        );
    }
    let names = |r: std::ops::Range<usize>| {
        w.receivers[r].iter().map(|(id, ..)| format!("\"{id}\"")).collect::<Vec<_>>().join(", ")
    };
    c += &format!(
        "[[input]]\nkind = \"beast_tcp_server\"\naddress = \"127.0.0.1:{server}\"\nreceivers = [{}]\n\n",
        names(4..8)
    );
    c += &format!(
        "[[input]]\nkind = \"udp\"\naddress = \"127.0.0.1:{udp}\"\nreceivers = [{}]\n\n",
        names(8..w.receivers.len())
    );
    for (port, format) in outputs {
        c +=
            &format!("[[output]]\nkind = \"udp\"\naddress = \"127.0.0.1:{port}\"\nformat = \"{format}\"\n\n");
    }
    c
}

/// The Python with `asterix_decoder`, or `None` (with a message).
fn python() -> Option<PathBuf> {
    common::python_with("asterix", "ASTERIX not cross-checked")
}

#[test]
fn daemon_end_to_end_over_loopback_with_faults() {
    let w = world();
    let ports: Vec<u16> = (0..6).map(|_| common::free_port()).collect();
    let json_sub = UdpSocket::bind("127.0.0.1:0").unwrap();
    let ax_sub = UdpSocket::bind("127.0.0.1:0").unwrap();
    let late_sub = UdpSocket::bind("127.0.0.1:0").unwrap();
    let (jp, ap, lp) = (
        json_sub.local_addr().unwrap().port(),
        ax_sub.local_addr().unwrap().port(),
        late_sub.local_addr().unwrap().port(),
    );
    // An unreachable subscriber first: it must not stop the others.
    let dead = common::free_port();
    let cfg_path = w.dir.path().join("fuse1090.toml");
    std::fs::write(&cfg_path, config(&w, &ports, &[(dead, "json"), (jp, "json"), (ap, "asterix062")]))
        .unwrap();
    let out = bin().arg("check-config").arg(&cfg_path).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    let mut daemon = daemon(&cfg_path, &w.dir.path().join("daemon.log"), None);
    std::thread::sleep(Duration::from_millis(400));

    // Faults on the TCP server: an unknown sender, garbage and a half frame
    // from a known one (127.0.1.4 is receiver 4).
    let server = format!("127.0.0.1:{}", ports[0]);
    if let Ok(mut s) = TcpStream::connect(&server) {
        let _ = s.write_all(b"hello from nowhere");
    }
    let garbage = {
        let sock = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
        sock.bind(&"127.0.1.4:0".parse::<std::net::SocketAddr>().unwrap().into()).unwrap();
        sock.connect(&server.parse::<std::net::SocketAddr>().unwrap().into()).unwrap();
        let mut s: TcpStream = sock.into();
        s.write_all(&[0x00, 0xff, 0x1a, 0x1a, 0x1a, 0x33, 0x01, 0x02]).unwrap();
        s
    };
    drop(garbage);

    let replay = bin()
        .arg("replay")
        .arg(&w.capture)
        .arg("--config")
        .arg(&cfg_path)
        .args(["--speed", "3"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut json_dg, mut ax_dg, mut late_dg) = (Vec::new(), Vec::new(), Vec::new());
    let halfway = Instant::now() + Duration::from_secs(5);
    std::thread::scope(|s| {
        s.spawn(|| collect(&json_sub, halfway, &mut json_dg));
        s.spawn(|| collect(&ax_sub, halfway, &mut ax_dg));
    });
    // SIGHUP with a new output list: the late subscriber joins, the dead one goes.
    std::fs::write(&cfg_path, config(&w, &ports, &[(jp, "json"), (ap, "asterix062"), (lp, "json")])).unwrap();
    signal(&daemon, "HUP");
    let end = Instant::now() + Duration::from_secs(8);
    std::thread::scope(|s| {
        s.spawn(|| collect(&json_sub, end, &mut json_dg));
        s.spawn(|| collect(&ax_sub, end, &mut ax_dg));
        s.spawn(|| collect(&late_sub, end, &mut late_dg));
    });
    let replay_out = replay.wait_with_output().unwrap();
    assert!(replay_out.status.success(), "{}", String::from_utf8_lossy(&replay_out.stderr));

    // SIGTERM: gone within two seconds, cleanly.
    signal(&daemon, "TERM");
    let status = exit_within(&mut daemon, Duration::from_secs(2)).expect("still running 2 s after SIGTERM");
    assert!(status.success(), "{status}");
    let mut log = String::new();
    std::fs::File::open(w.dir.path().join("daemon.log")).unwrap().read_to_string(&mut log).unwrap();

    // The operator sees every event in the log.
    for needle in [
        "unknown sender refused",
        "SIGHUP: configuration re-read",
        "disconnected",
        "stopping",
        "stats:",
        "clock jump: receiver restarted",
        // rx05, which multilateration excludes (declared 300 m off), is dated
        // by arrival less its network delay, learnt from GPS-timed receivers.
        "reports dated by arrival: network delay learnt receiver=\"rx05\"",
    ] {
        assert!(log.contains(needle), "log lacks {needle:?}:\n{}", &log[log.len().saturating_sub(3000)..]);
    }
    // The TCP clients started before their receivers listened: refused, then
    // connected after backing off.
    let refused = log.find("cannot connect").expect("a refused connection");
    assert!(log[refused..].contains(": connected receiver="), "no reconnection after the refusal");
    // Tracks for the aircraft of the truth, through every input kind.
    let records: Vec<Value> = json_dg.iter().map(|d| serde_json::from_slice(d).unwrap()).collect();
    let tracked: HashSet<String> = records
        .iter()
        .filter(|r| r["type"] == "track")
        .map(|r| r["hex"].as_str().unwrap().to_string())
        .collect();
    let flying: HashSet<String> = w
        .truth
        .iter()
        .filter(|t| t["type"] == "equipage")
        .map(|t| t["hex"].as_str().unwrap().to_string())
        .collect();
    let share = tracked.intersection(&flying).count() as f64 / flying.len() as f64;
    eprintln!(
        "{} JSON datagrams, {} ASTERIX blocks, {} after SIGHUP on the new output; {}/{} aircraft tracked",
        json_dg.len(),
        ax_dg.len(),
        late_dg.len(),
        tracked.len(),
        flying.len()
    );
    assert!(share > 0.8, "tracked {share:.2} of the aircraft");
    assert!(tracked.is_subset(&flying), "tracks for aircraft that do not exist");
    assert!(records.iter().any(|r| r["type"] == "mlat"), "no MLAT fixes");
    assert!(!late_dg.is_empty(), "the output added by SIGHUP got nothing");
    let mut used: HashSet<String> = HashSet::new();
    for r in records.iter().filter(|r| r["type"] == "mlat") {
        for id in r["receivers"].as_array().unwrap() {
            used.insert(id.as_str().unwrap().to_string());
        }
    }
    // One receiver of each input kind, and the one a receiver id frame names.
    for (i, (id, ..)) in w.receivers.iter().enumerate() {
        if [0, 5, 6, 9].contains(&i) {
            assert!(used.contains(id), "receiver {id} (input kind {}) never used", i / 4);
        }
    }

    // The recording (`record`) is a capture of what came in: every receiver,
    // every frame the replay sent (less the garbage), and it runs offline.
    let sent: u64 = String::from_utf8_lossy(&replay_out.stderr)
        .split_whitespace()
        .skip_while(|w| *w != "replay:")
        .nth(1)
        .and_then(|n| n.parse().ok())
        .expect("replay prints what it sent");
    let recorded = std::fs::read(w.dir.path().join("recorded.txt")).unwrap();
    let mut reader = CaptureReader::new(recorded.as_slice(), "recorded");
    let mut frames = 0u64;
    while let Some(r) = reader.next_record().unwrap() {
        frames += matches!(r, fuse1090::feed::capture::CaptureRecord::Frame(_)) as u64;
    }
    assert_eq!(reader.receivers().len(), w.receivers.len());
    assert_eq!(reader.skipped, 0);
    assert!(frames >= sent && frames <= sent + 10, "recorded {frames} of {sent} frames sent");

    // ASTERIX against JSON: same track numbers, addresses and positions.
    let Some(py) = python() else { return };
    let decoded = common::decode_asterix(&py, &ax_dg, w.dir.path());
    assert!(decoded.len() > 100, "{} ASTERIX records", decoded.len());
    let by_key: HashMap<(u64, String), Vec<&Value>> =
        records.iter().filter(|r| r["type"] == "track").fold(HashMap::new(), |mut m, r| {
            m.entry((r["id"].as_u64().unwrap(), r["hex"].as_str().unwrap().to_string())).or_default().push(r);
            m
        });
    let mut matched = 0;
    for (tn, adr, lat, lon, tod) in &decoded {
        let js = by_key
            .get(&(*tn, adr.clone()))
            .unwrap_or_else(|| panic!("ASTERIX track {tn}/{adr} not in the JSON"));
        // I062/070 rounds to 1/128 s: the record it encodes is within half a
        // step. A track can go out twice within a few milliseconds (an update
        // and a held release), so the nearest in time is not always the one
        // encoded: one of those within the step must have its position.
        let close: Vec<(f64, f64)> = js
            .iter()
            .filter(|r| (r["t"].as_f64().unwrap().rem_euclid(86_400.0) - tod).abs() <= 0.5 / 128.0 + 1e-6)
            .map(|r| (r["lat"].as_f64().unwrap(), r["lon"].as_f64().unwrap()))
            .collect();
        if !close.is_empty() {
            assert!(
                close.iter().any(|(jl, jo)| (jl - lat).abs() < 1e-5 && (jo - lon).abs() < 1e-5),
                "{tn}: {lat},{lon} vs {close:?}"
            );
            matched += 1;
        }
    }
    assert!(matched as f64 > 0.9 * decoded.len() as f64, "{matched} of {} matched", decoded.len());
}

/// A UDP port is one daemon's: a second one configured on it fails at
/// start-up, saying which input and why, instead of sharing the datagrams
/// or running deaf; a SIGHUP whose new input cannot bind says so and goes
/// on with the others, the port it keeps bound again.
#[test]
fn a_udp_port_taken_by_another_daemon_fails_its_start_and_sighup_goes_on_without_a_taken_port() {
    let work = common::scratch("e2e-udp-port");
    let dir = work.path();
    let (port, other) = (common::free_port(), common::free_port());
    let cfg = |extra: &str| {
        format!(
            "[service]\nstats_interval_s = 0.2\n\n[[receiver]]\nid = \"rx\"\nlat = 45.0\nlon = 5.0\n\
             alt_m = 100.0\nclock = \"beast12\"\nsource = \"127.0.3.5\"\n\n[[input]]\nkind = \"udp\"\n\
             address = \"127.0.0.1:{port}\"\n{extra}"
        )
    };
    let (cfg_a, log_a, log_b) = (dir.join("a.toml"), dir.join("a.log"), dir.join("b.log"));
    std::fs::write(&cfg_a, cfg("")).unwrap();
    let mut a = daemon(&cfg_a, &log_a, None);
    wait_for_log(&log_a, "running inputs=");
    let sender = UdpSocket::bind("127.0.3.5:0").unwrap();
    let frame = beast_frame();
    let send_until_counted = |n: u64| {
        let t0 = Instant::now();
        while counted(&log_a, "rx") < n {
            assert!(t0.elapsed() < Duration::from_secs(10), "daemon A counted {}", counted(&log_a, "rx"));
            sender.send_to(&frame, ("127.0.0.1", port)).unwrap();
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    send_until_counted(1);

    let cfg_b = dir.join("b.toml");
    std::fs::write(&cfg_b, cfg("")).unwrap();
    let mut b = daemon(&cfg_b, &log_b, None);
    let st = exit_within(&mut b, Duration::from_secs(10));
    let said = std::fs::read_to_string(&log_b).unwrap();
    let st = st.unwrap_or_else(|| panic!("B still running on a taken port: {said}"));
    assert!(!st.success(), "{said}");
    assert!(said.contains(&format!("input 1 (udp) cannot bind 127.0.0.1:{port}")), "{said}");
    assert!(!said.contains("running inputs="), "{said}");

    // A second input on a port something else holds: A says so, keeps its
    // own port (closed and bound again) and goes on.
    let _holder = UdpSocket::bind(("127.0.0.1", other)).unwrap();
    std::fs::write(&cfg_a, cfg(&format!("\n[[input]]\nkind = \"udp\"\naddress = \"127.0.0.1:{other}\"\n")))
        .unwrap();
    signal(&a, "HUP");
    wait_for_log(&log_a, &format!("SIGHUP: input 2 (udp) cannot bind 127.0.0.1:{other}"));
    let before = counted(&log_a, "rx");
    send_until_counted(before + 3);
    signal(&a, "TERM");
    assert!(a.wait().unwrap().success());
    let log = std::fs::read_to_string(&log_a).unwrap();
    assert!(!log.contains("input stopped"), "{log}");
}

/// A Beast TCP server input that runs out of file descriptors (more
/// receivers connected than the process may have descriptors) keeps its
/// listener: once descriptors are free again, a receiver that connects is
/// served. (An accept error used to end the input, refusing every receiver
/// from then on.) And a receiver is served on its newest connection only:
/// connecting again closes the older one.
#[test]
fn a_beast_server_survives_running_out_of_descriptors_and_keeps_one_connection_per_receiver() {
    let work = common::scratch("e2e-fds");
    let dir = work.path();
    let port = common::free_port();
    let cfg_path = dir.join("fds.toml");
    let mut cfg = format!(
        "[service]\nstats_interval_s = 0.2\n\n[[input]]\nkind = \"beast_tcp_server\"\naddress = \"127.0.0.1:{port}\"\n\n"
    );
    for i in 1..=60 {
        cfg += &format!(
            "[[receiver]]\nid = \"held{i}\"\nlat = 45.0\nlon = 5.0\nalt_m = 100.0\nclock = \"beast12\"\n\
             source = \"127.0.4.{i}\"\n\n"
        );
    }
    std::fs::write(&cfg_path, cfg).unwrap();
    let log_path = dir.join("fds.log");
    // A small descriptor limit for the daemon alone.
    let mut daemon = daemon(&cfg_path, &log_path, Some(48));
    let log = || std::fs::read_to_string(&log_path).unwrap_or_default();
    let connect = |from: usize| -> Option<TcpStream> {
        let s = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).ok()?;
        s.bind(&std::net::SocketAddr::from(([127, 0, 4, from as u8], 0)).into()).ok()?;
        s.connect_timeout(&std::net::SocketAddr::from(([127, 0, 0, 1], port)).into(), Duration::from_secs(2))
            .ok()?;
        Some(s.into())
    };
    let frame = beast_frame();
    let counted = |id: &str| counted(&log_path, id);
    // Frames on a connection of receiver held1 until the stats count `n` of them.
    let feed_until = |sock: &mut TcpStream, n: u64, what: &str| {
        let t0 = Instant::now();
        while counted("held1") < n {
            assert!(t0.elapsed() < Duration::from_secs(10), "{what}:\n{}", log());
            sock.write_all(&frame).unwrap();
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    let t0 = Instant::now();
    let mut first = None;
    while first.is_none() {
        assert!(t0.elapsed() < Duration::from_secs(10), "the daemon never listened:\n{}", log());
        first = connect(1);
        std::thread::sleep(Duration::from_millis(50));
    }
    // Connecting again closes the older connection; the newer one is served.
    let mut older = first.unwrap();
    older.write_all(&frame).unwrap();
    let mut newer = connect(1).unwrap();
    closed_by_the_daemon(&mut older).expect("the older connection stays open");
    feed_until(&mut newer, 4, "the newer connection's frames never counted");
    assert!(log().contains("the receiver connected again"), "{}", log());
    drop(newer);
    // Far more receivers than the daemon has descriptors left: the kernel
    // queues the rest, and the daemon's accepts fail.
    let held: Vec<TcpStream> = (2..=60).filter_map(connect).collect();
    let t0 = Instant::now();
    while !log().contains("accept failed") {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "accept never failed; the test proves nothing:\n{}",
            log()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(held);
    // Descriptors free again: a receiver connects and its frames count.
    let mut late = connect(1).expect("the listener is gone");
    feed_until(&mut late, counted("held1") + 5, "the new connection's frames never counted");
    signal(&daemon, "TERM");
    assert!(daemon.wait().unwrap().success());
    let text = log();
    assert!(!text.contains("input stopped"), "{text}");
    assert!(stats_number(&log_path, "socket errors ") > 0, "socket errors not counted:\n{text}");
}

/// A TCP read brings thousands of frames at once; the core takes them in
/// batches of its own size (the rest waits for the next batch) and loses
/// none of them; the stats line and the Prometheus endpoint say so.
#[test]
fn a_burst_of_frames_in_one_tcp_read_is_processed_whole() {
    let work = common::scratch("e2e-burst");
    let dir = work.path();
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let metrics = std::net::SocketAddr::from(([127, 0, 0, 1], common::free_port()));
    let cfg_path = dir.join("burst.toml");
    std::fs::write(
        &cfg_path,
        format!(
            "[service]\nstats_interval_s = 0.2\nmetrics_listen = \"{metrics}\"\n\n[[receiver]]\nid = \"busy\"\n\
             lat = 45.0\nlon = 5.0\nalt_m = 100.0\nclock = \"beast12\"\n\n[[input]]\n\
             kind = \"beast_tcp_client\"\naddress = \"{}\"\nreceiver = \"busy\"\n",
            listener.local_addr().unwrap()
        ),
    )
    .unwrap();
    let log_path = dir.join("burst.log");
    let mut daemon = daemon(&cfg_path, &log_path, None);
    let (mut sock, _) = listener.accept().unwrap();
    let burst: Vec<u8> = (0..20_000).flat_map(|_| beast_frame()).collect();
    sock.write_all(&burst).unwrap();
    let t0 = Instant::now();
    while stats_number(&log_path, "stats: frames ") < 20_000 && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(100));
    }
    // Metrics are refreshed once a second.
    let mut text = String::new();
    while !text.contains("fuse1090_frames_total 20000") && t0.elapsed() < Duration::from_secs(15) {
        std::thread::sleep(Duration::from_millis(200));
        text = scrape(metrics);
    }
    for want in [
        "fuse1090_frames_total 20000",
        "fuse1090_receiver_frames_total{receiver=\"busy\"} 20000",
        "fuse1090_queue_frames 0",
        "fuse1090_queue_drops_total 0",
        // The tracker's counters are exported too (nothing in one frame
        // repeated is impossible).
        "fuse1090_measurements_rejected_total{reason=\"non_finite\"} 0",
        "fuse1090_fusion_fallbacks_total 0",
        "fuse1090_tracks_withheld_spread_total 0",
        // As are multilateration's (one receiver: nothing to fix or drop).
        "fuse1090_mlat_outliers_dropped_total 0",
        "fuse1090_mlat_gps_time_jumps_total 0",
        "fuse1090_mlat_rejects_total{reason=\"residual\"} 0",
        "fuse1090_mlat_rejects_total{reason=\"ambiguous\"} 0",
        // One aircraft decoded; one position, never paired, makes no track.
        "fuse1090_aircraft_held{table=\"decoder\"} 1",
        "fuse1090_aircraft_held{table=\"tracker\"} 0",
        // The particle filters' (none started: one aircraft with a position).
        "fuse1090_sparse_filters_total{event=\"restarted\"} 0",
        "fuse1090_sparse_velocity_reports_total{outcome=\"contradicting\"} 0",
    ] {
        assert!(text.lines().any(|l| l == want), "{want} not in:\n{text}");
    }
    signal(&daemon, "TERM");
    assert!(daemon.wait().unwrap().success());
    assert_eq!(
        stats_number(&log_path, "stats: frames "),
        20_000,
        "{}",
        std::fs::read_to_string(&log_path).unwrap()
    );
}

/// What multilateration learnt of the receivers is saved at SIGTERM and
/// taken up by the next start: the receivers' records right after the
/// restart carry the timing learnt before it.
#[test]
fn the_learnt_state_survives_a_restart() {
    let work = common::scratch("e2e-state");
    let (port, state) = (common::free_port(), work.path().join("learnt.json"));
    let cfg = work.path().join("c.toml");
    let text = demo(port, 20.0, "kind = \"stdout\"\n")
        .replace("[service]\n", &format!("[service]\nstate_file = \"{}\"\n", state.display()));
    std::fs::write(&cfg, text).unwrap();
    let first_log = work.path().join("first.log");
    let mut first = daemon(&cfg, &first_log, None);
    wait_for_log(&first_log, "no learnt state yet");
    let t0 = Instant::now();
    while !std::fs::read_to_string(&first_log).unwrap_or_default().contains("demo replay finished") {
        assert!(t0.elapsed() < Duration::from_secs(20), "the demo never finished");
        std::thread::sleep(Duration::from_millis(100));
    }
    // The log says what multilateration made of each receiver, with the stats.
    let said = std::fs::read_to_string(&first_log).unwrap();
    assert!(said.contains("mlat receivers (state/sigma/offset/outliers/position): s1=ok/"), "{said}");
    signal(&first, "TERM");
    assert!(exit_within(&mut first, Duration::from_secs(5)).is_some_and(|s| s.success()));
    let saved: Value = serde_json::from_slice(&std::fs::read(&state).unwrap()).unwrap();
    let receivers = saved["receivers"].as_array().unwrap();
    assert_eq!(receivers.len(), 8);
    assert!(receivers.iter().all(|r| r["fixes"].as_u64().unwrap() > 100), "{saved}");
    // Started again: all eight taken up before any frame.
    let second_log = work.path().join("second.log");
    let mut second = daemon(&cfg, &second_log, None);
    wait_for_log(&second_log, "learnt state taken up");
    let said = std::fs::read_to_string(&second_log).unwrap();
    assert!(said.contains("receivers=8"), "{said}");
    signal(&second, "TERM");
    assert!(exit_within(&mut second, Duration::from_secs(5)).is_some());
}
