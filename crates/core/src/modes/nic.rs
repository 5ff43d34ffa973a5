//! Integrity and accuracy categories: NIC from type code and supplements
//! (DO-260/A/B, versions 0-2), NUCp for version 0, and the NACp -> EPU table
//! that turns a reported category into a position error we can filter with:
//! NACp, NUCp and NACv to the sigmas the tracker uses, in one place.

use crate::geo::FT_TO_M;

/// NIC of an airborne (TC 9-18, 20-22) or surface (TC 5-8) position.
///
/// `nic_a` comes from operational status (version 1's single supplement
/// counts as A), `nic_b` from the airborne position's own bit, `nic_c` from
/// surface operational status. Version 0 has no supplements: they read as 0.
pub fn nic(tc: u8, version: u8, nic_a: u8, nic_b: u8, nic_c: u8) -> Option<u8> {
    let (a, b, c) = match version {
        0 => (0, 0, 0),
        // Version 1 has one supplement; its meaning matches A=B=supplement.
        1 => (nic_a, nic_a, 0),
        _ => (nic_a, nic_b, nic_c),
    };
    Some(match tc {
        5 => 11,
        6 => 10,
        7 => {
            if a == 1 {
                9
            } else {
                8
            }
        }
        8 => match (a, c) {
            (1, 1) => 7,
            (1, 0) | (0, 1) => 6,
            _ => 0,
        },
        9 | 20 => 11,
        10 | 21 => 10,
        11 => {
            if a == 1 && b == 1 {
                9
            } else {
                8
            }
        }
        12 => 7,
        13 => 6,
        14 => 5,
        15 => 4,
        16 => {
            if a == 1 && b == 1 {
                3
            } else {
                2
            }
        }
        17 => 1,
        18 | 22 => 0,
        _ => return None,
    })
}

/// NUCp of a version 0 position (DO-260 table).
pub fn nuc_p(tc: u8) -> Option<u8> {
    Some(match tc {
        5 | 9 | 20 => 9,
        6 | 10 | 21 => 8,
        7 | 11 => 7,
        8 | 12 => 6,
        13 => 5,
        14 => 4,
        15 => 3,
        16 => 2,
        17 => 1,
        18 | 22 => 0,
        _ => return None,
    })
}

const NM: f64 = 1852.0;

/// A 95% horizontal radius over the per-axis sigma of the circular Gaussian
/// it bounds (sqrt(-2 ln 0.05)): NACp's EPU and NACv's bound to sigmas.
pub const R95_PER_SIGMA: f64 = 2.448;

/// NACv's 95% bounds: horizontal velocity (m/s) and vertical rate (ft/s);
/// `None` for 0 (unknown) and out-of-range values.
pub fn nacv_bounds(nac_v: u8) -> Option<(f64, f64)> {
    Some(match nac_v {
        1 => (10.0, 50.0),
        2 => (3.0, 15.0),
        3 => (1.0, 5.0),
        4 => (0.3, 1.5),
        _ => return None,
    })
}

/// The per-axis 1-sigma horizontal position error (m) a report claims:
/// its NACp's EPU over [`R95_PER_SIGMA`]; from a version 0 transponder,
/// which reports NUCp, half the protection limit (about its 95% accuracy
/// bound) instead. `None` when neither says anything. Every consumer of a
/// report's accuracy (the tracker, the published records) takes it from here.
pub fn position_sigma_m(nac_p: Option<u8>, nuc_p: Option<u8>) -> Option<f64> {
    let epu = match nac_p.filter(|&n| n > 0) {
        Some(n) => nacp_epu_m(n),
        None => nuc_p.and_then(nucp_hpl_m).map(|h| h / 2.0),
    };
    epu.map(|e| e / R95_PER_SIGMA)
}

