//! The turbine (REFERENCE §4).
//!
//! - Flow `W_t = k1 p_em / sqrt(T_em) sqrt(1 - Pi_t^k2)`, `Pi_t = p_es / p_em`, with `p_em` in
//!   **kPa**: with `k1` = 0.017 this gives 0.05 kg/s at 150 kPa and 1000 K, the flow of a 1.8 L
//!   engine at part load, where pascals would give 53 kg/s (the VEP4 model also scales its
//!   pressures by 1e-3 in the turbine). `sqrt(1 - Pi^k2)` has an infinite slope at
//!   `Pi_t = 1`; above `lin_ratio` it is continued linearly to zero at 1 (our rule, as for the
//!   throttle and wastegate). A reversed pressure difference (`p_es > p_em`, only in transients)
//!   reverses the flow with the two sides swapped; it carries the exhaust system's temperature
//!   and exchanges no work.
//! - Efficiency: blade speed ratio `BSR = omega_t r_t / sqrt(2 cp_e T_em (1 - Pi_t^((k_e-1)/k_e)))`,
//!   `r_t = D_t / 2`, `eta_t = eta_max (1 - ((BSR - BSR_opt) / BSR_opt)^2)` clamped to
//!   `[eta_min, 1]` (an isentropic expansion below 1e-9 of `cp_e T_em` counts as an infinite
//!   BSR: `eta_min`).
//! - Outlet `T_em (1 - eta_t (1 - Pi_t^((k_e-1)/k_e)))`, torque
//!   `W_t cp_e (T_em - T_t,out) / omega_t`.

use super::ad::Scalar;

/// The turbine's constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Turbine {
    /// `k1 / 1000` (kg K^0.5 / (s Pa)).
    pub k1_pa: f64,
    /// `k2`.
    pub k2: f64,
    /// Ratio where the linear continuation starts.
    pub lin_ratio: f64,
    /// `sqrt(1 - lin_ratio^k2)`.
    pub g_lin: f64,
    /// Blade tip radius (m).
    pub radius: f64,
    /// Peak efficiency.
    pub eta_max: f64,
    /// BSR at the peak.
    pub bsr_opt: f64,
    /// Lower clamp.
    pub eta_min: f64,
    /// Exhaust `cp` (J/(kg K)).
    pub cp: f64,
    /// `(k_e - 1) / k_e`.
    pub expo: f64,
}

/// The turbine at one operating point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurbinePoint<S> {
    /// Signed flow from the exhaust manifold to the exhaust system (kg/s).
    pub w: S,
    /// Temperature the flow carries into its downstream volume (K).
    pub t_carried: S,
    /// Delivered torque (N m).
    pub torque: S,
    /// Efficiency (-).
    pub eta: S,
    /// Blade speed ratio (-), 0 when no expansion.
    pub bsr: S,
}

impl Turbine {
    /// Constants from the parameters (`k1` per kPa) and the exhaust gas properties.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        k1_kpa: f64,
        k2: f64,
        lin_ratio: f64,
        diameter: f64,
        eta_max: f64,
        bsr_opt: f64,
        eta_min: f64,
        r_e: f64,
        k_e: f64,
    ) -> Self {
        Self {
            k1_pa: k1_kpa / 1000.0,
            k2,
            lin_ratio,
            g_lin: (1.0 - lin_ratio.powf(k2)).sqrt(),
            radius: diameter / 2.0,
            eta_max,
            bsr_opt,
            eta_min,
            cp: r_e * k_e / (k_e - 1.0),
            expo: (k_e - 1.0) / k_e,
        }
    }

    /// `sqrt(1 - pi^k2)` with the linear continuation, for `pi` in `[0, 1]`.
    #[inline]
    pub fn g<S: Scalar>(&self, pi: S) -> S {
        if pi.val() < self.lin_ratio {
            (-pi.max_c(0.0).powf(self.k2) + 1.0).sqrt()
        } else {
            (-pi + 1.0) * (self.g_lin / (1.0 - self.lin_ratio))
        }
    }

    /// The turbine between the exhaust manifold `(p_em Pa, t_em K)` and the exhaust system
    /// `(p_es, t_es)` at turbo speed `omega` (rad/s, positive).
    #[inline]
    pub fn point<S: Scalar>(
        &self,
        p_em: S,
        t_em: S,
        p_es: S,
        t_es: S,
        omega: S,
    ) -> TurbinePoint<S> {
        if p_em.val() < p_es.val() {
            let w = -(p_es / t_es.sqrt() * self.k1_pa * self.g(p_em / p_es));
            return TurbinePoint {
                w,
                t_carried: t_es,
                torque: S::cst(0.0),
                eta: S::cst(self.eta_min),
                bsr: S::cst(0.0),
            };
        }
        let pi = p_es / p_em;
        let w = p_em / t_em.sqrt() * self.k1_pa * self.g(pi);
        let y = -pi.powf(self.expo) + 1.0;
        let (eta, bsr) = if y.val() > 1e-9 {
            let bsr = omega * self.radius / (t_em * y * (2.0 * self.cp)).sqrt();
            let q = (bsr - self.bsr_opt) / self.bsr_opt;
            (
                ((-(q * q) + 1.0) * self.eta_max).clamp_c(self.eta_min, 1.0),
                bsr,
            )
        } else {
            (S::cst(self.eta_min), S::cst(0.0))
        };
        let drop = t_em * eta * y.max_c(0.0);
        TurbinePoint {
            w,
            t_carried: t_em - drop,
            torque: w * drop * self.cp / omega,
            eta,
            bsr,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flow_in_kpa_units_and_continuity() {
        let t = Turbine::new(0.017, 1.4, 0.99, 0.05, 0.75, 0.7, 0.3, 290.0, 1.3);
        let p = t.point(150e3, 1000.0, 100e3, 800.0, 10_000.0);
        let expected = 0.017 * 150.0 / 1000f64.sqrt() * (1.0 - (100.0f64 / 150.0).powf(1.4)).sqrt();
        assert!((p.w - expected).abs() < 1e-15, "{} vs {expected}", p.w);
        assert!((t.g(0.99 - 1e-12) - t.g(0.99 + 1e-12)).abs() < 1e-9);
        assert_eq!(t.g(1.0), 0.0);
        // Power = flow times enthalpy drop.
        let power = p.torque * 10_000.0;
        assert!((power - p.w * t.cp * (1000.0 - p.t_carried)).abs() < 1e-9 * power);
        let r = t.point(100e3, 1000.0, 101e3, 800.0, 10_000.0);
        assert!(r.w < 0.0 && r.torque == 0.0 && r.t_carried == 800.0);
    }
}
