//! Progress reporting without printing: long stages call an observer, and the caller
//! (the command-line tool draws a progress bar) decides what to show.

/// Receives progress of a long stage. Both methods default to doing nothing.
///
/// Implementations must be `Sync`: parallel stages call them from worker threads.
pub trait Progress: Sync {
    /// A stage starts with `total` units of work.
    fn start(&self, _stage: &str, _total: u64) {}
    /// `done` more units of work are complete.
    fn advance(&self, _done: u64) {}
    /// The stage is over.
    fn finish(&self) {}
}

/// A [`Progress`] that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {}
