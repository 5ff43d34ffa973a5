//! Accuracy against truth: per source and per aircraft, horizontal and
//! vertical RMSE, 95th percentile error, mean NEES with its 95% chi-square
//! band, continuity (share of the truth's time covered), track breaks and
//! false tracks.
//!
//! Rows by what produced the record: `track` records by their `source`
//! (fused, adsb, mlat), `mlat` fixes, and `position` records (decoded ADS-B
//! reports before tracking) as `adsb-report`.

pub mod montecarlo;
pub mod receivers;
mod truth;

pub use truth::Truth;
use truth::{en_offset, TruthPoint};

use std::collections::{BTreeMap, HashMap};
use std::io::BufRead;

use anyhow::{Context, Result};
use serde::Serialize;
use serde_json::Value;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// A gap in a track is a break when it exceeds this (s) and three times the
/// track's usual update interval (parked aircraft squitter every 5 s).
pub const GAP_S: f64 = 5.0;
/// A track whose mean error exceeds this is counted false (m).
pub const FALSE_TRACK_M: f64 = 1_000.0;

#[derive(Default)]
struct Acc {
    times: Vec<f64>,
    h_err: Vec<f64>,
    v_err: Vec<f64>,
    /// Horizontal velocity errors (m/s) of the records that give one.
    vel_err: Vec<f64>,
    /// (time, NEES) of each estimate with a covariance.
    nees: Vec<(f64, f64)>,
    /// Horizontal Cramér-Rao variances (trace, m^2) of MLAT fixes.
    crb: Vec<f64>,
    /// NEES summed per aircraft and minute, with the count: the batches of
    /// `nees_batch_band`.
    batches: Vec<(f64, usize)>,
}

/// One source's aircraft pooled for its overall row: their errors, how many,
/// their continuities summed (averaged at the end), breaks and false tracks.
#[derive(Default)]
struct Pooled {
    acc: Acc,
    aircraft: usize,
    cont: f64,
    cont_1km: f64,
    breaks: usize,
    false_tracks: usize,
}

/// Receivers of a simulated world, for the Cramér-Rao bound of MLAT fixes:
/// true ECEF position and true timing sigma (jitter and quantisation), by id.
pub struct Geometry {
    pub receivers: HashMap<String, ([f64; 3], f64)>,
    /// Sigma of the altitude constraint the solver applies (m).
    pub alt_sigma_m: f64,
}

impl Geometry {
    pub fn from_scenario(s: &crate::sim::scenario::Scenario, alt_sigma_m: f64) -> Geometry {
        use fuse1090_core::feed::capture::ClockKind;
        let receivers = crate::sim::all_receivers(s)
            .into_iter()
            .map(|r| {
                let tick = match r.clock {
                    ClockKind::Beast12 => 1.0 / 12e6,
                    ClockKind::Gps => 1e-9,
                };
                let sigma = ((r.jitter_ns * 1e-9).powi(2) + tick * tick / 12.0).sqrt();
                (r.id.clone(), (fuse1090_core::geo::geodetic_to_ecef(r.lat, r.lon, r.alt_m), sigma))
            })
            .collect();
        Geometry { receivers, alt_sigma_m }
    }
}

/// One row of the report.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub source: String,
    /// "all" for the overall row.
    pub hex: String,
    pub aircraft: usize,
    pub n: usize,
    pub h_rmse_m: f64,
    pub h_p95_m: f64,
    pub v_rmse_m: Option<f64>,
    /// Horizontal velocity (m/s) against the truth's, of the records that
    /// give one (tracks; not fixes).
    pub vel_rmse_ms: Option<f64>,
    pub nees: Option<f64>,
    pub nees_band: Option<[f64; 2]>,
    /// The same band from the spread of the NEES's sums per aircraft and
    /// minute (batch means, [`montecarlo::runs_band`] with the minutes as
    /// runs): honest where estimates share their errors (fixes from one
    /// clock synchronisation, a track's successive states), which the band
    /// above, of independent values, is not. `None` below 20 batches.
    pub nees_batch_band: Option<[f64; 2]>,
    /// Every NEES value with its time, for the Monte Carlo runner's
    /// per-epoch test (samples of one run are correlated in time).
    #[serde(skip)]
    pub nees_samples: Vec<(f64, f64)>,
    pub continuity: f64,
    /// The same, counting only estimates within 1 km of the truth.
    pub continuity_1km: f64,
    pub breaks: usize,
    pub false_tracks: usize,
    /// MLAT fixes, given the scenario: RMS of the Cramér-Rao bound of each
    /// fix's geometry (m) and the RMSE's ratio to it.
    pub crb_m: Option<f64>,
    pub crb_ratio: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub overall: Vec<Row>,
    pub aircraft: Vec<Row>,
    /// Records for addresses the truth does not know.
    pub unknown_records: usize,
    /// The fused track against the two single-source tracks, aircraft by
    /// aircraft, when the records have all three (`run --source-tracks`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fusion: Option<FusionComparison>,
    /// Each receiver as learnt (the records' last `receiver` record) beside
    /// its truth, when the truth has receivers.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub receivers: Vec<receivers::ReceiverRow>,
}

