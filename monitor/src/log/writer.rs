//! [`LogWriter`]: writes fdd messages to an MCAP file with pinned settings, so the same messages
//! always give the same bytes.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::error::LogError;
use super::messages::TopicMessage;
use super::schema::{builtin_topic, MESSAGE_ENCODING, SCHEMA_ENCODING};

/// The `library` field of the MCAP header of every file fdd writes.
pub const LIBRARY: &str = "fdd-monitor";
/// The `profile` field of the MCAP header (none: the channels say their own encodings).
pub const PROFILE: &str = "";

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChunkCompression {
    /// Uncompressed chunks.
    None,
    /// Zstandard at this level (1-19; 0 means zstd's default, 3).
    Zstd { level: u32 },
}

/// Writer settings. Every field is part of what makes the output bytes reproducible: the same
/// options, the same messages in the same order and the same build of the zstd library give the
/// same file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WriteOptions {
    /// Target uncompressed chunk size, bytes: a chunk is closed and written out once it is
    /// larger, so memory use stays at about one chunk whatever the length of the log.
    pub chunk_size: u64,
    /// Chunk compression.
    pub compression: ChunkCompression,
    /// Write a message-index record per channel after each chunk (16 uncompressed bytes per
    /// message). They let readers seek to a message inside a chunk; fdd's reader and the official
    /// readers order messages by decompressing whole chunks and do not need them. Files written
    /// in time order can leave them out: for 1 kHz inputs they are most of the file.
    pub message_indexes: bool,
}

impl WriteOptions {
    /// The default target chunk size, 1 MiB (about 25,000 fdd input samples).
    pub const DEFAULT_CHUNK_SIZE: u64 = 1024 * 1024;
    /// The default zstd level: 1, the fastest. On fdd's float-heavy JSON it compresses about
    /// as well as level 3 (measured: 30.2 vs 31.5 MB for a million input samples) and writes
    /// about 25% faster.
    pub const DEFAULT_ZSTD_LEVEL: u32 = 1;
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            chunk_size: Self::DEFAULT_CHUNK_SIZE,
            compression: ChunkCompression::Zstd {
                level: Self::DEFAULT_ZSTD_LEVEL,
            },
            message_indexes: true,
        }
    }
}

#[derive(Debug)]
struct Channel {
    id: u16,
    next_sequence: u32,
    schema_name: String,
    schema: String,
}

/// Writes JSON messages on JSON-schema channels to an MCAP file.
///
/// Each topic gets one schema record (encoding `jsonschema`) and one channel record (message
/// encoding `json`), written the first time the topic is used; built-in topics
/// ([`super::schema::TOPICS`]) need no registration, others are registered with
/// [`add_topic`](Self::add_topic). A message's log time and publish time are both the sample
/// time in ns. Chunks are written out as they fill, so memory use does not grow with the log.
///
/// Call [`finish`](Self::finish) and check its result: it writes the summary and footer, without
/// which readers must fall back to a slow linear scan. A writer dropped without `finish` is
/// finished by the drop, but an error there cannot be reported (it is logged with `tracing`).
///
/// Settings are pinned (`library` [`LIBRARY`], `profile` empty, single-threaded compression,
/// fixed chunk size and zstd level), so writing the same messages twice gives identical bytes.
pub struct LogWriter<W: Write + Seek> {
    inner: Option<mcap::Writer<W>>,
    file: PathBuf,
    channels: HashMap<String, Channel>,
    buf: Vec<u8>,
    messages: u64,
}

impl LogWriter<BufWriter<File>> {
    /// Creates (or truncates) `path` and writes to it with the default options.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, LogError> {
        Self::create_with(path, WriteOptions::default())
    }

    /// Creates (or truncates) `path` and writes to it with `options`.
    pub fn create_with(path: impl AsRef<Path>, options: WriteOptions) -> Result<Self, LogError> {
        let path = path.as_ref();
        let file = File::create(path).map_err(|source| LogError::Create {
            file: path.to_path_buf(),
            source,
        })?;
        LogWriter::with_options(BufWriter::with_capacity(1 << 16, file), path, options)
    }
}

