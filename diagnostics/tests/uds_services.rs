//! The UDS DTC services (`fdd_diagnostics::uds`) byte for byte.
//!
//! - A known memory (P0122-16 at 0x27, P0123-17 confirmed at 0x2F, P2135-62 untested at 0x50,
//!   with freeze frames) and the hand-computed bytes of every sub-function's response.
//! - Negative responses: wrong length, unknown service and sub-function, unknown DTC or record,
//!   refused clears; ClearDiagnosticInformation of one DTC and of all.
//! - A store over two event memories and a fixed store (availability mask 0x7F, negative max
//!   FDC), the shape the runtime's implementation takes.
//! - Cross-check with the Python `udsoncan` library (`tests/data/decode_uds.py`): it builds the
//!   requests, fdd answers them, and udsoncan decodes the answers (DTC ids, status bytes,
//!   snapshot DIDs and binary32 values, extended data). This test FAILS when python3 or
//!   udsoncan is missing (`python3 -m pip install udsoncan`; CI installs it in `.ci/run`).

use std::io::Write;
use std::process::{Command, Stdio};

use fdd_diagnostics::dtc::{
    DebounceConfig, Dtc, DtcGroup, DtcStatus, EventConfig, EventMemory, EventMemoryConfig,
    ReportContext,
};
use fdd_diagnostics::event::{DiagnosticEvent, Trigger};
use fdd_diagnostics::uds::{
    encode_dtcs_by_status_mask, encode_ext_data_records, encode_snapshot_records,
    encode_snapshot_value, freeze_frame_did, freeze_frame_dids, handle_request, memory_clear,
    memory_extended_data, memory_snapshot, ClearRefused, DtcStore, EventMemoryStore, ExtendedData,
    Nrc, Reply, SnapshotValue,
};
use fdd_diagnostics::{TestResult, Verdict};
use serde_json::{json, Value};

const P0122_16: [u8; 3] = [0x01, 0x22, 0x16];
const P0123_17: [u8; 3] = [0x01, 0x23, 0x17];
const P2135_62: [u8; 3] = [0x21, 0x35, 0x62];

fn dtc(s: &str) -> Dtc {
    s.parse().unwrap()
}

fn result(verdict: Verdict) -> TestResult {
    TestResult {
        value: 1.0,
        min: 0.0,
        max: 0.5,
        verdict,
    }
}

fn event(name: &str, dtc: &str, freeze_frame: &[&str]) -> EventConfig {
    let mut e = EventConfig::new(name, dtc, 2);
    e.debounce = DebounceConfig::MonitorInternal;
    e.freeze_frame = freeze_frame.iter().map(|s| s.to_string()).collect();
    e
}

/// The known memory:
///
/// | event | DTC | status | entry | freeze frame |
/// |---|---|---|---|---|
/// | tps_circuit_low | P0122-16 | 0x27 (first failure) | occurrence 1 | tps_a_v 0.125 V, engine_speed_rpm 812.5 |
/// | tps_circuit_high | P0123-17 | 0x2F (confirmed in the 2nd failed cycle, MIL disabled) | occurrence 2 | tps_a_v 4.875 V, throttle_angle_deg missing |
/// | tps_correlation | P2135-62 | 0x50 (never tested) | none | (throttle_angle_deg) |
///
/// DIDs: tps_a_v 0xFD00, engine_speed_rpm 0xFD01, throttle_angle_deg 0xFD02. The memory's
/// last call is at t = 5 s.
fn known_memory() -> EventMemory {
    let low = event(
        "tps_circuit_low",
        "P0122-16",
        &["tps_a_v", "engine_speed_rpm"],
    );
    let mut high = event(
        "tps_circuit_high",
        "P0123-17",
        &["tps_a_v", "throttle_angle_deg"],
    );
    high.mil.enabled = false;
    let corr = event("tps_correlation", "P2135-62", &["throttle_angle_deg"]);
    let mut mem = EventMemory::new(&EventMemoryConfig {
        capacity: 4,
        events: vec![low, high, corr],
    })
    .unwrap();
    let low = mem.event_id("tps_circuit_low").unwrap();
    let high = mem.event_id("tps_circuit_high").unwrap();
    let ignore = |_: DiagnosticEvent| {};
    let report = |mem: &mut EventMemory, id, v, t: f64, ff: &[f64]| {
        mem.report(
            id,
            &result(v),
            &ReportContext::at(t).with_freeze_frame(ff),
            ignore,
        )
        .unwrap()
        .byte()
    };
    mem.start_operation_cycle(1.0, ignore).unwrap();
    assert_eq!(
        report(&mut mem, high, Verdict::Failed, 1.5, &[4.875, f64::NAN]),
        0x27
    );
    assert_eq!(report(&mut mem, high, Verdict::Passed, 2.0, &[]), 0x26);
    mem.end_operation_cycle(3.0, ignore).unwrap();
    mem.start_operation_cycle(4.0, ignore).unwrap();
    // A new occurrence; the freeze frame keeps the first failure's values.
    assert_eq!(
        report(&mut mem, high, Verdict::Failed, 4.5, &[4.9, 30.0]),
        0x2F
    );
    assert_eq!(
        report(&mut mem, low, Verdict::Failed, 5.0, &[0.125, 812.5]),
        0x27
    );
    mem
}

