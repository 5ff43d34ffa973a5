//! The variational-Bayes learner of a source's measurement noise: how much
//! larger (or smaller) than its nominal covariance a source's errors are.
//!
//! A transponder's NACp is a claim, and an MLAT fix's covariance a model.
//! The noise actually seen is estimated Särkkä-Nummenmaa style, as an
//! inverse-gamma scale on the nominal covariance: each update's residual
//! teaches it, with forgetting towards the prior. A gated measurement's
//! innovation teaches it too (else a source claiming too much would be
//! gated forever), but held back (`Pending`) until it is clear the noise,
//! not the track, was wrong: taught if the track outlives the gated run or a
//! restart does not cure it, forgotten if a restart does. The track decides
//! when each of these happens; this type keeps the arithmetic.

use nalgebra::{Matrix6, Vector6};

use super::imm::Imm;

/// Inverse-gamma scale of a source's nominal measurement covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vb {
    pub alpha: f64,
    pub beta: f64,
}

impl Vb {
    fn prior(weight: f64) -> Vb {
        Vb { alpha: weight, beta: weight }
    }

    pub fn scale(&self) -> f64 {
        self.beta / self.alpha
    }
}

/// What gated innovations would teach the scale, held back until it is
/// clear whether the noise or the track was wrong. A track started on a wild
/// position (an MLAT fix 30 km off on tma-busy) gates every honest position
/// after it; taught at once, each raised the scale until they passed the gate
/// and the track crawled back over minutes instead of restarting.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Pending {
    alpha: f64,
    beta: f64,
    /// Gathered before the newest restart.
    before_restart: bool,
}

impl Pending {
    fn commit(&mut self, vb: &mut Vb) {
        vb.alpha += self.alpha;
        vb.beta += self.beta;
        *self = Pending::default();
    }
}

/// A noise scale this many times the one the covariance was built with
/// widens the covariance. At 1.25 the scale's own noise ratcheted it up
/// (fusion-8seg's fused NEES 1.98 -> 1.85, below its band); at 2 no
/// benchmark moves.
const WIDEN_AT_SCALE_RATIO: f64 = 2.0;

/// One source's noise scale as a track learns it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise {
    vb: Vb,
    pending: Pending,
    /// The scale when the filter's covariance last matched it (see `widen`).
    covered: f64,
}

impl Noise {
    /// A source's noise before anything is seen: the prior, of `weight`
    /// measurements' worth, at the nominal covariance.
    pub fn new(weight: f64) -> Noise {
        Noise { vb: Vb::prior(weight), pending: Pending::default(), covered: 1.0 }
    }

    /// The noise's scale on the nominal covariance.
    pub fn scale(&self) -> f64 {
        self.vb.scale()
    }

    /// Forgetting before a measurement: the posterior moves towards the
    /// prior's `weight` by `1 - rho`.
    pub fn forget(&mut self, rho: f64, weight: f64) {
        self.vb.alpha = rho * self.vb.alpha + (1.0 - rho) * weight;
        self.vb.beta = rho * self.vb.beta + (1.0 - rho) * weight;
    }

    /// An update's residual taught: `e` is the trace of the nominal
    /// covariance's inverse times the residual's expected outer product.
    pub fn learn(&mut self, e: f64) {
        self.vb.alpha += 1.0;
        self.vb.beta += 0.5 * e;
    }

    /// A measurement passed the gate. What gated ones held back is the
    /// noise's if gathered since the last restart (the track outlived
    /// them); from before it, forgotten once `cured` (the restart fixed the
    /// gating: the track was wrong, not the noise).
    pub fn accepted(&mut self, cured: bool) {
        if !self.pending.before_restart {
            self.pending.commit(&mut self.vb);
        } else if cured {
            self.pending = Pending::default();
        }
    }

    /// A measurement the gate left out, whose innovation would teach
    /// `excess`: held back. What was held from before a restart that did
    /// not cure the gating (`uncured`) is the noise's.
    pub fn gated(&mut self, excess: f64, uncured: bool) {
        if self.pending.before_restart && uncured {
            self.pending.commit(&mut self.vb);
        }
        self.pending.alpha += 1.0;
        self.pending.beta += 0.5 * excess;
    }

    /// The track restarts: what was held from before an earlier restart
    /// failed twice in a row, so it is the noise's; what is held now waits
    /// to see whether this restart cures it.
    pub fn restarting(&mut self) {
        if self.pending.before_restart {
            self.pending.commit(&mut self.vb);
        }
        self.pending.before_restart = true;
    }

