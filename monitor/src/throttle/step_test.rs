//! The TPS step test: a position sensor that jumps where the plate cannot.
//!
//! A bias that appears at once (a shifted ground, a connector) moves the TPS reading by a few
//! tenths of a volt in one sample. The TPS filter absorbs such a step within a few samples
//! (its process noise lets the plate move fast), so its innovation shows it only once, with a
//! variance that includes the filter's whole prediction uncertainty. This test compares the
//! measured change over a short window with the change the model predicts from the filter's
//! estimates, and scales the allowance with how fast the plate was moving: at rest the
//! allowance is the sensor's noise and a model-error floor, so a 6 deg step (0.33 V) stands out
//! by about 15 standard deviations; while the plate moves fast, a sensor lag of a millisecond or a mode switch of
//! the identified model can move the reading against the prediction by a fraction of the
//! motion, which the allowance covers.
//!
//! Pure logic on fixed arrays: no I/O, no allocation.

/// Samples in the window over which the change is compared.
pub const TPS_STEP_SAMPLES: usize = 3;
/// Samples before the window whose motion sets the allowance too.
const PRE_SAMPLES: usize = 3;
/// Ring length: the window, the samples before it, and one for the first difference.
const LEN: usize = TPS_STEP_SAMPLES + PRE_SAMPLES + 1;

/// Settings (see the `tps_step_*` keys of `ThrottleMonitorConfig`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepTestConfig {
    /// Failed above this many standard deviations.
    pub sigma: f64,
    /// Model-error floor of the standard deviation (V).
    pub floor_v: f64,
    /// Allowance per volt of recent one-sample motion.
    pub motion_scale: f64,
}

/// One sample's outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutcome {
    /// Normalized step over the window (signed, standard deviations).
    pub z: f64,
    /// True when this window and one of the two before it exceeded the threshold.
    pub failed: bool,
}

/// The test's state: the last readings (V) and the predicted one-sample changes (V).
#[derive(Debug, Clone)]
pub struct StepTest {
    cfg: StepTestConfig,
    y: [f64; LEN],
    predicted: [f64; LEN],
    /// Per sample, the larger of the predicted change and the model's spread (V).
    motion: [f64; LEN],
    len: usize,
    head: usize,
    /// Exceedances of the last three windows, as bits (bit 0 the newest).
    exceed: u8,
    /// The variance of the window before the latest exceedance (V^2).
    held_var: f64,
}

impl StepTest {
    pub fn new(cfg: StepTestConfig) -> Self {
        Self {
            cfg,
            y: [0.0; LEN],
            predicted: [0.0; LEN],
            motion: [0.0; LEN],
            len: 0,
            head: 0,
            exceed: 0,
            held_var: f64::INFINITY,
        }
    }

    /// Forgets the history (a missing or rail sample breaks the window).
    pub fn reset(&mut self) {
        self.len = 0;
        self.head = 0;
        self.exceed = 0;
    }

    /// Index of the sample `back` samples before the newest (0 = newest).
    fn at(&self, back: usize) -> usize {
        (self.head + LEN - 1 - back) % LEN
    }