/// Sends `request` to `store`; returns what `handle_request` said and the response bytes.
fn ask(store: &mut dyn DtcStore, request: &[u8]) -> (Reply, Vec<u8>) {
    let mut response = Vec::with_capacity(4095);
    let reply = handle_request(store, request, &mut response);
    (reply, response)
}

/// Asserts the positive response to `request` is `expected`.
fn positive(store: &mut dyn DtcStore, request: &[u8], expected: &[u8]) {
    let (reply, bytes) = ask(store, request);
    assert_eq!(
        (reply, bytes.as_slice()),
        (Reply::Positive, expected),
        "request {request:02X?}"
    );
}

/// Asserts the response to `request` is `7F SID nrc`.
fn negative(store: &mut dyn DtcStore, request: &[u8], nrc: Nrc) {
    let (reply, bytes) = ask(store, request);
    assert_eq!(
        (reply, bytes.as_slice()),
        (
            Reply::Negative(nrc),
            [0x7F, request[0], nrc.code()].as_slice()
        ),
        "request {request:02X?}"
    );
}

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

#[test]
fn freeze_frame_dids_name_signals_not_positions() {
    let mem = known_memory();
    let table: Vec<(u16, &str)> = freeze_frame_dids(&mem).collect();
    assert_eq!(
        table,
        [
            (0xFD00, "tps_a_v"),
            (0xFD01, "engine_speed_rpm"),
            (0xFD02, "throttle_angle_deg"),
        ]
    );
    assert_eq!(freeze_frame_did(&mem, "throttle_angle_deg"), Some(0xFD02));
    assert_eq!(freeze_frame_did(&mem, "unknown"), None);
}

#[test]
fn snapshot_values_are_big_endian_binary32() {
    assert_eq!(encode_snapshot_value(0.125), [0x3E, 0x00, 0x00, 0x00]);
    assert_eq!(encode_snapshot_value(812.5), [0x44, 0x4B, 0x20, 0x00]);
    assert_eq!(encode_snapshot_value(-2.5), [0xC0, 0x20, 0x00, 0x00]);
    assert_eq!(encode_snapshot_value(0.1), [0x3D, 0xCC, 0xCC, 0xCD]);
    // Missing is always the same quiet NaN, whatever NaN came in.
    assert_eq!(encode_snapshot_value(f64::NAN), [0x7F, 0xC0, 0x00, 0x00]);
    assert_eq!(encode_snapshot_value(-f64::NAN), [0x7F, 0xC0, 0x00, 0x00]);
    assert_eq!(encode_snapshot_value(1e39), [0x7F, 0x80, 0x00, 0x00]);
    assert_eq!(encode_snapshot_value(-1e39), [0xFF, 0x80, 0x00, 0x00]);
}

#[test]
fn read_dtcs_by_status_mask_count_and_supported() {
    let mut mem = known_memory();
    let mut store = EventMemoryStore::new(&mut mem, 6.0, |_| {});
    let s = &mut store;
    let all = cat(&[&P0122_16, &[0x27], &P0123_17, &[0x2F], &P2135_62, &[0x50]]);
    positive(s, &[0x19, 0x02, 0xFF], &cat(&[&[0x59, 0x02, 0xFF], &all]));
    positive(
        s,
        &[0x19, 0x02, 0x08],
        &cat(&[&[0x59, 0x02, 0xFF], &P0123_17, &[0x2F]]),
    );
    positive(
        s,
        &[0x19, 0x02, 0x40],
        &cat(&[&[0x59, 0x02, 0xFF], &P2135_62, &[0x50]]),
    );
    positive(s, &[0x19, 0x02, 0x00], &[0x59, 0x02, 0xFF]);
    positive(s, &[0x19, 0x02, 0x80], &[0x59, 0x02, 0xFF]);
    // Count, DTCFormatIdentifier 0x00 = SAE_J2012-DA_DTCFormat_00.
    positive(
        s,
        &[0x19, 0x01, 0x01],
        &[0x59, 0x01, 0xFF, 0x00, 0x00, 0x02],
    );
    positive(
        s,
        &[0x19, 0x01, 0xFF],
        &[0x59, 0x01, 0xFF, 0x00, 0x00, 0x03],
    );
    positive(
        s,
        &[0x19, 0x01, 0x00],
        &[0x59, 0x01, 0xFF, 0x00, 0x00, 0x00],
    );
    positive(s, &[0x19, 0x0A], &cat(&[&[0x59, 0x0A, 0xFF], &all]));
}

