//! The live recording (`[service] record`): every frame received, as a
//! capture file that `fuse1090 replay` and `run --capture` read.
//!
//! Bounded on disk: the file is rotated when it reaches `record_max_bytes`
//! or `record_max_age_s`, like logrotate (`FILE` → `FILE.1` → ... →
//! `FILE.N`, `N = record_keep`, the oldest deleted), and each new file
//! declares every receiver again, so that each is a capture of its own. A
//! write error (a full disk) never stops the service: it is counted and
//! logged (rate-limited), the frames meanwhile are counted as not recorded,
//! and a fresh file is tried again after [`RETRY_S`]. Only a regular file
//! is ever renamed or deleted: a recording to a device (`/dev/null`) or a
//! pipe is written, never rotated.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::feed::capture::{CaptureWriter, ReceiverDecl};
use crate::feed::RawFrame;

use super::loglimit::LogGate;

/// After a write error, seconds before a fresh file is tried.
pub const RETRY_S: f64 = 10.0;

/// Where and how much to record.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordLimits {
    pub path: PathBuf,
    pub max_bytes: u64,
    pub max_age_s: f64,
    /// Rotated files kept beside the current one.
    pub keep: usize,
}

/// Bytes that went into the writer (the file's size once flushed).
struct Counted<W> {
    inner: W,
    bytes: u64,
}

impl<W: Write> Write for Counted<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.bytes += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

type Writer = CaptureWriter<Counted<BufWriter<File>>>;

/// What the recording did, for the metrics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RecordStats {
    pub frames: u64,
    /// Frames not recorded: written when an error came, or while waiting
    /// to try a fresh file.
    pub dropped: u64,
    pub write_errors: u64,
    pub rotations: u64,
}

pub struct Recorder {
    limits: RecordLimits,
    out: Option<Writer>,
    /// Every receiver declared so far, in index order: each file declares all.
    decls: Vec<ReceiverDecl>,
    opened_at: f64,
    retry_at: f64,
    pub stats: RecordStats,
    error_log: LogGate,
}

impl Recorder {
    /// Creates the recording; an error here (a directory that does not
    /// exist, no permission) is the operator's to fix, at start.
    pub fn open(limits: RecordLimits, now: f64) -> io::Result<Recorder> {
        let out = Some(create(&limits.path)?);
        Ok(Recorder {
            limits,
            out,
            decls: Vec::new(),
            opened_at: now,
            retry_at: f64::NEG_INFINITY,
            stats: RecordStats::default(),
            error_log: LogGate::default(),
        })
    }

    pub fn receiver(&mut self, d: &ReceiverDecl, now: f64) {
        self.decls.push(d.clone());
        if let Some(w) = &mut self.out {
            if let Err(e) = w.receiver(d) {
                self.failed(e, now);
            }
        }
    }

    pub fn frame(&mut self, arrival: f64, rx: usize, frame: &RawFrame) {
        if self.due(arrival) {
            self.rotate(arrival);
        }
        let Some(w) = &mut self.out else {
            self.stats.dropped += 1;
            return;
        };
        match w.frame(arrival, rx, frame) {
            Ok(()) => self.stats.frames += 1,
            Err(e) => {
                self.stats.dropped += 1;
                self.failed(e, arrival);
            }
        }
    }

    /// Flushes and syncs the current file (at shutdown).
    pub fn finish(mut self) {
        if let Some(w) = self.out.take() {
            let done =
                w.into_inner().inner.into_inner().map_err(|e| e.into_error()).and_then(|f| f.sync_all());
            if let Err(e) = done {
                self.stats.write_errors += 1;
                tracing::error!(path = %self.limits.path.display(), "recording: {e}");
            }
        }
    }

    fn due(&self, now: f64) -> bool {
        match &self.out {
            None => now >= self.retry_at,
            Some(w) => {
                w.get_ref().bytes >= self.limits.max_bytes || now - self.opened_at >= self.limits.max_age_s
            }
        }
    }

    fn failed(&mut self, e: io::Error, now: f64) {
        self.stats.write_errors += 1;
        self.out = None;
        self.retry_at = now + RETRY_S;
        if let Some(held) = self.error_log.pass(now) {
            tracing::error!(
                path = %self.limits.path.display(),
                errors = self.stats.write_errors,
                held_back = held,
                "recording: {e}; frames not recorded until a fresh file can be written (the service goes on)"
            );
        }
    }

    /// The current file becomes `.1` (and so on up to `keep`), and a fresh
    /// one declares every receiver.
    fn rotate(&mut self, now: f64) {
        if let Some(w) = self.out.take() {
            if let Err(e) = w.into_inner().flush() {
                self.stats.write_errors += 1;
                tracing::warn!(path = %self.limits.path.display(), "recording: {e}");
            }
        }
        if let Err(e) = shift(&self.limits.path, self.limits.keep) {
            tracing::warn!(path = %self.limits.path.display(), "recording: rotation: {e}");
        }
        let fresh = create(&self.limits.path).and_then(|mut w| {
            self.decls.iter().try_for_each(|d| w.receiver(d).map(drop))?;
            Ok(w)
        });
        self.opened_at = now;
        self.stats.rotations += 1;
        match fresh {
            Ok(w) => self.out = Some(w),
            Err(e) => self.failed(e, now),
        }
    }
}

