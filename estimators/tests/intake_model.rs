//! The intake-manifold model (estimators/src/models/intake.rs) with `config/intake.toml`:
//!
//! - the oscillator's closed-form `expm(A dt)` against nalgebra's Padé `exp()` and an
//!   independent Taylor scaling-and-squaring, to 1e-12, over 600..6500 rpm;
//! - the nozzle flow function meets at `psi_crit` and at 0.97, and the steep region ends in the
//!   paper's quasi-steady `W_thr = W_inv - W_egr`;
//! - with the speed changing every segment (dt = 30/N), the discrete model (one step per
//!   segment) stays within the sensor noise of the RK4-integrated continuous model (0.1 ms);
//! - parameter errors name the key; bad inputs and readings are refused, never NaN;
//! - the sensors' analytic Jacobians against numerical ones.

use fdd_estimators::models::intake::{
    critical_ratio, flow_function, oscillator_transition, IntakeInput, IntakeInputError,
    IntakeModel, IntakeParams, IntakeState, MafSensor, MapMafSensors, MapSensor, ThrottleFlow,
    X_PM, X_PMES, X_Q1, X_Q2, X_WMES, X_WTHR,
};
use fdd_estimators::{numerical_jacobian, ObservationModel, TransitionModel};
use nalgebra::Matrix2;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde::Deserialize;

#[derive(Deserialize)]
struct File {
    model: IntakeParams,
}

fn params() -> IntakeParams {
    let text = include_str!("../../config/intake.toml");
    toml::from_str::<File>(text)
        .expect("config/intake.toml parses")
        .model
}

fn model(flow: ThrottleFlow) -> IntakeModel {
    IntakeModel::new(params(), flow).expect("valid parameters")
}

/// `exp(M)` by scaling and squaring a 30-term Taylor series (independent of the closed form).
fn taylor_expm(m: Matrix2<f64>) -> Matrix2<f64> {
    let norm = m.abs().max();
    let s = if norm > 0.5 {
        (norm / 0.5).log2().ceil() as i32
    } else {
        0
    };
    let a = m / 2f64.powi(s);
    let mut term = Matrix2::identity();
    let mut sum = Matrix2::identity();
    for k in 1..30 {
        term = term * a / k as f64;
        sum += term;
    }
    for _ in 0..s {
        sum = sum * sum;
    }
    sum
}

#[test]
fn oscillator_matches_matrix_exponential() {
    let xi = params().pump_damping;
    let mut worst_pade = 0.0f64;
    let mut worst_taylor = 0.0f64;
    let mut n = 600.0;
    while n <= 6500.0 {
        let w = IntakeModel::pump_frequency(n);
        let a = Matrix2::new(0.0, 1.0, -w * w, -2.0 * xi * w);
        for t in [30.0 / n, 30.0 / n / 7.0, 2.5e-3] {
            let closed = oscillator_transition(w, xi, t);
            // Compare in the scaled coordinates [q, q'/w], where all entries are O(1).
            let d = Matrix2::new(1.0, 0.0, 0.0, 1.0 / w);
            let di = Matrix2::new(1.0, 0.0, 0.0, w);
            let scaled = |e: Matrix2<f64>| d * e * di;
            let pade = (a * t).exp();
            let taylor = taylor_expm(a * t);
            worst_pade = worst_pade.max((scaled(closed) - scaled(pade)).abs().max());
            worst_taylor = worst_taylor.max((scaled(closed) - scaled(taylor)).abs().max());
        }
        n += 25.0;
    }
    println!("oscillator: max |closed - pade| = {worst_pade:.2e}, |closed - taylor| = {worst_taylor:.2e}");
    assert!(worst_pade < 1e-12, "{worst_pade}");
    // Repeated squaring of the Taylor reference itself loses a few digits at large w t.
    assert!(worst_taylor < 1e-11, "{worst_taylor}");
}

