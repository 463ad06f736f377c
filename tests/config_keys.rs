//! Hostile configuration values (issue 11): every key of config/fdd.toml, config/throttle.toml
//! and config/intake.toml (every leaf, array elements included, and the `[monitor]` keys that
//! take a default when absent) is set in turn to a wrong type, NaN, a negative value, zero,
//! 1e-9 (for keys in seconds), 1e300, and for arrays one element too many. The files are
//! written to a temporary directory and loaded the way `fdd replay` does (`RuntimeConfig::load`,
//! then the runtime with its monitors built from the files it names). Each value is either
//! refused with an error that names the file and the full key (`[monitor] period_s`,
//! `signals[1].max_age_s`, `[model] modes[2].a12`), or accepted, and then only if it is on the
//! allow-list below with the reason; an accepted value then runs the runtime for 1000 steps of
//! synthetic samples (and, for the throttle file's model and filter tables, a short Table II
//! run) without panicking. A key added without validation fails here.
//!
//! The regression tests after the walk pin the defects the walk was written for.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use fdd::config::{ThrottleConfig, DEFAULT_INTAKE_TOML, DEFAULT_THROTTLE_TOML};
use fdd::reproduce::table2::{run as table2, Table2Settings};
use fdd_monitor::intake::IntakeMonitorConfig;
use fdd_monitor::runtime::config::DEFAULT_RUNTIME_TOML;
use fdd_monitor::runtime::{NullSink, Runtime, RuntimeConfig};
use fdd_monitor::throttle::ThrottleMonitorConfig;
use toml_edit::{DocumentMut, Item, Value};

// ------------------------------------------------------------------------------------------
// The allow-list: values accepted on purpose, as (file, key pattern, mutations, reason). `*`
// in a pattern matches one index or one key segment.
// ------------------------------------------------------------------------------------------

