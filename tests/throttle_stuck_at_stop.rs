//! A TPS that sticks while the plate rests at the open stop, on a TPS 1.8 % high in gain (it
//! clips at 5 V there, so the stuck reading is the rail): the frozen test leaves clipped
//! readings alone (a healthy TPS repeats 5 V at the stop), and the combined filter, which
//! follows the TPS, never rules the stop out when the plate leaves it. Held-out version 5, log
//! 12 (whose scenario this is, cut at 470 s): never detected. The rail check now also asks the
//! wattmeter-only filter, which does not see the TPS, once it has ruled the stop out for
//! `watt_rail_persist_s` (1 s): P0123 at 456.8 s, 3.8 s after the onset.

use std::path::Path;
use std::process::Command;

const SCENARIO: &str = r#"name = "throttle_stuck_at_the_stop"
monitor = "throttle"
duration_s = 470.0
seed = 13012

[excitation]
kind = "steady_holds"

[sensors]
wattmeter_noise_std_w = 0.35
tps_noise_std_v = 0.003
tps_gain = 1.018399
tps_offset_v = 0.001838
wattmeter_gain = 1.027344
tps_lag_s = 0.001
wattmeter_lag_s = 0.003

[plant]
table1_rel_error = 0.015
table1_max_draws = 500
stop_restitution = 0.1
process_noise_scale = 0.5

[fault]
kind = "tps_stuck"
start_s = 453.0
"#;

#[test]
fn a_tps_stuck_at_the_stop_reading_is_named_when_the_plate_leaves_the_stop() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("throttle_stuck_at_the_stop.toml");
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
    let first_tps = log["dtcs"]
        .as_array()
        .expect("dtcs")
        .iter()
        .filter_map(|d| d.as_str())
        .find(|d| d.starts_with("P012"))
        .and_then(|d| d.rsplit("@ ").next())
        .and_then(|t| t.trim().parse::<f64>().ok());
    assert!(
        first_tps.is_some_and(|t| (453.0..463.0).contains(&t)),
        "a TPS DTC within 10 s of the onset at 453 s: {log}"
    );
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}
