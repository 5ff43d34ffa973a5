//! The core's two stages on two threads: the one runner that `run
//! --capture` and the daemon share.
//!
//! The front stage (decoding, grouping, multilateration) runs on the
//! caller's thread, driven by whatever feeds it: a capture's records with
//! their own times, or sockets and the clock with deadlines. It sends its
//! commands in batches over a bounded queue to the back stage's thread,
//! which applies them in order (tracking, fusion) and hands each batch's
//! events, the front's and its own interleaved as one thread would make
//! them, to a [`Sink`]: the capture's file, or the daemon's outputs, map
//! and metrics. Nothing flows back, so the events are the same whichever
//! thread made them and however the batches were cut.
//!
//! The bound on the queue is the back pressure: a tracker that falls
//! behind stops the front, which (live) leaves frames in the inputs' queue,
//! where they are counted if dropped.

use std::sync::mpsc::{sync_channel, SyncSender};
use std::thread::JoinHandle;

use anyhow::{Context, Result};

use crate::core::{Back, Cmd, Event};

/// What the back stage's thread does with the events.
pub trait Sink: Send + 'static {
    /// What the front thread sends with a batch besides its commands (its
    /// events already written out, its counters, the time).
    type With: Send + 'static;

    /// A batch applied: `events` are what its commands made, in order. An
    /// error stops the thread, and the front's next send says so.
    fn batch(&mut self, back: &Back, events: &[Event], with: Self::With) -> Result<()>;

    /// After the last batch.
    fn end(&mut self, back: &Back) -> Result<()>;
}

/// The back stage's thread and the queue to it.
pub struct TwoStages<S: Sink> {
    to_back: SyncSender<(Vec<Cmd>, S::With)>,
    thread: JoinHandle<(Back, S, Result<()>)>,
}

impl<S: Sink> TwoStages<S> {
    /// Starts the back stage's thread, named `name` (so `top -H` and
    /// `perf` tell the stages apart), behind a queue of `queue` batches.
    pub fn start(name: &str, mut back: Back, mut sink: S, queue: usize) -> Result<TwoStages<S>> {
        let (to_back, batches) = sync_channel::<(Vec<Cmd>, S::With)>(queue);
        let thread = std::thread::Builder::new()
            .name(name.to_string())
            .spawn(move || {
                let mut events = Vec::new();
                let run = || -> Result<()> {
                    for (cmds, with) in batches {
                        back.apply(cmds, &mut events);
                        sink.batch(&back, &events, with)?;
                        events.clear();
                    }
                    sink.end(&back)
                };
                let res = run();
                (back, sink, res)
            })
            .with_context(|| format!("cannot start the {name} thread"))?;
        Ok(TwoStages { to_back, thread })
    }

    /// Hands a batch to the back stage, waiting while its queue is full.
    /// False once the back stage has stopped (its error comes with `finish`).
    pub fn send(&self, cmds: Vec<Cmd>, with: S::With) -> bool {
        self.to_back.send((cmds, with)).is_ok()
    }

    /// No more batches: waits for the back stage to apply what it has, and
    /// returns it with its sink (for their counters), or why it stopped.
    pub fn finish(self) -> Result<(Back, S)> {
        drop(self.to_back);
        let (back, sink, res) =
            self.thread.join().map_err(|_| anyhow::anyhow!("the back stage's thread panicked"))?;
        res.map(|()| (back, sink))
    }
}
