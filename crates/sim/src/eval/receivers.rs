//! Receivers learnt against receivers true: what multilateration reported
//! of each receiver (the track stream's last `receiver` record) beside what
//! the simulator made it (the truth file's `receiver` line).
//!
//! A GPS receiver's offset is only known against the others (a bias common
//! to all goes into the emission time), so the true offsets are compared
//! as the learnt ones are reported: against the mean of the GPS receivers'.
//! A counter-timed receiver's true sigma is its jitter and its 12 MHz
//! counter's resolution together (a tick's uniform error, 24 ns): the
//! timing error its copies really carry.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use serde_json::Value;

/// A receiver as the simulator made it.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct TrueReceiver {
    pub id: String,
    pub clock: String,
    pub sigma_ns: f64,
    pub offset_ns: f64,
    pub multipath_prob: f64,
    pub multipath_delay_ns: f64,
    pub position_offset_en_m: [f64; 2],
}

impl TrueReceiver {
    /// The sigma of its timing error (ns): jitter, and a counter's resolution.
    pub fn timing_sigma_ns(&self) -> f64 {
        let tick_ns = 1e3 / 12.0;
        match self.clock.as_str() {
            "beast12" => self.sigma_ns.hypot(tick_ns / 12f64.sqrt()),
            _ => self.sigma_ns,
        }
    }
}

/// One receiver, learnt beside true; learnt values absent where the
/// records did not give them.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ReceiverRow {
    pub id: String,
    pub state: Option<String>,
    pub sigma_ns: f64,
    pub sigma_learnt_ns: Option<f64>,
    pub offset_ns: Option<f64>,
    pub offset_learnt_ns: Option<f64>,
    pub multipath_prob: f64,
    pub outlier_rate: Option<f64>,
    pub position_offset_en_m: [f64; 2],
    pub position_offset_learnt_en_m: Option<[f64; 2]>,
}

/// The rows, in the truth's order, for the latest record of each receiver.
pub fn compare(truth: &[TrueReceiver], latest: &BTreeMap<String, Value>) -> Vec<ReceiverRow> {
    let gps: Vec<f64> = truth.iter().filter(|r| r.clock == "gps").map(|r| r.offset_ns).collect();
    let gps_mean = gps.iter().sum::<f64>() / gps.len().max(1) as f64;
    truth
        .iter()
        .map(|r| {
            let rec = latest.get(&r.id);
            let num = |k: &str| rec.and_then(|v| v[k].as_f64());
            ReceiverRow {
                id: r.id.clone(),
                state: rec.and_then(|v| v["state"].as_str()).map(String::from),
                sigma_ns: r.timing_sigma_ns(),
                sigma_learnt_ns: num("sigma_ns"),
                offset_ns: (r.clock == "gps" && gps.len() >= 2).then_some(r.offset_ns - gps_mean),
                offset_learnt_ns: num("offset_ns"),
                multipath_prob: r.multipath_prob,
                outlier_rate: num("outlier_rate"),
                position_offset_en_m: r.position_offset_en_m,
                position_offset_learnt_en_m: rec.and_then(|v| {
                    let p = v["position_offset_en_m"].as_array()?;
                    Some([p.first()?.as_f64()?, p.get(1)?.as_f64()?])
                }),
            }
        })
        .collect()
}

/// The table `eval` prints.
pub fn table(rows: &[ReceiverRow]) -> String {
    let opt = |v: Option<f64>, p: usize| v.map_or("-".to_string(), |x| format!("{x:.p$}"));
    let en = |v: Option<[f64; 2]>| v.map_or("-".to_string(), |[e, n]| format!("{e:+.0},{n:+.0}"));
    let mut out = format!(
        "{:<10} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>11} {:>11}\n",
        "receiver",
        "state",
        "sigma_ns",
        "learnt",
        "offset_ns",
        "learnt",
        "multipath",
        "outliers",
        "position_m",
        "learnt"
    );
    for r in rows {
        out += &format!(
            "{:<10} {:>9} {:>9.0} {:>9} {:>9} {:>9} {:>9.3} {:>9} {:>11} {:>11}\n",
            r.id,
            r.state.as_deref().unwrap_or("-"),
            r.sigma_ns,
            opt(r.sigma_learnt_ns, 0),
            opt(r.offset_ns, 0),
            opt(r.offset_learnt_ns, 0),
            r.multipath_prob,
            opt(r.outlier_rate, 3),
            en(Some(r.position_offset_en_m)),
            en(r.position_offset_learnt_en_m),
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn learnt_beside_true_with_gps_offsets_against_their_mean() {
        let t = |id: &str, clock: &str, off: f64| TrueReceiver {
            id: id.into(),
            clock: clock.into(),
            sigma_ns: 50.0,
            offset_ns: off,
            multipath_prob: 0.1,
            multipath_delay_ns: 300.0,
            position_offset_en_m: [0.0, 0.0],
        };
        let truth =
            [t("a", "gps", 100.0), t("b", "gps", -100.0), t("c", "gps", 300.0), t("d", "beast12", 0.0)];
        let mut latest = BTreeMap::new();
        latest.insert(
            "a".to_string(),
            serde_json::json!({"type":"receiver","id":"a","state":"ok","sigma_ns":47.0,"offset_ns":-5.0,
                "outlier_rate":0.08,"position_offset_en_m":[3.0,-4.0]}),
        );
        let rows = compare(&truth, &latest);
        assert_eq!(rows[0].offset_ns, Some(0.0));
        assert_eq!(rows[2].offset_ns, Some(200.0));
        assert_eq!(rows[3].offset_ns, None, "a counter's offset is its clock's");
        assert_eq!((rows[0].sigma_learnt_ns, rows[0].outlier_rate), (Some(47.0), Some(0.08)));
        assert_eq!(rows[0].position_offset_learnt_en_m, Some([3.0, -4.0]));
        assert_eq!((rows[1].state.clone(), rows[1].sigma_learnt_ns), (None, None));
        let text = table(&rows);
        assert!(text.lines().nth(1).unwrap().starts_with("a ") && text.contains("+3,-4"), "{text}");
    }
}
