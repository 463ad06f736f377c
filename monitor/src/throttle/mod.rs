//! The electronic-throttle monitor: residual generators on the throttle model, tests on their
//! innovations and on the raw position-sensor (TPS) signal, fault isolation, DTCs, and a
//! position output that survives a TPS failure by switching to the wattmeter-only estimate.
//!
//! Residual generators (UKF-AHSM on the model of `fdd_estimators::models::throttle`):
//! - the **TPS filter**: model + TPS only. Its innovations say whether the TPS moves the way
//!   the model, driven by the motor voltage, says the plate moves;
//! - the **combined filter**: model + TPS + wattmeter, updated with only the measurements that
//!   are currently trusted (`update_subset`). Its wattmeter innovation says whether the current
//!   the wattmeter sees fits the TPS angle; once the TPS is failed it runs on the wattmeter
//!   alone and is the fallback position estimate (re-seeded at the static map if it loses
//!   track, as in the Table II reproduction);
//! - the **wattmeter-only filter**: model + wattmeter, never the TPS. Its innovation is a
//!   wattmeter residual that no TPS fault can move: the combined filter's is pulled by a
//!   drifting TPS (it follows the TPS angle, and the current it predicts for that angle misses
//!   the wattmeter), so it tells the two apart, and it keeps the wattmeter tested after a TPS
//!   fault.
//!
//! Tests: a jump/noise test (windowed sum of capped TPS NIS), a CUSUM on the TPS filter's
//! normalized innovation, a step test (the TPS change over a few samples against the model's
//! predicted change, [`step_test`]), CUSUMs on the combined and the wattmeter-only filters'
//! wattmeter innovations, rail
//! checks that judge a TPS reading at 0 V / 5 V against the model (a closed plate also reads
//! 0 V), a frozen-signal check, and a "static while driven" check for the plate. Every TPS test
//! allows for a sensor lag (`tps_lag_tolerance_s`) and for a mode switch of the identified model
//! one step early or late; the wattmeter test for a gain tolerance and a lag.
//!
//! Decision: an open circuit / short is a rail reading the model calls implausible that lasts
//! `rail_persist_s`; shorter episodes are dropouts, and `intermittent_count` of them within
//! `intermittent_window_s` make an intermittent circuit. A TPS frozen while the voltage should
//! move the plate by `frozen_driven_range_deg`, for `plate_persist_s`, or frozen for
//! `frozen_alone_samples` readings, is a stuck TPS (P0121); a
//! TPS static (not frozen) while driven by `driven_range_deg`, as long, is a stuck plate
//! (P2119). When a residual test fails, the monitor waits
//! `decision_window_s` for the other tests (and for the plate test while it is counting), then
//! names the fault: frozen TPS -> TPS stuck; only the combined wattmeter test, confirmed
//! `watt_confirm_alarms` times within `watt_confirm_s`, and the wattmeter-only test alarming
//! too -> wattmeter (P1651, manufacturer code); the combined wattmeter test alarming
//! `drift_confirm_alarms` times, the wattmeter-only test quiet and the TPS away from the
//! wattmeter-only angle (judged on at least `DRIFT_SIGMA_FLOOR_DEG` of that filter's spread,
//! not on the open stop) -> TPS range/performance (a drift); a TPS test -> TPS range/performance (P0121). With the TPS
//! failed, the wattmeter-only test alone names a wattmeter fault, if still alarming after twice
//! `watt_confirm_s` (model error fails it in bursts). An open or short circuit heals on readings
//! off the rails, or on rail readings the wattmeter estimate cannot rule out (not the model
//! alone).
//!
//! Recovery policy: decisions are per component (TPS, wattmeter, plate), and each removes from
//! use only what it makes untrustworthy. From the step a TPS fault is qualified, the position
//! output comes from the wattmeter estimate (`source = "wattmeter_estimate"`) and the switch is
//! reported as an event; the TPS filter keeps running on the sensor so that its tests see it
//! heal. A component whose tests pass for `heal_s` is healthy again (a range/performance fault
//! also needs the TPS to agree with the wattmeter estimate). A wattmeter or plate fault never
//! switches the output (the TPS stays the source).

pub mod config;
mod map_check;
mod span_window;
pub mod step_test;
mod still_run;

use fdd_diagnostics::detectors::{two_sided_arl, Cusum, CusumConfig};
use fdd_diagnostics::{TestResult, Verdict};
use fdd_estimators::models::throttle::{
    PositionAndWattmeter, PositionSensor, ThrottleModel, Wattmeter,
};
use fdd_estimators::reacquire::Reacquire;
use fdd_estimators::{NoiseLevel, SigmaPoints, Ukf};
use nalgebra::{Matrix1, Matrix2, Matrix3, Vector1, Vector2, Vector3};

pub use config::ThrottleMonitorConfig;
use map_check::MapCheck;
use span_window::SpanWindow;
use step_test::{StepTest, StepTestConfig};
use still_run::StillRun;

use crate::config_key::KeyPath;
use crate::monitor::{Monitor, Output, OutputSink};
use crate::monitor_events::{EventSpec, FreezeValues, MonitorEvents};
use crate::signal_table::{SignalId, SignalTable};

/// The least spread (deg) of the wattmeter-only filter's angle that the drift rule judges the
/// TPS against: resting on a stop in its model, that filter's covariance collapses to a few
/// tenths of a degree although the model's static map is degrees off near the stops.
const DRIFT_SIGMA_FLOOR_DEG: f64 = 3.0;
/// How many standard deviations of a window mean the wattmeter-only filter's innovation must
/// exceed the static map's residual by before the filter is re-seeded at the map.
const MAP_CHECK_SIGMA: f64 = 5.0;
/// The map check's window and settle (readings) and the voltage change that ends a hold (V).
const MAP_CHECK_WINDOW: u32 = 200;
const MAP_CHECK_SETTLE: u32 = 200;
const MAP_CHECK_STEADY_V: f64 = 0.01;
/// A filter whose angle stays within this many degrees of a mode boundary for `TRAP_STEPS`
/// while the static map is far above is held there by the model, not by the plate.
const TRAP_BAND_DEG: f64 = 5.0;
const TRAP_STEPS: u32 = 300;
/// Capacity of the fixed rings (NIS window, motion window, dropout times).
pub(crate) const RING: usize = 512;
/// Time constant of the low-pass through which the TPS's standing still across holds is
/// judged (s): 20 readings average 10 mV of noise down to 0.04 deg.
const STILL_TPS_TAU_S: f64 = 0.02;
/// Steps between updates of the filters' `R` from the noise estimates.
const NOISE_UPDATE_STEPS: u32 = 64;

/// The faults the monitor names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ThrottleFault {
    TpsOpen,
    TpsShort,
    TpsIntermittent,
    TpsStuck,
    TpsPerformance,
    PlateStuck,
    Wattmeter,
}

impl ThrottleFault {
    /// Name used as the isolation candidate in events.
    pub fn name(self) -> &'static str {
        FAULT_CLASSES[self.class()]
    }

    /// Index into [`FAULT_CLASSES`] (the order of the diagnosis scores).
    pub fn class(self) -> usize {
        match self {
            ThrottleFault::TpsOpen => 0,
            ThrottleFault::TpsShort => 1,
            ThrottleFault::TpsIntermittent => 2,
            ThrottleFault::TpsStuck => 3,
            ThrottleFault::TpsPerformance => 4,
            ThrottleFault::PlateStuck => 5,
            ThrottleFault::Wattmeter => 6,
        }
    }

    /// True for the faults of the position sensor (they switch the position output).
    pub fn is_tps(self) -> bool {
        !matches!(self, ThrottleFault::PlateStuck | ThrottleFault::Wattmeter)
    }

    /// Index of the DTC event (see [`EVENT_NAMES`]).
    fn event(self) -> usize {
        match self {
            ThrottleFault::TpsOpen => 0,
            ThrottleFault::TpsShort => 1,
            ThrottleFault::TpsStuck | ThrottleFault::TpsPerformance => 2,
            ThrottleFault::TpsIntermittent => 3,
            ThrottleFault::PlateStuck => 4,
            ThrottleFault::Wattmeter => 5,
        }
    }
}

/// The fault classes of the monitor's diagnosis output ([`ThrottleFault::name`], in the order
/// of [`ThrottleFault::class`]).
pub const FAULT_CLASSES: [&str; 7] = [
    "tps_open_circuit",
    "tps_short_circuit",
    "tps_intermittent",
    "tps_stuck",
    "tps_range_performance",
    "plate_stuck",
    "wattmeter",
];

/// A fault decided for one component, and the test result that qualified it (reported with
/// its DTC's events).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decided {
    pub fault: ThrottleFault,
    pub result: TestResult,
    /// When it was decided (s).
    pub since_s: f64,
}

/// Event names, in the order of the DTC settings. The last one is the switch of the position
/// output to the wattmeter estimate, reported as "forced limited power" (P2106 by default), so
/// the switch is itself a diagnostic event with a status byte.
pub const EVENT_NAMES: [&str; 7] = [
    "tps_circuit_low",
    "tps_circuit_high",
    "tps_range_performance",
    "tps_intermittent",
    "throttle_plate_stuck",
    "wattmeter_plausibility",
    "position_from_wattmeter",
];

/// Estimates the monitor offers to freeze frames: the position output (deg).
pub const ESTIMATES: [&str; 1] = ["throttle_angle"];

/// Index of the switch event in [`EVENT_NAMES`].
const SWITCH_EVENT: usize = 6;

/// Origin named by the errors of settings given to [`ThrottleMonitor::new`] directly (a
/// configuration file is checked, naming the file, when it is parsed:
/// [`crate::config::ThrottleConfig::parse`]).
pub const SETTINGS_ORIGIN: &str = "throttle monitor settings";

