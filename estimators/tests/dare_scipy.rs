//! `fdd_estimators::dare` against `scipy.linalg.solve_discrete_are`, plus the Kalman gains and
//! the refusal of systems without a stabilizing solution.
//!
//! `matches_scipy` draws seeded random systems `(A, B, Q, R)` for `N = 2, 4, 6, 14` states and
//! `M = 1, 2, 5` inputs of five kinds:
//!
//! - `generic`: Gaussian `A` with spectral radius about 1.1 (often unstable);
//! - `spread`: stiff `A = V diag V^-1` with eigenvalue magnitudes spread log-uniformly over
//!   1e-3..0.999 (both ends present; some complex pairs, some negative);
//! - `zoh10`, `zoh50`: the zero-order hold at 10 ms and 50 ms of a continuous system with poles
//!   from -0.2 to -4500 rad/s (both ends present; some complex pairs), so the fast modes give
//!   `A` eigenvalues down to `e^-225`;
//! - `zoh10s`: `zoh10` in badly scaled state units (state `i` multiplied by `10^u_i`,
//!   `u_i` in -3..3), as an engine model mixing pascals, kelvins and revolutions per minute is.
//!
//! It writes them to a temporary JSON file, runs `tests/data/dare_check.py` (scipy's solver
//! with its default balancing; it also reports the closed-loop spectral radius from numpy's
//! eigenvalues) and asserts, for every case, that the Rust solution is within 1e-9 of scipy's
//! (`||X - X_scipy||_F / ||X_scipy||_F`), that both satisfy the DARE to 1e-9 relative
//! ([`dare_residual`], `||res||_F / ||X||_F`), and that the closed-loop spectral radius
//! estimate agrees with numpy's. A missing scipy fails the test with a message saying to
//! `pip install scipy`; it is never skipped. Run with `-- --nocapture` for the table of worst
//! differences per size and kind, iteration counts and the time of one 14-state solve.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use fdd_estimators::dare::{
    dare_residual, solve_dare, solve_dare_detailed, spectral_radius, stationary_kalman, DareError,
    DareSolution,
};
use nalgebra::{DMatrix, Matrix1, Matrix1x2, Matrix2, Matrix2x1, SMatrix};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;
use serde_json::{json, Value};

// Counts heap allocations for `solvers_do_not_allocate`; delegates to the system allocator.
#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

/// Relative agreement with scipy and relative DARE residual required of every case.
const TOL: f64 = 1e-9;
/// Random systems per (size, kind).
const CASES_PER_KIND: usize = 4;
const KINDS: [Kind; 5] = [
    Kind::Generic,
    Kind::Spread,
    Kind::Zoh {
        dt: 0.010,
        scaled: false,
    },
    Kind::Zoh {
        dt: 0.050,
        scaled: false,
    },
    Kind::Zoh {
        dt: 0.010,
        scaled: true,
    },
];

#[derive(Debug, Clone, Copy)]
enum Kind {
    Generic,
    Spread,
    Zoh { dt: f64, scaled: bool },
}

impl Kind {
    fn label(self) -> &'static str {
        match self {
            Kind::Generic => "generic",
            Kind::Spread => "spread",
            Kind::Zoh { dt, scaled: false } if dt < 0.02 => "zoh10",
            Kind::Zoh { scaled: false, .. } => "zoh50",
            Kind::Zoh { scaled: true, .. } => "zoh10s",
        }
    }
}

/// One system with the Rust solution, in dynamic matrices for the JSON and the comparison.
struct Case {
    name: String,
    n: usize,
    m: usize,
    kind: &'static str,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    x: DMatrix<f64>,
    iterations: usize,
    closed_loop_radius: f64,
    residual: f64,
    a_radius: f64,
}

fn gaussian(rng: &mut Pcg64Mcg, rows: usize, cols: usize) -> DMatrix<f64> {
    DMatrix::from_fn(rows, cols, |_, _| rng.sample::<f64, _>(StandardNormal))
}

