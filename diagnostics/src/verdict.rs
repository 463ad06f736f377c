//! What one step of a test reports.

use serde::{Deserialize, Serialize};

/// Outcome of one test step, as an AUTOSAR Dem monitor reports it. `PrePassed` / `PreFailed`
/// are the "leaning" states a detector reports before its decision is qualified (for example a
/// CUSUM above half its threshold); the event memory's debounce turns them into qualified
/// results. `NotTested`: the test's enable conditions were false, so the step is no evidence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum Verdict {
    NotTested,
    Passed,
    Failed,
    PrePassed,
    PreFailed,
}

impl Verdict {
    /// True for the verdicts that count as a completed test (everything but `NotTested`).
    pub fn tested(self) -> bool {
        self != Verdict::NotTested
    }

    /// True when the step points to a fault (`Failed` or `PreFailed`).
    pub fn leans_failed(self) -> bool {
        matches!(self, Verdict::Failed | Verdict::PreFailed)
    }
}

/// One step of a test: its statistic and the band it must stay in. OBD convention: the test
/// passes when `min <= value <= max`; a residual test reports its statistic with `min = 0` and
/// `max` = its threshold.
///
/// In JSON a non-finite number (a test that did not run has NaN limits) is written as `null`
/// and read back as NaN, so every result round-trips.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TestResult {
    /// The test statistic (units of the test, e.g. a sum of NIS, or volts for a range check).
    #[serde(with = "nan_as_null")]
    pub value: f64,
    /// Lower limit.
    #[serde(with = "nan_as_null")]
    pub min: f64,
    /// Upper limit.
    #[serde(with = "nan_as_null")]
    pub max: f64,
    /// The verdict for this step.
    pub verdict: Verdict,
}

impl TestResult {
    /// A step in which the test did not run.
    pub const NOT_TESTED: TestResult = TestResult {
        value: f64::NAN,
        min: f64::NAN,
        max: f64::NAN,
        verdict: Verdict::NotTested,
    };

    /// The OBD service $06 record of this result under monitor id `mid`, test id `tid` and
    /// unit-and-scaling id `uasid`. Manufacturer-defined residual tests use `tid >= 0x80`.
    pub fn obd06(&self, mid: u8, tid: u8, uasid: u8) -> Obd06Record {
        Obd06Record {
            mid,
            tid,
            uasid,
            value: self.value,
            min: self.min,
            max: self.max,
            passed: self.min <= self.value && self.value <= self.max,
        }
    }
}

/// Serde helpers writing non-finite `f64` as `null` and reading `null` as NaN.
mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f64(*v)
        } else {
            s.serialize_none()
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }
}

/// An OBD service $06 (on-board monitoring test results) record, in engineering units; the
/// scaling to the 16-bit wire value is given by `uasid` (SAE J1979 unit-and-scaling id).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Obd06Record {
    pub mid: u8,
    pub tid: u8,
    pub uasid: u8,
    pub value: f64,
    pub min: f64,
    pub max: f64,
    /// `min <= value <= max`.
    pub passed: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obd06_passes_inside_band_only() {
        let r = TestResult {
            value: 3.0,
            min: 0.0,
            max: 5.0,
            verdict: Verdict::Passed,
        };
        assert!(r.obd06(0xA1, 0x81, 0x24).passed);
        let r = TestResult { value: 5.5, ..r };
        assert!(!r.obd06(0xA1, 0x81, 0x24).passed);
        assert!(!TestResult::NOT_TESTED.obd06(0, 0x80, 0).passed);
        assert!(!Verdict::NotTested.tested());
        assert!(Verdict::PreFailed.leans_failed() && !Verdict::PrePassed.leans_failed());
    }

    #[test]
    fn json_round_trips_including_untested_results() {
        let r = TestResult {
            value: 4.93,
            min: 0.25,
            max: 4.75,
            verdict: Verdict::Failed,
        };
        let text = serde_json::to_string(&r).expect("serializes");
        assert_eq!(
            text,
            r#"{"value":4.93,"min":0.25,"max":4.75,"verdict":"FAILED"}"#
        );
        assert_eq!(
            serde_json::from_str::<TestResult>(&text).expect("parses"),
            r
        );
        let text = serde_json::to_string(&TestResult::NOT_TESTED).expect("serializes");
        assert_eq!(
            text,
            r#"{"value":null,"min":null,"max":null,"verdict":"NOT_TESTED"}"#
        );
        let back: TestResult = serde_json::from_str(&text).expect("parses");
        assert!(back.value.is_nan() && back.min.is_nan() && back.max.is_nan());
        assert_eq!(back.verdict, Verdict::NotTested);
    }
}
