//! One aircraft of the fuser's table: its tracks (fused and single-source),
//! what waits for the MLAT hold, its identity and reported state, its
//! particle filter while it has no position, and what the conflict and
//! motion tests keep of it. Apart from the fuser that drives it, so that
//! the table's entry and how one starts read in one place.

use std::sync::Arc;

use super::hold::Waiting;
use super::methods::{Cross, Method};
use crate::recent::RecentCount;
use crate::track::imm::ImmSpec;
use crate::track::motion::{Motion, MotionTest};
use crate::track::particle::SparseTrack;
use crate::track::plane::Plane;
use crate::track::{Estimate, Track, TrackConfig};

/// An aircraft's tracks as they start: the fused one and the single-source
/// ones (which keep each update's gain for the information method), on the
/// MLAT-only models until its ADS-B is heard.
pub(super) fn fresh_tracks(
    tcfg: &Arc<TrackConfig>,
    spec: &Arc<ImmSpec>,
    method: Method,
) -> (Track, [Track; 2]) {
    let fused = Track::new(tcfg.clone(), spec.clone());
    let mut single = fused.clone();
    single.keep_gain = method == Method::Information;
    (fused, [single.clone(), single])
}

/// Estimates taken at the publication time (fused; ADS-B, MLAT).
#[derive(Default)]
pub(super) struct Taken {
    pub(super) fused: Option<Estimate>,
    pub(super) single: [Option<Estimate>; 2],
}

/// An entry of the fuser's table.
pub(super) struct Aircraft {
    pub(super) id: u64,
    pub(super) fused: Track,
    pub(super) single: [Track; 2],
    /// Data time of the newest measurement from each source.
    pub(super) last_source_t: [f64; 2],
    /// Arrival time the aircraft was last heard.
    pub(super) last_heard: f64,
    pub(super) next_due: f64,
    /// Time of applicability waiting to be published.
    pub(super) pending: Option<f64>,
    /// The tracks' estimates at `pending`, taken when they stood there
    /// (see [`super::Fuser::apply`]).
    pub(super) taken: Taken,
    /// Measurements waiting for the MLAT hold.
    pub(super) waiting: Waiting,
    pub(super) nac_p: Option<u8>,
    pub(super) alt_baro_ft: Option<i32>,
    pub(super) flight: Option<Arc<str>>,
    pub(super) squawk: Option<u16>,
    pub(super) nav_altitude_ft: Option<u32>,
    /// Its latest height (WGS-84 m) from an altitude reply, and when.
    pub(super) height: Option<(f64, f64)>,
    /// The particle filter while it has no position, and its next publication.
    pub(super) sparse: Option<Box<SparseTrack>>,
    pub(super) sparse_due: f64,
    /// When its groups first came too small for a fix while it had no position.
    pub(super) sparse_since: Option<f64>,
    /// The cloud's estimates in a row that had one mode and were tight
    /// enough to publish: at `sparse.handover_after` the tracks start from it.
    pub(super) sparse_publishable: u32,
    /// Its tracks started from a particle cloud and have had no fix since:
    /// published flagged `sparse`, and given back to a new cloud if the time
    /// differences keep missing them.
    pub(super) sparse_geometry: bool,
    pub(super) sparse_gated: u32,
    /// Its transmissions taken as time differences, faded over [`super::TDOA_SPAN_S`].
    pub(super) tdoa_recent: RecentCount,
    /// Its fixes whose clock synchronisation error persists, faded likewise.
    pub(super) fix_recent: RecentCount,
    pub(super) motion: MotionTest,
    pub(super) motion_plane: Option<Plane>,
    pub(super) motion_state: Motion,
    pub(super) motion_t: f64,
    pub(super) in_conflict: bool,
    /// An ADS-B measurement has been taken: the tracks use `Fuser::spec`.
    pub(super) adsb_heard: bool,
    pub(super) adsb_suspect: bool,
    pub(super) surface: bool,
    pub(super) cross: Cross,
}

impl Aircraft {
    /// A new aircraft, first heard at `now`, with its fresh `tracks`.
    pub(super) fn new(id: u64, tracks: (Track, [Track; 2]), now: f64, motion: MotionTest) -> Aircraft {
        let (fused, single) = tracks;
        Aircraft {
            id,
            fused,
            single,
            last_source_t: [f64::NEG_INFINITY; 2],
            last_heard: now,
            next_due: f64::NEG_INFINITY,
            pending: None,
            taken: Taken::default(),
            waiting: Waiting::default(),
            nac_p: None,
            alt_baro_ft: None,
            flight: None,
            squawk: None,
            nav_altitude_ft: None,
            height: None,
            sparse: None,
            sparse_due: f64::NEG_INFINITY,
            sparse_since: None,
            sparse_publishable: 0,
            sparse_geometry: false,
            sparse_gated: 0,
            tdoa_recent: RecentCount::default(),
            fix_recent: RecentCount::default(),
            motion,
            motion_plane: None,
            motion_state: Motion::Unknown,
            motion_t: f64::NEG_INFINITY,
            in_conflict: false,
            adsb_heard: false,
            adsb_suspect: false,
            surface: false,
            cross: Cross::new(),
        }
    }
}
