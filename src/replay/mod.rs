//! `fdd replay`: runs the configured monitors over a recorded MCAP log.
//!
//! # What it does
//!
//! - Streams the log with [`LogReader::next_message`] (borrowed messages, one chunk in memory
//!   at a time; never the whole file), in log-time order, or in file order when the file has no
//!   usable index (then every signal's times are checked).
//! - Maps topics and fields to runtime signals as configured ([`RuntimeConfig`]): each channel
//!   is resolved once, on first sight, to the signals it feeds (a channel nobody maps is
//!   counted as ignored); a message then costs one field lookup per mapped signal.
//! - Before applying a sample stamped `t` it runs every monitor step due before `t`
//!   ([`Scheduler::run_until`]), then stores the sample in the [`SignalTable`]. An operation
//!   cycle starts at the first message and ends after the last one (steps run up to the last
//!   time + 1 ns). A forward jump of the log time larger than `replay.max_gap_s` ends the cycle
//!   and starts a new one, rather than stepping every monitor through the pause.
//! - Monitors come from [`build_monitors`]: the [`StalenessMonitor`] ("no signal" events,
//!   FTB 0x31), and the subsystem monitors enabled in `[monitors]`.
//! - Outputs go to the sinks ([`ReplayOptions`]): `--events` (one `DiagnosticEvent` JSON per
//!   line), `--out` (an MCAP with the fdd output topics). Without them no output is serialized.
//! - Ends with a [`ReplaySummary`].
//!
//! # Bad input
//!
//! | input | what happens |
//! |---|---|
//! | file missing, not MCAP, unreadable header | [`ReplayError`] naming the file, nothing processed |
//! | truncated or corrupt file (fatal [`LogError`]) | everything readable before it is processed, the outputs are finished, and the summary carries the error in `stopped_early` (`fdd replay` exits non-zero) |
//! | unreadable chunk, chunk CRC mismatch, unknown channel id | counted (kind, topic, first time), reading goes on |
//! | invalid JSON, mapped field missing or not a number | counted per topic, the sample is dropped |
//! | NaN / infinite value (`null`), timestamp repeated or going backwards | refused by the signal table, counted per topic |
//! | a configured signal's topic absent | the signal is missing: its "no signal" event fails after `max_age_s` and the summary says so |
//! | log time jumping by more than `replay.max_gap_s` | counted; a new operation cycle starts |
//!
//! The first [`problems::LOGGED_PER_KIND`] occurrences of each problem are logged at `warn`
//! with file, topic and time.

pub mod config;
pub mod problems;
mod sinks;
pub mod staleness;
pub mod summary;
mod truth;

use std::cell::{Cell, RefCell};
use std::fs::File;
use std::io::{BufWriter, IsTerminal};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::Arc;
use std::time::Instant;

use fdd_monitor::log::{
    ChannelInfo, LogError, LogMessage, LogReader, LogWriter, ReadMode, WriteOptions,
};
use fdd_monitor::monitor::{Monitor, OutputSink};
use fdd_monitor::scheduler::Scheduler;
use fdd_monitor::signal_table::{SignalId, SignalTable};
use indicatif::{ProgressBar, ProgressStyle};

pub use config::RuntimeConfig;
pub use problems::{Problem, ProblemKind};
pub use sinks::{
    DtcRecord, FaultOnset, DTC_STATUS_TOPIC, EVENTS_TOPIC, INNOVATION_TOPIC, POSITION_TOPIC,
    TESTS_TOPIC,
};
pub use staleness::StalenessMonitor;
pub use summary::ReplaySummary;

use config::s_to_ns;
use problems::Problems;
use sinks::Sinks;
use summary::{
    ErrorStats, EstimateError, MonitorSummary, SignalSummary, TopicSummary, TruthSummary,
};

