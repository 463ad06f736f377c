//! Persistence of the event memory across power cycles: an A/B slot store, after the AUTOSAR
//! NvM "redundant block" (two copies, each with a CRC, the newest valid one wins).
//!
//! # Files
//!
//! For a base path `dir/dtc` the store keeps two slot files, `dir/dtc.a` and `dir/dtc.b`. A
//! write always goes to the slot that is *not* current (the older one, or one that is missing
//! or invalid) and makes it current only after the data was written and flushed to the device
//! (`fsync`), so a power loss or crash during a write can only damage the slot being written;
//! the current one, written earlier, is untouched. On the next start [`SlotStore::open`]
//! reads both and takes the valid one with the higher sequence number.
//!
//! # Slot format, version 1 (little-endian)
//!
//! | offset | field | type |
//! |---|---|---|
//! | 0 | magic | 4 bytes `FDDS` |
//! | 4 | format version | u16 = 1 |
//! | 6 | sequence number (1 for the first write, +1 per write) | u64 |
//! | 14 | hash of the DTC configuration ([`ConfigHasher`]) | u64 |
//! | 22 | payload length *n*, bytes | u32 |
//! | 26 | payload (opaque; see [`SectionWriter`]) | *n* bytes |
//! | 26 + *n* | CRC-32 (IEEE, as zlib) of bytes 0 .. 26 + *n* | u32 |
//!
//! A slot file must be exactly `30 + n` bytes long and at most [`MAX_SLOT_BYTES`]. Anything
//! else (missing, shorter than a header, torn by a write that did not finish, bad magic, an
//! unknown version, a length that does not match the file, a CRC mismatch) makes the slot
//! invalid: it is ignored with a [`SlotNote`] saying which file and why, never an error.
//!
//! # What a crash can leave
//!
//! A write truncates the target file, writes it whole and fsyncs it; if the file was new (or
//! its directory entry not yet known durable) the directory is fsynced too. A write cut short
//! leaves the target empty, short or with a bad CRC, and [`SlotStore::open`] falls back to the
//! other slot, which holds the previous write. What is lost is at most the write in progress;
//! a host that must not lose a confirmed DTC calls [`SlotStore::write`] when it is confirmed.

use std::fmt;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};

use fdd_diagnostics::dtc::Dtc;
use thiserror::Error;

/// The first four bytes of a slot file.
pub const SLOT_MAGIC: [u8; 4] = *b"FDDS";

/// The slot format this build writes and reads.
pub const SLOT_FORMAT_VERSION: u16 = 1;

/// Bytes before the payload: magic, version, sequence number, config hash, payload length.
pub const SLOT_HEADER_BYTES: usize = 4 + 2 + 8 + 8 + 4;

/// Header and CRC: a slot file is this many bytes longer than its payload.
pub const SLOT_OVERHEAD_BYTES: usize = SLOT_HEADER_BYTES + 4;

/// Largest slot file [`SlotStore::open`] reads (16 MiB; an event memory image is a few KiB):
/// a larger file is ignored with a note instead of being read into memory.
pub const MAX_SLOT_BYTES: u64 = 16 * 1024 * 1024;

/// Largest payload [`SlotStore::write`] accepts, so every slot it writes can be read back.
pub const MAX_PAYLOAD_BYTES: usize = MAX_SLOT_BYTES as usize - SLOT_OVERHEAD_BYTES;

/// One of the two slot files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SlotId {
    /// `<base>.a`
    A,
    /// `<base>.b`
    B,
}

impl SlotId {
    /// The other slot.
    pub const fn other(self) -> SlotId {
        match self {
            SlotId::A => SlotId::B,
            SlotId::B => SlotId::A,
        }
    }

    /// The file name suffix, `"a"` or `"b"`.
    pub const fn suffix(self) -> &'static str {
        match self {
            SlotId::A => "a",
            SlotId::B => "b",
        }
    }

    const fn index(self) -> usize {
        match self {
            SlotId::A => 0,
            SlotId::B => 1,
        }
    }
}

