//! Scoring a diagnosis system against ground truth, with the definitions of the DX'25
//! diagnostic competition on the LiU-ICE engine (shared/REFERENCE.md §7) plus the per-fault
//! figures a diagnosis engineer asks for.
//!
//! The system under test gives, per sample, a detection flag and a score per fault class (how
//! strongly it names each class, in `[0, 1]`); the truth gives, per sample, whether a fault is
//! present and which. Over all samples of all logs:
//!
//! - **TDR** (true detection rate): share of faulty samples that are flagged;
//! - **FAR** (false alarm rate): share of fault-free samples that are flagged;
//! - **FIA** (fault isolation accuracy): mean score of the true fault over the faulty samples
//!   that are flagged.
//!
//! Per fault class, over its *episodes* (a run of consecutive faulty samples of that class in
//! one log): the detection rate (episodes with a flag), the DTC rate (episodes during which any
//! DTC was raised), the correct-DTC rate (episodes during which a specific DTC naming the class
//! was raised), the group-DTC figures (a group DTC names several candidate classes when
//! isolation cannot decide yet: did its candidates include the true one?), and the median and
//! worst delay from the episode's first faulty sample to the first flag, the first DTC and the
//! first correct specific DTC. Over the fault-free time: false alarms per hour (rising edges of
//! the flag) and DTCs raised per hour.
//!
//! Samples the truth marks [`Truth::Ignored`] (a fault present but without effect on anything
//! measured, or a settling margin) count nowhere; they end no episode. A DTC raised during them
//! belongs to the episode they are part of: the open one, or else the one that opens next (at
//! its onset, delay 0: a stuck sensor named before the plate left its reading), unless
//! fault-free samples come first.
//!
//! This module is pure bookkeeping: no I/O, and allocation only per log and per episode.

use serde::Serialize;
use thiserror::Error;

/// What the truth says about one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Truth {
    /// No fault present.
    FaultFree,
    /// Fault class `index` (into the evaluator's classes) present.
    Faulty(usize),
    /// Not counted: e.g. a fault that is active but has no effect on any measured signal.
    Ignored,
}

/// A bad input to the evaluator, naming what was wrong.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EvaluationError {
    #[error("sample at t = {t_s} s: {got} fault scores, expected one per class ({expected})")]
    ScoreCount {
        t_s: f64,
        got: usize,
        expected: usize,
    },
    #[error("sample at t = {t_s} s: score {value} of class `{class}` is outside [0, 1]")]
    Score { t_s: f64, class: String, value: f64 },
    #[error("sample at t = {t_s} s: fault class index {index} but only {classes} classes")]
    Class {
        t_s: f64,
        index: usize,
        classes: usize,
    },
    #[error("sample at t = {t_s} s comes before the previous one (t = {previous_s} s)")]
    TimeOrder { t_s: f64, previous_s: f64 },
    #[error("time {t_s} s is not finite")]
    Time { t_s: f64 },
}

/// Figures of one fault class.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClassReport {
    pub class: String,
    /// Episodes of this fault in the evaluated logs.
    pub episodes: usize,
    /// Episodes with at least one flagged sample.
    pub detected: usize,
    /// Episodes during which any DTC (specific or group) was raised.
    pub any_dtc: usize,
    /// Episodes during which a specific DTC naming this class was raised.
    pub correct_dtc: usize,
    /// Episodes during which a specific DTC not naming this class was raised.
    pub wrong_dtc: usize,
    /// Episodes during which a group DTC was raised, and those of them in which a group DTC's
    /// candidates did not include this class.
    pub group_dtc: usize,
    pub group_missed: usize,
    /// `detected / episodes` (NaN without episodes).
    pub detection_rate: f64,
    /// `any_dtc / episodes` (NaN without episodes).
    pub dtc_rate: f64,
    /// `correct_dtc / episodes` (NaN without episodes).
    pub correct_dtc_rate: f64,
    /// Median and largest delay (s) from the episode's first faulty sample to its first flag,
    /// over the detected episodes (NaN when none was).
    pub median_detection_delay_s: f64,
    pub worst_detection_delay_s: f64,
    /// The same to the first DTC of any kind, over the episodes that got one.
    pub median_any_dtc_delay_s: f64,
    pub worst_any_dtc_delay_s: f64,
    /// The same to the first correct specific DTC, over the episodes that got one.
    pub median_dtc_delay_s: f64,
    pub worst_dtc_delay_s: f64,
}

