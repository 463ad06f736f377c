//! `fdd reproduce wheel`: the slip-control tutorial's experiment on fdd's whole-car truth. The
//! library is run on a held-out subset (every surface from 10 m/s with held-out car 11, and the
//! mass experiment on car 11): every stop is simulated on its own, so these are the figures the
//! whole command prints for those cases. Asserted: what holds of the line on them (the
//! mass from 300 kg; the friction beside a loop on the true slip on snow), with the figures of
//! what does not in the comments; that the tutorial's filter estimates the friction worse than
//! fdd's on dry and wet asphalt; the stopping distances; that the table names every surface;
//! determinism; the CLI once with `--tuning-only`. `-- --nocapture` prints the table.

use std::process::Command;

use fdd::reproduce::wheel::{self, LoopOn, StopRow, WheelReport, WheelSettings};

fn subset() -> WheelReport {
    wheel::run(&WheelSettings {
        held_out_speeds_m_s: Some(vec![10.0]),
        held_out_seeds: Some(vec![11]),
        ..Default::default()
    })
    .unwrap_or_else(|e| panic!("{e}"))
}

fn row<'a>(r: &'a WheelReport, surface: &str, estimator: LoopOn) -> &'a StopRow {
    r.held_out
        .iter()
        .find(|x| x.surface == surface && x.estimator == estimator)
        .unwrap_or_else(|| panic!("no held-out row {surface} {estimator:?}"))
}

#[test]
fn wheel_reproduction_on_held_out_cases() {
    let r = subset();
    let text = wheel::render(&r);
    println!("{text}");
    // Every surface is in the table, and the same run prints the same.
    for s in ["dry", "wet", "snow", "ice"] {
        assert!(text.contains(&format!("\n{s:<5}")), "{s} missing");
    }
    assert_eq!(text, wheel::render(&subset()), "not deterministic");

    for s in ["dry", "wet", "snow", "ice"] {
        let (tut, fdd) = (row(&r, s, LoopOn::Tutorial), row(&r, s, LoopOn::Fdd));
        for x in [tut, fdd] {
            assert_eq!(x.in_loop.not_stopped + x.beside_truth.not_stopped, 0, "{s}");
            assert_eq!(x.in_loop.refused_steps, 0, "{s}");
        }
        // The slip line is not met on any surface (the raw slip knows the true speed; every
        // estimate dead-reckons it through the stop): 2.2-2.4 x the raw slip's RMSE on dry,
        // wet and snow from 10 m/s, 12.6 x on ice. Not asserted as a pass; the ratio is
        // printed.
        println!(
            "{s}: fdd slip RMSE {:.4} vs raw {:.4}",
            fdd.in_loop.slip_rmse, fdd.in_loop.raw_slip_rmse
        );
    }
    // Beside a loop fed the true slip, fdd's friction comes within 0.05 within 0.5 s on snow
    // (0.335 s); on ice it takes 0.675 s, on dry and wet the load transfer keeps it out.
    let snow = row(&r, "snow", LoopOn::Fdd);
    assert!(
        snow.beside_truth.mu_time_s.is_some_and(|t| t <= 0.5),
        "{:?}",
        snow.beside_truth.mu_time_s
    );
    // The tutorial's friction (its known curve at its noisy slip) is far worse than fdd's on
    // dry and wet asphalt, where the curve is steep below the peak: 0.78 / 0.56 against
    // 0.14 / 0.10 beside the truth. On snow and ice, whose curves are flat around the
    // controller's slip, knowing the surface is worth more than the torque balance, and the
    // tutorial's is the better one (0.021 / 0.005 against 0.045 / 0.025).
    for s in ["dry", "wet"] {
        let (tut, fdd) = (row(&r, s, LoopOn::Tutorial), row(&r, s, LoopOn::Fdd));
        assert!(
            tut.beside_truth.mu_rmse > 3.0 * fdd.beside_truth.mu_rmse,
            "{s}: tutorial {} fdd {}",
            tut.beside_truth.mu_rmse,
            fdd.beside_truth.mu_rmse
        );
    }
    // With fdd's estimator in the loop the car stops within 5 % of the distance the same
    // controller fed the true slip needs on dry, wet and snow from 10 m/s (3.7, 3.2, 2.9 %),
    // within 30 % on ice (24.5 %), and shorter than with the tutorial's filter on snow and ice.
    for (s, tol) in [("dry", 0.05), ("wet", 0.05), ("snow", 0.05), ("ice", 0.3)] {
        let fdd = row(&r, s, LoopOn::Fdd);
        let excess = fdd.in_loop.distance_m / fdd.distance_true_slip_m - 1.0;
        assert!(excess.abs() <= tol, "{s}: {excess}");
    }
    for s in ["snow", "ice"] {
        let (tut, fdd) = (row(&r, s, LoopOn::Tutorial), row(&r, s, LoopOn::Fdd));
        assert!(
            fdd.in_loop.distance_m < tut.in_loop.distance_m,
            "{s}: {} vs {}",
            fdd.in_loop.distance_m,
            tut.in_loop.distance_m
        );
    }
    // The mass (rear left, held-out car 11): from 300 kg within 5 % from the 3rd event on
    // (451.5 kg after 10); from 600 kg it settles at 476 kg after 10 events, 5.8 % high: the
    // issue's line holds from below only.
    let rl = |kind: LoopOn, m0: f64| {
        r.mass_held_out[0]
            .tracks
            .iter()
            .find(|t| t.estimator == kind && t.start_kg == m0 && t.corner == "RL")
            .unwrap_or_else(|| panic!("no track {kind:?} {m0}"))
    };
    let from_300 = rl(LoopOn::Fdd, 300.0);
    assert!(
        from_300.events_to_band.is_some_and(|e| e <= 10),
        "{from_300:?}"
    );
    let from_600 = rl(LoopOn::Fdd, 600.0);
    let err = from_600.after_limit_kg / 450.0 - 1.0;
    assert!(err > 0.0 && err < 0.07, "{from_600:?}");
    // The tutorial's P0 = 0 keeps its mass at the start: within 1 % after 15 events.
    for m0 in [300.0, 600.0] {
        let t = rl(LoopOn::Tutorial, m0);
        assert!(
            t.after_event_kg.iter().all(|m| (m / m0 - 1.0).abs() < 0.01),
            "{t:?}"
        );
    }
}

#[test]
fn the_cli_runs_the_tuning_cases() {
    let out = Command::new(env!("CARGO_BIN_EXE_fdd"))
        .args(["reproduce", "wheel", "--tuning-only"])
        .output()
        .expect("fdd runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("tuning: 20 m/s on dry and snow"), "{text}");
    assert!(!text.contains("held-out"), "{text}");
}

#[test]
fn a_bad_parameter_file_is_named() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("wheel.toml");
    let text =
        include_str!("../config/wheel.toml").replace("friction_pull = ", "friction_pull = 7.0 #");
    std::fs::write(&path, text).expect("write");
    let out = Command::new(env!("CARGO_BIN_EXE_fdd"))
        .args(["reproduce", "wheel", "--tuning-only", "--params"])
        .arg(&path)
        .output()
        .expect("fdd runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("wheel.toml") && err.contains("[estimator]") && err.contains("friction_pull"),
        "{err}"
    );
}
