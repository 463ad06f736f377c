//! The intake model's analytic transition Jacobian (propagated alongside the substeps of the
//! discrete model, estimators/src/models/intake.rs) against central differences of the
//! transition, in both throttle-flow modes, over 800..6000 rpm, throttle 2..80 deg, EGR 0..1,
//! with manifold pressures in the choked region, the subsonic region, just below and just above
//! the steep ratio 0.97.
//!
//! Entries are compared in scaled coordinates (each state divided by its typical size), where
//! the Jacobian is O(1): `|J_ij - N_ij| * d_j / d_i <= 1e-6 * max(|N_ij| d_j / d_i, 1e-3)`,
//! i.e. 1e-6 relative for every entry that matters and 1e-9 absolute (scaled) for the ones that
//! are zero or negligible.

use fdd_estimators::models::intake::{
    IntakeInput, IntakeModel, IntakeParams, IntakeState, ThrottleFlow, X_PM, X_Q1, X_Q2,
};
use fdd_estimators::{numerical_jacobian, TransitionModel};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde::Deserialize;

#[derive(Deserialize)]
struct File {
    model: IntakeParams,
}

fn model(flow: ThrottleFlow) -> IntakeModel {
    let text = include_str!("../../config/intake.toml");
    let params = toml::from_str::<File>(text)
        .expect("config/intake.toml parses")
        .model;
    IntakeModel::new(params, flow).expect("valid parameters")
}

/// Typical size of each state component: Pa, Pa, kg/s, kg/s, Pa, Pa/s.
fn scales(speed: f64) -> [f64; 6] {
    let w = IntakeModel::pump_frequency(speed);
    [1e5, 1e5, 0.05, 0.05, 1e3, 1e3 * w]
}

/// Five-point (fourth-order) central differences with step `STEP * d_j` per component: the
/// reference. (The crate's default three-point differences with `eps^(1/3)` steps carry a
/// truncation error of about 1e-6 near psi = 0.97, where the subsonic flow function curves
/// most; they are compared too, to a looser bound.)
fn five_point(m: &IntakeModel, x: &IntakeState, u: &IntakeInput) -> nalgebra::SMatrix<f64, 6, 6> {
    const STEP: f64 = 1e-4;
    let d = scales(u[0]);
    let mut jac = nalgebra::SMatrix::<f64, 6, 6>::zeros();
    for j in 0..6 {
        let h = STEP * d[j];
        let at = |k: f64| {
            let mut z = *x;
            z[j] += k * h;
            m.transition(&z, u)
        };
        let col = (at(-2.0) - at(2.0) + (at(1.0) - at(-1.0)) * 8.0) / (12.0 * h);
        jac.set_column(j, &col);
    }
    jac
}

/// Worst scaled relative deviation between the analytic Jacobian and `reference` at `(x, u)`.
fn deviation(
    m: &IntakeModel,
    x: &IntakeState,
    u: &IntakeInput,
    reference: &nalgebra::SMatrix<f64, 6, 6>,
) -> f64 {
    let analytic = m.transition_jacobian(x, u);
    let d = scales(u[0]);
    let mut worst = 0.0f64;
    for i in 0..6 {
        for j in 0..6 {
            let s = d[j] / d[i];
            let a = analytic[(i, j)] * s;
            let n = reference[(i, j)] * s;
            assert!(a.is_finite(), "J[{i},{j}] = {a} at x = {x:?}, u = {u:?}");
            worst = worst.max((a - n).abs() / n.abs().max(1e-3));
        }
    }
    worst
}

/// `true` when the whole trajectory of the step with `p_m` perturbed by the numerical step
/// stays clear of the flow-function kinks (where the Jacobian is one-sided).
fn clear_of_kinks(m: &IntakeModel, x: &IntakeState, u: &IntakeInput) -> bool {
    let p = m.params();
    let kinks = [0.528_281_787_717_174_4, p.steep_ratio, 1.0];
    // Check the start and the end of the segment, and that no kink lies between them (p_m
    // moves monotonically within a segment at a fixed input, except through the linear region).
    let end = m.transition(x, u)[X_PM];
    let (lo, hi) = (x[X_PM].min(end) - 50.0, x[X_PM].max(end) + 50.0);
    for (pu, egr) in [
        (p.ambient_pressure_pa, false),
        (p.egr_upstream_pressure_pa, true),
    ] {
        if egr && u[2] == 0.0 {
            continue;
        }
        for k in kinks {
            let pk = k * pu;
            if pk > lo && pk < hi {
                return false;
            }
        }
    }
    true
}

