//! What speaks for and against reading an MB as one register, once its
//! layout fits: the register's fields against each other (a heading and speed
//! report's IAS and Mach against the reply's altitude, its two vertical
//! rates; a track and turn report's roll against its turn rate) and against
//! what is known of the aircraft (its altitude, its ADS-B or Comm-B track and
//! speed).
//!
//! Evidence is counted in points, one point a likelihood ratio of about 3:
//! a check that a wrong register passes about a third of the time is worth
//! 1, one that it passes a few times in a hundred 3. A check failed beyond
//! what measurement and lag explain contradicts the register outright. The
//! meteorological registers start 3 points down: few transponders serve them
//! and ground stations seldom ask for them, while 4,0, 5,0 and 6,0 are the
//! enhanced surveillance every interrogator reads.

use super::air;
use super::registers::{Bds40, Bds45, Bds50, Bds60};
use super::{Known, Register};
use crate::geo::KT_TO_MS;

/// The verdict on one candidate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Assessment {
    pub contradicted: bool,
    pub points: i32,
}

impl Assessment {
    fn add(&mut self, points: i32) {
        self.points += points;
    }
    fn contradict(&mut self) {
        self.contradicted = true;
    }
}

/// Points a register with no evidence of its own must make up.
const RARE_REGISTER: i32 = -3;

/// Mach from IAS at the altitude: IAS is not quite CAS (position error, a
/// few knots), the altitude is 25 or 100 ft steps and read at another moment.
const MACH_AGREES: f64 = 0.03;
const MACH_CONTRADICTS: f64 = 0.06;
/// How fast an aircraft's altitude can change (ft/s) when the altitude known is older.
const CLIMB_FT_PER_S: f64 = 100.0;
/// Barometric and inertial vertical rates measure one thing; the baro rate lags.
const VRATES_AGREE_FPM: i32 = 500;
const VRATES_CONTRADICT_FPM: i32 = 2000;
/// A coordinated turn's rate from its bank and airspeed, against the track rate reported.
const TURN_AGREES_DPS: f64 = 0.5;
/// Track and ground speed against a known velocity: agree, or contradict, plus
/// what a turning (3 deg/s) or accelerating (5 kt/s) aircraft changes in the age.
const TRACK_AGREES_DEG: f64 = 20.0;
const TRACK_CONTRADICTS_DEG: f64 = 45.0;
const GS_AGREES_KT: f64 = 30.0;
const GS_CONTRADICTS_KT: f64 = 80.0;
/// Heading against track: wind correction and magnetic variation.
const HEADING_AGREES_DEG: f64 = 30.0;
const HEADING_CONTRADICTS_DEG: f64 = 100.0;
/// Above every airport, an aircraft flies: its airspeeds and ground speed
/// cannot be near zero there.
const ABOVE_AIRPORTS_FT: f64 = 15_000.0;
const MIN_AIRBORNE_IAS_KT: u32 = 60;
const MIN_AIRBORNE_MACH: f64 = 0.15;
const MIN_AIRBORNE_TAS_KT: u32 = 80;
const MIN_AIRBORNE_GS_KT: u32 = 30;
/// Static air temperature against ISA at the altitude, and static pressure
/// against the pressure the altitude is.
const SAT_AGREES_C: f64 = 30.0;
const SAT_CONTRADICTS_C: f64 = 50.0;
const PRESSURE_AGREES_HPA: f64 = 20.0;
const PRESSURE_CONTRADICTS_HPA: f64 = 60.0;

pub fn assess(reg: &Register, known: &Known) -> Assessment {
    let mut a = Assessment::default();
    match reg {
        Register::SelectedVertical(r) => selected_vertical(r, &mut a),
        Register::TrackTurn(r) => track_turn(r, known, &mut a),
        Register::HeadingSpeed(r) => heading_speed(r, known, &mut a),
        Register::MeteoRoutine(r) => meteo(Some(r.sat_c), r.pressure_hpa, known, &mut a),
        Register::MeteoHazard(r) => {
            meteo(r.sat_c, r.pressure_hpa, known, &mut a);
            hazard(r, known, &mut a);
        }
        Register::Capability(map) => capability(*map, &mut a),
        Register::Identification(_) | Register::DataLink | Register::AcasRa => {}
    }
    if matches!(reg, Register::MeteoRoutine(_) | Register::MeteoHazard(_)) {
        a.add(RARE_REGISTER);
    }
    a
}

