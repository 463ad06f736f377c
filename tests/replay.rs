//! End-to-end checks of `fdd replay`: the committed fixtures, logs with bad input written here
//! (one problem each, at a known topic and time), remapped signal names, the outputs, and the
//! CLI's exit status and messages.

use std::fs;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use fdd::replay::{replay, ProblemKind, ReplayOptions, ReplaySummary, RuntimeConfig};
use fdd_diagnostics::event::DiagnosticEvent;
use fdd_monitor::log::{LogReader, LogWriter, MotorVoltage, ReadMode, TpsVoltage, Wattmeter};
use serde_json::json;

const MS: u64 = 1_000_000;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/data")
        .join(format!("{name}.mcap"))
}

fn default_config() -> RuntimeConfig {
    RuntimeConfig::load(None).expect("embedded config")
}

fn run_lib(log: &Path, opts: &ReplayOptions) -> ReplaySummary {
    replay(log, &default_config(), opts).expect("replay runs")
}

fn fdd(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fdd"))
        .args(args)
        .env_remove("RUST_LOG")
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("run fdd")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Writes the three throttle sensor topics at 1 kHz for `frames` frames; `edit(k, writer)` is
/// called for each frame and returns which of (motor voltage, tps, wattmeter) to write as usual.
fn write_sensors(
    path: &Path,
    frames: u64,
    mut edit: impl FnMut(u64, &mut LogWriter<std::io::BufWriter<fs::File>>) -> [bool; 3],
) {
    let mut w = LogWriter::create(path).expect("create log");
    for k in 0..frames {
        let t = k * MS;
        let x = (k as f64 * 0.01).sin();
        let [mv, tps, wm] = edit(k, &mut w);
        if mv {
            w.write_message(
                t,
                &MotorVoltage {
                    voltage_v: 0.5 + 0.2 * x,
                },
            )
            .expect("write");
        }
        if tps {
            w.write_message(t, &TpsVoltage { voltage_v: 1.0 + x })
                .expect("write");
        }
        if wm {
            w.write_message(
                t,
                &Wattmeter {
                    power_w: 0.3 + 0.1 * x,
                },
            )
            .expect("write");
        }
    }
    w.finish().expect("finish");
}

/// Removes the summary from an MCAP file's footer: readers then read it linearly, in file order
/// (as they do a file from a writer that wrote no index).
fn strip_summary(path: &Path) {
    let mut bytes = fs::read(path).expect("read");
    let footer = bytes.len() - 37;
    assert_eq!(bytes[footer], 0x02, "footer opcode");
    bytes[footer + 9..footer + 17].fill(0); // summary_start
    bytes[footer + 25..footer + 29].fill(0); // summary_crc
    fs::write(path, bytes).expect("write");
}

fn read_events(path: &Path) -> Vec<DiagnosticEvent> {
    let f = fs::File::open(path).expect("events file");
    BufReader::new(f)
        .lines()
        .map(|l| {
            let l = l.expect("line");
            serde_json::from_str::<DiagnosticEvent>(&l)
                .unwrap_or_else(|e| panic!("not a DiagnosticEvent: {e}: {l}"))
        })
        .collect()
}

#[test]
fn nominal_fixture_raises_nothing_and_events_file_is_json_lines() {
    let dir = tempfile::tempdir().expect("tempdir");
    let events = dir.path().join("events.jsonl");
    let s = run_lib(
        &fixture("throttle_nominal"),
        &ReplayOptions {
            events: Some(events.clone()),
            ..Default::default()
        },
    );
    assert_eq!(s.read_mode, ReadMode::Indexed);
    assert_eq!(s.messages, 480_000);
    assert_eq!(s.frames, 120_000);
    assert!(s.problems.is_empty(), "{:?}", s.problems);
    assert_eq!(s.missing_signals().count(), 0);
    assert_eq!(s.dtcs_raised().count(), 0, "{:?}", s.dtcs);
    assert!(s.stopped_early.is_none());
    assert_eq!(s.operation_cycles, 1);
    let truth = s.truth.as_ref().expect("the fixture has ground truth");
    assert!(truth.faults.is_empty());
    assert!(s
        .monitors
        .iter()
        .any(|m| m.name == "staleness" && m.steps == 120_000));
    // The events file holds every status change (here: each test completing for the first
    // time: the three "no signal" tests and the throttle monitor's), none with testFailed.
    let evs = read_events(&events);
    assert_eq!(evs.len() as u64, s.events);
    assert_eq!(s.events_file, Some((events.clone(), s.events)));
    assert!(evs.iter().all(|e| !e.status_after.test_failed()), "{evs:?}");
    assert_eq!(evs.iter().filter(|e| e.dtc.ftb == 0x31).count(), 3);
    assert!(s
        .monitors
        .iter()
        .any(|m| m.name == "throttle" && m.steps == 120_000));
}

#[test]
fn fault_fixture_reports_onset_from_truth() {
    let s = run_lib(&fixture("throttle_tps_open"), &ReplayOptions::default());
    let truth = s.truth.as_ref().expect("ground truth");
    assert_eq!(truth.faults.len(), 1);
    assert_eq!(truth.faults[0].fault, "tps_open");
    assert_eq!(truth.faults[0].onset_ns, 10_000 * MS);
    let table = s.render();
    assert!(table.contains("Ground truth"), "{table}");
    assert!(table.contains("tps_open"), "{table}");
}

#[test]
fn missing_channel_is_a_no_signal_dtc() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("no_wattmeter.mcap");
    write_sensors(&log, 500, |_, _| [true, true, false]);
    let events = dir.path().join("events.jsonl");
    let s = run_lib(
        &log,
        &ReplayOptions {
            events: Some(events.clone()),
            ..Default::default()
        },
    );
    let missing: Vec<_> = s.missing_signals().map(|m| m.name.as_str()).collect();
    assert_eq!(missing, ["wattmeter"]);
    let raised: Vec<_> = s.dtcs_raised().collect();
    assert_eq!(raised.len(), 1, "{raised:?}");
    assert_eq!(raised[0].event, "wattmeter_no_signal");
    assert_eq!(raised[0].dtc.to_string(), "P1650-31");
    assert_eq!(raised[0].dtc.ftb, 0x31);
    // Missing after the 5 ms start-up grace: the first check after it is at 6 ms.
    let at = raised[0].first_failed_s.expect("time");
    assert!((at - 0.006).abs() < 1e-9, "{at}");
    let table = s.render();
    assert!(table.contains("MISSING"), "{table}");
    assert!(table.contains("P1650-31"), "{table}");
    let evs = read_events(&events);
    assert!(evs
        .iter()
        .any(|e| e.event == "wattmeter_no_signal" && e.status_after.test_failed()));
}

