//! The Comm-B registers' layouts (ICAO Doc 9871, bits numbered 1-56 from the
//! MB field's most significant bit) and the structural test each one puts on
//! a 56-bit MB: a field whose status bit is clear must be all zero, reserved
//! bits must be zero, and a field that is set must lie in the range the
//! quantity can take. Passing the test means "could be this register", not
//! "is": several registers often fit one MB, and deciding between them is
//! [`super::infer`]'s job. Each parser returns `None` when the MB cannot be its
//! register, so a parse that succeeds is a candidate.

use crate::modes::fields::decode_callsign;
use crate::modes::message::me_bits;

/// Bits `first..=last` (1-56).
#[inline]
fn bits(mb: u64, first: u32, last: u32) -> u32 {
    me_bits(mb, first, last)
}

/// The value of a status-gated field: `None` when its status bit is clear,
/// `Err(())` when the status is clear but the field is not zero.
#[inline]
fn gated(mb: u64, status: u32, first: u32, last: u32) -> Result<Option<u32>, ()> {
    let v = bits(mb, first, last);
    match (bits(mb, status, status), v) {
        (1, v) => Ok(Some(v)),
        (_, 0) => Ok(None),
        _ => Err(()),
    }
}

/// A two's complement value: `sign` is the bit above the `width` magnitude bits.
#[inline]
fn signed(sign: u32, magnitude: u32, width: u32) -> i32 {
    magnitude as i32 - if sign == 1 { 1 << width } else { 0 }
}

/// A signed angle (sign bit, then `width` bits of 180/2^width degrees)
/// as degrees in [0, 360).
#[inline]
fn angle_deg(v: u32, width: u32) -> f64 {
    let deg = signed(v >> width, v & ((1 << width) - 1), width) as f64 * 180.0 / (1u32 << width) as f64;
    deg.rem_euclid(360.0)
}

/// BDS 1,0, data link capability: the first byte is 0x10 and bits 10-14 are reserved.
pub fn bds10(mb: u64) -> bool {
    bits(mb, 1, 8) == 0x10 && bits(mb, 10, 14) == 0
}

/// BDS 1,7, common-usage GICB capability: bits 1-24 say which registers the
/// transponder serves, bits 25-56 are reserved. Every transponder that has
/// the register serves aircraft identification (BDS 2,0, bit 7).
pub fn bds17(mb: u64) -> Option<u32> {
    (bits(mb, 25, 56) == 0 && bits(mb, 7, 7) == 1).then(|| bits(mb, 1, 24))
}

/// The registers a BDS 1,7 capability map names, bit 1 first.
pub const GICB_REGISTERS: [&str; 24] = [
    "0,5", "0,6", "0,7", "0,8", "0,9", "0,A", "2,0", "2,1", "4,0", "4,1", "4,2", "4,3", "4,4", "4,5", "4,8",
    "5,0", "5,1", "5,2", "5,3", "5,4", "5,5", "5,6", "5,F", "6,0",
];

/// BDS 2,0, aircraft identification: 0x20, then eight characters of the
/// ES alphabet, not all blank.
pub fn bds20(mb: u64) -> Option<[u8; 8]> {
    if bits(mb, 1, 8) != 0x20 {
        return None;
    }
    let cs = decode_callsign(mb);
    (!cs.contains(&b'#') && cs != [b' '; 8]).then_some(cs)
}

/// BDS 3,0, ACAS active resolution advisory: 0x30; the threat type (bits
/// 29-30) 3 is undefined, and with no threat (0) the identity field is zero.
pub fn bds30(mb: u64) -> bool {
    let tti = bits(mb, 29, 30);
    bits(mb, 1, 8) == 0x30 && tti != 3 && (tti != 0 || bits(mb, 31, 56) == 0)
}

/// BDS 4,0: selected vertical intention.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bds40 {
    pub mcp_alt_ft: Option<u32>,
    pub fms_alt_ft: Option<u32>,
    pub baro_setting_hpa: Option<f64>,
    /// VNAV, altitude hold, approach (when the mode bits' status is set).
    pub modes: Option<[bool; 3]>,
    /// Target altitude source: 0 unknown, 1 aircraft altitude, 2 MCP/FCU, 3 FMS.
    pub alt_source: Option<u8>,
}

/// Above this no autopilot lets a crew select an altitude.
const MAX_SELECTED_ALT_FT: u32 = 60_000;
/// Altimeter settings outside this are not pressures an altimeter is set to.
const BARO_SETTING_HPA: (f64, f64) = (850.0, 1100.0);

