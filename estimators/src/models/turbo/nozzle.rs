//! Compressible (nozzle) flow through the throttle and the wastegate.
//!
//! `W = p_us A / sqrt(R T_us) Psi(Pi)`, `Pi = p_ds / p_us`, with
//! `Psi = sqrt(2k/(k-1) (Pi^(2/k) - Pi^((k+1)/k)))` for `Pi` at or above the critical ratio
//! `(2/(k+1))^(k/(k-1))` and its value there below it (choked flow, REFERENCE §4: `Pi` limited
//! below at the critical ratio). `Psi` has an infinite slope at `Pi = 1`; above `lin_ratio` it is
//! continued linearly to zero at `Pi = 1` (Eriksson's MVEM library does the same with its
//! `PI_lin`, 0.99 in the VEP4 set), which bounds the throttle's and the wastegate's poles.
//! A reversed pressure difference reverses the flow with the roles of the two sides swapped and
//! the other side's temperature.

use super::ad::Scalar;
use super::params::critical_ratio;

/// The constants of one flow function.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nozzle {
    /// Ratio of specific heats in the flow function (tuned 2.0 for the throttle).
    pub k: f64,
    /// Critical pressure ratio.
    pub crit: f64,
    /// `Psi` when choked.
    pub choked: f64,
    /// Ratio where the linear continuation starts.
    pub lin_ratio: f64,
    /// `Psi(lin_ratio)`.
    pub psi_lin: f64,
    /// Gas constant of the flowing gas (J/(kg K)).
    pub r: f64,
}

impl Nozzle {
    /// Constants for ratio of specific heats `k`, linearization ratio `lin_ratio` (above the
    /// critical ratio, checked by the parameter validation) and gas constant `r`.
    pub fn new(k: f64, lin_ratio: f64, r: f64) -> Self {
        let crit = critical_ratio(k);
        let sub = |pi: f64| {
            (2.0 * k / (k - 1.0) * (pi.powf(2.0 / k) - pi.powf((k + 1.0) / k)))
                .max(0.0)
                .sqrt()
        };
        Self {
            k,
            crit,
            choked: sub(crit),
            lin_ratio,
            psi_lin: sub(lin_ratio),
            r,
        }
    }

    /// The flow function for a ratio `pi` in `[0, 1]`.
    #[inline]
    pub fn psi<S: Scalar>(&self, pi: S) -> S {
        let v = pi.val();
        if !(v >= self.crit) {
            S::cst(self.choked)
        } else if v < self.lin_ratio {
            let k = self.k;
            ((pi.powf(2.0 / k) - pi.powf((k + 1.0) / k)) * (2.0 * k / (k - 1.0)))
                .max_c(0.0)
                .sqrt()
        } else {
            (-pi + 1.0) * (self.psi_lin / (1.0 - self.lin_ratio))
        }
    }

    /// Signed mass flow (kg/s) through effective area `area` (m^2) from side 1 to side 2 and
    /// the temperature of the gas it carries (the upstream side's).
    #[inline]
    pub fn flow<S: Scalar>(&self, area: S, p1: S, t1: S, p2: S, t2: S) -> (S, S) {
        if p1.val() >= p2.val() {
            let w = p1 * area / (t1 * self.r).sqrt() * self.psi(p2 / p1);
            (w, t1)
        } else {
            let w = p2 * area / (t2 * self.r).sqrt() * self.psi(p1 / p2);
            (-w, t2)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flow_function_is_continuous_at_its_joints() {
        for (k, lin) in [(2.0, 0.9), (1.3, 0.99), (1.4, 0.97)] {
            let n = Nozzle::new(k, lin, 287.0);
            for x in [n.crit, n.lin_ratio] {
                let (a, b) = (n.psi(x - 1e-9), n.psi(x + 1e-9));
                assert!((a - b).abs() < 1e-6, "k {k} at {x}: {a} vs {b}");
            }
            assert_eq!(n.psi(1.0), 0.0);
            assert_eq!(n.psi(0.0), n.choked);
            assert_eq!(n.psi(f64::NAN), n.choked);
        }
        // Critical ratio of k = 2: (2/3)^2.
        assert!((Nozzle::new(2.0, 0.9, 287.0).crit - 4.0 / 9.0).abs() < 1e-15);
    }

    #[test]
    fn reversed_flow_is_the_mirror() {
        let n = Nozzle::new(1.3, 0.99, 290.0);
        let (w, t) = n.flow(1e-4, 150e3, 900.0, 105e3, 700.0);
        let (wr, tr) = n.flow(1e-4, 105e3, 700.0, 150e3, 900.0);
        assert!(w > 0.0 && (w + wr).abs() < 1e-15 && t == 900.0 && tr == 900.0);
    }
}
