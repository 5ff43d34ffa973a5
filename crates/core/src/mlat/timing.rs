//! A receiver's timing as its data shows it, learnt online: a Gaussian core
//! (its sigma, and a constant offset against the network) and late outliers
//! (multipath: a reflected path arrives late, never early, so the tail is
//! one-sided and heavy).
//!
//! Learnt from leave-one-out residuals of over-determined fixes: a
//! residual divided by `1 - leverage` is the receiver's error against what
//! the others say. Each is split between the core and the late tail by its
//! posterior under the model as it stands (an online EM step with
//! exponential forgetting). A plain running mean of squared residuals counted
//! every late copy into the sigma: a 25 ns receiver with 5% of its copies
//! 300 ns late looked like a 50 ns one, its good copies were under-weighted
//! and its late ones still failed whole groups.
//!
//! The tail is an exponential delay added to the core (an exponentially
//! modified Gaussian), so that a copy a little late is weighed by both.
//! The model starts from a prior per clock kind worth [`PRIOR_WEIGHT`]
//! residuals, so a handful of residuals cannot move it far.

/// Residuals the prior is worth.
pub const PRIOR_WEIGHT: f64 = 50.0;
/// Exponential memory (residuals): long enough for a sigma good to a few
/// per cent, short enough to follow a receiver whose timing changes.
const MEMORY: f64 = 400.0;
/// Step of the offset towards each (core) residual. Offsets of receivers
/// that share fixes are coupled: a small step converges where jumping to
/// each residual oscillates.
const OFFSET_STEP: f64 = 0.05;
/// Prior share of late copies and their prior mean delay (s).
const PRIOR_LATE_RATE: f64 = 0.02;
const PRIOR_LATE_MEAN_S: f64 = 300e-9;
/// The learnt late share is kept in this range: at zero the tail could
/// never be learnt again, and a receiver late more often than not has no
/// core to speak of (its copies are then mostly dropped as outliers).
const LATE_RATE_RANGE: (f64, f64) = (0.002, 0.5);
/// Off by more than this many sigmas of its core, a copy is more than any
/// core explains: late by multipath if late, a glitch if early.
pub const GLITCH_Z: f64 = 6.0;
/// A learnt offset is applied only after this many residuals.
pub const MIN_RESIDUALS: u64 = 20;

/// What has been learnt about one receiver's timing.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TimingModel {
    /// Residuals contributing.
    pub n: u64,
    /// Mean timing error of the core (s), removed from its timestamps.
    pub offset_s: f64,
    /// Variance of the core about the offset (s^2), as its fixes see it:
    /// its clock synchronisation's share included.
    pub var_s2: f64,
    /// Share of copies late, and their mean extra delay (s).
    pub late_rate: f64,
    pub late_mean_s: f64,
}

/// A receiver's timing as the configuration gives it (`[receiver.timing]`):
/// taken as it is and never learnt. For a receiver whose timing was measured
/// elsewhere, and for oracle runs that tell how far learning falls short of
/// knowing (`sim` writes one for each scenario).
#[derive(Clone, Copy, Debug, serde::Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct KnownTiming {
    /// Its timing noise, 1 sigma (ns).
    pub sigma_ns: f64,
    /// Its constant offset against the network (ns), removed from its times.
    #[serde(default)]
    pub offset_ns: f64,
    /// Share of its copies late (multipath), and their mean extra delay (ns).
    #[serde(default)]
    pub late_rate: f64,
    #[serde(default = "KnownTiming::default_late_delay_ns")]
    pub late_delay_ns: f64,
}

impl KnownTiming {
    fn default_late_delay_ns() -> f64 {
        PRIOR_LATE_MEAN_S * 1e9
    }

    /// What is wrong with it, if anything.
    pub fn check(&self) -> Result<(), String> {
        if !(self.sigma_ns > 0.0 && self.sigma_ns.is_finite()) {
            return Err(format!("sigma_ns = {}: positive", self.sigma_ns));
        }
        if !self.offset_ns.is_finite() {
            return Err("offset_ns must be finite".into());
        }
        if !(0.0..1.0).contains(&self.late_rate) {
            return Err(format!("late_rate = {}: from 0 to below 1", self.late_rate));
        }
        if !(self.late_delay_ns > 0.0 && self.late_delay_ns.is_finite()) {
            return Err(format!("late_delay_ns = {}: positive", self.late_delay_ns));
        }
        Ok(())
    }

