//! Loading the throttle configuration: the embedded default or a user file, with errors that
//! name the file and the key.

use std::path::Path;

use fdd_estimators::models::throttle::ThrottleParams;
use serde::Deserialize;

/// A configuration that could not be read or is invalid; `origin` names the file.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read {origin}: {source}")]
    Read {
        origin: String,
        source: std::io::Error,
    },
    #[error("{origin}: {message}")]
    Invalid { origin: String, message: String },
    /// The file is missing, too large or not text.
    #[error(transparent)]
    File(Box<crate::text_file::TextFileError>),
}

fn invalid(origin: &str, message: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        origin: origin.to_string(),
        message: message.into(),
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
            let text = crate::text_file::read_text(p).map_err(|e| ConfigError::File(Box::new(e)))?;
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
    /// Parses and validates a configuration text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: Self = toml::from_str(text).map_err(|e| invalid(origin, e.to_string()))?;
        cfg.model
            .validate()
            .map_err(|m| invalid(origin, format!("[model] {m}")))?;
        Ok(cfg)
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
    pub process_noise_f_diag: [f64; 3],
}

/// `[wattmeter_ukf]`: settings of the wattmeter-only UKFs.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WattmeterUkfConfig {
    pub ahsm_lambda: f64,
    pub arm_w0: f64,
    pub agm_v: [f64; 3],
    pub p0_diag: [f64; 3],
    pub q_diag: [f64; 3],
    pub r_floor: f64,
    pub reacquire_window: f64,
    pub reacquire_threshold: f64,
    pub reacquire_holdoff: u32,
    pub reseed_input_tau_s: f64,
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
    /// Parses and validates a TOML text; `origin` names the source in error messages.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: ThrottleConfig =
            toml::from_str(text).map_err(|e| invalid(origin, e.to_string()))?;
        cfg.model
            .validate()
            .map_err(|e| invalid(origin, format!("[model] {e}")))?;
        let ps = cfg.position_sensor;
        if !(ps.full_scale_v > 0.0 && ps.full_scale_deg > 0.0) {
            return Err(invalid(
                origin,
                "[position_sensor] full_scale_v and full_scale_deg must be positive",
            ));
        }
        let t = cfg.truth;
        if !(t.process_noise_scale >= 0.0) || t.process_noise_f_diag.iter().any(|v| !(*v >= 0.0)) {
            return Err(invalid(
                origin,
                "[truth] process_noise_scale and process_noise_f_diag must be finite and non-negative",
            ));
        }
        let w = cfg.wattmeter_ukf;
        let nonneg = w.q_diag.iter().chain(&w.p0_diag).all(|v| *v >= 0.0) && w.r_floor >= 0.0;
        if !(w.reseed_input_tau_s > 0.0) {
            return Err(invalid(
                origin,
                "[wattmeter_ukf] reseed_input_tau_s must be positive",
            ));
        }
        if !nonneg {
            return Err(invalid(
                origin,
                "[wattmeter_ukf] q_diag, p0_diag and r_floor must be non-negative",
            ));
        }
        Ok(cfg)
    }

    /// The embedded default, or the file at `path`.
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let (text, origin) = read_or_embedded(path, DEFAULT_THROTTLE_TOML, "config/throttle.toml")?;
        Self::parse(&text, &origin)
    }
}
