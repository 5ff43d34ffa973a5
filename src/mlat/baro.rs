//! The station's regional difference between GNSS height and barometric
//! altitude, learnt from the ADS-B aircraft that report both, for the
//! aircraft that report only a barometric altitude (Mode S only, or ADS-B
//! without velocity messages).
//!
//! Barometric altitude is referred to the standard atmosphere, so it departs
//! from the height above the ellipsoid by the day's pressure and temperature
//! plus the geoid: tens of metres, the same for every aircraft in the region
//! at one level and growing with height as the column's mean temperature
//! departs from the standard one. Taken as zero, that difference was the
//! largest vertical error of aircraft without ADS-B (tma-busy: 45 m for each
//! of them, the same for every fix of a flight) and, seen through an MLAT
//! geometry, a horizontal bias. So the difference is fitted as a straight
//! line in altitude by weighted least squares over the recent reports
//! (forgetting with a time constant of ten minutes, so weather moves it), and
//! its uncertainty is the scatter of the reports about that line plus the
//! line's own uncertainty at the altitude asked: a region whose difference
//! varies from place to place says so through its scatter.

use crate::geo::FT_TO_M;

/// How fast old reports fade (s).
const TIME_CONSTANT_S: f64 = 600.0;

/// Reports' weight (about that many recent ones) before the fit is used.
const MIN_WEIGHT: f64 = 30.0;

/// Altitude spread (kft, standard deviation) below which only a constant is
/// fitted: a slope from one level would extrapolate noise.
const MIN_SPREAD_KFT: f64 = 2.0;

/// Reports further than this many sigmas from the fit (but at least this
/// many metres) are left out (a transponder with a wrong difference, a
/// spoofer), once the fit stands...
const OUTLIER_SIGMAS: f64 = 5.0;
const OUTLIER_FLOOR_M: f64 = 15.0;

/// ...unless this many come in a row: then the difference has changed.
const RELEARN_AFTER: u32 = 50;

/// The least uncertainty of a correction (m): an aircraft's own difference
/// has it (both values in 25 ft steps, a few seconds old).
pub const OWN_DIFF_SIGMA_M: f64 = 8.0;

/// A correction to add to a barometric altitude, and its 1-sigma.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaroCorrection {
    pub diff_ft: f64,
    pub sigma_m: f64,
}

impl BaroCorrection {
    /// An aircraft's own reported difference.
    pub fn own(diff_ft: i32) -> BaroCorrection {
        BaroCorrection { diff_ft: diff_ft as f64, sigma_m: OWN_DIFF_SIGMA_M }
    }
}

/// Decayed sums of a weighted straight-line fit of the difference (ft)
/// against the altitude (kft).
#[derive(Clone, Debug, Default)]
pub struct RegionalBaro {
    t: f64,
    w: f64,
    x: f64,
    y: f64,
    xx: f64,
    xy: f64,
    yy: f64,
    /// Reports left out as outliers.
    pub outliers: u64,
    outliers_in_a_row: u32,
}

impl RegionalBaro {
    /// An aircraft's barometric altitude and its own GNSS-minus-baro
    /// difference (ft), reported at `t`.
    pub fn observe(&mut self, alt_ft: i32, diff_ft: i32, t: f64) {
        let (x, y) = (alt_ft as f64 / 1000.0, diff_ft as f64);
        if let Some(c) = self.at_kft(x) {
            if (y - c.diff_ft).abs() * FT_TO_M > OUTLIER_SIGMAS * c.sigma_m.max(OUTLIER_FLOOR_M) {
                self.outliers += 1;
                self.outliers_in_a_row += 1;
                if self.outliers_in_a_row < RELEARN_AFTER {
                    return;
                }
                // Not outliers: the difference has changed. Learnt again.
                *self = RegionalBaro { outliers: self.outliers, ..RegionalBaro::default() };
            }
        }
        self.outliers_in_a_row = 0;
        // Faded once a second at most: an exponential per report is dearer
        // than the rest of the update.
        if t > self.t + 1.0 || self.w == 0.0 {
            let k = if self.w == 0.0 { 1.0 } else { (-(t - self.t) / TIME_CONSTANT_S).exp() };
            for s in [&mut self.w, &mut self.x, &mut self.y, &mut self.xx, &mut self.xy, &mut self.yy] {
                *s *= k;
            }
            self.t = t;
        }
        self.w += 1.0;
        self.x += x;
        self.y += y;
        self.xx += x * x;
        self.xy += x * y;
        self.yy += y * y;
    }

