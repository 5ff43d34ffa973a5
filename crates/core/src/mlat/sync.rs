//! Clock synchronisation across the network: one [`PairFilter`] per receiver
//! pair that hears the same ADS-B positions, receiver health from how often
//! their measurements are outliers, and, per transmission, a common time base
//! built over a minimum spanning tree of the pairs weighted by their variance.
//!
//! GPS-timed receivers share one clock already (offset 0, no filter needed);
//! a free-running receiver joins the tree through its pair filters.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use super::clock::{PairFilter, PairParams, Update};
use super::solver::C_AIR;
use crate::feed::capture::ClockKind;

/// Per-transmission working lists, on the stack for any usual group (a
/// transmission is heard by a handful of receivers; a larger group spills
/// to the heap): their allocations were a tenth of a group's cost.
pub type GroupVec<T> = smallvec::SmallVec<[T; 16]>;

/// One receiver's copy, in its own local seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalCopy {
    pub rx: usize,
    pub t: f64,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RxHealth {
    pub sync_updates: u64,
    pub sync_outliers: u64,
    /// Exponential mean of the outlier indicator over recent sync updates.
    pub outlier_rate: f64,
    pub excluded: bool,
    pub exclusions: u64,
    /// When it was last excluded (server time).
    pub excluded_at: f64,
    /// Clock jumps seen in the receiver's own timestamps (restarts).
    pub clock_resets: u64,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SyncStats {
    pub updates: u64,
    pub outliers: u64,
    pub restarts: u64,
}

/// Multiplicative hashing for the pair table's integer keys: SipHash's
/// flooding resistance buys nothing for receiver indices and costs a lot here.
#[derive(Default)]
pub struct PairHasher(u64);

impl Hasher for PairHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_usize(&mut self, v: usize) {
        self.0 = (self.0.rotate_left(29) ^ v as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

/// One pair's measurement from a sync transmission: receivers `i < j`,
/// the clock difference `z` (s) with its variance `r` (s^2), at `tau` on i's clock.
struct PairMeasurement {
    i: usize,
    j: usize,
    z: f64,
    r: f64,
    tau: f64,
}

pub(crate) type PairMap = HashMap<(usize, usize), PairFilter, BuildHasherDefault<PairHasher>>;

/// The aircraft a counter-timed receiver's clock was lately synchronised on
/// most, with their shares of its recent sync transmissions (exponential
/// forgetting; two slots, a newcomer taking the smaller). A fix of such an
/// aircraft inherits the errors of its own ADS-B positions through the
/// clocks: not independent of its ADS-B, as a fix synchronised on other
/// aircraft is.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Reference {
    slots: [(u32, f64); 2],
    /// Sync transmissions noted, up to the memory: a plain mean over the
    /// first ones, so a receiver that only ever heard one aircraft knows it
    /// from the start.
    seen: u32,
}

/// Memory in sync transmissions: about the span a pair filter's estimate
/// rests on.
const REFERENCE_MEMORY: u32 = 20;
/// A pair's normalised innovation counts at most this much (3 sigma) when
/// an emitter is judged. A late copy (multipath) makes one pair's far
/// larger, and unclipped, the few pairs of an honest aircraft heard by
/// receivers with multipath outweighed all its consistent ones; clipped,
/// what is judged is the share of pairs that disagree, which a wrong
/// position makes large and a receiver's bad moments do not.
pub(crate) const JUDGE_NIS_CLIP: f64 = 9.0;

impl Reference {
    fn note(&mut self, addr: u32) {
        self.seen = (self.seen + 1).min(REFERENCE_MEMORY);
        let step = 1.0 / self.seen as f64;
        let mut found = false;
        for (a, share) in &mut self.slots {
            if *a == addr && *share > 0.0 {
                *share += step * (1.0 - *share);
                found = true;
            } else {
                *share *= 1.0 - step;
            }
        }
        if !found {
            let k = if self.slots[0].1 <= self.slots[1].1 { 0 } else { 1 };
            self.slots[k] = (addr, step);
        }
    }

    /// The share of the receiver's recent sync that came from `addr`.
    pub fn share_of(&self, addr: u32) -> f64 {
        self.slots.iter().filter(|(a, share)| *a == addr && *share > 0.0).map(|s| s.1).sum()
    }
}

pub struct ClockSync {
    pub params: PairParams,
    pub(crate) pairs: PairMap,
    pub(crate) clocks: Vec<ClockKind>,
    /// Per receiver, the GPS-timed receivers it has a pair filter with, in
    /// index order: what `gps_peers` answers without asking every receiver.
    pub(crate) gps_peers: Vec<Vec<usize>>,
    pub health: Vec<RxHealth>,
    /// The receivers' ids, for the log.
    ids: Vec<String>,
    pub references: Vec<Reference>,
    /// Each GPS-timed receiver's learnt offset against the network (s; zero
    /// for counters): pair filters relate a counter to a GPS receiver's own
    /// clock, bias and all, so converting through one GPS receiver or
    /// another must take their biases' difference into account.
    pub(crate) gps_bias: Vec<f64>,
    pub stats: SyncStats,
}

/// Above this recent outlier rate a receiver is excluded; below the second it is readmitted.
const EXCLUDE_RATE: f64 = 0.3;
const READMIT_RATE: f64 = 0.1;
pub(crate) const HEALTH_MIN_UPDATES: u64 = 30;
/// The shortest exclusion (s), doubled with each exclusion up to the
/// longest: a receiver whose sync fails now and then must not flap in and
/// out of the fixes, and one that keeps failing stays out longer each time,
/// yet never for good.
const MIN_EXCLUSION_S: f64 = 60.0;
const MAX_EXCLUSION_S: f64 = 3600.0;

impl ClockSync {
    pub fn new(params: PairParams) -> Self {
        ClockSync {
            params,
            pairs: PairMap::default(),
            clocks: Vec::new(),
            gps_peers: Vec::new(),
            health: Vec::new(),
            ids: Vec::new(),
            references: Vec::new(),
            gps_bias: Vec::new(),
            stats: SyncStats::default(),
        }
    }

    pub fn add_receiver(&mut self, clock: ClockKind, id: &str) {
        self.clocks.push(clock);
        self.ids.push(id.to_string());
        self.gps_peers.push(Vec::new());
        self.health.push(RxHealth::default());
        self.references.push(Reference::default());
        self.gps_bias.push(0.0);
    }

    /// Sets a GPS-timed receiver's learnt offset (s); ignored for counters,
    /// whose pairs absorb any constant.
    pub fn set_gps_bias(&mut self, rx: usize, bias_s: f64) {
        if self.clocks[rx] == ClockKind::Gps {
            self.gps_bias[rx] = bias_s;
        }
    }

    /// A receiver's learnt GPS offset (s), zero for a counter.
    pub fn gps_bias(&self, rx: usize) -> f64 {
        self.gps_bias[rx]
    }

    /// Aircraft `addr`'s ADS-B position was the reference of a sync
    /// transmission these receivers heard (GPS-timed ones need none).
    pub fn note_reference(&mut self, copies: &[LocalCopy], addr: u32) {
        for c in copies {
            if self.clocks[c.rx] != ClockKind::Gps {
                self.references[c.rx].note(addr);
            }
        }
    }

    /// The GPS-timed receivers `rx` has a pair filter with (converged or
    /// not), in index order. Dating a counter-timed receiver's reports looks
    /// for its best GPS partner among them: asking `edge` of every GPS
    /// receiver instead was 3% of a run's instructions on the scale world,
    /// where many counter-timed receivers share no aircraft with one.
    pub fn gps_peers(&self, rx: usize) -> &[usize] {
        &self.gps_peers[rx]
    }

    pub fn pairs(&self) -> impl Iterator<Item = (&(usize, usize), &PairFilter)> {
        self.pairs.iter()
    }

    /// A transmission from a known position heard by several receivers: one
    /// measurement for every pair. `ranges` are emitter-receiver distances
    /// (m), `var` each copy's timing variance plus its share of the
    /// emitter's position error (s^2), `geom_var` the pairs' shared part of
    /// the latter, row-major (`a * n + b`, read for a < b). Returns the summed normalised
    /// innovation (each capped at 100) of the pair measurements that met a
    /// converged filter, and how many those were, so the caller can judge the
    /// emitter too.
    // Over 80 lines, kept whole: each pair of a sync message's copies
    // against its filter, sharing the copies' stack arrays (per group).
    pub fn observe(
        &mut self,
        copies: &[LocalCopy],
        ranges: &[f64],
        var: &[f64],
        geom_var: &[f64],
        now: f64,
    ) -> (f64, u32) {
        let (mut nis_sum, mut judged) = (0.0, 0);
        // Per copy: its pairs that count for its health, their outliers,
        // and its partner (the last one: what a lone pair needs).
        let mut tally: GroupVec<(u32, u32, usize)> = smallvec::smallvec![(0, 0, 0); copies.len()];
        for a in 0..copies.len() {
            for b in a + 1..copies.len() {
                let Some(PairMeasurement { i, j, z, r, tau }) =
                    self.pair_measurement(copies, ranges, var, geom_var, a, b)
                else {
                    continue;
                };
                let (ca, _) = (copies[a], copies[b]);
                let params = self.params;
                // The filter's verdict read while it is at hand: a second
                // lookup per pair was a fifth of this function.
                let converged = |f: &PairFilter| (f.updates > params.min_updates * 2).then_some(f.last_nis);
                let (result, nis) = match self.pairs.get_mut(&(i, j)) {
                    Some(f) => (f.update(z, r, tau, now, &params), converged(f)),
                    None => {
                        let f = PairFilter::new(z, r, tau, now, &params);
                        let nis = converged(&f);
                        self.pairs.insert((i, j), f);
                        for (a, b) in [(i, j), (j, i)] {
                            if self.clocks[b] == ClockKind::Gps {
                                let peers = &mut self.gps_peers[a];
                                if let Err(at) = peers.binary_search(&b) {
                                    peers.insert(at, b);
                                }
                            }
                        }
                        (Update::Accepted, nis)
                    }
                };
                self.stats.updates += 1;
                match result {
                    Update::Outlier => self.stats.outliers += 1,
                    Update::Restarted => self.stats.restarts += 1,
                    Update::Accepted => {}
                }
                let outlier = result != Update::Accepted;
                // An excluded receiver still synchronises (so that it can
                // come back, and a later clock jump is seen), but its pairs
                // neither judge the emitter nor count against its partner.
                let (out_i, out_j) = (self.health[i].excluded, self.health[j].excluded);
                if let (Some(nis), false) = (nis, out_i || out_j) {
                    nis_sum += nis.min(JUDGE_NIS_CLIP);
                    judged += 1;
                }
                let (ka, kb) = if ca.rx == i { (a, b) } else { (b, a) };
                for (k, other, partner_out) in [(ka, kb, out_j), (kb, ka, out_i)] {
                    if !partner_out {
                        tally[k].0 += 1;
                        tally[k].1 += outlier as u32;
                        tally[k].2 = other;
                    }
                }
            }
        }
        // A pair that fails says one of its two is wrong, not which: the
        // one whose pairs mostly fail is. (Counted against both, a receiver
        // with multipath dragged its honest partners towards exclusion.) A
        // copy in one pair only (GPS receivers pair only with counters) is
        // judged by its partner's verdict, and half when neither can tell.
        let verdict = |k: usize| {
            let (pairs, outliers, _) = tally[k];
            (pairs >= 2).then_some(2 * outliers > pairs)
        };
        for (k, c) in copies.iter().enumerate() {
            let (pairs, outliers, partner) = tally[k];
            let share = match (pairs, verdict(k)) {
                (0, _) => continue,
                (_, Some(bad)) => bad as u8 as f64,
                _ if outliers == 0 => 0.0,
                _ => match verdict(partner) {
                    Some(true) => 0.0,
                    Some(false) => 1.0,
                    None => 0.5,
                },
            };
            self.note_health(c.rx, share, now);
        }
        (nis_sum, judged)
    }

    /// The measurement copies `a` and `b` of a sync transmission make for
    /// their pair (`None` for two GPS-timed receivers: no filter relates them).
    #[inline(always)]
    fn pair_measurement(
        &self,
        copies: &[LocalCopy],
        ranges: &[f64],
        var: &[f64],
        geom_var: &[f64],
        a: usize,
        b: usize,
    ) -> Option<PairMeasurement> {
        let (ca, cb) = (copies[a], copies[b]);
        if self.clocks[ca.rx] == ClockKind::Gps && self.clocks[cb.rx] == ClockKind::Gps {
            return None;
        }
        let (i, j, ti, tj, ri, rj) = if ca.rx < cb.rx {
            (ca.rx, cb.rx, ca.t, cb.t, ranges[a], ranges[b])
        } else {
            (cb.rx, ca.rx, cb.t, ca.t, ranges[b], ranges[a])
        };
        let z = (tj - rj / C_AIR) - (ti - ri / C_AIR);
        let r = var[a] + var[b] + geom_var[a * copies.len() + b];
        Some(PairMeasurement { i, j, z, r, tau: ti - ri / C_AIR })
    }

    /// What [`observe`](Self::observe) returns, the filters left as they
    /// are: a cluster worker judges an emitter against the clock service's
    /// filters while that service applies the measurement.
    pub fn judge(&self, copies: &[LocalCopy], ranges: &[f64], var: &[f64], geom_var: &[f64]) -> (f64, u32) {
        let (mut nis_sum, mut judged) = (0.0, 0);
        for a in 0..copies.len() {
            for b in a + 1..copies.len() {
                let Some(m) = self.pair_measurement(copies, ranges, var, geom_var, a, b) else {
                    continue;
                };
                let Some(f) = self.pairs.get(&(m.i, m.j)) else {
                    continue;
                };
                let converged = f.updates > self.params.min_updates * 2;
                if converged && !self.health[m.i].excluded && !self.health[m.j].excluded {
                    nis_sum += f.nis(m.z, m.r, m.tau, &self.params).min(JUDGE_NIS_CLIP);
                    judged += 1;
                }
            }
        }
        (nis_sum, judged)
    }

    /// A receiver's clock jumped (restart): its pairs start again, and the
    /// jump is not held against its health.
    pub fn reset_receiver(&mut self, rx: usize) {
        self.reset_pairs(rx);
        self.health[rx].clock_resets += 1;
        // Its clock is learnt again from what comes next.
        self.references[rx] = Reference::default();
    }

    /// A receiver's pairs start again (its clock jumped, or its position
    /// was corrected: what they learnt no longer holds).
    pub fn reset_pairs(&mut self, rx: usize) {
        let before = self.pairs.len();
        self.pairs.retain(|&(i, j), _| i != rx && j != rx);
        self.gps_peers[rx].clear();
        for peers in &mut self.gps_peers {
            peers.retain(|&g| g != rx);
        }
        self.stats.restarts += (before - self.pairs.len()) as u64;
    }

    /// One sync measurement of `rx`'s: its outlier rate, and its exclusion
    /// or readmission when that crosses a threshold (the rare part, apart).
    #[inline]
    fn note_health(&mut self, rx: usize, outlier: f64, now: f64) {
        let h = &mut self.health[rx];
        h.sync_updates += 1;
        h.sync_outliers += (outlier >= 0.5) as u64;
        h.outlier_rate = 0.97 * h.outlier_rate + 0.03 * outlier;
        let turns = if h.excluded { h.outlier_rate < READMIT_RATE } else { h.outlier_rate > EXCLUDE_RATE };
        if turns && h.sync_updates >= HEALTH_MIN_UPDATES {
            self.exclude_or_readmit(rx, now);
        }
    }

    #[cold]
    fn exclude_or_readmit(&mut self, rx: usize, now: f64) {
        fn exclusion_s(n: u64) -> f64 {
            (MIN_EXCLUSION_S * 2f64.powi(n.saturating_sub(1).min(16) as i32)).min(MAX_EXCLUSION_S)
        }
        let (h, id) = (&mut self.health[rx], &self.ids[rx]);
        // Logged at its first exclusions and then each power of two (every
        // one is in the metrics): a receiver in and out all day must not
        // fill the log.
        if !h.excluded {
            (h.excluded, h.excluded_at) = (true, now);
            h.exclusions += 1;
            if h.exclusions.is_power_of_two() {
                tracing::warn!(
                    receiver = %id,
                    rate = h.outlier_rate,
                    exclusions = h.exclusions,
                    "receiver excluded from MLAT: sync keeps failing (still synchronised, readmitted when it holds)"
                );
            }
        } else if now - h.excluded_at >= exclusion_s(h.exclusions) {
            h.excluded = false;
            if h.exclusions.is_power_of_two() {
                tracing::info!(receiver = %id, exclusions = h.exclusions, "receiver readmitted to MLAT");
            }
        }
    }

    /// The relation between two receivers' clocks if usable: `t_j = t_i + offset`,
    /// evaluated near `t_i`, with its variance.
    pub(crate) fn edge(&self, i: usize, j: usize, t_i: f64, now: f64) -> Option<(f64, f64)> {
        if self.clocks[i] == ClockKind::Gps && self.clocks[j] == ClockKind::Gps {
            return Some((self.gps_bias[j] - self.gps_bias[i], 0.0));
        }
        if i < j {
            let f = self.pairs.get(&(i, j)).filter(|f| f.valid(now, &self.params))?;
            Some(f.offset_at(t_i, &self.params))
        } else {
            let f = self.pairs.get(&(j, i)).filter(|f| f.valid(now, &self.params))?;
            // The filter relates t_i = t_j + offset(t_j), its time argument
            // in j's clock: solve tau = t_i - offset(tau) by fixed point from
            // the filter's current offset (a contraction by the drift, ~1e-4).
            let mut tau = t_i - f.offset();
            for _ in 0..2 {
                tau = t_i - f.offset_at(tau, &self.params).0;
            }
            let (o, v) = f.offset_at(tau, &self.params);
            Some((-o, v))
        }
    }

    /// Puts a transmission's copies on one time base: the root's clock (a GPS
    /// receiver when there is one), its learnt bias taken off, so that GPS
    /// receivers' times come out corrected and a counter's the same through
    /// whichever GPS receiver it is reached. Returns, per copy index, that
    /// time and the accumulated variance of the conversion; copies the tree
    /// cannot reach are `None`. Also returns the root's copy index.
    // Over 80 lines, kept whole: one walk of the clock tree per group (the
    // per-group path), its parts sharing the walk's stack arrays.
    pub fn common_time(&self, copies: &[LocalCopy], now: f64) -> (GroupVec<Option<(f64, f64)>>, usize) {
        let t = self.common_time_anchored(copies, now);
        (t.times, t.root)
    }

    /// [`ClockSync::common_time`], and per copy its anchor: the copy index
    /// of the GPS-timed receiver its time came through (itself for one),
    /// `None` without one. A GPS receiver's learnt bias moves every copy
    /// anchored on it, so that is what its bias must be learnt from.
    pub fn common_time_anchored(&self, copies: &[LocalCopy], now: f64) -> CommonTime {
        let n = copies.len();
        let mut out: GroupVec<Option<(f64, f64)>> = smallvec::smallvec![None; n];
        let mut anchors: GroupVec<Option<usize>> = smallvec::smallvec![None; n];
        if n == 0 {
            return CommonTime { times: out, root: 0, anchors };
        }
        // Edge weights once per pair: offset and variance, or None when the
        // pair is not usable; the reverse edge is the same relation inverted.
        // Plain loops over slices: iterator adapters and the small vectors'
        // checks on every access were two thirds of this function.
        // On the stack up to eight copies (a small vector built its inline
        // array and then moved it, a 1.5 KB copy per transmission).
        let mut w_stack = [None; 64];
        let mut w_heap = Vec::new();
        let w = if n * n <= w_stack.len() {
            &mut w_stack[..n * n]
        } else {
            w_heap.resize(n * n, None);
            &mut w_heap[..]
        };
        for a in 0..n {
            let ca = copies[a];
            for b in a + 1..n {
                if let Some((off, var)) = self.edge(ca.rx, copies[b].rx, ca.t, now) {
                    w[a * n + b] = Some((off, var));
                    w[b * n + a] = Some((-off, var));
                }
            }
        }
        let w = &*w;
        // The root: a GPS receiver if any, then the most edges, then the lowest index.
        let mut root = 0;
        let mut root_key = (false, 0);
        for a in 0..n {
            let gps = self.clocks[copies[a].rx] == ClockKind::Gps;
            let degree = w[a * n..(a + 1) * n].iter().filter(|e| e.is_some()).count();
            if a == 0 || (gps, degree) > root_key {
                (root, root_key) = (a, (gps, degree));
            }
        }
        // Prim's algorithm on variance, converting times as the tree grows:
        // each receiver outside the tree keeps its cheapest edge from it
        // (O(n^2), where rescanning every pair of tree and non-tree for each
        // addition was O(n^3)). Ties go to the lowest tree index, then the
        // lowest receiver index.
        out[root] = Some((copies[root].t, 0.0));
        let gps = |a: usize| self.clocks[copies[a].rx] == ClockKind::Gps;
        anchors[root] = gps(root).then_some(root);
        let times = &mut out[..];
        let mut in_tree_buf: GroupVec<bool> = smallvec::smallvec![false; n];
        let in_tree = &mut in_tree_buf[..];
        // (accumulated variance, tree end, offset) of each receiver's best edge.
        let mut best_buf: GroupVec<Option<(f64, usize, f64)>> = smallvec::smallvec![None; n];
        let best = &mut best_buf[..];
        let mut added = root;
        loop {
            in_tree[added] = true;
            let base = times[added].expect("in tree").1;
            let row = &w[added * n..(added + 1) * n];
            // Each outside receiver's best edge updated, and the cheapest of
            // them all found, in one pass.
            let mut next: Option<(f64, usize, usize, f64)> = None;
            for b in 0..n {
                if in_tree[b] {
                    continue;
                }
                // Edge added -> b: t_b = t_added + offset.
                if let Some((off, var)) = row[b] {
                    let acc = base + var;
                    if best[b].is_none_or(|(x, a, _)| acc < x || (acc == x && added < a)) {
                        best[b] = Some((acc, added, off));
                    }
                }
                if let Some((acc, a, off)) = best[b] {
                    if next.is_none_or(|(x, xa, _, _)| (acc, a) < (x, xa)) {
                        next = Some((acc, a, b, off));
                    }
                }
            }
            let Some((acc, a, b, off)) = next else { break };
            // b's own time, moved into a's clock, then a's conversion to the root applies.
            let (ta_root, _) = times[a].expect("in tree");
            let tb_in_a = copies[b].t - off;
            times[b] = Some((ta_root + (tb_in_a - copies[a].t), acc));
            anchors[b] = if gps(b) { Some(b) } else { anchors[a] };
            added = b;
        }
        // From the root's clock to the network's: its bias taken off.
        let root_bias = self.gps_bias[copies[root].rx];
        if root_bias != 0.0 {
            for (t, _) in out.iter_mut().flatten() {
                *t -= root_bias;
            }
        }
        CommonTime { times: out, root, anchors }
    }
}

/// A transmission's copies on one time base ([`ClockSync::common_time_anchored`]).
pub struct CommonTime {
    /// Per copy: its time and the conversion's variance, `None` if unreachable.
    pub times: GroupVec<Option<(f64, f64)>>,
    /// The root's copy index.
    pub root: usize,
    /// Per copy: the copy index of the GPS-timed receiver its time came
    /// through (itself for one), `None` without one.
    pub anchors: GroupVec<Option<usize>>,
}

#[cfg(test)]
mod tests;
