//! Piecewise-affine model of an automotive electronic throttle (DC motor, gears, return spring,
//! friction), after the wattmeter UKF paper (shared/REFERENCE.md §1, Table I), sampled at 1 ms.
//!
//! State `x = [0.1 theta, rho, i]`: `theta` the plate angle (deg), scaled by
//! [`ThrottleParams::angle_scale`]; `rho` the angular velocity in the identified model's own
//! units; `i` the motor current (A). Input: motor voltage `u` (V). In mode `s`, chosen by the
//! angle (`[0, 8]`, `(8, 16]`, `(16, 90]` deg):
//!
//! ```text
//! x+ = A_s x + [0, 0, b_s]' u + [0, c1_s sgn(rho) + c2_s sgn(theta - theta_sw) + c3_s, 0]'
//! ```
//!
//! How we read the paper's ambiguous points:
//! - `sgn(theta - 1)`: `theta` is the angle in **degrees**, so the term switches at 1 deg
//!   (`theta_sw` = [`ThrottleParams::friction_switch_deg`]), near the closed stop where a
//!   return-spring preload acts. With that reading each mode's static map `theta(u)` is one
//!   affine piece, and the three bands join up: mode 1 for u = 0.20..0.29 V, mode 2 for
//!   0.30..0.38 V, mode 3 from 0.34 V (a small hysteresis with mode 2). Reading it as the scaled
//!   state (a switch at 10 deg) would instead put a 7 deg jump in mode 2's static map in the
//!   middle of its band. The unit test `static_map_bands_join_up` checks these figures.
//! - `sgn(0) = 0`: at rest the Coulomb term vanishes.
//! - The plate lives in `[0, 90]` deg. A step that would leave the range puts the plate on the
//!   stop and zeroes its velocity (an inelastic stop); [`TransitionModel::constrain`] does this,
//!   so the truth simulation and every filter use the same rule.
//! - The mode is chosen from the angle at the start of the step (the paper's `theta_k in Theta_s`).

use nalgebra::{Matrix3, SMatrix, Vector1, Vector2, Vector3};
use serde::Deserialize;

use crate::model::{ObservationModel, TransitionModel};
use crate::param::{show, ParamError};

/// Identified coefficients of one mode (Table I). Dimensionless except as implied by the state
/// units: `b` maps volts to amperes per step, `c*` act on `rho`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThrottleMode {
    pub a12: f64,
    pub a21: f64,
    pub a22: f64,
    pub a23: f64,
    pub a32: f64,
    pub a33: f64,
    pub b: f64,
    pub c1: f64,
    pub c2: f64,
    pub c3: f64,
}

impl ThrottleMode {
    /// The coefficients with their keys, in Table I order.
    pub fn coefficients(&self) -> [(&'static str, f64); 10] {
        [
            ("a12", self.a12),
            ("a21", self.a21),
            ("a22", self.a22),
            ("a23", self.a23),
            ("a32", self.a32),
            ("a33", self.a33),
            ("b", self.b),
            ("c1", self.c1),
            ("c2", self.c2),
            ("c3", self.c3),
        ]
    }

    /// `A_s` of the mode.
    pub fn a(&self) -> Matrix3<f64> {
        Matrix3::new(
            1.0, self.a12, 0.0, self.a21, self.a22, self.a23, 0.0, self.a32, self.a33,
        )
    }
}

/// Throttle model parameters (loaded from `config/throttle.toml`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThrottleParams {
    /// Sampling period (s) the coefficients were identified for.
    pub dt_s: f64,
    /// `x[0] = angle_scale * theta_deg`.
    pub angle_scale: f64,
    /// Upper angle (deg) of mode 1 and of mode 2; mode 3 is above.
    #[serde(deserialize_with = "crate::param::exact_array")]
    pub mode_upper_deg: [f64; 2],
    /// Mechanical stops (deg).
    #[serde(deserialize_with = "crate::param::exact_array")]
    pub angle_limits_deg: [f64; 2],
    /// Angle (deg) at which the `c2 sgn(theta - theta_sw)` spring-preload term changes sign.
    pub friction_switch_deg: f64,
    /// Modes 1, 2, 3 (exactly three `[[model.modes]]` tables).
    #[serde(deserialize_with = "crate::param::exact_array")]
    pub modes: [ThrottleMode; 3],
}

/// Admissible ranges of the `[model]` keys.
pub mod ranges {
    use crate::param::Range;

