//! Datagrams and TCP reads with the time the kernel received them
//! (`SO_TIMESTAMPNS`; for a TCP read, that of its newest bytes).
//!
//! A frame's arrival time is a measurement: for receivers without GPS
//! timing it is the time of applicability of their ADS-B positions, and
//! latency is counted from it. Read from the clock after `recvfrom`, it
//! would include however long the datagram waited in the socket's buffer
//! for the input task to be scheduled, which under load is milliseconds
//! (the two cores are shared by the core's threads); the kernel's stamp
//! is taken as the datagram reaches the socket. Where the option cannot
//! be set or a datagram comes without a stamp, the clock is read instead;
//! so it is on systems other than Linux, which name the option differently.

use std::io::IoSliceMut;
use std::net::SocketAddr;
use std::os::fd::{AsFd, AsRawFd};

use nix::sys::socket::{recvmsg, ControlMessageOwned, MsgFlags, RecvMsg, SockaddrStorage};

use super::unix_now;

/// Asks the kernel to stamp every datagram this socket receives.
#[cfg(target_os = "linux")]
pub fn enable<F: AsFd>(socket: &F) -> std::io::Result<()> {
    nix::sys::socket::setsockopt(socket, nix::sys::socket::sockopt::ReceiveTimestampns, &true)
        .map_err(std::io::Error::from)
}

#[cfg(not(target_os = "linux"))]
pub fn enable<F: AsFd>(_socket: &F) -> std::io::Result<()> {
    Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "SO_TIMESTAMPNS is Linux's"))
}

/// Asks the kernel to tell, with each datagram, how many it has dropped on
/// this socket so far for want of buffer space (`SO_RXQ_OVFL`): losses no
/// counter of ours could otherwise see.
#[cfg(target_os = "linux")]
pub fn count_drops<F: AsFd>(socket: &F) -> std::io::Result<()> {
    nix::sys::socket::setsockopt(socket, nix::sys::socket::sockopt::RxqOvfl, &1).map_err(std::io::Error::from)
}

#[cfg(not(target_os = "linux"))]
pub fn count_drops<F: AsFd>(_socket: &F) -> std::io::Result<()> {
    Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "SO_RXQ_OVFL is Linux's"))
}

/// The kernel's running count of drops on the socket, in a control message.
#[cfg(target_os = "linux")]
fn drops(c: &ControlMessageOwned) -> Option<u32> {
    match c {
        ControlMessageOwned::RxqOvfl(n) => Some(*n),
        _ => None,
    }
}

#[cfg(not(target_os = "linux"))]
fn drops(_c: &ControlMessageOwned) -> Option<u32> {
    None
}

/// The kernel's stamp in a control message, as Unix seconds.
#[cfg(target_os = "linux")]
fn stamp(c: &ControlMessageOwned) -> Option<f64> {
    match c {
        ControlMessageOwned::ScmTimestampns(ts) => Some(ts.tv_sec() as f64 + ts.tv_nsec() as f64 * 1e-9),
        _ => None,
    }
}

#[cfg(not(target_os = "linux"))]
fn stamp(_c: &ControlMessageOwned) -> Option<f64> {
    None
}

fn socket_addr(a: &SockaddrStorage) -> Option<SocketAddr> {
    a.as_sockaddr_in()
        .map(|v4| SocketAddr::from(std::net::SocketAddrV4::from(*v4)))
        .or_else(|| a.as_sockaddr_in6().map(|v6| SocketAddr::from(std::net::SocketAddrV6::from(*v6))))
}

/// What a received message says: its length, its sender, when it arrived
/// (Unix seconds: the kernel's stamp, else the clock now) and the socket's
/// drop count if the kernel sent one. A truncated control buffer (not
/// expected: it holds both) loses them, not the message.
fn received(msg: &RecvMsg<'_, '_, SockaddrStorage>) -> ((usize, Option<SocketAddr>, f64), Option<u32>) {
    let (mut arrival, mut dropped) = (None, None);
    for c in msg.cmsgs().ok().into_iter().flatten() {
        arrival = arrival.or_else(|| stamp(&c));
        dropped = dropped.or_else(|| drops(&c));
    }
    ((msg.bytes, msg.address.as_ref().and_then(socket_addr), arrival.unwrap_or_else(unix_now)), dropped)
}

/// One datagram (or TCP read): see [`received`]. Blocking or not as the
/// socket is; `WouldBlock` and timeouts come back as errors.
pub fn recv<F: AsRawFd>(socket: &F, buf: &mut [u8]) -> std::io::Result<(usize, Option<SocketAddr>, f64)> {
    let mut control = nix::cmsg_space!(nix::sys::time::TimeSpec, u32);
    let mut iov = [IoSliceMut::new(buf)];
    let msg =
        recvmsg::<SockaddrStorage>(socket.as_raw_fd(), &mut iov, Some(&mut control), MsgFlags::empty())?;
    Ok(received(&msg).0)
}

