//! Fault isolation and sizing for the intake side: a bank of single-fault hypotheses, each with
//! one size parameter fitted by weighted least squares to the flow balances of [`residuals`]
//! over the frames of an episode (from the onset of an alarm), in constant memory and without
//! allocation.
//!
//! # Hypotheses ([`Hypothesis`], in the column order of [`residuals::FAULTS`])
//!
//! | hypothesis | size (unit) | fitted parameter `theta` (unit) | nominal | why this parameter |
//! |---|---|---|---|---|
//! | `p_ic` sensor gain | `g` (-), reads `g` x true | `c = 1/g` (-) | 1 | the choked throttle flow is linear in the true `p_ic = c p_ic,read` |
//! | `p_im` sensor gain | `g` (-) | `c = 1/g` (-) | 1 | the cylinder flow is nearly linear in `c p_im,read` |
//! | air mass flow sensor gain | `g` (-) | `c = 1/g` (-) | 1 | the true flow `c W_af,read` enters linearly |
//! | `T_ic` sensor bias | `b` (K), reads true + `b` | `b` (K) | 0 | the flows go as `1/T` and `1/sqrt(T)`: nearly linear over tens of K |
//! | leak before the throttle | hole diameter (mm) | effective area `A = C_d pi d^2/4` (m^2) | 0 | the leak flow is linear in `A` |
//! | leak after the throttle | hole diameter (mm) | effective area (m^2) | 0 | the same |
//! | throttle effective area | factor `a` (-) | `a` (-) | 1 | the throttle flow is linear in `a` |
//!
//! # What is fitted
//!
//! Under hypothesis `h` with parameter `theta`, the *corrected* balances `e_h(theta)` are the
//! balances of [`residuals::flow_balance`] recomputed with the readings corrected (`p = c p_read`,
//! `T = T_read - b`, `W_af = c W_af,read`), the throttle flow scaled (`a W_thr`), or a leak
//! flow added (before the throttle the MAF also measures the air that leaks out, so
//! `e_cyl = W_af - L - W_cyl`, `e_thr = W_af - L - W_thr`; after it the manifold loses `L`, so
//! `e_cyl = W_af - W_cyl - L`, `e_thr` unchanged). The leak flow `L` (kg/s, positive out to
//! ambient, negative when ambient air is drawn in) is the model's compressible nozzle flow
//! ([`nozzle::Nozzle`]) with the air's ratio of specific heats and gas constant, continued
//! linearly above the pressure ratio [`LEAK_LINEAR_RATIO`], through the effective area `A`
//! between the volume (`p_ic` or `p_im`, at `T_ic`) and ambient. The true hypothesis at its true
//! size brings `e_h` to the residual baseline (the model error the caller has learned) plus
//! noise, so its size is the minimizer of
//!
//! ```text
//! C_h(theta) = sum over frames (e_h(theta) - baseline)' W (e_h(theta) - baseline)
//! ```
//!
//! and `C_h` at the minimizer is its cost; the no-fault cost is `C` at the nominal parameter
//! (every hypothesis agrees there).
//!
//! The bank evaluates the balances itself, with the same component code (the model's throttle
//! and cylinders) at the same point as [`residuals::flow_balance`] (the tests check the two
//! agree to 1e-12 of the air flow), rather than calling it: `flow_balance` also runs the whole
//! model with 13 gradient seeds to tell whether the throttle is choked, about 2 us the bank
//! does not need.
//!
//! # Only two of the three balances are independent
//!
//! `r_tc = W_thr - W_cyl` is exactly `r_cyl - r_thr`, for the nominal and for every corrected
//! balance. Weighting all three with `diag(1/sigma_i^2)` would count the same information twice
//! and make the costs (and the probabilities built on them) overconfident by an arbitrary
//! factor. The bank therefore works on `(r_cyl, r_thr)` with their full covariance, which the
//! three standard deviations the caller knows determine exactly:
//! `var(r_tc) = var(r_cyl) + var(r_thr) - 2 cov`, so `cov = (s_cyl^2 + s_thr^2 - s_tc^2) / 2`
//! (the correlation is clamped to `[-0.99, 0.99]` when noisy estimates of the three violate
//! the triangle inequality), and `W` is its inverse. The cost is then a chi-square: the
//! Gaussian negative log-likelihood times 2, up to a constant.
//!
//! # Second order in the size, relinearized as the estimate moves, in constant memory
//!
//! A 10 % gain error is far from the nominal for these flows: near a wide-open throttle the
//! throttle flow goes nearly as `p_ic - p_im`, so a 10 % `p_ic` error changes it several-fold,
//! and the throttle's flow function has kinks (the critical ratio, the start of its linear
//! continuation). A Gauss-Newton fit linearized once at the nominal is biased there, and
//! relinearizing at the fitted size needs every frame again (memory growing with the episode).
//! Instead, each frame's corrected balances are expanded to second order around the bank's
//! *current* estimate `d_hat` of each hypothesis' parameter, with exact first and second
//! derivatives ([`Jet2`] numbers through the model's own throttle and cylinder components), and
//! written as a polynomial in the offset from the nominal, `d = theta - theta_0`:
//!
//! ```text
//! e_h(d) ~ e + J (d - d_hat) + H (d - d_hat)^2 / 2 = a0 + a1 d + a2 d^2
//! ```
//!
//! With `S_ij = sum a_i' W a_j` over the frames (the baseline subtracted from `a0`; six sums per
//! hypothesis) the cost is the quartic
//!
//! ```text
//! C_h(d) = S00 + 2 S01 d + (S11 + 2 S02) d^2 + 2 S12 d^3 + S22 d^4
//! ```
//!
//! exact for the frames' expansions whatever their expansion points. Each frame is thus
//! linearized where the estimate stood when it arrived: a recursive Gauss-Newton that
//! relinearizes as the estimate moves without keeping any frame (the first few frames are
//! expanded near the nominal; their second-order terms keep that error small). On the tests'
//! map-wide frames, expanding every frame at the nominal (still to second order) left a `p_ic`
//! gain of 1.10 at 1.143; following the estimate gives 1.100. After each frame the estimate is followed by Newton's
//! method on the quartic (a global search, a grid then golden sections, when Newton does not
//! land on a minimum); [`IsolationBank::fits`] searches globally. The four hypotheses linear in
//! their parameter have `a2 = 0` and exact expansions anywhere: their cost is a quadratic,
//! minimized in closed form. The admissible range ([`IsolationConfig`]) bounds every search,
//! and it holds the sign constraint on the leak areas: a leak whose unconstrained optimum is
//! negative is evaluated at zero area, so its cost is the no-fault cost.
//!
//! # The probabilities
//!
//! [`Fit::probability`] is the posterior probability of each fault hypothesis **given that
//! exactly one of the seven is present**, with equal prior probabilities, each evaluated at its
//! maximum-likelihood size (the profile likelihood; each has one free parameter, so no
//! complexity penalty separates them): `P_h = exp(-C_h / 2) / sum_k exp(-C_k / 2)`, under
//! Gaussian balances with the covariance above. It is only as calibrated as the standard
//! deviations: they must include the model error left after the baseline, not only the sensor
//! noise. Whether there is a fault at all is the no-fault cost against the best cost:
//! [`IsolationBank::evidence`] is the generalized likelihood ratio statistic
//! `C_none - min_h C_h`, chi-square with one degree of freedom for any one hypothesis under no
//! fault (the maximum over seven correlated ones is somewhat larger).
//!
//! # The choked throttle
//!
//! With the throttle choked, the throttle flow ignores `p_im`, and a `p_im` gain and a leak
//! after the throttle both leave `r_thr` untouched (the same column of [`residuals::SIGNATURE`]).
//! They differ in how the balances scale with the operating point: the gain's error goes with
//! the cylinder flow (proportional to `p_im`), the leak's with the pressure across the hole (at
//! manifold pressures below 0.53 ambient the hole itself is choked and its inflow is constant).
//! Over frames at several manifold pressures, only the right hypothesis fits them all; the tests
//! show both ways round.
//!
//! # Cost
//!
//! [`IsolationBank::push`] evaluates the two flows four times (nominal, and in `Jet2<1>` for
//! the three nonlinear hypotheses), two leak flows and a 2 x 2 inverse, adds 43 sums and takes
//! three one-dimensional Newton steps: about 0.4 us per frame, and [`IsolationBank::fits`]
//! about 1.1 us (the test prints both). Neither allocates.
//!
//! [`residuals`]: super::residuals
//! [`residuals::flow_balance`]: super::residuals::flow_balance
//! [`residuals::FAULTS`]: super::residuals::FAULTS
//! [`residuals::SIGNATURE`]: super::residuals::SIGNATURE
//! [`nozzle::Nozzle`]: super::nozzle::Nozzle

