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

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Runs fdd in `dir` with `args`; its exit status, stdout and stderr. A run longer than a
/// minute (a simulation that never ends) is killed and fails the test.
fn run_in(dir: &Path, args: &[&str]) -> (bool, String, String) {
    let mut child = fdd()
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run fdd");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    // Read the pipes on threads, so that a chatty child cannot block on a full pipe.
    let out_pipe = child.stdout.take().expect("stdout");
    let err_pipe = child.stderr.take().expect("stderr");
    let read = |mut p: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut b = Vec::new();
            let _ = p.read_to_end(&mut b);
            b
        })
    };
    let (out_t, err_t) = (read(Box::new(out_pipe)), read(Box::new(err_pipe)));
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("fdd {args:?} still running after 60 s: killed");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let (stdout, stderr) = (out_t.join().expect("stdout"), err_t.join().expect("stderr"));
    (status.success(), text(&stdout), text(&stderr))
}

/// A topic name, a truth `fault` string and a configured field of 70,000 characters (beyond the
/// 65,535 a `{:width$}` format takes) end the replay with its summary, not a panic: the table
/// shortens them and prints them in full below it.
#[test]
fn cells_longer_than_a_format_width_do_not_break_the_replay_summary() {
    use fdd_monitor::log::{LogWriter, MotorVoltage, ThrottleTruth};
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("long.mcap");
    let long_topic = format!("/{}", "t".repeat(70_000));
    let long_fault = "f".repeat(70_000);
    let mut w = LogWriter::create(&log).expect("create");
    w.add_topic(&long_topic, "x", "{}").expect("topic");
    for k in 0..50u64 {
        let t = k * 1_000_000;
        w.write_message(t, &MotorVoltage { voltage_v: 0.5 })
            .expect("write");
        w.write_raw_json(&long_topic, t, b"{\"x\": 1}")
            .expect("write");
        w.write_message(
            t,
            &ThrottleTruth {
                angle_deg: 1.0,
                velocity: 0.0,
                current_a: 0.0,
                fault: long_fault.clone(),
                fault_active: k >= 10,
                fault_observable: None,
            },
        )
        .expect("write");
    }
    w.finish().expect("finish");
    // A configuration whose TPS signal reads a 70,000-character field.
    let long_field = "v".repeat(70_000);
    let config = dir.path().join("fdd.toml");
    let cfg = fdd_monitor::runtime::config::DEFAULT_RUNTIME_TOML.replacen(
        "topic = \"/throttle/tps\"\nfield = \"voltage_v\"",
        &format!("topic = \"/throttle/tps\"\nfield = \"{long_field}\""),
        1,
    );
    assert!(
        cfg.contains(&long_field),
        "the TPS signal's field in config/fdd.toml moved"
    );
    std::fs::write(&config, cfg).expect("config");
    let events = dir.path().join("events.jsonl");
    let out = fdd()
        .arg("replay")
        .arg(&log)
        .arg("--config")
        .arg(&config)
        .arg("--events")
        .arg(&events)
        .arg("--no-progress")
        .output()
        .expect("run");
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(
        !stderr.contains("panicked"),
        "{}",
        &stderr[..stderr.len().min(2000)]
    );
    assert!(
        out.status.success(),
        "{}",
        &stderr[..stderr.len().min(2000)]
    );
    // Shortened in the columns, whole below the tables.
    assert!(stdout.contains('\u{2026}'));
    assert!(stdout.contains(&format!("topic, row 1: {long_topic}\n")));
    assert!(stdout.contains(&format!("fault, row 1: {long_fault}\n")));
    assert!(stdout.contains(&format!("field, row 2: {long_field}\n")));
    let widest_table_line = stdout
        .lines()
        .filter(|l| l.starts_with("  ") && !l.starts_with("    "))
        .map(|l| l.chars().count())
        .max()
        .unwrap_or(0);
    assert!(
        widest_table_line < 600,
        "a table line of {widest_table_line} characters"
    );
}

