//! Cost of one filter step (measurement update + time update), in the order fdd's monitors run
//! them: `update(y_k, u_k)` then `predict(u_k)`.
//!
//! - UKF-AHSM (L = 7), UKF-ARM (L = 4), UKF-AGM (L = 4) on the electronic throttle observed by
//!   the wattmeter only (n = 3, m = 1, u = 1), with the settings of `config/throttle.toml`.
//! - EKF on a 6-state, 2-measurement linear plant (analytic Jacobians: `A` and `C`), and on a
//!   6-state nonlinear plant whose models keep the default numerical (central-difference)
//!   Jacobians, to show what the numerical linearization costs.
//!
//! Every filter is stateful across iterations and is fed a pre-generated, cycled sequence of
//! simulated measurements, so it stays in the regime it runs in on the vehicle. Each sequence is
//! run through the filter twice before timing (every step must succeed), and every timed step is
//! checked too: a benchmark that silently measured the early-return error path would be useless.
//!
//! Run with `cargo bench -p fdd-estimators --bench filter_step`. With `FDD_BENCH_NIS=1` each
//! benchmark also prints, before timing, the mean NIS over the last warm-up pass (about `m` for
//! a consistent filter), to check that the filters run in a sensible regime.

use divan::{black_box, Bencher};
use fdd_estimators::models::linear::LinearModel;
use fdd_estimators::models::throttle::{ThrottleModel, ThrottleParams, Wattmeter};
use fdd_estimators::{
    Ekf, FilterError, Innovation, ObservationModel, SigmaPoints, TransitionModel, Ukf,
};
use nalgebra::{Matrix1, Matrix3, SMatrix, SVector, Vector1, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;

fn main() {
    divan::main();
}

/// Samples in each pre-generated sequence (a power of two, so cycling is a mask).
const SAMPLES: usize = 4096;
const MASK: usize = SAMPLES - 1;
/// Passes over the sequence before timing starts.
const WARMUP_PASSES: usize = 2;

/// One input/measurement pair fed to a filter.
#[derive(Clone, Copy)]
struct Sample<const M: usize, const U: usize> {
    u: SVector<f64, U>,
    y: SVector<f64, M>,
}

/// The update + predict pair every benchmark times.
trait Step<const M: usize, const U: usize> {
    fn step(&mut self, s: &Sample<M, U>) -> Result<Innovation<M>, FilterError>;
}

impl<T, O, const N: usize, const M: usize, const U: usize, const L: usize> Step<M, U>
    for Ukf<T, O, N, M, U, L>
where
    T: TransitionModel<N, U>,
    O: ObservationModel<N, M, U>,
{
    #[inline]
    fn step(&mut self, s: &Sample<M, U>) -> Result<Innovation<M>, FilterError> {
        let innovation = self.update(&s.y, &s.u)?;
        self.predict(&s.u)?;
        Ok(innovation)
    }
}

impl<T, O, const N: usize, const M: usize, const U: usize> Step<M, U> for Ekf<T, O, N, M, U>
where
    T: TransitionModel<N, U>,
    O: ObservationModel<N, M, U>,
{
    #[inline]
    fn step(&mut self, s: &Sample<M, U>) -> Result<Innovation<M>, FilterError> {
        let innovation = self.update(&s.y, &s.u)?;
        self.predict(&s.u)?;
        Ok(innovation)
    }
}

/// Warms `filter` up on `data` (panicking on any refused step), then times one step per
/// iteration, cycling through `data`. Panics after timing if any timed step was refused.
fn bench_filter<F, const M: usize, const U: usize>(
    bencher: Bencher,
    mut filter: F,
    data: &[Sample<M, U>],
) where
    F: Step<M, U>,
{
    assert_eq!(data.len(), SAMPLES);
    let mut nis_sum = 0.0;
    for pass in 0..WARMUP_PASSES {
        nis_sum = 0.0;
        for (k, s) in data.iter().enumerate() {
            match filter.step(s) {
                Ok(innovation) => nis_sum += innovation.nis,
                Err(e) => panic!("warm-up pass {pass}, sample {k}: filter refused the step: {e}"),
            }
        }
    }
    if std::env::var_os("FDD_BENCH_NIS").is_some() {
        eprintln!("mean NIS {:.3}", nis_sum / SAMPLES as f64);
    }
    let mut k = 0usize;
    let mut errors = 0u64;
    bencher.bench_local(|| {
        let s = black_box(&data[k & MASK]);
        k = k.wrapping_add(1);
        match filter.step(s) {
            Ok(innovation) => innovation.nis,
            Err(_) => {
                errors += 1;
                f64::NAN
            }
        }
    });
    assert_eq!(errors, 0, "{errors} of {k} timed steps were refused");
}

/// Rectangular pulses (random width and level) through a first-order low-pass: a smooth but
/// rich excitation. The last `rest` samples are zero so that a cycled trajectory, which starts
/// at rest, does not jump at the wrap.
fn pulse_train(
    rng: &mut Pcg64Mcg,
    width: (usize, usize),
    level: (f64, f64),
    smoothing: f64,
    rest: usize,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(SAMPLES);
    let (mut left, mut target, mut v) = (0usize, 0.0, 0.0);
    for k in 0..SAMPLES {
        if k >= SAMPLES - rest {
            target = 0.0;
        } else if left == 0 {
            left = rng.random_range(width.0..=width.1);
            target = rng.random_range(level.0..=level.1);
        }
        left = left.saturating_sub(1);
        v += smoothing * (target - v);
        out.push(v);
    }
    out
}

fn normal(rng: &mut Pcg64Mcg) -> f64 {
    rng.sample(StandardNormal)
}

// ------------------------------------------------------------------------------------------
// Throttle, wattmeter-only UKFs
// ------------------------------------------------------------------------------------------

fn throttle_config() -> toml::Table {
    toml::from_str(include_str!("../../config/throttle.toml")).expect("throttle.toml parses")
}

fn throttle_model() -> ThrottleModel {
    let params: ThrottleParams = throttle_config()
        .get("model")
        .expect("throttle.toml has a [model] table")
        .clone()
        .try_into()
        .expect("[model] is a valid ThrottleParams");
    ThrottleModel::new(params).expect("throttle parameters are valid")
}

/// The `[wattmeter_ukf]` settings of `config/throttle.toml` the bench needs.
#[derive(serde::Deserialize)]
struct WattmeterUkf {
    ahsm_lambda: f64,
    arm_w0: f64,
    agm_v: [f64; 3],
    p0_diag: [f64; 3],
    q_diag: [f64; 3],
    r_floor: f64,
}

fn wattmeter_ukf() -> WattmeterUkf {
    throttle_config()
        .get("wattmeter_ukf")
        .expect("throttle.toml has a [wattmeter_ukf] table")
        .clone()
        .try_into()
        .expect("[wattmeter_ukf] has the filter settings")
}

/// Initial state and the covariances, as `fdd reproduce table2` builds them for W = 1.
fn throttle_covariances() -> (Vector3<f64>, Matrix3<f64>, Matrix3<f64>, Matrix1<f64>) {
    let w = wattmeter_ukf();
    let x0 = Vector3::zeros();
    let p0 = Matrix3::from_diagonal(&Vector3::from(w.p0_diag));
    let q = Matrix3::from_diagonal(&Vector3::from(w.q_diag));
    let r = Matrix1::new(1.0 + w.r_floor);
    (x0, p0, q, r)
}

/// Simulated throttle under a 0..1.2 V pulse train, with the truth process noise of
/// `config/throttle.toml` and a wattmeter `i^2 + v`, `v ~ N(0, 1)` (R = 1 + the configured floor).
fn throttle_data(model: &ThrottleModel) -> Vec<Sample<1, 1>> {
    let mut rng = Pcg64Mcg::seed_from_u64(0x7407_7001);
    let volts = pulse_train(&mut rng, (20, 400), (0.0, 1.2), 0.1, 600);
    let process_std = Vector3::new(0.591_607_978_309_961_6, 0.0, 0.424_264_068_711_928_5) * 0.03;
    let mut x = Vector3::zeros();
    let mut data = Vec::with_capacity(SAMPLES);
    for &v in &volts {
        let u = Vector1::new(v);
        let y = Vector1::new(x[2] * x[2] + normal(&mut rng));
        data.push(Sample { u, y });
        let w = Vector3::from_fn(|i, _| process_std[i] * normal(&mut rng));
        x = model.transition(&x, &u) + w;
        model.constrain(&mut x);
    }
    data
}

#[divan::bench(sample_count = 1000, sample_size = 256)]
fn ukf_ahsm_throttle(bencher: Bencher) {
    let model = throttle_model();
    let (x0, p0, q, r) = throttle_covariances();
    let points = SigmaPoints::<3, 7>::ahsm(wattmeter_ukf().ahsm_lambda).expect("AHSM set");
    let filter = Ukf::<_, _, 3, 1, 1, 7>::new(model, Wattmeter, points, x0, p0, q, r)
        .expect("UKF-AHSM settings");
    bench_filter(bencher, filter, &throttle_data(&model));
}

#[divan::bench(sample_count = 1000, sample_size = 256)]
fn ukf_arm_throttle(bencher: Bencher) {
    let model = throttle_model();
    let (x0, p0, q, r) = throttle_covariances();
    let points = SigmaPoints::<3, 4>::arm(wattmeter_ukf().arm_w0).expect("ARM set");
    let filter = Ukf::<_, _, 3, 1, 1, 4>::new(model, Wattmeter, points, x0, p0, q, r)
        .expect("UKF-ARM settings");
    bench_filter(bencher, filter, &throttle_data(&model));
}

#[divan::bench(sample_count = 1000, sample_size = 256)]
fn ukf_agm_throttle(bencher: Bencher) {
    let model = throttle_model();
    let (x0, p0, q, r) = throttle_covariances();
    let points = SigmaPoints::<3, 4>::agm(&Vector3::from(wattmeter_ukf().agm_v)).expect("AGM set");
    let filter = Ukf::<_, _, 3, 1, 1, 4>::new(model, Wattmeter, points, x0, p0, q, r)
        .expect("UKF-AGM settings");
    bench_filter(bencher, filter, &throttle_data(&model));
}

// ------------------------------------------------------------------------------------------
// 6-state, 2-measurement EKFs
// ------------------------------------------------------------------------------------------

type V6 = SVector<f64, 6>;
type M6 = SMatrix<f64, 6, 6>;
type V2 = SVector<f64, 2>;
type M2 = SMatrix<f64, 2, 2>;

/// Sampling period of the 6-state plants (s).
const DT6: f64 = 1e-3;

/// `exp(M)` by scaling and squaring with a Taylor series (M small after scaling).
fn expm<const K: usize>(m: &SMatrix<f64, K, K>) -> SMatrix<f64, K, K> {
    let squarings = (m.norm().max(1e-300).log2().ceil() as i32 + 4).max(0);
    let a = m / 2f64.powi(squarings);
    let mut term = SMatrix::<f64, K, K>::identity();
    let mut sum = term;
    for i in 1..=16 {
        term = term * a / i as f64;
        sum += term;
    }
    for _ in 0..squarings {
        sum = sum * sum;
    }
    sum
}

/// A 6-state plant: a lightly damped oscillator (x0 position, x1 velocity, f = 8 Hz,
/// zeta = 0.15) driven through a lag (x2, tau = 20 ms) by the input, and a chain of three lags
/// (x3..x5, tau = 50, 80, 120 ms) fed by the oscillator position and the driving lag. Sensors:
/// oscillator position and the end of the chain. Zero-order-hold discretization at 1 ms.
fn linear_plant() -> LinearModel<6, 2, 1> {
    let w = 2.0 * std::f64::consts::PI * 8.0;
    let zeta = 0.15;
    let (t2, t3, t4, t5) = (0.020, 0.050, 0.080, 0.120);
    #[rustfmt::skip]
    let ac = SMatrix::<f64, 7, 7>::from_row_slice(&[
        // x0        x1              x2       x3         x4        x5        u
        0.0,         1.0,            0.0,     0.0,       0.0,      0.0,      0.0,
        -w * w,      -2.0 * zeta * w, w * w,  0.0,       0.0,      0.0,      0.0,
        0.0,         0.0,            -1.0/t2, 0.0,       0.0,      0.0,      1.0/t2,
        0.6 / t3,    0.0,            0.4/t3,  -1.0/t3,   0.0,      0.0,      0.0,
        0.0,         0.0,            0.0,     1.0/t4,    -1.0/t4,  0.0,      0.0,
        0.0,         0.0,            0.0,     0.0,       1.0/t5,   -1.0/t5,  0.0,
        0.0,         0.0,            0.0,     0.0,       0.0,      0.0,      0.0,
    ]);
    let ad = expm(&(ac * DT6));
    let a: M6 = ad.fixed_view::<6, 6>(0, 0).into_owned();
    let b: SMatrix<f64, 6, 1> = ad.fixed_view::<6, 1>(0, 6).into_owned();
    let mut c = SMatrix::<f64, 2, 6>::zeros();
    c[(0, 0)] = 1.0;
    c[(1, 5)] = 1.0;
    LinearModel {
        a,
        b,
        c,
        d: SMatrix::zeros(),
    }
}

/// A 6-state nonlinear plant (explicit Euler at 1 ms) that keeps the default numerical
/// Jacobians: a Duffing oscillator (x0, x1; 8 Hz, zeta ~ 0.15) with quadratic air drag, driven through a
/// saturating actuator lag (x2); a chain of lags (x3..x5) with a saturating coupling from the
/// oscillator. Sensors: the oscillator position and a quadratic reading of the chain end.
#[derive(Clone, Copy)]
struct NonlinearPlant;

/// Smooth saturation with unit slope at 0 and limits +-1.
#[inline]
fn sat(v: f64) -> f64 {
    v / (1.0 + v * v).sqrt()
}

impl TransitionModel<6, 1> for NonlinearPlant {
    fn transition(&self, x: &V6, u: &Vector1<f64>) -> V6 {
        let w2 = (2.0 * std::f64::consts::PI * 8.0_f64).powi(2);
        let dx = V6::new(
            x[1],
            -w2 * (x[0] + 0.5 * x[0] * x[0] * x[0]) - 15.0 * x[1] - 0.05 * x[1] * x[1].abs()
                + w2 * x[2],
            (2.0 * sat(u[0]) - x[2]) * (1.0 / 0.020),
            (sat(2.0 * x[0]) + 0.4 * x[2] - x[3]) * (1.0 / 0.050),
            (x[3] - x[4]) * (1.0 / 0.080),
            (x[4] - x[5]) * (1.0 / 0.120),
        );
        x + dx * DT6
    }
}

impl ObservationModel<6, 2, 1> for NonlinearPlant {
    fn observe(&self, x: &V6, _u: &Vector1<f64>) -> V2 {
        V2::new(x[0], x[5] + 0.25 * x[5] * x[5])
    }
}

/// Simulates `plant` under a pulse-train input with process noise `q_std` and measurement
/// noise `r_std`.
fn six_state_data<P>(plant: &P, seed: u64, q_std: &V6, r_std: &V2) -> Vec<Sample<2, 1>>
where
    P: TransitionModel<6, 1> + ObservationModel<6, 2, 1>,
{
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let input = pulse_train(&mut rng, (30, 500), (-1.0, 1.0), 0.2, 600);
    let mut x = V6::zeros();
    let mut data = Vec::with_capacity(SAMPLES);
    for &v in &input {
        let u = Vector1::new(v);
        let noise = V2::from_fn(|i, _| r_std[i] * normal(&mut rng));
        data.push(Sample {
            u,
            y: plant.observe(&x, &u) + noise,
        });
        let w = V6::from_fn(|i, _| q_std[i] * normal(&mut rng));
        x = plant.transition(&x, &u) + w;
    }
    data
}

fn six_state_noise() -> (V6, V2) {
    let q_std = V6::new(1e-4, 2e-2, 1e-3, 1e-4, 1e-4, 1e-4);
    let r_std = V2::new(1e-2, 1e-2);
    (q_std, r_std)
}

fn six_state_ekf<P>(plant: P, seed: u64) -> (Ekf<P, P, 6, 2, 1>, Vec<Sample<2, 1>>)
where
    P: TransitionModel<6, 1> + ObservationModel<6, 2, 1> + Copy,
{
    let (q_std, r_std) = six_state_noise();
    let data = six_state_data(&plant, seed, &q_std, &r_std);
    let q = M6::from_diagonal(&q_std.component_mul(&q_std));
    let r = M2::from_diagonal(&r_std.component_mul(&r_std));
    let filter =
        Ekf::new(plant, plant, V6::zeros(), M6::identity() * 0.1, q, r).expect("EKF settings");
    (filter, data)
}

#[divan::bench(sample_count = 1000, sample_size = 256)]
fn ekf6_linear_analytic_jacobian(bencher: Bencher) {
    let (filter, data) = six_state_ekf(linear_plant(), 0x6e6b_0001);
    bench_filter(bencher, filter, &data);
}

#[divan::bench(sample_count = 1000, sample_size = 256)]
fn ekf6_nonlinear_numerical_jacobian(bencher: Bencher) {
    let (filter, data) = six_state_ekf(NonlinearPlant, 0x6e6b_0002);
    bench_filter(bencher, filter, &data);
}

// ------------------------------------------------------------------------------------------
// Intake manifold (6 states, MAP + MAF): the three filters of the intake monitor
// ------------------------------------------------------------------------------------------

use fdd_estimators::models::intake::{
    IntakeInput, IntakeModel, IntakeParams, MafSensor, MapMafSensors, MapSensor, ThrottleFlow,
    X_WTHR,
};
use fdd_estimators::{DecentralizedPair, FederatedFilter, FusionNoise};

/// Engine speeds (rpm) the intake filters are timed at: idle, mid, top (segment 37.5, 10, 5 ms).
const INTAKE_SPEEDS: [u32; 3] = [800, 3000, 6000];

fn intake_model(flow: ThrottleFlow) -> IntakeModel {
    #[derive(serde::Deserialize)]
    struct File {
        model: IntakeParams,
    }
    let params = toml::from_str::<File>(include_str!("../../config/intake.toml"))
        .expect("intake.toml parses")
        .model;
    IntakeModel::new(params, flow).expect("intake parameters are valid")
}

/// Throttle range (deg) driven at each speed: part load around the speed's usual openings.
fn throttle_range(speed: f64) -> (f64, f64) {
    if speed < 1500.0 {
        (2.0, 12.0)
    } else if speed < 4500.0 {
        (5.0, 35.0)
    } else {
        (10.0, 80.0)
    }
}

/// Settings of the intake filters at one speed: the paper's filter model (throttle flow as a
/// random walk), initial estimate at the equilibrium of the lowest opening, `Q` with a random
/// walk on `W_thr` (2 % of the mean flow per segment) and on the pulsation, small model noise on
/// the other states, `R` from the configured sensor noise (700 Pa, 1.5 % of the mean flow).
struct IntakeSetup {
    model: IntakeModel,
    x0: V6,
    p0: M6,
    q: M6,
    r_map: f64,
    r_maf: f64,
    data: Vec<Sample<2, 3>>,
}

fn intake_setup(speed: u32) -> IntakeSetup {
    let truth = intake_model(ThrottleFlow::Nozzle);
    let model = intake_model(ThrottleFlow::RandomWalk);
    let p = truth.params().clone();
    let speed = f64::from(speed);
    let (lo, hi) = throttle_range(speed);
    let mut rng = Pcg64Mcg::seed_from_u64(0x1a7a_0000 + speed as u64);
    let throttle = pulse_train(&mut rng, (20, 300), (0.0, hi - lo), 0.2, 300);
    let x_lo = truth
        .equilibrium(&IntakeInput::new(speed, lo, 0.0))
        .expect("equilibrium");
    let x_mid = truth
        .equilibrium(&IntakeInput::new(speed, 0.5 * (lo + hi), 0.0))
        .expect("equilibrium");
    let w_mean = 0.5 * (x_lo[X_WTHR] + x_mid[X_WTHR]);
    let w = IntakeModel::pump_frequency(speed);
    let q_std = V6::new(100.0, 20.0, 0.02 * w_mean, 1e-3 * w_mean, 200.0, 200.0 * w);
    let mut x = x_lo;
    let mut data = Vec::with_capacity(SAMPLES);
    for &th in &throttle {
        // Rest at the lowest opening (pulse_train's zero is mapped to `lo`).
        let u = IntakeInput::new(speed, lo + th, 0.0);
        let y = V2::new(
            x[1] + p.map_noise_std_pa * normal(&mut rng),
            x[3] * (1.0 + p.maf_noise_rel * normal(&mut rng)),
        );
        data.push(Sample { u, y });
        x = truth.transition(&x, &u);
        // Pulsation excitation only (the truth's other states follow the nozzle model).
        x[4] += q_std[4] * normal(&mut rng);
        x[5] += q_std[5] * normal(&mut rng);
    }
    let mut p0 = V6::new(2e3, 2e3, 0.1 * w_mean, 0.1 * w_mean, 1e3, 1e3 * w);
    p0.component_mul_assign(&p0.clone());
    IntakeSetup {
        model,
        x0: x_lo,
        p0: M6::from_diagonal(&p0),
        q: M6::from_diagonal(&q_std.component_mul(&q_std)),
        r_map: p.map_noise_std_pa.powi(2),
        r_maf: (p.maf_noise_rel * w_mean).powi(2),
        data,
    }
}

impl IntakeSetup {
    fn noise(&self) -> FusionNoise<6, 1, 1> {
        FusionNoise {
            q: self.q,
            r1: Matrix1::new(self.r_map),
            r2: Matrix1::new(self.r_maf),
        }
    }
}

struct Pair(DecentralizedPair<IntakeModel, MapSensor, MafSensor, 6, 1, 1, 3>);
struct Federated(FederatedFilter<IntakeModel, MapSensor, MafSensor, 6, 1, 1, 3>);

impl Step<2, 3> for Pair {
    #[inline]
    fn step(&mut self, s: &Sample<2, 3>) -> Result<Innovation<2>, FilterError> {
        let fused = self
            .0
            .step(&s.u, &Vector1::new(s.y[0]), &Vector1::new(s.y[1]))?;
        Ok(nis_only(fused.nis))
    }
}

impl Step<2, 3> for Federated {
    #[inline]
    fn step(&mut self, s: &Sample<2, 3>) -> Result<Innovation<2>, FilterError> {
        let fused = self
            .0
            .step(&s.u, &Vector1::new(s.y[0]), &Vector1::new(s.y[1]))?;
        Ok(nis_only(fused.nis))
    }
}

/// An innovation carrying only the NIS (what `bench_filter` reads).
fn nis_only(nis: f64) -> Innovation<2> {
    Innovation {
        residual: V2::zeros(),
        covariance: M2::identity(),
        nis,
        dof: 2,
    }
}

/// Centralized EKF on MAP + MAF (update + predict).
#[divan::bench(args = INTAKE_SPEEDS, sample_count = 300, sample_size = 64)]
fn intake_ekf_centralized(bencher: Bencher, speed: u32) {
    let s = intake_setup(speed);
    let r = M2::from_diagonal(&V2::new(s.r_map, s.r_maf));
    let filter = Ekf::new(s.model.clone(), MapMafSensors, s.x0, s.p0, s.q, r).expect("EKF");
    bench_filter(bencher, filter, &s.data);
}

/// The paper's decentralized pair: MAP and MAF local EKFs, naive information fusion.
#[divan::bench(args = INTAKE_SPEEDS, sample_count = 300, sample_size = 64)]
fn intake_decentralized_pair(bencher: Bencher, speed: u32) {
    let s = intake_setup(speed);
    let pair = DecentralizedPair::new(s.model.clone(), MapSensor, MafSensor, s.x0, s.p0, s.noise())
        .expect("pair");
    bench_filter(bencher, Pair(pair), &s.data);
}

/// Federated filter (fusion-reset, beta = 1/2 each).
#[divan::bench(args = INTAKE_SPEEDS, sample_count = 300, sample_size = 64)]
fn intake_federated(bencher: Bencher, speed: u32) {
    let s = intake_setup(speed);
    let fed = FederatedFilter::new(
        s.model.clone(),
        MapSensor,
        MafSensor,
        s.x0,
        s.p0,
        s.noise(),
        [0.5, 0.5],
    )
    .expect("federated");
    bench_filter(bencher, Federated(fed), &s.data);
}
