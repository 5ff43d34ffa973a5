//! The local tangent plane a track lives in, re-centred as the aircraft moves.
//!
//! A flat east/north frame keeps the filters linear and their matrices 6x6;
//! it stays accurate only near its origin, so a track moves its origin under
//! the aircraft every few tens of kilometres (the frame's north turns by
//! the meridians' convergence, well under a degree per step, and the state
//! and covariance are rotated with it). Points are projected along the
//! ellipsoid normal onto the surface at the origin's height, so an aircraft
//! climbing far from the origin does not appear to move sideways; lengths
//! are those on that surface, so the plane also follows the aircraft's
//! height (a velocity report is in metres at the aircraft).

use nalgebra::{Matrix2, Vector3};

use crate::geo::{ecef_from_sin_cos, ecef_to_geodetic, geodetic_to_ecef, EARTH_MEAN_RADIUS_M};

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Plane {
    pub lat: f64,
    pub lon: f64,
    pub h: f64,
    origin: Vector3<f64>,
    east: Vector3<f64>,
    north: Vector3<f64>,
    up: Vector3<f64>,
}

impl Plane {
    pub fn new(lat: f64, lon: f64, h: f64) -> Plane {
        let sc = sin_cos(lat, lon);
        let [east, north, up] = axes(sc);
        Plane { lat, lon, h, origin: Vector3::from(ecef_from_sin_cos(sc, h)), east, north, up }
    }

    /// East/north (m) of a point, projected to the origin's height.
    pub fn to_en(&self, lat: f64, lon: f64) -> [f64; 2] {
        let d = Vector3::from(geodetic_to_ecef(lat, lon, self.h)) - self.origin;
        [d.dot(&self.east), d.dot(&self.north)]
    }

    /// Latitude and longitude (deg) of a plane point.
    pub fn to_geodetic(&self, e: f64, n: f64) -> (f64, f64) {
        // Drop to the curved surface at the origin's height.
        let u = -(e * e + n * n) / (2.0 * (EARTH_MEAN_RADIUS_M + self.h));
        let p = self.origin + self.east * e + self.north * n + self.up * u;
        let (lat, lon, _) = ecef_to_geodetic([p.x, p.y, p.z]);
        (lat, lon)
    }

    /// Plane-local east, north, up (m) of an ECEF point.
    pub fn ecef_to_local(&self, p: [f64; 3]) -> Vector3<f64> {
        let d = Vector3::from(p) - self.origin;
        Vector3::new(d.dot(&self.east), d.dot(&self.north), d.dot(&self.up))
    }

    /// The local up coordinate of the point at plane position (e, n) and height `h` (m).
    pub fn up_at(&self, e: f64, n: f64, h: f64) -> f64 {
        h - self.h - (e * e + n * n) / (2.0 * (EARTH_MEAN_RADIUS_M + self.h))
    }

    /// Rotation taking horizontal vectors given in the local east/north at
    /// (`lat`, `lon`) into this plane's axes (they differ by the meridians'
    /// convergence); its transpose goes back.
    pub fn from_local(&self, lat: f64, lon: f64) -> Matrix2<f64> {
        // The axes alone (every published estimate asks this): a whole plane
        // there computed its origin too.
        let [east, north, _] = axes(sin_cos(lat, lon));
        rotation(&east, &north, self)
    }

    /// How much longer a length on this plane's surface is on `other`'s
    /// (the ratio of their distances from the Earth's centre).
    pub fn scale_to(&self, other: &Plane) -> f64 {
        (EARTH_MEAN_RADIUS_M + other.h) / (EARTH_MEAN_RADIUS_M + self.h)
    }

    /// Rotation taking horizontal vectors of `self` into `other`'s axes.
    pub fn rotation_to(&self, other: &Plane) -> Matrix2<f64> {
        rotation(&self.east, &self.north, other)
    }
}

/// `[sin lat, cos lat, sin lon, cos lon]` of a position in degrees.
fn sin_cos(lat: f64, lon: f64) -> [f64; 4] {
    let (sp, cp) = lat.to_radians().sin_cos();
    let (sl, cl) = lon.to_radians().sin_cos();
    [sp, cp, sl, cl]
}

/// The local east, north and up unit vectors (ECEF) at a position given by
/// [`sin_cos`].
fn axes([sp, cp, sl, cl]: [f64; 4]) -> [Vector3<f64>; 3] {
    [Vector3::new(-sl, cl, 0.0), Vector3::new(-sp * cl, -sp * sl, cp), Vector3::new(cp * cl, cp * sl, sp)]
}

/// Rotation taking horizontal vectors given along `east` and `north` into
/// `to`'s axes.
fn rotation(east: &Vector3<f64>, north: &Vector3<f64>, to: &Plane) -> Matrix2<f64> {
    Matrix2::new(to.east.dot(east), to.east.dot(north), to.north.dot(east), to.north.dot(north))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_rotation() {
        let p = Plane::new(60.0, 10.0, 3000.0);
        for (e, n) in [(0.0, 0.0), (25_000.0, -10_000.0), (-40_000.0, 35_000.0)] {
            let (lat, lon) = p.to_geodetic(e, n);
            let back = p.to_en(lat, lon);
            assert!((back[0] - e).abs() < 0.01 && (back[1] - n).abs() < 0.01, "{back:?}");
        }
        // 1 km north is 1 km north; a plane 50 km east has north turned by
        // the meridians' convergence, dlon * sin(lat).
        let (lat, lon) = p.to_geodetic(0.0, 1000.0);
        assert!((crate::geo::distance_m(60.0, 10.0, lat, lon) - 1000.0).abs() < 5.0);
        let (lat2, lon2) = p.to_geodetic(50_000.0, 0.0);
        let q = Plane::new(lat2, lon2, 3000.0);
        let r = p.rotation_to(&q);
        let angle = r[(1, 0)].atan2(r[(0, 0)]).to_degrees();
        let expect = -(lon2 - 10.0) * 60f64.to_radians().sin();
        assert!((angle - expect).abs() < 0.01, "{angle} vs {expect}");
    }
}
