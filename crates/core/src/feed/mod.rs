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

/// A receiver timestamp usable for timing: present, and not the marker of
/// frames a multilateration server sent back.
pub fn has_timing(timestamp: u64) -> bool {
    timestamp != 0 && timestamp != MLAT_MAGIC_TIMESTAMP
}

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
        // A copy of a known length per case: one of the slice's length was a
        // call to memcpy for every frame.
        let mut data = [0u8; 14];
        match bytes.len() {
            2 => data[..2].copy_from_slice(bytes),
            7 => data[..7].copy_from_slice(bytes),
            14 => data.copy_from_slice(bytes),
            _ => return None,
        }
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
        has_timing(self.timestamp)
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
    /// Keep-alive frames of an idle readsb/dump1090 Beast port (a Mode A/C
    /// frame of zeros, timestamp and signal zero too): not frames.
    pub heartbeats: u64,
}

impl FeedStats {
    pub fn frames(&self) -> u64 {
        self.mode_ac + self.mode_s_short + self.mode_s_long
    }

    /// Frames that did not become frames: broken and truncated ones
    /// (garbage between frames is counted in bytes, `garbage_bytes`).
    pub fn input_errors(&self) -> u64 {
        self.broken_frames + self.truncated_frames
    }

    pub(crate) fn count_frame(&mut self, frame: &RawFrame) {
        match frame.len {
            2 => self.mode_ac += 1,
            7 => self.mode_s_short += 1,
            _ => self.mode_s_long += 1,
        }
    }
}