const ALLOWED: &[(File, &str, &[Mutation], &str)] = &[
    // config/fdd.toml
    (
        File::Runtime,
        "[replay] limits.*",
        &[Mutation::Huge],
        "a host that trusts its logs may lift a reader limit altogether (every length is still checked against the file before it is allocated)",
    ),
    // config/throttle.toml
    (
        File::Throttle,
        "[model] angle_limits_deg[0]",
        &[Mutation::Negative],
        "a closed stop below 0 deg is another sensor calibration; the angle order is checked",
    ),
    (
        File::Throttle,
        "[model] friction_switch_deg",
        &[Mutation::Negative, Mutation::Zero],
        "the preload switch may lie at or below the closed stop",
    ),
    (
        File::Throttle,
        "[model] modes[*].*",
        &[Mutation::Negative, Mutation::Zero],
        "identified coefficients are signed and may vanish (bounded to +-1000)",
    ),
    (
        File::Throttle,
        "[truth] process_noise_scale",
        &[Mutation::Zero],
        "0: a noise-free truth simulation",
    ),
    (
        File::Throttle,
        "[truth] process_noise_f_diag[*]",
        &[Mutation::Zero],
        "0: no process noise in that state (the file already has one)",
    ),
    (
        File::Throttle,
        "[wattmeter_ukf] ahsm_lambda",
        &[Mutation::Zero],
        "lambda = 0 is a valid AHSM set (n + lambda = 3 > 0)",
    ),
    (
        File::Throttle,
        "[wattmeter_ukf] agm_v[*]",
        &[Mutation::Negative],
        "AGM shape entries enter squared: the sign does not matter",
    ),
    (
        File::Throttle,
        "[wattmeter_ukf] q_diag[*]",
        &[Mutation::Zero],
        "process noise may vanish in a state (Q positive semidefinite)",
    ),
    (
        File::Throttle,
        "[wattmeter_ukf] r_floor",
        &[Mutation::Zero],
        "no floor: R is the wattmeter noise alone",
    ),
    (
        File::Throttle,
        "[wattmeter_ukf] reacquire_holdoff",
        &[Mutation::Zero],
        "0: the re-seed test runs again at the next update",
    ),
    (
        File::Throttle,
        "[monitor] wattmeter_r_floor",
        &[Mutation::Zero],
        "no floor: R is the wattmeter noise alone",
    ),
    (
        File::Throttle,
        "[monitor] noise_settle_s",
        &[Mutation::Zero, Mutation::Tiny],
        "0: the noise estimates are used at once (a shorter time is 0)",
    ),
    (
        File::Throttle,
        "[monitor] rail_low_v",
        &[Mutation::Zero],
        "a circuit-low candidate only at 0 V",
    ),
    (
        File::Throttle,
        "[monitor] rail_margin_deg",
        &[Mutation::Zero],
        "no margin beyond the 3 sigma of the estimate",
    ),
    (
        File::Throttle,
        "[monitor] static_map_error_frac",
        &[Mutation::Zero],
        "a static map taken as exact",
    ),
    (
        File::Throttle,
        "[monitor] tps_lag_tolerance_s",
        &[Mutation::Zero, Mutation::Tiny],
        "a TPS without lag (a shorter lag is none)",
    ),
    (
        File::Throttle,
        "[monitor] tps_step_floor_v",
        &[Mutation::Zero],
        "no floor on the step test's deviation",
    ),
    (
        File::Throttle,
        "[monitor] tps_step_motion_scale",
        &[Mutation::Zero],
        "no motion allowance in the step test",
    ),
    (
        File::Throttle,
        "[monitor] tps_step_mode_margin_deg",
        &[Mutation::Zero],
        "only the current mode in the mode-switch allowance",
    ),
    (
        File::Throttle,
        "[monitor] tps_step_rho_floor",
        &[Mutation::Zero],
        "the velocity estimate as it is",
    ),
    (
        File::Throttle,
        "[monitor] watt_model_error_w",
        &[Mutation::Zero],
        "no dead band before the wattmeter CUSUM",
    ),
    (
        File::Throttle,
        "[monitor] watt_gain_tolerance",
        &[Mutation::Zero],
        "no gain tolerance of the wattmeter",
    ),
    (
        File::Throttle,
        "[monitor] watt_lag_tolerance_s",
        &[Mutation::Zero, Mutation::Tiny],
        "a wattmeter without lag",
    ),
    (
        File::Throttle,
        "[monitor] static_map_from_deg",
        &[Mutation::Zero],
        "the static map counts from the closed stop",
    ),
    (
        File::Throttle,
        "[monitor] frozen_alone_samples",
        &[Mutation::Zero],
        "0: never a stuck TPS on repeated readings alone (documented)",
    ),
    // config/intake.toml
    (
        File::Intake,
        "[model] throttle_closed_angle_deg",
        &[Mutation::Zero],
        "a plate closing at right angles to the bore",
    ),
    (
        File::Intake,
        "[model] throttle_leak_area_m2",
        &[Mutation::Zero],
        "a plate that seals",
    ),
    (
        File::Intake,
        "[model] egr_max_area_m2",
        &[Mutation::Zero],
        "an engine without EGR",
    ),
    (
        File::Intake,
        "[model] pump_damping",
        &[Mutation::Zero],
        "an undamped pulsation oscillator (0 <= xi < 1)",
    ),
    (
        File::Intake,
        "[model] vol_eff_speeds_rpm[0]",
        &[Mutation::Zero],
        "the map may start at 0 rpm",
    ),
    (
        File::Intake,
        "[model] vol_eff_offset_kg_per_s[*]",
        &[Mutation::Negative, Mutation::Zero],
        "the offset is signed and may vanish (bounded to +-1 kg/s)",
    ),
    (
        File::Intake,
        "[monitor] q_std[*]",
        &[Mutation::Zero],
        "process noise may vanish in a state (Q positive semidefinite)",
    ),
    (
        File::Intake,
        "[monitor] map_low_pa",
        &[Mutation::Zero],
        "no MAP circuit-low limit",
    ),
    (
        File::Intake,
        "[monitor] map_low_margin_pa",
        &[Mutation::Zero],
        "no margin beyond the 3 sigma of the estimate",
    ),
    (
        File::Intake,
        "[monitor] map_high_margin_pa",
        &[Mutation::Zero],
        "no margin beyond the 3 sigma of the estimate",
    ),
    (
        File::Intake,
        "[monitor] maf_low_kg_s",
        &[Mutation::Zero],
        "no MAF circuit-low limit",
    ),
    (
        File::Intake,
        "[monitor] maf_low_margin_kg_s",
        &[Mutation::Zero],
        "no margin beyond the 3 sigma of the estimate",
    ),
    (
        File::Intake,
        "[monitor] throttle_model_rel",
        &[Mutation::Zero],
        "no model-error allowance",
    ),
    (
        File::Intake,
        "[monitor] pressure_model_rel",
        &[Mutation::Zero],
        "no model-error allowance",
    ),
    (
        File::Intake,
        "[monitor] flow_model_rel",
        &[Mutation::Zero],
        "no model-error allowance",
    ),
    (
        File::Intake,
        "[monitor] transient_tolerance_s",
        &[Mutation::Zero, Mutation::Tiny],
        "no transient allowance",
    ),
    (
        File::Intake,
        "[monitor] ambient_pressure_std_pa",
        &[Mutation::Zero],
        "an ambient pressure known exactly",
    ),
    (
        File::Intake,
        "[monitor] adapt_min_s",
        &[Mutation::Zero, Mutation::Tiny],
        "the residual tests start at once",
    ),
    (
        File::Intake,
        "[monitor] adapt_limit",
        &[Mutation::Zero],
        "no learned correction",
    ),
    (
        File::Intake,
        "[monitor] isolation_margin",
        &[Mutation::Zero],
        "the best hypothesis named without a lead",
    ),
    (
        File::Intake,
        "[monitor] isolation_margin_rel",
        &[Mutation::Zero],
        "no relative lead",
    ),
    (
        File::Intake,
        "[monitor] isolation_min_s",
        &[Mutation::Zero, Mutation::Tiny],
        "isolation may name a fault at the alarm",
    ),
    (
        File::Intake,
        "[monitor] episode_quiet_s",
        &[Mutation::Zero, Mutation::Tiny],
        "an episode closes as soon as the tests are quiet",
    ),
    (
        File::Intake,
        "[monitor] group_after_s",
        &[Mutation::Zero, Mutation::Tiny],
        "the group DTC at the alarm",
    ),
    (
        File::Intake,
        "[monitor] group_margin",
        &[Mutation::Zero],
        "never below the isolation margins anyway",
    ),
    (
        File::Intake,
        "[monitor] group_margin_rel",
        &[Mutation::Zero],
        "never below the isolation margins anyway",
    ),
    (
        File::Intake,
        "[monitor] heal_s",
        &[Mutation::Zero, Mutation::Tiny],
        "intake faults heal as soon as the readings are plausible",
    ),
    (
        File::Intake,
        "[monitor] noise_settle_segments",
        &[Mutation::Zero],
        "no settle segments after a throttle move",
    ),
];

