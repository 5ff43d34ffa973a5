//! Compact Position Reporting: the arithmetic only (no state, no policy).
//!
//! Latitude and longitude travel as 17-bit fractions of a zone. A global
//! decode needs one even and one odd frame; a local decode needs a reference
//! within half a zone. Surface frames use zones a quarter the size, so their
//! global decode is ambiguous by 90 degrees and needs a reference too.
//! Encoding lives here as well so the simulator and the tests share one
//! definition with the decoder.

const NB: f64 = 131_072.0; // 2^17
const NZ: f64 = 15.0;

/// Latitudes at which NL drops by one, from NL=59 at the equator to NL=1 past 87°.
const NL_TRANSITIONS: [f64; 58] = [
    10.470471299968,
    14.828174368687,
    18.186263570713,
    21.029394926028,
    23.545044865571,
    25.829247070588,
    27.938987101219,
    29.911356857318,
    31.772097076811,
    33.539934362985,
    35.228995977964,
    36.850251075935,
    38.412418924123,
    39.922566843339,
    41.386518322602,
    42.809140122436,
    44.194549514193,
    45.546267226602,
    46.867332524987,
    48.160391280966,
    49.427764392557,
    50.671501655538,
    51.893424691688,
    53.095161527960,
    54.278174722729,
    55.443784444950,
    56.593187562059,
    57.727473538661,
    58.847637761485,
    59.954592766940,
    61.049177742464,
    62.132166592103,
    63.204274793819,
    64.266165225674,
    65.318453096821,
    66.361710083826,
    67.396467740847,
    68.423220220833,
    69.442426311440,
    70.454510749876,
    71.459864730290,
    72.458845447289,
    73.451774416679,
    74.438934157251,
    75.420562566534,
    76.396843907945,
    77.367894613282,
    78.333740829227,
    79.294282254569,
    80.249232132805,
    81.198013492719,
    82.139569805106,
    83.071994447198,
    83.991735629806,
    84.891661907021,
    85.755416209444,
    86.535369975121,
    87.000000000000,
];

/// Number of longitude zones at a latitude.
pub fn nl(lat: f64) -> u32 {
    let a = lat.abs();
    59 - NL_TRANSITIONS.partition_point(|&t| t < a) as u32
}

#[inline]
fn modp(x: f64, y: f64) -> f64 {
    x - y * (x / y).floor()
}

fn norm_lon(mut lon: f64) -> f64 {
    lon = modp(lon + 180.0, 360.0) - 180.0;
    lon
}

/// One frame's CPR fields.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CprFields {
    pub odd: bool,
    pub lat: u32,
    pub lon: u32,
}

/// Global airborne decode; the position returned is that of the `odd` frame
/// when `latest_odd`, else of the even frame. `None` when the two frames
/// straddle a longitude-zone boundary (they disagree on NL).
pub fn global_airborne(even: CprFields, odd: CprFields, latest_odd: bool) -> Option<(f64, f64)> {
    let (rlat0, rlat1) = global_lats(even, odd, 360.0)?;
    let rlat0 = if rlat0 >= 270.0 { rlat0 - 360.0 } else { rlat0 };
    let rlat1 = if rlat1 >= 270.0 { rlat1 - 360.0 } else { rlat1 };
    if rlat0.abs() > 90.0 || rlat1.abs() > 90.0 || nl(rlat0) != nl(rlat1) {
        return None;
    }
    let lat = if latest_odd { rlat1 } else { rlat0 };
    let lon = global_lon(even, odd, latest_odd, lat, 360.0);
    Some((lat, norm_lon(lon)))
}

/// Global surface decode: of the four candidate positions, the one nearest
/// the reference (the receiver, or the aircraft's last position).
pub fn global_surface(
    even: CprFields,
    odd: CprFields,
    latest_odd: bool,
    ref_lat: f64,
    ref_lon: f64,
) -> Option<(f64, f64)> {
    let (rlat0, rlat1) = global_lats(even, odd, 90.0)?;
    // Each latitude has a northern and a southern solution, 90 degrees apart.
    let pick = |r: f64| if (r - 90.0 - ref_lat).abs() < (r - ref_lat).abs() { r - 90.0 } else { r };
    let (rlat0, rlat1) = (pick(rlat0), pick(rlat1));
    if nl(rlat0) != nl(rlat1) {
        return None;
    }
    let lat = if latest_odd { rlat1 } else { rlat0 };
    let lon = global_lon(even, odd, latest_odd, lat, 90.0);
    // Longitude is known modulo 90 degrees: take the candidate nearest the reference.
    let k = ((ref_lon - lon) / 90.0).round();
    Some((lat, norm_lon(lon + 90.0 * k)))
}

fn global_lats(even: CprFields, odd: CprFields, span: f64) -> Option<(f64, f64)> {
    let lat0 = even.lat as f64 / NB;
    let lat1 = odd.lat as f64 / NB;
    let j = (59.0 * lat0 - 60.0 * lat1 + 0.5).floor();
    let rlat0 = span / 60.0 * (modp(j, 60.0) + lat0);
    let rlat1 = span / 59.0 * (modp(j, 59.0) + lat1);
    (rlat0.is_finite() && rlat1.is_finite()).then_some((rlat0, rlat1))
}

