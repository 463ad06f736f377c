//! SAE J2012 trouble codes and their 2-byte and 3-byte (UDS) encodings.
//!
//! A J2012 code such as `P0123` is a letter (the system: P powertrain, C chassis, B body,
//! U network) and four hex digits, the first of which is only 0-3. Its 2-byte form packs the
//! letter into bits 15-14 (`00` P, `01` C, `10` B, `11` U), the second character into bits
//! 13-12 and the last three characters as nibbles:
//!
//! | code | 2 bytes |
//! |---|---|
//! | `P0123` | `0x0123` |
//! | `C0035` | `0x4035` |
//! | `B1234` | `0x9234` |
//! | `U0100` | `0xC100` |
//!
//! Every `u16` is a valid code, so the mapping is a bijection between `u16` and the 4 x 4 x 4096
//! code strings. The ISO 14229-1 (UDS) DTC is three bytes: the 2-byte code followed by the
//! failure type byte (FTB, SAE J2012-DA), written `P0123-1C` = `0x01231C`. These encodings agree
//! with the Python decoders `obd.decoders.parse_dtc` and `udsoncan.Dtc.id_iso` (see
//! `tests/data/dtc_vectors.json` and the script beside it).
//!
//! Parsing accepts either case and gives uppercase text back; anything else (spaces, a missing
//! or extra character, a second character above 3) is a [`DtcParseError`] naming the input and
//! the problem, for example `P5123: second character must be 0-3 (J2012 codes span P0000-P3FFF)`.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use thiserror::Error;

/// The system a J2012 code belongs to: its letter and the top two bits of the 2-byte form.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum DtcSystem {
    /// `P`, powertrain (bits 15-14 = `00`).
    Powertrain,
    /// `C`, chassis (`01`).
    Chassis,
    /// `B`, body (`10`).
    Body,
    /// `U`, network and vehicle integration (`11`).
    Network,
}

impl DtcSystem {
    /// All four systems in the order of their 2-bit value.
    pub const ALL: [DtcSystem; 4] = [
        DtcSystem::Powertrain,
        DtcSystem::Chassis,
        DtcSystem::Body,
        DtcSystem::Network,
    ];

    /// The code letter: `'P'`, `'C'`, `'B'` or `'U'`.
    pub const fn letter(self) -> char {
        match self {
            DtcSystem::Powertrain => 'P',
            DtcSystem::Chassis => 'C',
            DtcSystem::Body => 'B',
            DtcSystem::Network => 'U',
        }
    }

    /// The system of a letter, either case.
    pub const fn from_letter(c: char) -> Option<DtcSystem> {
        match c {
            'P' | 'p' => Some(DtcSystem::Powertrain),
            'C' | 'c' => Some(DtcSystem::Chassis),
            'B' | 'b' => Some(DtcSystem::Body),
            'U' | 'u' => Some(DtcSystem::Network),
            _ => None,
        }
    }

    /// The 2-bit value (0 P, 1 C, 2 B, 3 U).
    pub const fn bits(self) -> u8 {
        match self {
            DtcSystem::Powertrain => 0,
            DtcSystem::Chassis => 1,
            DtcSystem::Body => 2,
            DtcSystem::Network => 3,
        }
    }

    const fn from_bits(bits: u8) -> DtcSystem {
        DtcSystem::ALL[(bits & 3) as usize]
    }
}

/// Why a DTC string or number was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DtcParseErrorKind {
    /// The text is empty.
    Empty,
    /// The code part is not five characters long.
    Length,
    /// The first character is not P, C, B or U.
    Letter,
    /// The second character is not 0-3.
    SecondDigit,
    /// Characters 3-5 are not hex digits.
    HexDigits,
    /// The failure type byte after `-` is not two hex digits.
    FailureType,
    /// A 3-byte UDS value above `0xFFFFFF`.
    TooLarge,
}

impl DtcParseErrorKind {
    fn message(self) -> &'static str {
        match self {
            DtcParseErrorKind::Empty => "empty DTC (expected a code like P0123 or P0123-1C)",
            DtcParseErrorKind::Length => {
                "a J2012 code is a letter and 4 characters (like P0123), optionally followed by \
                 -FTB (like P0123-1C)"
            }
            DtcParseErrorKind::Letter => "first character must be P, C, B or U",
            DtcParseErrorKind::SecondDigit => {
                "second character must be 0-3 (J2012 codes span P0000-P3FFF)"
            }
            DtcParseErrorKind::HexDigits => "characters 3-5 must be hex digits 0-9, A-F",
            DtcParseErrorKind::FailureType => {
                "the failure type byte after '-' must be two hex digits (like -1C)"
            }
            DtcParseErrorKind::TooLarge => "a UDS DTC has 3 bytes (at most 0xFFFFFF)",
        }
    }
}

