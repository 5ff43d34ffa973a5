use super::*;

#[test]
fn receiver_ids_of_every_length_find_their_own_receiver() {
    // Short ids are packed into one integer with their length: ids that
    // differ only by trailing NULs or by length must not meet.
    let ids: Vec<Vec<u8>> = (0..=12)
        .flat_map(|n| [vec![b'r'; n], [vec![b'r'; n.saturating_sub(1)], vec![0]].concat()])
        .chain([b"r1".to_vec(), b"r10".to_vec(), b"r1\0".to_vec(), b"rx22".to_vec(), b"abcdefg".to_vec()])
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut map = ReceiverIds::default();
    for (rx, id) in ids.iter().enumerate() {
        map.insert(id, rx);
    }
    for (rx, id) in ids.iter().enumerate() {
        assert_eq!(map.get(id), Some(rx), "{id:?}");
    }
    for unknown in [&b"r2"[..], b"abcdefgh", b"x", b"rrrrrrrrrrrrrrrr"] {
        assert_eq!(map.get(unknown), None, "{unknown:?}");
    }
}

#[test]
fn fast_decimals_are_the_standard_parser_s_doubles() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    for i in 0..200_000u32 {
        // Arrival times as captures write them, and any split of up to 19 digits.
        let s = if i % 2 == 0 {
            format!("{:.6}", rng.gen_range(1.5e9..1.8e9))
        } else {
            let digits: String =
                (0..rng.gen_range(1..=19)).map(|_| rng.gen_range(b'0'..=b'9') as char).collect();
            let dot = rng.gen_range(0..=digits.len());
            format!("{}.{}", &digits[..dot], &digits[dot..])
        };
        let std = s.parse::<f64>().ok();
        match super::fast_decimal(s.as_bytes()) {
            Some(v) => assert_eq!(Some(v.to_bits()), std.map(f64::to_bits), "{s}"),
            None => assert!(s.len() > 16 || std.is_none(), "{s} left to the full parser"),
        }
    }
    // The writer's width (17 bytes, dot at 10) with a wrong byte anywhere, or past 2^53.
    let odd_17 = ["1700000000.52165x", "170000000x.521657", "1700000000.5216 7", "+700000000.521657"];
    let more_17 = ["17000.0000.521657", "1700000000..21657", "9999999999.999999", "1700000000.52165\n"];
    for s in
        ["", ".", "1..2", "-1.5", "+1", "1e5", "1.5x", "nan", "inf"].into_iter().chain(odd_17).chain(more_17)
    {
        assert_eq!(super::fast_decimal(s.as_bytes()), None, "{s}");
    }
    assert_eq!(super::fast_decimal(b"1700000012.121168"), Some(1700000012.121168));
}

#[test]
fn the_plain_line_path_reads_what_the_general_parser_reads_and_nothing_else() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut ids = ReceiverIds::default();
    ids.insert(b"r1", 0);
    ids.insert(b"rx22", 1);
    let good = "1700000000.023698 r1 <000F53FCF111A98D4004845881F13FE149670FB5F4;";
    let alphabet = b" \t.;<0123456789abcdefABCDEFrx*@%-+eG";
    let (mut plain, mut rejected) = (0, 0);
    for i in 0..100_000 {
        // Lines as written, then with up to three bytes changed, inserted or removed.
        let mut line = good.as_bytes().to_vec();
        if i % 4 == 1 {
            line = b"17.5 rx22 <5D4840D61F3A2B;".to_vec();
        }
        for _ in 0..rng.gen_range(0..=3) {
            let at = rng.gen_range(0..line.len());
            let byte = alphabet[rng.gen_range(0..alphabet.len())];
            match rng.gen_range(0..3) {
                0 => line[at] = byte,
                1 => line.insert(at, byte),
                _ => drop(line.remove(at)),
            }
        }
        let text = line.trim_ascii();
        if text.is_empty() || text[0] == b'#' || text.starts_with(b"receiver") {
            continue;
        }
        match super::plain_frame_line(text, &ids) {
            Some(rec) => {
                assert_eq!(
                    super::parse_frame_line(text, &ids),
                    Ok(rec),
                    "{:?}",
                    String::from_utf8_lossy(text)
                );
                plain += 1;
            }
            None => rejected += 1,
        }
    }
    // Both kinds were seen: the comparison above was made.
    assert!(plain > 20_000 && rejected > 20_000, "{plain} {rejected}");
}

#[test]
fn words_split_on_runs_of_spaces_and_tabs() {
    let w: Vec<&[u8]> = super::words(b"  1.5 \t rx1\t\t<00;  ").collect();
    assert_eq!(w, [&b"1.5"[..], b"rx1", b"<00;"]);
    assert_eq!(super::words(b" \t ").count(), 0);
}

