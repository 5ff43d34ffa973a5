//! Clock synchronisation of one receiver pair: a Kalman filter of the offset
//! and relative drift between their clocks, fed by transmissions whose
//! emitter position is known (ADS-B positions heard by both).
//!
//! Each measurement is `z = (t_j - d_j/c) - (t_i - d_i/c)`, the difference of
//! the two clocks at one instant, with the propagation delays removed. The
//! state is `[offset, drift]` at the time of the last update (in receiver i's
//! local seconds); the process noise models phase jitter and a random walk of
//! the relative frequency. Outliers are gated on the normalised innovation;
//! a run of them is a clock jump (a receiver restart) and restarts the filter,
//! as does time going backwards by more than reordering explains.

use nalgebra::{Matrix2, Vector2};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairParams {
    /// Phase random walk (s^2 per s).
    pub q_phase: f64,
    /// Relative frequency random walk (1/s^2 per s).
    pub q_drift: f64,
    /// Largest plausible relative drift at start (fraction): sets the initial drift variance.
    pub max_drift: f64,
    /// Normalised innovation squared beyond which a measurement is an outlier.
    pub gate: f64,
    /// Consecutive outliers that mean the clocks jumped.
    pub jump_after: u32,
    /// Updates needed before the pair is used.
    pub min_updates: u32,
    /// A pair not updated for this long (s) is not used.
    pub max_age_s: f64,
}

impl Default for PairParams {
    fn default() -> Self {
        PairParams {
            q_phase: (2e-9f64).powi(2),
            q_drift: (5e-9f64).powi(2),
            max_drift: 200e-6,
            gate: 25.0,
            jump_after: 4,
            min_updates: 4,
            max_age_s: 60.0,
        }
    }
}

/// What an update did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Update {
    Accepted,
    Outlier,
    /// The filter (re)started from this measurement.
    Restarted,
}

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct PairFilter {
    x: Vector2<f64>,
    p: Matrix2<f64>,
    /// Local time (receiver i) of the state, and server time of the last update.
    tau: f64,
    last_update: f64,
    pub updates: u32,
    outlier_run: u32,
    pub outliers: u64,
    pub restarts: u64,
    /// Exponential mean of squared innovations (s^2) and of their variances, for stats.
    innov2: f64,
    innov_var: f64,
    /// Normalised innovation squared of the last measurement offered.
    pub last_nis: f64,
}

impl PairFilter {
    pub fn new(z: f64, r: f64, tau: f64, now: f64, params: &PairParams) -> Self {
        PairFilter {
            x: Vector2::new(z, 0.0),
            p: Matrix2::new(r, 0.0, 0.0, params.max_drift * params.max_drift),
            tau,
            last_update: now,
            updates: 1,
            outlier_run: 0,
            outliers: 0,
            restarts: 0,
            innov2: 0.0,
            innov_var: 0.0,
            last_nis: 1.0,
        }
    }

    fn restart(&mut self, z: f64, r: f64, tau: f64, now: f64, params: &PairParams) {
        let (outliers, restarts) = (self.outliers, self.restarts + 1);
        *self = PairFilter::new(z, r, tau, now, params);
        self.outliers = outliers;
        self.restarts = restarts;
    }

    fn predicted(&self, tau: f64, params: &PairParams) -> (Vector2<f64>, Matrix2<f64>) {
        let dt = tau - self.tau;
        let f = Matrix2::new(1.0, dt, 0.0, 1.0);
        let a = dt.abs();
        let q = Matrix2::new(
            params.q_phase * a + params.q_drift * a.powi(3) / 3.0,
            params.q_drift * dt * a / 2.0,
            params.q_drift * dt * a / 2.0,
            params.q_drift * a,
        );
        (f * self.x, f * self.p * f.transpose() + q)
    }

    /// The normalised innovation squared a measurement would have, the
    /// filter left as it is (a cluster worker judging an emitter against
    /// the clock service's filters).
    pub fn nis(&self, z: f64, r: f64, tau: f64, params: &PairParams) -> f64 {
        let (x, p) = self.predicted(tau, params);
        (z - x[0]).powi(2) / (p[(0, 0)] + r)
    }

    /// Feeds one measurement `z` (s) with variance `r` (s^2) taken at local time `tau`.
    pub fn update(&mut self, z: f64, r: f64, tau: f64, now: f64, params: &PairParams) -> Update {
        // Reordering within a receiver is at most a second or so; more is a restart.
        if tau < self.tau - 5.0 {
            self.restart(z, r, tau, now, params);
            return Update::Restarted;
        }
        let (x, p) = self.predicted(tau, params);
        let y = z - x[0];
        let s = p[(0, 0)] + r;
        let nis = y * y / s;
        self.last_nis = nis;
        if self.updates >= 2 && nis > params.gate {
            self.outliers += 1;
            self.outlier_run += 1;
            if self.outlier_run >= params.jump_after {
                self.restart(z, r, tau, now, params);
                return Update::Restarted;
            }
            return Update::Outlier;
        }
        let k = Vector2::new(p[(0, 0)] / s, p[(1, 0)] / s);
        self.x = x + k * y;
        // Joseph form keeps P symmetric and positive.
        let ikh = Matrix2::new(1.0 - k[0], 0.0, -k[1], 1.0);
        self.p = ikh * p * ikh.transpose() + k * k.transpose() * r;
        self.tau = tau;
        self.last_update = now;
        self.updates += 1;
        self.outlier_run = 0;
        let w = 0.05;
        self.innov2 = (1.0 - w) * self.innov2 + w * y * y;
        self.innov_var = (1.0 - w) * self.innov_var + w * s;
        Update::Accepted
    }

