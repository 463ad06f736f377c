//! Diagnostic trouble codes: SAE J2012 codes, the ISO 14229-1 status byte, debouncing and the
//! event memory.
//!
//! - [`code`]: [`DtcCode`] (`P0123` <-> `0x0123`) and [`Dtc`] (`P0123-1C` <-> `0x01231C`).
//! - [`status`]: [`DtcStatus`], the status byte, and [`StatusBit`] names.
//! - [`debounce`]: counter-based, time-based and monitor-internal debouncing ([`Debouncer`]).
//! - [`config`]: [`EventMemoryConfig`] / [`EventConfig`] (serde) and their validation.
//! - [`memory`]: [`EventMemory`], the AUTOSAR-Dem-shaped memory that turns test results and
//!   operation cycles into status bytes, entries and [`crate::event::DiagnosticEvent`]s.

pub mod code;
pub mod config;
pub mod debounce;
pub mod memory;
pub mod status;

pub use code::{Dtc, DtcCode, DtcParseError, DtcParseErrorKind, DtcSystem};
pub use config::{EventConfig, EventMemoryConfig, FreezeFrameUpdate, MilConfig, MilOn};
pub use debounce::{CounterDebounce, DebounceConfig, Debouncer, Qualified, TimeDebounce};
pub use memory::{DemError, DtcGroup, EventId, EventInfo, EventMemory, MemoryEntry, ReportContext};
pub use memory::{
    DropReason, Dropped, EntryImage, EventImage, ImageError, ImageErrorKind, MemoryImage,
    RestoreReport, IMAGE_FORMAT_VERSION, IMAGE_MAGIC,
};
pub use status::{DtcStatus, StatusBit};
