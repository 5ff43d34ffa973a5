//! Who heard a transmission and who did not, as a likelihood for the
//! particle filter's positions: a particle where a listening receiver hears
//! most transmissions ([`crate::mlat::coverage`]) explains its silence
//! badly, one beyond where a receiver that heard it ever hears explains its
//! hearing badly.
//!
//! Why it belongs to the particles: one or two time differences have
//! mirror solutions that fit them equally (the other crossing of two
//! hyperbolas, the far end of one). The time differences cannot choose;
//! the receivers' coverage can.

use nalgebra::{Matrix2, Vector2};

use super::plane::Plane;
use crate::mlat::coverage::{band, RxCoverage, Unheard};

/// One receiver in the particles' plane.
struct Placed<'a> {
    rx: &'a RxCoverage,
    at: Vector2<f64>,
    /// Takes plane vectors into its own east and north.
    to_own: Matrix2<f64>,
}

impl<'a> Placed<'a> {
    fn new(plane: &Plane, rx: &'a RxCoverage) -> Self {
        let p = plane.ecef_to_local(rx.ecef);
        Placed { rx, at: Vector2::new(p.x, p.y), to_own: plane.from_local(rx.lat, rx.lon).transpose() }
    }

    /// Plane position (e, n) in its own east and north.
    fn own(&self, e: f64, n: f64) -> Vector2<f64> {
        self.to_own * (Vector2::new(e, n) - self.at)
    }
}

/// The receivers that heard a transmission, and the silent ones that could
/// have heard a part of the cloud.
pub struct Hearing<'a> {
    band: usize,
    heard: Vec<Placed<'a>>,
    silent: Vec<Placed<'a>>,
}

impl<'a> Hearing<'a> {
    /// `unheard`'s receivers for an aircraft at height `h` (m) at `t`: those
    /// that heard it, and those listening then that did not and reach into
    /// the box `[min, max]` (plane m) around the particles.
    pub fn new(plane: &Plane, unheard: &'a Unheard, t: f64, h: f64, min: [f64; 2], max: [f64; 2]) -> Self {
        let band = band(h);
        let rxs = &unheard.coverage.rxs;
        let heard =
            (unheard.heard.iter()).filter_map(|&k| rxs.get(k)).map(|rx| Placed::new(plane, rx)).collect();
        let silent = (rxs.iter().enumerate())
            .filter(|(k, rx)| rx.reach_m[band] > 0.0 && rx.listening(t) && !unheard.heard.contains(k))
            .map(|(_, rx)| Placed::new(plane, rx))
            .filter(|s| {
                let gap_e = (min[0] - s.at.x).max(s.at.x - max[0]).max(0.0);
                let gap_n = (min[1] - s.at.y).max(s.at.y - max[1]).max(0.0);
                gap_e.hypot(gap_n) < s.rx.reach_m[band]
            })
            .collect();
        Hearing { band, heard, silent }
    }

