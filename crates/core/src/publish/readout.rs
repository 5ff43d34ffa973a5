//! A fused track in the units and conventions of the tools that read
//! ADS-B (feet, knots, degrees, ft/min), shared by every output that speaks
//! their language (`aircraft.json`, SBS, Beast), so that a speed or a track
//! published one way is published the same way everywhere.
//!
//! A velocity is only said once it is known: an aircraft's reported ground
//! speed is a measurement, and a track just started has only a guess.

use crate::fuse::TrackReport;
use crate::track::measurement::Source;

pub const M_TO_FT: f64 = 1.0 / 0.3048;
pub const MS_TO_KT: f64 = 3600.0 / 1852.0;
/// Ground speed is published once each velocity component is known to this
/// (1 sigma, m/s): a 95% error within 10 m/s, what NACv 1 promises.
pub const MAX_VEL_SIGMA_MS: f64 = 4.0;
/// The track angle is published once the speed is this many sigmas: a
/// direction is meaningless for an aircraft that may be standing still.
const TRACK_MIN_SIGMAS: f64 = 3.0;

/// What a fused track says, in ADS-B tools' units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Readout {
    /// Height above the WGS-84 ellipsoid (ft).
    pub alt_geom_ft: Option<i64>,
    /// East and north velocity (kt), once known (see [`Readout::gs_kt`]).
    pub vel_en_kt: Option<[f64; 2]>,
    /// True track over ground (degrees), once the speed is well above its error.
    pub track_deg: Option<f64>,
    /// Rate of the geometric height (ft/min), when the height is known.
    pub geom_rate_fpm: Option<i64>,
    /// 1 sigma of each velocity component (m/s).
    pub vel_sigma_ms: f64,
    /// ADS-B fed the track lately; otherwise multilateration alone did.
    pub adsb: bool,
}

impl Readout {
    /// Ground speed (kt), once known.
    pub fn gs_kt(&self) -> Option<f64> {
        self.vel_en_kt.map(|[e, n]| e.hypot(n))
    }
}

pub fn readout(r: &TrackReport) -> Readout {
    let est = &r.est;
    let [ve, vn, vu] = est.vel_enu;
    let p = &est.state.p;
    let vel_sigma = (0.5 * (p[(2, 2)] + p[(3, 3)])).max(0.0).sqrt();
    let speed = ve.hypot(vn);
    let known = vel_sigma <= MAX_VEL_SIGMA_MS;
    Readout {
        alt_geom_ft: est.alt_m.map(|a| (a * M_TO_FT).round() as i64),
        vel_en_kt: known.then_some([ve * MS_TO_KT, vn * MS_TO_KT]),
        track_deg: (known && speed > TRACK_MIN_SIGMAS * vel_sigma)
            .then(|| ve.atan2(vn).to_degrees().rem_euclid(360.0)),
        geom_rate_fpm: est.alt_m.map(|_| (vu * M_TO_FT * 60.0).round() as i64),
        vel_sigma_ms: vel_sigma,
        adsb: r.sources.contains(&Source::Adsb),
    }
}
