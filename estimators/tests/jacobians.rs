//! Jacobians the EKF linearizes with must be right: numerical ones must match analytic
//! derivatives, and analytic overrides must match the function they claim to differentiate.
//!
//! - `numerical_jacobian` and the default trait methods (`transition_jacobian`,
//!   `observation_jacobian`), on a damped pendulum defined here whose derivatives are known in
//!   closed form, at random states including large ones (the step scales with `|x_j|`).
//! - The throttle sensors' analytic overrides (wattmeter `h = i^2`, position sensor, both
//!   together) against `numerical_jacobian` of their `observe`.
//! - The throttle's analytic `A_s` (its `transition_jacobian`) against `numerical_jacobian` of
//!   `transition`, in each of the three modes at states away from the switching surfaces (mode
//!   bounds, the 1 deg friction switch, `rho = 0`), with the parameters of
//!   `config/throttle.toml`. This also checks that the analytic Jacobian picks the mode the
//!   transition actually uses.
//!
//! Tolerance: `|J - J_ref| <= 1e-6 max(1, |J_ref|)` entrywise.

use fdd_estimators::models::throttle::{
    PositionAndWattmeter, PositionSensor, ThrottleModel, ThrottleParams, Wattmeter,
};
use fdd_estimators::{numerical_jacobian, ObservationModel, TransitionModel};
use nalgebra::{Matrix2, SMatrix, SVector, Vector1, Vector2, Vector3};
use proptest::prelude::*;

const TOL: f64 = 1e-6;

fn assert_jac_close<const R: usize, const C: usize>(
    what: &str,
    got: &SMatrix<f64, R, C>,
    want: &SMatrix<f64, R, C>,
) {
    for i in 0..R {
        for j in 0..C {
            let (g, w) = (got[(i, j)], want[(i, j)]);
            assert!(
                (g - w).abs() <= TOL * w.abs().max(1.0),
                "{what}: entry ({i},{j}) = {g} but expected {w}\ngot {got}\nwant {want}"
            );
        }
    }
}

/// Damped pendulum, explicit Euler: `x+ = [x0 + dt x1, x1 - dt (g sin x0 + c x1) + dt u]`,
/// observed as `y = [sin x0, x0 x1 + u]`. Uses the default (numerical) Jacobian methods.
struct Pendulum {
    dt: f64,
    g: f64,
    c: f64,
}

impl TransitionModel<2, 1> for Pendulum {
    fn transition(&self, x: &Vector2<f64>, u: &Vector1<f64>) -> Vector2<f64> {
        Vector2::new(
            x[0] + self.dt * x[1],
            x[1] - self.dt * (self.g * x[0].sin() + self.c * x[1]) + self.dt * u[0],
        )
    }
}

impl ObservationModel<2, 2, 1> for Pendulum {
    fn observe(&self, x: &Vector2<f64>, u: &Vector1<f64>) -> Vector2<f64> {
        Vector2::new(x[0].sin(), x[0] * x[1] + u[0])
    }
}

impl Pendulum {
    fn analytic_f(&self, x: &Vector2<f64>) -> Matrix2<f64> {
        Matrix2::new(
            1.0,
            self.dt,
            -self.dt * self.g * x[0].cos(),
            1.0 - self.dt * self.c,
        )
    }

    fn analytic_h(&self, x: &Vector2<f64>) -> Matrix2<f64> {
        Matrix2::new(x[0].cos(), 0.0, x[1], x[0])
    }
}

/// A pendulum with a coarse step, so that the off-identity part of `F` is not negligible.
const PENDULUM: Pendulum = Pendulum {
    dt: 0.1,
    g: 9.81,
    c: 0.7,
};

proptest! {
    #[test]
    fn pendulum_default_transition_jacobian_is_analytic(
        x0 in -10.0..=10.0f64,
        x1 in -50.0..=50.0f64,
        u in -5.0..=5.0f64,
    ) {
        let x = Vector2::new(x0, x1);
        let u = Vector1::new(u);
        let want = PENDULUM.analytic_f(&x);
        assert_jac_close("default transition_jacobian", &PENDULUM.transition_jacobian(&x, &u), &want);
        let direct = numerical_jacobian(|z| PENDULUM.transition(z, &u), &x);
        assert_jac_close("numerical_jacobian of transition", &direct, &want);
    }

    #[test]
    fn pendulum_default_observation_jacobian_is_analytic(
        x0 in -10.0..=10.0f64,
        x1 in -50.0..=50.0f64,
        u in -5.0..=5.0f64,
    ) {
        let x = Vector2::new(x0, x1);
        let u = Vector1::new(u);
        let want = PENDULUM.analytic_h(&x);
        assert_jac_close("default observation_jacobian", &PENDULUM.observation_jacobian(&x, &u), &want);
    }

    /// Large and small magnitudes: `g(x) = [x0^2 x1, exp(x1 / 100), x0 / x2]`.
    #[test]
    fn numerical_jacobian_scales_its_step(
        x0 in prop_oneof![-1e4..=-1e-3f64, 1e-3..=1e4f64],
        x1 in -300.0..=300.0f64,
        x2 in prop_oneof![-1e3..=-1.0f64, 1.0..=1e3f64],
    ) {
        let g = |z: &Vector3<f64>| Vector3::new(z[0] * z[0] * z[1], (z[1] / 100.0).exp(), z[0] / z[2]);
        let x = Vector3::new(x0, x1, x2);
        let want = SMatrix::<f64, 3, 3>::new(
            2.0 * x0 * x1, x0 * x0, 0.0,
            0.0, (x1 / 100.0).exp() / 100.0, 0.0,
            1.0 / x2, 0.0, -x0 / (x2 * x2),
        );
        assert_jac_close("numerical_jacobian", &numerical_jacobian(g, &x), &want);
    }

    #[test]
    fn sensor_jacobians_match_numerical(
        x0 in -1.0..=10.0f64,
        x1 in -20.0..=20.0f64,
        i in -5.0..=5.0f64,
        u in -12.0..=12.0f64,
    ) {
        let x = Vector3::new(x0, x1, i);
        let u = Vector1::new(u);
        let w = Wattmeter;
        let num = numerical_jacobian(|z| w.observe(z, &u), &x);
        let analytic = w.observation_jacobian(&x, &u);
        assert_jac_close("wattmeter", &analytic, &num);
        assert_jac_close("wattmeter closed form", &analytic, &SMatrix::<f64, 1, 3>::new(0.0, 0.0, 2.0 * i));

        let pos = PositionSensor::new(5.0, 90.0, 0.1);
        let num = numerical_jacobian(|z| pos.observe(z, &u), &x);
        assert_jac_close("position sensor", &pos.observation_jacobian(&x, &u), &num);

        let both = PositionAndWattmeter { position: pos };
        let num = numerical_jacobian(|z| both.observe(z, &u), &x);
        assert_jac_close("position and wattmeter", &both.observation_jacobian(&x, &u), &num);
    }
}

