//! The service's life on the async runtime, shaped like mini-redis's
//! server: [`serve`] takes the configuration, a shutdown future and a
//! stream of re-read configurations, so that the signals (see
//! [`signals`]) are an adapter around it and a test can drive it
//! in-process. Every task it starts is handed a [`Shutdown`] and ends
//! itself when told; the inputs have a stopper of their own, because a
//! reload replaces them.

use std::future::Future;
use std::path::PathBuf;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use tokio::sync::mpsc;

use super::config::InputConfig;
use super::inputs::{self, Registry};
use super::outputs::Outputs;
use super::record::{self, Recorder};
use super::shutdown::Tasks;
use super::{http, replay, stages, stream_out, unix_now, web, Sink, ToCore};
use crate::config::Config;
use crate::core::front::KnownReceiver;

/// How long the service's tasks have to end once told (inputs close their
/// connections, the HTTP server its own).
const TASKS_STOP: Duration = Duration::from_secs(2);

/// SIGTERM and SIGINT as the service's shutdown, SIGHUP as the
/// configuration file `path` read again: what [`serve`] takes. A file that
/// does not load is refused (said in the log and to systemd) and the
/// service keeps the configuration it has.
pub fn signals(path: PathBuf) -> Result<(impl Future<Output = ()>, mpsc::Receiver<Config>)> {
    use tokio::signal::unix::{signal, SignalKind};
    let mut term = signal(SignalKind::terminate())?;
    let mut hup = signal(SignalKind::hangup())?;
    let (reload, reloads) = mpsc::channel(1);
    tokio::spawn(async move {
        while hup.recv().await.is_some() {
            // systemd shows the state of a reload (`systemctl status`);
            // the unit's ExecReload checks the file first, so a
            // configuration refused fails `systemctl reload` itself.
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Reloading]);
            match Config::load(&path) {
                Ok(new) => {
                    if reload.send(new).await.is_err() {
                        break;
                    }
                }
                Err(e) => {
                    tracing::error!("SIGHUP: configuration refused, keeping the old one:\n{e:#}");
                    let status = "running on the old configuration: the new one was refused (see the log)";
                    let _ = sd_notify::notify(&[
                        sd_notify::NotifyState::Ready,
                        sd_notify::NotifyState::Status(status),
                    ]);
                }
            }
        }
    });
    let shutdown = async move {
        tokio::select! {
            _ = term.recv() => {}
            _ = tokio::signal::ctrl_c() => {}
        }
    };
    Ok((shutdown, reloads))
}

/// The inputs in `list`, each on its bound socket, as tasks that stop together.
fn start_inputs(
    list: &[InputConfig],
    bound: Vec<inputs::Bound>,
    tx: &SyncSender<ToCore>,
    reg: &Arc<Registry>,
) -> Tasks {
    let mut tasks = Tasks::default();
    for (i, b) in list.iter().zip(bound) {
        let task = inputs::spawn(i.clone(), b, tx.clone(), reg.clone(), tasks.shutdown());
        tasks.push(task);
    }
    tasks
}

/// Tells the inputs to stop and waits until they have (their ports free).
async fn stop_inputs(inputs: Tasks) {
    let late = inputs.stop(TASKS_STOP).await;
    if late > 0 {
        tracing::warn!(inputs = late, "inputs still running after being told to stop");
    }
}

/// The counters of a service run in-process, for whoever started it (a
/// test, a program embedding the service): its [`Registry`] of receivers
/// with their counters, there once [`serve_counted`] is running (its
/// receivers declared, its inputs' ports bound). The stats line and
/// Prometheus read the same atomics, so a test reading these reads what an
/// operator sees, typed, without parsing the log.
#[derive(Clone, Default)]
pub struct Counters(Arc<OnceLock<Arc<Registry>>>);

impl Counters {
    /// The service's registry, once it has started.
    pub fn registry(&self) -> Option<&Arc<Registry>> {
        self.0.get()
    }
}

/// The service on `cfg` until `shutdown` completes; each configuration from
/// `reloads` applied in turn (receivers, inputs and outputs replaced, the
/// core and its tracks kept). Its frames go to `sink` (a core when `None`).
pub async fn serve(
    cfg: Config,
    sink: Option<Sink>,
    shutdown: impl Future<Output = ()>,
    reloads: mpsc::Receiver<Config>,
) -> Result<()> {
    serve_counted(cfg, sink, shutdown, reloads, &Counters::default()).await
}

