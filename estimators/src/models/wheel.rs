//! The quarter car of the slip-control tutorial (seeds/002, REFERENCE §3): one wheel carrying a
//! quarter of the vehicle, braked (or driven) through the tyre's friction with the road, and the
//! 5-state EKF that estimates the wheel's angular speed, the vehicle speed, the slip, the road
//! friction coefficient and the quarter mass from a wheel-speed measurement alone, every 5 ms.
//!
//! # Model
//!
//! Continuous (forward motion only: `omega, v >= 0`):
//!
//! ```text
//! J domega/dt = r N mu(lambda) - T_b + T_d,     N = m g   (the tyre's force turns the wheel)
//!   dv/dt     = -g mu(lambda)                   (and decelerates the quarter car)
//!   lambda    = (v - r omega) / max(v, r omega, v_min)
//! ```
//!
//! with the Burckhardt tyre-road law `mu(lambda) = c1 (1 - exp(-c2 lambda)) - c3 lambda` for the
//! surface's coefficients ([`Burckhardt`]). The tutorial's discrete model is its forward-Euler
//! step at `Ts` with the slip and the friction carried as states that are recomputed from the
//! previous step's (a one-step delay the tutorial's EKF has too):
//!
//! ```text
//! omega+  = omega + Ts / J (r g mu m - T_b + T_d)
//! v+      = v - Ts g mu
//! lambda+ = slip(v, omega)
//! mu+     = mu(lambda)            (a known surface; or mu+ = mu, a random walk: unknown surface)
//! m+      = m
//! ```
//!
//! # What the tutorial leaves open, and what this module does
//!
//! - **Signs.** The text lost its minus signs; they are restored from the physics: a braking
//!   wheel turns slower than it rolls (`lambda > 0`), the road's force on the tyre then turns the
//!   wheel forward (`+ r g mu m`) and decelerates the car (`-g mu`). The brake torque `T_b >= 0`
//!   opposes the (forward) rotation; a drive torque `T_d` adds to it. Under traction the wheel
//!   turns faster than it rolls, `lambda < 0`, and the friction law is odd:
//!   `mu(-lambda) = -mu(lambda)` (the force then pushes the car forward).
//! - **Slip at standstill.** `(v - r omega) / v` is unbounded as `v -> 0` and wrong in traction
//!   (it runs to minus infinity at a spinning start). The denominator here is
//!   `max(v, r omega, v_min)`: the usual braking slip while braking, the traction slip
//!   `(v - r omega) / (r omega)` while driving, both in `[-1, 1]`, and below `v_min`
//!   ([`WheelParams::min_speed_m_s`], the tutorial's 0.5 m/s stop) a slip that goes to 0 with
//!   the speed difference instead of dividing by a vanishing speed. The Jacobian follows the
//!   branch in use.
//! - **Standstill.** `omega` and `v` are clamped at 0 ([`QuarterCar::constrain`]): a brake holds
//!   a stopped wheel instead of turning it backward (the tutorial's `sgn(omega) T_b` for a wheel
//!   that only turns forward).
//! - **Observability of `mu` and `m`.** The wheel speed alone gives, through the wheel's
//!   equation, the product `mu m` (the tyre force) once the torques are known. The vehicle
//!   equation ties `mu` alone to `v`, and `v` reaches the measurement only through the slip. With
//!   a known surface the curve `mu(lambda)` closes the loop (where its slope is not zero: not at
//!   the peak and not on the flat part of ice), so `v`, then `mu`, then `m` follow. With an
//!   unknown surface `m` is observable only while a torque decelerates (or accelerates) the car:
//!   at a steady slip the wheel decelerates with the car, so the wheel speed measures the
//!   deceleration the known torque gives the mass (`m = T / (g r mu)`-type balance, the car's
//!   momentum change against the tyre force's impulse); [`Friction::TorqueBalance`] puts that
//!   into the prediction, and the rolling wheel's zero slip ([`WheelSensors`]) anchors the speed
//!   between events, without which a speed error is taken for a mass error. While the car
//!   cruises (`mu ~ 0`) `m` is not observable at all; the filter then keeps it (its `Q` entry is
//!   tiny) instead of wandering. The tutorial's own chain (slip from the last step's speeds,
//!   friction from the last step's slip, wheel speed from the last step's friction) has a loop
//!   gain of about 3 per three steps at 20 m/s on dry asphalt: unstable as a predictor at 5 ms,
//!   which its large `Q` on slip and friction (1 each) hides by making the prediction count
//!   for little (`tests/wheel_model.rs`).
//! - **`P0 = 0`.** The tutorial starts with a zero covariance and predicts before it updates, so
//!   the first covariance it uses is `F 0 F' + Q = Q`, positive definite because every entry of
//!   `Q` is. [`WheelEkf`] does exactly that: its first step moves the initial state through the
//!   model and takes `Q` as the prior. Afterwards the covariance stays symmetric (the EKF
//!   symmetrizes every step) and positive definite (the update's posterior is checked by
//!   Cholesky; a step that would break it is refused and the estimate kept).