// ------------------------------------------------------------------------------------------
// Leaves and mutations.
// ------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mutation {
    WrongType,
    Nan,
    Negative,
    Zero,
    /// 1e-9, for keys in seconds (a period far below a nanosecond once made a replay endless).
    Tiny,
    Huge,
    Empty,
    ExtraElement,
}

#[derive(Debug, Clone, PartialEq)]
enum Seg {
    Key(String),
    Index(usize),
}

#[derive(Debug, Clone, PartialEq)]
enum Kind {
    Float(f64),
    Int(i64),
    Str,
    Bool,
    Array,
    TableArray,
}

#[derive(Debug, Clone)]
struct Leaf {
    path: Vec<Seg>,
    kind: Kind,
}

impl Leaf {
    /// The key as fdd's errors spell it: `[table] key` below a table, the dotted path below an
    /// array of tables (`signals[1].max_age_s`).
    fn key(&self) -> String {
        let mut out = String::new();
        let mut segs = self.path.iter().peekable();
        if let (Some(Seg::Key(t)), Some(Seg::Key(_))) = (self.path.first(), self.path.get(1)) {
            out.push_str(&format!("[{t}] "));
            segs.next();
        }
        let mut first = true;
        for s in segs {
            match s {
                Seg::Key(k) => {
                    if !first {
                        out.push('.');
                    }
                    out.push_str(k);
                }
                Seg::Index(i) => out.push_str(&format!("[{i}]")),
            }
            first = false;
        }
        out
    }

    fn last_key(&self) -> &str {
        self.path
            .iter()
            .rev()
            .find_map(|s| match s {
                Seg::Key(k) => Some(k.as_str()),
                Seg::Index(_) => None,
            })
            .unwrap_or("")
    }

