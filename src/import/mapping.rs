//! The mapping file of `fdd import`: which CSV column is the time and in what unit, and which
//! columns go to which topic and field, with the linear scaling into the field's unit.
//!
//! ```toml
//! [csv]                      # optional
//! delimiter = ","            # one ASCII character (default ",")
//!
//! [time]
//! column = "time"            # the time column ...
//! unit = "s"                 # ... and its unit: s, ms, us or ns
//! origin = "keep"            # "keep" (default): log time = the column's time;
//!                            # "first_row": the first row is at 0
//! offset_s = 0.0             # optional, added to every time (s)
//! # or, for rows without a time (stationary points): period_s = 1.0, row i at offset + i x period
//!
//! [truth]                    # optional: the ground-truth topic `--fault` fills
//! topic = "/truth/turbo"
//!
//! [[topics]]
//! topic = "/turbo/p_im"
//! description = "intake manifold pressure"   # optional, into the JSON schema
//! optional = false           # optional: true = skip the topic when the CSV lacks its columns
//! fields = [
//!   # value = column x scale + offset, in `unit` (written into the schema's description)
//!   { name = "pressure_pa", column = "p_im", unit = "Pa", scale = 1000.0, offset = 0.0 },
//! ]
//! ```
//!
//! Every table denies unknown keys, and every error names the mapping file, the table and the
//! key as the user wrote it (`topics[3].fields[0].scale = 0.0: ...`), the same way fdd's
//! configuration errors do ([`fdd_monitor::config_key`]).

use std::path::Path;

use fdd_monitor::config::ConfigError;
use fdd_monitor::config_key::{parse_toml, show, KeyPath, Range};
use fdd_monitor::log::{builtin_topic, TopicSchema};
use serde::Deserialize;

/// Most topics one mapping may write: fdd's reader refuses a log with more than 10,000
/// channels by default (`[replay.limits] max_channels`), and one is the truth topic.
pub const MAX_TOPICS: usize = 9_999;

/// Range of `[time] offset_s` (s): log times are unsigned 64-bit nanoseconds, at most
/// 1.8e10 s (585 years); an offset beyond cannot give a valid log time.
const OFFSET_RANGE: Range = Range::closed(-1.8e10, 1.8e10, "s");
/// Range of `[time] period_s` (s): at least 1 ns (the log-time resolution), at most a day
/// between two rows.
const PERIOD_RANGE: Range = Range::closed(1e-9, 86_400.0, "s");

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MappingFile {
    #[serde(default)]
    csv: CsvTable,
    time: TimeTable,
    truth: Option<TruthTable>,
    topics: Vec<TopicTable>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct CsvTable {
    delimiter: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TimeTable {
    column: Option<String>,
    unit: Option<String>,
    origin: Option<String>,
    offset_s: Option<f64>,
    period_s: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TruthTable {
    topic: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TopicTable {
    topic: String,
    description: Option<String>,
    #[serde(default)]
    optional: bool,
    fields: Vec<FieldTable>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FieldTable {
    name: String,
    column: String,
    unit: String,
    scale: Option<f64>,
    offset: Option<f64>,
    description: Option<String>,
}

/// Unit of the time column: the power of ten that turns it into ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeUnit {
    S,
    Ms,
    Us,
    Ns,
}

impl TimeUnit {
    /// `10^exp10` ns per unit.
    pub fn exp10(self) -> i32 {
        match self {
            TimeUnit::S => 9,
            TimeUnit::Ms => 6,
            TimeUnit::Us => 3,
            TimeUnit::Ns => 0,
        }
    }

    /// As written in the mapping.
    pub fn name(self) -> &'static str {
        match self {
            TimeUnit::S => "s",
            TimeUnit::Ms => "ms",
            TimeUnit::Us => "us",
            TimeUnit::Ns => "ns",
        }
    }
}

/// Where each row's log time comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum TimeSpec {
    /// A column holding the time in `unit`; log time = time - (first row's time when
    /// `from_first_row`) + `offset_ns`.
    Column {
        column: String,
        /// The mapping key naming the column (`[time] column`), for errors.
        key: String,
        unit: TimeUnit,
        from_first_row: bool,
        offset_ns: i128,
    },
    /// No time column: row `i` (from 0) is at `offset_ns + i * period_ns`.
    Periodic { period_ns: u64, offset_ns: i128 },
}

/// One field of a topic: `value = column * scale + offset`, in `unit`.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldSpec {
    /// The JSON key (`pressure_pa`).
    pub name: String,
    /// The CSV column (header name).
    pub column: String,
    /// The mapping key naming the column (`topics[3].fields[0].column`), for errors.
    pub column_key: String,
    /// The unit of the written value (`Pa`), for the schema's description.
    pub unit: String,
    pub scale: f64,
    pub offset: f64,
    pub description: Option<String>,
}

/// One output topic.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicSpec {
    pub topic: String,
    pub description: Option<String>,
    /// Skip the topic (instead of refusing the CSV) when the CSV has none of its columns.
    pub optional: bool,
    pub fields: Vec<FieldSpec>,
    /// The mapping key of the topic (`topics[3]`), for errors.
    pub key: String,
    /// fdd's own schema when the topic is one of fdd's input topics (`/intake/map`).
    pub builtin: Option<&'static TopicSchema>,
}

