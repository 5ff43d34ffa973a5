//! fuse1090 on several machines: NATS JetStream carries the work, each piece
//! of it done once.
//!
//! ```text
//!  receivers ─▶ ingest ──frames.<p>──▶ worker (partitions p..) ──events.<p>──▶ publisher ─▶ outputs
//!                                        │  ▲                                    (conflicts across
//!                                  sync.<p>  clock KV "snapshot"                  partitions)
//!                                        ▼  │
//!                                        clock (one ClockSync for the network)
//! ```
//!
//! - **ingest** puts every frame on the subject of its aircraft's partition
//!   (the address, recovered from the parity where it is not in clear, so
//!   every receiver's copy of a transmission lands in the same partition),
//!   in batches of `batch_s` of data time; every partition gets a batch each
//!   period, empty or not, so each knows how far time has gone.
//! - **worker** claims partitions (a KV key per partition, created only if
//!   absent and refreshed with its revision: two workers cannot hold one),
//!   and runs the same sans-IO [`Core`](crate::core::Core) per partition as
//!   one node does, with clock synchronisation shared ([`crate::mlat::shared`]).
//!   A batch is acknowledged once its events and sync notes are stored, so a
//!   worker that dies loses nothing: the next owner takes the partition's
//!   unacknowledged batches, and its republished events are dropped by
//!   their message ids. Track numbers are checkpointed per partition.
//! - **clock** applies every worker's sync notes in data-time order, up to
//!   the time every partition has reached, and stores the result as a
//!   snapshot that the workers load; a worker does not process a batch more
//!   than `clock_lag_s` ahead of the snapshot.
//! - **publisher** writes the events out and runs conflict prediction over
//!   all partitions' tracks (the workers do not).
//!
//! The format of what travels is in [`wire`]; the subjects and buckets are
//! named from `name` ([`Names`]). See docs/cluster.md.

mod claims;
pub mod clock;
mod consume;
pub mod ingest;
pub mod outage;
pub mod publisher;
pub mod wire;
pub mod worker;

use std::path::Path;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use async_nats::jetstream::{self, kv, stream};
use serde::{Deserialize, Serialize};

use crate::config::Config;
use crate::problem::{positive, Problem};

/// What a process does in the cluster.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    Ingest,
    Worker,
    Clock,
    Publisher,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClusterConfig {
    /// The NATS server (JetStream enabled).
    pub url: String,
    /// Prefix of every stream, subject and bucket: two clusters on one NATS
    /// server need two names.
    pub name: String,
    /// How many partitions the aircraft are spread over (fixed for a
    /// cluster's life: more than workers, so that a lost worker's share
    /// spreads over the others).
    pub partitions: u32,
    /// What this process does.
    pub roles: Vec<Role>,
    /// This worker's name (unique in the cluster); the host name and
    /// process id when absent.
    pub worker_id: Option<String>,
    /// Data time per frame batch (s).
    pub batch_s: f64,
    /// How far a worker may run ahead of the clock snapshot (s; at least
    /// two batches).
    pub clock_lag_s: f64,
    /// A partition whose worker has not renewed its claim for this long
    /// (s) is taken over.
    pub lease_s: f64,
    /// How often a worker stores its partitions' track numbers (s of data time).
    pub checkpoint_s: f64,
    /// The frame stream's bound (bytes): the oldest frames go first.
    pub max_stream_bytes: i64,
}

impl Default for ClusterConfig {
    fn default() -> Self {
        ClusterConfig {
            url: "nats://127.0.0.1:4222".into(),
            name: "fuse1090".into(),
            partitions: 12,
            roles: vec![Role::Ingest, Role::Worker, Role::Clock, Role::Publisher],
            worker_id: None,
            batch_s: 0.1,
            clock_lag_s: 0.3,
            lease_s: 3.0,
            checkpoint_s: 5.0,
            max_stream_bytes: 1 << 30,
        }
    }
}

