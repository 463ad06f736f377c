//! Thresholds for a stated false-alarm rate from fault-free data: an extreme-value (Gumbel)
//! fit to block maxima of a test statistic, extrapolated to the rate asked.
//!
//! A test fails when its statistic exceeds a threshold `h`. Over fault-free data, cut into
//! blocks of `B` seconds, the block maxima of a statistic with an exponential-type tail (a
//! CUSUM, a windowed sum of NIS) follow a Gumbel law `F(x) = exp(-exp(-(x - mu) / beta))`
//! (Fisher-Tippett-Gnedenko). A false-alarm rate of `lambda` per hour is a probability
//! `p = lambda B / 3600` that a block's maximum exceeds `h`, so `h = mu - beta ln(-ln(1 - p))`.
//! This extrapolates beyond the largest value seen, which an empirical quantile cannot do.
//!
//! The fit is by maximum likelihood (the fixed point for `beta`, then `mu` in closed form),
//! started from the method of moments. Its check is the probability-plot correlation
//! coefficient (PPCC): the correlation of the sorted maxima with the Gumbel quantiles at
//! their plotting positions (Gringorten's), near 1 for data that follow the law. A low PPCC or
//! a block maximum above the threshold itself says the data hold something the law does not
//! explain: a fault, most likely.
//!
//! Pure arithmetic; allocation only to sort a copy of the maxima.

use thiserror::Error;

/// Euler-Mascheroni constant (mean of the standard Gumbel law).
const EULER_GAMMA: f64 = 0.577_215_664_901_532_9;

/// A fitted Gumbel law of block maxima.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GumbelFit {
    /// Location `mu` and scale `beta` (units of the statistic).
    pub location: f64,
    pub scale: f64,
    /// Block maxima the fit used.
    pub blocks: usize,
    /// Probability-plot correlation coefficient (-1..1; 1 is a perfect fit).
    pub ppcc: f64,
}

/// Why a fit could not be made.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FitError {
    #[error("{got} block maxima, at least {needed} are needed for a fit")]
    TooFewBlocks { got: usize, needed: usize },
    #[error("block maximum {index} is {value}: not a finite number")]
    NotFinite { index: usize, value: f64 },
    #[error("the block maxima do not vary (all {value}): no tail to fit")]
    Constant { value: f64 },
}

/// Fewest block maxima a fit accepts.
pub const MIN_BLOCKS: usize = 20;

impl GumbelFit {
    /// Fits block maxima by maximum likelihood.
    pub fn fit(maxima: &[f64]) -> Result<Self, FitError> {
        if maxima.len() < MIN_BLOCKS {
            return Err(FitError::TooFewBlocks {
                got: maxima.len(),
                needed: MIN_BLOCKS,
            });
        }
        if let Some((index, &value)) = maxima.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(FitError::NotFinite { index, value });
        }
        let n = maxima.len() as f64;
        let mean = maxima.iter().sum::<f64>() / n;
        let var = maxima.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        if !(var > 0.0) {
            return Err(FitError::Constant { value: mean });
        }
        // Method of moments, then the ML fixed point beta = mean - sum(x w) / sum(w),
        // w = exp(-x / beta) (shifted by the minimum for range).
        let mut beta = var.sqrt() * 6f64.sqrt() / std::f64::consts::PI;
        let x0 = maxima.iter().copied().fold(f64::INFINITY, f64::min);
        for _ in 0..200 {
            let (mut sw, mut sxw) = (0.0, 0.0);
            for &x in maxima {
                let w = (-(x - x0) / beta).exp();
                sw += w;
                sxw += x * w;
            }
            let next = mean - sxw / sw;
            if !(next > 0.0 && next.is_finite()) {
                break;
            }
            let done = (next - beta).abs() <= 1e-12 * beta;
            beta = next;
            if done {
                break;
            }
        }
        let sw: f64 = maxima.iter().map(|&x| (-(x - x0) / beta).exp()).sum();
        let location = x0 - beta * (sw / n).ln();
        let mut fit = GumbelFit {
            location,
            scale: beta,
            blocks: maxima.len(),
            ppcc: f64::NAN,
        };
        fit.ppcc = fit.probability_plot_correlation(maxima);
        Ok(fit)
    }

    /// The value a block maximum exceeds with probability `p` (0 < p < 1).
    pub fn exceeded_with(&self, p: f64) -> f64 {
        self.location - self.scale * (-(1.0 - p).ln()).ln()
    }

    /// The threshold for `per_hour` false alarms per hour with blocks of `block_s` seconds.
    pub fn threshold(&self, per_hour: f64, block_s: f64) -> f64 {
        self.exceeded_with((per_hour * block_s / 3600.0).min(0.5))
    }

    /// False alarms per hour that threshold `h` gives (the inverse of [`GumbelFit::threshold`]).
    pub fn rate_per_hour(&self, h: f64, block_s: f64) -> f64 {
        let p = 1.0 - (-(-(h - self.location) / self.scale).exp()).exp();
        p * 3600.0 / block_s
    }

    /// Correlation of the sorted maxima with the Gumbel quantiles at Gringorten's plotting
    /// positions `(i - 0.44) / (n + 0.12)`.
    fn probability_plot_correlation(&self, maxima: &[f64]) -> f64 {
        let mut x = maxima.to_vec();
        x.sort_by(f64::total_cmp);
        let n = x.len() as f64;
        let q: Vec<f64> = (1..=x.len())
            .map(|i| {
                let p = (i as f64 - 0.44) / (n + 0.12);
                self.location - self.scale * (-p.ln()).ln()
            })
            .collect();
        correlation(&x, &q)
    }
}

