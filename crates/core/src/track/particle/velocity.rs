//! A velocity report (a Comm-B track and turn report) weighing the cloud.
//!
//! Until one is reported, the cloud's velocities are spread over every
//! airliner's (speeds of 60-300 m/s, every heading), and a report a few
//! metres per second wide, taken at once, leaves a handful of particles and
//! their positions with them: a cloud that looks tight wherever those few
//! happened to be. So a report is taken in steps (progressive correction,
//! Musso, Oudjane and Le Gland's remedy for a likelihood much narrower than
//! the prior): each step takes as much of the report as keeps the effective
//! sample size above the resampling share, and the cloud is resampled and
//! jittered (positions pulled back onto the newest transmission's surface)
//! before the next. The steps' likelihoods multiply to the report's, so the
//! posterior is the same; only the particles that carry it are renewed
//! between them. Where position and velocity are correlated in the cloud
//! (one receiver pair's hyperbola crossed at a rate that depends on where
//! along it the aircraft is), the report narrows the position too.
//!
//! A report no particle comes near, once the cloud has taken some, is left
//! out: a misread register, or an aircraft that turned, which the cloud's
//! straight-line motion does not follow. The next report tells which: one
//! that agrees with it confirms the change, and the cloud's velocities are
//! drawn again from it, positions kept.

use nalgebra::{Matrix2, Vector2, Vector4};
use rand::Rng;
use rand_distr::StandardNormal;

use super::surface::Differences;
use super::{SparseConfig, SparseTrack, LOST_CHI2};

/// Most steps one report is taken in; the last takes what is left of it.
const MAX_STEPS: usize = 8;
/// Two reports agree when they differ by less than this (chi-square, two
/// degrees of freedom: 0.1% of agreeing pairs differ more).
const AGREE_CHI2: f64 = 13.8;

/// A report that contradicted the cloud: its time, velocity and covariance.
pub(super) type Contradicting = (f64, Vector2<f64>, Matrix2<f64>);

/// What became of a velocity report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VelocityOutcome {
    /// Taken, in this many steps.
    Taken(u32),
    /// The cloud has taken reports before and no particle is near this
    /// one: a misread register, or a turn the cloud did not follow; left
    /// out until the next report says which.
    Contradicts,
    /// It agreed with the contradicting report before it: the aircraft
    /// turned or changed speed, and the cloud's velocities were drawn
    /// again from it.
    Redrawn,
    /// Not usable (a singular covariance, no transmission yet).
    Unusable,
}

impl SparseTrack {
    /// Moves the cloud to `t` and weighs it by a reported velocity `v_en`
    /// with covariance `cov` (m/s, east/north at the aircraft).
    pub fn velocity(
        &mut self,
        cfg: &SparseConfig,
        v_en: Vector2<f64>,
        cov: Matrix2<f64>,
        t: f64,
    ) -> VelocityOutcome {
        self.velocity_in(cfg, v_en, cov, t, MAX_STEPS)
    }

    /// [`Self::velocity`] in at most `max_steps` steps.
    fn velocity_in(
        &mut self,
        cfg: &SparseConfig,
        v_en: Vector2<f64>,
        cov: Matrix2<f64>,
        t: f64,
        max_steps: usize,
    ) -> VelocityOutcome {
        let (Some(info), Some(last)) = (cov.try_inverse(), self.last.as_ref()) else {
            return VelocityOutcome::Unusable;
        };
        let h = last.h;
        let Some(d) = Differences::new(&self.plane, &last.sites, h) else { return VelocityOutcome::Unusable };
        self.predict(cfg, t);
        let mut cost = self.velocity_cost(v_en, &info);
        let best = cost.iter().cloned().fold(f64::INFINITY, f64::min);
        if !best.is_finite() {
            return VelocityOutcome::Unusable;
        }
        if self.velocities > 0 && best > LOST_CHI2 {
            let confirmed = self.contradicting.is_some_and(|(t0, v0, cov0)| {
                let turn = cfg.accel_ms2 * (t - t0);
                let s = cov + cov0 + Matrix2::identity() * turn * turn;
                let r = v_en - v0;
                s.try_inverse().is_some_and(|i| (r.transpose() * i * r)[0] < AGREE_CHI2)
            });
            if !confirmed {
                self.contradicting = Some((t, v_en, cov));
                return VelocityOutcome::Contradicts;
            }
            self.contradicting = None;
            self.redraw_velocities(v_en, cov);
            return VelocityOutcome::Redrawn;
        }
        self.contradicting = None;
        let n = self.x.len() as f64;
        let floor = cfg.resample_below * n;
        if self.ess() < floor {
            // New particles: the costs are theirs to be weighed by.
            self.resample(&d, h);
            cost = self.velocity_cost(v_en, &info);
        }
        let (mut left, mut steps) = (1.0, 0);
        while left > 0.0 {
            steps += 1;
            let share =
                if steps as usize >= max_steps { left } else { self.largest_share(&cost, left, floor) };
            let scaled: Vec<f64> = cost.iter().map(|c| c * share).collect();
            self.reweigh(&scaled);
            left = if share >= left { 0.0 } else { left - share };
            if left > 0.0 || self.ess() < floor {
                self.resample(&d, h);
                cost = self.velocity_cost(v_en, &info);
            }
        }
        self.velocities += 1;
        VelocityOutcome::Taken(steps)
    }

