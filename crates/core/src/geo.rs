//! Geodesy: WGS-84 constants, geodetic <-> ECEF, and distances.
//!
//! Plausibility checks only need a great-circle distance on the mean sphere
//! (a 0.5% error is irrelevant against a speed limit); geometry that feeds
//! multilateration uses ECEF on the ellipsoid.

pub const WGS84_A: f64 = 6_378_137.0;
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);
pub const EARTH_MEAN_RADIUS_M: f64 = 6_371_008.8;
pub const KT_TO_MS: f64 = 1852.0 / 3600.0;
pub const FT_TO_M: f64 = 0.3048;

/// Meridian and prime-vertical radii of curvature (m) at a latitude (rad).
pub fn radii(lat_rad: f64) -> (f64, f64) {
    let w = (1.0 - WGS84_E2 * lat_rad.sin().powi(2)).sqrt();
    (WGS84_A * (1.0 - WGS84_E2) / (w * w * w), WGS84_A / w)
}

/// A point moved by a small east/north/up offset (m): the local radii at the
/// start, accurate to millimetres over kilometres.
pub fn displace(lat: f64, lon: f64, h: f64, enu: [f64; 3]) -> (f64, f64, f64) {
    let p = lat.to_radians();
    let (m, n) = radii(p);
    (lat + (enu[1] / (m + h)).to_degrees(), lon + (enu[0] / ((n + h) * p.cos())).to_degrees(), h + enu[2])
}

/// Straight-line distance between two ECEF points (m).
#[inline]
pub fn ecef_distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Great-circle distance (m) on the mean sphere.
pub fn distance_m(lat1: f64, lon1: f64, lat2: f64, lon2: f64) -> f64 {
    let (p1, p2) = (lat1.to_radians(), lat2.to_radians());
    let dp = p2 - p1;
    let dl = (lon2 - lon1).to_radians();
    let a = (dp / 2.0).sin().powi(2) + p1.cos() * p2.cos() * (dl / 2.0).sin().powi(2);
    2.0 * EARTH_MEAN_RADIUS_M * a.sqrt().min(1.0).asin()
}

/// Geodetic (deg, deg, m above the ellipsoid) to ECEF (m).
pub fn geodetic_to_ecef(lat: f64, lon: f64, h: f64) -> [f64; 3] {
    let (sp, cp) = lat.to_radians().sin_cos();
    let (sl, cl) = lon.to_radians().sin_cos();
    ecef_from_sin_cos([sp, cp, sl, cl], h)
}

/// ECEF (m) of a height above the ellipsoid where latitude and longitude
/// are given by their sines and cosines `[sin lat, cos lat, sin lon, cos lon]`
/// (as [`ecef_height_fast`] returns them): no trigonometry.
pub fn ecef_from_sin_cos([sp, cp, sl, cl]: [f64; 4], h: f64) -> [f64; 3] {
    let n = WGS84_A / (1.0 - WGS84_E2 * sp * sp).sqrt();
    [(n + h) * cp * cl, (n + h) * cp * sl, (n * (1.0 - WGS84_E2) + h) * sp]
}

/// Sine and cosine of the angle of the direction `(u, v)` (`v` along the
/// angle's zero); the zero angle for the zero vector.
#[inline]
fn unit(u: f64, v: f64) -> (f64, f64) {
    let k = (u * u + v * v).sqrt();
    if k > 0.0 {
        (u / k, v / k)
    } else {
        (0.0, 1.0)
    }
}

