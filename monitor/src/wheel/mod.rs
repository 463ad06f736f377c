//! The wheel monitor: a quarter-car filter per corner (fdd's estimator of
//! `fdd_estimators::models::wheel`, surface unknown) and the wheel-speed sensor checks an
//! ABS/ESC controller runs (REFERENCE §8), every 5 ms.
//!
//! # Per corner
//!
//! The filter takes the wheel's measured speed, its brake torque (as the ECU commands it) and,
//! on a front wheel, half the front axle's drive torque; it estimates the wheel speed, the
//! car's speed, the slip, the friction in use and the quarter mass ([`ESTIMATES`]). While less
//! than `rolling_torque_nm` acts on the wheel the rolling wheel's zero slip anchors the speed.
//! A wheel whose current is out of range is not fed (its reading is no reading).
//!
//! # Checks ([`checks`]) and their DTCs (per corner, SAE J2012 C0035 / C0040 / C0045 /
//! C0050 with the failure type byte)
//!
//! | check | fails when | FTB |
//! |---|---|---|
//! | current | out of `[current_min_ma, current_max_ma]` for `open_debounce_s` | 0x31 no signal |
//! | current | a shorter dropout that recovers | 0x1F intermittent |
//! | tone ring | innovation spikes beyond `spike_sigma` one revolution apart, `spikes_to_fail` in a row | 0x2F erratic |
//! | air gap | no speed with a valid current while the others' median moves (low speed), for `air_gap_debounce_s` (braked: `air_gap_braked_debounce_s`) | 0x29 invalid |
//! | ratio | the wheel's speed over the others' median, slip-corrected, beyond its learned offset (CUSUM), or that offset at its bound | 0x64 plausibility |
//!
//! The cross-wheel checks compare a wheel with the median of the other three, which one faulty
//! wheel cannot move. The ratio check runs only while every wheel's torque asks less than
//! [`GENTLE_MU`] of friction (slip under a percent; the remaining slip is corrected with the
//! dry curve's initial slope) above `ratio_min_speed_m_s`. A failed check stays failed until it
//! has passed for `heal_s`.
//!
//! # Information events
//!
//! At the end of each braking event the road surface under each wheel is named from the
//! event's slip and friction estimates ([`surface`]); the lowest-friction surface of the four
//! fails its information event (wet, snow, ice; dry passes them all). The car's mass (the sum
//! of the four quarter masses) outside `vehicle_mass_range_kg` after `mass_min_events` braking
//! events fails the mass event. These events never request the MIL.

pub mod checks;
pub mod config;
pub mod surface;

use fdd_diagnostics::{TestResult, Verdict};
use fdd_estimators::models::wheel::{
    Burckhardt, QuarterCar, Surface, WheelEkf, X_MASS, X_MU, X_OMEGA, X_SLIP, X_V,
};
use nalgebra::SVector;

use crate::config_key::KeyPath;
use crate::monitor::{Monitor, Output, OutputSink};
use crate::monitor_events::{EventSpec, FreezeValues, MonitorEvents};
use crate::signal_table::{SignalId, SignalTable};

use checks::{AirGap, Electrical, Ratio, ToneRing};
pub use config::{WheelConfig, WheelMonitorConfig, CORNERS, CORNER_NAMES, SENSOR_FTBS};
use surface::SurfaceEvidence;

/// The ratio check runs while every wheel's torque asks less than this friction (-).
pub const GENTLE_MU: f64 = 0.1;
/// Checks per corner, in [`SENSOR_FTBS`] order.
pub const CHECKS: usize = 5;
const C_OPEN: usize = 0;
const C_INTERMITTENT: usize = 1;
const C_ERRATIC: usize = 2;
const C_INVALID: usize = 3;
const C_PLAUSIBILITY: usize = 4;
/// Sensor events (corner-major), then the information events.
pub const EVENTS: usize = CORNERS * CHECKS + 4;
const EV_WET: usize = CORNERS * CHECKS;
const EV_MASS: usize = CORNERS * CHECKS + 3;

