//! Conformance monitor: does the timing agree with what an aircraft says?
//!
//! Each ADS-B position that was also multilaterated (the fix of the same
//! transmission) gives a difference whose covariance is the sum of both:
//! `d' (R_adsb + C_mlat)^-1 d` is chi-square with 2 degrees of freedom
//! for an honest aircraft. A CUSUM over those values, with a reference
//! well above the chi-square mean, stays at zero for honest traffic and
//! climbs by tens per fix for an offset of a few hundred metres. Each fix
//! adds at most 60% of the threshold, so a spoofer is flagged on its second
//! fix and a single wild fix (an MLAT failure) flags nobody; a chance
//! excursion of an honest aircraft would need several 1-in-1000 values in a
//! row. Fixes that do not fit their own timing (residual chi-square per
//! degree of freedom above 3) or have no redundancy are not used. The flag clears once the sum (capped
//! at twice the threshold) is back at zero and the last few fixes conform.
//!
//! While an aircraft is flagged, only fixes that could tell count: those
//! under which the offset it was flagged for (its running mean over the
//! non-conforming fixes) would itself fail the reference. A fix of poor
//! geometry (at the edge of coverage, or inflated for its synchronisation)
//! has a covariance wide enough to hold a 300 m spoof, and fixes like that
//! in a row once cleared a spoofer (tma-busy, seed 12: cleared after 290 s
//! with 194 m off at NIS 3.6, its spoofed positions then fused).

use crate::problem::{positive, Problem};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ConformanceConfig {
    /// Per-fix allowance subtracted from the chi-square(2) value.
    pub reference: f64,
    /// The sum that raises the flag.
    pub threshold: f64,
    /// Conforming fixes in a row (with the sum back at zero) that clear it.
    pub clear_after: u32,
}

impl Default for ConformanceConfig {
    fn default() -> Self {
        ConformanceConfig { reference: 10.0, threshold: 30.0, clear_after: 5 }
    }
}

impl ConformanceConfig {
    /// Every problem of the table at `path` (`core.fuse.conformance`), into `out`.
    pub fn validate(&self, path: &str, out: &mut Vec<Problem>) {
        if !(self.reference > 2.0 && self.reference.is_finite()) {
            out.push(Problem::at(
                path,
                format!("reference = {} must exceed 2 (the chi-square mean)", self.reference),
            ));
        }
        positive(path, &[("threshold", self.threshold)], out);
        if self.clear_after == 0 {
            out.push(Problem::at(path, "clear_after must be at least 1"));
        }
    }
}

/// One aircraft's monitor.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Monitor {
    pub sum: f64,
    pub suspect: bool,
    conforming: u32,
    /// Newest test value and offset (m), for the alert.
    pub last_nis: f64,
    pub last_offset_m: f64,
    /// While flagged: the offset (east, north m) flagged for, followed over
    /// the fixes that do not conform.
    flagged_offset: Option<[f64; 2]>,
}

/// Weight of each non-conforming fix in the flagged offset's running mean.
const OFFSET_WEIGHT: f64 = 0.2;

