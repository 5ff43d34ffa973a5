//! Kalman predictor and updater for the 6-state horizontal model, with any
//! linear measurement (position, velocity). The covariance update is the
//! short form `P - K S K'`, symmetrised: the Joseph form costs three times
//! the multiplications (a fifth of an IMM step) and changed no figure of the
//! Monte Carlo tables in double precision; every step still checks that the
//! covariance is positive definite and reports a filter that went
//! numerically bad instead of publishing it.

use nalgebra::{Matrix2, Matrix2x6, Matrix6, SMatrix, SVector, Vector2, Vector6};

/// A state estimate: mean `[e, n, ve, vn, ae, an]` (m, m/s, m/s^2) and covariance.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Gaussian {
    pub x: Vector6<f64>,
    pub p: Matrix6<f64>,
}

/// A linear measurement `z = H x + v`, `v ~ N(0, R)`, of `M` components.
/// Made by [`Linear::new`]; to change `H`, make a new one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Linear<const M: usize> {
    pub h: SMatrix<f64, M, 6>,
    pub z: SVector<f64, M>,
    pub r: SMatrix<f64, M, M>,
    /// [`Linear::find_selection`] of `h`, found once: asked at every use (per
    /// model, and for the gate and the combined NIS), the comparisons were
    /// 6% of an IMM update's instructions.
    selection: Option<usize>,
}

impl<const M: usize> Linear<M> {
    pub fn new(h: SMatrix<f64, M, 6>, z: SVector<f64, M>, r: SMatrix<f64, M, M>) -> Linear<M> {
        Linear { h, z, r, selection: Self::find_selection(&h) }
    }

    /// The same measurement with another noise covariance.
    pub fn with_r(self, r: SMatrix<f64, M, M>) -> Linear<M> {
        Linear { r, ..self }
    }

    /// `Some(k)` when `H` only picks the state's components `k..k + M` (the
    /// position and velocity measurements): `H x`, `H P H'` and `P H'` are
    /// then parts of `x` and `P`, the same numbers as the products (times
    /// 0 and 1, plus 0) without a third of an update's multiplications.
    fn find_selection(h: &SMatrix<f64, M, 6>) -> Option<usize> {
        // Compared whole against the two known forms: a search over
        // offsets cost half of what it saved.
        let picks = |k: usize| SMatrix::<f64, M, 6>::from_fn(|i, j| (j == k + i) as u8 as f64);
        [0, 2].into_iter().find(|&k| *h == picks(k))
    }
}

/// A horizontal position measurement (east, north; m) with its covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosMeasurement {
    pub z: Vector2<f64>,
    pub r: Matrix2<f64>,
}

impl PosMeasurement {
    pub fn linear(&self) -> Linear<2> {
        Linear::new(h(), self.z, self.r)
    }
}

/// A horizontal velocity measurement (east, north; m/s).
pub fn velocity(z: Vector2<f64>, r: Matrix2<f64>) -> Linear<2> {
    Linear::new(Matrix2x6::new(0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0), z, r)
}

/// The result of an update: the posterior and the innovation statistics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Updated {
    pub post: Gaussian,
    /// Normalised innovation squared (chi-square with M dof when consistent).
    pub nis: f64,
    /// The likelihood's normaliser, (2 pi)^(M/2) sqrt(det S): the measurement
    /// likelihood N(innovation; 0, S) is exp(-nis / 2) / `norm`. Kept apart
    /// because the likelihood itself underflows for a far-off measurement,
    /// and the IMM compares models without taking logarithms.
    pub norm: f64,
}

impl Updated {
    /// Logarithm of the measurement likelihood.
    pub fn log_likelihood(&self) -> f64 {
        -0.5 * self.nis - self.norm.ln()
    }
}

/// Position rows of the state.
pub fn h() -> Matrix2x6<f64> {
    Matrix2x6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0)
}

impl Gaussian {
    pub fn predict(&self, f: &Matrix6<f64>, q: &Matrix6<f64>) -> Gaussian {
        Gaussian { x: f * self.x, p: f * self.p * f.transpose() + q }
    }

    /// `None` when the innovation covariance is not positive definite.
    pub fn update(&self, m: &PosMeasurement) -> Option<Updated> {
        self.update_linear(&m.linear())
    }

    /// Innovation and its covariance `(z - H x, H P H' + R)`.
    pub fn innovation<const M: usize>(&self, m: &Linear<M>) -> (SVector<f64, M>, SMatrix<f64, M, M>) {
        match m.selection {
            Some(k) => (m.z - self.x.fixed_rows::<M>(k), self.p.fixed_view::<M, M>(k, k).into_owned() + m.r),
            None => (m.z - m.h * self.x, m.h * self.p * m.h.transpose() + m.r),
        }
    }

