//! `fdd simulate`: scenario file (throttle or intake) -> truth simulation with sensors and an
//! injected fault -> MCAP.

use std::path::{Path, PathBuf};

use fdd_fixtures::scenario::ScenarioError;
use fdd_fixtures::scenario_file::{AnyScenario, FixtureError};
use fdd_fixtures::throttle_log::{LogStats, FIXTURE_WRITE_OPTIONS};
use fdd_monitor::log::{LogError, LogWriter};

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

/// Runs the scenario named or located by `scenario` and writes its log to `out` with the
/// fixture writer settings (so `fdd simulate throttle_nominal -o x.mcap` reproduces
/// `fixtures/data/throttle_nominal.mcap`, and `fdd simulate intake_leak -o x.mcap`
/// `fixtures/data/intake_leak.mcap`, byte for byte).
pub fn simulate(scenario: &str, out: &Path) -> Result<LogStats, SimulateError> {
    let (sc, source) = find_scenario(scenario)?;
    if let ScenarioSource::File(f) = &source {
        let same = matches!((f.canonicalize(), out.canonicalize()), (Ok(a), Ok(b)) if a == b);
        if same {
            return Err(SimulateError::OutputIsScenario {
                out: out.to_path_buf(),
            });
        }
    }
    let writer = LogWriter::create_with(out, FIXTURE_WRITE_OPTIONS)?;
    let (_, stats) = sc.write_log(writer)?;
    Ok(stats)
}
