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

/// A key a parameter table once had under another name: it is read (any value) only so
/// that the table's check can refuse it with the new name, at the old key's line.
///
/// ```
/// use smspace::params::Renamed;
/// #[derive(serde::Deserialize, Default)]
/// #[serde(deny_unknown_fields, default)]
/// struct Table {
///     relative_noise: f64,
///     #[serde(rename = "noise")]
///     old_noise: Renamed,
/// }
/// let t: Table = toml::from_str("noise = 0.1").unwrap();
/// let err = t.old_noise.refuse("data", "noise", "relative_noise").unwrap_err();
/// assert!(err.to_string().contains("relative_noise = 0.1"), "{err}");
/// ```
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Renamed(Option<String>);

impl<'de> serde::Deserialize<'de> for Renamed {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let value = toml::Value::deserialize(deserializer)?;
        Ok(Self(Some(value.to_string())))
    }
}

impl Renamed {
    /// An error when the old key `table.old` was given, naming the key to write
    /// instead (`new`) with the value given.
    pub fn refuse(
        &self,
        table: &'static str,
        old: &'static str,
        new: &str,
    ) -> Result<(), InvalidParameter> {
        match &self.0 {
            None => Ok(()),
            Some(value) => Err(InvalidParameter::new(
                table,
                old,
                value,
                format!("the key is now {new}: write {new} = {value}"),
            )),
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
