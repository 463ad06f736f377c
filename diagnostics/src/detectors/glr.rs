//! GLR test for a jump of unknown size in the mean of normalized innovations.
//!
//! Input: the normalized innovation `z = r / sqrt(S)`, N(0, 1) and white without a fault.
//! Hypothesis H1(j, nu): from sample `j` on, the mean is `nu` (unknown). Over a sliding window of
//! the last M samples `z_{k-M+1} .. z_k`, the generalized log-likelihood ratio, maximized over the
//! jump size `nu` (its estimate is the mean since `j`) and the change time `j`, is
//!
//! ```text
//! g_k = max_{n = 1..M} S_n^2 / (2 n),     S_n = z_k + z_{k-1} + ... + z_{k-n+1}
//! ```
//!
//! computed in O(M) per step from the window (the sums are rebuilt every step, so nothing
//! drifts). Unlike the CUSUM it needs no assumed jump size, and it estimates both the change
//! time ([`Glr::change_age`]) and the jump ([`Glr::jump_estimate`]), which isolation can use.
//!
//! # Threshold
//!
//! The test fails when `g_k > c`, with `c` chosen so that one decision on fault-free data fails
//! with the configured probability `p`. The fault-free law of `g_k` has no closed form, but
//! `g_k > c` is the event that the Gaussian random walk `S_1, S_2, .., S_M` leaves the
//! widening corridor `|S_n| <= b_n = sqrt(2 c n)`, and that boundary-crossing probability is an
//! integral we evaluate numerically, deterministically and with no random numbers:
//!
//! ```text
//! f_1 = phi on [-b_1, b_1],     f_n(s) = integral over [-b_{n-1}, b_{n-1}] of f_{n-1}(u) phi(s - u) du
//! P(g > c) = P(|S_1| > b_1) + sum_{n=2..M} integral of f_{n-1}(u) [Q(b_n - u) + Q(b_n + u)] du
//! ```
//!
//! (`phi` the standard normal density, `Q` its upper tail). `f_n` is the density of the walks
//! still inside the corridor; each integrand is smooth (the Gaussian kernel times a smooth
//! density) on its closed interval, so composite 8-point Gauss–Legendre quadrature on panels at
//! most 2.5 standard deviations wide converges fast: the rule's error bound for the kernel is
//! below 1e-8 relative per panel, and unit tests check the result against a direct integral
//! (M = 2), against the same scheme with panels half as wide (agreement < 1e-6 relative) and
//! against a Monte Carlo run. Kernel values below 2.6e-18 of the peak (beyond 9 standard
//! deviations) are skipped. The crossing mass is summed directly, never as `1 - survival`, so
//! small `p` keep their relative precision. `c` is then solved by the Illinois (regula falsi)
//! method on `ln P(g > c) - ln p`, bracketed by `q1(p) / 2` (one change time alone) and
//! `q1(p / M) / 2` (Bonferroni), `q1` the chi-square(1) upper quantile; about six evaluations.
//!
//! Cost at construction (two solves: the threshold and the prefail level), release build:
//! about 5-10 ms for M = 20, 70 ms for M = 100, 0.3 to 0.5 s for M = 256 (growing like
//! `M^1.5`, and slowly with `1 / p`), hence [`MAX_GLR_WINDOW`]. The per-step cost is O(M), with
//! no allocation.
//!
//! Decisions in successive steps share M - 1 samples: `p` is the probability per decision, and
//! decisions on non-overlapping windows are independent (the statistical test counts those).

use serde::{Deserialize, Serialize};
use statrs::function::erf::erfc;

use super::chi_square::chi_square_upper_quantile;
use super::{grade, validate_probability, validate_window, Detector, Ring};
use crate::error::ConfigError;
use crate::verdict::{TestResult, Verdict};

/// Longest GLR window accepted (samples): the threshold integral's cost grows like `M^1.5`.
pub const MAX_GLR_WINDOW: usize = 256;

/// Configuration of a [`Glr`], e.g. (TOML)
///
/// ```toml
/// window = 50                      # samples searched for a change
/// false_alarm_probability = 1e-3   # per decision
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GlrConfig {
    /// M: number of samples searched for a change (samples), `1..=min(CAP, 256)`. Signed so that
    /// a negative value in a file reaches validation and is reported naming this field.
    pub window: i64,
    /// p: probability that one decision on fault-free data fails (per decision,
    /// dimensionless), in `[1e-12, 1)`.
    pub false_alarm_probability: f64,
}

