//! Sigma-point sets for the unscented transform.
//!
//! Every set here is stored the same way: a constant matrix `D` (n x L) of offsets in whitened
//! coordinates plus mean and covariance weights. For a state with mean `x` and any square root
//! `S` of its covariance (`S S' = P`) the points are `X_j = x + S d_j`. A set reproduces `x` and
//! `P` exactly when `sum_j wm_j d_j = 0`, `sum_j wm_j = 1` and `sum_j wc_j d_j d_j' = I`; the
//! constructors compute `D` so that these hold, which the tests check for every set.
//!
//! The sets are those of the throttle paper (shared/REFERENCE.md §1):
//! - AHSM, 2n+1 points, parameter lambda (Julier's symmetric set);
//! - ARM, n+1 points, parameter w0 (the "rho-minimal" simplex-like set);
//! - AGM, n+1 points, parameter vector v;
//!
//! plus the scaled set (alpha, beta, kappa) used by most libraries, whose covariance weight of
//! the centre point differs from its mean weight.

use nalgebra::{SMatrix, SVector};

use crate::error::ConfigError;
use crate::linalg::sym_sqrt_and_inv_sqrt;

/// Which family a set belongs to, with its parameters (for reports and configuration).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SigmaKind {
    /// Symmetric 2n+1 set with weight `lambda/(n+lambda)` on the centre.
    Ahsm { lambda: f64 },
    /// n+1 point set with centre weight `w0`.
    Arm { w0: f64 },
    /// n+1 point set shaped by a vector `v` (the vector itself stays with the caller's settings).
    Agm,
    /// Scaled symmetric set (Wan and van der Merwe).
    Scaled { alpha: f64, beta: f64, kappa: f64 },
}

impl SigmaKind {
    /// Short label used in tables.
    pub fn label(&self) -> &'static str {
        match self {
            SigmaKind::Ahsm { .. } => "AHSM",
            SigmaKind::Arm { .. } => "ARM",
            SigmaKind::Agm => "AGM",
            SigmaKind::Scaled { .. } => "scaled",
        }
    }
}

/// A sigma-point set for an n-dimensional state with `L` points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SigmaPoints<const N: usize, const L: usize> {
    offsets: SMatrix<f64, N, L>,
    mean_weights: SVector<f64, L>,
    cov_weights: SVector<f64, L>,
    kind: SigmaKind,
    /// `c` when the offsets are `[0, c I, -c I]` (AHSM and scaled sets): the points are then
    /// `x` and `x +- c col_i(S)`, placed without the dense product `S D` (same values, bit for
    /// bit, at a fifth of the cost).
    symmetric_scale: Option<f64>,
}

fn check_count(
    set: &'static str,
    n: usize,
    needed: usize,
    stored: usize,
) -> Result<(), ConfigError> {
    if needed != stored {
        return Err(ConfigError::PointCount {
            set,
            n,
            needed,
            stored,
        });
    }
    Ok(())
}

impl<const N: usize, const L: usize> SigmaPoints<N, L> {
    /// AHSM: `w0 = lambda/(n+lambda)`, `wi = 1/(2(n+lambda))`, points `x +- col_i(sqrt((n+lambda)P))`.
    /// Needs `L = 2n+1` and `n + lambda > 0`.
    pub fn ahsm(lambda: f64) -> Result<Self, ConfigError> {
        check_count("AHSM", N, 2 * N + 1, L)?;
        let n = N as f64;
        if !(n + lambda > 0.0) || !lambda.is_finite() {
            return Err(ConfigError::InvalidParameter {
                name: "lambda",
                value: lambda,
                reason: "n + lambda must be positive",
            });
        }
        let (offsets, mut w) = symmetric_offsets::<N, L>(n + lambda);
        w[0] = lambda / (n + lambda);
        Ok(Self {
            offsets,
            mean_weights: w,
            cov_weights: w,
            kind: SigmaKind::Ahsm { lambda },
            symmetric_scale: Some((n + lambda).sqrt()),
        })
    }

    /// Scaled set: `lambda = alpha^2 (n + kappa) - n`, mean weights as AHSM(lambda), covariance
    /// weight of the centre `lambda/(n+lambda) + 1 - alpha^2 + beta`.
    pub fn scaled(alpha: f64, beta: f64, kappa: f64) -> Result<Self, ConfigError> {
        check_count("scaled", N, 2 * N + 1, L)?;
        let n = N as f64;
        if !(alpha > 0.0) || !alpha.is_finite() {
            return Err(ConfigError::InvalidParameter {
                name: "alpha",
                value: alpha,
                reason: "must be positive",
            });
        }
        if !beta.is_finite() {
            return Err(ConfigError::InvalidParameter {
                name: "beta",
                value: beta,
                reason: "must be finite",
            });
        }
        let lambda = alpha * alpha * (n + kappa) - n;
        if !(n + lambda > 0.0) || !kappa.is_finite() {
            return Err(ConfigError::InvalidParameter {
                name: "kappa",
                value: kappa,
                reason: "alpha^2 (n + kappa) must be positive",
            });
        }
        let (offsets, mut wm) = symmetric_offsets::<N, L>(n + lambda);
        wm[0] = lambda / (n + lambda);
        let mut wc = wm;
        wc[0] += 1.0 - alpha * alpha + beta;
        Ok(Self {
            offsets,
            mean_weights: wm,
            cov_weights: wc,
            kind: SigmaKind::Scaled { alpha, beta, kappa },
            symmetric_scale: Some((n + lambda).sqrt()),
        })
    }