/// [`serve`], its counters left in `counters` for the caller to read.
pub async fn serve_counted(
    cfg: Config,
    sink: Option<Sink>,
    shutdown: impl Future<Output = ()>,
    reloads: mpsc::Receiver<Config>,
    counters: &Counters,
) -> Result<()> {
    let ingest_only = matches!(sink, Some(Sink::Cluster(..)));
    let cfg = for_sink(cfg, ingest_only);
    let registry = Arc::new(Registry { queue_frames: cfg.service.queue_frames, ..Default::default() });
    // Everything but the inputs stops at the end (a reload replaces those).
    let mut rest = Tasks::default();
    let web = start_http(&cfg, &registry, &mut rest).await?;
    // Every message holds a frame or more: the frames' bound bites first.
    let (tx, rx) = sync_channel::<ToCore>(cfg.service.queue_frames);
    let mut core_cfg = cfg.core.clone();
    core_cfg.publish_source_tracks = cfg.publish_source_tracks;
    let mut decls = Vec::new();
    for r in &cfg.receiver {
        registry.add(r.clone());
        decls.push(r.known());
    }
    let (streams, failed) = stream_out::start_all(&cfg.output, &[]).await;
    if let Some((n, e)) = failed.into_iter().next() {
        bail!("[[output]] {n} cannot start: {e}");
    }
    let outputs = Outputs::new(&cfg.output, &cfg.service, &streams);
    let setup = stages::Setup {
        receivers: decls,
        outputs,
        recorder: open_recorder(&cfg.service)?,
        registry: registry.clone(),
        stats_every: cfg.service.stats_interval_s,
        state_file: cfg.service.state_file.clone(),
        web,
    };
    // Every port bound before anything runs: one that is taken (another
    // daemon, a stale instance) fails the start, where systemd shows it.
    let bound = inputs::bind_all(&cfg.input).await.map_err(anyhow::Error::msg)?;
    let core_thread = start_sink(sink, &core_cfg, setup, &tx, rx)?;

    let running = start_inputs(&cfg.input, bound, &tx, &registry);
    // Handed out once the receivers are in it and the inputs' ports bound:
    // a caller that reads it may send at once. (One start per `Counters`:
    // a second keeps the first's.)
    let _ = counters.0.set(registry.clone());
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
    tracing::info!(
        inputs = cfg.input.len(),
        outputs = cfg.output.len(),
        receivers = cfg.receiver.len(),
        "running"
    );
    // Apart from the inputs' tasks: a reload that replaces the inputs must
    // not end the demo's replay.
    if let Some(capture) = cfg.service.demo_capture.clone() {
        let (speed, demo_cfg) = (cfg.service.demo_speed, cfg.clone());
        rest.spawn(async move {
            match replay::replay(&capture, &demo_cfg, speed).await {
                Ok(n) => tracing::info!(frames = n, "demo replay finished"),
                Err(e) => tracing::error!("demo replay: {e:#}"),
            }
        });
    }

    let mut live = Live { current: cfg, registry, tx, inputs: running, streams };
    live.follow(shutdown, reloads, ingest_only).await;
    tracing::info!("stopping");
    let Live { inputs, tx, .. } = live;
    stop_inputs(inputs).await;
    let late = rest.stop(TASKS_STOP).await;
    if late > 0 {
        tracing::warn!(tasks = late, "tasks still running at the stop");
    }
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    let _ = tx.send(ToCore::Shutdown);
    drop(tx);
    let _ = tokio::task::spawn_blocking(move || core_thread.join()).await;
    Ok(())
}

/// The recording `[service] record` asks for, opened.
fn open_recorder(service: &super::config::ServiceConfig) -> Result<Option<Recorder>> {
    let Some(p) = &service.record else { return Ok(None) };
    let limits = record::RecordLimits {
        path: p.clone(),
        max_bytes: service.record_max_bytes,
        max_age_s: service.record_max_age_s,
        keep: service.record_keep,
    };
    let recorder = Recorder::open(limits, unix_now())
        .with_context(|| format!("cannot create the recording {}", p.display()))?;
    Ok(Some(recorder))
}

