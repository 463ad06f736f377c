//! Range and rate checks on a raw signal: what OBD circuit codes need.
//!
//! A sensor's output voltage (or any raw signal, in its own units) must stay inside the band its
//! circuit can produce when healthy: below it points to a short to ground or an open circuit
//! with a pull-down ("circuit low", FTB 0x16), above it to a short to supply ("circuit high",
//! FTB 0x17). Its rate of change must stay below what the physics allows; a faster change is an
//! intermittent contact or an erratic signal (the monitor picks the FTB, e.g. 0x2F erratic or
//! 0x64 plausibility). These checks need no model; they decide the circuit codes (P0122/P0123
//! for throttle position A) while the model-based detectors decide range/performance (P0121).
//!
//! Each step yields two [`TestResult`]s, one per OBD $06 test: the range test (`value` = the
//! sample, `min`/`max` = the limits) and the rate test (`value = |dv/dt|`, `min = 0`,
//! `max` = the rate limit), plus the failed condition, if any, as a [`RangeRateFault`]. There
//! are no leaning verdicts: a sample is inside its limits or not; the event memory debounces.
//!
//! Bad input never corrupts state:
//! - a non-finite value (NaN, +-inf) is `Failed` with [`RangeRateFault::Invalid`] (signal
//!   invalid, FTB 0x29): a healthy acquisition chain never produces one. The rate is
//!   `NotTested` and the stored previous sample is kept.
//! - a time stamp that is not finite or not after the previous sample's (duplicate or out of
//!   order): the range is checked as usual, the rate is `NotTested` (no time elapsed to divide
//!   by) and the stored previous sample is kept, so the next in-order sample gets a true rate.
//!
//! The rate is taken between consecutive accepted samples. After a gap (samples missing, or
//! steps disabled) it is the mean rate over the gap, which never exceeds the fastest rate
//! within it: a gap can hide a fast change but cannot invent one.

use serde::{Deserialize, Serialize};

use crate::error::ConfigError;
use crate::verdict::{TestResult, Verdict};

/// Configuration of a [`RangeRateCheck`]. Units are the signal's own (volts for a sensor
/// circuit), e.g. (TOML, a 5 V throttle position sensor)
///
/// ```toml
/// low_limit = 0.2     # V
/// high_limit = 4.8    # V
/// max_rate = 100.0    # V/s
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangeRateConfig {
    /// Lowest value a healthy circuit produces (signal units, finite).
    pub low_limit: f64,
    /// Highest value a healthy circuit produces (signal units, finite, > `low_limit`).
    pub high_limit: f64,
    /// Fastest plausible change, signal units per second (> 0); absent: no rate check.
    #[serde(default)]
    pub max_rate: Option<f64>,
}

impl RangeRateConfig {
    /// Checks the configuration; errors name the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !self.low_limit.is_finite() {
            return Err(ConfigError::new(
                "low_limit",
                self.low_limit,
                "must be a finite number",
            ));
        }
        if !self.high_limit.is_finite() {
            return Err(ConfigError::new(
                "high_limit",
                self.high_limit,
                "must be a finite number",
            ));
        }
        if !(self.high_limit > self.low_limit) {
            return Err(ConfigError::new(
                "high_limit",
                self.high_limit,
                format!("must be greater than low_limit = {}", self.low_limit),
            ));
        }
        if let Some(rate) = self.max_rate {
            if !(rate > 0.0 && rate.is_finite()) {
                return Err(ConfigError::new(
                    "max_rate",
                    rate,
                    "must be a positive finite rate in signal units per second",
                ));
            }
        }
        Ok(())
    }
}

/// Which condition a [`RangeRateCheck`] step failed on, so the monitor can choose the DTC's
/// failure type byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RangeRateFault {
    /// The sample is NaN or infinite.
    Invalid,
    /// Below `low_limit`.
    CircuitLow,
    /// Above `high_limit`.
    CircuitHigh,
    /// `|dv/dt|` above `max_rate`.
    Rate,
}

impl RangeRateFault {
    /// The ISO 14229-1 / SAE J2012 failure type byte that usually goes with the condition:
    /// 0x29 signal invalid, 0x16 circuit voltage below threshold, 0x17 above threshold,
    /// 0x2F signal erratic. A monitor is free to choose another (e.g. 0x1C, 0x64).
    pub fn suggested_ftb(self) -> u8 {
        match self {
            RangeRateFault::Invalid => 0x29,
            RangeRateFault::CircuitLow => 0x16,
            RangeRateFault::CircuitHigh => 0x17,
            RangeRateFault::Rate => 0x2F,
        }
    }
}

/// What one step of a [`RangeRateCheck`] reports.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RangeRateResult {
    /// The range test: `value` = the sample, `min`/`max` = the limits.
    pub range: TestResult,
    /// The rate test: `value = |dv/dt|` (units per second), `min = 0`, `max` = the limit.
    pub rate: TestResult,
    /// The failed condition, the first of `Invalid`, `CircuitLow`, `CircuitHigh`, `Rate`.
    pub fault: Option<RangeRateFault>,
}