/// `n` distinct Mode S short frames (DF11), timestamps 0..n, for tests.
#[cfg(any(test, feature = "test-support"))]
pub fn test_frames(n: usize) -> Vec<RawFrame> {
    (0..n).map(|i| RawFrame::new(&[0x5d, 0x4b, 0x1a, 0x2b, 0, 0, i as u8], i as u64, 0).unwrap()).collect()
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
/// Sixteen digits at a time in one vector register on x86-64, then eight
/// at a time in one integer (validity and value for all of them at once),
/// the rest by table: every frame of a capture goes through here (a
/// capture line's 42 digits were a third of parsing it with the integer
/// path alone, and a table lookup per digit cost more still).
pub(crate) fn parse_hex_into(hex: &[u8], out: &mut [u8]) -> Option<usize> {
    if hex.len() % 2 != 0 || hex.len() / 2 > out.len() {
        return None;
    }
    let n = hex.len() / 2;
    #[cfg(target_arch = "x86_64")]
    let (hex, out) = {
        let mut sixteens = hex.chunks_exact(16);
        let mut outs = out.chunks_exact_mut(8);
        for (chunk, o) in (&mut sixteens).zip(&mut outs) {
            o.copy_from_slice(&hex16(chunk.try_into().expect("sixteen bytes"))?.to_le_bytes());
        }
        let done = hex.len() / 16 * 16;
        (&hex[done..], &mut out[done / 2..])
    };
    let mut chunks = hex.chunks_exact(8);
    let mut outs = out.chunks_exact_mut(4);
    for (chunk, o) in (&mut chunks).zip(&mut outs) {
        let word = u64::from_le_bytes(chunk.try_into().expect("eight bytes"));
        o.copy_from_slice(&hex8(word)?.to_le_bytes());
    }
    let at = hex.len() / 8 * 4;
    let mut bad = 0u8;
    for (o, pair) in out[at..].iter_mut().zip(chunks.remainder().chunks_exact(2)) {
        let (hi, lo) = (HEX_VALUE[pair[0] as usize], HEX_VALUE[pair[1] as usize]);
        bad |= hi | lo;
        *o = (hi << 4) | (lo & 15);
    }
    (bad & 0x10 == 0).then_some(n)
}

/// Sixteen hex digits (the first in the lowest byte) to their eight bytes
/// (the first in the lowest byte), or `None` if any is not a digit: the
/// integer path's arithmetic on sixteen bytes at once (SSE2, which every
/// x86-64 processor has).
#[cfg(target_arch = "x86_64")]
#[inline]
fn hex16(chunk: &[u8; 16]) -> Option<u64> {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86-64, so these instructions exist on every
    // processor this compiles for; the one load reads `chunk`'s 16 bytes.
    unsafe {
        let v = _mm_loadu_si128(chunk.as_ptr().cast());
        let splat = |c: u8| _mm_set1_epi8(c as i8);
        // Signed comparisons: a byte from 0x80 up is negative, below '0'
        // and (folded) below 'a', so it is neither.
        let within = |x, lo: u8, hi: u8| {
            _mm_and_si128(_mm_cmpgt_epi8(x, splat(lo - 1)), _mm_cmplt_epi8(x, splat(hi + 1)))
        };
        let digit = within(v, b'0', b'9');
        // `| 0x20` folds 'A'..='F' onto 'a'..='f' and nothing else onto them.
        let letter = within(_mm_or_si128(v, splat(0x20)), b'a', b'f');
        if _mm_movemask_epi8(_mm_or_si128(digit, letter)) != 0xFFFF {
            return None;
        }
        let nibbles = _mm_add_epi8(_mm_and_si128(v, splat(0x0F)), _mm_and_si128(letter, splat(9)));
        // Each 16-bit lane holds a pair, its first digit in the low byte.
        let pairs = _mm_or_si128(
            _mm_slli_epi16(_mm_and_si128(nibbles, _mm_set1_epi16(0x0F)), 4),
            _mm_srli_epi16(nibbles, 8),
        );
        Some(_mm_cvtsi128_si64(_mm_packus_epi16(pairs, pairs)) as u64)
    }
}

/// Eight hex digits (the first in the lowest byte) to their four bytes (the
/// first in the lowest byte), or `None` if any is not a digit.
#[inline]
fn hex8(v: u64) -> Option<u32> {
    const ONES: u64 = 0x0101_0101_0101_0101;
    const HIGH: u64 = 0x8080_8080_8080_8080;
    // Each byte's high bit: that byte (below 0x80) is at least `c`.
    let at_least = |x: u64, c: u8| (x + (0x80 - c as u64) * ONES) & HIGH;
    if v & HIGH != 0 {
        return None;
    }
    let digit = at_least(v, b'0') & !at_least(v, b'9' + 1);
    // Upper case folded to lower: `| 0x20` maps only 'A'..='F' and
    // 'a'..='f' into 'a'..='f'.
    let folded = v | (0x20 * ONES);
    let letter = at_least(folded, b'a') & !at_least(folded, b'f' + 1);
    if digit | letter != HIGH {
        return None;
    }
    let nibbles = (v & (0x0F * ONES)) + (letter >> 7) * 9;
    // Pairs of nibbles into bytes, then the bytes side by side.
    const LOW_BYTES: u64 = 0x00FF_00FF_00FF_00FF;
    let pairs = ((nibbles & LOW_BYTES) << 4) | ((nibbles >> 8) & LOW_BYTES);
    let quads = (pairs | (pairs >> 8)) & 0x0000_FFFF_0000_FFFF;
    Some((quads | (quads >> 16)) as u32)
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
        // Every byte in every place of the sixteen-digit (vector) and
        // eight-digit (integer) runs and the rest, up to a capture line's 42
        // digits, against the standard library's digit values. A third of
        // the strings have no stray byte, a third about one, a third many.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut out = [0u8; 21];
        let mut valid = 0;
        for _ in 0..300_000 {
            let len = 2 * rng.gen_range(0..=21);
            let stray = [0.0, 1.0 / len.max(1) as f64, 0.25][rng.gen_range(0..3)];
            let text: Vec<u8> = (0..len)
                .map(|_| match rng.gen_bool(stray) {
                    true => rng.gen(),
                    false => b"0123456789abcdefABCDEF"[rng.gen_range(0..22)],
                })
                .collect();
            let digits: Option<Vec<u32>> = text.iter().map(|&c| (c as char).to_digit(16)).collect();
            let expect = digits.map(|d| d.chunks(2).map(|p| (p[0] * 16 + p[1]) as u8).collect::<Vec<_>>());
            let got = parse_hex_into(&text, &mut out).map(|n| out[..n].to_vec());
            valid += (got.is_some() && len >= 32) as u32;
            assert_eq!(got, expect, "{:?}", String::from_utf8_lossy(&text));
        }
        assert!(valid > 30_000, "{valid} valid strings of two vector runs");
        // Odd length, or more than fits.
        assert_eq!(parse_hex_into(b"abc", &mut out), None);
        assert_eq!(parse_hex_into(&[b'0'; 44], &mut out), None);
    }
}
