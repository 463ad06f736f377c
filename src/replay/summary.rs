//! What a replay did, and its rendering as the table `fdd replay` prints at the end.

use std::fmt::Write as _;
use std::path::PathBuf;

use fdd_monitor::log::ReadMode;

use super::problems::{Problem, ProblemKind};
use super::sinks::{DtcRecord, FaultOnset};

/// Messages of one topic.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicSummary {
    pub topic: String,
    pub messages: u64,
    /// `signal tps (voltage_v)`, `ground truth`, or `ignored`.
    pub used_as: String,
}

/// One configured signal.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalSummary {
    pub name: String,
    pub topic: String,
    pub field: String,
    /// Samples accepted by the signal table.
    pub samples: u64,
    /// Messages on the topic whose sample was refused (bad JSON, missing field, NaN, time).
    pub rejected: u64,
    /// Time of the latest accepted sample, ns.
    pub last_sample_ns: Option<u64>,
    /// No sample ever arrived (the topic is not in the log, or every message was bad).
    pub missing: bool,
    /// The latest sample was older than max_age at the end of the log.
    pub stale_at_end: bool,
    /// Watched for staleness: false for the inputs of a monitor that did not run on this log.
    pub watched: bool,
}

/// A monitor that ran, or a note on one that did not.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorSummary {
    pub name: String,
    /// Steps run.
    pub steps: u64,
}

/// Mean and standard deviation of an error, deg.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStats {
    pub samples: u64,
    pub mean: f64,
    pub std: f64,
}

/// Ground-truth comparisons (logs with a truth topic).
#[derive(Debug, Clone, PartialEq)]
pub struct TruthSummary {
    /// Truth messages read.
    pub messages: u64,
    /// Faults active in the log, with onset and first DTC after it.
    pub faults: Vec<FaultOnset>,
    /// One comparison per truth topic of the configuration that had messages.
    pub estimates: Vec<EstimateError>,
}

/// An estimate's error against the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateError {
    /// The estimate compared (`truth.estimate`) and the truth field (`truth.field`).
    pub estimate: String,
    pub field: String,
    /// Estimates seen.
    pub estimates: u64,
    /// The first estimate's source, and when the source first changed, ns.
    pub first_source: Option<String>,
    pub switched_at_ns: Option<u64>,
    pub error_all: Option<ErrorStats>,
    pub error_after_switch: Option<ErrorStats>,
}

/// Everything the replay reports at the end.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplaySummary {
    pub log: PathBuf,
    /// The configuration's origin (a path or the embedded default).
    pub config: String,
    pub read_mode: ReadMode,
    /// Messages read (including refused ones).
    pub messages: u64,
    /// Distinct consecutive log times (one frame = the samples of one time step).
    pub frames: u64,
    /// Wall time of the replay, s.
    pub wall_s: f64,
    /// First and last log time processed, ns.
    pub time_range_ns: Option<(u64, u64)>,
    pub operation_cycles: u32,
    pub topics: Vec<TopicSummary>,
    pub signals: Vec<SignalSummary>,
    pub monitors: Vec<MonitorSummary>,
    /// Monitors enabled in the configuration that did not run on this log, with the reason.
    pub monitors_skipped: Vec<(String, String)>,
    pub problems: Vec<Problem>,
    /// Status changes (DiagnosticEvents) emitted.
    pub events: u64,
    /// Every event that changed status.
    pub dtcs: Vec<DtcRecord>,
    pub truth: Option<TruthSummary>,
    /// `--events` file and events written.
    pub events_file: Option<(PathBuf, u64)>,
    /// `--out` file and messages written.
    pub out_file: Option<(PathBuf, u64)>,
    /// The fatal error that stopped the reading before the end of the log (everything before
    /// it was processed and is reported).
    pub stopped_early: Option<String>,
}

impl ReplaySummary {
    /// Occurrences of problems of `kind` (all topics).
    pub fn problem_count(&self, kind: ProblemKind) -> u64 {
        self.problems
            .iter()
            .filter(|p| p.kind == kind)
            .map(|p| p.count)
            .sum()
    }

    /// The problem counter of `kind` on `topic`.
    pub fn problem(&self, kind: ProblemKind, topic: &str) -> Option<&Problem> {
        self.problems
            .iter()
            .find(|p| p.kind == kind && p.topic.as_deref() == Some(topic))
    }

    /// Watched signals that never had a sample.
    pub fn missing_signals(&self) -> impl Iterator<Item = &SignalSummary> {
        self.signals.iter().filter(|s| s.missing && s.watched)
    }

    /// Events whose testFailed bit was set at least once.
    pub fn dtcs_raised(&self) -> impl Iterator<Item = &DtcRecord> {
        self.dtcs.iter().filter(|d| d.raised > 0)
    }

