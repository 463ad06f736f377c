//! [`LogReader`]: streams the messages of an MCAP file in log-time order, one chunk at a time.
//!
//! # How it reads
//!
//! - **Indexed** (a finished file): the footer points to the summary section, whose chunk
//!   indexes give each chunk's offset and time range. Chunks are loaded in order of their first
//!   log time, and a chunk is loaded only when its first log time is not after the next message
//!   to yield; messages are merged across the loaded chunks by (log time, chunk position in the
//!   file, position in the chunk), through a binary heap holding each loaded chunk's next
//!   message (O(log k) per message for k loaded chunks). Memory holds only the chunks that
//!   overlap in time, which for files fdd writes (in time order) is one, or two at a boundary.
//!   The chunk indexes are checked when opening: one repeated (same offset and length) is used
//!   once, with a `tracing` warning; one whose bytes overlap an earlier chunk's or leave the
//!   data section is refused, and its chunk reported as a [`LogError::BadChunk`] when its turn
//!   comes. So every byte of the data section is decompressed at most once.
//! - **Linear** (no usable summary: a truncated file, a writer that did not finish, a file
//!   without chunk indexes): a `tracing` warning, then the records are read from start to end,
//!   one chunk at a time, and messages are yielded in **file order**; the caller must check that
//!   log times do not go backwards. A file cut short ends with a [`LogError::Truncated`] naming
//!   the byte where the readable data stops, after every complete chunk has been yielded. A
//!   file that ends with a valid footer and end magic is complete: a record running past the
//!   footer there is a [`LogError::Corrupt`], not a truncation.
//!
//! Chunks are decompressed whole and their CRC checked before any of their records is read. A
//! chunk of the usual kind (zstd or uncompressed, consistent lengths, complete records, right
//! CRC) is decoded here directly, its messages left in the decompressed chunk; anything else
//! (lz4 chunks, damaged chunks) goes through the mcap crate's sans-io reader, which also names
//! what is wrong. The record framing, the summary and the footer are parsed here with bounds
//! checks, so a corrupt length never causes a huge allocation or a panic.
//!
//! # Limits
//!
//! What one file may cost is bounded by [`ReadOptions`]: record, message and summary sizes
//! (bytes), numbers of chunk indexes, channels and schemas, and the total decompressed bytes
//! relative to the file's size. Going over one is a fatal [`LogError::LimitExceeded`] naming
//! the file, the limit (the [`ReadOptions`] field), its value and how to raise it. Sizes and
//! counts are checked before what they bound is allocated, the decompression budget before a
//! chunk is decompressed. The defaults are far above what fdd writes.
//!
//! # Errors
//!
//! [`LogReader::open_with`] fails on what makes the file unreadable: missing or unreadable file,
//! bad magic, an empty file, a summary over a limit and, with [`ReadOptions::validate_crcs`], a
//! data-section or summary CRC mismatch.
//! While iterating, a problem with one chunk ([`LogError::BadChunk`], a chunk CRC mismatch) or
//! one message ([`LogError::UnknownChannel`]) is yielded as an `Err` and reading continues
//! with the next one; a fatal error ([`LogError::is_fatal`]: truncation, corruption, a limit,
//! I/O) is the last item. Failed chunks are counted ([`ReadStats::chunks_failed`]), so that a
//! file whose chunks all fail ([`ReadStats::all_chunks_failed`]) is not taken for an empty
//! log. Decoding a message ([`LogMessage::decode`], [`LogMessage::field_f64`]) reports bad JSON
//! or a missing field with the file, topic, log time and chunk offset.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap, HashSet};
use std::fs::File;
use std::io::{self, BufReader, Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::Arc;

use mcap::records::op;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use serde::de::DeserializeOwned;

use super::crc32::Crc32;
use super::error::{CrcSection, LogError};
use super::field::{json_field_f64, FieldLookupError};
use super::records::{
    parse_channel, parse_chunk_index, parse_message_header, parse_schema, parse_statistics,
    ChunkIdx, Cur, MessageHeader, Statistics, DATA_END_RECORD, FOOTER_AND_MAGIC, MAGIC,
    MESSAGE_HEADER, RECORD_HEADER,
};

/// Reader settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadOptions {
    /// Also check the CRCs that cover the whole file: the data section and summary CRCs when
    /// opening (a mismatch fails the open; this reads the whole file once more), or in linear
    /// mode as the reading reaches them. Off by default.
    ///
    /// Each chunk's own CRC is always checked, before any of its messages is yielded (a
    /// mismatch is reported and the chunk skipped): the chunk is decompressed whole anyway,
    /// which is faster than streaming it record by record, and hashing it costs little. A
    /// stored CRC of 0 means "not computed" and is not checked.
    pub validate_crcs: bool,
    /// Only yield messages on these topics (all when `None`). Other messages are skipped when
    /// their chunk is loaded, without being copied.
    pub topics: Option<Vec<String>>,
    /// Largest record (chunk, decompressed chunk, record outside chunks) the reader will hold
    /// in memory, bytes; a larger chunk is reported and skipped ([`LogError::BadChunk`]), a
    /// larger record outside chunks stops the reading ([`LogError::LimitExceeded`]), instead of
    /// being allocated. Default [`Self::DEFAULT_MAX_RECORD_BYTES`].
    pub max_record_bytes: u64,
    /// Most chunk index records the summary may hold, a count (each costs about 100 bytes of
    /// memory while the file is opened, on top of the summary itself, and about 60 after). More fail the open with [`LogError::LimitExceeded`]. Repeated
    /// indexes of one chunk count here before they are merged. Default
    /// [`Self::DEFAULT_MAX_CHUNK_INDEXES`].
    pub max_chunk_indexes: u64,
    /// Most channels (distinct channel ids, in the summary or the data) the file may define, a
    /// count. More stop the reading with [`LogError::LimitExceeded`]. Default
    /// [`Self::DEFAULT_MAX_CHANNELS`].
    pub max_channels: u64,
    /// Most schemas (distinct schema ids, in the summary or the data) the file may define, a
    /// count; each holds its schema text in memory. More stop the reading with
    /// [`LogError::LimitExceeded`]. Default [`Self::DEFAULT_MAX_SCHEMAS`].
    pub max_schemas: u64,
    /// Largest message payload (the message data, without its 22-byte header), bytes. A larger
    /// one stops the reading with [`LogError::LimitExceeded`]. Default
    /// [`Self::DEFAULT_MAX_MESSAGE_BYTES`].
    pub max_message_bytes: u64,
    /// Largest summary section, bytes: the reader holds it whole while opening the file. A
    /// larger one fails the open with [`LogError::LimitExceeded`]. Default
    /// [`Self::DEFAULT_MAX_SUMMARY_BYTES`].
    pub max_summary_bytes: u64,
    /// Decompression budget, as a ratio (dimensionless) to the file's size: the chunks read
    /// may decompress to at most `max_decompression_ratio` times the file's bytes in total
    /// (counted from each chunk's declared uncompressed size, before it is decompressed), or
    /// [`decompressed_bytes_floor`](Self::decompressed_bytes_floor) if that is more. A chunk
    /// that would go over the budget stops the reading with [`LogError::LimitExceeded`]: this
    /// bounds the work and memory a small, highly compressed ("zip bomb") file can cost.
    /// Default [`Self::DEFAULT_MAX_DECOMPRESSION_RATIO`].
    pub max_decompression_ratio: u64,
    /// The smallest decompression budget, bytes, whatever the file's size, so that small
    /// files of very compressible messages still read (see
    /// [`max_decompression_ratio`](Self::max_decompression_ratio)). Default
    /// [`Self::DEFAULT_DECOMPRESSED_BYTES_FLOOR`].
    pub decompressed_bytes_floor: u64,
}

impl ReadOptions {
    /// Default [`ReadOptions::max_record_bytes`]: 256 MiB.
    pub const DEFAULT_MAX_RECORD_BYTES: u64 = 256 << 20;
    /// Default [`ReadOptions::max_chunk_indexes`]: 1,000,000 (fdd writes one per MiB of
    /// messages: a terabyte of log).
    pub const DEFAULT_MAX_CHUNK_INDEXES: u64 = 1_000_000;
    /// Default [`ReadOptions::max_channels`]: 10,000 (fdd writes about 20).
    pub const DEFAULT_MAX_CHANNELS: u64 = 10_000;
    /// Default [`ReadOptions::max_schemas`]: 10,000 (fdd writes about 20).
    pub const DEFAULT_MAX_SCHEMAS: u64 = 10_000;
    /// Default [`ReadOptions::max_message_bytes`]: 16 MiB (fdd's JSON messages are under
    /// 4 KiB).
    pub const DEFAULT_MAX_MESSAGE_BYTES: u64 = 16 << 20;
    /// Default [`ReadOptions::max_summary_bytes`]: 128 MiB (fdd's summaries are a few KiB).
    pub const DEFAULT_MAX_SUMMARY_BYTES: u64 = 128 << 20;
    /// Default [`ReadOptions::max_decompression_ratio`]: 1000 (zstd level 1 on fdd's JSON
    /// gives about 10).
    pub const DEFAULT_MAX_DECOMPRESSION_RATIO: u64 = 1000;
    /// Default [`ReadOptions::decompressed_bytes_floor`]: 64 MiB.
    pub const DEFAULT_DECOMPRESSED_BYTES_FLOOR: u64 = 64 << 20;

    /// The decompression budget for a file of `file_bytes` bytes, bytes: the larger of
    /// `max_decompression_ratio * file_bytes` and `decompressed_bytes_floor`.
    pub fn decompressed_budget(&self, file_bytes: u64) -> u64 {
        self.max_decompression_ratio
            .saturating_mul(file_bytes)
            .max(self.decompressed_bytes_floor)
    }
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions {
            validate_crcs: false,
            topics: None,
            max_record_bytes: Self::DEFAULT_MAX_RECORD_BYTES,
            max_chunk_indexes: Self::DEFAULT_MAX_CHUNK_INDEXES,
            max_channels: Self::DEFAULT_MAX_CHANNELS,
            max_schemas: Self::DEFAULT_MAX_SCHEMAS,
            max_message_bytes: Self::DEFAULT_MAX_MESSAGE_BYTES,
            max_summary_bytes: Self::DEFAULT_MAX_SUMMARY_BYTES,
            max_decompression_ratio: Self::DEFAULT_MAX_DECOMPRESSION_RATIO,
            decompressed_bytes_floor: Self::DEFAULT_DECOMPRESSED_BYTES_FLOOR,
        }
    }
}

