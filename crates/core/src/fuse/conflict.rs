//! Conflict prediction between tracks, TCAS II style (traffic advisory).
//!
//! For a pair: horizontal range `r`, range rate, the modified tau
//! `(DMOD^2 - r^2) / (r dr/dt)` (which, unlike plain `r / (dr/dt)`, still
//! warns of slow closures that end close), the vertical separation and its
//! tau, and the predicted closest point of approach. A pair is in conflict
//! when, with the sensitivity level of the lower aircraft's altitude,
//! horizontally `r < DMOD` or modified tau (and the time to closest
//! approach) under the TA tau, vertically
//! within ZTHR or converging to it within the same tau, and the predicted
//! miss distance under the configured limit (the miss-distance filter that
//! keeps traffic passing miles apart quiet).
//!
//! Pairs are found through a grid of cells about as large as the farthest
//! two aircraft can close within the longest tau, so the cost grows with
//! traffic density, not with the square of the traffic.

use crate::FastMap;

use serde::{Deserialize, Serialize};

use crate::geo::FT_TO_M;
use crate::problem::{not_negative, positive, Problem};

pub const NM: f64 = 1852.0;

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ConflictConfig {
    pub enabled: bool,
    /// Predicted horizontal miss distance beyond which no alert is raised (NM).
    pub max_miss_nm: f64,
    /// How often pairs are examined (s).
    pub interval_s: f64,
    /// An alert clears once its pair has failed the test this long (s): a
    /// pair whose predicted miss hovers at the limit raised and cleared an
    /// alert every second or two without it.
    pub clear_after_s: f64,
}

impl Default for ConflictConfig {
    fn default() -> Self {
        ConflictConfig { enabled: true, max_miss_nm: 1.0, interval_s: 1.0, clear_after_s: 3.0 }
    }
}

impl ConflictConfig {
    /// Every problem of the table at `path` (`core.fuse.conflict`), into `out`.
    pub fn validate(&self, path: &str, out: &mut Vec<Problem>) {
        positive(path, &[("max_miss_nm", self.max_miss_nm), ("interval_s", self.interval_s)], out);
        not_negative(path, &[("clear_after_s", self.clear_after_s)], out);
    }
}

/// TA thresholds of a sensitivity level: tau (s), DMOD (NM), ZTHR (ft).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Level {
    pub tau_s: f64,
    pub dmod_nm: f64,
    pub zthr_ft: f64,
}

/// TCAS II traffic-advisory thresholds by altitude (ft).
pub fn level(alt_ft: f64) -> Level {
    let (tau_s, dmod_nm, zthr_ft) = match alt_ft {
        a if a < 1_000.0 => (20.0, 0.30, 850.0),
        a if a < 2_350.0 => (25.0, 0.33, 850.0),
        a if a < 5_000.0 => (30.0, 0.48, 850.0),
        a if a < 10_000.0 => (40.0, 0.75, 850.0),
        a if a < 20_000.0 => (45.0, 1.00, 850.0),
        a if a < 42_000.0 => (48.0, 1.30, 850.0),
        _ => (48.0, 1.30, 1_200.0),
    };
    Level { tau_s, dmod_nm, zthr_ft }
}

/// What the conflict test needs of a track: a common east/north/up frame (m, m/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kinematics {
    pub addr: u32,
    pub pos: [f64; 3],
    pub vel: [f64; 3],
    /// Altitude for the sensitivity level (ft).
    pub alt_ft: f64,
}

/// An airborne track's latest state, as conflict prediction reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seen {
    pub addr: u32,
    /// When the state holds (s).
    pub t: f64,
    pub lat: f64,
    pub lon: f64,
    /// Height above the ellipsoid (m).
    pub alt_m: f64,
    pub vel_enu: [f64; 3],
    /// Altitude for the sensitivity level (ft).
    pub alt_ft: f64,
}

/// The tracks moved to `now` along their velocities, in a plane at the
/// first one in address order: the frame's origin (and so every figure)
/// must not depend on a hash map's order, or runs would differ.
pub fn kinematics_at(now: f64, mut seen: Vec<Seen>) -> Vec<Kinematics> {
    seen.sort_unstable_by_key(|s| s.addr);
    let Some(first) = seen.first() else {
        return Vec::new();
    };
    let origin = crate::track::plane::Plane::new(first.lat, first.lon, 0.0);
    seen.iter()
        .map(|s| {
            let en = origin.to_en(s.lat, s.lon);
            let (v, dt) = (s.vel_enu, (now - s.t).max(0.0));
            let pos = [en[0] + v[0] * dt, en[1] + v[1] * dt, s.alt_m + v[2] * dt];
            Kinematics { addr: s.addr, pos, vel: v, alt_ft: s.alt_ft }
        })
        .collect()
}