use nalgebra::{SMatrix, SVector};
use serde::Deserialize;

use crate::ekf::Ekf;
use crate::error::{ConfigError, FilterError};
use crate::innovation::Innovation;
use crate::model::{ObservationModel, TransitionModel};
use crate::param::{exact_array, ParamError};

/// State index of the wheel's angular speed `omega` (rad/s).
pub const X_OMEGA: usize = 0;
/// State index of the vehicle (quarter car) speed `v` (m/s).
pub const X_V: usize = 1;
/// State index of the slip `lambda` (-; positive braking).
pub const X_SLIP: usize = 2;
/// State index of the road friction coefficient in use `mu` (-; signed with the slip).
pub const X_MU: usize = 3;
/// State index of the quarter mass `m` (kg).
pub const X_MASS: usize = 4;
/// Input index of the brake torque `T_b` (N m, >= 0).
pub const U_BRAKE: usize = 0;
/// Input index of the drive torque `T_d` (N m).
pub const U_DRIVE: usize = 1;

/// The largest friction coefficient the state may hold (-): above every tyre-road pair
/// (racing tyres on dry asphalt reach about 1.7).
pub const MU_MAX: f64 = 2.0;
/// The quarter mass the state is kept within (kg): an empty small car's lightest corner to a
/// loaded van's heaviest. Only guards the estimate against nonsense while `m` is unobservable.
pub const MASS_BOUNDS_KG: (f64, f64) = (100.0, 1500.0);

/// The Burckhardt tyre-road friction law `mu(lambda) = c1 (1 - exp(-c2 lambda)) - c3 lambda`
/// for `lambda >= 0`, continued as an odd function (traction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Burckhardt {
    /// Maximum of the exponential part (-).
    pub c1: f64,
    /// Steepness at small slip (-).
    pub c2: f64,
    /// Linear fall beyond the peak (-).
    pub c3: f64,
}

impl Burckhardt {
    /// From `[c1, c2, c3]`.
    pub const fn new(c: [f64; 3]) -> Self {
        Self {
            c1: c[0],
            c2: c[1],
            c3: c[2],
        }
    }

    /// The friction coefficient at slip `lambda` (-), odd in `lambda`.
    pub fn mu(&self, lambda: f64) -> f64 {
        let a = lambda.abs();
        let m = self.c1 * (1.0 - (-self.c2 * a).exp()) - self.c3 * a;
        m.copysign(lambda)
    }

    /// `dmu/dlambda` at `lambda` (even in `lambda`).
    pub fn slope(&self, lambda: f64) -> f64 {
        self.c1 * self.c2 * (-self.c2 * lambda.abs()).exp() - self.c3
    }

    /// The slip of the largest friction in `[0, 1]` and that friction: where the slope is zero,
    /// `ln(c1 c2 / c3) / c2`, or slip 1 when the curve rises all the way (ice: `c3 = 0`).
    pub fn peak(&self) -> (f64, f64) {
        let lambda = if self.c3 > 0.0 && self.c1 * self.c2 > self.c3 {
            ((self.c1 * self.c2 / self.c3).ln() / self.c2).min(1.0)
        } else if self.c3 > 0.0 {
            0.0
        } else {
            1.0
        };
        (lambda, self.mu(lambda))
    }
}

