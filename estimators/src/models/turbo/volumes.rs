//! The six adiabatic control volumes: ideal gas, one mass and one temperature each.
//!
//! `p = M R T / V`; `dM/dt = sum W_in - sum W_out` and, from the energy balance with
//! `cv = R / (k - 1)`, `cp = k cv`,
//!
//! ```text
//! cv M dT/dt = cp sum(W_in T_in) - cp T sum(W_out) - cv T (sum W_in - sum W_out)
//!     M dT/dt = sum W_in (k T_in - T) - sum W_out (k - 1) T
//! ```
//!
//! which is REFERENCE §4's `dT/dt = (cp (T_in W_in - T W_out) - cv T (W_in - W_out)) / (cv M)`
//! for any number of connections. Each connection gives a signed flow into the volume and the
//! temperature of the gas it carries when it comes in; a negative flow leaves at the volume's own
//! temperature. A flow that changes direction therefore changes the temperature it carries (the
//! upstream volume's, REFERENCE: "with reversed flow, the upstream volume's temperature").

use super::ad::Scalar;

/// An ideal gas's constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gas {
    /// Specific gas constant (J/(kg K)).
    pub r: f64,
    /// Ratio of specific heats (-).
    pub k: f64,
}

impl Gas {
    /// `cp = R k / (k - 1)` (J/(kg K)).
    pub fn cp(&self) -> f64 {
        self.r * self.k / (self.k - 1.0)
    }
}

/// The mass and energy balance of one volume, accumulated connection by connection.
#[derive(Debug, Clone, Copy)]
pub struct Balance<S> {
    t: S,
    k: f64,
    dm: S,
    /// `M dT/dt` (kg K / s).
    m_dt: S,
}

impl<S: Scalar> Balance<S> {
    /// A volume at temperature `t` (K) holding a gas with ratio of specific heats `k`.
    #[inline]
    pub fn new(t: S, k: f64) -> Self {
        Self {
            t,
            k,
            dm: S::cst(0.0),
            m_dt: S::cst(0.0),
        }
    }

    /// Adds a connection: signed flow `w_in` into the volume (kg/s) carrying `t_in` (K) when it
    /// comes in. A zero flow counts as coming in, so that the Jacobian at a closed valve (the
    /// wastegate at 0) is the derivative for it opening; on the side it leaves, `t_in` is the
    /// volume's own temperature and both branches agree.
    #[inline]
    pub fn add(&mut self, w_in: S, t_in: S) {
        self.dm = self.dm + w_in;
        let per_kg = if w_in.val() >= 0.0 {
            t_in * self.k - self.t
        } else {
            self.t * (self.k - 1.0)
        };
        self.m_dt = self.m_dt + w_in * per_kg;
    }

    /// `(dM/dt kg/s, dT/dt K/s)` for the volume's mass `m` (kg).
    #[inline]
    pub fn rates(&self, m: S) -> (S, S) {
        (self.dm, self.m_dt / m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mixing_conserves_energy() {
        // Two inflows at different temperatures and an outflow equal to their sum: the internal
        // energy cv M T changes by the enthalpy flow in minus out.
        let air = Gas { r: 287.2, k: 1.4 };
        let cv = air.r / (air.k - 1.0);
        let (m, t) = (0.01, 320.0);
        let mut b = Balance::new(t, air.k);
        b.add(0.02, 300.0);
        b.add(0.01, 400.0);
        b.add(-0.025, t);
        let (dm, dt) = b.rates(m);
        let du = cv * (dm * t + m * dt);
        let dh = air.cp() * (0.02 * 300.0 + 0.01 * 400.0 - 0.025 * t);
        assert!((du - dh).abs() < 1e-9 * dh.abs(), "{du} vs {dh}");
    }
}
