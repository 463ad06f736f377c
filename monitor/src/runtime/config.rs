//! The runtime configuration (`config/fdd.toml`): the signals (and where logs carry them),
//! the "no signal" monitor, the monitors to run, the freeze frames their DTCs store, and the
//! settings of log replays (ground-truth topics, gaps). The file is embedded as the default;
//! a host or `--config F` replaces it as a whole. Unknown keys are errors, and every error
//! names the file and the key.
//!
//! The `[[signals]]` topics and fields, `[[truth]]` and `[replay]` only matter when a log is
//! replayed: a host that pushes samples itself addresses signals by name.

use std::path::Path;

use crate::signal_table::{SignalSpec, SignalTable};
use fdd_diagnostics::dtc::{
    DebounceConfig, EventConfig, EventMemoryConfig, FreezeFrameUpdate, MilConfig,
};
use serde::Deserialize;

use crate::config::ConfigError;

/// The default runtime configuration compiled into the binary.
pub const DEFAULT_RUNTIME_TOML: &str = include_str!("../../../config/fdd.toml");

/// Where the embedded default says it comes from in messages.
pub const EMBEDDED_ORIGIN: &str = "embedded config/fdd.toml";

/// `[[signals]]`: one runtime signal and where logs carry it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SignalConfig {
    /// Runtime name, as monitors ask for it (`tps`).
    pub name: String,
    /// Log topic (`/throttle/tps`).
    pub topic: String,
    /// Numeric JSON field of the topic's messages (`voltage_v`, or `outer.inner`).
    pub field: String,
    /// Age after which the latest sample is stale, s (> 0).
    pub max_age_s: f64,
    /// DTC of the signal's "no signal" event (`P0120-31`).
    pub stale_dtc: String,
}

const fn default_check_period_s() -> f64 {
    0.001
}
const fn default_priority() -> u8 {
    2
}

/// `[staleness]`: the staleness monitor.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StalenessConfig {
    /// Period of the staleness check, s (> 0).
    #[serde(default = "default_check_period_s")]
    pub check_period_s: f64,
    /// Event memory priority of the "no signal" events (1 highest .. 255).
    #[serde(default = "default_priority")]
    pub priority: u8,
    /// Debounce of the "no signal" events (default monitor-internal).
    #[serde(default = "default_debounce")]
    pub debounce: DebounceConfig,
}

fn default_debounce() -> DebounceConfig {
    DebounceConfig::MonitorInternal
}

impl Default for StalenessConfig {
    fn default() -> Self {
        StalenessConfig {
            check_period_s: default_check_period_s(),
            priority: default_priority(),
            debounce: default_debounce(),
        }
    }
}

/// One `[[truth]]` entry: a ground-truth topic of simulated logs. Its messages carry the
/// injected fault (`fault`, `fault_active`) and the true value of one quantity (`field`), which
/// the summary compares with the monitor estimate named `estimate`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthConfig {
    /// Topic of the truth messages (`/truth/throttle`).
    pub topic: String,
    /// Field holding the true value (`angle_deg`).
    pub field: String,
    /// Name of the monitor estimate compared with it (`throttle_angle`).
    pub estimate: String,
}

/// The default truth topics: the throttle's and the intake manifold's.
pub fn default_truths() -> Vec<TruthConfig> {
    vec![
        TruthConfig {
            topic: "/truth/throttle".into(),
            field: "angle_deg".into(),
            estimate: "throttle_angle".into(),
        },
        TruthConfig {
            topic: "/truth/intake".into(),
            field: "p_m_pa".into(),
            estimate: "manifold_pressure".into(),
        },
    ]
}

const fn default_max_gap_s() -> f64 {
    10.0
}

/// `[replay]`: replay settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayConfig {
    /// A forward jump of the log time larger than this ends the operation cycle, s (> 0).
    #[serde(default = "default_max_gap_s")]
    pub max_gap_s: f64,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        ReplayConfig {
            max_gap_s: default_max_gap_s(),
        }
    }
}

