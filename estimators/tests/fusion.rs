//! Decentralized and federated fusion of two sensors (REFERENCE §2).
//!
//! - The federated filter (fusion-reset, beta = 0.5/0.5 and 0.3/0.7) equals the centralized
//!   Kalman filter (an `Ekf` with both sensors, block-diagonal R) to 1e-9 at every step on a
//!   linear-Gaussian 4-state model with two scalar sensors (H1 = e2', H2 = e4'), including the
//!   joint NIS; and equals the centralized EKF on a small nonlinear model.
//! - The naive decentralized fusion is overconfident: its covariance is below the centralized
//!   one, and its state NEES over a long seeded simulation is well above N, while the
//!   federated filter's NEES mean is within 10% of N and its joint NIS mean within 10% of M.
//! - A NaN measurement is refused and leaves both filters unchanged.
//! - A step allocates nothing (counting global allocator, thread-local counter).

use std::hint::black_box;

use fdd_estimators::linalg::{cholesky, cholesky_solve, symmetric_eigen};
use fdd_estimators::models::linear::LinearModel;
use fdd_estimators::{
    DecentralizedPair, Ekf, FederatedFilter, FilterError, FusionNoise, ObservationModel,
    TransitionModel,
};
use nalgebra::{
    Matrix1, Matrix2, Matrix4, RowVector4, SMatrix, SVector, Vector1, Vector2, Vector4,
};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64Mcg;

// ---------------------------------------------------------------- counting allocator

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

use fdd_testkit::allocations_in;

// ---------------------------------------------------------------- linear 4-state model

type Central = LinearModel<4, 2, 1>;
type Local = LinearModel<4, 1, 1>;

fn a() -> Matrix4<f64> {
    Matrix4::new(
        0.90, 0.10, 0.00, 0.05, //
        -0.10, 0.85, 0.20, 0.00, //
        0.00, 0.00, 0.95, 0.10, //
        0.05, 0.00, -0.10, 0.80,
    )
}

fn b() -> SMatrix<f64, 4, 1> {
    SMatrix::<f64, 4, 1>::new(0.5, 0.0, 1.0, -0.3)
}

fn central() -> Central {
    let mut c = SMatrix::<f64, 2, 4>::zeros();
    c[(0, 1)] = 1.0; // H_map = e2'
    c[(1, 3)] = 1.0; // H_maf = e4'
    LinearModel {
        a: a(),
        b: b(),
        c,
        d: SMatrix::zeros(),
    }
}

fn local(row: usize) -> Local {
    let mut c = RowVector4::zeros();
    c[row] = 1.0;
    LinearModel {
        a: a(),
        b: b(),
        c,
        d: SMatrix::zeros(),
    }
}

fn q() -> Matrix4<f64> {
    let g = Matrix4::new(
        0.10, 0.02, 0.00, 0.00, //
        0.00, 0.08, 0.01, 0.00, //
        0.00, 0.00, 0.05, 0.02, //
        0.01, 0.00, 0.00, 0.07,
    );
    g * g.transpose()
}

const R1: f64 = 0.04;
const R2: f64 = 0.09;

fn p0() -> Matrix4<f64> {
    Matrix4::from_diagonal(&Vector4::new(1.0, 0.5, 2.0, 0.8))
}

fn noise() -> FusionNoise<4, 1, 1> {
    FusionNoise {
        q: q(),
        r1: Matrix1::new(R1),
        r2: Matrix1::new(R2),
    }
}

fn gaussian<const N: usize>(rng: &mut Pcg64Mcg, chol: &SMatrix<f64, N, N>) -> SVector<f64, N> {
    let z = SVector::<f64, N>::from_fn(|_, _| StandardNormal.sample(rng));
    chol * z
}

/// Seeded truth simulation: inputs and both sensors' measurements, and the true states.
type Sample = (Vector1<f64>, Vector1<f64>, Vector1<f64>, Vector4<f64>);

