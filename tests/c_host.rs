//! The C ABI from C: `examples/c/host.c`, compiled with `gcc -Wall -Wextra -Werror` and as
//! C++ with `g++` against the static library, replays fixtures' samples (`fdd replay
//! --samples`) and reports exactly the DTC status changes `fdd replay --events` reports;
//! under valgrind it leaks nothing and touches no invalid memory. Python's `ctypes` drives
//! the shared library as a second host.
//!
//! The libraries are built here with `cargo rustc -p fdd-monitor --features ffi
//! --crate-type staticlib --crate-type cdylib` into this test's own target directory.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use serde_json::Value;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The target directory and profile directory cargo built this test into.
fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    // target/<profile>/deps/c_host-<hash>
    exe.parent()
        .and_then(Path::parent)
        .expect("target/<profile>")
        .to_path_buf()
}

fn run(cmd: &mut Command) -> std::process::Output {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Builds `libfdd_monitor.a` / `.so` (once per test binary) and the C and C++ programs;
/// returns the directory of the programs and the profile directory of the libraries.
fn built() -> &'static (PathBuf, PathBuf) {
    static BUILT: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    BUILT.get_or_init(|| {
        let profile = profile_dir();
        let target = profile.parent().expect("target dir");
        let mut cargo = Command::new(env!("CARGO"));
        cargo
            .current_dir(root())
            .env("CARGO_TARGET_DIR", target)
            .args(["rustc", "-p", "fdd-monitor", "--features", "ffi"])
            .args(["--crate-type", "staticlib", "--crate-type", "cdylib"]);
        match profile.file_name().and_then(|n| n.to_str()) {
            Some("release") => {
                cargo.arg("--release");
            }
            Some("debug") => {}
            Some(other) => {
                cargo.args(["--profile", other]);
            }
            None => panic!("no profile directory in {}", profile.display()),
        }
        run(&mut cargo);
        let build = profile.join("c-host");
        run(Command::new("make")
            .arg("-C")
            .arg(root().join("examples/c"))
            .arg(format!("LIBDIR={}", profile.display()))
            .arg(format!("BUILD={}", build.display())));
        (build, profile)
    })
}

/// `(time_s, dtc, status before, status after, event)` of one status change.
type Change = (f64, String, u8, u8, String);

/// Replays `fixture` with `fdd replay`, writing its samples and events; returns the events.
fn replay(fixture: &str, dir: &Path) -> (PathBuf, Vec<Change>) {
    let log = root().join(format!("fixtures/data/{fixture}.mcap"));
    let samples = dir.join(format!("{fixture}.csv"));
    let events = dir.join(format!("{fixture}.jsonl"));
    run(Command::new(env!("CARGO_BIN_EXE_fdd"))
        .arg("replay")
        .arg(&log)
        .arg("--samples")
        .arg(&samples)
        .arg("--events")
        .arg(&events)
        .arg("--no-progress"));
    let text = std::fs::read_to_string(&events).expect("events file");
    let changes = text
        .lines()
        .map(|l| {
            let v: Value = serde_json::from_str(l).expect("JSON line");
            (
                v["time_s"].as_f64().expect("time_s"),
                v["dtc"].as_str().expect("dtc").to_string(),
                v["status_before"].as_u64().expect("status_before") as u8,
                v["status_after"].as_u64().expect("status_after") as u8,
                v["event"].as_str().expect("event").to_string(),
            )
        })
        .collect();
    (samples, changes)
}

/// The `EVENT` lines of the host's output.
fn host_changes(stdout: &str) -> Vec<Change> {
    stdout
        .lines()
        .filter_map(|l| l.strip_prefix("EVENT "))
        .map(|l| {
            let f: Vec<&str> = l.split(' ').collect();
            assert_eq!(f.len(), 6, "EVENT line {l:?}");
            let hex = |s: &str| u8::from_str_radix(s.trim_start_matches("0x"), 16).expect("hex");
            (
                f[1].parse().expect("time_s"),
                f[2].to_string(),
                hex(f[3]),
                hex(f[4]),
                f[5].to_string(),
            )
        })
        .collect()
}