    /// ARM with centre weight `0 < w0 < 1`: `rho = sqrt((1-w0)/n)`, `C = (I - rho^2 J)^(1/2)`,
    /// `wi = diag(w0 rho^2 C^-1 J C^-T)_i` (which equals rho^2), `X0 = x - S rho 1 / sqrt(w0)`,
    /// `Xi = x + col_i(S C W^(-1/2))`. Needs `L = n+1`.
    pub fn arm(w0: f64) -> Result<Self, ConfigError> {
        check_count("ARM", N, N + 1, L)?;
        if !(w0 > 0.0 && w0 < 1.0) {
            return Err(ConfigError::InvalidParameter {
                name: "w0",
                value: w0,
                reason: "must lie in (0, 1)",
            });
        }
        let n = N as f64;
        let rho = ((1.0 - w0) / n).sqrt();
        let ones = SMatrix::<f64, N, N>::from_element(1.0);
        let inner = SMatrix::<f64, N, N>::identity() - ones * (rho * rho);
        let (c, c_inv) = sym_sqrt_and_inv_sqrt(&inner).ok_or(ConfigError::InvalidParameter {
            name: "w0",
            value: w0,
            reason: "I - rho^2 J is not positive definite",
        })?;
        let wmat = c_inv * ones * c_inv.transpose() * (w0 * rho * rho);
        let mut w = SVector::<f64, L>::zeros();
        w[0] = w0;
        let mut offsets = SMatrix::<f64, N, L>::zeros();
        for i in 0..N {
            let wi = wmat[(i, i)];
            w[i + 1] = wi;
            offsets.set_column(i + 1, &(c.column(i) / wi.sqrt()));
            offsets[(i, 0)] = -rho / w0.sqrt();
        }
        Ok(Self {
            offsets,
            mean_weights: w,
            cov_weights: w,
            kind: SigmaKind::Arm { w0 },
            symmetric_scale: None,
        })
    }

    /// AGM with shape vector `v` (all entries non-zero): `w0 = 1/(1 + |v|^2)`, `wi = w0 vi^2`,
    /// `E = sqrt(P/w0) (I + v v')^(-1/2) diag(v)^-1`, `X0 = x - E w / w0`, `Xi = x + col_i(E)`.
    /// Needs `L = n+1`.
    pub fn agm(v: &SVector<f64, N>) -> Result<Self, ConfigError> {
        check_count("AGM", N, N + 1, L)?;
        if let Some(&bad) = v.iter().find(|x| !(x.abs() > 0.0) || !x.is_finite()) {
            return Err(ConfigError::InvalidParameter {
                name: "v",
                value: bad,
                reason: "every entry must be finite and non-zero",
            });
        }
        let w0 = 1.0 / (1.0 + v.norm_squared());
        let m = SMatrix::<f64, N, N>::identity() + v * v.transpose();
        let (_, m_inv_sqrt) = sym_sqrt_and_inv_sqrt(&m).ok_or(ConfigError::InvalidParameter {
            name: "v",
            value: v[0],
            reason: "I + v v' is not positive definite",
        })?;
        let dinv = SMatrix::<f64, N, N>::from_diagonal(&v.map(|x| 1.0 / x));
        let t = m_inv_sqrt * dinv / w0.sqrt();
        let wi: SVector<f64, N> = v.map(|x| w0 * x * x);
        let e = -(t * wi) / w0;
        let mut w = SVector::<f64, L>::zeros();
        let mut offsets = SMatrix::<f64, N, L>::zeros();
        w[0] = w0;
        offsets.set_column(0, &e);
        for i in 0..N {
            w[i + 1] = wi[i];
            offsets.set_column(i + 1, &t.column(i));
        }
        Ok(Self {
            offsets,
            mean_weights: w,
            cov_weights: w,
            kind: SigmaKind::Agm,
            symmetric_scale: None,
        })
    }

    /// Places the points for mean `x` and covariance square root `s` (`s s' = P`).
    #[inline]
    pub fn generate(&self, x: &SVector<f64, N>, s: &SMatrix<f64, N, N>) -> SMatrix<f64, N, L> {
        if let Some(c) = self.symmetric_scale {
            let mut pts = SMatrix::<f64, N, L>::zeros();
            for r in 0..N {
                pts[(r, 0)] = x[r];
            }
            for i in 0..N {
                for r in 0..N {
                    let d = s[(r, i)] * c;
                    pts[(r, 1 + i)] = x[r] + d;
                    pts[(r, 1 + N + i)] = x[r] - d;
                }
            }
            return pts;
        }
        let mut pts = s * self.offsets;
        for mut col in pts.column_iter_mut() {
            col += x;
        }
        pts
    }

    /// Weights for the mean.
    pub fn mean_weights(&self) -> &SVector<f64, L> {
        &self.mean_weights
    }

    /// Weights for covariances.
    pub fn cov_weights(&self) -> &SVector<f64, L> {
        &self.cov_weights
    }

    /// Offsets `D` in whitened coordinates.
    pub fn offsets(&self) -> &SMatrix<f64, N, L> {
        &self.offsets
    }

    /// Family and parameters.
    pub fn kind(&self) -> SigmaKind {
        self.kind
    }
}

/// Offsets `[0, c I, -c I]` with `c = sqrt(n + lambda)` and the non-centre weights `1/(2(n+lambda))`.
fn symmetric_offsets<const N: usize, const L: usize>(
    n_plus_lambda: f64,
) -> (SMatrix<f64, N, L>, SVector<f64, L>) {
    let c = n_plus_lambda.sqrt();
    let mut offsets = SMatrix::<f64, N, L>::zeros();
    let mut w = SVector::<f64, L>::from_element(0.5 / n_plus_lambda);
    w[0] = 0.0;
    for i in 0..N {
        offsets[(i, i + 1)] = c;
        offsets[(i, i + 1 + N)] = -c;
    }
    (offsets, w)
}
