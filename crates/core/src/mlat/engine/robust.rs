//! The robust solve and what it teaches: a group's outlying copies left
//! out one at a time while the fix stays over-determined, the copies judged
//! at the fix under each receiver's timing model, and the receivers' timing
//! learnt from the judged residuals. Apart from the engine's per-group path
//! ([`Mlat::on_group`]) so that the solve reads on its own.

use super::*;

/// Whether `after` lies within `before`'s uncertainty (99.9%, 3-D).
pub(super) fn near(before: &crate::mlat::solver::Fix, after: &crate::mlat::solver::Fix) -> bool {
    let c = nalgebra::Matrix3::from_fn(|r, k| before.cov_ecef[r][k]);
    let d = nalgebra::Vector3::from_fn(|r, _| after.ecef[r] - before.ecef[r]);
    c.try_inverse().is_some_and(|inv| (d.transpose() * inv * d)[0] <= 16.27)
}

/// Copies left out of a fix as outliers: measurement, site, sync variance (s^2).
pub(super) type Dropped = GroupVec<(Measurement, Site, f64)>;

/// A fix's copies judged under their receivers' timing models: the
/// problem linearised at the fix, and each copy's verdict (none for a
/// merged site, whose time is no single receiver's).
pub(super) struct Judged {
    pub(super) at: AtFix,
    pub(super) verdicts: GroupVec<Option<Verdict>>,
}

impl Judged {
    /// From every copy's verdict under its (first) receiver's model.
    pub(super) fn new(at: AtFix, all: &[Verdict], sites: &[Site]) -> Judged {
        let verdicts = all.iter().zip(sites).map(|(v, site)| (site.len() == 1).then_some(*v)).collect();
        Judged { at, verdicts }
    }

    pub(super) fn p_late(&self, k: usize) -> f64 {
        self.verdicts[k].map_or(0.0, |v| v.p_late)
    }
}

impl Mlat {
    /// Solves, leaving out each copy that is an outlier under its
    /// receiver's timing model (late by its multipath odds, or off by more
    /// than any core explains) while the fix stays over-determined: a
    /// receiver glitch or a reflected path costs that copy, not the
    /// transmission. Which copy is the outlier is only told with two or more
    /// degrees of freedom. What remains is rejected only when it has no
    /// consistent subset (see [`Mlat::consistent`]); otherwise the solver's
    /// covariance grows with the residuals. Returns the fix, its copies
    /// judged when the last round did so at the fix, and the copies left out
    /// in `dropped` (measurement, its site, its sync variance).
    ///
    /// Copies are left out one at a time, the worst first, and a late copy
    /// of a precise receiver with high leverage can pull the fix so that
    /// honest copies look the worst and go instead: the fix then fits what
    /// is left, hundreds of metres off with a covariance of tens. Multipath
    /// only delays, so a copy left out that is early beyond any core at the
    /// fix says the search went wrong; the group is then solved again with
    /// each copy left out first in turn.
    pub(super) fn solve_robust(
        &mut self,
        g: &mut GroupCopies,
        alt: Option<AltitudeConstraint>,
        guess: Option<[f64; 3]>,
    ) -> Result<(crate::mlat::solver::Fix, Option<Judged>), Reject> {
        let counted = self.stats.outliers_dropped;
        let greedy = self.solve_greedy(g, alt, guess);
        let early = match &greedy {
            Ok((fix, _)) => early_copies(fix, &g.dropped),
            Err(_) => 0,
        };
        if early == 0 {
            return greedy;
        }
        // Every copy back, then each left out in turn before the greedy
        // solve; the alternative with fewer early copies left out, then more
        // copies kept, then the lowest chi-square per degree of freedom.
        let first = g.clone();
        let mut all: Dropped = g.dropped.drain(..).collect();
        all.extend(
            g.ms.drain(..).zip(g.sites.drain(..)).zip(g.sync_vars.drain(..)).map(|((m, s), v)| (m, s, v)),
        );
        let mut best: Option<(usize, std::cmp::Reverse<usize>, f64, usize)> = None;
        for skip in 0..all.len() {
            g.split(&all, skip);
            if let Ok((fix, _)) = self.solve_greedy(g, alt, guess) {
                let score = (
                    early_copies(&fix, &g.dropped),
                    std::cmp::Reverse(g.ms.len()),
                    fix.chi2 / fix.dof.max(1) as f64,
                    skip,
                );
                if best.is_none_or(|b| score.partial_cmp(&b).is_some_and(|o| o.is_lt())) {
                    best = Some(score);
                }
            }
        }
        self.stats.outliers_dropped = counted;
        let chosen = best.filter(|b| b.0 < early).map(|b| b.3);
        self.stats.refixed += chosen.is_some() as u64;
        // The greedy's own path when no alternative does better: its early
        // copy is then a glitch of that receiver's, as early in every fix.
        let result = match chosen {
            Some(skip) => {
                g.split(&all, skip);
                self.solve_greedy(g, alt, guess)
            }
            None => {
                *g = first;
                greedy
            }
        };
        self.stats.outliers_dropped = counted + g.dropped.len() as u64;
        result
    }

