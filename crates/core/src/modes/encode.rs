//! Encoders for the frames fuse1090 synthesises (simulator, replay, tests):
//! DF17 ADS-B (identification, airborne and surface position with real CPR,
//! velocity, operational status, target state), DF11 all-call and the
//! address/parity replies DF0/4/5/16/20/21. Each is the exact inverse of the
//! decoder and is tested by round trip through it.

use super::cpr::CprFields;
use super::crc::syndrome;

/// Writes the parity of a DF11/17/18 frame (interrogator code `iid` for DF11).
pub fn set_parity(frame: &mut [u8], iid: u32) {
    set_address_parity(frame, iid);
}

/// Writes address/parity: CRC of the data XOR the address.
pub fn set_address_parity(frame: &mut [u8], addr: u32) {
    let n = frame.len();
    frame[n - 3..].fill(0);
    // With zero parity the syndrome is the CRC of the data.
    let p = syndrome(frame) ^ addr;
    frame[n - 3] = (p >> 16) as u8;
    frame[n - 2] = (p >> 8) as u8;
    frame[n - 1] = p as u8;
}

/// Feet to the 25 ft (Q=1) AC12 code; `None` outside -1000..=50175 ft.
pub fn ac12_q(alt_ft: i32) -> Option<u16> {
    let n = (alt_ft + 1000 + 12).div_euclid(25);
    if !(0..0x800).contains(&n) {
        return None;
    }
    let n = n as u16;
    Some(((n & 0x7F0) << 1) | 0x10 | (n & 0x0F))
}

/// Feet to the 25 ft AC13 code (M=0, Q=1).
pub fn ac13_q(alt_ft: i32) -> Option<u16> {
    let ac12 = ac12_q(alt_ft)?;
    Some(((ac12 & 0xFC0) << 1) | (ac12 & 0x3F))
}

/// Squawk given as 0xABCD octal digits to ID13.
pub fn id13(squawk: u16) -> u16 {
    let d = |shift: u16, bit: u16| (squawk >> shift >> bit) & 1;
    let (a, b, c, dd) = (12, 8, 4, 0);
    (d(c, 0) << 12)
        | (d(a, 0) << 11)
        | (d(c, 1) << 10)
        | (d(a, 1) << 9)
        | (d(c, 2) << 8)
        | (d(a, 2) << 7)
        | (d(b, 0) << 5)
        | (d(dd, 0) << 4)
        | (d(b, 1) << 3)
        | (d(dd, 1) << 2)
        | (d(b, 2) << 1)
        | d(dd, 2)
}

/// A DF17 frame from its address and ME field.
pub fn df17(ca: u8, addr: u32, me: u64) -> [u8; 14] {
    extended_squitter(17, ca, addr, me)
}

/// A DF18 frame (extended squitter from a non-transponder device: `cf` 2 is
/// fine TIS-B with an ICAO address, what multilateration results are sent as).
pub fn df18(cf: u8, addr: u32, me: u64) -> [u8; 14] {
    extended_squitter(18, cf, addr, me)
}

/// DF17 or DF18: the format, its 3-bit CA or CF, the address, ME, parity.
fn extended_squitter(df: u8, low3: u8, addr: u32, me: u64) -> [u8; 14] {
    let mut f = [0u8; 14];
    f[0] = (df << 3) | (low3 & 7);
    f[1..4].copy_from_slice(&addr.to_be_bytes()[1..]);
    f[4..11].copy_from_slice(&me.to_be_bytes()[1..]);
    set_parity(&mut f, 0);
    f
}

/// DF11 all-call reply.
pub fn df11(ca: u8, addr: u32, iid: u32) -> [u8; 7] {
    let mut f = [0u8; 7];
    f[0] = (11 << 3) | (ca & 7);
    f[1..4].copy_from_slice(&addr.to_be_bytes()[1..]);
    set_parity(&mut f, iid);
    f
}

/// DF0/4/16/20 (altitude) or DF5/21 (identity) reply with address/parity.
/// `code` is the 13-bit AC13 or ID13 field; `mb` the Comm-B field for DF20/21.
pub fn surveillance_reply(df: u8, fs: u8, code: u16, addr: u32, mb: Option<u64>) -> Vec<u8> {
    let long = df >= 16;
    let mut f = vec![0u8; if long { 14 } else { 7 }];
    f[0] = (df << 3) | (fs & 7);
    f[2] = ((code >> 8) & 0x1F) as u8;
    f[3] = code as u8;
    if let (true, Some(mb)) = (long, mb) {
        f[4..11].copy_from_slice(&mb.to_be_bytes()[1..]);
    }
    set_address_parity(&mut f, addr);
    f
}

fn callsign_code(c: u8) -> u64 {
    match c {
        b'A'..=b'Z' => (c - b'A' + 1) as u64,
        b'0'..=b'9' => (c - b'0' + 48) as u64,
        _ => 32,
    }
}