/// The four road surfaces of the tutorial's coefficient table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Surface {
    Dry,
    Wet,
    Snow,
    Ice,
}

impl Surface {
    /// Every surface, from the highest friction to the lowest.
    pub const ALL: [Surface; 4] = [Surface::Dry, Surface::Wet, Surface::Snow, Surface::Ice];

    /// The name used in configuration, logs and events (`dry`, `wet`, `snow`, `ice`).
    pub fn name(self) -> &'static str {
        match self {
            Surface::Dry => "dry",
            Surface::Wet => "wet",
            Surface::Snow => "snow",
            Surface::Ice => "ice",
        }
    }

    /// The surface of a name ([`Surface::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Index in [`Surface::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// The Burckhardt coefficients `[c1, c2, c3]` of each surface (the `[model.surfaces]` table).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceTable {
    #[serde(deserialize_with = "exact_array")]
    pub dry: [f64; 3],
    #[serde(deserialize_with = "exact_array")]
    pub wet: [f64; 3],
    #[serde(deserialize_with = "exact_array")]
    pub snow: [f64; 3],
    #[serde(deserialize_with = "exact_array")]
    pub ice: [f64; 3],
}

impl SurfaceTable {
    /// The friction law of a surface.
    pub fn curve(&self, s: Surface) -> Burckhardt {
        Burckhardt::new(match s {
            Surface::Dry => self.dry,
            Surface::Wet => self.wet,
            Surface::Snow => self.snow,
            Surface::Ice => self.ice,
        })
    }
}

/// Quarter-car parameters (the `[model]` table of `config/wheel.toml`). Units are in the names.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelParams {
    /// The filter's step `Ts` (s): the tutorial's 5 ms.
    pub dt_s: f64,
    /// Rolling radius of the wheel `r` (m).
    pub radius_m: f64,
    /// Moment of inertia of the wheel with tyre, brake disc and half shaft `J` (kg m^2).
    pub inertia_kg_m2: f64,
    /// Gravitational acceleration `g` (m/s^2).
    pub gravity_m_s2: f64,
    /// Quarter mass the filter starts from `m0` (kg): the tutorial's 450 kg.
    pub quarter_mass_kg: f64,
    /// Speed below which the slip's denominator stops shrinking (m/s).
    pub min_speed_m_s: f64,
    /// Burckhardt coefficients per surface.
    pub surfaces: SurfaceTable,
}

/// Admissible ranges of [`WheelParams`] and [`WheelFilterParams`].
pub mod ranges {
    use crate::param::Range;

    pub const DT_S: Range = Range::closed(1e-4, 0.1, "s");
    pub const RADIUS_M: Range = Range::closed(0.1, 1.0, "m");
    pub const INERTIA: Range = Range::closed(0.05, 50.0, "kg m^2");
    pub const GRAVITY: Range = Range::closed(9.7, 9.9, "m/s^2");
    pub const QUARTER_MASS_KG: Range = Range::closed(100.0, 1500.0, "kg");
    pub const MIN_SPEED_M_S: Range = Range::closed(0.01, 5.0, "m/s");
    pub const C1: Range = Range::above(0.0, 2.0, "");
    pub const C2: Range = Range::above(0.0, 1000.0, "");
    pub const C3: Range = Range::closed(0.0, 2.0, "");
    pub const PROCESS_NOISE: Range = Range::above(0.0, 1e6, "");
    pub const MEASUREMENT_VARIANCE: Range = Range::above(0.0, 1e6, "rad^2/s^2");
    pub const INITIAL_VARIANCE: Range = Range::closed(0.0, 1e6, "");
    pub const ROLLING_SLIP_STD: Range = Range::closed(0.0, 0.5, "");
    pub const PULL: Range = Range::closed(0.0, 1.0, "");
    pub const ROLLING_TORQUE_NM: Range = Range::closed(0.0, 1e4, "N m");
}

