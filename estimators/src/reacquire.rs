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
