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
use crate::config_key::{parse_toml, KeyPath};

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

/// The default truth topics: the throttle's, the intake manifold's and the air path's.
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
        TruthConfig {
            topic: "/truth/turbo".into(),
            field: "w_ei_kg_s".into(),
            estimate: "cylinder_flow".into(),
        },
        TruthConfig {
            topic: "/truth/wheel".into(),
            field: "value".into(),
            estimate: "vehicle_reference_speed".into(),
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
    /// `[replay.limits]`: the log reader's budget for one file; a key left out keeps the
    /// reader's default.
    #[serde(default)]
    pub limits: ReadLimits,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        ReplayConfig {
            max_gap_s: default_max_gap_s(),
            limits: ReadLimits::default(),
        }
    }
}

/// `[replay.limits]`: what one log may cost the reader, by the names of the
/// [`ReadOptions`](crate::log::ReadOptions) fields they set (see there for units and defaults).
/// A trusted file beyond a default is read by raising the key its error names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadLimits {
    /// Largest record or decompressed chunk held in memory, bytes.
    pub max_record_bytes: Option<u64>,
    /// Chunk indexes in the summary.
    pub max_chunk_indexes: Option<u64>,
    /// Distinct channel ids.
    pub max_channels: Option<u64>,
    /// Distinct schema ids.
    pub max_schemas: Option<u64>,
    /// One message's payload, bytes.
    pub max_message_bytes: Option<u64>,
    /// The summary section, bytes.
    pub max_summary_bytes: Option<u64>,
    /// Bytes decompressed in all, as a multiple of the file size.
    pub max_decompression_ratio: Option<u64>,
    /// Bytes decompressed in all, at least (for small files), bytes.
    pub decompressed_bytes_floor: Option<u64>,
}

