//! Publish stage: events rendered for subscribers ([`json`]: the track stream
//! of the contract).

pub mod asterix;
pub mod json;