/// TC 1-4 identification; `category` as 0xA3 for "A3".
pub fn me_identification(category: u8, callsign: &str) -> u64 {
    let tc = (0x0E - (category >> 4)) as u64;
    let mut me = (tc << 51) | (((category & 7) as u64) << 48);
    let bytes = callsign.as_bytes();
    for i in 0..8 {
        me |= callsign_code(*bytes.get(i).unwrap_or(&b' ')) << (42 - 6 * i);
    }
    me
}

/// TC 9-18 (baro) or 20-22 (GNSS height) airborne position.
pub fn me_airborne_position(tc: u8, alt_ft: Option<i32>, nic_b: u8, cpr: CprFields) -> u64 {
    let alt = alt_ft.and_then(ac12_q).unwrap_or(0) as u64;
    ((tc as u64) << 51)
        | ((nic_b as u64 & 1) << 48)
        | (alt << 36)
        | ((cpr.odd as u64) << 34)
        | ((cpr.lat as u64) << 17)
        | cpr.lon as u64
}

/// TC 5-8 surface position; `movement` is the DO-260B movement code, `track_deg` when valid.
pub fn me_surface_position(tc: u8, movement: u8, track_deg: Option<f64>, cpr: CprFields) -> u64 {
    let (status, trk) = match track_deg {
        Some(t) => (1u64, ((t.rem_euclid(360.0) * 128.0 / 360.0).round() as u64) & 0x7F),
        None => (0, 0),
    };
    ((tc as u64) << 51)
        | ((movement as u64 & 0x7F) << 44)
        | (status << 43)
        | (trk << 36)
        | ((cpr.odd as u64) << 34)
        | ((cpr.lat as u64) << 17)
        | cpr.lon as u64
}

/// Ground speed (kt) to the surface movement code (DO-260B), the inverse of
/// the decoder's table: the code whose band holds the speed.
pub fn movement_code(kt: f64) -> u8 {
    let code = if kt < 0.125 {
        1.0
    } else if kt < 1.0 {
        2.0 + ((kt - 0.125) / 0.125).floor()
    } else if kt < 2.0 {
        9.0 + ((kt - 1.0) / 0.25).floor()
    } else if kt < 15.0 {
        13.0 + ((kt - 2.0) / 0.5).floor()
    } else if kt < 70.0 {
        39.0 + (kt - 15.0).floor()
    } else if kt < 100.0 {
        94.0 + ((kt - 70.0) / 2.0).floor()
    } else if kt < 175.0 {
        109.0 + ((kt - 100.0) / 5.0).floor()
    } else {
        124.0
    };
    code as u8
}

/// TC 19 subtype 1 (or 2 when supersonic) ground-speed velocity.
pub fn me_velocity(
    ve_kt: f64,
    vn_kt: f64,
    vrate_fpm: Option<i32>,
    vrate_baro: bool,
    nac_v: u8,
    gnss_baro_diff_ft: Option<i32>,
) -> u64 {
    let supersonic = ve_kt.abs() > 1021.0 || vn_kt.abs() > 1021.0;
    let scale = if supersonic { 4.0 } else { 1.0 };
    let comp = |v: f64| -> (u64, u64) {
        let n = ((v.abs() / scale).round() as u64 + 1).min(1023);
        ((v < 0.0) as u64, n)
    };
    let (sew, vew) = comp(ve_kt);
    let (sns, vns) = comp(vn_kt);
    let (svr, vr) = match vrate_fpm {
        Some(r) => ((r < 0) as u64, ((r.unsigned_abs() as f64 / 64.0).round() as u64 + 1).min(511)),
        None => (0, 0),
    };
    let subtype = if supersonic { 2 } else { 1 };
    let (sdiff, diff) = match gnss_baro_diff_ft {
        Some(d) => ((d < 0) as u64, ((d.unsigned_abs() as f64 / 25.0).round() as u64 + 1).min(127)),
        None => (0, 0),
    };
    (19u64 << 51)
        | (subtype << 48)
        | (((nac_v & 7) as u64) << 43)
        | (sew << 42)
        | (vew << 32)
        | (sns << 31)
        | (vns << 21)
        | ((vrate_baro as u64) << 20)
        | (svr << 19)
        | (vr << 10)
        | (sdiff << 7)
        | diff
}

/// TC 31 operational status (version 1 or 2 layout), airborne or surface.
pub fn me_operational_status(surface: bool, version: u8, nic_a: u8, nac_p: u8, sil: u8) -> u64 {
    (31u64 << 51)
        | ((surface as u64) << 48)
        | (((version & 7) as u64) << 13)
        | (((nic_a & 1) as u64) << 12)
        | (((nac_p & 15) as u64) << 8)
        | (((sil & 3) as u64) << 4)
}

