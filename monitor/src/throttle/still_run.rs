//! How far the throttle's static map has moved while the TPS has stood still: the evidence of
//! a stuck plate across steady holds, relative to where the plate stopped, so that the static
//! map's absolute error does not count.
//!
//! The static map of the identified model is poor in absolute terms: its angle depends on
//! `1 - a33`, which a 1.5 % error of `a33 = 0.983` (mode 1) changes by most of its value, and a
//! quiet healthy plate rests 8 deg and more from it (a plant 1 % off Table I at 1.05 V: 67.8
//! against 76.3 deg). How much the map *moves* between two voltages is far better known. So a
//! plate is judged stuck when the map has moved by the driven range since the TPS last moved,
//! not when the map is that far from the TPS.
//!
//! The TPS is low-passed (time constant `tau_s`) before its range is judged, so that a noisy
//! sensor on a plate at rest stays still for as long as it rests (the range of raw 10 mV noise
//! grows past 1 deg within seconds). The map's range counts only from `settle` readings into
//! the run: a plate that has just come to rest after a short voltage pulse stands still while
//! the low-passed voltage behind the map is still coming back from the pulse.

/// A run of TPS readings within `range_deg` of each other (low-passed), and the static map's
/// range over it.
#[derive(Debug, Clone)]
pub struct StillRun {
    range_deg: f64,
    alpha: f64,
    settle: u64,
    lp: Option<f64>,
    lo: f64,
    hi: f64,
    eq_lo: f64,
    eq_hi: f64,
    steps: u64,
}

impl StillRun {
    /// A run that ends when the low-passed TPS (time constant `tau_s`, sampled every
    /// `period_s`) spans more than `range_deg`; the map's range counts from `settle` readings
    /// into it.
    pub fn new(range_deg: f64, tau_s: f64, period_s: f64, settle: u64) -> Self {
        Self {
            range_deg,
            alpha: -(-period_s / tau_s).exp_m1(),
            settle,
            lp: None,
            lo: 0.0,
            hi: 0.0,
            eq_lo: 0.0,
            eq_hi: 0.0,
            steps: 0,
        }
    }

    /// One TPS reading (deg) and the static map's angle at the same step (deg).
    pub fn push(&mut self, tps_deg: f64, eq_deg: f64) {
        let lp = match self.lp {
            Some(lp) => lp + self.alpha * (tps_deg - lp),
            None => tps_deg,
        };
        self.lp = Some(lp);
        let (lo, hi) = (self.lo.min(lp), self.hi.max(lp));
        if self.steps == 0 || hi - lo > self.range_deg {
            self.restart(lp, eq_deg);
        } else {
            self.lo = lo;
            self.hi = hi;
            if self.steps <= self.settle {
                self.eq_lo = eq_deg;
                self.eq_hi = eq_deg;
            } else {
                self.eq_lo = self.eq_lo.min(eq_deg);
                self.eq_hi = self.eq_hi.max(eq_deg);
            }
        }
        self.steps += 1;
    }

    fn restart(&mut self, lp: f64, eq_deg: f64) {
        self.lo = lp;
        self.hi = lp;
        self.eq_lo = eq_deg;
        self.eq_hi = eq_deg;
        self.steps = 0;
    }

    /// Forgets the run (a reading at a rail, a missing sample): the next reading starts one.
    pub fn clear(&mut self) {
        self.lp = None;
        self.steps = 0;
    }

    /// Readings in the run so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// How far the static map has ranged during the run (deg).
    pub fn map_span_deg(&self) -> f64 {
        self.eq_hi - self.eq_lo
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_map_span_counts_only_while_the_tps_stands_still() {
        let mut r = StillRun::new(1.0, 0.02, 0.001, 200);
        // 2 s at rest (TPS 30 deg with +-0.3 deg alternation), the map stepping 30 -> 45 deg.
        for k in 0..2000 {
            let tps = 30.0 + if k % 2 == 0 { 0.3 } else { -0.3 };
            let eq = if k < 1000 { 30.0 } else { 45.0 };
            r.push(tps, eq);
        }
        assert!(r.steps() >= 1999, "{}", r.steps());
        assert_eq!(r.map_span_deg(), 15.0);
        // The plate follows to 45 deg: the run restarts, and the old map span is gone.
        for _ in 0..500 {
            r.push(45.0, 45.0);
        }
        assert!(r.steps() < 500);
        assert_eq!(r.map_span_deg(), 0.0);
    }

    #[test]
    fn the_map_counts_only_once_the_run_has_settled() {
        let mut r = StillRun::new(1.0, 0.02, 0.001, 200);
        // The plate comes to rest while the map is still falling from a pulse (50 -> 8 deg
        // within 0.15 s): no span; a later hold change counts.
        for k in 0..1000 {
            let eq = (50.0 - 0.3 * k as f64).max(8.0);
            r.push(8.0, eq);
        }
        assert_eq!(r.map_span_deg(), 0.0);
        for _ in 0..100 {
            r.push(8.0, 20.0);
        }
        assert_eq!(r.map_span_deg(), 12.0);
    }

    #[test]
    fn a_slow_creep_past_the_range_restarts_the_run() {
        let mut r = StillRun::new(1.0, 0.02, 0.001, 0);
        for k in 0..3000 {
            r.push(10.0 + 1e-3 * k as f64, 10.0 + 1e-2 * k as f64);
        }
        // 1 deg per second of creep: no run lasts much over a second.
        assert!(r.steps() <= 1100, "{}", r.steps());
        assert!(r.map_span_deg() <= 11.0, "{}", r.map_span_deg());
        r.clear();
        r.push(50.0, 20.0);
        assert_eq!((r.steps(), r.map_span_deg()), (1, 0.0));
    }
}
