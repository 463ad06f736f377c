//! The UDS (ISO 14229-1) DTC services as pure logic: ReadDTCInformation (`0x19`) and
//! ClearDiagnosticInformation (`0x14`), answered from any [`DtcStore`].
//!
//! A diagnostic tester talks to fdd in request/response byte strings (the payload of an ISO-TP
//! or DoIP message, starting with the service id). [`handle_request`] parses one request and
//! writes the positive or negative response into a caller-owned `Vec<u8>`; the `encode_*`
//! functions build the positive responses directly, for a host that has already parsed the
//! request. None of them allocate beyond growing that `Vec` (reserve the transport's largest
//! message, 4095 bytes for ISO-TP, and a response that fits allocates nothing), and none keep
//! state: the DTC data come from
//! the [`DtcStore`] the caller passes, so the runtime can answer from several event memories at
//! once ([`EventMemoryStore`] is the reference implementation over one [`EventMemory`]).
//!
//! # Services and byte formats
//!
//! Multi-byte values are big-endian. `DTC` is the 3-byte UDS DTC (`P0123-1C` = `01 23 1C`, see
//! [`Dtc::to_u32`]); `st` its status byte ANDed with the DTCStatusAvailabilityMask `avail`.
//!
//! | request | positive response |
//! |---|---|
//! | `19 01 mask` reportNumberOfDTCByStatusMask | `59 01 avail 00 nn nn`: format [`DTC_FORMAT_IDENTIFIER`], then the number of DTCs with `st & mask != 0` (u16, saturating) |
//! | `19 02 mask` reportDTCByStatusMask | `59 02 avail` then `DTC st` for every DTC with `st & mask != 0` |
//! | `19 03` reportDTCSnapshotIdentification | `59 03` then `DTC 01` for every DTC that has a snapshot record |
//! | `19 04 DTC rec` reportDTCSnapshotRecordByDTCNumber, `rec` = `01` or `FF` (all) | `59 04 DTC st`, then if the DTC has a record: `01 n` and `n` times `DID(2) value(4)` |
//! | `19 06 DTC rec` reportDTCExtDataRecordByDTCNumber, `rec` = `01`-`03` or `FF` (all) | `59 06 DTC st`, then if the DTC has a memory entry: `rec data(1)` for each record asked for |
//! | `19 0A` reportSupportedDTC | `59 0A avail` then `DTC st` for every configured DTC |
//! | `14 group(3)` ClearDiagnosticInformation, `FF FF FF` = all DTCs, else one DTC | `54` |
//!
//! **Snapshot record** ([`SNAPSHOT_RECORD_NUMBER`] `0x01`, the only one fdd stores): the freeze
//! frame captured with the DTC's memory entry. Each value is a 2-byte DID followed by the value
//! as IEEE-754 binary32, big-endian, in the signal's own unit (V, rpm, deg, ... as configured);
//! a value that was not available is the quiet NaN `7F C0 00 00` ([`encode_snapshot_value`]).
//! A DTC without an entry, or whose entry has no freeze-frame signals, has no record: `19 03`
//! does not list it and `19 04` answers with `DTC st` alone (a record with zero identifiers
//! would be malformed). At most [`MAX_SNAPSHOT_IDENTIFIERS`] values fit in a record (the count
//! is one byte); further ones are not reported. How DIDs are assigned is the store's business;
//! [`EventMemoryStore`] numbers the distinct freeze-frame signals from `0xFD00` (below).
//!
//! **Extended data records**, one byte each, present only while the DTC has a memory entry
//! (AUTOSAR Dem keeps them in the entry; after displacement, aging or clear there is nothing):
//!
//! | record | content |
//! |---|---|
//! | [`EXT_OCCURRENCE_COUNTER`] `0x01` | occurrence counter: qualified failures (testFailed 0 -> 1) since the last clear, aging or loss of the entry, saturating at 255 |
//! | [`EXT_AGING_COUNTER`] `0x02` | aging counter: passed operation cycles counted towards erasing the entry |
//! | [`EXT_MAX_FDC`] `0x03` | largest fault detection counter since the last clear, -128..127 as two's complement (`7F` = qualified failed) |
//!
//! # Freeze-frame DIDs
//!
//! ISO 14229-1 wants a DID to mean the same thing wherever it appears in an ECU, so a DID names
//! a *signal*, not a position in one event's freeze frame. [`EventMemoryStore`] gives the
//! distinct freeze-frame signal names of its memory, in order of first appearance (events in
//! configuration order, each event's `freeze_frame` list in order), the DIDs
//! [`FREEZE_FRAME_DID_BASE`] `0xFD00`, `0xFD01`, ... (the range ISO 14229-1 Annex C leaves to
//! the system supplier ends at [`FREEZE_FRAME_DID_LAST`] `0xFEFF`; signals past the 512th get
//! no DID and are not reported). Two events that both capture `tps_a_v` report it under the
//! same DID. [`freeze_frame_dids`] lists the table (e.g. for a tester's description file);
//! [`freeze_frame_did`] looks one signal up.
//!
//! # Negative responses
//!
//! `7F SID NRC`, checked in the ISO 14229-1 order (service, minimum length, sub-function,
//! exact length, parameters):
//!
//! - `0x11` serviceNotSupported: any service but `0x19` and `0x14`;
//! - `0x13` incorrectMessageLengthOrInvalidFormat: `19` without a sub-function, or a request
//!   longer or shorter than its sub-function's format above (`14` must be exactly 4 bytes; the
//!   2020 memory-selection byte is not supported);
//! - `0x12` subFunctionNotSupported: any other sub-function, including one with the
//!   suppressPosRspMsgIndicationBit (bit 7) set: a read is pointless without its response;
//! - `0x31` requestOutOfRange: a DTC or group the store does not hold, or a record number fdd
//!   does not store;
//! - `0x22` conditionsNotCorrect / `0x72` generalProgrammingFailure: a clear the store refused
//!   ([`ClearRefused`]).
//!
//! An empty request has no service id to answer to and gets no response ([`Reply::NoResponse`],
//! empty `Vec`).

