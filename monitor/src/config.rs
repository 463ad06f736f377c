//! Loading the throttle and intake configurations: the embedded default or a user file. Every
//! value is checked against its physical range when the file is parsed (the model, the filter
//! tables and the `[monitor]` settings alike), and every error names the file, the table and
//! the key with the value as written ([`crate::config_key`]).

use std::path::Path;

use fdd_estimators::models::throttle::ThrottleParams;
use serde::Deserialize;

use crate::config_key::{parse_toml, show, KeyPath};

/// A configuration that could not be read or is invalid; `origin` names the file.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read {origin}: {source}")]
    Read {
        origin: String,
        source: std::io::Error,
    },
    /// A value refused: `key` is the full key as the user wrote it (`[monitor] period_s`,
    /// `signals[1].max_age_s`; see [`crate::config_key::KeyPath`]), `value` the value in
    /// readable form (`1e300`, `"P0120"`, `(missing)`), `reason` why, with the admissible range
    /// and its unit.
    #[error("{origin}: {key} = {value}: {reason}")]
    Invalid {
        origin: String,
        key: String,
        value: String,
        reason: String,
    },
    /// An error stated as a whole: the text is not TOML (`message` gives the line and column),
    /// or a check that relates several tables.
    #[error("{origin}: {message}")]
    Message { origin: String, message: String },
    /// The file is missing, too large or not text.
    #[error(transparent)]
    File(Box<crate::text_file::TextFileError>),
}

impl ConfigError {
    /// The file the error is about.
    pub fn origin(&self) -> &str {
        match self {
            ConfigError::Read { origin, .. }
            | ConfigError::Invalid { origin, .. }
            | ConfigError::Message { origin, .. } => origin,
            ConfigError::File(e) => match &**e {
                crate::text_file::TextFileError::Io { path, .. }
                | crate::text_file::TextFileError::TooLarge { path, .. }
                | crate::text_file::TextFileError::NotUtf8 { path, .. } => path,
            },
        }
    }

    /// The key refused, if the error is about one value.
    pub fn key(&self) -> Option<&str> {
        match self {
            ConfigError::Invalid { key, .. } => Some(key),
            _ => None,
        }
    }
}

/// The text of the file at `path`, or the embedded default, with the origin to name in errors
/// (`embedded <name>` or the path). Every configuration file of fdd is read through here.
pub(crate) fn read_or_embedded(
    path: Option<&Path>,
    embedded: &'static str,
    name: &str,
) -> Result<(std::borrow::Cow<'static, str>, String), ConfigError> {
    match path {
        None => Ok((embedded.into(), format!("embedded {name}"))),
        Some(p) => {
            let origin = p.display().to_string();
            let text =
                crate::text_file::read_text(p).map_err(|e| ConfigError::File(Box::new(e)))?;
            Ok((text.into(), origin))
        }
    }
}

/// The default intake configuration compiled into the binary.
pub const DEFAULT_INTAKE_TOML: &str = include_str!("../../config/intake.toml");

/// `config/intake.toml`: the intake model's parameters and the intake monitor's settings.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IntakeConfig {
    /// `[model]`: the intake manifold model (validated on load).
    pub model: fdd_estimators::models::intake::IntakeParams,
    /// `[monitor]`: the intake monitor (every key optional).
    #[serde(default)]
    pub monitor: crate::intake::IntakeMonitorConfig,
}

impl IntakeConfig {
    /// Parses and validates a configuration text (the model and the monitor settings, every
    /// key against its range); `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: Self = parse_toml(text, origin)?;
        cfg.validate(&KeyPath::file(origin))?;
        Ok(cfg)
    }

    /// Checks every value; `root` is the file's path (errors name `[model] ...`,
    /// `[monitor] ...`).
    pub fn validate(&self, root: &KeyPath) -> Result<(), ConfigError> {
        let model = root.key("model");
        self.model.validate().map_err(|e| model.param(e))?;
        self.monitor.validate(&root.key("monitor"))
    }

    /// The embedded default (`None`) or a file.
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let (text, origin) = read_or_embedded(path, DEFAULT_INTAKE_TOML, "config/intake.toml")?;
        Self::parse(&text, &origin)
    }
}

/// The default configuration compiled into the binary.
pub const DEFAULT_THROTTLE_TOML: &str = include_str!("../../config/throttle.toml");

