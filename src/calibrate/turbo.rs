//! `fdd calibrate` for the air-path monitor: from fault-free logs of one engine family, the
//! model's systematic error along the load (the offset map), the residuals' scales, the
//! learned offsets' range and the CUSUM thresholds.
//!
//! Method (three passes of every log through the runtime, the tests out of reach so that
//! nothing fails and every tested frame is a fault-free sample):
//!
//! 1. **Offset map.** Without a map, each tested frame's relative residual (its deviation
//!    plus its learned offset, as the monitor reports them) is taken; each log's mean is
//!    removed (what the learned offset takes up: engine to engine and drive to drive), and
//!    what is left is averaged at the map's nodes along the load `p_im / p_amb` with
//!    triangular weights; the mean over the logs is added back. The boost residual
//!    may be absent from the logs (see `OPTIONAL`): its test is then switched off
//!    (`shaft_test = false`); any other residual without data is an error. A node with less than
//!    [`MIN_NODE_S`] of weight takes its neighbour's value (the map is flat beyond the data).
//! 2. **Scales and offset range.** With the map: each residual's scale is the standard
//!    deviation of its tested deviations (overall, and per node with the same weights:
//!    `scale_map`); `adapt_limit` is [`ADAPT_MARGIN`] times the largest learned offset (at
//!    least the starting value). Both passes run with the same scales whatever the starting
//!    file holds ([`PASS_SCALE`]), so that a calibrated file calibrates to itself.
//! 3. **Thresholds.** With map and scales: each residual's CUSUM is cut into blocks, and its
//!    threshold is [`THRESHOLD_MARGIN`] times the largest value seen (at least
//!    [`THRESHOLD_FLOOR`]). Not the extreme-value fit of the other monitors: the reference of
//!    these CUSUMs is at least half the design shift (`min_shift`), so most fault-free blocks
//!    end at exactly 0 and the few that rise follow no block-maximum law (tried on the tuning
//!    set: probability-plot correlations 0.73-0.89).

use std::path::{Path, PathBuf};

use fdd_diagnostics::Verdict;
use fdd_monitor::monitor::Output;
use fdd_monitor::runtime::config::TruthConfig;
use fdd_monitor::runtime::Runtime;
use fdd_monitor::turbo::config::{TurboConfig, DEFAULT_TURBO_MONITOR_TOML};
use fdd_monitor::turbo::{N_RESIDUALS, RESIDUAL_ESTIMATES, R_BOOST, TEST_NAMES};

/// Residuals (rows of the maps).
const N: usize = N_RESIDUALS;

use super::{
    block_max, monitor_text, parse_doc, refuse_fault, replay_input, runtime_naming,
    runtime_with_only, CalibrateError, CalibrateOptions, Only,
};
use crate::replay::{ReplayObserver, RuntimeConfig};

/// The map's nodes (`p_im / p_amb`, -): from a closed throttle at idle to full boost.
pub const MAP_NODES: [f64; 12] = [0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2, 1.4, 1.7];
/// Least tested time at a node (s of triangular weight) for its own value.
pub const MIN_NODE_S: f64 = 20.0;
/// Threshold of the passes' CUSUMs: out of reach of a fault-free statistic.
const UNREACHABLE_CUSUM: f64 = 400.0;
/// Learned-offset range of the passes (-).
const WIDE_ADAPT_LIMIT: f64 = 0.3;
/// Each residual's scale in the first two passes (-): it sets how far a deviation may go while
/// the offsets still learn (`LEARN_BAND` scales), the same whatever the starting file says, so
/// that calibrating a calibrated file gives it back.
pub const PASS_SCALE: f64 = 0.05;
/// Margin on the largest learned offset seen (-).
pub const ADAPT_MARGIN: f64 = 1.5;
/// Each threshold is this many times the largest value its CUSUM reached in the logs ...
pub const THRESHOLD_MARGIN: f64 = 2.0;
/// ... and at least this (scales x frames: half a second of a deviation 1 scale above the
/// reference).
pub const THRESHOLD_FLOOR: f64 = 10.0;
/// Fewest blocks of `block_s` in which each test ran.
pub const MIN_BLOCKS: usize = 100;
/// The `[monitor]` key of each residual's threshold (one array).
const THRESHOLD_KEY: &str = "cusum_threshold";
/// Residuals the logs may leave untested: the boost residual has no value where the model's
/// exhaust side cannot pass the logged flow (a parameter set far from the engine). Its test is
/// then switched off in the file written (`shaft_test = false`) rather than run on scales
/// nothing calibrated; the others are needed.
const OPTIONAL: [bool; N] = [false, false, false, true];
/// The `[monitor]` key that switches the boost residual.
const SHAFT_KEY: &str = "shaft_test";