/// How the file is being read (see the [module documentation](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadMode {
    /// From the summary's chunk indexes: messages in log-time order.
    Indexed,
    /// Start to end without an index: messages in file order.
    Linear,
}

/// A schema record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SchemaInfo {
    /// Schema id in the file.
    pub id: u16,
    /// Schema name, e.g. `fdd.TpsVoltage`.
    pub name: String,
    /// Schema encoding, `jsonschema` for fdd's channels.
    pub encoding: String,
    /// The schema text.
    pub data: Vec<u8>,
}

/// A channel record, with its schema when the file has it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// Channel id in the file.
    pub id: u16,
    /// The topic.
    pub topic: Arc<str>,
    /// Message encoding, `json` for fdd's channels.
    pub message_encoding: String,
    /// The schema id (0: no schema).
    pub schema_id: u16,
    /// The schema, once its record has been read.
    pub schema: Option<Arc<SchemaInfo>>,
    /// Whether messages on this channel pass [`ReadOptions::topics`].
    wanted: bool,
}

/// Counters describing the reading so far (for progress and for checking that memory stays
/// bounded).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReadStats {
    /// Chunks in the file's index (indexed mode), once each: repeated indexes of one chunk
    /// count once, refused ones (overlapping another chunk, outside the data section) count;
    /// `None` in linear mode. At the end of an indexed read that no fatal error stopped,
    /// `chunks_loaded + chunks_failed` equals it.
    pub chunks_total: Option<usize>,
    /// Chunks loaded (read, decompressed and parsed without error) so far.
    pub chunks_loaded: usize,
    /// Chunks that could not be used so far, each reported by one non-fatal error: a chunk
    /// CRC mismatch, a chunk that cannot be decompressed or parsed, a chunk index that does not
    /// point to a chunk or was refused. See [`ReadStats::all_chunks_failed`].
    pub chunks_failed: usize,
    /// Indexes of an already indexed chunk (same offset and length) that the summary repeats,
    /// dropped when opening (a `tracing` warning says how many).
    pub duplicate_chunk_indexes: usize,
    /// Decompressed chunk bytes so far (each chunk's declared uncompressed size, counted when
    /// it is read), bytes; see [`ReadOptions::max_decompression_ratio`].
    pub decompressed_bytes: u64,
    /// Chunks held in memory right now.
    pub resident_chunks: usize,
    /// The most chunks held in memory at once.
    pub max_resident_chunks: usize,
    /// Messages yielded so far.
    pub messages: u64,
}

impl ReadStats {
    /// True when at least one chunk failed and none could be read: a file whose chunks are all
    /// unreadable (an unsupported compression, damage everywhere) is then not mistaken for an
    /// empty log. Meaningful once the reading has ended.
    pub fn all_chunks_failed(&self) -> bool {
        self.chunks_failed > 0 && self.chunks_loaded == 0
    }
}

/// One message, borrowed from the reader (see [`LogReader::next_message`]).
#[derive(Debug, Clone, Copy)]
pub struct LogMessage<'a> {
    /// The channel's topic.
    pub topic: &'a str,
    /// Log time, ns (for fdd's files the sample time).
    pub log_time_ns: u64,
    /// Publish time, ns (fdd writes the log time).
    pub publish_time_ns: u64,
    /// The channel's sequence number of the message.
    pub sequence: u32,
    /// The message bytes (JSON for fdd's channels).
    pub data: &'a [u8],
    /// The channel record.
    pub channel: &'a ChannelInfo,
    /// Byte offset of the chunk (or, outside chunks, the record) holding the message.
    pub offset: u64,
    file: &'a Arc<Path>,
}

/// One message, owned (what the reader's [`Iterator`] yields).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OwnedLogMessage {
    /// The channel's topic.
    pub topic: Arc<str>,
    /// Log time, ns.
    pub log_time_ns: u64,
    /// Publish time, ns.
    pub publish_time_ns: u64,
    /// The channel's sequence number of the message.
    pub sequence: u32,
    /// The message bytes.
    pub data: Vec<u8>,
    /// Byte offset of the chunk (or record) holding the message.
    pub offset: u64,
    file: Arc<Path>,
}

/// What decoding needs to name a message in an error.
struct MsgRef<'a> {
    file: &'a Path,
    topic: &'a str,
    log_time_ns: u64,
    offset: u64,
    data: &'a [u8],
}

impl MsgRef<'_> {
    fn decode<T: DeserializeOwned>(&self) -> Result<T, LogError> {
        serde_json::from_slice(self.data).map_err(|e| self.json_error(e))
    }

    fn json(&self) -> Result<serde_json::Value, LogError> {
        serde_json::from_slice(self.data).map_err(|e| self.json_error(e))
    }

    fn json_error(&self, source: serde_json::Error) -> LogError {
        use serde_json::error::Category;
        let (file, topic, log_time_ns, offset) = (
            self.file.to_path_buf(),
            self.topic.to_string(),
            self.log_time_ns,
            self.offset,
        );
        match source.classify() {
            Category::Data => {
                let text = source.to_string();
                match text
                    .strip_prefix("missing field `")
                    .and_then(|rest| rest.split('`').next())
                {
                    Some(field) => LogError::MissingField {
                        file,
                        topic,
                        log_time_ns,
                        offset,
                        field: field.to_string(),
                    },
                    None => LogError::WrongShape {
                        file,
                        topic,
                        log_time_ns,
                        offset,
                        source,
                    },
                }
            }
            Category::Io | Category::Syntax | Category::Eof => LogError::InvalidJson {
                file,
                topic,
                log_time_ns,
                offset,
                source,
            },
        }
    }

    #[inline]
    fn field_f64(&self, path: &str) -> Result<f64, LogError> {
        json_field_f64(self.data, path).map_err(|e| match e {
            FieldLookupError::Json(source) => self.json_error(source),
            FieldLookupError::Missing => LogError::MissingField {
                file: self.file.to_path_buf(),
                topic: self.topic.to_string(),
                log_time_ns: self.log_time_ns,
                offset: self.offset,
                field: path.to_string(),
            },
            FieldLookupError::NotANumber(found) => LogError::NotANumber {
                file: self.file.to_path_buf(),
                topic: self.topic.to_string(),
                log_time_ns: self.log_time_ns,
                offset: self.offset,
                field: path.to_string(),
                found,
            },
        })
    }
}

impl<'a> LogMessage<'a> {
    #[inline]
    fn msg_ref(&self) -> MsgRef<'a> {
        MsgRef {
            file: self.file,
            topic: self.topic,
            log_time_ns: self.log_time_ns,
            offset: self.offset,
            data: self.data,
        }
    }

    /// The file the message was read from.
    pub fn file(&self) -> &'a Path {
        self.file
    }

    /// Decodes the JSON message into `T`. Invalid JSON, a missing field or a mismatched type
    /// is a per-message [`LogError`] naming the file, topic and log time.
    pub fn decode<T: DeserializeOwned>(&self) -> Result<T, LogError> {
        self.msg_ref().decode()
    }

    /// Parses the JSON message into a `serde_json::Value`.
    pub fn json(&self) -> Result<serde_json::Value, LogError> {
        self.msg_ref().json()
    }

    /// The number at `path` (a field name, or names joined by `.`), `null` as NaN, without
    /// building a `Value`. See [`json_field_f64`].
    pub fn field_f64(&self, path: &str) -> Result<f64, LogError> {
        self.msg_ref().field_f64(path)
    }

    /// An owned copy.
    pub fn to_owned_message(&self) -> OwnedLogMessage {
        OwnedLogMessage {
            topic: self.channel.topic.clone(),
            log_time_ns: self.log_time_ns,
            publish_time_ns: self.publish_time_ns,
            sequence: self.sequence,
            data: self.data.to_vec(),
            offset: self.offset,
            file: self.file.clone(),
        }
    }
}

impl OwnedLogMessage {
    fn msg_ref(&self) -> MsgRef<'_> {
        MsgRef {
            file: &self.file,
            topic: &self.topic,
            log_time_ns: self.log_time_ns,
            offset: self.offset,
            data: &self.data,
        }
    }

    /// The file the message was read from.
    pub fn file(&self) -> &Path {
        &self.file
    }

    /// See [`LogMessage::decode`].
    pub fn decode<T: DeserializeOwned>(&self) -> Result<T, LogError> {
        self.msg_ref().decode()
    }

    /// See [`LogMessage::json`].
    pub fn json(&self) -> Result<serde_json::Value, LogError> {
        self.msg_ref().json()
    }

    /// See [`LogMessage::field_f64`].
    pub fn field_f64(&self, path: &str) -> Result<f64, LogError> {
        self.msg_ref().field_f64(path)
    }
}

/// The file, its read position, and (in linear mode with validation) the running CRC of what
/// has been read.
struct Source {
    r: BufReader<File>,
    pos: u64,
    hasher: Option<Crc32>,
}

impl Source {
    fn seek(&mut self, pos: u64) -> io::Result<()> {
        self.r.seek(SeekFrom::Start(pos))?;
        self.pos = pos;
        Ok(())
    }

    fn read_exact(&mut self, buf: &mut [u8]) -> io::Result<()> {
        self.r.read_exact(buf)?;
        if let Some(h) = self.hasher.as_mut() {
            h.update(buf);
        }
        self.pos += buf.len() as u64;
        Ok(())
    }

