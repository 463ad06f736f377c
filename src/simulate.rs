//! `fdd simulate`: scenario file (throttle or intake) -> truth simulation with sensors and an
//! injected fault -> MCAP.

use std::path::{Path, PathBuf};

use fdd_fixtures::scenario::ScenarioError;
use fdd_fixtures::scenario_file::{AnyScenario, AnySim, FixtureError};
use fdd_fixtures::throttle_log::{LogStats, FIXTURE_WRITE_OPTIONS};
use fdd_fixtures::{intake_log, throttle_log};
use fdd_monitor::log::{LogError, LogWriter};

/// Longest simulation `fdd simulate` (and `evaluate`, `calibrate` on scenario files) runs
/// without `--allow-long` (s): 24 h. A throttle hour is about 3.6 million samples and 170 MB
/// of log, so a day is already 4 GB; a longer `duration_s` is more likely a typo than meant.
/// Scenario files cannot ask for more than
/// [`fdd_fixtures::scenario::MAX_DURATION_S`] (30 days) at all.
pub const MAX_SIMULATE_S: f64 = 86_400.0;

/// How to simulate.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimulateOptions {
    /// Simulate scenarios longer than [`MAX_SIMULATE_S`] (`--allow-long`).
    pub allow_long: bool,
}

/// Why a simulation could not be written.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    #[error("no scenario `{name}`: not a file ({tried}), and not a bundled scenario (`fdd simulate --list`: {known})")]
    UnknownScenario {
        name: String,
        tried: String,
        known: String,
    },
    #[error("{}: refusing to write the log over its own scenario file", out.display())]
    OutputIsScenario { out: PathBuf },
    #[error("{}: refusing to write an MCAP log to a .toml file (a scenario or configuration file's name); give the log a .mcap name", out.display())]
    OutputIsToml { out: PathBuf },
    #[error("{origin}: duration_s = {duration_s:?} s is longer than the {max_s:?} s (24 h) fdd simulates without --allow-long (a throttle hour is about 170 MB of log); pass --allow-long to simulate it anyway")]
    TooLong {
        origin: String,
        duration_s: f64,
        max_s: f64,
    },
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error(transparent)]
    Fixture(#[from] FixtureError),
    #[error(transparent)]
    Log(#[from] LogError),
}

/// Where a scenario was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScenarioSource {
    /// A file (the argument, or `<argument>.toml`), relative to the working directory.
    File(PathBuf),
    /// One of the scenarios embedded in the binary ([`fdd_fixtures::bundled::BUNDLED`]).
    Bundled(&'static str),
}

impl ScenarioSource {
    /// How errors name the scenario: the file's path, or `bundled scenario NAME`.
    pub fn origin(&self) -> String {
        match self {
            Self::File(f) => f.display().to_string(),
            Self::Bundled(name) => format!("bundled scenario {name}"),
        }
    }
}

/// Finds a scenario (throttle or intake): the argument as a path (relative to the working
/// directory), the same with `.toml` appended, or the name of a scenario bundled in the binary
/// (the committed `fixtures/scenarios`, so a name works wherever fdd is installed).
pub fn find_scenario(arg: &str) -> Result<(AnyScenario, ScenarioSource), SimulateError> {
    let path = Path::new(arg);
    if path.is_file() {
        return Ok((AnyScenario::load(path)?, ScenarioSource::File(path.into())));
    }
    let with_ext = PathBuf::from(format!("{arg}.toml"));
    if with_ext.is_file() {
        return Ok((
            AnyScenario::load(&with_ext)?,
            ScenarioSource::File(with_ext),
        ));
    }
    if let Some((name, text)) = fdd_fixtures::bundled::BUNDLED
        .iter()
        .find(|(n, _)| *n == arg)
    {
        let origin = format!("bundled scenario {name}");
        return Ok((
            AnyScenario::parse(text, &origin)?,
            ScenarioSource::Bundled(name),
        ));
    }
    Err(SimulateError::UnknownScenario {
        name: arg.to_string(),
        tried: format!("{arg}, {}", with_ext.display()),
        known: fdd_fixtures::bundled::BUNDLED
            .iter()
            .map(|(n, _)| *n)
            .collect::<Vec<_>>()
            .join(", "),
    })
}

/// One line per bundled scenario: name, monitor, duration and fault.
pub fn list_bundled() -> Result<String, SimulateError> {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<28} {:<8} {:>10}  fault",
        "scenario", "monitor", "duration"
    );
    for (name, text) in fdd_fixtures::bundled::BUNDLED {
        let sc = AnyScenario::parse(text, name)?;
        let fault = match sc.fault_start_s() {
            Some(t) => format!("{} from {t} s", sc.fault_name()),
            None => sc.fault_name().to_string(),
        };
        let _ = writeln!(
            out,
            "{:<28} {:<8} {:>8} s  {fault}",
            name,
            sc.monitor().name(),
            sc.duration_s()
        );
    }
    Ok(out)
}

/// Refuses the scenario named or located by `scenario` when it is longer than
/// [`MAX_SIMULATE_S`] and `opts.allow_long` is not set (what [`simulate`] checks first), without
/// simulating it.
pub fn check_length(scenario: &Path, opts: &SimulateOptions) -> Result<(), SimulateError> {
    let (sc, source) = find_scenario(&scenario.to_string_lossy())?;
    if sc.duration_s() > MAX_SIMULATE_S && !opts.allow_long {
        return Err(SimulateError::TooLong {
            origin: source.origin(),
            duration_s: sc.duration_s(),
            max_s: MAX_SIMULATE_S,
        });
    }
    Ok(())
}

/// Runs the scenario named or located by `scenario` and writes its log to `out` with the
/// fixture writer settings (so `fdd simulate throttle_nominal -o x.mcap` reproduces
/// `fixtures/data/throttle_nominal.mcap`, and `fdd simulate intake_leak -o x.mcap`
/// `fixtures/data/intake_leak.mcap`, byte for byte).
///
/// Refuses, before writing anything: an output that is the scenario file itself (compared as
/// files: the same canonical path, or the same file through a hard link) or any `.toml` path
/// (a bundled scenario's source file, a configuration); a scenario longer than
/// [`MAX_SIMULATE_S`] unless `opts.allow_long`; a scenario whose simulator cannot be built.
pub fn simulate(
    scenario: &str,
    out: &Path,
    opts: &SimulateOptions,
) -> Result<LogStats, SimulateError> {
    let (sc, source) = find_scenario(scenario)?;
    if let ScenarioSource::File(f) = &source {
        if crate::paths::same_file(f, out) {
            return Err(SimulateError::OutputIsScenario {
                out: out.to_path_buf(),
            });
        }
    }
    let origin = source.origin();
    if out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
    {
        return Err(SimulateError::OutputIsToml {
            out: out.to_path_buf(),
        });
    }
    if sc.duration_s() > MAX_SIMULATE_S && !opts.allow_long {
        return Err(SimulateError::TooLong {
            origin,
            duration_s: sc.duration_s(),
            max_s: MAX_SIMULATE_S,
        });
    }
    // Built before the output is created, so a scenario the simulator refuses leaves no file.
    let sim = sc.simulator(&origin)?;
    let writer = LogWriter::create_with(out, FIXTURE_WRITE_OPTIONS)?;
    let (_, stats) = match sim {
        AnySim::Throttle(sim) => throttle_log::write_log(*sim, writer)?,
        AnySim::Intake(sim) => intake_log::write_log(*sim, writer)?,
    };
    Ok(stats)
}