/// What a raised DTC says about the fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DtcKind {
    /// A specific DTC: correct for exactly the classes given (e.g. every fault type of one
    /// sensor's DTC family).
    Specific,
    /// A group DTC (e.g. P0068): detected but not isolated; the classes given are its
    /// candidates.
    Group,
}

/// The figures over every log given to an [`Evaluator`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvaluationReport {
    pub logs: usize,
    /// Counted samples: faulty, faulty and flagged, fault-free, fault-free and flagged.
    pub faulty_samples: u64,
    pub faulty_flagged: u64,
    pub fault_free_samples: u64,
    pub fault_free_flagged: u64,
    /// TDR, FAR and FIA as fractions (NaN when their denominator is zero).
    pub tdr: f64,
    pub far: f64,
    pub fia: f64,
    /// Fault-free time (h): the sum of the intervals between consecutive fault-free samples.
    pub fault_free_hours: f64,
    /// Rising edges of the flag on fault-free samples, and DTCs raised while fault-free.
    pub false_alarms: u64,
    pub false_dtcs: u64,
    pub false_alarms_per_hour: f64,
    pub false_dtcs_per_hour: f64,
    pub classes: Vec<ClassReport>,
}

/// An episode being followed or finished.
#[derive(Debug, Clone, Copy)]
struct Episode {
    class: usize,
    onset_s: f64,
    first_flag_s: Option<f64>,
    first_dtc_s: Option<f64>,
    first_correct_dtc_s: Option<f64>,
    wrong_dtc: bool,
    group_dtc: bool,
    group_missed: bool,
}

impl Episode {
    /// Counts a DTC raised at `t_s` for this episode.
    fn dtc(&mut self, t_s: f64, classes: &[usize], kind: DtcKind) {
        self.first_dtc_s.get_or_insert(t_s);
        let names_it = classes.contains(&self.class);
        match (kind, names_it) {
            (DtcKind::Specific, true) => {
                self.first_correct_dtc_s.get_or_insert(t_s);
            }
            (DtcKind::Specific, false) => self.wrong_dtc = true,
            (DtcKind::Group, true) => self.group_dtc = true,
            (DtcKind::Group, false) => {
                self.group_dtc = true;
                self.group_missed = true;
            }
        }
    }
}

/// The state within the log being fed.
#[derive(Debug, Clone, Default)]
struct LogState {
    previous: Option<(f64, Truth, bool)>,
    open: Option<Episode>,
    /// DTCs raised while a fault was present without an observable effect yet and no episode
    /// was open: they count for the episode that opens next, at its onset (a sensor named
    /// stuck before the plate moves away from its reading), and for nothing if fault-free
    /// samples come first.
    early: Vec<(Vec<usize>, DtcKind)>,
}

/// Accumulates samples and DTCs of any number of logs; see the module documentation.
#[derive(Debug, Clone)]
pub struct Evaluator {
    classes: Vec<String>,
    logs: usize,
    faulty: u64,
    faulty_flagged: u64,
    free: u64,
    free_flagged: u64,
    fia_sum: f64,
    free_time_s: f64,
    false_alarms: u64,
    false_dtcs: u64,
    episodes: Vec<Episode>,
    log: LogState,
}

