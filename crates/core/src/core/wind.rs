//! The air the aircraft fly through, learnt from the aircraft that report
//! both ways: their ADS-B ground velocity and their Comm-B heading and speed
//! (6,0). It turns the heading and airspeed of an aircraft without ADS-B
//! into a ground velocity, with the uncertainty of what was learnt.
//!
//! Ground velocity is the velocity through the air turned by the magnetic
//! variation, scaled by how far the day's temperature (which sets true
//! airspeed from Mach) departs from the standard one, plus the wind:
//!
//! ```text
//! g_e =  p a_e + q a_n + w_e(h)        p = k cos(variation)
//! g_n = -q a_e + p a_n + w_n(h)        q = k sin(variation)
//! ```
//!
//! which is linear in (p, q, the winds), so one Kalman filter learns them
//! all. The variation and the temperature's scale are the region's, the
//! wind is the height's: a wind per 1,000 m layer, interpolated between the
//! layers' middles. Nearby layers' winds start correlated (a prior over the
//! profile, correlation length 3 km), so a layer nobody reports from leans
//! on its neighbours with their uncertainty, and the winds drift slowly
//! (random walk), so the weather can turn. The wind varies across the
//! region too; that scatter, learnt from the innovations beyond what the
//! model explains, is part of every prediction's uncertainty, and it is
//! the same for one aircraft's reports over minutes, which is why it is
//! given apart ([`Prediction::persistent`]).

use nalgebra::{DMatrix, DVector, Matrix2, Vector2};

use crate::mlat::state::AirSnapshot;

/// Layer thickness (m) and how many (from the ground up to 16,000 m).
const LAYER_M: f64 = 1000.0;
const LAYERS: usize = 16;
const N: usize = 2 + 2 * LAYERS;
/// Prior of the temperature's scale on true airspeed (a 15 deg C departure
/// changes the speed of sound by 2.5 to 3%).
const SCALE_PRIOR_SIGMA: f64 = 0.03;
/// Prior of the magnetic variation (rad): about 20 degrees, the range over
/// most inhabited latitudes.
const VARIATION_PRIOR_SIGMA_RAD: f64 = 0.35;
/// Prior of each wind component (m/s), and how far apart (m) layers'
/// winds are still much alike.
const WIND_PRIOR_SIGMA_MS: f64 = 25.0;
const WIND_CORRELATION_M: f64 = 3000.0;
/// How fast the wind may change (m/s over an hour, per component).
const WIND_DRIFT_MS_PER_HOUR: f64 = 5.0;
/// The wind's spread across the region (m/s) before any is learnt, and the
/// weight of each innovation in learning it.
const SCATTER_START_MS: f64 = 3.0;
const SCATTER_WEIGHT: f64 = 0.01;
/// A report further than this (chi-square, two degrees of freedom: one in
/// 10^8 by chance) from what was learnt does not teach: a misread register,
/// a wrong velocity.
const OUTLIER_CHI2: f64 = 37.0;

/// A velocity through the air: east and north (m/s) along the magnetic
/// heading, and its covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AirVector {
    pub en: Vector2<f64>,
    pub cov: Matrix2<f64>,
}

/// A ground velocity predicted from an air vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prediction {
    pub v_en: Vector2<f64>,
    /// The part of its error that one aircraft's reports share: what is not
    /// yet learnt, and the wind's spread across the region.
    pub persistent: Matrix2<f64>,
    /// The part each report has alone: the register's steps and age.
    pub independent: Matrix2<f64>,
}

/// What was learnt, for the stats.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WindStats {
    pub learnt: u64,
    pub outliers: u64,
}

pub struct WindField {
    x: DVector<f64>,
    p: DMatrix<f64>,
    /// The layers' winds' correlation, for the drift.
    corr: DMatrix<f64>,
    scatter_var: f64,
    t: Option<f64>,
    pub stats: WindStats,
}

impl Default for WindField {
    fn default() -> Self {
        let corr = DMatrix::from_fn(LAYERS, LAYERS, |i, j| {
            (-(i as f64 - j as f64).abs() * LAYER_M / WIND_CORRELATION_M).exp()
        });
        let mut p = DMatrix::zeros(N, N);
        p[(0, 0)] = SCALE_PRIOR_SIGMA.powi(2);
        p[(1, 1)] = VARIATION_PRIOR_SIGMA_RAD.powi(2);
        for i in 0..LAYERS {
            for j in 0..LAYERS {
                for axis in 0..2 {
                    p[(2 + 2 * i + axis, 2 + 2 * j + axis)] = WIND_PRIOR_SIGMA_MS.powi(2) * corr[(i, j)];
                }
            }
        }
        let mut x = DVector::zeros(N);
        x[0] = 1.0;
        WindField { x, p, corr, scatter_var: SCATTER_START_MS.powi(2), t: None, stats: WindStats::default() }
    }
}

