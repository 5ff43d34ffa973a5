//! TC 29 target state and status, and TC 31 aircraft operational status: the
//! messages that carry version, NACp, SIL, GVA and the NIC supplements that
//! the position messages need.

use super::message::me_bits;

#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct TargetState {
    /// 0 = DO-260A layout, 1 = DO-260B layout.
    pub subtype: u8,
    pub nac_p: u8,
    pub nic_baro: u8,
    pub sil: u8,
    /// Selected altitude (ft; MCP/FCU or FMS), subtype 1 only.
    pub selected_alt_ft: Option<i32>,
    /// Barometric pressure setting (hPa), subtype 1 only.
    pub baro_setting_hpa: Option<f64>,
    /// Selected heading (deg), subtype 1 only.
    pub selected_heading_deg: Option<f64>,
}

pub fn decode_target_state(me: u64) -> Option<TargetState> {
    let subtype = me_bits(me, 6, 7) as u8;
    if subtype > 1 {
        return None;
    }
    let mut ts = TargetState {
        subtype,
        nac_p: me_bits(me, 40, 43) as u8,
        nic_baro: me_bits(me, 44, 44) as u8,
        sil: me_bits(me, 45, 46) as u8,
        ..Default::default()
    };
    if subtype == 1 {
        let alt = me_bits(me, 10, 20);
        if alt != 0 {
            ts.selected_alt_ft = Some((alt as i32 - 1) * 32);
        }
        let baro = me_bits(me, 21, 29);
        if baro != 0 {
            ts.baro_setting_hpa = Some(800.0 + (baro - 1) as f64 * 0.8);
        }
        if me_bits(me, 30, 30) == 1 {
            ts.selected_heading_deg = Some(me_bits(me, 31, 39) as f64 * 180.0 / 256.0);
        }
    }
    Some(ts)
}

#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct OperationalStatus {
    /// 0 airborne, 1 surface.
    pub subtype: u8,
    pub version: u8,
    /// NIC supplement A (version 2) or the single supplement (version 1).
    pub nic_a: u8,
    /// NIC supplement C (surface, version 2).
    pub nic_c: u8,
    pub nac_p: u8,
    /// Geometric vertical accuracy (airborne, version 2).
    pub gva: Option<u8>,
    pub sil: u8,
    pub sil_supplement: u8,
    /// NIC-baro (airborne) or track/heading flag (surface).
    pub nic_baro: u8,
    /// Horizontal reference direction: true north (0) or magnetic north (1).
    pub hrd: u8,
    pub capability: u16,
    pub operational_mode: u16,
}

pub fn decode_operational_status(me: u64) -> Option<OperationalStatus> {
    let subtype = me_bits(me, 6, 8) as u8;
    if subtype > 1 {
        return None;
    }
    let version = me_bits(me, 41, 43) as u8;
    let mut os = OperationalStatus {
        subtype,
        version,
        capability: me_bits(me, 9, 24) as u16,
        operational_mode: me_bits(me, 25, 40) as u16,
        ..Default::default()
    };
    if version == 0 {
        // DO-260 had none of the accuracy fields.
        return Some(os);
    }
    os.nic_a = me_bits(me, 44, 44) as u8;
    os.nac_p = me_bits(me, 45, 48) as u8;
    if subtype == 0 && version >= 2 {
        os.gva = Some(me_bits(me, 49, 50) as u8);
    }
    os.sil = me_bits(me, 51, 52) as u8;
    os.nic_baro = me_bits(me, 53, 53) as u8;
    os.hrd = me_bits(me, 54, 54) as u8;
    if version >= 2 {
        os.sil_supplement = me_bits(me, 55, 55) as u8;
        if subtype == 1 {
            os.nic_c = me_bits(me, 20, 20) as u8;
        }
    }
    Some(os)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modes::message::me_of;

    #[test]
    fn operational_status_v2() {
        // From the beastblackbox capture: pyModeS reads version 2, NACp 9, SIL 3.
        let os = decode_operational_status(me_of("8D400159F82300060049B812CDB4")).unwrap();
        assert_eq!((os.version, os.nac_p, os.sil, os.subtype), (2, 9, 3, 0));
    }

    #[test]
    fn target_state_v2() {
        // Published example 8DA05629EA21485CBF3F8CADAEEB: selected altitude
        // 16992 ft, 1012.8 hPa, heading 66.8 deg, NACp 9, SIL 3 (checked with pyModeS).
        let ts = decode_target_state(me_of("8DA05629EA21485CBF3F8CADAEEB")).unwrap();
        assert_eq!(ts.subtype, 1);
        assert_eq!(ts.selected_alt_ft, Some(16992));
        assert!((ts.baro_setting_hpa.unwrap() - 1012.8).abs() < 1e-6);
        assert!((ts.selected_heading_deg.unwrap() - 66.8).abs() < 0.1);
        assert_eq!((ts.nac_p, ts.sil), (9, 3));
    }
}
