//! The crate-wide error: one variant per pipeline stage, each wrapping that stage's own
//! `thiserror` enum, so that a caller can handle "any smspace error" with one type and
//! still match on the stage that failed.

use crate::{
    agent::AgentError, analysis::AnalysisError, config::ConfigError, explore::ExploreError,
    io::IoError, kernel::KernelError, metric::MetricError,
};

/// Any error of the smspace library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(#[from] IoError),
    /// A configuration file is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An agent or environment is invalid.
    #[error(transparent)]
    Agent(#[from] AgentError),
    /// Exploration failed.
    #[error(transparent)]
    Explore(#[from] ExploreError),
    /// Tracing kernel sets failed.
    #[error(transparent)]
    Kernel(#[from] KernelError),
    /// Computing distances between kernel sets failed.
    #[error(transparent)]
    Metric(#[from] MetricError),
    /// An embedding failed.
    #[error(transparent)]
    Embed(#[from] crate::embed::EmbedError),
    /// Analysing a distance matrix failed.
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    /// The environment-invariance experiment failed.
    #[error(transparent)]
    Invariance(#[from] crate::invariance::InvarianceError),
    /// Writing the figures and report failed.
    #[error(transparent)]
    Report(#[from] crate::report::ReportError),
}

/// `Result` with the crate-wide [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