/// A checked mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct Mapping {
    /// The file, as errors name it.
    pub origin: String,
    pub delimiter: u8,
    pub time: TimeSpec,
    /// The ground-truth topic (`[truth] topic`), if any.
    pub truth_topic: Option<String>,
    pub topics: Vec<TopicSpec>,
}

impl Mapping {
    /// Reads (through fdd's 4 MiB text-file limit), parses and checks the mapping file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text =
            fdd_monitor::text_file::read_text(path).map_err(|e| ConfigError::File(Box::new(e)))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses and checks mapping text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let file: MappingFile = parse_toml(text, origin)?;
        let root = KeyPath::file(origin);

        let delimiter = match file.csv.delimiter.as_deref() {
            None => b',',
            Some(d) => match d.as_bytes() {
                [b] if usable_delimiter(*b) => *b,
                _ => {
                    return Err(root.key("csv").key("delimiter").invalid(
                        format!("{d:?}"),
                        "must be one ASCII character that cannot be part of a number or a quote (`,`, `;`, `\\t`, `|`, ...)",
                    ))
                }
            },
        };

        let time = check_time(&root.key("time"), &file.time)?;

        let truth_topic = match &file.truth {
            Some(t) => {
                let at = root.key("truth").key("topic");
                check_topic_name(&at, &t.topic)?;
                if builtin_topic(&t.topic).is_some() {
                    return Err(at.invalid(
                        format!("{:?}", t.topic),
                        "is one of fdd's own topics, whose truth has other fields; name the imported truth e.g. `/truth/turbo`",
                    ));
                }
                Some(t.topic.clone())
            }
            None => None,
        };

        let topics_key = root.key("topics");
        if file.topics.is_empty() {
            return Err(topics_key.invalid("[]", "the mapping must write at least one topic"));
        }
        if file.topics.len() > MAX_TOPICS {
            return Err(topics_key.invalid(
                format!("({} topics)", file.topics.len()),
                format!("at most {MAX_TOPICS} topics (fdd's reader accepts 10,000 channels by default, one is the truth)"),
            ));
        }
        let mut topics: Vec<TopicSpec> = Vec::with_capacity(file.topics.len());
        for (i, t) in file.topics.iter().enumerate() {
            let at = topics_key.index(i);
            let spec = check_topic(&at, t)?;
            if let Some(j) = topics.iter().position(|o| o.topic == spec.topic) {
                return Err(at.key("topic").invalid(
                    format!("{:?}", spec.topic),
                    format!("already written by topics[{j}]: one topic, one table"),
                ));
            }
            if truth_topic.as_deref() == Some(spec.topic.as_str()) {
                return Err(at
                    .key("topic")
                    .invalid(format!("{:?}", spec.topic), "is the [truth] topic"));
            }
            topics.push(spec);
        }
        Ok(Mapping {
            origin: origin.to_string(),
            delimiter,
            time,
            truth_topic,
            topics,
        })
    }
}

