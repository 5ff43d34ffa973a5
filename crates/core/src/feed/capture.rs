//! Capture files (contract v1): the one module that reads and writes them.
//!
//! ```text
//! # fuse1090 capture v1
//! receiver rx1 lat=43.6290 lon=1.3638 alt=152.0 clock=beast12
//! 1581500000.123456 rx1 <A1B2C3D4E5F6A08D4840D6202CC371C32CE0576098;
//! ```
//! A malformed line is reported with its file, line number and reason, then
//! skipped and counted; reading goes on. Frames reference receivers by index
//! so the processing core never hashes strings on the hot path.

use crate::FastMap;
use std::fmt;
use std::io::{self, BufRead, Write};

use super::avr::parse_avr_token;
use super::RawFrame;

/// How a receiver's timestamps count time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClockKind {
    /// Free-running 12 MHz counter (dump1090/readsb, Beast).
    Beast12,
    /// GPS time of day: seconds of day << 30 | nanoseconds (Radarcape).
    Gps,
}

impl ClockKind {
    pub fn name(self) -> &'static str {
        match self {
            ClockKind::Beast12 => "beast12",
            ClockKind::Gps => "gps",
        }
    }

    /// Ticks per second of a counter clock.
    pub fn frequency_hz(self) -> f64 {
        match self {
            ClockKind::Beast12 => 12e6,
            ClockKind::Gps => 1e9,
        }
    }

    /// A timestamp in seconds on the receiver's own scale (counter seconds,
    /// or seconds of day for GPS).
    pub fn seconds(self, ts: u64) -> f64 {
        // Timestamps have 48 bits: through i64 the conversion is one
        // instruction (from u64 it is a branch and several), same value.
        match self {
            ClockKind::Beast12 => ts as i64 as f64 / 12e6,
            ClockKind::Gps => (ts >> 30) as i64 as f64 + (ts & 0x3FFF_FFFF) as i64 as f64 * 1e-9,
        }
    }

    /// A GPS timestamp as Unix time, taking the day from `near_unix` (the
    /// arrival time), across midnight either way.
    pub fn gps_unix(ts: u64, near_unix: f64) -> f64 {
        let sod = (ts >> 30) as f64 + (ts & 0x3FFF_FFFF) as f64 * 1e-9;
        let day = (near_unix / 86_400.0).floor() * 86_400.0;
        let mut t = day + sod;
        if t - near_unix > 43_200.0 {
            t -= 86_400.0;
        } else if near_unix - t > 43_200.0 {
            t += 86_400.0;
        }
        t
    }

    /// A Unix time as a GPS timestamp.
    pub fn gps_timestamp(unix: f64) -> u64 {
        let sod = unix.rem_euclid(86_400.0);
        let mut secs = sod.floor() as u64;
        let mut ns = ((sod - secs as f64) * 1e9).round() as u64;
        if ns >= 1_000_000_000 {
            secs += 1;
            ns -= 1_000_000_000;
        }
        ((secs % 86_400) << 30) | ns
    }

    /// A GPS timestamp moved by a whole number of nanoseconds, wrapping at
    /// midnight. Integer arithmetic throughout: a Unix time in `f64`
    /// resolves only about 240 ns today, far coarser than the timestamps.
    pub fn gps_shift(ts: u64, shift_ns: i64) -> u64 {
        const DAY_NS: i64 = 86_400 * 1_000_000_000;
        let of_day = (ts >> 30) as i64 * 1_000_000_000 + (ts & 0x3FFF_FFFF) as i64;
        let moved = (of_day + shift_ns.rem_euclid(DAY_NS)).rem_euclid(DAY_NS);
        (((moved / 1_000_000_000) as u64) << 30) | (moved % 1_000_000_000) as u64
    }
}

impl std::str::FromStr for ClockKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "beast12" => Ok(ClockKind::Beast12),
            "gps" => Ok(ClockKind::Gps),
            _ => Err(format!("unknown clock {s:?} (expected beast12 or gps)")),
        }
    }
}

