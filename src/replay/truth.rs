//! Ground-truth messages, parsed in one pass: the fault fields every truth topic carries and
//! the configured top-level field holding the true value, borrowed (no allocation for an
//! unescaped fault name). Truth topics come at the sensors' rate (1 kHz for the throttle), so
//! the parse is on the replay's hot path.

use std::borrow::Cow;
use std::fmt;

use serde::de::{self, DeserializeSeed, IgnoredAny, MapAccess, Visitor};
use serde::Deserializer;

/// One truth message.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TruthMsg<'a> {
    pub fault: Cow<'a, str>,
    pub fault_active: bool,
    /// Whether the fault changes anything in this sample (`fault_observable`), when the topic
    /// says so (the intake truth does).
    pub fault_observable: Option<bool>,
    /// The configured field's value; NaN when it is `null`, missing or not a number.
    pub value: f64,
}

/// Parses `data` (a JSON object with `fault`, `fault_active` and the top-level `field`).
pub(crate) fn parse_truth<'a>(
    data: &'a [u8],
    field: &str,
) -> Result<TruthMsg<'a>, serde_json::Error> {
    let mut de = serde_json::Deserializer::from_slice(data);
    let msg = TruthSeed { field }.deserialize(&mut de)?;
    de.end()?;
    Ok(msg)
}

struct TruthSeed<'f> {
    field: &'f str,
}

impl<'de> DeserializeSeed<'de> for TruthSeed<'_> {
    type Value = TruthMsg<'de>;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_map(self)
    }
}

/// A string, borrowed from the input when it has no escapes (no allocation).
struct CowStr;

impl<'de> DeserializeSeed<'de> for CowStr {
    type Value = Cow<'de, str>;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Cow<'de, str>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a string")
            }
            fn visit_borrowed_str<E: de::Error>(self, v: &'de str) -> Result<Self::Value, E> {
                Ok(Cow::Borrowed(v))
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<Self::Value, E> {
                Ok(Cow::Owned(v.to_string()))
            }
            fn visit_string<E: de::Error>(self, v: String) -> Result<Self::Value, E> {
                Ok(Cow::Owned(v))
            }
        }
        d.deserialize_str(V)
    }
}

/// A number, or NaN for `null` or any other JSON value.
struct LenientF64;

impl<'de> DeserializeSeed<'de> for LenientF64 {
    type Value = f64;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<f64, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = f64;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a number or null")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<f64, E> {
                Ok(v)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<f64, E> {
                Ok(v as f64)
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<f64, E> {
                Ok(v as f64)
            }
            fn visit_unit<E: de::Error>(self) -> Result<f64, E> {
                Ok(f64::NAN)
            }
            fn visit_bool<E: de::Error>(self, _: bool) -> Result<f64, E> {
                Ok(f64::NAN)
            }
            fn visit_str<E: de::Error>(self, _: &str) -> Result<f64, E> {
                Ok(f64::NAN)
            }
            fn visit_seq<A: de::SeqAccess<'de>>(self, mut a: A) -> Result<f64, A::Error> {
                while a.next_element::<IgnoredAny>()?.is_some() {}
                Ok(f64::NAN)
            }
            fn visit_map<A: MapAccess<'de>>(self, mut a: A) -> Result<f64, A::Error> {
                while a.next_entry::<IgnoredAny, IgnoredAny>()?.is_some() {}
                Ok(f64::NAN)
            }
        }
        d.deserialize_any(V)
    }
}

impl<'de> Visitor<'de> for TruthSeed<'_> {
    type Value = TruthMsg<'de>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a truth object with `fault`, `fault_active` and the configured field")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let (mut fault, mut active, mut observable, mut value) = (None, None, None, f64::NAN);
        while let Some(key) = map.next_key_seed(CowStr)? {
            if key == "fault" {
                fault = Some(map.next_value_seed(CowStr)?);
            } else if key == "fault_active" {
                active = Some(map.next_value::<bool>()?);
            } else if key == "fault_observable" {
                observable = Some(map.next_value::<bool>()?);
            } else if key == self.field {
                value = map.next_value_seed(LenientF64)?;
            } else {
                map.next_value::<IgnoredAny>()?;
            }
        }
        Ok(TruthMsg {
            fault: fault.ok_or_else(|| de::Error::missing_field("fault"))?,
            fault_active: active.ok_or_else(|| de::Error::missing_field("fault_active"))?,
            fault_observable: observable,
            value,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_fault_fields_and_the_configured_value() {
        let m = parse_truth(
            br#"{"angle_deg": 12.5, "velocity": 1, "fault": "tps_open", "fault_active": true}"#,
            "angle_deg",
        )
        .expect("valid");
        assert_eq!(m.fault, "tps_open");
        assert!(m.fault_active);
        assert_eq!(m.value, 12.5);
        assert_eq!(m.fault_observable, None);
        assert!(matches!(m.fault, Cow::Borrowed(_)));
        let m = parse_truth(
            br#"{"fault": "leak", "fault_active": true, "fault_observable": false, "p_m_pa": 1e5}"#,
            "p_m_pa",
        )
        .expect("valid");
        assert_eq!((m.fault_observable, m.value), (Some(false), 1e5));
        let m = parse_truth(
            br#"{"p_m_pa": null, "fault": "none", "fault_active": false}"#,
            "p_m_pa",
        )
        .expect("valid");
        assert!(m.value.is_nan());
        let m = parse_truth(br#"{"fault": "none", "fault_active": false, "p": 3}"#, "q")
            .expect("valid");
        assert!(m.value.is_nan(), "a missing field gives NaN");
    }

    #[test]
    fn missing_fault_fields_and_bad_json_are_errors() {
        let e = parse_truth(br#"{"angle_deg": 1.0, "fault_active": true}"#, "angle_deg")
            .expect_err("no fault")
            .to_string();
        assert!(e.contains("fault"), "{e}");
        assert!(parse_truth(br#"{"fault": "x", "fault_active": 3}"#, "a").is_err());
        assert!(parse_truth(br#"{"fault": "x", "fault_active": true"#, "a").is_err());
        assert!(parse_truth(br#"{"fault": "x", "fault_active": true} x"#, "a").is_err());
    }
}
