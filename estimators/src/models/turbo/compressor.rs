//! The compressor: Psi-Phi model with the ellipse and the efficiency parabola (REFERENCE §4).
//!
//! - Tip speed `U_c = omega_t D_c / 2` (m/s) with the wheel diameter `D_c`; the testbed's
//!   "radius-like `R_c` and `omega_t / (2 pi)`" is the same number written as `pi D_c n`, the
//!   circumference times revolutions per second, and the VEP4 model of the public Fault
//!   Diagnosis Toolbox writes `U_c = omega_tc D_c / 2` literally.
//! - Head parameter `Psi = cp T_af (Pi_c^((k-1)/k) - 1) / (U_c^2 / 2)`, `Pi_c = p_c / p_af`.
//! - Flow parameter on the ellipse `Phi = Phi_max sqrt(1 - (Psi / Psi_max)^2)`, and the mass
//!   flow `W_c = Phi rho_af (pi D_c^2 / 4) U_c`, `rho_af = p_af / (R T_af)`: `Phi` is the flow
//!   through the wheel's disc at the tip speed (Eriksson and Nielsen, *Modeling and Control of
//!   Engines and Drivelines*, 2014, §8.4).
//! - Efficiency `eta_c = eta_max (1 - ((Phi - Phi_opt) / Phi_opt)^2)` clamped to
//!   `[eta_min, 1]`. REFERENCE gives the peak and the clamp only; this normalized parabola
//!   (zero at `Phi = 0` and at `2 Phi_opt`, which is `Phi_max` in the generic set) is our
//!   choice of its width, the same form as the turbine's in the blade speed ratio.
//! - Outlet temperature `T_af (1 + (Pi_c^((k-1)/k) - 1) / eta_c)`, torque
//!   `W_c cp (T_c,out - T_af) / omega_t`.
//!
//! Outside the ellipse's domain, our rules (each keeps the flow continuous):
//! - `Psi < 0` (`p_c < p_af`, a slow wheel passing a large flow): the ellipse is continued by
//!   the hyperbola `Phi = Phi_max sqrt(1 + (Psi / Psi_max)^2)`, which joins it with the same
//!   value and zero slope at `Psi = 0` and grows linearly with `|Psi|`: a compressor whose
//!   outlet is below its inlet passes more flow the larger the drop, like a restriction (the
//!   wheel windmills). Keeping `Phi_max` instead would choke the engine at the flow of the
//!   wheel's speed, 3.4 g/s at the VEP4 set's minimum turbo speed, less than idle with the
//!   wastegate open. No work is done there (`Pi_c^((k-1)/k) - 1` is floored at 0): the wheel
//!   does not expand the gas, and the outlet is at `T_af`.
//! - `Psi` near `Psi_max`: the ellipse's slope is infinite at `Psi_max`; above
//!   `head_linear_fraction * Psi_max` it is continued along its tangent, so that the flow
//!   crosses zero slightly above `Psi_max` and reverses (surge), floored at `-Phi_max`. A
//!   reversed flow carries the compressor volume's temperature back into the air filter volume;
//!   the wheel still works on the gas, so the torque uses `|W_c|`.

use std::f64::consts::PI;

use super::ad::Scalar;

/// The compressor's constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compressor {
    /// Wheel radius `D_c / 2` (m).
    pub radius: f64,
    /// Disc area `pi D_c^2 / 4` (m^2).
    pub area: f64,
    /// `Psi_max`.
    pub psi_max: f64,
    /// `Phi_max`.
    pub phi_max: f64,
    /// Head where the linear continuation starts.
    pub psi_lin: f64,
    /// `Phi(psi_lin)`.
    pub phi_lin: f64,
    /// `dPhi/dPsi` at `psi_lin` (negative).
    pub slope: f64,
    /// Peak efficiency.
    pub eta_max: f64,
    /// Flow parameter at the peak.
    pub phi_opt: f64,
    /// Lower efficiency clamp.
    pub eta_min: f64,
    /// Air `cp` (J/(kg K)).
    pub cp: f64,
    /// Air gas constant (J/(kg K)).
    pub r: f64,
    /// `(k - 1) / k` of air.
    pub expo: f64,
}

/// What the compressor does at one operating point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompressorPoint<S> {
    /// Signed mass flow from the air filter volume to the compressor volume (kg/s).
    pub w: S,
    /// Temperature of the gas the flow carries into its downstream volume (K): the outlet
    /// temperature forward, the compressor volume's temperature reversed.
    pub t_carried: S,
    /// Outlet temperature `T_c,out` of a forward flow (K).
    pub t_out: S,
    /// Absorbed torque (N m).
    pub torque: S,
    /// Isentropic efficiency (-).
    pub eta: S,
    /// Pressure ratio `p_c / p_af` (-).
    pub pi: S,
    /// Head parameter (-).
    pub psi: S,
    /// Flow parameter (-).
    pub phi: S,
}

