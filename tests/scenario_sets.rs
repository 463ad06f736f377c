//! The committed scenario sets (`fixtures/sets/`) are exactly what their generator scripts
//! write: a hand edit of a tuning or held-out file, or a script change whose files were not
//! regenerated, fails here. The scripts need only Python's standard library; without
//! `python3` the check is skipped outside CI.

use std::path::Path;
use std::process::Command;

fn check(script: &str) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = match Command::new("python3")
        .arg(root.join("tools").join(script))
        .arg("--check")
        .output()
    {
        Ok(o) => o,
        Err(e) => {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI must have python3: {e}"
            );
            eprintln!("python3 not found ({e}): {script} --check skipped");
            return;
        }
    };
    assert!(
        out.status.success(),
        "{script} --check: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn throttle_sets_regenerate_byte_for_byte() {
    check("make_sets_throttle.py");
}

#[test]
fn intake_sets_regenerate_byte_for_byte() {
    check("make_sets_intake.py");
}