/// Why a replay could not run (or its outputs could not be written).
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// Reading the log or writing the output MCAP.
    #[error(transparent)]
    Log(#[from] LogError),
    #[error("{}: cannot write the events file: {source}", file.display())]
    Events {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("monitor `{monitor}`: {message}")]
    Monitor { monitor: String, message: String },
    #[error("{}: refusing to write --{option} over the input log", file.display())]
    OutputIsInput { file: PathBuf, option: &'static str },
}

/// Where the outputs go.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReplayOptions {
    /// `--out`: MCAP file of the monitor outputs.
    pub out: Option<PathBuf>,
    /// `--events`: JSON-lines file of the DiagnosticEvents.
    pub events: Option<PathBuf>,
    /// Show a progress bar (only drawn when stderr is a terminal).
    pub progress: bool,
}

/// The monitors the configuration asks for, reading `table`.
///
/// `log_has_topic` says whether the log carries a topic, when that is known before reading
/// (an indexed file): a subsystem monitor none of whose input topics is in the log does not run
/// (a throttle log replayed with the intake monitor enabled raises no intake "no signal"
/// DTCs), and the staleness monitor does not watch its signals. Such monitors are returned in
/// the second list with the reason. With `None`, or when the log carries no monitor's topics
/// at all (a wrong mapping, rather than a log of another subsystem), every enabled monitor
/// runs.
#[allow(clippy::type_complexity)]
pub fn build_monitors(
    cfg: &RuntimeConfig,
    table: &SignalTable,
    log_has_topic: Option<&dyn Fn(&str) -> bool>,
) -> Result<(Vec<Box<dyn Monitor>>, Vec<(String, String)>), ReplayError> {
    let mut subsystems: Vec<Box<dyn Monitor>> = Vec::new();
    if cfg.monitors.throttle {
        subsystems.push(Box::new(throttle_monitor(cfg, table)?));
    }
    if cfg.monitors.intake {
        subsystems.push(Box::new(intake_monitor(cfg, table)?));
    }
    let mut skipped = Vec::new();
    let mut skip_signals = Vec::new();
    let mut monitors: Vec<Box<dyn Monitor>> = Vec::new();
    let present: Vec<bool> = subsystems
        .iter()
        .map(|m| match log_has_topic {
            None => true,
            Some(has) => m.inputs().iter().any(|&id| {
                let name = &table.spec(id).name;
                cfg.signals.iter().any(|s| s.name == *name && has(&s.topic))
            }),
        })
        .collect();
    // A log that carries no monitor's topics at all is more likely mapped wrongly than meant
    // for none of them: then every monitor runs and reports its signals missing.
    let none_present = !present.iter().any(|&p| p);
    for (m, present) in subsystems.into_iter().zip(present) {
        let names: Vec<String> = m
            .inputs()
            .iter()
            .map(|&id| table.spec(id).name.clone())
            .collect();
        if present || none_present {
            monitors.push(m);
        } else {
            let topics: Vec<&str> = cfg
                .signals
                .iter()
                .filter(|s| names.contains(&s.name))
                .map(|s| s.topic.as_str())
                .collect();
            skipped.push((
                m.name().to_string(),
                format!("the log has none of its topics ({})", topics.join(", ")),
            ));
            skip_signals.extend(names);
        }
    }
    // A signal another running monitor reads stays watched.
    skip_signals.retain(|n| {
        !monitors
            .iter()
            .any(|m| m.inputs().iter().any(|&id| table.spec(id).name == *n))
    });
    monitors.insert(
        0,
        Box::new(StalenessMonitor::from_config(cfg, table, &skip_signals)?),
    );
    for m in &monitors {
        if m.period_ns() == 0 {
            return Err(ReplayError::Monitor {
                monitor: m.name().to_string(),
                message: "period of 0 ns".into(),
            });
        }
    }
    Ok((monitors, skipped))
}

fn throttle_monitor(
    cfg: &RuntimeConfig,
    table: &SignalTable,
) -> Result<fdd_monitor::throttle::ThrottleMonitor, ReplayError> {
    let throttle = crate::config::ThrottleConfig::load(cfg.monitors.throttle_config.as_deref())?;
    let err = |message: String| ReplayError::Monitor {
        monitor: "throttle".into(),
        message,
    };
    let model =
        fdd_estimators::models::throttle::ThrottleModel::new(throttle.model).map_err(err)?;
    let monitor = fdd_monitor::throttle::ThrottleMonitor::new(
        model,
        throttle.position_sensor.full_scale_v,
        throttle.position_sensor.full_scale_deg,
        &throttle.monitor,
        table,
    )
    .map_err(|e| err(e.to_string()))?;
    tracing::info!(
        config = cfg
            .monitors
            .throttle_config
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "embedded config/throttle.toml".into()),
        "throttle monitor configured"
    );
    Ok(monitor)
}