/// Periods, durations and steps of a scenario file are checked against physical ranges, naming
/// the file, the key and the unit: a substep of 1e-300 s (a simulation that never ends) and a
/// duration of 1e12 s (a log that fills the disk) are refused; a scenario longer than a day
/// needs --allow-long.
#[test]
fn simulate_refuses_steps_and_durations_out_of_range() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scenario = |name: &str, from: &str, to: &str| {
        let text = std::fs::read_to_string(root().join(format!("fixtures/scenarios/{name}.toml")))
            .expect("scenario");
        assert!(text.contains(from), "{from}");
        std::fs::write(
            dir.path().join(format!("{name}.toml")),
            text.replacen(from, to, 1),
        )
        .expect("write");
    };
    scenario(
        "intake_leak",
        "duration_s = 60.0",
        "duration_s = 60.0\nmax_substep_s = 1e-300",
    );
    let (ok, _, err) = run_in(
        dir.path(),
        &["simulate", "intake_leak.toml", "-o", "x.mcap"],
    );
    assert!(!ok);
    assert!(
        err.contains("intake_leak.toml: max_substep_s = 1e-300: must be between 1e-6 and 0.001 s"),
        "{err}"
    );
    scenario(
        "throttle_nominal",
        "duration_s = 120.0",
        "duration_s = 1e12",
    );
    let (ok, _, err) = run_in(
        dir.path(),
        &["simulate", "throttle_nominal.toml", "-o", "x.mcap"],
    );
    assert!(
        !ok && err.contains("throttle_nominal.toml: duration_s = ") && err.contains(" s"),
        "{err}"
    );
    scenario(
        "throttle_nominal",
        "duration_s = 120.0",
        "duration_s = 90000.0",
    );
    let (ok, _, err) = run_in(
        dir.path(),
        &["simulate", "throttle_nominal.toml", "-o", "x.mcap"],
    );
    assert!(
        !ok && err.contains("--allow-long") && err.contains("90000.0"),
        "{err}"
    );
    assert!(!dir.path().join("x.mcap").exists(), "nothing written");
    scenario(
        "throttle_nominal",
        "sample_period_s = 0.001",
        "sample_period_s = 1e-9",
    );
    let (ok, _, err) = run_in(
        dir.path(),
        &["simulate", "throttle_nominal.toml", "-o", "x.mcap"],
    );
    assert!(
        !ok && err.contains("sample_period_s = 1e-9: must be between 1e-6"),
        "{err}"
    );
}

