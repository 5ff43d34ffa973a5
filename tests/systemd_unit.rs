//! The shipped systemd unit's system-call filter lets through every call the
//! service makes on purpose. A call the filter leaves out kills the service
//! with SIGSYS (or fails, with `SystemCallErrorNumber=`), and only on the
//! installed system: the unit once denied `@resources`, which holds
//! `sched_setscheduler`, the one call `realtime_priority` makes, while its
//! comment promised realtime scheduling up to priority 10.
//!
//! Checked two ways: the calls the code makes on purpose (a list), and every
//! call the daemon makes under `strace` through start, a scrape, SIGHUP and
//! SIGTERM. The groups are expanded by the system's own `systemd-analyze
//! syscall-filter`; the assignments are applied as systemd does: the first
//! sets the mode (an allow list unless it starts with `~`), each later one
//! adds to or takes from the set. Each test skips, saying so, where its tool
//! is missing.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{Read, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;

/// The calls the service makes itself, beyond what any program needs: the
/// realtime request, turning huge pages off, receive stamps on sockets,
/// batched datagram reads, and the allocator's page advice.
const NEEDED: [&str; 6] = ["sched_setscheduler", "prctl", "setsockopt", "recvmmsg", "madvise", "mmap"];

fn groups() -> Option<BTreeMap<String, Vec<String>>> {
    let out = Command::new("systemd-analyze").arg("syscall-filter").output().ok()?;
    if !out.status.success() {
        return None;
    }
    let mut groups: BTreeMap<String, Vec<String>> = BTreeMap::new();
    let mut current = None;
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        if line.starts_with('@') {
            let g = line.trim().to_string();
            groups.entry(g.clone()).or_default();
            current = Some(g);
        } else if let (Some(g), item) = (&current, line.trim()) {
            if !item.is_empty() && !item.starts_with('#') {
                groups.get_mut(g).expect("entered").push(item.to_string());
            }
        }
    }
    Some(groups)
}

fn expand(item: &str, groups: &BTreeMap<String, Vec<String>>, into: &mut BTreeSet<String>) {
    match groups.get(item) {
        Some(members) => members.iter().for_each(|m| expand(m, groups, into)),
        None => {
            into.insert(item.to_string());
        }
    }
}

/// The unit's system-call filter, as systemd builds it.
struct Filter {
    /// An allow list (the first assignment has no `~`), or a deny list.
    allow_list: bool,
    calls: BTreeSet<String>,
}

impl Filter {
    /// The unit's, or `None` (saying so) where `systemd-analyze` is missing.
    fn of_unit() -> Option<Filter> {
        let Some(groups) = groups() else {
            common::skipped("systemd-analyze not available; the unit's filter not checked");
            return None;
        };
        let unit = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/systemd/fuse1090.service"))
            .unwrap();
        let mut allow_list = None;
        let mut set = BTreeSet::new();
        for value in unit.lines().filter_map(|l| l.trim().strip_prefix("SystemCallFilter=")) {
            let (deny, items) = match value.strip_prefix('~') {
                Some(rest) => (true, rest),
                None => (false, value),
            };
            let mut calls = BTreeSet::new();
            items.split_whitespace().for_each(|i| expand(i, &groups, &mut calls));
            let allow_mode = *allow_list.get_or_insert(!deny);
            if deny == allow_mode {
                set.retain(|c| !calls.contains(c));
            } else {
                set.extend(calls);
            }
        }
        Some(Filter { allow_list: allow_list.expect("the unit filters system calls"), calls: set })
    }

    fn lets_through(&self, call: &str) -> bool {
        self.calls.contains(call) == self.allow_list
    }
}

#[test]
fn the_units_syscall_filter_allows_what_the_service_calls() {
    let Some(filter) = Filter::of_unit() else { return };
    let refused: Vec<&str> = NEEDED.iter().copied().filter(|c| !filter.lets_through(c)).collect();
    assert!(refused.is_empty(), "the unit's filter refuses {refused:?}");
    // What the unit means to refuse stays refused (so the reading above is systemd's).
    for call in ["reboot", "setpriority", "init_module"] {
        assert!(!filter.lets_through(call), "the unit's filter lets {call} through");
    }
}

