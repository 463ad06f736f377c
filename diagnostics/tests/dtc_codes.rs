//! SAE J2012 codes and their 2-byte / 3-byte UDS encodings.
//!
//! - Cross-check against two independent decoders: `tests/data/dtc_vectors.json` holds what
//!   Python `obd.decoders.parse_dtc` (2-byte codes) and `udsoncan.Dtc.id_iso` (3-byte UDS DTCs)
//!   print for 350 codes and 396 DTCs covering every letter and second digit with edge values,
//!   and how `udsoncan.Dtc.Status.from_byte` reads status bytes. The script
//!   `tests/data/gen_dtc_vectors.py` regenerates it (optional; needs `pip install obd udsoncan`).
//!   `obd` writes hex digits in lowercase (`U3fff`), so that comparison ignores case.
//! - Round trips: all 65,536 2-byte codes exhaustively, 3-byte DTCs by proptest.
//! - Invalid text is an error naming the input and the problem; a malformed DTC in the
//!   configuration is a `ConfigError` naming the key.

use std::collections::BTreeSet;

use fdd_diagnostics::dtc::{
    Dtc, DtcCode, DtcParseErrorKind, DtcStatus, DtcSystem, EventConfig, EventMemory,
    EventMemoryConfig, StatusBit,
};
use proptest::prelude::*;
use serde_json::Value;

fn vectors() -> Value {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/dtc_vectors.json"
    ))
    .expect("tests/data/dtc_vectors.json");
    serde_json::from_str(&text).expect("valid JSON")
}

#[test]
fn reference_examples_both_ways() {
    let codes = [
        ("P0123", 0x0123u16),
        ("C0035", 0x4035),
        ("B1234", 0x9234),
        ("U0100", 0xC100),
        ("P0000", 0x0000),
        ("P3FFF", 0x3FFF),
        ("C2ABC", 0x6ABC),
        ("B3000", 0xB000),
        ("U3FFF", 0xFFFF),
    ];
    for (text, value) in codes {
        let c: DtcCode = text.parse().unwrap();
        assert_eq!(c.to_u16(), value, "{text}");
        assert_eq!(DtcCode::from_u16(value).to_string(), text);
        assert_eq!(u16::from(c), value);
    }
    let dtcs = [
        ("P0123-1C", 0x01231Cu32),
        ("C0035-00", 0x403500),
        ("U0100-87", 0xC10087),
        ("B1234-FF", 0x9234FF),
        ("P0000-00", 0x000000),
        ("U3FFF-FF", 0xFFFFFF),
    ];
    for (text, value) in dtcs {
        let d: Dtc = text.parse().unwrap();
        assert_eq!(d.to_u32(), value, "{text}");
        assert_eq!(Dtc::from_u32(value).unwrap().to_string(), text);
        assert_eq!(u32::from(d), value);
        assert_eq!(&d.to_ascii(), text.as_bytes());
    }
    let d: Dtc = "P0123-1C".parse().unwrap();
    assert_eq!(d.code.system(), DtcSystem::Powertrain);
    assert_eq!((d.code.digit(), d.code.low(), d.ftb), (0, 0x123, 0x1C));
    // A bare code is FTB 00; either case is accepted, output is uppercase.
    assert_eq!("p0a2f".parse::<Dtc>().unwrap().to_string(), "P0A2F-00");
    assert_eq!("u0100-1c".parse::<Dtc>().unwrap().to_u32(), 0xC1001C);
}

#[test]
fn every_two_byte_code_round_trips() {
    let mut seen = BTreeSet::new();
    for v in 0..=u16::MAX {
        let c = DtcCode::from_u16(v);
        let text = c.to_string();
        assert_eq!(text.len(), 5);
        assert_eq!(text.parse::<DtcCode>().unwrap(), c, "{text}");
        assert_eq!(text.to_lowercase().parse::<DtcCode>().unwrap(), c);
        assert_eq!(&c.to_ascii(), text.as_bytes());
        assert_eq!(
            DtcCode::new(c.system(), c.digit(), c.low()),
            c,
            "components of {text}"
        );
        seen.insert(text);
    }
    assert_eq!(seen.len(), 65536, "the mapping is a bijection");
    for s in DtcSystem::ALL {
        assert_eq!(DtcSystem::from_letter(s.letter()), Some(s));
    }
}

proptest! {
    #[test]
    fn three_byte_dtcs_round_trip(v in 0u32..=0xFF_FFFF) {
        let d = Dtc::from_u32(v).unwrap();
        let text = d.to_string();
        prop_assert_eq!(text.len(), 8);
        prop_assert_eq!(text.parse::<Dtc>().unwrap().to_u32(), v);
        prop_assert_eq!(text.to_lowercase().parse::<Dtc>().unwrap(), d);
        prop_assert_eq!(d.code.to_u16() as u32, v >> 8);
        let json = serde_json::to_string(&d).unwrap();
        prop_assert_eq!(json, format!("\"{text}\""));
    }

    #[test]
    fn values_above_three_bytes_are_rejected(v in 0x0100_0000u32..) {
        let e = Dtc::from_u32(v).unwrap_err();
        prop_assert_eq!(e.kind, DtcParseErrorKind::TooLarge);
    }
}