impl Evaluator {
    /// An evaluator for these fault classes (the order of every score slice).
    pub fn new(classes: &[&str]) -> Self {
        Self {
            classes: classes.iter().map(|c| c.to_string()).collect(),
            logs: 0,
            faulty: 0,
            faulty_flagged: 0,
            free: 0,
            free_flagged: 0,
            fia_sum: 0.0,
            free_time_s: 0.0,
            false_alarms: 0,
            false_dtcs: 0,
            episodes: Vec::new(),
            log: LogState::default(),
        }
    }

    /// The fault classes.
    pub fn classes(&self) -> &[String] {
        &self.classes
    }

    /// Index of a class by name.
    pub fn class_index(&self, name: &str) -> Option<usize> {
        self.classes.iter().position(|c| c == name)
    }

    /// Starts a new log: time may start again and no episode continues across logs.
    pub fn start_log(&mut self) {
        self.end_log();
        self.logs += 1;
    }

    /// Ends the current log (also done by [`Evaluator::start_log`] and [`Evaluator::report`]).
    pub fn end_log(&mut self) {
        if let Some(e) = self.log.open.take() {
            self.episodes.push(e);
        }
        self.log.previous = None;
        self.log.early.clear();
    }

    /// One sample at `t_s` (s, non-decreasing within a log): the truth, the system's flag and its
    /// score per class. On error nothing is counted.
    pub fn sample(
        &mut self,
        t_s: f64,
        truth: Truth,
        flagged: bool,
        scores: &[f64],
    ) -> Result<(), EvaluationError> {
        self.check_time(t_s)?;
        if scores.len() != self.classes.len() {
            return Err(EvaluationError::ScoreCount {
                t_s,
                got: scores.len(),
                expected: self.classes.len(),
            });
        }
        if let Some((i, &value)) = scores
            .iter()
            .enumerate()
            .find(|(_, v)| !(0.0..=1.0).contains(*v))
        {
            return Err(EvaluationError::Score {
                t_s,
                class: self.classes[i].clone(),
                value,
            });
        }
        if let Truth::Faulty(index) = truth {
            if index >= self.classes.len() {
                return Err(EvaluationError::Class {
                    t_s,
                    index,
                    classes: self.classes.len(),
                });
            }
        }
        if self.logs == 0 {
            self.logs = 1;
        }
        let previous = self.log.previous;
        match truth {
            Truth::FaultFree => {
                self.close_episode();
                self.log.early.clear();
                self.free += 1;
                if flagged {
                    self.free_flagged += 1;
                }
                if let Some((t0, Truth::FaultFree, was_flagged)) = previous {
                    self.free_time_s += t_s - t0;
                    if flagged && !was_flagged {
                        self.false_alarms += 1;
                    }
                } else if flagged {
                    self.false_alarms += 1;
                }
            }
            Truth::Faulty(class) => {
                if self.log.open.is_some_and(|e| e.class != class) {
                    self.close_episode();
                }
                let early = &mut self.log.early;
                let e = self.log.open.get_or_insert_with(|| {
                    let mut e = Episode {
                        class,
                        onset_s: t_s,
                        first_flag_s: None,
                        first_dtc_s: None,
                        first_correct_dtc_s: None,
                        wrong_dtc: false,
                        group_dtc: false,
                        group_missed: false,
                    };
                    for (classes, kind) in early.drain(..) {
                        e.dtc(t_s, &classes, kind);
                    }
                    e
                });
                self.faulty += 1;
                if flagged {
                    self.faulty_flagged += 1;
                    self.fia_sum += scores[class];
                    e.first_flag_s.get_or_insert(t_s);
                }
            }
            Truth::Ignored => {}
        }
        self.log.previous = Some((t_s, truth, flagged));
        Ok(())
    }

