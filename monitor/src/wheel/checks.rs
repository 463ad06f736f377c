//! The checks of one wheel-speed sensor, each a small state machine fed once per 5 ms step:
//! the supply current (open circuit, intermittent contact), a wheel reading no speed while
//! the car moves (a lost pulse train: air gap), innovation spikes that recur once per
//! revolution (a damaged tone ring) and the wheel's speed against the others' (a gain error:
//! wrong tyre or tooth count). Pure logic: no I/O, no allocation.

use super::config::WheelMonitorConfig;

/// Electrical check: how long the current has been out of range, and what that made of it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Electrical {
    /// Time the current has been out of range without a break (s).
    pub bad_s: f64,
    /// The current is out of range for `open_debounce_s` now: no signal.
    pub open: bool,
    /// A dropout shorter than `open_debounce_s` ended at this time (s): an intermittent
    /// contact. `None` before any.
    pub last_dropout_s: Option<f64>,
}

impl Electrical {
    /// One step of `dt` (s) ending at `t` (s) with the current `ma` (mA). NaN is out of range
    /// (a current that does not arrive is no current).
    pub fn step(&mut self, cfg: &WheelMonitorConfig, t: f64, dt: f64, ma: f64) {
        let bad = ma.is_nan() || ma < cfg.current_min_ma || ma > cfg.current_max_ma;
        if bad {
            self.bad_s += dt;
            self.open = self.bad_s >= cfg.open_debounce_s - 1e-9;
        } else {
            if self.bad_s > 0.0 && !self.open {
                self.last_dropout_s = Some(t);
            }
            self.bad_s = 0.0;
            self.open = false;
        }
    }

    /// The current is in range this step.
    pub fn valid(&self) -> bool {
        self.bad_s == 0.0
    }
}

/// Air-gap check: how long the wheel has read no speed while the others say the car moves.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AirGap {
    /// Time in that state (s), unbraked and braked counted apart.
    pub free_s: f64,
    pub braked_s: f64,
}

impl AirGap {
    /// One step: `rim` this wheel's rim speed (m/s), `others` the other wheels' median rim
    /// speed (m/s), `braked` whether a brake torque acts on the wheel, `valid` its current.
    /// Returns whether the check fails now (None: not tested this step).
    pub fn step(
        &mut self,
        cfg: &WheelMonitorConfig,
        dt: f64,
        rim: f64,
        others: f64,
        braked: bool,
        valid: bool,
    ) -> Option<bool> {
        let tested =
            valid && others >= cfg.air_gap_others_m_s && others <= cfg.air_gap_max_speed_m_s;
        if !tested {
            // Outside its window the check neither fails nor clears an ongoing count unless
            // the wheel reads a speed.
            if rim >= cfg.zero_speed_m_s {
                *self = Self::default();
            }
            return None;
        }
        if rim < cfg.zero_speed_m_s {
            if braked {
                self.braked_s += dt;
            } else {
                self.free_s += dt;
            }
        } else {
            *self = Self::default();
        }
        Some(
            self.free_s >= cfg.air_gap_debounce_s
                || self.free_s + self.braked_s >= cfg.air_gap_braked_debounce_s,
        )
    }
}

/// Largest number of spikes remembered per wheel.
pub const SPIKE_MEMORY: usize = 8;

/// Tone-ring check: spikes of the wheel filter's normalized innovation and the wheel angle at
/// which each happened (the filter's speed integrated, rad: the faulty readings do not move
/// it). A defect on the ring passes the sensor once per revolution, so its spikes come at the
/// same angle revolution after revolution; the spikes of a lock and release do not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToneRing {
    /// Wheel angle (rad, not wrapped).
    pub angle_rad: f64,
    /// (time s, angle rad) of the last spikes, oldest first; `len` of them valid.
    spikes: [(f64, f64); SPIKE_MEMORY],
    len: usize,
    /// Largest chain of spikes one revolution apart found at the last spike.
    pub chain: u32,
}

impl Default for ToneRing {
    fn default() -> Self {
        Self {
            angle_rad: 0.0,
            spikes: [(0.0, 0.0); SPIKE_MEMORY],
            len: 0,
            chain: 0,
        }
    }
}

