//! Mean-value model of the intake manifold of a naturally aspirated 2.0 L four-cylinder engine
//! with EGR, after the MAP/MAF EKF paper (shared/REFERENCE.md §2), sampled once per 180 deg crank
//! segment: `dt = 30 / N` s (N in rpm), so the step length changes with every segment.
//!
//! State `x = [p_m, p_mes, W_thr, W_mes, q1, q2]`: manifold pressure (Pa), MAP sensor output (Pa),
//! throttle mass flow (kg/s), MAF sensor output (kg/s), pumping-fluctuation pressure `q` (Pa) and
//! its rate `q'` (Pa/s). Input `u = [N, theta, e]` (indices [`U_SPEED`], [`U_THROTTLE`],
//! [`U_EGR`]): engine speed (rpm), throttle opening (deg from the closed plate, `0..90 -
//! throttle_closed_angle_deg`) and EGR valve position (`0..1`). The step length is computed
//! inside from `u[0]`, so the generic filters need no change for the varying `dt`.
//!
//! Continuous model (what [`IntakeModel::continuous_derivative`] returns, integrated finely by
//! [`IntakeModel::integrate_rk4`] as the truth):
//!
//! ```text
//! dp_m/dt   = R T_m / V_m (W_thr(p_m, theta) + W_egr(p_m, e) - W_inv(p_m, N))
//! dp_mes/dt = (p_m + q1 - p_mes) / tau_map
//! dW_mes/dt = (W_thr(p_m, theta) - W_mes) / tau_maf
//! q1' = q2,  q2' = -w^2 q1 - 2 xi w q2,   w = 2 pi N / 30 rad/s
//! ```
//!
//! with `W_thr` algebraic (the nozzle flow; the truth stores its current value in `x[2]`).
//!
//! How we read the paper and where we depart from it:
//! - **Nozzle flow** `W = p_up A / sqrt(R T_up) Psi(psi)`, `psi = p_down / p_up`: choked
//!   (`psi < psi_crit = (2/(k+1))^(k/(k-1))`, 0.5283 for k = 1.4) and subsonic (`psi_crit <= psi
//!   < 0.97`) as in the paper. For `psi >= 0.97` the paper takes the throttle flow equal to the
//!   intake-valve flow, because the flow function is too steep there to compute the flow from the
//!   pressure ratio. Used literally inside `dp_m/dt` that rule freezes the pressure (with EGR
//!   closed `dp_m/dt = 0`, and the manifold could never leave the region when the throttle
//!   closes). We therefore continue `Psi` **linearly** from `Psi(0.97)` to zero at `psi = 1`
//!   (the linearization near `psi = 1` of Eriksson & Nielsen, *Modeling and Control of Engines
//!   and Drivelines*, 2014, §7.4), which keeps `Psi` continuous and its slope finite. In that
//!   region the manifold is then a fast first-order system whose quasi-steady state is
//!   `W_thr = W_inv - W_egr`: the paper's rule (the EGR is closed at the loads where the
//!   throttle is this wide open). `psi >= 1` (reverse flow) gives zero flow; a negative or NaN
//!   ratio is treated as 0 (choked) so that no NaN can come out of a flow.
//! - **EGR**: the same nozzle with upstream `p_egr`, `T_egr`, area `e * A_egr_max` (a linear
//!   valve characteristic, our choice).
//! - **Throttle area** (the paper gives none): `A(theta) = A_leak + Cd pi D^2 / 4 (1 - cos(a0 +
//!   theta) / cos(a0))` with the plate's closed angle `a0` (Heywood, *Internal Combustion Engine
//!   Fundamentals*, 1988, §7.2.1). `theta` is clamped to its range.
//! - **Intake valve**: `W_inv = eta_slope(N) p_m - eta_ofs(N)`, slope and offset interpolated
//!   linearly over speed between the mapped points and held constant outside them.
//! - **Pumping fluctuation**: the paper's oscillator has no input, so `q` only decays from its
//!   initial state; a filter must give `q1, q2` process noise to keep it alive. It is
//!   discretized exactly with the closed-form `expm(A dt)` ([`oscillator_transition`]); this
//!   needs `0 <= xi < 1`. At `dt = 30 / N` a step is one undamped period of the oscillation.
//! - **Discrete model** ([`TransitionModel`]): in general the step is cut into `n = ceil(dt /
//!   max_substep_s)` equal substeps. In each, `p_m` advances by an exponential (Rosenbrock)
//!   Euler step, `p+ = p + h f(p) phi1(h f'(p))`, exact for the linear part and stable however
//!   stiff the steep region makes it (the paper's plain Euler at `dt = 37.5 ms` is not); the
//!   sensor lags are discretized exactly for an input linear across the substep (first-order
//!   hold, `a = exp(-h / tau)` rather than the paper's `(1 + h/tau)^-1`, which at 800 rpm and
//!   `tau_map = 7 ms` would leave 17 % instead of 0.5 % of the old reading); and the oscillator's
//!   exact contribution to the MAP lag is added in closed form. `W_thr` is either recomputed from
//!   the nozzle model at the end of the step ([`ThrottleFlow::Nozzle`], what tracks the
//!   continuous model) or carried as a random walk ([`ThrottleFlow::RandomWalk`], the paper's
//!   filter; then `p_m` uses the state's `W_thr` held over the step).
//! - **Closed-form segment** (random walk only): with `W_thr` held, `dp_m/dt` is affine in
//!   `p_m` whenever the EGR flow is constant over the segment (valve closed, or its nozzle
//!   choked at both ends of the segment, the trajectory being monotone). Then the whole segment
//!   is computed exactly in one step, without substeps: `p_m` follows its exponential, the MAP
//!   lag is integrated exactly along that exponential, the MAF lag sees a constant input, the
//!   oscillator and its MAP contribution are the closed forms over `dt` (see
//!   `IntakeModel::affine_segment`). This is what the filters run at almost every segment
//!   (throttle-only driving, and EGR at part load where `p_m < 0.53 p_egr`), about 75 times
//!   fewer flow evaluations at 800 rpm; elsewhere the substeps run as above. The two agree
//!   where both apply except for the substeps' linear-in-time MAP-lag input, at most
//!   `max_substep_s^2 / 8 max|p_m''|` (around a pascal in a fast transient).
//! - **Bad input**: [`IntakeModel::check_input`] and [`IntakeModel::check_measurement`] name
//!   the offending value; the monitor calls them before a filter step. A transition with an
//!   input they would refuse returns the state unchanged rather than NaN.

use std::f64::consts::PI;

use nalgebra::{Matrix2, SMatrix, SVector, Vector1, Vector2, Vector3};
use serde::Deserialize;
use thiserror::Error;

use crate::model::{ObservationModel, TransitionModel};
use crate::param::{show, ParamError, Range};

/// The state vector `[p_m, p_mes, W_thr, W_mes, q1, q2]`.
pub type IntakeState = SVector<f64, 6>;
/// The input vector `[N (rpm), theta (deg), e (0..1)]`.
pub type IntakeInput = Vector3<f64>;

/// Index of the engine speed (rpm) in the input.
pub const U_SPEED: usize = 0;
/// Index of the throttle opening (deg from closed) in the input.
pub const U_THROTTLE: usize = 1;
/// Index of the EGR valve position (0..1) in the input.
pub const U_EGR: usize = 2;
/// State index of the manifold pressure (Pa).
pub const X_PM: usize = 0;
/// State index of the MAP sensor output (Pa).
pub const X_PMES: usize = 1;
/// State index of the throttle mass flow (kg/s).
pub const X_WTHR: usize = 2;
/// State index of the MAF sensor output (kg/s).
pub const X_WMES: usize = 3;
/// State index of the pumping fluctuation `q` (Pa).
pub const X_Q1: usize = 4;
/// State index of the pumping fluctuation rate `q'` (Pa/s).
pub const X_Q2: usize = 5;