/// Per aircraft, the RMSE of its fused, ADS-B and MLAT tracks over the time
/// all three cover (from the latest start to the earliest end). Over each
/// track's whole life the comparison is not like for like: the fused track
/// starts with the first MLAT fixes, a second or two before the ADS-B track,
/// and those first estimates (hundreds of metres, with covariances to match)
/// weigh on its RMSE alone.
#[derive(Clone, Debug, Serialize)]
pub struct FusionComparison {
    pub aircraft: usize,
    /// Aircraft whose fused track has the lowest of the three RMSEs.
    pub fused_best: usize,
    /// The others: address and how much worse (m) than the better single track.
    pub others: Vec<(String, f64)>,
}

/// See [`FusionComparison`]. `per` holds each (source, hex)'s estimate
/// times and horizontal errors.
fn compare_fusion(per: &BTreeMap<(String, String), (Acc, usize)>) -> Option<FusionComparison> {
    let mut cmp = FusionComparison { aircraft: 0, fused_best: 0, others: Vec::new() };
    for ((source, hex), (fused, _)) in per.range(("fused".to_string(), String::new())..) {
        if source != "fused" {
            break;
        }
        let get = |s: &str| per.get(&(s.to_string(), hex.clone())).map(|(a, _)| a);
        let (Some(adsb), Some(mlat)) = (get("adsb"), get("mlat")) else {
            continue;
        };
        let tracks = [fused, adsb, mlat];
        let first = |a: &Acc| a.times.iter().copied().fold(f64::INFINITY, f64::min);
        let last = |a: &Acc| a.times.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let t0 = tracks.iter().map(|a| first(a)).fold(f64::NEG_INFINITY, f64::max);
        let t1 = tracks.iter().map(|a| last(a)).fold(f64::INFINITY, f64::min);
        let rmse = |a: &Acc| {
            let v: Vec<f64> = a
                .times
                .iter()
                .zip(&a.h_err)
                .filter(|(t, _)| (t0..=t1).contains(*t))
                .map(|(_, e)| *e)
                .collect();
            (!v.is_empty()).then(|| rms(&v))
        };
        let (Some(f), Some(a), Some(m)) = (rmse(fused), rmse(adsb), rmse(mlat)) else {
            continue;
        };
        cmp.aircraft += 1;
        if f < a.min(m) {
            cmp.fused_best += 1;
        } else {
            cmp.others.push((hex.clone(), f - a.min(m)));
        }
    }
    (cmp.aircraft > 0).then_some(cmp)
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn p95(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() as f64 * 0.95).ceil() as usize).clamp(1, s.len()) - 1]
}

/// NEES values (time, value) summed per minute, with their counts.
fn minute_batches(nees: &[(f64, f64)]) -> Vec<(f64, usize)> {
    let mut by_minute: BTreeMap<i64, (f64, usize)> = BTreeMap::new();
    for &(t, x) in nees {
        let b = by_minute.entry((t / 60.0).floor() as i64).or_default();
        b.0 += x;
        b.1 += 1;
    }
    by_minute.into_values().collect()
}

/// 95% band of the mean of `n` chi-square(2) NEES values.
pub fn nees_band(n: usize, dof: f64) -> [f64; 2] {
    let k = n as f64 * dof;
    let chi = ChiSquared::new(k).expect("positive dof");
    [chi.inverse_cdf(0.025) / n as f64, chi.inverse_cdf(0.975) / n as f64]
}

