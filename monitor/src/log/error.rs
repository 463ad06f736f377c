//! [`LogError`]: everything that can go wrong reading or writing an fdd MCAP log.
//!
//! Every error names the file, and where known the topic, the message's log time and the byte
//! offset in the file (of the record, or of the chunk the message was stored in; a message's own
//! position inside a compressed chunk is not a file offset). [`LogError::is_fatal`] tells the
//! errors after which the reader cannot go on from those it reports and then continues past.

use std::fmt;
use std::path::{Path, PathBuf};

use thiserror::Error;

/// The part of an MCAP file a CRC covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CrcSection {
    /// The uncompressed records of one chunk (the chunk record's `uncompressed_crc`).
    Chunk,
    /// Every byte from the start of the file up to the DataEnd record.
    DataSection,
    /// The summary section and the start of the footer.
    Summary,
}

impl fmt::Display for CrcSection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CrcSection::Chunk => "chunk",
            CrcSection::DataSection => "data section",
            CrcSection::Summary => "summary section",
        })
    }
}

/// An error reading or writing an MCAP log. See the [module documentation](self).
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum LogError {
    /// The file does not exist or cannot be opened for reading. Fatal.
    #[error("{}: cannot open: {source}", file.display())]
    Open {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file cannot be created for writing. Fatal.
    #[error("{}: cannot create: {source}", file.display())]
    Create {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Reading failed at `offset`. Fatal.
    #[error("{}: read error at byte {offset}: {source}", file.display())]
    Io {
        file: PathBuf,
        offset: u64,
        #[source]
        source: std::io::Error,
    },
    /// The file does not start with the MCAP magic bytes. Fatal.
    #[error("{}: not an MCAP file (it does not start with the MCAP magic bytes)", file.display())]
    NotMcap { file: PathBuf },
    /// The file ends early: inside a record, or before its DataEnd record or footer (a writer
    /// that did not finish). Everything before `offset` has been read. Fatal.
    #[error("{}: truncated at byte {offset}: {detail}", file.display())]
    Truncated {
        file: PathBuf,
        offset: u64,
        detail: String,
    },
    /// The record structure at `offset` is invalid (an impossible length, an unparsable
    /// record outside any chunk); the reader cannot find the next record. Fatal.
    ///
    /// A record whose length runs past the end of a file that ends with a valid footer and end
    /// magic is corruption, not truncation: the file is complete, its record framing is wrong.
    #[error("{}: corrupt at byte {offset}: {detail}", file.display())]
    Corrupt {
        file: PathBuf,
        offset: u64,
        detail: String,
    },
    /// Reading the file would cost more than a limit of [`ReadOptions`] allows (too many
    /// chunk indexes, channels or schemas, a message, record or summary larger than allowed,
    /// chunks that decompress to more than the budget for the file's size). The summary size
    /// and the counts are checked before what they bound is allocated, the budget before a
    /// chunk is decompressed. `limit` names the [`ReadOptions`] field, `value` its setting (in
    /// the field's unit); a trusted file is read by raising that field. Fatal.
    ///
    /// [`ReadOptions`]: crate::log::ReadOptions
    #[error(
        "{}: {what}{}: over the reader's limit {limit} = {value}; if the file is trusted, raise it (`[replay.limits] {limit}` in the runtime configuration, ReadOptions::{limit} for a host)",
        file.display(),
        at_byte(offset)
    )]
    LimitExceeded {
        file: PathBuf,
        /// The [`ReadOptions`](crate::log::ReadOptions) field that sets the limit.
        limit: &'static str,
        /// The limit's value, in the unit of that field (a count, or bytes, or a ratio).
        value: u64,
        /// The byte offset of the record concerned, where there is one.
        offset: Option<u64>,
        /// What exceeds the limit, with the amount.
        what: String,
    },
    /// A CRC does not match. Chunk CRCs are always checked: the reader reports the mismatch,
    /// skips the chunk and continues. The data and summary section CRCs are checked with
    /// [`ReadOptions::validate_crcs`], and a mismatch there is fatal.
    ///
    /// [`ReadOptions::validate_crcs`]: crate::log::ReadOptions::validate_crcs
    #[error(
        "{}: {section} CRC mismatch (record at byte {offset}): stored {stored:#010x}, computed {computed:#010x}",
        file.display()
    )]
    CrcMismatch {
        file: PathBuf,
        section: CrcSection,
        offset: u64,
        stored: u32,
        computed: u32,
    },
    /// The chunk at `offset` cannot be decompressed or parsed; its messages are skipped and the
    /// reader continues with the next chunk.
    #[error("{}: unreadable chunk at byte {offset} (skipped): {detail}", file.display())]
    BadChunk {
        file: PathBuf,
        offset: u64,
        detail: String,
    },
    /// A message refers to a channel id that no Channel record defines; the message is skipped.
    #[error(
        "{}: message at {log_time_ns} ns (record or chunk at byte {offset}) uses unknown channel id {channel_id} (skipped)",
        file.display()
    )]
    UnknownChannel {
        file: PathBuf,
        offset: u64,
        log_time_ns: u64,
        channel_id: u16,
    },
    /// A message's bytes are not valid JSON. Per message.
    #[error(
        "{}: {topic} at {log_time_ns} ns (record or chunk at byte {offset}): invalid JSON: {source}",
        file.display()
    )]
    InvalidJson {
        file: PathBuf,
        topic: String,
        log_time_ns: u64,
        offset: u64,
        #[source]
        source: serde_json::Error,
    },
    /// A message is valid JSON but lacks a field the caller asked for. Per message.
    #[error(
        "{}: {topic} at {log_time_ns} ns (record or chunk at byte {offset}): field '{field}' is missing",
        file.display()
    )]
    MissingField {
        file: PathBuf,
        topic: String,
        log_time_ns: u64,
        offset: u64,
        field: String,
    },
    /// A field the caller asked for as a number holds something else. Per message.
    #[error(
        "{}: {topic} at {log_time_ns} ns (record or chunk at byte {offset}): field '{field}' is not a number (it is {found})",
        file.display()
    )]
    NotANumber {
        file: PathBuf,
        topic: String,
        log_time_ns: u64,
        offset: u64,
        field: String,
        found: &'static str,
    },
    /// A message is valid JSON but does not have the shape of the requested type (a field of
    /// the wrong type, an unknown enum value). Per message.
    #[error(
        "{}: {topic} at {log_time_ns} ns (record or chunk at byte {offset}): does not match the message type: {source}",
        file.display()
    )]
    WrongShape {
        file: PathBuf,
        topic: String,
        log_time_ns: u64,
        offset: u64,
        #[source]
        source: serde_json::Error,
    },
    /// The writer was asked to write to a topic that has no schema.
    #[error(
        "{}: topic '{topic}' has no schema: use a built-in topic or register it with LogWriter::add_topic",
        file.display()
    )]
    UnknownTopic { file: PathBuf, topic: String },
    /// A schema given to [`LogWriter::add_topic`](crate::log::LogWriter::add_topic) is not a
    /// JSON object, or the topic is already registered with another schema.
    #[error("{}: topic '{topic}': {detail}", file.display())]
    BadSchema {
        file: PathBuf,
        topic: String,
        detail: String,
    },
    /// A message could not be serialized to JSON.
    #[error("{}: {topic} at {log_time_ns} ns: cannot serialize: {source}", file.display())]
    Serialize {
        file: PathBuf,
        topic: String,
        log_time_ns: u64,
        #[source]
        source: serde_json::Error,
    },
    /// The MCAP writer failed (I/O error, or [`LogWriter::finish`] could not complete the
    /// file). Fatal.
    ///
    /// [`LogWriter::finish`]: crate::log::LogWriter::finish
    #[error("{}: MCAP write failed{}: {source}", file.display(), write_context(topic, log_time_ns))]
    Write {
        file: PathBuf,
        topic: Option<String>,
        log_time_ns: Option<u64>,
        #[source]
        source: mcap::McapError,
    },
}

