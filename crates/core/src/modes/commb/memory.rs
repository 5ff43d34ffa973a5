//! What the stateful decoder remembers of an aircraft for Comm-B inference
//! and for using its replies: its latest barometric altitude and velocity,
//! from whatever carried them (altitude replies, ADS-B, earlier track and
//! turn reports), its ADS-B velocity apart, its latest turn rate, and how
//! many heading reports it gave lately. A few values and their times, so the
//! aircraft table's own lifetime bounds it.

use super::{Inference, Known, KnownVelocity, Register};
use crate::recent::RecentCount;

/// Older than this, an altitude or velocity says too little to weigh a reply by.
const MAX_AGE_S: f64 = 30.0;
/// Heading reports are counted over about this long (s): the span over
/// which the errors they share (the wind where the aircraft is) add up in
/// its track's velocity.
const HEADING_SPAN_S: f64 = 60.0;

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Memory {
    alt: Option<(i32, f64)>,
    /// Track (deg), ground speed (kt), time.
    velocity: Option<(f64, f64, f64)>,
    /// The same, as ADS-B last reported it.
    adsb_velocity: Option<(f64, f64, f64)>,
    /// Turn rate (deg/s, from a track and turn report or two ADS-B
    /// velocities) and its time.
    turn: Option<(f64, f64)>,
    /// Heading reports identified, faded over [`HEADING_SPAN_S`].
    heading_reports: RecentCount,
}

/// What a Comm-B reply's user needs to know of the aircraft beyond the reply.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReplyContext {
    pub known: Known,
    /// Its latest ADS-B velocity, within the last 30 s.
    pub adsb_velocity: Option<KnownVelocity>,
    /// Its latest turn rate (deg/s), within the last 30 s.
    pub turn_dps: Option<f64>,
    /// Heading reports it gave over about the last minute, this one included.
    pub heading_reports: f64,
}

impl ReplyContext {
    /// Whether the aircraft reported its velocity by ADS-B within the last 30 s.
    pub fn adsb_velocity_recent(&self) -> bool {
        self.adsb_velocity.is_some()
    }
}

impl Memory {
    pub fn note_altitude(&mut self, alt_ft: i32, t: f64) {
        self.alt = Some((alt_ft, t));
    }

    pub fn note_velocity(&mut self, track_deg: f64, gs_kt: f64, t: f64) {
        self.velocity = Some((track_deg, gs_kt, t));
    }

    pub fn note_adsb_velocity(&mut self, track_deg: f64, gs_kt: f64, t: f64) {
        if let Some((track0, gs0, t0)) = self.adsb_velocity {
            // Two velocities a few seconds apart give the turn; further
            // apart, they say little of it now.
            let dt = t - t0;
            if (0.2..=5.0).contains(&dt) && gs0 > 50.0 {
                let turn = ((track_deg - track0 + 540.0).rem_euclid(360.0) - 180.0) / dt;
                self.turn = Some((turn, t));
            }
        }
        self.note_velocity(track_deg, gs_kt, t);
        self.adsb_velocity = Some((track_deg, gs_kt, t));
    }

    /// Takes up what an identified reply says of the aircraft's motion.
    pub fn note(&mut self, inference: &Inference, t: f64) {
        match inference {
            Inference::Identified(Register::TrackTurn(r)) => {
                if let (Some(track), Some(gs)) = (r.track_deg, r.gs_kt) {
                    self.note_velocity(track, gs as f64, t);
                }
                if let Some(rate) = r.track_rate_dps {
                    self.turn = Some((rate, t));
                }
            }
            Inference::Identified(Register::HeadingSpeed(_)) => {
                self.heading_reports.add(t, HEADING_SPAN_S);
            }
            _ => {}
        }
    }

    /// What a reply at `t` (carrying `own_alt_ft` when a DF20) comes with.
    pub fn context(&self, t: f64, own_alt_ft: Option<i32>) -> ReplyContext {
        let recent = |then: f64| (t - then).abs() <= MAX_AGE_S;
        ReplyContext {
            known: self.known(t, own_alt_ft),
            adsb_velocity: self.adsb_velocity.and_then(|(track_deg, gs_kt, then)| {
                recent(then).then(|| KnownVelocity { track_deg, gs_kt, age_s: (t - then).abs() })
            }),
            turn_dps: self.turn.and_then(|(rate, then)| recent(then).then_some(rate)),
            heading_reports: self.heading_reports.at(t, HEADING_SPAN_S),
        }
    }

    /// What is known at `t` for a reply that carries `own_alt_ft` (DF20) or not.
    pub fn known(&self, t: f64, own_alt_ft: Option<i32>) -> Known {
        let age = |then: f64| Some((t - then).abs()).filter(|&a| a <= MAX_AGE_S);
        Known {
            alt_ft: own_alt_ft
                .map(|a| (a, 0.0))
                .or_else(|| self.alt.and_then(|(a, then)| Some((a, age(then)?)))),
            velocity: self.velocity.and_then(|(track_deg, gs_kt, then)| {
                Some(KnownVelocity { track_deg, gs_kt, age_s: age(then)? })
            }),
        }
    }
}

/// Replies counted by what inference made of them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CommbStats {
    pub identified: u64,
    pub ambiguous: u64,
    /// Fitted registers' layouts, each contradicting what was known.
    pub contradicted: u64,
    pub no_register: u64,
}

impl CommbStats {
    pub fn count(&mut self, inference: &Inference) {
        match inference {
            Inference::Identified(_) => self.identified += 1,
            Inference::Ambiguous(_) => self.ambiguous += 1,
            Inference::Contradicted(_) => self.contradicted += 1,
            Inference::NoRegister => self.no_register += 1,
        }
    }
}
