//! `fdd calibrate` for the air-path monitor: on simulated fault-free drives it writes a
//! monitor file with an offset map, scales per load and thresholds, which `fdd replay
//! --config` loads and which calibrates to itself; a drive with a fault in it is refused,
//! naming the file and the fault.

use std::path::{Path, PathBuf};
use std::process::Command;

fn fdd() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_fdd"));
    c.env_remove("RUST_LOG").env_remove("RUST_BACKTRACE");
    c
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `fdd` with `args`, which must succeed; its standard output.
fn ok(args: &[&std::ffi::OsStr]) -> String {
    let out = fdd().args(args).output().expect("run");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{args:?}: {text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

/// A fault-free city drive of `duration_s` (and a fault from 100 s when `fault` is given),
/// simulated into `dir`; the log's path.
fn drive(dir: &Path, name: &str, seed: u64, duration_s: f64, fault: &str) -> PathBuf {
    let sc = dir.join(format!("turbo_{name}.toml"));
    std::fs::write(
        &sc,
        format!(
            "name = \"turbo_{name}\"\nmonitor = \"turbo\"\nduration_s = {duration_s:.1}\nseed = {seed}\n\
             [profile]\nstyle = \"city\"\n[plant]\nparam_rel_error = 0.02\nseed = {}\n{fault}",
            seed + 1
        ),
    )
    .expect("write scenario");
    let log = dir.join(format!("turbo_{name}.mcap"));
    ok(&[
        "simulate".as_ref(),
        sc.as_os_str(),
        "-o".as_ref(),
        log.as_os_str(),
    ]);
    log
}

fn calibrate(logs: &[&Path], config: &Path, out: &Path) -> String {
    let mut args: Vec<&std::ffi::OsStr> = vec!["calibrate".as_ref()];
    args.extend(logs.iter().map(|l| l.as_os_str()));
    args.extend([
        "--config".as_ref(),
        config.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    ok(&args)
}

#[test]
fn turbo_calibration_writes_maps_that_calibrate_to_themselves_and_refuses_a_fault() {
    let dir = tempfile::tempdir().expect("temp dir");
    let a = drive(dir.path(), "a", 91_001, 1200.0, "");
    let b = drive(dir.path(), "b", 91_011, 1200.0, "");
    let sim = root().join("config/fdd_turbo_sim.toml");
    let first = dir.path().join("first");
    let report = calibrate(&[&a, &b], &sim, &first);
    for words in [
        "offset map",
        "scales",
        "turbo_cylinder_flow",
        "turbo_throttle_flow",
    ] {
        assert!(report.contains(words), "{report}");
    }
    let written = std::fs::read_to_string(first.join("turbo.toml")).expect("turbo.toml");
    let cfg = fdd_monitor::turbo::TurboConfig::load(Some(&first.join("turbo.toml")))
        .expect("the written monitor file loads with its parameter file");
    let m = &cfg.monitor;
    assert!(m.offset_map_load.len() >= 3, "{:?}", m.offset_map_load);
    assert_eq!(m.scale_map.len(), m.offset_map_load.len());
    // The scales are the model's error here, far below the uncalibrated defaults, and every
    // threshold is above the floor.
    for (s, start) in m.residual_scale.iter().zip([0.065, 0.03, 0.07]) {
        assert!(*s > 0.0 && *s < start, "{:?}", m.residual_scale);
    }
    assert!(
        m.cusum_threshold.iter().all(|&h| h >= 10.0),
        "{:?}",
        m.cusum_threshold
    );

    // The written runtime configuration replays a log.
    let replay = ok(&[
        "replay".as_ref(),
        a.as_os_str(),
        "--config".as_ref(),
        first.join("fdd.toml").as_os_str(),
    ]);
    assert!(replay.contains("turbo"), "{replay}");

    // Calibrating from the calibrated file gives it back.
    let second = dir.path().join("second");
    calibrate(&[&a, &b], &first.join("fdd.toml"), &second);
    let again = std::fs::read_to_string(second.join("turbo.toml")).expect("turbo.toml");
    assert_eq!(again, written, "a calibrated file calibrates to itself");

    // A drive with a fault is refused, naming it.
    let f = drive(
        dir.path(),
        "f",
        91_021,
        200.0,
        "[fault]\nkind = \"waf_gain\"\ngain = 0.9\nstart_s = 100.0\n",
    );
    let out = fdd()
        .args([
            "calibrate".as_ref(),
            f.as_os_str(),
            "--config".as_ref(),
            sim.as_os_str(),
        ])
        .args(["-o".as_ref(), dir.path().join("refused").as_os_str()])
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("f.mcap") && err.contains("waf_gain"), "{err}");
}

/// A temporary directory with config/fdd.toml, the air-path monitor switched on with the
/// committed LiU-ICE monitor file (and its parameter file) beside it; the config's path.
fn liu_config() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temp dir");
    let base = std::fs::read_to_string(root().join("config/fdd.toml")).expect("fdd.toml");
    assert!(
        base.contains("\nturbo = false\n"),
        "config/fdd.toml changed"
    );
    let cfg = dir.path().join("fdd.toml");
    std::fs::write(
        &cfg,
        base.replace(
            "\nturbo = false\n",
            "\nturbo = true\nturbo_config = \"turbo_monitor.toml\"\n",
        ),
    )
    .expect("write config");
    for f in ["turbo_monitor.toml", "turbo_liu_ice.toml"] {
        std::fs::copy(root().join("config").join(f), dir.path().join(f)).expect("copy");
    }
    (dir, cfg)
}

/// The "DTCs raised" section of a replay report (not the whole report: it names the random
/// temp dir, which may spell a DTC).
fn dtc_section(report: &str) -> &str {
    report
        .split("\nDTCs raised (testFailed 0 -> 1)\n")
        .nth(1)
        .expect("the report has its DTC section")
}

/// The LiU-ICE monitor file: `fdd calibrate` on the two fault-free calibration logs writes the
/// committed `config/turbo_monitor.toml` byte for byte (so its thresholds, scales and map are
/// the command's, from fault-free data only), and the third fault-free log, which it was not
/// calibrated on, raises no DTC.
#[test]
fn liu_ice_monitor_file_is_what_calibrate_writes_from_the_fault_free_logs() {
    let (dir, cfg) = liu_config();
    let liu = root().join("fixtures/data/real/liu-ice");
    let a = liu.join("ftp75city2_NF_0-100s.mcap");
    let b = liu.join("ftp75city2_NF_140-260s.mcap");
    let out = dir.path().join("out");
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "calibrate".as_ref(),
        "--monitor".as_ref(),
        "turbo".as_ref(),
        "--block-s".as_ref(),
        "0.25".as_ref(),
    ];
    args.extend([a.as_os_str(), b.as_os_str()]);
    args.extend([
        "--config".as_ref(),
        cfg.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    ok(&args);
    let written = std::fs::read_to_string(out.join("turbo.toml")).expect("written");
    let committed =
        std::fs::read_to_string(root().join("config/turbo_monitor.toml")).expect("committed");
    assert!(
        written == committed,
        "config/turbo_monitor.toml differs from what fdd calibrate writes:\n{written}"
    );
    let judged = liu.join("ftp75city2_NF_window.mcap");
    let report = ok(&[
        "replay".as_ref(),
        "--no-progress".as_ref(),
        "--config".as_ref(),
        out.join("fdd.toml").as_os_str(),
        judged.as_os_str(),
    ]);
    assert!(report.contains("turbo ("), "{report}");
    assert!(
        dtc_section(&report).starts_with("  none\n"),
        "a DTC on fault-free driving:\n{report}"
    );
}

/// The LiU-ICE boost-sensor windows (the real engine's p_ic reading 0.85 and 1.15 times the
/// true pressure from the onset in `ftp75city2_fault_time.txt`): with the committed monitor
/// file the boost sensor's own DTC P0236-62 is raised after the onset. The flow balances
/// alone confuse a boost-sensor gain with the throttle's area where the throttle is choked;
/// the boost residual, which the sensor moves and the throttle does not, names it.
#[test]
fn liu_ice_boost_sensor_windows_raise_the_boost_sensors_dtc_after_the_onset() {
    let (_dir, cfg) = liu_config();
    let liu = root().join("fixtures/data/real/liu-ice");
    let times = std::fs::read_to_string(liu.join("ftp75city2_fault_time.txt")).expect("times");
    for name in ["ftp75city2_f_pic_085", "ftp75city2_f_pic_115"] {
        let onset: f64 = times
            .lines()
            .find_map(|l| l.strip_prefix(name)?.trim().parse().ok())
            .unwrap_or_else(|| panic!("{name}: no onset"));
        let log = liu.join(format!("{name}_window.mcap"));
        let report = ok(&[
            "replay".as_ref(),
            "--no-progress".as_ref(),
            "--config".as_ref(),
            cfg.as_os_str(),
            log.as_os_str(),
        ]);
        let at: f64 = dtc_section(&report)
            .lines()
            .find(|l| l.trim_start().starts_with("P0236-62"))
            .and_then(|l| l.split_whitespace().nth(2)?.parse().ok())
            .unwrap_or_else(|| panic!("{name}: no P0236-62:\n{report}"));
        assert!(
            at >= onset && at <= onset + 10.0,
            "{name}: P0236-62 at {at} s, onset {onset} s"
        );
    }
}