    /// The model it stands for, counted as learnt.
    pub fn model(&self) -> TimingModel {
        TimingModel {
            n: MEMORY as u64,
            offset_s: self.offset_ns * 1e-9,
            var_s2: (self.sigma_ns * 1e-9).powi(2),
            late_rate: self.late_rate,
            late_mean_s: self.late_delay_ns * 1e-9,
        }
    }
}

/// How a residual sits under a receiver's model.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Verdict {
    /// Posterior probability that the copy is a late one.
    pub p_late: f64,
    /// Normalised residual under the core alone.
    pub z: f64,
}

impl Verdict {
    /// An outlier: late by the model's odds, or off by more than any
    /// Gaussian core explains (an early copy cannot be multipath; a glitch).
    pub fn outlier(&self) -> bool {
        self.p_late > 0.5 || self.z.abs() > GLITCH_Z
    }

    /// How strongly (to pick the worst of several).
    pub fn score(&self) -> f64 {
        self.p_late.max((self.z.abs() / GLITCH_Z).min(1.0)) + self.z.abs() * 1e-3
    }
}

impl TimingModel {
    /// The prior of a receiver whose configured jitter is `sigma_s`.
    pub fn prior(sigma_s: f64) -> Self {
        TimingModel {
            n: 0,
            offset_s: 0.0,
            var_s2: sigma_s * sigma_s,
            late_rate: PRIOR_LATE_RATE,
            late_mean_s: PRIOR_LATE_MEAN_S,
        }
    }

    /// The core sigma (s).
    pub fn sigma(&self) -> f64 {
        self.var_s2.sqrt()
    }

    /// The offset to remove from its timestamps (s): none until learnt.
    pub fn offset(&self) -> f64 {
        if self.learnt() {
            self.offset_s
        } else {
            0.0
        }
    }

    /// How far its variance may be above the estimate (a factor, three
    /// standard errors): a variance averaged over `k` Gaussian residuals is
    /// uncertain by sqrt(2 / k), the prior counting as [`PRIOR_WEIGHT`] and
    /// the memory keeping no more than [`MEMORY`].
    pub fn variance_doubt(&self) -> f64 {
        let k = (self.n as f64 + PRIOR_WEIGHT).min(MEMORY);
        1.0 + 3.0 * (2.0 / k).sqrt()
    }

    pub fn learnt(&self) -> bool {
        self.n >= MIN_RESIDUALS
    }

    /// The variance (s^2) of the learnt offset's error: what an exponential
    /// average of the core's residuals with [`OFFSET_STEP`] wanders by.
    pub fn offset_var(&self) -> f64 {
        self.var_s2 * OFFSET_STEP / (2.0 - OFFSET_STEP)
    }

    /// How many residuals an error of the learnt offset lasts for.
    pub const OFFSET_MEMORY: f64 = 1.0 / OFFSET_STEP;

    /// A leave-one-out residual `d` (s, measured minus the others' model,
    /// its offset already removed) whose core variance is `var_s2`
    /// (receiver, sync and the others' prediction together).
    pub fn verdict(&self, d: f64, var_s2: f64) -> Verdict {
        let s = var_s2.max(1e-24).sqrt();
        let z = d / s;
        // The log-odds of late against core: the core a Gaussian, the late
        // copies a Gaussian plus an exponential delay of rate l, whose
        // density is (l/2) exp(l/2 (l s^2 - 2d)) erfc(x). Every copy of
        // every fix is judged, several times, so the logarithms are
        // gathered into one.
        let l = 1.0 / self.late_mean_s;
        let x = (l * s * s - d) / (s * std::f64::consts::SQRT_2);
        let (t, poly) = erfc_parts(x.abs());
        let (erfc_factor, erfc_exp) = if x >= 0.0 { (t, poly) } else { (2.0 - t * poly.exp(), 0.0) };
        let odds = self.late_rate / (1.0 - self.late_rate) * 0.5 * l * s * erfc_factor;
        let ln_odds = odds.ln() + erfc_exp + LN_SQRT_2PI + 0.5 * z * z + 0.5 * l * (l * s * s - 2.0 * d);
        let p_late = 1.0 / (1.0 + (-ln_odds).exp());
        Verdict { p_late, z }
    }

    /// How a residual `r` (s) of a copy with leverage `h` in its fix (0 for
    /// a copy left out, judged against the fix of the others) sits under
    /// the model, `var_s2` its variance as the fix weighted it: the
    /// residual and its variance are taken to the leave-one-out ones
    /// (E[r^2] = sigma^2 (1 - h) in the fit; the leave-one-out residual
    /// r / (1 - h) has variance sigma^2 / (1 - h)). The leverage is taken
    /// as it is up to 0.999: a precise receiver among sloppy ones has 0.99
    /// and more, and capping it lower made its late copies look checkable
    /// when they were not.
    pub fn judge(&self, r: f64, h: f64, var_s2: f64) -> Verdict {
        let keep = 1.0 - h.clamp(0.0, 0.999);
        self.verdict(r / keep, var_s2 / keep)
    }

