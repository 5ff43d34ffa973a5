//! Datagrams with the time the kernel received them (`SO_TIMESTAMPNS`).
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

use nix::sys::socket::{recvmsg, ControlMessageOwned, MsgFlags, SockaddrStorage};

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

/// The kernel's stamp in a control message, as Unix seconds.
#[cfg(target_os = "linux")]
fn stamp(c: ControlMessageOwned) -> Option<f64> {
    match c {
        ControlMessageOwned::ScmTimestampns(ts) => Some(ts.tv_sec() as f64 + ts.tv_nsec() as f64 * 1e-9),
        _ => None,
    }
}

#[cfg(not(target_os = "linux"))]
fn stamp(_c: ControlMessageOwned) -> Option<f64> {
    None
}

/// One datagram: its length, its sender and when it arrived (Unix
/// seconds: the kernel's stamp, else the clock now). Blocking or not as
/// the socket is; `WouldBlock` and timeouts come back as errors.
pub fn recv<F: AsRawFd>(socket: &F, buf: &mut [u8]) -> std::io::Result<(usize, Option<SocketAddr>, f64)> {
    let mut control = nix::cmsg_space!(nix::sys::time::TimeSpec);
    let mut iov = [IoSliceMut::new(buf)];
    let msg =
        recvmsg::<SockaddrStorage>(socket.as_raw_fd(), &mut iov, Some(&mut control), MsgFlags::empty())?;
    // A truncated control buffer (not expected: it holds one stamp) loses
    // the stamp, not the datagram.
    let arrival = msg.cmsgs().ok().into_iter().flatten().find_map(stamp);
    let peer = msg.address.and_then(|a| {
        a.as_sockaddr_in()
            .map(|v4| SocketAddr::from(std::net::SocketAddrV4::from(*v4)))
            .or_else(|| a.as_sockaddr_in6().map(|v6| SocketAddr::from(std::net::SocketAddrV6::from(*v6))))
    });
    Ok((msg.bytes, peer, arrival.unwrap_or_else(unix_now)))
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
}
