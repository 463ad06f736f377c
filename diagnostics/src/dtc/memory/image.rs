//! The persistent part of an [`EventMemory`]: a [`MemoryImage`], its binary encoding, and
//! [`EventMemory::restore`].
//!
//! The module is private; its types are re-exported from [`crate::dtc`], and
//! [`MemoryImage`] documents the content and the encoding.

use std::fmt;

use thiserror::Error;

use super::{Entry, EventId, EventMemory};
use crate::dtc::code::Dtc;
use crate::dtc::status::DtcStatus;

/// The first four bytes of an encoded [`MemoryImage`].
pub const IMAGE_MAGIC: [u8; 4] = *b"FDEM";

/// The encoding [`MemoryImage::encode`] writes and [`MemoryImage::decode`] reads.
pub const IMAGE_FORMAT_VERSION: u16 = 1;

/// Smallest encoded event: name length, DTC, 6 counter bytes, entry flag.
const MIN_EVENT_BYTES: usize = 1 + 4 + 6 + 1;
/// Smallest encoded freeze-frame signal: name length, value.
const MIN_SIGNAL_BYTES: usize = 1 + 8;

/// The state of an [`EventMemory`] that must survive a power cycle. Built by
/// [`EventMemory::image`], applied by [`EventMemory::restore`], encoded by
/// [`MemoryImage::encode`] and decoded by [`MemoryImage::decode`].
///
/// # What survives a power cycle
///
/// An ECU keeps its event memory in non-volatile memory (AUTOSAR NvM blocks) so that a
/// confirmed DTC, its counters and its freeze frame are still there after the ignition was
/// off. The image holds exactly that state:
///
/// - per event, identified by its configured **name and DTC**: the status byte, the failed-cycle
///   count (towards confirmation), the healing-cycle count (towards MIL off), the aging counter,
///   the occurrence counter, the largest FDC since the last clear, and its memory entry if it
///   has one (storage order, storage time, freeze-frame signal names and values);
/// - per memory: the next storage order number, the overflow indication and count, and the
///   number of operation cycles started.
///
/// Not in the image: the debouncers (every operation cycle start resets them anyway, and a
/// power-up always starts a new cycle), whether a cycle is running (a restored memory is
/// between cycles) and the time of the last call (the host's clock restarts at power-up; a
/// restored memory accepts any finite time as its first one). Stored times
/// ([`EntryImage::stored_time_s`]) stay on the clock of the power cycle that stored them.
///
/// # Encoding, version 1
///
/// Little-endian, no padding, no checksum (the slot store that holds the image adds one).
/// `varint` is an unsigned LEB128 number (7 bits per byte, low group first, at most 10
/// bytes); strings are a varint byte length followed by UTF-8.
///
/// | offset | field | type |
/// |---|---|---|
/// | 0 | magic | 4 bytes `FDEM` |
/// | 4 | format version | u16 = 1 |
/// | 6 | next storage seq | u64 |
/// | 14 | operation cycles started | u64 |
/// | 22 | overflow flag | u8, 0 or 1 |
/// | 23 | overflow count | u32 |
/// | 27 | event count | varint |
/// | | per event: name | string |
/// | | per event: DTC | u32, the 3-byte UDS value (at most `0xFFFFFF`) |
/// | | per event: status byte, failed cycles, healing cycles, aging counter, occurrence counter | 5 x u8 |
/// | | per event: max FDC | i8 |
/// | | per event: entry flag | u8, 0 (none) or 1 |
/// | | entry: storage seq | u64 |
/// | | entry: stored time, s | f64 (IEEE 754 bits) |
/// | | entry: freeze-frame signal count | varint |
/// | | per signal: name, value | string, f64 (NaN = no value) |
///
/// Nothing may follow the last event. [`MemoryImage::decode`] checks every length against the
/// bytes that are left before it allocates, and reports the first problem with its byte
/// offset ([`ImageError`]); it never panics. A new format gets a new version number; this
/// build refuses versions it does not know rather than guessing.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MemoryImage {
    /// The storage order number the next memory entry gets.
    pub next_seq: u64,
    /// Whether a new entry met a full memory since the last clear of all DTCs.
    pub overflow: bool,
    /// Entries that could not be stored since the last clear of all DTCs.
    pub overflow_count: u32,
    /// Operation cycles started over the memory's whole life (all power cycles).
    pub operation_cycles_started: u64,
    /// One record per event, in configuration order when built by [`EventMemory::image`].
    pub events: Vec<EventImage>,
}

