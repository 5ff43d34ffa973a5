//! Stateless decoding of one Mode S frame into a [`Message`].
//!
//! This is the hot path: no allocation, no state, one CRC per frame. Anything
//! that needs memory of earlier frames (error correction against known
//! addresses, CPR pairing, NIC supplements) is the stateful
//! [`Decoder`](super::Decoder)'s job.

use super::cpr::CprFields;
use super::crc::syndrome;
use super::fields::{decode_ac12, decode_ac13, decode_callsign, decode_id13};
use super::status::{decode_operational_status, decode_target_state, OperationalStatus, TargetState};
use super::velocity::{self, Velocity};

/// Bits `first..=last` of a 56-bit ME field, numbered 1-56 from the MSB as in DO-260B.
#[inline]
pub fn me_bits(me: u64, first: u32, last: u32) -> u32 {
    ((me >> (56 - last)) & ((1u64 << (last - first + 1)) - 1)) as u32
}

/// The parity verdict.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Parity {
    /// DF11/17/18 with parity that checks out (DF11: possibly overlaid by an interrogator code).
    Ok,
    /// DF17/18 repaired by flipping this bit (only ever done by the stateful decoder).
    Corrected(u8),
    /// DF11/17/18 whose parity does not check out.
    Bad,
    /// Address/parity reply: the address is recovered, not verified.
    AddressParity,
}

/// One decoded frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Message {
    pub df: u8,
    /// Announced address (DF11/17/18) or address recovered from the parity.
    pub addr: u32,
    pub parity: Parity,
    /// The raw syndrome (interrogator code for DF11).
    pub syndrome: u32,
    pub body: Body,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Body {
    /// DF0 short and DF16 long air-air surveillance.
    AirAir { vs: u8, alt_ft: Option<i32> },
    /// DF4 and DF20 altitude replies (DF20 carries a Comm-B MB field too).
    Altitude { fs: u8, alt_ft: Option<i32>, mb: Option<u64> },
    /// DF5 and DF21 identity replies.
    Identity { fs: u8, squawk: u16, mb: Option<u64> },
    /// DF11 all-call reply.
    AllCall { ca: u8, iid: u8 },
    /// DF17, and DF18 in the ADS-B/ADS-R/TIS-B fine formats.
    Extended(Extended),
    /// Parity bad (DF11/17/18), or a format we do not decode (DF19, DF24...).
    Undecoded,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extended {
    /// DF17 capability, or DF18 control field.
    pub ca_cf: u8,
    /// The address is not an ICAO 24-bit address (DF18 CF 1 and 5).
    pub non_icao: bool,
    pub tc: u8,
    pub me: u64,
    pub kind: Es,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Es {
    Identification {
        category: u8,
        callsign: [u8; 8],
    },
    SurfacePosition {
        movement_kt: Option<f64>,
        track_deg: Option<f64>,
        cpr: CprFields,
    },
    AirbornePosition {
        alt_ft: Option<i32>,
        gnss: bool,
        ss: u8,
        nic_b: u8,
        cpr: CprFields,
    },
    Velocity(Velocity),
    /// TC 28 subtype 1.
    Emergency {
        state: u8,
        squawk: u16,
    },
    TargetState(TargetState),
    OperationalStatus(OperationalStatus),
    /// A type code we recognise but do not decode further (TC 0, 23-27, 28/2 ...).
    Other,
}

/// Why a frame could not be decoded at all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// Mode A/C or a length that is not 56/112 bits.
    NotModeS,
    /// The DF does not match the frame length.
    WrongLength,
}

#[inline]
fn be_u64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0u64, |acc, &b| (acc << 8) | b as u64)
}

#[inline]
fn addr_of(b: &[u8]) -> u32 {
    ((b[1] as u32) << 16) | ((b[2] as u32) << 8) | b[3] as u32
}

