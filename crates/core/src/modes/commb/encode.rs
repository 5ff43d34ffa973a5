//! Comm-B registers written from values (the simulator's replies), the
//! inverse of [`super::registers`]: each field rounded to the register's
//! step, its status bit set when the value is given. Round trips through the
//! parsers are tested below.

use super::registers::{Bds40, Bds50, Bds60};

/// `v` into bits `first..=last` (1-56) of an MB field.
fn put(mb: &mut u64, first: u32, last: u32, v: u64) {
    let width = last - first + 1;
    *mb |= (v & ((1 << width) - 1)) << (56 - last);
}

/// A gated field: status bit, then `value` in the following bits.
fn gated(mb: &mut u64, status: u32, last: u32, value: Option<u64>) {
    if let Some(v) = value {
        put(mb, status, status, 1);
        put(mb, status + 1, last, v);
    }
}

/// Two's complement in `bits` bits of `x / step`, rounded.
fn twos(x: f64, step: f64, bits: u32) -> u64 {
    ((x / step).round() as i64).rem_euclid(1 << bits) as u64
}

/// An angle in degrees as the registers' sign + 10 bits (90/512 deg steps).
fn angle(deg: f64) -> u64 {
    let d = (deg + 180.0).rem_euclid(360.0) - 180.0;
    twos(d, 90.0 / 512.0, 11)
}

pub fn bds40(r: &Bds40) -> u64 {
    let mut mb = 0;
    gated(&mut mb, 1, 13, r.mcp_alt_ft.map(|a| (a as f64 / 16.0).round() as u64));
    gated(&mut mb, 14, 26, r.fms_alt_ft.map(|a| (a as f64 / 16.0).round() as u64));
    gated(&mut mb, 27, 39, r.baro_setting_hpa.map(|b| ((b - 800.0) / 0.1).round() as u64));
    gated(&mut mb, 48, 51, r.modes.map(|[v, h, a]| (v as u64) << 2 | (h as u64) << 1 | a as u64));
    gated(&mut mb, 54, 56, r.alt_source.map(u64::from));
    mb
}

pub fn bds50(r: &Bds50) -> u64 {
    let mut mb = 0;
    gated(&mut mb, 1, 11, r.roll_deg.map(|x| twos(x, 45.0 / 256.0, 10)));
    gated(&mut mb, 12, 23, r.track_deg.map(angle));
    gated(&mut mb, 24, 34, r.gs_kt.map(|v| (v / 2) as u64));
    gated(&mut mb, 35, 45, r.track_rate_dps.map(|x| twos(x, 8.0 / 256.0, 10)));
    gated(&mut mb, 46, 56, r.tas_kt.map(|v| (v / 2) as u64));
    mb
}

pub fn bds60(r: &Bds60) -> u64 {
    let mut mb = 0;
    gated(&mut mb, 1, 12, r.mag_heading_deg.map(angle));
    gated(&mut mb, 13, 23, r.ias_kt.map(u64::from));
    gated(&mut mb, 24, 34, r.mach.map(|m| (m / (2.048 / 512.0)).round() as u64));
    gated(&mut mb, 35, 45, r.baro_rate_fpm.map(|x| twos(x as f64, 32.0, 10)));
    gated(&mut mb, 46, 56, r.inertial_rate_fpm.map(|x| twos(x as f64, 32.0, 10)));
    mb
}

#[cfg(test)]
mod tests {
    use super::super::registers;
    use super::*;

    #[test]
    fn registers_round_trip() {
        let r40 = Bds40 {
            mcp_alt_ft: Some(35_008),
            fms_alt_ft: None,
            baro_setting_hpa: Some(1013.2),
            modes: Some([true, false, false]),
            alt_source: Some(2),
        };
        let back = registers::bds40(bds40(&r40)).unwrap();
        assert_eq!(
            (back.mcp_alt_ft, back.modes, back.alt_source),
            (r40.mcp_alt_ft, r40.modes, r40.alt_source)
        );
        assert!((back.baro_setting_hpa.unwrap() - 1013.2).abs() < 1e-6);
        // The worked examples' MBs, written again from their values.
        assert_eq!(bds50(&registers::bds50(0x81951536E024D4).unwrap()), 0x81951536E024D4);
        assert_eq!(bds60(&registers::bds60(0x8F39F91A7E27C4).unwrap()), 0x8F39F91A7E27C4);
        for (roll, track, rate) in [(-25.0, 359.9, -3.0), (30.0, 181.0, 2.5), (0.0, 0.0, 0.0)] {
            let r = Bds50 {
                roll_deg: Some(roll),
                track_deg: Some(track),
                gs_kt: Some(450),
                track_rate_dps: Some(rate),
                tas_kt: Some(430),
            };
            let b = registers::bds50(bds50(&r)).unwrap();
            assert!((b.roll_deg.unwrap() - roll).abs() <= 45.0 / 512.0);
            let dt = (b.track_deg.unwrap() - track).rem_euclid(360.0);
            assert!(dt.min(360.0 - dt) <= 90.0 / 1024.0, "{track} -> {b:?}");
            assert!((b.track_rate_dps.unwrap() - rate).abs() <= 4.0 / 256.0);
        }
        let r = Bds60 {
            mag_heading_deg: Some(271.3),
            ias_kt: Some(280),
            mach: Some(0.78),
            baro_rate_fpm: Some(-1504),
            inertial_rate_fpm: Some(-1472),
        };
        let b = registers::bds60(bds60(&r)).unwrap();
        assert_eq!(
            (b.ias_kt, b.baro_rate_fpm, b.inertial_rate_fpm),
            (r.ias_kt, r.baro_rate_fpm, r.inertial_rate_fpm)
        );
        assert!(
            (b.mach.unwrap() - 0.78).abs() <= 0.002 && (b.mag_heading_deg.unwrap() - 271.3).abs() <= 0.09
        );
    }
}