impl fmt::Display for SlotId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SlotId::A => "A",
            SlotId::B => "B",
        })
    }
}

/// A failed store operation: which file, which operation, and the I/O error.
#[derive(Debug, Error)]
pub enum PersistError {
    /// An I/O operation failed.
    #[error("{}: cannot {operation}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done (`"create directory"`, `"open for writing"`, `"write"`,
        /// `"fsync"`, `"fsync directory"`, ...).
        operation: &'static str,
        /// The error.
        source: io::Error,
    },
    /// The base path has no file name to derive the slot names from (`/`, `..`).
    #[error("{}: the slot base path needs a file name (e.g. dir/dtc for dir/dtc.a and dir/dtc.b)", .0.display())]
    BadBase(PathBuf),
    /// The payload does not fit a slot.
    #[error("payload of {len} bytes exceeds the slot maximum of {max} bytes")]
    PayloadTooLarge {
        /// Payload bytes given.
        len: usize,
        /// [`MAX_PAYLOAD_BYTES`].
        max: usize,
    },
}

/// Why a slot file was ignored.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SlotProblem {
    /// No such file (first start, or that slot was never written).
    Missing,
    /// The file exists but could not be read.
    Unreadable {
        /// `"open"`, `"read"` or `"stat"`.
        operation: &'static str,
        /// The I/O error kind.
        kind: io::ErrorKind,
        /// The I/O error's message.
        message: String,
    },
    /// Larger than [`MAX_SLOT_BYTES`]; not read.
    TooLarge {
        /// File length, bytes.
        len: u64,
    },
    /// Shorter than header and CRC (a write cut short right after it truncated the file).
    Short {
        /// File length, bytes.
        len: u64,
    },
    /// Does not start with [`SLOT_MAGIC`].
    BadMagic {
        /// The first four bytes.
        found: [u8; 4],
    },
    /// A format version this build does not read.
    UnsupportedVersion(u16),
    /// The file is shorter than its header says: a write cut short.
    Torn {
        /// Bytes the header announces (header, payload and CRC).
        expected: u64,
        /// File length, bytes.
        len: u64,
    },
    /// The file is longer than its header says.
    TrailingBytes {
        /// Bytes the header announces (header, payload and CRC).
        expected: u64,
        /// File length, bytes.
        len: u64,
    },
    /// The CRC does not match the content.
    BadCrc {
        /// The CRC in the file.
        stored: u32,
        /// The CRC of the content.
        computed: u32,
    },
    /// Valid, but with the same sequence number as slot A, which is taken instead (only
    /// possible if the files were copied by hand).
    SameSeq(u64),
}

impl fmt::Display for SlotProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SlotProblem::Missing => write!(f, "missing"),
            SlotProblem::Unreadable {
                operation, message, ..
            } => write!(f, "cannot {operation}: {message}"),
            SlotProblem::TooLarge { len } => {
                write!(f, "{len} bytes, larger than the {MAX_SLOT_BYTES}-byte maximum; not read")
            }
            SlotProblem::Short { len } => write!(
                f,
                "{len} bytes, shorter than the {SLOT_OVERHEAD_BYTES}-byte header and CRC (torn write)"
            ),
            SlotProblem::BadMagic { found } => {
                write!(f, "bad magic {found:02X?} (expected \"FDDS\")")
            }
            SlotProblem::UnsupportedVersion(v) => write!(
                f,
                "format version {v}, this build reads version {SLOT_FORMAT_VERSION}"
            ),
            SlotProblem::Torn { expected, len } => write!(
                f,
                "torn write: the header announces {expected} bytes but the file has {len}"
            ),
            SlotProblem::TrailingBytes { expected, len } => write!(
                f,
                "the header announces {expected} bytes but the file has {len}"
            ),
            SlotProblem::BadCrc { stored, computed } => write!(
                f,
                "CRC mismatch (stored 0x{stored:08X}, computed 0x{computed:08X})"
            ),
            SlotProblem::SameSeq(seq) => {
                write!(f, "same sequence number {seq} as slot A, which is used")
            }
        }
    }
}

