//! Acceptance test of hostile scenario files (issue 11): every key of real scenario files is set,
//! one at a time, to values it must not take, and the scenario is loaded as `fdd simulate` loads
//! it and its simulator built and run for a few hundred steps.
//!
//! Each leaf (every key, every element of an array) gets: a value of the wrong type, NaN, a
//! negative value, zero, 1e300, and (arrays) one element too many. For each the outcome must be:
//!
//! - an error whose text names the file and the full key path (`plant.table1.a23`, the array's
//!   key for one of its elements), or
//! - acceptance, listed in [`ALLOWED`] with the reason the value is legitimate (a calibration
//!   offset of either sign, a fault from the first sample, seed 0).
//!
//! Nothing may panic or run away. A key added to the scenario format without validation makes
//! this test fail as soon as a walked file uses it; the files walked are every committed
//! scenario (`fixtures/scenarios/`), the richest files of the scenario sets, and the files in
//! [`EXTRA`], which use every key the formats have.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::Instant;

use fdd_fixtures::scenario_file::{AnyScenario, AnySim};

/// What a leaf is set to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum M {
    /// A value of another type (a string for a number, a number for a string).
    WrongType,
    Nan,
    /// The value negated (-1 for zero); skipped when the value is already negative.
    Negative,
    Zero,
    /// 1e300.
    Huge,
    /// An array with one element more (a copy of its last).
    Extra,
}

const ALL: [M; 6] = [
    M::WrongType,
    M::Nan,
    M::Negative,
    M::Zero,
    M::Huge,
    M::Extra,
];