/// One event of a [`MemoryImage`].
#[derive(Debug, Clone, PartialEq)]
pub struct EventImage {
    /// The configured event name; with [`EventImage::dtc`] what identifies the event on restore.
    pub name: String,
    /// The event's DTC.
    pub dtc: Dtc,
    /// The status byte as it was (bits 1 and 6 are reset by the next operation cycle start).
    pub status: DtcStatus,
    /// Failed operation cycles counted towards confirmation.
    pub failed_cycles: u8,
    /// Passed operation cycles counted towards switching the MIL off.
    pub healing_cycles: u8,
    /// Aging cycles counted.
    pub aging_counter: u8,
    /// Occurrence counter (extended data).
    pub occurrence_counter: u8,
    /// Largest fault detection counter since the last clear (extended data).
    pub max_fdc: i8,
    /// The event's memory entry, if it had one.
    pub entry: Option<EntryImage>,
}

/// A memory entry of an [`EventImage`].
#[derive(Debug, Clone, PartialEq)]
pub struct EntryImage {
    /// Storage order (larger = stored later); decides "oldest" in displacement.
    pub stored_seq: u64,
    /// Time the entry was stored, s, on the clock of the power cycle that stored it.
    pub stored_time_s: f64,
    /// The freeze frame: `(signal, value)` in the order configured when it was stored; NaN
    /// where no value was given.
    pub freeze_frame: Vec<(String, f64)>,
}

impl MemoryImage {
    /// The record of the event named `name`.
    pub fn event(&self, name: &str) -> Option<&EventImage> {
        self.events.iter().find(|e| e.name == name)
    }

