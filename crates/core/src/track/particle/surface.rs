//! The surface of one transmission's time differences: where an aircraft
//! at a given height explains them, and how to get onto it (the particle
//! filter's placement, its regularisation's pull back, and the search for
//! a cloud's mirror solutions).

use nalgebra::{Matrix2, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::Sites;
use crate::mlat::solver::C_AIR;
use crate::track::plane::Plane;

/// Gauss-Newton steps pulling a drawn point onto a measurement's surface,
/// at most; it stops once a step is shorter than `PULL_CONVERGED_M` (m),
/// far below the time differences' noise.
const PULL_STEPS: usize = 12;
const PULL_CONVERGED_M: f64 = 0.01;

/// The time differences in metres, and their covariance's inverse, for sites
/// taken relative to the first; and how far each site can see an aircraft
/// at the height given (its radio horizon).
pub(super) struct Differences {
    pub(super) n: usize,
    rx: [Vector3<f64>; 3],
    z: [f64; 2],
    info: Matrix2<f64>,
    /// Cholesky factor of the differences' covariance (m), for drawing their noise.
    chol: Matrix2<f64>,
    horizon_m: [f64; 3],
}

/// Radio horizon (m) between antennas at heights `a` and `b` (m) over a
/// smooth Earth, with the usual 4/3 radius for refraction.
fn horizon_m(a: f64, b: f64) -> f64 {
    const K: f64 = 4_122.0;
    K * (a.max(0.0).sqrt() + b.max(0.0).sqrt())
}

impl Differences {
    pub(super) fn new(plane: &Plane, sites: Sites, h: f64) -> Option<Differences> {
        let n = sites.len();
        if !(2..=3).contains(&n) {
            return None;
        }
        let s = |i: usize| sites[i.min(n - 1)];
        let var = |i: usize| (s(i).2 * C_AIR).powi(2);
        // Differences against one site share its error.
        let cov = Matrix2::new(var(1) + var(0), var(0), var(0), var(2) + var(0));
        let (info, chol) = if n == 2 {
            (Matrix2::new(1.0 / cov[(0, 0)], 0.0, 0.0, 0.0), Matrix2::new(cov[(0, 0)].sqrt(), 0.0, 0.0, 0.0))
        } else {
            (cov.try_inverse()?, cov.cholesky()?.l())
        };
        Some(Differences {
            n,
            rx: std::array::from_fn(|i| plane.ecef_to_local(s(i).0)),
            z: std::array::from_fn(|i| (s(i + 1).1 - s(0).1) * C_AIR),
            info,
            chol,
            horizon_m: std::array::from_fn(|i| horizon_m(crate::geo::ecef_to_geodetic(s(i).0).2, h)),
        })
    }

    /// Whether every site can see plane position (e, n) at height `h`.
    pub(super) fn visible(&self, plane: &Plane, e: f64, n: f64, h: f64) -> bool {
        let p = Vector3::new(e, n, plane.up_at(e, n, h));
        (0..self.n).all(|i| (p - self.rx[i]).norm() <= self.horizon_m[i])
    }

    /// Residuals (m) at plane position (e, n) and height `h`.
    pub(super) fn residual(&self, plane: &Plane, e: f64, n: f64, h: f64) -> [f64; 2] {
        let p = Vector3::new(e, n, plane.up_at(e, n, h));
        let r0 = (p - self.rx[0]).norm();
        std::array::from_fn(
            |i| if i + 1 < self.n { (p - self.rx[i + 1]).norm() - r0 - self.z[i] } else { 0.0 },
        )
    }

    /// A draw of the differences' noise (m).
    pub(super) fn noise(&self, rng: &mut ChaCha8Rng) -> [f64; 2] {
        let z = nalgebra::Vector2::new(
            rng.sample::<f64, _>(StandardNormal),
            rng.sample::<f64, _>(StandardNormal),
        );
        let v = self.chol * z;
        [v[0], v[1]]
    }

    /// Chi-square of the residuals (1 or 2 degrees of freedom).
    pub(super) fn chi2(&self, r: [f64; 2]) -> f64 {
        let v = nalgebra::Vector2::new(r[0], r[1]);
        (v.transpose() * self.info * v)[0]
    }
}

/// A plane point moved by Gauss-Newton steps to where the residuals are
/// `target` (a draw of the measurement's noise: with two differences the
/// surface is a point at the height, and every particle pulled exactly onto
/// it would be the same), if it gets there within the sites' horizons.
pub(super) fn pull(
    d: &Differences,
    plane: &Plane,
    mut e: f64,
    mut n: f64,
    h: f64,
    target: [f64; 2],
) -> Option<(f64, f64)> {
    for _ in 0..PULL_STEPS {
        let (res, jac) = residual_jacobian(d, plane, e, n, h);
        let res = [res[0] - target[0], res[1] - target[1]];
        let step = if d.n == 2 {
            let g = jac[0];
            let gg = g[0] * g[0] + g[1] * g[1];
            if gg < 1e-12 {
                return None;
            }
            [res[0] * g[0] / gg, res[0] * g[1] / gg]
        } else {
            let j = Matrix2::new(jac[0][0], jac[0][1], jac[1][0], jac[1][1]);
            let s = j.try_inverse()? * nalgebra::Vector2::new(res[0], res[1]);
            [s[0], s[1]]
        };
        e -= step[0];
        n -= step[1];
        // Converged: further steps would move it by less than this.
        if step[0].abs() + step[1].abs() < PULL_CONVERGED_M {
            break;
        }
    }
    (d.visible(plane, e, n, h) && d.chi2(d.residual(plane, e, n, h)) <= 9.0).then_some((e, n))
}

/// Residuals and their gradients in (e, n) at a plane point.
fn residual_jacobian(d: &Differences, plane: &Plane, e: f64, n: f64, h: f64) -> ([f64; 2], [[f64; 2]; 2]) {
    let p = Vector3::new(e, n, plane.up_at(e, n, h));
    let unit = |i: usize| {
        let v = p - d.rx[i];
        let r = v.norm().max(1.0);
        [v[0] / r, v[1] / r]
    };
    let u0 = unit(0);
    let res = d.residual(plane, e, n, h);
    let jac = std::array::from_fn(|i| {
        let u = unit((i + 1).min(d.n - 1));
        [u[0] - u0[0], u[1] - u0[1]]
    });
    (res, jac)
}

/// Where the measurement's surface is, found from a spread of starting
/// points around the plane's origin (out to an airliner's radio horizon):
/// with two time differences its one or two points, with one points along
/// its curve.
pub(super) fn solutions<'a>(
    d: &'a Differences,
    plane: &'a Plane,
    h: f64,
) -> impl Iterator<Item = (f64, f64)> + 'a {
    const RADII_M: [f64; 4] = [30_000.0, 100_000.0, 200_000.0, 350_000.0];
    const BEARINGS: usize = 16;
    (0..RADII_M.len() * BEARINGS).filter_map(move |k| {
        let (r, a) = (RADII_M[k / BEARINGS], (k % BEARINGS) as f64 * std::f64::consts::TAU / BEARINGS as f64);
        pull(d, plane, r * a.sin(), r * a.cos(), h, [0.0, 0.0])
    })
}
