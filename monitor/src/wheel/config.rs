//! `config/wheel_monitor.toml`: which parameter file the wheel monitor's four quarter-car
//! filters run on (`config/wheel.toml`), the signals it reads per corner, its checks and its
//! DTCs.

use std::path::{Path, PathBuf};

use fdd_estimators::models::wheel::{WheelEstimatorParams, WheelParams};
use fdd_estimators::param::Range;
use serde::Deserialize;

use crate::config::ConfigError;
use crate::config_key::{parse_toml, KeyPath};

/// The monitor file compiled into the binary.
pub const DEFAULT_WHEEL_MONITOR_TOML: &str = include_str!("../../../config/wheel_monitor.toml");
/// The parameter file it names, compiled in with it.
pub const DEFAULT_WHEEL_PARAMS_TOML: &str = include_str!("../../../config/wheel.toml");
/// The name the embedded monitor file gives its parameter file.
pub const DEFAULT_PARAMS_NAME: &str = "wheel.toml";

/// Number of corners.
pub const CORNERS: usize = 4;
/// Corner names in signal, event and array order.
pub const CORNER_NAMES: [&str; CORNERS] = ["fl", "fr", "rl", "rr"];

/// `[monitor]` of the monitor file (every key optional).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WheelMonitorConfig {
    /// Step of the monitor (s): the ABS ECU's wheel-speed period.
    pub period_s: f64,
    /// Wheel speed per corner (rad/s), FL, FR, RL, RR.
    pub speed_signals: [String; CORNERS],
    /// Wheel-speed sensor supply current per corner (mA).
    pub current_signals: [String; CORNERS],
    /// Brake torque per corner as the ECU commands it (N m).
    pub brake_signals: [String; CORNERS],
    /// Drive torque at the front axle (N m), split equally between the front wheels.
    pub drive_signal: String,
    /// An active sensor's current outside `[current_min_ma, current_max_ma]` is a circuit
    /// fault (mA): a healthy one alternates between about 7 and 14 mA, an open circuit gives
    /// none, a short to supply more than 20.
    pub current_min_ma: f64,
    pub current_max_ma: f64,
    /// A current fault lasting this long is an open circuit, "no signal" (s); one that ends
    /// sooner is an intermittent contact.
    pub open_debounce_s: f64,
    /// A reading below this wheel rim speed counts as "no speed" (m/s): the ECU's timeout
    /// speed (a tone wheel with too few edges per timeout reads 0).
    pub zero_speed_m_s: f64,
    /// The other wheels' median rim speed above which a wheel reading "no speed" with a valid
    /// current is implausible (m/s): a lost pulse train (air gap), unless the wheel is locked.
    pub air_gap_others_m_s: f64,
    /// How long that must last with no brake on the wheel (s), and how long with one (s): a
    /// braked wheel may lock briefly (the ABS releases it within a few tenths; below its
    /// working speed a stopping car's wheels lock for good, which the speed window excludes).
    pub air_gap_debounce_s: f64,
    pub air_gap_braked_debounce_s: f64,
    /// The air-gap check looks only while the others' median rim speed is below this (m/s): a
    /// lost pulse train shows at low wheel speed (the signal's amplitude grows with speed);
    /// at higher speed a wheel reading zero is a lost signal of another kind, left to the
    /// plausibility check.
    pub air_gap_max_speed_m_s: f64,
    /// An innovation of the wheel's filter beyond this many standard deviations is a spike.
    pub spike_sigma: f64,
    /// Spikes that recur at the same wheel angle (within `spike_angle_tol_rad`) in
    /// `spikes_to_fail` of the last revolutions within `spike_window_s` are a damaged tone
    /// ring: its defect passes the sensor once per revolution.
    pub spike_angle_tol_rad: f64,
    pub spikes_to_fail: u32,
    pub spike_window_s: f64,
    /// Gain plausibility: the wheel's rim speed over the median of the others, tested while
    /// every wheel rolls freely (each wheel's torque magnitude below `free_torque_nm`) above
    /// `ratio_min_speed_m_s` (m/s).
    pub free_torque_nm: f64,
    pub ratio_min_speed_m_s: f64,
    /// The ratios' learned offsets (healthy tyres differ by wear and pressure): time constant
    /// while learning alone (s; afterwards ten times slower, and only within the CUSUM's
    /// reference), and the largest offset learned (-); an offset at that bound fails the test.
    pub ratio_learn_tau_s: f64,
    pub ratio_learn_limit: f64,
    /// Free-rolling time per operation cycle the offsets learn alone before the test starts (s).
    pub ratio_learn_min_s: f64,
    /// The smallest ratio error the test is built for (-; a CUSUM's reference is half of it)
    /// and the CUSUM's threshold (-, summed over 5 ms steps).
    pub ratio_min_shift: f64,
    pub ratio_cusum_threshold: f64,
    /// The mass range the car is built for, empty to fully loaded (kg): the four quarter
    /// masses' sum outside it (after at least `mass_min_events` braking events) raises the
    /// information event.
    pub vehicle_mass_range_kg: [f64; 2],
    pub mass_min_events: u32,
    /// Braking events classify the road surface from the slip and friction estimates while
    /// the slip is at least this (-): below it every surface's curve is about the same line.
    pub surface_min_slip: f64,
    /// A failed check heals after this long passing (s).
    pub heal_s: f64,
    /// Wheel-speed sensor DTCs per corner (SAE J2012 C0035 / C0040 / C0045 / C0050), without
    /// the failure type byte: each check adds its own (0x31 no signal, 0x1F intermittent, 0x2F
    /// erratic, 0x29 invalid, 0x64 plausibility).
    pub dtc_sensor: [String; CORNERS],
    /// Information events: the road surface class of the last braking event (wet, snow, ice;
    /// dry passes them all) and the mass out of range.
    pub dtc_surface_wet: String,
    pub dtc_surface_snow: String,
    pub dtc_surface_ice: String,
    pub dtc_mass: String,
}

