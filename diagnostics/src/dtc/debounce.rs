//! Debouncing (AUTOSAR Dem): turning a monitor's stream of verdicts into qualified results and
//! a fault detection counter (FDC, -128..127; +127 = qualified failed, -128 = qualified passed).
//!
//! Three algorithms, chosen per event by [`DebounceConfig`]:
//!
//! - **Counter-based** ([`CounterDebounce`], AUTOSAR `DemDebounceCounterBased`). An internal
//!   counter (16-bit, like Dem's) lives between `passed_threshold` (< 0) and `failed_threshold`
//!   (> 0). `PreFailed` adds `increment_step`, `PrePassed` subtracts `decrement_step`; reaching
//!   `failed_threshold` is a qualified `Failed`, reaching `passed_threshold` a qualified
//!   `Passed`. A `Failed` verdict sets the counter to `failed_threshold` at once, `Passed` to
//!   `passed_threshold`. Jump-up (SWS_Dem_00425): a `PreFailed` while the counter is below
//!   `jump_up_value` first sets it to `jump_up_value`, then adds the step (with the usual
//!   `jump_up_value = 0`: a `PreFailed` on a negative counter restarts counting from 0).
//!   Jump-down is the mirror image for `PrePassed` above `jump_down_value`. The FDC is the
//!   counter scaled linearly: `counter * 127 / failed_threshold` for `counter >= 0`,
//!   `counter * 128 / -passed_threshold` below (truncated toward zero), so it is exactly +127 at
//!   the failed threshold and -128 at the passed threshold. With the defaults
//!   (thresholds 127 / -128, steps 1) the FDC equals the counter.
//! - **Time-based** ([`TimeDebounce`], `DemDebounceTimeBase`). A `PreFailed` starts a failure
//!   timer (unless one is already running or the event is already qualified failed); when a
//!   `PreFailed` arrives `failed_time_s` or more after the timer started, the result is a
//!   qualified `Failed`. `PrePassed` and `passed_time_s` mirror it. There is no clock: time is
//!   the `time_s` of each report, so qualification happens at the first report at or after the
//!   deadline. `Failed` / `Passed` qualify at once. FDC = `127 * elapsed / failed_time_s` while
//!   the failure timer runs (`-128 * elapsed / passed_time_s` for the pass timer), +127 / -128
//!   once qualified.
//! - **Monitor-internal** (`DemDebounceMonitorInternal`): the monitor debounces itself; `Failed`
//!   and `Passed` qualify at once (FDC +127 / -128), `PreFailed` / `PrePassed` change nothing.
//!
//! `NotTested` never changes anything. Once qualified, further reports in the same direction
//! report the same qualified result again (the event memory sees no change then). The event
//! memory resets every debouncer at each operation cycle start and at ClearDTC (SWS_Dem_00344).

use serde::{Deserialize, Serialize};

use crate::error::ConfigError;
use crate::verdict::Verdict;

/// A qualified (debounced) test result.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum Qualified {
    /// The test passed (FDC -128).
    Passed,
    /// The test failed (FDC +127).
    Failed,
}

/// Which debounce algorithm an event uses, and its parameters. In TOML:
///
/// ```toml
/// debounce = { kind = "counter", increment_step = 10, decrement_step = 5, failed_threshold = 100, passed_threshold = -100, jump_up = true, jump_up_value = 0 }
/// debounce = { kind = "time", failed_time_s = 0.5, passed_time_s = 1.0 }
/// debounce = { kind = "monitor_internal" }
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DebounceConfig {
    /// Counter-based.
    Counter(CounterDebounce),
    /// Time-based.
    Time(TimeDebounce),
    /// The monitor debounces: only `Failed` / `Passed` count.
    MonitorInternal,
}

impl Default for DebounceConfig {
    /// Counter-based with the defaults of [`CounterDebounce`].
    fn default() -> Self {
        DebounceConfig::Counter(CounterDebounce::default())
    }
}

const fn one() -> u16 {
    1
}
const fn fdc_max() -> i16 {
    127
}
const fn fdc_min() -> i16 {
    -128
}

