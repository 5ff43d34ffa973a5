//! fuse1090 vs rs1090 on the same frames: the real beastblackbox capture's
//! Mode S frames (needs ../shared).

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use fuse1090::feed::{BeastParser, FeedEvent};
use rs1090::prelude::*;

fn frames() -> Vec<Vec<u8>> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/real/beastblackbox/ulss7-beast-bin-utc--1522782148.136310917--.log");
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = Vec::new();
    BeastParser::new().push_with(&bytes, &mut |e| {
        if let FeedEvent::Frame(f) = e {
            if !f.is_mode_ac() {
                out.push(f.bytes().to_vec())
            }
        }
    });
    out
}

fn bench(c: &mut Criterion) {
    let frames = frames();
    let mut g = c.benchmark_group("peers");
    g.throughput(Throughput::Elements(frames.len() as u64));
    g.bench_function("fuse1090", |b| {
        b.iter(|| frames.iter().filter(|f| fuse1090::modes::decode(black_box(f)).is_ok()).count())
    });
    g.bench_function("rs1090", |b| {
        b.iter(|| frames.iter().filter(|f| Message::from_bytes((black_box(f), 0)).is_ok()).count())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
