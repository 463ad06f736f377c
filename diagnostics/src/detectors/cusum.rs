//! Two-sided CUSUM on normalized innovations, for small persistent biases and drifts.
//!
//! Input: the normalized innovation `z = r / sqrt(S)` (dimensionless, N(0, 1) for a consistent
//! filter without a fault). With `delta` the smallest bias worth detecting, in innovation
//! standard deviations, and the reference value `k = delta / 2`:
//!
//! ```text
//! g+ = max(0, g+ + z - k)      (evidence of a positive bias)
//! g- = max(0, g- - z - k)      (evidence of a negative bias)
//! ```
//!
//! and the test fails when `max(g+, g-) > h`. This is Page's CUSUM, the sequential
//! log-likelihood-ratio test between N(0, 1) and N(±delta, 1) scaled by `1 / delta`; it is
//! optimal (Lorden) for a jump of exactly `delta` and detects any bias above `k`. A drift is
//! caught once its accumulated bias exceeds `k`.
//!
//! After an alarm both sums restart from 0, so the time between two false alarms is a fresh run
//! length and the mean time between false alarms equals the average run length without a fault,
//! `ARL0`. The threshold `h` is solved by bisection from the configured `ARL0` with Siegmund's
//! approximation for the one-sided run length of a N(mu, 1) sequence,
//!
//! ```text
//! ARL(mu) = (exp(-2 D b) + 2 D b - 1) / (2 D^2),   D = mu - k,   b = h + 1.166
//! ```
//!
//! (`b^2` at `D = 0`), combined for the two sides as `1/ARL = 1/ARL+ + 1/ARL-`. For `k = 0.5`
//! and `ARL0` in the hundreds to thousands the approximation is within about 1% of the exact
//! (Markov chain) values (e.g. one-sided h = 5: 938 vs 930 exact; h = 5 at mu = 1: 10.3 vs 10.4).
//! The predicted detection delay for a bias `mu` ([`Cusum::predicted_delay`]) is the same
//! formula at that `mu`, counted in samples from the first biased sample (inclusive) with the
//! statistic starting at 0. `tests/detector_statistics.rs` measures both figures.

use serde::{Deserialize, Serialize};

use super::{grade, Detector};
use crate::error::ConfigError;
use crate::verdict::{TestResult, Verdict};

/// Siegmund's constant: the overshoot correction `b = h + 2 * 0.583` for a Gaussian sequence.
const SIEGMUND_OVERSHOOT: f64 = 1.166;

/// Configuration of a [`Cusum`]. Give exactly one of `mean_steps_between_false_alarms` and
/// `false_alarm_rate`, e.g. (TOML)
///
/// ```toml
/// min_bias_sigma = 1.0                         # innovation standard deviations
/// mean_steps_between_false_alarms = 3.6e6      # one per hour at 1 kHz
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CusumConfig {
    /// delta: the smallest bias worth detecting, in innovation standard deviations (> 0). The
    /// reference value is `k = delta / 2`.
    pub min_bias_sigma: f64,
    /// ARL0: the mean time between false alarms, in steps of the monitor feeding the detector
    /// (> the run length of h = 0, about 1 step for delta = 1). A monitor stepping every `dt`
    /// seconds converts a time `T` as `T / dt`.
    #[serde(default)]
    pub mean_steps_between_false_alarms: Option<f64>,
    /// Alternatively the false-alarm rate, in alarms per step, in (0, 1): `ARL0 = 1 / rate`.
    #[serde(default)]
    pub false_alarm_rate: Option<f64>,
}

impl CusumConfig {
    /// Checks the configuration; returns `(k, h)`.
    pub fn validate(&self) -> Result<(f64, f64), ConfigError> {
        let delta = self.min_bias_sigma;
        if !(delta > 0.0 && delta.is_finite()) {
            return Err(ConfigError::new(
                "min_bias_sigma",
                delta,
                "must be a positive finite number of innovation standard deviations",
            ));
        }
        let k = delta / 2.0;
        let (field, arl0) = match (self.mean_steps_between_false_alarms, self.false_alarm_rate) {
            (Some(_), Some(rate)) => {
                return Err(ConfigError::new(
                    "false_alarm_rate",
                    rate,
                    "give either mean_steps_between_false_alarms or false_alarm_rate, not both",
                ))
            }
            (None, None) => {
                return Err(ConfigError::new(
                    "mean_steps_between_false_alarms",
                    "(missing)",
                    "give mean_steps_between_false_alarms or false_alarm_rate",
                ))
            }
            (Some(arl0), None) => {
                if !(arl0 > 0.0 && arl0.is_finite()) {
                    return Err(ConfigError::new(
                        "mean_steps_between_false_alarms",
                        arl0,
                        "must be a positive finite number of steps",
                    ));
                }
                ("mean_steps_between_false_alarms", arl0)
            }
            (None, Some(rate)) => {
                if !(rate > 0.0 && rate < 1.0) {
                    return Err(ConfigError::new(
                        "false_alarm_rate",
                        rate,
                        "must be a rate in alarms per step strictly between 0 and 1",
                    ));
                }
                ("false_alarm_rate", 1.0 / rate)
            }
        };
        let floor = two_sided_arl(0.0, k, 0.0);
        if !(arl0 > floor) {
            let value = if field == "false_alarm_rate" {
                1.0 / arl0
            } else {
                arl0
            };
            return Err(ConfigError::new(
                field,
                value,
                format!(
                    "too frequent: with min_bias_sigma = {delta} even h = 0 gives a false alarm \
                     every {floor:.3} steps on average"
                ),
            ));
        }
        Ok((k, solve_threshold(k, arl0)))
    }
}

