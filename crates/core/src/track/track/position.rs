//! A horizontal position as a track measures it: the report in the
//! track's plane with its covariance turned there and widened by its time
//! error along the velocity, the gate, the variational-Bayes teaching of
//! the source's noise (held back while a gated run may be the track's
//! fault), restarts after too many gated in a row, and the plane re-centred
//! as the aircraft flies away from it.

use super::*;

impl Track {
    #[allow(clippy::too_many_arguments)]
    // Over 80 lines, kept whole: one measurement's model, gate and update
    // on the per-measurement path, sharing the prediction.
    pub(super) fn position(
        &mut self,
        t: f64,
        dt: f64,
        (lat, lon, cov_en): (f64, f64, Matrix2<f64>),
        time_sigma_s: f64,
        persistent: SharedShare,
        source: Source,
    ) -> Outcome {
        let (Some(plane), Some(imm)) = (self.state.plane, self.state.imm.as_mut()) else {
            self.start(lat, lon, cov_en);
            return Outcome::Applied { nis: 0.0 };
        };
        let z = Vector2::from(plane.to_en(lat, lon));
        // The covariance is given in the reporting point's east/north.
        let turn = plane.from_local(lat, lon);
        let cov_en = turn * cov_en * turn.transpose();
        let prep = imm.prepare(dt);
        let pred = prep.combined();
        // The report's time error moves it along the velocity.
        let v = pred.x.fixed_rows::<2>(2).into_owned();
        let nominal = cov_en + v * v.transpose() * (time_sigma_s * time_sigma_s);
        let nominal = with_shared(nominal, &cov_en, &pred.p, persistent);
        let noise = &mut self.state.noise[source as usize];
        if self.cfg.vb {
            let (rho, prior) = match source {
                Source::Adsb => (self.cfg.vb_forgetting_adsb, self.cfg.vb_prior_adsb),
                Source::Mlat => (self.cfg.vb_forgetting, self.cfg.vb_prior),
            };
            noise.forget(rho, prior);
        }
        let Some(nom_inv) = nominal.try_inverse() else {
            return Outcome::Gated;
        };
        let h = kf::h();
        let base = Linear::new(h, z, nominal);
        let linear = |scale: f64| base.with_r(nominal * scale);
        let nis = {
            let (nu, s) = pred.innovation(&linear(noise.scale()));
            Gate::nis(&nu, &s)
        };
        if !self.gate.admits(nis) {
            // What the innovation would teach the scale, no more than one on
            // the gate would: one wild position must not carry the scale past
            // the gate alone.
            let excess = self.cfg.vb.then(|| {
                let (nu, _) = pred.innovation(&linear(1.0));
                let nu = nu * (self.gate.threshold() / nis).sqrt().min(1.0);
                let hph = h * pred.p * h.transpose();
                (nom_inv * (nu * nu.transpose() - hph)).trace().max(0.0)
            });
            return self.gated(source, excess, (lat, lon, cov_en));
        }
        self.state.gated_in_a_row = 0;
        self.state.accepted_since_start += 1;
        self.state.seen_whole_t = None;
        // Outliers the track outlived were the noise's; those before a
        // restart that cured the gating, the track's.
        let cured = self.state.accepted_since_start >= self.cfg.max_gated_in_a_row;
        noise.accepted(cured);
        // One variational step per measurement: update with the current noise
        // scale, then the scale's posterior from that update's residual.
        // Iterating the two to a fixed point (up to three updates) changed
        // no figure of the fusion or VB scenarios and cost 10% of the pipeline.
        //
        // Not over a track's first positions after a (re)start, while its
        // velocity is still unknown: their residuals are the velocity's, the
        // scale they taught made the next updates trust the positions less,
        // so the velocity came later and the residuals grew again (a source
        // claiming 25 m with 100 m errors, 16 in scale, taught 320 within
        // 17 s; with ADS-B's long memory it took a minute to come down).
        let done = imm.update(&prep, &linear(noise.scale()));
        let settled = self.state.accepted_since_start > self.cfg.max_gated_in_a_row;
        if let (Some(step), true, true) = (done, self.cfg.vb, settled) {
            let post = step.estimate;
            let res = z - h * post.x;
            let e = nom_inv * (res * res.transpose() + h * post.p * h.transpose());
            noise.learn(e.trace());
        }
        if self.cfg.vb {
            noise.widen(imm);
        }
        match done {
            Some(step) => {
                if self.keep_gain {
                    self.gain = gain(&pred, &step.estimate).map(|a| (t, a));
                }
                self.maybe_recentre(&step.estimate.x);
                Outcome::Applied { nis: step.nis }
            }
            None => {
                tracing::warn!("track filter went numerically bad; restarted");
                self.restarts += 1;
                self.start(lat, lon, cov_en);
                Outcome::Restarted
            }
        }
    }

    /// A position the gate left out: what its innovation would teach the
    /// scale (`excess`, with VB) is held back until it is clear the noise and
    /// not the track is wrong ([`Noise::gated`]), and too many in a row restart the
    /// track on it (`at`: its position and covariance in the plane).
    pub(super) fn gated(
        &mut self,
        source: Source,
        excess: Option<f64>,
        at: (f64, f64, Matrix2<f64>),
    ) -> Outcome {
        self.state.gated_in_a_row += 1;
        if let Some(excess) = excess {
            // A restart that did not cure the gating: the measurements are noisy.
            let uncured = self.state.accepted_since_start < self.cfg.max_gated_in_a_row;
            self.state.noise[source as usize].gated(excess, uncured);
        }
        if self.state.gated_in_a_row > self.cfg.max_gated_in_a_row {
            self.restarts += 1;
            for noise in &mut self.state.noise {
                noise.restarting();
            }
            let (lat, lon, cov_en) = at;
            self.start(lat, lon, cov_en);
            return Outcome::Restarted;
        }
        Outcome::Gated
    }

