//! The receivers' ids, in the order they were declared: the name of the
//! index (`rx`) that events carry.
//!
//! The front stage declares receivers and owns this table; whoever writes
//! events out (the back stage's thread, an output, a capture's writer)
//! holds a handle to the same table to name them. No stage keeps a copy
//! filled by a command. Receivers are only ever added, so an index stays
//! valid, and a writer that reads the table later than the event was made
//! finds the receiver all the same.

use std::sync::{Arc, PoisonError, RwLock, RwLockReadGuard};

/// A handle to the table; clones share it.
#[derive(Clone, Debug, Default)]
pub struct ReceiverNames(Arc<RwLock<Vec<Arc<str>>>>);

impl ReceiverNames {
    /// Declares the next receiver (the front stage's, as it declares it).
    pub(crate) fn push(&self, id: &str) {
        self.0.write().unwrap_or_else(PoisonError::into_inner).push(id.into());
    }

    /// The table as it is, for naming a batch of events (one lock a batch,
    /// not one a name).
    pub fn read(&self) -> Names<'_> {
        Names(self.0.read().unwrap_or_else(PoisonError::into_inner))
    }
}

/// The table, read.
pub struct Names<'a>(RwLockReadGuard<'a, Vec<Arc<str>>>);

impl Names<'_> {
    /// Receiver `rx`'s id ("?" for an index never declared).
    pub fn get(&self, rx: usize) -> &str {
        self.0.get(rx).map_or("?", |id| id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_handle_names_what_the_front_declares_after_it_was_taken() {
        let front = ReceiverNames::default();
        let writer = front.clone();
        front.push("a");
        front.push("b");
        let names = writer.read();
        assert_eq!((names.get(0), names.get(1), names.get(2)), ("a", "b", "?"));
    }
}
