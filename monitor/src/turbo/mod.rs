//! The turbocharged air-path monitor: the structural flow residuals of the intake side
//! ([`fdd_estimators::models::turbo::residuals`]) and the boost residual of the turbo shaft
//! ([`fdd_estimators::models::turbo::shaft_balance`]), each tested by a two-sided CUSUM after a
//! learned offset, an intake fault isolated and sized by the hypothesis bank
//! ([`fdd_estimators::models::turbo::isolation`]), and the DTCs.
//!
//! # Frames
//!
//! A frame is one sample of the boost pressure, the intercooler temperature, the manifold
//! pressure and the air flow with the same time stamp (the LiU-ICE logs and the truth simulator
//! write them together at 20 Hz), with the latest engine speed, throttle, wastegate and ambient
//! pressure and temperature. The monitor polls every `poll_period_s` and processes each new
//! frame once.
//!
//! # Residuals
//!
//! At each frame the model gives the cylinder flow `W_cyl(p_im)` and the throttle flow
//! `W_thr(p_ic, p_im, throttle)` at the readings; the three balances
//! `W_af - W_cyl`, `W_af - W_thr`, `W_thr - W_cyl` are low-passed (first order,
//! `filter_tau_s`) and the volumes' filling is subtracted through the same filter: for a
//! first-order low-pass `F`, `F(dM/dt) = (M - F(M)) / tau`, so the filtered filling of the
//! manifold is `V_im / (R T_ic) (p_im - F(p_im)) / tau` without differentiating a noisy
//! reading (both volumes' in `W_af - W_cyl`, the manifold's in `W_thr - W_cyl`, the
//! intercooler's in `W_af - W_thr`). Each is divided by the filtered cylinder flow (at least
//! `flow_floor_kg_s`): relative residuals.
//!
//! The fourth residual is the boost reading less the boost at which the turbo shaft's torques
//! balance with the *commanded* wastegate at the manifold readings (the model's cylinder flow,
//! exhaust side, turbine and compressor; the MAF and boost readings do not enter), low-passed
//! the same way and divided by the ambient pressure. No intake balance sees the wastegate; this
//! one sees it alone of the faults (and the boost sensor, and through the flow the manifold
//! sensors and leaks).
//!
//! # When a residual is tested
//!
//! The balances are quasi-static: they hold once the volumes have (nearly) stopped filling.
//! A residual is tested and learns only while the throttle has been still for
//! `transient_hold_s`, the filling through a fast filter ([`FAST_TAU_S`]) is at most
//! `steady_fill_max` of the flow, and the slow charge-air temperature reading has caught up
//! (`steady_temperature_max_k`); the throttle residuals also need a metering throttle
//! (`throttle_ratio_max`) and steady pressures (`steady_pressure_max`). The boost residual waits
//! for the throttle's hold and the volumes' filling only: with the temperature and pressure
//! conditions too it ran in 2.5 % of the boosted frames of a tuning tip-in drive (39 % without
//! them); the turbo's lag is within the 2 s hold, and the charge-air temperature enters it only
//! through the cylinder flow.
//!
//! # Offsets: a calibrated map and learned values
//!
//! The model is not the engine. Its systematic error along the load `p_im / p_amb` (the
//! engine family's, from fault-free logs by `fdd calibrate`) is the offset map
//! (`offset_map_load`, `offset_map`); what differs from engine to engine and drive to drive
//! (on the LiU-ICE logs up to 6 % between runs) is learned on top, like an ECU's adaptation
//! values: each residual's offset learns with time constant `adapt_tau_s` for its first
//! `adapt_min_s` of tested time in an operation cycle (its test waits), then ten times slower
//! and only while every deviation tested in that frame is below `max(LEARN_BAND scales,
//! min_shift / 2)` and no alarm is pending. An offset is bounded by `adapt_limit`.
//!
//! # Tests and decisions
//!
//! `z = (relative residual - map - offset) / scale`, the scale from `scale_map` at the load
//! (else `residual_scale`; the boost's widened by how much its prediction moves with the
//! wastegate `wastegate_tolerance` off its command, `hypot(scale, spread)`: where the
//! wastegate has authority, nearly closed at high exhaust flow, the exhaust side's spread from
//! engine to engine moves the boost by tenths of an atmosphere, which the boost controller
//! absorbs by moving the wastegate; the boost offset learns only where that spread is below
//! [`BOOST_LEARN_SPREAD`] scales, so that an offset learned under boost is not carried to part
//! load): a two-sided CUSUM per residual with reference
//! `max(cusum_min_bias_sigma / 2, min_shift / (2 scale))` (deviations below half the smallest
//! fault the tests are built for, or below the model's own spread at that load, do not
//! accumulate) and threshold `cusum_threshold` (reported every frame on `/fdd/tests` as
//! `turbo_<residual>`). The hypothesis bank collects the frames in which the cylinder
//! residual was tested since the CUSUMs were last all zero (about the fault's onset): each
//! frame's balances against map and offsets (in kg/s), with `max(scale, min_shift / 2)` as
//! their deviations (the throttle balances' widened [`UNTESTED_SIGMA`] times in a frame in
//! which they were not tested). The first alarm opens an episode; after `decision_window_s`
//! the bank fits each single-fault hypothesis (a gain on `p_ic`, `p_im` or the MAF, a bias on
//! `T_ic`, a leak before or after the throttle, the throttle's area) and the best is named when
//! its probability among them is at least `isolation_min_probability`; otherwise the group DTC
//! carries the three best as candidates. The boost residual, which the bank does not fit,
//! checks a boost-sensor decision (a fitted gain that would have moved it clearly while it
//! stayed in its band: the group) and breaks a tie in the boost sensor's favour when the bank
//! is unsure between it, the MAF and the throttle (which do not enter the boost prediction)
//! and the boost residual moved as the fitted gain would ([`BOOST_EVIDENCE_SCALES`],
//! [`BOOST_EVIDENCE_RATIO`]; where the throttle is choked its balance cannot tell a
//! boost-sensor gain from the throttle's area). A leak before and a leak after the throttle
//! share the leak DTC (the candidates say which). When the boost test alarmed alone (the
//! intake CUSUMs
//! each below half their thresholds), the wastegate is named (underboost P0299 for a boost
//! below the prediction, overboost P0234 above) if some wastegate position, closed to fully
//! open, explains most of the episode's boost deviations ([`WASTEGATE_BAND`]); otherwise the
//! boost sensor (at low exhaust flow the wastegate has no authority, and a deviation there is
//! the sensor's). A named fault stays failed for the operation cycle;
//! the tests start again from zero after a decision. The diagnosis (`fdd evaluate`'s samples)
//! is flagged while an episode is open or a decided fault stands, with the bank's
//! probabilities at the decision as scores.

