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
    /// Acceleration along the velocity (m/s^2) and velocity noise density.
    Tangential { accel: f64, q: f64 },
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
        let (f, q) = self.transition_parts(t, x);
        (f.dense(), q)
    }

    /// Transition and noise over `t`; the current statistical model at zero acceleration.
    pub fn transition(&self, t: f64) -> (Matrix6<f64>, Matrix6<f64>) {
        self.transition_at(t, &Vector6::zeros())
    }

    /// The prediction of `(x, p)` over `t`: `(F x, F p F' + Q)`, bit for
    /// bit the dense products' numbers at a fraction of their work (it was
    /// a fifth of the tracker's instructions).
    #[inline]
    pub fn predict(&self, t: f64, x: &Vector6<f64>, p: &Matrix6<f64>) -> (Vector6<f64>, Matrix6<f64>) {
        let (mut px, mut pp) = (Vector6::zeros(), Matrix6::zeros());
        self.predict_into(t, x, p, &mut px, &mut pp);
        (px, pp)
    }

    /// [`Self::predict`] written into `(out_x, out_p)`: the IMM predicts
    /// each model straight into its slot, where returning the pair moved
    /// its 336 bytes twice a prediction (6% of the IMM's preparation).
    pub fn predict_into(
        &self,
        t: f64,
        x: &Vector6<f64>,
        p: &Matrix6<f64>,
        out_x: &mut Vector6<f64>,
        out_p: &mut Matrix6<f64>,
    ) {
        let (f, q) = self.transition_parts(t, x);
        *out_x = f.apply(x);
        f.sandwich_into(p, out_p);
        *out_p += q;
    }

    fn transition_parts(&self, t: f64, x: &Vector6<f64>) -> (Transition, Matrix6<f64>) {
        match *self {
            MotionModel::CurrentStatistical { alpha, a_max } => {
                let unit = singer_noise(alpha, 1.0, t);
                let (qe, qn) = (rayleigh_variance(a_max, x[4]), rayleigh_variance(a_max, x[5]));
                (Transition::PerAxis(ca_transition(t)), two_axes(&(unit * qe), &(unit * qn)))
            }
            MotionModel::ConstantVelocity { q } => {
                let f = Matrix3::new(1.0, t, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0);
                (Transition::PerAxis(f), per_axis(&cv_noise(q, t)))
            }
            MotionModel::ConstantAcceleration { q } => {
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
                (Transition::PerAxis(ca_transition(t)), per_axis(&qq))
            }
            MotionModel::CoordinatedTurn { omega, q } => {
                // Heading increases clockwise: velocity rotates by -omega in
                // the (east, north) plane's mathematical sense.
                let w = -omega;
                let (s, c) = (w * t).sin_cos();
                let (a, b) = if w.abs() < 1e-9 { (t, 0.0) } else { (s / w, (1.0 - c) / w) };
                // State order: e, n, ve, vn, ae, an; the acceleration rows
                // are the centripetal one of the new velocity, a = w x v.
                let f =
                    Transition::Turn { h: [a, b, c, s, -w * s, w * c], m: [-b, a, -s, c, -w * c, -w * s] };
                (f, per_axis(&cv_noise(q, t)))
            }
            MotionModel::Tangential { accel, q } => {
                // The speed s grows by accel t along an unchanged direction:
                // the velocity scales by 1 + accel t / s and the position
                // moves by v t (1 + accel t / 2s), linear in the state for
                // the s of the point predicted from. The mean is exact; the
                // covariance scales an along-track velocity error by the
                // same 1 + accel t / s, where the true Jacobian passes it
                // unchanged (2.5% a second at 3 m/s^2 and 120 m/s). Below
                // 1 m/s there is no direction to accelerate along (nor in
                // `transition`, which has no state): constant velocity.
                let s = x[2].hypot(x[3]);
                let k = if s >= 1.0 { accel / s } else { 0.0 };
                let f = Matrix3::new(1.0, t + k * t * t / 2.0, 0.0, 0.0, 1.0 + k * t, 0.0, 0.0, k, 0.0);
                (Transition::Dense(Box::new(per_axis(&f))), per_axis(&cv_noise(q, t)))
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
                (Transition::PerAxis(f), per_axis(&singer_noise(alpha, sigma_a, t)))
            }
        }
    }
}