fn simulate(steps: usize, seed: u64) -> Vec<Sample> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let lq = cholesky(&q()).expect("Q SPD");
    let lp = cholesky(&p0()).expect("P0 SPD");
    let mut x = gaussian(&mut rng, &lp);
    let model = central();
    (0..steps)
        .map(|k| {
            let u = Vector1::new((k as f64 * 0.05).sin());
            x = model.a * x + model.b * u + gaussian(&mut rng, &lq);
            let v1: f64 = StandardNormal.sample(&mut rng);
            let v2: f64 = StandardNormal.sample(&mut rng);
            let y1 = Vector1::new(x[1] + R1.sqrt() * v1);
            let y2 = Vector1::new(x[3] + R2.sqrt() * v2);
            (u, y1, y2, x)
        })
        .collect()
}

fn close<const R: usize, const C: usize>(
    what: &str,
    k: usize,
    a: &SMatrix<f64, R, C>,
    b: &SMatrix<f64, R, C>,
) {
    let scale = a.amax().max(b.amax()).max(1.0);
    let err = (a - b).amax();
    assert!(err <= 1e-9 * scale, "{what} at step {k}: differ by {err:e}");
}

fn central_ekf() -> Ekf<Central, Central, 4, 2, 1> {
    Ekf::new(
        central(),
        central(),
        Vector4::zeros(),
        p0(),
        q(),
        Matrix2::new(R1, 0.0, 0.0, R2),
    )
    .expect("valid")
}

type Federated = FederatedFilter<Local, Local, Local, 4, 1, 1, 1>;
type Pair = DecentralizedPair<Local, Local, Local, 4, 1, 1, 1>;

fn federated(beta: [f64; 2]) -> Federated {
    FederatedFilter::new(
        local(0),
        local(1),
        local(3),
        Vector4::zeros(),
        p0(),
        noise(),
        beta,
    )
    .expect("valid")
}

fn pair() -> Pair {
    DecentralizedPair::new(
        local(0),
        local(1),
        local(3),
        Vector4::zeros(),
        p0(),
        noise(),
    )
    .expect("valid")
}

fn nees(x_true: &Vector4<f64>, x: &Vector4<f64>, p: &Matrix4<f64>) -> f64 {
    let e = x_true - x;
    let l = cholesky(p).expect("P SPD");
    e.dot(&cholesky_solve(&l, &e))
}

// ---------------------------------------------------------------- (a) equivalence

#[test]
fn federated_fusion_reset_equals_centralized_kf() {
    let data = simulate(300, 7);
    for beta in [[0.5, 0.5], [0.3, 0.7]] {
        let mut fed = federated(beta);
        let mut ekf = central_ekf();
        for (k, (u, y1, y2, _)) in data.iter().enumerate() {
            let step = fed.step(u, y1, y2).expect("federated step");
            ekf.predict(u).expect("predict");
            let inn = ekf.update(&Vector2::new(y1[0], y2[0]), u).expect("update");
            close("state", k, &step.x, ekf.state());
            close("covariance", k, &step.p, ekf.covariance());
            close("stored state", k, fed.state(), ekf.state());
            let nis_err = (step.nis - inn.nis).abs();
            assert!(
                nis_err <= 1e-9 * inn.nis.max(1.0),
                "joint NIS at step {k}: {} vs {}",
                step.nis,
                inn.nis
            );
            assert_eq!(step.dof, 2);
            // The locals' residuals are the centralized residual's components.
            assert!((step.local1.residual[0] - inn.residual[0]).abs() < 1e-9);
            assert!((step.local2.residual[0] - inn.residual[1]).abs() < 1e-9);
        }
    }
}

/// Small nonlinear plant: a damped pendulum with two extra states, sensors `x1 + 0.1 x0^2`
/// and `sin(x3) + 0.2 x2`.
#[derive(Debug, Clone, Copy)]
struct Pendulum;

impl TransitionModel<4, 1> for Pendulum {
    fn transition(&self, x: &Vector4<f64>, u: &Vector1<f64>) -> Vector4<f64> {
        let dt = 0.05;
        Vector4::new(
            x[0] + dt * x[1],
            x[1] + dt * (-9.81 * x[0].sin() - 0.3 * x[1] + u[0]),
            0.95 * x[2] + 0.05 * x[0] * x[1],
            0.9 * x[3] + 0.1 * x[0].cos(),
        )
    }
}