impl RangeRateResult {
    const NOT_TESTED: RangeRateResult = RangeRateResult {
        range: TestResult::NOT_TESTED,
        rate: TestResult::NOT_TESTED,
        fault: None,
    };

    /// The combined verdict: `Failed` if either test failed, `Passed` if a test ran and none
    /// failed, `NotTested` if neither ran.
    pub fn verdict(&self) -> Verdict {
        let (a, b) = (self.range.verdict, self.rate.verdict);
        if a == Verdict::Failed || b == Verdict::Failed {
            Verdict::Failed
        } else if a.tested() || b.tested() {
            Verdict::Passed
        } else {
            Verdict::NotTested
        }
    }
}

/// Range and rate check on one raw signal (see [the module docs](self)).
#[derive(Debug, Clone)]
pub struct RangeRateCheck {
    config: RangeRateConfig,
    /// Last accepted sample `(time s, value)`.
    previous: Option<(f64, f64)>,
    last_range: TestResult,
    last_rate: TestResult,
}

impl RangeRateCheck {
    /// Builds the check; errors name the offending field.
    pub fn new(config: &RangeRateConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Self {
            config: *config,
            previous: None,
            last_range: TestResult::NOT_TESTED,
            last_rate: TestResult::NOT_TESTED,
        })
    }

    /// One sample `value` (signal units) taken at `time_s` (seconds, any epoch, increasing).
    /// With `enabled == false` both tests are `NotTested` and nothing changes.
    pub fn step(&mut self, value: f64, time_s: f64, enabled: bool) -> RangeRateResult {
        if !enabled {
            return RangeRateResult::NOT_TESTED;
        }
        let (low, high) = (self.config.low_limit, self.config.high_limit);
        if !value.is_finite() {
            let range = TestResult {
                value,
                min: low,
                max: high,
                verdict: Verdict::Failed,
            };
            self.last_range = range;
            return RangeRateResult {
                range,
                rate: TestResult::NOT_TESTED,
                fault: Some(RangeRateFault::Invalid),
            };
        }
        let (range_verdict, range_fault) = if value < low {
            (Verdict::Failed, Some(RangeRateFault::CircuitLow))
        } else if value > high {
            (Verdict::Failed, Some(RangeRateFault::CircuitHigh))
        } else {
            (Verdict::Passed, None)
        };
        let range = TestResult {
            value,
            min: low,
            max: high,
            verdict: range_verdict,
        };
        self.last_range = range;

        let in_order = time_s.is_finite() && self.previous.is_none_or(|(t0, _)| time_s > t0);
        if !in_order {
            return RangeRateResult {
                range,
                rate: TestResult::NOT_TESTED,
                fault: range_fault,
            };
        }
        let previous = self.previous.replace((time_s, value));
        let rate = match (self.config.max_rate, previous) {
            (Some(limit), Some((t0, v0))) => {
                let r = ((value - v0) / (time_s - t0)).abs();
                let result = TestResult {
                    value: r,
                    min: 0.0,
                    max: limit,
                    verdict: if r > limit {
                        Verdict::Failed
                    } else {
                        Verdict::Passed
                    },
                };
                self.last_rate = result;
                result
            }
            _ => TestResult::NOT_TESTED,
        };
        let fault = range_fault.or(if rate.verdict == Verdict::Failed {
            Some(RangeRateFault::Rate)
        } else {
            None
        });
        RangeRateResult { range, rate, fault }
    }

    /// Forgets the previous sample and the last results, as after construction.
    pub fn reset(&mut self) {
        self.previous = None;
        self.last_range = TestResult::NOT_TESTED;
        self.last_rate = TestResult::NOT_TESTED;
    }

    /// The configuration in force.
    pub fn config(&self) -> &RangeRateConfig {
        &self.config
    }

    /// The most recent tested range result (what OBD service $06 reports).
    pub fn last_range(&self) -> TestResult {
        self.last_range
    }

    /// The most recent tested rate result (what OBD service $06 reports).
    pub fn last_rate(&self) -> TestResult {
        self.last_rate
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check() -> RangeRateCheck {
        RangeRateCheck::new(&RangeRateConfig {
            low_limit: 0.2,
            high_limit: 4.8,
            max_rate: Some(100.0),
        })
        .unwrap()
    }

    #[test]
    fn circuit_low_high_and_rate() {
        let mut c = check();
        // First sample: range only.
        let r = c.step(1.0, 0.000, true);
        assert_eq!(r.range.verdict, Verdict::Passed);
        assert_eq!((r.range.value, r.range.min, r.range.max), (1.0, 0.2, 4.8));
        assert_eq!(r.rate.verdict, Verdict::NotTested);
        assert_eq!((r.verdict(), r.fault), (Verdict::Passed, None));
        // 0.05 V in 1 ms = 50 V/s: fine.
        let r = c.step(1.05, 0.001, true);
        assert_eq!(r.rate.verdict, Verdict::Passed);
        assert!((r.rate.value - 50.0).abs() < 1e-9);
        assert_eq!((r.rate.min, r.rate.max), (0.0, 100.0));
        // Open circuit: 0.05 V, below the band and a -1000 V/s step. Range wins.
        let r = c.step(0.05, 0.002, true);
        assert_eq!(r.fault, Some(RangeRateFault::CircuitLow));
        assert_eq!(r.fault.unwrap().suggested_ftb(), 0x16);
        assert_eq!(
            (r.range.verdict, r.rate.verdict),
            (Verdict::Failed, Verdict::Failed)
        );
        assert!(!r.range.obd06(0x01, 0x0B, 0x0A).passed);
        let r = c.step(4.95, 0.100, true);
        assert_eq!(r.fault, Some(RangeRateFault::CircuitHigh));
        // In range but implausibly fast.
        let r = c.step(2.0, 0.101, true);
        assert_eq!(r.fault, Some(RangeRateFault::Rate));
        assert_eq!(r.range.verdict, Verdict::Passed);
        assert_eq!(r.verdict(), Verdict::Failed);
        // Limits are inclusive.
        let mut c = check();
        assert_eq!(c.step(0.2, 0.0, true).fault, None);
        assert_eq!(c.step(4.8, 1.0, true).fault, None);
    }

    #[test]
    fn bad_samples_do_not_corrupt_state() {
        let mut c = check();
        c.step(1.0, 1.0, true);
        let r = c.step(f64::NAN, 1.001, true);
        assert_eq!(r.fault, Some(RangeRateFault::Invalid));
        assert_eq!(r.range.verdict, Verdict::Failed);
        assert_eq!(r.rate.verdict, Verdict::NotTested);
        // Duplicate and out-of-order stamps: range only, previous sample kept.
        let r = c.step(3.0, 1.0, true);
        assert_eq!(
            (r.range.verdict, r.rate.verdict),
            (Verdict::Passed, Verdict::NotTested)
        );
        let r = c.step(1.0, 0.5, true);
        assert_eq!(r.rate.verdict, Verdict::NotTested);
        let r = c.step(4.5, f64::NAN, true);
        assert_eq!(r.rate.verdict, Verdict::NotTested);
        // The rate is against the last accepted sample (1.0 at 1.0 s): 0.01 V in 10 ms.
        let r = c.step(1.01, 1.010, true);
        assert_eq!(r.rate.verdict, Verdict::Passed);
        assert!((r.rate.value - 1.0).abs() < 1e-9, "{r:?}");
        // Disabled: nothing tested, nothing stored.
        let last = (c.last_range(), c.last_rate());
        let r = c.step(100.0, 2.0, false);
        assert_eq!(r.verdict(), Verdict::NotTested);
        assert_eq!(r.fault, None);
        assert_eq!(last, (c.last_range(), c.last_rate()));
        let r = c.step(1.02, 1.020, true);
        assert!((r.rate.value - 1.0).abs() < 1e-9);
        c.reset();
        assert_eq!(c.last_range().verdict, Verdict::NotTested);
        assert_eq!(c.step(1.0, 0.0, true).rate.verdict, Verdict::NotTested);
    }

    #[test]
    fn without_a_rate_limit_only_the_range_is_tested() {
        let mut c = RangeRateCheck::new(&RangeRateConfig {
            low_limit: -1.0,
            high_limit: 1.0,
            max_rate: None,
        })
        .unwrap();
        c.step(-1.0, 0.0, true);
        let r = c.step(1.0, 1e-6, true);
        assert_eq!(r.rate.verdict, Verdict::NotTested);
        assert_eq!(r.verdict(), Verdict::Passed);
    }

    #[test]
    fn config_errors_name_the_field() {
        let base = RangeRateConfig {
            low_limit: 0.2,
            high_limit: 4.8,
            max_rate: Some(100.0),
        };
        let field = |c: RangeRateConfig| RangeRateCheck::new(&c).unwrap_err().field;
        assert_eq!(
            field(RangeRateConfig {
                low_limit: f64::NAN,
                ..base
            }),
            "low_limit"
        );
        assert_eq!(
            field(RangeRateConfig {
                high_limit: f64::INFINITY,
                ..base
            }),
            "high_limit"
        );
        let wrong_order = RangeRateCheck::new(&RangeRateConfig {
            low_limit: 4.8,
            high_limit: 0.2,
            ..base
        })
        .unwrap_err();
        assert_eq!(wrong_order.field, "high_limit");
        assert!(
            wrong_order.to_string().contains("low_limit"),
            "{wrong_order}"
        );
        assert_eq!(
            field(RangeRateConfig {
                high_limit: 0.2,
                ..base
            }),
            "high_limit"
        );
        for rate in [0.0, -5.0, f64::NAN, f64::INFINITY] {
            assert_eq!(
                field(RangeRateConfig {
                    max_rate: Some(rate),
                    ..base
                }),
                "max_rate"
            );
        }
        let parsed: RangeRateConfig =
            serde_json::from_str(r#"{"low_limit": 0.2, "high_limit": 4.8}"#).unwrap();
        assert_eq!(parsed.max_rate, None);
        assert!(serde_json::from_str::<RangeRateConfig>(
            r#"{"low_limit": 0.2, "high_limit": 4.8, "max_rte": 3}"#
        )
        .is_err());
    }
}