/// Where the inputs' frames go, started: the core's two threads, or a
/// cluster's ingest thread (which declares the receivers through `tx` and
/// puts their frames on NATS). The thread that ends once `tx` is dropped.
fn start_sink(
    sink: Option<Sink>,
    core_cfg: &crate::core::CoreConfig,
    setup: stages::Setup,
    tx: &SyncSender<ToCore>,
    rx: Receiver<ToCore>,
) -> Result<std::thread::JoinHandle<()>> {
    let Some(Sink::Cluster(nats, cluster)) = sink else {
        return stages::start(core_cfg, setup, rx);
    };
    let (out, publish) = mpsc::channel(16);
    tokio::spawn(async move {
        if let Err(e) = crate::cluster::ingest::publish_live(&nats, publish).await {
            tracing::error!("ingest: {e:#}");
        }
    });
    for KnownReceiver { decl, .. } in setup.receivers {
        let _ = tx.send(ToCore::AddReceiver(decl));
    }
    let reg = setup.registry;
    let thread = std::thread::Builder::new()
        .name("ingest".into())
        .spawn(move || crate::cluster::ingest::live_sink(rx, reg, out, cluster))?;
    Ok(thread)
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
    tasks: &mut Tasks,
) -> Result<Option<Arc<web::WebData>>> {
    let (metrics_at, http_at) = (cfg.service.metrics_listen, cfg.http.listen);
    if metrics_at.is_none() && http_at.is_none() {
        return Ok(None);
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
        tasks.spawn(http::serve(listener, routes, counters, http::METRICS_CONNECTIONS));
        tracing::info!(address = %addr, "Prometheus metrics");
    }
    let Some(addr) = http_at else { return Ok(None) };
    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("the HTTP server ([http] listen) cannot bind {addr}"))?;
    let data =
        Arc::new(web::WebData::new(cfg.http.map_tiles.as_deref(), cfg.http.map_attribution.as_deref()));
    let routes = http::Routes { metrics: Some(handle), web: Some(data.clone()) };
    tasks.spawn(http::serve(listener, routes, registry.http.clone(), cfg.http.max_connections));
    tracing::info!(address = %addr, "HTTP: the map at /, /data/aircraft.json, /data/receivers.json, /metrics");
    Ok(Some(data))
}

/// What a reload changes: the configuration in force, the receivers'
/// registry, the way to the core, the inputs and the output streams.
struct Live {
    current: Config,
    registry: Arc<Registry>,
    tx: SyncSender<ToCore>,
    inputs: Tasks,
    streams: Vec<Arc<stream_out::Stream>>,
}

impl Live {
    /// Applies each configuration from `reloads` until `shutdown`.
    async fn follow(
        &mut self,
        shutdown: impl Future<Output = ()>,
        mut reloads: mpsc::Receiver<Config>,
        ingest_only: bool,
    ) {
        tokio::pin!(shutdown);
        let mut reloading = true;
        loop {
            tokio::select! {
                () = &mut shutdown => return,
                new = reloads.recv(), if reloading => {
                    let Some(new) = new.map(|c| for_sink(c, ingest_only)) else {
                        // No more reloads can come: the service runs on.
                        reloading = false;
                        continue;
                    };
                    let status = match self.reload(new).await {
                        0 => "running; configuration re-read".to_string(),
                        n => format!("running; configuration re-read, {n} input(s) could not bind (see the log)"),
                    };
                    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready, sd_notify::NotifyState::Status(&status)]);
                }
            }
        }
    }

    /// Applies a re-read configuration (SIGHUP): receivers added, updated and
    /// revoked; outputs replaced; inputs, if changed, closed and bound anew.
    /// Returns how many new inputs could not bind (said in the log; the
    /// service goes on without them).
    async fn reload(&mut self, new: Config) -> usize {
        // New receivers added, known ones updated in place, removed ones
        // revoked (their connections closed).
        for r in self.registry.reconfigure(&new.receiver) {
            let _ = self.tx.send(ToCore::AddReceiver(r.decl()));
        }
        // Logged once the receivers are in place (tests wait for it).
        tracing::info!("SIGHUP: configuration re-read");
        // Their ports are bound, and the map's settings served, once, at start.
        let current = &self.current;
        if new.http != current.http || new.service.metrics_listen != current.service.metrics_listen {
            tracing::warn!("SIGHUP: [http] and metrics_listen take effect at the next start");
        }
        let (started, failed) = stream_out::start_all(&new.output, &self.streams).await;
        for (n, e) in failed {
            tracing::error!("SIGHUP: [[output]] {n} cannot start: {e}; going on without it");
        }
        self.streams = started;
        let _ = self.tx.send(ToCore::Outputs(Outputs::new(&new.output, &new.service, &self.streams)));
        let left_out = if new.input == current.input { 0 } else { self.replace_inputs(&new.input).await };
        self.current = new;
        left_out
    }

    /// The inputs closed, then `list` bound and started: each input that
    /// binds runs; one that cannot is said and left out, the daemon going
    /// on with the rest. Returns how many were left out.
    async fn replace_inputs(&mut self, list: &[InputConfig]) -> usize {
        // Closed before the new ones bind the same ports.
        stop_inputs(std::mem::take(&mut self.inputs)).await;
        let (mut ok, mut bound) = (Vec::new(), Vec::new());
        for (n, i) in list.iter().enumerate() {
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
        self.inputs = start_inputs(&ok, bound, &self.tx, &self.registry);
        list.len() - ok.len()
    }
}
