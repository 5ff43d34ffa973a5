//! The live service (`fuse1090 run --config FILE`): sockets in, the same
//! sans-IO core as `run --capture`, datagrams out.
//!
//! Shaped like mini-redis: a tokio runtime owns the sockets (one task per
//! input, see [`inputs`]) and the signals; the core runs on two threads of
//! its own ([`stages`]), as `run --capture` does (its front stage fed
//! through one bounded queue, its back stage owning the outputs), so the
//! processing is exactly the offline pipeline with the system clock as its
//! time. SIGTERM
//! and SIGINT stop the inputs, let the core publish what it holds and end
//! within two seconds; SIGHUP re-reads the configuration and replaces
//! receivers (added, never renumbered), inputs and outputs while the core,
//! and so every track, stays. systemd is told READY once the sockets are
//! bound and fed WATCHDOG from the core loop, so a stuck core is restarted.

pub mod admit;
pub mod config;
pub mod http;
pub mod inputs;
pub mod loglimit;
pub mod map_assets;
pub mod outputs;
pub mod record;
pub mod registry;
pub mod replay;
mod report;
pub mod server;
mod stages;
pub mod stamp;
pub mod stream_out;
pub mod web;

use std::path::{Path, PathBuf};
use std::sync::mpsc::sync_channel;
use std::sync::Arc;

use anyhow::{bail, Context, Result};

use crate::config::Config;
use crate::core::front::KnownReceiver;
use crate::feed::capture::ReceiverDecl;
use crate::feed::RawFrame;
use config::InputConfig;
use inputs::Registry;
use outputs::Outputs;
use record::Recorder;

/// Most frames handled between two publications. A batch is whatever is
/// queued up to this, so under light load it is a frame or a few; under
/// heavy load each batch wakes the tracker thread and costs a channel
/// round, and at 973 k frames/s (`live_load`, 60 s, seven alternating
/// pairs) 512 gave an ADS-B-only p99 of 11-50 ms, median 23, against
/// 38-75 ms, median 61, for 128 (better in all seven); 1,024 and 2,048 were
/// no better than 512, and at 1x-6x it changed nothing measurable.
const BATCH: usize = 512;

/// What the sockets and the signal handlers tell the core thread.
pub enum ToCore {
    /// Frames that arrived together (a datagram, a read).
    Frames {
        rx: usize,
        arrival: f64,
        frames: Vec<RawFrame>,
        /// The sender's counters: its share of the queue is given back
        /// when the core takes the frames.
        from: Arc<inputs::RxCounters>,
    },
    AddReceiver(ReceiverDecl),
    Outputs(Outputs),
    Shutdown,
}

/// System time as Unix seconds.
pub fn unix_now() -> f64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}

/// Runs the service until SIGTERM or SIGINT.
pub fn run(config_path: &Path) -> Result<()> {
    let cfg = Config::load(config_path)?;
    if let Err(e) = no_huge_pages() {
        tracing::warn!("transparent huge pages left on ({e})");
    }
    if cfg.service.realtime_priority > 0 {
        match realtime(cfg.service.realtime_priority) {
            Ok(()) => {
                tracing::info!(priority = cfg.service.realtime_priority, "realtime round-robin scheduling")
            }
            Err(e) => tracing::warn!(
                priority = cfg.service.realtime_priority,
                "realtime scheduling refused ({e}): running time-shared; it needs CAP_SYS_NICE or an \
                 RLIMIT_RTPRIO of at least the priority (systemd: LimitRTPRIO=, RestrictRealtime=no)"
            ),
        }
    }
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    rt.block_on(serve(config_path.to_path_buf(), cfg, None))
}

/// Where the inputs' frames go: the core (one node), or a cluster's
/// ingest, which puts them on NATS for the workers ([`crate::cluster`]).
pub enum Sink {
    Core,
    Cluster(Arc<crate::cluster::Nats>, crate::cluster::ClusterConfig),
}

/// Turns transparent huge pages off for the whole process.
///
/// Why: the allocator asks for huge pages (`madvise`), which offline saves
/// part of `run --capture`'s time in fewer TLB misses, but with the
/// kernel's usual `defrag = madvise` the first touch of such a page may
/// compact memory on the spot, a stall of tens of milliseconds: at 1 M
/// frames/s (`live_load`) three runs in ten had an ADS-B-only p99 of 21-78
/// ms with them, none of fifteen over 1 ms without.
fn no_huge_pages() -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: a plain system call with integer arguments.
        let rc = unsafe { libc::prctl(libc::PR_SET_THP_DISABLE, 1, 0, 0, 0) };
        Ok(nix::errno::Errno::result(rc).map(drop)?)
    }
    #[cfg(not(target_os = "linux"))]
    {
        Ok(())
    }
}

