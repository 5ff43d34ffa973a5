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
        /// The share of `cov_en` that is the same in the aircraft's next
        /// positions too (an MLAT fix's clock synchronisation error).
        persistent: SharedShare,
        /// The share of `cov_en` that repeats the aircraft's own ADS-B
        /// errors (an MLAT fix from clocks synchronised on its ADS-B
        /// positions), 0 to 1: news only to a track without that ADS-B.
        adsb_echo: f64,
    },
    /// Ground velocity (east, north m/s, covariance) and climb rate (m/s, variance).
    Velocity { v_en: Vector2<f64>, cov: Matrix2<f64>, climb: Option<(f64, f64)> },
    /// Height only (m, variance): a Mode S altitude reply.
    Height { h: f64, var: f64 },
    /// Climb rate only (m/s, variance): a Comm-B vertical rate (BDS 6,0).
    Climb { rate: f64, var: f64 },
    /// Times of arrival of one transmission at 2 or 3 synchronised sites, too
    /// few for a fix: ECEF position (m), time in a common clock (s), sigma (s)
    /// of the error each transmission has afresh; and each site's error that
    /// persists from one transmission to the next (see [`Persistent`]).
    Tdoa { n: u8, sites: [([f64; 3], f64, f64); 3], persistent: [Persistent; 3] },
}

/// A site's timing error shared by an aircraft's successive transmissions
/// (the error of its learnt offset): the same in every one a track takes,
/// it cannot be averaged away, and a track counts it as often as its own
/// memory holds transmissions (`track::tdoa`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Persistent {
    /// Its variance (s^2).
    pub var_s2: f64,
    /// The most transmissions it is shared by: those of the aircraft within
    /// the time it lasts (at least 1).
    pub shared_by: f64,
}

/// None: no error shared with any other transmission.
impl Default for Persistent {
    fn default() -> Self {
        Persistent { var_s2: 0.0, shared_by: 1.0 }
    }
}

impl Persistent {
    /// How many transmissions a filter's estimate effectively averages once it
    /// takes the next one: its prior's variance along the measured differences
    /// (`state`), against one transmission's independent noise (`fresh`) and
    /// its persistent error (`persistent`), each counted that many times.
    ///
    /// A filter that has averaged k transmissions, each with noise r + N p,
    /// has a prior of (r + N p) / k; it should count the persistent error as
    /// often as it will have averaged, N = k + 1. So N = 1 + (r + N p) / s,
    /// that is N = (1 + r / s) / (1 - p / s): k + 1 for a filter that forgets
    /// nothing, fewer for one whose process noise keeps its prior wide. A
    /// prior already as sure as the persistent error alone allows holds
    /// every transmission (the caller's bound).
    pub fn memory(state: f64, fresh: f64, persistent: f64) -> f64 {
        if !(state > persistent && state > 0.0) {
            return f64::INFINITY;
        }
        (1.0 + fresh / state) / (1.0 - persistent / state)
    }

    /// Its variance (s^2) counted as often as a filter remembering `memory`
    /// transmissions should, at most as often as it is shared.
    pub fn counted(&self, memory: f64) -> f64 {
        self.var_s2 * memory.min(self.shared_by).max(1.0)
    }
}

/// The share of a position's covariance that stays from one position of
/// the aircraft to the next: an MLAT fix's clock synchronisation error,
/// which a pair filter carries for as long as its updates take to replace
/// it. A track counts it as often as its memory holds positions, at most
/// as often as it is shared (`track::persistent`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SharedShare {
    /// Its share of the covariance, 0 to 1.
    pub share: f64,
    /// The most positions it is shared by (at least 1).
    pub shared_by: f64,
}

/// None: every error the position's own.
impl Default for SharedShare {
    fn default() -> Self {
        SharedShare { share: 0.0, shared_by: 1.0 }
    }
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

#[cfg(test)]
mod tests {
    use super::Persistent;

    /// A filter that forgets nothing, having averaged k transmissions each
    /// counted with its persistent error k + 1 times, remembers k + 1 once it
    /// takes the next; one whose prior is wider (process noise) fewer; one
    /// already as sure as the persistent error allows, all it was given.
    #[test]
    fn memory_is_the_fixed_point_of_what_the_filter_has_averaged() {
        let (fresh, persistent) = (900.0, 400.0);
        for k in [1.0, 5.0, 30.0] {
            let prior = (fresh + (k + 1.0) * persistent) / k;
            let n = Persistent::memory(prior, fresh, persistent);
            assert!((n - (k + 1.0)).abs() < 1e-9, "{k}: {n}");
            assert!(Persistent::memory(2.0 * prior, fresh, persistent) < n);
        }
        assert_eq!(Persistent::memory(persistent, fresh, persistent), f64::INFINITY);
        let p = Persistent { var_s2: 4.0, shared_by: 6.0 };
        assert_eq!(p.counted(f64::INFINITY), 24.0);
        assert_eq!(p.counted(2.5), 10.0);
        assert_eq!(p.counted(0.2), 4.0);
    }
}
