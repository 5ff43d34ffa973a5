//! Output destinations: UDP (unicast or multicast) in JSON or ASTERIX
//! CAT062, or JSON lines on stdout. Sockets are non-blocking and every
//! error is counted: a destination that is unreachable never blocks or
//! stops the others, and nothing is sent anywhere but the configured
//! addresses.

use std::io::Write;
use std::net::{SocketAddr, UdpSocket};

use socket2::{Domain, Protocol, Socket, Type};

use super::config::{OutputConfig, OutputFormat, ServiceConfig};
use crate::core::Event;
use crate::publish::{asterix, json};

pub struct Destination {
    pub cfg: OutputConfig,
    socket: Option<UdpSocket>,
    pub sent: u64,
    pub errors: u64,
    last_error_log: f64,
}

fn udp_socket(cfg: &OutputConfig, addr: SocketAddr) -> std::io::Result<UdpSocket> {
    let domain = if addr.is_ipv4() { Domain::IPV4 } else { Domain::IPV6 };
    let s = Socket::new(domain, Type::DGRAM, Some(Protocol::UDP))?;
    if addr.ip().is_multicast() {
        if let SocketAddr::V4(_) = addr {
            s.set_multicast_ttl_v4(cfg.multicast_ttl)?;
            if let Some(ifa) = cfg.multicast_interface {
                s.set_multicast_if_v4(&ifa)?;
            }
        }
    }
    let any: SocketAddr =
        if addr.is_ipv4() { "0.0.0.0:0".parse().unwrap() } else { "[::]:0".parse().unwrap() };
    s.bind(&any.into())?;
    s.set_nonblocking(true)?;
    Ok(s.into())
}

pub struct Outputs {
    pub dests: Vec<Destination>,
    source: asterix::Source,
    max_bytes: usize,
}

impl Outputs {
    pub fn new(cfgs: &[OutputConfig], service: &ServiceConfig) -> Outputs {
        let dests = cfgs
            .iter()
            .map(|c| {
                let socket = match (c.kind.as_str(), c.address) {
                    ("udp", Some(a)) => match udp_socket(c, a) {
                        Ok(s) => Some(s),
                        Err(e) => {
                            tracing::error!(address = %a, "output socket: {e}");
                            None
                        }
                    },
                    _ => None,
                };
                Destination { cfg: c.clone(), socket, sent: 0, errors: 0, last_error_log: f64::NEG_INFINITY }
            })
            .collect();
        Outputs {
            dests,
            source: asterix::Source { sac: service.sac, sic: service.sic, service: service.service_id },
            max_bytes: service.max_datagram_bytes,
        }
    }

    /// Sends a batch of events to every destination; `name` gives receivers'
    /// ids for the JSON records, `now` is for rate-limited logs.
    pub fn publish<'a>(&mut self, events: &[Event], name: impl Fn(usize) -> &'a str, now: f64) {
        if events.is_empty() || self.dests.is_empty() {
            return;
        }
        let mut lines: Option<Vec<Vec<u8>>> = None;
        let mut blocks: Option<Vec<Vec<u8>>> = None;
        for d in &mut self.dests {
            let payloads = match d.cfg.format {
                OutputFormat::Json => lines.get_or_insert_with(|| {
                    events
                        .iter()
                        .filter(|e| !matches!(e, Event::Position(_)))
                        .map(|e| {
                            let mut b = Vec::new();
                            json::write_event(&mut b, e, &name);
                            b.pop(); // the newline: one object per datagram
                            b
                        })
                        .collect()
                }),
                OutputFormat::Asterix062 => blocks.get_or_insert_with(|| {
                    let records: Vec<Vec<u8>> = events
                        .iter()
                        .filter_map(|e| match e {
                            Event::Track(r) if r.source == "fused" => {
                                Some(asterix::record(self.source, r, r.ages_s))
                            }
                            _ => None,
                        })
                        .collect();
                    asterix::blocks(&records, self.max_bytes)
                }),
            };
            if d.cfg.kind == "stdout" {
                let mut out = std::io::stdout().lock();
                for p in payloads.iter() {
                    let ok = out.write_all(p).and_then(|_| out.write_all(b"\n"));
                    if ok.is_err() {
                        d.errors += 1;
                    } else {
                        d.sent += 1;
                    }
                }
                let _ = out.flush();
                continue;
            }
            let (Some(sock), Some(addr)) = (&d.socket, d.cfg.address) else {
                d.errors += payloads.len() as u64;
                continue;
            };
            for p in payloads.iter() {
                match sock.send_to(p, addr) {
                    Ok(_) => d.sent += 1,
                    Err(e) => {
                        d.errors += 1;
                        if now - d.last_error_log > 10.0 {
                            d.last_error_log = now;
                            tracing::warn!(address = %addr, errors = d.errors, "output: {e}");
                        }
                    }
                }
            }
        }
    }
}
