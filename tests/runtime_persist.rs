//! The runtime keeps its event memory across power cycles (`RuntimeBuilder::persistence`): a
//! TPS open circuit in two drives is confirmed, the runtime is dropped (power off) and a new
//! one restores it from the slot files; a configuration whose DTC table changed restores what
//! still matches and says what it dropped; ClearDTC is persisted too.

use std::path::Path;

use fdd::replay::RuntimeConfig;
use fdd_diagnostics::dtc::{Dtc, DtcGroup};
use fdd_monitor::log::LogReader;
use fdd_monitor::runtime::{NullSink, Runtime};

/// Feeds a throttle fixture through one operation cycle starting at `t0`.
fn drive(rt: &mut Runtime, cfg: &RuntimeConfig, fixture: &str, t0: u64) -> u64 {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("fixtures/data/{fixture}.mcap"));
    let mut reader = LogReader::open(&path).expect("fixture");
    let mut sink = NullSink;
    rt.start_operation_cycle(t0, &mut sink).expect("cycle");
    let mut frame = None;
    let mut last = t0;
    while let Some(m) = reader.next_message() {
        let m = m.expect("readable");
        let t = t0 + m.log_time_ns;
        if frame != Some(t) {
            if frame.is_some() {
                rt.advance_to(t - 1, &mut sink).expect("advance");
            }
            frame = Some(t);
        }
        for s in cfg.signals.iter().filter(|s| s.topic == m.topic) {
            let v = m.field_f64(&s.field).expect("field");
            rt.push(rt.signal(&s.name).expect("signal"), t, v)
                .expect("sample");
        }
        last = t;
    }
    rt.advance_to(last, &mut sink).expect("advance");
    rt.end_operation_cycle(last + 1, &mut sink).expect("end");
    last + 1
}

fn build(cfg: &RuntimeConfig, base: &Path) -> Runtime {
    Runtime::builder(cfg.clone())
        .only_monitors(&["throttle"])
        .persistence(base)
        .build()
        .expect("runtime")
        .0
}

#[test]
fn a_confirmed_dtc_survives_power_off_and_a_changed_table_drops_what_no_longer_matches() {
    let dir = tempfile::tempdir().expect("tempdir");
    let base = dir.path().join("fdd-memory");
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let open: Dtc = "P0122-16".parse().expect("dtc");
    let mut rt = build(&cfg, &base);
    assert!(
        rt.restore_notes().iter().all(|n| n.contains("missing")),
        "{:?}",
        rt.restore_notes()
    );
    let t = drive(&mut rt, &cfg, "throttle_tps_open", 0);
    let t = drive(&mut rt, &cfg, "throttle_tps_open", t + 1_000_000_000);
    let status = rt.status(open).expect("configured");
    assert!(status.confirmed(), "{:#04x}", status.byte());
    let ff_before: Vec<(String, f64)> = rt
        .freeze_frame(open)
        .expect("stored")
        .freeze_frame()
        .map(|(s, v)| (s.to_string(), v))
        .collect();
    let (writes, failures) = rt.persist_counts();
    assert!(
        writes >= 3 && failures == 0,
        "{writes} writes, {failures} failures"
    );
    drop(rt); // power off

    // Power on: a new runtime, a new clock origin.
    let rt = build(&cfg, &base);
    let restored = rt.status(open).expect("configured");
    assert_eq!(restored, status, "status byte restored");
    let ff_after: Vec<(String, f64)> = rt
        .freeze_frame(open)
        .expect("entry restored")
        .freeze_frame()
        .map(|(s, v)| (s.to_string(), v))
        .collect();
    assert_eq!(ff_after, ff_before);
    assert_eq!(rt.extended_data(open).expect("ext").occurrence_counter, 2);
    drop(rt);

    // A new software version whose TPS-low DTC changed: the rest is restored, the change said.
    let dir_cfg = tempfile::tempdir().expect("tempdir");
    let throttle = dir_cfg.path().join("throttle.toml");
    let text = fdd::config::DEFAULT_THROTTLE_TOML;
    assert!(
        !text.contains("\n[monitor]"),
        "the default has no [monitor] table"
    );
    std::fs::write(
        &throttle,
        format!("{text}\n[monitor]\ndtc_tps_low = \"P0122-00\"\n"),
    )
    .expect("write");
    let runtime_text = fdd::replay::config::DEFAULT_RUNTIME_TOML.replace(
        "throttle = true",
        &format!(
            "throttle = true\nthrottle_config = {:?}",
            throttle.display().to_string()
        ),
    );
    let cfg2 = RuntimeConfig::parse(&runtime_text, "changed.toml").expect("valid");
    let mut rt = build(&cfg2, &base);
    let notes = rt.restore_notes().join("\n");
    assert!(notes.contains("P0122-16"), "{notes}");
    let fallback: Dtc = "P2106-00".parse().expect("dtc");
    assert!(rt.status(fallback).expect("configured").confirmed());

    // ClearDTC is persisted at once.
    rt.clear_dtc(DtcGroup::All, 0, &mut NullSink)
        .expect("clear");
    drop(rt);
    let rt = build(&cfg2, &base);
    assert_eq!(rt.status(fallback).expect("configured").byte(), 0x50);
    let _ = t;
}