    /// Skips `n` bytes (reading them when they must be hashed).
    fn skip(&mut self, n: u64) -> io::Result<()> {
        if self.hasher.is_some() {
            let mut scratch = [0u8; 8192];
            let mut left = n;
            while left > 0 {
                let k = left.min(scratch.len() as u64) as usize;
                self.read_exact(&mut scratch[..k])?;
                left -= k as u64;
            }
            Ok(())
        } else {
            let to = self
                .pos
                .checked_add(n)
                .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "skip past u64::MAX"))?;
            self.seek(to)
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    log_time: u64,
    publish_time: u64,
    sequence: u32,
    channel_id: u16,
    start: usize,
    len: usize,
}

/// The messages of one loaded chunk (or one message outside chunks), in yield order.
#[derive(Debug, Default)]
struct Batch {
    offset: u64,
    entries: Vec<Entry>,
    arena: Vec<u8>,
    pos: usize,
}

impl Batch {
    fn reset(&mut self, offset: u64) {
        self.offset = offset;
        self.entries.clear();
        self.arena.clear();
        self.pos = 0;
    }

    fn push(&mut self, h: MessageHeader, data: &[u8]) {
        self.entries.push(Entry {
            log_time: h.log_time,
            publish_time: h.publish_time,
            sequence: h.sequence,
            channel_id: h.channel_id,
            start: self.arena.len(),
            len: data.len(),
        });
        self.arena.extend_from_slice(data);
    }

    fn exhausted(&self) -> bool {
        self.pos >= self.entries.len()
    }
}

enum Step {
    /// Yield the next message of the chunk in this slot.
    Yield(usize),
    Error(LogError),
    End,
}

/// Why a chunk index of the summary is not used (its chunk is reported as a
/// [`LogError::BadChunk`] when its turn comes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Refusal {
    /// The byte range leaves the data section (which ends at `data_end`).
    OutsideData { data_end: u64 },
    /// The byte range overlaps that of the chunk indexed at `other` (kept: the first in file
    /// order).
    Overlaps { other: u64, other_end: u64 },
    /// The end time is before the start time.
    TimesReversed,
}

/// A chunk index to load (indexed mode), or to report as refused.
#[derive(Debug, Clone, Copy)]
struct PendingChunk {
    idx: ChunkIdx,
    refusal: Option<Refusal>,
}

/// The merge key of a resident chunk's next message: (log time, chunk offset in the file,
/// position in the chunk, slot). Chunk offsets differ between resident chunks (repeated
/// indexes are merged when opening), so the slot never decides.
type HeadKey = (u64, u64, usize, usize);

/// Streams the messages of an MCAP file; see the [module documentation](self).
///
/// Use [`next_message`](Self::next_message) for borrowed messages (no copy), or iterate for
/// owned ones:
///
/// ```no_run
/// use fdd_monitor::log::{LogReader, TpsVoltage};
///
/// let mut reader = LogReader::open("run.mcap")?;
/// while let Some(msg) = reader.next_message() {
///     let msg = match msg {
///         Ok(m) => m,
///         Err(e) if e.is_fatal() => return Err(e.into()),
///         Err(e) => { eprintln!("skipped: {e}"); continue; }
///     };
///     if msg.topic == "/throttle/tps" {
///         let v = msg.field_f64("voltage_v")?; // or msg.decode::<TpsVoltage>()?
///         println!("{} ns: {v} V", msg.log_time_ns);
///     }
/// }
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct LogReader {
    path: Arc<Path>,
    src: Source,
    file_len: u64,
    options: ReadOptions,
    wanted_topics: Option<HashSet<String>>,
    mode: ReadMode,
    channels: Vec<Option<ChannelInfo>>,
    schemas: BTreeMap<u16, Arc<SchemaInfo>>,
    statistics: Option<Statistics>,
    /// Indexed mode: chunks in load order, and the next to load.
    pending: Vec<PendingChunk>,
    next_pending: usize,
    /// The loaded chunks (at most one in linear mode), by slot; `None` is a free slot.
    slots: Vec<Option<Batch>>,
    free_slots: Vec<usize>,
    resident_count: usize,
    /// Indexed mode: the next message of every resident chunk, smallest key first, so that
    /// choosing the next message costs O(log k) for k resident chunks.
    heads: BinaryHeap<Reverse<HeadKey>>,
    /// Indexed mode: the next message of the chunk the last message came from, kept out of
    /// `heads` until another chunk's message comes first, so that reading one chunk at a time
    /// (fdd's files) costs no heap operation.
    current: Option<HeadKey>,
    /// The slot whose last message was just yielded; freed on the next call, when the
    /// message's borrow has ended.
    done_slot: Option<usize>,
    /// Linear mode: the slot of the chunk being yielded.
    linear_slot: Option<usize>,
    /// Empty batches kept for their buffers.
    free: Vec<Batch>,
    /// Where the footer starts, when the file ends with a footer record and the end magic: a
    /// record running past it is then corruption, not truncation.
    footer_pos: Option<u64>,
    /// [`ReadOptions::decompressed_budget`] for this file, bytes.
    decompressed_budget: u64,
    /// Distinct channel ids defined so far.
    channel_count: usize,
    /// The body of the chunk record being decoded (kept for its capacity).
    chunk_buf: Vec<u8>,
    /// For [`LogReader::decode_chunk_directly`], made on first use.
    zstd: Option<zstd::bulk::Decompressor<'static>>,
    /// Whether plain chunks are decoded directly (always, but for the tests that compare with
    /// the general path).
    direct_chunks: bool,
    /// Linear mode: the DataEnd record has been read.
    seen_data_end: bool,
    finished: bool,
    stats: ReadStats,
}

impl std::fmt::Debug for LogReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogReader")
            .field("file", &self.path)
            .field("mode", &self.mode)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

/// Why the summary cannot be used (the reader then reads linearly).
type NoIndex = String;