/// `[position_sensor]`: linear 0..full_scale_deg -> 0..full_scale_v.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PositionSensorConfig {
    pub full_scale_v: f64,
    pub full_scale_deg: f64,
}

/// `[truth]`: process noise of the table2 truth simulation.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthConfig {
    pub process_noise_scale: f64,
    #[serde(deserialize_with = "fdd_estimators::param::exact_array")]
    pub process_noise_f_diag: [f64; 3],
}

/// `[wattmeter_ukf]`: settings of the wattmeter-only UKFs.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WattmeterUkfConfig {
    pub ahsm_lambda: f64,
    pub arm_w0: f64,
    #[serde(deserialize_with = "fdd_estimators::param::exact_array")]
    pub agm_v: [f64; 3],
    #[serde(deserialize_with = "fdd_estimators::param::exact_array")]
    pub p0_diag: [f64; 3],
    #[serde(deserialize_with = "fdd_estimators::param::exact_array")]
    pub q_diag: [f64; 3],
    pub r_floor: f64,
    pub reacquire_window: f64,
    pub reacquire_threshold: f64,
    pub reacquire_holdoff: u32,
    pub reseed_input_tau_s: f64,
}

/// Admissible ranges of the throttle file's `[position_sensor]`, `[truth]` and
/// `[wattmeter_ukf]` keys (the `[model]` keys: `fdd_estimators::models::throttle::ranges`; the
/// `[monitor]` keys: [`crate::throttle::ThrottleMonitorConfig::validate`]).
pub mod ranges {
    use crate::config_key::Range;

    /// `full_scale_v`: the position sensor's output at `full_scale_deg`.
    pub const FULL_SCALE_V: Range = Range::above(0.0, 100.0, "V");
    /// `full_scale_deg`.
    pub const FULL_SCALE_DEG: Range = Range::above(0.0, 360.0, "deg");
    /// `process_noise_scale` and the entries of `process_noise_f_diag` (0: no noise).
    pub const NOISE_SCALE: Range = Range::closed(0.0, 1e3, "");
    /// `ahsm_lambda`: the AHSM set needs n + lambda > 0 (n = 3 states).
    pub const AHSM_LAMBDA: Range = Range::above(-3.0, 1e3, "");
    /// `arm_w0`: the ARM centre weight.
    pub const ARM_W0: Range = Range::open(0.0, 1.0, "");
    /// Magnitude of each `agm_v` entry (the sign does not matter: entries enter squared).
    pub const AGM_V_ABS: Range = Range::above(0.0, 1e3, "");
    /// `p0_diag` entries: the initial covariance must be positive definite.
    pub const P0_DIAG: Range = Range::above(0.0, 1e6, "");
    /// `q_diag` entries: process noise may vanish in a state.
    pub const Q_DIAG: Range = Range::closed(0.0, 1e6, "");
    /// `r_floor` (A^4).
    pub const R_FLOOR: Range = Range::closed(0.0, 1e6, "A^4");
    /// `reacquire_window` (updates).
    pub const REACQUIRE_WINDOW: Range = Range::above(1.0, 1e6, "updates");
    /// `reacquire_threshold`: mean NIS per degree of freedom (1 is consistent).
    pub const REACQUIRE_THRESHOLD: Range = Range::above(1.0, 1e6, "");
    /// `reseed_input_tau_s`.
    pub const RESEED_TAU_S: Range = Range::closed(1e-4, 3600.0, "s");
}

/// The whole throttle file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThrottleConfig {
    pub model: ThrottleParams,
    pub position_sensor: PositionSensorConfig,
    pub truth: TruthConfig,
    pub wattmeter_ukf: WattmeterUkfConfig,
    /// `[monitor]`: the throttle monitor; every key has a default.
    #[serde(default)]
    pub monitor: crate::throttle::ThrottleMonitorConfig,
}