/// ECEF (m) to geodetic (deg, deg, m), by Bowring's method with two refinements
/// (sub-millimetre for anything between the Earth's centre region and orbit).
/// The latitude is carried through the iterations as a direction (its sine
/// and cosine up to a common factor), so they need square roots only: the
/// angles' tangent, arctangent and sine/cosine were most of the cost of
/// publishing a track and of starting a multilateration solve.
pub fn ecef_to_geodetic(p: [f64; 3]) -> (f64, f64, f64) {
    let [x, y, z] = p;
    let lon = y.atan2(x);
    let r = x.hypot(y);
    let b = WGS84_A * (1.0 - WGS84_F);
    let ep2 = (WGS84_A * WGS84_A - b * b) / (b * b);
    let (mut num, mut den) = (z * WGS84_A, r * b);
    for _ in 0..3 {
        // Parametric latitude: tan(beta) = (1 - f) tan(lat), |beta| <= 90 deg.
        let (u, v) = if den < 0.0 { (-(1.0 - WGS84_F) * num, -den) } else { ((1.0 - WGS84_F) * num, den) };
        let (sb, cb) = unit(u, v);
        num = z + ep2 * b * sb * sb * sb;
        den = r - WGS84_E2 * WGS84_A * cb * cb * cb;
    }
    let lat = num.atan2(den);
    let (sp, cp) = unit(num, den);
    let n = WGS84_A / (1.0 - WGS84_E2 * sp * sp).sqrt();
    let h = if cp.abs() > 1e-10 { r / cp - n } else { z.abs() - b };
    (lat.to_degrees(), lon.to_degrees(), h)
}

/// ECEF to geodetic height and the sines/cosines of latitude and longitude,
/// by one Bowring iteration: sub-millimetre for heights within 100 km of the
/// ellipsoid, and a third of the cost of [`ecef_to_geodetic`]. For hot loops
/// (the MLAT solver's altitude constraint) that need height and the local up
/// direction.
#[inline]
pub fn ecef_height_fast(p: [f64; 3]) -> (f64, [f64; 4]) {
    // Plain square roots: `hypot`'s overflow care costs more than the whole
    // conversion and Earth-sized numbers cannot overflow.
    let [x, y, z] = p;
    let r = (x * x + y * y).sqrt();
    let b = WGS84_A * (1.0 - WGS84_F);
    let ep2 = (WGS84_A * WGS84_A - b * b) / (b * b);
    // Parametric latitude, then one Bowring step.
    let (sb, cb) = {
        let t = (z * WGS84_A, r * b);
        let n = (t.0 * t.0 + t.1 * t.1).sqrt();
        (t.0 / n, t.1 / n)
    };
    let num = z + ep2 * b * sb * sb * sb;
    let den = r - WGS84_E2 * WGS84_A * cb * cb * cb;
    let nn = (num * num + den * den).sqrt();
    let (sp, cp) = (num / nn, den / nn);
    let (sl, cl) = if r > 0.0 { (y / r, x / r) } else { (0.0, 1.0) };
    let n = WGS84_A / (1.0 - WGS84_E2 * sp * sp).sqrt();
    let h = if cp.abs() > 1e-10 { r / cp - n } else { z.abs() - b };
    (h, [sp, cp, sl, cl])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ecef_round_trip() {
        for &(lat, lon, h) in &[
            (0.0, 0.0, 0.0),
            (43.629, 1.3638, 152.0),
            (-89.9, 120.0, 11000.0),
            (59.7, 30.6, 10668.0),
            (90.0, 0.0, 0.0),
            (-90.0, 45.0, 1000.0),
            (0.0, -179.0, -400.0),
            (30.0, -170.0, 400_000.0),
            (-45.0, 10.0, 20_200_000.0),
        ] {
            let (la, lo, hh) = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h));
            assert!(
                (la - lat).abs() < 1e-9 && (lo - lon).abs() < 1e-9 && (hh - h).abs() < 1e-4,
                "{lat} {lon} {h}"
            );
        }
    }

    #[test]
    fn fast_height_agrees_below_100_km() {
        for &(lat, lon, h) in
            &[(0.0, 0.0, 0.0), (43.6, 1.4, 3000.0), (-70.0, 120.0, 12_000.0), (60.0, -30.0, 95_000.0)]
        {
            let (hf, [sp, cp, sl, cl]) = ecef_height_fast(geodetic_to_ecef(lat, lon, h));
            assert!((hf - h).abs() < 1e-3, "{lat} {h}: {hf}");
            assert!((sp - lat.to_radians().sin()).abs() < 1e-9 && (cp - lat.to_radians().cos()).abs() < 1e-9);
            assert!(
                (sl - lon.to_radians().sin()).abs() < 1e-12 && (cl - lon.to_radians().cos()).abs() < 1e-12
            );
        }
    }

    #[test]
    fn one_degree_of_latitude() {
        let d = distance_m(0.0, 0.0, 1.0, 0.0);
        assert!((d - 111_195.0).abs() < 10.0, "{d}");
    }
}
