//! The service driven in-process, as mini-redis's tests drive its server:
//! `live::serve` with a configuration, a shutdown future and a channel of
//! re-read configurations, over real loopback sockets. A reload is a
//! configuration sent, not a SIGHUP, and the end is a future completing,
//! so the tests read what the service does from its sockets and its typed
//! counters ([`fuse1090::live::Counters`]), not its log.

mod common;

use std::io::{Read, Write};
use std::net::{TcpListener, UdpSocket};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use fuse1090::config::Config;
use fuse1090::live::registry::Registry;
use fuse1090::live::Counters;
use tokio::sync::{mpsc, oneshot};

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

/// A service started in-process on `cfg`: the way to stop it, to reload
/// it, its counters, and its end.
struct InProcess {
    stop: oneshot::Sender<()>,
    reload: mpsc::Sender<Config>,
    counters: Counters,
    end: std::sync::mpsc::Receiver<anyhow::Result<()>>,
}

impl InProcess {
    fn start(cfg: Config) -> InProcess {
        let (stop, stopped) = oneshot::channel::<()>();
        let (reload, reloads) = mpsc::channel(1);
        let (ended, end) = std::sync::mpsc::channel();
        let counters = Counters::default();
        let theirs = counters.clone();
        std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
            let shutdown = async { stopped.await.unwrap_or(()) };
            let _ =
                ended.send(rt.block_on(fuse1090::live::serve_counted(cfg, None, shutdown, reloads, &theirs)));
        });
        InProcess { stop, reload, counters, end }
    }

    /// Its registry, once it has started.
    fn registry(&self) -> Arc<Registry> {
        let t0 = Instant::now();
        loop {
            if let Some(r) = self.counters.registry() {
                return r.clone();
            }
            assert!(t0.elapsed() < Duration::from_secs(5), "the service did not start");
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Stops it and checks that it ended well and soon.
    fn stop(self) {
        self.stop.send(()).unwrap();
        let result = self.end.recv_timeout(Duration::from_secs(5)).expect("serve did not end");
        assert!(result.is_ok(), "{result:?}");
    }
}

/// Waits up to 10 s for `what` to hold.
fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !done() {
        assert!(t0.elapsed() < Duration::from_secs(10), "{what} did not happen");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A reload that moves a UDP receiver to another source address: datagrams
/// from the old address are refused from then on and the new one's are the
/// receiver's (the UDP input keeps a per-address cache of the receivers,
/// which the reload must refresh).
#[test]
fn a_reload_moves_a_udp_receiver_to_its_new_source_address() {
    let port = common::free_port();
    let cfg = |source: &str| {
        let text = format!(
            "[[receiver]]\nid = \"moved\"\nlat = 45.0\nlon = 5.0\nalt_m = 100.0\nclock = \"beast12\"\n\
             source = \"{source}\"\n\n[[input]]\nkind = \"udp\"\naddress = \"127.0.0.1:{port}\"\n"
        );
        Config::parse(&text, "moved.toml").unwrap()
    };
    let service = InProcess::start(cfg("127.0.3.1"));
    let reg = service.registry();
    let frames = || reg.counters_of("moved").unwrap().frames.load(Ordering::Relaxed);
    let unknown = || reg.unknown_senders.load(Ordering::Relaxed);
    // One frame per datagram.
    let frame = common::live::beast_frame();
    let send = |from: &str, n: usize| {
        let s = UdpSocket::bind(format!("{from}:0")).unwrap();
        for _ in 0..n {
            s.send_to(&frame, ("127.0.0.1", port)).unwrap();
        }
    };
    send("127.0.3.1", 5);
    wait_until("five frames counted from the configured address", || frames() == 5);
    assert_eq!(unknown(), 0);

    let generation = reg.generation.load(Ordering::Relaxed);
    service.reload.blocking_send(cfg("127.0.3.2")).unwrap();
    wait_until("the reload", || reg.generation.load(Ordering::Relaxed) > generation);
    send("127.0.3.1", 3);
    send("127.0.3.2", 7);
    wait_until("the old address's three refused", || unknown() == 3);
    wait_until("the new address's seven counted", || frames() == 12);
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!((frames(), unknown()), (12, 3), "after the move");
    service.stop();
}

/// A receiver that goes silent without closing its connection (power cut,
/// a NAT that forgot it) is dropped after the input's idle timeout and, for
/// a TCP client input, connected to again; its counters say so.
#[test]
fn a_silent_receiver_is_reconnected_after_the_idle_timeout() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let text = format!(
        "[[receiver]]\nid = \"quiet\"\nlat = 45.0\nlon = 5.0\nalt_m = 100.0\nclock = \"beast12\"\n\n\
         [[input]]\nkind = \"beast_tcp_client\"\naddress = \"{}\"\nreceiver = \"quiet\"\n\
         idle_timeout_s = 0.5\n",
        listener.local_addr().unwrap()
    );
    let service = InProcess::start(Config::parse(&text, "quiet.toml").unwrap());
    let (mut first, _) = listener.accept().unwrap();
    first.write_all(&common::live::beast_frame()).unwrap();
    let c = service.registry().counters_of("quiet").unwrap();
    let count = |n: &std::sync::atomic::AtomicU64| n.load(Ordering::Relaxed);
    // Then silence, the connection left open: the service closes it...
    let t0 = Instant::now();
    first.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut byte = [0u8; 1];
    assert!(matches!(first.read(&mut byte), Ok(0)), "the silent connection stays open");
    let closed_after = t0.elapsed();
    assert!(closed_after >= Duration::from_millis(400), "closed before the timeout: {closed_after:?}");
    // (The connection is counted lost once its task has closed it.)
    wait_until("the lost connection counted", || count(&c.disconnects) == 1);
    assert_eq!((count(&c.frames), count(&c.idle_timeouts)), (1, 1));
    // ... and connects again.
    listener.set_nonblocking(true).unwrap();
    wait_until("a reconnection", || listener.accept().is_ok());
    wait_until("the second connection counted", || count(&c.connects) == 2);
    service.stop();
}
