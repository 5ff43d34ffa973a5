//! What a decoded frame gives the tracker: its ADS-B position as a report
//! (NACp or NUCp to a sigma, its time of applicability and how it was
//! found), velocities, heights and identity as commands, and Comm-B track
//! and turn reports as velocities for aircraft without ADS-B.

use super::*;

impl Front {
    /// What a decoded frame tells the tracker: positions, velocities,
    /// altitudes, and identity.
    /// `timing`: the frame's time of applicability, for extended squitters;
    /// `correction`: what makes its barometric altitude a height (the one the
    /// MLAT solver is given).
    // Over 80 lines: one match over the message kinds, each arm a few lines.
    pub(super) fn feed_tracker(
        &mut self,
        cmds: &mut Vec<Cmd>,
        arrival: f64,
        timing: Option<(f64, Dating)>,
        d: &crate::modes::Decoded,
        report: Option<&PositionReport>,
        correction: Option<BaroCorrection>,
    ) {
        if !d.trusted() {
            return;
        }
        let addr = d.msg.addr;
        let tcfg = self.time_sigma;
        let baro_sigma_m = self.baro_sigma_m;
        let out = &mut *cmds;
        if let Some(p) = report {
            let Some(sigma) = p.sigma_m else {
                self.stats.untracked_positions += 1;
                return;
            };
            let time_sigma_s = match p.dating {
                Dating::Gps => tcfg.0,
                // The spread, and never below the GPS-timed sigma.
                Dating::Calibrated(spread) => spread.max(tcfg.0),
                Dating::Arrival => tcfg.1,
            };
            let m = Measurement {
                t: p.t,
                source: Source::Adsb,
                obs: Observation::Position {
                    lat: p.lat,
                    lon: p.lon,
                    cov_en: nalgebra::Matrix2::identity() * sigma * sigma,
                    height: p.alt_m.zip(p.alt_sigma_m.map(|s| s * s)),
                    time_sigma_s,
                    surface: p.surface,
                    claimed: p.nac_p.is_some_and(|n| n > 0),
                    persistent: SharedShare::default(),
                    adsb_echo: 0.0,
                },
            };
            out.push(Cmd::Measure { addr, nac_p: p.nac_p, m, now: arrival });
            if let Some(alt_ft) = p.alt_baro_ft {
                out.push(Cmd::AltBaro { addr, alt_ft });
            }
            return;
        }
        match d.commb {
            Some(Inference::Identified(Register::TrackTurn(r)))
                if self.commb_velocity && !d.commb_context.adsb_velocity_recent() =>
            {
                if let Some(m) = crate::core::commb::velocity(&r, arrival) {
                    self.stats.commb_velocities += 1;
                    out.push(Cmd::Measure { addr, nac_p: None, m, now: arrival });
                }
            }
            Some(Inference::Identified(Register::HeadingSpeed(r))) if self.commb_velocity => {
                let ctx = &d.commb_context;
                match ctx.adsb_velocity {
                    Some(v) => self.learn_wind(&r, ctx, v, arrival),
                    None => {
                        if let Some(m) = crate::core::commb::climb(&r, arrival) {
                            self.stats.commb_climbs += 1;
                            out.push(Cmd::Measure { addr, nac_p: None, m, now: arrival });
                        }
                        let heading = match self.commb_heading {
                            true => crate::core::commb::heading_velocity(&r, ctx, &self.wind, arrival),
                            false => None,
                        };
                        if let Some(m) = heading {
                            self.stats.commb_headings += 1;
                            out.push(Cmd::Measure { addr, nac_p: None, m, now: arrival });
                        }
                    }
                }
            }
            Some(Inference::Identified(Register::SelectedVertical(r))) => {
                if let Some(alt_ft) = r.mcp_alt_ft {
                    out.push(Cmd::NavAltitude { addr, alt_ft });
                }
            }
            _ => {}
        }
        let height_and_var = |alt_ft: i32| {
            let (h, sigma) = baro_height(alt_ft, correction, baro_sigma_m);
            (h, sigma * sigma)
        };
        match d.msg.body {
            Body::AirAir { alt_ft: Some(a), .. } | Body::Altitude { alt_ft: Some(a), .. } => {
                let (h, var) = height_and_var(a);
                let m = Measurement { t: arrival, source: Source::Mlat, obs: Observation::Height { h, var } };
                out.push(Cmd::Measure { addr, nac_p: None, m, now: arrival });
                out.push(Cmd::AltBaro { addr, alt_ft: a });
            }
            Body::Identity { squawk, .. } => out.push(Cmd::Squawk { addr, squawk }),
            Body::Extended(es) => match es.kind {
                Es::Identification { callsign, .. } => out.push(Cmd::Flight {
                    addr,
                    flight: crate::modes::fields::callsign_str(&callsign).to_string(),
                }),
                Es::Emergency { squawk, .. } => out.push(Cmd::Squawk { addr, squawk }),
                Es::Velocity(v) => {
                    let (Some(ve), Some(vn), Some((t_frame, _))) = (v.ve_kt, v.vn_kt, timing) else {
                        return;
                    };
                    // NACv's sigmas; unknown: wider than NACv 1's bounds.
                    let (h_sigma, v_sigma) = velocity_sigmas_ms(v.nac_v, (30.0, 100.0));
                    // Plus the 1 kt (or 4 kt supersonic) and 64 ft/min resolution.
                    let step = if v.subtype == 2 { 4.0 } else { 1.0 } * KT_TO_MS;
                    let hv = h_sigma.powi(2) + step * step / 12.0;
                    let climb = v.vrate_fpm.map(|r| {
                        (
                            r as f64 * FT_TO_M / 60.0,
                            v_sigma * v_sigma + (64.0 * FT_TO_M / 60.0).powi(2) / 12.0,
                        )
                    });
                    let m = Measurement {
                        t: t_frame,
                        source: Source::Adsb,
                        obs: Observation::Velocity {
                            v_en: nalgebra::Vector2::new(ve * KT_TO_MS, vn * KT_TO_MS),
                            cov: nalgebra::Matrix2::identity() * hv,
                            climb,
                        },
                    };
                    out.push(Cmd::Measure { addr, nac_p: None, m, now: arrival });
                }
                Es::AirbornePosition { alt_ft: Some(a), gnss: false, .. } => {
                    out.push(Cmd::AltBaro { addr, alt_ft: a })
                }
                _ => {}
            },
            _ => {}
        }
    }