    /// An aircraft's own difference when it reports one, else the region's.
    pub fn correction(&self, own_diff_ft: Option<i32>, alt_ft: i32) -> Option<BaroCorrection> {
        own_diff_ft.map(BaroCorrection::own).or_else(|| self.at(alt_ft))
    }

    /// The correction at a barometric altitude, once enough reports stand.
    pub fn at(&self, alt_ft: i32) -> Option<BaroCorrection> {
        self.at_kft(alt_ft as f64 / 1000.0)
    }

    fn at_kft(&self, x: f64) -> Option<BaroCorrection> {
        if self.w < MIN_WEIGHT {
            return None;
        }
        let (mx, my) = (self.x / self.w, self.y / self.w);
        let sxx = (self.xx - self.w * mx * mx).max(0.0);
        let sxy = self.xy - self.w * mx * my;
        let syy = (self.yy - self.w * my * my).max(0.0);
        let slope = if sxx / self.w >= MIN_SPREAD_KFT * MIN_SPREAD_KFT { sxy / sxx } else { 0.0 };
        // Scatter about the line (ft^2), then the line's own variance where
        // it is read (the reports are not independent, so this is a floor).
        let scatter = ((syy - slope * sxy) / self.w).max(0.0);
        let dx = x - mx;
        let line = scatter * (1.0 / self.w + if slope != 0.0 { dx * dx / sxx } else { 0.0 });
        let sigma_m = ((scatter + line).sqrt() * FT_TO_M).max(OWN_DIFF_SIGMA_M);
        Some(BaroCorrection { diff_ft: my + slope * dx, sigma_m })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn learns_a_difference_that_grows_with_altitude_and_says_how_well() {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut b = RegionalBaro::default();
        assert_eq!(b.at(10_000), None, "nothing learnt yet");
        // 150 ft at the surface, 10 ft more per 1,000 ft, reports in 25 ft
        // steps from 5,000 to 35,000 ft, with 30 ft of regional scatter.
        let truth = |alt: f64| 150.0 + 10.0 * alt / 1000.0;
        for k in 0..3_000 {
            let alt: f64 = r.gen_range(5_000.0..35_000.0);
            let diff = truth(alt) + 30.0 * (r.gen::<f64>() - 0.5) * 12f64.sqrt();
            b.observe(alt as i32, (diff / 25.0).round() as i32 * 25, k as f64 * 0.2);
        }
        for alt in [8_000, 20_000, 33_000] {
            let c = b.at(alt).expect("learnt");
            assert!((c.diff_ft - truth(alt as f64)).abs() < 5.0, "{alt}: {c:?}");
            // The scatter and the steps: about 31 ft, 9.5 m.
            assert!((c.sigma_m - 9.5).abs() < 1.5, "{alt}: {c:?}");
        }
        // A wrong difference is left out, not learnt...
        let before = b.at(20_000).unwrap();
        for k in 0..20 {
            b.observe(20_000, 2_000, 600.0 + k as f64);
        }
        assert_eq!(b.outliers, 20);
        assert!((b.at(20_000).unwrap().diff_ft - before.diff_ft).abs() < 1.0);
        // ...but one that every report has is a change, learnt again.
        for k in 0..100 {
            b.observe(20_000 + (k % 7) * 100, 2_000, 620.0 + k as f64);
        }
        assert!((b.at(20_000).unwrap().diff_ft - 2_000.0).abs() < 1.0);
    }

    #[test]
    fn one_level_gives_a_constant_and_old_reports_fade() {
        let mut b = RegionalBaro::default();
        for k in 0..100 {
            b.observe(30_000 + (k % 3) * 100, 200, k as f64);
        }
        let c = b.at(10_000).expect("learnt");
        assert!(
            (c.diff_ft - 200.0).abs() < 1e-9 && c.sigma_m == OWN_DIFF_SIGMA_M,
            "no slope from one level: {c:?}"
        );
        // The weather changes: an hour later the new difference has taken over.
        for k in 0..3_600 {
            b.observe(30_000, 100, 100.0 + k as f64);
        }
        assert!((b.at(30_000).unwrap().diff_ft - 100.0).abs() < 1.0);
    }
}