/// Counter-based debounce parameters (AUTOSAR names without the `DemDebounceCounter` prefix).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CounterDebounce {
    /// Added per `PreFailed` (>= 1; default 1).
    #[serde(default = "one")]
    pub increment_step: u16,
    /// Subtracted per `PrePassed` (>= 1; default 1).
    #[serde(default = "one")]
    pub decrement_step: u16,
    /// Qualified failed at or above this (> 0; default 127).
    #[serde(default = "fdc_max")]
    pub failed_threshold: i16,
    /// Qualified passed at or below this (< 0; default -128).
    #[serde(default = "fdc_min")]
    pub passed_threshold: i16,
    /// Enables jump-up (default false).
    #[serde(default)]
    pub jump_up: bool,
    /// Where a `PreFailed` below it starts counting up from; in
    /// `[passed_threshold, failed_threshold)` (default 0).
    #[serde(default)]
    pub jump_up_value: i16,
    /// Enables jump-down (default false).
    #[serde(default)]
    pub jump_down: bool,
    /// Where a `PrePassed` above it starts counting down from; in
    /// `(passed_threshold, failed_threshold]` (default 0).
    #[serde(default)]
    pub jump_down_value: i16,
}

impl Default for CounterDebounce {
    fn default() -> Self {
        CounterDebounce {
            increment_step: 1,
            decrement_step: 1,
            failed_threshold: 127,
            passed_threshold: -128,
            jump_up: false,
            jump_up_value: 0,
            jump_down: false,
            jump_down_value: 0,
        }
    }
}

/// Time-based debounce parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeDebounce {
    /// How long the fault condition (`PreFailed` reports) must persist, s (finite, >= 0).
    pub failed_time_s: f64,
    /// How long the good condition (`PrePassed` reports) must persist, s (finite, >= 0).
    pub passed_time_s: f64,
}

impl DebounceConfig {
    /// Checks the parameters; `field` is the path of this table as the user wrote it (for
    /// example `events[2].debounce`), and errors name `field.<key>`.
    pub fn validate(&self, field: &str) -> Result<(), ConfigError> {
        match self {
            DebounceConfig::Counter(c) => c.validate(field),
            DebounceConfig::Time(t) => t.validate(field),
            DebounceConfig::MonitorInternal => Ok(()),
        }
    }
}

impl CounterDebounce {
    /// Checks the parameters (see [`DebounceConfig::validate`]).
    pub fn validate(&self, field: &str) -> Result<(), ConfigError> {
        let f = |key: &str| format!("{field}.{key}");
        if self.increment_step == 0 {
            return Err(ConfigError::new(
                f("increment_step"),
                0,
                "must be at least 1 (a PREFAILED must move the counter)",
            ));
        }
        if self.decrement_step == 0 {
            return Err(ConfigError::new(
                f("decrement_step"),
                0,
                "must be at least 1 (a PREPASSED must move the counter)",
            ));
        }
        if self.failed_threshold <= self.passed_threshold {
            return Err(ConfigError::new(
                f("failed_threshold"),
                self.failed_threshold,
                format!(
                    "must be greater than passed_threshold = {} (thresholds in the wrong order)",
                    self.passed_threshold
                ),
            ));
        }
        if self.failed_threshold <= 0 {
            return Err(ConfigError::new(
                f("failed_threshold"),
                self.failed_threshold,
                "must be positive (the counter starts at 0 and counts up to it)",
            ));
        }
        if self.passed_threshold >= 0 {
            return Err(ConfigError::new(
                f("passed_threshold"),
                self.passed_threshold,
                "must be negative (the counter starts at 0 and counts down to it)",
            ));
        }
        if !(self.passed_threshold..self.failed_threshold).contains(&self.jump_up_value) {
            return Err(ConfigError::new(
                f("jump_up_value"),
                self.jump_up_value,
                format!(
                    "must lie in [passed_threshold, failed_threshold) = [{}, {})",
                    self.passed_threshold, self.failed_threshold
                ),
            ));
        }
        if !(self.jump_down_value > self.passed_threshold
            && self.jump_down_value <= self.failed_threshold)
        {
            return Err(ConfigError::new(
                f("jump_down_value"),
                self.jump_down_value,
                format!(
                    "must lie in (passed_threshold, failed_threshold] = ({}, {}]",
                    self.passed_threshold, self.failed_threshold
                ),
            ));
        }
        Ok(())
    }
}

