//! # smspace
//!
//! A *naive* sensorimotor agent discovers its own spatial configuration from
//! sensorimotor invariants, after Laflaquière, O'Regan, Argentieri, Gas & Terekhov,
//! "Learning agent's spatial configuration from sensorimotor invariants" (Robotics and
//! Autonomous Systems, 2015).
//!
//! The agent knows only motor commands `m ∈ ℝ^N` and raw sensor values
//! `s = σ_E(m) ∈ ℝ^K` in an environment `E` (paper eq. 2). Motor configurations that
//! give the same sensory input form the sets `M^s = { m | σ_E(m) = s }`, the kernels of
//! `σ_E − s` (section 2.3). These sets do not depend on the environment; a metric
//! between them gives a manifold that is, seen from outside, the configuration space of
//! the agent's sensor.
//!
//! The modules follow the pipeline:
//!
//! 1. [`agent`]: agents and environments, the sensorimotor law `s = σ_E(m)`;
//! 2. [`explore`]: motor babbling in a working space, and the probe grid;
//! 3. [`kernel`]: tracing the sets `M^i` along the Jacobian's null space (appendix A);
//!    [`learn`]: the same from a recorded log, through a law `ŝ(m)` learned from the data
//!    (section 3.2, step 2);
//! 4. [`metric`]: the periodic Hausdorff distance between sets, as a full matrix, a block
//!    of rows, or the `k` nearest sets (section 3.2, step 3);
//! 5. [`embed`]: coordinates for the manifold of sets from its distance matrix (CCA,
//!    Isomap, classical MDS; section 3.2);
//! 6. [`analysis`]: topology, dimension and agreement with the poses of the learned
//!    metric (section 3.3), and [`invariance`], the experiment that traces the same
//!    starts in several environments (sections 2.2, 2.3, 3.3).
//!
//! On the ground floor, the types every stage shares: [`params`] (checked parameters),
//! [`sets`] (closure records, set views, kernel shapes), [`matrix`] (the validated
//! distance matrix), [`registry`] (agents, metrics and embedding methods by name),
//! [`neighbours`] (the one landmark picker, kNN search and trustworthiness), [`io`]
//! (`.npy` and JSON interchange), [`progress`] (observers for long stages) and
//! [`threads`]; [`error`] wraps every module's error. No module imports one above it
//! (`tests/layers.rs`).
//!
//! The figures, the report and the cached run of every stage from an experiment file
//! are the `smspace-pipeline` crate, which depends on this one.
//!
//! The library never prints: progress goes through [`progress::Progress`], and every
//! failure a user can cause is a [`Result`] carrying the offending file or value.

pub mod agent;
pub mod analysis;
pub mod embed;
pub mod error;
pub mod explore;
pub mod invariance;
pub mod io;
pub mod kernel;
pub mod learn;
mod linalg;
pub mod matrix;
pub mod metric;
pub mod neighbours;
pub mod params;
pub mod progress;
pub mod registry;
pub mod sets;
pub mod threads;

pub use error::{Error, Result};

/// The README's library example, compiled and run as a doc test (`cargo test --doc`),
/// so that the README cannot drift from the library.
#[cfg(doctest)]
#[doc = include_str!("../../../README.md")]
pub struct ReadmeDoctests;

/// The guide's library chapter (`docs/library.md`), its example run as a doc test too.
#[cfg(doctest)]
#[doc = include_str!("../../../docs/library.md")]
pub struct GuideLibraryDoctests;
