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

/// Exponentially faded sums of a weighted straight-line fit of `y`
/// against `x`, the altitude (kft): the fit of [`RegionalBaro`] and of
/// [`GeometricBaro`].
#[derive(Clone, Debug, Default)]
struct FadedLine {
    /// When last faded.
    t: f64,
    /// Decayed count, and sums of w, w x, w x^2, w y, w x y, w y^2 and w^2.
    n: f64,
    w: f64,
    wx: f64,
    wxx: f64,
    wy: f64,
    wxy: f64,
    wyy: f64,
    ww: f64,
}

/// A [`FadedLine`]'s centred moments, and its slope (zero when the
/// altitudes spread less than [`MIN_SPREAD_KFT`]).
struct Moments {
    mx: f64,
    my: f64,
    sxx: f64,
    sxy: f64,
    syy: f64,
    slope: f64,
    sloped: bool,
}

impl FadedLine {
    /// A point of weight `w` at `t`. Faded once a second at most: an
    /// exponential per report is dearer than the rest of the update.
    fn add(&mut self, x: f64, y: f64, w: f64, t: f64) {
        if t > self.t + 1.0 || self.n == 0.0 {
            let k = if self.n == 0.0 { 1.0 } else { (-(t - self.t) / TIME_CONSTANT_S).exp() };
            for s in [
                &mut self.n,
                &mut self.w,
                &mut self.wx,
                &mut self.wxx,
                &mut self.wy,
                &mut self.wxy,
                &mut self.wyy,
                &mut self.ww,
            ] {
                *s *= k;
            }
            self.t = t;
        }
        self.n += 1.0;
        self.w += w;
        self.wx += w * x;
        self.wxx += w * x * x;
        self.wy += w * y;
        self.wxy += w * x * y;
        self.wyy += w * y * y;
        self.ww += w * w;
    }

    fn moments(&self) -> Moments {
        let (mx, my) = (self.wx / self.w, self.wy / self.w);
        let sxx = (self.wxx - self.w * mx * mx).max(0.0);
        let sxy = self.wxy - self.w * mx * my;
        let syy = (self.wyy - self.w * my * my).max(0.0);
        let sloped = sxx / self.w >= MIN_SPREAD_KFT * MIN_SPREAD_KFT;
        let slope = if sloped { sxy / sxx } else { 0.0 };
        Moments { mx, my, sxx, sxy, syy, slope, sloped }
    }
}

/// The difference (ft) against the altitude (kft), each report of weight one.
#[derive(Clone, Debug, Default)]
pub struct RegionalBaro {
    fit: FadedLine,
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
        self.fit.add(x, y, 1.0, t);
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
        let w = self.fit.w;
        if w < MIN_WEIGHT {
            return None;
        }
        let Moments { mx, my, sxx, sxy, syy, slope, .. } = self.fit.moments();
        // Scatter about the line (ft^2), then the line's own variance where
        // it is read (the reports are not independent, so this is a floor).
        let scatter = ((syy - slope * sxy) / w).max(0.0);
        let dx = x - mx;
        let line = scatter * (1.0 / w + if slope != 0.0 { dx * dx / sxx } else { 0.0 });
        let sigma_m = ((scatter + line).sqrt() * FT_TO_M).max(OWN_DIFF_SIGMA_M);
        Some(BaroCorrection { diff_ft: my + slope * dx, sigma_m })
    }
}

/// Looks (decayed) before [`GeometricBaro`] is used.
const MIN_LOOKS: f64 = 10.0;

/// The same difference seen through the multilateration geometry, for a
/// region where no aircraft reports it (Mode S-only traffic, as on
/// LocaRDS's networks, whose barometric altitudes stood 50 m above the
/// geometric heights at 5,000 m and 130 m at 10,000 m). Each
/// over-determined fix with an altitude constraint says how high the
/// aircraft is apart from the constraint, and that height minus the
/// barometric one is a look at the difference with the variance the
/// geometry gives it, often hundreds of metres: the looks are weighted by
/// it. Fitted, as [`RegionalBaro`] is, as a straight line in altitude; the
/// scatter of the aircraft about the line beyond the looks' own noise
/// (DerSimonian-Laird, at the most the looks cannot rule out) is part of
/// the correction's sigma, being what one aircraft's difference may be off
/// the region's. Old looks fade as the
/// region's reports do.
#[derive(Clone, Debug, Default)]
pub struct GeometricBaro {
    /// The difference (m) against the altitude (kft), weighted by 1/variance.
    fit: FadedLine,
}