use std::f64::consts::PI;
use std::ops::{Add, Div, Mul, Neg, Sub};

use thiserror::Error;

use super::ad::Scalar;
use super::dynamics::{MIN_DENSITY_KG_M3, TEMPERATURE_RANGE_K};
use super::nozzle::Nozzle;
use super::residuals::{ExhaustPressure, IntakeReadings};
use super::{TurboError, TurboInput, TurboModel};

/// Number of fault hypotheses.
pub const N_HYPOTHESES: usize = 7;

/// Pressure ratio above which the leak's flow function is continued linearly to zero at 1 (-):
/// the model's choice for the wastegate (a finite slope at equal pressures).
pub const LEAK_LINEAR_RATIO: f64 = 0.99;

/// Points of the grid on which the nonlinear hypotheses' quartic costs are first searched.
const GRID: usize = 64;
/// Golden-section iterations after the grid (the bracket shrinks by 0.618 each).
const GOLDEN_ITERATIONS: usize = 90;
/// Newton iterations when following an estimate from frame to frame.
const NEWTON_ITERATIONS: usize = 8;
/// Largest correlation of the two independent balances (keeps `W` finite).
const MAX_CORRELATION: f64 = 0.99;

/// A single-fault hypothesis, in the column order of [`super::residuals::FAULTS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Hypothesis {
    /// Boost (`p_ic`) sensor gain: the sensor reads `g` times the true pressure.
    PIcGain,
    /// Manifold pressure (`p_im`) sensor gain.
    PImGain,
    /// Air mass flow sensor gain.
    MafGain,
    /// Intercooler temperature sensor bias: the sensor reads the true temperature plus `b` (K).
    TIcBias,
    /// Leak out of the boost volume (between the intercooler and the throttle) to ambient.
    LeakBeforeThrottle,
    /// Leak between the intake manifold and ambient (into it while throttled, out when boosted).
    LeakAfterThrottle,
    /// Throttle effective area: the real area is `a` times the model's (actuator, deposits).
    ThrottleArea,
}

impl Hypothesis {
    /// All hypotheses, in index order.
    pub const ALL: [Hypothesis; N_HYPOTHESES] = [
        Hypothesis::PIcGain,
        Hypothesis::PImGain,
        Hypothesis::MafGain,
        Hypothesis::TIcBias,
        Hypothesis::LeakBeforeThrottle,
        Hypothesis::LeakAfterThrottle,
        Hypothesis::ThrottleArea,
    ];

