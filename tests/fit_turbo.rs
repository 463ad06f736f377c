//! `fdd fit turbo`: the committed `config/turbo_tsfs09.toml` is what the command writes, the
//! whole-model error figures, the component fits on synthetic data from the model itself, and
//! the errors for bad input.
//!
//! `FDD_BLESS=1 cargo test --release --test fit_turbo` rewrites the committed file;
//! `-- --nocapture` prints the error table.

use std::path::{Path, PathBuf};
use std::process::Command;

use fdd_estimators::models::turbo::fit::components::{
    fit_air_filter, fit_compressor, fit_exhaust, fit_exhaust_temp, fit_intercooler, fit_throttle,
    fit_turbine, fit_vol_eff,
};
use fdd_estimators::models::turbo::fit::{CompressorMapPoint, EnginePoint, FitOptions};
use fdd_estimators::models::turbo::{TurboInput, TurboModel, TurboParams};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

const DATA: &str = "fixtures/data/real/liu-tsfs09";
const COMMITTED: &str = "config/turbo_tsfs09.toml";

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

#[test]
fn command_reproduces_the_committed_file_and_meets_the_figures() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("turbo_tsfs09.toml");
    let out_s = out.to_str().expect("utf-8 path");
    let args = [
        "fit",
        "turbo",
        "--data",
        DATA,
        "--start",
        "config/turbo.toml",
        "-o",
        out_s,
    ];
    let text = fdd(&args);
    assert!(
        text.status.success(),
        "{}",
        String::from_utf8_lossy(&text.stderr)
    );
    println!("{}", String::from_utf8_lossy(&text.stdout));
    let written = std::fs::read(&out).expect("written");
    let committed_path = root().join(COMMITTED);
    if std::env::var_os("FDD_BLESS").is_some() {
        std::fs::write(&committed_path, &written).expect("bless");
    }
    let committed = std::fs::read(&committed_path).expect("committed file exists");
    assert!(
        written == committed,
        "{COMMITTED} differs from what `fdd fit turbo` writes (FDD_BLESS=1 rewrites it)"
    );
    // Deterministic: a second run writes the same bytes, and the file loads and validates.
    let mut json_args = args.to_vec();
    json_args.push("--json");
    let json = fdd(&json_args);
    assert!(json.status.success());
    assert_eq!(std::fs::read(&out).expect("rewritten"), committed);
    let params = fdd::fit::load_params(&committed_path).expect("the committed file loads");
    TurboModel::new(params).expect("and builds a model");

    let v: serde_json::Value = serde_json::from_slice(&json.stdout).expect("JSON");
    let pct = |set: &str, q: &str| v[set][q]["rmse_pct"].as_f64().expect("figure");
    for set in ["all", "held_out"] {
        println!(
            "{set}: p_ic {:.2} % (matched), p_im {:.2} %, m_dot_at {:.2} %, p_em {:.2} %",
            pct(set, "p_ic"),
            pct(set, "p_im"),
            pct(set, "m_dot_at"),
            pct(set, "p_em")
        );
    }
    // The targets, on all 344 points: p_im, p_ic and the air flow within 3 % of their
    // means, p_em within 5 % (the held-out figures are printed above; nothing was chosen on
    // them).
    for (q, target) in [
        ("p_im", 3.0),
        ("p_ic", 3.0),
        ("m_dot_at", 3.0),
        ("p_em", 5.0),
    ] {
        assert!(
            pct("all", q) <= target,
            "all points: {q} {} %",
            pct("all", q)
        );
    }
}

/// The generic TCSI set with the TSFS09 engine constants: the "truth" of the synthetic data.
fn truth() -> TurboParams {
    let mut p = fdd::fit::load_params(&root().join("config/turbo.toml")).expect("loads");
    let o = FitOptions::tsfs09();
    p.displacement_m3 = o.displacement_m3;
    p.stoichiometric_air_fuel_ratio = o.stoichiometric_air_fuel_ratio;
    p
}