pub mod config;

use fdd_diagnostics::{TestResult, Verdict};
use fdd_estimators::models::turbo::isolation::{
    Fit, Hypothesis, IsolationBank, IsolationConfig, IsolationFrame,
};
use fdd_estimators::models::turbo::residuals::{
    flow_balance, ExhaustPressure, IntakeReadings, R_CYL, R_TC, R_THR,
};
use fdd_estimators::models::turbo::shaft_balance::shaft_balance;
use fdd_estimators::models::turbo::{TurboInput, TurboModel};

use crate::config_key::KeyPath;
use crate::monitor::{Monitor, Output, OutputSink};
use crate::monitor_events::{EventSpec, FreezeValues, MonitorEvents};
use crate::signal_table::{SignalId, SignalTable};

pub use config::{TurboConfig, TurboMonitorConfig, N_RESIDUALS, RESIDUALS};

/// Index of the boost residual in [`RESIDUALS`].
pub const R_BOOST: usize = 3;

/// While learning after the start phase, every normalized residual must be within this many
/// scales.
pub const LEARN_BAND: f64 = 1.5;
/// How much wider the throttle balances' deviations are made in a frame in which they were
/// not tested (the bank then learns from the cylinder balance alone).
pub const UNTESTED_SIGMA: f64 = 1e3;
/// A boost deviation within this many scales of what the wastegate's range (closed to fully
/// open) can make is one a wastegate fault explains.
pub const WASTEGATE_BAND: f64 = 2.0;
/// The boost residual's offset learns only where the wastegate's tolerance moves the boost
/// prediction by at most this many scales.
pub const BOOST_LEARN_SPREAD: f64 = 0.25;
/// How much slower the offsets learn after the start phase.
pub const TRACK_SLOWDOWN: f64 = 10.0;

/// The monitor's events, in DTC order of the configuration.
pub const EVENT_NAMES: [&str; EVENTS] = [
    "turbo_p_im_range_performance",
    "turbo_p_ic_range_performance",
    "turbo_maf_range_performance",
    "turbo_t_ic_range_performance",
    "turbo_intake_leak",
    "turbo_throttle_actuator",
    "turbo_underboost",
    "turbo_overboost",
    "turbo_air_path_group",
];
/// Number of events.
pub const EVENTS: usize = 9;
const EV_UNDERBOOST: usize = 6;
const EV_OVERBOOST: usize = 7;
const EV_GROUP: usize = 8;
/// The fault class of a boost deviation the shaft balance alone shows.
const WASTEGATE_CLASS: &str = "turbo_wastegate";

/// The event and the fault class of each hypothesis of the bank.
pub fn hypothesis_event(h: Hypothesis) -> (usize, &'static str) {
    match h {
        Hypothesis::PImGain => (0, "turbo_p_im_sensor"),
        Hypothesis::PIcGain => (1, "turbo_p_ic_sensor"),
        Hypothesis::MafGain => (2, "turbo_maf_sensor"),
        Hypothesis::TIcBias => (3, "turbo_t_ic_sensor"),
        Hypothesis::LeakBeforeThrottle => (4, "turbo_leak_before_throttle"),
        Hypothesis::LeakAfterThrottle => (4, "turbo_leak_after_throttle"),
        Hypothesis::ThrottleArea => (5, "turbo_throttle_actuator"),
    }
}

/// The fault classes `fdd evaluate` scores.
pub const FAULT_CLASSES: [&str; 8] = [
    "turbo_p_im_sensor",
    "turbo_p_ic_sensor",
    "turbo_maf_sensor",
    "turbo_t_ic_sensor",
    "turbo_leak_before_throttle",
    "turbo_leak_after_throttle",
    "turbo_throttle_actuator",
    WASTEGATE_CLASS,
];

/// Test names on `/fdd/tests`, in [`RESIDUALS`] order.
pub const TEST_NAMES: [&str; N_RESIDUALS] = [
    "turbo_cylinder_flow",
    "turbo_throttle_flow",
    "turbo_throttle_cylinder",
    "turbo_boost_pressure",
];

/// Estimates the monitor outputs (and a freeze frame may hold): the model's cylinder and
/// throttle flows at the readings (kg/s), and the boost pressure (Pa) and turbo speed (rad/s)
/// at which the shaft's torques balance with the commanded wastegate (NaN where the balance
/// has no value).
pub const ESTIMATES: [&str; 4] = [
    "cylinder_flow",
    "throttle_flow",
    "boost_pressure",
    "turbo_speed",
];

/// A two-sided CUSUM that keeps its statistic until reset (the decision reads the side).
#[derive(Debug, Clone, Copy, Default)]
struct Cusum {
    up: f64,
    down: f64,
}

impl Cusum {
    fn step(&mut self, z: f64, k: f64) {
        self.up = (self.up + z - k).max(0.0);
        self.down = (self.down - z - k).max(0.0);
    }
    fn value(&self) -> f64 {
        self.up.max(self.down)
    }
    fn side(&self) -> i8 {
        if self.up >= self.down {
            1
        } else {
            -1
        }
    }
}

/// Time constant of the fast low-pass of the pressures that the steadiness condition compares
/// with the residuals' filter (s): fast enough to follow a filling volume, slow enough that
/// the sensors' noise does not look like one.
pub const FAST_TAU_S: f64 = 0.2;

/// Time constant of the slow low-pass of the intercooler temperature (s): about a slow
/// temperature sensor's own lag (a thermistor in the charge air), so that the difference
/// from the residuals' filter measures how far the reading still is from the gas after a
/// change of load (see `steady_temperature_max_k`).
pub const SLOW_TEMPERATURE_TAU_S: f64 = 5.0;

/// Names of the estimates the monitor also reports each frame (what `fdd calibrate` collects,
/// in [`RESIDUALS`] order): each relative residual's deviation from the offset map and the
/// learned offset (what its test sees, before the scale; NaN when not tested), each learned
/// offset (-), and the load the map is read at (`p_im / p_amb`, low-passed).
pub const RESIDUAL_ESTIMATES: [&str; 2 * N_RESIDUALS + 1] = [
    "residual_cylinder_flow",
    "residual_throttle_flow",
    "residual_throttle_cylinder",
    "residual_boost_pressure",
    "offset_cylinder_flow",
    "offset_throttle_flow",
    "offset_throttle_cylinder",
    "offset_boost_pressure",
    "intake_load",
];