/// Puts the calling thread, and so every thread it starts afterwards (they
/// inherit it), under round-robin realtime scheduling at `priority`.
///
/// Why: at a million frames a second the core's threads sleep and wake
/// thousands of times a second, and under time sharing each wake-up can wait
/// behind any other runnable process for a few milliseconds; a backlog then
/// builds and the ADS-B-only latency's tail is those waits (`live_load` at
/// 1 M frames/s: p99 4-42 ms time-shared, 0.8-1.0 ms at priority 10, same
/// hour). Threads block when they have no work, so the service takes the
/// CPU its frames need and no more (though more than time-shared: each
/// wake-up is served at once, so batches are smaller), and the kernel's
/// realtime throttling keeps a share for everything else. Not reset on
/// fork: to the kernel a new thread is a fork, and the threads started
/// afterwards would lose it (the service starts no processes).
fn realtime(priority: u8) -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param { sched_priority: priority.into() };
        // SAFETY: a plain system call on the calling thread (pid 0) with a
        // parameter that outlives it.
        let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_RR, &param) };
        Ok(nix::errno::Errno::result(rc).map(drop)?)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = priority;
        Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "not on this system"))
    }
}

/// The service until SIGTERM or SIGINT; its frames to `sink` (a core when `None`).
pub async fn serve(path: PathBuf, cfg: Config, sink: Option<Sink>) -> Result<()> {
    let ingest_only = matches!(sink, Some(Sink::Cluster(..)));
    let cfg = for_sink(cfg, ingest_only);
    let registry = Arc::new(Registry { queue_frames: cfg.service.queue_frames, ..Default::default() });
    let (http_tasks, web) = start_http(&cfg, &registry).await?;
    // Every message holds a frame or more: the frames' bound bites first.
    let (tx, rx) = sync_channel::<ToCore>(cfg.service.queue_frames);
    let mut core_cfg = cfg.core.clone();
    core_cfg.publish_source_tracks = cfg.publish_source_tracks;
    let mut decls = Vec::new();
    for r in &cfg.receiver {
        registry.add(r.clone());
        decls.push(r.known());
    }
    let (mut streams, failed) = stream_out::start_all(&cfg.output, &[]).await;
    if let Some((n, e)) = failed.into_iter().next() {
        bail!("[[output]] {n} cannot start: {e}");
    }
    let outputs = Outputs::new(&cfg.output, &cfg.service, &streams);
    let recorder = match &cfg.service.record {
        None => None,
        Some(p) => {
            let limits = record::RecordLimits {
                path: p.clone(),
                max_bytes: cfg.service.record_max_bytes,
                max_age_s: cfg.service.record_max_age_s,
                keep: cfg.service.record_keep,
            };
            Some(
                Recorder::open(limits, unix_now())
                    .with_context(|| format!("cannot create the recording {}", p.display()))?,
            )
        }
    };
    let stats_every = cfg.service.stats_interval_s;
    let state_file = cfg.service.state_file.clone();
    // Every port bound before anything runs: one that is taken (another
    // daemon, a stale instance) fails the start, where systemd shows it.
    let bound = inputs::bind_all(&cfg.input).await.map_err(anyhow::Error::msg)?;
    let reg = registry.clone();
    let core_thread = match sink {
        None | Some(Sink::Core) => {
            let setup = stages::Setup {
                receivers: decls,
                outputs,
                recorder,
                registry: reg,
                stats_every,
                state_file,
                web,
            };
            stages::start(&core_cfg, setup, rx)?
        }
        Some(Sink::Cluster(nats, cluster)) => {
            let (out, publish) = tokio::sync::mpsc::channel(16);
            tokio::spawn(async move {
                if let Err(e) = crate::cluster::ingest::publish_live(&nats, publish).await {
                    tracing::error!("ingest: {e:#}");
                }
            });
            for KnownReceiver { decl, .. } in decls {
                let _ = tx.send(ToCore::AddReceiver(decl));
            }
            std::thread::Builder::new()
                .name("ingest".into())
                .spawn(move || crate::cluster::ingest::live_sink(rx, reg, out, cluster))?
        }
    };

    let spawn_all = |list: &[InputConfig], bound: Vec<inputs::Bound>| -> Vec<tokio::task::JoinHandle<()>> {
        list.iter()
            .zip(bound)
            .map(|(i, b)| inputs::spawn(i.clone(), b, tx.clone(), registry.clone()))
            .collect()
    };
    let mut tasks = spawn_all(&cfg.input, bound);
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
    tracing::info!(
        inputs = cfg.input.len(),
        outputs = cfg.output.len(),
        receivers = cfg.receiver.len(),
        "running"
    );
    // Apart from the inputs' tasks: a reload that replaces the inputs must
    // not end the demo's replay.
    let mut demo_task = None;
    if let Some(capture) = cfg.service.demo_capture.clone() {
        let (speed, demo_cfg) = (cfg.service.demo_speed, cfg.clone());
        demo_task = Some(tokio::spawn(async move {
            match replay::replay(&capture, &demo_cfg, speed).await {
                Ok(n) => tracing::info!(frames = n, "demo replay finished"),
                Err(e) => tracing::error!("demo replay: {e:#}"),
            }
        }));
    }

    let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    let mut hup = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup())?;
    let mut current = cfg;
    loop {
        tokio::select! {
            _ = term.recv() => break,
            _ = tokio::signal::ctrl_c() => break,
            _ = hup.recv() => {
                // systemd shows the state of a reload (`systemctl status`);
                // the unit's ExecReload checks the file first, so a
                // configuration refused fails `systemctl reload` itself.
                let _ = sd_notify::notify(&[sd_notify::NotifyState::Reloading]);
                let status = match Config::load(&path).map(|c| for_sink(c, ingest_only)) {
                    Ok(new) => {
                        let left_out = reload(&new, &current, &registry, &tx, &mut tasks, &spawn_all, &mut streams).await;
                        current = new;
                        match left_out {
                            0 => "running; configuration re-read".to_string(),
                            n => format!("running; configuration re-read, {n} input(s) could not bind (see the log)"),
                        }
                    }
                    Err(e) => {
                        tracing::error!("SIGHUP: configuration refused, keeping the old one:\n{e:#}");
                        "running on the old configuration: the new one was refused (see the log)".to_string()
                    }
                };
                let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready, sd_notify::NotifyState::Status(&status)]);
            }
        }
    }
    tracing::info!("stopping");
    for t in tasks.into_iter().chain(http_tasks).chain(demo_task) {
        t.abort();
    }
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    let _ = tx.send(ToCore::Shutdown);
    drop(tx);
    let _ = tokio::task::spawn_blocking(move || core_thread.join()).await;
    Ok(())
}