    /// The DTCs whose confirmedDTC bit is set, in image order.
    pub fn confirmed_dtcs(&self) -> impl Iterator<Item = Dtc> + '_ {
        self.events
            .iter()
            .filter(|e| e.status.confirmed())
            .map(|e| e.dtc)
    }

    /// Appends the version-1 encoding (see [`MemoryImage`]) to `out`.
    /// Reusing `out` across calls avoids allocating once it is large enough.
    pub fn encode(&self, out: &mut Vec<u8>) {
        put_header(
            out,
            self.next_seq,
            self.operation_cycles_started,
            self.overflow,
            self.overflow_count,
            self.events.len(),
        );
        for e in &self.events {
            put_event(
                out,
                EventRecord {
                    name: &e.name,
                    dtc: e.dtc,
                    status: e.status,
                    failed_cycles: e.failed_cycles,
                    healing_cycles: e.healing_cycles,
                    aging_counter: e.aging_counter,
                    occurrence_counter: e.occurrence_counter,
                    max_fdc: e.max_fdc,
                },
                e.entry.as_ref().map(|x| {
                    (
                        x.stored_seq,
                        x.stored_time_s,
                        x.freeze_frame.iter().map(|(s, v)| (s.as_str(), *v)),
                    )
                }),
            );
        }
    }

    /// Decodes an encoding made by [`MemoryImage::encode`] (or
    /// [`EventMemory::encode_image`]). Every problem is an [`ImageError`] with the byte
    /// offset of the field that is wrong; nothing is allocated beyond what the input can hold.
    pub fn decode(bytes: &[u8]) -> Result<MemoryImage, ImageError> {
        let mut r = Reader {
            bytes,
            pos: 0,
            event: None,
        };
        let magic = r.take(4, "magic")?;
        if magic != IMAGE_MAGIC {
            let mut found = [0u8; 4];
            found.copy_from_slice(magic);
            return Err(r.error_at(0, ImageErrorKind::BadMagic { found }));
        }
        let at = r.pos;
        let version = r.u16("format version")?;
        if version != IMAGE_FORMAT_VERSION {
            return Err(r.error_at(at, ImageErrorKind::UnsupportedVersion(version)));
        }
        let next_seq = r.u64("next storage seq")?;
        let operation_cycles_started = r.u64("operation cycles started")?;
        let overflow = r.flag("overflow flag")?;
        let overflow_count = r.u32("overflow count")?;
        let n = r.count("event count", MIN_EVENT_BYTES)?;
        let mut events = Vec::with_capacity(n);
        for i in 0..n {
            r.event = Some(i);
            let name = r.string("event name")?;
            let at = r.pos;
            let raw = r.u32("DTC")?;
            let dtc = Dtc::from_u32(raw)
                .map_err(|_| r.error_at(at, ImageErrorKind::DtcOutOfRange(raw)))?;
            let status = DtcStatus::from_byte(r.u8("status byte")?);
            let failed_cycles = r.u8("failed cycles")?;
            let healing_cycles = r.u8("healing cycles")?;
            let aging_counter = r.u8("aging counter")?;
            let occurrence_counter = r.u8("occurrence counter")?;
            let max_fdc = i8::from_le_bytes([r.u8("max FDC")?]);
            let entry = if r.flag("entry flag")? {
                let stored_seq = r.u64("entry storage seq")?;
                let stored_time_s = r.f64("entry stored time")?;
                let m = r.count("freeze-frame signal count", MIN_SIGNAL_BYTES)?;
                let mut freeze_frame = Vec::with_capacity(m);
                for _ in 0..m {
                    let signal = r.string("freeze-frame signal name")?;
                    let value = r.f64("freeze-frame value")?;
                    freeze_frame.push((signal, value));
                }
                Some(EntryImage {
                    stored_seq,
                    stored_time_s,
                    freeze_frame,
                })
            } else {
                None
            };
            events.push(EventImage {
                name,
                dtc,
                status,
                failed_cycles,
                healing_cycles,
                aging_counter,
                occurrence_counter,
                max_fdc,
                entry,
            });
        }
        r.event = None;
        if r.pos != bytes.len() {
            let left = bytes.len() - r.pos;
            return Err(r.error_at(r.pos, ImageErrorKind::TrailingBytes(left)));
        }
        Ok(MemoryImage {
            next_seq,
            overflow,
            overflow_count,
            operation_cycles_started,
            events,
        })
    }
}

// ------------------------------------------------------------------------------ encoding

struct EventRecord<'a> {
    name: &'a str,
    dtc: Dtc,
    status: DtcStatus,
    failed_cycles: u8,
    healing_cycles: u8,
    aging_counter: u8,
    occurrence_counter: u8,
    max_fdc: i8,
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8 & 0x7F) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn put_str(out: &mut Vec<u8>, s: &str) {
    put_varint(out, s.len() as u64);
    out.extend_from_slice(s.as_bytes());
}

fn put_header(
    out: &mut Vec<u8>,
    next_seq: u64,
    cycles: u64,
    overflow: bool,
    overflow_count: u32,
    n_events: usize,
) {
    out.extend_from_slice(&IMAGE_MAGIC);
    out.extend_from_slice(&IMAGE_FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&next_seq.to_le_bytes());
    out.extend_from_slice(&cycles.to_le_bytes());
    out.push(u8::from(overflow));
    out.extend_from_slice(&overflow_count.to_le_bytes());
    put_varint(out, n_events as u64);
}

fn put_event<'a, I>(out: &mut Vec<u8>, e: EventRecord<'_>, entry: Option<(u64, f64, I)>)
where
    I: ExactSizeIterator<Item = (&'a str, f64)>,
{
    put_str(out, e.name);
    out.extend_from_slice(&e.dtc.to_u32().to_le_bytes());
    out.extend_from_slice(&[
        e.status.byte(),
        e.failed_cycles,
        e.healing_cycles,
        e.aging_counter,
        e.occurrence_counter,
    ]);
    out.extend_from_slice(&e.max_fdc.to_le_bytes());
    match entry {
        None => out.push(0),
        Some((seq, time_s, ff)) => {
            out.push(1);
            out.extend_from_slice(&seq.to_le_bytes());
            out.extend_from_slice(&time_s.to_bits().to_le_bytes());
            put_varint(out, ff.len() as u64);
            for (signal, value) in ff {
                put_str(out, signal);
                out.extend_from_slice(&value.to_bits().to_le_bytes());
            }
        }
    }
}

// ------------------------------------------------------------------------------ decoding

/// Why [`MemoryImage::decode`] refused its input, and where.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub struct ImageError {
    /// Byte offset of the field that is wrong (for a truncation: where the field starts).
    pub offset: usize,
    /// Index of the event record being read, if the problem is inside one.
    pub event: Option<usize>,
    /// What is wrong.
    pub kind: ImageErrorKind,
}

