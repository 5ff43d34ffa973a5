//! Configuration (TOML). Unknown keys are errors; every field has a default,
//! so an empty file (or none) is the built-in configuration. Errors carry the
//! file, line and column that the TOML parser reports.

use std::path::Path;

use anyhow::{Context, Result};
use serde::Deserialize;

use crate::core::CoreConfig;

#[derive(Clone, Debug, Default, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub core: CoreConfig,
    /// Publish per-source (adsb, mlat) tracks beside the fused ones.
    pub publish_source_tracks: bool,
}

/// Reads a TOML file into `T`; errors name the file (and, from the parser,
/// the line and column). Shared by configurations and scenarios.
pub fn load_toml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<(T, String)> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let name = path.display().to_string();
    Ok((parse_toml(&text, &name)?, name))
}

/// Parses TOML text into `T`, errors prefixed with `name`.
pub fn parse_toml<T: serde::de::DeserializeOwned>(text: &str, name: &str) -> Result<T> {
    toml::from_str(text).map_err(|e| anyhow::anyhow!("{name}: {e}"))
}

impl Config {
    pub fn load(path: &Path) -> Result<Config> {
        let (cfg, name): (Config, String) = load_toml(path)?;
        cfg.validated(&name)
    }

    pub fn parse(text: &str, name: &str) -> Result<Config> {
        parse_toml::<Config>(text, name)?.validated(name)
    }

    fn validated(self, name: &str) -> Result<Config> {
        self.core.validate().map_err(|e| anyhow::anyhow!("{name}: [core] {e}"))?;
        Ok(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_example_documents_every_field_at_its_default() {
        let text =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/fuse1090.toml")).unwrap();
        let example = Config::parse(&text, "config/fuse1090.toml").unwrap();
        let defaults = Config::default();
        // Same values: the example shows the defaults.
        assert_eq!(format!("{example:?}"), format!("{defaults:?}"));
        // Every field: an example missing one would still parse (defaults), so
        // compare the documented keys with the fields serde writes.
        fn keys(v: &toml::Value, prefix: &str, out: &mut Vec<String>) {
            if let toml::Value::Table(t) = v {
                for (k, v) in t {
                    let path = format!("{prefix}{k}");
                    match v {
                        toml::Value::Table(_) => keys(v, &format!("{path}."), out),
                        _ => out.push(path),
                    }
                }
            }
        }
        let (mut documented, mut fields) = (Vec::new(), Vec::new());
        keys(&text.parse::<toml::Value>().unwrap(), "", &mut documented);
        keys(&toml::Value::try_from(&defaults).unwrap(), "", &mut fields);
        documented.sort();
        fields.sort();
        assert_eq!(documented, fields, "config/fuse1090.toml must list every field");
    }

    #[test]
    fn defaults_unknown_keys_and_bad_values() {
        let c = Config::parse("", "empty").unwrap();
        assert_eq!(c.core.group_wait_s, CoreConfig::default().group_wait_s);
        let e = Config::parse("[core]\ngroup_wait = 1\n", "x.toml").unwrap_err().to_string();
        assert!(e.contains("x.toml") && e.contains("line 2") && e.contains("unknown field"), "{e}");
        let e = Config::parse("[core]\ngroup_wait_s = -1\n", "x.toml").unwrap_err().to_string();
        assert!(e.contains("group_wait_s"), "{e}");
    }
}