/// Intake model parameters (the `[model]` table of `config/intake.toml`). Units are in the names.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IntakeParams {
    /// Ambient (throttle upstream) pressure `p_a` (Pa).
    pub ambient_pressure_pa: f64,
    /// Ambient (throttle upstream) temperature `T_a` (K).
    pub ambient_temperature_k: f64,
    /// Specific gas constant of air `R` (J/(kg K)).
    pub gas_constant_j_per_kg_k: f64,
    /// Ratio of specific heats `k` (-).
    pub heat_capacity_ratio: f64,
    /// Manifold volume `V_m` (m^3).
    pub manifold_volume_m3: f64,
    /// Manifold temperature `T_m` (K), fixed (isothermal manifold).
    pub manifold_temperature_k: f64,
    /// Throttle bore `D` (m).
    pub throttle_bore_m: f64,
    /// Throttle discharge coefficient `Cd` (-).
    pub throttle_discharge_coefficient: f64,
    /// Plate angle at the closed stop `a0` (deg from the plane normal to the bore).
    pub throttle_closed_angle_deg: f64,
    /// Leakage area of the closed throttle (m^2).
    pub throttle_leak_area_m2: f64,
    /// EGR upstream (exhaust) pressure `p_egr` (Pa).
    pub egr_upstream_pressure_pa: f64,
    /// EGR gas temperature at the valve `T_egr` (K).
    pub egr_temperature_k: f64,
    /// Effective EGR valve area when fully open (m^2).
    pub egr_max_area_m2: f64,
    /// Pressure ratio above which the flow function is continued linearly to zero at 1 (the
    /// paper's 0.97).
    pub steep_ratio: f64,
    /// Speeds (rpm) of the volumetric-efficiency map, strictly increasing.
    pub vol_eff_speeds_rpm: Vec<f64>,
    /// `eta_slope` at each mapped speed (kg/(s Pa)).
    pub vol_eff_slope_kg_per_s_pa: Vec<f64>,
    /// `eta_ofs` at each mapped speed (kg/s).
    pub vol_eff_offset_kg_per_s: Vec<f64>,
    /// MAP sensor time constant `tau_map` (s).
    pub map_time_constant_s: f64,
    /// MAF sensor time constant `tau_maf` (s).
    pub maf_time_constant_s: f64,
    /// Damping ratio `xi` of the pumping-fluctuation oscillator, `0 <= xi < 1`.
    pub pump_damping: f64,
    /// Lowest engine speed a step is computed for (rpm); slower is refused.
    pub min_speed_rpm: f64,
    /// Highest engine speed accepted (rpm).
    pub max_speed_rpm: f64,
    /// Longest substep of the discrete model (s).
    pub max_substep_s: f64,
    /// Largest plausible MAP reading as a multiple of `p_a` (pulsation and sensor error above
    /// ambient); higher readings are refused.
    pub max_map_ratio: f64,
    /// MAP sensor noise standard deviation (Pa).
    pub map_noise_std_pa: f64,
    /// MAF sensor noise standard deviation relative to the reading (-).
    pub maf_noise_rel: f64,
}

/// Admissible ranges of the `[model]` keys: generous physical bounds, so that any engine and
/// weather the model can describe passes and typos (a unit off by 1e3, a sign) do not.
pub mod ranges {
    use crate::param::Range;

    /// Ambient pressure: 10 kPa (far above any road) to 200 kPa.
    pub const AMBIENT_PRESSURE_PA: Range = Range::closed(1e4, 2e5, "Pa");
    /// Ambient temperature: -73 C to 127 C.
    pub const AMBIENT_TEMPERATURE_K: Range = Range::closed(200.0, 400.0, "K");
    /// Specific gas constant.
    pub const GAS_CONSTANT: Range = Range::closed(100.0, 1000.0, "J/(kg K)");
    /// Ratio of specific heats (above 1 for any gas).
    pub const HEAT_CAPACITY_RATIO: Range = Range::above(1.0, 2.0, "");
    /// Manifold volume.
    pub const MANIFOLD_VOLUME_M3: Range = Range::above(0.0, 0.1, "m^3");
    /// Manifold and EGR gas temperatures.
    pub const MANIFOLD_TEMPERATURE_K: Range = Range::closed(200.0, 600.0, "K");
    /// EGR gas temperature at the valve.
    pub const EGR_TEMPERATURE_K: Range = Range::closed(200.0, 1500.0, "K");
    /// Throttle bore.
    pub const BORE_M: Range = Range::above(0.0, 0.5, "m");
    /// Discharge coefficient.
    pub const DISCHARGE_COEFFICIENT: Range = Range::above(0.0, 1.0, "");
    /// Closed plate angle (the effective area needs cos(a0) well above 0).
    pub const CLOSED_ANGLE_DEG: Range = Range::below(0.0, 45.0, "deg");
    /// Leakage and EGR valve areas (0: none).
    pub const AREA_M2: Range = Range::closed(0.0, 0.01, "m^2");
    /// Exhaust back-pressure upstream of the EGR valve.
    pub const EGR_PRESSURE_PA: Range = Range::closed(1e4, 1e6, "Pa");
    /// Speeds of the volumetric-efficiency map.
    pub const MAP_SPEED_RPM: Range = Range::closed(0.0, 20_000.0, "rpm");
    /// Volumetric-efficiency slope.
    pub const VE_SLOPE: Range = Range::above(0.0, 1e-3, "kg/(s Pa)");
    /// Volumetric-efficiency offset (signed).
    pub const VE_OFFSET: Range = Range::closed(-1.0, 1.0, "kg/s");
    /// Sensor time constants: from 0.1 ms to 1 s.
    pub const SENSOR_TIME_CONSTANT_S: Range = Range::closed(1e-4, 1.0, "s");
    /// Damping ratio of the (underdamped) pulsation oscillator.
    pub const PUMP_DAMPING: Range = Range::below(0.0, 1.0, "");
    /// Accepted engine speeds: below 50 rpm the segment time 30/N (and the number of
    /// substeps) grows without bound.
    pub const SPEED_RPM: Range = Range::closed(50.0, 20_000.0, "rpm");
    /// Longest substep: from 10 us (a 0.6 s segment at 50 rpm is then 60000 substeps) to 10 ms.
    pub const MAX_SUBSTEP_S: Range = Range::closed(1e-5, 1e-2, "s");
    /// Largest plausible MAP reading over ambient.
    pub const MAX_MAP_RATIO: Range = Range::closed(1.0, 5.0, "");
    /// MAP sensor noise.
    pub const MAP_NOISE_PA: Range = Range::above(0.0, 1e5, "Pa");
    /// MAF relative noise.
    pub const MAF_NOISE_REL: Range = Range::above(0.0, 1.0, "");
}