#[test]
fn python_obd_two_byte_vectors() {
    let doc = vectors();
    let codes = doc["codes"].as_array().unwrap();
    assert!(codes.len() >= 300);
    let mut letters_digits = BTreeSet::new();
    for v in codes {
        let value = v["u16"].as_u64().unwrap() as u16;
        let bytes: Vec<u8> = v["bytes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b.as_u64().unwrap() as u8)
            .collect();
        let obd = v["obd"].as_str().expect("obd decoded every vector");
        let c = DtcCode::from_u16(value);
        assert_eq!(c.to_u16().to_be_bytes().as_slice(), bytes.as_slice());
        assert!(
            c.to_string().eq_ignore_ascii_case(obd),
            "0x{value:04X}: fdd {c}, obd {obd}"
        );
        // obd's lowercase text parses to the same code.
        assert_eq!(obd.parse::<DtcCode>().unwrap().to_u16(), value, "{obd}");
        letters_digits.insert((c.system().letter(), c.digit()));
    }
    assert_eq!(
        letters_digits.len(),
        16,
        "every letter with every second digit"
    );
}

#[test]
fn python_udsoncan_three_byte_vectors() {
    let doc = vectors();
    let dtcs = doc["uds"].as_array().unwrap();
    assert!(dtcs.len() >= 300);
    let mut letters = BTreeSet::new();
    for v in dtcs {
        let value = v["u32"].as_u64().unwrap() as u32;
        let iso = v["udsoncan"].as_str().unwrap();
        let d = Dtc::from_u32(value).unwrap();
        assert_eq!(d.to_string(), iso, "0x{value:06X}");
        assert_eq!(iso.parse::<Dtc>().unwrap().to_u32(), value);
        letters.insert(d.code.system().letter());
    }
    assert_eq!(letters.len(), 4);
}

#[test]
fn python_udsoncan_status_flags() {
    let doc = vectors();
    let statuses = doc["status"].as_array().unwrap();
    for v in statuses {
        let byte = v["byte"].as_u64().unwrap() as u8;
        let flags = v["flags"].as_object().unwrap();
        assert_eq!(flags.len(), 8);
        let s = DtcStatus::from_byte(byte);
        for bit in StatusBit::ALL {
            let expected = flags[bit.name()].as_bool().unwrap();
            assert_eq!(s.get(bit), expected, "0x{byte:02X} {bit}");
        }
    }
    // The standard bytes of REFERENCE.md section 5 are in the vectors.
    let bytes: BTreeSet<u64> = statuses
        .iter()
        .map(|v| v["byte"].as_u64().unwrap())
        .collect();
    for b in [0x50, 0x27, 0x2F, 0xAF] {
        assert!(bytes.contains(&b));
    }
}

#[test]
fn invalid_text_is_a_clear_error() {
    use DtcParseErrorKind::*;
    let cases = [
        ("", Empty, ": empty DTC"),
        ("P5123", SecondDigit, "P5123: second character must be 0-3"),
        (
            "X0123",
            Letter,
            "X0123: first character must be P, C, B or U",
        ),
        ("0123", Letter, "first character must be P, C, B or U"),
        (
            "P012",
            Length,
            "P012: a J2012 code is a letter and 4 characters",
        ),
        (
            "P01234",
            Length,
            "a J2012 code is a letter and 4 characters",
        ),
        (
            "P012G",
            HexDigits,
            "P012G: characters 3-5 must be hex digits",
        ),
        ("P0123-1", FailureType, "P0123-1: the failure type byte"),
        ("P0123-1CC", FailureType, "failure type byte"),
        ("P0123-G1", FailureType, "failure type byte"),
        ("P0123-", FailureType, "failure type byte"),
        (" P0123", Letter, "first character"),
        ("P0123 ", Length, "a J2012 code"),
        ("P01é3", Length, "a J2012 code"),
    ];
    for (text, kind, message) in cases {
        let e = text.parse::<Dtc>().unwrap_err();
        assert_eq!(e.kind, kind, "{text:?}");
        assert_eq!(e.input, text);
        assert!(
            e.to_string().contains(message),
            "{text:?}: {e} does not contain {message:?}"
        );
    }
    // A bare code type refuses a failure type byte.
    assert!("P0123-1C".parse::<DtcCode>().is_err());
    // Through serde the same message comes out.
    let e = serde_json::from_str::<Dtc>("\"P4123-00\"").unwrap_err();
    assert!(
        e.to_string().contains("second character must be 0-3"),
        "{e}"
    );
}

#[test]
fn malformed_dtc_in_config_names_the_field() {
    let config = EventMemoryConfig {
        capacity: 4,
        events: vec![
            EventConfig::new("ok", "P0123-1C", 1),
            EventConfig::new("bad", "P5123-1C", 1),
        ],
    };
    let e = EventMemory::new(&config).unwrap_err();
    assert_eq!(e.field, "events[1].dtc");
    assert_eq!(e.value, "\"P5123-1C\"");
    assert!(e.reason.contains("second character must be 0-3"), "{e}");
    assert!(
        e.to_string()
            .starts_with("invalid `events[1].dtc` = \"P5123-1C\": second character"),
        "{e}"
    );

    let config = EventMemoryConfig {
        capacity: 4,
        events: vec![
            EventConfig::new("a", "P0123-1C", 1),
            EventConfig::new("b", "p0123-1c", 1),
        ],
    };
    let e = EventMemory::new(&config).unwrap_err();
    assert_eq!(e.field, "events[1].dtc");
    assert!(e.reason.contains("already used by events[0]"), "{e}");
}
