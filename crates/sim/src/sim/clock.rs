//! Receiver clocks: what timestamp a receiver writes for a true time of arrival.
//!
//! beast12: a free-running 12 MHz counter with an unknown offset, a frequency
//! error (ppm) that wanders as a random walk, timing jitter, restarts that
//! reset the counter, and quantisation to whole ticks. gps: GPS time of day
//! with jitter, to the nanosecond. The frequency walk is drawn on a 1 s grid
//! up front so a timestamp depends only on the time asked, not on call order.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::scenario::Receiver;
use fuse1090_core::feed::capture::ClockKind;

pub struct ClockModel {
    kind: ClockKind,
    /// The start's second of the day: adding scenario time to this small
    /// number keeps nanoseconds, which Unix time near 1.7e9 s in an f64 (a
    /// 240 ns step) would not.
    start_sod: f64,
    offset_ticks: f64,
    /// Phase error (s) accumulated by whole seconds since the start, and the
    /// frequency error (fractional) within each second.
    phase_s: Vec<f64>,
    freq: Vec<f64>,
    resets: Vec<f64>,
    reset_offsets: Vec<f64>,
    jitter_s: f64,
}

impl ClockModel {
    pub fn new(r: &Receiver, start_unix: f64, duration_s: f64, rng: &mut ChaCha8Rng) -> Self {
        let n = duration_s.ceil() as usize + 2;
        let walk = Normal::new(0.0, r.drift_walk_ppm.max(0.0) * 1e-6).expect("finite sigma");
        let mut freq = Vec::with_capacity(n);
        let mut phase_s = Vec::with_capacity(n);
        let (mut f, mut p) = (r.drift_ppm * 1e-6, 0.0);
        for _ in 0..n {
            freq.push(f);
            phase_s.push(p);
            p += f;
            f += walk.sample(rng);
        }
        let offset_ticks = match r.clock_offset_s {
            Some(s) => s * 12e6,
            None => rng.gen_range(0.0..1e4) * 12e6,
        };
        let mut resets = r.resets_s.clone();
        resets.sort_by(f64::total_cmp);
        let reset_offsets = resets.iter().map(|_| rng.gen_range(0.0..12e6)).collect();
        ClockModel {
            kind: r.clock,
            start_sod: start_unix.rem_euclid(86_400.0),
            offset_ticks,
            phase_s,
            freq,
            resets,
            reset_offsets,
            jitter_s: r.jitter_ns * 1e-9,
        }
    }

    /// Accumulated phase error at scenario time `t` (s).
    fn phase(&self, t: f64) -> f64 {
        let k = (t.max(0.0).floor() as usize).min(self.freq.len() - 1);
        self.phase_s[k] + self.freq[k] * (t - k as f64)
    }

    /// The 48-bit timestamp for a true arrival at scenario time `t`.
    pub fn timestamp(&self, t: f64, rng: &mut ChaCha8Rng) -> u64 {
        let jitter = if self.jitter_s > 0.0 {
            rng.sample::<f64, _>(rand_distr::StandardNormal) * self.jitter_s
        } else {
            0.0
        };
        match self.kind {
            ClockKind::Gps => ClockKind::gps_timestamp(self.start_sod + t + jitter),
            ClockKind::Beast12 => {
                // Since the last restart (or the start), the counter runs from its offset.
                let (since, offset) = match self.resets.iter().rposition(|&r| r <= t) {
                    Some(i) => (self.resets[i], self.reset_offsets[i]),
                    None => (0.0, self.offset_ticks),
                };
                let elapsed = (t - since) + self.phase(t) - self.phase(since) + jitter;
                let ticks = (offset + elapsed * 12e6).floor().max(0.0) as u64;
                ticks & 0xFFFF_FFFF_FFFF
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn receiver(clock: ClockKind) -> Receiver {
        let text = format!(
            "id = \"r\"\nlat = 0.0\nlon = 0.0\nalt_m = 0.0\nclock = \"{}\"\ndrift_ppm = 20.0\nclock_offset_s = 100.0\nresets_s = [50.0]",
            clock.name()
        );
        toml::from_str(&text).unwrap()
    }

    #[test]
    fn beast12_counts_at_12mhz_with_drift_and_resets() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let c = ClockModel::new(&receiver(ClockKind::Beast12), 1e9, 100.0, &mut rng);
        let t0 = c.timestamp(10.0, &mut rng);
        let t1 = c.timestamp(20.0, &mut rng);
        // 10 s at 12 MHz plus 20 ppm, to a tick.
        let d = t1 as f64 - t0 as f64;
        assert!((d - 10.0 * 12e6 * (1.0 + 20e-6)).abs() <= 1.0, "{d}");
        assert!((t0 as f64 - (100.0 + 10.0 * (1.0 + 20e-6)) * 12e6).abs() <= 1.0);
        // After the restart at 50 s the counter starts again near zero.
        assert!(c.timestamp(51.0, &mut rng) < 2 * 12_000_000 + 12_000_000);
    }

    #[test]
    fn gps_is_time_of_day_to_the_nanosecond() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let c = ClockModel::new(&receiver(ClockKind::Gps), 1_590_969_600.0, 100.0, &mut rng);
        let ts = c.timestamp(12.5, &mut rng);
        assert!((ClockKind::gps_unix(ts, 1_590_969_612.0) - 1_590_969_612.5).abs() < 1e-6);
        // Nanoseconds survive: 1 ns apart in, 1 ns apart out.
        let a = c.timestamp(12.000_000_100, &mut rng) & 0x3FFF_FFFF;
        let b = c.timestamp(12.000_000_101, &mut rng) & 0x3FFF_FFFF;
        assert_eq!((a, b - a), (100, 1));
    }
}
