//! `fdd replay`: runs the configured monitors over a recorded MCAP log, as a client of the
//! runtime a host embeds ([`Runtime`]): it reads the log, pushes samples, advances time and
//! renders the summary; the ground truth and the summary are the CLI's own.
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
//!   ([`Runtime::advance_to`]`(t - 1)`), then pushes the sample ([`Runtime::push`]). An operation
//!   cycle starts at the first message and ends after the last one (steps run up to the last
//!   time + 1 ns). A forward jump of the log time larger than `replay.max_gap_s` ends the cycle
//!   and starts a new one, rather than stepping every monitor through the pause.
//! - The runtime holds the [`StalenessMonitor`] ("no signal" events, FTB 0x31) and the
//!   subsystem monitors enabled in `[monitors]` that have at least one input topic in the log
//!   (for a file without an index the topics come from one pass over it); a log with no
//!   topic of any enabled monitor runs them all (a mapping error is likelier than a log for
//!   none of them), so its signals show as missing.
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
pub mod summary;
mod truth;

use std::fs::File;
use std::io::{BufWriter, IsTerminal, Write as _};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use fdd_monitor::log::{
    ChannelInfo, LogError, LogMessage, LogReader, LogWriter, ReadMode, WriteOptions,
};
use fdd_monitor::runtime::{Runtime, RuntimeError, Stamped};
use fdd_monitor::signal_table::SignalId;
use indicatif::{ProgressBar, ProgressStyle};

pub use config::RuntimeConfig;
pub use fdd_monitor::staleness::StalenessMonitor;
pub use problems::{Problem, ProblemKind};
pub use sinks::{
    DtcRecord, FaultOnset, DTC_STATUS_TOPIC, EVENTS_TOPIC, INNOVATION_TOPIC, POSITION_TOPIC,
    TESTS_TOPIC,
};
pub use summary::ReplaySummary;

use config::s_to_ns;
use problems::Problems;
pub use sinks::ReplayObserver;
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
    #[error("{}: cannot write the samples file: {source}", file.display())]
    Samples {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("monitor `{monitor}`: {message}")]
    Monitor { monitor: String, message: String },
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
    #[error("{}: refusing to write --{option} over {what}", file.display())]
    OutputIsInput {
        file: PathBuf,
        option: &'static str,
        /// What the file already is (`the input log`, `the --config file`, `--events`).
        what: &'static str,
    },
    /// Not one message could be read and every chunk that was tried failed (a compression
    /// this build cannot decode, a damaged file): an error, not an empty replay.
    #[error("{}: no message could be read: all {chunks} chunk(s) read failed; the first: {first}", file.display())]
    NothingRead {
        file: PathBuf,
        chunks: u64,
        first: String,
    },
}

/// Whether a reader error is about a whole chunk (its messages skipped).
fn chunk_error(e: &LogError) -> bool {
    matches!(
        e,
        LogError::BadChunk { .. }
            | LogError::CrcMismatch {
                section: fdd_monitor::log::CrcSection::Chunk,
                ..
            }
    )
}

/// The memory slot files of `--memory BASE` (`BASE.a`, `BASE.b`), as the runtime names them.
fn memory_slots(base: &Path) -> Vec<PathBuf> {
    let Some(name) = base.file_name() else {
        return Vec::new();
    };
    ["a", "b"]
        .iter()
        .map(|suffix| {
            let mut n = name.to_os_string();
            n.push(".");
            n.push(suffix);
            base.with_file_name(n)
        })
        .collect()
}

/// Whether two paths are (or would be) one file: the same existing file, or the same path.
fn same_target(a: &Path, b: &Path) -> bool {
    crate::paths::same_file(a, b)
        || match (std::path::absolute(a), std::path::absolute(b)) {
            (Ok(x), Ok(y)) => x == y,
            _ => a == b,
        }
}

