//! The daemon in a hostile world, as a child process over real loopback
//! sockets: what an attacker or an unlucky operator can do to it must cost
//! them their own share and nothing more, be counted, and never stop the
//! service.

use std::net::UdpSocket;
use std::time::{Duration, Instant};

mod common;
use common::live::*;

/// The flooding tests take a core each: one at a time, so that neither
/// measures the other's load.
static HEAVY: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// A receiver's configuration block.
fn receiver(id: &str, source: &str, extra: &str) -> String {
    format!(
        "[[receiver]]\nid = \"{id}\"\nlat = 43.6\nlon = 1.4\nalt_m = 150.0\nclock = \"beast12\"\n\
         source = \"{source}\"\n{extra}\n"
    )
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
    let mut daemon = daemon_unread_stdout(&cfg, &log);
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
    let _heavy = HEAVY.lock().unwrap_or_else(|e| e.into_inner());
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

/// The Prometheus text's value of `name` (a whole series name, labels
/// included), or 0.
fn metric(text: &str, name: &str) -> f64 {
    text.lines()
        .find_map(|l| l.strip_prefix(name).and_then(|rest| rest.strip_prefix(' ')))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(0.0)
}

/// The chaos run: the demo's eight honest receivers replayed into the TCP
/// server while, at once, a rate-limited receiver floods UDP, a stranger
/// floods UDP, a known receiver floods TCP, hundreds of idle connections
/// hit the input and the metrics port, the recording's disk is full
/// (`/dev/full`) and nobody reads stdout; then a reload removes the TCP
/// flooder. Afterwards: the honest receivers lost nothing, the removed one
/// is gone, the endpoint still answers, descriptors and memory are bounded,
/// every event is in a metric, and SIGTERM ends it all.
#[test]
fn chaos_costs_the_honest_receivers_nothing_and_every_event_is_counted() {
    let _heavy = HEAVY.lock().unwrap_or_else(|e| e.into_inner());
    let work = common::scratch("hostile-chaos");
    let (port, udp, metrics_port) = (common::free_port(), common::free_port(), common::free_port());
    let metrics = std::net::SocketAddr::from(([127, 0, 0, 1], metrics_port));
    let log = work.path().join("log");
    let cfg = work.path().join("c.toml");
    let base = demo(port, 10.0, "kind = \"stdout\"\n").replace(
        "[service]\n",
        &format!("[service]\nmetrics_listen = \"{metrics}\"\nrecord = \"/dev/full\"\n"),
    );
    let udp_input = format!("[[input]]\nkind = \"udp\"\naddress = \"127.0.0.1:{udp}\"\n\n");
    let full = format!(
        "{base}\n{}{}{udp_input}",
        receiver("udpflood", "127.0.3.1", "max_rate = 1000.0"),
        receiver("tcpflood", "127.0.3.2", "")
    );
    std::fs::write(&cfg, &full).unwrap();
    let mut daemon = daemon_unread_stdout(&cfg, &log);
    wait_for_log(&log, "running");
    let until = Instant::now() + Duration::from_secs(12);
    let tcp_flooder_closed = std::thread::scope(|s| {
        s.spawn(|| {
            while Instant::now() < until {
                send_frames("127.0.3.1", udp, 40, 100);
                send_frames("127.0.3.99", udp, 40, 20);
                std::thread::sleep(Duration::from_millis(3));
            }
        });
        // Idle crowds on the input and the metrics port, held open.
        let crowd = s.spawn(move || {
            let mut held = Vec::new();
            for k in 0..300u32 {
                let from = std::net::Ipv4Addr::new(127, 0, 6, 1 + (k % 200) as u8);
                for to in [port, metrics_port] {
                    let sock =
                        socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
                    let _ = sock.bind(&std::net::SocketAddr::from((from, 0)).into());
                    let target = std::net::SocketAddr::from(([127, 0, 0, 1], to));
                    if sock.connect_timeout(&target.into(), Duration::from_millis(200)).is_ok() {
                        held.push(sock);
                    }
                }
            }
            std::thread::sleep(Duration::from_secs(3));
            held.len()
        });
        let flood = s.spawn(move || {
            use std::io::Write;
            let sock = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
            sock.bind(&std::net::SocketAddr::from(([127, 0, 3, 2], 0)).into()).unwrap();
            sock.connect(&std::net::SocketAddr::from(([127, 0, 0, 1], port)).into()).unwrap();
            let mut stream: std::net::TcpStream = sock.into();
            stream.set_write_timeout(Some(Duration::from_secs(2))).unwrap();
            let chunk: Vec<u8> = (0..500).flat_map(|_| beast_frame()).collect();
            while Instant::now() < until {
                if stream.write_all(&chunk).is_err() {
                    return true;
                }
            }
            false
        });
        // Half way: the TCP flooder is removed from the configuration.
        std::thread::sleep(Duration::from_secs(5));
        let without = full.replace(&receiver("tcpflood", "127.0.3.2", ""), "");
        std::fs::write(&cfg, without).unwrap();
        signal(&daemon, "HUP");
        let held = crowd.join().unwrap();
        assert!(held > 0, "no idle connection held");
        flood.join().unwrap()
    });
    assert!(tcp_flooder_closed, "the removed receiver's connection stayed open");
    std::thread::sleep(Duration::from_millis(1500));
    // The endpoint answers after the storm, and says what happened.
    let text = scrape(metrics);
    assert!(text.contains("fuse1090_frames_total"), "the metrics endpoint does not answer:\n{text}");
    for name in [
        "fuse1090_receiver_throttled_total{receiver=\"udpflood\"}",
        "fuse1090_unknown_senders_total",
        "fuse1090_metrics_http_refused_total",
        "fuse1090_record_write_errors_total",
        "fuse1090_output_drops_total",
    ] {
        assert!(metric(&text, name) > 0.0, "{name} not counted:\n{text}");
    }
    // The honest receivers lost nothing, to floods or to anything else.
    for k in 1..=8 {
        let c = receiver_counts(&log, &format!("s{k}"));
        assert!(c[0] > 1000, "s{k}: {}", newest_stats(&log));
        assert_eq!(c[2..], [0, 0, 0], "s{k} lost frames: {}", newest_stats(&log));
    }
    // The removed receiver is gone: nothing counted for it after the reload.
    let gone = receiver_counts(&log, "tcpflood")[0];
    std::thread::sleep(Duration::from_millis(600));
    assert_eq!(receiver_counts(&log, "tcpflood")[0], gone);
    // Bounded: descriptors (the crowd's are closed) and memory.
    let pid = daemon.id();
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count());
    assert!(fds < 100, "{fds} descriptors open");
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let rss_kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or(0);
    assert!(rss_kb < 400_000, "resident {rss_kb} kB");
    signal(&daemon, "TERM");
    let st = exit_within(&mut daemon, Duration::from_secs(5));
    assert!(st.is_some_and(|s| s.success()), "{st:?}");
}
