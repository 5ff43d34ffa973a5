//! What a track gives: its estimate at a time, published in the
//! aircraft's own east/north, and the move of a horizontal state from one
//! local plane to another.

use nalgebra::{Matrix2, Matrix6, Vector2, Vector6};

use super::kf::Gaussian;
use super::plane::Plane;

/// A track's estimate at a time, ready to publish or fuse.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Estimate {
    pub t: f64,
    pub lat: f64,
    pub lon: f64,
    pub alt_m: Option<f64>,
    /// East, north, up (m/s) at the aircraft; up 0 when the height is unknown.
    pub vel_enu: [f64; 3],
    /// Horizontal position covariance at the aircraft (east/north, m^2).
    pub cov_local: [[f64; 2]; 2],
    /// Horizontal state and covariance in `plane`.
    pub plane: Plane,
    pub state: Gaussian,
}

impl Estimate {
    /// The estimate of a horizontal state `g` in `plane`, with its height
    /// and climb rate: position, velocity and covariance published in the
    /// aircraft's own east/north, not the plane's.
    pub fn new(t: f64, plane: Plane, g: Gaussian, alt_m: Option<f64>, climb: f64) -> Estimate {
        let (lat, lon, r, v) = at_aircraft(&plane, &g.x);
        let c = r * g.p.fixed_view::<2, 2>(0, 0) * r.transpose();
        Estimate {
            t,
            lat,
            lon,
            alt_m,
            vel_enu: [v[0], v[1], climb],
            cov_local: [[c[(0, 0)], c[(0, 1)]], [c[(1, 0)], c[(1, 1)]]],
            plane,
            state: g,
        }
    }

    /// Horizontal position covariance in the aircraft's own east/north (m^2).
    pub fn cov_en(&self) -> [[f64; 2]; 2] {
        self.cov_local
    }

    /// The largest horizontal standard deviation of its position (m): the
    /// square root of its covariance's larger eigenvalue.
    pub fn largest_sigma_m(&self) -> f64 {
        let [[a, b], [_, c]] = self.cov_local;
        (0.5 * (a + c) + (0.25 * (a - c).powi(2) + b * b).sqrt()).max(0.0).sqrt()
    }

    /// The horizontal state expressed in another plane.
    pub fn in_plane(&self, other: &Plane) -> Gaussian {
        transfer(&self.state, &self.plane, other)
    }
}

/// A plane state's position (lat, lon), the rotation from the plane's axes
/// to the aircraft's own east/north there, and its velocity in the latter.
pub(super) fn at_aircraft(plane: &Plane, x: &Vector6<f64>) -> (f64, f64, Matrix2<f64>, Vector2<f64>) {
    let (lat, lon) = plane.to_geodetic(x[0], x[1]);
    let r = plane.from_local(lat, lon).transpose();
    (lat, lon, r, r * Vector2::new(x[2], x[3]))
}

/// A track's mean position and velocity at a time (no covariance).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kinematics {
    pub t: f64,
    pub lat: f64,
    pub lon: f64,
    pub alt_m: Option<f64>,
    /// East, north, up (m/s) at the aircraft.
    pub vel_enu: [f64; 3],
}

/// A horizontal state moved from one plane to another: the position through
/// geodetic coordinates, vectors and covariance rotated by the planes' angle
/// and scaled by their heights' ratio (a plane measures lengths on the
/// surface at its own height).
pub fn transfer(g: &Gaussian, from: &Plane, to: &Plane) -> Gaussian {
    if from == to {
        return *g;
    }
    let r = from.rotation_to(to) * from.scale_to(to);
    // The transform is r on each (east, north) pair of the state, so the
    // covariance moves block by block (r P_ab r'): a third of the
    // multiplications of two full 6 x 6 products, which only add zeros.
    let mut x = Vector6::zeros();
    let mut p = Matrix6::zeros();
    for a in 0..3 {
        x.fixed_rows_mut::<2>(2 * a).copy_from(&(r * g.x.fixed_rows::<2>(2 * a)));
        for b in 0..3 {
            let block = r * g.p.fixed_view::<2, 2>(2 * a, 2 * b) * r.transpose();
            p.fixed_view_mut::<2, 2>(2 * a, 2 * b).copy_from(&block);
        }
    }
    let (lat, lon) = from.to_geodetic(g.x[0], g.x[1]);
    let en = to.to_en(lat, lon);
    x[0] = en[0];
    x[1] = en[1];
    Gaussian { x, p: (p + p.transpose()) * 0.5 }
}
