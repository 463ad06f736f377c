//! Throttle scenarios that once went wrong, replayed through `fdd evaluate --json` (each a
//! regression test of the fix named in its comment).

use std::path::Path;
use std::process::Command;

/// Writes `scenario` as `<name>.toml` in a temporary directory, runs `fdd evaluate --json` on
/// it and returns the parsed report.
fn evaluate(name: &str, scenario: &str) -> serde_json::Value {
    evaluate_with(name, scenario, "")
}

/// The position output after the switch to the wattmeter estimate: the issue's 7 deg std.
fn assert_position_within_7_deg_after_the_switch(log: &serde_json::Value) {
    let switched = &log["after_switch"][0];
    assert_eq!(switched["estimate"], "throttle_angle", "{log}");
    let std = switched["std"].as_f64().expect("std");
    assert!(
        std <= 7.0,
        "position error std after the switch {std:.2} deg"
    );
}

/// As [`evaluate`], with `monitor_keys` (TOML lines) as the throttle config's `[monitor]` table
/// over the embedded defaults (none: the embedded configuration).
fn evaluate_with(name: &str, scenario: &str, monitor_keys: &str) -> serde_json::Value {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(format!("{name}.toml"));
    std::fs::write(&path, scenario).expect("write scenario");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_fdd"));
    cmd.current_dir(Path::new(env!("CARGO_MANIFEST_DIR")))
        .args(["evaluate", "--json"]);
    if !monitor_keys.is_empty() {
        let throttle = dir.path().join("throttle.toml");
        let text = fdd::config::DEFAULT_THROTTLE_TOML;
        assert!(
            !text.contains("\n[monitor]"),
            "the default has no [monitor] table"
        );
        std::fs::write(&throttle, format!("{text}\n[monitor]\n{monitor_keys}\n"))
            .expect("write throttle config");
        let runtime = dir.path().join("fdd.toml");
        let runtime_text = fdd::replay::config::DEFAULT_RUNTIME_TOML.replace(
            "throttle = true",
            &format!(
                "throttle = true\nthrottle_config = {:?}",
                throttle.display().to_string()
            ),
        );
        std::fs::write(&runtime, runtime_text).expect("write runtime config");
        cmd.arg("--config").arg(&runtime);
    }
    let out = cmd.arg(&path).output().expect("run fdd");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("json")
}

/// The time (s) of the first DTC in `log` whose code starts with `prefix`.
fn first_dtc_s(log: &serde_json::Value, prefix: &str) -> Option<f64> {
    log["dtcs"]
        .as_array()
        .expect("dtcs")
        .iter()
        .filter_map(|d| d.as_str())
        .find(|d| d.starts_with(prefix))
        .and_then(|d| d.rsplit("@ ").next())
        .and_then(|t| t.trim().parse::<f64>().ok())
}

// A TPS shorted to its 5 V rail while the plate rests near the open stop, behind a TPS 2 %
// high in gain (a healthy sensor clips at 5 V there): the circuit fault heals at the stop,
// since the wattmeter estimate cannot rule the rail reading out, and must fail again when the
// plate leaves the stop. Before the fix the combined filter took the shorted TPS back, followed
// it to 90 deg and never ruled it out again, and the position output trusted the short for the
// rest of the drive (error std 9.0 deg after the switch in this scenario; 20.7 deg in held-out
// log 30 of version 4). With the wattmeter-only filter judging rail readings after such a heal,
// the output stays within the throttle issue's 7 deg.
const THROTTLE_SHORT_HOLDS_2: &str = r#"name = "throttle_short_holds_2"
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
    let v = evaluate("throttle_short_holds_2", THROTTLE_SHORT_HOLDS_2);
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
    assert_position_within_7_deg_after_the_switch(log);
    // Judging rail readings by the wattmeter-only filter raises nothing before the short.
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A healthy throttle driven stop to stop at full speed (a `mixed` drive's burst of full-range
// swings, 0 to 90 deg within a quarter second, at about 660 s), on a plant 1 % off Table I
// whose plate rebounds from its stops (restitution 0.3): at its 3.5 A peaks the model's
// current reads up to about 10 % off the wattmeter. The wattmeter tests' dead band allowed 4 %
// of the predicted reading and named a healthy wattmeter failed (P1651) at 663.6 s (held-out
// version 4, log 05, whose scenario this is, cut at 670 s); with 6 % nothing is raised.
const THROTTLE_FAST_SWINGS: &str = r#"name = "throttle_fast_swings"
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
    let v = evaluate("throttle_fast_swings", THROTTLE_FAST_SWINGS);
    let log = &v["logs"][0];
    assert_eq!(log["dtcs"].as_array().map(Vec::len), Some(0), "{log}");
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
    assert_eq!(v["monitors"][0]["false_alarms"], 0, "{v}");
}

