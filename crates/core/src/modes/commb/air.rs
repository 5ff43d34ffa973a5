//! The ISA atmosphere, as far as Comm-B inference needs it: a barometric
//! altitude is a pressure by definition, and the Mach number an indicated
//! (calibrated) airspeed gives depends on that pressure alone, so a heading
//! and speed report's IAS and Mach can be checked against the reply's
//! altitude without knowing the temperature or the wind.

use crate::geo::{FT_TO_M, KT_TO_MS};

const P0_PA: f64 = 101_325.0;
const T0_K: f64 = 288.15;
/// Speed of sound at sea level, ISA (m/s).
const A0_MS: f64 = 340.294;
const LAPSE_K_PER_M: f64 = 0.0065;
const TROPOPAUSE_M: f64 = 11_000.0;
const P11_PA: f64 = 22_632.06;
/// g / (R lapse) and R T11 / g for dry air.
const EXPONENT: f64 = 5.255_88;
const SCALE_HEIGHT_11_M: f64 = 6_341.62;
const FT: f64 = FT_TO_M;
const KT: f64 = KT_TO_MS;
/// Standard gravity (m/s^2).
pub const G_MS2: f64 = 9.80665;

/// Turn rate (deg/s) of a coordinated turn at `roll_deg` of bank and `tas_ms`.
pub fn turn_rate_dps(roll_deg: f64, tas_ms: f64) -> f64 {
    (G_MS2 * roll_deg.to_radians().tan() / tas_ms).to_degrees()
}

/// Bank (deg) of a coordinated turn at `rate_dps` and `tas_ms`.
pub fn bank_deg(rate_dps: f64, tas_ms: f64) -> f64 {
    (tas_ms * rate_dps.to_radians() / G_MS2).atan().to_degrees()
}

/// Static pressure (Pa) at a pressure altitude (ft).
pub fn pressure_pa(alt_ft: f64) -> f64 {
    let h = alt_ft * FT;
    if h < TROPOPAUSE_M {
        P0_PA * (1.0 - LAPSE_K_PER_M * h / T0_K).powf(EXPONENT)
    } else {
        P11_PA * (-(h - TROPOPAUSE_M) / SCALE_HEIGHT_11_M).exp()
    }
}

/// The pressure altitude (ft) of a static pressure (Pa).
pub fn altitude_ft(p_pa: f64) -> f64 {
    let h = if p_pa > P11_PA {
        T0_K / LAPSE_K_PER_M * (1.0 - (p_pa / P0_PA).powf(1.0 / EXPONENT))
    } else {
        TROPOPAUSE_M - SCALE_HEIGHT_11_M * (p_pa / P11_PA).ln()
    };
    h / FT
}

/// ISA static air temperature (deg C) at a pressure altitude (ft).
pub fn isa_temperature_c(alt_ft: f64) -> f64 {
    let h = (alt_ft * FT).min(TROPOPAUSE_M);
    T0_K - LAPSE_K_PER_M * h - 273.15
}

/// Impact pressure (Pa) of a calibrated airspeed (subsonic).
fn impact_pressure_pa(cas_kt: f64) -> f64 {
    let v = cas_kt * KT / A0_MS;
    P0_PA * ((1.0 + 0.2 * v * v).powf(3.5) - 1.0)
}

/// The Mach number of a calibrated airspeed at a pressure altitude.
pub fn mach_of_cas(cas_kt: f64, alt_ft: f64) -> f64 {
    let ratio = impact_pressure_pa(cas_kt) / pressure_pa(alt_ft);
    (5.0 * ((ratio + 1.0).powf(2.0 / 7.0) - 1.0)).sqrt()
}

/// Speed of sound (m/s) in the ISA atmosphere at a pressure altitude (ft).
pub fn speed_of_sound_ms(alt_ft: f64) -> f64 {
    A0_MS * ((isa_temperature_c(alt_ft) + 273.15) / T0_K).sqrt()
}

/// The calibrated airspeed (kt) of a Mach number at a pressure altitude (subsonic).
pub fn cas_of_mach(mach: f64, alt_ft: f64) -> f64 {
    let qc = pressure_pa(alt_ft) * ((1.0 + 0.2 * mach * mach).powf(3.5) - 1.0);
    A0_MS * (5.0 * ((qc / P0_PA + 1.0).powf(2.0 / 7.0) - 1.0)).sqrt() / KT
}

/// The pressure altitude (ft) at which a calibrated airspeed is this Mach
/// number; `None` for a Mach of zero.
pub fn altitude_of_cas_mach(cas_kt: f64, mach: f64) -> Option<f64> {
    let ratio = (1.0 + 0.2 * mach * mach).powf(3.5) - 1.0;
    (ratio > 0.0).then(|| altitude_ft(impact_pressure_pa(cas_kt) / ratio))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_atmosphere() {
        assert!((pressure_pa(0.0) - P0_PA).abs() < 1e-6);
        // ISA tables: 500 hPa at 18,289 ft, 250 hPa at 33,999 ft, FL390 196.6 hPa.
        assert!((altitude_ft(50_000.0) - 18_289.0).abs() < 5.0);
        assert!((altitude_ft(25_000.0) - 33_999.0).abs() < 5.0);
        assert!((pressure_pa(39_000.0) - 19_666.0).abs() < 20.0);
        assert!((altitude_ft(pressure_pa(41_000.0)) - 41_000.0).abs() < 1e-6);
        assert!((isa_temperature_c(36_089.0) + 56.5).abs() < 0.01);
        // At sea level CAS is TAS: 661.5 kt is Mach 1.
        assert!((mach_of_cas(661.47, 0.0) - 1.0).abs() < 1e-3);
        // 280 kt at FL350 is about Mach 0.82.
        assert!((mach_of_cas(280.0, 35_000.0) - 0.82).abs() < 0.01);
        let h = altitude_of_cas_mach(280.0, mach_of_cas(280.0, 35_000.0)).unwrap();
        assert!((h - 35_000.0).abs() < 1.0);
        assert!((cas_of_mach(mach_of_cas(250.0, 12_000.0), 12_000.0) - 250.0).abs() < 1e-6);
        // Mach 0.8 at FL350 (-54.3 deg C) is 461 kt true.
        assert!((0.8 * speed_of_sound_ms(35_000.0) / KT - 461.0).abs() < 1.0);
        // A rate-one turn (3 deg/s) at 250 kt: tan(bank) = 128.6 m/s x 0.0524 rad/s / g,
        // 34.5 degrees; and back.
        let bank = bank_deg(3.0, 250.0 * KT);
        assert!((bank - 34.48).abs() < 0.01, "{bank}");
        assert!((turn_rate_dps(bank, 250.0 * KT) - 3.0).abs() < 1e-9);
    }
}
