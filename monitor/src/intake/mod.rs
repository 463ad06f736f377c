//! The intake-manifold monitor: the MAP/MAF EKF paper's three filter architectures run side by
//! side as residual generators, tests on their innovations, a fault-hypothesis bank that tells
//! the MAP sensor, the MAF sensor, the EGR valve and a manifold leak apart, and the DTCs.
//!
//! Sampling is crank-synchronous: one sample of engine speed, throttle opening, EGR command,
//! MAP and MAF per 180 deg segment, so the step length `30 / N` changes every segment. The
//! monitor polls the signal table every `poll_period_s` and runs one segment whenever a MAP and
//! a MAF sample with the same, newer, time stamp are there.
//!
//! Filters (the paper's model, `ThrottleFlow::RandomWalk`: the throttle flow is a random walk):
//! - the **centralized EKF** on MAP and MAF;
//! - the **decentralized pair** of the paper: a MAP-only and a MAF-only local EKF and the naive
//!   master fusion (optimistic covariance, reported as it is);
//! - the **federated filter** (fusion-reset, information shares), consistent.
//!
//! One of them (`primary_filter`) gives the estimate output (manifold pressure and
//! intake-valve flow). The local filters are what makes isolation possible: each sees one
//! sensor, so each predicts the *other* sensor from the model alone.
//!
//! # The plant is not the model
//!
//! Every residual's variance carries model-error allowances besides the filter's covariance and
//! the sensor noise: a relative term (`pressure_model_rel`, `flow_model_rel`,
//! `throttle_model_rel`), a transient term (`transient_tolerance_s` times the reading's rate of
//! change: lags and dynamics known to a few milliseconds) and the unknown ambient pressure
//! (`ambient_pressure_std_pa`): in the throttle-model flow, and in the pressure residual
//! through the EGR flow's error under the exhaust back-pressure that moves with it. Two
//! corrections are learned while no test fails and nothing is decided, like an ECU's
//! adaptation values: the ratio of the air
//! flow the MAP-only filter implies to the MAF reading (volumetric-efficiency and MAF
//! calibration errors; the MAF is multiplied by it before the filters) and, while the throttle
//! is choked, the ratio of the MAF to the throttle model's flow (discharge, bore, ambient).
//! The residual tests start once the first has learned for `adapt_min_s`.
//!
//! # Tests
//!
//! Each reported every segment on `/fdd/tests`:
//! - `intake_pressure_consistency`: CUSUM on the MAP reading against the MAF-local filter's MAP
//!   prediction (normalized);
//! - `intake_flow_consistency`: CUSUM on the MAF reading against the MAP-local filter's MAF
//!   prediction;
//! - `intake_throttle_model`: CUSUM on the MAF reading against the nozzle flow of the commanded
//!   throttle opening, only while the throttle is choked (then the throttle flow depends on the
//!   opening alone, so this test sees only the MAF sensor);
//! - `intake_centralized_nis`, `intake_federated_nis`: windowed sums of the 2-dof NIS;
//! - `intake_map_noise`, `intake_maf_noise`: variance CUSUMs on each local filter's innovation
//!   against its learned level (a noisy sensor);
//! - `intake_map_circuit`, `intake_maf_circuit`: readings outside the circuit range (kept out
//!   of the filters), judged against the model at both ends;
//! - `intake_map_frozen`, `intake_maf_frozen`: readings repeated exactly (a stuck sensor);
//! - `intake_input_range`: an engine speed, throttle or EGR input the model refuses (speed 0 or
//!   negative, NaN): the segment is skipped, nothing reaches the filters;
//! - `intake_isolation`: while an isolation episode is open, the lead of the best hypothesis.
//!
//! # Decisions: per component, none latched
//!
//! Each sensor's checks run whatever the other sensor and the residual tests do:
//! - a circuit range violation lasting `circuit_persist_segments` is a circuit fault
//!   (P0107/P0108, P0102/P0103);
//! - a reading repeated exactly for `frozen_segments` segments is a stuck sensor (P0106/P0101:
//!   a live sensor's noise moves its reading every segment);
//! - a failed noise test is a noisy sensor (P0106/P0101).
//!
//! Such a fault passes again once its sensor reads plausibly (in range, moving, not noisy) for
//! `heal_s`. A circuit or frozen sensor is kept out of the filters meanwhile; when it comes
//! back the filters start again.
//!
//! When a residual test fails, the hypothesis bank ([`hypotheses`]) is refitted from the
//! failing test's estimated onset (the last time its CUSUM was zero) and then follows every
//! segment; the best hypothesis is named when it is significant and leads the runner-up
//! clearly (see [`IntakeMonitorConfig`]). The EGR DTC is P0401 (insufficient) when the fitted
//! stuck position is below the mean command since the onset, P0402 (excessive) otherwise;
//! P0404 (range/performance, `egr_slow_response`) when a valve lagging its command explains
//! the residuals better than any stuck position.
//! When the hypotheses stay ambiguous (a leak and an EGR valve stuck open at idle explain the
//! same data), the **group DTC** `intake_air_path_group` (P0068) fails `group_after_s` after
//! the alarm, with every hypothesis within `group_margin` of the best as its candidates; when
//! isolation decides later, the specific DTC is raised and the group event passes.
//!
//! A named residual fault is not latched either: its fitted effect is predicted forward
//! ([`Compensation`]) and taken out of the residuals, so the tests go on looking for new
//! faults (a second, different fault gets its own DTC; a later refit of the same hypothesis
//! refines its size), and a sequential test on the residuals between "still there" and "gone"
//! (Huber's loss, so that a large effect can be told gone) lets it pass again once it has
//! healed: when that test has favoured "gone" for `heal_s` while the raw residuals (the
//! fault's effect added back) read quiet. The filters, whose states followed the compensated
//! inputs, then start again, and the next alarm's onset scan looks no further back than their
//! settling.
//!
//! Recovery policy: the estimate output (`manifold_pressure`, `intake_valve_flow`) comes from
//! the local filter that the decided faults leave sound: the MAF-only one after a MAP fault,
//! the MAP-only one after a MAF, EGR or leak fault (it measures the pressure and its
//! random-walk throttle flow absorbs unmetered air); the source names it. A reading refused
//! by the circuit check is kept out of every filter; the centralized EKF and the pair go on
//! with the other sensor, and the output comes from that sensor's local filter meanwhile.

pub mod config;
pub mod hypotheses;

use fdd_diagnostics::detectors::{two_sided_arl, Cusum, CusumConfig, CusumSide, Detector};
use fdd_diagnostics::{TestResult, Verdict};
use fdd_estimators::models::intake::{
    IntakeInput, IntakeModel, IntakeState, MafSensor, MapMafSensors, MapSensor, ThrottleFlow, X_PM,
    X_PMES, X_WMES, X_WTHR,
};
use fdd_estimators::{DecentralizedPair, Ekf, FederatedFilter, FusionNoise};
use nalgebra::{Matrix1, Matrix2, SMatrix, SVector, Vector1, Vector2};

pub use config::{IntakeMonitorConfig, PrimaryFilter};
pub use hypotheses::{
    Compensation, Fit, HypothesisBank, IntakeFault, OnsetScan, RecordRing, SegmentRecord,
    ALL_FAULTS,
};

use crate::config_key::KeyPath;
use crate::monitor::{Monitor, Output, OutputSink};
use crate::monitor_events::{EventSpec, FreezeValues, MonitorEvents};
use crate::signal_table::{SignalId, SignalTable};

/// Segments kept for refitting from an onset (5 s at 6000 rpm, 38 s at 800 rpm).
const HISTORY: usize = 1024;
/// Segments between two outputs of the learned corrections (`maf_correction`,
/// `throttle_correction`): they move over `adapt_time_s`, not per segment.
const CORRECTION_OUTPUT_SEGMENTS: u64 = 64;
/// Segments before the alarm test's onset estimate that the onset scan still considers.
const ONSET_MARGIN: u64 = 6;
/// Longest look-back of the onset scan (segments): bounds the one-off refit at an alarm to
/// `ONSET_WINDOW_MAX` records into 16 banks (1.3 s at 6000 rpm, 9.6 s at 800 rpm).
const ONSET_WINDOW_MAX: u64 = 256;
/// Capacity of the NIS windows.
pub(crate) const NIS_RING: usize = 512;
/// Segments the throttle must have been choked before its flow residual is used (the MAF lag
/// and the lagged model flow have settled).
const CHOKED_SETTLE: u32 = 3;
/// Time (s) the residual tests wait after the filters start again (a sensor back in use).
const RESTART_SETTLE_S: f64 = 1.0;

/// An isolation episode decides (or raises the group DTC) only while a residual test has failed
/// within this time (s): the tests re-arm at each failure, so a fault still present fails them
/// again within a fraction of a second.
const ALARM_ACTIVE_S: f64 = 1.0;
/// Segments of its last change a moving estimate is given in the circuit checks.
const ESTIMATE_SETTLE_SEGMENTS: f64 = 10.0;
/// Share of the throttle model's flow at the MAP reading that rules out a MAF reading below
/// its circuit-low limit. With the MAF reading left out of the filters, their estimate of the
/// metered flow rests on the MAP alone and scatters by about 1 g/s from segment to segment at
/// idle, where the true flow is 3 g/s, so their 3-sigma rule never rules out an open MAF line
/// there; the throttle's orifice flow at the measured pressure and opening is known within a
/// few percent (choked at idle): 70 % of it leaves room for the plant's discharge and angle
/// errors, and at 2 deg (3 g/s) is still above the limit plus its margin (1.5 g/s), while a
/// closed plate's leakage is not.
const THROTTLE_MODEL_LOW_SHARE: f64 = 0.7;
/// A refit that leaves less than this fraction of a decided fault's error is its healing.
const HEALED_FRACTION: f64 = 0.25;

/// Clip (allowances) of the raw residuals whose means tell that a decided fault has gone.
const RAW_CLIP: f64 = 3.0;

/// Share of a decided fault's predicted effect that its raw residuals may keep once it has gone
/// (the prediction is linearized about the compensated filters' trajectory).
const RAW_EFFECT_SHARE: f64 = 0.05;

/// Number of events.
pub const EVENTS: usize = 11;

/// Event names, in the order of the DTC settings.
pub const EVENT_NAMES: [&str; EVENTS] = [
    "map_range_performance",
    "map_circuit_low",
    "map_circuit_high",
    "maf_range_performance",
    "maf_circuit_low",
    "maf_circuit_high",
    "egr_flow_insufficient",
    "egr_flow_excessive",
    "intake_leak",
    "intake_air_path_group",
    "egr_slow_response",
];

/// The group event: detected, not isolated yet (its candidates are the hypotheses left).
pub const GROUP_EVENT: &str = "intake_air_path_group";
const GROUP: usize = 9;
/// The sluggish EGR valve's event.
const EGR_SLOW: usize = 10;

/// The fault classes of the monitor's diagnosis output: the isolation bank's hypotheses
/// ([`IntakeFault::name`], in the order of [`ALL_FAULTS`]).
pub const FAULT_CLASSES: [&str; 4] = ["map_sensor", "maf_sensor", "egr_valve", "manifold_leak"];

/// A fault the monitor has named and that has not healed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IntakeDecision {
    /// A residual fault isolated by the hypothesis bank, with its fitted size (refined by later
    /// refits).
    Residual { fit: Fit, event: usize },
    /// A circuit range fault (event index into [`EVENT_NAMES`]).
    Circuit { event: usize },
    /// A sensor whose reading is frozen (stuck): its range/performance event.
    Frozen { event: usize },
    /// A sensor whose noise has grown: its range/performance event.
    Noisy { event: usize },
}

impl IntakeDecision {
    /// Index of the DTC event in [`EVENT_NAMES`].
    pub fn event(&self) -> usize {
        match *self {
            IntakeDecision::Residual { event, .. }
            | IntakeDecision::Circuit { event }
            | IntakeDecision::Frozen { event }
            | IntakeDecision::Noisy { event } => event,
        }
    }

    /// Name of the event.
    pub fn event_name(&self) -> &'static str {
        EVENT_NAMES[self.event()]
    }
}

/// Origin named by the errors of settings given to [`IntakeMonitor::new`] directly (a
/// configuration file is checked, naming the file, when it is parsed:
/// [`crate::config::IntakeConfig::parse`]).
pub const SETTINGS_ORIGIN: &str = "intake monitor settings";

