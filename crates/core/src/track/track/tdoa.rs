//! Time differences as a track measures them: too few receivers for a fix
//! heard a transmission, and its two or three time differences, with the
//! vertical channel's height, go straight into the track through an
//! unscented transform linearised once at the combined prediction.
//!
//! Each site's persistent error (its learnt offset's) is the same in every
//! transmission: a filter taking them as independent would average it away.
//! Counted once for every transmission that shares it, it is right for a
//! filter that remembers them all, and too much for one whose process noise
//! forgets all but the last few: the track is then surer of the aircraft
//! than its estimate says. So each transmission counts it as often as the
//! track's own memory holds transmissions, found from how sure the track
//! already is along the measured differences ([`Persistent::memory`]).

use super::*;
use nalgebra::SMatrix;

impl Track {
    /// Time differences straight into the track (augmented UKF), with the
    /// vertical channel's height: what a transmission heard by too few
    /// receivers for a fix still says.
    pub(super) fn tdoa(
        &mut self,
        t: f64,
        dt: f64,
        sites: &[([f64; 3], f64, f64)],
        persistent: &[Persistent],
    ) -> Outcome {
        let (Some(plane), Some(imm), Some(v)) =
            (self.state.plane, self.state.imm.as_mut(), self.state.vertical)
        else {
            return Outcome::Early;
        };
        let mut v = v;
        v.predict(t - self.state.t_v, self.cfg.vertical_q);
        let c = crate::mlat::solver::C_AIR;
        if !(2..=3).contains(&sites.len()) {
            return Outcome::Gated;
        }
        let site = |i: usize| sites[i.min(sites.len() - 1)];
        let m = crate::track::ukf::Tdoa {
            n: sites.len(),
            receivers: std::array::from_fn(|i| plane.ecef_to_local(site(i).0)),
            sigma_m: std::array::from_fn(|i| site(i).2 * c),
            z: std::array::from_fn(|i| (site(i + 1).1 - sites[0].1) * c),
        };
        let (h, hv) = (v.x[0], v.p[(0, 0)]);
        let up = |e: f64, n: f64, h: f64| plane.up_at(e, n, h);
        let prep = imm.prepare(dt);
        // One unscented transform at the combined prediction, as a linear
        // regression every model applies (see `ukf`).
        let combined = prep.combined();
        let gate = self.gate;
        let persistent: [Persistent; 3] =
            std::array::from_fn(|i| persistent.get(i).copied().unwrap_or_default());
        let step = match m.n {
            2 => crate::track::ukf::linearise::<1>(&combined, h, hv, &m, up)
                .map(|lin| with_persistent(lin, &combined, &persistent))
                .and_then(|lin| Self::gated_update(imm, &prep, &lin, gate)),
            _ => crate::track::ukf::linearise::<2>(&combined, h, hv, &m, up)
                .map(|lin| with_persistent(lin, &combined, &persistent))
                .and_then(|lin| Self::gated_update(imm, &prep, &lin, gate)),
        };
        match step {
            Some(nis) => Outcome::Applied { nis },
            None => Outcome::Gated,
        }
    }

    /// A linear update unless the combined prediction's NIS is beyond the gate.
    fn gated_update<const M: usize>(
        imm: &mut Imm,
        prep: &crate::track::imm::Prepared,
        m: &Linear<M>,
        gate: Gate,
    ) -> Option<f64> {
        let (nu, s) = prep.combined().innovation(m);
        if !gate.admits(Gate::nis(&nu, &s)) {
            return None;
        }
        imm.update(prep, m).map(|s| s.nis)
    }
}

/// `lin` with the sites' `persistent` errors added to its noise, each
/// counted as often as the track's memory (at `prior`) holds transmissions.
fn with_persistent<const M: usize>(
    lin: Linear<M>,
    prior: &Gaussian,
    persistent: &[Persistent; 3],
) -> Linear<M> {
    let c2 = crate::mlat::solver::C_AIR.powi(2);
    // The differences are against the first site: its error is in each.
    let pattern =
        |v: [f64; 3]| SMatrix::<f64, M, M>::from_fn(|i, j| v[0] + if i == j { v[i + 1] } else { 0.0 });
    let state = lin.h * prior.p * lin.h.transpose();
    let once = pattern(persistent.map(|p| p.var_s2 * c2));
    let n = Persistent::memory(state.trace(), lin.r.trace(), once.trace());
    let r = lin.r + pattern(persistent.map(|p| p.counted(n) * c2));
    lin.with_r(r)
}
