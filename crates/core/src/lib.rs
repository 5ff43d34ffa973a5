//! fuse1090's processing core: frames in, events out, time passed in.
//!
//! This crate is everything between a receiver's bytes and a subscriber's
//! bytes that does not touch the world. It has no sockets, no async
//! runtime, no metrics recorder and no clock: every function that depends
//! on time takes it as an argument. The compiler enforces that, because
//! none of those crates is among its dependencies. So the daemon
//! (`fuse1090 run`), an offline replay (`run --capture`) and a cluster's
//! worker drive the same code, and a capture replayed offline gives the
//! same output bytes every time.
//!
//! # How a frame flows through it
//!
//! ```text
//! bytes --feed--> RawFrame --core::Front--> decoded by modes (first copy)
//!                                         \-> copies grouped (mlat::group)
//!                                             --mlat::Mlat--> fix | time differences | why not
//!       core::Front --Cmd--> core::Back --fuse::Fuser--> tracks (track::Track, one IMM each)
//!                                                     --> Event: position, fix, track, alert, receiver
//!       Event --publish--> JSON lines, ASTERIX CAT062, aircraft.json, SBS, Beast
//! ```
//!
//! - [`feed`]: bytes to frames (Beast, AVR, hex lines) and the capture format.
//! - [`modes`]: Mode S decoding: CRC, fields, CPR, NIC, Comm-B inference, the
//!   stateful decoder that decides which positions are believed.
//! - [`mlat`]: the copies of one transmission grouped, receivers' clocks
//!   synchronised, their timing learnt, fixes solved.
//! - [`track`]: motion models, the IMM, one aircraft's track.
//! - [`fuse`]: the aircraft table, fusion of ADS-B and MLAT, conformance,
//!   conflicts.
//! - [`publish`]: events rendered in the formats subscribers read.
//! - [`core`]: the two stages that drive all of the above, `Front`
//!   (receivers, decoding, grouping, multilateration) and `Back` (tracking,
//!   fusion), joined by commands that only flow forward.
//! - [`geo`]: WGS-84, ECEF and local planes.
//!
//! `docs/architecture.md` in the repository has the types between the
//! stages and where each concern lives.

pub mod core;
pub mod feed;
pub mod fuse;
pub mod geo;
pub mod mlat;
pub mod modes;
pub mod problem;
pub mod publish;
pub mod recent;
pub mod track;

/// The hash map of the per-frame and per-measurement paths: foldhash, seeded
/// per process like the standard one (so nothing can depend on an iteration
/// order) but a fraction of SipHash's cost, which was 6% of all instructions
/// of `run --capture` on the scale world (five lookups a frame: receiver,
/// group, decoder, MLAT and tracker state).
pub type FastMap<K, V> = std::collections::HashMap<K, V, foldhash::fast::RandomState>;
