//! The error of a stage: any error of the core crate ([`smspace::Error`]), of an
//! experiment file ([`ConfigError`]) or of the report ([`ReportError`]), so that a
//! stage can use `?` on each and the run can say which stage failed and why.

use smspace::params::InvalidParameter;

use crate::config::ConfigError;
use crate::report::ReportError;

/// Any error of a stage.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the numerics (agents, kernels, metrics, embeddings, analysis, files).
    #[error(transparent)]
    Core(#[from] smspace::Error),
    /// An experiment or agent file is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Writing the figures and report failed.
    #[error(transparent)]
    Report(#[from] ReportError),
}

impl Error {
    /// The parameter this error is about, when it is an [`InvalidParameter`]: of any
    /// core module ([`smspace::Error::invalid_parameter`]) or of the report.
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            Error::Core(e) => e.invalid_parameter(),
            Error::Report(ReportError::InvalidParameter(p)) => Some(p),
            Error::Report(_) | Error::Config(_) => None,
        }
    }
}

impl crate::config::LocatedError for Error {
    fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        Error::invalid_parameter(self)
    }
}

/// Every error of a core module converts through [`smspace::Error`].
macro_rules! through_core {
    ($($error:ty),* $(,)?) => {
        $(impl From<$error> for Error {
            fn from(error: $error) -> Self {
                Error::Core(error.into())
            }
        })*
    };
}

through_core!(
    smspace::agent::AgentError,
    smspace::analysis::AnalysisError,
    smspace::embed::EmbedError,
    smspace::explore::ExploreError,
    smspace::invariance::InvarianceError,
    smspace::io::IoError,
    smspace::kernel::KernelError,
    smspace::learn::LearnError,
    smspace::metric::MetricError,
);

/// `Result` with a stage's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
