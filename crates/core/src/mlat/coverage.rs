//! Where each receiver hears aircraft, learnt from the traffic: for
//! sectors of bearing and rings of ground range around it, the share of
//! positioned aircraft's transmissions there that it heard.
//!
//! Why: an aircraft heard by two or three receivers only is placed by one
//! or two time differences, and those have mirror solutions (the other
//! crossing of two hyperbolas, the far end of one). What tells them apart
//! is who heard it and who did *not*: a point deep inside a listening
//! receiver's coverage is unlikely for a transmission it missed, one
//! beyond a receiver's reach for a transmission it heard. The particle
//! filter weighs its particles by that ([`crate::track::hearing`]).
//!
//! Learnt from ADS-B positions and fixes with redundancy (nothing but the
//! traffic: receivers' ranges differ with antennas, sites and terrain, by
//! bearing too). Each aircraft is sampled once every few seconds at most:
//! its successive transmissions are heard alike, and the sample costs a
//! look at every receiver. Counts are halved once a cell has seen enough, so that a
//! receiver's coverage follows a changed antenna. A receiver is listening
//! while it has sent anything lately; one that has not is never counted
//! as silent.

use std::sync::Arc;

use crate::geo::{ecef_to_geodetic, geodetic_to_ecef};
use crate::mlat::survey::enu_basis;

/// Bearing sectors around a receiver (45 degrees each, clockwise from north).
pub const SECTORS: usize = 8;
/// Ground range rings (m each), out to `RINGS * RING_M`: beyond any radio
/// horizon of an airliner.
pub const RING_M: f64 = 25_000.0;
pub const RINGS: usize = 24;
/// Height bands (m): a low aircraft's radio horizon is nearer, so a
/// receiver's reach depends on the height too.
pub const BANDS: usize = 2;
const BAND_SPLIT_M: f64 = 5_000.0;
/// One aircraft is sampled this often at most (s).
const SAMPLE_EVERY_S: f64 = 5.0;
/// A receiver that sent nothing for this long (s) is not listening.
pub const LISTENING_S: f64 = 10.0;
/// A cell's counts are halved once it was offered this many transmissions.
const CELL_MEMORY: f32 = 200.0;
/// How each receiver's coverage is modelled from its counts: per height
/// band and bearing sector, a reach (the ring within which it heard
/// `REACH_SHARE` of what it heard there, once it heard `SECTOR_HEARD`),
/// hearing a share of what flies inside. Not cell by cell: a cell's share
/// of one aircraft's transmissions is not the cell's share (transponders
/// differ in power, heights within a band in horizon), and small
/// differences between cells along a hyperbola, counted at every
/// transmission, pulled clouds onto wrong places; and cells learn slowly.
const SECTOR_HEARD: f32 = 30.0;
const REACH_SHARE: f32 = 0.98;
/// A sector is deaf (reach 0) once a receiver missed at least
/// `DEAF_MISSES` there and heard less than `DEAF_SHARE` of what flew there,
/// both counted within the furthest it hears in any direction.
const DEAF_SHARE: f32 = 0.05;
const DEAF_MISSES: f32 = 20.0;
/// A miss counts inside the reach (less its last ring, where the reach
/// ends) where a receiver hears at least this share...
const MISS_EVIDENCE: f32 = 0.5;
/// ...the share shrunk towards zero by this many offered transmissions...
const PRIOR_OFFERED: f32 = 4.0;
/// ...and no receiver is taken to hear more surely than this: a miss deep
/// inside its coverage happens (garbled replies, a weak transponder), and
/// one must not rule a place out alone.
const MAX_DETECT: f32 = 0.9;
/// A hearing counts only beyond this many rings past the reach (a reach
/// from a few dozen aircraft falls short of the true one), where the
/// receiver missed at least `BEYOND_MISSES` transmissions in the first
/// `BEYOND_EVIDENCE_RINGS` rings of it (nothing flying there is no
/// evidence)...
const BEYOND_MARGIN: usize = 1;
const BEYOND_MISSES: f32 = 30.0;
const BEYOND_EVIDENCE_RINGS: usize = 2;
/// ...as this share heard: an aircraft heard further than its kind usually
/// is (a strong transponder, a duct) is rare, not impossible.
const MIN_DETECT: f32 = 0.02;
/// A sector nothing is known of takes the others' reach once this many
/// are known.
const FALLBACK_SECTORS: usize = 3;
/// Where no sector can say, a hearing counts as beyond reach this many
/// rings past the furthest ring it ever heard an aircraft of the height
/// band in, once it heard this many of them (its range is about the same
/// all round, terrain shortens it).
const BEYOND_RINGS: usize = 2;
const BEYOND_AFTER_HEARD: f32 = 50.0;
/// The snapshot handed to the tracker is renewed this often (s).
const SNAPSHOT_EVERY_S: f64 = 2.0;

