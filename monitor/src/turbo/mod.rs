//! The turbocharged air-path monitor: the structural flow residuals of the intake side
//! ([`fdd_estimators::models::turbo::residuals`]), each tested by a two-sided CUSUM after a
//! learned offset, the fault isolated and sized by the hypothesis bank
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
//! reading (the manifold's in `W_af - W_cyl` and `W_thr - W_cyl`, the intercooler's in
//! `W_af - W_thr`: each residual keeps the sensors it already had). Each is divided by the
//! filtered cylinder flow (at least `flow_floor_kg_s`): relative residuals.
//!
//! # Learned offsets
//!
//! The model is not the engine: each relative residual has an offset that differs from engine
//! to engine and from drive to drive (on the LiU-ICE logs up to 6 % between the fault-free run
//! and the fault runs before their faults). Like an ECU's adaptation values, the offsets are
//! learned: for `adapt_min_s` after the start of each operation cycle with time constant
//! `adapt_tau_s` and no test, then ten times slower and only while every normalized residual is
//! within [`LEARN_BAND`] scales and no alarm is pending. An offset is bounded by `adapt_limit`:
//! a residual that needs more is not adapted away.
//!
//! # Tests and decisions
//!
//! `z = (relative residual - offset) / residual_scale`, a two-sided CUSUM per residual with
//! reference `cusum_min_bias_sigma / 2` and threshold `cusum_threshold` (reported every frame
//! on `/fdd/tests` as `turbo_<residual>`). The hypothesis bank collects every steady frame
//! (all three residuals tested) since the CUSUMs were last all zero, so that it holds the
//! frames since about the fault's onset: each frame's balances against their learned offsets
//! (in kg/s) with the residual scales as their deviations. The first alarm opens an episode;
//! after `decision_window_s` the bank fits each single-fault hypothesis (a gain on `p_ic`,
//! `p_im` or the MAF, a bias on `T_ic`, a leak before or after the throttle, the throttle's
//! area) and the best is named when its probability among them is at least
//! `isolation_min_probability`; otherwise the group DTC carries the three best as candidates.
//! A leak before and a leak after the throttle share the leak DTC (the candidates say which).
//! A named fault stays failed for the operation cycle; the tests start again from zero after a
//! decision.

pub mod config;

use fdd_diagnostics::{TestResult, Verdict};
use fdd_estimators::models::turbo::isolation::{
    Hypothesis, IsolationBank, IsolationConfig, IsolationFrame,
};
use fdd_estimators::models::turbo::residuals::{
    flow_balance, ExhaustPressure, IntakeReadings, R_CYL, R_TC, R_THR,
};
use fdd_estimators::models::turbo::{TurboInput, TurboModel};

use crate::config_key::KeyPath;
use crate::monitor::{Monitor, Output, OutputSink};
use crate::monitor_events::{EventSpec, FreezeValues, MonitorEvents};
use crate::signal_table::{SignalId, SignalTable};

pub use config::{TurboConfig, TurboMonitorConfig, RESIDUALS};

/// While learning after the start phase, every normalized residual must be within this many
/// scales.
pub const LEARN_BAND: f64 = 1.5;
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
    "turbo_air_path_group",
];
/// Number of events.
pub const EVENTS: usize = 7;
const EV_GROUP: usize = 6;

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
pub const FAULT_CLASSES: [&str; 7] = [
    "turbo_p_im_sensor",
    "turbo_p_ic_sensor",
    "turbo_maf_sensor",
    "turbo_t_ic_sensor",
    "turbo_leak_before_throttle",
    "turbo_leak_after_throttle",
    "turbo_throttle_actuator",
];

/// Test names on `/fdd/tests`, in [`RESIDUALS`] order.
pub const TEST_NAMES: [&str; 3] = [
    "turbo_cylinder_flow",
    "turbo_throttle_flow",
    "turbo_throttle_cylinder",
];

/// Estimates the monitor outputs (and a freeze frame may hold).
pub const ESTIMATES: [&str; 2] = ["cylinder_flow", "throttle_flow"];

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

/// First-order low-pass state.
#[derive(Debug, Clone, Copy)]
struct Filters {
    raw: [f64; 3],
    p_im: f64,
    p_ic: f64,
    w_cyl: f64,
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
    cycle_start_s: Option<f64>,
    filters: Option<Filters>,
    offsets: [f64; 3],
    /// Time (s) each residual has been enabled without a break (the throttle residuals need
    /// a throttle that meters, see `throttle_ratio_max`).
    enabled_s: [f64; 3],
    /// The throttle of the previous frame (%) and the time until which a transient holds the
    /// tests (s).
    last_throttle: f64,
    hold_until_s: f64,
    cusum: [Cusum; 3],
    /// Signs of the residuals that alarmed in the open episode.
    alarmed: [i8; 3],
    episode_start_s: Option<f64>,
    /// The test result of the first alarm of the episode (what qualifies the DTC).
    episode_result: TestResult,
    bank: IsolationBank,
    ev_result: [TestResult; EVENTS],
    ev_cands: [[(&'static str, f64); 3]; EVENTS],
    ev_ncand: [usize; EVENTS],
    estimates: [f64; 2],
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
            cycle_start_s: None,
            filters: None,
            offsets: [0.0; 3],
            enabled_s: [0.0; 3],
            last_throttle: f64::NAN,
            hold_until_s: f64::NEG_INFINITY,
            cusum: [Cusum::default(); 3],
            alarmed: [0; 3],
            episode_start_s: None,
            episode_result: TestResult::NOT_TESTED,
            bank,
            ev_result: [TestResult::NOT_TESTED; EVENTS],
            ev_cands: [[("", 0.0); 3]; EVENTS],
            ev_ncand: [0; EVENTS],
            estimates: [f64::NAN; 2],
            frames: 0,
            events,
            model,
            cfg: cfg.clone(),
        })
    }