impl WheelParams {
    /// Checks every key against its range ([`ranges`]), naming it relative to the `[model]`
    /// table (`surfaces.ice[1]`).
    pub fn validate(&self) -> Result<(), ParamError> {
        use ranges as r;
        r::DT_S.check("dt_s", self.dt_s)?;
        r::RADIUS_M.check("radius_m", self.radius_m)?;
        r::INERTIA.check("inertia_kg_m2", self.inertia_kg_m2)?;
        r::GRAVITY.check("gravity_m_s2", self.gravity_m_s2)?;
        r::QUARTER_MASS_KG.check("quarter_mass_kg", self.quarter_mass_kg)?;
        r::MIN_SPEED_M_S.check("min_speed_m_s", self.min_speed_m_s)?;
        for s in Surface::ALL {
            let c = self.surfaces.curve(s);
            let key = |i: usize| format!("surfaces.{}[{i}]", s.name());
            r::C1.check(&key(0), c.c1)?;
            r::C2.check(&key(1), c.c2)?;
            r::C3.check(&key(2), c.c3)?;
            if c.c1 * c.c2 <= c.c3 {
                return Err(ParamError::new(
                    key(2),
                    format!("{}", c.c3),
                    format!(
                        "must be below c1 c2 = {}: the friction would fall from zero slip on",
                        c.c1 * c.c2
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The EKF's noise (the `[filter]` table of `config/wheel.toml`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelFilterParams {
    /// Diagonal of the process noise covariance `Q` in state order `[omega, v, lambda, mu, m]`
    /// ((rad/s)^2, (m/s)^2, -, -, kg^2).
    #[serde(deserialize_with = "exact_array")]
    pub process_noise: [f64; 5],
    /// Variance of the wheel-speed measurement `R` ((rad/s)^2).
    pub measurement_variance_rad2_s2: f64,
    /// Diagonal of the initial covariance `P0`, same units as `process_noise`. The tutorial's
    /// is zero (it trusts its initial mass completely); a filter that must learn a mass it
    /// does not know starts with that mass's variance here.
    #[serde(deserialize_with = "exact_array")]
    pub initial_variance: [f64; 5],
    /// Standard deviation of the rolling wheel's slip about 0 (-), the pseudo-measurement of
    /// [`WheelSensors`]; 0 turns it off (the tutorial has none).
    pub rolling_slip_std: f64,
}

impl WheelFilterParams {
    /// Checks every key ([`ranges`]), relative to the `[filter]` table.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (i, &q) in self.process_noise.iter().enumerate() {
            ranges::PROCESS_NOISE.check(&format!("process_noise[{i}]"), q)?;
        }
        ranges::ROLLING_SLIP_STD.check("rolling_slip_std", self.rolling_slip_std)?;
        for (i, &v) in self.initial_variance.iter().enumerate() {
            ranges::INITIAL_VARIANCE.check(&format!("initial_variance[{i}]"), v)?;
        }
        ranges::MEASUREMENT_VARIANCE.check(
            "measurement_variance_rad2_s2",
            self.measurement_variance_rad2_s2,
        )
    }

    /// `Q` as a matrix.
    pub fn q(&self) -> SMatrix<f64, 5, 5> {
        SMatrix::from_diagonal(&SVector::from(self.process_noise))
    }
}

/// fdd's wheel estimator (the `[estimator]` table of `config/wheel.toml`): the tutorial's
/// filter with the surface unknown, its friction pulled toward the torque balance
/// ([`Friction::TorqueBalance`]) and the rolling wheel's zero slip as a pseudo-measurement
/// while less than `rolling_torque_nm` acts on the wheel.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelEstimatorParams {
    /// Share of the way to the torque balance the friction moves per step (-, 0..1; 0 makes
    /// it a random walk).
    pub friction_pull: f64,
    /// Brake plus drive torque magnitude below which the wheel counts as rolling (N m).
    pub rolling_torque_nm: f64,
    /// As [`WheelFilterParams::process_noise`].
    #[serde(deserialize_with = "exact_array")]
    pub process_noise: [f64; 5],
    /// As [`WheelFilterParams::measurement_variance_rad2_s2`].
    pub measurement_variance_rad2_s2: f64,
    /// As [`WheelFilterParams::initial_variance`].
    #[serde(deserialize_with = "exact_array")]
    pub initial_variance: [f64; 5],
    /// As [`WheelFilterParams::rolling_slip_std`].
    pub rolling_slip_std: f64,
}

impl WheelEstimatorParams {
    /// Checks every key, relative to the `[estimator]` table.
    pub fn validate(&self) -> Result<(), ParamError> {
        ranges::PULL.check("friction_pull", self.friction_pull)?;
        ranges::ROLLING_TORQUE_NM.check("rolling_torque_nm", self.rolling_torque_nm)?;
        self.filter().validate()
    }

    /// The filter's noise settings.
    pub fn filter(&self) -> WheelFilterParams {
        WheelFilterParams {
            process_noise: self.process_noise,
            measurement_variance_rad2_s2: self.measurement_variance_rad2_s2,
            initial_variance: self.initial_variance,
            rolling_slip_std: self.rolling_slip_std,
        }
    }

    /// The friction law.
    pub fn friction(&self) -> Friction {
        if self.friction_pull > 0.0 {
            Friction::TorqueBalance {
                pull: self.friction_pull,
            }
        } else {
            Friction::RandomWalk
        }
    }

    /// Whether a wheel with these torques (N m) counts as rolling.
    pub fn rolling(&self, torques: &SVector<f64, 2>) -> bool {
        torques[U_BRAKE].abs() + torques[U_DRIVE].abs() < self.rolling_torque_nm
    }
}

/// The slip `(v - r omega) / max(v, r omega, v_min)` (-): positive braking, negative driving,
/// within `[-1, 1]`, and going to 0 with the speed difference near standstill.
pub fn slip(v: f64, omega: f64, radius: f64, v_min: f64) -> f64 {
    slip_with_slopes(v, omega, radius, v_min).0
}

/// The slip and its partial derivatives `(lambda, dlambda/domega, dlambda/dv)` on the branch in
/// use.
pub fn slip_with_slopes(v: f64, omega: f64, radius: f64, v_min: f64) -> (f64, f64, f64) {
    let w = radius * omega;
    if v >= w && v >= v_min {
        // Braking (or rolling): (v - r omega) / v.
        ((v - w) / v, -radius / v, w / (v * v))
    } else if w > v && w >= v_min {
        // Traction: (v - r omega) / (r omega) = v / (r omega) - 1.
        (v / w - 1.0, -v * radius / (w * w), 1.0 / w)
    } else {
        ((v - w) / v_min, -radius / v_min, 1.0 / v_min)
    }
}

/// How the filter predicts the friction coefficient.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Friction {
    /// The tutorial's: the known surface's curve at the previous slip.
    Curve(Burckhardt),
    /// The surface is not known: `mu` is a random walk, estimated from the wheel's dynamics.
    RandomWalk,
    /// The surface is not known: `mu` is pulled, with the share `pull` per step (-, in
    /// `[0, 1]`), toward the friction that balances the wheel's torques while the wheel
    /// decelerates with the car, `(T_b - T_d) / (g (r m + J / r))` ([`torque_balance`]). The
    /// wheel's own dynamics settle within milliseconds, so the tyre force follows the brake
    /// torque except while the wheel locks or spins up, moments the wheel speed's innovations
    /// carry. Through it a wrong mass decelerates the predicted car at a wrong rate, which the
    /// rolling wheel's slip reveals after the event.
    TorqueBalance { pull: f64 },
}

/// The friction that balances the wheel's torques while the wheel decelerates with the car
/// (steady slip: `J domega/dt = J dv/dt / r = -J g mu / r`), and its derivative by the mass:
/// `mu = (T_b - T_d) / (g (r m + J / r))`. At standstill (both the car and the wheel's rim
/// slower than `min_speed_m_s`) a brake holds the car without any tyre force: only a drive
/// torque beyond the brake's moves it (`mu < 0`).
pub fn torque_balance(p: &WheelParams, x: &SVector<f64, 5>, u: &SVector<f64, 2>) -> (f64, f64) {
    let (r, j, g) = (p.radius_m, p.inertia_kg_m2, p.gravity_m_s2);
    let m = x[X_MASS];
    let standstill = x[X_V] < p.min_speed_m_s && r * x[X_OMEGA] < p.min_speed_m_s;
    let net = if standstill {
        (u[U_BRAKE] - u[U_DRIVE]).min(0.0)
    } else {
        u[U_BRAKE] - u[U_DRIVE]
    };
    let lever = r * m + j / r;
    let mu = net / (g * lever);
    (mu, -mu * r / lever)
}

/// The quarter car's discrete model (forward Euler at `dt_s`), state
/// `[omega, v, lambda, mu, m]`, input `[T_b, T_d]` (N m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuarterCar {
    pub params: WheelParams,
    pub friction: Friction,
}

impl QuarterCar {
    /// A model on `params` with a friction law.
    pub fn new(params: WheelParams, friction: Friction) -> Self {
        Self { params, friction }
    }

