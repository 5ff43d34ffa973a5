//! Multilateration on real data: LocaRDS (OpenSky sensors, GPS-timed), each
//! transmission a DF4 reply heard by five sensors, scored against the
//! aircraft's own ADS-B position.
//!
//! That reference is the aircraft's latest ADS-B position when the reply was
//! received, not its position at the reply: it lags by up to about a second.
//! The worst errors are almost all along-track with the fix ahead of the
//! reference, so covariance honesty is judged across track, where the lag
//! does not reach; the full-ellipse figure is printed for the record.
//!
//! The sets hold 23 rows twice (same aircraft, time, frame and sensors):
//! a transmission is counted once.

mod common;

use std::collections::HashMap;

use common::{en, mahalanobis2, run_core, shared_data};
use fuse1090::core::{CoreConfig, Event};
use fuse1090::geo::geodetic_to_ecef;
use fuse1090::mlat::solver::{solve, AltitudeConstraint, Measurement, SolverLimits};
use serde_json::Value;

/// One transmission of the reference: aircraft, arrival time, position.
#[derive(Clone)]
struct Transmission {
    id: u64,
    hex: String,
    frame: String,
    t: f64,
    lat: f64,
    lon: f64,
}

/// One fix to score: time, position, horizontal covariance.
#[derive(Clone)]
struct Scored {
    t: f64,
    lat: f64,
    lon: f64,
    cov_en: [[f64; 2]; 2],
}

#[derive(Debug)]
struct Figures {
    /// Share of transmissions with a fix, median and 90th percentile error
    /// (m), share inside their 95% ellipse, share within 1.96 sigma across
    /// track, mean along-track error (m).
    rate: f64,
    median: f64,
    p90: f64,
    inside: f64,
    cross: f64,
    along: f64,
}

impl Figures {
    fn row(&self, name: &str) -> String {
        format!(
            "{name:<44} {:>6.1}% {:>7.1} m {:>7.1} m {:>6.1}% {:>6.1}% {:>+6.1} m",
            100.0 * self.rate,
            self.median,
            self.p90,
            100.0 * self.inside,
            100.0 * self.cross,
            self.along
        )
    }

    /// What holds on any of the sets, in any order: fixes for 97% of
    /// transmissions, 90% within 1.96 sigma across track (the issue's
    /// targets), and a median below the peer's on the same transmissions.
    /// (The 40 m median is of all four sets: sets 1 and 3 are
    /// harder than 2 and 4, in the run over all four as much as alone.)
    fn hold(&self, peer: &Figures) -> bool {
        self.rate >= 0.97 && self.cross >= 0.90 && self.median < peer.median
    }
}

/// Scores fixes (by aircraft) against the reference: each transmission
/// takes the nearest unused fix of its aircraft within 20 ms of emission.
fn score(truth: &[Transmission], mut fixes: HashMap<String, Vec<(Scored, bool)>>) -> Figures {
    let mut by_hex: HashMap<&str, Vec<&Transmission>> = HashMap::new();
    for t in truth {
        by_hex.entry(&t.hex).or_default().push(t);
    }
    let (mut errs, mut inside, mut cross_ok, mut cross_n, mut along_sum) = (Vec::new(), 0, 0, 0, 0.0);
    for t in truth {
        let emitted = t.t - 0.1;
        let Some(slot) = fixes.get_mut(&t.hex).and_then(|v| {
            v.iter_mut()
                .filter(|(f, used)| !used && (f.t - emitted).abs() < 0.02)
                .min_by(|a, b| (a.0.t - emitted).abs().total_cmp(&(b.0.t - emitted).abs()))
        }) else {
            continue;
        };
        slot.1 = true;
        let f = &slot.0;
        let e = en(t.lat, t.lon, f.lat, f.lon);
        errs.push(e[0].hypot(e[1]));
        inside += (mahalanobis2(e, f.cov_en) <= 5.991) as usize;
        // Direction of flight from the nearest other reference point of the aircraft.
        let other = by_hex[t.hex.as_str()]
            .iter()
            .filter(|o| (2.0..60.0).contains(&(o.t - t.t).abs()))
            .min_by(|a, b| (a.t - t.t).abs().total_cmp(&(b.t - t.t).abs()));
        if let Some(o) = other {
            let sign = if o.t > t.t { 1.0 } else { -1.0 };
            let d = en(t.lat, t.lon, o.lat, o.lon);
            let n = d[0].hypot(d[1]);
            if n > 0.0 {
                let u = [sign * d[0] / n, sign * d[1] / n];
                let c = [-u[1], u[0]];
                let cov = f.cov_en;
                let var_c = c[0] * c[0] * cov[0][0] + 2.0 * c[0] * c[1] * cov[0][1] + c[1] * c[1] * cov[1][1];
                cross_n += 1;
                cross_ok += ((e[0] * c[0] + e[1] * c[1]).abs() <= 1.96 * var_c.sqrt()) as usize;
                along_sum += e[0] * u[0] + e[1] * u[1];
            }
        }
    }
    errs.sort_by(f64::total_cmp);
    let n = errs.len();
    Figures {
        rate: n as f64 / truth.len() as f64,
        median: errs[n / 2],
        p90: errs[n * 9 / 10],
        inside: inside as f64 / n as f64,
        cross: cross_ok as f64 / cross_n as f64,
        along: along_sum / cross_n as f64,
    }
}

