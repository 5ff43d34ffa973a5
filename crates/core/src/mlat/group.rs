//! Grouping: copies of the same transmission (identical bytes) heard by
//! several receivers, collected for a fixed wait after the first copy arrives.
//!
//! The grouper also de-duplicates for the decoder: only the first copy of a
//! transmission is decoded, the later ones join its group, and a copy
//! arriving after its group was handed out is recognised as late
//! ([`super::late`]) instead of being decoded again. Pending groups are
//! bounded; what is dropped is counted.

use std::collections::VecDeque;

use smallvec::{smallvec, SmallVec};

use crate::feed::RawFrame;

use super::late::{HandedOut, SAME_TRANSMISSION_S};
use super::pending::{Groups, PendingIndex};

/// One receiver's copy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Copy {
    pub rx: usize,
    pub timestamp: u64,
    pub arrival: f64,
    pub signal: u8,
}

/// What decoding the first copy taught us about the transmission.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GroupInfo {
    pub decoded: bool,
    pub df: u8,
    pub addr: u32,
    /// The address is verified (parity) or belongs to a known aircraft.
    pub addr_known: bool,
    /// Barometric altitude carried by this transmission (ft).
    pub alt_baro_ft: Option<i32>,
    /// What to add to its barometric altitude for its height above the
    /// ellipsoid: its own latest GNSS-baro difference (ADS-B velocity
    /// messages), or else the region's.
    pub baro_correction: Option<super::baro::BaroCorrection>,
    /// ADS-B position of this very transmission (ECEF, m) and its 1-sigma
    /// horizontal error (m): a clock synchronisation source.
    pub adsb_ecef: Option<[f64; 3]>,
    pub adsb_sigma_m: f64,
    /// The aircraft's ADS-B is not trusted (conformance monitor).
    pub suspect: bool,
    /// The ADS-B position this transmission reported (lat, lon, 1-sigma per
    /// axis m), whatever its accuracy: what the conformance monitor checks.
    pub report: Option<(f64, f64, f64)>,
}

/// All copies of one transmission.
///
/// Laid out in this order: the copies' length (after their inline slots)
/// and the frame's bytes (which confirm an index hit) then share a cache
/// line, and joining a group reads one line fewer (4% of the front stage).
#[derive(Clone, Debug, PartialEq)]
#[repr(C)]
pub struct Group {
    /// Inline for the usual handful of receivers: a transmission costs no
    /// allocation, and joining it touches one place in memory.
    pub copies: SmallVec<[Copy; 8]>,
    pub frame: RawFrame,
    pub first_arrival: f64,
    /// When it was sent, on the server's clock (Unix s, from its first copy
    /// that says; NaN when none does).
    pub emission: f64,
    pub info: GroupInfo,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GroupStats {
    pub groups: u64,
    pub copies: u64,
    /// A second copy of one transmission from the same receiver.
    pub duplicate_copies: u64,
    /// Groups dropped because too many were pending.
    pub overflow: u64,
    /// Copies of a transmission whose group had been handed out before they
    /// arrived: not decoded again, and no group of their own.
    pub late_copies: u64,
}

/// What happened to a frame.
#[derive(Debug, PartialEq)]
#[must_use]
pub enum Added {
    /// First copy: a new transmission, to decode and then [`Grouper::start`]
    /// with what decoding taught.
    New(NewGroup),
    /// Joined a pending group.
    Joined,
    /// Same receiver, same bytes, still pending: dropped.
    Duplicate,
    /// A copy of a transmission already handed out: dropped.
    Late,
}

/// A transmission's first copy, waiting for its decoded information to
/// become a group: the group is made whole, so nothing updates it after.
#[derive(Debug, PartialEq)]
#[must_use = "a new transmission becomes a group only when started"]
pub struct NewGroup {
    copy: Copy,
    frame: RawFrame,
    key: u128,
    emission: f64,
}

pub struct Grouper {
    wait_s: f64,
    max_pending: usize,
    pending: PendingIndex,
    queue: Queue,
    handed_out: HandedOut,
    stats: GroupStats,
}

/// The pending groups in first-arrival order, and the sequence number (mod
/// 2^32) of the oldest.
struct Queue {
    groups: VecDeque<Group>,
    base: u32,
}

impl Queue {
    /// Where the group numbered `seq` lies in the queue (past its end when
    /// handed out).
    fn offset(&self, seq: u32) -> usize {
        seq.wrapping_sub(self.base) as usize
    }
}

impl Groups for Queue {
    fn live(&self, seq: u32) -> bool {
        self.offset(seq) < self.groups.len()
    }

    fn has_key(&self, seq: u32, key: u128) -> bool {
        self.groups[self.offset(seq)].frame.key() == key
    }

