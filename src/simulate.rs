//! `fdd simulate`: scenario file -> truth simulation with sensors and an injected fault -> MCAP.

use std::path::{Path, PathBuf};

use fdd_fixtures::scenario::{Scenario, ScenarioError};
use fdd_fixtures::throttle_log::{write_log, LogStats, FIXTURE_WRITE_OPTIONS};
use fdd_fixtures::throttle_sim::{PlantError, SimError, ThrottlePlant, ThrottleSim};
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
    Plant(#[from] PlantError),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Log(#[from] LogError),
}

/// Finds a scenario by path, or by name among the committed scenarios.
pub fn find_scenario(arg: &str) -> Result<Scenario, SimulateError> {
    let path = Path::new(arg);
    if path.is_file() {
        return Ok(Scenario::load(path)?);
    }
    let dir = Scenario::committed_dir();
    let candidate: PathBuf = dir.join(format!("{arg}.toml"));
    if candidate.is_file() {
        return Ok(Scenario::load(&candidate)?);
    }
    let known = Scenario::load_dir(dir)
        .map(|all| {
            all.iter()
                .map(|s| s.name.clone())
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
/// `fixtures/data/throttle_nominal.mcap` byte for byte).
pub fn simulate(scenario: &str, out: &Path) -> Result<LogStats, SimulateError> {
    let sc = find_scenario(scenario)?;
    let plant = ThrottlePlant::from_default_config()?;
    let sim = ThrottleSim::new(&sc, &plant)?;
    let writer = LogWriter::create_with(out, FIXTURE_WRITE_OPTIONS)?;
    let (_, stats) = write_log(sim, writer)?;
    Ok(stats)
}