#[test]
fn nozzle_regimes_meet() {
    let p = params();
    let k = p.heat_capacity_ratio;
    let crit = critical_ratio(k);
    assert!((crit - 0.5283).abs() < 1e-4);
    let below = flow_function(crit - 1e-12, k, p.steep_ratio).0;
    let above = flow_function(crit + 1e-12, k, p.steep_ratio).0;
    assert!((below - above).abs() < 1e-9, "{below} vs {above}");
    let s = p.steep_ratio;
    let below = flow_function(s - 1e-12, k, s).0;
    let above = flow_function(s + 1e-12, k, s).0;
    assert!((below - above).abs() < 1e-9, "{below} vs {above}");
    // Linear to zero at 1, zero beyond, monotone non-increasing overall; NaN and negative
    // ratios count as choked.
    assert_eq!(flow_function(1.0, k, s).0, 0.0);
    assert_eq!(flow_function(1.3, k, s).0, 0.0);
    assert_eq!(flow_function(f64::NAN, k, s).0, below_choked(k, s));
    assert_eq!(flow_function(-0.5, k, s).0, below_choked(k, s));
    let mut last = f64::INFINITY;
    for i in 0..=1000 {
        let v = flow_function(i as f64 / 1000.0, k, s).0;
        assert!(v <= last + 1e-15 && v.is_finite());
        last = v;
    }
}

fn below_choked(k: f64, s: f64) -> f64 {
    flow_function(0.1, k, s).0
}

#[test]
fn steep_region_gives_paper_quasi_steady_flow() {
    let m = model(ThrottleFlow::Nozzle);
    // Wide-open throttle with EGR closed and with a little EGR: the manifold settles above 0.97
    // p_a, where the throttle flow equals intake-valve minus EGR flow.
    for (n, egr) in [(1500.0, 0.0), (3000.0, 0.0), (6000.0, 0.0), (2000.0, 0.1)] {
        let u = IntakeInput::new(n, 83.0, egr);
        let x = m.equilibrium(&u).expect("equilibrium exists");
        let psi = x[X_PM] / m.params().ambient_pressure_pa;
        let w_inv = m.intake_valve_flow(x[X_PM], n);
        let w_egr = m.egr_flow(x[X_PM], egr);
        assert!(psi > 0.97 && psi < 1.0, "psi = {psi} at {n} rpm");
        assert!(
            (x[X_WTHR] - (w_inv - w_egr)).abs() < 1e-9,
            "{} vs {}",
            x[X_WTHR],
            w_inv - w_egr
        );
    }
}

/// Speed random walk 800..6000 rpm changing every segment, throttle and EGR steps; the truth is
/// integrated with RK4 at 0.1 ms substeps (the segment length is not a multiple of 0.1 ms, so the
/// substep count is rounded and the step shortened slightly to land on the segment instant).
#[test]
fn discrete_model_tracks_continuous_with_varying_dt() {
    let m = model(ThrottleFlow::Nozzle);
    let p = m.params().clone();
    let mut rng = Pcg64::seed_from_u64(5);
    let mut speed = 2000.0f64;
    let mut throttle = 10.0f64;
    let mut egr = 0.0f64;
    let mut truth = m
        .equilibrium(&IntakeInput::new(speed, throttle, egr))
        .unwrap();
    truth[X_Q1] = 1500.0; // pulsation at its initial amplitude (decays: the paper's oscillator)
    let mut disc = truth;
    let (mut max_map, mut max_maf_rel, mut max_pm) = (0.0f64, 0.0f64, 0.0f64);
    let mut t = 0.0;
    let mut segments = 0;
    let mut dts = (f64::INFINITY, 0.0f64);
    while t < 20.0 {
        // Inputs for this segment.
        speed = (speed + rng.random_range(-150.0..150.0)).clamp(800.0, 6000.0);
        if rng.random_bool(0.01) {
            throttle = rng.random_range(0.0..83.0);
        }
        if rng.random_bool(0.005) {
            egr = if egr > 0.0 {
                0.0
            } else {
                rng.random_range(0.2..1.0)
            };
        }
        if rng.random_bool(0.01) {
            truth[X_Q1] += rng.random_range(-1500.0..1500.0);
            disc[X_Q1] = truth[X_Q1];
        }
        let u = IntakeInput::new(speed, throttle, egr);
        m.check_input(&u).unwrap();
        let dt = IntakeModel::segment_dt(speed);
        dts = (dts.0.min(dt), dts.1.max(dt));
        let sub = (dt / 1e-4).round().max(1.0) as usize;
        truth = m.integrate_rk4(&truth, &u, dt, sub);
        disc = m.transition(&disc, &u);
        t += dt;
        segments += 1;
        max_map = max_map.max((truth[X_PMES] - disc[X_PMES]).abs());
        max_pm = max_pm.max((truth[X_PM] - disc[X_PM]).abs());
        let maf_scale = truth[X_WMES].abs().max(2e-3);
        max_maf_rel = max_maf_rel.max((truth[X_WMES] - disc[X_WMES]).abs() / maf_scale);
        assert!(disc.iter().all(|v| v.is_finite()));
    }
    println!(
        "{segments} segments, dt {:.2}..{:.2} ms: max |MAP dev| = {max_map:.1} Pa (noise std {}), \
         max |p_m dev| = {max_pm:.1} Pa, max MAF dev = {:.3} % (noise {} %)",
        dts.0 * 1e3,
        dts.1 * 1e3,
        p.map_noise_std_pa,
        max_maf_rel * 100.0,
        p.maf_noise_rel * 100.0
    );
    assert!(max_map < p.map_noise_std_pa, "MAP deviation {max_map}");
    assert!(max_maf_rel < p.maf_noise_rel, "MAF deviation {max_maf_rel}");
}

