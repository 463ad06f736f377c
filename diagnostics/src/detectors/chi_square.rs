//! Windowed chi-square test on the normalized innovation squared (NIS).
//!
//! For a consistent filter without a fault, the NIS `r' S^-1 r` of an update that used `d`
//! measurement components is chi-square with `d` degrees of freedom, and the NIS of different
//! updates are independent (the innovations of an optimal filter are white). The sum of the last
//! W NIS is therefore chi-square with `D` = the sum of their degrees of freedom, and the test
//! fails when the sum exceeds the chi-square upper quantile at the configured false-alarm
//! probability `p`: `P(sum > threshold | no fault) = p` for each decision.
//!
//! The window sums W updates so a fault that raises the NIS a little on every step shows up
//! (the sum's mean grows like W while its spread grows like `sqrt(W)`), while a single outlier
//! is diluted.
//!
//! Successive decisions share W - 1 samples and are strongly correlated: `p` is the probability
//! per decision, and decisions on non-overlapping windows (every W-th step) are independent
//! Bernoulli(p) trials, which is how `tests/detector_statistics.rs` checks it.
//!
//! Updates may use different numbers of components (partial updates drop a failed sensor): each
//! step carries its own degrees of freedom and the threshold follows the window's total. The
//! quantile for a total is computed when the window first fills and again only when the total
//! changes (about a microsecond in release, no allocation): with a constant number of
//! components per update, once.

use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, Continuous, ContinuousCDF};
use statrs::function::erf::erfc_inv;

use fdd_estimators::Innovation;

use super::{grade, validate_probability, validate_window, Detector, Ring};
use crate::error::ConfigError;
use crate::verdict::{TestResult, Verdict};

/// Configuration of a [`ChiSquareWindow`], e.g. (TOML)
///
/// ```toml
/// window = 20                      # updates
/// false_alarm_probability = 1e-3   # per decision
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChiSquareConfig {
    /// W: number of consecutive updates whose NIS are summed (samples), `1..=CAP`. Signed so
    /// that a negative value in a file reaches validation and is reported naming this field.
    pub window: i64,
    /// p: probability that one decision on fault-free data fails (per decision,
    /// dimensionless), in `[1e-12, 1)`.
    pub false_alarm_probability: f64,
}

impl ChiSquareConfig {
    /// Checks the configuration for a detector holding at most `capacity` samples; returns the
    /// window length.
    pub fn validate(&self, capacity: usize) -> Result<usize, ConfigError> {
        let window = validate_window("window", self.window, capacity, usize::MAX)?;
        validate_probability("false_alarm_probability", self.false_alarm_probability)?;
        Ok(window)
    }
}

/// Windowed chi-square test on the NIS of the last W updates, `W <= CAP`.
///
/// Verdicts (see [the module docs](super)): `NotTested` until W valid NIS have been seen;
/// `Failed` when the sum exceeds the threshold; `PreFailed` above the quantile at `sqrt(p)`;
/// `PrePassed` while the window still holds samples of a failing window (W - 1 steps after a
/// `Failed` step); `Passed` otherwise. The window is not cleared after a failure: it keeps
/// failing while the faulty samples are in it, which is the evidence the debounce wants.
#[derive(Debug, Clone)]
pub struct ChiSquareWindow<const CAP: usize> {
    window: usize,
    p: f64,
    /// `(nis, dof)` per update.
    ring: Ring<(f64, u32), CAP>,
    /// Running sum of the NIS in the ring; recomputed from the ring every `window` pushes so
    /// rounding from adding and removing (possibly huge, faulty) values cannot accumulate.
    sum: f64,
    dof_sum: u64,
    pushes_since_resum: usize,
    /// Total degrees of freedom the cached limits are for (0: none cached yet).
    cached_dof: u64,
    threshold: f64,
    prefail: f64,
    /// Tested steps left in which a pass is only a `PrePassed`.
    settle: usize,
    last: TestResult,
}

impl<const CAP: usize> ChiSquareWindow<CAP> {
    /// Builds the detector; errors name the offending field.
    pub fn new(config: &ChiSquareConfig) -> Result<Self, ConfigError> {
        let window = config.validate(CAP)?;
        Ok(Self {
            window,
            p: config.false_alarm_probability,
            ring: Ring::new(window),
            sum: 0.0,
            dof_sum: 0,
            pushes_since_resum: 0,
            cached_dof: 0,
            threshold: f64::NAN,
            prefail: f64::NAN,
            settle: 0,
            last: TestResult::NOT_TESTED,
        })
    }

