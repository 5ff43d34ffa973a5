//! End-to-end offline throughput on `fixtures/scenarios/scale.toml` (200
//! receivers, 3,000 aircraft), cut to its first 10 s so one iteration stays
//! around a second: 1.2 M frames.
//! - `core`: frames already parsed, through the sans-IO core (frames/s);
//! - `front`: the same through the core's front stage alone (grouping,
//!   decoding, clock synchronisation, multilateration), its commands for the
//!   back stage dropped: the stage that shares a core with the parser;
//! - `run_capture`: the `run --capture` command itself (file in, parsing,
//!   the core's front and back stages on threads of their own, JSON lines out).
//!
//! Run: `cargo bench --bench pipeline`. With the binary's allocator
//! (mimalloc), so the figures are the command's.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fuse1090::core::{Core, CoreConfig};
use fuse1090::feed::capture::{CaptureReader, CaptureRecord};
use fuse1090::sim::scenario::Scenario;
use fuse1090::sim::simulate;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn capture() -> Vec<u8> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios/scale.toml");
    let mut s = Scenario::load(&path).unwrap();
    s.duration_s = 10.0;
    let mut cap = Vec::new();
    simulate(&s, &mut cap, std::io::sink()).unwrap();
    cap
}

fn bench(c: &mut Criterion) {
    let text = capture();
    let mut records = Vec::new();
    let mut reader = CaptureReader::new(&text[..], "scale");
    while let Some(r) = reader.next_record().unwrap() {
        records.push(r);
    }
    let frames = records.iter().filter(|r| matches!(r, CaptureRecord::Frame(_))).count() as u64;

    let mut g = c.benchmark_group("pipeline");
    g.sample_size(10);
    g.throughput(Throughput::Elements(frames));
    g.bench_function("core", |b| {
        b.iter(|| {
            let mut core = Core::new(&CoreConfig::default());
            for r in &records {
                match r {
                    CaptureRecord::Receiver(d) => {
                        core.handle_receiver(d.clone());
                    }
                    CaptureRecord::Frame(f) => {
                        core.handle_frame(f.arrival, f.rx, &f.frame);
                        while core.poll_event().is_some() {}
                    }
                }
            }
            core.finish();
            core.stats().positions
        })
    });
    g.bench_function("front", |b| {
        b.iter(|| {
            let (mut front, _) = Core::stages(&CoreConfig::default());
            let mut cmds = Vec::new();
            for r in &records {
                match r {
                    CaptureRecord::Receiver(d) => {
                        front.add_receiver(d.clone());
                    }
                    CaptureRecord::Frame(f) => front.on_frame(f.rx, f.arrival, &f.frame, &mut cmds),
                }
                cmds.clear();
            }
            front.finish(&mut cmds);
            front.stats().positions
        })
    });
    let dir = std::env::temp_dir().join(format!("fuse1090-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (cap, out) = (dir.join("capture.txt"), dir.join("out.jsonl"));
    std::fs::write(&cap, &text).unwrap();
    let cfg = fuse1090::config::Config::default();
    g.bench_function("run_capture", |b| {
        b.iter(|| fuse1090::cmd::run::run_capture(&cfg, &cap, &out).unwrap().frames)
    });
    g.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench);
criterion_main!(benches);
