//! fuse1090: a real-time ADS-B / Mode S receive-and-fuse daemon.
//!
//! Data flows one way through the stages, each a module:
//! [`feed`] (bytes → frames) → [`modes`] (frames → decoded messages) → mlat,
//! track → fuse → publish. The processing core is sans-IO: time is passed in,
//! never read from the system clock, so every stage can be driven by recorded
//! data and tested against truth.

pub mod cmd;
pub mod config;
pub mod core;
pub mod eval;
pub mod feed;
pub mod fuse;
pub mod geo;
pub mod live;
pub mod mlat;
pub mod modes;
pub mod publish;
pub mod sim;
pub mod track;