    /// Index in [`Self::ALL`], and the column of [`super::residuals::SIGNATURE`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The name, as in [`super::residuals::FAULTS`].
    pub fn name(self) -> &'static str {
        super::residuals::FAULTS[self.index()]
    }

    /// The unit of [`Fit::size`].
    pub fn size_unit(self) -> &'static str {
        match self {
            Hypothesis::PIcGain | Hypothesis::PImGain | Hypothesis::MafGain => "gain (-)",
            Hypothesis::TIcBias => "bias (K)",
            Hypothesis::LeakBeforeThrottle | Hypothesis::LeakAfterThrottle => "diameter (mm)",
            Hypothesis::ThrottleArea => "area factor (-)",
        }
    }

    /// The unit of [`Fit::parameter`].
    pub fn parameter_unit(self) -> &'static str {
        match self {
            Hypothesis::PIcGain | Hypothesis::PImGain | Hypothesis::MafGain => "1/gain (-)",
            Hypothesis::TIcBias => "bias (K)",
            Hypothesis::LeakBeforeThrottle | Hypothesis::LeakAfterThrottle => {
                "effective area (m^2)"
            }
            Hypothesis::ThrottleArea => "area factor (-)",
        }
    }

    /// The size of no fault, in the unit of [`Fit::size`] (gain 1, bias 0 K, diameter 0 mm,
    /// area factor 1).
    pub fn nominal_size(self) -> f64 {
        self.nominal_parameter()
    }

    /// The parameter of no fault (`theta_0`).
    fn nominal_parameter(self) -> f64 {
        match self {
            Hypothesis::TIcBias
            | Hypothesis::LeakBeforeThrottle
            | Hypothesis::LeakAfterThrottle => 0.0,
            _ => 1.0,
        }
    }
}

/// A refused configuration or frame.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum IsolationError {
    /// A configuration value is out of its range.
    #[error("isolation configuration {name} = {value}: {reason}")]
    Config {
        /// The field.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong.
        reason: &'static str,
    },
    /// A reading is not finite or outside the range the model evaluates unclamped.
    #[error("reading {name} = {value}: {reason}")]
    Reading {
        /// The reading.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong.
        reason: &'static str,
    },
    /// The model refuses the input.
    #[error("input refused: {0}")]
    Input(#[from] TurboError),
    /// A residual standard deviation is not finite and positive, or a baseline is not finite.
    #[error("{name} = {value} kg/s: {reason}")]
    Weight {
        /// The field.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong.
        reason: &'static str,
    },
}

/// The admissible sizes and the leak model. Sizes outside the ranges are not considered: they
/// bound the search, and a fit at a bound says so ([`Fit::at_bound`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IsolationConfig {
    /// Smallest and largest sensor gain (-).
    pub gain_range: (f64, f64),
    /// Smallest and largest `T_ic` bias (K).
    pub bias_range_k: (f64, f64),
    /// Largest leak hole diameter (mm).
    pub leak_max_diameter_mm: f64,
    /// Discharge coefficient of a leak's hole (-): effective area `C_d pi d^2 / 4`. A
    /// sharp-edged hole or split hose has 0.6 to 0.7.
    pub leak_discharge_coefficient: f64,
    /// Smallest and largest throttle area factor (-).
    pub throttle_area_range: (f64, f64),
}

impl Default for IsolationConfig {
    /// Gains 0.5 .. 1.5, biases +-40 K, holes up to 30 mm with `C_d` 0.65, throttle area
    /// factors 0.3 .. 1.5.
    fn default() -> Self {
        Self {
            gain_range: (0.5, 1.5),
            bias_range_k: (-40.0, 40.0),
            leak_max_diameter_mm: 30.0,
            leak_discharge_coefficient: 0.65,
            throttle_area_range: (0.3, 1.5),
        }
    }
}

impl IsolationConfig {
    /// Checks the ranges: finite, ordered, gains and area factors positive and bracketing 1,
    /// biases bracketing 0, diameter positive, `C_d` in `(0, 1]`.
    pub fn validate(&self) -> Result<(), IsolationError> {
        let bad = |name, value, reason| {
            Err(IsolationError::Config {
                name,
                value,
                reason,
            })
        };
        let pairs = [
            ("gain_range", self.gain_range, 1.0, true),
            ("bias_range_k", self.bias_range_k, 0.0, false),
            ("throttle_area_range", self.throttle_area_range, 1.0, true),
        ];
        for (name, (lo, hi), nominal, positive) in pairs {
            if !(lo.is_finite() && hi.is_finite()) {
                return bad(name, if lo.is_finite() { hi } else { lo }, "not finite");
            }
            if positive && !(lo > 0.0) {
                return bad(name, lo, "the lower end must be positive");
            }
            if !(lo < nominal && nominal < hi) {
                return bad(
                    name,
                    lo,
                    "the range must contain the nominal value strictly",
                );
            }
        }
        if !(self.leak_max_diameter_mm > 0.0 && self.leak_max_diameter_mm.is_finite()) {
            return bad(
                "leak_max_diameter_mm",
                self.leak_max_diameter_mm,
                "must be finite and positive",
            );
        }
        let cd = self.leak_discharge_coefficient;
        if !(cd > 0.0 && cd <= 1.0) {
            return bad("leak_discharge_coefficient", cd, "must be in (0, 1]");
        }
        Ok(())
    }

    /// Effective area (m^2) of a hole of diameter `d_mm` (mm).
    pub fn leak_area_m2(&self, d_mm: f64) -> f64 {
        let d = d_mm * 1e-3;
        self.leak_discharge_coefficient * PI * d * d / 4.0
    }

    /// Diameter (mm) of a hole of effective area `area_m2` (m^2; negative counts as 0).
    pub fn leak_diameter_mm(&self, area_m2: f64) -> f64 {
        1e3 * (4.0 * area_m2.max(0.0) / (PI * self.leak_discharge_coefficient)).sqrt()
    }
}

