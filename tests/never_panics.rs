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

mod capture_and_mlat {
    use fuse1090::core::{Core, CoreConfig, Event};
    use fuse1090::feed::capture::{CaptureReader, CaptureRecord};
    use proptest::prelude::*;

    fn line() -> impl Strategy<Value = String> {
        prop_oneof![
            // Receiver lines, good and bad.
            (-100.0f64..100.0, -200.0f64..200.0, -1e4f64..1e4, 0..4u8).prop_map(|(a, b, c, k)| format!(
                "receiver r{k} lat={a} lon={b} alt={c} clock={}",
                if k % 2 == 0 { "gps" } else { "beast12" }
            )),
            // Frame lines with random timestamps and bytes.
            (1.7e9f64..1.7e9 + 100.0, 0..5u8, any::<u64>(), prop::collection::vec(any::<u8>(), 7..=7))
                .prop_map(|(t, r, ts, b)| {
                    let hex: String = b.iter().map(|x| format!("{x:02X}")).collect();
                    format!("{t:.6} r{r} <{:012X}80{hex};", ts & 0xFFFF_FFFF_FFFF)
                }),
            // A valid DF4 from a fixed aircraft, heard with random timestamps.
            (1.7e9f64..1.7e9 + 100.0, 0..4u8, any::<u64>()).prop_map(|(t, r, ts)| format!(
                "{t:.6} r{r} <{:012X}8020001838CA3804;",
                ts & 0xFFFF_FFFF_FFFF
            )),
            ".{0,40}",
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        #[test]
        fn random_captures_never_panic_and_make_no_fix_from_noise(lines in prop::collection::vec(line(), 0..200)) {
            let text = lines.join("\n");
            let mut reader = CaptureReader::new(text.as_bytes(), "random");
            let mut core = Core::new(&CoreConfig::default());
            while let Some(rec) = reader.next_record().unwrap() {
                match rec {
                    CaptureRecord::Receiver(d) => {
                        core.handle_receiver(d);
                    }
                    CaptureRecord::Frame(f) => core.handle_frame(f.arrival, f.rx, &f.frame),
                }
            }
            core.finish();
            let events: Vec<Event> = std::iter::from_fn(|| core.poll_event()).collect();
            // Random timestamps are never geometrically consistent: no fix.
            let fixes = events.iter().filter(|e| matches!(e, Event::Mlat(_))).count();
            prop_assert_eq!(fixes, 0);
        }
    }
}