impl GlrConfig {
    /// Checks the configuration for a detector holding at most `capacity` samples; returns the
    /// window length.
    pub fn validate(&self, capacity: usize) -> Result<usize, ConfigError> {
        let window = validate_window("window", self.window, capacity, MAX_GLR_WINDOW)?;
        validate_probability("false_alarm_probability", self.false_alarm_probability)?;
        Ok(window)
    }
}

/// Sliding-window GLR test for a mean jump (see [the module docs](self)), `M <= CAP`.
///
/// Verdicts: `NotTested` until M valid samples have been seen; `Failed` when `g > c`;
/// `PreFailed` above the level the fault-free `g` exceeds with probability `sqrt(p)`;
/// `PrePassed` for M - 1 steps after a `Failed` step (the window still holds samples of the
/// failing one); `Passed` otherwise. The window is not cleared after a failure.
#[derive(Debug, Clone)]
pub struct Glr<const CAP: usize> {
    window: usize,
    p: f64,
    threshold: f64,
    prefail: f64,
    ring: Ring<f64, CAP>,
    settle: usize,
    statistic: f64,
    change_age: usize,
    jump: f64,
    last: TestResult,
}

impl<const CAP: usize> Glr<CAP> {
    /// Builds the detector and computes its thresholds (see the module docs for the method and
    /// its cost); errors name the offending field.
    pub fn new(config: &GlrConfig) -> Result<Self, ConfigError> {
        let window = config.validate(CAP)?;
        let p = config.false_alarm_probability;
        Ok(Self {
            window,
            p,
            threshold: glr_threshold(window, p),
            prefail: glr_threshold(window, p.sqrt()),
            ring: Ring::new(window),
            settle: 0,
            statistic: f64::NAN,
            change_age: 0,
            jump: f64::NAN,
            last: TestResult::NOT_TESTED,
        })
    }

    /// One normalized innovation `z = r / sqrt(S)` (dimensionless). `NotTested`, state
    /// unchanged, when disabled or `z` is not finite.
    ///
    /// Feed only components that took part in the update: a component excluded by a partial
    /// update carries a zero residual, which would read as fault-free evidence; step it with
    /// `enabled = false` instead.
    pub fn step(&mut self, z: f64, enabled: bool) -> TestResult {
        if !enabled || !z.is_finite() {
            return TestResult::NOT_TESTED;
        }
        self.ring.push(z);
        if !self.ring.is_full() {
            return TestResult::NOT_TESTED;
        }
        let mut sum = 0.0;
        let mut best = 0.0;
        let mut age = 1;
        let mut jump = z;
        for (i, x) in self.ring.newest_first().enumerate() {
            sum += x;
            let n = (i + 1) as f64;
            let g = sum * sum / (2.0 * n);
            if g > best {
                best = g;
                age = i + 1;
                jump = sum / n;
            }
        }
        self.statistic = best;
        self.change_age = age;
        self.jump = jump;
        let verdict = grade(best, self.prefail, self.threshold, self.settle > 0);
        if verdict == Verdict::Failed {
            self.settle = self.window - 1;
        } else {
            self.settle = self.settle.saturating_sub(1);
        }
        self.last = TestResult {
            value: best,
            min: 0.0,
            max: self.threshold,
            verdict,
        };
        self.last
    }

    /// Window length M (samples).
    pub fn window(&self) -> usize {
        self.window
    }

    /// Configured false-alarm probability per decision.
    pub fn false_alarm_probability(&self) -> f64 {
        self.p
    }

    /// Threshold `c` on the log-likelihood ratio (dimensionless).
    pub fn threshold(&self) -> f64 {
        self.threshold
    }

    /// Level above which a step is `PreFailed` (fault-free exceedance probability `sqrt(p)`).
    pub fn prefail_level(&self) -> f64 {
        self.prefail
    }

    /// The latest statistic `g` (NaN before the window has filled).
    pub fn statistic(&self) -> f64 {
        self.statistic
    }

    /// Maximum-likelihood change time of the latest decision: the number of samples since the
    /// jump, the newest counted as 1 (0 before the window has filled).
    pub fn change_age(&self) -> usize {
        self.change_age
    }

