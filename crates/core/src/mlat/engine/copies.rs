//! A group's copies made ready for a fix: each receiver's timestamp on its
//! local time base (GPS seconds of the day unwrapped, a counter's restarts
//! caught), the copies that cannot be used left out (unknown receiver, no
//! timing, a GPS time off by seconds, a receiver out of fixes), and the
//! rest turned into the solver's measurements on the network's time.
//!
//! Apart from the per-group path in `engine.rs` because this is the one
//! place that knows receivers' clock formats.

use super::*;

impl Mlat {
    /// A receiver's timestamp in its local seconds (small numbers, full
    /// precision), referred to the start of the frame's preamble.
    pub(super) fn local_time(&mut self, rx: usize, ts: u64, arrival: f64) -> f64 {
        let refer = match self.rxs[rx].clock {
            ClockKind::Beast12 => self.cfg.timestamp_offset_beast12_ns,
            ClockKind::Gps => self.cfg.timestamp_offset_gps_ns,
        } * 1e-9;
        self.raw_local_time(rx, ts, arrival) - refer
    }

    pub(super) fn raw_local_time(&mut self, rx: usize, ts: u64, arrival: f64) -> f64 {
        match self.rxs[rx].clock {
            ClockKind::Gps => {
                let sod_ns = (ts >> 30) as i64 * 1_000_000_000 + (ts & 0x3FFF_FFFF) as i64;
                let day = (arrival / 86_400.0).floor() as i64;
                let mut ns = day * 86_400_000_000_000 + sod_ns;
                let arr_ns = (arrival * 1e9) as i64;
                if ns - arr_ns > 43_200_000_000_000 {
                    ns -= 86_400_000_000_000;
                } else if arr_ns - ns > 43_200_000_000_000 {
                    ns += 86_400_000_000_000;
                }
                let epoch = *self.gps_epoch_ns.get_or_insert(day * 86_400_000_000_000);
                (ns - epoch) as f64 * 1e-9
            }
            ClockKind::Beast12 => {
                let shared = self.shared.is_some();
                let epoch_of = |ts: u64| if shared { shared_epoch(ts) } else { ts };
                let epoch = *self.rxs[rx].beast_epoch.get_or_insert_with(|| epoch_of(ts));
                let local = (ts as i64 - epoch as i64) as f64 / 12e6;
                // A counter that moved seconds more or less than the server's
                // clock restarted (or jumped): new epoch, its pairs start again.
                if let Some((l0, a0)) = self.rxs[rx].last_seen {
                    if ((local - l0) - (arrival - a0)).abs() > CLOCK_JUMP_S {
                        self.sync.reset_receiver(rx);
                        self.note_sync(SyncNote::ResetReceiver { now: arrival, rx: rx as u32 });
                        let epoch = epoch_of(ts);
                        let local = (ts - epoch) as f64 / 12e6;
                        self.rxs[rx].beast_epoch = Some(epoch);
                        self.rxs[rx].last_seen = Some((local, arrival));
                        // A receiver whose clock jumps all the time must not
                        // flood the log: its first jumps, then each power of
                        // two (all of them in the metric).
                        let n = self.sync.health[rx].clock_resets;
                        if n.is_power_of_two() {
                            tracing::info!(receiver = %self.rxs[rx].id, jumps = n, "clock jump: receiver restarted");
                        }
                        return local;
                    }
                }
                self.rxs[rx].last_seen = Some((local, arrival));
                local
            }
        }
    }

    /// A group's usable copies on their receivers' local time, with their
    /// arrivals: known receiver, timing, no GPS time off by seconds.
    // Inlined: its result, inline vectors, would otherwise be copied out.
    #[inline(always)]
    pub(super) fn usable_copies(&mut self, g: &Group) -> (GroupVec<LocalCopy>, GroupVec<f64>) {
        // Usable copies: known receiver, timing. An excluded receiver's are
        // read (its clock jumps seen) and synchronise it, so that it comes
        // back once its sync holds; they stay out of the fix.
        let mut copies: GroupVec<LocalCopy> = GroupVec::new();
        let mut arrivals: GroupVec<f64> = GroupVec::new();
        for c in &g.copies {
            if c.rx >= self.rxs.len() {
                self.stats.unknown_receiver += 1;
                continue;
            }
            if !crate::feed::has_timing(c.timestamp) {
                self.stats.no_timing += 1;
                continue;
            }
            let resets = self.sync.health[c.rx].clock_resets;
            let t = self.local_time(c.rx, c.timestamp, c.arrival);
            // A counter's jump is its restart; a GPS time's is judged
            // against the others' (below).
            if self.rxs[c.rx].clock == ClockKind::Beast12 {
                let jumped = self.sync.health[c.rx].clock_resets != resets;
                self.note_jump(c.rx, jumped);
            }
            copies.push(LocalCopy { rx: c.rx, t });
            arrivals.push(c.arrival);
        }
        self.drop_gps_time_jumps(&mut copies, &mut arrivals);
        (copies, arrivals)
    }

