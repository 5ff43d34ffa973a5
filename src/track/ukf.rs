//! Augmented unscented Kalman update for measurements that are not linear in
//! the state: here, time differences of arrival fed straight into a track
//! when a transmission reached too few receivers for a fix of its own (three,
//! or two plus an altitude).
//!
//! Augmented: the sigma points span the horizontal state, the height (from
//! the vertical channel, with its variance) and one noise term per receiver,
//! so the TDOAs' correlation through their common reference receiver, and
//! the height's uncertainty, come out of the transform instead of being
//! linearised by hand.
//!
//! For the IMM the transform is run once, on the combined prediction, and
//! turned into its statistical linear regression ([`linearise`]): a linear
//! measurement `H x + b` with the regression's residual in its noise, which
//! every model then applies with the ordinary linear update. One transform
//! instead of one per model (and per gate), the same first two moments.

use nalgebra::{DMatrix, DVector, SMatrix, SVector, Vector3};

use super::kf::{Gaussian, Linear};

/// Time differences of arrival at `receivers` (plane-local east, north, up
/// of each antenna, m) relative to the first: `z[i] = |p - r[i+1]| - |p - r[0]|`
/// in metres, each receiver's timing noise `sigma_m` (m, 1 sigma).
#[derive(Clone, Debug, PartialEq)]
pub struct Tdoa {
    pub receivers: Vec<Vector3<f64>>,
    pub sigma_m: Vec<f64>,
    pub z: Vec<f64>,
}

/// Scaled unscented transform parameters: alpha spreads the points, beta = 2
/// suits Gaussians.
const ALPHA: f64 = 0.5;
const BETA: f64 = 2.0;

impl Tdoa {
    fn predict(&self, x: &DVector<f64>, up: impl Fn(f64, f64, f64) -> f64) -> DVector<f64> {
        let (e, n, h) = (x[0], x[1], x[6]);
        let p = Vector3::new(e, n, up(e, n, h));
        let range = |i: usize| (p - self.receivers[i]).norm() + x[7 + i];
        let r0 = range(0);
        DVector::from_iterator(self.z.len(), (1..self.receivers.len()).map(|i| range(i) - r0))
    }
}

/// The unscented transform of `m` at `g` (augmented with the height and the
/// receivers' noise): the predicted measurement's mean and covariance, and
/// its cross-covariance with the augmented state.
struct Transform {
    z_mean: DVector<f64>,
    /// Innovation covariance (noise included through the sigma points).
    s: DMatrix<f64>,
    /// State-measurement cross-covariance (augmented state rows).
    c: DMatrix<f64>,
}

fn transform(
    g: &Gaussian,
    h: f64,
    h_var: f64,
    m: &Tdoa,
    up: impl Fn(f64, f64, f64) -> f64,
) -> Option<Transform> {
    let k = m.receivers.len();
    if k < 2 || m.sigma_m.len() != k || m.z.len() != k - 1 {
        return None;
    }
    let n = 7 + k;
    let mut mean = DVector::zeros(n);
    mean.rows_mut(0, 6).copy_from(&g.x);
    mean[6] = h;
    let mut cov = DMatrix::zeros(n, n);
    cov.view_mut((0, 0), (6, 6)).copy_from(&g.p);
    cov[(6, 6)] = h_var;
    for i in 0..k {
        cov[(7 + i, 7 + i)] = m.sigma_m[i] * m.sigma_m[i];
    }
    let lambda = ALPHA * ALPHA * n as f64 - n as f64;
    let l = (&cov * (n as f64 + lambda)).cholesky()?.l();
    let mut points = Vec::with_capacity(2 * n + 1);
    points.push(mean.clone());
    for j in 0..n {
        let c = l.column(j);
        points.push(&mean + c);
        points.push(&mean - c);
    }
    let w0m = lambda / (n as f64 + lambda);
    let w0c = w0m + 1.0 - ALPHA * ALPHA + BETA;
    let wi = 1.0 / (2.0 * (n as f64 + lambda));
    let zs: Vec<DVector<f64>> = points.iter().map(|p| m.predict(p, &up)).collect();
    let dim = k - 1;
    let mut z_mean = DVector::zeros(dim);
    for (j, z) in zs.iter().enumerate() {
        z_mean += z * if j == 0 { w0m } else { wi };
    }
    let mut s = DMatrix::zeros(dim, dim);
    let mut c = DMatrix::zeros(n, dim);
    for (j, (p, z)) in points.iter().zip(&zs).enumerate() {
        let w = if j == 0 { w0c } else { wi };
        let dz = z - &z_mean;
        s += &dz * dz.transpose() * w;
        c += (p - &mean) * dz.transpose() * w;
    }
    Some(Transform { z_mean, s, c })
}