fn intake_monitor(
    cfg: &RuntimeConfig,
    table: &SignalTable,
) -> Result<fdd_monitor::intake::IntakeMonitor, ReplayError> {
    let intake = crate::config::IntakeConfig::load(cfg.monitors.intake_config.as_deref())?;
    let err = |message: String| ReplayError::Monitor {
        monitor: "intake".into(),
        message,
    };
    let model = fdd_estimators::models::intake::IntakeModel::new(
        intake.model,
        fdd_estimators::models::intake::ThrottleFlow::RandomWalk,
    )
    .map_err(err)?;
    let monitor = fdd_monitor::intake::IntakeMonitor::new(&model, &intake.monitor, table)
        .map_err(|e| err(e.to_string()))?;
    tracing::info!(
        config = cfg
            .monitors
            .intake_config
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "embedded config/intake.toml".into()),
        "intake monitor configured"
    );
    Ok(monitor)
}

type SharedMonitor = Rc<RefCell<Box<dyn Monitor>>>;

/// Runs a shared monitor and tells the sinks the time of each call ([`fdd_monitor::monitor::Output`]
/// carries no time). Shared so that a new scheduler can take the monitors over after a gap.
struct Timed {
    inner: SharedMonitor,
    clock: Rc<Cell<u64>>,
    name: String,
    period_ns: u64,
    inputs: Vec<SignalId>,
}

impl Monitor for Timed {
    fn name(&self) -> &str {
        &self.name
    }
    fn period_ns(&self) -> u64 {
        self.period_ns
    }
    fn inputs(&self) -> &[SignalId] {
        &self.inputs
    }
    fn step(&mut self, now_ns: u64, signals: &SignalTable, out: &mut OutputSink<'_>) {
        self.clock.set(now_ns);
        self.inner.borrow_mut().step(now_ns, signals, out);
    }
    fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.clock.set(now_ns);
        self.inner.borrow_mut().start_operation_cycle(now_ns, out);
    }
    fn end_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.clock.set(now_ns);
        self.inner.borrow_mut().end_operation_cycle(now_ns, out);
    }
}

/// A channel, resolved on first sight.
struct Channel {
    topic: Arc<str>,
    messages: u64,
    /// Indices into `cfg.signals` of the signals this channel feeds.
    signals: Vec<usize>,
    /// Index into `cfg.truth` when this is a truth topic.
    truth: Option<usize>,
}

#[derive(Default, Clone, Copy)]
struct SignalStats {
    samples: u64,
    rejected: u64,
}

/// Messages between progress-bar updates.
const PROGRESS_EVERY: u64 = 1 << 14;

struct Replayer<'c> {
    cfg: &'c RuntimeConfig,
    file: PathBuf,
    table: SignalTable,
    sig_ids: Vec<SignalId>,
    monitors: Vec<SharedMonitor>,
    clock: Rc<Cell<u64>>,
    scheduler: Option<Scheduler>,
    steps: Vec<u64>,
    sinks: Sinks,
    channels: Vec<Option<Channel>>,
    sig: Vec<SignalStats>,
    problems: Problems,
    max_gap_ns: u64,
    first_ns: Option<u64>,
    latest_ns: u64,
    prev_ns: Option<u64>,
    messages: u64,
    frames: u64,
    cycles: u32,
    truth_messages: u64,
    truth_active: bool,
    /// Time of the previous message of each truth topic, ns.
    truth_prev_ns: Vec<Option<u64>>,
}