/// Stationary points of the model itself over speed and throttle, wastegate closed, ambient
/// 100 kPa and 298 K, with Gaussian noise (0.1 % on pressures, 0.3 K on temperatures, 0.5 %
/// on the air flow), as engine-map points.
fn synthetic_points(p: &TurboParams, seed: u64) -> Vec<EnginePoint> {
    synthetic_points_wastegate(p, seed, |_| 0.0)
}

/// [`synthetic_points`] with the wastegate of the `i`-th point at `wastegate(i)`.
fn synthetic_points_wastegate(
    p: &TurboParams,
    seed: u64,
    wastegate: impl Fn(usize) -> f64,
) -> Vec<EnginePoint> {
    let model = TurboModel::new(p.clone()).expect("valid");
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).expect("normal");
    let mut out = Vec::new();
    for rpm in [1000.0, 1800.0, 2600.0, 3400.0, 4200.0] {
        for thr in [8.0, 12.0, 18.0, 25.0, 35.0, 50.0, 70.0, 100.0] {
            for lambda in [0.9, 1.0] {
                let u = TurboInput {
                    throttle_pct: thr,
                    engine_speed_rad_s: rpm / 60.0 * 2.0 * std::f64::consts::PI,
                    wastegate_frac: wastegate(out.len()),
                    lambda,
                    ambient_pressure_pa: 100_000.0,
                    ambient_temperature_k: 298.0,
                };
                let x = model.stationary_point(&u, None).expect("stationary").state;
                let s = model.signals(&x, &u);
                let mut pr = |v: f64| v * (1.0 + 1e-3 * n.sample(&mut rng));
                let (p_af, p_ic, p_im, p_em, p_t) = (
                    pr(s.p_af_pa),
                    pr(s.p_ic_pa),
                    pr(s.p_im_pa),
                    pr(s.p_em_pa),
                    pr(s.p_es_pa),
                );
                let mut t = |v: f64| v + 0.3 * n.sample(&mut rng);
                let (t_ic, t_im, t_em, t_t) = (t(s.t_ic_k), t(s.t_im_k), t(s.t_em_k), t(s.t_es_k));
                out.push(EnginePoint {
                    p_af_pa: p_af,
                    p_ic_pa: p_ic,
                    p_im_pa: p_im,
                    p_em_pa: p_em,
                    p_t_pa: p_t,
                    t_af_k: 298.0,
                    t_ic_k: t_ic,
                    t_im_k: t_im,
                    t_em_k: t_em,
                    t_t_k: t_t,
                    engine_speed_rev_s: rpm / 60.0,
                    throttle_frac: thr / 100.0,
                    air_flow_kg_s: s.w_af_kg_s * (1.0 + 5e-3 * n.sample(&mut rng)),
                    lambda,
                });
            }
        }
    }
    out
}

fn close(got: f64, want: f64, rel: f64, what: &str) {
    assert!(
        (got - want).abs() <= rel * want.abs(),
        "{what}: fitted {got}, true {want} (tolerance {rel})"
    );
}