impl ReadLimits {
    /// The keys with their values, in file order.
    fn entries(&self) -> [(&'static str, Option<u64>); 8] {
        [
            ("max_record_bytes", self.max_record_bytes),
            ("max_chunk_indexes", self.max_chunk_indexes),
            ("max_channels", self.max_channels),
            ("max_schemas", self.max_schemas),
            ("max_message_bytes", self.max_message_bytes),
            ("max_summary_bytes", self.max_summary_bytes),
            ("max_decompression_ratio", self.max_decompression_ratio),
            ("decompressed_bytes_floor", self.decompressed_bytes_floor),
        ]
    }

    /// The reader's options: its defaults with the keys given here replaced.
    pub fn read_options(&self) -> crate::log::ReadOptions {
        let d = crate::log::ReadOptions::default();
        crate::log::ReadOptions {
            max_record_bytes: self.max_record_bytes.unwrap_or(d.max_record_bytes),
            max_chunk_indexes: self.max_chunk_indexes.unwrap_or(d.max_chunk_indexes),
            max_channels: self.max_channels.unwrap_or(d.max_channels),
            max_schemas: self.max_schemas.unwrap_or(d.max_schemas),
            max_message_bytes: self.max_message_bytes.unwrap_or(d.max_message_bytes),
            max_summary_bytes: self.max_summary_bytes.unwrap_or(d.max_summary_bytes),
            max_decompression_ratio: self
                .max_decompression_ratio
                .unwrap_or(d.max_decompression_ratio),
            decompressed_bytes_floor: self
                .decompressed_bytes_floor
                .unwrap_or(d.decompressed_bytes_floor),
            ..d
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
    /// The turbocharged air-path monitor.
    #[serde(default)]
    pub turbo: bool,
    /// Air-path monitor settings (a `config/turbo_monitor.toml`-shaped file naming its model
    /// parameter file; relative paths as for `throttle_config`); absent: the embedded default
    /// (the LiU-ICE engine's parameters).
    #[serde(default)]
    pub turbo_config: Option<std::path::PathBuf>,
    /// The wheel monitor (four quarter-car filters and the wheel-speed sensor checks).
    #[serde(default)]
    pub wheel: bool,
    /// Wheel monitor settings (a `config/wheel_monitor.toml`-shaped file naming its parameter
    /// file; relative paths as for `throttle_config`); absent: the embedded default.
    #[serde(default)]
    pub wheel_config: Option<std::path::PathBuf>,
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
        if self.turbo {
            v.push("turbo");
        }
        if self.wheel {
            v.push("wheel");
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

/// Admissible ranges of the runtime configuration's values.
pub mod ranges {
    use crate::config_key::Range;

    /// `signals[i].max_age_s`: from 100 us (a tenth of a 1 kHz sample period) to an hour.
    pub const MAX_AGE_S: Range = Range::closed(1e-4, 3600.0, "s");
    /// `[staleness] check_period_s`: from 10 us (a replay of a minute is then 6e6 checks; a
    /// period of a nanosecond made a replay run forever) to 10 s.
    pub const CHECK_PERIOD_S: Range = Range::closed(1e-5, 10.0, "s");
    /// `[replay] max_gap_s`: above the slowest sample spacing (an intake segment at cranking
    /// speed, 0.1 s) and at most a day.
    pub const MAX_GAP_S: Range = Range::closed(0.1, 86_400.0, "s");
    /// Debounce times of `[staleness] debounce` (time-based).
    pub const DEBOUNCE_TIME_S: Range = Range::closed(0.0, 3600.0, "s");
}

/// Seconds to nanoseconds, rounded, at least 1.
pub fn s_to_ns(s: f64) -> u64 {
    ((s * 1e9).round() as u64).max(1)
}

impl RuntimeConfig {
    /// Parses and validates a TOML text; `origin` names the source in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let mut cfg: RuntimeConfig = parse_toml(text, origin)?;
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
                &mut cfg.monitors.turbo_config,
                &mut cfg.monitors.wheel_config,
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

    /// Checks every value against its range ([`ranges`]); errors name the file and the key
    /// (`signals[1].max_age_s`, `[staleness] check_period_s`).
    pub fn validate(&self) -> Result<(), ConfigError> {
        let root = KeyPath::file(&self.origin);
        let signals = root.key("signals");
        if self.signals.is_empty() {
            return Err(signals.invalid("[]", "at least one signal is needed"));
        }
        for (i, s) in self.signals.iter().enumerate() {
            let at = signals.index(i);
            at.key("name").check_name(&s.name)?;
            at.key("topic").check_name(&s.topic)?;
            at.key("field").check_name(&s.field)?;
            if let Some(j) = self.signals[..i].iter().position(|t| t.name == s.name) {
                return Err(at.key("name").invalid(
                    format!("{:?}", s.name),
                    format!("already used by signals[{j}]"),
                ));
            }
            if let Some(j) = self.signals[..i]
                .iter()
                .position(|t| t.topic == s.topic && t.field == s.field)
            {
                return Err(at.key("field").invalid(
                    format!("{:?}", s.field),
                    format!("topic and field already mapped by signals[{j}]"),
                ));
            }
            at.key("max_age_s").check(s.max_age_s, ranges::MAX_AGE_S)?;
        }
        let st = root.key("staleness");
        st.key("check_period_s")
            .check(self.staleness.check_period_s, ranges::CHECK_PERIOD_S)?;
        if let DebounceConfig::Time(t) = &self.staleness.debounce {
            let d = st.key("debounce");
            d.key("failed_time_s")
                .check(t.failed_time_s, ranges::DEBOUNCE_TIME_S)?;
            d.key("passed_time_s")
                .check(t.passed_time_s, ranges::DEBOUNCE_TIME_S)?;
        }
        // The event memory validates DTCs, priority and debounce; rename its keys to ours.
        self.staleness_memory_config()
            .validate()
            .map_err(|e| rename_event_key(&root, &e.field).invalid(&e.value, e.reason))?;
        for (i, t) in self.truth.iter().enumerate() {
            let at = root.key("truth").index(i);
            at.key("topic").check_name(&t.topic)?;
            at.key("field").check_name(&t.field)?;
            at.key("estimate").check_name(&t.estimate)?;
            if let Some(j) = self.truth[..i].iter().position(|u| u.topic == t.topic) {
                return Err(at.key("topic").invalid(
                    format!("{:?}", t.topic),
                    format!("is already the topic of truth[{j}]"),
                ));
            }
        }
        root.key("replay")
            .key("max_gap_s")
            .check(self.replay.max_gap_s, ranges::MAX_GAP_S)?;
        // A limit of 0 would refuse every file; the largest is whatever a u64 holds (a host
        // that trusts its files may lift a limit altogether).
        for (key, v) in self.replay.limits.entries() {
            if let Some(v) = v {
                root.key("replay")
                    .key("limits")
                    .key(key)
                    .check_count(v, 1, u64::MAX, "")?;
            }
        }
        for (key, path) in [
            ("throttle_config", &self.monitors.throttle_config),
            ("intake_config", &self.monitors.intake_config),
            ("turbo_config", &self.monitors.turbo_config),
            ("wheel_config", &self.monitors.wheel_config),
        ] {
            if path.as_ref().is_some_and(|p| p.as_os_str().is_empty()) {
                return Err(root
                    .key("monitors")
                    .key(key)
                    .invalid("\"\"", "must name a file"));
            }
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
        SignalTable::new(self.signal_specs()).map_err(|e| ConfigError::Message {
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

/// The key of the event memory's `events[i].<key>` in this file: `events[i].dtc` ->
/// `signals[i].stale_dtc`, `events[i].name` -> `signals[i].name`, `events[i].priority` ->
/// `[staleness] priority`, `events[i].debounce.x` -> `[staleness] debounce.x`.
fn rename_event_key(root: &KeyPath, field: &str) -> KeyPath {
    let Some((index, key)) = field
        .strip_prefix("events[")
        .and_then(|rest| rest.split_once("]."))
    else {
        return root.join(field);
    };
    match (index.parse::<usize>(), key) {
        (Ok(i), "dtc") => root.key("signals").index(i).key("stale_dtc"),
        (Ok(i), "name") => root.key("signals").index(i).key("name"),
        _ => root.key("staleness").join(key),
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
                "maf",
                "turbo_p_ic",
                "turbo_t_ic",
                "turbo_p_im",
                "turbo_maf",
                "turbo_engine_speed",
                "turbo_throttle",
                "turbo_wastegate",
                "ambient_pressure",
                "ambient_temperature",
                "wheel_fl_speed",
                "wheel_fl_current",
                "wheel_fl_brake",
                "wheel_fr_speed",
                "wheel_fr_current",
                "wheel_fr_brake",
                "wheel_rl_speed",
                "wheel_rl_current",
                "wheel_rl_brake",
                "wheel_rr_speed",
                "wheel_rr_current",
                "wheel_rr_brake",
                "wheel_drive_torque"
            ]
        );
        assert_eq!(cfg.staleness.debounce, DebounceConfig::MonitorInternal);
        assert!(cfg.monitors.throttle);
        assert!(cfg.monitors.intake);
        // Off by default: the air path's false DTCs on other LiU-ICE runs; the wheel monitor
        // not yet judged.
        assert!(!cfg.monitors.turbo);
        assert!(!cfg.monitors.wheel);
        assert_eq!(cfg.signal_specs()[1].max_age_ns, 5_000_000);
        assert_eq!(cfg.signal_specs()[6].max_age_ns, 250_000_000);
        assert_eq!(cfg.truth, default_truths());
        let mem = cfg.staleness_memory_config();
        assert_eq!(mem.events[1].name, "tps_no_signal");
        assert_eq!(mem.validate().expect("valid").len(), 30);
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
        assert!(e.contains("[staleness] priority = 0"), "{e}");

        let text = DEFAULT_RUNTIME_TOML.replace("name = \"tps\"", "name = \"motor_voltage\"");
        let e = RuntimeConfig::parse(&text, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("signals[1].name"), "{e}");
    }
}
