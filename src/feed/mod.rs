//! Feed stage: bytes from a receiver become [`RawFrame`]s.
//!
//! Every parser here is a streaming state machine: it accepts input split at
//! arbitrary points (TCP) or whole datagrams (UDP), never panics, and counts
//! every byte it could not use in [`FeedStats`] instead of dropping it silently.
//! Frames are plain `Copy` values with the payload inline so the hot path never
//! allocates.

pub mod avr;
pub mod beast;
pub mod capture;
pub mod detect;
pub mod hexlines;

pub use avr::AvrParser;
pub use beast::BeastParser;
pub use detect::{detect_format, InputFormat};
pub use hexlines::HexLineParser;

/// The 48-bit timestamp value some feeders put on frames synthesised from MLAT
/// results ("MLAT" in ASCII): such frames carry no receiver timing.
pub const MLAT_MAGIC_TIMESTAMP: u64 = 0xFF00_4D4C_4154;

/// One frame as the receiver heard it.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Debug)]
pub struct RawFrame {
    /// Receiver timestamp (48 bits; 0 when the feed has none).
    pub timestamp: u64,
    /// Signal level byte (0 when unknown).
    pub signal: u8,
    len: u8,
    data: [u8; 14],
}

impl RawFrame {
    /// Builds a frame from 2 (Mode A/C), 7 (short) or 14 (long) bytes.
    pub fn new(bytes: &[u8], timestamp: u64, signal: u8) -> Option<Self> {
        if !matches!(bytes.len(), 2 | 7 | 14) {
            return None;
        }
        let mut data = [0u8; 14];
        data[..bytes.len()].copy_from_slice(bytes);
        Some(RawFrame { timestamp, signal, len: bytes.len() as u8, data })
    }

    /// The payload and its length as one integer (byte `i` in bits `8i..`,
    /// the length in the top byte): a key for grouping copies of one
    /// transmission. Read from the fixed, zero-padded array: copying a slice
    /// of the frame's length into a buffer and reading that back stalled on
    /// the store, a tenth of the grouping's time.
    #[inline]
    pub fn key(&self) -> u128 {
        let d = &self.data;
        let lo = u64::from_le_bytes([d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]]);
        let hi = u64::from_le_bytes([d[8], d[9], d[10], d[11], d[12], d[13], 0, self.len]);
        (hi as u128) << 64 | lo as u128
    }

    #[inline]
    pub fn bytes(&self) -> &[u8] {
        &self.data[..self.len as usize]
    }

    #[inline]
    pub fn is_mode_ac(&self) -> bool {
        self.len == 2
    }

    /// Timestamp is usable for timing (present and not the MLAT marker).
    pub fn has_timing(&self) -> bool {
        self.timestamp != 0 && self.timestamp != MLAT_MAGIC_TIMESTAMP
    }

    /// Upper-case hex of the payload.
    pub fn hex(&self) -> String {
        hex_upper(self.bytes())
    }
}

/// What a parser hands out.
#[derive(Clone, Copy, PartialEq, Debug)]
pub enum FeedEvent {
    Frame(RawFrame),
    /// readsb's 0xe3 frame: an 8-byte receiver id that applies to what follows.
    ReceiverId(u64),
    /// readsb's 0xe4 frame: the feeder's UUID (36 ASCII characters).
    ReceiverUuid([u8; 36]),
    /// Unix time at which the frames that follow arrived, for inputs that
    /// carry one per line (hex lines with a time column).
    ArrivalTime(f64),
}

/// Counters every parser keeps; nothing it skips goes uncounted.
#[derive(Clone, Copy, Default, Debug, PartialEq, Eq)]
pub struct FeedStats {
    pub bytes: u64,
    pub mode_ac: u64,
    pub mode_s_short: u64,
    pub mode_s_long: u64,
    pub receiver_ids: u64,
    /// Bytes that belonged to no frame.
    pub garbage_bytes: u64,
    /// Frames abandoned part-way (bad escape, bad character, too long).
    pub broken_frames: u64,
    /// Frames of a type we recognise but do not use (e.g. Beast status).
    pub skipped_frames: u64,
    /// Incomplete frames at the end of a datagram or of the input.
    pub truncated_frames: u64,
}

impl FeedStats {
    pub fn frames(&self) -> u64 {
        self.mode_ac + self.mode_s_short + self.mode_s_long
    }

    /// Input that did not become a frame: garbage bytes, broken and truncated frames.
    pub fn input_errors(&self) -> u64 {
        self.garbage_bytes + self.broken_frames + self.truncated_frames
    }

    pub(crate) fn count_frame(&mut self, frame: &RawFrame) {
        match frame.len {
            2 => self.mode_ac += 1,
            7 => self.mode_s_short += 1,
            _ => self.mode_s_long += 1,
        }
    }
}