impl LogReader {
    /// Opens `path` with the default options.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, LogError> {
        Self::open_with(path, ReadOptions::default())
    }

    /// Opens `path`: checks the magic, reads the footer and summary (or prepares a linear read
    /// when they are missing or unusable) and, with `validate_crcs`, checks the data section
    /// and summary CRCs. No message is read yet.
    pub fn open_with(path: impl AsRef<Path>, options: ReadOptions) -> Result<Self, LogError> {
        let path: Arc<Path> = Arc::from(path.as_ref());
        let open_err = |source| LogError::Open {
            file: path.to_path_buf(),
            source,
        };
        let file = File::open(&path).map_err(open_err)?;
        let meta = file.metadata().map_err(open_err)?;
        if meta.is_dir() {
            return Err(open_err(io::Error::other("is a directory")));
        }
        let file_len = meta.len();
        let decompressed_budget = options.decompressed_budget(file_len);
        let wanted_topics = options
            .topics
            .as_ref()
            .map(|t| t.iter().cloned().collect::<HashSet<_>>());
        let mut reader = LogReader {
            path,
            src: Source {
                r: BufReader::with_capacity(1 << 16, file),
                pos: 0,
                hasher: None,
            },
            file_len,
            options,
            wanted_topics,
            mode: ReadMode::Linear,
            channels: Vec::new(),
            schemas: BTreeMap::new(),
            statistics: None,
            pending: Vec::new(),
            next_pending: 0,
            slots: Vec::new(),
            free_slots: Vec::new(),
            resident_count: 0,
            heads: BinaryHeap::new(),
            current: None,
            done_slot: None,
            linear_slot: None,
            free: Vec::new(),
            footer_pos: None,
            decompressed_budget,
            channel_count: 0,
            chunk_buf: Vec::new(),
            zstd: None,
            direct_chunks: true,
            seen_data_end: false,
            finished: false,
            stats: ReadStats::default(),
        };
        reader.check_magic()?;
        match reader.read_index()? {
            Ok(()) => {
                reader.mode = ReadMode::Indexed;
                reader.stats.chunks_total = Some(reader.pending.len());
            }
            Err(reason) => {
                tracing::warn!(
                    file = %reader.path.display(),
                    "{reason}: reading the MCAP file linearly, messages in file order (not sorted by log time)"
                );
                reader.start_linear()?;
            }
        }
        Ok(reader)
    }

    /// The file being read.
    pub fn file(&self) -> &Path {
        &self.path
    }

    /// Indexed (log-time order) or linear (file order).
    pub fn mode(&self) -> ReadMode {
        self.mode
    }

    /// Counters of the reading so far.
    pub fn stats(&self) -> ReadStats {
        ReadStats {
            resident_chunks: self.resident_count,
            ..self.stats
        }
    }

    /// The number of messages in the file, from its statistics record (indexed mode only).
    pub fn message_count(&self) -> Option<u64> {
        self.statistics.map(|s| s.message_count)
    }

    /// First and last log time in the file, ns, from its statistics record (indexed mode, and
    /// only when the file has messages).
    pub fn time_range_ns(&self) -> Option<(u64, u64)> {
        self.statistics
            .filter(|s| s.message_count > 0)
            .map(|s| (s.start_time, s.end_time))
    }

    /// The channels known so far (in indexed mode all of them; in linear mode those read so
    /// far), by id.
    pub fn channels(&self) -> impl Iterator<Item = &ChannelInfo> {
        self.channels.iter().flatten()
    }

    /// The channel for `topic`, if known.
    pub fn channel(&self, topic: &str) -> Option<&ChannelInfo> {
        self.channels().find(|c| &*c.topic == topic)
    }

    fn err_io(&self, offset: u64, source: io::Error) -> LogError {
        LogError::Io {
            file: self.path.to_path_buf(),
            offset,
            source,
        }
    }

    fn check_magic(&mut self) -> Result<(), LogError> {
        let n = self.file_len.min(8) as usize;
        let mut head = [0u8; 8];
        self.src
            .read_exact(&mut head[..n])
            .map_err(|e| self.err_io(0, e))?;
        if head[..n] != MAGIC[..n] {
            return Err(LogError::NotMcap {
                file: self.path.to_path_buf(),
            });
        }
        if n < 8 {
            return Err(LogError::Truncated {
                file: self.path.to_path_buf(),
                offset: self.file_len,
                detail: format!(
                    "the file is {} bytes long, shorter than the MCAP magic",
                    self.file_len
                ),
            });
        }
        Ok(())
    }

    fn read_at(&mut self, offset: u64, buf: &mut [u8]) -> Result<(), LogError> {
        self.src
            .seek(offset)
            .and_then(|()| self.src.read_exact(buf))
            .map_err(|e| self.err_io(offset, e))
    }

    /// Reads the footer and summary. `Ok(Err(reason))`: no usable index, read linearly.
    fn read_index(&mut self) -> Result<Result<(), NoIndex>, LogError> {
        if self.file_len < 8 + FOOTER_AND_MAGIC {
            return Ok(Err("the file is too short to have a footer".into()));
        }
        let footer_pos = self.file_len - FOOTER_AND_MAGIC;
        let mut footer = [0u8; FOOTER_AND_MAGIC as usize];
        self.read_at(footer_pos, &mut footer)?;
        if footer[29..] != MAGIC[..] {
            return Ok(Err(
                "no end magic: the file is truncated or its writer did not finish".into(),
            ));
        }
        let mut c = Cur::new(&footer);
        let (opcode, len) = (c.bytes(1).map(|b| b[0]), c.u64());
        let (summary_start, _summary_offset_start, summary_crc) = (c.u64(), c.u64(), c.u32());
        let (Some(opcode), Some(len), Some(summary_start), Some(summary_crc)) =
            (opcode, len, summary_start, summary_crc)
        else {
            return Ok(Err("unreadable footer".into()));
        };
        if opcode != op::FOOTER || len != 20 {
            return Ok(Err("no footer record before the end magic".into()));
        }
        // The file is complete: whatever the summary, a record running past the footer is
        // corruption (linear mode tells it from truncation by this).
        self.footer_pos = Some(footer_pos);
        if summary_start == 0 {
            return Ok(Err("the file has no summary section".into()));
        }
        if summary_start < 8 + DATA_END_RECORD || summary_start > footer_pos {
            return Ok(Err(format!(
                "the footer's summary offset {summary_start} is outside the file"
            )));
        }
        let summary_len = footer_pos - summary_start;
        if summary_len > self.options.max_summary_bytes {
            return Err(self.limit(
                "max_summary_bytes",
                self.options.max_summary_bytes,
                Some(summary_start),
                format!("the summary section is {summary_len} bytes"),
            ));
        }
        let Ok(summary_len) = usize::try_from(summary_len) else {
            return Ok(Err(format!(
                "the summary section ({summary_len} bytes) does not fit in memory"
            )));
        };
        let mut summary = vec![0u8; summary_len];
        self.read_at(summary_start, &mut summary)?;
        if self.options.validate_crcs && summary_crc != 0 {
            let mut h = Crc32::new();
            h.update(&summary);
            h.update(&footer[..9 + 16]);
            let computed = h.finalize();
            if computed != summary_crc {
                return Err(LogError::CrcMismatch {
                    file: self.path.to_path_buf(),
                    section: CrcSection::Summary,
                    offset: summary_start,
                    stored: summary_crc,
                    computed,
                });
            }
        }

        // Parse the summary records. Schemas and channels: the first definition of an id wins
        // (as in the data section), so repeated records cost nothing.
        let mut chunks: Vec<ChunkIdx> = Vec::new();
        let mut statistics = None;
        let mut schemas: BTreeMap<u16, SchemaInfo> = BTreeMap::new();
        let mut channels: BTreeMap<u16, (u16, String, String)> = BTreeMap::new();
        let mut rest = &summary[..];
        let mut at = summary_start;
        while !rest.is_empty() {
            let mut c = Cur::new(rest);
            let (Some(opcode), Some(len)) = (c.bytes(1).map(|b| b[0]), c.u64()) else {
                return Ok(Err(format!("summary record at byte {at} is cut short")));
            };
            let body = match usize::try_from(len).ok().and_then(|n| c.bytes(n)) {
                Some(b) => b,
                None => {
                    return Ok(Err(format!(
                        "summary record at byte {at} runs past the footer"
                    )))
                }
            };
            let bad = |what: &str| Ok(Err(format!("unreadable {what} record at byte {at}")));
            match opcode {
                op::SCHEMA => match parse_schema(body) {
                    Some(s) => {
                        if s.id != 0 && !schemas.contains_key(&s.id) {
                            if schemas.len() as u64 >= self.options.max_schemas {
                                return Err(self.too_many_schemas(Some(at)));
                            }
                            schemas.insert(s.id, s);
                        }
                    }
                    None => return bad("schema"),
                },
                op::CHANNEL => match parse_channel(body) {
                    Some(ch) => {
                        if !channels.contains_key(&ch.id) {
                            if channels.len() as u64 >= self.options.max_channels {
                                return Err(self.too_many_channels(Some(at)));
                            }
                            channels.insert(
                                ch.id,
                                (
                                    ch.schema_id,
                                    ch.topic.to_string(),
                                    ch.message_encoding.to_string(),
                                ),
                            );
                        }
                    }
                    None => return bad("channel"),
                },
                op::CHUNK_INDEX => match parse_chunk_index(body) {
                    Some(ci) => {
                        if chunks.len() as u64 >= self.options.max_chunk_indexes {
                            return Err(self.limit(
                                "max_chunk_indexes",
                                self.options.max_chunk_indexes,
                                Some(at),
                                format!(
                                    "the summary holds more than {} chunk indexes",
                                    self.options.max_chunk_indexes
                                ),
                            ));
                        }
                        chunks.push(ci);
                    }
                    None => return bad("chunk index"),
                },
                op::STATISTICS => match parse_statistics(body) {
                    Some(s) => statistics = Some(s),
                    None => return bad("statistics"),
                },
                _ => {}
            }
            rest = c.b;
            at += RECORD_HEADER + len;
        }
        drop(summary);
        match statistics {
            None if chunks.is_empty() => {
                return Ok(Err(
                    "the summary has no chunk index and no statistics".into()
                ))
            }
            Some(s) if chunks.is_empty() && s.message_count > 0 => {
                return Ok(Err("the summary has no chunk index".into()))
            }
            _ => {}
        }
        let data_end_pos = summary_start - DATA_END_RECORD;

        if self.options.validate_crcs {
            let mut rec = [0u8; DATA_END_RECORD as usize];
            self.read_at(data_end_pos, &mut rec)?;
            let mut c = Cur::new(&rec);
            let (opcode, len, stored) = (c.bytes(1).map(|b| b[0]), c.u64(), c.u32());
            if opcode != Some(op::DATA_END) || len != Some(4) {
                return Ok(Err("no DataEnd record before the summary section".into()));
            }
            let stored = stored.unwrap_or(0);
            if stored != 0 {
                let computed = self.crc_of_prefix(data_end_pos)?;
                if computed != stored {
                    return Err(LogError::CrcMismatch {
                        file: self.path.to_path_buf(),
                        section: CrcSection::DataSection,
                        offset: data_end_pos,
                        stored,
                        computed,
                    });
                }
            }
        }

        for (_, s) in schemas {
            self.add_schema(s, None)?;
        }
        for (id, (schema_id, topic, encoding)) in channels {
            self.add_channel(id, schema_id, &topic, &encoding, None)?;
        }
        let (pending, duplicates) = check_chunk_indexes(chunks, data_end_pos);
        if duplicates > 0 {
            tracing::warn!(
                file = %self.path.display(),
                duplicates,
                "the summary repeats {duplicates} chunk indexes: each chunk is read once"
            );
        }
        let refused = pending.iter().filter(|p| p.refusal.is_some()).count();
        if refused > 0 {
            tracing::warn!(
                file = %self.path.display(),
                refused,
                "{refused} of the summary's chunk indexes overlap another chunk or leave the data section: their chunks are reported and skipped"
            );
        }
        self.stats.duplicate_chunk_indexes = duplicates;
        self.pending = pending;
        self.statistics = statistics;
        Ok(Ok(()))
    }

    /// CRC-32 of the first `len` bytes of the file.
    fn crc_of_prefix(&mut self, len: u64) -> Result<u32, LogError> {
        self.src.seek(0).map_err(|e| self.err_io(0, e))?;
        let mut h = Crc32::new();
        let mut buf = vec![0u8; 1 << 16];
        let mut left = len;
        while left > 0 {
            let k = left.min(buf.len() as u64) as usize;
            let at = self.src.pos;
            self.src
                .read_exact(&mut buf[..k])
                .map_err(|e| self.err_io(at, e))?;
            h.update(&buf[..k]);
            left -= k as u64;
        }
        Ok(h.finalize())
    }

    fn start_linear(&mut self) -> Result<(), LogError> {
        self.mode = ReadMode::Linear;
        self.src.seek(8).map_err(|e| self.err_io(8, e))?;
        if self.options.validate_crcs {
            let mut h = Crc32::new();
            h.update(MAGIC);
            self.src.hasher = Some(h);
        }
        Ok(())
    }

    /// Adds a schema (the first definition of an id wins); more than
    /// [`ReadOptions::max_schemas`] is an error. `offset`: the record or chunk defining it.
    fn add_schema(&mut self, s: SchemaInfo, offset: Option<u64>) -> Result<(), LogError> {
        if s.id == 0 || self.schemas.contains_key(&s.id) {
            return Ok(());
        }
        if self.schemas.len() as u64 >= self.options.max_schemas {
            return Err(self.too_many_schemas(offset));
        }
        let s = Arc::new(s);
        for ch in self.channels.iter_mut().flatten() {
            if ch.schema_id == s.id && ch.schema.is_none() {
                ch.schema = Some(s.clone());
            }
        }
        self.schemas.insert(s.id, s);
        Ok(())
    }

    /// Adds a channel (the first definition of an id wins); more than
    /// [`ReadOptions::max_channels`] is an error. `offset`: the record or chunk defining it.
    fn add_channel(
        &mut self,
        id: u16,
        schema_id: u16,
        topic: &str,
        message_encoding: &str,
        offset: Option<u64>,
    ) -> Result<(), LogError> {
        let i = usize::from(id);
        if matches!(self.channels.get(i), Some(Some(_))) {
            return Ok(()); // the first definition of an id wins
        }
        if self.channel_count as u64 >= self.options.max_channels {
            return Err(self.too_many_channels(offset));
        }
        if self.channels.len() <= i {
            // At most 65,536 entries (channel ids are u16).
            self.channels.resize_with(i + 1, || None);
        }
        let wanted = self
            .wanted_topics
            .as_ref()
            .is_none_or(|t| t.contains(topic));
        let schema = self.schemas.get(&schema_id).cloned();
        if let Some(slot) = self.channels.get_mut(i) {
            *slot = Some(ChannelInfo {
                id,
                topic: Arc::from(topic),
                message_encoding: message_encoding.to_string(),
                schema_id,
                schema,
                wanted,
            });
            self.channel_count += 1;
        }
        Ok(())
    }

    /// A [`LogError::LimitExceeded`] for the [`ReadOptions`] field `limit` set to `value`.
    fn limit(
        &self,
        limit: &'static str,
        value: u64,
        offset: Option<u64>,
        what: String,
    ) -> LogError {
        LogError::LimitExceeded {
            file: self.path.to_path_buf(),
            limit,
            value,
            offset,
            what,
        }
    }

    fn too_many_schemas(&self, offset: Option<u64>) -> LogError {
        let n = self.options.max_schemas;
        self.limit(
            "max_schemas",
            n,
            offset,
            format!("the file defines more than {n} schemas"),
        )
    }

    fn too_many_channels(&self, offset: Option<u64>) -> LogError {
        let n = self.options.max_channels;
        self.limit(
            "max_channels",
            n,
            offset,
            format!("the file defines more than {n} channels"),
        )
    }

    /// Checks a message payload of `len` bytes against [`ReadOptions::max_message_bytes`].
    fn check_message_len(&self, len: usize, offset: u64, log_time: u64) -> Result<(), LogError> {
        let max = self.options.max_message_bytes;
        if len as u64 > max {
            return Err(self.limit(
                "max_message_bytes",
                max,
                Some(offset),
                format!("a message at {log_time} ns is {len} bytes"),
            ));
        }
        Ok(())
    }

    fn wants(&self, channel_id: u16) -> bool {
        match self.channels.get(usize::from(channel_id)) {
            Some(Some(ch)) => ch.wanted,
            _ => true, // unknown channels are reported when yielded
        }
    }

    /// Reads the chunk record whose 9-byte header (`len` = body length) has just been read at
    /// `rec_pos`, leaving the source after the record, and decodes its messages into a batch.
    fn decode_chunk(&mut self, rec_pos: u64, len: u64) -> Result<Batch, LogError> {
        let max = self.options.max_record_bytes;
        let n = match usize::try_from(len) {
            Ok(n) if len <= max => n,
            _ => {
                let e = self.bad_chunk(
                    rec_pos,
                    format!(
                        "the chunk record is {len} bytes, more than ReadOptions::max_record_bytes = {max} (raise it if the file is trusted)"
                    ),
                );
                self.src
                    .skip(len)
                    .map_err(|io| self.err_io(rec_pos + RECORD_HEADER, io))?;
                return Err(e);
            }
        };
        let limit = usize::try_from(max).unwrap_or(usize::MAX);
        let mut body = std::mem::take(&mut self.chunk_buf);
        if body.len() < n {
            body.resize(n, 0);
        }
        let at = self.src.pos;
        if let Err(e) = self.src.read_exact(&mut body[..n]) {
            self.chunk_buf = body;
            return Err(self.err_io(at, e));
        }
        // The chunk's declared uncompressed size (bytes 16..24 of the body).
        let declared = body.get(16..24).and_then(|b| Cur::new(b).u64());
        // The decompression budget, from the declared size, before anything is decompressed.
        // Neither decoding path decompresses more than the declared size.
        if let Some(declared) = declared {
            let total = self.stats.decompressed_bytes.saturating_add(declared);
            if total > self.decompressed_budget {
                self.chunk_buf = body;
                return Err(self.over_decompression_budget(rec_pos, total));
            }
            self.stats.decompressed_bytes = total;
        }
        let direct = if self.direct_chunks {
            self.decode_chunk_directly(rec_pos, &body[..n], limit)
        } else {
            Ok(None)
        };
        let direct = match direct {
            Ok(d) => d,
            Err(e) => {
                self.chunk_buf = body;
                return Err(e);
            }
        };
        if let Some(batch) = direct {
            self.chunk_buf = body;
            self.stats.chunks_loaded += 1;
            return Ok(batch);
        }
        // Anything unusual: the mcap crate's reader decodes the chunk (and names what is wrong).
        // The chunk is decompressed whole and its CRC checked before any record is read: with
        // the mcap crate this is also the fastest way (record-by-record streaming decompression
        // is slower than decompressing and hashing the whole chunk).
        // The mcap crate's reader reserves a record's whole declared length before
        // decompressing it, so a record header inside a small chunk claiming hundreds of
        // megabytes would be allocated (found by the `mcap_reader` fuzz target: 4 KB of input,
        // 240 MB). No record of this chunk can be longer than the chunk record itself or its
        // declared uncompressed size (already within the decompression budget), so that bounds
        // every allocation for this chunk.
        if let Some(why) = uncompressed_record_overrun(&body[..n]) {
            self.chunk_buf = body;
            return Err(self.bad_chunk(rec_pos, why));
        }
        let declared = declared.and_then(|d| usize::try_from(d).ok()).unwrap_or(0);
        let chunk_limit = limit.min(n.max(declared));
        let mut lr = LinearReader::new_with_options(LinearReaderOptions {
            skip_start_magic: true,
            skip_end_magic: true,
            validate_chunk_crcs: true,
            prevalidate_chunk_crcs: true,
            record_length_limit: Some(chunk_limit),
            ..Default::default()
        });
        let total = RECORD_HEADER as usize + n;
        {
            let dst = lr.insert(total);
            dst[0] = op::CHUNK;
            dst[1..9].copy_from_slice(&len.to_le_bytes());
            dst[9..total].copy_from_slice(&body[..n]);
        }
        self.chunk_buf = body;
        lr.notify_read(total);

        let mut batch = self.free.pop().unwrap_or_default();
        batch.reset(rec_pos);
        let mut sorted = true;
        let mut last_time = 0u64;
        let mut eof_sent = false;
        loop {
            let event = match lr.next_event() {
                None => break,
                Some(Ok(event)) => event,
                Some(Err(mcap::McapError::BadChunkCrc { saved, calculated })) => {
                    self.recycle(batch);
                    return Err(LogError::CrcMismatch {
                        file: self.path.to_path_buf(),
                        section: CrcSection::Chunk,
                        offset: rec_pos,
                        stored: saved,
                        computed: calculated,
                    });
                }
                Some(Err(mcap::McapError::UnexpectedEof)) => {
                    self.recycle(batch);
                    return Err(self.bad_chunk(
                        rec_pos,
                        "the chunk's contents end before its header says they do".into(),
                    ));
                }
                Some(Err(e)) => {
                    self.recycle(batch);
                    return Err(self.bad_chunk(rec_pos, e.to_string()));
                }
            };
            match event {
                LinearReadEvent::ReadRequest(_) => {
                    if eof_sent {
                        self.recycle(batch);
                        return Err(self.bad_chunk(
                            rec_pos,
                            "the chunk reader asked for data past the end".into(),
                        ));
                    }
                    // The whole record is in: tell the reader there is no more.
                    eof_sent = true;
                    lr.notify_read(0);
                }
                LinearReadEvent::Record { opcode, data } => match opcode {
                    op::MESSAGE => {
                        let Some(h) = parse_message_header(data) else {
                            self.recycle(batch);
                            return Err(self.bad_chunk(
                                rec_pos,
                                "a message record is shorter than its header".into(),
                            ));
                        };
                        if !self.wants(h.channel_id) {
                            continue;
                        }
                        let payload = data.get(MESSAGE_HEADER..).unwrap_or_default();
                        if let Err(e) = self.check_message_len(payload.len(), rec_pos, h.log_time) {
                            self.recycle(batch);
                            return Err(e);
                        }
                        sorted &= h.log_time >= last_time;
                        last_time = h.log_time;
                        batch.push(h, payload);
                    }
                    op::SCHEMA => {
                        let added = match parse_schema(data) {
                            Some(s) => self.add_schema(s, Some(rec_pos)),
                            None => Err(self.bad_chunk(rec_pos, "unreadable schema record".into())),
                        };
                        if let Err(e) = added {
                            self.recycle(batch);
                            return Err(e);
                        }
                    }
                    op::CHANNEL => {
                        let added = match parse_channel(data) {
                            Some(ch) => self.add_channel(
                                ch.id,
                                ch.schema_id,
                                ch.topic,
                                ch.message_encoding,
                                Some(rec_pos),
                            ),
                            None => {
                                Err(self.bad_chunk(rec_pos, "unreadable channel record".into()))
                            }
                        };
                        if let Err(e) = added {
                            self.recycle(batch);
                            return Err(e);
                        }
                    }
                    _ => {}
                },
            }
        }
        if self.mode == ReadMode::Indexed && !sorted {
            batch.entries.sort_by_key(|e| e.log_time);
        }
        self.stats.chunks_loaded += 1;
        Ok(batch)
    }

    /// Decodes the chunk record `body` (at `rec_pos`) without the mcap crate's reader, when it
    /// is the usual kind: zstd-compressed or uncompressed, its lengths consistent (no padding),
    /// its records complete and within `limit`, its CRC right (when it has one). `None` for
    /// anything else, and the general path then decodes the chunk: the same messages, schemas
    /// and channels when the chunk is good, and the errors it always reported when it is not.
    /// Message data stays in the decompressed chunk (no copy). `Err` for a limit of
    /// [`ReadOptions`] exceeded, as the general path reports it.
    fn decode_chunk_directly(
        &mut self,
        rec_pos: u64,
        body: &[u8],
        limit: usize,
    ) -> Result<Option<Batch>, LogError> {
        let mut c = Cur::new(body);
        let header = (|| {
            let _start_time = c.u64()?;
            let _end_time = c.u64()?;
            let uncompressed_size = usize::try_from(c.u64()?).ok()?;
            let crc = c.u32()?;
            let compression = c.string()?;
            let compressed_size = c.u64()?;
            Some((uncompressed_size, crc, compression, compressed_size))
        })();
        let Some((uncompressed_size, crc, compression, compressed_size)) = header else {
            return Ok(None);
        };
        let records = c.b;
        if records.len() as u64 != compressed_size || uncompressed_size > limit {
            return Ok(None);
        }
        let mut batch = self.free.pop().unwrap_or_default();
        batch.reset(rec_pos);
        let decoded = match compression {
            "" if records.len() == uncompressed_size => {
                batch.arena.extend_from_slice(records);
                true
            }
            "zstd" => {
                batch.arena.reserve(uncompressed_size);
                if self.zstd.is_none() {
                    self.zstd = zstd::bulk::Decompressor::new().ok();
                }
                !zstd_window_too_large(records)
                    && self
                        .zstd
                        .as_mut()
                        .and_then(|z| z.decompress_to_buffer(records, &mut batch.arena).ok())
                        == Some(uncompressed_size)
            }
            _ => false,
        };
        if !decoded || (crc != 0 && crc32fast::hash(&batch.arena) != crc) {
            self.recycle(batch);
            return Ok(None);
        }
        let mut sorted = true;
        let mut last_time = 0u64;
        let mut i = 0;
        let arena = std::mem::take(&mut batch.arena);
        let mut over_limit = None;
        let complete = loop {
            let Some(header) = arena.get(i..i + RECORD_HEADER as usize) else {
                break i == arena.len();
            };
            let opcode = header[0];
            let Some(rlen) = Cur::new(&header[1..])
                .u64()
                .and_then(|l| usize::try_from(l).ok())
                .filter(|&l| l <= limit)
            else {
                break false;
            };
            let start = i + RECORD_HEADER as usize;
            let Some(data) = start
                .checked_add(rlen)
                .and_then(|end| arena.get(start..end))
            else {
                break false;
            };
            i = start + rlen;
            match opcode {
                op::MESSAGE => {
                    let Some(h) = parse_message_header(data) else {
                        break false;
                    };
                    if !self.wants(h.channel_id) {
                        continue;
                    }
                    let payload_len = rlen - MESSAGE_HEADER;
                    if let Err(e) = self.check_message_len(payload_len, rec_pos, h.log_time) {
                        over_limit = Some(e);
                        break false;
                    }
                    sorted &= h.log_time >= last_time;
                    last_time = h.log_time;
                    batch.entries.push(Entry {
                        log_time: h.log_time,
                        publish_time: h.publish_time,
                        sequence: h.sequence,
                        channel_id: h.channel_id,
                        start: start + MESSAGE_HEADER,
                        len: payload_len,
                    });
                }
                op::SCHEMA => match parse_schema(data) {
                    Some(s) => {
                        if let Err(e) = self.add_schema(s, Some(rec_pos)) {
                            over_limit = Some(e);
                            break false;
                        }
                    }
                    None => break false,
                },
                op::CHANNEL => match parse_channel(data) {
                    Some(ch) => {
                        let added = self.add_channel(
                            ch.id,
                            ch.schema_id,
                            ch.topic,
                            ch.message_encoding,
                            Some(rec_pos),
                        );
                        if let Err(e) = added {
                            over_limit = Some(e);
                            break false;
                        }
                    }
                    None => break false,
                },
                _ => {}
            }
        };
        batch.arena = arena;
        if let Some(e) = over_limit {
            self.recycle(batch);
            return Err(e);
        }
        if !complete {
            self.recycle(batch);
            return Ok(None);
        }
        if self.mode == ReadMode::Indexed && !sorted {
            batch.entries.sort_by_key(|e| e.log_time);
        }
        Ok(Some(batch))
    }

    /// The error for a chunk that would take the decompressed bytes to `total`, over the
    /// budget: it names the option that sets the budget for this file.
    fn over_decompression_budget(&self, rec_pos: u64, total: u64) -> LogError {
        let o = &self.options;
        let by_ratio = o.max_decompression_ratio.saturating_mul(self.file_len);
        let what = format!(
            "the chunks read so far decompress to {total} bytes, more than the budget of {} bytes for this {}-byte file (the larger of ReadOptions::max_decompression_ratio = {} times the file size and ReadOptions::decompressed_bytes_floor = {} bytes)",
            self.decompressed_budget, self.file_len, o.max_decompression_ratio, o.decompressed_bytes_floor
        );
        if by_ratio >= o.decompressed_bytes_floor {
            self.limit(
                "max_decompression_ratio",
                o.max_decompression_ratio,
                Some(rec_pos),
                what,
            )
        } else {
            self.limit(
                "decompressed_bytes_floor",
                o.decompressed_bytes_floor,
                Some(rec_pos),
                what,
            )
        }
    }

    fn bad_chunk(&self, offset: u64, detail: String) -> LogError {
        LogError::BadChunk {
            file: self.path.to_path_buf(),
            offset,
            detail,
        }
    }

    fn recycle(&mut self, batch: Batch) {
        if self.free.len() < 2 {
            self.free.push(batch);
        }
    }

    /// Puts a loaded batch in a free slot (and, in indexed mode, its first message in the
    /// merge heap). `None` for an empty batch, which is recycled.
    fn make_resident(&mut self, batch: Batch) -> Option<usize> {
        let Some(first) = batch.entries.first() else {
            self.recycle(batch);
            return None;
        };
        let key_head = (first.log_time, batch.offset);
        let slot = match self.free_slots.pop() {
            Some(slot) => slot,
            None => {
                self.slots.push(None);
                self.slots.len() - 1
            }
        };
        if let Some(s) = self.slots.get_mut(slot) {
            *s = Some(batch);
        }
        if self.mode == ReadMode::Indexed {
            self.heads.push(Reverse((key_head.0, key_head.1, 0, slot)));
        }
        self.resident_count += 1;
        self.stats.max_resident_chunks = self.stats.max_resident_chunks.max(self.resident_count);
        Some(slot)
    }

    /// Frees the slot whose last message was yielded by the previous call.
    fn free_done_slot(&mut self) {
        let Some(slot) = self.done_slot.take() else {
            return;
        };
        if let Some(batch) = self.slots.get_mut(slot).and_then(Option::take) {
            self.recycle(batch);
            self.free_slots.push(slot);
            self.resident_count -= 1;
        }
        if self.linear_slot == Some(slot) {
            self.linear_slot = None;
        }
    }

    /// Indexed mode: loads the chunks whose first log time is not after the next message to
    /// yield, then picks that message: the current chunk's next one unless the merge heap's
    /// smallest comes first (O(1) while one chunk is read, O(log k) for k resident chunks).
    fn indexed_step(&mut self) -> Step {
        loop {
            let head_time = match (self.current, self.heads.peek()) {
                (Some(c), Some(Reverse(h))) => Some(c.0.min(h.0)),
                (Some(c), None) => Some(c.0),
                (None, Some(Reverse(h))) => Some(h.0),
                (None, None) => None,
            };
            if let Some(p) = self.pending.get(self.next_pending).copied() {
                if head_time.is_none_or(|t| p.idx.start_time <= t) {
                    self.next_pending += 1;
                    if let Some(refusal) = p.refusal {
                        return Step::Error(self.refused_chunk(p.idx, refusal));
                    }
                    match self.load_indexed_chunk(p.idx) {
                        Ok(batch) => {
                            self.make_resident(batch);
                            continue;
                        }
                        Err(e) => return Step::Error(e),
                    }
                }
            }
            let current = self.current.take();
            return match (current, self.heads.peek()) {
                (Some(c), Some(Reverse(h))) if *h < c => {
                    let slot = h.3;
                    self.heads.pop();
                    self.heads.push(Reverse(c));
                    Step::Yield(slot)
                }
                (Some(c), _) => Step::Yield(c.3),
                (None, Some(&Reverse(h))) => {
                    self.heads.pop();
                    Step::Yield(h.3)
                }
                (None, None) => Step::End,
            };
        }
    }

    /// The error reporting a chunk index refused when opening.
    fn refused_chunk(&self, ci: ChunkIdx, refusal: Refusal) -> LogError {
        let end = ci.offset.saturating_add(ci.length);
        let detail = match refusal {
            Refusal::OutsideData { data_end } => format!(
                "the summary's chunk index gives bytes {}..{end}, outside the data section (bytes 8..{data_end}); the chunk is skipped",
                ci.offset
            ),
            Refusal::Overlaps { other, other_end } => format!(
                "the summary's chunk index gives bytes {}..{end}, which overlap the chunk indexed at bytes {other}..{other_end}; the chunk is skipped",
                ci.offset
            ),
            Refusal::TimesReversed => format!(
                "the summary's chunk index has its end time {} ns before its start time {} ns; the chunk is skipped",
                ci.end_time, ci.start_time
            ),
        };
        self.bad_chunk(ci.offset, detail)
    }

    fn load_indexed_chunk(&mut self, ci: ChunkIdx) -> Result<Batch, LogError> {
        let mut header = [0u8; RECORD_HEADER as usize];
        self.read_at(ci.offset, &mut header)?;
        let len = u64::from_le_bytes([
            header[1], header[2], header[3], header[4], header[5], header[6], header[7], header[8],
        ]);
        if header[0] != op::CHUNK || len.checked_add(RECORD_HEADER) != Some(ci.length) {
            return Err(LogError::BadChunk {
                file: self.path.to_path_buf(),
                offset: ci.offset,
                detail: "the summary's chunk index does not point to a chunk record".into(),
            });
        }
        self.decode_chunk(ci.offset, len)
    }

    fn linear_step(&mut self) -> Step {
        if let Some(slot) = self.linear_slot {
            if matches!(self.slots.get(slot), Some(Some(b)) if !b.exhausted()) {
                return Step::Yield(slot);
            }
        }
        loop {
            match self.linear_next_record() {
                Ok(Some(batch)) => {
                    if let Some(slot) = self.make_resident(batch) {
                        self.linear_slot = Some(slot);
                        return Step::Yield(slot);
                    }
                }
                Ok(None) => return Step::End,
                Err(e) => return Step::Error(e),
            }
        }
    }

    /// The error for records that stop short of where they should, at `offset`: truncation
    /// ([`LogError::Truncated`]) when the file does not end with a footer and the end magic,
    /// corruption ([`LogError::Corrupt`]) when it does (the file is complete, so its record
    /// lengths are wrong).
    fn truncated(&self, offset: u64, detail: String) -> LogError {
        match self.footer_pos {
            Some(footer) => LogError::Corrupt {
                file: self.path.to_path_buf(),
                offset,
                detail: format!(
                    "{detail}; the file ends with a valid footer (at byte {footer}) and end magic, so it is complete and its records are damaged"
                ),
            },
            None => LogError::Truncated {
                file: self.path.to_path_buf(),
                offset,
                detail,
            },
        }
    }

    /// Reads the next top-level record. `Ok(Some(batch))` for a chunk or a message (the batch
    /// may be empty), `Ok(None)` at the end of the data.
    fn linear_next_record(&mut self) -> Result<Option<Batch>, LogError> {
        loop {
            let rec_pos = self.src.pos;
            let left = self.file_len.saturating_sub(rec_pos);
            if left == 0 {
                if self.seen_data_end {
                    return Err(self.truncated(
                        rec_pos,
                        "the file ends inside its summary section (no footer)".into(),
                    ));
                }
                return Err(self.truncated(
                    rec_pos,
                    "the file ends without a DataEnd record or footer (its writer did not finish)"
                        .into(),
                ));
            }
            if left < RECORD_HEADER {
                return Err(self.truncated(rec_pos, "the file ends inside a record header".into()));
            }
            // The DataEnd CRC covers the bytes before the DataEnd record.
            let hasher_before = self.src.hasher;
            let mut header = [0u8; RECORD_HEADER as usize];
            self.src
                .read_exact(&mut header)
                .map_err(|e| self.err_io(rec_pos, e))?;
            let opcode = header[0];
            let len = u64::from_le_bytes([
                header[1], header[2], header[3], header[4], header[5], header[6], header[7],
                header[8],
            ]);
            let end = rec_pos.saturating_add(RECORD_HEADER).saturating_add(len);
            if let Some(footer) = self.footer_pos.filter(|&f| rec_pos < f && end > f) {
                return Err(LogError::Corrupt {
                    file: self.path.to_path_buf(),
                    offset: rec_pos,
                    detail: format!(
                        "the record here (opcode {opcode:#04x}, {len} bytes) runs past the footer at byte {footer}; the file ends with a valid footer and end magic, so it is complete and this record's length is damaged"
                    ),
                });
            }
            if len > left - RECORD_HEADER {
                return Err(self.truncated(
                    rec_pos,
                    format!(
                        "the record here (opcode {opcode:#04x}, {len} bytes) runs past the end of the file ({} bytes)",
                        self.file_len
                    ),
                ));
            }
            let body_pos = rec_pos + RECORD_HEADER;
            let small_record = |this: &mut Self| -> Result<Vec<u8>, LogError> {
                let max = this.options.max_record_bytes;
                let n = match usize::try_from(len) {
                    Ok(n) if len <= max => n,
                    _ => {
                        return Err(this.limit(
                            "max_record_bytes",
                            max,
                            Some(rec_pos),
                            format!("a record (opcode {opcode:#04x}) is {len} bytes"),
                        ))
                    }
                };
                let mut body = vec![0u8; n];
                this.src
                    .read_exact(&mut body)
                    .map_err(|e| this.err_io(body_pos, e))?;
                Ok(body)
            };
            match opcode {
                op::CHUNK if !self.seen_data_end => {
                    return self.decode_chunk(rec_pos, len).map(Some)
                }
                op::MESSAGE if !self.seen_data_end => {
                    let body = small_record(self)?;
                    let Some(h) = parse_message_header(&body) else {
                        return Err(LogError::Corrupt {
                            file: self.path.to_path_buf(),
                            offset: rec_pos,
                            detail: "a message record is shorter than its header".into(),
                        });
                    };
                    let mut batch = self.free.pop().unwrap_or_default();
                    batch.reset(rec_pos);
                    if self.wants(h.channel_id) {
                        let payload = body.get(MESSAGE_HEADER..).unwrap_or_default();
                        if let Err(e) = self.check_message_len(payload.len(), rec_pos, h.log_time) {
                            self.recycle(batch);
                            return Err(e);
                        }
                        batch.push(h, payload);
                    }
                    return Ok(Some(batch));
                }
                op::SCHEMA | op::CHANNEL if !self.seen_data_end => {
                    let body = small_record(self)?;
                    let ok = if opcode == op::SCHEMA {
                        match parse_schema(&body) {
                            Some(s) => {
                                self.add_schema(s, Some(rec_pos))?;
                                true
                            }
                            None => false,
                        }
                    } else {
                        match parse_channel(&body) {
                            Some(ch) => {
                                self.add_channel(
                                    ch.id,
                                    ch.schema_id,
                                    ch.topic,
                                    ch.message_encoding,
                                    Some(rec_pos),
                                )?;
                                true
                            }
                            None => false,
                        }
                    };
                    if !ok {
                        return Err(LogError::Corrupt {
                            file: self.path.to_path_buf(),
                            offset: rec_pos,
                            detail: format!("unreadable record (opcode {opcode:#04x})"),
                        });
                    }
                }
                op::DATA_END if !self.seen_data_end => {
                    let body = small_record(self)?;
                    self.seen_data_end = true;
                    let stored = Cur::new(&body).u32();
                    if let (Some(h), Some(stored)) = (hasher_before, stored) {
                        let computed = h.finalize();
                        if stored != 0 && stored != computed {
                            return Err(LogError::CrcMismatch {
                                file: self.path.to_path_buf(),
                                section: CrcSection::DataSection,
                                offset: rec_pos,
                                stored,
                                computed,
                            });
                        }
                    }
                    if !self.options.validate_crcs {
                        return Ok(None);
                    }
                    // Go on through the summary to check its CRC.
                    self.src.hasher = Some(Crc32::new());
                }
                op::FOOTER => {
                    if self.options.validate_crcs && !self.seen_data_end {
                        return Err(LogError::Corrupt {
                            file: self.path.to_path_buf(),
                            offset: rec_pos,
                            detail: "footer without a DataEnd record before it: the data section CRC cannot be checked".into(),
                        });
                    }
                    let body = small_record(self)?;
                    let mut c = Cur::new(&body);
                    let (_, _, stored) = (c.u64(), c.u64(), c.u32());
                    if let (Some(mut h), Some(stored)) = (hasher_before, stored) {
                        // From the summary start through the footer's summary_offset_start.
                        h.update(&header);
                        h.update(body.get(..16).unwrap_or(&body));
                        let computed = h.finalize();
                        if self.seen_data_end && stored != 0 && stored != computed {
                            return Err(LogError::CrcMismatch {
                                file: self.path.to_path_buf(),
                                section: CrcSection::Summary,
                                offset: rec_pos,
                                stored,
                                computed,
                            });
                        }
                    }
                    let at = self.src.pos;
                    let mut magic = [0u8; 8];
                    if self.file_len - at < 8 {
                        return Err(self.truncated(at, "the end magic is missing".into()));
                    }
                    self.src
                        .read_exact(&mut magic)
                        .map_err(|e| self.err_io(at, e))?;
                    if &magic != MAGIC {
                        return Err(LogError::Corrupt {
                            file: self.path.to_path_buf(),
                            offset: at,
                            detail: "bad end magic after the footer".into(),
                        });
                    }
                    return Ok(None);
                }
                _ => self.src.skip(len).map_err(|e| self.err_io(body_pos, e))?,
            }
        }
    }

    /// The next message, borrowed from the reader: in log-time order (indexed mode) or file
    /// order (linear mode). `Some(Err(_))` reports a problem: after a non-fatal one the next
    /// call continues; after a fatal one ([`LogError::is_fatal`]) the reader returns `None`.
    pub fn next_message(&mut self) -> Option<Result<LogMessage<'_>, LogError>> {
        if self.finished {
            return None;
        }
        // The previous message's borrow has ended: free the chunk it exhausted.
        self.free_done_slot();
        let step = match self.mode {
            ReadMode::Indexed => self.indexed_step(),
            ReadMode::Linear => self.linear_step(),
        };
        let slot = match step {
            Step::End => {
                self.finished = true;
                return None;
            }
            Step::Error(e) => {
                if e.is_fatal() {
                    self.finished = true;
                } else if matches!(
                    e,
                    LogError::BadChunk { .. }
                        | LogError::CrcMismatch {
                            section: CrcSection::Chunk,
                            ..
                        }
                ) {
                    // The non-fatal errors of a step are about a whole chunk.
                    self.stats.chunks_failed += 1;
                }
                return Some(Err(e));
            }
            Step::Yield(slot) => slot,
        };
        let Some(Some(batch)) = self.slots.get_mut(slot) else {
            self.finished = true;
            return None;
        };
        let Some(&e) = batch.entries.get(batch.pos) else {
            self.finished = true;
            return None;
        };
        batch.pos += 1;
        let offset = batch.offset;
        match batch.entries.get(batch.pos) {
            Some(next) if self.mode == ReadMode::Indexed => {
                self.current = Some((next.log_time, offset, batch.pos, slot));
            }
            Some(_) => {}
            None => self.done_slot = Some(slot),
        }
        let Some(Some(channel)) = self.channels.get(usize::from(e.channel_id)) else {
            return Some(Err(LogError::UnknownChannel {
                file: self.path.to_path_buf(),
                offset,
                log_time_ns: e.log_time,
                channel_id: e.channel_id,
            }));
        };
        self.stats.messages += 1;
        let data = match self.slots.get(slot) {
            Some(Some(b)) => b.arena.get(e.start..e.start.saturating_add(e.len)),
            _ => None,
        }
        .unwrap_or(&[]);
        Some(Ok(LogMessage {
            topic: &channel.topic,
            log_time_ns: e.log_time,
            publish_time_ns: e.publish_time,
            sequence: e.sequence,
            data,
            channel,
            offset,
            file: &self.path,
        }))
    }
}

