//! Soak: traffic that comes and goes for simulated hours through the same
//! core `run --capture` drives, with memory and every per-aircraft table
//! watched. A service that runs for weeks must forget the aircraft it no
//! longer hears: with thousands of new addresses an hour, a table that
//! never ages grows without end.
//!
//! The traffic is simulated in segments of a few minutes, each with
//! aircraft of its own (new addresses), one after the other on one clock.
//! The quick version runs in CI; the full one (three hours, 10,000 aircraft
//! an hour) is ignored by default: `cargo test --release --test soak -- --ignored`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use fuse1090::core::{Core, CoreConfig};
use fuse1090::feed::capture::{CaptureReader, CaptureRecord};
use fuse1090::sim::scenario::Scenario;

/// Five GPS-timed receivers 60 km apart, and `count` aircraft (a tenth
/// without ADS-B) from `first_hex`, for `duration_s` from `start`.
fn segment(seed: u64, start: f64, duration_s: f64, count: usize, first_hex: u32) -> Scenario {
    let mut text = format!("seed = {seed}\nstart_unix = {start}\nduration_s = {duration_s}\n");
    for (k, (lat, lon)) in
        [(48.0, 8.0), (48.5, 8.0), (47.5, 8.0), (48.0, 8.8), (48.0, 7.2)].iter().enumerate()
    {
        text += &format!(
            "[[receiver]]\nid = \"g{k}\"\nlat = {lat}\nlon = {lon}\nalt_m = 300.0\nclock = \"gps\"\n"
        );
    }
    text += &format!(
        "[[traffic]]\ncount = {count}\nfirst_hex = \"{first_hex:06X}\"\ncenter_lat = 48.0\ncenter_lon = 8.0\n\
         radius_km = 120.0\nalt_m = [1000.0, 12000.0]\nspeed_mps = [100.0, 250.0]\nmode_s_only = {}\n",
        count / 10
    );
    Scenario::parse(&text, "soak segment").unwrap()
}

/// Counts the bytes this test binary holds on the heap. Resident memory
/// was the first measure, but the allocator keeps freed pages mapped as it
/// sees fit, so it moved by more than a tenth between runs of the same
/// traffic; the live heap moves only when something is kept.
struct Counting;

static LIVE_BYTES: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is passed unchanged to the system allocator; the
// counter is only arithmetic beside it.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            LIVE_BYTES.fetch_add(layout.size(), Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE_BYTES.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            LIVE_BYTES.fetch_sub(layout.size(), Ordering::Relaxed);
            LIVE_BYTES.fetch_add(new_size, Ordering::Relaxed);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The heap this process holds now (kB).
fn heap_kb() -> u64 {
    (LIVE_BYTES.load(Ordering::Relaxed) / 1024) as u64
}

/// `periods` periods of `period_s`, each bringing `per_period` new aircraft
/// in segments of `segment_s`; at the end of each period: (heap kB,
/// decoder aircraft, MLAT aircraft, tracks).
fn soak(periods: usize, period_s: f64, per_period: usize, segment_s: f64) -> Vec<(u64, usize, usize, usize)> {
    let mut core = Core::new(&CoreConfig::default());
    let segments_per_hour = (period_s / segment_s).round() as usize;
    let per_segment = per_period / segments_per_hour;
    let start = 1_700_000_000.0;
    let mut hourly = Vec::new();
    for k in 0..periods * segments_per_hour {
        let s = segment(
            k as u64 + 1,
            start + k as f64 * segment_s,
            segment_s,
            per_segment,
            0x100000 + (k * per_segment) as u32,
        );
        let mut cap = Vec::new();
        fuse1090::sim::simulate(&s, &mut cap, std::io::sink()).unwrap();
        let mut reader = CaptureReader::new(cap.as_slice(), "segment");
        while let Some(rec) = reader.next_record().unwrap() {
            // The receivers are declared once, by the first segment.
            if k > 0 && matches!(rec, CaptureRecord::Receiver(_)) {
                continue;
            }
            core.handle_record(rec);
            while core.poll_event().is_some() {}
        }
        // The segment's capture is let go before the heap is read, so what
        // is counted is what the core keeps.
        drop(reader);
        drop(cap);
        if (k + 1) % segments_per_hour == 0 {
            hourly.push((
                heap_kb(),
                core.decoder().aircraft_count(),
                core.mlat().aircraft_count(),
                core.fuser().tracks(),
            ));
            eprintln!("period {}: {:?}", hourly.len(), hourly.last().unwrap());
        }
    }
    hourly
}

/// Tables hold what was heard lately, not everything ever heard: after the
/// first period their sizes and the heap stay flat.
fn assert_flat(hourly: &[(u64, usize, usize, usize)], per_period: usize) {
    let (first, last) = (hourly[0], *hourly.last().unwrap());
    for (name, a, b) in [("decoder", first.1, last.1), ("mlat", first.2, last.2), ("tracks", first.3, last.3)]
    {
        assert!(b <= a + a / 10 + 10, "{name} table grew from {a} to {b}: {hourly:?}");
        assert!(
            b < per_period * 3 / 4,
            "{name} table holds {b} of a period's {per_period} aircraft: {hourly:?}"
        );
    }
    assert!(last.0 <= first.0 + first.0 / 10, "the heap grew by over 10%: {hourly:?}");
}

/// The quick version: 10,000 aircraft an hour, each heard for 30 s, in
/// three periods of 20 minutes (the tables' times to live are 10 minutes
/// at most, so each period turns them over twice).
#[test]
fn an_hour_of_traffic_coming_and_going_leaves_the_tables_flat() {
    let periods = soak(3, 1200.0, 3_333, 30.0);
    assert_flat(&periods, 3_333);
}

/// The full soak: three hours of 10,000 aircraft an hour, each heard for
/// five minutes.
#[test]
#[ignore = "soak: three simulated hours, minutes of CPU; run with --ignored"]
fn three_hours_of_traffic_coming_and_going_leave_the_tables_flat() {
    let hours = soak(3, 3600.0, 10_000, 300.0);
    assert_flat(&hours, 10_000);
}