fn check_fixture(fixture: &str, monitors: &str, raised: &[&str]) {
    let (build, _) = built();
    let dir = tempfile::tempdir().expect("tempdir");
    let (samples, expected) = replay(fixture, dir.path());
    // Not a comparison of two empty lists: the fixture's DTCs are raised.
    for dtc in raised {
        assert!(
            expected
                .iter()
                .any(|c| c.1 == *dtc && c.2 & 1 == 0 && c.3 & 1 == 1),
            "{fixture}: fdd replay does not raise {dtc}: {expected:?}"
        );
    }
    for program in ["host", "host_cxx"] {
        let out = run(Command::new(build.join(program))
            .arg(&samples)
            .arg(monitors));
        let stdout = String::from_utf8_lossy(&out.stdout);
        let got = host_changes(&stdout);
        // Times equal to the last bit, but serde_json's default float parsing (of the events
        // file) may be one unit in the last place off the correctly rounded value.
        let same = |a: Option<&Change>, b: Option<&Change>| match (a, b) {
            (Some(a), Some(b)) => {
                (a.0 - b.0).abs() <= 2.0 * f64::EPSILON * a.0.abs()
                    && (&a.1, a.2, a.3, &a.4) == (&b.1, b.2, b.3, &b.4)
            }
            _ => false,
        };
        let n = got.len().max(expected.len());
        if let Some(k) = (0..n).find(|&k| !same(got.get(k), expected.get(k))) {
            panic!(
                "{fixture}: {program}'s status change {k} differs from fdd replay's: {:?} against {:?} ({} and {} changes)\n{stdout}",
                got.get(k),
                expected.get(k),
                got.len(),
                expected.len()
            );
        }
        // The DTC memory read by status mask, and the clear.
        for dtc in raised {
            assert!(
                stdout.contains(&format!("  {dtc}  0x")),
                "{fixture}: {program} does not list {dtc} by status mask:\n{stdout}"
            );
        }
        assert!(
            stdout.contains("DTCs with any failure bit after the clear: 0"),
            "{stdout}"
        );
        assert!(stdout.contains("  json {\"t_ns\":"), "{stdout}");
    }
}

#[test]
fn tps_open_events_equal_the_replays() {
    check_fixture("throttle_tps_open", "throttle", &["P0122-16", "P2106-00"]);
    // The position output switched to the wattmeter estimate, read through the ABI.
    let (build, _) = built();
    let dir = tempfile::tempdir().expect("tempdir");
    let (samples, _) = replay("throttle_tps_open", dir.path());
    let out = run(Command::new(build.join("host"))
        .arg(&samples)
        .arg("throttle"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("from wattmeter_estimate"), "{stdout}");
}

#[test]
fn tps_bias_events_equal_the_replays() {
    check_fixture("throttle_tps_bias", "throttle", &["P0121-64"]);
}

#[test]
fn intake_leak_events_equal_the_replays() {
    check_fixture("intake_leak", "intake", &["P2279-00"]);
}

#[test]
fn the_c_host_leaks_nothing_under_valgrind() {
    let (build, _) = built();
    let dir = tempfile::tempdir().expect("tempdir");
    let (samples, _) = replay("throttle_tps_open", dir.path());
    let out = run(Command::new("valgrind")
        .args([
            "--leak-check=full",
            "--show-leak-kinds=definite,indirect,possible",
        ])
        .args(["--errors-for-leak-kinds=definite,indirect,possible"])
        .args(["--error-exitcode=1", "-q"])
        .arg(build.join("host"))
        .arg(&samples)
        .arg("throttle"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("definitely lost") && !stderr.contains("Invalid"),
        "{stderr}"
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("P0122-16"));
}

#[test]
fn python_ctypes_drives_the_shared_library() {
    let (_, profile) = built();
    let lib = profile.join("libfdd_monitor.so");
    run(Command::new("python3")
        .arg(root().join("tests/data/ffi_ctypes.py"))
        .arg(&lib));
}
