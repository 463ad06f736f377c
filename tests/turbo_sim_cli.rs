//! `fdd simulate` on turbo scenarios (a bundled fixture, a file, a directory, a generated set's
//! refusals) and `fdd replay` reading the simulated truth as it reads the imported LiU-ICE one.

use std::path::Path;
use std::process::{Command, Output};

fn fdd() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_fdd"));
    c.env_remove("RUST_LOG").env_remove("RUST_BACKTRACE");
    c
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

const SHORT: &str = "monitor = \"turbo\"\nduration_s = 3.0\nseed = 4\n\n[profile]\nstyle = \"tip_in_out\"\n\n[fault]\nkind = \"leak_im\"\ndiameter_mm = 5\nstart_s = 1.0\n";

#[test]
fn a_bundled_turbo_scenario_simulates_to_its_fixture_from_anywhere() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("leak.mcap");
    let o = fdd()
        .args(["simulate", "turbo_leak_ic", "-o"])
        .arg(&log)
        .current_dir(dir.path())
        .output()
        .expect("run");
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("600 frames, 6600 messages"),
        "{}",
        text(&o)
    );
    let fresh = std::fs::read(&log).expect("log");
    let committed =
        std::fs::read(root().join("fixtures/data/turbo/turbo_leak_ic.mcap")).expect("fixture");
    assert!(fresh == committed, "differs from the committed fixture");
    let o = fdd().args(["simulate", "--list"]).output().expect("run");
    let listed = text(&o);
    assert!(
        listed.contains("turbo_leak_ic") && listed.contains("leak_ic_6mm from 15 s"),
        "{listed}"
    );
    assert!(listed.contains("turbo_heldout"), "{listed}");
}

#[test]
fn a_directory_of_turbo_scenarios_becomes_a_directory_of_logs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scen = dir.path().join("scenarios");
    std::fs::create_dir(&scen).expect("mkdir");
    for name in ["turbo_a", "turbo_b"] {
        std::fs::write(
            scen.join(format!("{name}.toml")),
            format!("name = \"{name}\"\n{SHORT}"),
        )
        .expect("write");
    }
    // A throttle or intake file beside them is not a turbo scenario and is left alone.
    std::fs::write(scen.join("notes.toml"), "monitor = \"intake\"\n").expect("write");
    let out = dir.path().join("logs");
    let o = fdd()
        .args(["simulate"])
        .arg(&scen)
        .arg("-o")
        .arg(&out)
        .output()
        .expect("run");
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("120 frames"), "{}", text(&o));
    for name in ["turbo_a", "turbo_b"] {
        assert!(out.join(format!("{name}.mcap")).is_file(), "{name}");
    }
    // A set or a directory is not written into one .mcap file.
    let o = fdd()
        .args(["simulate", "turbo_heldout", "-o"])
        .arg(dir.path().join("x.mcap"))
        .output()
        .expect("run");
    assert!(!o.status.success());
    assert!(text(&o).contains("give -o a directory"), "{}", text(&o));
}

#[test]
fn a_bad_turbo_scenario_is_refused_naming_the_file_and_the_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("turbo_bad.toml");
    std::fs::write(
        &file,
        format!(
            "name = \"turbo_bad\"\n{}",
            SHORT.replace("diameter_mm = 5", "diameter_mm = 4.5")
        ),
    )
    .expect("write");
    let o = fdd()
        .arg("simulate")
        .arg(&file)
        .arg("-o")
        .arg(dir.path().join("bad.mcap"))
        .output()
        .expect("run");
    assert!(!o.status.success());
    let t = text(&o);
    assert!(
        t.contains("turbo_bad.toml")
            && t.contains("fault.diameter_mm")
            && t.contains("whole number"),
        "{t}"
    );
    assert!(!dir.path().join("bad.mcap").exists());
    // The name must be the file's stem.
    std::fs::write(&file, format!("name = \"turbo_other\"\n{SHORT}")).expect("write");
    let o = fdd()
        .arg("simulate")
        .arg(&file)
        .arg("-o")
        .arg(dir.path().join("bad.mcap"))
        .output()
        .expect("run");
    assert!(!o.status.success());
    assert!(text(&o).contains("stem"), "{}", text(&o));
}

#[test]
fn replay_reads_the_simulated_truth_like_the_imported_one() {
    // config/fdd.toml reads the turbo truth topic (as tests/import.rs checks for the imported
    // LiU-ICE logs).
    let cfg = root().join("config/fdd.toml");
    let o = fdd()
        .arg("replay")
        .arg(root().join("fixtures/data/turbo/turbo_pim_gain.mcap"))
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("run");
    let out = text(&o);
    assert!(o.status.success(), "{out}");
    assert!(out.contains("/truth/turbo"), "{out}");
    assert!(
        out.lines()
            .any(|l| l.contains("pim_gain_1.10") && l.contains("15.000")),
        "the onset is read: {out}"
    );
    assert!(
        out.contains("Problems (counted; the replay went on)\n  none"),
        "{out}"
    );
}