impl TimeDebounce {
    /// Checks the parameters (see [`DebounceConfig::validate`]).
    pub fn validate(&self, field: &str) -> Result<(), ConfigError> {
        for (key, v) in [
            ("failed_time_s", self.failed_time_s),
            ("passed_time_s", self.passed_time_s),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(ConfigError::new(
                    format!("{field}.{key}"),
                    v,
                    "must be a finite number of seconds >= 0",
                ));
            }
        }
        Ok(())
    }
}

/// Where a time-based debouncer stands.
#[derive(Debug, Clone, Copy, PartialEq)]
enum TimeState {
    Idle,
    Failing { since: f64 },
    Passing { since: f64 },
    Failed,
    Passed,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum State {
    Counter(i16),
    Time(TimeState),
    Internal,
}

/// The debounce state of one event. Small and `Copy`; never allocates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Debouncer {
    config: DebounceConfig,
    state: State,
    fdc: i8,
}

impl Debouncer {
    /// A debouncer in its reset state (FDC 0). `config` should have passed
    /// [`DebounceConfig::validate`]; an invalid one still never panics.
    pub fn new(config: DebounceConfig) -> Self {
        let mut d = Debouncer {
            config,
            state: State::Internal,
            fdc: 0,
        };
        d.reset();
        d
    }

    /// The configuration.
    pub fn config(&self) -> &DebounceConfig {
        &self.config
    }

    /// Back to the initial state: counter 0, no timer, FDC 0.
    pub fn reset(&mut self) {
        self.state = match self.config {
            DebounceConfig::Counter(_) => State::Counter(0),
            DebounceConfig::Time(_) => State::Time(TimeState::Idle),
            DebounceConfig::MonitorInternal => State::Internal,
        };
        self.fdc = 0;
    }

    /// The fault detection counter, -128..=127.
    pub fn fdc(&self) -> i8 {
        self.fdc
    }

    /// For counter-based debouncing, the internal counter (between the thresholds).
    pub fn counter(&self) -> Option<i16> {
        match self.state {
            State::Counter(c) => Some(c),
            _ => None,
        }
    }

    /// Feeds one verdict reported at `time_s` (used by time-based debouncing only) and returns
    /// the qualified result, if the verdict leads to one.
    pub fn report(&mut self, verdict: Verdict, time_s: f64) -> Option<Qualified> {
        if verdict == Verdict::NotTested {
            return None;
        }
        match (self.config, &mut self.state) {
            (DebounceConfig::Counter(c), State::Counter(counter)) => {
                let (next, q) = counter_step(&c, *counter, verdict);
                *counter = next;
                self.fdc = counter_fdc(&c, next);
                q
            }
            (DebounceConfig::Time(t), State::Time(state)) => {
                let (next, q, fdc) = time_step(&t, *state, verdict, time_s);
                *state = next;
                self.fdc = fdc;
                q
            }
            _ => match verdict {
                Verdict::Failed => {
                    self.fdc = 127;
                    Some(Qualified::Failed)
                }
                Verdict::Passed => {
                    self.fdc = -128;
                    Some(Qualified::Passed)
                }
                _ => None,
            },
        }
    }
}