impl IntakeParams {
    /// Checks every key against its range ([`ranges`]) and the relations between them, naming
    /// the offending key relative to the `[model]` table (`vol_eff_speeds_rpm[3]`).
    pub fn validate(&self) -> Result<(), ParamError> {
        use ranges as r;
        let checks = [
            (
                "ambient_pressure_pa",
                self.ambient_pressure_pa,
                r::AMBIENT_PRESSURE_PA,
            ),
            (
                "ambient_temperature_k",
                self.ambient_temperature_k,
                r::AMBIENT_TEMPERATURE_K,
            ),
            (
                "gas_constant_j_per_kg_k",
                self.gas_constant_j_per_kg_k,
                r::GAS_CONSTANT,
            ),
            (
                "heat_capacity_ratio",
                self.heat_capacity_ratio,
                r::HEAT_CAPACITY_RATIO,
            ),
            (
                "manifold_volume_m3",
                self.manifold_volume_m3,
                r::MANIFOLD_VOLUME_M3,
            ),
            (
                "manifold_temperature_k",
                self.manifold_temperature_k,
                r::MANIFOLD_TEMPERATURE_K,
            ),
            ("throttle_bore_m", self.throttle_bore_m, r::BORE_M),
            (
                "throttle_discharge_coefficient",
                self.throttle_discharge_coefficient,
                r::DISCHARGE_COEFFICIENT,
            ),
            (
                "throttle_closed_angle_deg",
                self.throttle_closed_angle_deg,
                r::CLOSED_ANGLE_DEG,
            ),
            (
                "throttle_leak_area_m2",
                self.throttle_leak_area_m2,
                r::AREA_M2,
            ),
            (
                "egr_upstream_pressure_pa",
                self.egr_upstream_pressure_pa,
                r::EGR_PRESSURE_PA,
            ),
            (
                "egr_temperature_k",
                self.egr_temperature_k,
                r::EGR_TEMPERATURE_K,
            ),
            ("egr_max_area_m2", self.egr_max_area_m2, r::AREA_M2),
            (
                "map_time_constant_s",
                self.map_time_constant_s,
                r::SENSOR_TIME_CONSTANT_S,
            ),
            (
                "maf_time_constant_s",
                self.maf_time_constant_s,
                r::SENSOR_TIME_CONSTANT_S,
            ),
            ("pump_damping", self.pump_damping, r::PUMP_DAMPING),
            ("min_speed_rpm", self.min_speed_rpm, r::SPEED_RPM),
            ("max_speed_rpm", self.max_speed_rpm, r::SPEED_RPM),
            ("max_substep_s", self.max_substep_s, r::MAX_SUBSTEP_S),
            ("max_map_ratio", self.max_map_ratio, r::MAX_MAP_RATIO),
            ("map_noise_std_pa", self.map_noise_std_pa, r::MAP_NOISE_PA),
            ("maf_noise_rel", self.maf_noise_rel, r::MAF_NOISE_REL),
        ];
        for (key, v, range) in checks {
            range.check(key, v)?;
        }
        let crit = critical_ratio(self.heat_capacity_ratio);
        let steep = Range::open(crit, 1.0, "");
        if !steep.contains(self.steep_ratio) {
            return Err(ParamError::new(
                "steep_ratio",
                show(self.steep_ratio),
                format!(
                    "must lie between the critical ratio {crit:.4} (of heat_capacity_ratio) and 1"
                ),
            ));
        }
        if !(self.min_speed_rpm < self.max_speed_rpm) {
            return Err(ParamError::new(
                "max_speed_rpm",
                show(self.max_speed_rpm),
                format!(
                    "must be above `min_speed_rpm` = {}",
                    show(self.min_speed_rpm)
                ),
            ));
        }
        let lists = [
            ("vol_eff_speeds_rpm", self.vol_eff_speeds_rpm.len()),
            (
                "vol_eff_slope_kg_per_s_pa",
                self.vol_eff_slope_kg_per_s_pa.len(),
            ),
            (
                "vol_eff_offset_kg_per_s",
                self.vol_eff_offset_kg_per_s.len(),
            ),
        ];
        for (key, n) in lists {
            if !(1..=MAX_MAP_POINTS).contains(&n) {
                return Err(ParamError::new(
                    key,
                    format!("[{n} values]"),
                    format!("must have 1 to {MAX_MAP_POINTS} values"),
                ));
            }
        }
        // The three lists must have one length: blame the one that differs from the other two.
        let [(ks, ns), (kl, nl), (ko, no)] = lists;
        let odd = if nl == no && ns != nl {
            Some((ks, ns, nl))
        } else if ns == no && nl != ns {
            Some((kl, nl, ns))
        } else if ns == nl && no != ns {
            Some((ko, no, ns))
        } else if ns != nl {
            Some((kl, nl, ns))
        } else {
            None
        };
        if let Some((key, n, expected)) = odd {
            return Err(ParamError::new(
                key,
                format!("[{n} values]"),
                format!("must have one value per speed of the map: {expected} like the other vol_eff_* lists"),
            ));
        }
        let n = self.vol_eff_speeds_rpm.len();
        for i in 0..n {
            let s = self.vol_eff_speeds_rpm[i];
            let key = format!("vol_eff_speeds_rpm[{i}]");
            r::MAP_SPEED_RPM.check(&key, s)?;
            if i > 0 && !(s > self.vol_eff_speeds_rpm[i - 1]) {
                return Err(ParamError::new(
                    key,
                    show(s),
                    format!(
                        "must be above vol_eff_speeds_rpm[{}] = {} (speeds strictly increasing)",
                        i - 1,
                        show(self.vol_eff_speeds_rpm[i - 1])
                    ),
                ));
            }
            r::VE_SLOPE.check(
                &format!("vol_eff_slope_kg_per_s_pa[{i}]"),
                self.vol_eff_slope_kg_per_s_pa[i],
            )?;
            r::VE_OFFSET.check(
                &format!("vol_eff_offset_kg_per_s[{i}]"),
                self.vol_eff_offset_kg_per_s[i],
            )?;
        }
        Ok(())
    }
}

/// Most speeds of the volumetric-efficiency map.
pub const MAX_MAP_POINTS: usize = 1000;

/// A refused input or measurement, naming the quantity and its value.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum IntakeInputError {
    /// A value is NaN or infinite.
    #[error("{name} is not finite ({value})")]
    NonFinite { name: &'static str, value: f64 },
    /// A value is outside its admissible range.
    #[error("{name} = {value} is outside [{min}, {max}]")]
    OutOfRange {
        name: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
}

/// How the discrete model moves the throttle-flow state `W_thr`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ThrottleFlow {
    /// `W_thr` is recomputed each step from the nozzle model at the new manifold pressure, and
    /// the pressure dynamics use the nozzle flow along the step. Tracks the continuous model.
    #[default]
    Nozzle,
    /// `W_thr` is a random walk (the paper's filter), held over the step in the pressure dynamics.
    RandomWalk,
}

/// Critical pressure ratio `(2/(k+1))^(k/(k-1))`.
pub fn critical_ratio(k: f64) -> f64 {
    (2.0 / (k + 1.0)).powf(k / (k - 1.0))
}

/// Subsonic flow function `sqrt(2k/(k-1) (psi^(2/k) - psi^((k+1)/k)))` and its derivative.
fn subsonic(psi: f64, k: f64) -> (f64, f64) {
    let c = 2.0 * k / (k - 1.0);
    let a = psi.powf(2.0 / k);
    let b = psi.powf((k + 1.0) / k);
    let inner = (c * (a - b)).max(0.0);
    let val = inner.sqrt();
    let dinner = c * ((2.0 / k) * a / psi - ((k + 1.0) / k) * b / psi);
    let der = if val > 0.0 { 0.5 * dinner / val } else { 0.0 };
    (val, der)
}

/// The flow function `Psi(psi)` of the three regimes (choked, subsonic, linear continuation
/// above `steep`) and its derivative `dPsi/dpsi`. Ratios below 0, NaN or above 1 are handled as
/// described in the module docs (choked, choked, zero).
pub fn flow_function(psi: f64, k: f64, steep: f64) -> (f64, f64) {
    FlowConsts::new(k, steep).eval(psi)
}

/// The speed-independent constants of [`flow_function`], computed once per model.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FlowConsts {
    k: f64,
    steep: f64,
    crit: f64,
    choked: f64,
    top: f64,
    slope: f64,
}

impl FlowConsts {
    fn new(k: f64, steep: f64) -> Self {
        let top = subsonic(steep, k).0;
        Self {
            k,
            steep,
            crit: critical_ratio(k),
            // (k (2/(k+1))^((k+1)/(k-1)))^(1/2), equal to the subsonic formula at psi_crit.
            choked: (k * (2.0 / (k + 1.0)).powf((k + 1.0) / (k - 1.0))).sqrt(),
            top,
            slope: -top / (1.0 - steep),
        }
    }

    #[inline]
    fn eval(&self, psi: f64) -> (f64, f64) {
        let psi = if psi.is_nan() { 0.0 } else { psi };
        if psi < self.crit {
            (self.choked, 0.0)
        } else if psi < self.steep {
            subsonic(psi, self.k)
        } else if psi < 1.0 {
            (self.top + self.slope * (psi - self.steep), self.slope)
        } else {
            (0.0, 0.0)
        }
    }

    /// `d^2 Psi / dpsi^2`: non-zero only in the subsonic regime (the others are affine).
    fn curvature(&self, psi: f64) -> f64 {
        if psi.is_nan() || psi < self.crit || psi >= self.steep {
            return 0.0;
        }
        let k = self.k;
        let c = 2.0 * k / (k - 1.0);
        let a = psi.powf(2.0 / k);
        let b = psi.powf((k + 1.0) / k);
        let val = (c * (a - b)).max(0.0).sqrt();
        if !(val > 0.0) {
            return 0.0;
        }
        let dinner = c * ((2.0 / k) * a - ((k + 1.0) / k) * b) / psi;
        let d2inner =
            c * ((2.0 / k) * (2.0 / k - 1.0) * a - ((k + 1.0) / k) * (1.0 / k) * b) / (psi * psi);
        let der = 0.5 * dinner / val;
        (0.5 * d2inner - der * der) / val
    }
}

/// `expm(A t)` for `A = [[0, 1], [-w^2, -2 xi w]]` with `0 <= xi < 1`, in closed form:
/// `exp(-xi w t) (cos(wd t) I + sin(wd t) / wd (A + xi w I))`, `wd = w sqrt(1 - xi^2)`.
pub fn oscillator_transition(w: f64, xi: f64, t: f64) -> Matrix2<f64> {
    let wd = w * (1.0 - xi * xi).sqrt();
    let decay = (-xi * w * t).exp();
    let (s, c) = (wd * t).sin_cos();
    // sin(wd t) / wd, finite as wd -> 0.
    let sw = if wd * t == 0.0 { t } else { s / wd };
    decay * Matrix2::new(c + sw * xi * w, sw, -sw * w * w, c - sw * xi * w)
}

