//! On a linear-Gaussian model every Kalman-type filter must be *the* Kalman filter.
//!
//! For `x+ = A x + B u + w`, `y = C x + D u + v` the EKF's linearization is exact and every
//! sigma-point set reproduces the first two moments exactly, so the EKF and the UKF with each of
//! the four sets (AHSM, scaled, ARM, AGM) must give the same state, covariance and innovation as
//! a textbook Kalman filter written here with plain nalgebra (`P = A P A' + Q`,
//! `K = P C' (C P C' + R)^-1`, `P = (I - K C) P`). The test runs 200 steps of seeded random
//! inputs and measurements through all of them and compares, at every step, the estimate and
//! covariance (1e-9 relative) and the returned `Innovation` (residual, S, NIS = r' S^-1 r and
//! log-likelihood `-(m ln 2pi + ln det S + NIS) / 2`, `dof`).
//!
//! Every fourth step is a partial update (`update_subset`, masks `[true, false]` and
//! `[false, true]` in turn), compared with a textbook update that uses only the selected row of
//! `C` (dof = 1): the library's "zero residual, unit variance" trick for dropped components must
//! give exactly that update and an innovation with the dropped component neutral.

use std::f64::consts::PI;

use fdd_estimators::models::linear::LinearModel;
use fdd_estimators::{Ekf, FilterError, Innovation, SigmaPoints, Ukf};
use nalgebra::{Matrix2, Matrix2x4, Matrix4, SMatrix, SVector, Vector1, Vector2, Vector4};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;

const STEPS: usize = 200;
const TOL: f64 = 1e-9;

type Model = LinearModel<4, 2, 1>;

fn model() -> Model {
    LinearModel {
        a: Matrix4::new(
            0.90, 0.10, 0.00, 0.05, //
            -0.10, 0.85, 0.20, 0.00, //
            0.00, 0.00, 0.95, 0.10, //
            0.05, 0.00, -0.10, 0.80,
        ),
        b: SMatrix::<f64, 4, 1>::new(0.5, 0.0, 1.0, -0.3),
        c: Matrix2x4::new(
            1.0, 0.0, 0.5, 0.0, //
            0.0, 1.0, 0.0, -1.0,
        ),
        d: SMatrix::<f64, 2, 1>::new(0.2, -0.1),
    }
}

fn q() -> Matrix4<f64> {
    let g = Matrix4::new(
        0.10, 0.00, 0.00, 0.00, //
        0.03, 0.15, 0.00, 0.00, //
        0.00, -0.02, 0.08, 0.00, //
        0.01, 0.00, 0.04, 0.12,
    );
    g * g.transpose()
}

fn r() -> Matrix2<f64> {
    Matrix2::new(0.04, 0.01, 0.01, 0.09)
}

fn x0() -> Vector4<f64> {
    Vector4::new(1.0, -0.5, 0.2, 0.0)
}

fn p0() -> Matrix4<f64> {
    Matrix4::new(
        1.0, 0.1, 0.0, 0.0, //
        0.1, 2.0, 0.2, 0.0, //
        0.0, 0.2, 0.5, 0.05, //
        0.0, 0.0, 0.05, 1.0,
    )
}

/// One step of data: input, measurement, and which components the update uses.
#[derive(Debug, Clone, Copy)]
struct Step {
    u: Vector1<f64>,
    y: Vector2<f64>,
    mask: [bool; 2],
}

