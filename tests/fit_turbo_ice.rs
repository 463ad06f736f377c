//! `fdd fit turbo-ice`: the committed `config/turbo_liu_ice.toml` is what the command writes from
//! the fault-free calibration log (judged on the two other fault-free logs), and bad input fails
//! with an error naming the file and the missing topic.
//!
//! `FDD_BLESS=1 cargo test --release --test fit_turbo_ice` rewrites the committed file;
//! `-- --nocapture` prints the figures.

use std::path::PathBuf;
use std::process::Command;

const DIR: &str = "fixtures/data/real/liu-ice";
const COMMITTED: &str = "config/turbo_liu_ice.toml";

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fdd(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_fdd"))
        .current_dir(root())
        .args(args)
        .output()
        .expect("fdd runs")
}

fn log(name: &str) -> String {
    format!("{DIR}/ftp75city2_{name}.mcap")
}

#[test]
fn command_reproduces_the_committed_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("turbo_liu_ice.toml");
    let (calib, judge_a, judge_b) = (log("NF_0-100s"), log("NF_window"), log("NF_140-260s"));
    let args = [
        "fit",
        "turbo-ice",
        "--log",
        &calib,
        "--judge",
        &judge_a,
        "--judge",
        &judge_b,
        "--start",
        "config/turbo_vep4.toml",
        "-o",
        out.to_str().expect("utf-8 path"),
    ];
    let run = fdd(&args);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    println!("{}", String::from_utf8_lossy(&run.stdout));
    let written = std::fs::read(&out).expect("written");
    let committed_path = root().join(COMMITTED);
    if std::env::var_os("FDD_BLESS").is_some() {
        std::fs::write(&committed_path, &written).expect("bless");
    }
    let committed = std::fs::read(&committed_path).expect("committed file exists");
    assert!(
        written == committed,
        "{COMMITTED} differs from what `fdd fit turbo-ice` writes (FDD_BLESS=1 rewrites it)"
    );
    // Deterministic: a second run (with --json) writes the same bytes; the file loads, and
    // its [model] builds a model.
    let mut json_args = args.to_vec();
    json_args.push("--json");
    let json = fdd(&json_args);
    assert!(json.status.success());
    assert_eq!(std::fs::read(&out).expect("rewritten"), committed);
    let params = fdd::fit::load_params(&committed_path).expect("the committed file loads");
    fdd_estimators::models::turbo::TurboModel::new(params).expect("and builds a model");
    // The figures are for the three files, the calibration log first; the fault windows are
    // never read.
    let v: serde_json::Value = serde_json::from_slice(&json.stdout).expect("JSON");
    let logs = v["logs"].as_array().expect("logs");
    assert_eq!(logs.len(), 3);
    assert!(logs[0]["file"]
        .as_str()
        .expect("name")
        .ends_with("NF_0-100s.mcap"));
    let text = String::from_utf8_lossy(&committed);
    assert!(
        !text.contains("_f_p") && !text.contains("_f_waf"),
        "a fault window is named"
    );
    for l in logs {
        let pct = |q: &str| l["figures"][q]["rmse_pct"].as_f64().expect("figure");
        println!(
            "{}: p_im {:.2} %, p_ic {:.2} %, air {:.2} %",
            l["file"],
            pct("p_im"),
            pct("p_ic"),
            pct("air_flow")
        );
    }
}

#[test]
fn a_log_without_a_topic_fails_naming_the_topic_and_the_file() {
    // The calibration CSV imported with a mapping that leaves out the intercooler temperature.
    let dir = tempfile::tempdir().expect("temp dir");
    let full = std::fs::read_to_string(root().join("config/import/liu_ice.toml")).expect("mapping");
    let mapping: String = full
        .split("[[topics]]")
        .enumerate()
        .filter(|(_, block)| !block.contains("\"/turbo/T_ic\""))
        .map(|(i, block)| {
            if i == 0 {
                block.to_string()
            } else {
                format!("[[topics]]{block}")
            }
        })
        .collect();
    assert!(full.contains("/turbo/T_ic") && !mapping.contains("/turbo/T_ic"));
    let map_path = dir.path().join("no_t_ic.toml");
    std::fs::write(&map_path, mapping).expect("write mapping");
    let broken = dir.path().join("no_t_ic.mcap");
    let import = fdd(&[
        "import",
        &format!("{DIR}/ftp75city2_NF_0-100s.csv"),
        "--mapping",
        map_path.to_str().expect("utf-8"),
        "-o",
        broken.to_str().expect("utf-8"),
        "--no-progress",
    ]);
    assert!(
        import.status.success(),
        "{}",
        String::from_utf8_lossy(&import.stderr)
    );
    let out = dir.path().join("out.toml");
    let run = fdd(&[
        "fit",
        "turbo-ice",
        "--log",
        broken.to_str().expect("utf-8"),
        "--start",
        "config/turbo_vep4.toml",
        "-o",
        out.to_str().expect("utf-8"),
    ]);
    assert!(!run.status.success(), "a log without T_ic must fail");
    assert!(!out.exists(), "no output on failure");
    let e = String::from_utf8_lossy(&run.stderr);
    assert!(
        e.contains("no_t_ic.mcap") && e.contains("/turbo/T_ic") && e.contains("temperature_k"),
        "{e}"
    );
    // A file that is not a log: the reader's error names it.
    let not_log = dir.path().join("not_a_log.mcap");
    std::fs::write(&not_log, "not an MCAP file").expect("write");
    let run = fdd(&[
        "fit",
        "turbo-ice",
        "--log",
        not_log.to_str().expect("utf-8"),
        "--start",
        "config/turbo_vep4.toml",
        "-o",
        out.to_str().expect("utf-8"),
    ]);
    assert!(!run.status.success());
    let e = String::from_utf8_lossy(&run.stderr);
    assert!(e.contains("not_a_log.mcap"), "{e}");
}
