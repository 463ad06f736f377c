//! Where a configuration value sits, carried from parsing to the check that refuses it, so
//! that every error names the file, the table and the full key the user wrote.
//!
//! A [`KeyPath`] is a file (its origin: a path or `embedded config/throttle.toml`) plus the key
//! segments below the document root: table and key names and array indices. Validators get the
//! path of their table and extend it ([`KeyPath::key`], [`KeyPath::index`],
//! [`KeyPath::join`]); the checkers ([`KeyPath::check`], [`KeyPath::check_count`],
//! [`KeyPath::check_name`], [`KeyPath::check_dtc`]) compare a value with its admissible
//! [`Range`] and build the one error shape, [`ConfigError::Invalid`]:
//!
//! ```text
//! config/throttle.toml: [monitor] period_s = 1e300: must be between 1e-4 and 1 s
//! config/fdd.toml: signals[1].max_age_s = -1.0: must be between 1e-4 and 3600 s
//! config/throttle.toml: [model] modes[2].a12 = NaN: must be between -1000 and 1000
//! ```
//!
//! A key below a table is written `[table] key` (`[monitor] q_std[6]`, `[model] modes[2].a12`);
//! a key below an array of tables, which has no single table header, is written as the full
//! dotted path (`signals[1].max_age_s`). TOML errors (a wrong type, an unknown key, an array
//! of the wrong length) are located the same way from the span the TOML parser reports
//! ([`toml_error`]).

use std::fmt;

use fdd_diagnostics::dtc::Dtc;
pub use fdd_estimators::param::{show, Range};
use fdd_estimators::ParamError;

use crate::config::ConfigError;

/// One segment of a key path.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Segment {
    Key(String),
    Index(usize),
}

/// A file and a key path in it. Cheap enough to build at every check (configuration files
/// are parsed once).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyPath {
    origin: String,
    segments: Vec<Segment>,
}

impl KeyPath {
    /// The root of the file `origin`.
    pub fn file(origin: impl Into<String>) -> Self {
        Self {
            origin: origin.into(),
            segments: Vec::new(),
        }
    }

    /// The child key `name` (a table or a value).
    pub fn key(&self, name: &str) -> Self {
        let mut p = self.clone();
        p.segments.push(Segment::Key(name.to_string()));
        p
    }

    /// Element `i` of the array at this path.
    pub fn index(&self, i: usize) -> Self {
        let mut p = self.clone();
        p.segments.push(Segment::Index(i));
        p
    }

    /// The descendant named by a relative dotted path such as `modes[2].a12` or `q_std[3]`
    /// (the keys of a [`ParamError`]).
    pub fn join(&self, relative: &str) -> Self {
        let mut p = self.clone();
        for part in relative.split('.').filter(|s| !s.is_empty()) {
            let (name, mut rest) = match part.find('[') {
                Some(i) => (&part[..i], &part[i..]),
                None => (part, ""),
            };
            if !name.is_empty() {
                p.segments.push(Segment::Key(name.to_string()));
            }
            while let Some((inner, after)) = rest.strip_prefix('[').and_then(|r| r.split_once(']'))
            {
                match inner.parse::<usize>() {
                    Ok(i) => p.segments.push(Segment::Index(i)),
                    Err(_) => p.segments.push(Segment::Key(inner.to_string())),
                }
                rest = after;
            }
        }
        p
    }

    /// The file.
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// The key as the user reads it: `[monitor] period_s`, `signals[1].max_age_s`.
    pub fn path(&self) -> String {
        self.to_string()
    }

    /// The error "this key holds `value`, refused because `reason`". `value` is already
    /// readable: [`show`] for numbers, `{:?}` for strings.
    pub fn invalid(&self, value: impl fmt::Display, reason: impl Into<String>) -> ConfigError {
        ConfigError::Invalid {
            origin: self.origin.clone(),
            key: self.path(),
            value: value.to_string(),
            reason: reason.into(),
        }
    }

    /// A [`ParamError`] of the parameters at this path (its key is relative to this path).
    pub fn param(&self, e: ParamError) -> ConfigError {
        self.join(&e.key).invalid(e.value, e.reason)
    }