    /// Usable for multilateration at server time `now`.
    pub fn valid(&self, now: f64, params: &PairParams) -> bool {
        self.updates >= params.min_updates
            && self.outlier_run == 0
            && now - self.last_update <= params.max_age_s
    }

    /// Offset `t_j - t_i` (s) at local time `tau` and its variance (the
    /// first row of the prediction only: this runs for every pair of every
    /// multilaterated transmission).
    pub fn offset_at(&self, tau: f64, params: &PairParams) -> (f64, f64) {
        let dt = tau - self.tau;
        let a = dt.abs();
        let p = &self.p;
        let var = p[(0, 0)]
            + 2.0 * dt * p[(0, 1)]
            + dt * dt * p[(1, 1)]
            + params.q_phase * a
            + params.q_drift * a * a * a / 3.0;
        (self.x[0] + dt * self.x[1], var)
    }

    /// The offset at the time of the last update.
    pub fn offset(&self) -> f64 {
        self.x[0]
    }

    pub fn drift(&self) -> f64 {
        self.x[1]
    }

    /// RMS of recent innovations (s): how well the pair agrees with its data.
    pub fn residual_rms(&self) -> f64 {
        self.innov2.sqrt()
    }

    /// Expected RMS of the innovations (s), for comparison with [`Self::residual_rms`].
    pub fn expected_rms(&self) -> f64 {
        self.innov_var.sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn tracks_offset_and_drift_to_the_noise_floor() {
        let params = PairParams::default();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let sigma = 83e-9 * 2f64.sqrt();
        let noise = Normal::new(0.0, sigma).unwrap();
        let (offset0, drift) = (1234.5678, 40e-6);
        let truth = |tau: f64| offset0 + drift * tau;
        let mut f: Option<PairFilter> = None;
        let mut errs = Vec::new();
        for k in 0..600 {
            let tau = k as f64 * 0.5;
            let z = truth(tau) + noise.sample(&mut rng);
            match &mut f {
                None => f = Some(PairFilter::new(z, sigma * sigma, tau, tau, &params)),
                Some(f) => {
                    assert_ne!(f.update(z, sigma * sigma, tau, tau, &params), Update::Restarted);
                }
            }
            let f = f.as_ref().unwrap();
            if tau > 30.0 {
                let (o, var) = f.offset_at(tau + 0.25, &params);
                errs.push(((o - truth(tau + 0.25)) / var.sqrt(), o - truth(tau + 0.25)));
            }
        }
        let f = f.unwrap();
        assert!(f.valid(300.0, &params));
        assert!((f.drift() - drift).abs() < 0.05e-6, "{}", f.drift());
        // The predicted offset is consistent with its own variance and far
        // better than one measurement.
        let nees: f64 = errs.iter().map(|e| e.0 * e.0).sum::<f64>() / errs.len() as f64;
        assert!(nees > 0.5 && nees < 1.6, "{nees}");
        let rms = (errs.iter().map(|e| e.1 * e.1).sum::<f64>() / errs.len() as f64).sqrt();
        assert!(rms < sigma / 2.0, "{rms}");
        assert!((f.residual_rms() / f.expected_rms() - 1.0).abs() < 0.5);
    }

    #[test]
    fn outliers_are_gated_and_a_jump_restarts() {
        let params = PairParams::default();
        let r = (100e-9f64).powi(2);
        let mut f = PairFilter::new(10.0, r, 0.0, 0.0, &params);
        for k in 1..20 {
            assert_eq!(f.update(10.0, r, k as f64, k as f64, &params), Update::Accepted);
        }
        assert_eq!(f.update(10.0 + 5e-6, r, 20.0, 20.0, &params), Update::Outlier);
        assert_eq!(f.update(10.0, r, 21.0, 21.0, &params), Update::Accepted);
        // The receiver restarts: its clock is now 500 s behind, for good.
        let mut results = Vec::new();
        for k in 22..26 {
            results.push(f.update(-490.0, r, k as f64, k as f64, &params));
        }
        assert_eq!(results, [Update::Outlier, Update::Outlier, Update::Outlier, Update::Restarted]);
        assert!(!f.valid(25.0, &params), "a restarted pair waits for its updates");
        for k in 26..30 {
            f.update(-490.0, r, k as f64, k as f64, &params);
        }
        assert!(f.valid(29.0, &params));
        assert!((f.offset_at(29.0, &params).0 + 490.0).abs() < 1e-9);
        // Time far backwards: restart at once.
        assert_eq!(f.update(-490.0, r, 1.0, 30.0, &params), Update::Restarted);
        assert_eq!(f.restarts, 2);
    }

    #[test]
    fn stale_pairs_are_not_used() {
        let params = PairParams::default();
        let mut f = PairFilter::new(1.0, 1e-14, 0.0, 0.0, &params);
        for k in 1..5 {
            f.update(1.0, 1e-14, k as f64, k as f64, &params);
        }
        assert!(f.valid(10.0, &params));
        assert!(!f.valid(100.0, &params));
    }
}
