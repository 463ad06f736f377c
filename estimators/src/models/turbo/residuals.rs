//! Structural residuals of the intake side: three air-flow balances, each computed from the
//! model's own components at the *measured* pressures and temperatures, so that each leaves one
//! of the three intake-side sensors out and a fault of that sensor leaves it untouched.
//!
//! With the sensors `p_ic` (boost, throttle inlet), `T_ic`, `p_im` (manifold) and `W_af` (MAF)
//! and the inputs (engine speed, throttle, ambient), the model gives two flows without any
//! state estimate:
//!
//! - the **cylinder flow** `W_cyl(p_im, T_ic, N)` (volumetric efficiency; the manifold
//!   temperature is taken as the intercooler's: the LiU-ICE engine has no manifold temperature
//!   sensor, and adiabatic mixing keeps them within a few kelvin at steady state);
//! - the **throttle flow** `W_thr(p_ic, T_ic, p_im, throttle)` (compressible nozzle).
//!
//! In steady state all three flows are equal (the MAF sees the air the cylinders take; the
//! volumes' filling `V/(R T) dp/dt` averages out over a filtered residual), so
//!
//! | residual | balance | `p_ic` | `p_im` | `W_af` | `T_ic` | leak before throttle | leak after throttle | throttle area |
//! |---|---|---|---|---|---|---|---|---|
//! | `r_cyl` | `W_af - W_cyl` | 0 | X | X | X | X | X | 0 |
//! | `r_thr` | `W_af - W_thr` | X | (X) | X | X | X | 0 | X |
//! | `r_tc`  | `W_thr - W_cyl` | X | X | 0 | X | 0 | X | X |
//!
//! ([`SIGNATURE`]; `(X)`: `W_thr` depends on `p_im` only while the throttle is not choked.)
//! Each sensor fault leaves exactly one residual untouched: `p_ic` leaves `r_cyl`, `W_af` leaves
//! `r_tc`, and `p_im` leaves `r_thr` when the throttle is choked (otherwise none; its column
//! then differs from the others by having all three). A leak before the throttle looks like a
//! MAF fault in the signature (the MAF measures air the cylinders do not get) and a leak after
//! it like a `p_im` fault with the throttle choked; these are told apart by how the residual
//! scales with the operating point (a sensor gain scales with the reading; a leak with the
//! pressure across the hole), which the isolation does by fitting each hypothesis' size.
//!
//! The exhaust pressure enters the cylinder flow through the residual-gas term; it is not
//! measured, and [`ExhaustPressure`] says where it comes from: the ambient pressure (what the
//! LiU-ICE calibration assumed when fitting the volumetric efficiency) or an estimate (the
//! observer's, coupled to the sensors only through the exhaust side).
//!
//! Pure math; no allocation.

use super::{TurboInput, TurboModel, TurboSignals, TurboState, X_OMEGA_T, X_T_EM, X_T_ES};

/// The three residuals' sensitivity to each fault: rows [`R_CYL`], [`R_THR`], [`R_TC`]; columns
/// [`FAULTS`]. 2 = sensitive always, 1 = sensitive while the throttle is not choked, 0 = not.
pub const SIGNATURE: [[u8; 7]; 3] = [
    [0, 2, 2, 2, 2, 2, 0],
    [2, 1, 2, 2, 2, 0, 2],
    [2, 2, 0, 2, 0, 2, 2],
];
/// The faults of [`SIGNATURE`]'s columns.
pub const FAULTS: [&str; 7] = [
    "p_ic sensor",
    "p_im sensor",
    "air mass flow sensor",
    "T_ic sensor",
    "leak before the throttle",
    "leak after the throttle",
    "throttle area",
];
/// Row of `W_af - W_cyl`.
pub const R_CYL: usize = 0;
/// Row of `W_af - W_thr`.
pub const R_THR: usize = 1;
/// Row of `W_thr - W_cyl`.
pub const R_TC: usize = 2;

/// The measured intake side and the inputs, SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntakeReadings {
    /// Boost pressure after the intercooler (Pa).
    pub p_ic_pa: f64,
    /// Temperature after the intercooler (K).
    pub t_ic_k: f64,
    /// Intake manifold pressure (Pa).
    pub p_im_pa: f64,
    /// Air mass flow (kg/s).
    pub maf_kg_s: f64,
}

/// Where the exhaust manifold pressure of the cylinder flow's residual-gas term comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ExhaustPressure {
    /// The ambient pressure of the input.
    Ambient,
    /// An estimate: exhaust manifold and system pressures (Pa), their temperatures (K) and the
    /// turbo speed (rad/s), e.g. from the observer's state.
    Estimate {
        /// Exhaust manifold pressure (Pa).
        p_em_pa: f64,
        /// Exhaust manifold temperature (K).
        t_em_k: f64,
        /// Exhaust system pressure (Pa).
        p_es_pa: f64,
        /// Exhaust system temperature (K).
        t_es_k: f64,
        /// Turbo speed (rad/s).
        omega_t_rad_s: f64,
    },
}

impl ExhaustPressure {
    /// The exhaust side of an estimated state.
    pub fn from_state(model: &TurboModel, x: &TurboState) -> Self {
        let p = model.pressures(x);
        ExhaustPressure::Estimate {
            p_em_pa: p[4],
            t_em_k: x[X_T_EM],
            p_es_pa: p[5],
            t_es_k: x[X_T_ES],
            omega_t_rad_s: x[X_OMEGA_T],
        }
    }
}