/// The statistical linear regression of `m` at `g`: the linear measurement
/// `z' = H x + v`, `v ~ N(0, R)` with the transform's first two moments
/// (`z' = z - b` with the regression's offset `b` removed), for `M` time
/// differences (`None` when `m` has another number, or the transform fails).
pub fn linearise<const M: usize>(
    g: &Gaussian,
    h: f64,
    h_var: f64,
    m: &Tdoa,
    up: impl Fn(f64, f64, f64) -> f64,
) -> Option<Linear<M>> {
    if m.z.len() != M {
        return None;
    }
    let t = transform(g, h, h_var, m, up)?;
    let p_inv = g.p.cholesky()?.inverse();
    let pxz = t.c.view((0, 0), (6, t.z_mean.len())).into_owned();
    let p_inv = DMatrix::from_iterator(6, 6, p_inv.iter().copied());
    let hm = pxz.transpose() * &p_inv;
    let gx = DVector::from_iterator(6, g.x.iter().copied());
    let b = &t.z_mean - &hm * &gx;
    let r = &t.s - &hm * DMatrix::from_iterator(6, 6, g.p.iter().copied()) * hm.transpose();
    let r = (&r + r.transpose()) * 0.5;
    let z = DVector::from_column_slice(&m.z) - b;
    Some(Linear {
        h: SMatrix::from_iterator(hm.iter().copied()),
        z: SVector::from_iterator(z.iter().copied()),
        r: SMatrix::from_iterator(r.iter().copied()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::kf::diagonal;
    use nalgebra::Vector6;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn three_receivers_pull_a_track_to_the_truth_consistently() {
        // Receivers 30-60 km around, aircraft at 9 km: up = h (flat plane).
        let rx = vec![
            Vector3::new(0.0, 0.0, 100.0),
            Vector3::new(40_000.0, 5_000.0, 50.0),
            Vector3::new(-10_000.0, 45_000.0, 80.0),
        ];
        let truth = Vector3::new(12_000.0, 15_000.0, 9_000.0);
        let sigma = 30.0; // 100 ns
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, sigma).unwrap();
        let prior_sd = 300.0;
        let (mut nees, mut err2, mut err2_prior, runs) = (0.0, 0.0, 0.0, 400);
        for _ in 0..runs {
            let x0 = Vector6::new(
                truth.x + prior_sd * noise.sample(&mut rng) / sigma,
                truth.y + prior_sd * noise.sample(&mut rng) / sigma,
                0.0,
                0.0,
                0.0,
                0.0,
            );
            let g = diagonal(x0, [prior_sd * prior_sd, prior_sd * prior_sd, 1.0, 1.0, 0.1, 0.1]);
            let eps: Vec<f64> = (0..3).map(|_| noise.sample(&mut rng)).collect();
            let r = |i: usize| (truth - rx[i]).norm() + eps[i];
            let m =
                Tdoa { receivers: rx.clone(), sigma_m: vec![sigma; 3], z: vec![r(1) - r(0), r(2) - r(0)] };
            // As the tracker applies it: the regression, then a linear update.
            let lin = linearise::<2>(&g, truth.z, 25.0, &m, |_, _, h| h).unwrap();
            let u = g.update_linear(&lin).unwrap();
            let e = nalgebra::Vector2::new(u.post.x[0] - truth.x, u.post.x[1] - truth.y);
            let p = u.post.p.fixed_view::<2, 2>(0, 0).into_owned();
            nees += (e.transpose() * p.try_inverse().unwrap() * e)[0];
            err2 += e.norm_squared();
            err2_prior += (x0.fixed_rows::<2>(0) - truth.xy()).norm_squared();
        }
        let (rmse, prior) = ((err2 / runs as f64).sqrt(), (err2_prior / runs as f64).sqrt());
        let nees = nees / runs as f64;
        assert!(rmse < 0.5 * prior, "{rmse} vs prior {prior}");
        assert!((1.6..2.5).contains(&nees), "NEES {nees}");
    }
}
