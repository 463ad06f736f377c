//! [`LogReader`]: streams the messages of an MCAP file in log-time order, one chunk at a time.
//!
//! # How it reads
//!
//! - **Indexed** (a finished file): the footer points to the summary section, whose chunk
//!   indexes give each chunk's offset and time range. Chunks are loaded in order of their first
//!   log time, and a chunk is loaded only when its first log time is not after the next message
//!   to yield; messages are merged across the loaded chunks by (log time, chunk position in the
//!   file, position in the chunk). Memory holds only the chunks that overlap in time, which for
//!   files fdd writes (in time order) is one, or two at a boundary.
//! - **Linear** (no usable summary: a truncated file, a writer that did not finish, a file
//!   without chunk indexes): a `tracing` warning, then the records are read from start to end,
//!   one chunk at a time, and messages are yielded in **file order**; the caller must check that
//!   log times do not go backwards. A file cut short ends with a [`LogError::Truncated`] naming
//!   the byte where the readable data stops, after every complete chunk has been yielded.
//!
//! Chunks are decompressed whole and their CRC checked before any of their records is read. A
//! chunk of the usual kind (zstd or uncompressed, consistent lengths, complete records, right
//! CRC) is decoded here directly, its messages left in the decompressed chunk; anything else
//! goes through the mcap crate's sans-io reader, which also names what is wrong. The record
//! framing, the summary and the footer are parsed here with bounds checks, so a corrupt length
//! never causes a huge allocation or a panic.
//!
//! # Errors
//!
//! [`LogReader::open_with`] fails on what makes the file unreadable: missing or unreadable file,
//! bad magic, an empty file and, with [`ReadOptions::validate_crcs`], a data-section or summary
//! CRC mismatch.
//! While iterating, a problem with one chunk ([`LogError::BadChunk`], a chunk CRC mismatch) or
//! one message ([`LogError::UnknownChannel`]) is yielded as an `Err` and reading continues
//! with the next one; a fatal error ([`LogError::is_fatal`]: truncation, I/O) is the last item.
//! Decoding a message ([`LogMessage::decode`], [`LogMessage::field_f64`]) reports bad JSON or a
//! missing field with the file, topic, log time and chunk offset.

use std::collections::{BTreeMap, HashSet};
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
    /// Largest record (chunk, decompressed chunk, summary) the reader will hold in memory,
    /// bytes; a larger one is reported as corrupt instead of being allocated.
    pub max_record_bytes: u64,
}

impl ReadOptions {
    /// Default [`ReadOptions::max_record_bytes`]: 256 MiB.
    pub const DEFAULT_MAX_RECORD_BYTES: u64 = 256 << 20;
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions {
            validate_crcs: false,
            topics: None,
            max_record_bytes: Self::DEFAULT_MAX_RECORD_BYTES,
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
    /// Chunks in the file's index (indexed mode); `None` in linear mode.
    pub chunks_total: Option<usize>,
    /// Chunks loaded (read, decompressed and parsed without error) so far.
    pub chunks_loaded: usize,
    /// Chunks held in memory right now.
    pub resident_chunks: usize,
    /// The most chunks held in memory at once.
    pub max_resident_chunks: usize,
    /// Messages yielded so far.
    pub messages: u64,
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
    Yield(usize),
    Error(LogError),
    End,
}

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
    pending: Vec<ChunkIdx>,
    next_pending: usize,
    resident: Vec<Batch>,
    free: Vec<Batch>,
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
            resident: Vec::new(),
            free: Vec::new(),
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
            resident_chunks: self.resident.len(),
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
        if summary_start == 0 {
            return Ok(Err("the file has no summary section".into()));
        }
        if summary_start < 8 + DATA_END_RECORD || summary_start > footer_pos {
            return Ok(Err(format!(
                "the footer's summary offset {summary_start} is outside the file"
            )));
        }
        let summary_len = footer_pos - summary_start;
        if summary_len > self.options.max_record_bytes {
            return Ok(Err(format!(
                "the summary section ({summary_len} bytes) is larger than max_record_bytes"
            )));
        }
        let mut summary = vec![0u8; summary_len as usize];
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

