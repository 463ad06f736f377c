//! The air-path observer of the paper (seeds/004, REFERENCE §4): the mean value model run
//! with its inputs, corrected by the sensors through gains from stationary Kalman filters at
//! linearization points of the engine map, and augmented with `dC_eta_vol`, a slowly varying
//! offset of the volumetric efficiency that removes the stationary intake manifold pressure
//! error a proportional correction alone leaves (paper §4.1-4.2).
//!
//! # The discrete observer
//!
//! The paper writes it in continuous time, `dx/dt = f(x, u) + K (y - h(x))`. At the sensors'
//! sample time `dt` fdd runs the equivalent predictor-corrector,
//!
//! ```text
//! x-[k] = Phi(x^[k-1], u[k-1])          one SDIRK2 step of dt (the model's stiff step)
//! e[k]  = y[k] - h(x-[k], u[k])         innovation (sensor minus model)
//! x^[k] = x-[k] + K(N[k], p_im-[k]) e[k]
//! ```
//!
//! with `K` the stationary Kalman filter gain of the model linearized and discretized at the
//! grid node ([`design`]), looked up at the engine speed and the *predicted* intake manifold
//! pressure ([`gains`]): keyed on the estimate rather than the sensor, a drifting pressure
//! sensor does not also move the gains it is judged with.
//!
//! # Cost
//!
//! The step is [`super::discrete::TurboDiscrete14`] in one SDIRK2 step per sample with
//! Newton's tolerance at 1e-6 of the state scales ([`OBSERVER_NEWTON_TOL`]): Newton's
//! quadratic convergence leaves an error of the order of 1e-12 after such an update, and the
//! iterations halve (on the LiU-ICE fault-free drive at 20 Hz: 24.4 us per step at the default
//! 1e-10, 11.8 us at 1e-6, the same estimates to four digits).
//!
//! # Sensors
//!
//! Any `M` of [`Sensor`] (the TSFS09 transients log `p_im` and the air flow; the LiU-ICE logs
//! also `p_ic`). Values in SI units as the model's [`TurboSignals`].

pub mod design;
pub mod file;
pub mod gains;

use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

use super::ad::{Dual, Scalar};
use super::discrete::TurboDiscrete14;
use super::{
    TurboError, TurboInput, TurboModel, TurboSignals, TurboStateAugmented, N_STATES,
    N_STATES_AUGMENTED, X_DC_ETA_VOL,
};
use crate::param::ParamError;

pub use gains::{GainTable, GainTableError, Interpolation};

/// Newton's tolerance of the observer's step (see the module docs).
pub const OBSERVER_NEWTON_TOL: f64 = 1e-6;

/// A sensor the observer can use, and what of the model it reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Sensor {
    /// Boost pressure after the intercooler, before the throttle (Pa).
    PIc,
    /// Intake manifold pressure (Pa).
    PIm,
    /// Air mass flow through the air filter, the MAF sensor's flow (kg/s).
    Maf,
    /// Turbo speed (rad/s).
    TurboSpeed,
    /// Temperature after the intercooler (K).
    TIc,
}

impl Sensor {
    /// Every sensor.
    pub const ALL: [Sensor; 5] = [
        Sensor::PIc,
        Sensor::PIm,
        Sensor::Maf,
        Sensor::TurboSpeed,
        Sensor::TIc,
    ];

    /// The model's value of what the sensor measures.
    pub fn read<S: Scalar>(self, s: &TurboSignals<S>) -> S {
        match self {
            Sensor::PIc => s.p_ic_pa,
            Sensor::PIm => s.p_im_pa,
            Sensor::Maf => s.w_af_kg_s,
            Sensor::TurboSpeed => s.omega_t_rad_s,
            Sensor::TIc => s.t_ic_k,
        }
    }

    /// The name used in configuration files and reports.
    pub fn name(self) -> &'static str {
        match self {
            Sensor::PIc => "p_ic",
            Sensor::PIm => "p_im",
            Sensor::Maf => "maf",
            Sensor::TurboSpeed => "turbo_speed",
            Sensor::TIc => "T_ic",
        }
    }

    /// The unit of its value.
    pub fn unit(self) -> &'static str {
        match self {
            Sensor::PIc | Sensor::PIm => "Pa",
            Sensor::Maf => "kg/s",
            Sensor::TurboSpeed => "rad/s",
            Sensor::TIc => "K",
        }
    }

    /// A sensor from its [`Self::name`].
    pub fn from_name(name: &str) -> Option<Sensor> {
        Sensor::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// The sensors' values `h(x, u)` of the augmented model and their Jacobian `C = dh/dx`
/// (exact, forward-mode AD with 14 seeds).
pub fn measurement<const M: usize>(
    model: &TurboModel,
    sensors: &[Sensor; M],
    x: &TurboStateAugmented,
    u: &TurboInput,
) -> (SVector<f64, M>, SMatrix<f64, M, N_STATES_AUGMENTED>) {
    let xs: [Dual<N_STATES_AUGMENTED>; N_STATES] = std::array::from_fn(|j| Dual::var(x[j], j));
    let dc = Dual::var(x[X_DC_ETA_VOL], X_DC_ETA_VOL);
    let us = u.to_vector().map(Dual::cst);
    let us: [Dual<N_STATES_AUGMENTED>; super::N_INPUTS] = us.into();
    let s = model.evaluate(&xs, dc, &us);
    let mut y = SVector::<f64, M>::zeros();
    let mut c = SMatrix::<f64, M, N_STATES_AUGMENTED>::zeros();
    for (i, sensor) in sensors.iter().enumerate() {
        let v = sensor.read(&s);
        y[i] = v.v;
        for j in 0..N_STATES_AUGMENTED {
            c[(i, j)] = v.d[j];
        }
    }
    (y, c)
}

/// The sensors' values `h(x, u)` (no Jacobian).
pub fn measure<const M: usize>(
    model: &TurboModel,
    sensors: &[Sensor; M],
    x: &TurboStateAugmented,
    u: &TurboInput,
) -> SVector<f64, M> {
    let s = model.signals_augmented(x, u);
    SVector::from_fn(|i, _| sensors[i].read(&s))
}

/// What one observer update produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverStep<const M: usize> {
    /// Sensor minus the model's prediction, before the correction (the sensors' units).
    pub innovation: SVector<f64, M>,
    /// Sensor minus the corrected estimate.
    pub residual: SVector<f64, M>,
    /// Every signal of the corrected estimate.
    pub signals: TurboSignals,
}

