//! Interacting Multiple Model filter: several motion models run in
//! parallel, mixed before each step through a Markov transition matrix and
//! weighted after it by how likely each made the measurement.

//!
//! The model set is shared (an `Arc`) so a track's state is cheap to copy:
//! tracks keep copies to re-run late measurements in time order.

use std::sync::Arc;

use nalgebra::{DMatrix, Matrix6, Vector6};
use smallvec::SmallVec;

use super::kf::{Gaussian, Linear, PosMeasurement};
use super::models::MotionModel;

/// Per-model values, inline up to four models (the default set): a track
/// keeps a copy of its filter for every measurement in its reorder window,
/// and a heap allocation per copy cost more than the copy itself.
pub type PerModel<T> = SmallVec<[T; 4]>;

/// Steps closer than this (s) are one instant: the ADS-B position and the
/// MLAT fix of one transmission are dated a propagation time apart (at most
/// about 2 ms). The switching matrix is per step, so applying it between
/// them would let the models switch twice per transmission heard both ways:
/// a fused track would switch twice as often as either source's.
pub const SAME_INSTANT_S: f64 = 0.005;

/// The models and their Markov switching matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct ImmSpec {
    pub models: Vec<MotionModel>,
    /// Row i: probabilities of switching from model i to each model.
    pub transition: DMatrix<f64>,
    /// Per column, its one value off the diagonal when every column has one
    /// (a `sticky` matrix): what lets `prepare` share a sum across models.
    uniform_off: Option<PerModel<f64>>,
}

impl ImmSpec {
    pub fn new(models: Vec<MotionModel>, transition: DMatrix<f64>) -> ImmSpec {
        let n = models.len();
        assert_eq!((transition.nrows(), transition.ncols()), (n, n), "transition matrix shape");
        let off = |j: usize| transition[((j + 1) % n, j)];
        let uniform = (0..n).all(|j| (0..n).all(|i| i == j || transition[(i, j)] == off(j)));
        let uniform_off = uniform.then(|| (0..n).map(off).collect());
        ImmSpec { models, transition, uniform_off }
    }
}

#[derive(Clone, Debug)]
pub struct Imm {
    pub spec: Arc<ImmSpec>,
    pub filters: PerModel<Gaussian>,
    pub mu: PerModel<f64>,
}

/// What one IMM step produced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step {
    /// Combined estimate after the update.
    pub estimate: Gaussian,
    /// Normalised innovation squared of the combined prediction.
    pub nis: f64,
}

impl Imm {
    /// Starts every model from `init`, with equal probabilities.
    pub fn new(models: Vec<MotionModel>, transition: DMatrix<f64>, init: Gaussian) -> Imm {
        Imm::with_spec(Arc::new(ImmSpec::new(models, transition)), init)
    }

    pub fn with_spec(spec: Arc<ImmSpec>, init: Gaussian) -> Imm {
        let n = spec.models.len();
        Imm { filters: smallvec::smallvec![init; n], mu: smallvec::smallvec![1.0 / n as f64; n], spec }
    }

    /// A transition matrix that stays with probability `stay` and moves to
    /// each other model with equal share of the rest.
    pub fn sticky(n: usize, stay: f64) -> DMatrix<f64> {
        if n == 1 {
            return DMatrix::from_element(1, 1, 1.0);
        }
        DMatrix::from_fn(n, n, |r, c| if r == c { stay } else { (1.0 - stay) / (n - 1) as f64 })
    }

    /// A matrix with a home model, the first: it stays there with
    /// probability `stay_first`, and every other model returns to it with
    /// probability `to_first`. Every other move (from the first to another,
    /// between two others) has the first's leaving share, (1 - stay_first) /
    /// (n - 1), so each column has one value off its diagonal and
    /// `prepare` keeps its shared sum. Over time the first model's share
    /// tends to to_first / (to_first + 1 - stay_first). `None` when the
    /// values are not probabilities or leave another model no chance to stay.
    pub fn home(n: usize, stay_first: f64, to_first: f64) -> Option<DMatrix<f64>> {
        let probability = |p: f64| (0.0..=1.0).contains(&p);
        if !(probability(stay_first) && probability(to_first)) {
            return None;
        }
        if n == 1 {
            return Some(DMatrix::from_element(1, 1, 1.0));
        }
        let leave = (1.0 - stay_first) / (n - 1) as f64;
        let stay = 1.0 - to_first - (n - 2) as f64 * leave;
        (stay >= 0.0).then(|| {
            DMatrix::from_fn(n, n, |r, c| match (r, c) {
                (0, 0) => stay_first,
                (_, 0) => to_first,
                _ if r == c => stay,
                _ => leave,
            })
        })
    }

