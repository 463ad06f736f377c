//! fdd-diagnostics: the layer between the estimators' innovations and the diagnostic trouble
//! codes a vehicle engineer reads.
//!
//! - [`verdict`]: what one test step says ([`Verdict`], [`TestResult`], OBD service $06 records).
//! - [`detectors`]: windowed chi-square on the NIS, two-sided CUSUM, GLR for a mean jump, and
//!   range/rate checks on raw signals; thresholds derived from false-alarm figures.
//! - [`isolation`]: a fault signature matrix turning the set of fired tests into ranked fault
//!   candidates, or "unknown".
//! - [`dtc`]: SAE J2012 codes, the ISO 14229-1 status byte, debouncing and an AUTOSAR-Dem-shaped
//!   event memory that emits [`event::DiagnosticEvent`]s (documented JSON shape).
//! - [`evaluation`]: scoring a diagnosis system against ground truth (TDR, FAR, FIA as the DX'25
//!   competition defines them; per-fault detection and DTC rates and delays; false alarms per
//!   hour), the bookkeeping behind `fdd evaluate`.
//! - [`uds`]: the UDS DTC services (ReadDTCInformation `0x19`, ClearDiagnosticInformation
//!   `0x14`) answered from any [`uds::DtcStore`], with the byte formats fdd uses.
//!
//! Pure logic: no I/O, no clock (time is passed in), no heap allocation per step.

pub mod detectors;
pub mod dtc;
pub mod error;
pub mod evaluation;
pub mod event;
pub mod extreme_value;
pub mod isolation;
pub mod uds;
pub mod verdict;

pub use error::ConfigError;
pub use verdict::{Obd06Record, TestResult, Verdict};