fn log_uniform(rng: &mut Pcg64Mcg, lo: f64, hi: f64) -> f64 {
    (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp()
}

/// Magnitudes spread over `lo..hi`, both ends included, the rest log-uniform.
fn spread(rng: &mut Pcg64Mcg, count: usize, lo: f64, hi: f64) -> Vec<f64> {
    (0..count)
        .map(|i| match i {
            0 => hi,
            1 => lo,
            _ => log_uniform(rng, lo, hi),
        })
        .collect()
}

/// Real block-diagonal matrix of 1x1 blocks `[s]` and 2x2 blocks `[[s, w], [-w, s]]`
/// (eigenvalues `s +- i w`) from a list of magnitudes; about a third become complex pairs.
/// `discrete`: a magnitude is `|lambda|` and real ones get a random sign; otherwise a magnitude
/// is `-Re(lambda)` of a continuous pole.
fn blocks(rng: &mut Pcg64Mcg, mags: &[f64], discrete: bool) -> Vec<DMatrix<f64>> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < mags.len() {
        let pair = i + 1 < mags.len() && i >= 2 && rng.random::<f64>() < 0.35;
        if pair {
            let mag = mags[i];
            let block = if discrete {
                let theta = rng.random::<f64>() * std::f64::consts::PI;
                let (s, c) = theta.sin_cos();
                DMatrix::from_row_slice(2, 2, &[mag * c, mag * s, -mag * s, mag * c])
            } else {
                let w = mag * (0.2 + 1.8 * rng.random::<f64>());
                DMatrix::from_row_slice(2, 2, &[-mag, w, -w, -mag])
            };
            out.push(block);
            i += 2;
        } else {
            let sign = if discrete && rng.random::<f64>() < 0.3 {
                -1.0
            } else {
                1.0
            };
            let value = if discrete { sign * mags[i] } else { -mags[i] };
            out.push(DMatrix::from_element(1, 1, value));
            i += 1;
        }
    }
    out
}

fn block_diag(blocks: &[DMatrix<f64>]) -> DMatrix<f64> {
    let n: usize = blocks.iter().map(|b| b.nrows()).sum();
    let mut m = DMatrix::zeros(n, n);
    let mut at = 0;
    for b in blocks {
        let k = b.nrows();
        m.view_mut((at, at), (k, k)).copy_from(b);
        at += k;
    }
    m
}

/// Exact zero-order hold of one block of `Ac`: `(e^(Ac dt), Ac^-1 (e^(Ac dt) - I))`.
fn zoh_block(block: &DMatrix<f64>, dt: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    if block.nrows() == 1 {
        let p = block[(0, 0)];
        let f = (p * dt).exp();
        (
            DMatrix::from_element(1, 1, f),
            DMatrix::from_element(1, 1, (p * dt).exp_m1() / p),
        )
    } else {
        let (s, w) = (block[(0, 0)], block[(0, 1)]);
        let e = (s * dt).exp();
        let (sn, cs) = (w * dt).sin_cos();
        let f = DMatrix::from_row_slice(2, 2, &[e * cs, e * sn, -e * sn, e * cs]);
        let inv = block.clone().try_inverse().expect("s != 0");
        let g = &inv * (&f - DMatrix::identity(2, 2));
        (f, g)
    }
}

/// A random eigenvector basis with unit columns.
fn basis(rng: &mut Pcg64Mcg, n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut v = gaussian(rng, n, n);
    for mut c in v.column_iter_mut() {
        let norm = c.norm();
        c /= norm;
    }
    let inv = v.clone().try_inverse().expect("random basis is invertible");
    (v, inv)
}

