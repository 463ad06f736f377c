//! Fusion of two sensors' local Kalman filters into one master estimate (REFERENCE §2).
//!
//! Two architectures over the same plant, each with one local filter per sensor:
//!
//! - [`DecentralizedPair`]: the paper's decentralized EKF. Two local [`Ekf`]s run on their own
//!   sensor, completely independently (no feedback from the master), and the master fuses them
//!   in information form, `P_m^-1 = P_1^-1 + P_2^-1`, `P_m^-1 x_m = P_1^-1 x_1 + P_2^-1 x_2`.
//!   Both local estimates contain the same prediction (same model, same process noise), so this
//!   fusion counts the common prior information twice and **its covariance is optimistic**: the
//!   fused `P_m` is smaller than the error it claims to describe (state NEES above `N`). It is
//!   kept as the paper defines it so that its inconsistency can be reported as it is.
//! - [`FederatedFilter`]: Carlson's federated filter in fusion-reset mode with
//!   information-sharing factors `beta_1 + beta_2 = 1`. Each step the locals are reset from
//!   the master (`x_i = x_m`, `P_i = P_m / beta_i`, `Q_i = Q / beta_i`), predict and update with
//!   their own sensor, and the master fuses them in information form. The common prediction is
//!   split between the locals instead of being counted twice; with a linear model this is
//!   exactly the centralized Kalman filter that processes both sensors at once (and with
//!   nonlinear models exactly the centralized EKF, since both locals linearize at the same
//!   predicted state).
//!
//! Both are fixed-size and allocate nothing per step; every error is a [`FilterError`] value
//! after which the filter is as it was before the call. Inversions use the Cholesky routines
//! of [`crate::linalg`]. The information-form fusion of two estimates is computed in its
//! equivalent covariance form, `P = P_1 - P_1 (P_1 + P_2)^-1 P_1`, `x = x_1 + P_1 (P_1 +
//! P_2)^-1 (x_2 - x_1)` (one `N x N` factorization instead of three inverses), and the
//! federated filter's joint NIS by the chain rule with `M`-sized factorizations only.

use nalgebra::{SMatrix, SVector};

use crate::correction::{check_covariance, check_input, check_measurement, correct};
use crate::ekf::Ekf;
use crate::error::{ConfigError, FilterError};
use crate::innovation::Innovation;
use crate::linalg::{all_finite, cholesky, cholesky_solve, symmetrize};
use crate::model::{ObservationModel, TransitionModel};

/// Noise covariances of a two-sensor fusion: process noise `q` (positive semidefinite) and the
/// measurement noise `r1`, `r2` of sensor 1 and 2 (positive definite). The two sensors' noises
/// are assumed independent of each other.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FusionNoise<const N: usize, const M1: usize, const M2: usize> {
    /// Process noise covariance of the (shared) transition model.
    pub q: SMatrix<f64, N, N>,
    /// Measurement noise covariance of sensor 1.
    pub r1: SMatrix<f64, M1, M1>,
    /// Measurement noise covariance of sensor 2.
    pub r2: SMatrix<f64, M2, M2>,
}

/// What one fusion step produced: the master estimate and each local filter's innovation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FusedStep<const N: usize, const M1: usize, const M2: usize> {
    /// Fused (master) state estimate.
    pub x: SVector<f64, N>,
    /// Fused (master) covariance.
    pub p: SMatrix<f64, N, N>,
    /// Innovation of the local filter of sensor 1 (against that filter's own prediction).
    pub local1: Innovation<M1>,
    /// Innovation of the local filter of sensor 2.
    pub local2: Innovation<M2>,
    /// Normalized innovation squared of both sensors together; see the filters' `step` for
    /// what it is in each architecture. Its mean is `dof` for a consistent filter.
    pub nis: f64,
    /// Degrees of freedom of `nis`, `M1 + M2`.
    pub dof: usize,
}

