//! Scenario files (TOML): receivers, aircraft and their trajectories, and
//! generators for random traffic and receiver fields.
//!
//! Every value is checked where it is deserialised, so a bad one is reported
//! with the file, line and column the TOML parser knows; cross-field problems
//! name the entry. Unknown keys are errors.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Deserializer};

use fuse1090_core::feed::capture::ClockKind;
use fuse1090_core::modes::commb::Bds;

fn checked<'de, D: Deserializer<'de>>(d: D, ok: impl Fn(f64) -> bool, what: &str) -> Result<f64, D::Error> {
    let v = f64::deserialize(d)?;
    if v.is_finite() && ok(v) {
        Ok(v)
    } else {
        Err(serde::de::Error::custom(format!("{v} is not {what}")))
    }
}

fn latitude<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    checked(d, |v| v.abs() <= 90.0, "a latitude (-90..90)")
}
fn longitude<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    checked(d, |v| v.abs() <= 180.0, "a longitude (-180..180)")
}
fn non_negative<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    checked(d, |v| v >= 0.0, "non-negative")
}
fn positive<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    checked(d, |v| v > 0.0, "positive")
}
fn probability<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    checked(d, |v| (0.0..=1.0).contains(&v), "a probability (0..1)")
}
fn altitude<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    checked(d, |v| (-500.0..=30_000.0).contains(&v), "an altitude in metres (-500..30000)")
}
fn speed<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    checked(d, |v| (0.0..=1_200.0).contains(&v), "a speed in m/s (0..1200)")
}
fn opt_positive<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    positive(d).map(Some)
}
fn address<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    let s = String::deserialize(d)?;
    match u32::from_str_radix(&s, 16) {
        Ok(v) if s.len() == 6 => Ok(v),
        _ => Err(serde::de::Error::custom(format!("{s:?} is not a 24-bit address (6 hex digits)"))),
    }
}
fn nac<'de, D: Deserializer<'de>>(d: D) -> Result<u8, D::Error> {
    let v = u8::deserialize(d)?;
    if v <= 11 {
        Ok(v)
    } else {
        Err(serde::de::Error::custom(format!("{v} is not a NAC category (0..11)")))
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub seed: u64,
    /// Unix time of the scenario's start.
    pub start_unix: f64,
    #[serde(deserialize_with = "positive")]
    pub duration_s: f64,
    /// WGS-84 height minus barometric altitude, for the whole airspace (m).
    #[serde(default)]
    pub baro_offset_m: f64,
    /// Default Mode S reply rate (DF4/5/20/21) per aircraft (Hz).
    #[serde(default = "default_interrogation_hz", deserialize_with = "non_negative")]
    pub interrogation_hz: f64,
    /// The Comm-B registers DF20/21 replies carry, one at random each
    /// ("2,0", "4,0", "5,0", "6,0"): what the interrogators ask for.
    #[serde(default = "default_commb", deserialize_with = "commb_registers")]
    pub commb: Vec<Bds>,
    /// The air the aircraft fly through (still, ISA, no magnetic variation
    /// when absent): what makes heading and airspeed differ from track and
    /// ground speed in the Comm-B registers.
    #[serde(default)]
    pub air: Air,
    #[serde(default)]
    pub receiver: Vec<Receiver>,
    #[serde(default)]
    pub receiver_field: Vec<ReceiverField>,
    #[serde(default)]
    pub aircraft: Vec<Aircraft>,
    #[serde(default)]
    pub traffic: Vec<Traffic>,
}

/// Wind, magnetic variation and temperature, the same over the whole
/// airspace; the wind varies with height.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Air {
    /// The wind at heights, interpolated linearly between them and constant
    /// beyond; in ascending height.
    #[serde(default)]
    pub wind: Vec<WindAt>,
    /// East of true north is positive: a magnetic heading is the true
    /// heading minus it.
    #[serde(default)]
    pub magnetic_variation_deg: f64,
    /// The air's temperature minus ISA's at every height (deg C).
    #[serde(default)]
    pub isa_deviation_c: f64,
}

