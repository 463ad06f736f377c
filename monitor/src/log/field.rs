//! Extracting one numeric field from a JSON message by name, without building a
//! `serde_json::Value` (no allocation for keys without escapes).
//!
//! The runtime maps configurable `(topic, field)` pairs to signals; [`json_field_f64`] is that
//! lookup. A path is a field name, or names joined by `.` for nested objects
//! (`test_result.value`). `null` reads as NaN (fdd writes non-finite numbers as `null`).

use std::fmt;

use serde::de::{DeserializeSeed, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};

/// Why [`json_field_f64`] found no number.
#[derive(Debug)]
pub enum FieldLookupError {
    /// The bytes are not valid JSON.
    Json(serde_json::Error),
    /// The field (or an object on its path) is absent.
    Missing,
    /// The field holds something other than a number or `null`: `"a string"`, `"a boolean"`,
    /// `"an array"` or `"an object"`.
    NotANumber(&'static str),
}

impl fmt::Display for FieldLookupError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FieldLookupError::Json(e) => write!(f, "invalid JSON: {e}"),
            FieldLookupError::Missing => f.write_str("field missing"),
            FieldLookupError::NotANumber(found) => write!(f, "not a number (it is {found})"),
        }
    }
}

impl std::error::Error for FieldLookupError {}

/// The number at `path` (`name` or `outer.inner`) in the JSON object `json`; `null` gives NaN.
/// The whole text is checked to be valid JSON.
pub fn json_field_f64(json: &[u8], path: &str) -> Result<f64, FieldLookupError> {
    let mut de = serde_json::Deserializer::from_slice(json);
    let found = Lookup { path }
        .deserialize(&mut de)
        .map_err(FieldLookupError::Json)?;
    de.end().map_err(FieldLookupError::Json)?;
    match found {
        Found::Number(x) => Ok(x),
        Found::Null => Ok(f64::NAN),
        Found::Missing => Err(FieldLookupError::Missing),
        Found::Other(what) => Err(FieldLookupError::NotANumber(what)),
    }
}

enum Found {
    Number(f64),
    Null,
    Missing,
    Other(&'static str),
}

/// Looks up `path` in the value being deserialized.
struct Lookup<'p> {
    path: &'p str,
}

impl<'de> DeserializeSeed<'de> for Lookup<'_> {
    type Value = Found;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Found, D::Error> {
        d.deserialize_any(LookupVisitor { path: self.path })
    }
}

struct LookupVisitor<'p> {
    path: &'p str,
}

/// Consumes a sequence without keeping it.
fn skip_seq<'de, A: SeqAccess<'de>>(mut seq: A) -> Result<(), A::Error> {
    while seq.next_element::<IgnoredAny>()?.is_some() {}
    Ok(())
}

impl<'de> Visitor<'de> for LookupVisitor<'_> {
    type Value = Found;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a JSON value")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Found, A::Error> {
        let (head, rest) = match self.path.split_once('.') {
            Some((h, r)) => (h, Some(r)),
            None => (self.path, None),
        };
        let mut found = Found::Missing;
        while let Some(is_match) = map.next_key_seed(KeyEq(head))? {
            if is_match && matches!(found, Found::Missing) {
                found = match rest {
                    None => map.next_value_seed(Leaf)?,
                    Some(path) => map.next_value_seed(Lookup { path })?,
                };
            } else {
                map.next_value::<IgnoredAny>()?;
            }
        }
        Ok(found)
    }

    // Anything but an object has no fields.
    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Found, A::Error> {
        skip_seq(seq)?;
        Ok(Found::Missing)
    }
    fn visit_bool<E>(self, _: bool) -> Result<Found, E> {
        Ok(Found::Missing)
    }
    fn visit_i64<E>(self, _: i64) -> Result<Found, E> {
        Ok(Found::Missing)
    }
    fn visit_u64<E>(self, _: u64) -> Result<Found, E> {
        Ok(Found::Missing)
    }
    fn visit_f64<E>(self, _: f64) -> Result<Found, E> {
        Ok(Found::Missing)
    }
    fn visit_str<E>(self, _: &str) -> Result<Found, E> {
        Ok(Found::Missing)
    }
    fn visit_unit<E>(self) -> Result<Found, E> {
        Ok(Found::Missing)
    }
}

