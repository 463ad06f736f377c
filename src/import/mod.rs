//! `fdd import`: a CSV log (one row per sample time, one column per signal) to an MCAP log fdd
//! replays, as a mapping file says ([`mapping`]): which column is the time and in what unit,
//! and for each output topic the columns it carries, scaled into the field's unit
//! (`value = column x scale + offset`: kPa to Pa, g/s to kg/s, rpm to rad/s, percent to a
//! fraction).
//!
//! - **One message per row per topic**, all at the row's time (log time = publish time = the
//!   row's time in ns, converted exactly from the decimal text: `decimal`), in the mapping's
//!   topic order, then the truth.
//! - **Ground truth**: with a `[truth]` table in the mapping, every row also gets a message in
//!   fdd's truth shape (`fault`, `fault_active`, `fault_observable`, and a `value` that is
//!   `null`: nothing is known of the true value of measured data). Without a fault it says
//!   `"none"`/`false`, so a fault-free log is scored for false alarms; with
//!   [`FaultSpec`] (`--fault NAME --fault-onset-s T`) the rows from `T` on carry `NAME`/`true`.
//! - **Streaming**: the CSV is read row by row ([`csv_rows`]) and the MCAP written chunk by
//!   chunk, so memory does not grow with the file.
//! - **Errors** name the file, the line and the column (a field that is not a number, `NaN` or
//!   an infinity, a row with another number of fields than the header, a time not after the
//!   previous row's), or the mapping file and its key (a mapping error; a column the mapping
//!   names that the header lacks: the CSV's line 1, the column and the mapping key).
//! - **Nothing overwritten by mistake**: the output may not be the CSV or the mapping (same
//!   file, through links too), nor end in `.csv` or `.toml`; it is written to a temporary file
//!   beside it and renamed into place only when complete, so a failed import leaves no partial
//!   log and does not touch an existing one.
//! - **Reproducible**: the writer settings are those of fdd's fixtures
//!   ([`FIXTURE_WRITE_OPTIONS`]: zstd level 9, 256 KiB chunks, no message indexes) and nothing
//!   in the file depends on the clock, so the same CSV and mapping give the same bytes.

pub mod csv_rows;
mod decimal;
pub mod mapping;
pub mod schema;

use std::io::{BufWriter, IsTerminal};
use std::path::{Path, PathBuf};

use fdd_fixtures::throttle_log::FIXTURE_WRITE_OPTIONS;
use fdd_monitor::config::ConfigError;
use fdd_monitor::log::{LogError, LogWriter};
use indicatif::{ProgressBar, ProgressStyle};

use crate::limits::RangeArg;
use csv_rows::CsvRows;
use decimal::DecimalError;
pub use mapping::{FieldSpec, Mapping, TimeSpec, TimeUnit, TopicSpec};

/// `fdd import --fault-onset-s`: a log time, s.
pub const FAULT_ONSET: RangeArg = RangeArg {
    flag: "--fault-onset-s",
    min: 0.0,
    min_exclusive: false,
    max: 1.8e10,
    unit: "s",
    why: "a log time: unsigned 64-bit nanoseconds reach 1.8e10 s",
};

/// Longest fault name (characters).
pub const MAX_FAULT_NAME: usize = 64;

/// Rows between progress-bar updates.
const PROGRESS_EVERY: u64 = 4096;