/// The runtime answers UDS requests byte for byte: 0x19 0x02 after a TPS open circuit lists
/// P0122-16 and P2106-00 at 0x27, 0x19 0x06 gives the occurrence counter, 0x14 clears.
#[test]
fn the_runtime_answers_uds_dtc_requests() {
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let (mut rt, _) = Runtime::builder(cfg.clone())
        .only_monitors(&["throttle"])
        .build()
        .expect("runtime");
    drive(&mut rt, &cfg, "throttle_tps_open", 0);
    rt.start_operation_cycle(30_000_000_000, &mut NullSink)
        .expect("cycle");
    let mut sink = NullSink;
    let mut server = fdd_monitor::runtime::UdsServer::new(&mut rt, &mut sink);
    let mut resp = Vec::with_capacity(4095);
    server.handle(&[0x19, 0x02, 0x04], &mut resp);
    // testFailed stays until a passed test, pendingDTC and testFailedSinceLastClear stay,
    // the new cycle cleared bit 1 and set bit 6 (not completed this cycle): 0x65.
    assert_eq!(
        resp,
        [0x59, 0x02, 0xFF, 0x01, 0x22, 0x16, 0x65, 0x21, 0x06, 0x00, 0x65],
        "{resp:02X?}"
    );
    server.handle(&[0x19, 0x06, 0x01, 0x22, 0x16, 0x01], &mut resp);
    assert_eq!(
        resp,
        [0x59, 0x06, 0x01, 0x22, 0x16, 0x65, 0x01, 0x01],
        "{resp:02X?}"
    );
    server.handle(&[0x14, 0xFF, 0xFF, 0xFF], &mut resp);
    assert_eq!(resp, [0x54]);
    server.handle(&[0x19, 0x02, 0xFF], &mut resp);
    assert_eq!(
        resp.len(),
        3 + 4 * 37,
        "every DTC listed (status 0x50 matches 0xFF): the 30 signals' no-signal DTCs and the throttle monitor's 7"
    );
    assert!(resp[3..].chunks(4).all(|c| c[3] == 0x50), "{resp:02X?}");
}

/// `fdd replay --memory FILE`: consecutive replays are consecutive operation cycles of one
/// vehicle. A TPS open circuit in two logs is confirmed in the second; an intake log replayed
/// in between (the throttle monitor does not run on it) keeps the throttle DTCs as they were.
#[test]
fn replays_with_a_memory_file_act_as_consecutive_drives() {
    let dir = tempfile::tempdir().expect("tempdir");
    let memory = dir.path().join("vehicle");
    let fixture =
        |n: &str| Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("fixtures/data/{n}.mcap"));
    let status_at_end = |log: &str| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_fdd"))
            .arg("replay")
            .arg(fixture(log))
            .arg("--no-progress")
            .arg("--memory")
            .arg(&memory)
            .env_remove("RUST_LOG")
            .output()
            .expect("run fdd");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let first = status_at_end("throttle_tps_open");
    assert!(
        first.contains("P0122-16 tps_circuit_low") && first.contains("0x27"),
        "{first}"
    );
    let between = status_at_end("intake_leak");
    assert!(between.contains("P2279-00"), "{between}");
    let second = status_at_end("throttle_tps_open");
    // Confirmed in the second failed cycle, with the MIL on: 0xAF at the end of the log.
    let line = second
        .lines()
        .find(|l| l.contains("P0122-16 tps_circuit_low"))
        .expect("DTC line");
    assert!(line.trim_end().to_lowercase().ends_with("0xaf"), "{second}");
    // The intake DTC survived the throttle replays (its monitor was not in their runtime).
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let (rt, _) = Runtime::builder(cfg)
        .persistence(&memory)
        .build()
        .expect("runtime");
    let leak: Dtc = "P2279-00".parse().expect("dtc");
    assert!(
        rt.status(leak).expect("configured").contains(0x20),
        "testFailedSinceLastClear kept"
    );
}
