//! Time differences as a track measures them: too few receivers for a fix
//! heard a transmission, and its two or three time differences, with the
//! vertical channel's height, go straight into the track through an
//! unscented transform linearised once at the combined prediction.
//!
//! Each site's persistent error (its learnt offset's, its clock
//! synchronisation's) is the same in every transmission: each counts it as
//! often as the track's own memory holds transmissions, direction by
//! direction (two differences are rarely known alike; `track::persistent`).

use super::*;
use nalgebra::{Matrix6, SMatrix};

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
        let mut prep = imm.prepare(dt);
        if let Some(seen) = self.state.seen_whole_t {
            prep.widen(&unseen_turn(&prep.combined(), t - seen, dt, self.cfg.largest_turn_rps()));
        }
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
            Some(nis) => {
                if sites.len() == 3 && self.state.seen_whole_t.is_some() {
                    self.state.seen_whole_t = Some(t);
                }
                Outcome::Applied { nis }
            }
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

/// What the aircraft may have done unseen: one time difference places it
/// on a curve, and where along the curve only the track's motion models
/// say. They follow a turn their measurements show; one they do not show
/// can have gone on since the position was last measured whole
/// (`unseen_s` ago), at up to the largest turn rate the models know
/// (`turn_rps`, rad/s) at the aircraft's speed: an acceleration `a` held
/// for `unseen_s` moves it `a unseen_s^2 / 2` off the straight line, where
/// the models' small process noise keeps it known to hundreds of metres
/// (docs/tracking.md). White acceleration whose density grows with the
/// time unseen, `3/4 a^2 unseen_s`, accumulated since then spreads the
/// position by `a unseen_s^2 / 4` (1 sigma): the largest turn held all
/// along is two sigmas off, a gentler one less. Each step's noise is a
/// covariance, as a held acceleration's increments are not.
fn unseen_turn(pred: &Gaussian, unseen_s: f64, dt: f64, turn_rps: f64) -> Matrix6<f64> {
    let mut q = Matrix6::zeros();
    if unseen_s <= 0.0 || dt <= 0.0 {
        return q;
    }
    let a = pred.x[2].hypot(pred.x[3]) * turn_rps;
    let density = 0.75 * a * a * unseen_s;
    for axis in 0..2 {
        let (p, v) = (axis, axis + 2);
        q[(p, p)] = density * dt.powi(3) / 3.0;
        q[(p, v)] = density * dt * dt / 2.0;
        q[(v, p)] = q[(p, v)];
        q[(v, v)] = density * dt;
    }
    q
}

/// `lin` with the sites' `persistent` errors added to its noise, each
/// counted as often as the track's memory (at `prior`) holds transmissions,
/// direction by direction ([`persistent::counted`]): two differences are
/// not known alike, and taken over both at once (their traces, which the
/// widest direction fills), the memory was the shorter one, and the
/// persistent error undercounted along the crossing.
fn with_persistent<const M: usize>(
    lin: Linear<M>,
    prior: &Gaussian,
    persistent: &[Persistent; 3],
) -> Linear<M> {
    if persistent.iter().all(|p| p.var_s2 == 0.0) {
        return lin;
    }
    let c2 = crate::mlat::solver::C_AIR.powi(2);
    // The differences are against the first site: its error is in each.
    let pattern =
        |v: [f64; 3]| SMatrix::<f64, M, M>::from_fn(|i, j| v[0] + if i == j { v[i + 1] } else { 0.0 });
    let state = lin.h * prior.p * lin.h.transpose();
    let once = pattern(persistent.map(|p| p.var_s2 * c2));
    let counted =
        super::persistent::counted(&lin.r, &state, &once, |n| pattern(persistent.map(|p| p.counted(n) * c2)));
    let r = lin.r + counted;
    lin.with_r(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Matrix6, SMatrix, Vector2, Vector6};

    /// Two differences the track knows unalike (its prior along the first
    /// half the fresh noise, along the second ten times it), with the
    /// persistent error of the second and third sites alone: each direction
    /// counts it as its own memory says, not as their traces' would.
    #[test]
    fn each_direction_counts_the_persistent_error_as_its_own_memory_holds() {
        let (r, p) = (100.0, 20.0);
        let c2 = crate::mlat::solver::C_AIR.powi(2);
        let h = SMatrix::<f64, 2, 6>::from_fn(|i, j| (i == j) as u8 as f64);
        let lin = Linear::new(h, Vector2::zeros(), Matrix2::identity() * r);
        let prior = Gaussian {
            x: Vector6::zeros(),
            p: Matrix6::from_diagonal(&Vector6::new(0.5 * r, 10.0 * r, 1.0, 1.0, 1.0, 1.0)),
        };
        let site = |var_m2: f64| Persistent { var_s2: var_m2 / c2, shared_by: 1e6 };
        let persistent = [site(0.0), site(p), site(p)];
        let counted = with_persistent(lin, &prior, &persistent).r - Matrix2::identity() * r;
        for (i, s) in [(0, 0.5 * r), (1, 10.0 * r)] {
            let n = Persistent::memory(s, r, p);
            assert!((counted[(i, i)] - n * p).abs() < 1e-6 * n * p, "{i}: {counted} against {}", n * p);
        }
        assert!(counted[(0, 1)].abs() < 1e-9, "{counted}");
        // The well-known direction remembers many more transmissions.
        assert!(counted[(0, 0)] > 4.0 * counted[(1, 1)], "{counted}");
    }
}
