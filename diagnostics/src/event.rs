//! The diagnostic event emitted on every DTC status change, and its JSON shape.
//!
//! The event memory ([`crate::dtc::EventMemory`]) hands one [`DiagnosticEvent`] to the caller's
//! sink each time the ISO 14229-1 status byte of an event changes (and when its memory entry is
//! stored, refused, displaced, aged out or cleared, even if the byte stays the same). Reports that
//! change nothing emit nothing.
//!
//! # JSON shape
//!
//! One object per event (the CLI writes one per line). Example: the first qualified failure of
//! the throttle position sensor A "circuit high" test, right after a ClearDTC:
//!
//! ```json
//! {
//!   "time_s": 12.5,
//!   "event": "tps_a_high",
//!   "dtc": "P0123-1C",
//!   "dtc_uds": 74524,
//!   "trigger": "test_result",
//!   "status_before": 80,
//!   "status_after": 39,
//!   "changed": ["testFailed", "testFailedThisOperationCycle", "pendingDTC",
//!               "testNotCompletedSinceLastClear", "testFailedSinceLastClear",
//!               "testNotCompletedThisOperationCycle"],
//!   "fdc": 127,
//!   "occurrence_counter": 1,
//!   "aging_counter": 0,
//!   "memory": "stored",
//!   "displaced": null,
//!   "freeze_frame": [{"signal": "tps_a_v", "value": 4.93}, {"signal": "engine_speed_rpm", "value": null}],
//!   "test_result": {"value": 4.93, "min": 0.25, "max": 4.75, "verdict": "FAILED"},
//!   "candidates": [{"fault": "tps_a_short_to_supply", "score": 0.91}, {"fault": "tps_a_bias", "score": 0.09}]
//! }
//! ```
//!
//! | key | type | meaning |
//! |---|---|---|
//! | `time_s` | number | time of the report or operation-cycle call that caused the change, s |
//! | `event` | string | the configured event name |
//! | `dtc` | string | the UDS DTC as J2012 code and failure type byte, `"P0123-1C"` |
//! | `dtc_uds` | integer | the same as the 3-byte UDS value (`0x01231C` = 74524; JSON has no hex) |
//! | `trigger` | string | `"test_result"`, `"operation_cycle_start"`, `"operation_cycle_end"`, `"clear_dtc"` or `"displacement"` (another event took this event's memory entry) |
//! | `status_before`, `status_after` | integer 0-255 | the ISO 14229-1 status byte (`80` = `0x50`, `39` = `0x27`) |
//! | `changed` | array of strings | names of the bits that differ, bit 0 first: `testFailed`, `testFailedThisOperationCycle`, `pendingDTC`, `confirmedDTC`, `testNotCompletedSinceLastClear`, `testFailedSinceLastClear`, `testNotCompletedThisOperationCycle`, `warningIndicatorRequested` |
//! | `fdc` | integer -128..127 | fault detection counter after the change |
//! | `occurrence_counter` | integer 0-255 | qualified failures (testFailed 0 -> 1) since the last clear or aging |
//! | `aging_counter` | integer 0-255 | aging cycles counted so far |
//! | `memory` | string | what happened to the memory entry: `"unchanged"`, `"stored"`, `"not_stored"` (memory full, nothing displaceable: overflow), `"displaced"`, `"aged"`, `"cleared"` |
//! | `displaced` | string or null | with `"stored"`: the DTC whose entry this one displaced |
//! | `freeze_frame` | array of `{signal, value}` | the entry's freeze frame (when the entry could not be stored, the values of this report); empty when there is none. `value` is null when the signal had no finite value |
//! | `test_result` | object or null | the [`TestResult`] that caused the change (`verdict` one of `"PASSED"`, `"FAILED"`, `"PRE_PASSED"`, `"PRE_FAILED"`); null for operation-cycle, clear and displacement changes |
//! | `candidates` | array of `{fault, score}` | the isolation candidates the caller passed with the report, in its order; empty otherwise |
//!
//! [`TestResult`]'s numbers are plain JSON numbers; a non-finite one is written as `null` and read
//! back as NaN.

use serde::{Deserialize, Serialize};

use crate::dtc::{Dtc, DtcStatus, StatusBit};
use crate::verdict::TestResult;

/// What caused a status change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Trigger {
    /// A monitor's report ([`crate::dtc::EventMemory::report`]).
    TestResult,
    /// [`crate::dtc::EventMemory::start_operation_cycle`].
    OperationCycleStart,
    /// [`crate::dtc::EventMemory::end_operation_cycle`] (pending cleared, MIL healed, aging).
    OperationCycleEnd,
    /// [`crate::dtc::EventMemory::clear_dtc`].
    ClearDtc,
    /// Another event's new entry displaced this event's entry.
    Displacement,
}

