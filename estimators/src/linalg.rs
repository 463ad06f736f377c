//! Small dense linear algebra on fixed-size matrices that never allocates and reports failure
//! as a value (a filter must not panic on a bad covariance).

use nalgebra::{SMatrix, SVector};

/// Lower-triangular Cholesky factor `L` with `L L' = A` of a symmetric matrix.
///
/// Only the lower triangle of `a` is read. Returns the index of the failing pivot when `a` is not
/// positive definite (a pivot <= `tiny` times the largest diagonal entry, or not finite).
pub fn cholesky<const N: usize>(a: &SMatrix<f64, N, N>) -> Result<SMatrix<f64, N, N>, usize> {
    let mut l = SMatrix::<f64, N, N>::zeros();
    let scale = (0..N).map(|i| a[(i, i)].abs()).fold(0.0_f64, f64::max);
    let floor = scale * 1e-300_f64.max(f64::EPSILON * f64::EPSILON);
    for j in 0..N {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if !(d > floor) || !d.is_finite() {
            return Err(j);
        }
        let dj = d.sqrt();
        l[(j, j)] = dj;
        for i in (j + 1)..N {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / dj;
        }
    }
    Ok(l)
}

/// Solves `L L' X = B` for X given the Cholesky factor `L` (forward then back substitution).
pub fn cholesky_solve<const N: usize, const C: usize>(
    l: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, C>,
) -> SMatrix<f64, N, C> {
    let mut x = *b;
    for c in 0..C {
        for i in 0..N {
            let mut s = x[(i, c)];
            for k in 0..i {
                s -= l[(i, k)] * x[(k, c)];
            }
            x[(i, c)] = s / l[(i, i)];
        }
        for i in (0..N).rev() {
            let mut s = x[(i, c)];
            for k in (i + 1)..N {
                s -= l[(k, i)] * x[(k, c)];
            }
            x[(i, c)] = s / l[(i, i)];
        }
    }
    x
}

/// `ln det A` from the Cholesky factor of A.
pub fn cholesky_log_det<const N: usize>(l: &SMatrix<f64, N, N>) -> f64 {
    2.0 * (0..N).map(|i| l[(i, i)].ln()).sum::<f64>()
}

/// Replaces `a` by `(a + a') / 2`, removing the asymmetry that round-off adds at every step.
pub fn symmetrize<const N: usize>(a: &mut SMatrix<f64, N, N>) {
    for i in 0..N {
        for j in (i + 1)..N {
            let m = 0.5 * (a[(i, j)] + a[(j, i)]);
            a[(i, j)] = m;
            a[(j, i)] = m;
        }
    }
}