impl ClusterConfig {
    /// Every problem of `[cluster]`.
    pub fn validate(&self) -> Vec<Problem> {
        let at = |message: String| Problem::at("cluster", message);
        let mut errs = Vec::new();
        if !(1..=4096).contains(&self.partitions) {
            errs.push(at(format!("partitions = {} must be in 1..=4096", self.partitions)));
        }
        if self.roles.is_empty() {
            errs.push(at("roles must name at least one of ingest, worker, clock, publisher".into()));
        }
        if !(self.batch_s > 0.0 && self.batch_s <= 1.0) {
            errs.push(at(format!("batch_s = {} must be in (0, 1]", self.batch_s)));
        }
        if !(self.clock_lag_s >= 2.0 * self.batch_s && self.clock_lag_s <= 10.0) {
            errs.push(at(format!("clock_lag_s = {} must be in [2 batch_s, 10]", self.clock_lag_s)));
        }
        if !(self.lease_s >= 1.0 && self.lease_s <= 60.0) {
            errs.push(at(format!("lease_s = {} must be in [1, 60]", self.lease_s)));
        }
        positive("cluster", &[("checkpoint_s", self.checkpoint_s)], &mut errs);
        if self.max_stream_bytes < 1 << 20 {
            errs.push(at(format!("max_stream_bytes = {} must be at least 1 MiB", self.max_stream_bytes)));
        }
        if !self.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            || self.name.is_empty()
        {
            errs.push(at(format!("name = {:?} may hold letters, digits, '-' and '_' only", self.name)));
        }
        errs
    }

    pub fn has(&self, role: Role) -> bool {
        self.roles.contains(&role)
    }
}

/// The cluster's subjects, streams and buckets.
#[derive(Clone, Debug)]
pub struct Names {
    pub name: String,
}

impl Names {
    fn stream(&self, what: &str) -> String {
        format!("{}_{what}", self.name.to_uppercase().replace('-', "_"))
    }
    pub fn frames(&self, p: u32) -> String {
        format!("{}.frames.{p}", self.name)
    }
    pub fn receivers(&self) -> String {
        format!("{}.receivers", self.name)
    }
    pub fn events(&self, p: u32) -> String {
        format!("{}.events.{p}", self.name)
    }

    /// The clock's receiver records, beside the partitions' events.
    pub fn clock_records(&self) -> String {
        format!("{}.events.{CLOCK_RECORDS}", self.name)
    }
    pub fn sync(&self, p: u32) -> String {
        format!("{}.sync.{p}", self.name)
    }
    pub fn bucket(&self, what: &str) -> String {
        format!("{}-{what}", self.name)
    }
}

/// The last token of the clock's receiver records' subject.
pub const CLOCK_RECORDS: &str = "clock";

/// Message headers the roles read.
pub mod header {
    /// The data time a batch runs to (s).
    pub const TIME: &str = "Fuse1090-Time";
    /// How many receivers had been declared when the batch was made.
    pub const RECEIVERS: &str = "Fuse1090-Receivers";
    /// The last batch of a partition (a replay's end).
    pub const END: &str = "Fuse1090-End";
    /// How many frames the batch of events came from.
    pub const FRAMES: &str = "Fuse1090-Frames";
}

/// How far each partition's batches have come, for a stage that waits for
/// all of them (the clock, the publisher). A partition that has ended holds
/// nobody back.
///
/// A batch may come after a later one of its partition: a worker's store
/// that NATS lost is sent again after the ones its client kept through
/// the outage. So what was taken is remembered by batch time over
/// [`REORDER_WINDOW_S`], not only as the newest time, and a late batch
/// never taken is taken.
pub struct Watermarks {
    at: Vec<f64>,
    ended: Vec<bool>,
    /// The times of the batches taken lately, per partition (as bits: the
    /// times are positive, so their bits sort as they do).
    taken: Vec<std::collections::BTreeSet<u64>>,
}

/// How far (s of data time) behind its partition's newest a batch may come
/// and still be taken; older ones are taken to be replays. A reordering by
/// an outage spans the batches in flight, a few seconds of data at most.
pub const REORDER_WINDOW_S: f64 = 60.0;

