//! The ISO 14229-1 DTC status byte.
//!
//! | bit | mask | name (ISO 14229-1) | set when | cleared when |
//! |---|---|---|---|---|
//! | 0 | `0x01` | `testFailed` | a qualified failure | a qualified pass; ClearDTC |
//! | 1 | `0x02` | `testFailedThisOperationCycle` | a qualified failure | operation cycle start; ClearDTC |
//! | 2 | `0x04` | `pendingDTC` | a qualified failure | end of a cycle that completed the test without failure; ClearDTC |
//! | 3 | `0x08` | `confirmedDTC` | the failure was seen in the configured number of failed cycles | aging; displacement of the memory entry; ClearDTC |
//! | 4 | `0x10` | `testNotCompletedSinceLastClear` | ClearDTC | any qualified result |
//! | 5 | `0x20` | `testFailedSinceLastClear` | a qualified failure | ClearDTC |
//! | 6 | `0x40` | `testNotCompletedThisOperationCycle` | operation cycle start; ClearDTC | any qualified result |
//! | 7 | `0x80` | `warningIndicatorRequested` | the MIL rule fires (see [`crate::dtc::MilOn`]) | after the configured passing cycles; ClearDTC |
//!
//! After ClearDTC the byte is `0x50`; a first qualified failure gives `0x27`; a confirmed DTC
//! `0x2F`, with the MIL `0xAF`. The event memory ([`crate::dtc::EventMemory`]) applies these
//! rules; this module is only the byte and its bit names.

use std::fmt;

use serde::{Deserialize, Serialize};

/// One bit of the status byte. Serializes as its ISO 14229-1 name (`"testFailed"`, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum StatusBit {
    /// Bit 0, TF: the most recent qualified result was a failure.
    #[serde(rename = "testFailed")]
    TestFailed = 0,
    /// Bit 1, TFTOC: a qualified failure happened in the current operation cycle.
    #[serde(rename = "testFailedThisOperationCycle")]
    TestFailedThisOperationCycle = 1,
    /// Bit 2: failed in the current or the last completed operation cycle.
    #[serde(rename = "pendingDTC")]
    PendingDtc = 2,
    /// Bit 3: the failure is confirmed (stored long term, until aging or clear).
    #[serde(rename = "confirmedDTC")]
    ConfirmedDtc = 3,
    /// Bit 4, TNCSLC: no qualified result since the last ClearDTC.
    #[serde(rename = "testNotCompletedSinceLastClear")]
    TestNotCompletedSinceLastClear = 4,
    /// Bit 5, TFSLC: a qualified failure since the last ClearDTC.
    #[serde(rename = "testFailedSinceLastClear")]
    TestFailedSinceLastClear = 5,
    /// Bit 6, TNCTOC: no qualified result in the current operation cycle.
    #[serde(rename = "testNotCompletedThisOperationCycle")]
    TestNotCompletedThisOperationCycle = 6,
    /// Bit 7, WIR: the DTC requests the warning indicator (MIL).
    #[serde(rename = "warningIndicatorRequested")]
    WarningIndicatorRequested = 7,
}

impl StatusBit {
    /// All bits, bit 0 first.
    pub const ALL: [StatusBit; 8] = [
        StatusBit::TestFailed,
        StatusBit::TestFailedThisOperationCycle,
        StatusBit::PendingDtc,
        StatusBit::ConfirmedDtc,
        StatusBit::TestNotCompletedSinceLastClear,
        StatusBit::TestFailedSinceLastClear,
        StatusBit::TestNotCompletedThisOperationCycle,
        StatusBit::WarningIndicatorRequested,
    ];

    /// The bit's mask in the byte (`1 << bit`).
    pub const fn mask(self) -> u8 {
        1 << (self as u8)
    }

    /// The ISO 14229-1 name, as serialized (e.g. `"pendingDTC"`).
    pub const fn name(self) -> &'static str {
        match self {
            StatusBit::TestFailed => "testFailed",
            StatusBit::TestFailedThisOperationCycle => "testFailedThisOperationCycle",
            StatusBit::PendingDtc => "pendingDTC",
            StatusBit::ConfirmedDtc => "confirmedDTC",
            StatusBit::TestNotCompletedSinceLastClear => "testNotCompletedSinceLastClear",
            StatusBit::TestFailedSinceLastClear => "testFailedSinceLastClear",
            StatusBit::TestNotCompletedThisOperationCycle => "testNotCompletedThisOperationCycle",
            StatusBit::WarningIndicatorRequested => "warningIndicatorRequested",
        }
    }
}

impl fmt::Display for StatusBit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The ISO 14229-1 status byte of one DTC. Serializes as the number (0-255).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct DtcStatus(u8);