/// The two layers around height `alt_m` and the upper one's weight.
fn layers(alt_m: f64) -> (usize, usize, f64) {
    let u = (alt_m / LAYER_M - 0.5).clamp(0.0, (LAYERS - 1) as f64);
    let lo = (u.floor() as usize).min(LAYERS - 2);
    (lo, lo + 1, u - lo as f64)
}

impl WindField {
    /// The observation matrix of an air vector at `alt_m`.
    fn h(&self, alt_m: f64, a: Vector2<f64>) -> DMatrix<f64> {
        let mut h = DMatrix::zeros(2, N);
        h[(0, 0)] = a[0];
        h[(0, 1)] = a[1];
        h[(1, 0)] = a[1];
        h[(1, 1)] = -a[0];
        let (lo, hi, f) = layers(alt_m);
        for (layer, w) in [(lo, 1.0 - f), (hi, f)] {
            h[(0, 2 + 2 * layer)] = w;
            h[(1, 3 + 2 * layer)] = w;
        }
        h
    }

    /// The turning and scaling, as it acts on the air vector's error.
    fn rotation(&self) -> Matrix2<f64> {
        let (p, q) = (self.x[0], self.x[1]);
        Matrix2::new(p, q, -q, p)
    }

    /// Lets the winds drift up to `t` (Unix s).
    fn advance(&mut self, t: f64) {
        let dt = self.t.map_or(0.0, |t0| (t - t0).max(0.0));
        self.t = Some(self.t.map_or(t, |t0| t0.max(t)));
        if dt <= 0.0 {
            return;
        }
        let q = WIND_DRIFT_MS_PER_HOUR.powi(2) * dt / 3600.0;
        for i in 0..LAYERS {
            for j in 0..LAYERS {
                for axis in 0..2 {
                    self.p[(2 + 2 * i + axis, 2 + 2 * j + axis)] += q * self.corr[(i, j)];
                }
            }
        }
    }

    /// Learns from an aircraft at height `alt_m` whose air vector is `air`
    /// and ground velocity `ground` (with its covariance) at `t`; `shared`
    /// is how many of its reports lately share this one's share of the
    /// regional spread. Returns whether it taught (not an outlier).
    pub fn learn(
        &mut self,
        t: f64,
        alt_m: f64,
        air: &AirVector,
        ground: Vector2<f64>,
        ground_cov: Matrix2<f64>,
        shared: f64,
    ) -> bool {
        self.advance(t);
        let h = self.h(alt_m, air.en);
        let rot = self.rotation();
        let own = rot * air.cov * rot.transpose() + ground_cov;
        let nu = ground - to2(&(&h * &self.x));
        let hph = to22(&(&h * &self.p * h.transpose()));
        let s = hph + own + Matrix2::identity() * self.scatter_var * shared.max(1.0);
        let Some(s_inv) = s.try_inverse() else { return false };
        if (nu.transpose() * s_inv * nu)[0] > OUTLIER_CHI2 {
            self.stats.outliers += 1;
            return false;
        }
        // What the innovation shows beyond the model's and the reports' own
        // uncertainty is the wind's spread, per axis.
        let excess = (nu.norm_squared() - (hph + own).trace()) / 2.0;
        self.scatter_var += SCATTER_WEIGHT * (excess.max(0.0) - self.scatter_var);
        let ht = h.transpose();
        let k = &self.p * &ht * from22(&s_inv);
        self.x += &k * from2(&nu);
        let khp = &k * &h * &self.p;
        self.p -= khp;
        self.p = (&self.p + self.p.transpose()) * 0.5;
        self.stats.learnt += 1;
        true
    }

    /// The ground velocity of an aircraft at height `alt_m` whose air vector
    /// is `air`.
    pub fn predict(&self, alt_m: f64, air: &AirVector) -> Prediction {
        let h = self.h(alt_m, air.en);
        let rot = self.rotation();
        Prediction {
            v_en: to2(&(&h * &self.x)),
            persistent: to22(&(&h * &self.p * h.transpose())) + Matrix2::identity() * self.scatter_var,
            independent: rot * air.cov * rot.transpose(),
        }
    }

