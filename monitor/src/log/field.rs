//! Extracting one numeric field from a JSON message by name, without building a
//! `serde_json::Value` (no allocation for keys without escapes).
//!
//! The runtime maps configurable `(topic, field)` pairs to signals; [`json_field_f64`] is that
//! lookup. A path is a field name, or names joined by `.` for nested objects
//! (`test_result.value`). `null` reads as NaN (fdd writes non-finite numbers as `null`).

use std::fmt;

use serde::de::{DeserializeSeed, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};

use super::flat_json::{single_number_member, FlatObject, FlatValue};

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
///
/// A flat object (every signal message fdd writes) takes a fast path
/// ([`flat_json`](super::flat_json)) with the same result, bit for bit; anything else, and a
/// dotted path, goes through serde_json.
pub fn json_field_f64(json: &[u8], path: &str) -> Result<f64, FieldLookupError> {
    match flat_field_f64(json, path.as_bytes()) {
        // The flat scan refuses keys with a `.`, so a dotted path always misses there: whether
        // it is missing is for the general lookup to say.
        Some(Err(FieldLookupError::Missing)) if path.contains('.') => general_field_f64(json, path),
        Some(found) => found,
        None => general_field_f64(json, path),
    }
}

/// The fast path of [`json_field_f64`] for the top-level field `key`: `None` when `json` is not
/// a flat object or the number is one
/// [`number_f64`](super::flat_json::number_f64) leaves to serde_json. As serde_json: the first
/// of duplicate keys wins (the others are only checked to be valid).
#[inline]
fn flat_field_f64(json: &[u8], key: &[u8]) -> Option<Result<f64, FieldLookupError>> {
    if let Some(x) = single_number_member(json, key) {
        return Some(Ok(x));
    }
    let mut obj = FlatObject::new(json).ok()?;
    let mut found = None;
    while let Some((k, v)) = obj.next_member().ok()? {
        if found.is_none() && k == key {
            found = Some(v);
        }
    }
    Some(match found {
        None => Err(FieldLookupError::Missing),
        Some(FlatValue::Number(n)) => Ok(n.to_f64()?),
        Some(FlatValue::Null) => Ok(f64::NAN),
        Some(FlatValue::Bool(_)) => Err(FieldLookupError::NotANumber("a boolean")),
        Some(FlatValue::Str(_)) => Err(FieldLookupError::NotANumber("a string")),
    })
}