/// The wind at one height: the velocity of the air (blowing towards east
/// and north), not the meteorological "from" direction.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindAt {
    #[serde(deserialize_with = "altitude")]
    pub alt_m: f64,
    #[serde(deserialize_with = "wind_speed")]
    pub east_ms: f64,
    #[serde(deserialize_with = "wind_speed")]
    pub north_ms: f64,
}

fn wind_speed<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    checked(d, |v| v.abs() <= 150.0, "a wind component in m/s (-150..150)")
}

impl Air {
    /// The wind (east, north; m/s) at height `alt_m`.
    pub fn wind_at(&self, alt_m: f64) -> [f64; 2] {
        let w = &self.wind;
        match w.iter().position(|p| p.alt_m > alt_m) {
            None => w.last().map_or([0.0; 2], |p| [p.east_ms, p.north_ms]),
            Some(0) => [w[0].east_ms, w[0].north_ms],
            Some(i) => {
                let (a, b) = (w[i - 1], w[i]);
                let f = (alt_m - a.alt_m) / (b.alt_m - a.alt_m);
                [a.east_ms + f * (b.east_ms - a.east_ms), a.north_ms + f * (b.north_ms - a.north_ms)]
            }
        }
    }
}

fn default_commb() -> Vec<Bds> {
    vec![Bds::B20]
}

