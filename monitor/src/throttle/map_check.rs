//! Whether the wattmeter-only filter has settled on a wrong branch while the voltage holds.
//!
//! Fed by the wattmeter alone, the filter knows a plate at rest only through the current it
//! draws, and the identified model can hold an estimate in a limit cycle about the 8 deg mode
//! boundary (the velocity state changes scale and sign there) while the plate rests tens of
//! degrees higher: the boundary's current misses the wattmeter by a tenth of a watt, well inside
//! a 0.4 W wattmeter's noise sample by sample, so the filter's NIS never asks for a reset. Over a
//! steady hold, though, the mean of its innovation shows it, and the static map (the rest state
//! under the held voltage) explains the same readings. This module keeps those two means over
//! windows of a steady voltage; the monitor re-seeds the filter at the map when the map explains
//! the wattmeter clearly better and lies far from the estimate.

/// Means of two residual series over windows of readings taken while the voltage holds.
#[derive(Debug, Clone)]
pub struct MapCheck {
    window: u32,
    settle: u32,
    steady_v: f64,
    u_ref: f64,
    held: u32,
    n: u32,
    sum_filter: f64,
    sum_map: f64,
}

impl MapCheck {
    /// Windows of `window` readings, counted from `settle` readings after the voltage last
    /// moved by more than `steady_v` (V) from where the hold began (the plate and its current
    /// settle after a step).
    pub fn new(window: u32, settle: u32, steady_v: f64) -> Self {
        Self {
            window: window.max(1),
            settle,
            steady_v,
            u_ref: f64::NAN,
            held: 0,
            n: 0,
            sum_filter: 0.0,
            sum_map: 0.0,
        }
    }

    /// One step: the voltage `u` (V), the filter's wattmeter innovation and the reading less
    /// the map's prediction (W). Returns both means at the end of each window.
    pub fn push(&mut self, u: f64, filter_w: f64, map_w: f64) -> Option<(f64, f64)> {
        if !(u.is_finite() && filter_w.is_finite() && map_w.is_finite()) {
            self.clear();
            return None;
        }
        if self.held == 0 || (u - self.u_ref).abs() > self.steady_v {
            self.clear();
            self.u_ref = u;
        }
        self.held = self.held.saturating_add(1);
        if self.held <= self.settle {
            return None;
        }
        self.n += 1;
        self.sum_filter += filter_w;
        self.sum_map += map_w;
        if self.n < self.window {
            return None;
        }
        let n = f64::from(self.n);
        let means = (self.sum_filter / n, self.sum_map / n);
        self.n = 0;
        self.sum_filter = 0.0;
        self.sum_map = 0.0;
        Some(means)
    }

    /// Forgets the hold (a gap, a reset of the filter, a new operation cycle).
    pub fn clear(&mut self) {
        self.held = 0;
        self.n = 0;
        self.sum_filter = 0.0;
        self.sum_map = 0.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn means_come_once_per_window_after_the_settle() {
        let mut c = MapCheck::new(4, 2, 0.01);
        let mut out = Vec::new();
        for k in 0..12 {
            if let Some(m) = c.push(0.5, k as f64, -1.0) {
                out.push((k, m));
            }
        }
        // Readings 0 and 1 settle; 2..=5 and 6..=9 make the windows.
        assert_eq!(out, vec![(5, (3.5, -1.0)), (9, (7.5, -1.0))]);
    }

    #[test]
    fn a_voltage_step_or_a_gap_restarts_the_hold() {
        let mut c = MapCheck::new(3, 1, 0.01);
        assert_eq!(c.push(0.5, 1.0, 0.0), None);
        assert_eq!(c.push(0.5, 1.0, 0.0), None);
        // The voltage moves: settle again, and the window counts afresh.
        assert_eq!(c.push(0.6, 9.0, 0.0), None);
        assert_eq!(c.push(0.6, 2.0, 0.0), None);
        assert_eq!(c.push(0.605, 2.0, 0.0), None);
        assert_eq!(c.push(0.6, 2.0, 0.0), Some((2.0, 0.0)));
        // A missing reading clears it.
        assert_eq!(c.push(0.6, f64::NAN, 0.0), None);
        assert_eq!(c.push(0.6, 5.0, 0.0), None);
        assert_eq!(c.push(0.6, 5.0, 0.0), None);
        assert_eq!(c.push(0.6, 5.0, 0.0), None);
        assert_eq!(c.push(0.6, 5.0, 0.0), Some((5.0, 0.0)));
    }
}
