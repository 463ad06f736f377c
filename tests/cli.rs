//! The CLI as a user on another machine meets it: bundled scenarios (`fdd simulate --list`,
//! a name found without the source tree), scenario files relative to the working directory,
//! no log written over its own scenario, and a closed stdout (`fdd replay ... | head`) ending
//! the program quietly.

use std::path::Path;
use std::process::{Command, Stdio};

fn fdd() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_fdd"));
    c.env_remove("RUST_LOG").env_remove("RUST_BACKTRACE");
    c
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn bundled_scenarios_are_listed_and_found_outside_the_source_tree() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = fdd()
        .args(["simulate", "--list"])
        .current_dir(dir.path())
        .output()
        .expect("run");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for (name, _) in fdd_fixtures::bundled::BUNDLED {
        assert!(text.contains(name), "{name} missing from:\n{text}");
    }
    assert!(
        text.contains("throttle_tps_open") && text.contains("tps_open from 10 s"),
        "{text}"
    );

    // By name, from a directory without fixtures/: the bundled copy, byte for byte the fixture.
    let log = dir.path().join("open.mcap");
    let out = fdd()
        .args(["simulate", "throttle_tps_open", "-o"])
        .arg(&log)
        .current_dir(dir.path())
        .output()
        .expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let want = std::fs::read(root().join("fixtures/data/throttle_tps_open.mcap")).expect("fixture");
    assert_eq!(std::fs::read(&log).expect("written"), want);
}

#[test]
fn a_scenario_file_is_found_relative_to_the_working_directory_and_not_overwritten() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(root().join("fixtures/scenarios/throttle_tps_open.toml"))
        .expect("scenario")
        .replace("name = \"throttle_tps_open\"", "name = \"throttle_mine\"")
        .replace("duration_s = 20.0", "duration_s = 2.0")
        .replace("start_s = 10.0", "start_s = 1.0");
    std::fs::write(dir.path().join("throttle_mine.toml"), text).expect("write");
    let out = fdd()
        .args(["simulate", "throttle_mine", "-o", "mine.mcap"])
        .current_dir(dir.path())
        .output()
        .expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("2000 frames"));

    let out = fdd()
        .args(["simulate", "throttle_mine.toml", "-o", "throttle_mine.toml"])
        .current_dir(dir.path())
        .output()
        .expect("run");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("refusing to write the log over its own scenario file"),
        "{err}"
    );
    assert!(
        std::fs::read_to_string(dir.path().join("throttle_mine.toml"))
            .expect("still there")
            .contains("throttle_mine")
    );

    let out = fdd()
        .args(["simulate", "throttle_nope", "-o", "x.mcap"])
        .current_dir(dir.path())
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("no scenario `throttle_nope`"),
        "{err}"
    );
}

#[test]
fn a_closed_stdout_ends_the_replay_quietly() {
    let mut child = fdd()
        .arg("replay")
        .arg(root().join("fixtures/data/throttle_tps_open.mcap"))
        .arg("--no-progress")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    // The reader goes away before fdd prints its summary (as `| head -0` would).
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("wait");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.status.success(), "{:?}: {err}", out.status);
}

/// `fdd evaluate --json` on `inputs` (relative to the repository root), which must succeed;
/// its report.
fn evaluate_json(inputs: &[&str]) -> serde_json::Value {
    let out = fdd()
        .args(["evaluate", "--json"])
        .args(inputs.iter().map(|p| root().join(p)))
        .output()
        .expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("json")
}

/// `fdd evaluate` on a log and a scenario file (simulated on the fly): the JSON figures say
/// what happened, and each episode is judged against the right fault type.
#[test]
fn evaluate_scores_logs_and_scenarios_against_their_truth() {
    let v = evaluate_json(&[
        "fixtures/data/throttle_tps_open.mcap",
        "fixtures/scenarios/throttle_wattmeter.toml",
    ]);
    assert_eq!(v["logs"].as_array().map(Vec::len), Some(2));
    let m = &v["monitors"][0];
    assert_eq!(m["monitor"], "throttle");
    assert_eq!(m["logs"], 2);
    // No fault-free sample is flagged on either log before its onset (10 s each).
    assert_eq!(m["fault_free_flagged"], 0);
    assert_eq!(m["false_dtcs"], 0);
    let tdr = m["tdr"].as_f64().expect("tdr");
    assert!(tdr > 0.9 && tdr <= 1.0, "TDR {tdr}");
    let class = |name: &str| {
        m["classes"]
            .as_array()
            .and_then(|c| c.iter().find(|c| c["class"] == name))
            .unwrap_or_else(|| panic!("class {name}"))
            .clone()
    };
    for name in ["tps_open", "wattmeter"] {
        let c = class(name);
        assert_eq!(c["episodes"], 1, "{name}: {c}");
        assert_eq!(c["correct_dtc"], 1, "{name}: {c}");
        assert_eq!(c["wrong_dtc"], 0, "{name}: {c}");
    }
    assert_eq!(class("tps_bias")["episodes"], 0);
    // The TPS-open log switched the position output to the wattmeter estimate at its DTC
    // (10.02 s) and reports the error from then on; the wattmeter fault switches nothing.
    let switched = &v["logs"][0]["after_switch"];
    assert_eq!(switched.as_array().map(Vec::len), Some(1), "{switched}");
    assert_eq!(switched[0]["estimate"], "throttle_angle");
    let at = switched[0]["switched_at_s"].as_f64().expect("time");
    assert!((10.0..10.1).contains(&at), "switched at {at}");
    let std = switched[0]["std"].as_f64().expect("std");
    assert!(
        std > 0.5 && std < 7.0,
        "error std after the switch {std} deg"
    );
    assert_eq!(
        v["logs"][1]["after_switch"].as_array().map(Vec::len),
        Some(0)
    );

    // The tables name the figures; a file that is neither a log nor a scenario is refused.
    let out = fdd()
        .arg("evaluate")
        .arg(root().join("fixtures/data/throttle_tps_open.mcap"))
        .output()
        .expect("run");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("TDR") && text.contains("tps_open"), "{text}");
    assert!(
        text.contains("throttle_angle after its source switched: 1 logs"),
        "{text}"
    );
    let out = fdd()
        .arg("evaluate")
        .arg(root().join("README.md"))
        .output()
        .expect("run");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("README.md") && err.contains("neither"),
        "{err}"
    );
}

/// `fdd evaluate --json` says in which log the false alarms and false DTCs fell: a healthy
/// plant beyond the default configuration's range (the intake calibration set's training log:
/// false DTCs with the default) beside the nominal intake fixture (none).
#[test]
fn evaluate_counts_false_alarms_per_log() {
    let v = evaluate_json(&[
        "fixtures/data/intake_nominal.mcap",
        "fixtures/sets/intake_calibrate_train",
    ]);
    let logs = v["logs"].as_array().expect("logs");
    assert_eq!(logs.len(), 2);
    let count = |l: &serde_json::Value, k: &str| l[k].as_u64().expect("count");
    assert_eq!(count(&logs[0], "false_dtcs"), 0, "{}", logs[0]);
    assert_eq!(count(&logs[0], "false_alarms"), 0, "{}", logs[0]);
    assert!(count(&logs[1], "false_dtcs") > 0, "{}", logs[1]);
    let m = &v["monitors"][0];
    assert_eq!(m["monitor"], "intake");
    for k in ["false_dtcs", "false_alarms"] {
        let total: u64 = logs.iter().map(|l| count(l, k)).sum();
        assert_eq!(m[k].as_u64(), Some(total), "{k}: {v}");
    }
}
