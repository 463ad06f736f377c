//! A healthy throttle driven stop to stop at full speed (a `mixed` drive's burst of full-range
//! swings, 0 to 90 deg within a quarter second, at about 660 s), on a plant 1 % off Table I
//! whose plate rebounds from its stops (restitution 0.3): at its 3.5 A peaks the model's
//! current reads up to about 10 % off the wattmeter. The wattmeter tests' dead band allowed 4 %
//! of the predicted reading and named a healthy wattmeter failed (P1651) at 663.6 s (held-out
//! version 4, log 05, whose scenario this is, cut at 670 s); with 6 % nothing is raised.

use std::path::Path;
use std::process::Command;

const SCENARIO: &str = r#"name = "throttle_fast_swings"
monitor = "throttle"
duration_s = 670.0
seed = 11005

[excitation]
kind = "mixed"

[sensors]
wattmeter_noise_std_w = 0.25
tps_noise_std_v = 0.005
tps_gain = 1.017644
tps_offset_v = 0.014645
wattmeter_gain = 0.988559
tps_lag_s = 0.002
wattmeter_lag_s = 0.003

[plant]
table1_rel_error = 0.01
table1_max_draws = 500
stop_restitution = 0.3
process_noise_scale = 2.0

[fault]
kind = "none"
"#;

#[test]
fn full_speed_swings_between_the_stops_raise_no_wattmeter_dtc() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("throttle_fast_swings.toml");
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
    assert_eq!(log["dtcs"].as_array().map(Vec::len), Some(0), "{log}");
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
    assert_eq!(v["monitors"][0]["false_alarms"], 0, "{v}");
}