/// The result: the map, scales and thresholds, and the configuration texts to write.
#[derive(Debug, Clone)]
pub struct TurboCalibration {
    pub logs: Vec<PathBuf>,
    pub hours: f64,
    /// Nodes kept and the map's rows.
    pub map_load: Vec<f64>,
    pub map: Vec<[f64; N]>,
    pub scale_map: Vec<[f64; N]>,
    /// Tested time at each node (s of weight).
    pub node_s: Vec<f64>,
    pub scales: [f64; N],
    pub largest_offset: f64,
    pub adapt_limit: f64,
    pub tests: Vec<TurboThreshold>,
    /// The monitor file (`turbo.toml`), its parameter file's name and text, and `fdd.toml`.
    pub turbo_toml: String,
    pub params_name: String,
    pub params_toml: String,
    pub runtime_toml: String,
}

/// One CUSUM's threshold and the fault-free data it comes from.
#[derive(Debug, Clone)]
pub struct TurboThreshold {
    pub test: &'static str,
    /// Whether the logs reached the test (an optional one they did not is switched off).
    pub active: bool,
    /// Blocks in which the test ran, and those in which the CUSUM rose above 0.
    pub blocks: usize,
    pub rose: usize,
    /// The largest value, the log and time (s) of its block.
    pub max: f64,
    pub at: Option<(PathBuf, f64)>,
    pub threshold: f64,
}

/// What one pass gathers.
struct Collector {
    block_ns: u64,
    /// This frame's deviations, offsets and load (the estimates in [`RESIDUAL_ESTIMATES`]
    /// order), complete when the load arrives.
    frame: [f64; 2 * N + 1],
    /// Per log (one entry each, a few hundred bytes: memory does not grow with a log's
    /// length), per residual: sum and count of the relative residual ...
    log_totals: Vec<[(f64, u64); N]>,
    /// ... and per node of [`MAP_NODES`] its weighted sum and weight.
    log_nodes: Vec<NodeSums>,
    /// Per node and residual: the weighted sum of squared deviations and the weight (pass 2).
    dev_nodes: NodeSums,
    /// Per residual: sum of squares and count of tested deviations (pass 2).
    dev_sq: [f64; N],
    dev_n: [u64; N],
    largest_offset: f64,
    maxima: [Vec<(f64, usize, f64)>; N],
    current: [Option<(u64, f64)>; N],
    log_index: usize,
    frame_dt_s: f64,
    fault: Option<(String, f64)>,
    first_ns: Option<u64>,
    last_ns: u64,
    total_ns: u64,
}

impl Collector {
    fn new(block_s: f64, frame_dt_s: f64) -> Self {
        Self {
            block_ns: (block_s * 1e9) as u64,
            frame: [f64::NAN; 2 * N + 1],
            log_totals: Vec::new(),
            log_nodes: Vec::new(),
            dev_nodes: NodeSums::default(),
            dev_sq: [0.0; N],
            dev_n: [0; N],
            largest_offset: 0.0,
            maxima: Default::default(),
            current: [None; N],
            log_index: 0,
            frame_dt_s,
            fault: None,
            first_ns: None,
            last_ns: 0,
            total_ns: 0,
        }
    }

    fn take_frame(&mut self) {
        let load = self.frame[2 * N];
        for i in 0..N {
            self.add(i, self.frame[i], self.frame[N + i], load);
        }
        self.frame = [f64::NAN; 2 * N + 1];
    }

    /// A new log's accumulators.
    fn start_log(&mut self) {
        self.log_totals.push([(0.0, 0); N]);
        self.log_nodes.push(NodeSums::default());
    }

    /// One tested frame of residual `i` in the current log: its deviation, learned offset and
    /// load.
    fn add(&mut self, i: usize, dev: f64, off: f64, load: f64) {
        if !(dev.is_finite() && off.is_finite() && load.is_finite()) {
            return;
        }
        let (Some(t), Some(nodes)) = (self.log_totals.last_mut(), self.log_nodes.last_mut()) else {
            return;
        };
        let rel = dev + off;
        t[i].0 += rel;
        t[i].1 += 1;
        nodes.add(i, load, rel);
        self.dev_nodes.add(i, load, dev * dev);
        self.dev_sq[i] += dev * dev;
        self.dev_n[i] += 1;
        self.largest_offset = self.largest_offset.max(off.abs());
    }
}