#[derive(Debug, Clone, Copy)]
struct Sensor1;
impl ObservationModel<4, 1, 1> for Sensor1 {
    fn observe(&self, x: &Vector4<f64>, _u: &Vector1<f64>) -> Vector1<f64> {
        Vector1::new(x[1] + 0.1 * x[0] * x[0])
    }
}

#[derive(Debug, Clone, Copy)]
struct Sensor2;
impl ObservationModel<4, 1, 1> for Sensor2 {
    fn observe(&self, x: &Vector4<f64>, _u: &Vector1<f64>) -> Vector1<f64> {
        Vector1::new(x[3].sin() + 0.2 * x[2])
    }
}

#[derive(Debug, Clone, Copy)]
struct Both;
impl ObservationModel<4, 2, 1> for Both {
    fn observe(&self, x: &Vector4<f64>, u: &Vector1<f64>) -> Vector2<f64> {
        Vector2::new(Sensor1.observe(x, u)[0], Sensor2.observe(x, u)[0])
    }
}

#[test]
fn federated_equals_centralized_ekf_on_nonlinear_model() {
    let x0 = Vector4::new(0.3, 0.0, 0.1, 0.2);
    let p = Matrix4::from_diagonal(&Vector4::new(0.1, 0.1, 0.05, 0.05));
    let qn = Matrix4::from_diagonal(&Vector4::new(1e-4, 1e-3, 1e-4, 1e-4));
    let mut fed = FederatedFilter::new(
        Pendulum,
        Sensor1,
        Sensor2,
        x0,
        p,
        FusionNoise {
            q: qn,
            r1: Matrix1::new(1e-3),
            r2: Matrix1::new(2e-3),
        },
        [0.4, 0.6],
    )
    .expect("valid");
    let mut ekf = Ekf::new(
        Pendulum,
        Both,
        x0,
        p,
        qn,
        Matrix2::new(1e-3, 0.0, 0.0, 2e-3),
    )
    .expect("valid");
    let mut truth = Vector4::new(0.5, 0.0, 0.0, 0.0);
    let mut rng = Pcg64Mcg::seed_from_u64(11);
    for k in 0..400 {
        let u = Vector1::new(0.5 * (k as f64 * 0.02).sin());
        truth = Pendulum.transition(&truth, &u);
        let n1: f64 = StandardNormal.sample(&mut rng);
        let n2: f64 = StandardNormal.sample(&mut rng);
        let y = Both.observe(&truth, &u) + Vector2::new(0.03 * n1, 0.045 * n2);
        let step = fed
            .step(&u, &Vector1::new(y[0]), &Vector1::new(y[1]))
            .expect("federated");
        ekf.predict(&u).expect("predict");
        let inn = ekf.update(&y, &u).expect("update");
        close("state", k, &step.x, ekf.state());
        close("covariance", k, &step.p, ekf.covariance());
        assert!(
            (step.nis - inn.nis).abs() <= 1e-8 * inn.nis.max(1.0),
            "NIS at {k}"
        );
    }
}

// ---------------------------------------------------------------- (b) consistency

