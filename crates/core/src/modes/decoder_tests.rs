//! The stateful decoder's unit tests: the policy on addresses, CPR pairing and
//! plausibility, and Comm-B inference with what is known of the aircraft.

use super::*;
use crate::modes::commb::Register;
use crate::modes::cpr::encode as cpr_encode;
use crate::modes::encode::{
    ac13_q, df11, df17, me_airborne_position, me_surface_position, surveillance_reply,
};

const ADDR: u32 = 0x3C6DD4;

fn frame(bytes: &[u8]) -> RawFrame {
    RawFrame::new(bytes, 0, 0).unwrap()
}

fn position(lat: f64, lon: f64, odd: bool) -> RawFrame {
    frame(&df17(5, ADDR, me_airborne_position(11, Some(30_000), 0, cpr_encode(lat, lon, odd, false))))
}

#[test]
fn correction_only_for_known_addresses() {
    let mut d = Decoder::new(DecoderConfig::default());
    let mut bad = position(50.0, 8.0, false);
    let mut bytes = bad.bytes().to_vec();
    bytes[9] ^= 0x04;
    bad = frame(&bytes);
    // Unknown address: not corrected, no aircraft made up.
    let out = d.decode(&bad, 0.0).unwrap();
    assert_eq!(out.msg.parity, Parity::Bad);
    assert!(!out.known);
    assert_eq!(d.aircraft_count(), 0);
    assert_eq!(d.stats().corrected_unknown, 1);
    // Once a clean all-call names the aircraft, the same frame is repaired.
    d.decode(&frame(&df11(5, ADDR, 0)), 1.0).unwrap();
    let out = d.decode(&bad, 2.0).unwrap();
    assert_eq!(out.msg.parity, Parity::Corrected(9 * 8 + 5));
    assert_eq!(out.msg.body, message::decode(position(50.0, 8.0, false).bytes()).unwrap().body);
    assert_eq!(d.stats().corrected, 1);
    // Two bits wrong: never "corrected".
    bytes[10] ^= 0x40;
    assert_eq!(d.decode(&frame(&bytes), 3.0).unwrap().msg.parity, Parity::Bad);
}

#[test]
fn address_parity_never_creates_an_aircraft() {
    let mut d = Decoder::new(DecoderConfig::default());
    let reply = frame(&surveillance_reply(4, 0, 0x0C38, ADDR, None));
    let out = d.decode(&reply, 0.0).unwrap();
    assert!(!out.known && !out.trusted());
    assert_eq!(d.aircraft_count(), 0);
    d.decode(&position(50.0, 8.0, false), 1.0).unwrap();
    assert!(d.decode(&reply, 2.0).unwrap().trusted());
    assert_eq!(d.stats().address_parity_unknown, 1);
    assert_eq!(d.stats().address_parity_known, 1);
}

#[test]
fn first_decode_waits_for_confirmation() {
    let mut d = Decoder::new(DecoderConfig::default());
    assert_eq!(d.decode(&position(50.0, 8.0, false), 0.0).unwrap().position, None);
    let p = d.decode(&position(50.0005, 8.0, true), 0.5).unwrap().position.unwrap();
    assert!(!p.reliable, "a single global decode is not published");
    assert_eq!(p.method, CprMethod::Global);
    let p = d.decode(&position(50.001, 8.0, false), 1.0).unwrap().position.unwrap();
    assert!(p.reliable);
    assert!(distance_m(p.lat, p.lon, 50.001, 8.0) < 6.0);
}

#[test]
fn implausible_jump_is_rejected_and_a_new_track_rebuilt() {
    let mut d = Decoder::new(DecoderConfig::default());
    let mut t = 0.0;
    for k in 0..6 {
        d.decode(&position(50.0 + k as f64 * 0.001, 8.0, k % 2 == 1), t).unwrap();
        t += 0.5;
    }
    // A frame claiming 50 km away half a second later.
    let out = d.decode(&position(50.45, 8.0, false), t).unwrap();
    assert!(out.position.is_none());
    assert_eq!(d.stats().cpr_speed_reject, 1);
    // The honest track resumes at once.
    let p = d.decode(&position(50.0065, 8.0, true), t + 0.5).unwrap().position.unwrap();
    assert!(p.reliable && distance_m(p.lat, p.lon, 50.0065, 8.0) < 6.0);
}

#[test]
fn stale_pairs_are_not_combined() {
    let mut d = Decoder::new(DecoderConfig::default());
    d.decode(&position(50.0, 8.0, false), 0.0).unwrap();
    // 30 s later: outside the pair window, no position from the stale even frame.
    assert_eq!(d.decode(&position(50.1, 8.0, true), 30.0).unwrap().position, None);
    assert_eq!(d.stats().cpr_unresolved, 2);
    assert_eq!(d.stats().cpr_global, 0);
}

