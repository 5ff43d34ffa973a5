//! Load on the live service over loopback: the daemon (release build) as a
//! child process, `fuse1090 replay` pushing 20 s of the scale world (200
//! receivers, 3,000 aircraft) as UDP datagrams from 200 source addresses at
//! increasing speeds, a subscriber taking the JSON track stream.
//!
//! Printed per speed: frames offered and processed per second, frames
//! dropped, the daemon's CPU (share of one core) and peak memory, and the
//! latency from a frame's arrival to the track datagram it produced, p50 and
//! p99, for ADS-B-only updates and for tracks MLAT feeds (held for the MLAT
//! wait). All receivers are beast12 here, so a track's time of applicability
//! is the frame's arrival time and the latency is exact: both ends are the
//! kernel's receive stamps (the daemon's UDP input and this subscriber), so
//! neither a daemon input task nor this thread waiting for a core hides or
//! adds time.
//!
//! Run: `cargo bench --bench live_load` (minutes; not part of CI).
//! `FUSE1090_LOAD_SPEEDS=8,9` picks the speeds; `FUSE1090_LOAD_SECONDS=60`
//! plays more of the world (20 s by default): at 8x and above a run's p99
//! rests on one or two stalls, and a longer run weighs them fairly.
//! `FUSE1090_LOAD_BIN=path/to/fuse1090` measures another build's daemon.
//! The daemon runs with `realtime_priority = 10` (round-robin realtime
//! scheduling; this process, the load generator and the subscriber stay
//! time-shared), `FUSE1090_LOAD_RT=0` runs it time-shared; the last column
//! says how it ran (`rr10`, or `ts` when the system refused realtime).

use std::net::UdpSocket;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use fuse1090::feed::capture::CaptureReader;
use fuse1090::sim::scenario::Scenario;

fn proc_stat(pid: u32) -> (f64, f64) {
    // (CPU seconds, peak resident MB)
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let fields: Vec<&str> = stat.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let tick = 100.0;
    let cpu = fields.get(11).and_then(|u| u.parse::<f64>().ok()).unwrap_or(0.0)
        + fields.get(12).and_then(|s| s.parse::<f64>().ok()).unwrap_or(0.0);
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let hwm = status
        .lines()
        .find(|l| l.starts_with("VmHWM"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|k| k.parse::<f64>().ok())
        .unwrap_or(0.0);
    (cpu / tick, hwm / 1024.0)
}

fn pct(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() as f64 * p) as usize).min(v.len() - 1)]
}

