//! Fuzz target: bytes through each framing parser, split at a fuzzer-chosen
//! point, and every frame through the stateful decoder and the JSON renderer.
#![no_main]

use fuse1090::feed::{parser_for, FeedEvent, InputFormat};
use fuse1090::modes::json::DecodeRecord;
use fuse1090::modes::{Decoder, DecoderConfig};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&selector, rest)) = data.split_first() else { return };
    let format = match selector % 3 {
        0 => InputFormat::Beast,
        1 => InputFormat::Avr,
        _ => InputFormat::Hex,
    };
    let cut = if rest.is_empty() { 0 } else { (selector as usize * 7) % rest.len() };
    let mut parser = parser_for(format);
    let mut decoder = Decoder::new(DecoderConfig { reference: Some((52.0, 4.0)), ..Default::default() });
    let mut t = 0.0;
    let mut sink = |e| {
        if let FeedEvent::Frame(f) = e {
            t += 0.05;
            if let Ok(d) = decoder.decode(&f, t) {
                let _ = serde_json_len(&DecodeRecord::new(&d, &f));
            }
        }
    };
    parser.push(&rest[..cut], &mut sink);
    parser.push(&rest[cut..], &mut sink);
    parser.finish(&mut sink);
});

fn serde_json_len(r: &DecodeRecord) -> usize {
    format!("{r:?}").len()
}