/// A `receiver` line (also a cluster's receiver declaration, as JSON).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReceiverDecl {
    pub id: String,
    pub lat: f64,
    pub lon: f64,
    /// Metres above the WGS-84 ellipsoid.
    pub alt: f64,
    pub clock: ClockKind,
}

/// One frame line; `rx` indexes the receivers declared so far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CaptureFrame {
    pub arrival: f64,
    pub rx: usize,
    pub frame: RawFrame,
}

#[derive(Clone, Debug, PartialEq)]
pub enum CaptureRecord {
    Receiver(ReceiverDecl),
    Frame(CaptureFrame),
}

/// A line that could not be used.
#[derive(Clone, Debug, PartialEq)]
pub struct LineError {
    pub file: String,
    pub line: usize,
    pub reason: String,
}

impl fmt::Display for LineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: {}", self.file, self.line, self.reason)
    }
}

/// Streaming reader. Iterate it for records; malformed lines are counted in
/// `skipped` and the first few kept in `errors`.
pub struct CaptureReader<R> {
    input: R,
    file: String,
    line_no: usize,
    line: Vec<u8>,
    receivers: Vec<ReceiverDecl>,
    ids: ReceiverIds,
    pub skipped: u64,
    pub errors: Vec<LineError>,
}

/// How many line errors are kept for reporting (all are counted).
const KEEP_ERRORS: usize = 20;

impl<R: BufRead> CaptureReader<R> {
    pub fn new(input: R, file: impl Into<String>) -> Self {
        CaptureReader {
            input,
            file: file.into(),
            line_no: 0,
            line: Vec::with_capacity(128),
            receivers: Vec::new(),
            ids: ReceiverIds::default(),
            skipped: 0,
            errors: Vec::new(),
        }
    }

    pub fn receivers(&self) -> &[ReceiverDecl] {
        &self.receivers
    }

    /// The next record; `Ok(None)` at the end; `Err` only for I/O errors.
    pub fn next_record(&mut self) -> io::Result<Option<CaptureRecord>> {
        loop {
            // A line that lies whole in the reader's buffer is parsed there
            // (copying each line out was 3% of `run --capture`); one that
            // straddles the buffer's end is gathered in `line` first.
            let buf = self.input.fill_buf()?;
            if buf.is_empty() {
                return Ok(None);
            }
            let (parsed, used) = match memchr::memchr(b'\n', buf) {
                Some(n) => (parse_line(&buf[..n], &self.ids), n + 1),
                None => {
                    self.line.clear();
                    self.input.read_until(b'\n', &mut self.line)?;
                    (parse_line(&self.line, &self.ids), 0)
                }
            };
            self.input.consume(used);
            self.line_no += 1;
            match parsed {
                None => continue,
                Some(Ok(CaptureRecord::Receiver(r))) => {
                    if self.ids.get(r.id.as_bytes()).is_some() {
                        self.skip(format!("receiver {} declared twice", r.id));
                        continue;
                    }
                    self.ids.insert(r.id.as_bytes(), self.receivers.len());
                    self.receivers.push(r.clone());
                    return Ok(Some(CaptureRecord::Receiver(r)));
                }
                Some(Ok(rec)) => return Ok(Some(rec)),
                Some(Err(reason)) => self.skip(reason),
            }
        }
    }

    fn skip(&mut self, reason: String) {
        self.skipped += 1;
        if self.errors.len() < KEEP_ERRORS {
            self.errors.push(LineError { file: self.file.clone(), line: self.line_no, reason });
        }
    }
}