/// A value per height band, bearing sector and range ring.
pub type Table = [[[f32; RINGS]; SECTORS]; BANDS];

/// The height band of an aircraft at `h_m` (m).
pub fn band(h_m: f64) -> usize {
    (h_m >= BAND_SPLIT_M) as usize
}

/// The sector (clockwise from north, 45 degrees each) of a direction
/// given by its east and north components.
pub fn sector(e: f64, n: f64) -> usize {
    let (ae, an) = (e.abs(), n.abs());
    match (e >= 0.0, n >= 0.0) {
        (true, true) => (ae > an) as usize,
        (true, false) => 2 + (an > ae) as usize,
        (false, false) => 4 + (ae > an) as usize,
        (false, true) => 6 + (an > ae) as usize,
    }
}

/// One receiver's counts: heard and offered per cell.
#[derive(Clone)]
struct Cells {
    heard: Table,
    offered: Table,
}

/// One sector's coverage in one height band.
struct Sector {
    /// The rings within which it heard nearly all it heard (None before it
    /// heard enough to say).
    reach: Option<usize>,
    /// The share it heard inside the reach.
    inside: f32,
    /// Transmissions it missed beyond the reach.
    misses_beyond: f32,
}

impl Sector {
    /// For a sector nothing is known of, once enough others are: the
    /// shortest of their reaches and the least of their shares (a range is
    /// about the same all round; terrain shortens it, so the least).
    fn fallback(sectors: &[Sector; SECTORS]) -> Option<(usize, f32)> {
        let known = sectors.iter().filter_map(|s| s.reach.filter(|&k| k > 0).map(|k| (k, s.inside)));
        let (n, k, inside) =
            known.fold((0, RINGS, 1.0f32), |(n, k, p), (ks, ps)| (n + 1, k.min(ks), p.min(ps)));
        (n >= FALLBACK_SECTORS && inside >= MISS_EVIDENCE).then_some((k, inside))
    }

    /// One sector's counts; `heard_within` is how many rings out the
    /// receiver heard anything in any sector of the band (None before it
    /// heard anything): misses further out than any hearing, at the far
    /// end of the network's traffic, say nothing of this sector.
    fn of(heard: &[f32; RINGS], offered: &[f32; RINGS], heard_within: Option<usize>) -> Sector {
        let total: f32 = heard.iter().sum();
        let misses = |rings: std::ops::Range<usize>| -> f32 {
            let rings = rings.start.min(RINGS)..rings.end.min(RINGS);
            (offered[rings.clone()].iter().sum::<f32>() - heard[rings].iter().sum::<f32>()).max(0.0)
        };
        if total < SECTOR_HEARD {
            // A deaf sector (an antenna blocked that way) once it missed
            // enough where it hears in other directions; else nothing known.
            let Some(within) = heard_within else { return Sector::UNKNOWN };
            let offered_within: f32 = offered[..within.min(RINGS)].iter().sum();
            let missed = misses(0..within);
            let deaf = missed >= DEAF_MISSES && total < DEAF_SHARE * offered_within;
            return if deaf {
                Sector { reach: Some(0), inside: 0.0, misses_beyond: missed }
            } else {
                Sector::UNKNOWN
            };
        }
        let mut acc = 0.0;
        let k = (0..RINGS)
            .find(|&r| {
                acc += heard[r];
                acc >= REACH_SHARE * total
            })
            .map_or(RINGS, |r| r + 1);
        // Its share over the whole reach: where few fly near it (a network
        // whose traffic passes at its edge) the inner rings say little.
        let (h, o): (f32, f32) = (heard[..k].iter().sum(), offered[..k].iter().sum());
        // What it missed where a hearing starts to count as beyond its
        // reach: misses far past it (aircraft at the network's other end)
        // say nothing of how far it hears.
        let far = k + 1 + BEYOND_MARGIN;
        let misses_beyond = misses(far..far + BEYOND_EVIDENCE_RINGS);
        Sector { reach: Some(k), inside: h / (o + PRIOR_OFFERED), misses_beyond }
    }