/// One frame for the bank: the readings and inputs the balances are computed from, the
/// caller's baseline of the two independent balances and the three balances' noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IsolationFrame {
    /// The intake sensors.
    pub readings: IntakeReadings,
    /// The model inputs.
    pub input: TurboInput,
    /// Where the residual-gas term's exhaust pressure comes from.
    pub exhaust: ExhaustPressure,
    /// The fault-free level of `[r_cyl, r_thr]` at this frame (kg/s), e.g. learned from
    /// fault-free driving; `r_tc`'s is their difference. Subtracted before the fit.
    pub baseline_kg_s: [f64; 2],
    /// Standard deviations (kg/s) of `[r_cyl, r_thr, r_tc]` about their baselines at this
    /// frame: sensor noise and the model error left after the baseline. All three are needed:
    /// they fix the correlation of the two independent balances (see the module docs).
    pub sigma_kg_s: [f64; 3],
}

/// One frame's contribution: the nominal balances and, per hypothesis, the second-order
/// polynomial in `d = theta - theta_0` that approximates its corrected `[r_cyl, r_thr]`
/// (kg/s), expanded at the bank's current estimate of that hypothesis' parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameLinearization {
    /// `[r_cyl, r_thr, r_tc]` at the readings (kg/s), as [`super::residuals::flow_balance`].
    pub residuals_kg_s: [f64; 3],
    /// Per hypothesis ([`Hypothesis::ALL`] order), `[a0, a1, a2]` with
    /// `e_h(d) ~ a0 + a1 d + a2 d^2` (kg/s, kg/s per parameter unit, per unit squared; see
    /// [`Hypothesis::parameter_unit`]), before the baseline is subtracted.
    pub polynomials: [[[f64; 2]; 3]; N_HYPOTHESES],
    /// The parameter offsets `d` the polynomials were expanded at (exact for the four
    /// hypotheses linear in their parameter, whatever the point).
    pub expanded_at: [f64; N_HYPOTHESES],
    /// `W`, the inverse covariance of `[r_cyl, r_thr]` ((kg/s)^-2).
    pub weight: [[f64; 2]; 2],
}

/// One hypothesis' fit over the episode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// The hypothesis.
    pub hypothesis: Hypothesis,
    /// Fitted size in [`Hypothesis::size_unit`]: gain, bias (K), hole diameter (mm) or area
    /// factor.
    pub size: f64,
    /// Fitted parameter in [`Hypothesis::parameter_unit`] (`1/g`, K, m^2 or `a`).
    pub parameter: f64,
    /// Its standard error from the cost's curvature at the fit (`1/sqrt(C''/2)`), in the
    /// parameter's unit; infinite without information.
    pub parameter_std: f64,
    /// Weighted sum of squares at the fit (-): the chi-square of the module docs.
    pub cost: f64,
    /// Posterior probability of this hypothesis among the seven (see the module docs).
    pub probability: f64,
    /// Whether the fit is at a bound of the admissible range (a leak at zero area is).
    pub at_bound: bool,
}

/// The six sums of one hypothesis: `S_ij = sum a_i' W a_j` of the frames' polynomials (the
/// baseline subtracted from `a0`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Sums {
    s00: f64,
    s01: f64,
    s02: f64,
    s11: f64,
    s12: f64,
    s22: f64,
}

impl Sums {
    /// `C(d) = S00 + 2 S01 d + (S11 + 2 S02) d^2 + 2 S12 d^3 + S22 d^4`.
    #[inline]
    fn cost(&self, d: f64) -> f64 {
        self.s00
            + d * (2.0 * self.s01
                + d * (self.s11 + 2.0 * self.s02 + d * (2.0 * self.s12 + self.s22 * d)))
    }

    /// `C'(d) / 2`.
    #[inline]
    fn slope(&self, d: f64) -> f64 {
        self.s01 + d * (self.s11 + 2.0 * self.s02 + d * (3.0 * self.s12 + 2.0 * self.s22 * d))
    }

    /// `C''(d) / 2`: the information about the parameter.
    #[inline]
    fn information(&self, d: f64) -> f64 {
        self.s11 + 2.0 * self.s02 + 6.0 * d * (self.s12 + self.s22 * d)
    }

    /// Whether the cost is exactly quadratic (a hypothesis linear in its parameter).
    #[inline]
    fn quadratic(&self) -> bool {
        self.s02 == 0.0 && self.s12 == 0.0 && self.s22 == 0.0
    }
}

/// The hypothesis bank. Build once per model ([`Self::new`]), [`Self::reset`] at the onset of
/// each episode, [`Self::push`] every frame, [`Self::fits`] when the ranking is needed.
#[derive(Debug, Clone)]
pub struct IsolationBank {
    model: TurboModel,
    leak: Nozzle,
    r_air: f64,
    config: IsolationConfig,
    /// Admissible `d = theta - theta_0` per hypothesis.
    range: [(f64, f64); N_HYPOTHESES],
    frames: usize,
    /// `sum r' W r` at the nominal parameters (the no-fault cost).
    rr: f64,
    sums: [Sums; N_HYPOTHESES],
    /// The current estimate of each `d`: where the next frame is expanded.
    estimate: [f64; N_HYPOTHESES],
}

impl IsolationBank {
    /// A bank on `model`'s throttle and cylinder components (the ones
    /// [`super::residuals::flow_balance`] uses), with the leak nozzle of its air.
    pub fn new(model: &TurboModel, config: IsolationConfig) -> Result<Self, IsolationError> {
        config.validate()?;
        let p = model.params();
        let leak = Nozzle::new(
            p.air_heat_capacity_ratio,
            LEAK_LINEAR_RATIO,
            p.air_gas_constant_j_per_kg_k,
        );
        let (g_lo, g_hi) = config.gain_range;
        let gain = (1.0 / g_hi - 1.0, 1.0 / g_lo - 1.0);
        let leak_max = config.leak_area_m2(config.leak_max_diameter_mm);
        let (a_lo, a_hi) = config.throttle_area_range;
        Ok(Self {
            model: model.clone(),
            leak,
            r_air: p.air_gas_constant_j_per_kg_k,
            config,
            range: [
                gain,
                gain,
                gain,
                config.bias_range_k,
                (0.0, leak_max),
                (0.0, leak_max),
                (a_lo - 1.0, a_hi - 1.0),
            ],
            frames: 0,
            rr: 0.0,
            sums: [Sums::default(); N_HYPOTHESES],
            estimate: [0.0; N_HYPOTHESES],
        })
    }