fn coverage(times: &mut [f64], span: (f64, f64)) -> (f64, usize) {
    times.sort_by(f64::total_cmp);
    let mut gaps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    let limit = if gaps.is_empty() {
        GAP_S
    } else {
        let mut sorted = gaps.clone();
        sorted.sort_by(f64::total_cmp);
        GAP_S.max(3.0 * sorted[sorted.len() / 2])
    };
    let mut covered = 0.0;
    let mut breaks = 0;
    for gap in gaps.drain(..) {
        if gap <= limit {
            covered += gap;
        } else {
            breaks += 1;
        }
    }
    let dur = (span.1 - span.0).max(1e-9);
    ((covered / dur).min(1.0), breaks)
}

/// Evaluates the records of a track stream against the truth.
pub fn evaluate(truth: &Truth, records: impl BufRead) -> Result<Report> {
    evaluate_with(truth, records, None)
}

/// As [`evaluate`], with the receivers' geometry for the MLAT rows' bound.
pub fn evaluate_with(truth: &Truth, records: impl BufRead, geometry: Option<&Geometry>) -> Result<Report> {
    let Records { accs, unknown, latest_receiver } = read_records(truth, records, geometry)?;
    // Per aircraft rows (tracks of one aircraft merged), then overall per source.
    let mut per: BTreeMap<(String, String), (Acc, usize)> = BTreeMap::new();
    for ((source, hex, _id), acc) in accs {
        let mean_err = acc.h_err.iter().sum::<f64>() / acc.h_err.len().max(1) as f64;
        let e = per.entry((source, hex)).or_default();
        e.1 += (mean_err > FALSE_TRACK_M) as usize;
        e.0.times.extend(acc.times);
        e.0.h_err.extend(acc.h_err);
        e.0.v_err.extend(acc.v_err);
        e.0.vel_err.extend(acc.vel_err);
        e.0.nees.extend(acc.nees);
        e.0.crb.extend(acc.crb);
    }
    // Before `coverage` sorts the times apart from their errors.
    let fusion = compare_fusion(&per);
    let mut aircraft_rows = Vec::new();
    let mut overall: BTreeMap<String, Pooled> = BTreeMap::new();
    for ((source, hex), (mut acc, false_tracks)) in per {
        acc.batches = minute_batches(&acc.nees);
        let span = truth.span(&hex).unwrap_or((0.0, 0.0));
        let mut near: Vec<f64> =
            acc.times.iter().zip(&acc.h_err).filter(|&(_, &e)| e <= 1000.0).map(|(&t, _)| t).collect();
        let (cont_1km, _) = coverage(&mut near, span);
        let (cont, breaks) = coverage(&mut acc.times, span);
        aircraft_rows.push(row(&source, &hex, 1, &acc, (cont, cont_1km), breaks, false_tracks));
        // The tracks of aircraft without ADS-B also in a row of their own:
        // what multilateration and Mode S alone give.
        let mode_s_only = matches!(source.as_str(), "fused" | "mlat") && truth.adsb.get(&hex) == Some(&false);
        let rows = [Some(source.clone()), mode_s_only.then(|| format!("{source}:mode-s-only"))];
        for key in rows.into_iter().flatten() {
            let o = overall.entry(key).or_default();
            o.acc.h_err.extend(&acc.h_err);
            o.acc.v_err.extend(&acc.v_err);
            o.acc.vel_err.extend(&acc.vel_err);
            o.acc.nees.extend(&acc.nees);
            o.acc.crb.extend(&acc.crb);
            o.acc.batches.extend(&acc.batches);
            o.aircraft += 1;
            o.cont += cont;
            o.cont_1km += cont_1km;
            o.breaks += breaks;
            o.false_tracks += false_tracks;
        }
    }
    let overall = overall
        .into_iter()
        .map(|(source, o)| {
            let n = o.aircraft as f64;
            row(&source, "all", o.aircraft, &o.acc, (o.cont / n, o.cont_1km / n), o.breaks, o.false_tracks)
        })
        .collect();
    let receivers = receivers::compare(&truth.receivers, &latest_receiver);
    Ok(Report { overall, aircraft: aircraft_rows, unknown_records: unknown, fusion, receivers })
}

/// What a track stream's records add up to: errors per (source, hex,
/// track id), the records of unknown aircraft, each receiver's latest record.
struct Records {
    accs: BTreeMap<(String, String, String), Acc>,
    unknown: usize,
    latest_receiver: BTreeMap<String, Value>,
}

