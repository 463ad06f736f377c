//! The measurement-correction step shared by every Kalman-type filter: given the predicted
//! measurement, its covariance and the state-measurement cross-covariance, form the gain, the
//! corrected state and covariance, and the innovation statistics. Filters differ only in how
//! they obtain `y_pred`, `Pyy` and `Pxy` (linearization or sigma points).

use nalgebra::{SMatrix, SVector};

use crate::error::FilterError;
use crate::innovation::Innovation;
use crate::linalg::{all_finite, cholesky, cholesky_solve, first_non_finite, symmetrize};

/// Checks that `used` selects at least one component and that every selected measurement is finite.
pub(crate) fn check_measurement<const M: usize>(
    y: &SVector<f64, M>,
    used: &[bool; M],
) -> Result<(), FilterError> {
    if !used.iter().any(|&b| b) {
        return Err(FilterError::EmptySubset);
    }
    for i in 0..M {
        if used[i] && !y[i].is_finite() {
            return Err(FilterError::NonFiniteMeasurement {
                index: i,
                value: y[i],
            });
        }
    }
    Ok(())
}

/// Refuses a non-finite input vector.
pub(crate) fn check_input<const U: usize>(u: &SVector<f64, U>) -> Result<(), FilterError> {
    match first_non_finite(u) {
        Some((index, value)) => Err(FilterError::NonFiniteInput { index, value }),
        None => Ok(()),
    }
}

/// A corrected estimate, not yet committed to the filter.
pub(crate) struct Corrected<const N: usize, const M: usize> {
    pub x: SVector<f64, N>,
    pub p: SMatrix<f64, N, N>,
    /// Cholesky factor of `p`, computed to check it and kept so the next step can reuse it.
    pub p_chol: SMatrix<f64, N, N>,
    pub innovation: Innovation<M>,
}

/// Kalman correction restricted to the components flagged in `used`.
///
/// Excluded components get a zero residual, zero cross-covariance and a unit, uncorrelated
/// innovation variance, which makes their gain column exactly zero: the update is the same as one
/// built from the selected rows of `h` alone, without changing any matrix dimension.
#[allow(clippy::too_many_arguments)]
pub(crate) fn correct<const N: usize, const M: usize>(
    x_pred: &SVector<f64, N>,
    p_pred: &SMatrix<f64, N, N>,
    y: &SVector<f64, M>,
    y_pred: &SVector<f64, M>,
    mut pyy: SMatrix<f64, M, M>,
    mut pxy: SMatrix<f64, N, M>,
    used: &[bool; M],
) -> Result<Corrected<N, M>, FilterError> {
    let mut residual = y - y_pred;
    let mut dof = 0;
    for i in 0..M {
        if used[i] {
            dof += 1;
            continue;
        }
        residual[i] = 0.0;
        for j in 0..M {
            pyy[(i, j)] = 0.0;
            pyy[(j, i)] = 0.0;
        }
        pyy[(i, i)] = 1.0;
        for k in 0..N {
            pxy[(k, i)] = 0.0;
        }
    }
    symmetrize(&mut pyy);
    let l = cholesky(&pyy).map_err(|pivot| FilterError::NotPositiveDefinite {
        which: "innovation covariance",
        pivot,
    })?;
    // K' = Pyy^-1 Pxy'  (Pyy symmetric)
    let gain_t: SMatrix<f64, M, N> = cholesky_solve(&l, &pxy.transpose());
    let gain = gain_t.transpose();
    let x = x_pred + gain * residual;
    let mut p = p_pred - gain * pyy * gain_t;
    symmetrize(&mut p);
    if !all_finite(&x) {
        return Err(FilterError::NonFiniteResult { which: "state" });
    }
    if !all_finite(&p) {
        return Err(FilterError::NonFiniteResult {
            which: "covariance",
        });
    }
    let p_chol = cholesky(&p).map_err(|pivot| FilterError::NotPositiveDefinite {
        which: "posterior covariance",
        pivot,
    })?;
    let white = cholesky_solve(&l, &residual);
    let nis = residual.dot(&white);
    Ok(Corrected {
        x,
        p,
        p_chol,
        innovation: Innovation {
            residual,
            covariance: pyy,
            nis,
            dof,
        },
    })
}

/// Validates a covariance given at construction: finite, symmetric, and positive definite
/// (`strict`) or semidefinite (process noise may have zero rows, as the throttle's velocity does).
pub(crate) fn check_covariance<const N: usize>(
    name: &'static str,
    m: &SMatrix<f64, N, N>,
    strict: bool,
) -> Result<(), crate::error::ConfigError> {
    let kind = if strict { "definite" } else { "semidefinite" };
    let err = crate::error::ConfigError::NotPositive { name, kind };
    if !all_finite(m) {
        return Err(err);
    }
    let scale = m.amax().max(f64::MIN_POSITIVE);
    if (m - m.transpose()).amax() > 1e-12 * scale {
        return Err(err);
    }
    let Some((eigenvalues, _)) = crate::linalg::symmetric_eigen(m) else {
        return Err(err);
    };
    let min = eigenvalues.min();
    let ok = if strict {
        min > 0.0
    } else {
        min >= -1e-12 * scale
    };
    if ok {
        Ok(())
    } else {
        Err(err)
    }
}