    /// A DTC raised (pending or confirmed, as the caller counts) at `t_s`: a specific DTC
    /// correct for the fault classes `classes` (empty: it names none of them), or a group DTC
    /// whose candidates are `classes`. It belongs to the sample most recently given: during an
    /// episode it counts for that episode; on a fault-free sample (or before any) it is a false
    /// DTC.
    pub fn dtc(
        &mut self,
        t_s: f64,
        classes: &[usize],
        kind: DtcKind,
    ) -> Result<(), EvaluationError> {
        if !t_s.is_finite() {
            return Err(EvaluationError::Time { t_s });
        }
        if let Some(&c) = classes.iter().find(|&&c| c >= self.classes.len()) {
            return Err(EvaluationError::Class {
                t_s,
                index: c,
                classes: self.classes.len(),
            });
        }
        match (&mut self.log.open, self.log.previous) {
            // An episode goes on through samples without an observable effect (they end no
            // episode), so a DTC raised then still belongs to it.
            (Some(e), Some((_, Truth::Faulty(_) | Truth::Ignored, _))) => {
                e.dtc(t_s, classes, kind);
            }
            (None, Some((_, Truth::Ignored, _))) => self.log.early.push((classes.to_vec(), kind)),
            _ => self.false_dtcs += 1,
        }
        Ok(())
    }

    /// False alarms and false DTCs counted so far (the difference across a log is that log's).
    pub fn false_counts(&self) -> (u64, u64) {
        (self.false_alarms, self.false_dtcs)
    }

    /// The figures over everything given so far (ends the current log).
    pub fn report(&mut self) -> EvaluationReport {
        self.end_log();
        let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
        let hours = self.free_time_s / 3600.0;
        let classes = (0..self.classes.len())
            .map(|c| {
                let eps: Vec<&Episode> = self.episodes.iter().filter(|e| e.class == c).collect();
                let detected = eps.iter().filter(|e| e.first_flag_s.is_some()).count();
                let correct = eps
                    .iter()
                    .filter(|e| e.first_correct_dtc_s.is_some())
                    .count();
                let wrong = eps.iter().filter(|e| e.wrong_dtc).count();
                let any = eps.iter().filter(|e| e.first_dtc_s.is_some()).count();
                let group = eps.iter().filter(|e| e.group_dtc).count();
                let group_missed = eps.iter().filter(|e| e.group_missed).count();
                let (median_any, worst_any) = median_and_max(
                    eps.iter()
                        .filter_map(|e| e.first_dtc_s.map(|t| t - e.onset_s)),
                );
                let (median_flag, worst_flag) = median_and_max(
                    eps.iter()
                        .filter_map(|e| e.first_flag_s.map(|t| t - e.onset_s)),
                );
                let (median_dtc, worst_dtc) = median_and_max(
                    eps.iter()
                        .filter_map(|e| e.first_correct_dtc_s.map(|t| t - e.onset_s)),
                );
                ClassReport {
                    class: self.classes[c].clone(),
                    episodes: eps.len(),
                    detected,
                    any_dtc: any,
                    correct_dtc: correct,
                    wrong_dtc: wrong,
                    group_dtc: group,
                    group_missed,
                    detection_rate: ratio(detected as f64, eps.len() as f64),
                    dtc_rate: ratio(any as f64, eps.len() as f64),
                    correct_dtc_rate: ratio(correct as f64, eps.len() as f64),
                    median_detection_delay_s: median_flag,
                    worst_detection_delay_s: worst_flag,
                    median_any_dtc_delay_s: median_any,
                    worst_any_dtc_delay_s: worst_any,
                    median_dtc_delay_s: median_dtc,
                    worst_dtc_delay_s: worst_dtc,
                }
            })
            .collect();
        EvaluationReport {
            logs: self.logs,
            faulty_samples: self.faulty,
            faulty_flagged: self.faulty_flagged,
            fault_free_samples: self.free,
            fault_free_flagged: self.free_flagged,
            tdr: ratio(self.faulty_flagged as f64, self.faulty as f64),
            far: ratio(self.free_flagged as f64, self.free as f64),
            fia: ratio(self.fia_sum, self.faulty_flagged as f64),
            fault_free_hours: hours,
            false_alarms: self.false_alarms,
            false_dtcs: self.false_dtcs,
            false_alarms_per_hour: ratio(self.false_alarms as f64, hours),
            false_dtcs_per_hour: ratio(self.false_dtcs as f64, hours),
            classes,
        }
    }

