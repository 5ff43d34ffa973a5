//! Comm-B inference against pyModeS 3.6.1, on pyModeS's own sample of real
//! DF20 and DF21 replies (`../shared/data/real/pymodes`), run through
//! `tests/pymodes/commb_reference.py` in the Python `.ci/run` sets up.
//!
//! - Where pyModeS names one register, we name the same one, or say why not
//!   (we call the reply ambiguous only where one of pyModeS's range limits
//!   is narrower than ours), and every field of an agreed register is
//!   pyModeS's value.
//! - Where pyModeS is left with candidates, a register we name must be one of
//!   them, and it is checked against the same aircraft's unambiguous replies
//!   within 60 s: of that register (selected altitude equal; track and ground
//!   speed, or heading and IAS, close), or between 5,0 and 6,0 (track and
//!   heading close).
//!
//! The table of agreements and disagreements is printed (`--nocapture`).

mod common;

use std::collections::BTreeMap;
use std::process::Command;

use common::{frames, python_with, shared_data};
use fuse1090::feed::InputFormat;
use fuse1090::modes::commb::registers;
use fuse1090::modes::json::DecodeRecord;
use fuse1090::modes::{Decoder, DecoderConfig};
use serde_json::Value;

const SETS: [&str; 2] =
    ["real/pymodes/sample_data_commb_df20.csv", "real/pymodes/sample_data_commb_df21.csv"];

/// pyModeS's verdict: one register, several, or none.
fn theirs(r: &Value) -> (Option<&str>, Vec<&str>) {
    let cands = r.get("candidates").and_then(Value::as_array);
    let cands: Vec<&str> = cands.into_iter().flatten().filter_map(Value::as_str).collect();
    let one = if cands.is_empty() { r["bds"].as_str() } else { None };
    (one, cands)
}

fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

/// Whether two replies of one aircraft, close in time, agree on what changes
/// slowly: a register's own fields, or between a track and turn report and a
/// heading and speed report, the track and the heading (wind correction and
/// magnetic variation apart).
fn neighbours_agree(bds: &str, a: &Value, b: &Value) -> bool {
    let f = |v: &Value, k: &str| v.get(k).and_then(Value::as_f64);
    let other = b.get("bds").and_then(Value::as_str);
    if matches!((bds, other), ("5,0", Some("6,0")) | ("6,0", Some("5,0"))) {
        let direction = |v: &Value| f(v, "track").or(f(v, "mag_heading"));
        return direction(a).zip(direction(b)).is_some_and(|(x, y)| angle_diff(x, y) <= 35.0);
    }
    match bds {
        "4,0" => a.get("nav_altitude_mcp") == b.get("nav_altitude_mcp"),
        "5,0" => match (f(a, "track"), f(b, "track"), f(a, "gs"), f(b, "gs")) {
            (Some(t1), Some(t2), Some(g1), Some(g2)) => angle_diff(t1, t2) <= 30.0 && (g1 - g2).abs() <= 40.0,
            _ => false,
        },
        "6,0" => match (f(a, "mag_heading"), f(b, "mag_heading"), f(a, "ias"), f(b, "ias")) {
            (Some(h1), Some(h2), Some(i1), Some(i2)) => angle_diff(h1, h2) <= 30.0 && (i1 - i2).abs() <= 30.0,
            _ => false,
        },
        _ => false,
    }
}

/// Why we leave open a reply pyModeS names, when one of its range limits is
/// narrower than ours (roll 35 deg against 50, TAS-GS 200 kt against 250).
fn narrower_pymodes_limit(frame: &str, named: &str, ours: &[&str]) -> Option<String> {
    let mb = u64::from_str_radix(&frame[8..22], 16).ok()?;
    let other = ours.iter().find(|&&b| b != named)?;
    if *other != "5,0" {
        return None;
    }
    let r = registers::bds50(mb)?;
    let roll = r.roll_deg.map(f64::abs).unwrap_or(0.0);
    let wind = r.gs_kt.zip(r.tas_kt).map(|(g, a)| g.abs_diff(a)).unwrap_or(0);
    (roll > 35.0 || wind > 200).then(|| format!("5,0 fits with roll {roll:.0} deg, |TAS-GS| {wind} kt"))
}