/// Owned messages (a copy of each); [`LogReader::next_message`] avoids the copy.
impl Iterator for LogReader {
    type Item = Result<OwnedLogMessage, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_message().map(|r| r.map(|m| m.to_owned_message()))
    }
}

/// Checks the summary's chunk indexes against each other and the data section, which ends at
/// `data_end` (the DataEnd record). Returns them in load order (first log time, then file
/// position) and how many repeated an earlier index of the same chunk.
///
/// - An index repeating an earlier one (same offset and length) is dropped: a summary listing
///   one chunk thousands of times would otherwise load, decompress and yield that chunk as many
///   times.
/// - An index whose bytes leave the data section, or overlap those of a chunk indexed before it
///   in file order (the first one is kept), or whose end time is before its start time, is
///   refused: its chunk is reported as a [`LogError::BadChunk`] when its turn comes. Chunks
///   then never overlap, so their number is bounded by the file's size and each byte of the
///   data section is decompressed at most once.
///
/// O(n log n) for n indexes.
fn check_chunk_indexes(mut chunks: Vec<ChunkIdx>, data_end: u64) -> (Vec<PendingChunk>, usize) {
    // Stable: among equal (offset, length) the summary's order is kept, so the first of
    // repeated indexes is the one used.
    chunks.sort_by_key(|c| (c.offset, c.length));
    let mut out: Vec<PendingChunk> = Vec::with_capacity(chunks.len());
    let mut duplicates = 0;
    let mut last: Option<(u64, u64)> = None; // (offset, length) of the previous index
    let mut kept_range: Option<(u64, u64)> = None; // [start, end) of the last chunk kept
    for idx in chunks {
        if last == Some((idx.offset, idx.length)) {
            duplicates += 1;
            continue;
        }
        last = Some((idx.offset, idx.length));
        let end = idx.offset.checked_add(idx.length);
        let refusal = match end {
            Some(end) if idx.offset >= 8 && idx.length >= RECORD_HEADER && end <= data_end => {
                match kept_range {
                    Some((other, other_end)) if idx.offset < other_end => {
                        Some(Refusal::Overlaps { other, other_end })
                    }
                    _ if idx.start_time > idx.end_time => Some(Refusal::TimesReversed),
                    _ => {
                        kept_range = Some((idx.offset, end));
                        None
                    }
                }
            }
            _ => Some(Refusal::OutsideData { data_end }),
        };
        out.push(PendingChunk { idx, refusal });
    }
    out.sort_by_key(|p| (p.idx.start_time, p.idx.offset));
    (out, duplicates)
}