/// Fusion of two estimates `(x1, P1)`, `(x2, P2)` as in information form, `P^-1 = P1^-1 +
/// P2^-1`, `P^-1 x = P1^-1 x1 + P2^-1 x2`, computed in the equivalent covariance form
///
/// ```text
/// G = (P1 + P2)^-1 P1,   P = P1 - P1 G,   x = x1 + G' (x2 - x1)
/// ```
///
/// (`P1 (P1 + P2)^-1 = G'` since both are symmetric): one Cholesky factor of `P1 + P2` and one
/// solve with `N` right-hand sides instead of three `N x N` inverses. Both covariances must be
/// positive definite; the callers guarantee it (the local posteriors passed `correct`'s
/// Cholesky check, the initial ones the construction check).
fn fuse_pair<const N: usize>(
    x1: &SVector<f64, N>,
    p1: &SMatrix<f64, N, N>,
    x2: &SVector<f64, N>,
    p2: &SMatrix<f64, N, N>,
) -> Result<(SVector<f64, N>, SMatrix<f64, N, N>), FilterError> {
    let mut sum = p1 + p2;
    symmetrize(&mut sum);
    let l = cholesky(&sum).map_err(|pivot| FilterError::NotPositiveDefinite {
        which: "sum of the local covariances",
        pivot,
    })?;
    let g = cholesky_solve(&l, p1);
    let mut p = p1 - p1 * g;
    symmetrize(&mut p);
    let x = x1 + g.tr_mul(&(x2 - x1));
    if !all_finite(&x) {
        return Err(FilterError::NonFiniteResult {
            which: "fused state",
        });
    }
    if !all_finite(&p) {
        return Err(FilterError::NonFiniteResult {
            which: "fused covariance",
        });
    }
    Ok((x, p))
}

/// Normalized innovation squared of two sensors together against one prediction `(Pp, H1,
/// H2)`, `r' S^-1 r` with `r = [r1; r2]`, `S = H Pp H' + blockdiag(R1, R2)`, by the chain rule
/// (the sequential update, without its `N x N` covariance updates):
///
/// ```text
/// S1   = H1 Pp H1' + R1,                       v1 = S1^-1 r1,   NIS1 = r1' v1
/// C21  = H2 Pp H1',                            e2 = r2 - C21 v1  (= r2 - H2 K1 r1)
/// S2|1 = H2 Pp H2' + R2 - C21 S1^-1 C21',      NIS2 = e2' S2|1^-1 e2
/// ```
///
/// Only `M`-sized factorizations and `N x M` products. Errors when `S1` or `S2|1` is not
/// positive definite (the sequential update's innovation covariances).
#[allow(clippy::too_many_arguments)]
fn joint_nis<const N: usize, const M1: usize, const M2: usize>(
    pp: &SMatrix<f64, N, N>,
    h1: &SMatrix<f64, M1, N>,
    h2: &SMatrix<f64, M2, N>,
    r1: &SVector<f64, M1>,
    r2: &SVector<f64, M2>,
    noise1: &SMatrix<f64, M1, M1>,
    noise2: &SMatrix<f64, M2, M2>,
) -> Result<f64, FilterError> {
    let not_pd = |pivot| FilterError::NotPositiveDefinite {
        which: "innovation covariance",
        pivot,
    };
    let ph1 = pp * h1.transpose();
    let ph2 = pp * h2.transpose();
    let mut s1 = h1 * ph1 + noise1;
    symmetrize(&mut s1);
    let l1 = cholesky(&s1).map_err(not_pd)?;
    let v1 = cholesky_solve(&l1, r1);
    let c21 = h2 * ph1;
    let e2 = r2 - c21 * v1;
    // C21 S1^-1 C21' with S1^-1 C21' from one solve.
    let w = cholesky_solve(&l1, &c21.transpose());
    let mut s2 = h2 * ph2 + noise2 - c21 * w;
    symmetrize(&mut s2);
    let l2 = cholesky(&s2).map_err(not_pd)?;
    let nis = r1.dot(&v1) + e2.dot(&cholesky_solve(&l2, &e2));
    if !nis.is_finite() {
        return Err(FilterError::NonFiniteResult { which: "joint NIS" });
    }
    Ok(nis)
}

fn check_finite_state<const N: usize>(x: &SVector<f64, N>) -> Result<(), ConfigError> {
    if all_finite(x) {
        Ok(())
    } else {
        Err(ConfigError::InvalidParameter {
            name: "x0",
            value: f64::NAN,
            reason: "must be finite",
        })
    }
}

