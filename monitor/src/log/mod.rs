//! MCAP logs: message types, JSON schemas, a writer with reproducible output, and a streaming reader.
//!
//! fdd reads its inputs from, and writes its outputs to, [MCAP](https://mcap.dev) files whose
//! channels carry JSON messages (message encoding `json`) described by JSON schemas (schema
//! encoding `jsonschema`, draft 2020-12), so the Foxglove app and the official MCAP readers open
//! them. A message's log time and publish time are both the sample time in nanoseconds.
//!
//! - [`LogWriter`] writes typed messages ([`TopicMessage`]) or any `Serialize` value on a
//!   registered topic, with pinned settings (library `fdd-monitor`, empty profile, zstd level
//!   1, single-threaded compression, 1 MiB chunks), so the same messages give the same bytes.
//! - [`LogReader`] streams messages in log-time order, one chunk at a time, from the summary's
//!   chunk indexes; a file without a usable summary (truncated, unfinished) is read linearly in
//!   file order after a warning. [`LogMessage::decode`] and [`LogMessage::field_f64`] decode a
//!   message into a type or extract one numeric field by name.
//! - [`ReadOptions`] bounds what one file may cost the reader (sizes in bytes, counts of chunk
//!   indexes, channels and schemas, decompressed bytes relative to the file's size); going over
//!   a limit is a [`LogError::LimitExceeded`] naming the option to raise.
//! - [`LogError`] names the file, and where known the topic, log time and byte offset;
//!   [`LogError::is_fatal`] separates what stops the reading from per-message and per-chunk
//!   problems that are reported and skipped.
//!
//! # Topics
//!
//! Numbers that are not finite (NaN, infinities) are written as JSON `null` and read back as
//! NaN ([`nan_as_null`]).
//!
//! | topic | schema | field | JSON type | unit | meaning |
//! |---|---|---|---|---|---|
//! | `/throttle/motor_voltage` | `fdd.MotorVoltage` | `voltage_v` | number | V | voltage applied to the throttle motor (model input `u`) |
//! | `/throttle/tps` | `fdd.TpsVoltage` | `voltage_v` | number | V | throttle position sensor output (0..5 V for 0..90 deg by default) |
//! | `/throttle/wattmeter` | `fdd.Wattmeter` | `power_w` | number | W | motor power `i^2` into 1 ohm (numerically the squared current, A^2), with noise |
//! | `/truth/throttle` | `fdd.ThrottleTruth` | `angle_deg` | number | deg | true plate angle (fixtures only) |
//! | | | `velocity` | number | model units | true plate angular velocity `rho` of the identified model |
//! | | | `current_a` | number | A | true motor current |
//! | | | `fault` | string | | scenario fault name: `none`, `tps_stuck`, ... |
//! | | | `fault_active` | boolean | | the fault is active at this sample |
//! | `/fdd/throttle/position` | `fdd.PositionEstimate` | `angle_deg` | number | deg | estimated plate angle (`null`: no estimate) |
//! | | | `lower_deg`, `upper_deg` | number | deg | 95% interval |
//! | | | `source` | string | | `tps` (position sensor) or `wattmeter_estimate` (wattmeter UKF) |
//! | `/fdd/throttle/innovation` | `fdd.Innovation` | `filter` | string | | filter name, as configured |
//! | | | `residual` | array of number | measurement units (V, W) | innovation `y - h(x)` per component |
//! | | | `variance` | array of number | V^2, W^2 | innovation variance per component (diagonal of `S`) |
//! | | | `nis` | number | 1 | normalized innovation squared `r' S^-1 r` |
//! | | | `dof` | integer | | degrees of freedom of `nis` |
//! | `/fdd/tests` | `fdd.TestStatistic` | `test` | string | | test name, as configured |
//! | | | `value` | number | test units (1 for NIS tests, V for voltage range checks) | test statistic (`null`: not run) |
//! | | | `min`, `max` | number | test units | limits: passed when `min <= value <= max` (OBD $06) |
//! | | | `verdict` | string | | `PASSED`, `FAILED`, `PRE_PASSED`, `PRE_FAILED`, `NOT_TESTED` |
//! | `/fdd/dtc_status` | `fdd.DtcStatus` | `dtc` | string | | UDS DTC, J2012 code and failure type byte, `P0123-1C` |
//! | | | `status` | integer 0-255 | | ISO 14229-1 status byte (bit 0 testFailed .. bit 7 warningIndicatorRequested) |
//! | `/fdd/events` | `fdd.DiagnosticEvent` | (16 fields) | object | | one DTC status change: the JSON of `fdd_diagnostics::event::DiagnosticEvent`, documented there (`time_s` in s) |
//!
//! The schemas themselves, with each field's description, are in [`schema`]; [`TOPICS`] lists
//! them. Other topics can be written after [`LogWriter::add_topic`], and the reader reads any
//! MCAP file (other encodings are yielded as bytes).

mod crc32;
pub mod error;
pub mod field;
pub mod flat_json;
pub mod messages;
pub mod reader;
mod records;
pub mod schema;
pub mod writer;

pub use error::{CrcSection, LogError};
pub use field::{json_field_f64, FieldLookupError};
pub use messages::{
    nan_as_null, vec_nan_as_null, DtcStatusMsg, InnovationMsg, MotorVoltage, PositionEstimate,
    TestStatistic, ThrottleTruth, TopicMessage, TpsVoltage, Wattmeter,
};
pub use reader::{
    ChannelInfo, LogMessage, LogReader, OwnedLogMessage, ReadMode, ReadOptions, ReadStats,
    SchemaInfo,
};
pub use schema::{builtin_topic, TopicSchema, MESSAGE_ENCODING, SCHEMA_ENCODING, TOPICS};
pub use writer::{ChunkCompression, LogWriter, WriteOptions, LIBRARY, PROFILE};
