//! The Beast TCP server input: receivers connect and push. A sender is
//! known by its configured source address, or else names itself with
//! readsb's receiver id (0xe3) or UUID (0xe4) frame within its first
//! seconds; unknown ones are refused and counted. One connection per
//! receiver: a newer one closes the older (a half-open one may linger for
//! hours behind a NAT that forgot it).
//!
//! What protects a receiver's name: a connection named by its id may not
//! displace a live connection of that receiver from another source address
//! (anyone who knows an id could otherwise take the receiver over), unless
//! the receiver says `beast_id_takeover = true` (a receiver behind a
//! changing address, whose old connection may be half open). Strangers may
//! hold at most [`NAMING_PER_ADDRESS`] connections each, and
//! [`NAMING_AT_ONCE`] together, while they have not named themselves, and
//! each only for [`NAME_WAIT_S`] and [`NAME_BYTES`]: an idle crowd cannot
//! lock real receivers out. Every connection ends when its receiver is
//! removed from the configuration or its input is (SIGHUP).

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::Ordering;
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::io::Interest;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Notify};

use super::config::{BeastId, InputConfig};
use super::inputs::{count_parsed, forward, stream};
use super::registry::Registry;
use super::ToCore;
use crate::feed::{parser_for, FeedEvent, FrameParser, InputFormat, RawFrame};

/// How long a sender whose address names no receiver has to name itself,
/// how much it may send before it does, and how many may be at it at once,
/// in all and from one address: together they bound what strangers can
/// make the service hold.
pub const NAME_WAIT_S: f64 = 10.0;
pub const NAME_BYTES: usize = 256 << 10;
pub const NAMING_AT_ONCE: usize = 64;
pub const NAMING_PER_ADDRESS: usize = 4;

/// Connections naming themselves now, in all and per source address;
/// taken and given back under one lock, so the bounds hold exactly.
#[derive(Default)]
struct Naming {
    per_address: Mutex<HashMap<IpAddr, usize>>,
}

/// A naming slot, given back when dropped.
struct Slot<'a>(&'a Naming, IpAddr);

impl Naming {
    fn take(&self, ip: IpAddr) -> Result<Slot<'_>, &'static str> {
        let mut m = self.per_address.lock().expect("naming");
        if m.values().sum::<usize>() >= NAMING_AT_ONCE {
            return Err("too many connections naming themselves at once");
        }
        let n = m.entry(ip).or_default();
        if *n >= NAMING_PER_ADDRESS {
            return Err("too many connections from this address naming themselves at once");
        }
        *n += 1;
        Ok(Slot(self, ip))
    }
}

impl Drop for Slot<'_> {
    fn drop(&mut self) {
        let mut m = self.0.per_address.lock().expect("naming");
        if let Some(n) = m.get_mut(&self.1) {
            *n -= 1;
            if *n == 0 {
                m.remove(&self.1);
            }
        }
    }
}

/// Each receiver's newest connection: how to close it and where it comes from.
type Newest = Mutex<HashMap<usize, (Arc<Notify>, IpAddr)>>;

/// What one accepted connection needs, shared by all of the input's.
struct Shared {
    input: InputConfig,
    tx: SyncSender<ToCore>,
    reg: Arc<Registry>,
    newest: Newest,
    naming: Naming,
}

pub async fn tcp_server(
    input: &InputConfig,
    listener: TcpListener,
    tx: SyncSender<ToCore>,
    reg: Arc<Registry>,
) -> std::io::Result<()> {
    let fixed = input.receiver.as_deref().and_then(|id| reg.index_of(id));
    let shared = Arc::new(Shared {
        input: input.clone(),
        tx,
        reg: reg.clone(),
        newest: Newest::default(),
        naming: Naming::default(),
    });
    // Dropped with this task (the input removed or replaced by SIGHUP, or
    // the service stopping): every connection it accepted then ends.
    let (_alive, alive) = watch::channel(());
    let mut in_a_row = 0;
    loop {
        let (sock, peer) = match listener.accept().await {
            Ok(a) => a,
            Err(e) => {
                reg.socket_error(input, "accept", e, &mut in_a_row).await;
                continue;
            }
        };
        in_a_row = 0;
        let known = fixed.or_else(|| reg.by_source(peer.ip(), input));
        if known.is_none() && !reg.names_itself(input) {
            refuse(&reg, peer, "unknown sender refused");
            continue;
        }
        let (shared, alive) = (shared.clone(), alive.clone());
        tokio::spawn(async move { connection(sock, peer, known, &shared, alive).await });
    }
}

