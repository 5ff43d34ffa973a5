//! The core driven as the daemon drives it: between frames, by the
//! deadlines it gives (`poll_timeout`), and against the same capture
//! driven by its frames alone.

mod common;

use std::path::Path;

use fuse1090::core::{Core, CoreConfig, Event};
use fuse1090::feed::capture::{CaptureReader, CaptureRecord};

fn capture() -> Vec<u8> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::read(root.join("fixtures/captures/fusion-8seg/capture.txt")).unwrap()
}

#[test]
fn a_transmission_makes_its_group_wait_the_next_deadline() {
    let cfg = CoreConfig::default();
    let mut core = Core::new(&cfg);
    assert_eq!(core.poll_timeout(), None, "nothing to do before anything happened");
    let capture = capture();
    let mut reader = CaptureReader::new(&capture[..], "capture");
    let first = loop {
        match reader.next_record().unwrap().unwrap() {
            CaptureRecord::Receiver(d) => {
                core.handle_receiver(d);
            }
            CaptureRecord::Frame(f) => break f,
        }
    };
    core.handle_frame(first.arrival, first.rx, &first.frame);
    assert_eq!(core.poll_timeout(), Some(first.arrival + cfg.group_wait_s));
    assert_eq!(core.grouper().stats().groups, 1);
    core.handle_timeout(first.arrival + cfg.group_wait_s);
    let next = core.poll_timeout().unwrap();
    assert!(next > first.arrival + cfg.group_wait_s, "{next}");
}

#[test]
fn driven_by_its_deadlines_the_core_never_spins_and_hands_out_every_group_on_time() {
    let cfg = CoreConfig::default();
    let capture = capture();
    let (by_frames, frame_events, _) = common::run_core(&capture, &cfg);

    let mut core = Core::new(&cfg);
    let mut reader = CaptureReader::new(&capture[..], "capture");
    let (mut timeouts, mut events) = (0u64, Vec::new());
    while let Some(rec) = reader.next_record().unwrap() {
        if let CaptureRecord::Frame(f) = &rec {
            // What a sleeping loop does: wake at each deadline before the
            // next frame comes.
            while let Some(t) = core.poll_timeout().filter(|&t| t <= f.arrival) {
                core.handle_timeout(t);
                timeouts += 1;
                let next = core.poll_timeout();
                assert!(next.is_none_or(|n| n > t), "deadline {t} still due after it was handled: {next:?}");
                events.extend(std::iter::from_fn(|| core.poll_event()));
            }
        }
        core.handle_record(rec);
        events.extend(std::iter::from_fn(|| core.poll_event()));
    }
    core.finish();
    events.extend(std::iter::from_fn(|| core.poll_event()));

    assert!(timeouts > 1000, "{timeouts} deadlines in a capture of minutes");
    assert_eq!(core.grouper().stats().groups, by_frames.grouper().stats().groups);
    // The same transmissions are grouped and handed out in the same order
    // (before the frame that finds their wait over, either way); only the
    // time each is handed out at differs: its deadline, or that frame's
    // arrival. That time paces the fixes of ADS-B aircraft (one per
    // interval of processing time), so the two runs fix partly different
    // transmissions of them; those both fix agree.
    let fixes = |ev: &[Event]| -> Vec<fuse1090::mlat::MlatFix> {
        ev.iter().filter_map(|e| if let Event::Mlat(f) = e { Some((**f).clone()) } else { None }).collect()
    };
    let (a, b) = (fixes(&frame_events), fixes(&events));
    assert!(a.len() > 50, "{}", a.len());
    assert!(
        (a.len() as f64 - b.len() as f64).abs() <= 0.1 * a.len() as f64,
        "{} against {}",
        b.len(),
        a.len()
    );
    let (mut both, mut worst) = (0, 0f64);
    for x in &a {
        if let Some(y) = b.iter().find(|y| y.addr == x.addr && y.t == x.t) {
            let d = common::en(x.lat, x.lon, y.lat, y.lon);
            worst = worst.max(d[0].hypot(d[1]));
            both += 1;
        }
    }
    assert!(both >= a.len() / 4, "{both} transmissions fixed by both runs");
    assert!(worst < 5.0, "fixes of one transmission {worst} m apart");
    let tracks = |ev: &[Event]| ev.iter().filter(|e| matches!(e, Event::Track(_))).count();
    eprintln!(
        "{timeouts} deadlines handled; {} fixes ({} driven by frames alone, {both} of the same transmissions, at most {worst:.2} m apart); track reports {} (frames alone {})",
        b.len(),
        a.len(),
        tracks(&events),
        tracks(&frame_events)
    );
}

/// Every per-aircraft table empties once its aircraft are no longer heard:
/// the track and its conformance watch after the track's drop time, what
/// decoding and multilateration remember after the aircraft's time to
/// live, with nothing but time passing (`handle_timeout`).
#[test]
fn every_aircraft_table_ages_out_on_time_alone() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let capture = std::fs::read(root.join("fixtures/captures/surface/capture.txt")).unwrap();
    let cfg = CoreConfig::default();
    let mut core = Core::new(&cfg);
    let mut reader = CaptureReader::new(&capture[..], "capture");
    let mut last = f64::NEG_INFINITY;
    while let Some(rec) = reader.next_record().unwrap() {
        if let CaptureRecord::Frame(f) = &rec {
            last = f.arrival;
        }
        core.handle_record(rec);
        while core.poll_event().is_some() {}
    }
    let held = core.aircraft_held();
    assert!(held.decoder > 1 && held.mlat > 1 && held.tracker > 1 && held.conformance > 0, "{held:?}");

    let mut pass = |t: f64| {
        core.handle_timeout(t);
        while core.poll_event().is_some() {}
        core.aircraft_held()
    };
    let tracks_gone = pass(last + cfg.track.drop_after_s + 2.0);
    assert_eq!((tracks_gone.tracker, tracks_gone.conformance), (0, 0), "{tracks_gone:?}");
    assert_eq!(
        (tracks_gone.decoder, tracks_gone.mlat),
        (held.decoder, held.mlat),
        "what is remembered of an aircraft outlives its track"
    );
    // The decoder looks once a minute.
    let all_gone = pass(last + cfg.aircraft_ttl_s + 62.0);
    assert_eq!(all_gone, Default::default(), "before: {held:?}");
}
