//! One aircraft's track: a horizontal IMM in a re-centred local plane, a
//! vertical channel, a variational-Bayes scale of each source's measurement
//! noise, and a short history so late measurements are applied in time order.
//!
//! Why a history: MLAT fixes arrive after the copies of their transmission
//! have been collected (half a second), ADS-B positions straight away, so a
//! track can see measurements out of time order (the fusion stage's MLAT
//! hold makes that rare, but not impossible). The recent measurements are
//! kept, every fourth with a copy of the state from before it; a late one
//! restores the nearest copy before its time and the measurements from
//! there are re-applied around it. The result is the same as if everything
//! had arrived in order; the copies (1.7 kB each) are a quarter of what one
//! per measurement would cost, paid on every step, for a step or two more
//! in the rare re-run.
//!
//! Why VB: a transponder's NACp is a claim. Each source's noise scale is
//! learnt from the track's residuals (`noise.rs`, with why gated
//! measurements teach it only once a restart has shown the noise, not the
//! track, was wrong: taught at once and in full, a track started on one
//! wild MLAT fix let the honest fixes after it open the gate by raising the
//! scale, and crawled back over minutes).
//!
//! Beside it: what a track is given (`measurement.rs`) and what it gives
//! (`estimate.rs`), its noise learner (`noise.rs`) and lifecycle
//! (`lifecycle.rs`); its tests are in `track_tests.rs`. Within it, one
//! measurement model per kind of observation: a horizontal position with
//! its gate and restarts (`track/position.rs`), a velocity
//! (`track/velocity.rs`), time differences (`track/tdoa.rs`) and the
//! vertical channel's heights and climb rates (`track/vertical.rs`).

use std::collections::VecDeque;
use std::sync::Arc;

use smallvec::SmallVec;

use nalgebra::{Matrix2, Matrix6, Vector2, Vector6};

use super::config::TrackConfig;
use super::estimate::at_aircraft;
pub use super::estimate::{transfer, Estimate, Kinematics};
use super::gate::Gate;
use super::imm::{Imm, ImmSpec};
use super::kf::{self, Gaussian, Linear};
use super::lifecycle::Lifecycle;
pub use super::lifecycle::Stage;
pub use super::measurement::{Measurement, Observation, Outcome, Persistent, SharedShare, Source};
use super::noise::Noise;
use super::plane::Plane;

mod persistent;
mod position;
mod tdoa;
mod velocity;
mod vertical;
pub use vertical::Vertical;

/// Everything a measurement changes: copied before each one for re-runs.
#[derive(Clone, Debug)]
struct State {
    /// Newest measurement, newest horizontal and newest vertical update.
    t: f64,
    t_h: f64,
    t_v: f64,
    plane: Option<Plane>,
    imm: Option<Imm>,
    vertical: Option<Vertical>,
    /// Each source's noise scale (ADS-B, MLAT).
    noise: [Noise; 2],
    /// Trace of each source's newest nominal covariance (m^2), and whether
    /// it was the source's own claim.
    nominal: [Option<(f64, bool)>; 2],
    gated_in_a_row: u32,
    /// Positions accepted since the horizontal filter (re)started.
    accepted_since_start: u32,
    /// While the track knows the aircraft from time differences alone
    /// (started from a particle cloud, no position since): when its
    /// horizontal position was last measured whole, at the handover or by
    /// two time differences (see `track/tdoa.rs`).
    seen_whole_t: Option<f64>,
}

/// `I - K H` of an update: the posterior covariance times the prior's inverse.
fn gain(prior: &Gaussian, post: &Gaussian) -> Option<Matrix6<f64>> {
    Some(post.p * prior.p.cholesky()?.inverse())
}

/// Height variance (m^2) from which a height is taken to carry a persistent offset.
const BIASED_HEIGHT_VAR: f64 = 40.0 * 40.0;

/// Heights gated in a row before the vertical channel starts again.
const VERTICAL_RESTART: u8 = 3;
/// Past this distance from its plane's origin a track moves the origin (m).
const RECENTRE_M: f64 = 20_000.0;
/// Past this height above or below its plane a track moves the plane to its
/// height (m): a plane measures lengths on the surface at its own height, so
/// an aircraft 5 km above it seems to fly 0.08% slower in it than its
/// velocity reports say, a bias of 0.2 m/s at 250 m/s that velocity reports
/// of NACv 2 (1.2 m/s) soon make the track confident about; 100 m leaves
/// 4 mm/s.
const REHEIGHT_M: f64 = 100.0;
/// Most measurements kept for re-runs, whatever the reorder window: an
/// aircraft sends about seven a second (positions, velocities, fixes,
/// altitudes), so 24 cover the default 2 s window with room; a flood of
/// one aircraft's data (a replay run fast, a looping feed) cannot grow a
/// track's memory beyond this (every `SNAPSHOT_EVERY`th entry holds a copy
/// of the filter, 1.7 kB).
const MAX_HISTORY: usize = 24;
/// One measurement in this many keeps the state from before it.
const SNAPSHOT_EVERY: usize = 4;