/// A cluster's ingest puts frames on NATS and makes no tracks: the outputs
/// and the map are its publisher's (which may share the process and its
/// ports), the metrics endpoint stays.
fn for_sink(cfg: Config, ingest_only: bool) -> Config {
    if !ingest_only {
        return cfg;
    }
    let http = crate::live::config::HttpConfig { listen: None, ..cfg.http };
    Config { output: Vec::new(), http, ..cfg }
}

/// The Prometheus endpoint and the HTTP server, each bound before anything
/// runs (a taken port fails the start); the documents the HTTP server hands
/// out, for the tracker thread to render, when it is on.
pub(crate) async fn start_http(
    cfg: &Config,
    registry: &Arc<Registry>,
) -> Result<(Vec<tokio::task::JoinHandle<()>>, Option<Arc<web::WebData>>)> {
    let (metrics_at, http_at) = (cfg.service.metrics_listen, cfg.http.listen);
    let mut tasks = Vec::new();
    if metrics_at.is_none() && http_at.is_none() {
        return Ok((tasks, None));
    }
    let handle = metrics_exporter_prometheus::PrometheusBuilder::new()
        .install_recorder()
        .context("cannot start the Prometheus recorder")?;
    if let Some(addr) = metrics_at {
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .with_context(|| format!("the Prometheus endpoint cannot bind {addr}"))?;
        let routes = http::Routes { metrics: Some(handle.clone()), web: None };
        let counters = registry.metrics_http.clone();
        tasks.push(tokio::spawn(http::serve(listener, routes, counters, http::METRICS_CONNECTIONS)));
        tracing::info!(address = %addr, "Prometheus metrics");
    }
    let Some(addr) = http_at else { return Ok((tasks, None)) };
    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("the HTTP server ([http] listen) cannot bind {addr}"))?;
    let data =
        Arc::new(web::WebData::new(cfg.http.map_tiles.as_deref(), cfg.http.map_attribution.as_deref()));
    let routes = http::Routes { metrics: Some(handle), web: Some(data.clone()) };
    tasks.push(tokio::spawn(http::serve(listener, routes, registry.http.clone(), cfg.http.max_connections)));
    tracing::info!(address = %addr, "HTTP: the map at /, /data/aircraft.json, /data/receivers.json, /metrics");
    Ok((tasks, Some(data)))
}