/// First-order low-pass state.
#[derive(Debug, Clone, Copy)]
struct Filters {
    /// The three flow balances (kg/s) and the boost reading less the shaft balance's boost
    /// (Pa).
    raw: [f64; N_RESIDUALS],
    p_im: f64,
    p_ic: f64,
    /// The pressures through the fast low-pass ([`FAST_TAU_S`]).
    p_im_fast: f64,
    p_ic_fast: f64,
    /// The intercooler temperature through the residuals' filter and the slow one
    /// ([`SLOW_TEMPERATURE_TAU_S`]).
    t_ic: f64,
    t_ic_slow: f64,
    w_cyl: f64,
}

/// A calibrated map (offsets or scales) at `load` (linear between nodes, constant beyond the
/// ends; zero without nodes).
pub fn map_offset<const N: usize>(nodes: &[f64], values: &[[f64; N]], load: f64) -> [f64; N] {
    let n = nodes.len().min(values.len());
    if n == 0 {
        return [0.0; N];
    }
    if !(load > nodes[0]) {
        return values[0];
    }
    if load >= nodes[n - 1] {
        return values[n - 1];
    }
    let k = nodes[..n].partition_point(|&x| x <= load).clamp(1, n - 1);
    let (x0, x1) = (nodes[k - 1], nodes[k]);
    let w = (load - x0) / (x1 - x0);
    std::array::from_fn(|i| values[k - 1][i] + w * (values[k][i] - values[k - 1][i]))
}

/// The boost residual over an episode's frames, for the decision between the boost sensor and
/// the faults the bank fits from the flow balances.
#[derive(Debug, Clone, Copy, Default)]
struct BoostEvidence {
    dev: f64,
    scale: f64,
    reading: f64,
    n: u32,
}

/// Fewest frames of the boost residual for its evidence to count.
pub const BOOST_EVIDENCE_MIN_FRAMES: u32 = 20;
/// The boost residual's mean deviation "clearly off" (or clearly not): this many of its mean
/// scales (over the mean's own spread, the scale is a frame's).
pub const BOOST_EVIDENCE_SCALES: f64 = 1.5;
/// How far the boost residual's mean deviation may be from what the fitted boost-sensor gain
/// gives and still be its (a factor either way: the fitted gain and the learned offset are
/// both a few percent off).
pub const BOOST_EVIDENCE_RATIO: f64 = 2.5;

impl BoostEvidence {
    fn add(&mut self, dev: f64, scale: f64, reading: f64) {
        self.dev += dev;
        self.scale += scale;
        self.reading += reading;
        self.n += 1;
    }

    /// With a boost-sensor gain `gain` fitted by the bank: `Some(true)` when the boost
    /// residual's mean deviation is clearly off and within [`BOOST_EVIDENCE_RATIO`] of what
    /// that gain gives (`(1 - 1/gain)` times the mean reading, same sign), `Some(false)` when
    /// that gain would move it clearly but it stays within the band, `None` without enough
    /// frames or a verdict.
    fn favours_p_ic(&self, gain: f64) -> Option<bool> {
        if self.n < BOOST_EVIDENCE_MIN_FRAMES || !(gain > 0.0) {
            return None;
        }
        let n = f64::from(self.n);
        let (dev, scale, reading) = (self.dev / n, self.scale / n, self.reading / n);
        let expected = (1.0 - 1.0 / gain) * reading;
        let band = BOOST_EVIDENCE_SCALES * scale;
        let ratio = dev / expected;
        if dev.abs() >= band && (1.0 / BOOST_EVIDENCE_RATIO..=BOOST_EVIDENCE_RATIO).contains(&ratio)
        {
            Some(true)
        } else if expected.abs() >= 2.0 * band && dev.abs() < band {
            Some(false)
        } else {
            None
        }
    }
}

