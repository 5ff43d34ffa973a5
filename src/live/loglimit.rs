//! Log lines limited per cause and per receiver: a storm (a receiver that
//! reconnects every half second, a flood of strangers) must not fill the
//! disk with the same line, yet the first lines of a kind, and a count of
//! what was held back, must still reach the operator. The counts themselves
//! are in the metrics, unlimited.

use std::sync::Mutex;

/// Lines one cause of one receiver may write at once ...
pub const BURST: f64 = 6.0;
/// ... and then one per this many seconds.
pub const EVERY_S: f64 = 10.0;

/// A token bucket of log lines (see [`BURST`], [`EVERY_S`]).
#[derive(Debug)]
pub struct LogGate {
    /// Lines that may be written now, when last refilled, lines held back.
    inner: Mutex<(f64, f64, u64)>,
}

impl Default for LogGate {
    fn default() -> Self {
        LogGate { inner: Mutex::new((BURST, f64::NAN, 0)) }
    }
}

impl LogGate {
    /// Whether a line may be written at `now`: `Some(n)` with the number
    /// of lines held back since the last one, or `None` (this one held back).
    pub fn pass(&self, now: f64) -> Option<u64> {
        let mut g = self.inner.lock().expect("log gate");
        let (tokens, at, held) = *g;
        let tokens = if at.is_nan() { tokens } else { (tokens + (now - at).max(0.0) / EVERY_S).min(BURST) };
        if tokens >= 1.0 {
            *g = (tokens - 1.0, now, 0);
            Some(held)
        } else {
            *g = (tokens, now, held + 1);
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_burst_then_one_line_per_interval_with_the_count_of_the_rest() {
        let g = LogGate::default();
        // Two lines a second for a minute.
        let passed: Vec<(usize, u64)> =
            (0..120).filter_map(|k| g.pass(k as f64 * 0.5).map(|held| (k, held))).collect();
        assert_eq!(&passed[..6], &[(0, 0), (1, 0), (2, 0), (3, 0), (4, 0), (5, 0)]);
        assert_eq!(passed.len(), 6 + 5, "{passed:?}");
        assert!(passed[6..].iter().all(|&(_, held)| held >= 13), "{passed:?}");
        // Quiet for a minute: a burst is allowed again.
        assert!((0..6).all(|k| g.pass(200.0 + k as f64).is_some()));
    }
}