    const UNKNOWN: Sector = Sector { reach: None, inside: 0.0, misses_beyond: 0.0 };
}

/// A receiver's place and axes, and when it last sent anything (server s).
#[derive(Clone)]
struct Site {
    ecef: [f64; 3],
    lat_lon: (f64, f64),
    enu: [[f64; 3]; 3],
    last_heard: f64,
}

/// The learner, in the engine.
#[derive(Default)]
pub struct Coverage {
    /// Learnt only where it is used (the particle filter on).
    enabled: bool,
    sites: Vec<Site>,
    cells: Vec<Cells>,
    /// Last sample of each aircraft (server s).
    sampled: crate::FastMap<u32, f64>,
    snapshot: Option<(f64, Arc<CoverageSnapshot>)>,
}

/// What the tracker is handed: every receiver's place, when it last sent
/// anything, and what hearing or missing a transmission from each cell
/// around it costs.
#[derive(Debug, PartialEq)]
pub struct CoverageSnapshot {
    pub rxs: Vec<RxCoverage>,
}

#[derive(Debug, PartialEq)]
pub struct RxCoverage {
    pub ecef: [f64; 3],
    pub lat: f64,
    pub lon: f64,
    /// When it last sent anything (server s).
    pub last_heard: f64,
    /// -2 ln of the share it misses (chi-square units), per cell.
    miss_cost: Table,
    /// -2 ln of the share it hears, per cell.
    heard_cost: Table,
    /// Ground range (m) beyond which a miss costs nothing, per height band
    /// (0 before it was offered anything).
    pub reach_m: [f64; BANDS],
}

impl RxCoverage {
    /// A receiver at `ecef` (`lat`, `lon` deg) that last sent anything at
    /// `last_heard`, and heard `heard` of the `offered` transmissions of
    /// each cell.
    pub fn new(
        ecef: [f64; 3],
        (lat, lon): (f64, f64),
        last_heard: f64,
        heard: &Table,
        offered: &Table,
    ) -> Self {
        let zero = [[[0.0; RINGS]; SECTORS]; BANDS];
        let (mut miss_cost, mut heard_cost, mut reach_m) = (zero, zero, [0.0; BANDS]);
        for b in 0..BANDS {
            let heard_within = Self::heard_within(&heard[b]);
            let beyond = Self::beyond_ring(&heard[b], heard_within);
            let sectors: [Sector; SECTORS] =
                std::array::from_fn(|s| Sector::of(&heard[b][s], &offered[b][s], heard_within));
            let fallback = Sector::fallback(&sectors);
            for (s, sector) in sectors.iter().enumerate() {
                for (r, cost) in heard_cost[b][s].iter_mut().enumerate() {
                    let far = match sector.reach {
                        Some(k) => r > k + BEYOND_MARGIN && sector.misses_beyond >= BEYOND_MISSES,
                        None => false,
                    } || beyond.is_some_and(|k| r >= k);
                    *cost = if far { -2.0 * MIN_DETECT.ln() } else { 0.0 };
                }
                let hears = match sector.reach {
                    Some(k) => (sector.inside >= MISS_EVIDENCE).then_some((k, sector.inside)),
                    None => fallback,
                };
                if let Some((k, inside)) = hears {
                    let cost = -2.0 * (1.0 - inside.min(MAX_DETECT)).ln();
                    miss_cost[b][s][..k.saturating_sub(1)].fill(cost);
                    reach_m[b] = f64::max(reach_m[b], k.saturating_sub(1) as f64 * RING_M);
                }
            }
        }
        RxCoverage { ecef, lat, lon, last_heard, miss_cost, heard_cost, reach_m }
    }

    /// How many rings out it heard anything, in any sector.
    fn heard_within(heard: &[[f32; RINGS]; SECTORS]) -> Option<usize> {
        (0..RINGS).rev().find(|&r| heard.iter().any(|s| s[r] > 0.0)).map(|r| r + 1)
    }