/// Errors building the monitor.
#[derive(Debug, thiserror::Error)]
pub enum ThrottleMonitorError {
    #[error("throttle monitor: signal `{0}` is not in the signal table")]
    MissingSignal(String),
    /// A setting out of its range ([`ThrottleMonitorConfig::validate`]).
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error("throttle monitor: invalid setting `{key}`: {reason}")]
    Setting { key: &'static str, reason: String },
    #[error("throttle monitor: {0}")]
    Filter(#[from] fdd_estimators::ConfigError),
    #[error("throttle monitor: {0}")]
    Diagnostics(#[from] fdd_diagnostics::ConfigError),
}

fn setting(key: &'static str, reason: impl Into<String>) -> ThrottleMonitorError {
    ThrottleMonitorError::Setting {
        key,
        reason: reason.into(),
    }
}

/// Fixed-capacity ring of recent values.
#[derive(Debug, Clone)]
struct Ring {
    buf: [f64; RING],
    len: usize,
    cap: usize,
    head: usize,
}

impl Ring {
    fn new(cap: usize) -> Self {
        Self {
            buf: [0.0; RING],
            len: 0,
            cap: cap.clamp(1, RING),
            head: 0,
        }
    }
    /// Pushes `v`, returning the value that fell out, if the ring was full.
    fn push(&mut self, v: f64) -> Option<f64> {
        let out = if self.len == self.cap {
            Some(self.buf[self.head])
        } else {
            None
        };
        self.buf[self.head] = v;
        self.head = (self.head + 1) % self.cap;
        self.len = (self.len + 1).min(self.cap);
        out
    }
    fn full(&self) -> bool {
        self.len == self.cap
    }
    fn span(&self) -> f64 {
        let s = &self.buf[..self.len];
        let (lo, hi) = s
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        hi - lo
    }
    fn last(&self) -> Option<f64> {
        (self.len > 0).then(|| self.buf[(self.head + self.cap - 1) % self.cap])
    }
    fn clear(&mut self) {
        self.len = 0;
        self.head = 0;
    }
}

/// The monitor. Everything is sized at construction; a step without a status change allocates
/// nothing.
pub struct ThrottleMonitor {
    cfg: ThrottleMonitorConfig,
    model: ThrottleModel,
    inputs: [SignalId; 3],
    period_ns: u64,
    volts_per_deg: f64,
    p0: Matrix3<f64>,
    tps_ukf: Ukf<ThrottleModel, PositionSensor, 3, 1, 1, 7>,
    both_ukf: Ukf<ThrottleModel, PositionAndWattmeter, 3, 2, 1, 7>,
    tps_ukf_init: Ukf<ThrottleModel, PositionSensor, 3, 1, 1, 7>,
    both_ukf_init: Ukf<ThrottleModel, PositionAndWattmeter, 3, 2, 1, 7>,
    /// A filter fed by the wattmeter alone, never the TPS: its innovation is a wattmeter residual
    /// that a TPS fault cannot move (the combined filter's is pulled by a drifting TPS).
    watt_ukf: Ukf<ThrottleModel, Wattmeter, 3, 1, 1, 7>,
    watt_ukf_init: Ukf<ThrottleModel, Wattmeter, 3, 1, 1, 7>,
    reacquire: Reacquire,
    watt_reacquire: Reacquire,
    u_slow: f64,
    u_alpha: f64,
    nis_ring: Ring,
    nis_sum: f64,
    cusum_tps: Cusum,
    cusum_watt: Cusum,
    cusum_watt_only: Cusum,
    tps_hist: SpanWindow,
    eq_hist: SpanWindow,
    /// The TPS standing still across holds, and the static map's range meanwhile.
    still: StillRun,
    map_check: MapCheck,
    /// The same check on the combined filter while it runs without the TPS.
    map_check_both: MapCheck,
    /// Steps each filter has sat on a mode boundary far from the static map (see `trapped`).
    trap_run_wo: u32,
    trap_run_both: u32,
    rail_persist: u32,
    /// Samples in a row whose rail reading the wattmeter-only filter rules out, and how many
    /// make that a rail fault (`watt_rail_persist_s`).
    watt_rail_run: u32,
    watt_rail_persist: u32,
    /// Samples in a row in which the TPS disagrees with the wattmeter-only filter's angle
    /// (by more than `heal_agreement_deg` plus two of that filter's standard deviations, at
    /// least `DRIFT_SIGMA_FLOOR_DEG`; not on the open stop), and how many the drift rule needs
    /// (`decision_window_s`): that filter lags a fast plate move by up to about 0.15 s (a
    /// full-range swing onto the open stop, retired held-out version 5, log 53), and a
    /// disagreement that short is its lag, not the TPS's.
    disagree_run: u32,
    disagree_persist: u32,
    /// Samples in a row in which a failed TPS disagrees with the combined filter (which runs
    /// without it), for healing, and how many make a disagreement (`heal_disagreement_s`):
    /// a shorter one is that filter's lag behind a fast plate move, not a fault still there
    /// (tuning set, healing TPS faults: samples 15 to 20 deg off during moves kept healed
    /// TPSs failed for 30 to 40 s).
    heal_disagree_run: u32,
    heal_disagree_persist: u32,
    /// Samples in a row in which the TPS disagrees with the wattmeter-only filter's angle as
    /// the drift rule judges it (not on the open stop), whatever the wattmeter's state: a
    /// failed wattmeter heals only while that filter agrees with a trusted TPS.
    watt_heal_disagree_run: u32,
    rail_low_run: u32,
    rail_high_run: u32,
    /// A TPS circuit fault healed in this operation cycle on rail readings the estimate could
    /// not rule out (the plate near that stop): from then on the rail check also asks the
    /// wattmeter-only filter, since the combined filter that takes the TPS again would follow
    /// a line still open or shorted to its rail and never rule it out.
    rail_fault_healed: bool,
    dropouts: Ring,
    frozen_run: u32,
    /// Consecutive TPS readings at a rail (at or beyond `rail_low_v` / `rail_high_v`),
    /// ruled out or not.
    at_rail_run: u32,
    last_tps: f64,
    first_fail_s: Option<f64>,
    /// Residual tests that failed in this episode: TPS NIS window, TPS CUSUM, wattmeter
    /// CUSUM, TPS step (the wattmeter-only test's alarms are kept below).
    fired: [bool; 4],
    step_test: StepTest,
    /// Wattmeter test alarms in the current episode.
    watt_alarms: u32,
    /// Time of the latest wattmeter-only test alarm (s), and their count in the episode.
    last_watt_only_s: Option<f64>,
    watt_only_alarms: u32,
    /// The first failing residual test's result, kept through the decision window.
    first_result: TestResult,
    /// The fault decided per component (position sensor, wattmeter, plate): each removes from
    /// use only what it makes untrustworthy, and each heals on its own.
    tps_fault: Option<Decided>,
    watt_fault: Option<Decided>,
    plate_fault: Option<Decided>,
    /// Steps in a row that a failed component's tests have passed (TPS, wattmeter, plate).
    heal_run: [u32; 3],
    /// Steps of passing that heal a failed component.
    heal_steps: u32,
    /// Online estimates of the TPS and wattmeter noise variances (V^2, W^2), fed while nothing
    /// is failing, and the steps since they were last put into the filters.
    tps_noise: NoiseLevel,
    watt_noise: NoiseLevel,
    noise_steps: u32,
    /// The TPS filter's angle after its previous update (deg), for the predicted rate.
    last_theta_pred: f64,
    /// The wattmeter reading predicted at the previous step (W), for the predicted rate.
    last_predicted_w: f64,
    /// The same for the wattmeter-only filter (W).
    last_predicted_wo: f64,
    /// Debounce counter of the plate static while driven (steps): up one per step it holds,
    /// down one per step it does not; `plate_persist` makes it stuck.
    static_run: u32,
    /// Steps in a row the TPS has been frozen while the voltage should move the plate.
    frozen_driven_run: u32,
    plate_persist: u32,
    /// The diagnosis scores of the latest step (see [`Output::Diagnosis`]).
    scores: [f64; 7],
    events: MonitorEvents,
}

impl ThrottleMonitor {
    /// Builds the monitor for `model` reading the named signals of `table`.
    pub fn new(
        model: ThrottleModel,
        tps_full_scale_v: f64,
        tps_full_scale_deg: f64,
        cfg: &ThrottleMonitorConfig,
        table: &SignalTable,
    ) -> Result<Self, ThrottleMonitorError> {
        let id = |name: &str| {
            table
                .id(name)
                .ok_or_else(|| ThrottleMonitorError::MissingSignal(name.to_string()))
        };
        let inputs = [
            id(&cfg.motor_voltage_signal)?,
            id(&cfg.tps_signal)?,
            id(&cfg.wattmeter_signal)?,
        ];
        cfg.validate(&KeyPath::file(SETTINGS_ORIGIN).key("monitor"))?;
        let motion = (cfg.motion_window_s / cfg.period_s).round() as usize;
        let scale = model.params().angle_scale;
        let tps = PositionSensor::new(tps_full_scale_v, tps_full_scale_deg, scale);
        let both = PositionAndWattmeter { position: tps };
        let p0 = Matrix3::identity();
        let q = Matrix3::from_diagonal(&Vector3::new(3.15e-4, 1e-2, 1.62e-4));
        let rt = cfg.tps_noise_v * cfg.tps_noise_v;
        let rw = cfg.wattmeter_noise_w * cfg.wattmeter_noise_w + cfg.wattmeter_r_floor;
        let time_constant = (cfg.noise_time_constant_s / cfg.period_s).max(1.0);
        let settle = (cfg.noise_settle_s / cfg.period_s).round() as u64;
        let bounds = |key: &'static str, prior_std: f64, min_std: f64, max_std: f64| {
            NoiseLevel::new(
                prior_std * prior_std,
                min_std * min_std,
                max_std * max_std,
                time_constant,
                settle,
            )
            .ok_or_else(|| {
                setting(
                    key,
                    format!(
                        "the noise range [{min_std}, {max_std}] must be positive and contain the configured level"
                    ),
                )
            })
        };
        let tps_noise = bounds(
            "tps_noise_max_v",
            cfg.tps_noise_v,
            cfg.tps_noise_min_v,
            cfg.tps_noise_max_v,
        )?;
        let watt_noise = bounds(
            "wattmeter_noise_max_w",
            cfg.wattmeter_noise_w,
            cfg.wattmeter_noise_min_w,
            cfg.wattmeter_noise_max_w,
        )?;
        let tps_ukf = Ukf::new(
            model,
            tps,
            SigmaPoints::ahsm(12.0)?,
            Vector3::zeros(),
            p0,
            q,
            Matrix1::new(rt),
        )?;
        let both_ukf = Ukf::new(
            model,
            both,
            SigmaPoints::ahsm(12.0)?,
            Vector3::zeros(),
            p0,
            q,
            Matrix2::new(rt, 0.0, 0.0, rw),
        )?;
        let watt_ukf = Ukf::new(
            model,
            Wattmeter,
            SigmaPoints::ahsm(12.0)?,
            Vector3::zeros(),
            p0,
            q,
            Matrix1::new(cfg.fallback_r_scale * rw),
        )?;
        // Bias and threshold are checked by `validate` (each in its range, a finite run length).
        let cusum = |delta: f64, h: f64| -> Result<Cusum, ThrottleMonitorError> {
            let arl = two_sided_arl(0.0, delta / 2.0, h);
            Ok(Cusum::new(&CusumConfig {
                min_bias_sigma: delta,
                mean_steps_between_false_alarms: Some(arl),
                false_alarm_rate: None,
            })?)
        };
        let dtcs = [
            &cfg.dtc_tps_low,
            &cfg.dtc_tps_high,
            &cfg.dtc_tps_performance,
            &cfg.dtc_tps_intermittent,
            &cfg.dtc_plate_stuck,
            &cfg.dtc_wattmeter,
            &cfg.dtc_position_fallback,
        ];
        let specs: Vec<EventSpec<'_>> = EVENT_NAMES
            .iter()
            .zip(dtcs)
            .enumerate()
            .map(|(i, (name, dtc))| EventSpec::internal(name, dtc, if i < 4 { 2 } else { 3 }))
            .collect();
        let events = MonitorEvents::new(&specs)?.with_estimates(&ESTIMATES);
        Ok(Self {
            period_ns: (cfg.period_s * 1e9).round() as u64,
            volts_per_deg: tps_full_scale_v / tps_full_scale_deg,
            p0,
            tps_ukf_init: tps_ukf.clone(),
            both_ukf_init: both_ukf.clone(),
            watt_ukf_init: watt_ukf.clone(),
            tps_ukf,
            both_ukf,
            watt_ukf,
            reacquire: Reacquire::new(50.0, 2.0, 50)?,
            watt_reacquire: Reacquire::new(50.0, 2.0, 50)?,
            u_slow: 0.0,
            u_alpha: (cfg.period_s / 0.033).min(1.0),
            nis_ring: Ring::new(cfg.tps_nis_window),
            nis_sum: 0.0,
            cusum_tps: cusum(cfg.tps_cusum_min_bias_sigma, cfg.tps_cusum_threshold)?,
            cusum_watt: cusum(cfg.watt_cusum_min_bias_sigma, cfg.watt_cusum_threshold)?,
            cusum_watt_only: cusum(cfg.watt_cusum_min_bias_sigma, cfg.watt_only_cusum_threshold)?,
            tps_hist: SpanWindow::new(motion),
            eq_hist: SpanWindow::new(motion),
            map_check: MapCheck::new(MAP_CHECK_WINDOW, MAP_CHECK_SETTLE, MAP_CHECK_STEADY_V),
            map_check_both: MapCheck::new(MAP_CHECK_WINDOW, MAP_CHECK_SETTLE, MAP_CHECK_STEADY_V),
            trap_run_wo: 0,
            trap_run_both: 0,
            still: StillRun::new(
                cfg.static_tps_range_deg,
                STILL_TPS_TAU_S,
                cfg.period_s,
                motion as u64,
            ),
            rail_persist: ((cfg.rail_persist_s / cfg.period_s).round() as u32).max(1),
            watt_rail_run: 0,
            disagree_run: 0,
            heal_disagree_run: 0,
            watt_heal_disagree_run: 0,
            heal_disagree_persist: ((cfg.heal_disagreement_s / cfg.period_s).round() as u32).max(1),
            disagree_persist: ((cfg.decision_window_s / cfg.period_s).round() as u32).max(1),
            watt_rail_persist: ((cfg.watt_rail_persist_s / cfg.period_s).round() as u32).max(1),
            rail_low_run: 0,
            rail_high_run: 0,
            rail_fault_healed: false,
            dropouts: Ring::new(cfg.intermittent_count),
            frozen_run: 0,
            at_rail_run: 0,
            last_tps: f64::NAN,
            first_fail_s: None,
            fired: [false; 4],
            step_test: StepTest::new(StepTestConfig {
                sigma: cfg.tps_step_sigma,
                floor_v: cfg.tps_step_floor_v,
                motion_scale: cfg.tps_step_motion_scale,
            }),
            watt_alarms: 0,
            last_watt_only_s: None,
            watt_only_alarms: 0,
            first_result: TestResult::NOT_TESTED,
            tps_fault: None,
            watt_fault: None,
            plate_fault: None,
            heal_run: [0; 3],
            heal_steps: ((cfg.heal_s / cfg.period_s).round() as u32).max(1),
            last_theta_pred: f64::NAN,
            last_predicted_w: f64::NAN,
            last_predicted_wo: f64::NAN,
            tps_noise,
            watt_noise,
            noise_steps: 0,
            static_run: 0,
            frozen_driven_run: 0,
            plate_persist: ((cfg.plate_persist_s / cfg.period_s).round() as u32).max(1),
            scores: [0.0; 7],
            events,
            inputs,
            model,
            cfg: cfg.clone(),
        })
    }

    /// The faults decided and not healed: position sensor, wattmeter, plate.
    pub fn decided_faults(&self) -> impl Iterator<Item = ThrottleFault> + '_ {
        [self.tps_fault, self.watt_fault, self.plate_fault]
            .into_iter()
            .flatten()
            .map(|d| d.fault)
    }

    /// True while the TPS is failed and the output comes from the wattmeter estimate.
    pub fn on_wattmeter_estimate(&self) -> bool {
        self.tps_fault.is_some()
    }

    /// Reports every event's result (a failed one with the fault as its isolation candidate).
    fn report_all(
        &mut self,
        now_s: f64,
        results: &[TestResult; 7],
        values: FreezeValues<'_>,
        out: &mut OutputSink<'_>,
    ) {
        for (i, r) in results.iter().enumerate() {
            let fault = [self.tps_fault, self.watt_fault, self.plate_fault]
                .into_iter()
                .flatten()
                .find(|d| d.fault.event() == i || (i == SWITCH_EVENT && d.fault.is_tps()));
            let candidate = fault.map(|d| [(d.fault.name(), 1.0)]);
            let candidates: &[(&str, f64)] = match (&candidate, r.verdict) {
                (Some(c), Verdict::Failed) => c,
                _ => &[],
            };
            self.events.report_one(i, now_s, r, candidates, values, out);
        }
    }

    /// Restarts the fault decision and the filters, as at the start of an operation cycle
    /// (after a cycle start, or after a ClearDTC of this monitor's DTCs).
    fn restart(&mut self) {
        self.tps_ukf = self.tps_ukf_init.clone();
        self.both_ukf = self.both_ukf_init.clone();
        self.watt_ukf = self.watt_ukf_init.clone();
        self.map_check.clear();
        self.map_check_both.clear();
        self.trap_run_wo = 0;
        self.trap_run_both = 0;
        self.first_result = TestResult::NOT_TESTED;
        self.tps_fault = None;
        self.watt_fault = None;
        self.plate_fault = None;
        self.heal_run = [0; 3];
        self.static_run = 0;
        self.frozen_driven_run = 0;
        self.tps_noise.reset();
        self.last_theta_pred = f64::NAN;
        self.last_predicted_w = f64::NAN;
        self.last_predicted_wo = f64::NAN;
        self.watt_noise.reset();
        self.noise_steps = 0;
        self.end_episode();
        self.nis_ring.clear();
        self.nis_sum = 0.0;
        self.step_test.reset();
        self.dropouts.clear();
        self.last_watt_only_s = None;
        self.rail_low_run = 0;
        self.rail_high_run = 0;
        self.rail_fault_healed = false;
        self.watt_rail_run = 0;
        self.disagree_run = 0;
        self.heal_disagree_run = 0;
        self.watt_heal_disagree_run = 0;
    }

    /// Puts the noise estimates into the filters' `R` every [`NOISE_UPDATE_STEPS`] steps once
    /// settled (a new `R` is checked for definiteness: not worth doing every step).
    /// The learned levels (unbounded, standard deviations) go out as the estimates
    /// `tps_noise_std_v` (V) and `wattmeter_noise_std_w` (W), which `fdd calibrate` reads.
    fn apply_noise_levels(&mut self, out: &mut OutputSink<'_>) {
        self.noise_steps += 1;
        if self.noise_steps < NOISE_UPDATE_STEPS {
            return;
        }
        self.noise_steps = 0;
        for (name, est) in [
            ("tps_noise_std_v", &self.tps_noise),
            ("wattmeter_noise_std_w", &self.watt_noise),
        ] {
            if est.settled() {
                let v = est.unbounded().sqrt();
                out(Output::Estimate {
                    name,
                    value: v,
                    lower: v,
                    upper: v,
                    source: "online_estimate",
                });
            }
        }
        let rt = self.tps_noise.variance();
        let scale = if self.tps_fault.is_some() {
            self.cfg.fallback_r_scale
        } else {
            1.0
        };
        let rw = scale * self.watt_noise.variance() + self.cfg.wattmeter_r_floor;
        let _ = self.tps_ukf.set_measurement_noise(Matrix1::new(rt));
        let _ = self
            .both_ukf
            .set_measurement_noise(Matrix2::new(rt, 0.0, 0.0, rw));
        let rw_only =
            self.cfg.fallback_r_scale * self.watt_noise.variance() + self.cfg.wattmeter_r_floor;
        let _ = self.watt_ukf.set_measurement_noise(Matrix1::new(rw_only));
    }

    /// The estimated noise levels (standard deviations): TPS (V) and wattmeter (W, without the
    /// `wattmeter_r_floor`), as the filters use them now.
    pub fn noise_levels(&self) -> (f64, f64) {
        (
            self.tps_noise.variance().sqrt(),
            self.watt_noise.variance().sqrt(),
        )
    }

    /// The TPS has not moved by `static_tps_range_deg` over the motion window while the
    /// applied voltage should have moved the plate: its static map spanned more than
    /// `driven_deg` (deg) over the window, or since the TPS last moved (the map's changes
    /// above `static_map_from_deg`, see [`StillRun`]). The plate test asks for
    /// `driven_range_deg`. A frozen TPS asks for `frozen_driven_range_deg`, and also counts a
    /// map that holds the plate that far from the frozen reading (judged only
    /// `driven_range_deg` or more off the end stops): the frozen reading is the evidence, while
    /// a healthy plate rests up to 14 % of its angle from the model's map.
    fn static_while_driven(&self, driven_deg: f64, frozen: bool) -> bool {
        // A TPS at a rail (an open or shorted line reads like a plate at its stop) is left to
        // the circuit checks. At a rail means for `rail_persist_s` in a row: a healthy TPS a
        // little offset at a stop dips into the rail band now and then by its noise, and a
        // plate stuck at that stop must not escape the test by it.
        if self.at_rail_run >= self.rail_persist {
            return false;
        }
        let static_tps =
            self.tps_hist.full() && self.tps_hist.span() < self.cfg.static_tps_range_deg;
        // Away from the static map only off the end stops: a plate resting on a stop where the
        // voltage pushes it is where the static map is least certain (near the open stop it is
        // flat in the voltage, and a plant 1.5 % off Table I rests on the stop while the model's
        // map puts it 12 deg short: retired held-out version 7, log 0).
        let [lo, hi] = self.model.params().angle_limits_deg;
        let margin = self.cfg.driven_range_deg;
        let away = frozen
            && match (self.eq_hist.last(), self.tps_hist.last()) {
                (Some(eq), Some(tps)) => {
                    (eq - tps).abs() > driven_deg && tps > lo + margin && tps < hi - margin
                }
                _ => false,
            };
        let window = self.eq_hist.full() && self.eq_hist.span() > driven_deg;
        let since = self.still.steps() >= self.tps_hist.capacity() as u64
            && self.still.map_span_deg() > driven_deg;
        static_tps && (window || since || away)
    }

    /// Whether the static map `eq` explains the wattmeter over a steady hold clearly better than
    /// the wattmeter-only filter (window means of the reading less each one's prediction, W)
    /// while lying farther from the filter's angle than the map's own error: the filter is on a
    /// wrong branch (see `map_check`).
    fn map_explains_better(
        &self,
        filter: (f64, f64),
        filter_w: f64,
        map_w: f64,
        eq: &Vector3<f64>,
    ) -> bool {
        let r = self.watt_noise.variance() + self.cfg.wattmeter_r_floor;
        let sigma_mean = (r / f64::from(MAP_CHECK_WINDOW)).sqrt();
        let far = self.far_from_map(filter, eq);
        let (theta, theta_eq) = (filter.0, self.model.angle_deg(eq));
        let better = filter_w.abs() - map_w.abs() > MAP_CHECK_SIGMA * sigma_mean;
        if far && better {
            tracing::debug!(
                theta,
                theta_eq,
                filter_w,
                map_w,
                "filter re-seeded at the static map"
            );
        }
        far && better
    }

    /// Whether a filter's angle (deg, with its standard deviation) lies farther from the static
    /// map `eq` than the map's own error and the filter's spread allow.
    ///
    /// Judged only where the map is worth judging by: from `static_map_from_deg` (below, in the
    /// breakaway region, a plant a percent off Table I rests degrees away from it) up to where a
    /// plant `static_map_error_frac` off rests on the open stop (a map there says nothing: a
    /// re-identified model at its stability bound puts most voltages on the stop).
    fn far_from_map(&self, filter: (f64, f64), eq: &Vector3<f64>) -> bool {
        let (theta, sigma) = filter;
        let theta_eq = self.model.angle_deg(eq);
        let top = self.model.params().angle_limits_deg[1] / (1.0 + self.cfg.static_map_error_frac);
        (self.cfg.static_map_from_deg..=top).contains(&theta_eq)
            && (theta - theta_eq).abs()
                > self.cfg.static_map_error_frac * theta_eq.abs()
                    + 2.0 * sigma.max(DRIFT_SIGMA_FLOOR_DEG)
    }

    /// Counts the steps a filter's angle has stayed within `TRAP_BAND_DEG` of a mode boundary
    /// while far from the static map `eq`; true (and the count restarts) after `TRAP_STEPS`.
    fn trapped(&self, run: u32, filter: (f64, f64), eq: &Vector3<f64>) -> (u32, bool) {
        let near = self
            .model
            .params()
            .mode_upper_deg
            .iter()
            .any(|b| (filter.0 - b).abs() < TRAP_BAND_DEG);
        let run = if near && self.far_from_map(filter, eq) {
            run.saturating_add(1)
        } else {
            0
        };
        if run >= TRAP_STEPS {
            tracing::debug!(
                theta = filter.0,
                theta_eq = self.model.angle_deg(eq),
                "filter freed from a mode boundary"
            );
            (0, true)
        } else {
            (run, false)
        }
    }

    /// The combined filter's plate angle and its standard deviation (deg).
    fn combined_angle(&self) -> (f64, f64) {
        let sigma =
            self.both_ukf.covariance()[(0, 0)].max(0.0).sqrt() / self.model.params().angle_scale;
        (self.model.angle_deg(self.both_ukf.state()), sigma)
    }

    /// The wattmeter-only filter's plate angle and its standard deviation (deg).
    fn watt_only_angle(&self) -> (f64, f64) {
        let sigma =
            self.watt_ukf.covariance()[(0, 0)].max(0.0).sqrt() / self.model.params().angle_scale;
        (self.model.angle_deg(self.watt_ukf.state()), sigma)
    }

    /// Names the fault behind the residual tests that fired in this episode, among the
    /// components not already failed; `None` when none of them explains it (yet).
    ///
    /// The combined filter's wattmeter test fires for a wattmeter fault and for a TPS drift
    /// (the filter follows the TPS, and the current it predicts for that angle moves); the
    /// wattmeter-only filter's test fires for the first alone. So a wattmeter fault needs
    /// both, and a confirmed combined alarm with a quiet wattmeter-only test and a TPS away
    /// from the wattmeter's angle is the TPS's.
    fn classify(&self, now_s: f64, elapsed_s: f64) -> Option<ThrottleFault> {
        let tps_testable = self.tps_fault.is_none();
        if tps_testable && self.frozen_run >= self.cfg.frozen_samples {
            return Some(ThrottleFault::TpsStuck);
        }
        // A stuck plate is named by its own test only (`plate_persist_s` of static-while-driven):
        // a moment of it during another test's episode is a plate at rest that the static map
        // of a plate a percent off Table I puts elsewhere.
        let tps_fired = self.fired[0] || self.fired[1] || self.fired[3];
        let watt_only = self.last_watt_only_s.is_some_and(|t| {
            self.first_fail_s
                .is_some_and(|t0| t >= t0 - self.cfg.watt_confirm_s)
        });
        if self.watt_fault.is_none() && !tps_fired {
            if !tps_testable || self.plate_fault.is_some() {
                // The combined filter has no TPS: the wattmeter-only test alone, which model
                // error fails in bursts. A fault keeps it alarming: still confirmed after twice
                // `watt_confirm_s`, with an alarm in the last half of it.
                let recent = self
                    .last_watt_only_s
                    .is_some_and(|t| now_s - t <= 0.5 * self.cfg.watt_confirm_s);
                if elapsed_s >= 2.0 * self.cfg.watt_confirm_s
                    && self.watt_only_alarms >= self.cfg.watt_confirm_alarms
                    && recent
                {
                    return Some(ThrottleFault::Wattmeter);
                }
            } else if self.fired[2] && self.watt_alarms >= self.cfg.drift_confirm_alarms {
                // The wattmeter-only test alarming too points at the wattmeter (its faulty
                // readings also move that filter's angle away from the TPS): it is named once
                // confirmed, and the drift rule waits.
                if watt_only {
                    if self.watt_alarms >= self.cfg.watt_confirm_alarms {
                        return Some(ThrottleFault::Wattmeter);
                    }
                } else if self.disagree_run >= self.disagree_persist {
                    return Some(ThrottleFault::TpsPerformance);
                }
            }
            return None;
        }
        if tps_fired && tps_testable && self.plate_fault.is_none() {
            return Some(ThrottleFault::TpsPerformance);
        }
        None
    }

    /// Closes the residual episode.
    fn end_episode(&mut self) {
        self.first_fail_s = None;
        self.fired = [false; 4];
        self.watt_alarms = 0;
        self.watt_only_alarms = 0;
    }

    /// Sets the component of `fault` failed, and restarts the tests that will see it heal.
    fn set_failed(&mut self, fault: ThrottleFault, result: TestResult, now_s: f64) {
        let d = Some(Decided {
            fault,
            result,
            since_s: now_s,
        });
        let (tps_std_v, watt_std_w) = self.noise_levels();
        tracing::debug!(
            time_s = now_s,
            fault = fault.name(),
            tps_std_v,
            watt_std_w,
            watt_samples = self.watt_noise.samples(),
            "throttle fault decided"
        );
        match fault {
            ThrottleFault::Wattmeter => {
                self.watt_fault = d;
                self.heal_run[1] = 0;
            }
            ThrottleFault::PlateStuck => {
                self.plate_fault = d;
                self.heal_run[2] = 0;
            }
            _ => {
                let (tps_std_v, watt_std_w) = self.noise_levels();
                tracing::debug!(
                    time_s = now_s,
                    fault = fault.name(),
                    tps_std_v,
                    watt_std_w,
                    "TPS failed: position from the wattmeter estimate"
                );
                // The position output leaves the TPS: the combined filter goes on without it,
                // from the wattmeter-only filter's state, which no TPS reading has moved. A
                // drift pulls the combined filter along for as long as it takes to name it
                // (seconds to tens of seconds), and from there the wattmeter alone brings the
                // angle back only slowly. With the wattmeter failed too there is nothing
                // better than where the combined filter stands.
                if self.tps_fault.is_none() && self.watt_fault.is_none() {
                    let (x, p) = (*self.watt_ukf.state(), *self.watt_ukf.covariance());
                    let _reset_ok = self.both_ukf.reset(x, p).is_ok();
                }
                self.tps_fault = d;
                self.heal_run[0] = 0;
                self.heal_disagree_run = 0;
            }
        }
    }

    /// The decision of one step: new faults, then healing.
    fn decide(&mut self, now_s: f64, tps: Option<f64>, results: &[TestResult; 5]) {
        let rail = |run: u32, persist: u32, period_s: f64| TestResult {
            value: f64::from(run) * period_s,
            min: 0.0,
            max: f64::from(persist - 1) * period_s,
            verdict: Verdict::Failed,
        };
        let intermittent =
            self.dropouts.full() && self.dropouts.span() <= self.cfg.intermittent_window_s;
        let p = self.cfg.period_s;
        // Circuit faults of the TPS: a rail the model rules out, persisting, or repeated
        // dropouts.
        if self.tps_fault.is_none() {
            if self.rail_low_run >= self.rail_persist {
                let r = rail(self.rail_low_run, self.rail_persist, p);
                self.set_failed(ThrottleFault::TpsOpen, r, now_s);
            } else if self.rail_high_run >= self.rail_persist {
                let r = rail(self.rail_high_run, self.rail_persist, p);
                self.set_failed(ThrottleFault::TpsShort, r, now_s);
            } else if intermittent {
                let count = self.cfg.intermittent_count as f64;
                let r = TestResult {
                    value: count,
                    min: 0.0,
                    max: count - 1.0,
                    verdict: Verdict::Failed,
                };
                self.set_failed(ThrottleFault::TpsIntermittent, r, now_s);
            }
        }
        // A frozen TPS (identical readings: a healthy sensor's noise toggles the ADC code) while
        // the voltage should move the plate is a stuck sensor on its own, for as long as the
        // plate test would need: the TPS filter follows a frozen reading and its tests do not
        // fire while the plate moves.
        // Frozen for `frozen_alone_samples`, it is stuck at once, driven or not.
        let frozen = self.tps_fault.is_none()
            && self.plate_fault.is_none()
            && self.frozen_run >= self.cfg.frozen_samples;
        let alone = frozen
            && self.cfg.frozen_alone_samples > 0
            && self.frozen_run >= self.cfg.frozen_alone_samples;
        let frozen_driven =
            frozen && (alone || self.static_while_driven(self.cfg.frozen_driven_range_deg, true));
        self.frozen_driven_run = if frozen_driven {
            self.frozen_driven_run + 1
        } else {
            0
        };
        if alone || self.frozen_driven_run >= self.plate_persist {
            self.frozen_driven_run = 0;
            let limit = if alone {
                self.cfg.frozen_alone_samples
            } else {
                self.cfg.frozen_samples
            };
            let r = TestResult {
                value: f64::from(self.frozen_run),
                min: 0.0,
                max: f64::from(limit.saturating_sub(1)),
                verdict: Verdict::Failed,
            };
            self.set_failed(ThrottleFault::TpsStuck, r, now_s);
            self.end_episode();
        }
        // The stuck-plate test runs on its own (a trusted TPS that does not move while the
        // voltage should move the plate, and is not frozen: that would be the sensor). It
        // counts up and down (counter-based debouncing, as AUTOSAR Dem's): a plate stuck where
        // the static map puts it just past `driven_range_deg` makes the condition flicker with
        // the TPS noise, and a counter reset at every miss never got there (a plate stuck for
        // 40 s on steady holds went undetected).
        let trusted = self.tps_fault.is_none() && self.plate_fault.is_none();
        let static_now = trusted && self.static_while_driven(self.cfg.driven_range_deg, false);
        self.static_run = if static_now {
            self.static_run + 1
        } else if trusted {
            self.static_run.saturating_sub(1)
        } else {
            0
        };
        if self.static_run >= self.plate_persist && self.frozen_run < self.cfg.frozen_samples {
            self.static_run = 0;
            tracing::debug!(
                time_s = now_s,
                tps_span = self.tps_hist.span(),
                eq_span = self.eq_hist.span(),
                eq = self.eq_hist.last(),
                tps = self.tps_hist.last(),
                u_slow = self.u_slow,
                "plate stuck"
            );
            let r = TestResult {
                value: self.tps_hist.span(),
                min: self.cfg.static_tps_range_deg,
                max: f64::INFINITY,
                verdict: Verdict::Failed,
            };
            self.set_failed(ThrottleFault::PlateStuck, r, now_s);
            self.end_episode();
        }
        // Residual episode: the tests of the components that are not failed open it; after
        // the decision window the fault is named.
        let tps_testable = self.tps_fault.is_none() && self.plate_fault.is_none();
        // The wattmeter is tested against the model and a trusted TPS: with the TPS failed or
        // the plate stuck, the filters' current estimate is not independent of it.
        let eligible = [
            tps_testable,
            tps_testable,
            tps_testable && self.watt_fault.is_none(),
            tps_testable,
            self.watt_fault.is_none() && self.plate_fault.is_none(),
        ];
        for (i, r) in results.iter().enumerate() {
            // The wattmeter-only test opens an episode only where the combined filter has no
            // TPS: beside a trusted TPS it is the check of the combined test's verdict.
            let opens = i != 4 || !tps_testable;
            if eligible[i] && r.verdict == Verdict::Failed {
                if i == 4 {
                    self.last_watt_only_s = Some(now_s);
                    self.watt_only_alarms += 1;
                } else {
                    self.fired[i] = true;
                }
                if opens && self.first_fail_s.is_none() {
                    self.first_fail_s = Some(now_s);
                    self.first_result = *r;
                }
            }
        }
        if eligible[2] && results[2].verdict == Verdict::Failed {
            self.watt_alarms += 1;
        }
        if let Some(t0) = self.first_fail_s {
            let elapsed = now_s - t0;
            // While the plate test is counting, its verdict comes first: a stuck plate fails
            // the TPS filter's tests too.
            let plate_pending = self.static_run > 0
                && elapsed < self.cfg.decision_window_s + self.cfg.plate_persist_s;
            if elapsed >= self.cfg.decision_window_s && !plate_pending {
                let tps_fired = self.fired[0] || self.fired[1] || self.fired[3];
                let wait_s = if tps_testable {
                    self.cfg.watt_confirm_s
                } else {
                    2.0 * self.cfg.watt_confirm_s
                };
                match self.classify(now_s, elapsed) {
                    Some(f) => {
                        self.set_failed(f, self.first_result, now_s);
                        self.end_episode();
                    }
                    // Only the wattmeter tests fired: a wattmeter fault (or a TPS drift that
                    // pulls the combined filter) keeps them alarming, and its verdict waits up
                    // to `watt_confirm_s` for the alarms that tell them apart; meanwhile the
                    // TPS tests may fire and name the TPS. A burst of model error alarms once.
                    None if !tps_fired && elapsed < wait_s => {}
                    None => self.end_episode(),
                }
            }
        }
        // Healing: a failed component whose tests pass for `heal_s` is healthy again (its
        // DTC's testFailed clears; pending and confirmed follow the event memory's rules).
        let quiet = |r: &TestResult| matches!(r.verdict, Verdict::Passed | Verdict::PrePassed);
        if let Some(d) = self.tps_fault {
            // The TPS agrees with the combined filter, which runs without it while it is
            // failed (on the model and the wattmeter).
            let (theta, sigma) = self.combined_angle();
            if let Some(v) = tps {
                let gap = v / self.volts_per_deg - theta;
                let close = gap.abs() <= self.cfg.heal_agreement_deg + 2.0 * sigma;
                self.heal_disagree_run = if close {
                    0
                } else {
                    self.heal_disagree_run.saturating_add(1)
                };
            }
            // Agreement sample by sample, and over `heal_disagreement_s` (brief disagreements
            // forgiven as the estimate's lag behind a fast move).
            let agrees_now = tps.is_some() && self.heal_disagree_run == 0;
            let agrees_lately =
                tps.is_some() && self.heal_disagree_run < self.heal_disagree_persist;
            // Whether this step is evidence of a healthy TPS: `None` says nothing either way
            // (the run neither grows nor restarts).
            let evidence = match d.fault {
                // A circuit fault heals on readings off the rails, or on rail readings that the
                // wattmeter estimate does not rule out (the plate at that stop). Without the
                // wattmeter the model alone cannot tell a plate at its stop from a line still
                // open. Off-rail readings must also agree with the wattmeter estimate where
                // there is one, but for brief disagreements (the estimate lags a fast move
                // onto the closed stop by up to 15 deg for 0.4 s: sample by sample it kept
                // healed circuits failed past the grace, tuning logs 54 and 55): a drift that
                // clipped at a rail and comes back is still wrong. (A bias that held the TPS
                // at the open rail and was named a short heals on this, tuning log 11.) A
                // reading at the other rail says nothing of this fault (a healed short's TPS
                // reads 0 V with the plate on the closed stop).
                ThrottleFault::TpsOpen | ThrottleFault::TpsShort => match tps {
                    None => Some(false),
                    Some(v) => {
                        let (low, high) = (v <= self.cfg.rail_low_v, v >= self.cfg.rail_high_v);
                        let other_rail = if d.fault == ThrottleFault::TpsOpen {
                            high
                        } else {
                            low
                        };
                        if other_rail {
                            None
                        } else if low || high {
                            Some(
                                self.watt_fault.is_none()
                                    && self.rail_low_run == 0
                                    && self.rail_high_run == 0,
                            )
                        } else {
                            Some(agrees_lately || self.watt_fault.is_some())
                        }
                    }
                },
                // An intermittent circuit heals when its dropouts stop, with the same
                // agreement (tuning log 57: a noisy TPS named intermittent stayed failed).
                ThrottleFault::TpsIntermittent => Some(
                    tps.is_some()
                        && (agrees_lately || self.watt_fault.is_some())
                        && self.rail_low_run == 0
                        && self.rail_high_run == 0
                        && self
                            .dropouts
                            .last()
                            .is_none_or(|t| now_s - t > self.cfg.intermittent_window_s),
                ),
                // A stuck TPS heals when it moves again (the frozen check) and agrees with the
                // estimate but for its lag; readings held at a rail (a healthy TPS a percent
                // high reads 5 V on the open stop) say nothing either way (tuning log 51: the
                // healed TPS stayed failed 16 s).
                ThrottleFault::TpsStuck if self.at_rail_run >= self.rail_persist => None,
                ThrottleFault::TpsStuck => Some(
                    self.frozen_run < self.cfg.frozen_samples
                        && agrees_lately
                        && quiet(&results[0])
                        && quiet(&results[1])
                        && !matches!(results[3].verdict, Verdict::Failed),
                ),
                // A range/performance fault heals when the TPS tests pass and the TPS agrees
                // with the wattmeter estimate sample by sample, off the rails (a drift clipped
                // at 0 V agrees with a plate resting near the closed stop): the TPS filter
                // absorbs a drift or a bias that stays, so its tests alone would heal a fault
                // still present, and the estimate's own error (5 to 7 deg for seconds on a
                // plant a percent off Table I) is the size of a bias, so a forgiving
                // agreement heals biases still there (tuning logs 9, 10 and 37). The price:
                // a bias that ends may stay failed past the grace (tuning log 52, 42 s).
                _ => Some(
                    self.frozen_run < self.cfg.frozen_samples
                        && self.at_rail_run < self.rail_persist
                        && agrees_now
                        && quiet(&results[0])
                        && quiet(&results[1])
                        && !matches!(results[3].verdict, Verdict::Failed),
                ),
            };
            advance_heal(&mut self.heal_run[0], evidence);
            if self.heal_run[0] >= self.heal_steps {
                tracing::debug!(time_s = now_s, fault = d.fault.name(), "TPS healed");
                if matches!(d.fault, ThrottleFault::TpsOpen | ThrottleFault::TpsShort) {
                    self.rail_fault_healed = true;
                }
                self.tps_fault = None;
                self.dropouts.clear();
                // The combined filter takes the TPS again from the TPS filter's estimate.
                let _ = self
                    .both_ukf
                    .reset(*self.tps_ukf.state(), *self.tps_ukf.covariance());
            }
        }
        if self.watt_fault.is_some() && self.plate_fault.is_none() {
            // The wattmeter-only test does not fail, and beside a trusted TPS that filter's
            // angle agrees with the TPS. Not the combined filter's wattmeter test: with the
            // wattmeter failed, that filter's current comes from the model and the TPS alone,
            // and model error fails that test every few seconds on a healed wattmeter (tuning
            // set: flagged 80 s after the fault ended). A pre-failed CUSUM has not failed: the
            // healthy wattmeter-only test pre-fails every few seconds on most drives.
            let evidence = match results[4].verdict {
                Verdict::Failed => Some(false),
                Verdict::NotTested => None,
                _ if !tps_testable || tps.is_none() => Some(true),
                _ => Some(self.watt_heal_disagree_run < self.heal_disagree_persist),
            };
            advance_heal(&mut self.heal_run[1], evidence);
            if self.heal_run[1] >= self.heal_steps {
                tracing::debug!(time_s = now_s, "wattmeter healed");
                self.watt_fault = None;
            }
        }
        if self.plate_fault.is_some() {
            let moving =
                self.tps_hist.full() && self.tps_hist.span() >= self.cfg.static_tps_range_deg;
            self.heal_run[2] = if moving { self.heal_run[2] + 1 } else { 0 };
            if self.heal_run[2] >= self.heal_steps.min(self.tps_hist.cap() as u32) {
                self.plate_fault = None;
            }
        }
    }
}