    /// One update's NIS (dimensionless, `>= 0`) with the number of measurement components it
    /// used. A step with `enabled == false`, `dof == 0` (nothing measured), or a NIS that is not
    /// a finite non-negative number is `NotTested` and leaves the window unchanged.
    pub fn step(&mut self, nis: f64, dof: usize, enabled: bool) -> TestResult {
        let valid_nis = nis >= 0.0 && nis.is_finite();
        let dof32 = match u32::try_from(dof) {
            Ok(d) if enabled && valid_nis && d > 0 => d,
            _ => return TestResult::NOT_TESTED,
        };
        match self.ring.push((nis, dof32)) {
            Some((old_nis, old_dof)) => {
                self.sum += nis - old_nis;
                self.dof_sum = self.dof_sum + dof as u64 - old_dof as u64;
            }
            None => {
                self.sum += nis;
                self.dof_sum += dof as u64;
            }
        }
        self.pushes_since_resum += 1;
        if self.pushes_since_resum >= self.window {
            self.sum = self.ring.newest_first().map(|(x, _)| x).sum();
            self.pushes_since_resum = 0;
        }
        if !self.ring.is_full() {
            return TestResult::NOT_TESTED;
        }
        if self.dof_sum != self.cached_dof {
            let k = self.dof_sum as f64;
            self.threshold = chi_square_upper_quantile(self.p, k);
            self.prefail = chi_square_upper_quantile(self.p.sqrt(), k);
            self.cached_dof = self.dof_sum;
        }
        let verdict = grade(self.sum, self.prefail, self.threshold, self.settle > 0);
        if verdict == Verdict::Failed {
            self.settle = self.window - 1;
        } else {
            self.settle = self.settle.saturating_sub(1);
        }
        self.last = TestResult {
            value: self.sum,
            min: 0.0,
            max: self.threshold,
            verdict,
        };
        self.last
    }

    /// [`step`](Self::step) with an estimator's innovation (its `nis` and `dof`).
    pub fn step_innovation<const M: usize>(
        &mut self,
        innovation: &Innovation<M>,
        enabled: bool,
    ) -> TestResult {
        self.step(innovation.nis, innovation.dof, enabled)
    }

    /// Window length W (samples).
    pub fn window(&self) -> usize {
        self.window
    }

    /// Configured false-alarm probability per decision.
    pub fn false_alarm_probability(&self) -> f64 {
        self.p
    }

    /// The current sum of NIS over the window (partial sum before the window has filled).
    pub fn statistic(&self) -> f64 {
        self.sum
    }

    /// Threshold for the window's current total degrees of freedom; NaN before the first fill.
    pub fn threshold(&self) -> f64 {
        self.threshold
    }

    /// Threshold for a window in which every update has `dof` degrees of freedom.
    pub fn threshold_for_dof(&self, dof: usize) -> f64 {
        chi_square_upper_quantile(self.p, (self.window * dof) as f64)
    }
}

impl<const CAP: usize> Detector for ChiSquareWindow<CAP> {
    /// `(nis, dof)`.
    type Input = (f64, usize);

    fn step(&mut self, (nis, dof): (f64, usize), enabled: bool) -> TestResult {
        ChiSquareWindow::step(self, nis, dof, enabled)
    }

    fn reset(&mut self) {
        self.ring.clear();
        self.sum = 0.0;
        self.dof_sum = 0;
        self.pushes_since_resum = 0;
        self.settle = 0;
        self.last = TestResult::NOT_TESTED;
    }

    fn last_result(&self) -> TestResult {
        self.last
    }
}

