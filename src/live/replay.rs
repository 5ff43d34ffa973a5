//! `fuse1090 replay`: a capture's receivers played to a running daemon over
//! real sockets, one connection per receiver, in real time (or faster).
//!
//! Each receiver is reached the way the daemon's configuration expects it:
//! for a `beast_tcp_client` input we are the receiver's Beast port (we
//! listen, the daemon connects); for a `beast_tcp_server` input we connect
//! from the receiver's configured source address; for `udp` we send
//! datagrams from that address. GPS timestamps are moved to today, so the
//! daemon sees current times; free-running counters need no change.

use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpSocket, UdpSocket};

use super::config::{BeastId, InputKind};
use super::unix_now;
use crate::config::Config;
use crate::feed::beast;
use crate::feed::capture::{CaptureReader, CaptureRecord, ClockKind};
use crate::feed::detect::InputFormat;
use crate::feed::RawFrame;

/// How one receiver reaches the daemon.
#[derive(Clone, Copy, Debug)]
enum Route {
    /// We listen here; the daemon connects.
    Serve(SocketAddr),
    /// We connect here, from this local address, and name the receiver
    /// first when its address does not.
    Connect(SocketAddr, Option<std::net::IpAddr>, Option<BeastId>),
    /// Datagrams to here, from this local address.
    Datagram(SocketAddr, Option<std::net::IpAddr>),
}

fn route(cfg: &Config, id: &str) -> Option<Route> {
    let r = cfg.receiver.iter().find(|r| r.id == id)?;
    for input in cfg.input.iter().filter(|i| i.takes(r)) {
        let target = match input.address.ip() {
            ip if ip.is_unspecified() => SocketAddr::new([127, 0, 0, 1].into(), input.address.port()),
            _ => input.address,
        };
        match input.kind {
            InputKind::BeastTcpClient => return Some(Route::Serve(input.address)),
            InputKind::BeastTcpServer => return Some(Route::Connect(target, r.source, r.beast_name())),
            InputKind::Udp if input.format == InputFormat::Beast => {
                return Some(Route::Datagram(target, r.source))
            }
            InputKind::Udp => {}
        }
    }
    None
}

/// Plays the capture; returns the number of frames sent.
pub async fn replay(capture: &Path, cfg: &Config, speed: f64) -> Result<u64> {
    let file = File::open(capture).with_context(|| format!("cannot open {}", capture.display()))?;
    let mut reader = CaptureReader::new(BufReader::new(file), capture.display().to_string());
    let mut per_rx: HashMap<usize, Vec<(f64, RawFrame)>> = HashMap::new();
    while let Some(rec) = reader.next_record()? {
        if let CaptureRecord::Frame(f) = rec {
            per_rx.entry(f.rx).or_default().push((f.arrival, f.frame));
        }
    }
    let decls = reader.receivers().to_vec();
    let first = per_rx.values().flat_map(|v| v.iter().map(|f| f.0)).fold(f64::INFINITY, f64::min);
    if !first.is_finite() {
        bail!("{}: no frames", capture.display());
    }
    let start = unix_now() + 0.2;
    // GPS timestamps move by a whole number of nanoseconds (see
    // `ClockKind::gps_shift`); the schedule itself needs no such care.
    let shift_ns = ((start - first) * 1e9).round() as i64;
    tracing::info!(
        shift_ns,
        "the capture's times moved by {shift_ns} ns (subtract it from the output's to compare with the capture)"
    );
    let mut tasks = Vec::new();
    for (rx, frames) in per_rx {
        let decl = &decls[rx];
        let Some(route) = route(cfg, &decl.id) else {
            tracing::warn!(
                receiver = decl.id,
                "replay: no input of the configuration takes this receiver; skipped"
            );
            continue;
        };
        let gps = decl.clock == ClockKind::Gps;
        let id = decl.id.clone();
        tasks.push(tokio::spawn(async move {
            let r = play(route, frames, gps, start, first, shift_ns, speed).await;
            if let Err(e) = &r {
                tracing::error!(receiver = id, "replay: {e:#}");
            }
            r.unwrap_or(0)
        }));
    }
    let mut sent = 0;
    for t in tasks {
        sent += t.await.unwrap_or(0);
    }
    Ok(sent)
}

enum Sink {
    Tcp(tokio::net::TcpStream),
    Udp(UdpSocket, SocketAddr),
}

