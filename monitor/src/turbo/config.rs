//! `config/turbo_monitor.toml`: which model parameter file the air-path monitor runs on, the
//! signals it reads, its residual processing, its tests and its DTCs.

use std::path::{Path, PathBuf};

use crate::config::ConfigError;
use fdd_estimators::models::turbo::TurboParams;
use fdd_estimators::param::Range;
use serde::Deserialize;

use crate::config_key::{parse_toml, KeyPath};

/// The monitor file compiled into the binary.
pub const DEFAULT_TURBO_MONITOR_TOML: &str = include_str!("../../../config/turbo_monitor.toml");
/// The parameter file it names (`params = "turbo_liu_ice.toml"`), compiled in with it.
pub const DEFAULT_TURBO_PARAMS_TOML: &str = include_str!("../../../config/turbo_liu_ice.toml");
/// The name the embedded monitor file gives its parameter file.
pub const DEFAULT_PARAMS_NAME: &str = "turbo_liu_ice.toml";

/// Number of residuals: the three intake-side flow balances and the boost.
pub const N_RESIDUALS: usize = 4;
/// The residuals' names: the three flow balances in
/// [`fdd_estimators::models::turbo::residuals::SIGNATURE`] row order, then the boost reading
/// against the boost the shaft's balance gives
/// ([`fdd_estimators::models::turbo::shaft_balance`]).
pub const RESIDUALS: [&str; N_RESIDUALS] = [
    "cylinder_flow",
    "throttle_flow",
    "throttle_cylinder",
    "boost_pressure",
];