    /// `(domega/dt, dv/dt)` of the continuous quarter car at a state (rad/s^2, m/s^2), with the
    /// friction the curve gives at the kinematic slip (the reference the Euler step is checked
    /// against).
    pub fn derivatives(
        params: &WheelParams,
        curve: &Burckhardt,
        omega: f64,
        v: f64,
        mass_kg: f64,
        brake_nm: f64,
        drive_nm: f64,
    ) -> (f64, f64) {
        let lambda = slip(v, omega, params.radius_m, params.min_speed_m_s);
        let mu = curve.mu(lambda);
        let g = params.gravity_m_s2;
        (
            (params.radius_m * g * mu * mass_kg - brake_nm + drive_nm) / params.inertia_kg_m2,
            -g * mu,
        )
    }

    fn step(&self, x: &SVector<f64, 5>, u: &SVector<f64, 2>) -> (SVector<f64, 5>, [f64; 3]) {
        let p = &self.params;
        let (ts, r, g, j) = (p.dt_s, p.radius_m, p.gravity_m_s2, p.inertia_kg_m2);
        let (omega, v, lambda, mu, m) = (x[X_OMEGA], x[X_V], x[X_SLIP], x[X_MU], x[X_MASS]);
        let (slip_next, d_omega, d_v) = slip_with_slopes(v, omega, r, p.min_speed_m_s);
        let (mu_next, d_mu) = match self.friction {
            Friction::Curve(c) => (c.mu(lambda), c.slope(lambda)),
            Friction::RandomWalk => (mu, 0.0),
            Friction::TorqueBalance { pull } => {
                let (balance, _) = torque_balance(p, x, u);
                (mu + pull * (balance - mu), 0.0)
            }
        };
        let next = SVector::<f64, 5>::new(
            omega + ts / j * (r * g * mu * m - u[U_BRAKE] + u[U_DRIVE]),
            v - ts * g * mu,
            slip_next,
            mu_next,
            m,
        );
        (next, [d_omega, d_v, d_mu])
    }
}

impl TransitionModel<5, 2> for QuarterCar {
    fn transition(&self, x: &SVector<f64, 5>, u: &SVector<f64, 2>) -> SVector<f64, 5> {
        self.step(x, u).0
    }

