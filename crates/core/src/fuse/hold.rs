//! The MLAT hold's queue: an MLAT-fed aircraft's measurements wait here
//! `mlat_hold_s`, in time order, so that a fix arriving half a second after
//! the ADS-B of its moment is applied in its place (see the fusion stage's
//! page, [`super`]).

use std::collections::VecDeque;

use crate::track::Measurement;

/// Most measurements of one aircraft waiting for the MLAT hold (about seven
/// a second arrive): a flood is applied early rather than grown without bound.
pub(super) const MAX_WAITING: usize = 32;

/// One aircraft's measurements waiting for the MLAT hold, in time order.
/// Their times and release times are kept apart from the measurements
/// (152 bytes each) because the search for a late fix's place and the scan
/// for what is due read only those, and with thousands of aircraft the
/// lists are cold: searching the measurements themselves, a cache miss a
/// step, was 8% of the live tracker thread's time at 973 k frames/s.
/// Double-ended: what is due leaves from the front without moving the
/// rest up.
#[derive(Default)]
pub(super) struct Waiting {
    /// (time of applicability, release time) of each measurement.
    keys: VecDeque<(f64, f64)>,
    ms: VecDeque<Measurement>,
}

impl Waiting {
    pub(super) fn len(&self) -> usize {
        self.keys.len()
    }

    pub(super) fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    pub(super) fn insert(&mut self, release: f64, m: Measurement) {
        // Most come in time order; a late MLAT fix is searched for.
        let i = match self.keys.back() {
            Some(&(t, _)) if t > m.t => self.keys.partition_point(|&(t, _)| t <= m.t),
            _ => self.keys.len(),
        };
        self.keys.insert(i, (m.t, release));
        self.ms.insert(i, m);
    }

    /// How many, from the oldest, go in at `now`: up to the newest whose
    /// wait is over (older ones that came late go in with it).
    pub(super) fn due(&self, now: f64) -> usize {
        let newest = self.keys.iter().filter(|&&(_, r)| r <= now).map(|&(t, _)| t).reduce(f64::max);
        newest.map_or(0, |upto| self.keys.partition_point(|&(t, _)| t <= upto))
    }

    /// The oldest `n`, taken out in time order.
    pub(super) fn take(&mut self, n: usize) -> std::collections::vec_deque::Drain<'_, Measurement> {
        self.keys.drain(..n);
        self.ms.drain(..n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuse::tests::pos;

    #[test]
    fn the_hold_keeps_measurements_in_time_order_and_releases_up_to_the_newest_due() {
        let mut w = Waiting::default();
        // (time, release): a late fix (t 10.2) arrives after newer ADS-B.
        for (t, r) in [(10.0, 10.6), (10.4, 11.0), (10.6, 11.2), (10.2, 11.3), (10.8, 11.4)] {
            w.insert(r, pos(t, 45.0, 5.0));
        }
        let times = |w: &Waiting| w.ms.iter().map(|m| m.t).collect::<Vec<_>>();
        assert_eq!(times(&w), [10.0, 10.2, 10.4, 10.6, 10.8]);
        assert_eq!(w.due(10.5), 0);
        // At 11.2 the newest due is 10.6: the late 10.2 goes with it.
        assert_eq!(w.due(11.2), 4);
        let out: Vec<f64> = w.take(4).map(|m| m.t).collect();
        assert_eq!(out, [10.0, 10.2, 10.4, 10.6]);
        assert_eq!((w.len(), times(&w)), (1, vec![10.8]));
        assert_eq!(w.keys.len(), w.ms.len());
    }
}