fn global_lon(even: CprFields, odd: CprFields, latest_odd: bool, lat: f64, span: f64) -> f64 {
    let nl = nl(lat) as f64;
    let lon0 = even.lon as f64 / NB;
    let lon1 = odd.lon as f64 / NB;
    let m = (lon0 * (nl - 1.0) - lon1 * nl + 0.5).floor();
    let i = if latest_odd { 1.0 } else { 0.0 };
    let ni = (nl - i).max(1.0);
    let frac = if latest_odd { lon1 } else { lon0 };
    span / ni * (modp(m, ni) + frac)
}

/// Local decode against a reference within half a zone (about 180 NM airborne,
/// 45 NM on the surface).
pub fn local(cpr: CprFields, surface: bool, ref_lat: f64, ref_lon: f64) -> (f64, f64) {
    let span = if surface { 90.0 } else { 360.0 };
    let i = if cpr.odd { 1.0 } else { 0.0 };
    let dlat = span / (60.0 - i);
    let yz = cpr.lat as f64 / NB;
    let j = (ref_lat / dlat).floor() + (0.5 + modp(ref_lat, dlat) / dlat - yz).floor();
    let lat = dlat * (j + yz);
    let ni = (nl(lat) as f64 - i).max(1.0);
    let dlon = span / ni;
    let xz = cpr.lon as f64 / NB;
    let m = (ref_lon / dlon).floor() + (0.5 + modp(ref_lon, dlon) / dlon - xz).floor();
    (lat, norm_lon(dlon * (m + xz)))
}

/// Encodes a position (17-bit airborne, or the surface form with its finer zones).
pub fn encode(lat: f64, lon: f64, odd: bool, surface: bool) -> CprFields {
    let span = if surface { 90.0 } else { 360.0 };
    let i = if odd { 1.0 } else { 0.0 };
    let dlat = span / (4.0 * NZ - i);
    let yz = (NB * modp(lat, dlat) / dlat + 0.5).floor();
    let rlat = dlat * (yz / NB + (lat / dlat).floor());
    let ni = (nl(rlat) as f64 - i).max(1.0);
    let dlon = span / ni;
    let xz = (NB * modp(lon, dlon) / dlon + 0.5).floor();
    CprFields { odd, lat: (yz as u32) & 0x1FFFF, lon: (xz as u32) & 0x1FFFF }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nl_table_matches_the_closed_form() {
        for k in 0..8900 {
            let lat = k as f64 / 100.0;
            let closed = if lat >= 87.0 {
                if lat == 87.0 {
                    2
                } else {
                    1
                }
            } else {
                let a =
                    1.0 - (1.0 - (std::f64::consts::PI / (2.0 * NZ)).cos()) / lat.to_radians().cos().powi(2);
                (2.0 * std::f64::consts::PI / a.acos()).floor() as u32
            };
            assert_eq!(nl(lat), closed, "lat {lat}");
            assert_eq!(nl(-lat), closed);
        }
    }

    #[test]
    fn published_airborne_pair() {
        // The worked example most decoders are checked against (KLM, 2009):
        // 8D40621D58C382D690C8AC2863A7 (even) and 8D40621D58C386435CC412692AD6 (odd).
        let even = CprFields { odd: false, lat: 93000, lon: 51372 };
        let odd = CprFields { odd: true, lat: 74158, lon: 50194 };
        let (lat, lon) = global_airborne(even, odd, false).unwrap();
        assert!((lat - 52.2572021484375).abs() < 1e-9, "{lat}");
        assert!((lon - 3.91937255859375).abs() < 1e-9, "{lon}");
        let (llat, llon) = local(even, false, 52.258, 3.918);
        assert!((llat - lat).abs() < 1e-9 && (llon - lon).abs() < 1e-9);
    }

    #[test]
    fn encode_decode_round_trip_everywhere() {
        for &(lat, lon) in &[
            (52.2572, 3.9194),
            (-33.9, 151.2),
            (0.001, -179.999),
            (71.3, -156.8),
            (-54.8, -68.3),
            (43.629, 1.3638),
            (86.9, 10.0),
        ] {
            for surface in [false, true] {
                let e = encode(lat, lon, false, surface);
                let o = encode(lat, lon, true, surface);
                let tol = if surface { 1.5e-5 } else { 6e-5 };
                for latest_odd in [false, true] {
                    let (dlat, dlon) = if surface {
                        global_surface(e, o, latest_odd, lat + 0.3, lon - 0.3).unwrap()
                    } else {
                        global_airborne(e, o, latest_odd).unwrap()
                    };
                    assert!((dlat - lat).abs() < tol, "{lat},{lon} {surface} -> {dlat}");
                    // Half a quantisation step of the coarser (odd) longitude zone.
                    let span = if surface { 90.0 } else { 360.0 };
                    let lon_tol = span / (nl(lat) as f64 - 1.0).max(1.0) / NB / 2.0 + 1e-9;
                    assert!(
                        ((dlon - lon + 540.0) % 360.0 - 180.0).abs() < lon_tol,
                        "{lat},{lon} {surface} -> {dlon}"
                    );
                    let f = if latest_odd { o } else { e };
                    let (llat, llon) = local(f, surface, lat - 0.2, lon + 0.2);
                    assert!((llat - dlat).abs() < 1e-9 && (llon - dlon).abs() < 1e-9);
                }
            }
        }
    }

    #[test]
    fn zone_straddle_is_rejected() {
        // Even and odd taken on either side of the NL 36/35 boundary.
        let e = encode(NL_TRANSITIONS[23] - 0.01, 20.0, false, false);
        let o = encode(NL_TRANSITIONS[23] + 0.01, 20.0, true, false);
        assert!(global_airborne(e, o, true).is_none());
    }
}
