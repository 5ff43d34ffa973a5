//! A Comm-B track and turn report (BDS 5,0) as a velocity measurement, and
//! a heading and speed report's (BDS 6,0) vertical rate as a climb rate and
//! its heading and airspeed as a weaker velocity (through the wind learnt,
//! [`super::wind`]), for aircraft whose velocity nothing else reports (no
//! ADS-B).
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

use super::wind::{AirVector, WindField};
use crate::geo::{FT_TO_M, KT_TO_MS};
use crate::modes::commb::{air, Bds50, Bds60, ReplyContext, REFRESH_S};
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

/// The register's steps: heading (90/512 degrees), IAS (1 kt), Mach (0.004).
const HEADING_STEP_DEG: f64 = 90.0 / 512.0;
const MACH_STEP: f64 = 0.004;
/// The air data's own error (m/s of true airspeed, 1 sigma): pitot and
/// static position errors, a few knots.
const AIRSPEED_SIGMA_MS: f64 = 1.5;
/// The heading reference's own error (deg, 1 sigma).
const HEADING_SIGMA_DEG: f64 = 0.5;
/// An altitude older than this (s) does not convert a heading report's airspeeds.
const MAX_ALTITUDE_AGE_S: f64 = 5.0;
/// A prediction weaker than this (m/s, per axis, 1 sigma) tells a track
/// nothing its positions do not: the wind is not learnt yet.
const MAX_USEFUL_SIGMA_MS: f64 = 15.0;

/// The velocity through the air a heading and speed report gives: its
/// magnetic heading and its true airspeed (from its IAS, else its Mach, at
/// the altitude known; the standard atmosphere's temperature, which the
/// wind learner's scale corrects), with the register's steps and age.
/// `None` without a heading, an airspeed or an altitude.
pub fn air_vector(r: &Bds60, ctx: &ReplyContext) -> Option<(AirVector, f64)> {
    let heading_deg = r.mag_heading_deg?;
    // The altitude sets the airspeed's conversion (2% of true airspeed per
    // 1,000 ft): an identity reply's, remembered, only while an aircraft
    // changing level cannot have left it far.
    let (alt_ft, _) = ctx.known.alt_ft.filter(|&(_, age_s)| age_s <= MAX_ALTITUDE_AGE_S)?;
    let alt_ft = alt_ft as f64;
    let sound = air::speed_of_sound_ms(alt_ft);
    let (tas, step) = match (r.ias_kt, r.mach) {
        (Some(ias), _) if ias > 0 => {
            let tas = air::mach_of_cas(ias as f64, alt_ft) * sound;
            // One knot of IAS is about TAS/IAS knots of TAS: in m/s, tas / ias.
            (tas, tas / ias as f64)
        }
        (_, Some(mach)) if mach > 0.0 => (mach * sound, MACH_STEP * sound),
        _ => return None,
    };
    let age_sigma_s = REFRESH_S / 12f64.sqrt();
    let turn_rad_s = ctx.turn_dps.map_or(UNKNOWN_TURN_DPS, f64::abs).to_radians();
    let var_along = step * step / 12.0 + AIRSPEED_SIGMA_MS.powi(2) + (ALONG_ACCEL_MS2 * age_sigma_s).powi(2);
    let var_cross = (tas * HEADING_STEP_DEG.to_radians()).powi(2) / 12.0
        + (tas * HEADING_SIGMA_DEG.to_radians()).powi(2)
        + (tas * turn_rad_s * age_sigma_s).powi(2);
    let (s, c) = heading_deg.to_radians().sin_cos();
    let along = Vector2::new(s, c);
    let cross = Vector2::new(c, -s);
    let cov = along * along.transpose() * var_along + cross * cross.transpose() * var_cross;
    Some((AirVector { en: along * tas, cov }, alt_ft * FT_TO_M))
}

