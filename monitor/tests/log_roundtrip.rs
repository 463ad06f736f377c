//! Writing and reading back every message type; reproducible bytes; per-message decode errors.

mod log_common;

use std::io::{Cursor, Seek, SeekFrom, Write};

use fdd_diagnostics::event::DiagnosticEvent;
use fdd_monitor::log::*;
use log_common::*;

#[test]
fn reader_and_writer_can_move_to_another_thread() {
    fn send<T: Send>() {}
    send::<LogReader>();
    send::<LogWriter<std::io::BufWriter<std::fs::File>>>();
    send::<OwnedLogMessage>();
    send::<LogError>();
}

#[test]
fn every_message_type_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("all.mcap");
    let mut w = LogWriter::create(&path).unwrap();
    write_examples(&mut w, 5_000_000_000).unwrap();
    assert_eq!(w.messages_written(), 10);
    w.finish().unwrap();

    let mut r = LogReader::open(&path).unwrap();
    assert_eq!(r.mode(), ReadMode::Indexed);
    assert_eq!(r.message_count(), Some(10));
    assert_eq!(r.time_range_ns(), Some((5_000_000_000, 5_003_000_000)));
    // Every topic has its jsonschema schema and json encoding.
    for t in TOPICS {
        let ch = r.channel(t.topic).unwrap_or_else(|| panic!("{}", t.topic));
        assert_eq!(ch.message_encoding, "json");
        let s = ch.schema.as_ref().unwrap();
        assert_eq!(s.name, t.schema_name);
        assert_eq!(s.encoding, "jsonschema");
        assert_eq!(s.data, t.schema.as_bytes());
    }

    let e = examples();
    let mut n = 0;
    let mut events = Vec::new();
    while let Some(m) = r.next_message() {
        let m = m.unwrap();
        n += 1;
        assert_eq!(m.publish_time_ns, m.log_time_ns);
        assert_eq!(m.file(), path.as_path());
        match m.topic {
            "/throttle/motor_voltage" => {
                assert_eq!(m.decode::<MotorVoltage>().unwrap(), e.motor);
                assert_eq!(m.field_f64("voltage_v").unwrap(), 0.31);
            }
            "/throttle/tps" => assert_eq!(m.decode::<TpsVoltage>().unwrap(), e.tps),
            "/throttle/wattmeter" => {
                // NaN was written as null and reads back as NaN.
                assert_eq!(m.data, br#"{"power_w":null}"#);
                assert!(m.decode::<Wattmeter>().unwrap().power_w.is_nan());
                assert!(m.field_f64("power_w").unwrap().is_nan());
            }
            "/truth/throttle" => assert_eq!(m.decode::<ThrottleTruth>().unwrap(), e.truth),
            "/fdd/throttle/position" => {
                assert_eq!(m.decode::<PositionEstimate>().unwrap(), e.position)
            }
            "/fdd/throttle/innovation" => {
                let got: InnovationMsg = m.decode().unwrap();
                assert_eq!(got.filter, e.innovation.filter);
                assert_eq!(got.dof, 2);
                assert_eq!(got.residual[0], 0.01);
                assert!(got.residual[1].is_nan());
                assert_eq!(got.variance, e.innovation.variance);
                assert_eq!(got.nis, e.innovation.nis);
            }
            "/fdd/tests" => {
                let got: TestStatistic = m.decode().unwrap();
                assert!(got.value.is_nan());
                assert_eq!((got.min, got.max), (0.0, 31.4));
                assert_eq!(got.verdict, "NOT_TESTED");
            }
            "/fdd/dtc_status" => assert_eq!(m.decode::<DtcStatusMsg>().unwrap(), e.dtc),
            "/fdd/events" => {
                events.push(m.decode::<DiagnosticEvent>().unwrap());
                assert_eq!(m.field_f64("test_result.max").ok(), {
                    let v: serde_json::Value = m.json().unwrap();
                    v["test_result"]["max"].as_f64()
                });
            }
            other => panic!("unexpected topic {other}"),
        }
    }
    assert_eq!(n, 10);
    assert_eq!(events, vec![e.event, e.event_no_result]);
    assert_eq!(r.stats().messages, 10);
}

#[test]
fn the_same_messages_give_byte_identical_files() {
    let write = |chunk_size| {
        to_bytes(
            WriteOptions {
                chunk_size,
                ..WriteOptions::default()
            },
            |w| {
                write_examples(w, 0)?;
                write_inputs(w, 5_000)?;
                write_examples(w, 10_000_000_000)
            },
        )
    };
    for chunk_size in [512, WriteOptions::DEFAULT_CHUNK_SIZE] {
        let a = write(chunk_size);
        let b = write(chunk_size);
        assert!(a.len() > 1000);
        assert!(a == b, "chunk size {chunk_size}: the two files differ");
    }
    // Files written through LogWriter::create too.
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = Vec::new();
    for name in ["a.mcap", "b.mcap"] {
        let path = dir.path().join(name);
        let mut w = LogWriter::create(&path).unwrap();
        write_examples(&mut w, 0).unwrap();
        write_inputs(&mut w, 2_000).unwrap();
        w.finish().unwrap();
        bytes.push(std::fs::read(&path).unwrap());
    }
    assert_eq!(bytes[0], bytes[1]);
    // The header names the library and pins the profile.
    let lib = LIBRARY.as_bytes();
    assert!(bytes[0].windows(lib.len()).any(|w| w == lib));
    assert!(!bytes[0].windows(9).any(|w| w == b"mcap-rust"));
}