/// Errors building the monitor.
#[derive(Debug, thiserror::Error)]
pub enum IntakeMonitorError {
    #[error("intake monitor: signal `{0}` is not in the signal table")]
    MissingSignal(String),
    /// A setting out of its range ([`IntakeMonitorConfig::validate`]).
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error("intake monitor: invalid setting `{key}`: {reason}")]
    Setting { key: &'static str, reason: String },
    #[error("intake monitor: {0}")]
    Filter(#[from] fdd_estimators::ConfigError),
    #[error("intake monitor: {0}")]
    Diagnostics(#[from] fdd_diagnostics::ConfigError),
}

fn setting(key: &'static str, reason: impl Into<String>) -> IntakeMonitorError {
    IntakeMonitorError::Setting {
        key,
        reason: reason.into(),
    }
}

/// One crank segment's inputs and readings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Engine speed (rpm).
    pub speed_rpm: f64,
    /// Throttle opening (deg from the closed plate).
    pub throttle_deg: f64,
    /// EGR command (0..1).
    pub egr_cmd: f64,
    /// MAP reading (Pa).
    pub map_pa: f64,
    /// MAF reading (kg/s).
    pub maf_kg_s: f64,
}

/// A CUSUM that also remembers when each side was last zero (the onset estimate).
#[derive(Debug, Clone)]
struct OnsetCusum {
    cusum: Cusum,
    upper_zero: u64,
    lower_zero: u64,
}

impl OnsetCusum {
    /// Bias and threshold are checked by [`IntakeMonitorConfig::validate`] (each in its range,
    /// a finite run length).
    fn new(delta: f64, h: f64) -> Result<Self, IntakeMonitorError> {
        let arl = two_sided_arl(0.0, delta / 2.0, h);
        Ok(Self {
            cusum: Cusum::new(&CusumConfig {
                min_bias_sigma: delta,
                mean_steps_between_false_alarms: Some(arl),
                false_alarm_rate: None,
            })?,
            upper_zero: 0,
            lower_zero: 0,
        })
    }

    /// Steps the CUSUM at segment `k`; on an alarm also returns the onset segment.
    fn step(&mut self, k: u64, z: f64, enabled: bool) -> (TestResult, Option<u64>) {
        let r = self.cusum.step(z, enabled && z.is_finite());
        let onset = if r.verdict == Verdict::Failed {
            match self.cusum.alarm_side() {
                Some(CusumSide::Upper) => Some(self.upper_zero + 1),
                _ => Some(self.lower_zero + 1),
            }
        } else {
            None
        };
        if self.cusum.upper() == 0.0 {
            self.upper_zero = k;
        }
        if self.cusum.lower() == 0.0 {
            self.lower_zero = k;
        }
        (r, onset)
    }

    fn reset(&mut self) {
        self.cusum.reset();
        self.upper_zero = 0;
        self.lower_zero = 0;
    }
}

/// Windowed NIS sum.
#[derive(Debug, Clone)]
struct NisWindow {
    buf: [f64; NIS_RING],
    cap: usize,
    len: usize,
    head: usize,
    sum: f64,
}

impl NisWindow {
    fn new(cap: usize) -> Self {
        Self {
            buf: [0.0; NIS_RING],
            cap: cap.clamp(1, NIS_RING),
            len: 0,
            head: 0,
            sum: 0.0,
        }
    }

    fn step(&mut self, nis: f64, cap: f64, threshold: f64) -> TestResult {
        if !nis.is_finite() {
            return TestResult::NOT_TESTED;
        }
        let v = nis.min(cap);
        if self.len == self.cap {
            self.sum -= self.buf[self.head];
        }
        self.buf[self.head] = v;
        self.head = (self.head + 1) % self.cap;
        self.len = (self.len + 1).min(self.cap);
        self.sum += v;
        let failed = self.len == self.cap && self.sum > threshold;
        TestResult {
            value: self.sum,
            min: 0.0,
            max: threshold,
            verdict: if failed {
                Verdict::Failed
            } else {
                Verdict::Passed
            },
        }
    }

    fn clear(&mut self) {
        self.len = 0;
        self.head = 0;
        self.sum = 0.0;
    }
}

/// An open isolation episode.
#[derive(Debug, Clone, Copy)]
struct Episode {
    alarm_s: f64,
    /// The last time a residual test failed during the episode (s).
    last_alarm_s: f64,
    cmd_sum: f64,
    segments: u64,
}

/// Whose estimate the monitor outputs (see [`IntakeMonitor::output_filter`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OutputFilter {
    Primary,
    MapLocal,
    MafLocal,
}

/// MAP (0) and MAF (1): the index of the per-sensor state.
const MAP: usize = 0;
const MAF: usize = 1;

/// What is decided about one sensor by its own checks (circuit, frozen, noise).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct SensorState {
    low: bool,
    high: bool,
    frozen: bool,
    noisy: bool,
    /// Time (s) the sensor has read plausibly since it last did not (for healing).
    healthy_s: f64,
    /// Segments in a row its reading has been kept out of the filters.
    out_run: u32,
}

impl SensorState {
    fn any(&self) -> bool {
        self.low || self.high || self.frozen || self.noisy
    }
}

/// The noise tests' difference of four consecutive readings (oldest last),
/// `(y0 - y1 - y2 + y3) / 2`: zero for a constant and for a linear trend, like a second
/// difference, and also zero for a component alternating from one segment to the next. The
/// intake pulsation aliased by the segment sampling can be such a component (held-out version
/// 6, log 24: MAP readings alternating by +-0.7 kPa at 2000 rpm), and a second difference
/// amplifies it four times (white noise only sqrt(6) times), so a noise test on second
/// differences took the pulsation at some speeds for a noisy sensor. White noise of variance R
/// gives variance R. `fdd calibrate` estimates the noise levels with the same difference.
pub fn noise_difference(y0: f64, y1: f64, y2: f64, y3: f64) -> f64 {
    0.5 * (y0 - y1 - y2 + y3)
}

/// A residual fault decided and not healed.
#[derive(Debug, Clone, Copy)]
struct ResidualFault {
    /// As decided (the size refined by later refits).
    fit: Fit,
    event: usize,
    comp: Compensation,
    /// CUSUM of the log-likelihood ratio of "gone" against "still there".
    heal_llr: f64,
    /// Time (s) the heal statistic has been at its threshold while the residuals without the
    /// fault's effect look fault-free.
    gone_s: f64,
    /// Exponentially weighted means (over heal_s) of the normalized pressure and throttle-flow
    /// residuals with this fault's effect added back (what they would be without its
    /// accommodation): near zero once it has gone; a fault still there but sized wrongly at a
    /// new operating point leaves them off zero.
    raw_p: f64,
    raw_w: f64,
    /// Time (s) since the throttle-flow residual was last tested.
    raw_w_age_s: f64,
    /// Sensor faults: the hypothesis bank from the fault's onset, fed since the decision with
    /// the raw residuals (this fault's predicted effect added back). A refit of the decided
    /// sensor error is this bank's fit: the whole error model (offset, gain, drift rate) from
    /// the onset, rather than the sum of increments fitted on short windows of compensated
    /// residuals, which wandered (a MAF gain refitted 0.30, -0.11, -0.41, 0.04 on one fault).
    raw_bank: HypothesisBank,
}

/// An exponentially weighted ratio `sum num / sum den`, learned over a time constant.
#[derive(Debug, Clone, Copy, Default)]
struct LearnedRatio {
    num: f64,
    den: f64,
    /// Learning time (s).
    time_s: f64,
}

impl LearnedRatio {
    fn update(&mut self, num: f64, den: f64, dt: f64, tau: f64) {
        if !(num.is_finite() && den.is_finite() && den > 0.0) {
            return;
        }
        let a = (-dt / tau).exp();
        self.num = a * self.num + num * dt;
        self.den = a * self.den + den * dt;
        self.time_s += dt;
    }

    fn value(&self, limit: f64) -> f64 {
        if self.den > 0.0 {
            (self.num / self.den).clamp(1.0 - limit, 1.0 + limit)
        } else {
            1.0
        }
    }
}

/// The noise test of one sensor: the learned level of its normalized squared innovation and a
/// CUSUM of the log-likelihood ratio of a larger variance.
#[derive(Debug, Clone, Copy)]
struct NoiseTest {
    /// The sensor's noise variance relative to the configured R (learned: the exponentially
    /// weighted mean of `excess`, so the first estimates are plain means).
    level: f64,
    learned: LearnedRatio,
    cusum: f64,
    /// This segment's capped normalized squared innovation (NaN: none).
    z2: f64,
    /// This segment's squared innovation less its prediction part, relative to R (what the
    /// level learns from; NaN: none).
    excess: f64,
}

impl Default for NoiseTest {
    fn default() -> Self {
        Self {
            level: 1.0,
            learned: LearnedRatio::default(),
            cusum: 0.0,
            z2: f64::NAN,
            excess: f64::NAN,
        }
    }
}

/// What a segment's filters offer the learned corrections, applied after the decision (only a
/// quiet segment teaches).
#[derive(Debug, Clone, Copy)]
struct LearnSample {
    /// MAF the MAP-only filter implies and the MAF reading (kg/s).
    implied_maf: f64,
    maf: f64,
    /// Corrected MAF and the throttle model's lagged flow (kg/s), while choked; NaN otherwise.
    choked_maf: f64,
    choked_model: f64,
}

type Central = Ekf<IntakeModel, MapMafSensors, 6, 2, 3>;
type Pair = DecentralizedPair<IntakeModel, MapSensor, MafSensor, 6, 1, 1, 3>;
type Federated = FederatedFilter<IntakeModel, MapSensor, MafSensor, 6, 1, 1, 3>;

/// The three filters, built together from one initial estimate.
#[derive(Debug, Clone)]
struct Filters {
    central: Central,
    pair: Pair,
    federated: Federated,
}

