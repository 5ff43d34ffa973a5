//! Multilateration results as Beast frames, for readsb, dump1090 and
//! tar1090: what mlat-client sends back to a receiver's Beast input
//! (`--results beast,connect,...`), so that those tools show the aircraft
//! fuse1090 positioned although it broadcasts no ADS-B.
//!
//! Each publication of a fused track that multilateration alone fed becomes
//! a pair of airborne position squitters (even and odd CPR, so that the
//! receiving decoder can place it without a reference), a velocity squitter
//! once the velocity is known, and an identification squitter when a
//! callsign is known. They are DF18 with CF 2 (fine TIS-B, ICAO address)
//! rather than DF17, so that no tool mistakes them for the aircraft's own
//! ADS-B, and they carry the Beast timestamp `FF 00 4D 4C 41 54` ("\xff\0MLAT"),
//! which readsb and dump1090 take to mean "a multilateration result".
//! Aircraft that broadcast ADS-B are left out: the receiving decoder hears
//! them itself.

use crate::feed::beast;
use crate::feed::RawFrame;
use crate::fuse::TrackReport;
use crate::fuse::TrackSource;
use crate::modes::{cpr, encode};
use crate::publish::readout::Readout;

/// The Beast timestamp that marks a frame as a multilateration result.
pub const MLAT_TIMESTAMP: u64 = 0xFF00_4D4C_4154;
/// The signal byte sent: no level was measured.
const SIGNAL: u8 = 0xFF;
/// CF 2: fine TIS-B, ICAO 24-bit address.
const CF_FINE_TISB_ICAO: u8 = 2;
/// TC 18: airborne position with barometric altitude, NUCp 0 (the
/// accuracy is not the squitter's to say).
const TC_POSITION: u8 = 18;

/// Appends the frames for one publication of a fused track, if it is one
/// multilateration alone fed; `ro` is its [`readout`](super::readout).
pub fn mlat_result(r: &TrackReport, ro: &Readout, out: &mut Vec<u8>) {
    if ro.adsb || r.source != TrackSource::Fused {
        return;
    }
    let est = &r.est;
    // The squitter's altitude field is barometric: the transponder's own
    // altitude when its replies gave one, else the track's height.
    let alt_ft = r.alt_baro_ft.or(ro.alt_geom_ft.map(|a| a as i32));
    for odd in [false, true] {
        let cpr = cpr::encode(est.lat, est.lon, odd, false);
        let me = encode::me_airborne_position(TC_POSITION, alt_ft, 0, cpr);
        push(encode::df18(CF_FINE_TISB_ICAO, r.addr, me), out);
    }
    if let Some([ve, vn]) = ro.vel_en_kt {
        let rate = ro.geom_rate_fpm.map(|v| v.clamp(-33_000, 33_000) as i32);
        let me = encode::me_velocity(ve, vn, rate, false, 0, None);
        push(encode::df18(CF_FINE_TISB_ICAO, r.addr, me), out);
    }
    if let Some(flight) = r.flight.as_deref().filter(|f| !f.is_empty()) {
        // Category A0: no category information.
        push(encode::df18(CF_FINE_TISB_ICAO, r.addr, encode::me_identification(0xA0, flight)), out);
    }
}

fn push(frame: [u8; 14], out: &mut Vec<u8>) {
    if let Some(f) = RawFrame::new(&frame, MLAT_TIMESTAMP, SIGNAL) {
        beast::encode(&f, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::feed::{FeedEvent, FrameParser};
    use crate::modes::{crc, velocity};
    use crate::publish::readout::readout;
    use crate::publish::test_report::{report, Source};

    /// The frames sent for a report, parsed back from the Beast stream.
    fn frames(sources: &[Source]) -> Vec<RawFrame> {
        let r = report(0x3C6DD4, 100.0, sources);
        let mut wire = Vec::new();
        mlat_result(&r, &readout(&r), &mut wire);
        let mut parser = beast::BeastParser::new();
        let mut out = Vec::new();
        parser.push(&wire, &mut |e| {
            if let FeedEvent::Frame(f) = e {
                out.push(f)
            }
        });
        out
    }

    fn me(f: &RawFrame) -> u64 {
        u64::from_be_bytes([
            0,
            f.bytes()[4],
            f.bytes()[5],
            f.bytes()[6],
            f.bytes()[7],
            f.bytes()[8],
            f.bytes()[9],
            f.bytes()[10],
        ])
    }

    #[test]
    fn an_mlat_only_track_becomes_position_velocity_and_identification_squitters() {
        let sent = frames(&[Source::Mlat]);
        assert_eq!(sent.len(), 4, "even, odd, velocity, identification");
        for f in &sent {
            let b = f.bytes();
            assert_eq!((f.timestamp, f.signal, b.len()), (MLAT_TIMESTAMP, 0xFF, 14));
            assert_eq!((b[0] >> 3, b[0] & 7), (18, 2), "DF18, CF 2");
            assert_eq!(&b[1..4], &[0x3C, 0x6D, 0xD4]);
            assert_eq!(crc::syndrome(b), 0, "parity");
        }
        let cpr = |f: &RawFrame| {
            let m = me(f);
            assert_eq!(m >> 51, 18, "TC 18");
            cpr::CprFields {
                odd: (m >> 34) & 1 == 1,
                lat: ((m >> 17) & 0x1FFFF) as u32,
                lon: (m & 0x1FFFF) as u32,
            }
        };
        let (even, odd) = (cpr(&sent[0]), cpr(&sent[1]));
        assert!(!even.odd && odd.odd);
        let (lat, lon) = cpr::global_airborne(even, odd, true).unwrap();
        // A 17-bit CPR cell is about 5 m.
        assert!((lat - 43.5).abs() < 5e-5 && (lon - 1.25).abs() < 7e-5, "{lat} {lon}");
        let v = velocity::decode(me(&sent[2])).unwrap();
        // North-east at 100 m/s (194.4 kt), climbing 5 m/s (984 ft/min).
        assert_eq!(v.gs_kt().map(f64::round), Some(194.0));
        assert!((v.track_deg().unwrap() - 45.0).abs() < 0.5);
        assert!((v.vrate_fpm.unwrap() - 984).abs() <= 32, "{:?}", v.vrate_fpm);
        assert_eq!(me(&sent[3]) >> 51, 4, "identification, category set A");
    }

    #[test]
    fn aircraft_with_adsb_are_left_to_the_receiving_decoder() {
        assert!(frames(&[Source::Adsb, Source::Mlat]).is_empty());
        assert!(frames(&[Source::Adsb]).is_empty());
    }
}