fn random_system(
    rng: &mut Pcg64Mcg,
    n: usize,
    m: usize,
    kind: Kind,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let (a, b, mut q) = match kind {
        Kind::Generic => {
            let a = gaussian(rng, n, n) * (1.1 / (n as f64).sqrt());
            (a, gaussian(rng, n, m), DMatrix::zeros(n, n))
        }
        Kind::Spread => {
            let mags = spread(rng, n, 1e-3, 0.999);
            let lambda = block_diag(&blocks(rng, &mags, true));
            let (v, vi) = basis(rng, n);
            (&v * lambda * &vi, gaussian(rng, n, m), DMatrix::zeros(n, n))
        }
        Kind::Zoh { dt, .. } => {
            let mags = spread(rng, n, 0.2, 4500.0);
            let bl = blocks(rng, &mags, false);
            let (fs, gs): (Vec<_>, Vec<_>) = bl.iter().map(|b| zoh_block(b, dt)).unzip();
            let (v, vi) = basis(rng, n);
            let a = &v * block_diag(&fs) * &vi;
            let bc = gaussian(rng, n, m);
            let b = &v * block_diag(&gs) * &vi * bc;
            (a, b, DMatrix::zeros(n, n))
        }
    };
    // Q = Cq' Cq of random rank 1..=n (rank-deficient weights are the common case) plus, half
    // the time, a small full-rank part.
    let rank = rng.random_range(1..=n);
    let cq = gaussian(rng, rank, n);
    q += cq.transpose() * &cq;
    if rng.random::<f64>() < 0.5 {
        q += DMatrix::identity(n, n) * 1e-3;
    }
    let lr = gaussian(rng, m, m);
    let r = &lr * lr.transpose() + DMatrix::identity(m, m) * 0.1;
    if let Kind::Zoh { scaled: true, .. } = kind {
        // The same system in state units z = D x: A -> D A D^-1, B -> D B, Q -> D^-1 Q D^-1.
        let d: Vec<f64> = (0..n)
            .map(|_| 10f64.powf(rng.random_range(-3.0..3.0)))
            .collect();
        let a = DMatrix::from_fn(n, n, |i, j| d[i] * a[(i, j)] / d[j]);
        let b = DMatrix::from_fn(n, m, |i, j| d[i] * b[(i, j)]);
        let q = DMatrix::from_fn(n, n, |i, j| q[(i, j)] / (d[i] * d[j]));
        return (a, b, q, r);
    }
    (a, b, q, r)
}

fn to_fixed<const R: usize, const C: usize>(m: &DMatrix<f64>) -> SMatrix<f64, R, C> {
    assert_eq!(m.shape(), (R, C));
    SMatrix::from_fn(|i, j| m[(i, j)])
}

fn to_dynamic<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> DMatrix<f64> {
    DMatrix::from_fn(R, C, |i, j| m[(i, j)])
}

fn rows(m: &DMatrix<f64>) -> Value {
    Value::Array(
        m.row_iter()
            .map(|r| Value::Array(r.iter().map(|&v| json!(v)).collect()))
            .collect(),
    )
}

fn from_rows(v: &Value, n: usize, m: usize) -> DMatrix<f64> {
    let rows = v.as_array().expect("x is a list of rows");
    assert_eq!(rows.len(), n);
    DMatrix::from_fn(n, m, |i, j| {
        rows[i].as_array().expect("a row is a list")[j]
            .as_f64()
            .expect("a number")
    })
}

