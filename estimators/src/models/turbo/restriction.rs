//! Incompressible flow restrictions: the air filter, the intercooler and the exhaust system.
//!
//! `W = sign(dp) sqrt(p_us / (H T_us)) g(|dp|)` with `g = sqrt(dp)` above `dp_lin` and
//! `g = dp / sqrt(dp_lin)` below (REFERENCE §4). The square root's slope is infinite at
//! `dp = 0`; the linear piece keeps the Jacobian finite there, so that a quiet engine (idle, no
//! flow through the air filter to speak of) does not give an infinitely fast pole. The value is
//! continuous at `dp_lin`; the slope halves there (a kink the stiff step tolerates).

use super::ad::Scalar;

/// A restriction's constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Restriction {
    /// Flow resistance `H` (Pa^2 s^2 / (kg^2 K)).
    pub h: f64,
    /// Linearization pressure drop `dp_lin` (Pa).
    pub dp_lin: f64,
}

impl Restriction {
    /// Signed mass flow (kg/s) from side 1 `(p1 Pa, t1 K)` to side 2 `(p2, t2)`, and the
    /// temperature (K) of the gas it carries: the upstream side's (`t1` forward, `t2` when the
    /// flow reverses).
    #[inline]
    pub fn flow<S: Scalar>(&self, p1: S, t1: S, p2: S, t2: S) -> (S, S) {
        let forward = p1.val() >= p2.val();
        let (p_us, t_us, dp) = if forward {
            (p1, t1, p1 - p2)
        } else {
            (p2, t2, p2 - p1)
        };
        let g = if dp.val() >= self.dp_lin {
            dp.sqrt()
        } else {
            dp / self.dp_lin.sqrt()
        };
        let w = (p_us / (t_us * self.h)).sqrt() * g;
        if forward {
            (w, t_us)
        } else {
            (-w, t_us)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flow_is_odd_continuous_and_linear_near_zero() {
        let r = Restriction {
            h: 2e8,
            dp_lin: 2000.0,
        };
        let (w, t) = r.flow(101_300.0, 298.0, 99_300.0, 300.0);
        // 2 kPa over the filter at 298 K: sqrt(101300 * 2000 / (2e8 * 298)) = 0.0583 kg/s.
        assert!((w - (101_300.0f64 * 2000.0 / (2e8 * 298.0)).sqrt()).abs() < 1e-12);
        assert_eq!(t, 298.0);
        let (wr, tr) = r.flow(99_300.0, 300.0, 101_300.0, 298.0);
        assert_eq!((wr, tr), (-w, 298.0));
        let below = r
            .flow(100_000.0, 298.0, 100_000.0 - (2000.0 - 1e-6), 298.0)
            .0;
        let above = r
            .flow(100_000.0, 298.0, 100_000.0 - (2000.0 + 1e-6), 298.0)
            .0;
        assert!((above - below).abs() < 1e-8);
        let small = r.flow(100_000.0, 298.0, 100_000.0 - 10.0, 298.0).0;
        assert!((small * 2.0 - r.flow(100_000.0, 298.0, 100_000.0 - 20.0, 298.0).0).abs() < 1e-9);
        assert_eq!(r.flow(1e5, 298.0, 1e5, 298.0).0, 0.0);
    }
}