/// A model's transition matrix by its structure: every per-axis model's is
/// the same upper-triangular block for east and north, a turn's rows each
/// have their own position (the first two) and the two velocities.
///
/// Products by it are the dense products' numbers exactly, at a third of
/// their work: a dense product sums its terms in column order, and the
/// terms it has beyond these are products with zero, which add nothing to
/// a non-zero sum. A row of zeros (constant velocity's accelerations) gives
/// the dense sum of signed zeros in the mean; in the covariance `Q`, whose
/// zeros are all positive, is added after, which makes any zero positive
/// either way.
#[derive(Clone, Debug)]
enum Transition {
    PerAxis(Matrix3<f64>),
    /// No structure to use: tangential acceleration's, whose acceleration
    /// rows follow the velocity (a model off the default set). Boxed: inline
    /// it made every model's transition four times as large to move.
    Dense(Box<Matrix6<f64>>),
    /// Row `i` is `[i < 2] x_i + h_i ve + m_i vn`.
    Turn {
        h: [f64; 6],
        m: [f64; 6],
    },
}

impl Transition {
    fn dense(&self) -> Matrix6<f64> {
        match self {
            Transition::PerAxis(f) => per_axis(f),
            Transition::Dense(f) => **f,
            Transition::Turn { h, m } => Matrix6::from_fn(|i, j| match j {
                2 => h[i],
                3 => m[i],
                _ if j == i && i < 2 => 1.0,
                _ => 0.0,
            }),
        }
    }

    /// `F x`.
    fn apply(&self, x: &Vector6<f64>) -> Vector6<f64> {
        match self {
            Transition::Dense(f) => **f * x,
            Transition::PerAxis(f) => {
                debug_assert!(f[(1, 0)] == 0.0 && f[(2, 0)] == 0.0 && f[(2, 1)] == 0.0, "upper triangular");
                let mut y = Vector6::zeros();
                for axis in 0..2 {
                    let (p, v, a) = (axis, 2 + axis, 4 + axis);
                    y[p] = f[(0, 0)] * x[p] + f[(0, 1)] * x[v] + f[(0, 2)] * x[a];
                    y[v] = f[(1, 1)] * x[v] + f[(1, 2)] * x[a];
                    y[a] = if f[(2, 2)] == 0.0 {
                        x.iter().skip(1).fold(0.0 * x[0], |acc, &v| 0.0 * v + acc)
                    } else {
                        f[(2, 2)] * x[a]
                    };
                }
                y
            }
            Transition::Turn { h, m } => Vector6::from_fn(|i, _| {
                let (ve, vn) = (h[i] * x[2], m[i] * x[3]);
                if i < 2 {
                    x[i] + ve + vn
                } else {
                    ve + vn
                }
            }),
        }
    }

    /// `F p F'` into `out` (every element written).
    #[inline]
    fn sandwich_into(&self, p: &Matrix6<f64>, out: &mut Matrix6<f64>) {
        let mut fp = Matrix6::zeros();
        match self {
            Transition::Dense(f) => *out = **f * p * f.transpose(),
            Transition::PerAxis(f) => {
                for axis in 0..2 {
                    let (r0, r1, r2) = (axis, 2 + axis, 4 + axis);
                    for c in 0..6 {
                        let (b0, b1, b2) = (p[(r0, c)], p[(r1, c)], p[(r2, c)]);
                        fp[(r0, c)] = f[(0, 0)] * b0 + f[(0, 1)] * b1 + f[(0, 2)] * b2;
                        fp[(r1, c)] = f[(1, 1)] * b1 + f[(1, 2)] * b2;
                        fp[(r2, c)] = f[(2, 2)] * b2;
                    }
                }
                for axis in 0..2 {
                    let (c0, c1, c2) = (axis, 2 + axis, 4 + axis);
                    for i in 0..6 {
                        let (b0, b1, b2) = (fp[(i, c0)], fp[(i, c1)], fp[(i, c2)]);
                        out[(i, c0)] = b0 * f[(0, 0)] + b1 * f[(0, 1)] + b2 * f[(0, 2)];
                        out[(i, c1)] = b1 * f[(1, 1)] + b2 * f[(1, 2)];
                        out[(i, c2)] = b2 * f[(2, 2)];
                    }
                }
            }
            Transition::Turn { h, m } => {
                for i in 0..6 {
                    for c in 0..6 {
                        let (ve, vn) = (h[i] * p[(2, c)], m[i] * p[(3, c)]);
                        fp[(i, c)] = if i < 2 { p[(i, c)] + ve + vn } else { ve + vn };
                    }
                }
                for j in 0..6 {
                    for i in 0..6 {
                        let (ve, vn) = (fp[(i, 2)] * h[j], fp[(i, 3)] * m[j]);
                        out[(i, j)] = if j < 2 { fp[(i, j)] + ve + vn } else { ve + vn };
                    }
                }
            }
        }
    }
}