/// What a partition's batch is to the stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mark {
    /// Beyond the time the partition had reached: taken.
    New,
    /// At or below it: a replay after a takeover, already taken once.
    Replayed,
    /// No such partition.
    Unknown,
}

impl Watermarks {
    pub fn new(partitions: u32) -> Self {
        Watermarks {
            at: vec![f64::NEG_INFINITY; partitions as usize],
            ended: vec![false; partitions as usize],
            taken: vec![Default::default(); partitions as usize],
        }
    }

    /// Partition `p`'s batch running to `t` (its last when `end`).
    pub fn mark(&mut self, p: usize, t: f64, end: bool) -> Mark {
        let (Some(at), Some(taken)) = (self.at.get_mut(p), self.taken.get_mut(p)) else {
            return Mark::Unknown;
        };
        if t <= *at - REORDER_WINDOW_S || !taken.insert(t.to_bits()) {
            return Mark::Replayed;
        }
        *at = at.max(t);
        let floor = (*at - REORDER_WINDOW_S).max(0.0).to_bits();
        while taken.first().is_some_and(|&b| b < floor) {
            taken.pop_first();
        }
        self.ended[p] |= end;
        Mark::New
    }

    /// The time every partition still running has reached (infinite once all have ended).
    pub fn common(&self) -> f64 {
        (self.at.iter().zip(&self.ended)).filter(|(_, &e)| !e).map(|(&w, _)| w).fold(f64::INFINITY, f64::min)
    }

    /// The furthest any partition has reached.
    pub fn newest(&self) -> f64 {
        self.at.iter().cloned().fold(f64::MIN, f64::max)
    }

    pub fn all_ended(&self) -> bool {
        self.ended.iter().all(|&e| e)
    }
}

/// Reads a header as a number.
pub(crate) fn header_f64(m: &async_nats::Message, name: &str) -> Option<f64> {
    m.headers.as_ref()?.get(name)?.as_str().parse().ok()
}

/// Whether a message is a partition's last (a replay's end).
pub(crate) fn is_end(m: &async_nats::Message) -> bool {
    m.headers.as_ref().is_some_and(|h| h.get(header::END).is_some())
}

/// The headers of a message a role stores: its id (JetStream stores one
/// message per id within its window), the numbers it carries, and the end
/// mark on a partition's last.
pub(crate) fn headers(id: &str, end: bool, numbers: &[(&str, f64)]) -> async_nats::HeaderMap {
    let mut h = async_nats::HeaderMap::new();
    h.insert("Nats-Msg-Id", id);
    for (name, v) in numbers {
        h.insert(*name, v.to_string().as_str());
    }
    if end {
        h.insert(header::END, "1");
    }
    h
}

/// The connection, the JetStream context and every stream and bucket,
/// created if absent (each role may be the first to start).
pub struct Nats {
    pub client: async_nats::Client,
    pub js: jetstream::Context,
    pub names: Names,
    pub frames: stream::Stream,
    pub receivers: stream::Stream,
    pub events: stream::Stream,
    pub sync: stream::Stream,
    pub claims: kv::Store,
    pub workers: kv::Store,
    pub checkpoints: kv::Store,
    pub clock: kv::Store,
}