/// Per node of [`MAP_NODES`] and residual: a weighted sum and its weight (frames).
#[derive(Debug, Clone, Copy, Default)]
struct NodeSums {
    sum: [[f64; N]; MAP_NODES.len()],
    weight: [[f64; N]; MAP_NODES.len()],
}

impl NodeSums {
    /// `value` of residual `i` at `load`, shared by the two nodes around it.
    fn add(&mut self, i: usize, load: f64, value: f64) {
        for (j, a) in node_weights(load) {
            self.sum[j][i] += a * value;
            self.weight[j][i] += a;
        }
    }

    /// The weighted mean at each node (NaN without weight) and the weights.
    fn means(&self) -> (Vec<[f64; N]>, Vec<[f64; N]>) {
        let mean = self
            .sum
            .iter()
            .zip(&self.weight)
            .map(|(s, w)| std::array::from_fn(|i| s[i] / w[i]))
            .collect();
        (mean, self.weight.to_vec())
    }
}

impl ReplayObserver for Collector {
    fn begin_log(&mut self, _rt: &Runtime, _truths: &[TruthConfig]) {
        self.current = [None; N];
        self.first_ns = None;
        self.start_log();
    }

    fn output(&mut self, t_ns: u64, monitor: &str, output: &Output<'_>) {
        if monitor != "turbo" {
            return;
        }
        self.first_ns.get_or_insert(t_ns);
        self.last_ns = self.last_ns.max(t_ns);
        match *output {
            Output::Test { test, result } if result.verdict != Verdict::NotTested => {
                let Some(i) = TEST_NAMES.iter().position(|t| *t == test) else {
                    return;
                };
                block_max(
                    &mut self.current[i],
                    &mut self.maxima[i],
                    (t_ns, self.block_ns, self.log_index),
                    result.value,
                );
            }
            Output::Estimate { name, value, .. } => {
                if let Some(k) = RESIDUAL_ESTIMATES.iter().position(|n| *n == name) {
                    self.frame[k] = value;
                    if k == RESIDUAL_ESTIMATES.len() - 1 {
                        self.take_frame();
                    }
                }
            }
            _ => {}
        }
    }

    fn truth(&mut self, t_ns: u64, _index: usize, fault: &str, active: bool, _o: Option<bool>) {
        if active && self.fault.is_none() {
            self.fault = Some((fault.to_string(), t_ns as f64 * 1e-9));
        }
    }

    fn end_log(&mut self) {
        // The last, partial block is dropped.
        self.current = [None; N];
        if let Some(a) = self.first_ns {
            self.total_ns += self.last_ns.saturating_sub(a);
        }
        self.last_ns = 0;
    }
}

/// Runs every log through `cfg`, refusing one with a fault active.
fn pass(
    logs: &[PathBuf],
    cfg: &RuntimeConfig,
    block_s: f64,
    frame_dt_s: f64,
) -> Result<Collector, CalibrateError> {
    let mut c = Collector::new(block_s, frame_dt_s);
    for (i, file) in logs.iter().enumerate() {
        c.log_index = i;
        c.fault = None;
        replay_input(file, cfg, &mut c)?;
        refuse_fault(file, c.fault.take())?;
    }
    Ok(c)
}

/// Triangular weights of the nodes around `load` (all on an end node beyond it).
fn node_weights(load: f64) -> [(usize, f64); 2] {
    let n = MAP_NODES.len();
    let j = MAP_NODES.partition_point(|&x| x <= load);
    if j == 0 {
        [(0, 1.0), (0, 0.0)]
    } else if j >= n {
        [(n - 1, 1.0), (n - 1, 0.0)]
    } else {
        let a = (load - MAP_NODES[j - 1]) / (MAP_NODES[j] - MAP_NODES[j - 1]);
        [(j - 1, 1.0 - a), (j, a)]
    }
}