    /// The magnetic variation learnt (deg, east positive) and its sigma.
    pub fn variation_deg(&self) -> (f64, f64) {
        let (p, q) = (self.x[0], self.x[1]);
        (q.atan2(p).to_degrees(), (self.p[(1, 1)].sqrt() / p.hypot(q)).to_degrees())
    }

    /// The wind learnt at height `alt_m` (east, north; m/s) and each
    /// component's sigma.
    pub fn wind_at(&self, alt_m: f64) -> (Vector2<f64>, Vector2<f64>) {
        let (lo, hi, f) = layers(alt_m);
        let w = |axis: usize| {
            let (a, b) = (2 + 2 * lo + axis, 2 + 2 * hi + axis);
            let mean = (1.0 - f) * self.x[a] + f * self.x[b];
            let var = (1.0 - f).powi(2) * self.p[(a, a)]
                + f * f * self.p[(b, b)]
                + 2.0 * f * (1.0 - f) * self.p[(a, b)];
            (mean, var.max(0.0).sqrt())
        };
        let (e, n) = (w(0), w(1));
        (Vector2::new(e.0, n.0), Vector2::new(e.1, n.1))
    }

    /// The wind's spread across the region learnt (m/s, per component).
    pub fn scatter_ms(&self) -> f64 {
        self.scatter_var.sqrt()
    }

    /// What was learnt, to be kept across a restart (`None` before anything was).
    pub fn snapshot(&self) -> Option<AirSnapshot> {
        (self.stats.learnt > 0).then(|| AirSnapshot {
            x: self.x.iter().copied().collect(),
            p: self.p.transpose().iter().copied().collect(),
            scatter_var: self.scatter_var,
            t: self.t.unwrap_or(0.0),
            learnt: self.stats.learnt,
        })
    }

    /// Takes up what a previous run learnt, the winds having drifted since
    /// (to `now`, Unix s); false, and nothing taken, for a snapshot of
    /// another shape or with values no learner makes.
    pub fn restore(&mut self, s: &AirSnapshot, now: f64) -> bool {
        let sane = s.x.len() == N
            && s.p.len() == N * N
            && s.x.iter().chain(&s.p).all(|v| v.is_finite())
            && (0..N).all(|i| s.p[i * N + i] >= 0.0)
            && s.scatter_var.is_finite()
            && s.scatter_var >= 0.0
            && s.t.is_finite();
        if !sane {
            return false;
        }
        self.x = DVector::from_column_slice(&s.x);
        self.p = DMatrix::from_row_slice(N, N, &s.p);
        self.scatter_var = s.scatter_var;
        self.t = Some(s.t);
        self.stats.learnt = s.learnt;
        self.advance(now);
        true
    }
}