#[test]
fn naive_fusion_is_overconfident_federated_is_consistent() {
    const STEPS: usize = 40_000;
    const BURN_IN: usize = 200;
    let data = simulate(STEPS, 2024);
    let mut fed = federated([0.5, 0.5]);
    let mut naive = pair();
    let mut ekf = central_ekf();
    let (mut nees_fed, mut nees_naive, mut nis_fed, mut nis_naive) = (0.0, 0.0, 0.0, 0.0);
    let (mut nees_local1, mut nees_local2) = (0.0, 0.0);
    let mut max_overconfidence = f64::NEG_INFINITY;
    for (k, (u, y1, y2, x_true)) in data.iter().enumerate() {
        let f = fed.step(u, y1, y2).expect("federated");
        let n = naive.step(u, y1, y2).expect("naive");
        ekf.predict(u).expect("predict");
        ekf.update(&Vector2::new(y1[0], y2[0]), u).expect("update");
        if k < BURN_IN {
            continue;
        }
        nees_fed += nees(x_true, &f.x, &f.p);
        nees_naive += nees(x_true, &n.x, &n.p);
        nees_local1 += nees(x_true, naive.local1().state(), naive.local1().covariance());
        nees_local2 += nees(x_true, naive.local2().state(), naive.local2().covariance());
        nis_fed += f.nis;
        nis_naive += n.nis;
        let (d, _) = symmetric_eigen(&(ekf.covariance() - n.p)).expect("finite");
        max_overconfidence = max_overconfidence.max(d.max());
    }
    let count = (STEPS - BURN_IN) as f64;
    let (nees_fed, nees_naive) = (nees_fed / count, nees_naive / count);
    let (nis_fed, nis_naive) = (nis_fed / count, nis_naive / count);
    let (nees_local1, nees_local2) = (nees_local1 / count, nees_local2 / count);
    println!("N = 4, M = 2, {} steps after burn-in", STEPS - BURN_IN);
    println!("federated (beta 0.5/0.5): mean NEES {nees_fed:.3}, mean joint NIS {nis_fed:.3}");
    println!(
        "naive decentralized fusion: mean NEES {nees_naive:.3}, mean NIS (sum of locals) \
         {nis_naive:.3}; locals' NEES {nees_local1:.3} / {nees_local2:.3}"
    );
    println!("max eigenvalue of P_central - P_naive: {max_overconfidence:.4e}");
    let (p_c, p_n) = (ekf.covariance(), naive.covariance());
    println!(
        "final trace P: central {:.4}, naive {:.4}, federated {:.4}",
        p_c.trace(),
        p_n.trace(),
        fed.covariance().trace()
    );

    assert!(
        max_overconfidence > 0.0,
        "naive fused covariance should be below the centralized one in some direction"
    );
    assert!(p_n.trace() < p_c.trace());
    assert!(
        (nees_fed - 4.0).abs() < 0.4,
        "federated NEES mean {nees_fed} not within 10% of N = 4"
    );
    assert!(
        (nis_fed - 2.0).abs() < 0.2,
        "federated joint NIS mean {nis_fed} not within 10% of M = 2"
    );
    assert!(
        nees_naive > 1.25 * 4.0,
        "naive fusion NEES mean {nees_naive} should be clearly above N = 4"
    );
    // Each local filter on its own is a proper Kalman filter.
    assert!((nees_local1 - 4.0).abs() < 0.4 && (nees_local2 - 4.0).abs() < 0.4);
}

// ---------------------------------------------------------------- (c) bad input

#[test]
fn nan_measurement_is_refused_and_changes_nothing() {
    let data = simulate(20, 3);
    let mut fed = federated([0.5, 0.5]);
    let mut naive = pair();
    for (u, y1, y2, _) in &data {
        fed.step(u, y1, y2).expect("federated");
        naive.step(u, y1, y2).expect("naive");
    }
    let fed_before = fed.clone();
    let naive_before = naive.clone();
    let (u, y1, _, _) = data[0];
    let bad = Vector1::new(f64::NAN);
    assert!(matches!(
        fed.step(&u, &y1, &bad),
        Err(FilterError::NonFiniteMeasurement { index: 0, .. })
    ));
    assert!(matches!(
        naive.step(&u, &bad, &y1),
        Err(FilterError::NonFiniteMeasurement { index: 0, .. })
    ));
    assert!(matches!(
        fed.step(&Vector1::new(f64::INFINITY), &y1, &y1),
        Err(FilterError::NonFiniteInput { index: 0, .. })
    ));
    assert_eq!(fed.state(), fed_before.state());
    assert_eq!(fed.covariance(), fed_before.covariance());
    assert_eq!(fed.local_estimate(0), fed_before.local_estimate(0));
    assert_eq!(fed.local_estimate(1), fed_before.local_estimate(1));
    assert_eq!(naive.state(), naive_before.state());
    assert_eq!(naive.covariance(), naive_before.covariance());
    assert_eq!(naive.local1().state(), naive_before.local1().state());
    assert_eq!(
        naive.local1().covariance(),
        naive_before.local1().covariance()
    );
    assert_eq!(naive.local2().state(), naive_before.local2().state());
    assert_eq!(
        naive.local2().covariance(),
        naive_before.local2().covariance()
    );

    // Invalid sharing factors are refused at construction.
    for beta in [[0.5, 0.6], [0.0, 1.0], [f64::NAN, 0.5]] {
        assert!(FederatedFilter::new(
            local(0),
            local(1),
            local(3),
            Vector4::zeros(),
            p0(),
            noise(),
            beta
        )
        .is_err());
    }
}