/// Rows at the nodes `keep` of [`MAP_NODES`]: a residual with less than `min_w` of weight at
/// a node takes its value at the nearest kept node where it has enough (flat beyond its
/// data).
/// Residuals not `active` get `off_value` at every node.
fn fill_rows(
    keep: &[usize],
    mean: &[[f64; N]],
    w: &[[f64; N]],
    min_w: f64,
    frame_dt_s: f64,
    (active, off_value): ([bool; N], f64),
) -> Result<Vec<[f64; N]>, CalibrateError> {
    let mut rows: Vec<[f64; N]> = vec![[off_value; N]; keep.len()];
    for i in (0..N).filter(|&i| active[i]) {
        let own: Vec<usize> = (0..keep.len())
            .filter(|&k| w[keep[k]][i] >= min_w)
            .collect();
        if own.is_empty() {
            let most = w.iter().map(|r| r[i]).fold(0.0, f64::max) * frame_dt_s;
            let total: f64 = w.iter().map(|r| r[i]).sum::<f64>() * frame_dt_s;
            return Err(CalibrateError::Argument(format!(
                "test `{}`: tested for {total:.1} s in all and at most {most:.1} s at any load node of the offset map, {MIN_NODE_S} s needed at one; give longer or more fault-free logs (the tests wait for steady driving)",
                TEST_NAMES[i]
            )));
        }
        for (k, row) in rows.iter_mut().enumerate() {
            let near = own
                .iter()
                .copied()
                .min_by_key(|&o| o.abs_diff(k))
                .unwrap_or(k);
            row[i] = mean[keep[near]][i];
        }
    }
    Ok(rows)
}

/// The map from pass 1's samples: per residual, the log-centred residuals averaged at the
/// nodes, plus the mean over the logs. Returns the nodes kept (those where some residual has
/// [`MIN_NODE_S`] of data; the throttle residuals are not tested near full load), their
/// indices in [`MAP_NODES`], rows and tested time (s).
fn fit_map(c: &Collector) -> Result<FittedMap, CalibrateError> {
    let mut level = [0.0; N];
    let mut active = [true; N];
    for (i, l) in level.iter_mut().enumerate() {
        let (sum, n) = c
            .log_totals
            .iter()
            .fold((0.0, 0u64), |(s, n), t| (s + t[i].0, n + t[i].1));
        if n == 0 {
            if OPTIONAL[i] {
                active[i] = false;
                continue;
            }
            return Err(CalibrateError::NoData(TEST_NAMES[i]));
        }
        *l = sum / n as f64;
    }
    // Each log's residuals about its own mean `m`: at a node, sum(w (rel - m)) = S - m W.
    let mut centred = NodeSums::default();
    for (t, nodes) in c.log_totals.iter().zip(&c.log_nodes) {
        for i in (0..N).filter(|&i| t[i].1 > 0) {
            let m = t[i].0 / t[i].1 as f64;
            for j in 0..MAP_NODES.len() {
                centred.sum[j][i] += nodes.sum[j][i] - m * nodes.weight[j][i];
                centred.weight[j][i] += nodes.weight[j][i];
            }
        }
    }
    let (mean, w) = centred.means();
    let min_w = MIN_NODE_S / c.frame_dt_s;
    // An optional residual without a node of enough data is off too.
    for i in (0..N).filter(|&i| OPTIONAL[i]) {
        if !w.iter().any(|r| r[i] >= min_w) {
            active[i] = false;
        }
    }
    let keep: Vec<usize> = (0..MAP_NODES.len())
        .filter(|&j| (0..N).any(|i| active[i] && w[j][i] >= min_w))
        .collect();
    let mut rows = fill_rows(&keep, &mean, &w, min_w, c.frame_dt_s, (active, 0.0))?;
    for r in &mut rows {
        for i in 0..N {
            r[i] += level[i];
        }
    }
    let nodes = keep.iter().map(|&j| MAP_NODES[j]).collect();
    let node_s = keep
        .iter()
        .map(|&j| w[j].iter().copied().fold(0.0, f64::max) * c.frame_dt_s)
        .collect();
    Ok(FittedMap {
        nodes,
        keep,
        rows,
        node_s,
        active,
    })
}

/// The offset map of pass 1: the nodes kept, their indices in [`MAP_NODES`], the rows and the
/// tested time at each node (s).
struct FittedMap {
    nodes: Vec<f64>,
    keep: Vec<usize>,
    rows: Vec<[f64; N]>,
    node_s: Vec<f64>,
    /// Residuals with data (the others' tests are switched off, see [`OPTIONAL`]).
    active: [bool; N],
}

/// The maps written into a monitor file: nodes, offsets and scales (rows per node).
#[derive(Debug, Clone, Copy)]
struct Maps<'a> {
    nodes: &'a [f64],
    offsets: &'a [[f64; N]],
    scales: &'a [[f64; N]],
}