    /// The mutations that apply to this leaf, each with the value it writes (`None`: append a
    /// copy of the last element). Mutations equal to the file's value are left out.
    fn mutations(&self) -> Vec<(Mutation, Option<Value>)> {
        let k = self.last_key();
        let in_seconds =
            k.ends_with("_s") && !["kg_s", "deg_s", "per_s"].iter().any(|u| k.ends_with(u));
        match &self.kind {
            Kind::Float(d) => {
                let d = *d;
                let mut v = vec![
                    (Mutation::WrongType, Some(Value::from("x"))),
                    (Mutation::Nan, Some(Value::from(f64::NAN))),
                    (
                        Mutation::Negative,
                        Some(Value::from(if d != 0.0 { -d } else { -1.0 })),
                    ),
                    (Mutation::Huge, Some(Value::from(1e300))),
                ];
                if d != 0.0 {
                    v.push((Mutation::Zero, Some(Value::from(0.0))));
                }
                if in_seconds && d != 1e-9 {
                    v.push((Mutation::Tiny, Some(Value::from(1e-9))));
                }
                v
            }
            Kind::Int(d) => {
                let d = *d;
                let mut v = vec![
                    (Mutation::WrongType, Some(Value::from("x"))),
                    (Mutation::Nan, Some(Value::from(f64::NAN))),
                    (
                        Mutation::Negative,
                        Some(Value::from(if d != 0 { -d } else { -1 })),
                    ),
                    (Mutation::Huge, Some(Value::from(i64::MAX))),
                ];
                if d != 0 {
                    v.push((Mutation::Zero, Some(Value::from(0))));
                }
                v
            }
            Kind::Str => vec![
                (Mutation::WrongType, Some(Value::from(1))),
                (Mutation::Empty, Some(Value::from(""))),
            ],
            Kind::Bool => vec![(Mutation::WrongType, Some(Value::from("x")))],
            Kind::Array => vec![
                (Mutation::WrongType, Some(Value::from("x"))),
                (Mutation::ExtraElement, None),
            ],
            Kind::TableArray => vec![(Mutation::ExtraElement, None)],
        }
    }
}

fn leaves(doc: &DocumentMut) -> Vec<Leaf> {
    let mut out = Vec::new();
    for (k, item) in doc.as_table().iter() {
        walk_item(vec![Seg::Key(k.to_string())], item, &mut out);
    }
    out
}

fn walk_item(path: Vec<Seg>, item: &Item, out: &mut Vec<Leaf>) {
    match item {
        Item::Table(t) => {
            for (k, v) in t.iter() {
                let mut p = path.clone();
                p.push(Seg::Key(k.to_string()));
                walk_item(p, v, out);
            }
        }
        Item::ArrayOfTables(a) => {
            out.push(Leaf {
                path: path.clone(),
                kind: Kind::TableArray,
            });
            for (i, t) in a.iter().enumerate() {
                for (k, v) in t.iter() {
                    let mut p = path.clone();
                    p.push(Seg::Index(i));
                    p.push(Seg::Key(k.to_string()));
                    walk_item(p, v, out);
                }
            }
        }
        Item::Value(v) => walk_value(path, v, out),
        Item::None => {}
    }
}

fn walk_value(path: Vec<Seg>, v: &Value, out: &mut Vec<Leaf>) {
    let kind = match v {
        Value::Float(f) => Kind::Float(*f.value()),
        Value::Integer(i) => Kind::Int(*i.value()),
        Value::String(_) | Value::Datetime(_) => Kind::Str,
        Value::Boolean(_) => Kind::Bool,
        Value::Array(a) => {
            out.push(Leaf {
                path: path.clone(),
                kind: Kind::Array,
            });
            for (i, e) in a.iter().enumerate() {
                let mut p = path.clone();
                p.push(Seg::Index(i));
                walk_value(p, e, out);
            }
            return;
        }
        Value::InlineTable(t) => {
            for (k, e) in t.iter() {
                let mut p = path.clone();
                p.push(Seg::Key(k.to_string()));
                walk_value(p, e, out);
            }
            return;
        }
    };
    out.push(Leaf { path, kind });
}

/// Sets the value at `path` (`None`: appends a copy of the last element of the array there).
fn set(doc: &mut DocumentMut, path: &[Seg], new: Option<&Value>) {
    set_in_item(doc.as_item_mut(), path, new);
}

fn set_in_item(item: &mut Item, path: &[Seg], new: Option<&Value>) {
    match (item, path) {
        (Item::ArrayOfTables(a), []) => {
            let last = a.iter().last().expect("non-empty").clone();
            a.push(last);
        }
        (Item::Value(v), _) => set_in_value(v, path, new),
        (Item::Table(t), [Seg::Key(k), rest @ ..]) => {
            let child = t.get_mut(k).expect("key exists");
            if rest.is_empty() && !matches!(child, Item::ArrayOfTables(_)) {
                match new {
                    Some(n) => *child = Item::Value(n.clone()),
                    None => set_in_item(child, rest, None),
                }
            } else {
                set_in_item(child, rest, new);
            }
        }
        (Item::ArrayOfTables(a), [Seg::Index(i), rest @ ..]) => {
            let t = a.get_mut(*i).expect("index exists");
            let mut item = Item::Table(std::mem::take(t));
            set_in_item(&mut item, rest, new);
            if let Item::Table(back) = item {
                *t = back;
            }
        }
        (item, path) => panic!("cannot set {path:?} in {item:?}"),
    }
}