/// `[monitors]`: which monitors run (the staleness monitor always does).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct MonitorsConfig {
    /// The electronic-throttle monitor.
    #[serde(default)]
    pub throttle: bool,
    /// Throttle model and monitor settings (a `config/throttle.toml`-shaped file; a relative
    /// path is relative to the directory of the configuration file naming it); absent: the
    /// embedded default.
    #[serde(default)]
    pub throttle_config: Option<std::path::PathBuf>,
    /// The intake-manifold monitor.
    #[serde(default)]
    pub intake: bool,
    /// Intake model and monitor settings (a `config/intake.toml`-shaped file; relative paths as
    /// for `throttle_config`); absent: the embedded default.
    #[serde(default)]
    pub intake_config: Option<std::path::PathBuf>,
}

impl MonitorsConfig {
    /// Names of the enabled monitors.
    pub fn enabled(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        if self.throttle {
            v.push("throttle");
        }
        if self.intake {
            v.push("intake");
        }
        v
    }
}

/// `[freeze_frames]`: what each DTC stores at its first qualified failure. Items are names of
/// runtime signals (their latest value) or of estimates the monitor declares (the throttle
/// monitor's `throttle_angle`; the intake monitor's `manifold_pressure`, `intake_valve_flow`).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct FreezeFramesConfig {
    /// Per monitor (`staleness`, `throttle`, `intake`): the items of every event of that
    /// monitor. Absent: the monitor's default (its own signals and estimates; every watched
    /// signal for the "no signal" events).
    #[serde(default)]
    pub monitors: std::collections::BTreeMap<String, Vec<String>>,
    /// Per event name (`tps_circuit_low`, `map_no_signal`): overrides its monitor's list.
    #[serde(default)]
    pub events: std::collections::BTreeMap<String, Vec<String>>,
}

/// Which operation cycles age a DTC (count towards erasing a healed entry).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AgingCycle {
    /// Every operation cycle that completed the test without failure (the default).
    #[default]
    OperationCycle,
    /// Only cycles in which the host reported a warm-up ([`crate::runtime::Runtime::warm_up_completed`]),
    /// as OBD ages over warm-up cycles.
    WarmUpCycle,
}

/// `[operation_cycles]`: how the host's cycles count.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OperationCyclesConfig {
    /// `aging = "operation_cycle"` (default) or `"warm_up_cycle"`.
    #[serde(default)]
    pub aging: AgingCycle,
}

/// The whole runtime configuration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RuntimeConfig {
    /// The signals, in table order.
    pub signals: Vec<SignalConfig>,
    #[serde(default)]
    pub staleness: StalenessConfig,
    /// `[freeze_frames]`; absent: each monitor's defaults.
    #[serde(default)]
    pub freeze_frames: FreezeFramesConfig,
    /// `[operation_cycles]`; absent: every operation cycle is an aging cycle.
    #[serde(default)]
    pub operation_cycles: OperationCyclesConfig,
    /// `[[truth]]` tables; absent: [`default_truths`].
    #[serde(default = "default_truths")]
    pub truth: Vec<TruthConfig>,
    #[serde(default)]
    pub replay: ReplayConfig,
    #[serde(default)]
    pub monitors: MonitorsConfig,
    /// Where the configuration came from (a path, or [`EMBEDDED_ORIGIN`]).
    #[serde(skip)]
    pub origin: String,
}

fn invalid(origin: &str, key: &str, value: impl std::fmt::Display, reason: &str) -> ConfigError {
    ConfigError::Invalid {
        origin: origin.to_string(),
        message: format!("invalid `{key}` = {value}: {reason}"),
    }
}

/// Seconds to nanoseconds, rounded, at least 1.
pub fn s_to_ns(s: f64) -> u64 {
    ((s * 1e9).round() as u64).max(1)
}

