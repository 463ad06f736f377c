//! Configuration errors: every one names the field that is wrong.

use thiserror::Error;

/// A rejected configuration value. `field` is the path of the key as the user wrote it
/// (for example `events[2].debounce.failed_threshold`), so the message can be acted on.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("invalid `{field}` = {value}: {reason}")]
pub struct ConfigError {
    pub field: String,
    pub value: String,
    pub reason: String,
}

impl ConfigError {
    /// Builds an error for `field` holding `value`.
    pub fn new(
        field: impl Into<String>,
        value: impl std::fmt::Display,
        reason: impl Into<String>,
    ) -> Self {
        Self {
            field: field.into(),
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}
