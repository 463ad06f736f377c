//! The UKF's closed-form update for a linear sensor (`ObservationModel::affine_observation`)
//! gives what its sigma points give.
//!
//! For `h(x) = H x + d` the unscented transform is exact: the points reproduce `x` and `P`, so
//! `y_pred = H x + d`, `Pyy = H P H' + R` and `Pxy = P H'`. The UKF uses these directly when the
//! sensor declares itself linear (the throttle position sensor does). This runs the throttle
//! UKF with the position sensor twice over 3000 steps of a random voltage and a noisy
//! measurement, once with the sensor as it is and once wrapped so that it hides its linearity
//! (the full transform), for each sigma-point set, and requires the same states, covariances and
//! innovation statistics to 1e-9 relative after every update (both filters start each step from
//! the same estimate). A wrong `H`, a missing `R`, a transposed `Pxy` or a
//! gain built from the wrong covariance moves them by far more.

use fdd_estimators::models::throttle::{PositionSensor, ThrottleModel, ThrottleParams};
use fdd_estimators::{ObservationModel, SigmaPoints, Ukf};
use nalgebra::{Matrix1, Matrix3, SMatrix, Vector1, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// The position sensor without its `affine_observation`: the UKF must draw sigma points.
struct Opaque(PositionSensor);

impl ObservationModel<3, 1, 1> for Opaque {
    fn observe(&self, x: &Vector3<f64>, u: &Vector1<f64>) -> Vector1<f64> {
        self.0.observe(x, u)
    }
}

fn throttle() -> ThrottleModel {
    let table: toml::Table =
        toml::from_str(include_str!("../../config/throttle.toml")).expect("throttle.toml parses");
    let params: ThrottleParams = table["model"].clone().try_into().expect("[model]");
    ThrottleModel::new(params).expect("valid model")
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-6)
}

fn run<const L: usize>(label: &str, points: SigmaPoints<3, L>) {
    let model = throttle();
    let sensor = PositionSensor::new(5.0, 90.0, model.params().angle_scale);
    assert!(
        sensor.affine_observation(&Vector1::zeros()).is_some(),
        "the position sensor declares itself linear"
    );
    let x0 = Vector3::new(model.scaled_angle(20.0), 0.0, 0.5);
    let p0 = Matrix3::from_diagonal(&Vector3::new(0.5, 1.0, 0.2));
    let q = Matrix3::from_diagonal(&Vector3::new(3.15e-4, 1e-2, 1.62e-4));
    let r = Matrix1::new(1e-4);
    let mut fast = Ukf::new(model, sensor, points, x0, p0, q, r).expect("valid filter");
    let mut full = Ukf::new(model, Opaque(sensor), points, x0, p0, q, r).expect("valid filter");
    let mut rng = Pcg64::seed_from_u64(7);
    let mut truth = x0;
    for k in 0..3000 {
        let u = Vector1::new(rng.random_range(0.0..4.0));
        truth = fdd_estimators::TransitionModel::transition(&model, &truth, &u);
        fdd_estimators::TransitionModel::constrain(&model, &mut truth);
        let y = Vector1::new(sensor.volts(&truth) + rng.random_range(-0.02..0.02));
        // Each step starts both from the same estimate, so that round-off (large for the scaled
        // set's negative centre weight) does not accumulate through the piecewise dynamics.
        full.reset(*fast.state(), *fast.covariance())
            .expect("a valid estimate");
        let a = fast.update(&y, &u).expect("update");
        let b = full.update(&y, &u).expect("update");
        assert!(
            close(a.nis, b.nis) && close(a.residual[0], b.residual[0]),
            "{label} step {k}: innovation {a:?} vs {b:?}"
        );
        assert!(close(a.covariance[(0, 0)], b.covariance[(0, 0)]));
        let (xa, xb) = (fast.state(), full.state());
        let (pa, pb): (&SMatrix<f64, 3, 3>, &SMatrix<f64, 3, 3>) =
            (fast.covariance(), full.covariance());
        for i in 0..3 {
            assert!(close(xa[i], xb[i]), "{label} step {k}: x {xa} vs {xb}");
            for j in 0..3 {
                assert!(
                    close(pa[(i, j)], pb[(i, j)]),
                    "{label} step {k}: P {pa} vs {pb}"
                );
            }
        }
        fast.predict(&u).expect("predict");
        full.predict(&u).expect("predict");
    }
}

#[test]
fn closed_form_update_equals_the_sigma_points() {
    run("AHSM", SigmaPoints::<3, 7>::ahsm(12.0).expect("valid"));
    run(
        "scaled",
        SigmaPoints::<3, 7>::scaled(0.5, 2.0, 0.0).expect("valid"),
    );
    run("ARM", SigmaPoints::<3, 4>::arm(0.25).expect("valid"));
    run(
        "AGM",
        SigmaPoints::<3, 4>::agm(&Vector3::new(1.0, -1.0, 0.5)).expect("valid"),
    );
}
