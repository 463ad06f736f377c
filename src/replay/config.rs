//! The runtime configuration (`config/fdd.toml`), defined in the runtime crate
//! ([`fdd_monitor::runtime::config`]) and re-exported here for the CLI.

pub use fdd_monitor::runtime::config::*;