fn parse_receiver(text: &str) -> Result<CaptureRecord, String> {
    let mut words = text.split_ascii_whitespace();
    if words.next() != Some("receiver") {
        return Err(format!(
            "expected an arrival time or 'receiver', got {:?}",
            text.chars().take(20).collect::<String>()
        ));
    }
    let id = words.next().ok_or("receiver line without an id")?.to_string();
    let (mut lat, mut lon, mut alt, mut clock) = (None, None, None, None);
    for kv in words {
        let (k, v) = kv.split_once('=').ok_or_else(|| format!("expected key=value, got {kv:?}"))?;
        let num = || v.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or(format!("bad {k} value {v:?}"));
        match k {
            "lat" => lat = Some(num()?).filter(|x| x.abs() <= 90.0),
            "lon" => lon = Some(num()?).filter(|x| x.abs() <= 180.0),
            "alt" => alt = Some(num()?),
            "clock" => clock = Some(v.parse::<ClockKind>()?),
            _ => return Err(format!("unknown receiver key {k:?}")),
        }
    }
    Ok(CaptureRecord::Receiver(ReceiverDecl {
        id,
        lat: lat.ok_or("receiver needs a valid lat")?,
        lon: lon.ok_or("receiver needs a valid lon")?,
        alt: alt.ok_or("receiver needs alt")?,
        clock: clock.ok_or("receiver needs clock")?,
    }))
}

/// Receivers by their capture id. Ids of up to seven bytes (`r12`, `rx05`)
/// are looked up as one integer (their bytes and length): hashing and
/// comparing a byte string for every frame line was a ninth of parsing it.
#[derive(Default)]
struct ReceiverIds {
    short: FastMap<u64, usize>,
    long: FastMap<Vec<u8>, usize>,
}

impl ReceiverIds {
    fn short_key(id: &[u8]) -> Option<u64> {
        (id.len() < 8).then(|| {
            let bytes = id.iter().enumerate().fold(0u64, |k, (i, &b)| k | u64::from(b) << (8 * i));
            bytes | (id.len() as u64) << 56
        })
    }

    fn insert(&mut self, id: &[u8], rx: usize) {
        match Self::short_key(id) {
            Some(k) => self.short.insert(k, rx),
            None => self.long.insert(id.to_vec(), rx),
        };
    }

    fn get(&self, id: &[u8]) -> Option<usize> {
        match Self::short_key(id) {
            Some(k) => self.short.get(&k),
            None => self.long.get(id),
        }
        .copied()
    }
}

/// One line (without its newline): `None` for blank lines and comments.
fn parse_line(line: &[u8], ids: &ReceiverIds) -> Option<Result<CaptureRecord, String>> {
    let text = line.trim_ascii();
    if text.is_empty() || text[0] == b'#' {
        return None;
    }
    Some(if text.starts_with(b"receiver") {
        match std::str::from_utf8(text) {
            Ok(t) => parse_receiver(t),
            Err(_) => Err("receiver line is not text".to_string()),
        }
    } else {
        plain_frame_line(text, ids).map_or_else(|| parse_frame_line(text, ids), Ok)
    })
}

/// A frame line as [`CaptureWriter`] writes it, `SECONDS ID <HEX;` with
/// single spaces, in one pass; `None` for anything else, which the general
/// parser then reads or reports (its word splitting was over a quarter of
/// the parsing thread's instructions).
fn plain_frame_line(text: &[u8], ids: &ReceiverIds) -> Option<CaptureRecord> {
    // The words before the frame are a few bytes long, too short for
    // memchr's vector set-up to pay: a plain scan, and the arrival time's
    // width as the writer writes it (`%.6f` of ten-digit seconds) tried
    // first. A space before that place leaves a word fast_decimal refuses.
    let space = |s: &[u8]| s.iter().position(|&b| b == b' ');
    let first = if text.get(17) == Some(&b' ') { 17 } else { space(text)? };
    let arrival = fast_decimal(&text[..first])?;
    let rest = &text[first + 1..];
    let second = space(rest)?;
    let rx = ids.get(&rest[..second])?;
    let frame = frame_word(&rest[second + 1..]).ok()?;
    Some(CaptureRecord::Frame(CaptureFrame { arrival, rx, frame }))
}

