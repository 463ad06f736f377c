//! fdd-monitor: the runtime a host embeds.
//!
//! - [`log`]: MCAP logs with JSON-encoded, JSON-schema-described channels (what fdd reads and
//!   writes), streamed in log-time order.
//! - [`signal_table`]: latest value and timestamp per named signal, with staleness detection.
//! - [`scheduler`] and [`monitor`]: monitors declare their inputs and rate and are stepped at it.
//! - [`persist`]: the A/B slot store that keeps the event memories across power cycles.
//! - [`config`] and [`config_key`]: the configuration files, every value checked against its
//!   range, every error naming the file and the key.

pub mod config;
pub mod config_key;
#[cfg(feature = "ffi")]
pub mod ffi;
pub mod intake;
pub mod log;
pub mod monitor;
pub mod monitor_events;
pub mod persist;
pub mod runtime;
pub mod scheduler;
pub mod signal_table;
pub mod staleness;
pub mod text_file;
pub mod throttle;
pub mod turbo;
pub mod wheel;