    /// `dt_s`: from 10 us (a truth simulation over seconds takes 1e5 steps per second) to 1 s.
    pub const DT_S: Range = Range::closed(1e-5, 1.0, "s");
    /// `angle_scale`.
    pub const ANGLE_SCALE: Range = Range::above(0.0, 1e3, "");
    /// Angles (`mode_upper_deg`, `angle_limits_deg`, `friction_switch_deg`): one turn either way.
    pub const ANGLE_DEG: Range = Range::closed(-360.0, 360.0, "deg");
    /// Table I coefficients: identified discrete-time coefficients are of order 1 (Table I's
    /// largest is 1.89); signed, and zero is admissible.
    pub const COEFFICIENT: Range = Range::closed(-1e3, 1e3, "");
}

impl ThrottleParams {
    /// Checks every key against its range ([`ranges`]) and the order of the angles, naming the
    /// offending key relative to the `[model]` table (`dt_s`, `modes[2].a12`).
    pub fn validate(&self) -> Result<(), ParamError> {
        ranges::DT_S.check("dt_s", self.dt_s)?;
        ranges::ANGLE_SCALE.check("angle_scale", self.angle_scale)?;
        for (i, v) in self.mode_upper_deg.iter().enumerate() {
            ranges::ANGLE_DEG.check(&format!("mode_upper_deg[{i}]"), *v)?;
        }
        for (i, v) in self.angle_limits_deg.iter().enumerate() {
            ranges::ANGLE_DEG.check(&format!("angle_limits_deg[{i}]"), *v)?;
        }
        ranges::ANGLE_DEG.check("friction_switch_deg", self.friction_switch_deg)?;
        let [lo, hi] = self.angle_limits_deg;
        let [m1, m2] = self.mode_upper_deg;
        // Each in turn must lie above the one before: name the first that does not.
        let order = [
            ("angle_limits_deg[0]", lo),
            ("mode_upper_deg[0]", m1),
            ("mode_upper_deg[1]", m2),
            ("angle_limits_deg[1]", hi),
        ];
        for w in order.windows(2) {
            let ((before, b), (key, v)) = (w[0], w[1]);
            if !(v > b) {
                return Err(ParamError::new(
                    key,
                    show(v),
                    format!(
                        "must be above `{before}` = {} (angle_limits_deg[0] < mode_upper_deg[0] < mode_upper_deg[1] < angle_limits_deg[1])",
                        show(b)
                    ),
                ));
            }
        }
        for (s, m) in self.modes.iter().enumerate() {
            for (name, v) in m.coefficients() {
                ranges::COEFFICIENT.check(&format!("modes[{s}].{name}"), v)?;
            }
        }
        Ok(())
    }
}

/// The throttle dynamics (a [`TransitionModel`] with one input, the motor voltage).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThrottleModel {
    params: ThrottleParams,
}

/// Index (0, 1, 2) of the mode active at angle `theta_deg`.
#[inline]
pub fn mode_index(params: &ThrottleParams, theta_deg: f64) -> usize {
    if theta_deg <= params.mode_upper_deg[0] {
        0
    } else if theta_deg <= params.mode_upper_deg[1] {
        1
    } else {
        2
    }
}