/// Decodes one frame. Parity is checked but nothing is corrected.
pub fn decode(frame: &[u8]) -> Result<Message, FrameError> {
    let n = frame.len();
    if n != 7 && n != 14 {
        return Err(FrameError::NotModeS);
    }
    let df = if frame[0] >> 3 >= 24 { 24 } else { frame[0] >> 3 };
    let expect_long = df >= 16;
    if expect_long != (n == 14) {
        return Err(FrameError::WrongLength);
    }
    let syn = syndrome(frame);
    let ac13 = || (((frame[2] & 0x1F) as u16) << 8) | frame[3] as u16;
    let mb = || (n == 14).then(|| be_u64(&frame[4..11]));
    let ap = |body| Message { df, addr: syn, parity: Parity::AddressParity, syndrome: syn, body };
    Ok(match df {
        0 | 16 => ap(Body::AirAir { vs: (frame[0] >> 2) & 1, alt_ft: decode_ac13(ac13()) }),
        4 | 20 => ap(Body::Altitude { fs: frame[0] & 7, alt_ft: decode_ac13(ac13()), mb: mb() }),
        5 | 21 => ap(Body::Identity { fs: frame[0] & 7, squawk: decode_id13(ac13()), mb: mb() }),
        11 => {
            let ok = syn < 0x80;
            Message {
                df,
                addr: addr_of(frame),
                parity: if ok { Parity::Ok } else { Parity::Bad },
                syndrome: syn,
                body: if ok { Body::AllCall { ca: frame[0] & 7, iid: syn as u8 } } else { Body::Undecoded },
            }
        }
        17 | 18 => {
            let ok = syn == 0;
            Message {
                df,
                addr: addr_of(frame),
                parity: if ok { Parity::Ok } else { Parity::Bad },
                syndrome: syn,
                body: if ok { extended_body(frame) } else { Body::Undecoded },
            }
        }
        _ => Message { df, addr: syn, parity: Parity::AddressParity, syndrome: syn, body: Body::Undecoded },
    })
}

/// The ES part of a DF17/18 frame whose parity is good (or was corrected).
pub fn extended_body(frame: &[u8]) -> Body {
    let df = frame[0] >> 3;
    let ca_cf = frame[0] & 7;
    // DF18: CF 0/1 ADS-B, 2/5 TIS-B fine, 6 ADS-R share the DF17 ME formats.
    if df == 18 && !matches!(ca_cf, 0 | 1 | 2 | 5 | 6) {
        return Body::Undecoded;
    }
    let me = be_u64(&frame[4..11]);
    let tc = (me >> 51) as u8;
    Body::Extended(Extended {
        ca_cf,
        non_icao: df == 18 && matches!(ca_cf, 1 | 5),
        tc,
        me,
        kind: decode_me(tc, me),
    })
}

fn decode_me(tc: u8, me: u64) -> Es {
    let cpr =
        || CprFields { odd: me_bits(me, 22, 22) == 1, lat: me_bits(me, 23, 39), lon: me_bits(me, 40, 56) };
    match tc {
        1..=4 => Es::Identification {
            // "A3" style: set A-D from the type code, number from the CA sub-field.
            category: ((0x0E - tc) << 4) | me_bits(me, 6, 8) as u8,
            callsign: decode_callsign(me),
        },
        5..=8 => Es::SurfacePosition {
            movement_kt: movement(me_bits(me, 6, 12) as u8),
            track_deg: (me_bits(me, 13, 13) == 1).then(|| me_bits(me, 14, 20) as f64 * 360.0 / 128.0),
            cpr: cpr(),
        },
        9..=18 | 20..=22 => Es::AirbornePosition {
            alt_ft: decode_ac12(me_bits(me, 9, 20) as u16),
            gnss: tc >= 20,
            ss: me_bits(me, 6, 7) as u8,
            nic_b: me_bits(me, 8, 8) as u8,
            cpr: cpr(),
        },
        19 => velocity::decode(me).map_or(Es::Other, Es::Velocity),
        28 if me_bits(me, 6, 8) == 1 => {
            Es::Emergency { state: me_bits(me, 9, 11) as u8, squawk: decode_id13(me_bits(me, 12, 24) as u16) }
        }
        29 => decode_target_state(me).map_or(Es::Other, Es::TargetState),
        31 => decode_operational_status(me).map_or(Es::Other, Es::OperationalStatus),
        _ => Es::Other,
    }
}

/// Surface movement code to ground speed (kt), DO-260B table 2-14.
fn movement(code: u8) -> Option<f64> {
    let c = code as f64;
    Some(match code {
        1 => 0.0,
        2..=8 => 0.125 + (c - 2.0) * 0.125,
        9..=12 => 1.0 + (c - 9.0) * 0.25,
        13..=38 => 2.0 + (c - 13.0) * 0.5,
        39..=93 => 15.0 + (c - 39.0),
        94..=108 => 70.0 + (c - 94.0) * 2.0,
        109..=123 => 100.0 + (c - 109.0) * 5.0,
        124 => 175.0,
        _ => return None,
    })
}