pub fn bds40(mb: u64) -> Option<Bds40> {
    if bits(mb, 40, 47) != 0 || bits(mb, 52, 53) != 0 {
        return None;
    }
    let mcp = gated(mb, 1, 2, 13).ok()?.map(|v| v * 16);
    let fms = gated(mb, 14, 15, 26).ok()?.map(|v| v * 16);
    let baro = gated(mb, 27, 28, 39).ok()?.map(|v| 800.0 + v as f64 * 0.1);
    let modes = gated(mb, 48, 49, 51).ok()?.map(|v| [v & 4 != 0, v & 2 != 0, v & 1 != 0]);
    let source = gated(mb, 54, 55, 56).ok()?.map(|v| v as u8);
    if mcp.is_none() && fms.is_none() && baro.is_none() {
        return None;
    }
    if mcp.into_iter().chain(fms).any(|a| a > MAX_SELECTED_ALT_FT)
        || baro.is_some_and(|b| !(BARO_SETTING_HPA.0..=BARO_SETTING_HPA.1).contains(&b))
    {
        return None;
    }
    Some(Bds40 { mcp_alt_ft: mcp, fms_alt_ft: fms, baro_setting_hpa: baro, modes, alt_source: source })
}

/// The range of static air temperatures in the atmosphere aircraft fly in.
const SAT_C: (f64, f64) = (-80.0, 60.0);

/// BDS 4,4: meteorological routine air report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bds44 {
    /// Figure of merit / source (0-4).
    pub source: u8,
    pub wind_kt: u32,
    pub wind_dir_deg: f64,
    pub sat_c: f64,
    pub pressure_hpa: Option<u32>,
    pub turbulence: Option<u8>,
    pub humidity_pct: Option<f64>,
}

pub fn bds44(mb: u64) -> Option<Bds44> {
    let source = bits(mb, 1, 4);
    // A routine report without its wind is not one (the wind is its purpose).
    if source > 4 || bits(mb, 5, 5) != 1 {
        return None;
    }
    let wind_kt = bits(mb, 6, 14);
    let sat_c = signed(bits(mb, 24, 24), bits(mb, 25, 34), 10) as f64 * 0.25;
    let pressure_hpa = gated(mb, 35, 36, 46).ok()?;
    let turbulence = gated(mb, 47, 48, 49).ok()?.map(|v| v as u8);
    let humidity_pct = gated(mb, 50, 51, 56).ok()?.map(|v| v as f64 * 100.0 / 64.0);
    if wind_kt > 250 || !(SAT_C.0..=SAT_C.1).contains(&sat_c) {
        return None;
    }
    Some(Bds44 {
        source: source as u8,
        wind_kt,
        wind_dir_deg: bits(mb, 15, 23) as f64 * 180.0 / 256.0,
        sat_c,
        pressure_hpa,
        turbulence,
        humidity_pct,
    })
}

/// BDS 4,5: meteorological hazard report (hazard levels 0 nil to 3 severe).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bds45 {
    pub turbulence: Option<u8>,
    pub wind_shear: Option<u8>,
    pub microburst: Option<u8>,
    pub icing: Option<u8>,
    pub wake_vortex: Option<u8>,
    pub sat_c: Option<f64>,
    pub pressure_hpa: Option<u32>,
    pub radio_height_ft: Option<u32>,
}

pub fn bds45(mb: u64) -> Option<Bds45> {
    if bits(mb, 52, 56) != 0 {
        return None;
    }
    let level = |status| gated(mb, status, status + 1, status + 2).map(|v| v.map(|v| v as u8));
    let r = Bds45 {
        turbulence: level(1).ok()?,
        wind_shear: level(4).ok()?,
        microburst: level(7).ok()?,
        icing: level(10).ok()?,
        wake_vortex: level(13).ok()?,
        sat_c: gated(mb, 16, 17, 26).ok()?.map(|v| signed(v >> 9, v & 0x1FF, 9) as f64 * 0.25),
        pressure_hpa: gated(mb, 27, 28, 38).ok()?,
        radio_height_ft: gated(mb, 39, 40, 51).ok()?.map(|v| v * 16),
    };
    if mb == 0 || r.sat_c.is_some_and(|t| !(SAT_C.0..=SAT_C.1).contains(&t)) {
        return None;
    }
    Some(r)
}

/// BDS 5,0: track and turn report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bds50 {
    pub roll_deg: Option<f64>,
    pub track_deg: Option<f64>,
    pub gs_kt: Option<u32>,
    pub track_rate_dps: Option<f64>,
    pub tas_kt: Option<u32>,
}

/// Bank angles beyond this are aerobatics, not the aircraft Mode S serves.
const MAX_ROLL_DEG: f64 = 50.0;
/// Ground speed: the fastest airliner's true airspeed plus a jet stream.
const MAX_GS_KT: u32 = 700;
const MAX_TAS_KT: u32 = 600;
/// The largest wind an aircraft meets: true airspeed and ground speed differ by no more.
const MAX_WIND_KT: u32 = 250;