#[test]
fn commb_inference_agrees_with_pymodes() {
    let Some(py) = python_with("pyModeS", "Comm-B inference not compared with pyModeS") else { return };
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/pymodes/commb_reference.py");
    for set in SETS {
        let Some(csv) = shared_data(set) else { return };
        let out = Command::new(&py).arg(&script).arg(&csv).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let reference: Vec<Value> = String::from_utf8(out.stdout)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        let hex: String = reference.iter().map(|r| format!("{}\n", r["frame"].as_str().unwrap())).collect();
        let mut decoder = Decoder::new(DecoderConfig::default());
        let ours: Vec<Value> = frames(hex.as_bytes(), InputFormat::Hex)
            .iter()
            .map(|(_, f)| {
                serde_json::to_value(DecodeRecord::new(&decoder.decode(f, 0.0).unwrap(), f)).unwrap()
            })
            .collect();
        assert_eq!(ours.len(), reference.len(), "{set}: one record per reply");

        let mut table = BTreeMap::<String, usize>::new();
        let (mut named, mut agreed, mut fields) = (0, 0, 0);
        let (mut resolved, mut confirmed, mut unconfirmed, mut lonely) = (0, 0, 0, 0);
        for (i, (r, o)) in reference.iter().zip(&ours).enumerate() {
            let (one, cands) = theirs(r);
            let our = o.get("bds").and_then(Value::as_str);
            let our_cands: Vec<&str> = o
                .get("bds_candidates")
                .and_then(Value::as_array)
                .into_iter()
                .flatten()
                .filter_map(Value::as_str)
                .collect();
            let row = match (one, our) {
                (Some(b), Some(ob)) if b == ob => {
                    named += 1;
                    agreed += 1;
                    for (k, v) in r["fields"].as_object().unwrap() {
                        let (theirs, ours) = (v.as_f64(), o.get(k).and_then(Value::as_f64));
                        let same = match (theirs, ours) {
                            (Some(a), Some(b)) => {
                                (a - b).abs() <= 0.006
                                    || (k.contains("track") || k.contains("heading"))
                                        && angle_diff(a, b) <= 0.006
                            }
                            _ => v.as_str().is_some() && o.get(k) == Some(v),
                        };
                        assert!(same, "{set} row {i} ({b}): {k} ours {:?}, pyModeS {v}", o.get(k));
                        fields += 1;
                    }
                    format!("agree: {b}")
                }
                (Some(b), Some("ambiguous")) if our_cands.contains(&b) => {
                    named += 1;
                    let why = narrower_pymodes_limit(r["frame"].as_str().unwrap(), b, &our_cands);
                    let why = why.unwrap_or_else(|| panic!("{set} row {i}: pyModeS {b}, ours {our_cands:?}"));
                    println!("  row {i}: pyModeS {b}, ours ambiguous {our_cands:?}: {why}");
                    format!("pyModeS {b}, ours ambiguous {our_cands:?} (pyModeS's narrower range)")
                }
                (Some(b), ob) => panic!("{set} row {i}: pyModeS {b}, ours {ob:?} {our_cands:?}"),
                (None, Some("ambiguous")) => format!("both ambiguous: pyModeS {cands:?}, ours {our_cands:?}"),
                (None, Some(ob)) => {
                    assert!(cands.contains(&ob), "{set} row {i}: pyModeS {cands:?} or none, ours {ob}");
                    resolved += 1;
                    let t = r["t"].as_i64().unwrap();
                    let near: Vec<&Value> = reference
                        .iter()
                        .zip(&ours)
                        .filter(|(r2, o2)| {
                            r2["hex"] == r["hex"]
                                && (r2["t"].as_i64().unwrap() - t).abs() <= 60
                                && theirs(r2).0.is_some_and(|b| {
                                    b == ob || matches!((b, ob), ("5,0", "6,0") | ("6,0", "5,0"))
                                })
                                && o2.get("bds").and_then(Value::as_str) == theirs(r2).0
                        })
                        .map(|(_, o2)| o2)
                        .collect();
                    if near.is_empty() {
                        lonely += 1;
                    } else if near.iter().any(|n| neighbours_agree(ob, o, n)) {
                        confirmed += 1;
                    } else {
                        unconfirmed += 1;
                        println!("  row {i}: resolved {ob} of {cands:?}, unlike its neighbours: {o}");
                    }
                    format!("pyModeS {cands:?}, ours {ob}")
                }
                (None, None) => "neither names a register".to_string(),
            };
            *table.entry(row).or_default() += 1;
        }
        println!("{set}: {} replies", reference.len());
        for (row, n) in &table {
            println!("  {n:>5}  {row}");
        }
        println!(
            "  named by pyModeS {named}, the same register {agreed} ({:.2}%), {fields} fields equal; \
             resolved {resolved} of pyModeS's ambiguous: {confirmed} confirmed by neighbours, \
             {unconfirmed} unlike them, {lonely} without one",
            100.0 * agreed as f64 / named as f64
        );
        assert!(agreed as f64 >= 0.99 * named as f64, "{set}: {agreed} of {named}");
        assert!(resolved > 0 && unconfirmed as f64 <= 0.05 * (confirmed + unconfirmed) as f64, "{set}");
    }
}
