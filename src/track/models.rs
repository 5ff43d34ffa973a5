//! Motion models on the common state `[e, n, ve, vn, ae, an]`: each gives
//! the transition `F` and process noise `Q` over an interval `T`.
//!
//! - constant velocity (white-noise acceleration, acceleration held at zero);
//! - constant acceleration (Wiener-process acceleration, white jerk);
//! - coordinated turn at a fixed rate (a left and a right one make the usual
//!   IMM turn pair; linear because the rate is fixed); acceleration is the
//!   centripetal one the turn implies;
//! - Singer (acceleration a first-order Gauss-Markov process with time
//!   constant `1/alpha`), its noise integrated numerically;
//! - "current statistical" (Zhou's model): Singer's process with a non-zero
//!   mean equal to the current acceleration estimate, which makes the
//!   transition the constant-acceleration one, and a noise whose variance
//!   follows a Rayleigh law, `(4 - pi)/pi (a_max - |a|)^2` per axis: small
//!   while the estimate sits near the limit, large when the target could
//!   still start manoeuvring. It is the one model that needs the state, so
//!   the IMM asks every model through [`MotionModel::transition_at`].

use nalgebra::{Matrix3, Matrix6, Vector6};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MotionModel {
    /// Acceleration noise spectral density (m^2/s^3).
    ConstantVelocity { q: f64 },
    /// Jerk noise spectral density (m^2/s^5).
    ConstantAcceleration { q: f64 },
    /// Turn rate (rad/s, positive = right/clockwise seen from above) and velocity noise density.
    CoordinatedTurn { omega: f64, q: f64 },
    /// Manoeuvre rate alpha (1/s) and acceleration standard deviation (m/s^2).
    Singer { alpha: f64, sigma_a: f64 },
    /// Manoeuvre rate alpha (1/s) and largest acceleration (m/s^2).
    CurrentStatistical { alpha: f64, a_max: f64 },
}

/// Per-axis (position, velocity, acceleration) blocks into the 6-state layout.
fn per_axis(f: &Matrix3<f64>) -> Matrix6<f64> {
    two_axes(f, f)
}

/// East and north blocks, possibly different, into the 6-state layout.
fn two_axes(east: &Matrix3<f64>, north: &Matrix3<f64>) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    for (axis, f) in [east, north].into_iter().enumerate() {
        for r in 0..3 {
            for c in 0..3 {
                m[(2 * r + axis, 2 * c + axis)] = f[(r, c)];
            }
        }
    }
    m
}

fn ca_transition(t: f64) -> Matrix3<f64> {
    Matrix3::new(1.0, t, t * t / 2.0, 0.0, 1.0, t, 0.0, 0.0, 1.0)
}

/// Rayleigh-law acceleration variance of the current statistical model; a
/// tenth of the limit stays as a floor so the model never stops listening.
pub fn rayleigh_variance(a_max: f64, a: f64) -> f64 {
    let room = (a_max - a.abs()).max(0.1 * a_max);
    (4.0 - std::f64::consts::PI) / std::f64::consts::PI * room * room
}

fn cv_noise(q: f64, t: f64) -> Matrix3<f64> {
    Matrix3::new(t.powi(3) / 3.0, t * t / 2.0, 0.0, t * t / 2.0, t, 0.0, 0.0, 0.0, 1e-6) * q
}

impl MotionModel {
    /// Transition and noise over `t` from state `x` (only the current
    /// statistical model looks at it).
    pub fn transition_at(&self, t: f64, x: &Vector6<f64>) -> (Matrix6<f64>, Matrix6<f64>) {
        match *self {
            MotionModel::CurrentStatistical { alpha, a_max } => {
                let unit = singer_noise(alpha, 1.0, t);
                let (qe, qn) = (rayleigh_variance(a_max, x[4]), rayleigh_variance(a_max, x[5]));
                (per_axis(&ca_transition(t)), two_axes(&(unit * qe), &(unit * qn)))
            }
            _ => self.transition(t),
        }
    }

