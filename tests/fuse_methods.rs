//! Every fusion method over Monte Carlo runs of the reweighted-convex-
//! combination benchmark (fusion-8seg-1hz; the full 100-seed table is in
//! docs/fusion.md, from `fuse1090 eval --scenario ... --seeds 100`). The default
//! (measurement fusion) must beat both single-source tracks with a NEES
//! inside a loose band; the published reweighted combination must show its
//! overconfidence.

use fuse1090::config::Config;
use fuse1090::eval::montecarlo::{monte_carlo, McRow, RunConfig};
use fuse1090::fuse::Method;
use fuse1090::sim::scenario::Scenario;

/// Monte Carlo runs of a committed scenario (seeds `seeds`), under the
/// default configuration or a committed one; the table goes to stderr.
fn runs(scenario: &str, config: Option<&str>, methods: &[Method], seeds: std::ops::Range<u64>) -> Vec<McRow> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scenario::load(&root.join(format!("fixtures/scenarios/{scenario}.toml"))).unwrap();
    let cfg = match config {
        Some(c) => Config::load(&root.join(format!("fixtures/configs/{c}.toml"))).unwrap(),
        None => Config::default(),
    };
    let known = cfg.known_receivers();
    let rows = monte_carlo(&s, RunConfig { core: &cfg.core, known: &known }, methods, seeds).unwrap();
    eprintln!("{}", fuse1090::eval::montecarlo::table(&rows));
    rows
}

/// The real binary, as a user runs it.
fn fuse1090() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_fuse1090"))
}

fn row<'a>(rows: &'a [McRow], source: &str) -> &'a McRow {
    rows.iter().find(|r| r.source == source).unwrap_or_else(|| panic!("no {source} row"))
}

#[test]
fn methods_on_the_8_segment_benchmark() {
    let rows = runs("fusion-8seg-1hz", None, &Method::ALL, 1..13);
    let (adsb, mlat, fused) = (row(&rows, "adsb"), row(&rows, "mlat"), row(&rows, "fused/measurement"));
    // The raw sources are what the paper used: 32.78 m and 12.65 m.
    assert!((row(&rows, "adsb-report").h_rmse_m - 32.78).abs() < 2.0);
    assert!((row(&rows, "mlat-fix").h_rmse_m - 12.65).abs() < 1.0);
    assert!(fused.h_rmse_m < mlat.h_rmse_m && fused.h_rmse_m < adsb.h_rmse_m);
    assert!(fused.h_rmse_m < 10.8, "{}", fused.h_rmse_m);
    let nees = fused.nees.unwrap();
    assert!((1.6..=2.5).contains(&nees), "measurement fusion NEES {nees}");
    for m in ["convex", "information", "ci"] {
        let r = row(&rows, &format!("fused/{m}"));
        assert!(r.h_rmse_m < adsb.h_rmse_m && r.nees.unwrap() < 3.5, "{m}: {r:?}");
    }
    // Reweighted: its covariance is smaller than any unbiased fusion can reach.
    assert!(row(&rows, "fused/reweighted").nees.unwrap() > 8.0);
}

#[test]
fn methods_on_the_8_segment_flight_at_real_rates() {
    // fusion-8seg: the same flight and sites, positions and velocity at 2 Hz,
    // every transmission multilaterated. Target of the fusion issue: 5 m.
    let rows =
        runs("fusion-8seg", Some("every-transmission"), &[Method::Measurement, Method::Reweighted], 1..13);
    let (adsb, mlat, fused) = (row(&rows, "adsb"), row(&rows, "mlat"), row(&rows, "fused/measurement"));
    assert!(fused.h_rmse_m < 5.0, "{}", fused.h_rmse_m);
    assert!(fused.h_rmse_m < 0.5 * mlat.h_rmse_m.min(adsb.h_rmse_m), "{fused:?} {mlat:?} {adsb:?}");
    let nees = fused.nees.unwrap();
    assert!((1.6..=2.5).contains(&nees), "measurement fusion NEES {nees}");
    // The per-epoch N-run test (one sample per run every 2 s): fused inside
    // on most epochs, the reweighted combination on almost none.
    assert!(fused.epochs_in_band.unwrap() >= 0.8, "{fused:?}");
    assert!(row(&rows, "fused/reweighted").epochs_in_band.unwrap() < 0.2);
}

