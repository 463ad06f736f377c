//! End-to-end checks of `fdd reproduce intake`: on a 30 s tip-in/tip-out drive every EKF's
//! intake-valve flow RMSE is at most half that of the flow computed from the raw MAP, and the
//! federated filter's mean NIS is within 10 % of the measurement dimension (and equals the
//! centralized EKF's); the CLI prints the table.

use std::process::Command;

use fdd::reproduce::intake::{render, run, IntakeSettings};

fn short() -> IntakeSettings {
    IntakeSettings {
        duration_s: 30.0,
        ..IntakeSettings::default()
    }
}

#[test]
fn ekf_flow_rmse_at_most_half_of_raw_map_and_federated_is_consistent() {
    let r = run(&short()).expect("runs");
    println!("{}", render(&r));
    let raw = r.row("MAP sensor").expect("MAP row").rmse_winv_kg_s;
    for name in ["centralized EKF", "decentralized EKF", "federated EKF"] {
        let row = r.row(name).expect("filter row");
        let ratio = row.rmse_winv_kg_s / raw;
        println!("{name}: W_inv RMSE / raw-MAP W_inv RMSE = {ratio:.3} (limit 0.5)");
        assert!(ratio <= 0.5, "{name}: ratio {ratio}");
        assert_eq!(row.rejected_steps, 0, "{name} refused steps");
    }
    let fed = r.row("federated EKF").expect("row");
    let (nis, dof) = fed.mean_nis.expect("nis");
    let dev = (nis / dof as f64 - 1.0).abs();
    println!(
        "federated mean NIS {nis:.3} for dof {dof}: deviation {:.1} % (limit 10 %)",
        100.0 * dev
    );
    assert!(dev <= 0.10, "federated mean NIS {nis}");
    let (cen_nis, _) = r.row("centralized EKF").unwrap().mean_nis.unwrap();
    assert!(
        (cen_nis - nis).abs() <= 1e-6 * nis,
        "federated {nis} vs centralized {cen_nis}"
    );
    let dec = r.row("decentralized EKF").unwrap().mean_nis.unwrap();
    println!(
        "decentralized (naive) mean NIS {:.3} / {} (reported as is)",
        dec.0, dec.1
    );
}

#[test]
fn cli_prints_the_table_and_rejects_bad_settings() {
    let out = Command::new(env!("CARGO_BIN_EXE_fdd"))
        .args(["reproduce", "intake", "--duration", "10", "--seed", "3"])
        .output()
        .expect("runs fdd");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    for s in [
        "centralized EKF",
        "decentralized EKF",
        "federated EKF",
        "MAP sensor",
        "MAF sensor",
        "3.270e3",
        "7.560e-4",
    ] {
        assert!(text.contains(s), "missing {s:?} in\n{text}");
    }
    let bad = Command::new(env!("CARGO_BIN_EXE_fdd"))
        .args(["reproduce", "intake", "--egr", "2"])
        .output()
        .expect("runs fdd");
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("egr"));
}

/// The reproduction's filter settings are the intake monitor's defaults, so the table describes
/// the filters the monitor runs.
#[test]
fn reproduction_uses_the_monitor_filter_settings() {
    use fdd::reproduce::intake::{FEDERATED_SHARES, P0_STD_REL, Q_STD};
    let m = fdd_monitor::intake::IntakeMonitorConfig::default();
    assert_eq!(m.q_std, Q_STD);
    assert_eq!(m.p0_std, P0_STD_REL);
    assert_eq!(m.federated_shares, FEDERATED_SHARES);
}
