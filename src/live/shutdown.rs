//! Telling the service's tasks to stop, as mini-redis does: every task is
//! handed a [`Shutdown`] and ends itself when it fires, instead of being
//! aborted from outside. A task that is told finishes where it stands: an
//! input's connections close with it (their watch ends with the task), and
//! the caller can wait for it to be gone before binding its port again.
//!
//! One [`Stopper`] per set of tasks that stop together: the inputs (a
//! reload replaces them), and everything else at the service's end.
//! Dropping the stopper fires every `Shutdown` made from it.

use std::future::Future;

use tokio::sync::watch;
use tokio::task::JoinHandle;

/// Fires every [`Shutdown`] made from it when dropped (or [`Stopper::stop`]).
pub struct Stopper {
    /// Never sent on: its end is the signal.
    _fires_when_dropped: watch::Sender<()>,
}

/// A task's view of its [`Stopper`]: `fired` completes once it is dropped.
#[derive(Clone)]
pub struct Shutdown(watch::Receiver<()>);

impl Stopper {
    pub fn new() -> (Stopper, Shutdown) {
        let (tx, rx) = watch::channel(());
        (Stopper { _fires_when_dropped: tx }, Shutdown(rx))
    }

    /// Fires its shutdowns (the same as dropping it, said out loud).
    pub fn stop(self) {}
}

impl Shutdown {
    /// Completes once the stopper is gone.
    pub async fn fired(&mut self) {
        // Nothing is ever sent: the only way out is the sender's end.
        while self.0.changed().await.is_ok() {}
    }

    /// Runs `task` on the runtime until it ends or this fires.
    pub fn spawn(&self, task: impl Future<Output = ()> + Send + 'static) -> JoinHandle<()> {
        let mut stop = self.clone();
        tokio::spawn(async move {
            tokio::select! {
                () = task => {}
                () = stop.fired() => {}
            }
        })
    }
}

/// Tasks that stop together: the stopper that tells them and their handles.
pub struct Tasks {
    stopper: Stopper,
    shutdown: Shutdown,
    handles: Vec<JoinHandle<()>>,
}

impl Default for Tasks {
    fn default() -> Self {
        let (stopper, shutdown) = Stopper::new();
        Tasks { stopper, shutdown, handles: Vec::new() }
    }
}

impl Tasks {
    /// What tells them to stop, for a task started elsewhere.
    pub fn shutdown(&self) -> &Shutdown {
        &self.shutdown
    }

    /// A task started with [`Tasks::shutdown`], to be waited for.
    pub fn push(&mut self, task: JoinHandle<()>) {
        self.handles.push(task);
    }

    /// Runs `task` among them (see [`Shutdown::spawn`]).
    pub fn spawn(&mut self, task: impl Future<Output = ()> + Send + 'static) {
        let handle = self.shutdown.spawn(task);
        self.handles.push(handle);
    }

    /// Tells them to stop and waits, at most `limit`, until they have.
    /// Returns how many had not ended by then.
    pub async fn stop(self, limit: std::time::Duration) -> usize {
        drop(self.stopper);
        join_all(self.handles, limit).await
    }
}

/// Waits, at most `limit`, for `tasks` to end (told to by their stopper).
/// Returns how many had not ended by then.
async fn join_all(tasks: Vec<JoinHandle<()>>, limit: std::time::Duration) -> usize {
    let deadline = tokio::time::Instant::now() + limit;
    let mut late = 0;
    for t in tasks {
        if tokio::time::timeout_at(deadline, t).await.is_err() {
            late += 1;
        }
    }
    late
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[test]
    fn dropping_the_stopper_ends_every_task_made_from_it() {
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        rt.block_on(async {
            let (stopper, shutdown) = Stopper::new();
            let tasks: Vec<_> = (0..3).map(|_| shutdown.spawn(std::future::pending())).collect();
            let (other, other_shutdown) = Stopper::new();
            let survivor = other_shutdown.spawn(std::future::pending());
            tokio::time::sleep(Duration::from_millis(20)).await;
            assert!(tasks.iter().all(|t| !t.is_finished()));
            stopper.stop();
            assert_eq!(join_all(tasks, Duration::from_secs(1)).await, 0);
            assert!(!survivor.is_finished(), "another stopper's task stopped too");
            drop(other);
            assert_eq!(join_all(vec![survivor], Duration::from_secs(1)).await, 0);
        });
    }
}
