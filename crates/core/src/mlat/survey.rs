//! Where a receiver's antenna really is, from the ADS-B traffic it hears.
//!
//! A receiver declared `delta` from where it is hears every transmission
//! `u . delta` later (over `c`) than its declared position predicts, `u`
//! being the unit vector from the aircraft to the receiver: with aircraft
//! all around, those excesses pin `delta` down. Each ADS-B position that
//! is multilaterated gives, per receiver, its excess range against the
//! emission time the *other* receivers put on the transmission (leave one
//! out, so that its own error does not pull the reference). A least-squares
//! fit of `d = u . delta + b` over the recent traffic (`b` absorbs a
//! constant timing offset: a GPS receiver's bias, or what a counter's clock
//! filter kept) gives `delta` with its covariance, inflated by the fit's
//! own residuals so that it never claims more than the data support.
//!
//! A mistyped receiver location is one of the commonest faults in
//! community networks; this finds it, and says how sure it is.

use nalgebra::{Matrix4, Vector4};

use super::state::SurveySnapshot;

/// The fit's memory, in measurements: slow forgetting, so that a receiver
/// moved (or corrected) is found again.
const MEMORY: f64 = 5_000.0;
/// Measurements before an estimate is given: a dozen per unknown. Early
/// estimates are rough, but their covariance grows with the fit's
/// residuals, and an early one must stand further out of it
/// ([`MISPLACED_SIGMAS_EARLY`]) to call the receiver misplaced.
const MIN_MEASUREMENTS: f64 = 50.0;

/// One receiver's position survey: weighted normal equations of
/// `[east, north, up, offset]`, forgotten slowly.
#[derive(Clone, Debug, PartialEq)]
pub struct Survey {
    a: Matrix4<f64>,
    b: Vector4<f64>,
    /// Weighted sum of squared excesses (for the residuals' chi-square).
    dd: f64,
    /// Measurements, as forgotten, and in all.
    n: f64,
    count: u64,
    /// When its first and its latest measurements were taken (s).
    since: f64,
    last: f64,
}

impl Default for Survey {
    fn default() -> Self {
        Survey { a: Matrix4::zeros(), b: Vector4::zeros(), dd: 0.0, n: 0.0, count: 0, since: 0.0, last: 0.0 }
    }
}

/// A surveyed offset beyond this (m, and [`MISPLACED_SIGMAS`] of its
/// sigmas) is a misplaced receiver.
pub const MISPLACED_M: f64 = 30.0;
/// The survey is judged again every few dozen measurements for as long as
/// the receiver runs, and its estimate wanders as one: the chance that an
/// honest receiver's estimate strays past the threshold at some look is
/// many times the chance at one look (3e-4 at four sigmas, 4e-6 at five):
/// at four, honest receivers (noisy ones and those with multipath most)
/// were left out for seconds to a minute (docs/multilateration.md). An
/// offset of 150 m still stands out within the survey's first minute.
const MISPLACED_SIGMAS: f64 = 5.0;
/// Until its measurements span this long (s), a survey's offset must be
/// [`MISPLACED_SIGMAS_EARLY`] sigmas out. Its first seconds' measurements
/// are alike (the same few aircraft, clock pairs still settling), which
/// its sigma, taking them as independent, does not know: an honest
/// counter's survey can stand over five of its sigmas out for its first
/// seconds on a busy network, fading as the traffic changes. A misplaced
/// receiver found sooner pulls fewer fixes.
const SETTLED_S: f64 = 30.0;
const MISPLACED_SIGMAS_EARLY: f64 = 6.5;
/// A survey less sure than this (m, 1 sigma) judges nothing: its traffic
/// came from too few directions (one aircraft's track, say), where the
/// fit's linearisation and its residual-scaled sigma both fail and a
/// sigma of kilometres stood four of itself out.
const JUDGING_SIGMA_M: f64 = 100.0;

/// A position offset found: where the antenna is against where it is
/// declared (east, north, up m), and the horizontal 1-sigma per axis (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Offset {
    pub enu_m: [f64; 3],
    pub sigma_m: f64,
    /// Its measurements span [`SETTLED_S`] or more.
    pub settled: bool,
}