// A TPS that sticks while the plate rests at the open stop, on a TPS 1.8 % high in gain (it
// clips at 5 V there, so the stuck reading is the rail): the frozen test leaves clipped
// readings alone (a healthy TPS repeats 5 V at the stop), and the combined filter, which
// follows the TPS, never rules the stop out when the plate leaves it. Held-out version 5, log
// 12 (whose scenario this is, cut at 470 s): never detected. The rail check now also asks the
// wattmeter-only filter, which does not see the TPS, once it has ruled the stop out for
// `watt_rail_persist_s` (1 s): P0123 at 456.8 s, 3.8 s after the onset. Since that filter
// allows the static map its error (`static_map_error_frac`: a quiet healthy plate on the open
// stop was named shorted), it rules the stop out only once the map has come down further: P0123
// at 473.1 s, 20.1 s after the onset.
const THROTTLE_STUCK_AT_THE_STOP: &str = r#"name = "throttle_stuck_at_the_stop"
monitor = "throttle"
duration_s = 490.0
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
    let v = evaluate("throttle_stuck_at_the_stop", THROTTLE_STUCK_AT_THE_STOP);
    let log = &v["logs"][0];
    let first_tps = first_dtc_s(log, "P012");
    assert!(
        first_tps.is_some_and(|t| (453.0..478.0).contains(&t)),
        "a TPS DTC within 25 s of the onset at 453 s: {log}"
    );
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A plate stuck at the closed stop behind a TPS 20 mV high with 8 mV of noise: its readings
// dip below `rail_low_v` (30 mV) by the noise every few samples. The stuck-plate test left any
// sample at a rail to the circuit checks, so each dip restarted its persistence and the plate
// was never named (held-out version 5, log 47, whose scenario this is, cut at 480 s). A TPS
// counts as at a rail only after `rail_persist_s` of rail readings in a row.
const THROTTLE_PLATE_STUCK_CLOSED: &str = r#"name = "throttle_plate_stuck_closed"
monitor = "throttle"
duration_s = 480.0
seed = 13047

[excitation]
kind = "mixed"

[sensors]
wattmeter_noise_std_w = 0.05
tps_noise_std_v = 0.008
tps_gain = 1.000412
tps_offset_v = 0.019752
wattmeter_gain = 0.952876
tps_lag_s = 0.001
wattmeter_lag_s = 0.001

[plant]
table1_rel_error = 0.01
table1_max_draws = 500
stop_restitution = 0.3
process_noise_scale = 1.0

[fault]
kind = "plate_stuck"
start_s = 468.0
"#;

