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
//! Tests, each reported every segment on `/fdd/tests`:
//! - `intake_pressure_consistency`: CUSUM on the MAP reading against the MAF-local filter's MAP
//!   prediction (normalized);
//! - `intake_flow_consistency`: CUSUM on the MAF reading against the MAP-local filter's MAF
//!   prediction;
//! - `intake_throttle_model`: CUSUM on the MAF reading against the nozzle flow of the commanded
//!   throttle opening, only while the throttle is choked (then the throttle flow depends on the
//!   opening alone, so this test sees only the MAF sensor);
//! - `intake_centralized_nis`, `intake_federated_nis`: windowed sums of the 2-dof NIS;
//! - `intake_map_circuit`, `intake_maf_circuit`: readings outside the circuit range (kept out
//!   of the filters);
//! - `intake_map_frozen`, `intake_maf_frozen`: readings repeated exactly (a stuck sensor);
//! - `intake_input_range`: an engine speed, throttle or EGR input the model refuses (speed 0 or
//!   negative, NaN): the segment is skipped, nothing reaches the filters.
//!
//! Decision: a circuit range violation lasting `circuit_persist_segments` is a circuit fault
//! (P0107/P0108, P0102/P0103); a reading repeated exactly for `frozen_segments` segments is a
//! stuck sensor (P0106/P0101: a live sensor's noise moves its reading every segment). When a residual test fails, the hypothesis bank
//! ([`hypotheses`]) is refitted from the failing test's estimated onset (the last time its
//! CUSUM was zero) and then follows every segment; the best hypothesis is named when it is
//! significant and leads the runner-up clearly (see [`IntakeMonitorConfig`]). The EGR DTC is
//! P0401 (insufficient) when the fitted stuck position is below the mean command since the
//! onset, P0402 (excessive) otherwise. A named fault is latched for the operation cycle.
//!
//! Recovery policy: from the step a fault is named, the estimate output (`manifold_pressure`,
//! `intake_valve_flow`) comes from the local filter that fault leaves sound: the MAF-only one
//! after a MAP fault, the MAP-only one after a MAF, EGR or leak fault (it measures the pressure
//! and its random-walk throttle flow absorbs unmetered air); the source names it. A reading
//! refused by the circuit check is kept out of every filter; the centralized EKF and the pair go
//! on with the other sensor, and the output comes from that sensor's local filter meanwhile. A
//! new operation cycle starts again from the primary filter.

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
    Fit, HypothesisBank, IntakeFault, OnsetScan, RecordRing, SegmentRecord, ALL_FAULTS,
};

use crate::monitor::{Monitor, Output, OutputSink};
use crate::monitor_events::{EventSpec, FreezeValues, MonitorEvents};
use crate::signal_table::{SignalId, SignalTable};

/// Segments kept for refitting from an onset (5 s at 6000 rpm, 38 s at 800 rpm).
const HISTORY: usize = 1024;
/// Segments before the alarm test's onset estimate that the onset scan still considers.
const ONSET_MARGIN: u64 = 6;
/// Longest look-back of the onset scan (segments): bounds the one-off refit at an alarm to
/// `ONSET_WINDOW_MAX` records into 16 banks (1.3 s at 6000 rpm, 9.6 s at 800 rpm).
const ONSET_WINDOW_MAX: u64 = 256;
/// Capacity of the NIS windows.
const NIS_RING: usize = 512;
/// Segments the throttle must have been choked before its flow residual is used (the MAF lag
/// and the lagged model flow have settled).
const CHOKED_SETTLE: u32 = 3;

/// Event names, in the order of the DTC settings.
pub const EVENT_NAMES: [&str; 9] = [
    "map_range_performance",
    "map_circuit_low",
    "map_circuit_high",
    "maf_range_performance",
    "maf_circuit_low",
    "maf_circuit_high",
    "egr_flow_insufficient",
    "egr_flow_excessive",
    "intake_leak",
];

/// The fault classes of the monitor's diagnosis output: the isolation bank's hypotheses
/// ([`IntakeFault::name`], in the order of [`ALL_FAULTS`]).
pub const FAULT_CLASSES: [&str; 4] = ["map_sensor", "maf_sensor", "egr_valve", "manifold_leak"];