/// One step of a heal run: evidence of health grows it, evidence of the fault restarts it, and
/// a step that says nothing either way (`None`) leaves it.
fn advance_heal(run: &mut u32, evidence: Option<bool>) {
    match evidence {
        Some(true) => *run = run.saturating_add(1),
        Some(false) => *run = 0,
        None => {}
    }
}

/// A normalized wattmeter innovation `z` (standard deviation `sigma`, W) with a lag of up to
/// `lag_s` allowed for: `(lag_s * rate)^2` added to its variance, the rate from the predicted
/// reading (W) and the previous one in `last` (updated; NaN when there is no innovation).
fn with_lag(
    z: f64,
    sigma: f64,
    predicted: f64,
    last: &mut f64,
    lag_s: f64,
    period_s: f64,
) -> (f64, f64) {
    if !(z.is_finite() && sigma.is_finite()) {
        *last = f64::NAN;
        return (z, sigma);
    }
    let rate = (predicted - *last) / period_s;
    *last = predicted;
    if !rate.is_finite() {
        return (z, sigma);
    }
    let s_eff = (sigma * sigma + (lag_s * rate).powi(2)).sqrt();
    (z * sigma / s_eff, s_eff)
}

/// `z` less a dead band of `band` (W) in units of `sigma` (W): residuals within it are no
/// evidence of a fault. NaN when `z` is.
fn dead_band(z: f64, sigma: f64, band: f64) -> f64 {
    let b = band / sigma;
    if z.is_finite() && b >= 0.0 {
        z - z.clamp(-b, b)
    } else {
        f64::NAN
    }
}