/// NACv's bounds as 1-sigma errors (m/s): horizontal velocity per axis (its
/// bound a 2-D 95% radius) and vertical rate (a 1-D 95% bound). A NACv of
/// 0 (unknown) or out of range takes the `unknown` bounds (m/s, ft/s).
pub fn velocity_sigmas_ms(nac_v: u8, unknown: (f64, f64)) -> (f64, f64) {
    let (h95, v95_fps) = nacv_bounds(nac_v).unwrap_or(unknown);
    (h95 / R95_PER_SIGMA, v95_fps * FT_TO_M / 1.96)
}

/// Estimated position uncertainty (95% horizontal radius, metres) of a NACp;
/// `None` for 0 (unknown) and out-of-range values.
pub fn nacp_epu_m(nac_p: u8) -> Option<f64> {
    Some(match nac_p {
        1 => 10.0 * NM,
        2 => 4.0 * NM,
        3 => 2.0 * NM,
        4 => 1.0 * NM,
        5 => 0.5 * NM,
        6 => 0.3 * NM,
        7 => 0.1 * NM,
        8 => 0.05 * NM,
        9 => 30.0,
        10 => 10.0,
        11 => 3.0,
        _ => return None,
    })
}

/// Horizontal protection limit of a NUCp (metres), which DO-260 pairs with a
/// 95% accuracy bound of about half of it; used for version 0 transponders.
pub fn nucp_hpl_m(nuc_p: u8) -> Option<f64> {
    Some(match nuc_p {
        9 => 7.5,
        8 => 25.0,
        7 => 0.1 * NM,
        6 => 0.2 * NM,
        5 => 0.5 * NM,
        4 => 1.0 * NM,
        3 => 2.0 * NM,
        2 => 10.0 * NM,
        1 => 20.0 * NM,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn supplements_matter_only_where_the_tables_say() {
        assert_eq!(nic(11, 2, 1, 1, 0), Some(9));
        assert_eq!(nic(11, 2, 1, 0, 0), Some(8));
        assert_eq!(nic(11, 1, 1, 0, 0), Some(9));
        assert_eq!(nic(11, 0, 1, 1, 0), Some(8));
        assert_eq!(nic(16, 2, 1, 1, 0), Some(3));
        assert_eq!(nic(12, 0, 0, 0, 0), Some(7));
        assert_eq!(nic(8, 2, 1, 0, 0), Some(6));
        assert_eq!(nic(8, 2, 1, 0, 1), Some(7));
        assert_eq!(nic(19, 2, 0, 0, 0), None);
        assert_eq!(nuc_p(11), Some(7));
        assert_eq!(nacp_epu_m(9), Some(30.0));
        assert_eq!(nacp_epu_m(0), None);
        // DO-260B: NACv 2 is 3 m/s horizontal and 15 ft/s vertical (95%).
        assert_eq!(nacv_bounds(2), Some((3.0, 15.0)));
        assert_eq!((nacv_bounds(0), nacv_bounds(5)), (None, None));
    }

    #[test]
    fn categories_become_sigmas_a_95_percent_bound_being_about_two_of_them() {
        // NACp 9: EPU 30 m, a 2-D 95% radius, so 12.25 m per axis.
        let s = position_sigma_m(Some(9), None).unwrap();
        assert!((s - 12.25).abs() < 0.01, "{s}");
        // Version 0: half NUCp 7's 0.1 NM protection limit as the 95% bound.
        let s0 = position_sigma_m(None, Some(7)).unwrap();
        assert!((s0 - 0.05 * 1852.0 / 2.448).abs() < 1e-9, "{s0}");
        assert_eq!(position_sigma_m(Some(0), None), None);
        // NACv 2: 3 m/s horizontal (2-D) and 15 ft/s vertical (1-D) at 95%.
        let (h, v) = velocity_sigmas_ms(2, (30.0, 100.0));
        assert!((h - 3.0 / 2.448).abs() < 1e-12 && (v - 15.0 * 0.3048 / 1.96).abs() < 1e-12, "{h} {v}");
        assert_eq!(velocity_sigmas_ms(0, (30.0, 100.0)).0, 30.0 / 2.448);
    }
}
