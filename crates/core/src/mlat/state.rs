//! What multilateration has learnt of each receiver, kept across restarts
//! (`[service] state_file`): its timing calibration (bias and noise) and
//! its position survey. A restart then starts from what was known, not
//! from the configured priors; the receivers' clock pairs are learnt again
//! in seconds and are not kept.
//!
//! JSON, one object: `{"version":1,"saved_unix":..,"receivers":[{"id":..,
//! "clock":"gps","lat":..,"lon":..,"alt_m":..,"fixes":..,"bias_s":..,
//! "var_s2":..,"late_rate":..,"late_mean_s":..,"survey":{...}}],"air":{...}}`. A receiver is restored only if its id,
//! clock kind and declared position (within a metre) are unchanged: a
//! receiver moved or reconfigured is learnt afresh. `air` is what heading
//! reports taught of the wind and the magnetic variation (see
//! `core::wind`), absent from files written before it was learnt.

use serde::{Deserialize, Serialize};

use crate::feed::capture::ClockKind;

/// The file's version: a file of another version is ignored (and said so).
pub const VERSION: u32 = 1;

#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
pub struct LearntState {
    pub version: u32,
    pub saved_unix: f64,
    pub receivers: Vec<LearntReceiver>,
    #[serde(default)]
    pub air: Option<AirSnapshot>,
}

/// The wind learner's state: its estimate and covariance (row by row), the
/// regional spread, and when it last learnt (Unix s).
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
pub struct AirSnapshot {
    pub x: Vec<f64>,
    pub p: Vec<f64>,
    pub scatter_var: f64,
    pub t: f64,
    pub learnt: u64,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct LearntReceiver {
    pub id: String,
    pub clock: ClockKind,
    pub lat: f64,
    pub lon: f64,
    pub alt_m: f64,
    /// Fixes its calibration rests on, its timing bias (s) and noise variance (s^2).
    pub fixes: u64,
    pub bias_s: f64,
    pub var_s2: f64,
    /// Its late copies' share and mean delay (s): absent from files written
    /// before they were learnt.
    #[serde(default)]
    pub late_rate: Option<f64>,
    #[serde(default)]
    pub late_mean_s: Option<f64>,
    pub survey: SurveySnapshot,
}

/// A position survey's normal equations, as they stand.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
pub struct SurveySnapshot {
    /// The 4x4 matrix, column by column.
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    pub dd: f64,
    pub n: f64,
    pub count: u64,
    /// When its first and latest measurements were taken (s; absent from
    /// older state files, whose surveys are then taken as long enough).
    #[serde(default)]
    pub since: f64,
    #[serde(default)]
    pub last: f64,
}

impl LearntState {
    /// Reads a state file; `Ok(None)` when there is none yet.
    pub fn load(path: &std::path::Path) -> Result<Option<LearntState>, String> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(format!("{}: {e}", path.display())),
        };
        let state: LearntState =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        if state.version != VERSION {
            return Err(format!(
                "{}: version {} (this build reads {VERSION})",
                path.display(),
                state.version
            ));
        }
        Ok(Some(state))
    }

    /// Writes it whole or not at all (a temporary file renamed over it).
    pub fn save(&self, path: &std::path::Path) -> std::io::Result<()> {
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        let text = serde_json::to_vec(self).map_err(std::io::Error::other)?;
        std::fs::write(&tmp, text)?;
        std::fs::rename(&tmp, path)
    }
}