    /// Transition and noise over `t`; the current statistical model at zero acceleration.
    pub fn transition(&self, t: f64) -> (Matrix6<f64>, Matrix6<f64>) {
        match *self {
            MotionModel::CurrentStatistical { .. } => self.transition_at(t, &Vector6::zeros()),
            MotionModel::ConstantVelocity { q } => {
                let f = Matrix3::new(1.0, t, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0);
                (per_axis(&f), per_axis(&cv_noise(q, t)))
            }
            MotionModel::ConstantAcceleration { q } => {
                let f = ca_transition(t);
                let qq = Matrix3::new(
                    t.powi(5) / 20.0,
                    t.powi(4) / 8.0,
                    t.powi(3) / 6.0,
                    t.powi(4) / 8.0,
                    t.powi(3) / 3.0,
                    t * t / 2.0,
                    t.powi(3) / 6.0,
                    t * t / 2.0,
                    t,
                ) * q;
                (per_axis(&f), per_axis(&qq))
            }
            MotionModel::CoordinatedTurn { omega, q } => {
                // Heading increases clockwise: velocity rotates by -omega in
                // the (east, north) plane's mathematical sense.
                let w = -omega;
                let (s, c) = (w * t).sin_cos();
                let (a, b) = if w.abs() < 1e-9 { (t, 0.0) } else { (s / w, (1.0 - c) / w) };
                let mut f = Matrix6::zeros();
                // State order: e, n, ve, vn, ae, an.
                f[(0, 0)] = 1.0;
                f[(0, 2)] = a;
                f[(0, 3)] = -b;
                f[(1, 1)] = 1.0;
                f[(1, 2)] = b;
                f[(1, 3)] = a;
                f[(2, 2)] = c;
                f[(2, 3)] = -s;
                f[(3, 2)] = s;
                f[(3, 3)] = c;
                // Centripetal acceleration of the new velocity: a = w x v.
                f[(4, 2)] = -w * s;
                f[(4, 3)] = -w * c;
                f[(5, 2)] = w * c;
                f[(5, 3)] = -w * s;
                (f, per_axis(&cv_noise(q, t)))
            }
            MotionModel::Singer { alpha, sigma_a } => {
                let e = (-alpha * t).exp();
                let f = Matrix3::new(
                    1.0,
                    t,
                    (alpha * t - 1.0 + e) / (alpha * alpha),
                    0.0,
                    1.0,
                    (1.0 - e) / alpha,
                    0.0,
                    0.0,
                    e,
                );
                (per_axis(&f), per_axis(&singer_noise(alpha, sigma_a, t)))
            }
        }
    }
}

/// Singer process noise: the integral over the interval of
/// Phi(s) G q G^T Phi(s)^T with q = 2 alpha sigma_a^2. Closed form (Singer
/// 1970) where it is well conditioned; for very short steps its terms
/// cancel to rounding noise, so those are integrated numerically.
fn singer_noise(alpha: f64, sigma_a: f64, t: f64) -> Matrix3<f64> {
    let at = alpha * t;
    if at < 0.05 {
        return singer_noise_numeric(alpha, sigma_a, t);
    }
    let q = 2.0 * alpha * sigma_a * sigma_a;
    let (e1, e2) = ((-at).exp(), (-2.0 * at).exp());
    let a2 = alpha * alpha;
    let a3 = a2 * alpha;
    let q11 =
        (1.0 - e2 + 2.0 * at + 2.0 * at * at * at / 3.0 - 2.0 * at * at - 4.0 * at * e1) / (2.0 * a3 * a2);
    let q12 = (e2 + 1.0 - 2.0 * e1 + 2.0 * at * e1 - 2.0 * at + at * at) / (2.0 * a2 * a2);
    let q13 = (1.0 - e2 - 2.0 * at * e1) / (2.0 * a3);
    let q22 = (4.0 * e1 - 3.0 - e2 + 2.0 * at) / (2.0 * a3);
    let q23 = (e2 + 1.0 - 2.0 * e1) / (2.0 * a2);
    let q33 = (1.0 - e2) / (2.0 * alpha);
    Matrix3::new(q11, q12, q13, q12, q22, q23, q13, q23, q33) * q
}