#[test]
fn snapshot_identification_and_records() {
    let mut mem = known_memory();
    let mut store = EventMemoryStore::new(&mut mem, 6.0, |_| {});
    let s = &mut store;
    // P2135-62 has no entry, so no record.
    positive(
        s,
        &[0x19, 0x03],
        &cat(&[&[0x59, 0x03], &P0122_16, &[0x01], &P0123_17, &[0x01]]),
    );
    let low = cat(&[
        &[0x59, 0x04],
        &P0122_16,
        &[0x27, 0x01, 0x02],
        &[0xFD, 0x00, 0x3E, 0x00, 0x00, 0x00], // tps_a_v 0.125 V
        &[0xFD, 0x01, 0x44, 0x4B, 0x20, 0x00], // engine_speed_rpm 812.5
    ]);
    positive(s, &cat(&[&[0x19, 0x04], &P0122_16, &[0xFF]]), &low);
    positive(s, &cat(&[&[0x19, 0x04], &P0122_16, &[0x01]]), &low);
    // The first failure's values (FreezeFrameUpdate::First), tps_a_v under the same DID.
    positive(
        s,
        &cat(&[&[0x19, 0x04], &P0123_17, &[0x01]]),
        &cat(&[
            &[0x59, 0x04],
            &P0123_17,
            &[0x2F, 0x01, 0x02],
            &[0xFD, 0x00, 0x40, 0x9C, 0x00, 0x00], // tps_a_v 4.875 V
            &[0xFD, 0x02, 0x7F, 0xC0, 0x00, 0x00], // throttle_angle_deg missing
        ]),
    );
    positive(
        s,
        &cat(&[&[0x19, 0x04], &P2135_62, &[0xFF]]),
        &cat(&[&[0x59, 0x04], &P2135_62, &[0x50]]),
    );
}

#[test]
fn extended_data_records() {
    let mut mem = known_memory();
    let mut store = EventMemoryStore::new(&mut mem, 6.0, |_| {});
    let s = &mut store;
    let head = cat(&[&[0x59, 0x06], &P0123_17, &[0x2F]]);
    // Occurrence counter 2, aging counter 0, max FDC +127.
    positive(
        s,
        &cat(&[&[0x19, 0x06], &P0123_17, &[0xFF]]),
        &cat(&[&head, &[0x01, 0x02, 0x02, 0x00, 0x03, 0x7F]]),
    );
    for (record, byte) in [(0x01, 0x02), (0x02, 0x00), (0x03, 0x7F)] {
        positive(
            s,
            &cat(&[&[0x19, 0x06], &P0123_17, &[record]]),
            &cat(&[&head, &[record, byte]]),
        );
    }
    positive(
        s,
        &cat(&[&[0x19, 0x06], &P0122_16, &[0x01]]),
        &cat(&[&[0x59, 0x06], &P0122_16, &[0x27, 0x01, 0x01]]),
    );
    // No entry: the DTC and its status, no records.
    positive(
        s,
        &cat(&[&[0x19, 0x06], &P2135_62, &[0xFF]]),
        &cat(&[&[0x59, 0x06], &P2135_62, &[0x50]]),
    );
}

#[test]
fn negative_responses() {
    let mut mem = known_memory();
    let mut store = EventMemoryStore::new(&mut mem, 6.0, |_| {});
    let s = &mut store;
    use Nrc::*;
    // Unknown services.
    negative(s, &[0x22, 0xF1, 0x90], ServiceNotSupported);
    negative(s, &[0x59, 0x02, 0xFF], ServiceNotSupported);
    // Lengths.
    negative(s, &[0x19], IncorrectMessageLengthOrInvalidFormat);
    negative(s, &[0x19, 0x02], IncorrectMessageLengthOrInvalidFormat);
    negative(
        s,
        &[0x19, 0x02, 0xFF, 0x00],
        IncorrectMessageLengthOrInvalidFormat,
    );
    negative(s, &[0x19, 0x01], IncorrectMessageLengthOrInvalidFormat);
    negative(
        s,
        &[0x19, 0x0A, 0xFF],
        IncorrectMessageLengthOrInvalidFormat,
    );
    negative(
        s,
        &[0x19, 0x03, 0x01],
        IncorrectMessageLengthOrInvalidFormat,
    );
    negative(
        s,
        &cat(&[&[0x19, 0x04], &P0122_16]),
        IncorrectMessageLengthOrInvalidFormat,
    );
    negative(
        s,
        &cat(&[&[0x19, 0x06], &P0122_16, &[0xFF, 0x00]]),
        IncorrectMessageLengthOrInvalidFormat,
    );
    negative(
        s,
        &[0x14, 0xFF, 0xFF],
        IncorrectMessageLengthOrInvalidFormat,
    );
    // With the 2020 memory-selection byte: not supported.
    negative(
        s,
        &[0x14, 0xFF, 0xFF, 0xFF, 0x00],
        IncorrectMessageLengthOrInvalidFormat,
    );
    // Sub-functions: unsupported ones, and suppressPosRspMsgIndicationBit; the sub-function is
    // checked before the length.
    negative(s, &[0x19, 0x05, 0x01], SubFunctionNotSupported);
    negative(s, &[0x19, 0x00], SubFunctionNotSupported);
    negative(s, &[0x19, 0x14], SubFunctionNotSupported);
    negative(s, &[0x19, 0x82, 0xFF], SubFunctionNotSupported);
    // Unknown DTC (P0123-18), unsupported record numbers.
    negative(s, &[0x19, 0x04, 0x01, 0x23, 0x18, 0xFF], RequestOutOfRange);
    negative(s, &[0x19, 0x06, 0x01, 0x23, 0x18, 0xFF], RequestOutOfRange);
    for record in [0x00, 0x02, 0x10, 0xFE] {
        negative(
            s,
            &cat(&[&[0x19, 0x04], &P0122_16, &[record]]),
            RequestOutOfRange,
        );
    }
    for record in [0x00, 0x04, 0x90, 0xFE] {
        negative(
            s,
            &cat(&[&[0x19, 0x06], &P0122_16, &[record]]),
            RequestOutOfRange,
        );
    }
    negative(s, &[0x14, 0x01, 0x23, 0x18], RequestOutOfRange);
    // 0xFFFF33 (emission-related group) is not a group fdd knows.
    negative(s, &[0x14, 0xFF, 0xFF, 0x33], RequestOutOfRange);
    // An empty request gets no response.
    assert_eq!(ask(s, &[]), (Reply::NoResponse, vec![]));
    // Nothing above changed the memory.
    positive(
        s,
        &[0x19, 0x02, 0xFF],
        &cat(&[
            &[0x59, 0x02, 0xFF],
            &P0122_16,
            &[0x27],
            &P0123_17,
            &[0x2F],
            &P2135_62,
            &[0x50],
        ]),
    );
}