/// TC 29 subtype 1 target state and status with NACp and SIL only.
pub fn me_target_state(nac_p: u8, sil: u8) -> u64 {
    (29u64 << 51) | (1u64 << 49) | (((nac_p & 15) as u64) << 13) | (((sil & 3) as u64) << 10)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modes::cpr::encode as cpr_encode;
    use crate::modes::fields::{callsign_str, decode_ac12, decode_ac13, decode_id13};
    use crate::modes::message::{decode, Body, Es, Parity};

    fn es(frame: &[u8]) -> Es {
        let m = decode(frame).unwrap();
        assert_eq!(m.parity, Parity::Ok);
        match m.body {
            Body::Extended(e) => e.kind,
            b => panic!("{b:?}"),
        }
    }

    #[test]
    fn altitude_and_squawk_codes_round_trip() {
        for ft in (-1000..50_000).step_by(25) {
            assert_eq!(decode_ac12(ac12_q(ft).unwrap()), Some(ft));
            assert_eq!(decode_ac13(ac13_q(ft).unwrap()), Some(ft));
        }
        for sq in [0x0000u16, 0x7700, 0x1200, 0x7777, 0x0421] {
            assert_eq!(decode_id13(id13(sq)), sq);
        }
    }

    #[test]
    fn df17_messages_round_trip() {
        let addr = 0xABC123;
        let Es::Identification { category, callsign } = es(&df17(5, addr, me_identification(0xA3, "TEST12")))
        else {
            panic!()
        };
        assert_eq!((category, callsign_str(&callsign)), (0xA3, "TEST12"));

        let cpr = cpr_encode(43.6, 1.36, true, false);
        let Es::AirbornePosition { alt_ft, cpr: c, nic_b, gnss, .. } =
            es(&df17(5, addr, me_airborne_position(11, Some(35_000), 1, cpr)))
        else {
            panic!()
        };
        assert_eq!((alt_ft, c, nic_b, gnss), (Some(35_000), cpr, 1, false));

        let cpr = cpr_encode(43.6, 1.36, false, true);
        let Es::SurfacePosition { movement_kt, track_deg, cpr: c } =
            es(&df17(5, addr, me_surface_position(7, 20, Some(90.0), cpr)))
        else {
            panic!()
        };
        assert_eq!((movement_kt, track_deg, c), (Some(5.5), Some(90.0), cpr));

        for (ve, vn, vr) in [(-120.0, 300.0, Some(-1280)), (0.0, -80.0, None), (1500.0, 400.0, Some(640))] {
            let Es::Velocity(v) = es(&df17(5, addr, me_velocity(ve, vn, vr, true, 2, Some(-150)))) else {
                panic!()
            };
            let step = if v.subtype == 2 { 4.0 } else { 1.0 };
            assert!((v.ve_kt.unwrap() - ve).abs() <= step && (v.vn_kt.unwrap() - vn).abs() <= step);
            assert_eq!((v.vrate_fpm, v.vrate_baro, v.nac_v), (vr, true, 2));
            assert_eq!(v.gnss_baro_diff_ft, Some(-150));
        }

        let Es::OperationalStatus(os) = es(&df17(5, addr, me_operational_status(false, 2, 1, 9, 3))) else {
            panic!()
        };
        assert_eq!((os.version, os.nic_a, os.nac_p, os.sil, os.subtype), (2, 1, 9, 3, 0));
        let Es::OperationalStatus(os) = es(&df17(5, addr, me_operational_status(true, 2, 0, 10, 3))) else {
            panic!()
        };
        assert_eq!((os.subtype, os.nac_p), (1, 10));
        for kt in [0.0, 0.5, 1.3, 7.2, 33.0, 85.0, 130.0, 200.0] {
            let code = movement_code(kt);
            let Es::SurfacePosition { movement_kt, .. } =
                es(&df17(5, addr, me_surface_position(7, code, None, cpr_encode(1.0, 1.0, false, true))))
            else {
                panic!()
            };
            let back = movement_kt.unwrap();
            // Code 124 is "175 kt or more".
            assert!(back <= kt && (kt - back < 5.0 || back == 175.0), "{kt} -> {code} -> {back}");
        }
        let Es::TargetState(ts) = es(&df17(5, addr, me_target_state(8, 2))) else { panic!() };
        assert_eq!((ts.nac_p, ts.sil), (8, 2));
    }

    #[test]
    fn replies_round_trip() {
        let addr = 0x4840D6;
        let m = decode(&df11(5, addr, 0)).unwrap();
        assert_eq!((m.addr, m.parity, m.body), (addr, Parity::Ok, Body::AllCall { ca: 5, iid: 0 }));
        let m = decode(&df11(5, addr, 3)).unwrap();
        assert_eq!(m.body, Body::AllCall { ca: 5, iid: 3 });
        for df in [0u8, 4, 16, 20] {
            let m = decode(&surveillance_reply(df, 0, ac13_q(12_300).unwrap(), addr, None)).unwrap();
            assert_eq!((m.df, m.addr, m.parity), (df, addr, Parity::AddressParity));
            let alt = match m.body {
                Body::AirAir { alt_ft, .. } | Body::Altitude { alt_ft, .. } => alt_ft,
                b => panic!("{b:?}"),
            };
            assert_eq!(alt, Some(12_300));
        }
        for df in [5u8, 21] {
            let m = decode(&surveillance_reply(df, 0, id13(0x7500), addr, Some(0x20 << 48))).unwrap();
            assert_eq!(m.addr, addr);
            assert!(matches!(m.body, Body::Identity { squawk: 0x7500, .. }));
        }
    }
}