impl ThrottleConfig {
    /// Parses and validates a TOML text (every key against its range, the `[monitor]`
    /// settings included); `origin` names the source in error messages.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: ThrottleConfig = parse_toml(text, origin)?;
        cfg.validate(&KeyPath::file(origin))?;
        Ok(cfg)
    }

    /// Checks every value; `root` is the file's path (errors name `[model] ...`,
    /// `[wattmeter_ukf] ...`, `[monitor] ...`).
    pub fn validate(&self, root: &KeyPath) -> Result<(), ConfigError> {
        let model = root.key("model");
        self.model.validate().map_err(|e| model.param(e))?;
        let ps = root.key("position_sensor");
        ps.key("full_scale_v")
            .check(self.position_sensor.full_scale_v, ranges::FULL_SCALE_V)?;
        ps.key("full_scale_deg")
            .check(self.position_sensor.full_scale_deg, ranges::FULL_SCALE_DEG)?;
        let t = root.key("truth");
        t.key("process_noise_scale")
            .check(self.truth.process_noise_scale, ranges::NOISE_SCALE)?;
        for (i, v) in self.truth.process_noise_f_diag.iter().enumerate() {
            t.key("process_noise_f_diag")
                .index(i)
                .check(*v, ranges::NOISE_SCALE)?;
        }
        let w = &self.wattmeter_ukf;
        let u = root.key("wattmeter_ukf");
        u.key("ahsm_lambda")
            .check(w.ahsm_lambda, ranges::AHSM_LAMBDA)?;
        u.key("arm_w0").check(w.arm_w0, ranges::ARM_W0)?;
        for (i, v) in w.agm_v.iter().enumerate() {
            let at = u.key("agm_v").index(i);
            if !ranges::AGM_V_ABS.contains(v.abs()) {
                return Err(at.invalid(
                    show(*v),
                    "must be non-zero, with a magnitude of at most 1000",
                ));
            }
        }
        for (i, v) in w.p0_diag.iter().enumerate() {
            u.key("p0_diag").index(i).check(*v, ranges::P0_DIAG)?;
        }
        for (i, v) in w.q_diag.iter().enumerate() {
            u.key("q_diag").index(i).check(*v, ranges::Q_DIAG)?;
        }
        u.key("r_floor").check(w.r_floor, ranges::R_FLOOR)?;
        u.key("reacquire_window")
            .check(w.reacquire_window, ranges::REACQUIRE_WINDOW)?;
        u.key("reacquire_threshold")
            .check(w.reacquire_threshold, ranges::REACQUIRE_THRESHOLD)?;
        u.key("reacquire_holdoff")
            .check_count(w.reacquire_holdoff, 0, 1_000_000, "updates")?;
        u.key("reseed_input_tau_s")
            .check(w.reseed_input_tau_s, ranges::RESEED_TAU_S)?;
        self.monitor.validate(&root.key("monitor"))
    }

    /// The embedded default, or the file at `path`.
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let (text, origin) = read_or_embedded(path, DEFAULT_THROTTLE_TOML, "config/throttle.toml")?;
        Self::parse(&text, &origin)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_file_the_table_and_the_key() {
        let cases = [
            // Was reported as parameter `lambda`.
            (
                DEFAULT_THROTTLE_TOML.replace("ahsm_lambda = 12.0", "ahsm_lambda = -3.0"),
                "t.toml: [wattmeter_ukf] ahsm_lambda = -3.0: must be above -3 and at most 1000",
            ),
            // Did not say which coefficient.
            (
                DEFAULT_THROTTLE_TOML.replace("c2 = 0.0615", "c2 = nan"),
                "t.toml: [model] modes[2].c2 = NaN: must be between -1000 and 1000",
            ),
            // Extra entries were dropped silently.
            (
                DEFAULT_THROTTLE_TOML.replace("p0_diag = [1.0, 1.0, 1.0]", "p0_diag = [1.0, 1.0, 1.0, 1.0]"),
                "t.toml: [wattmeter_ukf] p0_diag = [1.0, 1.0, 1.0, 1.0]: invalid length 4, expected an array of exactly 3 values",
            ),
            (
                format!("{DEFAULT_THROTTLE_TOML}\n[monitor]\nperiod_s = 1e300\n"),
                "t.toml: [monitor] period_s = 1e300: must be between 1e-4 and 1 s",
            ),
        ];
        for (text, want) in cases {
            let e = ThrottleConfig::parse(&text, "t.toml")
                .unwrap_err()
                .to_string();
            assert_eq!(e, want);
        }
        let text = DEFAULT_INTAKE_TOML.replace("min_speed_rpm = 300.0", "min_speed_rpm = 1e-9");
        let e = IntakeConfig::parse(&text, "i.toml")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "i.toml: [model] min_speed_rpm = 1e-9: must be between 50 and 20000 rpm"
        );
        ThrottleConfig::load(None).expect("embedded throttle");
        IntakeConfig::load(None).expect("embedded intake");
    }
}