#[test]
fn bad_messages_are_counted_with_topic_and_time_and_replay_goes_on() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("bad.mcap");
    write_sensors(&log, 100, |k, w| {
        let t = k * MS;
        match k {
            20 => {
                w.write_raw_json("/throttle/tps", t, b"{\"voltage_v\": 1.0,")
                    .expect("write");
                [true, false, true]
            }
            30 => {
                w.write("/throttle/wattmeter", t, &json!({"power": 0.3}))
                    .expect("write");
                [true, true, false]
            }
            40 => {
                w.write_raw_json("/throttle/motor_voltage", t, b"{\"voltage_v\": null}")
                    .expect("write");
                [false, true, true]
            }
            50 => {
                // A second TPS sample at the same time.
                w.write_message(t, &TpsVoltage { voltage_v: 1.0 })
                    .expect("write");
                [true, true, true]
            }
            _ => [true, true, true],
        }
    });
    let s = run_lib(&log, &ReplayOptions::default());
    let check = |kind: ProblemKind, topic: &str, ms: u64| {
        let p = s
            .problem(kind, topic)
            .unwrap_or_else(|| panic!("no {kind:?} on {topic}: {:?}", s.problems));
        assert_eq!(p.count, 1, "{p:?}");
        assert_eq!(p.first_time_ns, Some(ms * MS), "{p:?}");
        assert!(p.first_message.contains("bad.mcap"), "{p:?}");
        assert!(p.first_message.contains(topic), "{p:?}");
    };
    check(ProblemKind::InvalidJson, "/throttle/tps", 20);
    check(ProblemKind::MissingField, "/throttle/wattmeter", 30);
    check(ProblemKind::NonFinite, "/throttle/motor_voltage", 40);
    check(ProblemKind::TimeRepeated, "/throttle/tps", 50);
    assert_eq!(s.problems.len(), 4, "{:?}", s.problems);
    assert_eq!(s.messages, 301);
    assert!(s.stopped_early.is_none());
    let tps = s.signals.iter().find(|x| x.name == "tps").expect("tps");
    assert_eq!((tps.samples, tps.rejected), (99, 2));
    // Single lost samples are far below max_age: nothing raised, nothing missing.
    assert_eq!(s.dtcs_raised().count(), 0);
    assert_eq!(s.missing_signals().count(), 0);

    // The CLI: exit 0, and the summary names each problem.
    let out = fdd(&["replay", log.to_str().expect("utf-8")]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    // Shown with --nocapture.
    println!("{stdout}\n{}", text(&out.stderr));
    for needle in [
        "invalid JSON",
        "missing field",
        "NaN or infinite value",
        "timestamp repeats",
        "/throttle/wattmeter",
        "0.020",
        "0.030",
    ] {
        assert!(stdout.contains(needle), "{needle} not in\n{stdout}");
    }
    // The first occurrences are also logged (warn is the default level).
    assert!(text(&out.stderr).contains("invalid JSON"));
}