/// The streaming decoder the mcap crate uses refuses a zstd frame whose window exceeds its
/// default limit, 2^27 + 1 bytes ("Frame requires too much memory for decoding"); one-shot
/// decompression into a buffer of the known size does not look at the window. The direct path
/// refuses such a frame too (its header's window descriptor, RFC 8878 3.1.1.1.2), so that both
/// paths read a damaged chunk alike.
fn zstd_window_too_large(frame: &[u8]) -> bool {
    const MAGIC: [u8; 4] = [0x28, 0xb5, 0x2f, 0xfd];
    const MAX_WINDOW: u64 = (1 << 27) + 1;
    match frame {
        [m0, m1, m2, m3, fhd, wd, ..] if [*m0, *m1, *m2, *m3] == MAGIC && fhd & 0x20 == 0 => {
            let log = 10 + u64::from(wd >> 3);
            let base = 1u64 << log;
            base + (base / 8) * u64::from(wd & 7) > MAX_WINDOW
        }
        _ => false,
    }
}

/// In an uncompressed chunk (`body`: the chunk record's body), a record whose declared length
/// runs past the chunk's records section: described, else `None`. The mcap crate's chunk
/// reader subtracts such a record's length from what is left of the section without a check
/// (an integer overflow: a panic in a debug build, found replaying the `mcap_reader` fuzz
/// corpus), so the chunk is refused before it gets there. Compressed chunks are bounded by
/// the decompressor's sizes.
fn uncompressed_record_overrun(body: &[u8]) -> Option<String> {
    let mut c = Cur::new(body);
    c.u64()?;
    c.u64()?;
    c.u64()?;
    c.u32()?;
    if !c.string()?.is_empty() {
        return None;
    }
    let declared = c.u64()?;
    let records = c.b;
    let mut left = declared.min(records.len() as u64);
    let mut at = 0usize;
    while left >= RECORD_HEADER {
        let len = Cur::new(records.get(at + 1..at + 9)?).u64()?;
        if len > left - RECORD_HEADER {
            return Some(format!(
                "a record at byte {at} of the chunk's records declares {len} bytes, more than the {} left in them",
                left - RECORD_HEADER
            ));
        }
        left -= RECORD_HEADER + len;
        at += usize::try_from(RECORD_HEADER + len).ok()?;
    }
    None
}