/// A slot file that [`SlotStore::open`] ignored.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlotNote {
    /// Which slot.
    pub slot: SlotId,
    /// Its file.
    pub path: PathBuf,
    /// Why it was ignored.
    pub problem: SlotProblem,
}

impl fmt::Display for SlotNote {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "slot {} ({}) ignored: {}",
            self.slot,
            self.path.display(),
            self.problem
        )
    }
}

/// The slot [`SlotStore::open`] recovered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecoveredSlot {
    /// Which slot.
    pub slot: SlotId,
    /// Its file.
    pub path: PathBuf,
    /// Its sequence number.
    pub seq: u64,
    /// The configuration hash stored with it.
    pub config_hash: u64,
    /// Whether that hash equals the one given to [`SlotStore::open`]. If not, the DTC
    /// configuration changed since the write: restore the payload anyway (restoring matches
    /// events by name and DTC and reports what it dropped) or discard it.
    pub config_matches: bool,
    /// The payload as written.
    pub payload: Vec<u8>,
}

/// What [`SlotStore::open`] found.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Recovered {
    /// The valid slot with the highest sequence number; `None` when neither is valid (first
    /// start, or both damaged: see `notes`).
    pub current: Option<RecoveredSlot>,
    /// Every slot file that was ignored, and why (a missing slot too).
    pub notes: Vec<SlotNote>,
}

impl Recovered {
    /// The recovered payload, if any.
    pub fn payload(&self) -> Option<&[u8]> {
        self.current.as_ref().map(|c| c.payload.as_slice())
    }

    /// Whether the store held nothing valid.
    pub fn is_first_start(&self) -> bool {
        self.current.is_none()
    }
}

/// Where a [`SlotStore::write`] went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Written {
    /// The slot written, now current.
    pub slot: SlotId,
    /// Its sequence number.
    pub seq: u64,
}

/// The A/B slot store (see the [module documentation](self)).
#[derive(Debug)]
pub struct SlotStore {
    dir: PathBuf,
    paths: [PathBuf; 2],
    config_hash: u64,
    current: Option<(SlotId, u64)>,
    /// Whether the slot file's directory entry is known to be durable (directory fsynced
    /// since the file was created).
    dir_synced: [bool; 2],
    buf: Vec<u8>,
}