    /// The configuration.
    pub fn config(&self) -> &IsolationConfig {
        &self.config
    }

    /// Forgets every frame: the start of a new episode.
    pub fn reset(&mut self) {
        self.frames = 0;
        self.rr = 0.0;
        self.sums = [Sums::default(); N_HYPOTHESES];
        self.estimate = [0.0; N_HYPOTHESES];
    }

    /// Frames accumulated since the last [`Self::reset`].
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The no-fault cost `C_none` (every hypothesis at its nominal parameter).
    pub fn no_fault_cost(&self) -> f64 {
        self.rr
    }

    /// The throttle flow (kg/s) at the corrected readings, as `flow_balance`'s state has it
    /// (every intake temperature the intercooler's).
    #[inline]
    fn w_thr<S: Scalar>(&self, u: &TurboInput, p_ic: S, t: S, p_im: S) -> S {
        self.model
            .c
            .throttle
            .flow(S::cst(u.throttle_pct), p_ic, t, p_im, t)
            .0
    }

    /// The cylinder air flow (kg/s) at the corrected readings.
    #[inline]
    fn w_cyl<S: Scalar>(&self, u: &TurboInput, p_em: f64, t: S, p_im: S) -> S {
        self.model
            .c
            .cylinders
            .point(
                p_im,
                t,
                S::cst(p_em),
                S::cst(u.engine_speed_rad_s),
                S::cst(u.lambda),
                S::cst(u.ambient_temperature_k),
                S::cst(0.0),
            )
            .w_ei
    }

    /// One frame's polynomials, each nonlinear hypothesis expanded at the bank's current
    /// estimate of its parameter (before any frame: the nominal). Refuses non-finite values,
    /// pressures below what the model evaluates unclamped, temperatures outside its range,
    /// inputs the model refuses, and standard deviations that are not finite and positive.
    pub fn linearize(&self, f: &IsolationFrame) -> Result<FrameLinearization, IsolationError> {
        let weight = self.check(f)?;
        let r = &f.readings;
        let u = &f.input;
        let (p_amb, t_amb) = (u.ambient_pressure_pa, u.ambient_temperature_k);
        let p_em = match f.exhaust {
            ExhaustPressure::Ambient => p_amb,
            ExhaustPressure::Estimate { p_em_pa, .. } => p_em_pa,
        };
        let maf = r.maf_kg_s;
        let (p_ic, p_im, t) = (r.p_ic_pa, r.p_im_pa, r.t_ic_k);
        let w_thr = self.w_thr(u, p_ic, t, p_im);
        let w_cyl = self.w_cyl(u, p_em, t, p_im);
        let e0 = [maf - w_cyl, maf - w_thr];
        // Leak flow per m^2 of effective area (kg/s/m^2, positive out).
        let l_ic = self.leak.flow(1.0, p_ic, t, p_amb, t_amb).0;
        let l_im = self.leak.flow(1.0, p_im, t, p_amb, t_amb).0;

        // The nonlinear hypotheses: Jet2 at the current estimate `d_hat`, then re-centred on
        // `d = 0`: e(d) ~ e + J (d - d_hat) + H (d - d_hat)^2 / 2.
        let est = self.estimate;
        let seed = |d_hat: f64, nominal: f64| Jet2::<1>::var(nominal + d_hat, 0);
        let poly = |e: [Jet2<1>; 2], d_hat: f64| -> [[f64; 2]; 3] {
            let mut a = [[0.0; 2]; 3];
            for k in 0..2 {
                let (v, j, h) = (e[k].v, e[k].d[0], e[k].dd[0]);
                a[0][k] = v - j * d_hat + 0.5 * h * d_hat * d_hat;
                a[1][k] = j - h * d_hat;
                a[2][k] = 0.5 * h;
            }
            a
        };
        let cst = Jet2::<1>::cst;
        let pic = {
            let c = seed(est[0], 1.0);
            let w = self.w_thr(u, c * p_ic, cst(t), cst(p_im));
            poly([cst(e0[0]), -w + maf], est[0])
        };
        let pim = {
            let c = seed(est[1], 1.0);
            let w_t = self.w_thr(u, cst(p_ic), cst(t), c * p_im);
            let w_c = self.w_cyl(u, p_em, cst(t), c * p_im);
            poly([-w_c + maf, -w_t + maf], est[1])
        };
        let tic = {
            let tt = -seed(est[3], 0.0) + t;
            let w_t = self.w_thr(u, cst(p_ic), tt, cst(p_im));
            let w_c = self.w_cyl(u, p_em, tt, cst(p_im));
            poly([-w_c + maf, -w_t + maf], est[3])
        };
        let zero = [0.0; 2];
        Ok(FrameLinearization {
            residuals_kg_s: [e0[0], e0[1], w_thr - w_cyl],
            polynomials: [
                pic,
                pim,
                [e0, [maf, maf], zero],
                tic,
                [e0, [-l_ic, -l_ic], zero],
                [e0, [-l_im, 0.0], zero],
                [e0, [0.0, -w_thr], zero],
            ],
            expanded_at: [est[0], est[1], 0.0, est[3], 0.0, 0.0, 0.0],
            weight,
        })
    }

