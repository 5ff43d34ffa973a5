//! Plain hex lines: one frame per line, optionally with a Unix time before it,
//! separated by spaces, tabs or commas (`1457996400,"8D406B90...",...` as in
//! pyModeS' sample CSVs, or just `8D406B90...`). A line's time goes out as a
//! [`FeedEvent::ArrivalTime`] just before its frame, so CPR pairing can use it
//! when frames carry no receiver timestamp.

use super::{frame_from_hex, FeedEvent, FeedStats, FrameParser};

/// Lines longer than this are garbage, not data.
const MAX_LINE: usize = 512;

#[derive(Default)]
pub struct HexLineParser {
    line: Vec<u8>,
    stats: FeedStats,
}

impl HexLineParser {
    pub fn new() -> Self {
        Self::default()
    }

    fn end_line(&mut self, sink: &mut dyn FnMut(FeedEvent)) {
        let line = std::mem::take(&mut self.line);
        let text = String::from_utf8_lossy(&line);
        let text = text.trim();
        if text.is_empty() || text.starts_with('#') {
            self.line = line;
            self.line.clear();
            return;
        }
        match parse_hex_line(text) {
            Some((time, frame)) => {
                self.stats.count_frame(&frame);
                if let Some(t) = time {
                    sink(FeedEvent::ArrivalTime(t));
                }
                sink(FeedEvent::Frame(frame));
            }
            None => {
                self.stats.broken_frames += 1;
                self.stats.garbage_bytes += line.len() as u64;
            }
        }
        self.line = line;
        self.line.clear();
    }
}

/// Splits a line into an optional time and a frame.
pub fn parse_hex_line(text: &str) -> Option<(Option<f64>, super::RawFrame)> {
    let mut time = None;
    let mut frame = None;
    for tok in text
        .split(|c: char| c == ',' || c.is_whitespace())
        .map(|t| t.trim_matches(|c| c == '"' || c == '*' || c == ';' || c == '\u{feff}'))
        .filter(|t| !t.is_empty())
    {
        if frame.is_none() && matches!(tok.len(), 14 | 28) {
            if let Some(f) = frame_from_hex(tok, 0, 0) {
                frame = Some(f);
                continue;
            }
        }
        if frame.is_none() && time.is_none() {
            time = tok.parse::<f64>().ok().filter(|t| t.is_finite());
        }
    }
    frame.map(|f| (time, f))
}

impl FrameParser for HexLineParser {
    fn push(&mut self, input: &[u8], sink: &mut dyn FnMut(FeedEvent)) {
        self.stats.bytes += input.len() as u64;
        for &c in input {
            if c == b'\n' || c == b'\r' {
                self.end_line(sink);
            } else if self.line.len() < MAX_LINE {
                self.line.push(c);
            } else {
                self.stats.garbage_bytes += 1;
            }
        }
    }

    fn finish(&mut self, sink: &mut dyn FnMut(FeedEvent)) {
        if !self.line.is_empty() {
            self.end_line(sink);
        }
    }

    fn stats(&self) -> &FeedStats {
        &self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_and_bare_lines() {
        let (t, f) = parse_hex_line("1457996400,\"8D406B909945DE10000405999BE4\",\"406B90\",19").unwrap();
        assert_eq!(t, Some(1457996400.0));
        assert_eq!(f.hex(), "8D406B909945DE10000405999BE4");
        let (t, f) = parse_hex_line("5D4840D61F3A2B").unwrap();
        assert_eq!(t, None);
        assert_eq!(f.bytes().len(), 7);
        assert!(parse_hex_line("hello world").is_none());
    }

    #[test]
    fn lines_split_anywhere() {
        let text = b"# comment\n1.5 8D406B909945DE10000405999BE4\r\nnot a frame\n5D4840D61F3A2B";
        for cut in 0..text.len() {
            let mut p = HexLineParser::new();
            let mut out = Vec::new();
            p.push(&text[..cut], &mut |e| out.push(e));
            p.push(&text[cut..], &mut |e| out.push(e));
            p.finish(&mut |e| out.push(e));
            assert_eq!(out.len(), 3);
            assert_eq!(out[0], FeedEvent::ArrivalTime(1.5));
            assert!(matches!(out[2], FeedEvent::Frame(f) if f.bytes().len() == 7));
            assert_eq!(p.stats().broken_frames, 1);
        }
    }
}