impl<'a> Maps<'a> {
    fn new(nodes: &'a [f64], offsets: &'a [[f64; N]], scales: &'a [[f64; N]]) -> Option<Self> {
        Some(Self {
            nodes,
            offsets,
            scales,
        })
    }
}

/// The monitor file's text with the `[monitor]` keys set: numbers, arrays of numbers and the
/// map (an array of rows).
fn with_keys(
    text: &str,
    origin: &str,
    numbers: &[(&str, f64)],
    flags: &[(&str, bool)],
    arrays: &[(&str, &[f64])],
    map: Option<Maps<'_>>,
    params: &str,
) -> Result<String, CalibrateError> {
    let mut doc = parse_doc(text, origin)?;
    doc["params"] = toml_edit::value(params);
    if doc.get("monitor").is_none() {
        doc["monitor"] = toml_edit::table();
    }
    for (k, v) in numbers {
        doc["monitor"][*k] = toml_edit::value(*v);
    }
    for (k, v) in flags {
        doc["monitor"][*k] = toml_edit::value(*v);
    }
    // Six decimals: far below any scale, and a file one reads.
    let array = |v: &[f64]| {
        let mut a = toml_edit::Array::new();
        for x in v {
            a.push((x * 1e6).round() / 1e6);
        }
        a
    };
    for (k, v) in arrays {
        doc["monitor"][*k] = toml_edit::value(array(v));
    }
    let rows = |rows: &[[f64; N]]| {
        let mut a = toml_edit::Array::new();
        for r in rows {
            a.push(array(r));
        }
        a
    };
    if let Some(m) = map {
        doc["monitor"]["offset_map_load"] = toml_edit::value(array(m.nodes));
        doc["monitor"]["offset_map"] = toml_edit::value(rows(m.offsets));
        doc["monitor"]["scale_map"] = toml_edit::value(rows(m.scales));
        for key in ["offset_map", "scale_map"] {
            if let Some(a) = doc["monitor"][key].as_array_mut() {
                // One row per line.
                for v in a.iter_mut() {
                    v.decor_mut().set_prefix("\n    ");
                }
                a.set_trailing("\n");
                a.set_trailing_comma(true);
            }
        }
    }
    Ok(doc.to_string())
}

/// The monitor file to start from and its parameter file's name and text.
fn start_files(base: &RuntimeConfig) -> Result<(String, String, String, String), CalibrateError> {
    let path = base.monitors.turbo_config.as_deref();
    let (text, origin) = monitor_text(
        path,
        DEFAULT_TURBO_MONITOR_TOML,
        "config/turbo_monitor.toml",
    )?;
    let doc = parse_doc(&text, &origin)?;
    let name = doc
        .get("params")
        .and_then(|p| p.as_str())
        .ok_or_else(|| CalibrateError::Toml {
            origin: origin.clone(),
            message: "`params`: expected the name of the model's parameter file".into(),
        })?
        .to_string();
    let params = match path {
        Some(p) => fdd_monitor::text_file::read_text(
            &p.parent().unwrap_or_else(|| Path::new(".")).join(&name),
        )?,
        None => fdd_monitor::turbo::config::DEFAULT_TURBO_PARAMS_TOML.to_string(),
    };
    // The parameter file goes beside the calibrated monitor file under its own base name.
    let file_name = Path::new(&name)
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "turbo_params.toml".into());
    Ok((text, origin, file_name, params))
}

