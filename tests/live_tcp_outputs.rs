//! TCP outputs across reloads, over real loopback sockets: a subscriber of
//! an output the reload leaves unchanged stays connected and served; an
//! output changed on the same port is closed and bound anew, serving its new
//! format. The JSON lines a `format = "json"` TCP output sends are the track
//! stream, one object per line.

mod common;

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use common::live::{daemon, demo, signal, wait_for_log};

fn connect(port: u16) -> BufReader<TcpStream> {
    let t0 = Instant::now();
    loop {
        match TcpStream::connect(("127.0.0.1", port)) {
            Ok(s) => {
                s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
                return BufReader::new(s);
            }
            Err(e) => assert!(t0.elapsed() < Duration::from_secs(10), "{e}"),
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The next `n` lines (fewer if the connection ends or goes quiet).
fn lines(r: &mut BufReader<TcpStream>, n: usize) -> Vec<String> {
    let mut out = Vec::new();
    while out.len() < n {
        let mut line = String::new();
        match r.read_line(&mut line) {
            Ok(0) | Err(_) => break,
            Ok(_) => out.push(line.trim_end().to_string()),
        }
    }
    out
}

#[test]
fn a_reload_keeps_unchanged_subscribers_and_rebinds_a_changed_output() {
    let work = common::scratch("tcp-outputs");
    let port = common::free_port();
    // The demo's own output (its stdout, unread) and the one under test.
    let output = |format: &str| {
        format!(
            "kind = \"stdout\"\n\n[[output]]\nkind = \"tcp_server\"\naddress = \"127.0.0.1:{port}\"\n\
             format = \"{format}\"\n"
        )
    };
    let input = common::free_port();
    let cfg = work.path().join("c.toml");
    std::fs::write(&cfg, demo(input, 1.0, &output("json"))).unwrap();
    let log = work.path().join("d.log");
    let mut child = daemon(&cfg, &log, None);
    wait_for_log(&log, "running");

    let mut a = connect(port);
    for line in lines(&mut a, 20) {
        let v: serde_json::Value = serde_json::from_str(&line).unwrap_or_else(|e| panic!("{e}: {line}"));
        assert!(v["type"].is_string(), "{line}");
    }
    // The same configuration again: the subscriber is kept.
    signal(&child, "HUP");
    wait_for_log(&log, "SIGHUP: configuration re-read");
    assert_eq!(
        lines(&mut a, 20).len(),
        20,
        "the subscriber lost its stream at a reload that changed nothing"
    );

    // The output changed on the same port: closed, bound anew, in SBS.
    std::fs::write(&cfg, demo(input, 1.0, &output("sbs"))).unwrap();
    signal(&child, "HUP");
    let t0 = Instant::now();
    while std::fs::read_to_string(&log).unwrap().matches("SIGHUP: configuration re-read").count() < 2 {
        assert!(t0.elapsed() < Duration::from_secs(10), "no second reload");
        std::thread::sleep(Duration::from_millis(20));
    }
    let rest = lines(&mut a, 100_000);
    assert!(rest.iter().all(|l| l.starts_with('{')), "the old subscriber got another format");
    let mut b = connect(port);
    let got = lines(&mut b, 10);
    assert_eq!(got.len(), 10);
    assert!(got.iter().all(|l| l.starts_with("MSG,")), "{got:?}");
    let _ = child.kill();
    let _ = child.wait();
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(!text.contains("cannot start"), "{text}");
}
