//! Multilateration stage: [`group`]ing copies of one transmission across
//! receivers (late copies of handed-out ones recognised by [`late`]),
//! [`clock`] synchronisation of receiver pairs and the network time base
//! ([`sync`]), the TDOA [`solver`], the [`engine`] that turns complete
//! groups into fixes, each receiver's learnt [`timing`], and the region's
//! GNSS-baro difference ([`baro`]) that turns barometric altitudes into
//! heights.

pub mod baro;
pub mod clock;
pub mod coverage;
pub mod engine;
pub mod group;
mod late;
mod pending;
pub mod report;
pub mod shared;
pub mod solver;
pub mod state;
pub mod survey;
pub mod sync;
pub mod timing;

pub use engine::{Mlat, MlatConfig, MlatFix, MlatStats};
pub use report::{Exclusion, ReceiverReport, RxState};
