//! `fdd reproduce wheel`: the slip-control tutorial's experiment (seeds/002, REFERENCE §3) and
//! what it leaves unshown. A car brakes under a PI slip controller per wheel that closes its
//! loop on a quarter-car EKF's slip; the tutorial shows one 3 s stop from 20 m/s on one surface
//! with the filter's own model as the "real" car and a mass that starts right. Here the real
//! car is fdd's truth simulator (a whole car, not the filters' model), the stops run on four
//! surfaces from three speeds to standstill, the estimates are judged against the truth, and
//! the mass is started wrong.
//!
//! # Protocol (fixed before any held-out figure was looked at)
//!
//! - **Truth**: [`WheelPlant`] of fdd-fixtures (RK4 at 0.1 ms, tyre relaxation and carcass
//!   damping, brake lag and dead time, rolling resistance, drag, load transfer) on the
//!   committed plant file, in a **quarter-car layout**: total mass 1800 kg (4 x 450 kg), front
//!   static share 0.5, so that every corner carries the tutorial's 450 kg at rest; the
//!   centre-of-gravity height 0.21 m and the wheelbase 3.85 m give the least load transfer
//!   the plant's parameter checks accept after the perturbation below (cg height >= 0.2 m,
//!   wheelbase <= 4 m): `h / L` = 0.055, so braking at `a` moves each wheel's load by
//!   `2 (h / L) a / g` of its static load, 12 % in a dry ABS stop, 0.6 % on ice. The load
//!   transfer is kept (the plant has no switch for it, and it is real). All four corners are
//!   on the same surface and get the same driver demand.
//! - **Not the filters' model**: every perturbable key of the plant (radii, inertias, the
//!   layout above, resistances, tyre, brake lag, dead time and torque gain, every friction
//!   coefficient) is multiplied by its own `1 + e`, `e ~ U[-0.03, 0.03]`
//!   ([`PARAM_REL_ERROR`], [`perturb`]), on top of the plant file's own offsets from the
//!   filters' `config/wheel.toml` (friction coefficients 4-6 % off the table, brake torque
//!   gain 0.96, radii 0.308 / 0.310 m against 0.31 m, inertias 1.2 / 1.0 against 1.0 kg m^2).
//!   The seed's car is the perturbation; seed `s` draws it from its own stream and each
//!   corner's sensor from another ([`seed_stream`]).
//! - **True quarter mass and friction**: a corner's friction is the coefficient its tyre uses
//!   (the plant's `mu`), its slip the kinematic slip, its quarter mass its normal load over
//!   g (450 kg at rest, moving with the load transfer while braking). In the mass experiment
//!   all four corners get the same brake torque; each then decelerates a quarter of the car
//!   whatever the load transfer does to the tyres' loads, so the true quarter mass there is
//!   the total over four, 450 kg ([`TRUE_QUARTER_MASS_KG`]).
//! - **Sensors**: a [`ToneWheelSensor`] per corner (the plant file's 48-tooth ring, pitch
//!   errors, jitter, 1 us timer, 5 ms windows), no fault; its window speed is the filters'
//!   measurement every 5 ms.
//! - **Controller**: the plant file's [`SlipController`] per corner (PI on the slip, gains
//!   scheduled with speed, off below 2 m/s), fed the estimator's slip and vehicle speed of its
//!   corner, or the truth's (kinematic slip, body speed) for the baseline. Driver demand
//!   [`DEMAND_N_M`] on every corner, above any wheel's peak brake torque on any surface (dry
//!   front about 1.7 kN m), ramped linearly over [`PEDAL_RAMP_S`] from the onset at
//!   [`ONSET_S`]; before the onset the car rolls.
//! - **Estimators**, one per corner, fed that corner's brake torque as the ECU's actuator
//!   model gives it ([`BrakeModel`]: the command through the plant file's nominal dead time
//!   and lag at unit gain; the applied torque is not measured, and the car's own lag, dead
//!   time and pad gain are perturbed from those), its drive torque and its tone-wheel speed,
//!   both started at the tutorial's `[v0 / r, v0, 0, 0, 450 kg]` with the true initial speed
//!   at t = 0: (a) **the tutorial's filter**: `[filter]` of `config/wheel.toml` (its Q, R,
//!   P0 = 0), [`Friction::Curve`] with the table's curve of the surface under the car (the
//!   surface known, as in the tutorial; the table's coefficients, not the truth's), no rolling
//!   pseudo-measurement; (b) **fdd's**: `[estimator]` (the surface unknown:
//!   [`Friction::TorqueBalance`] or a random walk, the rolling wheel's zero slip while both
//!   the torque on the wheel and the driver's demand of it are below `rolling_torque_nm`).
//!   Both estimators also run beside the stops whose controller is fed the true slip, which
//!   gives their error without the loop's feedback on it.
//! - **Revised during tuning, before any held-out case was run**: the filters were first fed
//!   the raw command (the actuator's 30 ms lag then reads as a friction 0.3 too high for
//!   0.15 s at every onset), and the rolling rule first looked at the torque only (it then
//!   took a wheel the ABS had released for a rolling one while it spun back up from a slip of
//!   0.4); the figures beside the truth were added.
//! - **Figures of a stop**, over the samples from the onset to the first with the true speed
//!   below the controller's disengage speed (2 m/s), pooled over the four corners: RMSE of
//!   `v` (each corner's estimate against the body speed), of the slip and of `mu` against the
//!   truth; the **raw slip**'s RMSE (the kinematic slip from the corner's tone-wheel speed,
//!   its true radius and the true body speed: the issue's "slip computed from the raw wheel
//!   speed and the true vehicle speed"); the **mu time**: per corner, the first time after the
//!   onset from which the 20 ms centred mean of `|mu_est - mu_true|` (the 5 samples k-2..k+2
//!   that lie in the window) stays <= 0.05 up to the window's end ("never" if the last one
//!   exceeds it), the stop's being the latest corner's; the **stopping distance** from the
//!   onset to standstill with that estimator in the loop, against the same stop with the
//!   controller fed the true slip and speed. Steps a filter refused (its estimate kept) are
//!   counted.
//! - **Cases**: tuning = stops from 20 m/s on dry and snow with cars 1-3, and the mass
//!   experiment with car 1; held-out = stops on dry, wet, snow and ice from 10, 20 and 30 m/s
//!   with cars 11-13, and the mass experiment with cars 11-13. A row gives the mean over its
//!   cars of the RMSEs and distances and the latest mu time.
//! - **Tuning**: only the values of `[estimator]`, only on the tuning cases' figures
//!   (`--tuning-only` runs nothing else); the held-out cases are run after the tuning stopped
//!   and reported as they come. The line is judged on the held-out cases: per
//!   surface, every held-out stop's mu time <= 0.5 s, and every held-out row's slip RMSE <=
//!   half its raw slip RMSE; the mass within 5 % from 300 kg and from 600 kg within 10 events
//!   for every held-out car.
//! - **Mass experiment** (dry, the same layout and perturbation; no slip control: the demand
//!   is below the peak): from 20 m/s, an event is: the driver brakes every corner with
//!   [`MASS_BRAKE_N_M`] (0.4 g for 450 kg, ramped over [`PEDAL_RAMP_S`]) until the true speed
//!   is below 10 m/s, releases, the car rolls 1 s, the front axle drives it with
//!   [`MASS_DRIVE_N_M`] back to 20 m/s, it rolls 1 s. [`MASS_EVENTS`] events; fdd's estimator
//!   and the tutorial's filter each started at 300 kg and at 600 kg. The corner judged is the
//!   rear left (braked, never driven); the front left's figures are given beside it (a
//!   quarter car of a driven wheel sees its own drive torque push the whole car: it is not a
//!   quarter car while driving). Per start: the estimate after each event (at its end); the
//!   events until within 5 % of 450 kg and staying there to the last event; the estimate
//!   after 10 events.
//!
//! # What the held-out figures show (run once, after the tuning)
//!
//! Neither estimator meets the friction or slip line with it in the loop, on any
//! surface; fdd's mass line holds from 300 kg, not from 600 kg. The reasons, as the samples
//! (`--series`) show them:
//!
//! - **The raw slip knows the true speed.** With the tone wheel's 0.1 % resolution the slip
//!   from the measured wheel speed and the true vehicle speed is off only by the window's lag
//!   while the wheel decelerates and by the quantization near 2 m/s. Nothing measures the
//!   vehicle speed while every wheel slips: both filters dead-reckon it from their friction
//!   through the whole stop, and the slip's error is that speed error over a speed that goes to
//!   2 m/s (a friction 2 % off leaves the speed about 0.4 m/s off after a 10 s snow stop: a
//!   slip error of 0.1 at 4 m/s).
//! - **A quarter car does not know its load.** The wheel's torques give the tyre force; the
//!   friction is that force over the normal load, which the load transfer moves (12 % of the
//!   static load in a dry stop, the least the plant accepts): fdd's friction is off by about
//!   as much on dry and wet asphalt, front corners high and rear corners low, and so are the
//!   speeds each corner dead-reckons.
//! - **In the loop the errors feed back.** A speed estimate that runs low makes the controller
//!   brake harder and the true slip leaves the peak; one that runs high releases the wheel.
//!   When the estimate reaches 2 m/s before the car does, the ABS lets go and the wheels lock,
//!   and the friction estimate jumps within the figures' window: no in-loop mu time survives
//!   to its end (ending the window where the ABS let go instead gives 0.52-0.72 s on snow and
//!   1.0-1.1 s on ice for car 11 from 20 m/s, still not 0.5 s). Beside a loop on the true
//!   slip, fdd's friction is within 0.05 after 0.35-0.5 s on snow, 0.7-1.0 s on ice.
//! - **The tutorial's filter** makes its prediction count for little (Q of 1 on slip and
//!   friction); its friction is the known curve at a noisy slip, far off on dry and wet
//!   asphalt, where the curve is steep below the peak, but closer than fdd's on snow and ice,
//!   whose curves are flat around the controller's slip. Its P0 = 0 keeps its mass at its
//!   start (301 and 600 kg after 10 events).
//! - **Mass.** fdd's rear-left estimate learns from the speed error the rolling slip reveals
//!   after each brake. Both starts approach about 480 kg (6-7 % high: from 600 kg it is
//!   475-479 kg after 10 events; from 300 kg it crosses into the band at the 3rd-4th event and
//!   is still rising by about 1 kg an event at the 15th), a bias the quarter car's missing
//!   rolling resistance, drag and brake gain would put on the other side; the re-acceleration,
//!   which the rear corner's filter sees as rolling while the car speeds up, probably pushes it
//!   up. The front left, whose own drive torque pushes the whole car back up, learns 640-735 kg:
//!   a quarter car of a driven wheel is no quarter car while it drives.

