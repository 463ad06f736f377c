//! Online estimate of a sensor's noise variance from its own readings, so that a monitor copes
//! with a sensor noisier (or quieter) than its configuration says without a host having to
//! know the level.
//!
//! The estimate uses *third differences* of the raw readings,
//! `d_k = y_k - 3 y_k-1 + 3 y_k-2 - y_k-3`: for white noise of variance `R` on a signal that
//! is smooth at the sampling rate, `d` has variance `20 R`, and the signal's own part (its
//! third difference, a jerk times `dt^3`) is small except at a sudden input change (second
//! differences leave a plate's accelerations in, which read as 50 % more TPS noise). Those rare large values are winsorized:
//! each `|d|` is clipped at [`CLIP_SIGMA`] standard deviations of the current estimate, which
//! for Gaussian noise biases the estimate by less than 0.5 %. The estimate does not depend on
//! any filter or model, so neither a model mismatch nor an overconfident filter can talk it
//! down (an estimate from the filter's own innovations would partly return the `R` it assumed).
//! Quantization counts as noise (`LSB^2 / 12` on top), which is what a filter's `R` should
//! hold.
//!
//! Averaging: the running mean over the first samples (weight `1/n`), then an exponentially
//! weighted mean with weight `alpha` (time constant `1/alpha` samples). The monitor feeds it
//! only while no test fails and nothing is being isolated (a noise fault must not raise the
//! level that would reveal it), and calls [`NoiseLevel::gap`] when a sample is skipped, so that
//! no difference spans a gap.
//!
//! Pure arithmetic, fixed size, no allocation.

/// Clip of the differences, in standard deviations of the current estimate.
pub const CLIP_SIGMA: f64 = 3.0;
/// Variance of a third difference of unit white noise: `1 + 9 + 9 + 1`.
const GAIN: f64 = 20.0;

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
    /// Mean of the winsorized `d^2 / 20`.
    var: f64,
    n: u64,
    last: [f64; 3],
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
            var: prior,
            n: 0,
            last: [f64::NAN; 3],
        })
    }

    /// One raw reading `y` (measurement units).
    pub fn push(&mut self, y: f64) {
        if !y.is_finite() {
            self.gap();
            return;
        }
        let [y1, y2, y3] = self.last;
        if y1.is_finite() && y2.is_finite() && y3.is_finite() {
            let d = y - 3.0 * y1 + 3.0 * y2 - y3;
            // The clip follows the estimate; during the first samples it follows the prior.
            let scale = if self.n == 0 { self.prior } else { self.var };
            let c2 = CLIP_SIGMA * CLIP_SIGMA * GAIN * scale;
            let d2 = (d * d).min(c2);
            self.n += 1;
            let w = (1.0 / self.n as f64).max(self.alpha);
            self.var += w * (d2 / GAIN - self.var);
        }
        self.last = [y, y1, y2];
    }

    /// A sample was not fed (a test failing, the sensor refused): the next differences start
    /// afresh.
    pub fn gap(&mut self) {
        self.last = [f64::NAN; 3];
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
            self.var.clamp(self.min, self.max)
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
            self.var
        }
    }

    /// Back to the prior (a new operation cycle keeps nothing).
    pub fn reset(&mut self) {
        self.var = self.prior;
        self.n = 0;
        self.gap();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    use rand_pcg::Pcg64;

    /// White noise of std 0.3 on a smooth signal with occasional steps (an input change): the
    /// estimate finds 0.09 within 5 %.
    #[test]
    fn recovers_the_noise_variance_of_a_smooth_signal_with_steps() {
        let mut rng = Pcg64::seed_from_u64(7);
        let mut est = NoiseLevel::new(0.01, 1e-4, 10.0, 20_000.0, 500).expect("valid");
        for k in 0..100_000 {
            let t = f64::from(k) * 1e-3;
            let step = if (k / 2000) % 2 == 0 { 0.0 } else { 1.5 };
            let signal = 0.5 * (t * 3.0).sin() + step;
            let n: f64 = rng.sample(StandardNormal);
            est.push(signal + 0.3 * n);
        }
        let v = est.variance();
        assert!((v - 0.09).abs() < 0.05 * 0.09, "estimate {v}");
    }

    #[test]
    fn prior_until_settled_bounds_after_and_gaps_break_differences() {
        let mut est = NoiseLevel::new(0.04, 0.01, 0.1, 100.0, 3).expect("valid");
        assert_eq!(est.variance(), 0.04);
        // +-1 alternating: third differences of 8, clipped at 3 sigma of the estimate.
        for k in 0..6 {
            est.push(if k % 2 == 0 { 1.0 } else { -1.0 });
        }
        assert_eq!(est.samples(), 3);
        assert_eq!(est.variance(), 0.1);
        // After a gap no difference spans it.
        est.gap();
        est.push(100.0);
        est.push(100.0);
        assert_eq!(est.samples(), 3);
        est.reset();
        assert_eq!(est.variance(), 0.04);
        assert!(NoiseLevel::new(0.04, 0.05, 0.1, 100.0, 3).is_none());
        assert!(NoiseLevel::new(f64::NAN, 0.01, 0.1, 100.0, 3).is_none());
    }
}