    /// Adds one frame to the episode's sums and moves each nonlinear hypothesis' expansion
    /// point to its new estimate. A refused frame ([`Self::linearize`]) leaves the bank as it
    /// was.
    pub fn push(&mut self, f: &IsolationFrame) -> Result<(), IsolationError> {
        let lin = self.linearize(f)?;
        let w = lin.weight;
        let form = |x: &[f64; 2], y: &[f64; 2]| {
            w[0][0] * x[0] * y[0] + w[0][1] * (x[0] * y[1] + x[1] * y[0]) + w[1][1] * x[1] * y[1]
        };
        let b = f.baseline_kg_s;
        let r = [lin.residuals_kg_s[0] - b[0], lin.residuals_kg_s[1] - b[1]];
        self.rr += form(&r, &r);
        for (s, p) in self.sums.iter_mut().zip(&lin.polynomials) {
            let a0 = [p[0][0] - b[0], p[0][1] - b[1]];
            let (a1, a2) = (&p[1], &p[2]);
            s.s00 += form(&a0, &a0);
            s.s01 += form(&a0, a1);
            s.s02 += form(&a0, a2);
            s.s11 += form(a1, a1);
            s.s12 += form(a1, a2);
            s.s22 += form(a2, a2);
        }
        self.frames += 1;
        for i in [0, 1, 3] {
            self.estimate[i] = self.minimize(i, Some(self.estimate[i]));
        }
        Ok(())
    }

    /// The minimizer of hypothesis `i`'s cost over its range: closed form for a quadratic
    /// cost; otherwise Newton from `start` when it converges to a point of positive curvature
    /// that lowers the cost, else a global search.
    fn minimize(&self, i: usize, start: Option<f64>) -> f64 {
        let s = &self.sums[i];
        let (lo, hi) = self.range[i];
        if self.frames == 0 {
            return 0.0;
        }
        if s.quadratic() {
            // A convex quadratic's constrained minimum is the clamped unconstrained one.
            let a = s.information(0.0);
            return if a > 0.0 {
                (-s.s01 / a).clamp(lo, hi)
            } else if s.cost(lo) <= s.cost(hi) {
                lo
            } else {
                hi
            };
        }
        if let Some(mut d) = start {
            let c0 = s.cost(d);
            for _ in 0..NEWTON_ITERATIONS {
                let info = s.information(d);
                if !(info > 0.0) {
                    break;
                }
                let next = (d - s.slope(d) / info).clamp(lo, hi);
                let done = (next - d).abs() <= 1e-12 * (hi - lo);
                d = next;
                if done {
                    // A stationary point (or a bound with the slope outwards) with positive
                    // curvature that is no worse than the start: a local minimum.
                    let outward = (d == lo && s.slope(d) >= 0.0) || (d == hi && s.slope(d) <= 0.0);
                    let stationary = s.slope(d).abs() <= 1e-9 * s.information(d).abs() * (hi - lo);
                    if (stationary || outward) && s.cost(d) <= c0 {
                        return d;
                    }
                    break;
                }
            }
        }
        minimize_quartic(s, lo, hi)
    }

    /// The fit of one hypothesis (its probability among the seven needs them all: use
    /// [`Self::fits`]; here it is NaN).
    pub fn fit(&self, h: Hypothesis) -> Fit {
        let i = h.index();
        let s = &self.sums[i];
        let (lo, hi) = self.range[i];
        // The global search: the episode's estimate was followed by Newton, which a
        // multi-modal cost can mislead.
        let d = if s.quadratic() {
            self.minimize(i, None)
        } else if self.frames == 0 {
            0.0
        } else {
            minimize_quartic(s, lo, hi)
        };
        let info = s.information(d);
        let theta = h.nominal_parameter() + d;
        let size = match h {
            Hypothesis::PIcGain | Hypothesis::PImGain | Hypothesis::MafGain => 1.0 / theta,
            Hypothesis::LeakBeforeThrottle | Hypothesis::LeakAfterThrottle => {
                self.config.leak_diameter_mm(theta)
            }
            Hypothesis::TIcBias | Hypothesis::ThrottleArea => theta,
        };
        Fit {
            hypothesis: h,
            size,
            parameter: theta,
            parameter_std: if info > 0.0 {
                1.0 / info.sqrt()
            } else {
                f64::INFINITY
            },
            cost: if self.frames == 0 {
                0.0
            } else {
                s.cost(d).max(0.0)
            },
            probability: f64::NAN,
            at_bound: self.frames > 0 && (d == lo || d == hi),
        }
    }

    /// Every hypothesis' fit, the best (lowest cost) first, with the probabilities of the
    /// module docs (equal, 1/7, before any frame).
    pub fn fits(&self) -> [Fit; N_HYPOTHESES] {
        let mut fits = Hypothesis::ALL.map(|h| self.fit(h));
        fits.sort_by(|a, b| a.cost.total_cmp(&b.cost));
        let best = fits[0].cost;
        let mut total = 0.0;
        for f in &mut fits {
            f.probability = (-0.5 * (f.cost - best)).exp();
            total += f.probability;
        }
        for f in &mut fits {
            f.probability /= total;
        }
        fits
    }

    /// The generalized likelihood ratio statistic `C_none - min_h C_h` (>= 0): how much better
    /// the best single fault explains the episode than no fault.
    pub fn evidence(&self) -> f64 {
        let best = Hypothesis::ALL
            .iter()
            .map(|&h| self.fit(h).cost)
            .fold(f64::INFINITY, f64::min);
        (self.rr - best).max(0.0)
    }

