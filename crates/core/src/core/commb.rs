//! A Comm-B track and turn report (BDS 5,0) as a velocity measurement, and
//! a heading and speed report's vertical rate (BDS 6,0) as a climb rate,
//! for aircraft whose velocity nothing else reports (no ADS-B).
//!
//! The register holds the aircraft's true track and ground speed as its
//! avionics last wrote them, and they refresh it at least every 1.3 s (ICAO
//! Doc 9871): a reply's values are up to that old. So the measurement is
//! dated half that before the reply, and the age's spread (1.3 s / sqrt 12)
//! becomes velocity error through the aircraft's acceleration: across its
//! track, the turn rate the same register reports (or a standard-rate turn's
//! when it reports none), along it a typical acceleration. The register's
//! steps (2 kt, 0.18 degrees) and the avionics' own error complete it.

use nalgebra::{Matrix2, Vector2};

use crate::geo::{FT_TO_M, KT_TO_MS};
use crate::modes::commb::{Bds50, Bds60, REFRESH_S};
use crate::track::measurement::{Measurement, Observation, Source};

/// Turn rate assumed when the register does not report one: a standard-rate turn.
const UNKNOWN_TURN_DPS: f64 = 3.0;
/// Along-track acceleration of an airliner changing speed (m/s^2, 1 sigma).
const ALONG_ACCEL_MS2: f64 = 1.0;
/// The avionics' own ground speed error, per axis (m/s, 1 sigma).
const SENSOR_SIGMA_MS: f64 = 0.5;

/// The velocity a reply received at `arrival` (Unix s) reports, or `None`
/// when it lacks the track or the ground speed.
pub fn velocity(r: &Bds50, arrival: f64) -> Option<Measurement> {
    let (track_deg, gs_kt) = (r.track_deg?, r.gs_kt?);
    let gs = gs_kt as f64 * KT_TO_MS;
    let age_sigma_s = REFRESH_S / 12f64.sqrt();
    let turn_rad_s = r.track_rate_dps.map_or(UNKNOWN_TURN_DPS, f64::abs).to_radians();
    let var_along = (2.0 * KT_TO_MS).powi(2) / 12.0 + (ALONG_ACCEL_MS2 * age_sigma_s).powi(2);
    let var_cross =
        (gs * (90.0f64 / 512.0).to_radians()).powi(2) / 12.0 + (gs * turn_rad_s * age_sigma_s).powi(2);
    let (s, c) = track_deg.to_radians().sin_cos();
    let along = Vector2::new(s, c);
    let cross = Vector2::new(c, -s);
    let cov = along * along.transpose() * var_along
        + cross * cross.transpose() * var_cross
        + Matrix2::identity() * SENSOR_SIGMA_MS.powi(2);
    Some(Measurement {
        t: arrival - REFRESH_S / 2.0,
        // Mode S surveillance, as altitude replies: with multilateration, apart from ADS-B.
        source: Source::Mlat,
        obs: Observation::Velocity { v_en: along * gs, cov, climb: None },
    })
}

/// Vertical acceleration of an airliner levelling off or starting a climb
/// (m/s^2, 1 sigma): what a register up to 1.3 s old is off by.
const VERTICAL_ACCEL_MS2: f64 = 0.5;
/// The sensors' own error (m/s, 1 sigma): the inertial vertical rate (the
/// air data and inertial references blended) and the barometric one, which
/// lags the aircraft by seconds and carries the air's ups and downs.
const INERTIAL_RATE_SIGMA_MS: f64 = 0.5;
const BARO_RATE_SIGMA_MS: f64 = 1.5;
/// The register's step (32 ft/min).
const VRATE_STEP_MS: f64 = 32.0 * FT_TO_M / 60.0;

/// The climb rate a reply received at `arrival` (Unix s) reports: its
/// inertial vertical rate, else its barometric one; `None` without either.
pub fn climb(r: &Bds60, arrival: f64) -> Option<Measurement> {
    let (fpm, sensor) = match (r.inertial_rate_fpm, r.baro_rate_fpm) {
        (Some(v), _) => (v, INERTIAL_RATE_SIGMA_MS),
        (None, Some(v)) => (v, BARO_RATE_SIGMA_MS),
        (None, None) => return None,
    };
    let age_sigma_s = REFRESH_S / 12f64.sqrt();
    let var =
        sensor * sensor + VRATE_STEP_MS * VRATE_STEP_MS / 12.0 + (VERTICAL_ACCEL_MS2 * age_sigma_s).powi(2);
    Some(Measurement {
        t: arrival - REFRESH_S / 2.0,
        source: Source::Mlat,
        obs: Observation::Climb { rate: fpm as f64 * FT_TO_M / 60.0, var },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turning_widens_across_track() {
        let r = |rate| Bds50 {
            roll_deg: None,
            track_deg: Some(90.0),
            gs_kt: Some(400),
            track_rate_dps: Some(rate),
            tas_kt: None,
        };
        let Observation::Velocity { v_en, cov, .. } = velocity(&r(0.0), 100.0).unwrap().obs else { panic!() };
        assert!((v_en[0] - 400.0 * KT_TO_MS).abs() < 1e-9 && v_en[1].abs() < 1e-9);
        // East is along track: steps and acceleration; north across.
        assert!((cov[(0, 0)] - (0.0882 + 0.1408 + 0.25)).abs() < 1e-3, "{cov}");
        assert!(cov[(1, 1)] < 0.4);
        let Observation::Velocity { cov: turning, .. } = velocity(&r(3.0), 100.0).unwrap().obs else {
            panic!()
        };
        // 206 m/s at 3 deg/s for 0.375 s: 4 m/s across.
        assert!((turning[(1, 1)].sqrt() - 4.07).abs() < 0.05, "{turning}");
        assert!(velocity(&Bds50 { gs_kt: None, ..r(0.0) }, 0.0).is_none());
    }

    #[test]
    fn the_inertial_rate_is_preferred_to_the_barometric() {
        let r = Bds60 {
            mag_heading_deg: None,
            ias_kt: None,
            mach: None,
            baro_rate_fpm: Some(-1500),
            inertial_rate_fpm: Some(2000),
        };
        let rate_var = |m: Measurement| match m.obs {
            Observation::Climb { rate, var } => (rate, var),
            other => panic!("{other:?}"),
        };
        let (rate, var) = rate_var(climb(&r, 10.0).unwrap());
        assert!((rate - 10.16).abs() < 1e-9, "{rate}");
        let (baro, baro_var) = rate_var(climb(&Bds60 { inertial_rate_fpm: None, ..r }, 10.0).unwrap());
        assert!((baro + 7.62).abs() < 1e-9 && baro_var > var, "{baro} {baro_var} {var}");
        assert!(climb(&Bds60 { inertial_rate_fpm: None, baro_rate_fpm: None, ..r }, 10.0).is_none());
    }
}
