//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

use fuse1090::feed::{parser_for, FeedEvent, InputFormat, RawFrame};

/// A file under ../shared/data, or `None` (with a message) when the shared
/// folder is absent, as it is in a user's clone.
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("SKIP: {} not found (../shared is absent); test not run", p.display());
        None
    }
}

/// Every frame of an input, with the arrival time (if the format carries one).
pub fn frames(bytes: &[u8], format: InputFormat) -> Vec<(Option<f64>, RawFrame)> {
    let mut parser = parser_for(format);
    let mut out = Vec::new();
    let mut t = None;
    let mut sink = |e| match e {
        FeedEvent::ArrivalTime(x) => t = Some(x),
        FeedEvent::Frame(f) => out.push((t, f)),
        _ => {}
    };
    parser.push(bytes, &mut sink);
    parser.finish(&mut sink);
    out
}

/// Upper-case hex to bytes.
pub fn unhex(s: &str) -> Vec<u8> {
    (0..s.len()).step_by(2).map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap()).collect()
}