#[test]
fn clear_one_dtc_then_all() {
    let mut mem = known_memory();
    let mut events = Vec::new();
    let mut store = EventMemoryStore::new(&mut mem, 6.0, |e| events.push(e));
    let s = &mut store;
    positive(s, &[0x14, 0x01, 0x23, 0x17], &[0x54]);
    positive(
        s,
        &[0x19, 0x02, 0xFF],
        &cat(&[
            &[0x59, 0x02, 0xFF],
            &P0122_16,
            &[0x27],
            &P0123_17,
            &[0x50],
            &P2135_62,
            &[0x50],
        ]),
    );
    // Its entry is gone: no snapshot, no extended data.
    positive(s, &[0x19, 0x03], &cat(&[&[0x59, 0x03], &P0122_16, &[0x01]]));
    positive(
        s,
        &cat(&[&[0x19, 0x06], &P0123_17, &[0xFF]]),
        &cat(&[&[0x59, 0x06], &P0123_17, &[0x50]]),
    );
    s.set_time(7.0);
    positive(s, &[0x14, 0xFF, 0xFF, 0xFF], &[0x54]);
    positive(s, &[0x19, 0x02, 0x2F], &[0x59, 0x02, 0xFF]);
    positive(
        s,
        &[0x19, 0x01, 0x50],
        &[0x59, 0x01, 0xFF, 0x00, 0x00, 0x03],
    );
    positive(s, &[0x19, 0x03], &[0x59, 0x03]);
    // Clearing an already clear memory is still a positive response.
    positive(s, &[0x14, 0xFF, 0xFF, 0xFF], &[0x54]);
    assert_eq!(store.time_s(), 7.0);
    assert_eq!(store.memory().entries_used(), 0);
    // The clears reached the sink, stamped with the store's time: P0123-17 at 6 s, then
    // P0122-16 at 7 s (P2135-62 was already clear).
    let seen: Vec<(f64, String, Trigger, u8, u8)> = events
        .iter()
        .map(|e| {
            (
                e.time_s,
                e.dtc.to_string(),
                e.trigger,
                e.status_before.byte(),
                e.status_after.byte(),
            )
        })
        .collect();
    assert_eq!(
        seen,
        [
            (6.0, "P0123-17".into(), Trigger::ClearDtc, 0x2F, 0x50),
            (7.0, "P0122-16".into(), Trigger::ClearDtc, 0x27, 0x50),
        ]
    );
}

#[test]
fn clear_at_a_time_before_the_memory_is_refused() {
    let mut mem = known_memory();
    // The memory's last call was at 5 s.
    let mut store = EventMemoryStore::new(&mut mem, 4.0, |_| {});
    negative(
        &mut store,
        &[0x14, 0xFF, 0xFF, 0xFF],
        Nrc::ConditionsNotCorrect,
    );
    store.set_time(f64::NAN);
    negative(
        &mut store,
        &[0x14, 0xFF, 0xFF, 0xFF],
        Nrc::ConditionsNotCorrect,
    );
    positive(
        &mut store,
        &[0x19, 0x01, 0x08],
        &[0x59, 0x01, 0xFF, 0x00, 0x00, 0x01],
    );
    store.set_time(6.0);
    assert_eq!(
        store.clear(DtcGroup::Dtc(dtc("P0123-18"))),
        Err(ClearRefused::UnknownDtc(dtc("P0123-18")))
    );
}

#[test]
fn encoders_append_and_leave_the_buffer_alone_on_error() {
    let mut mem = known_memory();
    let store = EventMemoryStore::new(&mut mem, 6.0, |_| {});
    let mut out = vec![0xAA, 0xBB];
    encode_dtcs_by_status_mask(&store, 0x08, &mut out);
    assert_eq!(
        out,
        cat(&[&[0xAA, 0xBB, 0x59, 0x02, 0xFF], &P0123_17, &[0x2F]])
    );
    let before = out.clone();
    assert_eq!(
        encode_snapshot_records(&store, dtc("P0123-18"), 0xFF, &mut out),
        Err(Nrc::RequestOutOfRange)
    );
    assert_eq!(
        encode_snapshot_records(&store, dtc("P0123-17"), 0x02, &mut out),
        Err(Nrc::RequestOutOfRange)
    );
    assert_eq!(
        encode_ext_data_records(&store, dtc("P0123-18"), 0x01, &mut out),
        Err(Nrc::RequestOutOfRange)
    );
    assert_eq!(out, before);
}

