//! An ADS-B transmission as a clock synchronisation source: its copies'
//! time differences against the ranges from its reported position, given
//! to the pair filters (or, in a cluster, noted for the clock role), and
//! the aircraft judged by how well its positions agree with the timing, so
//! that a spoofer or a broken transponder stops being a source.

use super::*;

impl Mlat {
    /// Aircraft health: the mean clipped normalised innovation of a
    /// source's sync measurements against converged pairs is about 1 for an
    /// honest aircraft, a little more where receivers have multipath; a
    /// position offset biases most of its pairs and drives it up. Past the
    /// threshold the aircraft is no longer a sync source (for good: a
    /// spoofer does not become honest).
    pub(super) fn judge_sync_source(&mut self, addr: u32, nis_sum: f64, judged: u32) {
        if judged == 0 {
            return;
        }
        let a = self.aircraft.entry(addr).or_default();
        let mean = nis_sum / judged as f64;
        a.sync_uses += 1;
        a.sync_nis += (mean - a.sync_nis) / (a.sync_uses.min(20) as f64);
        if !a.sync_banned && a.sync_uses >= 10 && a.sync_nis > SYNC_SOURCE_MAX_NIS {
            a.sync_banned = true;
            self.stats.sync_banned_aircraft += 1;
            tracing::warn!(
                aircraft = format!("{addr:06X}"),
                "ADS-B positions disagree with the timing: not used for sync"
            );
        }
    }

    /// Recent mean normalised innovation of an aircraft's sync measurements.
    pub fn sync_nis(&self, addr: u32) -> Option<f64> {
        self.aircraft.get(&addr).filter(|a| a.sync_uses > 0).map(|a| a.sync_nis)
    }

    /// Whether an aircraft's ADS-B positions are refused as sync sources.
    pub fn sync_banned(&self, addr: u32) -> bool {
        self.aircraft.get(&addr).is_some_and(|a| a.sync_banned)
    }

    pub(super) fn sync_from(
        &mut self,
        copies: &[LocalCopy],
        p: [f64; 3],
        addr: u32,
        sigma_pos: f64,
        now: f64,
    ) -> (f64, u32) {
        self.stats.sync_messages += 1;
        let n = copies.len();
        // On the stack: a sync message's dozen heap lists cost as much as
        // its clock filters' updates.
        let ranges: GroupVec<f64> = copies.iter().map(|c| ecef_distance(self.rxs[c.rx].ecef, p)).collect();
        let var: GroupVec<f64> = copies.iter().map(|c| self.rxs[c.rx].sigma().powi(2)).collect();
        // The emitter's position error moves the two ranges differently: by
        // the difference of the unit vectors towards the receivers.
        let units: GroupVec<[f64; 3]> = copies
            .iter()
            .zip(&ranges)
            .map(|(c, r)| {
                let e = self.rxs[c.rx].ecef;
                [(e[0] - p[0]) / r, (e[1] - p[1]) / r, (e[2] - p[2]) / r]
            })
            .collect();
        // Only the pairs `observe` reads (a before b).
        let mut geom: smallvec::SmallVec<[f64; 64]> = smallvec::smallvec![0.0; n * n];
        for a in 0..n {
            for b in a + 1..n {
                let d2: f64 = (0..3).map(|k| (units[a][k] - units[b][k]).powi(2)).sum();
                geom[a * n + b] = sigma_pos * sigma_pos * d2 / (C_AIR * C_AIR);
            }
        }
        match &mut self.shared {
            None => {
                let judged = self.sync.observe(copies, &ranges, &var, &geom, now);
                self.sync.note_reference(copies, addr);
                judged
            }
            Some(notes) => {
                notes.push(SyncNote::Observed {
                    now,
                    addr,
                    copies: copies.iter().map(|c| (c.rx as u32, c.t)).collect(),
                    ranges: ranges.to_vec(),
                    var: var.to_vec(),
                    geom: geom.to_vec(),
                });
                self.sync.judge(copies, &ranges, &var, &geom)
            }
        }
    }
}