/// Pearson correlation of two equally long samples.
fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    sab / (saa * sbb).sqrt()
}

/// The mean of a standard Gumbel law, for checks.
pub fn gumbel_mean(location: f64, scale: f64) -> f64 {
    location + EULER_GAMMA * scale
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn gumbel_sample(rng: &mut Pcg64, mu: f64, beta: f64) -> f64 {
        let u: f64 = rng.random_range(1e-12..1.0);
        mu - beta * (-u.ln()).ln()
    }

    /// Known law: the fit recovers it, and the threshold's exceedance probability is the one
    /// asked (checked against the law itself).
    #[test]
    fn recovers_a_known_gumbel_law() {
        let mut rng = Pcg64::seed_from_u64(3);
        let x: Vec<f64> = (0..2000)
            .map(|_| gumbel_sample(&mut rng, 10.0, 2.0))
            .collect();
        let f = GumbelFit::fit(&x).expect("fit");
        assert!((f.location - 10.0).abs() < 0.15, "{f:?}");
        assert!((f.scale - 2.0).abs() < 0.1, "{f:?}");
        assert!(f.ppcc > 0.99, "{f:?}");
        let h = f.threshold(1e-3, 10.0);
        assert!((f.rate_per_hour(h, 10.0) - 1e-3).abs() < 1e-9);
        // p = 1e-3 * 10 / 3600; h = mu + beta * (-ln(-ln(1 - p))) ~ mu + 12.8 beta.
        assert!(
            (h - (f.location + 12.79 * f.scale)).abs() < 0.05 * f.scale,
            "{h}"
        );
        assert!((gumbel_mean(f.location, f.scale) - x.iter().sum::<f64>() / 2000.0).abs() < 0.15);
    }

    /// Maxima of exponential blocks (the tail of a CUSUM) are Gumbel in the limit; a sample
    /// with a few huge values (a fault) has a poor probability-plot correlation.
    #[test]
    fn block_maxima_fit_and_outliers_show() {
        let mut rng = Pcg64::seed_from_u64(5);
        let block = |rng: &mut Pcg64| {
            (0..500)
                .map(|_| -rng.random_range(1e-12f64..1.0).ln())
                .fold(0.0, f64::max)
        };
        let mut x: Vec<f64> = (0..200).map(|_| block(&mut rng)).collect();
        let f = GumbelFit::fit(&x).expect("fit");
        assert!(f.ppcc > 0.98, "{f:?}");
        // ln(500) = 6.2 and scale 1 for exponential blocks of 500.
        assert!(
            (f.location - 6.2).abs() < 0.3 && (f.scale - 1.0).abs() < 0.2,
            "{f:?}"
        );
        for v in x.iter_mut().take(30) {
            *v += 200.0;
        }
        let g = GumbelFit::fit(&x).expect("fit");
        assert!(g.ppcc < 0.95, "{g:?}");
    }

    #[test]
    fn refuses_what_it_cannot_fit() {
        assert!(matches!(
            GumbelFit::fit(&[1.0; 5]),
            Err(FitError::TooFewBlocks { got: 5, .. })
        ));
        assert!(matches!(
            GumbelFit::fit(&[1.0; 30]),
            Err(FitError::Constant { .. })
        ));
        let mut x = vec![1.0; 30];
        x[3] = f64::NAN;
        assert!(matches!(
            GumbelFit::fit(&x),
            Err(FitError::NotFinite { index: 3, .. })
        ));
    }
}
