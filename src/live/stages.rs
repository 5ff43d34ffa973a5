//! The core's two threads in the daemon: the front stage (frames in,
//! decoding, grouping, multilateration) and the back stage (tracking,
//! fusion, the outputs), run by the same two-stage runner as `run
//! --capture` ([`crate::stages::TwoStages`]); what differs is what drives
//! the front and where the events go.
//!
//! The front thread ([`FrontThread`]) sleeps until the next frame or the
//! core's next deadline, whichever comes first: a group's wait running out
//! ([`Front::poll_timeout`]), a held publication or the conflict
//! assessment in the tracker (its [`Back::poll_timeout`], which the back
//! thread leaves in a [`Deadline`] after each batch), the once-a-second
//! metrics, the receivers' line, systemd's watchdog. So a group is handed
//! out at its deadline, not at the next poll, and an idle daemon wakes
//! about once a second. The back thread's [`Sink`] ([`BackThread`])
//! publishes each batch's events to the outputs and the map, and writes the
//! stats line and the metrics.

use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::inputs::Registry;
use super::outputs::{self, FrameForward, Outputs};
use super::record::Recorder;
use super::{readings, report, unix_now, web, ToCore, BATCH};
use crate::core::front::KnownReceiver;
use crate::core::{Back, Cmd, Core, CoreConfig, Event, Front, ReceiverNames};
use crate::stages::{Sink, TwoStages};

/// A time (Unix s) one thread leaves for another: the tracker's next
/// deadline, for the front thread's sleep.
#[derive(Default)]
struct Deadline(AtomicU64);

impl Deadline {
    fn set(&self, t: Option<f64>) {
        self.0.store(t.unwrap_or(f64::INFINITY).to_bits(), Ordering::Relaxed);
    }

    fn get(&self) -> Option<f64> {
        Some(f64::from_bits(self.0.load(Ordering::Relaxed))).filter(|t| t.is_finite())
    }
}

/// The longest the front thread sleeps when nothing is due: it looks at
/// the tracker's deadline again (set while it slept) at least this often.
const MAX_SLEEP_S: f64 = 1.0;

/// Batches between the two stages: bounded, so a stalled tracker stops
/// the front, whose input queue then drops (and counts) what it cannot take.
const STAGE_QUEUE: usize = 64;

/// What the front thread sends the back thread with a batch of commands:
/// the time they were made and its counters, or new outputs (SIGHUP, with
/// no commands).
pub(super) enum Tick {
    Batch { now: f64, front: report::FrontSnapshot },
    Outputs(Outputs),
}

/// What the core's threads are given beyond the core's configuration.
pub(super) struct Setup {
    pub receivers: Vec<KnownReceiver>,
    pub outputs: Outputs,
    pub recorder: Option<Recorder>,
    pub registry: Arc<Registry>,
    /// Seconds between stats lines (and the receivers' MLAT line).
    pub stats_every: f64,
    /// Where the learnt receiver timing is taken up from and saved to.
    pub state_file: Option<PathBuf>,
    /// The HTTP server's documents, rendered by the tracker thread.
    pub web: Option<Arc<web::WebData>>,
}

/// Starts the core's two threads; the front thread's handle (it finishes
/// the back stage before it ends). Frames and commands come through `rx`.
pub(super) fn start(cfg: &CoreConfig, setup: Setup, rx: Receiver<ToCore>) -> anyhow::Result<JoinHandle<()>> {
    let (front, back) = Core::stages(cfg);
    let Setup { receivers, outputs, recorder, registry, stats_every, state_file, web } = setup;
    let tracker_due = Arc::new(Deadline::default());
    let forward = outputs.frame_forward();
    let sink = BackThread {
        names: front.receiver_names(),
        outputs,
        registry: registry.clone(),
        web: web.map(web::WebPublisher::new),
        stats_every,
        due: tracker_due.clone(),
        front: report::FrontSnapshot::default(),
        last_stats: (unix_now(), 0),
        next_stats: unix_now() + stats_every,
        next_metrics: 0.0,
    };
    let stages = TwoStages::start("tracker", back, sink, STAGE_QUEUE)?;
    let mut front = FrontThread {
        front,
        cmds: Vec::new(),
        forward,
        recorder,
        registry,
        stages,
        tracker_due,
        state_file,
        stats_every,
        dispatched: 0,
        announced: HashSet::new(),
    };
    front.take_up(receivers);
    Ok(std::thread::Builder::new().name("core".into()).spawn(move || front.run(rx))?)
}

/// The core's front thread: frames in, commands to the back thread, the
/// recording, and the watchdog (a stalled back thread blocks it too).
struct FrontThread {
    front: Front,
    cmds: Vec<Cmd>,
    forward: FrameForward,
    recorder: Option<Recorder>,
    registry: Arc<Registry>,
    stages: TwoStages<BackThread>,
    tracker_due: Arc<Deadline>,
    state_file: Option<PathBuf>,
    stats_every: f64,
    /// Frames handed to the core so far.
    dispatched: u64,
    /// Receivers whose learnt network delay was logged.
    announced: HashSet<String>,
}