/// Calibrates the air-path monitor of `base` on the fault-free logs `logs` (see the
/// [module documentation](self)).
pub fn calibrate(
    logs: Vec<PathBuf>,
    base: &RuntimeConfig,
    opts: &CalibrateOptions,
) -> Result<TurboCalibration, CalibrateError> {
    let (text, origin, params_name, params_toml) = start_files(base)?;
    let work = tempfile::tempdir().map_err(crate::evaluate::EvaluateError::Temp)?;
    std::fs::write(work.path().join(&params_name), &params_toml).map_err(|source| {
        CalibrateError::Write {
            file: work.path().join(&params_name),
            source,
        }
    })?;
    let start = TurboConfig::parse(&text, &origin, &params_toml, &params_name)?.monitor;
    // Frames are the sensors' samples; the monitor's frame period is not a setting: the
    // LiU-ICE logs and the simulator write 20 Hz (a node's weight is counted in frames).
    let frame_dt_s = 0.05;
    let unreachable = [UNREACHABLE_CUSUM; N];

    let neutral = [PASS_SCALE; N];
    // Pass 1: the map (every test on, to see which the logs reach).
    let pass1 = with_keys(
        &text,
        &origin,
        &[("adapt_limit", WIDE_ADAPT_LIMIT)],
        &[(SHAFT_KEY, true)],
        &[(THRESHOLD_KEY, &unreachable), ("residual_scale", &neutral)],
        Maps::new(&[], &[], &[]),
        &params_name,
    )?;
    let cfg = runtime_with_only(base, work.path(), &pass1, Only::Turbo)?;
    let c = pass(&logs, &cfg, opts.block_s, frame_dt_s)?;
    let FittedMap {
        nodes: map_load,
        keep,
        rows: map,
        node_s,
        active,
    } = fit_map(&c)?;
    drop(c);
    let flags = [(SHAFT_KEY, active[R_BOOST])];

    // Pass 2: scales and the offsets' range with the map.
    let pass2 = with_keys(
        &text,
        &origin,
        &[("adapt_limit", WIDE_ADAPT_LIMIT)],
        &flags,
        &[(THRESHOLD_KEY, &unreachable), ("residual_scale", &neutral)],
        Maps::new(&map_load, &map, &[]),
        &params_name,
    )?;
    let cfg = runtime_with_only(base, work.path(), &pass2, Only::Turbo)?;
    let c = pass(&logs, &cfg, opts.block_s, frame_dt_s)?;
    let mut scales = [PASS_SCALE; N];
    for i in (0..N).filter(|&i| active[i]) {
        if c.dev_n[i] < 100 {
            return Err(CalibrateError::NoData(TEST_NAMES[i]));
        }
        scales[i] = (c.dev_sq[i] / c.dev_n[i] as f64).sqrt();
    }
    let (ms, w) = c.dev_nodes.means();
    let scale_map: Vec<[f64; N]> = fill_rows(
        &keep,
        &ms,
        &w,
        MIN_NODE_S / frame_dt_s,
        frame_dt_s,
        (active, PASS_SCALE * PASS_SCALE),
    )?
    .into_iter()
    .map(|r| r.map(f64::sqrt))
    .collect();
    let largest_offset = c.largest_offset;
    let adapt_limit = (ADAPT_MARGIN * largest_offset)
        .max(start.adapt_limit)
        .min(WIDE_ADAPT_LIMIT);
    drop(c);

    // Pass 3: the thresholds with map, scales and range.
    let numbers = [("adapt_limit", adapt_limit)];
    let pass3 = with_keys(
        &text,
        &origin,
        &numbers,
        &flags,
        &[(THRESHOLD_KEY, &unreachable), ("residual_scale", &scales)],
        Maps::new(&map_load, &map, &scale_map),
        &params_name,
    )?;
    let cfg = runtime_with_only(base, work.path(), &pass3, Only::Turbo)?;
    let c = pass(&logs, &cfg, opts.block_s, frame_dt_s)?;
    let hours = c.total_ns as f64 * 1e-9 / 3600.0;
    let mut tests = Vec::new();
    for (i, name) in TEST_NAMES.iter().enumerate() {
        let blocks = c.maxima[i].len();
        if !active[i] {
            tests.push(TurboThreshold {
                test: name,
                active: false,
                blocks,
                rose: 0,
                max: 0.0,
                at: None,
                threshold: UNREACHABLE_CUSUM,
            });
            continue;
        }
        if blocks < MIN_BLOCKS {
            return Err(CalibrateError::Argument(format!(
                "test `{name}`: tested in {blocks} blocks of {} s, at least {MIN_BLOCKS} are needed; give longer or more logs (steady driving: the tests wait for the pressures and the charge-air temperature to settle)",
                opts.block_s
            )));
        }
        let (max, log, t_s) = c.maxima[i]
            .iter()
            .copied()
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap_or((0.0, 0, 0.0));
        let rose = c.maxima[i].iter().filter(|m| m.0 > 0.0).count();
        tests.push(TurboThreshold {
            test: name,
            active: true,
            blocks,
            rose,
            max,
            at: logs.get(log).cloned().map(|f| (f, t_s)),
            threshold: (THRESHOLD_MARGIN * max).max(THRESHOLD_FLOOR),
        });
    }
    let thresholds: Vec<f64> = tests.iter().map(|t| t.threshold).collect();
    let turbo_toml = with_keys(
        &text,
        &origin,
        &numbers,
        &flags,
        &[(THRESHOLD_KEY, &thresholds), ("residual_scale", &scales)],
        Maps::new(&map_load, &map, &scale_map),
        &params_name,
    )?;
    // The configuration written must build a monitor.
    let cfg = runtime_with_only(base, work.path(), &turbo_toml, Only::Turbo)?;
    Runtime::new(&cfg).map_err(|e| CalibrateError::Toml {
        origin: "the calibrated turbo.toml".into(),
        message: e.to_string(),
    })?;
    let runtime_toml = runtime_naming(base, "turbo_config", "turbo.toml")?;
    Ok(TurboCalibration {
        logs,
        hours,
        map_load,
        map,
        scale_map,
        node_s,
        scales,
        largest_offset,
        adapt_limit,
        tests,
        turbo_toml,
        params_name,
        params_toml,
        runtime_toml,
    })
}