/// The paper's decentralized EKF: one independent local [`Ekf`] per sensor on the same
/// transition model, and a master that fuses them as `P_m^-1 = P_1^-1 + P_2^-1`,
/// `P_m^-1 x_m = P_1^-1 x_1 + P_2^-1 x_2`.
///
/// The locals are never reset from the master, as in the paper. Because both carry the same
/// prediction (prior and process noise), the master counts that information twice: the fused
/// covariance is **optimistic** (smaller than the true error covariance, and smaller than the
/// centralized filter's). Use [`FederatedFilter`] for a consistent fusion.
#[derive(Debug, Clone)]
pub struct DecentralizedPair<
    T,
    O1,
    O2,
    const N: usize,
    const M1: usize,
    const M2: usize,
    const U: usize,
> {
    local1: Ekf<T, O1, N, M1, U>,
    local2: Ekf<T, O2, N, M2, U>,
    x: SVector<f64, N>,
    p: SMatrix<f64, N, N>,
}

impl<T, O1, O2, const N: usize, const M1: usize, const M2: usize, const U: usize>
    DecentralizedPair<T, O1, O2, N, M1, M2, U>
where
    T: TransitionModel<N, U>,
    O1: ObservationModel<N, M1, U>,
    O2: ObservationModel<N, M2, U>,
{
    /// Builds both local filters from the same initial estimate `x0`, `p0` and process noise.
    /// The initial master estimate is the fusion of the two locals (so already `p0 / 2`).
    pub fn new(
        transition: T,
        observation1: O1,
        observation2: O2,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        noise: FusionNoise<N, M1, M2>,
    ) -> Result<Self, ConfigError>
    where
        T: Clone,
    {
        let local1 = Ekf::new(transition.clone(), observation1, x0, p0, noise.q, noise.r1)?;
        let local2 = Ekf::new(transition, observation2, x0, p0, noise.q, noise.r2)?;
        Self::from_locals(local1, local2)
    }

    /// Wraps two already built local filters (which may differ in their process noise).
    pub fn from_locals(
        local1: Ekf<T, O1, N, M1, U>,
        local2: Ekf<T, O2, N, M2, U>,
    ) -> Result<Self, ConfigError> {
        let mut pair = Self {
            local1,
            local2,
            x: SVector::zeros(),
            p: SMatrix::identity(),
        };
        let (x, p) = pair.fuse().map_err(|_| ConfigError::NotPositive {
            name: "P0",
            kind: "definite",
        })?;
        pair.x = x;
        pair.p = p;
        Ok(pair)
    }

    /// The master fusion of the current local estimates (information form, naive: the common
    /// prediction is counted twice, so the covariance is optimistic).
    pub fn fuse(&self) -> Result<(SVector<f64, N>, SMatrix<f64, N, N>), FilterError> {
        fuse_pair(
            self.local1.state(),
            self.local1.covariance(),
            self.local2.state(),
            self.local2.covariance(),
        )
    }

    /// One step: both locals predict with `u` and update with their own measurement, then the
    /// master fuses them. `nis` in the result is `local1.nis + local2.nis`: each local filter
    /// is a proper Kalman filter, so its mean is `M1 + M2` even though the *fused* covariance
    /// is optimistic (the two local innovations are correlated through the shared process
    /// noise, so the sum is not chi-square; the fused estimate's inconsistency shows in its
    /// state error, not here).
    ///
    /// Inputs and measurements are checked before anything changes; on any error both locals
    /// and the master are left as they were.
    pub fn step(
        &mut self,
        u: &SVector<f64, U>,
        y1: &SVector<f64, M1>,
        y2: &SVector<f64, M2>,
    ) -> Result<FusedStep<N, M1, M2>, FilterError> {
        check_input(u)?;
        check_measurement(y1, &[true; M1])?;
        check_measurement(y2, &[true; M2])?;
        let step = self.rolled_back_on_error(|pair| pair.try_step(u, y1, y2))?;
        self.x = step.x;
        self.p = step.p;
        Ok(step)
    }

    /// Runs `f` on the pair; if it fails, both locals are put back as they were (the master is
    /// only written by the callers, after success).
    fn rolled_back_on_error<R>(
        &mut self,
        f: impl FnOnce(&mut Self) -> Result<R, FilterError>,
    ) -> Result<R, FilterError> {
        let saved = (
            *self.local1.state(),
            *self.local1.covariance(),
            *self.local2.state(),
            *self.local2.covariance(),
        );
        let result = f(self);
        if result.is_err() {
            // The saved estimates were accepted by the filters before, so the resets succeed.
            let r1 = self.local1.reset(saved.0, saved.1);
            let r2 = self.local2.reset(saved.2, saved.3);
            debug_assert!(r1.is_ok() && r2.is_ok());
        }
        result
    }

    fn try_step(
        &mut self,
        u: &SVector<f64, U>,
        y1: &SVector<f64, M1>,
        y2: &SVector<f64, M2>,
    ) -> Result<FusedStep<N, M1, M2>, FilterError> {
        self.local1.predict(u)?;
        self.local2.predict(u)?;
        let local1 = self.local1.update(y1, u)?;
        let local2 = self.local2.update(y2, u)?;
        let (x, p) = self.fuse()?;
        Ok(FusedStep {
            x,
            p,
            local1,
            local2,
            nis: local1.nis + local2.nis,
            dof: local1.dof + local2.dof,
        })
    }

    /// One step with a sensor missing (a reading refused as implausible, a lost signal): both
    /// locals predict, each updates only if its measurement is given, then the master fuses
    /// them. A local without its sensor runs on the model alone, so the other sensor's local
    /// keeps a usable estimate through the outage. On any error nothing changes.
    pub fn step_partial(
        &mut self,
        u: &SVector<f64, U>,
        y1: Option<&SVector<f64, M1>>,
        y2: Option<&SVector<f64, M2>>,
    ) -> Result<(), FilterError> {
        check_input(u)?;
        if let Some(y) = y1 {
            check_measurement(y, &[true; M1])?;
        }
        if let Some(y) = y2 {
            check_measurement(y, &[true; M2])?;
        }
        let (x, p) = self.rolled_back_on_error(|pair| {
            pair.local1.predict(u)?;
            pair.local2.predict(u)?;
            if let Some(y) = y1 {
                pair.local1.update(y, u)?;
            }
            if let Some(y) = y2 {
                pair.local2.update(y, u)?;
            }
            pair.fuse()
        })?;
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// Fused state estimate (after the last successful step).
    pub fn state(&self) -> &SVector<f64, N> {
        &self.x
    }

    /// Fused covariance (optimistic, see the type's documentation).
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.p
    }

    /// The local filter of sensor 1.
    pub fn local1(&self) -> &Ekf<T, O1, N, M1, U> {
        &self.local1
    }

    /// The local filter of sensor 2.
    pub fn local2(&self) -> &Ekf<T, O2, N, M2, U> {
        &self.local2
    }
}