/// Seeded simulation of the true system, shared by every filter.
fn data() -> Vec<Step> {
    let m = model();
    let gq = fdd_estimators::linalg::cholesky(&q()).unwrap();
    let gr = fdd_estimators::linalg::cholesky(&r()).unwrap();
    let mut rng = Pcg64Mcg::seed_from_u64(0x11ea_5eed);
    let mut x = x0() + Vector4::new(0.3, -0.2, 0.1, 0.4);
    (0..STEPS)
        .map(|k| {
            let u = Vector1::new(2.0 * rng.sample::<f64, _>(StandardNormal));
            let w = Vector4::from_fn(|_, _| rng.sample(StandardNormal));
            x = m.a * x + m.b * u + gq * w;
            let v = Vector2::from_fn(|_, _| rng.sample(StandardNormal));
            let y = m.c * x + m.d * u + gr * v;
            let mask = match k % 8 {
                3 => [true, false],
                7 => [false, true],
                _ => [true, true],
            };
            Step { u, y, mask }
        })
        .collect()
}

/// What a textbook update must return as the innovation.
struct Expected {
    residual: Vector2<f64>,
    covariance: Matrix2<f64>,
    nis: f64,
    log_likelihood: f64,
    dof: usize,
}

/// The textbook linear Kalman filter.
struct TextbookKf {
    m: Model,
    q: Matrix4<f64>,
    r: Matrix2<f64>,
    x: Vector4<f64>,
    p: Matrix4<f64>,
}

impl TextbookKf {
    fn predict(&mut self, u: &Vector1<f64>) {
        self.x = self.m.a * self.x + self.m.b * u;
        self.p = self.m.a * self.p * self.m.a.transpose() + self.q;
    }

    fn update_full(&mut self, y: &Vector2<f64>, u: &Vector1<f64>) -> Expected {
        let c = self.m.c;
        let s = c * self.p * c.transpose() + self.r;
        let s_inv = s.try_inverse().expect("S invertible");
        let k = self.p * c.transpose() * s_inv;
        let res = y - c * self.x - self.m.d * u;
        self.x += k * res;
        self.p = (Matrix4::identity() - k * c) * self.p;
        let nis = (res.transpose() * s_inv * res)[(0, 0)];
        Expected {
            residual: res,
            covariance: s,
            nis,
            log_likelihood: -0.5 * (2.0 * (2.0 * PI).ln() + s.determinant().ln() + nis),
            dof: 2,
        }
    }

    /// Update with row `i` of `C` only (a scalar measurement).
    fn update_row(&mut self, i: usize, y: &Vector2<f64>, u: &Vector1<f64>) -> Expected {
        let c = self.m.c.row(i).into_owned();
        let s = (c * self.p * c.transpose())[(0, 0)] + self.r[(i, i)];
        let k = self.p * c.transpose() / s;
        let res = y[i] - (c * self.x)[(0, 0)] - (self.m.d.row(i) * u)[(0, 0)];
        self.x += k * res;
        self.p = (Matrix4::identity() - k * c) * self.p;
        let nis = res * res / s;
        let mut residual = Vector2::zeros();
        residual[i] = res;
        let mut covariance = Matrix2::identity();
        covariance[(i, i)] = s;
        Expected {
            residual,
            covariance,
            nis,
            log_likelihood: -0.5 * ((2.0 * PI).ln() + s.ln() + nis),
            dof: 1,
        }
    }

    fn update(&mut self, y: &Vector2<f64>, u: &Vector1<f64>, mask: [bool; 2]) -> Expected {
        match mask {
            [true, true] => self.update_full(y, u),
            [true, false] => self.update_row(0, y, u),
            [false, true] => self.update_row(1, y, u),
            [false, false] => unreachable!("no empty masks in the data"),
        }
    }
}

/// The part of the filter API this test drives, so one loop checks EKF and UKFs alike.
trait Filter {
    fn predict(&mut self, u: &Vector1<f64>) -> Result<(), FilterError>;
    fn update(&mut self, y: &Vector2<f64>, u: &Vector1<f64>) -> Result<Innovation<2>, FilterError>;
    fn update_subset(
        &mut self,
        y: &Vector2<f64>,
        u: &Vector1<f64>,
        mask: &[bool; 2],
    ) -> Result<Innovation<2>, FilterError>;
    fn state(&self) -> Vector4<f64>;
    fn covariance(&self) -> Matrix4<f64>;
}

