//! Fuzz target: arbitrary text as a configuration file, through the whole
//! check (TOML, fields, every live-service rule). It must answer with a
//! configuration or an error, never panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = fuse1090::config::Config::parse(text, "fuzz.toml");
    }
});