/// A predicted conflict.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conflict {
    pub a: u32,
    pub b: u32,
    /// Modified tau (s; 0 inside DMOD).
    pub tau_s: f64,
    /// Time to the closest point of approach (s) and the miss distance there (m).
    pub t_cpa_s: f64,
    pub miss_m: f64,
    /// Vertical separation now (m).
    pub dz_m: f64,
}

/// The pair test.
pub fn assess(cfg: &ConflictConfig, a: &Kinematics, b: &Kinematics) -> Option<Conflict> {
    let (dz, vz) = (b.pos[2] - a.pos[2], b.vel[2] - a.vel[2]);
    // The vertical test first: it is cheap and most pairs in a cell are at
    // other levels. Before the level is even looked up, the test with the
    // table's loosest values (ZTHR 1,200 ft to be within, 850 ft and tau
    // 48 s to close on): a pair that fails it fails at every level, and
    // the lookup was half of a rejected pair's cost.
    let within = |zthr_ft: f64| dz.abs() < zthr_ft * FT_TO_M;
    let closing =
        |zthr_ft: f64, tau_s: f64| dz * vz < 0.0 && (dz.abs() - zthr_ft * FT_TO_M) / vz.abs() < tau_s;
    if !(within(1_200.0) || closing(850.0, 48.0)) {
        return None;
    }
    let lvl = level(a.alt_ft.min(b.alt_ft));
    let (dx, dy) = (b.pos[0] - a.pos[0], b.pos[1] - a.pos[1]);
    let (vx, vy) = (b.vel[0] - a.vel[0], b.vel[1] - a.vel[1]);
    if !(within(lvl.zthr_ft) || closing(lvl.zthr_ft, lvl.tau_s)) {
        return None;
    }
    let r = dx.hypot(dy);
    let rdot = if r > 0.0 { (dx * vx + dy * vy) / r } else { 0.0 };
    let dmod = lvl.dmod_nm * NM;
    let v2 = vx * vx + vy * vy;
    let t_cpa = if v2 > 0.0 { (-(dx * vx + dy * vy) / v2).max(0.0) } else { 0.0 };
    let miss = (dx + vx * t_cpa).hypot(dy + vy * t_cpa);
    let tau = if r < dmod {
        0.0
    } else if rdot < 0.0 {
        (dmod * dmod - r * r) / (r * rdot)
    } else {
        return None;
    };
    // Modified tau runs ahead of the time to closest approach by DMOD^2 /
    // (v^2 t); the look-ahead holds for both.
    let horizontal = tau < lvl.tau_s && (r < dmod || t_cpa <= lvl.tau_s) && miss < cfg.max_miss_nm * NM;
    horizontal.then_some(Conflict {
        a: a.addr,
        b: b.addr,
        tau_s: tau,
        t_cpa_s: t_cpa,
        miss_m: miss,
        dz_m: dz,
    })
}