impl Nats {
    pub async fn connect(cfg: &ClusterConfig) -> Result<Nats> {
        let client = async_nats::ConnectOptions::new()
            .connection_timeout(Duration::from_secs(5))
            .name(format!("fuse1090 {:?}", cfg.roles))
            .event_callback(|event| async move {
                if matches!(event, async_nats::Event::Disconnected) {
                    outage::count_disconnect();
                    tracing::warn!("NATS connection lost: reconnecting");
                }
            })
            .connect(cfg.url.as_str())
            .await
            .with_context(|| format!("cannot connect to NATS at {}", cfg.url))?;
        let js = jetstream::new(client.clone());
        let names = Names { name: cfg.name.clone() };
        let n = &cfg.name;
        let max = cfg.max_stream_bytes;
        let frames = stream(&js, &names, "FRAMES", format!("{n}.frames.>"), max, Keep::AnHour).await?;
        let receivers = stream(&js, &names, "RECEIVERS", names.receivers(), 64 << 20, Keep::Always).await?;
        let events = stream(&js, &names, "EVENTS", format!("{n}.events.>"), max, Keep::AnHour).await?;
        let sync = stream(&js, &names, "SYNC", format!("{n}.sync.>"), max, Keep::AnHour).await?;
        let lease = Duration::from_secs_f64(cfg.lease_s);
        let bucket = |what: &str, max_age: Duration| kv::Config {
            bucket: names.bucket(what),
            history: 1,
            max_age,
            ..Default::default()
        };
        let claims = kv_store(&js, bucket("claims", lease)).await?;
        let workers = kv_store(&js, bucket("workers", lease)).await?;
        let checkpoints = kv_store(&js, bucket("checkpoints", Duration::from_secs(3600))).await?;
        let clock = kv_store(&js, bucket("clock", Duration::from_secs(3600))).await?;
        Ok(Nats { client, js, names, frames, receivers, events, sync, claims, workers, checkpoints, clock })
    }
}

impl Nats {
    /// Every receiver declared, in declaration order from the first (the
    /// order gives each its index, so one unreadable is an error, not a skip).
    pub async fn receiver_declarations(&self) -> Result<Declarations> {
        let config = jetstream::consumer::pull::Config {
            deliver_policy: jetstream::consumer::DeliverPolicy::All,
            ack_policy: jetstream::consumer::AckPolicy::None,
            ..Default::default()
        };
        Ok(Declarations(outage::Follow::start(&self.receivers, config, true, "the receiver stream").await?))
    }
}

/// The receivers' declarations as they come ([`Nats::receiver_declarations`]).
pub struct Declarations(outage::Follow);

impl Declarations {
    /// The next declaration, or `None` once the stream ends.
    pub async fn next(&mut self) -> Option<Result<crate::feed::capture::ReceiverDecl>> {
        let m = match self.0.next().await? {
            Ok(m) => m,
            Err(e) => return Some(Err(e)),
        };
        Some(serde_json::from_slice(&m.payload).context("receiver declaration unreadable"))
    }
}

/// How long a stream keeps its messages.
#[derive(Clone, Copy, PartialEq)]
enum Keep {
    /// Data: an hour, and the oldest go when the stream is full.
    AnHour,
    /// The receivers' declarations: their order gives each receiver its
    /// index, so one lost would renumber every later receiver, and a role
    /// started after it aged out could not read the receivers at all. Never
    /// aged out; a full stream refuses a new declaration (an error) rather
    /// than drop an old one.
    Always,
}

/// A stream of the cluster's, created if absent (and its limits set as
/// `keep` says on one an earlier version made): bounded in bytes, with a
/// two-minute window in which a message id is stored once.
async fn stream(
    js: &jetstream::Context,
    names: &Names,
    what: &str,
    subject: String,
    max_bytes: i64,
    keep: Keep,
) -> Result<stream::Stream> {
    let (max_age, discard) = match keep {
        Keep::AnHour => (Duration::from_secs(3600), stream::DiscardPolicy::Old),
        // Zero: no age limit.
        Keep::Always => (Duration::ZERO, stream::DiscardPolicy::New),
    };
    let cfg = stream::Config {
        name: names.stream(what),
        subjects: vec![subject],
        max_bytes,
        max_age,
        discard,
        duplicate_window: Duration::from_secs(120),
        ..Default::default()
    };
    let mut s = js.get_or_create_stream(cfg.clone()).await.map_err(|e| create_error(e, what, max_bytes))?;
    let have = &s.cached_info().config;
    if (have.max_age, have.discard) != (max_age, discard) {
        js.update_stream(&cfg).await.with_context(|| format!("cannot set the {what} stream's limits"))?;
        s = js.get_stream(&cfg.name).await.with_context(|| format!("cannot read the {what} stream"))?;
    }
    Ok(s)
}

