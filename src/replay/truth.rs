//! Ground-truth messages, parsed in one pass: the fault fields every truth topic carries and
//! the configured top-level field holding the true value, borrowed (no allocation for an
//! unescaped fault name). Truth topics come at the sensors' rate (1 kHz for the throttle), so
//! the parse is on the replay's hot path.

use std::borrow::Cow;
use std::fmt;

use fdd_monitor::log::flat_json::{FlatObject, FlatValue, PlainKey};
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
///
/// A flat object (every truth message fdd writes) takes a fast path
/// ([`fdd_monitor::log::flat_json`]) with the same result, bit for bit; anything else, and
/// every error, goes through serde_json.
#[inline(never)]
pub(crate) fn parse_truth<'a>(
    data: &'a [u8],
    field: &str,
) -> Result<TruthMsg<'a>, serde_json::Error> {
    match parse_flat_truth(data, field) {
        Some(msg) => Ok(msg),
        None => parse_truth_general(data, field),
    }
}

/// The fast path of [`parse_truth`]: `None` when `data` is not a flat object, a fault field is
/// missing or of the wrong type (serde_json then names the error), or the number is one
/// `fdd_monitor::log::flat_json::number_f64` leaves to serde_json. As the general path: for a
/// repeated key the last one wins, and the fault keys take precedence over `field`.
#[inline]
fn parse_flat_truth<'a>(data: &'a [u8], field: &str) -> Option<TruthMsg<'a>> {
    let (mut fault, mut active, mut observable, mut value) = (None, None, None, f64::NAN);
    let field = field.as_bytes();
    let mut obj = FlatObject::new(data).ok()?;
    // The keys where fdd writes them are only compared; any other is read and looked up.
    let layout = LAYOUTS
        .iter()
        .find(|l| obj.clone().next_key_is(l[0].0))
        .map_or(&[][..], |l| &l[..]);
    let mut expected = layout.iter();
    loop {
        let (key, role) = match expected.next() {
            Some(&(k, role)) if obj.next_key_is(k) => (k.bytes(), role),
            _ => {
                // Off the layout: read every further key.
                expected = [].iter();
                match obj.next_key().ok()? {
                    Some(b"fault") => (&b"fault"[..], Role::Fault),
                    Some(b"fault_active") => (&b"fault_active"[..], Role::Active),
                    Some(b"fault_observable") => (&b"fault_observable"[..], Role::Observable),
                    Some(k) => (k, Role::Other),
                    None => break,
                }
            }
        };
        // The fault keys first, as the general path; a wrong type is for it to name.
        match role {
            Role::Fault => match obj.value().ok()? {
                FlatValue::Str(s) => fault = Some(s),
                _ => return None,
            },
            Role::Active => match obj.value().ok()? {
                FlatValue::Bool(b) => active = Some(b),
                _ => return None,
            },
            Role::Observable => match obj.value().ok()? {
                FlatValue::Bool(b) => observable = Some(b),
                _ => return None,
            },
            Role::Other if key == field => {
                value = match obj.value().ok()? {
                    FlatValue::Number(n) => n.to_f64()?,
                    _ => f64::NAN,
                }
            }
            Role::Other => obj.skip_value().ok()?,
        }
    }
    Some(TruthMsg {
        fault: match fault? {
            b"none" => Cow::Borrowed("none"),
            // Printable ASCII, so always UTF-8.
            name => Cow::Borrowed(std::str::from_utf8(name).ok()?),
        },
        fault_active: active?,
        fault_observable: observable,
        value,
    })
}

/// What a truth key is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Fault,
    Active,
    Observable,
    Other,
}

/// The truth messages' keys in the order fdd writes them (`ThrottleTruth`, `IntakeTruth` of
/// `fdd_monitor::log`), for the fast path: a key where it is expected is only compared.
const LAYOUTS: [&[(PlainKey, Role)]; 2] = [
    &[
        (PlainKey::new(b"angle_deg"), Role::Other),
        (PlainKey::new(b"velocity"), Role::Other),
        (PlainKey::new(b"current_a"), Role::Other),
        (PlainKey::new(b"fault"), Role::Fault),
        (PlainKey::new(b"fault_active"), Role::Active),
    ],
    &[
        (PlainKey::new(b"p_m_pa"), Role::Other),
        (PlainKey::new(b"w_thr_kg_s"), Role::Other),
        (PlainKey::new(b"w_egr_kg_s"), Role::Other),
        (PlainKey::new(b"w_inv_kg_s"), Role::Other),
        (PlainKey::new(b"w_leak_kg_s"), Role::Other),
        (PlainKey::new(b"egr_actual"), Role::Other),
        (PlainKey::new(b"fault"), Role::Fault),
        (PlainKey::new(b"fault_active"), Role::Active),
        (PlainKey::new(b"fault_observable"), Role::Observable),
    ],
];