/// `ARRIVAL ID <FRAME;`, on bytes: this is the hot path of `run --capture`.
fn parse_frame_line(text: &[u8], ids: &ReceiverIds) -> Result<CaptureRecord, String> {
    let mut words = words(text);
    let first = words.next().unwrap_or_default();
    let arrival: f64 = fast_decimal(first)
        .or_else(|| std::str::from_utf8(first).ok().and_then(|s| s.parse().ok()))
        .filter(|t: &f64| t.is_finite())
        .ok_or_else(|| {
            format!(
                "expected an arrival time or 'receiver', got {:?}",
                String::from_utf8_lossy(&first[..first.len().min(20)])
            )
        })?;
    let id = words.next().ok_or("frame line without a receiver id")?;
    let rx = ids.get(id).ok_or_else(|| format!("undeclared receiver {:?}", String::from_utf8_lossy(id)))?;
    let token = words.next().ok_or("frame line without a frame")?;
    if words.next().is_some() {
        return Err("trailing text after the frame".into());
    }
    let frame = frame_word(token)?;
    Ok(CaptureRecord::Frame(CaptureFrame { arrival, rx, frame }))
}

/// A line's frame, `<HEX;`, or why it is not one.
fn frame_word(word: &[u8]) -> Result<RawFrame, &'static str> {
    let token = word.strip_suffix(b";").ok_or("frame must end with ';'")?;
    if token.first() != Some(&b'<') {
        return Err("frame must be in the '<' form");
    }
    parse_avr_token(token).ok_or("malformed frame")
}

/// The words of a line, between runs of spaces and tabs (`memchr` finds
/// their ends: a byte-at-a-time split was the parser's largest cost).
fn words(text: &[u8]) -> impl Iterator<Item = &[u8]> {
    let mut rest = text;
    std::iter::from_fn(move || {
        let start = rest.iter().position(|&b| b != b' ' && b != b'\t')?;
        let end = start + memchr::memchr2(b' ', b'\t', &rest[start..]).unwrap_or(rest.len() - start);
        let word = &rest[start..end];
        rest = &rest[end..];
        Some(word)
    })
}

/// A plain decimal (`DIGITS[.DIGITS]`) whose digits, read as an integer,
/// stay within 2^53: that integer and the power of ten are then exact
/// doubles and their quotient is the correctly rounded value, the same
/// double `str::parse` gives (Clinger's fast path). Anything else (signs,
/// exponents, more digits) is `None`, for the full parser.
///
/// The writer's own form, ten digits, a dot and six (`%.6f` of Unix
/// seconds), is read inline as two groups of eight, the dot stepped over;
/// anything else goes to the general path, out of line so that the common
/// case pays for neither a call nor its registers.
#[inline]
fn fast_decimal(s: &[u8]) -> Option<f64> {
    if s.len() == 17 && s[10] == b'.' {
        let high = digits8(u64::from_le_bytes(s[..8].try_into().expect("eight bytes")))?;
        let tail = u64::from_le_bytes(s[9..].try_into().expect("eight bytes"));
        let low = (tail & !0xFFFF) | u64::from(u16::from_le_bytes([s[8], s[9]]));
        let m = high * 100_000_000 + digits8(low)?;
        return (m <= 1 << 53).then(|| m as f64 / 1e6);
    }
    fast_decimal_general(s)
}

#[inline(never)]
fn fast_decimal_general(s: &[u8]) -> Option<f64> {
    static POW10: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17,
        1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let dot = s.iter().position(|&b| b == b'.');
    let (int_end, frac_start) = dot.map_or((s.len(), s.len()), |d| (d, d + 1));
    let frac_len = s.len() - frac_start;
    let digits = int_end + frac_len;
    if digits == 0 || digits > 19 {
        return None;
    }
    static POW10_U64: [u64; 8] = [1, 10, 100, 1_000, 10_000, 100_000, 1_000_000, 10_000_000];
    // Nineteen digits fit a u64; a second dot or any other byte fails.
    let mut m = 0u64;
    for (start, end) in [(0, int_end), (frac_start, s.len())] {
        let mut eights = s[start..end].chunks_exact(8);
        for eight in &mut eights {
            m = m * 100_000_000 + digits8(u64::from_le_bytes(eight.try_into().expect("eight bytes")))?;
        }
        // The last few digits as one more group of eight, the bytes before
        // them read as zeros: the eight bytes that end with them when there
        // are eight, else a copy. A digit at a time was half of this
        // function's instructions.
        let k = eights.remainder().len();
        if k > 0 {
            let tail = if end >= 8 {
                let v = u64::from_le_bytes(s[end - 8..end].try_into().expect("eight bytes"));
                let keep = !0u64 << (8 * (8 - k));
                (v & keep) | (0x3030_3030_3030_3030 & !keep)
            } else {
                let mut padded = [b'0'; 8];
                padded[8 - k..].copy_from_slice(&s[end - k..end]);
                u64::from_le_bytes(padded)
            };
            m = m * POW10_U64[k] + digits8(tail)?;
        }
    }
    (m <= 1 << 53).then(|| m as f64 / POW10[frac_len])
}