async fn play(
    route: Route,
    frames: Vec<(f64, RawFrame)>,
    gps: bool,
    start: f64,
    first: f64,
    shift_ns: i64,
    speed: f64,
) -> Result<u64> {
    let mut sink = match route {
        Route::Serve(addr) => {
            let l = TcpListener::bind(addr).await.with_context(|| format!("listen {addr}"))?;
            let (s, _) = l.accept().await?;
            Sink::Tcp(s)
        }
        Route::Connect(addr, src, name) => {
            let s = if addr.is_ipv4() { TcpSocket::new_v4()? } else { TcpSocket::new_v6()? };
            if let Some(ip) = src {
                s.bind(SocketAddr::new(ip, 0)).with_context(|| format!("bind {ip}"))?;
            }
            let mut conn = s.connect(addr).await.with_context(|| format!("connect {addr}"))?;
            // The receiver's name before its frames, so that a daemon that
            // does not know it by address can tell who it is.
            let mut named = Vec::new();
            match name {
                Some(BeastId::Id(id)) => beast::encode_receiver_id(id, &mut named),
                Some(BeastId::Uuid(u)) => beast::encode_receiver_uuid(&u, &mut named),
                None => {}
            }
            conn.write_all(&named).await?;
            Sink::Tcp(conn)
        }
        Route::Datagram(addr, src) => {
            let local = SocketAddr::new(
                src.unwrap_or(if addr.is_ipv4() { [0, 0, 0, 0].into() } else { [0u16; 8].into() }),
                0,
            );
            Sink::Udp(UdpSocket::bind(local).await?, addr)
        }
    };
    let mut sent = 0u64;
    let mut buf = Vec::with_capacity(64 * 1024);
    let mut i = 0;
    while i < frames.len() {
        let due = start + (frames[i].0 - first) / speed;
        let wait = due - unix_now();
        if wait > 0.0 {
            tokio::time::sleep(Duration::from_secs_f64(wait)).await;
        }
        // Everything due by now, in one write (a datagram: up to 1,400 bytes).
        let now = unix_now();
        buf.clear();
        while i < frames.len() && start + (frames[i].0 - first) / speed <= now {
            let mut f = frames[i].1;
            if gps && f.has_timing() {
                f.timestamp = ClockKind::gps_shift(f.timestamp, shift_ns);
            }
            beast::encode(&f, &mut buf);
            i += 1;
            sent += 1;
            if matches!(sink, Sink::Udp(..)) && buf.len() > 1_400 {
                break;
            }
        }
        match &mut sink {
            Sink::Tcp(s) => s.write_all(&buf).await?,
            Sink::Udp(s, addr) => {
                s.send_to(&buf, *addr).await?;
            }
        }
    }
    if let Sink::Tcp(mut s) = sink {
        let _ = s.shutdown().await;
    }
    Ok(sent)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::AsyncReadExt;

    /// Frames of a GPS-timed receiver recorded in 2020, replayed today over
    /// a real socket: every timestamp moves by one and the same whole number
    /// of nanoseconds, so the differences between them (what
    /// multilateration uses) are exact. Through `f64` Unix seconds they were
    /// off by up to about 120 ns.
    #[test]
    fn replayed_gps_timestamps_keep_their_differences_to_the_nanosecond() {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let cfg = Config::parse(
            &format!(
                "[[receiver]]\nid = \"g\"\nlat = 49.0\nlon = 2.5\nalt_m = 100.0\nclock = \"gps\"\n\
                 source = \"127.0.0.1\"\n[[input]]\nkind = \"beast_tcp_server\"\naddress = \"127.0.0.1:{port}\"\n"
            ),
            "test",
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let capture = dir.path().join("c.txt");
        let gps = |s: u64, ns: u64| (s << 30) | ns;
        // Nanoseconds that no f64 Unix time of today holds.
        let stamps = [gps(43_200, 123_456_789), gps(43_200, 123_456_790), gps(43_200, 987_654_321)];
        let decl = cfg.receiver[0].decl();
        let mut w = crate::feed::capture::CaptureWriter::new(Vec::new(), "test").unwrap();
        w.receiver(&decl).unwrap();
        for (k, ts) in stamps.iter().enumerate() {
            let arrival = 1_590_969_600.0 + 43_200.0 + 0.2 + k as f64 * 0.01;
            w.frame(arrival, 0, &RawFrame::new(&[0x20, 0, 0, 0, 0, 0, 0], *ts, 0).unwrap()).unwrap();
        }
        std::fs::write(&capture, w.into_inner()).unwrap();
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        let received = rt.block_on(async {
            listener.set_nonblocking(true).unwrap();
            let l = TcpListener::from_std(listener).unwrap();
            let server = tokio::spawn(async move {
                let (mut s, _) = l.accept().await.unwrap();
                let mut bytes = Vec::new();
                s.read_to_end(&mut bytes).await.unwrap();
                bytes
            });
            assert_eq!(replay(&capture, &cfg, 50.0).await.unwrap(), 3);
            server.await.unwrap()
        });
        let mut got = Vec::new();
        let mut parser = crate::feed::parser_for(crate::feed::InputFormat::Beast);
        parser.push(&received, &mut |ev| {
            if let crate::feed::FeedEvent::Frame(f) = ev {
                got.push(f.timestamp)
            }
        });
        assert_eq!(got.len(), 3);
        let ns = |t: u64| (t >> 30) as i64 * 1_000_000_000 + (t & 0x3FFF_FFFF) as i64;
        for (a, b) in stamps.iter().zip(&got) {
            assert_eq!(ns(*b) - ns(got[0]), ns(*a) - ns(stamps[0]), "{got:x?}");
        }
        assert_ne!(got[0], stamps[0], "moved to today");
    }
}