/// Initial velocity uncertainty without a velocity report (m/s, 1 sigma).
const INIT_SPEED_SIGMA: f64 = 150.0;
const INIT_ACCEL_SIGMA: f64 = 2.0;

#[derive(Clone, Debug)]
pub struct Track {
    /// The models' switching matrices by the time from which each applies,
    /// oldest first (one, unless `set_spec` changed it within the reorder
    /// window): a step re-run from the history switches as it did when it
    /// first ran.
    specs: SmallVec<[(f64, Arc<ImmSpec>); 2]>,
    cfg: Arc<TrackConfig>,
    gate: Gate,
    state: State,
    /// Measurements within the reorder window, in time order, every
    /// `SNAPSHOT_EVERY`th (and always the oldest) with the state before it.
    history: VecDeque<(Measurement, Option<Box<State>>)>,
    /// A copy's allocation the history let go of, for the next copy: one
    /// allocation and one free for every fourth measurement were 3% of the
    /// tracking stage.
    spare: Option<Box<State>>,
    lifecycle: Lifecycle,
    /// Time of the newest accepted position (Unix s).
    pub last_position_t: f64,
    /// Started from a particle cloud ([`Track::start_from`]): its time
    /// differences count towards its confirmation.
    started_from_cloud: bool,
    pub restarts: u64,
    /// Keep `I - K H` of each update (for the cross-covariance of track fusion).
    pub keep_gain: bool,
    /// Time and `I - K H` (posterior covariance times the prior's inverse) of the newest update.
    pub gain: Option<(f64, Matrix6<f64>)>,
}

impl Track {
    pub fn new(cfg: Arc<TrackConfig>, spec: Arc<ImmSpec>) -> Track {
        let gate = Gate::new(cfg.gate_probability);
        // Both sources start from the full prior: a light one let ADS-B's first
        // residuals (the velocity's, before the start-up rule) overshoot.
        let noise = [Noise::new(cfg.vb_prior); 2];
        Track {
            specs: smallvec::smallvec![(f64::NEG_INFINITY, spec)],
            gate,
            state: State {
                t: f64::NEG_INFINITY,
                t_h: f64::NEG_INFINITY,
                t_v: f64::NEG_INFINITY,
                plane: None,
                imm: None,
                vertical: None,
                noise,
                nominal: [None; 2],
                gated_in_a_row: 0,
                accepted_since_start: 0,
                seen_whole_t: None,
            },
            cfg,
            history: VecDeque::new(),
            spare: None,
            lifecycle: Lifecycle::default(),
            last_position_t: f64::NEG_INFINITY,
            started_from_cloud: false,
            restarts: 0,
            keep_gain: false,
            gain: None,
        }
    }

    /// Changes the models' switching matrix (the same models) for the steps
    /// from `t` on, or from just after the newest step already taken when `t`
    /// is not after it (those keep the matrix they ran with).
    pub fn set_spec(&mut self, t: f64, spec: Arc<ImmSpec>) {
        if Arc::ptr_eq(&self.specs[self.specs.len() - 1].1, &spec) {
            return;
        }
        let newest = self.state.t;
        // Just after `newest` (times are positive: Unix seconds).
        let from = if t > newest { t } else { f64::from_bits(newest.to_bits() + 1) };
        self.specs.retain(|(f, _)| *f < from);
        // The next step of this state is at `from` or later.
        if let Some(imm) = &mut self.state.imm {
            imm.spec = spec.clone();
        }
        self.specs.push((from, spec));
        // Nothing older than the history is ever run again.
        let oldest = self.history.front().map_or(newest, |(m, _)| m.t);
        while self.specs.len() > 1 && self.specs[1].0 <= oldest {
            self.specs.remove(0);
        }
    }

    /// The matrix of a step at `t`.
    fn spec_at(specs: &[(f64, Arc<ImmSpec>)], t: f64) -> &Arc<ImmSpec> {
        &specs.iter().rev().find(|(from, _)| *from <= t).unwrap_or(&specs[0]).1
    }

    /// Time of the newest applied measurement.
    pub fn t(&self) -> f64 {
        self.state.t
    }

    pub fn vb_scale(&self, source: Source) -> f64 {
        self.state.noise[source as usize].scale()
    }