impl SlotStore {
    /// Opens the store at `base` (slot files `<base>.a` and `<base>.b`; the directory is
    /// created if needed) for a DTC configuration with hash `config_hash`, and reads both
    /// slots. Invalid or missing slots are notes in the returned [`Recovered`], never errors;
    /// the only errors are a base path without a file name and a directory that cannot be
    /// created or read.
    pub fn open(
        base: impl AsRef<Path>,
        config_hash: u64,
    ) -> Result<(SlotStore, Recovered), PersistError> {
        let base = base.as_ref();
        let name = base
            .file_name()
            .ok_or_else(|| PersistError::BadBase(base.to_path_buf()))?;
        let dir = match base.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        fs::create_dir_all(&dir).map_err(|source| PersistError::Io {
            path: dir.clone(),
            operation: "create directory",
            source,
        })?;
        fs::read_dir(&dir).map_err(|source| PersistError::Io {
            path: dir.clone(),
            operation: "read directory",
            source,
        })?;
        let path = |slot: SlotId| {
            let mut n = name.to_os_string();
            n.push(".");
            n.push(slot.suffix());
            dir.join(n)
        };
        let paths = [path(SlotId::A), path(SlotId::B)];

        let mut notes = Vec::new();
        let mut valid: Vec<RecoveredSlot> = Vec::with_capacity(2);
        for slot in [SlotId::A, SlotId::B] {
            let p = &paths[slot.index()];
            match read_slot(p) {
                Ok((seq, hash, payload)) => valid.push(RecoveredSlot {
                    slot,
                    path: p.clone(),
                    seq,
                    config_hash: hash,
                    config_matches: hash == config_hash,
                    payload,
                }),
                Err(problem) => notes.push(SlotNote {
                    slot,
                    path: p.clone(),
                    problem,
                }),
            }
        }
        // The newest valid slot; on a tie A (and a note for B).
        let current = match valid.len() {
            2 => {
                let (a, b) = (valid.remove(0), valid.remove(0));
                if b.seq > a.seq {
                    Some(b)
                } else {
                    if b.seq == a.seq {
                        notes.push(SlotNote {
                            slot: SlotId::B,
                            path: b.path,
                            problem: SlotProblem::SameSeq(b.seq),
                        });
                    }
                    Some(a)
                }
            }
            _ => valid.pop(),
        };

        // Directory entries of files found now are made durable once, so a file created by a
        // run that crashed before its directory fsync is not lost on a later power cut.
        let existing = [0, 1].map(|i| fs::symlink_metadata(&paths[i]).is_ok());
        let dir_ok = sync_dir(&dir).is_ok();
        let store = SlotStore {
            dir,
            paths,
            config_hash,
            current: current.as_ref().map(|c| (c.slot, c.seq)),
            dir_synced: existing.map(|e| e && dir_ok),
            buf: Vec::new(),
        };
        Ok((store, Recovered { current, notes }))
    }

    /// Writes `payload` as the next slot: to the slot that is not current (A if neither is),
    /// with sequence number current + 1 (1 if none), the configuration hash given to
    /// [`SlotStore::open`] and a CRC. The file is truncated, written whole and fsynced (and
    /// the directory fsynced if the file is new); only then does the slot become current. On
    /// an error the current slot is unchanged (the target slot may now be invalid; the next
    /// write tries it again).
    pub fn write(&mut self, payload: &[u8]) -> Result<Written, PersistError> {
        if payload.len() > MAX_PAYLOAD_BYTES {
            return Err(PersistError::PayloadTooLarge {
                len: payload.len(),
                max: MAX_PAYLOAD_BYTES,
            });
        }
        let (target, seq) = match self.current {
            Some((slot, seq)) => (slot.other(), seq.saturating_add(1)),
            None => (SlotId::A, 1),
        };
        let buf = &mut self.buf;
        buf.clear();
        buf.extend_from_slice(&SLOT_MAGIC);
        buf.extend_from_slice(&SLOT_FORMAT_VERSION.to_le_bytes());
        buf.extend_from_slice(&seq.to_le_bytes());
        buf.extend_from_slice(&self.config_hash.to_le_bytes());
        buf.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        buf.extend_from_slice(payload);
        let crc = crc32fast::hash(buf);
        buf.extend_from_slice(&crc.to_le_bytes());

        let i = target.index();
        let path = &self.paths[i];
        let io_err = |operation: &'static str| {
            move |source| PersistError::Io {
                path: path.clone(),
                operation,
                source,
            }
        };
        let created = fs::symlink_metadata(path).is_err();
        if created {
            self.dir_synced[i] = false;
        }
        let mut f = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(path)
            .map_err(io_err("open for writing"))?;
        f.write_all(buf).map_err(io_err("write"))?;
        f.sync_all().map_err(io_err("fsync"))?;
        drop(f);
        if !self.dir_synced[i] {
            sync_dir(&self.dir).map_err(|source| PersistError::Io {
                path: self.dir.clone(),
                operation: "fsync directory",
                source,
            })?;
            self.dir_synced[i] = true;
        }
        self.current = Some((target, seq));
        Ok(Written { slot: target, seq })
    }

    /// The current slot and its sequence number (the last write, or what `open` recovered).
    pub fn current(&self) -> Option<(SlotId, u64)> {
        self.current
    }

    /// The sequence number the next [`SlotStore::write`] will use.
    pub fn next_seq(&self) -> u64 {
        self.current.map_or(1, |(_, s)| s.saturating_add(1))
    }

    /// The file of `slot`.
    pub fn path(&self, slot: SlotId) -> &Path {
        &self.paths[slot.index()]
    }

    /// The configuration hash written with every slot.
    pub fn config_hash(&self) -> u64 {
        self.config_hash
    }
}

