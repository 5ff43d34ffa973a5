//! What is known of each receiver: its report (state, the reason it is left
//! out, its learnt timing and position offset) for the run report, the
//! stats line, Prometheus and the track stream, and what has been learnt of
//! it kept across a restart (`[service] state_file`). Apart from the
//! engine's per-group path: read by the operator, not by the solver.

use super::{Mlat, JUMPS_EXCLUDE};
use crate::feed::capture::ClockKind;
use crate::geo::{ecef_distance, geodetic_to_ecef};
use crate::mlat::report::{Exclusion, ReceiverReport, RxState};
use crate::mlat::state::{LearntReceiver, LearntState};
use crate::mlat::survey::Survey;
use crate::mlat::sync::RxHealth;
use crate::mlat::timing::TimingModel;

impl Mlat {
    /// What is known of receiver `rx` at data time `t` (see [`ReceiverReport`]).
    pub fn receiver_report(&self, rx: usize, t: f64) -> ReceiverReport {
        let (r, h) = (&self.rxs[rx], &self.sync.health[rx]);
        let reason = if r.jumps > JUMPS_EXCLUDE {
            Some(Exclusion::TimeJumps)
        } else if r.misplaced {
            Some(Exclusion::Misplaced)
        } else {
            h.excluded.then_some(Exclusion::SyncFailing)
        };
        let gps_mean = gps_mean_offset(self.rxs.iter().map(|o| (o.clock, &o.timing)));
        let mut report = timing_report(rx, t, reason, h, r.clock, &r.timing, gps_mean);
        let offset = r.survey.offset();
        report.position_offset_en_m = offset.map(|o| [o.enu_m[0], o.enu_m[1]]);
        report.position_offset_sigma_m = offset.map(|o| o.sigma_m);
        report
    }

    /// What has been learnt of every receiver, to be kept across a restart.
    pub fn learnt(&self, saved_unix: f64) -> LearntState {
        let receivers = (self.rxs.iter())
            .map(|r| LearntReceiver {
                id: r.id.clone(),
                clock: r.clock,
                lat: r.declared.0,
                lon: r.declared.1,
                alt_m: r.declared.2,
                fixes: r.timing.n,
                bias_s: r.timing.offset_s,
                var_s2: r.timing.var_s2,
                late_rate: Some(r.timing.late_rate),
                late_mean_s: Some(r.timing.late_mean_s),
                survey: r.survey.snapshot(),
            })
            .collect();
        LearntState { version: crate::mlat::state::VERSION, saved_unix, receivers, air: None }
    }

    /// Takes up what a previous run learnt, for each receiver with the same
    /// id, clock kind and declared position; returns how many.
    pub fn restore(&mut self, state: &LearntState) -> usize {
        let mut restored = 0;
        for r in &mut self.rxs {
            if r.timing_known {
                continue;
            }
            let Some(l) = state.receivers.iter().find(|l| l.id == r.id) else { continue };
            let same_place = geodetic_to_ecef(l.lat, l.lon, l.alt_m);
            if l.clock != r.clock || ecef_distance(same_place, r.declared_ecef) > 1.0 {
                continue;
            }
            if !(l.bias_s.is_finite() && l.var_s2.is_finite() && l.var_s2 >= 0.0) {
                continue;
            }
            let prior = TimingModel::prior(r.sigma_t);
            r.timing = TimingModel {
                n: l.fixes,
                offset_s: l.bias_s,
                var_s2: l.var_s2,
                late_rate: l.late_rate.filter(|v| (0.0..1.0).contains(v)).unwrap_or(prior.late_rate),
                late_mean_s: l.late_mean_s.filter(|v| v.is_finite() && *v > 0.0).unwrap_or(prior.late_mean_s),
            };
            if let Some(s) = Survey::from_snapshot(&l.survey) {
                r.survey = s;
            }
            restored += 1;
        }
        for rx in 0..self.rxs.len() {
            self.sync.set_gps_bias(rx, self.rxs[rx].bias());
        }
        restored
    }

    /// Every receiver's state in one line (`receivers: id=state/sigma/...`).
    pub fn receivers_line(&self, now: f64, names: &dyn Fn(usize) -> String) -> String {
        let all: Vec<String> = (0..self.rxs.len())
            .map(|k| crate::mlat::report::summary(&self.receiver_report(k, now), &names(k)))
            .collect();
        format!("mlat receivers (state/sigma/offset/outliers/position): {}", all.join(" "))
    }
}