    /// One residual: `r` (s) at a fix that used the copy (leverage `h`), or
    /// a left-out copy's residual against the fix of the others (`h` 0);
    /// `sync_var_s2` is the clock synchronisation's share of its variance
    /// (beside the model's own in judging it).
    /// Returns the step its offset took (see [`TimingModel::shift`]).
    pub fn learn(&mut self, r: f64, h: f64, sync_var_s2: f64) -> f64 {
        self.learn_against(r, h, sync_var_s2, 0.0)
    }

    /// [`TimingModel::learn`] with the offset's lesson shifted (see
    /// [`TimingModel::learn_shifted`]).
    pub fn learn_against(&mut self, r: f64, h: f64, sync_var_s2: f64, shift: f64) -> f64 {
        let v = self.judge(r, h, self.var_s2 + sync_var_s2);
        self.learn_shifted(r, h, v, shift)
    }

    /// [`TimingModel::learn`] with the residual already judged (`v`, as
    /// [`TimingModel::judge`] gave it with the model's variance and the
    /// sync's), and the offset stepping towards `r + shift` instead of `r`:
    /// what the receiver's offset moves in the fix is not its copy alone (see
    /// [`Residual`]). The copy's own residual still teaches the core's
    /// variance and the late tail.
    pub fn learn_shifted(&mut self, r: f64, h: f64, v: Verdict, shift: f64) -> f64 {
        let h = h.clamp(0.0, 0.95);
        let d = r / (1.0 - h);
        if v.outlier() && v.p_late < 0.5 {
            // Early beyond any core: a glitch (or a wrong position), which
            // says nothing about the core or the tail.
            return 0.0;
        }
        self.n += 1;
        let a = 1.0 / (self.n as f64 + PRIOR_WEIGHT).min(MEMORY);
        let core = 1.0 - v.p_late;
        let step = OFFSET_STEP * core * (r + shift);
        self.offset_s += step;
        // The core's variance from its share of this residual, the clock
        // synchronisation's part left in: sync errors shared by receivers
        // converted through the same pairs partly cancel in the residuals
        // while still moving the fix, so taking them out made the fixes
        // overconfident on a counter-timed world (left in, they are a little
        // conservative).
        self.var_s2 += a * core * (r * r / (1.0 - h) - self.var_s2);
        // Never below a tenth of a nanosecond.
        self.var_s2 = self.var_s2.max(1e-20);
        let rate = self.late_rate + a * (v.p_late - self.late_rate);
        if v.p_late > 1e-3 {
            // The delay beyond the core: what the residual exceeds zero by.
            let w = a * v.p_late / rate.max(1e-9);
            self.late_mean_s += w.min(1.0) * (d.max(0.0) - self.late_mean_s);
        }
        self.late_rate = rate.clamp(LATE_RATE_RANGE.0, LATE_RATE_RANGE.1);
        self.late_mean_s = self.late_mean_s.max(3.0 * self.sigma()).max(10e-9);
        step
    }

    /// Moves the offset by `ds` (s): the engine keeps the offsets of a fix's
    /// receivers summing to what they did, since only their differences are
    /// observed (a common offset is the emission time's).
    pub fn shift(&mut self, ds: f64) {
        self.offset_s += ds;
    }
}

/// ln sqrt(2 pi).
const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_8;