#[test]
fn backwards_timestamp_in_a_linearly_read_log_is_counted() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("backwards.mcap");
    write_sensors(&log, 100, |k, w| {
        if k == 61 {
            // A TPS sample stamped 55 ms written after the one at 60 ms.
            w.write_message(55 * MS, &TpsVoltage { voltage_v: 1.0 })
                .expect("write");
        }
        [true, true, true]
    });
    strip_summary(&log);
    let s = run_lib(&log, &ReplayOptions::default());
    assert_eq!(s.read_mode, ReadMode::Linear);
    assert!(s.stopped_early.is_none(), "{:?}", s.stopped_early);
    let p = s
        .problem(ProblemKind::TimeBackwards, "/throttle/tps")
        .unwrap_or_else(|| panic!("{:?}", s.problems));
    assert_eq!((p.count, p.first_time_ns), (1, Some(55 * MS)));
    assert!(p.first_message.contains("backwards"), "{p:?}");
    assert_eq!(s.problems.len(), 1, "{:?}", s.problems);
    assert_eq!(s.messages, 301);
    let out = fdd(&["replay", log.to_str().expect("utf-8")]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("timestamp goes backwards"));
}

#[test]
fn a_long_gap_starts_a_new_operation_cycle() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("gap.mcap");
    let mut w = LogWriter::create(&log).expect("create");
    for k in (0..100u64).chain(30_000..30_100) {
        let t = k * MS;
        w.write_message(t, &MotorVoltage { voltage_v: 0.5 })
            .expect("w");
        w.write_message(t, &TpsVoltage { voltage_v: 1.0 })
            .expect("w");
        w.write_message(t, &Wattmeter { power_w: 0.3 }).expect("w");
    }
    w.finish().expect("finish");
    let s = run_lib(&log, &ReplayOptions::default());
    assert_eq!(s.operation_cycles, 2);
    let p = s
        .problem(ProblemKind::TimeGap, "/throttle/motor_voltage")
        .expect("gap");
    assert_eq!((p.count, p.first_time_ns), (1, Some(30_000 * MS)));
    // 100 + 100 steps (plus none through the 29.9 s pause), and no staleness across it.
    assert_eq!(s.monitors[0].steps, 200);
    assert_eq!(s.dtcs_raised().count(), 0, "{:?}", s.dtcs);
}