    /// A source's nominal noise changes from a stand-in to its own claim
    /// (the NACp arrives): what the scale learned under the stand-in is the
    /// real noise, so it is kept in metres, not as a ratio to a nominal that
    /// no longer applies. (vb-noise sends NACp every 10 s: a transponder
    /// honestly claiming NACp 6 was first judged against the 38 m stand-in,
    /// and the ratio learned then, carried into its real claim, made its
    /// ADS-B track 486 m RMS against 189 m without VB.)
    pub(super) fn rebase_vb(&mut self, source: Source, trace: f64, claimed: bool) {
        let i = source as usize;
        if let Some((old, false)) = self.state.nominal[i] {
            if self.cfg.vb && claimed && old > 0.0 && trace > 0.0 {
                self.state.noise[i].rebase(old / trace);
            }
        }
        self.state.nominal[i] = Some((trace, claimed));
    }

    /// (Re)starts the horizontal filter on a position: velocity unknown.
    pub(super) fn start(&mut self, lat: f64, lon: f64, cov_en: Matrix2<f64>) {
        let plane = Plane::new(lat, lon, self.state.vertical.map_or(0.0, |v| v.x[0]));
        let vs = INIT_SPEED_SIGMA * INIT_SPEED_SIGMA;
        let va = INIT_ACCEL_SIGMA * INIT_ACCEL_SIGMA;
        let mut p = Matrix6::from_diagonal(&Vector6::new(0.0, 0.0, vs, vs, va, va));
        p.fixed_view_mut::<2, 2>(0, 0).copy_from(&cov_en);
        self.state.plane = Some(plane);
        let spec = Self::spec_at(&self.specs, self.state.t).clone();
        self.state.imm = Some(Imm::with_spec(spec, Gaussian { x: Vector6::zeros(), p }));
        self.state.gated_in_a_row = 0;
        self.state.accepted_since_start = 0;
        self.state.seen_whole_t = None;
        for noise in &mut self.state.noise {
            noise.covered_now();
        }
    }

    /// Starts the track at `t` from an estimate made elsewhere (a particle
    /// cloud with one mode): its position and velocity, in `plane`, with
    /// their covariance; the acceleration unknown, as at any start. What the
    /// track took before (heights, Comm-B velocities) stays in its vertical
    /// channel; its history of measurements goes, as a measurement older
    /// than the start can no longer be put in its place.
    pub fn start_from(&mut self, t: f64, plane: Plane, g: &Gaussian) {
        let va = INIT_ACCEL_SIGMA * INIT_ACCEL_SIGMA;
        let mut p = g.p;
        p[(4, 4)] = va;
        p[(5, 5)] = va;
        self.state.plane = Some(plane);
        let spec = Self::spec_at(&self.specs, t).clone();
        self.state.imm = Some(Imm::with_spec(spec, Gaussian { x: g.x, p }));
        self.state.t = self.state.t.max(t);
        self.state.t_h = t;
        self.state.gated_in_a_row = 0;
        self.state.accepted_since_start = 0;
        self.state.seen_whole_t = Some(t);
        for noise in &mut self.state.noise {
            noise.covered_now();
        }
        self.history.clear();
        self.started_from_cloud = true;
    }

    /// `x`: the filter's newest combined estimate.
    pub(super) fn maybe_recentre(&mut self, x: &Vector6<f64>) {
        let (Some(plane), Some(imm)) = (self.state.plane, self.state.imm.as_mut()) else {
            return;
        };
        let h = self.state.vertical.map_or(plane.h, |v| v.x[0]);
        if x[0].hypot(x[1]) < RECENTRE_M && (h - plane.h).abs() < REHEIGHT_M {
            return;
        }
        let (lat, lon) = plane.to_geodetic(x[0], x[1]);
        let new = Plane::new(lat, lon, h);
        for f in &mut imm.filters {
            *f = transfer(f, &plane, &new);
        }
        self.state.plane = Some(new);
    }
}

/// The `nominal` noise of a position with its `persistent` share of
/// `cov_en` counted as often as the track's memory (its prior covariance
/// `prior_p`, taken to the plane's position) holds positions, at most as
/// often as it is shared ([`super::persistent::counted`]); the rest taken as
/// the position's own. Nothing is computed for a position with no share
/// (every ADS-B one).
fn with_shared(
    nominal: Matrix2<f64>,
    cov_en: &Matrix2<f64>,
    prior_p: &Matrix6<f64>,
    persistent: SharedShare,
) -> Matrix2<f64> {
    if !persistent.share.is_finite() || persistent.share <= 0.0 {
        return nominal;
    }
    let state = kf::h() * prior_p * kf::h().transpose();
    let once = cov_en * persistent.share.min(1.0);
    let fresh = nominal - once;
    let shared_by = persistent.shared_by.max(1.0);
    fresh + super::persistent::counted(&fresh, &state, &once, |n| once * n.min(shared_by).max(1.0))
}
