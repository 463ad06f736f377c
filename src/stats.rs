//! Running statistics for error reports.

/// Mean and standard deviation accumulated one sample at a time (Welford's update, stable for
/// millions of samples).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RunningStats {
    count: u64,
    mean: f64,
    m2: f64,
}

impl RunningStats {
    /// Adds one sample.
    pub fn push(&mut self, v: f64) {
        self.count += 1;
        let d = v - self.mean;
        self.mean += d / self.count as f64;
        self.m2 += d * (v - self.mean);
    }

    /// Number of samples.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Sample mean (NaN when empty).
    pub fn mean(&self) -> f64 {
        if self.count == 0 {
            f64::NAN
        } else {
            self.mean
        }
    }

    /// Population standard deviation (NaN when empty).
    pub fn std(&self) -> f64 {
        if self.count == 0 {
            f64::NAN
        } else {
            (self.m2 / self.count as f64).sqrt()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_two_pass_formula() {
        let data = [1.0, 4.0, -2.5, 7.25, 3.0, 3.0, 1e-3];
        let mut s = RunningStats::default();
        data.iter().for_each(|&v| s.push(v));
        let n = data.len() as f64;
        let mean = data.iter().sum::<f64>() / n;
        let var = data.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        assert_eq!(s.count(), 7);
        assert!((s.mean() - mean).abs() < 1e-12);
        assert!((s.std() - var.sqrt()).abs() < 1e-12);
        assert!(RunningStats::default().mean().is_nan());
    }
}