/// The common face of the framing parsers, so callers can pick one at run time.
pub trait FrameParser {
    /// Feeds a piece of a byte stream; complete frames go to `sink`.
    fn push(&mut self, input: &[u8], sink: &mut dyn FnMut(FeedEvent));
    /// End of stream (or of a datagram): an incomplete tail is counted and dropped.
    fn finish(&mut self, sink: &mut dyn FnMut(FeedEvent));
    fn stats(&self) -> &FeedStats;

    /// A datagram is a complete unit: parse it and drop any incomplete tail.
    fn push_datagram(&mut self, datagram: &[u8], sink: &mut dyn FnMut(FeedEvent)) {
        self.push(datagram, sink);
        self.finish(sink);
    }
}

/// A parser for the given format.
pub fn parser_for(format: InputFormat) -> Box<dyn FrameParser + Send> {
    match format {
        InputFormat::Beast => Box::new(BeastParser::new()),
        InputFormat::Avr => Box::new(AvrParser::new()),
        InputFormat::Hex => Box::new(HexLineParser::new()),
    }
}

pub(crate) fn hex_upper(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789ABCDEF";
    let mut s = String::with_capacity(bytes.len() * 2);
    for &b in bytes {
        s.push(DIGITS[(b >> 4) as usize] as char);
        s.push(DIGITS[(b & 15) as usize] as char);
    }
    s
}

/// Value of each byte as a hex digit; 0x10 marks a byte that is not one.
const HEX_VALUE: [u8; 256] = {
    let mut t = [0x10u8; 256];
    let mut i = 0;
    while i < 10 {
        t[b'0' as usize + i] = i as u8;
        i += 1;
    }
    let mut i = 0;
    while i < 6 {
        t[b'a' as usize + i] = 10 + i as u8;
        t[b'A' as usize + i] = 10 + i as u8;
        i += 1;
    }
    t
};

/// Decodes an even-length hex string into `out`; `None` on any bad digit.
///
/// By table, with one validity test per string: every frame of a capture
/// goes through here, and the digit-by-digit match cost a tenth of parsing.
pub(crate) fn parse_hex_into(hex: &[u8], out: &mut [u8]) -> Option<usize> {
    if hex.len() % 2 != 0 || hex.len() / 2 > out.len() {
        return None;
    }
    let mut bad = 0u8;
    for (o, pair) in out.iter_mut().zip(hex.chunks_exact(2)) {
        let (hi, lo) = (HEX_VALUE[pair[0] as usize], HEX_VALUE[pair[1] as usize]);
        bad |= hi | lo;
        *o = (hi << 4) | (lo & 15);
    }
    (bad & 0x10 == 0).then_some(hex.len() / 2)
}

/// Parses a frame hex string (4, 14 or 28 digits).
pub fn frame_from_hex(hex: &str, timestamp: u64, signal: u8) -> Option<RawFrame> {
    let mut buf = [0u8; 14];
    let n = parse_hex_into(hex.trim().as_bytes(), &mut buf)?;
    RawFrame::new(&buf[..n], timestamp, signal)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_s_key_is_its_bytes_and_length() {
        let long = frame_from_hex("8D4840D6202CC371C32CE0576098", 1, 2).unwrap();
        let short = frame_from_hex("5D4840D61F3A2B", 3, 4).unwrap();
        let padded = frame_from_hex("5D4840D61F3A2B00000000000000", 3, 4).unwrap();
        let mut expect = [0u8; 16];
        expect[..14].copy_from_slice(long.bytes());
        expect[15] = 14;
        assert_eq!(long.key(), u128::from_le_bytes(expect));
        // Timing and signal are not part of it; the length is.
        assert_eq!(short.key(), frame_from_hex("5D4840D61F3A2B", 9, 9).unwrap().key());
        assert_ne!(short.key(), padded.key());
        assert_eq!(short.key() & ((1 << 56) - 1), padded.key() & ((1 << 56) - 1));
    }

    #[test]
    fn hex_digits_of_both_cases_decode_and_every_other_byte_is_refused() {
        let mut out = [0u8; 14];
        assert_eq!(parse_hex_into(b"8d4840D6202cC371", &mut out), Some(8));
        assert_eq!(out[..8], [0x8D, 0x48, 0x40, 0xD6, 0x20, 0x2C, 0xC3, 0x71]);
        // Every byte that is not a hex digit, in either position of a pair.
        for c in (0..=255u8).filter(|c| !c.is_ascii_hexdigit()) {
            assert_eq!(parse_hex_into(&[c, b'0'], &mut out), None, "{c:#x} first");
            assert_eq!(parse_hex_into(&[b'0', c], &mut out), None, "{c:#x} second");
        }
        // Odd length, or more than fits.
        assert_eq!(parse_hex_into(b"abc", &mut out), None);
        assert_eq!(parse_hex_into(&[b'0'; 30], &mut out), None);
    }
}