/// Reads and checks one slot file: `(seq, config hash, payload)` or why it is invalid.
fn read_slot(path: &Path) -> Result<(u64, u64, Vec<u8>), SlotProblem> {
    let unreadable = |operation: &'static str| {
        move |e: io::Error| SlotProblem::Unreadable {
            operation,
            kind: e.kind(),
            message: e.to_string(),
        }
    };
    let file = match File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Err(SlotProblem::Missing),
        Err(e) => return Err(unreadable("open")(e)),
    };
    let len = file.metadata().map_err(unreadable("stat"))?.len();
    if len > MAX_SLOT_BYTES {
        return Err(SlotProblem::TooLarge { len });
    }
    let mut bytes = Vec::with_capacity(len as usize);
    // Bounded even if the file grows after the stat.
    file.take(MAX_SLOT_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(unreadable("read"))?;
    let len = bytes.len() as u64;
    if len > MAX_SLOT_BYTES {
        return Err(SlotProblem::TooLarge { len });
    }
    if bytes.len() < SLOT_OVERHEAD_BYTES {
        return Err(SlotProblem::Short { len });
    }
    let field = |at: usize| -> [u8; 8] {
        let mut a = [0u8; 8];
        a.copy_from_slice(&bytes[at..at + 8]);
        a
    };
    if bytes[0..4] != SLOT_MAGIC {
        let mut found = [0u8; 4];
        found.copy_from_slice(&bytes[0..4]);
        return Err(SlotProblem::BadMagic { found });
    }
    let version = u16::from_le_bytes([bytes[4], bytes[5]]);
    if version != SLOT_FORMAT_VERSION {
        return Err(SlotProblem::UnsupportedVersion(version));
    }
    let seq = u64::from_le_bytes(field(6));
    let hash = u64::from_le_bytes(field(14));
    let n = u32::from_le_bytes([bytes[22], bytes[23], bytes[24], bytes[25]]);
    let expected = SLOT_OVERHEAD_BYTES as u64 + u64::from(n);
    if len < expected {
        return Err(SlotProblem::Torn { expected, len });
    }
    if len > expected {
        return Err(SlotProblem::TrailingBytes { expected, len });
    }
    let body = bytes.len() - 4;
    let stored = u32::from_le_bytes([
        bytes[body],
        bytes[body + 1],
        bytes[body + 2],
        bytes[body + 3],
    ]);
    let computed = crc32fast::hash(&bytes[..body]);
    if stored != computed {
        return Err(SlotProblem::BadCrc { stored, computed });
    }
    bytes.truncate(body);
    bytes.drain(..SLOT_HEADER_BYTES);
    Ok((seq, hash, bytes))
}

/// Makes the directory's entries durable (a new file's name survives a power cut).
#[cfg(unix)]
fn sync_dir(dir: &Path) -> io::Result<()> {
    File::open(dir)?.sync_all()
}

/// Directories cannot be opened for fsync here; the file's own fsync is all there is.
#[cfg(not(unix))]
fn sync_dir(_dir: &Path) -> io::Result<()> {
    Ok(())
}

// ------------------------------------------------------------------------------ config hash