/// A field delimiter: one ASCII character that is no part of a number (digits, `.`, `-`, `+`,
/// letters of `e`, `NaN`), nor a quote or a line end.
fn usable_delimiter(b: u8) -> bool {
    b.is_ascii()
        && !b.is_ascii_alphanumeric()
        && !matches!(b, b'"' | b'\n' | b'\r' | b'.' | b'-' | b'+')
}

fn check_time(at: &KeyPath, t: &TimeTable) -> Result<TimeSpec, ConfigError> {
    let offset_s = t.offset_s.unwrap_or(0.0);
    at.key("offset_s").check(offset_s, OFFSET_RANGE)?;
    let offset_ns = (offset_s * 1e9).round() as i128;
    match (&t.column, t.period_s) {
        (Some(_), Some(p)) => Err(at.key("period_s").invalid(
            show(p),
            "give either `column` (a time column) or `period_s` (rows evenly spaced), not both",
        )),
        (None, None) => Err(at.key("column").invalid(
            "(missing)",
            "give `column` (the time column, with `unit`) or `period_s` (rows evenly spaced, s)",
        )),
        (Some(column), None) => {
            at.key("column").check_name(column)?;
            let unit = match t.unit.as_deref() {
                Some("s") => TimeUnit::S,
                Some("ms") => TimeUnit::Ms,
                Some("us") => TimeUnit::Us,
                Some("ns") => TimeUnit::Ns,
                Some(other) => {
                    return Err(at.key("unit").invalid(
                        format!("{other:?}"),
                        "must be one of \"s\", \"ms\", \"us\", \"ns\"",
                    ))
                }
                None => {
                    return Err(at.key("unit").invalid(
                        "(missing)",
                        "the time column's unit: one of \"s\", \"ms\", \"us\", \"ns\"",
                    ))
                }
            };
            let from_first_row = match t.origin.as_deref() {
                None | Some("keep") => false,
                Some("first_row") => true,
                Some(other) => {
                    return Err(at.key("origin").invalid(
                        format!("{other:?}"),
                        "must be \"keep\" (log time = the column's time) or \"first_row\" (the first row at 0)",
                    ))
                }
            };
            Ok(TimeSpec::Column {
                column: column.clone(),
                key: at.key("column").path(),
                unit,
                from_first_row,
                offset_ns,
            })
        }
        (None, Some(p)) => {
            at.key("period_s").check(p, PERIOD_RANGE)?;
            for (key, given) in [("unit", t.unit.is_some()), ("origin", t.origin.is_some())] {
                if given {
                    return Err(at.key(key).invalid(
                        "(given)",
                        "only with a time `column`; with `period_s` the rows have no time of their own",
                    ));
                }
            }
            Ok(TimeSpec::Periodic {
                period_ns: ((p * 1e9).round() as u64).max(1),
                offset_ns,
            })
        }
    }
}

/// A channel topic: `/` then segments of letters, digits, `_`, `.`, `-` separated by `/`.
fn check_topic_name(at: &KeyPath, topic: &str) -> Result<(), ConfigError> {
    let ok = topic.len() <= 256
        && topic.strip_prefix('/').is_some_and(|rest| {
            rest.split('/').all(|seg| {
                !seg.is_empty()
                    && seg
                        .bytes()
                        .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'.' | b'-'))
            })
        });
    if !ok {
        return Err(at.invalid(
            format!("{topic:?}"),
            "must be a topic such as \"/turbo/p_im\": `/` then names of letters, digits, `_`, `.`, `-` separated by `/` (at most 256 characters)",
        ));
    }
    Ok(())
}

