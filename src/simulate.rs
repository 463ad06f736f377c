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
    #[error("no scenario `{name}`: not a file, and not in {dir} (known: {known})")]
    UnknownScenario {
        name: String,
        dir: String,
        known: String,
    },
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error(transparent)]
    Fixture(#[from] FixtureError),
    #[error(transparent)]
    Log(#[from] LogError),
}

/// Finds a scenario (throttle or intake) by path, or by name among the committed scenarios.
pub fn find_scenario(arg: &str) -> Result<AnyScenario, SimulateError> {
    let path = Path::new(arg);
    if path.is_file() {
        return Ok(AnyScenario::load(path)?);
    }
    let dir = AnyScenario::committed_dir();
    let candidate: PathBuf = dir.join(format!("{arg}.toml"));
    if candidate.is_file() {
        return Ok(AnyScenario::load(&candidate)?);
    }
    let known = AnyScenario::load_dir(dir)
        .map(|all| {
            all.iter()
                .map(|s| s.name().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        })
        .unwrap_or_default();
    Err(SimulateError::UnknownScenario {
        name: arg.to_string(),
        dir: dir.display().to_string(),
        known,
    })
}

/// Runs the scenario named or located by `scenario` and writes its log to `out` with the
/// fixture writer settings (so `fdd simulate throttle_nominal -o x.mcap` reproduces
/// `fixtures/data/throttle_nominal.mcap`, and `fdd simulate intake_leak -o x.mcap`
/// `fixtures/data/intake_leak.mcap`, byte for byte).
pub fn simulate(scenario: &str, out: &Path) -> Result<LogStats, SimulateError> {
    let sc = find_scenario(scenario)?;
    let writer = LogWriter::create_with(out, FIXTURE_WRITE_OPTIONS)?;
    let (_, stats) = sc.write_log(writer)?;
    Ok(stats)
}