/// Applies a re-read configuration (SIGHUP): receivers added, updated and
/// revoked; outputs replaced; inputs, if changed, closed and bound anew.
/// Returns how many new inputs could not bind (said in the log; the
/// service goes on without them).
async fn reload(
    new: &Config,
    current: &Config,
    registry: &Arc<Registry>,
    tx: &std::sync::mpsc::SyncSender<ToCore>,
    tasks: &mut Vec<tokio::task::JoinHandle<()>>,
    spawn_all: &impl Fn(&[InputConfig], Vec<inputs::Bound>) -> Vec<tokio::task::JoinHandle<()>>,
    streams: &mut Vec<Arc<stream_out::Stream>>,
) -> usize {
    // New receivers added, known ones updated in place, removed ones
    // revoked (their connections closed).
    for r in registry.reconfigure(&new.receiver) {
        let _ = tx.send(ToCore::AddReceiver(r.decl()));
    }
    // Logged once the receivers are in place (tests wait for it).
    tracing::info!("SIGHUP: configuration re-read");
    // Their ports are bound, and the map's settings served, once, at start.
    if new.http != current.http || new.service.metrics_listen != current.service.metrics_listen {
        tracing::warn!("SIGHUP: [http] and metrics_listen take effect at the next start");
    }
    let (started, failed) = stream_out::start_all(&new.output, streams).await;
    for (n, e) in failed {
        tracing::error!("SIGHUP: [[output]] {n} cannot start: {e}; going on without it");
    }
    *streams = started;
    let _ = tx.send(ToCore::Outputs(Outputs::new(&new.output, &new.service, streams)));
    if new.input == current.input {
        return 0;
    }
    // Closed before the new ones bind the same ports.
    for t in tasks.drain(..) {
        t.abort();
        let _ = t.await;
    }
    // Each input that binds runs; one that cannot is said and left out,
    // the daemon going on with the rest.
    let (mut ok, mut bound) = (Vec::new(), Vec::new());
    for (n, i) in new.input.iter().enumerate() {
        match inputs::bind(i).await {
            Ok(b) => {
                ok.push(i.clone());
                bound.push(b);
            }
            Err(e) => tracing::error!(
                "SIGHUP: input {} ({}) cannot bind {}: {e}; running without it",
                n + 1,
                i.kind.name(),
                i.address
            ),
        }
    }
    *tasks = spawn_all(&ok, bound);
    new.input.len() - ok.len()
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    /// The setting is the process's: one thread's call covers the threads
    /// that were already running and those started afterwards.
    #[test]
    fn huge_pages_are_off_for_every_thread_after_the_call() {
        fn off() -> libc::c_int {
            // SAFETY: a query with integer arguments.
            unsafe { libc::prctl(libc::PR_GET_THP_DISABLE, 0, 0, 0, 0) }
        }
        std::thread::spawn(super::no_huge_pages).join().unwrap().unwrap();
        assert_eq!(off(), 1, "the thread that was running");
        assert_eq!(std::thread::spawn(off).join().unwrap(), 1, "a thread started afterwards");
    }

    /// The service relies on threads started after the call inheriting the
    /// policy (an earlier version asked for reset-on-fork, which the kernel
    /// also applies to new threads: only the input thread ran realtime and
    /// the latency got worse). Where realtime scheduling is not permitted,
    /// the refusal is a permission error the service can report.
    #[test]
    fn realtime_scheduling_is_inherited_by_threads_started_afterwards() {
        fn policy() -> libc::c_int {
            // SAFETY: a query of the calling thread's policy.
            unsafe { libc::sched_getscheduler(0) }
        }
        std::thread::spawn(|| match super::realtime(1) {
            Ok(()) => {
                assert_eq!(policy(), libc::SCHED_RR);
                let child = std::thread::spawn(policy).join().unwrap();
                assert_eq!(child, libc::SCHED_RR, "a thread started afterwards is time-shared");
            }
            Err(e) => {
                let why = format!("realtime scheduling not permitted here ({e}); only the refusal checked");
                eprintln!("SKIP: {why}");
                if let Ok(log) = std::env::var("FUSE1090_SKIP_LOG") {
                    use std::io::Write;
                    let f = std::fs::OpenOptions::new().create(true).append(true).open(log);
                    let _ = f.and_then(|mut f| f.write_all(format!("live::realtime: {why}\n").as_bytes()));
                }
                assert_eq!(e.kind(), std::io::ErrorKind::PermissionDenied, "{e}");
                assert_eq!(policy(), libc::SCHED_OTHER);
            }
        })
        .join()
        .unwrap();
    }
}