fn check_topic(at: &KeyPath, t: &TopicTable) -> Result<TopicSpec, ConfigError> {
    let topic_key = at.key("topic");
    check_topic_name(&topic_key, &t.topic)?;
    if t.topic.starts_with("/fdd/") || t.topic == "/fdd" {
        return Err(topic_key.invalid(
            format!("{:?}", t.topic),
            "`/fdd/` topics are fdd's monitor outputs, not inputs",
        ));
    }
    let builtin = builtin_topic(&t.topic);
    if builtin.is_some() && t.topic.starts_with("/truth/") {
        return Err(topic_key.invalid(
            format!("{:?}", t.topic),
            "is a simulated truth topic of fdd with fields a CSV does not have; use [truth] for an imported log's fault",
        ));
    }
    if let Some(d) = &t.description {
        at.key("description").check_name(d)?;
    }
    let fields_key = at.key("fields");
    if t.fields.is_empty() {
        return Err(fields_key.invalid("[]", "a topic needs at least one field"));
    }
    let mut fields: Vec<FieldSpec> = Vec::with_capacity(t.fields.len());
    for (i, f) in t.fields.iter().enumerate() {
        let fa = fields_key.index(i);
        let name_key = fa.key("name");
        let valid_name = f.name.len() <= 128
            && f.name
                .bytes()
                .next()
                .is_some_and(|b| b.is_ascii_alphabetic() || b == b'_')
            && f.name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'_');
        if !valid_name {
            return Err(name_key.invalid(
                format!("{:?}", f.name),
                "must be a name of letters, digits and `_` not starting with a digit, with its unit in it (`pressure_pa`); a dot would read as a nested path in config/fdd.toml",
            ));
        }
        if let Some(j) = fields.iter().position(|o| o.name == f.name) {
            return Err(name_key.invalid(
                format!("{:?}", f.name),
                format!("already fields[{j}] of this topic"),
            ));
        }
        fa.key("column").check_name(&f.column)?;
        fa.key("unit").check_name(&f.unit)?;
        let scale = f.scale.unwrap_or(1.0);
        if !scale.is_finite() || scale == 0.0 {
            return Err(fa.key("scale").invalid(
                show(scale),
                "must be a finite number other than 0 (value = column x scale + offset)",
            ));
        }
        let offset = f.offset.unwrap_or(0.0);
        if !offset.is_finite() {
            return Err(fa.key("offset").invalid(
                show(offset),
                "must be a finite number (value = column x scale + offset)",
            ));
        }
        if let Some(d) = &f.description {
            fa.key("description").check_name(d)?;
        }
        fields.push(FieldSpec {
            name: f.name.clone(),
            column: f.column.clone(),
            column_key: fa.key("column").path(),
            unit: f.unit.clone(),
            scale,
            offset,
            description: f.description.clone(),
        });
    }
    if let Some(b) = builtin {
        let mut want = required_fields(b);
        want.sort();
        let mut have: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
        have.sort();
        if want != have {
            return Err(fields_key.invalid(
                format!("{have:?}"),
                format!(
                    "{} is an fdd topic with the fields {want:?} (its schema `{}`): map exactly those",
                    b.topic, b.schema_name
                ),
            ));
        }
    }
    Ok(TopicSpec {
        topic: t.topic.clone(),
        description: t.description.clone(),
        optional: t.optional,
        fields,
        key: at.path(),
        builtin,
    })
}