fn set_in_value(v: &mut Value, path: &[Seg], new: Option<&Value>) {
    match (v, path) {
        (Value::Array(a), []) => {
            let last = a.iter().last().expect("non-empty").clone();
            a.push(last);
        }
        (v, []) => *v = new.expect("a value").clone(),
        (Value::Array(a), [Seg::Index(i), rest @ ..]) => {
            set_in_value(a.get_mut(*i).expect("index exists"), rest, new)
        }
        (Value::InlineTable(t), [Seg::Key(k), rest @ ..]) => {
            set_in_value(t.get_mut(k).expect("key exists"), rest, new)
        }
        (v, path) => panic!("cannot set {path:?} in {v:?}"),
    }
}

/// Whether `key` matches `pattern` (`*` matching one index or one key segment).
fn matches(pattern: &str, key: &str) -> bool {
    fn tokens(s: &str) -> Vec<String> {
        let mut out = Vec::new();
        let mut cur = String::new();
        for c in s.chars() {
            if matches!(c, '.' | '[' | ']' | ' ') {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
                out.push(c.to_string());
            } else {
                cur.push(c);
            }
        }
        if !cur.is_empty() {
            out.push(cur);
        }
        out
    }
    let (p, k) = (tokens(pattern), tokens(key));
    p.len() == k.len() && p.iter().zip(&k).all(|(a, b)| a == "*" || a == b)
}

// ------------------------------------------------------------------------------------------
// Loading and running.
// ------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum File {
    Runtime,
    Throttle,
    Intake,
}

impl File {
    fn name(self) -> &'static str {
        match self {
            File::Runtime => "fdd.toml",
            File::Throttle => "throttle.toml",
            File::Intake => "intake.toml",
        }
    }
}

/// The three files as the walk starts from: the shipped ones, the `[monitor]` tables filled
/// with every key that takes a default (same values, so the same behaviour).
fn base_docs() -> [DocumentMut; 3] {
    let parse = |t: &str| t.parse::<DocumentMut>().expect("shipped file parses");
    let mut throttle = parse(DEFAULT_THROTTLE_TOML);
    fill_monitor_defaults(
        &mut throttle,
        toml::Value::try_from(ThrottleMonitorConfig::default()).expect("serializes"),
    );
    let mut intake = parse(DEFAULT_INTAKE_TOML);
    fill_monitor_defaults(
        &mut intake,
        toml::Value::try_from(IntakeMonitorConfig::default()).expect("serializes"),
    );
    [parse(DEFAULT_RUNTIME_TOML), throttle, intake]
}

fn fill_monitor_defaults(doc: &mut DocumentMut, defaults: toml::Value) {
    let toml::Value::Table(defaults) = defaults else {
        panic!("settings serialize to a table");
    };
    if doc.get("monitor").is_none() {
        doc["monitor"] = toml_edit::table();
    }
    let table = doc["monitor"].as_table_mut().expect("[monitor] is a table");
    for (k, v) in defaults {
        if !table.contains_key(&k) {
            table[&k] = Item::Value(to_edit(&v));
        }
    }
}

fn to_edit(v: &toml::Value) -> Value {
    match v {
        toml::Value::String(s) => Value::from(s.as_str()),
        toml::Value::Integer(i) => Value::from(*i),
        toml::Value::Float(f) => Value::from(*f),
        toml::Value::Boolean(b) => Value::from(*b),
        toml::Value::Array(a) => Value::Array(a.iter().map(to_edit).collect()),
        other => panic!("unexpected default {other:?}"),
    }
}

/// The runtime file as written: the shipped one naming the monitor files beside it.
fn runtime_text(doc: &DocumentMut) -> String {
    let mut doc = doc.clone();
    if doc.get("monitors").is_none() {
        doc["monitors"] = toml_edit::table();
    }
    doc["monitors"]["throttle_config"] = toml_edit::value("throttle.toml");
    doc["monitors"]["intake_config"] = toml_edit::value("intake.toml");
    doc.to_string()
}

fn write(dir: &Path, file: File, doc: &DocumentMut) {
    let text = match file {
        File::Runtime => runtime_text(doc),
        _ => doc.to_string(),
    };
    std::fs::write(dir.join(file.name()), text).expect("write");
}

/// Loads the files as `fdd replay` does and builds the runtime: the error text, if refused.
fn load(dir: &Path) -> Result<Runtime, String> {
    let cfg = RuntimeConfig::load(Some(&dir.join("fdd.toml"))).map_err(|e| e.to_string())?;
    Runtime::new(&cfg).map_err(|e| e.to_string())
}

/// Steps of the synthetic run: 1 s at 1 ms.
const STEPS_MS: u64 = 1000;