    /// The first ring taken as beyond reach in every sector: a few past the
    /// furthest it heard anything in, once it heard enough to say.
    fn beyond_ring(heard: &[[f32; RINGS]; SECTORS], heard_within: Option<usize>) -> Option<usize> {
        let total: f32 = heard.iter().flatten().sum();
        heard_within.filter(|_| total >= BEYOND_AFTER_HEARD).map(|k| k + BEYOND_RINGS)
    }

    /// The cost (chi-square units) of its missing a transmission from an
    /// aircraft in height band `band`, `east_m`, `north_m` of it (its own
    /// axes): -2 ln of the share it misses there, where that is strong
    /// evidence, else 0.
    pub fn miss_cost_at(&self, band: usize, east_m: f64, north_m: f64) -> f64 {
        Self::cell(&self.miss_cost, band, east_m, north_m).unwrap_or(0.0)
    }

    /// The cost of its hearing one from there: -2 ln of the share it hears,
    /// where that is strong evidence (beyond its reach), else 0.
    pub fn heard_cost_at(&self, band: usize, east_m: f64, north_m: f64) -> f64 {
        Self::cell(&self.heard_cost, band, east_m, north_m).unwrap_or(-2.0 * (MIN_DETECT as f64).ln())
    }

    #[inline]
    fn cell(table: &Table, band: usize, east_m: f64, north_m: f64) -> Option<f64> {
        let ring = ((east_m * east_m + north_m * north_m).sqrt() / RING_M) as usize;
        (ring < RINGS).then(|| table[band][sector(east_m, north_m)][ring] as f64)
    }

    /// Whether it was listening at server time `t`.
    pub fn listening(&self, t: f64) -> bool {
        (t - self.last_heard).abs() <= LISTENING_S
    }
}

/// A transmission's receivers and the coverage of all of them: the
/// silence of those that did not hear it.
#[derive(Clone, Debug, PartialEq)]
pub struct Unheard {
    pub coverage: Arc<CoverageSnapshot>,
    /// The receivers that heard it (indices into `coverage.rxs`).
    pub heard: smallvec::SmallVec<[usize; 8]>,
}

impl Coverage {
    /// A learner that learns (the default one does nothing).
    pub fn enabled() -> Self {
        Coverage { enabled: true, ..Default::default() }
    }

    /// A receiver added (nothing kept while the learner is off: the
    /// engine adds every receiver it knows when it turns it on).
    pub fn add_receiver(&mut self, lat: f64, lon: f64, alt_m: f64) {
        if !self.enabled {
            return;
        }
        self.sites.push(Site {
            ecef: geodetic_to_ecef(lat, lon, alt_m),
            lat_lon: (lat, lon),
            enu: enu_basis(lat, lon),
            last_heard: f64::NEG_INFINITY,
        });
        let zero = [[[0.0; RINGS]; SECTORS]; BANDS];
        self.cells.push(Cells { heard: zero, offered: zero });
    }

    /// Receiver `rx` sent something at server time `now`.
    #[inline]
    pub fn note_heard(&mut self, rx: usize, now: f64) {
        if let (true, Some(s)) = (self.enabled, self.sites.get_mut(rx)) {
            s.last_heard = now;
        }
    }

    /// A transmission's group at server time `now`: its receivers were
    /// listening, and its ADS-B position (unless suspect) is a sample.
    pub fn on_group(&mut self, g: &crate::mlat::group::Group, now: f64) {
        if !self.enabled {
            return;
        }
        for c in &g.copies {
            self.note_heard(c.rx, now);
        }
        if let (Some(a), false) = (g.info.adsb_ecef, g.info.suspect) {
            self.observe(g.info.addr, a, g.copies.iter().map(|c| c.rx), now);
        }
    }