use std::path::{Path, PathBuf};

use fdd_estimators::models::wheel::{
    Friction, QuarterCar, Surface as FilterSurface, WheelEkf, WheelEstimatorParams,
    WheelFilterParams, WheelParams, X_MASS, X_MU, X_SLIP, X_V,
};
use fdd_estimators::{ConfigError as FilterConfigError, ParamError};
use fdd_fixtures::wheel_control::{SlipControlInput, SlipController};
use fdd_fixtures::wheel_params::{perturb, WheelPlantError, WheelPlantFile, WheelPlantParams};
use fdd_fixtures::wheel_plant::{WheelCommand, WheelPlant, WheelStepError};
use fdd_fixtures::wheel_sensor::ToneWheelSensor;
use fdd_fixtures::wheel_tyre::{kinematic_slip, Corner, Surface, SurfaceSchedule, CORNERS};
use nalgebra::SVector;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The quarter car's parameter file, embedded: `config/wheel.toml`.
pub const DEFAULT_PARAMS_TOML: &str = include_str!("../../config/wheel.toml");
/// How errors name the embedded parameter file.
pub const DEFAULT_PARAMS_ORIGIN: &str = "config/wheel.toml (embedded)";

/// Relative error of every perturbed plant key (-): `U[-0.03, 0.03]`, the spread of one car
/// type's parameters across a fleet, on top of the plant file's own offsets from the filters'
/// model.
pub const PARAM_REL_ERROR: f64 = 0.03;
/// Total mass of the quarter-car layout (kg): four of the tutorial's 450 kg.
pub const TOTAL_MASS_KG: f64 = 1800.0;
/// The static quarter mass (kg) and the true quarter mass of the mass experiment.
pub const TRUE_QUARTER_MASS_KG: f64 = 450.0;
/// Front axle's static share (-): equal static loads.
pub const FRONT_STATIC_SHARE: f64 = 0.5;
/// Centre-of-gravity height (m): the plant accepts 0.2 m and more; 0.21 stays above it after
/// a 3 % perturbation.
pub const CG_HEIGHT_M: f64 = 0.21;
/// Wheelbase (m): the plant accepts up to 4 m; 3.85 stays below it after a 3 % perturbation.
pub const WHEELBASE_M: f64 = 3.85;

/// Time of the braking onset (s): the car rolls before it.
pub const ONSET_S: f64 = 0.5;
/// The driver's pedal ramp to the full demand (s).
pub const PEDAL_RAMP_S: f64 = 0.15;
/// The driver's brake demand per corner in a stop (N m).
pub const DEMAND_N_M: f64 = 2500.0;
/// Band of the mu time (-): the 0.05.
pub const MU_BAND: f64 = 0.05;
/// Half-width of the mu time's centred mean (samples): 5 samples of 5 ms span 20 ms.
pub const MU_MEAN_HALF: usize = 2;
/// Longest stop simulated (s): an ice stop from 30 m/s takes about 60 s.
pub const STOP_LIMIT_S: f64 = 150.0;
/// Initial speeds of the held-out stops (m/s).
pub const SPEEDS_M_S: [f64; 3] = [10.0, 20.0, 30.0];
/// Initial speed of the tuning stops (m/s): the tutorial's.
pub const TUNING_SPEED_M_S: f64 = 20.0;
/// Surfaces of the tuning stops.
pub const TUNING_SURFACES: [Surface; 2] = [Surface::Dry, Surface::Snow];
/// Cars (seeds) of the tuning cases.
pub const TUNING_SEEDS: [u64; 3] = [1, 2, 3];
/// Cars of the held-out cases.
pub const HELD_OUT_SEEDS: [u64; 3] = [11, 12, 13];
/// Car of the mass experiment's tuning run.
pub const MASS_TUNING_SEED: u64 = 1;

/// Brake torque per corner of a mass-experiment event (N m): 0.4 g for 450 kg at 0.31 m.
pub const MASS_BRAKE_N_M: f64 = 550.0;
/// Drive torque at the front axle when the mass experiment re-accelerates (N m): about
/// 0.25 g for the car.
pub const MASS_DRIVE_N_M: f64 = 1400.0;
/// Speed the mass experiment starts from and drives back to (m/s).
pub const MASS_HIGH_M_S: f64 = 20.0;
/// Speed at which its braking ends (m/s).
pub const MASS_LOW_M_S: f64 = 10.0;
/// Rolling after the brake and after the drive (s).
pub const MASS_ROLL_S: f64 = 1.0;
/// Events of the mass experiment.
pub const MASS_EVENTS: usize = 15;
/// The events the issue allows (-).
pub const MASS_EVENT_LIMIT: usize = 10;
/// Band of the mass (-): 5 %.
pub const MASS_BAND: f64 = 0.05;
/// The wrong initial masses (kg).
pub const MASS_STARTS_KG: [f64; 2] = [300.0, 600.0];