/// Which side of a [`Cusum`] alarmed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CusumSide {
    /// `g+`: the innovation mean went up (the measurement reads high against the model).
    Upper,
    /// `g-`: the innovation mean went down.
    Lower,
}

/// Two-sided CUSUM (see [the module docs](self)).
///
/// Verdicts: `Failed` when `max(g+, g-) > h` (the sums then restart from 0); `PreFailed` above
/// `h / 2`; `PrePassed` for the first `ceil(ARL(delta))` tested steps after construction, reset
/// or an alarm, the mean time the CUSUM needs to detect the smallest bias worth detecting from
/// a restart (a pass before then is weak evidence); `Passed` otherwise; `NotTested` when
/// disabled or `z` is not finite (state unchanged).
#[derive(Debug, Clone)]
pub struct Cusum {
    k: f64,
    h: f64,
    settle_steps: usize,
    settle: usize,
    g_upper: f64,
    g_lower: f64,
    alarm_side: Option<CusumSide>,
    last: TestResult,
}

impl Cusum {
    /// Builds the detector; errors name the offending field.
    pub fn new(config: &CusumConfig) -> Result<Self, ConfigError> {
        let (k, h) = config.validate()?;
        let delay = two_sided_arl(config.min_bias_sigma, k, h);
        let settle_steps = if delay.is_finite() {
            delay.ceil() as usize
        } else {
            usize::MAX
        };
        Ok(Self {
            k,
            h,
            settle_steps,
            settle: settle_steps,
            g_upper: 0.0,
            g_lower: 0.0,
            alarm_side: None,
            last: TestResult::NOT_TESTED,
        })
    }

    /// One normalized innovation `z = r / sqrt(S)` (dimensionless).
    ///
    /// Feed only components that took part in the update: a component excluded by a partial
    /// update carries a zero residual, which would read as fault-free evidence; step it with
    /// `enabled = false` instead.
    pub fn step(&mut self, z: f64, enabled: bool) -> TestResult {
        if !enabled || !z.is_finite() {
            return TestResult::NOT_TESTED;
        }
        self.g_upper = (self.g_upper + z - self.k).max(0.0);
        self.g_lower = (self.g_lower - z - self.k).max(0.0);
        let value = self.g_upper.max(self.g_lower);
        let verdict = grade(value, 0.5 * self.h, self.h, self.settle > 0);
        if verdict == Verdict::Failed {
            self.alarm_side = Some(if self.g_upper >= self.g_lower {
                CusumSide::Upper
            } else {
                CusumSide::Lower
            });
            self.g_upper = 0.0;
            self.g_lower = 0.0;
            self.settle = self.settle_steps;
        } else {
            self.settle = self.settle.saturating_sub(1);
        }
        self.last = TestResult {
            value,
            min: 0.0,
            max: self.h,
            verdict,
        };
        self.last
    }

    /// Reference value `k = delta / 2` (innovation standard deviations).
    pub fn reference(&self) -> f64 {
        self.k
    }

    /// Threshold `h` (innovation standard deviations times steps, the unit of the sums).
    pub fn threshold(&self) -> f64 {
        self.h
    }

    /// Current `max(g+, g-)`.
    pub fn statistic(&self) -> f64 {
        self.g_upper.max(self.g_lower)
    }

    /// Current `g+` (evidence of a positive bias).
    pub fn upper(&self) -> f64 {
        self.g_upper
    }

    /// Current `g-` (evidence of a negative bias).
    pub fn lower(&self) -> f64 {
        self.g_lower
    }

    /// The side that crossed at the most recent alarm (`None` before any, or after reset).
    pub fn alarm_side(&self) -> Option<CusumSide> {
        self.alarm_side
    }