/// A 64-bit hash of a DTC configuration, stored in every slot so that a restart can tell
/// whether the configuration changed since the write.
///
/// FNV-1a 64 (offset basis `0xcbf29ce484222325`, prime `0x100000001b3`) over the UTF-8 bytes
/// of each line followed by `\n`, in the order given. It depends on nothing but those bytes:
/// stable across runs, builds, Rust versions and platforms (unlike `std`'s `DefaultHasher`).
/// Not a cryptographic hash; it detects changes, not tampering. Feed one line per event,
/// `monitor/event/DTC` ([`ConfigHasher::event`]), in configuration order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConfigHasher(u64);

impl Default for ConfigHasher {
    fn default() -> Self {
        Self::new()
    }
}

impl ConfigHasher {
    const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    /// The hash of nothing.
    pub const fn new() -> Self {
        ConfigHasher(Self::OFFSET_BASIS)
    }

    fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= u64::from(x);
            self.0 = self.0.wrapping_mul(Self::PRIME);
        }
    }

    /// Adds one line (`\n` is appended).
    pub fn line(&mut self, line: &str) -> &mut Self {
        self.bytes(line.as_bytes());
        self.bytes(b"\n");
        self
    }

    /// Adds the line `monitor/event/DTC`, e.g. `intake/map_perf/P0106-64`.
    pub fn event(&mut self, monitor: &str, event: &str, dtc: Dtc) -> &mut Self {
        self.bytes(monitor.as_bytes());
        self.bytes(b"/");
        self.bytes(event.as_bytes());
        self.bytes(b"/");
        self.bytes(&dtc.to_ascii());
        self.bytes(b"\n");
        self
    }

    /// The hash so far.
    pub const fn finish(&self) -> u64 {
        self.0
    }
}

/// [`ConfigHasher`] over `lines`.
pub fn config_hash<I, S>(lines: I) -> u64
where
    I: IntoIterator<Item = S>,
    S: AsRef<str>,
{
    let mut h = ConfigHasher::new();
    for l in lines {
        h.line(l.as_ref());
    }
    h.finish()
}

// ------------------------------------------------------------------------------ sections

/// Writes a list of named sections into a payload (e.g. one encoded event memory image per
/// monitor): a u32 section count, then per section a u16 name length, the UTF-8 name, a u32
/// data length and the data (little-endian). Read back with [`unpack_sections`].
///
/// Writes straight into the caller's buffer, so a reused buffer allocates nothing:
///
/// ```
/// use fdd_monitor::persist::{unpack_sections, SectionWriter};
/// let mut payload = Vec::new();
/// let mut w = SectionWriter::new(&mut payload);
/// w.section("intake", |buf| buf.extend_from_slice(b"image bytes")).unwrap();
/// w.section("throttle", |buf| buf.extend_from_slice(b"more")).unwrap();
/// w.finish();
/// let sections = unpack_sections(&payload).unwrap();
/// assert_eq!(sections, [("intake", &b"image bytes"[..]), ("throttle", &b"more"[..])]);
/// ```
#[derive(Debug)]
pub struct SectionWriter<'a> {
    out: &'a mut Vec<u8>,
    count_at: usize,
    count: u32,
}

/// A section that [`SectionWriter::section`] could not write.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum SectionWriteError {
    /// The name is longer than 65535 bytes.
    #[error("section name of {0} bytes is longer than 65535 bytes")]
    NameTooLong(usize),
    /// The data is longer than `u32::MAX` bytes.
    #[error("section data of {0} bytes is longer than 4 GiB")]
    DataTooLarge(usize),
    /// More than `u32::MAX` sections.
    #[error("more than 2^32 - 1 sections")]
    TooMany,
    /// The fill function removed bytes it had not written; the payload is unusable.
    #[error("the section's fill function shrank the buffer below the section start")]
    BufferShrunk,
}

impl<'a> SectionWriter<'a> {
    /// Starts a section list at the end of `out`.
    pub fn new(out: &'a mut Vec<u8>) -> Self {
        let count_at = out.len();
        out.extend_from_slice(&0u32.to_le_bytes());
        SectionWriter {
            out,
            count_at,
            count: 0,
        }
    }

