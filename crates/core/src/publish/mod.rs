//! Publish stage: events rendered for subscribers ([`json`]: the track
//! stream, [`asterix`]: CAT062, [`aircraft_json`]: readsb's aircraft.json
//! for map clients, [`beast`]: multilateration results as extended
//! squitters for readsb and dump1090, [`sbs`]: BaseStation text), all from
//! one [`readout`] of each track in those tools' units.

pub mod aircraft_json;
pub mod asterix;
pub mod beast;
pub mod json;
pub mod readout;
pub mod sbs;

/// A fused track to render in the publishers' tests (and the cluster
/// publisher's, through the `test-support` feature).
#[cfg(any(test, feature = "test-support"))]
pub mod test_report {
    use std::sync::Arc;

    use crate::fuse::{Sources, TrackReport};
    use crate::track::kf::Gaussian;
    pub use crate::track::measurement::Source;
    use crate::track::motion::Motion;
    use crate::track::plane::Plane;
    use crate::track::Estimate;

    /// Track 7 of `addr` at `t` from `sources`: at 43.5 N 1.25 E, 1000 m,
    /// north-east at 100 m/s and climbing 5 m/s, its velocity known to 1 m/s.
    pub fn report(addr: u32, t: f64, sources: &[Source]) -> TrackReport {
        TrackReport {
            id: 7,
            addr,
            source: crate::fuse::TrackSource::Fused,
            est: Estimate {
                t,
                lat: 43.5,
                lon: 1.25,
                alt_m: Some(1000.0),
                // North-east at 100 m/s, climbing 5 m/s.
                vel_enu: [100.0 / 2f64.sqrt(), 100.0 / 2f64.sqrt(), 5.0],
                cov_local: [[100.0, 0.0], [0.0, 25.0]],
                plane: Plane::new(43.5, 1.25, 0.0),
                state: Gaussian { x: Default::default(), p: nalgebra::Matrix6::identity() },
            },
            alt_baro_ft: Some(3200),
            sources: sources.iter().copied().collect::<Sources>(),
            nac_p: Some(9),
            period_s: 1.0,
            motion: Motion::Moving,
            adsb_suspect: false,
            flight: Some(Arc::from("AFR12")),
            squawk: Some(0x7001),
            nav_altitude_ft: None,
            sparse: false,
            ages_s: [None, None],
        }
    }

    /// A decoded ADS-B position of `addr` at `t`.
    pub fn position(addr: u32, t: f64, surface: bool) -> crate::core::PositionReport {
        crate::core::PositionReport {
            addr,
            t,
            lat: 43.5,
            lon: 1.25,
            alt_m: None,
            alt_baro_ft: None,
            alt_sigma_m: None,
            nac_p: None,
            sigma_m: None,
            dating: crate::core::Dating::Arrival,
            surface,
            rx: 0,
        }
    }
}
