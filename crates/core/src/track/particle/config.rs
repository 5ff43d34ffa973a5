//! The particle filter's parameters (`[core.track.sparse]`), their
//! defaults and their checks.

use serde::{Deserialize, Serialize};

use crate::problem::{positive, Problem};

/// The particle filter's parameters (`[core.track.sparse]`).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct SparseConfig {
    /// Track aircraft heard by too few receivers for a fix with particles
    /// (on by default; off, the receivers' coverage is not learnt either).
    pub enabled: bool,
    pub particles: usize,
    /// Resample when the effective sample size falls below this share of the particles.
    pub resample_below: f64,
    /// White acceleration of the motion model (m/s^2, per axis).
    pub accel_ms2: f64,
    /// Initial speeds are drawn between these (m/s).
    pub speed_ms: [f64; 2],
    /// Initial positions are drawn within this of the first sites (m); the
    /// sites' radio horizons bound them too.
    pub max_range_m: f64,
    /// Published only once the cloud's position is this tight (m, 1 sigma,
    /// largest axis) and has one mode.
    pub publish_sigma_m: f64,
    /// Most filters running at once (each holds its particles: 40 kB at 1,000);
    /// aircraft beyond are refused and counted.
    pub max_filters: usize,
    /// An aircraft gets a filter once its groups have been too small for a
    /// fix this long (s): most aircraft entering coverage are fixed within
    /// seconds, and a filter costs about a millisecond to start.
    pub start_after_s: f64,
    /// The aircraft's Gaussian tracks take over from the cloud once this
    /// many of its estimates in a row (one a second) were publishable: one
    /// might be a cloud passing through one mode on its way between two.
    /// 0: only at the aircraft's first fix.
    pub handover_after: u32,
    /// Who heard a transmission and who did not (the receivers' coverage,
    /// learnt from ADS-B and fixes) weighs the particles in full once in this long
    /// (s); 0: not at all. One aircraft's successive transmissions are
    /// heard or missed alike (its transponder's power, its place).
    pub hearing_memory_s: f64,
}

impl Default for SparseConfig {
    fn default() -> Self {
        SparseConfig {
            enabled: true,
            particles: 1000,
            resample_below: 0.5,
            accel_ms2: 1.0,
            speed_ms: [60.0, 300.0],
            max_range_m: 400_000.0,
            publish_sigma_m: 3_000.0,
            max_filters: 500,
            start_after_s: 10.0,
            handover_after: 3,
            hearing_memory_s: 10.0,
        }
    }
}

impl SparseConfig {
    /// Every problem of the table at `path` (`core.track.sparse`), into `out`.
    pub fn validate(&self, path: &str, out: &mut Vec<Problem>) {
        if !(100..=100_000).contains(&self.particles) {
            out.push(Problem::at(path, format!("particles = {} must be 100 to 100000", self.particles)));
        }
        if !(self.resample_below > 0.0 && self.resample_below <= 1.0) {
            out.push(Problem::at(
                path,
                format!("resample_below = {} must be in (0, 1]", self.resample_below),
            ));
        }
        if !(self.speed_ms[0] >= 0.0 && self.speed_ms[0] < self.speed_ms[1]) {
            out.push(Problem::at(
                path,
                format!("speed_ms = {:?} must be an increasing pair from 0", self.speed_ms),
            ));
        }
        if !(self.hearing_memory_s.is_finite() && self.hearing_memory_s >= 0.0) {
            out.push(Problem::at(
                path,
                format!("hearing_memory_s = {} must be 0 (off) or more", self.hearing_memory_s),
            ));
        }
        positive(
            path,
            &[
                ("accel_ms2", self.accel_ms2),
                ("max_range_m", self.max_range_m),
                ("publish_sigma_m", self.publish_sigma_m),
                ("start_after_s", self.start_after_s),
            ],
            out,
        );
    }
}