/// Reads a track stream against the truth.
fn read_records(truth: &Truth, records: impl BufRead, geometry: Option<&Geometry>) -> Result<Records> {
    let mut accs: BTreeMap<(String, String, String), Acc> = BTreeMap::new();
    let mut unknown = 0;
    let mut latest_receiver: BTreeMap<String, Value> = BTreeMap::new();
    for (i, line) in records.lines().enumerate() {
        let line = line?;
        if line.trim().is_empty() {
            continue;
        }
        let v: Value = serde_json::from_str(&line).with_context(|| format!("tracks line {}", i + 1))?;
        let source = match v["type"].as_str() {
            // A particle filter's estimates (too few receivers for a fix) apart.
            Some("track") if v["sparse"].as_bool() == Some(true) => {
                format!("{}:sparse", v["source"].as_str().unwrap_or("fused"))
            }
            Some("track") => v["source"].as_str().unwrap_or("fused").to_string(),
            Some("mlat") => "mlat-fix".to_string(),
            Some("position") => "adsb-report".to_string(),
            Some("receiver") => {
                if let Some(id) = v["id"].as_str() {
                    latest_receiver.insert(id.to_string(), v);
                }
                continue;
            }
            _ => continue,
        };
        let (Some(hex), Some(t), Some(lat), Some(lon)) =
            (v["hex"].as_str(), v["t"].as_f64(), v["lat"].as_f64(), v["lon"].as_f64())
        else {
            continue;
        };
        let hex = hex.to_uppercase();
        // A spoofer's broadcast positions are false by design: keep them apart.
        let source = if truth.spoofers.contains(&hex) && source.starts_with("adsb") {
            format!("{source}+spoof")
        } else {
            source
        };
        let id = v["id"].as_u64().map(|x| x.to_string()).unwrap_or_default();
        let Some(tp) = truth.at(&hex, t) else {
            if !truth.tracks.contains_key(&hex) {
                unknown += 1;
            }
            continue;
        };
        accs.entry((source, hex, id)).or_default().add(&v, &tp, t, en_offset(&tp, lat, lon), geometry);
    }
    Ok(Records { accs, unknown, latest_receiver })
}

/// One row of the report from its accumulated errors.
fn row(
    source: &str,
    hex: &str,
    aircraft: usize,
    acc: &Acc,
    (cont, cont_1km): (f64, f64),
    breaks: usize,
    false_tracks: usize,
) -> Row {
    Row {
        source: source.to_string(),
        hex: hex.to_string(),
        aircraft,
        n: acc.h_err.len(),
        h_rmse_m: rms(&acc.h_err),
        h_p95_m: p95(&acc.h_err),
        v_rmse_m: (!acc.v_err.is_empty()).then(|| rms(&acc.v_err)),
        vel_rmse_ms: (!acc.vel_err.is_empty()).then(|| rms(&acc.vel_err)),
        nees: (!acc.nees.is_empty())
            .then(|| acc.nees.iter().map(|(_, x)| x).sum::<f64>() / acc.nees.len() as f64),
        nees_band: (!acc.nees.is_empty()).then(|| nees_band(acc.nees.len(), 2.0)),
        nees_batch_band: (acc.batches.len() >= 20)
            .then(|| montecarlo::runs_band(&acc.batches, 2.0))
            .flatten(),
        nees_samples: acc.nees.clone(),
        continuity: cont,
        continuity_1km: cont_1km,
        breaks,
        false_tracks,
        crb_m: (!acc.crb.is_empty()).then(|| (acc.crb.iter().sum::<f64>() / acc.crb.len() as f64).sqrt()),
        crb_ratio: (!acc.crb.is_empty() && acc.crb.len() == acc.h_err.len())
            .then(|| rms(&acc.h_err) / (acc.crb.iter().sum::<f64>() / acc.crb.len() as f64).sqrt()),
    }
}