/// The air-path monitor (see the module docs). No heap allocation per frame.
#[derive(Debug)]
pub struct TurboMonitor {
    cfg: TurboMonitorConfig,
    model: TurboModel,
    /// p_ic, T_ic, p_im, maf, speed, throttle, wastegate, ambient p, ambient T.
    inputs: [SignalId; 9],
    period_ns: u64,
    /// `V_im / R`, `V_ic / R` (m^3 kg K / J).
    v_im_r: f64,
    v_ic_r: f64,
    last_t_ns: Option<u64>,
    filters: Option<Filters>,
    offsets: [f64; N_RESIDUALS],
    /// Steady time (s) each offset has learned in this operation cycle.
    learned_s: [f64; N_RESIDUALS],
    /// Tested time (s) without a rising CUSUM since the last decision.
    healthy_s: f64,
    /// Time (s) each residual has been enabled without a break (the throttle residuals need
    /// a throttle that meters, see `throttle_ratio_max`).
    enabled_s: [f64; N_RESIDUALS],
    /// The throttle of the previous frame (%) and the time until which a transient holds the
    /// tests (s).
    last_throttle: f64,
    hold_until_s: f64,
    cusum: [Cusum; N_RESIDUALS],
    /// Signs of the residuals that alarmed in the open episode.
    alarmed: [i8; N_RESIDUALS],
    episode_start_s: Option<f64>,
    /// The test result of the first alarm of the episode (what qualifies the DTC).
    episode_result: TestResult,
    /// Frames since the boost test last started accumulating in which its deviation was within
    /// what some wastegate position could make, and those in which it was not (see
    /// [`WASTEGATE_BAND`]).
    wastegate_frames: [u32; 2],
    /// The boost residual over the bank's frames (since the CUSUMs were last all zero) where
    /// it was tested: sums of its deviation and scale (ambient pressures) and of the boost
    /// reading over the ambient pressure, and their number (see [`BoostEvidence`]).
    boost_evidence: BoostEvidence,
    bank: IsolationBank,
    ev_result: [TestResult; EVENTS],
    ev_cands: [[(&'static str, f64); 3]; EVENTS],
    ev_ncand: [usize; EVENTS],
    estimates: [f64; ESTIMATES.len()],
    /// The diagnosis scores per [`FAULT_CLASSES`]: the bank's probabilities at the last
    /// decision of the operation cycle (0 before any).
    scores: [f64; FAULT_CLASSES.len()],
    frames: u64,
    events: MonitorEvents,
}

impl TurboMonitor {
    /// The monitor on `params`' model with settings `cfg`, reading the named signals of
    /// `table`. Errors name the setting or the signal.
    pub fn new(
        params: &fdd_estimators::models::turbo::TurboParams,
        cfg: &TurboMonitorConfig,
        table: &SignalTable,
    ) -> Result<Self, String> {
        cfg.validate(&KeyPath::file("turbo monitor settings").key("monitor"))
            .map_err(|e| e.to_string())?;
        let model = TurboModel::new(params.clone()).map_err(|e| e.to_string())?;
        let id = |name: &str| {
            table
                .id(name)
                .ok_or_else(|| format!("signal `{name}` is not in the runtime's signal table"))
        };
        let inputs = [
            id(&cfg.p_ic_signal)?,
            id(&cfg.t_ic_signal)?,
            id(&cfg.p_im_signal)?,
            id(&cfg.maf_signal)?,
            id(&cfg.speed_signal)?,
            id(&cfg.throttle_signal)?,
            id(&cfg.wastegate_signal)?,
            id(&cfg.ambient_pressure_signal)?,
            id(&cfg.ambient_temperature_signal)?,
        ];
        let dtcs = [
            &cfg.dtc_p_im,
            &cfg.dtc_p_ic,
            &cfg.dtc_maf,
            &cfg.dtc_t_ic,
            &cfg.dtc_leak,
            &cfg.dtc_throttle,
            &cfg.dtc_underboost,
            &cfg.dtc_overboost,
            &cfg.dtc_group,
        ];
        let bank =
            IsolationBank::new(&model, IsolationConfig::default()).map_err(|e| e.to_string())?;
        let specs: Vec<EventSpec<'_>> = EVENT_NAMES
            .iter()
            .zip(dtcs)
            .map(|(name, dtc)| EventSpec::internal(name, dtc, 2))
            .collect();
        let events = MonitorEvents::new(&specs)
            .map_err(|e| e.to_string())?
            .with_estimates(&ESTIMATES);
        let p = model.params();
        Ok(Self {
            period_ns: (cfg.poll_period_s * 1e9).round().max(1.0) as u64,
            v_im_r: p.intake_manifold_volume_m3 / p.air_gas_constant_j_per_kg_k,
            v_ic_r: p.intercooler_volume_m3 / p.air_gas_constant_j_per_kg_k,
            inputs,
            last_t_ns: None,
            filters: None,
            offsets: [0.0; N_RESIDUALS],
            learned_s: [0.0; N_RESIDUALS],
            healthy_s: 0.0,
            enabled_s: [0.0; N_RESIDUALS],
            last_throttle: f64::NAN,
            hold_until_s: f64::NEG_INFINITY,
            cusum: [Cusum::default(); N_RESIDUALS],
            alarmed: [0; N_RESIDUALS],
            episode_start_s: None,
            episode_result: TestResult::NOT_TESTED,
            wastegate_frames: [0; 2],
            boost_evidence: BoostEvidence::default(),
            bank,
            ev_result: [TestResult::NOT_TESTED; EVENTS],
            ev_cands: [[("", 0.0); 3]; EVENTS],
            ev_ncand: [0; EVENTS],
            estimates: [f64::NAN; ESTIMATES.len()],
            scores: [0.0; FAULT_CLASSES.len()],
            frames: 0,
            events,
            model,
            cfg: cfg.clone(),
        })
    }

    /// The learned offsets of the relative residuals ([`RESIDUALS`] order).
    pub fn offsets(&self) -> [f64; N_RESIDUALS] {
        self.offsets
    }

    /// Frames processed.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    fn reset_tests(&mut self) {
        self.healthy_s = 0.0;
        self.bank.reset();
        self.wastegate_frames = [0; 2];
        self.boost_evidence = BoostEvidence::default();
        self.cusum = [Cusum::default(); N_RESIDUALS];
        self.alarmed = [0; N_RESIDUALS];
        self.episode_start_s = None;
        self.episode_result = TestResult::NOT_TESTED;
    }

    fn reset_cycle(&mut self) {
        self.filters = None;
        self.enabled_s = [0.0; N_RESIDUALS];
        self.last_throttle = f64::NAN;
        self.hold_until_s = f64::NEG_INFINITY;
        self.offsets = [0.0; N_RESIDUALS];
        self.learned_s = [0.0; N_RESIDUALS];
        self.reset_tests();
        self.ev_result = [TestResult::NOT_TESTED; EVENTS];
        self.ev_ncand = [0; EVENTS];
        self.scores = [0.0; FAULT_CLASSES.len()];
        self.last_t_ns = None;
    }

    /// One frame at `t_ns`.
    #[allow(clippy::too_many_arguments)]
    pub fn process_frame(
        &mut self,
        t_ns: u64,
        r: &IntakeReadings,
        u: &TurboInput,
        signals: Option<&SignalTable>,
        out: &mut OutputSink<'_>,
    ) {
        let t_s = t_ns as f64 * 1e-9;
        let dt = self
            .last_t_ns
            .map_or(f64::INFINITY, |l| t_ns.saturating_sub(l) as f64 * 1e-9);
        self.last_t_ns = Some(t_ns);
        self.frames += 1;
        let valid = self.model.check_input(u).is_ok()
            && [r.p_ic_pa, r.t_ic_k, r.p_im_pa, r.maf_kg_s]
                .iter()
                .all(|v| v.is_finite() && *v > 0.0);
        if !valid {
            // Nothing to test: the filters start again with the next valid frame.
            self.filters = None;
            for name in TEST_NAMES {
                out(Output::Test {
                    test: name,
                    result: TestResult::NOT_TESTED,
                });
            }
            self.emit_diagnosis(out);
            return;
        }
        if dt.is_finite()
            && (u.throttle_pct - self.last_throttle).abs() > self.cfg.throttle_rate_max_pct_s * dt
        {
            self.hold_until_s = t_s + self.cfg.transient_hold_s;
        }
        self.last_throttle = u.throttle_pct;
        let steady = t_s >= self.hold_until_s;
        let b = flow_balance(&self.model, r, u, &ExhaustPressure::Ambient);
        // The boost the shaft's balance gives with the commanded wastegate.
        let shaft = if self.cfg.shaft_test {
            shaft_balance(&self.model, r, u).ok()
        } else {
            None
        };
        let (p_ic_model, omega) =
            shaft.map_or((f64::NAN, f64::NAN), |s| (s.p_ic_pa, s.omega_t_rad_s));
        self.estimates = [b.w_cyl_kg_s, b.w_thr_kg_s, p_ic_model, omega];
        let now = [
            b.residuals[R_CYL],
            b.residuals[R_THR],
            b.residuals[R_TC],
            r.p_ic_pa - p_ic_model,
        ];
        let tau = self.cfg.filter_tau_s;
        // The throttle meters the flow only with a clear pressure drop across it.
        let metering = r.p_im_pa <= self.cfg.throttle_ratio_max * r.p_ic_pa;
        let enabled = [true, metering, metering, shaft.is_some()];
        let f = match self.filters {
            Some(mut f) if dt <= self.cfg.max_frame_gap_s => {
                let a = (dt / tau).min(1.0);
                for (i, &on) in enabled.iter().enumerate() {
                    if on {
                        if i == R_BOOST && self.enabled_s[i] == 0.0 {
                            // Starts at the frame: the balance had no value while disabled.
                            f.raw[i] = now[i];
                        } else {
                            f.raw[i] += a * (now[i] - f.raw[i]);
                        }
                        self.enabled_s[i] += dt;
                    } else {
                        // Restarted when enabled again: nothing of the unmetered time is kept.
                        f.raw[i] = now[i];
                        self.enabled_s[i] = 0.0;
                    }
                }
                f.p_im += a * (r.p_im_pa - f.p_im);
                f.p_ic += a * (r.p_ic_pa - f.p_ic);
                let af = (dt / FAST_TAU_S).min(1.0);
                f.p_im_fast += af * (r.p_im_pa - f.p_im_fast);
                f.p_ic_fast += af * (r.p_ic_pa - f.p_ic_fast);
                f.t_ic += a * (r.t_ic_k - f.t_ic);
                f.t_ic_slow += (dt / SLOW_TEMPERATURE_TAU_S).min(1.0) * (r.t_ic_k - f.t_ic_slow);
                f.w_cyl += a * (b.w_cyl_kg_s - f.w_cyl);
                f
            }
            _ => {
                // (Re)start: the filters at the frame, the tests from zero.
                self.reset_tests();
                self.enabled_s = [0.0; N_RESIDUALS];
                Filters {
                    raw: now,
                    p_im: r.p_im_pa,
                    p_ic: r.p_ic_pa,
                    p_im_fast: r.p_im_pa,
                    p_ic_fast: r.p_ic_pa,
                    t_ic: r.t_ic_k,
                    t_ic_slow: r.t_ic_k,
                    w_cyl: b.w_cyl_kg_s,
                }
            }
        };
        self.filters = Some(f);
        let fill_im = self.v_im_r / r.t_ic_k * (r.p_im_pa - f.p_im) / tau;
        let fill_ic = self.v_ic_r / r.t_ic_k * (r.p_ic_pa - f.p_ic) / tau;
        let reference = f.w_cyl.max(self.cfg.flow_floor_kg_s);
        // The volumes' filling, through the fast filter (not the sensors' noise), is small
        // against the flow, and the charge-air temperature reading has caught up (see
        // `steady_fill_max`, `steady_temperature_max_k`).
        let filling = (self.v_im_r * (f.p_im_fast - f.p_im).abs()
            + self.v_ic_r * (f.p_ic_fast - f.p_ic).abs())
            / (r.t_ic_k * tau);
        let filled = steady && filling <= self.cfg.steady_fill_max * reference;
        let steady = filled && (f.t_ic - f.t_ic_slow).abs() <= self.cfg.steady_temperature_max_k;
        // The throttle residuals also wait for steady pressures (`steady_pressure_max`).
        let eps = self.cfg.steady_pressure_max;
        let pressures = (f.p_im_fast - f.p_im).abs() <= eps * f.p_im
            && (f.p_ic_fast - f.p_ic).abs() <= eps * f.p_ic;
        // How much the boost prediction moves with the wastegate `wastegate_tolerance` away
        // from its command (toward closed, or open where it is nearly closed), in ambient
        // pressures: the prediction's spread where the wastegate has authority. Only in a frame
        // whose boost can be tested (`filled`): elsewhere nothing uses it.
        let boost_spread = match shaft {
            Some(_) if filled && self.cfg.wastegate_tolerance > 0.0 => {
                let d = self.cfg.wastegate_tolerance;
                let w = if u.wastegate_frac >= d {
                    u.wastegate_frac - d
                } else {
                    u.wastegate_frac + d
                };
                let v = TurboInput {
                    wastegate_frac: w,
                    ..*u
                };
                shaft_balance(&self.model, r, &v).map_or(f64::INFINITY, |s| {
                    (s.p_ic_pa - p_ic_model).abs() / u.ambient_pressure_pa
                })
            }
            _ => 0.0,
        };
        // The boost also needs its spread (the balance at the tolerance's other position may
        // find no root: then nothing says how far to trust the prediction).
        let steady_r = [
            steady,
            steady && pressures,
            steady && pressures,
            filled && boost_spread.is_finite(),
        ];
        let load = f.p_im / u.ambient_pressure_pa;
        let base = map_offset(&self.cfg.offset_map_load, &self.cfg.offset_map, load);
        let mut scale = if self.cfg.scale_map.is_empty() {
            self.cfg.residual_scale
        } else {
            map_offset(&self.cfg.offset_map_load, &self.cfg.scale_map, load)
        };
        // The boost's offset learns only where the wastegate has next to no authority (its
        // tolerance moves the prediction by less than [`BOOST_LEARN_SPREAD`] scales: an offset
        // learned under boost would carry the model's error at that load to every other);
        // its scale is widened by that movement.
        let boost_conditioned = boost_spread <= BOOST_LEARN_SPREAD * scale[R_BOOST];
        scale[R_BOOST] = scale[R_BOOST].hypot(boost_spread);
        let mut rel = [0.0; N_RESIDUALS];
        rel[R_CYL] = (f.raw[R_CYL] - fill_im - fill_ic) / reference - base[R_CYL];
        rel[R_THR] = (f.raw[R_THR] - fill_ic) / reference - base[R_THR];
        rel[R_TC] = (f.raw[R_TC] - fill_im) / reference - base[R_TC];
        // The boost: reading less the shaft balance's, in ambient pressures.
        rel[R_BOOST] = f.raw[R_BOOST] / u.ambient_pressure_pa - base[R_BOOST];
        let z: [f64; N_RESIDUALS] = std::array::from_fn(|i| (rel[i] - self.offsets[i]) / scale[i]);
        // A residual counts once its filter has run a time constant since it was enabled, and
        // is tested once its offset has learned for `adapt_min_s` of steady frames.
        let settled: [bool; N_RESIDUALS] = std::array::from_fn(|i| self.enabled_s[i] >= tau);
        let learning: [bool; N_RESIDUALS] =
            std::array::from_fn(|i| self.learned_s[i] < self.cfg.adapt_min_s);
        let learning_phase = learning[R_CYL];
        // Quiet: no episode open and every residual tested this frame near its offset (one
        // that is not tested now, e.g. a throttle residual while the pressures settle, has no
        // say: its deviation there is the transient's, not a fault's).
        let quiet = self.episode_start_s.is_none()
            && (0..N_RESIDUALS).all(|i| {
                !settled[i]
                    || learning[i]
                    || !steady_r[i]
                    || z[i].abs() * scale[i] < (LEARN_BAND * scale[i]).max(0.5 * self.cfg.min_shift)
            });
        {
            let step = dt.min(self.cfg.max_frame_gap_s);
            let lim = self.cfg.adapt_limit;
            for i in (0..N_RESIDUALS).filter(|&i| {
                steady_r[i]
                    && settled[i]
                    && (learning[i] || quiet)
                    && (i != R_BOOST || boost_conditioned)
            }) {
                let tau_a = if learning[i] {
                    self.learned_s[i] += step;
                    self.cfg.adapt_tau_s
                } else {
                    self.cfg.adapt_tau_s * TRACK_SLOWDOWN
                };
                let a = (step / tau_a).min(1.0);
                self.offsets[i] =
                    (self.offsets[i] + a * (rel[i] - self.offsets[i])).clamp(-lim, lim);
            }
        }
        // The reference: half the smallest shift the tests are built for, in scales, and at
        // least half `cusum_min_bias_sigma` (deviations the model error makes at every load
        // do not accumulate).
        let k: [f64; N_RESIDUALS] = std::array::from_fn(|i| {
            (0.5 * self.cfg.cusum_min_bias_sigma).max(0.5 * self.cfg.min_shift / scale[i])
        });
        let mut alarm = None;
        let mut residuals = [f64::NAN; RESIDUAL_ESTIMATES.len()];
        residuals[N_RESIDUALS..2 * N_RESIDUALS].copy_from_slice(&self.offsets);
        residuals[2 * N_RESIDUALS] = load;
        for i in 0..N_RESIDUALS {
            let h = self.cfg.cusum_threshold[i];
            let result = if learning[i] || !settled[i] || !steady_r[i] {
                TestResult::NOT_TESTED
            } else {
                residuals[i] = z[i] * scale[i];
                self.cusum[i].step(z[i], k[i]);
                let v = self.cusum[i].value();
                let verdict = if v > h {
                    Verdict::Failed
                } else if v > 0.5 * h {
                    Verdict::PreFailed
                } else {
                    Verdict::Passed
                };
                if verdict == Verdict::Failed && self.alarmed[i] == 0 {
                    self.alarmed[i] = self.cusum[i].side();
                    alarm.get_or_insert(TestResult {
                        value: v,
                        min: 0.0,
                        max: h,
                        verdict,
                    });
                }
                TestResult {
                    value: v,
                    min: 0.0,
                    max: h,
                    verdict,
                }
            };
            out(Output::Test {
                test: TEST_NAMES[i],
                result,
            });
        }
        // The bank holds the frames since the CUSUMs were last all zero (about the onset of
        // whatever they are accumulating) in which the cylinder-flow residual was tested; the
        // throttle balances count only where they were tested too (elsewhere their deviations
        // are made [`UNTESTED_SIGMA`] times wider: no information).
        let tested: [bool; N_RESIDUALS] =
            std::array::from_fn(|i| steady_r[i] && settled[i] && !learning[i]);
        let widen = if tested[R_THR] && tested[R_TC] {
            1.0
        } else {
            UNTESTED_SIGMA
        };
        if self.episode_start_s.is_none() && self.cusum.iter().all(|c| c.value() == 0.0) {
            self.bank.reset();
            self.boost_evidence = BoostEvidence::default();
        } else if tested[R_CYL] {
            if tested[R_BOOST] {
                self.boost_evidence.add(
                    z[R_BOOST] * scale[R_BOOST],
                    scale[R_BOOST],
                    r.p_ic_pa / u.ambient_pressure_pa,
                );
            }
            let frame = IsolationFrame {
                readings: *r,
                input: *u,
                exhaust: ExhaustPressure::Ambient,
                baseline_kg_s: [
                    (base[R_CYL] + self.offsets[R_CYL]) * reference,
                    (base[R_THR] + self.offsets[R_THR]) * reference,
                ],
                sigma_kg_s: std::array::from_fn(|i| {
                    let w = if i == R_CYL { 1.0 } else { widen };
                    w * scale[i].max(0.5 * self.cfg.min_shift) * reference
                }),
            };
            // A frame the bank refuses (a reading it cannot linearize) is left out.
            let _ = self.bank.push(&frame);
        }
        // While the boost test accumulates: could any wastegate position explain its
        // deviation? The boost the balance gives with the wastegate closed and fully open
        // bounds what a wastegate fault can do (at low exhaust flow the two are the same: the
        // wastegate has no authority there, and a deviation is the boost sensor's).
        if tested[R_BOOST] && (self.cusum[R_BOOST].value() > 0.0 || self.episode_start_s.is_some())
        {
            let bound = |wg: f64| {
                let v = TurboInput {
                    wastegate_frac: wg,
                    ..*u
                };
                shaft_balance(&self.model, r, &v).map(|s| s.p_ic_pa)
            };
            if let (Ok(closed), Ok(open)) = (bound(0.0), bound(1.0)) {
                let (lo, hi) = (
                    (open - p_ic_model) / u.ambient_pressure_pa,
                    (closed - p_ic_model) / u.ambient_pressure_pa,
                );
                let band = WASTEGATE_BAND * scale[R_BOOST];
                let dev = z[R_BOOST] * scale[R_BOOST];
                let within = dev >= lo - band && dev <= hi + band;
                self.wastegate_frames[usize::from(!within)] += 1;
            }
        } else if self.cusum[R_BOOST].value() == 0.0 && self.episode_start_s.is_none() {
            self.wastegate_frames = [0; 2];
        }
        if let Some(first) = alarm {
            if self.episode_start_s.is_none() {
                self.episode_start_s = Some(t_s);
                self.episode_result = first;
            }
        }
        if let Some(e0) = self.episode_start_s {
            if t_s - e0 >= self.cfg.decision_window_s {
                self.decide_episode();
                self.reset_tests();
            }
        } else if self.ev_result.iter().any(|r| r.verdict == Verdict::Failed) {
            // A decided fault is gone once the cylinder residual has been tested for `heal_s`
            // with no CUSUM rising (a fault still there makes them rise again and decides
            // again): its events pass (the DTCs stay stored).
            if self.cusum.iter().any(|c| c.value() > 0.0) {
                self.healthy_s = 0.0;
            } else if tested[R_CYL] {
                self.healthy_s += dt.min(self.cfg.max_frame_gap_s);
                if self.healthy_s >= self.cfg.heal_s {
                    self.ev_result = [TestResult::NOT_TESTED; EVENTS];
                    self.ev_ncand = [0; EVENTS];
                    self.scores = [0.0; FAULT_CLASSES.len()];
                }
            }
        }
        let now_s = t_s;
        let values = FreezeValues {
            signals,
            estimates: &self.estimates,
        };
        for e in 0..EVENT_NAMES.len() {
            let result = self.ev_result[e];
            let cands = self.ev_cands[e];
            let n = if result.verdict == Verdict::Failed {
                self.ev_ncand[e]
            } else {
                0
            };
            let result = if result.verdict == Verdict::NotTested && !learning_phase {
                TestResult {
                    value: 0.0,
                    min: 0.0,
                    max: 0.0,
                    verdict: Verdict::Passed,
                }
            } else {
                result
            };
            self.events
                .report_one(e, now_s, &result, &cands[..n], values, out);
        }
        for (i, name) in ESTIMATES.iter().enumerate() {
            out(Output::Estimate {
                name,
                value: self.estimates[i],
                lower: f64::NAN,
                upper: f64::NAN,
                source: "model at the readings",
            });
        }
        for (name, value) in RESIDUAL_ESTIMATES.iter().zip(residuals) {
            out(Output::Estimate {
                name,
                value,
                lower: f64::NAN,
                upper: f64::NAN,
                source: "relative residual",
            });
        }
        self.emit_diagnosis(out);
    }

    /// Flagged while an episode is open (not yet named: scores 0) or while a decided fault
    /// stands (the bank's probabilities at its decision).
    fn emit_diagnosis(&self, out: &mut OutputSink<'_>) {
        let decided = self.ev_result.iter().any(|r| r.verdict == Verdict::Failed);
        let flagged = decided || self.episode_start_s.is_some();
        let none = [0.0; FAULT_CLASSES.len()];
        out(Output::Diagnosis {
            flagged,
            scores: if decided { &self.scores } else { &none },
        });
    }

    fn decide_episode(&mut self) {
        let result = TestResult {
            verdict: Verdict::Failed,
            ..self.episode_result
        };
        self.scores = [0.0; FAULT_CLASSES.len()];
        // The boost test alone, with the intake balances holding (none alarmed, each below
        // half its threshold): the boost the commanded wastegate does not give, or the boost
        // sensor. The wastegate when some position explains most of the episode's deviations
        // (a boost reading above the prediction is overboost), the sensor otherwise (its
        // gain moves the reading where the wastegate has no authority).
        let intake_holds = (0..R_BOOST).all(|i| {
            self.alarmed[i] == 0 && self.cusum[i].value() <= 0.5 * self.cfg.cusum_threshold[i]
        });
        if self.alarmed[R_BOOST] != 0 && intake_holds {
            let [within, outside] = self.wastegate_frames;
            let (event, class) = if within >= outside {
                let e = if self.alarmed[R_BOOST] > 0 {
                    EV_OVERBOOST
                } else {
                    EV_UNDERBOOST
                };
                (e, WASTEGATE_CLASS)
            } else {
                hypothesis_event(Hypothesis::PIcGain)
            };
            if let Some(i) = FAULT_CLASSES.iter().position(|c| *c == class) {
                self.scores[i] = 1.0;
            }
            self.ev_result[event] = result;
            self.ev_cands[event] = [(class, 1.0), ("", 0.0), ("", 0.0)];
            self.ev_ncand[event] = 1;
            return;
        }
        let fits = self.bank.fits();
        for f in &fits {
            let class = hypothesis_event(f.hypothesis).1;
            if let Some(i) = FAULT_CLASSES.iter().position(|c| *c == class) {
                self.scores[i] += f.probability;
            }
        }
        let mut best = fits[0];
        // The boost residual, which the bank does not fit, checks a boost-sensor decision and
        // breaks a tie in its favour: a boost-sensor gain g moves it by (1 - 1/g) times the
        // reading, while the MAF and the throttle, which the bank confuses with the boost
        // sensor where the throttle is choked, do not enter the boost prediction at all (the
        // manifold-pressure gain, a charge-air temperature bias and the leaks do: no tie is
        // broken against them). See [`BoostEvidence::favours_p_ic`].
        let p_ic = fits
            .iter()
            .take(3)
            .find(|f| f.hypothesis == Hypothesis::PIcGain);
        let unsure = best.probability < self.cfg.isolation_min_probability;
        let boost_blind = matches!(
            best.hypothesis,
            Hypothesis::PIcGain | Hypothesis::MafGain | Hypothesis::ThrottleArea
        );
        if let Some(&f) = p_ic {
            match self.boost_evidence.favours_p_ic(f.size) {
                Some(true) if unsure && boost_blind => {
                    // Named on the boost residual's word: a stated score of 1.
                    best = Fit {
                        probability: 1.0,
                        ..f
                    };
                    self.scores = [0.0; FAULT_CLASSES.len()];
                    if let Some(i) = FAULT_CLASSES.iter().position(|c| *c == "turbo_p_ic_sensor") {
                        self.scores[i] = 1.0;
                    }
                }
                Some(false) if best.hypothesis == Hypothesis::PIcGain && !unsure => {
                    // The boost did not move as that gain would move it: the group.
                    best.probability = 0.0;
                }
                _ => {}
            }
        }
        if self.bank.frames() > 0 && best.probability >= self.cfg.isolation_min_probability {
            let (event, class) = hypothesis_event(best.hypothesis);
            self.ev_result[event] = result;
            self.ev_cands[event] = [(class, best.probability), ("", 0.0), ("", 0.0)];
            self.ev_ncand[event] = 1;
        } else {
            for (k, f) in fits.iter().take(3).enumerate() {
                self.ev_cands[EV_GROUP][k] = (hypothesis_event(f.hypothesis).1, f.probability);
            }
            self.ev_ncand[EV_GROUP] = 3;
            self.ev_result[EV_GROUP] = result;
        }
    }

    /// The bank's fits of the open episode, best first (for tools and tests).
    pub fn isolation_fits(&self) -> [fdd_estimators::models::turbo::isolation::Fit; 7] {
        self.bank.fits()
    }
}

impl Monitor for TurboMonitor {
    fn name(&self) -> &str {
        "turbo"
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
        let [pic, tic, pim, maf, n, th, wg, pa, ta] = self.inputs;
        let (Some(s_pic), Some(s_tic), Some(s_pim), Some(s_maf)) = (
            signals.get(pic),
            signals.get(tic),
            signals.get(pim),
            signals.get(maf),
        ) else {
            return;
        };
        let t = s_pim.t_ns;
        if s_pic.t_ns != t
            || s_maf.t_ns != t
            || t > now_ns
            || self.last_t_ns.is_some_and(|l| t <= l)
        {
            return;
        }
        let (Some(s_n), Some(s_th), Some(s_wg), Some(s_pa), Some(s_ta)) = (
            signals.get(n),
            signals.get(th),
            signals.get(wg),
            signals.get(pa),
            signals.get(ta),
        ) else {
            return;
        };
        let r = IntakeReadings {
            p_ic_pa: s_pic.value,
            t_ic_k: s_tic.value,
            p_im_pa: s_pim.value,
            maf_kg_s: s_maf.value,
        };
        let u = TurboInput {
            throttle_pct: s_th.value,
            engine_speed_rad_s: s_n.value,
            wastegate_frac: s_wg.value.clamp(0.0, 1.0),
            lambda: 1.0,
            ambient_pressure_pa: s_pa.value,
            ambient_temperature_k: s_ta.value,
        };
        self.process_frame(t, &r, &u, Some(signals), out);
    }

    fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.events.start_operation_cycle(now_ns, out);
        self.reset_cycle();
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

    /// The nine signals and the two model flows at the failure.
    fn default_freeze_frame(&self) -> Vec<String> {
        [
            &self.cfg.p_ic_signal,
            &self.cfg.t_ic_signal,
            &self.cfg.p_im_signal,
            &self.cfg.maf_signal,
            &self.cfg.speed_signal,
            &self.cfg.throttle_signal,
            &self.cfg.wastegate_signal,
            &self.cfg.ambient_pressure_signal,
            &self.cfg.ambient_temperature_signal,
        ]
        .into_iter()
        .cloned()
        .chain(ESTIMATES.iter().map(|e| e.to_string()))
        .collect()
    }

    /// A cleared fault is tested again from scratch.
    fn restart_tests(&mut self, _now_ns: u64) {
        self.reset_tests();
        self.ev_result = [TestResult::NOT_TESTED; EVENTS];
        self.ev_ncand = [0; EVENTS];
        self.scores = [0.0; FAULT_CLASSES.len()];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_maps_interpolate_between_nodes_and_hold_beyond_them() {
        let nodes = [0.3, 0.5, 1.0];
        let rows = [[0.0, 1.0, -1.0], [0.2, 1.0, 1.0], [0.4, 0.0, 1.0]];
        assert_eq!(map_offset(&[], &[], 0.7), [0.0; 3]);
        assert_eq!(map_offset(&nodes, &rows, 0.1), rows[0]);
        assert_eq!(map_offset(&nodes, &rows, 0.3), rows[0]);
        assert_eq!(map_offset(&nodes, &rows, 2.0), rows[2]);
        assert_eq!(map_offset(&nodes, &rows, f64::NAN), rows[0]);
        let m = map_offset(&nodes, &rows, 0.4);
        for (got, want) in m.iter().zip([0.1, 1.0, 0.0]) {
            assert!((got - want).abs() < 1e-12, "{m:?}");
        }
        let m = map_offset(&nodes, &rows, 0.75);
        for (got, want) in m.iter().zip([0.3, 0.5, 1.0]) {
            assert!((got - want).abs() < 1e-12, "{m:?}");
        }
        // Exactly at an inner node: its row.
        assert_eq!(map_offset(&nodes, &rows, 0.5), rows[1]);
    }

    /// `n` frames of a boost deviation `dev` at scale `scale` and a reading of `reading`
    /// ambient pressures.
    fn evidence(n: u32, dev: f64, scale: f64, reading: f64) -> BoostEvidence {
        let mut e = BoostEvidence::default();
        for _ in 0..n {
            e.add(dev, scale, reading);
        }
        e
    }

    #[test]
    fn the_boost_evidence_says_whether_a_boost_sensor_gain_moved_the_boost() {
        // A 10 % gain at a reading of 1.1 atm moves the boost residual by 0.1 atm.
        let moved = evidence(40, 0.1, 0.015, 1.1);
        assert_eq!(moved.favours_p_ic(1.10), Some(true));
        // ... not by what a gain below 1 would (the other sign), nor by four times less.
        assert_eq!(moved.favours_p_ic(0.90), None);
        assert_eq!(moved.favours_p_ic(1.02), None);
        // A boost that stayed within its band while the fitted gain would move it clearly
        // out: not the boost sensor.
        let still = evidence(40, 0.005, 0.015, 1.1);
        assert_eq!(still.favours_p_ic(1.10), Some(false));
        // Within the band and a gain too small to say: no word either way.
        assert_eq!(still.favours_p_ic(1.01), None);
        // Too few frames, or a gain that is no gain: no word.
        assert_eq!(
            evidence(BOOST_EVIDENCE_MIN_FRAMES - 1, 0.1, 0.015, 1.1).favours_p_ic(1.1),
            None
        );
        assert_eq!(moved.favours_p_ic(0.0), None);
        assert_eq!(moved.favours_p_ic(f64::NAN), None);
    }

    #[test]
    fn every_hypothesis_has_an_event_and_a_scored_class() {
        for h in Hypothesis::ALL {
            let (e, class) = hypothesis_event(h);
            assert!(e < EV_GROUP, "{h:?}");
            assert!(FAULT_CLASSES.contains(&class), "{h:?}");
        }
        // Both leaks share the leak event; every other hypothesis has its own.
        let events: Vec<usize> = Hypothesis::ALL
            .iter()
            .map(|&h| hypothesis_event(h).0)
            .collect();
        assert_eq!(events, vec![1, 0, 2, 3, 4, 4, 5]);
    }
}