    /// The search for outliers, worst first (see [`Mlat::solve_robust`]).
    fn solve_greedy(
        &mut self,
        g: &mut GroupCopies,
        alt: Option<AltitudeConstraint>,
        guess: Option<[f64; 3]>,
    ) -> Result<(crate::mlat::solver::Fix, Option<Judged>), Reject> {
        let open = SolverLimits { chi2_reject: false, ..self.limits };
        let anchored = guess.is_some();
        let mut before: Option<crate::mlat::solver::Fix> = None;
        loop {
            let fix = match solve(&g.ms, alt, guess, &open) {
                Ok(f) => f,
                Err(why) => return before.map_or(Err(why), |b| self.undrop(g, b, anchored)),
            };
            // Without a copy the equations may have another solution that
            // fits them, far off (with one degree of freedom left, LocaRDS's
            // went tens of kilometres away): a fix that moved beyond the
            // uncertainty of the one with the copy is not the same fix.
            if let Some(b) = before.take() {
                if !near(&b, &fix) {
                    return self.undrop(g, b, anchored);
                }
            }
            if fix.dof < 3 {
                return self.consistent(fix, &g.sites, anchored).map(|f| (f, None));
            }
            let Some(at) = AtFix::new(&g.ms, alt, &fix) else {
                return self.consistent(fix, &g.sites, anchored).map(|f| (f, None));
            };
            let all = self.verdicts(&at, &g.ms, &g.sites);
            let mut worst: Option<(usize, f64)> = None;
            for (k, v) in all.iter().enumerate() {
                if v.outlier() && worst.is_none_or(|(_, s)| v.score() > s) {
                    worst = Some((k, v.score()));
                }
            }
            let Some((k, _)) = worst else {
                let judged = Judged::new(at, &all, &g.sites);
                return self.consistent(fix, &g.sites, anchored).map(|f| (f, Some(judged)));
            };
            let (m, site, var) = (g.ms.remove(k), g.sites.remove(k), g.sync_vars.remove(k));
            self.stats.outliers_dropped += 1;
            g.dropped.push((m, site, var));
            before = Some(fix);
        }
    }

    /// Each copy's odds of being late at the fix (see [`Judged`]).
    pub(super) fn judge(
        &self,
        ms: &[Measurement],
        sites: &[Site],
        alt: Option<AltitudeConstraint>,
        fix: &crate::mlat::solver::Fix,
    ) -> Option<Judged> {
        let at = AtFix::new(ms, alt, fix)?;
        let all = self.verdicts(&at, ms, sites);
        Some(Judged::new(at, &all, sites))
    }

    /// Each copy's residual at the linearised fix judged under its (first)
    /// receiver's timing model, with the variance the fix weighted it by.
    fn verdicts(&self, at: &AtFix, ms: &[Measurement], sites: &[Site]) -> GroupVec<Verdict> {
        (ms.iter().zip(sites).enumerate())
            .map(|(k, (m, site))| {
                let (r, h) = at.residual(k);
                self.rxs[site[0]].timing.judge(r, h, m.sigma_t.powi(2))
            })
            .collect()
    }

    /// The last copy left out is put back: the fix with it stands.
    fn undrop(
        &mut self,
        g: &mut GroupCopies,
        fix: crate::mlat::solver::Fix,
        anchored: bool,
    ) -> Result<(crate::mlat::solver::Fix, Option<Judged>), Reject> {
        if let Some((m, site, var)) = g.dropped.pop() {
            self.stats.outliers_dropped -= 1;
            g.ms.push(m);
            g.sites.push(site);
            g.sync_vars.push(var);
        }
        self.consistent(fix, &g.sites, anchored).map(|f| (f, None))
    }