impl Filter for Ekf<Model, Model, 4, 2, 1> {
    fn predict(&mut self, u: &Vector1<f64>) -> Result<(), FilterError> {
        Ekf::predict(self, u)
    }
    fn update(&mut self, y: &Vector2<f64>, u: &Vector1<f64>) -> Result<Innovation<2>, FilterError> {
        Ekf::update(self, y, u)
    }
    fn update_subset(
        &mut self,
        y: &Vector2<f64>,
        u: &Vector1<f64>,
        mask: &[bool; 2],
    ) -> Result<Innovation<2>, FilterError> {
        Ekf::update_subset(self, y, u, mask)
    }
    fn state(&self) -> Vector4<f64> {
        *Ekf::state(self)
    }
    fn covariance(&self) -> Matrix4<f64> {
        *Ekf::covariance(self)
    }
}

impl<const L: usize> Filter for Ukf<Model, Model, 4, 2, 1, L> {
    fn predict(&mut self, u: &Vector1<f64>) -> Result<(), FilterError> {
        Ukf::predict(self, u)
    }
    fn update(&mut self, y: &Vector2<f64>, u: &Vector1<f64>) -> Result<Innovation<2>, FilterError> {
        Ukf::update(self, y, u)
    }
    fn update_subset(
        &mut self,
        y: &Vector2<f64>,
        u: &Vector1<f64>,
        mask: &[bool; 2],
    ) -> Result<Innovation<2>, FilterError> {
        Ukf::update_subset(self, y, u, mask)
    }
    fn state(&self) -> Vector4<f64> {
        *Ukf::state(self)
    }
    fn covariance(&self) -> Matrix4<f64> {
        *Ukf::covariance(self)
    }
}

fn close_vec<const R: usize>(got: &SVector<f64, R>, want: &SVector<f64, R>) -> bool {
    (got - want).norm() <= TOL * want.norm().max(1.0)
}

fn close_mat<const R: usize, const C: usize>(
    got: &SMatrix<f64, R, C>,
    want: &SMatrix<f64, R, C>,
) -> bool {
    (got - want).norm() <= TOL * want.norm()
}

fn close(got: f64, want: f64) -> bool {
    (got - want).abs() <= TOL * want.abs().max(1.0)
}

fn check_innovation(name: &str, k: usize, got: &Innovation<2>, want: &Expected) {
    assert_eq!(got.dof, want.dof, "{name} step {k}: dof");
    assert!(
        close_vec(&got.residual, &want.residual),
        "{name} step {k}: residual {} vs textbook {}",
        got.residual,
        want.residual
    );
    assert!(
        close_mat(&got.covariance, &want.covariance),
        "{name} step {k}: S {} vs textbook {}",
        got.covariance,
        want.covariance
    );
    assert!(
        close(got.nis, want.nis),
        "{name} step {k}: NIS {} vs textbook {}",
        got.nis,
        want.nis
    );
    assert!(
        close(got.log_likelihood(), want.log_likelihood),
        "{name} step {k}: log-likelihood {} vs textbook {}",
        got.log_likelihood(),
        want.log_likelihood
    );
    // Internal consistency of the returned statistics themselves.
    let s_inv = got.covariance.try_inverse().expect("S invertible");
    let nis = (got.residual.transpose() * s_inv * got.residual)[(0, 0)];
    assert!(close(got.nis, nis), "{name} step {k}: NIS != r' S^-1 r");
    let ll =
        -0.5 * (got.dof as f64 * (2.0 * PI).ln() + got.covariance.determinant().ln() + got.nis);
    assert!(
        close(got.log_likelihood(), ll),
        "{name} step {k}: log-likelihood inconsistent with S and NIS"
    );
}

