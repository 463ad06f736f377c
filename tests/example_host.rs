//! `examples/host.rs` (the host loop of the README) builds with the tests and runs on a
//! fixture: it reports the DTCs `fdd replay` reports, the switch of the position output to the
//! wattmeter estimate, reads the DTC memory by status mask and clears it.

use std::path::PathBuf;
use std::process::Command;

/// The example binary cargo built beside this test binary (`target/<profile>/examples/host`).
fn example() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    let dir = exe.parent().and_then(|d| d.parent()).expect("target dir");
    dir.join("examples").join("host")
}

#[test]
fn the_host_example_runs_on_a_fixture() {
    let root = env!("CARGO_MANIFEST_DIR");
    let out = Command::new(example())
        .arg(format!("{root}/fixtures/data/throttle_tps_open.mcap"))
        .output()
        .expect("run examples/host (built by cargo test)");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The DTCs and times `fdd replay` prints for this fixture (README, tests/replay.rs).
    assert!(
        text.contains("10.019 s  P0122-16  tps_circuit_low"),
        "{text}"
    );
    assert!(
        text.contains("10.019 s  P2106-00  position_from_wattmeter"),
        "{text}"
    );
    assert!(text.contains("from wattmeter_estimate"), "{text}");
    assert!(text.contains("  P0122-16  0x27  occurrences 1"), "{text}");
    assert!(text.contains("freeze frame: motor_voltage="), "{text}");
    assert!(
        text.contains("DTCs with any failure bit after the clear: 0"),
        "{text}"
    );
}
