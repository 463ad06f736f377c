//! Configuration of the event memory and its events (serde, TOML-friendly), and its validation.
//!
//! ```toml
//! capacity = 8                       # memory entries (>= 1)
//!
//! [[events]]
//! name = "tps_a_high"                # unique, non-empty
//! dtc = "P0123-1C"                   # J2012 code and failure type byte ("P0123" = FTB 00); unique
//! priority = 2                       # 1 = highest .. 255 = lowest (AUTOSAR convention)
//! confirmation_threshold = 2         # failed operation cycles to confirm (default 2, OBD)
//! aging_threshold = 40               # passed cycles after the MIL went off to erase (default 40)
//! freeze_frame = ["tps_a_v", "engine_speed_rpm"]   # signals captured with the entry (default none)
//! freeze_frame_update = "first"      # "first" (default) or "latest"
//! mil = { enabled = true, on = "confirmed", off_after_passing_cycles = 3 }   # the defaults
//! debounce = { kind = "counter", increment_step = 10, decrement_step = 5, failed_threshold = 100, passed_threshold = -100 }
//! ```
//!
//! Unknown keys are errors. [`EventMemoryConfig::validate`] (also run by
//! [`crate::dtc::EventMemory::new`]) rejects bad values with a [`ConfigError`] naming the key
//! as written, relative to this table: `capacity`, `events[2].dtc`,
//! `events[2].debounce.failed_threshold`, `events[0].freeze_frame[1]`, ...

use serde::{Deserialize, Serialize};

use crate::dtc::code::Dtc;
use crate::dtc::debounce::DebounceConfig;
use crate::error::ConfigError;

/// When an event requests the MIL (sets `warningIndicatorRequested`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MilOn {
    /// When the failure is confirmed, i.e. in the `confirmation_threshold`-th failed operation
    /// cycle (OBD: the 2nd consecutive one). A recurrence after the MIL went off needs the same
    /// number of failed cycles again.
    #[default]
    Confirmed,
    /// At every qualified failure (for faults that must be shown at once).
    FirstFailure,
}

const fn default_true() -> bool {
    true
}
const fn three() -> u8 {
    3
}
const fn two() -> u8 {
    2
}
const fn forty() -> u8 {
    40
}

/// The warning indicator (MIL) rules of an event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MilConfig {
    /// Whether the event requests the MIL at all (default true).
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// When it is switched on (default `confirmed`).
    #[serde(default)]
    pub on: MilOn,
    /// Consecutive passed operation cycles (test completed, no failure) that switch it off
    /// (>= 1; default 3, OBD).
    #[serde(default = "three")]
    pub off_after_passing_cycles: u8,
}

impl Default for MilConfig {
    fn default() -> Self {
        MilConfig {
            enabled: true,
            on: MilOn::Confirmed,
            off_after_passing_cycles: 3,
        }
    }
}

/// Which failure's values the freeze frame holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FreezeFrameUpdate {
    /// Captured when the entry is stored and kept until it is erased (OBD convention).
    #[default]
    First,
    /// Captured again at every new occurrence (`testFailed` 0 -> 1) while the entry exists.
    Latest,
}

/// One event (one DTC) of the memory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EventConfig {
    /// Unique name, used in the emitted events.
    pub name: String,
    /// The UDS DTC: J2012 code and failure type byte, `"P0123-1C"`; a bare code means FTB 00.
    pub dtc: String,
    /// 1 (highest) to 255 (lowest), AUTOSAR convention; decides displacement.
    pub priority: u8,
    /// Debounce algorithm.
    pub debounce: DebounceConfig,
    /// Operation cycles with a failure (counted since the pending bit was last cleared) that
    /// confirm the DTC (>= 1; default 2).
    #[serde(default = "two")]
    pub confirmation_threshold: u8,
    /// Passed operation cycles, counted once the MIL is off, after which the entry is erased
    /// and `confirmedDTC` cleared (>= 1; default 40).
    #[serde(default = "forty")]
    pub aging_threshold: u8,
    /// MIL rules.
    #[serde(default)]
    pub mil: MilConfig,
    /// Signals captured in the freeze frame, in the order the caller passes their values.
    #[serde(default)]
    pub freeze_frame: Vec<String>,
    /// Which failure the freeze frame holds.
    #[serde(default)]
    pub freeze_frame_update: FreezeFrameUpdate,
}

