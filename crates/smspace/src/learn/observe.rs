//! Learning's stages as the progress observer sees them ([`crate::progress::Progress`]):
//! every stage that can take long starts with its name and its units of work, advances
//! as chunks of rows complete, and finishes. The stages, in order:
//!
//! | stage | units | what |
//! |---|---|---|
//! | [`NOISE`] | logs | the noise and rank estimate of every log |
//! | [`SENSOR_TREE`] | logs | `invariants`: the k-d tree of the fitted samples in sensor space |
//! | [`PAIRS`] | samples | `invariants`: each fitted sample's nearest sensory neighbour |
//! | [`BASIS`] | samples | `invariants`: the sums of `Σ` and `C` over the pairs |
//! | [`EIGEN`] | solves | `invariants`: the generalised eigenproblem, solved again after each round of setting aliased pairs aside |
//! | [`HELD_PAIRS`] | samples | `invariants`: the invariants' change between each held-out sample and its nearest fitted sample in sensor space |
//! | [`TREE`] | steps | the k-d tree of a log's fitted samples (the bandwidth, then the periodic images) |
//! | [`INVARIANT_TREE`] | steps | `invariants`: the k-d tree of the fitted samples' invariants |
//! | [`HELD_OUT`] | samples | the law at the held-out samples (the local fits there; for `invariants`, `ŝ = g(z)`) |
//! | [`RANK`] | probes | the rank of the law's Jacobian at seeded samples |
//!
//! (The local fits: [`NOISE`], [`TREE`], [`HELD_OUT`] for every log, then [`RANK`];
//! `invariants`: every stage, the last four for every log.) Tracing follows, as the
//! stage `trace` of [`crate::kernel::trace_sets`].
//!
//! Work is cut into chunks of rows that depend on the row count alone, and the results
//! are gathered in row order: the observer changes nothing in the result.

use rayon::prelude::*;

use crate::progress::Progress;

/// The noise and rank estimate.
pub const NOISE: &str = "noise";
/// A k-d tree of motor samples.
pub const TREE: &str = "k-d tree";
/// The k-d tree of sensor values.
pub const SENSOR_TREE: &str = "sensor tree";
/// Nearest sensory neighbours.
pub const PAIRS: &str = "pairs";
/// The basis sums.
pub const BASIS: &str = "basis sums";
/// The eigenproblem.
pub const EIGEN: &str = "eigen";
/// The invariants' change between held-out samples and their sensory neighbours.
pub const HELD_PAIRS: &str = "held pairs";
/// The k-d tree of the fitted samples' invariants.
pub const INVARIANT_TREE: &str = "z tree";
/// The held-out samples.
pub const HELD_OUT: &str = "held out";
/// The rank of the law's Jacobian.
pub const RANK: &str = "rank";

/// Rows per unit of progress reported at once.
pub(super) const CHUNK: usize = 4096;

/// Runs `work` as the stage `name` of `total` units: started before, finished after
/// (`work` advances it).
pub(super) fn stage<T>(
    progress: &dyn Progress,
    name: &str,
    total: u64,
    work: impl FnOnce() -> T,
) -> T {
    progress.start(name, total);
    let out = work();
    progress.finish();
    out
}

/// `f(row)` for every row, in parallel, in row order, advancing `progress` by each
/// chunk of rows (at most [`CHUNK`], a 64th of them) as it completes.
pub(super) fn map_rows<T: Send>(
    rows: &[u32],
    progress: &dyn Progress,
    f: impl Fn(u32) -> T + Sync + Send,
) -> Vec<T> {
    // Small enough that a few thousand rows still spread over the threads.
    let chunk = (rows.len() / 64).clamp(1, CHUNK);
    rows.par_chunks(chunk)
        .flat_map_iter(|chunk| {
            let out: Vec<T> = chunk.iter().map(|&row| f(row)).collect();
            progress.advance(chunk.len() as u64);
            out
        })
        .collect()
}