/// Refuses outputs that would overwrite an input (the log, the configuration file) or each
/// other (`--out` and `--events` the same file, a memory slot among them).
fn check_outputs(log: &Path, cfg: &RuntimeConfig, opts: &ReplayOptions) -> Result<(), ReplayError> {
    let mut inputs: Vec<(PathBuf, &'static str)> = vec![(log.to_path_buf(), "the input log")];
    if Path::new(&cfg.origin).is_file() {
        inputs.push((PathBuf::from(&cfg.origin), "the --config file"));
    }
    for p in [&cfg.monitors.throttle_config, &cfg.monitors.intake_config]
        .into_iter()
        .flatten()
    {
        inputs.push((p.clone(), "a monitor settings file of the configuration"));
    }
    let mut outputs: Vec<(PathBuf, &'static str)> = Vec::new();
    if let Some(p) = &opts.out {
        outputs.push((p.clone(), "out"));
    }
    if let Some(p) = &opts.events {
        outputs.push((p.clone(), "events"));
    }
    if let Some(p) = &opts.samples {
        outputs.push((p.clone(), "samples"));
    }
    if let Some(base) = &opts.memory {
        outputs.extend(memory_slots(base).into_iter().map(|p| (p, "memory")));
    }
    for (i, (o, option)) in outputs.iter().enumerate() {
        if let Some((_, what)) = inputs.iter().find(|(p, _)| crate::paths::same_file(p, o)) {
            return Err(ReplayError::OutputIsInput {
                file: o.clone(),
                option,
                what,
            });
        }
        if let Some((_, other)) = outputs[..i]
            .iter()
            .find(|(p, other)| *other != *option && same_target(p, o))
        {
            return Err(ReplayError::OutputIsInput {
                file: o.clone(),
                option,
                what: match *other {
                    "out" => "the --out file",
                    "events" => "the --events file",
                    "samples" => "the --samples file",
                    _ => "a --memory slot file",
                },
            });
        }
    }
    Ok(())
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
    /// `--memory`: keep the event memory in these slot files (`<base>.a`, `<base>.b`) across
    /// replays, so consecutive logs act as consecutive operation cycles of one vehicle.
    pub memory: Option<PathBuf>,
    /// `--samples`: CSV file (`t_ns,signal,value`) of every sample the runtime accepted, in
    /// the order pushed: the input of a host that has no MCAP reader (`examples/c/host.c`).
    pub samples: Option<PathBuf>,
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

struct Replayer<'c, 'o> {
    cfg: &'c RuntimeConfig,
    file: PathBuf,
    rt: Runtime,
    sig_ids: Vec<SignalId>,
    sinks: Sinks<'o>,
    channels: Vec<Option<Channel>>,
    sig: Vec<SignalStats>,
    problems: Problems,
    max_gap_ns: u64,
    first_ns: Option<u64>,
    latest_ns: u64,
    prev_ns: Option<u64>,
    messages: u64,
    frames: u64,
    truth_messages: u64,
    /// Whether each truth topic's fault was active in its previous message.
    truth_active: Vec<bool>,
    /// Time of the previous message of each truth topic, ns.
    truth_prev_ns: Vec<Option<u64>>,
}

/// The replay's sink: every runtime output to the collectors and writers.
fn sink_of<'a, 'o>(sinks: &'a mut Sinks<'o>) -> impl FnMut(Stamped<'_>) + use<'a, 'o> {
    |o: Stamped<'_>| sinks.on_output(o.t_ns, o.monitor, o.output)
}

impl Replayer<'_, '_> {
    fn runtime_error(&mut self, e: RuntimeError) {
        tracing::error!("{}: runtime refused a call: {e}", self.file.display());
    }

    fn start_cycle(&mut self, t_ns: u64) {
        let res = self
            .rt
            .start_operation_cycle(t_ns, &mut sink_of(&mut self.sinks));
        if let Err(e) = res {
            self.runtime_error(e);
        }
    }

    /// Runs the steps up to the latest time and ends the cycle 1 ns after it.
    fn end_cycle(&mut self) {
        if !self.rt.operation_cycle_active() {
            return;
        }
        let end = self.latest_ns.saturating_add(1);
        let res = {
            let mut sink = sink_of(&mut self.sinks);
            self.rt
                .advance_to(self.latest_ns, &mut sink)
                .and_then(|_| self.rt.end_operation_cycle(end, &mut sink))
        };
        if let Err(e) = res {
            self.runtime_error(e);
        }
    }

    /// Moves time to `t_ns` before a sample stamped `t_ns` is applied: every step due before
    /// `t_ns` runs on the samples so far.
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
        let res = self.rt.advance_to(t_ns - 1, &mut sink_of(&mut self.sinks));
        if let Err(e) = res {
            self.runtime_error(e);
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
            rt,
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
            match rt.push(sig_ids[i], t, v) {
                Ok(()) => {
                    sig[i].samples += 1;
                    sinks.sample(t, &s.name, v);
                    if let Some(obs) = sinks.observer.as_mut() {
                        obs.sample(t, &s.name, v);
                    }
                }
                Err(RuntimeError::Sample { source: e, .. }) => {
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
                Err(e) => {
                    sig[i].rejected += 1;
                    tracing::error!("{}: signal `{}`: {e}", file.display(), s.name);
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
                    if let Some(obs) = sinks.observer.as_mut() {
                        obs.truth(t, ti, &tm.fault, tm.fault_active, tm.fault_observable);
                    }
                    // Onsets, activity and observability are kept per truth topic: in a log
                    // of two subsystems each truth has its own faults.
                    if tm.fault_active && !truth_active[ti] {
                        sinks.fault_onset(ti, msg.topic, &tm.fault, t);
                    }
                    truth_active[ti] = tm.fault_active;
                    if let (Some(obs), Some(prev)) = (tm.fault_observable, truth_prev_ns[ti]) {
                        sinks.fault_observable(ti, obs && tm.fault_active, t.saturating_sub(prev));
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
    replay_with(log, cfg, opts, None)
}

/// [`replay`] with an observer that sees every monitor output (innovations, test statistics
/// and diagnoses included) and the ground truth as they happen.
pub fn replay_observed(
    log: &Path,
    cfg: &RuntimeConfig,
    opts: &ReplayOptions,
    observer: &mut dyn ReplayObserver,
) -> Result<ReplaySummary, ReplayError> {
    replay_with(log, cfg, opts, Some(observer))
}

fn replay_with(
    log: &Path,
    cfg: &RuntimeConfig,
    opts: &ReplayOptions,
    mut observer: Option<&mut dyn ReplayObserver>,
) -> Result<ReplaySummary, ReplayError> {
    let started = Instant::now();
    let mut reader = LogReader::open_with(log, cfg.replay.limits.read_options())?;
    let file = reader.file().to_path_buf();
    let read_mode = reader.mode();

    check_outputs(log, cfg, opts)?;

    // Which monitors run: those with at least one input topic in the log. An indexed file
    // lists its channels up front; a file without a usable index is scanned once for them.
    let topics: Vec<String> = match read_mode {
        ReadMode::Indexed => reader.channels().map(|c| c.topic.to_string()).collect(),
        _ => scan_topics(log, cfg),
    };
    let (run, skipped) = monitors_for_log(cfg, &topics);
    for (name, reason) in &skipped {
        tracing::info!(
            "monitor `{name}` does not run on {}: {reason}",
            file.display()
        );
    }
    let run_refs: Vec<&str> = run.iter().map(String::as_str).collect();
    // Innovations and test statistics only go to `--out`.
    let mut builder = Runtime::builder(cfg.clone())
        .only_monitors(&run_refs)
        .detail_outputs(opts.out.is_some() || observer.is_some());
    if let Some(base) = &opts.memory {
        builder = builder.persistence(base);
    }
    let (rt, _) = builder.build()?;
    for n in rt.restore_notes() {
        tracing::info!("{}: {n}", file.display());
    }
    let sig_ids = cfg
        .signals
        .iter()
        .map(|s| {
            rt.signal(&s.name).ok_or_else(|| ReplayError::Monitor {
                monitor: "signal table".into(),
                message: format!("signal `{}` not declared", s.name),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    // The staleness monitor watches exactly the signals of the monitors that run.
    let watched: Vec<SignalId> = rt.watched_signals().to_vec();
    for s in &cfg.signals {
        let watched_signal = rt.signal(&s.name).is_some_and(|id| watched.contains(&id));
        if watched_signal && !topics.contains(&s.topic) {
            tracing::warn!(
                "{}: the log has no topic {}: signal `{}` will be missing",
                file.display(),
                s.topic,
                s.name
            );
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
    let mut sinks = Sinks::new(events_file, out, &cfg.truth);
    if let Some(p) = &opts.samples {
        let f = File::create(p).map_err(|source| ReplayError::Samples {
            file: p.clone(),
            source,
        })?;
        let mut w = BufWriter::with_capacity(1 << 16, f);
        writeln!(w, "t_ns,signal,value").map_err(|source| ReplayError::Samples {
            file: p.clone(),
            source,
        })?;
        sinks.samples_file = Some((p.clone(), w));
    }
    // A monitor's truth topic is the one whose estimate it outputs; its DTCs detect that
    // topic's faults (and a monitor of none, the "no signal" monitor, any topic's).
    sinks.monitor_truth = rt
        .monitor_names()
        .filter_map(|m| {
            let estimates = rt.estimate_names(m).unwrap_or(&[]);
            let t = cfg
                .truth
                .iter()
                .position(|t| estimates.contains(&t.estimate.as_str()))?;
            Some((m.to_string(), t))
        })
        .collect();
    sinks.classes = rt
        .monitor_names()
        .filter_map(|m| Some((m.to_string(), rt.fault_classes(m)?)))
        .collect();
    if let Some(obs) = observer.as_mut() {
        obs.begin_log(&rt, &cfg.truth);
    }
    sinks.observer = observer;

    let mut r = Replayer {
        cfg,
        file: file.clone(),
        sig: vec![SignalStats::default(); cfg.signals.len()],
        rt,
        sig_ids,
        sinks,
        channels: Vec::new(),
        problems: Problems::default(),
        max_gap_ns: s_to_ns(cfg.replay.max_gap_s),
        first_ns: None,
        latest_ns: 0,
        prev_ns: None,
        messages: 0,
        frames: 0,
        truth_messages: 0,
        truth_active: vec![false; cfg.truth.len()],
        truth_prev_ns: vec![None; cfg.truth.len()],
    };

    let (pb, pb_start) = progress_bar(&reader, opts.progress);
    let mut fatal: Option<ReplayError> = None;
    // Chunks the reader could not decode (their messages skipped), and the first such error:
    // a log of which not one chunk decodes is an error, not an empty replay.
    let (mut chunks_failed, mut first_chunk_error) = (0u64, None::<String>);
    while let Some(item) = reader.next_message() {
        match item {
            Ok(msg) => r.handle(&msg),
            Err(e) if e.is_fatal() => {
                fatal = Some(e.into());
                break;
            }
            Err(e) => {
                if chunk_error(&e) {
                    chunks_failed += 1;
                    first_chunk_error.get_or_insert_with(|| e.to_string());
                }
                r.problems.record_log_error(&e);
            }
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
    if let Some(obs) = r.sinks.observer.as_mut() {
        obs.end_log();
    }

    if r.messages == 0 {
        if let Some(e) = fatal {
            return Err(e);
        }
        if let Some(first) = first_chunk_error {
            return Err(ReplayError::NothingRead {
                file,
                chunks: chunks_failed,
                first,
            });
        }
    }

    let last = r.latest_ns;
    let table = r.rt.signals();
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
                last_sample_ns: table.get(id).map(|x| x.t_ns),
                missing: table.missing(id),
                stale_at_end: table.is_stale(id, last),
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
    let monitors =
        r.rt.step_counts()
            .map(|(name, steps)| MonitorSummary {
                name: name.to_string(),
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
        operation_cycles: r.rt.operation_cycles(),
        topics,
        signals,
        monitors,
        monitors_skipped: skipped,
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

/// The enabled subsystem monitors that would run on `log` (see [`monitors_for_log`]).
pub(crate) fn monitors_on_log(log: &Path, cfg: &RuntimeConfig) -> Result<Vec<String>, ReplayError> {
    let reader = LogReader::open_with(log, cfg.replay.limits.read_options())?;
    let topics: Vec<String> = match reader.mode() {
        ReadMode::Indexed => reader.channels().map(|c| c.topic.to_string()).collect(),
        _ => scan_topics(log, cfg),
    };
    Ok(monitors_for_log(cfg, &topics).0)
}

/// The enabled subsystem monitors that run on a log with these topics, and those that do
/// not (with the reason). A monitor runs when the log carries at least one of its input
/// topics; a log that carries no monitor's topics at all is more likely mapped wrongly than
/// meant for none of them, so then every enabled monitor runs and reports its signals missing.
fn monitors_for_log(
    cfg: &RuntimeConfig,
    topics: &[String],
) -> (Vec<String>, Vec<(String, String)>) {
    let inputs = |name: &str| -> Vec<String> {
        let sigs = fdd_monitor::runtime::monitor_inputs(cfg, name).unwrap_or_default();
        cfg.signals
            .iter()
            .filter(|s| sigs.contains(&s.name))
            .map(|s| s.topic.clone())
            .collect()
    };
    let enabled = cfg.monitors.enabled();
    let present: Vec<(&str, Vec<String>, bool)> = enabled
        .iter()
        .map(|&m| {
            let t = inputs(m);
            let p = t.iter().any(|x| topics.iter().any(|y| y == x));
            (m, t, p)
        })
        .collect();
    let none_present = !present.iter().any(|(_, _, p)| *p);
    let mut run = Vec::new();
    let mut skipped = Vec::new();
    for (m, t, p) in present {
        if p || none_present {
            run.push(m.to_string());
        } else {
            skipped.push((
                m.to_string(),
                format!("the log has none of its topics ({})", t.join(", ")),
            ));
        }
    }
    (run, skipped)
}

/// The topics of a log without a usable index, from one pass over it (a truncated file is read
/// up to its first unreadable record).
fn scan_topics(log: &Path, cfg: &RuntimeConfig) -> Vec<String> {
    let mut topics: Vec<String> = Vec::new();
    let Ok(mut reader) = LogReader::open_with(log, cfg.replay.limits.read_options()) else {
        return topics;
    };
    while let Some(item) = reader.next_message() {
        match item {
            Ok(msg) => {
                if !topics.iter().any(|t| t == msg.topic) {
                    topics.push(msg.topic.to_string());
                }
            }
            Err(e) if e.is_fatal() => break,
            Err(_) => {}
        }
    }
    topics
}
