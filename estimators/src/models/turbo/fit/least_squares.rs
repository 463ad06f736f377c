//! Small least-squares solvers for the offline calibration: linear least squares by SVD with
//! column equilibration, and Levenberg-Marquardt with a forward-difference Jacobian.
//!
//! Both allocate (dynamic nalgebra matrices): the fit runs once, offline, on a few hundred
//! points and at most a handful of parameters, so clarity matters more than speed. Both are
//! deterministic: the same inputs give bit-identical results (no randomness, no threads), which
//! is what makes the generated parameter file byte-for-byte reproducible.

use nalgebra::{DMatrix, DVector};

/// Options of [`levenberg_marquardt`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    /// Most outer iterations (Jacobian evaluations).
    pub max_iterations: usize,
    /// Relative decrease of the cost, and relative step length, below which the iteration
    /// stops as converged (-).
    pub rel_tol: f64,
    /// Initial damping (relative to the diagonal of `J^T J`) (-).
    pub lambda0: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            max_iterations: 300,
            rel_tol: 1e-13,
            lambda0: 1e-3,
        }
    }
}

/// The result of [`levenberg_marquardt`].
#[derive(Debug, Clone, PartialEq)]
pub struct LmSolution {
    /// The parameters at the minimum.
    pub x: Vec<f64>,
    /// Root mean square of the residuals there (in the residuals' unit).
    pub residual_rms: f64,
    /// Outer iterations used.
    pub iterations: usize,
    /// Whether a stopping test (not the iteration limit) ended the iteration.
    pub converged: bool,
    /// One standard error per parameter, `sqrt(diag((J^T J)^-1) s^2)` with `s^2` the residual
    /// variance: a large value (relative to the parameter) marks a parameter the data hardly
    /// determine. NaN where `J^T J` is singular.
    pub std_errors: Vec<f64>,
}

/// Minimizes `sum r_i(x)^2` from `x0` by Levenberg-Marquardt with Marquardt's diagonal
/// scaling. `residuals` returns `None` for parameters it refuses (outside the physical set):
/// the step is then shortened, as for a step that increases the cost. `typical` gives each
/// parameter's magnitude for the finite-difference steps (`sqrt(eps) max(|x_j|, typical_j)`).
/// Returns `None` if the residuals at `x0` are refused or not finite.
pub fn levenberg_marquardt<F>(
    residuals: F,
    x0: &[f64],
    typical: &[f64],
    opts: &LmOptions,
) -> Option<LmSolution>
where
    F: Fn(&[f64]) -> Option<Vec<f64>>,
{
    let finite = |r: Option<Vec<f64>>| r.filter(|r| r.iter().all(|v| v.is_finite()));
    let n = x0.len();
    let mut x = x0.to_vec();
    let mut r = finite(residuals(&x))?;
    let m = r.len();
    let mut cost = sum_sq(&r);
    let mut lambda = opts.lambda0;
    let mut converged = false;
    let mut iterations = 0;
    let mut jac = jacobian(&residuals, &x, &r, typical)?;
    while iterations < opts.max_iterations {
        iterations += 1;
        let jt = jac.transpose();
        let a = &jt * &jac;
        let g = &jt * DVector::from_column_slice(&r);
        let diag: Vec<f64> = (0..n).map(|j| a[(j, j)].max(1e-300)).collect();
        let mut accepted = None;
        while lambda < 1e16 {
            let mut mat = a.clone();
            for (j, d) in diag.iter().enumerate() {
                mat[(j, j)] += lambda * d;
            }
            let Some(chol) = mat.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let delta = chol.solve(&(-&g));
            let x_new: Vec<f64> = x.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
            match finite(residuals(&x_new)) {
                Some(r_new) if sum_sq(&r_new) < cost => {
                    accepted = Some((x_new, r_new, delta.norm()));
                    lambda = (lambda / 10.0).max(1e-15);
                    break;
                }
                _ => lambda *= 10.0,
            }
        }
        let Some((x_new, r_new, step)) = accepted else {
            // No step decreases the cost: a (local) minimum to the precision of the arithmetic.
            converged = true;
            break;
        };
        let cost_new = sum_sq(&r_new);
        let small_decrease = cost - cost_new <= opts.rel_tol * cost;
        let x_norm = x_new.iter().map(|v| v * v).sum::<f64>().sqrt();
        let small_step = step <= opts.rel_tol.sqrt() * (x_norm + opts.rel_tol.sqrt());
        x = x_new;
        r = r_new;
        cost = cost_new;
        if small_decrease || small_step || cost == 0.0 {
            converged = true;
            break;
        }
        jac = jacobian(&residuals, &x, &r, typical)?;
    }
    let jac = jacobian(&residuals, &x, &r, typical).unwrap_or(jac);
    let dof = m.saturating_sub(n).max(1) as f64;
    let s2 = cost / dof;
    let std_errors = match (jac.transpose() * &jac).try_inverse() {
        Some(inv) => (0..n).map(|j| (inv[(j, j)] * s2).max(0.0).sqrt()).collect(),
        None => vec![f64::NAN; n],
    };
    Some(LmSolution {
        residual_rms: (cost / m.max(1) as f64).sqrt(),
        x,
        iterations,
        converged,
        std_errors,
    })
}