/// Odd values that are legitimately accepted: (key pattern, mutations, reason). In a pattern,
/// `*` stands for any run of characters; keys are dotted, array elements `key[i]`.
const ALLOWED: &[(&str, &[M], &str)] = &[
    ("seed", &[M::Zero], "0 is a seed like any other"),
    ("plant.seed", &[M::Zero], "0 is a seed like any other"),
    (
        "*fault.start_s",
        &[M::Zero],
        "a fault may be present from the first sample",
    ),
    // Throttle excitation (motor voltages, V, within the 12 V supply's +-14 V).
    (
        "excitation*.amplitude_v[0]",
        &[M::Negative],
        "the pulse train's lowest level: a reverse voltage (the H-bridge can apply one)",
    ),
    (
        "excitation*.amplitude_v[1]",
        &[M::Zero],
        "pulses up to 0 V: the plate rests on its closed stop, a dull but valid drive",
    ),
    (
        "excitation*.level_v[0]",
        &[M::Zero, M::Negative],
        "the lowest ramp or hold level: 0 V or a reverse voltage (the output is clamped to limits_v)",
    ),
    (
        "excitation*.idle_v[0]",
        &[M::Zero, M::Negative],
        "the lowest idle level: 0 V or a reverse voltage (clamped to limits_v)",
    ),
    (
        "excitation*.blip_v[0]",
        &[M::Zero, M::Negative],
        "the lowest blip level: 0 V or a reverse voltage (clamped to limits_v)",
    ),
    (
        "excitation.limits_v[0]",
        &[M::Negative],
        "the clamp's lower end: a reverse voltage the H-bridge can apply",
    ),
    (
        "excitation*.mean_v",
        &[M::Zero, M::Negative],
        "a chirp centred on 0 V or on a reverse voltage (clamped to limits_v)",
    ),
    (
        "excitation*.amplitude_v",
        &[M::Zero],
        "a chirp of amplitude 0 is a constant voltage",
    ),
    (
        "excitation*.dither_v",
        &[M::Zero],
        "no dither: exactly constant holds",
    ),
    (
        "excitation.transition_s",
        &[M::Zero],
        "an abrupt switch between mixed segments",
    ),
    // Throttle sensors.
    (
        "sensors.tps_noise_std_v",
        &[M::Zero],
        "a noise-free TPS (before the ADC)",
    ),
    (
        "sensors.wattmeter_noise_std_w",
        &[M::Zero],
        "a noise-free wattmeter",
    ),
    (
        "sensors.tps_offset_v",
        &[M::Zero, M::Negative],
        "a calibration offset of either sign, or none",
    ),
    (
        "sensors.wattmeter_offset_w",
        &[M::Zero, M::Negative],
        "a calibration offset of either sign, or none",
    ),
    (
        "sensors.tps_lag_s",
        &[M::Zero],
        "0 is no lag (the documented default)",
    ),
    (
        "sensors.wattmeter_lag_s",
        &[M::Zero],
        "0 is no lag (the documented default)",
    ),
    // Throttle plant.
    (
        "plant.table1_rel_error",
        &[M::Zero],
        "no Table I error: the plant file's plant",
    ),
    (
        "plant.stop_restitution",
        &[M::Zero],
        "an inelastic stop (the plant file's)",
    ),
    (
        "plant.process_noise_scale",
        &[M::Zero],
        "a plant without process noise",
    ),
    (
        "plant.stop_deg[0]",
        &[M::Negative],
        "the closed stop a little below 0 deg (the TPS reads 0 V there)",
    ),
    (
        "plant.table1.*",
        &[M::Zero, M::Negative],
        "an explicit Table I value of either sign (within +-10) whose modes stay stable",
    ),
    // Throttle faults.
    (
        "*fault.bias_deg",
        &[M::Negative],
        "a TPS bias of either sign",
    ),
    (
        "*fault.drift_deg_per_s",
        &[M::Negative],
        "a TPS drift of either sign",
    ),
    (
        "*fault.gain",
        &[M::Zero],
        "a wattmeter fault that reads no power at all (only its offset)",
    ),
    (
        "*fault.offset_w",
        &[M::Zero, M::Negative],
        "a wattmeter fault offset of either sign, or none with a gain error",
    ),
    // Intake.
    (
        "pulsation_rel",
        &[M::Zero],
        "no pumping pulsation",
    ),
    (
        "plant.param_rel_error",
        &[M::Zero],
        "no parameter error: the plant file's plant",
    ),
    (
        "plant.ve_error_*",
        &[M::Zero, M::Negative],
        "a volumetric-efficiency error of either sign, or none",
    ),
    (
        "plant.discharge_error_*",
        &[M::Zero, M::Negative],
        "a throttle discharge error of either sign, or none",
    ),
    (
        "sensors.map_noise_std_pa",
        &[M::Zero],
        "a noise-free MAP sensor",
    ),
    (
        "sensors.maf_noise_rel",
        &[M::Zero],
        "a noise-free MAF sensor",
    ),
    (
        "sensors.map_offset_pa",
        &[M::Zero, M::Negative],
        "a calibration offset of either sign, or none",
    ),
    (
        "sensors.maf_offset_kg_s",
        &[M::Zero, M::Negative],
        "a calibration offset of either sign, or none",
    ),
    (
        "profile.egr_pos",
        &[M::Zero],
        "no EGR in the tip-outs",
    ),
    (
        "profile.egr_pos[0]",
        &[M::Zero],
        "EGR positions from closed",
    ),
    (
        "profile.*_prob",
        &[M::Zero],
        "a probability of 0: the event never happens",
    ),
    (
        "profile.low_throttle_deg",
        &[M::Zero],
        "tip-outs to the closed plate",
    ),
    (
        "profile.throttle_deg",
        &[M::Zero],
        "a speed sweep at the closed plate",
    ),
    (
        "profile.throttle_deg[0]",
        &[M::Zero],
        "operating points from the closed plate",
    ),
    (
        "profile.high_throttle_deg[0]",
        &[M::Zero],
        "tip-ins from the closed plate",
    ),
    (
        "profile.blip_throttle_deg[0]",
        &[M::Zero],
        "blips from the closed plate",
    ),
    (
        "profile.blip_rpm[0]",
        &[M::Zero],
        "blips that may not raise the speed",
    ),
    (
        "*fault.bias_pa",
        &[M::Negative],
        "a MAP bias of either sign",
    ),
    (
        "*fault.bias_kg_s",
        &[M::Negative],
        "a MAF bias of either sign",
    ),
    (
        "*fault.rate_*",
        &[M::Negative],
        "a sensor drift of either sign",
    ),
];