/// What the monitor named this operation cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IntakeDecision {
    /// A residual fault isolated by the hypothesis bank, with its fitted size.
    Residual { fit: Fit, event: usize },
    /// A circuit range fault (event index into [`EVENT_NAMES`]).
    Circuit { event: usize },
    /// A sensor whose reading is frozen (stuck): its range/performance event.
    Frozen { event: usize },
}

impl IntakeDecision {
    /// Index of the DTC event in [`EVENT_NAMES`].
    pub fn event(&self) -> usize {
        match *self {
            IntakeDecision::Residual { event, .. }
            | IntakeDecision::Circuit { event }
            | IntakeDecision::Frozen { event } => event,
        }
    }

    /// Name of the event.
    pub fn event_name(&self) -> &'static str {
        EVENT_NAMES[self.event()]
    }
}

/// Errors building the monitor.
#[derive(Debug, thiserror::Error)]
pub enum IntakeMonitorError {
    #[error("intake monitor: signal `{0}` is not in the signal table")]
    MissingSignal(String),
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
    fn new(key: &'static str, delta: f64, h: f64) -> Result<Self, IntakeMonitorError> {
        if !(delta > 0.0 && h > 0.0 && delta.is_finite() && h.is_finite()) {
            return Err(setting(key, "min bias and threshold must be positive"));
        }
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
    map_low_run: u32,
    map_high_run: u32,
    maf_low_run: u32,
    maf_high_run: u32,
    history: RecordRing,
    scan: OnsetScan,
    /// The isolation's state this segment: PreFailed while an episode is open (value: the lead
    /// of the best hypothesis over the runner-up), Failed when it names a fault.
    isolation: TestResult,
    episode: Option<Episode>,
    decided: Option<IntakeDecision>,
    deciding: TestResult,
    candidates: [(&'static str, f64); 4],
    /// The diagnosis scores of the latest segment (see [`Output::Diagnosis`]).
    scores: [f64; 4],
    events: MonitorEvents,
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
        for (key, v) in [
            ("poll_period_s", cfg.poll_period_s),
            ("map_noise_pa", cfg.map_noise_pa),
            ("maf_noise_kg_s", cfg.maf_noise_kg_s),
            ("maf_noise_rel", cfg.maf_noise_rel),
            ("map_high_ratio", cfg.map_high_ratio),
            ("maf_high_kg_s", cfg.maf_high_kg_s),
            ("clip_sigma", cfg.clip_sigma),
            ("choked_ratio", cfg.choked_ratio),
            ("flow_ratio_max", cfg.flow_ratio_max),
            ("nis_cap", cfg.nis_cap),
            ("nis_threshold", cfg.nis_threshold),
            ("isolation_min_glr", cfg.isolation_min_glr),
            ("isolation_max_s", cfg.isolation_max_s),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(setting(key, format!("{v} must be a positive number")));
            }
        }
        for (key, v) in [
            ("map_low_pa", cfg.map_low_pa),
            ("map_low_margin_pa", cfg.map_low_margin_pa),
            ("maf_low_kg_s", cfg.maf_low_kg_s),
            ("maf_low_margin_kg_s", cfg.maf_low_margin_kg_s),
            ("throttle_model_rel", cfg.throttle_model_rel),
            ("isolation_margin", cfg.isolation_margin),
            ("isolation_min_s", cfg.isolation_min_s),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(setting(key, format!("{v} must be a number >= 0")));
            }
        }
        if cfg.nis_window == 0 || cfg.nis_window > NIS_RING {
            return Err(setting("nis_window", format!("must be 1..={NIS_RING}")));
        }
        if cfg.circuit_persist_segments == 0 {
            return Err(setting("circuit_persist_segments", "must be at least 1"));
        }
        if cfg.frozen_segments < 2 {
            return Err(setting("frozen_segments", "must be at least 2"));
        }
        for (i, v) in cfg.q_std.iter().chain(cfg.p0_std.iter()).enumerate() {
            let key = if i < 6 { "q_std" } else { "p0_std" };
            if !(v.is_finite() && *v >= 0.0) {
                return Err(setting(key, format!("entry {} = {v} must be >= 0", i % 6)));
            }
        }
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
                "pressure_cusum_threshold",
                cfg.pressure_cusum_min_bias_sigma,
                cfg.pressure_cusum_threshold,
            )?,
            cusum_x: OnsetCusum::new(
                "flow_cusum_threshold",
                cfg.flow_cusum_min_bias_sigma,
                cfg.flow_cusum_threshold,
            )?,
            cusum_t: OnsetCusum::new(
                "throttle_cusum_threshold",
                cfg.throttle_cusum_min_bias_sigma,
                cfg.throttle_cusum_threshold,
            )?,
            nis_central: NisWindow::new(cfg.nis_window),
            nis_federated: NisWindow::new(cfg.nis_window),
            map_frozen_run: 0,
            maf_frozen_run: 0,
            last_map: f64::NAN,
            last_maf: f64::NAN,
            map_low_run: 0,
            map_high_run: 0,
            maf_low_run: 0,
            maf_high_run: 0,
            history: RecordRing::new(HISTORY),
            scan: OnsetScan::default(),
            isolation: TestResult::NOT_TESTED,
            episode: None,
            decided: None,
            deciding: TestResult::NOT_TESTED,
            candidates: [("", 0.0); 4],
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