    /// Maximum-likelihood jump size of the latest decision, in innovation standard deviations
    /// (NaN before the window has filled).
    pub fn jump_estimate(&self) -> f64 {
        self.jump
    }
}

impl<const CAP: usize> Detector for Glr<CAP> {
    /// The normalized innovation `z`.
    type Input = f64;

    fn step(&mut self, z: f64, enabled: bool) -> TestResult {
        Glr::step(self, z, enabled)
    }

    fn reset(&mut self) {
        self.ring.clear();
        self.settle = 0;
        self.statistic = f64::NAN;
        self.change_age = 0;
        self.jump = f64::NAN;
        self.last = TestResult::NOT_TESTED;
    }

    fn last_result(&self) -> TestResult {
        self.last
    }
}

/// Positive Gauss–Legendre nodes and weights of the 8-point rule on [-1, 1].
const GL8_X: [f64; 4] = [
    0.183_434_642_495_649_8,
    0.525_532_409_916_329,
    0.796_666_477_413_626_7,
    0.960_289_856_497_536_3,
];
const GL8_W: [f64; 4] = [
    0.362_683_783_378_362,
    0.313_706_645_877_887_3,
    0.222_381_034_453_374_5,
    0.101_228_536_290_376_3,
];

/// Widest quadrature panel, in standard deviations of the step (the kernel's scale).
const PANEL_WIDTH: f64 = 2.5;

/// Beyond this distance the Gaussian kernel (< 2.6e-18 of its peak) is dropped.
const KERNEL_REACH: f64 = 9.0;

const INV_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// Composite Gauss–Legendre nodes (ascending) and weights on `[-b, b]`.
fn quadrature(b: f64, x: &mut Vec<f64>, w: &mut Vec<f64>) {
    x.clear();
    w.clear();
    let panels = ((2.0 * b / PANEL_WIDTH).ceil() as usize).max(1);
    let width = 2.0 * b / panels as f64;
    let half = 0.5 * width;
    for i in 0..panels {
        let centre = -b + (i as f64 + 0.5) * width;
        for j in (0..4).rev() {
            x.push(centre - half * GL8_X[j]);
            w.push(half * GL8_W[j]);
        }
        for j in 0..4 {
            x.push(centre + half * GL8_X[j]);
            w.push(half * GL8_W[j]);
        }
    }
}

/// Standard normal upper tail `P(Z > x)`.
fn normal_tail(x: f64) -> f64 {
    0.5 * erfc(x / std::f64::consts::SQRT_2)
}

/// Fault-free probability that one decision of a window-`window` GLR exceeds `threshold`:
/// `P(max_{n <= M} S_n^2 / (2n) > c)` for a standard Gaussian random walk, by the quadrature
/// in [the module docs](self). NaN for `window == 0` or a negative or NaN threshold.
/// Allocates (construction-time helper).
pub fn glr_false_alarm_probability(window: usize, threshold: f64) -> f64 {
    if window == 0 || !(threshold >= 0.0) {
        return f64::NAN;
    }
    if threshold.is_infinite() {
        return 0.0;
    }
    let bound = |n: usize| (2.0 * threshold * n as f64).sqrt();
    let b1 = bound(1);
    let mut p = 2.0 * normal_tail(b1);
    if window == 1 || b1 == 0.0 {
        return p;
    }
    // `a[j] = w[j] f_{n-1}(u[j])`: the weighted density of the walks still inside.
    let (mut u, mut w) = (Vec::new(), Vec::new());
    quadrature(b1, &mut u, &mut w);
    let mut a: Vec<f64> = u
        .iter()
        .zip(&w)
        .map(|(&x, &wx)| wx * INV_SQRT_2PI * (-0.5 * x * x).exp())
        .collect();
    let (mut s, mut ws, mut next) = (Vec::new(), Vec::new(), Vec::new());
    for n in 2..=window {
        let b = bound(n);
        // Only walks within KERNEL_REACH of the corridor's edge can leave it in one step.
        p += u
            .iter()
            .zip(&a)
            .filter(|(&x, _)| b - x.abs() < KERNEL_REACH)
            .map(|(&x, &ax)| ax * (normal_tail(b - x) + normal_tail(b + x)))
            .sum::<f64>();
        if n == window {
            break;
        }
        quadrature(b, &mut s, &mut ws);
        next.clear();
        let (mut lo, mut hi) = (0, 0);
        for (&si, &wi) in s.iter().zip(&ws) {
            while lo < u.len() && u[lo] < si - KERNEL_REACH {
                lo += 1;
            }
            while hi < u.len() && u[hi] <= si + KERNEL_REACH {
                hi += 1;
            }
            let density: f64 = u[lo..hi]
                .iter()
                .zip(&a[lo..hi])
                .map(|(&x, &ax)| {
                    let d = si - x;
                    ax * (-0.5 * d * d).exp()
                })
                .sum();
            next.push(wi * INV_SQRT_2PI * density);
        }
        std::mem::swap(&mut u, &mut s);
        std::mem::swap(&mut w, &mut ws);
        std::mem::swap(&mut a, &mut next);
    }
    p
}

