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

/// A fitted generalized extreme-value (GEV) law of block maxima, in Hosking's
/// parametrization: `F(x) = exp(-(1 - k (x - xi) / alpha)^(1/k))`, `k = 0` the Gumbel law,
/// `k < 0` a heavy (Frechet-type) tail (`k > 0`, a bounded tail, is not fitted: see
/// [`GevFit::fit`]). Block maxima of a statistic
/// whose input is not stationary noise (a CUSUM fed by model error that comes and goes) have
/// a heavier tail than Gumbel's; assuming Gumbel there would put the threshold too low.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GevFit {
    /// Location `xi`, scale `alpha` (units of the statistic) and shape `k` (-).
    pub location: f64,
    pub scale: f64,
    pub shape: f64,
    pub blocks: usize,
    /// Probability-plot correlation coefficient against the fitted law.
    pub ppcc: f64,
}

impl GevFit {
    /// Fits block maxima by L-moments (Hosking, Wallis and Wood 1985: probability-weighted
    /// moments, the shape from Hosking's rational approximation), robust for the few dozen to
    /// few hundred maxima a calibration has.
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
        let mut x = maxima.to_vec();
        x.sort_by(f64::total_cmp);
        let n = x.len() as f64;
        let (mut b0, mut b1, mut b2) = (0.0, 0.0, 0.0);
        for (j, &v) in x.iter().enumerate() {
            let j = j as f64;
            b0 += v;
            b1 += v * j / (n - 1.0);
            b2 += v * j * (j - 1.0) / ((n - 1.0) * (n - 2.0));
        }
        b0 /= n;
        b1 /= n;
        b2 /= n;
        let l1 = b0;
        let l2 = 2.0 * b1 - b0;
        let l3 = 6.0 * b2 - 6.0 * b1 + b0;
        if !(l2 > 0.0) {
            return Err(FitError::Constant { value: l1 });
        }
        let t3 = l3 / l2;
        let c = 2.0 / (3.0 + t3) - std::f64::consts::LN_2 / 3f64.ln();
        // A bounded tail (k > 0) is not taken: the statistics fdd calibrates (CUSUMs, sums of
        // NIS) have at least exponential tails, and a bounded fit would cap the threshold at
        // the sample's reach whatever rate is asked. Such samples get the Gumbel law.
        let k = (7.8590 * c + 2.9554 * c * c).min(0.0);
        let (location, scale) = if k > -1e-6 {
            let scale = l2 / std::f64::consts::LN_2;
            (l1 - EULER_GAMMA * scale, scale)
        } else {
            let g = gamma(1.0 + k);
            let scale = l2 * k / ((1.0 - 2f64.powf(-k)) * g);
            (l1 - scale * (1.0 - g) / k, scale)
        };
        let mut fit = GevFit {
            location,
            scale,
            shape: k,
            blocks: x.len(),
            ppcc: f64::NAN,
        };
        let q: Vec<f64> = (1..=x.len())
            .map(|i| fit.quantile((i as f64 - 0.44) / (n + 0.12)))
            .collect();
        fit.ppcc = correlation(&x, &q);
        Ok(fit)
    }

    /// The value a block maximum stays below with probability `f`.
    pub fn quantile(&self, f: f64) -> f64 {
        let y = -f.ln();
        if self.shape > -1e-6 {
            self.location - self.scale * y.ln()
        } else {
            self.location + self.scale / self.shape * (1.0 - y.powf(self.shape))
        }
    }

    /// The threshold for `per_hour` false alarms per hour with blocks of `block_s` seconds.
    pub fn threshold(&self, per_hour: f64, block_s: f64) -> f64 {
        self.quantile(1.0 - (per_hour * block_s / 3600.0).min(0.5))
    }
}

/// The gamma function (Lanczos approximation, g = 7, 9 terms; relative error below 1e-13 for
/// the arguments used here, 0.5..3).
fn gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        return std::f64::consts::PI / ((std::f64::consts::PI * x).sin() * gamma(1.0 - x));
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    (2.0 * std::f64::consts::PI).sqrt() * t.powf(x + 0.5) * (-t).exp() * a
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

    /// GEV by L-moments: a Gumbel sample gives a shape near 0 and the same threshold; a heavy
    /// tail (Frechet, shape -0.2) is recognized and puts the threshold higher.
    #[test]
    fn gev_recovers_gumbel_and_heavy_tails() {
        assert!(
            (gamma(5.0) - 24.0).abs() < 1e-10
                && (gamma(0.5) - std::f64::consts::PI.sqrt()).abs() < 1e-12
        );
        let mut rng = Pcg64::seed_from_u64(11);
        let x: Vec<f64> = (0..3000)
            .map(|_| gumbel_sample(&mut rng, 10.0, 2.0))
            .collect();
        let g = GevFit::fit(&x).expect("fit");
        assert!(
            g.shape > -0.05 && g.shape <= 0.0 && (g.location - 10.0).abs() < 0.2,
            "{g:?}"
        );
        let gu = GumbelFit::fit(&x).expect("fit");
        let (hg, hu) = (g.threshold(1e-3, 10.0), gu.threshold(1e-3, 10.0));
        assert!((hg - hu).abs() < 0.15 * (hu - gu.location), "{hg} {hu}");
        // Frechet-type: x = xi + alpha/k (1 - (-ln u)^k), k = -0.2.
        let k = -0.2;
        let y: Vec<f64> = (0..3000)
            .map(|_| {
                let u: f64 = rng.random_range(1e-12..1.0);
                5.0 + 1.0 / k * (1.0 - (-u.ln()).powf(k))
            })
            .collect();
        let f = GevFit::fit(&y).expect("fit");
        assert!((f.shape - k).abs() < 0.05, "{f:?}");
        assert!(f.ppcc > 0.98, "{f:?}");
        let exact = 5.0 + 1.0 / k * (1.0 - (-(1.0 - 1e-3 * 10.0 / 3600.0f64).ln()).powf(k));
        let h = f.threshold(1e-3, 10.0);
        assert!((h / exact - 1.0).abs() < 0.5, "{h} vs {exact}");
        assert!(h > GumbelFit::fit(&y).expect("fit").threshold(1e-3, 10.0));
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