/// Carlson's federated Kalman filter, fusion-reset mode, with two local EKFs (one per sensor)
/// and information-sharing factors `beta = [beta_1, beta_2]`, `beta_i > 0`, `sum = 1` (no
/// master share).
///
/// Each step:
/// 1. the locals are reset from the master: `x_i = x_m`, `P_i = P_m / beta_i`, `Q_i = Q / beta_i`;
/// 2. each local predicts (`x_i- = f(x_m, u)`, `P_i- = F P_i F' + Q_i = P_m- / beta_i`, with `F`
///    taken at `x_m`, so the prediction is computed once) and updates with its own sensor,
///    linearized at the common prediction;
/// 3. the master fuses them: `P_m^-1 = sum P_i^-1`, `P_m^-1 x_m = sum P_i^-1 x_i`.
///
/// The shared prior information is split `beta_1 + beta_2 = 1` between the locals, so it is
/// counted once: the result equals the centralized (E)KF processing both sensors together.
/// The model's `constrain` is applied to the predicted state and to the fused state.
#[derive(Debug, Clone)]
pub struct FederatedFilter<
    T,
    O1,
    O2,
    const N: usize,
    const M1: usize,
    const M2: usize,
    const U: usize,
> {
    transition: T,
    observation1: O1,
    observation2: O2,
    x: SVector<f64, N>,
    p: SMatrix<f64, N, N>,
    noise: FusionNoise<N, M1, M2>,
    beta: [f64; 2],
    local_x: [SVector<f64, N>; 2],
    local_p: [SMatrix<f64, N, N>; 2],
}

impl<T, O1, O2, const N: usize, const M1: usize, const M2: usize, const U: usize>
    FederatedFilter<T, O1, O2, N, M1, M2, U>