/// fuse1090's fixes of a capture, by aircraft.
fn run(capture: &[u8]) -> HashMap<String, Vec<(Scored, bool)>> {
    let (_, events, _) = run_core(capture, &CoreConfig::default());
    let mut fixes: HashMap<String, Vec<(Scored, bool)>> = HashMap::new();
    for e in &events {
        if let Event::Mlat(f) = e {
            let s = Scored { t: f.t, lat: f.lat, lon: f.lon, cov_en: f.cov_en };
            fixes.entry(format!("{:06X}", f.addr)).or_default().push((s, false));
        }
    }
    fixes
}

/// The reference, each transmission once, with the set (1-4) it is in.
fn reference(truth: &str, sets: &[String]) -> Vec<(Transmission, usize)> {
    let set_of: HashMap<u64, usize> = (sets.iter().enumerate())
        .flat_map(|(k, text)| {
            text.lines().skip(1).map(move |l| (l.split(',').next().unwrap().parse().unwrap(), k + 1))
        })
        .collect();
    let mut out: Vec<(Transmission, usize)> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for l in truth.lines() {
        let v: Value = serde_json::from_str(l).unwrap();
        let key = (v["hex"].to_string(), v["t"].to_string(), v["frame"].to_string());
        if !seen.insert(key) {
            continue;
        }
        let t = Transmission {
            id: v["id"].as_u64().unwrap(),
            hex: v["hex"].as_str().unwrap().to_string(),
            frame: v["frame"].as_str().unwrap().to_string(),
            t: v["t"].as_f64().unwrap(),
            lat: v["lat"].as_f64().unwrap(),
            lon: v["lon"].as_f64().unwrap(),
        };
        out.push((t, set_of[&v["id"].as_u64().unwrap()]));
    }
    out
}

/// The capture and reference of some sets only, in the order given, each
/// set an hour after the previous one (each spans an hour; host time and
/// the GPS timestamps' second of day move alike).
fn reorder(
    capture: &str,
    reference: &[(Transmission, usize)],
    order: &[usize],
) -> (Vec<u8>, Vec<Transmission>) {
    let shift = |set: usize| 3600.0 * order.iter().position(|&s| s == set).unwrap() as f64;
    let mut by_frame: HashMap<&str, Vec<(f64, usize)>> = HashMap::new();
    for (t, set) in reference {
        by_frame.entry(t.frame.as_str()).or_default().push((t.t, *set));
    }
    let mut text = String::new();
    let mut lines: Vec<(f64, String)> = Vec::new();
    for l in capture.lines() {
        let fields: Vec<&str> = l.split(' ').collect();
        let Ok(arrival) = fields[0].parse::<f64>() else {
            text.push_str(l);
            text.push('\n');
            continue;
        };
        // A line is its transmission's whose frame it carries, received in
        // the few milliseconds after its arrival time (one a millisecond).
        let beast = fields[2].trim_start_matches('<').trim_end_matches(';');
        let set =
            by_frame[&beast[14..]].iter().find(|(t, _)| (-0.001..0.02).contains(&(arrival - t))).unwrap().1;
        if !order.contains(&set) {
            continue;
        }
        let dt = shift(set);
        let ts = u64::from_str_radix(&beast[..12], 16).unwrap() + ((dt as u64) << 30);
        lines.push((arrival + dt, format!("{:.6} {} <{ts:012X}{};", arrival + dt, fields[1], &beast[12..])));
    }
    lines.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (_, l) in lines {
        text.push_str(&l);
        text.push('\n');
    }
    let truth = (reference.iter())
        .filter(|(_, s)| order.contains(s))
        .map(|(t, s)| Transmission { t: t.t + shift(*s), ..t.clone() })
        .collect();
    (text.into_bytes(), truth)
}