/// The ground velocity a heading and speed report received at `arrival`
/// gives through the wind learnt, or `None` when the report lacks what it
/// needs or the wind is not learnt well enough to say anything. The part
/// of its error the aircraft's reports share (the wind where it flies) is
/// counted once for all its reports of the last minute, so a track fed
/// every one of them is not made surer than that.
pub fn heading_velocity(
    r: &Bds60,
    ctx: &ReplyContext,
    wind: &WindField,
    arrival: f64,
) -> Option<Measurement> {
    let (air, alt_m) = air_vector(r, ctx)?;
    let p = wind.predict(alt_m, &air);
    if p.persistent.trace() > 2.0 * MAX_USEFUL_SIGMA_MS.powi(2) {
        return None;
    }
    let cov = p.persistent * ctx.heading_reports.max(1.0) + p.independent;
    Some(Measurement {
        t: arrival - REFRESH_S / 2.0,
        source: Source::Mlat,
        obs: Observation::Velocity { v_en: p.v_en, cov, climb: None },
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

    /// A heading and speed report: its airspeed from the IAS at the altitude
    /// (else the Mach), nothing without a heading or an altitude, and through
    /// a wind learnt, a ground velocity whose shared part is counted once
    /// for the aircraft's reports of the last minute.
    #[test]
    fn a_heading_report_through_the_wind_learnt() {
        let r = Bds60 {
            mag_heading_deg: Some(90.0),
            ias_kt: Some(250),
            mach: Some(0.6),
            baro_rate_fpm: None,
            inertial_rate_fpm: None,
        };
        let ctx = |alt: Option<i32>, reports: f64| ReplyContext {
            known: crate::modes::commb::Known { alt_ft: alt.map(|a| (a, 0.0)), velocity: None },
            adsb_velocity: None,
            turn_dps: Some(0.0),
            heading_reports: reports,
        };
        let (a, alt_m) = air_vector(&r, &ctx(Some(20_000), 1.0)).unwrap();
        // 250 kt IAS at FL200 is Mach 0.55, 336 kt true (ISA).
        let tas = air::mach_of_cas(250.0, 20_000.0) * air::speed_of_sound_ms(20_000.0);
        assert!((tas / KT_TO_MS - 336.0).abs() < 1.0, "{}", tas / KT_TO_MS);
        assert!((a.en[0] - tas).abs() < 1e-9 && a.en[1].abs() < 1e-9, "{}", a.en);
        assert!((alt_m - 6096.0).abs() < 1.0);
        // Across the heading (north) the 0.5 degree reference and the step.
        assert!((a.cov[(1, 1)].sqrt() - tas * 0.5f64.to_radians()).abs() < 0.2, "{}", a.cov);
        let (m, _) = air_vector(&Bds60 { ias_kt: None, ..r }, &ctx(Some(20_000), 1.0)).unwrap();
        assert!((m.en[0] - 0.6 * air::speed_of_sound_ms(20_000.0)).abs() < 1e-9);
        assert!(air_vector(&r, &ctx(None, 1.0)).is_none());
        assert!(air_vector(&Bds60 { mag_heading_deg: None, ..r }, &ctx(Some(20_000), 1.0)).is_none());

        // Nothing learnt: too weak to say anything.
        let mut wind = WindField::default();
        assert!(heading_velocity(&r, &ctx(Some(20_000), 1.0), &wind, 100.0).is_none());
        // A west wind of 20 m/s and no variation, learnt from aircraft on many headings.
        for k in 0..300 {
            let h = (k * 47 % 360) as f64;
            let (s, c) = h.to_radians().sin_cos();
            let air = AirVector { en: Vector2::new(s, c) * 180.0, cov: Matrix2::identity() };
            let g = air.en + Vector2::new(20.0, 0.0);
            wind.learn(k as f64, 6_000.0, &air, g, Matrix2::identity(), 1.0);
        }
        let velocity_cov = |reports| match heading_velocity(&r, &ctx(Some(20_000), reports), &wind, 400.0) {
            Some(Measurement { obs: Observation::Velocity { v_en, cov, .. }, t, .. }) => {
                assert!((t - (400.0 - REFRESH_S / 2.0)).abs() < 1e-9);
                assert!((v_en - Vector2::new(tas + 20.0, 0.0)).norm() < 1.0, "{v_en}");
                cov
            }
            other => panic!("{other:?}"),
        };
        let (one, many) = (velocity_cov(1.0), velocity_cov(15.0));
        assert!(many[(0, 0)] > one[(0, 0)] + 10.0 * wind.scatter_ms().powi(2), "{one} {many}");
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