where
    T: TransitionModel<N, U>,
    O1: ObservationModel<N, M1, U>,
    O2: ObservationModel<N, M2, U>,
{
    /// Builds the filter. `p0`, `r1`, `r2` must be symmetric positive definite, `q` positive
    /// semidefinite, `beta` positive and summing to 1 (within 1e-9).
    pub fn new(
        transition: T,
        observation1: O1,
        observation2: O2,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        noise: FusionNoise<N, M1, M2>,
        beta: [f64; 2],
    ) -> Result<Self, ConfigError> {
        check_covariance("P0", &p0, true)?;
        check_covariance("Q", &noise.q, false)?;
        check_covariance("R1", &noise.r1, true)?;
        check_covariance("R2", &noise.r2, true)?;
        check_finite_state(&x0)?;
        for &b in &beta {
            if !(b > 0.0 && b.is_finite()) {
                return Err(ConfigError::InvalidParameter {
                    name: "beta",
                    value: b,
                    reason: "information-sharing factors must be positive and finite",
                });
            }
        }
        let sum = beta[0] + beta[1];
        if (sum - 1.0).abs() > 1e-9 {
            return Err(ConfigError::InvalidParameter {
                name: "beta",
                value: sum,
                reason: "information-sharing factors must sum to 1",
            });
        }
        Ok(Self {
            transition,
            observation1,
            observation2,
            x: x0,
            p: p0,
            noise,
            beta,
            local_x: [x0; 2],
            local_p: [p0 / beta[0], p0 / beta[1]],
        })
    }

    /// One step: reset, local predict and update, master fusion. On success the master holds
    /// the fused estimate and the locals their posteriors (see [`Self::local_estimate`]).
    ///
    /// `local1`, `local2` in the result are the locals' own innovations, whose covariance uses
    /// the inflated `P_i- = P_m- / beta_i` (so their NIS is deflated and not chi-square on its
    /// own). `nis` is the innovation of both sensors together against the master prediction,
    /// `r' S^-1 r` with `S = H P_m- H' + blockdiag(R1, R2)` and `H` the stacked Jacobians at the
    /// prediction (computed by the chain rule `NIS(y1) + NIS(y2 | y1)` with only `M`-sized
    /// factorizations, without forming the stacked vectors); it equals the
    /// centralized EKF's NIS and is chi-square with `M1 + M2` degrees of freedom when the
    /// filter is consistent.
    ///
    /// Inputs and measurements are checked first; on any error nothing changes.
    pub fn step(
        &mut self,
        u: &SVector<f64, U>,
        y1: &SVector<f64, M1>,
        y2: &SVector<f64, M2>,
    ) -> Result<FusedStep<N, M1, M2>, FilterError> {
        check_input(u)?;
        check_measurement(y1, &[true; M1])?;
        check_measurement(y2, &[true; M2])?;

        // Common prediction from the master (steps 1 and 2: every local would compute the same
        // x_m- and, scaled by 1/beta_i, the same P_m-).
        let (mut xp, f) = self.transition.transition_with_jacobian(&self.x, u);
        self.transition.constrain(&mut xp);
        let mut pp = f * self.p * f.transpose() + self.noise.q;
        symmetrize(&mut pp);
        if !all_finite(&xp) || !all_finite(&pp) {
            return Err(FilterError::NonFiniteResult {
                which: "prediction",
            });
        }

        let h1 = self.observation1.observation_jacobian(&xp, u);
        let yp1 = self.observation1.observe(&xp, u);
        let h2 = self.observation2.observation_jacobian(&xp, u);
        let yp2 = self.observation2.observe(&xp, u);

        // Local updates with the shared-out covariances.
        let p1 = pp / self.beta[0];
        let pxy1 = p1 * h1.transpose();
        let c1 = correct(
            &xp,
            &p1,
            y1,
            &yp1,
            h1 * pxy1 + self.noise.r1,
            pxy1,
            &[true; M1],
        )?;
        let p2 = pp / self.beta[1];
        let pxy2 = p2 * h2.transpose();
        let c2 = correct(
            &xp,
            &p2,
            y2,
            &yp2,
            h2 * pxy2 + self.noise.r2,
            pxy2,
            &[true; M2],
        )?;

        // Step 3: master fusion.
        let (mut x, p) = fuse_pair(&c1.x, &c1.p, &c2.x, &c2.p)?;
        self.transition.constrain(&mut x);

        // Joint innovation against the master prediction, by the chain rule
        // r' S^-1 r = NIS(y1 | prior) + NIS(y2 | prior, y1), both linearized at the prediction.
        let nis = joint_nis(
            &pp,
            &h1,
            &h2,
            &(y1 - yp1),
            &(y2 - yp2),
            &self.noise.r1,
            &self.noise.r2,
        )?;

        self.x = x;
        self.p = p;
        self.local_x = [c1.x, c2.x];
        self.local_p = [c1.p, c2.p];
        Ok(FusedStep {
            x,
            p,
            local1: c1.innovation,
            local2: c2.innovation,
            nis,
            dof: M1 + M2,
        })
    }

    /// Replaces the master estimate. On error nothing changes.
    pub fn reset(&mut self, x: SVector<f64, N>, p: SMatrix<f64, N, N>) -> Result<(), ConfigError> {
        check_covariance("P", &p, true)?;
        check_finite_state(&x)?;
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// Fused (master) state estimate.
    pub fn state(&self) -> &SVector<f64, N> {
        &self.x
    }

    /// Fused (master) covariance.
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.p
    }

    /// Posterior estimate `(x_i, P_i)` of local filter `i` (0 or 1) after the last step. `P_i`
    /// includes the `1 / beta_i` inflation of the shared prior. Panics if `i > 1`.
    pub fn local_estimate(&self, i: usize) -> (&SVector<f64, N>, &SMatrix<f64, N, N>) {
        (&self.local_x[i], &self.local_p[i])
    }

    /// The information-sharing factors.
    pub fn shares(&self) -> [f64; 2] {
        self.beta
    }
}