// ------------------------------------------------------------------ other stores

/// A store with fixed contents: the availability mask and values an EventMemory cannot
/// produce (bit 7 unsupported, negative max FDC, more values than a record holds).
struct FixedStore {
    dtcs: Vec<(Dtc, u8, Option<ExtendedData>, usize)>,
}

impl DtcStore for FixedStore {
    fn status_availability_mask(&self) -> u8 {
        0x7F
    }

    fn for_each_dtc(&self, f: &mut dyn FnMut(Dtc, DtcStatus)) {
        for &(d, s, _, _) in &self.dtcs {
            f(d, DtcStatus::from_byte(s));
        }
    }

    fn snapshot(&self, dtc: Dtc, visit: &mut dyn FnMut(SnapshotValue)) -> Option<DtcStatus> {
        let &(_, s, _, n) = self.dtcs.iter().find(|e| e.0 == dtc)?;
        for k in 0..n {
            visit(SnapshotValue {
                did: 0x1000 + k as u16,
                value: k as f64,
            });
        }
        Some(DtcStatus::from_byte(s))
    }

    fn extended_data(&self, dtc: Dtc) -> Option<ExtendedData> {
        let &(_, s, x, _) = self.dtcs.iter().find(|e| e.0 == dtc)?;
        Some(x.unwrap_or(ExtendedData {
            status: DtcStatus::from_byte(s),
            stored: false,
            occurrence_counter: 0,
            aging_counter: 0,
            max_fdc: 0,
        }))
    }

    fn clear(&mut self, _group: DtcGroup) -> Result<usize, ClearRefused> {
        Err(ClearRefused::MemoryFailure("NvM write failed"))
    }
}

#[test]
fn availability_mask_negative_fdc_and_full_records() {
    let a = dtc("C0035-28");
    let b = dtc("U0100-87");
    let mut store = FixedStore {
        dtcs: vec![
            (
                a,
                0xAF,
                Some(ExtendedData {
                    status: DtcStatus::from_byte(0xAF),
                    stored: true,
                    occurrence_counter: 255,
                    aging_counter: 39,
                    max_fdc: -5,
                }),
                300,
            ),
            (b, 0x80, None, 0),
        ],
    };
    let s = &mut store;
    // Bit 7 is not available: reported as 0, and a mask on it alone matches nothing.
    positive(
        s,
        &[0x19, 0x02, 0xFF],
        &[0x59, 0x02, 0x7F, 0x40, 0x35, 0x28, 0x2F],
    );
    positive(s, &[0x19, 0x02, 0x80], &[0x59, 0x02, 0x7F]);
    positive(
        s,
        &[0x19, 0x01, 0x80],
        &[0x59, 0x01, 0x7F, 0x00, 0x00, 0x00],
    );
    positive(
        s,
        &[0x19, 0x0A],
        &[
            0x59, 0x0A, 0x7F, 0x40, 0x35, 0x28, 0x2F, 0xC1, 0x00, 0x87, 0x00,
        ],
    );
    // Max FDC -5 is 0xFB.
    positive(
        s,
        &[0x19, 0x06, 0x40, 0x35, 0x28, 0xFF],
        &[
            0x59, 0x06, 0x40, 0x35, 0x28, 0x2F, 0x01, 0xFF, 0x02, 0x27, 0x03, 0xFB,
        ],
    );
    // 300 values: the record carries the first 255.
    let (reply, bytes) = ask(s, &[0x19, 0x04, 0x40, 0x35, 0x28, 0xFF]);
    assert_eq!(reply, Reply::Positive);
    assert_eq!(bytes[..8], [0x59, 0x04, 0x40, 0x35, 0x28, 0x2F, 0x01, 0xFF]);
    assert_eq!(bytes.len(), 8 + 255 * 6);
    assert_eq!(
        bytes[bytes.len() - 6..],
        [0x10, 0xFE, 0x43, 0x7E, 0x00, 0x00]
    ); // 254.0
    negative(s, &[0x14, 0xFF, 0xFF, 0xFF], Nrc::GeneralProgrammingFailure);
}

/// Two event memories behind one store, as the runtime holds them (one per monitor): DTCs of
/// the first memory, then the second; one DID per signal name across both; a clear of all
/// clears both, a clear of one DTC goes to the memory that holds it.
struct TwoMemories {
    memories: [EventMemory; 2],
    time_s: f64,
    dids: Vec<(String, u16)>,
}

impl TwoMemories {
    fn new(memories: [EventMemory; 2]) -> Self {
        let mut dids: Vec<(String, u16)> = Vec::new();
        for m in &memories {
            for (_, signal) in freeze_frame_dids(m) {
                if !dids.iter().any(|(s, _)| s == signal) {
                    let did = 0xFD00 + dids.len() as u16;
                    dids.push((signal.to_string(), did));
                }
            }
        }
        TwoMemories {
            memories,
            time_s: 0.0,
            dids,
        }
    }
}

impl DtcStore for TwoMemories {
    fn status_availability_mask(&self) -> u8 {
        DtcStatus::AVAILABILITY_MASK
    }