impl RuntimeConfig {
    /// Parses and validates a TOML text; `origin` names the source in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let mut cfg: RuntimeConfig = toml::from_str(text).map_err(|e| ConfigError::Invalid {
            origin: origin.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        cfg.origin = origin.to_string();
        cfg.validate()?;
        Ok(cfg)
    }

    /// The embedded default, or the file at `path`.
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let (text, origin) =
            crate::config::read_or_embedded(path, DEFAULT_RUNTIME_TOML, "config/fdd.toml")?;
        let mut cfg = Self::parse(&text, &origin)?;
        // A monitor settings file named relative to a configuration file is beside it (so a
        // directory written by `fdd calibrate` works from anywhere).
        if let Some(dir) = path.and_then(Path::parent) {
            for p in [
                &mut cfg.monitors.throttle_config,
                &mut cfg.monitors.intake_config,
            ]
            .into_iter()
            .flatten()
            {
                if p.is_relative() {
                    *p = dir.join(&*p);
                }
            }
        }
        tracing::info!(
            config = %cfg.origin,
            signals = cfg.signals.len(),
            "runtime configuration loaded from {}",
            cfg.origin
        );
        Ok(cfg)
    }

    /// Checks every value; errors name the key (`signals[1].max_age_s`).
    pub fn validate(&self) -> Result<(), ConfigError> {
        let o = &self.origin;
        if self.signals.is_empty() {
            return Err(invalid(o, "signals", "[]", "at least one signal is needed"));
        }
        for (i, s) in self.signals.iter().enumerate() {
            let key = |k: &str| format!("signals[{i}].{k}");
            for (k, v) in [("name", &s.name), ("topic", &s.topic), ("field", &s.field)] {
                if v.trim().is_empty() {
                    return Err(invalid(o, &key(k), format!("{v:?}"), "must not be empty"));
                }
            }
            if let Some(j) = self.signals[..i].iter().position(|t| t.name == s.name) {
                return Err(invalid(
                    o,
                    &key("name"),
                    format!("{:?}", s.name),
                    &format!("already used by signals[{j}]"),
                ));
            }
            if let Some(j) = self.signals[..i]
                .iter()
                .position(|t| t.topic == s.topic && t.field == s.field)
            {
                return Err(invalid(
                    o,
                    &key("field"),
                    format!("{:?}", s.field),
                    &format!("topic and field already mapped by signals[{j}]"),
                ));
            }
            if !(s.max_age_s > 0.0 && s.max_age_s.is_finite()) {
                return Err(invalid(
                    o,
                    &key("max_age_s"),
                    s.max_age_s,
                    "must be a positive finite number of seconds",
                ));
            }
        }
        let st = &self.staleness;
        if !(st.check_period_s > 0.0 && st.check_period_s.is_finite()) {
            return Err(invalid(
                o,
                "staleness.check_period_s",
                st.check_period_s,
                "must be a positive finite number of seconds",
            ));
        }
        // The event memory validates DTCs, priority and debounce; rename its keys to ours.
        self.staleness_memory_config().validate().map_err(|e| {
            let key = rename_event_key(&e.field);
            invalid(o, &key, &e.value, &e.reason)
        })?;
        for (i, t) in self.truth.iter().enumerate() {
            for (key, v) in [
                ("topic", &t.topic),
                ("field", &t.field),
                ("estimate", &t.estimate),
            ] {
                if v.trim().is_empty() {
                    return Err(invalid(
                        o,
                        &format!("truth[{i}].{key}"),
                        "\"\"",
                        "must not be empty",
                    ));
                }
            }
            if self.truth[..i].iter().any(|u| u.topic == t.topic) {
                return Err(invalid(
                    o,
                    &format!("truth[{i}].topic"),
                    &t.topic,
                    "is already a truth topic",
                ));
            }
        }
        let g = self.replay.max_gap_s;
        if !(g > 0.0 && g.is_finite()) {
            return Err(invalid(
                o,
                "replay.max_gap_s",
                g,
                "must be a positive finite number of seconds",
            ));
        }
        Ok(())
    }

    /// The signal table's declarations, in `signals` order (a signal's index in `signals` is
    /// its [`crate::signal_table::SignalId`] index).
    pub fn signal_specs(&self) -> Vec<SignalSpec> {
        self.signals
            .iter()
            .map(|s| SignalSpec {
                name: s.name.clone(),
                max_age_ns: s_to_ns(s.max_age_s),
            })
            .collect()
    }

    /// The embedded default configuration.
    pub fn embedded() -> Result<Self, ConfigError> {
        Self::parse(DEFAULT_RUNTIME_TOML, EMBEDDED_ORIGIN)
    }

    /// An empty signal table of the configured signals.
    pub fn signal_table(&self) -> Result<SignalTable, ConfigError> {
        SignalTable::new(self.signal_specs()).map_err(|e| ConfigError::Invalid {
            origin: self.origin.clone(),
            message: e.to_string(),
        })
    }

    /// The staleness monitor's event memory: one event `<signal>_no_signal` per signal, in
    /// `signals` order.
    pub fn staleness_memory_config(&self) -> EventMemoryConfig {
        EventMemoryConfig {
            capacity: self.signals.len().max(1),
            events: self
                .signals
                .iter()
                .map(|s| EventConfig {
                    debounce: self.staleness.debounce,
                    mil: MilConfig::default(),
                    freeze_frame: Vec::new(),
                    freeze_frame_update: FreezeFrameUpdate::First,
                    ..EventConfig::new(
                        stale_event_name(&s.name),
                        s.stale_dtc.clone(),
                        self.staleness.priority,
                    )
                })
                .collect(),
        }
    }
}

