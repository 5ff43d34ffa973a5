//! Track-to-track fusion of an ADS-B track and an MLAT track at one time.
//!
//! - `convex`: inverse-covariance weighting, as if the two errors were
//!   independent (they are not: both tracks share the aircraft's manoeuvres,
//!   so this is slightly optimistic);
//! - `information`: Bar-Shalom-Campo, the same weighting corrected by the
//!   tracks' cross-covariance, which [`Cross`] carries by the standard
//!   recursion for tracks driven by the same process noise;
//! - `ci`: covariance intersection, consistent for any unknown correlation,
//!   with the weight that minimises the trace;
//! - `reweighted`: the reweighted convex combination, `w1 = P1 P2^-1`,
//!   `w2 = P2 P1^-1` scaling each track's information by the other's
//!   relative size (our reading: information `P1^-1 w2` and `P2^-1 w1`,
//!   which are symmetric). Its covariance is smaller than the independent
//!   optimum, so it claims more than any unbiased fusion can deliver: kept
//!   for comparison, never the default.
//! - `measurement`: not here; one filter fed by both kinds of measurement.
//!
//! Both states are moved into the ADS-B track's plane first (position
//! through geodetic coordinates, vectors rotated), already at the same time.

use nalgebra::Matrix6;
use serde::Deserialize;

use crate::track::kf::Gaussian;
use crate::track::Estimate;

#[derive(Clone, Copy, Debug, Default, Deserialize, serde::Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    #[default]
    Measurement,
    Information,
    Convex,
    Ci,
    Reweighted,
}

impl Method {
    pub const ALL: [Method; 5] =
        [Method::Measurement, Method::Information, Method::Convex, Method::Ci, Method::Reweighted];

    pub fn name(self) -> &'static str {
        match self {
            Method::Measurement => "measurement",
            Method::Information => "information",
            Method::Convex => "convex",
            Method::Ci => "ci",
            Method::Reweighted => "reweighted",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Method::ALL.into_iter().find(|m| m.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
            format!("unknown fusion method {s:?} (expected one of {})", names.join(", "))
        })
    }
}

/// Cross-covariance of the two tracks' errors (ADS-B x MLAT), by the
/// recursion `P12 <- (I - K1 H) (F P12 F' + Q) (I - K2 H)'`, where each
/// track's `I - K H` is its posterior covariance times its prior's inverse
/// (the IMM's combined ones). The prediction uses one motion model (the
/// set's first); the planes' small rotation is neglected, as is the order
/// of late measurements: an approximation, measured by the NEES.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cross {
    pub t: f64,
    pub p12: Matrix6<f64>,
}

impl Cross {
    pub fn new() -> Cross {
        Cross { t: f64::NEG_INFINITY, p12: Matrix6::zeros() }
    }

    /// `P12` predicted to `t` with transition `f_q(dt)`.
    pub fn at(&self, t: f64, f_q: impl Fn(f64) -> (Matrix6<f64>, Matrix6<f64>)) -> Matrix6<f64> {
        if !self.t.is_finite() || t <= self.t {
            return self.p12;
        }
        let (f, q) = f_q(t - self.t);
        f * self.p12 * f.transpose() + q
    }

    /// Track `first` (the ADS-B one) or the other was updated at `t` with `I - K H = a`.
    pub fn update(
        &mut self,
        t: f64,
        first: bool,
        a: &Matrix6<f64>,
        f_q: impl Fn(f64) -> (Matrix6<f64>, Matrix6<f64>),
    ) {
        let p = self.at(t, f_q);
        self.p12 = if first { a * p } else { p * a.transpose() };
        self.t = self.t.max(t);
    }
}

impl Default for Cross {
    fn default() -> Self {
        Cross::new()
    }
}

fn inv(p: &Matrix6<f64>) -> Option<Matrix6<f64>> {
    p.cholesky().map(|c| c.inverse())
}

fn symmetric(p: Matrix6<f64>) -> Matrix6<f64> {
    (p + p.transpose()) * 0.5
}

/// Fuses two estimates at the same time; `None` when a covariance is not
/// positive definite (the caller publishes the better single track).
pub fn fuse(method: Method, a: &Estimate, b: &Estimate, cross: Option<&Matrix6<f64>>) -> Option<Estimate> {
    let x1 = a.state;
    let x2 = b.in_plane(&a.plane);
    let g = match method {
        Method::Convex | Method::Measurement => convex(&x1, &x2)?,
        Method::Information => match cross {
            Some(p12) => information(&x1, &x2, p12)?,
            None => convex(&x1, &x2)?,
        },
        Method::Ci => ci(&x1, &x2)?,
        Method::Reweighted => reweighted(&x1, &x2)?,
    };
    if !g.healthy() {
        return None;
    }
    let alt_m = a.alt_m.or(b.alt_m);
    let up = if a.alt_m.is_some() { a.vel_enu[2] } else { b.vel_enu[2] };
    Some(Estimate::new(a.t, a.plane, g, alt_m, up))
}

/// The single track with the smaller horizontal position covariance.
pub fn better(a: &Estimate, b: &Estimate) -> Estimate {
    let tr = |e: &Estimate| e.state.p[(0, 0)] + e.state.p[(1, 1)];
    if tr(a) <= tr(b) {
        *a
    } else {
        *b
    }
}

