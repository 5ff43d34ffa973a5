//! One receiver as multilateration knows it: where it is (declared,
//! surveyed), its clock and its learnt timing, its sync partner, its time
//! jumps and how often its offset is taught; and what follows from those
//! for one of its copies (weight, variance, the offset's lasting error).

use super::*;

pub(super) struct Rx {
    /// Its configured id, for the log.
    pub(super) id: String,
    pub(super) ecef: [f64; 3],
    pub(super) clock: ClockKind,
    /// Configured jitter (s): the prior for the learnt noise.
    pub(super) sigma_t: f64,
    pub(super) beast_epoch: Option<u64>,
    /// Last (local time, arrival time) seen, to notice clock jumps.
    pub(super) last_seen: Option<(f64, f64)>,
    pub(super) timing: TimingModel,
    /// Its timing given by the configuration: not learnt.
    pub(super) timing_known: bool,
    /// Found misplaced by its survey (without `self_survey`): out of fixes.
    pub(super) misplaced: bool,
    /// Where the traffic says its antenna is, and its east-north-up frame.
    pub(super) survey: Survey,
    pub(super) enu: [[f64; 3]; 3],
    /// Its declared position (geodetic and ECEF; `ecef` is the one in use),
    /// and the surveyed offset in use instead (east, north m), if any.
    pub(super) declared: (f64, f64, f64),
    pub(super) declared_ecef: [f64; 3],
    pub(super) surveyed: Option<[f64; 2]>,
    /// The surveyed position's uncertainty as a timing variance (s^2): its
    /// horizontal variance per axis, and the distance to the survey's
    /// latest estimate, which it follows only once that moves beyond it.
    pub(super) surveyed_var_s2: f64,
    /// The GPS-timed receiver its clock is best synchronised with, and when
    /// that was last chosen (arrival time).
    pub(super) gps_partner: Option<(usize, f64)>,
    /// Recent share of its copies whose time jumped (a counter that
    /// restarted, a GPS time off by whole seconds from the others').
    pub(super) jumps: f64,
    /// When its offset last learnt from a fix (server time), and the mean
    /// time between its lessons: how long an error of its offset lasts.
    pub(super) offset_learnt_t: Option<f64>,
    pub(super) lesson_interval_s: f64,
}

impl Rx {
    /// Timing sigma (s) to weight this receiver with: its learnt core
    /// (which starts from the configured jitter), never better than a third
    /// of the configured one. The floor is the weights' only: below it, a
    /// receiver learnt a little low would be weighted more, its residuals
    /// would shrink faster than its leverage says, and it would be learnt
    /// lower still. The fixes' covariances take the learnt core
    /// ([`Mlat::believed_var`], `solver::sandwich`).
    pub(super) fn sigma(&self) -> f64 {
        self.timing.sigma().max(self.sigma_t / 3.0)
    }

    pub(super) fn bias(&self) -> f64 {
        self.timing.offset()
    }

    /// The variance (s^2) of one of its copies on the network's time, its
    /// timing taken as `sigma` (s): that, its surveyed position's doubt,
    /// and the clock synchronisation's `sync_var_s2`.
    pub(super) fn copy_var(&self, sigma: f64, sync_var_s2: f64) -> f64 {
        sigma * sigma + self.surveyed_var_s2 + sync_var_s2
    }

    /// Its learnt offset's error at `now`: the variance (s^2) and how long
    /// (s) that error lasts, from now on, before its lessons replace it (a
    /// receiver no fix has taught for a while keeps its error that much
    /// longer). None when its timing is given.
    pub(super) fn offset_error(&self, now: f64) -> Option<(f64, f64)> {
        if self.timing_known {
            return None;
        }
        let idle = self.offset_learnt_t.map_or(f64::INFINITY, |t| (now - t).max(0.0));
        let lasts = self.lesson_interval_s * TimingModel::OFFSET_MEMORY + idle;
        Some((self.timing.offset_var(), lasts))
    }

    /// A lesson taught at `now`.
    pub(super) fn lesson_at(&mut self, now: f64) {
        /// Weight of each interval in the mean interval between lessons.
        const WEIGHT: f64 = 0.05;
        if let Some(t) = self.offset_learnt_t {
            self.lesson_interval_s += WEIGHT * ((now - t).max(0.0) - self.lesson_interval_s);
        }
        self.offset_learnt_t = Some(now);
    }
}