#[test]
fn transition_jacobian_matches_numerical() {
    let mut rng = Pcg64::seed_from_u64(0x1a7a_ce01);
    for flow in [ThrottleFlow::Nozzle, ThrottleFlow::RandomWalk] {
        let m = model(flow);
        let pa = m.params().ambient_pressure_pa;
        let mut worst = 0.0f64;
        let mut worst3 = 0.0f64;
        let mut tested = 0;
        // Ratios p_m / p_a: choked, subsonic, just below and just above the steep ratio 0.97.
        let ratios = [0.30, 0.45, 0.60, 0.80, 0.95, 0.965, 0.975, 0.99];
        for speed in [800.0, 1250.0, 2000.0, 3000.0, 4500.0, 6000.0] {
            for throttle in [2.0, 5.0, 10.0, 25.0, 50.0, 80.0] {
                for egr in [0.0, 0.3, 1.0] {
                    let u = IntakeInput::new(speed, throttle, egr);
                    for &r in &ratios {
                        let mut x = m.equilibrium(&u).expect("equilibrium");
                        x[X_PM] = r * pa;
                        x[1] = x[X_PM] + rng.random_range(-2e3..2e3);
                        x[2] *= rng.random_range(0.8..1.2);
                        x[3] = x[2] * rng.random_range(0.9..1.1);
                        x[X_Q1] = rng.random_range(-1500.0..1500.0);
                        x[X_Q2] = rng.random_range(-1.0..1.0)
                            * 1500.0
                            * IntakeModel::pump_frequency(speed);
                        if !clear_of_kinks(&m, &x, &u) {
                            continue;
                        }
                        let dev = deviation(&m, &x, &u, &five_point(&m, &x, &u));
                        let default = numerical_jacobian(|z| m.transition(z, &u), &x);
                        let dev3 = deviation(&m, &x, &u, &default);
                        assert!(dev3 < 1e-5, "{flow:?}: {dev3:.2e} against the default");
                        worst3 = worst3.max(dev3);
                        assert!(
                            dev < 1e-6,
                            "{flow:?}: deviation {dev:.2e} at {speed} rpm, {throttle} deg, \
                             EGR {egr}, p_m/p_a {r}"
                        );
                        worst = worst.max(dev);
                        tested += 1;
                    }
                }
            }
        }
        println!(
            "{flow:?}: {tested} points, worst scaled relative deviation {worst:.2e} against \
             five-point differences, {worst3:.2e} against the default three-point ones"
        );
        assert!(tested > 300, "only {tested} points clear of the kinks");
    }
}

#[test]
fn jacobian_path_gives_the_same_state() {
    // The state computed alongside the Jacobian is the transition's, bit for bit; the
    // oscillator block is the exact one.
    for flow in [ThrottleFlow::Nozzle, ThrottleFlow::RandomWalk] {
        let m = model(flow);
        for speed in [800.0, 3000.0, 6000.0] {
            let u = IntakeInput::new(speed, 20.0, 0.5);
            let mut x = m.equilibrium(&u).unwrap();
            x[X_Q1] = 700.0;
            let j = m.transition_jacobian(&x, &u);
            let osc = fdd_estimators::models::intake::oscillator_transition(
                IntakeModel::pump_frequency(speed),
                m.params().pump_damping,
                IntakeModel::segment_dt(speed),
            );
            let w = IntakeModel::pump_frequency(speed);
            assert!((j[(X_Q1, X_Q1)] - osc[(0, 0)]).abs() < 1e-9);
            assert!((j[(X_Q2, X_Q1)] - osc[(1, 0)]).abs() < 1e-9 * w * w);
            assert!((j[(X_Q1, X_Q2)] - osc[(0, 1)]).abs() < 1e-9 / w);
        }
    }
    // A refused input: the transition is the identity, so is its Jacobian.
    let m = model(ThrottleFlow::Nozzle);
    let x = m.equilibrium(&IntakeInput::new(2000.0, 10.0, 0.0)).unwrap();
    let j = m.transition_jacobian(&x, &IntakeInput::new(0.0, 10.0, 0.0));
    assert_eq!(j, nalgebra::SMatrix::<f64, 6, 6>::identity());
}
