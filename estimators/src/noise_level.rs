//! Online estimate of a sensor's noise variance from a filter's innovations, so that a monitor
//! copes with a sensor noisier (or quieter) than its configuration says without a host having
//! to know the level.
//!
//! The estimate uses the *differences* of consecutive innovations: for white measurement noise
//! of variance `R` on top of a slowly varying part (model error, a small bias, the filter's
//! own lag), `e_k - e_k-1` has variance about `2 S`, and the slowly varying part cancels. So a
//! bias or a model mismatch, which the residual tests are there to see, is not mistaken for
//! noise and does not raise the noise estimate that normalizes those tests. The innovation
//! variance `S = H P H' + R` is reduced to `R` by subtracting the filter's own part
//! (`S - R` as the filter computes it), averaged the same way.
//!
//! Averaging: the running mean over the first samples (weight `1/n`), then an exponentially
//! weighted mean with weight `alpha` (time constant `1/alpha` samples). The monitor feeds it
//! only while no test fails and nothing is being isolated, and calls [`NoiseLevel::gap`] when
//! a sample is skipped, so that no difference spans a gap.
//!
//! Pure arithmetic, fixed size, no allocation.

/// Running estimate of a measurement noise variance `R` (squared units of the measurement).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseLevel {
    /// Configured variance, used until `settle` samples have been seen.
    prior: f64,
    /// Bounds of the estimate (variance).
    min: f64,
    max: f64,
    alpha: f64,
    settle: u64,
    /// Mean of `(e_k - e_k-1)^2 / 2` and of the filter's part `S - R`.
    diff_var: f64,
    filter_var: f64,
    n: u64,
    last: f64,
}

impl NoiseLevel {
    /// An estimate starting from the configured variance `prior`, kept within `[min, max]`,
    /// averaging over about `time_constant` samples once `settle` samples have been seen.
    /// Non-finite or inconsistent arguments give `None`.
    pub fn new(prior: f64, min: f64, max: f64, time_constant: f64, settle: u64) -> Option<Self> {
        let ok = prior.is_finite()
            && prior > 0.0
            && min.is_finite()
            && min > 0.0
            && max.is_finite()
            && min <= prior
            && prior <= max
            && time_constant.is_finite()
            && time_constant >= 1.0;
        ok.then_some(Self {
            prior,
            min,
            max,
            alpha: 1.0 / time_constant,
            settle,
            diff_var: 0.0,
            filter_var: 0.0,
            n: 0,
            last: f64::NAN,
        })
    }

    /// One innovation `e` (measurement units) with the filter's innovation variance `s` and the
    /// `r` it used (so `s - r` is the filter's own part).
    pub fn push(&mut self, e: f64, s: f64, r: f64) {
        if !(e.is_finite() && s.is_finite() && r.is_finite()) {
            self.last = f64::NAN;
            return;
        }
        if self.last.is_finite() {
            self.n += 1;
            let w = (1.0 / self.n as f64).max(self.alpha);
            let d = e - self.last;
            self.diff_var += w * (0.5 * d * d - self.diff_var);
            self.filter_var += w * ((s - r).max(0.0) - self.filter_var);
        }
        self.last = e;
    }

    /// A sample was not fed (a test failing, the sensor refused): the next difference starts
    /// afresh.
    pub fn gap(&mut self) {
        self.last = f64::NAN;
    }

    /// Differences averaged so far.
    pub fn samples(&self) -> u64 {
        self.n
    }

    /// True once the estimate replaces the prior.
    pub fn settled(&self) -> bool {
        self.n >= self.settle
    }

    /// The variance to use: the prior until settled, then the estimate within the bounds.
    pub fn variance(&self) -> f64 {
        if self.settled() {
            (self.diff_var - self.filter_var).clamp(self.min, self.max)
        } else {
            self.prior
        }
    }

    /// The estimate without the bounds (NaN before the first difference): what a calibration
    /// reads.
    pub fn unbounded(&self) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            self.diff_var - self.filter_var
        }
    }

    /// Back to the prior (a new operation cycle keeps nothing).
    pub fn reset(&mut self) {
        self.diff_var = 0.0;
        self.filter_var = 0.0;
        self.n = 0;
        self.last = f64::NAN;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    use rand_pcg::Pcg64;

    /// White noise of std 0.3 on a slowly varying mean (a bias ramp and a sinusoid, as model
    /// error would give): the estimate finds 0.09 within 5 % and ignores the mean.
    #[test]
    fn recovers_the_noise_variance_under_a_slow_mean() {
        let mut rng = Pcg64::seed_from_u64(7);
        let mut est = NoiseLevel::new(0.01, 1e-4, 10.0, 20_000.0, 500).expect("valid");
        for k in 0..100_000 {
            let t = f64::from(k) * 1e-3;
            let mean = 0.5 * (t * 0.7).sin() + 0.01 * t;
            let n: f64 = rng.sample(StandardNormal);
            // The filter's own part: 0.002, i.e. s = r + 0.002 with r = 0.01 as configured.
            est.push(
                mean + 0.3 * n + 0.002f64.sqrt() * rng.sample::<f64, _>(StandardNormal),
                0.012,
                0.01,
            );
        }
        let v = est.variance();
        assert!((v - 0.09).abs() < 0.05 * 0.09, "estimate {v}");
    }

    #[test]
    fn prior_until_settled_bounds_after_and_gaps_break_differences() {
        let mut est = NoiseLevel::new(0.04, 0.01, 0.1, 100.0, 3).expect("valid");
        assert_eq!(est.variance(), 0.04);
        // Alternating +-1: differences of 2, variance estimate 2 (bounded to 0.1).
        for k in 0..4 {
            est.push(if k % 2 == 0 { 1.0 } else { -1.0 }, 0.0, 0.0);
        }
        assert_eq!(est.samples(), 3);
        assert_eq!(est.variance(), 0.1);
        assert!((est.unbounded() - 2.0).abs() < 1e-12);
        // After a gap the next sample starts a new difference: no jump from -1 to 100 counted.
        est.gap();
        est.push(100.0, 0.0, 0.0);
        assert_eq!(est.samples(), 3);
        est.reset();
        assert_eq!(est.variance(), 0.04);
        assert!(NoiseLevel::new(0.04, 0.05, 0.1, 100.0, 3).is_none());
        assert!(NoiseLevel::new(f64::NAN, 0.01, 0.1, 100.0, 3).is_none());
    }
}