/// A failure of the reproduction.
#[derive(Debug, Error)]
pub enum WheelReproError {
    /// Reading the parameter file.
    #[error("{file}: {source}")]
    Read {
        /// The file.
        file: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The parameter file does not parse.
    #[error("{origin}: {message}")]
    Parse {
        /// The file.
        origin: String,
        /// The parser's message.
        message: String,
    },
    /// A parameter is out of range.
    #[error("{origin}: [{table}] {source}")]
    Param {
        /// The file.
        origin: String,
        /// Its table.
        table: &'static str,
        /// The key and why.
        source: ParamError,
    },
    /// The truth's plant file or a value set on it.
    #[error(transparent)]
    Plant(#[from] WheelPlantError),
    /// A plant step.
    #[error(transparent)]
    Step(#[from] WheelStepError),
    /// A filter could not be built.
    #[error("wheel filter: {0}")]
    Filter(#[from] FilterConfigError),
    /// Writing a series file.
    #[error("{file}: {source}")]
    Write {
        /// The file.
        file: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A simulation worker thread ended without a result (it panicked).
    #[error("fdd reproduce wheel: a simulation worker stopped without a result")]
    Worker,
}

/// The tables of `config/wheel.toml` the reproduction uses.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParamsFile {
    model: WheelParams,
    filter: WheelFilterParams,
    estimator: WheelEstimatorParams,
}

/// The quarter car's parameters, the tutorial's filter and fdd's estimator, checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelFilters {
    /// `[model]`.
    pub model: WheelParams,
    /// `[filter]`: the tutorial's.
    pub filter: WheelFilterParams,
    /// `[estimator]`: fdd's.
    pub estimator: WheelEstimatorParams,
}

impl WheelFilters {
    /// Parses and checks a parameter file's text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, WheelReproError> {
        let f: ParamsFile = toml::from_str(text).map_err(|e| WheelReproError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        let param = |table: &'static str| {
            move |source: ParamError| WheelReproError::Param {
                origin: origin.to_string(),
                table,
                source,
            }
        };
        f.model.validate().map_err(param("model"))?;
        f.filter.validate().map_err(param("filter"))?;
        f.estimator.validate().map_err(param("estimator"))?;
        Ok(Self {
            model: f.model,
            filter: f.filter,
            estimator: f.estimator,
        })
    }

    /// The parameter file at `path`, or the embedded `config/wheel.toml`.
    pub fn load(path: Option<&Path>) -> Result<Self, WheelReproError> {
        match path {
            None => Self::parse(DEFAULT_PARAMS_TOML, DEFAULT_PARAMS_ORIGIN),
            Some(p) => {
                let text = std::fs::read_to_string(p).map_err(|source| WheelReproError::Read {
                    file: p.to_path_buf(),
                    source,
                })?;
                Self::parse(&text, &p.display().to_string())
            }
        }
    }
}

/// What closes the slip loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LoopOn {
    /// The truth's slip and speed (the baseline).
    Truth,
    /// The tutorial's filter (surface known).
    Tutorial,
    /// fdd's estimator (surface unknown).
    Fdd,
}

impl LoopOn {
    /// Name in the table.
    pub fn name(self) -> &'static str {
        match self {
            LoopOn::Truth => "true slip",
            LoopOn::Tutorial => "tutorial",
            LoopOn::Fdd => "fdd",
        }
    }
}

/// The independent stream `k` of seed `seed` (splitmix64 of both), so that a car's plant and
/// its four sensors never share a stream and no two seeds' streams coincide.
pub fn seed_stream(seed: u64, k: u64) -> u64 {
    let mut z = seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(k.wrapping_mul(0xD1B5_4A32_D192_ED03))
        .wrapping_add(0x2545_F491_4F6C_DD1D);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The truth's physics for car `seed`: the committed plant in the quarter-car layout, then
/// perturbed by [`PARAM_REL_ERROR`] from the seed's plant stream.
pub fn car(file: &WheelPlantFile, seed: u64) -> WheelPlantParams {
    let mut p = file.plant();
    p.vehicle.total_mass_kg = TOTAL_MASS_KG;
    p.vehicle.front_static_share = FRONT_STATIC_SHARE;
    p.vehicle.cg_height_m = CG_HEIGHT_M;
    p.vehicle.wheelbase_m = WHEELBASE_M;
    let mut rng = Pcg64Mcg::seed_from_u64(seed_stream(seed, 0));
    perturb(&mut p, PARAM_REL_ERROR, &mut rng);
    p
}

/// The filter's surface of the truth's.
fn filter_surface(s: Surface) -> FilterSurface {
    match s {
        Surface::Dry => FilterSurface::Dry,
        Surface::Wet => FilterSurface::Wet,
        Surface::Snow => FilterSurface::Snow,
        Surface::Ice => FilterSurface::Ice,
    }
}

/// One estimator per corner.
struct Bank {
    ekf: Vec<WheelEkf>,
    estimator: Option<WheelEstimatorParams>,
    refused: u64,
}

impl Bank {
    /// The tutorial's filter (`kind` Tutorial: it is given the curve of `surface`) or fdd's
    /// estimator (`kind` Fdd: the surface unknown), started at `[v0 / r, v0, 0, 0, m0]` (m/s,
    /// kg).
    fn new(
        f: &WheelFilters,
        kind: LoopOn,
        surface: Surface,
        v0: f64,
        m0: f64,
    ) -> Result<Self, WheelReproError> {
        let (friction, filter, estimator) = match kind {
            LoopOn::Fdd => (
                f.estimator.friction(),
                f.estimator.filter(),
                Some(f.estimator),
            ),
            _ => (
                Friction::Curve(f.model.surfaces.curve(filter_surface(surface))),
                f.filter,
                None,
            ),
        };
        let mut ekf = Vec::with_capacity(CORNERS);
        for _ in 0..CORNERS {
            ekf.push(WheelEkf::new(
                QuarterCar::new(f.model, friction),
                &filter,
                v0,
                m0,
            )?);
        }
        Ok(Self {
            ekf,
            estimator,
            refused: 0,
        })
    }

    /// One 5 ms step of every corner: the measured wheel speeds (rad/s), the torques
    /// `[brake, drive]` (N m) the ECU's actuator model gives for the period, and the driver's
    /// demands `[brake, drive]` (N m). A wheel counts as rolling (fdd's estimator) when both
    /// its torque and its demand are below `rolling_torque_nm`: while the ABS holds the brake
    /// released against the driver's pedal the wheel is spinning back up from a slip, not
    /// rolling.
    fn step(
        &mut self,
        omega: &[f64; CORNERS],
        torques: &[[f64; 2]; CORNERS],
        demands: &[[f64; 2]; CORNERS],
    ) {
        for (i, ekf) in self.ekf.iter_mut().enumerate() {
            let u = SVector::<f64, 2>::new(torques[i][0], torques[i][1]);
            let d = SVector::<f64, 2>::new(demands[i][0], demands[i][1]);
            let rolling = self
                .estimator
                .is_some_and(|e| e.rolling(&u) && e.rolling(&d));
            if ekf.step(omega[i], &u, rolling).is_err() {
                self.refused += 1;
            }
        }
    }

    fn state(&self, i: usize) -> &SVector<f64, 5> {
        self.ekf[i].state()
    }
}

/// The ECU's model of its brake actuators: each corner's commanded torque after the nominal
/// dead time, through the nominal first-order lag, at unit gain (the ECU does not know its pads'
/// friction), averaged over each controller period: the torque the filters are given. The
/// nominal dead time and lag are the plant file's unperturbed `[brakes]` values; the car's
/// own are perturbed from them.
#[derive(Debug, Clone)]
pub struct BrakeModel {
    tau_s: f64,
    period_s: f64,
    /// Whole periods in the dead time, and the rest (s).
    whole: usize,
    rest_s: f64,
    /// The last `whole + 2` commands per corner, newest last.
    history: Vec<[f64; CORNERS]>,
    applied: [f64; CORNERS],
}

impl BrakeModel {
    /// A model with lag `tau_s` (s, > 0), dead time `dead_s` (s, >= 0) and period `period_s`
    /// (s, > 0), at rest.
    pub fn new(tau_s: f64, dead_s: f64, period_s: f64) -> Self {
        let whole = (dead_s / period_s).floor() as usize;
        Self {
            tau_s,
            period_s,
            whole,
            rest_s: dead_s - whole as f64 * period_s,
            history: vec![[0.0; CORNERS]; whole + 2],
            applied: [0.0; CORNERS],
        }
    }

    /// Issues `cmd` (N m per corner) for the coming period; returns the model's mean applied
    /// torque over it (N m).
    pub fn step(&mut self, cmd: &[f64; CORNERS]) -> [f64; CORNERS] {
        self.history.remove(0);
        self.history.push(cmd.map(|c| c.max(0.0)));
        let n = self.history.len();
        // Over [0, rest) the lag sees the command issued whole + 1 periods ago, then the one
        // issued whole periods ago.
        let (older, newer) = (
            self.history[n - 2 - self.whole],
            self.history[n - 1 - self.whole],
        );
        let mut out = [0.0; CORNERS];
        for i in 0..CORNERS {
            let mut x = self.applied[i];
            let mut sum = 0.0;
            for (s, w) in [
                (self.rest_s, older[i]),
                (self.period_s - self.rest_s, newer[i]),
            ] {
                if s > 0.0 {
                    let e = (-s / self.tau_s).exp();
                    sum += w * s + (x - w) * self.tau_s * (1.0 - e);
                    x = w + (x - w) * e;
                }
            }
            self.applied[i] = x;
            out[i] = sum / self.period_s;
        }
        out
    }
}

/// A car with its four tone-wheel sensors.
struct Rig {
    plant: WheelPlant,
    sensors: Vec<ToneWheelSensor>,
    radii: [f64; CORNERS],
    slip_floor_m_s: f64,
    dt_s: f64,
}

impl Rig {
    fn new(
        file: &WheelPlantFile,
        seed: u64,
        surface: Surface,
        v0: f64,
    ) -> Result<Self, WheelReproError> {
        let params = car(file, seed);
        let mut plant = WheelPlant::new(params, v0, SurfaceSchedule::uniform(surface))?;
        plant.set_total_mass(TOTAL_MASS_KG)?;
        let w0 = plant.wheel_speeds_rad_s();
        let a0 = plant.wheel_angles_rad();
        let mut sensors = Vec::with_capacity(CORNERS);
        for i in 0..CORNERS {
            sensors.push(ToneWheelSensor::new(
                file.tone_wheel,
                &[],
                seed_stream(seed, 1 + i as u64),
                0.0,
                a0[i],
                w0[i],
            )?);
        }
        Ok(Self {
            plant,
            sensors,
            radii: params.vehicle.wheel_radius_m,
            slip_floor_m_s: params.tyre.slip_speed_floor_m_s,
            dt_s: file.slip_control.period_s,
        })
    }

    /// One controller period with `cmd` held: the window speed of each corner (rad/s).
    fn step(&mut self, cmd: &WheelCommand) -> Result<[f64; CORNERS], WheelReproError> {
        let sensors = &mut self.sensors;
        self.plant.step_observed(self.dt_s, cmd, |sub| {
            for c in Corner::ALL {
                sensors[c.index()].advance(&sub.span(c));
            }
        })?;
        let t = self.plant.time_s();
        let mut w = [0.0; CORNERS];
        for (i, s) in self.sensors.iter_mut().enumerate() {
            w[i] = s.end_window(t).speed_rad_s;
        }
        Ok(w)
    }
}

/// One stop's case.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StopCase {
    /// Surface under all four wheels.
    #[serde(serialize_with = "ser_surface")]
    pub surface: Surface,
    /// Initial speed (m/s).
    pub v0_m_s: f64,
    /// The car (seed).
    pub seed: u64,
}