/// [`singer_noise`] by Simpson's rule.
fn singer_noise_numeric(alpha: f64, sigma_a: f64, t: f64) -> Matrix3<f64> {
    let q = 2.0 * alpha * sigma_a * sigma_a;
    let phi_g = |s: f64| {
        let e = (-alpha * s).exp();
        nalgebra::Vector3::new((alpha * s - 1.0 + e) / (alpha * alpha), (1.0 - e) / alpha, e)
    };
    // Enough even intervals to follow the exponential over the step.
    let n = ((alpha * t * 8.0).ceil() as usize).clamp(16, 4096) & !1;
    let h = t / n as f64;
    let mut acc = Matrix3::zeros();
    for k in 0..=n {
        let w = if k == 0 || k == n {
            1.0
        } else if k % 2 == 1 {
            4.0
        } else {
            2.0
        };
        let v = phi_g(k as f64 * h);
        acc += w * v * v.transpose();
    }
    acc * (h / 3.0) * q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_velocity_moves_and_drops_acceleration() {
        let (f, q) = MotionModel::ConstantVelocity { q: 1.0 }.transition(2.0);
        let x = f * Vector6::new(0.0, 0.0, 10.0, -5.0, 3.0, 3.0);
        assert_eq!(x, Vector6::new(20.0, -10.0, 10.0, -5.0, 0.0, 0.0));
        assert!((q[(0, 0)] - 8.0 / 3.0).abs() < 1e-12 && (q[(2, 2)] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn coordinated_turn_turns_right_at_its_rate() {
        // Heading north at 100 m/s, turning right 3 deg/s for 30 s: heading 90 deg (east).
        let omega = 3f64.to_radians();
        let (f, _) = MotionModel::CoordinatedTurn { omega, q: 0.0 }.transition(30.0);
        let x = f * Vector6::new(0.0, 0.0, 0.0, 100.0, 0.0, 0.0);
        assert!((x[2] - 100.0).abs() < 1e-9 && x[3].abs() < 1e-9, "{x:?}");
        // A quarter circle of radius v / omega.
        let r = 100.0 / omega;
        assert!((x[0] - r).abs() < 1e-6 && (x[1] - r).abs() < 1e-6);
        // Centripetal acceleration v * omega, pointing at the centre (south).
        assert!((x[5] + 100.0 * omega).abs() < 1e-9 && x[4].abs() < 1e-9);
    }

    #[test]
    fn singer_limits() {
        // Fast manoeuvres (large alpha): acceleration forgets at once; slow ones:
        // close to constant acceleration over a short step.
        let (f, q) = MotionModel::Singer { alpha: 0.1, sigma_a: 2.0 }.transition(0.5);
        assert!((f[(4, 4)] - (-0.05f64).exp()).abs() < 1e-12);
        assert!((f[(0, 4)] - 0.125).abs() < 0.01);
        // Stationary acceleration variance: after a long step, sigma_a^2.
        let (_, q_long) = MotionModel::Singer { alpha: 1.0, sigma_a: 2.0 }.transition(50.0);
        assert!((q_long[(4, 4)] - 4.0).abs() < 0.01, "{}", q_long[(4, 4)]);
        assert!(q.cholesky().is_some());
    }

    #[test]
    fn singer_noise_closed_form_matches_the_integral() {
        for (alpha, t) in [(0.1, 0.5), (0.5, 1.0), (1.0, 0.2), (0.05, 30.0), (2.0, 5.0)] {
            let (a, b) = (singer_noise(alpha, 1.7, t), singer_noise_numeric(alpha, 1.7, t));
            let rel = (a - b).norm() / b.norm();
            assert!(rel < 1e-5, "alpha {alpha} t {t}: {rel}");
        }
    }

    #[test]
    fn current_statistical_keeps_the_acceleration_and_narrows_near_the_limit() {
        let cs = MotionModel::CurrentStatistical { alpha: 0.1, a_max: 10.0 };
        let x = Vector6::new(0.0, 0.0, 100.0, 0.0, 9.0, 0.0);
        let (f, q) = cs.transition_at(2.0, &x);
        let y = f * x;
        assert!((y[0] - (200.0 + 18.0)).abs() < 1e-9 && (y[4] - 9.0).abs() < 1e-12);
        // East sits near the limit (little room), north at zero (the most).
        assert!(q[(4, 4)] < 0.05 * q[(5, 5)], "{} vs {}", q[(4, 4)], q[(5, 5)]);
        let expect = (4.0 - std::f64::consts::PI) / std::f64::consts::PI * 100.0;
        let unit = MotionModel::Singer { alpha: 0.1, sigma_a: 1.0 }.transition(2.0).1;
        assert!((q[(5, 5)] - expect * unit[(5, 5)]).abs() < 1e-9);
    }
}
