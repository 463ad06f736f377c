//! Fault isolation over a fault signature matrix.
//!
//! Rows are residual tests, columns are faults. An entry says how the test reacts to the fault:
//! `1` it reacts (if the fault is present the test fires), `0` it cannot react, `X` it may react
//! (depending on size, operating point or timing). Given the verdicts of the tests, a fault stays
//! a candidate when
//! - no test that fired has a `0` for it (the fault cannot explain that test), and
//! - no test that passed has a `1` for it (the fault would have fired it: exoneration).
//!
//! Only qualified verdicts are evidence: `Failed` counts as fired and `Passed` as not fired.
//! `NotTested` (enable conditions false) and the unqualified `PreFailed`/`PrePassed` are no
//! evidence at all, so a test that has not run yet can neither accuse nor exonerate.
//!
//! Candidates are ranked by the share of fired tests their column explains with a `1` (an `X`
//! explains half), best first. When at least one test fired and no column is consistent, the
//! answer is "unknown fault": the pattern is outside the modelled faults.
//!
//! Single-fault isolation, as for the OBD monitors here; multiple simultaneous faults show up as
//! "unknown" unless one column covers the union of their patterns.

use serde::Deserialize;

use crate::error::ConfigError;
use crate::verdict::Verdict;

/// How a test reacts to a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sensitivity {
    /// `0`: the test cannot react to the fault.
    No,
    /// `1`: the test reacts to the fault.
    Yes,
    /// `X`: the test may react.
    May,
}

/// Configuration: test names, fault names and one row string per test, entries separated by
/// whitespace, each `0`, `1` or `X`. Example (TOML):
///
/// ```toml
/// tests = ["r_position", "r_wattmeter", "r_both"]
/// faults = ["position_sensor", "wattmeter", "plate_stuck"]
/// rows = ["1 0 X",
///         "0 1 1",
///         "1 1 1"]
/// ```
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SignatureConfig {
    pub tests: Vec<String>,
    pub faults: Vec<String>,
    pub rows: Vec<String>,
}

/// A validated fault signature matrix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SignatureMatrix {
    tests: Vec<String>,
    faults: Vec<String>,
    /// Row-major, `tests.len() x faults.len()`.
    entries: Vec<Sensitivity>,
}

/// One ranked candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// Column index of the fault in the matrix.
    pub fault: usize,
    /// Share (0..1) of the fired tests that the fault's column explains (`1` counts 1, `X` 0.5).
    pub score: f64,
}

/// Outcome of one isolation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Diagnosis {
    /// No test has fired.
    NoFault,
    /// Tests fired and at least one fault explains them (see the candidate list).
    Isolated,
    /// Tests fired and no modelled fault explains the pattern.
    Unknown,
}

/// Ranked candidates, reused from step to step (storage sized once for the matrix's faults).
#[derive(Debug, Clone, PartialEq)]
pub struct Candidates {
    list: Vec<Candidate>,
    diagnosis: Diagnosis,
}

impl Candidates {
    /// Empty storage for `matrix`; pass it to [`SignatureMatrix::isolate`].
    pub fn for_matrix(matrix: &SignatureMatrix) -> Self {
        Self {
            list: Vec::with_capacity(matrix.faults.len()),
            diagnosis: Diagnosis::NoFault,
        }
    }

    /// The verdict of the last isolation.
    pub fn diagnosis(&self) -> Diagnosis {
        self.diagnosis
    }

    /// Consistent faults, best first (empty for `NoFault` and `Unknown`).
    pub fn ranked(&self) -> &[Candidate] {
        &self.list
    }

    /// The best candidate, if any.
    pub fn top(&self) -> Option<Candidate> {
        self.list.first().copied()
    }
}

