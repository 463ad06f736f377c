//! Linear time-invariant model `x+ = A x + B u`, `y = C x + D u`. Used as the reference case in
//! which every Kalman-type filter must reduce to the textbook Kalman filter.

use nalgebra::{SMatrix, SVector};

use crate::model::{ObservationModel, TransitionModel};

/// Discrete LTI system matrices.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearModel<const N: usize, const M: usize, const U: usize> {
    pub a: SMatrix<f64, N, N>,
    pub b: SMatrix<f64, N, U>,
    pub c: SMatrix<f64, M, N>,
    pub d: SMatrix<f64, M, U>,
}

impl<const N: usize, const M: usize, const U: usize> TransitionModel<N, U>
    for LinearModel<N, M, U>
{
    #[inline]
    fn transition(&self, x: &SVector<f64, N>, u: &SVector<f64, U>) -> SVector<f64, N> {
        self.a * x + self.b * u
    }

    fn transition_jacobian(
        &self,
        _x: &SVector<f64, N>,
        _u: &SVector<f64, U>,
    ) -> SMatrix<f64, N, N> {
        self.a
    }
}

impl<const N: usize, const M: usize, const U: usize> ObservationModel<N, M, U>
    for LinearModel<N, M, U>
{
    #[inline]
    fn observe(&self, x: &SVector<f64, N>, u: &SVector<f64, U>) -> SVector<f64, M> {
        self.c * x + self.d * u
    }

    fn observation_jacobian(
        &self,
        _x: &SVector<f64, N>,
        _u: &SVector<f64, U>,
    ) -> SMatrix<f64, M, N> {
        self.c
    }
}