/// Event names, corner-major in [`SENSOR_FTBS`] order, then the information events.
pub const EVENT_NAMES: [&str; EVENTS] = [
    "wheel_fl_no_signal",
    "wheel_fl_intermittent",
    "wheel_fl_tone_ring",
    "wheel_fl_air_gap",
    "wheel_fl_plausibility",
    "wheel_fr_no_signal",
    "wheel_fr_intermittent",
    "wheel_fr_tone_ring",
    "wheel_fr_air_gap",
    "wheel_fr_plausibility",
    "wheel_rl_no_signal",
    "wheel_rl_intermittent",
    "wheel_rl_tone_ring",
    "wheel_rl_air_gap",
    "wheel_rl_plausibility",
    "wheel_rr_no_signal",
    "wheel_rr_intermittent",
    "wheel_rr_tone_ring",
    "wheel_rr_air_gap",
    "wheel_rr_plausibility",
    "road_surface_wet",
    "road_surface_snow",
    "road_surface_ice",
    "vehicle_mass_out_of_range",
];

/// The fault classes `fdd evaluate` scores: the sensor events' names.
pub const FAULT_CLASSES: [&str; CORNERS * CHECKS] = {
    let mut out = [""; CORNERS * CHECKS];
    let mut i = 0;
    while i < CORNERS * CHECKS {
        out[i] = EVENT_NAMES[i];
        i += 1;
    }
    out
};

/// Estimates per corner (vehicle speed m/s, slip -, friction -, quarter mass kg), then the
/// car's: reference speed (the median rim speed, m/s) and mass (kg).
pub const ESTIMATES: [&str; 4 * CORNERS + 2] = [
    "wheel_fl_vehicle_speed",
    "wheel_fl_slip",
    "wheel_fl_friction",
    "wheel_fl_quarter_mass",
    "wheel_fr_vehicle_speed",
    "wheel_fr_slip",
    "wheel_fr_friction",
    "wheel_fr_quarter_mass",
    "wheel_rl_vehicle_speed",
    "wheel_rl_slip",
    "wheel_rl_friction",
    "wheel_rl_quarter_mass",
    "wheel_rr_vehicle_speed",
    "wheel_rr_slip",
    "wheel_rr_friction",
    "wheel_rr_quarter_mass",
    "vehicle_reference_speed",
    "vehicle_mass",
];

/// Test names on `/fdd/tests`, per corner: the current (mA), the air-gap time (s), the tone
/// ring's chain of spikes (-), the ratio's CUSUM (-).
pub const TEST_NAMES: [[&str; 4]; CORNERS] = [
    [
        "wheel_fl_current",
        "wheel_fl_air_gap",
        "wheel_fl_tone_ring",
        "wheel_fl_ratio",
    ],
    [
        "wheel_fr_current",
        "wheel_fr_air_gap",
        "wheel_fr_tone_ring",
        "wheel_fr_ratio",
    ],
    [
        "wheel_rl_current",
        "wheel_rl_air_gap",
        "wheel_rl_tone_ring",
        "wheel_rl_ratio",
    ],
    [
        "wheel_rr_current",
        "wheel_rr_air_gap",
        "wheel_rr_tone_ring",
        "wheel_rr_ratio",
    ],
];

/// One 5 ms frame of the monitor's inputs: per corner the wheel speed (rad/s), the sensor
/// current (mA) and the brake torque (N m), and the front axle's drive torque (N m). NaN where
/// a value has not arrived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelReadings {
    pub speed: [f64; CORNERS],
    pub current: [f64; CORNERS],
    pub brake: [f64; CORNERS],
    pub drive: f64,
}

/// One corner's filter, checks and braking-event evidence.
#[derive(Debug, Clone)]
struct CornerState {
    ekf: WheelEkf,
    started: bool,
    electrical: Electrical,
    air_gap: AirGap,
    tone: ToneRing,
    ratio: Ratio,
    surface: SurfaceEvidence,
    braking: bool,
    last_surface: Option<Surface>,
    /// Per check: failed now (latched until healed) and time passed since.
    failed: [bool; CHECKS],
    passed_s: [f64; CHECKS],
}

/// The wheel monitor (see the module documentation).
pub struct WheelMonitor {
    cfg: WheelMonitorConfig,
    model: QuarterCar,
    estimator: fdd_estimators::models::wheel::WheelEstimatorParams,
    curves: [Burckhardt; 4],
    inputs: Vec<SignalId>,
    speed_ids: [SignalId; CORNERS],
    current_ids: [SignalId; CORNERS],
    brake_ids: [SignalId; CORNERS],
    drive_id: SignalId,
    period_ns: u64,
    last_t_ns: Option<u64>,
    corners: Vec<CornerState>,
    braking_events: u32,
    estimates: [f64; ESTIMATES.len()],
    scores: [f64; FAULT_CLASSES.len()],
    events: MonitorEvents,
}

