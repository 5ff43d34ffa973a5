//! Tracker configuration (`[track]`): the IMM model set, noise, the
//! NACp-driven sampling table, lifecycle and bounds. Validated as a whole so
//! every problem is reported at once.

use std::sync::Arc;

use nalgebra::DMatrix;
use serde::Deserialize;

use super::imm::ImmSpec;
use super::models::MotionModel;
use crate::problem::{not_negative, positive, Problem};

/// One model of the IMM set, as written in the configuration.
#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ModelConfig {
    /// Constant velocity; `q` acceleration noise density (m^2/s^3).
    Cv { q: f64 },
    /// Constant acceleration; `q` jerk noise density (m^2/s^5).
    Ca { q: f64 },
    /// Coordinated turn at `turn_dps` (deg/s, positive right); `q` as for cv.
    Ct { turn_dps: f64, q: f64 },
    /// Singer: manoeuvre rate `alpha` (1/s), acceleration sigma (m/s^2).
    Singer { alpha: f64, sigma_a: f64 },
    /// Current statistical: manoeuvre rate `alpha` (1/s), largest acceleration (m/s^2).
    Cs { alpha: f64, a_max: f64 },
    /// Tangential acceleration: `accel` (m/s^2, positive speeding up) along
    /// the velocity; `q` as for cv.
    Ta { accel: f64, q: f64 },
}

impl ModelConfig {
    pub fn model(&self) -> MotionModel {
        match *self {
            ModelConfig::Cv { q } => MotionModel::ConstantVelocity { q },
            ModelConfig::Ca { q } => MotionModel::ConstantAcceleration { q },
            ModelConfig::Ct { turn_dps, q } => {
                MotionModel::CoordinatedTurn { omega: turn_dps.to_radians(), q }
            }
            ModelConfig::Singer { alpha, sigma_a } => MotionModel::Singer { alpha, sigma_a },
            ModelConfig::Cs { alpha, a_max } => MotionModel::CurrentStatistical { alpha, a_max },
            ModelConfig::Ta { accel, q } => MotionModel::Tangential { accel, q },
        }
    }

    fn check(&self) -> Result<(), String> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{name} = {v} must be positive"))
            }
        };
        let within = |name: &str, v: f64, limit: f64| {
            if v.is_finite() && v.abs() <= limit {
                Ok(())
            } else {
                Err(format!("{name} = {v} must be within +-{limit}"))
            }
        };
        match *self {
            ModelConfig::Cv { q } | ModelConfig::Ca { q } => positive("q", q),
            ModelConfig::Ct { turn_dps, q } => positive("q", q).and(within("turn_dps", turn_dps, 20.0)),
            ModelConfig::Singer { alpha, sigma_a } => {
                positive("alpha", alpha).and(positive("sigma_a", sigma_a))
            }
            ModelConfig::Cs { alpha, a_max } => positive("alpha", alpha).and(positive("a_max", a_max)),
            ModelConfig::Ta { accel, q } => positive("q", q).and(within("accel", accel, 20.0)),
        }
    }
}

/// The switching matrix of an aircraft not heard in ADS-B (Mode S only, or
/// not yet): one that keeps to the first model (constant velocity) and
/// returns to it (`Imm::home`). Such an aircraft is measured by MLAT fixes
/// alone, often hundreds of metres apart at a fix or two a second, where the
/// models' likelihoods hardly differ: its model probabilities then sit near
/// the matrix's stationary share, which for `stay` is equal for every model,
/// so the manoeuvre models kept three quarters of the weight in straight
/// flight and their noise went into the estimate. ADS-B aircraft keep
/// `stay`/`transition`: their positions and velocities tell the models
/// apart within a second or two, and this matrix's later switching cost
/// them more than it saved (docs/tracking.md).
#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct MlatOnlyConfig {
    /// Off: such aircraft switch like any other.
    pub enabled: bool,
    /// Probability of staying in the first model from one step to the next.
    pub stay_first: f64,
    /// Each other model's probability of returning to the first.
    pub to_first: f64,
}

impl Default for MlatOnlyConfig {
    fn default() -> Self {
        MlatOnlyConfig { enabled: true, stay_first: 0.99, to_first: 0.1 }
    }
}

