//! Mean value model of the air path of a turbocharged spark-ignition engine: 13 states, after
//! Eriksson (2007) and the observer paper (shared/REFERENCE.md §4, seeds/004): the mass and
//! temperature of six adiabatic control volumes and the turbo speed. The monitor will linearize
//! it at engine-map points and run an observer on it at 20 Hz (LiU-ICE logs, 50 ms) or about
//! 100 Hz; [`discrete`] holds the step for those rates.
//!
//! # States (indices `X_*`), SI units
//!
//! | index | state | | index | state |
//! |---|---|---|---|---|
//! | [`X_M_AF`] | air filter mass (kg) | | [`X_T_AF`] | its temperature (K) |
//! | [`X_M_C`] | compressor outlet mass | | [`X_T_C`] | temperature |
//! | [`X_M_IC`] | intercooler / throttle inlet mass | | [`X_T_IC`] | temperature |
//! | [`X_M_IM`] | intake manifold mass | | [`X_T_IM`] | temperature |
//! | [`X_M_EM`] | exhaust manifold mass | | [`X_T_EM`] | temperature |
//! | [`X_M_ES`] | exhaust system (after the turbine) mass | | [`X_T_ES`] | temperature |
//! | [`X_OMEGA_T`] | turbo speed (rad/s) | | [`X_DC_ETA_VOL`] | augmented: `dC_eta_vol` (-) |
//!
//! The pressures follow, `p = M R T / V`. Mass and temperature rather than pressure and
//! temperature because they are what the balances conserve: `dM/dt` is exactly the flow
//! difference, which the mass-conservation test checks to 1e-9.
//!
//! # Inputs ([`TurboInput`], or a vector with indices `U_*`)
//!
//! Throttle position (%), engine speed (rad/s), wastegate position (0 closed .. 1 open),
//! lambda, ambient pressure (Pa) and temperature (K).
//!
//! **Lambda, not the fuel flow**, is the input, as in the paper: the fuel only enters the
//! exhaust flow, `W_f = W_ei / (AFs lambda)` (6.6 % of it at lambda 1), so the model needs no
//! fuel measurement, and an SI engine under closed-loop lambda control runs at lambda 1 where
//! none is logged. The LiU-ICE logs have no lambda and an `injected_fuel_mass` whose unit is not
//! stated (its ratio to the air flow varies from 4.5 to 18 in the fault-free window, so it is not
//! kg/s at lambda 1); TSFS09 logs lambda. A caller with a trusted fuel flow passes
//! `lambda = W_air / (AFs W_f)`.
//!
//! # Outputs
//!
//! [`TurboModel::signals`] returns every pressure, temperature and flow ([`TurboSignals`]): the
//! sensors of the LiU engines (`p_ic`, `T_ic`, `p_im`, `W_af`; TSFS09 also `p_em`, `T_c`, `p_c`,
//! turbo speed) and the intermediate flows, for the observer to pick its output matrix from.
//! [`TurboModel::evaluate`] is the same evaluation generic over the scalar: with [`ad::Dual`]
//! seeds it gives the gradient of any output.
//!
//! # The components (each module states its formulas and our rules where REFERENCE is silent)
//!
//! [`restriction`] (air filter, intercooler, exhaust system), [`compressor`], [`throttle`],
//! [`cylinder`] (volumetric efficiency, fuel, exhaust temperature with the pipe heat loss),
//! [`turbine`], [`wastegate`], [`shaft`], [`volumes`] (mass and energy balances), [`dynamics`]
//! (assembled right-hand side), [`stationary`] (operating points by pseudo-transient
//! continuation), [`discrete`] (the step: SDIRK2 with Newton, and its transition matrix),
//! [`ad`] (forward-mode automatic differentiation for the exact Jacobians), [`params`];
//! [`fit`] calibrates the parameters to stationary engine-map data (`fdd fit turbo`).
//!
//! # Decisions where REFERENCE §4 is ambiguous
//!
//! - Turbine `k1` "p in kPa": `W_t = k1 p_em[kPa] / sqrt(T_em[K]) sqrt(1 - Pi_t^k2)` (only kPa
//!   gives a plausible flow, see [`turbine`]).
//! - Compressor tip speed `U_c = omega_t D_c / 2` with `D_c` the wheel diameter (the generic
//!   set's "R_c 0.06" is the testbed's `compressor.D`; see [`compressor`]).
//! - Reversed flows carry the upstream volume's temperature at every connection, including the
//!   compressor and the turbine, which then exchange no work with the gas except that the
//!   compressor still absorbs `|W_c|` times its head (see [`volumes`], [`compressor`],
//!   [`turbine`]).
//! - The turbo speed limits are a saturated integrator ([`shaft`]).
//! - Infinite slopes (`sqrt` at zero pressure drop, the nozzle and turbine flow functions at
//!   `Pi = 1`, the ellipse at `Psi_max`) are all replaced near the singular point by a linear
//!   continuation, so that the Jacobian stays finite and the stiff step stays well posed.
//! - The compressor below `Psi = 0` (outlet below inlet) follows the hyperbola that continues
//!   the ellipse, rather than staying choked at `Phi_max` (see [`compressor`]).
//! - The volumetric-efficiency polynomial (VEP4) is evaluated at `p_im` clamped to its fitted
//!   range, 25 .. 230 kPa (see [`cylinder`]).
//! - The 14th state `dC_eta_vol` (paper §4.2): the evaluation takes the correction as an
//!   argument ([`TurboModel::evaluate`]), [`TurboModel::derivative`] and friends use 0, and the
//!   `*_augmented` methods and [`discrete::TurboDiscrete14`] implement the 14-state model with
//!   `d(dC_eta_vol)/dt = 0`. One evaluation serves both (no duplicated model), while each filter
//!   gets a plain fixed-size state: 13 for the plain observer, 14 for the augmented one.
//!
//! # Impossible states and inputs
//!
//! The evaluation never panics and never returns NaN, even for NaN components: a mass is
//! evaluated as at least `V` times [`dynamics::MIN_DENSITY_KG_M3`], a temperature within
//! [`dynamics::TEMPERATURE_RANGE_K`], the turbo speed within its limits, the inputs within the
//! ranges [`TurboModel::check_input`] accepts (NaN maps to the lower bound). [`TurboModel::check_state`] and
//! [`TurboModel::check_input`] name what is out of range; [`TurboModel::constrain`] moves a
//! state back into the physical set (what the filters do after each step).