fn ser_surface<S: serde::Serializer>(s: &Surface, ser: S) -> Result<S::Ok, S::Error> {
    ser.serialize_str(s.name())
}

/// One sample of a stop (after the step ending at `t_s`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopSample {
    /// Time (s).
    pub t_s: f64,
    /// True body speed (m/s).
    pub v_m_s: f64,
    /// True kinematic slip per corner (-).
    pub slip: [f64; CORNERS],
    /// True friction per corner (-).
    pub mu: [f64; CORNERS],
    /// True quarter mass per corner: normal load over g (kg).
    pub quarter_mass_kg: [f64; CORNERS],
    /// Tone-wheel speed per corner (rad/s).
    pub omega_meas_rad_s: [f64; CORNERS],
    /// Raw slip per corner: from the tone-wheel speed, the true radius and the true speed (-).
    pub raw_slip: [f64; CORNERS],
    /// Commanded brake torque per corner (N m).
    pub brake_cmd_n_m: [f64; CORNERS],
    /// Estimates per estimator ([`ESTIMATORS`] order) and corner `[v, slip, mu, m]` (NaN for
    /// an estimator not run: with an estimator in the loop, only it runs; with the loop on the
    /// truth, both run beside it).
    pub est: [[[f64; 4]; CORNERS]; 2],
}

/// One stop simulated.
#[derive(Debug, Clone)]
pub struct StopRun {
    /// The case.
    pub case: StopCase,
    /// What closed the loop.
    pub loop_on: LoopOn,
    /// Every controller period's sample.
    pub samples: Vec<StopSample>,
    /// Distance from the onset to standstill (m).
    pub distance_m: f64,
    /// Whether the car came to a standstill within [`STOP_LIMIT_S`].
    pub stopped: bool,
    /// Filter steps refused (estimate kept), all corners, per estimator.
    pub refused_steps: [u64; 2],
}

/// The estimators compared, in the index order of [`StopSample::est`].
pub const ESTIMATORS: [LoopOn; 2] = [LoopOn::Tutorial, LoopOn::Fdd];

/// Simulates one stop with the loop closed on `loop_on`.
pub fn simulate_stop(
    f: &WheelFilters,
    file: &WheelPlantFile,
    case: StopCase,
    loop_on: LoopOn,
) -> Result<StopRun, WheelReproError> {
    let mut rig = Rig::new(file, case.seed, case.surface, case.v0_m_s)?;
    // The estimators run: the one in the loop, or both beside a loop closed on the truth.
    let mut banks: [Option<Bank>; 2] = [None, None];
    for (k, kind) in ESTIMATORS.into_iter().enumerate() {
        if loop_on == kind || loop_on == LoopOn::Truth {
            banks[k] = Some(Bank::new(
                f,
                kind,
                case.surface,
                case.v0_m_s,
                f.model.quarter_mass_kg,
            )?);
        }
    }
    let in_loop = ESTIMATORS.iter().position(|&k| k == loop_on);
    let mut ctl: Vec<SlipController> = (0..CORNERS)
        .map(|_| SlipController::new(file.slip_control))
        .collect();
    let mut brakes = BrakeModel::new(
        file.brakes.time_constant_s,
        file.brakes.dead_time_s,
        rig.dt_s,
    );
    let steps = (STOP_LIMIT_S / rig.dt_s).ceil() as usize;
    let mut samples = Vec::with_capacity(steps.min(40_000));
    let mut onset_distance = None;
    let mut stopped = false;
    for _ in 0..steps {
        let t = rig.plant.time_s();
        let demand = if t + 1e-9 < ONSET_S {
            0.0
        } else {
            DEMAND_N_M * ((t - ONSET_S) / PEDAL_RAMP_S + rig.dt_s / PEDAL_RAMP_S).min(1.0)
        };
        if demand > 0.0 && onset_distance.is_none() {
            onset_distance = Some(rig.plant.distance_m());
        }
        let mut cmd = [0.0; CORNERS];
        for (i, c) in ctl.iter_mut().enumerate() {
            let (slip, speed) = match in_loop.and_then(|k| banks[k].as_ref()) {
                None => (rig.plant.slip()[i], rig.plant.speed_m_s()),
                Some(b) => (b.state(i)[X_SLIP], b.state(i)[X_V]),
            };
            cmd[i] = c.update(&SlipControlInput {
                slip,
                speed_m_s: speed,
                demand_n_m: demand,
            });
        }
        let omega = rig.step(&WheelCommand::brake(cmd))?;
        let modelled = brakes.step(&cmd);
        for b in banks.iter_mut().flatten() {
            b.step(
                &omega,
                &modelled.map(|c| [c, 0.0]),
                &[[demand, 0.0]; CORNERS],
            );
        }
        let v = rig.plant.speed_m_s();
        let mut raw = [0.0; CORNERS];
        let mut est = [[[f64::NAN; 4]; CORNERS]; 2];
        for i in 0..CORNERS {
            raw[i] = kinematic_slip(v, rig.radii[i] * omega[i], rig.slip_floor_m_s);
            for (k, b) in banks.iter().enumerate() {
                if let Some(b) = b {
                    let x = b.state(i);
                    est[k][i] = [x[X_V], x[X_SLIP], x[X_MU], x[X_MASS]];
                }
            }
        }
        samples.push(StopSample {
            t_s: rig.plant.time_s(),
            v_m_s: v,
            slip: rig.plant.slip(),
            mu: rig.plant.mu(),
            quarter_mass_kg: rig.plant.quarter_masses_kg(),
            omega_meas_rad_s: omega,
            raw_slip: raw,
            brake_cmd_n_m: cmd,
            est,
        });
        if v <= 0.0 && onset_distance.is_some() {
            stopped = true;
            break;
        }
    }
    Ok(StopRun {
        case,
        loop_on,
        samples,
        distance_m: rig.plant.distance_m() - onset_distance.unwrap_or(0.0),
        stopped,
        refused_steps: banks.map(|b| b.map_or(0, |b| b.refused)),
    })
}

/// Figures of one estimator in one stop (in the loop, or beside a loop on the truth).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StopFigures {
    /// RMSE of the vehicle speed (m/s).
    pub v_rmse_m_s: f64,
    /// RMSE of the slip (-).
    pub slip_rmse: f64,
    /// RMSE of the raw slip (-).
    pub raw_slip_rmse: f64,
    /// RMSE of the friction (-).
    pub mu_rmse: f64,
    /// The mu time (s after the onset; None: never).
    pub mu_time_s: Option<f64>,
    /// Stopping distance with the estimator in the loop (m).
    pub distance_m: f64,
    /// Whether it stopped within the limit.
    pub stopped: bool,
    /// Samples in the window (per corner).
    pub samples: usize,
    /// Filter steps refused.
    pub refused_steps: u64,
}