    fn transition_jacobian(&self, x: &SVector<f64, 5>, u: &SVector<f64, 2>) -> SMatrix<f64, 5, 5> {
        self.transition_with_jacobian(x, u).1
    }

    fn transition_with_jacobian(
        &self,
        x: &SVector<f64, 5>,
        u: &SVector<f64, 2>,
    ) -> (SVector<f64, 5>, SMatrix<f64, 5, 5>) {
        let (next, [d_omega, d_v, d_mu]) = self.step(x, u);
        let p = &self.params;
        let k = p.dt_s * p.radius_m * p.gravity_m_s2 / p.inertia_kg_m2;
        let mut f = SMatrix::<f64, 5, 5>::zeros();
        f[(X_OMEGA, X_OMEGA)] = 1.0;
        f[(X_OMEGA, X_MU)] = k * x[X_MASS];
        f[(X_OMEGA, X_MASS)] = k * x[X_MU];
        f[(X_V, X_V)] = 1.0;
        f[(X_V, X_MU)] = -p.dt_s * p.gravity_m_s2;
        f[(X_SLIP, X_OMEGA)] = d_omega;
        f[(X_SLIP, X_V)] = d_v;
        match self.friction {
            Friction::Curve(_) => f[(X_MU, X_SLIP)] = d_mu,
            Friction::RandomWalk => f[(X_MU, X_MU)] = 1.0,
            Friction::TorqueBalance { pull } => {
                let p = &self.params;
                let m = x[X_MASS];
                let (r, j) = (p.radius_m, p.inertia_kg_m2);
                let lever = r * m + j / r;
                let balance = (u[U_BRAKE] - u[U_DRIVE]) / (p.gravity_m_s2 * lever);
                f[(X_MU, X_MU)] = 1.0 - pull;
                f[(X_MU, X_MASS)] = -pull * balance * r / lever;
            }
        }
        f[(X_MASS, X_MASS)] = 1.0;
        (next, f)
    }

