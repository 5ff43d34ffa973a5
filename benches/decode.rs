//! Decode throughput: stateless Mode S decoding of a realistic frame mix
//! (frames/s) and Beast framing (bytes/s).
//!
//! The mix is the real beastblackbox capture's Mode S frames when ../shared is
//! present (DF17 of every type code, DF11, DF0/4/5/16/20/21 in their recorded
//! proportions), else a synthetic mix built with our encoders in the same
//! proportions; and Comm-B register inference per reply on real replies. Run:
//! `cargo bench --bench decode`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use fuse1090::feed::beast::encode as beast_encode;
use fuse1090::feed::{BeastParser, FeedEvent, RawFrame};
use fuse1090::modes::commb::{infer, Inference, Known};
use fuse1090::modes::cpr::encode as cpr_encode;
use fuse1090::modes::encode::{
    ac13_q, df11, df17, me_airborne_position, me_identification, me_velocity, surveillance_reply,
};
use fuse1090::modes::{decode, Body, Decoder, DecoderConfig};

const CAPTURE: &str = "../shared/data/real/beastblackbox/ulss7-beast-bin-utc--1522782148.136310917--.log";

fn real_frames() -> Option<Vec<RawFrame>> {
    let bytes = std::fs::read(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(CAPTURE)).ok()?;
    let mut out = Vec::new();
    BeastParser::new().push_with(&bytes, &mut |e| {
        if let FeedEvent::Frame(f) = e {
            if !f.is_mode_ac() {
                out.push(f)
            }
        }
    });
    Some(out)
}

/// DF17 positions/velocity/identification, DF11, DF4, DF20 in about the
/// proportions of a real feed.
fn synthetic_frames() -> Vec<RawFrame> {
    let mut out = Vec::new();
    for k in 0..1000u32 {
        let addr = 0x400000 + k % 50;
        let lat = 50.0 + (k as f64) * 1e-3;
        let f: Vec<u8> = match k % 10 {
            0..=2 => df17(
                5,
                addr,
                me_airborne_position(11, Some(35_000), 0, cpr_encode(lat, 4.0, k % 2 == 1, false)),
            )
            .to_vec(),
            3 | 4 => df17(5, addr, me_velocity(200.0, -150.0, Some(-640), true, 1, None)).to_vec(),
            5 => df17(5, addr, me_identification(0xA3, "TEST123")).to_vec(),
            6 | 7 => df11(5, addr, 0).to_vec(),
            8 => surveillance_reply(4, 0, ac13_q(35_000).unwrap(), addr, None),
            _ => surveillance_reply(20, 0, ac13_q(35_000).unwrap(), addr, Some(0x2012345678)),
        };
        out.push(RawFrame::new(&f, k as u64 * 6000, 100).unwrap());
    }
    out
}

fn bench(c: &mut Criterion) {
    let frames = real_frames().unwrap_or_else(synthetic_frames);

    let mut g = c.benchmark_group("decode");
    g.throughput(Throughput::Elements(frames.len() as u64));
    g.bench_function("stateless", |b| {
        b.iter(|| {
            let mut n = 0u32;
            for f in &frames {
                if let Ok(m) = decode(black_box(f.bytes())) {
                    n = n.wrapping_add(m.addr);
                }
            }
            n
        })
    });
    g.bench_function("stateful", |b| {
        b.iter_batched(
            || Decoder::new(DecoderConfig::default()),
            |mut d| {
                for (i, f) in frames.iter().enumerate() {
                    let _ = black_box(d.decode(f, i as f64 * 0.004));
                }
                d
            },
            criterion::BatchSize::LargeInput,
        )
    });
    g.finish();
    bench_commb(c);

    let mut wire = Vec::new();
    while wire.len() < 4 << 20 {
        for f in &frames {
            beast_encode(f, &mut wire);
        }
    }
    let mut g = c.benchmark_group("framing");
    g.throughput(Throughput::Bytes(wire.len() as u64));
    g.bench_function("beast", |b| {
        b.iter(|| {
            let mut p = BeastParser::new();
            let mut n = 0u64;
            for chunk in wire.chunks(64 << 10) {
                p.push_with(black_box(chunk), &mut |e| {
                    if let FeedEvent::Frame(f) = e {
                        n += f.timestamp
                    }
                });
            }
            n
        })
    });
    g.finish();
}

const COMMB: [&str; 2] = [
    "../shared/data/real/pymodes/sample_data_commb_df20.csv",
    "../shared/data/real/pymodes/sample_data_commb_df21.csv",
];

/// Comm-B inference alone, per reply, on pyModeS's 10,000 real DF20/21
/// replies (4,0, 5,0 and 6,0 mostly: the full inference, not the 2,0 fast
/// path), each with its own altitude where it carries one.
fn bench_commb(c: &mut Criterion) {
    let text: String = COMMB.iter().filter_map(|p| std::fs::read_to_string(p).ok()).collect();
    let replies: Vec<(u64, Known)> = text
        .lines()
        .filter_map(|l| decode(&unhex(l.rsplit(',').next()?)?).ok())
        .filter_map(|m| match m.body {
            Body::Altitude { alt_ft, mb: Some(mb), .. } => {
                Some((mb, Known { alt_ft: alt_ft.map(|a| (a, 0.0)), velocity: None }))
            }
            Body::Identity { mb: Some(mb), .. } => Some((mb, Known::default())),
            _ => None,
        })
        .collect();
    if replies.is_empty() {
        eprintln!("commb_infer: ../shared/data/real/pymodes absent, not measured");
        return;
    }
    let mut g = c.benchmark_group("decode");
    g.throughput(Throughput::Elements(replies.len() as u64));
    g.bench_function("commb_infer", |b| {
        b.iter(|| {
            replies
                .iter()
                .filter(|(mb, k)| matches!(infer(black_box(*mb), k), Inference::Identified(_)))
                .count()
        })
    });
    g.finish();
}

fn unhex(s: &str) -> Option<Vec<u8>> {
    let s = s.trim();
    (0..s.len()).step_by(2).map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok()).collect()
}

criterion_group!(benches, bench);
criterion_main!(benches);
