//! The crate-wide error: one variant per pipeline stage, each wrapping that stage's own
//! `thiserror` enum, so that a caller can handle "any smspace error" with one type and
//! still match on the stage that failed.

use crate::params::InvalidParameter;
use crate::{
    agent::AgentError, analysis::AnalysisError, explore::ExploreError, io::IoError,
    kernel::KernelError, metric::MetricError,
};

/// Any error of the smspace library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(#[from] IoError),
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
    /// Learning the law from a log, or reading the log, failed.
    #[error(transparent)]
    Learn(#[from] crate::learn::LearnError),
}

impl Error {
    /// The parameter this error is about, when it is an [`InvalidParameter`] (wrapped
    /// in its module's error): what the configuration reader uses to point at the
    /// parameter's line.
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            Error::Agent(e) => e.invalid_parameter(),
            Error::Explore(e) => e.invalid_parameter(),
            Error::Kernel(e) => e.invalid_parameter(),
            Error::Metric(e) => e.invalid_parameter(),
            Error::Embed(e) => e.invalid_parameter(),
            Error::Analysis(e) => e.invalid_parameter(),
            Error::Invariance(e) => e.invalid_parameter(),
            Error::Learn(e) => e.invalid_parameter(),
            Error::Io(_) => None,
        }
    }
}

/// `Result` with the crate-wide [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
