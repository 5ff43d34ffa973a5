//! The TDOA solver: where an emitter is, given when several receivers heard it.
//!
//! Pseudorange form in ECEF: receiver i measured `rho_i = c * t_i` (metres, in
//! one common clock), the model is `|p - r_i| + b` with `b` the unknown
//! emission time times c. An optional altitude pseudo-measurement (the
//! message's own or a recent Mode S altitude, with an age-inflated sigma)
//! makes three receivers enough and stabilises weak geometry.
//!
//! Start: Bancroft's closed form (4+ receivers; both roots are tried, which
//! handles the mirror solution) or a caller's guess; with one degree of
//! freedom or none and no guess, also starts that look for a second
//! solution (a group two solutions fit is ambiguous); then Levenberg-Marquardt
//! on 4x4 normal equations with nalgebra fixed-size matrices (no heap).
//! Covariance from the weighted Jacobian at the solution, scaled by the
//! residual chi-square when that exceeds its degrees of freedom, so a fix
//! never claims more than its own residuals support.

use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};

use crate::geo::{ecef_from_sin_cos, ecef_height_fast, ecef_to_geodetic};

/// Speed of light in air (the simulator's and the solver's; refractive index 1.0003).
pub const C_AIR: f64 = 299_792_458.0 / 1.0003;

/// One receiver's measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurement {
    pub pos: [f64; 3],
    /// Time of arrival in the common clock (s), relative to any epoch shared by the group.
    pub t: f64,
    /// 1-sigma timing error (s).
    pub sigma_t: f64,
}

/// Height above the ellipsoid (m) with its 1-sigma.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AltitudeConstraint {
    pub h_m: f64,
    pub sigma_m: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverLimits {
    /// Reject fixes whose residual chi-square exceeds this quantile's value
    /// (when `chi2_reject`); the quantile also says when a start's fit is
    /// good enough not to try the others.
    pub chi2_quantile: f64,
    pub chi2_reject: bool,
    pub max_iterations: usize,
    /// Farther than this from every receiver (m): reject.
    pub max_range_m: f64,
    pub min_height_m: f64,
    pub max_height_m: f64,
    /// Largest horizontal dilution of precision accepted.
    pub max_gdop: f64,
}

impl Default for SolverLimits {
    fn default() -> Self {
        SolverLimits {
            chi2_quantile: 0.999,
            chi2_reject: true,
            // Well-conditioned fixes converge in a handful; a surface target
            // among receivers in one plane can take 30.
            max_iterations: 40,
            max_range_m: 500_000.0,
            min_height_m: -1_000.0,
            max_height_m: 25_000.0,
            max_gdop: 50.0,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fix {
    pub ecef: [f64; 3],
    pub lat: f64,
    pub lon: f64,
    pub h_m: f64,
    /// Emission time in the common clock (s).
    pub t_emit: f64,
    /// Position covariance (ECEF, m^2).
    pub cov_ecef: [[f64; 3]; 3],
    /// Horizontal covariance in the local east/north plane (m^2).
    pub cov_en: [[f64; 2]; 2],
    /// Residual chi-square and its degrees of freedom.
    pub chi2: f64,
    pub dof: usize,
    /// Geometric dilution of precision (3-D position, in units of the timing sigma).
    pub gdop: f64,
    pub iterations: usize,
    /// The other solution of an exactly determined group started from an
    /// earlier fix (ECEF), where one was found: the group fits it as well.
    pub mirror: Option<[f64; 3]>,
}

/// Why no fix.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Reject {
    TooFewMeasurements,
    Diverged,
    Singular,
    Residual,
    Range,
    Height,
    Gdop,
    /// Two solutions fit (exactly determined, or two far apart with
    /// little redundancy) and no earlier fix with redundancy chooses.
    Ambiguous,
}

impl Reject {
    pub const ALL: [Reject; 8] = [
        Reject::TooFewMeasurements,
        Reject::Diverged,
        Reject::Singular,
        Reject::Residual,
        Reject::Range,
        Reject::Height,
        Reject::Gdop,
        Reject::Ambiguous,
    ];
    /// Its place in [`Reject::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            Reject::TooFewMeasurements => "too_few",
            Reject::Diverged => "diverged",
            Reject::Singular => "singular",
            Reject::Residual => "residual",
            Reject::Range => "range",
            Reject::Height => "height",
            Reject::Gdop => "gdop",
            Reject::Ambiguous => "ambiguous",
        }
    }
}