/// Runs the runtime on synthetic samples (the throttle signals every 1 ms, the intake signals
/// every 15 ms, a 2000 rpm segment) for [`STEPS_MS`] ms; returns the steps the monitors ran.
/// A hang would stop the test here (the step count is bounded by the periods' ranges).
fn drive(rt: &mut Runtime) -> u64 {
    let mut sink = NullSink;
    rt.start_operation_cycle(0, &mut sink)
        .expect("cycle starts");
    let id = |rt: &Runtime, n: &str| rt.signal(n);
    let throttle = ["motor_voltage", "tps", "wattmeter"].map(|n| id(rt, n));
    let intake = [
        "engine_speed",
        "intake_throttle",
        "egr_command",
        "map",
        "maf",
    ]
    .map(|n| id(rt, n));
    for k in 1..=STEPS_MS {
        let t = k * 1_000_000;
        let x = (k as f64 * 0.01).sin();
        let values = [
            2.0 + x,
            2.5 + 0.5 * x + 1e-3 * (k % 7) as f64,
            0.5 + 0.2 * x,
        ];
        for (s, v) in throttle.iter().zip(values) {
            if let Some(s) = s {
                let _ = rt.push(*s, t, v);
            }
        }
        if k % 15 == 0 {
            let values = [
                2000.0 + 10.0 * x,
                10.0 + x,
                0.1,
                50_000.0 + 500.0 * x + (k % 11) as f64 * 30.0,
                0.012 + 1e-4 * x,
            ];
            for (s, v) in intake.iter().zip(values) {
                if let Some(s) = s {
                    let _ = rt.push(*s, t, v);
                }
            }
        }
        rt.advance_to(t, &mut sink).expect("advance");
    }
    rt.end_operation_cycle(STEPS_MS * 1_000_000 + 1, &mut sink)
        .expect("cycle ends");
    rt.step_counts().map(|(_, n)| n).sum()
}

/// The outcome of one case: `Ok(accepted)` or the failure to report.
fn case(
    dir: &Path,
    file: File,
    leaf: &Leaf,
    m: Mutation,
    allowed: &mut [bool],
) -> Result<(), String> {
    let key = leaf.key();
    let path = dir.join(file.name()).display().to_string();
    let outcome = catch_unwind(AssertUnwindSafe(|| -> Result<Option<u64>, String> {
        match load(dir) {
            Err(e) => Err(e),
            Ok(mut rt) => {
                let steps = drive(&mut rt);
                if file == File::Throttle
                    && matches!(leaf.path.first(), Some(Seg::Key(t)) if t != "monitor")
                {
                    // The model and filter tables also feed `fdd reproduce table2`.
                    let cfg = ThrottleConfig::load(Some(&dir.join("throttle.toml")))
                        .map_err(|e| format!("reloading: {e}"))?;
                    let s = Table2Settings {
                        samples: 300,
                        seed: 1,
                        wattmeter_std: 1.0,
                        particles: None,
                    };
                    table2(&cfg, &s).map_err(|e| format!("accepted, but table2 fails: {e}"))?;
                }
                Ok(Some(steps))
            }
        }
    }));
    match outcome {
        Err(_) => Err(format!("{key} {m:?}: PANIC")),
        Ok(Err(e)) if e.starts_with("accepted") || e.starts_with("reloading") => {
            Err(format!("{key} {m:?}: {e}"))
        }
        Ok(Err(e)) => {
            if std::env::var_os("CONFIG_KEYS_VERBOSE").is_some() {
                eprintln!("{m:?}: {e}");
            }
            if e.contains(&path) && e.contains(&key) {
                Ok(())
            } else {
                Err(format!(
                    "{key} {m:?}: the error does not name `{path}` and `{key}`: {e}"
                ))
            }
        }
        Ok(Ok(steps)) => {
            // At most one step per 10 us of each monitor (the shortest periods admitted).
            let steps = steps.unwrap_or(0);
            if steps > 5 * STEPS_MS * 100 {
                return Err(format!("{key} {m:?}: {steps} steps in 1 s"));
            }
            match ALLOWED
                .iter()
                .position(|(f, p, ms, _)| *f == file && matches(p, &key) && ms.contains(&m))
            {
                Some(i) => {
                    allowed[i] = true;
                    Ok(())
                }
                None => Err(format!("{key} {m:?}: accepted but not on the allow-list")),
            }
        }
    }
}