/// Autopilots select altitudes in hundreds of feet (the register's 16 ft
/// steps round them), and altimeters are set to standard or a QNH.
fn selected_vertical(r: &Bds40, a: &mut Assessment) {
    let round = |ft: u32| (ft as i64 - (ft as i64 + 50) / 100 * 100).abs() <= 16;
    for alt in [r.mcp_alt_ft, r.fms_alt_ft].into_iter().flatten() {
        if round(alt) {
            a.add(1);
        }
    }
    if let Some(b) = r.baro_setting_hpa {
        // Standard (1013.25 hPa) is 1013.2 or 1013.3 in the register's steps.
        if (b - 1013.25).abs() <= 0.06 {
            a.add(2);
        } else if (950.0..=1050.0).contains(&b) {
            a.add(1);
        }
    }
}

/// A transponder that reports its GICB capability serves enhanced
/// surveillance (4,0, 5,0 and 6,0) more often than not; a wrong register's
/// bits name all three one time in eight.
fn capability(map: u32, a: &mut Assessment) {
    let serves = |bit: u32| map >> (24 - bit) & 1 == 1;
    if serves(9) && serves(16) && serves(24) {
        a.add(2);
    }
}

/// Whether the aircraft is surely airborne (above every airport).
fn airborne(known: &Known) -> bool {
    known.alt_ft.is_some_and(|(alt, age_s)| alt as f64 - CLIMB_FT_PER_S * age_s > ABOVE_AIRPORTS_FT)
}

fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

fn track_turn(r: &Bds50, known: &Known, a: &mut Assessment) {
    if airborne(known)
        && (r.gs_kt.is_some_and(|v| v < MIN_AIRBORNE_GS_KT)
            || r.tas_kt.is_some_and(|v| v < MIN_AIRBORNE_TAS_KT))
    {
        a.contradict();
    }
    if let (Some(roll), Some(rate), Some(tas)) = (r.roll_deg, r.track_rate_dps, r.tas_kt) {
        if tas > 0 {
            let expected = air::turn_rate_dps(roll, tas as f64 * KT_TO_MS);
            if (rate - expected).abs() <= TURN_AGREES_DPS {
                // Level wings and no turn is what zeros give too: worth less.
                a.add(if roll.abs() >= 1.0 || rate != 0.0 { 3 } else { 1 });
            }
        }
    }
    if let (Some(gs), Some(tas)) = (r.gs_kt, r.tas_kt) {
        if gs.abs_diff(tas) <= 100 {
            a.add(1);
        }
    }
    if let Some(v) = known.velocity {
        let track = r.track_deg.map(|t| angle_diff(t, v.track_deg) - 3.0 * v.age_s);
        let gs = r.gs_kt.map(|g| (g as f64 - v.gs_kt).abs() - 5.0 * v.age_s);
        if track.is_some_and(|d| d > TRACK_CONTRADICTS_DEG) || gs.is_some_and(|d| d > GS_CONTRADICTS_KT) {
            a.contradict();
        } else if track.is_some_and(|d| d <= TRACK_AGREES_DEG) && gs.is_some_and(|d| d <= GS_AGREES_KT) {
            a.add(3);
        }
    }
}