fn solve_fixed<const N: usize, const M: usize>(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<DareSolution<N, M>, DareError> {
    solve_dare_detailed::<N, M>(&to_fixed(a), &to_fixed(b), &to_fixed(q), &to_fixed(r))
}

fn residual_fixed<const N: usize, const M: usize>(case: &Case, x: &DMatrix<f64>) -> f64 {
    dare_residual::<N, M>(
        &to_fixed(&case.a),
        &to_fixed(&case.b),
        &to_fixed(&case.q),
        &to_fixed(&case.r),
        &to_fixed(x),
    )
}

fn cases_for<const N: usize, const M: usize>(seed: u64, out: &mut Vec<Case>) {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    for kind in KINDS {
        for i in 0..CASES_PER_KIND {
            let (a, b, q, r) = random_system(&mut rng, N, M, kind);
            let name = format!("n{N}m{M}-{}-{i}", kind.label());
            let s = solve_fixed::<N, M>(&a, &b, &q, &r)
                .unwrap_or_else(|e| panic!("{name}: Rust solver refused the system: {e}"));
            let a_radius = spectral_radius(&to_fixed::<N, N>(&a));
            out.push(Case {
                name,
                n: N,
                m: M,
                kind: kind.label(),
                a,
                b,
                q,
                r,
                x: to_dynamic(&s.x),
                iterations: s.iterations,
                closed_loop_radius: s.closed_loop_radius,
                residual: s.residual,
                a_radius,
            });
        }
    }
}

fn residual_of(case: &Case, x: &DMatrix<f64>) -> f64 {
    match (case.n, case.m) {
        (2, 1) => residual_fixed::<2, 1>(case, x),
        (2, 2) => residual_fixed::<2, 2>(case, x),
        (2, 5) => residual_fixed::<2, 5>(case, x),
        (4, 1) => residual_fixed::<4, 1>(case, x),
        (4, 2) => residual_fixed::<4, 2>(case, x),
        (4, 5) => residual_fixed::<4, 5>(case, x),
        (6, 1) => residual_fixed::<6, 1>(case, x),
        (6, 2) => residual_fixed::<6, 2>(case, x),
        (6, 5) => residual_fixed::<6, 5>(case, x),
        (14, 1) => residual_fixed::<14, 1>(case, x),
        (14, 2) => residual_fixed::<14, 2>(case, x),
        (14, 5) => residual_fixed::<14, 5>(case, x),
        other => unreachable!("no size {other:?}"),
    }
}

/// Runs the scipy script on the cases; panics (fails the test) when python3 or scipy is missing.
fn scipy_solutions(cases: &[Case]) -> (String, Vec<Value>) {
    let doc = json!({
        "cases": cases
            .iter()
            .map(|c| json!({
                "name": c.name,
                "a": rows(&c.a),
                "b": rows(&c.b),
                "q": rows(&c.q),
                "r": rows(&c.r),
                "x_rust": rows(&c.x),
            }))
            .collect::<Vec<_>>()
    });
    let path = std::env::temp_dir().join(format!("fdd_dare_cases_{}.json", std::process::id()));
    std::fs::write(&path, serde_json::to_string(&doc).expect("serializable"))
        .expect("write the cases to a temporary file");
    let script: PathBuf = [env!("CARGO_MANIFEST_DIR"), "tests", "data", "dare_check.py"]
        .iter()
        .collect();
    let output = Command::new("python3").arg(&script).arg(&path).output();
    // FDD_DARE_KEEP_CASES=FILE keeps the cases (with the Rust solutions) for a closer look.
    if let Some(keep) = std::env::var_os("FDD_DARE_KEEP_CASES") {
        std::fs::copy(&path, keep).expect("copy the cases to FDD_DARE_KEEP_CASES");
    }
    let _ = std::fs::remove_file(&path);
    let output = output.unwrap_or_else(|e| {
        panic!("cannot run python3 ({e}): install Python 3 and then `python3 -m pip install scipy`")
    });
    assert!(
        output.status.success(),
        "{} failed ({}); this test needs scipy: `python3 -m pip install scipy`\n{}",
        script.display(),
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    let reply: Value = serde_json::from_slice(&output.stdout).expect("dare_check.py prints JSON");
    let version = reply["scipy"].as_str().unwrap_or("?").to_string();
    let solutions = reply["solutions"]
        .as_array()
        .expect("a list of solutions")
        .clone();
    (version, solutions)
}

#[derive(Default)]
struct Worst {
    count: usize,
    diff: f64,
    residual: f64,
    scipy_residual: f64,
    radius_diff: f64,
    min_iter: usize,
    max_iter: usize,
    max_radius: f64,
    max_a_radius: f64,
}

#[test]
fn matches_scipy() {
    let mut cases = Vec::new();
    cases_for::<2, 1>(21, &mut cases);
    cases_for::<2, 2>(22, &mut cases);
    cases_for::<2, 5>(25, &mut cases);
    cases_for::<4, 1>(41, &mut cases);
    cases_for::<4, 2>(42, &mut cases);
    cases_for::<4, 5>(45, &mut cases);
    cases_for::<6, 1>(61, &mut cases);
    cases_for::<6, 2>(62, &mut cases);
    cases_for::<6, 5>(65, &mut cases);
    cases_for::<14, 1>(141, &mut cases);
    cases_for::<14, 2>(142, &mut cases);
    cases_for::<14, 5>(145, &mut cases);

    let (version, solutions) = scipy_solutions(&cases);
    assert_eq!(solutions.len(), cases.len());

    let mut table: Vec<((usize, usize, &'static str), Worst)> = Vec::new();
    let mut failures = String::new();
    for (case, sol) in cases.iter().zip(&solutions) {
        assert_eq!(sol["name"].as_str(), Some(case.name.as_str()));
        if let Some(err) = sol.get("error") {
            writeln!(failures, "{}: scipy failed: {err}", case.name).unwrap();
            continue;
        }
        let xs = from_rows(&sol["x"], case.n, case.n);
        let diff = (&case.x - &xs).norm() / xs.norm();
        let scipy_residual = residual_of(case, &xs);
        let np_radius = sol["closed_loop_radius"].as_f64().expect("a number");
        let radius_diff = (case.closed_loop_radius - np_radius).abs() / np_radius.max(1e-300);
        if !(diff <= TOL && case.residual <= TOL && scipy_residual <= TOL && radius_diff <= 1e-6) {
            writeln!(
                failures,
                "{}: |X - X_scipy|/|X_scipy| = {diff:.2e}, residual {:.2e}, scipy residual \
                 {scipy_residual:.2e}, closed-loop radius {} vs numpy {np_radius}",
                case.name, case.residual, case.closed_loop_radius
            )
            .unwrap();
        }
        let key = (case.n, case.m, case.kind);
        let idx = match table.iter().position(|(k, _)| *k == key) {
            Some(i) => i,
            None => {
                table.push((
                    key,
                    Worst {
                        min_iter: usize::MAX,
                        ..Worst::default()
                    },
                ));
                table.len() - 1
            }
        };
        let w = &mut table[idx].1;
        w.count += 1;
        w.diff = w.diff.max(diff);
        w.residual = w.residual.max(case.residual);
        w.scipy_residual = w.scipy_residual.max(scipy_residual);
        w.radius_diff = w.radius_diff.max(radius_diff);
        w.min_iter = w.min_iter.min(case.iterations);
        w.max_iter = w.max_iter.max(case.iterations);
        w.max_radius = w.max_radius.max(case.closed_loop_radius);
        w.max_a_radius = w.max_a_radius.max(case.a_radius);
    }

    println!(
        "DARE vs scipy {version}: {} systems, worst per size and kind",
        cases.len()
    );
    println!(
        "{:>3} {:>2} {:<8} {:>2} {:>10} {:>10} {:>10} {:>10} {:>6} {:>9} {:>9}",
        "N",
        "M",
        "kind",
        "#",
        "rel diff",
        "residual",
        "scipy res",
        "rho diff",
        "iter",
        "rho(A)",
        "rho(S)"
    );
    for ((n, m, kind), w) in &table {
        println!(
            "{n:>3} {m:>2} {kind:<8} {:>2} {:>10.2e} {:>10.2e} {:>10.2e} {:>10.2e} {:>6} {:>9.6} {:>9.6}",
            w.count,
            w.diff,
            w.residual,
            w.scipy_residual,
            w.radius_diff,
            format!("{}-{}", w.min_iter, w.max_iter),
            w.max_a_radius,
            w.max_radius
        );
    }
    assert!(failures.is_empty(), "cases off scipy:\n{failures}");
}

/// Rough time of one 14-state, 5-input solve (printed; asserted only to be finite).
#[test]
fn time_of_a_14_state_solve() {
    let mut rng = Pcg64Mcg::seed_from_u64(7);
    let (a, b, q, r) = random_system(
        &mut rng,
        14,
        5,
        Kind::Zoh {
            dt: 0.010,
            scaled: false,
        },
    );
    let (a, b, q, r) = (
        to_fixed::<14, 14>(&a),
        to_fixed::<14, 5>(&b),
        to_fixed::<14, 14>(&q),
        to_fixed::<5, 5>(&r),
    );
    let first = solve_dare_detailed(&a, &b, &q, &r).expect("solvable");
    let reps = 200;
    let start = Instant::now();
    for _ in 0..reps {
        let x = solve_dare(std::hint::black_box(&a), std::hint::black_box(&b), &q, &r)
            .expect("solvable");
        std::hint::black_box(x);
    }
    let per = start.elapsed().as_secs_f64() / reps as f64;
    println!(
        "one 14x14 (M = 5, zoh10) solve: {:.1} us, {} doubling steps",
        per * 1e6,
        first.iterations
    );
    assert!(per.is_finite());
}

/// The solvers promise no heap allocation (fixed-size matrices only): checked on a 14-state
/// solve, the Kalman gains and a refused system.
#[test]
fn solvers_do_not_allocate() {
    let mut rng = Pcg64Mcg::seed_from_u64(11);
    let (a, b, q, r) = random_system(
        &mut rng,
        14,
        5,
        Kind::Zoh {
            dt: 0.050,
            scaled: true,
        },
    );
    let (a, b, q, r) = (
        to_fixed::<14, 14>(&a),
        to_fixed::<14, 5>(&b),
        to_fixed::<14, 14>(&q),
        to_fixed::<5, 5>(&r),
    );
    // The filter form of the same problem: stationary_kalman(A', B', Q, R) solves the DARE
    // solve_dare(A, B, Q, R) does.
    let (a_f, c_f) = (a.transpose(), b.transpose());
    let unstable = Matrix2::new(1.2, 0.0, 0.0, 0.5);
    let mut results = None;
    let allocations = fdd_testkit::allocations_in(|| {
        let x = solve_dare_detailed(&a, &b, &q, &r).map(|s| s.x);
        let k = stationary_kalman(&a_f, &c_f, &q, &r).map(|k| k.prediction_covariance);
        let e = solve_dare(
            &unstable,
            &Matrix2x1::new(0.0, 1.0),
            &Matrix2::identity(),
            &Matrix1::new(1.0),
        );
        results = Some((x, k, e));
    });
    assert_eq!(allocations, 0);
    let (x, k, e) = results.expect("the section ran");
    let (x, k) = (x.expect("solvable"), k.expect("solvable"));
    assert!((x - k).norm() <= 1e-12 * x.norm());
    assert!(matches!(e, Err(DareError::NotStabilizable { .. })));
}

#[test]
fn unstabilizable_systems_are_refused() {
    let r = Matrix1::new(1.0);
    let b = Matrix2x1::new(0.0, 1.0);
    // The unstable mode 1.2 is weighted by Q but not reachable from B: the iterates overflow.
    let a = Matrix2::new(1.2, 0.0, 0.0, 0.5);
    match solve_dare(&a, &b, &Matrix2::identity(), &r) {
        Err(DareError::NotStabilizable {
            closed_loop_radius, ..
        }) => assert_eq!(closed_loop_radius, f64::INFINITY),
        other => panic!("expected NotStabilizable, got {other:?}"),
    }
    // Same mode, not weighted by Q either: the iteration settles on a non-stabilizing solution.
    match solve_dare(&a, &b, &Matrix2::new(0.0, 0.0, 0.0, 1.0), &r) {
        Err(DareError::NotStabilizable {
            closed_loop_radius, ..
        }) => assert!(
            (closed_loop_radius - 1.2).abs() < 1e-9,
            "{closed_loop_radius}"
        ),
        other => panic!("expected NotStabilizable, got {other:?}"),
    }
    // An uncontrollable mode on the unit circle: no stabilizing solution at all.
    let a1 = Matrix2::new(1.0, 0.0, 0.3, 0.5);
    let err = solve_dare(&a1, &b, &Matrix2::identity(), &r).unwrap_err();
    assert!(
        matches!(err, DareError::NotStabilizable { .. }),
        "expected NotStabilizable, got {err:?}"
    );
    assert!(err.to_string().contains("stabilizable"));
    // Controllable but not weighted by Q: a stabilizing solution exists (scipy finds X = 3 for
    // this scalar case), but the SDA from Q = 0 cannot reach it, which is documented and
    // reported as the same error rather than a wrong X.
    let e = solve_dare(
        &Matrix1::new(2.0),
        &Matrix1::new(1.0),
        &Matrix1::new(0.0),
        &r,
    );
    assert!(matches!(e, Err(DareError::NotStabilizable { .. })), "{e:?}");
    // The filter form: a position integrator observed through its velocity only is not
    // detectable.
    let a_pv = Matrix2::new(1.0, 0.1, 0.0, 1.0);
    let c_v = Matrix1x2::new(0.0, 1.0);
    let k = stationary_kalman(
        &a_pv,
        &c_v,
        &(Matrix2::identity() * 1e-3),
        &Matrix1::new(0.1),
    );
    assert!(matches!(k, Err(DareError::NotStabilizable { .. })), "{k:?}");
}

#[test]
fn scalar_kalman_gain_by_hand() {
    // Random walk x+ = x + w, y = x + v: P^2 = q P + q r, K = P / (P + r), L = K.
    let (q, r) = (0.04, 0.25);
    let kf = stationary_kalman(
        &Matrix1::new(1.0),
        &Matrix1::new(1.0),
        &Matrix1::new(q),
        &Matrix1::new(r),
    )
    .expect("detectable and stabilizable");
    let p = (q + (q * q + 4.0 * q * r).sqrt()) / 2.0;
    let k = p / (p + r);
    assert!((kf.prediction_covariance[(0, 0)] - p).abs() < 1e-14);
    assert!((kf.filter_gain[(0, 0)] - k).abs() < 1e-14);
    assert!((kf.predictor_gain[(0, 0)] - k).abs() < 1e-14);
    assert!((kf.innovation_covariance[(0, 0)] - (p + r)).abs() < 1e-14);
    assert!((kf.filtered_covariance[(0, 0)] - p * r / (p + r)).abs() < 1e-14);
    assert!((kf.closed_loop_radius - (1.0 - k)).abs() < 1e-12);
}

#[test]
fn kalman_gain_matches_riccati_recursion() {
    // Constant-velocity model at 10 ms, observed in position, with a slow (0.999) velocity
    // decay: 1e5 steps of P <- A (P - P C' (C P C' + R)^-1 C P) A' + Q from P = Q.
    let a = Matrix2::new(1.0, 0.01, 0.0, 0.999);
    let c = Matrix1x2::new(1.0, 0.0);
    let q = Matrix2::new(1e-6, 0.0, 0.0, 1e-4);
    let r = Matrix1::new(1e-2);
    let kf = stationary_kalman(&a, &c, &q, &r).expect("detectable and stabilizable");

    let mut p = q;
    for _ in 0..100_000 {
        let s = c * p * c.transpose() + r;
        let k = p * c.transpose() / s[(0, 0)];
        let pf = p - k * c * p;
        p = a * pf * a.transpose() + q;
        p = (p + p.transpose()) * 0.5;
    }
    let k = p * c.transpose() / (c * p * c.transpose() + r)[(0, 0)];
    let rel = |x: f64, y: f64| (x - y).abs() / y.abs();
    let p_rel = (kf.prediction_covariance - p).norm() / p.norm();
    assert!(p_rel < 1e-10, "P off the recursion by {p_rel:e}");
    for i in 0..2 {
        assert!(rel(kf.filter_gain[(i, 0)], k[(i, 0)]) < 1e-9);
        let l = (a * k)[(i, 0)];
        assert!(rel(kf.predictor_gain[(i, 0)], l) < 1e-9);
    }
    // The closed loop A - L C against the eigenvalues of the 2x2 (trace and determinant).
    let cl = a - kf.predictor_gain * c;
    let (tr, det) = (cl.trace(), cl.determinant());
    let disc = tr * tr / 4.0 - det;
    let rho = if disc >= 0.0 {
        (tr / 2.0).abs() + disc.sqrt()
    } else {
        det.sqrt()
    };
    assert!(
        (kf.closed_loop_radius - rho).abs() < 1e-12,
        "{} vs {rho}",
        kf.closed_loop_radius
    );
    assert!(kf.closed_loop_radius < 1.0);
    println!(
        "Kalman 2x1: K = [{:.6e}, {:.6e}], rho(A - L C) = {:.9}, {} doubling steps",
        kf.filter_gain[(0, 0)],
        kf.filter_gain[(1, 0)],
        kf.closed_loop_radius,
        kf.iterations
    );
}