/// erfc(z) for z >= 0 as `t * exp(poly)`, apart so that its logarithm
/// neither underflows for large z nor costs a logarithm of its own
/// (Chebyshev fit, fractional error below 1.2e-7 everywhere).
pub(crate) fn erfc_parts(z: f64) -> (f64, f64) {
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    (t, poly)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Exp, Normal};

    /// erfc from its parts, for either sign.
    fn erfc(x: f64) -> f64 {
        let (t, poly) = erfc_parts(x.abs());
        let e = t * poly.exp();
        if x >= 0.0 {
            e
        } else {
            2.0 - e
        }
    }

    #[test]
    fn erfc_matches_known_values() {
        for (x, v) in [(0.0, 1.0), (1.0, 0.157_299_207), (-1.0, 1.842_700_793), (5.0, 1.537_459_8e-12)] {
            assert!((erfc(x) / v - 1.0).abs() < 1e-6, "x {x}: {} against {v}", erfc(x));
        }
        // Far out, its logarithm still holds where erfc itself underflows.
        let (t, poly) = erfc_parts(40.0);
        assert!((t.ln() + poly - (-1600.0 - (40.0 * std::f64::consts::PI.sqrt()).ln())).abs() < 1e-3);
    }

    #[test]
    fn the_verdict_is_the_posterior_of_the_two_densities() {
        let m = TimingModel { late_rate: 0.07, late_mean_s: 250e-9, ..TimingModel::prior(40e-9) };
        let var = (45e-9f64).powi(2);
        let s = var.sqrt();
        for d in [-200e-9, -60e-9, 0.0, 30e-9, 90e-9, 150e-9, 400e-9, 1.5e-6] {
            let core = (1.0 - m.late_rate) * (-0.5 * (d / s).powi(2)).exp()
                / (s * (2.0 * std::f64::consts::PI).sqrt());
            let l = 1.0 / m.late_mean_s;
            let late = m.late_rate
                * 0.5
                * l
                * (0.5 * l * (l * s * s - 2.0 * d)).exp()
                * erfc((l * s * s - d) / (s * std::f64::consts::SQRT_2));
            let want = late / (late + core);
            let got = m.verdict(d, var).p_late;
            assert!((got - want).abs() < 1e-6, "d {d}: {got} against {want}");
        }
        // Never late at all: never judged late.
        let clean = TimingModel { late_rate: 0.0, ..m };
        assert_eq!(clean.verdict(400e-9, var).p_late, 0.0);
    }

    /// Residuals of a receiver with the given core, offset and late tail.
    fn learn_from(sigma: f64, offset: f64, late: (f64, f64), n: usize, seed: u64) -> TimingModel {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let core = Normal::new(0.0, sigma).unwrap();
        let delay = Exp::new(1.0 / late.1).unwrap();
        let mut m = TimingModel::prior(50e-9);
        for _ in 0..n {
            let mut e = offset + core.sample(&mut rng);
            if rng.gen::<f64>() < late.0 {
                e += delay.sample(&mut rng);
            }
            // A fit absorbs the share `h` of a copy's error, and the others'
            // errors move it: its residual's variance is sigma^2 (1 - h).
            // The model's offset is removed before the fit, as the engine does.
            let h: f64 = 0.3;
            let others = (h * (1.0 - h)).sqrt() * core.sample(&mut rng);
            m.learn((e - m.offset()) * (1.0 - h) + others, h, 0.0);
        }
        m
    }

    #[test]
    fn the_core_sigma_is_learnt_apart_from_the_late_copies() {
        // 25 ns with 5% of copies 300 ns late: a running mean of squares
        // would say about 70 ns.
        for (seed, sigma, late) in
            [(1, 25e-9, (0.05, 300e-9)), (2, 60e-9, (0.15, 800e-9)), (3, 150e-9, (0.02, 100e-9))]
        {
            let m = learn_from(sigma, 40e-9, late, 5000, seed);
            let rel = m.sigma() / sigma - 1.0;
            assert!(rel.abs() < 0.15, "sigma {:.1} ns for {:.0} ns", m.sigma() * 1e9, sigma * 1e9);
            assert!((m.offset_s - 40e-9).abs() < 0.3 * sigma.max(20e-9), "offset {:.1} ns", m.offset_s * 1e9);
            if late.1 > 4.0 * sigma {
                assert!(
                    (m.late_rate - late.0).abs() < 0.4 * late.0,
                    "late rate {} for {}",
                    m.late_rate,
                    late.0
                );
                assert!(
                    (m.late_mean_s / late.1 - 1.0).abs() < 0.35,
                    "late mean {:.0} ns",
                    m.late_mean_s * 1e9
                );
            }
        }
    }

    #[test]
    fn a_clean_receiver_learns_no_tail() {
        let m = learn_from(30e-9, 0.0, (0.0, 1e-6), 5000, 4);
        assert!(m.late_rate < 0.01, "late rate {}", m.late_rate);
        assert!((m.sigma() / 30e-9 - 1.0).abs() < 0.1, "sigma {:.1} ns", m.sigma() * 1e9);
    }

    #[test]
    fn a_late_copy_is_an_outlier_and_an_early_one_of_the_same_size_is_not_late() {
        let m = TimingModel { late_rate: 0.1, late_mean_s: 400e-9, ..TimingModel::prior(30e-9) };
        let var = (30e-9f64).powi(2);
        assert!(m.verdict(300e-9, var).outlier());
        assert!(m.verdict(300e-9, var).p_late > 0.99);
        assert!(m.verdict(-300e-9, var).p_late < 0.01);
        // An early copy that far off is still no part of the core: a glitch.
        assert!(m.verdict(-300e-9, var).outlier());
        assert!(!m.verdict(40e-9, var).outlier());
    }
}