/// `[monitor]` of the monitor file (every key optional).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TurboMonitorConfig {
    /// How often the monitor looks for a new frame of samples (s).
    pub poll_period_s: f64,
    /// Boost pressure after the intercooler (Pa).
    pub p_ic_signal: String,
    /// Temperature after the intercooler (K).
    pub t_ic_signal: String,
    /// Intake manifold pressure (Pa).
    pub p_im_signal: String,
    /// Air mass flow (kg/s).
    pub maf_signal: String,
    /// Engine speed (rad/s).
    pub speed_signal: String,
    /// Throttle position (%).
    pub throttle_signal: String,
    /// Wastegate position (0 closed .. 1 open).
    pub wastegate_signal: String,
    /// Ambient pressure (Pa).
    pub ambient_pressure_signal: String,
    /// Ambient temperature (K).
    pub ambient_temperature_signal: String,
    /// Time constant of the residuals' first-order low-pass (s); the volumes' filling is
    /// subtracted through the same filter (see the monitor's docs).
    pub filter_tau_s: f64,
    /// Smallest air flow a residual is divided by (kg/s): below it (an engine stopping) the
    /// relative residuals would be noise over nothing.
    pub flow_floor_kg_s: f64,
    /// Frames with a larger gap than this between them (s) restart the filters.
    pub max_frame_gap_s: f64,
    /// The throttle-flow residuals are tested only while the throttle's pressure ratio
    /// `p_im / p_ic` is at most this (-): nearer 1 the throttle flow follows the small pressure
    /// drop across a nearly open plate, and a sensor's noise moves it by tens of percent.
    pub throttle_ratio_max: f64,
    /// A throttle moving faster than this (%/s) is a transient: ...
    pub throttle_rate_max_pct_s: f64,
    /// ... and the tests and the learning wait this long after it (s): the quasi-static balances
    /// hold again once the volumes have filled and the filters have forgotten the transient.
    pub transient_hold_s: f64,
    /// The tests and the learning also wait while the volumes' filling (or emptying) is more
    /// than this fraction of the cylinder flow (-): after a tip-out the intercooler empties
    /// through the closed throttle for seconds, long after the throttle has stopped, and the
    /// balances are then dominated by the filling term, whose volume and temperature the
    /// model knows least.
    pub steady_fill_max: f64,
    /// The throttle residuals also wait while the boost or the manifold pressure through the
    /// fast filter is more than this fraction away from the residuals' filter (-): the
    /// throttle flow at a small opening and a high boost pressure (a tip-out) is where the
    /// throttle model is least known.
    pub steady_pressure_max: f64,
    /// ... and while the intercooler temperature through the residuals' filter is more than
    /// this from its slow low-pass (K): a charge-air temperature sensor is slow (seconds),
    /// and after a change of boost it reads the gas of seconds ago; the model's flows scale
    /// with the temperature (a 20 K lag moves the cylinder flow by 6 %).
    pub steady_temperature_max_k: f64,
    /// Nodes of the calibrated offset map (intake manifold pressure over ambient pressure,
    /// low-passed; strictly increasing): the model's systematic error, which changes with the
    /// load, as the engine family's fault-free logs show it (`fdd calibrate`). Empty: no map.
    pub offset_map_load: Vec<f64>,
    /// The map's value at each node, one `[cylinder_flow, throttle_flow, throttle_cylinder,
    /// boost_pressure]` row per node (relative residuals, -: the flows over the cylinder flow,
    /// the boost over the ambient pressure); linear between nodes, constant beyond the ends.
    /// The learned offsets come on top of it.
    pub offset_map: Vec<[f64; N_RESIDUALS]>,
    /// Each residual's scale at the map's nodes (rows as `offset_map`, -): the model's error
    /// differs from engine to engine more at some loads than at others (near full boost
    /// most), so a test is as sensitive as the model is good where the engine runs. Empty:
    /// `residual_scale` everywhere.
    pub scale_map: Vec<[f64; N_RESIDUALS]>,
    /// Whether the boost residual (the boost reading against the boost the shaft's balance
    /// gives with the commanded wastegate) is computed and tested at all: `fdd calibrate`
    /// turns it off when the fault-free logs leave it untested, so that no test runs on a
    /// scale nothing calibrated.
    pub shaft_test: bool,
    /// How far the wastegate's effective opening may be from its command on a healthy engine
    /// (fraction of travel, 0..0.5): linkage and actuator tolerance, and the exhaust side's
    /// spread from engine to engine, which a boost controller absorbs by moving the
    /// wastegate. Where the wastegate has authority (high exhaust flow, nearly closed) a small
    /// opening moves the boost by tenths of an atmosphere, so the boost residual's scale is
    /// widened by the boost this tolerance moves at the frame (`hypot(scale, spread)`), and its
    /// offset learns only where that spread is within the scale. 0: not widened.
    pub wastegate_tolerance: f64,
    /// Time constant of the learned residual offsets (s).
    pub adapt_tau_s: f64,
    /// Each offset learns alone (at `adapt_tau_s`) for this much of its residual's tested
    /// time in an operation cycle (s) before its test starts; then ten times slower.
    pub adapt_min_s: f64,
    /// Largest learned offset of a relative residual (-): a residual that would need more is a
    /// fault, not an adaptation.
    pub adapt_limit: f64,
    /// Scale of each relative residual (its fault-free standard deviation after the offset),
    /// in [`RESIDUALS`] order; `scale_map`, when given, replaces it.
    pub residual_scale: [f64; N_RESIDUALS],
    /// Twice the smallest CUSUM reference, in scales (the reference is also at least half
    /// `min_shift`).
    pub cusum_min_bias_sigma: f64,
    /// Smallest fault effect the tests are built for, relative to the cylinder flow (-): a
    /// 5 % sensor gain error moves a balance by about 5 % of the flow. A CUSUM's reference is
    /// at least half of it and the offsets go on learning while every deviation is below half
    /// of it (or `LEARN_BAND` scales): the model's error from engine to engine, which moves
    /// the residuals by a few percent as the load changes, is neither accumulated nor frozen.
    pub min_shift: f64,
    /// Threshold of each residual's two-sided CUSUM, in [`RESIDUALS`] order.
    pub cusum_threshold: [f64; N_RESIDUALS],
    /// After the first residual alarm, how long the bank goes on collecting frames before it
    /// decides (s).
    pub decision_window_s: f64,
    /// Smallest probability of the best hypothesis among the seven for it to be named (else
    /// the group DTC).
    pub isolation_min_probability: f64,
    /// A decided fault is taken as gone after this much tested time (s) with no CUSUM rising:
    /// its events pass again (the DTCs stay stored; a fault still present decides again).
    pub heal_s: f64,
    /// DTC of a `p_im` sensor gain or offset (range/performance, signal compare failure).
    pub dtc_p_im: String,
    /// DTC of a boost pressure sensor fault.
    pub dtc_p_ic: String,
    /// DTC of an air mass flow sensor fault.
    pub dtc_maf: String,
    /// DTC of an intercooler temperature sensor bias.
    pub dtc_t_ic: String,
    /// DTC of a leak of the intake air system (before or after the throttle).
    pub dtc_leak: String,
    /// DTC of a throttle body / actuator fault (the throttle passes other than its position
    /// says).
    pub dtc_throttle: String,
    /// DTC of boost below what the commanded wastegate gives (the boost residual alone: the
    /// wastegate more open than commanded, or the turbo weaker than the model).
    pub dtc_underboost: String,
    /// DTC of boost above what the commanded wastegate gives (the boost residual alone: the
    /// wastegate more closed than commanded).
    pub dtc_overboost: String,
    /// DTC of an air-path fault detected and not isolated (the candidates name the faults
    /// still possible).
    pub dtc_group: String,
}