impl Default for WheelMonitorConfig {
    fn default() -> Self {
        let per = |what: &str| CORNER_NAMES.map(|c| format!("wheel_{c}_{what}"));
        Self {
            period_s: 0.005,
            speed_signals: per("speed"),
            current_signals: per("current"),
            brake_signals: per("brake"),
            drive_signal: "wheel_drive_torque".into(),
            current_min_ma: 3.5,
            current_max_ma: 21.0,
            open_debounce_s: 0.09,
            zero_speed_m_s: 0.2,
            air_gap_others_m_s: 0.8,
            air_gap_debounce_s: 0.3,
            air_gap_braked_debounce_s: 1.0,
            air_gap_max_speed_m_s: 5.0,
            spike_sigma: 6.0,
            spike_angle_tol_rad: 0.4,
            spikes_to_fail: 3,
            spike_window_s: 1.0,
            free_torque_nm: 30.0,
            ratio_min_speed_m_s: 5.0,
            ratio_learn_tau_s: 3.0,
            ratio_learn_limit: 0.02,
            ratio_learn_min_s: 10.0,
            ratio_min_shift: 0.015,
            ratio_cusum_threshold: 2.0,
            vehicle_mass_range_kg: [1300.0, 2500.0],
            mass_min_events: 3,
            surface_min_slip: 0.05,
            heal_s: 2.0,
            dtc_sensor: ["C0035", "C0040", "C0045", "C0050"].map(String::from),
            dtc_surface_wet: "C1A01-00".into(),
            dtc_surface_snow: "C1A02-00".into(),
            dtc_surface_ice: "C1A03-00".into(),
            dtc_mass: "C1A10-00".into(),
        }
    }
}

/// The failure type bytes of the sensor checks, in event order per corner.
pub const SENSOR_FTBS: [&str; 5] = ["31", "1F", "2F", "29", "64"];