/// Files using every key the formats have (in addition to the committed ones): a throttle
/// scenario with a `mixed` excitation and every style's sub-table, an explicit Table I, stops,
/// and two faults with all their keys; a chirp one; one intake scenario per drive profile with
/// all its keys, and faults of every kind with a key.
const EXTRA: &[(&str, &str)] = &[
    (
        "throttle_all_keys",
        r#"
name = "throttle_all_keys"
monitor = "throttle"
duration_s = 20.0
seed = 7
sample_period_s = 0.001
[excitation]
kind = "mixed"
segment_s = [2.0, 4.0]
transition_s = 0.3
styles = ["pulse_train", "chirp", "pedal_ramps", "steady_holds", "idle_blips"]
limits_v = [0.0, 1.2]
[excitation.pulse_train]
amplitude_v = [0.0, 1.2]
pulse_s = [0.05, 1.0]
block_s = [2.0, 10.0]
cutoff_hz = [0.5, 20.0]
[excitation.chirp]
mean_v = 0.6
amplitude_v = 0.45
f_hz = [0.05, 5.0]
period_s = 20.0
sweep = "linear"
[excitation.pedal_ramps]
level_v = [0.15, 1.15]
ramp_s = [0.2, 3.0]
hold_s = [0.3, 4.0]
[excitation.steady_holds]
level_v = [0.2, 1.1]
hold_s = [5.0, 20.0]
dither_v = 0.005
[excitation.idle_blips]
idle_v = [0.15, 0.25]
idle_s = [1.0, 6.0]
blip_v = [0.4, 1.0]
blip_s = [0.15, 0.8]
[sensors]
tps_noise_std_v = 0.005
adc_bits = 10
wattmeter_noise_std_w = 0.1
tps_gain = 1.01
tps_offset_v = 0.01
tps_lag_s = 0.0015
wattmeter_gain = 1.02
wattmeter_offset_w = 0.02
wattmeter_lag_s = 0.002
[plant]
table1_rel_error = 0.01
table1_max_draws = 100
stop_deg = [0.0, 90.0]
stop_restitution = 0.2
process_noise_scale = 1.0
seed = 5
[plant.table1]
b = [0.0741, 0.0346, 0.0442]
a33 = [0.944, 0.9514, 0.9043]
[fault]
kind = "tps_intermittent"
start_s = 5.0
end_s = 15.0
dropout_rate_hz = 5.0
dropout_s = [0.002, 0.01]
[second_fault]
kind = "wattmeter"
start_s = 8.0
gain = 1.2
offset_w = 0.3
"#,
    ),
    (
        "throttle_chirp_keys",
        r#"
name = "throttle_chirp_keys"
monitor = "throttle"
duration_s = 20.0
seed = 8
[excitation]
kind = "chirp"
mean_v = 0.6
amplitude_v = 0.45
f_hz = [0.05, 5.0]
period_s = 20.0
sweep = "exponential"
limits_v = [0.0, 1.2]
[fault]
kind = "tps_noise"
start_s = 5.0
noise_std_v = 0.2
[second_fault]
kind = "tps_drift"
start_s = 6.0
drift_deg_per_s = 2.0
"#,
    ),
    (
        "intake_idle_keys",
        r#"
name = "intake_idle_keys"
monitor = "intake"
duration_s = 20.0
seed = 9
pulsation_rel = 0.02
max_substep_s = 1e-4
[profile]
kind = "idle"
speed_rpm = 800.0
throttle_deg = 2.0
[fault]
kind = "map_gain"
start_s = 5.0
end_s = 15.0
gain = 1.1
[second_fault]
kind = "maf_noise"
start_s = 6.0
std_rel = 0.05
"#,
    ),
    (
        "intake_sweep_keys",
        r#"
name = "intake_sweep_keys"
monitor = "intake"
duration_s = 20.0
seed = 10
[profile]
kind = "speed_sweep"
min_rpm = 800.0
max_rpm = 6000.0
sweep_s = 20.0
throttle_deg = 15.0
[fault]
kind = "map_drift"
start_s = 5.0
rate_pa_per_s = 500.0
[second_fault]
kind = "maf_bias"
start_s = 6.0
bias_kg_s = 0.002
"#,
    ),
    (
        "intake_steady_keys",
        r#"
name = "intake_steady_keys"
monitor = "intake"
duration_s = 20.0
seed = 11
[profile]
kind = "steady_holds"
speed_rpm = [900.0, 5000.0]
throttle_deg = [3.0, 40.0]
hold_s = [8.0, 20.0]
ramp_s = [0.5, 2.0]
egr_pos = [0.2, 0.5]
egr_on_prob = 0.5
[fault]
kind = "egr_sluggish"
start_s = 5.0
time_constant_s = 2.0
[second_fault]
kind = "map_noise"
start_s = 6.0
std_pa = 2000.0
"#,
    ),
    (
        "intake_ramps_keys",
        r#"
name = "intake_ramps_keys"
monitor = "intake"
duration_s = 20.0
seed = 12
[profile]
kind = "pedal_ramps"
speed_rpm = [800.0, 6000.0]
throttle_deg = [2.0, 70.0]
ramp_s = [1.5, 6.0]
egr_pos = [0.2, 0.5]
egr_on_prob = 0.5
[fault]
kind = "maf_drift"
start_s = 5.0
rate_kg_s_per_s = 0.0005
[second_fault]
kind = "leak"
start_s = 6.0
diameter_m = 0.003
"#,
    ),
    (
        "intake_mixed_keys",
        r#"
name = "intake_mixed_keys"
monitor = "intake"
duration_s = 20.0
seed = 13
[profile]
kind = "mixed"
speed_rpm = [800.0, 6000.0]
leg_s = [1.0, 4.0]
tip_in_prob = 0.3
egr_pos = [0.2, 0.5]
egr_on_prob = 0.6
[plant]
param_rel_error = 0.05
ve_error_rel = 0.02
ve_error_speed = -0.01
ve_error_pressure = 0.03
discharge_error_rel = 0.02
discharge_error_angle = -0.03
ambient_pressure_pa = 95000.0
ambient_temperature_k = 285.0
seed = 77
[sensors]
map_noise_std_pa = 700.0
maf_noise_rel = 0.015
map_gain = 1.01
map_offset_pa = 300.0
map_time_constant_s = 0.01
maf_gain = 0.98
maf_offset_kg_s = 2e-4
maf_time_constant_s = 0.02
[fault]
kind = "map_bias"
start_s = 5.0
bias_pa = 5000.0
"#,
    ),
    (
        "intake_tipin_keys",
        r#"
name = "intake_tipin_keys"
monitor = "intake"
duration_s = 20.0
seed = 14
[profile]
kind = "tip_in_out"
low_throttle_deg = 3.0
high_throttle_deg = [20.0, 60.0]
speed_rpm = [900.0, 4500.0]
dwell_s = [1.0, 2.5]
ramp_s = 0.15
egr_pos = 0.3
[fault]
kind = "egr_stuck_open"
start_s = 5.0
position = 0.3
[second_fault]
kind = "maf_gain"
start_s = 6.0
gain = 1.1
"#,
    ),
    (
        "intake_blips_keys",
        r#"
name = "intake_blips_keys"
monitor = "intake"
duration_s = 20.0
seed = 15
[profile]
kind = "idle_blips"
speed_rpm = 800.0
throttle_deg = 2.0
blip_prob = 0.3
blip_throttle_deg = [4.0, 10.0]
blip_rpm = [150.0, 600.0]
blip_s = [0.3, 0.8]
[fault]
kind = "leak"
start_s = 5.0
diameter_m = 0.003
"#,
    ),
];