/// The name of a signal's "no signal" event.
pub fn stale_event_name(signal: &str) -> String {
    format!("{signal}_no_signal")
}

/// `events[i].dtc` -> `signals[i].stale_dtc`, `events[i].priority` -> `staleness.priority`,
/// `events[i].debounce.x` -> `staleness.debounce.x`.
fn rename_event_key(field: &str) -> String {
    let Some(rest) = field.strip_prefix("events[") else {
        return field.to_string();
    };
    let Some((index, key)) = rest.split_once("].") else {
        return field.to_string();
    };
    if key == "dtc" {
        format!("signals[{index}].stale_dtc")
    } else if key == "name" {
        format!("signals[{index}].name")
    } else {
        format!("staleness.{key}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_default_is_valid() {
        let cfg = RuntimeConfig::load(None).expect("embedded config");
        let names: Vec<_> = cfg.signals.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "motor_voltage",
                "tps",
                "wattmeter",
                "engine_speed",
                "intake_throttle",
                "egr_command",
                "map",
                "maf"
            ]
        );
        assert_eq!(cfg.staleness.debounce, DebounceConfig::MonitorInternal);
        assert!(cfg.monitors.throttle);
        assert!(cfg.monitors.intake);
        assert_eq!(cfg.signal_specs()[1].max_age_ns, 5_000_000);
        assert_eq!(cfg.signal_specs()[6].max_age_ns, 250_000_000);
        assert_eq!(cfg.truth, default_truths());
        let mem = cfg.staleness_memory_config();
        assert_eq!(mem.events[1].name, "tps_no_signal");
        assert_eq!(mem.validate().expect("valid").len(), 8);
    }

    #[test]
    fn errors_name_the_key() {
        let text = DEFAULT_RUNTIME_TOML.replace("max_age_s = 0.005", "max_age_sec = 0.005");
        let e = RuntimeConfig::parse(&text, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.toml: "), "{e}");
        assert!(e.contains("max_age_sec"), "{e}");

        let text = DEFAULT_RUNTIME_TOML.replace("\"P0120-31\"", "\"X0120-31\"");
        let e = RuntimeConfig::parse(&text, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("signals[1].stale_dtc"), "{e}");

        let text = DEFAULT_RUNTIME_TOML.replace("\"P0120-31\"", "\"P2100-31\"");
        let e = RuntimeConfig::parse(&text, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("signals[1].stale_dtc"), "{e}");

        let text = DEFAULT_RUNTIME_TOML.replacen("max_age_s = 0.005", "max_age_s = -1.0", 1);
        let e = RuntimeConfig::parse(&text, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("signals[0].max_age_s"), "{e}");

        let text = DEFAULT_RUNTIME_TOML.replace("priority = 2", "priority = 0");
        let e = RuntimeConfig::parse(&text, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("staleness.priority"), "{e}");

        let text = DEFAULT_RUNTIME_TOML.replace("name = \"tps\"", "name = \"motor_voltage\"");
        let e = RuntimeConfig::parse(&text, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("signals[1].name"), "{e}");
    }
}