    /// Mean time between false alarms (steps) that `h` was solved for (Siegmund).
    pub fn mean_steps_between_false_alarms(&self) -> f64 {
        two_sided_arl(0.0, self.k, self.h)
    }

    /// Predicted mean detection delay (steps, the first biased sample counted as 1, statistic
    /// starting at 0) for a bias of `bias_sigma` innovation standard deviations (Siegmund).
    pub fn predicted_delay(&self, bias_sigma: f64) -> f64 {
        two_sided_arl(bias_sigma, self.k, self.h)
    }
}

impl Detector for Cusum {
    /// The normalized innovation `z`.
    type Input = f64;

    fn step(&mut self, z: f64, enabled: bool) -> TestResult {
        Cusum::step(self, z, enabled)
    }

    fn reset(&mut self) {
        self.g_upper = 0.0;
        self.g_lower = 0.0;
        self.settle = self.settle_steps;
        self.alarm_side = None;
        self.last = TestResult::NOT_TESTED;
    }

    fn last_result(&self) -> TestResult {
        self.last
    }
}

/// Siegmund's approximation of the average run length of the one-sided CUSUM
/// `g = max(0, g + x - k)`, alarm at `g > h`, started at 0, for `x ~ N(mu, 1)` (steps).
pub fn siegmund_arl(mu: f64, k: f64, h: f64) -> f64 {
    let d = mu - k;
    let b = h + SIEGMUND_OVERSHOOT;
    let x = 2.0 * d * b;
    if x.abs() < 1e-4 {
        // exp(-x) + x - 1 = x^2/2 (1 - x/3 + x^2/12 - ...): avoid the cancellation.
        b * b * (1.0 - x / 3.0 + x * x / 12.0)
    } else {
        ((-x).exp_m1() + x) / (2.0 * d * d)
    }
}

/// Average run length of the two-sided CUSUM for `x ~ N(mu, 1)`:
/// `1/ARL = 1/ARL+(mu) + 1/ARL-(mu)`, the lower side seeing `-mu` (steps).
pub fn two_sided_arl(mu: f64, k: f64, h: f64) -> f64 {
    let upper = siegmund_arl(mu, k, h);
    let lower = siegmund_arl(-mu, k, h);
    1.0 / (1.0 / upper + 1.0 / lower)
}