    /// The cost at plane position (e, n), in chi-square units: -2 ln of the
    /// chance that those that heard it heard, and the others missed, a
    /// transmission from there.
    pub fn cost(&self, e: f64, n: f64) -> f64 {
        let heard = self.heard.iter().map(|s| {
            let d = s.own(e, n);
            s.rx.heard_cost_at(self.band, d.x, d.y)
        });
        let silent = self.silent.iter().map(|s| {
            let d = s.own(e, n);
            s.rx.miss_cost_at(self.band, d.x, d.y)
        });
        heard.chain(silent).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlat::coverage::{CoverageSnapshot, Table, BANDS, RINGS, SECTORS};
    use std::sync::Arc;

    /// A receiver at (e, n) of `plane` that heard 90 of 100 transmissions
    /// from within `hears_m`, none of 100 beyond, at any height.
    fn rx(plane: &Plane, e: f64, n: f64, hears_m: f64, last_heard: f64) -> RxCoverage {
        let (lat, lon) = plane.to_geodetic(e, n);
        let rings = (hears_m / crate::mlat::coverage::RING_M) as usize;
        let mut heard: Table = [[[0.0; RINGS]; SECTORS]; BANDS];
        heard.iter_mut().flatten().for_each(|s| s[..rings].fill(90.0));
        let offered = [[[100.0; RINGS]; SECTORS]; BANDS];
        RxCoverage::new(
            crate::geo::geodetic_to_ecef(lat, lon, 100.0),
            (lat, lon),
            last_heard,
            &heard,
            &offered,
        )
    }

    /// Near a listening receiver that did not hear: costly; beyond its
    /// reach, or while it was not listening: free. Beyond the reach of one
    /// that heard: costly.
    #[test]
    fn receivers_weigh_by_their_coverage() {
        let plane = Plane::new(48.0, 8.0, 0.0);
        let unheard = Unheard {
            coverage: Arc::new(CoverageSnapshot {
                rxs: vec![
                    rx(&plane, 0.0, 0.0, 125_000.0, 50.0),
                    rx(&plane, 200_000.0, 0.0, 125_000.0, 50.0),
                    rx(&plane, 0.0, 200_000.0, 125_000.0, -50.0),
                ],
            }),
            heard: smallvec::smallvec![1],
        };
        let h = 10_000.0;
        let s = Hearing::new(&plane, &unheard, 55.0, h, [-300_000.0; 2], [300_000.0; 2]);
        assert_eq!((s.heard.len(), s.silent.len()), (1, 1));
        // Inside the silent one's reach (its last ring aside), heard at 140 km.
        let missed_there = -2.0 * (1.0 - 450.0f64 / 504.0).ln();
        let heard_beyond = -2.0 * 0.02f64.ln();
        assert!((s.cost(60_000.0, 0.0) - missed_there).abs() < 1e-4, "{}", s.cost(60_000.0, 0.0));
        // Beyond the silent one's reach, within the hearing one's: the best place.
        assert_eq!(s.cost(150_000.0, 0.0), 0.0);
        // Inside the silent one's reach, beyond the hearing one's.
        assert!((s.cost(20_000.0, -60_000.0) - heard_beyond - missed_there).abs() < 1e-4);
        // The first receiver's reach does not get to a box far from it.
        let far = Hearing::new(&plane, &unheard, 55.0, h, [250_000.0; 2], [300_000.0; 2]);
        assert!(far.silent.is_empty());
    }

    /// Two sites 60 km apart hear an aircraft 80 km north of their
    /// baseline: one time difference, whose hyperbola runs north and south
    /// alike. A third receiver 100 km south, hearing everything within
    /// 150 km, hears nothing: the particle filter weighed by who heard
    /// leaves the southern half, which without it it keeps.
    #[test]
    fn a_silent_receiver_rules_out_a_mirror() {
        use crate::track::particle::{SparseConfig, SparseTrack};
        let plane = Plane::new(48.0, 8.0, 0.0);
        let h = 10_000.0;
        let site = |e: f64, n: f64| {
            let (lat, lon) = plane.to_geodetic(e, n);
            crate::geo::geodetic_to_ecef(lat, lon, 100.0)
        };
        let sites = [site(-30_000.0, 0.0), site(30_000.0, 0.0)];
        let unheard = Unheard {
            coverage: Arc::new(CoverageSnapshot {
                rxs: vec![
                    rx(&plane, -30_000.0, 0.0, 150_000.0, 0.0),
                    rx(&plane, 30_000.0, 0.0, 150_000.0, 0.0),
                    rx(&plane, 20_000.0, -100_000.0, 150_000.0, 0.0),
                ],
            }),
            heard: smallvec::smallvec![0, 1],
        };
        let toas = |t: f64| {
            let (lat, lon) = plane.to_geodetic(20_000.0 + 200.0 * t, 80_000.0);
            let p = crate::geo::geodetic_to_ecef(lat, lon, h);
            sites.map(|s| (s, t + crate::geo::ecef_distance(p, s) / crate::mlat::solver::C_AIR, 50e-9))
        };
        let cfg = SparseConfig { enabled: true, hearing_memory_s: 1.0, ..Default::default() };
        let south_share = |unheard: Option<&Unheard>, seed: u64| {
            let mut s = SparseTrack::start(&cfg, &toas(0.0), unheard, 0.0, h, seed).unwrap();
            for k in 1..=30 {
                let t = k as f64;
                s.update(&cfg, &toas(t), unheard, t, h);
            }
            // In the cloud's own plane, centred between the sites.
            let (cloud, _) = s.gaussian();
            let baseline = cloud.to_en(plane.lat, plane.lon)[1];
            s.particles().filter(|(x, _)| x[1] < baseline).map(|(_, w)| w).sum::<f64>()
        };
        // Over a few seeds: a cloud left to itself loses part of one half
        // or the other by chance.
        let with: Vec<f64> = (1..=4).map(|seed| south_share(Some(&unheard), seed)).collect();
        let without: Vec<f64> = (1..=4).map(|seed| south_share(None, seed)).collect();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        assert!(with.iter().all(|&w| w < 0.05), "{with:?} {without:?}");
        assert!(mean(&without) > 0.25, "{with:?} {without:?}");
    }
}
