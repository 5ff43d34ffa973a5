//! Configuration (TOML). Unknown keys are errors; every field has a default,
//! so an empty file (or none) is the built-in configuration. Errors carry the
//! file, line and column that the TOML parser reports.

use std::path::Path;

use serde::Deserialize;

use crate::core::CoreConfig;
use crate::live::config::{HttpConfig, InputConfig, OutputConfig, ReceiverConfig, ServiceConfig};

#[derive(Clone, Debug, Default, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub core: CoreConfig,
    /// Publish per-source (adsb, mlat) tracks beside the fused ones.
    pub publish_source_tracks: bool,
    pub service: ServiceConfig,
    pub http: HttpConfig,
    /// The live service's receivers, inputs and outputs.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub receiver: Vec<ReceiverConfig>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub input: Vec<InputConfig>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub output: Vec<OutputConfig>,
    /// Several processes over NATS JetStream (docs/cluster.md); absent, one node.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cluster: Option<crate::cluster::ClusterConfig>,
}

impl Config {
    /// The receivers the configuration describes, as the core is told them
    /// ([`crate::core::Core::know`]): `run --config` and every Monte Carlo run.
    pub fn known_receivers(&self) -> Vec<crate::core::front::KnownReceiver> {
        self.receiver.iter().map(|r| r.known()).collect()
    }

    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|source| ConfigError::Read { file: file.clone(), source })?;
        Config::parse(&text, &file)
    }

    pub fn parse(text: &str, file: &str) -> Result<Config, ConfigError> {
        let cfg: Config = toml::from_str(text)
            .map_err(|e| ConfigError::Syntax { file: file.to_string(), message: e.to_string() })?;
        cfg.validated(file)
    }

    /// Every problem at once, each naming its table.
    fn validated(self, file: &str) -> Result<Config, ConfigError> {
        let mut problems: Vec<Problem> = Vec::new();
        if let Err(e) = self.core.validate() {
            problems.extend(e);
        }
        problems.extend(crate::live::config::validate(
            &self.service,
            &self.receiver,
            &self.input,
            &self.output,
        ));
        problems.extend(self.http.validate());
        if let Some(c) = &self.cluster {
            problems.extend(c.validate());
        }
        if problems.is_empty() {
            Ok(self)
        } else {
            Err(ConfigError::Invalid { file: file.to_string(), problems })
        }
    }
}

/// Why a configuration was refused.
#[derive(Debug)]
pub enum ConfigError {
    /// The file could not be read.
    Read { file: String, source: std::io::Error },
    /// Not TOML of the configuration's shape (an unknown key, a misspelt
    /// kind, a value of the wrong type): the parser's message, with the
    /// line and column.
    Syntax { file: String, message: String },
    /// Values out of range or at odds with each other: every one at once.
    Invalid { file: String, problems: Vec<Problem> },
}

pub use crate::problem::Problem;

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            // The reason is the source's (`{:#}` shows the chain).
            ConfigError::Read { file, .. } => write!(f, "cannot read {file}"),
            ConfigError::Syntax { file, message } => write!(f, "{file}: {message}"),
            ConfigError::Invalid { file, problems } => {
                let lines: Vec<String> = problems.iter().map(|p| format!("{file}: {p}")).collect();
                write!(f, "{}", lines.join("\n"))
            }
        }
    }
}