    fn pending(&self) -> impl ExactSizeIterator<Item = (u128, u32)> {
        let base = self.base;
        self.groups.iter().enumerate().map(move |(i, g)| (g.frame.key(), base.wrapping_add(i as u32)))
    }
}

impl Grouper {
    pub fn new(wait_s: f64, max_pending: usize) -> Self {
        Grouper {
            wait_s,
            max_pending,
            pending: PendingIndex::new(),
            queue: Queue { groups: VecDeque::new(), base: 0 },
            handed_out: HandedOut::new(),
            stats: GroupStats::default(),
        }
    }

    pub fn stats(&self) -> &GroupStats {
        &self.stats
    }

    /// One receiver's copy, sent at `emission` on the server's clock (Unix s;
    /// NaN if its receiver cannot say).
    pub fn add(
        &mut self,
        rx: usize,
        arrival: f64,
        frame: &RawFrame,
        emission: f64,
        done: &mut impl FnMut(&Group),
    ) -> Added {
        self.stats.copies += 1;
        let copy = Copy { rx, timestamp: frame.timestamp, arrival, signal: frame.signal };
        let k = frame.key();
        if let Some(seq) = self.pending.find(k, &self.queue) {
            let i = self.queue.offset(seq);
            let g = &mut self.queue.groups[i];
            match g.copies.iter().find(|c| c.rx == rx) {
                None => {
                    // Sent long before the group's: a late copy of an
                    // earlier transmission of the same bytes (a steady
                    // velocity message, say), not a copy of this one.
                    if (emission - g.emission).abs() > SAME_TRANSMISSION_S
                        && self.handed_out.holds(k, emission)
                    {
                        self.stats.late_copies += 1;
                        return Added::Late;
                    }
                    if g.emission.is_nan() {
                        g.emission = emission;
                    }
                    g.copies.push(copy);
                    return Added::Joined;
                }
                // The same receiver again with the same timestamp: a duplicate.
                Some(c) if c.timestamp == copy.timestamp || !frame.has_timing() => {
                    self.stats.duplicate_copies += 1;
                    return Added::Duplicate;
                }
                // Same bytes, another time: a second transmission (replies
                // repeat their bytes); it starts its own group below.
                Some(_) => {}
            }
        }
        // Its transmission's group can have been handed out only if it
        // arrived the wait after being sent at the earliest (NaN: never).
        if arrival + SAME_TRANSMISSION_S >= emission + self.wait_s && self.handed_out.holds(k, emission) {
            self.stats.late_copies += 1;
            return Added::Late;
        }
        // Room is made before the caller decodes: the group handed out
        // for it is processed before anything this copy teaches.
        if self.queue.groups.len() >= self.max_pending {
            self.stats.overflow += 1;
            self.pop_front(done);
        }
        Added::New(NewGroup { copy, frame: *frame, key: k, emission })
    }

    /// Makes the group of a transmission `add` found new, with what
    /// decoding its first copy taught (the default when it did not decode).
    /// Inlined: it is on every new transmission's path.
    #[inline(always)]
    pub fn start(&mut self, new: NewGroup, info: GroupInfo) {
        let NewGroup { copy, frame, key, emission } = new;
        self.stats.groups += 1;
        let q = &mut self.queue;
        q.groups.push_back(Group {
            frame,
            first_arrival: copy.arrival,
            emission,
            copies: smallvec![copy],
            info,
        });
        let seq = q.base.wrapping_add(q.groups.len() as u32 - 1);
        self.pending.insert(key, seq, q);
    }

    /// When the oldest pending group's wait runs out (`None`: none pending).
    pub fn next_deadline(&self) -> Option<f64> {
        self.queue.groups.front().map(|g| g.first_arrival + self.wait_s)
    }

    /// Hands out every group whose wait has run out by `now`.
    pub fn advance(&mut self, now: f64, done: &mut impl FnMut(&Group)) {
        while self.queue.groups.front().is_some_and(|g| g.first_arrival + self.wait_s <= now) {
            self.pop_front(done);
        }
    }

    pub fn flush(&mut self, done: &mut impl FnMut(&Group)) {
        while !self.queue.groups.is_empty() {
            self.pop_front(done);
        }
    }

