//! Bad samples and bad settings are refused with the right error, and a refused step leaves the
//! filter exactly as it was.
//!
//! Onboard, a NaN or infinite sample must not reach the estimate: a single NaN would otherwise
//! poison the state and covariance for good. For the UKF (every sigma-point set) and the EKF,
//! on a linear model with 2 inputs and 3 measurements (so that the reported index means
//! something) and on the throttle with position sensor and wattmeter, this checks that:
//!
//! - `predict` with a non-finite input returns `FilterError::NonFiniteInput` naming the first bad
//!   component, and `update`/`update_subset` with a non-finite measurement (in a used component)
//!   or input return `NonFiniteMeasurement` / `NonFiniteInput` likewise;
//! - after any refused call, the state and covariance are bit-identical to before, and the
//!   filter still accepts the next good sample;
//! - a non-finite value in a component that `update_subset` drops is ignored: the update is
//!   bit-identical to one with any finite value there;
//! - `update_subset` with an all-false mask is `FilterError::EmptySubset`;
//! - a non-positive-definite, asymmetric or non-finite `P0`/`R`, an indefinite `Q` given to `new`,
//!   and a bad covariance or non-finite state given to `reset`, are `ConfigError`s (and a refused
//!   `reset` changes nothing).

use fdd_estimators::models::linear::LinearModel;
use fdd_estimators::models::throttle::{
    PositionAndWattmeter, PositionSensor, ThrottleModel, ThrottleParams,
};
use fdd_estimators::{ConfigError, Ekf, FilterError, Innovation, SigmaPoints, Ukf};
use nalgebra::{Matrix3, SMatrix, SVector, Vector1, Vector2, Vector3};

const BAD: [f64; 3] = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];

type Lin = LinearModel<3, 3, 2>;

fn lin() -> Lin {
    LinearModel {
        a: Matrix3::new(0.9, 0.1, 0.0, -0.1, 0.8, 0.2, 0.0, 0.1, 0.95),
        b: SMatrix::<f64, 3, 2>::new(1.0, 0.0, 0.0, 0.5, 0.2, 0.3),
        c: Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.5, 0.3, 0.0, 1.0),
        d: SMatrix::<f64, 3, 2>::new(0.0, 0.1, 0.2, 0.0, 0.0, 0.0),
    }
}

fn lin_q() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 0.01))
}

fn lin_r() -> Matrix3<f64> {
    Matrix3::new(0.1, 0.01, 0.0, 0.01, 0.2, 0.0, 0.0, 0.0, 0.1)
}

fn lin_p0() -> Matrix3<f64> {
    Matrix3::new(1.0, 0.2, 0.0, 0.2, 1.0, 0.1, 0.0, 0.1, 2.0)
}

fn lin_x0() -> Vector3<f64> {
    Vector3::new(0.5, -1.0, 2.0)
}

/// Uniform access to the filters under test.
trait Filter<const N: usize, const M: usize, const U: usize> {
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
    fn reset(&mut self, x: SVector<f64, N>, p: SMatrix<f64, N, N>) -> Result<(), ConfigError>;
    fn state(&self) -> SVector<f64, N>;
    fn covariance(&self) -> SMatrix<f64, N, N>;
}

macro_rules! impl_filter {
    ($ty:ty, $n:literal, $m:literal, $u:literal $(, const $l:ident)?) => {
        impl<T, O $(, const $l: usize)?> Filter<$n, $m, $u> for $ty
        where
            T: fdd_estimators::TransitionModel<$n, $u>,
            O: fdd_estimators::ObservationModel<$n, $m, $u>,
        {
            fn predict(&mut self, u: &SVector<f64, $u>) -> Result<(), FilterError> {
                <$ty>::predict(self, u)
            }
            fn update_subset(
                &mut self,
                y: &SVector<f64, $m>,
                u: &SVector<f64, $u>,
                used: &[bool; $m],
            ) -> Result<Innovation<$m>, FilterError> {
                <$ty>::update_subset(self, y, u, used)
            }
            fn update(
                &mut self,
                y: &SVector<f64, $m>,
                u: &SVector<f64, $u>,
            ) -> Result<Innovation<$m>, FilterError> {
                <$ty>::update(self, y, u)
            }
            fn reset(
                &mut self,
                x: SVector<f64, $n>,
                p: SMatrix<f64, $n, $n>,
            ) -> Result<(), ConfigError> {
                <$ty>::reset(self, x, p)
            }
            fn state(&self) -> SVector<f64, $n> {
                *<$ty>::state(self)
            }
            fn covariance(&self) -> SMatrix<f64, $n, $n> {
                *<$ty>::covariance(self)
            }
        }
    };
}