impl GeometricBaro {
    /// A fix's height apart from its altitude constraint, `geom_m` with
    /// variance `geom_var_m2`, against the barometric altitude `alt_ft`
    /// with its own (steps, age) variance `baro_var_m2` as a height, at `t`.
    pub fn observe(&mut self, geom_m: f64, geom_var_m2: f64, alt_ft: i32, baro_var_m2: f64, t: f64) {
        let var = geom_var_m2 + baro_var_m2;
        let (x, d) = (alt_ft as f64 / 1000.0, geom_m - alt_ft as f64 * FT_TO_M);
        if !(var > 0.0 && var.is_finite() && d.is_finite()) {
            return;
        }
        self.fit.add(x, d, 1.0 / var, t);
    }

    /// The region's difference at a barometric altitude as a correction,
    /// once enough looks stand, and only when surer than `fallback_sigma_m`
    /// (the uncertainty of taking none).
    pub fn correction(&self, alt_ft: i32, fallback_sigma_m: f64) -> Option<BaroCorrection> {
        let FadedLine { n, w, ww, .. } = self.fit;
        if n < MIN_LOOKS {
            return None;
        }
        let Moments { mx, my: md, sxx, sxy: sxd, syy: sdd, slope, sloped } = self.fit.moments();
        // The weighted residual sum of squares about the line, against the
        // degrees of freedom it would have were the looks' variances all.
        let q = (sdd - slope * sxd).max(0.0);
        let dof = (n - 1.0 - sloped as u8 as f64).max(1.0);
        // Noisy looks hide a spread of tens of metres (one aircraft's looks
        // share its own difference, so they are not as many as they count):
        // the spread taken is the most the looks cannot rule out, Q two of
        // its standard deviations (sqrt(2 dof) under no spread) higher.
        let spread = w - ww / w;
        let tau2 = if spread > 0.0 { ((q - dof + (2.0 * dof).sqrt()) / spread).max(0.0) } else { 0.0 };
        // The line's own variance where it is read, scaled up when the
        // looks scatter more than their variances say.
        let dx = alt_ft as f64 / 1000.0 - mx;
        let line = (1.0 / w + if sloped { dx * dx / sxx } else { 0.0 }) * (q / dof).max(1.0);
        let sigma_m = (tau2 + line).sqrt().max(OWN_DIFF_SIGMA_M);
        let diff_m = md + slope * dx;
        (sigma_m < fallback_sigma_m).then_some(BaroCorrection { diff_ft: diff_m / FT_TO_M, sigma_m })
    }
}

/// Size of a region for [`GeometricBaros`] (degrees of latitude and of
/// longitude): about the scale over which the weather's part of the
/// difference holds, and wider than most networks' coverage of one aircraft.
const CELL_DEG: f64 = 2.0;
/// A region not looked at for this long is forgotten (s).
const CELL_FORGET_S: f64 = 6.0 * TIME_CONSTANT_S;

/// A [`GeometricBaro`] per region: the difference is a region's (weather
/// and geoid), and one network can span several (LocaRDS's sensors reach
/// from Lisbon, where the barometric altitudes were a little below the
/// geometric heights, to Zurich, where they were 130 m above).
#[derive(Clone, Debug, Default)]
pub struct GeometricBaros {
    cells: crate::FastMap<(i32, i32), GeometricBaro>,
}

impl GeometricBaros {
    fn cell(lat: f64, lon: f64) -> (i32, i32) {
        ((lat / CELL_DEG).floor() as i32, (lon / CELL_DEG).floor() as i32)
    }

    /// A look (see [`GeometricBaro::observe`]) from a fix at `lat`, `lon`.
    pub fn observe(&mut self, lat: f64, lon: f64, look: (f64, f64), alt_ft: i32, baro_var_m2: f64, t: f64) {
        let cell = self.cells.entry(Self::cell(lat, lon)).or_default();
        cell.observe(look.0, look.1, alt_ft, baro_var_m2, t);
    }

    /// The correction for an aircraft near `lat`, `lon` (see
    /// [`GeometricBaro::correction`]).
    pub fn correction(
        &self,
        lat: f64,
        lon: f64,
        alt_ft: i32,
        fallback_sigma_m: f64,
    ) -> Option<BaroCorrection> {
        self.cells.get(&Self::cell(lat, lon))?.correction(alt_ft, fallback_sigma_m)
    }

    /// Forgets regions no fix has looked at for a while.
    pub fn prune(&mut self, now: f64) {
        self.cells.retain(|_, c| now - c.fit.t <= CELL_FORGET_S);
    }