impl WheelMonitorConfig {
    /// Checks every key, naming it under `at` (`file: [monitor] key`).
    pub fn validate(&self, at: &KeyPath) -> Result<(), ConfigError> {
        const PERIOD: Range = Range::closed(1e-4, 0.1, "s");
        const CURRENT: Range = Range::closed(0.0, 100.0, "mA");
        const TIME: Range = Range::closed(0.0, 3600.0, "s");
        const TIME_POS: Range = Range::above(0.0, 3600.0, "s");
        const SPEED: Range = Range::closed(0.0, 100.0, "m/s");
        const SIGMA: Range = Range::above(0.0, 1e3, "");
        const ANGLE: Range = Range::above(0.0, 3.2, "rad");
        const TORQUE: Range = Range::closed(0.0, 1e4, "N m");
        const FRACTION: Range = Range::above(0.0, 0.5, "");
        const CUSUM: Range = Range::above(0.0, 1e6, "");
        const MASS: Range = Range::above(0.0, 5000.0, "kg");
        const SLIP: Range = Range::above(0.0, 1.0, "");
        at.key("period_s").check(self.period_s, PERIOD)?;
        for (k, v) in [
            ("current_min_ma", self.current_min_ma),
            ("current_max_ma", self.current_max_ma),
        ] {
            at.key(k).check(v, CURRENT)?;
        }
        if self.current_min_ma >= self.current_max_ma {
            return Err(at.key("current_max_ma").invalid(
                crate::config_key::show(self.current_max_ma),
                "must be above current_min_ma",
            ));
        }
        at.key("open_debounce_s")
            .check(self.open_debounce_s, TIME_POS)?;
        for (k, v) in [
            ("zero_speed_m_s", self.zero_speed_m_s),
            ("air_gap_others_m_s", self.air_gap_others_m_s),
            ("air_gap_max_speed_m_s", self.air_gap_max_speed_m_s),
            ("ratio_min_speed_m_s", self.ratio_min_speed_m_s),
        ] {
            at.key(k).check(v, SPEED)?;
        }
        for (k, v) in [
            ("air_gap_debounce_s", self.air_gap_debounce_s),
            ("air_gap_braked_debounce_s", self.air_gap_braked_debounce_s),
            ("spike_window_s", self.spike_window_s),
            ("ratio_learn_tau_s", self.ratio_learn_tau_s),
            ("heal_s", self.heal_s),
        ] {
            at.key(k).check(v, TIME_POS)?;
        }
        at.key("ratio_learn_min_s")
            .check(self.ratio_learn_min_s, TIME)?;
        at.key("spike_sigma").check(self.spike_sigma, SIGMA)?;
        at.key("spike_angle_tol_rad")
            .check(self.spike_angle_tol_rad, ANGLE)?;
        at.key("spikes_to_fail").check(
            f64::from(self.spikes_to_fail),
            Range::closed(2.0, 100.0, ""),
        )?;
        at.key("free_torque_nm")
            .check(self.free_torque_nm, TORQUE)?;
        at.key("ratio_learn_limit")
            .check(self.ratio_learn_limit, FRACTION)?;
        at.key("ratio_min_shift")
            .check(self.ratio_min_shift, FRACTION)?;
        at.key("ratio_cusum_threshold")
            .check(self.ratio_cusum_threshold, CUSUM)?;
        for (i, &m) in self.vehicle_mass_range_kg.iter().enumerate() {
            at.key("vehicle_mass_range_kg").index(i).check(m, MASS)?;
        }
        if self.vehicle_mass_range_kg[0] >= self.vehicle_mass_range_kg[1] {
            return Err(at.key("vehicle_mass_range_kg").invalid(
                format!("{:?}", self.vehicle_mass_range_kg),
                "the lower bound must be below the upper",
            ));
        }
        at.key("mass_min_events")
            .check(f64::from(self.mass_min_events), Range::closed(0.0, 1e6, ""))?;
        at.key("surface_min_slip")
            .check(self.surface_min_slip, SLIP)?;
        let sensor: Vec<(String, String)> = self
            .dtc_sensor
            .iter()
            .enumerate()
            .map(|(i, d)| {
                (
                    format!("dtc_sensor[{i}]"),
                    format!("{d}-{}", SENSOR_FTBS[0]),
                )
            })
            .collect();
        let mut dtcs: Vec<(&str, &str)> = sensor
            .iter()
            .map(|(k, d)| (k.as_str(), d.as_str()))
            .collect();
        dtcs.extend([
            ("dtc_surface_wet", self.dtc_surface_wet.as_str()),
            ("dtc_surface_snow", self.dtc_surface_snow.as_str()),
            ("dtc_surface_ice", self.dtc_surface_ice.as_str()),
            ("dtc_mass", self.dtc_mass.as_str()),
        ]);
        at.check_dtcs(&dtcs)
    }
}

/// The monitor file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct WheelFile {
    /// The quarter car's parameter file, relative to the monitor file (its `[model]` and
    /// `[estimator]` tables are read; the tutorial's `[filter]` is not used by the monitor).
    params: String,
    #[serde(default)]
    monitor: WheelMonitorConfig,
}

/// The tables of the parameter file the monitor uses.
#[derive(Debug, Clone, Deserialize)]
struct ParamsFile {
    model: WheelParams,
    estimator: WheelEstimatorParams,
}

