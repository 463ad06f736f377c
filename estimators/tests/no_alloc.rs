//! Kalman-type filter steps allocate nothing on the heap.
//!
//! The crate promises (lib.rs) that no Kalman-type predict or update allocates: onboard, a
//! filter step runs in a fixed time budget where a call into the allocator is not acceptable.
//! This binary installs a counting global allocator and runs 1000 predict + update steps of
//!
//! - the UKF with each sigma-point set (AHSM, scaled, ARM, AGM) on the throttle model, observed
//!   by the wattmeter alone and by position sensor + wattmeter (full and partial updates);
//! - the EKF on a 6-state, 2-measurement linear model, with analytic Jacobians and with the
//!   default numerical ones, and on the throttle;
//!
//! asserting that the number of allocations in the measured section is exactly 0. Only
//! allocations made by the measuring thread while a section is open are counted (thread-local
//! flag and counter), so tests running in parallel threads cannot disturb each other. A sanity
//! test checks that the counter does see an allocation made inside a section.

use std::hint::black_box;

use fdd_estimators::models::linear::LinearModel;
use fdd_estimators::models::throttle::{
    PositionAndWattmeter, PositionSensor, ThrottleModel, ThrottleParams, Wattmeter,
};
use fdd_estimators::{
    Ekf, FilterError, Innovation, ObservationModel, SigmaPoints, TransitionModel, Ukf,
};
use nalgebra::{Matrix3, SMatrix, SVector, Vector1, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;

const STEPS: usize = 1000;

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

use fdd_testkit::allocations_in;

#[test]
fn counter_sees_allocations() {
    assert_eq!(allocations_in(|| {}), 0);
    assert_eq!(
        allocations_in(|| {
            black_box(black_box(2.0_f64).sqrt());
        }),
        0
    );
    let n = allocations_in(|| {
        black_box(Vec::<u64>::with_capacity(black_box(64)));
    });
    assert!(n >= 1, "a Vec allocation was not counted");
    let n = allocations_in(|| {
        let mut v = black_box(Vec::<u64>::with_capacity(1));
        v.extend(0..black_box(1000u64));
        black_box(v);
    });
    assert!(n >= 2, "alloc + realloc counted {n} times");
    // Only the measured section counts.
    let outside = Vec::<u8>::with_capacity(16);
    assert_eq!(allocations_in(|| drop(black_box(outside))), 0);
}

/// The filter API exercised here.
trait Step<const M: usize, const U: usize> {
    fn predict(&mut self, u: &SVector<f64, U>) -> Result<(), FilterError>;
    fn update_subset(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
        used: &[bool; M],
    ) -> Result<Innovation<M>, FilterError>;
    fn update(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
    ) -> Result<Innovation<M>, FilterError>;
}

impl<T, O, const N: usize, const M: usize, const U: usize, const L: usize> Step<M, U>
    for Ukf<T, O, N, M, U, L>
where
    T: TransitionModel<N, U>,
    O: ObservationModel<N, M, U>,
{
    fn predict(&mut self, u: &SVector<f64, U>) -> Result<(), FilterError> {
        Ukf::predict(self, u)
    }
    fn update_subset(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
        used: &[bool; M],
    ) -> Result<Innovation<M>, FilterError> {
        Ukf::update_subset(self, y, u, used)
    }
    fn update(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
    ) -> Result<Innovation<M>, FilterError> {
        Ukf::update(self, y, u)
    }
}

impl<T, O, const N: usize, const M: usize, const U: usize> Step<M, U> for Ekf<T, O, N, M, U>
where
    T: TransitionModel<N, U>,
    O: ObservationModel<N, M, U>,
{
    fn predict(&mut self, u: &SVector<f64, U>) -> Result<(), FilterError> {
        Ekf::predict(self, u)
    }
    fn update_subset(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
        used: &[bool; M],
    ) -> Result<Innovation<M>, FilterError> {
        Ekf::update_subset(self, y, u, used)
    }
    fn update(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
    ) -> Result<Innovation<M>, FilterError> {
        Ekf::update(self, y, u)
    }
}

/// Runs the steps inside a measured section and asserts zero allocations. Every fifth update
/// is partial (the first component only) when there is more than one measurement. Also asserts
/// that no call was refused, so the run measured real filter steps and not early error returns.
fn assert_steps_allocate_nothing<const M: usize, const U: usize>(
    name: &str,
    filter: &mut impl Step<M, U>,
    data: &[(SVector<f64, U>, SVector<f64, M>)],
) {
    let mut partial = [false; M];
    partial[0] = true;
    let mut refused = 0usize;
    let mut nis_sum = 0.0;
    let count = allocations_in(|| {
        for (k, (u, y)) in data.iter().enumerate() {
            if filter.predict(u).is_err() {
                refused += 1;
            }
            let r = if M > 1 && k % 5 == 4 {
                filter.update_subset(y, u, &partial)
            } else {
                filter.update(y, u)
            };
            match r {
                Ok(inn) => nis_sum += black_box(inn).nis,
                Err(_) => refused += 1,
            }
        }
    });
    assert_eq!(
        count, 0,
        "{name}: {count} heap allocations in {STEPS} steps"
    );
    assert_eq!(refused, 0, "{name}: {refused} steps refused");
    assert!(
        nis_sum.is_finite() && nis_sum > 0.0,
        "{name}: NIS sum {nis_sum}"
    );
}

fn throttle() -> ThrottleModel {
    let table: toml::Table =
        toml::from_str(include_str!("../../config/throttle.toml")).expect("throttle.toml parses");
    let params: ThrottleParams = table["model"].clone().try_into().expect("[model]");
    ThrottleModel::new(params).unwrap()
}

/// Simulated throttle run: `(u, [position volts, wattmeter])` per step, through all three modes.
fn throttle_data(
    model: &ThrottleModel,
    sensor: &PositionAndWattmeter,
) -> Vec<(Vector1<f64>, Vector2<f64>)> {
    let mut rng = Pcg64Mcg::seed_from_u64(7);
    let mut x = Vector3::zeros();
    let mut out = Vec::with_capacity(STEPS);
    for k in 0..STEPS {
        let u = Vector1::new(0.6 + 0.5 * (k as f64 / 60.0).sin());
        let y = sensor.observe(&x, &u)
            + Vector2::new(
                0.01 * rng.sample::<f64, _>(StandardNormal),
                0.01 * rng.sample::<f64, _>(StandardNormal),
            );
        out.push((u, y));
        let w = Vector3::new(0.005, 0.0, 0.005).component_mul(&Vector3::from_fn(|_, _| {
            rng.sample::<f64, _>(StandardNormal)
        }));
        x = model.transition(&x, &u) + w;
        model.constrain(&mut x);
    }
    out
}

fn throttle_ukf_case<O, const M: usize, const L: usize>(
    name: &str,
    model: ThrottleModel,
    sensor: O,
    points: SigmaPoints<3, L>,
    r: SMatrix<f64, M, M>,
    data: &[(Vector1<f64>, SVector<f64, M>)],
) where
    O: ObservationModel<3, M, 1>,
{
    let q = Matrix3::from_diagonal(&Vector3::new(3.15e-4, 1e-4, 1.62e-4));
    let mut ukf = Ukf::new(
        model,
        sensor,
        points,
        Vector3::zeros(),
        Matrix3::identity(),
        q,
        r,
    )
    .expect("valid filter");
    assert_steps_allocate_nothing(name, &mut ukf, data);
}

#[test]
fn throttle_ukf_steps_allocate_nothing() {
    let model = throttle();
    let both = PositionAndWattmeter {
        position: PositionSensor::new(5.0, 90.0, model.params().angle_scale),
    };
    let data2 = throttle_data(&model, &both);
    let data1: Vec<(Vector1<f64>, Vector1<f64>)> = data2
        .iter()
        .map(|(u, y)| (*u, Vector1::new(y[1])))
        .collect();
    let r1 = SMatrix::<f64, 1, 1>::new(1e-2);
    let r2 = SMatrix::<f64, 2, 2>::from_diagonal(&Vector2::new(1e-4, 1e-2));

    let ahsm = SigmaPoints::<3, 7>::ahsm(12.0).unwrap();
    let scaled = SigmaPoints::<3, 7>::scaled(0.5, 2.0, 0.0).unwrap();
    let arm = SigmaPoints::<3, 4>::arm(0.25).unwrap();
    let agm = SigmaPoints::<3, 4>::agm(&Vector3::new(1.0, 1.0, 1.0)).unwrap();

    throttle_ukf_case("wattmeter UKF-AHSM", model, Wattmeter, ahsm, r1, &data1);
    throttle_ukf_case("wattmeter UKF-scaled", model, Wattmeter, scaled, r1, &data1);
    throttle_ukf_case("wattmeter UKF-ARM", model, Wattmeter, arm, r1, &data1);
    throttle_ukf_case("wattmeter UKF-AGM", model, Wattmeter, agm, r1, &data1);

    throttle_ukf_case("pos+watt UKF-AHSM", model, both, ahsm, r2, &data2);
    throttle_ukf_case("pos+watt UKF-scaled", model, both, scaled, r2, &data2);
    throttle_ukf_case("pos+watt UKF-ARM", model, both, arm, r2, &data2);
    throttle_ukf_case("pos+watt UKF-AGM", model, both, agm, r2, &data2);

    let q = Matrix3::from_diagonal(&Vector3::new(3.15e-4, 1e-4, 1.62e-4));
    let mut ekf = Ekf::new(model, both, Vector3::zeros(), Matrix3::identity(), q, r2).unwrap();
    assert_steps_allocate_nothing("pos+watt EKF", &mut ekf, &data2);
}

type Lin6 = LinearModel<6, 2, 1>;

/// The linear model without its Jacobian overrides, so the EKF uses `numerical_jacobian`.
struct NumericalJacobians(Lin6);

impl TransitionModel<6, 1> for NumericalJacobians {
    fn transition(&self, x: &SVector<f64, 6>, u: &Vector1<f64>) -> SVector<f64, 6> {
        self.0.transition(x, u)
    }
}

impl ObservationModel<6, 2, 1> for NumericalJacobians {
    fn observe(&self, x: &SVector<f64, 6>, u: &Vector1<f64>) -> Vector2<f64> {
        self.0.observe(x, u)
    }
}

fn lin6() -> Lin6 {
    // Two lightly damped oscillators and two integrators with leakage, weakly coupled.
    let mut a = SMatrix::<f64, 6, 6>::identity() * 0.9;
    a[(0, 1)] = 0.1;
    a[(1, 0)] = -0.1;
    a[(2, 3)] = 0.2;
    a[(3, 2)] = -0.2;
    a[(4, 0)] = 0.05;
    a[(5, 2)] = 0.05;
    a[(5, 5)] = 0.98;
    LinearModel {
        a,
        b: SMatrix::<f64, 6, 1>::new(1.0, 0.0, 0.5, 0.0, 0.0, 0.2),
        c: SMatrix::<f64, 2, 6>::new(
            1.0, 0.0, 0.0, 0.0, 1.0, 0.0, //
            0.0, 0.0, 1.0, 0.0, 0.0, 1.0,
        ),
        d: SMatrix::<f64, 2, 1>::new(0.0, 0.1),
    }
}

fn lin6_data() -> Vec<(Vector1<f64>, Vector2<f64>)> {
    let m = lin6();
    let mut rng = Pcg64Mcg::seed_from_u64(11);
    let mut x = SVector::<f64, 6>::zeros();
    (0..STEPS)
        .map(|_| {
            let u = Vector1::new(rng.sample::<f64, _>(StandardNormal));
            x = m.a * x
                + m.b * u
                + SVector::<f64, 6>::from_fn(|_, _| 0.1 * rng.sample::<f64, _>(StandardNormal));
            let y = m.c * x
                + m.d * u
                + Vector2::from_fn(|_, _| 0.2 * rng.sample::<f64, _>(StandardNormal));
            (u, y)
        })
        .collect()
}

#[test]
fn linear_ekf_steps_allocate_nothing() {
    let data = lin6_data();
    let q = SMatrix::<f64, 6, 6>::identity() * 0.01;
    let r = SMatrix::<f64, 2, 2>::new(0.04, 0.01, 0.01, 0.04);
    let p0 = SMatrix::<f64, 6, 6>::identity();
    let x0 = SVector::<f64, 6>::zeros();

    let mut ekf = Ekf::new(lin6(), lin6(), x0, p0, q, r).unwrap();
    assert_steps_allocate_nothing("6-state EKF", &mut ekf, &data);

    let mut ekf = Ekf::new(
        NumericalJacobians(lin6()),
        NumericalJacobians(lin6()),
        x0,
        p0,
        q,
        r,
    )
    .unwrap();
    assert_steps_allocate_nothing("6-state EKF, numerical Jacobians", &mut ekf, &data);
}

/// Refused steps must not allocate either (errors are plain values, no formatting).
#[test]
fn refused_steps_allocate_nothing() {
    let mut ekf = Ekf::new(
        lin6(),
        lin6(),
        SVector::<f64, 6>::zeros(),
        SMatrix::<f64, 6, 6>::identity(),
        SMatrix::<f64, 6, 6>::identity() * 0.01,
        SMatrix::<f64, 2, 2>::identity(),
    )
    .unwrap();
    let mut refused = 0;
    let count = allocations_in(|| {
        for _ in 0..STEPS {
            refused += ekf.predict(&Vector1::new(f64::NAN)).is_err() as usize;
            refused += ekf
                .update(&Vector2::new(0.0, f64::INFINITY), &Vector1::new(0.0))
                .is_err() as usize;
            refused += ekf
                .update_subset(&Vector2::zeros(), &Vector1::new(0.0), &[false, false])
                .is_err() as usize;
        }
    });
    assert_eq!(count, 0);
    assert_eq!(refused, 3 * STEPS);
}