/// `phi1(z) = (e^z - 1) / z`.
#[inline]
fn phi1(z: f64) -> f64 {
    if z.abs() < 1e-8 {
        1.0 + z / 2.0
    } else {
        z.exp_m1() / z
    }
}

/// `phi1'(z) = (e^z - phi1(z)) / z`.
#[inline]
fn dphi1(z: f64) -> f64 {
    if z.abs() < 1e-3 {
        0.5 + z * (1.0 / 3.0 + z * (1.0 / 8.0 + z / 30.0))
    } else {
        (z.exp() - phi1(z)) / z
    }
}

/// Exact contribution of the pulsation `q(0)` to the MAP lag's output after a step `h` (s):
/// `g = (1/tau) [1 0] (A + I/tau)^-1 (expm(A h) - exp(-h/tau) I)`, from the variation of
/// constants for `y' = (q1 - y) / tau`, `q' = A q`. Valid for any `h`; `e = expm(A h)` and
/// `decay = exp(-h / tau)` are passed in because the callers have them.
#[inline]
fn map_pulsation_gain(
    w: f64,
    xi: f64,
    tau: f64,
    h: f64,
    e: &Matrix2<f64>,
    decay: f64,
) -> nalgebra::RowVector2<f64> {
    debug_assert!(h > 0.0);
    // A + I/tau is never singular: its determinant 1/tau^2 - 2 xi w / tau + w^2 > 0 for xi < 1.
    let m22 = 1.0 / tau - 2.0 * xi * w;
    let det = (1.0 / tau) * m22 + w * w;
    let row = nalgebra::RowVector2::new(m22 / det, -1.0 / det) / tau;
    row * (e - Matrix2::identity() * decay)
}

/// Weight `c(z, r)` of `f0 h` in the output of a first-order lag (time constant `tau`, `r = h /
/// tau`) after a step `h` whose input moves along the exponential `p(t) = p0 + f0 t phi1(j t)`,
/// `z = j h`:
///
/// ```text
/// y(h) = a y0 + (1 - a) p0 + f0 h c(z, r),   a = exp(-r),
/// c(z, r) = int_0^1 r exp(-r (1 - s)) s phi1(z s) ds = r exp(-r) (phi1(z + r) - phi1(r)) / z.
/// ```
///
/// `c` is a weighted mean of `s phi1(z s)` (weights summing to `1 - a`), so it is bounded and
/// well-conditioned; only the divided difference cancels, by about `eps / |z|`. Below `|z| =
/// 1e-3` a series in `z` is used instead (truncation below 1e-14 relative).
fn lag_ramp_weight(z: f64, r: f64) -> f64 {
    if z.abs() >= 1e-3 {
        let em = (-r).exp();
        // exp(-r) phi1(z + r) = (e^z - e^-r) / (z + r), written so that neither overflows.
        let first = if z + r < 500.0 {
            em * phi1(z + r)
        } else {
            (z.exp() - em) / (z + r)
        };
        // exp(-r) phi1(r) = (1 - e^-r) / r.
        let second = -(-r).exp_m1() / r;
        r * (first - second) / z
    } else {
        // c = sum_k z^(k-1) / k! J_k(r), J_k(r) = int_0^1 r exp(-r (1 - s)) s^k ds.
        let m = lag_moments(r);
        m[0] + z * (m[1] / 2.0 + z * (m[2] / 6.0 + z * m[3] / 24.0))
    }
}

/// `J_k(r) = int_0^1 r exp(-r (1 - s)) s^k ds` for `k = 1..4` (each in `[0, 1]`): the
/// all-positive series `r e^-r sum_m r^m / (m! (m + k + 1))` up to `r = 20`, above it the
/// recurrence `J_k = 1 - (k / r) J_(k-1)` from `J_0 = 1 - e^-r`, stable there (`k / r < 1`).
fn lag_moments(r: f64) -> [f64; 4] {
    let mut out = [0.0; 4];
    if r <= 20.0 {
        let mut term = 1.0; // r^m / m!
        let mut m = 0.0;
        for _ in 0..200 {
            for (k, o) in out.iter_mut().enumerate() {
                *o += term / (m + k as f64 + 2.0);
            }
            m += 1.0;
            term *= r / m;
            if term < 1e-17 * out[0] {
                break;
            }
        }
        let scale = r * (-r).exp();
        for o in &mut out {
            *o *= scale;
        }
    } else {
        let mut prev = -(-r).exp_m1();
        for (k, o) in out.iter_mut().enumerate() {
            prev = 1.0 - (k as f64 + 1.0) / r * prev;
            *o = prev;
        }
    }
    out
}

/// The intake manifold model: continuous truth and per-segment discrete transition.
#[derive(Debug, Clone, PartialEq)]
pub struct IntakeModel {
    /// Shared, so that a filter bank's copies of the model (a monitor builds several filters
    /// on it at the start of every operation cycle) cost a reference count, not an allocation.
    params: std::sync::Arc<IntakeParams>,
    flow: ThrottleFlow,
    /// `R T_m / V_m` (Pa / kg).
    gain: f64,
    /// `p_a / sqrt(R T_a)` (kg / (s m^2)).
    thr_scale: f64,
    /// `p_egr / sqrt(R T_egr)`.
    egr_scale: f64,
    /// Constants of the flow function.
    nozzle: FlowConsts,
}