/// What a fix's covariance is scaled by: its chi-square per degree of
/// freedom when the residuals say the sigmas were optimistic (beyond what
/// chance explains at 1%), else one, so that an honest fix keeps an
/// unbiased covariance while optimistic sigmas, which exceed it routinely,
/// do not. The solver scales with it, and the hedge reads it back.
fn residual_scale(chi2: f64, dof: usize) -> f64 {
    if dof > 0 && chi2 > chi2_quantile(dof, 0.99) {
        chi2 / dof as f64
    } else {
        1.0
    }
}

/// Upper unit normal of the ellipsoid at a point (the gradient of height).
fn up(lat: f64, lon: f64) -> Vector3<f64> {
    let (sp, cp) = lat.to_radians().sin_cos();
    let (sl, cl) = lon.to_radians().sin_cos();
    Vector3::new(cp * cl, cp * sl, sp)
}

struct Normal {
    a: Matrix4<f64>,
    g: Vector4<f64>,
    chi2: f64,
}

/// Normal equations and chi-square at state `x = (p, b)`.
fn normal(x: &Vector4<f64>, ms: &[Measurement], t0: f64, alt: Option<AltitudeConstraint>) -> Normal {
    let p = x.fixed_rows::<3>(0).into_owned();
    let mut a = Matrix4::zeros();
    let mut g = Vector4::zeros();
    let mut chi2 = 0.0;
    for m in ms {
        let d = p - Vector3::from(m.pos);
        let r = d.norm().max(1.0);
        let rho = C_AIR * (m.t - t0);
        let res = rho - r - x[3];
        let w = 1.0 / (C_AIR * m.sigma_t).powi(2);
        let j = Vector4::new(d[0] / r, d[1] / r, d[2] / r, 1.0);
        a += w * j * j.transpose();
        g += w * res * j;
        chi2 += w * res * res;
    }
    if let Some(c) = alt {
        let (h, [sp, cp, sl, cl]) = ecef_height_fast([p[0], p[1], p[2]]);
        let u = Vector3::new(cp * cl, cp * sl, sp);
        let res = c.h_m - h;
        let w = 1.0 / (c.sigma_m * c.sigma_m);
        let j = Vector4::new(u[0], u[1], u[2], 0.0);
        a += w * j * j.transpose();
        g += w * res * j;
        chi2 += w * res * res;
    }
    Normal { a, g, chi2 }
}

/// Bancroft's closed form: both candidate states (p, b) for 4+ pseudoranges.
fn bancroft(ms: &[Measurement], t0: f64) -> [Option<Vector4<f64>>; 2] {
    let lorentz = |u: &Vector4<f64>, v: &Vector4<f64>| u[0] * v[0] + u[1] * v[1] + u[2] * v[2] - u[3] * v[3];
    // Rows [s_i, -rho_i]; B+ = (B^T W B)^-1 B^T W, with the receivers' weights.
    let mut btb = Matrix4::zeros();
    let mut bte = Vector4::zeros();
    let mut bta = Vector4::zeros();
    for m in ms {
        let rho = C_AIR * (m.t - t0);
        let row = Vector4::new(m.pos[0], m.pos[1], m.pos[2], -rho);
        let w = 1.0 / (m.sigma_t * 1e9).powi(2);
        let a = 0.5 * lorentz(&row, &row);
        btb += w * row * row.transpose();
        bte += w * row;
        bta += w * a * row;
    }
    let Some(inv) = btb.try_inverse() else { return [None, None] };
    let (u, v) = (inv * bte, inv * bta);
    let (qa, qb, qc) = (lorentz(&u, &u), 2.0 * (lorentz(&u, &v) - 1.0), lorentz(&v, &v));
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 || qa.abs() < 1e-300 {
        return [None, None];
    }
    let s = disc.sqrt();
    let root = |l: f64| {
        let y = v + l * u;
        // y = (p, b) with b defined by rho = |p - s| + b.
        Some(Vector4::new(y[0], y[1], y[2], y[3]))
    };
    [root((-qb + s) / (2.0 * qa)), root((-qb - s) / (2.0 * qa))]
}