    /// A transmission of aircraft `addr` from `ecef` heard by `heard`:
    /// counted for every listening receiver, if the aircraft is due a
    /// sample.
    pub fn observe(
        &mut self,
        addr: u32,
        ecef: [f64; 3],
        heard: impl Iterator<Item = usize> + Clone,
        now: f64,
    ) {
        let due = self.enabled && self.sampled.get(&addr).is_none_or(|&t| (now - t).abs() >= SAMPLE_EVERY_S);
        if !due {
            return;
        }
        self.sampled.insert(addr, now);
        let b = band(ecef_to_geodetic(ecef).2);
        for (rx, (site, cells)) in self.sites.iter().zip(self.cells.iter_mut()).enumerate() {
            if (now - site.last_heard).abs() > LISTENING_S {
                continue;
            }
            let d = [ecef[0] - site.ecef[0], ecef[1] - site.ecef[1], ecef[2] - site.ecef[2]];
            let dot = |a: &[f64; 3]| a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
            let (e, n) = (dot(&site.enu[0]), dot(&site.enu[1]));
            let ring = ((e * e + n * n).sqrt() / RING_M) as usize;
            if ring >= RINGS {
                continue;
            }
            let s = sector(e, n);
            let was_heard = heard.clone().any(|h| h == rx);
            let offered = &mut cells.offered[b][s][ring];
            let got = &mut cells.heard[b][s][ring];
            *offered += 1.0;
            *got += was_heard as u8 as f32;
            if *offered >= CELL_MEMORY {
                *offered *= 0.5;
                *got *= 0.5;
            }
        }
    }

    /// Who heard a transmission (its copies), with the coverage, for the
    /// tracker (`None` while the learner is off).
    pub fn unheard(&mut self, heard: &[crate::mlat::group::Copy], now: f64) -> Option<Unheard> {
        self.enabled
            .then(|| Unheard { coverage: self.snapshot(now), heard: heard.iter().map(|c| c.rx).collect() })
    }

    /// The coverage as the tracker takes it, renewed every few seconds.
    pub fn snapshot(&mut self, now: f64) -> Arc<CoverageSnapshot> {
        match &self.snapshot {
            Some((t, s)) if (now - t).abs() < SNAPSHOT_EVERY_S => s.clone(),
            _ => {
                let rxs = (self.sites.iter().zip(&self.cells))
                    .map(|(site, c)| {
                        RxCoverage::new(site.ecef, site.lat_lon, site.last_heard, &c.heard, &c.offered)
                    })
                    .collect();
                let s = Arc::new(CoverageSnapshot { rxs });
                self.snapshot = Some((now, s.clone()));
                s
            }
        }
    }

    /// Forgets the samples of aircraft not sampled for `ttl_s`.
    pub fn prune(&mut self, now: f64, ttl_s: f64) {
        self.sampled.retain(|_, t| now - *t <= ttl_s);
    }