/// Counts and sizes on the command line have a stated maximum: a particle count that used to
/// panic ("capacity overflow") or abort on a 24 TB allocation is refused at once, naming the
/// flag and the range; so are negative numbers (clap used to call `-1` an unexpected argument).
#[test]
fn numeric_arguments_are_range_checked_naming_the_flag() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (args, flag, range) in [
        (
            &[
                "reproduce",
                "table2",
                "--samples",
                "10",
                "--particles",
                "24000000000000",
            ][..],
            "--particles",
            "from 2 to 1000000 particles",
        ),
        (
            &["reproduce", "table2", "--particles", "-1"][..],
            "--particles",
            "from 2 to 1000000 particles",
        ),
        (
            &["reproduce", "table2", "--samples", "-5"][..],
            "--samples",
            "from 1 to 1000000000 samples",
        ),
        (
            &[
                "reproduce",
                "table2",
                "--samples",
                "10",
                "--wattmeter-std",
                "-1",
            ][..],
            "--wattmeter-std",
            "A^2",
        ),
        (
            &["reproduce", "table2", "--seed", "-1"][..],
            "--seed",
            "from 0 to",
        ),
        (
            &["reproduce", "intake", "--duration", "-1"][..],
            "--duration",
            "from 1.0 to 3600.0 s",
        ),
        (
            &["reproduce", "intake", "--duration", "1e300"][..],
            "--duration",
            "from 1.0 to 3600.0 s",
        ),
        (
            &["reproduce", "intake", "--egr", "-0.5"][..],
            "--egr",
            "from 0.0 to 1.0",
        ),
        (
            &["calibrate", "x.toml", "-o", "cal", "--block-s", "-1"][..],
            "--block-s",
            "from 0.1 to 86400.0 s",
        ),
        (
            &[
                "calibrate",
                "x.toml",
                "-o",
                "cal",
                "--false-alarms-per-hour",
                "nan",
            ][..],
            "--false-alarms-per-hour",
            "per hour",
        ),
    ] {
        let (ok, _, err) = run_in(dir.path(), args);
        assert!(!ok, "{args:?}");
        assert!(
            err.contains(flag) && err.contains(range) && !err.contains("unexpected argument"),
            "{args:?}: {err}"
        );
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// No command writes its output over one of its inputs: `simulate -o` its own scenario file
/// (through another path, a hard link, or a bundled scenario's `.toml`), `replay --out` or
/// `--events` the log or the configuration, `--out` and `--events` one file, `calibrate -o` the
/// directory of its `--config`.
#[test]
fn outputs_never_overwrite_inputs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let text = std::fs::read_to_string(root().join("fixtures/scenarios/throttle_tps_open.toml"))
        .expect("scenario")
        .replace("name = \"throttle_tps_open\"", "name = \"throttle_mine\"");
    std::fs::write(d.join("throttle_mine.toml"), &text).expect("write");
    std::fs::create_dir(d.join("sub")).expect("mkdir");
    #[cfg(unix)]
    std::fs::hard_link(d.join("throttle_mine.toml"), d.join("linked.mcap")).expect("link");
    for out in [
        "sub/../throttle_mine.toml",
        "./throttle_mine.toml",
        "linked.mcap",
    ] {
        if out == "linked.mcap" && !cfg!(unix) {
            continue;
        }
        let (ok, _, err) = run_in(d, &["simulate", "throttle_mine.toml", "-o", out]);
        assert!(!ok && err.contains("refusing"), "{out}: {err}");
        assert_eq!(
            std::fs::read_to_string(d.join("throttle_mine.toml")).expect("still there"),
            text,
            "{out}"
        );
    }
    // A bundled scenario's source file (here a copy named like it) is a .toml file.
    std::fs::write(d.join("throttle_tps_open.toml.orig"), "x").expect("write");
    let (ok, _, err) = run_in(
        d,
        &[
            "simulate",
            "throttle_tps_open",
            "-o",
            "sub/throttle_tps_open.toml",
        ],
    );
    assert!(
        !ok && err.contains("refusing") && err.contains(".toml"),
        "{err}"
    );
    assert!(!d.join("sub/throttle_tps_open.toml").exists());

    let log = d.join("in.mcap");
    std::fs::copy(root().join("fixtures/data/throttle_tps_open.mcap"), &log).expect("copy");
    let config = d.join("fdd.toml");
    std::fs::write(&config, fdd_monitor::runtime::config::DEFAULT_RUNTIME_TOML).expect("config");
    let before = std::fs::read(&log).expect("log");
    for (args, word) in [
        (
            &["replay", "in.mcap", "--out", "./in.mcap"][..],
            "the input log",
        ),
        (
            &["replay", "in.mcap", "--events", "sub/../in.mcap"][..],
            "the input log",
        ),
        (
            &[
                "replay", "in.mcap", "--config", "fdd.toml", "--events", "fdd.toml",
            ][..],
            "the --config file",
        ),
        (
            &[
                "replay", "in.mcap", "--out", "o.mcap", "--events", "./o.mcap",
            ][..],
            "the --out file",
        ),
    ] {
        let mut args = args.to_vec();
        args.push("--no-progress");
        let (ok, _, err) = run_in(d, &args);
        assert!(
            !ok && err.contains("refusing") && err.contains(word),
            "{args:?}: {err}"
        );
    }
    std::fs::rename(&log, d.join("in.a")).expect("rename");
    let (ok, _, err) = run_in(d, &["replay", "in.a", "--memory", "in", "--no-progress"]);
    assert!(
        !ok && err.contains("refusing to write --memory over the input log"),
        "{err}"
    );
    std::fs::rename(d.join("in.a"), &log).expect("rename");
    assert_eq!(std::fs::read(&log).expect("log"), before);
    assert!(!d.join("o.mcap").exists());
    let (ok, _, err) = run_in(
        d,
        &["calibrate", "in.mcap", "--config", "fdd.toml", "-o", "."],
    );
    assert!(
        !ok && err.contains("refusing") && err.contains("--config"),
        "{err}"
    );
}