    /// Ground speed of the current estimate (m/s).
    pub fn speed(&self) -> Option<f64> {
        let x = self.state.imm.as_ref()?.mean();
        Some(x[2].hypot(x[3]))
    }

    pub fn has_position(&self) -> bool {
        self.state.imm.is_some()
    }

    /// Coasting at `t`: no position (a fix, ADS-B) for longer than `after_s`.
    pub fn coasting_at(&self, t: f64, after_s: f64) -> bool {
        t - self.last_position_t > after_s
    }

    /// Applies a measurement in its time order.
    pub fn apply(&mut self, m: Measurement) -> Outcome {
        let oldest = self.history.front().map_or(f64::NEG_INFINITY, |(h, _)| h.t);
        let outcome = if m.t >= self.state.t {
            self.apply_and_store(m)
        } else if m.t < oldest || m.t < self.state.t - self.cfg.reorder_window_s {
            return Outcome::TooLate;
        } else {
            // Back to the nearest copy before the first newer measurement,
            // then the older ones from there, this one and the newer ones
            // again, in order.
            let i = self.history.partition_point(|(h, _)| h.t <= m.t);
            let j = self.nearest_copy(i);
            let mut tail = self.history.drain(j..);
            let (first, before) = tail.next().expect("a newer measurement exists");
            let rest: Vec<Measurement> = std::iter::once(first).chain(tail.map(|(h, _)| h)).collect();
            self.state = *before.expect("found with a copy");
            let (older, newer) = rest.split_at(i - j);
            for h in older {
                self.apply_and_store(*h);
            }
            let o = self.apply_and_store(m);
            for h in newer {
                self.apply_and_store(*h);
            }
            o
        };
        match (m.obs, outcome) {
            (Observation::Position { .. }, _) => {
                self.record_hit(matches!(outcome, Outcome::Applied { .. } | Outcome::Restarted), m.t)
            }
            // Time differences confirm a track started from a particle
            // cloud (which has no position to count): accepted as a position
            // is, or gated. Others wait for positions, whose heights they
            // publish with them.
            (Observation::Tdoa { .. }, Outcome::Applied { .. } | Outcome::Gated)
                if self.started_from_cloud =>
            {
                self.lifecycle.record(
                    matches!(outcome, Outcome::Applied { .. }),
                    self.cfg.confirm_m,
                    self.cfg.confirm_n,
                )
            }
            _ => {}
        }
        // Older entries go, up to the next copy, once that copy is older
        // than the window (or there are too many): the oldest kept always
        // has one to go back to.
        let horizon = self.state.t - self.cfg.reorder_window_s;
        while let Some(next) = (1..self.history.len()).find(|&k| self.history[k].1.is_some()) {
            if self.history[next].0.t >= horizon && self.history.len() <= MAX_HISTORY {
                break;
            }
            for (_, copy) in self.history.drain(..next) {
                self.spare = self.spare.take().or(copy);
            }
        }
        outcome
    }

    fn apply_and_store(&mut self, m: Measurement) -> Outcome {
        let copy = self.history.iter().rev().take(SNAPSHOT_EVERY - 1).all(|(_, s)| s.is_none());
        let before = copy.then(|| match self.spare.take() {
            Some(mut b) => {
                (*b).clone_from(&self.state);
                b
            }
            None => Box::new(self.state.clone()),
        });
        let o = self.apply_one(&m);
        self.history.push_back((m, before));
        o
    }

    /// Index of the nearest history entry at or before `i` that keeps a copy
    /// of the state (the oldest always does).
    fn nearest_copy(&self, i: usize) -> usize {
        (0..=i).rev().find(|&k| self.history[k].1.is_some()).expect("the oldest has a copy")
    }

    /// The state after the history's measurements before index `i`, from
    /// the nearest copy (the estimate of a time between copies).
    fn replayed(&self, i: usize) -> State {
        let j = self.nearest_copy(i);
        let mut scratch = Track {
            specs: self.specs.clone(),
            cfg: self.cfg.clone(),
            gate: self.gate,
            state: self.history[j].1.as_deref().expect("found with a copy").clone(),
            history: VecDeque::new(),
            spare: None,
            lifecycle: self.lifecycle.stage_only(),
            last_position_t: self.last_position_t,
            started_from_cloud: self.started_from_cloud,
            restarts: 0,
            keep_gain: false,
            gain: None,
        };
        for (h, _) in self.history.range(j..i) {
            scratch.apply_one(h);
        }
        scratch.state
    }

