//! The monitor plugin interface.
