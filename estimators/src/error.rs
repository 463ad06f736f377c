//! Errors a filter reports to its caller instead of panicking or producing NaN states.

use thiserror::Error;

/// Why a filter step was refused. After any of these the filter keeps the state and covariance
/// it had before the call, so the caller can skip the sample and carry on.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum FilterError {
    /// An input (control) component is NaN or infinite.
    #[error("input u[{index}] is not finite ({value})")]
    NonFiniteInput { index: usize, value: f64 },
    /// A measurement component is NaN or infinite.
    #[error("measurement y[{index}] is not finite ({value})")]
    NonFiniteMeasurement { index: usize, value: f64 },
    /// A matrix that must be symmetric positive definite is not (Cholesky failed at `pivot`).
    #[error("{which} is not positive definite (Cholesky failed at pivot {pivot})")]
    NotPositiveDefinite { which: &'static str, pivot: usize },
    /// The step produced a NaN or infinite state or covariance (divergence).
    #[error("{which} became non-finite; step rejected")]
    NonFiniteResult { which: &'static str },
    /// A partial update was asked to use no measurement at all.
    #[error("partial update selects no measurement component")]
    EmptySubset,
}

/// Errors in filter or sigma-point construction parameters.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ConfigError {
    /// A parameter is outside its admissible range.
    #[error("parameter `{name}` = {value} is invalid: {reason}")]
    InvalidParameter {
        name: &'static str,
        value: f64,
        reason: &'static str,
    },
    /// The number of sigma points the set produces does not fit the filter's storage.
    #[error(
        "sigma-point set `{set}` produces {needed} points for n = {n}, filter stores {stored}"
    )]
    PointCount {
        set: &'static str,
        n: usize,
        needed: usize,
        stored: usize,
    },
    /// A matrix given at construction is not symmetric positive (semi)definite.
    #[error("matrix `{name}` must be symmetric positive {kind}")]
    NotPositive {
        name: &'static str,
        kind: &'static str,
    },
}