fn heading_speed(r: &Bds60, known: &Known, a: &mut Assessment) {
    if airborne(known)
        && (r.ias_kt.is_some_and(|v| v < MIN_AIRBORNE_IAS_KT)
            || r.mach.is_some_and(|v| v < MIN_AIRBORNE_MACH))
    {
        a.contradict();
    }
    if let (Some(ias), Some(mach)) = (r.ias_kt, r.mach) {
        match known.alt_ft {
            Some((alt, age_s)) => {
                let slack = air::mach_of_cas(ias as f64, alt as f64 + CLIMB_FT_PER_S * age_s)
                    - air::mach_of_cas(ias as f64, alt as f64);
                let d = (air::mach_of_cas(ias as f64, alt as f64) - mach).abs() - slack.abs();
                if d > MACH_CONTRADICTS {
                    a.contradict();
                } else if d <= MACH_AGREES {
                    a.add(3);
                }
            }
            None => match air::altitude_of_cas_mach(ias as f64, mach) {
                Some(h) if (-2_000.0..=60_000.0).contains(&h) => a.add(1),
                Some(_) => a.contradict(),
                None => {}
            },
        }
    }
    if let (Some(baro), Some(inertial)) = (r.baro_rate_fpm, r.inertial_rate_fpm) {
        let d = (baro - inertial).abs();
        if d > VRATES_CONTRADICT_FPM {
            a.contradict();
        } else if d <= VRATES_AGREE_FPM {
            a.add(if baro == 0 && inertial == 0 { 1 } else { 3 });
        }
    }
    if let (Some(hdg), Some(v)) = (r.mag_heading_deg, known.velocity) {
        let d = angle_diff(hdg, v.track_deg) - 3.0 * v.age_s;
        if d > HEADING_CONTRADICTS_DEG {
            a.contradict();
        } else if d <= HEADING_AGREES_DEG {
            a.add(1);
        }
    }
}

fn meteo(sat_c: Option<f64>, pressure_hpa: Option<u32>, known: &Known, a: &mut Assessment) {
    let Some((alt, age_s)) = known.alt_ft else { return };
    let alt = alt as f64;
    if let Some(t) = sat_c {
        let d = (t - air::isa_temperature_c(alt)).abs();
        if d > SAT_CONTRADICTS_C {
            a.contradict();
        } else if d <= SAT_AGREES_C {
            a.add(1);
        }
    }
    if let Some(p) = pressure_hpa {
        let slack = (air::pressure_pa(alt - CLIMB_FT_PER_S * age_s) - air::pressure_pa(alt)) / 100.0;
        let d = (p as f64 - air::pressure_pa(alt) / 100.0).abs() - slack;
        if d > PRESSURE_CONTRADICTS_HPA {
            a.contradict();
        } else if d <= PRESSURE_AGREES_HPA {
            a.add(3);
        }
    }
}

/// A radio altimeter reads a few thousand feet at most, and never more than
/// the aircraft's height above the lowest ground.
fn hazard(r: &Bds45, known: &Known, a: &mut Assessment) {
    if let (Some(rh), Some((alt, _))) = (r.radio_height_ft, known.alt_ft) {
        if rh as i64 > alt as i64 + 2_000 {
            a.contradict();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::registers::{bds50, bds60};
    use super::*;
    use crate::modes::commb::KnownVelocity;

    #[test]
    fn heading_and_speed_checked_against_the_altitude() {
        // IAS 252 kt, Mach 0.42 at 5,450 ft (the reply's altitude).
        let r = Register::HeadingSpeed(bds60(0x8F39F91A7E27C4).unwrap());
        let at = |alt| assess(&r, &Known { alt_ft: Some((alt, 0.0)), velocity: None });
        assert_eq!(at(5_450), Assessment { contradicted: false, points: 6 });
        assert!(at(30_000).contradicted);
    }

    #[test]
    fn track_and_turn_against_a_known_velocity() {
        // Track 114.3 deg, 438 kt, roll 2.1 deg and 0.125 deg/s at 424 kt TAS.
        let r = Register::TrackTurn(bds50(0x81951536E024D4).unwrap());
        let with = |track_deg, gs_kt| {
            assess(
                &r,
                &Known { alt_ft: None, velocity: Some(KnownVelocity { track_deg, gs_kt, age_s: 1.0 }) },
            )
        };
        assert_eq!(with(112.0, 440.0).points, 3 + 1 + 3);
        assert!(with(200.0, 440.0).contradicted);
        assert!(with(114.0, 300.0).contradicted);
    }
}