/// Eigen-decomposition `A = V diag(d) V'` of a symmetric matrix by cyclic Jacobi rotations.
///
/// Written here because nalgebra's `SymmetricEigen` needs dimension bounds that const-generic
/// code cannot state; for the small matrices of a filter Jacobi is accurate to round-off and
/// converges in a handful of sweeps. Returns `None` for non-finite input.
pub fn symmetric_eigen<const N: usize>(
    a: &SMatrix<f64, N, N>,
) -> Option<(SVector<f64, N>, SMatrix<f64, N, N>)> {
    if !all_finite(a) {
        return None;
    }
    let mut m = *a;
    symmetrize(&mut m);
    let mut v = SMatrix::<f64, N, N>::identity();
    for _sweep in 0..64 {
        let off: f64 = (0..N)
            .flat_map(|i| ((i + 1)..N).map(move |j| (i, j)))
            .map(|(i, j)| m[(i, j)] * m[(i, j)])
            .sum();
        let diag: f64 = (0..N).map(|i| m[(i, i)] * m[(i, i)]).sum();
        if off <= f64::EPSILON * f64::EPSILON * diag || off == 0.0 {
            break;
        }
        for p in 0..N {
            for q in (p + 1)..N {
                let apq = m[(p, q)];
                if apq == 0.0 {
                    continue;
                }
                let theta = (m[(q, q)] - m[(p, p)]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..N {
                    let mkp = m[(k, p)];
                    let mkq = m[(k, q)];
                    m[(k, p)] = c * mkp - s * mkq;
                    m[(k, q)] = s * mkp + c * mkq;
                }
                for k in 0..N {
                    let mpk = m[(p, k)];
                    let mqk = m[(q, k)];
                    m[(p, k)] = c * mpk - s * mqk;
                    m[(q, k)] = s * mpk + c * mqk;
                }
                for k in 0..N {
                    let vkp = v[(k, p)];
                    let vkq = v[(k, q)];
                    v[(k, p)] = c * vkp - s * vkq;
                    v[(k, q)] = s * vkp + c * vkq;
                }
            }
        }
    }
    Some((SVector::<f64, N>::from_fn(|i, _| m[(i, i)]), v))
}

/// Symmetric square root and inverse square root of a symmetric positive definite matrix via
/// its eigen-decomposition. Used once at construction by the ARM and AGM sigma-point sets.
pub fn sym_sqrt_and_inv_sqrt<const N: usize>(
    a: &SMatrix<f64, N, N>,
) -> Option<(SMatrix<f64, N, N>, SMatrix<f64, N, N>)> {
    let (d, v) = symmetric_eigen(a)?;
    if d.iter().any(|&x| !(x > 0.0)) {
        return None;
    }
    let s: SVector<f64, N> = d.map(f64::sqrt);
    let sqrt = v * SMatrix::<f64, N, N>::from_diagonal(&s) * v.transpose();
    let inv = v * SMatrix::<f64, N, N>::from_diagonal(&s.map(|x| 1.0 / x)) * v.transpose();
    Some((sqrt, inv))
}

/// True when every entry is finite.
#[inline]
pub fn all_finite<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> bool {
    // `v * 0` is 0 for a finite entry and NaN for an infinite or NaN one, so the sum is 0
    // exactly when all are finite; no early exit, so this runs branch-free on the filters'
    // per-step path.
    let mut zero = 0.0;
    for v in m.iter() {
        zero += v * 0.0;
    }
    zero == 0.0
}

/// Index and value of the first non-finite entry of a vector, if any.
pub fn first_non_finite<const R: usize>(v: &SVector<f64, R>) -> Option<(usize, f64)> {
    v.iter()
        .enumerate()
        .find(|(_, x)| !x.is_finite())
        .map(|(i, x)| (i, *x))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    #[test]
    fn cholesky_reconstructs_and_solves() {
        let a = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0);
        let l = cholesky(&a).expect("SPD");
        assert!((l * l.transpose() - a).norm() < 1e-12);
        let b = nalgebra::Vector3::new(1.0, -2.0, 0.5);
        let x = cholesky_solve(&l, &b);
        assert!((a * x - b).norm() < 1e-12);
        let det = a.determinant();
        assert!((cholesky_log_det(&l) - det.ln()).abs() < 1e-12);
    }

    #[test]
    fn cholesky_rejects_indefinite_and_nan() {
        let a = Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        assert_eq!(cholesky(&a), Err(1));
        let mut b = Matrix3::identity();
        b[(2, 2)] = f64::NAN;
        assert_eq!(cholesky(&b), Err(2));
        assert_eq!(cholesky(&Matrix3::<f64>::zeros()), Err(0));
    }

    #[test]
    fn jacobi_eigen_decomposes() {
        let a = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0);
        let (d, v) = symmetric_eigen(&a).expect("finite");
        let back = v * Matrix3::from_diagonal(&d) * v.transpose();
        assert!((back - a).norm() < 1e-12);
        assert!((v.transpose() * v - Matrix3::identity()).norm() < 1e-12);
        assert!((d.sum() - a.trace()).abs() < 1e-12);
    }

    #[test]
    fn symmetric_roots_are_inverse_of_each_other() {
        let a = Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0);
        let (s, si) = sym_sqrt_and_inv_sqrt(&a).expect("SPD");
        assert!((s * s - a).norm() < 1e-12);
        assert!((s * si - Matrix3::identity()).norm() < 1e-12);
    }
}