    /// Frames per second of wall time.
    pub fn frames_per_s(&self) -> f64 {
        if self.wall_s > 0.0 {
            self.frames as f64 / self.wall_s
        } else {
            f64::NAN
        }
    }

    /// The summary table printed by `fdd replay`.
    pub fn render(&self) -> String {
        let mut s = String::new();
        let _ = self.render_into(&mut s);
        s
    }

    fn render_into(&self, s: &mut String) -> std::fmt::Result {
        writeln!(s, "fdd replay: {}", self.log.display())?;
        let mut head = Table::new(&["", ""]);
        head.row(vec!["config".into(), self.config.clone()]);
        head.row(vec![
            "read".into(),
            match self.read_mode {
                ReadMode::Indexed => "indexed (log-time order)".into(),
                ReadMode::Linear => {
                    "linear (no usable index: file order, times checked per signal)".into()
                }
            },
        ]);
        head.row(vec![
            "log time".into(),
            match self.time_range_ns {
                Some((a, b)) => format!(
                    "{} .. {} s ({} s)",
                    secs(a),
                    secs(b),
                    secs(b.saturating_sub(a))
                ),
                None => "no messages".into(),
            },
        ]);
        head.row(vec![
            "messages".into(),
            format!(
                "{} in {} frames, {:.3} s wall time, {:.0} frames/s",
                self.messages,
                self.frames,
                self.wall_s,
                self.frames_per_s()
            ),
        ]);
        head.row(vec![
            "operation cycles".into(),
            self.operation_cycles.to_string(),
        ]);
        let mut mons: Vec<String> = self
            .monitors
            .iter()
            .map(|m| format!("{} ({} steps)", m.name, m.steps))
            .collect();
        mons.extend(
            self.monitors_skipped
                .iter()
                .map(|(m, why)| format!("{m} (not run: {why})")),
        );
        head.row(vec!["monitors".into(), mons.join(", ")]);
        head.row(vec![
            "events".into(),
            format!("{} DTC status changes", self.events),
        ]);
        if let Some((p, n)) = &self.events_file {
            head.row(vec![
                "events file".into(),
                format!("{} ({n} events)", p.display()),
            ]);
        }
        if let Some((p, n)) = &self.out_file {
            head.row(vec![
                "output log".into(),
                format!("{} ({n} messages)", p.display()),
            ]);
        }
        head.render_plain(s)?;
        if let Some(e) = &self.stopped_early {
            writeln!(s, "\nSTOPPED EARLY: {e}")?;
            writeln!(
                s,
                "(everything before this point was processed and is reported below)"
            )?;
        }

        writeln!(s, "\nTopics")?;
        let mut t = Table::new(&["topic", "messages", "used as"]);
        for tp in &self.topics {
            t.row(vec![
                tp.topic.clone(),
                tp.messages.to_string(),
                tp.used_as.clone(),
            ]);
        }
        t.render(s)?;

        writeln!(s, "\nSignals")?;
        let mut t = Table::new(&[
            "signal",
            "topic",
            "field",
            "samples",
            "refused",
            "last sample (s)",
            "state",
        ]);
        for sg in &self.signals {
            let state = if !sg.watched {
                "not used: its monitor does not run on this log".to_string()
            } else if sg.missing {
                "MISSING: no sample in the log".to_string()
            } else if sg.stale_at_end {
                "stale at the end of the log".to_string()
            } else {
                "ok".to_string()
            };
            t.row(vec![
                sg.name.clone(),
                sg.topic.clone(),
                sg.field.clone(),
                sg.samples.to_string(),
                sg.rejected.to_string(),
                sg.last_sample_ns.map(secs).unwrap_or_else(|| "-".into()),
                state,
            ]);
        }
        t.render(s)?;

        writeln!(s, "\nProblems (counted; the replay went on)")?;
        if self.problems.is_empty() {
            writeln!(s, "  none")?;
        } else {
            let mut t = Table::new(&["problem", "topic", "count", "first at (s)"]);
            for p in &self.problems {
                t.row(vec![
                    p.kind.label().into(),
                    p.topic.clone().unwrap_or_else(|| "-".into()),
                    p.count.to_string(),
                    p.first_time_ns.map(secs).unwrap_or_else(|| "-".into()),
                ]);
            }
            t.render(s)?;
            writeln!(s, "  first occurrences:")?;
            for p in &self.problems {
                writeln!(s, "    {}", p.first_message)?;
            }
        }

        writeln!(s, "\nDTCs raised (testFailed 0 -> 1)")?;
        let raised: Vec<_> = self.dtcs_raised().collect();
        if raised.is_empty() {
            writeln!(s, "  none")?;
        } else {
            let mut t = Table::new(&["DTC", "event", "first at (s)", "times", "status at end"]);
            for d in raised {
                t.row(vec![
                    d.dtc.to_string(),
                    d.event.clone(),
                    d.first_failed_s
                        .map(|x| format!("{x:.3}"))
                        .unwrap_or_default(),
                    d.raised.to_string(),
                    format!("{:#04x}", d.status.byte()),
                ]);
            }
            t.render(s)?;
        }

        if let Some(tr) = &self.truth {
            writeln!(s, "\nGround truth ({} messages)", tr.messages)?;
            if tr.faults.is_empty() {
                writeln!(
                    s,
                    "  no fault active in the log: every DTC raised is a false alarm"
                )?;
            } else {
                let observable = tr.faults.iter().any(|f| f.observable_ns.is_some());
                // A log of two subsystems has faults from two truth topics: say whose.
                let topics = tr.faults.iter().any(|f| f.truth != tr.faults[0].truth);
                let mut header = vec![
                    "fault",
                    "onset (s)",
                    "first DTC after onset",
                    "at (s)",
                    "detection delay (ms)",
                ];
                if observable {
                    header.push("of which observable (ms)");
                }
                if topics {
                    header.insert(1, "truth topic");
                }
                let mut t = Table::new(&header);
                for f in &tr.faults {
                    let (dtc, at, delay) = match &f.detected {
                        Some((dtc, ev, at)) => (
                            format!("{dtc} {ev}"),
                            format!("{at:.3}"),
                            format!("{:.1}", (at - f.onset_ns as f64 * 1e-9) * 1e3),
                        ),
                        None => ("none".into(), "-".into(), "not detected".into()),
                    };
                    let mut row = vec![f.fault.clone(), secs(f.onset_ns), dtc, at, delay];
                    if topics {
                        row.insert(1, f.topic.clone());
                    }
                    if observable {
                        row.push(
                            f.observable_ns
                                .map_or("-".into(), |ns| format!("{:.1}", ns as f64 * 1e-6)),
                        );
                    }
                    t.row(row);
                }
                t.render(s)?;
            }
            for e in &tr.estimates {
                write!(
                    s,
                    "  estimate error ({} vs truth {}): ",
                    e.estimate, e.field
                )?;
                match e.error_all {
                    None => writeln!(s, "no estimates ({} seen)", e.estimates)?,
                    Some(a) => {
                        write!(
                            s,
                            "all {} samples mean {:.3} std {:.3}",
                            a.samples, a.mean, a.std
                        )?;
                        let from = e.first_source.as_deref().unwrap_or("?");
                        match (e.switched_at_ns, e.error_after_switch) {
                            (Some(at), Some(b)) => writeln!(
                                s,
                                "; after the switch away from {from} at {} s: {} samples mean {:.3} std {:.3}",
                                secs(at),
                                b.samples,
                                b.mean,
                                b.std
                            )?,
                            _ => writeln!(s, "; source never switched away from {from}")?,
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

/// Nanoseconds as seconds, millisecond resolution.
fn secs(ns: u64) -> String {
    format!("{:.3}", ns as f64 * 1e-9)
}

/// Widest cell a table pads to (characters). A longer cell of a padded column (a topic, field
/// or fault name of any length is possible in a log or a configuration) is shortened with an
/// ellipsis in the table and printed in full below it, so the columns stay readable and
/// nothing is lost; the last column is not padded and is printed whole.
pub const MAX_CELL_CHARS: usize = 60;

/// A left-aligned text table (numbers right-aligned). Cells are padded by hand, never with a
/// `{:width$}` format (whose width is limited to 65,535).
struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

/// `c` cut to `max` characters, the last one an ellipsis; `None` when it fits.
fn shortened(c: &str, max: usize) -> Option<String> {
    if c.chars().count() <= max {
        return None;
    }
    let mut s: String = c.chars().take(max.saturating_sub(1)).collect();
    s.push('\u{2026}');
    Some(s)
}

/// Appends `n` spaces.
fn pad(s: &mut String, n: usize) {
    s.extend(std::iter::repeat_n(' ', n));
}

impl Table {
    fn new(header: &[&str]) -> Self {
        Table {
            header: header.iter().map(|h| h.to_string()).collect(),
            rows: Vec::new(),
        }
    }

    fn row(&mut self, cells: Vec<String>) {
        self.rows.push(cells);
    }

    /// Whether column `i` of a row of `n` cells is padded (every column but the last).
    fn padded(i: usize, n: usize) -> bool {
        i + 1 < n
    }

    /// Cell `i` of a row of `n` cells as shown: shortened to [`MAX_CELL_CHARS`] in a padded
    /// column.
    fn shown(c: &str, i: usize, n: usize) -> std::borrow::Cow<'_, str> {
        match shortened(c, MAX_CELL_CHARS).filter(|_| Self::padded(i, n)) {
            Some(s) => s.into(),
            None => c.into(),
        }
    }

    fn widths(&self) -> Vec<usize> {
        let n = self.header.len();
        let mut w: Vec<usize> = self
            .header
            .iter()
            .enumerate()
            .map(|(i, h)| Self::shown(h, i, n).chars().count())
            .collect();
        for r in &self.rows {
            for (i, c) in r.iter().enumerate() {
                if i < w.len() {
                    w[i] = w[i].max(Self::shown(c, i, r.len()).chars().count());
                }
            }
        }
        w
    }

    /// Columns whose cells are all numbers (or `-`) are right-aligned.
    fn numeric(&self) -> Vec<bool> {
        (0..self.header.len())
            .map(|i| {
                !self.rows.is_empty()
                    && self.rows.iter().all(|r| {
                        r.get(i).is_some_and(|c| {
                            !c.is_empty()
                                && c.chars()
                                    .all(|ch| ch.is_ascii_digit() || ch == '.' || ch == '-')
                        })
                    })
            })
            .collect()
    }

    fn line(s: &mut String, cells: &[String], widths: &[usize], numeric: &[bool]) {
        s.push(' ');
        for (i, c) in cells.iter().enumerate() {
            let c = Self::shown(c, i, cells.len());
            let w = widths.get(i).copied().unwrap_or(0);
            let fill = w.saturating_sub(c.chars().count());
            let last = i + 1 == cells.len();
            s.push(' ');
            if numeric.get(i).copied().unwrap_or(false) {
                pad(s, fill);
                s.push_str(&c);
            } else {
                s.push_str(&c);
                if !last {
                    pad(s, fill);
                }
            }
        }
        s.push('\n');
    }

    /// The cells shortened in the table, in full: `  (column, row N) text`.
    fn notes(&self, s: &mut String) {
        let mut first = true;
        for (r, row) in self.rows.iter().enumerate() {
            for (i, c) in row.iter().enumerate() {
                if Self::padded(i, row.len()) && shortened(c, MAX_CELL_CHARS).is_some() {
                    if first {
                        s.push_str("  cells shortened above, in full:\n");
                        first = false;
                    }
                    let column = self.header.get(i).map_or("", String::as_str);
                    let column = if column.is_empty() { "value" } else { column };
                    s.push_str(&format!("    {column}, row {}: {c}\n", r + 1));
                }
            }
        }
    }

    fn render(&self, s: &mut String) -> std::fmt::Result {
        let (w, n) = (self.widths(), self.numeric());
        Self::line(s, &self.header, &w, &n);
        for r in &self.rows {
            Self::line(s, r, &w, &n);
        }
        self.notes(s);
        Ok(())
    }

    /// Without the header row.
    fn render_plain(&self, s: &mut String) -> std::fmt::Result {
        let (w, n) = (self.widths(), self.numeric());
        for r in &self.rows {
            Self::line(s, r, &w, &n);
        }
        self.notes(s);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cell of any length (here 70,000 characters, beyond the 65,535 a `{:width$}` format
    /// takes) is shortened in its column and printed in full below the table.
    #[test]
    fn long_cells_are_shortened_in_the_table_and_kept_below_it() {
        let long = "t".repeat(70_000);
        let mut t = Table::new(&["topic", "messages", "used as"]);
        t.row(vec![long.clone(), "12".into(), "ignored".into()]);
        t.row(vec!["/a".into(), long.clone(), format!("signal {long}")]);
        let mut s = String::new();
        t.render(&mut s).expect("render");
        let lines: Vec<&str> = s.lines().collect();
        assert!(
            lines[..2]
                .iter()
                .all(|l| l.chars().count() < 3 * MAX_CELL_CHARS),
            "{}",
            &s[..400]
        );
        assert!(lines[1].contains('\u{2026}'));
        // The last column is not padded: printed whole in its row.
        assert!(lines[2].ends_with(&format!(" signal {long}")));
        assert!(s.contains(&format!("topic, row 1: {long}\n")));
        assert!(s.contains(&format!("messages, row 2: {long}\n")));
        // Short tables are unchanged: columns padded to the widest cell, numbers right-aligned.
        let mut t = Table::new(&["a", "n", "z"]);
        t.row(vec!["xyz".into(), "5".into(), "q".into()]);
        let mut s = String::new();
        t.render(&mut s).expect("render");
        assert_eq!(s, "  a   n z\n  xyz 5 q\n");
    }
}