    /// Forward motion only (a brake holds a stopped wheel), the slip within `[-1, 1]`, the
    /// friction within [`MU_MAX`], the mass within [`MASS_BOUNDS_KG`].
    fn constrain(&self, x: &mut SVector<f64, 5>) {
        x[X_OMEGA] = x[X_OMEGA].max(0.0);
        x[X_V] = x[X_V].max(0.0);
        x[X_SLIP] = x[X_SLIP].clamp(-1.0, 1.0);
        x[X_MU] = x[X_MU].clamp(-MU_MAX, MU_MAX);
        x[X_MASS] = x[X_MASS].clamp(MASS_BOUNDS_KG.0, MASS_BOUNDS_KG.1);
    }
}

/// The wheel-speed sensor, `y[0] = omega` (rad/s), and the rolling wheel's slip,
/// `y[1] = slip(v, omega)` (-): a pseudo-measurement of 0 while no torque acts on the wheel (a
/// free-rolling tyre slips by its rolling resistance only, a few thousandths), used only when
/// the caller says the wheel rolls ([`WheelEkf::step`]). It is what makes the speed and, over a
/// braking event, the mass observable when the surface is unknown (module notes).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WheelSensors {
    /// Rolling radius (m).
    pub radius_m: f64,
    /// The slip's denominator floor (m/s).
    pub min_speed_m_s: f64,
}

impl ObservationModel<5, 2, 2> for WheelSensors {
    fn observe(&self, x: &SVector<f64, 5>, _u: &SVector<f64, 2>) -> SVector<f64, 2> {
        SVector::<f64, 2>::new(
            x[X_OMEGA],
            slip(x[X_V], x[X_OMEGA], self.radius_m, self.min_speed_m_s),
        )
    }

    fn observation_jacobian(
        &self,
        x: &SVector<f64, 5>,
        _u: &SVector<f64, 2>,
    ) -> SMatrix<f64, 2, 5> {
        let (_, d_omega, d_v) =
            slip_with_slopes(x[X_V], x[X_OMEGA], self.radius_m, self.min_speed_m_s);
        SMatrix::<f64, 2, 5>::new(1.0, 0.0, 0.0, 0.0, 0.0, d_omega, d_v, 0.0, 0.0, 0.0)
    }
}

/// The tutorial's EKF: predict with the torques, then update with the measured wheel speed,
/// every `dt_s`.
#[derive(Debug, Clone)]
pub struct WheelEkf {
    ekf: Ekf<QuarterCar, WheelSensors, 5, 2, 2>,
    q: SMatrix<f64, 5, 5>,
    p0: SMatrix<f64, 5, 5>,
    /// Before the first step the filter holds the start state; its covariance is `p0`, which
    /// may be singular (the tutorial's is zero) and is only ever used through `F p0 F' + Q`.
    started: bool,
    /// `rolling_slip_std > 0`: the rolling pseudo-measurement is on.
    use_rolling: bool,
}