#[test]
fn component_fits_recover_the_model_parameters_from_its_own_noisy_data() {
    let t = truth();
    let pts = synthetic_points(&t, 7);
    // Start every fitted value away from the truth.
    let mut start = t.clone();
    start.air_filter_resistance_pa2_s2_per_kg2_k *= 2.0;
    start.exhaust_resistance_pa2_s2_per_kg2_k *= 0.5;
    start.exhaust_temp_zero_flow_k = 900.0;
    start.exhaust_temp_flow_gain_k_s_per_kg = 500.0;
    start.exhaust_pipe_length_m = 0.2;

    let af = fit_air_filter(&pts, &start).expect("air filter");
    close(
        af.ambient_pressure_pa.value,
        100_000.0,
        1e-3,
        "ambient pressure",
    );
    close(
        af.resistance.value,
        t.air_filter_resistance_pa2_s2_per_kg2_k,
        0.05,
        "air filter H",
    );

    let ex = fit_exhaust(&pts, &start, 100_000.0).expect("exhaust");
    close(
        ex.resistance.value,
        t.exhaust_resistance_pa2_s2_per_kg2_k,
        0.05,
        "exhaust H",
    );

    // The truth's factor is 0.8 at every p_im: the fitted polynomial must be too.
    let ve = fit_vol_eff(&pts, &start).expect("volumetric efficiency");
    for kpa in [40.0, 80.0, 120.0] {
        for n in [1.0, 2.6, 4.2] {
            let [s1, s2] = ve.speed_coeffs_krpm;
            let v = ve.poly_kpa.iter().fold(0.0, |acc, c| acc * kpa + c) + s1 * n + s2 * n * n;
            close(v, t.vol_eff_factor, 0.02, "volumetric efficiency factor");
        }
    }

    let mut thr_start = start.clone();
    thr_start.throttle_area_coeffs_m2_rad = [1e-5, 0.0, 1e-3];
    let th = fit_throttle(&pts, &thr_start).expect("throttle");
    let mut fitted = t.clone();
    fitted.throttle_area_coeffs_m2_rad = th.coeffs;
    for pct in [12.0, 25.0, 35.0] {
        close(
            fitted.throttle_area_m2(pct),
            t.throttle_area_m2(pct),
            0.03,
            "throttle area",
        );
    }

    let et = fit_exhaust_temp(&pts, &start).expect("exhaust temperature");
    close(et.t0_k.value, t.exhaust_temp_zero_flow_k, 0.01, "T_0");
    close(
        et.c_eo.value,
        t.exhaust_temp_flow_gain_k_s_per_kg,
        0.1,
        "C_eo",
    );
    close(
        et.pipe_length_m.value,
        t.exhaust_pipe_length_m,
        0.1,
        "pipe length",
    );

    let mut ic_start = t.clone();
    ic_start.intercooler_effectiveness = 0.3;
    let ic = fit_intercooler(&pts, &ic_start).expect("intercooler");
    close(
        ic.effectiveness,
        t.intercooler_effectiveness,
        0.03,
        "intercooler effectiveness",
    );
}

#[test]
fn volumetric_efficiency_fit_recovers_a_speed_dependence() {
    // A truth whose factor depends on p_im and on the speed: 0.75 + 0.002 p_im[kPa] - 0.000005
    // p_im^2 + 0.05 n - 0.008 n^2 (n in 1000 rpm), unclamped over the points (1 to 400 kPa).
    let mut t = truth();
    t.vol_eff_factor = 1.0;
    t.vol_eff_poly_kpa = [0.0, 0.0, -5e-6, 2e-3, 0.75];
    t.vol_eff_poly_min_kpa = 1.0;
    t.vol_eff_poly_max_kpa = 400.0;
    t.vol_eff_speed_coeffs_krpm = [0.05, -0.008];
    t.vol_eff_speed_min_krpm = 0.5;
    t.vol_eff_speed_max_krpm = 5.0;
    t.validate().expect("valid truth");
    let pts = synthetic_points(&t, 11);
    let ve = fit_vol_eff(&pts, &t).expect("volumetric efficiency");
    let factor = |poly: &[f64; 5], s: [f64; 2], kpa: f64, n: f64| {
        poly.iter().fold(0.0, |acc, c| acc * kpa + c) + s[0] * n + s[1] * n * n
    };
    // At the points' own manifold pressures and speeds (the domain the data cover).
    let mut worst = 0.0f64;
    let mut sq = 0.0;
    for p in &pts {
        let (kpa, n) = (p.p_im_pa / 1000.0, p.engine_speed_rev_s * 60.0 / 1000.0);
        let want = factor(
            &t.vol_eff_poly_kpa,
            t.vol_eff_speed_coeffs_krpm,
            kpa.clamp(t.vol_eff_poly_min_kpa, t.vol_eff_poly_max_kpa),
            n,
        );
        let got = factor(
            &ve.poly_kpa,
            ve.speed_coeffs_krpm,
            kpa.clamp(ve.min_kpa, ve.max_kpa),
            n,
        );
        worst = worst.max((got / want - 1.0).abs());
        sq += (got / want - 1.0).powi(2);
    }
    let rms = (sq / pts.len() as f64).sqrt();
    println!("factor error: RMS {rms}, worst {worst}");
    assert!(
        rms < 0.005 && worst < 0.01,
        "relative factor error RMS {rms}, worst {worst}"
    );
    // The speed terms themselves, not only their sum with the polynomial: the truth's
    // speed part changes the factor by 0.033 between 1000 and 4200 rpm at any p_im.
    let part = |s: [f64; 2], n: f64| s[0] * n + s[1] * n * n;
    close(
        part(ve.speed_coeffs_krpm, 4.2) - part(ve.speed_coeffs_krpm, 1.0),
        part(t.vol_eff_speed_coeffs_krpm, 4.2) - part(t.vol_eff_speed_coeffs_krpm, 1.0),
        0.15,
        "speed part between 1000 and 4200 rpm",
    );
    // The speed range is the points' (1000 to 4200 rpm), rounded outwards to 0.1.
    assert_eq!((ve.speed_min_krpm, ve.speed_max_krpm), (1.0, 4.2));
}