impl std::error::Error for ConfigError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ConfigError::Read { source, .. } => Some(source),
            _ => None,
        }
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
    fn a_refused_configuration_says_why_by_kind_table_and_field() {
        let text = "[service]\nstats_interval_s = -1\n\n[core.track]\ngate_probability = 2\n\n\
                    [[input]]\nkind = \"beast_tcp_client\"\naddress = \"127.0.0.1:30005\"\n";
        let Err(ConfigError::Invalid { file, problems }) = Config::parse(text, "bad.toml") else {
            panic!("not refused as invalid");
        };
        assert_eq!(file, "bad.toml");
        let at = |table: &str| problems.iter().find(|p| p.table == table).map(|p| p.message.clone());
        assert_eq!(at("[service]").as_deref(), Some("stats_interval_s = -1 must be positive"));
        assert!(at("[core.track]").is_some_and(|m| m.starts_with("gate_probability = 2")), "{problems:?}");
        assert_eq!(at("[[input]] 1").as_deref(), Some("beast_tcp_client needs receiver"));
        assert_eq!(problems.len(), 3, "{problems:?}");
        let shown = Config::parse(text, "bad.toml").unwrap_err().to_string();
        assert!(shown.contains("bad.toml: [[input]] 1: beast_tcp_client needs receiver"), "{shown}");
        assert!(matches!(Config::parse("[core\n", "x.toml"), Err(ConfigError::Syntax { .. })));
        let missing = Config::load(Path::new("/nonexistent/fuse1090.toml")).unwrap_err();
        assert!(
            matches!(&missing, ConfigError::Read { source, .. } if source.kind() == std::io::ErrorKind::NotFound)
        );
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

    #[test]
    fn every_problem_is_reported_at_once_with_its_table() {
        let text = r#"
[core]
group_wait_s = 9
max_range_km = -1
[core.mlat]
jitter_gps_ns = 0
[core.track.sparse]
particles = 5
[core.fuse.conflict]
interval_s = 0
[service]
realtime_priority = 100
[[receiver]]
id = "a"
lat = 95.0
lon = 1.0
alt_m = 0.0
clock = "gps"
beast_id = "12345"
[receiver.timing]
sigma_ns = 30
late_rate = 1.5
[[input]]
kind = "beast_tcp_client"
address = "127.0.0.1:30005"
receiver = "nobody"
[[input]]
kind = "udp"
address = "0.0.0.0:0"
[[output]]
kind = "udp"
format = "json"
"#;
        let e = Config::parse(text, "bad.toml").unwrap_err().to_string();
        for needle in [
            "bad.toml: [core] group_wait_s",
            "bad.toml: [core] max_range_km = -1 must be positive",
            "bad.toml: [core.mlat] jitter_gps_ns = 0 must be positive",
            "bad.toml: [core.track.sparse] particles = 5 must be 100 to 100000",
            "bad.toml: [core.fuse.conflict] interval_s = 0 must be positive",
            "[service] realtime_priority = 100 must be in 0..=99",
            "[[receiver]] 1 (a): position out of range",
            "[[receiver]] 1 (a): beast_id = \"12345\": 16 hex digits or a UUID",
            "[[receiver]] 1 (a): timing: late_rate = 1.5: from 0 to below 1",
            "[[input]] 1: receiver \"nobody\" is not declared",
            "[[output]] 1: udp needs address",
            "[[input]] 2: address 0.0.0.0:0: port 0 is no port",
        ] {
            assert!(e.contains(needle), "{needle:?} missing from:\n{e}");
        }
        // Kinds are enums: a misspelt one stops the parse, naming the field,
        // its line and what it may be.
        let e = Config::parse(
            "[[receiver]]\nid = \"a\"\nlat = 0.0\nlon = 0.0\nalt_m = 0.0\nclock = \"atomic\"\n",
            "c.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("line 6") && e.contains("atomic") && e.contains("expected `beast12` or `gps`"),
            "{e}"
        );
        let e = Config::parse("[service]\nmetrics_listen = \"nowhere\"\n", "m.toml").unwrap_err().to_string();
        assert!(e.contains("metrics_listen") && e.contains("nowhere"), "{e}");
        // What is off is absent; the empty string earlier files wrote is read so.
        let c = Config::parse("[service]\nrecord = \"\"\nmetrics_listen = \"\"\n", "old.toml").unwrap();
        assert_eq!((c.service.record, c.service.metrics_listen), (None, None));
        let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/config/demo.toml");
        assert!(Config::load(std::path::Path::new(demo)).is_ok());
    }
}