/// Singer process noise: the integral over the interval of
/// Phi(s) G q G^T Phi(s)^T with q = 2 alpha sigma_a^2. Closed form (Singer
/// 1970) where it is well conditioned; for short steps its terms cancel to
/// rounding noise, so those take the integral's power series instead.
fn singer_noise(alpha: f64, sigma_a: f64, t: f64) -> Matrix3<f64> {
    let at = alpha * t;
    if at < 0.05 {
        return singer_noise_short(alpha, sigma_a, t);
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

/// Terms of the short-step series: at alpha t < 0.05 the first left out is
/// below 1e-13 of the sum.
const SERIES_TERMS: usize = 9;

/// The short-step series' coefficients. With x = alpha t, the three rows of
/// Phi(s) G are power series in s whose k-th terms are (-alpha)^(k - o)
/// s^k / k! from k = o, with o = 2, 1, 0 (position, velocity,
/// acceleration); integrating their products term by term gives
/// Q_ij = q t^(o_i + o_j + 1) sum_p C_ij[p] (-x)^p with
/// C_ij[p] = sum over m + n = p of 1 / ((p + o_i + o_j + 1) (m + o_i)! (n + o_j)!).
/// Rows: (1,1), (1,2), (1,3), (2,2), (2,3), (3,3).
const SINGER_SERIES: [[f64; SERIES_TERMS]; 6] = {
    const PAIRS: [(usize, usize); 6] = [(2, 2), (2, 1), (2, 0), (1, 1), (1, 0), (0, 0)];
    const fn factorial(n: usize) -> f64 {
        let (mut f, mut k) = (1.0, 2);
        while k <= n {
            f *= k as f64;
            k += 1;
        }
        f
    }
    let mut c = [[0.0; SERIES_TERMS]; 6];
    let mut e = 0;
    while e < 6 {
        let (oi, oj) = PAIRS[e];
        let mut p = 0;
        while p < SERIES_TERMS {
            let mut m = 0;
            while m <= p {
                c[e][p] += 1.0 / ((p + oi + oj + 1) as f64 * factorial(m + oi) * factorial(p - m + oj));
                m += 1;
            }
            p += 1;
        }
        e += 1;
    }
    c
};

/// [`singer_noise`] for short steps, by its power series in alpha t (the
/// Simpson integration it replaces took sixteen exponentials a step and was
/// 1e-5 off in the position term).
fn singer_noise_short(alpha: f64, sigma_a: f64, t: f64) -> Matrix3<f64> {
    let q = 2.0 * alpha * sigma_a * sigma_a;
    let x = alpha * t;
    let sum = |row: &[f64; SERIES_TERMS]| row.iter().rev().fold(0.0, |acc, &c| acc * -x + c);
    let [c11, c12, c13, c22, c23, c33] = &SINGER_SERIES;
    let (t2, t3) = (t * t, t * t * t);
    let (q11, q12, q13) = (sum(c11) * t3 * t2, sum(c12) * t2 * t2, sum(c13) * t3);
    let (q22, q23, q33) = (sum(c22) * t3, sum(c23) * t2, sum(c33) * t);
    Matrix3::new(q11, q12, q13, q12, q22, q23, q13, q23, q33) * q
}

/// [`singer_noise`] by Simpson's rule over `n` (even) intervals: the tests' reference.
#[cfg(test)]
fn singer_noise_numeric(alpha: f64, sigma_a: f64, t: f64, n: usize) -> Matrix3<f64> {
    let q = 2.0 * alpha * sigma_a * sigma_a;
    let phi_g = |s: f64| {
        let e = (-alpha * s).exp();
        nalgebra::Vector3::new((alpha * s - 1.0 + e) / (alpha * alpha), (1.0 - e) / alpha, e)
    };
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
    use nalgebra::Vector2;

    #[test]
    fn the_sparse_prediction_is_the_dense_products_bit_for_bit() {
        // Entries of both signs and magnitudes from 1e-3 to 1e6, as a
        // track's covariance and state have.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut next = move || rng.gen_range(-0.5..0.5) * 10f64.powf(rng.gen_range(-3.0..6.0));
        let models = [
            MotionModel::ConstantVelocity { q: 0.5 },
            MotionModel::ConstantAcceleration { q: 0.3 },
            MotionModel::CoordinatedTurn { omega: 3f64.to_radians(), q: 0.5 },
            MotionModel::CoordinatedTurn { omega: -3f64.to_radians(), q: 0.5 },
            MotionModel::Singer { alpha: 0.5, sigma_a: 2.0 },
            MotionModel::CurrentStatistical { alpha: 1.0, a_max: 8.0 },
            MotionModel::Tangential { accel: -2.0, q: 0.5 },
        ];
        for _ in 0..200 {
            let x = Vector6::from_fn(|_, _| next());
            let a = Matrix6::from_fn(|_, _| next());
            let p = a * a.transpose() + Matrix6::from_fn(|i, j| if i == j { 1.0 } else { next() });
            for model in models {
                for t in [0.0, 1e-4, 0.05, 0.5, 1.0, 7.3] {
                    let (f, q) = model.transition_at(t, &x);
                    let (px, pp) = model.predict(t, &x, &p);
                    let (dx, dp) = (f * x, f * p * f.transpose() + q);
                    let bits = |v: &[f64]| v.iter().map(|e| e.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(px.as_slice()), bits(dx.as_slice()), "{model:?} t {t}: mean");
                    assert_eq!(bits(pp.as_slice()), bits(dp.as_slice()), "{model:?} t {t}: covariance");
                }
            }
        }
    }

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
    fn tangential_acceleration_speeds_up_along_the_track() {
        // 120 m/s on heading 60 deg, +3 m/s^2 for ten 1 s steps: 150 m/s on
        // the same heading, 120 x 10 + 3 x 100 / 2 = 1,350 m along it, the
        // acceleration vector 3 m/s^2 along the track; -3 m/s^2 the mirror.
        let heading = Vector2::new(60f64.to_radians().sin(), 60f64.to_radians().cos());
        for (accel, speed, distance) in [(3.0, 150.0, 1350.0), (-3.0, 90.0, 1050.0)] {
            let model = MotionModel::Tangential { accel, q: 0.5 };
            let v = heading * 120.0;
            let mut x = Vector6::new(0.0, 0.0, v.x, v.y, 0.0, 0.0);
            for _ in 0..10 {
                x = model.predict(1.0, &x, &Matrix6::identity()).0;
            }
            let (p, v, a) = (Vector2::new(x[0], x[1]), Vector2::new(x[2], x[3]), Vector2::new(x[4], x[5]));
            assert!((v - heading * speed).norm() < 1e-9, "{accel}: velocity {v:?}");
            assert!((p - heading * distance).norm() < 1e-9, "{accel}: position {p:?}");
            assert!((a - heading * accel).norm() < 1e-9, "{accel}: acceleration {a:?}");
        }
        // No acceleration, or no speed to accelerate along (a standstill,
        // or `transition` without a state): constant velocity's motion.
        let x = Vector6::new(5.0, -3.0, 100.0, 40.0, 0.0, 0.0);
        let (cv, _) = MotionModel::ConstantVelocity { q: 1.0 }.transition(2.0);
        let (tangential, _) = MotionModel::Tangential { accel: 0.0, q: 1.0 }.transition_at(2.0, &x);
        assert_eq!(tangential * x, cv * x);
        let (still, _) = MotionModel::Tangential { accel: 3.0, q: 1.0 }.transition(2.0);
        assert_eq!(still, cv);
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
            let (a, b) = (singer_noise(alpha, 1.7, t), singer_noise_numeric(alpha, 1.7, t, 4096));
            let rel = (a - b).norm() / b.norm();
            assert!(rel < 1e-5, "alpha {alpha} t {t}: {rel}");
        }
    }

    #[test]
    fn singer_noise_short_step_series_matches_the_integral_entry_by_entry() {
        // Each entry on its own scale (they span t^5 to t), and both sides of
        // the switch to the closed form meet.
        for (alpha, t) in [(1.0, 0.001), (1.0, 0.02), (1.0, 0.0499), (0.1, 0.3), (2.0, 0.01), (1.0, 0.0)] {
            let (a, b) = (singer_noise_short(alpha, 1.7, t), singer_noise_numeric(alpha, 1.7, t, 512));
            for (i, j) in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)] {
                let rel = (a[(i, j)] - b[(i, j)]).abs() / b[(i, j)].abs().max(1e-300);
                assert!(
                    rel < 1e-10 || b[(i, j)] == 0.0 && a[(i, j)] == 0.0,
                    "alpha {alpha} t {t} ({i},{j}): {rel}"
                );
            }
        }
        let (alpha, t) = (1.0, 0.05);
        let (short, closed) = (singer_noise_short(alpha, 1.7, t), singer_noise(alpha, 1.7, t * 1.000_001));
        for (i, j) in [(0, 0), (0, 1), (1, 1), (2, 2)] {
            let rel = (short[(i, j)] - closed[(i, j)]).abs() / closed[(i, j)].abs();
            assert!(rel < 1e-4, "({i},{j}) at the switch: {rel}");
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
