//! Helpers shared by the `log_*` integration tests: example messages of every topic and small
//! file utilities.
#![allow(dead_code)]

use std::io::Cursor;
use std::path::Path;

use fdd_diagnostics::event::DiagnosticEvent;
use fdd_monitor::log::*;

/// One example of each message type, as (log time ns, message) written in this order.
pub struct Examples {
    pub motor: MotorVoltage,
    pub tps: TpsVoltage,
    pub watt: Wattmeter,
    pub truth: ThrottleTruth,
    pub position: PositionEstimate,
    pub innovation: InnovationMsg,
    pub test: TestStatistic,
    pub dtc: DtcStatusMsg,
    pub event: DiagnosticEvent,
    pub event_no_result: DiagnosticEvent,
}

pub fn examples() -> Examples {
    let event: DiagnosticEvent = serde_json::from_str(
        r#"{"time_s": 12.5, "event": "tps_a_high", "dtc": "P0123-1C", "dtc_uds": 74524,
            "trigger": "test_result", "status_before": 80, "status_after": 39,
            "changed": ["testFailed", "testFailedThisOperationCycle", "pendingDTC",
                        "testNotCompletedSinceLastClear", "testFailedSinceLastClear",
                        "testNotCompletedThisOperationCycle"],
            "fdc": 127, "occurrence_counter": 1, "aging_counter": 0, "memory": "stored",
            "displaced": null,
            "freeze_frame": [{"signal": "tps_a_v", "value": 4.93}, {"signal": "engine_speed_rpm", "value": null}],
            "test_result": {"value": 4.93, "min": 0.25, "max": 4.75, "verdict": "FAILED"},
            "candidates": [{"fault": "tps_a_short_to_supply", "score": 0.91}, {"fault": "tps_a_bias", "score": 0.09}]}"#,
    )
    .expect("example event");
    let event_no_result: DiagnosticEvent = serde_json::from_str(
        r#"{"time_s": 13.0, "event": "tps_a_high", "dtc": "P0123-1C", "dtc_uds": 74524,
            "trigger": "clear_dtc", "status_before": 39, "status_after": 80,
            "changed": ["testFailed"], "fdc": 0, "occurrence_counter": 0, "aging_counter": 0,
            "memory": "cleared", "displaced": "P0122-00", "freeze_frame": [],
            "test_result": null, "candidates": []}"#,
    )
    .expect("example event");
    Examples {
        motor: MotorVoltage { voltage_v: 0.31 },
        tps: TpsVoltage { voltage_v: 1.25 },
        watt: Wattmeter { power_w: f64::NAN },
        truth: ThrottleTruth {
            angle_deg: 22.5,
            velocity: -0.125,
            current_a: 0.5,
            fault: "tps_stuck".into(),
            fault_active: true,
            fault_observable: None,
        },
        position: PositionEstimate {
            angle_deg: 22.0,
            lower_deg: 19.5,
            upper_deg: 24.5,
            source: "wattmeter_estimate".into(),
        },
        innovation: InnovationMsg {
            filter: "ukf_ahsm".into(),
            residual: vec![0.01, f64::INFINITY],
            variance: vec![0.04, 1.0],
            nis: 0.0025,
            dof: 2,
        },
        test: TestStatistic {
            test: "nis_window".into(),
            value: f64::NAN,
            min: 0.0,
            max: 31.4,
            verdict: "NOT_TESTED".into(),
        },
        dtc: DtcStatusMsg {
            dtc: "P0123-1C".into(),
            status: 0x2F,
        },
        event,
        event_no_result,
    }
}

/// Writes every example once, at 1 ms steps from `t0_ns`.
pub fn write_examples<W: std::io::Write + std::io::Seek>(
    w: &mut LogWriter<W>,
    t0_ns: u64,
) -> Result<(), LogError> {
    let e = examples();
    let ms = 1_000_000;
    w.write_message(t0_ns, &e.motor)?;
    w.write_message(t0_ns, &e.tps)?;
    w.write_message(t0_ns, &e.watt)?;
    w.write_message(t0_ns, &e.truth)?;
    w.write_message(t0_ns + ms, &e.position)?;
    w.write_message(t0_ns + ms, &e.innovation)?;
    w.write_message(t0_ns + ms, &e.test)?;
    w.write_message(t0_ns + 2 * ms, &e.dtc)?;
    w.write_message(t0_ns + 2 * ms, &e.event)?;
    w.write_message(t0_ns + 3 * ms, &e.event_no_result)?;
    Ok(())
}

/// A run of input samples on the three input topics, 1 ms apart: `n` samples, 3 messages each.
pub fn write_inputs<W: std::io::Write + std::io::Seek>(
    w: &mut LogWriter<W>,
    n: u64,
) -> Result<(), LogError> {
    for k in 0..n {
        let t = k * 1_000_000;
        let x = (k as f64 * 0.001).sin();
        w.write_message(t, &MotorVoltage { voltage_v: x })?;
        w.write_message(t, &TpsVoltage { voltage_v: 2.5 + x })?;
        w.write_message(t, &Wattmeter { power_w: x * x })?;
    }
    Ok(())
}

/// An in-memory MCAP file written by `f`.
pub fn to_bytes(
    options: WriteOptions,
    f: impl FnOnce(&mut LogWriter<Cursor<Vec<u8>>>) -> Result<(), LogError>,
) -> Vec<u8> {
    let mut w =
        LogWriter::with_options(Cursor::new(Vec::new()), "memory", options).expect("create writer");
    f(&mut w).expect("write");
    w.finish().expect("finish").into_inner()
}

/// A message as the tests compare them: topic, log time, data.
pub type Msg = (String, u64, Vec<u8>);

/// (topic, log time, data) of every message, or the first error.
pub fn read_all(path: &Path, options: ReadOptions) -> Result<Vec<Msg>, LogError> {
    let mut r = LogReader::open_with(path, options)?;
    let mut out = Vec::new();
    while let Some(m) = r.next_message() {
        let m = m?;
        out.push((m.topic.to_string(), m.log_time_ns, m.data.to_vec()));
    }
    Ok(out)
}

/// Reads everything, collecting messages and errors; panics if a fatal error is not last.
pub fn read_lenient(reader: &mut LogReader) -> (Vec<Msg>, Vec<LogError>) {
    let mut msgs = Vec::new();
    let mut errs: Vec<LogError> = Vec::new();
    let mut guard = 0u64;
    while let Some(m) = reader.next_message() {
        guard += 1;
        assert!(guard < 100_000_000, "reader does not terminate");
        if let Some(last) = errs.last() {
            assert!(!last.is_fatal(), "an item followed a fatal error: {last}");
        }
        match m {
            Ok(m) => msgs.push((m.topic.to_string(), m.log_time_ns, m.data.to_vec())),
            Err(e) => errs.push(e),
        }
    }
    (msgs, errs)
}

/// Floats equal, with NaN equal to NaN.
pub fn same(a: f64, b: f64) -> bool {
    a == b || (a.is_nan() && b.is_nan())
}
