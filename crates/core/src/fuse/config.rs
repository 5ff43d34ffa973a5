//! The fusion stage's configuration (`[core.fuse]`).

use serde::Deserialize;

use super::{ConflictConfig, ConformanceConfig, Method};
use crate::problem::{not_negative, Problem};

#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct FuseConfig {
    /// How the fused track is made: measurement, information, convex, ci, reweighted.
    pub method: Method,
    /// How long measurements of an aircraft that MLAT feeds wait, in time
    /// order, before they are applied and the track is published (s): about
    /// the core's group wait, so the fix of the same transmission is in it.
    pub mlat_hold_s: f64,
    /// A source fed a track "lately" within this time (s): `sources`.
    pub sources_window_s: f64,
    /// Measurements more than this far from the present are rejected (s).
    pub max_time_error_s: f64,
    pub conformance: ConformanceConfig,
    pub conflict: ConflictConfig,
}

impl Default for FuseConfig {
    fn default() -> Self {
        FuseConfig {
            method: Method::Measurement,
            mlat_hold_s: 0.6,
            sources_window_s: 10.0,
            max_time_error_s: 10.0,
            conformance: ConformanceConfig::default(),
            conflict: ConflictConfig::default(),
        }
    }
}

impl FuseConfig {
    /// Every problem of the table at `path` (`core.fuse`) and its
    /// sub-tables, into `out`.
    pub fn validate(&self, path: &str, out: &mut Vec<Problem>) {
        not_negative(
            path,
            &[
                ("mlat_hold_s", self.mlat_hold_s),
                ("sources_window_s", self.sources_window_s),
                ("max_time_error_s", self.max_time_error_s),
            ],
            out,
        );
        self.conformance.validate(&format!("{path}.conformance"), out);
        self.conflict.validate(&format!("{path}.conflict"), out);
    }
}