#[test]
fn round_trip_and_bad_lines() {
    let mut w = CaptureWriter::new(Vec::new(), "test").unwrap();
    let rx =
        ReceiverDecl { id: "rx1".into(), lat: 43.629, lon: 1.3638, alt: 152.0, clock: ClockKind::Beast12 };
    let i = w.receiver(&rx).unwrap();
    let f = crate::feed::frame_from_hex("8D4840D6202CC371C32CE0576098", 0xA1B2C3D4E5F6, 0xA0).unwrap();
    w.frame(1581500000.123456, i, &f).unwrap();
    let mut text = String::from_utf8(w.into_inner()).unwrap();
    assert!(text.contains("1581500000.123456 rx1 <A1B2C3D4E5F6A08D4840D6202CC371C32CE0576098;"), "{text}");
    text += "1581500001.0 rx2 <A1B2C3D4E5F6A08D4840D6202CC371C32CE0576098;\n";
    text += "garbage here\n";
    text += "1581500001.0 rx1 <A1B2C3D4E5F6A08D4840D6202CC371C32CE05760;\n";
    text += "receiver rx1 lat=1 lon=2 alt=3 clock=gps\n";
    text += "receiver rx9 lat=91 lon=2 alt=3 clock=gps\n";
    text += "1581500002.5 rx1 <000000000000FF5D4840D61F3A2B;\n";
    // Lines whole in the reader's buffer and lines across its end (a
    // buffer smaller than a line, or ending mid-line): the same records.
    text += "1581500003.5 rx1 <000000000000FF5D4840D61F3A2B;"; // no final newline
    for capacity in [1 << 16, 1, 7, 50, 64] {
        let mut r =
            CaptureReader::new(std::io::BufReader::with_capacity(capacity, text.as_bytes()), "mem.txt");
        let mut recs = Vec::new();
        while let Some(x) = r.next_record().unwrap() {
            recs.push(x);
        }
        assert_eq!(recs.len(), 4, "buffer {capacity}");
        assert_eq!(recs[0], CaptureRecord::Receiver(rx.clone()));
        assert_eq!(
            recs[1],
            CaptureRecord::Frame(CaptureFrame { arrival: 1581500000.123456, rx: 0, frame: f })
        );
        assert!(matches!(recs[3], CaptureRecord::Frame(CaptureFrame { arrival: 1581500003.5, .. })));
        assert_eq!(r.skipped, 5);
        let reasons: Vec<String> = r.errors.iter().map(|e| e.to_string()).collect();
        assert!(reasons[0].starts_with("mem.txt:5: undeclared receiver \"rx2\""), "{reasons:?}");
        assert!(reasons[1].contains("expected an arrival time"));
        assert!(reasons[2].contains("malformed frame"));
        assert!(reasons[3].contains("declared twice"));
        assert!(reasons[4].starts_with("mem.txt:9:") && reasons[4].contains("valid lat"), "{reasons:?}");
    }
}

#[test]
fn gps_shift_is_exact_to_the_nanosecond() {
    let gps = |s: u64, ns: u64| (s << 30) | ns;
    // Differences between shifted timestamps are the originals' exactly,
    // including across midnight either way and for shifts of decades.
    let stamps = [gps(3_600, 123_456_789), gps(3_600, 123_456_790), gps(86_399, 999_999_999), gps(0, 1)];
    for shift in [0i64, 1, -1, 1_764_000_000_123_456_789, -86_400_000_000_001, 86_399_999_999_999] {
        for &a in &stamps {
            let moved = ClockKind::gps_shift(a, shift);
            assert!(moved & 0x3FFF_FFFF < 1_000_000_000);
            assert!(moved >> 30 < 86_400);
            let back = ClockKind::gps_shift(moved, -shift);
            assert_eq!(back, a, "shift {shift} of {a:#x}");
            for &b in &stamps {
                let ns = |t: u64| (t >> 30) as i64 * 1_000_000_000 + (t & 0x3FFF_FFFF) as i64;
                let day = 86_400_000_000_000i64;
                let before = (ns(b) - ns(a)).rem_euclid(day);
                let after = (ns(ClockKind::gps_shift(b, shift)) - ns(moved)).rem_euclid(day);
                assert_eq!(before, after, "shift {shift}");
            }
        }
    }
    assert_eq!(ClockKind::gps_shift(gps(86_399, 999_999_999), 1), gps(0, 0));
    assert_eq!(ClockKind::gps_shift(gps(0, 0), -1), gps(86_399, 999_999_999));
}

#[test]
fn gps_timestamps_across_midnight() {
    let t = 1590969599.75; // 23:59:59.75 UTC
    let ts = ClockKind::gps_timestamp(t);
    assert!((ClockKind::gps_unix(ts, t + 0.5) - t).abs() < 1e-6);
    assert!((ClockKind::gps_unix(ClockKind::gps_timestamp(t + 0.5), t) - (t + 0.5)).abs() < 1e-6);
}