    /// A fix whose residuals, once the outliers are out, are beyond what
    /// sigmas as large as its receivers' learnt ones could be explain (the
    /// chi-square quantile, times the doubt in the least known receiver's
    /// variance) has no consistent subset. Within it, the solver's
    /// covariance grows with the residuals, and the receivers' sigmas with
    /// what they learn from them.
    ///
    /// An aircraft's first fix (no earlier one, `anchored` false) with one
    /// degree of freedom gets no doubt: its equations may have a second
    /// solution kilometres off, which fits them about as badly as the
    /// aircraft's own does when one copy is late, and only the plain
    /// quantile tells the two apart. Taken, it became the guess the next
    /// fixes started from, so they found it too, and a track began there.
    fn consistent(
        &self,
        fix: crate::mlat::solver::Fix,
        sites: &[Site],
        anchored: bool,
    ) -> Result<crate::mlat::solver::Fix, Reject> {
        if fix.dof == 0 {
            return Ok(fix);
        }
        // The doubt is at least one: below the plain quantile, no need of it.
        let limit = crate::mlat::solver::chi2_quantile(fix.dof, self.limits.chi2_quantile);
        if fix.chi2 <= limit {
            return Ok(fix);
        }
        if !anchored && fix.dof < 2 {
            return Err(Reject::Residual);
        }
        let doubt =
            (sites.iter().flatten()).map(|&rx| self.rxs[rx].timing.variance_doubt()).fold(1.0, f64::max);
        if fix.chi2 > limit * doubt {
            return Err(Reject::Residual);
        }
        Ok(fix)
    }

    /// Self-calibration: each copy's residual teaches its receiver's timing
    /// model (see [`TimingModel::learn`]), those in the fix with their
    /// leverage and verdict at the fix (`judged`, per site), those left out
    /// against the fix of the others. A bias
    /// common to all receivers is absorbed by the emission time, so only
    /// relative offsets are learnt, which is all the solver needs.
    pub(super) fn learn(
        &mut self,
        judged: &Judged,
        fix: &crate::mlat::solver::Fix,
        g: &GroupCopies,
        anchors: &[(usize, Option<usize>)],
        now: f64,
    ) {
        let (sites, sync_vars, dropped) = (&g.sites[..], &g.sync_vars[..], &g.dropped);
        // In a cluster the lessons go to the clock service, which learns
        // once for every worker; here they are learnt as they come.
        let shared = self.shared.is_some();
        let anchored = sites.iter().any(|site| site.iter().any(|&rx| self.rxs[rx].timing_known));
        let mut res: GroupVec<Residual> = GroupVec::new();
        let mut lessons = Lessons::new(anchored);
        let shifts = self.cluster_shifts(judged, sites, anchors);
        for (k, (site, &var)) in sites.iter().zip(sync_vars).enumerate() {
            let (r, h) = judged.at.residual(k);
            // A merged site's residual is no single receiver's (nor verdict).
            let Some(v) = judged.verdicts[k] else { continue };
            let rx = site[0];
            let rx_state = &self.rxs[rx];
            if h >= 0.95 || rx_state.timing_known {
                continue;
            }
            // The verdict the fix was hedged with, unless the fix weighted
            // the receiver at its floor rather than its learnt sigma.
            let used_offset_s = rx_state.timing.offset();
            let shift_s = shifts[k];
            let lesson = if rx_state.sigma() == rx_state.timing.sigma() {
                Residual::Judged { rx: rx as u32, r, h, v, used_offset_s, shift_s }
            } else {
                Residual::Against { rx: rx as u32, r, h, var, used_offset_s, shift_s }
            };
            match shared {
                true => res.push(lesson),
                false => lessons.teach(&lesson, &mut self.rxs),
            }
        }
        for (m, site, var) in dropped {
            if site.len() > 1 || self.rxs[site[0]].timing_known {
                continue;
            }
            let r = m.t - fix.t_emit - ecef_distance(m.pos, fix.ecef) / C_AIR;
            let used_offset_s = self.rxs[site[0]].timing.offset();
            let lesson =
                Residual::Against { rx: site[0] as u32, r, h: 0.0, var: *var, used_offset_s, shift_s: 0.0 };
            match shared {
                true => res.push(lesson),
                false => lessons.teach(&lesson, &mut self.rxs),
            }
        }
        if shared {
            if !res.is_empty() {
                self.note_timing(now, &res, anchored);
            }
            return;
        }
        for rx in lessons.finish(&mut self.rxs) {
            self.rxs[rx].lesson_at(now);
            self.sync.set_gps_bias(rx, self.rxs[rx].bias());
        }
    }
}

