//! End-to-end checks of the Table II reproduction: determinism, the protocol's properties, the
//! accuracy the wattmeter-only UKFs must keep, and the CLI's handling of bad input.

use std::process::Command;

use fdd::config::ThrottleConfig;
use fdd::reproduce::table2::{render, run, Table2Settings};

fn settings(samples: usize, seed: u64, wattmeter_std: f64) -> Table2Settings {
    Table2Settings {
        samples,
        seed,
        wattmeter_std,
        particles: None,
    }
}

#[test]
fn same_seed_same_numbers_and_noise_level_does_not_change_truth() {
    let cfg = ThrottleConfig::load(None).expect("embedded config");
    let a = run(&cfg, &settings(30_000, 7, 1.0)).expect("runs");
    let b = run(&cfg, &settings(30_000, 7, 1.0)).expect("runs");
    for (x, y) in a.ukfs.iter().zip(&b.ukfs) {
        assert_eq!(x.error, y.error, "{} not deterministic", x.name);
    }
    let c = run(&cfg, &settings(30_000, 7, 0.1)).expect("runs");
    assert_eq!(
        a.mode_share, c.mode_share,
        "truth must not depend on the sensor noise"
    );
    let d = run(&cfg, &settings(30_000, 8, 1.0)).expect("runs");
    assert_ne!(
        a.mode_share, d.mode_share,
        "another seed gives another trajectory"
    );
}

#[test]
fn wattmeter_ukfs_stay_within_the_papers_error() {
    let cfg = ThrottleConfig::load(None).expect("embedded config");
    let r = run(&cfg, &settings(300_000, 1, 1.0)).expect("runs");
    println!("{}", render(&r));
    for share in r.mode_share {
        assert!(
            share >= 0.05,
            "each mode must hold at least 5% of samples: {:?}",
            r.mode_share
        );
    }
    for e in &r.ukfs {
        assert_eq!(e.rejected_steps, 0, "{} rejected steps", e.name);
        assert!(
            e.error.std() <= 4.0,
            "{}: std {:.3} deg",
            e.name,
            e.error.std()
        );
        assert!(
            e.error.mean().abs() <= 1.0,
            "{}: mean {:.3} deg",
            e.name,
            e.error.mean()
        );
    }
}

#[test]
fn a_better_wattmeter_does_not_hurt_the_symmetric_set() {
    let cfg = ThrottleConfig::load(None).expect("embedded config");
    let coarse = run(&cfg, &settings(300_000, 1, 1.0)).expect("runs");
    let fine = run(&cfg, &settings(300_000, 1, 0.1)).expect("runs");
    let (c, f) = (&coarse.ukfs[0], &fine.ukfs[0]);
    assert_eq!(c.name, "UKF-AHSM");
    assert!(
        f.error.std() <= c.error.std(),
        "AHSM std with W = 0.1: {:.3}, with W = 1: {:.3}",
        f.error.std(),
        c.error.std()
    );
}

#[test]
fn particle_filter_reference_runs_on_the_same_data() {
    let cfg = ThrottleConfig::load(None).expect("embedded config");
    let mut s = settings(5_000, 3, 1.0);
    s.particles = Some(300);
    let r = run(&cfg, &s).expect("runs");
    let pf = r.particle_filter.expect("requested");
    assert_eq!(pf.error.count(), 5_000);
    assert!(pf.error.std() < 10.0, "PF std {}", pf.error.std());
}

/// The default config text with the line assigning `key` replaced by `key = value`.
fn with_line(key: &str, value: &str) -> String {
    let text = fdd::config::DEFAULT_THROTTLE_TOML;
    let prefix = format!("{key} = ");
    assert!(
        text.lines().any(|l| l.starts_with(&prefix)),
        "no `{key}` line"
    );
    text.lines()
        .map(|l| {
            if l.starts_with(&prefix) {
                format!("{key} = {value}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn bad_settings_and_config_are_named() {
    let cfg = ThrottleConfig::load(None).expect("embedded config");
    let err = run(&cfg, &settings(10, 1, -1.0)).unwrap_err().to_string();
    assert!(err.contains("wattmeter-std"), "{err}");
    let err = run(&cfg, &settings(0, 1, 1.0)).unwrap_err().to_string();
    assert!(err.contains("samples"), "{err}");

    // Filter settings are checked when the file is parsed, naming the file and the key.
    let text = with_line("arm_w0", "1.5");
    let err = ThrottleConfig::parse(&text, "test.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("test.toml: [wattmeter_ukf] arm_w0 = 1.5: "),
        "{err}"
    );

    let text = with_line("dt_s", "-0.001");
    let err = ThrottleConfig::parse(&text, "test.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("test.toml") && err.contains("dt_s"), "{err}");

    let text = fdd::config::DEFAULT_THROTTLE_TOML.replace("ahsm_lambda", "ahsm_lambada");
    let err = ThrottleConfig::parse(&text, "test.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("ahsm_lambada"), "{err}");

    let err = ThrottleConfig::load(Some(std::path::Path::new("/nonexistent/throttle.toml")))
        .unwrap_err()
        .to_string();
    assert!(err.contains("/nonexistent/throttle.toml"), "{err}");
}

#[test]
fn cli_prints_the_table_and_refuses_bad_arguments() {
    let exe = env!("CARGO_BIN_EXE_fdd");
    let out = Command::new(exe)
        .args(["reproduce", "table2", "--samples", "2000", "--seed", "2"])
        .output()
        .expect("runs");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for label in ["UKF-AHSM", "UKF-ARM", "UKF-AGM", "mode share", "wall time"] {
        assert!(text.contains(label), "missing {label} in\n{text}");
    }
    let out = Command::new(exe)
        .args([
            "reproduce",
            "table2",
            "--samples",
            "10",
            "--wattmeter-std",
            "nan",
        ])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("wattmeter-std"));
    let out = Command::new(exe)
        .args(["reproduce", "table2", "--config", "/nonexistent.toml"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent.toml"));
}
