//! The engine in a cluster ([`crate::cluster`]): the clock synchronisation
//! and the receivers' timing models are learnt once, by the clock service,
//! from every worker's notes; an engine in shared mode notes what it would
//! have applied and takes the service's snapshots. Also the parts of a
//! configuration both sides derive alike (pair parameters, timing priors).

use super::*;

/// A receiver's timing model before anything is learnt: its clock kind's configured jitter.
pub fn timing_prior(cfg: &MlatConfig, clock: ClockKind) -> TimingModel {
    TimingModel::prior(jitter_ns(cfg, clock) * 1e-9)
}

pub(super) fn jitter_ns(cfg: &MlatConfig, clock: ClockKind) -> f64 {
    match clock {
        ClockKind::Beast12 => cfg.jitter_beast12_ns,
        ClockKind::Gps => cfg.jitter_gps_ns,
    }
}

/// The clock pairs' parameters a configuration gives (also the cluster's clock service's).
pub fn pair_params(cfg: &MlatConfig) -> PairParams {
    PairParams {
        q_phase: (cfg.clock_phase_noise_ns * 1e-9).powi(2),
        q_drift: (cfg.clock_drift_walk_ppb * 1e-9).powi(2),
        ..PairParams::default()
    }
}

impl TimingModels for Vec<Rx> {
    fn model(&mut self, rx: usize) -> &mut TimingModel {
        &mut self[rx].timing
    }
}

impl Mlat {
    /// Clock synchronisation done elsewhere, once for a cluster
    /// ([`super::shared`]): this engine notes its sync transmissions and
    /// clock resets instead of applying them, and uses the snapshots given
    /// to [`load_sync`](Self::load_sync).
    pub fn share_sync(&mut self) {
        self.shared = Some(Vec::new());
    }

    /// The notes made since the last call (empty on a single node).
    pub fn take_sync_notes(&mut self) -> Vec<SyncNote> {
        self.shared.as_mut().map(std::mem::take).unwrap_or_default()
    }

    /// The clock service's state, in place of this engine's own: the clock
    /// pairs, the receivers' timing models (but those the configuration
    /// gives) and their position surveys, each receiver then placed as its
    /// survey says (left out if misplaced, or moved with `self_survey`), as
    /// every other worker places it.
    pub fn load_sync(&mut self, snapshot: &SyncSnapshot) {
        self.sync.load_snapshot(snapshot);
        for (rx, model) in snapshot.timing.iter().enumerate().take(self.rxs.len()) {
            if !self.rxs[rx].timing_known {
                self.rxs[rx].timing = *model;
                self.sync.set_gps_bias(rx, self.rxs[rx].bias());
            }
        }
        for (rx, survey) in snapshot.surveys.iter().enumerate().take(self.rxs.len()) {
            let Some(survey) = Survey::from_snapshot(survey) else { continue };
            if survey != self.rxs[rx].survey {
                self.rxs[rx].survey = survey;
                self.place(rx, snapshot.t);
            }
        }
    }

    pub(super) fn note_sync(&mut self, note: SyncNote) {
        if let Some(notes) = &mut self.shared {
            notes.push(note);
        }
    }

    /// A fix's lessons for the receivers' timing, for the clock service.
    pub(super) fn note_timing(&mut self, now: f64, res: &[Residual], anchored: bool) {
        self.note_sync(SyncNote::Timing { now, residuals: res.to_vec(), anchored });
    }
}