/// [`json_field_f64`] by serde_json, for any JSON.
fn general_field_f64(json: &[u8], path: &str) -> Result<f64, FieldLookupError> {
    // serde_json skips the strings it ignores without checking that they are UTF-8, so a text
    // with invalid bytes in a string off the path would be read as JSON. Parsing it as a
    // `Value` checks every string and names the position (found by the `json_field` fuzz
    // target); text that is UTF-8 (all of fdd's messages) does not pay for it.
    if !json.is_ascii() && std::str::from_utf8(json).is_err() {
        if let Err(e) = serde_json::from_slice::<serde_json::Value>(json) {
            return Err(FieldLookupError::Json(e));
        }
    }
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
    fn the_fast_path_takes_flat_objects_only() {
        let fast = |j: &str, k: &str| flat_field_f64(j.as_bytes(), k.as_bytes());
        assert_eq!(
            fast(r#"{"voltage_v":1.25}"#, "voltage_v").unwrap().unwrap(),
            1.25
        );
        assert!(fast(r#"{"voltage_v":null}"#, "voltage_v")
            .unwrap()
            .unwrap()
            .is_nan());
        assert!(matches!(
            fast(r#"{"a":1,"a":true}"#, "a"),
            Some(Ok(x)) if x == 1.0
        ));
        assert!(matches!(
            fast(r#"{"a":"x"}"#, "a"),
            Some(Err(FieldLookupError::NotANumber("a string")))
        ));
        assert!(matches!(
            fast(r#"{"a":1}"#, "b"),
            Some(Err(FieldLookupError::Missing))
        ));
        assert!(fast(r#"{"a":{"b":1}}"#, "a").is_none());
        assert!(fast(r#"{"a":1e400}"#, "a").is_none());
        assert!(fast(r#"{"a":1, "b": }"#, "a").is_none());
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

    /// The fast path against serde_json, on generated and mutated inputs.
    mod fast_path_is_serde_json {
        use super::super::*;
        use crate::log::flat_json::number_f64;
        use crate::log::messages::{MotorVoltage, ThrottleTruth};
        use proptest::prelude::*;

        /// A comparable form of a lookup's outcome (numbers by their bits).
        fn outcome(r: &Result<f64, FieldLookupError>) -> String {
            match r {
                Ok(x) => format!("ok {:016x}", x.to_bits()),
                Err(FieldLookupError::Json(e)) => format!("json {e}"),
                Err(FieldLookupError::Missing) => "missing".into(),
                Err(FieldLookupError::NotANumber(w)) => format!("nan {w}"),
            }
        }

        fn number_text() -> impl Strategy<Value = String> {
            prop_oneof![
                // As fdd writes them (ryu, shortest round trip), and other spellings.
                any::<f64>().prop_map(|x| serde_json::to_string(&x).unwrap()),
                any::<f64>().prop_map(|x| format!("{x:e}")),
                any::<f64>().prop_map(|x| format!("{x:E}")),
                any::<f64>().prop_map(|x| format!("{x}")),
                (-1e3..1e3f64).prop_map(|x| serde_json::to_string(&x).unwrap()),
                any::<u64>().prop_map(|x| x.to_string()),
                any::<i64>().prop_map(|x| x.to_string()),
                "-?(0|[1-9][0-9]{0,24})(\\.[0-9]{1,24})?([eE][+-]?[0-9]{1,11})?",
            ]
        }

        fn value_text() -> impl Strategy<Value = String> {
            prop_oneof![
                6 => number_text(),
                1 => prop_oneof![
                    Just("null".to_string()),
                    Just("true".to_string()),
                    Just("false".to_string()),
                    Just(r#""none""#.to_string()),
                    Just(r#""a\"b""#.to_string()),
                    Just("\"\u{e9}\"".to_string()),
                    Just("[1, 2.5]".to_string()),
                    Just(r#"{"voltage_v": 2}"#.to_string()),
                    Just("NaN".to_string()),
                    Just("1e400".to_string()),
                ],
            ]
        }

        const KEYS: [&str; 8] = [
            "voltage_v",
            "a",
            "power_w",
            "\\u0061",
            "\u{e9}",
            "",
            "a.b",
            "voltage_v ",
        ];

        fn ws() -> impl Strategy<Value = &'static str> {
            prop_oneof![8 => Just(""), 1 => Just(" "), 1 => Just("\n\t\r ")]
        }

        fn object_text() -> impl Strategy<Value = String> {
            let member = (ws(), 0..KEYS.len(), ws(), ws(), value_text(), ws())
                .prop_map(|(w1, k, w2, w3, v, w4)| format!("{w1}\"{}\"{w2}:{w3}{v}{w4}", KEYS[k]));
            (ws(), prop::collection::vec(member, 0..4), ws())
                .prop_map(|(w0, m, w5)| format!("{w0}{{{}}}{w5}", m.join(",")))
        }

        /// An object, possibly with one byte deleted, inserted or replaced, or cut short.
        fn input() -> impl Strategy<Value = Vec<u8>> {
            const BYTES: &[u8] = b"{}[],:\"\\ -+.eE019nulltruefalse\x00\x1f\x7f\xc3\xff";
            (
                object_text(),
                0..5u8,
                any::<prop::sample::Index>(),
                0..BYTES.len(),
            )
                .prop_map(|(text, how, at, byte)| {
                    let b = text.into_bytes();
                    let i = at.index(b.len() + 1);
                    fdd_testkit::mutate(b, how, i, BYTES[byte])
                })
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(4096))]

            #[test]
            fn lookups_agree(json in input(), k in 0..KEYS.len()) {
                let path = KEYS[k];
                let general = general_field_f64(&json, path);
                prop_assert_eq!(outcome(&json_field_f64(&json, path)), outcome(&general));
                // (json_field_f64 sends a dotted path to serde_json.)
                if !path.contains('.') {
                    if let Some(fast) = flat_field_f64(&json, path.as_bytes()) {
                        prop_assert_eq!(outcome(&fast), outcome(&general));
                    }
                }
            }

            #[test]
            fn numbers_agree(text in number_text()) {
                let serde: Result<f64, _> = serde_json::from_str(&text);
                match number_f64(text.as_bytes()) {
                    Some(x) => prop_assert_eq!(x.to_bits(), serde.unwrap().to_bits(), "{}", text),
                    // Left to serde_json: out of range, or a significand or exponent too
                    // long for u64 / i32.
                    None => {
                        let (mantissa, exp) = text.split_once(['e', 'E']).unwrap_or((&text, ""));
                        let digits = |s: &str| s.bytes().filter(u8::is_ascii_digit).count();
                        prop_assert!(
                            serde.is_err() || digits(mantissa) > 19 || digits(exp) > 9,
                            "{} not handled", text
                        );
                    }
                }
            }

            /// Every signal and truth message fdd writes takes the fast path.
            #[test]
            fn fdd_messages_take_the_fast_path(x in any::<f64>(), y in -1e3..1e3f64) {
                for v in [x, y] {
                    let json = serde_json::to_vec(&MotorVoltage { voltage_v: v }).unwrap();
                    let fast = flat_field_f64(&json, b"voltage_v");
                    prop_assert!(fast.is_some(), "{}", String::from_utf8_lossy(&json));
                    // The quickest path, for every finite number.
                    prop_assert_eq!(
                        single_number_member(&json, b"voltage_v").is_some(),
                        v.is_finite()
                    );
                    prop_assert_eq!(
                        outcome(&fast.unwrap()),
                        outcome(&general_field_f64(&json, "voltage_v"))
                    );
                }
                let truth = ThrottleTruth {
                    angle_deg: y,
                    velocity: x,
                    current_a: -y,
                    fault: "tps_stuck".into(),
                    fault_active: true,
                    fault_observable: None,
                };
                let json = serde_json::to_vec(&truth).unwrap();
                for key in ["angle_deg", "velocity", "current_a", "fault", "fault_active", "x"] {
                    let fast = flat_field_f64(&json, key.as_bytes());
                    prop_assert!(fast.is_some());
                    prop_assert_eq!(
                        outcome(&fast.unwrap()),
                        outcome(&general_field_f64(&json, key))
                    );
                }
            }
        }
    }

    #[test]
    fn invalid_utf8_in_a_string_off_the_path_is_invalid_json() {
        let json = b"{\"a\\\"b\":2,\"x\":[1,{\"\x9a\x9ay\":3}]}";
        assert!(serde_json::from_slice::<serde_json::Value>(json).is_err());
        assert!(matches!(
            json_field_f64(json, "a\"b"),
            Err(FieldLookupError::Json(_))
        ));
    }
}
