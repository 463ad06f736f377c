//! A TPS shorted to its 5 V rail while the plate rests near the open stop, behind a TPS 2 %
//! high in gain (a healthy sensor clips at 5 V there): the circuit fault heals at the stop,
//! since the wattmeter estimate cannot rule the rail reading out, and must fail again when the
//! plate leaves the stop. Before the fix the combined filter took the shorted TPS back, followed
//! it to 90 deg and never ruled it out again, and the position output trusted the short for the
//! rest of the drive (error std 9.0 deg after the switch in this scenario; 20.7 deg in held-out
//! log 30 of version 4). With the wattmeter-only filter judging rail readings after such a heal,
//! the output stays within the throttle issue's 7 deg.

use std::path::Path;
use std::process::Command;

const SCENARIO: &str = r#"name = "throttle_short_holds_2"
monitor = "throttle"
duration_s = 150.0
seed = 2

[excitation]
kind = "steady_holds"
level_v = [0.2, 1.2]
hold_s = [4.0, 8.0]

[sensors]
tps_gain = 1.02

[fault]
kind = "tps_short"
start_s = 20.0
"#;

#[test]
fn a_short_that_heals_at_the_stop_fails_again_when_the_plate_leaves_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("throttle_short_holds_2.toml");
    std::fs::write(&path, SCENARIO).expect("write scenario");
    let out = Command::new(env!("CARGO_BIN_EXE_fdd"))
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")))
        .args(["evaluate", "--json"])
        .arg(&path)
        .output()
        .expect("run fdd");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    let log = &v["logs"][0];
    let dtcs: Vec<&str> = log["dtcs"]
        .as_array()
        .expect("dtcs")
        .iter()
        .filter_map(|d| d.as_str())
        .collect();
    assert!(
        dtcs.iter()
            .all(|d| d.starts_with("P0123-17") || d.starts_with("P2106-00")),
        "only the short and the switch: {dtcs:?}"
    );
    let switched = &log["after_switch"][0];
    assert_eq!(switched["estimate"], "throttle_angle", "{log}");
    let std = switched["std"].as_f64().expect("std");
    assert!(
        std < 7.0,
        "position error std after the switch {std:.2} deg"
    );
    // Judging rail readings by the wattmeter-only filter raises nothing before the short.
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}