    /// The learned offsets of the relative residuals ([`RESIDUALS`] order).
    pub fn offsets(&self) -> [f64; 3] {
        self.offsets
    }

    /// Frames processed.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    fn reset_tests(&mut self) {
        self.bank.reset();
        self.cusum = [Cusum::default(); 3];
        self.alarmed = [0; 3];
        self.episode_start_s = None;
        self.episode_result = TestResult::NOT_TESTED;
    }

    fn reset_cycle(&mut self) {
        self.filters = None;
        self.enabled_s = [0.0; 3];
        self.last_throttle = f64::NAN;
        self.hold_until_s = f64::NEG_INFINITY;
        self.cycle_start_s = None;
        self.offsets = [0.0; 3];
        self.reset_tests();
        self.ev_result = [TestResult::NOT_TESTED; EVENTS];
        self.ev_ncand = [0; EVENTS];
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
        self.estimates = [b.w_cyl_kg_s, b.w_thr_kg_s];
        let tau = self.cfg.filter_tau_s;
        // The throttle meters the flow only with a clear pressure drop across it.
        let metering = r.p_im_pa <= self.cfg.throttle_ratio_max * r.p_ic_pa;
        let enabled = [true, metering, metering];
        let f = match self.filters {
            Some(mut f) if dt <= self.cfg.max_frame_gap_s => {
                let a = (dt / tau).min(1.0);
                for (i, &on) in enabled.iter().enumerate() {
                    if on {
                        f.raw[i] += a * (b.residuals[i] - f.raw[i]);
                        self.enabled_s[i] += dt;
                    } else {
                        // Restarted when enabled again: nothing of the unmetered time is kept.
                        f.raw[i] = b.residuals[i];
                        self.enabled_s[i] = 0.0;
                    }
                }
                f.p_im += a * (r.p_im_pa - f.p_im);
                f.p_ic += a * (r.p_ic_pa - f.p_ic);
                f.w_cyl += a * (b.w_cyl_kg_s - f.w_cyl);
                f
            }
            _ => {
                // (Re)start: the filters at the frame, the tests from zero.
                self.reset_tests();
                self.enabled_s = [0.0; 3];
                Filters {
                    raw: b.residuals,
                    p_im: r.p_im_pa,
                    p_ic: r.p_ic_pa,
                    w_cyl: b.w_cyl_kg_s,
                }
            }
        };
        self.filters = Some(f);
        let start = *self.cycle_start_s.get_or_insert(t_s);
        let fill_im = self.v_im_r / r.t_ic_k * (r.p_im_pa - f.p_im) / tau;
        let fill_ic = self.v_ic_r / r.t_ic_k * (r.p_ic_pa - f.p_ic) / tau;
        let reference = f.w_cyl.max(self.cfg.flow_floor_kg_s);
        let mut rel = [0.0; 3];
        rel[R_CYL] = (f.raw[R_CYL] - fill_im) / reference;
        rel[R_THR] = (f.raw[R_THR] - fill_ic) / reference;
        rel[R_TC] = (f.raw[R_TC] - fill_im) / reference;
        let z: [f64; 3] =
            std::array::from_fn(|i| (rel[i] - self.offsets[i]) / self.cfg.residual_scale[i]);
        let learning_phase = t_s - start < self.cfg.adapt_min_s;
        // A residual counts once its filter has run a time constant since it was enabled.
        let settled: [bool; 3] = std::array::from_fn(|i| self.enabled_s[i] >= tau);
        let quiet = self.episode_start_s.is_none()
            && (0..3).all(|i| !settled[i] || z[i].abs() < LEARN_BAND);
        if steady && (learning_phase || quiet) {
            let tau_a = if learning_phase {
                self.cfg.adapt_tau_s
            } else {
                self.cfg.adapt_tau_s * TRACK_SLOWDOWN
            };
            let a = (dt.min(self.cfg.max_frame_gap_s) / tau_a).min(1.0);
            let lim = self.cfg.adapt_limit;
            for i in (0..3).filter(|&i| settled[i]) {
                self.offsets[i] =
                    (self.offsets[i] + a * (rel[i] - self.offsets[i])).clamp(-lim, lim);
            }
        }
        let k = 0.5 * self.cfg.cusum_min_bias_sigma;
        let mut alarm = None;
        for i in 0..3 {
            let h = self.cfg.cusum_threshold[i];
            let result = if learning_phase || !settled[i] || !steady {
                TestResult::NOT_TESTED
            } else {
                self.cusum[i].step(z[i], k);
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
        // The bank holds the steady frames since the CUSUMs were last all zero (about the
        // onset of whatever they are accumulating).
        let tested = steady && !learning_phase && settled.iter().all(|&s| s);
        if self.episode_start_s.is_none() && self.cusum.iter().all(|c| c.value() == 0.0) {
            self.bank.reset();
        } else if tested {
            let frame = IsolationFrame {
                readings: *r,
                input: *u,
                exhaust: ExhaustPressure::Ambient,
                baseline_kg_s: [
                    self.offsets[R_CYL] * reference,
                    self.offsets[R_THR] * reference,
                ],
                sigma_kg_s: std::array::from_fn(|i| self.cfg.residual_scale[i] * reference),
            };
            // A frame the bank refuses (a reading it cannot linearize) is left out.
            let _ = self.bank.push(&frame);
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
    }

    fn decide_episode(&mut self) {
        let result = TestResult {
            verdict: Verdict::Failed,
            ..self.episode_result
        };
        let fits = self.bank.fits();
        let best = fits[0];
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
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