pub mod ad;
pub mod compressor;
pub mod cylinder;
pub mod discrete;
pub mod dynamics;
pub mod fit;
pub mod isolation;
pub mod nozzle;
pub mod observer;
pub mod params;
pub mod residuals;
pub mod restriction;
pub mod shaft;
pub mod shaft_balance;
pub mod stationary;
pub mod throttle;
pub mod turbine;
pub mod volumes;
pub mod wastegate;

/// The model of a parameter file's `[model]` table (unit tests of the residual modules).
#[cfg(test)]
pub(crate) fn model_from_file_text(text: &str) -> TurboModel {
    #[derive(serde::Deserialize)]
    struct F {
        model: TurboParams,
    }
    let f: F = toml::from_str(text).expect("parses");
    TurboModel::new(f.model).expect("valid")
}

use std::sync::Arc;

use nalgebra::{SMatrix, SVector};
use thiserror::Error;

use crate::param::ParamError;
use ad::{Dual, Scalar};
use dynamics::Consts;
pub use dynamics::TurboSignals;
pub use params::TurboParams;

/// Number of states of the plain model.
pub const N_STATES: usize = 13;
/// Number of states of the augmented model.
pub const N_STATES_AUGMENTED: usize = 14;
/// Number of inputs.
pub const N_INPUTS: usize = 6;

/// Air filter volume mass (kg).
pub const X_M_AF: usize = 0;
/// Air filter volume temperature (K).
pub const X_T_AF: usize = 1;
/// Compressor outlet volume mass (kg).
pub const X_M_C: usize = 2;
/// Compressor outlet volume temperature (K).
pub const X_T_C: usize = 3;
/// Intercooler / throttle inlet volume mass (kg).
pub const X_M_IC: usize = 4;
/// Intercooler volume temperature (K).
pub const X_T_IC: usize = 5;
/// Intake manifold mass (kg).
pub const X_M_IM: usize = 6;
/// Intake manifold temperature (K).
pub const X_T_IM: usize = 7;
/// Exhaust manifold mass (kg).
pub const X_M_EM: usize = 8;
/// Exhaust manifold temperature (K).
pub const X_T_EM: usize = 9;
/// Exhaust system mass (kg).
pub const X_M_ES: usize = 10;
/// Exhaust system temperature (K).
pub const X_T_ES: usize = 11;
/// Turbo speed (rad/s).
pub const X_OMEGA_T: usize = 12;
/// The augmented state `dC_eta_vol` (-), additive correction of the volumetric-efficiency
/// factor, constant in the model.
pub const X_DC_ETA_VOL: usize = 13;

