//! Change detectors on innovations and range/rate checks on raw signals.
//!
//! | detector | input per step | statistic (`value`) | limit (`max`) from |
//! |---|---|---|---|
//! | [`ChiSquareWindow`] | NIS and its degrees of freedom | sum of the last W NIS | chi-square quantile at the false-alarm probability |
//! | [`Cusum`] | normalized innovation `z = r / sqrt(S)` | `max(g+, g-)` | mean time between false alarms (Siegmund) |
//! | [`Glr`] | normalized innovation `z` | max log-likelihood ratio of a mean jump in the window | false-alarm probability (numerical boundary-crossing integral) |
//! | [`RangeRateCheck`] | raw value and its time stamp | the value; the absolute rate of change | configured limits |
//!
//! Every threshold is traceable to a false-alarm figure (the statistical tests in
//! `tests/detector_statistics.rs` measure it), and no step allocates (`tests/detector_no_alloc.rs`).
//!
//! # Verdicts
//!
//! Each step yields a [`TestResult`] with `min = 0` and `max` = the threshold, so
//! [`TestResult::obd06`] gives the OBD service $06 record directly. The statistical detectors
//! grade a step as:
//!
//! - `NotTested`: the enable condition is false, the input is not a finite number (the filter
//!   reports its own divergence; a NaN is no evidence either way), or, for the windowed tests,
//!   the window has not filled since construction or [`Detector::reset`]. Such a step leaves
//!   the detector's state exactly as it was.
//! - `Failed`: statistic `>` threshold.
//! - `PreFailed`: statistic above the *prefail level*: the level the fault-free statistic exceeds
//!   with probability `sqrt(p)` (windowed tests), or half the threshold (CUSUM). Both are
//!   "halfway to the threshold" on the log-likelihood scale, where the statistics live: the
//!   fault-free tail of each decays roughly like `exp(-statistic)`.
//! - `PrePassed`: statistic at or below the prefail level, but the detector has not yet seen a
//!   full detection horizon of data since the last failure (windowed tests: the window still
//!   holds samples of the failing window; CUSUM: fewer steps since its restart, or since start,
//!   than it needs on average to detect the smallest bias worth detecting). The event memory's
//!   debounce then walks back towards "passed" instead of jumping there.
//! - `Passed`: otherwise.
//!
//! The range/rate check has no leaning states: a value is inside its limits or not.

pub mod chi_square;
pub mod cusum;
pub mod glr;
pub mod range_rate;

pub use chi_square::{chi_square_upper_quantile, ChiSquareConfig, ChiSquareWindow};
pub use cusum::{siegmund_arl, two_sided_arl, Cusum, CusumConfig, CusumSide};
pub use glr::{glr_false_alarm_probability, glr_threshold, Glr, GlrConfig, MAX_GLR_WINDOW};
pub use range_rate::{RangeRateCheck, RangeRateConfig, RangeRateFault, RangeRateResult};

use crate::error::ConfigError;
use crate::verdict::{TestResult, Verdict};

/// A detector that turns one input per step into a [`TestResult`].
pub trait Detector {
    /// What one step consumes (a normalized innovation, or NIS and degrees of freedom).
    type Input;

    /// Runs one step. With `enabled == false` the step is `NotTested` and changes nothing.
    fn step(&mut self, input: Self::Input, enabled: bool) -> TestResult;

    /// Forgets all data, as after construction.
    fn reset(&mut self);

    /// The most recent tested result (what OBD service $06 reports), `NOT_TESTED` if none.
    fn last_result(&self) -> TestResult;
}

/// Smallest false-alarm probability accepted. Below it the thresholds are set by rounding
/// rather than by the configuration (`1 - p` is 1 in f64 well before p reaches 1e-16); and a
/// per-decision probability of 1e-12 at 1 kHz is already one false alarm per 30 years.
pub const MIN_FALSE_ALARM_PROBABILITY: f64 = 1e-12;

/// Checks a probability field: finite, in `[MIN_FALSE_ALARM_PROBABILITY, 1)`.
pub(crate) fn validate_probability(field: &str, p: f64) -> Result<f64, ConfigError> {
    if !(p > 0.0 && p < 1.0) {
        return Err(ConfigError::new(
            field,
            p,
            "must be a probability strictly between 0 and 1",
        ));
    }
    if p < MIN_FALSE_ALARM_PROBABILITY {
        return Err(ConfigError::new(
            field,
            p,
            format!("must be at least {MIN_FALSE_ALARM_PROBABILITY:e} (numerical resolution)"),
        ));
    }
    Ok(p)
}