/// Why an import failed. Every variant names the file it is about.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The mapping file is missing, not TOML or has a value refused (file, table and key).
    #[error(transparent)]
    Mapping(#[from] ConfigError),
    #[error("cannot read {}: {source}", file.display())]
    Read {
        file: PathBuf,
        source: std::io::Error,
    },
    /// A problem in the CSV at `line` (1 = the header) and, when known, in column
    /// `(number from 1, name)`.
    #[error("{}: line {line}{}: {message}", file.display(), show_column(column))]
    Csv {
        file: PathBuf,
        line: u64,
        column: Option<(usize, String)>,
        message: String,
    },
    /// The mapping names a column the CSV's header does not have.
    #[error("{}: line 1 (the header) has no column `{column}`, which {mapping} names at {key} (the header's columns: {columns})", file.display())]
    MissingColumn {
        file: PathBuf,
        column: String,
        mapping: String,
        key: String,
        columns: String,
    },
    #[error("{}: refusing to write the log over its {what}", out.display())]
    OutputIsInput { out: PathBuf, what: &'static str },
    #[error("{}: refusing to write an MCAP log to a .{ext} file (a CSV or mapping file's name); give the log a .mcap name", out.display())]
    OutputExtension { out: PathBuf, ext: String },
    #[error("--fault {name:?}: {reason}")]
    FaultName { name: String, reason: String },
    #[error("{mapping}: --fault needs a [truth] table in the mapping naming the truth topic (e.g. topic = \"/truth/turbo\")")]
    NoTruthTopic { mapping: String },
    #[error("{}: --fault-onset-s {onset_s} s is after the last row ({last_s} s of log time): the fault would never be active; is the onset in the log's time base ([time] origin, offset_s)?", file.display())]
    OnsetAfterEnd {
        file: PathBuf,
        onset_s: f64,
        last_s: String,
    },
    #[error("{}: no data rows after the header", file.display())]
    NoRows { file: PathBuf },
    #[error("{}: none of the topics of {mapping} has its columns in this file: nothing to write", file.display())]
    NothingToWrite { file: PathBuf, mapping: String },
    #[error("cannot write {}: {source}", out.display())]
    Write {
        out: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Log(#[from] LogError),
}

fn show_column(column: &Option<(usize, String)>) -> String {
    match column {
        Some((n, name)) => format!(", column {n} `{name}`"),
        None => String::new(),
    }
}

/// A fault to mark in the truth: `name` from `onset_s` (log time, s) on.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultSpec {
    /// The truth's `fault` (e.g. `pim_gain_1.15`): letters, digits, `_`, `.`, `-`; `+` joins
    /// two faults active at once, as fdd's simulated truth writes them (`a+b`).
    pub name: String,
    pub onset_s: f64,
}

impl FaultSpec {
    /// The onset in ns, after checking the name and the onset's range.
    fn check(&self) -> Result<u64, ImportError> {
        let bad = |reason: &str| ImportError::FaultName {
            name: self.name.clone(),
            reason: reason.to_string(),
        };
        let n = &self.name;
        if n.is_empty() || n == "none" {
            return Err(bad("a fault name is needed (\"none\" is the truth's word for no fault: leave --fault out for a fault-free log)"));
        }
        if n.chars().count() > MAX_FAULT_NAME {
            return Err(bad(&format!("longer than {MAX_FAULT_NAME} characters")));
        }
        if !n
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'.' | b'-' | b'+'))
        {
            return Err(bad("use letters, digits, `_`, `.`, `-` (and `+` between two faults active at once), e.g. pim_gain_1.15"));
        }
        // Each name (of `a+b`, two faults at once) starts with a letter and ends with a letter
        // or digit, so that a sign such as `pim_gain_+15` is not read as two faults
        // `pim_gain_` and `15`.
        let well_formed = |part: &str| {
            part.bytes().next().is_some_and(|b| b.is_ascii_alphabetic())
                && part
                    .bytes()
                    .last()
                    .is_some_and(|b| b.is_ascii_alphanumeric())
        };
        if !n.split('+').all(well_formed) {
            return Err(bad(if n.contains('+') {
                "`+` joins two fault names, each starting with a letter (`a+b`, which fdd evaluate counts as `a`); write a sign some other way, e.g. pim_gain_1.15 for a gain of +15 %"
            } else {
                "a fault name starts with a letter and ends with a letter or digit, e.g. pim_gain_1.15"
            }));
        }
        FAULT_ONSET
            .check(self.onset_s)
            .map_err(|reason| ImportError::FaultName {
                name: self.name.clone(),
                reason,
            })?;
        Ok((self.onset_s * 1e9).round() as u64)
    }
}

/// How to import.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImportOptions {
    /// The fault to mark in the truth (needs a `[truth]` table in the mapping).
    pub fault: Option<FaultSpec>,
    /// Draw a progress bar (only when stderr is a terminal).
    pub progress: bool,
}