/// The peer: a plain least-squares fix of each transmission from its row
/// of the sets, every sensor at the fixed 50 ns, with the row's
/// barometric altitude (75 m: a plain solver does not know its difference
/// from the geometric one), no outlier handling; its covariance is the
/// solver's.
fn peer(sets: &[String], sensors: &str, reference: &[(Transmission, usize)]) -> Figures {
    let sensors: HashMap<&str, [f64; 3]> = (sensors.lines().skip(1))
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0], geodetic_to_ecef(f[1].parse().unwrap(), f[2].parse().unwrap(), f[3].parse().unwrap()))
        })
        .collect();
    let rows: HashMap<u64, &str> = (sets.iter().flat_map(|s| s.lines().skip(1)))
        .map(|l| (l.split(',').next().unwrap().parse().unwrap(), l))
        .collect();
    let limits = SolverLimits { chi2_reject: false, ..SolverLimits::default() };
    let mut fixes: HashMap<String, Vec<(Scored, bool)>> = HashMap::new();
    for (t, _) in reference {
        let row = rows[&t.id];
        let baro_m: f64 = row.split(',').nth(5).unwrap().parse().unwrap();
        let list: Vec<Vec<f64>> = serde_json::from_str(row.split('"').nth(1).unwrap()).unwrap();
        let ms: Vec<Measurement> = (list.iter())
            .map(|m| Measurement { pos: sensors[m[0].to_string().as_str()], t: m[1] * 1e-9, sigma_t: 50e-9 })
            .collect();
        let alt = AltitudeConstraint { h_m: baro_m, sigma_m: 75.0 };
        if let Ok(f) = solve(&ms, Some(alt), None, &limits) {
            let s = Scored { t: t.t - 0.1, lat: f.lat, lon: f.lon, cov_en: f.cov_en };
            fixes.entry(t.hex.clone()).or_default().push((s, false));
        }
    }
    let truth: Vec<Transmission> = reference.iter().map(|(t, _)| t.clone()).collect();
    score(&truth, fixes)
}

#[test]
fn locards_fixes_are_accurate_their_covariance_honest_and_nothing_is_fitted_to_them() {
    let dir = "real/locards/";
    let Some(cap) = shared_data(&format!("{dir}capture_set_1-4.txt")) else { return };
    let read = |name: &str| std::fs::read_to_string(shared_data(&format!("{dir}{name}")).unwrap()).unwrap();
    let capture = std::fs::read_to_string(cap).unwrap();
    let sets: Vec<String> = (1..=4).map(|k| read(&format!("set_{k}.csv"))).collect();
    let sensors = read("sensors.csv");
    let reference = reference(&read("truth_set_1-4.jsonl"), &sets);
    let of = |chosen: &[usize]| -> Vec<(Transmission, usize)> {
        reference.iter().filter(|(_, s)| chosen.contains(s)).cloned().collect()
    };
    let truth =
        |r: &[(Transmission, usize)]| -> Vec<Transmission> { r.iter().map(|(t, _)| t.clone()).collect() };
    let full = run(capture.as_bytes());
    let ours = score(&truth(&reference), full.clone());
    let peer_all = peer(&sets, &sensors, &reference);
    let reversed = {
        let (cap, t) = reorder(&capture, &reference, &[4, 3, 2, 1]);
        score(&t, run(&cap))
    };
    // No constant fitted to these sets: each half run on its own, from
    // nothing learnt, does as well as the run over all four did on the same
    // transmissions, and better than the peer on them.
    let halves: Vec<Half> = [[1, 3], [2, 4]]
        .into_iter()
        .map(|half| {
            let (cap, t) = reorder(&capture, &reference, &half);
            Half {
                name: format!("sets {}, {}", half[0], half[1]),
                alone: score(&t, run(&cap)),
                within: score(&truth(&of(&half)), full.clone()),
                peer: peer(&sets, &sensors, &of(&half)),
            }
        })
        .collect();
    let mut table = format!(
        "LocaRDS sets 1-4, {} transmissions:\n{:<44} {:>7} {:>9} {:>9} {:>7} {:>7} {:>8}\n",
        reference.len(),
        "",
        "fixes",
        "median",
        "p90",
        "in 95%",
        "across",
        "along"
    );
    table += &(ours.row("fuse1090") + "\n");
    table += &(reversed.row("fuse1090, sets 4, 3, 2, 1") + "\n");
    table += &(peer_all.row("peer: plain least squares, 50 ns") + "\n");
    // Measured with this scorer on the build before issue 35 (78fe8f1).
    table += &format!(
        "{:<44} {:>6.1}% {:>7.1} m {:>7.1} m {:>7} {:>6.1}%\n",
        "before issue 35 (recorded)", 97.7, 39.7, 185.0, "-", 88.8
    );
    for h in &halves {
        table += &(h.alone.row(&format!("fuse1090, {} alone", h.name)) + "\n");
        table += &(h.within.row(&format!("fuse1090, {} within sets 1-4", h.name)) + "\n");
        table += &(h.peer.row(&format!("peer, {}", h.name)) + "\n");
    }
    eprintln!("{table}");
    assert!(ours.hold(&peer_all) && ours.median <= 40.0, "{table}");
    assert!(reversed.hold(&peer_all) && reversed.median <= 40.0, "{table}");
    for h in &halves {
        assert!(h.alone.hold(&h.peer), "{}: {table}", h.name);
        // Within a tenth: alone, a half has half the traffic to learn the
        // receivers' timing and the barometric difference from.
        assert!(h.alone.median <= 1.1 * h.within.median, "{}: {table}", h.name);
    }
    // The fixes lead the stale reference along track, by tens of metres on average.
    assert!(ours.along > 20.0, "{table}");
}

/// Half of the sets: run on their own, the same transmissions in the run
/// over all four, and the peer on them.
struct Half {
    name: String,
    alone: Figures,
    within: Figures,
    peer: Figures,
}
