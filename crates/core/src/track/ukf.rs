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

use nalgebra::{SMatrix, SVector, Vector3};

use super::kf::{Gaussian, Linear};

/// Time differences of arrival at the first `n` (2 or 3) of `receivers`
/// (plane-local east, north, up of each antenna, m) relative to the first:
/// `z[i] = |p - r[i+1]| - |p - r[0]|` in metres, each receiver's timing
/// noise `sigma_m` (m, 1 sigma). Fixed arrays: no allocation per update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tdoa {
    pub n: usize,
    pub receivers: [Vector3<f64>; 3],
    pub sigma_m: [f64; 3],
    pub z: [f64; 2],
}

/// Scaled unscented transform parameters: alpha spreads the points, beta = 2
/// suits Gaussians.
const ALPHA: f64 = 0.5;
const BETA: f64 = 2.0;

/// Most sigma points: 2 N + 1 for the largest augmented state (6 + height + 3 receivers).
const MAX_POINTS: usize = 21;

impl Tdoa {
    /// The `M` time differences at augmented state `x` (`N` = 7 + `M` + 1:
    /// horizontal state, height, one noise term per receiver).
    fn predict<const M: usize, const N: usize>(
        &self,
        x: &SVector<f64, N>,
        up: &impl Fn(f64, f64, f64) -> f64,
    ) -> SVector<f64, M> {
        let (e, n, h) = (x[0], x[1], x[6]);
        let p = Vector3::new(e, n, up(e, n, h));
        let range = |i: usize| (p - self.receivers[i]).norm() + x[7 + i];
        let r0 = range(0);
        SVector::from_fn(|i, _| range(i + 1) - r0)
    }
}

/// The statistical linear regression of `m` at `g` for `M` time differences
/// through an augmented state of `N` = `M` + 8 dimensions (`None` when they
/// do not match `m`, or the transform fails): the unscented transform's
/// predicted measurement, its covariance (noise included through the sigma
/// points) and cross-covariance with the horizontal state, turned into
/// `z' = H x + v`.
fn regression<const M: usize, const N: usize>(
    g: &Gaussian,
    h: f64,
    h_var: f64,
    m: &Tdoa,
    up: impl Fn(f64, f64, f64) -> f64,
) -> Option<Linear<M>> {
    let k = M + 1;
    if m.n != k || N != 7 + k || 2 * N + 1 > MAX_POINTS {
        return None;
    }
    let mut mean = SVector::<f64, N>::zeros();
    mean.fixed_rows_mut::<6>(0).copy_from(&g.x);
    mean[6] = h;
    let mut cov = SMatrix::<f64, N, N>::zeros();
    cov.fixed_view_mut::<6, 6>(0, 0).copy_from(&g.p);
    cov[(6, 6)] = h_var;
    for i in 0..k {
        cov[(7 + i, 7 + i)] = m.sigma_m[i] * m.sigma_m[i];
    }
    let nf = N as f64;
    let lambda = ALPHA * ALPHA * nf - nf;
    let l = (cov * (nf + lambda)).cholesky()?.l();
    let w0m = lambda / (nf + lambda);
    let w0c = w0m + 1.0 - ALPHA * ALPHA + BETA;
    let wi = 1.0 / (2.0 * (nf + lambda));
    // Point 0 is the mean, points 2j+1 and 2j+2 the mean plus and minus
    // column j of the square root.
    let mut zs = [SVector::<f64, M>::zeros(); MAX_POINTS];
    zs[0] = m.predict(&mean, &up);
    for j in 0..N {
        let c = l.column(j);
        zs[2 * j + 1] = m.predict(&(mean + c), &up);
        zs[2 * j + 2] = m.predict(&(mean - c), &up);
    }
    let z_mean = zs[1..2 * N + 1].iter().fold(zs[0] * w0m, |acc, z| acc + z * wi);
    let d0 = zs[0] - z_mean;
    let mut s = d0 * d0.transpose() * w0c;
    // Cross-covariance with the horizontal state only (the mean point adds nothing).
    let mut pxz = SMatrix::<f64, 6, M>::zeros();
    for j in 0..N {
        let dx = l.fixed_view::<6, 1>(0, j);
        let (dp, dm) = (zs[2 * j + 1] - z_mean, zs[2 * j + 2] - z_mean);
        s += (dp * dp.transpose() + dm * dm.transpose()) * wi;
        pxz += dx * (dp - dm).transpose() * wi;
    }
    let p_inv = g.p.cholesky()?.inverse();
    let hm = pxz.transpose() * p_inv;
    let b = z_mean - hm * g.x;
    let r = s - hm * g.p * hm.transpose();
    let z = SVector::<f64, M>::from_fn(|i, _| m.z[i]) - b;
    Some(Linear::new(hm, z, (r + r.transpose()) * 0.5))
}

/// The statistical linear regression of `m` at `g` (augmented with the
/// height and the receivers' noise): the linear measurement `z' = H x + v`,
/// `v ~ N(0, R)` with the transform's first two moments (`z' = z - b` with
/// the regression's offset `b` removed), for `M` time differences (`None`
/// when `m` has another number, or the transform fails).
pub fn linearise<const M: usize>(
    g: &Gaussian,
    h: f64,
    h_var: f64,
    m: &Tdoa,
    up: impl Fn(f64, f64, f64) -> f64,
) -> Option<Linear<M>> {
    match M {
        1 => regression::<M, 9>(g, h, h_var, m, up),
        2 => regression::<M, 10>(g, h, h_var, m, up),
        _ => None,
    }
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
        let rx = [
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
            let eps: [f64; 3] = std::array::from_fn(|_| noise.sample(&mut rng));
            let r = |i: usize| (truth - rx[i]).norm() + eps[i];
            let m = Tdoa { n: 3, receivers: rx, sigma_m: [sigma; 3], z: [r(1) - r(0), r(2) - r(0)] };
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