#[test]
fn random_walk_mode_holds_throttle_flow() {
    let m = model(ThrottleFlow::RandomWalk);
    let u = IntakeInput::new(2000.0, 10.0, 0.0);
    let x = m.equilibrium(&u).unwrap();
    let mut y = x;
    y[X_WTHR] *= 1.1;
    let next = m.transition(&y, &u);
    assert_eq!(next[X_WTHR], y[X_WTHR]);
    assert!(next[X_PM] > x[X_PM]);
    // At equilibrium, the random-walk model stays there.
    let same = m.transition(&x, &u);
    assert!((same[X_PM] - x[X_PM]).abs() < 1e-6 * x[X_PM]);
}

#[test]
fn validation_names_the_key() {
    type Edit = Box<dyn Fn(&mut IntakeParams)>;
    let cases: Vec<(&str, Edit)> = vec![
        (
            "manifold_volume_m3",
            Box::new(|p| p.manifold_volume_m3 = 0.0),
        ),
        (
            "map_time_constant_s",
            Box::new(|p| p.map_time_constant_s = f64::NAN),
        ),
        ("pump_damping", Box::new(|p| p.pump_damping = 1.0)),
        (
            "heat_capacity_ratio",
            Box::new(|p| p.heat_capacity_ratio = 1.0),
        ),
        ("steep_ratio", Box::new(|p| p.steep_ratio = 0.4)),
        (
            "vol_eff_speeds_rpm[2]",
            Box::new(|p| p.vol_eff_speeds_rpm[2] = 900.0),
        ),
        (
            "vol_eff_offset_kg_per_s",
            Box::new(|p| {
                p.vol_eff_offset_kg_per_s.pop();
            }),
        ),
        (
            "vol_eff_slope_kg_per_s_pa[0]",
            Box::new(|p| p.vol_eff_slope_kg_per_s_pa[0] = -1.0),
        ),
        ("min_speed_rpm", Box::new(|p| p.min_speed_rpm = 9000.0)),
        ("egr_max_area_m2", Box::new(|p| p.egr_max_area_m2 = -1e-5)),
    ];
    for (key, edit) in cases {
        let mut p = params();
        edit(&mut p);
        let err = IntakeModel::new(p, ThrottleFlow::Nozzle).unwrap_err();
        assert!(err.contains(key), "`{key}` not named in: {err}");
    }
    // Unknown keys are refused by the parser.
    let bad = "[model]\nbogus = 1.0\n";
    assert!(toml::from_str::<File>(bad).is_err());
}