    pub fn estimate(&self) -> Gaussian {
        combine(&self.filters, &self.mu)
    }

    /// The combined state's mean alone (what needs no covariance).
    pub fn mean(&self) -> Vector6<f64> {
        self.filters.iter().zip(&self.mu).fold(Vector6::zeros(), |x, (g, &w)| x + g.x * w)
    }

    /// Mixing and model-matched prediction over `dt`: everything of a step
    /// that does not depend on the measurement, so a caller can gate on the
    /// combined prediction and try several noise levels (VB) without
    /// predicting again.
    pub fn prepare(&self, dt: f64) -> Prepared {
        if dt.abs() < SAME_INSTANT_S {
            return self.prepare_unmixed(dt);
        }
        let (n, tr) = (self.spec.models.len(), &self.spec.transition);
        let c: PerModel<f64> = (0..n).map(|j| (0..n).map(|i| tr[(i, j)] * self.mu[i]).sum()).collect();
        // Each prediction written where it stays (collecting them moved
        // every 336-byte Gaussian once more), into zeros: a copy of the
        // filters to overwrite cost a sixth more.
        let zero = Gaussian { x: Vector6::zeros(), p: Matrix6::zeros() };
        // The inline slots written as zero bytes, then cut or grown to n:
        // n clones of `zero` were n calls to memcpy.
        let mut predicted = PerModel::from_buf([zero; 4]);
        predicted.resize(n, zero);
        // Model j starts from the mixture of the n filters with weights
        // w_ij = tr_ij mu_i / c_j. Around the filter's combined mean xr,
        // with d_i = x_i - xr and A_i = P_i + d_i d_i', that mixture has the
        // mean xr + m_j, m_j = sum_i w_ij d_i, and the covariance
        // sum_i w_ij A_i - m_j m_j'. When every column of the transition
        // matrix has one value r_j off its diagonal (a `sticky` matrix, the
        // configured default), sum_i tr_ij mu_i A_i = r_j B + (tr_jj - r_j)
        // mu_j A_j with B = sum_i mu_i A_i the same for every j: each mixture
        // is then one pass over two matrices instead of n (the mixtures were
        // two fifths of this preparation). d_i and m_j are the models'
        // small disagreements, so subtracting m_j m_j' loses nothing.
        let xr = self.mean();
        let mut spread = PerModel::<(Vector6<f64>, Matrix6<f64>)>::new();
        for g in &self.filters {
            let d = g.x - xr;
            let mut a = g.p;
            a.ger(1.0, &d, &d, 1.0);
            spread.push((d, a));
        }
        // (each column's value off the diagonal, B) when the matrix is sticky.
        let shared = self.spec.uniform_off.as_ref().map(|off| {
            let mut b = Matrix6::<f64>::zeros();
            for ((_, a), &mu) in spread.iter().zip(&self.mu) {
                b.zip_apply(a, |b, a| *b += mu * a);
            }
            (off, b)
        });
        for (j, ((cj, model), out)) in c.iter().zip(&self.spec.models).zip(predicted.iter_mut()).enumerate() {
            let cj = cj.max(1e-300);
            let (mut m, mut p) = (Vector6::<f64>::zeros(), Matrix6::<f64>::zeros());
            if let Some((off, b)) = &shared {
                // m_j = sum_i w_ij d_i reduces to own * d_j: sum_i mu_i d_i
                // is zero, xr being that mean.
                let (r, own) = (off[j] / cj, (tr[(j, j)] - off[j]) * self.mu[j] / cj);
                let (d, a) = &spread[j];
                m = d * own;
                p.zip_zip_apply(b, a, |p, b, a| *p = r * b + own * a);
            } else {
                for (i, (d, a)) in spread.iter().enumerate() {
                    let w = tr[(i, j)] * self.mu[i] / cj;
                    m.axpy(w, d, 1.0);
                    p.zip_apply(a, |p, a| *p += w * a);
                }
            }
            p.ger(-1.0, &m, &m, 1.0);
            model.predict_into(dt, &(xr + m), &p, &mut out.x, &mut out.p);
        }
        // Every caller needs it (gate, NIS, linearisation): computed once.
        let combined = combine(&predicted, &c);
        Prepared { c, predicted, combined }
    }