/// The monitor's configuration.
#[derive(Debug, Clone)]
pub struct WheelConfig {
    /// The quarter car's parameters (validated).
    pub params: WheelParams,
    /// fdd's estimator settings (validated).
    pub estimator: WheelEstimatorParams,
    /// Where they came from (for messages).
    pub params_origin: String,
    /// `[monitor]`.
    pub monitor: WheelMonitorConfig,
}

impl WheelConfig {
    /// Parses a monitor file's text and its parameter file's text; `origin` and
    /// `params_origin` name them in errors.
    pub fn parse(
        text: &str,
        origin: &str,
        params_text: &str,
        params_origin: &str,
    ) -> Result<Self, ConfigError> {
        let f: WheelFile = parse_toml(text, origin)?;
        f.monitor.validate(&KeyPath::file(origin).key("monitor"))?;
        let p: ParamsFile = parse_toml(params_text, params_origin)?;
        let root = KeyPath::file(params_origin);
        p.model.validate().map_err(|e| root.key("model").param(e))?;
        p.estimator
            .validate()
            .map_err(|e| root.key("estimator").param(e))?;
        Ok(Self {
            params: p.model,
            estimator: p.estimator,
            params_origin: params_origin.to_string(),
            monitor: f.monitor,
        })
    }

    /// The embedded default (`None`: `config/wheel_monitor.toml` with `config/wheel.toml`) or
    /// a monitor file and the parameter file it names (relative to the monitor file).
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let Some(path) = path else {
            return Self::parse(
                DEFAULT_WHEEL_MONITOR_TOML,
                "embedded config/wheel_monitor.toml",
                DEFAULT_WHEEL_PARAMS_TOML,
                "embedded config/wheel.toml",
            );
        };
        let origin = path.display().to_string();
        let text = crate::text_file::read_text(path).map_err(|e| ConfigError::File(Box::new(e)))?;
        let f: WheelFile = parse_toml(&text, &origin)?;
        let params_path: PathBuf = path
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .join(&f.params);
        let params_text = crate::text_file::read_text(&params_path)
            .map_err(|e| ConfigError::File(Box::new(e)))?;
        Self::parse(
            &text,
            &origin,
            &params_text,
            &params_path.display().to_string(),
        )
    }
}

/// The parameter file the embedded monitor file names (a test checks it is the embedded one).
pub fn embedded_params_name() -> Option<String> {
    toml::from_str::<WheelFile>(DEFAULT_WHEEL_MONITOR_TOML)
        .ok()
        .map(|f| f.params)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_default_loads_and_names_its_parameter_file() {
        let c = WheelConfig::load(None).expect("embedded");
        assert_eq!(embedded_params_name().as_deref(), Some(DEFAULT_PARAMS_NAME));
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/wheel_monitor.toml");
        let d = WheelConfig::load(Some(&path)).expect("from disk");
        assert_eq!(d.monitor, c.monitor);
        assert_eq!(d.params, c.params);
        assert_eq!(d.estimator, c.estimator);
    }

    #[test]
    fn errors_name_the_file_and_key() {
        let at = KeyPath::file("w.toml").key("monitor");
        WheelMonitorConfig::default()
            .validate(&at)
            .expect("defaults");
        let c = WheelMonitorConfig {
            current_min_ma: 30.0,
            current_max_ma: 21.0,
            ..Default::default()
        };
        let e = c.validate(&at).unwrap_err().to_string();
        assert!(e.contains("w.toml") && e.contains("current_max_ma"), "{e}");
        let mut c = WheelMonitorConfig::default();
        c.dtc_sensor[2] = "X99".into();
        let e = c.validate(&at).unwrap_err().to_string();
        assert!(e.contains("dtc_sensor[2]"), "{e}");
        let e = WheelConfig::parse(
            "params = \"p.toml\"\n[monitor]\nspike_sigmaa = 1.0\n",
            "w.toml",
            DEFAULT_WHEEL_PARAMS_TOML,
            "p.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("w.toml") && e.contains("spike_sigmaa"), "{e}");
        let bad: String = DEFAULT_WHEEL_PARAMS_TOML
            .lines()
            .map(|l| {
                if l.starts_with("friction_pull") {
                    "friction_pull = 2.0".to_string()
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        let e = WheelConfig::parse("params = \"p.toml\"\n", "w.toml", &bad, "p.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("p.toml") && e.contains("friction_pull"), "{e}");
    }
}
