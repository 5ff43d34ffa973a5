//! Kalman predictor and updater for the 6-state horizontal model, with a
//! position measurement. Joseph-form update so the covariance stays
//! symmetric and positive definite; every step checks it and reports a
//! filter that went numerically bad instead of publishing it.

use nalgebra::{Matrix2, Matrix2x6, Matrix6, Vector2, Vector6};

/// A state estimate: mean `[e, n, ve, vn, ae, an]` (m, m/s, m/s^2) and covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gaussian {
    pub x: Vector6<f64>,
    pub p: Matrix6<f64>,
}

/// A horizontal position measurement (east, north; m) with its covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosMeasurement {
    pub z: Vector2<f64>,
    pub r: Matrix2<f64>,
}

/// The result of an update: the posterior and the innovation statistics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Updated {
    pub post: Gaussian,
    /// Normalised innovation squared (chi-square, 2 dof when consistent).
    pub nis: f64,
    /// Measurement likelihood N(innovation; 0, S).
    pub likelihood: f64,
}

pub fn h() -> Matrix2x6<f64> {
    Matrix2x6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0)
}

impl Gaussian {
    pub fn predict(&self, f: &Matrix6<f64>, q: &Matrix6<f64>) -> Gaussian {
        Gaussian { x: f * self.x, p: f * self.p * f.transpose() + q }
    }

    /// `None` when the innovation covariance is not positive definite.
    pub fn update(&self, m: &PosMeasurement) -> Option<Updated> {
        let h = h();
        let nu = m.z - h * self.x;
        let s = h * self.p * h.transpose() + m.r;
        // Positive definite or nothing: a determinant alone passes -S.
        let chol = s.cholesky()?;
        let s_inv = chol.inverse();
        let det = chol.l().diagonal().product().powi(2);
        if !(det > 0.0 && det.is_finite()) {
            return None;
        }
        let k = self.p * h.transpose() * s_inv;
        let ikh = Matrix6::identity() - k * h;
        let p = ikh * self.p * ikh.transpose() + k * m.r * k.transpose();
        let nis = (nu.transpose() * s_inv * nu)[0];
        let likelihood = (-0.5 * nis).exp() / (2.0 * std::f64::consts::PI * det.sqrt());
        Some(Updated { post: Gaussian { x: self.x + k * nu, p: (p + p.transpose()) * 0.5 }, nis, likelihood })
    }

    /// Covariance symmetric, finite and positive definite.
    pub fn healthy(&self) -> bool {
        self.x.iter().all(|v| v.is_finite())
            && self.p.iter().all(|v| v.is_finite())
            && self.p.cholesky().is_some()
    }
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
        assert!(u.post.healthy());
        let bad = PosMeasurement { z: Vector2::zeros(), r: -Matrix2::identity() * 1e3 };
        assert!(g.update(&bad).is_none());
    }
}
