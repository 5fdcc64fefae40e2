//! The crate-wide error: one variant per pipeline stage, each wrapping that stage's own
//! `thiserror` enum, so that a caller can handle "any smspace error" with one type and
//! still match on the stage that failed.

use crate::io::IoError;
use crate::metric::MetricError;

/// Any error of the smspace library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(#[from] IoError),
    /// Computing distances between kernel sets failed.
    #[error(transparent)]
    Metric(#[from] MetricError),
}

/// `Result` with the crate-wide [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
