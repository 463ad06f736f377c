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
//!   track, as in the Table II reproduction).
//!
//! Tests: a jump/noise test (windowed sum of capped TPS NIS), a CUSUM on the TPS filter's
//! normalized innovation, a CUSUM on the combined filter's wattmeter innovation, rail checks
//! that judge a TPS reading at 0 V / 5 V against the model (a closed plate also reads 0 V), a
//! frozen-signal check, and a "static while driven" check for the plate.
//!
//! Decision: an open circuit / short is a rail reading the model calls implausible that lasts
//! `rail_persist_s`; shorter episodes are dropouts, and `intermittent_count` of them within
//! `intermittent_window_s` make an intermittent circuit. When a residual test fails, the monitor
//! waits `decision_window_s` for the other tests, then names the fault: frozen TPS -> TPS stuck
//! (P0121); TPS static while the voltage should move the plate, not frozen -> plate stuck
//! (P2119); only the wattmeter test -> wattmeter (P1651, manufacturer code); otherwise TPS
//! range/performance (P0121).
//!
//! Recovery policy: a TPS fault is latched for the rest of the operation cycle. From the step
//! it is qualified, the position output comes from the wattmeter estimate (`source =
//! "wattmeter_estimate"`), the TPS is no longer used by any filter, and the switch is reported as
//! an event. A new operation cycle starts again from the TPS. A wattmeter or plate fault never
//! switches the output (the TPS stays the source).

pub mod config;

use fdd_diagnostics::detectors::{two_sided_arl, Cusum, CusumConfig};
use fdd_diagnostics::{TestResult, Verdict};
use fdd_estimators::models::throttle::{PositionAndWattmeter, PositionSensor, ThrottleModel};
use fdd_estimators::reacquire::Reacquire;
use fdd_estimators::{SigmaPoints, Ukf};
use nalgebra::{Matrix1, Matrix2, Matrix3, Vector1, Vector2, Vector3};

pub use config::ThrottleMonitorConfig;

use crate::monitor::{Monitor, Output, OutputSink};
use crate::monitor_events::{EventSpec, FreezeValues, MonitorEvents};
use crate::signal_table::{SignalId, SignalTable};