#[test]
fn a_plate_stuck_at_the_closed_stop_is_named_despite_rail_band_dips() {
    let v = evaluate("throttle_plate_stuck_closed", THROTTLE_PLATE_STUCK_CLOSED);
    let log = &v["logs"][0];
    let plate = first_dtc_s(log, "P2119");
    assert!(
        plate.is_some_and(|t| (468.0..473.0).contains(&t)),
        "P2119 within 5 s of the onset at 468 s: {log}"
    );
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A TPS drift on a plate held near the open stop: the reading clips at 5 V (P0123, the
// position output goes to the wattmeter estimate), and when the plate comes down the drifted
// reading leaves the rail 25 deg above the plate. A circuit fault healed on any off-rail
// reading (the clause meant for rail readings the wattmeter estimate cannot rule out accepted
// every reading off the rails), so the output went back to the drifting TPS for 10 s (error
// std 11.5 deg after the switch; held-out version 5, log 48, whose scenario this is). Off-rail
// readings now heal only where they agree with the wattmeter estimate.
const THROTTLE_DRIFT_CLIPS: &str = r#"name = "throttle_drift_clips"
monitor = "throttle"
duration_s = 400.0
seed = 13048

[excitation]
kind = "steady_holds"

[sensors]
wattmeter_noise_std_w = 0.45
tps_noise_std_v = 0.003
tps_gain = 0.993205
tps_offset_v = -0.01234
wattmeter_gain = 0.963169

[plant]
table1_rel_error = 0.015
table1_max_draws = 500
stop_restitution = 0.0
process_noise_scale = 1.0

[fault]
kind = "tps_drift"
start_s = 300.0
end_s = 340.0
drift_deg_per_s = 1.684811
"#;

#[test]
fn a_drift_that_clipped_at_a_rail_does_not_take_the_position_back() {
    let v = evaluate("throttle_drift_clips", THROTTLE_DRIFT_CLIPS);
    let log = &v["logs"][0];
    assert_position_within_7_deg_after_the_switch(log);
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A healthy TPS 1 % high (it clips at 5 V at the open stop) on a `mixed` drive whose
// full-range swings end on that stop: the wattmeter-only filter lags the swing by about
// 0.15 s, and the drift rule, judged at one sample, named a TPS range/performance fault at
// 113.9 s (held-out version 5, log 53, whose plant and drive this is, without its faults).
// The disagreement must now hold for `decision_window_s`.
const THROTTLE_SWING_ONTO_THE_CLIPPED_STOP: &str = r#"name = "throttle_swing_onto_the_clipped_stop"
monitor = "throttle"
duration_s = 200.0
seed = 13053

[excitation]
kind = "mixed"

[sensors]
wattmeter_noise_std_w = 0.15
tps_noise_std_v = 0.003
tps_gain = 1.010107
tps_offset_v = 0.004113
wattmeter_gain = 1.044007

[plant]
table1_rel_error = 0.015
table1_max_draws = 500
stop_restitution = 0.1
process_noise_scale = 1.0

[fault]
kind = "none"
"#;

#[test]
fn a_swing_onto_the_clipped_stop_raises_no_tps_dtc() {
    let v = evaluate(
        "throttle_swing_onto_the_clipped_stop",
        THROTTLE_SWING_ONTO_THE_CLIPPED_STOP,
    );
    let log = &v["logs"][0];
    assert_eq!(log["dtcs"].as_array().map(Vec::len), Some(0), "{log}");
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A TPS open circuit at idle with small blips, behind a TPS 15 mV high with 8 mV of noise (a
// healthy one reads the rail band at the closed stop now and then): the rail reading is
// plausible at idle, and the blips, shorter than `watt_rail_persist_s`, are where the
// wattmeter-only filter sees the plate leave the stop. The drift rule names the TPS once the
// disagreement has held for `decision_window_s`; a persistence of 1 s lost this fault
// (held-out version 5, log 25, whose scenario this is, cut at 460 s).
const THROTTLE_OPEN_AT_IDLE: &str = r#"name = "throttle_open_at_idle"
monitor = "throttle"
duration_s = 460.0
seed = 13025

[excitation]
kind = "idle_blips"

[sensors]
wattmeter_noise_std_w = 0.15
tps_noise_std_v = 0.008
tps_gain = 0.989125
tps_offset_v = 0.014557
wattmeter_gain = 1.034889

[plant]
table1_rel_error = 0.01
table1_max_draws = 500
stop_restitution = 0.0
process_noise_scale = 1.0

[fault]
kind = "tps_open"
start_s = 451.0
"#;

#[test]
fn a_tps_open_at_idle_is_named_at_the_first_blips() {
    let v = evaluate("throttle_open_at_idle", THROTTLE_OPEN_AT_IDLE);
    let log = &v["logs"][0];
    let first_tps = first_dtc_s(log, "P012");
    assert!(
        first_tps.is_some_and(|t| (451.0..455.0).contains(&t)),
        "a TPS DTC within 4 s of the onset at 451 s: {log}"
    );
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A TPS drifting down at 2.8 deg/s on a `mixed` drive (held-out version 6, log 20, whose
// scenario this is, cut at 520 s). Two defects: the combined filter had followed the drift
// for the 7 s it took to name it, and went on from there on the wattmeter alone (error std
// 12.7 deg after the switch in version-6 log 21); and the drift, clipped at 0 V, healed 12 s
// later against a plate resting near the closed stop, so the output went back to the TPS,
// the combined filter followed it to 0 deg and a healthy wattmeter was named (P1651 at
// 503 s; 23 deg std after the switch). The combined filter now starts from the
// wattmeter-only filter's state when the TPS fails, and a range/performance fault does not
// heal on readings held at a rail.
const THROTTLE_DRIFT_TO_THE_CLOSED_RAIL: &str = r#"name = "throttle_drift_to_the_closed_rail"
monitor = "throttle"
duration_s = 520.0
seed = 15020

[excitation]
kind = "mixed"

[sensors]
wattmeter_noise_std_w = 0.25
tps_noise_std_v = 0.003
tps_gain = 1.004437
tps_offset_v = 0.003808
wattmeter_gain = 0.985364
tps_lag_s = 0.002
wattmeter_lag_s = 0.001

[plant]
table1_rel_error = 0.0
table1_max_draws = 500
stop_restitution = 0.0
process_noise_scale = 1.0

[fault]
kind = "tps_drift"
start_s = 472.0
drift_deg_per_s = -2.828587
"#;

#[test]
fn a_drift_clipped_at_the_closed_rail_neither_heals_nor_blames_the_wattmeter() {
    let v = evaluate(
        "throttle_drift_to_the_closed_rail",
        THROTTLE_DRIFT_TO_THE_CLOSED_RAIL,
    );
    let log = &v["logs"][0];
    let dtcs: Vec<&str> = log["dtcs"]
        .as_array()
        .expect("dtcs")
        .iter()
        .filter_map(|d| d.as_str())
        .collect();
    assert!(dtcs.iter().any(|d| d.starts_with("P0121")), "{log}");
    assert!(!dtcs.iter().any(|d| d.starts_with("P1651")), "{log}");
    let std = log["after_switch"][0]["std"].as_f64().expect("std");
    assert!(
        std < 7.0,
        "position error std after the switch {std:.2} deg"
    );
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A slow TPS drift (1.75 deg/s) on steady holds, named 28 s after its onset (held-out
// version 6, log 21, whose scenario this is): the combined filter had followed it by some
// 25 deg by then, and from there the wattmeter alone brought the angle back only slowly
// (error std 12.7 deg after the switch, mean -12.9). Starting the combined filter from the
// wattmeter-only filter's state at the switch: 1.4 deg.
const THROTTLE_SLOW_DRIFT_ON_HOLDS: &str = r#"name = "throttle_slow_drift_on_holds"
monitor = "throttle"
duration_s = 521.0
seed = 15021

[excitation]
kind = "steady_holds"

[sensors]
wattmeter_noise_std_w = 0.15
tps_noise_std_v = 0.005
tps_gain = 1.010928
tps_offset_v = 0.006719
wattmeter_gain = 0.984159
wattmeter_lag_s = 0.001

[plant]
table1_rel_error = 0.005
table1_max_draws = 500
stop_restitution = 0.1
process_noise_scale = 0.5

[fault]
kind = "tps_drift"
start_s = 461.0
drift_deg_per_s = -1.750462
"#;

#[test]
fn after_a_slow_drift_the_position_starts_from_the_wattmeter_only_estimate() {
    let v = evaluate("throttle_slow_drift_on_holds", THROTTLE_SLOW_DRIFT_ON_HOLDS);
    let log = &v["logs"][0];
    let switched = &log["after_switch"][0];
    let (mean, std) = (
        switched["mean"].as_f64().expect("mean"),
        switched["std"].as_f64().expect("std"),
    );
    assert!(
        std < 4.0 && mean.abs() < 4.0,
        "position error after the switch: mean {mean:.2}, std {std:.2} deg"
    );
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A plate stuck at 49 deg for 40 s of steady holds, behind a low-noise TPS (5 mV, about one ADC
// code): while the voltage holds it at a level whose static map lies just past
// `driven_range_deg` from the stuck angle, the static-while-driven condition flickers with the
// TPS noise. Its counter was reset at every miss and never reached `plate_persist_s` in 7 s of
// such a hold, so the plate was never named (held-out version 7, log 51, whose scenario this
// is). The counter now debounces up and down.
const THROTTLE_PLATE_STUCK_HOLDS: &str = r#"name = "throttle_plate_stuck_holds"
monitor = "throttle"
duration_s = 400.0
seed = 17051

[excitation]
kind = "steady_holds"

[sensors]
wattmeter_noise_std_w = 0.25
tps_noise_std_v = 0.005
tps_gain = 1.003667
tps_offset_v = 0.016596
wattmeter_gain = 0.950029
tps_lag_s = 0.001

[plant]
table1_rel_error = 0.005
table1_max_draws = 500
stop_restitution = 0.1
process_noise_scale = 2.0

[fault]
kind = "plate_stuck"
start_s = 300.0
end_s = 340.0
"#;

#[test]
fn a_plate_stuck_on_a_hold_just_past_the_driven_range_is_named() {
    let v = evaluate("throttle_plate_stuck_holds", THROTTLE_PLATE_STUCK_HOLDS);
    let log = &v["logs"][0];
    let plate = first_dtc_s(log, "P2119");
    // The hold that puts the static map 8 deg from the stuck angle starts at 317.5 s; the map
    // has moved 8 deg since the TPS stood still already at 301.8 s.
    assert!(
        plate.is_some_and(|t| (300.0..319.0).contains(&t)),
        "P2119 by 1.5 s into the hold at 317.5 s: {log}"
    );
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A fault-free plant 1.5 % off Table I whose plate rests on the open stop at a voltage the
// model's static map puts 12 deg short of it (the map is flat there), behind a TPS quieter than
// one ADC code: with the stuck-plate counter debounced, "static and 12 deg away from the map"
// held long enough to name a stuck plate (retired held-out version 7, log 0, whose scenario
// this is, cut after the false P2119 at 1437 s). "Away from the map" now counts only off the
// end stops.
const THROTTLE_OPEN_STOP_REST: &str = r#"name = "throttle_open_stop_rest"
monitor = "throttle"
duration_s = 1440.0
seed = 17000

[excitation]
kind = "steady_holds"

[sensors]
wattmeter_noise_std_w = 0.15
tps_noise_std_v = 0.003
tps_gain = 1.006457
tps_offset_v = -0.006618
wattmeter_gain = 0.969794
tps_lag_s = 0.002
wattmeter_lag_s = 0.003

[plant]
table1_rel_error = 0.015
table1_max_draws = 500
stop_restitution = 0.1
process_noise_scale = 0.5

[fault]
kind = "none"
"#;

#[test]
fn a_healthy_plate_resting_on_the_open_stop_is_not_named_stuck() {
    let v = evaluate("throttle_open_stop_rest", THROTTLE_OPEN_STOP_REST);
    let log = &v["logs"][0];
    assert_eq!(log["dtcs"].as_array().map(Vec::len), Some(0), "{log}");
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// A TPS that sticks during a steady hold, on holds whose levels lie a few degrees apart (the
// plate wanders about the hold by its process noise): a frozen TPS was named only when the
// static map moved `driven_range_deg` (8 deg), 25.9 s after the onset (retired held-out version
// 8, log 12, whose scenario this is, cut at 440 s). A frozen reading is itself the evidence, and
// its drive (`frozen_driven_range_deg`, 3 deg) only says the plate has left it: P0121 within
// half a second.
const THROTTLE_STUCK_ON_HOLDS: &str = r#"name = "throttle_stuck_on_holds"
monitor = "throttle"
duration_s = 440.0
seed = 19012

[excitation]
kind = "steady_holds"

[sensors]
wattmeter_noise_std_w = 0.45
tps_noise_std_v = 0.005
tps_gain = 0.985754
tps_offset_v = 0.009023
wattmeter_gain = 0.950485
tps_lag_s = 0.002
wattmeter_lag_s = 0.003

[plant]
table1_rel_error = 0.015
table1_max_draws = 500
stop_restitution = 0.1
process_noise_scale = 0.5

[fault]
kind = "tps_stuck"
start_s = 428.0
"#;

#[test]
fn a_tps_stuck_on_a_hold_is_named_without_waiting_for_a_large_move() {
    let v = evaluate("throttle_stuck_on_holds", THROTTLE_STUCK_ON_HOLDS);
    let log = &v["logs"][0];
    let stuck = first_dtc_s(log, "P0121");
    assert!(
        stuck.is_some_and(|t| (428.0..428.3).contains(&t)),
        "P0121 within 0.3 s of the onset at 428 s: {log}"
    );
    assert_eq!(v["monitors"][0]["false_dtcs"], 0, "{v}");
}

// The same stuck TPS with `frozen_alone_samples = 0` waits for the static map to move 3 deg
// away (428.49 s): 200 identical readings name it on their own, 0.2 s after the onset.
#[test]
fn a_tps_frozen_for_frozen_alone_samples_is_stuck_without_a_drive() {
    let v = evaluate_with(
        "throttle_stuck_on_holds",
        THROTTLE_STUCK_ON_HOLDS,
        "frozen_alone_samples = 0",
    );
    let log = &v["logs"][0];
    let stuck = first_dtc_s(log, "P0121");
    assert!(
        stuck.is_some_and(|t| (428.3..429.5).contains(&t)),
        "P0121 only once the plate left the reading: {log}"
    );
    let v = evaluate_with(
        "throttle_stuck_on_holds",
        THROTTLE_STUCK_ON_HOLDS,
        "frozen_alone_samples = 200",
    );
    let stuck = first_dtc_s(&v["logs"][0], "P0121");
    assert!(
        stuck.is_some_and(|t| (428.15..428.25).contains(&t)),
        "P0121 200 readings after the onset: {v}"
    );
}

/// A scenario of the tuning set's healing block (`fixtures/sets/throttle_tuning/<file>`).
fn tuning_scenario(file: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/sets/throttle_tuning")
        .join(file);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Asserts that the fault of a healing scenario (120 s to 160 s) was named with `dtc` and that
/// no flag outlived the evaluation's 10-s heal grace (a false alarm) and no DTC was false.
fn heals_within_the_grace(name: &str, dtc: &str) {
    let v = evaluate(name, &tuning_scenario(&format!("{name}.toml")));
    let log = &v["logs"][0];
    assert!(
        first_dtc_s(log, dtc).is_some_and(|t| (120.0..130.0).contains(&t)),
        "{dtc} named soon after 120 s: {log}"
    );
    assert_eq!(log["false_alarms"], 0, "healed within 10 s of 160 s: {log}");
    assert_eq!(log["false_dtcs"], 0, "{log}");
}

// A TPS stuck for 40 s that then moves again, behind a TPS a percent high that reads 5 V on
// the open stop: every sample of disagreement with the wattmeter estimate (which lags fast
// moves by up to 20 deg) restarted the 5-s heal, and so did each visit to the open stop, so
// the healed TPS stayed failed until 175.8 s. A stuck TPS now heals when it moves again and
// agrees with the estimate but for disagreements shorter than `heal_disagreement_s` (0.5 s),
// and rail readings neither count nor restart the heal.
#[test]
fn a_stuck_tps_that_moves_again_heals_within_the_grace() {
    heals_within_the_grace("throttle_tuning_51_tps_stuck_heals", "P0121");
}

// An open circuit that ends after 40 s: the healthy TPS then read 0 V with the plate on the
// closed stop, and the wattmeter-only filter (lagging the move by 0.3 s) ruled that reading
// out at once after the heal: the open circuit was named again 6.5 s after it had ended. After
// a healed circuit fault that filter rules rail readings out only over `decision_window_s`, and
// the heal forgives disagreements shorter than `heal_disagreement_s` (sample by sample it
// healed at 171.5 s).
#[test]
fn an_open_circuit_that_ends_is_not_named_again_at_the_closed_stop() {
    heals_within_the_grace("throttle_tuning_54_tps_open_heals", "P0122");
}

// A short that ends after 40 s, with the plate then swept onto the closed stop, where the
// TPS reads 0 V while the wattmeter estimate still puts the plate 15 deg higher: a reading at
// the other rail restarted the heal (healed at 170.9 s, then a healthy TPS named intermittent
// at 180.5 s). A reading at the other rail says nothing of a short.
#[test]
fn a_short_that_ends_heals_within_the_grace() {
    heals_within_the_grace("throttle_tuning_55_tps_short_heals", "P0123");
}

// A wattmeter offset that ends after 40 s: its heal waited for the combined filter's
// wattmeter test to stay quiet for 5 s, but with the wattmeter failed that filter's current
// comes from the model and the TPS alone, and on this plant (Table I 1.5 % off) model error
// failed that test every few seconds: never healed (80 s). The heal now asks the
// wattmeter-only test not to fail and that filter's angle to agree with the TPS.
#[test]
fn a_wattmeter_fault_that_ends_heals_within_the_grace() {
    heals_within_the_grace("throttle_tuning_58_wattmeter_heals", "P1651");
}

// A quiet plate (process noise x0.1; the sets' x0.5-2 make the plate wander 10-20 deg about a
// hold) of a plant 1.5 % off Table I on a chirp: at 1.05 V it rests at 67.8 deg where the
// model's static map says 76.3, and the TPS stands still. The plate test took the map sitting
// 8 deg from the TPS for a stuck plate (P2119 at 40.85 s); it now asks the map to move.
const THROTTLE_QUIET_CHIRP: &str = r#"name = "throttle_quiet_chirp"
monitor = "throttle"
duration_s = 60.0
seed = 1040

[excitation]
kind = "chirp"

[sensors]
wattmeter_noise_std_w = 0.1
tps_noise_std_v = 0.003
tps_gain = 1.001548
tps_offset_v = 0.015615
wattmeter_gain = 1.010756
wattmeter_lag_s = 0.003

[plant]
table1_rel_error = 0.015
table1_max_draws = 500
stop_restitution = 0.3
process_noise_scale = 0.1

[fault]
kind = "none"
"#;

#[test]
fn a_quiet_healthy_plate_away_from_the_static_map_is_not_named_stuck() {
    let v = evaluate("throttle_quiet_chirp", THROTTLE_QUIET_CHIRP);
    let log = &v["logs"][0];
    assert_eq!(log["dtcs"].as_array().map(Vec::len), Some(0), "{log}");
}

// A quiet plate (process noise x0.05) of a plant 1.5 % off Table I, stepped from 0.2 to 1 V:
// it chatters on the 8 deg mode boundary for 0.2 s at 1.18 A (the velocity state changes sign
// there), while the combined filter's estimate, straddling the boundary, relaxes towards mode
// 2's stall current (0.71 A/V against mode 1's 1.32): a residual of about 1 W, alarming five
// times in 2 s, named the wattmeter at 101.67 s (tuning log 60). The wattmeter test now allows
// the modes' stall currents near a boundary (`mode_switch_current_spread`).
const THROTTLE_QUIET_BOUNDARY: &str = r#"name = "throttle_quiet_boundary"
monitor = "throttle"
duration_s = 110.0
seed = 1060

[excitation]
kind = "pulse_train"

[sensors]
wattmeter_noise_std_w = 0.4
tps_noise_std_v = 0.01
tps_gain = 1.012268
tps_offset_v = 0.01842
wattmeter_gain = 0.98317

[plant]
table1_rel_error = 0.015
table1_max_draws = 500
stop_restitution = 0.1
process_noise_scale = 0.05

[fault]
kind = "none"
"#;

#[test]
fn a_quiet_plate_chattering_on_a_mode_boundary_is_no_wattmeter_fault() {
    let v = evaluate("throttle_quiet_boundary", THROTTLE_QUIET_BOUNDARY);
    let log = &v["logs"][0];
    assert_eq!(log["dtcs"].as_array().map(Vec::len), Some(0), "{log}");
}

// A TPS short at 112 s on a chirp (tuning log 19, cut): the position output comes from the
// combined filter on the model and the wattmeter. At 124 s the chirp swings the voltage from
// 0.2 to 1 V and the plate rises to 65 deg, but the filter's estimate stayed on the 8 deg mode
// boundary for 4 s (the identified model holds a plate pushed into it: the velocity state
// changes scale and sign there, and the wattmeter alone cannot pull the estimate off): error
// std 15.3 deg after the switch. A filter sitting within 5 deg of a boundary for 0.3 s while the
// static map stands above 30 deg and far away is re-seeded at the map: 3.4 deg.
const THROTTLE_CHIRP_SHORT_TRAP: &str = r#"name = "throttle_chirp_short_trap"
monitor = "throttle"
duration_s = 135.0
seed = 1019

[excitation]
kind = "chirp"

[sensors]
wattmeter_noise_std_w = 0.1
tps_noise_std_v = 0.006
tps_gain = 1.001948
tps_offset_v = -0.011088
wattmeter_gain = 1.004857

[plant]
table1_rel_error = 0.0
table1_max_draws = 200
stop_restitution = 0.2
process_noise_scale = 0.7

[fault]
kind = "tps_short"
start_s = 112.0
"#;

#[test]
fn the_limp_home_estimate_is_freed_from_the_8_deg_mode_boundary() {
    let v = evaluate("throttle_chirp_short_trap", THROTTLE_CHIRP_SHORT_TRAP);
    let log = &v["logs"][0];
    assert_position_within_7_deg_after_the_switch(log);
}

// A quiet plate resting on the open stop at 1.05 V (the model's map: 76.5 deg) behind a TPS
// 1.2 % high that clips at 5 V: the wattmeter-only filter, which at rest knows the angle only
// through the map, ruled the 5 V reading out and named a short at 39.13 s. It now allows the
// map its error (`static_map_error_frac`); without that allowance the short comes back.
const THROTTLE_QUIET_OPEN_STOP: &str = r#"name = "throttle_quiet_open_stop"
monitor = "throttle"
duration_s = 45.0
seed = 1049

[excitation]
kind = "pedal_ramps"

[sensors]
wattmeter_noise_std_w = 0.444
tps_noise_std_v = 0.005
tps_gain = 1.011751
tps_offset_v = -0.009732
wattmeter_gain = 0.955132

[plant]
table1_rel_error = 0.015
table1_max_draws = 500
stop_restitution = 0.1
process_noise_scale = 0.1

[fault]
kind = "none"
"#;

#[test]
fn a_quiet_plate_on_the_open_stop_with_a_clipped_tps_is_not_a_short() {
    let v = evaluate("throttle_quiet_open_stop", THROTTLE_QUIET_OPEN_STOP);
    let log = &v["logs"][0];
    assert_eq!(first_dtc_s(log, "P0123"), None, "{log}");
    let v = evaluate_with(
        "throttle_quiet_open_stop",
        THROTTLE_QUIET_OPEN_STOP,
        "static_map_error_frac = 0.0",
    );
    let log = &v["logs"][0];
    assert!(first_dtc_s(log, "P0123").is_some(), "{log}");
}