impl Replayer<'_> {
    fn start_cycle(&mut self, t_ns: u64) {
        let mut sched = Scheduler::new(t_ns);
        for m in &self.monitors {
            let (name, period_ns, inputs) = {
                let b = m.borrow();
                (b.name().to_string(), b.period_ns(), b.inputs().to_vec())
            };
            // build_monitors refused zero periods, so adding cannot fail.
            if let Err(e) = sched.add(Box::new(Timed {
                inner: m.clone(),
                clock: self.clock.clone(),
                name,
                period_ns,
                inputs,
            })) {
                tracing::error!("{e}");
            }
        }
        self.cycles += 1;
        tracing::info!(
            "operation cycle {} starts at {:.6} s",
            self.cycles,
            t_ns as f64 * 1e-9
        );
        let sinks = &mut self.sinks;
        self.clock.set(t_ns);
        sched.start_operation_cycle(t_ns, &mut |o| sinks.on_output(o));
        self.scheduler = Some(sched);
    }

    /// Runs the steps up to the latest time and ends the cycle 1 ns after it.
    fn end_cycle(&mut self) {
        let Some(mut sched) = self.scheduler.take() else {
            return;
        };
        let end = self.latest_ns.saturating_add(1);
        let Self { table, sinks, .. } = self;
        sched.run_until(end, table, &mut |o| sinks.on_output(o));
        self.clock.set(end);
        sched.end_operation_cycle(end, &mut |o| sinks.on_output(o));
        for (k, (_, n)) in sched.step_counts().enumerate() {
            self.steps[k] += n;
        }
        tracing::info!(
            "operation cycle {} ends at {:.6} s",
            self.cycles,
            end as f64 * 1e-9
        );
    }

    /// Moves time to `t_ns` before a sample stamped `t_ns` is applied.
    fn advance(&mut self, t_ns: u64, topic: &str) {
        if self.first_ns.is_none() {
            self.first_ns = Some(t_ns);
            self.latest_ns = t_ns;
            self.start_cycle(t_ns);
            return;
        }
        if t_ns <= self.latest_ns {
            return;
        }
        if t_ns - self.latest_ns > self.max_gap_ns {
            let (from, file) = (self.latest_ns, &self.file);
            self.problems
                .record(ProblemKind::TimeGap, Some(topic), Some(t_ns), || {
                    format!(
                        "{}: {topic} at {t_ns} ns ({:.6} s): log time jumps {:.3} s forward from {:.6} s (more than replay.max_gap_s = {} s): the operation cycle ends and a new one starts",
                        file.display(),
                        t_ns as f64 * 1e-9,
                        (t_ns - from) as f64 * 1e-9,
                        from as f64 * 1e-9,
                        self.cfg.replay.max_gap_s
                    )
                });
            self.end_cycle();
            self.latest_ns = t_ns;
            self.start_cycle(t_ns);
            return;
        }
        let Self {
            scheduler,
            table,
            sinks,
            ..
        } = self;
        if let Some(s) = scheduler.as_mut() {
            s.run_until(t_ns, table, &mut |o| sinks.on_output(o));
        }
        self.latest_ns = t_ns;
    }

    fn resolve(cfg: &RuntimeConfig, ch: &ChannelInfo) -> Channel {
        let signals: Vec<usize> = cfg
            .signals
            .iter()
            .enumerate()
            .filter(|(_, s)| *s.topic == *ch.topic)
            .map(|(i, _)| i)
            .collect();
        let truth = cfg.truth.iter().position(|t| *t.topic == *ch.topic);
        tracing::debug!(
            channel = ch.id,
            topic = %ch.topic,
            "channel {} {}: {}",
            ch.id,
            ch.topic,
            if signals.is_empty() && truth.is_none() {
                "ignored (not mapped)".to_string()
            } else {
                let mut v: Vec<String> = signals
                    .iter()
                    .map(|&i| format!("signal {}", cfg.signals[i].name))
                    .collect();
                if truth.is_some() {
                    v.push("ground truth".into());
                }
                v.join(", ")
            }
        );
        Channel {
            topic: ch.topic.clone(),
            messages: 0,
            signals,
            truth,
        }
    }

    fn handle(&mut self, msg: &LogMessage<'_>) {
        let t = msg.log_time_ns;
        self.messages += 1;
        if self.prev_ns != Some(t) {
            self.frames += 1;
            self.prev_ns = Some(t);
        }
        self.advance(t, msg.topic);

        let ci = usize::from(msg.channel.id);
        if ci >= self.channels.len() {
            self.channels.resize_with(ci + 1, || None);
        }
        let Self {
            cfg,
            file,
            table,
            sig_ids,
            sinks,
            channels,
            sig,
            problems,
            truth_messages,
            truth_active,
            truth_prev_ns,
            ..
        } = self;
        let ch = channels[ci].get_or_insert_with(|| Self::resolve(cfg, msg.channel));
        ch.messages += 1;
        for &i in &ch.signals {
            let s = &cfg.signals[i];
            let v = match msg.field_f64(&s.field) {
                Ok(v) => v,
                Err(e) => {
                    sig[i].rejected += 1;
                    problems.record_log_error(&e);
                    continue;
                }
            };
            match table.set(sig_ids[i], t, v) {
                Ok(()) => sig[i].samples += 1,
                Err(e) => {
                    sig[i].rejected += 1;
                    problems.record(
                        ProblemKind::of_sample_error(&e),
                        Some(msg.topic),
                        Some(t),
                        || {
                            format!(
                                "{}: {} at {t} ns ({:.6} s): signal `{}` (field '{}'): sample {v} refused: {e}",
                                file.display(),
                                msg.topic,
                                t as f64 * 1e-9,
                                s.name,
                                s.field
                            )
                        },
                    );
                }
            }
        }
        if let Some(ti) = ch.truth {
            *truth_messages += 1;
            let field = &cfg.truth[ti].field;
            match truth::parse_truth(msg.data, field) {
                Ok(tm) => {
                    // A null (NaN) or missing true value only disables the comparison; a dotted
                    // field path is looked up the general way.
                    sinks.truths[ti].value = if field.contains('.') {
                        msg.field_f64(field).unwrap_or(f64::NAN)
                    } else {
                        tm.value
                    };
                    if tm.fault_active && !*truth_active {
                        sinks.fault_onset(&tm.fault, t);
                    }
                    *truth_active = tm.fault_active;
                    if let (Some(obs), Some(prev)) = (tm.fault_observable, truth_prev_ns[ti]) {
                        sinks.fault_observable(obs && tm.fault_active, t.saturating_sub(prev));
                    }
                    truth_prev_ns[ti] = Some(t);
                }
                Err(e) => {
                    problems.record(ProblemKind::WrongShape, Some(msg.topic), Some(t), || {
                        format!(
                            "{}: {} at {t} ns: unreadable ground-truth message (fields `fault`, `fault_active`): {e}",
                            file.display(),
                            msg.topic
                        )
                    })
                }
            }
        }
    }
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

