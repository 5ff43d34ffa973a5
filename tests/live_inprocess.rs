//! The service driven in-process, as mini-redis's tests drive its server:
//! `live::serve` with a configuration, a shutdown future and a channel of
//! re-read configurations, over real loopback sockets. A reload is a
//! configuration sent, not a SIGHUP, and the end is a future completing,
//! so the test reads what the service does from its sockets, not its log.

mod common;

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use fuse1090::config::Config;

/// Datagrams arriving at `sock` until `until`.
fn received(sock: &UdpSocket, until: Instant) -> usize {
    let mut n = 0;
    let mut buf = vec![0u8; 65_536];
    while Instant::now() < until {
        if sock.recv(&mut buf).is_ok() {
            n += 1;
        }
    }
    n
}

fn output_to(text: &str, port: u16) -> Config {
    let text = format!("{text}kind = \"udp\"\naddress = \"127.0.0.1:{port}\"\n");
    Config::parse(&text, "in-process.toml").unwrap()
}

#[test]
fn the_service_reloads_and_stops_when_told_in_process() {
    let (first, second) = (UdpSocket::bind("127.0.0.1:0").unwrap(), UdpSocket::bind("127.0.0.1:0").unwrap());
    for s in [&first, &second] {
        s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    }
    let input_port = common::free_port();
    // The demo: the surface capture replayed into the service's own Beast
    // TCP server, fast.
    let demo = common::live::demo(input_port, 4.0, "");
    let cfg = output_to(&demo, first.local_addr().unwrap().port());
    let moved = output_to(&demo, second.local_addr().unwrap().port());

    // The service on a runtime of its own, as `fuse1090 run` runs it.
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let (reload, reloads) = tokio::sync::mpsc::channel(1);
    let (ended, end) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        let shutdown = async { stopped.await.unwrap_or(()) };
        let _ = ended.send(rt.block_on(fuse1090::live::serve(cfg, None, shutdown, reloads)));
    });

    let at_first = received(&first, Instant::now() + Duration::from_secs(4));
    assert!(at_first > 20, "{at_first} track datagrams at the configured output");
    reload.blocking_send(moved).unwrap();
    // The reload takes effect between two batches.
    received(&first, Instant::now() + Duration::from_millis(500));
    let t = Instant::now() + Duration::from_secs(3);
    let (after_first, at_second) = std::thread::scope(|s| {
        let a = s.spawn(|| received(&first, t));
        let b = received(&second, t);
        (a.join().unwrap(), b)
    });
    assert_eq!(after_first, 0, "the replaced output still sent");
    assert!(at_second > 10, "{at_second} track datagrams at the new output");

    let asked = Instant::now();
    stop.send(()).unwrap();
    let result =
        end.recv_timeout(Duration::from_secs(5)).expect("serve did not end within 5 s of its shutdown");
    assert!(result.is_ok(), "{result:?}");
    assert!(asked.elapsed() < Duration::from_secs(3), "took {:?}", asked.elapsed());
    // Its input was told to stop and did: the port is free again.
    std::net::TcpListener::bind(("127.0.0.1", input_port)).expect("the input's port still taken");
}
