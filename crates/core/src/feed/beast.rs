//! Beast binary framing: `0x1a`, a type byte, then an escaped body in which
//! every literal `0x1a` is doubled.
//!
//! Types '1' (Mode A/C), '2' (Mode S short) and '3' (Mode S long) carry a 48-bit
//! big-endian timestamp and a signal byte before the payload. readsb adds 0xe3
//! (8-byte receiver id for the frames that follow) and 0xe4 (36-character
//! UUID); Radarcape's '4' status frame is recognised and skipped. Anything else
//! is garbage we resynchronise past: a frame only starts at a `0x1a` that is not
//! the second half of an escaped pair.
//!
//! The hot path looks at each body once with `memchr`: a body with no `0x1a`
//! in it needs no unescaping and is copied straight out.

use super::{FeedEvent, FeedStats, FrameParser, RawFrame};
use memchr::memchr;

const ESC: u8 = 0x1a;
/// Longest body we ever unescape (the UUID frame).
const MAX_BODY: usize = 36;
/// Longest escaped frame: marker, type and a body where every byte is doubled.
const MAX_ESCAPED: usize = 2 + 2 * MAX_BODY;

/// Streaming Beast parser; keeps at most one incomplete frame between calls.
#[derive(Default)]
pub struct BeastParser {
    carry: Vec<u8>,
    stats: FeedStats,
}

enum Step {
    /// Parsed or skipped something; continue at this index.
    Next(usize),
    /// Need more bytes; the incomplete frame starts at this index.
    Incomplete(usize),
}

impl BeastParser {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn stats(&self) -> &FeedStats {
        &self.stats
    }

    /// Monomorphised entry point (the trait method goes through `dyn`).
    pub fn push_with<F: FnMut(FeedEvent)>(&mut self, input: &[u8], sink: &mut F) {
        self.stats.bytes += input.len() as u64;
        let mut input = input;
        if !self.carry.is_empty() {
            // Complete the pending frame from the front of `input`; appending
            // MAX_ESCAPED bytes is always enough to finish any frame.
            let old = self.carry.len();
            let take = input.len().min(MAX_ESCAPED);
            self.carry.extend_from_slice(&input[..take]);
            let buf = std::mem::take(&mut self.carry);
            let used = self.parse(&buf, sink);
            if used >= old {
                input = &input[used - old..];
            } else {
                // Still incomplete: only possible when `input` was short.
                self.carry.extend_from_slice(&buf[used..]);
                self.carry.extend_from_slice(&input[take..]);
                return;
            }
        }
        let used = self.parse(input, sink);
        self.carry.extend_from_slice(&input[used..]);
    }

    pub fn finish_with<F: FnMut(FeedEvent)>(&mut self, _sink: &mut F) {
        if !self.carry.is_empty() {
            self.stats.truncated_frames += 1;
            self.carry.clear();
        }
    }

    /// Parses `buf`, returning how much of it was used (the rest is an
    /// incomplete frame).
    fn parse<F: FnMut(FeedEvent)>(&mut self, buf: &[u8], sink: &mut F) -> usize {
        let mut i = 0;
        while i < buf.len() {
            if buf[i] != ESC {
                match memchr(ESC, &buf[i..]) {
                    None => {
                        self.stats.garbage_bytes += (buf.len() - i) as u64;
                        return buf.len();
                    }
                    Some(k) => {
                        self.stats.garbage_bytes += k as u64;
                        i += k;
                    }
                }
            }
            match self.frame_at(buf, i, sink) {
                Step::Next(next) => i = next,
                Step::Incomplete(at) => return at,
            }
        }
        buf.len()
    }