/// One accepted connection, from naming (if its address did not) to its end.
async fn connection(
    sock: TcpStream,
    peer: SocketAddr,
    known: Option<usize>,
    sh: &Shared,
    mut alive: watch::Receiver<()>,
) {
    let reg = &sh.reg;
    let mut parser = parser_for(InputFormat::Beast);
    let (rx, early) = match known {
        Some(rx) => (rx, None),
        None => {
            let slot = match sh.naming.take(peer.ip()) {
                Ok(s) => s,
                Err(why) => return refuse(reg, peer, &format!("unknown sender refused: {why}")),
            };
            let named = identify(&sock, parser.as_mut(), &sh.input, reg).await;
            drop(slot);
            match named {
                Ok((rx, frames, arrival, bytes)) => (rx, Some((frames, arrival, bytes))),
                Err(why) => return refuse(reg, peer, &format!("unknown sender refused: {why}")),
            }
        }
    };
    let (cfg, c) = reg.get(rx);
    let stop = Arc::new(Notify::new());
    {
        let mut newest = sh.newest.lock().expect("connections");
        if let Some((_, from)) = newest.get(&rx) {
            if known.is_none() && *from != peer.ip() && !cfg.beast_id_takeover {
                drop(newest);
                let why = format!(
                    "receiver {} is connected from another address (beast_id_takeover is off)",
                    cfg.id
                );
                return refuse(reg, peer, &format!("sender refused: {why}"));
            }
        }
        if let Some((older, _)) = newest.insert(rx, (stop.clone(), peer.ip())) {
            // A permit is stored if that task is not waiting yet; if it has
            // ended, nobody reads it.
            older.notify_one();
        }
    }
    c.connects.fetch_add(1, Ordering::Relaxed);
    if let Some(held) = c.connection_log.pass(super::unix_now()) {
        tracing::info!(peer = %peer, receiver = cfg.id, held_back = held, "receiver connected");
    }
    if let Some((frames, arrival, bytes)) = early {
        c.bytes.fetch_add(bytes as u64, Ordering::Relaxed);
        count_parsed(&c, &Default::default(), parser.stats());
        forward(&sh.tx, reg, &c, rx, arrival, frames);
    }
    let closed = |why: &str| Err(std::io::Error::other(format!("closed: {why}")));
    let r = if c.revoked.load(Ordering::Relaxed) {
        closed("the receiver was removed from the configuration")
    } else {
        tokio::select! {
            r = stream(sock, parser, &sh.input, &sh.tx, reg, rx) => r,
            _ = stop.notified() => closed("the receiver connected again"),
            _ = c.revoke.notified() => closed("the receiver was removed from the configuration"),
            _ = alive.changed() => closed("its input was removed"),
        }
    };
    {
        let mut newest = sh.newest.lock().expect("connections");
        if newest.get(&rx).is_some_and(|(s, _)| Arc::ptr_eq(s, &stop)) {
            newest.remove(&rx);
        }
    }
    c.disconnects.fetch_add(1, Ordering::Relaxed);
    if let Some(held) = c.connection_log.pass(super::unix_now()) {
        let why = r.err().map_or("end of stream".into(), |e| e.to_string());
        tracing::warn!(peer = %peer, receiver = cfg.id, held_back = held, "receiver disconnected: {why}");
    }
}

/// Counts a refused sender and logs the first of each power of two.
pub(super) fn refuse(reg: &Registry, peer: std::net::SocketAddr, why: &str) {
    let n = reg.unknown_senders.fetch_add(1, Ordering::Relaxed) + 1;
    if n.is_power_of_two() {
        tracing::warn!(peer = %peer, refused = n, "{why}");
    }
}