    /// Appends a section named `name` whose data `fill` appends to the buffer it is given.
    /// On an error nothing of the section remains.
    pub fn section(
        &mut self,
        name: &str,
        fill: impl FnOnce(&mut Vec<u8>),
    ) -> Result<(), SectionWriteError> {
        let name_len =
            u16::try_from(name.len()).map_err(|_| SectionWriteError::NameTooLong(name.len()))?;
        let count = self
            .count
            .checked_add(1)
            .ok_or(SectionWriteError::TooMany)?;
        let start = self.out.len();
        self.out.extend_from_slice(&name_len.to_le_bytes());
        self.out.extend_from_slice(name.as_bytes());
        let len_at = self.out.len();
        self.out.extend_from_slice(&0u32.to_le_bytes());
        fill(self.out);
        let Some(data_len) = self.out.len().checked_sub(len_at + 4) else {
            self.out.truncate(start);
            return Err(SectionWriteError::BufferShrunk);
        };
        let Ok(n) = u32::try_from(data_len) else {
            self.out.truncate(start);
            return Err(SectionWriteError::DataTooLarge(data_len));
        };
        self.out[len_at..len_at + 4].copy_from_slice(&n.to_le_bytes());
        self.count = count;
        Ok(())
    }

    /// Writes the section count.
    pub fn finish(self) {
        // Only missing after a `BufferShrunk` error.
        if let Some(dst) = self.out.get_mut(self.count_at..self.count_at + 4) {
            dst.copy_from_slice(&self.count.to_le_bytes());
        }
    }
}

/// Why [`unpack_sections`] refused a payload, and where.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("section list: {what} at byte {offset}")]
pub struct SectionError {
    /// Byte offset of the field that is wrong.
    pub offset: usize,
    /// What is wrong.
    pub what: &'static str,
}

/// The `(name, data)` sections of a payload written by [`SectionWriter`], in order, borrowing
/// from `bytes`. Never panics; every length is checked against the bytes left.
pub fn unpack_sections(bytes: &[u8]) -> Result<Vec<(&str, &[u8])>, SectionError> {
    struct Cursor<'b> {
        bytes: &'b [u8],
        pos: usize,
    }
    impl<'b> Cursor<'b> {
        fn take(&mut self, n: usize, what: &'static str) -> Result<&'b [u8], SectionError> {
            if self.bytes.len() - self.pos < n {
                return Err(SectionError {
                    offset: self.pos,
                    what,
                });
            }
            let s = &self.bytes[self.pos..self.pos + n];
            self.pos += n;
            Ok(s)
        }
        fn u16(&mut self, what: &'static str) -> Result<usize, SectionError> {
            let b = self.take(2, what)?;
            Ok(u16::from_le_bytes([b[0], b[1]]) as usize)
        }
        fn u32(&mut self, what: &'static str) -> Result<usize, SectionError> {
            let b = self.take(4, what)?;
            Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        }
    }
    let mut c = Cursor { bytes, pos: 0 };
    let count = c.u32("truncated section count")?;
    // Each section takes at least 6 bytes: a bad count cannot make us allocate more than that.
    let mut out = Vec::with_capacity(count.min((bytes.len() - c.pos) / 6));
    for _ in 0..count {
        let name_len = c.u16("truncated section name length")?;
        let name_at = c.pos;
        let raw = c.take(name_len, "truncated section name")?;
        let name = std::str::from_utf8(raw).map_err(|_| SectionError {
            offset: name_at,
            what: "section name is not UTF-8",
        })?;
        let data_len = c.u32("truncated section data length")?;
        let data = c.take(data_len, "truncated section data")?;
        out.push((name, data));
    }
    if c.pos != bytes.len() {
        return Err(SectionError {
            offset: c.pos,
            what: "trailing bytes after the last section",
        });
    }
    Ok(out)
}