impl_filter!(Ekf<T, O, 3, 3, 2>, 3, 3, 2);
impl_filter!(Ukf<T, O, 3, 3, 2, L>, 3, 3, 2, const L);
impl_filter!(Ekf<T, O, 3, 2, 1>, 3, 2, 1);
impl_filter!(Ukf<T, O, 3, 2, 1, L>, 3, 2, 1, const L);

/// Bit pattern of the estimate, so that "unchanged" means exactly unchanged (NaN included).
fn snapshot<const N: usize, const M: usize, const U: usize>(
    f: &impl Filter<N, M, U>,
) -> (Vec<u64>, Vec<u64>) {
    (
        f.state().iter().map(|v| v.to_bits()).collect(),
        f.covariance().iter().map(|v| v.to_bits()).collect(),
    )
}

fn same_value(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits()
}

/// The input/measurement checks for one filter. `u_ok`, `y_ok` are a good sample.
fn check_refusals<const N: usize, const M: usize, const U: usize>(
    name: &str,
    f: &mut impl Filter<N, M, U>,
    u_ok: SVector<f64, U>,
    y_ok: SVector<f64, M>,
) {
    // Move away from the initial estimate so that "unchanged" is a real statement.
    f.predict(&u_ok).unwrap();
    f.update(&y_ok, &u_ok).unwrap();
    let all = [true; M];

    for bad in BAD {
        for idx in 0..U {
            let mut u = u_ok;
            u[idx] = bad;
            let before = snapshot(f);
            match f.predict(&u) {
                Err(FilterError::NonFiniteInput { index, value }) => {
                    assert_eq!(index, idx, "{name}: predict index");
                    assert!(same_value(value, bad), "{name}: predict value {value}");
                }
                other => panic!("{name}: predict with u[{idx}] = {bad} gave {other:?}"),
            }
            assert_eq!(snapshot(f), before, "{name}: predict changed the estimate");

            // The input is checked by the update too, even with a good measurement.
            match f.update(&y_ok, &u) {
                Err(FilterError::NonFiniteInput { index, value }) => {
                    assert_eq!(index, idx, "{name}: update index");
                    assert!(same_value(value, bad));
                }
                other => panic!("{name}: update with u[{idx}] = {bad} gave {other:?}"),
            }
            assert_eq!(snapshot(f), before, "{name}: update changed the estimate");
        }

        for idx in 0..M {
            let mut y = y_ok;
            y[idx] = bad;
            let before = snapshot(f);
            match f.update(&y, &u_ok) {
                Err(FilterError::NonFiniteMeasurement { index, value }) => {
                    assert_eq!(index, idx, "{name}: update index");
                    assert!(same_value(value, bad));
                }
                other => panic!("{name}: update with y[{idx}] = {bad} gave {other:?}"),
            }
            assert_eq!(snapshot(f), before, "{name}: update changed the estimate");

            // Same through update_subset when the bad component is used.
            let mut used = [false; M];
            used[idx] = true;
            match f.update_subset(&y, &u_ok, &used) {
                Err(FilterError::NonFiniteMeasurement { index, .. }) => assert_eq!(index, idx),
                other => panic!("{name}: update_subset with y[{idx}] = {bad} gave {other:?}"),
            }
            assert_eq!(snapshot(f), before);

            // Dropped component: the bad value is ignored, and the result is the one with any
            // finite value in its place.
            if M > 1 {
                let mut used = all;
                used[idx] = false;
                let mut twin_y = y_ok;
                twin_y[idx] = 12345.0;
                let (x_before, p_before) = (f.state(), f.covariance());
                let got = f
                    .update_subset(&y, &u_ok, &used)
                    .unwrap_or_else(|e| panic!("{name}: dropped bad y[{idx}] still refused: {e}"));
                assert_eq!(got.residual[idx], 0.0);
                assert_eq!(got.dof, M - 1);
                let after_bad = snapshot(f);
                // Undo, then redo with the finite stand-in.
                f.reset(x_before, p_before).unwrap();
                assert_eq!(snapshot(f), before);
                let twin = f.update_subset(&twin_y, &u_ok, &used).unwrap();
                assert_eq!(snapshot(f), after_bad, "{name}: dropped component leaked");
                assert_eq!(twin, got);
            }
        }
    }

    // Several bad components: the first one is reported.
    let mut y = y_ok;
    y[M - 1] = f64::NAN;
    y[0] = f64::INFINITY;
    let before = snapshot(f);
    assert!(matches!(
        f.update(&y, &u_ok),
        Err(FilterError::NonFiniteMeasurement { index: 0, .. })
    ));
    assert_eq!(snapshot(f), before);

    // Empty subset, with good or bad data.
    assert_eq!(
        f.update_subset(&y_ok, &u_ok, &[false; M]),
        Err(FilterError::EmptySubset)
    );
    assert_eq!(
        f.update_subset(&y, &u_ok, &[false; M]),
        Err(FilterError::EmptySubset)
    );
    assert_eq!(snapshot(f), before);

    // Still usable, and a good step changes the estimate.
    f.predict(&u_ok)
        .unwrap_or_else(|e| panic!("{name}: good predict after refusals: {e}"));
    f.update(&y_ok, &u_ok)
        .unwrap_or_else(|e| panic!("{name}: good update after refusals: {e}"));
    assert_ne!(snapshot(f), before);
}

