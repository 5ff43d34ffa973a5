//! A count of recent events that fades exponentially over a span: how many
//! of an aircraft's reports or transmissions lately share an error that
//! persists about that long, kept in two numbers rather than a list of
//! times, so a per-aircraft table stays small.

/// The faded count and the time of the newest event.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RecentCount {
    count: f64,
    t: f64,
}

impl RecentCount {
    /// The count at `t`, faded over `span_s`.
    pub fn at(&self, t: f64, span_s: f64) -> f64 {
        self.count * (-(t - self.t).abs() / span_s).exp()
    }

    /// One more event at `t`; the count with it.
    pub fn add(&mut self, t: f64, span_s: f64) -> f64 {
        self.count = self.at(t, span_s) + 1.0;
        self.t = t;
        self.count
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_fade_over_the_span() {
        let mut r = RecentCount::default();
        assert_eq!(r.at(100.0, 60.0), 0.0);
        assert_eq!(r.add(100.0, 60.0), 1.0);
        assert_eq!(r.add(100.0, 60.0), 2.0);
        // A span later, the two count as 2/e; with one more, 1 + 2/e.
        assert!((r.at(160.0, 60.0) - 2.0 / std::f64::consts::E).abs() < 1e-12);
        assert!((r.add(160.0, 60.0) - (1.0 + 2.0 / std::f64::consts::E)).abs() < 1e-12);
    }
}
