//! Publish stage: events rendered for subscribers ([`json`]: the track
//! stream, [`asterix`]: CAT062, [`aircraft_json`]: readsb's aircraft.json
//! for map clients).

pub mod aircraft_json;
pub mod asterix;
pub mod json;