#[test]
fn surface_needs_a_reference_and_resolves_with_one() {
    let surface = |lat: f64, lon: f64, odd: bool| {
        frame(&df17(5, ADDR, me_surface_position(7, 10, Some(45.0), cpr_encode(lat, lon, odd, true))))
    };
    let mut d = Decoder::new(DecoderConfig::default());
    d.decode(&surface(-33.94, 151.17, false), 0.0).unwrap();
    assert_eq!(d.decode(&surface(-33.94, 151.17, true), 1.0).unwrap().position, None);
    assert_eq!(d.stats().cpr_no_reference, 1);

    let mut d = Decoder::new(DecoderConfig { reference: Some((-33.9, 151.2)), ..Default::default() });
    d.decode(&surface(-33.94, 151.17, false), 0.0).unwrap();
    d.decode(&surface(-33.94001, 151.17, true), 1.0).unwrap();
    let p = d.decode(&surface(-33.94002, 151.17, false), 2.0).unwrap().position.unwrap();
    assert!(p.surface && p.reliable);
    assert!(distance_m(p.lat, p.lon, -33.94002, 151.17) < 2.0, "{p:?}");
}

#[test]
fn receiver_local_decode_cannot_confirm_an_alias() {
    // 400 km from the receiver, a lone frame decoded locally against the
    // receiver aliases to about 267 km away. It must never be published,
    // and the pair that follows must replace it with the truth.
    let mut d = Decoder::new(DecoderConfig { reference: Some((46.4, 8.0)), ..Default::default() });
    let alias = d.decode(&position(50.0, 8.0, false), 0.0).unwrap().position.unwrap();
    assert_eq!(alias.method, CprMethod::LocalReceiver);
    assert!(!alias.reliable && distance_m(alias.lat, alias.lon, 50.0, 8.0) > 100_000.0);
    assert!(d.decode(&position(50.0, 8.0, false), 0.2).unwrap().position.is_none_or(|p| !p.reliable));
    d.decode(&position(50.0005, 8.0, true), 0.5).unwrap();
    let p = d.decode(&position(50.001, 8.0, false), 1.0).unwrap().position.unwrap();
    assert!(p.reliable && distance_m(p.lat, p.lon, 50.001, 8.0) < 6.0, "{p:?}");
}

#[test]
fn positions_beyond_max_range_are_rejected() {
    let cfg = DecoderConfig { reference: Some((46.4, 8.0)), max_range_m: 200_000.0, ..Default::default() };
    let mut d = Decoder::new(cfg);
    d.decode(&position(50.0, 8.0, false), 0.0).unwrap();
    assert!(d.decode(&position(50.0005, 8.0, true), 0.5).unwrap().position.is_none());
    assert!(d.stats().cpr_range_reject >= 1);
}

#[test]
fn comm_b_inference_uses_what_is_known_of_the_aircraft() {
    // A real DF21 reply (pyModeS's sample): 6,0 with IAS 279 kt and Mach
    // 0.688 (26,400 ft in ISA), or 5,0 with roll 22.5 deg and 344 kt.
    let (addr, mb) = (0x4CA6E3, 0x901A2F2B21B000);
    let df21 = frame(&surveillance_reply(21, 0, 0, addr, Some(mb)));
    let altitude = |ft| frame(&surveillance_reply(4, 0, ac13_q(ft).unwrap(), addr, None));
    let mut d = Decoder::new(DecoderConfig::default());
    // Of an unknown address nothing is remembered, whatever it sent.
    d.decode(&altitude(26_400), 0.0).unwrap();
    assert!(matches!(d.decode(&df21, 0.5).unwrap().commb, Some(Inference::Ambiguous(_))));
    d.decode(&frame(&df11(5, addr, 0)), 1.0).unwrap();
    d.decode(&altitude(26_400), 2.0).unwrap();
    match d.decode(&df21, 3.0).unwrap().commb {
        Some(Inference::Identified(Register::HeadingSpeed(r))) => assert_eq!(r.ias_kt, Some(279)),
        other => panic!("{other:?}"),
    }
    // At 10,000 ft that IAS is not that Mach: not 6,0, and 5,0 has nothing for it.
    d.decode(&altitude(10_000), 4.0).unwrap();
    assert!(matches!(
        d.decode(&df21, 5.0).unwrap().commb,
        Some(Inference::Identified(Register::TrackTurn(_)))
    ));
    // An altitude a minute old is not used.
    assert!(matches!(d.decode(&df21, 70.0).unwrap().commb, Some(Inference::Ambiguous(_))));
    let c = d.stats().commb;
    assert_eq!((c.identified, c.ambiguous), (2, 2));
}
