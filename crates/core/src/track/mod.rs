//! Tracking stage: per-aircraft state estimation.
//!
//! Shaped like Stone Soup: motion models ([`models`]) say how a state moves
//! and how uncertain that is; the predictor and updater ([`kf`]) apply them
//! and a measurement; the IMM ([`imm`]) runs several models side by side and
//! mixes them by how well each explains the data. All in a local east/north
//! plane with fixed-size nalgebra matrices: the horizontal state is
//! `[e, n, ve, vn, ae, an]` for every model, so the IMM can mix them.

pub mod config;
pub mod estimate;
pub mod gate;
pub mod hearing;
pub mod imm;
pub mod kf;
pub mod lifecycle;
pub mod measurement;
pub mod models;
pub mod motion;
pub mod noise;
pub mod particle;
pub mod plane;
#[allow(clippy::module_inception)]
pub mod track;
pub mod ukf;

pub use config::{ModelConfig, TrackConfig};
pub use imm::{Imm, ImmSpec};
pub use kf::{Gaussian, Linear, PosMeasurement};
pub use models::MotionModel;
pub use track::{Estimate, Measurement, Observation, Outcome, Persistent, SharedShare, Source, Stage, Track};
