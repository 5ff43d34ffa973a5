//! The live service's part of the configuration: receivers, inputs,
//! outputs and operations. Checked as a whole: every problem is reported at
//! once, each with the table it is in (`[[input]] 2: ...`).

use crate::problem::{positive, Problem};
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;

use serde::{Deserialize, Deserializer, Serialize};

use crate::core::front::KnownReceiver;
use crate::feed::capture::{ClockKind, ReceiverDecl};
use crate::feed::detect::InputFormat;
use crate::mlat::timing::KnownTiming;

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ServiceConfig {
    /// Record every frame received to this capture file (v1), for replay.
    #[serde(deserialize_with = "off_if_empty", skip_serializing_if = "Option::is_none")]
    pub record: Option<PathBuf>,
    /// The recording is rotated (`FILE` → `FILE.1` ...) at this size (bytes) ...
    pub record_max_bytes: u64,
    /// ... or this age (s), whichever comes first ...
    pub record_max_age_s: f64,
    /// ... keeping this many rotated files beside the current one.
    pub record_keep: usize,
    /// What multilateration has learnt of each receiver (timing, position
    /// survey), saved here at shutdown and taken up at start.
    #[serde(deserialize_with = "off_if_empty", skip_serializing_if = "Option::is_none")]
    pub state_file: Option<PathBuf>,
    /// One stats line in the log this often (s).
    pub stats_interval_s: f64,
    /// Prometheus text endpoint (host:port).
    #[serde(deserialize_with = "off_if_empty", skip_serializing_if = "Option::is_none")]
    pub metrics_listen: Option<SocketAddr>,
    /// ASTERIX data source identifier and service identification.
    pub sac: u8,
    pub sic: u8,
    pub service_id: u8,
    /// Largest UDP datagram an output sends (bytes).
    pub max_datagram_bytes: usize,
    /// Frames waiting between the inputs and the core; beyond it frames are dropped and counted.
    pub queue_frames: usize,
    /// Demo: replay this capture into our own inputs at start, at this speed.
    #[serde(deserialize_with = "off_if_empty", skip_serializing_if = "Option::is_none")]
    pub demo_capture: Option<PathBuf>,
    pub demo_speed: f64,
    /// Realtime round-robin priority (1-99) for the service's threads, so
    /// other processes on the machine cannot delay a frame's way through;
    /// 0: ordinary time sharing. Read at start.
    pub realtime_priority: u8,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        ServiceConfig {
            record: None,
            record_max_bytes: 1 << 30,
            record_max_age_s: 3600.0,
            record_keep: 8,
            state_file: None,
            stats_interval_s: 60.0,
            metrics_listen: None,
            sac: 0,
            sic: 1,
            service_id: 1,
            max_datagram_bytes: 1400,
            queue_frames: 65_536,
            demo_capture: None,
            demo_speed: 1.0,
            realtime_priority: 0,
        }
    }
}

/// `[http]`: the map's data, readsb-compatible JSON and `/metrics` on one port.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct HttpConfig {
    /// Where to listen (host:port). Absent: off.
    #[serde(deserialize_with = "off_if_empty", skip_serializing_if = "Option::is_none")]
    pub listen: Option<SocketAddr>,
    /// Connections served at once; more are closed at accept and counted.
    pub max_connections: usize,
    /// A tile server for the map's background, as a URL template with
    /// `{z}`, `{x}` and `{y}` (and optionally `{s}`). Absent: the map draws
    /// the coastlines and borders it carries, and needs no network.
    #[serde(deserialize_with = "off_if_empty", skip_serializing_if = "Option::is_none")]
    pub map_tiles: Option<String>,
    /// The tiles' attribution, shown in the map's corner (most tile
    /// providers require one).
    #[serde(deserialize_with = "off_if_empty", skip_serializing_if = "Option::is_none")]
    pub map_attribution: Option<String>,
}

impl Default for HttpConfig {
    fn default() -> Self {
        // A browser holds a few connections; a hundred viewers fit.
        HttpConfig { listen: None, max_connections: 256, map_tiles: None, map_attribution: None }
    }
}

