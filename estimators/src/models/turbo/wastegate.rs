//! The wastegate: compressible orifice flow of exhaust gas (`k_e`, `R_e`) from the exhaust
//! manifold past the turbine into the exhaust system, through the effective area
//! `u_wg Cd A_max` (REFERENCE §4). The position `u_wg` (0 closed .. 1 open) is clamped to its
//! range; a reversed pressure difference reverses the flow (with the exhaust system's
//! temperature).

use super::ad::Scalar;
use super::nozzle::Nozzle;

/// The wastegate's constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wastegate {
    /// The flow function with `k_e`, the linearization ratio and `R_e`.
    pub nozzle: Nozzle,
    /// `Cd A_max` (m^2).
    pub area_max: f64,
}

impl Wastegate {
    /// Signed flow (kg/s) from the exhaust manifold `(p_em, t_em)` to the exhaust system
    /// `(p_es, t_es)` at position `u_wg`, and the temperature it carries.
    #[inline]
    pub fn flow<S: Scalar>(&self, u_wg: S, p_em: S, t_em: S, p_es: S, t_es: S) -> (S, S) {
        let area = u_wg.clamp_c(0.0, 1.0) * self.area_max;
        self.nozzle.flow(area, p_em, t_em, p_es, t_es)
    }
}
