//! The conflict monitor: which pairs are in conflict now, with hysteresis,
//! and the alerts that say when that changes.
//!
//! Apart from the fuser so that a cluster's publisher, which sees every
//! partition's tracks but keeps no filters, runs the same alerts as one node
//! ([`crate::cluster`]); the fuser gives it its tracks' kinematics, the
//! publisher the published tracks'.

use super::conflict::{self, Conflict, ConflictConfig, Kinematics};
use super::records::Alert;
use crate::FastMap;

/// An active conflict's alert stays up to this many times the predicted miss
/// distance that raised it.
pub const HOLD_MISS_FACTOR: f64 = 1.25;

#[derive(Default)]
pub struct ConflictMonitor {
    next: f64,
    /// Active conflicts: the latest assessment and when the pair last met the test.
    active: FastMap<(u32, u32), (Conflict, f64)>,
}

impl ConflictMonitor {
    pub fn new() -> Self {
        ConflictMonitor { next: f64::NEG_INFINITY, active: FastMap::default() }
    }

    /// Whether an assessment is due at `now` (every `interval_s`); if so,
    /// the next one is scheduled.
    /// When the next assessment falls due (`None` when conflicts are off).
    pub fn next_due(&self, cfg: &ConflictConfig) -> Option<f64> {
        cfg.enabled.then_some(self.next)
    }

    pub fn due(&mut self, cfg: &ConflictConfig, now: f64) -> bool {
        if !cfg.enabled || now < self.next {
            return false;
        }
        self.next = now + cfg.interval_s;
        true
    }

    /// Assesses the pairs among `kin` at `now`; an alert for each pair that
    /// became or stopped being a conflict (raised first, then by address).
    /// `id` gives an address's track number. Returns how many were raised.
    pub fn assess(
        &mut self,
        cfg: &ConflictConfig,
        now: f64,
        kin: &[Kinematics],
        id: impl Fn(u32) -> u64,
        out: &mut Vec<Alert>,
    ) -> u64 {
        // An active pair keeps its alert up to a predicted miss a quarter
        // larger than the one that raises it, and until it has failed the
        // test for `clear_after_s`: pairs passing about the limit apart
        // raised and cleared alerts every few seconds.
        let raise_m = cfg.max_miss_nm * conflict::NM;
        let relaxed = ConflictConfig { max_miss_nm: cfg.max_miss_nm * HOLD_MISS_FACTOR, ..cfg.clone() };
        let mut found: FastMap<(u32, u32), (Conflict, f64)> = conflict::find(&relaxed, kin)
            .into_iter()
            .map(|c| ((c.a.min(c.b), c.a.max(c.b)), (c, now)))
            .filter(|(k, (c, _))| c.miss_m < raise_m || self.active.contains_key(k))
            .collect();
        for (k, &(c, met)) in &self.active {
            if !found.contains_key(k) && now - met < cfg.clear_after_s {
                found.insert(*k, (c, met));
            }
        }
        let mut changes: Vec<(bool, Conflict)> = found
            .iter()
            .filter(|(k, _)| !self.active.contains_key(k))
            .map(|(_, (c, _))| (true, *c))
            .chain(self.active.iter().filter(|(k, _)| !found.contains_key(k)).map(|(_, (c, _))| (false, *c)))
            .collect();
        changes.sort_by_key(|(active, c)| (!active, c.a.min(c.b), c.a.max(c.b)));
        let mut raised = 0;
        for (active, c) in changes {
            raised += active as u64;
            out.push(Alert::Conflict {
                t: now,
                pair: [(c.a, id(c.a)), (c.b, id(c.b))],
                active,
                tau_s: c.tau_s,
                t_cpa_s: c.t_cpa_s,
                miss_m: c.miss_m,
                dz_m: c.dz_m,
            });
        }
        self.active = found;
        raised
    }

    /// The addresses in an active conflict.
    pub fn involved(&self) -> impl Iterator<Item = u32> + '_ {
        self.active.keys().flat_map(|&(a, b)| [a, b])
    }
}