/// `sgn` of the model's sign terms: 0 at 0.
pub(crate) fn sgn(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

impl ThrottleModel {
    /// Wraps validated parameters.
    pub fn new(params: ThrottleParams) -> Result<Self, String> {
        params.validate().map_err(|e| e.to_string())?;
        Ok(Self { params })
    }

    /// The parameters.
    pub fn params(&self) -> &ThrottleParams {
        &self.params
    }

    /// Plate angle (deg) of a state.
    #[inline]
    pub fn angle_deg(&self, x: &Vector3<f64>) -> f64 {
        x[0] / self.params.angle_scale
    }

    /// Scaled state component for an angle (deg).
    pub fn scaled_angle(&self, theta_deg: f64) -> f64 {
        theta_deg * self.params.angle_scale
    }

    /// Mode index (0..3) active in state `x`.
    pub fn mode(&self, x: &Vector3<f64>) -> usize {
        mode_index(&self.params, self.angle_deg(x))
    }

    /// How far (deg) the next step's angle could differ if the plate at `theta_deg`, with a
    /// velocity state of magnitude up to `rho_abs`, were in another mode whose band lies within
    /// `margin_deg`: `|a12_s' - a12_s| rho_abs`. The identified modes scale the velocity state
    /// differently (a12 is -0.003, 0.0021 and 0.0442 in Table I), so a fast plate crossing a
    /// mode boundary jumps by degrees in one step, and an estimate a fraction of a degree off
    /// the boundary predicts the jump one step early or late. Below 16 deg the velocity state
    /// hardly moves the angle, so it is poorly observed there: give a bound, not the estimate.
    pub fn mode_switch_spread_deg(&self, theta_deg: f64, rho_abs: f64, margin_deg: f64) -> f64 {
        let theta = theta_deg;
        let s = mode_index(&self.params, theta);
        let lo = mode_index(&self.params, theta - margin_deg);
        let hi = mode_index(&self.params, theta + margin_deg);
        let a12 = self.params.modes[s].a12;
        (lo..=hi)
            .map(|t| (self.params.modes[t].a12 - a12).abs() * rho_abs)
            .fold(0.0, f64::max)
            / self.params.angle_scale
    }

    /// How far (A^2, the wattmeter's unit) the squared current could be off if the plate at
    /// `theta_deg` were in another mode whose band lies within `margin_deg`: the largest
    /// difference of the modes' static `(b u / (1 - a33))^2` under the voltage `u` (V). The
    /// identified modes give the motor different stall gains (1.32, 0.71 and 0.46 A/V in
    /// Table I), and a plate held at a mode boundary (the velocity state's scale and sign change
    /// there, so a plate pushed into the 8 deg boundary chatters on it) draws the current of
    /// whichever mode the plant is in while an estimate a fraction of a degree away relaxes
    /// towards another's. Zero away from the boundaries.
    pub fn mode_switch_current_spread(&self, theta_deg: f64, u: f64, margin_deg: f64) -> f64 {
        let lo = mode_index(&self.params, theta_deg - margin_deg);
        let hi = mode_index(&self.params, theta_deg + margin_deg);
        let sq = |t: usize| {
            let m = &self.params.modes[t];
            (m.b * u / (1.0 - m.a33)).powi(2)
        };
        let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
        for t in lo..=hi {
            let v = sq(t);
            min = min.min(v);
            max = max.max(v);
        }
        (max - min).max(0.0)
    }

    /// Steady state of mode `s` under constant voltage `u` (ignoring the stops and with
    /// `sgn(rho) = 0`), returned as the angle in degrees. Used to check how the modes join.
    pub fn static_angle_deg(&self, s: usize, u: f64, above_switch: bool) -> f64 {
        let m = &self.params.modes[s];
        let i = m.b * u / (1.0 - m.a33);
        let phi = m.c2 * if above_switch { 1.0 } else { -1.0 } + m.c3;
        let x1 = -(m.a23 * i + phi) / m.a21;
        x1 / self.params.angle_scale
    }
}

impl ThrottleModel {
    /// The state at rest under a constant voltage `u` (V): for each mode its static angle, and
    /// the mode whose angle band contains it (the bands join up, so normally exactly one does;
    /// in a gap the nearest band wins). Velocity zero, current `b u / (1 - a33)`, plate clamped to
    /// its stops. This is the throttle's static map, used to re-seed an estimator that has lost
    /// track (a stuck UKF can be re-seeded where the plate must be if it has settled).
    pub fn equilibrium(&self, u: f64) -> Vector3<f64> {
        let p = &self.params;
        let mut best = (f64::INFINITY, Vector3::zeros());
        for s in 0..3 {
            let mut theta = self.static_angle_deg(s, u, true);
            if theta < p.friction_switch_deg {
                theta = self.static_angle_deg(s, u, false);
            }
            let (lo, hi) = match s {
                0 => (f64::NEG_INFINITY, p.mode_upper_deg[0]),
                1 => (p.mode_upper_deg[0], p.mode_upper_deg[1]),
                _ => (p.mode_upper_deg[1], f64::INFINITY),
            };
            let distance = if theta < lo {
                lo - theta
            } else if theta > hi {
                theta - hi
            } else {
                0.0
            };
            if distance < best.0 {
                let m = &p.modes[s];
                let mut x = Vector3::new(theta * p.angle_scale, 0.0, m.b * u / (1.0 - m.a33));
                self.constrain(&mut x);
                best = (distance, x);
            }
        }
        best.1
    }
}

impl ThrottleModel {
    /// The transition (before the stops) in mode `mode`, which the caller has taken from the
    /// angle (the identification needs the mode for its sensitivities too).
    #[inline]
    pub fn transition_in(&self, x: &Vector3<f64>, u: f64, mode: usize) -> Vector3<f64> {
        let theta = self.angle_deg(x);
        let m = &self.params.modes[mode];
        let drift = m.c1 * sgn(x[1]) + m.c2 * sgn(theta - self.params.friction_switch_deg) + m.c3;
        Vector3::new(
            x[0] + m.a12 * x[1],
            m.a21 * x[0] + m.a22 * x[1] + m.a23 * x[2] + drift,
            m.a32 * x[1] + m.a33 * x[2] + m.b * u,
        )
    }
}

impl TransitionModel<3, 1> for ThrottleModel {
    #[inline]
    fn transition(&self, x: &Vector3<f64>, u: &Vector1<f64>) -> Vector3<f64> {
        self.transition_in(x, u[0], mode_index(&self.params, self.angle_deg(x)))
    }

    /// `A_s` of the active mode: the sign terms are piecewise constant, so their derivative is
    /// zero almost everywhere.
    fn transition_jacobian(&self, x: &Vector3<f64>, _u: &Vector1<f64>) -> Matrix3<f64> {
        self.params.modes[self.mode(x)].a()
    }

    #[inline]
    fn constrain(&self, x: &mut Vector3<f64>) {
        let [lo, hi] = self.params.angle_limits_deg;
        let (lo, hi) = (lo * self.params.angle_scale, hi * self.params.angle_scale);
        if x[0] < lo {
            x[0] = lo;
            x[1] = 0.0;
        } else if x[0] > hi {
            x[0] = hi;
            x[1] = 0.0;
        }
    }
}

/// Throttle position sensor: 0..90 deg maps linearly to 0..5 V.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionSensor {
    /// Volts per unit of the scaled angle state `x[0]`.
    volts_per_state: f64,
}