impl Default for TurboMonitorConfig {
    fn default() -> Self {
        Self {
            poll_period_s: 0.01,
            p_ic_signal: "turbo_p_ic".into(),
            t_ic_signal: "turbo_t_ic".into(),
            p_im_signal: "turbo_p_im".into(),
            maf_signal: "turbo_maf".into(),
            speed_signal: "turbo_engine_speed".into(),
            throttle_signal: "turbo_throttle".into(),
            wastegate_signal: "turbo_wastegate".into(),
            ambient_pressure_signal: "ambient_pressure".into(),
            ambient_temperature_signal: "ambient_temperature".into(),
            filter_tau_s: 1.0,
            flow_floor_kg_s: 2e-3,
            max_frame_gap_s: 0.5,
            throttle_ratio_max: 0.9,
            throttle_rate_max_pct_s: 20.0,
            transient_hold_s: 2.0,
            steady_fill_max: 0.05,
            steady_pressure_max: 0.02,
            steady_temperature_max_k: 1.0,
            offset_map_load: Vec::new(),
            offset_map: Vec::new(),
            scale_map: Vec::new(),
            shaft_test: true,
            wastegate_tolerance: 0.05,
            adapt_tau_s: 5.0,
            adapt_min_s: 15.0,
            adapt_limit: 0.1,
            residual_scale: [0.05, 0.025, 0.05, 0.05],
            cusum_min_bias_sigma: 1.0,
            min_shift: 0.05,
            cusum_threshold: [200.0; N_RESIDUALS],
            decision_window_s: 2.0,
            isolation_min_probability: 0.9,
            heal_s: 10.0,
            dtc_p_im: "P0106-62".into(),
            dtc_p_ic: "P0236-62".into(),
            dtc_maf: "P0101-62".into(),
            dtc_t_ic: "P0096-62".into(),
            dtc_leak: "P2279-64".into(),
            dtc_throttle: "P2119-00".into(),
            dtc_underboost: "P0299-00".into(),
            dtc_overboost: "P0234-00".into(),
            dtc_group: "P0068-62".into(),
        }
    }
}