    /// A step within `SAME_INSTANT_S` of the last: the models cannot have
    /// switched in between, so no mixing; each model goes on from its own
    /// posterior with its own probability.
    fn prepare_unmixed(&self, dt: f64) -> Prepared {
        let predicted: PerModel<Gaussian> = self
            .filters
            .iter()
            .zip(&self.spec.models)
            .map(|(g, model)| {
                let (x, p) = model.predict(dt, &g.x, &g.p);
                Gaussian { x, p }
            })
            .collect();
        let combined = combine(&predicted, &self.mu);
        Prepared { c: self.mu.clone(), predicted, combined }
    }

    /// The combined prediction over `dt`, without changing the filter.
    pub fn predicted(&self, dt: f64) -> Gaussian {
        if dt == 0.0 {
            return self.estimate();
        }
        self.prepare(dt).combined()
    }

    /// Predicts over `dt` and updates with a position `m`.
    pub fn step(&mut self, dt: f64, m: &PosMeasurement) -> Option<Step> {
        self.step_linear(dt, &m.linear())
    }

    /// Predicts over `dt` and updates with `m`. `None` when a model's update
    /// is numerically impossible: the filter is then spent (partly updated)
    /// and the caller resets the track.
    pub fn step_linear<const M: usize>(&mut self, dt: f64, m: &Linear<M>) -> Option<Step> {
        let p = self.prepare(dt);
        self.update(&p, m)
    }

    /// The update half of a step, from a preparation of this filter. The
    /// result depends only on `p` and `m`, so calling it again with another
    /// `m` replaces the previous update. `None` as for [`Imm::step_linear`].
    pub fn update<const M: usize>(&mut self, p: &Prepared, m: &Linear<M>) -> Option<Step> {
        self.update_with(
            p,
            |g| g.update_linear(m),
            |g| {
                let (nu, s) = g.innovation(m);
                s.cholesky().map_or(f64::INFINITY, |c| nu.dot(&c.solve(&nu)))
            },
        )
    }

    /// The update half with any measurement: `update` applies it to one
    /// model's prediction, `nis` scores the combined prediction.
    pub fn update_with(
        &mut self,
        p: &Prepared,
        update: impl Fn(&Gaussian) -> Option<super::kf::Updated>,
        nis: impl Fn(&Gaussian) -> f64,
    ) -> Option<Step> {
        let n = self.spec.models.len();
        // (NIS, likelihood normaliser, prior probability) per model.
        let mut lik = PerModel::<(f64, f64, f64)>::with_capacity(n);
        // Each posterior written where it stays: collecting them and moving
        // the list into the filters copied 1.3 KB a step. Nothing reads the
        // filters before they are all written (`p` holds the predictions).
        for ((pred, cj), f) in p.predicted.iter().zip(&p.c).zip(self.filters.iter_mut()) {
            let u = update(pred)?;
            *f = u.post;
            lik.push((u.nis, u.norm, cj.max(1e-300)));
        }
        // Model probabilities c_j exp(-nis_j / 2) / norm_j, each exponent
        // taken relative to the smallest NIS: plain likelihoods would
        // underflow to zero for a measurement far from every model, and this
        // needs no logarithms (two per model were 1% of a run).
        let least = lik.iter().map(|l| l.0).fold(f64::INFINITY, f64::min);
        if !least.is_finite() {
            return None;
        }
        // The best fit's weight is at least 1e-300 / norm, far from zero for
        // any covariance a track can have.
        let w: PerModel<f64> =
            lik.iter().map(|&(nis, norm, c)| (-0.5 * (nis - least)).exp() * c / norm).collect();
        let total: f64 = w.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let mu: PerModel<f64> = w.iter().map(|x| x / total).collect();
        // NIS of the combined prediction (the track's own consistency check).
        let nis = nis(&p.combined());
        let estimate = combine(&self.filters, &mu);
        if !estimate.healthy() {
            return None;
        }
        self.mu = mu;
        Some(Step { estimate, nis })
    }
}