/// The `required` keys of one of fdd's schemas.
fn required_fields(b: &TopicSchema) -> Vec<&str> {
    // The schemas are fdd's own, checked by fdd-monitor's tests; an unreadable one has none.
    let Some(start) = b.schema.find("\"required\"") else {
        return Vec::new();
    };
    let rest = &b.schema[start..];
    let (Some(open), Some(close)) = (rest.find('['), rest.find(']')) else {
        return Vec::new();
    };
    rest.get(open + 1..close)
        .unwrap_or_default()
        .split(',')
        .map(|s| s.trim().trim_matches('"'))
        .filter(|s| !s.is_empty())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[time]
column = "time"
unit = "s"

[truth]
topic = "/truth/turbo"

[[topics]]
topic = "/turbo/p_im"
fields = [{ name = "pressure_pa", column = "p_im", unit = "Pa", scale = 1000 }]
"#;

    fn err(text: &str) -> String {
        Mapping::parse(text, "m.toml")
            .expect_err("refused")
            .to_string()
    }

    #[test]
    fn a_good_mapping_reads() {
        let m = Mapping::parse(GOOD, "m.toml").expect("valid");
        assert_eq!(m.delimiter, b',');
        assert_eq!(m.truth_topic.as_deref(), Some("/truth/turbo"));
        assert_eq!(m.topics[0].fields[0].scale, 1000.0);
        assert_eq!(m.topics[0].fields[0].offset, 0.0);
        assert_eq!(
            m.topics[0].fields[0].column_key,
            "topics[0].fields[0].column"
        );
        assert!(matches!(
            m.time,
            TimeSpec::Column {
                unit: TimeUnit::S,
                from_first_row: false,
                offset_ns: 0,
                ..
            }
        ));
    }

    #[test]
    fn errors_name_file_table_and_key() {
        let e = err(&GOOD.replace("unit = \"s\"", "unit = \"sec\""));
        assert!(
            e.starts_with("m.toml: [time] unit = \"sec\": must be one of"),
            "{e}"
        );
        let e = err(&GOOD.replace("scale = 1000", "scale = 0"));
        assert!(
            e.starts_with("m.toml: topics[0].fields[0].scale = 0.0:"),
            "{e}"
        );
        let e = err(&GOOD.replace("scale = 1000", "scale = nan"));
        assert!(e.contains("topics[0].fields[0].scale = NaN"), "{e}");
        let e = err(&GOOD.replace("scale = 1000", "scael = 1000"));
        assert!(
            e.contains("topics[0].fields[0]") && e.contains("scael"),
            "{e}"
        );
        let e = err(&GOOD.replace("\"/turbo/p_im\"", "\"turbo\""));
        assert!(e.contains("topics[0].topic = \"turbo\""), "{e}");
        let e = err(&GOOD.replace("\"/turbo/p_im\"", "\"/truth/turbo\""));
        assert!(e.contains("is the [truth] topic"), "{e}");
        let e = err(&GOOD.replace("\"/turbo/p_im\"", "\"/fdd/x\""));
        assert!(e.contains("monitor outputs"), "{e}");
        let e = err(&GOOD.replace("column = \"time\"", "period_s = 1.0"));
        assert!(e.contains("[time] unit = (given)"), "{e}");
        let e = err(&GOOD
            .replace("column = \"time\"\n", "")
            .replace("unit = \"s\"\n", ""));
        assert!(e.contains("[time] column = (missing)"), "{e}");
        let e = err(&GOOD.replace("pressure_pa", "pressure.pa"));
        assert!(
            e.contains("topics[0].fields[0].name = \"pressure.pa\""),
            "{e}"
        );
        let e = err(&format!("{GOOD}\n[csv]\ndelimiter = \"ab\"\n"));
        assert!(e.contains("[csv] delimiter = \"ab\""), "{e}");
        let e = err(&GOOD.replace("/truth/turbo", "/truth/intake"));
        assert!(e.contains("[truth] topic = \"/truth/intake\""), "{e}");
    }

    #[test]
    fn fdd_input_topics_need_exactly_their_fields() {
        let text = GOOD.replace("/turbo/p_im", "/intake/map");
        let m = Mapping::parse(&text, "m.toml").expect("valid");
        assert!(m.topics[0].builtin.is_some());
        let e = err(&text.replace("pressure_pa", "p_pa"));
        assert!(e.contains("[\"pressure_pa\"]"), "{e}");
        assert_eq!(
            required_fields(&fdd_monitor::log::schema::INTAKE_TRUTH),
            [
                "p_m_pa",
                "w_thr_kg_s",
                "w_egr_kg_s",
                "w_inv_kg_s",
                "w_leak_kg_s",
                "egr_actual",
                "fault",
                "fault_active",
                "fault_observable"
            ]
        );
    }
}