#[test]
fn turbine_fit_recovers_the_turbine_flow_whatever_the_wastegate_passes() {
    // A truth whose turbine flow is linear in 1 - Pi_t over the whole range (its continuation
    // from 0.3), run with the wastegate half open at every other point: the fit must find the
    // turbine's flow from the power balance, not the whole exhaust flow.
    let mut t = truth();
    t.turbine_linear_ratio = 0.3;
    t.validate().expect("valid truth");
    let pts = synthetic_points_wastegate(&t, 5, |i| if i % 2 == 0 { 0.0 } else { 0.5 });
    let mut start = t.clone();
    start.turbine_flow_k1_kg_k05_per_s_kpa = 0.05;
    let tu = fit_turbine(&pts, &start).expect("turbine");
    assert!(tu.points >= 10, "{} points used", tu.points);
    let mut fitted = t.clone();
    fitted.turbine_flow_k1_kg_k05_per_s_kpa = tu.k1.value;
    fitted.turbine_linear_ratio = tu.linear_ratio;
    let flow = |q: &TurboParams, p: &EnginePoint| {
        let m = TurboModel::new(q.clone()).expect("valid");
        let x = m.state_from_pressures(
            [
                p.p_af_pa, p.p_ic_pa, p.p_ic_pa, p.p_im_pa, p.p_em_pa, p.p_t_pa,
            ],
            [p.t_af_k, p.t_ic_k, p.t_ic_k, p.t_im_k, p.t_em_k, p.t_t_k],
            1e4,
        );
        let u = TurboInput {
            throttle_pct: 50.0,
            engine_speed_rad_s: 300.0,
            wastegate_frac: 0.0,
            lambda: 1.0,
            ambient_pressure_pa: 100_000.0,
            ambient_temperature_k: 298.0,
        };
        m.signals(&x, &u).w_t_kg_s
    };
    for p in pts.iter().filter(|p| p.p_em_pa > 1.1 * p.p_t_pa) {
        close(flow(&fitted, p), flow(&t, p), 0.03, "turbine flow");
    }
    // Half the points bypass part of the exhaust: the fit says so.
    assert!(
        tu.bypass_share.0 > 0.05 && tu.bypass_share.1 > 0.2,
        "bypass {:?}",
        tu.bypass_share
    );
}