fn counter_step(c: &CounterDebounce, counter: i16, verdict: Verdict) -> (i16, Option<Qualified>) {
    let failed = c.failed_threshold;
    let passed = c.passed_threshold;
    match verdict {
        Verdict::Failed => (failed, Some(Qualified::Failed)),
        Verdict::Passed => (passed, Some(Qualified::Passed)),
        Verdict::PreFailed => {
            let mut x = counter as i32;
            if c.jump_up && x < c.jump_up_value as i32 {
                x = c.jump_up_value as i32;
            }
            x += c.increment_step as i32;
            if x >= failed as i32 {
                (failed, Some(Qualified::Failed))
            } else {
                (x as i16, None)
            }
        }
        Verdict::PrePassed => {
            let mut x = counter as i32;
            if c.jump_down && x > c.jump_down_value as i32 {
                x = c.jump_down_value as i32;
            }
            x -= c.decrement_step as i32;
            if x <= passed as i32 {
                (passed, Some(Qualified::Passed))
            } else {
                (x as i16, None)
            }
        }
        Verdict::NotTested => (counter, None),
    }
}

fn counter_fdc(c: &CounterDebounce, counter: i16) -> i8 {
    let x = counter as i32;
    let v = if x >= 0 {
        x * 127 / (c.failed_threshold as i32).max(1)
    } else {
        x * 128 / (-(c.passed_threshold as i32)).max(1)
    };
    v.clamp(-128, 127) as i8
}

fn ramp(elapsed: f64, total: f64, end: f64) -> i8 {
    if !(total > 0.0) || elapsed >= total {
        return end as i8;
    }
    let f = (elapsed.max(0.0) / total) * end;
    f.trunc().clamp(-128.0, 127.0) as i8
}