/// The chi-square upper quantile: `x` with `P(X > x) = p` for `X ~ chi2(dof)`.
///
/// Solved on the survival function (not as `inverse_cdf(1 - p)`, which loses the relative
/// precision of small `p` to rounding in `1 - p`): Newton's method on `ln sf(x) - ln p`,
/// started at the Wilson–Hilferty approximation, safeguarded by bisection inside a bracket.
/// Returns NaN unless `0 < p < 1` and `dof > 0`. No allocation.
pub fn chi_square_upper_quantile(p: f64, dof: f64) -> f64 {
    if !(p > 0.0 && p < 1.0 && dof > 0.0 && dof.is_finite()) {
        return f64::NAN;
    }
    let Ok(dist) = ChiSquared::new(dof) else {
        return f64::NAN;
    };
    let ln_p = p.ln();
    // Bracket: sf(lo) > p >= sf(hi).
    let mut lo = 0.0_f64;
    let mut hi = dof.max(1.0);
    while dist.sf(hi) > p {
        lo = hi;
        hi *= 2.0;
    }
    // Wilson–Hilferty: (X/k)^(1/3) is nearly normal with mean 1 - 2/(9k), variance 2/(9k).
    let z = std::f64::consts::SQRT_2 * erfc_inv(2.0 * p);
    let a = 2.0 / (9.0 * dof);
    let mut x = dof * (1.0 - a + z * a.sqrt()).powi(3);
    if !(x > lo && x < hi) {
        x = 0.5 * (lo + hi);
    }
    for _ in 0..200 {
        let s = dist.sf(x);
        if s > p {
            lo = x;
        } else {
            hi = x;
        }
        let density = dist.pdf(x);
        let mut next = x + (s.ln() - ln_p) * s / density;
        if !next.is_finite() || next <= lo || next >= hi {
            next = 0.5 * (lo + hi);
        }
        if (next - x).abs() <= 1e-14 * x.max(1e-300) || hi - lo <= 1e-15 * hi {
            return next;
        }
        x = next;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(window: i64, p: f64) -> ChiSquareConfig {
        ChiSquareConfig {
            window,
            false_alarm_probability: p,
        }
    }

    #[test]
    fn quantile_matches_statrs() {
        for &dof in &[1.0, 2.0, 3.0, 7.0, 20.0, 100.0, 1000.0] {
            let d = ChiSquared::new(dof).unwrap();
            for &p in &[0.5, 0.1, 0.01, 1e-3, 1e-6] {
                let x = chi_square_upper_quantile(p, dof);
                let reference = d.inverse_cdf(1.0 - p);
                assert!(
                    (x - reference).abs() <= 1e-8 * reference,
                    "dof {dof} p {p}: {x} vs statrs {reference}"
                );
                assert!((d.sf(x) / p - 1.0).abs() < 1e-9, "dof {dof} p {p}");
            }
            // Far tail, where inverse_cdf(1 - p) has lost precision: check sf directly.
            for &p in &[1e-9, 1e-12] {
                let x = chi_square_upper_quantile(p, dof);
                assert!((d.sf(x) / p - 1.0).abs() < 1e-8, "dof {dof} p {p}");
            }
        }
        // Textbook values.
        assert!((chi_square_upper_quantile(0.05, 1.0) - 3.841_458_820_694_124).abs() < 1e-9);
        assert!((chi_square_upper_quantile(0.01, 10.0) - 23.209_251_158_954_35).abs() < 1e-8);
        assert!(chi_square_upper_quantile(0.0, 2.0).is_nan());
        assert!(chi_square_upper_quantile(0.1, 0.0).is_nan());
    }

    #[test]
    fn config_errors_name_the_field() {
        let e = ChiSquareWindow::<16>::new(&cfg(-4, 0.01)).unwrap_err();
        assert_eq!(e.field, "window");
        let e = ChiSquareWindow::<16>::new(&cfg(0, 0.01)).unwrap_err();
        assert_eq!(e.field, "window");
        let e = ChiSquareWindow::<16>::new(&cfg(17, 0.01)).unwrap_err();
        assert_eq!(e.field, "window");
        for p in [0.0, 1.0, 1.5, -0.1, f64::NAN] {
            let e = ChiSquareWindow::<16>::new(&cfg(8, p)).unwrap_err();
            assert_eq!(e.field, "false_alarm_probability");
        }
        let negative: ChiSquareConfig =
            serde_json::from_str(r#"{"window": -3, "false_alarm_probability": 0.01}"#).unwrap();
        let e = negative.validate(16).unwrap_err();
        assert_eq!(e.field, "window");
        assert!(e.to_string().contains("`window` = -3"), "{e}");
        let unknown = serde_json::from_str::<ChiSquareConfig>(
            r#"{"window": 3, "false_alarm_probabilty": 0.01}"#,
        );
        assert!(unknown
            .unwrap_err()
            .to_string()
            .contains("false_alarm_probabilty"));
    }

    #[test]
    fn verdict_sequence() {
        let mut d = ChiSquareWindow::<8>::new(&cfg(4, 0.01)).unwrap();
        let threshold = chi_square_upper_quantile(0.01, 8.0);
        let prefail = chi_square_upper_quantile(0.1, 8.0);
        assert!((d.threshold_for_dof(2) - threshold).abs() < 1e-12);
        // Not tested until the window has filled.
        for _ in 0..3 {
            assert_eq!(d.step(2.0, 2, true).verdict, Verdict::NotTested);
        }
        let r = d.step(2.0, 2, true);
        assert_eq!(r.verdict, Verdict::Passed);
        assert_eq!((r.value, r.min), (8.0, 0.0));
        assert!((r.max - threshold).abs() < 1e-12);
        // One large NIS: sum 2 + 2 + 2 + 12 = 18, above the prefail level (13.36) and below
        // the threshold (20.09).
        let r = d.step(12.0, 2, true);
        assert!(r.value > prefail && r.value < threshold, "{r:?}");
        assert_eq!(r.verdict, Verdict::PreFailed);
        // Another one: 2 + 2 + 12 + 14 = 30, failed.
        let r = d.step(14.0, 2, true);
        assert_eq!(r.verdict, Verdict::Failed);
        assert!(!r.obd06(0xA1, 0x81, 0x01).passed);
        // Back to normal: windows 2 12 14 1 (29), 12 14 1 1 (28) fail; 14 1 1 1 (17) leans
        // failed; 1 1 1 1 (4) passes, but the next two windows still overlap the last failing
        // one (12 14 1 1), so they are PrePassed; then Passed.
        let verdicts: Vec<Verdict> = (0..6).map(|_| d.step(1.0, 2, true).verdict).collect();
        assert_eq!(
            verdicts,
            vec![
                Verdict::Failed,
                Verdict::Failed,
                Verdict::PreFailed,
                Verdict::PrePassed,
                Verdict::PrePassed,
                Verdict::Passed,
            ]
        );
        assert!(d.last_result().obd06(0xA1, 0x81, 0x01).passed);
    }

    #[test]
    fn disabled_and_invalid_steps_change_nothing() {
        let mut d = ChiSquareWindow::<8>::new(&cfg(3, 0.05)).unwrap();
        d.step(1.0, 1, true);
        d.step(2.0, 1, true);
        let before = (d.statistic(), d.ring.newest_first().collect::<Vec<_>>());
        for r in [
            d.step(100.0, 1, false),
            d.step(f64::NAN, 1, true),
            d.step(f64::INFINITY, 1, true),
            d.step(-1.0, 1, true),
            d.step(1.0, 0, true),
        ] {
            assert_eq!(r.verdict, Verdict::NotTested);
        }
        assert_eq!(
            before,
            (d.statistic(), d.ring.newest_first().collect::<Vec<_>>())
        );
        let r = d.step(3.0, 1, true);
        assert_eq!(r.value, 6.0);
        assert_eq!(d.last_result(), r);
        // Disabled steps do not overwrite the last tested result ($06 reports it).
        d.step(0.0, 1, false);
        assert_eq!(d.last_result(), r);
        Detector::reset(&mut d);
        assert_eq!(d.step(1.0, 1, true).verdict, Verdict::NotTested);
        assert_eq!(d.last_result().verdict, Verdict::NotTested);
    }

    #[test]
    fn threshold_follows_the_total_degrees_of_freedom() {
        let mut d = ChiSquareWindow::<8>::new(&cfg(3, 0.01)).unwrap();
        for _ in 0..3 {
            d.step(1.0, 3, true);
        }
        assert!((d.threshold() - chi_square_upper_quantile(0.01, 9.0)).abs() < 1e-12);
        // A partial update with 1 component enters: total 3 + 3 + 1.
        d.step(1.0, 1, true);
        assert!((d.threshold() - chi_square_upper_quantile(0.01, 7.0)).abs() < 1e-12);
        d.step(1.0, 1, true);
        d.step(1.0, 1, true);
        assert!((d.threshold() - chi_square_upper_quantile(0.01, 3.0)).abs() < 1e-12);
    }

    #[test]
    fn running_sum_does_not_drift() {
        let mut d = ChiSquareWindow::<8>::new(&cfg(5, 0.01)).unwrap();
        d.step(1e15, 1, true);
        for i in 0..23 {
            d.step(0.1 * i as f64, 1, true);
        }
        let exact: f64 = (18..23).map(|i| 0.1 * i as f64).sum();
        assert!((d.statistic() - exact).abs() < 1e-9, "{}", d.statistic());
    }

    #[test]
    fn innovation_input() {
        let innovation = Innovation::<2> {
            residual: Default::default(),
            covariance: Default::default(),
            nis: 3.5,
            dof: 2,
        };
        let mut d = ChiSquareWindow::<4>::new(&cfg(1, 0.01)).unwrap();
        let r = d.step_innovation(&innovation, true);
        assert_eq!(r.value, 3.5);
        assert!((r.max - chi_square_upper_quantile(0.01, 2.0)).abs() < 1e-12);
    }
}