#[test]
fn truncated_log_is_read_up_to_the_cut_and_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("half.mcap");
    let bytes = fs::read(fixture("throttle_nominal")).expect("fixture");
    fs::write(&log, &bytes[..bytes.len() / 2]).expect("write");
    let s = run_lib(&log, &ReplayOptions::default());
    let e = s.stopped_early.as_deref().expect("stopped early");
    assert!(e.contains("half.mcap") && e.contains("truncated"), "{e}");
    assert!(s.messages > 100_000, "{}", s.messages);
    assert_eq!(s.read_mode, ReadMode::Linear);

    let out = fdd(&["replay", log.to_str().expect("utf-8")]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains("half.mcap") && stderr.contains("truncated"),
        "{stderr}"
    );
    // The summary of what was read is printed first.
    assert!(text(&out.stdout).contains("STOPPED EARLY"));
}

#[test]
fn non_mcap_file_fails_naming_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("notes.mcap");
    fs::write(&log, "this is not an MCAP file\n").expect("write");
    let out = fdd(&["replay", log.to_str().expect("utf-8")]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("notes.mcap"), "{stderr}");
    assert!(stderr.contains("not an MCAP file"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let out = fdd(&["replay", "/nonexistent/run.mcap"]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("/nonexistent/run.mcap"));
}

#[test]
fn unknown_config_key_is_an_error_naming_file_and_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = dir.path().join("mine.toml");
    let text_cfg = fdd::replay::config::DEFAULT_RUNTIME_TOML
        .replace("check_period_s = 0.001", "check_periode_s = 0.001");
    fs::write(&cfg, text_cfg).expect("write");
    let e = RuntimeConfig::load(Some(&cfg)).unwrap_err().to_string();
    assert!(
        e.contains("mine.toml") && e.contains("check_periode_s"),
        "{e}"
    );
    let log = fixture("throttle_tps_open");
    let out = fdd(&[
        "replay",
        log.to_str().expect("utf-8"),
        "--config",
        cfg.to_str().expect("utf-8"),
    ]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("mine.toml") && stderr.contains("check_periode_s"),
        "{stderr}"
    );
}

#[test]
fn out_writes_an_mcap_of_the_outputs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("no_wattmeter.mcap");
    write_sensors(&log, 200, |_, _| [true, true, false]);
    let out = dir.path().join("out.mcap");
    let s = run_lib(
        &log,
        &ReplayOptions {
            out: Some(out.clone()),
            ..Default::default()
        },
    );
    let mut reader = LogReader::open(&out).expect("readable output");
    assert_eq!(reader.mode(), ReadMode::Indexed);
    let (mut events, mut status) = (Vec::new(), Vec::new());
    let mut per_step = 0u64;
    for m in reader.by_ref() {
        let m = m.expect("message");
        match &*m.topic {
            "/fdd/events" => events.push(m.decode::<DiagnosticEvent>().expect("event")),
            "/fdd/dtc_status" => status.push(
                m.decode::<fdd_monitor::log::DtcStatusMsg>()
                    .expect("status"),
            ),
            "/fdd/throttle/position"
            | "/fdd/throttle/innovation"
            | "/fdd/tests"
            | "/fdd/diagnosis" => per_step += 1,
            other => panic!("unexpected topic {other}"),
        }
    }
    assert_eq!(events.len() as u64, s.events);
    assert!(events
        .iter()
        .any(|e| e.event == "wattmeter_no_signal" && e.status_after.test_failed()));
    assert!(status
        .iter()
        .any(|m| m.dtc == "P1650-31" && m.status & 0x01 == 0x01));
    assert!(
        per_step > 0,
        "the throttle monitor's per-step outputs are written"
    );
    assert_eq!(
        s.out_file,
        Some((out, events.len() as u64 + status.len() as u64 + per_step))
    );
}

#[test]
fn remapped_config_replays_a_log_with_other_names() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("other_names.mcap");
    let schema = r#"{"type": "object"}"#;
    let mut w = LogWriter::create(&log).expect("create");
    for topic in ["/car/etc/motor", "/car/etc/sensors"] {
        w.add_topic(topic, "test.Any", schema).expect("topic");
    }
    for k in 0..300u64 {
        let t = k * MS;
        w.write("/car/etc/motor", t, &json!({"u": 0.5})).expect("w");
        w.write(
            "/car/etc/sensors",
            t,
            &json!({"position": {"volts": 1.2}, "power": {"watts": 0.3}}),
        )
        .expect("w");
    }
    w.finish().expect("finish");

    // With the default mapping nothing matches: every enabled monitor runs (a log with none of
    // any monitor's topics is taken as mis-mapped) and every signal they read is missing (the
    // turbo and wheel monitors are off by default: their nine and thirteen signals are not
    // watched).
    let s = run_lib(&log, &ReplayOptions::default());
    let n = RuntimeConfig::load(None).expect("default").signals.len();
    assert_eq!(n, 30, "3 throttle, 5 intake, 9 turbo and 13 wheel signals");
    assert_eq!(s.missing_signals().count(), 8);
    assert_eq!(s.dtcs_raised().count(), 8);

    let cfg_text = r#"
