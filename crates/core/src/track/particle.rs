//! A regularised particle filter for an aircraft heard by too few receivers
//! for a fix: two or three synchronised sites give one or two time
//! differences, which with the aircraft's height place it on a curve (one
//! difference) or at one of two points (two), and its motion across the
//! hyperbolas of successive transmissions narrows that down. Such a posterior
//! is banana-shaped or two-peaked for a long time, which a Kalman or
//! unscented filter (one Gaussian) represents badly; particles represent it
//! as it is.
//!
//! The state of each particle is [east, north, v_east, v_north] on a plane
//! tangent at the receivers that first heard the aircraft; the height is the
//! aircraft's own (barometric, corrected), not estimated. Particles start on
//! the first measurement's surface: points drawn around the sites are pulled
//! onto it by Gauss-Newton steps, with speeds and headings drawn from an
//! airliner's range. They move with a constant velocity perturbed by white
//! acceleration, are weighted by the time differences' likelihood, and are
//! resampled when the effective sample size falls below a share of their
//! number, then jittered by a Gaussian kernel of the cloud's own covariance
//! (Musso's regularisation) so that no diversity is lost, each jittered
//! position pulled back onto the newest measurement's surface (at a draw of
//! its noise). A particle beyond a site's radio horizon has no weight: that,
//! not the time differences, bounds how far out along a hyperbola the
//! aircraft can be. When no particle explains a measurement the cloud has
//! lost the aircraft: it starts again from that measurement and counts it.
//! A receiver's persistent timing error (its learnt offset's) is counted
//! as often as the cloud's spread says it remembers transmissions
//! ([`Persistent::memory`]), as the Gaussian tracks count it.
//! Who heard each transmission and who did not weighs the particles too
//! ([`super::hearing`]), and a cloud is published only once that rules
//! out the newest transmission's mirror solutions, which the time
//! differences cannot tell from it.

use nalgebra::{Matrix4, Matrix6, Vector4, Vector6};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::hearing::Hearing;
use super::kf::Gaussian;
use super::measurement::Persistent;
use super::plane::Plane;
use crate::mlat::coverage::Unheard;

mod config;
mod surface;
pub use config::SparseConfig;
mod velocity;
use surface::{pull, Differences};
pub use velocity::VelocityOutcome;

/// One transmission's sites: ECEF position (m), time of arrival in the common
/// clock (s), timing sigma (s); 2 or 3 of them.
pub type Sites<'a> = &'a [([f64; 3], f64, f64)];

/// What became of one measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SparseOutcome {
    Updated,
    /// No particle explained it: the cloud started again from it.
    Restarted,
    /// Not usable (sites, or the cloud could not be placed on it).
    Unusable,
}

/// The particle filter of one aircraft.
#[derive(Clone, Debug)]
pub struct SparseTrack {
    plane: Plane,
    pub t: f64,
    x: Vec<Vector4<f64>>,
    /// Normalised weights.
    w: Vec<f64>,
    rng: ChaCha8Rng,
    pub restarts: u32,
    pub resamples: u32,
    /// Velocity reports taken since the cloud was placed.
    velocities: u32,
    /// The newest report, if it contradicted the cloud.
    contradicting: Option<velocity::Contradicting>,
    /// The newest transmission: its sites, the height, and who heard it.
    last: Option<Last>,
}

#[derive(Clone, Debug)]
struct Last {
    sites: Vec<([f64; 3], f64, f64)>,
    h: f64,
    unheard: Option<Unheard>,
}

/// A mirror solution of the newest transmission counts as ruled out only
/// where who heard it makes it this much less likely than the cloud's mean
/// (chi-square units: a likelihood ratio of 20). The time differences
/// alone cannot choose between mirrors, and a cloud left to itself loses
/// one of two equal modes by chance: published, it would be one mode's
/// estimate with the confidence of both.
const MIRROR_EVIDENCE: f64 = 6.0;

/// How far copies of too few placed particles are moved before being pulled back (m).
const FILL_JITTER_M: f64 = 2_000.0;
/// A measurement no particle explains better than this (chi-square) restarts the cloud.
const LOST_CHI2: f64 = 100.0;