impl Compressor {
    /// Constants from the wheel and map parameters and the air properties.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        diameter: f64,
        psi_max: f64,
        phi_max: f64,
        head_linear_fraction: f64,
        eta_max: f64,
        phi_opt: f64,
        eta_min: f64,
        r: f64,
        k: f64,
    ) -> Self {
        let psi_lin = head_linear_fraction * psi_max;
        let root = (1.0 - head_linear_fraction * head_linear_fraction).sqrt();
        Self {
            radius: diameter / 2.0,
            area: PI * diameter * diameter / 4.0,
            psi_max,
            phi_max,
            psi_lin,
            phi_lin: phi_max * root,
            slope: -phi_max * head_linear_fraction / (psi_max * root),
            eta_max,
            phi_opt,
            eta_min,
            cp: r * k / (k - 1.0),
            r,
            expo: (k - 1.0) / k,
        }
    }

    /// The flow parameter of a head parameter (ellipse, continued as described in the module
    /// docs).
    #[inline]
    pub fn phi<S: Scalar>(&self, psi: S) -> S {
        let v = psi.val();
        if !(v > 0.0) {
            let q = psi / self.psi_max;
            (q * q + 1.0).sqrt() * self.phi_max
        } else if v < self.psi_lin {
            let q = psi / self.psi_max;
            (-(q * q) + 1.0).sqrt() * self.phi_max
        } else {
            ((psi - self.psi_lin) * self.slope + self.phi_lin).max_c(-self.phi_max)
        }
    }

    /// Efficiency at flow parameter `phi`.
    /// The head parameter at which the wheel passes the flow parameter `phi` (-): the inverse of
    /// [`Self::phi`], which falls strictly with `psi` for `psi > 0` and rises with `|psi|`
    /// below (the windmilling continuation, `phi > phi_max`), so each `phi > -phi_max` has
    /// one `psi` on the branch the model uses (the negative one above `phi_max`).
    pub fn psi_from_phi(&self, phi: f64) -> f64 {
        if phi > self.phi_max {
            let q = phi / self.phi_max;
            -self.psi_max * (q * q - 1.0).sqrt()
        } else if phi >= self.phi_lin {
            let q = phi / self.phi_max;
            self.psi_max * (1.0 - q * q).max(0.0).sqrt()
        } else {
            self.psi_lin + (phi - self.phi_lin) / self.slope
        }
    }

    #[inline]
    pub fn efficiency<S: Scalar>(&self, phi: S) -> S {
        let q = (phi - self.phi_opt) / self.phi_opt;
        ((-(q * q) + 1.0) * self.eta_max).clamp_c(self.eta_min, 1.0)
    }

    /// The operating point at inlet `(p_af Pa, t_af K)`, outlet volume `(p_c, t_c)` and turbo
    /// speed `omega` (rad/s, already limited to its positive range by the caller).
    #[inline]
    pub fn point<S: Scalar>(
        &self,
        p_af: S,
        t_af: S,
        p_c: S,
        t_c: S,
        omega: S,
    ) -> CompressorPoint<S> {
        let u = omega * self.radius;
        let pi = p_c / p_af;
        let x = pi.powf(self.expo) - 1.0;
        let psi = t_af * x * (2.0 * self.cp) / (u * u);
        let phi = self.phi(psi);
        let w = phi * p_af / (t_af * self.r) * u * self.area;
        let eta = self.efficiency(phi);
        let rise = t_af * x.max_c(0.0) / eta;
        let t_out = t_af + rise;
        let torque = w.abs_s() * rise * self.cp / omega;
        let t_carried = if w.val() >= 0.0 { t_out } else { t_c };
        CompressorPoint {
            w,
            t_carried,
            t_out,
            torque,
            eta,
            pi,
            psi,
            phi,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn generic() -> Compressor {
        Compressor::new(0.06, 2.3, 0.12, 0.95, 0.8, 0.06, 0.3, 287.2, 1.4)
    }

    #[test]
    fn ellipse_is_continuous_and_reverses_above_psi_max() {
        let c = generic();
        let (a, b) = (c.phi(c.psi_lin - 1e-9), c.phi(c.psi_lin + 1e-9));
        assert!((a - b).abs() < 1e-8);
        assert!((c.phi(-1e-9) - c.phi_max).abs() < 1e-12);
        assert!(c.phi(-2.0 * c.psi_max) > 2.2 * c.phi_max);
        assert!((c.phi(1e-9) - c.phi_max).abs() < 1e-12);
        assert!(c.phi(1.1 * c.psi_max) < 0.0);
        assert_eq!(c.phi(100.0), -c.phi_max);
        assert!((c.efficiency(0.06) - 0.8).abs() < 1e-15);
        // The inverse, on every branch.
        for psi in [-3.0, -0.5, 0.0, 0.5, 2.0, c.psi_lin, 2.25, 2.4] {
            let back = c.psi_from_phi(c.phi(psi));
            assert!((back - psi).abs() < 1e-9, "{psi} -> {back}");
        }
        assert_eq!(c.efficiency(0.0), 0.3);
    }

    #[test]
    fn energy_balance_of_a_forward_point() {
        let c = generic();
        let omega = 8000.0;
        let p = c.point(100e3, 298.0, 150e3, 340.0, omega);
        assert!(p.w > 0.0 && p.t_out > 298.0 && p.t_carried == p.t_out);
        // Shaft power equals the enthalpy rise of the flow.
        let power = p.torque * omega;
        assert!((power - p.w * c.cp * (p.t_out - 298.0)).abs() < 1e-9 * power);
    }
}
