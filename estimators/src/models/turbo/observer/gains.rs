//! The gain schedule: one stationary Kalman gain per node of a grid over engine speed and intake
//! manifold pressure, looked up at the observer's operating point.
//!
//! The paper switches to the gain of the nearest engine-map point ([`Interpolation::Nearest`]);
//! gains that jump as the operating point crosses a cell boundary put steps into the estimates,
//! so the default interpolates bilinearly between the four nodes around the point
//! ([`Interpolation::Bilinear`]), which is continuous. Outside the grid the point is clamped to
//! its edge (the nearest gains are the best known). A convex combination of stabilizing gains
//! is not guaranteed to stabilize every system in between, but neighbouring nodes' closed loops
//! are close, and `fdd reproduce turbo` compares both rules.

use nalgebra::SMatrix;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::models::turbo::N_STATES_AUGMENTED;

/// How gains are looked up between nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    /// The node nearest in the grid's normalized coordinates (the paper's rule).
    Nearest,
    /// Bilinear between the four surrounding nodes.
    Bilinear,
}

/// A gain table that cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GainTableError {
    /// An axis is empty, not strictly increasing or not finite.
    #[error(
        "gain table: axis `{axis}` must hold finite, strictly increasing values (got {len} values)"
    )]
    Axis {
        /// `speeds_rad_s` or `pressures_pa`.
        axis: &'static str,
        /// Its length.
        len: usize,
    },
    /// The gain list does not have one matrix per node.
    #[error("gain table: {got} gain matrices for {want} nodes ({speeds} speeds x {pressures} pressures)")]
    Shape {
        /// Matrices given.
        got: usize,
        /// Nodes.
        want: usize,
        /// Speed nodes.
        speeds: usize,
        /// Pressure nodes.
        pressures: usize,
    },
    /// A gain is not finite.
    #[error("gain table: node ({speed_rad_s} rad/s, {pressure_pa} Pa) has a non-finite gain")]
    NonFinite {
        /// The node's speed.
        speed_rad_s: f64,
        /// The node's pressure.
        pressure_pa: f64,
    },
}

/// Gains `K` (14 states x `M` sensors) on a grid, speed-major: node `(i, j)` (speed `i`,
/// pressure `j`) is `gains[i * pressures.len() + j]`.
#[derive(Debug, Clone, PartialEq)]
pub struct GainTable<const M: usize> {
    speeds_rad_s: Vec<f64>,
    pressures_pa: Vec<f64>,
    gains: Vec<SMatrix<f64, N_STATES_AUGMENTED, M>>,
}

fn check_axis(axis: &'static str, v: &[f64]) -> Result<(), GainTableError> {
    let ok = !v.is_empty() && v.iter().all(|x| x.is_finite()) && v.windows(2).all(|w| w[0] < w[1]);
    if ok {
        Ok(())
    } else {
        Err(GainTableError::Axis { axis, len: v.len() })
    }
}

/// Position of `x` on an increasing axis: the cell's lower index and the fraction within it
/// (clamped to the axis).
fn locate(axis: &[f64], x: f64) -> (usize, f64) {
    let n = axis.len();
    if n == 1 || x.is_nan() || x <= axis[0] {
        return (0, 0.0);
    }
    if x >= axis[n - 1] {
        return (n - 2, 1.0);
    }
    // First index with axis[i] > x, minus one: the cell [axis[i], axis[i+1]).
    let i = axis.partition_point(|&a| a <= x) - 1;
    (i, (x - axis[i]) / (axis[i + 1] - axis[i]))
}

impl<const M: usize> GainTable<M> {
    /// A table from its axes and its gains (speed-major).
    pub fn new(
        speeds_rad_s: Vec<f64>,
        pressures_pa: Vec<f64>,
        gains: Vec<SMatrix<f64, N_STATES_AUGMENTED, M>>,
    ) -> Result<Self, GainTableError> {
        check_axis("speeds_rad_s", &speeds_rad_s)?;
        check_axis("pressures_pa", &pressures_pa)?;
        let want = speeds_rad_s.len() * pressures_pa.len();
        if gains.len() != want {
            return Err(GainTableError::Shape {
                got: gains.len(),
                want,
                speeds: speeds_rad_s.len(),
                pressures: pressures_pa.len(),
            });
        }
        for (k, g) in gains.iter().enumerate() {
            if !g.iter().all(|v| v.is_finite()) {
                return Err(GainTableError::NonFinite {
                    speed_rad_s: speeds_rad_s[k / pressures_pa.len()],
                    pressure_pa: pressures_pa[k % pressures_pa.len()],
                });
            }
        }
        Ok(Self {
            speeds_rad_s,
            pressures_pa,
            gains,
        })
    }

