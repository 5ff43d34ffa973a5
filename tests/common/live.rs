//! Helpers for the tests that run the daemon as a child process over real
//! loopback sockets: start it, signal it, wait for it, read its log's stats
//! line and its Prometheus endpoint.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fuse1090"))
}

/// The daemon on `cfg`, logging at info level to `log` (and, with
/// `max_fds`, under that descriptor limit).
pub fn daemon(cfg: &Path, log: &Path, max_fds: Option<u32>) -> Child {
    let cmd = match max_fds {
        Some(n) => {
            let mut c = Command::new("sh");
            c.args(["-c", &format!("ulimit -n {n} && exec \"$0\" \"$@\"")])
                .arg(env!("CARGO_BIN_EXE_fuse1090"));
            c
        }
        None => bin(),
    };
    run(cmd, cfg, log, Stdio::null())
}

/// The daemon on `cfg`, logging to `log`, its stdout a pipe nobody reads.
pub fn daemon_unread_stdout(cfg: &Path, log: &Path) -> Child {
    run(bin(), cfg, log, Stdio::piped())
}

fn run(mut cmd: Command, cfg: &Path, log: &Path, stdout: Stdio) -> Child {
    cmd.args(["run", "--config"])
        .arg(cfg)
        .env("RUST_LOG", "info")
        .stderr(Stdio::from(std::fs::File::create(log).unwrap()))
        .stdout(stdout)
        .spawn()
        .unwrap()
}

/// One Beast Mode S long frame (a DF17 airborne position; the inputs count
/// frames before any CRC check).
pub fn beast_frame() -> Vec<u8> {
    let mut frame = vec![0x1a, b'3', 0, 0, 0, 0, 0, 1, 0x80];
    frame.extend_from_slice(&[
        0x8d, 0x40, 0x62, 0x1d, 0x58, 0xc3, 0x82, 0xd6, 0x90, 0xc8, 0xac, 0x28, 0x63, 0xa7,
    ]);
    frame
}

/// The newest stats line of a log ("" before the first).
pub fn newest_stats(log: &Path) -> String {
    let log = std::fs::read_to_string(log).unwrap_or_default();
    log.lines().rev().find(|l| l.contains("stats: frames")).unwrap_or("").to_string()
}

/// The number after `label` in the newest stats line of a log (0 if none).
pub fn stats_number(log: &Path, label: &str) -> u64 {
    let last = newest_stats(log);
    let digits: String =
        last.split(label).nth(1).unwrap_or("").chars().take_while(char::is_ascii_digit).collect();
    digits.parse().unwrap_or(0)
}

/// Receiver `id`'s frame count in the newest stats line of a log.
pub fn counted(log: &Path, id: &str) -> u64 {
    let last = newest_stats(log);
    last.split([' ', '['])
        .find_map(|w| w.strip_prefix(&format!("{id}=")))
        .and_then(|r| r.split('/').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0)
}

/// Polls a daemon's log until it holds `needle`: a loaded CI machine may
/// take its time to start or re-read.
pub fn wait_for_log(log: &Path, needle: &str) {
    let t0 = Instant::now();
    while !std::fs::read_to_string(log).unwrap_or_default().contains(needle) {
        assert!(t0.elapsed() < Duration::from_secs(10), "no {needle:?} in {}", log.display());
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The daemon's exit status once it has exited, if it does within `limit`
/// (still running then: killed, and `None`).
pub fn exit_within(child: &mut Child, limit: Duration) -> Option<std::process::ExitStatus> {
    let t0 = Instant::now();
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            return Some(st);
        }
        if t0.elapsed() > limit {
            child.kill().unwrap();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

pub fn signal(child: &Child, sig: &str) {
    assert!(Command::new("kill").args(["-s", sig, &child.id().to_string()]).status().unwrap().success());
}

/// The Prometheus endpoint's text (a plain HTTP/1.0 GET).
pub fn scrape(addr: std::net::SocketAddr) -> String {
    let Ok(mut s) = TcpStream::connect(addr) else { return String::new() };
    let _ = s.write_all(b"GET /metrics HTTP/1.0\r\nHost: localhost\r\n\r\n");
    let mut text = String::new();
    let _ = s.read_to_string(&mut text);
    text
}

/// Receiver `id`'s counts in the newest stats line of a log: frames, input
/// errors, queue drops, throttled (over `max_rate`), over its fair share.
pub fn receiver_counts(log: &Path, id: &str) -> [u64; 5] {
    let last = newest_stats(log);
    let mut out = [0; 5];
    if let Some(r) = last.split([' ', '[']).find_map(|w| w.strip_prefix(&format!("{id}="))) {
        for (k, part) in r.trim_end_matches(']').split('/').take(5).enumerate() {
            let digits: String = part.chars().take_while(char::is_ascii_digit).collect();
            out[k] = digits.parse().unwrap_or(0);
        }
    }
    out
}

/// The demo configuration (eight GPS-timed receivers replaying the surface
/// capture into its Beast TCP server) with its server on `port`, the replay
/// at `speed`, stats every half second, its HTTP server on a free port and
/// one JSON output of `output`'s kind.
pub fn demo(port: u16, speed: f64, output: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("config/demo.toml")).unwrap();
    let (head, _) = text.split_once("[[output]]").unwrap();
    head.replace("127.0.0.1:30104", &format!("127.0.0.1:{port}"))
        .replace("fixtures/", &format!("{}/fixtures/", root.display()))
        .replace("demo_speed = 1.0", &format!("demo_speed = {speed}"))
        .replace("stats_interval_s = 10.0", "stats_interval_s = 0.5")
        .replace("127.0.0.1:8090", &format!("127.0.0.1:{}", super::free_port()))
        + &format!("[[output]]\nformat = \"json\"\n{output}")
}

/// The demo's `[http]` table with `listen` on `port`, and `extra` in it.
pub fn with_http(text: &str, port: u16, extra: &str) -> String {
    let (head, tail) = text.split_once("[http]\nlisten = \"").expect("the demo serves HTTP");
    let (_, rest) = tail.split_once('"').unwrap();
    format!("{head}[http]\nlisten = \"127.0.0.1:{port}\"\n{extra}{rest}")
}