/// What was written.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ImportStats {
    /// Data rows read.
    pub rows: u64,
    /// Messages written (rows x topics, truth included).
    pub messages: u64,
    /// Log time of the first and last row, ns.
    pub first_ns: u64,
    pub last_ns: u64,
    /// The data topics written, in the mapping's order.
    pub topics: Vec<String>,
    /// Optional topics left out because the CSV has none of their columns.
    pub skipped: Vec<String>,
    /// The truth topic, if written.
    pub truth_topic: Option<String>,
    /// Rows with the fault active.
    pub fault_rows: u64,
}

impl ImportStats {
    /// The summary `fdd import` prints.
    pub fn render(&self, out: &Path, fault: Option<&FaultSpec>) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "wrote {}: {} rows, {} messages on {} topics, log time {} .. {} s",
            out.display(),
            self.rows,
            self.messages,
            self.topics.len() + usize::from(self.truth_topic.is_some()),
            seconds(self.first_ns),
            seconds(self.last_ns)
        );
        if let Some(t) = &self.truth_topic {
            match fault {
                Some(f) => {
                    let _ = writeln!(
                        s,
                        "truth {t}: fault `{}` from {} s ({} of {} rows active)",
                        f.name, f.onset_s, self.fault_rows, self.rows
                    );
                }
                None => {
                    let _ = writeln!(s, "truth {t}: no fault (fault-free log)");
                }
            }
        }
        if !self.skipped.is_empty() {
            let _ = writeln!(
                s,
                "optional topics without their columns in this CSV, not written: {}",
                self.skipped.join(", ")
            );
        }
        s
    }
}

/// `ns` as seconds, exactly, without trailing zeros (`97.755235366`, `343`).
pub fn seconds(ns: u64) -> String {
    let text = format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000);
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// One field to write: the JSON key (quoted), the row value's slot and the scaling.
struct PlannedField {
    key_json: String,
    slot: usize,
    scale: f64,
    offset: f64,
}

struct PlannedTopic {
    topic: String,
    fields: Vec<PlannedField>,
}

/// The mapping resolved against the CSV's header.
struct Plan {
    /// The time column's index, for a `TimeSpec::Column`.
    time_column: Option<usize>,
    /// The CSV column of each value slot, in column order (so the first bad field of a row
    /// is the leftmost).
    slots: Vec<usize>,
    topics: Vec<PlannedTopic>,
    skipped: Vec<String>,
}

fn find_column(
    rows: &CsvRows,
    mapping: &Mapping,
    column: &str,
    key: &str,
) -> Result<Option<usize>, ImportError> {
    let mut found = rows
        .header()
        .iter()
        .enumerate()
        .filter(|(_, h)| h.as_str() == column);
    let first = found.next().map(|(i, _)| i);
    if let (Some(i), Some((j, _))) = (first, found.next()) {
        return Err(rows.error(
            1,
            Some((j, String::new())),
            format!(
                "the column name `{column}` (which {} names at {key}) is also column {}: which one is meant is ambiguous",
                mapping.origin,
                i + 1
            ),
        ));
    }
    Ok(first)
}

fn missing(rows: &CsvRows, mapping: &Mapping, column: &str, key: &str) -> ImportError {
    let header = rows.header();
    let mut columns = header
        .iter()
        .take(30)
        .map(|h| format!("`{h}`"))
        .collect::<Vec<_>>()
        .join(", ");
    if header.len() > 30 {
        columns.push_str(&format!(", ... ({} in all)", header.len()));
    }
    ImportError::MissingColumn {
        file: rows.file().to_path_buf(),
        column: column.to_string(),
        mapping: mapping.origin.clone(),
        key: key.to_string(),
        columns,
    }
}