    /// Validates a frame and returns `W`.
    fn check(&self, f: &IsolationFrame) -> Result<[[f64; 2]; 2], IsolationError> {
        let r = &f.readings;
        let (t_lo, t_hi) = TEMPERATURE_RANGE_K;
        if !(r.t_ic_k >= t_lo && r.t_ic_k <= t_hi) {
            return Err(IsolationError::Reading {
                name: "T_ic (K)",
                value: r.t_ic_k,
                reason: "outside the model's temperature range 150..3000 K",
            });
        }
        // Below this the model's evaluation clamps the mass, and flow_balance would differ.
        let p_min = MIN_DENSITY_KG_M3 * self.r_air * r.t_ic_k;
        for (name, value) in [("p_ic (Pa)", r.p_ic_pa), ("p_im (Pa)", r.p_im_pa)] {
            if !(value >= p_min && value.is_finite()) {
                return Err(IsolationError::Reading {
                    name,
                    value,
                    reason: "not finite or below the model's smallest density",
                });
            }
        }
        if !r.maf_kg_s.is_finite() {
            return Err(IsolationError::Reading {
                name: "air mass flow (kg/s)",
                value: r.maf_kg_s,
                reason: "not finite",
            });
        }
        if let ExhaustPressure::Estimate { p_em_pa, .. } = f.exhaust {
            if !(p_em_pa > 0.0 && p_em_pa.is_finite()) {
                return Err(IsolationError::Reading {
                    name: "p_em estimate (Pa)",
                    value: p_em_pa,
                    reason: "not finite and positive",
                });
            }
        }
        // The model's check: it evaluates clamped inputs otherwise.
        self.model.check_input(&f.input)?;
        for (name, value) in [
            ("baseline of r_cyl", f.baseline_kg_s[0]),
            ("baseline of r_thr", f.baseline_kg_s[1]),
        ] {
            if !value.is_finite() {
                return Err(IsolationError::Weight {
                    name,
                    value,
                    reason: "not finite",
                });
            }
        }
        let names = ["sigma of r_cyl", "sigma of r_thr", "sigma of r_tc"];
        for (name, &value) in names.iter().zip(&f.sigma_kg_s) {
            if !(value > 0.0 && value.is_finite()) {
                return Err(IsolationError::Weight {
                    name,
                    value,
                    reason: "must be finite and positive",
                });
            }
        }
        Ok(weight(f.sigma_kg_s))
    }
}

/// `W`: the inverse covariance of `[r_cyl, r_thr]` from the standard deviations of the three
/// balances (module docs).
fn weight(sigma: [f64; 3]) -> [[f64; 2]; 2] {
    let [s1, s2, s3] = sigma.map(|s| s * s);
    let bound = MAX_CORRELATION * (s1 * s2).sqrt();
    let cov = (0.5 * (s1 + s2 - s3)).clamp(-bound, bound);
    let det = s1 * s2 - cov * cov;
    [[s2 / det, -cov / det], [-cov / det, s1 / det]]
}

/// The minimizer of `C(d)` over `[lo, hi]`: the best of a grid, then a golden-section search
/// in the grid cells on either side of it.
fn minimize_quartic(s: &Sums, lo: f64, hi: f64) -> f64 {
    let step = (hi - lo) / GRID as f64;
    let at = |i: usize| if i == GRID { hi } else { lo + step * i as f64 };
    let mut best = (0, f64::INFINITY);
    for i in 0..=GRID {
        let c = s.cost(at(i));
        if c < best.1 {
            best = (i, c);
        }
    }
    let (mut a, mut b) = (at(best.0.saturating_sub(1)), at((best.0 + 1).min(GRID)));
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let mut x1 = b - g * (b - a);
    let mut x2 = a + g * (b - a);
    let (mut f1, mut f2) = (s.cost(x1), s.cost(x2));
    for _ in 0..GOLDEN_ITERATIONS {
        if f1 <= f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = s.cost(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = s.cost(x2);
        }
    }
    // The bracket's ends are candidates too (a minimum on the range's bound).
    let mut d = 0.5 * (a + b);
    for x in [lo, hi] {
        if s.cost(x) < s.cost(d) {
            d = x;
        }
    }
    d
}

/// A value with its gradient and the diagonal of its Hessian with respect to `K` seeded
/// variables: the second derivative of a corrected balance by each seed, and no cross terms
/// (each hypothesis moves one parameter). A [`Scalar`], so the model's component code
/// evaluates it; the bank uses `K = 1`, one evaluation per nonlinear hypothesis, because each
/// is expanded at its own estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jet2<const K: usize> {
    /// The value.
    pub v: f64,
    /// `dv/dz_k`.
    pub d: [f64; K],
    /// `d^2 v / dz_k^2`.
    pub dd: [f64; K],
}

impl<const K: usize> Jet2<K> {
    /// The seeded variable `k` with value `v`.
    #[inline]
    pub fn var(v: f64, k: usize) -> Self {
        let mut d = [0.0; K];
        d[k] = 1.0;
        Self { v, d, dd: [0.0; K] }
    }

    /// `phi(self)` given `phi`, `phi'` and `phi''` at the value: `(phi o x)' = phi' x'`,
    /// `(phi o x)'' = phi'' x'^2 + phi' x''`.
    #[inline]
    fn chain(self, v: f64, d1: f64, d2: f64) -> Self {
        let mut out = Self {
            v,
            d: self.d,
            dd: self.dd,
        };
        for k in 0..K {
            out.d[k] = d1 * self.d[k];
            out.dd[k] = d2 * self.d[k] * self.d[k] + d1 * self.dd[k];
        }
        out
    }

    #[inline]
    fn recip(self) -> Self {
        let r = 1.0 / self.v;
        self.chain(r, -r * r, 2.0 * r * r * r)
    }
}

impl<const K: usize> Add for Jet2<K> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: Self) -> Self {
        self.v += o.v;
        for k in 0..K {
            self.d[k] += o.d[k];
            self.dd[k] += o.dd[k];
        }
        self
    }
}

impl<const K: usize> Sub for Jet2<K> {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        self + (-o)
    }
}

impl<const K: usize> Mul for Jet2<K> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        let mut out = self;
        out.v = self.v * o.v;
        for k in 0..K {
            out.d[k] = self.d[k] * o.v + self.v * o.d[k];
            out.dd[k] = self.dd[k] * o.v + 2.0 * self.d[k] * o.d[k] + self.v * o.dd[k];
        }
        out
    }
}

