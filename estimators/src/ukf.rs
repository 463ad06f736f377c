//! Unscented Kalman filter with additive process and measurement noise, generic over the
//! sigma-point set.

use nalgebra::{SMatrix, SVector};

use crate::correction::{check_covariance, check_input, check_measurement, correct};
use crate::error::{ConfigError, FilterError};
use crate::innovation::Innovation;
use crate::linalg::{all_finite, cholesky, symmetrize};
use crate::model::{ObservationModel, TransitionModel};
use crate::sigma_points::SigmaPoints;

/// An additive-noise UKF: `x[k+1] = f(x[k], u[k]) + w`, `y = h(x, u) + v`, `w ~ N(0, Q)`,
/// `v ~ N(0, R)`. `N` states, `M` measurements, `U` inputs, `L` sigma points.
///
/// `predict` propagates sigma points drawn from the posterior through `f`; `update` draws fresh
/// points from the prediction (so that `Q` is seen by the measurement) and propagates them
/// through `h`. Nothing is allocated on the heap.
#[derive(Debug, Clone)]
pub struct Ukf<T, O, const N: usize, const M: usize, const U: usize, const L: usize> {
    transition: T,
    observation: O,
    points: SigmaPoints<N, L>,
    x: SVector<f64, N>,
    p: SMatrix<f64, N, N>,
    q: SMatrix<f64, N, N>,
    r: SMatrix<f64, M, M>,
    /// Cholesky factor of `p` when it is known (after an update), saving the next predict a
    /// factorization.
    p_chol: Option<SMatrix<f64, N, N>>,
}