/// Chi-square quantile for small degrees of freedom (Wilson-Hilferty; within
/// a few percent for dof >= 1 at the tail quantiles used here).
pub fn chi2_quantile(dof: usize, q: f64) -> f64 {
    let k = dof.max(1) as f64;
    // Standard normal quantile by Acklam's rational approximation (tail part suffices here).
    let z = {
        let p = q.clamp(1e-12, 1.0 - 1e-12);
        let t = (-2.0 * (1.0 - p).ln()).sqrt();
        t - (2.515_517 + 0.802_853 * t + 0.010_328 * t * t)
            / (1.0 + 1.432_788 * t + 0.189_269 * t * t + 0.001_308 * t.powi(3))
    };
    let h = 2.0 / (9.0 * k);
    k * (1.0 - h + z * h.sqrt()).powi(3)
}

/// Two solutions further apart than this (m) are two, not one found twice.
const MIRROR_APART_M: f64 = 1_000.0;
/// Starts above the first receivers, for a group with little redundancy
/// and no earlier fix.
const EXPLORE_STARTS: usize = 4;
/// Radii (m) of the rings of starts around a first solution.
const RING_RADII_M: [f64; 2] = [40_000.0, 90_000.0];

/// Starts around `p` (ECEF), at its height: eight bearings at each of
/// [`RING_RADII_M`].
fn ring_starts(p: Vector3<f64>) -> impl Iterator<Item = Vector3<f64>> {
    let u = p.normalize();
    let e1 = Vector3::z().cross(&u).try_normalize(1e-9).unwrap_or_else(Vector3::x);
    let e2 = u.cross(&e1);
    RING_RADII_M.into_iter().flat_map(move |r| {
        (0..8).map(move |k| {
            let a = k as f64 * std::f64::consts::FRAC_PI_4;
            p + (e1 * a.cos() + e2 * a.sin()) * r
        })
    })
}