    /// `buf[i]` is 0x1a.
    #[inline]
    fn frame_at<F: FnMut(FeedEvent)>(&mut self, buf: &[u8], i: usize, sink: &mut F) -> Step {
        let Some(&ty) = buf.get(i + 1) else {
            return Step::Incomplete(i);
        };
        let body_len = match ty {
            b'1' => 6 + 1 + 2,
            b'2' => 6 + 1 + 7,
            b'3' | b'4' => 6 + 1 + 14,
            0xe3 => 8,
            0xe4 => 36,
            ESC => {
                // An escaped data byte outside any frame: not a frame start.
                self.stats.garbage_bytes += 2;
                return Step::Next(i + 2);
            }
            _ => {
                self.stats.garbage_bytes += 1;
                return Step::Next(i + 1);
            }
        };
        let start = i + 2;
        if let Some(body) = buf.get(start..start + body_len) {
            if !contains_esc(body) {
                self.emit(ty, body, sink);
                return Step::Next(start + body_len);
            }
        }
        // Slow path: unescape.
        let mut body = [0u8; MAX_BODY];
        let mut j = start;
        for slot in body.iter_mut().take(body_len) {
            let Some(&b) = buf.get(j) else {
                return Step::Incomplete(i);
            };
            if b == ESC {
                match buf.get(j + 1) {
                    None => return Step::Incomplete(i),
                    Some(&ESC) => j += 2,
                    Some(_) => {
                        // A lone 0x1a inside a body: the frame was cut short and
                        // a new one starts here.
                        self.stats.broken_frames += 1;
                        self.stats.garbage_bytes += (j - i) as u64;
                        return Step::Next(j);
                    }
                }
            } else {
                j += 1;
            }
            *slot = b;
        }
        self.emit(ty, &body[..body_len], sink);
        Step::Next(j)
    }

    #[inline]
    fn emit<F: FnMut(FeedEvent)>(&mut self, ty: u8, body: &[u8], sink: &mut F) {
        match ty {
            b'1' if body.iter().all(|&b| b == 0) => self.stats.heartbeats += 1,
            b'1' | b'2' | b'3' => {
                let ts = body[..6].iter().fold(0u64, |acc, &b| (acc << 8) | b as u64);
                if let Some(frame) = RawFrame::new(&body[7..], ts, body[6]) {
                    self.stats.count_frame(&frame);
                    sink(FeedEvent::Frame(frame));
                }
            }
            0xe3 => {
                let id = body.iter().fold(0u64, |acc, &b| (acc << 8) | b as u64);
                self.stats.receiver_ids += 1;
                sink(FeedEvent::ReceiverId(id));
            }
            0xe4 => {
                let mut uuid = [0u8; 36];
                uuid.copy_from_slice(body);
                self.stats.receiver_ids += 1;
                sink(FeedEvent::ReceiverUuid(uuid));
            }
            _ => self.stats.skipped_frames += 1,
        }
    }
}

/// Whether any byte of a short body (8 to 36 bytes) is 0x1a, eight at a time.
/// `memchr` is built for long haystacks; on a frame body its set-up costs more
/// than this whole check.
#[inline]
fn contains_esc(b: &[u8]) -> bool {
    #[inline]
    fn word_has_esc(w: u64) -> bool {
        let x = w ^ 0x1a1a_1a1a_1a1a_1a1a;
        x.wrapping_sub(0x0101_0101_0101_0101) & !x & 0x8080_8080_8080_8080 != 0
    }
    #[inline]
    fn word(b: &[u8], at: usize) -> u64 {
        u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
    }
    let n = b.len();
    if n < 8 {
        return b.contains(&ESC);
    }
    let mut at = 0;
    while at + 8 <= n {
        if word_has_esc(word(b, at)) {
            return true;
        }
        at += 8;
    }
    // The last, overlapping word covers the tail.
    at < n && word_has_esc(word(b, n - 8))
}

impl FrameParser for BeastParser {
    fn push(&mut self, input: &[u8], sink: &mut dyn FnMut(FeedEvent)) {
        self.push_with(input, &mut |e| sink(e));
    }
    fn finish(&mut self, sink: &mut dyn FnMut(FeedEvent)) {
        self.finish_with(&mut |e| sink(e));
    }
    fn stats(&self) -> &FeedStats {
        &self.stats
    }
}

/// Encodes readsb's receiver id frame (0xe3): the 8-byte id of the
/// receiver whose frames follow (`replay` names a receiver with it).
pub fn encode_receiver_id(id: u64, out: &mut Vec<u8>) {
    encode_body(0xe3, &id.to_be_bytes(), out);
}