impl<W: Write + Seek> LogWriter<W> {
    /// Writes to `w` with the default options; `name` (a path or a description) names the
    /// output in errors.
    pub fn new(w: W, name: impl Into<PathBuf>) -> Result<Self, LogError> {
        Self::with_options(w, name, WriteOptions::default())
    }

    /// Writes to `w` with `options`; `name` names the output in errors.
    pub fn with_options(
        w: W,
        name: impl Into<PathBuf>,
        options: WriteOptions,
    ) -> Result<Self, LogError> {
        let file = name.into();
        let (compression, level) = match options.compression {
            ChunkCompression::None => (None, 0),
            ChunkCompression::Zstd { level } => (Some(mcap::Compression::Zstd), level),
        };
        let inner = mcap::WriteOptions::new()
            .compression(compression)
            .compression_level(level)
            .compression_threads(0)
            .library(LIBRARY)
            .profile(PROFILE)
            .chunk_size(Some(options.chunk_size))
            .use_chunks(true)
            .emit_message_indexes(options.message_indexes)
            .create(w)
            .map_err(|source| LogError::Write {
                file: file.clone(),
                topic: None,
                log_time_ns: None,
                source,
            })?;
        Ok(LogWriter {
            inner: Some(inner),
            file,
            channels: HashMap::new(),
            buf: Vec::with_capacity(256),
            messages: 0,
        })
    }

    /// The name given at creation (the path for [`LogWriter::create`]).
    pub fn file(&self) -> &Path {
        &self.file
    }

    /// Messages written so far.
    pub fn messages_written(&self) -> u64 {
        self.messages
    }

    /// Registers `topic` with a JSON schema (`schema_json`, a JSON object) named
    /// `schema_name`, writing its schema and channel records now. Registering a topic again
    /// with the same schema does nothing; with another schema it is an error.
    pub fn add_topic(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema_json: &str,
    ) -> Result<(), LogError> {
        if let Some(ch) = self.channels.get(topic) {
            if ch.schema_name == schema_name && ch.schema == schema_json {
                return Ok(());
            }
            return Err(LogError::BadSchema {
                file: self.file.clone(),
                topic: topic.into(),
                detail: format!(
                    "already registered with schema '{}', a different schema",
                    ch.schema_name
                ),
            });
        }
        match serde_json::from_str::<serde_json::Value>(schema_json) {
            Ok(v) if v.is_object() => {}
            Ok(_) => {
                return Err(LogError::BadSchema {
                    file: self.file.clone(),
                    topic: topic.into(),
                    detail: "the JSON schema is not a JSON object".into(),
                })
            }
            Err(e) => {
                return Err(LogError::BadSchema {
                    file: self.file.clone(),
                    topic: topic.into(),
                    detail: format!("the JSON schema is not valid JSON: {e}"),
                })
            }
        }
        self.register(topic, schema_name, schema_json)?;
        Ok(())
    }

    fn register(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema_json: &str,
    ) -> Result<&mut Channel, LogError> {
        let file = &self.file;
        let write_err = |source| LogError::Write {
            file: file.clone(),
            topic: Some(topic.into()),
            log_time_ns: None,
            source,
        };
        let inner = self.inner.as_mut().ok_or_else(|| write_err(finished()))?;
        let schema_id = inner
            .add_schema(schema_name, SCHEMA_ENCODING, schema_json.as_bytes())
            .map_err(write_err)?;
        let id = inner
            .add_channel(schema_id, topic, MESSAGE_ENCODING, &BTreeMap::new())
            .map_err(write_err)?;
        Ok(self.channels.entry(topic.to_string()).or_insert(Channel {
            id,
            next_sequence: 0,
            schema_name: schema_name.into(),
            schema: schema_json.into(),
        }))
    }

