//! The one gate of a track: every measurement (position, velocity, height,
//! time differences) is judged by its normalised innovation squared (NIS)
//! against the same chi-square threshold, computed one way.
//!
//! Why one threshold for every kind: the configured `gate_probability` is a
//! statement about outliers, not about a measurement's dimension; the
//! two-degree quantile it sets is the horizontal position's, the kind that
//! gates most, and the others have kept it since they were added.

use nalgebra::{SMatrix, SVector};

/// The threshold on the NIS that a measurement must not exceed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gate {
    threshold: f64,
}

impl Gate {
    /// The gate passing `probability` of a consistent track's measurements.
    pub fn new(probability: f64) -> Gate {
        // A chi-square with two degrees of freedom is an exponential of mean 2,
        // so its quantile has a closed form; the general numerical inverse cost
        // ten thousand instructions for every new track.
        Gate { threshold: -2.0 * (1.0 - probability).ln() }
    }

    pub fn threshold(&self) -> f64 {
        self.threshold
    }

    /// The NIS of innovation `nu` with covariance `s`; infinite when `s`
    /// cannot be inverted (a degenerate innovation is gated).
    pub fn nis<const M: usize>(nu: &SVector<f64, M>, s: &SMatrix<f64, M, M>) -> f64 {
        s.try_inverse().map_or(f64::INFINITY, |si| (nu.transpose() * si * nu)[0])
    }

    /// Whether a measurement with this NIS goes in (NaN does not).
    pub fn admits(&self, nis: f64) -> bool {
        nis <= self.threshold
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix2, Vector2};

    use super::*;

    // The threshold's quantile: `track_tests.rs`, through a track.
    #[test]
    fn nis_is_the_mahalanobis_square_and_nan_or_singular_is_gated() {
        let g = Gate::new(0.99);
        let s = Matrix2::new(4.0, 0.0, 0.0, 1.0);
        assert_eq!(Gate::nis(&Vector2::new(2.0, 1.0), &s), 2.0);
        assert!(g.admits(2.0));
        assert!(!g.admits(g.threshold() * 1.000_001));
        assert!(!g.admits(f64::NAN));
        assert!(!g.admits(Gate::nis(&Vector2::new(1.0, 1.0), &Matrix2::zeros())));
    }
}