impl Monitor {
    /// One ADS-B/MLAT pair: east/north difference (m) and its covariance.
    /// Returns the new flag when it changed.
    pub fn push(&mut self, cfg: &ConformanceConfig, d: [f64; 2], s: [[f64; 2]; 2]) -> Option<bool> {
        let det = s[0][0] * s[1][1] - s[0][1] * s[1][0];
        if !(det > 0.0 && s[0][0] > 0.0 && d.iter().all(|v| v.is_finite())) {
            return None;
        }
        let test = |d: [f64; 2]| {
            (s[1][1] * d[0] * d[0] - (s[0][1] + s[1][0]) * d[0] * d[1] + s[0][0] * d[1] * d[1]) / det
        };
        let nis = test(d);
        // Flagged: a fix that would pass the offset flagged for cannot
        // clear it (nor tell anything else).
        if let (true, Some(o)) = (self.suspect, self.flagged_offset) {
            if test(o) < cfg.reference {
                return None;
            }
        }
        self.last_nis = nis;
        self.last_offset_m = d[0].hypot(d[1]);
        // Capped at twice the threshold, so a flag clears in a few
        // conforming fixes however far off the aircraft was.
        // One fix moves the sum by at most 60% of the threshold: a single
        // wild fix (an MLAT failure) cannot flag anybody, two in a row can.
        let step = (nis - cfg.reference).min(0.6 * cfg.threshold);
        self.sum = (self.sum + step).clamp(0.0, 2.0 * cfg.threshold);
        let fits = nis < cfg.reference;
        self.conforming = if fits { self.conforming + 1 } else { 0 };
        if !fits {
            self.flagged_offset = Some(match self.flagged_offset {
                Some(o) if self.suspect => [0, 1].map(|k| o[k] + OFFSET_WEIGHT * (d[k] - o[k])),
                _ => d,
            });
        }
        if !self.suspect && self.sum > cfg.threshold {
            self.suspect = true;
            return Some(true);
        }
        if self.suspect && self.sum == 0.0 && self.conforming >= cfg.clear_after {
            self.suspect = false;
            self.flagged_offset = None;
            return Some(false);
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn honest_never_flags_offsets_flag_at_once_and_clear() {
        let cfg = ConformanceConfig::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        // ADS-B 38 m and MLAT 20 m per axis: 43 m combined.
        let (sa, sm) = (37.8f64, 20.0f64);
        let var = sa * sa + sm * sm;
        let n = Normal::new(0.0, var.sqrt()).unwrap();
        let s = [[var, 0.0], [0.0, var]];
        let mut honest = Monitor::default();
        for _ in 0..1_000_000 {
            assert_eq!(honest.push(&cfg, [n.sample(&mut rng), n.sample(&mut rng)], s), None);
        }
        // One wild fix among honest ones: no flag.
        assert_eq!(honest.push(&cfg, [60_000.0, 0.0], s), None);
        for _ in 0..20 {
            assert_eq!(honest.push(&cfg, [n.sample(&mut rng), n.sample(&mut rng)], s), None);
        }
        for offset in [300.0, 2000.0] {
            let mut m = Monitor::default();
            let mut fixes = 0;
            while !m.suspect && fixes < 10 {
                fixes += 1;
                m.push(&cfg, [offset + n.sample(&mut rng), n.sample(&mut rng)], s);
            }
            assert_eq!(fixes, 2, "{offset} m");
            // Honest again: cleared after the configured run.
            let mut k = 0;
            while m.suspect {
                k += 1;
                m.push(&cfg, [n.sample(&mut rng), n.sample(&mut rng)], s);
                assert!(k < 30);
            }
            assert!(k >= cfg.clear_after as usize);
        }
    }

    /// A spoofer flagged for 300 m is not cleared by fixes too wide to see
    /// 300 m (200 m per axis: it passes at NIS 2.3); fixes that could see it
    /// and find the aircraft where it says it is clear it.
    #[test]
    fn only_fixes_that_could_tell_clear_a_flag() {
        let cfg = ConformanceConfig::default();
        let tight = [[43.0f64.powi(2), 0.0], [0.0, 43.0f64.powi(2)]];
        let wide = [[200.0f64.powi(2), 0.0], [0.0, 200.0f64.powi(2)]];
        let mut m = Monitor::default();
        m.push(&cfg, [300.0, 10.0], tight);
        assert_eq!(m.push(&cfg, [290.0, -5.0], tight), Some(true));
        for _ in 0..200 {
            assert_eq!(m.push(&cfg, [300.0, 0.0], wide), None);
        }
        assert!(m.suspect);
        // Tight fixes still seeing the offset keep it; honest ones clear it.
        for _ in 0..10 {
            assert_eq!(m.push(&cfg, [310.0, 0.0], tight), None);
        }
        let mut k = 0;
        while m.suspect {
            k += 1;
            m.push(&cfg, [5.0, -8.0], tight);
            assert!(k < 30);
        }
    }
}