    /// Hands out the oldest group where it lies (moving its 400 bytes out
    /// of the queue for each transmission was 1% of the front stage's time).
    /// Its entry in the index goes stale with it.
    fn pop_front(&mut self, done: &mut impl FnMut(&Group)) {
        if let Some(g) = self.queue.groups.front() {
            done(g);
            if !g.emission.is_nan() {
                self.handed_out.remember(g.frame.key(), g.emission);
            }
            self.queue.groups.pop_front();
            self.queue.base = self.queue.base.wrapping_add(1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(hex: &str) -> RawFrame {
        crate::feed::frame_from_hex(hex, 5, 1).unwrap()
    }

    /// What `add` did, a new transmission started without decoded information.
    #[derive(Debug, PartialEq)]
    enum Seen {
        New,
        Joined,
        Duplicate,
        Late,
    }

    fn add(
        g: &mut Grouper,
        rx: usize,
        arrival: f64,
        frame: &RawFrame,
        emission: f64,
        out: &mut Vec<Group>,
    ) -> Seen {
        match g.add(rx, arrival, frame, emission, &mut keep(out)) {
            Added::New(n) => {
                g.start(n, GroupInfo::default());
                Seen::New
            }
            Added::Joined => Seen::Joined,
            Added::Duplicate => Seen::Duplicate,
            Added::Late => Seen::Late,
        }
    }

    /// A receiver of handed-out groups that keeps copies of them.
    fn keep(out: &mut Vec<Group>) -> impl FnMut(&Group) + '_ {
        |g| out.push(g.clone())
    }

    #[test]
    fn copies_join_until_the_wait_runs_out() {
        let mut g = Grouper::new(0.2, 100);
        let mut out = Vec::new();
        let a = f("8D4840D6202CC371C32CE0576098");
        assert_eq!(add(&mut g, 0, 10.0, &a, f64::NAN, &mut out), Seen::New);
        assert_eq!(add(&mut g, 1, 10.05, &a, f64::NAN, &mut out), Seen::Joined);
        assert_eq!(add(&mut g, 1, 10.06, &a, f64::NAN, &mut out), Seen::Duplicate);
        // Same bytes from a receiver already in the group, at another time: a new transmission.
        let later = crate::feed::frame_from_hex("8D4840D6202CC371C32CE0576098", 99, 1).unwrap();
        assert_eq!(add(&mut g, 1, 10.07, &later, f64::NAN, &mut out), Seen::New);
        assert_eq!(add(&mut g, 2, 10.1, &f("5D4840D61F3A2B"), f64::NAN, &mut out), Seen::New);
        g.advance(10.19, &mut keep(&mut out));
        assert!(out.is_empty());
        g.advance(10.2, &mut keep(&mut out));
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].copies.len(), 2);
        // The same bytes after the wait are a new transmission.
        g.advance(10.7, &mut keep(&mut out));
        assert_eq!(add(&mut g, 0, 10.7, &a, f64::NAN, &mut out), Seen::New);
        g.flush(&mut keep(&mut out));
        assert_eq!(out.len(), 4);
        assert_eq!(g.stats().duplicate_copies, 1);
    }

    #[test]
    fn a_copy_later_than_the_wait_is_late_and_a_repeat_is_new() {
        let mut g = Grouper::new(0.5, 100);
        let mut out = Vec::new();
        let a = f("8D4840D6202CC371C32CE0576098");
        // Sent at 10.00 s (on the server's clock, as each copy's receiver
        // puts it there): rx0 and rx1 on time, rx2 0.8 s late (its link's
        // burst), over a link whose least delay is 60 ms longer.
        assert_eq!(add(&mut g, 0, 10.04, &a, 10.0, &mut out), Seen::New);
        assert_eq!(add(&mut g, 1, 10.05, &a, 10.01, &mut out), Seen::Joined);
        g.advance(10.6, &mut keep(&mut out));
        assert_eq!(out.len(), 1);
        assert_eq!(add(&mut g, 2, 10.9, &a, 10.06, &mut out), Seen::Late);
        // The same bytes sent again 0.5 s later (a steady velocity message):
        // a transmission of its own, from every receiver.
        assert_eq!(add(&mut g, 2, 10.95, &a, 10.5, &mut out), Seen::New);
        // rx1's copy of the repeat is late too, but it is not the first
        // transmission's: it joins the repeat's pending group.
        assert_eq!(add(&mut g, 1, 11.05, &a, 10.51, &mut out), Seen::Joined);
        // A late copy of the first transmission that finds the repeat
        // pending is still late, not a copy of the repeat.
        assert_eq!(add(&mut g, 3, 11.1, &a, 10.02, &mut out), Seen::Late);
        // A copy whose receiver cannot say when it was sent: new.
        g.advance(11.5, &mut keep(&mut out));
        assert_eq!(add(&mut g, 4, 11.6, &a, f64::NAN, &mut out), Seen::New);
        assert_eq!(g.stats().late_copies, 2);
        assert_eq!(g.stats().groups, 3);
    }

    #[test]
    fn pending_groups_are_bounded() {
        let mut g = Grouper::new(1.0, 2);
        let mut out = Vec::new();
        for (i, hex) in ["5D4840D61F3A2B", "5D4840D61F3A2C", "5D4840D61F3A2D"].iter().enumerate() {
            add(&mut g, 0, i as f64 * 0.01, &f(hex), f64::NAN, &mut out);
        }
        assert_eq!(out.len(), 1);
        assert_eq!(g.stats().overflow, 1);
        // The evicted group's key is gone: its bytes start a new group.
        assert_eq!(add(&mut g, 1, 0.05, &f("5D4840D61F3A2B"), f64::NAN, &mut out), Seen::New);
    }
}
