//! The daemon in a hostile world, as a child process over real loopback
//! sockets: what an attacker or an unlucky operator can do to it must cost
//! them their own share and nothing more, be counted, and never stop the
//! service.

use std::net::UdpSocket;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::live::*;

/// A receiver's configuration block.
fn receiver(id: &str, source: &str, extra: &str) -> String {
    format!(
        "[[receiver]]\nid = \"{id}\"\nlat = 43.6\nlon = 1.4\nalt_m = 150.0\nclock = \"beast12\"\n\
         source = \"{source}\"\n{extra}\n"
    )
}

/// The demo configuration (eight GPS-timed receivers replaying the surface
/// capture into its Beast TCP server) with its server on `port`, the replay
/// at `speed`, stats every half second and one JSON output of `output`'s kind.
fn demo(port: u16, speed: f64, output: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("config/demo.toml")).unwrap();
    let (head, _) = text.split_once("[[output]]").unwrap();
    head.replace("127.0.0.1:30104", &format!("127.0.0.1:{port}"))
        .replace("fixtures/", &format!("{}/fixtures/", root.display()))
        .replace("demo_speed = 1.0", &format!("demo_speed = {speed}"))
        .replace("stats_interval_s = 10.0", "stats_interval_s = 0.5")
        + &format!("[[output]]\nformat = \"json\"\n{output}")
}

/// Datagrams of `n` Beast frames each from `src` to `port`, `count` times.
fn send_frames(src: &str, port: u16, n: usize, count: usize) {
    let sock = UdpSocket::bind((src, 0)).unwrap();
    let datagram: Vec<u8> = (0..n).flat_map(|_| beast_frame()).collect();
    for _ in 0..count {
        let _ = sock.send_to(&datagram, ("127.0.0.1", port));
    }
}

/// A stdout nobody reads (a pipe kept open, never read) and the demo's
/// traffic, replayed fast, filling it: the core goes on (frames keep being
/// counted) and SIGTERM still ends the daemon at once.
#[test]
fn an_unread_stdout_stops_nothing() {
    let work = common::scratch("hostile-stdout");
    let (port, log) = (common::free_port(), work.path().join("log"));
    let cfg = work.path().join("c.toml");
    std::fs::write(&cfg, demo(port, 20.0, "kind = \"stdout\"\n")).unwrap();
    let mut daemon = Command::new(env!("CARGO_BIN_EXE_fuse1090"))
        .args(["run", "--config"])
        .arg(&cfg)
        .env("RUST_LOG", "info")
        .stderr(Stdio::from(std::fs::File::create(&log).unwrap()))
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    // The capture's 120 s at 20x: all of it within 6 s, far more lines than
    // the pipe's 64 KiB hold.
    let t0 = Instant::now();
    while !std::fs::read_to_string(&log).unwrap_or_default().contains("demo replay finished")
        && t0.elapsed() < Duration::from_secs(20)
    {
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_millis(1000));
    let sent = 33_000;
    let counted = stats_number(&log, "stats: frames ");
    assert!(counted > sent, "the core stalled: {counted} frames counted\n{}", newest_stats(&log));
    let dropped = stats_number(&log, "output drops ");
    assert!(dropped > 0, "the pipe never filled: {}", newest_stats(&log));
    signal(&daemon, "TERM");
    let status = exit_within(&mut daemon, Duration::from_secs(5));
    assert!(status.is_some_and(|s| s.success()), "SIGTERM did not end the daemon: {status:?}");
}

/// A UDP output to a port where nobody listens: the kernel's refusals are
/// counted as output errors (the socket is connected to its destination).
#[test]
fn an_output_to_a_closed_port_counts_its_errors() {
    let work = common::scratch("hostile-closed-output");
    let (port, closed, log) = (common::free_port(), common::free_port(), work.path().join("log"));
    let cfg = work.path().join("c.toml");
    std::fs::write(&cfg, demo(port, 4.0, &format!("kind = \"udp\"\naddress = \"127.0.0.1:{closed}\"\n")))
        .unwrap();
    let mut daemon = daemon(&cfg, &log, None);
    let t0 = Instant::now();
    while stats_number(&log, "output errors ") == 0 && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(100));
    }
    signal(&daemon, "TERM");
    assert!(exit_within(&mut daemon, Duration::from_secs(5)).is_some());
    assert!(stats_number(&log, "output errors ") > 0, "{}", newest_stats(&log));
}

/// A receiver with `max_rate = 1000` flooded over UDP for 3 s at tens of
/// thousands of frames a second, by its own address (UDP sources can be
/// spoofed): it loses its excess and nothing after (at an honest pace every
/// frame counts again at once), and the honest receivers beside it lose
/// nothing at all.
#[test]
fn a_udp_flood_costs_the_flooded_receiver_its_excess_only() {
    let work = common::scratch("hostile-flood");
    let (port, log) = (common::free_port(), work.path().join("log"));
    let cfg = work.path().join("c.toml");
    let mut text = String::from("[service]\nstats_interval_s = 0.25\n\n");
    text += &receiver("flooded", "127.0.3.1", "max_rate = 1000.0");
    for k in 0..3 {
        text += &receiver(&format!("honest{k}"), &format!("127.0.3.{}", 10 + k), "");
    }
    text += &format!("[[input]]\nkind = \"udp\"\naddress = \"127.0.0.1:{port}\"\n");
    std::fs::write(&cfg, text).unwrap();
    let mut daemon = daemon(&cfg, &log, None);
    wait_for_log(&log, "running");
    let flood_until = Instant::now() + Duration::from_secs(3);
    std::thread::scope(|s| {
        s.spawn(|| {
            while Instant::now() < flood_until {
                send_frames("127.0.3.1", port, 40, 200);
                std::thread::sleep(Duration::from_millis(2));
            }
        });
        // The honest ones: 5 frames every 10 ms each (500 frames/s), for 4 s.
        for k in 0..3 {
            s.spawn(move || {
                for _ in 0..400 {
                    send_frames(&format!("127.0.3.{}", 10 + k), port, 5, 1);
                    std::thread::sleep(Duration::from_millis(10));
                }
            });
        }
    });
    std::thread::sleep(Duration::from_millis(600));
    let after_flood = receiver_counts(&log, "flooded");
    assert!(after_flood[3] > 10_000, "the flood was not throttled: {after_flood:?}");
    // Now an honest pace from the flooded receiver: 2 s at 500 frames/s.
    for _ in 0..200 {
        send_frames("127.0.3.1", port, 5, 1);
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(600));
    let later = receiver_counts(&log, "flooded");
    assert_eq!(later[0] - after_flood[0], 1000, "{after_flood:?} then {later:?}");
    assert_eq!(later[3], after_flood[3], "throttled after the flood: {after_flood:?} then {later:?}");
    // Nothing of theirs dropped by us; the kernel may have dropped
    // datagrams of anyone while the flood filled the socket's buffer
    // (counted, though no receiver can be named for them).
    let kernel = stats_number(&log, "kernel drops ");
    for k in 0..3 {
        let c = receiver_counts(&log, &format!("honest{k}"));
        assert_eq!(c[1..], [0, 0, 0, 0], "honest{k}: {}", newest_stats(&log));
        assert!(c[0] == 2000 || (kernel > 0 && c[0] >= 1800), "honest{k}: {}", newest_stats(&log));
    }
    signal(&daemon, "TERM");
    assert!(exit_within(&mut daemon, Duration::from_secs(5)).is_some_and(|s| s.success()));
}
