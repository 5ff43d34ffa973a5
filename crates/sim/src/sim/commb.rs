//! The Comm-B registers a simulated aircraft's DF20/21 replies carry, filled
//! from its true state: 5,0 (track, ground speed, roll and track rate of a
//! coordinated turn, true airspeed), 6,0 (heading, IAS and Mach, vertical
//! rates) and 4,0 (the altitude it will hold in a minute as the selected
//! altitude, standard altimeter setting). Heading and airspeed are the
//! aircraft's motion through the scenario's air: its ground velocity less
//! the wind at its height, the heading magnetic, Mach against the speed of
//! sound at the air's temperature. Values are the register's steps of the
//! truth, no noise beyond that and the register's age (the caller's).

use super::scenario::Air;
use super::trajectory::{Sample, Trajectory};
use fuse1090_core::geo::{FT_TO_M, KT_TO_MS};
use fuse1090_core::modes::commb::registers::{Bds40, Bds50, Bds60};
use fuse1090_core::modes::commb::{air, encode, Bds};

fn track_deg(s: &Sample) -> f64 {
    s.vel[0].atan2(s.vel[1]).to_degrees().rem_euclid(360.0)
}

/// The MB of register `bds` at scenario time `t`; `None` when the aircraft
/// is not flying then (or the register is not one the simulator fills).
pub fn register(bds: Bds, traj: &Trajectory, t: f64, baro_offset_m: f64, atmosphere: &Air) -> Option<u64> {
    let s = traj.at(t)?;
    let alt_ft = (s.alt_m - baro_offset_m) / FT_TO_M;
    let gs_ms = s.vel[0].hypot(s.vel[1]);
    let wind = atmosphere.wind_at(s.alt_m);
    let through_air = [s.vel[0] - wind[0], s.vel[1] - wind[1]];
    let tas_ms = through_air[0].hypot(through_air[1]);
    let true_heading_deg = through_air[0].atan2(through_air[1]).to_degrees();
    let fpm = (s.vel[2] / FT_TO_M * 60.0).round() as i32;
    Some(match bds {
        Bds::B50 => {
            // The turn rate over the second around t.
            let (a, b) = (traj.at(t - 0.5).unwrap_or(s), traj.at(t + 0.5).unwrap_or(s));
            let rate_dps = ((track_deg(&b) - track_deg(&a) + 540.0).rem_euclid(360.0) - 180.0)
                * if gs_ms > 1.0 { 1.0 } else { 0.0 };
            // The bank of the turn through the air (about the track's turn).
            let roll_deg = air::bank_deg(rate_dps, tas_ms);
            let two_kt = |ms: f64| ((ms / KT_TO_MS / 2.0).round() * 2.0) as u32;
            encode::bds50(&Bds50 {
                roll_deg: Some(roll_deg),
                track_deg: Some(track_deg(&s)),
                gs_kt: Some(two_kt(gs_ms)),
                track_rate_dps: Some(rate_dps),
                tas_kt: Some(two_kt(tas_ms)),
            })
        }
        Bds::B60 => {
            // The speed of sound goes with the square root of the temperature.
            let isa_k = air::isa_temperature_c(alt_ft) + 273.15;
            let sound_ms =
                air::speed_of_sound_ms(alt_ft) * ((isa_k + atmosphere.isa_deviation_c) / isa_k).sqrt();
            let mach = tas_ms / sound_ms;
            encode::bds60(&Bds60 {
                mag_heading_deg: Some(
                    (true_heading_deg - atmosphere.magnetic_variation_deg).rem_euclid(360.0),
                ),
                ias_kt: Some(air::cas_of_mach(mach, alt_ft).round() as u32),
                mach: Some(mach),
                baro_rate_fpm: Some(fpm),
                inertial_rate_fpm: Some(fpm),
            })
        }
        Bds::B40 => {
            let ahead = traj.at(t + 60.0).or_else(|| traj.at(traj.t_end())).unwrap_or(s);
            let target_ft = ((ahead.alt_m - baro_offset_m) / FT_TO_M / 100.0).round() * 100.0;
            encode::bds40(&Bds40 {
                mcp_alt_ft: Some(target_ft.max(0.0) as u32),
                fms_alt_ft: None,
                baro_setting_hpa: Some(1013.2),
                modes: None,
                alt_source: None,
            })
        }
        _ => return None,
    })
}
