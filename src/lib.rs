//! fuse1090: a real-time ADS-B / Mode S receive-and-fuse daemon.
//!
//! Three crates show the layers:
//! - `fuse1090-core` (`crates/core`): the sans-IO processing core, from
//!   framing to the output encoders. Data flows one way through its
//!   modules: [`feed`] (bytes → frames) → [`modes`] (frames → decoded
//!   messages) → [`mlat`], [`track`] → [`fuse`] → [`publish`], driven by
//!   [`core`]'s two stages. Time is passed in, never read, so every stage
//!   can be driven by recorded data and tested against truth.
//! - `fuse1090-sim` (`crates/sim`): the simulator and the evaluator.
//! - this crate, the daemon and the CLI: sockets, HTTP, NATS, signals and
//!   files around the core ([`live`], [`cluster`], [`cmd`], [`config`]).
//!
//! The core's and the simulator's modules are re-exported here, so
//! `fuse1090::mlat::Mlat` and `fuse1090_core::mlat::Mlat` are one type.

pub mod cluster;
pub mod cmd;
pub mod config;
pub mod live;
pub mod stages;

pub use fuse1090_core::{core, feed, fuse, geo, mlat, modes, problem, publish, track, FastMap};
pub use fuse1090_sim::{eval, sim};