/// Solves for the emitter. `guess` (ECEF) is tried first when given.
// Over 80 lines, kept whole: start, Levenberg-Marquardt iterations and
// covariance share the stack matrices of one solve on the per-fix path.
pub fn solve(
    ms: &[Measurement],
    alt: Option<AltitudeConstraint>,
    guess: Option<[f64; 3]>,
    limits: &SolverLimits,
) -> Result<Fix, Reject> {
    let n = ms.len() + alt.is_some() as usize;
    if ms.len() < 3 || n < 4 {
        return Err(Reject::TooFewMeasurements);
    }
    // Work relative to the earliest arrival so pseudoranges stay small.
    let t0 = ms.iter().map(|m| m.t).fold(f64::INFINITY, f64::min);
    let mut starts: [Option<Vector4<f64>>; 4 + EXPLORE_STARTS] = [None; 4 + EXPLORE_STARTS];
    let b_for = |p: Vector3<f64>| {
        // Emission offset that best matches the measurements from p.
        let mut s = 0.0;
        for m in ms {
            s += C_AIR * (m.t - t0) - (p - Vector3::from(m.pos)).norm();
        }
        s / ms.len() as f64
    };
    if let Some(g) = guess {
        let p = Vector3::from(g);
        starts[0] = Some(Vector4::new(p[0], p[1], p[2], b_for(p)));
    }
    if ms.len() >= 4 {
        let [a, b] = bancroft(ms, t0);
        starts[1] = a;
        starts[2] = b;
    }
    {
        // Centroid of the receivers, lifted to the constrained altitude or 10 km.
        let mut c = Vector3::zeros();
        for m in ms {
            c += Vector3::from(m.pos);
        }
        c /= ms.len() as f64;
        let (_, sc) = ecef_height_fast([c[0], c[1], c[2]]);
        let h = alt.map_or(10_000.0, |a| a.h_m);
        let p = Vector3::from(ecef_from_sin_cos(sc, h));
        starts[3] = Some(Vector4::new(p[0], p[1], p[2], b_for(p)));
    }
    let dof = n - 4;
    if guess.is_none() && dof <= 1 {
        // Little redundancy and nothing to start from: a second solution
        // must be looked for, or the first one found is taken for the only
        // one. The aircraft is within reach of every receiver, so above
        // each of them is a start near each solution.
        let h = alt.map_or(10_000.0, |a| a.h_m);
        for (slot, m) in starts[4..].iter_mut().zip(ms) {
            let (_, sc) = ecef_height_fast(m.pos);
            let p = Vector3::from(ecef_from_sin_cos(sc, h));
            *slot = Some(Vector4::new(p[0], p[1], p[2], b_for(p)));
        }
    }
    let chi2_limit = if dof > 0 && limits.chi2_quantile < 1.0 {
        chi2_quantile(dof, limits.chi2_quantile)
    } else {
        f64::INFINITY
    };
    let mut best: Option<(Vector4<f64>, Normal, usize)> = None;
    let mut saw_failure = false;
    // Every solution that fits, to see whether a second one does too.
    let mut fits: [Option<Vector3<f64>>; 4 + EXPLORE_STARTS + 16] = [None; 4 + EXPLORE_STARTS + 16];
    // A refined start: kept among the fits if it fits, and as the best if it is.
    let mut take = |(x, nrm, it): (Vector4<f64>, Normal, usize),
                    best: &mut Option<(Vector4<f64>, Normal, usize)>| {
        let height = ecef_height_fast([x[0], x[1], x[2]]).0;
        if nrm.chi2 <= chi2_limit && (limits.min_height_m..=limits.max_height_m).contains(&height) {
            if let Some(slot) = fits.iter_mut().find(|f| f.is_none()) {
                *slot = Some(Vector3::new(x[0], x[1], x[2]));
            }
        }
        if best.as_ref().is_none_or(|b| nrm.chi2 < b.1.chi2) {
            *best = Some((x, nrm, it));
        }
    };
    for start in starts.into_iter().flatten() {
        // Bancroft's other root is often in space or inside the Earth: skip
        // starts no aircraft could be at.
        if !start.iter().all(|v| v.is_finite())
            || !(-5_000.0..60_000.0).contains(&ecef_height_fast([start[0], start[1], start[2]]).0)
        {
            continue;
        }
        match refine(start, ms, t0, alt, limits.max_iterations) {
            Some(refined) => {
                take(refined, &mut best);
                // A clean fit from a good start needs no second opinion.
                if best.as_ref().is_some_and(|b| b.1.chi2 <= chi2_limit * 0.5 || dof == 0) && guess.is_some()
                {
                    break;
                }
            }
            None => saw_failure = true,
        }
    }
    // Exactly determined and started from an earlier fix: the solution
    // found is the one nearer that fix, and the other is looked for too
    // (kept apart from the best, which it fits as exactly): the caller
    // tells whether the aircraft could be at either.
    let look_for_mirror = guess.is_some() && dof == 0;
    if let (true, Some(b)) = (look_for_mirror || (guess.is_none() && dof <= 1), &best) {
        // Receivers nearly in a line see the aircraft and a second solution
        // alike, and starts near them fall to either side: a ring of starts
        // around the first solution looks for the other.
        let first = Vector3::new(b.0[0], b.0[1], b.0[2]);
        let mut scratch = None;
        let into = if look_for_mirror { &mut scratch } else { &mut best };
        // A mirror that matters is within reach of the earlier fix, so
        // within tens of kilometres: the inner ring finds it.
        let rings = if look_for_mirror { 1 } else { RING_RADII_M.len() };
        for start in ring_starts(first).take(8 * rings) {
            let start = Vector4::new(start[0], start[1], start[2], b_for(start));
            if let Some(refined) = refine(start, ms, t0, alt, limits.max_iterations) {
                take(refined, into);
            }
        }
    }
    let Some((x, nrm, iterations)) = best else {
        return Err(if saw_failure { Reject::Diverged } else { Reject::Singular });
    };
    if limits.chi2_reject && nrm.chi2 > chi2_limit {
        return Err(Reject::Residual);
    }
    // With little redundancy two solutions far apart can both fit (the
    // mirror of an exactly determined group, barely told apart by one more
    // measurement): without an earlier fix to choose, neither is the fix.
    // Taken blindly, the better fitting one was the mirror for whole tracks,
    // tens of kilometres off with covariances of tens of metres.
    if guess.is_none() && dof >= 1 {
        let here = Vector3::new(x[0], x[1], x[2]);
        if fits.iter().flatten().any(|f| (f - here).norm() > MIRROR_APART_M) {
            return Err(Reject::Ambiguous);
        }
    }
    let p = [x[0], x[1], x[2]];
    let here = Vector3::from(p);
    let mirror = look_for_mirror
        .then(|| fits.iter().flatten().find(|f| (*f - here).norm() > MIRROR_APART_M))
        .flatten()
        .map(|f| [f[0], f[1], f[2]]);
    let (h, [sp, cp, sl, cl]) = ecef_height_fast(p);
    let (lat, lon) = (sp.atan2(cp).to_degrees(), sl.atan2(cl).to_degrees());
    if !(limits.min_height_m..=limits.max_height_m).contains(&h) {
        return Err(Reject::Height);
    }
    let nearest =
        ms.iter().map(|m| (Vector3::from(p) - Vector3::from(m.pos)).norm()).fold(f64::INFINITY, f64::min);
    if nearest > limits.max_range_m {
        return Err(Reject::Range);
    }
    let Some(cov4) = scaled_inverse(&nrm.a) else { return Err(Reject::Singular) };
    let scale = residual_scale(nrm.chi2, dof);
    let cov3: Matrix3<f64> = cov4.fixed_view::<3, 3>(0, 0).into_owned() * scale;
    let mean_sigma_m = {
        let s: f64 = ms.iter().map(|m| 1.0 / (C_AIR * m.sigma_t).powi(2)).sum::<f64>() / ms.len() as f64;
        1.0 / s.sqrt()
    };
    let gdop = (cov4.fixed_view::<3, 3>(0, 0).trace()).sqrt() / mean_sigma_m;
    let cen = cov_en_of(&cov3, [sp, cp, sl, cl]);
    // Geometry limit on the horizontal part (height is usually constrained).
    let hdop = ((cen[0][0] + cen[1][1]) / scale).sqrt() / mean_sigma_m;
    if !hdop.is_finite() || hdop > limits.max_gdop {
        return Err(Reject::Gdop);
    }
    let mut cov_ecef = [[0.0; 3]; 3];
    for (r, row) in cov_ecef.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = cov3[(r, c)];
        }
    }
    Ok(Fix {
        ecef: p,
        lat,
        lon,
        h_m: h,
        t_emit: t0 + x[3] / C_AIR,
        cov_ecef,
        cov_en: cen,
        chi2: nrm.chi2,
        dof,
        gdop,
        iterations,
        mirror,
    })
}