/// The messages of `logs` (repository-relative fixtures), merged in log-time order into one
/// MCAP file at `out`.
fn merged_log(logs: &[&str], out: &Path) {
    let mut msgs = Vec::new();
    for l in logs {
        let reader = fdd_monitor::log::LogReader::open(root().join(l)).expect("fixture");
        for m in reader {
            msgs.push(m.expect("message"));
        }
    }
    msgs.sort_by_key(|m| m.log_time_ns);
    let mut w = fdd_monitor::log::LogWriter::create(out).expect("create");
    for m in &msgs {
        w.write_raw_json(&m.topic, m.log_time_ns, &m.data)
            .expect("write");
    }
    w.finish().expect("finish");
}

/// A log of both subsystems (the TPS open circuit and the intake leak, both from 10 s) keeps
/// each truth topic's fault state apart: each fault's onset, first DTC, delay and observable
/// time are what its own fixture alone gives (the leak was "detected" by the throttle's
/// P0122 at 10.019 s, and each truth's observability was added to the other's fault).
#[test]
fn two_truth_topics_keep_their_own_fault_onsets() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("both.mcap");
    let (throttle, intake) = (
        "fixtures/data/throttle_tps_open.mcap",
        "fixtures/data/intake_leak.mcap",
    );
    merged_log(&[throttle, intake], &log);
    /// The fault rows of a replay's ground-truth table, as words.
    fn fault_rows(log: &Path) -> Vec<Vec<String>> {
        let out = fdd()
            .arg("replay")
            .arg(log)
            .arg("--no-progress")
            .output()
            .expect("run");
        assert!(out.status.success(), "{}", text(&out.stderr));
        let stdout = text(&out.stdout);
        let table = stdout
            .split("\nGround truth")
            .nth(1)
            .unwrap_or_else(|| panic!("no truth in\n{stdout}"));
        table
            .lines()
            .skip(2)
            .take_while(|l| l.starts_with("  ") && !l.contains("estimate error"))
            .map(|l| l.split_whitespace().map(str::to_string).collect())
            .collect()
    }
    let both = fault_rows(&log);
    let alone: Vec<Vec<String>> = [throttle, intake]
        .iter()
        .flat_map(|l| fault_rows(&root().join(l)))
        .collect();
    assert_eq!(both.len(), 2, "{both:?}");
    for (mut b, a) in both.into_iter().zip(alone) {
        let topic = b.remove(1);
        assert!(topic.starts_with("/truth/"), "{b:?}");
        assert_eq!(b, a, "fault of {topic} in the merged log vs its own log");
    }
}

