//! What a track is given: measurements (a position, a velocity, a height,
//! or time differences too few for a fix), who made them, and what became
//! of each.

use nalgebra::{Matrix2, Vector2};

/// Who measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    Adsb = 0,
    Mlat = 1,
}

impl Source {
    pub fn name(self) -> &'static str {
        match self {
            Source::Adsb => "adsb",
            Source::Mlat => "mlat",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Observation {
    /// Horizontal position with its covariance (east/north, m^2), an
    /// optional height (m, variance) and the 1-sigma uncertainty of the
    /// measurement's time (s), which becomes along-track error.
    /// `surface`: an ADS-B surface position. `claimed`: the covariance is
    /// the source's own claim (NACp, an MLAT fix's), not a stand-in (an
    /// ADS-B position before its NACp is known).
    Position {
        lat: f64,
        lon: f64,
        cov_en: Matrix2<f64>,
        height: Option<(f64, f64)>,
        time_sigma_s: f64,
        surface: bool,
        claimed: bool,
    },
    /// Ground velocity (east, north m/s, covariance) and climb rate (m/s, variance).
    Velocity { v_en: Vector2<f64>, cov: Matrix2<f64>, climb: Option<(f64, f64)> },
    /// Height only (m, variance): a Mode S altitude reply.
    Height { h: f64, var: f64 },
    /// Climb rate only (m/s, variance): a Comm-B vertical rate (BDS 6,0).
    Climb { rate: f64, var: f64 },
    /// Times of arrival of one transmission at 2 or 3 synchronised sites, too
    /// few for a fix: ECEF position (m), time in a common clock (s), sigma (s).
    Tdoa { n: u8, sites: [([f64; 3], f64, f64); 3] },
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurement {
    /// Time of applicability (Unix s).
    pub t: f64,
    pub source: Source,
    pub obs: Observation,
}

/// What became of a measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// Applied; the NIS of a position (2 dof), else 0.
    Applied { nis: f64 },
    /// A position the track's gate rejected as an outlier.
    Gated,
    /// Older than the reorder window: not applied.
    TooLate,
    /// Nothing to apply it to yet (a velocity before any position).
    Early,
    /// The filter went numerically bad (or the data forced a restart): the
    /// track restarted on this measurement.
    Restarted,
}
