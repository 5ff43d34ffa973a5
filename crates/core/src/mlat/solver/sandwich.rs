//! A fix's covariance when its measurements were weighted otherwise than
//! their variances are believed to be.
//!
//! The engine weights a receiver at no better than a floor (see
//! `Rx::sigma`): below it, a receiver learnt a little low would be weighted
//! more, its leverage would rise, its residuals would shrink faster than
//! `1 - h` says, and it would be learnt lower still. Weights that stop
//! there keep the learning stable, but a receiver far better than the floor
//! then gets a fix covariance from the floor: an airport's 10 ns receivers
//! under a 17 ns floor claimed 2.5 times their fixes' error variance. The
//! least-squares estimate with weights `W` and measurement variances `V`
//! has the covariance `A^-1 J^T W V W J A^-1` (`A = J^T W J`), which is
//! `A^-1` only where `V = W^-1`; that "sandwich" is what such a fix reports.

use super::*;

impl AtFix {
    /// `fix` with its covariance for measurement variances `var(k)` (s^2,
    /// `None` where it is its weight's), the solver's scaling by its
    /// residuals kept. Unchanged when every variance is its weight's.
    pub fn sandwich(&self, fix: &Fix, var: impl Fn(usize) -> Option<f64>) -> Fix {
        // A^-1 (A + sum_k (w_k^2 v_k - w_k) j_k j_k^T) A^-1: only the
        // measurements whose variance differs add a term.
        let mut middle = Matrix4::zeros();
        let mut changed = false;
        for (k, &(_, j, w, _)) in self.rows.iter().enumerate() {
            let Some(v_s2) = var(k) else { continue };
            let v_m2 = v_s2 * C_AIR * C_AIR;
            if !(v_m2.is_finite() && v_m2 > 0.0) {
                continue;
            }
            middle += j * j.transpose() * (w * (w * v_m2 - 1.0));
            changed = true;
        }
        if !changed {
            return *fix;
        }
        let scale = residual_scale(self.chi2, fix.dof);
        let extra = self.inv * middle * self.inv;
        let mut cov = Matrix3::from_fn(|r, c| fix.cov_ecef[r][c]) + extra.fixed_view::<3, 3>(0, 0) * scale;
        // Symmetric and positive however the terms round.
        cov = (cov + cov.transpose()) * 0.5;
        if cov.cholesky().is_none() {
            return *fix;
        }
        let mut out = *fix;
        let (_, [sp, cp, sl, cl]) = ecef_height_fast(fix.ecef);
        out.cov_ecef = std::array::from_fn(|r| std::array::from_fn(|c| cov[(r, c)]));
        out.cov_en = cov_en_of(&cov, [sp, cp, sl, cl]);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::ecef_distance;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// Six receivers about 50 km apart, the target at 9 km over them.
    fn sites() -> Vec<[f64; 3]> {
        [(48.80, 2.30), (48.95, 2.60), (48.60, 2.70), (48.55, 2.10), (49.05, 2.05), (48.40, 2.40)]
            .iter()
            .map(|&(lat, lon)| crate::geo::geodetic_to_ecef(lat, lon, 100.0))
            .collect()
    }

    #[test]
    fn measurements_weighted_as_worse_than_they_are_report_their_own_covariance() {
        // Receivers of 8 ns weighted as 17 ns, one of them as 40 ns: the
        // fixes' errors against the covariance reported as solved
        // (weights' variances) and as sandwiched (the true ones).
        let target = crate::geo::geodetic_to_ecef(48.75, 2.40, 9_000.0);
        let sigma = 8e-9;
        let weight_sigma = |k: usize| if k == 2 { 40e-9 } else { 17e-9 };
        let noise = Normal::new(0.0, sigma).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (mut plain, mut sandwiched, mut n) = (0.0, 0.0, 0.0);
        for _ in 0..2000 {
            let ms: Vec<Measurement> = (sites().iter().enumerate())
                .map(|(k, &pos)| Measurement {
                    pos,
                    t: ecef_distance(pos, target) / C_AIR + noise.sample(&mut rng),
                    sigma_t: weight_sigma(k),
                })
                .collect();
            let Ok(fix) = solve(&ms, None, Some(target), &SolverLimits::default()) else { continue };
            let at = AtFix::new(&ms, None, &fix).expect("normal matrix");
            let told = at.sandwich(&fix, |_| Some(sigma * sigma));
            let e = Vector3::from(fix.ecef) - Vector3::from(target);
            let nees = |f: &Fix| {
                let c = Matrix3::from_fn(|r, c| f.cov_ecef[r][c]);
                (e.transpose() * c.try_inverse().unwrap() * e)[0]
            };
            plain += nees(&fix);
            sandwiched += nees(&told);
            n += 1.0;
        }
        let (plain, sandwiched) = (plain / n, sandwiched / n);
        // Three dimensions: a consistent covariance gives a mean NEES of 3.
        assert!(plain < 1.5, "as weighted: {plain}");
        assert!((sandwiched / 3.0 - 1.0).abs() < 0.1, "sandwiched: {sandwiched}");
    }

    #[test]
    fn nothing_changes_where_the_weights_are_the_variances() {
        let target = crate::geo::geodetic_to_ecef(48.75, 2.40, 9_000.0);
        let ms: Vec<Measurement> = (sites().iter())
            .map(|&pos| Measurement { pos, t: ecef_distance(pos, target) / C_AIR, sigma_t: 30e-9 })
            .collect();
        let fix = solve(&ms, None, Some(target), &SolverLimits::default()).expect("fix");
        let at = AtFix::new(&ms, None, &fix).expect("normal matrix");
        assert_eq!(at.sandwich(&fix, |_| None).cov_ecef, fix.cov_ecef);
        let same = at.sandwich(&fix, |_| Some(30e-9f64.powi(2)));
        for r in 0..3 {
            for c in 0..3 {
                let (a, b) = (same.cov_ecef[r][c], fix.cov_ecef[r][c]);
                assert!((a - b).abs() <= 1e-9 * fix.cov_ecef[r][r].abs().max(1.0), "{a} against {b}");
            }
        }
    }
}