/// The gain-scheduled observer (see the module docs). Fixed-size state; no heap per step.
#[derive(Debug, Clone)]
pub struct TurboObserver<const M: usize> {
    step: TurboDiscrete14,
    sensors: [Sensor; M],
    gains: GainTable<M>,
    interpolation: Interpolation,
    augmented: bool,
    x: TurboStateAugmented,
    last_input: Option<TurboInput>,
}

impl<const M: usize> TurboObserver<M> {
    /// An observer on `model` sampled every `dt_s`, with `sensors` in the order of the gain
    /// table's columns. With `augmented` false, the `dC_eta_vol` state is held at 0 (its gain
    /// row ignored): the paper's observer before its §4.2.
    pub fn new(
        model: TurboModel,
        dt_s: f64,
        sensors: [Sensor; M],
        gains: GainTable<M>,
        interpolation: Interpolation,
        augmented: bool,
    ) -> Result<Self, ParamError> {
        let step =
            TurboDiscrete14::new(model, dt_s, dt_s)?.with_newton_tolerance(OBSERVER_NEWTON_TOL)?;
        Ok(Self {
            step,
            sensors,
            gains,
            interpolation,
            augmented,
            x: TurboStateAugmented::zeros(),
            last_input: None,
        })
    }

    /// The model.
    pub fn model(&self) -> &TurboModel {
        self.step.model()
    }

    /// The sensors, in the order of `y`.
    pub fn sensors(&self) -> &[Sensor; M] {
        &self.sensors
    }

    /// The current estimate (after the last update).
    pub fn state(&self) -> &TurboStateAugmented {
        &self.x
    }

    /// Starts from `x` (e.g. a stationary point); the next update does not predict.
    pub fn reset(&mut self, x: TurboStateAugmented) {
        self.x = x;
        if !self.augmented {
            self.x[X_DC_ETA_VOL] = 0.0;
        }
        self.last_input = None;
    }

    /// Starts from the model's stationary point at input `u`.
    pub fn reset_stationary(&mut self, u: &TurboInput) -> Result<(), TurboError> {
        let s = self.model().stationary_point(u, None)?;
        let mut x = TurboStateAugmented::zeros();
        for i in 0..N_STATES {
            x[i] = s.state[i];
        }
        self.reset(x);
        Ok(())
    }

    /// One sample: predicts from the previous estimate with the previous input over `dt`
    /// (nothing on the first sample after a reset), then corrects with the sensors `y` at the
    /// input `u` of this sample. A failed step (an input the model refuses) leaves the estimate
    /// unchanged and returns the error.
    pub fn update(
        &mut self,
        u: &TurboInput,
        y: &SVector<f64, M>,
    ) -> Result<ObserverStep<M>, TurboError> {
        self.model().check_input(u)?;
        let predicted = match self.last_input {
            Some(prev) => self.step.step(&self.x, &prev)?,
            None => self.x,
        };
        let model = self.step.model();
        let h = measure(model, &self.sensors, &predicted, u);
        let innovation = y - h;
        let s = model.signals_augmented(&predicted, u);
        let mut k = self
            .gains
            .lookup(u.engine_speed_rad_s, s.p_im_pa, self.interpolation);
        if !self.augmented {
            k.row_mut(X_DC_ETA_VOL).fill(0.0);
        }
        let mut x = predicted + k * innovation;
        let mut x13 = super::TurboState::from_fn(|i, _| x[i]);
        model.constrain(&mut x13);
        for i in 0..N_STATES {
            x[i] = x13[i];
        }
        if !x[X_DC_ETA_VOL].is_finite() {
            x[X_DC_ETA_VOL] = 0.0;
        }
        self.x = x;
        self.last_input = Some(*u);
        let signals = model.signals_augmented(&self.x, u);
        let residual = SVector::from_fn(|i, _| y[i] - self.sensors[i].read(&signals));
        Ok(ObserverStep {
            innovation,
            residual,
            signals,
        })
    }
}
