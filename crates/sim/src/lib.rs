//! fuse1090's synthetic world and its judge.
//!
//! - [`sim`]: a scenario (receivers with their clocks and timing faults,
//!   aircraft with their flight plans and equipage) becomes a capture in
//!   fuse1090's capture format, the truth of every aircraft and receiver,
//!   and an "oracle" configuration that tells fuse1090 what the simulator
//!   knows.
//! - [`eval`]: an output stream scored against that truth: errors, NEES
//!   against its band, track continuity, alerts, and Monte Carlo over seeds.
//!
//! It depends on the core only for its types and encoders (frames are
//! encoded by `fuse1090_core::modes`), never on the daemon, so a
//! simulated capture exercises exactly what a recorded one does.

pub mod eval;
pub mod sim;