/// Jacobi scaling of a symmetric positive matrix: `d = diag(a)^-1/2` and
/// `d a d`, whose unit diagonal Cholesky handles even when pseudorange
/// weights (1e6 and more) and an altitude weight (1e-4) share one matrix.
fn jacobi(a: &Matrix4<f64>) -> (Vector4<f64>, Matrix4<f64>) {
    let d = Vector4::from_fn(|i, _| 1.0 / a[(i, i)].max(1e-300).sqrt());
    (d, Matrix4::from_fn(|r, c| a[(r, c)] * d[r] * d[c]))
}

/// Solves `a x = g` through the Jacobi-scaled matrix.
fn scaled_solve(a: &Matrix4<f64>, g: &Vector4<f64>) -> Option<Vector4<f64>> {
    let (d, s) = jacobi(a);
    let y = s.cholesky()?.solve(&g.component_mul(&d));
    Some(y.component_mul(&d))
}

/// Inverse of a symmetric positive definite matrix, through the scaled one.
fn scaled_inverse(a: &Matrix4<f64>) -> Option<Matrix4<f64>> {
    let (d, s) = jacobi(a);
    let inv = s.cholesky()?.inverse();
    Some(Matrix4::from_fn(|r, c| inv[(r, c)] * d[r] * d[c]))
}