    pub fn update_linear<const M: usize>(&self, m: &Linear<M>) -> Option<Updated> {
        let (nu, s) = self.innovation(m);
        // Positive definite or nothing: a determinant alone passes -S.
        let chol = s.cholesky()?;
        let s_inv = chol.inverse();
        let det = chol.l().diagonal().product().powi(2);
        if !(det > 0.0 && det.is_finite()) {
            return None;
        }
        let pht = match m.selection {
            Some(k) => self.p.fixed_columns::<M>(k).into_owned(),
            None => self.p * m.h.transpose(),
        };
        let k = pht * s_inv;
        let p = self.p - k * pht.transpose();
        let nis = (nu.transpose() * s_inv * nu)[0];
        let two_pi_pow = (2.0 * std::f64::consts::PI).powi(M as i32 / 2)
            * if M % 2 == 1 { (2.0 * std::f64::consts::PI).sqrt() } else { 1.0 };
        Some(Updated {
            post: Gaussian { x: self.x + k * nu, p: (p + p.transpose()) * 0.5 },
            nis,
            norm: two_pi_pow * det.sqrt(),
        })
    }

    /// Mean and covariance finite, the covariance positive definite.
    pub fn healthy(&self) -> bool {
        // Over the plain arrays: nalgebra's element iterator cost a tenth of an
        // IMM update for these 42 checks.
        self.x.as_slice().iter().chain(self.p.as_slice()).all(|v| v.is_finite())
            && self.p.cholesky().is_some()
    }
}

/// A zero state with a diagonal covariance.
pub fn diagonal(x: Vector6<f64>, var: [f64; 6]) -> Gaussian {
    Gaussian { x, p: Matrix6::from_diagonal(&Vector6::from(var)) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn update_moves_towards_the_measurement_by_the_gain() {
        let g = Gaussian { x: Vector6::zeros(), p: Matrix6::identity() * 100.0 };
        let m = PosMeasurement { z: Vector2::new(10.0, 0.0), r: Matrix2::identity() * 100.0 };
        let u = g.update(&m).unwrap();
        // Equal prior and measurement variance: halfway, variance halved.
        assert!((u.post.x[0] - 5.0).abs() < 1e-12);
        assert!((u.post.p[(0, 0)] - 50.0).abs() < 1e-9);
        assert!((u.nis - 0.5).abs() < 1e-12);
        assert!(
            (u.log_likelihood().exp() - (-0.25f64).exp() / (2.0 * std::f64::consts::PI * 200.0)).abs()
                < 1e-12
        );
        assert!(u.post.healthy());
        let bad = PosMeasurement { z: Vector2::zeros(), r: -Matrix2::identity() * 1e3 };
        assert!(g.update(&bad).is_none());
    }

    #[test]
    fn selected_rows_give_the_products_numbers() {
        let a = Matrix6::from_fn(|i, j| ((i * 7 + j * 3) % 11) as f64 - 4.5);
        let g = Gaussian { x: Vector6::from_fn(|i, _| i as f64 * 1.7 - 3.0), p: a * a.transpose() };
        let z = Vector2::new(3.0, -2.0);
        let r = Matrix2::new(4.0, 1.0, 1.0, 9.0);
        let general = Matrix2x6::new(1.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0);
        for (m, pick) in [
            (PosMeasurement { z, r }.linear(), Some(0)),
            (velocity(z, r), Some(2)),
            (Linear::new(general, z, r), None),
        ] {
            assert_eq!(m.selection, pick);
            let (nu, s) = g.innovation(&m);
            assert_eq!((nu, s), (m.z - m.h * g.x, m.h * g.p * m.h.transpose() + m.r));
            let u = g.update_linear(&m).unwrap();
            let k = g.p * m.h.transpose() * s.try_inverse().unwrap();
            assert!((u.post.x - (g.x + k * nu)).norm() < 1e-9 * g.x.norm().max(1.0));
        }
    }

    #[test]
    fn a_velocity_measurement_sets_velocity_and_leaves_position() {
        let g = diagonal(Vector6::zeros(), [100.0, 100.0, 1e4, 1e4, 1.0, 1.0]);
        let u = g.update_linear(&velocity(Vector2::new(100.0, -50.0), Matrix2::identity())).unwrap();
        assert!((u.post.x[2] - 100.0).abs() < 0.02 && (u.post.x[3] + 50.0).abs() < 0.02);
        assert_eq!((u.post.x[0], u.post.p[(0, 0)]), (0.0, 100.0));
    }
}