/// A rejected DTC: the input as given and what is wrong with it. Displays as
/// `"<input>: <problem>"`.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{input}: {}", kind.message())]
pub struct DtcParseError {
    /// The rejected text (or the number, as `0x...`).
    pub input: String,
    /// The problem.
    pub kind: DtcParseErrorKind,
}

impl DtcParseError {
    fn new(input: &str, kind: DtcParseErrorKind) -> Self {
        Self {
            input: input.to_string(),
            kind,
        }
    }

    /// The problem alone, without the input (e.g. `"second character must be 0-3 ..."`).
    pub fn reason(&self) -> &'static str {
        self.kind.message()
    }
}

/// An SAE J2012 code such as `P0123`, stored as its 2-byte form.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct DtcCode(u16);

impl DtcCode {
    /// The code with 2-byte form `value`. Every `u16` is a code.
    pub const fn from_u16(value: u16) -> Self {
        DtcCode(value)
    }

    /// The 2-byte form (bits 15-14 system, 13-12 second character, then three nibbles).
    pub const fn to_u16(self) -> u16 {
        self.0
    }

    /// The code `letter` `digit` `low` (e.g. `(Powertrain, 0, 0x123)` = `P0123`). `digit` is
    /// masked to 0-3 and `low` to 12 bits.
    pub const fn new(system: DtcSystem, digit: u8, low: u16) -> Self {
        DtcCode(((system.bits() as u16) << 14) | (((digit & 3) as u16) << 12) | (low & 0x0FFF))
    }

    /// The system (letter).
    pub const fn system(self) -> DtcSystem {
        DtcSystem::from_bits((self.0 >> 14) as u8)
    }

    /// The second character, 0-3 (J2012: 0 and 2 generic, 1 manufacturer, 3 mixed).
    pub const fn digit(self) -> u8 {
        ((self.0 >> 12) & 3) as u8
    }

    /// The last three characters as a 12-bit number.
    pub const fn low(self) -> u16 {
        self.0 & 0x0FFF
    }

    /// The five characters as ASCII bytes, e.g. `*b"P0123"` (no allocation).
    pub fn to_ascii(self) -> [u8; 5] {
        const HEX: &[u8; 16] = b"0123456789ABCDEF";
        let v = self.0;
        [
            self.system().letter() as u8,
            b'0' + self.digit(),
            HEX[((v >> 8) & 0xF) as usize],
            HEX[((v >> 4) & 0xF) as usize],
            HEX[(v & 0xF) as usize],
        ]
    }
}

fn hex_value(b: u8) -> Option<u8> {
    match b {
        b'0'..=b'9' => Some(b - b'0'),
        b'a'..=b'f' => Some(b - b'a' + 10),
        b'A'..=b'F' => Some(b - b'A' + 10),
        _ => None,
    }
}

/// Parses the five characters of a code; `input` is the whole text, for the error.
fn parse_code(code: &[u8], input: &str) -> Result<DtcCode, DtcParseError> {
    let err = |kind| Err(DtcParseError::new(input, kind));
    if code.is_empty() {
        return err(DtcParseErrorKind::Empty);
    }
    let Some(system) = DtcSystem::from_letter(code[0] as char) else {
        return err(DtcParseErrorKind::Letter);
    };
    if code.len() != 5 {
        return err(DtcParseErrorKind::Length);
    }
    let digit = match code[1] {
        d @ b'0'..=b'3' => d - b'0',
        _ => return err(DtcParseErrorKind::SecondDigit),
    };
    let mut low = 0u16;
    for &b in &code[2..5] {
        let Some(n) = hex_value(b) else {
            return err(DtcParseErrorKind::HexDigits);
        };
        low = (low << 4) | n as u16;
    }
    Ok(DtcCode::new(system, digit, low))
}

impl FromStr for DtcCode {
    type Err = DtcParseError;

    /// Parses `P0123` (either case). A failure type suffix is an error here; use [`Dtc`].
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.is_empty() {
            return Err(DtcParseError::new(s, DtcParseErrorKind::Empty));
        }
        parse_code(s.as_bytes(), s)
    }
}

impl fmt::Display for DtcCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let a = self.to_ascii();
        // The bytes are ASCII by construction.
        f.write_str(std::str::from_utf8(&a).map_err(|_| fmt::Error)?)
    }
}

impl From<u16> for DtcCode {
    fn from(v: u16) -> Self {
        DtcCode(v)
    }
}

impl From<DtcCode> for u16 {
    fn from(c: DtcCode) -> Self {
        c.0
    }
}

/// A UDS (ISO 14229-1) DTC: a J2012 code and its failure type byte, e.g. `P0123-1C` =
/// `0x01231C`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Dtc {
    /// The J2012 code.
    pub code: DtcCode,
    /// The failure type byte (SAE J2012-DA), e.g. `0x1C` voltage out of range; `0x00` means no
    /// subtype information.
    pub ftb: u8,
}