impl SparseTrack {
    /// A cloud on the surface of the first measurement (`None` when the sites
    /// are unusable or no drawn point reaches the surface).
    pub fn start(
        cfg: &SparseConfig,
        sites: Sites,
        unheard: Option<&Unheard>,
        t: f64,
        h: f64,
        seed: u64,
    ) -> Option<SparseTrack> {
        let centre = sites.iter().fold([0.0; 3], |a, s| [a[0] + s.0[0], a[1] + s.0[1], a[2] + s.0[2]]);
        let k = sites.len().max(1) as f64;
        let (lat, lon, _) = crate::geo::ecef_to_geodetic(centre.map(|c| c / k));
        let mut s = SparseTrack {
            plane: Plane::new(lat, lon, h),
            t,
            x: Vec::new(),
            w: Vec::new(),
            rng: <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(seed),
            restarts: 0,
            resamples: 0,
            velocities: 0,
            contradicting: None,
            last: None,
        };
        s.place(cfg, sites, unheard, h).then_some(s)
    }

    /// Draws the particles onto the measurement's surface, weighed by who
    /// heard it and who did not; false if none got there.
    fn place(&mut self, cfg: &SparseConfig, sites: Sites, unheard: Option<&Unheard>, h: f64) -> bool {
        let Some(d) = Differences::new(&self.plane, sites, h) else { return false };
        self.last = Some(Last { sites: sites.to_vec(), h, unheard: unheard.cloned() });
        let mut x = Vec::with_capacity(cfg.particles);
        let mut tries = 0;
        while x.len() < cfg.particles && tries < cfg.particles * 4 {
            tries += 1;
            // Uniform over the disc around the sites.
            let r = cfg.max_range_m * self.rng.gen::<f64>().sqrt();
            let a = self.rng.gen::<f64>() * std::f64::consts::TAU;
            let target = d.noise(&mut self.rng);
            let Some((e, n)) = pull(&d, &self.plane, r * a.cos(), r * a.sin(), h, target) else { continue };
            let speed = self.rng.gen_range(cfg.speed_ms[0]..cfg.speed_ms[1]);
            let heading = self.rng.gen::<f64>() * std::f64::consts::TAU;
            x.push(Vector4::new(e, n, speed * heading.sin(), speed * heading.cos()));
        }
        if x.is_empty() {
            return false;
        }
        // Fill up to the count by copies of the placed ones, moved a little
        // along the surface.
        let placed = x.len();
        while x.len() < cfg.particles {
            let mut c = x[self.rng.gen_range(0..placed)];
            let (de, dn): (f64, f64) = (self.rng.sample(StandardNormal), self.rng.sample(StandardNormal));
            let target = d.noise(&mut self.rng);
            let (e0, n0) = (c[0] + FILL_JITTER_M * de, c[1] + FILL_JITTER_M * dn);
            if let Some((e, n)) = pull(&d, &self.plane, e0, n0, h, target) {
                c[0] = e;
                c[1] = n;
            }
            x.push(c);
        }
        self.x = x;
        self.velocities = 0;
        self.contradicting = None;
        let hearing = self.hearing(unheard, h).filter(|_| cfg.hearing_memory_s > 0.0);
        let cost: Vec<f64> =
            self.x.iter().map(|x| hearing.as_ref().map_or(0.0, |s| s.cost(x[0], x[1]))).collect();
        self.w = vec![1.0; self.x.len()];
        self.reweigh(&cost);
        true
    }

