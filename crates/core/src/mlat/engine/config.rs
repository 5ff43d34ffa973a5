//! The multilateration engine's configuration (`[core.mlat]`).

use serde::Deserialize;

use crate::problem::{not_negative, positive, Problem};

#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct MlatConfig {
    /// Receivers closer than this (m) count as one site, their times
    /// averaged: only where their times cannot differ by more than their
    /// noise (15 m is 50 ns).
    pub min_separation_m: f64,
    /// Timing jitter, 1 sigma (ns), by clock type.
    pub jitter_beast12_ns: f64,
    pub jitter_gps_ns: f64,
    /// Uncertainty (m) of the barometric-to-geometric correction applied to
    /// Mode S altitudes when no local estimate exists.
    pub baro_sigma_m: f64,
    /// A recent altitude is used up to this age (s), its sigma growing by
    /// `alt_growth_mps` per second.
    pub max_alt_age_s: f64,
    pub alt_growth_mps: f64,
    /// Lowest NACp of an ADS-B position used for clock synchronisation.
    pub min_sync_nacp: u8,
    /// Clock model of the pair filters: phase noise (ns per square-root
    /// second) and random walk of the relative frequency (parts per billion
    /// per square-root second). Smaller values average sync measurements longer.
    pub clock_phase_noise_ns: f64,
    pub clock_drift_walk_ppb: f64,
    /// Where each clock type's timestamp sits in the frame, relative to the
    /// start of the preamble (ns); subtracted so every receiver's time refers
    /// to the same point of the frame.
    pub timestamp_offset_beast12_ns: f64,
    pub timestamp_offset_gps_ns: f64,
    /// Learn each receiver's timing bias and noise from the residuals of
    /// over-determined fixes (self-calibration).
    pub calibrate: bool,
    /// Aircraft that broadcast ADS-B positions are multilaterated at most this
    /// often (s) to cross-check them and feed their MLAT track; 0 does every
    /// transmission. Mode S only aircraft always get every transmission, and
    /// clock synchronisation always uses every ADS-B position.
    pub adsb_interval_s: f64,
    /// Use a receiver's position as surveyed from the traffic when it is
    /// found misplaced (more than 30 m and four sigmas off), instead
    /// of the declared one. Off: the offset is only reported.
    pub self_survey: bool,
}

impl Default for MlatConfig {
    fn default() -> Self {
        MlatConfig {
            min_separation_m: 15.0,
            jitter_beast12_ns: 83.0,
            jitter_gps_ns: 50.0,
            baro_sigma_m: 75.0,
            max_alt_age_s: 30.0,
            alt_growth_mps: 15.0,
            min_sync_nacp: 6,
            clock_phase_noise_ns: 0.5,
            clock_drift_walk_ppb: 2.0,
            timestamp_offset_beast12_ns: 0.0,
            timestamp_offset_gps_ns: 0.0,
            calibrate: true,
            adsb_interval_s: 1.0,
            self_survey: false,
        }
    }
}

impl MlatConfig {
    /// Every problem of the table at `path` (`core.mlat`), into `out`. A
    /// timing sigma of zero would weigh a receiver infinitely; a negative
    /// interval or age turns a test around.
    pub fn validate(&self, path: &str, out: &mut Vec<Problem>) {
        positive(
            path,
            &[
                ("jitter_beast12_ns", self.jitter_beast12_ns),
                ("jitter_gps_ns", self.jitter_gps_ns),
                ("baro_sigma_m", self.baro_sigma_m),
            ],
            out,
        );
        not_negative(
            path,
            &[
                ("min_separation_m", self.min_separation_m),
                ("max_alt_age_s", self.max_alt_age_s),
                ("alt_growth_mps", self.alt_growth_mps),
                ("clock_phase_noise_ns", self.clock_phase_noise_ns),
                ("clock_drift_walk_ppb", self.clock_drift_walk_ppb),
                ("adsb_interval_s", self.adsb_interval_s),
            ],
            out,
        );
        for (name, v) in [
            ("timestamp_offset_beast12_ns", self.timestamp_offset_beast12_ns),
            ("timestamp_offset_gps_ns", self.timestamp_offset_gps_ns),
        ] {
            if !v.is_finite() {
                out.push(Problem::at(path, format!("{name} = {v} must be a number")));
            }
        }
        if self.min_sync_nacp > 11 {
            out.push(Problem::at(path, format!("min_sync_nacp = {} must be 0 to 11", self.min_sync_nacp)));
        }
    }
}