    /// Draws every particle's velocity from the report (`v_en`, `cov` in
    /// the east/north where the particle is), positions and weights kept.
    fn redraw_velocities(&mut self, v_en: Vector2<f64>, cov: Matrix2<f64>) {
        let Some(l) = cov.cholesky().map(|c| c.l()) else { return };
        let turn = self.convergence();
        for i in 0..self.x.len() {
            let z = Vector2::new(self.rng.sample(StandardNormal), self.rng.sample(StandardNormal));
            let x = &mut self.x[i];
            let v = rotate(turn.at(x), v_en + l * z);
            (x[2], x[3]) = (v[0], v[1]);
        }
    }

    /// Each particle's chi-square against the report: its velocity turned
    /// from the cloud's plane into the east/north where it is.
    fn velocity_cost(&self, v_en: Vector2<f64>, info: &Matrix2<f64>) -> Vec<f64> {
        let turn = self.convergence();
        self.x
            .iter()
            .map(|x: &Vector4<f64>| {
                let r = rotate(-turn.at(x), Vector2::new(x[2], x[3])) - v_en;
                (r.transpose() * info * r)[0]
            })
            .collect()
    }

    /// How the east/north at a point of the cloud's plane is turned from
    /// the plane's own: the meridians' convergence, degrees a few hundred
    /// kilometres out. Exact at the cloud's mean, linear around it (what
    /// that leaves out is a few hundredths of a degree at 300 km); a
    /// particle's own would take a geodetic conversion each, most of a
    /// report's cost.
    fn convergence(&self) -> Convergence {
        let (m, _) = self.moments();
        let angle = |e: f64, n: f64| {
            let (lat, lon) = self.plane.to_geodetic(e, n);
            let r = self.plane.from_local(lat, lon);
            r[(1, 0)].atan2(r[(0, 0)])
        };
        const STEP_M: f64 = 10_000.0;
        let at = angle(m[0], m[1]);
        Convergence {
            origin: [m[0], m[1]],
            at,
            per_m: [(angle(m[0] + STEP_M, m[1]) - at) / STEP_M, (angle(m[0], m[1] + STEP_M) - at) / STEP_M],
        }
    }

    /// The effective sample size of the weights.
    pub(super) fn ess(&self) -> f64 {
        1.0 / self.w.iter().map(|w| w * w).sum::<f64>()
    }

    /// The largest share (at most `left`) of a likelihood with costs
    /// `cost` (chi-square) that leaves an effective sample size of at
    /// least `floor`: by bisection, the size falling as the share grows.
    fn largest_share(&self, cost: &[f64], left: f64, floor: f64) -> f64 {
        let best = cost.iter().cloned().fold(f64::INFINITY, f64::min);
        let ess = |share: f64| {
            let (mut s, mut s2) = (0.0, 0.0);
            for (w, c) in self.w.iter().zip(cost) {
                let v = w * (-0.5 * share * (c - best)).exp();
                s += v;
                s2 += v * v;
            }
            s * s / s2
        };
        if ess(left) >= floor {
            return left;
        }
        let (mut lo, mut hi) = (0.0, left);
        for _ in 0..30 {
            let mid = 0.5 * (lo + hi);
            if ess(mid) >= floor {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        // Some progress every step, however little the cloud can take.
        lo.max(left / 1e3)
    }
}

/// The turn of the local east/north against a plane's, linear around a point.
struct Convergence {
    origin: [f64; 2],
    at: f64,
    per_m: [f64; 2],
}

impl Convergence {
    /// The turn (rad) at particle `x`.
    fn at(&self, x: &Vector4<f64>) -> f64 {
        self.at + self.per_m[0] * (x[0] - self.origin[0]) + self.per_m[1] * (x[1] - self.origin[1])
    }
}

/// `v` turned by `angle` (rad, counter-clockwise).
fn rotate(angle: f64, v: Vector2<f64>) -> Vector2<f64> {
    let (s, c) = angle.sin_cos();
    Vector2::new(c * v[0] - s * v[1], s * v[0] + c * v[1])
}

#[cfg(test)]
mod tests;