const POLL: Range = Range::closed(1e-4, 1.0, "s");
const TAU: Range = Range::closed(0.05, 60.0, "s");
const FLOOR: Range = Range::closed(1e-5, 1.0, "kg/s");
const GAP: Range = Range::closed(0.05, 60.0, "s");
const RATIO: Range = Range::closed(0.1, 1.0, "");
const RATE: Range = Range::above(0.0, 1e4, "%/s");
const HOLD: Range = Range::closed(0.0, 60.0, "s");
const MIN_BIAS: Range = Range::above(0.0, 50.0, "");
const CUSUM_H: Range = Range::above(0.0, 1e6, "");
const MIN_SHIFT: Range = Range::closed(0.0, 1.0, "");
const STEADY_T: Range = Range::above(0.0, 100.0, "K");
const STEADY: Range = Range::closed(1e-4, 1.0, "");
const LOAD: Range = Range::closed(0.0, 5.0, "");
const MAP_VALUE: Range = Range::closed(-1.0, 1.0, "");
const ADAPT_TAU: Range = Range::closed(0.1, 3600.0, "s");
const ADAPT_MIN: Range = Range::closed(0.0, 3600.0, "s");
const ADAPT_LIMIT: Range = Range::closed(0.0, 1.0, "");
const SCALE: Range = Range::above(0.0, 10.0, "");
const PROBABILITY: Range = Range::closed(0.0, 1.0, "");
const WG_TOLERANCE: Range = Range::closed(0.0, 0.5, "");
const HEAL: Range = Range::closed(0.1, 3600.0, "s");
const WINDOW: Range = Range::closed(0.0, 60.0, "s");

impl TurboMonitorConfig {
    /// Checks every key; errors name it under `at` (`[monitor]`).
    pub fn validate(&self, at: &KeyPath) -> Result<(), ConfigError> {
        at.key("poll_period_s").check(self.poll_period_s, POLL)?;
        for (k, v) in [
            ("p_ic_signal", &self.p_ic_signal),
            ("t_ic_signal", &self.t_ic_signal),
            ("p_im_signal", &self.p_im_signal),
            ("maf_signal", &self.maf_signal),
            ("speed_signal", &self.speed_signal),
            ("throttle_signal", &self.throttle_signal),
            ("wastegate_signal", &self.wastegate_signal),
            ("ambient_pressure_signal", &self.ambient_pressure_signal),
            (
                "ambient_temperature_signal",
                &self.ambient_temperature_signal,
            ),
        ] {
            at.key(k).check_name(v)?;
        }
        at.key("filter_tau_s").check(self.filter_tau_s, TAU)?;
        at.key("flow_floor_kg_s")
            .check(self.flow_floor_kg_s, FLOOR)?;
        at.key("max_frame_gap_s").check(self.max_frame_gap_s, GAP)?;
        at.key("throttle_ratio_max")
            .check(self.throttle_ratio_max, RATIO)?;
        at.key("throttle_rate_max_pct_s")
            .check(self.throttle_rate_max_pct_s, RATE)?;
        at.key("transient_hold_s")
            .check(self.transient_hold_s, HOLD)?;
        at.key("steady_fill_max")
            .check(self.steady_fill_max, STEADY)?;
        at.key("steady_pressure_max")
            .check(self.steady_pressure_max, STEADY)?;
        at.key("steady_temperature_max_k")
            .check(self.steady_temperature_max_k, STEADY_T)?;
        at.key("wastegate_tolerance")
            .check(self.wastegate_tolerance, WG_TOLERANCE)?;
        for (i, &x) in self.offset_map_load.iter().enumerate() {
            let k = at.key("offset_map_load").index(i);
            k.check(x, LOAD)?;
            if i > 0 && x <= self.offset_map_load[i - 1] {
                return Err(k.invalid(
                    crate::config_key::show(x),
                    format!(
                        "not above the node before it ({}): the nodes must increase",
                        self.offset_map_load[i - 1]
                    ),
                ));
            }
        }
        if self.offset_map.len() != self.offset_map_load.len() {
            return Err(at.key("offset_map").invalid(
                format!("{} rows", self.offset_map.len()),
                format!(
                    "offset_map_load has {} nodes: one row per node",
                    self.offset_map_load.len()
                ),
            ));
        }
        for (i, row) in self.offset_map.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                at.key("offset_map").index(i).index(j).check(v, MAP_VALUE)?;
            }
        }
        if !self.scale_map.is_empty() && self.scale_map.len() != self.offset_map_load.len() {
            return Err(at.key("scale_map").invalid(
                format!("{} rows", self.scale_map.len()),
                format!(
                    "offset_map_load has {} nodes: one row per node, or none",
                    self.offset_map_load.len()
                ),
            ));
        }
        for (i, row) in self.scale_map.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                at.key("scale_map").index(i).index(j).check(v, SCALE)?;
            }
        }
        at.key("adapt_tau_s").check(self.adapt_tau_s, ADAPT_TAU)?;
        at.key("adapt_min_s").check(self.adapt_min_s, ADAPT_MIN)?;
        at.key("adapt_limit").check(self.adapt_limit, ADAPT_LIMIT)?;
        for (i, &s) in self.residual_scale.iter().enumerate() {
            at.key("residual_scale").index(i).check(s, SCALE)?;
        }
        // No run-length bound as for the other monitors' CUSUMs: the reference here is at
        // least half `min_shift` (not a Gaussian design), and no run length is computed.
        at.key("cusum_min_bias_sigma")
            .check(self.cusum_min_bias_sigma, MIN_BIAS)?;
        for (i, &h) in self.cusum_threshold.iter().enumerate() {
            at.key("cusum_threshold").index(i).check(h, CUSUM_H)?;
        }
        at.key("min_shift").check(self.min_shift, MIN_SHIFT)?;
        at.key("decision_window_s")
            .check(self.decision_window_s, WINDOW)?;
        at.key("isolation_min_probability")
            .check(self.isolation_min_probability, PROBABILITY)?;
        at.key("heal_s").check(self.heal_s, HEAL)?;
        at.check_dtcs(&[
            ("dtc_p_im", &self.dtc_p_im),
            ("dtc_p_ic", &self.dtc_p_ic),
            ("dtc_maf", &self.dtc_maf),
            ("dtc_t_ic", &self.dtc_t_ic),
            ("dtc_leak", &self.dtc_leak),
            ("dtc_throttle", &self.dtc_throttle),
            ("dtc_underboost", &self.dtc_underboost),
            ("dtc_overboost", &self.dtc_overboost),
            ("dtc_group", &self.dtc_group),
        ])
    }
}