#[test]
fn uncompressed_files_without_message_indexes_read_back_too() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.mcap");
    let bytes = to_bytes(
        WriteOptions {
            chunk_size: 300,
            compression: ChunkCompression::None,
            message_indexes: false,
        },
        |w| write_inputs(w, 100),
    );
    std::fs::write(&path, &bytes).unwrap();
    let msgs = read_all(&path, ReadOptions::default()).unwrap();
    assert_eq!(msgs.len(), 300);
    let validated = read_all(
        &path,
        ReadOptions {
            validate_crcs: true,
            ..ReadOptions::default()
        },
    )
    .unwrap();
    assert_eq!(msgs, validated);
}

#[test]
fn custom_topics_and_topic_errors() {
    let mut w = LogWriter::new(Cursor::new(Vec::new()), "custom.mcap").unwrap();
    // Unknown topic: an error naming the file and topic.
    let e = w
        .write("/engine/speed", 0, &serde_json::json!({"rpm": 800.0}))
        .unwrap_err();
    assert!(matches!(e, LogError::UnknownTopic { .. }));
    assert!(e.to_string().contains("custom.mcap"), "{e}");
    assert!(e.to_string().contains("/engine/speed"), "{e}");
    // Bad schemas.
    assert!(matches!(
        w.add_topic("/engine/speed", "x", "not json"),
        Err(LogError::BadSchema { .. })
    ));
    assert!(matches!(
        w.add_topic("/engine/speed", "x", "[1]"),
        Err(LogError::BadSchema { .. })
    ));
    let schema = r#"{"type": "object", "properties": {"rpm": {"type": "number"}}}"#;
    w.add_topic("/engine/speed", "demo.Speed", schema).unwrap();
    w.add_topic("/engine/speed", "demo.Speed", schema).unwrap();
    assert!(matches!(
        w.add_topic("/engine/speed", "demo.Speed2", schema),
        Err(LogError::BadSchema { .. })
    ));
    w.write("/engine/speed", 7, &serde_json::json!({"rpm": 800.0}))
        .unwrap();
    let bytes = w.finish().unwrap().into_inner();

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("custom.mcap");
    std::fs::write(&path, bytes).unwrap();
    let mut r = LogReader::open(&path).unwrap();
    let ch = r.channel("/engine/speed").unwrap();
    assert_eq!(ch.schema.as_ref().unwrap().name, "demo.Speed");
    let m = r.next_message().unwrap().unwrap();
    assert_eq!((m.topic, m.log_time_ns), ("/engine/speed", 7));
    assert_eq!(m.field_f64("rpm").unwrap(), 800.0);
}

#[test]
fn bad_json_and_missing_fields_are_reported_per_message_and_reading_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad_json.mcap");
    let mut w = LogWriter::create(&path).unwrap();
    w.write_message(1_000, &TpsVoltage { voltage_v: 1.0 })
        .unwrap();
    w.write_raw_json("/throttle/tps", 2_000, b"{\"voltage_v\": 1.")
        .unwrap();
    w.write_raw_json("/throttle/tps", 3_000, br#"{"volts": 1.0}"#)
        .unwrap();
    w.write_raw_json("/throttle/tps", 4_000, br#"{"voltage_v": "high"}"#)
        .unwrap();
    w.write_message(5_000, &TpsVoltage { voltage_v: 2.0 })
        .unwrap();
    w.finish().unwrap();

    let mut r = LogReader::open(&path).unwrap();
    let mut values = Vec::new();
    let mut errors = Vec::new();
    while let Some(m) = r.next_message() {
        let m = m.unwrap(); // the framing is fine: only decoding fails
        match m.field_f64("voltage_v") {
            Ok(v) => values.push((m.log_time_ns, v)),
            Err(e) => {
                assert!(!e.is_fatal());
                assert_eq!(e.topic(), Some("/throttle/tps"));
                assert_eq!(e.log_time_ns(), Some(m.log_time_ns));
                assert_eq!(e.file(), path.as_path());
                assert!(e.offset().is_some());
                // The typed decode reports the same kind of problem.
                let typed = m.decode::<TpsVoltage>().unwrap_err();
                assert_eq!(typed.log_time_ns(), Some(m.log_time_ns));
                errors.push((e, typed));
            }
        }
    }
    assert_eq!(values, vec![(1_000, 1.0), (5_000, 2.0)]);
    assert_eq!(errors.len(), 3);
    let msg = |e: &LogError| e.to_string();
    assert!(matches!(errors[0].0, LogError::InvalidJson { .. }));
    assert!(matches!(errors[0].1, LogError::InvalidJson { .. }));
    assert!(matches!(&errors[1].0, LogError::MissingField { field, .. } if field == "voltage_v"));
    assert!(matches!(&errors[1].1, LogError::MissingField { field, .. } if field == "voltage_v"));
    assert!(matches!(
        &errors[2].0,
        LogError::NotANumber {
            found: "a string",
            ..
        }
    ));
    assert!(matches!(errors[2].1, LogError::WrongShape { .. }));
    for (a, b) in &errors {
        for e in [a, b] {
            let text = msg(e);
            assert!(text.contains("bad_json.mcap"), "{text}");
            assert!(text.contains("/throttle/tps"), "{text}");
            assert!(text.contains(" ns"), "{text}");
        }
    }
    assert!(msg(&errors[1].0).contains("'voltage_v' is missing"));
}

/// A sink that fails after `limit` bytes, to check that write and finish errors surface.
#[derive(Debug)]
struct FailingSink {
    inner: Cursor<Vec<u8>>,
    limit: usize,
}

impl Write for FailingSink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.inner.get_ref().len() + buf.len() > self.limit {
            return Err(std::io::Error::other("disk full"));
        }
        self.inner.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for FailingSink {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.inner.seek(pos)
    }
}