/// The best RMSE a causal filter can expect on the 1 Hz benchmark if it is
/// told when each segment starts but not its acceleration: a constant-
/// acceleration filter whose acceleration covariance is reset at each switch
/// by the benchmark's typical jump, fed both sources at their true noise
/// (ADS-B 23.18 m per axis, MLAT 12.65 m horizontal RMS). Its covariance is
/// the exact mean square error under that model, so no Monte Carlo is needed.
#[test]
fn the_1hz_benchmark_bound_for_a_filter_told_the_segment_times() {
    use nalgebra::{Matrix2, Matrix2x6, Matrix6, Vector6};
    let r_adsb = 23.18f64.powi(2);
    let r_mlat = 12.65f64.powi(2) / 2.0;
    let r = Matrix2::identity() * (1.0 / (1.0 / r_adsb + 1.0 / r_mlat));
    // Jumps of the acceleration vector at the seven switches: 6, 6.9, 6.3,
    // 6.3, 7.0, 6, 3 m/s^2; RMS 6.1 m/s^2, i.e. 4.3 m/s^2 per axis.
    let jump_var = 4.3f64.powi(2);
    let mut f = Matrix6::identity();
    for i in 0..2 {
        f[(i, i + 2)] = 1.0;
        f[(i, i + 4)] = 0.5;
        f[(i + 2, i + 4)] = 1.0;
    }
    let h = Matrix2x6::new(1., 0., 0., 0., 0., 0., 0., 1., 0., 0., 0., 0.);
    let mut p = Matrix6::from_diagonal(&Vector6::new(r[(0, 0)], r[(0, 0)], 1e4, 1e4, jump_var, jump_var));
    let (mut sum, mut n) = (0.0, 0);
    for k in 1..80 {
        p = f * p * f.transpose();
        if k % 10 == 0 {
            p[(4, 4)] += jump_var;
            p[(5, 5)] += jump_var;
        }
        let s = h * p * h.transpose() + r;
        let gain = p * h.transpose() * s.try_inverse().unwrap();
        p = (Matrix6::identity() - gain * h) * p;
        if k >= 5 {
            sum += p[(0, 0)] + p[(1, 1)];
            n += 1;
        }
    }
    let rmse = (sum / n as f64).sqrt();
    eprintln!("bound for a filter told the segment times: {rmse:.2} m (paper: 8.85 m)");
    // The paper's figure is below what such a filter can honestly claim.
    assert!((8.9..9.6).contains(&rmse), "{rmse}");
}

/// Issue 5's consistency target on fusion-8seg: the default IMM's ADS-B-only
/// and MLAT-only tracks each keep a pooled mean NEES inside the band of 400
/// runs. The MLAT-only track, positions only at about 5 Hz, is the sensitive
/// one: with the current-statistical model's manoeuvre rate at 0.5/s it sat
/// at 2.06 against 1.98-2.02 (too slow to follow an acceleration onset).
#[test]
fn single_source_tracks_are_consistent_at_real_rates() {
    let rows = runs("fusion-8seg", Some("every-transmission"), &[Method::Measurement], 1..401);
    for source in ["adsb", "mlat"] {
        let r = row(&rows, source);
        let (nees, band) = (r.nees.unwrap(), r.nees_band.unwrap());
        assert!(band[0] <= nees && nees <= band[1], "{source}: NEES {nees} outside {band:?}");
    }
}

/// fusion-8seg-selfsync: free-running clocks synchronised on nothing but the
/// one aircraft's own ADS-B, every transmission multilaterated. A fix then
/// carries the aircraft's ADS-B errors back through the clocks, so it tells
/// a track that has the ADS-B next to nothing new: counted as news it made
/// the fused track worse than the ADS-B track alone and overconfident
/// (15.5 m against 10.7 m, NEES 39 over 100 seeds). Each fix's information
/// is now counted only for the share of its synchronisation learnt from
/// other aircraft.
#[test]
fn fixes_synchronised_on_their_own_aircraft_are_not_news_to_its_fused_track() {
    let rows = runs("fusion-8seg-selfsync", Some("every-transmission"), &[Method::Measurement], 1..13);
    let (adsb, fused) = (row(&rows, "adsb"), row(&rows, "fused/measurement"));
    assert!(fused.h_rmse_m < 1.05 * adsb.h_rmse_m, "{fused:?} {adsb:?}");
    assert!(fused.nees.unwrap() < 1.5 * adsb.nees.unwrap(), "{fused:?} {adsb:?}");
}