impl fmt::Display for ImageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "memory image: {} at byte {}", self.kind, self.offset)?;
        if let Some(i) = self.event {
            write!(f, " (event record {i})")?;
        }
        Ok(())
    }
}

/// What is wrong in an encoded [`MemoryImage`].
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ImageErrorKind {
    /// The input does not start with [`IMAGE_MAGIC`].
    #[error("bad magic {found:02X?} (expected \"FDEM\")")]
    BadMagic {
        /// The first four bytes.
        found: [u8; 4],
    },
    /// A format version this build cannot read.
    #[error("unsupported format version {0} (this build reads version {IMAGE_FORMAT_VERSION})")]
    UnsupportedVersion(u16),
    /// The input ends inside a field.
    #[error("truncated: {field} needs {needed} bytes but only {available} are left")]
    Truncated {
        /// The field.
        field: &'static str,
        /// Bytes the field needs (for a count: the least its items can take).
        needed: u64,
        /// Bytes left in the input.
        available: usize,
    },
    /// A varint longer than 10 bytes or above `u64::MAX`.
    #[error("malformed {field} (varint longer than 10 bytes or above 2^64 - 1)")]
    BadVarint {
        /// The field.
        field: &'static str,
    },
    /// A string that is not UTF-8.
    #[error("{field} is not valid UTF-8")]
    InvalidUtf8 {
        /// The field.
        field: &'static str,
    },
    /// A flag byte other than 0 or 1.
    #[error("{field} is {value}, expected 0 or 1")]
    InvalidFlag {
        /// The field.
        field: &'static str,
        /// The byte found.
        value: u8,
    },
    /// A DTC value above the 3-byte UDS range.
    #[error("DTC value 0x{0:X} is above 0xFFFFFF")]
    DtcOutOfRange(u32),
    /// Bytes after the last event record.
    #[error("{0} trailing bytes after the last event record")]
    TrailingBytes(usize),
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    event: Option<usize>,
}

impl<'a> Reader<'a> {
    fn error_at(&self, offset: usize, kind: ImageErrorKind) -> ImageError {
        ImageError {
            offset,
            event: self.event,
            kind,
        }
    }

    fn left(&self) -> usize {
        self.bytes.len().saturating_sub(self.pos)
    }