/// The front thread's own timers (Unix s, and systemd's watchdog).
struct Timers {
    delay_metrics: f64,
    receivers_line: f64,
    watchdog: Option<Duration>,
    last_ping: Instant,
}

impl FrontThread {
    /// The configured receivers declared, and what an earlier run learnt
    /// of their timing taken up.
    fn take_up(&mut self, receivers: Vec<KnownReceiver>) {
        self.front.know(receivers.clone());
        for KnownReceiver { decl, .. } in receivers {
            if let Some(r) = &mut self.recorder {
                r.receiver(&decl, unix_now());
            }
            self.front.add_receiver(decl);
        }
        let Some(path) = &self.state_file else { return };
        match crate::mlat::state::LearntState::load(path) {
            Ok(Some(state)) => {
                let (n, air) = self.front.restore(&state, unix_now());
                tracing::info!(path = %path.display(), receivers = n, air, "learnt state taken up");
            }
            Ok(None) => tracing::info!(path = %path.display(), "no learnt state yet"),
            Err(e) => tracing::warn!("learnt state not taken up: {e}"),
        }
    }

    fn run(mut self, rx: Receiver<ToCore>) {
        let mut timers = Timers {
            delay_metrics: 0.0,
            receivers_line: unix_now() + self.stats_every,
            watchdog: sd_notify::watchdog_enabled(),
            last_ping: Instant::now(),
        };
        // What did not fit the last batch: a TCP read can bring thousands of
        // frames at once, and they must not hold the tracker's batch back.
        let mut carry: Option<ToCore> = None;
        loop {
            let msg = match carry.take() {
                Some(m) => Some(m),
                None => match rx.recv_timeout(self.sleep(&timers)) {
                    Ok(m) => Some(m),
                    Err(RecvTimeoutError::Timeout) => None,
                    Err(RecvTimeoutError::Disconnected) => break,
                },
            };
            if !self.batch(msg, &rx, &mut carry) || !self.end_batch(&mut timers) {
                break;
            }
        }
        self.finish();
    }

    /// How long to wait for the next message: until the core's next
    /// deadline or one of this thread's timers, whichever is first.
    fn sleep(&self, timers: &Timers) -> Duration {
        let now = unix_now();
        let tracker = self.front.tracker_timeout(self.tracker_due.get());
        let due =
            [self.front.poll_timeout(), tracker, Some(timers.delay_metrics), Some(timers.receivers_line)]
                .into_iter()
                .flatten()
                .fold(now + MAX_SLEEP_S, f64::min);
        let mut wait = Duration::from_secs_f64((due - now).clamp(0.0, MAX_SLEEP_S));
        if let Some(w) = timers.watchdog {
            wait = wait.min((w / 2).saturating_sub(timers.last_ping.elapsed()));
        }
        wait
    }

    /// Takes `msg` and whatever else is queued, up to a bound, into the
    /// core. False when the service is stopping.
    fn batch(&mut self, mut msg: Option<ToCore>, rx: &Receiver<ToCore>, carry: &mut Option<ToCore>) -> bool {
        let mut n = 0;
        while let Some(m) = msg.take() {
            match m {
                ToCore::Frames { rx: r, arrival, mut frames, from } => {
                    let room = BATCH.saturating_sub(n).max(1);
                    if frames.len() > room {
                        let rest = frames.split_off(room);
                        *carry = Some(ToCore::Frames { rx: r, arrival, frames: rest, from: from.clone() });
                    }
                    from.admission.queued.fetch_sub(frames.len(), Ordering::Relaxed);
                    for frame in &frames {
                        if let Some(w) = &mut self.recorder {
                            w.frame(arrival, r, frame);
                        }
                        self.forward.push(frame);
                        self.front.on_frame(r, arrival, frame, &mut self.cmds);
                    }
                    self.dispatched += frames.len() as u64;
                    n += frames.len();
                    self.registry.queued.fetch_sub(frames.len(), Ordering::Relaxed);
                }
                ToCore::AddReceiver(d) => {
                    n += 1;
                    if let Some(w) = &mut self.recorder {
                        w.receiver(&d, unix_now());
                    }
                    self.front.add_receiver(d);
                }
                ToCore::Outputs(o) => {
                    self.forward = o.frame_forward();
                    if !self.stages.send(Vec::new(), Tick::Outputs(o)) {
                        return false;
                    }
                }
                ToCore::Shutdown => return false,
            }
            // Bounded batches: what a frame produced goes out within a
            // fraction of a millisecond, not after tens of thousands of others.
            if n < BATCH && carry.is_none() {
                msg = rx.try_recv().ok();
            }
        }
        true
    }