impl WheelMonitor {
    /// The monitor on `cfg`, reading the named signals of `table`. Errors name the setting or
    /// the signal.
    pub fn new(cfg: &WheelConfig, table: &SignalTable) -> Result<Self, String> {
        let m = &cfg.monitor;
        m.validate(&KeyPath::file("wheel monitor settings").key("monitor"))
            .map_err(|e| e.to_string())?;
        let id = |name: &str| {
            table
                .id(name)
                .ok_or_else(|| format!("signal `{name}` is not in the runtime's signal table"))
        };
        let ids = |names: &[String; CORNERS]| -> Result<[SignalId; CORNERS], String> {
            Ok([
                id(&names[0])?,
                id(&names[1])?,
                id(&names[2])?,
                id(&names[3])?,
            ])
        };
        let speed_ids = ids(&m.speed_signals)?;
        let current_ids = ids(&m.current_signals)?;
        let brake_ids = ids(&m.brake_signals)?;
        let drive_id = id(&m.drive_signal)?;
        let mut inputs = Vec::with_capacity(3 * CORNERS + 1);
        inputs.extend(speed_ids);
        inputs.extend(current_ids);
        inputs.extend(brake_ids);
        inputs.push(drive_id);
        let model = QuarterCar::new(cfg.params, cfg.estimator.friction());
        let filter = cfg.estimator.filter();
        let ekf = WheelEkf::new(model, &filter, 0.0, cfg.params.quarter_mass_kg)
            .map_err(|e| format!("wheel estimator: {e}"))?;
        let corner = CornerState {
            ekf,
            started: false,
            electrical: Electrical::default(),
            air_gap: AirGap::default(),
            tone: ToneRing::default(),
            ratio: Ratio::default(),
            surface: SurfaceEvidence::default(),
            braking: false,
            last_surface: None,
            failed: [false; CHECKS],
            passed_s: [0.0; CHECKS],
        };
        let sensor_dtcs: Vec<String> = (0..CORNERS)
            .flat_map(|c| SENSOR_FTBS.map(|f| format!("{}-{f}", m.dtc_sensor[c])))
            .collect();
        let mut specs: Vec<EventSpec<'_>> = sensor_dtcs
            .iter()
            .zip(EVENT_NAMES)
            .map(|(dtc, name)| EventSpec::internal(name, dtc, 2))
            .collect();
        for (name, dtc) in EVENT_NAMES[EV_WET..].iter().zip([
            &m.dtc_surface_wet,
            &m.dtc_surface_snow,
            &m.dtc_surface_ice,
            &m.dtc_mass,
        ]) {
            specs.push(EventSpec::information(name, dtc, 5));
        }
        let events = MonitorEvents::new(&specs)
            .map_err(|e| e.to_string())?
            .with_estimates(&ESTIMATES);
        let s = &cfg.params.surfaces;
        Ok(Self {
            cfg: m.clone(),
            model,
            estimator: cfg.estimator,
            curves: Surface::ALL.map(|x| s.curve(x)),
            inputs,
            speed_ids,
            current_ids,
            brake_ids,
            drive_id,
            period_ns: (m.period_s * 1e9).round().max(1.0) as u64,
            last_t_ns: None,
            corners: vec![corner; CORNERS],
            braking_events: 0,
            estimates: [f64::NAN; ESTIMATES.len()],
            scores: [0.0; FAULT_CLASSES.len()],
            events,
        })
    }

    fn reset_cycle(&mut self) {
        self.last_t_ns = None;
        self.braking_events = 0;
        for c in &mut self.corners {
            c.started = false;
            c.electrical = Electrical::default();
            c.air_gap = AirGap::default();
            c.tone = ToneRing::default();
            c.ratio = Ratio::default();
            c.surface = SurfaceEvidence::default();
            c.braking = false;
            c.last_surface = None;
            c.failed = [false; CHECKS];
            c.passed_s = [0.0; CHECKS];
        }
        self.estimates = [f64::NAN; ESTIMATES.len()];
        self.scores = [0.0; FAULT_CLASSES.len()];
    }