impl HttpConfig {
    pub fn validate(&self) -> Vec<Problem> {
        let mut errs = Vec::new();
        if self.listen.is_some_and(|a| a.port() == 0) {
            errs.push(Problem::new("[http]", "listen: port 0 is no port"));
        }
        if !(1..=10_000).contains(&self.max_connections) {
            errs.push(Problem::new(
                "[http]",
                format!("max_connections = {} must be in 1..=10000", self.max_connections),
            ));
        }
        if let Some(url) = &self.map_tiles {
            if !["{z}", "{x}", "{y}"].iter().all(|p| url.contains(p)) {
                errs.push(Problem::new(
                    "[http]",
                    format!("map_tiles = {url:?} must contain {{z}}, {{x}} and {{y}}"),
                ));
            }
        }
        errs
    }
}

/// What can be off is off when absent; an empty string, which earlier
/// configurations wrote for it, is read as absent too.
fn off_if_empty<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: Deserializer<'de>,
    T: std::str::FromStr,
    T::Err: std::fmt::Display,
{
    let text = String::deserialize(d)?;
    if text.is_empty() {
        return Ok(None);
    }
    text.parse().map(Some).map_err(|e| serde::de::Error::custom(format!("{text:?}: {e}")))
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ReceiverConfig {
    pub id: String,
    pub lat: f64,
    pub lon: f64,
    /// Antenna height above the WGS-84 ellipsoid (m).
    pub alt_m: f64,
    /// beast12 (free-running 12 MHz counter) or gps (Radarcape GPS time).
    pub clock: ClockKind,
    /// Source address that identifies it on TCP-server and UDP inputs.
    #[serde(default)]
    pub source: Option<IpAddr>,
    /// What names it on TCP-server inputs when its address does not (a
    /// receiver behind a changing or shared address): readsb's receiver id
    /// frame (0xe3), as 16 hex digits, or its UUID frame (0xe4), as the
    /// 36-character UUID.
    #[serde(default)]
    pub beast_id: Option<String>,
    /// Whether a connection naming it by `beast_id` may close its live
    /// connection from another source address (a receiver behind a
    /// changing address). Off: anyone who knows the id could take it over.
    #[serde(default)]
    pub beast_id_takeover: bool,
    /// Most frames per second accepted from it; more are dropped and counted (0: no limit).
    #[serde(default)]
    pub max_rate: f64,
    /// Its timing, when known: taken as it is instead of learnt.
    #[serde(default)]
    pub timing: Option<KnownTiming>,
}

/// A receiver's name in its Beast stream (readsb's 0xe3 or 0xe4 frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BeastId {
    Id(u64),
    Uuid([u8; 36]),
}

impl BeastId {
    /// 16 hex digits (0xe3) or a 36-character UUID (0xe4), any case.
    pub fn parse(text: &str) -> Option<BeastId> {
        match text.len() {
            16 => u64::from_str_radix(text, 16).ok().map(BeastId::Id),
            36 if text.bytes().enumerate().all(|(i, b)| {
                if matches!(i, 8 | 13 | 18 | 23) {
                    b == b'-'
                } else {
                    b.is_ascii_hexdigit()
                }
            }) =>
            {
                let mut uuid = [0u8; 36];
                uuid.copy_from_slice(text.to_ascii_lowercase().as_bytes());
                Some(BeastId::Uuid(uuid))
            }
            _ => None,
        }
    }

    /// The name a receiver id or UUID frame carries, if it is one.
    pub fn of(ev: &crate::feed::FeedEvent) -> Option<BeastId> {
        match ev {
            crate::feed::FeedEvent::ReceiverId(id) => Some(BeastId::Id(*id)),
            crate::feed::FeedEvent::ReceiverUuid(u) => {
                Some(BeastId::Uuid(u.to_ascii_lowercase().try_into().ok()?))
            }
            _ => None,
        }
    }
}

impl std::fmt::Display for BeastId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BeastId::Id(id) => write!(f, "{id:016x}"),
            BeastId::Uuid(u) => write!(f, "{}", String::from_utf8_lossy(u)),
        }
    }
}

impl ReceiverConfig {
    /// Its `beast_id` parsed (`None` when absent or, before validation, malformed).
    pub fn beast_name(&self) -> Option<BeastId> {
        self.beast_id.as_deref().and_then(BeastId::parse)
    }

