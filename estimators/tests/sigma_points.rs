//! Property tests of the sigma-point sets: every set must reproduce the mean and covariance it
//! was built from.
//!
//! The whole unscented transform rests on the moment conditions `sum wm_j X_j = x` and
//! `sum wc_j (X_j - x)(X_j - x)' = P` (and `sum wm_j = 1`). For random SPD `P` (`A A' + 0.1 I`,
//! entries of `A` in [-3, 3]), random means (entries in [-100, 100]) and random set parameters,
//! the points from `generate(&x, &chol(P))` must give back `x` and `P` to 1e-9 relative, for
//! n = 3 and n = 5 and for each of AHSM, scaled, ARM and AGM. A wrong weight, a wrong offset or
//! a wrong centre point moves the moments by O(1), far beyond the tolerance.
//!
//! The second half checks that the constructors refuse parameters for which the set does not
//! exist (`n + lambda <= 0`, `w0` outside (0, 1), a zero entry in `v`, a point count `L` that
//! does not match the set), so a bad configuration surfaces as a `ConfigError` and not as NaN
//! weights at run time.

use fdd_estimators::linalg::cholesky;
use fdd_estimators::{ConfigError, SigmaKind, SigmaPoints};
use nalgebra::{SMatrix, SVector, Vector3};
use proptest::prelude::*;

/// Relative tolerance of the moment checks.
const TOL: f64 = 1e-9;

fn spd<const N: usize>(a: &[f64]) -> SMatrix<f64, N, N> {
    let a = SMatrix::<f64, N, N>::from_row_slice(a);
    a * a.transpose() + SMatrix::<f64, N, N>::identity() * 0.1
}

/// Checks the weight sum, the mean and the covariance reproduced by `set` for `(x, p)`.
fn assert_reproduces<const N: usize, const L: usize>(
    set: &SigmaPoints<N, L>,
    x: &SVector<f64, N>,
    p: &SMatrix<f64, N, N>,
) -> Result<(), TestCaseError> {
    let s = cholesky(p)
        .map_err(|pivot| TestCaseError::fail(format!("test P not SPD (pivot {pivot}): {p}")))?;
    let pts = set.generate(x, &s);
    // The symmetric sets place their points without the dense product; same values, bit for bit.
    let mut dense = s * set.offsets();
    for mut col in dense.column_iter_mut() {
        col += x;
    }
    for (got, want) in pts.iter().zip(dense.iter()) {
        prop_assert!(
            got.to_bits() == want.to_bits() || (*got == 0.0 && *want == 0.0),
            "{:?}: point coordinate {got:e} differs from x + S D = {want:e}",
            set.kind()
        );
    }
    let wm = set.mean_weights();
    let wc = set.cov_weights();
    let kind = set.kind();

    let wsum = wm.sum();
    prop_assert!(
        (wsum - 1.0).abs() <= 1e-12 * wm.abs().sum().max(1.0),
        "{kind:?}: mean weights sum to {wsum}"
    );

    let mean = pts * wm;
    let mean_err = (mean - x).norm();
    prop_assert!(
        mean_err <= TOL * x.norm().max(1.0),
        "{kind:?}: mean error {mean_err:e} (x = {x}, mean = {mean})"
    );

    let mut cov = SMatrix::<f64, N, N>::zeros();
    for j in 0..L {
        let d = pts.column(j) - mean;
        cov += wc[j] * d * d.transpose();
    }
    let cov_err = (cov - p).norm();
    prop_assert!(
        cov_err <= TOL * p.norm(),
        "{kind:?}: covariance error {cov_err:e} (||P|| = {:e})",
        p.norm()
    );
    Ok(())
}

/// Parameters of one random case, shared by the four sets.
#[derive(Debug, Clone)]
struct SetParams {
    lambda: f64,
    alpha: f64,
    beta: f64,
    kappa: f64,
    w0: f64,
}

fn set_params() -> impl Strategy<Value = SetParams> {
    (
        0.5..=20.0f64,
        0.1..=1.0f64,
        0.0..=3.0f64,
        0.0..=3.0f64,
        0.05..=0.95f64,
    )
        .prop_map(|(lambda, alpha, beta, kappa, w0)| SetParams {
            lambda,
            alpha,
            beta,
            kappa,
            w0,
        })
}

/// AGM shape vector: magnitudes in [0.2, 3] with a random sign.
fn agm_v(n: usize) -> impl Strategy<Value = Vec<f64>> {
    proptest::collection::vec(
        (0.2..=3.0f64, any::<bool>()).prop_map(|(m, neg)| if neg { -m } else { m }),
        n,
    )
}