/// One fix's lesson for one receiver's timing model. `shift_s` is what the
/// offset's lesson differs from the copy's residual by: a GPS-timed
/// receiver's learnt bias also moves the counter-timed copies whose times
/// came through it, so its offset learns from all of them together (their
/// weighted mean residual), and those copies' own offsets from what they
/// differ from that mean. (Taught by its own copy alone, a GPS receiver
/// among counters synchronised through it could not see its bias, which
/// moved them all alike, and the bias wandered by microseconds.)
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Residual {
    /// A copy in the fix, with the verdict the fix was hedged with.
    Judged {
        rx: u32,
        r: f64,
        h: f64,
        v: Verdict,
        used_offset_s: f64,
        #[serde(default)]
        shift_s: f64,
    },
    /// A copy judged here against the model's variance and the sync's (`var`).
    Against {
        rx: u32,
        r: f64,
        h: f64,
        var: f64,
        used_offset_s: f64,
        #[serde(default)]
        shift_s: f64,
    },
}

impl Residual {
    #[inline]
    pub fn rx(&self) -> usize {
        match *self {
            Residual::Judged { rx, .. } | Residual::Against { rx, .. } => rx as usize,
        }
    }

    /// The residual against a model whose offset is now `offset_s`: the
    /// fix removed `used_offset_s` from the copy's time. (A cluster's clock
    /// service learns from fixes made with its models of a moment ago;
    /// taken as they came, a burst of fixes made before a correction
    /// arrived applied that correction once each, and the offsets swung.)
    #[inline]
    fn against(&self, offset_s: f64) -> f64 {
        match *self {
            // The difference first: exactly zero, and so the residual
            // exactly as it was, when nothing moved in between (one node).
            Residual::Judged { r, used_offset_s, .. } | Residual::Against { r, used_offset_s, .. } => {
                r + (used_offset_s - offset_s)
            }
        }
    }
}

/// Receivers' timing models by index: the engine's receivers, or the
/// cluster clock service's plain list.
pub trait TimingModels {
    fn model(&mut self, rx: usize) -> &mut TimingModel;
}

impl TimingModels for Vec<TimingModel> {
    fn model(&mut self, rx: usize) -> &mut TimingModel {
        &mut self[rx]
    }
}

/// One fix's lessons being taught, one receiver at a time (in the order
/// the fix judged them), and the common step taken back at the end unless
/// the fix was anchored.
#[derive(Default)]
pub struct Lessons {
    sum: f64,
    moved: smallvec::SmallVec<[usize; 16]>,
    anchored: bool,
}

impl Lessons {
    /// A fix's lessons; `anchored` when it had a receiver whose timing is
    /// given (the configuration's `[receiver.timing]`): its offset is the
    /// time scale, so the learning receivers' offsets are measured against
    /// it and their common step is kept. (Taken back, a lone learning
    /// receiver among given ones could never move, and several kept
    /// whatever common error they started with, against the given ones'
    /// absolute offsets.)
    pub fn new(anchored: bool) -> Lessons {
        Lessons { anchored, ..Lessons::default() }
    }

    #[inline]
    pub fn teach(&mut self, r: &Residual, models: &mut impl TimingModels) {
        let m = models.model(r.rx());
        let d = r.against(m.offset());
        self.sum += match *r {
            Residual::Judged { h, v, shift_s, .. } => m.learn_shifted(d, h, v, shift_s),
            Residual::Against { h, var, shift_s, .. } => m.learn_against(d, h, var, shift_s),
        };
        self.moved.push(r.rx());
    }

    /// Only differences of offsets are observed (a common offset is the
    /// emission time's): without an anchor the lessons' common step is
    /// taken back, or it would wander. Returns the receivers whose offsets
    /// moved.
    #[inline]
    pub fn finish(self, models: &mut impl TimingModels) -> smallvec::SmallVec<[usize; 16]> {
        if !self.moved.is_empty() && !self.anchored {
            let common = self.sum / self.moved.len() as f64;
            for &rx in &self.moved {
                models.model(rx).shift(-common);
            }
        }
        self.moved
    }
}

/// Teaches one fix's residuals to the models ([`Lessons`]).
pub fn learn_residuals(
    res: &[Residual],
    anchored: bool,
    models: &mut impl TimingModels,
) -> smallvec::SmallVec<[usize; 16]> {
    let mut lessons = Lessons::new(anchored);
    for r in res {
        lessons.teach(r, models);
    }
    lessons.finish(models)
}