    fn record_hit(&mut self, hit: bool, t: f64) {
        if hit {
            self.last_position_t = self.last_position_t.max(t);
        }
        self.lifecycle.record(hit, self.cfg.confirm_m, self.cfg.confirm_n);
    }

    /// Where the track is in its lifecycle.
    pub fn stage(&self) -> Stage {
        self.lifecycle.stage()
    }

    /// Published, fused and watched for conflicts only once confirmed.
    pub fn confirmed(&self) -> bool {
        self.lifecycle.confirmed()
    }

    fn apply_one(&mut self, m: &Measurement) -> Outcome {
        let dt = if self.state.t_h.is_finite() { m.t - self.state.t_h } else { 0.0 };
        // A state restored from the history may be older than a change of
        // matrix (with one matrix, every state has it).
        if let (Some(imm), true) = (&mut self.state.imm, self.specs.len() > 1) {
            let spec = Self::spec_at(&self.specs, m.t);
            if !Arc::ptr_eq(&imm.spec, spec) {
                imm.spec = spec.clone();
            }
        }
        let outcome = match m.obs {
            Observation::Position { lat, lon, cov_en, height, time_sigma_s, claimed, persistent, .. } => {
                if let Some((h, var)) = height {
                    self.vertical(m.t, 0, h, var);
                }
                self.rebase_vb(m.source, cov_en.trace(), claimed);
                self.position(m.t, dt, (lat, lon, cov_en), time_sigma_s, persistent, m.source)
            }
            Observation::Velocity { v_en, cov, climb } => {
                if let Some((c, var)) = climb {
                    self.vertical(m.t, 1, c, var);
                }
                self.velocity(m.t, dt, v_en, cov)
            }
            Observation::Height { h, var } => {
                self.vertical(m.t, 0, h, var);
                Outcome::Applied { nis: 0.0 }
            }
            // A climb rate the channel's gate keeps out (a Comm-B register
            // misread, say) is counted as gated, as a position would be.
            Observation::Climb { rate, var } => match self.vertical(m.t, 1, rate, var) {
                true => Outcome::Applied { nis: 0.0 },
                false => Outcome::Gated,
            },
            Observation::Tdoa { n, sites, persistent } => {
                self.tdoa(m.t, dt, &sites[..n as usize], &persistent[..n as usize])
            }
        };
        // The horizontal filter moved to m.t only if it took the measurement.
        if matches!(outcome, Outcome::Applied { .. } | Outcome::Restarted)
            && !matches!(m.obs, Observation::Height { .. } | Observation::Climb { .. })
            && self.state.imm.is_some()
        {
            self.state.t_h = m.t;
        }
        self.state.t = m.t;
        outcome
    }

    /// Where the track was at its newest horizontal update, without the
    /// covariance: what a scan over every track needs, at a fraction of an
    /// estimate's cost.
    pub fn kinematics(&self) -> Option<Kinematics> {
        let (plane, imm) = (self.state.plane?, self.state.imm.as_ref()?);
        let x = imm.mean();
        if !x.iter().all(|v| v.is_finite()) {
            return None;
        }
        let t = self.state.t_h;
        let (lat, lon, _, v) = at_aircraft(&plane, &x);
        let vertical = self.state.vertical.map(|v| (v.x[0] + v.x[1] * (t - self.state.t_v), v.x[1]));
        Some(Kinematics {
            t,
            lat,
            lon,
            alt_m: vertical.map(|h| h.0),
            vel_enu: [v[0], v[1], vertical.map_or(0.0, |h| h.1)],
        })
    }

    /// The estimate at `t`: the state after every measurement up to `t`,
    /// predicted to `t`. `None` before the first position, for a time older
    /// than the history, or when the state is not healthy (never published).
    pub fn estimate_at(&self, t: f64) -> Option<Estimate> {
        let replayed;
        let state = if t >= self.state.t {
            &self.state
        } else {
            let i = self.history.partition_point(|(h, _)| h.t <= t);
            if i == 0 {
                return None;
            }
            match self.history.get(i) {
                Some((_, Some(before))) => before,
                Some((_, None)) => {
                    replayed = self.replayed(i);
                    &replayed
                }
                None => &self.state,
            }
        };
        let (plane, imm) = (state.plane?, state.imm.as_ref()?);
        let g = imm.predicted(t - state.t_h);
        if !g.healthy() {
            return None;
        }
        let vertical = state.vertical.map(|mut v| {
            v.predict(t - state.t_v, self.cfg.vertical_q);
            v
        });
        Some(Estimate::new(t, plane, g, vertical.map(|v| v.x[0]), vertical.map_or(0.0, |v| v.x[1])))
    }
}

#[cfg(test)]
#[path = "track_tests.rs"]
mod tests;