/// The two model flows at the readings and the three balances (kg/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlowBalance {
    /// Cylinder flow from `p_im` (kg/s).
    pub w_cyl_kg_s: f64,
    /// Throttle flow from `p_ic`, `p_im` and the throttle (kg/s).
    pub w_thr_kg_s: f64,
    /// `[W_af - W_cyl, W_af - W_thr, W_thr - W_cyl]` (kg/s), rows of [`SIGNATURE`].
    pub residuals: [f64; 3],
}

/// The model state whose intake-side volumes hold the readings (the air filter at ambient, the
/// compressor outlet at the boost pressure, every intake temperature the intercooler's) and
/// whose exhaust side is `exhaust` (or ambient pressure, 900 K and the lowest turbo speed).
pub fn reading_state(
    model: &TurboModel,
    r: &IntakeReadings,
    u: &TurboInput,
    exhaust: &ExhaustPressure,
) -> TurboState {
    let (p_em, t_em, p_es, t_es, omega) = match *exhaust {
        ExhaustPressure::Ambient => (
            u.ambient_pressure_pa,
            900.0,
            u.ambient_pressure_pa,
            800.0,
            model.params().turbo_speed_min_rad_s,
        ),
        ExhaustPressure::Estimate {
            p_em_pa,
            t_em_k,
            p_es_pa,
            t_es_k,
            omega_t_rad_s,
        } => (p_em_pa, t_em_k, p_es_pa, t_es_k, omega_t_rad_s),
    };
    model.state_from_pressures(
        [
            u.ambient_pressure_pa,
            r.p_ic_pa,
            r.p_ic_pa,
            r.p_im_pa,
            p_em,
            p_es,
        ],
        [
            u.ambient_temperature_k,
            r.t_ic_k,
            r.t_ic_k,
            r.t_ic_k,
            t_em,
            t_es,
        ],
        omega,
    )
}

/// The flow balance at the readings (see the module docs).
pub fn flow_balance(
    model: &TurboModel,
    r: &IntakeReadings,
    u: &TurboInput,
    exhaust: &ExhaustPressure,
) -> FlowBalance {
    let x = reading_state(model, r, u, exhaust);
    let s: TurboSignals = model.signals(&x, u);
    let w_cyl = s.w_ei_kg_s;
    let w_thr = s.w_thr_kg_s;
    FlowBalance {
        w_cyl_kg_s: w_cyl,
        w_thr_kg_s: w_thr,
        residuals: [r.maf_kg_s - w_cyl, r.maf_kg_s - w_thr, w_thr - w_cyl],
    }
}

/// Whether the throttle is choked at the readings: its flow does not move with `p_im` (its
/// derivative by the manifold mass is zero), so `r_thr` leaves the `p_im` sensor out
/// ([`SIGNATURE`]'s 1 entries). Computes the model's gradient: a separate call from
/// [`flow_balance`], which the monitor runs every frame without needing it.
pub fn throttle_choked(
    model: &TurboModel,
    r: &IntakeReadings,
    u: &TurboInput,
    exhaust: &ExhaustPressure,
) -> bool {
    let x = reading_state(model, r, u, exhaust);
    let g = model.signals_with_gradient(&x, u);
    g.w_thr_kg_s.d[super::X_M_IM] == 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The generic TCSI set.
    fn model() -> TurboModel {
        crate::models::turbo::model_from_file_text(include_str!("../../../../config/turbo.toml"))
    }

    fn input(throttle_pct: f64, rpm: f64) -> TurboInput {
        TurboInput {
            throttle_pct,
            engine_speed_rad_s: rpm * std::f64::consts::PI / 30.0,
            wastegate_frac: 0.5,
            lambda: 1.0,
            ambient_pressure_pa: 101_300.0,
            ambient_temperature_k: 298.0,
        }
    }

    /// At a stationary point of the model itself, with its own p_em, the three balances are 0;
    /// a gain on one sensor moves exactly the residuals its column says.
    #[test]
    fn balances_vanish_at_stationary_points_and_each_sensor_fault_spares_its_residual() {
        let m = model();
        for (th, rpm) in [(15.0, 1500.0), (30.0, 2500.0), (100.0, 3000.0)] {
            let u = input(th, rpm);
            let x = m.stationary_point(&u, None).expect("stationary").state;
            let s = m.signals(&x, &u);
            let ex = ExhaustPressure::from_state(&m, &x);
            let r = IntakeReadings {
                p_ic_pa: s.p_ic_pa,
                t_ic_k: s.t_ic_k,
                p_im_pa: s.p_im_pa,
                maf_kg_s: s.w_af_kg_s,
            };
            let b = flow_balance(&m, &r, &u, &ex);
            let scale = s.w_af_kg_s;
            // T_im differs from T_ic by the throttle's mixing only: within 2 %.
            for v in b.residuals {
                assert!(v.abs() < 0.02 * scale, "{th} % {rpm} rpm: {b:?}");
            }
            let gains = [(0usize, 1.1), (1, 1.1), (2, 1.1)];
            for (sensor, g) in gains {
                let mut rf = r;
                match sensor {
                    0 => rf.p_ic_pa *= g,
                    1 => rf.p_im_pa *= g,
                    _ => rf.maf_kg_s *= g,
                }
                let bf = flow_balance(&m, &rf, &u, &ex);
                for (row, sig) in SIGNATURE.iter().enumerate() {
                    let moved = (bf.residuals[row] - b.residuals[row]).abs() > 1e-3 * scale;
                    let expected = match sig[sensor] {
                        0 => false,
                        1 => !throttle_choked(&m, &r, &u, &ex),
                        _ => true,
                    };
                    assert_eq!(
                        moved, expected,
                        "{th} % {rpm} rpm, sensor {sensor}, residual {row}: {b:?} -> {bf:?}"
                    );
                }
            }
        }
    }
}
