//! Configuration loading (the throttle and intake files), re-exported from the runtime crate,
//! where the monitors are built.

pub use fdd_monitor::config::*;