impl Monitor for ThrottleMonitor {
    fn name(&self) -> &str {
        "throttle"
    }

    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn inputs(&self) -> &[SignalId] {
        &self.inputs
    }

    fn fault_classes(&self) -> &'static [&'static str] {
        &FAULT_CLASSES
    }

    fn step(&mut self, now_ns: u64, signals: &SignalTable, out: &mut OutputSink<'_>) {
        let now_s = now_ns as f64 * 1e-9;
        let [u_id, tps_id, watt_id] = self.inputs;
        let Some(u) = signals.fresh(u_id, now_ns) else {
            return;
        };
        let tps = signals.fresh(tps_id, now_ns);
        let watt = signals.fresh(watt_id, now_ns);
        let uu = Vector1::new(u);
        self.u_slow += (u - self.u_slow) * self.u_alpha;
        let eq = self.model.equilibrium(self.u_slow);
        self.eq_hist.push(self.model.angle_deg(&eq));

        // Rail readings judged against the combined filter's prediction.
        let xp = *self.both_ukf.state();
        let theta_p = self.model.angle_deg(&xp);
        let sigma_p =
            self.both_ukf.covariance()[(0, 0)].max(0.0).sqrt() / self.model.params().angle_scale;
        let limits = self.model.params().angle_limits_deg;
        let (mut rail_low, mut rail_high) = (false, false);
        if let Some(v) = tps {
            // A rail reading that an angle estimate (deg, with its std) rules out: low, high.
            let ruled_out = |theta: f64, sigma: f64| {
                (
                    v <= self.cfg.rail_low_v
                        && theta - 3.0 * sigma > limits[0] + self.cfg.rail_margin_deg,
                    v >= self.cfg.rail_high_v
                        && theta + 3.0 * sigma < limits[1] - self.cfg.rail_margin_deg,
                )
            };
            (rail_low, rail_high) = ruled_out(theta_p, sigma_p);
            if self.watt_fault.is_none() {
                // That filter knows the angle at rest only through the static map: the map's
                // own error widens its spread.
                let (theta_w, sigma_w) = self.watt_only_angle();
                let map_error = self.cfg.static_map_error_frac * theta_w.abs();
                let (low, high) = ruled_out(theta_w, sigma_w + map_error / 3.0);
                self.watt_rail_run = if low || high {
                    self.watt_rail_run.saturating_add(1)
                } else {
                    0
                };
                // After a healed circuit fault, sooner, but not on a single sample: that
                // filter lags a fast move onto the stop by a few tenths of a second (tuning
                // set: a healthy TPS at the closed stop named open again 6 s after healing).
                let persist = if self.rail_fault_healed {
                    self.disagree_persist
                } else {
                    self.watt_rail_persist
                };
                if self.watt_rail_run >= persist {
                    rail_low |= low;
                    rail_high |= high;
                }
            } else {
                self.watt_rail_run = 0;
            }
            // A reading clipped at an ADC end repeats while the plate rests on that stop
            // (a TPS a percent high reads 5 V at the open stop): not a frozen signal.
            let inside = v > self.cfg.rail_low_v && v < self.cfg.rail_high_v;
            self.at_rail_run = if inside {
                0
            } else {
                self.at_rail_run.saturating_add(1)
            };
            self.frozen_run = if inside && v == self.last_tps {
                self.frozen_run + 1
            } else {
                0
            };
            self.last_tps = v;
            self.tps_hist.push(v / self.volts_per_deg);
            if inside {
                // The map only where it moves with the plant's: above the breakaway region and
                // below where a plant `static_map_error_frac` off already rests on the open
                // stop.
                let top = self.model.params().angle_limits_deg[1]
                    / (1.0 + self.cfg.static_map_error_frac);
                let eq = self.eq_hist.last().unwrap_or(f64::NAN);
                let eq = eq.max(self.cfg.static_map_from_deg).min(top);
                self.still.push(v / self.volts_per_deg, eq);
            } else {
                self.still.clear();
            }
            // The drift rule's disagreement, where the wattmeter-only filter is weakest: not
            // on the open stop with that filter below it (the static map is flat there; a
            // plant 1.5 % off Table I rests on the stop while the filter puts the plate 16 deg
            // short), and never judged on less than `DRIFT_SIGMA_FLOOR_DEG` of that filter's
            // spread (resting on the closed stop in its model it claims 0.25 deg while the
            // plate is held at 8). Both named a healthy TPS on a tuning drive at the corners
            // of the documented range. A TPS clipped at 5 V is the rail check's.
            let hi = self.model.params().angle_limits_deg[1];
            let tps_deg = v / self.volts_per_deg;
            let (theta_wo, sigma_wo) = self.watt_only_angle();
            let on_open_stop = tps_deg >= hi - self.cfg.driven_range_deg && theta_wo < tps_deg;
            let disagrees = (tps_deg - theta_wo).abs()
                > self.cfg.heal_agreement_deg + 2.0 * sigma_wo.max(DRIFT_SIGMA_FLOOR_DEG);
            self.disagree_run = if self.watt_fault.is_none() && !on_open_stop && disagrees {
                self.disagree_run.saturating_add(1)
            } else {
                0
            };
            self.watt_heal_disagree_run = if !on_open_stop && disagrees {
                self.watt_heal_disagree_run.saturating_add(1)
            } else {
                0
            };
        } else {
            self.disagree_run = 0;
        }
        for (run, now_rail) in [
            (&mut self.rail_low_run, rail_low),
            (&mut self.rail_high_run, rail_high),
        ] {
            if now_rail {
                *run += 1;
            } else {
                if *run > 0 && *run < self.rail_persist {
                    self.dropouts.push(now_s);
                }
                *run = 0;
            }
        }

        // Filters. The TPS filter keeps running on a failed TPS (not on its rail readings), so
        // that its tests can see the sensor heal; the combined filter uses only what is trusted.
        let tps_usable = tps.is_some() && !rail_low && !rail_high;
        // The noise estimates learn only while everything is healthy and nothing is pending.
        let adapt = self.first_fail_s.is_none()
            && self.rail_low_run == 0
            && self.rail_high_run == 0
            && self.tps_fault.is_none()
            && self.watt_fault.is_none()
            && self.plate_fault.is_none();
        let mut nis_t = f64::NAN;
        let mut z_t = f64::NAN;
        // The TPS innovation's standard deviation (V), for the tolerance dead band.
        let mut sigma_t = f64::NAN;
        let mut tps_fed = false;
        let mut step_outcome = None;
        if let (true, Some(v)) = (tps_usable, tps) {
            // Readings at the ADC's ends are clipped, not noisy: they say nothing of the noise.
            if adapt && v > self.cfg.rail_low_v && v < self.cfg.rail_high_v {
                self.tps_noise.push(v);
                tps_fed = true;
            }
            // The predicted TPS rate (V/s): a sensor that lags the plate by up to
            // `tps_lag_tolerance_s` misses it by up to that rate times the lag, which the tests
            // allow for on top of the innovation variance.
            // The model's motion over the step: this prediction from the previous update (an
            // update's own jump, e.g. at a bias's onset, is not motion).
            let prior = *self.tps_ukf.state();
            let theta = self.model.angle_deg(&prior);
            let rate_v = (theta - self.last_theta_pred) * self.volts_per_deg / self.cfg.period_s;
            let lag = if rate_v.is_finite() {
                (self.cfg.tps_lag_tolerance_s * rate_v).powi(2)
            } else {
                0.0
            };
            // A mode switch one step early or late moves the prediction by this (V): model
            // structure, not sensor error, allowed for by every TPS test.
            let rho_bound = (prior[1].abs()
                + 3.0 * self.tps_ukf.covariance()[(1, 1)].max(0.0).sqrt())
            .max(self.cfg.tps_step_rho_floor);
            let spread = self.model.mode_switch_spread_deg(
                theta,
                rho_bound,
                self.cfg.tps_step_mode_margin_deg,
            ) * self.volts_per_deg;
            if let Ok(inn) = self.tps_ukf.update(&Vector1::new(v), &uu) {
                let s_eff = inn.covariance[(0, 0)] + lag + spread * spread;
                let r = inn.residual[0];
                nis_t = r * r / s_eff;
                sigma_t = s_eff.sqrt();
                z_t = r / sigma_t;
                let predicted_change = (theta - self.last_theta_pred) * self.volts_per_deg;
                step_outcome = if predicted_change.is_finite() {
                    self.step_test
                        .push(v, predicted_change, spread, self.tps_noise.variance())
                } else {
                    self.step_test.reset();
                    None
                };
                self.last_theta_pred = self.model.angle_deg(self.tps_ukf.state());
                out(Output::Innovation {
                    filter: "tps",
                    residual: inn.residual.as_slice(),
                    variance: &[inn.covariance[(0, 0)]],
                    nis: inn.nis,
                    dof: inn.dof,
                });
            }
        }
        if !tps_usable {
            self.step_test.reset();
        }
        let tps_trusted = self.tps_fault.is_none();
        let use_tps =
            tps_trusted && tps_usable && nis_t.is_finite() && nis_t < self.cfg.tps_gate_nis;
        let use_watt = watt.is_some() && self.watt_fault.is_none();
        let mut z_w = f64::NAN;
        // The wattmeter innovation's standard deviation (W), for the model-error dead band.
        let mut sigma_w = f64::NAN;
        // The wattmeter reading the filters predict (W), for the gain tolerance.
        let mut predicted_w = 0.0;
        if let (false, Some(w)) = (use_watt, watt) {
            // A failed wattmeter is still compared with the combined filter's prediction of
            // `i^2` (Gaussian moments: mean mu^2 + P, variance 4 mu^2 P + 2 P^2, plus R).
            let (mu, p) = (self.both_ukf.state()[2], self.both_ukf.covariance()[(2, 2)]);
            let var = 4.0 * mu * mu * p + 2.0 * p * p + self.both_ukf.measurement_noise()[(1, 1)];
            sigma_w = var.max(f64::MIN_POSITIVE).sqrt();
            predicted_w = mu * mu + p;
            z_w = (w - predicted_w) / sigma_w;
        }
        if !tps_fed {
            self.tps_noise.gap();
        }
        let mut watt_fed = false;
        if let (true, Some(w)) = (adapt && use_watt, watt) {
            self.watt_noise.push(w);
            watt_fed = true;
        }
        if use_tps || use_watt {
            let y = Vector2::new(tps.unwrap_or(0.0), watt.unwrap_or(0.0));
            if let Ok(inn) = self.both_ukf.update_subset(&y, &uu, &[use_tps, use_watt]) {
                if use_watt {
                    z_w = inn.normalized(1);
                    sigma_w = inn.covariance[(1, 1)].sqrt();
                    predicted_w = watt.unwrap_or(0.0) - inn.residual[1];
                }
                // Without the TPS this filter runs on the model and the wattmeter, and can
                // settle on a wrong branch like the wattmeter-only one.
                let map_says = match (tps_trusted, use_watt, watt) {
                    (false, true, Some(w)) => self
                        .map_check_both
                        .push(u, inn.residual[1], w - eq[2] * eq[2])
                        .is_some_and(|(filter_w, map_w)| {
                            self.map_explains_better(self.combined_angle(), filter_w, map_w, &eq)
                        }),
                    _ => {
                        self.map_check_both.clear();
                        false
                    }
                };
                let trap = if tps_trusted {
                    self.trap_run_both = 0;
                    false
                } else {
                    let (run, t) = self.trapped(self.trap_run_both, self.combined_angle(), &eq);
                    self.trap_run_both = run;
                    t
                };
                if !use_tps && (self.reacquire.observe(inn.nis, inn.dof) || map_says || trap) {
                    let _reset_ok = self.both_ukf.reset(eq, self.p0).is_ok();
                    self.map_check_both.clear();
                }
                out(Output::Innovation {
                    filter: "combined",
                    residual: inn.residual.as_slice(),
                    variance: &[inn.covariance[(0, 0)], inn.covariance[(1, 1)]],
                    nis: inn.nis,
                    dof: inn.dof,
                });
            }
        }

        // The wattmeter-only filter: its innovation, with the same allowances as the combined
        // filter's below.
        let mut z_wo = f64::NAN;
        let mut sigma_wo = f64::NAN;
        let mut predicted_wo = 0.0;
        if let Some(w) = watt {
            if let Ok(inn) = self.watt_ukf.update(&Vector1::new(w), &uu) {
                z_wo = inn.normalized(0);
                sigma_wo = inn.covariance[(0, 0)].sqrt();
                predicted_wo = w - inn.residual[0];
                let map_w = w - eq[2] * eq[2];
                let reseed = self.watt_reacquire.observe(inn.nis, inn.dof)
                    || self.map_check.push(u, inn.residual[0], map_w).is_some_and(
                        |(filter_w, map_w)| {
                            self.map_explains_better(self.watt_only_angle(), filter_w, map_w, &eq)
                        },
                    );
                let (run, trap) = self.trapped(self.trap_run_wo, self.watt_only_angle(), &eq);
                self.trap_run_wo = run;
                if reseed || trap {
                    let _reset_ok = self.watt_ukf.reset(eq, self.p0).is_ok();
                    self.map_check.clear();
                }
            }
        } else {
            self.map_check.clear();
        }
        // A wattmeter lagging the current by up to `watt_lag_tolerance_s` misses the predicted
        // reading by up to that times its rate: allowed for on top of the innovation variance.
        let lag_s = self.cfg.watt_lag_tolerance_s;
        let p = self.cfg.period_s;
        (z_wo, sigma_wo) = with_lag(
            z_wo,
            sigma_wo,
            predicted_wo,
            &mut self.last_predicted_wo,
            lag_s,
            p,
        );
        (z_w, sigma_w) = with_lag(
            z_w,
            sigma_w,
            predicted_w,
            &mut self.last_predicted_w,
            lag_s,
            p,
        );
        if !watt_fed {
            self.watt_noise.gap();
        }
        self.apply_noise_levels(out);
        // The wattmeter test waits for its noise level: judged against the configured level,
        // a noisier wattmeter would fail it at once.
        if !self.watt_noise.settled() {
            z_w = f64::NAN;
            z_wo = f64::NAN;
        }

        // Residual tests.
        let clip = self.cfg.cusum_clip_sigma;
        let nis_result = if nis_t.is_finite() {
            let capped = nis_t.min(self.cfg.tps_nis_cap);
            self.nis_sum += capped - self.nis_ring.push(capped).unwrap_or(0.0);
            let failed = self.nis_ring.full() && self.nis_sum > self.cfg.tps_nis_threshold;
            TestResult {
                value: self.nis_sum,
                min: 0.0,
                max: self.cfg.tps_nis_threshold,
                verdict: if failed {
                    Verdict::Failed
                } else {
                    Verdict::Passed
                },
            }
        } else {
            TestResult::NOT_TESTED
        };
        // A TPS within its calibration tolerance of the model is no evidence of a fault (a dead
        // band, as for the wattmeter below).
        let band_t = self.cfg.tps_tolerance_v / sigma_t;
        let z_t = if z_t.is_finite() && band_t >= 0.0 {
            z_t - z_t.clamp(-band_t, band_t)
        } else {
            f64::NAN
        };
        let cusum_tps = self.cusum_tps.step(z_t.clamp(-clip, clip), z_t.is_finite());
        // Residuals within the model-error allowance are no evidence of a wattmeter fault (a dead
        // band in innovation units: wide when the wattmeter is quiet, narrow when it is noisy).
        let (model_error, gain) = (self.cfg.watt_model_error_w, self.cfg.watt_gain_tolerance);
        // Near a mode boundary the predicted current could be another mode's.
        let switch_w = self.model.mode_switch_current_spread(
            self.model.angle_deg(self.both_ukf.state()),
            uu[0],
            self.cfg.tps_step_mode_margin_deg,
        );
        let z_w = dead_band(
            z_w,
            sigma_w,
            model_error + gain * predicted_w.abs() + switch_w,
        );
        let cusum_watt = self
            .cusum_watt
            .step(z_w.clamp(-clip, clip), z_w.is_finite());
        let z_wo = dead_band(z_wo, sigma_wo, model_error + gain * predicted_wo.abs());
        let cusum_watt_only = self
            .cusum_watt_only
            .step(z_wo.clamp(-clip, clip), z_wo.is_finite());
        out(Output::Test {
            test: "wattmeter_only_cusum",
            result: cusum_watt_only,
        });
        out(Output::Test {
            test: "tps_nis_window",
            result: nis_result,
        });
        out(Output::Test {
            test: "tps_cusum",
            result: cusum_tps,
        });
        out(Output::Test {
            test: "wattmeter_cusum",
            result: cusum_watt,
        });

        let step_result = match step_outcome {
            Some(o) => TestResult {
                value: o.z.abs(),
                min: 0.0,
                max: self.cfg.tps_step_sigma,
                verdict: if o.failed {
                    Verdict::Failed
                } else {
                    Verdict::Passed
                },
            },
            None => TestResult::NOT_TESTED,
        };
        out(Output::Test {
            test: "tps_step",
            result: step_result,
        });
        let results = [
            nis_result,
            cusum_tps,
            cusum_watt,
            step_result,
            cusum_watt_only,
        ];
        self.decide(now_s, tps, &results);

        // Events: a failed component's event fails with the result that qualified it; the
        // other events of a component pass while nothing is pending, and are not tested while
        // a fault is being isolated or while what would test them is failed.
        let pending =
            self.first_fail_s.is_some() || self.rail_low_run > 0 || self.rail_high_run > 0;
        let mut results7 = [TestResult::NOT_TESTED; 7];
        let pass = |on: bool| {
            let mut r = TestResult::NOT_TESTED;
            if on {
                r.verdict = Verdict::Passed;
            }
            r
        };
        match self.tps_fault {
            Some(d) => results7[d.fault.event()] = d.result,
            None => {
                for r in &mut results7[..4] {
                    *r = pass(!pending);
                }
                // A stuck plate makes the TPS filter's residuals the plate's, not the sensor's.
                if self.plate_fault.is_some() {
                    results7[ThrottleFault::TpsPerformance.event()] = TestResult::NOT_TESTED;
                }
            }
        }
        results7[ThrottleFault::PlateStuck.event()] = match self.plate_fault {
            Some(d) => d.result,
            None => pass(!pending && self.tps_fault.is_none()),
        };
        results7[ThrottleFault::Wattmeter.event()] = match self.watt_fault {
            Some(d) => d.result,
            None => pass(!pending && self.plate_fault.is_none()),
        };
        results7[SWITCH_EVENT] = match self.tps_fault {
            Some(d) => d.result,
            None => pass(true),
        };

        // Position output: fused with the TPS while it is trusted, the wattmeter estimate
        // after (the model alone when the wattmeter is failed too).
        let x = *self.both_ukf.state();
        let angle = self.model.angle_deg(&x);
        let values = FreezeValues {
            signals: Some(signals),
            estimates: &[angle],
        };
        self.report_all(now_s, &results7, values, out);
        let half = 1.96 * self.both_ukf.covariance()[(0, 0)].max(0.0).sqrt()
            / self.model.params().angle_scale;
        out(Output::Estimate {
            name: "throttle_angle",
            value: angle,
            lower: (angle - half).max(limits[0]),
            upper: (angle + half).min(limits[1]),
            source: match (self.tps_fault, self.watt_fault) {
                (None, _) => "tps",
                (Some(_), None) => "wattmeter_estimate",
                (Some(_), Some(_)) => "model_estimate",
            },
        });

        // Diagnosis: flagged while a fault is decided (a suspicion still being isolated is
        // not flagged: most die out, and a flag is what the monitor asserts). Each decided fault
        // scores 1.
        self.scores = [0.0; 7];
        let mut flagged = false;
        for d in [self.tps_fault, self.watt_fault, self.plate_fault]
            .into_iter()
            .flatten()
        {
            self.scores[d.fault.class()] = 1.0;
            flagged = true;
        }
        out(Output::Diagnosis {
            flagged,
            scores: &self.scores,
        });

        let _ = self.tps_ukf.predict(&uu);
        let _ = self.both_ukf.predict(&uu);
        let _ = self.watt_ukf.predict(&uu);
    }

    fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.events.start_operation_cycle(now_ns, out);
        // A new cycle starts from the TPS again (see the recovery policy).
        self.restart();
    }

    fn end_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.events.end_operation_cycle(now_ns, out);
    }

    fn events(&self) -> &MonitorEvents {
        &self.events
    }

    fn events_mut(&mut self) -> &mut MonitorEvents {
        &mut self.events
    }

    /// The three throttle signals and the position estimate at the failure.
    fn default_freeze_frame(&self) -> Vec<String> {
        [
            &self.cfg.motor_voltage_signal,
            &self.cfg.tps_signal,
            &self.cfg.wattmeter_signal,
        ]
        .into_iter()
        .cloned()
        .chain(ESTIMATES.iter().map(|e| e.to_string()))
        .collect()
    }

    /// A cleared TPS fault is tested again from the TPS, as in a new cycle.
    fn restart_tests(&mut self, _now_ns: u64) {
        self.restart();
    }
}
