//! What the engine makes of a group: a fix, time differences for the
//! tracker, or why neither.

use crate::mlat::solver::Reject;

/// One multilateration fix.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MlatFix {
    pub addr: u32,
    /// Emission time (Unix s): exact when a GPS-timed receiver is in the
    /// group's tree, else from the first arrival.
    pub t: f64,
    pub lat: f64,
    pub lon: f64,
    pub alt_m: f64,
    pub cov_en: [[f64; 2]; 2],
    pub cov_ecef: [[f64; 3]; 3],
    pub receivers: smallvec::SmallVec<[usize; 8]>,
    pub gdop: f64,
    /// Residual chi-square per degree of freedom (0 when exactly determined).
    pub chi2: f64,
    pub dof: usize,
    pub altitude_used: bool,
    /// Share of the timing variance that came from clock synchronisation
    /// (0 for GPS-timed groups): errors that persist from fix to fix.
    pub sync_share: f64,
    /// The share of the clock synchronisation behind this fix that was
    /// learnt from this same aircraft's ADS-B positions: errors it shares
    /// with the aircraft's ADS-B track.
    pub self_sync_share: f64,
    pub df: u8,
}

/// A transmission heard by too few synchronised sites for a fix: what the
/// tracker can still use (time differences against its own estimate).
#[derive(Clone, Debug, PartialEq)]
pub struct TdoaGroup {
    pub addr: u32,
    /// Approximate time of emission (Unix s): the first arrival.
    pub t: f64,
    /// Each site: ECEF position (m), time of arrival in the common clock (s), sigma (s).
    pub sites: Vec<([f64; 3], f64, f64)>,
    /// Each site's share of that sigma that persists from one transmission
    /// to the next (the error of its learnt offset): its variance (s^2) and
    /// how long it lasts (s). The same error in every transmission a track
    /// takes, it cannot be averaged away (see `track::Persistent`).
    pub persistent: Vec<(f64, f64)>,
    /// Each site's clock synchronisation variance (s^2), part of its sigma:
    /// the pair filters' estimate's error, which changes only as their
    /// updates replace it, over many of the aircraft's transmissions.
    pub sync_var: Vec<f64>,
    /// Who heard it, with every receiver's coverage: the silence of the
    /// others places it too (`None` where nothing is known of coverage).
    pub unheard: Option<crate::mlat::coverage::Unheard>,
}

impl TdoaGroup {
    /// How many of `recent` transmissions over `span_s` share an error that
    /// lasts `lasts` s (at least this one).
    pub fn shared_by(recent: f64, lasts: f64, span_s: f64) -> f64 {
        (recent * lasts.min(span_s) / span_s).max(1.0)
    }
}

/// What multilateration made of one group.
#[derive(Clone, Debug, PartialEq)]
pub enum GroupOutcome {
    Fix(Box<MlatFix>),
    /// Too few synchronised sites for a fix, or to choose between a fix's
    /// two solutions, but enough for a track that knows where the aircraft
    /// is: the time differences, for the tracker.
    Tdoa(TdoaGroup),
    /// Nothing for the tracker, and why (each reason also counted in
    /// [`MlatStats`](super::MlatStats)).
    NoFix(NoFix),
}

/// Why a group gave no fix.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoFix {
    /// Undecoded, or fewer than two usable copies, or too few sites.
    TooFewReceivers,
    /// An ADS-B aircraft multilaterated less than `adsb_interval_s` ago.
    AdsbRecent,
    /// The solver's (or the choice of solution's) reason.
    Rejected(Reject),
    /// Exactly determined, from an address nothing has confirmed.
    UnverifiedAddress,
}

impl GroupOutcome {
    /// The fix, if the group gave one.
    pub fn fix(self) -> Option<MlatFix> {
        match self {
            GroupOutcome::Fix(f) => Some(*f),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The transmissions sharing a persistent error: those within the time
    /// it lasts, at least this one.
    #[test]
    fn a_persistent_error_is_shared_by_the_transmissions_it_lasts_over() {
        assert_eq!(TdoaGroup::shared_by(1.0, f64::INFINITY, 30.0), 1.0);
        // Sixty transmissions in the span, the error lasting beyond it: all share it.
        assert_eq!(TdoaGroup::shared_by(60.0, f64::INFINITY, 30.0), 60.0);
        // An error that lasts a tenth of the span is shared by a tenth of them.
        assert_eq!(TdoaGroup::shared_by(60.0, 3.0, 30.0), 6.0);
        // A brief one by this transmission alone.
        assert_eq!(TdoaGroup::shared_by(60.0, 0.0, 30.0), 1.0);
    }
}