/// The registers the simulator can fill from an aircraft's state.
fn commb_registers<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Bds>, D::Error> {
    let names = Vec::<String>::deserialize(d)?;
    let regs = names
        .iter()
        .map(|n| n.parse::<Bds>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(serde::de::Error::custom)?;
    match regs.iter().find(|b| !matches!(b, Bds::B20 | Bds::B40 | Bds::B50 | Bds::B60)) {
        Some(b) => Err(serde::de::Error::custom(format!(
            "the simulator writes 2,0, 4,0, 5,0 and 6,0, not {}",
            b.as_str()
        ))),
        None if regs.is_empty() => Err(serde::de::Error::custom("no Comm-B register")),
        None => Ok(regs),
    }
}

fn default_interrogation_hz() -> f64 {
    0.5
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Receiver {
    pub id: String,
    #[serde(deserialize_with = "latitude")]
    pub lat: f64,
    #[serde(deserialize_with = "longitude")]
    pub lon: f64,
    #[serde(deserialize_with = "altitude")]
    pub alt_m: f64,
    pub clock: ClockKind,
    /// beast12: the counter's value at the start, in seconds (random when absent).
    #[serde(default)]
    pub clock_offset_s: Option<f64>,
    /// Frequency error of the clock (ppm).
    #[serde(default)]
    pub drift_ppm: f64,
    /// Random walk of the frequency error (ppm per square-root second).
    #[serde(default, deserialize_with = "non_negative")]
    pub drift_walk_ppm: f64,
    /// Timing jitter, 1 sigma (ns).
    #[serde(default, deserialize_with = "non_negative")]
    pub jitter_ns: f64,
    /// A constant timing offset (ns): a real GPS receiver's fixed bias of
    /// up to hundreds of ns against true time (for a counter it merges
    /// into the clock's unknown offset).
    #[serde(default)]
    pub bias_ns: f64,
    /// Multipath: the share of receptions that take a reflected path, and
    /// the mean of its extra delay (ns, exponential: late, never early).
    #[serde(default, deserialize_with = "probability")]
    pub multipath_prob: f64,
    #[serde(default, deserialize_with = "non_negative")]
    pub multipath_delay_ns: f64,
    /// Scenario times (s) at which the receiver restarts and its counter starts again from zero.
    #[serde(default)]
    pub resets_s: Vec<f64>,
    /// Declared minus true position, east/north/up (m): a misconfigured receiver.
    #[serde(default)]
    pub position_error_m: [f64; 3],
    #[serde(default = "default_range_km", deserialize_with = "positive")]
    pub range_km: f64,
    #[serde(default, deserialize_with = "probability")]
    pub loss: f64,
    #[serde(default = "default_delay_ms", deserialize_with = "non_negative")]
    pub delay_ms: f64,
    #[serde(default = "default_delay_spread_ms", deserialize_with = "non_negative")]
    pub delay_spread_ms: f64,
    /// Bursts of extra network delay: how many per minute on average, how long, how much.
    #[serde(default, deserialize_with = "non_negative")]
    pub burst_per_min: f64,
    #[serde(default = "default_burst_s", deserialize_with = "non_negative")]
    pub burst_s: f64,
    #[serde(default, deserialize_with = "non_negative")]
    pub burst_ms: f64,
}

fn default_range_km() -> f64 {
    400.0
}
fn default_delay_ms() -> f64 {
    50.0
}
fn default_delay_spread_ms() -> f64 {
    10.0
}
fn default_burst_s() -> f64 {
    1.0
}

/// Many receivers at random in a disk around a centre.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReceiverField {
    pub count: usize,
    pub id_prefix: String,
    #[serde(deserialize_with = "latitude")]
    pub center_lat: f64,
    #[serde(deserialize_with = "longitude")]
    pub center_lon: f64,
    #[serde(deserialize_with = "positive")]
    pub radius_km: f64,
    /// Share of GPS-timed receivers; the rest are beast12.
    #[serde(default, deserialize_with = "probability")]
    pub gps_share: f64,
    #[serde(default, deserialize_with = "non_negative")]
    pub max_drift_ppm: f64,
    #[serde(default = "default_jitter_ns", deserialize_with = "non_negative")]
    pub jitter_ns: f64,
    #[serde(default = "default_range_km", deserialize_with = "positive")]
    pub range_km: f64,
    #[serde(default, deserialize_with = "probability")]
    pub loss: f64,
}

fn default_jitter_ns() -> f64 {
    83.0
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aircraft {
    #[serde(deserialize_with = "address")]
    pub hex: u32,
    #[serde(default)]
    pub callsign: String,
    /// ADS-B out; false for a Mode S only transponder.
    #[serde(default = "yes")]
    pub adsb: bool,
    #[serde(default = "default_nac_p", deserialize_with = "nac")]
    pub nac_p: u8,
    #[serde(default = "default_nac_v", deserialize_with = "nac")]
    pub nac_v: u8,
    /// True GNSS error per axis, 1 sigma (m); default from NACp (EPU / 2.448).
    #[serde(default, deserialize_with = "opt_positive")]
    pub pos_sigma_m: Option<f64>,
    /// Correlation time of the GNSS error (s); 0 for white noise.
    #[serde(default, deserialize_with = "non_negative")]
    pub gnss_tau_s: f64,
    #[serde(default)]
    pub on_ground: bool,
    #[serde(default = "default_squawk")]
    pub squawk: String,
    pub start: StartState,
    #[serde(default)]
    pub segments: Vec<Segment>,
    /// Broadcast positions offset from the truth, east/north (m): a spoofer.
    #[serde(default)]
    pub spoof_offset_m: Option<[f64; 2]>,
    #[serde(default)]
    pub rates: Rates,
    /// When the aircraft appears and leaves (scenario seconds).
    #[serde(default, deserialize_with = "non_negative")]
    pub start_s: f64,
    #[serde(default)]
    pub end_s: Option<f64>,
}

fn yes() -> bool {
    true
}
fn default_nac_p() -> u8 {
    8
}
fn default_nac_v() -> u8 {
    2
}
fn default_squawk() -> String {
    "1000".into()
}

#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartState {
    #[serde(deserialize_with = "latitude")]
    pub lat: f64,
    #[serde(deserialize_with = "longitude")]
    pub lon: f64,
    #[serde(deserialize_with = "altitude")]
    pub alt_m: f64,
    #[serde(deserialize_with = "speed")]
    pub speed_mps: f64,
    pub heading_deg: f64,
    #[serde(default)]
    pub vrate_mps: f64,
}

/// Rates in force for a stretch of time: straight (all zero), constant-rate
/// turn (positive = right), acceleration, climb or descent, or any mix.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    #[serde(deserialize_with = "positive")]
    pub duration_s: f64,
    #[serde(default)]
    pub turn_dps: f64,
    #[serde(default)]
    pub accel_mps2: f64,
    #[serde(default)]
    pub vrate_mps: f64,
}