    fn take(&mut self, n: u64, field: &'static str) -> Result<&'a [u8], ImageError> {
        let available = self.left();
        match usize::try_from(n) {
            Ok(n) if n <= available => {
                let s = &self.bytes[self.pos..self.pos + n];
                self.pos += n;
                Ok(s)
            }
            _ => Err(self.error_at(
                self.pos,
                ImageErrorKind::Truncated {
                    field,
                    needed: n,
                    available,
                },
            )),
        }
    }

    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], ImageError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N as u64, field)?);
        Ok(a)
    }

    fn u8(&mut self, field: &'static str) -> Result<u8, ImageError> {
        Ok(self.array::<1>(field)?[0])
    }

    fn u16(&mut self, field: &'static str) -> Result<u16, ImageError> {
        self.array(field).map(u16::from_le_bytes)
    }

    fn u32(&mut self, field: &'static str) -> Result<u32, ImageError> {
        self.array(field).map(u32::from_le_bytes)
    }

    fn u64(&mut self, field: &'static str) -> Result<u64, ImageError> {
        self.array(field).map(u64::from_le_bytes)
    }

    fn f64(&mut self, field: &'static str) -> Result<f64, ImageError> {
        self.u64(field).map(f64::from_bits)
    }

    fn flag(&mut self, field: &'static str) -> Result<bool, ImageError> {
        let at = self.pos;
        match self.u8(field)? {
            0 => Ok(false),
            1 => Ok(true),
            value => Err(self.error_at(at, ImageErrorKind::InvalidFlag { field, value })),
        }
    }

    fn varint(&mut self, field: &'static str) -> Result<u64, ImageError> {
        let at = self.pos;
        let mut v: u64 = 0;
        for i in 0..10 {
            let b = self.u8(field)?;
            let group = u64::from(b & 0x7F);
            // The 10th byte may only hold the top bit of a u64.
            if i == 9 && group > 1 {
                break;
            }
            v |= group << (7 * i);
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(self.error_at(at, ImageErrorKind::BadVarint { field }))
    }

    /// A count of items that take at least `min_item` bytes each: refused (as a truncation)
    /// when the rest of the input cannot hold that many, so the caller may allocate it.
    fn count(&mut self, field: &'static str, min_item: usize) -> Result<usize, ImageError> {
        let at = self.pos;
        let n = self.varint(field)?;
        let available = self.left();
        let fits = usize::try_from(n)
            .ok()
            .filter(|&n| n <= available / min_item);
        fits.ok_or_else(|| {
            self.error_at(
                at,
                ImageErrorKind::Truncated {
                    field,
                    needed: n.saturating_mul(min_item as u64),
                    available,
                },
            )
        })
    }

    fn string(&mut self, field: &'static str) -> Result<String, ImageError> {
        let n = self.varint(field)?;
        let at = self.pos;
        let raw = self.take(n, field)?;
        match std::str::from_utf8(raw) {
            Ok(s) => Ok(s.to_owned()),
            Err(_) => Err(self.error_at(at, ImageErrorKind::InvalidUtf8 { field })),
        }
    }
}

// ------------------------------------------------------------------------------ restore

/// What [`EventMemory::restore`] did with an image.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RestoreReport {
    /// Events whose status byte and counters were restored.
    pub restored_events: usize,
    /// Memory entries restored (with or without their freeze-frame values).
    pub restored_entries: usize,
    /// What was not restored, and why, in image order.
    pub dropped: Vec<Dropped>,
    /// Configured events the image had no valid record of: they start as after ClearDTC
    /// (`0x50`), like a newly added event.
    pub not_in_image: Vec<EventId>,
}

impl RestoreReport {
    /// True when every record of the image was restored completely.
    pub fn nothing_dropped(&self) -> bool {
        self.dropped.is_empty()
    }
}

/// One event record (or part of it) that [`EventMemory::restore`] did not restore.
#[derive(Debug, Clone, PartialEq)]
pub struct Dropped {
    /// The event name in the image.
    pub name: String,
    /// The DTC in the image.
    pub dtc: Dtc,
    /// Why, and how much was dropped.
    pub reason: DropReason,
}

impl fmt::Display for Dropped {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "event {:?} ({}): {}", self.name, self.dtc, self.reason)
    }
}

/// Why (part of) an event record was not restored.
#[derive(Debug, Clone, PartialEq)]
pub enum DropReason {
    /// No configured event has this name. Everything of the record is dropped.
    NotConfigured,
    /// The configured event of this name has another DTC. Everything of the record is dropped:
    /// a status byte and freeze frame belong to the DTC a tester read them under.
    DtcChanged {
        /// The DTC configured now.
        configured: Dtc,
    },
    /// An earlier record of the image has the same name. This record is dropped.
    DuplicateInImage,
    /// The entry's freeze-frame signals (names or order) differ from the configured ones.
    /// Status, counters and the entry (its storage order and time) are restored; its
    /// freeze-frame values are not (they read as missing, as for a report without values).
    FreezeFrameChanged {
        /// The signals in the image.
        persisted: Vec<String>,
    },
    /// The image has more entries than the memory's capacity. This entry (lower priority,
    /// or among equal priorities older) is not restored; the event's status byte and counters
    /// are, and the lost entry counts as an overflow (as a new entry meeting a full memory).
    CapacityExceeded {
        /// The configured capacity.
        capacity: usize,
    },
}

