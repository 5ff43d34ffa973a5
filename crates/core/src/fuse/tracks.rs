//! One measurement into an aircraft's tracks: the fused track (without a
//! suspect aircraft's ADS-B), the single-source ones when a method or the
//! output needs them, the cross-covariance of track-to-track fusion, the
//! static/moving test, and when the next publication falls due.

use super::*;

impl Fuser {
    // Over 80 lines: the per-measurement sequence (tracks, fusion's
    // cross-covariance, counters, motion test, publication due).
    pub(super) fn apply_to_tracks(&mut self, addr: u32, m: Measurement) {
        let Some(a) = self.aircraft.get_mut(&addr) else {
            return;
        };
        if m.source == Source::Adsb && !a.adsb_heard {
            // From its first ADS-B on, in time order: a late measurement
            // re-run from the history switches as it did the first time. A
            // fused track whose ADS-B was flagged before any was applied (it
            // waited for the MLAT hold) stays fed by MLAT alone.
            a.adsb_heard = true;
            let fused = (!a.adsb_suspect).then_some(&mut a.fused);
            for track in fused.into_iter().chain(&mut a.single) {
                track.set_spec(m.t, self.spec.clone());
            }
        }
        // A flagged aircraft's ADS-B stays out of the fused track.
        let into_fused = !(a.adsb_suspect && m.source == Source::Adsb);
        let outcome = if into_fused {
            self.stats.reruns += (m.t < a.fused.t()) as u64;
            // Its ADS-B is in the fused track (unless flagged, when no clock
            // is synchronised on it either).
            a.fused.apply(if a.adsb_suspect { m } else { without_echo(m) })
        } else {
            self.stats.suspect_excluded += 1;
            Outcome::Early
        };
        // Single-source tracks cost as much as the fused one: run only when
        // a track-to-track method or their publication needs them.
        let single = if self.singles {
            // The MLAT-only track has no ADS-B: the echo is news to it,
            // unless a track-to-track method fuses it with the ADS-B track.
            let t2t = self.cfg.method != Method::Measurement;
            a.single[m.source as usize].apply(if t2t { without_echo(m) } else { m })
        } else if into_fused {
            outcome
        } else {
            Outcome::Applied { nis: 0.0 }
        };
        if self.singles && a.single[0].keep_gain {
            let model = self.spec.models[0];
            let f_q = |dt: f64| model.transition(dt);
            match (single, a.single[m.source as usize].gain) {
                (Outcome::Restarted, _) => a.cross = Cross::new(),
                (Outcome::Applied { .. }, Some((t, g))) if t == m.t => {
                    a.cross.update(t, m.source == Source::Adsb, &g, f_q)
                }
                _ => {}
            }
        }
        match outcome {
            Outcome::TooLate => self.stats.too_late += 1,
            Outcome::Gated => self.stats.gated += 1,
            Outcome::Restarted => self.stats.restarts += 1,
            _ => {}
        }
        // Placed by a position (a fix, ADS-B), the aircraft needs its cloud no
        // more: freed now, not at its next time differences, which an
        // aircraft heard by enough receivers may never send.
        let cloud_done = a.sparse.is_some() && a.fused.has_position();
        // Tracks started from a particle cloud and given back to a new one
        // have nothing more to do.
        if a.sparse_geometry && self.sparse_geometry(addr, &m, outcome) {
            return;
        }
        if cloud_done {
            self.release_cloud(addr);
        }
        let Some(a) = self.aircraft.get_mut(&addr) else { return };
        if !matches!(m.obs, Observation::Position { .. } | Observation::Tdoa { .. }) {
            return;
        }
        if matches!(single, Outcome::Applied { .. } | Outcome::Restarted) {
            a.last_source_t[m.source as usize] = a.last_source_t[m.source as usize].max(m.t);
        }
        if let Observation::Position { lat, lon, cov_en, surface, .. } = m.obs {
            a.surface = surface;
            if m.t - a.motion_t >= self.tcfg.motion_interval_s {
                a.motion_t = m.t;
                Self::motion(a, lat, lon, cov_en);
            }
        }
        if !matches!(outcome, Outcome::Applied { .. }) || !a.fused.confirmed() {
            return;
        }
        // Due already in this batch: it goes out at its newest measurement
        // (the ADS-B a moment after its own transmission's fix, say).
        if let Some(p) = a.pending {
            a.pending = Some(p.max(m.t));
            return;
        }
        if m.t < a.next_due {
            return;
        }
        let period = a.period_s(&self.tcfg);
        if !a.next_due.is_finite() {
            a.next_due = m.t;
        }
        while a.next_due <= m.t {
            a.next_due += period;
        }
        a.pending = Some(m.t);
    }

    /// The static/moving test over the aircraft's recent position
    /// measurements; an airborne aircraft faster than a taxiing one moves
    /// without the test (which costs a small matrix factorisation).
    fn motion(a: &mut Aircraft, lat: f64, lon: f64, cov: Matrix2<f64>) {
        if !a.surface && a.fused.speed().is_some_and(|v| v > 30.0) {
            a.motion_state = Motion::Moving;
            return;
        }
        let plane = match a.motion_plane {
            Some(p) if crate::geo::distance_m(p.lat, p.lon, lat, lon) < 5_000.0 => p,
            _ => {
                let p = Plane::new(lat, lon, 0.0);
                a.motion_plane = Some(p);
                a.motion.restart();
                p
            }
        };
        let en = plane.to_en(lat, lon);
        a.motion_state = a.motion.push(Fix2 { pos: Vector2::new(en[0], en[1]), cov });
    }
}

/// The least share of a fix's timing variance counted as independent of
/// its aircraft's ADS-B (a 100-fold inflation at most).
const MIN_INDEPENDENT_SHARE: f64 = 0.01;

/// A position as a track that has the aircraft's ADS-B counts it: what
/// repeats that ADS-B (`adsb_echo`) is no news, so only the rest is counted
/// (its covariance inflated by the inverse of the rest's share).
fn without_echo(mut m: Measurement) -> Measurement {
    if let Observation::Position { cov_en, adsb_echo, .. } = &mut m.obs {
        if *adsb_echo > 0.0 {
            *cov_en /= (1.0 - *adsb_echo).max(MIN_INDEPENDENT_SHARE);
        }
    }
    m
}
