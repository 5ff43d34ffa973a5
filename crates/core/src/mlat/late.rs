//! Late copies: a receiver's copy of a transmission whose group was already
//! handed out (its link delayed it past the group wait, in a burst say).
//!
//! Taken as a new transmission, such a copy was decoded again: its position
//! report went out twice, its measurement went into the aircraft's tracks
//! twice (a track then believes it knows more than it does), and a handful
//! of late copies together could make a fix of their own from too few sites.
//! Identical bytes alone cannot tell a late copy from a repeat (replies,
//! identification and steady velocity messages repeat their bytes), but the
//! time it was sent can: each copy's emission on the server's clock
//! ([`crate::core::lateness`], its receiver's timestamp put on the server's
//! clock by the link's least delay) differs from another copy's of the same
//! transmission by the two links' least delays, tens of milliseconds, while
//! an extended squitter repeats its bytes 0.4 s later at the soonest. So each
//! handed-out group leaves its bytes and emission time here, and a copy that
//! arrived the group wait after its emission and misses the pending groups
//! is checked against them.
//!
//! The table is a fixed set of two-way buckets, the older entry of a bucket
//! giving way: a remembered group costs one write and no allocation, and one
//! forgotten early (a busy bucket) only means its late copy is taken as new.

use super::pending::hash;

/// Copies of one transmission have emission times this close (s): their
/// links' least delays apart (a LAN's millisecond against a distant
/// feeder's 100 ms), plus 4 ms of propagation between sites 1,200 km apart
/// and a counter's drift over the least delay's window; half the 0.4 s
/// after which an airborne position or velocity message is sent again at
/// the soonest (identification every 5 s, acquisition squitters every
/// 0.8 s or more).
pub const SAME_TRANSMISSION_S: f64 = 0.2;

/// Buckets (a power of two): at 20,000 transmissions a second (the scale
/// world) a bucket is written about every six seconds, far longer than a
/// link's delay bursts last.
const BUCKETS: usize = 1 << 17;

#[derive(Clone, Copy)]
struct Entry {
    key: u128,
    /// Emission on the server's clock (Unix s); minus infinity: empty, the
    /// oldest of all, matching no time.
    t: f64,
}

const EMPTY: Entry = Entry { key: 0, t: f64::NEG_INFINITY };

pub(super) struct HandedOut {
    /// Two entries a bucket, side by side.
    slots: Vec<Entry>,
}

impl HandedOut {
    pub(super) fn new() -> Self {
        HandedOut { slots: vec![EMPTY; 2 * BUCKETS] }
    }

    fn bucket(key: u128) -> usize {
        2 * ((hash(key) >> 32) as usize & (BUCKETS - 1))
    }

    /// A handed-out transmission with these bytes, sent at `t` (Unix s on the
    /// server's clock).
    pub(super) fn remember(&mut self, key: u128, t: f64) {
        let b = Self::bucket(key);
        let pair = &mut self.slots[b..b + 2];
        // The older (or empty) way gives way.
        let way = usize::from(pair[1].t < pair[0].t);
        pair[way] = Entry { key, t };
    }

    /// Whether a copy with these bytes sent at `t` belongs to a
    /// transmission already handed out.
    pub(super) fn holds(&self, key: u128, t: f64) -> bool {
        let b = Self::bucket(key);
        self.slots[b..b + 2].iter().any(|e| e.key == key && (e.t - t).abs() <= SAME_TRANSMISSION_S)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_copy_matches_its_transmission_and_not_a_repeat_of_the_same_bytes() {
        let mut h = HandedOut::new();
        h.remember(7, 100.0);
        assert!(h.holds(7, 100.08), "another receiver over a slower link");
        assert!(!h.holds(7, 100.4), "a repeat of the same bytes");
        assert!(!h.holds(8, 100.0), "other bytes");
        // The repeat handed out in its turn: both are remembered.
        h.remember(7, 100.4);
        assert!(h.holds(7, 100.0) && h.holds(7, 100.401));
    }

    #[test]
    fn a_full_bucket_forgets_its_oldest() {
        let mut h = HandedOut::new();
        // One key at three times: one bucket, whatever the hash.
        h.remember(7, 1.0);
        h.remember(7, 2.0);
        h.remember(7, 3.0);
        assert!(!h.holds(7, 1.0));
        assert!(h.holds(7, 2.0) && h.holds(7, 3.0));
    }
}