impl fmt::Display for DropReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DropReason::NotConfigured => {
                write!(f, "no longer configured; status, counters and entry dropped")
            }
            DropReason::DtcChanged { configured } => write!(
                f,
                "DTC changed to {configured}; status, counters and entry dropped"
            ),
            DropReason::DuplicateInImage => {
                write!(f, "listed twice in the image; the later record dropped")
            }
            DropReason::FreezeFrameChanged { persisted } => write!(
                f,
                "freeze-frame signals changed (image has {persisted:?}); values dropped, status, counters and entry kept"
            ),
            DropReason::CapacityExceeded { capacity } => write!(
                f,
                "entry does not fit the capacity of {capacity}; entry dropped, status and counters kept"
            ),
        }
    }
}

impl EventMemory {
    /// The state that must survive a power cycle (see [`MemoryImage`]). Allocates the image;
    /// [`EventMemory::encode_image`] writes the same bytes without building it.
    pub fn image(&self) -> MemoryImage {
        let events = self
            .defs
            .iter()
            .zip(&self.states)
            .map(|(d, s)| EventImage {
                name: d.name.clone(),
                dtc: d.dtc,
                status: s.status,
                failed_cycles: s.failed_cycles,
                healing_cycles: s.healing_cycles,
                aging_counter: s.aging_counter,
                occurrence_counter: s.occurrence_counter,
                max_fdc: s.max_fdc,
                entry: self.slot_entry(s.slot).map(|(e, values)| EntryImage {
                    stored_seq: e.seq,
                    stored_time_s: e.stored_time_s,
                    freeze_frame: d
                        .freeze_frame
                        .iter()
                        .cloned()
                        .zip(values.iter().copied())
                        .collect(),
                }),
            })
            .collect();
        MemoryImage {
            next_seq: self.next_seq,
            overflow: self.overflow,
            overflow_count: self.overflow_count,
            operation_cycles_started: self.cycles_started,
            events,
        }
    }

    /// Appends the encoding of [`EventMemory::image`] to `out` without building the image:
    /// allocates nothing once `out` is large enough.
    pub fn encode_image(&self, out: &mut Vec<u8>) {
        put_header(
            out,
            self.next_seq,
            self.cycles_started,
            self.overflow,
            self.overflow_count,
            self.defs.len(),
        );
        for (d, s) in self.defs.iter().zip(&self.states) {
            put_event(
                out,
                EventRecord {
                    name: &d.name,
                    dtc: d.dtc,
                    status: s.status,
                    failed_cycles: s.failed_cycles,
                    healing_cycles: s.healing_cycles,
                    aging_counter: s.aging_counter,
                    occurrence_counter: s.occurrence_counter,
                    max_fdc: s.max_fdc,
                },
                self.slot_entry(s.slot).map(|(e, values)| {
                    (
                        e.seq,
                        e.stored_time_s,
                        d.freeze_frame
                            .iter()
                            .map(String::as_str)
                            .zip(values.iter().copied()),
                    )
                }),
            );
        }
    }

    /// The entry in slot `slot` and its freeze-frame values (the slot's whole stride; zip with
    /// the event's signals).
    fn slot_entry(&self, slot: Option<u16>) -> Option<(Entry, &[f64])> {
        let k = slot? as usize;
        let e = (*self.slots.get(k)?)?;
        let base = k * self.ff_stride;
        Some((e, self.ff.get(base..base + self.ff_stride)?))
    }