    fn close_episode(&mut self) {
        if let Some(e) = self.log.open.take() {
            self.episodes.push(e);
        }
    }

    fn check_time(&self, t_s: f64) -> Result<(), EvaluationError> {
        if !t_s.is_finite() {
            return Err(EvaluationError::Time { t_s });
        }
        if let Some((previous_s, _, _)) = self.log.previous {
            if t_s < previous_s {
                return Err(EvaluationError::TimeOrder { t_s, previous_s });
            }
        }
        Ok(())
    }
}

/// Median (mean of the two middle values for an even count) and maximum; NaN for none.
fn median_and_max(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let mut v: Vec<f64> = values.collect();
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    (median, v[n - 1])
}

#[cfg(test)]
mod tests {
    use super::*;

    const CLASSES: [&str; 2] = ["tps_bias", "wattmeter"];

    /// A hand-built case whose answers are counted by hand in the comments.
    #[test]
    fn figures_of_a_hand_built_case() {
        let mut ev = Evaluator::new(&CLASSES);
        // Log 1: 10 fault-free samples at 1 s, flagged at t = 3 and 4 (one false alarm, two
        // flagged samples), then tps_bias from t = 10 to 19, flagged from t = 12 with scores
        // 0.75 on tps_bias; a correct DTC at t = 14.
        ev.start_log();
        for k in 0..10 {
            let t = k as f64;
            ev.sample(t, Truth::FaultFree, k == 3 || k == 4, &[0.0, 0.0])
                .unwrap();
        }
        for k in 10..20 {
            let t = k as f64;
            ev.sample(t, Truth::Faulty(0), k >= 12, &[0.75, 0.25])
                .unwrap();
            if k == 14 {
                ev.dtc(t, &[0], DtcKind::Specific).unwrap();
            }
        }
        // Log 2: wattmeter from the start (t = 0..4), flagged at t = 2..4 with score 0.5 on
        // it, and a wrong DTC (tps_bias) at t = 3; then 5 fault-free samples (t = 5..9) with a
        // false DTC at t = 8; time restarts at 0 in a new log.
        ev.start_log();
        for k in 0..5 {
            let t = k as f64;
            ev.sample(t, Truth::Faulty(1), k >= 2, &[0.5, 0.5]).unwrap();
            if k == 3 {
                ev.dtc(t, &[0], DtcKind::Specific).unwrap();
            }
        }
        for k in 5..10 {
            let t = k as f64;
            ev.sample(t, Truth::FaultFree, false, &[0.0, 0.0]).unwrap();
            if k == 8 {
                ev.dtc(t, &[], DtcKind::Specific).unwrap();
            }
        }
        // An ignored sample changes nothing.
        ev.sample(10.0, Truth::Ignored, true, &[1.0, 0.0]).unwrap();
        let r = ev.report();
        assert_eq!(r.logs, 2);
        // Faulty: 10 + 5 = 15, flagged 8 + 3 = 11. Fault-free: 10 + 5 = 15, flagged 2.
        assert_eq!((r.faulty_samples, r.faulty_flagged), (15, 11));
        assert_eq!((r.fault_free_samples, r.fault_free_flagged), (15, 2));
        assert!((r.tdr - 11.0 / 15.0).abs() < 1e-12);
        assert!((r.far - 2.0 / 15.0).abs() < 1e-12);
        // FIA: (8 * 0.75 + 3 * 0.5) / 11.
        assert!((r.fia - 7.5 / 11.0).abs() < 1e-12);
        // Fault-free time: 9 s in log 1, 4 s in log 2.
        assert!((r.fault_free_hours - 13.0 / 3600.0).abs() < 1e-15);
        assert_eq!((r.false_alarms, r.false_dtcs), (1, 1));
        assert!((r.false_alarms_per_hour - 3600.0 / 13.0).abs() < 1e-9);
        let tps = &r.classes[0];
        assert_eq!(
            (tps.episodes, tps.detected, tps.correct_dtc, tps.wrong_dtc),
            (1, 1, 1, 0)
        );
        assert_eq!(tps.median_detection_delay_s, 2.0);
        assert_eq!(tps.worst_dtc_delay_s, 4.0);
        let watt = &r.classes[1];
        assert_eq!(
            (
                watt.episodes,
                watt.detected,
                watt.correct_dtc,
                watt.wrong_dtc
            ),
            (1, 1, 0, 1)
        );
        assert_eq!(watt.correct_dtc_rate, 0.0);
        assert_eq!(watt.median_detection_delay_s, 2.0);
        assert!(watt.median_dtc_delay_s.is_nan());
    }