/// `h` with `two_sided_arl(0, k, h) = arl0`, by bisection (the run length grows with `h`).
/// The caller has checked `arl0 > two_sided_arl(0, k, 0)`.
fn solve_threshold(k: f64, arl0: f64) -> f64 {
    let mut lo = 0.0;
    let mut hi = 1.0;
    while two_sided_arl(0.0, k, hi) < arl0 {
        lo = hi;
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if two_sided_arl(0.0, k, mid) < arl0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(delta: f64, arl0: f64) -> CusumConfig {
        CusumConfig {
            min_bias_sigma: delta,
            mean_steps_between_false_alarms: Some(arl0),
            false_alarm_rate: None,
        }
    }

    #[test]
    fn siegmund_reproduces_published_figures() {
        // One-sided k = 0.5, h = 5 (exact Markov-chain values 930 and 10.4).
        assert!((siegmund_arl(0.0, 0.5, 5.0) - 938.2).abs() < 1.0);
        assert!((siegmund_arl(1.0, 0.5, 5.0) - 10.34).abs() < 0.05);
        // Continuous at D = 0 (b^2) and symmetric two-sided figure at mu = 0.
        let b = 4.0 + SIEGMUND_OVERSHOOT;
        assert!((siegmund_arl(0.5, 0.5, 4.0) - b * b).abs() < 1e-9);
        assert!((siegmund_arl(0.5 + 1e-6, 0.5, 4.0) - b * b).abs() < 1e-3);
        assert!((two_sided_arl(0.0, 0.5, 5.0) - 938.2 / 2.0).abs() < 0.5);
    }

    #[test]
    fn threshold_solves_the_configured_mean_time() {
        for (delta, arl0) in [(1.0, 500.0), (0.5, 1e4), (2.0, 1e6), (0.1, 1e9), (1.0, 2.0)] {
            let c = Cusum::new(&cfg(delta, arl0)).unwrap();
            assert!(
                (c.mean_steps_between_false_alarms() / arl0 - 1.0).abs() < 1e-9,
                "delta {delta} arl0 {arl0}"
            );
            assert_eq!(c.reference(), delta / 2.0);
            assert!(c.predicted_delay(delta) < arl0);
        }
        let by_rate = Cusum::new(&CusumConfig {
            min_bias_sigma: 1.0,
            mean_steps_between_false_alarms: None,
            false_alarm_rate: Some(1e-3),
        })
        .unwrap();
        assert!(
            (by_rate.threshold() - Cusum::new(&cfg(1.0, 1e3)).unwrap().threshold()).abs() < 1e-9
        );
    }

    #[test]
    fn config_errors_name_the_field() {
        for delta in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(
                cfg(delta, 500.0).validate().unwrap_err().field,
                "min_bias_sigma"
            );
        }
        for arl0 in [0.0, -5.0, f64::NAN, f64::INFINITY, 1.01] {
            assert_eq!(
                cfg(1.0, arl0).validate().unwrap_err().field,
                "mean_steps_between_false_alarms"
            );
        }
        let mut both = cfg(1.0, 500.0);
        both.false_alarm_rate = Some(0.002);
        assert_eq!(both.validate().unwrap_err().field, "false_alarm_rate");
        let neither = CusumConfig {
            min_bias_sigma: 1.0,
            mean_steps_between_false_alarms: None,
            false_alarm_rate: None,
        };
        assert_eq!(
            neither.validate().unwrap_err().field,
            "mean_steps_between_false_alarms"
        );
        for rate in [0.0, 1.0, 2.0, f64::NAN, 0.99] {
            let c = CusumConfig {
                min_bias_sigma: 1.0,
                mean_steps_between_false_alarms: None,
                false_alarm_rate: Some(rate),
            };
            assert_eq!(c.validate().unwrap_err().field, "false_alarm_rate");
        }
        let parsed: Result<CusumConfig, _> =
            serde_json::from_str(r#"{"min_bias_sigma": 1.0, "mean_time": 5.0}"#);
        assert!(parsed.unwrap_err().to_string().contains("mean_time"));
        let parsed: CusumConfig =
            serde_json::from_str(r#"{"min_bias_sigma": 1.0, "false_alarm_rate": 0.001}"#).unwrap();
        assert!(parsed.validate().is_ok());
    }

    #[test]
    fn recursion_and_verdicts() {
        let mut c = Cusum::new(&cfg(1.0, 500.0)).unwrap();
        let h = c.threshold();
        assert!(h > 3.0 && h < 6.0, "{h}");
        // Initially a pass is only PrePassed (no horizon seen yet).
        let r = c.step(0.0, true);
        assert_eq!(r.verdict, Verdict::PrePassed);
        assert_eq!((r.value, r.min, r.max), (0.0, 0.0, h));
        // g+ = 1.5 - 0.5 = 1.0, g- = 0.
        c.step(1.5, true);
        assert_eq!((c.upper(), c.lower()), (1.0, 0.0));
        // g- = max(0, 0 + 2 - 0.5) = 1.5, g+ = max(0, 1 - 2 - 0.5) = 0.
        c.step(-2.0, true);
        assert_eq!((c.upper(), c.lower()), (0.0, 1.5));
        // Push g- over h/2, then over h.
        let r = c.step(-(0.5 * h) - 0.5, true);
        assert_eq!(r.verdict, Verdict::PreFailed);
        let r = c.step(-h, true);
        assert_eq!(r.verdict, Verdict::Failed);
        assert!(r.value > h);
        assert_eq!(c.alarm_side(), Some(CusumSide::Lower));
        // Restarted from 0; PrePassed for ceil(ARL(delta)) steps, then Passed.
        assert_eq!(c.statistic(), 0.0);
        let settle = c.predicted_delay(1.0).ceil() as usize;
        for _ in 0..settle {
            assert_eq!(c.step(0.0, true).verdict, Verdict::PrePassed);
        }
        assert_eq!(c.step(0.0, true).verdict, Verdict::Passed);
        // An upward alarm.
        let r = c.step(h + 1.0, true);
        assert_eq!(r.verdict, Verdict::Failed);
        assert_eq!(c.alarm_side(), Some(CusumSide::Upper));
    }

    #[test]
    fn disabled_and_invalid_steps_change_nothing() {
        let mut c = Cusum::new(&cfg(1.0, 500.0)).unwrap();
        c.step(1.7, true);
        let last = c.last_result();
        let state = (c.upper(), c.lower(), c.settle);
        for r in [
            c.step(10.0, false),
            c.step(f64::NAN, true),
            c.step(f64::NEG_INFINITY, true),
        ] {
            assert_eq!(r.verdict, Verdict::NotTested);
        }
        assert_eq!(state, (c.upper(), c.lower(), c.settle));
        assert_eq!(c.last_result(), last);
        Detector::reset(&mut c);
        assert_eq!(c.statistic(), 0.0);
        assert_eq!(c.last_result().verdict, Verdict::NotTested);
    }
}
