//! The road surface of a braking event, from the wheel filter's slip and friction estimates:
//! the surface of the tutorial's table whose Burckhardt curve fits them best. Below a few
//! percent slip every surface's curve is about the same straight line (the initial slopes
//! differ by a factor of two, the peaks by twenty), so only frames with the tyre driven toward
//! its peak count ([`super::config::WheelMonitorConfig::surface_min_slip`]).

use fdd_estimators::models::wheel::{Burckhardt, Surface};

/// Frames (5 ms) an event needs before it names a surface: 0.1 s near the peak.
pub const MIN_FRAMES: u32 = 20;

/// The squared misfit of each surface's curve over one braking event.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SurfaceEvidence {
    sse: [f64; 4],
    frames: u32,
}

impl SurfaceEvidence {
    /// Adds a frame's estimates (slip and friction, -).
    pub fn add(&mut self, curves: &[Burckhardt; 4], slip: f64, mu: f64) {
        if !(slip.is_finite() && mu.is_finite()) {
            return;
        }
        for (e, c) in self.sse.iter_mut().zip(curves) {
            let d = mu - c.mu(slip);
            *e += d * d;
        }
        self.frames += 1;
    }

    /// Frames collected.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// The best-fitting surface, once the event has [`MIN_FRAMES`].
    pub fn best(&self) -> Option<Surface> {
        if self.frames < MIN_FRAMES {
            return None;
        }
        let mut best = 0;
        for i in 1..4 {
            if self.sse[i] < self.sse[best] {
                best = i;
            }
        }
        Some(Surface::ALL[best])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curves() -> [Burckhardt; 4] {
        [
            Burckhardt::new([1.2801, 23.99, 0.52]),
            Burckhardt::new([0.857, 33.822, 0.347]),
            Burckhardt::new([0.1946, 94.129, 0.0646]),
            Burckhardt::new([0.05, 306.39, 0.0]),
        ]
    }

    #[test]
    fn each_surface_is_named_from_frames_near_its_peak_with_a_curve_a_few_percent_off() {
        let c = curves();
        for (i, s) in Surface::ALL.into_iter().enumerate() {
            let mut e = SurfaceEvidence::default();
            for k in 0..40_u32 {
                let slip = 0.08 + 0.002 * f64::from(k % 10);
                // The truth's curve 5 % below the table's, plus a wobble.
                let mu = 0.95 * c[i].mu(slip) + 0.01 * (f64::from(k) * 0.7).sin();
                e.add(&c, slip, mu);
                if k + 1 < MIN_FRAMES {
                    assert_eq!(e.best(), None);
                }
            }
            assert_eq!(e.best(), Some(s), "{s:?}");
        }
    }
}