impl Plan {
    fn new(mapping: &Mapping, rows: &CsvRows) -> Result<Self, ImportError> {
        let time_column = match &mapping.time {
            TimeSpec::Column { column, key, .. } => Some(
                find_column(rows, mapping, column, key)?
                    .ok_or_else(|| missing(rows, mapping, column, key))?,
            ),
            TimeSpec::Periodic { .. } => None,
        };
        // Per topic, the column index of each field (None: not in the header).
        let mut resolved: Vec<Vec<Option<usize>>> = Vec::with_capacity(mapping.topics.len());
        for t in &mapping.topics {
            let mut cols = Vec::with_capacity(t.fields.len());
            for f in &t.fields {
                cols.push(find_column(rows, mapping, &f.column, &f.column_key)?);
            }
            resolved.push(cols);
        }
        let mut slots: Vec<usize> = resolved.iter().flatten().flatten().copied().collect();
        slots.sort_unstable();
        slots.dedup();
        let mut topics = Vec::new();
        let mut skipped = Vec::new();
        for (t, cols) in mapping.topics.iter().zip(&resolved) {
            if t.optional && cols.iter().all(Option::is_none) {
                skipped.push(t.topic.clone());
                continue;
            }
            let mut fields = Vec::with_capacity(t.fields.len());
            for (f, c) in t.fields.iter().zip(cols) {
                let Some(c) = c else {
                    return Err(missing(rows, mapping, &f.column, &f.column_key));
                };
                fields.push(PlannedField {
                    key_json: schema::json_string(&f.name),
                    slot: slots.binary_search(c).unwrap_or_default(),
                    scale: f.scale,
                    offset: f.offset,
                });
            }
            topics.push(PlannedTopic {
                topic: t.topic.clone(),
                fields,
            });
        }
        if topics.is_empty() {
            return Err(ImportError::NothingToWrite {
                file: rows.file().to_path_buf(),
                mapping: mapping.origin.clone(),
            });
        }
        // Only the columns of written topics are parsed.
        let used: Vec<usize> = {
            let mut u: Vec<usize> = topics
                .iter()
                .flat_map(|t| t.fields.iter().map(|f| slots[f.slot]))
                .collect();
            u.sort_unstable();
            u.dedup();
            u
        };
        for t in &mut topics {
            for f in &mut t.fields {
                f.slot = used.binary_search(&slots[f.slot]).unwrap_or_default();
            }
        }
        Ok(Plan {
            time_column,
            slots: used,
            topics,
            skipped,
        })
    }
}

/// Refuses an output that is one of the inputs, or named like one.
fn check_output(csv: &Path, mapping: &Path, out: &Path) -> Result<(), ImportError> {
    for (input, what) in [(csv, "CSV input"), (mapping, "mapping file")] {
        if crate::paths::same_file(input, out) {
            return Err(ImportError::OutputIsInput {
                out: out.to_path_buf(),
                what,
            });
        }
    }
    if let Some(ext) = out.extension().and_then(|e| e.to_str()) {
        if ext.eq_ignore_ascii_case("csv") || ext.eq_ignore_ascii_case("toml") {
            return Err(ImportError::OutputExtension {
                out: out.to_path_buf(),
                ext: ext.to_string(),
            });
        }
    }
    Ok(())
}

fn progress_bar(len: u64, enabled: bool) -> ProgressBar {
    if !enabled || !std::io::stderr().is_terminal() || len == 0 {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template(
        "{wide_bar} {percent:>3}% of the CSV [{elapsed_precise}, eta {eta}]",
    ) {
        pb.set_style(style);
    }
    pb
}

/// The field's text (UTF-8), for messages.
fn text(field: &[u8]) -> Option<&str> {
    std::str::from_utf8(field).ok()
}

/// A field shown in a message: quoted, at most 40 characters.
fn shown(field: &[u8]) -> String {
    let s = String::from_utf8_lossy(field);
    if s.chars().count() > 40 {
        format!("{:?}...", s.chars().take(37).collect::<String>())
    } else {
        format!("{s:?}")
    }
}

/// Parses a data field: a finite decimal number.
fn parse_value(field: &[u8]) -> Result<f64, String> {
    if field.is_empty() {
        return Err("empty field: not a number".into());
    }
    let Some(t) = text(field) else {
        return Err(format!("{}: not a number (not UTF-8 text)", shown(field)));
    };
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!(
            "{}: not a finite number (NaN and infinities are refused: a sensor reading is a number)",
            shown(field)
        )),
        Err(_) => Err(format!("{}: not a number", shown(field))),
    }
}