#[test]
fn write_and_finish_errors_name_the_file() {
    // Failing during the writes.
    let sink = FailingSink {
        inner: Cursor::new(Vec::new()),
        limit: 4_000,
    };
    let mut w = LogWriter::with_options(
        sink,
        "full_disk.mcap",
        WriteOptions {
            chunk_size: 256,
            ..WriteOptions::default()
        },
    )
    .unwrap();
    let err = (0..10_000u64)
        .find_map(|k| {
            w.write_message(
                k,
                &TpsVoltage {
                    voltage_v: k as f64,
                },
            )
            .err()
        })
        .expect("the sink fills up");
    assert!(err.is_fatal());
    let text = err.to_string();
    assert!(text.contains("full_disk.mcap"), "{text}");
    assert!(text.contains("/throttle/tps"), "{text}");
    assert!(w.finish().is_err());

    // Failing only in finish (the summary does not fit).
    let mut probe = LogWriter::new(Cursor::new(Vec::new()), "probe").unwrap();
    probe
        .write_message(1, &TpsVoltage { voltage_v: 1.0 })
        .unwrap();
    let full = probe.finish().unwrap().into_inner().len();
    let sink = FailingSink {
        inner: Cursor::new(Vec::new()),
        limit: full - 20,
    };
    let mut w = LogWriter::new(sink, "short.mcap").unwrap();
    w.write_message(1, &TpsVoltage { voltage_v: 1.0 }).unwrap();
    let err = w.finish().unwrap_err();
    assert!(matches!(err, LogError::Write { .. }));
    assert!(err.to_string().contains("short.mcap"), "{err}");
}

#[test]
fn missing_and_non_mcap_files_are_fatal_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.mcap");
    let e = LogReader::open(&missing).unwrap_err();
    assert!(matches!(e, LogError::Open { .. }) && e.is_fatal());
    assert!(e.to_string().contains("nope.mcap"), "{e}");

    let text = dir.path().join("text.mcap");
    std::fs::write(&text, "time,voltage\n0,1.0\n").unwrap();
    let e = LogReader::open(&text).unwrap_err();
    assert!(matches!(e, LogError::NotMcap { .. }) && e.is_fatal());
    assert!(e.to_string().contains("text.mcap"), "{e}");

    let empty = dir.path().join("empty.mcap");
    std::fs::write(&empty, "").unwrap();
    let e = LogReader::open(&empty).unwrap_err();
    assert!(matches!(e, LogError::Truncated { offset: 0, .. }), "{e}");

    let e = LogReader::open(dir.path()).unwrap_err();
    assert!(matches!(e, LogError::Open { .. }), "{e}");
}

#[test]
fn topic_filter_skips_other_channels() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("filter.mcap");
    std::fs::write(
        &path,
        to_bytes(
            WriteOptions {
                chunk_size: 1000,
                ..WriteOptions::default()
            },
            |w| write_inputs(w, 200),
        ),
    )
    .unwrap();
    let msgs = read_all(
        &path,
        ReadOptions {
            topics: Some(vec!["/throttle/wattmeter".into()]),
            ..ReadOptions::default()
        },
    )
    .unwrap();
    assert_eq!(msgs.len(), 200);
    assert!(msgs.iter().all(|m| m.0 == "/throttle/wattmeter"));
    // The owned iterator gives the same as the borrowed one.
    let owned: Vec<_> = LogReader::open(&path)
        .unwrap()
        .map(|m| m.unwrap())
        .collect();
    assert_eq!(owned.len(), 600);
    assert_eq!(&*owned[2].topic, "/throttle/wattmeter");
    assert_eq!(owned[2].decode::<Wattmeter>().unwrap().power_w, 0.0);
}