pub fn bds50(mb: u64) -> Option<Bds50> {
    let r = Bds50 {
        roll_deg: gated(mb, 1, 2, 11).ok()?.map(|v| signed(v >> 9, v & 0x1FF, 9) as f64 * 45.0 / 256.0),
        track_deg: gated(mb, 12, 13, 23).ok()?.map(|v| angle_deg(v, 10)),
        gs_kt: gated(mb, 24, 25, 34).ok()?.map(|v| v * 2),
        track_rate_dps: gated(mb, 35, 36, 45)
            .ok()?
            .map(|v| signed(v >> 9, v & 0x1FF, 9) as f64 * 8.0 / 256.0),
        tas_kt: gated(mb, 46, 47, 56).ok()?.map(|v| v * 2),
    };
    if mb == 0
        || r.roll_deg.is_some_and(|x| x.abs() > MAX_ROLL_DEG)
        || r.gs_kt.is_some_and(|x| x > MAX_GS_KT)
        || r.tas_kt.is_some_and(|x| x > MAX_TAS_KT)
        || matches!((r.gs_kt, r.tas_kt), (Some(g), Some(a)) if g.abs_diff(a) > MAX_WIND_KT)
    {
        return None;
    }
    Some(r)
}

/// BDS 6,0: heading and speed report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bds60 {
    pub mag_heading_deg: Option<f64>,
    pub ias_kt: Option<u32>,
    pub mach: Option<f64>,
    pub baro_rate_fpm: Option<i32>,
    pub inertial_rate_fpm: Option<i32>,
}

const MAX_IAS_KT: u32 = 500;
const MAX_MACH: f64 = 1.0;
const MAX_VRATE_FPM: i32 = 6000;

pub fn bds60(mb: u64) -> Option<Bds60> {
    let rate = |v: u32| signed(v >> 9, v & 0x1FF, 9) * 32;
    let r = Bds60 {
        mag_heading_deg: gated(mb, 1, 2, 12).ok()?.map(|v| angle_deg(v, 10)),
        ias_kt: gated(mb, 13, 14, 23).ok()?,
        mach: gated(mb, 24, 25, 34).ok()?.map(|v| v as f64 * 2.048 / 512.0),
        baro_rate_fpm: gated(mb, 35, 36, 45).ok()?.map(rate),
        inertial_rate_fpm: gated(mb, 46, 47, 56).ok()?.map(rate),
    };
    if mb == 0
        || r.ias_kt.is_some_and(|x| x > MAX_IAS_KT)
        || r.mach.is_some_and(|x| x > MAX_MACH)
        || r.baro_rate_fpm.into_iter().chain(r.inertial_rate_fpm).any(|x| x.abs() > MAX_VRATE_FPM)
    {
        return None;
    }
    Some(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mb(hex: &str) -> u64 {
        u64::from_str_radix(hex, 16).unwrap()
    }

    // The MB fields of the worked examples in "The 1090 MHz Riddle" (Comm-B
    // chapter), whose values pyModeS reproduces.
    #[test]
    fn track_and_turn() {
        let r = bds50(mb("81951536E024D4")).unwrap();
        assert!((r.roll_deg.unwrap() - 2.109375).abs() < 1e-9);
        assert!((r.track_deg.unwrap() - 114.2578125).abs() < 1e-9);
        assert_eq!(r.gs_kt, Some(438));
        assert!((r.track_rate_dps.unwrap() - 0.125).abs() < 1e-9);
        assert_eq!(r.tas_kt, Some(424));
    }

    #[test]
    fn heading_and_speed() {
        let r = bds60(mb("8F39F91A7E27C4")).unwrap();
        assert!((r.mag_heading_deg.unwrap() - 42.71484375).abs() < 1e-9);
        assert_eq!(r.ias_kt, Some(252));
        assert!((r.mach.unwrap() - 0.42).abs() < 1e-9);
        assert_eq!(r.baro_rate_fpm, Some(-1920));
        assert_eq!(r.inertial_rate_fpm, Some(-1920));
    }

    #[test]
    fn selected_vertical_intention() {
        let r = bds40(mb("85E42F31300000")).unwrap();
        assert_eq!(r.mcp_alt_ft, Some(3008));
        assert_eq!(r.fms_alt_ft, Some(3008));
        assert!((r.baro_setting_hpa.unwrap() - 1020.0).abs() < 1e-9);
        assert_eq!(r.alt_source, None);
        assert_eq!(&bds20(mb("201584F2346820")).unwrap(), b"EXS2MF  ");
    }

    #[test]
    fn a_set_field_without_its_status_is_not_the_register() {
        // Bit 1 (the roll's status) clear, bit 11 (part of the roll) set.
        assert_eq!(bds50(1 << (56 - 11)), None);
        // Reserved bits of BDS 4,0 set.
        assert_eq!(bds40((1 << 55) | (1 << (56 - 45))), None);
        assert!(bds17(mb("FA81C100000000")).is_some());
        assert!(bds17(mb("FA81C100000001")).is_none());
    }
}