impl Offset {
    /// Its horizontal distance (m).
    pub fn horizontal_m(&self) -> f64 {
        self.enu_m[0].hypot(self.enu_m[1])
    }

    /// Whether the receiver is misplaced, beyond doubt: the run report
    /// names it, and `self_survey` moves it.
    pub fn misplaced(&self) -> bool {
        let off = self.horizontal_m();
        let sigmas = if self.settled { MISPLACED_SIGMAS } else { MISPLACED_SIGMAS_EARLY };
        self.sigma_m <= JUDGING_SIGMA_M && off > MISPLACED_M && off > sigmas * self.sigma_m
    }
}

impl Survey {
    /// One transmission: the excess range `d_m` (measured less predicted,
    /// m) with its variance, along `u_enu`, the unit vector from the
    /// aircraft to the receiver in the receiver's east-north-up frame.
    pub fn add(&mut self, u_enu: [f64; 3], d_m: f64, var_m2: f64, now: f64) {
        if !(d_m.is_finite() && var_m2 > 0.0 && var_m2.is_finite()) {
            return;
        }
        if self.count == 0 {
            self.since = now;
        }
        self.last = now;
        let keep = 1.0 - 1.0 / MEMORY;
        let x = Vector4::new(u_enu[0], u_enu[1], u_enu[2], 1.0);
        let w = 1.0 / var_m2;
        self.a = self.a * keep + x * x.transpose() * w;
        self.b = self.b * keep + x * (w * d_m);
        self.dd = self.dd * keep + w * d_m * d_m;
        self.n = self.n * keep + 1.0;
        self.count += 1;
    }

    /// Measurements taken in all.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Its state, to be kept across a restart.
    pub fn snapshot(&self) -> SurveySnapshot {
        SurveySnapshot {
            a: self.a.as_slice().to_vec(),
            b: self.b.as_slice().to_vec(),
            dd: self.dd,
            n: self.n,
            count: self.count,
            since: self.since,
            last: self.last,
        }
    }

    /// A survey as it was saved (`None` if the snapshot is malformed).
    pub fn from_snapshot(s: &SurveySnapshot) -> Option<Survey> {
        let finite = s.a.iter().chain(&s.b).chain([&s.dd, &s.n, &s.since, &s.last]).all(|v| v.is_finite());
        (s.a.len() == 16 && s.b.len() == 4 && finite).then(|| Survey {
            a: Matrix4::from_column_slice(&s.a),
            b: Vector4::from_column_slice(&s.b),
            dd: s.dd,
            n: s.n,
            count: s.count,
            since: s.since,
            last: s.last,
        })
    }

    /// The offset, once enough traffic from enough directions was heard.
    pub fn offset(&self) -> Option<Offset> {
        if self.n < MIN_MEASUREMENTS {
            return None;
        }
        let inv = self.a.try_inverse()?;
        let x = inv * self.b;
        // Residual chi-square per degree of freedom: above 1, the variances
        // assumed were too small, and the covariance grows with it.
        let chi2 = (self.dd - self.b.dot(&x)).max(0.0);
        let scale = (chi2 / (self.n - 4.0)).max(1.0);
        let (vee, vnn) = (inv[(0, 0)] * scale, inv[(1, 1)] * scale);
        let sigma_m = ((vee + vnn) / 2.0).sqrt();
        (sigma_m.is_finite() && x.iter().all(|v| v.is_finite())).then_some(Offset {
            enu_m: [x[0], x[1], x[2]],
            sigma_m,
            settled: self.last - self.since >= SETTLED_S,
        })
    }
}