/// A log none of whose chunks decode (a compression this build does not read, as lz4 was
/// before fdd read it) fails naming the file and the first chunk's error, instead of a
/// successful replay of nothing.
#[test]
fn a_log_whose_chunks_all_fail_is_an_error() {
    use fdd_monitor::log::{LogWriter, MotorVoltage};
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("odd.mcap");
    let mut w = LogWriter::create(&log).expect("create");
    for k in 0..5000u64 {
        w.write_message(k * 1_000_000, &MotorVoltage { voltage_v: 0.5 })
            .expect("write");
    }
    w.finish().expect("finish");
    // Every chunk (and its index) says it is compressed with "zzzz"; the CRCs that cover those
    // bytes are zeroed (MCAP: not computed).
    let mut b = std::fs::read(&log).expect("read");
    let (mut pos, end) = (8usize, b.len() - 8);
    let (mut chunks, u64_at) = (0, |b: &[u8], i: usize| {
        u64::from_le_bytes(b[i..i + 8].try_into().expect("8 bytes")) as usize
    });
    while pos + 9 <= end {
        let (op, len) = (b[pos], u64_at(&b, pos + 1));
        let body = pos + 9;
        let compression_at = match op {
            0x06 => Some(body + 8 + 8 + 8 + 4),
            0x08 => {
                let map_len =
                    u32::from_le_bytes(b[body + 32..body + 36].try_into().expect("4")) as usize;
                Some(body + 36 + map_len + 8)
            }
            0x0F => {
                b[body..body + 4].fill(0);
                None
            }
            0x02 => {
                b[body + 16..body + 20].fill(0);
                None
            }
            _ => None,
        };
        if let Some(at) = compression_at {
            assert_eq!(&b[at..at + 8], b"\x04\x00\x00\x00zstd", "record at {pos}");
            b[at + 4..at + 8].copy_from_slice(b"zzzz");
            chunks += usize::from(op == 0x06);
        }
        pos = body + len;
    }
    assert!(chunks >= 1);
    std::fs::write(&log, b).expect("write");
    let (ok, stdout, err) = run_in(dir.path(), &["replay", "odd.mcap", "--no-progress"]);
    assert!(!ok, "a replay of nothing succeeded:\n{stdout}");
    assert!(
        err.contains("odd.mcap")
            && err.contains("no message could be read")
            && err.contains("chunk"),
        "{err}"
    );
    assert!(err.contains("zzzz"), "the first chunk's error: {err}");
}

/// A log beyond one of the reader's limits is refused with the limit's name and the key of the
/// runtime configuration that raises it; raised there, the same log replays.
#[test]
fn a_log_over_a_read_limit_names_the_key_that_raises_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let fixture = root().join("fixtures/data/throttle_tps_open.mcap");
    let cfg = std::fs::read_to_string(root().join("config/fdd.toml")).expect("read config");
    let limited = cfg.replace("max_channels = 10000 ", "max_channels = 2 ");
    assert_ne!(
        limited, cfg,
        "config/fdd.toml sets [replay.limits] max_channels"
    );
    std::fs::write(dir.path().join("limited.toml"), &limited).expect("write");
    let log = fixture.to_str().expect("utf-8 path");
    let (ok, _, err) = run_in(
        dir.path(),
        &["replay", log, "--config", "limited.toml", "--no-progress"],
    );
    assert!(!ok, "a log over max_channels replayed");
    assert!(
        err.contains("throttle_tps_open.mcap")
            && err.contains("max_channels = 2")
            && err.contains("`[replay.limits] max_channels`"),
        "{err}"
    );
    let raised = cfg.replace("max_channels = 10000 ", "max_channels = 4 ");
    std::fs::write(dir.path().join("raised.toml"), raised).expect("write");
    let (ok, _, err) = run_in(
        dir.path(),
        &["replay", log, "--config", "raised.toml", "--no-progress"],
    );
    assert!(ok, "{err}");
}

/// `--config /dev/zero` (a file with no end) was read until memory ran out; it is now refused
/// after the 4 MiB a text file may have, naming the file.
#[test]
fn a_config_without_an_end_is_refused_not_read_forever() {
    let log = root().join("fixtures/data/throttle_tps_open.mcap");
    let log = log.to_str().expect("utf-8 path");
    for args in [
        vec!["replay", log, "--config", "/dev/zero", "--no-progress"],
        vec![
            "reproduce",
            "table2",
            "--samples",
            "10",
            "--config",
            "/dev/zero",
        ],
    ] {
        let (ok, _, err) = run_in(root(), &args);
        assert!(!ok, "{args:?} succeeded");
        assert!(
            err.contains("/dev/zero") && err.contains("larger than"),
            "{args:?}: {err}"
        );
    }
}