/// Short names of the 14 states, with units, for messages and tables.
pub const STATE_NAMES: [&str; N_STATES_AUGMENTED] = [
    "m_af (kg)",
    "T_af (K)",
    "m_c (kg)",
    "T_c (K)",
    "m_ic (kg)",
    "T_ic (K)",
    "m_im (kg)",
    "T_im (K)",
    "m_em (kg)",
    "T_em (K)",
    "m_es (kg)",
    "T_es (K)",
    "omega_t (rad/s)",
    "dC_eta_vol (-)",
];

/// Input index: throttle position (%).
pub const U_THROTTLE_PCT: usize = 0;
/// Input index: engine speed (rad/s).
pub const U_ENGINE_SPEED_RAD_S: usize = 1;
/// Input index: wastegate position (0 closed .. 1 open).
pub const U_WASTEGATE: usize = 2;
/// Input index: lambda (-).
pub const U_LAMBDA: usize = 3;
/// Input index: ambient pressure (Pa).
pub const U_AMBIENT_PRESSURE_PA: usize = 4;
/// Input index: ambient temperature (K).
pub const U_AMBIENT_TEMPERATURE_K: usize = 5;

/// Accepted throttle positions (%).
pub const THROTTLE_RANGE_PCT: (f64, f64) = (0.0, 100.0);
/// Accepted engine speeds (rad/s): stopped to 14 300 rpm.
pub const ENGINE_SPEED_RANGE_RAD_S: (f64, f64) = (0.0, 1500.0);
/// Accepted wastegate positions.
pub const WASTEGATE_RANGE: (f64, f64) = (0.0, 1.0);
/// Accepted lambda (rich full-load enrichment to lean burn).
pub const LAMBDA_RANGE: (f64, f64) = (0.5, 3.0);
/// Accepted ambient pressures (Pa).
pub const AMBIENT_PRESSURE_RANGE_PA: (f64, f64) = (1e4, 2e5);
/// Accepted ambient temperatures (K).
pub const AMBIENT_TEMPERATURE_RANGE_K: (f64, f64) = (200.0, 400.0);

/// The plain model's state.
pub type TurboState = SVector<f64, N_STATES>;
/// The augmented model's state (`dC_eta_vol` last).
pub type TurboStateAugmented = SVector<f64, N_STATES_AUGMENTED>;
/// The input as a vector (indices `U_*`), for the filter traits.
pub type TurboInputVector = SVector<f64, N_INPUTS>;

/// The model's inputs, with units in the names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurboInput {
    /// Throttle position (%), 0 closed .. 100 wide open.
    pub throttle_pct: f64,
    /// Engine speed (rad/s).
    pub engine_speed_rad_s: f64,
    /// Wastegate position (-), 0 closed .. 1 open.
    pub wastegate_frac: f64,
    /// Normalized air/fuel ratio (-).
    pub lambda: f64,
    /// Ambient pressure (Pa).
    pub ambient_pressure_pa: f64,
    /// Ambient temperature (K).
    pub ambient_temperature_k: f64,
}

impl TurboInput {
    /// The input vector (indices `U_*`).
    pub fn to_vector(&self) -> TurboInputVector {
        TurboInputVector::from([
            self.throttle_pct,
            self.engine_speed_rad_s,
            self.wastegate_frac,
            self.lambda,
            self.ambient_pressure_pa,
            self.ambient_temperature_k,
        ])
    }

    /// From an input vector (indices `U_*`).
    pub fn from_vector(u: &TurboInputVector) -> Self {
        Self {
            throttle_pct: u[U_THROTTLE_PCT],
            engine_speed_rad_s: u[U_ENGINE_SPEED_RAD_S],
            wastegate_frac: u[U_WASTEGATE],
            lambda: u[U_LAMBDA],
            ambient_pressure_pa: u[U_AMBIENT_PRESSURE_PA],
            ambient_temperature_k: u[U_AMBIENT_TEMPERATURE_K],
        }
    }

