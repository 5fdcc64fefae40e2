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
    /// Learning the law from a log, or reading the log, failed.
    #[error(transparent)]
    Learn(#[from] crate::learn::LearnError),
    /// Writing the figures and report failed.
    #[cfg(feature = "pipeline")]
    #[error(transparent)]
    Report(#[from] crate::report::ReportError),
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
            Error::Metric(MetricError::Invalid(p)) => Some(p),
            Error::Learn(e) => e.invalid_parameter(),
            _ => None,
        }
    }
}

/// A parameter out of its domain, located by its table and key as in an experiment
/// file, so that the configuration reader can point at the line without searching the
/// message.
///
/// ```
/// let e = smspace::error::InvalidParameter::new("exploration", "n", 0, "explore at least one configuration");
/// assert_eq!(e.to_string(), "invalid exploration parameter n = 0: explore at least one configuration");
/// ```
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid {table} parameter {key} = {value}: {reason}")]
pub struct InvalidParameter {
    /// The table (`exploration`, `kernel`, …).
    pub table: &'static str,
    /// The key in that table.
    pub key: &'static str,
    /// The value given, formatted.
    pub value: String,
    /// What a valid value looks like.
    pub reason: String,
}

impl InvalidParameter {
    /// The error for `table.key = value`.
    pub fn new(
        table: &'static str,
        key: &'static str,
        value: impl std::fmt::Display,
        reason: impl Into<String>,
    ) -> Self {
        Self {
            table,
            key,
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}

/// The one checked-parameter pattern of the crate (after linfa): a serde parameter
/// struct `XParams` with documented defaults is checked into `XValidParams`, the only
/// form an algorithm runs, before any work starts. Every failed check is an
/// [`InvalidParameter`] naming its table and key, wrapped in the module's own error.
///
/// ```
/// use smspace::error::{CheckParams, InvalidParameter};
/// /// Steps of a walk.
/// struct WalkParams { steps: usize }
/// /// Checked [`WalkParams`].
/// struct WalkValidParams { steps: usize }
/// impl CheckParams for WalkParams {
///     type Valid = WalkValidParams;
///     type Error = InvalidParameter;
///     fn check_params(&self) -> Result<WalkValidParams, InvalidParameter> {
///         if self.steps == 0 {
///             return Err(InvalidParameter::new("walk", "steps", 0, "take at least one step"));
///         }
///         Ok(WalkValidParams { steps: self.steps })
///     }
/// }
/// assert!(WalkParams { steps: 0 }.check_params().is_err());
/// ```
pub trait CheckParams {
    /// The checked form (`XValidParams`).
    type Valid;
    /// The module's error; it wraps [`InvalidParameter`].
    type Error: From<InvalidParameter>;
    /// Checks every parameter; the result is the only form that runs.
    fn check_params(&self) -> std::result::Result<Self::Valid, Self::Error>;
}

/// `Result` with the crate-wide [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
