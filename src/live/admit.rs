//! Admission of a receiver's frames to the core's queue: its configured
//! rate limit, then its fair share of the queue.
//!
//! Both apply to every input kind alike (TCP client, TCP server, UDP), per
//! receiver, whatever connection or socket its frames come through, because
//! they are decided where every input hands frames to the core.
//!
//! - **Rate limit** (`max_rate`, off by default): a token bucket with one
//!   second of burst. Only admitted frames take tokens, so the bucket never
//!   goes below empty: a flood costs the flooder its excess and nothing
//!   after it (a bucket charged for dropped frames too went without bound
//!   negative and locked an honest receiver out for days after a spoofed
//!   burst).
//! - **Fair share** (always on): while the queue is less than half full,
//!   anyone may add to it; past half, a receiver may hold at most
//!   `queue_frames / receivers` of it. A flooding receiver, known or
//!   spoofed, then fills at most half the queue plus its share, and the
//!   others keep the other half: honest receivers lose nothing unless their
//!   own load alone exceeds what the core can take.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;

/// Token bucket: frames per second, one second (at least one frame) of burst.
#[derive(Debug)]
pub struct Bucket {
    tokens: f64,
    /// Time of the last refill (Unix s); NaN before the first frame.
    at: f64,
}

impl Default for Bucket {
    fn default() -> Self {
        Bucket { tokens: 0.0, at: f64::NAN }
    }
}

impl Bucket {
    /// Admits up to `n` frames arriving at `now` under `rate`; returns how
    /// many. Arrival times of different sockets may be out of order by a
    /// little: time never runs backwards for the bucket.
    pub fn take(&mut self, n: usize, now: f64, rate: f64) -> usize {
        let burst = rate.max(1.0);
        if self.at.is_nan() {
            (self.tokens, self.at) = (burst, now);
        }
        self.tokens = (self.tokens + (now - self.at).max(0.0) * rate).min(burst);
        self.at = self.at.max(now);
        let admitted = (self.tokens as usize).min(n);
        self.tokens -= admitted as f64;
        admitted
    }
}

/// One receiver's admission state, shared by all its connections.
#[derive(Debug, Default)]
pub struct Admission {
    bucket: Mutex<Bucket>,
    /// `max_rate` as f64 bits (0: no limit); changed by SIGHUP.
    rate_bits: AtomicU64,
    /// Its frames in the core's queue now.
    pub queued: AtomicUsize,
}

/// Why frames were not admitted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// Over its configured `max_rate`.
    Rate,
    /// Over its share of a queue more than half full.
    Share,
    /// The queue is full.
    Full,
}

impl Admission {
    pub fn set_rate(&self, max_rate: f64) {
        self.rate_bits.store(max_rate.to_bits(), Ordering::Relaxed);
    }

    fn rate(&self) -> f64 {
        f64::from_bits(self.rate_bits.load(Ordering::Relaxed))
    }

    /// How many of `n` frames arriving at `now` pass the rate limit.
    pub fn within_rate(&self, n: usize, now: f64) -> usize {
        let rate = self.rate();
        if rate > 0.0 {
            self.bucket.lock().expect("bucket").take(n, now, rate)
        } else {
            n
        }
    }

    /// Whether `n` more frames of this receiver fit a queue holding `total`
    /// of at most `capacity`, shared by `receivers` receivers.
    pub fn fits(&self, n: usize, total: usize, capacity: usize, receivers: usize) -> Result<(), Refusal> {
        if total + n > capacity {
            return Err(Refusal::Full);
        }
        let share = capacity / receivers.max(1);
        if total + n > capacity / 2 && self.queued.load(Ordering::Relaxed) + n > share {
            return Err(Refusal::Share);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_costs_the_flooder_its_excess_and_nothing_after_it() {
        let mut b = Bucket::default();
        let rate = 1000.0;
        // 20 s of 100,000 frames/s, in batches of 100 every millisecond.
        let mut admitted = 0;
        for k in 0..20_000 {
            admitted += b.take(100, k as f64 * 1e-3, rate);
        }
        // The burst plus the rate, no more.
        assert!((20_000..=21_001).contains(&admitted), "{admitted}");
        // Then an honest pace: every frame passes at once, no debt to repay.
        let mut later = 0;
        for k in 0..1000 {
            later += b.take(1, 20.0 + k as f64 * 1e-3, rate);
        }
        assert_eq!(later, 1000);
    }

    #[test]
    fn time_running_backwards_grants_nothing() {
        let mut b = Bucket::default();
        assert_eq!(b.take(10, 100.0, 5.0), 5);
        assert_eq!(b.take(10, 90.0, 5.0), 0);
        assert_eq!(b.take(10, 100.4, 5.0), 2);
        // A rate under one frame a second still lets one through now and then.
        let mut slow = Bucket::default();
        assert_eq!((0..10).map(|k| slow.take(1, k as f64, 0.5)).sum::<usize>(), 5);
    }

    #[test]
    fn past_half_a_queue_each_receiver_holds_at_most_its_share() {
        let (flood, honest) = (Admission::default(), Admission::default());
        // 4 receivers, room for 1,000: a share is 250.
        flood.queued.store(600, Ordering::Relaxed);
        assert_eq!(flood.fits(10, 600, 1000, 4), Err(Refusal::Share));
        assert_eq!(honest.fits(10, 600, 1000, 4), Ok(()));
        assert_eq!(honest.fits(10, 995, 1000, 4), Err(Refusal::Full));
        // Under half full, anyone may add.
        flood.queued.store(400, Ordering::Relaxed);
        assert_eq!(flood.fits(10, 400, 1000, 4), Ok(()));
    }

    #[test]
    fn the_rate_limit_is_off_at_zero_and_follows_a_reload() {
        let a = Admission::default();
        assert_eq!(a.within_rate(1_000_000, 1.0), 1_000_000);
        a.set_rate(10.0);
        assert_eq!(a.within_rate(100, 2.0), 10);
        a.set_rate(0.0);
        assert_eq!(a.within_rate(100, 2.0), 100);
    }
}