    fn array(&self) -> [f64; N_INPUTS] {
        self.to_vector().into()
    }
}

/// A refused input or state, or a failed computation.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum TurboError {
    /// An input is NaN or infinite.
    #[error("input {name} is not finite ({value})")]
    InputNotFinite { name: &'static str, value: f64 },
    /// An input is outside its accepted range.
    #[error("input {name} = {value} is outside [{min}, {max}]")]
    InputOutOfRange {
        name: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
    /// A state is NaN, infinite or outside the physical set.
    #[error("state {name} = {value}: {reason}")]
    State {
        name: &'static str,
        value: f64,
        reason: &'static str,
    },
    /// The stationary-point iteration did not converge.
    #[error(
        "no stationary point after {iterations} iterations (scaled residual {residual:e} 1/s)"
    )]
    NotConverged { iterations: usize, residual: f64 },
    /// The implicit step's Newton iterations did not converge, even with the step cut into
    /// `pieces` equal parts.
    #[error("the implicit step did not converge, even in {pieces} pieces")]
    StepNotConverged { pieces: u32 },
    /// A computation produced NaN or an infinity.
    #[error("non-finite result in {what}")]
    NonFinite { what: &'static str },
}

/// The continuous-time model. Cheap to clone (the parameters are shared).
#[derive(Debug, Clone, PartialEq)]
pub struct TurboModel {
    params: Arc<TurboParams>,
    c: Consts,
    scales: [f64; N_STATES_AUGMENTED],
}