/// Deserializes a map key and tells whether it equals the wanted name.
struct KeyEq<'k>(&'k str);

impl<'de> DeserializeSeed<'de> for KeyEq<'_> {
    type Value = bool;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<bool, D::Error> {
        d.deserialize_str(self)
    }
}

impl<'de> Visitor<'de> for KeyEq<'_> {
    type Value = bool;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a string key")
    }
    fn visit_str<E>(self, s: &str) -> Result<bool, E> {
        Ok(s == self.0)
    }
}

/// The value at the end of the path.
struct Leaf;

impl<'de> DeserializeSeed<'de> for Leaf {
    type Value = Found;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Found, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Leaf {
    type Value = Found;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a JSON value")
    }
    fn visit_f64<E>(self, x: f64) -> Result<Found, E> {
        Ok(Found::Number(x))
    }
    fn visit_i64<E>(self, x: i64) -> Result<Found, E> {
        Ok(Found::Number(x as f64))
    }
    fn visit_u64<E>(self, x: u64) -> Result<Found, E> {
        Ok(Found::Number(x as f64))
    }
    fn visit_unit<E>(self) -> Result<Found, E> {
        Ok(Found::Null)
    }
    fn visit_none<E>(self) -> Result<Found, E> {
        Ok(Found::Null)
    }
    fn visit_bool<E>(self, _: bool) -> Result<Found, E> {
        Ok(Found::Other("a boolean"))
    }
    fn visit_str<E>(self, _: &str) -> Result<Found, E> {
        Ok(Found::Other("a string"))
    }
    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Found, A::Error> {
        skip_seq(seq)?;
        Ok(Found::Other("an array"))
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Found, A::Error> {
        while map.next_entry::<IgnoredAny, IgnoredAny>()?.is_some() {}
        Ok(Found::Other("an object"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn get(json: &str, path: &str) -> Result<f64, FieldLookupError> {
        json_field_f64(json.as_bytes(), path)
    }

    #[test]
    fn finds_numbers_and_nested_fields() {
        let j = r#"{"a": 1, "b": -2.5, "c": {"d": [1, 2], "e": 7e-3}, "f": null, "g": 18446744073709551615}"#;
        assert_eq!(get(j, "a").unwrap(), 1.0);
        assert_eq!(get(j, "b").unwrap(), -2.5);
        assert_eq!(get(j, "c.e").unwrap(), 7e-3);
        assert!(get(j, "f").unwrap().is_nan());
        assert_eq!(get(j, "g").unwrap(), u64::MAX as f64);
        assert!(matches!(get(j, "x"), Err(FieldLookupError::Missing)));
        assert!(matches!(get(j, "c.x"), Err(FieldLookupError::Missing)));
        assert!(matches!(get(j, "a.b"), Err(FieldLookupError::Missing)));
        assert!(matches!(
            get(j, "c"),
            Err(FieldLookupError::NotANumber("an object"))
        ));
        assert!(matches!(
            get(j, "c.d"),
            Err(FieldLookupError::NotANumber("an array"))
        ));
        assert!(matches!(
            get(r#"{"s": "1.0"}"#, "s"),
            Err(FieldLookupError::NotANumber("a string"))
        ));
        assert!(matches!(
            get(r#"{"s": true}"#, "s"),
            Err(FieldLookupError::NotANumber("a boolean"))
        ));
        // Escaped keys compare by their value.
        assert_eq!(get(r#"{"\u0061": 3}"#, "a").unwrap(), 3.0);
        // The first of duplicate keys wins.
        assert_eq!(get(r#"{"a": 1, "a": 2}"#, "a").unwrap(), 1.0);
        assert!(matches!(get("[1, 2]", "a"), Err(FieldLookupError::Missing)));
    }

    #[test]
    fn invalid_json_is_an_error_even_after_the_field() {
        assert!(matches!(
            get(r#"{"a": 1, "b": }"#, "a"),
            Err(FieldLookupError::Json(_))
        ));
        assert!(matches!(
            get(r#"{"a": 1} trailing"#, "a"),
            Err(FieldLookupError::Json(_))
        ));
        assert!(matches!(get("", "a"), Err(FieldLookupError::Json(_))));
        assert!(matches!(
            get(r#"{"a": NaN}"#, "a"),
            Err(FieldLookupError::Json(_))
        ));
    }
}