#[cfg(test)]
mod overrun_tests {
    use super::uncompressed_record_overrun;

    /// A chunk body: no compression (or `compression`), `records_len` declared, `records`.
    fn chunk(compression: &str, records_len: u64, records: &[u8]) -> Vec<u8> {
        let mut b = vec![0u8; 28];
        b.extend_from_slice(&(compression.len() as u32).to_le_bytes());
        b.extend_from_slice(compression.as_bytes());
        b.extend_from_slice(&records_len.to_le_bytes());
        b.extend_from_slice(records);
        b
    }

    fn record(opcode: u8, len: u64, body: &[u8]) -> Vec<u8> {
        let mut r = vec![opcode];
        r.extend_from_slice(&len.to_le_bytes());
        r.extend_from_slice(body);
        r
    }

    #[test]
    fn a_record_longer_than_the_records_left_is_found() {
        let two = [record(5, 3, b"abc"), record(5, 2, b"de")].concat();
        assert_eq!(
            uncompressed_record_overrun(&chunk("", two.len() as u64, &two)),
            None
        );
        // The section declared shorter than its records (the bytes are there): the second
        // record runs past it.
        let e = uncompressed_record_overrun(&chunk("", 22, &two)).expect("found");
        assert!(
            e.contains("byte 12") && e.contains("declares 2 bytes") && e.contains("the 1 left"),
            "{e}"
        );
        // A length near u64::MAX does not wrap.
        let huge = record(5, u64::MAX - 3, b"abc");
        assert!(uncompressed_record_overrun(&chunk("", huge.len() as u64, &huge)).is_some());
        // Compressed chunks and bodies too short to hold a header are left to the decoders.
        assert_eq!(uncompressed_record_overrun(&chunk("zstd", 22, &two)), None);
        assert_eq!(uncompressed_record_overrun(&[0u8; 10]), None);
    }
}