#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct TrackConfig {
    /// The IMM model set.
    pub models: Vec<ModelConfig>,
    /// Probability of staying in a model from one step to the next; the rest
    /// is shared equally. Ignored when `transition` is given.
    pub stay: f64,
    /// Full Markov switching matrix (rows sum to 1), optional.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub transition: Option<Vec<Vec<f64>>>,
    /// The switching matrix of aircraft heard only through multilateration.
    pub mlat_only: MlatOnlyConfig,
    /// The particle filter of aircraft heard by too few receivers for a fix.
    pub sparse: super::particle::SparseConfig,
    /// Vertical channel (height, climb rate): acceleration noise density (m^2/s^3).
    pub vertical_q: f64,
    /// Output period by NACp 0..=11 (s).
    pub period_by_nacp: [f64; 12],
    /// Period of tracks without NACp (MLAT only) (s).
    pub period_default_s: f64,
    /// Late measurements up to this age are put in time order (s).
    pub reorder_window_s: f64,
    /// Time-of-applicability uncertainty of an ADS-B position (s, 1 sigma):
    /// GPS-timed receivers, and receivers timed by arrival at the server
    /// until their network delay is learnt (`core::delay`; then its spread,
    /// at least the first).
    pub adsb_time_sigma_gps_s: f64,
    pub adsb_time_sigma_arrival_s: f64,
    /// MLAT fixes' covariance, as the conformance monitor weighs them
    /// against ADS-B, is multiplied by up to this much, in proportion to the
    /// share of their timing variance that came from clock synchronisation
    /// (which persists from fix to fix). A track counts that share as often
    /// as its own memory holds fixes instead (`track::persistent`).
    pub mlat_sync_inflation: f64,
    /// Comm-B track and turn reports (BDS 5,0) of aircraft without ADS-B
    /// velocity feed their tracks as velocity measurements, and their heading
    /// and speed reports' vertical rates (BDS 6,0) as climb rates.
    pub commb_velocity: bool,
    /// With `commb_velocity`: heading and speed reports' heading and
    /// airspeed too, through the wind, magnetic variation and temperature
    /// learnt from the aircraft that also report their velocity by ADS-B.
    pub commb_heading: bool,
    /// Variational-Bayes scale of each source's measurement noise.
    pub vb: bool,
    /// Per-measurement forgetting factor of the VB estimate of MLAT fixes'
    /// noise (0-1).
    pub vb_forgetting: f64,
    /// The same for ADS-B positions. Their nominal noise is a transponder's
    /// claim (NACp), which may be wrong for good; the prior re-enters at
    /// every step, so a short memory keeps the estimate near the claim (an
    /// over-claim's scale reached 70% of the real one at 0.95, 90% at 0.98,
    /// both with a prior of 5).
    /// MLAT fixes' covariance is our own geometry's, and their tracks did
    /// worse with the longer memory (fusion-8seg-selfsync's fused NEES 3.25
    /// -> 4.19; docs/tracking.md).
    pub vb_forgetting_adsb: f64,
    /// Weight of the prior (nominal noise) in the VB estimate, in
    /// measurements: every track starts with it, and for MLAT fixes it
    /// re-enters at every step with the forgetting.
    pub vb_prior: f64,
    /// The weight that re-enters for ADS-B positions: lighter, as the claim
    /// may be wrong for good. At 5 an over-claim's scale stayed at 90% of
    /// the real ratio, at 1 it reaches it (344 and 331 of 343 on the two
    /// vb-noise flights); no benchmark moved by more than 0.03 m. Starting
    /// light as well let the first residuals overshoot (379).
    pub vb_prior_adsb: f64,
    /// Position measurements beyond this chi-square probability are gated out.
    pub gate_probability: f64,
    /// After this many gated measurements in a row the track restarts on the new data.
    pub max_gated_in_a_row: u32,
    /// Confirmation: `confirm_m` accepted positions among the last `confirm_n`.
    pub confirm_m: u32,
    pub confirm_n: u32,
    /// A track without a position update for this long is coasting (s) and
    /// dropped after `drop_after_s`.
    pub coast_after_s: f64,
    pub drop_after_s: f64,
    /// A coasting track (no position for `coast_after_s`) whose largest
    /// horizontal sigma is beyond this (m) is not published (counted): it
    /// no longer says where the aircraft is (one fed positions, however
    /// poor, is published). A
    /// track predicted across minutes without a position, while the
    /// aircraft was still heard, then pulled along one time difference's
    /// hyperbola, was published tens of kilometres off at thousands of
    /// metres a second. The same limit as a particle cloud's by default.
    pub publish_sigma_m: f64,
    /// Largest number of aircraft tracked; more are refused and counted.
    pub max_tracks: usize,
    /// Static/moving test: window of positions, their spacing (s; closer
    /// ones are skipped: slow movers need time to show) and false-alarm rate.
    pub motion_window: usize,
    pub motion_interval_s: f64,
    pub motion_false_alarm: f64,
}

