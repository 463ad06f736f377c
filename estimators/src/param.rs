//! Checking parameters a user writes against their physical range, with errors that name the
//! key as written and the value in readable form.
//!
//! A [`Range`] is the admissible interval of one key with its unit; [`Range::check`] refuses
//! NaN, infinities and values outside it with a [`ParamError`] whose message states the bound
//! (`must be between 1e-4 and 1 s`). The keys of a [`ParamError`] are relative to the table
//! the parameters come from (`dt_s`, `modes[2].a12`, `vol_eff_speeds_rpm[3]`); the caller adds
//! the file and the table.

use serde::{Deserialize, Deserializer};
use thiserror::Error;

/// A parameter outside its admissible range. `key` is relative to the parameters' table,
/// `value` is readable (`1e300`, `NaN`, `"text"`), `reason` states the admissible range.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("`{key}` = {value}: {reason}")]
pub struct ParamError {
    pub key: String,
    pub value: String,
    pub reason: String,
}

impl ParamError {
    /// An error for `key` holding `value` (already readable).
    pub fn new(
        key: impl Into<String>,
        value: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        Self {
            key: key.into(),
            value: value.into(),
            reason: reason.into(),
        }
    }
}

/// A number as it is printed in messages: the shortest form that reads back to the same value,
/// with an exponent for very large and very small magnitudes (`1e300`, `0.001`, `-1.0`, `NaN`).
pub fn show(v: f64) -> String {
    format!("{v:?}")
}

/// A bound as printed in messages: plain between 0.001 and a million (`1`, `3600`, `0.5`),
/// with an exponent otherwise (`1e-4`, `1e15`).
pub fn show_bound(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || (1e-3..1e6).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// The admissible interval of a parameter and its unit. Each end is closed (the bound is
/// admissible) or open.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    pub min: f64,
    pub max: f64,
    /// `min` itself is refused.
    pub min_open: bool,
    /// `max` itself is refused.
    pub max_open: bool,
    /// Unit in messages (`s`, `V`, `deg`; empty for dimensionless values).
    pub unit: &'static str,
}

impl Range {
    /// `min <= v <= max`.
    pub const fn closed(min: f64, max: f64, unit: &'static str) -> Self {
        Self {
            min,
            max,
            min_open: false,
            max_open: false,
            unit,
        }
    }

    /// `min < v <= max` (typically `0 < v`).
    pub const fn above(min: f64, max: f64, unit: &'static str) -> Self {
        Self {
            min,
            max,
            min_open: true,
            max_open: false,
            unit,
        }
    }

    /// `min <= v < max`.
    pub const fn below(min: f64, max: f64, unit: &'static str) -> Self {
        Self {
            min,
            max,
            min_open: false,
            max_open: true,
            unit,
        }
    }

    /// `min < v < max`.
    pub const fn open(min: f64, max: f64, unit: &'static str) -> Self {
        Self {
            min,
            max,
            min_open: true,
            max_open: true,
            unit,
        }
    }

    /// Whether `v` is admissible (never for NaN or an infinity).
    pub fn contains(&self, v: f64) -> bool {
        let lo = if self.min_open {
            v > self.min
        } else {
            v >= self.min
        };
        let hi = if self.max_open {
            v < self.max
        } else {
            v <= self.max
        };
        v.is_finite() && lo && hi
    }

    /// The requirement in words: `must be between 1e-4 and 1 s`, `must be above 0 and at most
    /// 10 V`, `must be at least 0 and below 1`.
    pub fn describe(&self) -> String {
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        let (lo, hi) = (show_bound(self.min), show_bound(self.max));
        match (self.min_open, self.max_open) {
            (false, false) => format!("must be between {lo} and {hi}{unit}"),
            (true, false) => format!("must be above {lo} and at most {hi}{unit}"),
            (false, true) => format!("must be at least {lo} and below {hi}{unit}"),
            (true, true) => format!("must be above {lo} and below {hi}{unit}"),
        }
    }

    /// `Ok` if `v` is admissible, else an error for `key` stating the range.
    pub fn check(&self, key: &str, v: f64) -> Result<(), ParamError> {
        if self.contains(v) {
            Ok(())
        } else {
            Err(ParamError::new(key, show(v), self.describe()))
        }
    }
}

/// Deserializes a fixed-size array from a TOML array of exactly `N` values: serde's own
/// `[T; N]` reads the first `N` and silently drops the rest. Use with
/// `#[serde(deserialize_with = "fdd_estimators::param::exact_array")]`.
pub fn exact_array<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    let v: Vec<T> = Vec::deserialize(d)?;
    let n = v.len();
    v.try_into().map_err(|_| {
        let expected = format!("an array of exactly {N} values");
        serde::de::Error::invalid_length(n, &expected.as_str())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_refuse_nan_infinities_and_out_of_range_and_state_the_bound() {
        let r = Range::closed(1e-4, 1.0, "s");
        assert!(r.contains(1e-4) && r.contains(1.0) && r.contains(0.5));
        for v in [f64::NAN, f64::INFINITY, -1.0, 0.0, 1e300, 1.0 + 1e-12] {
            assert!(!r.contains(v), "{v}");
        }
        let e = r.check("period_s", 1e300).unwrap_err();
        assert_eq!(
            e.to_string(),
            "`period_s` = 1e300: must be between 1e-4 and 1 s"
        );
        let e = Range::above(0.0, 10.0, "")
            .check("x", f64::NAN)
            .unwrap_err();
        assert_eq!(e.to_string(), "`x` = NaN: must be above 0 and at most 10");
        assert!(!Range::above(0.0, 10.0, "").contains(0.0));
        assert!(!Range::below(0.0, 1.0, "").contains(1.0));
        assert_eq!(show_bound(3600.0), "3600");
        assert_eq!(show_bound(0.5), "0.5");
        assert_eq!(show_bound(-3.0), "-3");
        assert_eq!(show_bound(1e-5), "1e-5");
        assert_eq!(show_bound(1e15), "1e15");
    }

    #[derive(Debug, Deserialize)]
    struct A {
        #[serde(deserialize_with = "exact_array")]
        v: [f64; 3],
    }

    #[test]
    fn exact_arrays_refuse_extra_and_missing_entries() {
        let a: A = toml::from_str("v = [1.0, 2.0, 3.0]").expect("three values");
        assert_eq!(a.v, [1.0, 2.0, 3.0]);
        for text in ["v = [1.0, 2.0, 3.0, 4.0]", "v = [1.0, 2.0]"] {
            let e = toml::from_str::<A>(text).unwrap_err();
            assert!(
                e.message().contains("exactly 3 values"),
                "{text}: {}",
                e.message()
            );
        }
    }
}