fn main() {
    if std::env::args().any(|a| a == "--list" || a == "--test") {
        return;
    }
    let dir = std::env::temp_dir().join("fuse1090-load");
    std::fs::create_dir_all(&dir).unwrap();
    let capture = dir.join("capture.txt");
    let mut s =
        Scenario::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios/scale.toml")).unwrap();
    let seconds: f64 =
        std::env::var("FUSE1090_LOAD_SECONDS").ok().and_then(|v| v.parse().ok()).unwrap_or(20.0);
    s.duration_s = seconds;
    for f in &mut s.receiver_field {
        f.gps_share = 0.0;
    }
    let mut cap = Vec::new();
    fuse1090::sim::simulate(&s, &mut cap, std::io::sink()).unwrap();
    std::fs::write(&capture, &cap).unwrap();
    let mut reader = CaptureReader::new(cap.as_slice(), "scale");
    let mut frames = 0u64;
    while let Some(r) = reader.next_record().unwrap() {
        frames += matches!(r, fuse1090::feed::capture::CaptureRecord::Frame(_)) as u64;
    }
    let rxs = reader.receivers().to_vec();
    println!(
        "scale world, {seconds} s: {} receivers, {frames} frames ({:.0} frames/s at 1x)",
        rxs.len(),
        frames as f64 / seconds
    );
    println!(
        "{:>6} {:>12} {:>12} {:>9} {:>6} {:>8} {:>16} {:>16} {:>18} {:>6}",
        "speed",
        "offered/s",
        "processed/s",
        "dropped",
        "cpu",
        "peak MB",
        "adsb p50/p99 ms",
        "mlat p50/p99 ms",
        "adsb n / late p99",
        "sched"
    );
    // FUSE1090_LOAD_SPEEDS="1,2" runs only those speeds.
    let speeds: Vec<f64> = std::env::var("FUSE1090_LOAD_SPEEDS")
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![1.0, 2.0, 4.0, 8.0]);
    // FUSE1090_LOAD_BIN=path runs another build's daemon (A/B comparisons;
    // the load generator stays this build's).
    let daemon_bin =
        std::env::var("FUSE1090_LOAD_BIN").unwrap_or_else(|_| env!("CARGO_BIN_EXE_fuse1090").into());
    let rt: u8 = std::env::var("FUSE1090_LOAD_RT").ok().and_then(|v| v.parse().ok()).unwrap_or(10);
    println!("daemon: {daemon_bin}, realtime_priority = {rt}");
    for speed in speeds {
        let sub = UdpSocket::bind("127.0.0.1:0").unwrap();
        fuse1090::live::stamp::enable(&sub).unwrap();
        // A free UDP port (the daemon's input is UDP: a port a TCP bind
        // found free can still be a UDP socket's, the subscriber's among them).
        let port = UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let mut cfg = format!(
            "[service]\nstats_interval_s = 1000.0\nqueue_frames = 262144\nrealtime_priority = {rt}\n\n[[input]]\nkind = \"udp\"\naddress = \"127.0.0.1:{port}\"\n\n[[output]]\nkind = \"udp\"\naddress = \"{}\"\nformat = \"json\"\n\n",
            sub.local_addr().unwrap()
        );
        for (i, r) in rxs.iter().enumerate() {
            cfg += &format!(
                "[[receiver]]\nid = \"{}\"\nlat = {}\nlon = {}\nalt_m = {}\nclock = \"beast12\"\nsource = \"127.1.{}.{}\"\n\n",
                r.id,
                r.lat,
                r.lon,
                r.alt,
                i / 250,
                1 + i % 250
            );
        }
        let cfg_path = dir.join("load.toml");
        std::fs::write(&cfg_path, cfg).unwrap();
        let log = std::fs::File::create(dir.join("daemon.log")).unwrap();
        let mut daemon = Command::new(&daemon_bin)
            .args(["run", "--config"])
            .arg(&cfg_path)
            .env("RUST_LOG", "info")
            .stderr(Stdio::from(log))
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(300));
        if let Ok(Some(status)) = daemon.try_wait() {
            let log = std::fs::read_to_string(dir.join("daemon.log")).unwrap_or_default();
            panic!("the daemon exited at start ({status}):\n{log}");
        }
        let pid = daemon.id();
        let started = Instant::now();
        let replay = Command::new(env!("CARGO_BIN_EXE_fuse1090"))
            .arg("replay")
            .arg(&capture)
            .arg("--config")
            .arg(&cfg_path)
            .args(["--speed", &speed.to_string()])
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Received datagrams are kept raw and read after the run: parsing
        // JSON as they come took the subscriber a good share of a core at
        // 8x, on the two cores the daemon and the load generator share, and
        // a subscriber that falls behind adds its own backlog to the figure.
        let (mut arena, mut got) =
            (vec![Vec::<u8>::with_capacity(1 << 20)], Vec::<(f64, usize, usize, usize)>::new());
        got.reserve(4 << 20);
        let mut buf = vec![0u8; 65_536];
        sub.set_read_timeout(Some(Duration::from_millis(100))).unwrap();
        let deadline = Instant::now() + Duration::from_secs_f64(seconds / speed + 3.0);
        while Instant::now() < deadline {
            // The kernel's stamp: when the track datagram reached us, however
            // late this thread is scheduled to read it.
            if let Ok((n, _, t_recv)) = fuse1090::live::stamp::recv(&sub, &mut buf) {
                if arena.last().unwrap().len() + n > 1 << 20 {
                    arena.push(Vec::with_capacity(1 << 20));
                }
                let c = arena.len() - 1;
                got.push((t_recv, c, arena[c].len(), n));
                arena[c].extend_from_slice(&buf[..n]);
            }
        }
        let tracks: Vec<(f64, serde_json::Value)> = got
            .iter()
            .filter_map(|&(t_recv, c, at, n)| {
                let v = serde_json::from_slice::<serde_json::Value>(&arena[c][at..at + n]).ok()?;
                (v["type"] == "track").then_some((t_recv, v))
            })
            .collect();
        // The second half of the stream (by the tracks' own times): past
        // start-up (3,000 tracks created, clock sync converging).
        let t0 = tracks.iter().filter_map(|(_, v)| v["t"].as_f64()).fold(f64::INFINITY, f64::min);
        let (mut adsb, mut mlat, mut adsb_late) = (Vec::new(), Vec::new(), Vec::new());
        for (t_recv, v) in &tracks {
            let t = v["t"].as_f64().unwrap_or(*t_recv);
            let lat_ms = (t_recv - t) * 1000.0;
            let sources = v["sources"].as_array().map(|a| a.len()).unwrap_or(0);
            if sources == 1 && v["sources"][0] == "adsb" {
                adsb.push(lat_ms);
                if t > t0 + seconds / 2.0 / speed {
                    adsb_late.push(lat_ms);
                }
            } else {
                mlat.push(lat_ms);
            }
        }
        let out = replay.wait_with_output().unwrap();
        let sent: f64 = String::from_utf8_lossy(&out.stderr)
            .split_whitespace()
            .skip_while(|w| *w != "replay:")
            .nth(1)
            .and_then(|n| n.parse().ok())
            .unwrap_or(0.0);
        let elapsed = started.elapsed().as_secs_f64();
        let (cpu, peak) = proc_stat(pid);
        Command::new("kill").args(["-s", "TERM", &pid.to_string()]).status().unwrap();
        let _ = daemon.wait();
        let text = std::fs::read_to_string(dir.join("daemon.log")).unwrap_or_default();
        let last = text.lines().rev().find(|l| l.contains("stats:")).unwrap_or("");
        let num_after = |key: &str| -> f64 {
            last.split(key)
                .nth(1)
                .and_then(|r| r.split_whitespace().next())
                .and_then(|n| n.trim_end_matches(',').parse().ok())
                .unwrap_or(0.0)
        };
        let processed = num_after("stats: frames ");
        let dropped = num_after("queue drops ") + (sent - processed).max(0.0) - num_after("queue drops ");
        let span = seconds / speed;
        // How the daemon really ran: it falls back to time sharing, with a
        // warning, where realtime scheduling is not permitted.
        let sched =
            if text.contains("realtime round-robin scheduling") { format!("rr{rt}") } else { "ts".into() };
        println!(
            "{:>6} {:>12.0} {:>12.0} {:>9.0} {:>5.0}% {:>8.0} {:>7.1}/{:<8.1} {:>7.0}/{:<8.0} {:>8}/{:<9.1} {:>6}",
            speed,
            sent / span,
            processed / span,
            dropped,
            100.0 * cpu / elapsed,
            peak,
            pct(&mut adsb, 0.5),
            pct(&mut adsb, 0.99),
            pct(&mut mlat, 0.5),
            pct(&mut mlat, 0.99),
            adsb.len(),
            pct(&mut adsb_late, 0.99),
            sched,
        );
    }
}
