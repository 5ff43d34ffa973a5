//! fuse1090: a real-time ADS-B / Mode S receive-and-fuse daemon.
//!
//! Data flows one way through the stages, each a module:
//! [`feed`] (bytes → frames) → [`modes`] (frames → decoded messages) → mlat,
//! track → fuse → publish. The processing core is sans-IO: time is passed in,
//! never read from the system clock, so every stage can be driven by recorded
//! data and tested against truth.

pub mod cluster;
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

/// The hash map of the per-frame and per-measurement paths: foldhash, seeded
/// per process like the standard one (so nothing can depend on an iteration
/// order) but a fraction of SipHash's cost, which was 6% of all instructions
/// of `run --capture` on the scale world (five lookups a frame: receiver,
/// group, decoder, MLAT and tracker state).
pub type FastMap<K, V> = std::collections::HashMap<K, V, foldhash::fast::RandomState>;