/// Imports `csv` as `mapping` says into the MCAP log `out`. See the [module documentation](self).
pub fn import(
    csv: &Path,
    mapping_path: &Path,
    out: &Path,
    opts: &ImportOptions,
) -> Result<ImportStats, ImportError> {
    let mapping = Mapping::load(mapping_path)?;
    check_output(csv, mapping_path, out)?;
    let fault = match &opts.fault {
        Some(f) => {
            let onset_ns = f.check()?;
            if mapping.truth_topic.is_none() {
                return Err(ImportError::NoTruthTopic {
                    mapping: mapping.origin.clone(),
                });
            }
            Some((f, onset_ns))
        }
        None => None,
    };
    let mut rows = CsvRows::open(csv, mapping.delimiter)?;
    let plan = Plan::new(&mapping, &rows)?;

    // Written beside the output and renamed into place once complete.
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let write_err = |source| ImportError::Write {
        out: out.to_path_buf(),
        source,
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".fdd-import-").suffix(".mcap.tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        // As `File::create`: 0666 less the umask.
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(&dir).map_err(write_err)?;
    let mut writer = LogWriter::with_options(
        BufWriter::with_capacity(1 << 16, tmp.as_file_mut()),
        out,
        FIXTURE_WRITE_OPTIONS,
    )?;
    let by_topic: Vec<&TopicSpec> = plan
        .topics
        .iter()
        .filter_map(|p| mapping.topics.iter().find(|t| t.topic == p.topic))
        .collect();
    for t in &by_topic {
        match t.builtin {
            Some(b) => writer.add_topic(b.topic, b.schema_name, b.schema)?,
            None => writer.add_topic(
                &t.topic,
                &schema::schema_name(&t.topic),
                &schema::topic_schema(t),
            )?,
        }
    }
    if let Some(t) = &mapping.truth_topic {
        writer.add_topic(t, schema::TRUTH_SCHEMA_NAME, schema::TRUTH_SCHEMA)?;
    }
    // The writer is finished on failure too (the temporary file is then deleted), so that
    // dropping it does not warn about an unfinished log.
    let result = write_rows(
        &mut rows,
        &plan,
        &mapping,
        fault,
        &mut writer,
        opts.progress,
    );
    let finished = writer.finish();
    let mut stats = result?;
    finished?;
    if let Some((f, onset)) = fault {
        if onset > stats.last_ns {
            return Err(ImportError::OnsetAfterEnd {
                file: csv.to_path_buf(),
                onset_s: f.onset_s,
                last_s: seconds(stats.last_ns),
            });
        }
    }
    stats.skipped = plan.skipped.clone();
    tmp.persist(out).map_err(|e| write_err(e.error))?;
    Ok(stats)
}

/// Writes every row of `rows` as `plan` says; the stats of what was written.
fn write_rows<W: std::io::Write + std::io::Seek>(
    rows: &mut CsvRows,
    plan: &Plan,
    mapping: &Mapping,
    fault: Option<(&FaultSpec, u64)>,
    writer: &mut LogWriter<W>,
    progress: bool,
) -> Result<ImportStats, ImportError> {
    let truth_off = schema::truth_message("none", false);
    let truth_on = fault.map(|(f, _)| schema::truth_message(&f.name, true));

    let pb = progress_bar(rows.file_len(), progress);
    let mut stats = ImportStats {
        topics: plan.topics.iter().map(|t| t.topic.clone()).collect(),
        truth_topic: mapping.truth_topic.clone(),
        ..ImportStats::default()
    };
    let mut values = vec![0.0f64; plan.slots.len()];
    let mut buf: Vec<u8> = Vec::with_capacity(256);
    let mut prev: Option<(u64, u64)> = None;
    let mut first_row_time: Option<i128> = None;
    while rows.next_row()? {
        let line = rows.line();
        let rec = rows.record();
        let t_ns = match (&mapping.time, plan.time_column) {
            (
                TimeSpec::Column {
                    unit,
                    from_first_row,
                    offset_ns,
                    ..
                },
                Some(col),
            ) => {
                let field = rec.get(col).unwrap_or_default().trim_ascii();
                let at = || Some((col, String::new()));
                let raw = text(field)
                    .ok_or(DecimalError::NotANumber)
                    .and_then(|t| decimal::scaled_integer(t, unit.exp10()))
                    .map_err(|e| {
                        let why = match e {
                            DecimalError::NotANumber => {
                                format!("not a time in {} (a decimal number)", unit.name())
                            }
                            DecimalError::NotFinite => "not a finite time".to_string(),
                            DecimalError::OutOfRange => {
                                "beyond any log time (over 10^38 ns)".to_string()
                            }
                        };
                        let what = if field.is_empty() {
                            "empty field".to_string()
                        } else {
                            shown(field)
                        };
                        rows.error(line, at(), format!("{what}: {why}"))
                    })?;
                let base = if *from_first_row {
                    raw.checked_sub(*first_row_time.get_or_insert(raw))
                } else {
                    Some(raw)
                };
                let t = base.and_then(|b| b.checked_add(*offset_ns));
                t.and_then(|t| u64::try_from(t).ok()).ok_or_else(|| {
                    let shown_t = t.map_or_else(|| "beyond 10^38".to_string(), |t| t.to_string());
                    rows.error(
                        line,
                        at(),
                        format!(
                            "{} {} gives log time {shown_t} ns, outside 0 .. 2^64 ns (shift it with [time] offset_s or origin = \"first_row\" in {})",
                            shown(field),
                            unit.name(),
                            mapping.origin
                        ),
                    )
                })?
            }
            (
                TimeSpec::Periodic {
                    period_ns,
                    offset_ns,
                },
                _,
            ) => {
                let t = offset_ns + i128::from(stats.rows) * i128::from(*period_ns);
                u64::try_from(t).map_err(|_| {
                    rows.error(
                        line,
                        None,
                        format!(
                            "row {} at [time] offset_s + {} x period_s gives log time {t} ns, outside 0 .. 2^64 ns ({})",
                            stats.rows, stats.rows, mapping.origin
                        ),
                    )
                })?
            }
            // Plan::new found the column of a TimeSpec::Column.
            (TimeSpec::Column { .. }, None) => 0,
        };
        if let Some((p, pline)) = prev {
            if t_ns <= p {
                let col = plan.time_column.map(|c| (c, String::new()));
                return Err(rows.error(
                    line,
                    col,
                    format!(
                        "log time {t_ns} ns is not after the previous row's ({p} ns, line {pline}): the rows' times must increase (by 1 ns at least)"
                    ),
                ));
            }
        }
        prev = Some((t_ns, line));
        for (slot, &col) in plan.slots.iter().enumerate() {
            let field = rec.get(col).unwrap_or_default().trim_ascii();
            values[slot] =
                parse_value(field).map_err(|m| rows.error(line, Some((col, String::new())), m))?;
        }
        for t in &plan.topics {
            buf.clear();
            buf.push(b'{');
            for (i, f) in t.fields.iter().enumerate() {
                if i > 0 {
                    buf.push(b',');
                }
                buf.extend_from_slice(f.key_json.as_bytes());
                buf.push(b':');
                let raw = values[f.slot];
                let v = raw * f.scale + f.offset;
                if !v.is_finite() {
                    return Err(rows.error(
                        line,
                        Some((plan.slots[f.slot], String::new())),
                        format!(
                            "{raw:?} x {:?} + {:?} is not a finite number (topic {})",
                            f.scale, f.offset, t.topic
                        ),
                    ));
                }
                serde_json::to_writer(&mut buf, &v).map_err(|e| {
                    rows.error(line, None, format!("cannot encode {v} as JSON: {e}"))
                })?;
            }
            buf.push(b'}');
            writer.write_raw_json(&t.topic, t_ns, &buf)?;
        }
        if let Some(topic) = &mapping.truth_topic {
            let msg = match (fault, &truth_on) {
                (Some((_, onset)), Some(on)) if t_ns >= onset => {
                    stats.fault_rows += 1;
                    on
                }
                _ => &truth_off,
            };
            writer.write_raw_json(topic, t_ns, msg)?;
        }
        if stats.rows == 0 {
            stats.first_ns = t_ns;
        }
        stats.last_ns = t_ns;
        stats.rows += 1;
        if stats.rows % PROGRESS_EVERY == 0 {
            pb.set_position(rows.position());
        }
    }
    pb.finish_and_clear();
    if stats.rows == 0 {
        return Err(ImportError::NoRows {
            file: rows.file().to_path_buf(),
        });
    }
    stats.messages = writer.messages_written();
    Ok(stats)
}