/// What happened to the event's memory entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MemoryAction {
    /// Nothing.
    Unchanged,
    /// A new entry was stored (possibly displacing another, see `displaced`).
    Stored,
    /// The memory was full and no entry could be displaced: the entry was not stored (overflow).
    NotStored,
    /// This event's entry was displaced by a more important one.
    Displaced,
    /// The entry aged out and was erased.
    Aged,
    /// The entry was erased by ClearDTC.
    Cleared,
}

/// One freeze-frame value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FreezeFrameValue {
    /// The signal name, as configured.
    pub signal: String,
    /// Its value at capture; `None` (JSON `null`) when it had no finite value.
    pub value: Option<f64>,
}

/// One isolation candidate, as passed in with the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FaultCandidate {
    /// The fault name.
    pub fault: String,
    /// Its score (the isolation's measure; higher is more likely).
    pub score: f64,
}

/// One DTC status change. See the [module documentation](self) for the JSON shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticEvent {
    /// Time of the cause, s.
    pub time_s: f64,
    /// The configured event name.
    pub event: String,
    /// The DTC, serialized as `"P0123-1C"`.
    pub dtc: Dtc,
    /// The DTC as the 3-byte UDS value.
    pub dtc_uds: u32,
    /// What caused the change.
    pub trigger: Trigger,
    /// The status byte before.
    pub status_before: DtcStatus,
    /// The status byte after.
    pub status_after: DtcStatus,
    /// The bits that differ, bit 0 first.
    pub changed: Vec<StatusBit>,
    /// Fault detection counter after the change.
    pub fdc: i8,
    /// Qualified failures since the last clear or aging (saturates at 255).
    pub occurrence_counter: u8,
    /// Aging cycles counted so far.
    pub aging_counter: u8,
    /// What happened to the memory entry.
    pub memory: MemoryAction,
    /// The DTC whose entry this event's new entry displaced.
    pub displaced: Option<Dtc>,
    /// The freeze frame.
    pub freeze_frame: Vec<FreezeFrameValue>,
    /// The test result that caused the change, if a report did.
    pub test_result: Option<TestResult>,
    /// The isolation candidates passed with the report.
    pub candidates: Vec<FaultCandidate>,
}

impl DiagnosticEvent {
    /// Whether `bit` changed.
    pub fn bit_changed(&self, bit: StatusBit) -> bool {
        self.changed.contains(&bit)
    }
}

/// The freeze frame carried by an [`EventView`]: the configured signal names and their values
/// (borrowed from the memory entry or from the report). `values` may be shorter than `signals`
/// (a report without values for an entry that could not be stored); a missing or non-finite
/// value is written as `null`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FreezeFrameView<'a> {
    /// Signal names, in configured order.
    pub signals: &'a [String],
    /// Their values, in the same order.
    pub values: &'a [f64],
}

impl<'a> FreezeFrameView<'a> {
    /// An empty freeze frame.
    pub const EMPTY: FreezeFrameView<'static> = FreezeFrameView {
        signals: &[],
        values: &[],
    };

    /// `(signal, value)` pairs; `None` where no finite value was captured.
    pub fn iter(&self) -> impl Iterator<Item = (&'a str, Option<f64>)> + 'a {
        let values = self.values;
        self.signals
            .iter()
            .enumerate()
            .map(move |(j, s)| (s.as_str(), values.get(j).copied().filter(|v| v.is_finite())))
    }

    /// Number of signals.
    pub fn len(&self) -> usize {
        self.signals.len()
    }

    /// True without signals.
    pub fn is_empty(&self) -> bool {
        self.signals.is_empty()
    }
}