/// Reads a connection from an address no receiver has until the sender
/// names itself with readsb's receiver id (0xe3) or UUID (0xe4) frame, and
/// looks the receiver up by its `beast_id`. Returns it with the frames read
/// meanwhile (the connection is one receiver's, before its name too), the
/// last read's arrival and the bytes read. The first name holds for the
/// connection: later ones are not looked at.
async fn identify(
    sock: &TcpStream,
    parser: &mut (dyn FrameParser + Send),
    input: &InputConfig,
    reg: &Registry,
) -> Result<(usize, Vec<RawFrame>, f64, usize), String> {
    let _ = super::stamp::enable(sock);
    let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(NAME_WAIT_S);
    let mut buf = vec![0u8; 16 * 1024];
    let (mut frames, mut bytes, mut named) = (Vec::new(), 0usize, None);
    loop {
        let read = sock.async_io(Interest::READABLE, || super::stamp::recv(sock, &mut buf));
        let (n, _, arrival) = tokio::time::timeout_at(deadline, read)
            .await
            .map_err(|_| format!("no receiver named within {NAME_WAIT_S} s"))?
            .map_err(|e| e.to_string())?;
        if n == 0 {
            return Err("closed before naming a receiver".into());
        }
        bytes += n;
        parser.push(&buf[..n], &mut |ev| match ev {
            FeedEvent::Frame(f) => frames.push(f),
            other => named = named.or(BeastId::of(&other)),
        });
        if let Some(id) = named {
            return reg
                .by_beast_id(id, input)
                .map(|rx| (rx, frames, arrival, bytes))
                .ok_or_else(|| format!("it names receiver {id}, which this input does not take"));
        }
        if bytes > NAME_BYTES {
            return Err(format!("{bytes} bytes without naming a receiver"));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::live::config::{InputKind, ReceiverConfig};
    use crate::live::inputs;
    use std::sync::mpsc::sync_channel;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    use crate::feed::test_frames as frames;

    fn beast(frames: &[RawFrame]) -> Vec<u8> {
        let mut out = Vec::new();
        for f in frames {
            crate::feed::beast::encode(f, &mut out);
        }
        out
    }

    /// A TCP server input on a free loopback port taking any receiver.
    fn server_input() -> (InputConfig, SocketAddr) {
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let address: SocketAddr = ([127, 0, 0, 1], port).into();
        let input = InputConfig {
            kind: InputKind::BeastTcpServer,
            address,
            receiver: None,
            receivers: Vec::new(),
            format: crate::feed::detect::InputFormat::Beast,
            idle_timeout_s: 0.0,
        };
        (input, address)
    }

    /// A Beast TCP server input on a free loopback port, running for
    /// `reg` into `tx` until the stopper is told; its address.
    async fn start_server(
        reg: &Arc<Registry>,
        tx: std::sync::mpsc::SyncSender<ToCore>,
    ) -> (SocketAddr, crate::live::shutdown::Stopper, tokio::task::JoinHandle<()>) {
        let (input, address) = server_input();
        let bound = inputs::bind(&input).await.unwrap();
        let (stopper, shutdown) = crate::live::shutdown::Stopper::new();
        let task = inputs::spawn(input, bound, tx, reg.clone(), &shutdown);
        // The input's task listening before the test connects.
        tokio::time::sleep(Duration::from_millis(50)).await;
        (address, stopper, task)
    }

    /// A connection to `to` from loopback address `from`.
    async fn connect(from: [u8; 4], to: SocketAddr) -> TcpStream {
        let s = tokio::net::TcpSocket::new_v4().unwrap();
        s.bind(SocketAddr::from((from, 0))).unwrap();
        s.connect(to).await.unwrap()
    }

    /// Whether the daemon closed `s` within a second.
    async fn closed(s: &mut TcpStream) -> bool {
        let mut b = [0u8; 1];
        matches!(tokio::time::timeout(Duration::from_secs(1), s.read(&mut b)).await, Ok(Ok(0)) | Ok(Err(_)))
    }

    /// A Beast TCP server takes a sender its address does not name once it
    /// names itself (readsb's receiver id or UUID frame), with the frames it
    /// sent before its name too, and refuses and counts one that names an
    /// unknown receiver or nobody.
    #[test]
    fn a_tcp_sender_is_known_by_the_receiver_id_or_uuid_it_sends() {
        use tokio::io::AsyncWriteExt;
        let uuid = *b"0f1e2d3c-4b5a-6978-8796-a5b4c3d2e1f0";
        let reg = Arc::new(Registry { queue_frames: 1000, ..Default::default() });
        for r in [
            ReceiverConfig::for_test("a", Some("0102030405060708")),
            ReceiverConfig::for_test("b", Some("0F1E2D3C-4B5A-6978-8796-A5B4C3D2E1F0")),
            ReceiverConfig::for_test("c", None),
        ] {
            reg.add(r);
        }
        let (tx, core) = sync_channel(100);
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        rt.block_on(async {
            let (address, stopper, task) = start_server(&reg, tx).await;
            let mut id = Vec::new();
            crate::feed::beast::encode_receiver_id(0x0102_0304_0506_0708, &mut id);
            let mut named_uuid = Vec::new();
            crate::feed::beast::encode_receiver_uuid(&uuid, &mut named_uuid);
            let mut unknown = Vec::new();
            crate::feed::beast::encode_receiver_id(0xdead_beef, &mut unknown);
            let sessions = [
                [beast(&frames(1)), named_uuid, beast(&frames(2))].concat(),
                [id, beast(&frames(3))].concat(),
                [unknown, beast(&frames(4))].concat(),
                beast(&frames(5)),
            ];
            for bytes in sessions {
                let mut s = TcpStream::connect(address).await.unwrap();
                s.write_all(&bytes).await.unwrap();
                s.shutdown().await.unwrap();
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            stopper.stop();
            let _ = task.await;
        });
        let mut got: Vec<(usize, usize)> = Vec::new();
        for m in core.try_iter() {
            if let ToCore::Frames { rx, frames, .. } = m {
                match got.last_mut() {
                    Some((last, n)) if *last == rx => *n += frames.len(),
                    _ => got.push((rx, frames.len())),
                }
            }
        }
        assert_eq!(got, vec![(1, 3), (0, 3)]);
        assert_eq!(reg.unknown_senders.load(Ordering::Relaxed), 2);
        assert_eq!(reg.counters(1).connects.load(Ordering::Relaxed), 1);
    }

    /// Who may hold a receiver's name: an idle crowd from one address gets
    /// four naming slots, not the real receiver's; a connection naming a
    /// receiver connected from another address is refused (unless the
    /// receiver allows takeover), and one from the same address replaces
    /// it; removing the receiver from the configuration closes its
    /// connection, and no new one is taken.
    #[test]
    fn a_receivers_name_cannot_be_blocked_or_hijacked_and_removal_revokes_it() {
        let reg = Arc::new(Registry { queue_frames: 1000, ..Default::default() });
        let mut open = ReceiverConfig::for_test("open", Some("00000000000000bb"));
        open.beast_id_takeover = true;
        let kept = [ReceiverConfig::for_test("a", Some("00000000000000aa")), open];
        for r in kept.clone() {
            reg.add(r);
        }
        let (tx, _core) = sync_channel(1000);
        let named = |id: u64| {
            let mut b = Vec::new();
            crate::feed::beast::encode_receiver_id(id, &mut b);
            [b, beast(&frames(1))].concat()
        };
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        rt.block_on(async {
            let (address, stopper, task) = start_server(&reg, tx).await;
            // Ten idle strangers from one address: four wait to name
            // themselves, six are closed at once.
            let mut crowd = Vec::new();
            for _ in 0..10 {
                crowd.push(connect([127, 0, 5, 1], address).await);
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
            let mut shut = 0;
            for s in &mut crowd {
                shut += closed(s).await as usize;
            }
            assert_eq!(shut, 6);
            // The real receiver, from elsewhere, still names itself.
            let mut real = connect([127, 0, 5, 2], address).await;
            real.write_all(&named(0xaa)).await.unwrap();
            tokio::time::sleep(Duration::from_millis(100)).await;
            assert_eq!(reg.counters(0).connects.load(Ordering::Relaxed), 1);
            // Its id from another address: refused, the real one kept.
            let mut thief = connect([127, 0, 5, 3], address).await;
            thief.write_all(&named(0xaa)).await.unwrap();
            assert!(closed(&mut thief).await);
            assert!(!closed(&mut real).await, "the real receiver was displaced");
            // From its own address again (a reconnect): the newer one wins.
            let mut again = connect([127, 0, 5, 2], address).await;
            again.write_all(&named(0xaa)).await.unwrap();
            assert!(closed(&mut real).await);
            // A receiver that allows takeover is taken over from anywhere.
            let mut first = connect([127, 0, 5, 4], address).await;
            first.write_all(&named(0xbb)).await.unwrap();
            tokio::time::sleep(Duration::from_millis(100)).await;
            let mut moved = connect([127, 0, 5, 5], address).await;
            moved.write_all(&named(0xbb)).await.unwrap();
            assert!(closed(&mut first).await);
            // "a" removed from the configuration: its connection ends, and
            // naming it again is refused.
            reg.reconfigure(&kept[1..]);
            assert!(closed(&mut again).await);
            let mut late = connect([127, 0, 5, 2], address).await;
            late.write_all(&named(0xaa)).await.unwrap();
            assert!(closed(&mut late).await);
            assert!(!closed(&mut moved).await, "a kept receiver was closed");
            // The input itself removed: its connections end with it.
            stopper.stop();
            let _ = task.await;
            assert!(closed(&mut moved).await);
        });
        assert_eq!(reg.counters(0).connects.load(Ordering::Relaxed), 2);
    }
}
