//! Latest value and timestamp per named signal, with staleness detection.
//!
//! Monitors do not read logs or buses: the host (or the replay) pushes timestamped samples into
//! the table, and monitors read the latest value of the signals they declared. Names are the
//! runtime's own (`motor_voltage`, `tps`, ...); the mapping from a log's topics and fields to
//! these names lives in the configuration, so a differently named log replays without code
//! changes.
//!
//! The table refuses samples that would corrupt it (non-finite values, time going backwards,
//! repeated timestamps) and says why; the caller counts and reports them and carries on.

use std::fmt;

/// Index of a signal in its table (cheap to copy; resolve names once at start-up).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SignalId(usize);

impl SignalId {
    /// Position of the signal in the table.
    pub fn index(self) -> usize {
        self.0
    }

    /// The id at position `index` (a host that keeps ids as integers, as the C ABI does); the
    /// runtime refuses an index outside its table.
    pub fn from_index(index: usize) -> Self {
        SignalId(index)
    }
}

/// One signal's declaration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SignalSpec {
    /// Runtime name, e.g. `tps`.
    pub name: String,
    /// A signal whose latest sample is older than this is stale (ns).
    pub max_age_ns: u64,
}

/// A value with its timestamp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub value: f64,
    pub t_ns: u64,
}

/// Why a sample was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SampleError {
    /// NaN or infinite value.
    #[error("non-finite value")]
    NonFinite,
    /// Earlier than the signal's latest sample.
    #[error("timestamp goes backwards ({t_ns} ns after {last_ns} ns)")]
    Backwards { t_ns: u64, last_ns: u64 },
    /// Same timestamp as the signal's latest sample.
    #[error("timestamp repeats ({t_ns} ns)")]
    Repeated { t_ns: u64 },
}

/// Why the table could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TableError {
    #[error("signal `{0}` is declared twice")]
    Duplicate(String),
    #[error("signal `{0}` has max_age_ns = 0: it would always be stale")]
    ZeroAge(String),
}

/// The table. Storage is sized at construction; `set` and `get` never allocate.
#[derive(Debug, Clone)]
pub struct SignalTable {
    specs: Vec<SignalSpec>,
    latest: Vec<Option<Sample>>,
}

impl SignalTable {
    /// A table of the named signals, all lost after `max_age_ns` (a test or a host whose
    /// signals share one rate).
    pub fn with_names(names: &[&str], max_age_ns: u64) -> Result<Self, TableError> {
        Self::new(
            names
                .iter()
                .map(|n| SignalSpec {
                    name: (*n).to_string(),
                    max_age_ns,
                })
                .collect(),
        )
    }

    /// Builds a table of the given signals.
    pub fn new(specs: Vec<SignalSpec>) -> Result<Self, TableError> {
        for (i, s) in specs.iter().enumerate() {
            if specs[..i].iter().any(|o| o.name == s.name) {
                return Err(TableError::Duplicate(s.name.clone()));
            }
            if s.max_age_ns == 0 {
                return Err(TableError::ZeroAge(s.name.clone()));
            }
        }
        let latest = vec![None; specs.len()];
        Ok(Self { specs, latest })
    }

    /// The id of a signal by name.
    pub fn id(&self, name: &str) -> Option<SignalId> {
        self.specs.iter().position(|s| s.name == name).map(SignalId)
    }

    /// Number of signals.
    pub fn len(&self) -> usize {
        self.specs.len()
    }

    /// True when the table has no signal.
    pub fn is_empty(&self) -> bool {
        self.specs.is_empty()
    }

    /// Declaration of a signal.
    pub fn spec(&self, id: SignalId) -> &SignalSpec {
        &self.specs[id.0]
    }

    /// Stores a sample, unless it is non-finite or not newer than the latest one (the table
    /// then keeps what it had).
    pub fn set(&mut self, id: SignalId, t_ns: u64, value: f64) -> Result<(), SampleError> {
        if !value.is_finite() {
            return Err(SampleError::NonFinite);
        }
        if let Some(last) = self.latest[id.0] {
            if t_ns < last.t_ns {
                return Err(SampleError::Backwards {
                    t_ns,
                    last_ns: last.t_ns,
                });
            }
            if t_ns == last.t_ns {
                return Err(SampleError::Repeated { t_ns });
            }
        }
        self.latest[id.0] = Some(Sample { value, t_ns });
        Ok(())
    }

    /// Latest sample, if any arrived.
    pub fn get(&self, id: SignalId) -> Option<Sample> {
        self.latest[id.0]
    }