impl PositionSensor {
    /// Sensor with `full_scale_v` volts at `full_scale_deg` degrees, for a model whose state
    /// carries `angle_scale * theta`.
    pub fn new(full_scale_v: f64, full_scale_deg: f64, angle_scale: f64) -> Self {
        Self {
            volts_per_state: full_scale_v / full_scale_deg / angle_scale,
        }
    }

    /// Sensor voltage for a state.
    #[inline]
    pub fn volts(&self, x: &Vector3<f64>) -> f64 {
        self.volts_per_state * x[0]
    }
}

impl ObservationModel<3, 1, 1> for PositionSensor {
    #[inline]
    fn observe(&self, x: &Vector3<f64>, _u: &Vector1<f64>) -> Vector1<f64> {
        Vector1::new(self.volts(x))
    }

    fn observation_jacobian(&self, _x: &Vector3<f64>, _u: &Vector1<f64>) -> SMatrix<f64, 1, 3> {
        SMatrix::<f64, 1, 3>::new(self.volts_per_state, 0.0, 0.0)
    }

    fn affine_observation(&self, _u: &Vector1<f64>) -> Option<(SMatrix<f64, 1, 3>, Vector1<f64>)> {
        Some((
            SMatrix::<f64, 1, 3>::new(self.volts_per_state, 0.0, 0.0),
            Vector1::zeros(),
        ))
    }
}

/// Wattmeter on the motor supply: `y = i^2` (power into a unit resistance, A^2). It cannot tell
/// the sign of the current.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Wattmeter;

impl ObservationModel<3, 1, 1> for Wattmeter {
    #[inline]
    fn observe(&self, x: &Vector3<f64>, _u: &Vector1<f64>) -> Vector1<f64> {
        Vector1::new(x[2] * x[2])
    }

    fn observation_jacobian(&self, x: &Vector3<f64>, _u: &Vector1<f64>) -> SMatrix<f64, 1, 3> {
        SMatrix::<f64, 1, 3>::new(0.0, 0.0, 2.0 * x[2])
    }
}

/// Position sensor and wattmeter together: `y = [volts, i^2]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionAndWattmeter {
    pub position: PositionSensor,
}

impl ObservationModel<3, 2, 1> for PositionAndWattmeter {
    #[inline]
    fn observe(&self, x: &Vector3<f64>, _u: &Vector1<f64>) -> Vector2<f64> {
        Vector2::new(self.position.volts(x), x[2] * x[2])
    }