    /// The friction the corner's torques ask at its estimated quarter mass (-, signed).
    fn torque_mu(&self, c: usize, torques: &SVector<f64, 2>) -> f64 {
        let p = &self.model.params;
        let m = self.corners[c].ekf.state()[X_MASS];
        (torques[0] - torques[1])
            / (p.gravity_m_s2 * (p.radius_m * m + p.inertia_kg_m2 / p.radius_m))
    }

    /// One 5 ms frame at `t_ns`.
    pub fn process_frame(
        &mut self,
        t_ns: u64,
        readings: &WheelReadings,
        signals: Option<&SignalTable>,
        out: &mut OutputSink<'_>,
    ) {
        let WheelReadings {
            speed,
            current,
            brake,
            drive,
        } = *readings;
        let t = t_ns as f64 * 1e-9;
        let dt = self.last_t_ns.map_or(self.cfg.period_s, |l| {
            (t_ns.saturating_sub(l) as f64 * 1e-9).min(10.0 * self.cfg.period_s)
        });
        self.last_t_ns = Some(t_ns);
        let r = self.model.params.radius_m;
        let drive = if drive.is_finite() { drive } else { 0.0 };
        let mut rim = [f64::NAN; CORNERS];
        let mut z = [0.0; CORNERS];
        let mut torques = [SVector::<f64, 2>::zeros(); CORNERS];
        for c in 0..CORNERS {
            let front = c < 2;
            let b = if brake[c].is_finite() {
                brake[c].max(0.0)
            } else {
                0.0
            };
            torques[c] = SVector::<f64, 2>::new(b, if front { 0.5 * drive } else { 0.0 });
            let st = &mut self.corners[c];
            st.electrical.step(&self.cfg, t, dt, current[c]);
            if !st.electrical.valid() || !speed[c].is_finite() {
                continue;
            }
            rim[c] = r * speed[c].max(0.0);
            if !st.started {
                // Start the filter at the wheel's speed (rolling).
                if st
                    .ekf
                    .restart(rim[c], self.model.params.quarter_mass_kg)
                    .is_ok()
                {
                    st.started = true;
                }
                continue;
            }
            let rolling = self.estimator.rolling(&torques[c]);
            if let Ok(inn) = st.ekf.step(speed[c].max(0.0), &torques[c], rolling) {
                let s = inn.covariance[(0, 0)];
                if s > 0.0 {
                    z[c] = inn.residual[0] / s.sqrt();
                }
            }
        }
        // The others' median rim speed for each corner, and the car's reference (the median of
        // all readable wheels).
        let others = |c: usize| -> f64 {
            let mut v = [0.0; 3];
            let mut n = 0;
            for (k, &x) in rim.iter().enumerate() {
                if k != c && x.is_finite() {
                    v[n] = x;
                    n += 1;
                }
            }
            median(&mut v[..n])
        };
        let mut all = rim;
        let valid_n = {
            let mut n = 0;
            for k in 0..CORNERS {
                if all[k].is_finite() {
                    all[n] = all[k];
                    n += 1;
                }
            }
            n
        };
        let reference = median(&mut all[..valid_n]);
        let gentle = (0..CORNERS).all(|c| self.torque_mu(c, &torques[c]).abs() < GENTLE_MU)
            && valid_n == CORNERS
            && reference >= self.cfg.ratio_min_speed_m_s;
        // Slip-corrected rim speeds for the ratio: v = r omega / (1 - lambda), lambda from the
        // torque's friction over the dry curve's initial slope.
        let slope0 = self.curves[0].slope(0.0);
        let mut corrected = [f64::NAN; CORNERS];
        if gentle {
            for c in 0..CORNERS {
                let lambda = self.torque_mu(c, &torques[c]) / slope0;
                corrected[c] = rim[c] / (1.0 - lambda);
            }
        }
        let mut any_braking_ended = false;
        for c in 0..CORNERS {
            let o = others(c);
            let braked = torques[c][0] > self.cfg.free_torque_nm;
            let mut verdicts: [Option<bool>; CHECKS] = [None; CHECKS];
            let st = &mut self.corners[c];
            verdicts[C_OPEN] = Some(st.electrical.open);
            verdicts[C_INTERMITTENT] = Some(st.electrical.last_dropout_s.is_some_and(|d| d == t));
            if st.electrical.valid() && st.started {
                let x = *st.ekf.state();
                verdicts[C_ERRATIC] = Some(st.tone.step(&self.cfg, t, dt, x[X_OMEGA], z[c]));
                verdicts[C_INVALID] =
                    st.air_gap
                        .step(&self.cfg, dt, rim[c], o, braked, st.electrical.valid());
                if gentle {
                    let mut v = [0.0; 3];
                    let mut n = 0;
                    for (k, &x) in corrected.iter().enumerate() {
                        if k != c {
                            v[n] = x;
                            n += 1;
                        }
                    }
                    let e = corrected[c] / median(&mut v[..n]) - 1.0;
                    verdicts[C_PLAUSIBILITY] = st.ratio.step(&self.cfg, dt, e);
                }
                // Braking events: the surface evidence while the slip is high enough.
                if braked {
                    st.braking = true;
                    if x[X_SLIP] >= self.cfg.surface_min_slip {
                        st.surface.add(&self.curves, x[X_SLIP], x[X_MU]);
                    }
                } else if st.braking {
                    st.braking = false;
                    if let Some(s) = st.surface.best() {
                        st.last_surface = Some(s);
                    }
                    st.surface = SurfaceEvidence::default();
                    any_braking_ended = true;
                }
            }
            for (k, v) in verdicts.iter().enumerate() {
                match v {
                    Some(true) => {
                        st.failed[k] = true;
                        st.passed_s[k] = 0.0;
                    }
                    Some(false) if st.failed[k] => {
                        st.passed_s[k] += dt;
                        if st.passed_s[k] >= self.cfg.heal_s {
                            st.failed[k] = false;
                        }
                    }
                    _ => {}
                }
            }
            // Outputs of the tests' statistics.
            let names = TEST_NAMES[c];
            let result = |value: f64, min: f64, max: f64, failed: bool| TestResult {
                value,
                min,
                max,
                verdict: if failed {
                    Verdict::Failed
                } else {
                    Verdict::Passed
                },
            };
            out(Output::Test {
                test: names[0],
                result: result(
                    current[c],
                    self.cfg.current_min_ma,
                    self.cfg.current_max_ma,
                    st.failed[C_OPEN] || st.failed[C_INTERMITTENT],
                ),
            });
            out(Output::Test {
                test: names[1],
                result: match verdicts[C_INVALID] {
                    Some(_) => result(
                        st.air_gap.free_s + st.air_gap.braked_s,
                        0.0,
                        self.cfg.air_gap_debounce_s,
                        st.failed[C_INVALID],
                    ),
                    None => TestResult::NOT_TESTED,
                },
            });
            out(Output::Test {
                test: names[2],
                result: match verdicts[C_ERRATIC] {
                    Some(_) => result(
                        f64::from(st.tone.chain),
                        0.0,
                        f64::from(self.cfg.spikes_to_fail),
                        st.failed[C_ERRATIC],
                    ),
                    None => TestResult::NOT_TESTED,
                },
            });
            out(Output::Test {
                test: names[3],
                result: match verdicts[C_PLAUSIBILITY] {
                    Some(_) => result(
                        st.ratio.value(),
                        0.0,
                        self.cfg.ratio_cusum_threshold,
                        st.failed[C_PLAUSIBILITY],
                    ),
                    None => TestResult::NOT_TESTED,
                },
            });
        }
        if any_braking_ended {
            self.braking_events += 1;
        }
        // Estimates.
        let mut mass = 0.0;
        for (c, st) in self.corners.iter().enumerate() {
            let x = st.ekf.state();
            let e = &mut self.estimates[4 * c..4 * c + 4];
            if st.started {
                e.copy_from_slice(&[x[X_V], x[X_SLIP], x[X_MU], x[X_MASS]]);
                mass += x[X_MASS];
            } else {
                e.fill(f64::NAN);
                mass = f64::NAN;
            }
        }
        self.estimates[4 * CORNERS] = reference;
        self.estimates[4 * CORNERS + 1] = mass;
        // Events: the sensor checks, then the information.
        let values = FreezeValues {
            signals,
            estimates: &self.estimates,
        };
        let mut n_failed = 0;
        self.scores = [0.0; FAULT_CLASSES.len()];
        for c in 0..CORNERS {
            for k in 0..CHECKS {
                let e = c * CHECKS + k;
                let failed = self.corners[c].failed[k];
                if failed {
                    self.scores[e] = 1.0;
                    n_failed += 1;
                }
                let r = TestResult {
                    value: if failed { 1.0 } else { 0.0 },
                    min: 0.0,
                    max: 0.5,
                    verdict: if failed {
                        Verdict::Failed
                    } else {
                        Verdict::Passed
                    },
                };
                if self.corners[c].started || failed {
                    self.events.report_one(e, t, &r, &[], values, out);
                }
            }
        }
        if n_failed > 1 {
            let n = f64::from(n_failed);
            for s in &mut self.scores {
                *s /= n;
            }
        }
        // The lowest-friction surface named at the last braking events.
        let lowest = self
            .corners
            .iter()
            .filter_map(|c| c.last_surface)
            .max_by_key(|s| s.index());
        if let Some(low) = lowest {
            for (k, s) in [Surface::Wet, Surface::Snow, Surface::Ice]
                .into_iter()
                .enumerate()
            {
                let failed = low == s;
                let r = TestResult {
                    value: low.index() as f64,
                    min: 0.0,
                    max: s.index() as f64 - 0.5,
                    verdict: if failed {
                        Verdict::Failed
                    } else {
                        Verdict::Passed
                    },
                };
                self.events.report_one(EV_WET + k, t, &r, &[], values, out);
            }
        }
        if self.braking_events >= self.cfg.mass_min_events && mass.is_finite() {
            let [lo, hi] = self.cfg.vehicle_mass_range_kg;
            let failed = mass < lo || mass > hi;
            let r = TestResult {
                value: mass,
                min: lo,
                max: hi,
                verdict: if failed {
                    Verdict::Failed
                } else {
                    Verdict::Passed
                },
            };
            self.events.report_one(EV_MASS, t, &r, &[], values, out);
        }
        for (i, name) in ESTIMATES.iter().enumerate() {
            out(Output::Estimate {
                name,
                value: self.estimates[i],
                lower: f64::NAN,
                upper: f64::NAN,
                source: "quarter-car filter",
            });
        }
        out(Output::Diagnosis {
            flagged: n_failed > 0,
            scores: &self.scores,
        });
    }
}