/// Eight decimal digits (the first in the lowest byte) as their number,
/// all at once in the integer's bytes (Lemire's method); `None` if any is
/// not a digit.
fn digits8(v: u64) -> Option<u64> {
    const ONES: u64 = 0x0101_0101_0101_0101;
    const HIGH_NIBBLES: u64 = 0xF0 * ONES;
    // '0'..='9' are 0x30..=0x39: 0x3 above, and still 0x3 with 6 added.
    if v & HIGH_NIBBLES != 0x30 * ONES || v.wrapping_add(0x06 * ONES) & HIGH_NIBBLES != 0x30 * ONES {
        return None;
    }
    let d = v - 0x30 * ONES;
    // Pairs (10 a + b in every other byte), then the two halves of four.
    let pairs = d * 10 + (d >> 8);
    const EVERY_FOURTH: u64 = 0x0000_00FF_0000_00FF;
    // The products' low halves overflow by design: only bits 32.. are kept.
    let quads = (pairs & EVERY_FOURTH)
        .wrapping_mul(100 + (1_000_000 << 32))
        .wrapping_add(((pairs >> 16) & EVERY_FOURTH).wrapping_mul(1 + (10_000 << 32)));
    Some(quads >> 32)
}

/// Writes capture files; frames must come after their receiver's declaration.
pub struct CaptureWriter<W: Write> {
    out: W,
    ids: Vec<String>,
}

impl<W: Write> CaptureWriter<W> {
    pub fn new(mut out: W, comment: &str) -> io::Result<Self> {
        writeln!(out, "# fuse1090 capture v1")?;
        for line in comment.lines() {
            writeln!(out, "# {line}")?;
        }
        Ok(CaptureWriter { out, ids: Vec::new() })
    }

    /// Declares a receiver; returns its index for [`Self::frame`].
    pub fn receiver(&mut self, r: &ReceiverDecl) -> io::Result<usize> {
        writeln!(
            self.out,
            "receiver {} lat={:.8} lon={:.8} alt={:.2} clock={}",
            r.id,
            r.lat,
            r.lon,
            r.alt,
            r.clock.name()
        )?;
        self.ids.push(r.id.clone());
        Ok(self.ids.len() - 1)
    }

    pub fn frame(&mut self, arrival: f64, rx: usize, frame: &RawFrame) -> io::Result<()> {
        let mut line = [0u8; 80];
        let mut n = 0;
        let mut put = |b: &[u8]| {
            line[n..n + b.len()].copy_from_slice(b);
            n += b.len();
        };
        put(b"<");
        const HEX: &[u8; 16] = b"0123456789ABCDEF";
        for shift in (0..12).rev() {
            put(&[HEX[((frame.timestamp >> (shift * 4)) & 15) as usize]]);
        }
        put(&[HEX[(frame.signal >> 4) as usize], HEX[(frame.signal & 15) as usize]]);
        for &b in frame.bytes() {
            put(&[HEX[(b >> 4) as usize], HEX[(b & 15) as usize]]);
        }
        put(b";");
        writeln!(
            self.out,
            "{arrival:.6} {} {}",
            self.ids[rx],
            std::str::from_utf8(&line[..n]).expect("ascii")
        )
    }

    pub fn into_inner(self) -> W {
        self.out
    }

    pub fn get_ref(&self) -> &W {
        &self.out
    }
}

#[cfg(test)]
mod tests;