fn throttle() -> ThrottleModel {
    let table: toml::Table =
        toml::from_str(include_str!("../../config/throttle.toml")).expect("throttle.toml parses");
    let params: ThrottleParams = table
        .get("model")
        .expect("[model] table")
        .clone()
        .try_into()
        .expect("[model] is ThrottleParams");
    ThrottleModel::new(params).expect("valid parameters")
}

#[test]
fn throttle_analytic_jacobian_matches_numerical_in_each_mode() {
    let model = throttle();
    // (angle in deg, mode it lies in). All at least 0.5 deg from the mode bounds (8, 16) and
    // the friction switch (1 deg); the numerical step moves the angle by ~6e-5 deg.
    let angles = [
        (0.5, 0),
        (4.0, 0),
        (7.5, 0),
        (8.5, 1),
        (12.0, 1),
        (15.5, 1),
        (16.5, 2),
        (50.0, 2),
        (85.0, 2),
    ];
    let mut modes_seen = [0usize; 3];
    for &(theta, mode) in &angles {
        for rho in [-40.0, -2.0, -0.3, 0.3, 2.0, 40.0] {
            for i in [-2.0, 0.0, 0.5, 3.0] {
                let x = Vector3::new(model.scaled_angle(theta), rho, i);
                assert_eq!(model.mode(&x), mode, "theta = {theta}");
                for u in [-6.0, 0.0, 0.3, 12.0] {
                    let u = Vector1::new(u);
                    let analytic = model.transition_jacobian(&x, &u);
                    assert_eq!(analytic, model.params().modes[mode].a());
                    let num = numerical_jacobian(|z| model.transition(z, &u), &x);
                    assert_jac_close(
                        &format!("throttle A_s at theta={theta} rho={rho} i={i} u={}", u[0]),
                        &analytic,
                        &num,
                    );
                }
                modes_seen[mode] += 1;
            }
        }
    }
    assert!(modes_seen.iter().all(|&c| c > 0));
    // The modes are really different, so a Jacobian from the wrong mode would be caught.
    let a: Vec<_> = model.params().modes.iter().map(|m| m.a()).collect();
    for s in 0..3 {
        for t in (s + 1)..3 {
            assert!((a[s] - a[t]).amax() > 1e-2, "modes {s} and {t} share A");
        }
    }
}

/// The parameters really come from the file (spot checks against `config/throttle.toml`).
#[test]
fn throttle_parameters_loaded_from_config() {
    let model = throttle();
    let p = model.params();
    assert_eq!(p.angle_scale, 0.1);
    assert_eq!(p.mode_upper_deg, [8.0, 16.0]);
    assert_eq!(p.modes[0].a21, 0.148);
    assert_eq!(p.modes[1].a23, 1.8944);
    assert_eq!(p.modes[2].a12, 0.0442);
    let a3 = p.modes[2].a();
    assert_eq!(a3[(0, 0)], 1.0);
    assert_eq!(a3[(0, 1)], 0.0442);
    assert_eq!(a3[(2, 1)], 0.0349);
    assert_eq!(a3[(2, 2)], 0.9043);
    assert_eq!(a3[(0, 2)], 0.0);
    assert_eq!(a3[(2, 0)], 0.0);
}

/// The EKF relies on `transition_jacobian` being the derivative of the same mean map: away from
/// the switching surfaces a small perturbation of the state must propagate through `A_s`.
#[test]
fn throttle_transition_is_affine_within_a_mode() {
    let model = throttle();
    let u = Vector1::new(0.8);
    for theta in [4.0, 12.0, 50.0] {
        let x = Vector3::new(model.scaled_angle(theta), 1.5, 0.7);
        let a = model.transition_jacobian(&x, &u);
        let dx = SVector::<f64, 3>::new(0.01, 0.2, -0.3);
        let lhs = model.transition(&(x + dx), &u) - model.transition(&x, &u);
        assert!(
            (lhs - a * dx).amax() < 1e-12,
            "theta = {theta}: {lhs} vs {}",
            a * dx
        );
    }
}