[[signals]]
name = "motor_voltage"
topic = "/car/etc/motor"
field = "u"
max_age_s = 0.005
stale_dtc = "P2100-31"

[[signals]]
name = "tps"
topic = "/car/etc/sensors"
field = "position.volts"
max_age_s = 0.005
stale_dtc = "P0120-31"

[[signals]]
name = "wattmeter"
topic = "/car/etc/sensors"
field = "power.watts"
max_age_s = 0.005
stale_dtc = "P1650-31"
"#;
    let cfg_path = dir.path().join("car.toml");
    fs::write(&cfg_path, cfg_text).expect("write");
    let cfg = RuntimeConfig::load(Some(&cfg_path)).expect("valid config");
    let s = replay(&log, &cfg, &ReplayOptions::default()).expect("replay");
    assert!(s.problems.is_empty(), "{:?}", s.problems);
    assert_eq!(s.missing_signals().count(), 0);
    assert_eq!(s.dtcs_raised().count(), 0, "{:?}", s.dtcs);
    for sg in &s.signals {
        assert_eq!(sg.samples, 300, "{sg:?}");
    }
    assert!(s.truth.is_none());
    // The same through the CLI.
    let out = fdd(&[
        "replay",
        log.to_str().expect("utf-8"),
        "--config",
        cfg_path.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("signal tps (position.volts)"));
}

#[test]
fn verbosity_chooses_what_fdd_logs_about_itself() {
    let log = fixture("throttle_tps_open");
    let log = log.to_str().expect("utf-8");
    let quiet = fdd(&["replay", log]);
    assert!(quiet.status.success());
    assert!(
        !text(&quiet.stderr).contains("INFO"),
        "{}",
        text(&quiet.stderr)
    );
    let v = fdd(&["-v", "replay", log]);
    let stderr = text(&v.stderr);
    assert!(v.status.success());
    for needle in [
        "runtime configuration loaded",
        "monitor `staleness` started",
        "replay finished",
    ] {
        assert!(stderr.contains(needle), "{needle} not in\n{stderr}");
    }
    // Never one line per step or message at info.
    assert!(stderr.lines().count() < 20, "{stderr}");
    let rust_log = Command::new(env!("CARGO_BIN_EXE_fdd"))
        .args(["replay", log])
        .env("RUST_LOG", "info")
        .output()
        .expect("run");
    assert!(text(&rust_log.stderr).contains("replay finished"));
}