    /// Takes the reading `y` (V), the change of the predicted reading since the previous
    /// estimate (V: prediction minus the previous update's reading), how much more the
    /// prediction could be off by the model's own structure (V, e.g. a mode switch one step
    /// early or late; counted as motion) and the sensor's noise variance `r` (V^2). `None`
    /// until the window is full.
    pub fn push(
        &mut self,
        y: f64,
        predicted_change: f64,
        model_spread: f64,
        r: f64,
    ) -> Option<StepOutcome> {
        self.y[self.head] = y;
        self.predicted[self.head] = predicted_change;
        self.motion[self.head] = predicted_change.abs().max(model_spread.abs());
        self.head = (self.head + 1) % LEN;
        self.len = (self.len + 1).min(LEN);
        if self.len < LEN {
            return None;
        }
        let n = TPS_STEP_SAMPLES;
        let predicted: f64 = (0..n).map(|b| self.predicted[self.at(b)]).sum();
        let d = self.y[self.at(0)] - self.y[self.at(n)] - predicted;
        // Motion that sets the allowance: every predicted change in and before the window, and
        // the measured changes before it (those inside would include the step itself).
        let mut m: f64 = 0.0;
        for b in 0..n + PRE_SAMPLES {
            m = m.max(self.motion[self.at(b)]);
        }
        for b in n..n + PRE_SAMPLES {
            m = m.max((self.y[self.at(b)] - self.y[self.at(b + 1)]).abs());
        }
        let mut var = 2.0 * r + self.cfg.floor_v.powi(2) + (self.cfg.motion_scale * m).powi(2);
        // A window right after an exceedance is judged with the allowance in force before it:
        // the filter's update on a step moves its velocity estimate, so its next predictions
        // move too and would widen the allowance by the step itself.
        if self.exceed & 0b11 != 0 {
            var = var.min(self.held_var);
        } else {
            self.held_var = var;
        }
        let z = d / var.max(f64::MIN_POSITIVE).sqrt();
        self.exceed = ((self.exceed << 1) | u8::from(z.abs() > self.cfg.sigma)) & 0b111;
        Some(StepOutcome {
            z,
            failed: self.exceed & 1 == 1 && self.exceed.count_ones() >= 2,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test() -> StepTest {
        StepTest::new(StepTestConfig {
            sigma: 10.0,
            floor_v: 0.01,
            motion_scale: 2.0,
        })
    }

    /// Feeds readings with a model that predicts them exactly, returning the outcomes.
    fn feed(t: &mut StepTest, ys: &[f64], predicted: &[f64]) -> Vec<Option<StepOutcome>> {
        ys.iter()
            .zip(predicted)
            .map(|(&y, &p)| t.push(y, p, 0.0, 0.005f64.powi(2)))
            .collect()
    }

    #[test]
    fn a_step_at_rest_fails_and_a_spike_does_not() {
        let mut t = test();
        let mut ys = vec![1.0; 20];
        for y in &mut ys[10..] {
            *y += 0.3;
        }
        let out = feed(&mut t, &ys, &[0.0; 20]);
        assert!(
            out[..7].iter().all(Option::is_none) || out[..7].iter().flatten().all(|o| !o.failed)
        );
        assert!(
            out[10].is_some_and(|o| o.z > 10.0 && !o.failed),
            "{:?}",
            out[10]
        );
        assert!(out[11].is_some_and(|o| o.failed), "{:?}", out[11]);
        // Once the window is past the step, it passes again.
        assert!(out[14..].iter().flatten().all(|o| !o.failed));

        let mut t = test();
        let mut ys = vec![1.0; 20];
        ys[10] += 0.3;
        // A spike: the filter would follow part of it and predict no motion back.
        let out = feed(&mut t, &ys, &[0.0; 20]);
        assert!(out.iter().flatten().all(|o| !o.failed), "{out:?}");
    }

    #[test]
    fn motion_the_model_predicts_is_no_step_and_fast_motion_widens_the_allowance() {
        // A plate moving 0.05 V per sample, predicted: nothing.
        let mut t = test();
        let ys: Vec<f64> = (0..30).map(|k| 0.05 * k as f64).collect();
        let out = feed(&mut t, &ys, &[0.05; 30]);
        assert!(out.iter().flatten().all(|o| o.z.abs() < 1e-9));
        // The same plate read 0.1 V behind the prediction for a few samples (a lag): covered
        // by the allowance of twice the motion.
        let mut t = test();
        let mut ys = ys;
        for y in &mut ys[15..18] {
            *y -= 0.1;
        }
        let out = feed(&mut t, &ys, &[0.05; 30]);
        assert!(out.iter().flatten().all(|o| !o.failed), "{out:?}");
        // At rest, twice that is a step (16 standard deviations of a 5 mV sensor with the
        // 10 mV floor), and the 0.1 V alone is not (8).
        let mut t = test();
        let mut ys = vec![1.0; 30];
        for y in &mut ys[15..] {
            *y -= 0.2;
        }
        let out = feed(&mut t, &ys, &[0.0; 30]);
        assert!(out.iter().flatten().any(|o| o.failed));
    }

    #[test]
    fn reset_empties_the_window() {
        let mut t = test();
        feed(&mut t, &[1.0; 10], &[0.0; 10]);
        t.reset();
        assert!(t.push(2.0, 0.0, 0.0, 1e-4).is_none());
    }
}