    /// The fault named this operation cycle, if any.
    pub fn decision(&self) -> Option<IntakeDecision> {
        self.decided
    }

    /// The hypotheses ranked by their statistic, as of the last segment of the current or last
    /// isolation episode.
    pub fn ranked_hypotheses(&self) -> [Fit; 4] {
        self.scan.ranked()
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

    fn report_all(
        &mut self,
        now_s: f64,
        verdicts: [Verdict; 9],
        values: FreezeValues<'_>,
        out: &mut OutputSink<'_>,
    ) {
        let n = if self.decided.is_some() {
            self.candidates
                .iter()
                .take_while(|c| !c.0.is_empty())
                .count()
        } else {
            0
        };
        let candidates = self.candidates;
        self.events.report(
            now_s,
            &verdicts,
            &self.deciding,
            &candidates[..n],
            values,
            out,
        );
    }

    /// Circuit range check of one reading: updates the run counters and says whether the
    /// reading is usable.
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
        // A low reading counts against the sensor only where the model rules such a value
        // out (NaN always does): the filter's estimate of the sensor's output (p_mes, W_mes),
        // less 3 sigma, above the limit plus a margin; before the filters run, the model's
        // steady state for this segment's inputs above it (computed only for a low reading).
        let ruled_out = |i: usize, limit: f64| match &self.filters {
            Some(f) => {
                let sigma = f.central.covariance()[(i, i)].max(0.0).sqrt();
                f.central.state()[i] - 3.0 * sigma > limit
            }
            None => self.model.equilibrium(&u).is_none_or(|x| x[i] > limit),
        };
        let map_low = seg.map_pa.is_nan()
            || (seg.map_pa < self.cfg.map_low_pa
                && ruled_out(1, self.cfg.map_low_pa + self.cfg.map_low_margin_pa));
        let maf_low = seg.maf_kg_s.is_nan()
            || (seg.maf_kg_s < self.cfg.maf_low_kg_s
                && ruled_out(3, self.cfg.maf_low_kg_s + self.cfg.maf_low_margin_kg_s));
        let map_ok = Self::circuit(
            &mut self.map_low_run,
            &mut self.map_high_run,
            map_low,
            seg.map_pa > self.cfg.map_high_ratio * p_a,
        );
        let maf_ok = Self::circuit(
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
                map_ok,
                seg.map_pa,
                self.cfg.map_low_pa,
                self.cfg.map_high_ratio * p_a,
            ),
        });
        out(Output::Test {
            test: "intake_maf_circuit",
            result: circuit_result(
                maf_ok,
                seg.maf_kg_s,
                self.cfg.maf_low_kg_s,
                self.cfg.maf_high_kg_s,
            ),
        });

        let mut residual_alarm: Option<u64> = None;
        if map_ok && maf_ok {
            if self.filters.is_none() && self.build_filters(&u).is_err() {
                self.skipped += 1;
                return;
            }
            residual_alarm = self.run_filters(k, &u, seg, out);
        } else {
            // A refused reading: the filters go on with the other sensor (a local filter
            // without its sensor runs on the model), no residual test this segment.
            self.skipped += 1;
            if self.filters.is_some() {
                self.run_filters_partial(&u, seg, map_ok, maf_ok);
            }
        }

        self.isolation = TestResult::NOT_TESTED;
        self.decide(now_s, k, seg, residual_alarm);
        if self.isolation.verdict != Verdict::NotTested {
            out(Output::Test {
                test: "intake_isolation",
                result: self.isolation,
            });
        }

        let mut verdicts = [Verdict::NotTested; 9];
        match self.decided {
            Some(d) => verdicts[d.event()] = Verdict::Failed,
            None if self.episode.is_none()
                && self.map_low_run == 0
                && self.map_high_run == 0
                && self.maf_low_run == 0
                && self.maf_high_run == 0 =>
            {
                verdicts = [Verdict::Passed; 9];
            }
            None => {}
        }
        let est = self.estimate(seg, map_ok, maf_ok);
        let values = FreezeValues {
            signals,
            estimates: &est.as_ref().map_or([f64::NAN; 2], |e| [e.pm, e.w]),
        };
        self.report_all(now_s, verdicts, values, out);
        if let Some(e) = est {
            e.emit(out);
        }
        let flagged = self.diagnose(residual_alarm.is_some());
        out(Output::Diagnosis {
            flagged,
            scores: &self.scores,
        });
    }

    /// This segment's diagnosis scores (into `self.scores`); returns whether it is flagged.
    /// Flagged while a fault is decided, an isolation episode is open, a residual test fails or
    /// a circuit check fails. The scores are the decided fault's candidates; during an episode,
    /// the hypotheses' GLR statistics normalized to sum to 1; for a circuit or frozen-reading
    /// fault, all on the sensor.
    fn diagnose(&mut self, residual_alarm: bool) -> bool {
        self.scores = [0.0; 4];
        let sensor = |event: usize| {
            if event < 3 {
                IntakeFault::MapSensor
            } else {
                IntakeFault::MafSensor
            }
        };
        match self.decided {
            Some(IntakeDecision::Residual { .. }) => {
                for (name, score) in self.candidates {
                    if let Some(i) = FAULT_CLASSES.iter().position(|c| *c == name) {
                        self.scores[i] = score;
                    }
                }
                return true;
            }
            Some(IntakeDecision::Circuit { event } | IntakeDecision::Frozen { event }) => {
                self.scores[sensor(event).index()] = 1.0;
                return true;
            }
            None => {}
        }
        if self.map_low_run > 0 || self.map_high_run > 0 {
            self.scores[IntakeFault::MapSensor.index()] = 1.0;
            return true;
        }
        if self.maf_low_run > 0 || self.maf_high_run > 0 {
            self.scores[IntakeFault::MafSensor.index()] = 1.0;
            return true;
        }
        if self.episode.is_some() {
            let ranked = self.scan.ranked();
            let total: f64 = ranked.iter().map(|f| f.glr.max(0.0)).sum();
            if total > 0.0 {
                for f in ranked {
                    self.scores[f.fault.index()] = f.glr.max(0.0) / total;
                }
            }
            return true;
        }
        residual_alarm
    }

    /// Steps the three filters and the residual tests; returns the first failing residual test
    /// and its onset segment.
    fn run_filters(
        &mut self,
        k: u64,
        u: &IntakeInput,
        seg: &Segment,
        out: &mut OutputSink<'_>,
    ) -> Option<u64> {
        let filters = self.filters.as_mut()?;
        let y_map = Vector1::new(seg.map_pa);
        let y_maf = Vector1::new(seg.maf_kg_s);
        let central = filters.central.predict(u).and_then(|()| {
            filters
                .central
                .update(&Vector2::new(seg.map_pa, seg.maf_kg_s), u)
        });
        let pair = filters.pair.step(u, &y_map, &y_maf);
        let fed = filters.federated.step(u, &y_map, &y_maf);
        let (Ok(ci), Ok(ps), Ok(fs)) = (central, pair, fed) else {
            self.rejected += 1;
            return None;
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

        // Cross residuals: each local filter predicts the sensor it does not use.
        let (x_maf, p_maf) = (
            filters.pair.local2().state(),
            filters.pair.local2().covariance(),
        );
        let s_p = (p_maf[(X_PMES, X_PMES)] + self.r_map).sqrt();
        let z_p = (seg.map_pa - x_maf[X_PMES]) / s_p;
        let (x_map, p_map) = (
            filters.pair.local1().state(),
            filters.pair.local1().covariance(),
        );
        let s_x = (p_map[(X_WMES, X_WMES)] + self.r_maf).sqrt();
        let z_x = (seg.maf_kg_s - x_map[X_WMES]) / s_x;

        // Throttle-model flow residuals. The throttle flow computed at the MAP reading (lagged
        // like the MAF) depends on the MAF sensor (directly) and on the MAP sensor (through the
        // pressure ratio), but not on the EGR or a leak, which change the true pressure and the
        // true throttle flow together. Its variance carries the MAP noise through the flow
        // function's slope, so the near-ambient region, where that slope is steep, weighs
        // nothing. The test uses it only while the throttle is choked (then it sees the MAF
        // alone); the isolation bank uses it everywhere, with the MAP hypothesis's signature.
        let p = self.model.params();
        let p_hat = filters.central.state()[X_PM];
        let dt = IntakeModel::segment_dt(seg.speed_rpm);
        let (w_model, dw_dp) = self
            .model
            .throttle_flow_area(seg.map_pa, self.model.throttle_area(seg.throttle_deg));
        let a = (-dt / p.maf_time_constant_s).exp();
        if self.w_model_lag.is_nan() {
            (self.w_model_lag, self.dw_dp_lag) = (w_model, dw_dp);
        }
        self.w_model_lag = a * self.w_model_lag + (1.0 - a) * w_model;
        self.dw_dp_lag = a * self.dw_dp_lag + (1.0 - a) * dw_dp;
        let choked_limit = self.cfg.choked_ratio * p.ambient_pressure_pa;
        let choked = p_hat < choked_limit && seg.map_pa < choked_limit;
        self.choked_run = if choked { self.choked_run + 1 } else { 0 };
        // Beyond `flow_ratio_max` the flow function is too steep (and ends at ratio 1) for a
        // MAP error to act linearly on the computed flow: no flow residual there.
        let in_range = seg.map_pa < self.cfg.flow_ratio_max * p.ambient_pressure_pa;
        self.flow_run = if in_range { self.flow_run + 1 } else { 0 };
        let s_w = ((self.cfg.maf_noise_rel * seg.maf_kg_s).powi(2)
            + (self.cfg.throttle_model_rel * self.w_model_lag).powi(2)
            + (self.dw_dp_lag * self.cfg.map_noise_pa).powi(2))
        .sqrt();
        let z_flow = if self.flow_run >= CHOKED_SETTLE && s_w > 0.0 {
            (seg.maf_kg_s - self.w_model_lag) / s_w
        } else {
            f64::NAN
        };
        let z_w = if self.choked_run >= CHOKED_SETTLE {
            z_flow
        } else {
            f64::NAN
        };

        // Linearized manifold response over this segment (for the hypothesis bank). The flows
        // a leak or the EGR would add are evaluated at the MAP-only local filter's pressure: it
        // follows the true pressure under every fault but the MAP sensor's, whereas the
        // centralized estimate is pulled off it by the very inconsistency being isolated (and
        // near ambient those flows change fast with the pressure).
        let p_true = x_map[X_PM];
        let (slope, _) = self.model.vol_eff(seg.speed_rpm);
        let egr_area = self.model.egr_area(seg.egr_cmd);
        let d_egr = if egr_area > 0.0 {
            self.model.egr_flow_area(p_true, egr_area).1
        } else {
            0.0
        };
        let j = self.gain * (d_egr - slope);
        let z = j * dt;
        let record = SegmentRecord {
            z_p,
            s_p,
            z_w: z_flow,
            s_w,
            map_flow_gain: self.dw_dp_lag,
            decay: z.exp(),
            input_gain: self.gain * dt * phi1(z),
            maf: seg.maf_kg_s,
            egr_full: self.model.egr_flow_area(p_true, p.egr_max_area_m2).0,
            egr_cmd: seg.egr_cmd,
            leak_unit: self.model.throttle_flow_area(p_true, 1.0).0,
            p_ref: x_maf[X_PM],
        };
        self.history.push(record);
        if self.episode.is_some() {
            self.scan.push(k, &record);
        }

        let clip = self.cfg.clip_sigma;
        let (rp, onset_p) = self.cusum_p.step(k, z_p.clamp(-clip, clip), true);
        let (rx, onset_x) = self.cusum_x.step(k, z_x.clamp(-clip, clip), true);
        let (rt, onset_t) = self
            .cusum_t
            .step(k, z_w.clamp(-clip, clip), z_w.is_finite());
        let rc = self
            .nis_central
            .step(ci.nis, self.cfg.nis_cap, self.cfg.nis_threshold);
        let rf = self
            .nis_federated
            .step(fs.nis, self.cfg.nis_cap, self.cfg.nis_threshold);
        let window_onset = k.saturating_sub(self.cfg.nis_window as u64 - 1);
        let tests = [
            ("intake_pressure_consistency", rp, onset_p),
            ("intake_flow_consistency", rx, onset_x),
            ("intake_throttle_model", rt, onset_t),
            (
                "intake_centralized_nis",
                rc,
                (rc.verdict == Verdict::Failed).then_some(window_onset),
            ),
            (
                "intake_federated_nis",
                rf,
                (rf.verdict == Verdict::Failed).then_some(window_onset),
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
        alarm
    }

    fn decide(&mut self, now_s: f64, k: u64, seg: &Segment, residual_alarm: Option<u64>) {
        if self.decided.is_some() {
            return;
        }
        let persist = self.cfg.circuit_persist_segments;
        let circuit = [
            (self.map_low_run, 1),
            (self.map_high_run, 2),
            (self.maf_low_run, 4),
            (self.maf_high_run, 5),
        ];
        for (run, event) in circuit {
            if run >= persist {
                self.deciding = TestResult {
                    value: f64::from(run),
                    min: 0.0,
                    max: f64::from(persist - 1),
                    verdict: Verdict::Failed,
                };
                self.candidates = [(EVENT_NAMES[event], 1.0), ("", 0.0), ("", 0.0), ("", 0.0)];
                self.decided = Some(IntakeDecision::Circuit { event });
                self.episode = None;
                return;
            }
        }
        let frozen_limit = self.cfg.frozen_segments;
        for (run, event, name) in [
            (self.map_frozen_run, 0, IntakeFault::MapSensor.name()),
            (self.maf_frozen_run, 3, IntakeFault::MafSensor.name()),
        ] {
            if run >= frozen_limit {
                self.deciding = TestResult {
                    value: f64::from(run),
                    min: 0.0,
                    max: f64::from(frozen_limit - 1),
                    verdict: Verdict::Failed,
                };
                self.candidates = [(name, 1.0), ("", 0.0), ("", 0.0), ("", 0.0)];
                self.decided = Some(IntakeDecision::Frozen { event });
                self.episode = None;
                return;
            }
        }
        if self.episode.is_none() {
            if let Some(onset) = residual_alarm {
                // Refit the hypotheses from the candidate onsets back from the estimate.
                let earliest = onset
                    .saturating_sub(ONSET_MARGIN)
                    .max(k.saturating_sub(ONSET_WINDOW_MAX))
                    .max(1);
                self.scan = OnsetScan::new(earliest, k);
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
                    cmd_sum,
                    segments: n,
                });
                return;
            }
            return;
        }
        let Some(mut ep) = self.episode else {
            return;
        };
        ep.cmd_sum += seg.egr_cmd;
        ep.segments += 1;
        self.episode = Some(ep);
        let ranked = self.scan.ranked();
        let elapsed = now_s - ep.alarm_s;
        let best = ranked[0];
        let significant = best.glr >= self.cfg.isolation_min_glr;
        let clear = best.glr - ranked[1].glr >= self.cfg.isolation_margin;
        self.isolation = TestResult {
            value: best.glr - ranked[1].glr,
            min: 0.0,
            max: self.cfg.isolation_margin,
            verdict: Verdict::PreFailed,
        };
        // A repeated reading is a stuck sensor in the making: the frozen check names it.
        let repeating = self.map_frozen_run > 0 || self.maf_frozen_run > 0;
        if elapsed >= self.cfg.isolation_min_s && significant && clear && !repeating {
            self.isolation.verdict = Verdict::Failed;
            let total: f64 = ranked
                .iter()
                .map(|f| f.glr.max(0.0))
                .sum::<f64>()
                .max(1e-12);
            for (c, f) in self.candidates.iter_mut().zip(ranked.iter()) {
                *c = (f.fault.name(), f.glr.max(0.0) / total);
            }
            let event = match best.fault {
                IntakeFault::MapSensor => 0,
                IntakeFault::MafSensor => 3,
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
            self.deciding = TestResult {
                value: best.glr,
                min: 0.0,
                max: self.cfg.isolation_min_glr,
                verdict: Verdict::Failed,
            };
            self.decided = Some(IntakeDecision::Residual { fit: best, event });
            self.episode = None;
            tracing::debug!(
                time_s = now_s,
                fault = best.fault.name(),
                parameter = best.parameter,
                glr = best.glr,
                "intake fault isolated"
            );
        } else if elapsed >= self.cfg.isolation_max_s && !significant {
            // Unexplained alarm: no hypothesis is significant. Close the episode.
            self.episode = None;
            self.isolation.verdict = Verdict::Passed;
        }
        // Significant but ambiguous (two faults explain the data equally well, e.g. a leak and
        // an EGR valve stuck open while the EGR command does not move): no DTC is named; the
        // episode goes on until the driving separates them.
    }

    /// Steps the filters through a segment with a refused reading: the centralized EKF and the
    /// decentralized pair update with the sensor that is left, the federated filter (which
    /// needs both) waits.
    fn run_filters_partial(&mut self, u: &IntakeInput, seg: &Segment, map_ok: bool, maf_ok: bool) {
        let Some(f) = self.filters.as_mut() else {
            return;
        };
        let y = Vector2::new(
            if map_ok { seg.map_pa } else { 0.0 },
            if maf_ok { seg.maf_kg_s } else { 0.0 },
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
        let (y_map, y_maf) = (Vector1::new(seg.map_pa), Vector1::new(seg.maf_kg_s));
        let pair = f
            .pair
            .step_partial(u, map_ok.then_some(&y_map), maf_ok.then_some(&y_maf));
        if central.is_err() || pair.is_err() {
            self.rejected += 1;
        }
    }

    /// Which filter's estimate is the output. The configured primary while both sensors are
    /// trusted; after a MAP fault (named, or a refused MAP reading) the MAF-only local filter,
    /// after a MAF, EGR or leak fault the MAP-only local filter: it measures the pressure
    /// itself and its random-walk throttle flow absorbs any unmetered air, so its pressure and
    /// intake-valve flow stay right.
    fn output_filter(&self, map_ok: bool, maf_ok: bool) -> OutputFilter {
        let map_fault = match self.decided {
            Some(IntakeDecision::Residual { fit, .. }) => Some(fit.fault == IntakeFault::MapSensor),
            Some(d) => Some(d.event() <= 2),
            None => None,
        };
        match (map_fault, map_ok, maf_ok) {
            (Some(true), ..) | (None, false, true) => OutputFilter::MafLocal,
            (Some(false), ..) | (None, true, false) => OutputFilter::MapLocal,
            (None, ..) => OutputFilter::Primary,
        }
    }

    /// The estimate output of this segment: from the filter the recovery policy chooses.
    fn estimate(&self, seg: &Segment, map_ok: bool, maf_ok: bool) -> Option<Estimates> {
        let f = self.filters.as_ref()?;
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

    fn reset_cycle_state(&mut self) {
        self.filters = None;
        self.last_t_ns = None;
        self.decided = None;
        self.deciding = TestResult::NOT_TESTED;
        self.episode = None;
        self.scan = OnsetScan::default();
        self.history.clear();
        self.cusum_p.reset();
        self.cusum_x.reset();
        self.cusum_t.reset();
        self.nis_central.clear();
        self.nis_federated.clear();
        self.map_low_run = 0;
        self.map_high_run = 0;
        self.maf_low_run = 0;
        self.maf_high_run = 0;
        self.map_frozen_run = 0;
        self.maf_frozen_run = 0;
        (self.last_map, self.last_maf) = (f64::NAN, f64::NAN);
        self.choked_run = 0;
        self.segment = 0;
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