/// The mean offset (s) of the GPS-timed receivers whose timing is learnt,
/// when there are two or more (`timings`: every receiver's clock and model):
/// biases are relative (a common one goes into the emission time), so a GPS
/// receiver's is told against this.
pub fn gps_mean_offset<'a>(timings: impl Iterator<Item = (ClockKind, &'a TimingModel)>) -> Option<f64> {
    let (mut n, mut sum) = (0usize, 0.0);
    for (_, m) in timings.filter(|(clock, m)| *clock == ClockKind::Gps && m.learnt()) {
        n += 1;
        sum += m.offset_s;
    }
    (n >= 2).then(|| sum / n as f64)
}

/// Receiver `rx`'s report at `t` from its clock health `h` and its timing
/// model `m`, out of the fixes for `reason`, a GPS receiver's offset told
/// against `gps_mean` ([`gps_mean_offset`]); its position fields left out
/// (the engine and a cluster's clock add their survey's). A misplaced
/// receiver's timing is not reported: what it learnt, it learnt against a
/// wrong position (its sigma several times the truth), and out of the
/// fixes it learns nothing more.
pub fn timing_report(
    rx: usize,
    t: f64,
    reason: Option<Exclusion>,
    h: &RxHealth,
    clock: ClockKind,
    m: &TimingModel,
    gps_mean: Option<f64>,
) -> ReceiverReport {
    let learnt = m.learnt() && reason != Some(Exclusion::Misplaced);
    let state = if reason.is_some() {
        RxState::Excluded
    } else if m.learnt() || h.sync_updates >= crate::mlat::sync::HEALTH_MIN_UPDATES {
        RxState::Ok
    } else {
        RxState::Learning
    };
    let offset_ns =
        gps_mean.filter(|_| clock == ClockKind::Gps && learnt).map(|mean| (m.offset_s - mean) * 1e9);
    ReceiverReport {
        t,
        rx,
        state,
        reason,
        sigma_ns: learnt.then(|| m.sigma() * 1e9),
        offset_ns,
        outlier_rate: learnt.then_some(m.late_rate),
        late_delay_ns: learnt.then_some(m.late_mean_s * 1e9),
        position_offset_en_m: None,
        position_offset_sigma_m: None,
    }
}

impl Mlat {
    /// One line of MLAT state: valid pairs, sync residual per receiver (ns),
    /// fixes, rejects by reason, excluded receivers.
    pub fn report(&self, now: f64, names: &dyn Fn(usize) -> String) -> String {
        let params = &self.sync.params;
        let mut per_rx: Vec<(f64, usize)> = vec![(0.0, 0); self.rxs.len()];
        let mut valid = 0;
        let mut total = 0;
        for (&(i, j), p) in self.sync.pairs() {
            total += 1;
            if p.valid(now, params) {
                valid += 1;
                for k in [i, j] {
                    per_rx[k].0 += p.residual_rms();
                    per_rx[k].1 += 1;
                }
            }
        }
        let residuals: Vec<String> = per_rx
            .iter()
            .enumerate()
            .filter(|(_, (_, n))| *n > 0)
            .map(|(k, (s, n))| format!("{}={:.0}", names(k), s / *n as f64 * 1e9))
            .collect();
        let excluded: Vec<String> =
            self.sync.health.iter().enumerate().filter(|(_, h)| h.excluded).map(|(k, _)| names(k)).collect();
        let mut rejects: Vec<String> = (self.stats.rejects.iter())
            .filter(|&(_, n)| n > 0)
            .map(|(why, n)| format!("{}={n}", why.name()))
            .collect();
        rejects.sort();
        // Receivers whose declared position the traffic contradicts.
        let misplaced: Vec<String> = (self.rxs.iter().enumerate())
            .filter_map(|(k, r)| {
                let o = r.survey.offset().filter(|o| o.misplaced())?;
                Some(format!(
                    "{} declared {:.0} m off: {:+.0} m east, {:+.0} m north, +-{:.0} m",
                    names(k),
                    o.horizontal_m(),
                    o.enu_m[0],
                    o.enu_m[1],
                    o.sigma_m
                ))
            })
            .collect();
        format!(
            "mlat: {} fixes from {} groups; pairs {valid}/{total} valid; sync residual ns [{}]; rejects [{}]; \
             excluded [{}]; misplaced [{}]; sync messages {}, pair updates {}, outliers {}, restarts {}; \
             GPS time jumps {}; self-synchronised fixes {}; survey outliers {}",
            self.stats.fixes,
            self.stats.groups,
            residuals.join(" "),
            rejects.join(" "),
            excluded.join(" "),
            misplaced.join("; "),
            self.stats.sync_messages,
            self.sync.stats.updates,
            self.sync.stats.outliers,
            self.sync.stats.restarts,
            self.stats.time_jumps,
            self.stats.self_synced_fixes,
            self.stats.survey_gross
        )
    }
}