    /// Regions held.
    pub fn regions(&self) -> usize {
        self.cells.len()
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

    /// Looks at a region's difference: a line in altitude, each aircraft
    /// off it by its own amount (`scatter_m`), seen through geometries of
    /// 50 to 400 m vertical sigma. Returns the learner and the aircraft's
    /// (altitude ft, true difference m).
    fn looks(line: impl Fn(f64) -> f64, scatter_m: f64, seed: u64) -> (GeometricBaro, Vec<(i32, f64)>) {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let gauss = |r: &mut rand_chacha::ChaCha8Rng| {
            (-2.0 * (1.0 - r.gen::<f64>()).ln()).sqrt() * (std::f64::consts::TAU * r.gen::<f64>()).cos()
        };
        let mut g = GeometricBaro::default();
        let mut aircraft = Vec::new();
        for k in 0..40 {
            let alt_ft = (r.gen_range(15_000.0..39_000.0) / 100.0) as i32 * 100;
            let own = line(alt_ft as f64) + scatter_m * gauss(&mut r);
            aircraft.push((alt_ft, own));
            // A look every 10 s for a minute and a half.
            for j in 0..9 {
                let sigma: f64 = r.gen_range(50.0..400.0);
                let geom = alt_ft as f64 * FT_TO_M + own + sigma * gauss(&mut r);
                g.observe(geom, sigma * sigma, alt_ft, 25.0, (k * 9 + j) as f64 * 1.1);
            }
        }
        (g, aircraft)
    }

    #[test]
    fn the_geometry_tells_the_difference_and_how_far_one_aircraft_may_be_off_it() {
        let line = |alt_ft: f64| -30.0 - 4.0 * alt_ft / 1000.0;
        let (mut inside, mut n, mut unsure, mut sigmas) = (0, 0, 0, 0.0);
        for seed in 1..=10 {
            let (g, aircraft) = looks(line, 25.0, seed);
            for (alt_ft, own) in aircraft {
                // No surer than the 75 m of taking none: none given.
                let Some(c) = g.correction(alt_ft, 75.0) else {
                    unsure += 1;
                    continue;
                };
                let diff_m = c.diff_ft * FT_TO_M;
                // The region's line to within a few of the correction's sigmas.
                assert!((diff_m - line(alt_ft as f64)).abs() < 3.0 * c.sigma_m, "{alt_ft}: {c:?}");
                // Its sigma says how far one aircraft's own difference may be.
                assert!(c.sigma_m > 15.0, "{c:?}");
                sigmas += c.sigma_m;
                inside += ((diff_m - own).abs() <= 1.96 * c.sigma_m) as usize;
                n += 1;
            }
        }
        let (share, sigma) = (inside as f64 / n as f64, sigmas / n as f64);
        eprintln!(
            "{share:.3} of the aircraft within 1.96 sigma (mean {sigma:.0} m); {unsure} of 400 without"
        );
        assert!(unsure <= 40, "{unsure} of 400 without a correction");
        // Honest, and at most twice as wide as the aircraft's 25 m spread.
        assert!(share >= 0.9 && sigma < 50.0, "{share} within 1.96 sigma, mean sigma {sigma:.0} m");
    }

    #[test]
    fn too_few_looks_or_too_vague_ones_give_no_correction() {
        let mut g = GeometricBaro::default();
        for k in 0..5 {
            g.observe(10_000.0 - 90.0, 100.0f64.powi(2), (10_000.0 / FT_TO_M) as i32, 25.0, k as f64);
        }
        assert_eq!(g.correction(33_000, 75.0), None, "five looks");
        // Looks so vague that the correction would be no surer than none.
        let mut g = GeometricBaro::default();
        for k in 0..100 {
            let e = if k % 2 == 0 { 2_000.0 } else { -2_000.0 };
            g.observe(10_000.0 + e, 2_000.0f64.powi(2), (10_000.0 / FT_TO_M) as i32, 25.0, k as f64);
        }
        assert_eq!(g.correction(33_000, 75.0), None);
    }

    #[test]
    fn regions_are_learnt_apart_and_forgotten() {
        let mut g = GeometricBaros::default();
        let alt_ft = 33_000;
        for k in 0..60 {
            let h = alt_ft as f64 * FT_TO_M;
            let wobble = if k % 2 == 0 { 10.0 } else { -10.0 };
            g.observe(47.3, 8.5, (h - 130.0 + wobble, 50.0f64.powi(2)), alt_ft, 25.0, k as f64);
            g.observe(38.9, -9.1, (h + 15.0 + wobble, 50.0f64.powi(2)), alt_ft, 25.0, k as f64);
        }
        let zurich = g.correction(47.0, 8.0, alt_ft, 75.0).unwrap().diff_ft * FT_TO_M;
        let lisbon = g.correction(38.5, -9.5, alt_ft, 75.0).unwrap().diff_ft * FT_TO_M;
        assert!((zurich + 130.0).abs() < 10.0 && (lisbon - 15.0).abs() < 10.0, "{zurich} {lisbon}");
        assert_eq!(g.correction(52.0, 4.0, alt_ft, 75.0), None, "nothing looked at there");
        g.prune(60.0 + CELL_FORGET_S + 1.0);
        assert_eq!(g.regions(), 0);
    }
}
