//! Writes a small sample file with every topic (for `tools/check_mcap.py`, the independent check
//! with the official Python MCAP reader), and runs that check when Python and the `mcap` package
//! are installed.
//!
//! The sample goes to `$FDD_MCAP_SAMPLE` if set, else to `<target>/tmp/log_sample.mcap`; a file
//! that the check must reject goes next to it as `log_sample_bad.mcap`.

mod log_common;

use std::path::{Path, PathBuf};
use std::process::Command;

use fdd_monitor::log::*;
use log_common::*;

fn sample_path() -> PathBuf {
    match std::env::var_os("FDD_MCAP_SAMPLE") {
        Some(p) => PathBuf::from(p),
        None => Path::new(env!("CARGO_TARGET_TMPDIR")).join("log_sample.mcap"),
    }
}

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/check_mcap.py")
}

fn run_check(path: &Path) -> (bool, String) {
    let out = Command::new("python3")
        .arg(script())
        .arg(path)
        .output()
        .expect("run python3");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

#[test]
fn sample_file_passes_the_python_check() {
    let path = sample_path();
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    let mut w = LogWriter::create_with(
        &path,
        WriteOptions {
            chunk_size: 16 * 1024,
            ..WriteOptions::default()
        },
    )
    .unwrap();
    write_examples(&mut w, 0).unwrap();
    write_inputs(&mut w, 1_000).unwrap();
    write_examples(&mut w, 2_000_000_000).unwrap();
    w.finish().unwrap();
    let n = read_all(&path, ReadOptions::default()).unwrap().len();
    assert_eq!(n, 3_020);

    // A file the check must reject: invalid JSON, and a message that breaks its schema.
    let bad = path.with_file_name("log_sample_bad.mcap");
    let mut w = LogWriter::create(&bad).unwrap();
    w.write_message(1, &TpsVoltage { voltage_v: 1.0 }).unwrap();
    w.write_raw_json("/throttle/tps", 2, b"{\"voltage_v\": 1.")
        .unwrap();
    w.write_raw_json(
        "/fdd/dtc_status",
        3,
        br#"{"dtc": "P0123-1C", "status": 300}"#,
    )
    .unwrap();
    w.finish().unwrap();

    // Late messages: chunks overlap in time. The Python reader must agree on the log-time
    // order (the check fails if log times go backwards).
    let unordered = path.with_file_name("log_sample_unordered.mcap");
    let mut w = LogWriter::create_with(
        &unordered,
        WriteOptions {
            chunk_size: 512,
            ..WriteOptions::default()
        },
    )
    .unwrap();
    for k in 0..500u64 {
        let t = 1_000_000_000 + k * 1_000_000 - if k % 9 == 0 { 30_000_000 } else { 0 };
        w.write_message(
            t,
            &TpsVoltage {
                voltage_v: k as f64,
            },
        )
        .unwrap();
    }
    w.finish().unwrap();

    if !fdd_testkit::python_modules_available("mcap.reader") {
        println!("sample written to {}", path.display());
        return;
    }
    let (ok, text) = run_check(&path);
    println!("{text}");
    assert!(ok, "check_mcap.py rejected the sample:\n{text}");
    assert!(text.contains("OK: 3020 messages on 9 topics"), "{text}");

    let (ok, text) = run_check(&unordered);
    println!("{text}");
    assert!(ok, "check_mcap.py rejected the unordered sample:\n{text}");

    let (ok, text) = run_check(&bad);
    println!("{text}");
    assert!(!ok, "check_mcap.py accepted a bad file:\n{text}");
    assert!(
        text.contains("/throttle/tps at 2 ns: invalid JSON"),
        "{text}"
    );
    if text.contains("schemas validated") {
        assert!(
            text.contains("/fdd/dtc_status at 3 ns: does not match schema"),
            "{text}"
        );
    }
}