/// Forward-difference Jacobian (m x n) at `x` with residuals `r`; `None` if a perturbed point
/// is refused in both directions.
fn jacobian<F>(residuals: &F, x: &[f64], r: &[f64], typical: &[f64]) -> Option<DMatrix<f64>>
where
    F: Fn(&[f64]) -> Option<Vec<f64>>,
{
    let (m, n) = (r.len(), x.len());
    let mut jac = DMatrix::zeros(m, n);
    for j in 0..n {
        let h = f64::EPSILON.sqrt() * x[j].abs().max(typical.get(j).copied().unwrap_or(1.0));
        let mut xp = x.to_vec();
        xp[j] = x[j] + h;
        let rp = match residuals(&xp).filter(|v| v.len() == m && v.iter().all(|v| v.is_finite())) {
            Some(rp) => rp,
            None => {
                xp[j] = x[j] - h;
                residuals(&xp).filter(|v| v.len() == m && v.iter().all(|v| v.is_finite()))?
            }
        };
        let dx = xp[j] - x[j];
        for i in 0..m {
            jac[(i, j)] = (rp[i] - r[i]) / dx;
        }
    }
    Some(jac)
}

fn sum_sq(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// The least-squares solution of `a x = b` (minimum norm if rank deficient), by SVD after
/// scaling each column to unit norm: the volumetric-efficiency polynomial's columns span
/// `p^0 .. p^4` with `p` up to 200 kPa, twelve decades, which unscaled would lose the small
/// singular values to rounding. `None` if a column is all zero, a value is not finite or the
/// SVD fails.
pub fn linear_least_squares(a: &DMatrix<f64>, b: &DVector<f64>) -> Option<DVector<f64>> {
    if a.nrows() != b.len() || a.iter().chain(b.iter()).any(|v| !v.is_finite()) {
        return None;
    }
    let scales: Vec<f64> = a.column_iter().map(|c| c.norm()).collect();
    if scales.iter().any(|s| !(*s > 0.0)) {
        return None;
    }
    let mut scaled = a.clone();
    for (j, s) in scales.iter().enumerate() {
        scaled.column_mut(j).scale_mut(1.0 / s);
    }
    let svd = scaled.svd(true, true);
    let y = svd.solve(b, 1e-14).ok()?;
    Some(DVector::from_iterator(
        y.len(),
        y.iter().zip(scales.iter()).map(|(v, s)| v / s),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_least_squares_recovers_a_polynomial_over_twelve_decades() {
        // y = 1e-9 p^4 - 5e-7 p^3 + 1e-4 p^2 - 6e-3 p + 0.9 over p = 20 .. 200, exactly.
        let c = [1e-9, -5e-7, 1e-4, -6e-3, 0.9];
        let ps: Vec<f64> = (0..40)
            .map(|i| 20.0 + 180.0 * f64::from(i) / 39.0)
            .collect();
        let a = DMatrix::from_fn(ps.len(), 5, |i, j| ps[i].powi(4 - j as i32));
        let b = DVector::from_iterator(
            ps.len(),
            ps.iter().map(|p| c.iter().fold(0.0, |acc, k| acc * p + k)),
        );
        let x = linear_least_squares(&a, &b).expect("solves");
        for (got, want) in x.iter().zip(c) {
            assert!(
                (got - want).abs() <= 1e-7 * want.abs(),
                "{got:e} vs {want:e}"
            );
        }
        assert!(linear_least_squares(&DMatrix::zeros(3, 1), &DVector::zeros(3)).is_none());
    }

    #[test]
    fn levenberg_marquardt_finds_the_rosenbrock_minimum() {
        // r = (10 (x1 - x0^2), 1 - x0): minimum 0 at (1, 1), from the classic start (-1.2, 1).
        let f = |x: &[f64]| Some(vec![10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]]);
        let s =
            levenberg_marquardt(f, &[-1.2, 1.0], &[1.0, 1.0], &LmOptions::default()).expect("runs");
        assert!(s.converged);
        assert!(
            (s.x[0] - 1.0).abs() < 1e-6 && (s.x[1] - 1.0).abs() < 1e-6,
            "{:?}",
            s.x
        );
        assert!(s.residual_rms < 1e-6);
    }

    #[test]
    fn levenberg_marquardt_fits_an_exponential_and_its_standard_errors() {
        // y = 2 exp(-0.7 t) + 0.3 with a deterministic +-1e-3 perturbation: the fit recovers
        // the parameters to about the perturbation and its standard errors are of that order.
        let ts: Vec<f64> = (0..50).map(|i| 0.1 * f64::from(i)).collect();
        let ys: Vec<f64> = ts
            .iter()
            .enumerate()
            .map(|(i, t)| 2.0 * (-0.7 * t).exp() + 0.3 + if i % 2 == 0 { 1e-3 } else { -1e-3 })
            .collect();
        let f = |x: &[f64]| {
            Some(
                ts.iter()
                    .zip(&ys)
                    .map(|(t, y)| x[0] * (-x[1] * t).exp() + x[2] - y)
                    .collect(),
            )
        };
        let s = levenberg_marquardt(f, &[1.0, 0.2, 0.0], &[1.0; 3], &LmOptions::default())
            .expect("runs");
        assert!(s.converged);
        for (got, want) in s.x.iter().zip([2.0, 0.7, 0.3]) {
            assert!((got - want).abs() < 5e-3, "{:?}", s.x);
        }
        assert!((s.residual_rms - 1e-3).abs() < 2e-4, "{}", s.residual_rms);
        assert!(
            s.std_errors.iter().all(|e| *e > 0.0 && *e < 5e-3),
            "{:?}",
            s.std_errors
        );
    }

    #[test]
    fn refused_parameters_shorten_the_step() {
        // Minimum of (x - 3)^2 with x > 0 enforced by refusing x <= 0: from 0.1 the first full
        // Gauss-Newton step is fine; from a start where it overshoots below 0 it is damped.
        let f = |x: &[f64]| (x[0] > 0.0).then(|| vec![x[0].ln() - 3f64.ln()]);
        let s = levenberg_marquardt(f, &[0.01], &[1.0], &LmOptions::default()).expect("runs");
        assert!((s.x[0] - 3.0).abs() < 1e-6, "{:?}", s.x);
        assert!(levenberg_marquardt(f, &[-1.0], &[1.0], &LmOptions::default()).is_none());
    }
}