/// Runs all four sets for one `(x, P)`. `L2` = 2n+1, `L1` = n+1.
fn check_all_sets<const N: usize, const L2: usize, const L1: usize>(
    a: &[f64],
    x: &[f64],
    v: &[f64],
    prm: &SetParams,
) -> Result<(), TestCaseError> {
    let p = spd::<N>(a);
    let x = SVector::<f64, N>::from_column_slice(x);
    let v = SVector::<f64, N>::from_column_slice(v);

    let ahsm = SigmaPoints::<N, L2>::ahsm(prm.lambda).expect("valid lambda");
    prop_assert_eq!(ahsm.kind(), SigmaKind::Ahsm { lambda: prm.lambda });
    assert_reproduces(&ahsm, &x, &p)?;

    let scaled = SigmaPoints::<N, L2>::scaled(prm.alpha, prm.beta, prm.kappa).expect("valid");
    assert_reproduces(&scaled, &x, &p)?;

    let arm = SigmaPoints::<N, L1>::arm(prm.w0).expect("valid w0");
    assert_reproduces(&arm, &x, &p)?;

    let agm = SigmaPoints::<N, L1>::agm(&v).expect("valid v");
    assert_reproduces(&agm, &x, &p)?;
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn sets_reproduce_mean_and_covariance_n3(
        a in proptest::collection::vec(-3.0..=3.0f64, 9),
        x in proptest::collection::vec(-100.0..=100.0f64, 3),
        v in agm_v(3),
        prm in set_params(),
    ) {
        check_all_sets::<3, 7, 4>(&a, &x, &v, &prm)?;
    }

    #[test]
    fn sets_reproduce_mean_and_covariance_n5(
        a in proptest::collection::vec(-3.0..=3.0f64, 25),
        x in proptest::collection::vec(-100.0..=100.0f64, 5),
        v in agm_v(5),
        prm in set_params(),
    ) {
        check_all_sets::<5, 11, 6>(&a, &x, &v, &prm)?;
    }

    /// AHSM with `-n < lambda < 0` (negative centre weight) is still a valid set.
    #[test]
    fn ahsm_negative_lambda_reproduces_moments(
        a in proptest::collection::vec(-3.0..=3.0f64, 9),
        x in proptest::collection::vec(-100.0..=100.0f64, 3),
        lambda in -2.9..=-0.1f64,
    ) {
        let set = SigmaPoints::<3, 7>::ahsm(lambda).expect("n + lambda > 0");
        prop_assert!(set.mean_weights()[0] < 0.0);
        assert_reproduces(&set, &Vector3::from_column_slice(&x), &spd::<3>(&a))?;
    }
}

/// The scaled set's covariance weights differ from its mean weights only at the centre, by
/// `1 - alpha^2 + beta`; the other sets use one weight vector for both.
#[test]
fn scaled_set_centre_covariance_weight() {
    let (alpha, beta, kappa) = (0.5, 2.0, 1.0);
    let set = SigmaPoints::<3, 7>::scaled(alpha, beta, kappa).unwrap();
    let lambda = alpha * alpha * (3.0 + kappa) - 3.0;
    let wm = set.mean_weights();
    let wc = set.cov_weights();
    assert!((wm[0] - lambda / (3.0 + lambda)).abs() < 1e-15);
    assert!((wc[0] - wm[0] - (1.0 - alpha * alpha + beta)).abs() < 1e-15);
    for j in 1..7 {
        assert_eq!(wc[j], wm[j]);
        assert!((wm[j] - 0.5 / (3.0 + lambda)).abs() < 1e-15);
    }
    for set in [
        SigmaPoints::<3, 4>::arm(0.3).unwrap(),
        SigmaPoints::<3, 4>::agm(&Vector3::new(1.0, -2.0, 0.5)).unwrap(),
    ] {
        assert_eq!(set.mean_weights(), set.cov_weights());
    }
}

fn is_invalid(r: Result<impl std::fmt::Debug, ConfigError>, param: &str) -> bool {
    matches!(r, Err(ConfigError::InvalidParameter { name, .. }) if name == param)
}