    /// A receiver known only by its declaration (where it is, its clock):
    /// a cluster's publisher, which sees no frames, lists the network's
    /// receivers on its map with these.
    pub fn declared(d: &crate::feed::capture::ReceiverDecl) -> ReceiverConfig {
        ReceiverConfig {
            id: d.id.clone(),
            lat: d.lat,
            lon: d.lon,
            alt_m: d.alt,
            clock: d.clock,
            source: None,
            beast_id: None,
            beast_id_takeover: false,
            max_rate: 0.0,
            timing: None,
        }
    }

    /// A receiver at 0,0 with a counter clock, known by `beast_id` only.
    #[cfg(test)]
    pub fn for_test(id: &str, beast_id: Option<&str>) -> ReceiverConfig {
        ReceiverConfig {
            id: id.into(),
            lat: 0.0,
            lon: 0.0,
            alt_m: 0.0,
            clock: ClockKind::Beast12,
            source: None,
            beast_id: beast_id.map(Into::into),
            beast_id_takeover: false,
            max_rate: 0.0,
            timing: None,
        }
    }

    pub fn decl(&self) -> ReceiverDecl {
        ReceiverDecl { id: self.id.clone(), lat: self.lat, lon: self.lon, alt: self.alt_m, clock: self.clock }
    }

    /// What the core is told of it.
    pub fn known(&self) -> KnownReceiver {
        KnownReceiver { decl: self.decl(), timing: self.timing }
    }
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum InputKind {
    /// Connects to a receiver's Beast output (readsb 30005, Radarcape 10003).
    BeastTcpClient,
    /// Receivers connect and push Beast (readsb --net-connector ...,beast_out).
    BeastTcpServer,
    /// Datagrams of Beast or AVR frames.
    Udp,
}

impl InputKind {
    /// As the configuration spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::BeastTcpClient => "beast_tcp_client",
            Self::BeastTcpServer => "beast_tcp_server",
            Self::Udp => "udp",
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct InputConfig {
    pub kind: InputKind,
    /// beast_tcp_client: where to connect. Others: where to listen.
    pub address: SocketAddr,
    /// beast_tcp_client: the receiver at the other end. Others: optional, a
    /// receiver for every sender (else senders are told apart by `source`).
    #[serde(default)]
    pub receiver: Option<String>,
    /// beast_tcp_server and udp: the receivers allowed to send here (each
    /// recognised by its `source`, or on a TCP server by its `beast_id`);
    /// empty: any receiver with either.
    #[serde(default)]
    pub receivers: Vec<String>,
    /// udp: beast or avr.
    #[serde(default = "beast")]
    pub format: InputFormat,
    /// TCP inputs: a connection that brings nothing for this long (s) is
    /// closed (a client then reconnects); 0: never. A receiver always has
    /// traffic, and readsb and dump1090 send a heartbeat on an idle Beast
    /// port every 60 s; a connection silent for longer is a receiver gone
    /// without a word (power cut, a NAT that forgot it), which TCP alone
    /// would notice only when we write to it, and we never do.
    #[serde(default = "idle_timeout")]
    pub idle_timeout_s: f64,
}

fn idle_timeout() -> f64 {
    120.0
}

impl InputConfig {
    /// Whether receiver `r` may reach the service through this input.
    pub fn takes(&self, r: &ReceiverConfig) -> bool {
        match &self.receiver {
            Some(id) => *id == r.id,
            None => {
                (r.source.is_some() || r.beast_id.is_some())
                    && (self.receivers.is_empty() || self.receivers.contains(&r.id))
            }
        }
    }
}

fn beast() -> InputFormat {
    InputFormat::Beast
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum OutputFormat {
    /// The track stream: one JSON object per datagram or line.
    Json,
    /// ASTERIX CAT062 data blocks (UDP).
    Asterix062,
    /// Multilateration results as Beast extended squitters, as mlat-client
    /// sends them (TCP).
    Beast,
    /// SBS / BaseStation text lines, the port-30003 convention (TCP).
    Sbs,
}

impl OutputFormat {
    /// As the configuration spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Json => "json",
            Self::Asterix062 => "asterix062",
            Self::Beast => "beast",
            Self::Sbs => "sbs",
        }
    }

