//! The `fdd` package: configuration loading, log replay and the paper reproductions behind the
//! `fdd` CLI.
//! The filters, models and simulators live in the workspace crates (`fdd-estimators`,
//! `fdd-fixtures`, ...); this crate wires them to files and commands.

pub mod calibrate;
pub mod config;
pub mod evaluate;
pub mod fit;
pub mod import;
pub mod limits;
pub mod paths;
pub mod replay;
pub mod reproduce;
pub mod simulate;
pub mod stats;