    /// The speed axis (rad/s).
    pub fn speeds_rad_s(&self) -> &[f64] {
        &self.speeds_rad_s
    }

    /// The pressure axis (Pa).
    pub fn pressures_pa(&self) -> &[f64] {
        &self.pressures_pa
    }

    /// The gains, speed-major.
    pub fn gains(&self) -> &[SMatrix<f64, N_STATES_AUGMENTED, M>] {
        &self.gains
    }

    fn node(&self, i: usize, j: usize) -> &SMatrix<f64, N_STATES_AUGMENTED, M> {
        &self.gains[i * self.pressures_pa.len() + j]
    }

    /// The gain at engine speed `speed_rad_s` and intake manifold pressure `p_im_pa`. No heap.
    pub fn lookup(
        &self,
        speed_rad_s: f64,
        p_im_pa: f64,
        mode: Interpolation,
    ) -> SMatrix<f64, N_STATES_AUGMENTED, M> {
        let (i, a) = locate(&self.speeds_rad_s, speed_rad_s);
        let (j, b) = locate(&self.pressures_pa, p_im_pa);
        let i1 = (i + 1).min(self.speeds_rad_s.len() - 1);
        let j1 = (j + 1).min(self.pressures_pa.len() - 1);
        match mode {
            Interpolation::Nearest => {
                let ii = if a < 0.5 { i } else { i1 };
                let jj = if b < 0.5 { j } else { j1 };
                *self.node(ii, jj)
            }
            Interpolation::Bilinear => {
                self.node(i, j) * ((1.0 - a) * (1.0 - b))
                    + self.node(i1, j) * (a * (1.0 - b))
                    + self.node(i, j1) * ((1.0 - a) * b)
                    + self.node(i1, j1) * (a * b)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> GainTable<1> {
        // K[0] = speed + pressure / 1000 at every node: bilinear reproduces it exactly.
        let speeds = vec![100.0, 200.0, 400.0];
        let pressures = vec![30e3, 60e3];
        let mut gains = Vec::new();
        for s in &speeds {
            for p in &pressures {
                let mut k = SMatrix::<f64, N_STATES_AUGMENTED, 1>::zeros();
                k[0] = s + p / 1000.0;
                gains.push(k);
            }
        }
        GainTable::new(speeds, pressures, gains).expect("valid")
    }

    #[test]
    fn bilinear_is_exact_for_bilinear_data_and_clamps_outside() {
        let t = table();
        let k = t.lookup(150.0, 45e3, Interpolation::Bilinear);
        assert!((k[0] - (150.0 + 45.0)).abs() < 1e-12, "{}", k[0]);
        let k = t.lookup(300.0, 59e3, Interpolation::Bilinear);
        assert!((k[0] - (300.0 + 59.0)).abs() < 1e-12);
        // Clamped to the edges (and NaN to the first node).
        assert_eq!(t.lookup(1000.0, 1e6, Interpolation::Bilinear)[0], 460.0);
        assert_eq!(t.lookup(0.0, 0.0, Interpolation::Bilinear)[0], 130.0);
        assert_eq!(
            t.lookup(f64::NAN, f64::NAN, Interpolation::Bilinear)[0],
            130.0
        );
    }

    #[test]
    fn nearest_picks_the_closest_node() {
        let t = table();
        assert_eq!(t.lookup(140.0, 40e3, Interpolation::Nearest)[0], 130.0);
        assert_eq!(t.lookup(160.0, 50e3, Interpolation::Nearest)[0], 260.0);
        assert_eq!(t.lookup(390.0, 31e3, Interpolation::Nearest)[0], 430.0);
    }

    #[test]
    fn bad_tables_are_refused() {
        let g = vec![SMatrix::<f64, N_STATES_AUGMENTED, 1>::zeros(); 2];
        assert!(matches!(
            GainTable::new(vec![2.0, 1.0], vec![1.0], g.clone()),
            Err(GainTableError::Axis {
                axis: "speeds_rad_s",
                ..
            })
        ));
        assert!(matches!(
            GainTable::new(vec![1.0, 2.0], vec![1.0, 2.0], g.clone()),
            Err(GainTableError::Shape {
                got: 2,
                want: 4,
                ..
            })
        ));
        let mut bad = g;
        bad[1][3] = f64::NAN;
        assert!(matches!(
            GainTable::new(vec![1.0, 2.0], vec![5.0], bad),
            Err(GainTableError::NonFinite { speed_rad_s, .. }) if speed_rad_s == 2.0
        ));
    }
}