    /// Learns the wind from an aircraft's heading and speed report and its
    /// ADS-B velocity, when that is fresh (the two a second apart at most).
    fn learn_wind(
        &mut self,
        r: &crate::modes::commb::Bds60,
        ctx: &crate::modes::commb::ReplyContext,
        v: crate::modes::commb::KnownVelocity,
        arrival: f64,
    ) {
        /// ADS-B ground velocity's error per axis (m/s): 1 kt steps and NACv 1 or better.
        const ADSB_SIGMA_MS: f64 = 1.0;
        if v.age_s > 1.0 {
            return;
        }
        let Some((air, alt_m)) = crate::core::commb::air_vector(r, ctx) else { return };
        let (s, c) = v.track_deg.to_radians().sin_cos();
        let ground = nalgebra::Vector2::new(s, c) * v.gs_kt * KT_TO_MS;
        let cov = nalgebra::Matrix2::identity() * ADSB_SIGMA_MS.powi(2);
        self.wind.learn(arrival, alt_m, &air, ground, cov, ctx.heading_reports);
    }

    /// The ADS-B position report of a decoded frame, if it has a published
    /// position; `correction` makes its barometric altitude a height.
    pub(super) fn position_report(
        &self,
        rx: usize,
        (t, dating): (f64, Dating),
        d: &crate::modes::Decoded,
        correction: Option<BaroCorrection>,
    ) -> Option<PositionReport> {
        let (Some(p), Body::Extended(es)) = (d.position.filter(|p| p.reliable), d.msg.body) else {
            return None;
        };
        let (alt_m, alt_baro_ft, alt_sigma_m) = match es.kind {
            Es::AirbornePosition { alt_ft: Some(a), gnss: true, .. } => {
                (Some(a as f64 * FT_TO_M), None, Some(15.0))
            }
            Es::AirbornePosition { alt_ft: Some(a), gnss: false, .. } => {
                let (h, sigma) = baro_height(a, correction, self.baro_sigma_m);
                (Some(h), Some(a), Some(sigma))
            }
            _ => (None, None, None),
        };
        Some(PositionReport {
            addr: d.msg.addr,
            t,
            lat: p.lat,
            lon: p.lon,
            alt_m,
            alt_baro_ft,
            alt_sigma_m,
            nac_p: d.nac_p,
            sigma_m: position_sigma_m(d.nac_p, d.nuc_p),
            dating,
            surface: p.surface,
            rx,
        })
    }
}
