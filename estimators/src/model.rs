//! The two small traits a plant model implements so that every filter can use it: how the state
//! moves (`TransitionModel`) and what the sensors see (`ObservationModel`). Keeping them apart
//! lets one plant be observed by several sensor sets (a throttle with its position sensor, with
//! a wattmeter only, or with both) without repeating the dynamics.

use nalgebra::{SMatrix, SVector};

/// Discrete-time state transition `x[k+1] = f(x[k], u[k])` (noise-free mean).
pub trait TransitionModel<const N: usize, const U: usize> {
    /// The mean next state.
    fn transition(&self, x: &SVector<f64, N>, u: &SVector<f64, U>) -> SVector<f64, N>;

    /// `df/dx` at `(x, u)`. Models with a simple closed form override this; the default
    /// differentiates `transition` numerically with central differences.
    fn transition_jacobian(&self, x: &SVector<f64, N>, u: &SVector<f64, U>) -> SMatrix<f64, N, N> {
        numerical_jacobian(|z| self.transition(z, u), x)
    }

    /// The next state and `df/dx` together. Filters that need both (the EKF) call this, so a
    /// model whose step is expensive (the intake model integrates substeps) can compute them in
    /// one pass; the default calls the two methods.
    fn transition_with_jacobian(
        &self,
        x: &SVector<f64, N>,
        u: &SVector<f64, U>,
    ) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
        (self.transition(x, u), self.transition_jacobian(x, u))
    }

    /// Moves a state onto the set the plant can physically occupy (for example a throttle plate
    /// against its stop). Filters apply it to propagated sigma points and to posterior means.
    /// The default leaves the state as it is.
    fn constrain(&self, _x: &mut SVector<f64, N>) {}
}

/// Measurement function `y[k] = h(x[k], u[k])` (noise-free mean).
pub trait ObservationModel<const N: usize, const M: usize, const U: usize> {
    /// The predicted measurement.
    fn observe(&self, x: &SVector<f64, N>, u: &SVector<f64, U>) -> SVector<f64, M>;

    /// `dh/dx` at `(x, u)`; numerical central differences unless overridden.
    fn observation_jacobian(&self, x: &SVector<f64, N>, u: &SVector<f64, U>) -> SMatrix<f64, M, N> {
        numerical_jacobian(|z| self.observe(z, u), x)
    }

    /// `(H, d)` when `h(x, u) = H x + d` for every state (a linear sensor). The UKF then forms
    /// the predicted measurement and its covariances in closed form (`H x + d`, `H P H' + R`,
    /// `P H'`), which is what its sigma points give for a linear `h`, without drawing them.
    /// `None` (the default) keeps the unscented transform.
    fn affine_observation(
        &self,
        _u: &SVector<f64, U>,
    ) -> Option<(SMatrix<f64, M, N>, SVector<f64, M>)> {
        None
    }
}

/// Central-difference Jacobian of `g` at `x`. The step for component j is
/// `h_j = eps^(1/3) * max(1, |x_j|)`, which balances truncation (O(h^2)) against round-off
/// (O(eps/h)) and gives about 10 correct digits for smooth functions.
pub fn numerical_jacobian<const N: usize, const R: usize>(
    g: impl Fn(&SVector<f64, N>) -> SVector<f64, R>,
    x: &SVector<f64, N>,
) -> SMatrix<f64, R, N> {
    // eps^(1/3) for f64, precomputed: `cbrt` is evaluated in software and showed up in profiles.
    const BASE: f64 = 6.055454452393343e-6;
    let mut jac = SMatrix::<f64, R, N>::zeros();
    let mut z = *x;
    for j in 0..N {
        let h = BASE * x[j].abs().max(1.0);
        z[j] = x[j] + h;
        let plus = g(&z);
        z[j] = x[j] - h;
        let minus = g(&z);
        z[j] = x[j];
        jac.set_column(j, &((plus - minus) * (0.5 / h)));
    }
    jac
}