#[cfg(test)]
mod tests {
    //! The cheap fusion and joint-NIS forms against the textbook ones they replace.

    use super::*;
    use nalgebra::{SMatrix, SVector};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// Typical sizes of the intake filter's states (Pa, Pa, kg/s, kg/s, Pa, Pa/s): the
    /// covariances the fusion sees span 20 orders of magnitude.
    const SCALE: [f64; 6] = [2e3, 2e3, 1e-3, 1e-3, 1e3, 6e5];

    fn random_spd(rng: &mut Pcg64, cond: f64) -> SMatrix<f64, 6, 6> {
        let b = SMatrix::<f64, 6, 6>::from_fn(|_, _| rng.random_range(-1.0..1.0));
        let a = b * b.transpose() + SMatrix::<f64, 6, 6>::identity() * (1.0 / cond);
        let d = SMatrix::<f64, 6, 6>::from_diagonal(&SVector::<f64, 6>::from(SCALE));
        d * a * d
    }

    /// The information form the filters used before: three inverses by Cholesky.
    fn information_form(
        x1: &SVector<f64, 6>,
        p1: &SMatrix<f64, 6, 6>,
        x2: &SVector<f64, 6>,
        p2: &SMatrix<f64, 6, 6>,
    ) -> (SVector<f64, 6>, SMatrix<f64, 6, 6>) {
        let eye = SMatrix::<f64, 6, 6>::identity();
        let (l1, l2) = (cholesky(p1).unwrap(), cholesky(p2).unwrap());
        let mut info = cholesky_solve(&l1, &eye) + cholesky_solve(&l2, &eye);
        symmetrize(&mut info);
        let info_x = cholesky_solve(&l1, x1) + cholesky_solve(&l2, x2);
        let l = cholesky(&info).unwrap();
        let mut p = cholesky_solve(&l, &eye);
        symmetrize(&mut p);
        (cholesky_solve(&l, &info_x), p)
    }

    #[test]
    fn covariance_form_fusion_equals_information_form() {
        let mut rng = Pcg64::seed_from_u64(0xf05e);
        let mut worst = 0.0f64;
        for case in 0..400 {
            // Well to poorly conditioned (in scaled units), and one local far more certain.
            let cond = [1e1, 1e3, 1e5][case % 3];
            let p1 = random_spd(&mut rng, cond);
            let p2 = random_spd(&mut rng, cond) * [1.0, 0.01, 100.0][(case / 3) % 3];
            let x1 = SVector::<f64, 6>::from_fn(|i, _| SCALE[i] * rng.random_range(-5.0..5.0));
            let x2 = SVector::<f64, 6>::from_fn(|i, _| SCALE[i] * rng.random_range(-5.0..5.0));
            let (x, p) = fuse_pair(&x1, &p1, &x2, &p2).expect("fuses");
            let (xr, pr) = information_form(&x1, &p1, &x2, &p2);
            // Scaled units: x_i / d_i, P_ij / (d_i d_j); relative to the reference's size.
            let pn = SMatrix::<f64, 6, 6>::from_fn(|i, j| pr[(i, j)] / (SCALE[i] * SCALE[j]));
            let pmax = pn.amax();
            let xmax = (0..6).map(|i| (xr[i] / SCALE[i]).abs()).fold(0.0, f64::max);
            let mut dev = 0.0f64;
            for i in 0..6 {
                dev = dev.max((x[i] - xr[i]).abs() / SCALE[i] / xmax);
                for j in 0..6 {
                    dev = dev.max((p[(i, j)] - pr[(i, j)]).abs() / (SCALE[i] * SCALE[j]) / pmax);
                }
            }
            worst = worst.max(dev);
            assert!(dev < 1e-9, "case {case}: deviation {dev:.2e}");
        }
        println!("covariance-form fusion vs information form: worst {worst:.2e}");
    }