/// The median of a few values (sorts them in place); NaN for none.
fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    v.sort_unstable_by(f64::total_cmp);
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

impl Monitor for WheelMonitor {
    fn name(&self) -> &str {
        "wheel"
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
        // A frame: the four wheel speeds stamped alike and newer than the last frame.
        let mut speed = [f64::NAN; CORNERS];
        let mut t = None;
        for (c, id) in self.speed_ids.iter().enumerate() {
            let Some(s) = signals.get(*id) else {
                return;
            };
            if t.is_some_and(|t| t != s.t_ns) {
                return;
            }
            t = Some(s.t_ns);
            speed[c] = s.value;
        }
        let Some(t) = t else {
            return;
        };
        if t > now_ns || self.last_t_ns.is_some_and(|l| t <= l) {
            return;
        }
        let value = |id: SignalId| signals.get(id).map_or(f64::NAN, |s| s.value);
        let current = self.current_ids.map(value);
        let brake = self.brake_ids.map(value);
        let drive = value(self.drive_id);
        let readings = WheelReadings {
            speed,
            current,
            brake,
            drive,
        };
        self.process_frame(t, &readings, Some(signals), out);
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

    /// The wheel speeds and currents, the car's reference speed and mass.
    fn default_freeze_frame(&self) -> Vec<String> {
        self.cfg
            .speed_signals
            .iter()
            .chain(&self.cfg.current_signals)
            .chain(&self.cfg.brake_signals)
            .cloned()
            .chain([
                "vehicle_reference_speed".to_string(),
                "vehicle_mass".to_string(),
            ])
            .collect()
    }

    /// A cleared DTC is tested again from scratch.
    fn restart_tests(&mut self, _now_ns: u64) {
        for c in &mut self.corners {
            c.failed = [false; CHECKS];
            c.passed_s = [0.0; CHECKS];
            c.air_gap = AirGap::default();
            c.tone = ToneRing::default();
            c.ratio.up = 0.0;
            c.ratio.down = 0.0;
        }
    }
}