/// The window of a stop: samples from the onset to the first with the true speed below
/// `v_off` (exclusive).
fn window(run: &StopRun, v_off: f64) -> (usize, usize) {
    let a = run.samples.partition_point(|s| s.t_s <= ONSET_S + 1e-9);
    let b = run.samples[a..]
        .iter()
        .position(|s| s.v_m_s < v_off)
        .map_or(run.samples.len(), |k| a + k);
    (a, b)
}

/// The mu time of estimator `k`'s corner over samples `[a, b)` (s after the onset).
fn mu_time(run: &StopRun, (a, b): (usize, usize), k: usize, corner: usize) -> Option<f64> {
    if b <= a {
        return None;
    }
    let err: Vec<f64> = run.samples[a..b]
        .iter()
        .map(|s| (s.est[k][corner][2] - s.mu[corner]).abs())
        .collect();
    let n = err.len();
    let mean = |k: usize| {
        let lo = k.saturating_sub(MU_MEAN_HALF);
        let hi = (k + MU_MEAN_HALF + 1).min(n);
        err[lo..hi].iter().sum::<f64>() / (hi - lo) as f64
    };
    // The last sample whose centred mean is outside the band; the time is the next one's.
    let mut first_in = None;
    for k in (0..n).rev() {
        let m = mean(k);
        if m.is_nan() || m > MU_BAND {
            break;
        }
        first_in = Some(k);
    }
    first_in.map(|k| run.samples[a + k].t_s - ONSET_S)
}

/// The figures of estimator `k` ([`ESTIMATORS`] order) in a stop run (in the loop, or beside
/// a loop on the truth); `v_off` is the controller's disengage speed (m/s).
pub fn stop_figures(run: &StopRun, k: usize, v_off: f64) -> StopFigures {
    let (a, b) = window(run, v_off);
    let mut ss = [0.0; 4];
    let mut n = 0usize;
    for s in &run.samples[a..b] {
        for i in 0..CORNERS {
            let e = s.est[k][i];
            ss[0] += (e[0] - s.v_m_s).powi(2);
            ss[1] += (e[1] - s.slip[i]).powi(2);
            ss[2] += (s.raw_slip[i] - s.slip[i]).powi(2);
            ss[3] += (e[2] - s.mu[i]).powi(2);
            n += 1;
        }
    }
    let rms = |x: f64| (x / n.max(1) as f64).sqrt();
    let times: Vec<Option<f64>> = (0..CORNERS).map(|i| mu_time(run, (a, b), k, i)).collect();
    let mu_time_s = times
        .iter()
        .try_fold(0.0f64, |acc, t| t.map(|t| acc.max(t)));
    StopFigures {
        v_rmse_m_s: rms(ss[0]),
        slip_rmse: rms(ss[1]),
        raw_slip_rmse: rms(ss[2]),
        mu_rmse: rms(ss[3]),
        mu_time_s,
        distance_m: run.distance_m,
        stopped: run.stopped,
        samples: b - a,
        refused_steps: run.refused_steps[k],
    }
}

/// An estimator's figures over a row's cars.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// Mean over the cars: RMSE of v (m/s).
    pub v_rmse_m_s: f64,
    /// Mean: RMSE of the slip.
    pub slip_rmse: f64,
    /// Mean: RMSE of the raw slip.
    pub raw_slip_rmse: f64,
    /// Mean: RMSE of mu.
    pub mu_rmse: f64,
    /// Latest mu time over the cars (None: some car never).
    pub mu_time_s: Option<f64>,
    /// Mean stopping distance of the runs (m).
    pub distance_m: f64,
    /// Stops that did not come to a standstill within the limit.
    pub not_stopped: usize,
    /// Filter steps refused, summed.
    pub refused_steps: u64,
    /// Per car.
    pub per_car: Vec<StopFigures>,
}

impl Summary {
    fn of(figs: Vec<StopFigures>) -> Self {
        let n = figs.len().max(1) as f64;
        let mean = |g: fn(&StopFigures) -> f64| figs.iter().map(g).sum::<f64>() / n;
        Self {
            v_rmse_m_s: mean(|x| x.v_rmse_m_s),
            slip_rmse: mean(|x| x.slip_rmse),
            raw_slip_rmse: mean(|x| x.raw_slip_rmse),
            mu_rmse: mean(|x| x.mu_rmse),
            mu_time_s: figs
                .iter()
                .try_fold(0.0f64, |acc, x| x.mu_time_s.map(|t| acc.max(t))),
            distance_m: mean(|x| x.distance_m),
            not_stopped: figs.iter().filter(|x| !x.stopped).count(),
            refused_steps: figs.iter().map(|x| x.refused_steps).sum(),
            per_car: figs,
        }
    }
}

/// One table row: a surface and initial speed, one estimator, over its cars.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StopRow {
    /// Surface name.
    pub surface: &'static str,
    /// Initial speed (m/s).
    pub v0_m_s: f64,
    /// The estimator (`tutorial` or `fdd`).
    pub estimator: LoopOn,
    /// Cars.
    pub seeds: Vec<u64>,
    /// With the estimator in the loop (the experiment).
    pub in_loop: Summary,
    /// The same estimator beside the stops whose controller is fed the true slip: its error
    /// without the loop's feedback on it.
    pub beside_truth: Summary,
    /// Mean stopping distance with the controller fed the true slip (m).
    pub distance_true_slip_m: f64,
}

/// The mass experiment's result for one estimator and start.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MassTrack {
    /// The estimator.
    pub estimator: LoopOn,
    /// Initial mass (kg).
    pub start_kg: f64,
    /// Corner name.
    pub corner: &'static str,
    /// The estimate at the end of each event (kg).
    pub after_event_kg: Vec<f64>,
    /// The first event after which the estimate is within the band up to the last (None:
    /// not by the last event).
    pub events_to_band: Option<usize>,
    /// The estimate after [`MASS_EVENT_LIMIT`] events (kg).
    pub after_limit_kg: f64,
}

/// The mass experiment on one car.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MassRun {
    /// The car.
    pub seed: u64,
    /// Per estimator, start and corner (rear left, front left).
    pub tracks: Vec<MassTrack>,
    /// The true quarter mass (kg).
    pub true_quarter_mass_kg: f64,
    /// The brake torque gain of this car (-): the commanded torque's error goes into the
    /// learned mass.
    pub brake_torque_gain: f64,
    /// Filter steps refused, all filters.
    pub refused_steps: u64,
}