// ---------------------------------------------------------------- (d) no allocation

#[test]
fn fusion_steps_allocate_nothing() {
    let data = simulate(1000, 5);
    let mut fed = federated([0.5, 0.5]);
    let mut naive = pair();
    let mut nonlinear = FederatedFilter::new(
        Pendulum,
        Sensor1,
        Sensor2,
        Vector4::new(0.3, 0.0, 0.1, 0.2),
        Matrix4::identity() * 0.1,
        FusionNoise {
            q: Matrix4::identity() * 1e-4,
            r1: Matrix1::new(1e-2),
            r2: Matrix1::new(1e-2),
        },
        [0.5, 0.5],
    )
    .expect("valid");
    let mut refused = 0usize;
    let mut sink = 0.0;
    let count = allocations_in(|| {
        for (u, y1, y2, _) in &data {
            match fed.step(u, y1, y2) {
                Ok(s) => sink += black_box(s).nis,
                Err(_) => refused += 1,
            }
            match naive.step(u, y1, y2) {
                Ok(s) => sink += black_box(s).nis,
                Err(_) => refused += 1,
            }
            match nonlinear.step(u, y1, y2) {
                Ok(s) => sink += black_box(s).nis,
                Err(_) => refused += 1,
            }
            match naive.fuse() {
                Ok((x, _)) => sink += black_box(x)[0],
                Err(_) => refused += 1,
            }
        }
    });
    assert_eq!(refused, 0);
    assert!(sink.is_finite());
    assert_eq!(count, 0, "fusion steps allocated {count} times");
}

/// A partial step with both measurements is the full step; with one missing, that local runs
/// on the model alone (its state is the prediction) and the other updates as usual; a NaN
/// measurement is refused and changes nothing.
#[test]
fn partial_step_runs_the_locals_that_have_a_measurement() {
    let data = simulate(200, 31);
    let (mut full, mut part) = (pair(), pair());
    for (k, (u, y1, y2, _)) in data.iter().enumerate() {
        full.step(u, y1, y2).expect("full step");
        part.step_partial(u, Some(y1), Some(y2))
            .expect("partial step");
        close("state", k, full.state(), part.state());
        close("covariance", k, full.covariance(), part.covariance());
    }
    // Sensor 1 lost: local 1 predicts only, local 2 is unaffected.
    let (mut only2, mut model1) = (part.clone(), part.local1().clone());
    let mut reference2 = part.local2().clone();
    for (k, (u, _, y2, _)) in data.iter().enumerate().take(50) {
        only2.step_partial(u, None, Some(y2)).expect("partial step");
        model1.predict(u).expect("predict");
        reference2.predict(u).expect("predict");
        reference2.update(y2, u).expect("update");
        close(
            "model-only local",
            k,
            only2.local1().state(),
            model1.state(),
        );
        close(
            "updated local",
            k,
            only2.local2().state(),
            reference2.state(),
        );
    }
    let before = (*only2.state(), *only2.local1().state());
    let (u, _, _, _) = &data[0];
    assert!(only2
        .step_partial(u, Some(&Vector1::new(f64::NAN)), None)
        .is_err());
    assert_eq!((*only2.state(), *only2.local1().state()), before);
}