    /// Who heard the transmission, and the silent receivers that could have
    /// heard a part of the cloud, for an aircraft at height `h`.
    fn hearing<'a>(&self, unheard: Option<&'a Unheard>, h: f64) -> Option<Hearing<'a>> {
        let unheard = unheard?;
        let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for x in &self.x {
            for k in 0..2 {
                min[k] = min[k].min(x[k]);
                max[k] = max[k].max(x[k]);
            }
        }
        Some(Hearing::new(&self.plane, unheard, self.t, h, min, max))
    }

    /// Multiplies the weights by the likelihood of costs `cost` (chi-square
    /// units, taken relative to the least: no underflow), and normalises.
    fn reweigh(&mut self, cost: &[f64]) {
        let best = cost.iter().cloned().fold(f64::INFINITY, f64::min);
        for (w, c) in self.w.iter_mut().zip(cost) {
            *w *= (-0.5 * (c - best)).exp();
        }
        let sum: f64 = self.w.iter().sum();
        self.w.iter_mut().for_each(|w| *w /= sum);
    }

    /// Moves the cloud to `t` and weighs it by one transmission's time
    /// differences, at the aircraft's height `h` (m).
    pub fn update(
        &mut self,
        cfg: &SparseConfig,
        sites: Sites,
        unheard: Option<&Unheard>,
        t: f64,
        h: f64,
    ) -> SparseOutcome {
        self.update_with(cfg, sites, &[], unheard, t, h)
    }

    /// [`Self::update`] with each site's `persistent` error besides the
    /// error `sites` give (each transmission's own), counted as often as
    /// the cloud's memory holds transmissions ([`Persistent::memory`]): how
    /// spread its particles' predictions of the differences are.
    pub fn update_with(
        &mut self,
        cfg: &SparseConfig,
        sites: Sites,
        persistent: &[Persistent],
        unheard: Option<&Unheard>,
        t: f64,
        h: f64,
    ) -> SparseOutcome {
        let Some(fresh) = Differences::new(&self.plane, sites, h) else { return SparseOutcome::Unusable };
        let dt = self.predict(cfg, t);
        let res: Vec<[f64; 2]> = self.x.iter().map(|x| fresh.residual(&self.plane, x[0], x[1], h)).collect();
        // The residuals are the same under either; only the noise differs.
        let counted = self.counted(sites, persistent, &res);
        let d = match &counted {
            Some(c) => {
                let Some(d) = Differences::new(&self.plane, c, h) else { return SparseOutcome::Unusable };
                d
            }
            None => fresh,
        };
        let sites_counted = counted.unwrap_or_else(|| sites.to_vec());
        self.last = Some(Last { sites: sites_counted, h, unheard: unheard.cloned() });
        // Beyond a site's horizon, or faster than any airliner: impossible.
        let max_speed = cfg.speed_ms[1] * 1.25;
        let chi: Vec<f64> = (self.x.iter().zip(&res))
            .map(|(x, r)| {
                if !d.visible(&self.plane, x[0], x[1], h) || x[2].hypot(x[3]) > max_speed {
                    f64::INFINITY
                } else {
                    d.chi2(*r)
                }
            })
            .collect();
        let best = chi.iter().cloned().fold(f64::INFINITY, f64::min);
        // NaN included: no particle explained it.
        if best.is_nan() || best > LOST_CHI2 {
            self.restarts += 1;
            // A new cloud remembers this transmission alone.
            let once = with_persistent(sites, persistent, |_| 1.0);
            return if self.place(cfg, &once, unheard, h) {
                SparseOutcome::Restarted
            } else {
                SparseOutcome::Unusable
            };
        }
        // Who heard it weighs too, but only the time differences say
        // whether the cloud still holds the aircraft (above).
        let share = if cfg.hearing_memory_s > 0.0 { (dt / cfg.hearing_memory_s).min(1.0) } else { 0.0 };
        let cost = match self.hearing(unheard, h).filter(|_| share > 0.0) {
            Some(hearing) => {
                self.x.iter().zip(&chi).map(|(x, c)| c + share * hearing.cost(x[0], x[1])).collect()
            }
            None => chi,
        };
        self.reweigh(&cost);
        if self.ess() < cfg.resample_below * self.x.len() as f64 {
            self.resample(&d, h);
        }
        SparseOutcome::Updated
    }

    /// Moves the particles to `t` (never back) with a constant velocity
    /// perturbed by white acceleration; returns how far (s).
    fn predict(&mut self, cfg: &SparseConfig, t: f64) -> f64 {
        let dt = (t - self.t).max(0.0);
        self.t = self.t.max(t);
        let q = cfg.accel_ms2;
        for x in &mut self.x {
            let (ae, an): (f64, f64) = (self.rng.sample(StandardNormal), self.rng.sample(StandardNormal));
            let (ae, an) = (ae * q, an * q);
            x[0] += x[2] * dt + 0.5 * ae * dt * dt;
            x[1] += x[3] * dt + 0.5 * an * dt * dt;
            x[2] += ae * dt;
            x[3] += an * dt;
        }
        dt
    }

    /// The sites with each one's persistent error counted as often as the
    /// cloud's memory holds transmissions: the spread of its particles'
    /// residuals `res` is what it knows along the differences. `None` when
    /// no site has one: the sites as they are.
    fn counted(
        &self,
        sites: Sites,
        persistent: &[Persistent],
        res: &[[f64; 2]],
    ) -> Option<Vec<([f64; 3], f64, f64)>> {
        if persistent.iter().all(|p| p.var_s2 == 0.0) {
            return None;
        }
        let c2 = crate::mlat::solver::C_AIR.powi(2);
        let m = sites.len() - 1;
        let (mut mean, mut spread) = ([0.0; 2], 0.0);
        for (r, w) in res.iter().zip(&self.w) {
            for k in 0..m {
                mean[k] += w * r[k];
            }
        }
        for (r, w) in res.iter().zip(&self.w) {
            spread += (0..m).map(|k| w * (r[k] - mean[k]).powi(2)).sum::<f64>();
        }
        // Traces over the differences, each against the first site.
        let var = |i: usize| sites.get(i).map_or(0.0, |s| s.2 * s.2 * c2);
        let once = |i: usize| persistent.get(i).map_or(0.0, |p| p.var_s2 * c2);
        let trace = |v: &dyn Fn(usize) -> f64| (1..=m).map(|i| v(0) + v(i)).sum::<f64>();
        let memory = Persistent::memory(spread, trace(&var), trace(&once));
        Some(with_persistent(sites, persistent, |p| memory.min(p.shared_by).max(1.0)))
    }

    /// Systematic resampling, then a Gaussian kernel jitter of the cloud's
    /// covariance at Silverman/Musso's bandwidth for 4 dimensions. The cloud
    /// of one or two time differences is a thin curved sheet that a kernel
    /// of its overall covariance would mostly leave: each jittered position is
    /// pulled back onto the newest measurement's surface (a move that keeps
    /// what it explains).
    fn resample(&mut self, d: &Differences, h: f64) {
        self.resamples += 1;
        let (_, cov) = self.moments();
        let n = self.x.len();
        let mut out = Vec::with_capacity(n);
        let u0 = self.rng.gen::<f64>() / n as f64;
        let (mut acc, mut i) = (self.w[0], 0);
        for k in 0..n {
            let u = u0 + k as f64 / n as f64;
            while u > acc && i + 1 < n {
                i += 1;
                acc += self.w[i];
            }
            out.push(self.x[i]);
        }
        let bandwidth = (4.0 / (n as f64 * 6.0)).powf(1.0 / 8.0);
        // A floor, so that a cloud of copies spreads again.
        let floor = Matrix4::from_diagonal(&Vector4::new(50.0f64.powi(2), 50.0f64.powi(2), 4.0, 4.0));
        if let Some(l) = (cov * (bandwidth * bandwidth) + floor).cholesky() {
            let l = l.l();
            for x in &mut out {
                let z = Vector4::from_fn(|_, _| self.rng.sample::<f64, _>(StandardNormal));
                let moved = *x + l * z;
                // Where the surface cannot be reached from there (time
                // differences nearly parallel far out), the jittered state as it is.
                let target = d.noise(&mut self.rng);
                *x = match pull(d, &self.plane, moved[0], moved[1], h, target) {
                    Some((e, n)) => Vector4::new(e, n, moved[2], moved[3]),
                    None => moved,
                };
            }
        }
        self.x = out;
        self.w = vec![1.0 / n as f64; n];
    }

    /// The particles' states [e, n, ve, vn] in the cloud's plane, and their weights.
    pub fn particles(&self) -> impl Iterator<Item = (&Vector4<f64>, f64)> {
        self.x.iter().zip(self.w.iter().copied())
    }

    /// Weighted mean and covariance of the state.
    pub fn moments(&self) -> (Vector4<f64>, Matrix4<f64>) {
        let mean = self.x.iter().zip(&self.w).fold(Vector4::zeros(), |m, (x, w)| m + x * *w);
        let cov = self.x.iter().zip(&self.w).fold(Matrix4::zeros(), |c, (x, w)| {
            let d = x - mean;
            c + d * d.transpose() * *w
        });
        (mean, cov)
    }

    /// Whether the cloud's position has one mode: split along its major axis
    /// at the mean, the two halves' centres are less than four of their own
    /// spreads apart (a two-peaked cloud's halves are its peaks, far apart
    /// for their width; a Gaussian's are 2.65 of them apart).
    pub fn unimodal(&self) -> bool {
        let (mean, cov) = self.moments();
        self.one_mode(&mean, &cov)
    }

    fn one_mode(&self, mean: &Vector4<f64>, cov: &Matrix4<f64>) -> bool {
        let pos = cov.fixed_view::<2, 2>(0, 0).into_owned();
        let eig = pos.symmetric_eigen();
        let k = if eig.eigenvalues[0] > eig.eigenvalues[1] { 0 } else { 1 };
        let axis = eig.eigenvectors.column(k).into_owned();
        let mut halves = [(0.0, 0.0, 0.0); 2];
        for (x, w) in self.x.iter().zip(&self.w) {
            let s = (x[0] - mean[0]) * axis[0] + (x[1] - mean[1]) * axis[1];
            let h = &mut halves[(s > 0.0) as usize];
            h.0 += w;
            h.1 += w * s;
            h.2 += w * s * s;
        }
        let stats = halves.map(|(w, s, ss)| {
            if w <= 0.0 {
                (0.0, 0.0)
            } else {
                let m = s / w;
                (m, (ss / w - m * m).max(0.0))
            }
        });
        let spread = ((stats[0].1 + stats[1].1) / 2.0).sqrt();
        (stats[1].0 - stats[0].0) < 4.0 * spread.max(1.0) || halves.iter().any(|h| h.0 < 0.05)
    }

    /// The cloud as a Gaussian of the trackers' state [e, n, ve, vn, ae, an]
    /// in its plane (no acceleration), for publication.
    pub fn gaussian(&self) -> (Plane, Gaussian) {
        let (m, cov) = self.moments();
        (self.plane, as_gaussian(&m, &cov))
    }

    /// [`Self::gaussian`], when the cloud is worth publishing: one-peaked,
    /// its position within `max_sigma_m` (1 sigma, largest axis), its
    /// newest transmission's mirror solutions ruled out.
    pub fn publishable(&self, max_sigma_m: f64) -> Option<(Plane, Gaussian)> {
        let (m, cov) = self.moments();
        let sigma =
            cov.fixed_view::<2, 2>(0, 0).into_owned().symmetric_eigen().eigenvalues.max().max(0.0).sqrt();
        (sigma <= max_sigma_m && self.one_mode(&m, &cov) && !self.mirror_open(&m, &cov))
            .then(|| (self.plane, as_gaussian(&m, &cov)))
    }

    /// Whether the newest transmission has a solution far outside the
    /// cloud that who heard it does not rule out.
    fn mirror_open(&self, mean: &Vector4<f64>, cov: &Matrix4<f64>) -> bool {
        let Some(last) = &self.last else { return false };
        let position = (nalgebra::Vector2::new(mean[0], mean[1]), cov.fixed_view::<2, 2>(0, 0).into_owned());
        mirrors(&self.plane, &last.sites, last.h, last.unheard.as_ref(), self.t, position).open
    }
}