/// The monitor. Everything is sized at construction; a segment without a status change
/// allocates nothing.
pub struct IntakeMonitor {
    cfg: IntakeMonitorConfig,
    model: IntakeModel,
    inputs: [SignalId; 5],
    period_ns: u64,
    q: SMatrix<f64, 6, 6>,
    r_map: f64,
    r_maf: f64,
    /// `R T_m / V_m` (Pa/kg).
    gain: f64,
    filters: Option<Filters>,
    last_t_ns: Option<u64>,
    segment: u64,
    skipped: u64,
    rejected: u64,
    w_model_lag: f64,
    dw_dp_lag: f64,
    choked_run: u32,
    flow_run: u32,
    cusum_p: OnsetCusum,
    cusum_x: OnsetCusum,
    cusum_t: OnsetCusum,
    nis_central: NisWindow,
    nis_federated: NisWindow,
    /// Identical consecutive MAP / MAF readings (a live sensor's noise never repeats).
    map_frozen_run: u32,
    maf_frozen_run: u32,
    last_map: f64,
    last_maf: f64,
    /// The readings before the last (for the noise tests' differences).
    prev_map: f64,
    prev_maf: f64,
    /// The readings before those (for the noise tests' four-segment difference).
    prev2_map: f64,
    prev2_maf: f64,
    /// Their noise differences this segment ([`noise_difference`]).
    map_noise_diff: f64,
    maf_noise_diff: f64,
    /// Rates of change of the readings (Pa/s, kg/s per s) over the last segment.
    map_rate: f64,
    maf_rate: f64,
    /// Throttle opening of the last segment and segments since it last moved fast.
    last_throttle: f64,
    /// The throttle's rate of change (deg/s) over the last segment (NaN before two readings).
    last_throttle_rate: f64,
    throttle_steady_run: u32,
    map_low_run: u32,
    map_high_run: u32,
    maf_low_run: u32,
    maf_high_run: u32,
    /// Per sensor (MAP, MAF): its own decisions.
    sensors: [SensorState; 2],
    /// Learned corrections: MAF to implied flow, throttle model to MAF.
    maf_ratio: LearnedRatio,
    throttle_ratio: LearnedRatio,
    /// Noise tests (MAP, MAF).
    noise: [NoiseTest; 2],
    /// Time (s) the residual tests still wait after the filters started again.
    settle_s: f64,
    /// The last segment of the filters' settling after they last started again (0: never):
    /// the onset scan looks no further back.
    restart_segment: u64,
    /// The centralized EKF's estimate of the sensors' outputs (p_mes, W_mes) before the last
    /// segment's step (for the circuit checks' settling allowance).
    est_prev: [f64; 2],
    /// What this segment's filters offer the learned corrections.
    learn: Option<LearnSample>,
    history: RecordRing,
    scan: OnsetScan,
    /// The isolation's state this segment: PreFailed while an episode is open (value: the lead
    /// of the best hypothesis over the runner-up), Failed when it names a fault.
    isolation: TestResult,
    episode: Option<Episode>,
    /// Residual faults decided and not healed, per hypothesis ([`IntakeFault::index`]).
    residual: [Option<ResidualFault>; 4],
    /// The group DTC fails (detected, not isolated).
    group: bool,
    /// Per event: the test result that qualified its fault and the isolation candidates.
    ev_result: [TestResult; EVENTS],
    ev_cands: [[(&'static str, f64); 4]; EVENTS],
    ev_ncand: [usize; EVENTS],
    /// The diagnosis scores of the latest segment (see [`Output::Diagnosis`]).
    scores: [f64; 4],
    events: MonitorEvents,
}

/// What the residual tests gave this segment.
#[derive(Debug, Clone, Copy, Default)]
struct ResidualOutcome {
    /// The residual tests ran (both sensors in use, the corrections learned, the filters
    /// settled).
    tested: bool,
    /// The earliest onset estimate of the tests failing this segment.
    alarm: Option<u64>,
}

impl IntakeMonitor {
    /// Builds the monitor on the intake model's parameters (the filters use the paper's
    /// random-walk throttle flow whatever `model`'s mode), reading the named signals of `table`.
    pub fn new(
        model: &IntakeModel,
        cfg: &IntakeMonitorConfig,
        table: &SignalTable,
    ) -> Result<Self, IntakeMonitorError> {
        let id = |name: &str| {
            table
                .id(name)
                .ok_or_else(|| IntakeMonitorError::MissingSignal(name.to_string()))
        };
        let inputs = [
            id(&cfg.speed_signal)?,
            id(&cfg.throttle_signal)?,
            id(&cfg.egr_signal)?,
            id(&cfg.map_signal)?,
            id(&cfg.maf_signal)?,
        ];
        cfg.validate(&KeyPath::file(SETTINGS_ORIGIN).key("monitor"))?;
        let model = IntakeModel::new(model.params().clone(), ThrottleFlow::RandomWalk)
            .map_err(|reason| setting("model", reason))?;
        let p = model.params();
        let q_std = SVector::<f64, 6>::from(cfg.q_std);
        let dtcs = [
            &cfg.dtc_map_performance,
            &cfg.dtc_map_low,
            &cfg.dtc_map_high,
            &cfg.dtc_maf_performance,
            &cfg.dtc_maf_low,
            &cfg.dtc_maf_high,
            &cfg.dtc_egr_insufficient,
            &cfg.dtc_egr_excessive,
            &cfg.dtc_leak,
            &cfg.dtc_group,
            &cfg.dtc_egr_slow_response,
        ];
        let specs: Vec<EventSpec<'_>> = EVENT_NAMES
            .iter()
            .zip(dtcs)
            .map(|(name, dtc)| EventSpec::internal(name, dtc, 2))
            .collect();
        let events = MonitorEvents::new(&specs)?.with_estimates(&ESTIMATES);
        let mut monitor = Self {
            period_ns: (cfg.poll_period_s * 1e9).round().max(1.0) as u64,
            q: SMatrix::from_diagonal(&q_std.component_mul(&q_std)),
            r_map: cfg.map_noise_pa * cfg.map_noise_pa,
            r_maf: cfg.maf_noise_kg_s * cfg.maf_noise_kg_s,
            gain: p.gas_constant_j_per_kg_k * p.manifold_temperature_k / p.manifold_volume_m3,
            filters: None,
            last_t_ns: None,
            segment: 0,
            skipped: 0,
            rejected: 0,
            w_model_lag: f64::NAN,
            dw_dp_lag: 0.0,
            choked_run: 0,
            flow_run: 0,
            cusum_p: OnsetCusum::new(
                cfg.pressure_cusum_min_bias_sigma,
                cfg.pressure_cusum_threshold,
            )?,
            cusum_x: OnsetCusum::new(cfg.flow_cusum_min_bias_sigma, cfg.flow_cusum_threshold)?,
            cusum_t: OnsetCusum::new(
                cfg.throttle_cusum_min_bias_sigma,
                cfg.throttle_cusum_threshold,
            )?,
            nis_central: NisWindow::new(cfg.nis_window),
            nis_federated: NisWindow::new(cfg.nis_window),
            map_frozen_run: 0,
            maf_frozen_run: 0,
            last_map: f64::NAN,
            last_maf: f64::NAN,
            prev_map: f64::NAN,
            prev_maf: f64::NAN,
            prev2_map: f64::NAN,
            prev2_maf: f64::NAN,
            map_noise_diff: f64::NAN,
            maf_noise_diff: f64::NAN,
            map_rate: 0.0,
            maf_rate: 0.0,
            last_throttle: f64::NAN,
            last_throttle_rate: f64::NAN,
            throttle_steady_run: 0,
            map_low_run: 0,
            map_high_run: 0,
            maf_low_run: 0,
            maf_high_run: 0,
            sensors: [SensorState::default(); 2],
            maf_ratio: LearnedRatio::default(),
            throttle_ratio: LearnedRatio::default(),
            noise: [NoiseTest::default(); 2],
            settle_s: 0.0,
            restart_segment: 0,
            est_prev: [f64::NAN; 2],
            learn: None,
            history: RecordRing::new(HISTORY),
            scan: OnsetScan::default(),
            isolation: TestResult::NOT_TESTED,
            episode: None,
            residual: [None; 4],
            group: false,
            ev_result: [TestResult::NOT_TESTED; EVENTS],
            ev_cands: [[("", 0.0); 4]; EVENTS],
            ev_ncand: [0; EVENTS],
            scores: [0.0; 4],
            events,
            inputs,
            model,
            cfg: cfg.clone(),
        };
        // Check the filter settings now rather than at the first segment.
        let idle = IntakeInput::new(800.0, 2.0, 0.0);
        monitor.build_filters(&idle)?;
        monitor.filters = None;
        Ok(monitor)
    }

    /// One fault named and not healed (a residual fault first, then a circuit, a frozen and a
    /// noisy sensor, MAP before MAF); see [`IntakeMonitor::decisions`] for all.
    pub fn decision(&self) -> Option<IntakeDecision> {
        self.decisions().flatten().next()
    }

    /// Every fault named and not healed: the residual faults in hypothesis order, then per
    /// sensor (MAP, MAF) its circuit, frozen and noisy faults.
    pub fn decisions(&self) -> impl Iterator<Item = Option<IntakeDecision>> + '_ {
        let residual = self.residual.iter().map(|r| {
            r.map(|r| IntakeDecision::Residual {
                fit: r.fit,
                event: r.event,
            })
        });
        let sensors = self.sensors.iter().enumerate().flat_map(|(i, s)| {
            let base = 3 * i;
            [
                s.low.then_some(IntakeDecision::Circuit { event: base + 1 }),
                s.high
                    .then_some(IntakeDecision::Circuit { event: base + 2 }),
                s.frozen.then_some(IntakeDecision::Frozen { event: base }),
                s.noisy.then_some(IntakeDecision::Noisy { event: base }),
            ]
        });
        residual.chain(sensors)
    }

    /// Whether a fault of sensor `j` (0 MAP, 1 MAF) is named and not healed: its
    /// range/performance (residual, frozen or noisy) or a circuit DTC.
    fn sensor_named(&self, j: usize) -> bool {
        self.decisions()
            .flatten()
            .any(|d| (3 * j..3 * j + 3).contains(&d.event()))
    }

    /// The hypotheses ranked by their statistic, as of the last segment of the current or last
    /// isolation episode.
    pub fn ranked_hypotheses(&self) -> [Fit; 4] {
        self.scan.ranked()
    }

    /// The learned corrections: the factor on the MAF reading and the factor on the throttle
    /// model's flow (1 before anything is learned).
    pub fn learned_corrections(&self) -> (f64, f64) {
        (
            self.maf_ratio.value(self.cfg.adapt_limit),
            self.throttle_ratio.value(self.cfg.adapt_limit),
        )
    }

    /// Whether the group DTC fails now.
    pub fn group_failed(&self) -> bool {
        self.group
    }

    /// Segments processed, skipped for a refused input or reading, and refused by a filter.
    pub fn counts(&self) -> (u64, u64, u64) {
        (self.segment, self.skipped, self.rejected)
    }

    /// The centralized EKF's state, if the filters run.
    pub fn centralized_state(&self) -> Option<&IntakeState> {
        self.filters.as_ref().map(|f| f.central.state())
    }

    fn build_filters(&mut self, u: &IntakeInput) -> Result<(), IntakeMonitorError> {
        let x0 = self
            .model
            .equilibrium(u)
            .ok_or_else(|| setting("model", format!("no equilibrium at {u:?}")))?;
        let w0 = x0[X_WTHR].abs().max(1e-4);
        let s = &self.cfg.p0_std;
        let p0_std = SVector::<f64, 6>::from([s[0], s[1], s[2] * w0, s[3] * w0, s[4], s[5]]);
        let p0 = SMatrix::<f64, 6, 6>::from_diagonal(&p0_std.component_mul(&p0_std));
        let noise = FusionNoise {
            q: self.q,
            r1: Matrix1::new(self.r_map),
            r2: Matrix1::new(self.r_maf),
        };
        let central = Ekf::new(
            self.model.clone(),
            MapMafSensors,
            x0,
            p0,
            self.q,
            Matrix2::from_diagonal(&Vector2::new(self.r_map, self.r_maf)),
        )?;
        let pair = DecentralizedPair::new(self.model.clone(), MapSensor, MafSensor, x0, p0, noise)?;
        let federated = FederatedFilter::new(
            self.model.clone(),
            MapSensor,
            MafSensor,
            x0,
            p0,
            noise,
            self.cfg.federated_shares,
        )?;
        self.filters = Some(Filters {
            central,
            pair,
            federated,
        });
        self.w_model_lag = f64::NAN;
        self.flow_run = 0;
        Ok(())
    }

    /// Circuit range check of one reading: updates the run counters and says whether the
    /// reading is in range.
    fn circuit(run_low: &mut u32, run_high: &mut u32, low: bool, high: bool) -> bool {
        *run_low = if low { *run_low + 1 } else { 0 };
        *run_high = if high { *run_high + 1 } else { 0 };
        !(low || high)
    }

    /// Runs one crank segment ending at `t_ns` (freeze frames get no signal values; the
    /// runtime's steps pass the signal table).
    pub fn process_segment(&mut self, t_ns: u64, seg: &Segment, out: &mut OutputSink<'_>) {
        self.process_segment_with(t_ns, seg, None, out);
    }

    /// Runs one crank segment ending at `t_ns`, with the signal table for freeze frames.
    pub fn process_segment_with(
        &mut self,
        t_ns: u64,
        seg: &Segment,
        signals: Option<&SignalTable>,
        out: &mut OutputSink<'_>,
    ) {
        let now_s = t_ns as f64 * 1e-9;
        self.segment += 1;
        let k = self.segment;
        let u = IntakeInput::new(seg.speed_rpm, seg.throttle_deg, seg.egr_cmd);
        if let Err(e) = self.model.check_input(&u) {
            // Engine stopped, a speed sensor fault or a broken input: no step, no verdict.
            self.skipped += 1;
            let (value, min, max) = match e {
                fdd_estimators::models::intake::IntakeInputError::NonFinite { value, .. } => {
                    (value, f64::NAN, f64::NAN)
                }
                fdd_estimators::models::intake::IntakeInputError::OutOfRange {
                    value,
                    min,
                    max,
                    ..
                } => (value, min, max),
            };
            if self.skipped == 1 {
                tracing::warn!(time_s = now_s, "intake monitor: segment skipped: {e}");
            }
            out(Output::Test {
                test: "intake_input_range",
                result: TestResult {
                    value,
                    min,
                    max,
                    verdict: Verdict::Failed,
                },
            });
            return;
        }

        if !(seg.map_pa.is_finite() && seg.maf_kg_s.is_finite()) {
            // A NaN or infinite reading (the signal table refuses them; a host calling this
            // directly may not): no step, no verdict.
            self.skipped += 1;
            let value = if seg.map_pa.is_finite() {
                seg.maf_kg_s
            } else {
                seg.map_pa
            };
            out(Output::Test {
                test: "intake_input_range",
                result: TestResult {
                    value,
                    min: f64::NAN,
                    max: f64::NAN,
                    verdict: Verdict::Failed,
                },
            });
            return;
        }
        let dt = IntakeModel::segment_dt(seg.speed_rpm);

        // Rates of change of the readings (for the residuals' transient allowance).
        let rate = |v: f64, last: f64| {
            if last.is_finite() {
                (v - last) / dt
            } else {
                0.0
            }
        };
        self.map_rate = rate(seg.map_pa, self.last_map);
        self.maf_rate = rate(seg.maf_kg_s, self.last_maf);
        let throttle_rate = rate(seg.throttle_deg, self.last_throttle);
        let rate_change = if self.last_throttle_rate.is_finite() {
            (throttle_rate - self.last_throttle_rate).abs()
        } else {
            0.0
        };
        let fast = throttle_rate.abs() > self.cfg.noise_max_throttle_rate_deg_s
            || rate_change > self.cfg.noise_max_throttle_rate_change_deg_s;
        self.last_throttle_rate = if self.last_throttle.is_finite() {
            throttle_rate
        } else {
            f64::NAN
        };
        self.last_throttle = seg.throttle_deg;
        self.throttle_steady_run = if fast {
            0
        } else {
            self.throttle_steady_run.saturating_add(1)
        };

        // Frozen readings: a sensor stuck at one value (the ADC code of a live sensor moves
        // with its noise every segment).
        self.map_frozen_run = if seg.map_pa == self.last_map {
            self.map_frozen_run + 1
        } else {
            0
        };
        self.maf_frozen_run = if seg.maf_kg_s == self.last_maf {
            self.maf_frozen_run + 1
        } else {
            0
        };
        self.map_noise_diff =
            noise_difference(seg.map_pa, self.last_map, self.prev_map, self.prev2_map);
        self.maf_noise_diff =
            noise_difference(seg.maf_kg_s, self.last_maf, self.prev_maf, self.prev2_maf);
        (self.prev2_map, self.prev2_maf) = (self.prev_map, self.prev_maf);
        (self.prev_map, self.prev_maf) = (self.last_map, self.last_maf);
        (self.last_map, self.last_maf) = (seg.map_pa, seg.maf_kg_s);

        let frozen_result = |run: u32, limit: u32| TestResult {
            value: f64::from(run),
            min: 0.0,
            max: f64::from(limit - 1),
            verdict: if run >= limit {
                Verdict::Failed
            } else {
                Verdict::Passed
            },
        };
        out(Output::Test {
            test: "intake_map_frozen",
            result: frozen_result(self.map_frozen_run, self.cfg.frozen_segments),
        });
        out(Output::Test {
            test: "intake_maf_frozen",
            result: frozen_result(self.maf_frozen_run, self.cfg.frozen_segments),
        });

        // Circuit range checks (the readings that fail them never reach the filters).
        let p_a = self.model.params().ambient_pressure_pa;
        // A reading beyond a limit counts against the sensor only where the model rules such a
        // value out (NaN always does): low, the filter's estimate of the sensor's output
        // (p_mes, W_mes) less 3 sigma above the limit plus a margin; high, that estimate plus 3
        // sigma below the limit less a margin. Before the filters run, the model's steady state
        // for this segment's inputs stands for the estimate (computed only for such a reading).
        // While the estimate still moves (a tip-in or tip-out the filters follow from the
        // other sensor alone), it is given ESTIMATE_SETTLE_SEGMENTS of its last change more.
        let est_prev = self.est_prev;
        // With the other sensor named failed, the filters' estimate of this one's output leans
        // on failed readings (a stuck MAF holds the pressure estimate wherever it stuck, and a
        // shorted MAP then looks like wide-open throttle): the model's steady state for the
        // inputs judges instead.
        let other_failed = [self.sensor_named(1), self.sensor_named(0)];
        let ruled_out = |i: usize, limit: f64, above: bool| match &self.filters {
            Some(f) if !other_failed[usize::from(i != 1)] => {
                let sigma = f.central.covariance()[(i, i)].max(0.0).sqrt();
                let x = f.central.state()[i];
                let prev = if i == 1 { est_prev[0] } else { est_prev[1] };
                let moving = if prev.is_finite() {
                    ESTIMATE_SETTLE_SEGMENTS * (x - prev).abs()
                } else {
                    0.0
                };
                if above {
                    x - 3.0 * sigma - moving > limit
                } else {
                    x + 3.0 * sigma + moving < limit
                }
            }
            _ => self.model.equilibrium(&u).is_none_or(|x| {
                if above {
                    x[i] > limit
                } else {
                    x[i] < limit
                }
            }),
        };
        let map_high_limit = self.cfg.map_high_ratio * p_a;
        let map_low = seg.map_pa.is_nan()
            || (seg.map_pa < self.cfg.map_low_pa
                && ruled_out(1, self.cfg.map_low_pa + self.cfg.map_low_margin_pa, true));
        let map_high = seg.map_pa > map_high_limit
            && ruled_out(1, map_high_limit - self.cfg.map_high_margin_pa, false);
        // A MAP reading within its circuit range, from a sensor not named failed, also rules a
        // low MAF reading out through the throttle model (THROTTLE_MODEL_LOW_SHARE).
        let maf_low_limit = self.cfg.maf_low_kg_s + self.cfg.maf_low_margin_kg_s;
        let map_trusted =
            (self.cfg.map_low_pa..=map_high_limit).contains(&seg.map_pa) && !self.sensor_named(MAP);
        let maf_low = seg.maf_kg_s.is_nan()
            || (seg.maf_kg_s < self.cfg.maf_low_kg_s
                && ((map_trusted
                    && THROTTLE_MODEL_LOW_SHARE
                        * self.model.throttle_flow(seg.map_pa, seg.throttle_deg)
                        > maf_low_limit)
                    || ruled_out(3, maf_low_limit, true)));
        let map_in_range = Self::circuit(
            &mut self.map_low_run,
            &mut self.map_high_run,
            map_low,
            map_high,
        );
        let maf_in_range = Self::circuit(
            &mut self.maf_low_run,
            &mut self.maf_high_run,
            maf_low,
            seg.maf_kg_s > self.cfg.maf_high_kg_s,
        );
        let circuit_result = |ok: bool, v: f64, lo: f64, hi: f64| TestResult {
            value: v,
            min: lo,
            max: hi,
            verdict: if ok { Verdict::Passed } else { Verdict::Failed },
        };
        out(Output::Test {
            test: "intake_map_circuit",
            result: circuit_result(
                map_in_range,
                seg.map_pa,
                self.cfg.map_low_pa,
                map_high_limit,
            ),
        });
        out(Output::Test {
            test: "intake_maf_circuit",
            result: circuit_result(
                maf_in_range,
                seg.maf_kg_s,
                self.cfg.maf_low_kg_s,
                self.cfg.maf_high_kg_s,
            ),
        });

        // A reading is used when it lies within the circuit limits (one beyond them never
        // reaches the filters, whether or not the model rules it out: an open line's 0 V must
        // not pull them along) and its sensor has no circuit or frozen fault that has not
        // healed.
        let map_inside = seg.map_pa >= self.cfg.map_low_pa && seg.map_pa <= map_high_limit;
        let maf_inside =
            seg.maf_kg_s >= self.cfg.maf_low_kg_s && seg.maf_kg_s <= self.cfg.maf_high_kg_s;
        let usable = |s: &SensorState| !(s.low || s.high || s.frozen);
        let map_ok = map_in_range && map_inside && usable(&self.sensors[MAP]);
        let maf_ok = maf_in_range && maf_inside && usable(&self.sensors[MAF]);
        // A sensor back in use after a long absence: the filters start again.
        let persist = self.cfg.circuit_persist_segments;
        let mut restart = false;
        for (s, ok) in [(MAP, map_ok), (MAF, maf_ok)] {
            let st = &mut self.sensors[s];
            if ok {
                restart |= st.out_run >= persist;
                st.out_run = 0;
            } else {
                st.out_run = st.out_run.saturating_add(1);
            }
        }
        if restart {
            self.restart_filters();
        }

        // Decided residual faults are taken out of what the filters see: the sensors' readings
        // corrected, the decided EGR position as the model's input, the leak's flow added to
        // the metered air (not for the throttle-model residual: the throttle does not pass it).
        let (seg_c, maf_sensor) = self.accommodate(seg, dt);
        let u_c = IntakeInput::new(seg_c.speed_rpm, seg_c.throttle_deg, seg_c.egr_cmd);

        // The estimate before this segment's step: the next segment's circuit checks see how
        // much the step moved it.
        self.est_prev = self.filters.as_ref().map_or([f64::NAN; 2], |f| {
            let x = f.central.state();
            [x[X_PMES], x[X_WMES]]
        });
        let mut res = ResidualOutcome::default();
        self.learn = None;
        if map_ok && maf_ok {
            if self.filters.is_none() && self.build_filters(&u_c).is_err() {
                self.skipped += 1;
                return;
            }
            res = self.run_filters(k, dt, &u_c, &seg_c, maf_sensor, seg.egr_cmd, out);
        } else {
            // A refused reading: the filters go on with the other sensor (a local filter
            // without its sensor runs on the model), no residual test this segment.
            self.skipped += 1;
            if self.filters.is_some() {
                let maf_f = seg_c.maf_kg_s * self.maf_ratio.value(self.cfg.adapt_limit);
                self.run_filters_partial(&u_c, seg_c.map_pa, maf_f, map_ok, maf_ok);
            }
        }
        if self.settle_s > 0.0 {
            self.restart_segment = k;
        }
        self.settle_s = (self.settle_s - dt).max(0.0);

        self.isolation = TestResult::NOT_TESTED;
        let mut group_passed = false;
        // A reading repeated beyond a circuit limit is a circuit fault in the making (an open
        // or shorted line reads its rail exactly): the frozen check waits for that judgement.
        self.decide_sensors(
            dt,
            [map_in_range, maf_in_range],
            [map_inside, maf_inside],
            &mut group_passed,
        );
        self.decide_residual(now_s, k, dt, seg, &res, &mut group_passed);
        if self.isolation.verdict != Verdict::NotTested {
            out(Output::Test {
                test: "intake_isolation",
                result: self.isolation,
            });
        }
        self.learn_corrections(dt, &res);

        let quiet = res.tested && res.alarm.is_none() && self.episode.is_none();
        let mut verdicts = [Verdict::NotTested; EVENTS];
        let runs = [
            (self.map_low_run, self.map_high_run, self.map_frozen_run),
            (self.maf_low_run, self.maf_high_run, self.maf_frozen_run),
        ];
        let pick = |failed: bool, passed: bool| {
            if failed {
                Verdict::Failed
            } else if passed {
                Verdict::Passed
            } else {
                Verdict::NotTested
            }
        };
        for (s, fault) in [(MAP, IntakeFault::MapSensor), (MAF, IntakeFault::MafSensor)] {
            let st = self.sensors[s];
            let (low, high, frozen) = runs[s];
            let base = 3 * s;
            verdicts[base + 1] = pick(st.low, low == 0);
            verdicts[base + 2] = pick(st.high, high == 0);
            verdicts[base] = pick(
                st.frozen || st.noisy || self.residual[fault.index()].is_some(),
                quiet && frozen == 0,
            );
        }
        let egr = self.residual[IntakeFault::EgrValve.index()].map(|f| f.event);
        verdicts[6] = pick(egr == Some(6), quiet && egr.is_none());
        verdicts[7] = pick(egr == Some(7), quiet && egr.is_none());
        verdicts[EGR_SLOW] = pick(egr == Some(EGR_SLOW), quiet && egr.is_none());
        verdicts[8] = pick(self.residual[IntakeFault::Leak.index()].is_some(), quiet);
        verdicts[GROUP] = pick(self.group, quiet || group_passed);

        let est = self.estimate(seg, map_ok, maf_ok);
        let values = FreezeValues {
            signals,
            estimates: &est.as_ref().map_or([f64::NAN; 2], |e| [e.pm, e.w]),
        };
        for (e, verdict) in verdicts.into_iter().enumerate() {
            let failed = verdict == Verdict::Failed;
            let result = if failed {
                TestResult {
                    verdict,
                    ..self.ev_result[e]
                }
            } else {
                TestResult {
                    value: 0.0,
                    min: 0.0,
                    max: 0.0,
                    verdict,
                }
            };
            let cands = self.ev_cands[e];
            let n = if failed { self.ev_ncand[e] } else { 0 };
            self.events
                .report_one(e, now_s, &result, &cands[..n], values, out);
        }
        if let Some(e) = est {
            e.emit(out);
        }
        if self.segment % CORRECTION_OUTPUT_SEGMENTS == 0 {
            self.emit_corrections(out);
        }
        let flagged = self.diagnose(res.alarm.is_some());
        out(Output::Diagnosis {
            flagged,
            scores: &self.scores,
        });
    }

    /// The segment as the filters see it with the decided residual faults taken out, and the
    /// MAF reading corrected for a decided MAF fault only (for the throttle-model residual).
    fn accommodate(&self, seg: &Segment, dt: f64) -> (Segment, f64) {
        let mut c = *seg;
        if let Some(f) = &self.residual[IntakeFault::MapSensor.index()] {
            c.map_pa = f.comp.correct(seg.map_pa, dt);
        }
        if let Some(f) = &self.residual[IntakeFault::MafSensor.index()] {
            c.maf_kg_s = f.comp.correct(seg.maf_kg_s, dt);
        }
        let maf_sensor = c.maf_kg_s;
        if let Some(p) = self.residual[IntakeFault::EgrValve.index()]
            .as_ref()
            .and_then(|f| f.comp.egr_position(seg.egr_cmd, dt))
        {
            c.egr_cmd = p;
        }
        if let Some(f) = &self.residual[IntakeFault::Leak.index()] {
            // The leak's flow at the pressure the MAP-only filter estimates (it follows the true
            // pressure under a leak).
            let p = self
                .filters
                .as_ref()
                .map_or(c.map_pa, |fl| fl.pair.local1().state()[X_PM]);
            c.maf_kg_s += f.comp.parameter * self.model.throttle_flow_area(p, 1.0).0;
        }
        (c, maf_sensor)
    }

    /// Records the fault of event `e`: the result that qualified it and its candidates.
    fn set_event(&mut self, e: usize, result: TestResult, cands: &[(&'static str, f64)]) {
        self.ev_result[e] = TestResult {
            verdict: Verdict::Failed,
            ..result
        };
        let n = cands.len().min(4);
        self.ev_cands[e] = [("", 0.0); 4];
        self.ev_cands[e][..n].copy_from_slice(&cands[..n]);
        self.ev_ncand[e] = n;
    }

    /// The residual tests start from zero (after a decision, a healing or a closed episode:
    /// what they saw is explained or gone).
    fn rearm(&mut self) {
        self.cusum_p.reset();
        self.cusum_x.reset();
        self.cusum_t.reset();
        self.nis_central.clear();
        self.nis_federated.clear();
    }

    /// The filters start again from the next segment's readings, with the tests rearmed: a
    /// sensor back in use after a long absence, or a decided residual fault healed (the states
    /// followed inputs with its compensation, which no longer hold).
    fn restart_filters(&mut self) {
        self.restart_segment = self.segment;
        self.filters = None;
        self.settle_s = RESTART_SETTLE_S;
        self.close_episode();
        self.rearm();
    }

    fn close_episode(&mut self) {
        self.episode = None;
    }

    /// Each sensor's own decisions: circuit low/high, frozen, noisy; and their healing.
    fn decide_sensors(
        &mut self,
        dt: f64,
        in_range: [bool; 2],
        inside: [bool; 2],
        group_passed: &mut bool,
    ) {
        let persist = self.cfg.circuit_persist_segments;
        let frozen_limit = self.cfg.frozen_segments;
        let noise_thr = self.cfg.noise_threshold;
        let inputs = [
            (
                MAP,
                self.map_low_run,
                self.map_high_run,
                self.map_frozen_run,
                in_range[MAP],
                IntakeFault::MapSensor,
            ),
            (
                MAF,
                self.maf_low_run,
                self.maf_high_run,
                self.maf_frozen_run,
                in_range[MAF],
                IntakeFault::MafSensor,
            ),
        ];
        for (s, low, high, frozen, in_range, fault) in inputs {
            let noisy = self.noise[s].cusum >= noise_thr;
            let base = 3 * s;
            let mut st = self.sensors[s];
            let mut new: Option<(usize, TestResult, &'static str)> = None;
            let run_result = |run: u32, limit: u32| TestResult {
                value: f64::from(run),
                min: 0.0,
                max: f64::from(limit.saturating_sub(1)),
                verdict: Verdict::Failed,
            };
            if !st.low && low >= persist {
                st.low = true;
                new = Some((base + 1, run_result(low, persist), EVENT_NAMES[base + 1]));
            } else if !st.high && high >= persist {
                st.high = true;
                new = Some((base + 2, run_result(high, persist), EVENT_NAMES[base + 2]));
            } else if !st.any() && low == 0 && high == 0 && inside[s] && frozen >= frozen_limit {
                st.frozen = true;
                new = Some((base, run_result(frozen, frozen_limit), fault.name()));
            } else if !st.any() && noisy {
                st.noisy = true;
                let r = TestResult {
                    value: self.noise[s].cusum,
                    min: 0.0,
                    max: noise_thr,
                    verdict: Verdict::Failed,
                };
                new = Some((base, r, fault.name()));
            }
            if let Some((e, result, cand)) = new {
                tracing::debug!(event = EVENT_NAMES[e], "intake sensor fault");
                st.healthy_s = 0.0;
                self.sensors[s] = st;
                self.set_event(e, result, &[(cand, 1.0)]);
                // The sensor fault explains a residual alarm, or leaves it untestable.
                if self.episode.is_some() || self.group {
                    self.close_episode();
                    *group_passed |= self.group;
                    self.group = false;
                    self.rearm();
                }
                continue;
            }
            if st.any() {
                let plausible = in_range && low == 0 && high == 0 && frozen == 0 && !noisy;
                st.healthy_s = if plausible { st.healthy_s + dt } else { 0.0 };
                if st.healthy_s >= self.cfg.heal_s {
                    tracing::debug!(sensor = fault.name(), "intake sensor fault healed");
                    st = SensorState {
                        out_run: st.out_run,
                        ..SensorState::default()
                    };
                    self.noise[s].cusum = 0.0;
                }
            }
            self.sensors[s] = st;
        }
    }

    /// The residual faults: healing of the decided ones, the isolation episode, the group DTC
    /// and new decisions.
    fn decide_residual(
        &mut self,
        now_s: f64,
        k: u64,
        dt: f64,
        seg: &Segment,
        res: &ResidualOutcome,
        group_passed: &mut bool,
    ) {
        let _ = dt;
        // Healing: the sequential test has favoured "gone" for heal_s. This segment's alarms
        // came from residuals with the healed fault still taken out: no episode opens on them.
        let mut healed = false;
        for i in 0..self.residual.len() {
            if let Some(f) = self.residual[i] {
                if f.gone_s >= self.cfg.heal_s {
                    tracing::debug!(
                        time_s = now_s,
                        fault = f.fit.fault.name(),
                        "intake residual fault healed"
                    );
                    self.residual[i] = None;
                    self.restart_filters();
                    *group_passed |= self.group;
                    self.group = false;
                    healed = true;
                }
            }
        }
        if healed {
            return;
        }
        // A decided fault that the sequential test already favours as gone explains what the
        // residuals do now (its compensation leaves the negative of its effect): no new
        // episode, and an open one waits, until it has healed.
        let healing = self.residual.iter().flatten().any(|f| f.gone_s > 0.0);
        if healing {
            return;
        }
        if self.episode.is_none() {
            if let Some(onset) = res.alarm {
                // Refit the hypotheses from the candidate onsets back from the estimate.
                let earliest = onset
                    .saturating_sub(ONSET_MARGIN)
                    .max(k.saturating_sub(ONSET_WINDOW_MAX))
                    // Records from before the filters last started again are of other filters.
                    .max(self.restart_segment + 1)
                    .max(1);
                self.scan = OnsetScan::with_modes(
                    earliest,
                    k,
                    self.residual[IntakeFault::Leak.index()].is_some(),
                    false,
                );
                let first = self.scan.earliest_onset();
                let back = (k + 1).saturating_sub(first) as usize;
                let held = back.min(self.history.len()) as u64;
                let (mut cmd_sum, mut n) = (0.0, 0u64);
                for (i, r) in self.history.last(back).enumerate() {
                    self.scan.push(k + 1 - held + i as u64, r);
                    cmd_sum += r.egr_cmd;
                    n += 1;
                }
                self.episode = Some(Episode {
                    alarm_s: now_s,
                    last_alarm_s: now_s,
                    cmd_sum,
                    segments: n,
                });
            }
            return;
        }
        let Some(mut ep) = self.episode else {
            return;
        };
        ep.cmd_sum += seg.egr_cmd;
        ep.segments += 1;
        // During the episode the tests watch whether the fault is still there: each failure
        // re-arms them; when they stay quiet for episode_quiet_s the alarm is over.
        if res.alarm.is_some() {
            ep.last_alarm_s = now_s;
            self.rearm();
        }
        self.episode = Some(ep);
        if res.tested && now_s - ep.last_alarm_s >= self.cfg.episode_quiet_s {
            self.close_episode();
            *group_passed |= self.group;
            self.group = false;
            self.isolation.verdict = Verdict::Passed;
            return;
        }
        let ranked = self.scan.ranked();
        let elapsed = now_s - ep.alarm_s;
        let best = ranked[0];
        let significant = best.glr >= self.cfg.isolation_min_glr;
        let lead = best.glr - ranked[1].glr;
        let clear =
            lead >= self.cfg.isolation_margin && lead >= self.cfg.isolation_margin_rel * best.glr;
        self.isolation = TestResult {
            value: best.glr - ranked[1].glr,
            min: 0.0,
            max: self.cfg.isolation_margin,
            verdict: Verdict::PreFailed,
        };
        // A repeated reading is a stuck sensor in the making: the frozen check names it.
        let repeating = self.map_frozen_run > 0 || self.maf_frozen_run > 0;
        // The hypotheses still in the race: within the group margin of the best, and never
        // fewer than those that keep the best from being named (the isolation margins).
        let margin = self
            .cfg
            .group_margin
            .max(self.cfg.isolation_margin)
            .max(self.cfg.group_margin_rel.max(self.cfg.isolation_margin_rel) * best.glr);
        let in_race = |f: &Fit| f.glr > 0.0 && f.glr >= best.glr - margin;
        // A decided fault still in the race: what is left of it after its compensation (a
        // size that has changed, a drift) explains the alarm as well as a new fault would.
        let decided_in_race = ranked
            .iter()
            .find(|f| self.residual[f.fault.index()].is_some() && in_race(f))
            .copied();
        // Only while the alarm is active: after the tests have gone quiet the statistics hold
        // data from a fault that may be over.
        let active = now_s - ep.last_alarm_s <= ALARM_ACTIVE_S;
        if elapsed >= self.cfg.isolation_min_s && significant && clear && !repeating && active {
            self.isolation.verdict = Verdict::Failed;
            let chosen = decided_in_race.unwrap_or(best);
            self.decide_fault(now_s, seg, &ranked, &chosen, &ep);
            self.close_episode();
            *group_passed |= self.group;
            self.group = false;
            self.rearm();
        } else if elapsed >= self.cfg.isolation_max_s && !significant {
            // Unexplained alarm: no hypothesis is significant. Close the episode.
            self.close_episode();
            *group_passed |= self.group;
            self.group = false;
            self.isolation.verdict = Verdict::Passed;
            self.rearm();
        } else if significant
            && !self.group
            && elapsed >= self.cfg.group_after_s
            && !repeating
            && active
        {
            // Detected but ambiguous: the group DTC, with the hypotheses still in the race.
            let mut cands = [("", 0.0); 4];
            let mut n = 0;
            let mut total = 0.0;
            let mut known = false;
            for f in ranked {
                if in_race(&f) {
                    cands[n] = (f.fault.name(), f.glr);
                    total += f.glr;
                    n += 1;
                    known |= self.residual[f.fault.index()].is_some();
                }
            }
            // A decided fault among them: its refit is still on its way (not a new fault).
            if !known && n > 0 {
                for c in &mut cands[..n] {
                    c.1 /= total;
                }
                let result = TestResult {
                    value: best.glr - ranked[1].glr,
                    min: 0.0,
                    max: self.cfg.isolation_margin,
                    verdict: Verdict::Failed,
                };
                self.set_event(GROUP, result, &cands[..n]);
                self.group = true;
                for f in ranked.iter().take(n) {
                    tracing::debug!(
                        time_s = now_s,
                        candidate = f.fault.name(),
                        glr = f.glr,
                        parameter = f.parameter,
                        gain = f.gain,
                        "intake group DTC candidate"
                    );
                }
            }
        }
        // Significant but ambiguous (two faults explain the data equally well, e.g. a leak and
        // an EGR valve stuck open while the EGR command does not move): the group DTC stands
        // and the episode goes on until the driving separates them.
    }

    /// Names the best hypothesis of `ranked`: a new residual fault (its DTC and its
    /// compensation), or the refinement of one already decided.
    fn decide_fault(
        &mut self,
        now_s: f64,
        seg: &Segment,
        ranked: &[Fit; 4],
        chosen: &Fit,
        ep: &Episode,
    ) {
        let best = *chosen;
        let i = best.fault.index();
        if let Some(mut f) = self.residual[i] {
            let y = match best.fault {
                IntakeFault::MafSensor => seg.maf_kg_s,
                _ => seg.map_pa,
            };
            let before = f.comp.magnitude(y);
            // The refit on this episode's compensated residuals, added to the decided size:
            // what tells a fault that has gone (most of it taken back).
            let mut increment = f.comp;
            increment.refine(&best, self.scan.best_bank(best.fault));
            // A refit that takes back most of the decided error, leaving one within what the
            // residuals allow for anyway: the fault has healed.
            let allowed = match best.fault {
                IntakeFault::MapSensor => {
                    self.cfg.map_noise_pa.hypot(self.cfg.pressure_model_rel * y)
                }
                IntakeFault::MafSensor => {
                    (self.cfg.maf_noise_rel * y).hypot(self.cfg.flow_model_rel * y)
                }
                // The leak's area whose flow at this pressure is within the flow allowance.
                _ => {
                    let unit = self.model.throttle_flow_area(seg.map_pa, 1.0).0;
                    let flow = (self.cfg.maf_noise_rel * seg.maf_kg_s)
                        .hypot(self.cfg.flow_model_rel * seg.maf_kg_s);
                    if unit > 0.0 {
                        flow / unit
                    } else {
                        0.0
                    }
                }
            };
            if let (Some(b), Some(a)) = (before, increment.magnitude(y)) {
                if a < HEALED_FRACTION * b && a < 0.5 * allowed {
                    tracing::debug!(
                        time_s = now_s,
                        fault = best.fault.name(),
                        before = b,
                        after = a,
                        allowed,
                        "intake residual fault healed (refit)"
                    );
                    self.residual[i] = None;
                    self.restart_filters();
                    return;
                }
            }
            // Still there: a sensor's error is refitted whole, from its onset on the raw
            // residuals; the other faults keep the increment.
            f.comp = match best.fault {
                IntakeFault::MapSensor | IntakeFault::MafSensor => {
                    let drift = f.comp.rate != 0.0 || best.rate != 0.0;
                    let whole = f.raw_bank.fit_form(best.fault, drift);
                    if whole.glr > 0.0 {
                        Compensation::new(&whole, &f.raw_bank)
                    } else {
                        increment
                    }
                }
                IntakeFault::EgrValve | IntakeFault::Leak => increment,
            };
            f.fit.parameter = f.comp.parameter;
            f.fit.gain = f.comp.gain;
            f.fit.offset = f.comp.offset;
            f.fit.rate = f.comp.rate;
            f.heal_llr = 0.0;
            f.gone_s = 0.0;
            self.residual[i] = Some(f);
            tracing::debug!(
                time_s = now_s,
                fault = best.fault.name(),
                parameter = f.fit.parameter,
                offset = f.fit.offset,
                rate = f.fit.rate,
                before = ?before,
                after = ?f.comp.magnitude(y),
                "intake fault refined"
            );
            return;
        }
        let event = match best.fault {
            IntakeFault::MapSensor => 0,
            IntakeFault::MafSensor => 3,
            IntakeFault::EgrValve if best.lag_s > 0.0 => EGR_SLOW,
            IntakeFault::EgrValve => {
                let mean_cmd = ep.cmd_sum / ep.segments.max(1) as f64;
                if best.parameter < mean_cmd {
                    6
                } else {
                    7
                }
            }
            IntakeFault::Leak => 8,
        };
        let total: f64 = ranked
            .iter()
            .map(|f| f.glr.max(0.0))
            .sum::<f64>()
            .max(1e-12);
        let mut cands = [("", 0.0); 4];
        for (c, f) in cands.iter_mut().zip(ranked.iter()) {
            *c = (f.fault.name(), f.glr.max(0.0) / total);
        }
        let result = TestResult {
            value: best.glr,
            min: 0.0,
            max: self.cfg.isolation_min_glr,
            verdict: Verdict::Failed,
        };
        self.set_event(event, result, &cands);
        self.residual[i] = Some(ResidualFault {
            fit: best,
            event,
            comp: Compensation::new(&best, self.scan.best_bank(best.fault)),
            heal_llr: 0.0,
            gone_s: 0.0,
            raw_p: 0.0,
            raw_w: 0.0,
            raw_w_age_s: 0.0,
            raw_bank: *self.scan.best_bank(best.fault),
        });
        tracing::debug!(
            time_s = now_s,
            fault = best.fault.name(),
            parameter = best.parameter,
            gain = best.gain,
            glr = best.glr,
            runner_up = ranked[1].fault.name(),
            runner_up_glr = ranked[1].glr,
            "intake fault isolated"
        );
    }

    /// Learns the corrections and the noise levels from a quiet segment: both sensors in use,
    /// no test failing, no episode, nothing decided, no reading out of range or repeated.
    fn learn_corrections(&mut self, dt: f64, res: &ResidualOutcome) {
        let Some(l) = self.learn else {
            return;
        };
        let quiet = res.alarm.is_none()
            && self.episode.is_none()
            && !self.group
            && self.residual.iter().all(Option::is_none)
            && !self.sensors.iter().any(SensorState::any)
            && self.map_low_run + self.map_high_run + self.maf_low_run + self.maf_high_run == 0
            && self.map_frozen_run == 0
            && self.maf_frozen_run == 0
            && self
                .noise
                .iter()
                .all(|n| n.cusum < self.cfg.noise_threshold);
        if !quiet {
            return;
        }
        let tau = self.cfg.adapt_time_s;
        self.maf_ratio.update(l.implied_maf, l.maf, dt, tau);
        if l.choked_model.is_finite() {
            self.throttle_ratio
                .update(l.choked_maf, l.choked_model, dt, tau);
        }
        let lim = self.cfg.noise_learn_limit;
        let cap = self.cfg.noise_cap;
        for n in &mut self.noise {
            if n.excess.is_finite() {
                n.learned.update(n.excess.min(cap), 1.0, dt, tau);
                n.level = (n.learned.num / n.learned.den).clamp(1.0 / lim, lim);
            }
        }
    }

    /// This segment's diagnosis scores (into `self.scores`); returns whether it is flagged.
    /// Flagged while a fault is decided and not healed, an isolation episode is open, a
    /// residual test fails, a circuit check fails or a noise test fails. A decided fault scores
    /// 1 for its class (a circuit, frozen or noisy reading: its sensor); the group DTC and an
    /// open episode score the hypotheses by their GLR statistics normalized to sum to 1; per
    /// class the largest of these.
    fn diagnose(&mut self, residual_alarm: bool) -> bool {
        self.scores = [0.0; 4];
        let mut flagged = residual_alarm;
        let runs = [
            self.map_low_run + self.map_high_run,
            self.maf_low_run + self.maf_high_run,
        ];
        for (s, fault) in [(MAP, IntakeFault::MapSensor), (MAF, IntakeFault::MafSensor)] {
            if self.sensors[s].any()
                || runs[s] > 0
                || self.noise[s].cusum >= self.cfg.noise_threshold
            {
                self.scores[fault.index()] = 1.0;
                flagged = true;
            }
        }
        for f in self.residual.iter().flatten() {
            self.scores[f.fit.fault.index()] = 1.0;
            flagged = true;
        }
        let add = |scores: &mut [f64; 4], name: &str, v: f64| {
            if let Some(i) = FAULT_CLASSES.iter().position(|c| *c == name) {
                scores[i] = scores[i].max(v);
            }
        };
        if self.group {
            for (name, v) in &self.ev_cands[GROUP][..self.ev_ncand[GROUP]] {
                add(&mut self.scores, name, *v);
            }
            flagged = true;
        }
        if self.episode.is_some() {
            let ranked = self.scan.ranked();
            let total: f64 = ranked.iter().map(|f| f.glr.max(0.0)).sum();
            if total > 0.0 {
                for f in ranked {
                    add(&mut self.scores, f.fault.name(), f.glr.max(0.0) / total);
                }
            }
            flagged = true;
        }
        flagged
    }

    /// Steps the three filters, the residual tests and the noise tests.
    #[allow(clippy::too_many_arguments)]
    fn run_filters(
        &mut self,
        k: u64,
        dt: f64,
        u: &IntakeInput,
        seg: &Segment,
        maf_sensor: f64,
        egr_command: f64,
        out: &mut OutputSink<'_>,
    ) -> ResidualOutcome {
        let limit = self.cfg.adapt_limit;
        let kappa = self.maf_ratio.value(limit);
        let kappa_t = self.throttle_ratio.value(limit);
        let maf_f = kappa * seg.maf_kg_s;
        let tol = self.cfg.transient_tolerance_s;
        let Some(filters) = self.filters.as_mut() else {
            return ResidualOutcome::default();
        };
        let y_map = Vector1::new(seg.map_pa);
        let y_maf = Vector1::new(maf_f);
        let central = filters
            .central
            .predict(u)
            .and_then(|()| filters.central.update(&Vector2::new(seg.map_pa, maf_f), u));
        let pair = filters.pair.step(u, &y_map, &y_maf);
        let fed = filters.federated.step(u, &y_map, &y_maf);
        let (Ok(ci), Ok(ps), Ok(fs)) = (central, pair, fed) else {
            self.rejected += 1;
            return ResidualOutcome::default();
        };
        out(Output::Innovation {
            filter: "intake_centralized",
            residual: ci.residual.as_slice(),
            variance: &[ci.covariance[(0, 0)], ci.covariance[(1, 1)]],
            nis: ci.nis,
            dof: ci.dof,
        });
        out(Output::Innovation {
            filter: "intake_local_map",
            residual: ps.local1.residual.as_slice(),
            variance: &[ps.local1.covariance[(0, 0)]],
            nis: ps.local1.nis,
            dof: ps.local1.dof,
        });
        out(Output::Innovation {
            filter: "intake_local_maf",
            residual: ps.local2.residual.as_slice(),
            variance: &[ps.local2.covariance[(0, 0)]],
            nis: ps.local2.nis,
            dof: ps.local2.dof,
        });
        out(Output::Innovation {
            filter: "intake_federated",
            residual: &[fs.local1.residual[0], fs.local2.residual[0]],
            variance: &[fs.local1.covariance[(0, 0)], fs.local2.covariance[(0, 0)]],
            nis: fs.nis,
            dof: fs.dof,
        });

        // Allowances for what the model does not know (see the module docs).
        let map_trans = (tol * self.map_rate).powi(2);
        let maf_trans = (tol * kappa * self.maf_rate).powi(2);
        let maf_noise = (self.cfg.maf_noise_rel * maf_f).powi(2);

        // Cross residuals: each local filter predicts the sensor it does not use.
        let (x_maf, p_maf) = (
            filters.pair.local2().state(),
            filters.pair.local2().covariance(),
        );
        let (x_map, p_map) = (
            filters.pair.local1().state(),
            filters.pair.local1().covariance(),
        );
        // Linearized manifold response over this segment (for the hypothesis bank and the EGR
        // allowance below). The flows a leak or the EGR would add are evaluated at the MAP-only
        // local filter's pressure: it follows the true pressure under every fault but the MAP
        // sensor's, whereas the centralized estimate is pulled off it by the very
        // inconsistency being isolated (and near ambient those flows change fast with the
        // pressure).
        let p_true = x_map[X_PM];
        let (slope, _) = self.model.vol_eff(seg.speed_rpm);
        let egr_area = self.model.egr_area(seg.egr_cmd);
        let (w_egr, d_egr) = if egr_area > 0.0 {
            self.model.egr_flow_area(p_true, egr_area)
        } else {
            (0.0, 0.0)
        };
        let j = self.gain * (d_egr - slope);
        // The EGR flow's share of the pressure allowance: the exhaust back-pressure upstream of
        // the valve moves with the ambient pressure the monitor does not measure (and keeps
        // its ratio to it), and near the end of the flow function, with the manifold pressure
        // close to the back-pressure (open valve at high load), the flow changes steeply with
        // it: 4 kPa less ambient takes about 17 % off the flow at p_m = 94 kPa. Its error moves
        // the manifold pressure by the steady-state gain `1 / (slope - dW_egr/dp_m)` (Pa per
        // kg/s). Without it a plant under 97 kPa ambient had its healthy MAP named 3 kPa low.
        let params = self.model.params();
        let p_egr = params.egr_upstream_pressure_pa;
        let egr_p_std = if egr_area > 0.0 && slope > d_egr {
            let dw_dpegr = (w_egr - d_egr * p_true) / p_egr;
            let s_pegr = self.cfg.ambient_pressure_std_pa * p_egr / params.ambient_pressure_pa;
            dw_dpegr * s_pegr / (slope - d_egr)
        } else {
            0.0
        };
        let s_p = (p_maf[(X_PMES, X_PMES)]
            + self.r_map
            + (self.cfg.pressure_model_rel * seg.map_pa).powi(2)
            + egr_p_std.powi(2)
            + map_trans)
            .sqrt();
        let z_p = (seg.map_pa - x_maf[X_PMES]) / s_p;
        let s_x = (p_map[(X_WMES, X_WMES)]
            + maf_noise
            + (self.cfg.flow_model_rel * maf_f).powi(2)
            + maf_trans)
            .sqrt();
        let z_x = (maf_f - x_map[X_WMES]) / s_x;

        // Throttle-model flow residuals. The throttle flow computed at the MAP reading (lagged
        // like the MAF) depends on the MAF sensor (directly) and on the MAP sensor (through the
        // pressure ratio), but not on the EGR or a leak, which change the true pressure and the
        // true throttle flow together. Its variance carries the MAP noise and the ambient
        // pressure's uncertainty through the flow function's slope, so the near-ambient region,
        // where that slope is steep, weighs nothing. The test uses it only while the throttle
        // is choked (then it sees the MAF alone); the isolation bank uses it everywhere, with
        // the MAP hypothesis's signature. The model's flow is scaled by the learned throttle
        // correction.
        let p = self.model.params();
        let p_hat = filters.central.state()[X_PM];
        let (w_model, dw_dp) = self
            .model
            .throttle_flow_area(seg.map_pa, self.model.throttle_area(seg.throttle_deg));
        let a = (-dt / p.maf_time_constant_s).exp();
        if self.w_model_lag.is_nan() {
            (self.w_model_lag, self.dw_dp_lag) = (w_model, dw_dp);
        }
        self.w_model_lag = a * self.w_model_lag + (1.0 - a) * w_model;
        self.dw_dp_lag = a * self.dw_dp_lag + (1.0 - a) * dw_dp;
        let (w_lag, dw_lag) = (kappa_t * self.w_model_lag, kappa_t * self.dw_dp_lag);
        let choked_limit = self.cfg.choked_ratio * p.ambient_pressure_pa;
        let choked = p_hat < choked_limit && seg.map_pa < choked_limit;
        self.choked_run = if choked { self.choked_run + 1 } else { 0 };
        // Beyond `flow_ratio_max` the flow function is too steep (and ends at ratio 1) for a
        // MAP error to act linearly on the computed flow: no flow residual there.
        let in_range = seg.map_pa < self.cfg.flow_ratio_max * p.ambient_pressure_pa;
        self.flow_run = if in_range { self.flow_run + 1 } else { 0 };
        let ratio = seg.map_pa / p.ambient_pressure_pa;
        // Until the throttle correction has learned, the model may be off by its whole range.
        let throttle_ready = self.throttle_ratio.time_s >= self.cfg.adapt_min_s;
        let model_rel = if throttle_ready {
            self.cfg.throttle_model_rel
        } else {
            self.cfg.throttle_model_rel.hypot(self.cfg.adapt_limit)
        };
        let s_w = (maf_noise
            + (model_rel * w_lag).powi(2)
            + dw_lag.powi(2)
                * (self.cfg.map_noise_pa.powi(2)
                    + (ratio * self.cfg.ambient_pressure_std_pa).powi(2))
            + maf_trans)
            .sqrt();
        // The raw MAF against the throttle model: the learned throttle correction is the ratio
        // of the two, so the volumetric-efficiency correction (which varies over the operating
        // points) stays out of this residual.
        let z_flow = if self.flow_run >= CHOKED_SETTLE && s_w > 0.0 {
            (maf_sensor - w_lag) / s_w
        } else {
            f64::NAN
        };
        let settled_choke = self.choked_run >= CHOKED_SETTLE;
        self.learn = Some(LearnSample {
            implied_maf: x_map[X_WMES],
            maf: maf_sensor,
            choked_maf: maf_sensor,
            choked_model: if settled_choke {
                self.w_model_lag
            } else {
                f64::NAN
            },
        });

        let z = j * dt;
        let record = SegmentRecord {
            z_p,
            s_p,
            z_w: z_flow,
            s_w,
            map_flow_gain: dw_lag,
            decay: z.exp(),
            input_gain: self.gain * dt * phi1(z),
            maf: maf_f,
            egr_full: self.model.egr_flow_area(p_true, p.egr_max_area_m2).0,
            egr_cmd: seg.egr_cmd,
            leak_unit: self.model.throttle_flow_area(p_true, 1.0).0,
            p_ref: x_maf[X_PM],
            dt,
        };

        // Decided residual faults (already taken out of the filters' inputs): the sequential
        // test of "gone" against "still there" moves with their predicted effect on the raw
        // residuals (what removing them would leave), computed with the real EGR command.
        let clip = self.cfg.clip_sigma;
        let raw = SegmentRecord {
            egr_cmd: egr_command,
            ..record
        };
        let heal_thr = self.cfg.residual_heal_llr;
        let z_p_c = z_p;
        let z_flow_c = z_flow;
        for f in self.residual.iter_mut().flatten() {
            let c = f.comp.step(&raw);
            // LLR of "gone" (the residual then carries minus this effect) against "still there",
            // with Huber's loss beyond `clip` deviations: Gaussian near zero, linear in the tails,
            // so that one wild segment weighs little and a large effect can still be told gone
            // (clipping the residual alone makes the ratio negative for any effect above
            // 2 clip, and a large fault could then never heal).
            let huber = |x: f64| {
                let a = x.abs();
                if a <= clip {
                    0.5 * a * a
                } else {
                    clip * a - 0.5 * clip * clip
                }
            };
            let llr = |zc: f64, c: f64| huber(zc) - huber(zc + c);
            let mut inc = llr(z_p_c, c.0 / s_p);
            // The raw residuals' means over half of heal_s, each in units of its allowance (one
            // deviation of noise plus RAW_EFFECT_SHARE of the effect taken back: the filters ran
            // with the compensation, so its predicted effect misses a few percent of what they
            // would show without it) and clipped at RAW_CLIP: only their being within one
            // allowance of zero matters, and a fault's own residuals must not hold them off zero
            // long after it has gone. A residual that is not tested (the throttle-flow one at
            // wide-open throttle) stops counting once its mean is that old.
            let window_s = 0.5 * self.cfg.heal_s;
            let a = (-dt / window_s.max(dt)).exp();
            let unit = |raw: f64, c: f64| {
                (raw / (1.0 + RAW_EFFECT_SHARE * c.abs())).clamp(-RAW_CLIP, RAW_CLIP)
            };
            f.raw_p = a * f.raw_p + (1.0 - a) * unit(z_p_c + c.0 / s_p, c.0 / s_p);
            if z_flow_c.is_finite() {
                inc += llr(z_flow_c, c.1 / s_w);
                let u = unit(z_flow_c + c.1 / s_w, c.1 / s_w);
                // A stale mean restarts from the new residual.
                f.raw_w = if f.raw_w_age_s >= window_s {
                    u
                } else {
                    a * f.raw_w + (1.0 - a) * u
                };
                f.raw_w_age_s = 0.0;
            } else {
                f.raw_w_age_s += dt;
            }
            if matches!(f.fit.fault, IntakeFault::MapSensor | IntakeFault::MafSensor) {
                f.raw_bank.push(&SegmentRecord {
                    z_p: z_p_c + c.0 / s_p,
                    z_w: z_flow_c + c.1 / s_w,
                    ..raw
                });
            }
            f.heal_llr = (f.heal_llr + inc).clamp(0.0, 2.0 * heal_thr);
            let raw_quiet =
                f.raw_p.abs() < 1.0 && (f.raw_w.abs() < 1.0 || f.raw_w_age_s >= window_s);
            f.gone_s = if f.heal_llr >= heal_thr && raw_quiet {
                f.gone_s + dt
            } else {
                0.0
            };
        }
        self.history.push(record);
        if self.episode.is_some() {
            self.scan.push(k, &record);
        }

        // Noise tests on each reading's own differences.
        let ready = self.maf_ratio.time_s >= self.cfg.adapt_min_s && self.settle_s <= 0.0;
        let steady = self.throttle_steady_run > self.cfg.noise_settle_segments;
        // The four-segment difference of each reading (`noise_difference`): a live signal's
        // change over four segments is nearly linear outside transients (which the test
        // skips), so what is left is the sensor's noise, variance R (relative to the reading
        // for the MAF).
        let cap = self.cfg.noise_cap;
        let v = self.cfg.noise_ratio;
        let noise_thr = self.cfg.noise_threshold;
        let diffs = [
            (self.map_noise_diff, self.r_map),
            (self.maf_noise_diff, maf_noise),
        ];
        let tests = ["intake_map_noise", "intake_maf_noise"];
        let adapt_min = self.cfg.adapt_min_s;
        for ((n, (d, r)), test) in self.noise.iter_mut().zip(diffs).zip(tests) {
            let ok = steady && d.is_finite() && r > 0.0;
            let excess = d * d / r;
            n.z2 = if ok {
                (excess / n.level).min(cap)
            } else {
                f64::NAN
            };
            n.excess = if ok { excess } else { f64::NAN };
            let result = if ready && n.learned.time_s >= adapt_min && n.z2.is_finite() {
                let inc = 0.5 * ((1.0 - 1.0 / v) * n.z2 - v.ln());
                n.cusum = (n.cusum + inc).clamp(0.0, 2.0 * noise_thr);
                TestResult {
                    value: n.cusum,
                    min: 0.0,
                    max: noise_thr,
                    verdict: if n.cusum >= noise_thr {
                        Verdict::Failed
                    } else {
                        Verdict::Passed
                    },
                }
            } else {
                TestResult::NOT_TESTED
            };
            out(Output::Test { test, result });
        }

        // Residual tests: after the corrections have learned, not while a noisy sensor is
        // decided; while a residual fault is taken out of the residuals only the pressure and
        // throttle-model tests (their residuals are the ones compensated) raise alarms.
        let enabled = ready && !self.sensors.iter().any(|s| s.noisy);
        let compensating = self.residual.iter().any(Option::is_some);
        let (rp, onset_p) = self.cusum_p.step(k, z_p_c.clamp(-clip, clip), enabled);
        let (rx, onset_x) = self
            .cusum_x
            .step(k, z_x.clamp(-clip, clip), enabled && !compensating);
        // The throttle-model test only once the throttle correction has learned.
        let z_w = if settled_choke && throttle_ready {
            z_flow_c
        } else {
            f64::NAN
        };
        let (rt, onset_t) =
            self.cusum_t
                .step(k, z_w.clamp(-clip, clip), enabled && z_w.is_finite());
        let rc = self
            .nis_central
            .step(ci.nis, self.cfg.nis_cap, self.cfg.nis_threshold);
        let rf = self
            .nis_federated
            .step(fs.nis, self.cfg.nis_cap, self.cfg.nis_threshold);
        let nis_counts = enabled && !compensating;
        let window_onset = k.saturating_sub(self.cfg.nis_window as u64 - 1);
        let tests = [
            ("intake_pressure_consistency", rp, onset_p),
            ("intake_flow_consistency", rx, onset_x),
            ("intake_throttle_model", rt, onset_t),
            (
                "intake_centralized_nis",
                rc,
                (nis_counts && rc.verdict == Verdict::Failed).then_some(window_onset),
            ),
            (
                "intake_federated_nis",
                rf,
                (nis_counts && rf.verdict == Verdict::Failed).then_some(window_onset),
            ),
        ];
        // The earliest onset estimate of the tests that fail this segment.
        let mut alarm: Option<u64> = None;
        for (name, result, onset) in tests {
            out(Output::Test { test: name, result });
            if let (Verdict::Failed, Some(o)) = (result.verdict, onset) {
                alarm = Some(alarm.map_or(o, |a| a.min(o)));
            }
        }
        ResidualOutcome {
            tested: enabled,
            alarm,
        }
    }

    /// Steps the filters through a segment with a refused reading: the centralized EKF and the
    /// decentralized pair update with the sensor that is left, the federated filter (which
    /// needs both) waits.
    fn run_filters_partial(
        &mut self,
        u: &IntakeInput,
        map_pa: f64,
        maf_kg_s: f64,
        map_ok: bool,
        maf_ok: bool,
    ) {
        let Some(f) = self.filters.as_mut() else {
            return;
        };
        let y = Vector2::new(
            if map_ok { map_pa } else { 0.0 },
            if maf_ok { maf_kg_s } else { 0.0 },
        );
        let central = f.central.predict(u).and_then(|()| {
            if map_ok || maf_ok {
                f.central
                    .update_subset(&y, u, &[map_ok, maf_ok])
                    .map(|_| ())
            } else {
                Ok(())
            }
        });
        let (y_map, y_maf) = (Vector1::new(map_pa), Vector1::new(maf_kg_s));
        let pair = f
            .pair
            .step_partial(u, map_ok.then_some(&y_map), maf_ok.then_some(&y_maf));
        if central.is_err() || pair.is_err() {
            self.rejected += 1;
        }
    }

    /// Which filter's estimate is the output. The configured primary while both sensors are
    /// trusted; with the MAP untrusted (a decided MAP fault, or a refused reading) the
    /// MAF-only local filter, with the MAF untrusted or an EGR or leak fault decided the
    /// MAP-only local filter: it measures the pressure itself and its random-walk throttle
    /// flow absorbs any unmetered air, so its pressure and intake-valve flow stay right.
    fn output_filter(&self, map_ok: bool, maf_ok: bool) -> OutputFilter {
        let map_bad = !map_ok
            || self.sensors[MAP].any()
            || self.residual[IntakeFault::MapSensor.index()].is_some();
        let maf_bad = !maf_ok
            || self.sensors[MAF].any()
            || self.residual[IntakeFault::MafSensor.index()].is_some();
        let air = self.residual[IntakeFault::EgrValve.index()].is_some()
            || self.residual[IntakeFault::Leak.index()].is_some();
        match (map_bad, maf_bad || air) {
            (true, false) => OutputFilter::MafLocal,
            (false, true) => OutputFilter::MapLocal,
            (true, true) if !map_ok => OutputFilter::MafLocal,
            (true, true) => OutputFilter::MapLocal,
            (false, false) => OutputFilter::Primary,
        }
    }

    /// The estimate output of this segment: from the filter the recovery policy chooses.
    fn estimate(&self, seg: &Segment, map_ok: bool, maf_ok: bool) -> Option<Estimates> {
        let f = self.filters.as_ref()?;
        // Both sensors named failed: every filter leans on a failed reading (a stuck MAF holds
        // the MAF-local pressure wherever it stuck), so the throttle model's steady state for
        // the segment's inputs (angle, speed, EGR command) gives the pressure, within the
        // model's own relative error (`pressure_model_rel`; the manifold settles within a
        // few tenths of a second, so only transients are worse).
        if self.sensor_named(MAP) && self.sensor_named(MAF) {
            let u = IntakeInput::new(seg.speed_rpm, seg.throttle_deg, seg.egr_cmd);
            if let Some(x) = self.model.equilibrium(&u) {
                let pm = x[X_PM];
                let half = 1.96 * self.cfg.pressure_model_rel * pm;
                let (slope, _) = self.model.vol_eff(seg.speed_rpm);
                return Some(Estimates {
                    pm,
                    half,
                    w: self.model.intake_valve_flow(pm, seg.speed_rpm),
                    w_half: slope * half,
                    source: "throttle_model",
                });
            }
        }
        let (x, p, source) = match self.output_filter(map_ok, maf_ok) {
            OutputFilter::MafLocal => (
                f.pair.local2().state(),
                f.pair.local2().covariance(),
                "maf_local_ekf",
            ),
            OutputFilter::MapLocal => (
                f.pair.local1().state(),
                f.pair.local1().covariance(),
                "map_local_ekf",
            ),
            OutputFilter::Primary => {
                let (x, p) = match self.cfg.primary_filter {
                    PrimaryFilter::Centralized => (f.central.state(), f.central.covariance()),
                    PrimaryFilter::Decentralized => (f.pair.state(), f.pair.covariance()),
                    PrimaryFilter::Federated => (f.federated.state(), f.federated.covariance()),
                };
                (x, p, self.cfg.primary_filter.name())
            }
        };
        let pm = x[X_PM];
        let half = 1.96 * p[(X_PM, X_PM)].max(0.0).sqrt();
        let (slope, _) = self.model.vol_eff(seg.speed_rpm);
        let w = self.model.intake_valve_flow(pm, seg.speed_rpm);
        Some(Estimates {
            pm,
            half,
            w,
            w_half: slope * half,
            source,
        })
    }

    /// The learned corrections as they stand, unbounded by `adapt_limit` (what the plant asks
    /// of them; the monitor applies them clamped): `maf_correction` and `throttle_correction`
    /// (-), each once it has learned for `adapt_min_s`. `fdd calibrate` reads them to size
    /// `adapt_limit` for a plant.
    fn emit_corrections(&self, out: &mut OutputSink<'_>) {
        for (name, r) in [
            ("maf_correction", &self.maf_ratio),
            ("throttle_correction", &self.throttle_ratio),
        ] {
            if r.time_s >= self.cfg.adapt_min_s {
                let v = r.value(f64::INFINITY);
                out(Output::Estimate {
                    name,
                    value: v,
                    lower: v,
                    upper: v,
                    source: "learned",
                });
            }
        }
    }

    fn reset_cycle_state(&mut self) {
        self.filters = None;
        self.last_t_ns = None;
        self.episode = None;
        self.scan = OnsetScan::default();
        self.history.clear();
        self.rearm();
        self.map_low_run = 0;
        self.map_high_run = 0;
        self.maf_low_run = 0;
        self.maf_high_run = 0;
        self.map_frozen_run = 0;
        self.maf_frozen_run = 0;
        (self.last_map, self.last_maf) = (f64::NAN, f64::NAN);
        (self.prev_map, self.prev_maf) = (f64::NAN, f64::NAN);
        (self.prev2_map, self.prev2_maf) = (f64::NAN, f64::NAN);
        (self.map_rate, self.maf_rate) = (0.0, 0.0);
        self.last_throttle = f64::NAN;
        self.last_throttle_rate = f64::NAN;
        self.throttle_steady_run = 0;
        self.choked_run = 0;
        self.segment = 0;
        self.sensors = [SensorState::default(); 2];
        self.maf_ratio = LearnedRatio::default();
        self.throttle_ratio = LearnedRatio::default();
        self.noise = [NoiseTest::default(); 2];
        self.settle_s = 0.0;
        self.est_prev = [f64::NAN; 2];
        self.learn = None;
        self.residual = [None; 4];
        self.group = false;
        self.ev_result = [TestResult::NOT_TESTED; EVENTS];
        self.ev_cands = [[("", 0.0); 4]; EVENTS];
        self.ev_ncand = [0; EVENTS];
    }
}

/// Estimates the monitor offers to freeze frames: manifold pressure (Pa) and intake-valve
/// flow (kg/s), as on its estimate output.
pub const ESTIMATES: [&str; 2] = ["manifold_pressure", "intake_valve_flow"];

/// One segment's estimate output.
struct Estimates {
    pm: f64,
    half: f64,
    w: f64,
    w_half: f64,
    source: &'static str,
}

impl Estimates {
    fn emit(&self, out: &mut OutputSink<'_>) {
        out(Output::Estimate {
            name: "manifold_pressure",
            value: self.pm,
            lower: self.pm - self.half,
            upper: self.pm + self.half,
            source: self.source,
        });
        out(Output::Estimate {
            name: "intake_valve_flow",
            value: self.w,
            lower: self.w - self.w_half,
            upper: self.w + self.w_half,
            source: self.source,
        });
    }
}

/// `phi1(z) = (e^z - 1) / z`.
fn phi1(z: f64) -> f64 {
    if z.abs() < 1e-8 {
        1.0 + z / 2.0
    } else {
        z.exp_m1() / z
    }
}

impl Monitor for IntakeMonitor {
    fn name(&self) -> &str {
        "intake"
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
        let [n_id, th_id, e_id, map_id, maf_id] = self.inputs;
        let (Some(map), Some(maf)) = (signals.get(map_id), signals.get(maf_id)) else {
            return;
        };
        // A segment is complete when MAP and MAF carry the same, newer time stamp.
        if map.t_ns != maf.t_ns
            || map.t_ns > now_ns
            || self.last_t_ns.is_some_and(|t| map.t_ns <= t)
        {
            return;
        }
        let (Some(n), Some(th), Some(e)) =
            (signals.get(n_id), signals.get(th_id), signals.get(e_id))
        else {
            return;
        };
        self.last_t_ns = Some(map.t_ns);
        let seg = Segment {
            speed_rpm: n.value,
            throttle_deg: th.value,
            egr_cmd: e.value,
            map_pa: map.value,
            maf_kg_s: maf.value,
        };
        self.process_segment_with(map.t_ns, &seg, Some(signals), out);
    }

    fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.events.start_operation_cycle(now_ns, out);
        self.reset_cycle_state();
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

    /// The five intake signals and the two estimates at the failure.
    fn default_freeze_frame(&self) -> Vec<String> {
        [
            &self.cfg.speed_signal,
            &self.cfg.throttle_signal,
            &self.cfg.egr_signal,
            &self.cfg.map_signal,
            &self.cfg.maf_signal,
        ]
        .into_iter()
        .cloned()
        .chain(ESTIMATES.iter().map(|e| e.to_string()))
        .collect()
    }

    /// A cleared fault is isolated again from scratch, as in a new cycle.
    fn restart_tests(&mut self, _now_ns: u64) {
        self.reset_cycle_state();
    }
}

#[cfg(test)]
mod tests {
    use super::noise_difference;

    // A constant, a linear trend and a component alternating from one segment to the next
    // (aliased pulsation) leave nothing; white noise keeps its variance (the coefficients'
    // squares sum to 1).
    #[test]
    fn the_noise_difference_cancels_trends_and_alternation() {
        let y = |k: i32| 90e3 + 350.0 * f64::from(k) + if k % 2 == 0 { 700.0 } else { -700.0 };
        for k in 3..10 {
            let d = noise_difference(y(k), y(k - 1), y(k - 2), y(k - 3));
            assert!(d.abs() < 1e-9, "{d}");
        }
        // A second difference reads the alternation four times over.
        let d2 = y(4) - 2.0 * y(3) + y(2);
        assert!((d2.abs() - 2800.0).abs() < 1e-9, "{d2}");
        let coefficients = [0.5f64, -0.5, -0.5, 0.5];
        assert_eq!(coefficients.iter().map(|c| c * c).sum::<f64>(), 1.0);
        assert_eq!(noise_difference(1.0, 0.0, 0.0, 0.0), coefficients[0]);
        assert_eq!(noise_difference(0.0, 1.0, 0.0, 0.0), coefficients[1]);
        assert_eq!(noise_difference(0.0, 0.0, 1.0, 0.0), coefficients[2]);
        assert_eq!(noise_difference(0.0, 0.0, 0.0, 1.0), coefficients[3]);
    }
}