    /// `v` within `range` (never NaN nor infinite).
    pub fn check(&self, v: f64, range: Range) -> Result<(), ConfigError> {
        if range.contains(v) {
            Ok(())
        } else {
            Err(self.invalid(show(v), range.describe()))
        }
    }

    /// A count `n` within `min..=max` `unit` (`samples`, `segments`, `alarms`).
    pub fn check_count(
        &self,
        n: impl Into<u64>,
        min: u64,
        max: u64,
        unit: &str,
    ) -> Result<(), ConfigError> {
        let n = n.into();
        if (min..=max).contains(&n) {
            Ok(())
        } else {
            Err(self.invalid(n, format!("must be between {min} and {max} {unit}")))
        }
    }

    /// A name (of a signal, a topic, a field) that must not be blank.
    pub fn check_name(&self, s: &str) -> Result<(), ConfigError> {
        if s.trim().is_empty() {
            Err(self.invalid(format!("{s:?}"), "must not be empty"))
        } else {
            Ok(())
        }
    }

    /// A DTC (`P0120-31`: SAE J2012 code and failure type byte).
    pub fn check_dtc(&self, s: &str) -> Result<Dtc, ConfigError> {
        s.parse::<Dtc>()
            .map_err(|e| self.invalid(format!("{s:?}"), e.reason()))
    }

    /// The DTC keys `entries` (key, text) of this table: each a valid DTC, and no two the same
    /// (a monitor's events are told apart by their DTC).
    pub fn check_dtcs(&self, entries: &[(&str, &str)]) -> Result<(), ConfigError> {
        let mut seen: Vec<(&str, Dtc)> = Vec::with_capacity(entries.len());
        for &(key, text) in entries {
            let d = self.key(key).check_dtc(text)?;
            if let Some((other, _)) = seen.iter().find(|(_, e)| *e == d) {
                return Err(self
                    .key(key)
                    .invalid(format!("{text:?}"), format!("DTC {d} is already `{other}`")));
            }
            seen.push((key, d));
        }
        Ok(())
    }
}

impl fmt::Display for KeyPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut segs = self.segments.iter();
        let mut first = true;
        // `[table] rest` when the path starts with a table (a key followed by a key).
        if let (Some(Segment::Key(table)), Some(Segment::Key(_))) =
            (self.segments.first(), self.segments.get(1))
        {
            write!(f, "[{table}] ")?;
            segs.next();
        }
        for s in segs {
            match s {
                Segment::Key(k) => {
                    if !first {
                        f.write_str(".")?;
                    }
                    f.write_str(k)?;
                }
                Segment::Index(i) => write!(f, "[{i}]")?,
            }
            first = false;
        }
        Ok(())
    }
}

/// Smallest bias of a CUSUM (`*_min_bias_sigma`), in innovation standard deviations.
pub const CUSUM_MIN_BIAS: Range = Range::above(0.0, 100.0, "sigma");
/// Threshold of a CUSUM (`*_cusum_threshold`), in normalized residual x steps.
pub const CUSUM_THRESHOLD: Range = Range::above(0.0, 1e4, "");

/// A CUSUM's smallest bias `delta` (key `bias`) and threshold `h` (key `threshold`), both in
/// `table`: each in its range, and together giving a finite false-alarm run length (the
/// run length grows like `exp(delta h)`).
pub fn check_cusum(
    table: &KeyPath,
    bias: &str,
    delta: f64,
    threshold: &str,
    h: f64,
) -> Result<(), ConfigError> {
    table.key(bias).check(delta, CUSUM_MIN_BIAS)?;
    table.key(threshold).check(h, CUSUM_THRESHOLD)?;
    let arl = fdd_diagnostics::detectors::two_sided_arl(0.0, delta / 2.0, h);
    if !arl.is_finite() {
        let h_max = (700.0 / delta - 2.0).floor().max(0.0);
        return Err(table.key(threshold).invalid(
            show(h),
            format!(
                "must be at most {} with `{bias}` = {}: beyond, the false-alarm run length overflows",
                fdd_estimators::param::show_bound(h_max),
                show(delta)
            ),
        ));
    }
    Ok(())
}

