//! TC 19 airborne velocity, subtypes 1-4: ground speed components (subsonic
//! and supersonic), or heading and airspeed; vertical rate with its source;
//! the GNSS-baro altitude difference; NACv.

use super::message::me_bits;

#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Velocity {
    pub subtype: u8,
    pub nac_v: u8,
    /// East and north ground speed components (kt), subtypes 1-2.
    pub ve_kt: Option<f64>,
    pub vn_kt: Option<f64>,
    /// Heading (deg) and airspeed (kt), subtypes 3-4.
    pub heading_deg: Option<f64>,
    pub airspeed_kt: Option<u16>,
    pub airspeed_is_tas: bool,
    /// Vertical rate (ft/min) and whether it is barometric (else GNSS).
    pub vrate_fpm: Option<i32>,
    pub vrate_baro: bool,
    /// GNSS height minus barometric altitude (ft).
    pub gnss_baro_diff_ft: Option<i32>,
}

impl Velocity {
    pub fn gs_kt(&self) -> Option<f64> {
        Some(self.ve_kt?.hypot(self.vn_kt?))
    }

    /// Track over ground (deg, 0-360).
    pub fn track_deg(&self) -> Option<f64> {
        let (ve, vn) = (self.ve_kt?, self.vn_kt?);
        if ve == 0.0 && vn == 0.0 {
            return None;
        }
        Some(ve.atan2(vn).to_degrees().rem_euclid(360.0))
    }
}

pub fn decode(me: u64) -> Option<Velocity> {
    let subtype = me_bits(me, 6, 8) as u8;
    if !(1..=4).contains(&subtype) {
        return None;
    }
    let scale = if subtype == 2 || subtype == 4 { 4.0 } else { 1.0 };
    let mut v = Velocity { subtype, nac_v: me_bits(me, 11, 13) as u8, ..Default::default() };
    if subtype <= 2 {
        let ew = me_bits(me, 15, 24);
        let ns = me_bits(me, 26, 35);
        if ew != 0 && ns != 0 {
            let sign = |neg: u32| if neg == 1 { -1.0 } else { 1.0 };
            v.ve_kt = Some(sign(me_bits(me, 14, 14)) * (ew - 1) as f64 * scale);
            v.vn_kt = Some(sign(me_bits(me, 25, 25)) * (ns - 1) as f64 * scale);
        }
    } else {
        if me_bits(me, 14, 14) == 1 {
            v.heading_deg = Some(me_bits(me, 15, 24) as f64 * 360.0 / 1024.0);
        }
        let asp = me_bits(me, 26, 35);
        if asp != 0 {
            v.airspeed_kt = Some(((asp - 1) as f64 * scale) as u16);
            v.airspeed_is_tas = me_bits(me, 25, 25) == 1;
        }
    }
    v.vrate_baro = me_bits(me, 36, 36) == 1;
    let vr = me_bits(me, 38, 46);
    if vr != 0 {
        let sign = if me_bits(me, 37, 37) == 1 { -1 } else { 1 };
        v.vrate_fpm = Some(sign * (vr as i32 - 1) * 64);
    }
    let diff = me_bits(me, 50, 56);
    if diff != 0 {
        let sign = if me_bits(me, 49, 49) == 1 { -1 } else { 1 };
        v.gnss_baro_diff_ft = Some(sign * (diff as i32 - 1) * 25);
    }
    Some(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modes::message::me_of;

    #[test]
    fn ground_speed_subtype_1() {
        // Published example: 8D485020994409940838175B284F -> 159 kt, 182.88 deg, -832 ft/min.
        let v = decode(me_of("8D485020994409940838175B284F")).unwrap();
        assert_eq!(v.subtype, 1);
        assert!((v.gs_kt().unwrap() - 159.20).abs() < 0.01);
        assert!((v.track_deg().unwrap() - 182.88).abs() < 0.01);
        assert_eq!(v.vrate_fpm, Some(-832));
        assert!(!v.vrate_baro);
        assert_eq!(v.gnss_baro_diff_ft, Some(550));
    }

    #[test]
    fn supersonic_airspeed_subtype_4() {
        // Subtype 4: airspeed in 4 kt steps; 0x12C (300) -> (300 - 1) * 4 kt IAS.
        let me =
            (19u64 << 51) | (4 << 48) | (1 << 42) | (0x100 << 32) | (0x12C << 21) | (1 << 20) | (17 << 10);
        let v = decode(me).unwrap();
        assert_eq!((v.subtype, v.airspeed_kt, v.airspeed_is_tas), (4, Some(1196), false));
        assert_eq!(v.heading_deg, Some(90.0));
        assert_eq!(v.vrate_fpm, Some(1024));
    }

    #[test]
    fn airspeed_subtype_3() {
        // Published example: 8DA05F219B06B6AF189400CBC33F -> 375 kt TAS, 243.98 deg, -2304 ft/min.
        let v = decode(me_of("8DA05F219B06B6AF189400CBC33F")).unwrap();
        assert_eq!(v.subtype, 3);
        assert_eq!(v.airspeed_kt, Some(375));
        assert!(v.airspeed_is_tas);
        assert!((v.heading_deg.unwrap() - 243.98).abs() < 0.01);
        assert_eq!(v.vrate_fpm, Some(-2304));
        assert!(v.vrate_baro);
    }
}
