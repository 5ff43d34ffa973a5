//! Multilateration stage: [`group`]ing copies of one transmission across
//! receivers, [`clock`] synchronisation of receiver pairs and the network
//! time base ([`sync`]), the TDOA [`solver`], and the [`engine`] that turns
//! complete groups into fixes.

pub mod clock;
pub mod engine;
pub mod group;
mod pending;
pub mod solver;
pub mod sync;

pub use engine::{Mlat, MlatConfig, MlatFix, MlatStats};