    /// Serializes `msg` to JSON and writes it on `topic` at `log_time_ns` (the sample time,
    /// ns; also the publish time). `topic` must be built in or registered with
    /// [`add_topic`](Self::add_topic). Non-finite numbers should be marked with
    /// [`nan_as_null`](super::messages::nan_as_null) (serde_json writes them as `null` anyway).
    pub fn write<T: Serialize + ?Sized>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &T,
    ) -> Result<(), LogError> {
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        let result = match serde_json::to_writer(&mut buf, msg) {
            Ok(()) => self.write_raw_json(topic, log_time_ns, &buf),
            Err(source) => Err(LogError::Serialize {
                file: self.file.clone(),
                topic: topic.into(),
                log_time_ns,
                source,
            }),
        };
        self.buf = buf;
        result
    }

    /// Writes `msg` on its own topic ([`TopicMessage::TOPIC`]).
    pub fn write_message<M: TopicMessage>(
        &mut self,
        log_time_ns: u64,
        msg: &M,
    ) -> Result<(), LogError> {
        self.write(M::TOPIC, log_time_ns, msg)
    }

    /// Writes `json` (already-serialized JSON, written as given and not checked) on `topic` at
    /// `log_time_ns`. `topic` must be built in or registered with [`add_topic`](Self::add_topic).
    pub fn write_raw_json(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        json: &[u8],
    ) -> Result<(), LogError> {
        let header = if let Some(channel) = self.channels.get_mut(topic) {
            next_header(channel, log_time_ns)
        } else {
            match builtin_topic(topic) {
                Some(t) => next_header(
                    self.register(t.topic, t.schema_name, t.schema)?,
                    log_time_ns,
                ),
                None => {
                    return Err(LogError::UnknownTopic {
                        file: self.file.clone(),
                        topic: topic.into(),
                    })
                }
            }
        };
        let write_err = |source| LogError::Write {
            file: self.file.clone(),
            topic: Some(topic.into()),
            log_time_ns: Some(log_time_ns),
            source,
        };
        let inner = self.inner.as_mut().ok_or_else(|| write_err(finished()))?;
        inner
            .write_to_known_channel(&header, json)
            .map_err(write_err)?;
        self.messages += 1;
        Ok(())
    }

    /// Finishes the file (last chunk, summary, footer), flushes it and returns the underlying
    /// writer. An error here means the file is incomplete.
    pub fn finish(mut self) -> Result<W, LogError> {
        let file = self.file.clone();
        let write_err = |source| LogError::Write {
            file: file.clone(),
            topic: None,
            log_time_ns: None,
            source,
        };
        let mut inner = self.inner.take().ok_or_else(|| write_err(finished()))?;
        inner.finish().map_err(write_err)?;
        let mut w = inner.into_inner();
        w.flush().map_err(|e| write_err(mcap::McapError::Io(e)))?;
        Ok(w)
    }
}

/// The header of the next message on `channel`, advancing its sequence number.
fn next_header(channel: &mut Channel, log_time_ns: u64) -> mcap::records::MessageHeader {
    let header = mcap::records::MessageHeader {
        channel_id: channel.id,
        sequence: channel.next_sequence,
        log_time: log_time_ns,
        publish_time: log_time_ns,
    };
    channel.next_sequence = channel.next_sequence.wrapping_add(1);
    header
}

fn finished() -> mcap::McapError {
    mcap::McapError::AttemptedWriteAfterFailure
}

impl<W: Write + Seek> Drop for LogWriter<W> {
    fn drop(&mut self) {
        if let Some(mut inner) = self.inner.take() {
            tracing::warn!(
                file = %self.file.display(),
                "LogWriter dropped without finish(); finishing the file now"
            );
            if let Err(e) = inner.finish() {
                tracing::error!(
                    file = %self.file.display(),
                    error = %e,
                    "could not finish the MCAP file: it is incomplete"
                );
            }
        }
    }
}

impl<W: Write + Seek> std::fmt::Debug for LogWriter<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogWriter")
            .field("file", &self.file)
            .field("topics", &self.channels.len())
            .field("messages", &self.messages)
            .field("finished", &self.inner.is_none())
            .finish()
    }
}