/// Encodes readsb's UUID frame (0xe4): the feeder's 36-character UUID.
pub fn encode_receiver_uuid(uuid: &[u8; 36], out: &mut Vec<u8>) {
    encode_body(0xe4, uuid, out);
}

fn encode_body(ty: u8, body: &[u8], out: &mut Vec<u8>) {
    out.push(ESC);
    out.push(ty);
    push_escaped(body.iter().copied(), out);
}

/// A frame's body with every literal 0x1a doubled.
fn push_escaped(body: impl IntoIterator<Item = u8>, out: &mut Vec<u8>) {
    for b in body {
        out.push(b);
        if b == ESC {
            out.push(ESC);
        }
    }
}

/// Encodes a frame as Beast binary (used by `replay`, tests and benchmarks).
pub fn encode(frame: &RawFrame, out: &mut Vec<u8>) {
    out.push(ESC);
    out.push(match frame.bytes().len() {
        2 => b'1',
        7 => b'2',
        _ => b'3',
    });
    let ts = frame.timestamp.to_be_bytes();
    push_escaped(ts[2..].iter().chain(std::iter::once(&frame.signal)).chain(frame.bytes()).copied(), out);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn collect(parser: &mut BeastParser, chunks: &[&[u8]]) -> Vec<FeedEvent> {
        let mut out = Vec::new();
        for c in chunks {
            parser.push_with(c, &mut |e| out.push(e));
        }
        parser.finish_with(&mut |e| out.push(e));
        out
    }

    fn long_frame() -> RawFrame {
        // DF17 identification, with 0x1a in the timestamp and signal to force escapes.
        let bytes = [0x8D, 0x48, 0x40, 0xD6, 0x20, 0x2C, 0xC3, 0x71, 0xC3, 0x2C, 0xE0, 0x57, 0x60, 0x98];
        RawFrame::new(&bytes, 0x1a1a_0000_1a01, 0x1a).unwrap()
    }

    #[test]
    fn escapes_inside_timestamp_and_signal_round_trip() {
        let f = long_frame();
        let mut wire = Vec::new();
        encode(&f, &mut wire);
        assert_eq!(wire.len(), 2 + 21 + 4, "four escaped bytes");
        let out = collect(&mut BeastParser::new(), &[&wire]);
        assert_eq!(out, vec![FeedEvent::Frame(f)]);
    }

    #[test]
    fn stream_split_at_every_point() {
        let f = long_frame();
        let short = RawFrame::new(&[0x5D, 0x48, 0x40, 0xD6, 0x1a, 0x2C, 0xC3], 12345, 200).unwrap();
        let mut wire = Vec::new();
        encode(&f, &mut wire);
        encode(&short, &mut wire);
        encode(&f, &mut wire);
        for cut in 0..=wire.len() {
            for cut2 in cut..=wire.len() {
                let mut p = BeastParser::new();
                let out = collect(&mut p, &[&wire[..cut], &wire[cut..cut2], &wire[cut2..]]);
                assert_eq!(out.len(), 3, "cut at {cut},{cut2}");
                assert_eq!(out[1], FeedEvent::Frame(short));
                assert_eq!(p.stats().garbage_bytes, 0);
                assert_eq!(p.stats().truncated_frames, 0);
            }
        }
    }

    #[test]
    fn garbage_between_frames_is_counted_and_skipped() {
        let f = long_frame();
        let mut wire = vec![0x00, 0x33, 0x1a, 0x1a, 0x33, 0xff];
        encode(&f, &mut wire);
        wire.extend_from_slice(&[0x42, 0x1a, 0x99, 0x07]);
        encode(&f, &mut wire);
        let mut p = BeastParser::new();
        let out = collect(&mut p, &[&wire]);
        assert_eq!(out.len(), 2);
        assert_eq!(p.stats().garbage_bytes, 6 + 4);
    }

    #[test]
    fn frame_cut_by_new_frame_resyncs() {
        let f = long_frame();
        let mut first = Vec::new();
        encode(&f, &mut first);
        let mut wire = first[..11].to_vec(); // half a frame
        encode(&f, &mut wire);
        let mut p = BeastParser::new();
        let out = collect(&mut p, &[&wire]);
        assert_eq!(out, vec![FeedEvent::Frame(f)]);
        assert_eq!(p.stats().broken_frames, 1);

        // Cut right after a lone 0x1a, the next marker reads as an escaped data
        // byte (Beast cannot tell them apart) and that frame is lost, but the
        // parser is back in sync for the one after.
        let mut wire = first[..12].to_vec();
        assert_eq!(wire[11], ESC);
        for _ in 0..3 {
            encode(&f, &mut wire);
        }
        let out = collect(&mut BeastParser::new(), &[&wire]);
        assert!(out.len() >= 2 && out[out.len() - 2..].iter().all(|e| *e == FeedEvent::Frame(f)));
    }

    #[test]
    fn truncated_tail_and_datagrams() {
        let f = long_frame();
        let mut wire = Vec::new();
        encode(&f, &mut wire);
        encode(&f, &mut wire);
        let cut = wire.len() - 5;
        let mut p = BeastParser::new();
        let mut out = Vec::new();
        p.push_datagram(&wire[..cut], &mut |e| out.push(e));
        assert_eq!(out.len(), 1);
        assert_eq!(p.stats().truncated_frames, 1);
        // The next datagram starts clean: the tail of the previous one is not glued on.
        p.push_datagram(&wire, &mut |e| out.push(e));
        assert_eq!(out.len(), 3);
    }

    #[test]
    fn escape_detection_agrees_with_a_plain_scan() {
        for len in 8..=36 {
            for pos in 0..len {
                let mut b = vec![0x55u8; len];
                assert!(!contains_esc(&b));
                b[pos] = ESC;
                assert!(contains_esc(&b), "len {len} pos {pos}");
                b[pos] = 0x1b;
                assert!(!contains_esc(&b));
            }
        }
    }

    #[test]
    fn receiver_id_and_uuid_frames_round_trip_through_the_encoders() {
        let mut wire = Vec::new();
        encode_receiver_id(0x1a1a_0203_0405_061a, &mut wire);
        let uuid = *b"0f1e2d3c-4b5a-6978-8796-a5b4c3d2e1f0";
        encode_receiver_uuid(&uuid, &mut wire);
        let out = collect(&mut BeastParser::new(), &[&wire]);
        assert_eq!(out, vec![FeedEvent::ReceiverId(0x1a1a_0203_0405_061a), FeedEvent::ReceiverUuid(uuid)]);
    }

    #[test]
    fn receiver_id_and_uuid_frames() {
        let mut wire = vec![0x1a, 0xe3, 1, 2, 3, 4, 5, 6, 0x1a, 0x1a, 8];
        wire.extend_from_slice(&[0x1a, 0xe4]);
        wire.extend_from_slice(b"0123456789abcdef0123456789abcdef0123");
        wire.extend_from_slice(&[0x1a, b'4']);
        wire.extend_from_slice(&[0u8; 21]);
        let mut p = BeastParser::new();
        let out = collect(&mut p, &[&wire]);
        assert_eq!(out[0], FeedEvent::ReceiverId(0x0102030405061a08));
        assert!(matches!(out[1], FeedEvent::ReceiverUuid(u) if &u[..4] == b"0123"));
        assert_eq!(p.stats().skipped_frames, 1);
        assert_eq!(out.len(), 2);
    }

    #[test]
    fn a_beast_heartbeat_is_counted_not_a_frame() {
        let mut p = BeastParser::default();
        let mut frames = 0;
        let mut bytes = vec![0x1a, b'1', 0, 0, 0, 0, 0, 0, 0, 0, 0];
        encode(&RawFrame::new(&[0x20, 0, 0, 0, 0, 0, 0], 5, 9).unwrap(), &mut bytes);
        p.push(&bytes, &mut |e| frames += matches!(e, FeedEvent::Frame(_)) as usize);
        assert_eq!((frames, p.stats().heartbeats, p.stats().input_errors()), (1, 1, 0));
    }
}
