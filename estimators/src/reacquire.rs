//! Covariance re-acquisition: a filter whose innovations stay too large for too long is no longer
//! described by its covariance (it has locked onto a wrong branch of a multimodal posterior, such
//! as the wrong mode of a piecewise model). Re-opening its covariance lets the data pull it back;
//! its mean is kept.
//!
//! The test is an exponentially weighted mean of the NIS per degree of freedom, which is 1 for a
//! consistent filter. When it exceeds `threshold`, the caller resets the covariance, and the
//! average restarts at 1 so that one episode triggers one reset.

/// EWMA consistency monitor on the NIS.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reacquire {
    /// Forgetting factor per update, `1 - 1/window`.
    keep: f64,
    threshold: f64,
    /// Updates to wait after a reset before testing again.
    holdoff: u32,
    mean_nis: f64,
    wait: u32,
    resets: u64,
}

impl Reacquire {
    /// `window`: effective averaging length in updates (> 1); `threshold`: mean NIS per degree
    /// of freedom that triggers (> 1); `holdoff`: updates to skip after a reset.
    pub fn new(window: f64, threshold: f64, holdoff: u32) -> Result<Self, crate::ConfigError> {
        if !(window > 1.0) || !window.is_finite() {
            return Err(crate::ConfigError::InvalidParameter {
                name: "reacquire_window",
                value: window,
                reason: "must be a finite number above 1",
            });
        }
        if !(threshold > 1.0) || !threshold.is_finite() {
            return Err(crate::ConfigError::InvalidParameter {
                name: "reacquire_threshold",
                value: threshold,
                reason: "must be a finite number above 1 (the consistent mean NIS)",
            });
        }
        Ok(Self {
            keep: 1.0 - 1.0 / window,
            threshold,
            holdoff,
            mean_nis: 1.0,
            wait: holdoff,
            resets: 0,
        })
    }

    /// Feeds one update's NIS and degrees of freedom; returns true when the caller should reset
    /// the covariance now.
    pub fn observe(&mut self, nis: f64, dof: usize) -> bool {
        if !nis.is_finite() || dof == 0 {
            return false;
        }
        self.mean_nis = self.keep * self.mean_nis + (1.0 - self.keep) * nis / dof as f64;
        if self.wait > 0 {
            self.wait -= 1;
            return false;
        }
        if self.mean_nis > self.threshold {
            self.mean_nis = 1.0;
            self.wait = self.holdoff;
            self.resets += 1;
            return true;
        }
        false
    }

    /// Current averaged NIS per degree of freedom.
    pub fn mean_nis(&self) -> f64 {
        self.mean_nis
    }

    /// Resets triggered so far.
    pub fn resets(&self) -> u64 {
        self.resets
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn consistent_innovations_never_trigger_and_biased_ones_do() {
        let mut r = Reacquire::new(50.0, 2.0, 50).expect("valid");
        // NIS of exactly its expectation: never triggers.
        assert!((0..10_000).all(|_| !r.observe(1.0, 1)));
        // NIS of 4 (a 2-sigma persistent bias): the average 4 - 3 (1 - 1/50)^k passes 2 after
        // k = ln(1.5)/ln(1/(1 - 1/50)) ~ 20 updates; then it holds off.
        let first = (1..=200).find(|_| r.observe(4.0, 1)).expect("triggers");
        assert!((20..=22).contains(&first), "triggered after {first}");
        assert_eq!(r.resets(), 1);
        assert!((0..50).all(|_| !r.observe(4.0, 1)), "holdoff respected");
        // Degrees of freedom normalize the NIS.
        let mut r2 = Reacquire::new(50.0, 2.0, 0).expect("valid");
        assert!((0..1000).all(|_| !r2.observe(3.0, 2)));
        assert!(!r2.observe(f64::NAN, 1));
    }

    #[test]
    fn rejects_bad_settings() {
        assert!(Reacquire::new(1.0, 2.0, 0).is_err());
        assert!(Reacquire::new(50.0, 0.5, 0).is_err());
        assert!(Reacquire::new(f64::NAN, 2.0, 0).is_err());
    }
}