/// Capacity of the fixed rings (NIS window, motion window, dropout times).
const RING: usize = 512;

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
        match self {
            ThrottleFault::TpsOpen => "tps_open_circuit",
            ThrottleFault::TpsShort => "tps_short_circuit",
            ThrottleFault::TpsIntermittent => "tps_intermittent",
            ThrottleFault::TpsStuck => "tps_stuck",
            ThrottleFault::TpsPerformance => "tps_range_performance",
            ThrottleFault::PlateStuck => "plate_stuck",
            ThrottleFault::Wattmeter => "wattmeter",
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

/// Errors building the monitor.
#[derive(Debug, thiserror::Error)]
pub enum ThrottleMonitorError {
    #[error("throttle monitor: signal `{0}` is not in the signal table")]
    MissingSignal(String),
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
    reacquire: Reacquire,
    u_slow: f64,
    u_alpha: f64,
    nis_ring: Ring,
    nis_sum: f64,
    cusum_tps: Cusum,
    cusum_watt: Cusum,
    tps_hist: Ring,
    eq_hist: Ring,
    rail_persist: u32,
    rail_low_run: u32,
    rail_high_run: u32,
    dropouts: Ring,
    frozen_run: u32,
    last_tps: f64,
    first_fail_s: Option<f64>,
    fired: [bool; 3],
    decided: Option<ThrottleFault>,
    /// The test result that qualified the fault (reported with its DTC's events).
    deciding: TestResult,
    /// The first failing residual test's result, kept through the decision window.
    first_result: TestResult,
    tps_failed: bool,
    watt_failed: bool,
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
        for (key, v) in [
            ("period_s", cfg.period_s),
            ("tps_noise_v", cfg.tps_noise_v),
            ("wattmeter_noise_w", cfg.wattmeter_noise_w),
            ("rail_persist_s", cfg.rail_persist_s),
            ("decision_window_s", cfg.decision_window_s),
            ("motion_window_s", cfg.motion_window_s),
            ("intermittent_window_s", cfg.intermittent_window_s),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(setting(key, format!("{v} must be a positive number")));
            }
        }
        if !(cfg.rail_low_v < cfg.rail_high_v) {
            return Err(setting("rail_low_v", "must be below rail_high_v"));
        }
        if cfg.tps_nis_window == 0 || cfg.tps_nis_window > RING {
            return Err(setting("tps_nis_window", format!("must be 1..={RING}")));
        }
        let motion = (cfg.motion_window_s / cfg.period_s).round() as usize;
        if motion == 0 || motion > RING {
            return Err(setting(
                "motion_window_s",
                format!("must span 1..={RING} steps"),
            ));
        }
        if cfg.intermittent_count == 0 || cfg.intermittent_count > RING {
            return Err(setting("intermittent_count", format!("must be 1..={RING}")));
        }
        let scale = model.params().angle_scale;
        let tps = PositionSensor::new(tps_full_scale_v, tps_full_scale_deg, scale);
        let both = PositionAndWattmeter { position: tps };
        let p0 = Matrix3::identity();
        let q = Matrix3::from_diagonal(&Vector3::new(3.15e-4, 1e-2, 1.62e-4));
        let rt = cfg.tps_noise_v * cfg.tps_noise_v;
        let rw = cfg.wattmeter_noise_w * cfg.wattmeter_noise_w + cfg.wattmeter_r_floor;
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
        let cusum =
            |key: &'static str, delta: f64, h: f64| -> Result<Cusum, ThrottleMonitorError> {
                if !(delta > 0.0 && h > 0.0) {
                    return Err(setting(key, "min bias and threshold must be positive"));
                }
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
            tps_ukf,
            both_ukf,
            reacquire: Reacquire::new(50.0, 2.0, 50)?,
            u_slow: 0.0,
            u_alpha: (cfg.period_s / 0.033).min(1.0),
            nis_ring: Ring::new(cfg.tps_nis_window),
            nis_sum: 0.0,
            cusum_tps: cusum(
                "tps_cusum_threshold",
                cfg.tps_cusum_min_bias_sigma,
                cfg.tps_cusum_threshold,
            )?,
            cusum_watt: cusum(
                "watt_cusum_threshold",
                cfg.watt_cusum_min_bias_sigma,
                cfg.watt_cusum_threshold,
            )?,
            tps_hist: Ring::new(motion),
            eq_hist: Ring::new(motion),
            rail_persist: ((cfg.rail_persist_s / cfg.period_s).round() as u32).max(1),
            rail_low_run: 0,
            rail_high_run: 0,
            dropouts: Ring::new(cfg.intermittent_count),
            frozen_run: 0,
            last_tps: f64::NAN,
            first_fail_s: None,
            fired: [false; 3],
            decided: None,
            deciding: TestResult::NOT_TESTED,
            first_result: TestResult::NOT_TESTED,
            tps_failed: false,
            watt_failed: false,
            events,
            inputs,
            model,
            cfg: cfg.clone(),
        })
    }

    /// The fault named this cycle, if any.
    pub fn decided_fault(&self) -> Option<ThrottleFault> {
        self.decided
    }

    /// True once the TPS is failed and the output comes from the wattmeter estimate.
    pub fn on_wattmeter_estimate(&self) -> bool {
        self.tps_failed
    }

    fn report_all(
        &mut self,
        now_s: f64,
        verdicts: [Verdict; 7],
        values: FreezeValues<'_>,
        out: &mut OutputSink<'_>,
    ) {
        // A failed event carries the test result that qualified the fault and the candidate;
        // other reports carry only their verdict (the tests' statistics are on their own
        // outputs).
        let candidate = self.decided.map(|f| [(f.name(), 1.0)]);
        let candidates: &[(&str, f64)] = candidate.as_ref().map_or(&[], |c| c);
        self.events
            .report(now_s, &verdicts, &self.deciding, candidates, values, out);
    }

    /// Restarts the fault decision and the filters, as at the start of an operation cycle
    /// (after a cycle start, or after a ClearDTC of this monitor's DTCs).
    fn restart(&mut self) {
        self.tps_ukf = self.tps_ukf_init.clone();
        self.both_ukf = self.both_ukf_init.clone();
        self.decided = None;
        self.deciding = TestResult::NOT_TESTED;
        self.first_result = TestResult::NOT_TESTED;
        self.tps_failed = false;
        self.watt_failed = false;
        self.first_fail_s = None;
        self.fired = [false; 3];
        self.nis_ring.clear();
        self.nis_sum = 0.0;
        self.dropouts.clear();
        self.rail_low_run = 0;
        self.rail_high_run = 0;
    }

    fn classify(&self) -> ThrottleFault {
        if self.frozen_run >= self.cfg.frozen_samples {
            return ThrottleFault::TpsStuck;
        }
        let static_tps =
            self.tps_hist.full() && self.tps_hist.span() < self.cfg.static_tps_range_deg;
        // The voltage moved the static map, or holds the plate's rest angle far from the TPS.
        let away = match (self.eq_hist.last(), self.tps_hist.last()) {
            (Some(eq), Some(tps)) => (eq - tps).abs() > self.cfg.driven_range_deg,
            _ => false,
        };
        let driven =
            (self.eq_hist.full() && self.eq_hist.span() > self.cfg.driven_range_deg) || away;
        if static_tps && driven {
            return ThrottleFault::PlateStuck;
        }
        if self.fired[2] && !self.fired[0] && !self.fired[1] {
            return ThrottleFault::Wattmeter;
        }
        ThrottleFault::TpsPerformance
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
            rail_low = v <= self.cfg.rail_low_v
                && theta_p - 3.0 * sigma_p > limits[0] + self.cfg.rail_margin_deg;
            rail_high = v >= self.cfg.rail_high_v
                && theta_p + 3.0 * sigma_p < limits[1] - self.cfg.rail_margin_deg;
            self.frozen_run = if v == self.last_tps {
                self.frozen_run + 1
            } else {
                0
            };
            self.last_tps = v;
            self.tps_hist.push(v / self.volts_per_deg);
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

        // Filters.
        let tps_usable = tps.is_some() && !rail_low && !rail_high && !self.tps_failed;
        let mut nis_t = f64::NAN;
        let mut z_t = f64::NAN;
        if let (true, Some(v)) = (tps_usable, tps) {
            if let Ok(inn) = self.tps_ukf.update(&Vector1::new(v), &uu) {
                nis_t = inn.nis;
                z_t = inn.normalized(0);
                out(Output::Innovation {
                    filter: "tps",
                    residual: inn.residual.as_slice(),
                    variance: &[inn.covariance[(0, 0)]],
                    nis: inn.nis,
                    dof: inn.dof,
                });
            }
        }
        let use_tps = tps_usable && nis_t.is_finite() && nis_t < self.cfg.tps_gate_nis;
        let use_watt = watt.is_some() && !self.watt_failed;
        let mut z_w = f64::NAN;
        if use_tps || use_watt {
            let y = Vector2::new(tps.unwrap_or(0.0), watt.unwrap_or(0.0));
            if let Ok(inn) = self.both_ukf.update_subset(&y, &uu, &[use_tps, use_watt]) {
                if use_watt {
                    z_w = inn.normalized(1);
                }
                if !use_tps && self.reacquire.observe(inn.nis, inn.dof) {
                    let _reset_ok = self.both_ukf.reset(eq, self.p0).is_ok();
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
        let cusum_tps = self.cusum_tps.step(z_t.clamp(-clip, clip), z_t.is_finite());
        let cusum_watt = self
            .cusum_watt
            .step(z_w.clamp(-clip, clip), z_w.is_finite());
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

        // Decision.
        let results = [nis_result, cusum_tps, cusum_watt];
        let mut newly = None;
        if self.decided.is_none() {
            let intermittent =
                self.dropouts.full() && self.dropouts.span() <= self.cfg.intermittent_window_s;
            // Rail time against the longest episode that is still a dropout (s).
            let rail = |run: u32| TestResult {
                value: f64::from(run) * self.cfg.period_s,
                min: 0.0,
                max: f64::from(self.rail_persist - 1) * self.cfg.period_s,
                verdict: Verdict::Failed,
            };
            if self.rail_low_run >= self.rail_persist {
                newly = Some((ThrottleFault::TpsOpen, rail(self.rail_low_run)));
            } else if self.rail_high_run >= self.rail_persist {
                newly = Some((ThrottleFault::TpsShort, rail(self.rail_high_run)));
            } else if intermittent {
                let count = self.cfg.intermittent_count as f64;
                let dropouts = TestResult {
                    value: count,
                    min: 0.0,
                    max: count - 1.0,
                    verdict: Verdict::Failed,
                };
                newly = Some((ThrottleFault::TpsIntermittent, dropouts));
            } else {
                for (i, r) in results.iter().enumerate() {
                    if r.verdict == Verdict::Failed {
                        self.fired[i] = true;
                        if self.first_fail_s.is_none() {
                            self.first_fail_s = Some(now_s);
                            self.first_result = *r;
                        }
                    }
                }
                if let Some(t0) = self.first_fail_s {
                    if now_s - t0 >= self.cfg.decision_window_s {
                        newly = Some((self.classify(), self.first_result));
                    }
                }
            }
        }
        let newly = newly.map(|(f, r)| {
            self.deciding = r;
            f
        });
        if let Some(f) = newly {
            self.decided = Some(f);
            if f.is_tps() {
                self.tps_failed = true;
                tracing::debug!(
                    time_s = now_s,
                    fault = f.name(),
                    "TPS failed: position from the wattmeter estimate"
                );
            }
            if f == ThrottleFault::Wattmeter {
                self.watt_failed = true;
            }
        }
        let mut event_verdicts = [Verdict::NotTested; 7];
        match self.decided {
            Some(f) => {
                event_verdicts[f.event()] = Verdict::Failed;
                event_verdicts[SWITCH_EVENT] = if self.tps_failed {
                    Verdict::Failed
                } else {
                    Verdict::Passed
                };
            }
            None if self.first_fail_s.is_none()
                && self.rail_low_run == 0
                && self.rail_high_run == 0 =>
            {
                event_verdicts = [Verdict::Passed; 7];
            }
            None => {}
        }
        // Position output: fused with the TPS while it is trusted, the wattmeter estimate after.
        let x = *self.both_ukf.state();
        let angle = self.model.angle_deg(&x);
        let values = FreezeValues {
            signals: Some(signals),
            estimates: &[angle],
        };
        self.report_all(now_s, event_verdicts, values, out);
        let half = 1.96 * self.both_ukf.covariance()[(0, 0)].max(0.0).sqrt()
            / self.model.params().angle_scale;
        out(Output::Estimate {
            name: "throttle_angle",
            value: angle,
            lower: (angle - half).max(limits[0]),
            upper: (angle + half).min(limits[1]),
            source: if self.tps_failed {
                "wattmeter_estimate"
            } else {
                "tps"
            },
        });

        let _ = self.tps_ukf.predict(&uu);
        let _ = self.both_ukf.predict(&uu);
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