/// A step's measurement-independent half (see [`Imm::prepare`]).
#[derive(Clone, Debug)]
pub struct Prepared {
    c: PerModel<f64>,
    predicted: PerModel<Gaussian>,
    combined: Gaussian,
}

impl Prepared {
    /// The moment-matched combined prediction.
    pub fn combined(&self) -> Gaussian {
        self.combined
    }

    /// Every model's prediction, and so the combined one, less sure by `q`:
    /// process noise the models do not have, the same for all.
    pub fn widen(&mut self, q: &Matrix6<f64>) {
        for g in self.predicted.iter_mut() {
            g.p += q;
        }
        self.combined.p += q;
    }
}

/// Gaussian mixture moment-matched to one Gaussian.
pub fn combine(parts: &[Gaussian], w: &[f64]) -> Gaussian {
    let mut x = Vector6::zeros();
    for (g, &wi) in parts.iter().zip(w) {
        x += g.x * wi;
    }
    let mut p = Matrix6::zeros();
    for (g, &wi) in parts.iter().zip(w) {
        let d = g.x - x;
        p += (g.p + d * d.transpose()) * wi;
    }
    Gaussian { x, p }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, SMatrix, SVector, Vector2};

    #[test]
    fn a_home_matrix_keeps_its_shared_sum_and_its_stationary_share() {
        let t = Imm::home(4, 0.99, 0.1).expect("valid");
        for r in 0..4 {
            assert!((t.row(r).sum() - 1.0).abs() < 1e-12, "row {r}");
        }
        let models = vec![MotionModel::ConstantVelocity { q: 0.05 }; 4];
        assert!(
            ImmSpec::new(models, t.clone()).uniform_off.is_some(),
            "one value off each column's diagonal"
        );
        // The chain's long-run share of the first model, by iterating it.
        let mut mu = nalgebra::RowDVector::from_element(4, 0.25);
        for _ in 0..10_000 {
            mu = &mu * &t;
        }
        assert!((mu[0] - 0.1 / (0.1 + 0.01)).abs() < 1e-9, "{mu}");
        assert_eq!(Imm::home(1, 0.99, 0.1), Some(DMatrix::from_element(1, 1, 1.0)));
        assert_eq!(Imm::home(2, 0.99, 0.1).map(|t| t[(1, 1)]), Some(0.9));
        // Returning more often than the other models could stay; not probabilities.
        assert_eq!(Imm::home(4, 0.0, 0.5), None);
        assert_eq!(Imm::home(4, 1.2, 0.1), None);
        assert_eq!(Imm::home(4, 0.99, f64::NAN), None);
    }

    /// Straight flight and turns either way at about 3 deg/s.
    fn straight_and_turns() -> Vec<MotionModel> {
        vec![
            MotionModel::ConstantVelocity { q: 0.5 },
            MotionModel::CoordinatedTurn { omega: 0.05, q: 0.5 },
            MotionModel::CoordinatedTurn { omega: -0.05, q: 0.5 },
        ]
    }

    /// The mixing's shortcuts (around the combined mean; one pass per model
    /// for a matrix with uniform columns) against the textbook: each model's
    /// weights applied to the filters, moment-matched, predicted.
    #[test]
    fn mixing_equals_the_textbook_mixture_for_any_transition_matrix() {
        let models = straight_and_turns();
        let filter = |k: f64| Gaussian {
            x: Vector6::new(1e4 + 30.0 * k, -2e4 + 10.0 * k, 200.0 - k, 5.0 * k, 0.1 * k, -0.2),
            p: Matrix6::from_fn(|r, c| if r == c { 50.0 + 10.0 * k * (r + 1) as f64 } else { 0.3 * k }),
        };
        let uneven = DMatrix::from_row_slice(3, 3, &[0.9, 0.07, 0.03, 0.2, 0.75, 0.05, 0.1, 0.1, 0.8]);
        for transition in [Imm::sticky(3, 0.9), uneven] {
            let mut imm = Imm::new(models.clone(), transition.clone(), filter(0.0));
            imm.filters = smallvec::smallvec![filter(0.0), filter(1.0), filter(2.0)];
            imm.mu = smallvec::smallvec![0.6, 0.3, 0.1];
            let prep = imm.prepare(1.5);
            for (j, model) in models.iter().enumerate() {
                let c: f64 = (0..3).map(|i| transition[(i, j)] * imm.mu[i]).sum();
                let w: Vec<f64> = (0..3).map(|i| transition[(i, j)] * imm.mu[i] / c).collect();
                let mixed = combine(&imm.filters, &w);
                let (x, p) = model.predict(1.5, &mixed.x, &mixed.p);
                let got = prep.predicted[j];
                assert!((got.x - x).amax() < 1e-9 * x.amax(), "model {j}: {} vs {}", got.x, x);
                assert!((got.p - p).amax() < 1e-9 * p.amax(), "model {j}: {} vs {}", got.p, p);
            }
        }
    }

    /// Three models whose filters disagree, with probabilities 0.5, 0.3, 0.2.
    fn disagreeing(transition: DMatrix<f64>) -> Imm {
        let filter = |k: f64| Gaussian {
            x: Vector6::new(30.0 * k, 10.0 * k, 200.0 - k, 5.0 * k, 0.1 * k, -0.2),
            p: Matrix6::from_diagonal(&Vector6::new(50.0, 60.0, 4.0, 5.0, 0.1, 0.1)),
        };
        let mut imm = Imm::new(straight_and_turns(), transition, filter(0.0));
        imm.filters = smallvec::smallvec![filter(0.0), filter(1.0), filter(2.0)];
        imm.mu = smallvec::smallvec![0.5, 0.3, 0.2];
        imm
    }

    /// Model probabilities after an update against log-sum-exp over each
    /// model's log-likelihood and prior, where plain likelihoods underflow
    /// too (a measurement kilometres from every model) and for a model the
    /// transition matrix makes impossible.
    #[test]
    fn model_probabilities_are_the_normalised_likelihoods_however_far_the_measurement() {
        // Nothing switches into the second model.
        let closed = DMatrix::from_row_slice(3, 3, &[0.9, 0.0, 0.1, 0.1, 0.0, 0.9, 0.2, 0.0, 0.8]);
        for (transition, offset) in [(Imm::sticky(3, 0.9), 5.0), (Imm::sticky(3, 0.9), 3e4), (closed, 40.0)] {
            let mut imm = disagreeing(transition);
            let prep = imm.prepare(1.0);
            let target = prep.predicted[1].x;
            let m = PosMeasurement {
                z: Vector2::new(target[0] + offset, target[1]),
                r: Matrix2::identity() * 25.0,
            }
            .linear();
            let logs: Vec<f64> = (0..3)
                .map(|j| {
                    let u = prep.predicted[j].update_linear(&m).unwrap();
                    u.log_likelihood() + prep.c[j].max(1e-300).ln()
                })
                .collect();
            let top = logs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let total: f64 = logs.iter().map(|l| (l - top).exp()).sum();
            imm.update(&prep, &m).unwrap();
            for (j, l) in logs.iter().enumerate() {
                let want = (l - top).exp() / total;
                assert!(
                    (imm.mu[j] - want).abs() < 1e-12,
                    "offset {offset}, model {j}: {} vs {want}",
                    imm.mu[j]
                );
            }
        }
    }

    /// The ADS-B position and the MLAT fix of one transmission, applied one
    /// after the other, are the same step as both applied at once: the
    /// second must not mix the models again.
    #[test]
    fn two_measurements_of_one_instant_are_one_step() {
        let imm = disagreeing(Imm::sticky(3, 0.8));
        let adsb = PosMeasurement { z: Vector2::new(215.0, 12.0), r: Matrix2::identity() * 900.0 }.linear();
        let fix =
            PosMeasurement { z: Vector2::new(240.0, 20.0), r: Matrix2::new(80.0, 10.0, 10.0, 60.0) }.linear();
        let (mut h, mut z, mut r) =
            (SMatrix::<f64, 4, 6>::zeros(), SVector::<f64, 4>::zeros(), SMatrix::<f64, 4, 4>::zeros());
        for (k, m) in [&adsb, &fix].into_iter().enumerate() {
            h.fixed_view_mut::<2, 6>(2 * k, 0).copy_from(&m.h);
            z.fixed_rows_mut::<2>(2 * k).copy_from(&m.z);
            r.fixed_view_mut::<2, 2>(2 * k, 2 * k).copy_from(&m.r);
        }
        let both = Linear::new(h, z, r);
        let mut joint = imm.clone();
        let prep = joint.prepare(1.0);
        joint.update(&prep, &both).unwrap();
        // The fix is dated at emission, the report at its first reception:
        // a fraction of a millisecond apart (0.04 m of flight here).
        for (gap, tol) in [(0.0, 1e-9), (0.0002, 1e-3)] {
            let mut seq = imm.clone();
            let prep = seq.prepare(1.0);
            seq.update(&prep, &adsb).unwrap();
            let prep = seq.prepare(gap);
            seq.update(&prep, &fix).unwrap();
            for j in 0..3 {
                // Position and velocity: a turn model's prediction makes its
                // acceleration from the velocity, whatever the interval.
                let (a, b) = (seq.filters[j], joint.filters[j]);
                let (ax, bx) = (a.x.fixed_rows::<4>(0), b.x.fixed_rows::<4>(0));
                let (ap, bp) = (a.p.fixed_view::<4, 4>(0, 0), b.p.fixed_view::<4, 4>(0, 0));
                assert!(
                    (seq.mu[j] - joint.mu[j]).abs() < tol,
                    "gap {gap}, model {j}: {} vs {}",
                    seq.mu[j],
                    joint.mu[j]
                );
                assert!((ax - bx).amax() < 50.0 * tol, "gap {gap}, model {j}: {ax} vs {bx}");
                assert!((ap - bp).amax() < tol * bp.amax(), "gap {gap}, model {j}: {ap} vs {bp}");
            }
        }
    }

    #[test]
    fn probabilities_follow_the_model_that_explains_the_data() {
        // A target turning right at 3 deg/s: the right-turn model wins.
        let omega = 3f64.to_radians();
        let models = vec![
            MotionModel::ConstantVelocity { q: 0.5 },
            MotionModel::CoordinatedTurn { omega, q: 0.5 },
            MotionModel::CoordinatedTurn { omega: -omega, q: 0.5 },
        ];
        let init = Gaussian {
            x: Vector6::new(0.0, 0.0, 0.0, 100.0, 0.0, 0.0),
            p: Matrix6::from_diagonal(&Vector6::new(100.0, 100.0, 25.0, 25.0, 1.0, 1.0)),
        };
        let mut imm = Imm::new(models, Imm::sticky(3, 0.95), init);
        let (f, _) = MotionModel::CoordinatedTurn { omega, q: 0.0 }.transition(1.0);
        let mut truth = init.x;
        for _ in 0..20 {
            truth = f * truth;
            let m = PosMeasurement { z: Vector2::new(truth[0], truth[1]), r: Matrix2::identity() * 25.0 };
            imm.step(1.0, &m).unwrap();
        }
        assert!(imm.mu[1] > 0.8, "{:?}", imm.mu);
        let e = imm.estimate();
        assert!((e.x[0] - truth[0]).abs() < 5.0 && (e.x[1] - truth[1]).abs() < 5.0);
    }
}