/// The IMM told the 1 Hz benchmark's own manoeuvres (turns at +-3 deg/s,
/// speed changes of exactly +-3 m/s^2; fixtures/configs/benchmark-
/// accelerations.toml) is what the paper's 8.85 m needs, and it must stay
/// consistent. It drifted to 9.01 m (NEES 2.08) unnoticed when a
/// transmission heard both ways became one IMM step: its staying
/// probability had been tuned for two.
#[test]
fn the_benchmark_model_set_stays_near_the_papers_figure() {
    let tuned = runs("fusion-8seg-1hz", Some("benchmark-accelerations"), &[Method::Measurement], 1..401);
    let default = runs("fusion-8seg-1hz", None, &[Method::Measurement], 1..401);
    let (t, d) = (row(&tuned, "fused/measurement"), row(&default, "fused/measurement"));
    // Over these 400 seeds (docs/fusion.md's): 8.93 m against the default's
    // 9.78 m; tuned for two steps, 9.01 m.
    assert!(t.h_rmse_m < 8.97 && t.h_rmse_m < d.h_rmse_m - 0.6, "{t:?} against {d:?}");
    let (nees, band) = (t.nees.unwrap(), t.nees_band.unwrap());
    assert!(band[0] <= nees && nees <= band[1], "{t:?}");
}

/// `eval --seeds N --first-seed S --method M` as a user runs it (the real
/// binary): seeds S..S+N with that method alone, the same pooled figures
/// as the library's Monte Carlo over those seeds and not those of seeds 1..=N.
#[test]
fn eval_runs_the_seeds_and_the_method_it_is_given() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = fuse1090()
        .args(["eval", "--scenario"])
        .arg(root.join("fixtures/scenarios/fusion-8seg-1hz.toml"))
        .args(["--seeds", "2", "--first-seed", "5", "--method", "ci", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    let fused: Vec<&str> =
        rows.iter().filter_map(|r| r["source"].as_str()).filter(|s| s.starts_with("fused")).collect();
    assert_eq!(fused, ["fused/ci"]);
    let cli = rows.iter().find(|r| r["source"] == "fused/ci").unwrap();
    assert_eq!(cli["seeds"], 2);
    let these = runs("fusion-8seg-1hz", None, &[Method::Ci], 5..7);
    let first = runs("fusion-8seg-1hz", None, &[Method::Ci], 1..3);
    let rmse = |rows: &[McRow]| row(rows, "fused/ci").h_rmse_m;
    assert!((cli["h_rmse_m"].as_f64().unwrap() - rmse(&these)).abs() < 1e-9);
    assert!((rmse(&these) - rmse(&first)).abs() > 1e-6);
    // Receivers described by the configuration (here the oracle `sim`
    // writes: every receiver's true timing) are known to every run, as
    // `run --config` makes them known: the fixes are no longer those of
    // receivers whose timing is learnt.
    let dir = tempfile::tempdir().unwrap();
    let sim = fuse1090()
        .args(["sim", "--scenario"])
        .arg(root.join("fixtures/scenarios/fusion-8seg-1hz.toml"))
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(sim.status.success(), "{}", String::from_utf8_lossy(&sim.stderr));
    let oracle = fuse1090::config::Config::load(&dir.path().join("oracle.toml")).unwrap();
    let known = oracle.known_receivers();
    assert!(known.iter().all(|k| k.timing.is_some()));
    let s = Scenario::load(&root.join("fixtures/scenarios/fusion-8seg-1hz.toml")).unwrap();
    let told = monte_carlo(&s, RunConfig { core: &oracle.core, known: &known }, &[Method::Ci], 5..7).unwrap();
    let fix_nees = |rows: &[McRow]| row(rows, "mlat-fix").nees.unwrap();
    assert!((fix_nees(&told) - fix_nees(&these)).abs() > 1e-6, "{} {}", fix_nees(&told), fix_nees(&these));
    // A method that does not exist is the operator's mistake, said as such.
    let bad = fuse1090()
        .args(["eval", "--scenario", "x.toml", "--seeds", "2", "--method", "average"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown fusion method \"average\""));
    let none = fuse1090().args(["eval", "--scenario", "x.toml", "--seeds", "0"]).output().unwrap();
    assert!(!none.status.success());
    assert!(String::from_utf8_lossy(&none.stderr).contains("--seeds must be at least 1"));
}
