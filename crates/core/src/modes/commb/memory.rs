//! What the stateful decoder remembers of an aircraft for Comm-B inference:
//! its latest barometric altitude and velocity, from whatever carried them
//! (altitude replies, ADS-B, earlier track and turn reports). Two values and
//! their times, so the aircraft table's own lifetime bounds it.

use super::{Inference, Known, KnownVelocity, Register};

/// Older than this, an altitude or velocity says too little to weigh a reply by.
const MAX_AGE_S: f64 = 30.0;

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Memory {
    alt: Option<(i32, f64)>,
    /// Track (deg), ground speed (kt), time.
    velocity: Option<(f64, f64, f64)>,
    /// When the aircraft last reported its velocity by ADS-B.
    adsb_velocity_t: Option<f64>,
}

impl Memory {
    pub fn note_altitude(&mut self, alt_ft: i32, t: f64) {
        self.alt = Some((alt_ft, t));
    }

    pub fn note_velocity(&mut self, track_deg: f64, gs_kt: f64, t: f64) {
        self.velocity = Some((track_deg, gs_kt, t));
    }

    pub fn note_adsb_velocity(&mut self, track_deg: f64, gs_kt: f64, t: f64) {
        self.note_velocity(track_deg, gs_kt, t);
        self.adsb_velocity_t = Some(t);
    }

    /// Whether the aircraft reported its velocity by ADS-B within the last 30 s.
    pub fn adsb_velocity_recent(&self, t: f64) -> bool {
        self.adsb_velocity_t.is_some_and(|then| (t - then).abs() <= MAX_AGE_S)
    }

    /// Takes up what an identified reply says of the aircraft's motion.
    pub fn note(&mut self, inference: &Inference, t: f64) {
        if let Inference::Identified(Register::TrackTurn(r)) = inference {
            if let (Some(track), Some(gs)) = (r.track_deg, r.gs_kt) {
                self.note_velocity(track, gs as f64, t);
            }
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