    fn for_each_dtc(&self, f: &mut dyn FnMut(Dtc, DtcStatus)) {
        for m in &self.memories {
            for id in m.event_ids() {
                f(m.dtc(id), m.status(id));
            }
        }
    }

    fn snapshot(&self, dtc: Dtc, visit: &mut dyn FnMut(SnapshotValue)) -> Option<DtcStatus> {
        let did_of = |signal: &str| self.dids.iter().find(|(s, _)| s == signal).map(|&(_, d)| d);
        self.memories
            .iter()
            .find_map(|m| memory_snapshot(m, dtc, &did_of, visit))
    }

    fn extended_data(&self, dtc: Dtc) -> Option<ExtendedData> {
        self.memories
            .iter()
            .find_map(|m| memory_extended_data(m, dtc))
    }

    fn clear(&mut self, group: DtcGroup) -> Result<usize, ClearRefused> {
        let t = self.time_s;
        match group {
            DtcGroup::Dtc(d) => {
                let m = self
                    .memories
                    .iter_mut()
                    .find(|m| m.event_id_by_dtc(d).is_some())
                    .ok_or(ClearRefused::UnknownDtc(d))?;
                memory_clear(m, group, t, |_| {})
            }
            _ => {
                let mut n = 0;
                for m in &mut self.memories {
                    n += memory_clear(m, group, t, |_| {})?;
                }
                Ok(n)
            }
        }
    }
}

#[test]
fn a_store_over_two_memories() {
    let throttle = known_memory();
    let mut map = event("map_range", "P0106-00", &["map_kpa", "engine_speed_rpm"]);
    map.mil.enabled = false;
    let mut intake = EventMemory::new(&EventMemoryConfig {
        capacity: 2,
        events: vec![map],
    })
    .unwrap();
    let id = intake.event_id("map_range").unwrap();
    intake.start_operation_cycle(0.0, |_| {}).unwrap();
    intake
        .report(
            id,
            &result(Verdict::Failed),
            &ReportContext::at(1.0).with_freeze_frame(&[101.25, 900.0]),
            |_| {},
        )
        .unwrap();
    let mut store = TwoMemories::new([throttle, intake]);
    store.time_s = 10.0;
    let s = &mut store;
    let p0106 = [0x01, 0x06, 0x00];
    positive(
        s,
        &[0x19, 0x02, 0x01],
        &cat(&[
            &[0x59, 0x02, 0xFF],
            &P0122_16,
            &[0x27],
            &P0123_17,
            &[0x2F],
            &p0106,
            &[0x27],
        ]),
    );
    // map_kpa is new (0xFD03); engine_speed_rpm keeps the throttle memory's 0xFD01.
    positive(
        s,
        &cat(&[&[0x19, 0x04], &p0106, &[0xFF]]),
        &cat(&[
            &[0x59, 0x04],
            &p0106,
            &[0x27, 0x01, 0x02],
            &[0xFD, 0x03, 0x42, 0xCA, 0x80, 0x00], // 101.25 kPa
            &[0xFD, 0x01, 0x44, 0x61, 0x00, 0x00], // 900 rpm
        ]),
    );
    positive(
        s,
        &[0x19, 0x03],
        &cat(&[
            &[0x59, 0x03],
            &P0122_16,
            &[0x01],
            &P0123_17,
            &[0x01],
            &p0106,
            &[0x01],
        ]),
    );
    positive(s, &cat(&[&[0x14], &p0106]), &[0x54]);
    positive(
        s,
        &[0x19, 0x01, 0x01],
        &[0x59, 0x01, 0xFF, 0x00, 0x00, 0x02],
    );
    negative(s, &[0x14, 0x01, 0x06, 0x01], Nrc::RequestOutOfRange);
    positive(s, &[0x14, 0xFF, 0xFF, 0xFF], &[0x54]);
    positive(
        s,
        &[0x19, 0x01, 0x01],
        &[0x59, 0x01, 0xFF, 0x00, 0x00, 0x00],
    );
}

// ------------------------------------------------------------------ udsoncan cross-check

/// Runs `tests/data/decode_uds.py` on `input`; panics (test failure) when python3 or udsoncan
/// is missing or the script fails.
fn run_udsoncan(input: &Value) -> Value {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/decode_uds.py");
    let mut child = Command::new("python3")
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| {
            panic!(
                "the udsoncan cross-check needs python3 on PATH ({e}); install Python 3 and \
                 `python3 -m pip install udsoncan` (CI does, in .ci/run)"
            )
        });
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(input.to_string().as_bytes())
        .expect("write to decode_uds.py");
    let out = child.wait_with_output().expect("run decode_uds.py");
    let stderr = String::from_utf8_lossy(&out.stderr);
    match out.status.code() {
        Some(0) => {}
        Some(3) => panic!(
            "the udsoncan cross-check needs the Python package udsoncan: \
             `python3 -m pip install udsoncan` (CI installs it in .ci/run)\n{stderr}"
        ),
        _ => panic!(
            "tests/data/decode_uds.py failed ({}):\n{stderr}",
            out.status
        ),
    }
    serde_json::from_slice(&out.stdout).expect("decode_uds.py prints JSON")
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// What udsoncan must read for DTC `d` with status `status` (snapshots and extended data
/// empty unless given).
fn expected_dtc(d: &str, status: u8, snapshots: Value, extended: Value) -> Value {
    let d = dtc(d);
    json!({
        "id": d.to_u32(),
        "iso": d.to_string(),
        "status": status,
        "snapshots": snapshots,
        "snapshot_records": [],
        "extended_data": extended,
    })
}