/// Checks a window length field: `1 <= window <= min(capacity, max)`.
pub(crate) fn validate_window(
    field: &str,
    window: i64,
    capacity: usize,
    max: usize,
) -> Result<usize, ConfigError> {
    if window < 1 {
        return Err(ConfigError::new(
            field,
            window,
            "must be a positive number of samples",
        ));
    }
    let limit = capacity.min(max);
    match usize::try_from(window) {
        Ok(w) if w <= limit => Ok(w),
        _ => Err(ConfigError::new(
            field,
            window,
            if capacity <= max {
                format!("exceeds this detector's capacity of {capacity} samples")
            } else {
                format!("exceeds the largest supported window of {max} samples")
            },
        )),
    }
}

/// Grades a statistic (see the module docs). `settling`: a pass is only a `PrePassed`.
pub(crate) fn grade(value: f64, prefail: f64, threshold: f64, settling: bool) -> Verdict {
    if value > threshold {
        Verdict::Failed
    } else if value > prefail {
        Verdict::PreFailed
    } else if settling {
        Verdict::PrePassed
    } else {
        Verdict::Passed
    }
}

/// A fixed-capacity ring buffer holding the last `window <= CAP` values; no heap.
#[derive(Debug, Clone)]
pub(crate) struct Ring<T: Copy + Default, const CAP: usize> {
    buf: [T; CAP],
    window: usize,
    /// Index the next value is written to, in `0..window`.
    next: usize,
    len: usize,
}

impl<T: Copy + Default, const CAP: usize> Ring<T, CAP> {
    /// An empty ring keeping the last `window` values (`1 <= window <= CAP`, checked by callers).
    pub(crate) fn new(window: usize) -> Self {
        debug_assert!(window >= 1 && window <= CAP);
        Self {
            buf: [T::default(); CAP],
            window,
            next: 0,
            len: 0,
        }
    }

    /// Appends `x`; returns the value it evicted once the ring is full.
    pub(crate) fn push(&mut self, x: T) -> Option<T> {
        let evicted = if self.len == self.window {
            Some(self.buf[self.next])
        } else {
            self.len += 1;
            None
        };
        self.buf[self.next] = x;
        self.next += 1;
        if self.next == self.window {
            self.next = 0;
        }
        evicted
    }

    pub(crate) fn is_full(&self) -> bool {
        self.len == self.window
    }

    pub(crate) fn clear(&mut self) {
        self.next = 0;
        self.len = 0;
    }

    /// The stored values, newest first.
    pub(crate) fn newest_first(&self) -> impl Iterator<Item = T> + '_ {
        // Before the first wrap `next == len` and the second slice is empty; once full, the
        // older values sit in `next..window`.
        self.buf[..self.next]
            .iter()
            .rev()
            .chain(self.buf[self.next..self.len].iter().rev())
            .copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_keeps_the_last_window_values_newest_first() {
        let mut r = Ring::<f64, 8>::new(3);
        assert_eq!(r.newest_first().count(), 0);
        assert_eq!(r.push(1.0), None);
        assert_eq!(r.push(2.0), None);
        assert!(!r.is_full());
        assert_eq!(r.newest_first().collect::<Vec<_>>(), vec![2.0, 1.0]);
        assert_eq!(r.push(3.0), None);
        assert!(r.is_full());
        assert_eq!(r.push(4.0), Some(1.0));
        assert_eq!(r.push(5.0), Some(2.0));
        assert_eq!(r.newest_first().collect::<Vec<_>>(), vec![5.0, 4.0, 3.0]);
        r.clear();
        assert_eq!(r.newest_first().count(), 0);
    }

    #[test]
    fn grading_bands() {
        assert_eq!(grade(11.0, 5.0, 10.0, false), Verdict::Failed);
        assert_eq!(grade(10.0, 5.0, 10.0, false), Verdict::PreFailed);
        assert_eq!(grade(5.0, 5.0, 10.0, false), Verdict::Passed);
        assert_eq!(grade(5.0, 5.0, 10.0, true), Verdict::PrePassed);
        assert_eq!(grade(6.0, 5.0, 10.0, true), Verdict::PreFailed);
    }

    #[test]
    fn shared_validation_names_the_field() {
        for p in [0.0, 1.0, -0.5, 2.0, f64::NAN, f64::INFINITY, 1e-13] {
            let e = validate_probability("false_alarm_probability", p).unwrap_err();
            assert_eq!(e.field, "false_alarm_probability");
        }
        assert_eq!(validate_probability("p", 0.01), Ok(0.01));
        for w in [-3, 0, 65] {
            let e = validate_window("window", w, 64, 1000).unwrap_err();
            assert_eq!(e.field, "window");
        }
        let e = validate_window("window", 300, 1024, 256).unwrap_err();
        assert!(e.reason.contains("256"), "{e}");
        assert_eq!(validate_window("window", 64, 64, 1000), Ok(64));
    }
}