/// The monitor file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct TurboFile {
    /// The model's parameter file, relative to the monitor file (its `[model]` table is read;
    /// other tables, such as a fit's `[measurement_noise]`, are ignored).
    params: String,
    #[serde(default)]
    monitor: TurboMonitorConfig,
}

/// A parameter file's `[model]`.
#[derive(Debug, Clone, Deserialize)]
struct ParamsFile {
    model: TurboParams,
}

/// The monitor's configuration: its model parameters and settings.
#[derive(Debug, Clone)]
pub struct TurboConfig {
    /// The model's parameters (validated).
    pub params: TurboParams,
    /// Where they came from (for messages).
    pub params_origin: String,
    /// `[monitor]`.
    pub monitor: TurboMonitorConfig,
}

impl TurboConfig {
    /// Parses a monitor file's text and its parameter file's text; `origin` and
    /// `params_origin` name them in errors.
    pub fn parse(
        text: &str,
        origin: &str,
        params_text: &str,
        params_origin: &str,
    ) -> Result<Self, ConfigError> {
        let f: TurboFile = parse_toml(text, origin)?;
        let root = KeyPath::file(origin);
        f.monitor.validate(&root.key("monitor"))?;
        let p: ParamsFile = parse_toml(params_text, params_origin)?;
        p.model
            .validate()
            .map_err(|e| KeyPath::file(params_origin).key("model").param(e))?;
        Ok(Self {
            params: p.model,
            params_origin: params_origin.to_string(),
            monitor: f.monitor,
        })
    }

