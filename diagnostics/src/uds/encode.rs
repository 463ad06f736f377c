//! Positive (and negative) response encoders. Each one *appends* to `out`, so a host can put
//! the response after its own header; [`super::handle_request`] clears `out` first. A function
//! that returns `Err` leaves `out` as it was.

use crate::dtc::Dtc;

use super::{
    DtcStore, Nrc, ReportType, SnapshotValue, ALL_RECORDS, DTC_FORMAT_IDENTIFIER,
    EXT_AGING_COUNTER, EXT_MAX_FDC, EXT_OCCURRENCE_COUNTER, MAX_SNAPSHOT_IDENTIFIERS,
    POSITIVE_RESPONSE_OFFSET, SID_NEGATIVE_RESPONSE, SID_READ_DTC_INFORMATION,
    SNAPSHOT_RECORD_NUMBER,
};

const RESPONSE_SID: u8 = SID_READ_DTC_INFORMATION + POSITIVE_RESPONSE_OFFSET;

fn push_dtc(out: &mut Vec<u8>, dtc: Dtc) {
    let [_, h, m, l] = dtc.to_u32().to_be_bytes();
    out.extend_from_slice(&[h, m, l]);
}

fn header(out: &mut Vec<u8>, report: ReportType) {
    out.extend_from_slice(&[RESPONSE_SID, report.byte()]);
}

/// A snapshot value as sent: IEEE-754 binary32, big-endian. NaN (a value that was not
/// available) is always the quiet NaN `7F C0 00 00`; magnitudes beyond the binary32 range
/// become infinities, and precision drops to about 7 significant digits.
pub fn encode_snapshot_value(value: f64) -> [u8; 4] {
    let v = if value.is_nan() {
        f32::NAN
    } else {
        value as f32
    };
    v.to_be_bytes()
}

/// `7F sid nrc`.
pub fn encode_negative_response(sid: u8, nrc: Nrc, out: &mut Vec<u8>) {
    out.extend_from_slice(&[SID_NEGATIVE_RESPONSE, sid, nrc.code()]);
}

/// `59 01 avail 00 count(2)`: how many DTCs have `status & avail & mask != 0` (saturating at
/// 65535), with format [`DTC_FORMAT_IDENTIFIER`].
pub fn encode_number_of_dtcs_by_status_mask(store: &dyn DtcStore, mask: u8, out: &mut Vec<u8>) {
    let avail = store.status_availability_mask();
    let mut count: u16 = 0;
    store.for_each_dtc(&mut |_, status| {
        if status.byte() & avail & mask != 0 {
            count = count.saturating_add(1);
        }
    });
    header(out, ReportType::NumberOfDtcByStatusMask);
    out.extend_from_slice(&[avail, DTC_FORMAT_IDENTIFIER]);
    out.extend_from_slice(&count.to_be_bytes());
}

/// `59 02 avail {DTC status}`: every DTC with `status & avail & mask != 0` (status reported
/// as `status & avail`), in the store's order. Mask `0x00` matches nothing.
pub fn encode_dtcs_by_status_mask(store: &dyn DtcStore, mask: u8, out: &mut Vec<u8>) {
    let avail = store.status_availability_mask();
    header(out, ReportType::DtcByStatusMask);
    out.push(avail);
    store.for_each_dtc(&mut |dtc, status| {
        let st = status.byte() & avail;
        if st & mask != 0 {
            push_dtc(out, dtc);
            out.push(st);
        }
    });
}

/// `59 0A avail {DTC status}`: every configured DTC, whatever its status.
pub fn encode_supported_dtcs(store: &dyn DtcStore, out: &mut Vec<u8>) {
    let avail = store.status_availability_mask();
    header(out, ReportType::SupportedDtc);
    out.push(avail);
    store.for_each_dtc(&mut |dtc, status| {
        push_dtc(out, dtc);
        out.push(status.byte() & avail);
    });
}