/// Walks every leaf of `file`; returns the failures and which allow-list entries were used.
fn walk(file: File) -> (Vec<String>, Vec<bool>, usize) {
    let dir = tempfile::tempdir().expect("tempdir");
    let docs = base_docs();
    let files = [File::Runtime, File::Throttle, File::Intake];
    for (f, doc) in files.iter().zip(&docs) {
        write(dir.path(), *f, doc);
    }
    let i = files.iter().position(|f| *f == file).expect("file");
    let base = &docs[i];
    let mut failures = Vec::new();
    let mut allowed = vec![false; ALLOWED.len()];
    let mut cases = 0;
    // The base itself loads and runs.
    let mut rt = load(dir.path()).expect("the shipped files load");
    drive(&mut rt);
    for leaf in leaves(base) {
        for (m, value) in leaf.mutations() {
            let mut doc = base.clone();
            set(&mut doc, &leaf.path, value.as_ref());
            write(dir.path(), file, &doc);
            cases += 1;
            if let Err(f) = case(dir.path(), file, &leaf, m, &mut allowed) {
                failures.push(f);
            }
        }
    }
    write(dir.path(), file, base);
    (failures, allowed, cases)
}

fn check_walk(file: File) {
    let (failures, allowed, cases) = walk(file);
    // Allow-list entries of this file that no case used are stale.
    let unused: Vec<&str> = ALLOWED
        .iter()
        .zip(&allowed)
        .filter(|((f, _, _, _), used)| *f == file && !**used)
        .map(|((_, p, _, _), _)| *p)
        .collect();
    assert!(
        failures.is_empty() && unused.is_empty(),
        "{} of {cases} cases of {} failed:\n{}\nunused allow-list entries: {unused:?}",
        failures.len(),
        file.name(),
        failures.join("\n")
    );
    assert!(cases > 100, "only {cases} cases");
}

#[test]
fn every_key_of_fdd_toml_is_validated() {
    check_walk(File::Runtime);
}

#[test]
fn every_key_of_throttle_toml_is_validated() {
    check_walk(File::Throttle);
}

#[test]
fn every_key_of_intake_toml_is_validated() {
    check_walk(File::Intake);
}

// ------------------------------------------------------------------------------------------
// Regression tests of the defects.
// ------------------------------------------------------------------------------------------

/// The runtime error of the shipped files with `line` appended to (or replacing `old` in) the
/// `[monitor]` table of the throttle or intake file, or changed in fdd.toml.
fn runtime_error(file: File, old: &str, new: &str) -> (String, String) {
    let dir = tempfile::tempdir().expect("tempdir");
    let docs = base_docs();
    for (f, doc) in [File::Runtime, File::Throttle, File::Intake]
        .iter()
        .zip(&docs)
    {
        write(dir.path(), *f, doc);
    }
    let p = dir.path().join(file.name());
    let text = std::fs::read_to_string(&p).expect("read");
    assert!(text.contains(old), "{old} not in {}", file.name());
    std::fs::write(&p, text.replacen(old, new, 1)).expect("write");
    let e = load(dir.path()).expect_err("refused");
    (e, p.display().to_string())
}

#[test]
fn monitor_settings_errors_name_the_file_the_table_and_the_range() {
    let (e, path) = runtime_error(File::Throttle, "period_s = 0.001", "period_s = 1e300");
    assert_eq!(
        e,
        format!("{path}: [monitor] period_s = 1e300: must be between 1e-4 and 1 s")
    );
    let (e, path) = runtime_error(
        File::Intake,
        "poll_period_s = 0.001",
        "poll_period_s = 1e-9",
    );
    assert_eq!(
        e,
        format!("{path}: [monitor] poll_period_s = 1e-9: must be between 1e-5 and 1 s")
    );
}