/// Why a stream could not be made, in the operator's terms: JetStream
/// reserves each stream's whole bound up front, so a server whose store
/// (by default three quarters of its disk's free space) cannot hold the
/// bounds refuses the stream, however little is in it yet.
fn create_error(e: jetstream::context::CreateStreamError, what: &str, max_bytes: i64) -> anyhow::Error {
    use jetstream::context::CreateStreamErrorKind as Kind;
    use jetstream::ErrorCode;
    let storage = matches!(e.kind(), Kind::JetStream(j)
        if [ErrorCode::STORAGE_RESOURCES_EXCEEDED, ErrorCode::INSUFFICIENT_RESOURCES].contains(&j.error_code()));
    let why = if storage {
        format!(
            "cannot create the {what} stream: the NATS server cannot reserve its {} MiB \
             (the cluster's streams take three times [cluster] max_stream_bytes and 64 MiB): \
             lower max_stream_bytes, or give nats-server more store (jetstream max_file_store, free disk)",
            max_bytes >> 20
        )
    } else {
        format!("cannot create the {what} stream (is JetStream enabled: nats-server -js?)")
    };
    anyhow::Error::new(e).context(why)
}

async fn kv_store(js: &jetstream::Context, cfg: kv::Config) -> Result<kv::Store> {
    let name = cfg.bucket.clone();
    match js.get_key_value(&name).await {
        Ok(s) => Ok(s),
        Err(_) => js.create_key_value(cfg).await.with_context(|| format!("cannot create the {name} bucket")),
    }
}

/// Runs this process's roles until the publisher has written a replay's
/// end, or SIGTERM/SIGINT.
pub fn run(cfg: &Config, path: Option<&Path>, capture: Option<&Path>, output: Option<&Path>) -> Result<()> {
    let cluster = cfg.cluster.clone().context("no [cluster] section")?;
    if capture.is_some() && !cluster.has(Role::Ingest) {
        bail!("--capture replays into the cluster: it needs the ingest role");
    }
    if output.is_some() && !cluster.has(Role::Publisher) {
        bail!("--output is the publisher's: it needs the publisher role");
    }
    let rt =
        tokio::runtime::Builder::new_current_thread().enable_all().build().context("cannot start tokio")?;
    rt.block_on(async move {
        let nats = std::sync::Arc::new(Nats::connect(&cluster).await?);
        let worker_stats = std::sync::Arc::new(std::sync::Mutex::new(worker::WorkerStats::default()));
        let roles = Roles { cfg, cluster: &cluster, nats: &nats, path, capture, output };
        let (mut tasks, until_done) = roles.spawn(&worker_stats)?;
        // A replay (or a publisher writing a file) ends with its input.
        let ends = capture.is_some() || output.is_some();
        wait(&mut tasks, until_done, ends).await?;
        // What was published reaches the server, unless it is gone.
        let _ = tokio::time::timeout(Duration::from_secs(2), nats.client.flush()).await;
        // A worker says what it did when it stops.
        if cluster.has(Role::Worker) {
            println!("{}", *worker_stats.lock().expect("stats lock"));
        }
        Ok(())
    })
}

/// What this process was asked to run, and with what.
struct Roles<'a> {
    cfg: &'a Config,
    cluster: &'a ClusterConfig,
    nats: &'a std::sync::Arc<Nats>,
    path: Option<&'a Path>,
    capture: Option<&'a Path>,
    output: Option<&'a Path>,
}

