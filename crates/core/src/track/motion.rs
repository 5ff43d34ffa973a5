//! Static/moving test for targets located by multilateration (surface
//! traffic): over a sliding window of N fixes, the differences to the newest
//! fix, normalised by the fixes' own covariances, are chi-square when the
//! target stands still; a statistic beyond the false-alarm threshold says it
//! moves.
//!
//! The differences share the newest fix, so their joint covariance is the
//! block diagonal of the older fixes' covariances plus the newest one's in
//! every block. Two forms: along one axis (N-1 degrees of freedom, the form
//! of the published surface-MLAT result: 5.99 for N=3 and 9.49 for N=5 at 5%)
//! and in the plane (2(N-1) degrees of freedom), which the tracker uses
//! because a target may move in any direction.

use nalgebra::{DMatrix, DVector, Matrix2, Vector2};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// One fix: east/north position (m) and its covariance (m^2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fix2 {
    pub pos: Vector2<f64>,
    pub cov: Matrix2<f64>,
}

/// The statistic along the unit vector `u`: chi-square with N-1 dof when static.
pub fn statistic_axis(window: &[Fix2], u: Vector2<f64>) -> Option<f64> {
    let (newest, older) = window.split_last()?;
    let m = older.len();
    if m == 0 {
        return None;
    }
    let vn = (u.transpose() * newest.cov * u)[0];
    let d = DVector::from_iterator(m, older.iter().map(|f| u.dot(&(f.pos - newest.pos))));
    let c =
        DMatrix::from_fn(m, m, |r, k| vn + if r == k { (u.transpose() * older[r].cov * u)[0] } else { 0.0 });
    let ci = c.cholesky()?.inverse();
    Some((d.transpose() * ci * d)[0])
}

/// The statistic in the plane: chi-square with 2(N-1) dof when static.
pub fn statistic_2d(window: &[Fix2]) -> Option<f64> {
    let (newest, older) = window.split_last()?;
    let m = older.len();
    if m == 0 {
        return None;
    }
    let mut d = DVector::zeros(2 * m);
    let mut c = DMatrix::zeros(2 * m, 2 * m);
    for (i, f) in older.iter().enumerate() {
        let diff = f.pos - newest.pos;
        d[2 * i] = diff[0];
        d[2 * i + 1] = diff[1];
        for j in 0..m {
            for (r, k) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                let own = if i == j { older[i].cov[(r, k)] } else { 0.0 };
                c[(2 * i + r, 2 * j + k)] = own + newest.cov[(r, k)];
            }
        }
    }
    let ci = c.cholesky()?.inverse();
    Some((d.transpose() * ci * d)[0])
}

/// Threshold of a chi-square test with `dof` degrees of freedom at false-alarm rate `pfa`.
pub fn threshold(dof: usize, pfa: f64) -> f64 {
    ChiSquared::new(dof as f64).expect("positive dof").inverse_cdf(1.0 - pfa)
}

/// P(noncentral chi-square(dof, lambda) <= x): the probability of calling a
/// mover static. Poisson mixture of central chi-squares.
pub fn noncentral_cdf(dof: usize, lambda: f64, x: f64) -> f64 {
    let half = lambda / 2.0;
    let mut weight = (-half).exp();
    let mut sum = 0.0;
    for j in 0..500 {
        if j > 0 {
            weight *= half / j as f64;
        }
        sum += weight * ChiSquared::new((dof + 2 * j) as f64).expect("dof").cdf(x);
        if j as f64 > half && weight < 1e-15 {
            break;
        }
    }
    sum
}

/// Static, moving, or not yet known: the track's `motion`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Motion {
    Unknown,
    Static,
    Moving,
}

impl Motion {
    pub fn name(self) -> &'static str {
        match self {
            Motion::Unknown => "unknown",
            Motion::Static => "static",
            Motion::Moving => "moving",
        }
    }
}

/// The plane test over the last `n` fixes at a false-alarm rate.
#[derive(Clone, Debug)]
pub struct MotionTest {
    n: usize,
    threshold: f64,
    window: std::collections::VecDeque<Fix2>,
}

impl MotionTest {
    pub fn new(n: usize, pfa: f64) -> MotionTest {
        assert!(n >= 2, "a window of at least two fixes");
        MotionTest { n, threshold: threshold(2 * (n - 1), pfa), window: Default::default() }
    }

    /// Forgets the fixes (the plane they were measured in has moved) but keeps
    /// the threshold, whose numerical inverse is costly to recompute.
    pub fn restart(&mut self) {
        self.window.clear();
    }

    pub fn push(&mut self, fix: Fix2) -> Motion {
        if self.window.len() == self.n {
            self.window.pop_front();
        }
        self.window.push_back(fix);
        if self.window.len() < self.n {
            return Motion::Unknown;
        }
        match statistic_2d(self.window.make_contiguous()) {
            Some(s) if s <= self.threshold => Motion::Static,
            Some(_) => Motion::Moving,
            None => Motion::Unknown,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_match_the_chi_square_table() {
        assert!((threshold(2, 0.05) - 5.991).abs() < 1e-3);
        assert!((threshold(4, 0.05) - 9.488).abs() < 1e-3);
        // Noncentral with lambda 0 is the central distribution.
        assert!((noncentral_cdf(2, 0.0, 5.991) - 0.95).abs() < 1e-4);
        // Against scipy.stats.ncx2.cdf: (5.991; 2, 4) = 0.584534, (9.488; 4, 10) = 0.284030.
        assert!((noncentral_cdf(2, 4.0, 5.991) - 0.584534).abs() < 1e-5);
        assert!((noncentral_cdf(4, 10.0, 9.488) - 0.284030).abs() < 1e-5);
    }

    #[test]
    fn a_window_of_identical_fixes_is_static_and_a_runner_is_not() {
        let cov = Matrix2::identity();
        let mut t = MotionTest::new(3, 0.05);
        assert_eq!(t.push(Fix2 { pos: Vector2::zeros(), cov }), Motion::Unknown);
        assert_eq!(t.push(Fix2 { pos: Vector2::zeros(), cov }), Motion::Unknown);
        assert_eq!(t.push(Fix2 { pos: Vector2::new(0.5, 0.0), cov }), Motion::Static);
        assert_eq!(t.push(Fix2 { pos: Vector2::new(10.0, 0.0), cov }), Motion::Moving);
        let w = [Fix2 { pos: Vector2::zeros(), cov }, Fix2 { pos: Vector2::new(3.0, 0.0), cov }];
        // One difference of 3 m with variance 1 + 1 along x: 4.5.
        assert!((statistic_axis(&w, Vector2::new(1.0, 0.0)).unwrap() - 4.5).abs() < 1e-12);
        assert!((statistic_2d(&w).unwrap() - 4.5).abs() < 1e-12);
    }
}