    fn observation_jacobian(&self, x: &Vector3<f64>, _u: &Vector1<f64>) -> SMatrix<f64, 2, 3> {
        SMatrix::<f64, 2, 3>::new(
            self.position.volts_per_state,
            0.0,
            0.0,
            0.0,
            0.0,
            2.0 * x[2],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table1() -> ThrottleParams {
        let m = |v: [f64; 10]| ThrottleMode {
            a12: v[0],
            a21: v[1],
            a22: v[2],
            a23: v[3],
            a32: v[4],
            a33: v[5],
            b: v[6],
            c1: v[7],
            c2: v[8],
            c3: v[9],
        };
        ThrottleParams {
            dt_s: 1e-3,
            angle_scale: 0.1,
            mode_upper_deg: [8.0, 16.0],
            angle_limits_deg: [0.0, 90.0],
            friction_switch_deg: 1.0,
            modes: [
                m([
                    -0.003, 0.148, 0.9625, -0.8673, 0.0005, 0.944, 0.0741, -0.0654, -0.007, 0.2255,
                ]),
                m([
                    0.0021, -0.143, 0.9941, 1.8944, -0.0004, 0.9514, 0.0346, -0.1068, 0.0529,
                    -0.3419,
                ]),
                m([
                    0.0442, -0.0192, 0.7981, 0.3538, 0.0349, 0.9043, 0.0442, -0.0055, 0.0615,
                    -0.0862,
                ]),
            ],
        }
    }

    #[test]
    fn static_map_bands_join_up() {
        let model = ThrottleModel::new(table1()).expect("valid");
        // Reading sgn(theta - 1) in degrees: every mode has voltages whose static angle lies in
        // its own band, and the voltage ranges of neighbouring bands meet (within 0.02 V).
        let band = |s: usize| -> (f64, f64) {
            let hits: Vec<f64> = (0..=12_000)
                .map(|k| k as f64 * 1e-4)
                .filter(|&u| {
                    let th = model.static_angle_deg(s, u, true);
                    let (lo, hi) = [(1.0, 8.0), (8.0, 16.0), (16.0, 90.0)][s];
                    th > lo && th <= hi
                })
                .collect();
            (hits[0], hits[hits.len() - 1])
        };
        let (b1, b2, b3) = (band(0), band(1), band(2));
        assert!(
            (b1.1 - b2.0).abs() < 0.02,
            "mode 1 ends {b1:?}, mode 2 starts {b2:?}"
        );
        assert!(
            (b2.1 - b3.0).abs() < 0.05,
            "mode 2 ends {b2:?}, mode 3 starts {b3:?}"
        );
        // The 72 deg at 1 V noted in REFERENCE.md.
        assert!((model.static_angle_deg(2, 1.0, true) - 72.2).abs() < 0.5);
        // The scaled reading (switch at 10 deg) would split mode 2's static map into two affine
        // pieces 7 deg apart at 10 deg; the degree reading keeps one piece per mode.
        let jump = model.static_angle_deg(1, 0.4, true) - model.static_angle_deg(1, 0.4, false);
        assert!((jump - 7.4).abs() < 0.1, "jump {jump}");
    }

    #[test]
    fn a_mode_switch_spread_appears_only_near_a_boundary() {
        let model = ThrottleModel::new(table1()).expect("valid");
        let m = &model.params().modes;
        // 0.5 deg below 16 deg with the velocity state at 10: mode 3 is within the margin.
        let near = model.mode_switch_spread_deg(15.5, 10.0, 1.5);
        let expect = (m[2].a12 - m[1].a12).abs() * 10.0 / model.params().angle_scale;
        assert!((near - expect).abs() < 1e-12, "{near} vs {expect}");
        assert!(near > 4.0, "a 16 deg crossing at rho = 10 jumps {near} deg");
        // Far from every boundary, or at rest, nothing.
        assert_eq!(model.mode_switch_spread_deg(40.0, 10.0, 1.5), 0.0);
        assert_eq!(model.mode_switch_spread_deg(15.5, 0.0, 1.5), 0.0);
        // Near 8 deg the modes differ little in a12.
        let low = model.mode_switch_spread_deg(8.5, 10.0, 1.5);
        assert!(low > 0.0 && low < 1.0, "{low}");
    }

    #[test]
    fn a_current_spread_appears_only_near_a_boundary_and_grows_with_the_voltage() {
        let model = ThrottleModel::new(table1()).expect("valid");
        let m = &model.params().modes;
        let stall = |t: usize, u: f64| (m[t].b * u / (1.0 - m[t].a33)).powi(2);
        // Just below 8 deg at 1 V: modes 1 and 2, whose stall gains are 1.32 and 0.71 A/V.
        let near = model.mode_switch_current_spread(7.9, 1.0, 1.5);
        let expect = stall(0, 1.0) - stall(1, 1.0);
        assert!((near - expect).abs() < 1e-12, "{near} vs {expect}");
        assert!(near > 1.0, "{near} A^2 at 1 V");
        // Quadratic in the voltage, and zero at 0 V.
        let half = model.mode_switch_current_spread(7.9, 0.5, 1.5);
        assert!((half - 0.25 * near).abs() < 1e-12, "{half}");
        assert_eq!(model.mode_switch_current_spread(7.9, 0.0, 1.5), 0.0);
        // Within one mode's band, nothing.
        assert_eq!(model.mode_switch_current_spread(40.0, 1.0, 1.5), 0.0);
        assert_eq!(model.mode_switch_current_spread(4.0, 1.0, 1.5), 0.0);
        // Near 16 deg, modes 2 and 3.
        let upper = model.mode_switch_current_spread(16.5, 1.0, 1.5);
        assert!(
            (upper - (stall(1, 1.0) - stall(2, 1.0))).abs() < 1e-12,
            "{upper}"
        );
    }

    #[test]
    fn equilibrium_is_a_fixed_point_inside_its_band() {
        let model = ThrottleModel::new(table1()).expect("valid");
        for &u in &[0.25, 0.34, 0.6, 1.0] {
            let x = model.equilibrium(u);
            let mut y = x;
            for _ in 0..5000 {
                y = model.transition(&y, &Vector1::new(u));
                model.constrain(&mut y);
            }
            let (a, b) = (model.angle_deg(&x), model.angle_deg(&y));
            assert!(
                (a - b).abs() < 1.0,
                "u = {u}: static map {a} deg, simulated {b} deg"
            );
        }
        // Below ~0.19 V the spring holds the plate on its lower stop.
        assert_eq!(model.angle_deg(&model.equilibrium(0.05)), 0.0);
    }

    #[test]
    fn stops_clamp_angle_and_stop_the_plate() {
        let model = ThrottleModel::new(table1()).expect("valid");
        let mut x = Vector3::new(-0.3, 5.0, 0.2);
        model.constrain(&mut x);
        assert_eq!(x, Vector3::new(0.0, 0.0, 0.2));
        let mut x = Vector3::new(9.4, -2.0, 0.2);
        model.constrain(&mut x);
        assert_eq!(x, Vector3::new(9.0, 0.0, 0.2));
        let mut x = Vector3::new(4.0, -2.0, 0.2);
        model.constrain(&mut x);
        assert_eq!(x, Vector3::new(4.0, -2.0, 0.2));
    }

    #[test]
    fn modes_follow_the_angle_bands_and_sensors_scale() {
        let model = ThrottleModel::new(table1()).expect("valid");
        assert_eq!(model.mode(&Vector3::new(0.8, 0.0, 0.0)), 0);
        assert_eq!(model.mode(&Vector3::new(0.81, 0.0, 0.0)), 1);
        assert_eq!(model.mode(&Vector3::new(1.6, 0.0, 0.0)), 1);
        assert_eq!(model.mode(&Vector3::new(1.61, 0.0, 0.0)), 2);
        let tps = PositionSensor::new(5.0, 90.0, 0.1);
        assert!((tps.volts(&Vector3::new(9.0, 0.0, 0.0)) - 5.0).abs() < 1e-12);
        assert!((tps.volts(&Vector3::new(4.5, 0.0, 0.0)) - 2.5).abs() < 1e-12);
        let y = Wattmeter.observe(&Vector3::new(1.0, 0.0, -1.5), &Vector1::new(0.0));
        assert_eq!(y[0], 2.25);
    }

    #[test]
    fn invalid_parameters_name_the_key() {
        let mut p = table1();
        p.mode_upper_deg = [20.0, 16.0];
        assert!(ThrottleModel::new(p)
            .unwrap_err()
            .contains("mode_upper_deg"));
        let mut p = table1();
        p.dt_s = 0.0;
        assert!(ThrottleModel::new(p).unwrap_err().contains("dt_s"));
        let mut p = table1();
        p.modes[1].a23 = f64::NAN;
        assert!(ThrottleModel::new(p).unwrap_err().contains("modes[1]"));
    }
}
