//! `fuse1090 run`: the pipeline, live (the daemon) or offline over a capture.
//! Offline it is deterministic and as fast as the CPU allows, driven by the
//! capture's own arrival times.

use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};

use crate::config::Config;
use crate::core::{Back, Cmd, Core, Event, Front, ReceiverNames};
use crate::feed::capture::{CaptureReader, CaptureRecord};
use crate::publish::json::write_event;
use crate::stages::{Sink, TwoStages};

pub struct RunArgs {
    pub config: Option<PathBuf>,
    pub capture: Option<PathBuf>,
    pub output: Option<PathBuf>,
    pub source_tracks: bool,
}

/// What an offline run did; printed as one line on stdout, with
/// `diagnostics` (the multilateration and tracking reports, the skipped
/// lines) for stderr. Returned rather than printed, so that a library
/// caller (a test, a benchmark) decides what is shown.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    pub frames: u64,
    pub messages: u64,
    pub aircraft: u64,
    pub fixes: u64,
    pub tracks: u64,
    pub positions: u64,
    pub skipped_lines: u64,
    pub span_s: f64,
    pub elapsed_s: f64,
    pub diagnostics: Vec<String>,
}

impl Summary {
    /// The part that depends only on the input (no wall-clock figures).
    pub fn deterministic(&self) -> String {
        format!(
            "frames={} messages={} aircraft={} fixes={} tracks={} positions={} skipped_lines={} span_s={:.3}",
            self.frames,
            self.messages,
            self.aircraft,
            self.fixes,
            self.tracks,
            self.positions,
            self.skipped_lines,
            self.span_s
        )
    }
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} elapsed_s={:.3} rate={:.0}/s",
            self.deterministic(),
            self.elapsed_s,
            self.frames as f64 / self.elapsed_s.max(1e-9)
        )
    }
}

pub fn run(args: RunArgs) -> Result<()> {
    let mut cfg = match &args.config {
        Some(p) => Config::load(p)?,
        None => Config::default(),
    };
    cfg.publish_source_tracks |= args.source_tracks;
    if cfg.cluster.is_some() {
        cfg.core.publish_source_tracks = cfg.publish_source_tracks;
        return crate::cluster::run(
            &cfg,
            args.config.as_deref(),
            args.capture.as_deref(),
            args.output.as_deref(),
        );
    }
    match (&args.capture, &args.output) {
        (Some(capture), Some(output)) => {
            let summary = run_capture(&cfg, capture, output)?;
            for line in &summary.diagnostics {
                eprintln!("{line}");
            }
            super::print_stdout(&format!("{summary}\n"))
        }
        (Some(_), None) => bail!("--capture needs --output"),
        (None, _) if args.config.is_none() => bail!("run needs --config (live) or --capture (offline)"),
        (None, _) => crate::live::run(args.config.as_deref().expect("checked above")),
    }
}

/// Records per batch handed from the parsing thread to the core.
const BATCH: usize = 4096;

/// The front stage's own ADS-B reports and MLAT fixes of a batch, already
/// written as JSON lines: `text[ends[k-1]..ends[k]]` is the k-th. The back stage is the pipeline's critical path and those
/// events are over half of the output's bytes, so the front's thread, which
/// had time to spare, writes them.
struct Written {
    text: Vec<u8>,
    ends: Vec<usize>,
}

impl Written {
    /// A batch's commands, and its front events written.
    fn of(cmds: Vec<Cmd>, front: &Front) -> (Vec<Cmd>, Written) {
        // Sized for the batch's events up front (a record is 200-300
        // bytes): growing from empty copied each batch's text five times.
        let events = cmds.iter().filter(|c| matches!(c, Cmd::Event(ev) if Self::from_front(ev))).count();
        let (mut text, mut ends) = (Vec::with_capacity(events * 320), Vec::with_capacity(events));
        for c in &cmds {
            if let Cmd::Event(ev) = c {
                if Self::from_front(ev) {
                    write_event(&mut text, ev, |i| front.receiver_id(i));
                    ends.push(text.len());
                }
            }
        }
        (cmds, Written { text, ends })
    }

    /// The events the front stage makes that it writes (the back makes tracks and alerts).
    fn from_front(ev: &Event) -> bool {
        matches!(ev, Event::Position(_) | Event::Mlat(_))
    }
}

/// The back stage's sink of `run --capture`: the events written to the
/// file in order, the front's already as text, the back's written here
/// between them.
struct FileSink {
    out: BufWriter<File>,
    names: ReceiverNames,
    line: Vec<u8>,
}

impl Sink for FileSink {
    type With = Written;

    fn batch(&mut self, _: &Back, events: &[Event], written: Written) -> Result<()> {
        let names = self.names.read();
        let mut ends = written.ends.iter();
        let mut start = 0;
        for ev in events {
            let res = if Written::from_front(ev) {
                let end = *ends.next().context("a front event without its text")?;
                let text = &written.text[start..end];
                start = end;
                self.out.write_all(text)
            } else {
                self.line.clear();
                write_event(&mut self.line, ev, |i| names.get(i));
                self.out.write_all(&self.line)
            };
            res.context("writing output")?;
        }
        Ok(())
    }

    fn end(&mut self, _: &Back) -> Result<()> {
        self.out.flush().context("writing output")
    }
}