    /// A byte stream, not datagrams: carried over TCP only.
    pub fn is_stream(self) -> bool {
        matches!(self, OutputFormat::Beast | OutputFormat::Sbs)
    }
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum OutputKind {
    /// Datagrams, unicast or multicast.
    Udp,
    /// JSON lines on standard output, for a look.
    Stdout,
    /// Subscribers connect to `address` (like readsb's 30005 or 30003).
    TcpServer,
    /// Pushed to `address`, reconnecting (like mlat-client's
    /// `--results beast,connect,host:30104`).
    TcpConnect,
}

impl OutputKind {
    /// As the configuration spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Udp => "udp",
            Self::Stdout => "stdout",
            Self::TcpServer => "tcp_server",
            Self::TcpConnect => "tcp_connect",
        }
    }

    pub fn is_tcp(self) -> bool {
        matches!(self, OutputKind::TcpServer | OutputKind::TcpConnect)
    }
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OutputConfig {
    /// udp, stdout, tcp_server or tcp_connect.
    #[serde(default = "udp")]
    pub kind: OutputKind,
    #[serde(default)]
    pub address: Option<SocketAddr>,
    pub format: OutputFormat,
    /// Multicast: time to live and the interface address to send from.
    #[serde(default = "one")]
    pub multicast_ttl: u32,
    #[serde(default)]
    pub multicast_interface: Option<std::net::Ipv4Addr>,
    /// tcp_server: subscribers served at once; more are closed at accept
    /// and counted.
    #[serde(default = "max_clients")]
    pub max_clients: usize,
    /// beast: every frame received, from every receiver, as it came (its
    /// receiver's timestamp and signal), besides the multilateration results.
    #[serde(default)]
    pub forward_frames: bool,
}

fn max_clients() -> usize {
    64
}

fn udp() -> OutputKind {
    OutputKind::Udp
}

fn one() -> u32 {
    1
}

/// Every problem of the live part, each with its table.
// Over 80 lines: a flat list of independent checks, one per field.
pub fn validate(
    service: &ServiceConfig,
    receivers: &[ReceiverConfig],
    inputs: &[InputConfig],
    outputs: &[OutputConfig],
) -> Vec<Problem> {
    let mut errs = Vec::new();
    positive(
        "service",
        &[("stats_interval_s", service.stats_interval_s), ("demo_speed", service.demo_speed)],
        &mut errs,
    );
    // Port 0 would listen on a port the kernel picks and nobody knows.
    if service.metrics_listen.is_some_and(|a| a.port() == 0) {
        errs.push(Problem::new("[service]", "metrics_listen: port 0 is no port"));
    }
    if !(64..=65_000).contains(&service.max_datagram_bytes) {
        errs.push(Problem::new(
            "[service]",
            format!("max_datagram_bytes = {} must be in 64..=65000", service.max_datagram_bytes),
        ));
    }
    if service.record_max_bytes < 4096 {
        errs.push(Problem::new(
            "[service]",
            format!("record_max_bytes = {} must be at least 4096", service.record_max_bytes),
        ));
    }
    if !(service.record_max_age_s >= 1.0 && service.record_max_age_s.is_finite()) {
        errs.push(Problem::new(
            "[service]",
            format!("record_max_age_s = {} must be at least 1", service.record_max_age_s),
        ));
    }
    if service.queue_frames == 0 {
        errs.push(Problem::new("[service]", "queue_frames must be positive"));
    }
    if service.realtime_priority > 99 {
        errs.push(Problem::new(
            "[service]",
            format!("realtime_priority = {} must be in 0..=99", service.realtime_priority),
        ));
    }
    for (i, r) in receivers.iter().enumerate() {
        let at = format!("[[receiver]] {} ({})", i + 1, r.id);
        if r.id.is_empty() || r.id.contains(char::is_whitespace) {
            errs.push(Problem::new(&at, "id must be a non-empty word"));
        }
        if receivers[..i].iter().any(|o| o.id == r.id) {
            errs.push(Problem::new(&at, "id used twice"));
        }
        if !(r.lat.abs() <= 90.0 && r.lon.abs() <= 180.0 && r.alt_m.is_finite()) {
            errs.push(Problem::new(&at, "position out of range"));
        }
        if let Some(s) = r.source {
            if receivers[..i].iter().any(|o| o.source == Some(s)) {
                errs.push(Problem::new(&at, format!("source {s} used twice")));
            }
        }
        if let Some(b) = &r.beast_id {
            match BeastId::parse(b) {
                None => errs.push(Problem::new(&at, format!("beast_id = {b:?}: 16 hex digits or a UUID"))),
                Some(id) => {
                    if receivers[..i].iter().any(|o| o.beast_name() == Some(id)) {
                        errs.push(Problem::new(&at, format!("beast_id {b} used twice")));
                    }
                }
            }
        }
        if !(r.max_rate >= 0.0 && r.max_rate.is_finite()) {
            errs.push(Problem::new(&at, "max_rate must be zero or positive"));
        }
        if let Some(Err(e)) = r.timing.map(|t| t.check()) {
            errs.push(Problem::new(&at, format!("timing: {e}")));
        }
    }
    let known = |id: &str| receivers.iter().any(|r| r.id == id);
    for (i, input) in inputs.iter().enumerate() {
        let at = format!("[[input]] {}", i + 1);
        match (&input.receiver, input.kind) {
            (None, InputKind::BeastTcpClient) => {
                errs.push(Problem::new(&at, "beast_tcp_client needs receiver"))
            }
            (Some(id), _) if !known(id) => {
                errs.push(Problem::new(&at, format!("receiver {id:?} is not declared")))
            }
            _ => {}
        }
        for id in &input.receivers {
            if !known(id) {
                errs.push(Problem::new(&at, format!("receivers: {id:?} is not declared")));
            }
        }
        if input.address.port() == 0 {
            errs.push(Problem::new(&at, format!("address {}: port 0 is no port", input.address)));
        }
        if !(input.idle_timeout_s >= 0.0 && input.idle_timeout_s.is_finite()) {
            errs.push(Problem::new(
                &at,
                format!("idle_timeout_s = {} must be zero or positive", input.idle_timeout_s),
            ));
        }
        if input.format == InputFormat::Hex {
            errs.push(Problem::new(&at, "format = hex: beast or avr"));
        }
        if input.format == InputFormat::Avr && input.kind != InputKind::Udp {
            errs.push(Problem::new(&at, "avr only over udp"));
        }
    }
    for (i, o) in outputs.iter().enumerate() {
        let at = format!("[[output]] {}", i + 1);
        if (o.kind == OutputKind::Udp || o.kind.is_tcp()) && o.address.is_none() {
            errs.push(Problem::new(&at, format!("{} needs address", o.kind.name())));
        }
        if o.format.is_stream() && !o.kind.is_tcp() {
            errs.push(Problem::new(
                &at,
                format!("format = {}: a byte stream, over tcp_server or tcp_connect", o.format.name()),
            ));
        }
        if o.format == OutputFormat::Asterix062 && o.kind != OutputKind::Udp {
            errs.push(Problem::new(&at, "asterix062 goes over udp"));
        }
        if o.forward_frames && o.format != OutputFormat::Beast {
            errs.push(Problem::new(&at, "forward_frames is for format = beast"));
        }
        if !(1..=10_000).contains(&o.max_clients) {
            errs.push(Problem::new(&at, format!("max_clients = {} must be in 1..=10000", o.max_clients)));
        }
        if o.address.is_some_and(|a| a.port() == 0) {
            errs.push(Problem::new(&at, "address: port 0 is no port"));
        }
        if o.kind == OutputKind::Stdout && o.format != OutputFormat::Json {
            errs.push(Problem::new(&at, "stdout prints json only"));
        }
    }
    errs
}

#[cfg(test)]
mod tests {
    use super::HttpConfig;

    #[test]
    fn a_tile_url_must_name_the_tile() {
        let with = |url: &str| HttpConfig { map_tiles: Some(url.into()), ..HttpConfig::default() }.validate();
        assert!(with("https://tiles.example/{z}/{x}/{y}.png").is_empty());
        let errs = with("https://tiles.example/{z}/{x}.png");
        assert_eq!(errs.len(), 1, "{errs:?}");
        assert_eq!(errs[0].table, "[http]");
        assert!(errs[0].message.starts_with("map_tiles = ") && errs[0].message.contains("{y}"), "{errs:?}");
    }
}