impl DtcStatus {
    /// Bit 0, `testFailed`.
    pub const TF: u8 = 0x01;
    /// Bit 1, `testFailedThisOperationCycle`.
    pub const TFTOC: u8 = 0x02;
    /// Bit 2, `pendingDTC`.
    pub const PDTC: u8 = 0x04;
    /// Bit 3, `confirmedDTC`.
    pub const CDTC: u8 = 0x08;
    /// Bit 4, `testNotCompletedSinceLastClear`.
    pub const TNCSLC: u8 = 0x10;
    /// Bit 5, `testFailedSinceLastClear`.
    pub const TFSLC: u8 = 0x20;
    /// Bit 6, `testNotCompletedThisOperationCycle`.
    pub const TNCTOC: u8 = 0x40;
    /// Bit 7, `warningIndicatorRequested`.
    pub const WIR: u8 = 0x80;

    /// The byte after ClearDTC (and at power-up without stored state): `0x50`, both
    /// "not completed" bits set.
    pub const AFTER_CLEAR: DtcStatus = DtcStatus(Self::TNCSLC | Self::TNCTOC);

    /// The DTCStatusAvailabilityMask this implementation reports: all eight bits are supported.
    pub const AVAILABILITY_MASK: u8 = 0xFF;

    /// The status with byte `byte`.
    pub const fn from_byte(byte: u8) -> Self {
        DtcStatus(byte)
    }

    /// The byte.
    pub const fn byte(self) -> u8 {
        self.0
    }

    /// Whether `bit` is set.
    pub const fn get(self, bit: StatusBit) -> bool {
        self.0 & bit.mask() != 0
    }

    /// Sets `bit` to `on`.
    pub fn set(&mut self, bit: StatusBit, on: bool) {
        self.set_mask(bit.mask(), on);
    }

    /// Sets (`on`) or clears every bit of `mask`.
    pub fn set_mask(&mut self, mask: u8, on: bool) {
        if on {
            self.0 |= mask;
        } else {
            self.0 &= !mask;
        }
    }

    /// Whether every bit of `mask` is set.
    pub const fn contains(self, mask: u8) -> bool {
        self.0 & mask == mask
    }

    /// UDS ReadDTCInformation matching: true when any bit of `mask` is set.
    pub const fn matches(self, mask: u8) -> bool {
        self.0 & mask != 0
    }

    /// The bits that differ between `self` and `other`, bit 0 first.
    pub fn changed_bits(self, other: DtcStatus) -> impl Iterator<Item = StatusBit> {
        let diff = self.0 ^ other.0;
        StatusBit::ALL
            .into_iter()
            .filter(move |b| diff & b.mask() != 0)
    }

    /// `testFailed`.
    pub const fn test_failed(self) -> bool {
        self.0 & Self::TF != 0
    }

    /// `pendingDTC`.
    pub const fn pending(self) -> bool {
        self.0 & Self::PDTC != 0
    }

    /// `confirmedDTC`.
    pub const fn confirmed(self) -> bool {
        self.0 & Self::CDTC != 0
    }

    /// `warningIndicatorRequested`.
    pub const fn warning_indicator(self) -> bool {
        self.0 & Self::WIR != 0
    }
}

impl From<u8> for DtcStatus {
    fn from(b: u8) -> Self {
        DtcStatus(b)
    }
}

impl From<DtcStatus> for u8 {
    fn from(s: DtcStatus) -> Self {
        s.0
    }
}

/// `0x2F`.
impl fmt::LowerHex for DtcStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::LowerHex::fmt(&self.0, f)
    }
}

impl fmt::UpperHex for DtcStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::UpperHex::fmt(&self.0, f)
    }
}

/// `0x2F [testFailed, testFailedThisOperationCycle, pendingDTC, confirmedDTC, testFailedSinceLastClear]`.
impl fmt::Display for DtcStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:02X} [", self.0)?;
        let mut first = true;
        for b in StatusBit::ALL {
            if self.get(b) {
                if !first {
                    f.write_str(", ")?;
                }
                f.write_str(b.name())?;
                first = false;
            }
        }
        f.write_str("]")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_and_names() {
        for (i, b) in StatusBit::ALL.into_iter().enumerate() {
            assert_eq!(b.mask(), 1 << i);
            assert_eq!(
                serde_json::to_string(&b).unwrap(),
                format!("\"{}\"", b.name())
            );
        }
        assert_eq!(DtcStatus::AFTER_CLEAR.byte(), 0x50);
        let changed: Vec<_> = DtcStatus::from_byte(0x50)
            .changed_bits(DtcStatus::from_byte(0x27))
            .collect();
        assert_eq!(
            changed,
            [
                StatusBit::TestFailed,
                StatusBit::TestFailedThisOperationCycle,
                StatusBit::PendingDtc,
                StatusBit::TestNotCompletedSinceLastClear,
                StatusBit::TestFailedSinceLastClear,
                StatusBit::TestNotCompletedThisOperationCycle,
            ]
        );
        assert_eq!(
            DtcStatus::from_byte(0x2F).to_string(),
            "0x2F [testFailed, testFailedThisOperationCycle, pendingDTC, confirmedDTC, \
             testFailedSinceLastClear]"
        );
    }
}