/// A TOML error of `text` (the file `origin`) as a [`ConfigError`]: located at the key whose
/// key or value holds the error's span when there is one ([`ConfigError::Invalid`] with the
/// value as written and the parser's message), else with its line and column
/// ([`ConfigError::Message`]).
pub fn toml_error(origin: &str, text: &str, e: &toml::de::Error) -> ConfigError {
    let message = shorten_unknown_field(e.message().trim_end());
    let Some(span) = e.span() else {
        return ConfigError::Message {
            origin: origin.to_string(),
            message,
        };
    };
    let root = KeyPath::file(origin);
    // The recoverable parse keeps what it could read, so that an error in one value (a float
    // that overflows) is still located.
    let (doc, _) = toml::de::DeTable::parse_recoverable(text);
    let found = locate(&root, doc.get_ref(), span.start);
    match found {
        Some((mut at, shape, value_span)) => {
            let mut value = match shape {
                Shape::Table => "(table)".to_string(),
                Shape::TableArray => "(array of tables)".to_string(),
                Shape::Value => text.get(value_span).unwrap_or_default().trim().to_string(),
            };
            // A table array of the wrong length is reported at its first table: name the array.
            if message.starts_with("invalid length") {
                if let Some(Segment::Index(_)) = at.segments.last() {
                    at.segments.pop();
                    value = "(array of tables)".to_string();
                }
            }
            // `missing field `x`` points at the table: name the field.
            if let Some(field) = message
                .strip_prefix("missing field `")
                .and_then(|r| r.strip_suffix('`'))
            {
                at = at.key(field);
                value = "(missing)".to_string();
            }
            if value.chars().count() > 80 {
                value = format!("{}...", value.chars().take(77).collect::<String>());
            }
            at.invalid(value, message)
        }
        None => {
            let before = text.get(..span.start).unwrap_or(text);
            let line = before.matches('\n').count() + 1;
            let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            ConfigError::Message {
                origin: origin.to_string(),
                message: format!("line {line}, column {column}: {message}"),
            }
        }
    }
}

/// `unknown field `x`, expected one of `a`, `b`, ...` with the list of a large table replaced
/// by the nearest key, if one is near (`did you mean `isolation_margin`?`).
fn shorten_unknown_field(message: &str) -> String {
    let Some((head, list)) = message.split_once(", expected one of ") else {
        return message.to_string();
    };
    let Some(unknown) = head
        .strip_prefix("unknown field `")
        .and_then(|r| r.strip_suffix('`'))
    else {
        return message.to_string();
    };
    let keys: Vec<&str> = list.split(", ").map(|k| k.trim_matches('`')).collect();
    if keys.len() <= 8 {
        return message.to_string();
    }
    let nearest = keys
        .iter()
        .map(|k| (edit_distance(unknown, k), *k))
        .min()
        .filter(|(d, _)| *d <= 3);
    match nearest {
        Some((_, k)) => format!("{head}: not a key of this table (did you mean `{k}`?)"),
        None => format!("{head}: not a key of this table"),
    }
}

/// Levenshtein distance of two keys.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// What a located key holds, for the value shown in the message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Shape {
    Value,
    Table,
    TableArray,
}

fn shape(v: &toml::de::DeValue<'_>) -> Shape {
    match v {
        toml::de::DeValue::Table(_) => Shape::Table,
        toml::de::DeValue::Array(a)
            if !a.is_empty() && a.iter().all(|e| e.get_ref().is_table()) =>
        {
            Shape::TableArray
        }
        _ => Shape::Value,
    }
}

/// Where an error is: the key, what it holds and the span of its value.
type Located = (KeyPath, Shape, std::ops::Range<usize>);

/// The deepest key whose key or value span contains `pos`, and what it holds.
fn locate(at: &KeyPath, table: &toml::de::DeTable<'_>, pos: usize) -> Option<Located> {
    for (k, v) in table.iter() {
        let here = at.key(k.get_ref());
        if let Some(deeper) = locate_value(&here, v, pos) {
            return Some(deeper);
        }
        if k.span().contains(&pos) || v.span().contains(&pos) {
            return Some((here, shape(v.get_ref()), v.span()));
        }
    }
    None
}