#[test]
fn each_error_names_the_key_the_user_wrote() {
    let cases = [
        (
            File::Throttle,
            "tps_cusum_min_bias_sigma = 1.0",
            "tps_cusum_min_bias_sigma = 0.0",
            "[monitor] tps_cusum_min_bias_sigma = 0.0: must be above 0",
        ),
        (
            File::Throttle,
            "dtc_tps_low = \"P0122-16\"",
            "dtc_tps_low = \"X0122\"",
            "[monitor] dtc_tps_low = \"X0122\": ",
        ),
        (
            File::Throttle,
            "tps_noise_v = 0.0052",
            "tps_noise_v = 1e300",
            "[monitor] tps_noise_v = 1e300: must be between 1e-6 and 1 V",
        ),
        (
            File::Intake,
            "federated_shares = [0.5, 0.5]",
            "federated_shares = [0.5, 1.5]",
            "[monitor] federated_shares[1] = 1.5: must be above 0 and below 1",
        ),
        (
            File::Throttle,
            "ahsm_lambda = 12.0",
            "ahsm_lambda = -5.0",
            "[wattmeter_ukf] ahsm_lambda = -5.0: must be above -3",
        ),
        (
            File::Throttle,
            "a12 = 0.0442",
            "a12 = nan",
            "[model] modes[2].a12 = NaN: must be between -1000 and 1000",
        ),
        (
            File::Runtime,
            "max_age_s = 0.25\n# P0105",
            "max_age_s = -0.25\n# P0105",
            "signals[6].max_age_s = -0.25: must be between 1e-4 and 3600 s",
        ),
    ];
    for (file, old, new, want) in cases {
        let (e, path) = runtime_error(file, old, new);
        assert!(
            e.starts_with(&format!("{path}: {want}")),
            "{e}\nwanted: {want}"
        );
    }
    // A huge period was reported as `motion_window_s`.
    let (e, _) = runtime_error(File::Throttle, "period_s = 0.001", "period_s = 5e-5");
    assert!(e.contains("[monitor] period_s = 5e-5"), "{e}");
    let (e, _) = runtime_error(
        File::Throttle,
        "motion_window_s = 0.2",
        "motion_window_s = 60.0",
    );
    assert!(
        e.contains("[monitor] motion_window_s = 60.0: must span 1 to 512 steps"),
        "{e}"
    );
}

#[test]
fn a_negative_or_nan_clip_is_refused_not_a_panic() {
    for v in ["-1.0", "nan", "0.0"] {
        let (e, path) = runtime_error(
            File::Throttle,
            "cusum_clip_sigma = 8.0",
            &format!("cusum_clip_sigma = {v}"),
        );
        assert!(
            e.starts_with(&format!("{path}: [monitor] cusum_clip_sigma = ")),
            "{e}"
        );
        assert!(e.ends_with("must be above 0 and at most 1000 sigma"), "{e}");
    }
}

#[test]
fn periods_far_below_a_microsecond_are_refused_with_the_bound() {
    let (e, path) = runtime_error(
        File::Runtime,
        "check_period_s = 0.001",
        "check_period_s = 1e-9",
    );
    assert_eq!(
        e,
        format!("{path}: [staleness] check_period_s = 1e-9: must be between 1e-5 and 10 s")
    );
    let (e, _) = runtime_error(File::Runtime, "max_gap_s = 10.0", "max_gap_s = 1e300");
    assert!(
        e.contains("[replay] max_gap_s = 1e300: must be between 0.1 and 86400 s"),
        "{e}"
    );
}

#[test]
fn extra_array_entries_are_refused_with_the_expected_length() {
    let (e, path) = runtime_error(
        File::Throttle,
        "agm_v = [0.8819, 0.8819, 0.8819]",
        "agm_v = [0.8819, 0.8819, 0.8819, 0.8819]",
    );
    assert!(
        e.starts_with(&format!(
            "{path}: [wattmeter_ukf] agm_v = [0.8819, 0.8819, 0.8819, 0.8819]: invalid length 4, expected an array of exactly 3 values"
        )),
        "{e}"
    );
    let (e, _) = runtime_error(
        File::Intake,
        "q_std = [150.0, 20.0, 2.1e-3, 3e-5, 200.0, 6e4]",
        "q_std = [150.0, 20.0, 2.1e-3, 3e-5, 200.0, 6e4, 1.0]",
    );
    assert!(
        e.contains("[monitor] q_std = ") && e.contains("exactly 6 values"),
        "{e}"
    );
    let four_modes = format!(
        "{DEFAULT_THROTTLE_TOML}\n[[model.modes]]\na12 = 0.0\na21 = 0.0\na22 = 0.0\na23 = 0.0\na32 = 0.0\na33 = 0.0\nb = 0.0\nc1 = 0.0\nc2 = 0.0\nc3 = 0.0\n"
    );
    let e = ThrottleConfig::parse(&four_modes, "t.toml")
        .expect_err("four modes")
        .to_string();
    assert!(
        e.starts_with("t.toml: [model] modes = (array of tables): invalid length 4"),
        "{e}"
    );
}

#[test]
fn values_are_printed_readably() {
    let (e, _) = runtime_error(
        File::Intake,
        "nis_threshold = 1500.0",
        "nis_threshold = 1e300",
    );
    assert!(e.contains("nis_threshold = 1e300:"), "{e}");
    assert!(e.len() < 200, "{e}");
    let (e, _) = runtime_error(File::Runtime, "\"P0120-31\"", "\"Q0120-31\"");
    assert!(e.contains("signals[1].stale_dtc = \"Q0120-31\": "), "{e}");
}