/// Datagrams read several at a time (`recvmmsg` on Linux), each with its
/// own stamp: under load many wait in the socket's buffer, and a system
/// call and a trip through the runtime's readiness for each cost the
/// input thread about a tenth of its time at 973 k frames/s (200
/// receivers, about five frames a datagram). Elsewhere one at a time.
pub struct Datagrams {
    bufs: Vec<Vec<u8>>,
    /// Per datagram read: length, sender, arrival.
    got: Vec<(usize, Option<SocketAddr>, f64)>,
    /// The kernel's count of drops on the socket, as of the last read that
    /// brought one (see [`count_drops`]).
    kernel_drops: Option<u32>,
}

impl Datagrams {
    /// Up to `batch` datagrams of up to `size` bytes each per read.
    pub fn new(batch: usize, size: usize) -> Datagrams {
        let batch = if cfg!(target_os = "linux") { batch.max(1) } else { 1 };
        Datagrams { bufs: vec![vec![0u8; size]; batch], got: Vec::with_capacity(batch), kernel_drops: None }
    }

    /// Reads what is waiting, up to the batch (at least one datagram, or
    /// an error: `WouldBlock` when none is, the socket being non-blocking).
    pub fn recv<F: AsRawFd>(&mut self, socket: &F) -> std::io::Result<usize> {
        self.got.clear();
        #[cfg(target_os = "linux")]
        {
            // Made for each read, not kept: its raw pointers make it not
            // `Send`, which a spawned input task must be.
            let mut headers = nix::sys::socket::MultiHeaders::<SockaddrStorage>::preallocate(
                self.bufs.len(),
                Some(nix::cmsg_space!(nix::sys::time::TimeSpec, u32)),
            );
            let mut iovs: Vec<[IoSliceMut; 1]> = self.bufs.iter_mut().map(|b| [IoSliceMut::new(b)]).collect();
            let msgs = nix::sys::socket::recvmmsg(
                socket.as_raw_fd(),
                &mut headers,
                iovs.iter_mut(),
                MsgFlags::MSG_DONTWAIT,
                None,
            )?;
            for msg in msgs {
                let (d, dropped) = received(&msg);
                self.got.push(d);
                self.kernel_drops = dropped.or(self.kernel_drops);
            }
        }
        #[cfg(not(target_os = "linux"))]
        {
            let d = recv(socket, &mut self.bufs[0])?;
            self.got.push(d);
        }
        Ok(self.got.len())
    }

    /// The kernel's running count of datagrams it dropped on the socket
    /// (wrapping at 2^32), once it has sent one.
    pub fn kernel_drops(&self) -> Option<u32> {
        self.kernel_drops
    }

