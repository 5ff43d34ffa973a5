//! Where each receiver is: the position survey fed from the ADS-B traffic
//! (see [`Survey`](crate::mlat::survey::Survey)), and what its verdict does
//! to the receiver, leaving it out of fixes or, with `self_survey`, moving
//! it. Apart from the engine's per-group path so that the receivers'
//! placement reads on its own; the engine calls [`Mlat::survey_from`] once
//! per ADS-B group.
use super::{GroupVec, LocalCopy, Mlat, SURVEY_CHECK_EVERY};
use crate::feed::capture::ClockKind;
use crate::geo::{ecef_distance, geodetic_to_ecef};
use crate::mlat::shared::{SurveyRow, SyncNote};
use crate::mlat::solver::C_AIR;

/// The surveyed position in use follows the survey once it moves by more
/// than this many of its sigmas, and at least this far (m).
const FOLLOW_SIGMAS: f64 = 2.0;
const FOLLOW_FLOOR_M: f64 = 1.0;
/// A copy whose emission time is this far (s) from the group's median is
/// no survey's measurement: 300 km, beyond any receiver's range, where a
/// misplaced position or a clock's offset moves it by microseconds.
const SURVEY_GROSS_S: f64 = 1e-3;

impl Mlat {
    /// One ADS-B position, multilaterated: each receiver's range excess
    /// against the emission time the others give it (see
    /// [`Survey`](crate::mlat::survey::Survey)). A counter-timed receiver is
    /// surveyed as a GPS-timed one is: its clock pairs run on the network's
    /// time (the GPS receivers'), which its position error does not move, so
    /// they do not absorb that error.
    pub(super) fn survey_from(
        &mut self,
        copies: &[LocalCopy],
        times: &[Option<(f64, f64)>],
        a: [f64; 3],
        sigma_a: f64,
        now: f64,
    ) {
        // (receiver, emission as its copy says and with its learnt offset
        // removed, weight, part of the reference)
        let mut emitted: GroupVec<(usize, f64, f64, f64, bool)> = GroupVec::new();
        for (c, t) in copies.iter().zip(times) {
            let Some((t, var)) = t else { continue };
            let rx = &self.rxs[c.rx];
            let w = 1.0 / (var + rx.sigma().powi(2));
            // A receiver is surveyed without its learnt offset: the survey
            // fits its own constant, and a misplaced receiver's timing
            // offset, learnt from fixes its wrong position pulled, is no
            // constant. The reference is corrected (a GPS receiver's offset
            // came off in the common time base, a counter's comes off here).
            let e = t - ecef_distance(rx.ecef, a) / C_AIR;
            let (raw, corrected) = match rx.clock {
                ClockKind::Gps => (e + rx.bias(), e),
                ClockKind::Beast12 => (e, e - rx.bias()),
            };
            // An excluded receiver (a misplaced one, say) is surveyed but
            // is no one's reference.
            emitted.push((c.rx, raw, corrected, w, !self.out_of_fixes(c.rx)));
        }
        // A copy whose time puts the emission further from the others' than
        // any position or timing fault can (a counter converted through
        // pairs from before its restart: in a cluster, until the clock
        // service has applied the restart) would be one measurement tens of
        // kilometres off in its own survey and, through the reference, in
        // every other's, never forgotten: left out, and counted.
        let mut mid: GroupVec<f64> = emitted.iter().filter(|x| x.4).map(|x| x.2).collect();
        mid.sort_unstable_by(f64::total_cmp);
        if let Some(&median) = mid.get(mid.len() / 2) {
            let before = emitted.len();
            emitted.retain(|x| (x.2 - median).abs() <= SURVEY_GROSS_S);
            self.stats.survey_gross += (before - emitted.len()) as u64;
        }
        let mut rows: Vec<SurveyRow> = Vec::new();
        let (sw, swe) = (emitted.iter())
            .filter(|x| x.4)
            .fold((0.0, 0.0), |(sw, swe), &(_, _, corrected, w, _)| (sw + w, swe + w * corrected));
        for &(rx, e, corrected, w, in_reference) in &emitted {
            // The others' emission time, leaving this copy out.
            let (w_others, swe_others) = if in_reference { (sw - w, swe - w * corrected) } else { (sw, swe) };
            if w_others <= 0.0 || emitted.len() < 3 {
                continue;
            }
            let t_emit = swe_others / w_others;
            let r = &self.rxs[rx];
            // Against its declared position, whatever position is in use.
            let e = e + (ecef_distance(r.ecef, a) - ecef_distance(r.declared_ecef, a)) / C_AIR;
            let range = ecef_distance(r.declared_ecef, a);
            // Declared beyond any range it could hear the aircraft from (at
            // 0,0, say): off by more than a linear fit can find, and
            // excluded for its clock pairs failing instead.
            if range > self.limits.max_range_m {
                continue;
            }
            let u: [f64; 3] = std::array::from_fn(|k| (r.declared_ecef[k] - a[k]) / range);
            let u_enu = r.enu.map(|axis| axis[0] * u[0] + axis[1] * u[1] + axis[2] * u[2]);
            // Timing (its own and the others'), and the ADS-B position's
            // error, which moves its range and the others' differently.
            let var = C_AIR * C_AIR * (1.0 / w + 1.0 / w_others) + 2.0 * sigma_a * sigma_a;
            let d_m = C_AIR * (e - t_emit);
            // In a cluster the survey is the clock service's, from every
            // worker's traffic, and comes back with its snapshots.
            if self.shared.is_some() {
                rows.push(SurveyRow { rx: rx as u32, u_enu, d_m, var_m2: var });
                continue;
            }
            self.rxs[rx].survey.add(u_enu, d_m, var, now);
            if self.rxs[rx].survey.count() % SURVEY_CHECK_EVERY == 0 {
                self.place(rx, now);
            }
        }
        if !rows.is_empty() {
            self.note_sync(SyncNote::Survey { now, rows });
        }
    }