/// Every conflicting pair among `tracks`, through a grid.
pub fn find(cfg: &ConflictConfig, tracks: &[Kinematics]) -> Vec<Conflict> {
    // Two aircraft closing at 1,200 m/s for 48 s: 58 km; a cell that size
    // means a conflicting pair is in the same or a neighbouring cell.
    const CELL_M: f64 = 60_000.0;
    let key = |k: &Kinematics| ((k.pos[0] / CELL_M).floor() as i64, (k.pos[1] / CELL_M).floor() as i64);
    let mut grid: FastMap<(i64, i64), Vec<usize>> = FastMap::default();
    for (i, k) in tracks.iter().enumerate() {
        grid.entry(key(k)).or_default().push(i);
    }
    // Each pair once: a cell with itself and with the four of its eight
    // neighbours that come after it (the other four take it with them).
    // Visiting every aircraft's nine cells saw each pair twice and cost a
    // hash lookup per aircraft and cell: the search took 45% more, and a
    // pass holds the tracker's thread (every update behind it waits).
    let mut out = Vec::new();
    let mut test = |i: usize, j: usize| {
        let (i, j) = (i.min(j), i.max(j));
        if let Some(c) = assess(cfg, &tracks[i], &tracks[j]) {
            out.push(c);
        }
    };
    for (&(cx, cy), members) in &grid {
        for (n, &i) in members.iter().enumerate() {
            for &j in &members[n + 1..] {
                test(i, j);
            }
        }
        for (dx, dy) in [(1, -1), (1, 0), (1, 1), (0, 1)] {
            if let Some(others) = grid.get(&(cx + dx, cy + dy)) {
                for &i in members {
                    for &j in others {
                        test(i, j);
                    }
                }
            }
        }
    }
    out.sort_by_key(|c| (c.a, c.b));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k(addr: u32, x: f64, y: f64, vx: f64, vy: f64, alt_ft: f64) -> Kinematics {
        Kinematics { addr, pos: [x, y, alt_ft * FT_TO_M], vel: [vx, vy, 0.0], alt_ft }
    }

    #[test]
    fn the_vertical_prefilter_is_looser_than_every_level() {
        // `assess` rejects before looking the level up with ZTHR 1,200 ft
        // (within), 850 ft and tau 48 s (closing): no level may be looser.
        for ft in (-2_000..60_000).step_by(50) {
            let l = level(ft as f64);
            assert!((850.0..=1_200.0).contains(&l.zthr_ft) && l.tau_s <= 48.0, "{ft} ft: {l:?}");
        }
    }

    #[test]
    fn head_on_at_fl350_alerts_between_48_and_35_s_and_a_5_nm_pass_does_not() {
        let cfg = ConflictConfig::default();
        // 250 m/s each, head-on: closing 500 m/s.
        let first = (0..120)
            .map(|s| 100.0 - s as f64)
            .find(|&t| {
                assess(
                    &cfg,
                    &k(1, 0.0, 0.0, 250.0, 0.0, 35_000.0),
                    &k(2, 500.0 * t, 0.0, -250.0, 0.0, 35_000.0),
                )
                .is_some()
            })
            .unwrap();
        assert!((35.0..=48.0).contains(&first), "first alert {first} s before CPA");
        // The same, 5 NM apart laterally: never.
        for s in 0..200 {
            let t = 100.0 - s as f64;
            assert!(assess(
                &cfg,
                &k(1, 0.0, 0.0, 250.0, 0.0, 35_000.0),
                &k(2, 500.0 * t, 5.0 * NM, -250.0, 0.0, 35_000.0)
            )
            .is_none());
        }
        // 2,000 ft apart vertically, level: never.
        assert!(assess(
            &cfg,
            &k(1, 0.0, 0.0, 250.0, 0.0, 35_000.0),
            &k(2, 5_000.0, 0.0, -250.0, 0.0, 37_000.0)
        )
        .is_none());
        assert_eq!(level(500.0).tau_s, 20.0);
        assert_eq!(level(45_000.0).zthr_ft, 1_200.0);
    }

    #[test]
    fn the_grid_finds_what_all_pairs_find() {
        let cfg = ConflictConfig::default();
        let mut tracks = Vec::new();
        for i in 0..400u32 {
            let f = i as f64;
            tracks.push(k(
                i,
                (f * 7919.0) % 300_000.0,
                (f * 104_729.0) % 300_000.0,
                200.0 * (f * 0.3).cos(),
                200.0 * (f * 0.3).sin(),
                30_000.0,
            ));
        }
        // Other levels, climbing and descending: pairs the vertical test
        // decides, in every altitude band.
        for i in 0..400u32 {
            let f = i as f64;
            let mut t = k(
                2000 + i,
                (f * 6133.0) % 300_000.0,
                (f * 7_727.0) % 300_000.0,
                220.0 * (f * 0.7).cos(),
                220.0 * (f * 0.7).sin(),
                2_000.0 + (f * 977.0) % 38_000.0,
            );
            t.vel[2] = 20.0 * (f * 1.3).sin();
            tracks.push(t);
        }
        // And some certain ones, across cell borders.
        for i in 0..10u32 {
            let x = 59_000.0 + 60_000.0 * i as f64;
            tracks.push(k(1000 + 2 * i, x, 1000.0, 250.0, 0.0, 30_000.0));
            tracks.push(k(1001 + 2 * i, x + 15_000.0, 1200.0, -250.0, 0.0, 30_000.0));
        }
        // Across the corners and the north border: each pair meets once.
        let corner: f64 = 120_000.0;
        for (n, (ax, ay, bx, by)) in
            [(-1e3, -1e3, 1e3, 1e3), (-1e3, 1e3, 1e3, -1e3), (5e3, -1e3, 5e3, 1e3)].into_iter().enumerate()
        {
            let (a, b) = ([corner + ax, corner + ay], [corner + bx, corner + by]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let v = 250.0 / dx.hypot(dy);
            let alt = 20_000.0 + 3_000.0 * n as f64;
            tracks.push(k(3000 + 2 * n as u32, a[0], a[1], dx * v, dy * v, alt));
            tracks.push(k(3001 + 2 * n as u32, b[0], b[1], -dx * v, -dy * v, alt));
        }
        let mut brute = Vec::new();
        for i in 0..tracks.len() {
            for j in i + 1..tracks.len() {
                if let Some(c) = assess(&cfg, &tracks[i], &tracks[j]) {
                    brute.push(c);
                }
            }
        }
        brute.sort_by_key(|c| (c.a, c.b));
        for n in 0..3 {
            assert!(brute.iter().any(|c| (c.a, c.b) == (3000 + 2 * n, 3001 + 2 * n)), "corner pair {n}");
        }
        assert!(brute.len() >= 13, "{}", brute.len());
        assert_eq!(find(&cfg, &tracks), brute);
    }
}