/// Runs the mass experiment on car `seed`.
pub fn mass_experiment(
    f: &WheelFilters,
    file: &WheelPlantFile,
    seed: u64,
) -> Result<MassRun, WheelReproError> {
    let mut rig = Rig::new(file, seed, Surface::Dry, MASS_HIGH_M_S)?;
    let kinds = [LoopOn::Fdd, LoopOn::Tutorial];
    let mut banks = Vec::new();
    for kind in kinds {
        for m0 in MASS_STARTS_KG {
            banks.push((
                kind,
                m0,
                Bank::new(f, kind, Surface::Dry, MASS_HIGH_M_S, m0)?,
            ));
        }
    }
    // Corners judged: rear left, and front left beside it.
    let judged = [Corner::RearLeft, Corner::FrontLeft];
    let mut after: Vec<Vec<[f64; 2]>> = vec![Vec::new(); banks.len()];
    let mut brakes = BrakeModel::new(
        file.brakes.time_constant_s,
        file.brakes.dead_time_s,
        rig.dt_s,
    );
    let dt = rig.dt_s;
    let roll_steps = (MASS_ROLL_S / dt).round() as usize;
    // Each phase at most a minute: the brake and drive phases end by speed.
    let max_steps = (60.0 / dt) as usize;
    let mut step_with = |rig: &mut Rig,
                         banks: &mut Vec<(LoopOn, f64, Bank)>,
                         brake: f64,
                         drive: f64|
     -> Result<(), WheelReproError> {
        let cmd = WheelCommand {
            brake_torque_n_m: [brake; CORNERS],
            drive_torque_n_m: drive,
        };
        let omega = rig.step(&cmd)?;
        let modelled = brakes.step(&cmd.brake_torque_n_m);
        let mut torques = modelled.map(|b| [b, 0.0]);
        for c in Corner::ALL {
            if c.is_front() {
                torques[c.index()][1] = 0.5 * drive;
            }
        }
        let mut demands = [[brake, 0.0]; CORNERS];
        for c in Corner::ALL {
            if c.is_front() {
                demands[c.index()][1] = 0.5 * drive;
            }
        }
        for (_, _, b) in banks.iter_mut() {
            b.step(&omega, &torques, &demands);
        }
        Ok(())
    };
    for _ in 0..MASS_EVENTS {
        let start = rig.plant.time_s();
        for _ in 0..max_steps {
            if rig.plant.speed_m_s() < MASS_LOW_M_S {
                break;
            }
            let ramp = ((rig.plant.time_s() - start) / PEDAL_RAMP_S + dt / PEDAL_RAMP_S).min(1.0);
            step_with(&mut rig, &mut banks, MASS_BRAKE_N_M * ramp, 0.0)?;
        }
        for _ in 0..roll_steps {
            step_with(&mut rig, &mut banks, 0.0, 0.0)?;
        }
        for _ in 0..max_steps {
            if rig.plant.speed_m_s() >= MASS_HIGH_M_S {
                break;
            }
            step_with(&mut rig, &mut banks, 0.0, MASS_DRIVE_N_M)?;
        }
        for _ in 0..roll_steps {
            step_with(&mut rig, &mut banks, 0.0, 0.0)?;
        }
        for (k, (_, _, b)) in banks.iter().enumerate() {
            after[k].push(judged.map(|c| b.state(c.index())[X_MASS]));
        }
    }
    let mut tracks = Vec::new();
    for (k, (kind, m0, _)) in banks.iter().enumerate() {
        for (j, c) in judged.iter().enumerate() {
            let series: Vec<f64> = after[k].iter().map(|x| x[j]).collect();
            let inside = |m: f64| (m / TRUE_QUARTER_MASS_KG - 1.0).abs() <= MASS_BAND;
            let last_out = series.iter().rposition(|&m| !inside(m));
            let events_to_band = match last_out {
                None => Some(1),
                Some(i) if i + 1 < series.len() => Some(i + 2),
                Some(_) => None,
            };
            tracks.push(MassTrack {
                estimator: *kind,
                start_kg: *m0,
                corner: c.name(),
                after_limit_kg: series
                    .get(MASS_EVENT_LIMIT - 1)
                    .copied()
                    .unwrap_or(f64::NAN),
                after_event_kg: series,
                events_to_band,
            });
        }
    }
    Ok(MassRun {
        seed,
        tracks,
        true_quarter_mass_kg: TRUE_QUARTER_MASS_KG,
        brake_torque_gain: car(file, seed).brakes.torque_gain,
        refused_steps: banks.iter().map(|(_, _, b)| b.refused).sum(),
    })
}

/// Settings.
#[derive(Debug, Clone, Default)]
pub struct WheelSettings {
    /// The quarter car's parameter file (default: the embedded `config/wheel.toml`).
    pub params: Option<PathBuf>,
    /// If set, the samples of the 20 m/s stops of the first held-out car (with `tuning_only`
    /// the first tuning car) are written here as CSV, one file per surface and loop.
    pub series: Option<PathBuf>,
    /// Run only the tuning cases.
    pub tuning_only: bool,
    /// Held-out initial speeds to run (m/s; None: the protocol's [`SPEEDS_M_S`]). A subset
    /// gives the same figures for its cases as the whole set (every case is simulated on its
    /// own); the tests use one to stay fast.
    pub held_out_speeds_m_s: Option<Vec<f64>>,
    /// Held-out cars to run (None: the protocol's [`HELD_OUT_SEEDS`]), for stops and the mass
    /// experiment.
    pub held_out_seeds: Option<Vec<u64>>,
}

/// The report.
#[derive(Debug, Clone, Serialize)]
pub struct WheelReport {
    /// Whether only the tuning cases were run.
    pub tuning_only: bool,
    /// Tuning rows.
    pub tuning: Vec<StopRow>,
    /// Held-out rows.
    pub held_out: Vec<StopRow>,
    /// Mass experiment, tuning car.
    pub mass_tuning: Vec<MassRun>,
    /// Mass experiment, held-out cars.
    pub mass_held_out: Vec<MassRun>,
    /// The line on the held-out cases.
    pub verdict: Verdict,
    /// The held-out cars run.
    pub held_out_seeds: Vec<u64>,
    /// The held-out initial speeds run (m/s).
    pub held_out_speeds_m_s: Vec<f64>,
    /// fdd's estimator settings used.
    #[serde(skip)]
    pub estimator: Option<WheelEstimatorParams>,
}

/// One surface's held-out figures for the line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SurfaceVerdict {
    /// Surface name.
    pub surface: &'static str,
    /// Per estimator ([`ESTIMATORS`] order), in the loop: the latest mu time over the
    /// surface's held-out stops (None: some stop never).
    pub mu_time_s: [Option<f64>; 2],
    /// The same beside the loop on the truth.
    pub mu_time_beside_truth_s: [Option<f64>; 2],
    /// Per estimator, in the loop: the largest ratio of a row's slip RMSE to its raw slip's.
    pub slip_ratio: [f64; 2],
}

impl SurfaceVerdict {
    /// fdd's estimator meets the mu line on this surface (in the loop).
    pub fn mu_met(&self) -> bool {
        self.mu_time_s[1].is_some_and(|t| t <= 0.5)
    }

    /// fdd's estimator meets the slip line on this surface (in the loop).
    pub fn slip_met(&self) -> bool {
        self.slip_ratio[1] <= 0.5
    }
}

/// One estimator's mass figures from one start over the held-out cars (rear left).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MassVerdict {
    /// The estimator.
    pub estimator: LoopOn,
    /// Initial mass (kg).
    pub start_kg: f64,
    /// The most events to the band over the cars (None: some car not by the last event).
    pub events_to_band: Option<usize>,
    /// The least and the largest estimate after [`MASS_EVENT_LIMIT`] events over the cars
    /// (kg).
    pub after_limit_kg: (f64, f64),
}

impl MassVerdict {
    /// Within 5 % within the 10 events on every car.
    pub fn met(&self) -> bool {
        self.events_to_band.is_some_and(|e| e <= MASS_EVENT_LIMIT)
    }
}

/// The line, judged on the held-out cases.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verdict {
    /// Per surface.
    pub surfaces: Vec<SurfaceVerdict>,
    /// Per estimator and start.
    pub mass: Vec<MassVerdict>,
}

/// Stop jobs: (row key, case, loop) for the given surfaces, speeds and cars.
fn stop_jobs(surfaces: &[Surface], speeds: &[f64], seeds: &[u64]) -> Vec<(StopCase, LoopOn)> {
    let mut jobs = Vec::new();
    for &surface in surfaces {
        for &v0 in speeds {
            for &seed in seeds {
                for l in [LoopOn::Truth, LoopOn::Tutorial, LoopOn::Fdd] {
                    jobs.push((
                        StopCase {
                            surface,
                            v0_m_s: v0,
                            seed,
                        },
                        l,
                    ));
                }
            }
        }
    }
    jobs
}

/// Runs `f` over `items` on the machine's threads, results in the items' order.
fn parallel<T: Sync, R: Send>(
    items: &[T],
    f: impl Fn(&T) -> Result<R, WheelReproError> + Sync,
) -> Result<Vec<R>, WheelReproError> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(items.len().max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut slots: Vec<Option<Result<R, WheelReproError>>> = Vec::new();
    slots.resize_with(items.len(), || None);
    let slots = std::sync::Mutex::new(slots);
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if k >= items.len() {
                    break;
                }
                let r = f(&items[k]);
                if let Ok(mut g) = slots.lock() {
                    g[k] = Some(r);
                }
            });
        }
    });
    let slots = slots.into_inner().unwrap_or_else(|e| e.into_inner());
    slots
        .into_iter()
        .map(|r| r.unwrap_or(Err(WheelReproError::Worker)))
        .collect()
}