fn to2(v: &DVector<f64>) -> Vector2<f64> {
    Vector2::new(v[0], v[1])
}
fn to22(m: &DMatrix<f64>) -> Matrix2<f64> {
    Matrix2::new(m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)])
}
fn from22(m: &Matrix2<f64>) -> DMatrix<f64> {
    DMatrix::from_row_slice(2, 2, &[m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)]])
}
fn from2(v: &Vector2<f64>) -> DVector<f64> {
    DVector::from_column_slice(&[v[0], v[1]])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Air vector of a magnetic heading (deg) and true airspeed (m/s).
    fn air(heading_deg: f64, tas: f64) -> AirVector {
        let (s, c) = heading_deg.to_radians().sin_cos();
        AirVector { en: Vector2::new(s, c) * tas, cov: Matrix2::identity() * 0.5 }
    }

    /// Aircraft at several heights and headings in a world with a wind
    /// profile, 4 degrees of variation and a 2% warmer air: what is learnt
    /// predicts a new aircraft's ground velocity within its uncertainty.
    #[test]
    fn wind_variation_and_temperature_learnt_from_aircraft_reporting_both() {
        let variation = 4f64.to_radians();
        let scale = 1.02;
        let wind = |h: f64| Vector2::new(5.0 + 3.0 * h / 1000.0, -2.0 + 1.5 * h / 1000.0);
        let truth = |heading_deg: f64, tas: f64, h: f64| {
            let (s, c) = (heading_deg.to_radians() + variation).sin_cos();
            Vector2::new(s, c) * tas * scale + wind(h)
        };
        let mut f = WindField::default();
        let mut t = 0.0;
        for k in 0..600 {
            let heading = (k * 37 % 360) as f64;
            let h = 500.0 + (k * 613 % 11_000) as f64;
            t += 1.0;
            let g = truth(heading, 200.0, h);
            assert!(f.learn(t, h, &air(heading, 200.0), g, Matrix2::identity() * 0.25, 1.0));
        }
        let (var_deg, var_sigma) = f.variation_deg();
        assert!((var_deg - 4.0).abs() < 0.3 && var_sigma < 0.3, "{var_deg} {var_sigma}");
        let (w, w_sigma) = f.wind_at(7_000.0);
        assert!((w - wind(7_000.0)).norm() < 1.5 && w_sigma.max() < 1.5, "{w} {w_sigma}");
        // A new heading at a height in between: within 3 sigma, and the
        // sigma is a few m/s, not the prior's tens.
        let p = f.predict(6_300.0, &air(123.0, 230.0));
        let cov = p.persistent + p.independent;
        let err = p.v_en - truth(123.0, 230.0, 6_300.0);
        assert!((err.transpose() * cov.try_inverse().unwrap() * err)[0] < 9.0, "{err} {cov}");
        assert!(cov.trace().sqrt() < 3.0, "{cov}");
    }

    /// Kept across a restart: the same estimate, the winds less certain by
    /// the hours they may have drifted, the variation as sure; a snapshot
    /// of another shape or with values no learner makes is refused.
    #[test]
    fn what_was_learnt_survives_a_restart_and_the_wind_ages() {
        let mut f = WindField::default();
        assert!(f.snapshot().is_none());
        for k in 0..300 {
            let heading = (k * 41 % 360) as f64;
            let (s, c) = heading.to_radians().sin_cos();
            let g = Vector2::new(s, c) * 200.0 + Vector2::new(10.0, -5.0);
            f.learn(k as f64, 8_000.0, &air(heading, 200.0), g, Matrix2::identity() * 0.25, 1.0);
        }
        let snap = f.snapshot().unwrap();
        let mut g = WindField::default();
        assert!(g.restore(&snap, 300.0));
        assert_eq!(g.wind_at(8_000.0).0, f.wind_at(8_000.0).0);
        assert_eq!(g.variation_deg(), f.variation_deg());
        let mut later = WindField::default();
        assert!(later.restore(&snap, 300.0 + 4.0 * 3600.0));
        // At a layer's middle, four hours at 5 m/s an hour: 10 m/s more, in quadrature.
        let (sigma, aged) = (f.wind_at(7_500.0).1[0], later.wind_at(7_500.0).1[0]);
        assert!((aged - (sigma * sigma + 100.0).sqrt()).abs() < 0.1, "{sigma} {aged}");
        assert_eq!(later.variation_deg(), f.variation_deg());
        let mut bad = snap.clone();
        bad.x.pop();
        assert!(!WindField::default().restore(&bad, 0.0));
        let mut bad = snap;
        bad.p[0] = f64::NAN;
        assert!(!WindField::default().restore(&bad, 0.0));
    }

    /// A report far off what was learnt (a misread register) is counted
    /// and teaches nothing; before anything is learnt, a prediction says it
    /// knows little.
    #[test]
    fn an_outlier_is_counted_and_an_unlearnt_prediction_is_wide() {
        let mut f = WindField::default();
        let p = f.predict(9_000.0, &air(90.0, 220.0));
        assert!(p.persistent.trace().sqrt() > 50.0, "{}", p.persistent);
        for k in 0..200 {
            let heading = (k * 53 % 360) as f64;
            let (s, c) = heading.to_radians().sin_cos();
            let g = Vector2::new(s, c) * 220.0 + Vector2::new(20.0, 0.0);
            f.learn(k as f64, 9_000.0, &air(heading, 220.0), g, Matrix2::identity() * 0.25, 1.0);
        }
        let before = f.wind_at(9_000.0).0;
        let wrong = Vector2::new(-150.0, 40.0);
        assert!(!f.learn(300.0, 9_000.0, &air(0.0, 220.0), wrong, Matrix2::identity() * 0.25, 1.0));
        assert_eq!(f.stats.outliers, 1);
        assert_eq!(f.wind_at(9_000.0).0, before);
        assert!((before - Vector2::new(20.0, 0.0)).norm() < 1.0, "{before}");
    }
}
