//! The `decode` command as a user runs it: the real binary, files and stdin.

mod common;

use std::io::Write;
use std::process::{Command, Stdio};

use common::shared_data;

fn fuse1090() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fuse1090"))
}

#[test]
fn decodes_the_real_beast_capture_to_json_lines() {
    let Some(path) = shared_data("real/beastblackbox/ulss7-beast-bin-utc--1522782148.136310917--.log") else {
        return;
    };
    let out = fuse1090().arg("decode").arg(&path).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 8_928);
    // Contract: absent, never null; hex is six upper-case digits.
    for v in &lines {
        let obj = v.as_object().unwrap();
        assert!(obj.values().all(|x| !x.is_null()));
        let hex = obj["hex"].as_str().unwrap();
        assert!(hex.len() == 6 && hex.chars().all(|c| c.is_ascii_hexdigit() && !c.is_ascii_lowercase()));
        for key in ["df", "crc_ok", "frame", "ts", "signal"] {
            assert!(obj.contains_key(key), "{key} missing in {v}");
        }
    }
    let with_pos = lines.iter().filter(|v| v.get("lat").is_some()).count();
    assert!(with_pos >= 1_366, "{with_pos}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("8928 Mode S"), "{stderr}");
}

#[test]
fn decodes_avr_from_stdin_with_format_detection() {
    let fixture =
        std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/frames/published.avr")).unwrap();
    let mut child = fuse1090()
        .args(["decode", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(&fixture).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let lines: Vec<serde_json::Value> =
        String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 9);
    assert_eq!(lines[0]["flight"], "KLM1023");
    assert_eq!(lines[0]["category"], "A0");
    // The KLM pair decodes, but one global decode is not yet published.
    assert_eq!(lines[2]["cpr"], "odd");
    assert!(lines[2].get("lat").is_none());
    assert_eq!(lines[3]["gs"], 159.2);
    assert_eq!(lines[3]["geom_rate"], -832);
    assert!(lines[3].get("baro_rate").is_none());
    assert_eq!(lines[4]["tas"], 375);
    assert_eq!(lines[4]["mag_heading"], 243.98);
    assert_eq!(lines[4]["baro_rate"], -2304);
    assert_eq!((lines[5]["nac_p"].as_u64(), lines[5]["sil"].as_u64()), (Some(9), Some(3)));
    assert_eq!(lines[6]["squawk"], "1017");
    assert_eq!((lines[7]["df"].as_u64(), lines[7]["crc_ok"].as_bool()), (Some(11), Some(true)));
    // DF0 from an address no verified frame named: decoded, but not trusted.
    assert_eq!((lines[8]["alt_baro"].as_i64(), lines[8]["crc_ok"].as_bool()), (Some(31000), Some(false)));
}

#[test]
fn surface_positions_with_a_reference() {
    use fuse1090::modes::cpr::encode;
    use fuse1090::modes::encode::{df17, me_surface_position};
    let mut text = String::new();
    for (k, lat) in [43.6290, 43.6291, 43.6292].iter().enumerate() {
        let f = df17(
            5,
            0x39AC45,
            me_surface_position(7, 12, Some(270.0), encode(*lat, 1.3638, k % 2 == 1, true)),
        );
        text += &format!("{}.0 {}\n", 1000 + k, fuse1090::feed::RawFrame::new(&f, 0, 0).unwrap().hex());
    }
    let work = common::scratch("cli");
    let dir = work.path();
    let path = dir.join("surface.txt");
    std::fs::write(&path, text).unwrap();
    let out = fuse1090()
        .args(["decode", "--format", "hex", "--reference", "43.6,1.4"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(out.status.success());
    let last: serde_json::Value =
        serde_json::from_str(String::from_utf8(out.stdout).unwrap().lines().last().unwrap()).unwrap();
    assert_eq!(last["surface"], true);
    assert!((last["lat"].as_f64().unwrap() - 43.6292).abs() < 1e-4, "{last}");
    assert!((last["lon"].as_f64().unwrap() - 1.3638).abs() < 1e-4, "{last}");
    assert_eq!(last["track"], 270.0);
}

#[test]
fn refuses_data_that_is_not_mode_s() {
    let out = fuse1090().args(["decode", "Cargo.toml"]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("not Mode S data"), "{err}");

    let out = fuse1090().args(["decode", "no/such/file"]).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot open"));

    // Forced format, but nothing in it decodes.
    let out = fuse1090().args(["decode", "--format", "beast", "Cargo.toml"]).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no Mode S frames"));

    let out = fuse1090().args(["decode", "--reference", "95,0", "-"]).output().unwrap();
    assert!(!out.status.success());
}
