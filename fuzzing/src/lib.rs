//! The bodies of fdd's fuzz targets, one function per input fdd accepts from a user.
//!
//! `fuzz/` (a cargo-fuzz crate outside the workspace, built with nightly and libFuzzer) calls
//! each function from a one-line target; `tests/corpora.rs` calls the same functions, on
//! stable, on every committed corpus input and every input that once crashed a target
//! (`fuzz/regressions/<target>/`), so a fixed defect stays fixed without a fuzzer.
//!
//! Every function takes arbitrary bytes and must return without panicking, hanging or growing
//! memory beyond what the input's size explains; the errors fdd reports for bad input are the
//! expected outcome and are dropped. Where two paths of fdd must agree (the fast JSON field
//! lookup and serde_json), the function asserts it, so a disagreement is a crash too.

use std::cell::RefCell;
use std::io::Write;
use std::path::{Path, PathBuf};

use fdd_monitor::log::{json_field_f64, FieldLookupError, LogReader, ReadOptions};
use fdd_monitor::runtime::{Runtime, RuntimeConfig, Stamped};

pub mod seeds;

/// A target's body: arbitrary bytes in, what it made of them out.
pub type Target = fn(&[u8]) -> Outcome;

/// The fuzz targets, by name (the names of `fuzz/fuzz_targets/*.rs` and of the corpus
/// directories), with their bodies.
pub const TARGETS: &[(&str, Target)] = &[
    ("mcap_reader", mcap_reader),
    ("json_field", json_field),
    ("runtime_config", runtime_config),
    ("throttle_config", throttle_config),
    ("intake_config", intake_config),
    ("scenario", scenario),
    ("replay", replay),
];

/// What a target made of an input: refused (an error fdd reports, the expected outcome for
/// most mutated inputs) or accepted and run through. The fuzzer ignores it; the corpus test
/// checks that the seeds are accepted, so a harness that refuses everything is caught.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    Refused,
    Accepted,
}

/// Simulated time a configuration target drives a runtime for, ns (0.3 s: several hundred
/// throttle steps and a few dozen intake steps, enough to run every test once).
pub const DRIVE_NS: u64 = 300_000_000;

/// Longest scenario the `scenario` target simulates, s; longer ones are only parsed and
/// validated (a valid 24-hour scenario is not a defect, just slow).
pub const MAX_SIMULATED_S: f64 = 1.0;

thread_local! {
    /// One scratch directory per thread, reused for every input (the reader and the replay
    /// take a path).
    static SCRATCH: RefCell<Option<PathBuf>> = const { RefCell::new(None) };
}

/// A per-thread scratch file `name` holding `bytes`.
fn scratch_file(name: &str, bytes: &[u8]) -> PathBuf {
    SCRATCH.with(|s| {
        let mut s = s.borrow_mut();
        let dir = s.get_or_insert_with(|| {
            let d = std::env::temp_dir().join(format!(
                "fdd-fuzz-{}-{:?}",
                std::process::id(),
                std::thread::current().id()
            ));
            // The harness's own scratch space: failing to make it is an environment problem,
            // not an input the target judges.
            std::fs::create_dir_all(&d).expect("cannot create the fuzz scratch directory");
            d
        });
        let p = dir.join(name);
        let mut f = std::fs::File::create(&p).expect("cannot create a fuzz scratch file");
        f.write_all(bytes)
            .expect("cannot write a fuzz scratch file");
        p
    })
}

/// Reads every message of an MCAP file the way `fdd replay` does (indexed when the summary is
/// usable, linear otherwise), once with the default options and once with CRC validation and
/// a topic filter, looking up a numeric field and decoding each message.
pub fn mcap_reader(data: &[u8]) -> Outcome {
    let path = scratch_file("in.mcap", data);
    let first = read_all(&path, ReadOptions::default());
    let _ = read_all(
        &path,
        ReadOptions {
            validate_crcs: true,
            topics: Some(vec!["/throttle/tps".into(), "/intake/map".into()]),
            ..ReadOptions::default()
        },
    );
    first
}