/// The richest files of the scenario sets (plant, sensors, two faults, plant seeds).
const SET_FILES: [&str; 4] = [
    "fixtures/sets/throttle_calibrate_train/throttle_calibrate_train_00_nominal.toml",
    "fixtures/sets/throttle_tuning/throttle_tuning_37_wattmeter_then_tps_bias.toml",
    "fixtures/sets/intake_heldout/intake_held_56_egr_stuck_open_and_leak.toml",
    "fixtures/sets/intake_calibrate_heldout/intake_calibrate_heldout_43_egr_stuck_open_idle_blips.toml",
];

/// Frames run per accepted scenario: enough to reach every part of a simulator's step.
const THROTTLE_FRAMES: usize = 300;
const INTAKE_FRAMES: usize = 30;

/// One segment of a key path.
#[derive(Debug, Clone, PartialEq)]
enum Seg {
    Key(String),
    Index(usize),
}

/// `a.b[1]` for a path; `a.b` without the element index (the key errors name).
fn show_path(path: &[Seg], with_index: bool) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            Seg::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Seg::Index(i) if with_index => s.push_str(&format!("[{i}]")),
            Seg::Index(_) => {}
        }
    }
    s
}

/// Every leaf of `v` (scalars, array elements) and every array, with their paths.
fn leaves(v: &toml::Value, path: &mut Vec<Seg>, out: &mut Vec<(Vec<Seg>, toml::Value)>) {
    match v {
        toml::Value::Table(t) => {
            for (k, x) in t {
                path.push(Seg::Key(k.clone()));
                leaves(x, path, out);
                path.pop();
            }
        }
        toml::Value::Array(a) => {
            out.push((path.clone(), v.clone()));
            for (i, x) in a.iter().enumerate() {
                path.push(Seg::Index(i));
                leaves(x, path, out);
                path.pop();
            }
        }
        _ => out.push((path.clone(), v.clone())),
    }
}

