//! Bad input that the replay counts and goes on past: one counter per (kind, topic), with the
//! first occurrence's time and message. The first few occurrences of each are logged at `warn`.

use fdd_monitor::log::{CrcSection, LogError};
use fdd_monitor::signal_table::SampleError;

/// Occurrences of one (kind, topic) logged at `warn` before the rest are only counted.
pub const LOGGED_PER_KIND: u64 = 3;

/// What was wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ProblemKind {
    /// A message is not valid JSON.
    InvalidJson,
    /// A message lacks the mapped field (or a field the truth topic needs).
    MissingField,
    /// The mapped field holds something other than a number.
    NotANumber,
    /// A truth message has fields of the wrong type.
    WrongShape,
    /// NaN or infinite value (`null` in JSON).
    NonFinite,
    /// A sample older than the signal's latest one (possible in linear reads, in file order).
    TimeBackwards,
    /// A sample with the same time as the signal's latest one.
    TimeRepeated,
    /// The log time jumped forward by more than `replay.max_gap_s`: a new operation cycle.
    TimeGap,
    /// A message on a channel id the file never defines.
    UnknownChannel,
    /// A chunk that cannot be decompressed or parsed, or fails its CRC (its messages are lost).
    BadChunk,
    /// Anything else the reader reports as non-fatal.
    Other,
}

impl ProblemKind {
    /// Short label used in the summary.
    pub fn label(self) -> &'static str {
        match self {
            ProblemKind::InvalidJson => "invalid JSON",
            ProblemKind::MissingField => "missing field",
            ProblemKind::NotANumber => "field not a number",
            ProblemKind::WrongShape => "wrong message shape",
            ProblemKind::NonFinite => "NaN or infinite value",
            ProblemKind::TimeBackwards => "timestamp goes backwards",
            ProblemKind::TimeRepeated => "timestamp repeats",
            ProblemKind::TimeGap => "time gap (new operation cycle)",
            ProblemKind::UnknownChannel => "unknown channel id",
            ProblemKind::BadChunk => "unreadable chunk (skipped)",
            ProblemKind::Other => "other",
        }
    }

    /// The kind of a non-fatal reader or decoding error.
    pub fn of_log_error(e: &LogError) -> ProblemKind {
        match e {
            LogError::InvalidJson { .. } => ProblemKind::InvalidJson,
            LogError::MissingField { .. } => ProblemKind::MissingField,
            LogError::NotANumber { .. } => ProblemKind::NotANumber,
            LogError::WrongShape { .. } => ProblemKind::WrongShape,
            LogError::UnknownChannel { .. } => ProblemKind::UnknownChannel,
            LogError::BadChunk { .. } => ProblemKind::BadChunk,
            LogError::CrcMismatch {
                section: CrcSection::Chunk,
                ..
            } => ProblemKind::BadChunk,
            _ => ProblemKind::Other,
        }
    }

    /// The kind of a sample the signal table refused.
    pub fn of_sample_error(e: &SampleError) -> ProblemKind {
        match e {
            SampleError::NonFinite => ProblemKind::NonFinite,
            SampleError::Backwards { .. } => ProblemKind::TimeBackwards,
            SampleError::Repeated { .. } => ProblemKind::TimeRepeated,
        }
    }
}

/// One (kind, topic) counter.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    pub kind: ProblemKind,
    /// The topic concerned, when known.
    pub topic: Option<String>,
    pub count: u64,
    /// Log time of the first occurrence, ns, when known.
    pub first_time_ns: Option<u64>,
    /// The first occurrence's message (names the file, topic and time).
    pub first_message: String,
}

/// All counters, in order of first occurrence.
#[derive(Debug, Default)]
pub struct Problems {
    list: Vec<Problem>,
}

impl Problems {
    /// Counts one occurrence; `message` is built (and logged) only for the first few.
    pub fn record(
        &mut self,
        kind: ProblemKind,
        topic: Option<&str>,
        time_ns: Option<u64>,
        message: impl FnOnce() -> String,
    ) {
        let k = match self
            .list
            .iter()
            .position(|p| p.kind == kind && p.topic.as_deref() == topic)
        {
            Some(k) => k,
            None => {
                self.list.push(Problem {
                    kind,
                    topic: topic.map(str::to_string),
                    count: 0,
                    first_time_ns: time_ns,
                    first_message: String::new(),
                });
                self.list.len() - 1
            }
        };
        let p = &mut self.list[k];
        p.count += 1;
        if p.count <= LOGGED_PER_KIND {
            let text = message();
            if p.count == 1 {
                p.first_message.clone_from(&text);
            }
            if p.count == LOGGED_PER_KIND {
                tracing::warn!(
                    "{text} (further '{}' problems{} are counted in the summary, not logged)",
                    kind.label(),
                    topic.map(|t| format!(" on {t}")).unwrap_or_default()
                );
            } else {
                tracing::warn!("{text}");
            }
        }
    }

    /// Counts a non-fatal reader or decoding error.
    pub fn record_log_error(&mut self, e: &LogError) {
        self.record(
            ProblemKind::of_log_error(e),
            e.topic(),
            e.log_time_ns(),
            || e.to_string(),
        );
    }

    /// The counters.
    pub fn list(&self) -> &[Problem] {
        &self.list
    }

    /// Into the counters.
    pub fn into_list(self) -> Vec<Problem> {
        self.list
    }
}