/// Accepted: opened, and every item read was a message.
fn read_all(path: &Path, options: ReadOptions) -> Outcome {
    let Ok(mut reader) = LogReader::open_with(path, options) else {
        return Outcome::Refused;
    };
    let mut outcome = Outcome::Accepted;
    let _ = (
        reader.message_count(),
        reader.time_range_ns(),
        reader.mode(),
    );
    let _ = reader.channels().count();
    // The reader yields at most one item per message or per bad chunk; a bound far above what
    // a fuzz input can hold still turns a reader that never ends into a failure.
    let bound = 64 * data_len(path) + 1024;
    let mut items = 0u64;
    while let Some(item) = reader.next_message() {
        items += 1;
        assert!(
            items <= bound,
            "the reader yielded more than {bound} items from a {} byte file",
            data_len(path)
        );
        match item {
            Ok(m) => {
                let _ = m.field_f64("voltage_v");
                let _ = m.field_f64("test_result.value");
                let _ = m.json();
            }
            Err(e) => {
                outcome = Outcome::Refused;
                if e.is_fatal() {
                    break;
                }
            }
        }
    }
    let _ = reader.stats();
    outcome
}

fn data_len(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}

/// The JSON field lookup the runtime maps signals with: the first byte is the length of the
/// field path (at most 31), the next bytes the path, the rest the JSON text. Besides not
/// panicking, the lookup must agree with serde_json on whether the text is JSON at all (but
/// for numbers beyond f64's range, which `Value` refuses), and on the number found where the
/// path's key occurs once in the text.
pub fn json_field(data: &[u8]) -> Outcome {
    let Some((&n, rest)) = data.split_first() else {
        return Outcome::Refused;
    };
    let n = usize::from(n & 31).min(rest.len());
    let (path, json) = rest.split_at(n);
    let Ok(path) = std::str::from_utf8(path) else {
        return Outcome::Refused;
    };
    let found = json_field_f64(json, path);
    let value: Result<serde_json::Value, _> = serde_json::from_slice(json);
    // A number beyond f64's range (`5e324`) is valid JSON that serde_json's `Value` cannot
    // hold; the lookup reads past it when it is not on the path, as serde_json itself does
    // when it skips a value.
    if value
        .as_ref()
        .is_err_and(|e| e.to_string().starts_with("number out of range"))
    {
        return if found.is_ok() {
            Outcome::Accepted
        } else {
            Outcome::Refused
        };
    }
    match (&value, &found) {
        (Err(_), Ok(x)) => panic!("invalid JSON read as {x} at {path:?}"),
        (Ok(_), Err(FieldLookupError::Json(e))) => panic!("valid JSON refused: {e}"),
        _ => {}
    }
    let outcome = if found.is_ok() {
        Outcome::Accepted
    } else {
        Outcome::Refused
    };
    let Ok(value) = value else { return outcome };
    // serde_json's Value keeps the last of duplicate keys, the lookup the first: compare only
    // where every key on the path occurs once in the text.
    let once = |k: &str| {
        let quoted = format!("\"{k}\"");
        json.windows(quoted.len())
            .filter(|w| *w == quoted.as_bytes())
            .count()
            == 1
    };
    if path.is_empty() || !path.split('.').all(once) {
        return outcome;
    }
    let mut v = &value;
    for k in path.split('.') {
        match v.get(k) {
            Some(inner) => v = inner,
            None => return outcome,
        }
    }
    let expected = match v {
        serde_json::Value::Number(x) => x.as_f64(),
        serde_json::Value::Null => Some(f64::NAN),
        _ => None,
    };
    if let (Some(e), Ok(x)) = (expected, &found) {
        assert!(
            e.to_bits() == x.to_bits() || (e.is_nan() && x.is_nan()),
            "{path:?}: lookup {x:?}, serde_json {e:?}"
        );
    }
    if expected.is_some() {
        assert!(found.is_ok(), "{path:?}: lookup {found:?}, serde_json {v}");
    }
    outcome
}

/// A runtime configuration (`config/fdd.toml`) as text: loaded, and if accepted, a runtime
/// built from it driven with samples on every signal for [`DRIVE_NS`].
pub fn runtime_config(data: &[u8]) -> Outcome {
    let Ok(text) = std::str::from_utf8(data) else {
        return Outcome::Refused;
    };
    match RuntimeConfig::parse(text, "fuzz/fdd.toml") {
        Ok(cfg) => drive(&cfg),
        Err(_) => Outcome::Refused,
    }
}