impl<const K: usize> Div for Jet2<K> {
    type Output = Self;
    #[inline]
    fn div(self, o: Self) -> Self {
        // The quotient rule through the reciprocal's chain rule.
        Mul::mul(self, o.recip())
    }
}

impl<const K: usize> Neg for Jet2<K> {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        self * -1.0
    }
}

impl<const K: usize> Add<f64> for Jet2<K> {
    type Output = Self;
    #[inline]
    fn add(mut self, c: f64) -> Self {
        self.v += c;
        self
    }
}

impl<const K: usize> Sub<f64> for Jet2<K> {
    type Output = Self;
    #[inline]
    fn sub(mut self, c: f64) -> Self {
        self.v -= c;
        self
    }
}

impl<const K: usize> Mul<f64> for Jet2<K> {
    type Output = Self;
    #[inline]
    fn mul(mut self, c: f64) -> Self {
        self.v *= c;
        for k in 0..K {
            self.d[k] *= c;
            self.dd[k] *= c;
        }
        self
    }
}

impl<const K: usize> Div<f64> for Jet2<K> {
    type Output = Self;
    #[inline]
    fn div(self, c: f64) -> Self {
        self * (1.0 / c)
    }
}

impl<const K: usize> Scalar for Jet2<K> {
    #[inline]
    fn cst(v: f64) -> Self {
        Self {
            v,
            d: [0.0; K],
            dd: [0.0; K],
        }
    }
    #[inline]
    fn val(self) -> f64 {
        self.v
    }
    #[inline]
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        if s > 0.0 {
            self.chain(s, 0.5 / s, -0.25 / (s * self.v))
        } else {
            // As `Dual`: never differentiated at 0 (the flow functions are linear there).
            self.chain(s, 0.0, 0.0)
        }
    }
    #[inline]
    fn powf(self, e: f64) -> Self {
        let p = self.v.powf(e);
        if self.v != 0.0 {
            let d1 = e * p / self.v;
            self.chain(p, d1, (e - 1.0) * d1 / self.v)
        } else {
            self.chain(p, e * self.v.powf(e - 1.0), 0.0)
        }
    }
    #[inline]
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e, e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jet2_derivatives_match_calculus() {
        // f = x^1.3 exp(x/2) / sqrt(x + 1) - 3 / x, first and second derivatives by x, and a
        // second variable that does not enter has zero derivatives.
        let x = Jet2::<2>::var(1.7, 0);
        let f = x.powf(1.3) * (x * 0.5).exp() / (x + 1.0).sqrt() - Jet2::cst(3.0) / x;
        let g = |a: f64| a.powf(1.3) * (0.5 * a).exp() / (a + 1.0).sqrt() - 3.0 / a;
        let (a, h) = (1.7, 1e-4);
        assert!((f.v - g(a)).abs() < 1e-14);
        let d1 = (g(a + h) - g(a - h)) / (2.0 * h);
        let d2 = (g(a + h) - 2.0 * g(a) + g(a - h)) / (h * h);
        assert!((f.d[0] - d1).abs() < 1e-7, "{} vs {d1}", f.d[0]);
        assert!((f.dd[0] - d2).abs() < 1e-5, "{} vs {d2}", f.dd[0]);
        assert_eq!((f.d[1], f.dd[1]), (0.0, 0.0));
        // Products of two seeded variables keep only the diagonal.
        let y = Jet2::<2>::var(0.3, 1);
        let p = x * x * y;
        assert!((p.dd[0] - 2.0 * 0.3).abs() < 1e-15 && p.dd[1] == 0.0);
    }

    #[test]
    fn weight_inverts_the_covariance_the_three_sigmas_imply() {
        // r_cyl = m - a, r_thr = m - b, r_tc = r_cyl - r_thr = b - a with independent m, a, b.
        let (sm, sa, sb) = (2.0, 3.0, 1.5);
        let s1: f64 = sm * sm + sa * sa;
        let s2 = sm * sm + sb * sb;
        let s3 = sa * sa + sb * sb;
        let w = weight([s1.sqrt(), s2.sqrt(), s3.sqrt()]);
        // Covariance: [[s1, sm^2], [sm^2, s2]]; W times it is the identity.
        let c = [[s1, sm * sm], [sm * sm, s2]];
        let [c0, c1] = c;
        for (i, wi) in w.iter().enumerate() {
            for (j, (a, b)) in c0.iter().zip(&c1).enumerate() {
                let v = wi[0] * a + wi[1] * b;
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12, "{w:?}");
            }
        }
        // Violating the triangle inequality is clamped to a finite weight.
        let w = weight([1.0, 1.0, 5.0]);
        assert!(w.iter().flatten().all(|v| v.is_finite()));
    }

    #[test]
    fn quartic_minimizer_finds_the_global_minimum_in_range() {
        // C(d) = (d^2 - 1)^2 + 0.1 d = d^4 - 2 d^2 + 0.1 d + 1: minima near -1 (lower) and
        // +1; as sums: S00 = 1, 2 S01 = 0.1, S11 + 2 S02 = -2, S22 = 1.
        let s = Sums {
            s00: 1.0,
            s01: 0.05,
            s02: -1.0,
            s11: 0.0,
            s12: 0.0,
            s22: 1.0,
        };
        let d = minimize_quartic(&s, -3.0, 3.0);
        let exact = -1.0124;
        assert!((d - exact).abs() < 1e-3, "{d}");
        // Restricted to [0, 3] it is the other one, and to [2, 3] the bound.
        let d = minimize_quartic(&s, 0.0, 3.0);
        assert!((d - 0.9874).abs() < 1e-3, "{d}");
        assert_eq!(minimize_quartic(&s, 2.0, 3.0), 2.0);
    }
}