fn create(path: &Path) -> io::Result<Writer> {
    let file = File::create(path)?;
    CaptureWriter::new(Counted { inner: BufWriter::new(file), bytes: 0 }, "fuse1090 live recording")
}

/// `path.{keep-1}` → `path.{keep}` ... `path` → `path.1`; the oldest beyond
/// `keep` deleted. Regular files only.
fn shift(path: &Path, keep: usize) -> io::Result<()> {
    let regular = |p: &Path| std::fs::symlink_metadata(p).is_ok_and(|m| m.file_type().is_file());
    if !regular(path) {
        return Ok(());
    }
    let numbered = |k: usize| {
        let mut s = path.as_os_str().to_owned();
        s.push(format!(".{k}"));
        PathBuf::from(s)
    };
    if keep == 0 {
        return std::fs::remove_file(path);
    }
    if regular(&numbered(keep)) {
        std::fs::remove_file(numbered(keep))?;
    }
    for k in (1..keep).rev() {
        if regular(&numbered(k)) {
            std::fs::rename(numbered(k), numbered(k + 1))?;
        }
    }
    std::fs::rename(path, numbered(1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::feed::capture::{CaptureReader, CaptureRecord, ClockKind};

    fn decl(id: &str) -> ReceiverDecl {
        ReceiverDecl { id: id.into(), lat: 43.6, lon: 1.4, alt: 150.0, clock: ClockKind::Beast12 }
    }

    fn frame(k: u64) -> RawFrame {
        RawFrame::new(&[0x5d, 0x4b, 0x1a, 0x2b, 0, 0, (k % 256) as u8], k, 0).unwrap()
    }

    /// Frames and receivers of a capture file.
    fn read(path: &Path) -> (Vec<String>, usize) {
        let text = std::fs::read(path).unwrap();
        let mut r = CaptureReader::new(text.as_slice(), "rec");
        let mut frames = 0;
        while let Some(rec) = r.next_record().unwrap() {
            frames += matches!(rec, CaptureRecord::Frame(_)) as usize;
        }
        assert!(r.errors.is_empty(), "{:?}", r.errors);
        (r.receivers().iter().map(|d| d.id.clone()).collect(), frames)
    }

    #[test]
    fn rotates_by_size_and_time_keeps_a_bounded_number_of_whole_captures() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rec.txt");
        let limits = RecordLimits { path: path.clone(), max_bytes: 20_000, max_age_s: 30.0, keep: 3 };
        let mut r = Recorder::open(limits, 0.0).unwrap();
        r.receiver(&decl("a"), 0.0);
        // About 45 bytes a frame: a file every ~440 frames; 5,000 frames in 10 s.
        for k in 0..5000u64 {
            if k == 2000 {
                r.receiver(&decl("b"), 4.0);
            }
            r.frame(k as f64 * 0.002, (k >= 2000 && k % 2 == 1) as usize, &frame(k));
        }
        let rotations = r.stats.rotations;
        assert!(rotations >= 10, "{rotations}");
        r.finish();
        let mut names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, ["rec.txt", "rec.txt.1", "rec.txt.2", "rec.txt.3"]);
        for name in &names {
            let p = dir.path().join(name);
            assert!(std::fs::metadata(&p).unwrap().len() < 20_000 + 200, "{name}");
            let (rxs, frames) = read(&p);
            assert_eq!(rxs, ["a", "b"], "{name} declares every receiver");
            assert!(frames > 100, "{name}: {frames}");
        }
        // By time too: a quiet receiver's file rotates after max_age_s.
        let path = dir.path().join("slow.txt");
        let limits = RecordLimits { path, max_bytes: u64::MAX, max_age_s: 30.0, keep: 2 };
        let mut r = Recorder::open(limits, 0.0).unwrap();
        r.receiver(&decl("a"), 0.0);
        for k in 0..100u64 {
            r.frame(k as f64, 0, &frame(k));
        }
        assert_eq!(r.stats.rotations, 3);
    }

    /// `/dev/full` fails every write with "no space left": counted, the
    /// frames counted as not recorded, nothing renamed, and no panic.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_full_disk_is_counted_and_never_stops_the_caller() {
        let full = Path::new("/dev/full");
        if !full.exists() {
            return;
        }
        let limits = RecordLimits { path: full.into(), max_bytes: 1 << 30, max_age_s: 3600.0, keep: 2 };
        let mut r = Recorder::open(limits, 0.0).unwrap();
        r.receiver(&decl("a"), 0.0);
        for k in 0..20_000u64 {
            r.frame(k as f64 * 0.001, 0, &frame(k));
        }
        // One error per try: the first buffer's flush, then one every RETRY_S.
        assert_eq!(r.stats.write_errors, 2, "{:?}", r.stats);
        assert_eq!(r.stats.frames + r.stats.dropped, 20_000);
        assert!(r.stats.dropped > 10_000, "{:?}", r.stats);
        assert!(full.exists() && !Path::new("/dev/full.1").exists());
    }
}