fn at_byte(offset: &Option<u64>) -> String {
    offset
        .map(|o| format!(" (at byte {o})"))
        .unwrap_or_default()
}

fn write_context(topic: &Option<String>, log_time_ns: &Option<u64>) -> String {
    match (topic, log_time_ns) {
        (Some(t), Some(ns)) => format!(" ({t} at {ns} ns)"),
        (Some(t), None) => format!(" ({t})"),
        (None, Some(ns)) => format!(" (at {ns} ns)"),
        (None, None) => String::new(),
    }
}

impl LogError {
    /// The file the error is about.
    pub fn file(&self) -> &Path {
        match self {
            LogError::Open { file, .. }
            | LogError::Create { file, .. }
            | LogError::Io { file, .. }
            | LogError::NotMcap { file }
            | LogError::Truncated { file, .. }
            | LogError::Corrupt { file, .. }
            | LogError::LimitExceeded { file, .. }
            | LogError::CrcMismatch { file, .. }
            | LogError::BadChunk { file, .. }
            | LogError::UnknownChannel { file, .. }
            | LogError::InvalidJson { file, .. }
            | LogError::MissingField { file, .. }
            | LogError::NotANumber { file, .. }
            | LogError::WrongShape { file, .. }
            | LogError::UnknownTopic { file, .. }
            | LogError::BadSchema { file, .. }
            | LogError::Serialize { file, .. }
            | LogError::Write { file, .. } => file,
        }
    }