    /// Restores a persisted image into this memory, which should be freshly built from the
    /// current configuration, before any operation cycle (whatever state it had is replaced).
    ///
    /// An image record is restored when an event of the same name with the same DTC is
    /// configured; everything else is listed in [`RestoreReport::dropped`] with its
    /// [`DropReason`] (freeze-frame signals changed: values dropped, the rest kept; more
    /// entries than the capacity: the highest priority and, among equal priorities, the latest
    /// stored are kept). Configured events without a record start at `0x50`.
    ///
    /// Status bytes are restored as persisted (a confirmed `0x2F` stays `0x2F`); the next
    /// [`EventMemory::start_operation_cycle`] applies the usual cycle-start rules. Debouncers
    /// are reset, no cycle is running, and the time check starts over: the first call may use
    /// any finite time, as the host's clock restarts at power-up.
    pub fn restore(&mut self, image: &MemoryImage) -> RestoreReport {
        for st in &mut self.states {
            st.reset();
            st.slot = None;
        }
        self.slots.fill(None);
        self.ff.fill(f64::NAN);
        self.cycle_active = false;
        self.last_time_s = f64::NEG_INFINITY;
        self.next_seq = image.next_seq;
        self.cycles_started = image.operation_cycles_started;
        self.overflow = image.overflow;
        self.overflow_count = image.overflow_count;

        let mut report = RestoreReport::default();
        let mut seen = vec![false; self.defs.len()];
        // (event index, entry, whether its freeze-frame values can be restored)
        let mut entries: Vec<(usize, &EntryImage, bool)> = Vec::new();
        for rec in &image.events {
            let drop = |reason| Dropped {
                name: rec.name.clone(),
                dtc: rec.dtc,
                reason,
            };
            let Some(i) = self.defs.iter().position(|d| d.name == rec.name) else {
                report.dropped.push(drop(DropReason::NotConfigured));
                continue;
            };
            let def = &self.defs[i];
            if def.dtc != rec.dtc {
                report.dropped.push(drop(DropReason::DtcChanged {
                    configured: def.dtc,
                }));
                continue;
            }
            if seen[i] {
                report.dropped.push(drop(DropReason::DuplicateInImage));
                continue;
            }
            seen[i] = true;
            let st = &mut self.states[i];
            st.status = rec.status;
            st.failed_cycles = rec.failed_cycles;
            st.healing_cycles = rec.healing_cycles;
            st.aging_counter = rec.aging_counter;
            st.occurrence_counter = rec.occurrence_counter;
            st.max_fdc = rec.max_fdc;
            report.restored_events += 1;
            if let Some(e) = &rec.entry {
                let same_signals = e.freeze_frame.len() == def.freeze_frame.len()
                    && e.freeze_frame
                        .iter()
                        .zip(&def.freeze_frame)
                        .all(|((a, _), b)| a == b);
                if !same_signals {
                    report.dropped.push(drop(DropReason::FreezeFrameChanged {
                        persisted: e.freeze_frame.iter().map(|(s, _)| s.clone()).collect(),
                    }));
                }
                entries.push((i, e, same_signals));
            }
        }

        let capacity = self.slots.len();
        if entries.len() > capacity {
            // Highest priority (smallest number) first, then latest stored.
            entries.sort_by(|a, b| {
                let (pa, pb) = (self.defs[a.0].priority, self.defs[b.0].priority);
                pa.cmp(&pb).then(b.1.stored_seq.cmp(&a.1.stored_seq))
            });
            for (i, _, _) in entries.drain(capacity..) {
                report.dropped.push(Dropped {
                    name: self.defs[i].name.clone(),
                    dtc: self.defs[i].dtc,
                    reason: DropReason::CapacityExceeded { capacity },
                });
                self.overflow = true;
                self.overflow_count = self.overflow_count.saturating_add(1);
            }
        }
        entries.sort_by_key(|(_, e, _)| e.stored_seq);
        for (k, (i, e, same_signals)) in entries.into_iter().enumerate() {
            self.slots[k] = Some(Entry {
                event: i as u16,
                seq: e.stored_seq,
                stored_time_s: e.stored_time_s,
            });
            self.states[i].slot = Some(k as u16);
            if same_signals {
                let base = k * self.ff_stride;
                for (dst, (_, v)) in self.ff[base..base + self.ff_stride]
                    .iter_mut()
                    .zip(&e.freeze_frame)
                {
                    *dst = *v;
                }
            }
            // Keep "next entry is the latest" even for a hand-made image.
            self.next_seq = self.next_seq.max(e.stored_seq.saturating_add(1));
            report.restored_entries += 1;
        }
        report.not_in_image = (0..self.defs.len())
            .filter(|&i| !seen[i])
            .map(|i| EventId(i as u16))
            .collect();
        report
    }
}