impl EventConfig {
    /// An event with the given name, DTC text and priority, counter-based debounce with
    /// defaults and all other settings at their defaults.
    pub fn new(name: impl Into<String>, dtc: impl Into<String>, priority: u8) -> Self {
        EventConfig {
            name: name.into(),
            dtc: dtc.into(),
            priority,
            debounce: DebounceConfig::default(),
            confirmation_threshold: 2,
            aging_threshold: 40,
            mil: MilConfig::default(),
            freeze_frame: Vec::new(),
            freeze_frame_update: FreezeFrameUpdate::First,
        }
    }

    /// Checks this event; `field` is its path (e.g. `events[2]`). Returns the parsed DTC.
    pub fn validate(&self, field: &str) -> Result<Dtc, ConfigError> {
        let f = |key: &str| format!("{field}.{key}");
        if self.name.trim().is_empty() {
            return Err(ConfigError::new(
                f("name"),
                format!("{:?}", self.name),
                "must not be empty",
            ));
        }
        let dtc: Dtc = self.dtc.parse().map_err(|e: crate::dtc::DtcParseError| {
            ConfigError::new(f("dtc"), format!("{:?}", self.dtc), e.reason())
        })?;
        if self.priority == 0 {
            return Err(ConfigError::new(
                f("priority"),
                0,
                "must be 1 (highest) to 255 (lowest)",
            ));
        }
        self.debounce.validate(&f("debounce"))?;
        if self.confirmation_threshold == 0 {
            return Err(ConfigError::new(
                f("confirmation_threshold"),
                0,
                "must be at least 1 failed operation cycle",
            ));
        }
        if self.aging_threshold == 0 {
            return Err(ConfigError::new(
                f("aging_threshold"),
                0,
                "must be at least 1 operation cycle",
            ));
        }
        if self.mil.off_after_passing_cycles == 0 {
            return Err(ConfigError::new(
                f("mil.off_after_passing_cycles"),
                0,
                "must be at least 1 operation cycle",
            ));
        }
        for (i, s) in self.freeze_frame.iter().enumerate() {
            if s.trim().is_empty() {
                return Err(ConfigError::new(
                    format!("{field}.freeze_frame[{i}]"),
                    format!("{s:?}"),
                    "signal name must not be empty",
                ));
            }
            if let Some(j) = self.freeze_frame[..i].iter().position(|t| t == s) {
                return Err(ConfigError::new(
                    format!("{field}.freeze_frame[{i}]"),
                    format!("{s:?}"),
                    format!("duplicates freeze_frame[{j}]"),
                ));
            }
        }
        Ok(dtc)
    }
}

/// The event memory: its capacity and its events.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EventMemoryConfig {
    /// Number of memory entries (extended data + freeze frame), >= 1. Status bytes exist for
    /// every event regardless.
    pub capacity: usize,
    /// The events, in the order of their [`crate::dtc::EventId`]s.
    #[serde(default)]
    pub events: Vec<EventConfig>,
}

impl EventMemoryConfig {
    /// Checks every value; errors name the key (`capacity`, `events[i].<key>`). Returns the
    /// parsed DTC of each event.
    pub fn validate(&self) -> Result<Vec<Dtc>, ConfigError> {
        if self.capacity == 0 {
            return Err(ConfigError::new(
                "capacity",
                0,
                "the event memory needs at least 1 entry",
            ));
        }
        if self.events.len() > u16::MAX as usize {
            return Err(ConfigError::new(
                "events",
                self.events.len(),
                "at most 65535 events",
            ));
        }
        let mut dtcs = Vec::with_capacity(self.events.len());
        for (i, ev) in self.events.iter().enumerate() {
            let field = format!("events[{i}]");
            let dtc = ev.validate(&field)?;
            if let Some(j) = dtcs.iter().position(|d| *d == dtc) {
                return Err(ConfigError::new(
                    format!("{field}.dtc"),
                    format!("{:?}", ev.dtc),
                    format!("DTC {dtc} is already used by events[{j}]"),
                ));
            }
            if let Some(j) = self.events[..i].iter().position(|e| e.name == ev.name) {
                return Err(ConfigError::new(
                    format!("{field}.name"),
                    format!("{:?}", ev.name),
                    format!("name is already used by events[{j}]"),
                ));
            }
            dtcs.push(dtc);
        }
        Ok(dtcs)
    }
}