impl Default for TrackConfig {
    fn default() -> Self {
        TrackConfig {
            models: vec![
                ModelConfig::Cv { q: 0.05 },
                ModelConfig::Ct { turn_dps: 3.0, q: 0.05 },
                ModelConfig::Ct { turn_dps: -3.0, q: 0.05 },
                ModelConfig::Cs { alpha: 1.0, a_max: 8.0 },
            ],
            stay: 0.9,
            transition: None,
            mlat_only: MlatOnlyConfig::default(),
            sparse: Default::default(),
            vertical_q: 0.5,
            period_by_nacp: [1.0, 1.0, 1.0, 1.0, 1.0, 0.8, 0.6, 0.6, 0.6, 0.8, 1.0, 1.0],
            period_default_s: 1.0,
            reorder_window_s: 2.0,
            adsb_time_sigma_gps_s: 0.01,
            adsb_time_sigma_arrival_s: 0.1,
            mlat_sync_inflation: 4.0,
            commb_velocity: true,
            commb_heading: true,
            vb: true,
            vb_forgetting: 0.95,
            vb_forgetting_adsb: 0.98,
            vb_prior: 5.0,
            vb_prior_adsb: 1.0,
            gate_probability: 0.9999,
            max_gated_in_a_row: 5,
            confirm_m: 3,
            confirm_n: 5,
            coast_after_s: 3.0,
            drop_after_s: 20.0,
            publish_sigma_m: 3_000.0,
            max_tracks: 20_000,
            motion_window: 5,
            motion_interval_s: 1.0,
            motion_false_alarm: 0.05,
        }
    }
}

impl TrackConfig {
    /// Every problem of the table at `path` (`core.track`), into `out`.
    // Over 80 lines: a flat list of independent checks, one per field.
    pub fn validate(&self, path: &str, out: &mut Vec<Problem>) {
        let mut bad = |message: String| out.push(Problem::at(path, message));
        if self.models.is_empty() {
            bad("models: at least one model".to_string());
        }
        for (i, m) in self.models.iter().enumerate() {
            if let Err(e) = m.check() {
                bad(format!("models[{i}]: {e}"));
            }
        }
        if let Some(t) = &self.transition {
            let n = self.models.len();
            if t.len() != n || t.iter().any(|r| r.len() != n) {
                bad(format!("transition must be {n}x{n}, one row and column per model"));
            } else if t.iter().any(|r| {
                r.iter().any(|p| !(0.0..=1.0).contains(p)) || (r.iter().sum::<f64>() - 1.0).abs() > 1e-6
            }) {
                bad("transition rows must be probabilities summing to 1".into());
            }
        } else if !(self.stay > 0.0 && self.stay <= 1.0) {
            bad(format!("stay = {} must be in (0, 1]", self.stay));
        }
        let m = &self.mlat_only;
        if m.enabled && super::Imm::home(self.models.len(), m.stay_first, m.to_first).is_none() {
            bad(format!(
                "mlat_only: stay_first = {} and to_first = {} must be probabilities that leave the \
                 other models a chance to stay",
                m.stay_first, m.to_first
            ));
        }
        if let Some(p) = self.period_by_nacp.iter().find(|p| !(p.is_finite() && **p > 0.0 && **p <= 60.0)) {
            bad(format!("period_by_nacp: {p} must be in (0, 60]"));
        }
        if !(self.mlat_sync_inflation.is_finite() && self.mlat_sync_inflation >= 1.0) {
            bad(format!("mlat_sync_inflation = {} must be at least 1", self.mlat_sync_inflation));
        }
        for (name, v) in
            [("vb_forgetting", self.vb_forgetting), ("vb_forgetting_adsb", self.vb_forgetting_adsb)]
        {
            if !(v > 0.0 && v <= 1.0) {
                bad(format!("{name} = {v} must be in (0, 1]"));
            }
        }
        if !(self.gate_probability > 0.5 && self.gate_probability < 1.0) {
            bad(format!("gate_probability = {} must be in (0.5, 1)", self.gate_probability));
        }
        if self.confirm_m == 0 || self.confirm_m > self.confirm_n || self.confirm_n > 32 {
            bad(format!(
                "confirm_m = {} of confirm_n = {}: need 1 <= m <= n <= 32",
                self.confirm_m, self.confirm_n
            ));
        }
        if self.max_tracks == 0 {
            bad("max_tracks must be positive".into());
        }
        if self.motion_window < 2 || !(self.motion_false_alarm > 0.0 && self.motion_false_alarm < 1.0) {
            bad("motion_window must be at least 2 and motion_false_alarm in (0, 1)".into());
        }
        positive(
            path,
            &[
                ("vertical_q", self.vertical_q),
                ("period_default_s", self.period_default_s),
                ("reorder_window_s", self.reorder_window_s),
                ("coast_after_s", self.coast_after_s),
                ("drop_after_s", self.drop_after_s),
                ("publish_sigma_m", self.publish_sigma_m),
                ("motion_interval_s", self.motion_interval_s),
                ("vb_prior", self.vb_prior),
                ("vb_prior_adsb", self.vb_prior_adsb),
            ],
            out,
        );
        not_negative(
            path,
            &[
                ("adsb_time_sigma_gps_s", self.adsb_time_sigma_gps_s),
                ("adsb_time_sigma_arrival_s", self.adsb_time_sigma_arrival_s),
            ],
            out,
        );
        self.sparse.validate(&format!("{path}.sparse"), out);
    }