mod encode;
mod memory_store;

use thiserror::Error;

use crate::dtc::{Dtc, DtcCode, DtcGroup, DtcStatus};

pub use encode::{
    encode_dtcs_by_status_mask, encode_ext_data_records, encode_negative_response,
    encode_number_of_dtcs_by_status_mask, encode_snapshot_identification, encode_snapshot_records,
    encode_snapshot_value, encode_supported_dtcs,
};
pub use memory_store::{
    freeze_frame_did, freeze_frame_dids, memory_clear, memory_extended_data, memory_snapshot,
    EventMemoryStore, FREEZE_FRAME_DID_BASE, FREEZE_FRAME_DID_LAST,
};

#[cfg(doc)]
use crate::dtc::EventMemory;

/// ReadDTCInformation.
pub const SID_READ_DTC_INFORMATION: u8 = 0x19;
/// ClearDiagnosticInformation.
pub const SID_CLEAR_DIAGNOSTIC_INFORMATION: u8 = 0x14;
/// First byte of every negative response.
pub const SID_NEGATIVE_RESPONSE: u8 = 0x7F;
/// A positive response's service id is the request's plus this.
pub const POSITIVE_RESPONSE_OFFSET: u8 = 0x40;

/// DTCFormatIdentifier of `59 01`: `0x00` SAE_J2012-DA_DTCFormat_00, the 2-byte SAE J2012
/// code followed by the J2012-DA failure type byte, which is what every fdd [`Dtc`] is
/// (ISO_14229-1_DTCFormat, `0x01`, would declare the three bytes manufacturer-defined, and a
/// tester would not show them as `P0123-1C`).
pub const DTC_FORMAT_IDENTIFIER: u8 = 0x00;
/// groupOfDTC meaning every DTC.
pub const GROUP_ALL_DTCS: u32 = 0x00FF_FFFF;
/// The one snapshot record fdd stores per DTC: the freeze frame of its memory entry.
pub const SNAPSHOT_RECORD_NUMBER: u8 = 0x01;
/// Record number asking for every record (snapshot or extended data).
pub const ALL_RECORDS: u8 = 0xFF;
/// Extended data record: occurrence counter (1 byte).
pub const EXT_OCCURRENCE_COUNTER: u8 = 0x01;
/// Extended data record: aging counter (1 byte).
pub const EXT_AGING_COUNTER: u8 = 0x02;
/// Extended data record: maximum fault detection counter since the last clear (1 byte, signed).
pub const EXT_MAX_FDC: u8 = 0x03;
/// Most values one snapshot record can carry (DTCSnapshotRecordNumberOfIdentifiers is a byte;
/// 0 is not used, see the module documentation).
pub const MAX_SNAPSHOT_IDENTIFIERS: usize = 255;

