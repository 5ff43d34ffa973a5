//! AVR text framing, as dump1090/readsb and Beast boxes emit it:
//!
//! - `*HEX;` a frame without timing;
//! - `@TTTTTTTTTTTTHEX;` and `%TTTTTTTTTTTTHEX;` a 48-bit timestamp (12 hex digits) then the frame;
//! - `<TTTTTTTTTTTTSSHEX;` timestamp, signal byte, frame (the capture format's form).
//!
//! Lines end in CR, LF or both; a frame also ends at its `;`. The parser is a
//! byte-at-a-time state machine so it can resume anywhere in a split stream;
//! AVR is a low-rate format, so clarity wins over speed here.

use super::{parse_hex_into, FeedEvent, FeedStats, FrameParser, RawFrame};

/// Longest token: `<` + 12 + 2 + 28 hex digits.
const MAX_TOKEN: usize = 1 + 12 + 2 + 28;

#[derive(Default)]
pub struct AvrParser {
    token: Vec<u8>,
    in_token: bool,
    stats: FeedStats,
}

impl AvrParser {
    pub fn new() -> Self {
        Self::default()
    }

    fn end_token(&mut self, sink: &mut dyn FnMut(FeedEvent)) {
        self.in_token = false;
        // dump1090's keep-alive on an idle raw port: not a frame.
        if self.token == b"*0000" {
            self.stats.heartbeats += 1;
            self.token.clear();
            return;
        }
        match parse_avr_token(&self.token) {
            Some(frame) => {
                self.stats.count_frame(&frame);
                sink(FeedEvent::Frame(frame));
            }
            None => {
                self.stats.broken_frames += 1;
                self.stats.garbage_bytes += self.token.len() as u64;
            }
        }
        self.token.clear();
    }
}

/// Parses one token such as `*8D4840D6...` (without the `;`).
pub fn parse_avr_token(token: &[u8]) -> Option<RawFrame> {
    let (&kind, rest) = token.split_first()?;
    let (ts_digits, sig_digits) = match kind {
        b'*' => (0, 0),
        b'@' | b'%' => (12, 0),
        b'<' => (12, 2),
        _ => return None,
    };
    if rest.len() < ts_digits + sig_digits {
        return None;
    }
    // Timestamp, signal and frame in one pass: their digit counts are
    // even, so the bytes split where the digits do.
    let (ts_len, sig_len) = (ts_digits / 2, sig_digits / 2);
    let mut bytes = [0u8; 6 + 1 + 14];
    let n = parse_hex_into(rest, &mut bytes[..ts_len + sig_len + 14])? - ts_len - sig_len;
    let mut ts = [0u8; 8];
    if ts_len == 6 {
        // Fixed length: a copy of a variable one was a call to memcpy.
        ts[2..].copy_from_slice(&bytes[..6]);
    }
    let sig = if sig_len > 0 { bytes[ts_len] } else { 0 };
    RawFrame::new(&bytes[ts_len + sig_len..][..n], u64::from_be_bytes(ts), sig)
}

impl FrameParser for AvrParser {
    fn push(&mut self, input: &[u8], sink: &mut dyn FnMut(FeedEvent)) {
        self.stats.bytes += input.len() as u64;
        for &c in input {
            match c {
                b'*' | b'@' | b'%' | b'<' => {
                    if self.in_token {
                        // A new frame began before the old one ended.
                        self.stats.broken_frames += 1;
                        self.stats.garbage_bytes += self.token.len() as u64;
                        self.token.clear();
                    }
                    self.in_token = true;
                    self.token.push(c);
                }
                b';' | b'\r' | b'\n' => {
                    if self.in_token {
                        self.end_token(sink);
                    } else if c == b';' {
                        self.stats.garbage_bytes += 1;
                    }
                }
                _ if self.in_token => {
                    self.token.push(c);
                    if self.token.len() > MAX_TOKEN {
                        self.stats.broken_frames += 1;
                        self.stats.garbage_bytes += self.token.len() as u64;
                        self.token.clear();
                        self.in_token = false;
                    }
                }
                b' ' | b'\t' => {}
                _ => self.stats.garbage_bytes += 1,
            }
        }
    }

    fn finish(&mut self, _sink: &mut dyn FnMut(FeedEvent)) {
        if self.in_token {
            self.stats.truncated_frames += 1;
            self.token.clear();
            self.in_token = false;
        }
    }

    fn stats(&self) -> &FeedStats {
        &self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(chunks: &[&[u8]]) -> (Vec<RawFrame>, FeedStats) {
        let mut p = AvrParser::new();
        let mut out = Vec::new();
        let mut sink = |e| {
            if let FeedEvent::Frame(f) = e {
                out.push(f)
            }
        };
        for c in chunks {
            p.push(c, &mut sink);
        }
        p.finish(&mut sink);
        (out, *p.stats())
    }

    #[test]
    fn all_four_forms() {
        let text = b"*8D4840D6202CC371C32CE0576098;\r\n\
            @0000112233448D4840D6202CC371C32CE0576098;\n\
            %0000112233445D4840D61F3A2B;\n\
            <000011223344C85D4840D61F3A2B;\n*2000;\n";
        let (frames, stats) = run(&[text]);
        assert_eq!(frames.len(), 5);
        assert_eq!(frames[0].hex(), "8D4840D6202CC371C32CE0576098");
        assert_eq!(frames[0].timestamp, 0);
        assert_eq!(frames[1].timestamp, 0x1122_3344);
        assert_eq!(frames[3].signal, 0xC8);
        assert_eq!(frames[3].hex(), "5D4840D61F3A2B");
        assert!(frames[4].is_mode_ac());
        assert_eq!(stats.garbage_bytes, 0);
    }

    #[test]
    fn split_stream_garbage_and_truncation() {
        let text = b"xx*8D4840D6202CC371C32CE0576098;*8D48ZZ;\n*8D4840D6202CC371C32CE0576098;*8D48";
        for cut in 0..text.len() {
            let (frames, stats) = run(&[&text[..cut], &text[cut..]]);
            assert_eq!(frames.len(), 2, "cut {cut}");
            assert_eq!(stats.broken_frames, 1);
            assert_eq!(stats.truncated_frames, 1);
            assert_eq!(stats.garbage_bytes, 2 + 7);
        }
    }

    #[test]
    fn wrong_lengths_rejected() {
        let (frames, stats) = run(&[b"*8D4840;\n*8D4840D6202CC371C32CE057609;\n<0011;\n"]);
        assert!(frames.is_empty());
        assert_eq!(stats.broken_frames, 3);
    }

    #[test]
    fn a_raw_heartbeat_is_counted_not_a_frame() {
        let mut p = AvrParser::new();
        let mut frames = 0;
        p.push(b"*0000;\n*8D4840D6202CC371C32CE0576098;\n*0000;\n", &mut |e| {
            frames += matches!(e, FeedEvent::Frame(_)) as usize
        });
        assert_eq!((frames, p.stats.heartbeats, p.stats.input_errors()), (1, 2, 0));
    }
}