#[test]
fn shaft_fit_recovers_a_loss_torque_from_one_measured_turbo_speed() {
    use fdd_estimators::models::turbo::fit::shaft::fit_shaft_torque;
    use fdd_estimators::models::turbo::fit::ShaftAnchor;
    use fdd_estimators::models::turbo::X_OMEGA_T;
    // A truth with a speed-independent loss of 0.03 N m and a turbine flow linear in 1 - Pi_t
    // from 0.35 (the continuation the turbine fit picks for these points, so that its form is
    // the truth's), its map with the wastegate closed; one part-load point's turbo speed is
    // "measured". The fit starts without the loss and a wrong turbine flow.
    let mut t = truth();
    t.turbine_linear_ratio = 0.35;
    t.turbo_friction_torque_n_m = 0.03;
    t.validate().expect("valid truth");
    let pts = synthetic_points(&t, 9);
    let model = TurboModel::new(t.clone()).expect("valid");
    let u = TurboInput {
        throttle_pct: 18.0,
        engine_speed_rad_s: 1800.0 / 60.0 * std::f64::consts::TAU,
        wastegate_frac: 0.0,
        lambda: 1.0,
        ambient_pressure_pa: 100_000.0,
        ambient_temperature_k: 298.0,
    };
    let measured = model.stationary_point(&u, None).expect("stationary").state[X_OMEGA_T];
    let anchor = ShaftAnchor {
        throttle_pct: u.throttle_pct,
        engine_speed_rad_s: u.engine_speed_rad_s,
        p_im_pa: 60e3,
        wastegate_frac: Some(0.0),
        lambda: 1.0,
        ambient_temperature_k: 298.0,
        turbo_speed_rad_s: measured,
    };
    let mut start = t.clone();
    start.turbo_friction_torque_n_m = 0.0;
    start.turbine_flow_k1_kg_k05_per_s_kpa *= 1.5;
    let opts = FitOptions::tsfs09();
    let (fitted, fit) = fit_shaft_torque(&pts, &start, &anchor, 100_000.0, &opts).expect("fits");
    // The turbine fit reads the compressor's power at the intercooler's outlet pressure (the
    // map has no compressor-outlet pressure), a few % low on these points, and the torque
    // absorbs what the turbine flow misses: 10 % and 8 %, against a start 1.5 times off.
    close(fit.torque_n_m, 0.03, 0.1, "loss torque");
    close(
        fitted.turbine_flow_k1_kg_k05_per_s_kpa,
        t.turbine_flow_k1_kg_k05_per_s_kpa,
        0.08,
        "turbine k1 refitted with the torque",
    );
    close(fit.fitted_speed_rad_s, measured, 1e-6, "anchor speed");
    assert!(fit.start_speed_rad_s > 1.02 * measured, "{fit:?}");
    // A speed the model cannot reach even without any loss is refused, not fitted.
    let too_fast = ShaftAnchor {
        turbo_speed_rad_s: 4.0 * measured,
        ..anchor
    };
    let err = fit_shaft_torque(&pts, &start, &too_fast, 100_000.0, &opts)
        .expect_err("unreachable speed")
        .to_string();
    assert!(err.contains("shaft loss torque"), "{err}");
}

#[test]
fn compressor_fit_recovers_the_ellipse_and_efficiency_from_a_model_map() {
    // A map generated by the model's compressor at the reference inlet, in corrected units,
    // with 0.5 % noise on the flow and 0.005 on the efficiency.
    let t = truth();
    let o = FitOptions::tsfs09();
    let model = TurboModel::new(t.clone()).expect("valid");
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    let n = Normal::new(0.0, 1.0).expect("normal");
    let (tr, pr) = (
        o.compressor_reference_temperature_k,
        o.compressor_reference_pressure_pa,
    );
    let mut map = Vec::new();
    for rpm in [80_000.0, 110_000.0, 140_000.0, 170_000.0] {
        for pi in [1.05, 1.2, 1.4, 1.6, 1.8, 2.0, 2.2] {
            let omega = rpm * 2.0 * std::f64::consts::PI / 60.0;
            let x = model.state_from_pressures(
                [pr, pr * pi, pr * pi, pr, pr, pr],
                [tr, 350.0, 300.0, 300.0, 900.0, 800.0],
                omega,
            );
            let u = TurboInput {
                throttle_pct: 50.0,
                engine_speed_rad_s: 300.0,
                wastegate_frac: 0.0,
                lambda: 1.0,
                ambient_pressure_pa: pr,
                ambient_temperature_k: tr,
            };
            let s = model.signals(&x, &u);
            if s.psi_c > 0.9 * t.compressor_head_max || s.w_c_kg_s <= 0.0 {
                continue;
            }
            map.push(CompressorMapPoint {
                corrected_flow_kg_s: s.w_c_kg_s * (1.0 + 5e-3 * n.sample(&mut rng)),
                pressure_ratio: pi,
                corrected_speed_rpm: rpm,
                efficiency: s.eta_c + 5e-3 * n.sample(&mut rng),
            });
        }
    }
    assert!(map.len() >= 12, "{} map points", map.len());
    let mut start = t.clone();
    start.compressor_flow_at_efficiency_max = 0.05;
    let f = fit_compressor(&map, &start, &o).expect("compressor");
    close(f.head_max.value, t.compressor_head_max, 0.03, "Psi_max");
    close(f.flow_max.value, t.compressor_flow_max, 0.03, "Phi_max");
    close(
        f.efficiency_max.value,
        t.compressor_efficiency_max,
        0.02,
        "eta_max",
    );
    close(
        f.flow_at_efficiency_max.value,
        t.compressor_flow_at_efficiency_max,
        0.03,
        "Phi_opt",
    );
}