/// One DTC status change, borrowed from the event memory that emits it: what
/// [`DiagnosticEvent`] holds, without a single allocation. The memory hands views to its sink
/// (`EventMemory::report_view` and friends), so a sink that only counts events, copies their
/// fixed part or writes their JSON (the [`Serialize`] impl writes exactly the
/// [`DiagnosticEvent`] shape) allocates nothing; [`EventView::to_event`] makes the owned form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EventView<'a> {
    /// Time of the cause, s.
    pub time_s: f64,
    /// The configured event name.
    pub event: &'a str,
    /// The DTC.
    pub dtc: Dtc,
    /// What caused the change.
    pub trigger: Trigger,
    /// The status byte before.
    pub status_before: DtcStatus,
    /// The status byte after.
    pub status_after: DtcStatus,
    /// Fault detection counter after the change.
    pub fdc: i8,
    /// Qualified failures since the last clear or aging (saturates at 255).
    pub occurrence_counter: u8,
    /// Aging cycles counted so far.
    pub aging_counter: u8,
    /// What happened to the memory entry.
    pub memory: MemoryAction,
    /// The DTC whose entry this event's new entry displaced.
    pub displaced: Option<Dtc>,
    /// The freeze frame.
    pub freeze_frame: FreezeFrameView<'a>,
    /// The test result that caused the change, if a report did.
    pub test_result: Option<TestResult>,
    /// The isolation candidates passed with the report.
    pub candidates: &'a [(&'a str, f64)],
}

impl EventView<'_> {
    /// Whether `bit` changed.
    pub fn bit_changed(&self, bit: StatusBit) -> bool {
        self.status_before
            .changed_bits(self.status_after)
            .any(|b| b == bit)
    }

    /// True when this change sets testFailed (a new qualified failure).
    pub fn raised(&self) -> bool {
        !self.status_before.test_failed() && self.status_after.test_failed()
    }

    /// The owned event (allocates the strings and lists).
    pub fn to_event(&self) -> DiagnosticEvent {
        DiagnosticEvent {
            time_s: self.time_s,
            event: self.event.to_string(),
            dtc: self.dtc,
            dtc_uds: self.dtc.to_u32(),
            trigger: self.trigger,
            status_before: self.status_before,
            status_after: self.status_after,
            changed: self.status_before.changed_bits(self.status_after).collect(),
            fdc: self.fdc,
            occurrence_counter: self.occurrence_counter,
            aging_counter: self.aging_counter,
            memory: self.memory,
            displaced: self.displaced,
            freeze_frame: self
                .freeze_frame
                .iter()
                .map(|(signal, value)| FreezeFrameValue {
                    signal: signal.to_string(),
                    value,
                })
                .collect(),
            test_result: self.test_result,
            candidates: self
                .candidates
                .iter()
                .map(|(f, score)| FaultCandidate {
                    fault: (*f).to_string(),
                    score: *score,
                })
                .collect(),
        }
    }
}

