//! How much later than its link's usual a receiver's frame arrived: the
//! receiver's own timestamps put on the server's clock.
//!
//! The grouping needs it to know a late copy (a link's delay burst) when it
//! sees one, for every kind of receiver: a GPS time alone is not on the
//! server's clock, and a free-running counter is on no common clock at all
//! unless the clock synchronisation has a GPS-timed partner for it, which a
//! network of counter-timed receivers does not. What every receiver has is
//! the difference between a frame's arrival and its own timestamp: the
//! counter's offset from the server's clock plus that frame's network
//! delay. Its lower envelope is the offset plus the link's least delay, so
//! a frame's timestamp plus that envelope is when it would have arrived over
//! an unhurried link: its emission on the server's clock, up to the link's
//! least delay, the same for every frame of that receiver.
//!
//! The envelope is the minimum over a window of 30 to 60 s (the minimum of
//! the current and the previous half window): long enough that a burst of
//! many seconds does not lift it, short enough that a counter's drift (80
//! ppm is 5 ms a minute) hardly moves it. A counter restarted from zero
//! makes the offset jump up by what it read before, and a GPS receiver's
//! seconds of the day make it jump by a day at midnight: a frame more than
//! 10 s later than the envelope starts it again (a link that stalls that
//! long costs only the stall: the next frame on time brings the envelope
//! down).

/// Half of the window over which the least offset is taken (s).
const HALF_WINDOW_S: f64 = 30.0;
/// A frame this much later than the envelope (s): the counter restarted.
const RESTART_S: f64 = 10.0;

/// One receiver's least offset between its timestamps and the server's clock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lateness {
    /// Least offset of the current half window (s).
    current: f64,
    /// Least offset of the current and the previous half window (s): the
    /// envelope.
    least: f64,
    /// When the current half window ends (the server's Unix s).
    ends: f64,
}

impl Default for Lateness {
    fn default() -> Self {
        Lateness { current: f64::INFINITY, least: f64::INFINITY, ends: f64::NEG_INFINITY }
    }
}

impl Lateness {
    /// A frame stamped `rx_time` (s, on the receiver's own scale) arrived at
    /// `arrival` (the server's Unix s): its emission on the server's clock,
    /// never after its arrival.
    ///
    /// Every frame of every receiver passes here, so the usual case is a few
    /// plain comparisons: with `f64::min`, whose care for NaN no offset
    /// needs, the front stage ran 7.4 M more instructions on the scale
    /// world's first 400 k lines (1% of them).
    pub fn emission(&mut self, rx_time: f64, arrival: f64) -> f64 {
        let offset = arrival - rx_time;
        if offset > self.least + RESTART_S || arrival >= self.ends {
            self.turn(offset, arrival);
        }
        if offset < self.current {
            self.current = offset;
            if offset < self.least {
                self.least = offset;
            }
        }
        rx_time + self.least
    }

    /// A restart (the envelope starts again) or a new half window.
    #[cold]
    fn turn(&mut self, offset: f64, arrival: f64) {
        let previous = if offset > self.least + RESTART_S || arrival - self.ends >= HALF_WINDOW_S {
            // Restarted, or silent for a whole window: both halves forgotten.
            f64::INFINITY
        } else {
            self.current
        };
        *self = Lateness { current: f64::INFINITY, least: previous, ends: arrival + HALF_WINDOW_S };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A counter 5 s behind the server's clock, drifting 80 ppm, over a link
    /// of 30-50 ms with a 0.8 s burst at 20-22 s and a restart at 100 s
    /// (reading 105 s before it).
    #[test]
    fn lateness_is_the_delay_beyond_the_links_least_and_follows_a_restart() {
        let mut l = Lateness::default();
        let delay = |k: u32, t: f64| {
            if (20.0..22.0).contains(&t) {
                0.8
            } else {
                0.03 + 0.02 * ((k * 7919) % 100) as f64 / 100.0
            }
        };
        let mut worst_normal: f64 = 0.0;
        let mut burst = Vec::new();
        let mut after_restart = Vec::new();
        for k in 0..2000u32 {
            let t = 1e6 + k as f64 * 0.1;
            let counter = if t < 1e6 + 100.0 { (t - 1e6 + 5.0) * (1.0 + 80e-6) } else { t - 1e6 - 100.0 };
            let arrival = t + delay(k, t - 1e6);
            let late = arrival - l.emission(counter, arrival);
            assert!(late >= 0.0);
            let s = t - 1e6;
            match s {
                _ if (20.0..22.0).contains(&s) => burst.push(late),
                _ if (5.0..100.0).contains(&s) => worst_normal = worst_normal.max(late),
                _ if s >= 100.0 => after_restart.push(late),
                _ => {}
            }
        }
        // The link's own spread (20 ms) and the drift, nothing more.
        assert!(worst_normal < 0.025, "{worst_normal}");
        assert!(burst.iter().all(|&x| (0.75..0.8).contains(&x)), "{burst:?}");
        // From the first frame after it: that frame alone reads as on time.
        assert!(after_restart.iter().all(|&x| x < 0.025), "{:?}", &after_restart[..5]);
    }
}
