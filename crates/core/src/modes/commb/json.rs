//! The `decode` output's fields for the Comm-B registers that have no place
//! among the ADS-B ones (track, ground speed, airspeeds, heading and vertical
//! rates go to those): readsb's names where readsb has the field
//! (`nav_altitude_mcp`, `nav_qnh`, `nav_modes`, `roll`, `track_rate`, `mach`,
//! `ws`, `wd`, `oat`), plain names with units otherwise.

use serde::Serialize;

use super::registers::GICB_REGISTERS;
use super::Register;
use crate::modes::json::round;

#[derive(Serialize, Default, Debug, PartialEq)]
pub struct CommbFields {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nav_altitude_mcp: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nav_altitude_fms: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nav_qnh: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nav_modes: Option<Vec<&'static str>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub roll: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub track_rate: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mach: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ws: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wd: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub oat: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub static_pressure_hpa: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub humidity_pct: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radio_height_ft: Option<u32>,
    /// Hazard levels (0 nil .. 3 severe): turbulence, wind shear, microburst,
    /// icing, wake vortex; `null` where not reported.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hazards: Option<[Option<u8>; 5]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub turbulence: Option<u8>,
    /// BDS 1,7: the registers the transponder serves.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gicb_capability: Option<Vec<&'static str>>,
}

impl CommbFields {
    pub fn new(reg: &Register) -> Self {
        let mut f = CommbFields::default();
        match *reg {
            Register::SelectedVertical(r) => {
                f.nav_altitude_mcp = r.mcp_alt_ft;
                f.nav_altitude_fms = r.fms_alt_ft;
                f.nav_qnh = r.baro_setting_hpa.map(|v| round(v, 1));
                f.nav_modes = r.modes.map(|m| {
                    ["vnav", "althold", "approach"]
                        .into_iter()
                        .zip(m)
                        .filter(|&(_, on)| on)
                        .map(|(n, _)| n)
                        .collect()
                });
            }
            Register::TrackTurn(r) => {
                f.roll = r.roll_deg.map(|v| round(v, 2));
                f.track_rate = r.track_rate_dps.map(|v| round(v, 3));
            }
            Register::HeadingSpeed(r) => f.mach = r.mach.map(|v| round(v, 3)),
            Register::MeteoRoutine(r) => {
                f.ws = Some(r.wind_kt);
                f.wd = Some(round(r.wind_dir_deg, 1));
                f.oat = Some(r.sat_c);
                f.static_pressure_hpa = r.pressure_hpa;
                f.humidity_pct = r.humidity_pct.map(|v| round(v, 1));
                f.turbulence = r.turbulence;
            }
            Register::MeteoHazard(r) => {
                f.hazards = Some([r.turbulence, r.wind_shear, r.microburst, r.icing, r.wake_vortex]);
                f.oat = r.sat_c;
                f.static_pressure_hpa = r.pressure_hpa;
                f.radio_height_ft = r.radio_height_ft;
            }
            Register::Capability(map) => {
                f.gicb_capability = Some(
                    GICB_REGISTERS
                        .iter()
                        .enumerate()
                        .filter(|&(i, _)| map >> (23 - i) & 1 == 1)
                        .map(|(_, &r)| r)
                        .collect(),
                );
            }
            Register::DataLink | Register::Identification(_) | Register::AcasRa => {}
        }
        f
    }
}