    /// Latest sample, if any arrived; `None` also for an id of another table.
    pub fn try_get(&self, id: SignalId) -> Option<Sample> {
        self.latest.get(id.0).copied().flatten()
    }

    /// Latest value if the signal is fresh at `now_ns` (not stale, and not from the future).
    pub fn fresh(&self, id: SignalId, now_ns: u64) -> Option<f64> {
        match self.latest[id.0] {
            Some(s) if s.t_ns <= now_ns && now_ns - s.t_ns <= self.specs[id.0].max_age_ns => {
                Some(s.value)
            }
            _ => None,
        }
    }

    /// True when the signal has a sample but it is older than its `max_age_ns` at `now_ns`.
    /// A signal that never arrived is "missing", reported by [`SignalTable::missing`].
    pub fn is_stale(&self, id: SignalId, now_ns: u64) -> bool {
        matches!(self.latest[id.0], Some(s) if now_ns > s.t_ns && now_ns - s.t_ns > self.specs[id.0].max_age_ns)
    }

    /// True when no sample of the signal has arrived yet.
    pub fn missing(&self, id: SignalId) -> bool {
        self.latest[id.0].is_none()
    }

    /// All ids, in declaration order.
    pub fn ids(&self) -> impl Iterator<Item = SignalId> + '_ {
        (0..self.specs.len()).map(SignalId)
    }
}

impl fmt::Display for SignalId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "signal #{}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_from_names_shares_one_age_and_refuses_a_repeated_name() {
        let t = SignalTable::with_names(&["map", "maf"], 7).expect("table");
        assert!(t.id("map").is_some() && t.id("maf").is_some() && t.id("tps").is_none());
        assert!(matches!(
            SignalTable::with_names(&["map", "map"], 7),
            Err(TableError::Duplicate(n)) if n == "map"
        ));
        assert!(matches!(
            SignalTable::with_names(&["map"], 0),
            Err(TableError::ZeroAge(_))
        ));
    }

    fn table() -> SignalTable {
        SignalTable::new(vec![
            SignalSpec {
                name: "tps".into(),
                max_age_ns: 5_000_000,
            },
            SignalSpec {
                name: "motor_voltage".into(),
                max_age_ns: 5_000_000,
            },
        ])
        .expect("valid")
    }

    #[test]
    fn keeps_latest_and_detects_staleness() {
        let mut t = table();
        let tps = t.id("tps").expect("declared");
        assert!(t.missing(tps));
        assert!(!t.is_stale(tps, 10));
        t.set(tps, 1_000_000, 2.5).expect("fresh");
        t.set(tps, 2_000_000, 2.6).expect("fresh");
        assert_eq!(
            t.get(tps),
            Some(Sample {
                value: 2.6,
                t_ns: 2_000_000
            })
        );
        assert_eq!(t.fresh(tps, 7_000_000), Some(2.6));
        assert!(!t.is_stale(tps, 7_000_000));
        assert!(t.is_stale(tps, 7_000_001));
        assert_eq!(t.fresh(tps, 7_000_001), None);
        assert_eq!(t.id("nope"), None);
    }

    #[test]
    fn refuses_bad_samples_and_keeps_state() {
        let mut t = table();
        let tps = t.id("tps").expect("declared");
        t.set(tps, 1_000, 1.0).expect("first");
        assert_eq!(t.set(tps, 2_000, f64::NAN), Err(SampleError::NonFinite));
        assert_eq!(
            t.set(tps, 2_000, f64::INFINITY),
            Err(SampleError::NonFinite)
        );
        assert_eq!(
            t.set(tps, 500, 1.5),
            Err(SampleError::Backwards {
                t_ns: 500,
                last_ns: 1_000
            })
        );
        assert_eq!(
            t.set(tps, 1_000, 1.5),
            Err(SampleError::Repeated { t_ns: 1_000 })
        );
        assert_eq!(
            t.get(tps),
            Some(Sample {
                value: 1.0,
                t_ns: 1_000
            })
        );
    }

    #[test]
    fn rejects_bad_declarations() {
        let dup = vec![
            SignalSpec {
                name: "a".into(),
                max_age_ns: 1,
            },
            SignalSpec {
                name: "a".into(),
                max_age_ns: 1,
            },
        ];
        assert_eq!(
            SignalTable::new(dup).unwrap_err(),
            TableError::Duplicate("a".into())
        );
        let zero = vec![SignalSpec {
            name: "a".into(),
            max_age_ns: 0,
        }];
        assert_eq!(
            SignalTable::new(zero).unwrap_err(),
            TableError::ZeroAge("a".into())
        );
    }
}