/// The Cramér-Rao bound of a geometry: the horizontal (east/north)
/// covariance (m^2) of any unbiased fix of an emitter at `truth` heard by
/// receivers at `pos` with timing sigmas `sigma_t` (s), with an optional
/// altitude constraint of sigma `alt_sigma_m`.
pub fn crb_en(
    pos: &[[f64; 3]],
    sigma_t: &[f64],
    alt_sigma_m: Option<f64>,
    truth: [f64; 3],
) -> Option<[[f64; 2]; 2]> {
    let p = Vector3::from(truth);
    let mut a = Matrix4::zeros();
    for (r, s) in pos.iter().zip(sigma_t) {
        let d = p - Vector3::from(*r);
        let n = d.norm().max(1.0);
        let j = Vector4::new(d[0] / n, d[1] / n, d[2] / n, 1.0);
        a += j * j.transpose() / (C_AIR * s).powi(2);
    }
    let (lat, lon, _) = ecef_to_geodetic(truth);
    if let Some(sh) = alt_sigma_m {
        let u = up(lat, lon);
        let j = Vector4::new(u[0], u[1], u[2], 0.0);
        a += j * j.transpose() / (sh * sh);
    }
    let c = scaled_inverse(&a)?.fixed_view::<3, 3>(0, 0).into_owned();
    let (sp, cp) = lat.to_radians().sin_cos();
    let (sl, cl) = lon.to_radians().sin_cos();
    Some(cov_en_of(&c, [sp, cp, sl, cl]))
}

/// An ECEF position covariance seen in the local east/north plane, given the
/// sines and cosines of latitude and longitude there.
fn cov_en_of(c: &Matrix3<f64>, [sp, cp, sl, cl]: [f64; 4]) -> [[f64; 2]; 2] {
    let e = Vector3::new(-sl, cl, 0.0);
    let n = Vector3::new(-sp * cl, -sp * sl, cp);
    [
        [(e.transpose() * c * e)[0], (e.transpose() * c * n)[0]],
        [(n.transpose() * c * e)[0], (n.transpose() * c * n)[0]],
    ]
}

/// Levenberg-Marquardt from `x`.
fn refine(
    mut x: Vector4<f64>,
    ms: &[Measurement],
    t0: f64,
    alt: Option<AltitudeConstraint>,
    max_iterations: usize,
) -> Option<(Vector4<f64>, Normal, usize)> {
    let mut cur = normal(&x, ms, t0, alt);
    let mut lambda = 1e-6;
    let mut last = Vector4::zeros();
    for it in 1..=max_iterations {
        // At the optimum to within 3% of the fix's own uncertainty: the full
        // Gauss-Newton step would lower chi-square by less than 0.001 (along
        // a direction the geometry barely fixes, such as the height of a
        // surface target, steps stay metres long near the optimum while
        // changing nothing that matters). The undamped step: a damped one is
        // short because of the damping, not because the fit is done.
        if scaled_solve(&cur.a, &cur.g).is_some_and(|gn| cur.g.dot(&gn) < 1e-3) {
            return Some((x, cur, it));
        }
        let mut a = cur.a;
        for k in 0..4 {
            a[(k, k)] *= 1.0 + lambda;
        }
        let mut step = scaled_solve(&a, &cur.g)?;
        if !step.iter().all(|v| v.is_finite()) {
            return None;
        }
        // A step that turns back on the last one is zig-zagging across a
        // curved valley (the height of a target in the receivers' plane):
        // half of it lands near the floor, where the full one overshoots
        // again; without this a fifth of such fixes ran out of iterations.
        if step.dot(&last) < 0.0 {
            step *= 0.5;
        }
        last = step;
        let cand = x + step;
        let next = normal(&cand, ms, t0, alt);
        // Converged: a centimetre step. Checked before acceptance, because at
        // the optimum chi-square only wobbles in its last digits.
        if step.fixed_rows::<3>(0).norm() < 1e-2 {
            return Some(if next.chi2 <= cur.chi2 { (cand, next, it) } else { (x, cur, it) });
        }
        if next.chi2 <= cur.chi2 {
            // Also converged: the fit no longer improves (inconsistent data
            // settles at its least-squares optimum without millimetre steps).
            let stalled =
                cur.chi2 - next.chi2 <= 1e-9 * cur.chi2.max(1e-12) && step.fixed_rows::<3>(0).norm() < 1.0;
            x = cand;
            cur = next;
            lambda = (lambda * 0.1).max(1e-12);
            if stalled {
                return Some((x, cur, it));
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e8 {
                return Some((x, cur, it));
            }
        }
    }
    None
}

mod at_fix;
pub use at_fix::{hedge, AtFix};
mod sandwich;

#[cfg(test)]
mod tests;