    #[test]
    fn a_dtc_before_the_fault_is_observable_counts_for_its_episode() {
        let mut ev = Evaluator::new(&["tps_stuck", "plate"]);
        // Log 1: fault-free 0..4; the fault present without effect at 5..6, where the correct
        // DTC is raised (t = 5.5); observable from 7 to 9.
        for k in 0..5 {
            ev.sample(k as f64, Truth::FaultFree, false, &[0.0, 0.0])
                .unwrap();
        }
        ev.sample(5.0, Truth::Ignored, true, &[1.0, 0.0]).unwrap();
        ev.dtc(5.5, &[0], DtcKind::Specific).unwrap();
        ev.sample(6.0, Truth::Ignored, true, &[1.0, 0.0]).unwrap();
        for k in 7..10 {
            ev.sample(k as f64, Truth::Faulty(0), true, &[1.0, 0.0])
                .unwrap();
        }
        // Log 2: a DTC during a settling margin that fault-free samples follow counts nowhere,
        // and does not carry over to the next episode.
        ev.start_log();
        ev.sample(0.0, Truth::Ignored, false, &[0.0, 0.0]).unwrap();
        ev.dtc(0.5, &[1], DtcKind::Specific).unwrap();
        ev.sample(1.0, Truth::FaultFree, false, &[0.0, 0.0])
            .unwrap();
        ev.sample(2.0, Truth::Faulty(1), false, &[0.0, 0.0])
            .unwrap();
        let r = ev.report();
        assert_eq!(r.false_dtcs, 0);
        let stuck = &r.classes[0];
        assert_eq!(
            (stuck.episodes, stuck.any_dtc, stuck.correct_dtc),
            (1, 1, 1)
        );
        assert_eq!(stuck.median_dtc_delay_s, 0.0);
        let plate = &r.classes[1];
        assert_eq!((plate.episodes, plate.any_dtc), (1, 0));
    }