/// The daemon itself under `strace`: the demo configuration (eight receivers
/// replayed over TCP) with realtime scheduling, the Prometheus endpoint
/// (scraped once), recording, a UDP input and an ASTERIX output, then SIGHUP
/// and SIGTERM; every system call it made must pass the unit's filter.
#[test]
fn the_daemon_makes_no_call_the_units_filter_refuses() {
    let Some(filter) = Filter::of_unit() else { return };
    if Command::new("strace").arg("-V").output().map_or(true, |o| !o.status.success()) {
        common::skipped("strace not available; the daemon's calls not checked");
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let work = common::scratch("unit");
    let dir = work.path();
    let (metrics, input) = (common::free_port(), common::free_port());
    let sink = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let demo = std::fs::read_to_string(root.join("config/demo.toml")).unwrap();
    let demo = demo.replace("127.0.0.1:8090", &format!("127.0.0.1:{}", common::free_port()));
    let cfg = demo.replacen(
        "[service]\n",
        &format!(
            "[service]\nmetrics_listen = \"127.0.0.1:{metrics}\"\nrealtime_priority = 5\nrecord = \"{}\"\n",
            dir.join("record.txt").display()
        ),
        1,
    ) + &format!(
        "\n[[input]]\nkind = \"udp\"\naddress = \"127.0.0.1:{input}\"\nformat = \"beast\"\n\n\
         [[output]]\nkind = \"udp\"\naddress = \"{}\"\nformat = \"asterix062\"\n",
        sink.local_addr().unwrap()
    );
    let (cfg_path, trace) = (dir.join("cfg.toml"), dir.join("trace.txt"));
    std::fs::write(&cfg_path, cfg).unwrap();
    let mut strace = Command::new("strace")
        .args(["-f", "-qq", "-o"])
        .arg(&trace)
        .arg(env!("CARGO_BIN_EXE_fuse1090"))
        .args(["run", "--config"])
        .arg(&cfg_path)
        .current_dir(root)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The daemon's pid from its execve in the trace (strace's own children
    // include short-lived probes of the kernel's ptrace features).
    let deadline = Instant::now() + Duration::from_secs(10);
    let daemon: i32 = loop {
        let text = std::fs::read_to_string(&trace).unwrap_or_default();
        if let Some(pid) = text
            .lines()
            .find(|l| l.contains("execve(") && l.contains("fuse1090"))
            .and_then(|l| l.split_whitespace().next()?.parse().ok())
        {
            break pid;
        }
        assert!(Instant::now() < deadline, "strace started no daemon");
        std::thread::sleep(Duration::from_millis(20));
    };
    // A Beast frame to the UDP input (a DF11 all-call reply, type 2), again
    // until the daemon has read one (it may not have bound the port yet),
    // and the metrics scraped once the endpoint answers: waits with a
    // deadline, not guesses, so a slow machine only takes longer.
    let frame = [0x1a, 0x32, 0, 0, 0, 0, 0, 0, 0x80, 0x5d, 0x4c, 0xa4, 0xe5, 0x5a, 0x73, 0x8b];
    let deadline = Instant::now() + Duration::from_secs(20);
    while !std::fs::read_to_string(&trace).unwrap_or_default().contains("recvmmsg(")
        && Instant::now() < deadline
    {
        sink.send_to(&frame, ("127.0.0.1", input)).unwrap();
        std::thread::sleep(Duration::from_millis(100));
    }
    let mut scrape = String::new();
    while !scrape.contains("fuse1090_") && Instant::now() < deadline {
        scrape.clear();
        if let Ok(mut s) = std::net::TcpStream::connect(("127.0.0.1", metrics)) {
            let _ = s.write_all(b"GET /metrics HTTP/1.0\r\n\r\n");
            let _ = s.read_to_string(&mut scrape);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    // SAFETY: signals to the child this test started.
    unsafe { libc::kill(daemon, libc::SIGHUP) };
    std::thread::sleep(Duration::from_millis(1000));
    unsafe { libc::kill(daemon, libc::SIGTERM) };
    let deadline = Instant::now() + Duration::from_secs(10);
    while strace.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            // SAFETY: as above.
            unsafe { libc::kill(daemon, libc::SIGKILL) };
            let _ = strace.kill();
            let text = std::fs::read_to_string(&trace).unwrap_or_default();
            let tail: Vec<&str> = text.lines().rev().take(30).collect();
            panic!("the daemon did not stop on SIGTERM; the trace ends {tail:#?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let text = std::fs::read_to_string(&trace).unwrap();
    assert!(scrape.contains("fuse1090_"), "the metrics endpoint answered: {scrape:.200}");
    for call in ["sched_setscheduler(", "prctl(PR_SET_THP_DISABLE", "recvmmsg(", "sendto("] {
        assert!(text.contains(call), "the daemon never called {call}: the run did not cover it");
    }
    // `PID name(args) = result`, or `PID <... name resumed> ...`.
    let calls: BTreeSet<&str> = text
        .lines()
        .filter_map(|l| {
            let rest = l.split_once(' ')?.1.trim_start();
            let rest = rest.strip_prefix("<... ").unwrap_or(rest);
            let end = rest.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))?;
            (end > 0).then(|| &rest[..end])
        })
        .collect();
    let refused: Vec<&str> = calls.iter().copied().filter(|c| !filter.lets_through(c)).collect();
    eprintln!("the daemon made {} distinct system calls", calls.len());
    assert!(refused.is_empty(), "the unit's filter refuses {refused:?} (all: {calls:?})");
}

/// The unit and the drop-in `fuse1090 unit-limits` writes for the demo pass
/// `systemd-analyze verify` without a complaint (it only warns about an
/// assignment it cannot parse, so its words are read, not its status).
#[test]
fn the_unit_and_its_generated_limits_verify_cleanly() {
    if Command::new("systemd-analyze").arg("--version").output().map_or(true, |o| !o.status.success()) {
        common::skipped("systemd-analyze not available; the unit not verified");
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let work = common::scratch("unit-verify");
    let dir = work.path();
    let bin = env!("CARGO_BIN_EXE_fuse1090");
    let unit = std::fs::read_to_string(root.join("systemd/fuse1090.service")).unwrap();
    std::fs::write(dir.join("fuse1090.service"), unit.replace("/usr/local/bin/fuse1090", bin)).unwrap();
    std::fs::create_dir(dir.join("fuse1090.service.d")).unwrap();
    let limits = Command::new(bin).args(["unit-limits"]).arg(root.join("config/demo.toml")).output().unwrap();
    assert!(limits.status.success());
    let text = String::from_utf8(limits.stdout).unwrap();
    assert!(text.contains("SocketBindDeny=any") && text.contains("IPAddressDeny=any"), "{text}");
    std::fs::write(dir.join("fuse1090.service.d/limits.conf"), &text).unwrap();
    let out = Command::new("systemd-analyze")
        .args(["verify", "fuse1090.service"])
        .current_dir(dir)
        .env("SYSTEMD_UNIT_PATH", format!("{}:", dir.display()))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr).to_string() + &String::from_utf8_lossy(&out.stdout);
    let complaints: Vec<&str> = said.lines().filter(|l| l.contains("fuse1090.service")).collect();
    assert!(complaints.is_empty(), "systemd-analyze verify:\n{said}");
}
