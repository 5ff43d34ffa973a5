//! The grouper's index of pending transmissions: a frame's bytes to the
//! sequence number of the newest pending group with those bytes.
//!
//! Hand-written because it is the front stage's hottest lookup (every frame
//! at up to two million a second) and a general map was a cache miss per
//! frame and another per handed-out group. Three choices make it small and
//! cheap:
//! - a slot is 8 bytes, a 32-bit tag of the key's hash and the sequence
//!   number, not the 16-byte key: the index is a quarter of a general map's
//!   size and stays in cache. A tag match is confirmed against the group
//!   itself, which a hit touches anyway to join it.
//! - a handed-out group's entry is not removed (that was a lookup per group);
//!   it goes stale, is skipped by lookups and reused by inserts.
//! - the table is rebuilt from the pending groups before it fills; rebuilds
//!   are counted in insertions, so an entry never outlives the 2^32 groups
//!   after which its sequence number would come round again.

/// An empty slot. Tags are never zero.
const EMPTY: u64 = 0;
const MIN_SLOTS: usize = 1024;

pub(super) struct PendingIndex {
    slots: Vec<u64>,
    /// Insertions since the last rebuild, plus the entries it put in.
    filled: usize,
}

/// What the index asks of the pending groups, by sequence number (mod 2^32).
pub(super) trait Groups {
    /// Whether the group is still pending.
    fn live(&self, seq: u32) -> bool;
    /// Whether the (pending) group's bytes are `key`.
    fn has_key(&self, seq: u32, key: u128) -> bool;
    /// Every pending group's key and sequence number, oldest first (what a
    /// rebuild indexes).
    fn pending(&self) -> impl ExactSizeIterator<Item = (u128, u32)>;
}

/// A frame key's hash: a folded multiply of its two halves (frame bytes end
/// in 24 bits of parity, so they are well spread); its high half is the
/// better mixed.
pub(super) fn hash(key: u128) -> u64 {
    let (lo, hi) = (key as u64 ^ 0x243f_6a88_85a3_08d3, (key >> 64) as u64 ^ 0x1319_8a2e_0370_7344);
    let wide = u128::from(lo) * u128::from(hi);
    wide as u64 ^ (wide >> 64) as u64
}

impl PendingIndex {
    pub(super) fn new() -> Self {
        PendingIndex { slots: vec![EMPTY; MIN_SLOTS], filled: 0 }
    }

    /// Home slot and tag of a key.
    fn hash(&self, key: u128) -> (usize, u64) {
        let h = hash(key);
        let home = (h >> 32) as usize & (self.slots.len() - 1);
        (home, (h | 1) << 32)
    }

    /// The sequence number of the pending group with bytes `key`.
    pub(super) fn find(&self, key: u128, groups: &impl Groups) -> Option<u32> {
        let (mut i, tag) = self.hash(key);
        let mask = self.slots.len() - 1;
        loop {
            let s = self.slots[i];
            if s == EMPTY {
                return None;
            }
            let seq = s as u32;
            if s & !0xffff_ffff == tag && groups.live(seq) && groups.has_key(seq, key) {
                return Some(seq);
            }
            i = (i + 1) & mask;
        }
    }

    /// Maps `key` to `seq` (a pending group already), replacing the entry
    /// of an older pending group with the same bytes.
    pub(super) fn insert(&mut self, key: u128, seq: u32, groups: &impl Groups) {
        // Rebuilt at five eighths full: linear probing stays short.
        if (self.filled + 1) * 8 > self.slots.len() * 5 {
            let pending = groups.pending();
            let len = (pending.len() * 4).next_power_of_two().max(MIN_SLOTS);
            self.slots.clear();
            self.slots.resize(len, EMPTY);
            self.filled = 0;
            for (k, s) in pending {
                self.put(k, s, groups);
            }
        }
        self.put(key, seq, groups);
    }

    fn put(&mut self, key: u128, seq: u32, groups: &impl Groups) {
        self.filled += 1;
        let (mut i, tag) = self.hash(key);
        let mask = self.slots.len() - 1;
        let mut free = None;
        loop {
            let s = self.slots[i];
            if s == EMPTY {
                break;
            }
            let old = s as u32;
            if !groups.live(old) {
                free.get_or_insert(i);
            } else if s & !0xffff_ffff == tag && groups.has_key(old, key) {
                // The newer group owns the bytes from now on.
                free = Some(i);
                break;
            }
            i = (i + 1) & mask;
        }
        self.slots[free.unwrap_or(i)] = tag | u64::from(seq);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pending groups `base..base + keys.len()` with these keys.
    struct Queue {
        base: u32,
        keys: Vec<u128>,
    }

    impl Groups for Queue {
        fn live(&self, seq: u32) -> bool {
            (seq.wrapping_sub(self.base) as usize) < self.keys.len()
        }
        fn has_key(&self, seq: u32, key: u128) -> bool {
            self.keys[seq.wrapping_sub(self.base) as usize] == key
        }
        fn pending(&self) -> impl ExactSizeIterator<Item = (u128, u32)> {
            let base = self.base;
            self.keys.iter().enumerate().map(move |(i, &k)| (k, base.wrapping_add(i as u32)))
        }
    }

    impl Queue {
        fn push(&mut self, index: &mut PendingIndex, key: u128) -> u32 {
            let seq = self.base.wrapping_add(self.keys.len() as u32);
            self.keys.push(key);
            index.insert(key, seq, self);
            seq
        }
        fn pop(&mut self) {
            self.keys.remove(0);
            self.base = self.base.wrapping_add(1);
        }
    }

    /// Against a plain map kept the way the grouper kept one, over enough
    /// groups for many rebuilds, with repeated bytes, and across the
    /// sequence numbers' wrap at 2^32.
    #[test]
    fn agrees_with_a_map_through_rebuilds_and_the_wrap() {
        let mut index = PendingIndex::new();
        let mut q = Queue { base: u32::MAX - 5000, keys: Vec::new() };
        let mut map = std::collections::HashMap::<u128, u32>::new();
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for step in 0..200_000u32 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            // Few distinct keys, so bytes repeat while a group is pending.
            let key = (u128::from(x % 3000) << 64) | (u128::from(x % 3000) * 0x1_0000_0001);
            let want = map.get(&key).copied().filter(|&s| q.live(s));
            assert_eq!(index.find(key, &q), want, "step {step}");
            if x % 3 == 0 {
                let seq = q.push(&mut index, key);
                map.insert(key, seq);
            }
            // A window of 500 to 1500 pending groups.
            while q.keys.len() > 500 + (step as usize / 7 % 1000) {
                let gone = q.base;
                q.pop();
                map.retain(|_, s| *s != gone);
            }
        }
        assert!(q.base < 1_000_000, "the sequence numbers wrapped");
        assert!(index.slots.len() <= 8192, "rebuilds keep the table small: {}", index.slots.len());
    }
}