    #[test]
    fn group_then_specific_dtcs_are_counted_per_episode() {
        let mut ev = Evaluator::new(&["map_bias", "leak", "egr"]);
        // Episode 1 (leak, t = 0..9): a group DTC naming {leak, egr} at t = 1, the specific leak
        // DTC at t = 4. Episode 2 (map_bias, t = 20..29, after fault-free 10..19): a group DTC
        // naming {leak, egr} at t = 21 (misses the truth), a wrong specific DTC (egr) at t = 23.
        for k in 0..30 {
            let t = f64::from(k);
            let truth = match k {
                0..=9 => Truth::Faulty(1),
                10..=19 => Truth::FaultFree,
                _ => Truth::Faulty(0),
            };
            ev.sample(t, truth, !(10..=19).contains(&k), &[0.0; 3])
                .unwrap();
            match k {
                1 | 21 => ev.dtc(t, &[1, 2], DtcKind::Group).unwrap(),
                4 => ev.dtc(t, &[1], DtcKind::Specific).unwrap(),
                23 => ev.dtc(t, &[2], DtcKind::Specific).unwrap(),
                _ => {}
            }
        }
        let r = ev.report();
        let leak = &r.classes[1];
        assert_eq!(
            (
                leak.any_dtc,
                leak.group_dtc,
                leak.group_missed,
                leak.correct_dtc
            ),
            (1, 1, 0, 1)
        );
        assert_eq!(leak.median_any_dtc_delay_s, 1.0);
        assert_eq!(leak.median_dtc_delay_s, 4.0);
        let map = &r.classes[0];
        assert_eq!(
            (
                map.any_dtc,
                map.group_dtc,
                map.group_missed,
                map.correct_dtc,
                map.wrong_dtc
            ),
            (1, 1, 1, 0, 1)
        );
        assert_eq!(map.worst_any_dtc_delay_s, 1.0);
        assert!(map.median_dtc_delay_s.is_nan());
        assert_eq!(r.false_dtcs, 0);
        assert!(matches!(
            ev.dtc(30.0, &[3], DtcKind::Group),
            Err(EvaluationError::Class { index: 3, .. })
        ));
    }

    #[test]
    fn episodes_split_on_a_class_change_and_delays_take_the_median() {
        let mut ev = Evaluator::new(&CLASSES);
        // Three tps_bias episodes separated by fault-free samples, detected after 1, 3 and 2 s;
        // then a wattmeter episode right after a tps_bias one (no fault-free sample between).
        let mut t = 0.0;
        for delay in [1.0, 3.0, 2.0] {
            ev.sample(t, Truth::FaultFree, false, &[0.0, 0.0]).unwrap();
            t += 1.0;
            let onset = t;
            for _ in 0..5 {
                ev.sample(t, Truth::Faulty(0), t - onset >= delay, &[1.0, 0.0])
                    .unwrap();
                t += 1.0;
            }
        }
        ev.sample(t, Truth::Faulty(1), false, &[0.0, 0.0]).unwrap();
        let r = ev.report();
        assert_eq!(r.classes[0].episodes, 3);
        assert_eq!(r.classes[0].median_detection_delay_s, 2.0);
        assert_eq!(r.classes[0].worst_detection_delay_s, 3.0);
        assert_eq!(r.classes[1].episodes, 1);
        assert_eq!(r.classes[1].detected, 0);
        assert_eq!(r.classes[1].detection_rate, 0.0);
        assert_eq!(r.fia, 1.0);
    }

    #[test]
    fn bad_samples_are_refused_and_count_nothing() {
        let mut ev = Evaluator::new(&CLASSES);
        ev.sample(1.0, Truth::FaultFree, false, &[0.0, 0.0])
            .unwrap();
        assert!(matches!(
            ev.sample(2.0, Truth::FaultFree, false, &[0.0]),
            Err(EvaluationError::ScoreCount { got: 1, .. })
        ));
        let e = ev
            .sample(2.0, Truth::Faulty(0), true, &[1.5, 0.0])
            .unwrap_err();
        assert!(e.to_string().contains("tps_bias"), "{e}");
        assert!(matches!(
            ev.sample(2.0, Truth::Faulty(2), true, &[0.0, 0.0]),
            Err(EvaluationError::Class { index: 2, .. })
        ));
        assert!(matches!(
            ev.sample(0.5, Truth::FaultFree, false, &[0.0, 0.0]),
            Err(EvaluationError::TimeOrder { .. })
        ));
        assert!(ev
            .sample(f64::NAN, Truth::FaultFree, false, &[0.0, 0.0])
            .is_err());
        assert!(ev.dtc(2.0, &[5], DtcKind::Specific).is_err());
        let r = ev.report();
        assert_eq!((r.fault_free_samples, r.faulty_samples), (1, 0));
        assert!(r.tdr.is_nan());
    }
}