/// [`parse_truth`] by serde_json, for any JSON.
fn parse_truth_general<'a>(data: &'a [u8], field: &str) -> Result<TruthMsg<'a>, serde_json::Error> {
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

    #[test]
    fn the_layouts_are_the_keys_fdd_writes_in_order() {
        let keys = |text: String| -> Vec<String> {
            let mut obj = FlatObject::new(text.as_bytes()).unwrap();
            let mut out = Vec::new();
            while let Some((k, _)) = obj.next_member().unwrap() {
                out.push(String::from_utf8(k.to_vec()).unwrap());
            }
            out
        };
        let throttle = fdd_monitor::log::ThrottleTruth {
            angle_deg: 1.0,
            velocity: 2.0,
            current_a: 3.0,
            fault: "none".into(),
            fault_active: false,
            fault_observable: None,
        };
        let intake = fdd_monitor::log::messages::IntakeTruth {
            p_m_pa: 1.0,
            w_thr_kg_s: 2.0,
            w_egr_kg_s: 3.0,
            w_inv_kg_s: 4.0,
            w_leak_kg_s: 5.0,
            egr_actual: 6.0,
            fault: "none".into(),
            fault_active: false,
            fault_observable: true,
        };
        let written = [
            keys(serde_json::to_string(&throttle).unwrap()),
            keys(serde_json::to_string(&intake).unwrap()),
        ];
        for (key, role) in LAYOUTS.iter().flat_map(|l| l.iter()) {
            let expected = match key.bytes() {
                b"fault" => Role::Fault,
                b"fault_active" => Role::Active,
                b"fault_observable" => Role::Observable,
                _ => Role::Other,
            };
            assert_eq!(*role, expected);
        }
        for (layout, written) in LAYOUTS.iter().zip(written) {
            let layout: Vec<String> = layout
                .iter()
                .map(|(k, _)| String::from_utf8(k.bytes().to_vec()).unwrap())
                .collect();
            assert_eq!(layout, written);
        }
    }

    /// The fast path against serde_json, on generated and mutated inputs.
    mod fast_path_is_serde_json {
        use super::super::*;
        use fdd_monitor::log::ThrottleTruth;
        use proptest::prelude::*;

        /// A comparable form of a parse's outcome (the value by its bits).
        fn outcome(r: &Result<TruthMsg<'_>, serde_json::Error>) -> String {
            match r {
                Ok(m) => format!(
                    "ok {:?} borrowed={} {} {:?} {:016x}",
                    m.fault,
                    matches!(m.fault, Cow::Borrowed(_)),
                    m.fault_active,
                    m.fault_observable,
                    m.value.to_bits()
                ),
                Err(e) => format!("error {e}"),
            }
        }

        fn value_text() -> impl Strategy<Value = String> {
            prop_oneof![
                4 => any::<f64>().prop_map(|x| serde_json::to_string(&x).unwrap()),
                2 => (-1e3..1e3f64).prop_map(|x| serde_json::to_string(&x).unwrap()),
                1 => any::<i64>().prop_map(|x| x.to_string()),
                1 => "-?(0|[1-9][0-9]{0,21})(\\.[0-9]{1,21})?([eE][+-]?[0-9]{1,4})?",
                2 => prop_oneof![
                    Just("null".to_string()),
                    Just("true".to_string()),
                    Just("false".to_string()),
                    Just(r#""none""#.to_string()),
                    Just(r#""tps_stuck""#.to_string()),
                    Just(r#""t\u0070s""#.to_string()),
                    Just("\"\u{e9}\"".to_string()),
                    Just("[true]".to_string()),
                    Just(r#"{"fault": "x"}"#.to_string()),
                    Just("1e400".to_string()),
                ],
            ]
        }

        const KEYS: [&str; 10] = [
            "fault",
            "fault_active",
            "fault_observable",
            "angle_deg",
            "p_m_pa",
            "velocity",
            "fault\\u005factive",
            "",
            "w_egr_kg_s",
            "egr_actual",
        ];

        fn ws() -> impl Strategy<Value = &'static str> {
            prop_oneof![8 => Just(""), 1 => Just(" "), 1 => Just("\n\t ")]
        }

        fn object_text() -> impl Strategy<Value = String> {
            let member = (ws(), 0..KEYS.len(), ws(), value_text())
                .prop_map(|(w1, k, w2, v)| format!("{w1}\"{}\":{w2}{v}", KEYS[k]));
            // Usually the fault fields are there, so that the fast path has work.
            let fault = prop_oneof![
                Just(r#""fault":"none","fault_active":false"#.to_string()),
                Just(
                    r#""fault": "leak", "fault_active": true, "fault_observable": false"#
                        .to_string()
                ),
                Just(String::new()),
            ];
            (prop::collection::vec(member, 0..4), fault, any::<bool>()).prop_map(
                |(mut m, f, first)| {
                    if !f.is_empty() {
                        if first {
                            m.insert(0, f);
                        } else {
                            m.push(f);
                        }
                    }
                    format!("{{{}}}", m.join(","))
                },
            )
        }

        /// Truth messages as fdd writes them (the fast path's layouts).
        fn fdd_truth_text() -> impl Strategy<Value = String> {
            let number = || prop_oneof![any::<f64>(), -100.0..100.0f64, Just(0.0)];
            (
                prop::array::uniform6(number()),
                prop_oneof![Just("none"), Just("tps_stuck"), Just("leak")],
                any::<[bool; 2]>(),
                any::<bool>(),
            )
                .prop_map(|(x, fault, [active, observable], throttle)| {
                    if throttle {
                        serde_json::to_string(&ThrottleTruth {
                            angle_deg: x[0],
                            velocity: x[1],
                            current_a: x[2],
                            fault: fault.into(),
                            fault_active: active,
                            fault_observable: None,
                        })
                    } else {
                        serde_json::to_string(&fdd_monitor::log::messages::IntakeTruth {
                            p_m_pa: x[0],
                            w_thr_kg_s: x[1],
                            w_egr_kg_s: x[2],
                            w_inv_kg_s: x[3],
                            w_leak_kg_s: x[4],
                            egr_actual: x[5],
                            fault: fault.into(),
                            fault_active: active,
                            fault_observable: observable,
                        })
                    }
                    .unwrap()
                })
        }

        fn input() -> impl Strategy<Value = Vec<u8>> {
            const BYTES: &[u8] = b"{}[],:\"\\ -.e09ntf\x00\x7f\xc3";
            (
                prop_oneof![object_text(), fdd_truth_text()],
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
            fn parses_agree(data in input(), f in 0..KEYS.len()) {
                let field = KEYS[f];
                let general = parse_truth_general(&data, field);
                prop_assert_eq!(outcome(&parse_truth(&data, field)), outcome(&general));
                if let Some(fast) = parse_flat_truth(&data, field) {
                    prop_assert_eq!(outcome(&Ok(fast)), outcome(&general));
                }
            }

            /// Every truth message fdd writes takes the fast path.
            #[test]
            fn fdd_messages_take_the_fast_path(
                x in any::<f64>(),
                y in -100.0..100.0f64,
                active in any::<bool>(),
            ) {
                let truth = ThrottleTruth {
                    angle_deg: y,
                    velocity: x,
                    current_a: -x,
                    fault: "tps_stuck".into(),
                    fault_active: active,
                    fault_observable: None,
                };
                let data = serde_json::to_vec(&truth).unwrap();
                for field in ["angle_deg", "velocity", "current_a", "fault", "x"] {
                    let fast = parse_flat_truth(&data, field);
                    prop_assert!(fast.is_some());
                    prop_assert_eq!(
                        outcome(&Ok(fast.unwrap())),
                        outcome(&parse_truth_general(&data, field))
                    );
                }
            }
        }
    }
}