impl TurboModel {
    /// Wraps validated parameters.
    pub fn new(params: TurboParams) -> Result<Self, ParamError> {
        params.validate()?;
        let c = Consts::new(&params);
        // Typical magnitudes: the mass of each volume at 1.2 (intake) or 0.4 (exhaust) kg/m^3,
        // 300 K intake and 900 K exhaust, 1e4 rad/s, a correction of 0.1.
        let mut scales = [0.0; N_STATES_AUGMENTED];
        for i in 0..6 {
            let (rho, t) = if i < 4 { (1.2, 300.0) } else { (0.4, 900.0) };
            scales[2 * i] = rho * c.volume[i];
            scales[2 * i + 1] = t;
        }
        scales[X_OMEGA_T] = 1e4;
        scales[X_DC_ETA_VOL] = 0.1;
        Ok(Self {
            params: Arc::new(params),
            c,
            scales,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &TurboParams {
        &self.params
    }

    /// Typical magnitude of each state (14, the augmented last): the scale of the implicit
    /// step's Newton tolerance, of the stationary iteration's residual and of the exponential
    /// step's balancing.
    pub fn state_scales(&self) -> &[f64; N_STATES_AUGMENTED] {
        &self.scales
    }

    /// The full evaluation, generic over the scalar: `x` the 13 states, `dc` the
    /// volumetric-efficiency correction (0 for the plain model), `u` the inputs (indices `U_*`).
    /// Seed [`ad::Dual`] variables to get gradients of any signal.
    pub fn evaluate<S: Scalar>(
        &self,
        x: &[S; N_STATES],
        dc: S,
        u: &[S; N_INPUTS],
    ) -> TurboSignals<S> {
        self.c.eval(x, dc, u, true)
    }

    /// Every signal at state `x` and input `u` (plain model).
    pub fn signals(&self, x: &TurboState, u: &TurboInput) -> TurboSignals {
        self.evaluate(&(*x).into(), 0.0, &u.array())
    }

    /// Every signal with its gradient with respect to the 13 states (`.v` the value, `.d[j]`
    /// the derivative by state `j`): the rows of an output matrix for any choice of sensors.
    pub fn signals_with_gradient(
        &self,
        x: &TurboState,
        u: &TurboInput,
    ) -> TurboSignals<Dual<N_STATES>> {
        let xs: [Dual<N_STATES>; N_STATES] = std::array::from_fn(|j| Dual::var(x[j], j));
        self.evaluate(&xs, Dual::cst(0.0), &u.array().map(Dual::cst))
    }

    /// Every signal of the augmented model at `x` (`dC_eta_vol` last).
    pub fn signals_augmented(&self, x: &TurboStateAugmented, u: &TurboInput) -> TurboSignals {
        let (x13, dc) = split(x);
        self.evaluate(&x13, dc, &u.array())
    }

    /// `dx/dt` of the plain model.
    pub fn derivative(&self, x: &TurboState, u: &TurboInput) -> TurboState {
        TurboState::from(self.signals(x, u).dxdt)
    }

    /// `dx/dt` of the augmented model (the last component is 0).
    pub fn derivative_augmented(
        &self,
        x: &TurboStateAugmented,
        u: &TurboInput,
    ) -> TurboStateAugmented {
        let s = self.signals_augmented(x, u);
        let mut f = TurboStateAugmented::zeros();
        for i in 0..N_STATES {
            f[i] = s.dxdt[i];
        }
        f
    }

    /// `dx/dt` and the exact Jacobian `df/dx` (forward-mode automatic differentiation: one
    /// evaluation with 13 seeds), plain model.
    pub fn derivative_and_jacobian(
        &self,
        x: &TurboState,
        u: &TurboInput,
    ) -> (TurboState, SMatrix<f64, N_STATES, N_STATES>) {
        self.jacobian13(x, u, true)
    }

    /// As [`Self::derivative_and_jacobian`] with the turbo speed's derivative unsaturated (the
    /// implicit step projects instead, see [`shaft`]).
    pub(crate) fn jacobian13(
        &self,
        x: &TurboState,
        u: &TurboInput,
        saturate: bool,
    ) -> (TurboState, SMatrix<f64, N_STATES, N_STATES>) {
        let xs: [Dual<N_STATES>; N_STATES] = std::array::from_fn(|j| Dual::var(x[j], j));
        let us = u.array().map(Dual::cst);
        let s = self.c.eval(&xs, Dual::cst(0.0), &us, saturate);
        let f = TurboState::from_fn(|i, _| s.dxdt[i].v);
        let jac = SMatrix::from_fn(|i, j| s.dxdt[i].d[j]);
        (f, jac)
    }

    /// `dx/dt` and `df/dx` of the augmented model (the last row is 0; the last column is
    /// `df/d dC_eta_vol`, non-zero in the rows the cylinder flow enters).
    pub fn derivative_and_jacobian_augmented(
        &self,
        x: &TurboStateAugmented,
        u: &TurboInput,
    ) -> (
        TurboStateAugmented,
        SMatrix<f64, N_STATES_AUGMENTED, N_STATES_AUGMENTED>,
    ) {
        self.jacobian14(x, u, true)
    }

    /// As [`Self::derivative_and_jacobian_augmented`], optionally unsaturated.
    pub(crate) fn jacobian14(
        &self,
        x: &TurboStateAugmented,
        u: &TurboInput,
        saturate: bool,
    ) -> (
        TurboStateAugmented,
        SMatrix<f64, N_STATES_AUGMENTED, N_STATES_AUGMENTED>,
    ) {
        let xs: [Dual<N_STATES_AUGMENTED>; N_STATES] = std::array::from_fn(|j| Dual::var(x[j], j));
        let dc = Dual::var(x[X_DC_ETA_VOL], X_DC_ETA_VOL);
        let us = u.array().map(Dual::cst);
        let s = self.c.eval(&xs, dc, &us, saturate);
        let f = TurboStateAugmented::from_fn(|i, _| if i < N_STATES { s.dxdt[i].v } else { 0.0 });
        let jac = SMatrix::from_fn(|i, j| if i < N_STATES { s.dxdt[i].d[j] } else { 0.0 });
        (f, jac)
    }

    /// `df/du` of the plain model (exact, 6 seeds), columns in input order `U_*`.
    pub fn input_jacobian(
        &self,
        x: &TurboState,
        u: &TurboInput,
    ) -> SMatrix<f64, N_STATES, N_INPUTS> {
        let xs = (*x).map(Dual::<N_INPUTS>::cst);
        let xs: [Dual<N_INPUTS>; N_STATES] = xs.into();
        let ua = u.array();
        let us: [Dual<N_INPUTS>; N_INPUTS] = std::array::from_fn(|j| Dual::var(ua[j], j));
        let s = self.evaluate(&xs, Dual::cst(0.0), &us);
        SMatrix::from_fn(|i, j| s.dxdt[i].d[j])
    }

    /// Refuses inputs the model must not be run with: a non-finite component or one outside
    /// its accepted range (`*_RANGE*` constants).
    pub fn check_input(&self, u: &TurboInput) -> Result<(), TurboError> {
        let checks = [
            ("throttle position (%)", u.throttle_pct, THROTTLE_RANGE_PCT),
            (
                "engine speed (rad/s)",
                u.engine_speed_rad_s,
                ENGINE_SPEED_RANGE_RAD_S,
            ),
            ("wastegate position", u.wastegate_frac, WASTEGATE_RANGE),
            ("lambda", u.lambda, LAMBDA_RANGE),
            (
                "ambient pressure (Pa)",
                u.ambient_pressure_pa,
                AMBIENT_PRESSURE_RANGE_PA,
            ),
            (
                "ambient temperature (K)",
                u.ambient_temperature_k,
                AMBIENT_TEMPERATURE_RANGE_K,
            ),
        ];
        for (name, value, (min, max)) in checks {
            if !value.is_finite() {
                return Err(TurboError::InputNotFinite { name, value });
            }
            if !(min..=max).contains(&value) {
                return Err(TurboError::InputOutOfRange {
                    name,
                    value,
                    min,
                    max,
                });
            }
        }
        Ok(())
    }

    /// Refuses a state outside the physical set: a non-finite component, a mass at or below
    /// zero, a temperature outside [`dynamics::TEMPERATURE_RANGE_K`], a turbo speed outside its
    /// limits by more than 1 rad/s (the evaluation clamps all of them).
    pub fn check_state(&self, x: &TurboState) -> Result<(), TurboError> {
        let (t_lo, t_hi) = dynamics::TEMPERATURE_RANGE_K;
        for (i, &v) in x.iter().enumerate() {
            let name = STATE_NAMES[i];
            let reason = if !v.is_finite() {
                Some("not finite")
            } else if i == X_OMEGA_T {
                let s = &self.c.shaft;
                (!(s.omega_min - 1.0..=s.omega_max + 1.0).contains(&v))
                    .then_some("outside the turbo speed limits")
            } else if i % 2 == 0 {
                (!(v > 0.0)).then_some("a mass must be positive")
            } else {
                (!(t_lo..=t_hi).contains(&v)).then_some("temperature outside 150..3000 K")
            };
            if let Some(reason) = reason {
                return Err(TurboError::State {
                    name,
                    value: v,
                    reason,
                });
            }
        }
        Ok(())
    }

    /// Moves a state into the physical set: masses to at least `V` times
    /// [`dynamics::MIN_DENSITY_KG_M3`], temperatures into [`dynamics::TEMPERATURE_RANGE_K`], the
    /// turbo speed into its limits; NaN goes to the lower bound.
    pub fn constrain(&self, x: &mut TurboState) {
        let (t_lo, t_hi) = dynamics::TEMPERATURE_RANGE_K;
        for i in 0..6 {
            x[2 * i] = x[2 * i].clamp_c(
                dynamics::MIN_DENSITY_KG_M3 * self.c.volume[i],
                f64::INFINITY,
            );
            x[2 * i + 1] = x[2 * i + 1].clamp_c(t_lo, t_hi);
        }
        let s = &self.c.shaft;
        x[X_OMEGA_T] = x[X_OMEGA_T].clamp_c(s.omega_min, s.omega_max);
    }

    /// The state with pressures `p` (Pa), temperatures `t` (K) of the six volumes in state
    /// order and turbo speed `omega_t` (rad/s).
    pub fn state_from_pressures(&self, p: [f64; 6], t: [f64; 6], omega_t: f64) -> TurboState {
        let mut x = TurboState::zeros();
        for i in 0..6 {
            x[2 * i] = p[i] * self.c.volume[i] / (self.c.gas(i).r * t[i]);
            x[2 * i + 1] = t[i];
        }
        x[X_OMEGA_T] = omega_t;
        x
    }

    /// The six pressures (Pa) of a state, in state order (no clamping).
    pub fn pressures(&self, x: &TurboState) -> [f64; 6] {
        std::array::from_fn(|i| x[2 * i] * x[2 * i + 1] * self.c.gas(i).r / self.c.volume[i])
    }
}

/// The 13 plain states and the correction of an augmented state.
fn split(x: &TurboStateAugmented) -> ([f64; N_STATES], f64) {
    (std::array::from_fn(|i| x[i]), x[X_DC_ETA_VOL])
}
