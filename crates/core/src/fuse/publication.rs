//! An aircraft's publication, once due: the estimates its tracks gave at
//! the publication time, fused by the configured method (or the fused
//! track's own), with the sources heard lately, as a `TrackReport`; the
//! single-source tracks beside it when asked for. The sampling period is
//! the NACp table's, the densest while the aircraft is in a conflict.

use super::*;

impl Fuser {
    // Over 80 lines: most of it is the report's fields and the method's match.
    pub(super) fn publish(&mut self, addr: u32, out: &mut Vec<Output>) {
        let Some(a) = self.aircraft.get_mut(&addr) else {
            return;
        };
        let Some(t) = a.pending.take() else {
            return;
        };
        let period = a.period_s(&self.tcfg);
        let window = self.cfg.sources_window_s;
        // Time since the source's newest position.
        let age = |s: Source| t - a.last_source_t[s as usize];
        let sources = [Source::Adsb, Source::Mlat].into_iter().filter(|&s| age(s) <= window).collect();
        // A coasting single-source track (no position lately) is not fused.
        let coast = self.tcfg.coast_after_s;
        let confirmed = |s: Source| a.single[s as usize].confirmed();
        let taken = std::mem::take(&mut a.taken);
        // Asked now, a track answers as it did at `t` from its history, or
        // nothing once its history no longer reaches back that far.
        let as_taken = |track: &Track, est: Option<Estimate>| {
            debug_assert!(track.estimate_at(t).is_none_or(|now| Some(now) == est), "estimate at {t}");
            est
        };
        let single = |s: Source| {
            let est = as_taken(&a.single[s as usize], taken.single[s as usize]);
            est.filter(|_| age(s) <= coast && confirmed(s))
        };
        let (adsb, mlat) = (single(Source::Adsb), single(Source::Mlat));
        // A confirmed track whose source is still heard of (within the
        // sources window) but whose newest position is older than the
        // coasting limit: predicting it that far is not aligning it.
        let stale = |s: Source| confirmed(s) && age(s) > coast && age(s) <= window;
        let fused = match self.cfg.method {
            Method::Measurement => as_taken(&a.fused, taken.fused),
            method => match (adsb.filter(|_| !a.adsb_suspect), mlat) {
                (Some(x), Some(y)) => match methods::fuse(
                    method,
                    &x,
                    &y,
                    Some(&a.cross.at(t, |dt| self.spec.models[0].transition(dt))),
                ) {
                    Some(f) => Some(f),
                    None => {
                        self.stats.fusion_fallbacks += 1;
                        Some(methods::better(&x, &y))
                    }
                },
                (x, y) => {
                    // (ADS-B left out as suspect is left out on purpose.)
                    let missing = if x.is_none() { Source::Adsb } else { Source::Mlat };
                    let suspect = missing == Source::Adsb && a.adsb_suspect;
                    if x.is_some() != y.is_some() && stale(missing) && !suspect {
                        self.stats.fusion_fallbacks += 1;
                    }
                    x.or(y)
                }
            },
        };
        let report = |source: TrackSource, est: Estimate, sources: Sources| TrackReport {
            id: a.id,
            addr,
            source,
            est,
            alt_baro_ft: a.alt_baro_ft,
            sources,
            nac_p: a.nac_p,
            period_s: period,
            motion: a.motion_state,
            adsb_suspect: a.adsb_suspect,
            flight: a.flight.clone(),
            squawk: a.squawk,
            nav_altitude_ft: a.nav_altitude_ft,
            sparse: a.sparse_geometry,
            ages_s: [Source::Adsb, Source::Mlat].map(|s| Some(age(s).max(0.0)).filter(|age| *age <= window)),
        };
        // Coasted (no position lately) until too spread to say where the
        // aircraft is: withheld, counted once per publication. A track fed
        // positions is published however poor they are (an honest NACp 1).
        let limit = self.tcfg.publish_sigma_m;
        let lost = |track: &Track, est: &Option<Estimate>| {
            est.is_some_and(|e| track.coasting_at(t, coast) && e.largest_sigma_m() > limit)
        };
        let (fused_lost, adsb_lost, mlat_lost) = (
            lost(&a.fused, &fused),
            lost(&a.single[Source::Adsb as usize], &adsb),
            lost(&a.single[Source::Mlat as usize], &mlat),
        );
        if fused_lost || (self.publish_source_tracks && (adsb_lost || mlat_lost)) {
            self.stats.withheld_spread += 1;
        }
        if let Some(est) = fused.filter(|_| !fused_lost) {
            out.push(Output::Track(Box::new(report(TrackSource::Fused, est, sources))));
            self.stats.published += 1;
        }
        if self.publish_source_tracks {
            let (adsb, mlat) = (adsb.filter(|_| !adsb_lost), mlat.filter(|_| !mlat_lost));
            for (s, est) in [(Source::Adsb, adsb), (Source::Mlat, mlat)] {
                if let Some(est) = est {
                    out.push(Output::Track(Box::new(report(s.into(), est, smallvec::smallvec![s]))));
                }
            }
        }
    }
}

impl Aircraft {
    /// The sampling period in force: the NACp table's, the densest in conflict.
    pub(super) fn period_s(&self, cfg: &TrackConfig) -> f64 {
        if self.in_conflict {
            cfg.densest_period_s()
        } else {
            cfg.period_s(self.nac_p)
        }
    }
}