#[test]
fn bad_inputs_are_refused_without_nan() {
    let m = model(ThrottleFlow::Nozzle);
    let x = m.equilibrium(&IntakeInput::new(2000.0, 10.0, 0.0)).unwrap();
    for (u, name) in [
        (IntakeInput::new(0.0, 10.0, 0.0), "engine speed"),
        (IntakeInput::new(-800.0, 10.0, 0.0), "engine speed"),
        (IntakeInput::new(f64::NAN, 10.0, 0.0), "engine speed"),
        (IntakeInput::new(f64::INFINITY, 10.0, 0.0), "engine speed"),
        (IntakeInput::new(2000.0, f64::NAN, 0.0), "throttle"),
        (IntakeInput::new(2000.0, 95.0, 0.0), "throttle"),
        (IntakeInput::new(2000.0, 10.0, f64::NAN), "EGR"),
        (IntakeInput::new(2000.0, 10.0, 1.5), "EGR"),
    ] {
        let err = m.check_input(&u).unwrap_err();
        let text = err.to_string();
        assert!(text.contains(name), "{text}");
        let next = m.transition(&x, &u);
        assert!(next.iter().all(|v| v.is_finite()), "{u:?} gave {next:?}");
    }
    // Speed refusals leave the state as it was.
    assert_eq!(m.transition(&x, &IntakeInput::new(0.0, 10.0, 0.0)), x);
    assert_eq!(m.transition(&x, &IntakeInput::new(-1.0, 10.0, 0.0)), x);
    // A NaN state is not propagated into a step.
    let mut nan = x;
    nan[X_PM] = f64::NAN;
    assert!(m
        .transition(&nan, &IntakeInput::new(2000.0, 10.0, 0.0))
        .iter()
        .skip(1)
        .all(|v| v.is_finite()));
    // Extreme but valid states (sigma points far out) stay finite.
    for pm in [-5e4, 0.0, 2e5, 1e7] {
        let mut y = x;
        y[X_PM] = pm;
        let next = m.transition(&y, &IntakeInput::new(800.0, 83.0, 1.0));
        assert!(next.iter().all(|v| v.is_finite()), "p_m {pm}: {next:?}");
    }
    // Measurements.
    let pa = m.params().ambient_pressure_pa;
    assert!(m.check_measurement(0.5 * pa, 0.01).is_ok());
    assert!(m.check_measurement(1.05 * pa, 0.01).is_ok());
    match m.check_measurement(1.3 * pa, 0.01) {
        Err(IntakeInputError::OutOfRange { name, value, .. }) => {
            assert!(name.contains("MAP") && value == 1.3 * pa)
        }
        other => panic!("{other:?}"),
    }
    assert!(m.check_measurement(-10.0, 0.01).is_err());
    assert!(m.check_measurement(f64::NAN, 0.01).is_err());
    assert!(m.check_measurement(5e4, f64::NAN).is_err());
    assert!(m.check_measurement(5e4, -1.0).is_err());
}

#[test]
fn sensor_jacobians_match_numerical() {
    let m = model(ThrottleFlow::Nozzle);
    let u = IntakeInput::new(2500.0, 20.0, 0.3);
    let x = m.equilibrium(&u).unwrap() + IntakeState::from([100.0, -50.0, 1e-3, 2e-3, 300.0, 5.0]);
    let num2 = numerical_jacobian(|z| MapMafSensors.observe(z, &u), &x);
    assert!(
        (MapMafSensors.observation_jacobian(&x, &u) - num2)
            .abs()
            .max()
            < 1e-6
    );
    let num_map = numerical_jacobian(|z| MapSensor.observe(z, &u), &x);
    assert!(
        (MapSensor.observation_jacobian(&x, &u) - num_map)
            .abs()
            .max()
            < 1e-6
    );
    let num_maf = numerical_jacobian(|z| MafSensor.observe(z, &u), &x);
    assert!(
        (MafSensor.observation_jacobian(&x, &u) - num_maf)
            .abs()
            .max()
            < 1e-6
    );
    assert_eq!(MapMafSensors.observe(&x, &u)[0], x[X_PMES]);
    assert_eq!(MapMafSensors.observe(&x, &u)[1], x[X_WMES]);
    // The transition Jacobian (numerical default) is finite and has the oscillator block.
    let j = m.transition_jacobian(&x, &u);
    assert!(j.iter().all(|v| v.is_finite()));
    let osc = oscillator_transition(
        IntakeModel::pump_frequency(2500.0),
        m.params().pump_damping,
        30.0 / 2500.0,
    );
    assert!((j[(X_Q1, X_Q1)] - osc[(0, 0)]).abs() < 1e-6);
    assert!((j[(X_Q2, X_Q1)] - osc[(1, 0)]).abs() < 1e-6 * osc[(1, 0)].abs().max(1.0));
}

#[test]
fn idle_operating_point_is_plausible() {
    let m = model(ThrottleFlow::Nozzle);
    let x = m.equilibrium(&IntakeInput::new(800.0, 2.0, 0.0)).unwrap();
    println!(
        "idle 800 rpm, 2 deg: p_m = {:.0} Pa, W = {:.2e} kg/s",
        x[X_PM], x[X_WTHR]
    );
    assert!(x[X_PM] > 25e3 && x[X_PM] < 45e3, "{}", x[X_PM]);
    let wot = m.equilibrium(&IntakeInput::new(6000.0, 83.0, 0.0)).unwrap();
    println!(
        "WOT 6000 rpm: p_m = {:.0} Pa, W = {:.3} kg/s",
        wot[X_PM], wot[X_WTHR]
    );
    assert!(wot[X_WTHR] > 0.07 && wot[X_WTHR] < 0.12);
}