    /// The joint NIS as the federated filter computed it before: two sequential full updates.
    fn sequential_nis<const M1: usize, const M2: usize>(
        pp: &SMatrix<f64, 6, 6>,
        h1: &SMatrix<f64, M1, 6>,
        h2: &SMatrix<f64, M2, 6>,
        r1: &SVector<f64, M1>,
        r2: &SVector<f64, M2>,
        n1: &SMatrix<f64, M1, M1>,
        n2: &SMatrix<f64, M2, M2>,
    ) -> f64 {
        let xp = SVector::<f64, 6>::zeros();
        let pxy = pp * h1.transpose();
        let s1 = correct(
            &xp,
            pp,
            r1,
            &SVector::zeros(),
            h1 * pxy + n1,
            pxy,
            &[true; M1],
        )
        .expect("first update");
        let pxy = s1.p * h2.transpose();
        let yp2_given1 = h2 * (s1.x - xp);
        let s2 = correct(
            &s1.x,
            &s1.p,
            r2,
            &yp2_given1,
            h2 * pxy + n2,
            pxy,
            &[true; M2],
        )
        .expect("second update");
        s1.innovation.nis + s2.innovation.nis
    }

    fn check_nis<const M1: usize, const M2: usize>(rng: &mut Pcg64) -> f64 {
        let pp = random_spd(rng, 1e3);
        let h1 = SMatrix::<f64, M1, 6>::from_fn(|_, j| rng.random_range(-1.0..1.0) / SCALE[j]);
        let h2 = SMatrix::<f64, M2, 6>::from_fn(|_, j| rng.random_range(-1.0..1.0) / SCALE[j]);
        let b1 = SMatrix::<f64, M1, M1>::from_fn(|_, _| rng.random_range(-1.0..1.0));
        let b2 = SMatrix::<f64, M2, M2>::from_fn(|_, _| rng.random_range(-1.0..1.0));
        let n1 = b1 * b1.transpose() + SMatrix::<f64, M1, M1>::identity() * 0.1;
        let n2 = b2 * b2.transpose() + SMatrix::<f64, M2, M2>::identity() * 0.1;
        let r1 = SVector::<f64, M1>::from_fn(|_, _| rng.random_range(-3.0..3.0));
        let r2 = SVector::<f64, M2>::from_fn(|_, _| rng.random_range(-3.0..3.0));
        let cheap = joint_nis(&pp, &h1, &h2, &r1, &r2, &n1, &n2).expect("PD");
        let reference = sequential_nis(&pp, &h1, &h2, &r1, &r2, &n1, &n2);
        let rel = (cheap - reference).abs() / reference;
        assert!(rel < 1e-9, "{cheap} vs {reference}");
        rel
    }

    #[test]
    fn joint_nis_equals_sequential_updates() {
        let mut rng = Pcg64::seed_from_u64(0x0015);
        let mut worst = 0.0f64;
        for _ in 0..300 {
            worst = worst.max(check_nis::<1, 1>(&mut rng));
            worst = worst.max(check_nis::<2, 1>(&mut rng));
            worst = worst.max(check_nis::<1, 3>(&mut rng));
        }
        println!("joint NIS vs sequential updates: worst relative {worst:.2e}");
    }

    #[test]
    fn fusion_of_non_positive_sum_is_refused() {
        let p = SMatrix::<f64, 6, 6>::identity();
        let x = SVector::<f64, 6>::zeros();
        let err = fuse_pair(&x, &p, &x, &(-p * 2.0)).unwrap_err();
        assert!(matches!(err, FilterError::NotPositiveDefinite { .. }));
    }
}
