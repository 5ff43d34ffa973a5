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
mod readings;
pub mod record;
pub mod registry;
pub mod replay;
mod report;
pub mod server;
mod service;
pub mod shutdown;
mod stages;
pub mod stamp;
pub mod stream_out;
pub mod web;

use std::path::Path;
use std::sync::Arc;

use anyhow::Result;

use crate::config::Config;
use crate::feed::capture::ReceiverDecl;
use crate::feed::RawFrame;
use outputs::Outputs;

/// Most frames handled between two publications. A batch is whatever is
/// queued up to this, so under light load it is a frame or a few; under
/// heavy load each batch wakes the tracker thread and costs a channel
/// round, and at 973 k frames/s (`live_load`, 60 s, seven alternating
/// pairs) 512 gave an ADS-B-only p99 of 11-50 ms, median 23, against
/// 38-75 ms, median 61, for 128 (better in all seven); 1,024 and 2,048 were
/// no better than 512, and at 1x-6x it changed nothing measurable.
const BATCH: usize = 512;

pub(crate) use service::start_http;
pub use service::{serve, serve_counted, signals, Counters};

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
    rt.block_on(async {
        let (shutdown, reloads) = signals(config_path.to_path_buf())?;
        serve(cfg, None, shutdown, reloads).await
    })
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