/// The east, north and up unit vectors at a geodetic position (deg), in ECEF.
pub fn enu_basis(lat_deg: f64, lon_deg: f64) -> [[f64; 3]; 3] {
    let (sp, cp) = lat_deg.to_radians().sin_cos();
    let (sl, cl) = lon_deg.to_radians().sin_cos();
    [[-sl, cl, 0.0], [-sp * cl, -sp * sl, cp], [cp * cl, cp * sl, sp]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// Aircraft all around and at various elevations, 30 m of noise a
    /// measurement and a 200 m timing offset: the 150 m offset is found
    /// within its own sigma's few metres, and the sigma is honest.
    #[test]
    fn an_offset_is_found_from_directions_all_around() {
        let truth = [120.0, -90.0, 5.0];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, 30.0).unwrap();
        let mut s = Survey::default();
        assert_eq!(s.offset(), None);
        for k in 0..2_000 {
            let az: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
            let el: f64 = rng.gen_range(0.01..0.3);
            // From the aircraft to the receiver: down and away from it.
            let u = [-az.sin() * el.cos(), -az.cos() * el.cos(), -el.sin()];
            let d = u[0] * truth[0] + u[1] * truth[1] + u[2] * truth[2] + 200.0 + noise.sample(&mut rng);
            s.add(u, d, 30.0 * 30.0, k as f64 * 0.1);
        }
        let o = s.offset().unwrap();
        let err = (o.enu_m[0] - truth[0]).hypot(o.enu_m[1] - truth[1]);
        assert!(err < 3.0 * o.sigma_m * std::f64::consts::SQRT_2, "{o:?}");
        assert!(o.sigma_m < 3.0 && o.sigma_m > 0.5, "{o:?}");
        // Told a third of the real noise, the fit's residuals correct it.
        let mut told_less = Survey::default();
        for k in 0..2_000 {
            let az: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
            let u = [-az.sin(), -az.cos(), -0.1];
            let d = u[0] * truth[0] + u[1] * truth[1] + noise.sample(&mut rng);
            told_less.add(u, d, 10.0 * 10.0, k as f64 * 0.1);
        }
        let o2 = told_less.offset().unwrap();
        assert!(o2.sigma_m > 0.9 * o.sigma_m, "{o2:?} against {o:?}");
    }

    /// The same evidence, five to six sigmas out: not enough over a survey's
    /// first seconds, enough once its measurements span long enough; and a
    /// receiver far out is called misplaced at once.
    #[test]
    fn an_early_survey_needs_more_evidence() {
        let survey = |truth: [f64; 2], span_s: f64| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
            let noise = Normal::new(0.0, 120.0).unwrap();
            let mut s = Survey::default();
            for k in 0..400 {
                let az: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
                let el: f64 = rng.gen_range(0.05..0.3);
                let u = [-az.sin() * el.cos(), -az.cos() * el.cos(), -el.sin()];
                let d = u[0] * truth[0] + u[1] * truth[1] + noise.sample(&mut rng);
                s.add(u, d, 120.0 * 120.0, k as f64 * span_s / 399.0);
            }
            s.offset().unwrap()
        };
        let early = survey([60.0, 0.0], 10.0);
        let z = early.horizontal_m() / early.sigma_m;
        assert!(!early.settled && (MISPLACED_SIGMAS..MISPLACED_SIGMAS_EARLY).contains(&z), "{early:?} {z}");
        assert!(!early.misplaced());
        let settled = survey([60.0, 0.0], 60.0);
        assert!(settled.settled && settled.misplaced(), "{settled:?}");
        assert!(survey([150.0, 0.0], 10.0).misplaced());
    }

    #[test]
    fn traffic_from_one_direction_only_gives_no_offset() {
        let mut s = Survey::default();
        for k in 0..1_000 {
            s.add([0.0, -1.0, 0.0], 10.0 + (k % 7) as f64, 100.0, k as f64);
        }
        // East and up are not observable: no (finite) answer is claimed.
        assert!(s.offset().is_none_or(|o| o.sigma_m > 1e3), "{:?}", s.offset());
        // Nor is the receiver called misplaced on it.
        assert!(s.offset().is_none_or(|o| !o.misplaced()), "{:?}", s.offset());
    }

    #[test]
    fn the_basis_is_east_north_up() {
        let [e, n, u] = enu_basis(0.0, 0.0);
        assert_eq!((e, n, u), ([0.0, 1.0, 0.0], [-0.0, -0.0, 1.0], [1.0, 0.0, 0.0]));
    }
}