/// What one transmission's time differences say of an estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mirrors {
    /// A solution lies within the estimate.
    pub own: bool,
    /// A solution lies far outside it, and who heard the transmission
    /// does not rule it out (see [`MIRROR_EVIDENCE`]).
    pub open: bool,
}

/// The solutions of one transmission's time differences (`sites`, an
/// aircraft at height `h`, heard at `t` by those `unheard` says) against
/// an estimate (`position`: mean and covariance in `plane`): with a
/// solution far outside it that nothing rules out, the estimate may be
/// either, and is not worth publishing.
pub fn mirrors(
    plane: &Plane,
    sites: Sites,
    h: f64,
    unheard: Option<&Unheard>,
    t: f64,
    (mean, cov): (nalgebra::Vector2<f64>, nalgebra::Matrix2<f64>),
) -> Mirrors {
    let mut m = Mirrors { own: false, open: false };
    let Some(d) = Differences::new(plane, sites, h) else { return m };
    let Some(info) = cov.try_inverse() else { return Mirrors { own: false, open: true } };
    let all = ([f64::NEG_INFINITY; 2], [f64::INFINITY; 2]);
    let hearing = unheard.map(|u| Hearing::new(plane, u, t, h, all.0, all.1));
    let cost = |e: f64, n: f64| hearing.as_ref().map_or(0.0, |h| h.cost(e, n));
    let here = cost(mean[0], mean[1]);
    for (e, n) in surface::solutions(&d, plane, h) {
        let x = nalgebra::Vector2::new(e - mean[0], n - mean[1]);
        if (x.transpose() * info * x)[0] > 25.0 && x.norm() > 1_000.0 {
            m.open |= cost(e, n) - here < MIRROR_EVIDENCE;
        } else {
            m.own = true;
        }
        if m.own && m.open {
            break;
        }
    }
    m
}

/// `sites` with each one's `persistent` variance counted `times(p)` times
/// into its sigma.
pub fn with_persistent(
    sites: Sites,
    persistent: &[Persistent],
    times: impl Fn(&Persistent) -> f64,
) -> Vec<([f64; 3], f64, f64)> {
    (sites.iter().enumerate())
        .map(|(i, &(pos, t, sigma))| {
            let extra = persistent.get(i).map_or(0.0, |p| p.var_s2 * times(p));
            (pos, t, (sigma * sigma + extra).sqrt())
        })
        .collect()
}

/// Mean and covariance of [e, n, ve, vn] as the trackers' six-state Gaussian.
fn as_gaussian(m: &Vector4<f64>, cov: &Matrix4<f64>) -> Gaussian {
    let mut g = Gaussian { x: Vector6::new(m[0], m[1], m[2], m[3], 0.0, 0.0), p: Matrix6::zeros() };
    g.p.fixed_view_mut::<4, 4>(0, 0).copy_from(cov);
    g
}

#[cfg(test)]
mod tests;
