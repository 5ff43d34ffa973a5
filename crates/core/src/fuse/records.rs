//! What the fusion stage hands out: published track states and alerts,
//! and its counters.

use std::sync::Arc;

use crate::track::measurement::Source;
use crate::track::motion::Motion;
use crate::track::Estimate;

/// What the fusion stage emits.
#[derive(Clone, Debug, PartialEq)]
pub enum Output {
    Track(Box<TrackReport>),
    Alert(Alert),
}

/// A change worth telling subscribers (contract `type: "alert"`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Alert {
    /// The timing contradicts (or again confirms) an aircraft's ADS-B positions.
    AdsbSuspect { t: f64, addr: u32, id: u64, suspect: bool, offset_m: Option<f64>, nis: f64 },
    /// A predicted conflict starts (or ends) between two tracks.
    Conflict { t: f64, pair: [(u32, u64); 2], active: bool, tau_s: f64, t_cpa_s: f64, miss_m: f64, dz_m: f64 },
}

/// The sources that fed a track lately; inline (a heap list per published
/// track was measurable).
pub type Sources = smallvec::SmallVec<[Source; 2]>;

/// Which track a report is of: the fused one, or one source's alone
/// (`--source-tracks`). The track stream's `source`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum TrackSource {
    Fused,
    Adsb,
    Mlat,
}

impl TrackSource {
    pub fn name(self) -> &'static str {
        match self {
            TrackSource::Fused => "fused",
            TrackSource::Adsb => "adsb",
            TrackSource::Mlat => "mlat",
        }
    }
}

impl From<Source> for TrackSource {
    fn from(s: Source) -> Self {
        match s {
            Source::Adsb => TrackSource::Adsb,
            Source::Mlat => TrackSource::Mlat,
        }
    }
}

/// A published track state (contract `type: "track"`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrackReport {
    pub id: u64,
    pub addr: u32,
    pub source: TrackSource,
    pub est: Estimate,
    pub alt_baro_ft: Option<i32>,
    pub sources: Sources,
    pub nac_p: Option<u8>,
    pub period_s: f64,
    pub motion: Motion,
    pub adsb_suspect: bool,
    /// Shared with the aircraft: a copy per publication was an allocation.
    pub flight: Option<Arc<str>>,
    pub squawk: Option<u16>,
    /// The altitude selected on the autopilot (Comm-B 4,0), ft.
    pub nav_altitude_ft: Option<u32>,
    /// A particle filter's estimate of an aircraft heard by too few receivers for a fix.
    pub sparse: bool,
    /// Age (s) of the newest ADS-B and MLAT measurement, when recent.
    pub ages_s: [Option<f64>; 2],
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FuseStats {
    pub measurements: u64,
    pub rejected_non_finite: u64,
    pub rejected_speed: u64,
    pub rejected_time: u64,
    pub too_late: u64,
    /// Measurements older than one the fused track already had, put in
    /// their place by re-running the newer ones (the MLAT hold keeps these rare).
    pub reruns: u64,
    pub gated: u64,
    pub restarts: u64,
    pub table_full: u64,
    pub tracks_created: u64,
    pub tracks_dropped: u64,
    pub published: u64,
    /// Publications due whose estimate was beyond `publish_sigma_m`: withheld.
    pub withheld_spread: u64,
    /// Fusion of two tracks impossible (a covariance not positive definite,
    /// or one track's newest position older than the coasting limit): the
    /// better single track published, once per publication.
    pub fusion_fallbacks: u64,
    /// Conformance flags raised (the monitor itself runs in the core's
    /// front stage, which also keeps flagged ADS-B out of clock sync).
    pub suspect_flags: u64,
    /// ADS-B measurements of flagged aircraft kept out of their fused track.
    pub suspect_excluded: u64,
    /// Groups too small for a fix given to tracks as time differences.
    pub tdoa: u64,
    pub conflicts: u64,
    pub sparse: SparseStats,
}

/// The particle filters of aircraft heard by too few receivers for a fix.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SparseStats {
    pub started: u64,
    pub updates: u64,
    /// Clouds that no particle of which explained a measurement: started again.
    pub restarts: u64,
    pub resamples: u64,
    /// Groups of an aircraft whose height was not known: not used.
    pub no_height: u64,
    pub published: u64,
    /// Clouds given up once a position (a fix, ADS-B) placed the aircraft.
    pub handed_over: u64,
    /// Clouds whose one mode the tracks took over (before any fix).
    pub handed_over_one_mode: u64,
    /// Tracks taken over from a cloud that the time differences then kept
    /// missing: dropped for a new cloud.
    pub given_back: u64,
    /// Tracks taken over from a cloud for which a transmission had another
    /// solution that who heard it did not rule out: dropped for a new cloud.
    pub mirrored: u64,
    /// Tracks taken over from a cloud that their time differences alone no
    /// longer held within `publish_sigma_m`: dropped for a new cloud.
    pub spread: u64,
    /// Aircraft not given a filter: as many as `max_filters` were running.
    pub refused: u64,
    /// Velocity reports (Comm-B) the clouds took.
    pub velocities: u64,
    /// Velocity reports no particle of a cloud that had taken some before
    /// came near: left out.
    pub velocities_contradicting: u64,
    /// Velocity reports that confirmed the one that contradicted the cloud
    /// before them (the aircraft turned or changed speed): the cloud's
    /// velocities drawn again from them.
    pub velocities_redrawn: u64,
}

/// One line for people (the offline run's report): what came in, what was
/// turned away and why, what went out.
impl std::fmt::Display for FuseStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let rejected: Vec<String> =
            self.rejected().iter().filter(|(_, n)| *n > 0).map(|(k, n)| format!("{k}={n}")).collect();
        write!(
            f,
            "{} measurements, rejected [{}], gated {}, re-run {}; tracks {} created, {} dropped, \
             {} restarts; {} published ({} withheld, too spread), fusion fallbacks {}; ADS-B suspect flags {} ({} positions kept out); \
             TDOA updates {}; conflicts {}",
            self.measurements,
            rejected.join(" "),
            self.gated,
            self.reruns,
            self.tracks_created,
            self.tracks_dropped,
            self.restarts,
            self.published,
            self.withheld_spread,
            self.fusion_fallbacks,
            self.suspect_flags,
            self.suspect_excluded,
            self.tdoa,
            self.conflicts
        )?;
        let s = &self.sparse;
        if s.started > 0 {
            write!(
                f,
                "; sparse geometry: {} particle filters ({} refused, table full), {} updates, {} restarts, \
                 {} velocity reports ({} contradicting, left out, {} confirming a change), {} published, {} handed over at a fix, {} at one mode \
                 ({} given back, {} for a mirror, {} for their spread), {} groups without a height",
                s.started,
                s.refused,
                s.updates,
                s.restarts,
                s.velocities,
                s.velocities_contradicting,
                s.velocities_redrawn,
                s.published,
                s.handed_over,
                s.handed_over_one_mode,
                s.given_back,
                s.mirrored,
                s.spread,
                s.no_height
            )?;
        }
        Ok(())
    }
}

impl FuseStats {
    /// The measurements turned away as bad input, by reason: what the
    /// service exports and sums in its stats line.
    pub fn rejected(&self) -> [(&'static str, u64); 5] {
        [
            ("non_finite", self.rejected_non_finite),
            ("speed", self.rejected_speed),
            ("time", self.rejected_time),
            ("too_late", self.too_late),
            ("table_full", self.table_full),
        ]
    }
}