fn progress_bar(reader: &LogReader, enabled: bool) -> (ProgressBar, Option<u64>) {
    if !enabled || !std::io::stderr().is_terminal() {
        return (ProgressBar::hidden(), None);
    }
    match reader.time_range_ns() {
        Some((a, b)) => {
            let pb = ProgressBar::new(((b - a) / 1_000_000).max(1));
            if let Ok(style) = ProgressStyle::with_template(
                "{wide_bar} {percent:>3}% of the log time [{elapsed_precise}, eta {eta}]",
            ) {
                pb.set_style(style);
            }
            (pb, Some(a))
        }
        None => {
            let pb = ProgressBar::new_spinner();
            if let Ok(style) =
                ProgressStyle::with_template("{spinner} {pos} messages [{elapsed_precise}]")
            {
                pb.set_style(style);
            }
            (pb, None)
        }
    }
}

/// Replays `log` with `cfg`. See the [module documentation](self).
///
/// `Err` when the log cannot be opened (or not a single message can be read), or an output
/// cannot be created. A fatal error after some messages is reported in
/// [`ReplaySummary::stopped_early`], with everything before it processed and the outputs
/// finished.
pub fn replay(
    log: &Path,
    cfg: &RuntimeConfig,
    opts: &ReplayOptions,
) -> Result<ReplaySummary, ReplayError> {
    let started = Instant::now();
    let mut reader = LogReader::open(log)?;
    let file = reader.file().to_path_buf();
    let read_mode = reader.mode();

    for (path, option) in [(&opts.out, "out"), (&opts.events, "events")] {
        if let Some(p) = path {
            if same_file(p, log) {
                return Err(ReplayError::OutputIsInput {
                    file: p.clone(),
                    option,
                });
            }
        }
    }

    let table = cfg.signal_table()?;
    let sig_ids = cfg
        .signals
        .iter()
        .map(|s| {
            table.id(&s.name).ok_or_else(|| ReplayError::Monitor {
                monitor: "signal table".into(),
                message: format!("signal `{}` not declared", s.name),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let known_topics = (read_mode == ReadMode::Indexed).then(|| {
        reader
            .channels()
            .map(|c| c.topic.to_string())
            .collect::<Vec<String>>()
    });
    let has_topic = |t: &str| {
        known_topics
            .as_ref()
            .is_some_and(|k| k.iter().any(|x| x == t))
    };
    let (monitors, skipped) = build_monitors(
        cfg,
        &table,
        known_topics
            .is_some()
            .then_some(&has_topic as &dyn Fn(&str) -> bool),
    )?;
    // The staleness monitor (first) watches exactly the signals of the monitors that run.
    let watched: Vec<SignalId> = monitors
        .first()
        .map(|m| m.inputs().to_vec())
        .unwrap_or_default();
    for (name, reason) in &skipped {
        tracing::info!(
            "monitor `{name}` does not run on {}: {reason}",
            file.display()
        );
    }
    for m in &monitors {
        tracing::info!(
            monitor = m.name(),
            "monitor `{}` started: period {} ms, {} inputs",
            m.name(),
            m.period_ns() as f64 * 1e-6,
            m.inputs().len()
        );
    }
    let monitors_unavailable: Vec<String> = cfg
        .monitors
        .enabled()
        .into_iter()
        .filter(|name| !monitors.iter().any(|m| m.name() == *name))
        .map(str::to_string)
        .collect();
    for m in &monitors_unavailable {
        tracing::info!(
            "monitor `{m}` is enabled in {} but not part of this build: skipped",
            cfg.origin
        );
    }
    if read_mode == ReadMode::Indexed {
        for s in &cfg.signals {
            if reader.channel(&s.topic).is_none() {
                tracing::warn!(
                    "{}: the log has no topic {}: signal `{}` will be missing",
                    file.display(),
                    s.topic,
                    s.name
                );
            }
        }
    }

    let events_file = match &opts.events {
        None => None,
        Some(p) => {
            let f = File::create(p).map_err(|source| ReplayError::Events {
                file: p.clone(),
                source,
            })?;
            Some((p.clone(), BufWriter::with_capacity(1 << 16, f)))
        }
    };
    let out = match &opts.out {
        None => None,
        Some(p) => Some(LogWriter::create_with(p, WriteOptions::default())?),
    };
    let clock = Rc::new(Cell::new(0));
    let sinks = Sinks::new(clock.clone(), events_file, out, &cfg.truth);

    let n_monitors = monitors.len();
    let mut r = Replayer {
        cfg,
        file: file.clone(),
        sig: vec![SignalStats::default(); cfg.signals.len()],
        table,
        sig_ids,
        monitors: monitors
            .into_iter()
            .map(|m| Rc::new(RefCell::new(m)))
            .collect(),
        clock,
        scheduler: None,
        steps: vec![0; n_monitors],
        sinks,
        channels: Vec::new(),
        problems: Problems::default(),
        max_gap_ns: s_to_ns(cfg.replay.max_gap_s),
        first_ns: None,
        latest_ns: 0,
        prev_ns: None,
        messages: 0,
        frames: 0,
        cycles: 0,
        truth_messages: 0,
        truth_active: false,
        truth_prev_ns: vec![None; cfg.truth.len()],
    };

    let (pb, pb_start) = progress_bar(&reader, opts.progress);
    let mut fatal: Option<ReplayError> = None;
    while let Some(item) = reader.next_message() {
        match item {
            Ok(msg) => r.handle(&msg),
            Err(e) if e.is_fatal() => {
                fatal = Some(e.into());
                break;
            }
            Err(e) => r.problems.record_log_error(&e),
        }
        if let Some(e) = r.sinks.error.take() {
            fatal = Some(e);
            break;
        }
        if r.messages % PROGRESS_EVERY == 0 {
            match pb_start {
                Some(a) => pb.set_position(r.latest_ns.saturating_sub(a) / 1_000_000),
                None => pb.set_position(r.messages),
            }
        }
    }
    pb.finish_and_clear();
    r.end_cycle();
    if fatal.is_none() {
        fatal = r.sinks.error.take();
    }
    let finished = r.sinks.finish();
    let (events_file, out_file) = match finished {
        Ok(x) => x,
        Err(e) => {
            fatal.get_or_insert(e);
            (None, None)
        }
    };
    let wall_s = started.elapsed().as_secs_f64();

    if r.messages == 0 {
        if let Some(e) = fatal {
            return Err(e);
        }
    }

    let last = r.latest_ns;
    let signals = cfg
        .signals
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let id = r.sig_ids[i];
            SignalSummary {
                name: s.name.clone(),
                topic: s.topic.clone(),
                field: s.field.clone(),
                samples: r.sig[i].samples,
                rejected: r.sig[i].rejected,
                last_sample_ns: r.table.get(id).map(|x| x.t_ns),
                missing: r.table.missing(id),
                stale_at_end: r.table.is_stale(id, last),
                watched: watched.contains(&id),
            }
        })
        .collect();
    let topics = r
        .channels
        .iter()
        .flatten()
        .map(|c| TopicSummary {
            topic: c.topic.to_string(),
            messages: c.messages,
            used_as: {
                let mut v: Vec<String> = c
                    .signals
                    .iter()
                    .map(|&i| format!("signal {} ({})", cfg.signals[i].name, cfg.signals[i].field))
                    .collect();
                if c.truth.is_some() {
                    v.push("ground truth".into());
                }
                if v.is_empty() {
                    "ignored (not mapped)".into()
                } else {
                    v.join(", ")
                }
            },
        })
        .collect();
    let monitors = r
        .monitors
        .iter()
        .zip(&r.steps)
        .map(|(m, &steps)| MonitorSummary {
            name: m.borrow().name().to_string(),
            steps,
        })
        .collect();
    let stats = |s: &crate::stats::RunningStats| {
        (s.count() > 0).then(|| ErrorStats {
            samples: s.count(),
            mean: s.mean(),
            std: s.std(),
        })
    };
    let truth = (r.truth_messages > 0).then(|| TruthSummary {
        messages: r.truth_messages,
        faults: r.sinks.onsets.clone(),
        estimates: r
            .sinks
            .truths
            .iter()
            .filter(|t| t.estimates > 0 || !t.value.is_nan())
            .map(|t| EstimateError {
                estimate: t.estimate.clone(),
                field: t.field.clone(),
                estimates: t.estimates,
                first_source: t.first_source.clone(),
                switched_at_ns: t.switched_at_ns,
                error_all: stats(&t.error_all),
                error_after_switch: stats(&t.error_after_switch),
            })
            .collect(),
    });
    let summary = ReplaySummary {
        log: file,
        config: cfg.origin.clone(),
        read_mode,
        messages: r.messages,
        frames: r.frames,
        wall_s,
        time_range_ns: r.first_ns.map(|a| (a, last)),
        operation_cycles: r.cycles,
        topics,
        signals,
        monitors,
        monitors_unavailable,
        problems: std::mem::take(&mut r.problems).into_list(),
        events: r.sinks.events,
        dtcs: r.sinks.dtcs.clone(),
        truth,
        events_file,
        out_file,
        stopped_early: fatal.map(|e| e.to_string()),
    };
    tracing::info!(
        messages = summary.messages,
        frames = summary.frames,
        wall_s = summary.wall_s,
        frames_per_s = summary.frames_per_s(),
        events = summary.events,
        problems = summary.problems.iter().map(|p| p.count).sum::<u64>(),
        "replay finished: {} messages, {} frames in {:.3} s ({:.0} frames/s), {} DTC status changes",
        summary.messages,
        summary.frames,
        summary.wall_s,
        summary.frames_per_s(),
        summary.events
    );
    Ok(summary)
}