/// The intake fixtures through `fdd replay`'s library entry on the default configuration: the
/// intake monitor runs (the throttle monitor does not, and its signals are not watched), each
/// fault raises exactly its specific DTC (after the group DTC P0068-00 where isolation took
/// longer than `group_after_s`), and the summary carries the observable driving time before
/// the first DTC from the truth's `fault_observable`.
#[test]
fn intake_fixtures_replay_with_their_dtc() {
    for (name, dtc) in [
        ("intake_map_bias", "P0106-64"),
        ("intake_maf_gain", "P0101-64"),
        ("intake_egr_stuck_open", "P0402-00"),
        ("intake_egr_stuck_closed", "P0401-00"),
        ("intake_leak", "P2279-00"),
    ] {
        let s = run_lib(&fixture(name), &ReplayOptions::default());
        assert!(s.problems.is_empty(), "{name}: {:?}", s.problems);
        assert_eq!(s.missing_signals().count(), 0, "{name}");
        let names: Vec<&str> = s.monitors.iter().map(|m| m.name.as_str()).collect();
        assert!(
            names.contains(&"intake") && !names.contains(&"throttle"),
            "{names:?}"
        );
        const GROUP: &str = "P0068-00";
        let raised: Vec<String> = s
            .dtcs_raised()
            .map(|d| d.dtc.to_string())
            .filter(|d| d != GROUP)
            .collect();
        assert_eq!(raised, vec![dtc.to_string()], "{name}");
        let truth = s.truth.as_ref().expect("ground truth");
        assert_eq!(truth.faults.len(), 1, "{name}");
        let f = &truth.faults[0];
        let (d, _, first) = f.detected.as_ref().expect("detected");
        assert!(
            d.to_string() == dtc || d.to_string() == GROUP,
            "{name}: {d}"
        );
        // The specific DTC's time (the output switches when the fault is named).
        let at = &s
            .dtcs
            .iter()
            .find(|r| r.dtc.to_string() == dtc)
            .and_then(|r| r.first_failed_s)
            .expect("specific DTC time");
        assert!(*at >= *first, "{name}");
        let observable = f
            .observable_ns
            .expect("the intake truth reports observability");
        let wall = first - f.onset_ns as f64 * 1e-9;
        assert!(
            observable as f64 * 1e-9 <= wall + 0.05,
            "{name}: observable {observable} ns of {wall} s"
        );
        // From the DTC on, the output comes from the local filter the fault leaves sound (the
        // MAF-only one after a MAP fault, the MAP-only one otherwise): unbiased.
        let e = &truth.estimates[0];
        assert_eq!(e.estimate, "manifold_pressure");
        let switched = e.switched_at_ns.expect("the output switched") as f64 * 1e-9;
        // The DTC is stamped with the segment's time, the output with the poll step (<= 1 ms on).
        assert!(
            (0.0..=1e-3).contains(&(switched - at)),
            "{name}: switch at {switched} s, DTC at {at} s"
        );
        let after = e.error_after_switch.expect("errors after the switch");
        println!(
            "{name}: pressure error after the switch mean {:.0} std {:.0} Pa",
            after.mean, after.std
        );
        assert!(
            after.mean.abs() < 300.0 && after.std < 1200.0,
            "{name}: {after:?}"
        );
    }
    let s = run_lib(&fixture("intake_nominal"), &ReplayOptions::default());
    assert_eq!(s.dtcs_raised().count(), 0, "{:?}", s.dtcs);
    let e = s.truth.as_ref().expect("truth").estimates[0]
        .error_all
        .expect("compared");
    assert!(e.std < 1000.0 && e.mean.abs() < 200.0, "{e:?}");
}

/// `--out` of an intake replay carries the intake outputs on their own topics, and the file
/// passes the official Python reader with CRC and JSON-schema checks (`tools/check_mcap.py`;
/// in CI a missing reader is a failure).
#[test]
fn intake_replay_output_passes_the_official_reader() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("intake_out.mcap");
    let s = run_lib(
        &fixture("intake_map_bias"),
        &ReplayOptions {
            out: Some(out.clone()),
            ..ReplayOptions::default()
        },
    );
    assert!(s.stopped_early.is_none());
    let mut reader = LogReader::open(&out).expect("output readable");
    let (mut estimates, mut innovations, mut sources) = (0u64, 0u64, Vec::<String>::new());
    while let Some(m) = reader.next_message() {
        let m = m.expect("message");
        match m.topic {
            "/fdd/intake/estimate" => {
                estimates += 1;
                let j = m.json().expect("json");
                let src = j["source"].as_str().expect("source").to_string();
                if !sources.contains(&src) {
                    sources.push(src);
                }
            }
            "/fdd/intake/innovation" => innovations += 1,
            _ => {}
        }
    }
    assert!(
        estimates > 6000 && innovations > 12_000,
        "{estimates} {innovations}"
    );
    assert_eq!(
        sources,
        vec!["centralized_ekf", "maf_local_ekf"],
        "switch on the MAP fault"
    );
    if !fdd_testkit::python_modules_available("mcap.reader, jsonschema") {
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/check_mcap.py");
    let o = Command::new("python3")
        .arg(script)
        .arg(&out)
        .output()
        .expect("python3 runs");
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}
