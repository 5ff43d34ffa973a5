//! The engine's counters: groups, fixes, and every group left without a
//! fix by its reason.

use crate::mlat::solver::Reject;

#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MlatStats {
    pub groups: u64,
    pub too_few_receivers: u64,
    pub unknown_receiver: u64,
    pub no_timing: u64,
    pub excluded_receiver_copies: u64,
    pub close_receivers: u64,
    pub sync_messages: u64,
    /// ADS-B aircraft groups not multilaterated (interval not yet elapsed).
    pub adsb_skipped: u64,
    /// Copies dropped as outliers so the rest of a transmission could be fixed.
    pub outliers_dropped: u64,
    /// Fixes solved again because a copy the outlier search left out was
    /// early at its fix (the search had been misled; see `solve_robust`).
    pub refixed: u64,
    /// GPS-timed copies whose time disagreed with the others' by more than
    /// light takes (see `drop_gps_time_jumps`).
    pub time_jumps: u64,
    /// Copies left out of the receivers' position surveys, their emission
    /// times too far from the others' to be any receiver's fault (see
    /// `survey_from`).
    pub survey_gross: u64,
    /// Aircraft currently not trusted as sync sources, and the positions refused.
    pub sync_banned_aircraft: u64,
    pub sync_refused: u64,
    pub fixes: u64,
    /// Fixes whose clock synchronisation came mostly (over half) from
    /// their own aircraft's ADS-B: a network short of other references.
    pub self_synced_fixes: u64,
    pub unverified_address: u64,
    pub rejects: RejectCounts,
}

/// Groups that gave no fix, counted per reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RejectCounts([u64; Reject::ALL.len()]);

impl RejectCounts {
    pub fn get(&self, why: Reject) -> u64 {
        self.0[why.index()]
    }

    pub(super) fn add(&mut self, why: Reject) {
        self.0[why.index()] += 1;
    }

    /// Every reason with its count, zeros included.
    pub fn iter(&self) -> impl Iterator<Item = (Reject, u64)> + '_ {
        Reject::ALL.iter().map(|&why| (why, self.get(why)))
    }
}