impl Mlat {
    /// Per site, what its offset's lesson differs from its residual by
    /// (see [`Residual`]): a GPS-timed receiver learns the weighted mean
    /// residual of the sites anchored on it (its own and the counters'
    /// whose times came through it), and those counters what they differ
    /// from that mean. Only where the receiver learns from this fix and
    /// something came through it; elsewhere nothing.
    fn cluster_shifts(
        &self,
        judged: &Judged,
        sites: &[Site],
        anchors: &[(usize, Option<usize>)],
    ) -> GroupVec<f64> {
        let mut shifts: GroupVec<f64> = smallvec::smallvec![0.0; sites.len()];
        let anchor_of = |k: usize| -> Option<usize> {
            let site = &sites[k];
            let rx = *site.first()?;
            (site.len() == 1).then_some(())?;
            anchors.iter().find(|(r, _)| *r == rx).and_then(|(_, a)| *a)
        };
        let site_anchor: GroupVec<Option<usize>> = (0..sites.len()).map(anchor_of).collect();
        for (k, site) in sites.iter().enumerate() {
            // Site k is a GPS receiver that learns here: the copies anchored on it.
            let rx = site[0];
            if site_anchor[k] != Some(rx) || judged.verdicts[k].is_none() || self.rxs[rx].timing_known {
                continue;
            }
            if judged.at.residual(k).1 >= 0.95 {
                continue;
            }
            let (mut sum, mut weight, mut members) = (0.0, 0.0, 0);
            for (j, a) in site_anchor.iter().enumerate() {
                if *a != Some(rx) {
                    continue;
                }
                let Some(v) = judged.verdicts[j] else { continue };
                let w = judged.at.weight(j) * (1.0 - v.p_late);
                sum += w * judged.at.residual(j).0;
                weight += w;
                members += 1;
            }
            if members < 2 || weight <= 0.0 {
                continue;
            }
            let mean = sum / weight;
            for (j, a) in site_anchor.iter().enumerate() {
                if *a == Some(rx) {
                    shifts[j] = if j == k { mean - judged.at.residual(j).0 } else { -mean };
                }
            }
        }
        shifts
    }
}

/// Copies left out that are early at the fix beyond any core: multipath
/// only delays, so for these it is the fix that is wrong, not the copy (or
/// the copy is a glitch, early whichever fix it meets).
fn early_copies(fix: &crate::mlat::solver::Fix, dropped: &Dropped) -> usize {
    (dropped.iter())
        .filter(|(m, _, _)| {
            m.t - fix.t_emit - ecef_distance(m.pos, fix.ecef) / C_AIR
                < -crate::mlat::timing::GLITCH_Z * m.sigma_t
        })
        .count()
}

/// A group's copies as the robust solve works on them: those in the fix
/// (measurement, site, sync variance, in step) and those left out.
#[derive(Clone)]
pub(super) struct GroupCopies {
    pub ms: GroupVec<Measurement>,
    pub sites: GroupVec<Site>,
    pub sync_vars: GroupVec<f64>,
    pub dropped: Dropped,
}

impl GroupCopies {
    /// The group `all` with copy `skip` left out: the rest in the fix,
    /// that one the first dropped.
    fn split(&mut self, all: &Dropped, skip: usize) {
        self.ms.clear();
        self.sites.clear();
        self.sync_vars.clear();
        self.dropped.clear();
        for (k, (m, s, v)) in all.iter().enumerate() {
            if k == skip {
                self.dropped.push((*m, s.clone(), *v));
            } else {
                self.ms.push(*m);
                self.sites.push(s.clone());
                self.sync_vars.push(*v);
            }
        }
    }
}