/// A throttle configuration (`config/throttle.toml`) as a file beside a runtime configuration
/// that names it; accepted ones drive a runtime for [`DRIVE_NS`].
pub fn throttle_config(data: &[u8]) -> Outcome {
    monitor_config(data, "throttle")
}

/// An intake configuration (`config/intake.toml`), as [`throttle_config`].
pub fn intake_config(data: &[u8]) -> Outcome {
    monitor_config(data, "intake")
}

fn monitor_config(data: &[u8], monitor: &str) -> Outcome {
    let file = scratch_file(&format!("{monitor}.toml"), data);
    let runtime = format!(
        "{}\n[monitors]\nthrottle = true\nintake = true\n{monitor}_config = {:?}\n",
        fdd_signals_toml(),
        file.display().to_string()
    );
    match RuntimeConfig::parse(&runtime, "fuzz/fdd.toml") {
        Ok(cfg) => drive(&cfg),
        Err(_) => Outcome::Refused,
    }
}

/// The `[[signals]]` and `[staleness]` tables of the embedded runtime configuration (every
/// table before `[monitors]`).
fn fdd_signals_toml() -> &'static str {
    let text = fdd_monitor::runtime::config::DEFAULT_RUNTIME_TOML;
    text.find("\n[monitors]").map_or(text, |i| &text[..i])
}

/// Builds the runtime of `cfg` and, if it builds, pushes a plausible sample on every signal
/// each millisecond and advances, for [`DRIVE_NS`].
fn drive(cfg: &RuntimeConfig) -> Outcome {
    let Ok(mut rt) = Runtime::new(cfg) else {
        return Outcome::Refused;
    };
    let ids: Vec<_> = cfg
        .signals
        .iter()
        .filter_map(|s| rt.signal(&s.name))
        .collect();
    let mut sink = |_: Stamped<'_>| {};
    if rt.start_operation_cycle(0, &mut sink).is_err() {
        return Outcome::Refused;
    }
    let mut t = 1_000_000u64;
    while t <= DRIVE_NS {
        for (i, &id) in ids.iter().enumerate() {
            let x = 0.5 + 0.1 * (((t / 1_000_000) as f64) * 0.01 + i as f64).sin();
            let _ = rt.push(id, t, x);
        }
        if rt.advance_to(t, &mut sink).is_err() {
            return Outcome::Refused;
        }
        t += 1_000_000;
    }
    let _ = rt.dtcs_by_status_mask(0xFF).count();
    let _ = rt.end_operation_cycle(t, &mut sink);
    Outcome::Accepted
}

/// A scenario file as `fdd simulate` reads it; a valid one of at most [`MAX_SIMULATED_S`] is
/// simulated into an in-memory log.
pub fn scenario(data: &[u8]) -> Outcome {
    let Ok(text) = std::str::from_utf8(data) else {
        return Outcome::Refused;
    };
    let Ok(s) = fdd_fixtures::scenario_file::AnyScenario::parse(text, "fuzz/scenario.toml") else {
        return Outcome::Refused;
    };
    if !(s.duration_s() <= MAX_SIMULATED_S) {
        return Outcome::Accepted;
    }
    let Ok(w) = fdd_monitor::log::LogWriter::with_options(
        std::io::Cursor::new(Vec::new()),
        "fuzz.mcap",
        fdd_monitor::log::WriteOptions::default(),
    ) else {
        return Outcome::Refused;
    };
    match s.write_log(w) {
        Ok(_) => Outcome::Accepted,
        Err(_) => Outcome::Refused,
    }
}

/// A log replayed end to end through the embedded default configuration, as `fdd replay` does,
/// and its summary rendered.
pub fn replay(data: &[u8]) -> Outcome {
    let path = scratch_file("replay.mcap", data);
    let Ok(cfg) = RuntimeConfig::embedded() else {
        return Outcome::Refused;
    };
    match fdd::replay::replay(&path, &cfg, &fdd::replay::ReplayOptions::default()) {
        Ok(summary) => {
            let _ = summary.render();
            Outcome::Accepted
        }
        Err(_) => Outcome::Refused,
    }
}
