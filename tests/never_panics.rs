//! Property tests: arbitrary bytes through every framing path and the decoder
//! never panic, never make up an aircraft, and account for every byte.

use fuse1090::feed::{parser_for, FeedEvent, InputFormat, RawFrame};
use fuse1090::modes::{Decoder, DecoderConfig, Parity};
use proptest::prelude::*;

fn run(format: InputFormat, chunks: &[Vec<u8>]) -> (Decoder, u64) {
    let mut parser = parser_for(format);
    let mut decoder = Decoder::new(DecoderConfig { reference: Some((45.0, 5.0)), ..Default::default() });
    let mut frames = 0;
    let mut t = 0.0;
    let mut sink = |e| {
        if let FeedEvent::Frame(f) = e {
            frames += 1;
            t += 0.01;
            if let Ok(d) = decoder.decode(&f, t) {
                // A frame that did not verify never counts as trusted.
                if d.msg.parity == Parity::Bad {
                    assert!(!d.trusted());
                }
            }
        }
    };
    for c in chunks {
        parser.push(c, &mut sink);
    }
    parser.finish(&mut sink);
    let s = parser.stats();
    assert_eq!(s.frames(), frames);
    (decoder, frames)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn arbitrary_bytes_never_panic(chunks in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..200), 0..8)) {
        for format in [InputFormat::Beast, InputFormat::Avr, InputFormat::Hex] {
            let (decoder, _) = run(format, &chunks);
            // Random bytes essentially never carry a valid parity; any aircraft
            // made must come from a frame that verified.
            prop_assert!(decoder.aircraft_count() as u64 <= decoder.stats().parity_ok);
        }
    }

    #[test]
    fn beast_like_noise_never_panics(chunks in prop::collection::vec(
        prop::collection::vec(prop_oneof![Just(0x1au8), Just(b'1'), Just(b'2'), Just(b'3'), Just(0xe3), any::<u8>()], 0..300), 0..6)) {
        run(InputFormat::Beast, &chunks);
    }

    #[test]
    fn any_frame_bytes_decode_without_panic(bytes in prop::collection::vec(any::<u8>(), 14), ts in any::<u64>()) {
        let mut d = Decoder::new(DecoderConfig::default());
        for len in [2usize, 7, 14] {
            let f = RawFrame::new(&bytes[..len], ts, 0).unwrap();
            let _ = d.decode(&f, f64::from_bits(ts));
            let _ = d.decode(&f, 0.0);
        }
    }
}