impl Acc {
    /// One record's errors against the truth point `tp` at `t`, `e` its
    /// east/north offset (m); with the scenario's geometry, an MLAT fix's
    /// Cramér-Rao bound.
    fn add(&mut self, v: &Value, tp: &TruthPoint, t: f64, e: [f64; 2], geometry: Option<&Geometry>) {
        self.times.push(t);
        self.h_err.push(e[0].hypot(e[1]));
        if let Some(alt) = v["alt_m"].as_f64() {
            self.v_err.push(alt - tp.alt);
        }
        if let (Some(vel), Some(truth)) = (east_north(&v["vel_enu"]), tp.vel) {
            self.vel_err.push((vel[0] - truth[0]).hypot(vel[1] - truth[1]));
        }
        if let (Some(g), Some(ids)) = (geometry, v["receivers"].as_array()) {
            let (pos, sig): (Vec<[f64; 3]>, Vec<f64>) =
                ids.iter().filter_map(|id| g.receivers.get(id.as_str()?)).copied().unzip();
            let alt = v["altitude_used"].as_bool().unwrap_or(false).then_some(g.alt_sigma_m);
            let truth_ecef = fuse1090_core::geo::geodetic_to_ecef(tp.lat, tp.lon, tp.alt);
            if let Some(c) = fuse1090_core::mlat::solver::crb_en(&pos, &sig, alt, truth_ecef) {
                self.crb.push(c[0][0] + c[1][1]);
            }
        }
        if let Some(c) = v["cov_en"].as_array() {
            let g = |r: usize, k: usize| c.get(r).and_then(|x| x.get(k)).and_then(Value::as_f64);
            if let (Some(a), Some(b), Some(cc), Some(d)) = (g(0, 0), g(0, 1), g(1, 0), g(1, 1)) {
                let det = a * d - b * cc;
                if det > 0.0 {
                    self.nees.push((t, (d * e[0] * e[0] - (b + cc) * e[0] * e[1] + a * e[1] * e[1]) / det));
                }
            }
        }
    }
}

/// The east and north of a `vel_enu` array.
fn east_north(v: &Value) -> Option<[f64; 2]> {
    Some([v.get(0)?.as_f64()?, v.get(1)?.as_f64()?])
}

fn fmt_opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("-".into(), |x| format!("{x:.prec$}"))
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let header = format!(
            "{:<18} {:>6} {:>8} {:>9} {:>8} {:>8} {:>7} {:>15} {:>15} {:>6} {:>6} {:>6} {:>5} {:>15} {:>7}",
            "source",
            "hex",
            "n",
            "h_rmse_m",
            "h_p95_m",
            "v_rmse_m",
            "nees",
            "nees_95%",
            "batch_95%",
            "cont",
            "cont1k",
            "breaks",
            "false",
            "crb_m (ratio)",
            "vel_ms"
        );
        let line = |r: &Row| {
            format!(
                "{:<18} {:>6} {:>8} {:>9.2} {:>8.2} {:>8} {:>7} {:>15} {:>15} {:>6.3} {:>6.3} {:>6} {:>5} {:>15} {:>7}",
                r.source,
                if r.hex == "all" { format!("{} ac", r.aircraft) } else { r.hex.clone() },
                r.n,
                r.h_rmse_m,
                r.h_p95_m,
                fmt_opt(r.v_rmse_m, 2),
                fmt_opt(r.nees, 2),
                r.nees_band.map_or("-".into(), |b| format!("[{:.2}, {:.2}]", b[0], b[1])),
                r.nees_batch_band.map_or("-".into(), |b| format!("[{:.2}, {:.2}]", b[0], b[1])),
                r.continuity,
                r.continuity_1km,
                r.breaks,
                r.false_tracks,
                match (r.crb_m, r.crb_ratio) {
                    (Some(c), Some(k)) => format!("{c:.2} ({k:.2}x)"),
                    _ => "-".into(),
                },
                fmt_opt(r.vel_rmse_ms, 2)
            )
        };
        writeln!(f, "{header}")?;
        for r in &self.overall {
            writeln!(f, "{}", line(r))?;
        }
        if self.aircraft.len() > 1 {
            writeln!(f, "\nper aircraft:\n{header}")?;
            for r in &self.aircraft {
                writeln!(f, "{}", line(r))?;
            }
        }
        if let Some(c) = &self.fusion {
            let others: Vec<String> = c.others.iter().map(|(h, d)| format!("{h} +{d:.2} m")).collect();
            writeln!(
                f,
                "\nfused against the ADS-B and MLAT tracks over the span all three cover: lowest RMSE for {} of {} \
                 aircraft{}",
                c.fused_best,
                c.aircraft,
                if others.is_empty() { String::new() } else { format!(" (not: {})", others.join(", ")) }
            )?;
        }
        if !self.receivers.is_empty() {
            write!(
                f,
                "\nreceivers, learnt (the last receiver record) against true:\n{}",
                receivers::table(&self.receivers)
            )?;
        }
        if self.unknown_records > 0 {
            writeln!(f, "\n{} records for addresses not in the truth", self.unknown_records)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