impl WheelEkf {
    /// A filter at the tutorial's start `[v0 / r, v0, 0, 0, m0]` with the covariance
    /// `initial_variance` (see the module notes: the first step makes `F P0 F' + Q` the prior).
    pub fn new(
        model: QuarterCar,
        filter: &WheelFilterParams,
        v0_m_s: f64,
        m0_kg: f64,
    ) -> Result<Self, ConfigError> {
        let q = filter.q();
        let p0 = SMatrix::from_diagonal(&SVector::from(filter.initial_variance));
        let r = SMatrix::<f64, 2, 2>::new(
            filter.measurement_variance_rad2_s2,
            0.0,
            0.0,
            filter.rolling_slip_std.powi(2).max(f64::MIN_POSITIVE),
        );
        let sensors = WheelSensors {
            radius_m: model.params.radius_m,
            min_speed_m_s: model.params.min_speed_m_s,
        };
        let x0 = Self::start_state(&model.params, v0_m_s, m0_kg);
        // The EKF is built with `Q` as a stand-in (it requires a positive definite matrix):
        // the first step replaces it by `F P0 F' + Q`.
        let ekf = Ekf::new(model, sensors, x0, q, q, r)?;
        Ok(Self {
            ekf,
            q,
            p0,
            started: false,
            use_rolling: filter.rolling_slip_std > 0.0,
        })
    }

    fn start_state(p: &WheelParams, v0: f64, m0: f64) -> SVector<f64, 5> {
        SVector::<f64, 5>::new(v0.max(0.0) / p.radius_m, v0.max(0.0), 0.0, 0.0, m0)
    }

    /// Back to the start at a new speed and mass, with the covariance `initial_variance`.
    pub fn restart(&mut self, v0_m_s: f64, m0_kg: f64) -> Result<(), ConfigError> {
        let x0 = Self::start_state(&self.model().params, v0_m_s, m0_kg);
        self.ekf.reset(x0, self.q)?;
        self.started = false;
        Ok(())
    }

    /// One step: predict with the torques `[T_b, T_d]` (N m) applied over the last period, then
    /// update with the measured wheel speed (rad/s) and, when `rolling` (no torque on the wheel)
    /// and the filter has a `rolling_slip_std`, with the rolling wheel's zero slip. On error
    /// the estimate is kept. The innovation's second component is 0 when it was not used.
    pub fn step(
        &mut self,
        omega_meas: f64,
        torques: &SVector<f64, 2>,
        rolling: bool,
    ) -> Result<Innovation<2>, FilterError> {
        if self.started {
            self.ekf.predict(torques)?;
        } else {
            // The first prediction from P0 (the tutorial's: zero): F P0 F' + Q.
            let model = self.ekf.transition_model();
            let (mut x, f) = model.transition_with_jacobian(self.ekf.state(), torques);
            model.constrain(&mut x);
            let mut p = f * self.p0 * f.transpose() + self.q;
            p = (p + p.transpose()) * 0.5;
            self.ekf
                .reset(x, p)
                .map_err(|_| FilterError::NonFiniteResult {
                    which: "prediction",
                })?;
            self.started = true;
        }
        let used = [true, rolling && self.use_rolling];
        self.ekf
            .update_subset(&SVector::<f64, 2>::new(omega_meas, 0.0), torques, &used)
    }

    /// The estimate `[omega, v, lambda, mu, m]`.
    pub fn state(&self) -> &SVector<f64, 5> {
        self.ekf.state()
    }

    /// The estimate's covariance.
    pub fn covariance(&self) -> &SMatrix<f64, 5, 5> {
        self.ekf.covariance()
    }

    /// The model the filter runs.
    pub fn model(&self) -> &QuarterCar {
        self.ekf.transition_model()
    }

    /// Replaces the friction law (the surface the filter assumes), keeping the estimate.
    pub fn set_friction(&mut self, friction: Friction) {
        self.ekf.transition_model_mut().friction = friction;
    }
}