    /// The nominal covariance changed by `1 / k` (a stand-in replaced by the
    /// source's own claim): the scale learnt is kept in metres.
    pub fn rebase(&mut self, k: f64) {
        self.vb.beta *= k;
        self.pending.beta *= k;
        self.covered *= k;
    }

    /// The filter's covariance was just built at the current scale.
    pub fn covered_now(&mut self) {
        self.covered = self.scale();
    }

    /// A filter's position covariance was built around the nominal noise at
    /// the scale of their time; once the noise is found several times larger,
    /// that covariance is too small by up to the same ratio, and with
    /// precise velocity reports nothing else widens it: the positions' gain
    /// stays as small as the claim made it and the early, believed errors
    /// stay in the estimate. So the position block grows by the ratio (cross
    /// terms by its root: a change of units, it stays positive definite).
    /// Smaller rises are left to the scale's own noise; falls only lower the
    /// reference.
    pub fn widen(&mut self, imm: &mut Imm) {
        let scale = self.scale();
        if scale > WIDEN_AT_SCALE_RATIO * self.covered {
            let a = (scale / self.covered).sqrt();
            let t = Matrix6::from_diagonal(&Vector6::new(a, a, 1.0, 1.0, 1.0, 1.0));
            for f in &mut imm.filters {
                f.p = t * f.p * t;
            }
            self.covered = scale;
        } else if scale < self.covered {
            self.covered = scale;
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::track::imm::ImmSpec;
    use crate::track::kf::Gaussian;

    #[test]
    fn a_scale_that_doubles_widens_the_position_block_only() {
        let cv = crate::track::models::MotionModel::ConstantVelocity { q: 1.0 };
        let spec = Arc::new(ImmSpec::new(vec![cv], nalgebra::DMatrix::identity(1, 1)));
        let p = Matrix6::from_fn(|i, j| if i == j { 4.0 } else { 1.0 });
        let mut imm = Imm::with_spec(spec, Gaussian { x: Vector6::zeros(), p });
        let mut noise = Noise { covered: 10.0, ..Noise::new(1.0) };
        let mut widen = |scale: f64, imm: &mut Imm| {
            noise.vb = Vb { alpha: 1.0, beta: scale };
            noise.widen(imm);
            noise.covered
        };
        assert_eq!(widen(19.0, &mut imm), 10.0);
        assert_eq!(imm.filters[0].p, p, "under twice: left to the scale's noise");
        assert_eq!(widen(40.0, &mut imm), 40.0);
        let q = imm.filters[0].p;
        assert_eq!((q[(0, 0)], q[(1, 1)], q[(0, 1)]), (16.0, 16.0, 4.0), "position block x4");
        assert_eq!((q[(0, 2)], q[(5, 1)]), (2.0, 2.0), "cross terms x2");
        assert_eq!(q.fixed_view::<4, 4>(2, 2), p.fixed_view::<4, 4>(2, 2), "velocity, acceleration kept");
        assert_eq!(widen(30.0, &mut imm), 30.0);
        assert_eq!(imm.filters[0].p, q, "a fall only lowers the reference");
        widen(59.0, &mut imm);
        assert_eq!(imm.filters[0].p, q, "twice is measured from the lowered reference");
        widen(61.0, &mut imm);
        assert!(imm.filters[0].p[(0, 0)] > 16.0 * 2.0);
    }

    #[test]
    fn held_back_teaching_is_the_noises_unless_a_restart_cures_the_gating() {
        let mut outlived = Noise::new(1.0);
        outlived.gated(8.0, false);
        assert_eq!(outlived.scale(), 1.0, "held back while gated");
        outlived.accepted(false);
        assert_eq!(outlived.scale(), 5.0 / 2.0, "the track outlived it: taught");

        let mut cured = Noise::new(1.0);
        cured.gated(8.0, false);
        cured.restarting();
        cured.accepted(true);
        assert_eq!(cured.scale(), 1.0, "a restart cured it: the track was wrong");

        let mut uncured = Noise::new(1.0);
        uncured.gated(8.0, false);
        uncured.restarting();
        uncured.gated(8.0, true);
        assert_eq!(uncured.scale(), 5.0 / 2.0, "gated again after the restart: the first run taught");
    }
}
