//! A transmission's group, handed out once its wait is over: to the
//! multilateration engine, its outcome to the tracker (a fix as a position
//! with its sync share, time differences), to the conformance monitor, and
//! to the network delay of receivers dated by arrival.

use super::*;

/// Vertical sigma (m) of a reported position's height: its 25 ft steps
/// and the GNSS-baro difference's error; and of a height from barometric
/// altitude alone, without that difference.
const REPORTED_HEIGHT_SIGMA_M: f64 = 30.0;
const BARO_ONLY_SIGMA_M: f64 = 150.0;

impl GroupCtx<'_> {
    pub(super) fn on_group(&mut self, g: &Group, now: f64, cmds: &mut Vec<Cmd>) {
        self.learn_delay(g);
        let fix = match self.mlat.on_group(g, now) {
            GroupOutcome::Fix(fix) => fix,
            GroupOutcome::Tdoa(t) => {
                self.tdoa_conformance(g, &t, cmds);
                return cmds.push(Cmd::Tdoa { g: t, now });
            }
            // Counted by the engine.
            GroupOutcome::NoFix(_) => return,
        };
        self.stats.fixes += 1;
        let c = fix.cov_en;
        // Synchronisation errors persist from fix to fix: the conformance
        // monitor, which weighs fixes against ADS-B one by one, takes them
        // inflated; a track counts them by its own memory (the share).
        let inflation = 1.0 + fix.sync_share * (self.sync_inflation - 1.0);
        let m = Measurement {
            t: fix.t,
            source: Source::Mlat,
            obs: Observation::Position {
                lat: fix.lat,
                lon: fix.lon,
                cov_en: nalgebra::Matrix2::new(c[0][0], c[0][1], c[1][0], c[1][1]),
                // Heights come from altitude reports: a fix's own height is
                // either the barometric one it was given, or (without one)
                // so poorly determined that its linearised sigma cannot be
                // trusted (hundreds of metres off at 20 m sigma on the surface).
                height: None,
                time_sigma_s: 0.0,
                surface: false,
                claimed: true,
                // How many fixes share it is the fuser's to say.
                persistent: SharedShare { share: fix.sync_share.clamp(0.0, 1.0), shared_by: 1.0 },
                // What clocks synchronised on this aircraft's own ADS-B put
                // in the fix is its ADS-B errors again: the fuser counts only
                // the rest in a track that has its ADS-B.
                adsb_echo: fix.self_sync_share.clamp(0.0, 1.0),
            },
        };
        let (addr, t) = (fix.addr, fix.t);
        // The same transmission's ADS-B position against its fix, when the
        // fix has redundancy and fits its own timing.
        let pair = g.info.report.filter(|_| fix.dof >= 1 && fix.chi2 <= 3.0).map(|(lat, lon, sigma)| {
            (crate::track::plane::Plane::new(lat, lon, 0.0).to_en(fix.lat, fix.lon), sigma)
        });
        cmds.push(Cmd::Event(Event::Mlat(fix)));
        if let Some((d, sigma)) = pair {
            let v = sigma * sigma;
            let s = [
                [v + c[0][0] * inflation, c[0][1] * inflation],
                [c[1][0] * inflation, v + c[1][1] * inflation],
            ];
            let cfg = self.conformance;
            self.conformance_check(g, addr, t, cmds, |m| m.push(cfg, d, s));
        }
        cmds.push(Cmd::Measure { addr, nac_p: None, m, now });
    }

    /// The same transmission's ADS-B position against its time differences,
    /// where too few receivers heard it for a fix: a spoofer that only two
    /// or three receivers hear is caught as one that more hear is.
    fn tdoa_conformance(&mut self, g: &Group, t: &crate::mlat::engine::TdoaGroup, cmds: &mut Vec<Cmd>) {
        let Some((lat, lon, sigma)) = g.info.report else { return };
        let (h, sigma_v) = match (g.info.adsb_ecef, g.info.alt_baro_ft) {
            (Some(e), _) => (crate::geo::ecef_to_geodetic(e).2, REPORTED_HEIGHT_SIGMA_M),
            (None, Some(ft)) => baro_height(ft, g.info.baro_correction, BARO_ONLY_SIGMA_M),
            (None, None) => return,
        };
        let p = geodetic_to_ecef(lat, lon, h);
        let enu = crate::mlat::survey::enu_basis(lat, lon);
        let Some(test) = crate::fuse::conformance::tdoa_test(&t.sites, p, sigma, sigma_v, enu) else {
            return;
        };
        let cfg = self.conformance;
        self.conformance_check(g, t.addr, t.t, cmds, |m| m.push_tdoa(cfg, test));
    }

    /// One check of aircraft `addr`'s ADS-B by the conformance monitor
    /// (`check` pushes it), and the alert when its verdict changed.
    fn conformance_check(
        &mut self,
        g: &Group,
        addr: u32,
        t: f64,
        cmds: &mut Vec<Cmd>,
        check: impl FnOnce(&mut Monitor) -> Option<bool>,
    ) {
        self.stats.conformance_checks += 1;
        // Heard when its first copy arrived, not when the group was
        // handed out (at the end of a capture, much later).
        let heard = g.first_arrival;
        let w =
            (self.watched.entry(addr)).or_insert(Watched { monitor: Monitor::default(), last_heard: heard });
        w.last_heard = heard;
        if let Some(suspect) = check(&mut w.monitor) {
            let (offset_m, nis) = (w.monitor.last_offset_m, w.monitor.last_nis);
            cmds.push(Cmd::Suspect { addr, t, suspect, offset_m, nis });
        }
    }

    /// A transmission whose first copy (the one decoded and reported) came
    /// from a receiver dated by arrival, also heard by a GPS-timed one: how
    /// late that first copy arrived. Only first copies are learnt from: the
    /// reports are theirs, and the first of several copies is the least
    /// delayed.
    fn learn_delay(&mut self, g: &Group) {
        let first = g.copies[0];
        if !self.receivers[first.rx].arrival_dated {
            return;
        }
        let exact = g.copies[1..].iter().find_map(|c| {
            (self.receivers[c.rx].decl.clock == ClockKind::Gps && crate::feed::has_timing(c.timestamp))
                .then(|| ClockKind::gps_unix(c.timestamp, c.arrival))
        });
        if let Some(t) = exact {
            self.receivers[first.rx].delay.push(first.arrival - t);
        }
    }
}