    /// The `i`th datagram of the last read: bytes, sender, arrival.
    pub fn get(&self, i: usize) -> (&[u8], Option<SocketAddr>, f64) {
        let (n, peer, arrival) = self.got[i];
        (&self.bufs[i][..n], peer, arrival)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::UdpSocket;
    use std::time::Duration;

    #[cfg(target_os = "linux")]
    #[test]
    fn a_datagram_is_stamped_when_it_arrived_not_when_it_was_read() {
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        enable(&rx).unwrap();
        rx.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        // The first socket of a system to ask for stamps switches them on
        // through a deferred kernel job; until it has run, a datagram is
        // stamped when it is read. So: a few tries.
        let mut tries = Vec::new();
        for _ in 0..20 {
            let sent = unix_now();
            tx.send_to(b"frame", rx.local_addr().unwrap()).unwrap();
            // Read well after it arrived, as a busy input task would.
            std::thread::sleep(Duration::from_millis(100));
            let mut buf = [0u8; 64];
            let (n, peer, arrival) = recv(&rx, &mut buf).unwrap();
            let read = unix_now();
            assert_eq!(&buf[..n], b"frame");
            assert_eq!(peer, Some(tx.local_addr().unwrap()));
            assert!(arrival >= sent - 0.001 && arrival <= read, "{sent} {arrival} {read}");
            if arrival < sent + 0.05 && read - arrival > 0.08 {
                return;
            }
            tries.push(arrival - sent);
        }
        panic!("every datagram stamped at its read, not its arrival: {tries:?} s after sending");
    }

    #[test]
    fn without_the_option_a_datagram_gets_the_clock_at_the_read() {
        let rx = UdpSocket::bind("[::1]:0").or_else(|_| UdpSocket::bind("127.0.0.1:0")).unwrap();
        rx.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        let tx = UdpSocket::bind(if rx.local_addr().unwrap().is_ipv6() { "[::1]:0" } else { "127.0.0.1:0" })
            .unwrap();
        tx.send_to(b"x", rx.local_addr().unwrap()).unwrap();
        std::thread::sleep(Duration::from_millis(100));
        let before = unix_now();
        let (n, peer, arrival) = recv(&rx, &mut [0u8; 8]).unwrap();
        assert_eq!((n, peer), (1, Some(tx.local_addr().unwrap())));
        assert!(arrival >= before, "{arrival} {before}");
    }

    #[test]
    fn several_datagrams_are_read_at_once_in_order_with_their_senders() {
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        let _ = enable(&rx);
        rx.set_nonblocking(true).unwrap();
        let (a, b) = (UdpSocket::bind("127.0.0.1:0").unwrap(), UdpSocket::bind("127.0.0.1:0").unwrap());
        for (k, s) in [&a, &b, &a, &b, &a].into_iter().enumerate() {
            s.send_to(&vec![k as u8; k + 1], rx.local_addr().unwrap()).unwrap();
        }
        std::thread::sleep(Duration::from_millis(50));
        let mut d = Datagrams::new(4, 16);
        let mut seen = Vec::new();
        let (mut last, mut reads) = (0.0, Vec::new());
        while let Ok(n) = d.recv(&rx) {
            reads.push(n);
            for i in 0..n {
                let (bytes, peer, arrival) = d.get(i);
                assert!(arrival >= last);
                last = arrival;
                seen.push((bytes.to_vec(), peer.unwrap()));
            }
        }
        let (pa, pb) = (a.local_addr().unwrap(), b.local_addr().unwrap());
        let want: Vec<(Vec<u8>, SocketAddr)> =
            [pa, pb, pa, pb, pa].into_iter().enumerate().map(|(k, p)| (vec![k as u8; k + 1], p)).collect();
        assert_eq!(seen, want);
        // All five were waiting: one call took four of them.
        assert_eq!(reads, if cfg!(target_os = "linux") { vec![4, 1] } else { vec![1; 5] });
        // Nothing waiting: `WouldBlock`, not an empty read.
        assert_eq!(d.recv(&rx).unwrap_err().kind(), std::io::ErrorKind::WouldBlock);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_tcp_read_is_stamped_when_its_bytes_arrived() {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let mut tx = std::net::TcpStream::connect(l.local_addr().unwrap()).unwrap();
        let (rx, _) = l.accept().unwrap();
        enable(&rx).unwrap();
        rx.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        let mut tries = Vec::new();
        for _ in 0..20 {
            let sent = unix_now();
            std::io::Write::write_all(&mut tx, b"frame").unwrap();
            std::thread::sleep(Duration::from_millis(100));
            let mut buf = [0u8; 64];
            let (n, peer, arrival) = recv(&rx, &mut buf).unwrap();
            let read = unix_now();
            assert_eq!(&buf[..n], b"frame");
            assert_eq!(peer, None);
            assert!(arrival >= sent - 0.001 && arrival <= read, "{sent} {arrival} {read}");
            if arrival < sent + 0.05 && read - arrival > 0.08 {
                return;
            }
            tries.push(arrival - sent);
        }
        panic!("every read stamped at its read, not its arrival: {tries:?} s after sending");
    }

    /// Datagrams sent to a socket whose small buffer is full are lost in
    /// the kernel; the next read says how many.
    #[cfg(target_os = "linux")]
    #[test]
    fn the_kernels_drops_on_a_full_socket_are_counted() {
        let rx = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::DGRAM, None).unwrap();
        rx.set_recv_buffer_size(4096).unwrap();
        rx.bind(&"127.0.0.1:0".parse::<SocketAddr>().unwrap().into()).unwrap();
        let rx: UdpSocket = rx.into();
        count_drops(&rx).unwrap();
        rx.set_nonblocking(true).unwrap();
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        for _ in 0..200 {
            tx.send_to(&[7u8; 200], rx.local_addr().unwrap()).unwrap();
        }
        let mut d = Datagrams::new(8, 256);
        let mut got = 0;
        while let Ok(n) = d.recv(&rx) {
            got += n;
        }
        // The count comes with the first datagram queued after the drops.
        assert_eq!(d.kernel_drops(), None);
        tx.send_to(&[7u8; 200], rx.local_addr().unwrap()).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(20));
        got += d.recv(&rx).unwrap() - 1;
        let dropped = d.kernel_drops().expect("a drop count") as usize;
        assert!(dropped > 0 && got + dropped == 200, "read {got}, dropped {dropped}");
    }
}