fn get_mut<'a>(v: &'a mut toml::Value, path: &[Seg]) -> &'a mut toml::Value {
    path.iter().fold(v, |v, seg| match (seg, v) {
        (Seg::Key(k), toml::Value::Table(t)) => t.get_mut(k).expect("key"),
        (Seg::Index(i), toml::Value::Array(a)) => &mut a[*i],
        _ => panic!("path {path:?} does not fit"),
    })
}

/// `value` mutated by `m`, or `None` when the mutation does not apply (or changes nothing).
fn mutate(value: &toml::Value, m: M) -> Option<toml::Value> {
    use toml::Value as V;
    let negative = |x: f64| {
        if x > 0.0 {
            Some(-x)
        } else if x == 0.0 {
            Some(-1.0)
        } else {
            None
        }
    };
    Some(match (value, m) {
        (V::Array(a), M::Extra) => {
            let mut a = a.clone();
            a.push(a.last()?.clone());
            V::Array(a)
        }
        (V::Array(_), _) | (_, M::Extra) => return None,
        (V::String(_), M::WrongType) => V::Integer(1),
        (_, M::WrongType) => V::String("x".into()),
        (_, M::Nan) => V::Float(f64::NAN),
        (_, M::Huge) => V::Float(1e300),
        (V::Integer(i), M::Negative) => V::Integer(if *i > 0 {
            -*i
        } else if *i == 0 {
            -1
        } else {
            return None;
        }),
        (V::Float(x), M::Negative) => V::Float(negative(*x)?),
        (V::Integer(i), M::Zero) if *i != 0 => V::Integer(0),
        (V::Float(x), M::Zero) if *x != 0.0 => V::Float(0.0),
        (V::Integer(_) | V::Float(_), _) => return None,
        (V::String(_), M::Negative) => V::Integer(-1),
        (V::String(_), M::Zero) => V::Integer(0),
        (_, _) => return None,
    })
}

fn glob(pattern: &str, s: &str) -> bool {
    match pattern.split_once('*') {
        None => pattern == s,
        Some((head, rest)) => {
            let Some(tail) = s.strip_prefix(head) else {
                return false;
            };
            (0..=tail.len()).any(|i| tail.is_char_boundary(i) && glob(rest, &tail[i..]))
        }
    }
}

fn allowed(path: &str, m: M) -> Option<&'static str> {
    ALLOWED
        .iter()
        .find(|(p, ms, _)| ms.contains(&m) && glob(p, path))
        .map(|(_, _, why)| *why)
}

/// Loads `file` as `fdd simulate` does, builds its simulator and runs a few frames; the error
/// text if any. A panic is an `Err` naming it.
fn load_and_run(file: &Path) -> Result<Result<(), String>, String> {
    let origin = file.display().to_string();
    catch_unwind(AssertUnwindSafe(|| {
        let sc = AnyScenario::load(file).map_err(|e| e.to_string())?;
        let sim = sc.simulator(&origin).map_err(|e| e.to_string())?;
        let n = match sim {
            AnySim::Throttle(s) => s.take(THROTTLE_FRAMES).count(),
            AnySim::Intake(s) => s.take(INTAKE_FRAMES).count(),
        };
        assert!(n > 0, "no frame simulated");
        Ok(())
    }))
    .map_err(|p| {
        p.downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "a panic".into())
    })
}

