//! Checked parameters: the one pattern every algorithm's parameters follow (after
//! linfa), and the error of a parameter out of its domain. A leaf module: every stage
//! imports it, it imports none.

/// A parameter out of its domain, located by its table and key as in an experiment
/// file, so that the configuration reader can point at the line without searching the
/// message.
///
/// ```
/// let e = smspace::params::InvalidParameter::new("exploration", "n", 0, "explore at least one configuration");
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
/// use smspace::params::{CheckParams, InvalidParameter};
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