impl<T, O, const N: usize, const M: usize, const U: usize, const L: usize> Ukf<T, O, N, M, U, L>
where
    T: TransitionModel<N, U>,
    O: ObservationModel<N, M, U>,
{
    /// Builds a filter. `p0` and `r` must be symmetric positive definite, `q` positive semidefinite.
    pub fn new(
        transition: T,
        observation: O,
        points: SigmaPoints<N, L>,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        q: SMatrix<f64, N, N>,
        r: SMatrix<f64, M, M>,
    ) -> Result<Self, ConfigError> {
        check_covariance("P0", &p0, true)?;
        check_covariance("Q", &q, false)?;
        check_covariance("R", &r, true)?;
        if !all_finite(&x0) {
            return Err(ConfigError::InvalidParameter {
                name: "x0",
                value: f64::NAN,
                reason: "must be finite",
            });
        }
        Ok(Self {
            transition,
            observation,
            points,
            x: x0,
            p: p0,
            q,
            r,
            p_chol: None,
        })
    }

    /// Current state estimate.
    pub fn state(&self) -> &SVector<f64, N> {
        &self.x
    }

    /// Current state covariance.
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.p
    }

    /// Measurement noise covariance `R`.
    pub fn measurement_noise(&self) -> &SMatrix<f64, M, M> {
        &self.r
    }

    /// Replaces `R`, e.g. with an online estimate of the sensor noise. It must be symmetric
    /// positive definite; on error nothing changes.
    pub fn set_measurement_noise(&mut self, r: SMatrix<f64, M, M>) -> Result<(), ConfigError> {
        check_covariance("R", &r, true)?;
        self.r = r;
        Ok(())
    }

    /// The sigma-point set in use.
    pub fn sigma_points(&self) -> &SigmaPoints<N, L> {
        &self.points
    }

    /// The transition model (read-only).
    pub fn transition_model(&self) -> &T {
        &self.transition
    }

    /// The observation model (read-only).
    pub fn observation_model(&self) -> &O {
        &self.observation
    }

    /// Replaces the estimate, e.g. to re-initialize after a detected divergence. `p` must be
    /// symmetric positive definite and `x` finite; on error nothing changes.
    pub fn reset(&mut self, x: SVector<f64, N>, p: SMatrix<f64, N, N>) -> Result<(), ConfigError> {
        check_covariance("P", &p, true)?;
        if !all_finite(&x) {
            return Err(ConfigError::InvalidParameter {
                name: "x",
                value: f64::NAN,
                reason: "must be finite",
            });
        }
        self.x = x;
        self.p = p;
        self.p_chol = None;
        Ok(())
    }

    /// Time update with input `u`. On error the estimate is unchanged.
    pub fn predict(&mut self, u: &SVector<f64, U>) -> Result<(), FilterError> {
        check_input(u)?;
        let s = match self.p_chol {
            Some(l) => l,
            None => cholesky(&self.p).map_err(|pivot| FilterError::NotPositiveDefinite {
                which: "state covariance",
                pivot,
            })?,
        };
        let mut pts = self.points.generate(&self.x, &s);
        for j in 0..L {
            let mut xj = self.transition.transition(&pts.column(j).into_owned(), u);
            self.transition.constrain(&mut xj);
            pts.set_column(j, &xj);
        }
        let x = weighted_mean(&pts, self.points.mean_weights());
        let mut p = self.q;
        let wc = self.points.cov_weights();
        for j in 0..L {
            let d = pts.column(j) - x;
            add_weighted_outer(&mut p, wc[j], &d, &d);
        }
        symmetrize(&mut p);
        if !all_finite(&x) || !all_finite(&p) {
            return Err(FilterError::NonFiniteResult {
                which: "prediction",
            });
        }
        self.x = x;
        self.p = p;
        self.p_chol = None;
        Ok(())
    }

    /// Measurement update with every component of `y`.
    pub fn update(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
    ) -> Result<Innovation<M>, FilterError> {
        self.update_subset(y, u, &[true; M])
    }

    /// Measurement update using only the components of `y` flagged in `used` (a failed sensor is
    /// dropped, not fed garbage). On error the estimate is unchanged.
    pub fn update_subset(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
        used: &[bool; M],
    ) -> Result<Innovation<M>, FilterError> {
        check_input(u)?;
        check_measurement(y, used)?;
        let (y_pred, pyy, pxy) = match self.observation.affine_observation(u) {
            Some((h, d)) => {
                // A linear sensor: the sigma points would give these moments exactly.
                let pxy = self.p * h.transpose();
                (h * self.x + d, h * pxy + self.r, pxy)
            }
            None => self.unscented_measurement_moments(u)?,
        };
        let mut c = correct(&self.x, &self.p, y, &y_pred, pyy, pxy, used)?;
        self.transition.constrain(&mut c.x);
        self.x = c.x;
        self.p = c.p;
        self.p_chol = Some(c.p_chol);
        Ok(c.innovation)
    }

    /// `y_pred`, `Pyy` (with `R`) and `Pxy` from sigma points drawn from the prediction.
    #[allow(clippy::type_complexity)]
    fn unscented_measurement_moments(
        &self,
        u: &SVector<f64, U>,
    ) -> Result<(SVector<f64, M>, SMatrix<f64, M, M>, SMatrix<f64, N, M>), FilterError> {
        let s = cholesky(&self.p).map_err(|pivot| FilterError::NotPositiveDefinite {
            which: "state covariance",
            pivot,
        })?;
        let xs = self.points.generate(&self.x, &s);
        let mut ys = SMatrix::<f64, M, L>::zeros();
        for j in 0..L {
            ys.set_column(j, &self.observation.observe(&xs.column(j).into_owned(), u));
        }
        let y_pred = weighted_mean(&ys, self.points.mean_weights());
        let wc = self.points.cov_weights();
        let mut pyy = self.r;
        let mut pxy = SMatrix::<f64, N, M>::zeros();
        for j in 0..L {
            let dy = ys.column(j) - y_pred;
            let dx = xs.column(j) - self.x;
            add_weighted_outer(&mut pyy, wc[j], &dy, &dy);
            add_weighted_outer(&mut pxy, wc[j], &dx, &dy);
        }
        Ok((y_pred, pyy, pxy))
    }
}

/// `acc += (w a) b'`, element by element in the order nalgebra's `acc += w * a * b.transpose()`
/// uses (the same values, bit for bit), without the temporaries: this runs once per sigma point
/// and step, and the generic expression costs several times the arithmetic.
#[inline(always)]
fn add_weighted_outer<const R: usize, const C: usize>(
    acc: &mut SMatrix<f64, R, C>,
    w: f64,
    a: &SVector<f64, R>,
    b: &SVector<f64, C>,
) {
    for c in 0..C {
        for r in 0..R {
            acc[(r, c)] += (w * a[r]) * b[c];
        }
    }
}

/// `sum_j w_j col_j(pts)`, the columns taken in order.
#[inline(always)]
fn weighted_mean<const R: usize, const L: usize>(
    pts: &SMatrix<f64, R, L>,
    w: &SVector<f64, L>,
) -> SVector<f64, R> {
    let mut mean = SVector::<f64, R>::zeros();
    for j in 0..L {
        for r in 0..R {
            mean[r] += w[j] * pts[(r, j)];
        }
    }
    mean
}