#[test]
fn every_key_refuses_bad_values_naming_file_and_key() {
    let started = Instant::now();
    let dir = tempfile::tempdir().expect("tempdir");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files: Vec<(String, String)> = Vec::new();
    let mut committed: Vec<PathBuf> = std::fs::read_dir(root.join("fixtures/scenarios"))
        .expect("fixtures/scenarios")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    committed.sort();
    for p in committed.iter().chain(
        SET_FILES
            .iter()
            .map(|f| root.join(f))
            .collect::<Vec<_>>()
            .iter(),
    ) {
        let name = p.file_stem().expect("stem").to_string_lossy().into_owned();
        files.push((name, std::fs::read_to_string(p).expect("read")));
    }
    files.extend(EXTRA.iter().map(|(n, t)| (n.to_string(), t.to_string())));

    let (mut checked, mut accepted) = (0, Vec::new());
    let mut failures = Vec::new();
    for (name, text) in &files {
        let doc: toml::Value = toml::from_str(text).expect("valid TOML");
        let file = dir.path().join(format!("{name}.toml"));
        std::fs::write(&file, text).expect("write");
        assert_eq!(
            load_and_run(&file),
            Ok(Ok(())),
            "{name} itself must be valid"
        );
        let mut found = Vec::new();
        leaves(&doc, &mut Vec::new(), &mut found);
        for (path, value) in &found {
            for m in ALL {
                let Some(bad) = mutate(value, m) else {
                    continue;
                };
                let mut d = doc.clone();
                *get_mut(&mut d, path) = bad.clone();
                std::fs::write(&file, toml::to_string(&d).expect("serialize")).expect("write");
                checked += 1;
                let (shown, key) = (show_path(path, true), show_path(path, false));
                let what = format!("{name}: {shown} = {bad} ({m:?})");
                match load_and_run(&file) {
                    Err(panic) => failures.push(format!("{what}: PANIC {panic}")),
                    Ok(Ok(())) => match allowed(&shown, m) {
                        Some(why) => accepted.push(format!("{what}: accepted, {why}")),
                        None => failures.push(format!("{what}: accepted, and not in ALLOWED")),
                    },
                    Ok(Err(e)) => {
                        let names_file = e.contains(&file.display().to_string());
                        let names_key = if key.contains('.') {
                            e.contains(&format!("(key {key})"))
                        } else {
                            e.contains(&format!(": {key} = ")) || e.contains(&format!(": {key}: "))
                        };
                        if !(names_file && names_key) {
                            failures.push(format!(
                                "{what}: the error does not name the file and `{key}`: {e}"
                            ));
                        }
                        if e.len() > 2000 {
                            failures.push(format!("{what}: an error of {} characters", e.len()));
                        }
                    }
                }
            }
        }
    }
    println!(
        "{checked} bad values checked in {} files in {:.1} s; accepted as legitimate:",
        files.len(),
        started.elapsed().as_secs_f64()
    );
    for a in &accepted {
        println!("  {a}");
    }
    assert!(
        failures.is_empty(),
        "{} of {checked} bad values:\n{}",
        failures.len(),
        failures.join("\n")
    );
    // Every allow-list entry is still needed (an entry nothing matches hides nothing, but it
    // says something the format no longer does).
    let unused: Vec<String> = ALLOWED
        .iter()
        .flat_map(|(pattern, ms, _)| ms.iter().map(move |m| (pattern, m)))
        .filter(|(pattern, m)| {
            !accepted.iter().any(|a| {
                let shown = a.split_once(": ").map_or("", |x| x.1);
                let shown = shown.split_once(" = ").map_or("", |x| x.0);
                glob(pattern, shown) && a.contains(&format!("({m:?})"))
            })
        })
        .map(|(pattern, m)| format!("({pattern}, {m:?})"))
        .collect();
    assert!(
        unused.is_empty(),
        "ALLOWED entries that matched no accepted value: {unused:?}"
    );
}