/// `59 03 {DTC 01}`: every DTC that has a snapshot record (a memory entry with at least one
/// value). Calls [`DtcStore::snapshot`] once per DTC, so it costs a lookup per DTC.
pub fn encode_snapshot_identification(store: &dyn DtcStore, out: &mut Vec<u8>) {
    header(out, ReportType::SnapshotIdentification);
    store.for_each_dtc(&mut |dtc, _| {
        let mut has_values = false;
        let _ = store.snapshot(dtc, &mut |_| has_values = true);
        if has_values {
            push_dtc(out, dtc);
            out.push(SNAPSHOT_RECORD_NUMBER);
        }
    });
}

/// `59 04 DTC status [01 n {DID value(4)}]` for `record` [`SNAPSHOT_RECORD_NUMBER`] or
/// [`ALL_RECORDS`]; the record part is absent when the DTC has none. Values are encoded by
/// [`encode_snapshot_value`]; at most [`MAX_SNAPSHOT_IDENTIFIERS`] are written.
///
/// `Err(RequestOutOfRange)` for another record number or a DTC the store does not hold.
pub fn encode_snapshot_records(
    store: &dyn DtcStore,
    dtc: Dtc,
    record: u8,
    out: &mut Vec<u8>,
) -> Result<(), Nrc> {
    if record != SNAPSHOT_RECORD_NUMBER && record != ALL_RECORDS {
        return Err(Nrc::RequestOutOfRange);
    }
    let avail = store.status_availability_mask();
    let start = out.len();
    header(out, ReportType::SnapshotRecordByDtcNumber);
    push_dtc(out, dtc);
    let status_at = out.len();
    out.push(0); // status, known once the store has answered
    let count_at = out.len() + 1;
    let mut count = 0usize;
    let status = store.snapshot(dtc, &mut |v: SnapshotValue| {
        if count == MAX_SNAPSHOT_IDENTIFIERS {
            return;
        }
        if count == 0 {
            out.extend_from_slice(&[SNAPSHOT_RECORD_NUMBER, 0]);
        }
        out.extend_from_slice(&v.did.to_be_bytes());
        out.extend_from_slice(&encode_snapshot_value(v.value));
        count += 1;
    });
    let Some(status) = status else {
        out.truncate(start);
        return Err(Nrc::RequestOutOfRange);
    };
    out[status_at] = status.byte() & avail;
    if count > 0 {
        // count <= MAX_SNAPSHOT_IDENTIFIERS = 255.
        out[count_at] = count as u8;
    }
    Ok(())
}

/// `59 06 DTC status {record data}` for `record` [`EXT_OCCURRENCE_COUNTER`],
/// [`EXT_AGING_COUNTER`], [`EXT_MAX_FDC`] or [`ALL_RECORDS`] (all three, in that order); no
/// records when the DTC has no memory entry.
///
/// `Err(RequestOutOfRange)` for another record number or a DTC the store does not hold.
pub fn encode_ext_data_records(
    store: &dyn DtcStore,
    dtc: Dtc,
    record: u8,
    out: &mut Vec<u8>,
) -> Result<(), Nrc> {
    if !matches!(
        record,
        EXT_OCCURRENCE_COUNTER | EXT_AGING_COUNTER | EXT_MAX_FDC | ALL_RECORDS
    ) {
        return Err(Nrc::RequestOutOfRange);
    }
    let data = store.extended_data(dtc).ok_or(Nrc::RequestOutOfRange)?;
    let avail = store.status_availability_mask();
    header(out, ReportType::ExtDataRecordByDtcNumber);
    push_dtc(out, dtc);
    out.push(data.status.byte() & avail);
    if data.stored {
        let records = [
            (EXT_OCCURRENCE_COUNTER, data.occurrence_counter),
            (EXT_AGING_COUNTER, data.aging_counter),
            (EXT_MAX_FDC, data.max_fdc.to_be_bytes()[0]),
        ];
        for (number, byte) in records {
            if record == ALL_RECORDS || record == number {
                out.extend_from_slice(&[number, byte]);
            }
        }
    }
    Ok(())
}