fn snap(did: u16, value: Option<f64>, raw: &str) -> Value {
    json!({"record": 1, "did": did, "raw": raw, "value": value})
}

#[test]
fn udsoncan_decodes_what_fdd_sends() {
    let mut mem = known_memory();
    let mut store = EventMemoryStore::new(&mut mem, 6.0, |_| {});
    let [fd00, fd01, fd02] = [0xFD00u16, 0xFD01, 0xFD02];
    let (p0122, p0123, p2135) = (0x012216u32, 0x012317u32, 0x213562u32);

    // (name, udsoncan request parameters, the request fdd is sent, decoder options)
    let cases: Vec<(&str, Value, Vec<u8>, Value)> = vec![
        (
            "count",
            json!({"service": "ReadDTCInformation", "subfunction": 1, "status_mask": 0x09}),
            vec![0x19, 0x01, 0x09],
            json!({"subfunction": 1}),
        ),
        (
            "by_mask",
            json!({"service": "ReadDTCInformation", "subfunction": 2, "status_mask": 0xFF}),
            vec![0x19, 0x02, 0xFF],
            json!({"subfunction": 2}),
        ),
        (
            "confirmed",
            json!({"service": "ReadDTCInformation", "subfunction": 2, "status_mask": 0x08}),
            vec![0x19, 0x02, 0x08],
            json!({"subfunction": 2}),
        ),
        (
            "supported",
            json!({"service": "ReadDTCInformation", "subfunction": 0x0A}),
            vec![0x19, 0x0A],
            json!({"subfunction": 0x0A}),
        ),
        (
            "snapshot_ids",
            json!({"service": "ReadDTCInformation", "subfunction": 3}),
            vec![0x19, 0x03],
            json!({"subfunction": 3}),
        ),
        (
            "snapshot_low",
            json!({"service": "ReadDTCInformation", "subfunction": 4, "dtc": p0122, "snapshot_record_number": 0xFF}),
            cat(&[&[0x19, 0x04], &P0122_16, &[0xFF]]),
            json!({"subfunction": 4, "dids": [fd00, fd01, fd02]}),
        ),
        (
            "snapshot_high",
            json!({"service": "ReadDTCInformation", "subfunction": 4, "dtc": p0123, "snapshot_record_number": 0x01}),
            cat(&[&[0x19, 0x04], &P0123_17, &[0x01]]),
            json!({"subfunction": 4, "dids": [fd00, fd01, fd02]}),
        ),
        (
            "snapshot_none",
            json!({"service": "ReadDTCInformation", "subfunction": 4, "dtc": p2135, "snapshot_record_number": 0xFF}),
            cat(&[&[0x19, 0x04], &P2135_62, &[0xFF]]),
            json!({"subfunction": 4, "dids": [fd00, fd01, fd02]}),
        ),
        (
            "ext_all",
            json!({"service": "ReadDTCInformation", "subfunction": 6, "dtc": p0123, "extended_data_record_number": 0xFF}),
            cat(&[&[0x19, 0x06], &P0123_17, &[0xFF]]),
            json!({"subfunction": 6, "ext_size": 1}),
        ),
        (
            "ext_fdc",
            json!({"service": "ReadDTCInformation", "subfunction": 6, "dtc": p0122, "extended_data_record_number": 0x03}),
            cat(&[&[0x19, 0x06], &P0122_16, &[0x03]]),
            json!({"subfunction": 6, "ext_size": 1}),
        ),
        (
            "ext_none",
            json!({"service": "ReadDTCInformation", "subfunction": 6, "dtc": p2135, "extended_data_record_number": 0xFF}),
            cat(&[&[0x19, 0x06], &P2135_62, &[0xFF]]),
            json!({"subfunction": 6, "ext_size": 1}),
        ),
        (
            "unknown_dtc",
            json!({"service": "ReadDTCInformation", "subfunction": 4, "dtc": 0x012318, "snapshot_record_number": 0xFF}),
            vec![0x19, 0x04, 0x01, 0x23, 0x18, 0xFF],
            json!({}),
        ),
        (
            "clear_one",
            json!({"service": "ClearDiagnosticInformation", "group": p0123}),
            cat(&[&[0x14], &P0123_17]),
            json!({}),
        ),
        (
            "after_clear_one",
            json!({"service": "ReadDTCInformation", "subfunction": 2, "status_mask": 0xFF}),
            vec![0x19, 0x02, 0xFF],
            json!({"subfunction": 2}),
        ),
        (
            "clear_all",
            json!({"service": "ClearDiagnosticInformation", "group": 0xFFFFFF}),
            vec![0x14, 0xFF, 0xFF, 0xFF],
            json!({}),
        ),
        (
            "after_clear_all",
            json!({"service": "ReadDTCInformation", "subfunction": 2, "status_mask": 0xFF}),
            vec![0x19, 0x02, 0xFF],
            json!({"subfunction": 2}),
        ),
    ];

    let mut requests = Vec::new();
    let mut responses = Vec::new();
    for (name, params, request, options) in &cases {
        let mut r = params.clone();
        r["name"] = json!(name);
        requests.push(r);
        let (_, bytes) = ask(&mut store, request);
        let mut o = options.clone();
        o["name"] = json!(name);
        o["payload"] = json!(hex(&bytes));
        responses.push(o);
    }
    let decoded = run_udsoncan(&json!({"requests": requests, "responses": responses}));
    eprintln!("udsoncan {}", decoded["udsoncan_version"]);

    // udsoncan builds exactly the requests fdd was sent.
    for (name, _, request, _) in &cases {
        assert_eq!(
            decoded["requests"][name],
            json!(hex(request)),
            "udsoncan's {name} request"
        );
    }

    let r = &decoded["responses"];
    let rd = |name: &str, key: &str| r[name][key].clone();
    for (name, _, request, _) in &cases {
        assert_eq!(
            rd(name, "positive"),
            json!(*name != "unknown_dtc"),
            "{name}"
        );
        assert_eq!(rd(name, "service_id"), json!(request[0]), "{name}");
    }

    // 0x01: availability, format SAE_J2012-DA_DTCFormat_00, count of TF | CDTC.
    assert_eq!(rd("count", "status_availability"), json!(0xFF));
    assert_eq!(rd("count", "dtc_format"), json!(0x00));
    assert_eq!(rd("count", "dtc_count"), json!(2));

    // 0x02 / 0x0A: DTC ids, J2012 text and status bytes.
    let all = json!([
        expected_dtc("P0122-16", 0x27, json!([]), json!([])),
        expected_dtc("P0123-17", 0x2F, json!([]), json!([])),
        expected_dtc("P2135-62", 0x50, json!([]), json!([])),
    ]);
    for name in ["by_mask", "supported"] {
        assert_eq!(rd(name, "status_availability"), json!(0xFF), "{name}");
        assert_eq!(rd(name, "dtcs"), all, "{name}");
    }
    assert_eq!(
        rd("confirmed", "dtcs"),
        json!([expected_dtc("P0123-17", 0x2F, json!([]), json!([]))])
    );

    // 0x03: record 1 for the two DTCs with an entry (udsoncan leaves their status at 0).
    let ids = rd("snapshot_ids", "dtcs");
    let ids: Vec<(u64, Value)> = ids
        .as_array()
        .unwrap()
        .iter()
        .map(|d| (d["id"].as_u64().unwrap(), d["snapshot_records"].clone()))
        .collect();
    assert_eq!(
        ids,
        [(p0122 as u64, json!([1])), (p0123 as u64, json!([1]))]
    );

    // 0x04: DIDs and binary32 values.
    assert_eq!(
        rd("snapshot_low", "dtcs"),
        json!([expected_dtc(
            "P0122-16",
            0x27,
            json!([
                snap(fd00, Some(0.125), "3e000000"),
                snap(fd01, Some(812.5), "444b2000"),
            ]),
            json!([])
        )])
    );
    assert_eq!(
        rd("snapshot_high", "dtcs"),
        json!([expected_dtc(
            "P0123-17",
            0x2F,
            json!([
                snap(fd00, Some(4.875), "409c0000"),
                snap(fd02, None, "7fc00000"),
            ]),
            json!([])
        )])
    );
    assert_eq!(
        rd("snapshot_none", "dtcs"),
        json!([expected_dtc("P2135-62", 0x50, json!([]), json!([]))])
    );

    // 0x06: occurrence 2, aging 0, max FDC 0x7F.
    let ext = |record: u8, raw: &str| json!({"record": record, "raw": raw});
    assert_eq!(
        rd("ext_all", "dtcs"),
        json!([expected_dtc(
            "P0123-17",
            0x2F,
            json!([]),
            json!([ext(1, "02"), ext(2, "00"), ext(3, "7f")])
        )])
    );
    assert_eq!(
        rd("ext_fdc", "dtcs"),
        json!([expected_dtc(
            "P0122-16",
            0x27,
            json!([]),
            json!([ext(3, "7f")])
        )])
    );
    assert_eq!(
        rd("ext_none", "dtcs"),
        json!([expected_dtc("P2135-62", 0x50, json!([]), json!([]))])
    );

    // Negative response and clears.
    assert_eq!(rd("unknown_dtc", "nrc"), json!(0x31));
    assert_eq!(rd("unknown_dtc", "nrc_name"), json!("RequestOutOfRange"));
    for name in ["clear_one", "clear_all"] {
        assert_eq!(rd(name, "service"), json!("ClearDiagnosticInformation"));
    }
    assert_eq!(
        rd("after_clear_one", "dtcs"),
        json!([
            expected_dtc("P0122-16", 0x27, json!([]), json!([])),
            expected_dtc("P0123-17", 0x50, json!([]), json!([])),
            expected_dtc("P2135-62", 0x50, json!([]), json!([])),
        ])
    );
    assert_eq!(
        rd("after_clear_all", "dtcs"),
        json!([
            expected_dtc("P0122-16", 0x50, json!([]), json!([])),
            expected_dtc("P0123-17", 0x50, json!([]), json!([])),
            expected_dtc("P2135-62", 0x50, json!([]), json!([])),
        ])
    );
}