impl IntakeModel {
    /// Wraps validated parameters; `flow` chooses how the discrete model moves `W_thr`.
    pub fn new(params: IntakeParams, flow: ThrottleFlow) -> Result<Self, String> {
        params.validate().map_err(|e| e.to_string())?;
        let r = params.gas_constant_j_per_kg_k;
        Ok(Self {
            gain: r * params.manifold_temperature_k / params.manifold_volume_m3,
            thr_scale: params.ambient_pressure_pa / (r * params.ambient_temperature_k).sqrt(),
            egr_scale: params.egr_upstream_pressure_pa / (r * params.egr_temperature_k).sqrt(),
            nozzle: FlowConsts::new(params.heat_capacity_ratio, params.steep_ratio),
            params: std::sync::Arc::new(params),
            flow,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &IntakeParams {
        &self.params
    }

    /// How `W_thr` is moved.
    pub fn throttle_flow_mode(&self) -> ThrottleFlow {
        self.flow
    }

    /// Segment length `30 / N` (s) for a speed in rpm.
    #[inline]
    pub fn segment_dt(speed_rpm: f64) -> f64 {
        30.0 / speed_rpm
    }

    /// Pulsation frequency `w = 2 pi N / 30` (rad/s).
    #[inline]
    pub fn pump_frequency(speed_rpm: f64) -> f64 {
        2.0 * PI * speed_rpm / 30.0
    }

    /// Refuses inputs the model must not be stepped with: a non-finite component, a speed
    /// outside `[min_speed_rpm, max_speed_rpm]` (so 0 and negative speeds), a throttle opening
    /// outside `[0, 90 - a0]` deg, an EGR position outside `[0, 1]`.
    pub fn check_input(&self, u: &IntakeInput) -> Result<(), IntakeInputError> {
        let p = &self.params;
        let checks = [
            (
                "engine speed (rpm)",
                u[U_SPEED],
                p.min_speed_rpm,
                p.max_speed_rpm,
            ),
            (
                "throttle opening (deg)",
                u[U_THROTTLE],
                0.0,
                90.0 - p.throttle_closed_angle_deg,
            ),
            ("EGR valve position", u[U_EGR], 0.0, 1.0),
        ];
        for (name, value, min, max) in checks {
            if !value.is_finite() {
                return Err(IntakeInputError::NonFinite { name, value });
            }
            if !(value >= min && value <= max) {
                return Err(IntakeInputError::OutOfRange {
                    name,
                    value,
                    min,
                    max,
                });
            }
        }
        Ok(())
    }

    /// Refuses implausible sensor readings: non-finite, a MAP below 0 or above `max_map_ratio *
    /// p_a` (the manifold of a naturally aspirated engine cannot be much above ambient), a
    /// negative MAF beyond five noise deviations of a zero flow.
    pub fn check_measurement(&self, map_pa: f64, maf_kg_s: f64) -> Result<(), IntakeInputError> {
        let p = &self.params;
        if !map_pa.is_finite() {
            return Err(IntakeInputError::NonFinite {
                name: "MAP (Pa)",
                value: map_pa,
            });
        }
        if !maf_kg_s.is_finite() {
            return Err(IntakeInputError::NonFinite {
                name: "MAF (kg/s)",
                value: maf_kg_s,
            });
        }
        let max = p.max_map_ratio * p.ambient_pressure_pa;
        if !(map_pa >= 0.0 && map_pa <= max) {
            return Err(IntakeInputError::OutOfRange {
                name: "MAP (Pa)",
                value: map_pa,
                min: 0.0,
                max,
            });
        }
        if maf_kg_s < -1e-3 {
            return Err(IntakeInputError::OutOfRange {
                name: "MAF (kg/s)",
                value: maf_kg_s,
                min: -1e-3,
                max: f64::INFINITY,
            });
        }
        Ok(())
    }

    fn input_ok(&self, u: &IntakeInput) -> bool {
        let p = &self.params;
        u.iter().all(|v| v.is_finite())
            && u[U_SPEED] >= p.min_speed_rpm
            && u[U_SPEED] <= p.max_speed_rpm
    }

    /// Effective throttle area (m^2) at opening `theta_deg` (clamped to `[0, 90 - a0]`).
    pub fn throttle_area(&self, theta_deg: f64) -> f64 {
        let p = &self.params;
        let a0 = p.throttle_closed_angle_deg;
        let th = if theta_deg.is_nan() {
            0.0
        } else {
            theta_deg.clamp(0.0, 90.0 - a0)
        };
        let open = 1.0 - (a0 + th).to_radians().cos() / a0.to_radians().cos();
        p.throttle_leak_area_m2
            + p.throttle_discharge_coefficient * PI * p.throttle_bore_m.powi(2) / 4.0 * open
    }

    /// Effective EGR area (m^2) at position `e` (clamped to `[0, 1]`).
    pub fn egr_area(&self, e: f64) -> f64 {
        let e = if e.is_nan() { 0.0 } else { e.clamp(0.0, 1.0) };
        e * self.params.egr_max_area_m2
    }

    /// Throttle flow (kg/s) and its derivative with respect to `p_m`, for an effective area.
    pub fn throttle_flow_area(&self, p_m: f64, area: f64) -> (f64, f64) {
        let p = &self.params;
        let (f, d) = self.nozzle.eval(p_m / p.ambient_pressure_pa);
        let s = self.thr_scale * area;
        (s * f, s * d / p.ambient_pressure_pa)
    }

    /// Throttle flow (kg/s) at manifold pressure `p_m` (Pa) and opening `theta_deg`.
    pub fn throttle_flow(&self, p_m: f64, theta_deg: f64) -> f64 {
        self.throttle_flow_area(p_m, self.throttle_area(theta_deg))
            .0
    }

    /// EGR flow (kg/s) and its derivative with respect to `p_m`, for an effective area.
    pub fn egr_flow_area(&self, p_m: f64, area: f64) -> (f64, f64) {
        let p = &self.params;
        let (f, d) = self.nozzle.eval(p_m / p.egr_upstream_pressure_pa);
        let s = self.egr_scale * area;
        (s * f, s * d / p.egr_upstream_pressure_pa)
    }

    /// EGR flow (kg/s) at manifold pressure `p_m` (Pa) and valve position `e`.
    pub fn egr_flow(&self, p_m: f64, e: f64) -> f64 {
        self.egr_flow_area(p_m, self.egr_area(e)).0
    }

    /// `(eta_slope, eta_ofs)` at `speed_rpm`, linear between mapped speeds, constant outside.
    pub fn vol_eff(&self, speed_rpm: f64) -> (f64, f64) {
        let p = &self.params;
        let s = &p.vol_eff_speeds_rpm;
        let (sl, of) = (&p.vol_eff_slope_kg_per_s_pa, &p.vol_eff_offset_kg_per_s);
        let last = s.len() - 1;
        if !(speed_rpm > s[0]) {
            return (sl[0], of[0]);
        }
        if speed_rpm >= s[last] {
            return (sl[last], of[last]);
        }
        let i = s.partition_point(|&v| v <= speed_rpm) - 1;
        let t = (speed_rpm - s[i]) / (s[i + 1] - s[i]);
        (
            sl[i] + t * (sl[i + 1] - sl[i]),
            of[i] + t * (of[i + 1] - of[i]),
        )
    }

    /// Intake-valve flow `eta_slope p_m - eta_ofs` (kg/s).
    pub fn intake_valve_flow(&self, p_m: f64, speed_rpm: f64) -> f64 {
        let (s, o) = self.vol_eff(speed_rpm);
        s * p_m - o
    }

    /// Continuous-time derivative of the state (the truth model). `x[2]` is algebraic in the
    /// continuous model, so its derivative is returned as 0; [`Self::integrate_rk4`] stores the
    /// current nozzle flow in it.
    pub fn continuous_derivative(&self, x: &IntakeState, u: &IntakeInput) -> IntakeState {
        let p = &self.params;
        let n = u[U_SPEED];
        let w_thr = self.throttle_flow(x[X_PM], u[U_THROTTLE]);
        let w_egr = self.egr_flow(x[X_PM], u[U_EGR]);
        let w_inv = self.intake_valve_flow(x[X_PM], n);
        let w = Self::pump_frequency(n);
        IntakeState::from([
            self.gain * (w_thr + w_egr - w_inv),
            (x[X_PM] + x[X_Q1] - x[X_PMES]) / p.map_time_constant_s,
            0.0,
            (w_thr - x[X_WMES]) / p.maf_time_constant_s,
            x[X_Q2],
            -w * w * x[X_Q1] - 2.0 * p.pump_damping * w * x[X_Q2],
        ])
    }

    /// Integrates the continuous model over `dt` with `substeps` classical RK4 steps at a
    /// constant input, and sets `x[2]` to the throttle flow at the end. Returns `x` unchanged
    /// for a non-finite input or `substeps == 0`.
    pub fn integrate_rk4(
        &self,
        x: &IntakeState,
        u: &IntakeInput,
        dt: f64,
        substeps: usize,
    ) -> IntakeState {
        if substeps == 0 || !dt.is_finite() || u.iter().any(|v| !v.is_finite()) {
            return *x;
        }
        let h = dt / substeps as f64;
        let mut z = *x;
        for _ in 0..substeps {
            let k1 = self.continuous_derivative(&z, u);
            let k2 = self.continuous_derivative(&(z + k1 * (h / 2.0)), u);
            let k3 = self.continuous_derivative(&(z + k2 * (h / 2.0)), u);
            let k4 = self.continuous_derivative(&(z + k3 * h), u);
            z += (k1 + 2.0 * k2 + 2.0 * k3 + k4) * (h / 6.0);
        }
        z[X_WTHR] = self.throttle_flow(z[X_PM], u[U_THROTTLE]);
        z
    }

    /// The steady state under a constant input: `p_m` where throttle plus EGR flow equals the
    /// intake-valve flow (bisection), sensors reading it, no pulsation. `None` for an input
    /// [`Self::check_input`] refuses.
    pub fn equilibrium(&self, u: &IntakeInput) -> Option<IntakeState> {
        self.check_input(u).ok()?;
        let a_thr = self.throttle_area(u[U_THROTTLE]);
        let a_egr = self.egr_area(u[U_EGR]);
        let f = |pm: f64| {
            self.throttle_flow_area(pm, a_thr).0 + self.egr_flow_area(pm, a_egr).0
                - self.intake_valve_flow(pm, u[U_SPEED])
        };
        let (mut lo, mut hi) = (
            0.0,
            self.params
                .ambient_pressure_pa
                .max(self.params.egr_upstream_pressure_pa),
        );
        if f(hi) > 0.0 {
            return None;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if f(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let pm = 0.5 * (lo + hi);
        let w = self.throttle_flow_area(pm, a_thr).0;
        Some(IntakeState::from([pm, pm, w, w, 0.0, 0.0]))
    }

    /// One segment of the discrete model (see the module docs), for a valid input.
    fn step(&self, x: &IntakeState, u: &IntakeInput) -> IntakeState {
        self.run_segment::<false>(x, u).0
    }

    /// One segment and its exact Jacobian `d x+ / d x` (the derivative of the discrete map, in
    /// closed form or propagated alongside the substeps), for a valid input.
    fn step_with_jacobian(&self, x: &IntakeState, u: &IntakeInput) -> (IntakeState, IntakeJac) {
        self.run_segment::<true>(x, u)
    }

    /// One segment: the closed form of [`Self::affine_segment`] where it applies (random-walk
    /// throttle with the EGR flow constant over the segment), the substeps otherwise.
    #[inline]
    fn run_segment<const JAC: bool>(
        &self,
        x: &IntakeState,
        u: &IntakeInput,
    ) -> (IntakeState, IntakeJac) {
        if self.flow == ThrottleFlow::RandomWalk {
            if let Some(out) = self.affine_segment::<JAC>(x, u) {
                return out;
            }
        }
        self.substep_segment::<JAC>(x, u)
    }

    /// The whole segment in closed form, or `None` where the pressure dynamics are not affine
    /// in `p_m` over it (then [`Self::substep_segment`] runs). Only in
    /// [`ThrottleFlow::RandomWalk`] mode: `W_thr` is the state's, held over the segment, so
    /// `dp_m/dt = gain (W_thr + W_egr - slope p_m + ofs)` is affine in `p_m` exactly when the
    /// EGR flow is constant: valve closed (area 0, known from the input alone) or nozzle choked
    /// (`p_m / p_egr < psi_crit`) over the whole segment. The affine trajectory is monotone
    /// between its start and its end, so checking both ends is exact. Then, with
    /// `j = -gain slope` (1/s), `f0` the start's `dp_m/dt` (Pa/s), `z = j dt`, `r = dt / tau_map`,
    /// `a = exp(-r)`:
    ///
    /// ```text
    /// p_m(dt)   = p0 + f0 dt phi1(z)                              (exact exponential)
    /// p_mes(dt) = a p_mes0 + (1 - a) p0 + f0 dt c(z, r) + g q0     (lag along that path, exact)
    /// W_mes(dt) = b W_mes0 + (1 - b) W_thr,  b = exp(-dt / tau_maf)
    /// q(dt)     = expm(A dt) q0
    /// ```
    ///
    /// with `c` from [`lag_ramp_weight`] and `g` the oscillator's exact contribution to the MAP
    /// lag ([`map_pulsation_gain`]) over the whole step. The map is affine in the state, so its
    /// Jacobian is exact and constant over the state. The substep path would give the same
    /// `p_m`, `W_mes` and `q` (its pressure step is exact for affine dynamics) and a MAP within
    /// the error of its linear-in-time lag input, `max_substep_s^2 / 8 max|p_m''|` (a fraction of
    /// a pascal); 1 to 2 exponentials replace up to 75 substeps.
    fn affine_segment<const JAC: bool>(
        &self,
        x: &IntakeState,
        u: &IntakeInput,
    ) -> Option<(IntakeState, IntakeJac)> {
        let p = &self.params;
        let n_rpm = u[U_SPEED];
        let a_egr = self.egr_area(u[U_EGR]);
        let p0 = x[X_PM];
        let pe = p.egr_upstream_pressure_pa;
        let crit = self.nozzle.crit;
        // A closed valve gives exactly zero flow; a choked one its constant choked flow.
        let w_egr = if a_egr == 0.0 {
            0.0
        } else if p0 / pe < crit {
            self.egr_flow_area(p0, a_egr).0
        } else {
            return None;
        };
        let dt = Self::segment_dt(n_rpm);
        let (slope, ofs) = self.vol_eff(n_rpm);
        let w_thr = x[X_WTHR];
        let j = -self.gain * slope;
        let f0 = self.gain * (w_thr + w_egr - (slope * p0 - ofs));
        let z = j * dt;
        let ph = phi1(z);
        let pm = p0 + f0 * dt * ph;
        if a_egr != 0.0 && !(pm / pe < crit) {
            return None;
        }

        let tau = p.map_time_constant_s;
        let r = dt / tau;
        let one_minus_a = -(-r).exp_m1();
        let a = 1.0 - one_minus_a;
        let c = lag_ramp_weight(z, r);
        let w = Self::pump_frequency(n_rpm);
        let e = oscillator_transition(w, p.pump_damping, dt);
        let g = map_pulsation_gain(w, p.pump_damping, tau, dt, &e, a);
        let q0 = Vector2::new(x[X_Q1], x[X_Q2]);
        let pmes = a * x[X_PMES] + one_minus_a * p0 + f0 * dt * c + (g * q0)[0];
        let maf_one_minus_b = -(-dt / p.maf_time_constant_s).exp_m1();
        let b = 1.0 - maf_one_minus_b;
        let wmes = b * x[X_WMES] + maf_one_minus_b * w_thr;
        let q = e * q0;
        let next = IntakeState::from([pm, pmes, w_thr, wmes, q[0], q[1]]);

        let mut jac = IntakeJac::zeros();
        if JAC {
            // d f0 / d p0 = j, d f0 / d W_thr = gain.
            jac[(X_PM, X_PM)] = 1.0 + z * ph;
            jac[(X_PM, X_WTHR)] = self.gain * dt * ph;
            jac[(X_PMES, X_PM)] = one_minus_a + z * c;
            jac[(X_PMES, X_PMES)] = a;
            jac[(X_PMES, X_WTHR)] = self.gain * dt * c;
            jac[(X_PMES, X_Q1)] = g[0];
            jac[(X_PMES, X_Q2)] = g[1];
            jac[(X_WTHR, X_WTHR)] = 1.0;
            jac[(X_WMES, X_WMES)] = b;
            jac[(X_WMES, X_WTHR)] = maf_one_minus_b;
            jac.fixed_view_mut::<2, 2>(X_Q1, X_Q1).copy_from(&e);
        }
        Some((next, jac))
    }

    /// The substep loop of [`Self::step`]; with `JAC` it also propagates the sensitivities of
    /// `p_m`, `p_mes`, `W_mes` (and the oscillator) to the initial state. The state is computed
    /// by the same operations either way, so both paths give bit-identical states.
    fn substep_segment<const JAC: bool>(
        &self,
        x: &IntakeState,
        u: &IntakeInput,
    ) -> (IntakeState, IntakeJac) {
        let p = &self.params;
        let n_rpm = u[U_SPEED];
        let dt = Self::segment_dt(n_rpm);
        let substeps = (dt / p.max_substep_s).ceil().max(1.0);
        let h = dt / substeps;
        let substeps = substeps as usize;
        let w = Self::pump_frequency(n_rpm);
        let xi = p.pump_damping;
        let e = oscillator_transition(w, xi, h);
        let tau = p.map_time_constant_s;
        let g = map_pulsation_gain(w, xi, tau, h, &e, (-h / tau).exp());
        let map_lag = LagCoeffs::new(h, tau);
        let maf_lag = LagCoeffs::new(h, p.maf_time_constant_s);

        let (slope, ofs) = self.vol_eff(n_rpm);
        let a_thr = self.throttle_area(u[U_THROTTLE]);
        let a_egr = self.egr_area(u[U_EGR]);
        let nozzle = self.flow == ThrottleFlow::Nozzle;
        // Returns f = dp_m/dt, j = df/dp_m, the throttle flow and its derivative, and (only
        // with JAC) dj/dp_m.
        let flows = |pm: f64| -> (f64, f64, f64, f64, f64) {
            let (wt, dwt) = if nozzle {
                self.throttle_flow_area(pm, a_thr)
            } else {
                (x[X_WTHR], 0.0)
            };
            // A closed EGR valve (area 0) gives exactly zero flow and slope.
            let (we, dwe) = if a_egr == 0.0 {
                (0.0, 0.0)
            } else {
                self.egr_flow_area(pm, a_egr)
            };
            let f = self.gain * (wt + we - (slope * pm - ofs));
            let j = self.gain * (dwt + dwe - slope);
            let dj = if JAC {
                let pa = p.ambient_pressure_pa;
                let pe = p.egr_upstream_pressure_pa;
                let d2t = if nozzle {
                    self.thr_scale * a_thr * self.nozzle.curvature(pm / pa) / (pa * pa)
                } else {
                    0.0
                };
                let d2e = if a_egr == 0.0 {
                    0.0
                } else {
                    self.egr_scale * a_egr * self.nozzle.curvature(pm / pe) / (pe * pe)
                };
                self.gain * (d2t + d2e)
            } else {
                0.0
            };
            (f, j, wt, dwt, dj)
        };

        let mut pm = x[X_PM];
        let mut pmes = x[X_PMES];
        let mut wmes = x[X_WMES];
        let mut q = Vector2::new(x[X_Q1], x[X_Q2]);
        let (mut f, mut j, mut wt, dwt0, mut dj) = flows(pm);
        // Sensitivities (JAC only). `s_*` are d(.)/d[p_m0, W_thr0]; `pmes_*`, `wmes_*` the
        // sensor outputs' derivatives; `qk` = e^k, the oscillator's transition so far.
        let mut s_pm = [1.0, 0.0];
        let mut s_wt = if nozzle { [dwt0, 0.0] } else { [0.0, 1.0] };
        let (mut pmes_x, mut pmes_pmes) = ([0.0, 0.0], 1.0);
        let mut pmes_q = nalgebra::RowVector2::new(0.0, 0.0);
        let (mut wmes_x, mut wmes_wmes) = ([0.0, 0.0], 1.0);
        let mut qk = Matrix2::identity();
        // phi1 and phi1' of the last z: z = h j is the same in every substep wherever the flows
        // are affine in p_m (choked or linear region, closed EGR, random-walk throttle).
        let (mut z_last, mut ph, mut dph) = (f64::NAN, 0.0, 0.0);
        for _ in 0..substeps {
            let z = h * j;
            if z != z_last {
                z_last = z;
                ph = phi1(z);
                if JAC {
                    dph = dphi1(z);
                }
            }
            let pm1 = pm + h * f * ph;
            let (f1, j1, wt1, dwt1, dj1) = flows(pm1);
            if JAC {
                // d pm1 = (1 + h j phi1 + h f phi1'(z) h dj) d pm + h phi1 df/dW dW.
                let a = 1.0 + h * j * ph + h * f * dph * h * dj;
                let b = if nozzle { 0.0 } else { h * ph * self.gain };
                let s_pm1 = [a * s_pm[0], a * s_pm[1] + b];
                let s_wt1 = if nozzle {
                    [dwt1 * s_pm1[0], 0.0]
                } else {
                    [0.0, 1.0]
                };
                for c in 0..2 {
                    pmes_x[c] =
                        map_lag.a * pmes_x[c] + map_lag.b0 * s_pm[c] + map_lag.b1 * s_pm1[c];
                    wmes_x[c] =
                        maf_lag.a * wmes_x[c] + maf_lag.b0 * s_wt[c] + maf_lag.b1 * s_wt1[c];
                }
                pmes_pmes *= map_lag.a;
                wmes_wmes *= maf_lag.a;
                pmes_q = map_lag.a * pmes_q + g * qk;
                qk = e * qk;
                (s_pm, s_wt) = (s_pm1, s_wt1);
            }
            pmes = map_lag.apply(pmes, pm, pm1) + (g * q)[0];
            wmes = maf_lag.apply(wmes, wt, wt1);
            q = e * q;
            (pm, f, j, wt, dj) = (pm1, f1, j1, wt1, dj1);
        }
        let next = IntakeState::from([pm, pmes, wt, wmes, q[0], q[1]]);
        let mut jac = IntakeJac::zeros();
        if JAC {
            let cols = [X_PM, X_WTHR];
            for c in 0..2 {
                jac[(X_PM, cols[c])] = s_pm[c];
                jac[(X_PMES, cols[c])] = pmes_x[c];
                jac[(X_WTHR, cols[c])] = s_wt[c];
                jac[(X_WMES, cols[c])] = wmes_x[c];
            }
            jac[(X_PMES, X_PMES)] = pmes_pmes;
            jac[(X_PMES, X_Q1)] = pmes_q[0];
            jac[(X_PMES, X_Q2)] = pmes_q[1];
            jac[(X_WMES, X_WMES)] = wmes_wmes;
            jac.fixed_view_mut::<2, 2>(X_Q1, X_Q1).copy_from(&qk);
        }
        (next, jac)
    }
}

/// The 6 x 6 transition Jacobian.
type IntakeJac = SMatrix<f64, 6, 6>;

/// Output after a substep `h` of a first-order lag with time constant `tau`, for an input
/// linear from `u0` to `u1` over the substep (exact), with the exponentials computed once per
/// segment: `a y + (1 - a) u0 + ramp (u1 - u0)`, i.e. `a y + b0 u0 + b1 u1` with
/// `b0 = 1 - a - ramp`, `b1 = ramp` (the derivative's weights).
struct LagCoeffs {
    a: f64,
    one_minus_a: f64,
    ramp: f64,
    b0: f64,
    b1: f64,
}

impl LagCoeffs {
    fn new(h: f64, tau: f64) -> Self {
        let r = h / tau;
        let one_minus_a = -(-r).exp_m1();
        let a = 1.0 - one_minus_a;
        let ramp = if r < 1e-4 {
            // 1 - (1 - e^-r)/r = r/2 - r^2/6 + ...
            r / 2.0 - r * r / 6.0
        } else {
            1.0 - one_minus_a / r
        };
        Self {
            a,
            one_minus_a,
            ramp,
            b0: one_minus_a - ramp,
            b1: ramp,
        }
    }

    /// The lag's output after the substep.
    #[inline]
    fn apply(&self, y: f64, u0: f64, u1: f64) -> f64 {
        self.a * y + self.one_minus_a * u0 + (u1 - u0) * self.ramp
    }
}

impl TransitionModel<6, 3> for IntakeModel {
    /// One crank segment, `dt = 30 / u[0]`. Returns `x` unchanged for an input
    /// [`IntakeModel::check_input`] refuses on speed or finiteness (never NaN).
    fn transition(&self, x: &IntakeState, u: &IntakeInput) -> IntakeState {
        if !self.input_ok(u) || x.iter().any(|v| !v.is_finite()) {
            return *x;
        }
        self.step(x, u)
    }

    /// The exact derivative of [`Self::transition`] (in closed form for the closed-form segment;
    /// otherwise propagated through the substeps alongside the state, with the flow function's
    /// second derivative for the exponential-Euler factor).
    /// Not defined on the flow function's kinks (`psi_crit`, `steep_ratio`, 1), where the
    /// one-sided value is returned. The identity where `transition` returns `x` unchanged.
    fn transition_jacobian(&self, x: &IntakeState, u: &IntakeInput) -> IntakeJac {
        if !self.input_ok(u) || x.iter().any(|v| !v.is_finite()) {
            return IntakeJac::identity();
        }
        self.step_with_jacobian(x, u).1
    }

    /// One pass (closed form or substeps) for both (the EKF's predict).
    fn transition_with_jacobian(
        &self,
        x: &IntakeState,
        u: &IntakeInput,
    ) -> (IntakeState, IntakeJac) {
        if !self.input_ok(u) || x.iter().any(|v| !v.is_finite()) {
            return (*x, IntakeJac::identity());
        }
        self.step_with_jacobian(x, u)
    }
}

/// MAP and MAF together: `y = [p_mes, W_mes]` (the centralized filter's `H`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MapMafSensors;

/// MAP only: `y = p_mes` (a decentralized local filter).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MapSensor;

/// MAF only: `y = W_mes` (a decentralized local filter).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MafSensor;

impl ObservationModel<6, 2, 3> for MapMafSensors {
    #[inline]
    fn observe(&self, x: &IntakeState, _u: &IntakeInput) -> Vector2<f64> {
        Vector2::new(x[X_PMES], x[X_WMES])
    }

    fn observation_jacobian(&self, _x: &IntakeState, _u: &IntakeInput) -> SMatrix<f64, 2, 6> {
        let mut h = SMatrix::<f64, 2, 6>::zeros();
        h[(0, X_PMES)] = 1.0;
        h[(1, X_WMES)] = 1.0;
        h
    }
}

impl ObservationModel<6, 1, 3> for MapSensor {
    #[inline]
    fn observe(&self, x: &IntakeState, _u: &IntakeInput) -> Vector1<f64> {
        Vector1::new(x[X_PMES])
    }

    fn observation_jacobian(&self, _x: &IntakeState, _u: &IntakeInput) -> SMatrix<f64, 1, 6> {
        let mut h = SMatrix::<f64, 1, 6>::zeros();
        h[(0, X_PMES)] = 1.0;
        h
    }
}

impl ObservationModel<6, 1, 3> for MafSensor {
    #[inline]
    fn observe(&self, x: &IntakeState, _u: &IntakeInput) -> Vector1<f64> {
        Vector1::new(x[X_WMES])
    }

    fn observation_jacobian(&self, _x: &IntakeState, _u: &IntakeInput) -> SMatrix<f64, 1, 6> {
        let mut h = SMatrix::<f64, 1, 6>::zeros();
        h[(0, X_WMES)] = 1.0;
        h
    }
}

#[cfg(test)]
mod tests {
    //! The closed-form segment of the random-walk model against fine integration, the substep
    //! path and finite differences (private functions, hence here rather than in `tests/`).

    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn model(flow: ThrottleFlow) -> IntakeModel {
        #[derive(Deserialize)]
        struct File {
            model: IntakeParams,
        }
        let text = include_str!("../../../config/intake.toml");
        let params = toml::from_str::<File>(text)
            .expect("config/intake.toml parses")
            .model;
        IntakeModel::new(params, flow).expect("valid parameters")
    }

    /// `y(h) / h` for `p' = 1 + j p`, `y' = p - y` from `p = y = 0` (tau = 1, so `r = h`,
    /// `z = j h`, `f0 = 1`) by classical RK4 with `n` steps: `c(z, r)` by its definition.
    fn rk4_weight(z: f64, r: f64, n: usize) -> f64 {
        let (h, j) = (r, z / r);
        let d = |p: f64, y: f64| (1.0 + j * p, p - y);
        let dt = h / n as f64;
        let (mut p, mut y) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let k1 = d(p, y);
            let k2 = d(p + 0.5 * dt * k1.0, y + 0.5 * dt * k1.1);
            let k3 = d(p + 0.5 * dt * k2.0, y + 0.5 * dt * k2.1);
            let k4 = d(p + dt * k3.0, y + dt * k3.1);
            p += dt / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
            y += dt / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
        }
        y / h
    }

    #[test]
    fn lag_ramp_weight_matches_fine_rk4() {
        let mut worst = 0.0f64;
        for r in [1e-3, 0.05, 0.3, 0.71, 2.0, 5.36, 14.3, 25.0, 60.0] {
            for z in [
                -8.0f64, -1.2, -0.16, -0.0105, -1.001e-3, -0.999e-3, -1e-5, 0.0, 1e-4, 2e-3, 0.5,
            ] {
                // Steps small against both time scales.
                let n = (2000.0 * (1.0 + r + z.abs())) as usize;
                let reference = rk4_weight(z, r, n);
                let c = lag_ramp_weight(z, r);
                let rel = (c - reference).abs() / reference.abs();
                worst = worst.max(rel);
                assert!(rel < 1e-11, "c({z}, {r}) = {c:e}, RK4 {reference:e}");
            }
        }
        // The series and the direct formula meet at the switch |z| = 1e-3.
        for r in [1e-3, 0.05, 0.71, 5.36, 30.0] {
            let z = -1e-3;
            let m = lag_moments(r);
            let series = m[0] + z * (m[1] / 2.0 + z * (m[2] / 6.0 + z * m[3] / 24.0));
            let direct = lag_ramp_weight(z, r);
            // The direct formula's cancellation costs about 4 eps / |z| = 9e-13 here.
            assert!(
                (series - direct).abs() < 3e-12 * direct,
                "{series} vs {direct}"
            );
        }
        println!("c(z, r): worst relative deviation from RK4 {worst:.2e}");
    }

    /// States in the affine case (random-walk throttle, EGR closed or choked) at speeds over the
    /// accepted range: `(x, u)` pairs where `affine_segment` applies.
    fn affine_cases(m: &IntakeModel) -> Vec<(IntakeState, IntakeInput)> {
        let mut rng = Pcg64::seed_from_u64(0x00af_f10e);
        let pa = m.params().ambient_pressure_pa;
        let mut out = Vec::new();
        for speed in [300.0, 800.0, 1250.0, 3000.0, 6000.0, 8000.0] {
            for throttle in [2.0, 10.0, 40.0, 80.0] {
                for egr in [0.0, 0.3, 1.0] {
                    let u = IntakeInput::new(speed, throttle, egr);
                    for ratio in [0.2, 0.3, 0.45, 0.6, 0.9] {
                        let Some(mut x) = m.equilibrium(&u) else {
                            continue;
                        };
                        x[X_PM] = ratio * pa;
                        x[X_PMES] = x[X_PM] + rng.random_range(-3e3..3e3);
                        x[X_WTHR] *= rng.random_range(0.5..1.5);
                        x[X_WMES] = x[X_WTHR] * rng.random_range(0.8..1.2);
                        x[X_Q1] = rng.random_range(-1500.0..1500.0);
                        x[X_Q2] = rng.random_range(-1.0..1.0)
                            * 1500.0
                            * IntakeModel::pump_frequency(speed);
                        if m.affine_segment::<false>(&x, &u).is_some() {
                            out.push((x, u));
                        }
                    }
                }
            }
        }
        out
    }

    #[test]
    fn closed_form_agrees_with_substeps_in_the_affine_case() {
        let m = model(ThrottleFlow::RandomWalk);
        let p = m.params().clone();
        let cases = affine_cases(&m);
        assert!(cases.len() > 200, "only {} affine cases", cases.len());
        let (mut worst_map_rel, mut worst_ratio, mut worst_other) = (0.0f64, 0.0f64, 0.0f64);
        let mut worst_map_pa = 0.0f64;
        for (x, u) in &cases {
            let closed = m.affine_segment::<false>(x, u).expect("affine").0;
            // The public transition takes the closed form here.
            assert_eq!(m.transition(x, u), closed);
            let sub = m.substep_segment::<false>(x, u).0;
            // p_m (exact exponential in both), W_thr, W_mes (constant lag input) and q agree to
            // round-off; compare in scaled units.
            let w = IntakeModel::pump_frequency(u[U_SPEED]);
            let scale = [1e5, 1e5, 0.05, 0.05, 1e3, 1e3 * w];
            for i in [X_PM, X_WTHR, X_WMES, X_Q1, X_Q2] {
                let d = (closed[i] - sub[i]).abs() / scale[i];
                worst_other = worst_other.max(d);
                assert!(
                    d < 1e-11,
                    "state {i}: {} vs {} at {x:?}, {u:?}",
                    closed[i],
                    sub[i]
                );
            }
            // The MAP differs by the substeps' linear-in-time lag input: at most h^2 / 8 times
            // the largest |p_m''| = |j f0| (j < 0, so the start's) over the segment.
            let dt = IntakeModel::segment_dt(u[U_SPEED]);
            let h = dt / (dt / p.max_substep_s).ceil();
            let (slope, _) = m.vol_eff(u[U_SPEED]);
            let j = -m.gain * slope;
            let f0 = (closed[X_PM] - x[X_PM]) / (dt * phi1(j * dt));
            let bound = h * h / 8.0 * (j * f0).abs() + 1e-8;
            let dmap = (closed[X_PMES] - sub[X_PMES]).abs();
            assert!(
                dmap <= bound,
                "MAP {dmap} Pa > bound {bound} Pa at {x:?}, {u:?}"
            );
            worst_ratio = worst_ratio.max(dmap / bound);
            worst_map_rel = worst_map_rel.max(dmap / closed[X_PMES].abs());
            worst_map_pa = worst_map_pa.max(dmap);
        }
        println!(
            "{} affine segments: MAP closed vs substeps worst {worst_map_pa:.3} Pa, \
             {worst_map_rel:.2e} relative ({:.0} % of the interpolation bound); other states \
             {worst_other:.1e} scaled",
            cases.len(),
            worst_ratio * 100.0
        );
        // Far inside the 700 Pa MAP noise: the two discretizations are interchangeable.
        assert!(worst_map_pa < 5.0, "{worst_map_pa}");
        assert!(worst_map_rel < 1e-4, "{worst_map_rel}");
    }

    #[test]
    fn closed_form_jacobian_matches_five_point_differences() {
        let m = model(ThrottleFlow::RandomWalk);
        let cases = affine_cases(&m);
        let mut worst = 0.0f64;
        for (x, u) in &cases {
            let (state, jac) = m.affine_segment::<true>(x, u).expect("affine");
            assert_eq!(state, m.affine_segment::<false>(x, u).expect("affine").0);
            let w = IntakeModel::pump_frequency(u[U_SPEED]);
            let d = [1e5, 1e5, 0.05, 0.05, 1e3, 1e3 * w];
            for c in 0..6 {
                let step = 1e-4 * d[c];
                let at = |k: f64| {
                    let mut z = *x;
                    z[c] += k * step;
                    // Stay on the closed form (a perturbation may not leave the choked region
                    // in these cases, checked here).
                    m.affine_segment::<false>(&z, u).expect("still affine").0
                };
                let col = (at(-2.0) - at(2.0) + (at(1.0) - at(-1.0)) * 8.0) / (12.0 * step);
                for i in 0..6 {
                    let s = d[c] / d[i];
                    let (a, n) = (jac[(i, c)] * s, col[i] * s);
                    let dev = (a - n).abs() / n.abs().max(1e-3);
                    worst = worst.max(dev);
                    assert!(
                        dev < 1e-7,
                        "J[{i},{c}] = {a:e} vs {n:e} (scaled) at {x:?}, {u:?}"
                    );
                }
            }
        }
        println!(
            "closed-form Jacobian: worst scaled deviation {worst:.2e} over {} segments",
            cases.len()
        );
    }
}
