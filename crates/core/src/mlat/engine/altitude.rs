//! The aircraft's barometric altitude as a constraint on its fix: as a
//! height above the ellipsoid (its own GNSS-baro difference, or the
//! region's), with a variance that grows with its age and the climb since.
//! One rule for the solver's constraint and the tracker's heights.

use super::*;

/// Height above the ellipsoid (m) of a barometric altitude, and its 1-sigma
/// (m): corrected by the aircraft's own GNSS-baro difference when it reports
/// one, or the region's (`baro`), else taken as is with the configured
/// `baro_sigma_m`. One rule for the MLAT solver's altitude constraint and
/// the tracker's heights.
pub fn baro_height(alt_ft: i32, correction: Option<BaroCorrection>, baro_sigma_m: f64) -> (f64, f64) {
    match correction {
        Some(c) => ((alt_ft as f64 + c.diff_ft) * FT_TO_M, c.sigma_m),
        None => (alt_ft as f64 * FT_TO_M, baro_sigma_m),
    }
}

/// A barometric altitude recent enough to constrain a fix: feet, its
/// variance (m^2: the 25 ft steps and the climb since), and its correction
/// to the ellipsoid as known when it was reported.
#[derive(Clone, Copy)]
pub(super) struct Baro {
    pub ft: i32,
    pub var_m2: f64,
    pub correction: Option<BaroCorrection>,
}

impl Mlat {
    /// The aircraft's barometric altitude when recent enough to constrain a
    /// fix, and the constraint it makes: its height above the ellipsoid and
    /// sigma.
    pub(super) fn altitude_constraint(
        &self,
        ac: &AcState,
        now: f64,
    ) -> (Option<Baro>, Option<AltitudeConstraint>) {
        // The barometric altitude's own height and variance (25 ft steps,
        // climb since), apart from its correction to the ellipsoid, when
        // recent enough to constrain the fix.
        let baro = ac.alt_ft.and_then(|(ft, t, diff)| {
            let age = (now - t).abs();
            let quant = 25.0 * FT_TO_M / 12f64.sqrt();
            let var = quant.powi(2) + (age * self.cfg.alt_growth_mps).powi(2);
            (age <= self.cfg.max_alt_age_s).then_some(Baro { ft, var_m2: var, correction: diff })
        });
        let alt = baro.map(|Baro { ft, var_m2: var, correction: diff }| {
            // The correction is the aircraft's own when its ADS-B reports
            // one (GNSS minus baro, in 25 ft steps), else the region's from
            // the ADS-B traffic, else from the fixes' geometry: taken as zero
            // instead, an error the same for every fix of the flight (45 m
            // on tma-busy, 90 m on LocaRDS) moved its fixes off the same way
            // for minutes, which a track fed by them could not average away.
            let diff = diff.or_else(|| {
                let (lat, lon, _) = crate::geo::ecef_to_geodetic(ac.last_fix?.0);
                self.geometric_baro.correction(lat, lon, ft, self.cfg.baro_sigma_m)
            });
            let (h_m, correction) = baro_height(ft, diff, self.cfg.baro_sigma_m);
            AltitudeConstraint { h_m, sigma_m: (var + correction.powi(2)).sqrt() }
        });
        (baro, alt)
    }
}