    /// What receiver `rx`'s survey says is done: with `self_survey` it is
    /// used where the survey puts it, without it left out if misplaced.
    pub(super) fn place(&mut self, rx: usize, now: f64) {
        if self.cfg.self_survey {
            self.apply_survey(rx, now);
        } else {
            self.judge_position(rx);
        }
    }

    /// Without `self_survey`, a receiver its survey finds misplaced is left
    /// out of fixes (its wrong position would pull each one), and taken back
    /// if the survey stops saying so.
    fn judge_position(&mut self, rx: usize) {
        let r = &mut self.rxs[rx];
        let offset = r.survey.offset();
        let misplaced = offset.is_some_and(|o| o.misplaced());
        if misplaced == r.misplaced {
            return;
        }
        r.misplaced = misplaced;
        match offset.filter(|_| misplaced) {
            Some(o) => tracing::warn!(
                receiver = %r.id,
                east_m = format!("{:+.0}", o.enu_m[0]),
                north_m = format!("{:+.0}", o.enu_m[1]),
                sigma_m = format!("{:.0}", o.sigma_m),
                "receiver excluded from MLAT: its declared position is wrong (set self_survey = true to use the surveyed one)"
            ),
            None => {
                tracing::info!(receiver = %r.id, "receiver readmitted to MLAT: its survey agrees with its declared position")
            }
        }
    }

    /// Puts a misplaced receiver where the traffic says it is (or back where
    /// it was declared once the survey no longer says so), and follows the
    /// survey as it firms up: a position held at the first estimate until
    /// the survey moved 10 m from it kept metres of error in every fix the
    /// receiver was in, all in one direction, with a covariance that knew
    /// nothing of it. Its clock pairs start again when it is relocated.
    fn apply_survey(&mut self, rx: usize, now: f64) {
        let r = &self.rxs[rx];
        let target =
            r.survey.offset().filter(|o| o.misplaced()).map(|o| ([o.enu_m[0], o.enu_m[1]], o.sigma_m));
        // What the position in use may be off by goes into its copies'
        // variance: left out, every fix with a surveyed receiver claimed
        // more than its position was known to.
        let spread = match (r.surveyed, target) {
            (Some(a), Some((t, sigma))) => {
                (sigma * sigma + 0.5 * ((a[0] - t[0]).powi(2) + (a[1] - t[1]).powi(2))) / (C_AIR * C_AIR)
            }
            _ => 0.0,
        };
        self.rxs[rx].surveyed_var_s2 = spread;
        let r = &self.rxs[rx];
        let moved = match (r.surveyed, target) {
            (None, None) => false,
            (Some(a), Some((t, sigma))) => {
                (a[0] - t[0]).hypot(a[1] - t[1]) > (FOLLOW_SIGMAS * sigma).max(FOLLOW_FLOOR_M)
            }
            _ => true,
        };
        // Declared to surveyed, or back: what the pairs learnt rested on a
        // position tens of metres off. A surveyed position made more
        // precise moves their ranges by nanoseconds, which they follow.
        let relocated = r.surveyed.is_none() || target.is_none();
        if !moved {
            return;
        }
        let (lat, lon, alt) = r.declared;
        let r = &mut self.rxs[rx];
        r.surveyed = target.map(|t| t.0);
        r.surveyed_var_s2 = target.map_or(0.0, |(_, sigma)| (sigma / C_AIR).powi(2));
        r.ecef = match r.surveyed {
            Some([e, n]) => {
                let (la, lo, h) = crate::geo::displace(lat, lon, alt, [e, n, 0.0]);
                geodetic_to_ecef(la, lo, h)
            }
            None => r.declared_ecef,
        };
        tracing::info!(receiver = %r.id, offset_en_m = ?r.surveyed, "self-survey: the receiver's position in use changed");
        if relocated {
            self.sync.reset_pairs(rx);
            self.note_sync(crate::mlat::shared::SyncNote::ResetPairs { now, rx: rx as u32 });
        }
    }
}