impl ToneRing {
    /// One step ending at `t` (s): the wheel turned by `omega * dt` (rad, the filter's speed),
    /// and the innovation was `z` standard deviations. Returns whether the check fails now.
    pub fn step(&mut self, cfg: &WheelMonitorConfig, t: f64, dt: f64, omega: f64, z: f64) -> bool {
        self.angle_rad += omega.max(0.0) * dt;
        // Forget spikes older than the window.
        let keep_from = self.spikes[..self.len]
            .iter()
            .position(|&(ts, _)| t - ts <= cfg.spike_window_s)
            .unwrap_or(self.len);
        if keep_from > 0 {
            self.spikes.copy_within(keep_from..self.len, 0);
            self.len -= keep_from;
        }
        if z.abs() < cfg.spike_sigma || !z.is_finite() {
            return false;
        }
        if self.len == SPIKE_MEMORY {
            self.spikes.copy_within(1..SPIKE_MEMORY, 0);
            self.len -= 1;
        }
        self.spikes[self.len] = (t, self.angle_rad);
        self.len += 1;
        // The longest chain ending at this spike whose links are each one revolution (within
        // the tolerance), walking back through the remembered spikes.
        let tau = std::f64::consts::TAU;
        let mut chain = 1;
        let mut at = self.angle_rad;
        for k in (0..self.len - 1).rev() {
            let gap = at - self.spikes[k].1;
            if (gap - tau).abs() <= cfg.spike_angle_tol_rad {
                chain += 1;
                at = self.spikes[k].1;
            }
        }
        self.chain = chain;
        chain >= cfg.spikes_to_fail
    }
}

/// Gain plausibility: a two-sided CUSUM of the wheel's speed ratio against the others' over its
/// learned offset.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Ratio {
    /// Learned offset of the ratio (-).
    pub offset: f64,
    /// Free-rolling time learned this operation cycle (s).
    pub learned_s: f64,
    /// CUSUM statistics of positive and negative deviations.
    pub up: f64,
    pub down: f64,
}

impl Ratio {
    /// One step with this wheel's speed over the others' median, less one (`e`, -), when the
    /// wheels roll freely. Returns `Some(failed)` when tested.
    pub fn step(&mut self, cfg: &WheelMonitorConfig, dt: f64, e: f64) -> Option<bool> {
        if !e.is_finite() {
            return None;
        }
        let dev = e - self.offset;
        let learning = self.learned_s < cfg.ratio_learn_min_s;
        // Learn alone at first, then only while the deviation is within the reference (a
        // fault's shift is not learned away).
        let k = 0.5 * cfg.ratio_min_shift;
        if learning || dev.abs() < k {
            let a = (dt / cfg.ratio_learn_tau_s).min(1.0);
            let tau_scale = if learning { 1.0 } else { 0.1 };
            self.offset = (self.offset + a * tau_scale * dev)
                .clamp(-cfg.ratio_learn_limit, cfg.ratio_learn_limit);
            self.learned_s += dt;
        }
        if learning {
            return None;
        }
        self.up = (self.up + dev - k).max(0.0);
        self.down = (self.down - dev - k).max(0.0);
        let at_bound = self.offset.abs() >= cfg.ratio_learn_limit - 1e-12;
        Some(self.up.max(self.down) > cfg.ratio_cusum_threshold || at_bound)
    }