impl SignatureMatrix {
    /// Parses and validates a configuration; errors name the offending field (`rows[1]`, ...).
    pub fn new(cfg: &SignatureConfig) -> Result<Self, ConfigError> {
        if cfg.tests.is_empty() {
            return Err(ConfigError::new(
                "tests",
                "[]",
                "at least one test is needed",
            ));
        }
        if cfg.faults.is_empty() {
            return Err(ConfigError::new(
                "faults",
                "[]",
                "at least one fault is needed",
            ));
        }
        for (field, names) in [("tests", &cfg.tests), ("faults", &cfg.faults)] {
            for (i, n) in names.iter().enumerate() {
                if names[..i].contains(n) {
                    return Err(ConfigError::new(
                        format!("{field}[{i}]"),
                        n,
                        "duplicate name",
                    ));
                }
            }
        }
        if cfg.rows.len() != cfg.tests.len() {
            return Err(ConfigError::new(
                "rows",
                cfg.rows.len(),
                format!("need one row per test ({} tests)", cfg.tests.len()),
            ));
        }
        let mut entries = Vec::with_capacity(cfg.tests.len() * cfg.faults.len());
        for (r, row) in cfg.rows.iter().enumerate() {
            let field = format!("rows[{r}]");
            let cells: Vec<&str> = row.split_whitespace().collect();
            if cells.len() != cfg.faults.len() {
                return Err(ConfigError::new(
                    field,
                    format!("{row:?}"),
                    format!("need {} entries, one per fault", cfg.faults.len()),
                ));
            }
            for cell in cells {
                entries.push(match cell {
                    "0" => Sensitivity::No,
                    "1" => Sensitivity::Yes,
                    "X" | "x" => Sensitivity::May,
                    other => {
                        return Err(ConfigError::new(
                            field,
                            format!("{other:?}"),
                            "entries must be 0, 1 or X",
                        ))
                    }
                });
            }
        }
        let m = Self {
            tests: cfg.tests.clone(),
            faults: cfg.faults.clone(),
            entries,
        };
        for f in 0..m.faults.len() {
            if (0..m.tests.len()).all(|t| m.entry(t, f) == Sensitivity::No) {
                return Err(ConfigError::new(
                    format!("faults[{f}]"),
                    &m.faults[f],
                    "no test reacts to this fault: it can never be detected",
                ));
            }
        }
        Ok(m)
    }

    /// Entry for test `t` and fault `f`.
    pub fn entry(&self, t: usize, f: usize) -> Sensitivity {
        self.entries[t * self.faults.len() + f]
    }

    /// Test names (rows).
    pub fn tests(&self) -> &[String] {
        &self.tests
    }

    /// Fault names (columns).
    pub fn faults(&self) -> &[String] {
        &self.faults
    }

    /// Fault name of a candidate.
    pub fn fault_name(&self, c: &Candidate) -> &str {
        &self.faults[c.fault]
    }

