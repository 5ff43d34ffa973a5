//! A fix's least-squares problem linearised once at the fix (residuals,
//! Jacobian rows, weights, leverages, the normal matrix's inverse), and the
//! fix hedged against copies that may be late: what the engine judges the
//! copies by, and what widens the covariance where a late copy could not
//! be told.

use super::*;

/// The least-squares problem linearised at a fix: each measurement's
/// residual (m), Jacobian row and weight, the normal matrix's inverse and
/// the chi-square. What residuals, leverages and the hedge are read from,
/// built once per fix: the engine judges the copies from it and hedges
/// with the same.
pub struct AtFix {
    /// Per measurement: residual (m), Jacobian row, weight, leverage.
    pub(super) rows: Vec<(f64, Vector4<f64>, f64, f64)>,
    pub(super) inv: Matrix4<f64>,
    pub(super) chi2: f64,
}

impl AtFix {
    /// `None` when the normal matrix has no inverse.
    pub fn new(ms: &[Measurement], alt: Option<AltitudeConstraint>, fix: &Fix) -> Option<AtFix> {
        let t0 = ms.iter().map(|m| m.t).fold(f64::INFINITY, f64::min);
        let x = Vector4::new(fix.ecef[0], fix.ecef[1], fix.ecef[2], C_AIR * (fix.t_emit - t0));
        let nrm = normal(&x, ms, t0, alt);
        let inv = scaled_inverse(&nrm.a)?;
        let p = Vector3::from(fix.ecef);
        let rows = (ms.iter())
            .map(|m| {
                let d = p - Vector3::from(m.pos);
                let r = d.norm().max(1.0);
                let res = C_AIR * (m.t - t0) - r - x[3];
                let j = Vector4::new(d[0] / r, d[1] / r, d[2] / r, 1.0);
                let w = 1.0 / (C_AIR * m.sigma_t).powi(2);
                (res, j, w, w * (j.transpose() * inv * j)[0])
            })
            .collect();
        Some(AtFix { rows, inv, chi2: nrm.chi2 })
    }

    /// Measurement `k`'s residual (s) and leverage.
    pub fn residual(&self, k: usize) -> (f64, f64) {
        let (res, _, _, leverage) = self.rows[k];
        (res / C_AIR, leverage)
    }

    /// Measurement `k`'s weight in the fit (relative: 1 / its variance).
    pub fn weight(&self, k: usize) -> f64 {
        self.rows[k].2
    }

    /// The fix's height (m) as its time differences alone put it, apart
    /// from its altitude constraint `alt`, and that height's variance:
    /// leaving the constraint out (Sherman-Morrison on the normal matrix,
    /// before any scaling by the residuals) moves the height by h / (1 - h)
    /// of the constraint's residual and divides the variance by 1 - h,
    /// where h is the constraint's leverage. `None` where the constraint
    /// carries the height all but alone.
    pub fn height_apart(&self, fix: &Fix, alt: AltitudeConstraint) -> Option<(f64, f64)> {
        let (lat, lon) = (fix.lat.to_radians(), fix.lon.to_radians());
        let up = Vector4::new(lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin(), 0.0);
        let v = (up.transpose() * self.inv * up)[0];
        let h = v / alt.sigma_m.powi(2);
        if !(v > 0.0 && h < 0.999) {
            return None;
        }
        Some((fix.h_m - h / (1.0 - h) * (alt.h_m - fix.h_m), v / (1.0 - h)))
    }
}

/// A fix hedged against copies that may be late without the others being
/// able to tell. A copy with most of the leverage (a precise receiver among sloppy ones)
/// pulls the fix wherever its time goes, and when it is late the fix is
/// off by as much while its covariance, set by that receiver's sigma, says
/// metres. Under the mixture "copy good" / "copy late, so worthless" the
/// fix is the leave-one-out fix with probability `p`, the posterior that
/// the copy is late (`p_late` of a measurement's index, from its residual
/// and leverage at the fix as `at` gives them): its covariance grows
/// by `p` times what leaving the copy out adds plus the spread between the
/// two fixes, `p (1 - p) d d^T` (each copy taken on its own, linearised
/// at the fix: Sherman-Morrison on the normal matrix). The position stays:
/// moved by `p d` towards the fixes without the copies (the mixture's
/// mean), network-rough's fixes came out worse, and their covariance too
/// large. A copy the fix cannot stand without (leverage near one) is
/// taken at 0.999.
pub fn hedge(fix: &Fix, at: &AtFix, p_late: impl Fn(usize) -> f64) -> Fix {
    // The fix's covariance as the solver scaled it.
    let scale = residual_scale(at.chi2, fix.dof);
    let mut cov = Matrix3::from_fn(|r, c| fix.cov_ecef[r][c]);
    for (k, &(res, j, w, leverage)) in at.rows.iter().enumerate() {
        let pl = p_late(k);
        if pl <= 0.0 {
            continue;
        }
        let keep = (1.0 - leverage).max(0.001);
        let g3 = (at.inv * j * w).fixed_rows::<3>(0).into_owned();
        // Leaving the copy out: the state moves by -g res / keep, the
        // covariance grows by g g^T / (w keep).
        let step = g3 * (res / keep);
        cov +=
            (g3 * g3.transpose()) * (pl * scale / (w * keep)) + step * step.transpose() * (pl * (1.0 - pl));
    }
    let mut out = *fix;
    let (_, [sp, cp, sl, cl]) = ecef_height_fast(fix.ecef);
    out.cov_ecef = std::array::from_fn(|r| std::array::from_fn(|c| cov[(r, c)]));
    out.cov_en = cov_en_of(&cov, [sp, cp, sl, cl]);
    out
}