impl Dtc {
    /// The DTC `code`-`ftb`.
    pub const fn new(code: DtcCode, ftb: u8) -> Self {
        Dtc { code, ftb }
    }

    /// The 3-byte UDS value: `code << 8 | ftb`.
    pub const fn to_u32(self) -> u32 {
        ((self.code.to_u16() as u32) << 8) | self.ftb as u32
    }

    /// The DTC of a 3-byte UDS value; values above `0xFFFFFF` are an error.
    pub fn from_u32(value: u32) -> Result<Self, DtcParseError> {
        if value > 0x00FF_FFFF {
            return Err(DtcParseError {
                input: format!("0x{value:X}"),
                kind: DtcParseErrorKind::TooLarge,
            });
        }
        Ok(Dtc {
            code: DtcCode::from_u16((value >> 8) as u16),
            ftb: (value & 0xFF) as u8,
        })
    }

    /// The eight characters as ASCII bytes, e.g. `*b"P0123-1C"` (no allocation).
    pub fn to_ascii(self) -> [u8; 8] {
        const HEX: &[u8; 16] = b"0123456789ABCDEF";
        let c = self.code.to_ascii();
        [
            c[0],
            c[1],
            c[2],
            c[3],
            c[4],
            b'-',
            HEX[(self.ftb >> 4) as usize],
            HEX[(self.ftb & 0xF) as usize],
        ]
    }
}

impl FromStr for Dtc {
    type Err = DtcParseError;

    /// Parses `P0123-1C` (either case). A bare code `P0123` is accepted with FTB `0x00`
    /// ("no subtype information").
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bytes = s.as_bytes();
        if bytes.is_empty() {
            return Err(DtcParseError::new(s, DtcParseErrorKind::Empty));
        }
        let (code_part, ftb_part) = match bytes.iter().position(|&b| b == b'-') {
            Some(i) => (&bytes[..i], Some(&bytes[i + 1..])),
            None => (bytes, None),
        };
        let code = parse_code(code_part, s)?;
        let ftb = match ftb_part {
            None => 0,
            Some([h, l]) => match (hex_value(*h), hex_value(*l)) {
                (Some(h), Some(l)) => (h << 4) | l,
                _ => return Err(DtcParseError::new(s, DtcParseErrorKind::FailureType)),
            },
            Some(_) => return Err(DtcParseError::new(s, DtcParseErrorKind::FailureType)),
        };
        Ok(Dtc { code, ftb })
    }
}

impl fmt::Display for Dtc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let a = self.to_ascii();
        f.write_str(std::str::from_utf8(&a).map_err(|_| fmt::Error)?)
    }
}

impl TryFrom<u32> for Dtc {
    type Error = DtcParseError;

    fn try_from(v: u32) -> Result<Self, Self::Error> {
        Dtc::from_u32(v)
    }
}

impl From<Dtc> for u32 {
    fn from(d: Dtc) -> Self {
        d.to_u32()
    }
}

/// Serialized as the text `"P0123"`.
impl Serialize for DtcCode {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for DtcCode {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// Serialized as the text `"P0123-1C"`.
impl Serialize for Dtc {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Dtc {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_examples() {
        assert_eq!("P0123".parse::<DtcCode>().unwrap().to_u16(), 0x0123);
        assert_eq!("C0035".parse::<DtcCode>().unwrap().to_u16(), 0x4035);
        assert_eq!("U0100".parse::<DtcCode>().unwrap().to_u16(), 0xC100);
        assert_eq!("P0123-1C".parse::<Dtc>().unwrap().to_u32(), 0x01231C);
        assert_eq!(Dtc::from_u32(0x01231C).unwrap().to_string(), "P0123-1C");
        assert_eq!(DtcCode::from_u16(0xFFFF).to_string(), "U3FFF");
    }

    #[test]
    fn errors_name_the_problem() {
        let e = "P5123".parse::<DtcCode>().unwrap_err();
        assert_eq!(e.kind, DtcParseErrorKind::SecondDigit);
        assert!(e
            .to_string()
            .starts_with("P5123: second character must be 0-3"));
        assert_eq!(
            "X0123".parse::<Dtc>().unwrap_err().kind,
            DtcParseErrorKind::Letter
        );
        assert_eq!(
            "P0123-1".parse::<Dtc>().unwrap_err().kind,
            DtcParseErrorKind::FailureType
        );
        assert_eq!(
            Dtc::from_u32(0x0100_0000).unwrap_err().to_string(),
            "0x1000000: a UDS DTC has 3 bytes (at most 0xFFFFFF)"
        );
    }
}