#[cfg(test)]
pub(crate) fn me_of(hex: &str) -> u64 {
    u64::from_str_radix(&hex[8..22], 16).unwrap()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes(hex: &str) -> Vec<u8> {
        (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap()).collect()
    }

    #[test]
    fn identification() {
        let m = decode(&bytes("8D4840D6202CC371C32CE0576098")).unwrap();
        assert_eq!((m.df, m.addr, m.parity), (17, 0x4840D6, Parity::Ok));
        let Body::Extended(es) = m.body else { panic!() };
        assert_eq!(es.tc, 4);
        let Es::Identification { category, callsign } = es.kind else { panic!() };
        assert_eq!(&callsign, b"KLM1023 ");
        assert_eq!(category, 0xA0);
    }

    #[test]
    fn airborne_position() {
        let m = decode(&bytes("8D40621D58C382D690C8AC2863A7")).unwrap();
        let Body::Extended(es) = m.body else { panic!() };
        let Es::AirbornePosition { alt_ft, cpr, gnss, .. } = es.kind else { panic!() };
        assert_eq!(alt_ft, Some(38000));
        assert!(!gnss);
        assert_eq!(cpr, CprFields { odd: false, lat: 93000, lon: 51372 });
    }

    #[test]
    fn address_parity_and_all_call() {
        let m = decode(&bytes("A00015B7C26E1370AA00005DD34A")).unwrap();
        assert_eq!((m.df, m.addr, m.parity), (20, 0x4D010D, Parity::AddressParity));
        let m = decode(&bytes("5D4840D61F3A2B")).unwrap();
        assert_eq!(m.df, 11);
        // From the beastblackbox capture: a clean DF11 all-call with IID 0.
        let m = decode(&bytes("5F4001594B0FBB")).unwrap();
        assert_eq!((m.addr, m.parity), (0x400159, Parity::Ok));
        assert_eq!(m.body, Body::AllCall { ca: 7, iid: 0 });
    }

    #[test]
    fn altitude_and_identity_replies() {
        // DF0 from the capture: 31000 ft for 780C5D.
        let m = decode(&bytes("02E1941026BC90")).unwrap();
        assert_eq!((m.df, m.addr), (0, 0x780C5D));
        assert_eq!(m.body, Body::AirAir { vs: 0, alt_ft: Some(31000) });
    }

    #[test]
    fn emergency_status() {
        // From the beastblackbox capture: TC 28/1, no emergency, squawk 1017.
        let m = decode(&bytes("8F400159E1181500000000D94095")).unwrap();
        let Body::Extended(es) = m.body else { panic!() };
        assert_eq!(es.kind, Es::Emergency { state: 0, squawk: 0x1017 });
    }

    #[test]
    fn df18_control_field() {
        use crate::modes::encode::set_parity;
        let mut f = bytes("8D4840D6202CC371C32CE0576098");
        for (cf, decoded, non_icao) in
            [(0, true, false), (1, true, true), (2, true, false), (3, false, false), (6, true, false)]
        {
            f[0] = (18 << 3) | cf;
            set_parity(&mut f, 0);
            let m = decode(&f).unwrap();
            assert_eq!((m.df, m.parity), (18, Parity::Ok));
            match m.body {
                Body::Extended(es) => {
                    assert!(decoded, "CF {cf}");
                    assert_eq!(es.non_icao, non_icao);
                    assert!(matches!(es.kind, Es::Identification { .. }));
                }
                _ => assert!(!decoded, "CF {cf}"),
            }
        }
    }

    #[test]
    fn gnss_height_position() {
        use crate::modes::encode::{df17, me_airborne_position};
        let cpr = crate::modes::cpr::encode(10.0, 20.0, false, false);
        let m = decode(&df17(5, 0x123456, me_airborne_position(20, Some(11_975), 0, cpr))).unwrap();
        let Body::Extended(es) = m.body else { panic!() };
        assert!(matches!(es.kind, Es::AirbornePosition { alt_ft: Some(11_975), gnss: true, .. }));
    }

    #[test]
    fn length_mismatch_and_mode_ac() {
        assert_eq!(decode(&bytes("8D4840D61F3A2B")), Err(FrameError::WrongLength));
        assert_eq!(decode(&bytes("2000")), Err(FrameError::NotModeS));
    }

    #[test]
    fn surface_movement_table_is_monotonic() {
        let mut last = -1.0;
        for code in 1..=124 {
            let v = movement(code).unwrap();
            assert!(v > last || code == 1);
            last = v;
        }
        assert_eq!(movement(0), None);
        assert_eq!(movement(125), None);
    }
}