    /// Time moved on, the batch's commands to the tracker, the timers that
    /// fell due. False when the tracker is gone.
    fn end_batch(&mut self, timers: &mut Timers) -> bool {
        self.forward.flush();
        let now = unix_now();
        self.front.advance(now, &mut self.cmds);
        if now >= timers.delay_metrics {
            timers.delay_metrics = now + 1.0;
            report::front_metrics(&self.front, self.recorder.as_ref().map(|r| &r.stats), &mut self.announced);
        }
        if now >= timers.receivers_line {
            timers.receivers_line = now + self.stats_every;
            let front = &self.front;
            tracing::info!("{}", front.mlat().receivers_line(now, &|k| front.receiver_id(k).to_string()));
        }
        // The next batch's buffer at this one's size: grown from empty, every
        // batch reallocated it several times (malloc and free were 6% of this
        // thread at 1 M frames/s), as `run --capture` found before.
        let cap = self.cmds.len();
        let cmds = std::mem::replace(&mut self.cmds, Vec::with_capacity(cap));
        if !self.stages.send(cmds, Tick::Batch { now, front: self.snapshot() }) {
            return false;
        }
        if timers.watchdog.is_some_and(|w| timers.last_ping.elapsed() * 2 >= w) {
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
            timers.last_ping = Instant::now();
        }
        true
    }

    fn snapshot(&self) -> report::FrontSnapshot {
        report::FrontSnapshot {
            stats: *self.front.stats(),
            aircraft: self.front.decoder().stats().aircraft_created,
            self_synced_fixes: self.front.mlat().stats.self_synced_fixes,
            dispatched: self.dispatched,
            held: self.front.aircraft_held(),
        }
    }

    /// Everything pending processed and handed over, the learnt state saved,
    /// the tracker and the recording finished.
    fn finish(mut self) {
        self.front.finish(&mut self.cmds);
        if let Some(path) = &self.state_file {
            match self.front.learnt_state(unix_now()).save(path) {
                Ok(()) => tracing::info!(path = %path.display(), "learnt state saved"),
                Err(e) => tracing::error!(path = %path.display(), "learnt state not saved: {e}"),
            }
        }
        let cmds = std::mem::take(&mut self.cmds);
        self.stages.send(cmds, Tick::Batch { now: unix_now(), front: self.snapshot() });
        if let Err(e) = self.stages.finish() {
            tracing::error!("the tracker stopped: {e:#}");
        }
        if let Some(w) = self.recorder {
            w.finish();
        }
    }
}

/// The core's back thread: commands in, tracks and alerts out to the
/// outputs (with the front's events, in order), stats and metrics.
struct BackThread {
    /// The receivers' ids, the front's table, to name them in events.
    names: ReceiverNames,
    outputs: Outputs,
    registry: Arc<Registry>,
    web: Option<web::WebPublisher>,
    stats_every: f64,
    /// Where the tracker's next deadline is left for the front thread.
    due: Arc<Deadline>,
    /// The front's counters, as of its latest batch.
    front: report::FrontSnapshot,
    /// When the last stats line was written, and the fixes counted then:
    /// its rates are of the interval.
    last_stats: (f64, u64),
    next_stats: f64,
    next_metrics: f64,
}

impl Sink for BackThread {
    type With = Tick;

    fn batch(&mut self, back: &Back, events: &[Event], tick: Tick) -> anyhow::Result<()> {
        let now = match tick {
            Tick::Outputs(o) => {
                self.outputs = o;
                return Ok(());
            }
            Tick::Batch { now, front } => {
                self.front = front;
                now
            }
        };
        self.due.set(back.poll_timeout());
        let names = self.names.read();
        self.outputs.publish(events, |i| names.get(i), now);
        drop(names);
        if let Some(w) = &mut self.web {
            w.observe(events, now);
            w.maybe_render(now, self.front.stats.messages, &self.registry);
        }
        let (stats_due, metrics_due) = (now >= self.next_stats, now >= self.next_metrics);
        if stats_due || metrics_due {
            // Read once for both when both fall due.
            let readings = readings::readings(&self.front, back, &self.registry, &self.outputs);
            if stats_due {
                self.stats_line(&readings, now);
                self.next_stats = now + self.stats_every;
            }
            if metrics_due {
                readings.iter().for_each(readings::Reading::export);
                self.next_metrics = now + 1.0;
            }
        }
        Ok(())
    }

    fn end(&mut self, back: &Back) -> anyhow::Result<()> {
        let readings = readings::readings(&self.front, back, &self.registry, &self.outputs);
        self.stats_line(&readings, unix_now());
        outputs::flush_stdout(Duration::from_secs(1));
        Ok(())
    }
}

impl BackThread {
    fn stats_line(&mut self, readings: &[readings::Reading], now: f64) {
        let (last, last_fixes) = self.last_stats;
        let interval = (self.front.stats.fixes - last_fixes, now - last);
        tracing::info!("{}", readings::stats_line(readings, interval));
        self.last_stats = (now, self.front.stats.fixes);
    }
}