/// Runs `filter` and the textbook filter side by side over the shared data.
fn check_against_textbook(name: &str, mut filter: impl Filter) {
    let data = data();
    let mut kf = TextbookKf {
        m: model(),
        q: q(),
        r: r(),
        x: x0(),
        p: p0(),
    };
    let mut partial_updates = 0;
    for (k, st) in data.iter().enumerate() {
        filter
            .predict(&st.u)
            .unwrap_or_else(|e| panic!("{name} step {k}: predict: {e}"));
        kf.predict(&st.u);
        assert!(
            close_vec(&filter.state(), &kf.x),
            "{name} step {k}: predicted state {} vs textbook {}",
            filter.state(),
            kf.x
        );
        assert!(
            close_mat(&filter.covariance(), &kf.p),
            "{name} step {k}: predicted covariance {} vs textbook {}",
            filter.covariance(),
            kf.p
        );

        let got = if st.mask == [true, true] {
            filter.update(&st.y, &st.u)
        } else {
            partial_updates += 1;
            filter.update_subset(&st.y, &st.u, &st.mask)
        }
        .unwrap_or_else(|e| panic!("{name} step {k}: update: {e}"));
        let want = kf.update(&st.y, &st.u, st.mask);
        check_innovation(name, k, &got, &want);
        assert!(
            close_vec(&filter.state(), &kf.x),
            "{name} step {k}: corrected state {} vs textbook {}",
            filter.state(),
            kf.x
        );
        assert!(
            close_mat(&filter.covariance(), &kf.p),
            "{name} step {k}: corrected covariance {} vs textbook {}",
            filter.covariance(),
            kf.p
        );
    }
    assert_eq!(partial_updates, STEPS / 4);
}

fn ukf<const L: usize>(points: SigmaPoints<4, L>) -> Ukf<Model, Model, 4, 2, 1, L> {
    Ukf::new(model(), model(), points, x0(), p0(), q(), r()).expect("valid filter")
}

#[test]
fn ekf_equals_textbook_kalman_filter() {
    let ekf = Ekf::new(model(), model(), x0(), p0(), q(), r()).expect("valid filter");
    check_against_textbook("EKF", ekf);
}

#[test]
fn ukf_ahsm_equals_textbook_kalman_filter() {
    check_against_textbook("UKF-AHSM", ukf(SigmaPoints::<4, 9>::ahsm(2.0).unwrap()));
    // A negative centre weight must not change the result on a linear model.
    check_against_textbook(
        "UKF-AHSM(-1)",
        ukf(SigmaPoints::<4, 9>::ahsm(-1.0).unwrap()),
    );
}

#[test]
fn ukf_scaled_equals_textbook_kalman_filter() {
    check_against_textbook(
        "UKF-scaled",
        ukf(SigmaPoints::<4, 9>::scaled(0.5, 2.0, 1.0).unwrap()),
    );
}

#[test]
fn ukf_arm_equals_textbook_kalman_filter() {
    check_against_textbook("UKF-ARM", ukf(SigmaPoints::<4, 5>::arm(0.25).unwrap()));
}

#[test]
fn ukf_agm_equals_textbook_kalman_filter() {
    let v = Vector4::new(1.0, -0.5, 2.0, 0.8);
    check_against_textbook("UKF-AGM", ukf(SigmaPoints::<4, 5>::agm(&v).unwrap()));
}

/// The data must exercise the filter: residuals are not all tiny, so a filter that ignored the
/// measurements (or the inputs) would be caught by the state comparison.
#[test]
fn data_is_informative() {
    let data = data();
    let mut kf = TextbookKf {
        m: model(),
        q: q(),
        r: r(),
        x: x0(),
        p: p0(),
    };
    let mut moved = 0.0_f64;
    for st in &data {
        kf.predict(&st.u);
        let before = kf.x;
        kf.update(&st.y, &st.u, st.mask);
        moved = moved.max((kf.x - before).norm());
    }
    assert!(moved > 0.1, "largest correction only {moved}");
    let u_max = data.iter().map(|s| s.u[0].abs()).fold(0.0, f64::max);
    assert!(u_max > 1.0);
}