/// Groups stop runs into rows (one per surface, speed and estimator).
fn rows(runs: &[StopRun], v_off: f64) -> Vec<StopRow> {
    let mut out: Vec<StopRow> = Vec::new();
    let mut keys: Vec<(Surface, u64)> = Vec::new();
    for r in runs {
        let key = (r.case.surface, r.case.v0_m_s.to_bits());
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    for (surface, v0_bits) in keys {
        let v0 = f64::from_bits(v0_bits);
        let of = |l: LoopOn| {
            runs.iter()
                .filter(move |r| r.case.surface == surface && r.case.v0_m_s == v0 && r.loop_on == l)
                .collect::<Vec<_>>()
        };
        let truth = of(LoopOn::Truth);
        let d_true = truth.iter().map(|r| r.distance_m).sum::<f64>() / truth.len().max(1) as f64;
        for (k, l) in ESTIMATORS.into_iter().enumerate() {
            let rs = of(l);
            out.push(StopRow {
                surface: surface.name(),
                v0_m_s: v0,
                estimator: l,
                seeds: rs.iter().map(|r| r.case.seed).collect(),
                in_loop: Summary::of(rs.iter().map(|r| stop_figures(r, k, v_off)).collect()),
                beside_truth: Summary::of(
                    truth.iter().map(|r| stop_figures(r, k, v_off)).collect(),
                ),
                distance_true_slip_m: d_true,
            });
        }
    }
    out
}

fn verdict(held: &[StopRow], mass: &[MassRun]) -> Verdict {
    let latest = |rs: &[&StopRow], beside: bool| {
        rs.iter().try_fold(0.0f64, |acc, r| {
            let t = if beside {
                r.beside_truth.mu_time_s
            } else {
                r.in_loop.mu_time_s
            };
            t.map(|t| acc.max(t))
        })
    };
    let mut surfaces = Vec::new();
    for s in Surface::ALL {
        let of = |l: LoopOn| -> Vec<&StopRow> {
            held.iter()
                .filter(|r| r.surface == s.name() && r.estimator == l)
                .collect()
        };
        let rows = ESTIMATORS.map(of);
        if rows.iter().any(|r| r.is_empty()) {
            continue;
        }
        surfaces.push(SurfaceVerdict {
            surface: s.name(),
            mu_time_s: [latest(&rows[0], false), latest(&rows[1], false)],
            mu_time_beside_truth_s: [latest(&rows[0], true), latest(&rows[1], true)],
            slip_ratio: rows.map(|rs| {
                rs.iter()
                    .map(|r| r.in_loop.slip_rmse / r.in_loop.raw_slip_rmse)
                    .fold(0.0, f64::max)
            }),
        });
    }
    let mut out = Vec::new();
    if !mass.is_empty() {
        for l in ESTIMATORS {
            for m0 in MASS_STARTS_KG {
                let tracks: Vec<&MassTrack> = mass
                    .iter()
                    .flat_map(|m| m.tracks.iter())
                    .filter(|t| {
                        t.estimator == l && t.start_kg == m0 && t.corner == Corner::RearLeft.name()
                    })
                    .collect();
                out.push(MassVerdict {
                    estimator: l,
                    start_kg: m0,
                    events_to_band: tracks
                        .iter()
                        .try_fold(0usize, |acc, t| t.events_to_band.map(|e| acc.max(e))),
                    after_limit_kg: tracks.iter().fold((f64::INFINITY, 0.0f64), |acc, t| {
                        (acc.0.min(t.after_limit_kg), acc.1.max(t.after_limit_kg))
                    }),
                });
            }
        }
    }
    Verdict {
        surfaces,
        mass: out,
    }
}

/// Runs the reproduction.
pub fn run(s: &WheelSettings) -> Result<WheelReport, WheelReproError> {
    let filters = WheelFilters::load(s.params.as_deref())?;
    let file = WheelPlantFile::committed()?;
    let v_off = file.slip_control.min_speed_m_s;
    let tuning_jobs = stop_jobs(&TUNING_SURFACES, &[TUNING_SPEED_M_S], &TUNING_SEEDS);
    let held_speeds = s
        .held_out_speeds_m_s
        .clone()
        .unwrap_or_else(|| SPEEDS_M_S.to_vec());
    let held_seeds = s
        .held_out_seeds
        .clone()
        .unwrap_or_else(|| HELD_OUT_SEEDS.to_vec());
    let held_jobs = if s.tuning_only {
        Vec::new()
    } else {
        stop_jobs(&Surface::ALL, &held_speeds, &held_seeds)
    };
    let mass_seeds: Vec<(bool, u64)> = std::iter::once((true, MASS_TUNING_SEED))
        .chain(
            held_seeds
                .iter()
                .filter(|_| !s.tuning_only)
                .map(|&k| (false, k)),
        )
        .collect();
    // Longest jobs first keeps both threads busy to the end.
    enum Job {
        Stop(StopCase, LoopOn, bool),
        Mass(u64, bool),
    }
    enum Done {
        Stop(Box<StopRun>, bool),
        Mass(MassRun, bool),
    }
    let mut jobs: Vec<Job> = Vec::new();
    for &(seed_tuning, seed) in &mass_seeds {
        jobs.push(Job::Mass(seed, seed_tuning));
    }
    let mut stops: Vec<(StopCase, LoopOn, bool)> = tuning_jobs
        .iter()
        .map(|&(c, l)| (c, l, true))
        .chain(held_jobs.iter().map(|&(c, l)| (c, l, false)))
        .collect();
    // Slow surfaces and high speeds first (an ice stop from 30 m/s is the longest).
    stops.sort_by(|a, b| {
        let cost = |c: &StopCase| c.v0_m_s / (0.1 + file.plant().surfaces.get(c.surface).c1);
        cost(&b.0).total_cmp(&cost(&a.0))
    });
    jobs.extend(stops.into_iter().map(|(c, l, t)| Job::Stop(c, l, t)));
    let done = parallel(&jobs, |j| match *j {
        Job::Stop(c, l, t) => Ok(Done::Stop(
            Box::new(simulate_stop(&filters, &file, c, l)?),
            t,
        )),
        Job::Mass(seed, t) => Ok(Done::Mass(mass_experiment(&filters, &file, seed)?, t)),
    })?;
    let mut tuning_runs = Vec::new();
    let mut held_runs = Vec::new();
    let mut mass_tuning = Vec::new();
    let mut mass_held_out = Vec::new();
    for d in done {
        match d {
            Done::Stop(r, true) => tuning_runs.push(*r),
            Done::Stop(r, false) => held_runs.push(*r),
            Done::Mass(m, true) => mass_tuning.push(m),
            Done::Mass(m, false) => mass_held_out.push(m),
        }
    }
    // Rows in the protocol's order (surface, speed, seed), whatever order the jobs ran in.
    let order = |runs: &mut Vec<StopRun>| {
        runs.sort_by(|a, b| {
            filter_surface(a.case.surface)
                .cmp(&filter_surface(b.case.surface))
                .then(a.case.v0_m_s.total_cmp(&b.case.v0_m_s))
                .then(a.case.seed.cmp(&b.case.seed))
                .then(a.loop_on.cmp(&b.loop_on))
        });
    };
    order(&mut tuning_runs);
    order(&mut held_runs);
    mass_held_out.sort_by_key(|m| m.seed);
    if let Some(dir) = &s.series {
        let (runs, seed) = if s.tuning_only {
            (&tuning_runs, TUNING_SEEDS[0])
        } else {
            (
                &held_runs,
                held_seeds.first().copied().unwrap_or(HELD_OUT_SEEDS[0]),
            )
        };
        for r in runs
            .iter()
            .filter(|r| r.case.seed == seed && r.case.v0_m_s == TUNING_SPEED_M_S)
        {
            write_series(dir, r)?;
        }
    }
    let tuning = rows(&tuning_runs, v_off);
    let held_out = rows(&held_runs, v_off);
    let verdict = verdict(&held_out, &mass_held_out);
    Ok(WheelReport {
        tuning_only: s.tuning_only,
        tuning,
        held_out,
        mass_tuning,
        mass_held_out,
        verdict,
        held_out_seeds: if s.tuning_only {
            Vec::new()
        } else {
            held_seeds
        },
        held_out_speeds_m_s: if s.tuning_only {
            Vec::new()
        } else {
            held_speeds
        },
        estimator: Some(filters.estimator),
    })
}

fn write_series(dir: &Path, r: &StopRun) -> Result<(), WheelReproError> {
    use std::fmt::Write;
    std::fs::create_dir_all(dir).map_err(|source| WheelReproError::Write {
        file: dir.to_path_buf(),
        source,
    })?;
    let name = match r.loop_on {
        LoopOn::Truth => "true_slip",
        LoopOn::Tutorial => "tutorial",
        LoopOn::Fdd => "fdd",
    };
    let path = dir.join(format!(
        "wheel_stop_{}_{}ms_car{}_{name}.csv",
        r.case.surface.name(),
        r.case.v0_m_s,
        r.case.seed
    ));
    let mut text = String::from("t_s,v_true_m_s");
    for c in Corner::ALL {
        let n = c.name();
        let _ = write!(
            text,
            ",{n}_slip_true,{n}_mu_true,{n}_quarter_mass_true_kg,{n}_omega_meas_rad_s,{n}_slip_raw,{n}_brake_cmd_n_m"
        );
        for e in ESTIMATORS {
            let k = match e {
                LoopOn::Fdd => "fdd",
                _ => "tutorial",
            };
            let _ = write!(
                text,
                ",{n}_{k}_v_m_s,{n}_{k}_slip,{n}_{k}_mu,{n}_{k}_mass_kg"
            );
        }
    }
    text.push('\n');
    for s in &r.samples {
        let _ = write!(text, "{},{}", s.t_s, s.v_m_s);
        for i in 0..CORNERS {
            let _ = write!(
                text,
                ",{},{},{},{},{},{}",
                s.slip[i],
                s.mu[i],
                s.quarter_mass_kg[i],
                s.omega_meas_rad_s[i],
                s.raw_slip[i],
                s.brake_cmd_n_m[i],
            );
            for e in &s.est {
                let _ = write!(text, ",{},{},{},{}", e[i][0], e[i][1], e[i][2], e[i][3]);
            }
        }
        text.push('\n');
    }
    std::fs::write(&path, text).map_err(|source| WheelReproError::Write { file: path, source })
}

fn seconds(t: Option<f64>) -> String {
    t.map_or_else(|| "never".to_string(), |t| format!("{t:.3} s"))
}

fn time_cell(t: Option<f64>) -> String {
    t.map_or_else(|| "never".to_string(), |t| format!("{t:.3}"))
}

fn stop_table(s: &mut String, title: &str, rows: &[StopRow]) {
    use std::fmt::Write;
    let _ = writeln!(s, "{title}");
    let _ = writeln!(
        s,
        "{:<5} {:>3} {:<9} | {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} | {:>7} {:>7} {:>7} {:>7} | {:>7}",
        "", "", "", "in the", "loop", "", "", "", "", "", "beside", "a loop", "on the", "truth", "",
    );
    let _ = writeln!(
        s,
        "{:<5} {:>3} {:<9} | {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} | {:>7} {:>7} {:>7} {:>7} | {:>7}",
        "surf",
        "v0",
        "estimator",
        "v RMSE",
        "slip",
        "raw",
        "mu",
        "mu t s",
        "stop m",
        "refused",
        "v RMSE",
        "slip",
        "mu",
        "mu t s",
        "true m",
    );
    for r in rows {
        let (a, b) = (&r.in_loop, &r.beside_truth);
        let _ = writeln!(
            s,
            "{:<5} {:>3.0} {:<9} | {:>7.3} {:>7.4} {:>7.4} {:>7.4} {:>7} {:>7.2} {:>7} | {:>7.3} {:>7.4} {:>7.4} {:>7} | {:>7.2}{}",
            r.surface,
            r.v0_m_s,
            r.estimator.name(),
            a.v_rmse_m_s,
            a.slip_rmse,
            a.raw_slip_rmse,
            a.mu_rmse,
            time_cell(a.mu_time_s),
            a.distance_m,
            a.refused_steps,
            b.v_rmse_m_s,
            b.slip_rmse,
            b.mu_rmse,
            time_cell(b.mu_time_s),
            r.distance_true_slip_m,
            if a.not_stopped + b.not_stopped > 0 {
                format!("  ({} not stopped)", a.not_stopped + b.not_stopped)
            } else {
                String::new()
            }
        );
    }
}

fn mass_table(s: &mut String, title: &str, runs: &[MassRun]) {
    use std::fmt::Write;
    let _ = writeln!(s, "{title}");
    let _ = writeln!(
        s,
        "{:<5} {:<10} {:<6} {:>8} {:>16} {:>15} {:>12}  estimate after each event (kg)",
        "car", "estimator", "corner", "start kg", "events to +-5 %", "after 10 (kg)", "brake gain"
    );
    for m in runs {
        for t in &m.tracks {
            let series: Vec<String> = t.after_event_kg.iter().map(|x| format!("{x:.0}")).collect();
            let _ = writeln!(
                s,
                "{:<5} {:<10} {:<6} {:>8.0} {:>16} {:>15.1} {:>12.4}  {}",
                m.seed,
                t.estimator.name(),
                t.corner,
                t.start_kg,
                t.events_to_band
                    .map_or_else(|| format!("not by {MASS_EVENTS}"), |e| e.to_string()),
                t.after_limit_kg,
                m.brake_torque_gain,
                series.join(" ")
            );
        }
    }
}

/// The report as text.
pub fn render(r: &WheelReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Slip-controlled stops (tutorial seeds/002): truth = fdd's whole car, {TOTAL_MASS_KG:.0} kg, front share {FRONT_STATIC_SHARE}, cg {CG_HEIGHT_M} m, wheelbase {WHEELBASE_M} m, every key perturbed +-{:.0} %; demand {DEMAND_N_M:.0} N m per corner from {ONSET_S} s; RMSEs pooled over the corners from the onset to 2 m/s, mean over the cars; mu time = latest over corners and cars (20 ms mean of |mu error| <= {MU_BAND} from then on)",
        PARAM_REL_ERROR * 100.0
    );
    if let Some(e) = &r.estimator {
        let _ = writeln!(
            s,
            "fdd's [estimator]: friction_pull {}, rolling_torque_nm {}, process_noise {:?}, measurement_variance_rad2_s2 {}, initial_variance {:?}, rolling_slip_std {}",
            e.friction_pull,
            e.rolling_torque_nm,
            e.process_noise,
            e.measurement_variance_rad2_s2,
            e.initial_variance,
            e.rolling_slip_std
        );
    }
    stop_table(
        &mut s,
        &format!("tuning: {TUNING_SPEED_M_S:.0} m/s on dry and snow, cars {TUNING_SEEDS:?}"),
        &r.tuning,
    );
    if !r.tuning_only {
        stop_table(
            &mut s,
            &format!(
                "held-out: cars {:?}, {:?} m/s",
                r.held_out_seeds, r.held_out_speeds_m_s
            ),
            &r.held_out,
        );
    }
    mass_table(
        &mut s,
        &format!(
            "mass (dry; events: brake {MASS_BRAKE_N_M:.0} N m per corner {MASS_HIGH_M_S:.0} -> {MASS_LOW_M_S:.0} m/s, roll {MASS_ROLL_S} s, drive {MASS_DRIVE_N_M:.0} N m back, roll {MASS_ROLL_S} s; true quarter mass {TRUE_QUARTER_MASS_KG:.0} kg), tuning car"
        ),
        &r.mass_tuning,
    );
    if !r.tuning_only {
        mass_table(&mut s, "mass, held-out cars", &r.mass_held_out);
        let v = &r.verdict;
        let met = |m: bool| if m { "met" } else { "NOT met" };
        let _ = writeln!(
            s,
            "issue 14 on the held-out cases (in the loop; beside the loop on the truth in brackets):"
        );
        for sv in &v.surfaces {
            let _ = writeln!(
                s,
                "  {:<5} fdd: mu within {MU_BAND} after {} ({}) [{}], slip RMSE up to {:.2} x the raw slip's ({}); tutorial: {} [{}], {:.2} x",
                sv.surface,
                seconds(sv.mu_time_s[1]),
                met(sv.mu_met()),
                seconds(sv.mu_time_beside_truth_s[1]),
                sv.slip_ratio[1],
                met(sv.slip_met()),
                seconds(sv.mu_time_s[0]),
                seconds(sv.mu_time_beside_truth_s[0]),
                sv.slip_ratio[0],
            );
        }
        for mv in &v.mass {
            let _ = writeln!(
                s,
                "  mass, {} from {:.0} kg (rear left, every car): within 5 % {}{}; after 10 events {:.0}-{:.0} kg",
                mv.estimator.name(),
                mv.start_kg,
                mv.events_to_band
                    .map_or_else(
                        || format!("not by event {MASS_EVENTS}"),
                        |e| format!("from event {e} on (at most)"),
                    ),
                if mv.estimator == LoopOn::Fdd {
                    format!(" ({})", met(mv.met()))
                } else {
                    String::new()
                },
                mv.after_limit_kg.0,
                mv.after_limit_kg.1,
            );
        }
    }
    s
}
