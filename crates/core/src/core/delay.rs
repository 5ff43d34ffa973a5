//! How late a receiver's frames reach the server: learnt for receivers whose
//! reports can only be dated by their arrival (a counter clock not
//! synchronised with any GPS-timed receiver, or a feed without timestamps).
//!
//! Dated by arrival, an ADS-B position is a network delay late, tens of
//! milliseconds: every report of such a receiver then sits metres behind the
//! aircraft along its track, the same way each time, which a track cannot
//! average out and takes for its own error (on tma-busy the receiver that
//! delivered most reports first was one MLAT had excluded, and its reports
//! were 33 ms late). Where a GPS-timed receiver heard the same transmission,
//! the difference between the two is that delay, within the propagation
//! difference between the two sites (a millisecond per 300 km). The mean
//! and spread are learnt over the latest few hundred such transmissions, so
//! a report is dated by its arrival less the mean, with the spread as its
//! uncertainty. Delay bursts (a congested link) are left out of the learning
//! and counted; a lasting change of the delay is relearnt from scratch.

/// Transmissions learnt from before the estimate is used.
const WARMUP: u64 = 20;
/// Memory of the estimate, in transmissions.
const MEMORY: f64 = 500.0;
/// A delay this many spreads from the mean (after the warm-up) is a burst.
const BURST_SIGMAS: f64 = 6.0;
/// Floor of the spread used for the burst test (s): a steady link must
/// not make every small wobble a burst.
const MIN_SPREAD_S: f64 = 0.002;
/// Bursts in a row taken for a lasting change of the delay.
const RELEARN_AFTER: u32 = 50;
/// A frame cannot arrive before it was sent: earlier than this (the
/// propagation difference between two sites is a few milliseconds at the
/// most) the sample says a clock is wrong (the server's, or the GPS-timed
/// receiver's), not the link.
const EARLIEST_S: f64 = -0.005;

/// A receiver's network delay: mean and spread of its frames' arrival after
/// their time of applicability.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DelayCal {
    n: u64,
    mean: f64,
    var: f64,
    bursts_in_a_row: u32,
    /// Samples left out as bursts.
    pub bursts: u64,
    /// Samples left out as impossible: arriving before they were sent.
    pub impossible: u64,
}

impl DelayCal {
    /// One transmission: it arrived `delay_s` after its time of applicability.
    pub fn push(&mut self, delay_s: f64) {
        if !delay_s.is_finite() {
            return;
        }
        if delay_s < EARLIEST_S {
            self.impossible += 1;
            return;
        }
        if self.n >= WARMUP {
            let spread = self.var.sqrt().max(MIN_SPREAD_S);
            if (delay_s - self.mean).abs() > BURST_SIGMAS * spread {
                self.bursts += 1;
                self.bursts_in_a_row += 1;
                if self.bursts_in_a_row >= RELEARN_AFTER {
                    *self =
                        DelayCal { bursts: self.bursts, impossible: self.impossible, ..DelayCal::default() };
                }
                return;
            }
        }
        self.bursts_in_a_row = 0;
        self.n += 1;
        // Weights 1/n at first (the plain mean and variance), then a memory
        // of the latest transmissions.
        let w = 1.0 / (self.n as f64).min(MEMORY);
        let d = delay_s - self.mean;
        self.mean += w * d;
        self.var = (1.0 - w) * (self.var + w * d * d);
    }

    /// (mean, spread) of the delay (s), once learnt. Never negative: the
    /// samples a little below zero are the two sites' propagation
    /// difference, and dating a report after its arrival would put it in
    /// the future.
    pub fn estimate(&self) -> Option<(f64, f64)> {
        (self.n >= WARMUP).then(|| (self.mean.max(0.0), self.var.sqrt()))
    }

    /// Transmissions learnt from since the last (re)start.
    pub fn samples(&self) -> u64 {
        self.n
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn learns_the_mean_and_spread_ignores_bursts_and_relearns_a_change() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let delay = Normal::new(0.033, 0.010).unwrap();
        let mut cal = DelayCal::default();
        for k in 0..WARMUP - 1 {
            cal.push(delay.sample(&mut rng));
            assert!(cal.estimate().is_none(), "{k}");
        }
        // Two seconds of 800 ms bursts every 50 transmissions.
        for k in 0..2000 {
            let burst = k % 50 < 2 && k > 100;
            cal.push(delay.sample(&mut rng) + if burst { 0.8 } else { 0.0 });
        }
        let (mean, spread) = cal.estimate().unwrap();
        assert!((mean - 0.033).abs() < 0.002, "{mean}");
        assert!((spread - 0.010).abs() < 0.0015, "{spread}");
        assert!((75..=80).contains(&cal.bursts), "{}", cal.bursts);
        // The link moves to 120 ms for good: relearnt, not refused forever.
        let later = Normal::new(0.120, 0.010).unwrap();
        for _ in 0..RELEARN_AFTER as usize + 200 {
            cal.push(later.sample(&mut rng));
        }
        let (mean, _) = cal.estimate().unwrap();
        assert!((mean - 0.120).abs() < 0.003, "{mean}");
        cal.push(f64::NAN);
        assert!(cal.estimate().unwrap().0.is_finite());
    }

    /// A server clock a second fast (or a GPS receiver a second slow) makes
    /// every frame seem to arrive before it was sent: nothing is learnt from
    /// that, and a link a hair faster than the propagation difference is
    /// taken as no delay, never a negative one.
    #[test]
    fn arrivals_before_the_transmission_are_not_a_delay() {
        let mut cal = DelayCal::default();
        for _ in 0..100 {
            cal.push(-1.0);
        }
        assert_eq!((cal.estimate(), cal.impossible), (None, 100));
        for k in 0..100 {
            cal.push(-0.001 + 1e-5 * (k % 3) as f64);
        }
        assert_eq!(cal.estimate().map(|e| e.0), Some(0.0));
    }
}