#[cfg(test)]
mod direct_chunk_tests {
    //! Chunks decoded directly against the mcap crate's reader: the same messages, schemas,
    //! channels and errors, on good files and on damaged ones.

    use std::io::Cursor;

    use proptest::prelude::*;

    use super::*;
    use crate::log::{ChunkCompression, LogWriter, ThrottleTruth, TpsVoltage, WriteOptions};

    fn file(compression: ChunkCompression, chunk_size: u64) -> Vec<u8> {
        let options = WriteOptions {
            chunk_size,
            compression,
            ..WriteOptions::default()
        };
        let mut w = LogWriter::with_options(Cursor::new(Vec::new()), "memory", options)
            .expect("create writer");
        for k in 0..80u64 {
            let t = 1_000_000 * k;
            w.write_message(
                t,
                &TpsVoltage {
                    voltage_v: k as f64 * 0.01,
                },
            )
            .expect("write");
            if k % 3 == 0 {
                let truth = ThrottleTruth {
                    angle_deg: k as f64,
                    velocity: 0.0,
                    current_a: 0.5,
                    fault: "none".into(),
                    fault_active: false,
                    fault_observable: None,
                };
                w.write_message(t, &truth).expect("write");
            }
        }
        w.finish().expect("finish").into_inner()
    }

    /// Everything a reader yields, errors as their text.
    fn read(path: &Path, validate_crcs: bool, direct: bool) -> Vec<String> {
        let options = ReadOptions {
            validate_crcs,
            ..ReadOptions::default()
        };
        let mut r = match LogReader::open_with(path, options) {
            Ok(r) => r,
            Err(e) => return vec![format!("open: {e}")],
        };
        r.direct_chunks = direct;
        let mut out = Vec::new();
        while let Some(m) = r.next_message() {
            out.push(match m {
                Ok(m) => format!(
                    "{} {} {} {} {:?} {:?}",
                    m.topic,
                    m.log_time_ns,
                    m.publish_time_ns,
                    m.sequence,
                    m.channel.schema.as_ref().map(|s| s.name.clone()),
                    m.data
                ),
                Err(e) => format!("error: {e}"),
            });
        }
        out.push(format!("{:?}", r.stats()));
        out
    }

    #[test]
    fn good_files_read_the_same() {
        let dir = tempfile::tempdir().unwrap();
        for compression in [ChunkCompression::Zstd { level: 3 }, ChunkCompression::None] {
            for chunk_size in [200, 4096, 1 << 20] {
                let path = dir.path().join("good.mcap");
                std::fs::write(&path, file(compression, chunk_size)).unwrap();
                for validate in [false, true] {
                    let direct = read(&path, validate, true);
                    assert!(direct.len() > 100, "{direct:?}");
                    assert_eq!(direct, read(&path, validate, false));
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        #[test]
        fn damaged_files_read_the_same(
            flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
            validate in any::<bool>(),
            zstd in any::<bool>(),
        ) {
            let compression = if zstd {
                ChunkCompression::Zstd { level: 3 }
            } else {
                ChunkCompression::None
            };
            let mut bytes = file(compression, 300);
            for (i, v) in flips {
                let i = i.index(bytes.len());
                bytes[i] = v;
            }
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("damaged.mcap");
            std::fs::write(&path, &bytes).unwrap();
            prop_assert_eq!(read(&path, validate, true), read(&path, validate, false));
        }
    }
}