#[test]
fn ahsm_rejects_lambda_at_or_below_minus_n() {
    assert!(is_invalid(SigmaPoints::<3, 7>::ahsm(-3.0), "lambda"));
    assert!(is_invalid(SigmaPoints::<3, 7>::ahsm(-3.5), "lambda"));
    assert!(is_invalid(SigmaPoints::<5, 11>::ahsm(-5.0), "lambda"));
    assert!(is_invalid(SigmaPoints::<3, 7>::ahsm(f64::NAN), "lambda"));
    assert!(is_invalid(
        SigmaPoints::<3, 7>::ahsm(f64::INFINITY),
        "lambda"
    ));
    // Just inside the admissible range.
    assert!(SigmaPoints::<3, 7>::ahsm(-2.9).is_ok());
    assert!(SigmaPoints::<5, 11>::ahsm(-4.9).is_ok());
}

#[test]
fn scaled_rejects_bad_parameters() {
    assert!(is_invalid(
        SigmaPoints::<3, 7>::scaled(0.0, 2.0, 0.0),
        "alpha"
    ));
    assert!(is_invalid(
        SigmaPoints::<3, 7>::scaled(-0.5, 2.0, 0.0),
        "alpha"
    ));
    assert!(is_invalid(
        SigmaPoints::<3, 7>::scaled(f64::NAN, 2.0, 0.0),
        "alpha"
    ));
    assert!(is_invalid(
        SigmaPoints::<3, 7>::scaled(0.5, f64::NAN, 0.0),
        "beta"
    ));
    // alpha^2 (n + kappa) <= 0.
    assert!(is_invalid(
        SigmaPoints::<3, 7>::scaled(0.5, 2.0, -3.0),
        "kappa"
    ));
    assert!(is_invalid(
        SigmaPoints::<3, 7>::scaled(0.5, 2.0, -4.0),
        "kappa"
    ));
    assert!(is_invalid(
        SigmaPoints::<3, 7>::scaled(0.5, 2.0, f64::NAN),
        "kappa"
    ));
    assert!(SigmaPoints::<3, 7>::scaled(0.5, 2.0, -2.5).is_ok());
}

#[test]
fn arm_rejects_w0_outside_open_unit_interval() {
    for w0 in [0.0, 1.0, -0.1, 1.5, f64::NAN, f64::INFINITY] {
        assert!(
            is_invalid(SigmaPoints::<3, 4>::arm(w0), "w0"),
            "w0 = {w0} accepted"
        );
    }
    assert!(SigmaPoints::<3, 4>::arm(1e-6).is_ok());
    assert!(SigmaPoints::<3, 4>::arm(1.0 - 1e-6).is_ok());
}

#[test]
fn agm_rejects_zero_or_non_finite_entries() {
    for bad in [0.0, -0.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        for i in 0..3 {
            let mut v = Vector3::new(1.0, -0.5, 2.0);
            v[i] = bad;
            assert!(
                is_invalid(SigmaPoints::<3, 4>::agm(&v), "v"),
                "v = {v:?} accepted"
            );
        }
    }
}

#[test]
fn constructors_reject_wrong_point_count() {
    fn is_count(r: Result<impl std::fmt::Debug, ConfigError>, n: usize, needed: usize) -> bool {
        matches!(r, Err(ConfigError::PointCount { n: rn, needed: rneed, .. }) if rn == n && rneed == needed)
    }
    let v3 = Vector3::new(1.0, 1.0, 1.0);
    // Symmetric sets need 2n+1 points.
    assert!(is_count(SigmaPoints::<3, 4>::ahsm(12.0), 3, 7));
    assert!(is_count(SigmaPoints::<3, 6>::ahsm(12.0), 3, 7));
    assert!(is_count(SigmaPoints::<3, 8>::ahsm(12.0), 3, 7));
    assert!(is_count(SigmaPoints::<3, 4>::scaled(0.5, 2.0, 0.0), 3, 7));
    assert!(is_count(SigmaPoints::<5, 7>::scaled(0.5, 2.0, 0.0), 5, 11));
    // Minimal sets need n+1 points.
    assert!(is_count(SigmaPoints::<3, 7>::arm(0.25), 3, 4));
    assert!(is_count(SigmaPoints::<3, 3>::arm(0.25), 3, 4));
    assert!(is_count(SigmaPoints::<3, 7>::agm(&v3), 3, 4));
    assert!(is_count(SigmaPoints::<3, 5>::agm(&v3), 3, 4));
    // The count is checked before the parameters: a bad parameter with a wrong L reports L.
    assert!(is_count(SigmaPoints::<3, 4>::ahsm(-10.0), 3, 7));
}
