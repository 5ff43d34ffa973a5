//! The back stage of the core: tracking, fusion and alerts, driven by the
//! front stage's commands. It reads nothing of the front, so the commands
//! can be applied at once (one thread) or shipped to another thread in
//! batches (`run --capture`) with the same result.

use super::{event, Event};
use crate::fuse::{Fuser, Output};
use crate::mlat::engine::TdoaGroup;
use crate::track::Measurement;

/// What the front stage asks of the tracker, in the order it must happen.
#[derive(Clone, Debug)]
pub enum Cmd {
    /// An event of the front stage (an ADS-B report, an MLAT fix), passed
    /// through so the output keeps its order.
    Event(Event),
    /// A measurement of aircraft `addr`, at arrival time `now`.
    Measure {
        addr: u32,
        nac_p: Option<u8>,
        m: Measurement,
        now: f64,
    },
    /// Time differences of a transmission too few receivers heard for a fix.
    Tdoa {
        g: TdoaGroup,
        now: f64,
    },
    AltBaro {
        addr: u32,
        alt_ft: i32,
    },
    Squawk {
        addr: u32,
        squawk: u16,
    },
    Flight {
        addr: u32,
        flight: String,
    },
    /// The altitude selected on the autopilot (Comm-B 4,0), ft.
    NavAltitude {
        addr: u32,
        alt_ft: u32,
    },
    /// The conformance monitor's verdict on an aircraft's ADS-B changed.
    Suspect {
        addr: u32,
        t: f64,
        suspect: bool,
        offset_m: Option<f64>,
        nis: f64,
    },
    /// Time moved forward (arrival-time scale).
    Advance(f64),
    /// End of input.
    Finish,
}

pub struct Back {
    fuser: Fuser,
    outputs: Vec<Output>,
}

impl Back {
    pub fn new(fuser: Fuser) -> Back {
        Back { fuser, outputs: Vec::new() }
    }

    pub fn fuser(&self) -> &Fuser {
        &self.fuser
    }

    pub fn fuser_mut(&mut self) -> &mut Fuser {
        &mut self.fuser
    }

    /// When the tracker next has work of its own (a held publication, the
    /// conflict assessment, the sweep): an `Advance` to that time is due.
    pub fn poll_timeout(&self) -> Option<f64> {
        self.fuser.poll_timeout()
    }

    /// Applies commands in order; the events they make go to `out`.
    pub fn apply(&mut self, cmds: impl IntoIterator<Item = Cmd>, out: &mut impl Extend<Event>) {
        for cmd in cmds {
            let o = &mut self.outputs;
            match cmd {
                Cmd::Event(e) => out.extend(Some(e)),
                Cmd::Measure { addr, nac_p, m, now } => self.fuser.on_measurement(addr, nac_p, m, now, o),
                Cmd::Tdoa { g, now } => self.fuser.on_tdoa(&g, now, o),
                Cmd::AltBaro { addr, alt_ft } => self.fuser.set_alt_baro(addr, alt_ft),
                Cmd::Squawk { addr, squawk } => self.fuser.set_squawk(addr, squawk),
                Cmd::Flight { addr, flight } => self.fuser.set_flight(addr, flight),
                Cmd::NavAltitude { addr, alt_ft } => self.fuser.set_nav_altitude(addr, alt_ft),
                Cmd::Suspect { addr, t, suspect, offset_m, nis } => {
                    self.fuser.set_suspect(addr, t, suspect, offset_m, nis, o)
                }
                Cmd::Advance(now) => self.fuser.advance(now, o),
                Cmd::Finish => self.fuser.finish(o),
            }
            // Most commands make nothing, and draining nothing into `out`
            // was still a call and its bookkeeping: 2% of this stage's time.
            if !self.outputs.is_empty() {
                out.extend(self.outputs.drain(..).map(event));
            }
        }
    }
}