/// Transmission rates (Hz); `None` keeps the default for the equipage.
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rates {
    pub position_hz: Option<f64>,
    pub velocity_hz: Option<f64>,
    pub ident_hz: Option<f64>,
    pub status_hz: Option<f64>,
    pub target_state_hz: Option<f64>,
    pub df11_hz: Option<f64>,
    pub interrogation_hz: Option<f64>,
}

/// Random airborne traffic in a disk.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Traffic {
    pub count: usize,
    #[serde(deserialize_with = "address")]
    pub first_hex: u32,
    #[serde(deserialize_with = "latitude")]
    pub center_lat: f64,
    #[serde(deserialize_with = "longitude")]
    pub center_lon: f64,
    #[serde(deserialize_with = "positive")]
    pub radius_km: f64,
    pub alt_m: [f64; 2],
    pub speed_mps: [f64; 2],
    /// How many of them have no ADS-B out.
    #[serde(default)]
    pub mode_s_only: usize,
    /// How many broadcast false positions, and how far off (m).
    #[serde(default)]
    pub spoofers: usize,
    #[serde(default)]
    pub spoof_offset_m: Vec<f64>,
    #[serde(default = "default_nac_p", deserialize_with = "nac")]
    pub nac_p: u8,
}

impl Scenario {
    pub fn load(path: &Path) -> Result<Scenario> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        Scenario::parse(&text, &path.display().to_string())
    }

    /// Parses and checks a scenario, errors prefixed with `name`.
    pub fn parse(text: &str, name: &str) -> Result<Scenario> {
        let s: Scenario = toml::from_str(text).map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
        s.validate().map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
        Ok(s)
    }

    fn validate(&self) -> Result<()> {
        if self.air.wind.windows(2).any(|w| w[1].alt_m <= w[0].alt_m) {
            bail!("air: the wind's heights must ascend");
        }
        if self.air.magnetic_variation_deg.abs() > 180.0 || self.air.isa_deviation_c.abs() > 60.0 {
            bail!("air: magnetic variation beyond 180 degrees or ISA deviation beyond 60 degrees");
        }
        let mut ids = std::collections::HashSet::new();
        for r in &self.receiver {
            if !ids.insert(r.id.as_str()) {
                bail!("receiver {:?} is declared twice", r.id);
            }
            if r.id.is_empty() || r.id.contains(char::is_whitespace) {
                bail!("receiver id {:?} must be a single word", r.id);
            }
            if let Some(t) = r.resets_s.iter().find(|t| !(0.0..=self.duration_s).contains(*t)) {
                bail!("receiver {}: reset at {t} s is outside the scenario", r.id);
            }
        }
        let mut hexes = std::collections::HashSet::new();
        for a in &self.aircraft {
            if !hexes.insert(a.hex) {
                bail!("aircraft {:06X} is declared twice", a.hex);
            }
            if a.squawk.len() != 4 || !a.squawk.chars().all(|c| ('0'..='7').contains(&c)) {
                bail!("aircraft {:06X}: squawk {:?} is not four octal digits", a.hex, a.squawk);
            }
            if a.callsign.len() > 8
                || !a.callsign.chars().all(|c| c.is_ascii_uppercase() || c.is_ascii_digit())
            {
                bail!("aircraft {:06X}: callsign {:?} must be up to 8 of A-Z 0-9", a.hex, a.callsign);
            }
            if let Some(end) = a.end_s {
                if end <= a.start_s {
                    bail!("aircraft {:06X}: end_s must come after start_s", a.hex);
                }
            }
            let rates = [
                a.rates.position_hz,
                a.rates.velocity_hz,
                a.rates.ident_hz,
                a.rates.status_hz,
                a.rates.target_state_hz,
                a.rates.df11_hz,
                a.rates.interrogation_hz,
            ];
            if rates.iter().flatten().any(|r| !(0.0..=20.0).contains(r)) {
                bail!("aircraft {:06X}: rates must be in 0..20 Hz", a.hex);
            }
        }
        for t in &self.traffic {
            if t.mode_s_only + t.spoofers > t.count {
                bail!("traffic at {:06X}: mode_s_only + spoofers exceeds count", t.first_hex);
            }
            if t.alt_m[0] > t.alt_m[1] || t.speed_mps[0] > t.speed_mps[1] || t.speed_mps[0] < 0.0 {
                bail!("traffic at {:06X}: ranges must be [low, high]", t.first_hex);
            }
            if t.spoofers > 0 && t.spoof_offset_m.is_empty() {
                bail!("traffic at {:06X}: spoofers need spoof_offset_m", t.first_hex);
            }
        }
        if self.receiver.is_empty() && self.receiver_field.is_empty() {
            bail!("a scenario needs at least one receiver");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
seed = 1
start_unix = 1700000000.0
duration_s = 10.0
[[receiver]]
id = "rx1"
lat = 43.6
lon = 1.4
alt_m = 150.0
clock = "gps"
[[aircraft]]
hex = "4840D6"
start = { lat = 43.7, lon = 1.4, alt_m = 3000.0, speed_mps = 120.0, heading_deg = 90.0 }
"#;

    #[test]
    fn parses_and_reports_bad_values_with_their_line() {
        let s = Scenario::parse(MINIMAL, "m.toml").unwrap();
        assert_eq!(s.aircraft[0].hex, 0x4840D6);
        assert_eq!(s.receiver[0].clock, ClockKind::Gps);

        let bad = MINIMAL.replace("lat = 43.6", "lat = 143.6");
        let e = Scenario::parse(&bad, "m.toml").unwrap_err().to_string();
        assert!(e.contains("m.toml") && e.contains("line 7") && e.contains("not a latitude"), "{e}");

        let bad = MINIMAL.replace("clock = \"gps\"", "clock = \"gps\"\ncolour = 3");
        let e = Scenario::parse(&bad, "m.toml").unwrap_err().to_string();
        assert!(e.contains("line 11") && e.contains("unknown field"), "{e}");

        let bad = MINIMAL.replace("hex = \"4840D6\"", "hex = \"4840D\"");
        assert!(Scenario::parse(&bad, "m.toml").unwrap_err().to_string().contains("24-bit address"));

        let bad = MINIMAL.replace("duration_s = 10.0", "duration_s = -1.0");
        assert!(Scenario::parse(&bad, "m.toml").unwrap_err().to_string().contains("line 4"));

        let bad = format!("{MINIMAL}\n[[aircraft]]\nhex = \"4840D6\"\nstart = {{ lat = 1, lon = 1, alt_m = 1, speed_mps = 1, heading_deg = 1 }}\n");
        assert!(Scenario::parse(&bad, "m.toml").unwrap_err().to_string().contains("declared twice"));
    }

    #[test]
    fn the_air_interpolated_and_checked() {
        let air = "\n[air]\nmagnetic_variation_deg = -3.0\nwind = [\n  { alt_m = 0.0, east_ms = 4.0, north_ms = 0.0 },\n  { alt_m = 10000.0, east_ms = 44.0, north_ms = -10.0 },\n]\n";
        let s = Scenario::parse(&format!("{MINIMAL}{air}"), "m.toml").unwrap();
        assert_eq!(s.air.wind_at(-100.0), [4.0, 0.0]);
        assert_eq!(s.air.wind_at(2_500.0), [14.0, -2.5]);
        assert_eq!(s.air.wind_at(12_000.0), [44.0, -10.0]);
        assert_eq!(Scenario::parse(MINIMAL, "m.toml").unwrap().air.wind_at(5_000.0), [0.0, 0.0]);
        let down = air.replace("alt_m = 10000.0", "alt_m = -10.0");
        let e = Scenario::parse(&format!("{MINIMAL}{down}"), "m.toml").unwrap_err().to_string();
        assert!(e.contains("must ascend"), "{e}");
        let gale = air.replace("east_ms = 44.0", "east_ms = 440.0");
        let e = Scenario::parse(&format!("{MINIMAL}{gale}"), "m.toml").unwrap_err().to_string();
        assert!(e.contains("not a wind component"), "{e}");
    }
}