fn locate_value(
    at: &KeyPath,
    v: &toml::Spanned<toml::de::DeValue<'_>>,
    pos: usize,
) -> Option<Located> {
    match v.get_ref() {
        toml::de::DeValue::Table(t) => locate(at, t, pos),
        toml::de::DeValue::Array(a) => {
            for (i, e) in a.iter().enumerate() {
                let here = at.index(i);
                if let Some(deeper) = locate_value(&here, e, pos) {
                    return Some(deeper);
                }
                if e.span().contains(&pos) {
                    return Some((here, shape(e.get_ref()), e.span()));
                }
            }
            None
        }
        _ => None,
    }
}

/// Parses `text` (the file `origin`) into `T`, TOML errors located by [`toml_error`].
pub fn parse_toml<T: serde::de::DeserializeOwned>(
    text: &str,
    origin: &str,
) -> Result<T, ConfigError> {
    toml::from_str(text).map_err(|e| toml_error(origin, text, &e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_read_as_table_and_key() {
        let f = KeyPath::file("x.toml");
        assert_eq!(
            f.key("monitor").key("period_s").path(),
            "[monitor] period_s"
        );
        assert_eq!(
            f.key("monitor").key("q_std").index(6).path(),
            "[monitor] q_std[6]"
        );
        assert_eq!(
            f.key("model").join("modes[2].a12").path(),
            "[model] modes[2].a12"
        );
        assert_eq!(
            f.key("signals").index(1).key("max_age_s").path(),
            "signals[1].max_age_s"
        );
        assert_eq!(f.key("signals").path(), "signals");
        assert_eq!(f.key("m").join("a[0][1].b").path(), "[m] a[0][1].b");
        assert_eq!(
            f.key("staleness").join("debounce.failed_time_s").path(),
            "[staleness] debounce.failed_time_s"
        );
        let e = f
            .key("monitor")
            .key("period_s")
            .check(1e300, Range::closed(1e-4, 1.0, "s"))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "x.toml: [monitor] period_s = 1e300: must be between 1e-4 and 1 s"
        );
        let e = f
            .key("m")
            .key("dtc_x")
            .check_dtc("X12")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.toml: [m] dtc_x = \"X12\": "), "{e}");
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Doc {
        signals: Vec<Sig>,
        model: Model,
    }
    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Sig {
        name: String,
        max_age_s: f64,
    }
    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Model {
        #[serde(deserialize_with = "fdd_estimators::param::exact_array")]
        v: [f64; 3],
    }

    #[test]
    fn toml_errors_name_the_key() {
        let ok = "[[signals]]\nname = \"a\"\nmax_age_s = 1.0\n[model]\nv = [1.0, 2.0, 3.0]\n";
        parse_toml::<Doc>(ok, "f.toml").expect("valid");
        let cases = [
            (
                ok.replace("max_age_s = 1.0", "max_age_s = \"x\""),
                "f.toml: signals[0].max_age_s = \"x\": invalid type",
            ),
            (
                ok.replace("max_age_s = 1.0", "max_age = 1.0"),
                "f.toml: signals[0].max_age = 1.0: unknown field `max_age`",
            ),
            (
                ok.replace("max_age_s = 1.0\n", ""),
                "f.toml: signals[0].max_age_s = (missing): missing field",
            ),
            (
                ok.replace("3.0]", "3.0, 4.0]"),
                "f.toml: [model] v = [1.0, 2.0, 3.0, 4.0]: invalid length 4",
            ),
            (
                ok.replace("2.0, 3.0]", "true, 3.0]"),
                "f.toml: [model] v[1] = true: invalid type",
            ),
            (
                ok.replace("max_age_s = 1.0", "max_age_s = 1e400"),
                "f.toml: signals[0].max_age_s = 1e400: ",
            ),
        ];
        for (text, want) in cases {
            let e = parse_toml::<Doc>(&text, "f.toml").unwrap_err().to_string();
            assert!(e.starts_with(want), "{e}\nwanted: {want}");
        }
        let long = format!(
            "unknown field `isolation_margni`, expected one of {}",
            ["a", "b", "c", "d", "e", "f", "g", "h", "isolation_margin"]
                .map(|k| format!("`{k}`"))
                .join(", ")
        );
        assert_eq!(
            shorten_unknown_field(&long),
            "unknown field `isolation_margni`: not a key of this table (did you mean `isolation_margin`?)"
        );
        let e = parse_toml::<Doc>("[[signals]\n", "f.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("f.toml: line 1, column"), "{e}");
    }
}