fn time_step(
    t: &TimeDebounce,
    state: TimeState,
    verdict: Verdict,
    now: f64,
) -> (TimeState, Option<Qualified>, i8) {
    match verdict {
        Verdict::Failed => (TimeState::Failed, Some(Qualified::Failed), 127),
        Verdict::Passed => (TimeState::Passed, Some(Qualified::Passed), -128),
        Verdict::PreFailed => {
            let since = match state {
                TimeState::Failed => return (TimeState::Failed, Some(Qualified::Failed), 127),
                TimeState::Failing { since } => since,
                _ => now,
            };
            let elapsed = now - since;
            if elapsed >= t.failed_time_s {
                (TimeState::Failed, Some(Qualified::Failed), 127)
            } else {
                (
                    TimeState::Failing { since },
                    None,
                    ramp(elapsed, t.failed_time_s, 127.0),
                )
            }
        }
        Verdict::PrePassed => {
            let since = match state {
                TimeState::Passed => return (TimeState::Passed, Some(Qualified::Passed), -128),
                TimeState::Passing { since } => since,
                _ => now,
            };
            let elapsed = now - since;
            if elapsed >= t.passed_time_s {
                (TimeState::Passed, Some(Qualified::Passed), -128)
            } else {
                (
                    TimeState::Passing { since },
                    None,
                    ramp(elapsed, t.passed_time_s, -128.0),
                )
            }
        }
        Verdict::NotTested => (state, None, 0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Verdict::*;

    fn counter(c: CounterDebounce) -> Debouncer {
        c.validate("d").unwrap();
        Debouncer::new(DebounceConfig::Counter(c))
    }

    #[test]
    fn counter_steps_thresholds_and_fdc_scaling() {
        let mut d = counter(CounterDebounce {
            increment_step: 4,
            decrement_step: 2,
            failed_threshold: 10,
            passed_threshold: -8,
            ..Default::default()
        });
        assert_eq!(d.report(PreFailed, 0.0), None);
        assert_eq!((d.counter(), d.fdc()), (Some(4), 50)); // 4 * 127 / 10
        assert_eq!(d.report(PreFailed, 0.0), None);
        assert_eq!(d.report(PreFailed, 0.0), Some(Qualified::Failed));
        assert_eq!((d.counter(), d.fdc()), (Some(10), 127));
        assert_eq!(d.report(PreFailed, 0.0), Some(Qualified::Failed));
        assert_eq!(d.report(NotTested, 0.0), None);
        assert_eq!(d.fdc(), 127);
        assert_eq!(d.report(PrePassed, 0.0), None);
        assert_eq!(d.counter(), Some(8));
        assert_eq!(d.report(Passed, 0.0), Some(Qualified::Passed));
        assert_eq!((d.counter(), d.fdc()), (Some(-8), -128));
        assert_eq!(d.report(PrePassed, 0.0), Some(Qualified::Passed));
        assert_eq!(d.report(PreFailed, 0.0), None);
        assert_eq!((d.counter(), d.fdc()), (Some(-4), -64));
        assert_eq!(d.report(Failed, 0.0), Some(Qualified::Failed));
        d.reset();
        assert_eq!((d.counter(), d.fdc()), (Some(0), 0));
    }

    #[test]
    fn jump_up_and_down() {
        let mut d = counter(CounterDebounce {
            increment_step: 2,
            decrement_step: 2,
            failed_threshold: 6,
            passed_threshold: -6,
            jump_up: true,
            jump_up_value: 0,
            jump_down: true,
            jump_down_value: 1,
        });
        d.report(Passed, 0.0);
        assert_eq!(d.counter(), Some(-6));
        // Below the jump-up value: jump to 0, then step.
        assert_eq!(d.report(PreFailed, 0.0), None);
        assert_eq!(d.counter(), Some(2));
        assert_eq!(d.report(PreFailed, 0.0), None);
        assert_eq!(d.counter(), Some(4));
        // Above the jump-down value: jump to 1, then step.
        assert_eq!(d.report(PrePassed, 0.0), None);
        assert_eq!(d.counter(), Some(-1));
        assert_eq!(d.report(PrePassed, 0.0), None);
        assert_eq!(d.counter(), Some(-3));
    }

    #[test]
    fn time_based() {
        let t = TimeDebounce {
            failed_time_s: 0.5,
            passed_time_s: 1.0,
        };
        t.validate("d").unwrap();
        let mut d = Debouncer::new(DebounceConfig::Time(t));
        assert_eq!(d.report(PreFailed, 10.0), None);
        assert_eq!(d.fdc(), 0);
        assert_eq!(d.report(PreFailed, 10.25), None);
        assert_eq!(d.fdc(), 63);
        assert_eq!(d.report(PreFailed, 10.5), Some(Qualified::Failed));
        assert_eq!(d.fdc(), 127);
        assert_eq!(d.report(PreFailed, 11.0), Some(Qualified::Failed));
        assert_eq!(d.report(PrePassed, 11.0), None);
        assert_eq!(d.report(PrePassed, 11.5), None);
        assert_eq!(d.fdc(), -64);
        // The failure timer restarts when the direction changes.
        assert_eq!(d.report(PreFailed, 11.6), None);
        assert_eq!(d.report(PreFailed, 12.0), None);
        assert_eq!(d.report(PreFailed, 12.1), Some(Qualified::Failed));
        assert_eq!(d.report(Passed, 12.2), Some(Qualified::Passed));
        assert_eq!(d.fdc(), -128);
    }

    #[test]
    fn monitor_internal() {
        let mut d = Debouncer::new(DebounceConfig::MonitorInternal);
        assert_eq!(d.report(PreFailed, 0.0), None);
        assert_eq!(d.fdc(), 0);
        assert_eq!(d.report(Failed, 0.0), Some(Qualified::Failed));
        assert_eq!(d.fdc(), 127);
        assert_eq!(d.report(Passed, 0.0), Some(Qualified::Passed));
        assert_eq!(d.fdc(), -128);
    }

    #[test]
    fn validation_names_the_field() {
        let e = CounterDebounce {
            failed_threshold: -5,
            passed_threshold: 5,
            ..Default::default()
        }
        .validate("events[2].debounce")
        .unwrap_err();
        assert_eq!(e.field, "events[2].debounce.failed_threshold");
        assert!(e.reason.contains("wrong order"), "{e}");
        let e = TimeDebounce {
            failed_time_s: f64::NAN,
            passed_time_s: 1.0,
        }
        .validate("events[0].debounce")
        .unwrap_err();
        assert_eq!(e.field, "events[0].debounce.failed_time_s");
    }
}