    /// The copies' synchronised times as the solver's measurements, one per
    /// site, with the sync variances the fix's report and calibration need.
    // Inlined: its result, inline vectors, would otherwise be copied out.
    #[inline(always)]
    pub(super) fn measurements(
        &mut self,
        copies: &[LocalCopy],
        times: &[Option<(f64, f64)>],
        addr: u32,
    ) -> Measured {
        // One measurement per site: receivers closer than the minimum
        // separation add no geometry, so their times are averaged (inverse
        // variance) into one measurement with a smaller sigma.
        let mut ms: GroupVec<Measurement> = GroupVec::new();
        let mut sites: GroupVec<Site> = GroupVec::new();
        // Each measurement's clock synchronisation variance (s^2): not the receiver's own.
        let mut sync_vars: GroupVec<f64> = GroupVec::new();
        let (mut sync_var, mut self_var, mut all_var) = (0.0, 0.0, 0.0);
        for (c, t) in copies.iter().zip(times) {
            let Some((t, var)) = t else { continue };
            sync_var += var;
            self_var += var * self.sync.references[c.rx].share_of(addr);
            all_var += var + self.rxs[c.rx].sigma().powi(2);
            let rx = &self.rxs[c.rx];
            // A GPS receiver's offset came off in the common time base.
            let offset = if rx.clock == ClockKind::Gps { 0.0 } else { rx.bias() };
            let m =
                Measurement { pos: rx.ecef, t: *t - offset, sigma_t: rx.copy_var(rx.sigma(), *var).sqrt() };
            match ms.iter().position(|o| ecef_distance(o.pos, m.pos) < self.cfg.min_separation_m) {
                Some(k) => {
                    self.stats.close_receivers += 1;
                    let (w1, w2) = (1.0 / ms[k].sigma_t.powi(2), 1.0 / m.sigma_t.powi(2));
                    ms[k].t = (ms[k].t * w1 + m.t * w2) / (w1 + w2);
                    ms[k].sigma_t = (1.0 / (w1 + w2)).sqrt();
                    sync_vars[k] = sync_vars[k].min(*var);
                    sites[k].push(c.rx);
                }
                None => {
                    ms.push(m);
                    sites.push(smallvec::smallvec![c.rx]);
                    sync_vars.push(*var);
                }
            }
        }
        Measured {
            g: robust::GroupCopies { ms, sites, sync_vars, dropped: Dropped::new() },
            sync_var,
            self_var,
            all_var,
        }
    }

    /// The variance (s^2) measurement `k` of `g` is believed to have where
    /// its weight says otherwise: a lone receiver weighted at its floor
    /// rather than at its learnt core (see `Rx::sigma`).
    pub(super) fn believed_var(&self, g: &robust::GroupCopies, k: usize) -> Option<f64> {
        let [rx] = g.sites[k][..] else { return None };
        let r = &self.rxs[rx];
        let learnt = r.timing.sigma();
        (learnt < r.sigma()).then(|| r.copy_var(learnt, g.sync_vars[k]))
    }

    pub(super) fn note_jump(&mut self, rx: usize, jumped: bool) {
        let r = &mut self.rxs[rx];
        r.jumps += JUMP_MEMORY * (jumped as u8 as f64 - r.jumps);
    }

    /// GPS-timed copies of one transmission agree to milliseconds (the
    /// time light takes across any network): one off by more is a GPS time
    /// that jumped (by whole seconds, typically), and would fail the fix,
    /// the clock pairs and every GPS receiver's survey with it. Among three
    /// or more the majority tells which; of two, the one that jumps more
    /// often, or both when neither does.
    pub(super) fn drop_gps_time_jumps(
        &mut self,
        copies: &mut GroupVec<LocalCopy>,
        arrivals: &mut GroupVec<f64>,
    ) {
        let gps: GroupVec<usize> =
            (0..copies.len()).filter(|&k| self.rxs[copies[k].rx].clock == ClockKind::Gps).collect();
        if gps.len() < 2 {
            return;
        }
        // Nearly always they agree, and no median is needed to say so.
        let (lo, hi) = (gps.iter()).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &k| {
            (lo.min(copies[k].t), hi.max(copies[k].t))
        });
        if hi - lo <= GPS_AGREE_S {
            for &k in &gps {
                self.note_jump(copies[k].rx, false);
            }
            return;
        }
        let mut times: GroupVec<f64> = gps.iter().map(|&k| copies[k].t).collect();
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        let mut off: GroupVec<usize> =
            gps.iter().copied().filter(|&k| (copies[k].t - median).abs() > GPS_AGREE_S).collect();
        if gps.len() == 2 && !off.is_empty() {
            let (a, b) = (gps[0], gps[1]);
            let (ja, jb) = (self.rxs[copies[a].rx].jumps, self.rxs[copies[b].rx].jumps);
            off = if ja > jb {
                smallvec::smallvec![a]
            } else if jb > ja {
                smallvec::smallvec![b]
            } else {
                smallvec::smallvec![a, b]
            };
        }
        for &k in &gps {
            self.note_jump(copies[k].rx, off.contains(&k));
        }
        self.stats.time_jumps += off.len() as u64;
        for &k in off.iter().rev() {
            copies.remove(k);
            arrivals.remove(k);
        }
    }

    /// A receiver whose copies stay out of fixes: excluded by its sync's
    /// health, found misplaced, or its time jumping.
    pub(super) fn out_of_fixes(&self, rx: usize) -> bool {
        self.sync.health[rx].excluded || self.rxs[rx].misplaced || self.rxs[rx].jumps > JUMPS_EXCLUDE
    }
}