        // Parse the summary records.
        let mut chunks = Vec::new();
        let mut statistics = None;
        let mut schemas = Vec::new();
        let mut channels = Vec::new();
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
                    Some(s) => schemas.push(s),
                    None => return bad("schema"),
                },
                op::CHANNEL => match parse_channel(body) {
                    Some(ch) => channels.push((
                        ch.id,
                        ch.schema_id,
                        ch.topic.to_string(),
                        ch.message_encoding.to_string(),
                    )),
                    None => return bad("channel"),
                },
                op::CHUNK_INDEX => match parse_chunk_index(body) {
                    Some(ci) => chunks.push(ci),
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
        let data_end_pos = summary_start - DATA_END_RECORD;
        for ci in &chunks {
            let end = ci.offset.checked_add(ci.length);
            if ci.offset < 8 || ci.length < RECORD_HEADER || end.is_none_or(|e| e > data_end_pos) {
                return Ok(Err(format!(
                    "a chunk index points outside the data section (chunk at byte {})",
                    ci.offset
                )));
            }
            if ci.start_time > ci.end_time {
                return Ok(Err(format!(
                    "a chunk index has its end time before its start time (chunk at byte {})",
                    ci.offset
                )));
            }
        }
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

        for s in schemas {
            self.add_schema(s);
        }
        for (id, schema_id, topic, encoding) in channels {
            self.add_channel(id, schema_id, &topic, &encoding);
        }
        chunks.sort_by_key(|c| (c.start_time, c.offset));
        self.pending = chunks;
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

    fn add_schema(&mut self, s: SchemaInfo) {
        if s.id == 0 || self.schemas.contains_key(&s.id) {
            return;
        }
        let s = Arc::new(s);
        for ch in self.channels.iter_mut().flatten() {
            if ch.schema_id == s.id && ch.schema.is_none() {
                ch.schema = Some(s.clone());
            }
        }
        self.schemas.insert(s.id, s);
    }

    fn add_channel(&mut self, id: u16, schema_id: u16, topic: &str, message_encoding: &str) {
        let i = usize::from(id);
        if self.channels.len() <= i {
            self.channels.resize_with(i + 1, || None);
        }
        if self.channels[i].is_some() {
            return; // the first definition of an id wins
        }
        let wanted = self
            .wanted_topics
            .as_ref()
            .is_none_or(|t| t.contains(topic));
        self.channels[i] = Some(ChannelInfo {
            id,
            topic: Arc::from(topic),
            message_encoding: message_encoding.to_string(),
            schema_id,
            schema: self.schemas.get(&schema_id).cloned(),
            wanted,
        });
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
        if len > self.options.max_record_bytes {
            let e = self.bad_chunk(
                rec_pos,
                format!("the chunk record is {len} bytes, more than max_record_bytes"),
            );
            self.src
                .skip(len)
                .map_err(|io| self.err_io(rec_pos + RECORD_HEADER, io))?;
            return Err(e);
        }
        let limit = usize::try_from(self.options.max_record_bytes).unwrap_or(usize::MAX);
        let mut body = std::mem::take(&mut self.chunk_buf);
        let n = len as usize;
        if body.len() < n {
            body.resize(n, 0);
        }
        let at = self.src.pos;
        let read = self.src.read_exact(&mut body[..n]);
        let direct = match read {
            Ok(()) if self.direct_chunks => self.decode_chunk_directly(rec_pos, &body[..n], limit),
            Ok(()) => None,
            Err(e) => {
                self.chunk_buf = body;
                return Err(self.err_io(at, e));
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
        let mut lr = LinearReader::new_with_options(LinearReaderOptions {
            skip_start_magic: true,
            skip_end_magic: true,
            validate_chunk_crcs: true,
            prevalidate_chunk_crcs: true,
            record_length_limit: Some(limit),
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
                        sorted &= h.log_time >= last_time;
                        last_time = h.log_time;
                        batch.push(h, data.get(MESSAGE_HEADER..).unwrap_or_default());
                    }
                    op::SCHEMA => match parse_schema(data) {
                        Some(s) => self.add_schema(s),
                        None => {
                            self.recycle(batch);
                            return Err(self.bad_chunk(rec_pos, "unreadable schema record".into()));
                        }
                    },
                    op::CHANNEL => match parse_channel(data) {
                        Some(ch) => {
                            self.add_channel(ch.id, ch.schema_id, ch.topic, ch.message_encoding)
                        }
                        None => {
                            self.recycle(batch);
                            return Err(self.bad_chunk(rec_pos, "unreadable channel record".into()));
                        }
                    },
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
    /// Message data stays in the decompressed chunk (no copy).
    fn decode_chunk_directly(&mut self, rec_pos: u64, body: &[u8], limit: usize) -> Option<Batch> {
        let mut c = Cur::new(body);
        let _start_time = c.u64()?;
        let _end_time = c.u64()?;
        let uncompressed_size = usize::try_from(c.u64()?).ok()?;
        let crc = c.u32()?;
        let compression = c.string()?;
        let compressed_size = c.u64()?;
        let records = c.b;
        if records.len() as u64 != compressed_size || uncompressed_size > limit {
            return None;
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
            return None;
        }
        let mut sorted = true;
        let mut last_time = 0u64;
        let mut i = 0;
        let arena = std::mem::take(&mut batch.arena);
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
                    sorted &= h.log_time >= last_time;
                    last_time = h.log_time;
                    batch.entries.push(Entry {
                        log_time: h.log_time,
                        publish_time: h.publish_time,
                        sequence: h.sequence,
                        channel_id: h.channel_id,
                        start: start + MESSAGE_HEADER,
                        len: rlen - MESSAGE_HEADER,
                    });
                }
                op::SCHEMA => match parse_schema(data) {
                    Some(s) => self.add_schema(s),
                    None => break false,
                },
                op::CHANNEL => match parse_channel(data) {
                    Some(ch) => {
                        self.add_channel(ch.id, ch.schema_id, ch.topic, ch.message_encoding)
                    }
                    None => break false,
                },
                _ => {}
            }
        };
        batch.arena = arena;
        if !complete {
            self.recycle(batch);
            return None;
        }
        if self.mode == ReadMode::Indexed && !sorted {
            batch.entries.sort_by_key(|e| e.log_time);
        }
        Some(batch)
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

    fn make_resident(&mut self, batch: Batch) -> Option<usize> {
        if batch.entries.is_empty() {
            self.recycle(batch);
            return None;
        }
        self.resident.push(batch);
        self.stats.max_resident_chunks = self.stats.max_resident_chunks.max(self.resident.len());
        Some(self.resident.len() - 1)
    }

    fn indexed_step(&mut self) -> Step {
        loop {
            let mut head: Option<(usize, u64, u64)> = None;
            for (i, b) in self.resident.iter().enumerate() {
                if let Some(e) = b.entries.get(b.pos) {
                    let better = match head {
                        None => true,
                        Some((_, t, o)) => (e.log_time, b.offset) < (t, o),
                    };
                    if better {
                        head = Some((i, e.log_time, b.offset));
                    }
                }
            }
            if let Some(ci) = self.pending.get(self.next_pending).copied() {
                if head.is_none_or(|(_, t, _)| ci.start_time <= t) {
                    self.next_pending += 1;
                    match self.load_indexed_chunk(ci) {
                        Ok(batch) => {
                            self.make_resident(batch);
                            continue;
                        }
                        Err(e) => return Step::Error(e),
                    }
                }
            }
            return match head {
                Some((i, _, _)) => Step::Yield(i),
                None => Step::End,
            };
        }
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
        if let Some(i) = self.resident.iter().position(|b| !b.exhausted()) {
            return Step::Yield(i);
        }
        loop {
            match self.linear_next_record() {
                Ok(Some(batch)) => {
                    if let Some(i) = self.make_resident(batch) {
                        return Step::Yield(i);
                    }
                }
                Ok(None) => return Step::End,
                Err(e) => return Step::Error(e),
            }
        }
    }

    fn truncated(&self, offset: u64, detail: String) -> LogError {
        LogError::Truncated {
            file: self.path.to_path_buf(),
            offset,
            detail,
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
                if len > this.options.max_record_bytes {
                    return Err(LogError::Corrupt {
                        file: this.path.to_path_buf(),
                        offset: rec_pos,
                        detail: format!(
                            "record (opcode {opcode:#04x}) of {len} bytes, more than max_record_bytes"
                        ),
                    });
                }
                let mut body = vec![0u8; len as usize];
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
                        batch.push(h, body.get(MESSAGE_HEADER..).unwrap_or_default());
                    }
                    return Ok(Some(batch));
                }
                op::SCHEMA | op::CHANNEL if !self.seen_data_end => {
                    let body = small_record(self)?;
                    let ok = if opcode == op::SCHEMA {
                        parse_schema(&body).map(|s| self.add_schema(s)).is_some()
                    } else {
                        match parse_channel(&body) {
                            Some(ch) => {
                                self.add_channel(
                                    ch.id,
                                    ch.schema_id,
                                    ch.topic,
                                    ch.message_encoding,
                                );
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
        // The previous message's borrow has ended: free the chunks that are done.
        let mut i = 0;
        while i < self.resident.len() {
            if self.resident[i].exhausted() {
                let b = self.resident.swap_remove(i);
                self.recycle(b);
            } else {
                i += 1;
            }
        }
        let step = match self.mode {
            ReadMode::Indexed => self.indexed_step(),
            ReadMode::Linear => self.linear_step(),
        };
        let i = match step {
            Step::End => {
                self.finished = true;
                return None;
            }
            Step::Error(e) => {
                if e.is_fatal() {
                    self.finished = true;
                }
                return Some(Err(e));
            }
            Step::Yield(i) => i,
        };
        let Some(batch) = self.resident.get_mut(i) else {
            self.finished = true;
            return None;
        };
        let &e = batch.entries.get(batch.pos)?;
        batch.pos += 1;
        let offset = batch.offset;
        let Some(Some(channel)) = self.channels.get(usize::from(e.channel_id)) else {
            return Some(Err(LogError::UnknownChannel {
                file: self.path.to_path_buf(),
                offset,
                log_time_ns: e.log_time,
                channel_id: e.channel_id,
            }));
        };
        self.stats.messages += 1;
        let data = self
            .resident
            .get(i)
            .and_then(|b| b.arena.get(e.start..e.start + e.len))
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