/// The ReadDTCInformation sub-functions fdd answers (ISO 14229-1 reportType).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ReportType {
    /// `0x01` reportNumberOfDTCByStatusMask.
    NumberOfDtcByStatusMask = 0x01,
    /// `0x02` reportDTCByStatusMask.
    DtcByStatusMask = 0x02,
    /// `0x03` reportDTCSnapshotIdentification.
    SnapshotIdentification = 0x03,
    /// `0x04` reportDTCSnapshotRecordByDTCNumber.
    SnapshotRecordByDtcNumber = 0x04,
    /// `0x06` reportDTCExtDataRecordByDTCNumber.
    ExtDataRecordByDtcNumber = 0x06,
    /// `0x0A` reportSupportedDTC.
    SupportedDtc = 0x0A,
}

impl ReportType {
    /// The sub-function of byte `b`, if fdd supports it (bit 7, suppressPosRspMsgIndicationBit,
    /// must be clear).
    pub const fn from_byte(b: u8) -> Option<Self> {
        match b {
            0x01 => Some(ReportType::NumberOfDtcByStatusMask),
            0x02 => Some(ReportType::DtcByStatusMask),
            0x03 => Some(ReportType::SnapshotIdentification),
            0x04 => Some(ReportType::SnapshotRecordByDtcNumber),
            0x06 => Some(ReportType::ExtDataRecordByDtcNumber),
            0x0A => Some(ReportType::SupportedDtc),
            _ => None,
        }
    }

    /// The sub-function byte.
    pub const fn byte(self) -> u8 {
        self as u8
    }
}

/// A negative response code (ISO 14229-1 Annex A) that fdd sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Error)]
#[repr(u8)]
pub enum Nrc {
    /// `0x11`: the service id is not one fdd answers.
    #[error("serviceNotSupported (0x11)")]
    ServiceNotSupported = 0x11,
    /// `0x12`: the sub-function is not one fdd answers.
    #[error("subFunctionNotSupported (0x12)")]
    SubFunctionNotSupported = 0x12,
    /// `0x13`: the request is shorter or longer than its format.
    #[error("incorrectMessageLengthOrInvalidFormat (0x13)")]
    IncorrectMessageLengthOrInvalidFormat = 0x13,
    /// `0x22`: the store cannot do it now (e.g. a ClearDTC refused while driving).
    #[error("conditionsNotCorrect (0x22)")]
    ConditionsNotCorrect = 0x22,
    /// `0x31`: unknown DTC or group, or a record number fdd does not store.
    #[error("requestOutOfRange (0x31)")]
    RequestOutOfRange = 0x31,
    /// `0x72`: the store failed to erase its (non-volatile) memory.
    #[error("generalProgrammingFailure (0x72)")]
    GeneralProgrammingFailure = 0x72,
}

impl Nrc {
    /// The code byte.
    pub const fn code(self) -> u8 {
        self as u8
    }
}