impl TurboCalibration {
    /// The report `fdd calibrate` prints (after the common header).
    pub fn render_body(&self, s: &mut String) {
        use std::fmt::Write as _;
        let _ = writeln!(
            s,
            "offset map (relative residuals {} at p_im/p_amb; s of data):",
            fdd_monitor::turbo::RESIDUALS.join(", ")
        );
        let row = |r: &[f64; N], sign: bool| {
            r.iter()
                .map(|v| {
                    if sign {
                        format!("{v:+.4}")
                    } else {
                        format!("{v:.4}")
                    }
                })
                .collect::<Vec<_>>()
                .join(" ")
        };
        for (((x, r), q), w) in self
            .map_load
            .iter()
            .zip(&self.map)
            .zip(&self.scale_map)
            .zip(&self.node_s)
        {
            let _ = writeln!(
                s,
                "  {x:>4.2}  {}   scales {}  ({w:.0} s)",
                row(r, true),
                row(q, false)
            );
        }
        let _ = writeln!(
            s,
            "scales {} (std of the tested deviations); largest learned offset {:.4}, adapt_limit {:.3}",
            row(&self.scales, false),
            self.largest_offset,
            self.adapt_limit
        );
        let _ = writeln!(
            s,
            "thresholds: {THRESHOLD_MARGIN} x the largest fault-free value, at least {THRESHOLD_FLOOR} (the CUSUMs' reference is half the design shift: most blocks end at 0, and no extreme-value law describes the few that rise)"
        );
        let _ = writeln!(
            s,
            "{:<24} {:>6} {:>6} {:>10} {:>10}   largest in",
            "test", "blocks", "rose", "max seen", "threshold"
        );
        for t in self.tests.iter().filter(|t| !t.active) {
            let _ = writeln!(
                s,
                "{:<24} off: never tested in the logs (shaft_test = false)",
                t.test
            );
        }
        for t in self.tests.iter().filter(|t| t.active) {
            let at = t.at.as_ref().map_or(String::from("-"), |(f, ts)| {
                format!("{} at {ts:.1} s", f.display())
            });
            let _ = writeln!(
                s,
                "{:<24} {:>6} {:>6} {:>10.3} {:>10.3}   {at}",
                t.test, t.blocks, t.rose, t.max, t.threshold
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_weights_interpolate_and_sum_to_one() {
        for load in [0.0, 0.2, 0.25, 0.55, 0.99, 1.0, 1.3, 1.7, 3.0] {
            let w = node_weights(load);
            assert!((w[0].1 + w[1].1 - 1.0).abs() < 1e-12, "{load}: {w:?}");
            if (MAP_NODES[0]..MAP_NODES[MAP_NODES.len() - 1]).contains(&load) {
                // The weighted node position is the load itself.
                let x = w[0].1 * MAP_NODES[w[0].0] + w[1].1 * MAP_NODES[w[1].0];
                assert!((x - load).abs() < 1e-12, "{load}: {w:?}");
            }
        }
    }

    #[test]
    fn the_map_recovers_a_load_shape_under_per_log_offsets() {
        // Two logs with different offsets (what the learned offsets take up) over the same
        // loads; the residual falls linearly with the load on both.
        let shape = |load: f64| 0.04 - 0.05 * load;
        let mut c = Collector::new(10.0, 0.05);
        for off in [0.02, -0.01] {
            c.start_log();
            for k in 0..4000 {
                let l = 0.3 + 0.6 * (k as f64 / 3999.0);
                // Deviation and learned offset as the monitor reports them: their sum is rel.
                for i in 0..N {
                    c.add(i, shape(l), off, l);
                }
            }
        }
        let FittedMap {
            nodes,
            keep,
            rows,
            node_s,
            active,
        } = fit_map(&c).expect("map");
        // Every residual had data, the optional one too.
        assert_eq!(active, [true; N]);
        assert_eq!(nodes.len(), keep.len());
        assert!(nodes.iter().all(|&x| (0.3..=0.9).contains(&x)), "{nodes:?}");
        assert!(node_s.iter().all(|&s| s >= MIN_NODE_S), "{node_s:?}");
        // The map's slope is the shape's; its level is the mean over the logs.
        let level = 0.5 * (0.02 - 0.01);
        for (x, r) in nodes.iter().zip(&rows) {
            let want = shape(*x) + level;
            // Triangular averaging biases the end nodes by up to half a cell of slope.
            let tol = if *x == nodes[0] || *x == nodes[nodes.len() - 1] {
                3e-3
            } else {
                1e-3
            };
            for v in r {
                assert!((v - want).abs() < tol, "node {x}: {r:?} vs {want}");
            }
        }
    }

    #[test]
    fn rows_without_data_take_the_nearest_nodes_value() {
        let mean = vec![
            [1.0, 10.0, 100.0, 7.0],
            [2.0, f64::NAN, 200.0, 8.0],
            [3.0, f64::NAN, 300.0, 9.0],
        ];
        let w = vec![
            [50.0, 50.0, 50.0, 50.0],
            [50.0, 0.0, 50.0, 50.0],
            [50.0, 1.0, 50.0, 50.0],
        ];
        let all = ([true; N], f64::NAN);
        let rows = fill_rows(&[0, 1, 2], &mean, &w, 10.0, 0.05, all).expect("rows");
        assert_eq!(
            rows,
            vec![
                [1.0, 10.0, 100.0, 7.0],
                [2.0, 10.0, 200.0, 8.0],
                [3.0, 10.0, 300.0, 9.0]
            ]
        );
        // A residual with no node of enough data is refused, naming its test.
        let w = vec![[50.0, 1.0, 50.0, 50.0]; 3];
        let e = fill_rows(&[0, 1, 2], &mean, &w, 10.0, 0.05, all)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("turbo_throttle_flow") && e.contains("0.2 s in all"),
            "{e}"
        );
        // A residual switched off (the boost residual of logs that never reach it) is not
        // refused: it takes the given value at every node.
        let off = ([true, false, true, true], 0.25);
        let rows = fill_rows(&[0, 1, 2], &mean, &w, 10.0, 0.05, off).expect("rows");
        assert!(rows.iter().all(|r| r[1] == 0.25), "{rows:?}");
        assert_eq!(rows[2], [3.0, 0.25, 300.0, 9.0]);
    }

    #[test]
    fn the_written_file_carries_the_maps_and_reloads() {
        let text = fdd_monitor::turbo::config::DEFAULT_TURBO_MONITOR_TOML;
        let out = with_keys(
            text,
            "t.toml",
            &[("adapt_limit", 0.2)],
            &[("shaft_test", false)],
            &[("cusum_threshold", &[10.0, 20.0, 30.0, 40.0])],
            Maps::new(
                &[0.3, 0.6],
                &[[0.01, -0.02, 0.03, 0.04]; 2],
                &[[0.005, 0.002, 0.004, 0.006]; 2],
            ),
            "p.toml",
        )
        .expect("edited");
        let c = TurboConfig::parse(
            &out,
            "t.toml",
            fdd_monitor::turbo::config::DEFAULT_TURBO_PARAMS_TOML,
            "p.toml",
        )
        .expect("parses");
        assert_eq!(c.monitor.offset_map_load, vec![0.3, 0.6]);
        assert_eq!(c.monitor.offset_map, vec![[0.01, -0.02, 0.03, 0.04]; 2]);
        assert_eq!(c.monitor.scale_map, vec![[0.005, 0.002, 0.004, 0.006]; 2]);
        assert_eq!(c.monitor.cusum_threshold, [10.0, 20.0, 30.0, 40.0]);
        assert_eq!(c.monitor.adapt_limit, 0.2);
        assert!(!c.monitor.shaft_test);
        assert!(out.contains("params = \"p.toml\""), "{out}");
    }
}