/// The threshold `c` with `glr_false_alarm_probability(window, c) = p` (relative precision
/// about 1e-9 in `p`), solved as described in [the module docs](self). NaN unless
/// `window >= 1` and `0 < p < 1`. Allocates (construction-time helper).
pub fn glr_threshold(window: usize, p: f64) -> f64 {
    if window == 0 || !(p > 0.0 && p < 1.0) {
        return f64::NAN;
    }
    let single = 0.5 * chi_square_upper_quantile(p, 1.0);
    if window == 1 {
        return single;
    }
    let target = p.ln();
    let excess = |c: f64| glr_false_alarm_probability(window, c).ln() - target;
    // Bracket: more change times can only add crossings, and the union bound caps them.
    let mut lo = single;
    let mut f_lo = excess(lo);
    while !(f_lo >= 0.0) && lo > 1e-9 {
        lo *= 0.5;
        f_lo = excess(lo);
    }
    let mut hi = 0.5 * chi_square_upper_quantile(p / window as f64, 1.0);
    let mut f_hi = excess(hi);
    while !(f_hi <= 0.0) && hi.is_finite() {
        hi *= 1.5;
        f_hi = excess(hi);
    }
    if f_lo == 0.0 {
        return lo;
    }
    if f_hi == 0.0 {
        return hi;
    }
    // Illinois: regula falsi that halves the stale end's value when one end repeats.
    let mut last_side = 0_i8;
    for _ in 0..100 {
        let c = hi - f_hi * (hi - lo) / (f_hi - f_lo);
        if !(c > lo && c < hi) {
            return 0.5 * (lo + hi);
        }
        let f = excess(c);
        if f.abs() < 1e-9 || hi - lo < 1e-13 * hi {
            return c;
        }
        if f > 0.0 {
            lo = c;
            f_lo = f;
            if last_side == -1 {
                f_hi *= 0.5;
            }
            last_side = -1;
        } else {
            hi = c;
            f_hi = f;
            if last_side == 1 {
                f_lo *= 0.5;
            }
            last_side = 1;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    use rand_pcg::Pcg64Mcg;

    fn cfg(window: i64, p: f64) -> GlrConfig {
        GlrConfig {
            window,
            false_alarm_probability: p,
        }
    }

    #[test]
    fn window_one_is_the_chi_square_test() {
        // g = z^2 / 2 > c  <=>  z^2 > 2c.
        let c = glr_threshold(1, 0.01);
        assert!((2.0 * c - chi_square_upper_quantile(0.01, 1.0)).abs() < 1e-12);
        let p = glr_false_alarm_probability(1, c);
        assert!((p / 0.01 - 1.0).abs() < 1e-9);
    }

    #[test]
    fn window_two_matches_a_direct_integral() {
        // P(|S1| > b1 or |S1 + Z2| > b2), by a fine midpoint rule over S1, independent of the
        // Gauss–Legendre code.
        let c = 3.0;
        let b1 = f64::sqrt(2.0 * c);
        let b2 = f64::sqrt(4.0 * c);
        let steps = 200_000;
        let h = 2.0 * b1 / steps as f64;
        let mut inside_cross = 0.0;
        for i in 0..steps {
            let x = -b1 + (i as f64 + 0.5) * h;
            let density = INV_SQRT_2PI * (-0.5 * x * x).exp();
            inside_cross += h * density * (normal_tail(b2 - x) + normal_tail(b2 + x));
        }
        let exact = 2.0 * normal_tail(b1) + inside_cross;
        let p = glr_false_alarm_probability(2, c);
        assert!((p / exact - 1.0).abs() < 1e-7, "{p} vs {exact}");
    }

    #[test]
    fn quadrature_is_converged() {
        // The same integral with the panels halved (twice the nodes): a refinement changes
        // nothing at the precision that matters.
        for (m, c) in [(20, 4.0), (50, 9.0), (100, 15.0)] {
            let p = glr_false_alarm_probability(m, c);
            let fine = fine_probability(m, c);
            assert!((p / fine - 1.0).abs() < 1e-6, "M {m} c {c}: {p} vs {fine}");
        }
    }

    /// `glr_false_alarm_probability` with panels of half the width and no kernel cut-off
    /// (reference only).
    fn fine_probability(window: usize, threshold: f64) -> f64 {
        let quad = |b: f64| {
            let (mut xf, mut wf) = (Vec::new(), Vec::new());
            let panels = ((2.0 * b / PANEL_WIDTH).ceil() as usize).max(1) * 2;
            let width = 2.0 * b / panels as f64;
            let half = 0.5 * width;
            for i in 0..panels {
                let centre = -b + (i as f64 + 0.5) * width;
                for j in (0..4).rev() {
                    xf.push(centre - half * GL8_X[j]);
                    wf.push(half * GL8_W[j]);
                }
                for j in 0..4 {
                    xf.push(centre + half * GL8_X[j]);
                    wf.push(half * GL8_W[j]);
                }
            }
            (xf, wf)
        };
        let bound = |n: usize| (2.0 * threshold * n as f64).sqrt();
        let mut p = 2.0 * normal_tail(bound(1));
        let (mut u, w) = quad(bound(1));
        let mut a: Vec<f64> = u
            .iter()
            .zip(&w)
            .map(|(&x, &wx)| wx * INV_SQRT_2PI * (-0.5 * x * x).exp())
            .collect();
        for n in 2..=window {
            let b = bound(n);
            p += u
                .iter()
                .zip(&a)
                .map(|(&x, &ax)| ax * (normal_tail(b - x) + normal_tail(b + x)))
                .sum::<f64>();
            let (s, ws) = quad(b);
            let next: Vec<f64> = s
                .iter()
                .zip(&ws)
                .map(|(&si, &wi)| {
                    wi * INV_SQRT_2PI
                        * u.iter()
                            .zip(&a)
                            .map(|(&x, &ax)| ax * (-0.5 * (si - x) * (si - x)).exp())
                            .sum::<f64>()
                })
                .collect();
            u = s;
            a = next;
        }
        p
    }

    #[test]
    fn threshold_inverts_the_probability() {
        for (m, p) in [(2, 0.05), (10, 0.01), (20, 1e-3), (64, 1e-6), (256, 1e-12)] {
            let c = glr_threshold(m, p);
            let back = glr_false_alarm_probability(m, c);
            assert!(
                (back / p - 1.0).abs() < 1e-8,
                "M {m} p {p}: c {c} gives {back}"
            );
            // Between the single-test and the Bonferroni bounds.
            assert!(c > 0.5 * chi_square_upper_quantile(p, 1.0));
            assert!(c < 0.5 * chi_square_upper_quantile(p / m as f64, 1.0));
        }
        assert!(glr_threshold(0, 0.1).is_nan());
        assert!(glr_threshold(5, 1.0).is_nan());
    }

    #[test]
    fn probability_agrees_with_monte_carlo() {
        // 200k fault-free windows of M = 10 at the p = 0.05 threshold: the count of exceedances
        // is Binomial(200k, 0.05), sd 97; allow 4 sd.
        let (m, p) = (10, 0.05);
        let c = glr_threshold(m, p);
        let mut rng = Pcg64Mcg::seed_from_u64(7);
        let trials = 200_000;
        let mut hits = 0;
        for _ in 0..trials {
            let mut sum = 0.0;
            let mut g: f64 = 0.0;
            for n in 1..=m {
                sum += rng.sample::<f64, _>(StandardNormal);
                g = g.max(sum * sum / (2.0 * n as f64));
            }
            if g > c {
                hits += 1;
            }
        }
        let expected = trials as f64 * p;
        let sd = (expected * (1.0 - p)).sqrt();
        assert!(
            (hits as f64 - expected).abs() < 4.0 * sd,
            "{hits} exceedances, expected {expected}"
        );
    }

    #[test]
    fn statistic_and_estimates() {
        let mut d = Glr::<8>::new(&cfg(4, 0.01)).unwrap();
        for z in [0.0, 0.0, 0.0] {
            assert_eq!(d.step(z, true).verdict, Verdict::NotTested);
        }
        // Window [0, 0, 0, 2]: best change time is the last sample, g = 4 / 2 = 2.
        let r = d.step(2.0, true);
        assert_eq!(r.value, 2.0);
        assert_eq!((d.change_age(), d.jump_estimate()), (1, 2.0));
        // Window [0, 0, 2, 2]: S_2 = 4, g = 16 / 4 = 4.
        let r = d.step(2.0, true);
        assert_eq!(r.value, 4.0);
        assert_eq!((d.change_age(), d.jump_estimate()), (2, 2.0));
        assert_eq!(r.max, d.threshold());
        assert_eq!(r.min, 0.0);
    }

    #[test]
    fn verdict_sequence() {
        let mut d = Glr::<8>::new(&cfg(4, 0.01)).unwrap();
        let (c, pre) = (d.threshold(), d.prefail_level());
        assert!(pre < c && pre > 0.0);
        for _ in 0..4 {
            d.step(0.0, true);
        }
        assert_eq!(d.last_result().verdict, Verdict::Passed);
        // A single sample whose g = z^2/2 lands between the prefail level and the threshold.
        let z = (pre + c).sqrt(); // z^2 / 2 = (pre + c) / 2
        assert_eq!(d.step(z, true).verdict, Verdict::PreFailed);
        // A big jump: failed while in the window; then PrePassed until the window no longer
        // overlaps the failing one.
        assert_eq!(d.step(10.0, true).verdict, Verdict::Failed);
        let verdicts: Vec<Verdict> = (0..7).map(|_| d.step(0.0, true).verdict).collect();
        assert!(verdicts[0].leans_failed());
        let last_failed = verdicts.iter().rposition(|&v| v == Verdict::Failed);
        let first_clear = verdicts.iter().position(|&v| !v.leans_failed()).unwrap();
        let settle_end = last_failed.map_or(0, |i| i + 1) + 3;
        for (i, v) in verdicts.iter().enumerate().skip(first_clear) {
            let expected = if i < settle_end {
                Verdict::PrePassed
            } else {
                Verdict::Passed
            };
            assert_eq!(*v, expected, "step {i}: {verdicts:?}");
        }
        assert_eq!(verdicts[6], Verdict::Passed);
    }

    #[test]
    fn disabled_and_invalid_steps_change_nothing() {
        let mut d = Glr::<8>::new(&cfg(3, 0.01)).unwrap();
        for z in [0.5, -0.2, 0.1] {
            d.step(z, true);
        }
        let last = d.last_result();
        let window: Vec<f64> = d.ring.newest_first().collect();
        for r in [
            d.step(50.0, false),
            d.step(f64::NAN, true),
            d.step(f64::INFINITY, true),
        ] {
            assert_eq!(r.verdict, Verdict::NotTested);
        }
        assert_eq!(window, d.ring.newest_first().collect::<Vec<_>>());
        assert_eq!(d.last_result(), last);
        Detector::reset(&mut d);
        assert_eq!(d.step(0.0, true).verdict, Verdict::NotTested);
    }

    #[test]
    fn config_errors_name_the_field() {
        for w in [-1, 0, 9] {
            assert_eq!(Glr::<8>::new(&cfg(w, 0.01)).unwrap_err().field, "window");
        }
        let e = Glr::<1024>::new(&cfg(300, 0.01)).unwrap_err();
        assert_eq!(e.field, "window");
        for p in [0.0, 1.0, f64::NAN, -3.0, 1e-20] {
            assert_eq!(
                Glr::<8>::new(&cfg(4, p)).unwrap_err().field,
                "false_alarm_probability"
            );
        }
        let parsed: Result<GlrConfig, _> =
            serde_json::from_str(r#"{"window": 4, "false_alarm_probability": 0.01, "x": 1}"#);
        assert!(parsed.is_err());
    }
}