pub fn convex(a: &Gaussian, b: &Gaussian) -> Option<Gaussian> {
    let (ia, ib) = (inv(&a.p)?, inv(&b.p)?);
    let p = symmetric(inv(&(ia + ib))?);
    Some(Gaussian { x: p * (ia * a.x + ib * b.x), p })
}

pub fn information(a: &Gaussian, b: &Gaussian, p12: &Matrix6<f64>) -> Option<Gaussian> {
    let p21 = p12.transpose();
    let s = a.p + b.p - p12 - p21;
    let si = inv(&symmetric(s))?;
    let k = (a.p - p12) * si;
    let x = a.x + k * (b.x - a.x);
    let p = symmetric(a.p - k * (a.p - p21));
    p.cholesky()?;
    Some(Gaussian { x, p })
}

pub fn ci(a: &Gaussian, b: &Gaussian) -> Option<Gaussian> {
    let (ia, ib) = (inv(&a.p)?, inv(&b.p)?);
    let at = |w: f64| -> Option<Gaussian> {
        let info = ia * w + ib * (1.0 - w);
        let p = symmetric(inv(&info)?);
        Some(Gaussian { x: p * (ia * a.x * w + ib * b.x * (1.0 - w)), p })
    };
    // Position trace as the criterion (what is published); golden section.
    let cost = |w: f64| at(w).map_or(f64::INFINITY, |g| g.p[(0, 0)] + g.p[(1, 1)]);
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
    let (mut fc, mut fd) = (cost(c), cost(d));
    for _ in 0..40 {
        if fc < fd {
            hi = d;
            d = c;
            fd = fc;
            c = hi - phi * (hi - lo);
            fc = cost(c);
        } else {
            lo = c;
            c = d;
            fc = fd;
            d = lo + phi * (hi - lo);
            fd = cost(d);
        }
    }
    // The ends are candidates too (one track may dominate).
    [0.0, (lo + hi) / 2.0, 1.0]
        .into_iter()
        .filter_map(|w| at(w).map(|g| (cost(w), g)))
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .map(|(_, g)| g)
}

pub fn reweighted(a: &Gaussian, b: &Gaussian) -> Option<Gaussian> {
    let (ia, ib) = (inv(&a.p)?, inv(&b.p)?);
    // w1 = P1 P2^-1, w2 = P2 P1^-1; information P1^-1 w2 and P2^-1 w1.
    let wa = symmetric(ia * b.p * ia);
    let wb = symmetric(ib * a.p * ib);
    let p = symmetric(inv(&(wa + wb))?);
    Some(Gaussian { x: p * (wa * a.x + wb * b.x), p })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;

    fn g(x: f64, var: f64) -> Gaussian {
        Gaussian { x: Vector6::new(x, 0.0, 0.0, 0.0, 0.0, 0.0), p: Matrix6::identity() * var }
    }

    #[test]
    fn the_methods_on_scalar_cases() {
        let (a, b) = (g(0.0, 100.0), g(10.0, 25.0));
        let c = convex(&a, &b).unwrap();
        assert!((c.x[0] - 8.0).abs() < 1e-9 && (c.p[(0, 0)] - 20.0).abs() < 1e-9);
        // Uncorrelated: information fusion equals convex.
        let i = information(&a, &b, &Matrix6::zeros()).unwrap();
        assert!((i.x - c.x).norm() < 1e-9 && (i.p - c.p).norm() < 1e-9);
        // Fully correlated through the better track: nothing to gain.
        let i = information(&a, &b, &(Matrix6::identity() * 25.0)).unwrap();
        assert!((i.p[(0, 0)] - 25.0).abs() < 1e-6, "{}", i.p[(0, 0)]);
        // CI never below the better input's... and never above it.
        let k = ci(&a, &b).unwrap();
        assert!(k.p[(0, 0)] <= 25.0 + 1e-9 && k.p[(0, 0)] >= 20.0 - 1e-9);
        // Reweighted: below the independent optimum (20), as published.
        let r = reweighted(&a, &b).unwrap();
        let expect = 100.0f64.powi(2) * 25.0f64.powi(2) / (100.0f64.powi(3) + 25.0f64.powi(3));
        assert!((r.p[(0, 0)] - expect).abs() < 1e-9 && r.p[(0, 0)] < 20.0);
        assert!(r.x[0] > c.x[0]);
    }

    /// A covariance that is not positive definite (a filter gone bad) is
    /// fused by no method: the caller then publishes the better track.
    #[test]
    fn no_method_fuses_a_covariance_that_is_not_positive_definite() {
        let good = g(0.0, 25.0);
        let mut bad = g(10.0, 100.0);
        bad.p[(1, 1)] = -4.0;
        for (x, y) in [(&good, &bad), (&bad, &good)] {
            assert!(convex(x, y).is_none());
            assert!(information(x, y, &Matrix6::zeros()).is_none());
            assert!(ci(x, y).is_none());
            assert!(reweighted(x, y).is_none());
        }
        // And a pair of good ones is (the check above is not vacuous).
        let other = g(10.0, 100.0);
        assert!(convex(&good, &other).is_some() && information(&good, &other, &Matrix6::zeros()).is_some());
        assert!(ci(&good, &other).is_some() && reweighted(&good, &other).is_some());
    }
}