    /// Isolates from one verdict per test (same order as the rows) into `out`. Extra or missing
    /// verdicts are treated as `NotTested`. Allocates nothing once `out` is sized for this matrix.
    pub fn isolate(&self, verdicts: &[Verdict], out: &mut Candidates) {
        out.list.clear();
        let nt = self.tests.len();
        let verdict = |t: usize| verdicts.get(t).copied().unwrap_or(Verdict::NotTested);
        let fired = (0..nt).filter(|&t| verdict(t) == Verdict::Failed).count();
        if fired == 0 {
            out.diagnosis = Diagnosis::NoFault;
            return;
        }
        for f in 0..self.faults.len() {
            let mut explained = 0.0;
            let mut consistent = true;
            for t in 0..nt {
                match (verdict(t), self.entry(t, f)) {
                    (Verdict::Failed, Sensitivity::No) | (Verdict::Passed, Sensitivity::Yes) => {
                        consistent = false;
                        break;
                    }
                    (Verdict::Failed, Sensitivity::Yes) => explained += 1.0,
                    (Verdict::Failed, Sensitivity::May) => explained += 0.5,
                    _ => {}
                }
            }
            if consistent {
                out.list.push(Candidate {
                    fault: f,
                    score: explained / fired as f64,
                });
            }
        }
        // Stable insertion sort: ties keep the configured fault order, and no allocation.
        for i in 1..out.list.len() {
            let mut j = i;
            while j > 0 && out.list[j - 1].score < out.list[j].score {
                out.list.swap(j - 1, j);
                j -= 1;
            }
        }
        out.diagnosis = if out.list.is_empty() {
            Diagnosis::Unknown
        } else {
            Diagnosis::Isolated
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Verdict::{Failed as F, NotTested as N, Passed as P, PreFailed as PF};

    /// Three residuals, four faults: sensor A, sensor B, actuator, and a leak that only the
    /// third residual sees; the actuator may or may not disturb residual 3.
    fn matrix() -> SignatureMatrix {
        SignatureMatrix::new(&SignatureConfig {
            tests: vec!["r1".into(), "r2".into(), "r3".into()],
            faults: vec![
                "sensor_a".into(),
                "sensor_b".into(),
                "actuator".into(),
                "leak".into(),
            ],
            rows: vec!["1 0 1 0".into(), "0 1 1 0".into(), "1 1 X 1".into()],
        })
        .expect("valid")
    }

    fn isolate(v: &[Verdict]) -> (Diagnosis, Vec<String>) {
        let m = matrix();
        let mut out = Candidates::for_matrix(&m);
        m.isolate(v, &mut out);
        let names = out
            .ranked()
            .iter()
            .map(|c| m.fault_name(c).to_string())
            .collect();
        (out.diagnosis(), names)
    }

    #[test]
    fn every_single_fault_pattern_isolates_to_its_fault() {
        let m = matrix();
        for f in 0..m.faults().len() {
            // The fault's own pattern, with X read both ways.
            for x_fires in [false, true] {
                let v: Vec<Verdict> = (0..m.tests().len())
                    .map(|t| match m.entry(t, f) {
                        Sensitivity::Yes => F,
                        Sensitivity::No => P,
                        Sensitivity::May => {
                            if x_fires {
                                F
                            } else {
                                P
                            }
                        }
                    })
                    .collect();
                let (d, names) = isolate(&v);
                assert_eq!(d, Diagnosis::Isolated, "{v:?}");
                assert_eq!(names[0], m.faults()[f], "pattern {v:?} ranked {names:?}");
            }
        }
    }

    #[test]
    fn unexplained_pattern_is_unknown_and_silence_is_no_fault() {
        // r1 alone fired: sensor A would also have fired r3, the actuator r2; nobody else can
        // fire r1. No column explains it.
        assert_eq!(isolate(&[F, P, P]).0, Diagnosis::Unknown);
        assert!(isolate(&[F, P, P]).1.is_empty());
        // r1 and r2 fired, r3 passed: the actuator, whose r3 entry is X.
        assert_eq!(isolate(&[F, F, P]).1, vec!["actuator"]);
        assert_eq!(isolate(&[P, P, P]).0, Diagnosis::NoFault);
        assert_eq!(isolate(&[]).0, Diagnosis::NoFault);
    }

    #[test]
    fn untested_and_unqualified_verdicts_are_no_evidence() {
        // Only r3 fired so far; r1, r2 not run: every fault with 1 or X on r3 stays a candidate,
        // ranked 1 before X.
        let (d, names) = isolate(&[N, N, F]);
        assert_eq!(d, Diagnosis::Isolated);
        assert_eq!(names, vec!["sensor_a", "sensor_b", "leak", "actuator"]);
        // A PreFailed r1 neither accuses nor exonerates.
        assert_eq!(isolate(&[PF, N, F]).1, names);
        // Once r1 passes, sensor A and the actuator (which would have fired it) are exonerated.
        assert_eq!(isolate(&[P, N, F]).1, vec!["sensor_b", "leak"]);
    }

    #[test]
    fn bad_matrices_name_the_field() {
        let good = SignatureConfig {
            tests: vec!["r1".into(), "r2".into()],
            faults: vec!["a".into(), "b".into()],
            rows: vec!["1 0".into(), "0 1".into()],
        };
        let err = |cfg: SignatureConfig| SignatureMatrix::new(&cfg).unwrap_err().field;
        assert_eq!(
            err(SignatureConfig {
                rows: vec!["1 0".into()],
                ..good.clone()
            }),
            "rows"
        );
        assert_eq!(
            err(SignatureConfig {
                rows: vec!["1 0".into(), "0 1 1".into()],
                ..good.clone()
            }),
            "rows[1]"
        );
        assert_eq!(
            err(SignatureConfig {
                rows: vec!["1 2".into(), "0 1".into()],
                ..good.clone()
            }),
            "rows[0]"
        );
        assert_eq!(
            err(SignatureConfig {
                rows: vec!["1 0".into(), "0 0".into()],
                ..good.clone()
            }),
            "faults[1]"
        );
        assert_eq!(
            err(SignatureConfig {
                faults: vec!["a".into(), "a".into()],
                ..good.clone()
            }),
            "faults[1]"
        );
        assert_eq!(
            err(SignatureConfig {
                tests: vec![],
                ..good
            }),
            "tests"
        );
    }
}