/// Covariances that `new` and `reset` must refuse, with the name they must be refused under.
fn bad_spd() -> Vec<(&'static str, Matrix3<f64>)> {
    vec![
        (
            "indefinite",
            Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        ),
        (
            "singular",
            Matrix3::from_diagonal(&Vector3::new(1.0, 0.0, 1.0)),
        ),
        ("negative", -Matrix3::identity()),
        ("zero", Matrix3::zeros()),
        (
            "asymmetric",
            Matrix3::new(1.0, 0.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        ),
        (
            "nan",
            Matrix3::from_diagonal(&Vector3::new(1.0, f64::NAN, 1.0)),
        ),
        (
            "inf",
            Matrix3::from_diagonal(&Vector3::new(1.0, f64::INFINITY, 1.0)),
        ),
    ]
}

fn not_positive(r: Result<(), ConfigError>, name: &str) -> bool {
    matches!(r, Err(ConfigError::NotPositive { name: n, .. }) if n == name)
}

fn check_reset<const M: usize, const U: usize>(name: &str, f: &mut impl Filter<3, M, U>) {
    let before = snapshot(f);
    for (what, p) in bad_spd() {
        assert!(
            not_positive(f.reset(Vector3::zeros(), p), "P"),
            "{name}: reset with {what} P accepted"
        );
        assert_eq!(
            snapshot(f),
            before,
            "{name}: refused reset changed the estimate"
        );
    }
    for bad in BAD {
        let r = f.reset(Vector3::new(0.0, bad, 0.0), Matrix3::identity());
        assert!(
            matches!(r, Err(ConfigError::InvalidParameter { name: "x", .. })),
            "{name}: reset with x[1] = {bad} gave {r:?}"
        );
        assert_eq!(
            snapshot(f),
            before,
            "{name}: refused reset changed the estimate"
        );
    }
    let x = Vector3::new(0.1, 0.2, 0.3);
    let p = Matrix3::identity() * 2.0;
    f.reset(x, p).unwrap();
    assert_eq!(f.state(), x);
    assert_eq!(f.covariance(), p);
}

fn lin_u() -> Vector2<f64> {
    Vector2::new(0.3, -1.2)
}

fn lin_y() -> Vector3<f64> {
    Vector3::new(0.7, -0.4, 2.5)
}

fn lin_ukf<const L: usize>(points: SigmaPoints<3, L>) -> Ukf<Lin, Lin, 3, 3, 2, L> {
    Ukf::new(lin(), lin(), points, lin_x0(), lin_p0(), lin_q(), lin_r()).unwrap()
}

fn lin_ekf() -> Ekf<Lin, Lin, 3, 3, 2> {
    Ekf::new(lin(), lin(), lin_x0(), lin_p0(), lin_q(), lin_r()).unwrap()
}

#[test]
fn linear_filters_refuse_non_finite_samples() {
    check_refusals("EKF", &mut lin_ekf(), lin_u(), lin_y());
    let ahsm = SigmaPoints::<3, 7>::ahsm(2.0).unwrap();
    let scaled = SigmaPoints::<3, 7>::scaled(0.5, 2.0, 1.0).unwrap();
    let arm = SigmaPoints::<3, 4>::arm(0.25).unwrap();
    let agm = SigmaPoints::<3, 4>::agm(&Vector3::new(1.0, -1.0, 0.5)).unwrap();
    check_refusals("UKF-AHSM", &mut lin_ukf(ahsm), lin_u(), lin_y());
    check_refusals("UKF-scaled", &mut lin_ukf(scaled), lin_u(), lin_y());
    check_refusals("UKF-ARM", &mut lin_ukf(arm), lin_u(), lin_y());
    check_refusals("UKF-AGM", &mut lin_ukf(agm), lin_u(), lin_y());
}

fn throttle() -> ThrottleModel {
    let table: toml::Table =
        toml::from_str(include_str!("../../config/throttle.toml")).expect("throttle.toml parses");
    let params: ThrottleParams = table["model"].clone().try_into().expect("[model]");
    ThrottleModel::new(params).unwrap()
}

#[test]
fn throttle_filters_refuse_non_finite_samples() {
    let model = throttle();
    let sensor = PositionAndWattmeter {
        position: PositionSensor::new(5.0, 90.0, model.params().angle_scale),
    };
    let x0 = Vector3::new(model.scaled_angle(20.0), 0.0, 0.5);
    let p0 = Matrix3::identity();
    let q = Matrix3::from_diagonal(&Vector3::new(3.15e-4, 0.0, 1.62e-4));
    let r = SMatrix::<f64, 2, 2>::from_diagonal(&Vector2::new(1e-4, 1e-3));
    let u = Vector1::new(1.5);
    let y = Vector2::new(1.2, 0.3);

    let mut ekf = Ekf::new(model, sensor, x0, p0, q, r).unwrap();
    check_refusals("throttle EKF", &mut ekf, u, y);
    check_reset("throttle EKF", &mut ekf);

    let mut ukf = Ukf::new(
        model,
        sensor,
        SigmaPoints::<3, 7>::ahsm(12.0).unwrap(),
        x0,
        p0,
        q,
        r,
    )
    .unwrap();
    check_refusals("throttle UKF-AHSM", &mut ukf, u, y);
    check_reset("throttle UKF-AHSM", &mut ukf);

    let mut ukf = Ukf::new(
        model,
        sensor,
        SigmaPoints::<3, 4>::arm(0.25).unwrap(),
        x0,
        p0,
        q,
        r,
    )
    .unwrap();
    check_refusals("throttle UKF-ARM", &mut ukf, u, y);
}

#[test]
fn reset_refuses_bad_covariance_and_state() {
    let mut ekf = lin_ekf();
    check_reset("EKF", &mut ekf);
    let mut ukf = lin_ukf(SigmaPoints::<3, 4>::arm(0.25).unwrap());
    check_reset("UKF-ARM", &mut ukf);
}

#[test]
fn new_refuses_bad_covariances() {
    let pts = SigmaPoints::<3, 7>::ahsm(2.0).unwrap();
    for (what, bad) in bad_spd() {
        // P0 and R must be positive definite.
        let e = Ekf::new(lin(), lin(), lin_x0(), bad, lin_q(), lin_r()).map(|_| ());
        assert!(not_positive(e, "P0"), "EKF accepted {what} P0");
        let u = Ukf::new(lin(), lin(), pts, lin_x0(), bad, lin_q(), lin_r()).map(|_| ());
        assert!(not_positive(u, "P0"), "UKF accepted {what} P0");
        let e = Ekf::new(lin(), lin(), lin_x0(), lin_p0(), lin_q(), bad).map(|_| ());
        assert!(not_positive(e, "R"), "EKF accepted {what} R");
        let u = Ukf::new(lin(), lin(), pts, lin_x0(), lin_p0(), lin_q(), bad).map(|_| ());
        assert!(not_positive(u, "R"), "UKF accepted {what} R");
        // Q only needs to be semidefinite: a singular or zero Q is fine, the rest is not.
        let e = Ekf::new(lin(), lin(), lin_x0(), lin_p0(), bad, lin_r()).map(|_| ());
        let u = Ukf::new(lin(), lin(), pts, lin_x0(), lin_p0(), bad, lin_r()).map(|_| ());
        if what == "singular" || what == "zero" {
            assert!(e.is_ok() && u.is_ok(), "semidefinite {what} Q refused");
        } else {
            assert!(not_positive(e, "Q"), "EKF accepted {what} Q");
            assert!(not_positive(u, "Q"), "UKF accepted {what} Q");
        }
    }
    for bad in BAD {
        let x0 = Vector3::new(0.0, 0.0, bad);
        let e = Ekf::new(lin(), lin(), x0, lin_p0(), lin_q(), lin_r()).map(|_| ());
        assert!(matches!(
            e,
            Err(ConfigError::InvalidParameter { name: "x0", .. })
        ));
        let u = Ukf::new(lin(), lin(), pts, x0, lin_p0(), lin_q(), lin_r()).map(|_| ());
        assert!(matches!(
            u,
            Err(ConfigError::InvalidParameter { name: "x0", .. })
        ));
    }
}
