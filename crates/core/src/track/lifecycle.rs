//! A track's lifecycle: tentative until M of its last N positions were
//! accepted (Stone Soup's M-of-N initiator), then confirmed; only a
//! confirmed track is published, fused or watched for conflicts. Deletion
//! is the fusion stage's: an aircraft not heard for `drop_after_s` is
//! dropped with its tracks (`Fuser::advance`).

/// Lifecycle stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Tentative,
    Confirmed,
}

/// The recent positions' outcomes and the stage they led to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lifecycle {
    /// Recent position outcomes, newest in bit 0 (1 = accepted).
    hits: u32,
    /// Positions seen, up to 32.
    seen: u32,
    stage: Stage,
}

impl Default for Lifecycle {
    fn default() -> Self {
        Lifecycle { hits: 0, seen: 0, stage: Stage::Tentative }
    }
}

impl Lifecycle {
    pub fn stage(&self) -> Stage {
        self.stage
    }

    pub fn confirmed(&self) -> bool {
        self.stage == Stage::Confirmed
    }

    /// A position's outcome: accepted (`hit`) or not. Confirmed once `m` of
    /// the last `n` (at most 32) were accepted; a confirmed track stays so.
    pub fn record(&mut self, hit: bool, m: u32, n: u32) {
        self.hits = (self.hits << 1) | hit as u32;
        self.seen = (self.seen + 1).min(32);
        let window = n.min(self.seen);
        let mask = if window >= 32 { u32::MAX } else { (1u32 << window) - 1 };
        if (self.hits & mask).count_ones() >= m {
            self.stage = Stage::Confirmed;
        }
    }

    /// The stage alone, as a replay of the history starts from: the
    /// outcomes of the replayed positions are not counted again.
    pub fn stage_only(&self) -> Lifecycle {
        Lifecycle { stage: self.stage, ..Lifecycle::default() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confirmed_at_m_of_the_last_n_and_not_before() {
        let mut l = Lifecycle::default();
        for hit in [true, false, true, false, true] {
            l.record(hit, 3, 4);
            assert!(!l.confirmed(), "never three of the last four: {l:?}");
        }
        l.record(true, 3, 4);
        assert!(l.confirmed(), "three of the last four");
        for _ in 0..10 {
            l.record(false, 3, 4);
        }
        assert!(l.confirmed(), "a confirmed track stays so");
        assert_eq!(l.stage_only(), Lifecycle { stage: Stage::Confirmed, ..Lifecycle::default() });
    }
}