/// What [`handle_request`] wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reply {
    /// A positive response (`SID + 0x40 ...`).
    Positive,
    /// A negative response `7F SID NRC`.
    Negative(Nrc),
    /// Nothing (an empty request); the response buffer is empty.
    NoResponse,
}

/// One value of a snapshot (freeze-frame) record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SnapshotValue {
    /// Its 2-byte data identifier; the same DID must mean the same signal everywhere in the
    /// ECU (ISO 14229-1 DID rule), whichever DTC's snapshot it appears in.
    pub did: u16,
    /// The value in the signal's unit; NaN when it was not available at capture.
    pub value: f64,
}

/// The extended data of one DTC (see the module documentation for the records).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ExtendedData {
    /// The DTC's status byte (before masking with the availability mask).
    pub status: DtcStatus,
    /// Whether the DTC has a memory entry; without one no record is reported.
    pub stored: bool,
    /// Qualified failures (testFailed 0 -> 1) since the last clear, aging or loss of the entry
    /// (saturating at 255).
    pub occurrence_counter: u8,
    /// Passed operation cycles counted towards aging.
    pub aging_counter: u8,
    /// Largest fault detection counter since the last clear, -128..=127.
    pub max_fdc: i8,
}

/// Why a store refused a ClearDiagnosticInformation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Error)]
pub enum ClearRefused {
    /// The group names one DTC and the store does not hold it (NRC `0x31`).
    #[error("DTC {0} is not configured")]
    UnknownDtc(Dtc),
    /// The store does not support clearing this group (NRC `0x31`).
    #[error("clearing {0:?} is not supported")]
    UnsupportedGroup(DtcGroup),
    /// Not possible now; the text says why (NRC `0x22`).
    #[error("ClearDTC not possible now: {0}")]
    ConditionsNotCorrect(&'static str),
    /// Erasing the stored data failed (NRC `0x72`).
    #[error("erasing the DTC memory failed: {0}")]
    MemoryFailure(&'static str),
}

impl ClearRefused {
    /// The negative response code a tester gets for this refusal.
    pub const fn nrc(&self) -> Nrc {
        match self {
            ClearRefused::UnknownDtc(_) | ClearRefused::UnsupportedGroup(_) => {
                Nrc::RequestOutOfRange
            }
            ClearRefused::ConditionsNotCorrect(_) => Nrc::ConditionsNotCorrect,
            ClearRefused::MemoryFailure(_) => Nrc::GeneralProgrammingFailure,
        }
    }
}

/// Where the UDS services read and clear DTCs. The runtime implements it over its event
/// memories (one per monitor); [`EventMemoryStore`] implements it over one [`EventMemory`].
///
/// Object-safe, and the query methods hand data out through callbacks so that answering a
/// request allocates nothing. Contract:
///
/// - every DTC appears once across the whole store (a DTC names one event);
/// - [`for_each_dtc`](Self::for_each_dtc) visits DTCs in a stable order, which is the order of
///   every list in a response;
/// - a DTC unknown to [`snapshot`](Self::snapshot) and [`extended_data`](Self::extended_data)
///   is unknown to [`clear`](Self::clear) too, and vice versa.
pub trait DtcStore {
    /// The status bits this store supports (ISO 14229-1 DTCStatusAvailabilityMask). fdd
    /// supports all eight: [`DtcStatus::AVAILABILITY_MASK`] (`0xFF`). Reported status bytes are
    /// ANDed with it.
    fn status_availability_mask(&self) -> u8;

    /// Calls `f` with every configured DTC and its status byte, in a stable order
    /// (configuration order).
    fn for_each_dtc(&self, f: &mut dyn FnMut(Dtc, DtcStatus));

    /// The snapshot record ([`SNAPSHOT_RECORD_NUMBER`]) of `dtc`: calls `visit` once per value,
    /// in record order, and returns the DTC's status. `None` if the DTC is not configured (then
    /// `visit` is not called). A configured DTC without a memory entry returns its status
    /// without calling `visit`.
    fn snapshot(&self, dtc: Dtc, visit: &mut dyn FnMut(SnapshotValue)) -> Option<DtcStatus>;

    /// The extended data of `dtc`, `None` if it is not configured.
    fn extended_data(&self, dtc: Dtc) -> Option<ExtendedData>;

    /// ClearDiagnosticInformation for `group`: resets status (to `0x50`), counters and memory
    /// entries of every DTC in it. Returns how many DTCs were cleared.
    fn clear(&mut self, group: DtcGroup) -> Result<usize, ClearRefused>;
}

/// Answers one UDS request from `store`: clears `response`, then writes the positive response
/// or the negative response `7F SID NRC` into it (see the [module documentation](self) for the
/// formats and the NRC rules). Allocates only if `response` has to grow.
pub fn handle_request(store: &mut dyn DtcStore, request: &[u8], response: &mut Vec<u8>) -> Reply {
    response.clear();
    let Some(&sid) = request.first() else {
        return Reply::NoResponse;
    };
    let result = match sid {
        SID_READ_DTC_INFORMATION => read_dtc_information(&*store, request, response),
        SID_CLEAR_DIAGNOSTIC_INFORMATION => clear_diagnostic_information(store, request, response),
        _ => Err(Nrc::ServiceNotSupported),
    };
    match result {
        Ok(()) => Reply::Positive,
        Err(nrc) => {
            response.clear();
            encode_negative_response(sid, nrc, response);
            Reply::Negative(nrc)
        }
    }
}

/// The DTC of three request bytes (every 3-byte value is a DTC).
fn dtc_of(high: u8, middle: u8, low: u8) -> Dtc {
    Dtc::new(DtcCode::from_u16(u16::from_be_bytes([high, middle])), low)
}

fn read_dtc_information(
    store: &dyn DtcStore,
    request: &[u8],
    out: &mut Vec<u8>,
) -> Result<(), Nrc> {
    let [_, sub_function, params @ ..] = request else {
        return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
    };
    let Some(report) = ReportType::from_byte(*sub_function) else {
        return Err(Nrc::SubFunctionNotSupported);
    };
    match (report, params) {
        (ReportType::NumberOfDtcByStatusMask, &[mask]) => {
            encode_number_of_dtcs_by_status_mask(store, mask, out);
            Ok(())
        }
        (ReportType::DtcByStatusMask, &[mask]) => {
            encode_dtcs_by_status_mask(store, mask, out);
            Ok(())
        }
        (ReportType::SnapshotIdentification, &[]) => {
            encode_snapshot_identification(store, out);
            Ok(())
        }
        (ReportType::SnapshotRecordByDtcNumber, &[h, m, l, record]) => {
            encode_snapshot_records(store, dtc_of(h, m, l), record, out)
        }
        (ReportType::ExtDataRecordByDtcNumber, &[h, m, l, record]) => {
            encode_ext_data_records(store, dtc_of(h, m, l), record, out)
        }
        (ReportType::SupportedDtc, &[]) => {
            encode_supported_dtcs(store, out);
            Ok(())
        }
        _ => Err(Nrc::IncorrectMessageLengthOrInvalidFormat),
    }
}

fn clear_diagnostic_information(
    store: &mut dyn DtcStore,
    request: &[u8],
    out: &mut Vec<u8>,
) -> Result<(), Nrc> {
    let &[_, h, m, l] = request else {
        return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
    };
    let group = if u32::from_be_bytes([0, h, m, l]) == GROUP_ALL_DTCS {
        DtcGroup::All
    } else {
        DtcGroup::Dtc(dtc_of(h, m, l))
    };
    store.clear(group).map_err(|e| e.nrc())?;
    out.push(SID_CLEAR_DIAGNOSTIC_INFORMATION + POSITIVE_RESPONSE_OFFSET);
    Ok(())
}