    /// Aircraft whose last sample is remembered.
    pub fn sampled_count(&self) -> usize {
        self.sampled.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::plane::Plane;

    #[test]
    fn sectors_run_clockwise_from_north() {
        let at = |deg: f64| {
            let a = deg.to_radians();
            sector(a.sin(), a.cos())
        };
        let got: Vec<usize> = [10.0, 80.0, 100.0, 170.0, 190.0, 260.0, 280.0, 350.0].map(at).to_vec();
        assert_eq!(got, (0..8).collect::<Vec<_>>());
    }

    /// A receiver hearing everything within 100 km to its east and nothing
    /// to its west: learnt so, its reach is where it stops hearing, and a
    /// receiver that sent nothing is never counted.
    #[test]
    fn learns_where_a_receiver_hears() {
        let plane = Plane::new(48.0, 8.0, 0.0);
        let mut c = Coverage::enabled();
        c.add_receiver(48.0, 8.0, 200.0);
        c.add_receiver(48.5, 8.0, 200.0);
        let mut now = 0.0;
        for k in 0..4000u32 {
            now = k as f64 * 0.1;
            c.note_heard(0, now);
            let bearing = (k as f64 * 0.618_034).fract() * std::f64::consts::TAU;
            let range = 5_000.0 + (k as f64 * 0.414_213).fract() * 295_000.0;
            let (e, n) = (range * bearing.sin(), range * bearing.cos());
            let (lat, lon) = plane.to_geodetic(e, n);
            let heard = e > 0.0 && range < 100_000.0;
            let rxs: &[usize] = if heard { &[0] } else { &[] };
            // Every aircraft its own address: each one sampled.
            c.observe(k, geodetic_to_ecef(lat, lon, 10_000.0), rxs.iter().copied(), now);
        }
        let s = c.snapshot(now);
        let rx = &s.rxs[0];
        let high = band(10_000.0);
        // Where it hears: a miss costs much, hearing little.
        assert!(
            rx.miss_cost_at(high, 50_000.0, 10_000.0) > 3.0,
            "{}",
            rx.miss_cost_at(high, 50_000.0, 10_000.0)
        );
        assert_eq!(rx.heard_cost_at(high, 50_000.0, 10_000.0), 0.0);
        // Where it does not (its deaf west, beyond its reach east): a miss
        // costs nothing, hearing much.
        assert_eq!(rx.miss_cost_at(high, -50_000.0, 10_000.0), 0.0);
        assert!(rx.heard_cost_at(high, -50_000.0, 10_000.0) > 5.0);
        assert_eq!(rx.miss_cost_at(high, 150_000.0, 0.0), 0.0);
        assert!(rx.heard_cost_at(high, 150_000.0, 0.0) > 5.0);
        // Misses count inside its reach less its last ring.
        assert_eq!(rx.reach_m[high], 75_000.0);
        // Nothing was offered low: nothing known there.
        assert_eq!(rx.reach_m[0], 0.0);
        assert_eq!(rx.miss_cost_at(0, 50_000.0, 10_000.0), 0.0);
        assert_eq!(rx.heard_cost_at(0, 50_000.0, 10_000.0), 0.0);
        assert!(rx.listening(now) && !rx.listening(now + 60.0));
        // The other receiver was never listening: nothing learnt of it.
        assert_eq!(s.rxs[1].reach_m, [0.0; BANDS]);
        assert!(!s.rxs[1].listening(now));
    }

    /// A sector that heard few aircraft yet, but missed many far beyond
    /// where the receiver hears in any direction (the network's other end),
    /// is not taken for deaf: only misses where it could hear say so.
    #[test]
    fn misses_beyond_any_hearing_do_not_make_a_sector_deaf() {
        let plane = Plane::new(48.0, 8.0, 0.0);
        let mut c = Coverage::enabled();
        c.add_receiver(48.0, 8.0, 200.0);
        let mut k = 0u32;
        let mut offer = |c: &mut Coverage, bearing_deg: f64, range_m: f64| {
            k += 1;
            let now = k as f64 * 0.01;
            c.note_heard(0, now);
            let b = bearing_deg.to_radians();
            let (lat, lon) = plane.to_geodetic(range_m * b.sin(), range_m * b.cos());
            let heard = (0.0..180.0).contains(&bearing_deg) && range_m < 100_000.0;
            let rxs: &[usize] = if heard { &[0] } else { &[] };
            c.observe(k, geodetic_to_ecef(lat, lon, 10_000.0), rxs.iter().copied(), now);
        };
        for j in 0..2000 {
            let f = |x: f64| (j as f64 * x).fract();
            // Everywhere but the first sector: its east hears within 100 km, its west nothing.
            offer(&mut c, 45.0 + 315.0 * f(0.618_034), 5_000.0 + 295_000.0 * f(0.414_213));
        }
        for j in 0..300 {
            // The first sector: a few near (heard), many far beyond any hearing.
            let near = j % 30 == 0;
            let range = if near { 20_000.0 + 700.0 * j as f64 } else { 300_000.0 + 800.0 * j as f64 };
            offer(&mut c, 20.0, range);
        }
        let rx = &c.snapshot(1e6).rxs[0];
        let high = band(10_000.0);
        // Heard 50 km out in the first sector: nothing against it.
        assert_eq!(rx.heard_cost_at(high, 10_000.0, 50_000.0), 0.0);
        // The west, which missed everything within the east's reach, is deaf.
        assert!(rx.heard_cost_at(high, -50_000.0, 10_000.0) > 5.0);
    }

    /// One aircraft's transmissions count once every few seconds.
    #[test]
    fn an_aircraft_is_sampled_now_and_then() {
        let mut c = Coverage::enabled();
        c.add_receiver(48.0, 8.0, 200.0);
        let at = geodetic_to_ecef(48.2, 8.0, 10_000.0);
        for k in 0..100 {
            let now = k as f64 * 0.1;
            c.note_heard(0, now);
            c.observe(7, at, [0usize].into_iter(), now);
        }
        let offered: f32 = c.cells[0].offered.iter().flatten().flatten().sum();
        assert_eq!(offered, 2.0);
        c.prune(100.0, 30.0);
        assert_eq!(c.sampled_count(), 0);
    }
}