    /// The topic, where the error is about one message or topic.
    pub fn topic(&self) -> Option<&str> {
        match self {
            LogError::InvalidJson { topic, .. }
            | LogError::MissingField { topic, .. }
            | LogError::NotANumber { topic, .. }
            | LogError::WrongShape { topic, .. }
            | LogError::UnknownTopic { topic, .. }
            | LogError::BadSchema { topic, .. }
            | LogError::Serialize { topic, .. } => Some(topic),
            LogError::Write { topic, .. } => topic.as_deref(),
            _ => None,
        }
    }

    /// The log time of the message concerned, ns, where known.
    pub fn log_time_ns(&self) -> Option<u64> {
        match self {
            LogError::UnknownChannel { log_time_ns, .. }
            | LogError::InvalidJson { log_time_ns, .. }
            | LogError::MissingField { log_time_ns, .. }
            | LogError::NotANumber { log_time_ns, .. }
            | LogError::WrongShape { log_time_ns, .. }
            | LogError::Serialize { log_time_ns, .. } => Some(*log_time_ns),
            LogError::Write { log_time_ns, .. } => *log_time_ns,
            _ => None,
        }
    }

    /// The byte offset in the file (of the record, or of the chunk holding the message), where
    /// known.
    pub fn offset(&self) -> Option<u64> {
        match self {
            LogError::Io { offset, .. }
            | LogError::Truncated { offset, .. }
            | LogError::Corrupt { offset, .. }
            | LogError::CrcMismatch { offset, .. }
            | LogError::BadChunk { offset, .. }
            | LogError::UnknownChannel { offset, .. }
            | LogError::InvalidJson { offset, .. }
            | LogError::MissingField { offset, .. }
            | LogError::NotANumber { offset, .. }
            | LogError::WrongShape { offset, .. } => Some(*offset),
            LogError::LimitExceeded { offset, .. } => *offset,
            _ => None,
        }
    }

    /// True when reading (or writing) cannot continue after this error: the reader yields no
    /// more messages after a fatal error. Non-fatal errors concern one message or one chunk,
    /// which the reader skips before going on.
    pub fn is_fatal(&self) -> bool {
        match self {
            LogError::CrcMismatch { section, .. } => *section != CrcSection::Chunk,
            LogError::BadChunk { .. }
            | LogError::UnknownChannel { .. }
            | LogError::InvalidJson { .. }
            | LogError::MissingField { .. }
            | LogError::NotANumber { .. }
            | LogError::WrongShape { .. }
            | LogError::UnknownTopic { .. }
            | LogError::BadSchema { .. }
            | LogError::Serialize { .. } => false,
            LogError::Open { .. }
            | LogError::Create { .. }
            | LogError::Io { .. }
            | LogError::NotMcap { .. }
            | LogError::Truncated { .. }
            | LogError::Corrupt { .. }
            | LogError::LimitExceeded { .. }
            | LogError::Write { .. } => true,
        }
    }
}
