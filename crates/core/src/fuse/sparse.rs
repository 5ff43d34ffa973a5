//! Aircraft heard by too few receivers for a fix: their time differences
//! feed a particle filter ([`crate::track::particle`]), and its estimate is
//! published, flagged `sparse`, while the cloud has one mode and is tight
//! enough to say where the aircraft is. Once it has been so for a few
//! estimates in a row, or a fix comes, the aircraft's Gaussian tracks take
//! over: started from the cloud's mean and covariance, they take the time
//! differences from then on (an unscented update, which one mode and a few
//! kilometres of spread allow) and are published flagged `sparse` until the
//! first fix. Tracks the time differences keep missing were started from a
//! wrong cloud, and tracks a transmission gives a second solution nothing
//! rules out may be on the wrong one of two: either way they are dropped
//! and a new cloud starts.

use super::{Aircraft, Fuser, Output, TrackReport};
use crate::fuse::TrackSource;
use crate::mlat::engine::TdoaGroup;
use crate::track::measurement::{Measurement, Observation, Outcome, Persistent, Source};
use crate::track::motion::Motion;
use crate::track::particle::{mirrors, with_persistent, SparseOutcome, SparseTrack};
use crate::track::Estimate;

/// A height older than this does not place the aircraft on its surface (s).
const HEIGHT_MAX_AGE_S: f64 = 30.0;

/// The aircraft's height (m) for a transmission at `t`, if one recent enough is known.
fn height_at(a: &Aircraft, t: f64) -> Option<f64> {
    a.height.filter(|&(_, at)| (t - at).abs() <= HEIGHT_MAX_AGE_S).map(|(h, _)| h)
}

impl Fuser {
    /// One transmission's time differences for an aircraft without a position.
    pub(super) fn sparse_tdoa(
        &mut self,
        g: &TdoaGroup,
        persistent: &[Persistent],
        now: f64,
        out: &mut Vec<Output>,
    ) {
        let cfg = &self.tcfg.sparse;
        let Some(a) = self.aircraft.get_mut(&g.addr) else { return };
        if !cfg.enabled || a.adsb_heard {
            return;
        }
        let Some(h) = height_at(a, g.t) else {
            self.stats.sparse.no_height += 1;
            return;
        };
        a.last_heard = now;
        let since = *a.sparse_since.get_or_insert(g.t);
        let stats = &mut self.stats.sparse;
        let s = match a.sparse.as_mut() {
            None if g.t - since < cfg.start_after_s => return,
            None if self.sparse_active >= cfg.max_filters => {
                stats.refused += 1;
                return;
            }
            None => {
                // A new cloud remembers this transmission alone.
                let once = with_persistent(&g.sites, persistent, |_| 1.0);
                let Some(s) = SparseTrack::start(cfg, &once, g.unheard.as_ref(), g.t, h, g.addr as u64)
                else {
                    return;
                };
                stats.started += 1;
                self.sparse_active += 1;
                a.sparse.insert(Box::new(s))
            }
            Some(s) => {
                let resamples = s.resamples;
                match s.update_with(cfg, &g.sites, persistent, g.unheard.as_ref(), g.t, h) {
                    SparseOutcome::Updated => stats.updates += 1,
                    SparseOutcome::Restarted => {
                        stats.restarts += 1;
                        tracing::info!(
                            hex = format!("{:06X}", g.addr),
                            "particle filter lost the aircraft: started again from its newest time differences"
                        );
                    }
                    SparseOutcome::Unusable => return,
                }
                stats.resamples += (s.resamples - resamples) as u64;
                s
            }
        };
        let period = self.tcfg.period_default_s;
        if g.t < a.sparse_due {
            return;
        }
        let Some((plane, gauss)) = s.publishable(cfg.publish_sigma_m) else {
            a.sparse_publishable = 0;
            return;
        };
        let t = s.t;
        a.sparse_publishable += 1;
        if cfg.handover_after > 0 && a.sparse_publishable >= cfg.handover_after {
            // The tracks start where the cloud is; the cloud goes.
            // (The single-source tracks only where they run.)
            let singles = if self.singles { &mut a.single[..] } else { &mut [] };
            for track in std::iter::once(&mut a.fused).chain(singles) {
                track.start_from(t, plane, &gauss);
            }
            a.sparse = None;
            a.sparse_geometry = true;
            a.sparse_gated = 0;
            self.sparse_active -= 1;
            stats.handed_over_one_mode += 1;
        }
        a.sparse_due = g.t + period;
        stats.published += 1;
        out.push(Output::Track(Box::new(TrackReport {
            id: a.id,
            addr: g.addr,
            source: TrackSource::Fused,
            est: Estimate::new(t, plane, gauss, Some(h), 0.0),
            alt_baro_ft: a.alt_baro_ft,
            sources: smallvec::smallvec![Source::Mlat],
            nac_p: None,
            period_s: period,
            motion: Motion::Unknown,
            adsb_suspect: false,
            flight: a.flight.clone(),
            squawk: a.squawk,
            nav_altitude_ft: a.nav_altitude_ft,
            sparse: true,
            ages_s: [None, Some(0.0)],
        })));
    }
}