    /// The embedded default (`None`: `config/turbo_monitor.toml` with
    /// `config/turbo_liu_ice.toml`) or a monitor file and the parameter file it names
    /// (relative to the monitor file's directory).
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let Some(path) = path else {
            return Self::parse(
                DEFAULT_TURBO_MONITOR_TOML,
                "embedded config/turbo_monitor.toml",
                DEFAULT_TURBO_PARAMS_TOML,
                "embedded config/turbo_liu_ice.toml",
            );
        };
        let origin = path.display().to_string();
        let text = crate::text_file::read_text(path).map_err(|e| ConfigError::File(Box::new(e)))?;
        let f: TurboFile = parse_toml(&text, &origin)?;
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

/// The embedded monitor file names the embedded parameter file (checked by a test, so that the
/// default and a copy of `config/` behave alike).
pub fn embedded_params_name() -> Option<String> {
    toml::from_str::<TurboFile>(DEFAULT_TURBO_MONITOR_TOML)
        .ok()
        .map(|f| f.params)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_default_loads_and_names_its_parameter_file() {
        let c = TurboConfig::load(None).expect("embedded");
        assert_eq!(c.monitor, {
            let f: TurboFile = toml::from_str(DEFAULT_TURBO_MONITOR_TOML).expect("parses");
            f.monitor
        });
        assert_eq!(embedded_params_name().as_deref(), Some(DEFAULT_PARAMS_NAME));
        // The same files from disk give the same configuration.
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/turbo_monitor.toml");
        let d = TurboConfig::load(Some(&dir)).expect("from disk");
        assert_eq!(d.monitor, c.monitor);
        assert_eq!(d.params, c.params);
    }

    #[test]
    fn errors_name_the_file_and_key() {
        let at = KeyPath::file("t.toml").key("monitor");
        TurboMonitorConfig::default()
            .validate(&at)
            .expect("defaults");
        let mut c = TurboMonitorConfig::default();
        c.residual_scale[1] = 0.0;
        let e = c.validate(&at).unwrap_err().to_string();
        assert!(
            e.starts_with("t.toml: [monitor] residual_scale[1] = 0"),
            "{e}"
        );
        let c = TurboMonitorConfig {
            dtc_leak: "P22".into(),
            ..Default::default()
        };
        let e = c.validate(&at).unwrap_err().to_string();
        assert!(e.contains("dtc_leak"), "{e}");
        // The maps: increasing nodes, one row per node.
        let c = TurboMonitorConfig {
            offset_map_load: vec![0.3, 0.3],
            offset_map: vec![[0.0; N_RESIDUALS]; 2],
            ..Default::default()
        };
        let e = c.validate(&at).unwrap_err().to_string();
        assert!(
            e.contains("offset_map_load[1]") && e.contains("increase"),
            "{e}"
        );
        let c = TurboMonitorConfig {
            offset_map_load: vec![0.3, 0.5],
            offset_map: vec![[0.0; N_RESIDUALS]],
            ..Default::default()
        };
        let e = c.validate(&at).unwrap_err().to_string();
        assert!(
            e.contains("offset_map") && e.contains("one row per node"),
            "{e}"
        );
        let c = TurboMonitorConfig {
            offset_map_load: vec![0.3, 0.5],
            offset_map: vec![[0.0; N_RESIDUALS]; 2],
            scale_map: vec![[0.01; N_RESIDUALS], [0.01, 0.0, 0.01, 0.01]],
            ..Default::default()
        };
        let e = c.validate(&at).unwrap_err().to_string();
        assert!(e.contains("scale_map[1][1]"), "{e}");
        let c = TurboMonitorConfig {
            scale_map: vec![[0.01; N_RESIDUALS]; 2],
            ..c
        };
        c.validate(&at).expect("a valid map");
        let e = TurboConfig::parse(
            "params = \"p.toml\"\n[monitor]\nfilter_tau = 1.0\n",
            "t.toml",
            DEFAULT_TURBO_PARAMS_TOML,
            "p.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("t.toml") && e.contains("filter_tau"), "{e}");
        let e = TurboConfig::parse(
            "params = \"p.toml\"\n",
            "t.toml",
            "[model]\nair_gas_constant_j_per_kg_k = -1.0\n",
            "p.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("p.toml"), "{e}");
    }
}