/// A copy of the data directory with `engine_map.csv` edited by `edit`.
fn broken_data(edit: impl Fn(&str) -> String) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    let src = root().join(DATA);
    for f in ["comp_map.csv", "turb_map.csv"] {
        std::fs::copy(src.join(f), dir.path().join(f)).expect("copy");
    }
    let text = std::fs::read_to_string(src.join("engine_map.csv")).expect("read");
    std::fs::write(dir.path().join("engine_map.csv"), edit(&text)).expect("write");
    dir
}

fn fit_error(data: &Path) -> String {
    let out = data.join("out.toml");
    let o = fdd(&[
        "fit",
        "turbo",
        "--data",
        data.to_str().expect("utf-8"),
        "--start",
        "config/turbo.toml",
        "-o",
        out.to_str().expect("utf-8"),
    ]);
    assert!(!o.status.success(), "bad input must fail");
    assert!(!out.exists(), "no output on failure");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn bad_input_errors_name_file_line_and_column() {
    // A missing column: the header is line 1.
    let dir = broken_data(|t| t.replacen("p_em,", "p_em_x,", 1));
    let e = fit_error(dir.path());
    assert!(
        e.contains("engine_map.csv") && e.contains("line 1") && e.contains("`p_em`"),
        "{e}"
    );
    // A non-numeric cell: line 4 (the third data row), column 3 (p_im).
    let dir = broken_data(|t| {
        let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
        let mut cells: Vec<&str> = lines[3].split(',').collect();
        cells[2] = "12x";
        lines[3] = cells.join(",");
        lines.join("\n") + "\n"
    });
    let e = fit_error(dir.path());
    assert!(
        e.contains("engine_map.csv")
            && e.contains("line 4")
            && e.contains("column 3")
            && e.contains("`p_im`")
            && e.contains("12x"),
        "{e}"
    );
    // A row with a field too few.
    let dir = broken_data(|t| {
        let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
        let cut = lines[5].rfind(',').expect("comma");
        lines[5].truncate(cut);
        lines.join("\n") + "\n"
    });
    let e = fit_error(dir.path());
    assert!(e.contains("engine_map.csv") && e.contains("line 6"), "{e}");
}

#[test]
fn a_missing_or_unusable_transient_is_named() {
    // The maps intact but no throttle-step log: the shaft fit's log is named.
    let dir = broken_data(|t| t.to_string());
    let err = fit_error(dir.path());
    assert!(
        err.contains("shaft's loss torque") && err.contains("grupp1_airstep.mcap"),
        "{err}"
    );
    // In its place a log without a stationary start: grupp2's wastegate position moves by more
    // than 2 %-points between two samples 0.31 s after its start.
    std::fs::copy(
        root().join(DATA).join("grupp2_wastegate.mcap"),
        dir.path().join("grupp1_airstep.mcap"),
    )
    .expect("copy");
    let err = fit_error(dir.path());
    assert!(
        err.contains("grupp1_airstep.mcap") && err.contains("stationary start"),
        "{err}"
    );
}
