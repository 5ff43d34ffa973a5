//! Multilateration stage: grouping copies of one transmission across
//! receivers (this module's [`group`]); clock synchronisation and the TDOA
//! solver build on the groups.

pub mod group;
pub mod solver;