impl Fuser {
    /// A measurement's outcome for tracks started from a particle cloud:
    /// a position (a fix, ADS-B) ends their sparse geometry; time
    /// differences gated `max_gated_in_a_row` times in a row mean the cloud
    /// was wrong, and the aircraft goes back to a new one (returns whether
    /// it did).
    pub(super) fn sparse_geometry(&mut self, addr: u32, m: &Measurement, outcome: Outcome) -> bool {
        let Some(a) = self.aircraft.get_mut(&addr) else { return false };
        match (m.obs, outcome) {
            (Observation::Position { .. }, Outcome::Applied { .. } | Outcome::Restarted) => {
                a.sparse_geometry = false;
            }
            (Observation::Tdoa { .. }, Outcome::Applied { .. }) => {
                a.sparse_gated = 0;
                // Time differences alone hold a handed-over track only as
                // well as a cloud would have to be to be published: past
                // that, its Gaussian is a straight slice of a curved sheet
                // (where along a hyperbola the aircraft is, only its motion
                // says), and the cloud, which takes who heard it, is the
                // better judge.
                let limit = self.tcfg.sparse.publish_sigma_m;
                let spread = a.fused.estimate_at(m.t).map_or(0.0, |e| e.largest_sigma_m());
                if spread > limit {
                    self.give_back(
                        addr,
                        "its time differences alone no longer held it within the publication limit",
                    );
                    self.stats.sparse.spread += 1;
                    return true;
                }
            }
            (Observation::Tdoa { .. }, Outcome::Gated) => {
                a.sparse_gated += 1;
                if a.sparse_gated >= self.tcfg.max_gated_in_a_row {
                    self.give_back(addr, "the time differences kept missing them");
                    self.stats.sparse.given_back += 1;
                    return true;
                }
            }
            _ => {}
        }
        false
    }
}

impl Fuser {
    /// Whether a transmission with two time differences has a solution far
    /// from the aircraft's tracks started from a cloud (no fix yet) that who
    /// heard it does not rule out. The tracks may then be on either (near
    /// a line through its receivers the two solutions part, and a track
    /// follows one or the other as well), and one Gaussian cannot say so:
    /// the aircraft goes back to a cloud, which can hold both. One time
    /// difference's far solutions are its curve's, which the tracks' own
    /// history rules out.
    pub(super) fn sparse_mirrored(&mut self, g: &TdoaGroup, persistent: &[Persistent]) -> bool {
        let Some(a) = self.aircraft.get(&g.addr) else { return false };
        if !a.sparse_geometry || g.sites.len() != 3 {
            return false;
        }
        let (Some(h), Some(est)) = (height_at(a, g.t), a.fused.estimate_at(g.t)) else { return false };
        let position =
            (est.state.x.fixed_rows::<2>(0).into_owned(), est.state.p.fixed_view::<2, 2>(0, 0).into_owned());
        // With no solution near the tracks they are off, not on a mirror:
        // the gate sees to that.
        let sites = with_persistent(&g.sites, persistent, |_| 1.0);
        let m = mirrors(&est.plane, &sites, h, g.unheard.as_ref(), g.t, position);
        if !(m.own && m.open) {
            return false;
        }
        self.give_back(g.addr, "a transmission had another solution who heard it could not rule out");
        self.stats.sparse.mirrored += 1;
        true
    }

    /// Frees aircraft `addr`'s cloud, if it has one, once a position placed
    /// it (counted as handed over at a fix).
    pub(super) fn release_cloud(&mut self, addr: u32) {
        if self.aircraft.get_mut(&addr).is_some_and(|a| a.sparse.take().is_some()) {
            self.stats.sparse.handed_over += 1;
            self.sparse_active -= 1;
        }
    }

    /// Drops the tracks an aircraft's cloud started, for a new cloud from
    /// its next time differences, at once; logged with `why`.
    fn give_back(&mut self, addr: u32, why: &str) {
        let Some(a) = self.aircraft.get_mut(&addr) else { return };
        (a.fused, a.single) = super::fresh_tracks(&self.tcfg, &self.spec_mlat_only, self.cfg.method);
        a.sparse_geometry = false;
        a.sparse_publishable = 0;
        a.sparse_gated = 0;
        a.sparse_since = Some(f64::NEG_INFINITY);
        tracing::info!(hex = format!("{addr:06X}"), "tracks started from a particle cloud given back: {why}");
    }
}