/// Writes the [`DiagnosticEvent`] JSON shape, key for key, without building one.
impl Serialize for EventView<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{SerializeSeq, SerializeStruct};

        struct Changed(DtcStatus, DtcStatus);
        impl Serialize for Changed {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut seq = s.serialize_seq(None)?;
                for b in self.0.changed_bits(self.1) {
                    seq.serialize_element(&b)?;
                }
                seq.end()
            }
        }
        struct Frame<'f>(FreezeFrameView<'f>);
        impl Serialize for Frame<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                #[derive(Serialize)]
                struct Item<'i> {
                    signal: &'i str,
                    value: Option<f64>,
                }
                let mut seq = s.serialize_seq(Some(self.0.len()))?;
                for (signal, value) in self.0.iter() {
                    seq.serialize_element(&Item { signal, value })?;
                }
                seq.end()
            }
        }
        struct Candidates<'c>(&'c [(&'c str, f64)]);
        impl Serialize for Candidates<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                #[derive(Serialize)]
                struct Item<'i> {
                    fault: &'i str,
                    score: f64,
                }
                let mut seq = s.serialize_seq(Some(self.0.len()))?;
                for &(fault, score) in self.0 {
                    seq.serialize_element(&Item { fault, score })?;
                }
                seq.end()
            }
        }

        let mut st = s.serialize_struct("DiagnosticEvent", 17)?;
        st.serialize_field("time_s", &self.time_s)?;
        st.serialize_field("event", self.event)?;
        st.serialize_field("dtc", &self.dtc)?;
        st.serialize_field("dtc_uds", &self.dtc.to_u32())?;
        st.serialize_field("trigger", &self.trigger)?;
        st.serialize_field("status_before", &self.status_before)?;
        st.serialize_field("status_after", &self.status_after)?;
        st.serialize_field("changed", &Changed(self.status_before, self.status_after))?;
        st.serialize_field("fdc", &self.fdc)?;
        st.serialize_field("occurrence_counter", &self.occurrence_counter)?;
        st.serialize_field("aging_counter", &self.aging_counter)?;
        st.serialize_field("memory", &self.memory)?;
        st.serialize_field("displaced", &self.displaced)?;
        st.serialize_field("freeze_frame", &Frame(self.freeze_frame))?;
        st.serialize_field("test_result", &self.test_result)?;
        st.serialize_field("candidates", &Candidates(self.candidates))?;
        st.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::verdict::Verdict;

    fn example() -> DiagnosticEvent {
        let before = DtcStatus::from_byte(0x50);
        let after = DtcStatus::from_byte(0x27);
        DiagnosticEvent {
            time_s: 12.5,
            event: "tps_a_high".into(),
            dtc: "P0123-1C".parse().unwrap(),
            dtc_uds: 0x01231C,
            trigger: Trigger::TestResult,
            status_before: before,
            status_after: after,
            changed: before.changed_bits(after).collect(),
            fdc: 127,
            occurrence_counter: 1,
            aging_counter: 0,
            memory: MemoryAction::Stored,
            displaced: None,
            freeze_frame: vec![
                FreezeFrameValue {
                    signal: "tps_a_v".into(),
                    value: Some(4.93),
                },
                FreezeFrameValue {
                    signal: "engine_speed_rpm".into(),
                    value: None,
                },
            ],
            test_result: Some(TestResult {
                value: 4.93,
                min: 0.25,
                max: 4.75,
                verdict: Verdict::Failed,
            }),
            candidates: vec![
                FaultCandidate {
                    fault: "tps_a_short_to_supply".into(),
                    score: 0.91,
                },
                FaultCandidate {
                    fault: "tps_a_bias".into(),
                    score: 0.09,
                },
            ],
        }
    }

    /// The documented example above is exactly what serde writes, and it reads back.
    #[test]
    fn json_shape_matches_the_documentation() {
        let doc = r#"{
          "time_s": 12.5,
          "event": "tps_a_high",
          "dtc": "P0123-1C",
          "dtc_uds": 74524,
          "trigger": "test_result",
          "status_before": 80,
          "status_after": 39,
          "changed": ["testFailed", "testFailedThisOperationCycle", "pendingDTC",
                      "testNotCompletedSinceLastClear", "testFailedSinceLastClear",
                      "testNotCompletedThisOperationCycle"],
          "fdc": 127,
          "occurrence_counter": 1,
          "aging_counter": 0,
          "memory": "stored",
          "displaced": null,
          "freeze_frame": [{"signal": "tps_a_v", "value": 4.93}, {"signal": "engine_speed_rpm", "value": null}],
          "test_result": {"value": 4.93, "min": 0.25, "max": 4.75, "verdict": "FAILED"},
          "candidates": [{"fault": "tps_a_short_to_supply", "score": 0.91}, {"fault": "tps_a_bias", "score": 0.09}]
        }"#;
        let e = example();
        let written: serde_json::Value = serde_json::to_value(&e).unwrap();
        let documented: serde_json::Value = serde_json::from_str(doc).unwrap();
        assert_eq!(written, documented);
        let back: DiagnosticEvent = serde_json::from_str(doc).unwrap();
        assert_eq!(back, e);
        // Key order follows the documentation.
        let text = serde_json::to_string(&e).unwrap();
        assert!(text.starts_with(r#"{"time_s":12.5,"event":"tps_a_high","dtc":"P0123-1C","#));
        assert!(e.bit_changed(StatusBit::PendingDtc));
        assert!(!e.bit_changed(StatusBit::ConfirmedDtc));
    }

    /// A view writes the same JSON as its owned event, and converts to it.
    #[test]
    fn view_serializes_as_the_event() {
        let e = example();
        let signals: Vec<String> = e.freeze_frame.iter().map(|f| f.signal.clone()).collect();
        let values = [4.93, f64::NAN];
        let candidates = [("tps_a_short_to_supply", 0.91), ("tps_a_bias", 0.09)];
        let view = EventView {
            time_s: e.time_s,
            event: &e.event,
            dtc: e.dtc,
            trigger: e.trigger,
            status_before: e.status_before,
            status_after: e.status_after,
            fdc: e.fdc,
            occurrence_counter: e.occurrence_counter,
            aging_counter: e.aging_counter,
            memory: e.memory,
            displaced: e.displaced,
            freeze_frame: FreezeFrameView {
                signals: &signals,
                values: &values,
            },
            test_result: e.test_result,
            candidates: &candidates,
        };
        assert_eq!(
            serde_json::to_string(&view).unwrap(),
            serde_json::to_string(&e).unwrap()
        );
        assert_eq!(view.to_event(), e);
        assert!(view.raised());
        assert!(view.bit_changed(StatusBit::PendingDtc));
        assert!(!view.bit_changed(StatusBit::ConfirmedDtc));
    }
}