/// Runs a capture file through the core and writes the event stream.
///
/// Three threads for the machine's two cores: one parses the capture into
/// batches, one runs the core's front stage (decoding, grouping, MLAT,
/// conformance) and writes its events' JSON, one its back stage (tracking,
/// fusion) and writes the file. Batches keep the file's order and nothing
/// flows back from the back stage, so the output is the same bytes as a
/// single-threaded run.
pub fn run_capture(cfg: &Config, capture: &Path, output: &Path) -> Result<Summary> {
    let started = Instant::now();
    let file = File::open(capture).with_context(|| format!("cannot open {}", capture.display()))?;
    let out_file = File::create(output).with_context(|| format!("cannot create {}", output.display()))?;
    let name = capture.display().to_string();
    let (tx, rx) = std::sync::mpsc::sync_channel::<Vec<CaptureRecord>>(8);
    // Named so `top -H` and `perf report --sort comm` tell the stages apart.
    let parser =
        named_thread("capture-parse", move || -> Result<(u64, Vec<crate::feed::capture::LineError>)> {
            yield_to_the_core_stages();
            let mut reader = CaptureReader::new(BufReader::with_capacity(1 << 20, file), name.clone());
            let mut batch = Vec::with_capacity(BATCH);
            while let Some(rec) = reader.next_record().with_context(|| format!("reading {name}"))? {
                batch.push(rec);
                if batch.len() == BATCH
                    && tx.send(std::mem::replace(&mut batch, Vec::with_capacity(BATCH))).is_err()
                {
                    break;
                }
            }
            if !batch.is_empty() {
                let _ = tx.send(batch);
            }
            Ok((reader.skipped, reader.errors))
        })?;
    let mut core_cfg = cfg.core.clone();
    core_cfg.publish_source_tracks = cfg.publish_source_tracks;
    let (mut front, back) = Core::stages(&core_cfg);
    front.know(cfg.known_receivers());
    let sink = FileSink {
        out: BufWriter::with_capacity(1 << 20, out_file),
        names: front.receiver_names(),
        line: Vec::new(),
    };
    let stages = TwoStages::start("core-back", back, sink, 8)?;
    let (mut first, mut last) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut cmds = Vec::new();
    for batch in rx {
        for rec in batch {
            if let CaptureRecord::Frame(f) = &rec {
                first = first.min(f.arrival);
                last = last.max(f.arrival);
            }
            front.on_record(rec, &mut cmds);
        }
        // A writer that stopped (an output error) says why when finished.
        // The next batch's buffer at this one's size: growing a vector of
        // commands from empty every batch cost more than the commands' moves.
        let cap = cmds.len();
        let (cmds, text) = Written::of(std::mem::replace(&mut cmds, Vec::with_capacity(cap)), &front);
        if !stages.send(cmds, text) {
            break;
        }
    }
    let (skipped, errors) = parser.join().map_err(|_| anyhow::anyhow!("capture reader panicked"))??;
    front.finish(&mut cmds);
    let (cmds, text) = Written::of(cmds, &front);
    stages.send(cmds, text);
    let (back, _) = stages.finish()?;
    let diagnostics = diagnostics(&front, &back, last, &errors, skipped);
    let s = front.stats();
    Ok(Summary {
        frames: s.frames,
        messages: s.messages,
        aircraft: front.decoder().stats().aircraft_created,
        fixes: s.fixes,
        tracks: back.fuser().stats().tracks_created,
        positions: s.positions,
        skipped_lines: skipped,
        span_s: if last >= first { last - first } else { 0.0 },
        elapsed_s: started.elapsed().as_secs_f64(),
        diagnostics,
    })
}

/// The run's reports for stderr: multilateration, its receivers, the
/// network delays learnt, late copies, tracking, and the lines skipped.
fn diagnostics(
    front: &Front,
    back: &Back,
    last: f64,
    errors: &[crate::feed::capture::LineError],
    skipped: u64,
) -> Vec<String> {
    let name = |k: usize| front.receiver_id(k).to_string();
    let mut diagnostics = vec![front.mlat().report(last, &name), front.mlat().receivers_line(last, &name)];
    diagnostics.extend(front.delay_report());
    diagnostics.extend(front.air_report());
    let late = front.late_copies();
    if !late.is_empty() {
        let by_rx: Vec<String> = late.iter().take(6).map(|(id, n)| format!("{id} {n}")).collect();
        diagnostics.push(format!(
            "grouping: {} late copies (arrived after their transmission was processed: not decoded again): {}",
            front.stats().late_copies,
            by_rx.join(", ")
        ));
    }
    diagnostics.push(format!("tracking: {}", back.fuser().stats()));
    diagnostics.extend(errors.iter().map(|e| format!("fuse1090: skipped {e}")));
    if skipped > errors.len() as u64 {
        diagnostics.push(format!("fuse1090: ... {skipped} malformed lines skipped in all"));
    }
    diagnostics
}

/// Lowers the calling thread's priority (nice 10). The parser needs about
/// a fifth of a core while the two core stages need both: at the same
/// priority it took its turns from them, the back stage on the critical
/// path among them, and `run --capture` on the scale world took 7-10%
/// longer. It still runs whenever a core stage waits for work, and it
/// cannot fall behind for long: they wait for its batches.
fn yield_to_the_core_stages() {
    #[cfg(target_os = "linux")]
    // SAFETY: gettid and setpriority take and return plain integers. On
    // Linux, PRIO_PROCESS with a thread id changes that one thread's nice
    // value; raising it needs no privilege, and a failure leaves it as it was.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t, 10);
    }
}

fn named_thread<T: Send + 'static>(
    name: &str,
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<std::thread::JoinHandle<T>> {
    std::thread::Builder::new()
        .name(name.to_string())
        .spawn(f)
        .with_context(|| format!("cannot start the {name} thread"))
}