    /// The CUSUM statistic (the larger side).
    pub fn value(&self) -> f64 {
        self.up.max(self.down)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> WheelMonitorConfig {
        WheelMonitorConfig::default()
    }

    #[test]
    fn the_current_separates_an_open_circuit_from_a_dropout() {
        let c = cfg();
        let mut e = Electrical::default();
        let dt = 0.005;
        let mut t = 0.0;
        for _ in 0..10 {
            t += dt;
            e.step(&c, t, dt, 7.0);
        }
        assert!(e.valid() && !e.open && e.last_dropout_s.is_none());
        // 40 ms without current, then back: intermittent, not open.
        for _ in 0..8 {
            t += dt;
            e.step(&c, t, dt, 0.2);
            assert!(!e.open);
        }
        t += dt;
        e.step(&c, t, dt, 14.0);
        assert_eq!(e.last_dropout_s, Some(t));
        let dropout = e.last_dropout_s;
        // 90 ms without current: open (18 steps), and staying open is not a dropout.
        let start = t;
        let mut opened = None;
        for _ in 0..30 {
            t += dt;
            e.step(&c, t, dt, f64::NAN);
            if e.open && opened.is_none() {
                opened = Some(t - start);
            }
        }
        let opened = opened.expect("opens");
        assert!((opened - 0.09).abs() < 1e-9, "{opened}");
        t += dt;
        e.step(&c, t, dt, 7.0);
        assert_eq!(
            e.last_dropout_s, dropout,
            "an open circuit's end is no dropout"
        );
        assert!(!e.open && e.valid());
    }

    #[test]
    fn a_wheel_reading_nothing_while_the_others_move_fails_after_its_debounce() {
        let c = cfg();
        let mut a = AirGap::default();
        let dt = 0.005;
        // Others at 2 m/s, this one at 0, unbraked: fails after 0.3 s.
        let mut n = 0;
        while a.step(&c, dt, 0.0, 2.0, false, true) != Some(true) {
            n += 1;
            assert!(n < 1000);
        }
        assert_eq!(n + 1, 60);
        // Braked (a lock): needs 1 s.
        let mut a = AirGap::default();
        let mut n = 0;
        while a.step(&c, dt, 0.0, 2.0, true, true) != Some(true) {
            n += 1;
            assert!(n < 1000);
        }
        assert_eq!(n + 1, 200);
        // A wheel reading a speed clears it; outside the speed window it is not tested.
        assert_eq!(a.step(&c, dt, 2.0, 2.0, false, true), Some(false));
        assert_eq!(a.step(&c, dt, 0.0, 12.0, false, true), None);
        assert_eq!(a.step(&c, dt, 0.0, 0.3, false, true), None);
        assert_eq!(a.step(&c, dt, 0.0, 2.0, false, false), None);
    }

    #[test]
    fn spikes_once_per_revolution_fail_and_random_spikes_do_not() {
        let c = cfg();
        let dt = 0.005;
        let omega = 40.0; // rad/s: a revolution in 0.157 s, 31.4 steps.
        let mut r = ToneRing::default();
        let mut failed_at = None;
        let mut next_spike = std::f64::consts::TAU * 0.3;
        for k in 1..400 {
            let t = k as f64 * dt;
            let spike = r.angle_rad + omega * dt >= next_spike;
            if spike {
                next_spike += std::f64::consts::TAU;
            }
            let z = if spike { -9.0 } else { 0.5 };
            if r.step(&c, t, dt, omega, z) && failed_at.is_none() {
                failed_at = Some(t);
            }
        }
        let f = failed_at.expect("fails");
        // The third spike: 0.3 rev + 2 revolutions.
        assert!(f < (2.3 * std::f64::consts::TAU / omega) + 0.02, "{f}");
        // Spikes at angles that do not repeat (every 0.7 revolution) never chain.
        let mut r = ToneRing::default();
        let mut next_spike = 0.7 * std::f64::consts::TAU;
        for k in 1..2000 {
            let t = k as f64 * dt;
            let spike = r.angle_rad + omega * dt >= next_spike;
            if spike {
                next_spike += 0.7 * std::f64::consts::TAU;
            }
            assert!(
                !r.step(&c, t, dt, omega, if spike { 9.0 } else { 0.0 }),
                "{t}"
            );
        }
    }

    #[test]
    fn a_ratio_shift_after_learning_fails_and_the_learned_offset_does_not() {
        let c = cfg();
        let dt = 0.005;
        let mut r = Ratio::default();
        // A tyre 0.8 % larger than the others: learned, never failing.
        for _ in 0..((60.0 / dt) as usize) {
            assert_ne!(r.step(&c, dt, -0.008), Some(true));
        }
        assert!((r.offset + 0.008).abs() < 1e-3, "{}", r.offset);
        // Then a 2 % gain error: fails within a second (reference 0.75 %, threshold 2).
        let mut n = 0;
        while r.step(&c, dt, -0.008 + 0.02) != Some(true) {
            n += 1;
            assert!(n < 400, "{n}");
        }
        assert!(n < 200, "{n}");
    }
}