impl Roles<'_> {
    /// Each role's task started; the tasks whose end ends a replay.
    fn spawn(
        &self,
        worker_stats: &std::sync::Arc<std::sync::Mutex<worker::WorkerStats>>,
    ) -> Result<(tokio::task::JoinSet<Result<()>>, Vec<tokio::task::Id>)> {
        let (cfg, cluster) = (self.cfg, self.cluster);
        let mut tasks = tokio::task::JoinSet::new();
        let mut until_done = Vec::new();
        if let Some(path) = self.capture {
            let (nats, cluster, path) = (self.nats.clone(), cluster.clone(), path.to_path_buf());
            until_done.push(
                tasks.spawn(async move { ingest::replay(&nats, &cluster, &path).await.map(|_| ()) }).id(),
            );
        } else if cluster.has(Role::Ingest) {
            // Live: the daemon's inputs, with the frames put on NATS.
            let sink = crate::live::Sink::Cluster(self.nats.clone(), cluster.clone());
            let (path, cfg) = (self.path.context("live ingest needs --config")?.to_path_buf(), cfg.clone());
            let (shutdown, reloads) = crate::live::signals(path)?;
            tasks.spawn(async move { crate::live::serve(cfg, Some(sink), shutdown, reloads).await });
        }
        if cluster.has(Role::Clock) {
            let (nats, cluster, mlat) = (self.nats.clone(), cluster.clone(), cfg.core.mlat.clone());
            tasks.spawn(async move { clock::run(&nats, &cluster, &mlat).await.map(|_| ()) });
        }
        if cluster.has(Role::Worker) {
            let (nats, cluster, core, shown) =
                (self.nats.clone(), cluster.clone(), cfg.core.clone(), worker_stats.clone());
            tasks.spawn(async move { worker::run(nats, cluster, core, shown).await });
        }
        if cluster.has(Role::Publisher) {
            // The metrics endpoint is a live ingest's when it shares the process.
            let mut config = cfg.clone();
            if cluster.has(Role::Ingest) && self.capture.is_none() {
                config.service.metrics_listen = None;
            }
            let (nats, cluster) = (self.nats.clone(), cluster.clone());
            let output = self.output.map(Path::to_path_buf);
            until_done.push(
                tasks
                    .spawn(async move { publisher::run(&nats, &cluster, &config, output).await.map(|_| ()) })
                    .id(),
            );
        }
        Ok((tasks, until_done))
    }
}

/// Until a task fails, SIGTERM or Ctrl-C, every task has ended, or (with
/// `ends`) the tasks in `until_done` have.
async fn wait(
    tasks: &mut tokio::task::JoinSet<Result<()>>,
    mut until_done: Vec<tokio::task::Id>,
    ends: bool,
) -> Result<()> {
    let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    loop {
        tokio::select! {
            done = tasks.join_next_with_id() => match done {
                None => return Ok(()),
                Some(Ok((id, res))) => {
                    res?;
                    until_done.retain(|&t| t != id);
                    if until_done.is_empty() && ends {
                        return Ok(());
                    }
                }
                Some(Err(e)) => bail!("a cluster task failed: {e}"),
            },
            _ = term.recv() => return Ok(()),
            _ = tokio::signal::ctrl_c() => return Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A batch that comes after a later one of its partition (sent again
    /// after an outage) is taken once; a replay after a takeover, or one
    /// older than the window, is not; the common time waits for the
    /// partition furthest behind and passes one that ended.
    #[test]
    fn watermarks_take_a_late_batch_once_and_refuse_replays() {
        let mut w = Watermarks::new(2);
        assert_eq!(w.mark(0, 100.0, false), Mark::New);
        assert_eq!(w.mark(0, 100.2, false), Mark::New);
        assert_eq!(w.mark(0, 100.1, false), Mark::New, "late, never taken");
        assert_eq!(w.mark(0, 100.1, false), Mark::Replayed, "taken already");
        assert_eq!(w.mark(0, 100.2 - REORDER_WINDOW_S - 1.0, false), Mark::Replayed, "older than the window");
        assert_eq!(w.mark(5, 100.0, false), Mark::Unknown);
        assert_eq!(w.common(), f64::NEG_INFINITY, "partition 1 not heard yet");
        assert_eq!(w.mark(1, 50.0, false), Mark::New);
        assert_eq!(w.common(), 50.0);
        assert_eq!(w.mark(1, 60.0, true), Mark::New);
        assert_eq!(w.common(), 100.2, "an ended partition holds nobody back");
        assert!(!w.all_ended());
        // The remembered times stay within the window.
        for k in 1..2000 {
            w.mark(0, 100.2 + k as f64 * 0.1, false);
        }
        assert!(w.taken[0].len() <= (REORDER_WINDOW_S / 0.1) as usize + 2, "{}", w.taken[0].len());
    }
}