    pub fn imm_spec(&self) -> Arc<ImmSpec> {
        let n = self.models.len();
        let transition = match &self.transition {
            Some(t) => DMatrix::from_fn(n, n, |r, c| t[r][c]),
            None => super::Imm::sticky(n, self.stay),
        };
        Arc::new(ImmSpec::new(self.models.iter().map(ModelConfig::model).collect(), transition))
    }

    /// The spec of aircraft heard only through MLAT (see [`MlatOnlyConfig`]):
    /// `spec` itself when that is off.
    pub fn imm_spec_mlat_only(&self, spec: &Arc<ImmSpec>) -> Arc<ImmSpec> {
        let m = &self.mlat_only;
        match super::Imm::home(self.models.len(), m.stay_first, m.to_first) {
            Some(t) if m.enabled => Arc::new(ImmSpec::new(spec.models.clone(), t)),
            _ => spec.clone(),
        }
    }

    /// The largest turn rate of the models (rad/s): their coordinated
    /// turns', or a standard-rate turn's (3 degrees a second) without any.
    pub fn largest_turn_rps(&self) -> f64 {
        let turns = self.models.iter().filter_map(|m| match m {
            ModelConfig::Ct { turn_dps, .. } => Some(turn_dps.abs()),
            _ => None,
        });
        turns.reduce(f64::max).unwrap_or(3.0).to_radians()
    }

    /// The output period for a NACp (s).
    pub fn period_s(&self, nac_p: Option<u8>) -> f64 {
        match nac_p {
            Some(n) => self.period_by_nacp[(n as usize).min(11)],
            None => self.period_default_s,
        }
    }

    /// The densest period of the table: used while a track is in conflict.
    pub fn densest_period_s(&self) -> f64 {
        self.period_by_nacp.iter().copied().fold(self.period_default_s, f64::min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `[core]` table of a configuration file (its other tables are
    /// the daemon's, and ignored here).
    fn core_of(text: &str) -> crate::core::CoreConfig {
        #[derive(serde::Deserialize)]
        struct File {
            #[serde(default)]
            core: crate::core::CoreConfig,
        }
        toml::from_str::<File>(text).unwrap().core
    }

    #[test]
    fn the_benchmark_model_set_loads_and_bad_models_are_each_named() {
        let t = &core_of(include_str!("../../../../fixtures/configs/benchmark-accelerations.toml")).track;
        assert!(t.models.contains(&ModelConfig::Ta { accel: -3.0, q: 0.05 }), "{:?}", t.models);
        assert_eq!(t.imm_spec().models.len(), 5);
        let bad = TrackConfig {
            models: vec![ModelConfig::Ta { accel: 30.0, q: 0.05 }, ModelConfig::Ta { accel: 1.0, q: 0.0 }],
            ..TrackConfig::default()
        };
        let mut errs = Vec::new();
        bad.validate("core.track", &mut errs);
        let said = |m: &str| errs.contains(&Problem::at("core.track", m));
        assert!(said("models[0]: accel = 30 must be within +-20"), "{errs:?}");
        assert!(said("models[1]: q = 0 must be positive"), "{errs:?}");
    }

    #[test]
    fn the_mlat_only_matrix_is_checked_and_can_be_turned_off() {
        let text = "[core.track]\nmlat_only = { stay_first = 0.5, to_first = 0.9 }\n";
        let err = core_of(text).validate().unwrap_err();
        assert!(
            err.iter().any(|p| p.table == "[core.track]"
                && p.message.starts_with("mlat_only: stay_first = 0.5 and to_first = 0.9")),
            "{err:?}"
        );
        let off = TrackConfig {
            mlat_only: MlatOnlyConfig { enabled: false, ..Default::default() },
            ..Default::default()
        };
        let spec = off.imm_spec();
        assert!(Arc::ptr_eq(&off.imm_spec_mlat_only(&spec), &spec));
        let on = TrackConfig::default();
        let spec = on.imm_spec();
        assert_eq!(on.imm_spec_mlat_only(&spec).transition, super::super::Imm::home(4, 0.99, 0.1).unwrap());
    }
}
