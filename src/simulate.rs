//! `fdd simulate`: scenario file (throttle or intake) -> truth simulation with sensors and an
//! injected fault -> MCAP.
//!
//! Turbo scenarios (`monitor = "turbo"`, [`fdd_fixtures::turbo_scenario`]) take their own
//! branch ([`simulate_turbo`]): a file, a bundled turbo fixture's name (`turbo_leak_ic`), a
//! directory of turbo scenario files, or a generated set (`turbo_tuning`, `turbo_heldout`);
//! a directory or a set is written as one log per scenario into the `-o` directory.
//!
//! Wheel scenarios (`monitor = "wheel"`, [`fdd_fixtures::wheel_scenario`]) likewise
//! ([`simulate_wheel`]): a file or a directory of wheel scenario files (no wheel fixtures are
//! bundled yet). A directory holds turbo or wheel scenarios, not both.

use std::path::{Path, PathBuf};

use fdd_fixtures::scenario::ScenarioError;
use fdd_fixtures::scenario_file::{AnyScenario, AnySim, FixtureError};
use fdd_fixtures::throttle_log::{LogStats, FIXTURE_WRITE_OPTIONS};
use fdd_fixtures::turbo_scenario::{SetKind, TurboScenario};
use fdd_fixtures::turbo_sim::{TurboSim, TurboSimError};
use fdd_fixtures::wheel_log::WheelLogError;
use fdd_fixtures::wheel_scenario::WheelScenario;
use fdd_fixtures::wheel_sim::{WheelSim, WheelSimError};
use fdd_fixtures::{
    intake_log, throttle_log, turbo_log, turbo_scenario, wheel_log, wheel_scenario,
};
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
    #[error(transparent)]
    TurboSim(#[from] TurboSimError),
    #[error(transparent)]
    WheelSim(#[from] WheelSimError),
    #[error(transparent)]
    WheelLog(#[from] WheelLogError),
    #[error("{}: cannot create the output directory: {source}", out.display())]
    OutputDir {
        out: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: no turbo or wheel scenario file (monitor = \"turbo\" or \"wheel\") in this directory", dir.display())]
    NoTurboScenarios { dir: PathBuf },
    #[error("{}: the directory holds both turbo and wheel scenario files; simulate them from separate directories", dir.display())]
    MixedScenarios { dir: PathBuf },
    #[error("{}: refusing to write the logs of several scenarios into a .mcap path: give -o a directory", out.display())]
    OutputNotDirectory { out: PathBuf },
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
    for (name, text) in turbo_scenario::BUNDLED {
        let sc = TurboScenario::parse(text, name)?;
        let fault = match sc.fault.fault {
            fdd_fixtures::turbo_faults::TurboFault::None => "none".to_string(),
            f => format!("{} from {} s", f.truth_name(), sc.fault.start_s),
        };
        let _ = writeln!(
            out,
            "{:<28} {:<8} {:>8} s  {fault}",
            name, "turbo", sc.duration_s
        );
    }
    for (name, text) in wheel_scenario::BUNDLED {
        let sc = WheelScenario::parse(text, name)?;
        let fault = match sc.fault.fault {
            fdd_fixtures::wheel_faults::WheelFault::None => "none".to_string(),
            _ => format!("{} from {} s", sc.fault.truth_name(), sc.fault.start_s),
        };
        let _ = writeln!(
            out,
            "{:<28} {:<8} {:>8} s  {fault}",
            name, "wheel", sc.duration_s
        );
    }
    let _ = writeln!(
        out,
        "{:<28} {:<8} {:>10}  generated set: -o names a directory",
        SetKind::Tuning.name(),
        "turbo",
        ""
    );
    let _ = writeln!(
        out,
        "{:<28} {:<8} {:>10}  generated set: -o names a directory",
        SetKind::HeldOut.name(),
        "turbo",
        ""
    );
    Ok(out)
}

/// Refuses the scenario named or located by `scenario` when it is longer than
/// [`MAX_SIMULATE_S`] and `opts.allow_long` is not set (what [`simulate`] checks first), without
/// simulating it.
pub fn check_length(scenario: &Path, opts: &SimulateOptions) -> Result<(), SimulateError> {
    if let Some(wheel) = find_wheel(&scenario.to_string_lossy())? {
        let list = match wheel {
            WheelInput::One {
                scenario, origin, ..
            } => vec![(*scenario, origin)],
            WheelInput::Many(list) => list,
        };
        for (sc, origin) in list {
            too_long(sc.duration_s, &origin, opts)?;
        }
        return Ok(());
    }
    if let Some(turbo) = find_turbo(&scenario.to_string_lossy())? {
        let list = match turbo {
            TurboInput::One {
                scenario, origin, ..
            } => vec![(*scenario, origin)],
            TurboInput::Many(list) => list,
        };
        for (sc, origin) in list {
            if sc.duration_s > MAX_SIMULATE_S && !opts.allow_long {
                return Err(SimulateError::TooLong {
                    origin,
                    duration_s: sc.duration_s,
                    max_s: MAX_SIMULATE_S,
                });
            }
        }
        return Ok(());
    }
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
    if let Some(wheel) = find_wheel(scenario)? {
        return simulate_wheel(wheel, out, opts);
    }
    if let Some(turbo) = find_turbo(scenario)? {
        return simulate_turbo(turbo, out, opts);
    }
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

/// Turbo scenarios found for an argument of `fdd simulate`.
#[derive(Debug)]
pub enum TurboInput {
    /// One scenario (a file or a bundled fixture), with how errors name it and its file.
    One {
        scenario: Box<TurboScenario>,
        origin: String,
        file: Option<PathBuf>,
    },
    /// Several (a directory or a generated set): one log each, into a directory.
    Many(Vec<(TurboScenario, String)>),
}

/// The turbo scenarios `arg` names, if it names any: a generated set's name
/// ([`SetKind::parse`]), a directory (its `.toml` files that say `monitor = "turbo"`), a file
/// (or the name with `.toml`) that says `monitor = "turbo"`, or a bundled turbo fixture's name.
/// `None` for everything else (throttle and intake scenarios take the other branch).
pub fn find_turbo(arg: &str) -> Result<Option<TurboInput>, SimulateError> {
    let path = Path::new(arg);
    if path.is_dir() {
        let (turbo, wheel) = scan_dir(path)?;
        if turbo.is_empty() {
            if wheel.is_empty() {
                return Err(SimulateError::NoTurboScenarios { dir: path.into() });
            }
            // A directory of wheel scenarios: the wheel branch's ([`find_wheel`]).
            return Ok(None);
        }
        if !wheel.is_empty() {
            return Err(SimulateError::MixedScenarios { dir: path.into() });
        }
        let mut many = Vec::new();
        for f in turbo {
            many.push((TurboScenario::load(&f)?, f.display().to_string()));
        }
        return Ok(Some(TurboInput::Many(many)));
    }
    let with_ext = PathBuf::from(format!("{arg}.toml"));
    for f in [path, with_ext.as_path()] {
        if f.is_file() {
            let text = fdd_monitor::text_file::read_text(f).map_err(ScenarioError::from)?;
            if !turbo_scenario::is_turbo_text(&text) {
                return Ok(None);
            }
            return Ok(Some(TurboInput::One {
                scenario: Box::new(TurboScenario::load(f)?),
                origin: f.display().to_string(),
                file: Some(f.to_path_buf()),
            }));
        }
    }
    if let Some(kind) = SetKind::parse(arg) {
        let many = turbo_scenario::generate_set(kind)
            .into_iter()
            .map(|sc| {
                let origin = format!("generated set {} scenario {}", kind.name(), sc.name);
                (sc, origin)
            })
            .collect();
        return Ok(Some(TurboInput::Many(many)));
    }
    if let Some((name, text)) = turbo_scenario::BUNDLED.iter().find(|(n, _)| *n == arg) {
        let origin = format!("bundled scenario {name}");
        return Ok(Some(TurboInput::One {
            scenario: Box::new(TurboScenario::parse(text, &origin)?),
            origin,
            file: None,
        }));
    }
    Ok(None)
}

/// The `.toml` files of a directory that say `monitor = "turbo"` and `monitor = "wheel"`,
/// each sorted by name.
fn scan_dir(path: &Path) -> Result<(Vec<PathBuf>, Vec<PathBuf>), SimulateError> {
    let origin = path.display().to_string();
    let read_err = |source| ScenarioError::Read {
        origin: origin.clone(),
        source,
    };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(path).map_err(read_err)? {
        let p = entry.map_err(read_err)?.path();
        if p.extension().is_some_and(|e| e == "toml") {
            files.push(p);
        }
    }
    files.sort();
    let (mut turbo, mut wheel) = (Vec::new(), Vec::new());
    for f in files {
        let text = fdd_monitor::text_file::read_text(&f).map_err(ScenarioError::from)?;
        if turbo_scenario::is_turbo_text(&text) {
            turbo.push(f);
        } else if wheel_scenario::is_wheel_text(&text) {
            wheel.push(f);
        }
    }
    Ok((turbo, wheel))
}

/// Simulates one turbo scenario into the log `out`.
fn simulate_one_turbo(
    sc: &TurboScenario,
    origin: &str,
    out: &Path,
    opts: &SimulateOptions,
) -> Result<LogStats, SimulateError> {
    if sc.duration_s > MAX_SIMULATE_S && !opts.allow_long {
        return Err(SimulateError::TooLong {
            origin: origin.to_string(),
            duration_s: sc.duration_s,
            max_s: MAX_SIMULATE_S,
        });
    }
    // Built before the output is created, so a scenario the simulator refuses leaves no file.
    let sim = TurboSim::from_scenario(sc, origin)?;
    let writer = LogWriter::create_with(out, FIXTURE_WRITE_OPTIONS)?;
    let (_, stats) = turbo_log::write_log(sim, writer)?;
    Ok(stats)
}

/// The turbo branch of [`simulate`]: one scenario into the log `out` (the same refusals as
/// the other monitors' scenarios), or several into the directory `out` (created if needed),
/// as `out/<name>.mcap`, simulated in parallel on the machine's cores; the stats are summed.
pub fn simulate_turbo(
    input: TurboInput,
    out: &Path,
    opts: &SimulateOptions,
) -> Result<LogStats, SimulateError> {
    match input {
        TurboInput::One {
            scenario,
            origin,
            file,
        } => {
            check_single_out(file.as_deref(), out)?;
            simulate_one_turbo(&scenario, &origin, out, opts)
        }
        TurboInput::Many(list) => simulate_many(
            &list,
            out,
            opts,
            |sc| sc.name.as_str(),
            |sc| sc.duration_s,
            |sc, origin, file| simulate_one_turbo(sc, origin, file, opts),
        ),
    }
}

/// Refuses a scenario longer than [`MAX_SIMULATE_S`] unless `opts.allow_long`.
fn too_long(duration_s: f64, origin: &str, opts: &SimulateOptions) -> Result<(), SimulateError> {
    if duration_s > MAX_SIMULATE_S && !opts.allow_long {
        return Err(SimulateError::TooLong {
            origin: origin.to_string(),
            duration_s,
            max_s: MAX_SIMULATE_S,
        });
    }
    Ok(())
}

/// Refuses to write one scenario's log over its own scenario file or into a `.toml` path.
fn check_single_out(file: Option<&Path>, out: &Path) -> Result<(), SimulateError> {
    if let Some(f) = file {
        if crate::paths::same_file(f, out) {
            return Err(SimulateError::OutputIsScenario {
                out: out.to_path_buf(),
            });
        }
    }
    if out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
    {
        return Err(SimulateError::OutputIsToml {
            out: out.to_path_buf(),
        });
    }
    Ok(())
}

/// Simulates every `(scenario, origin)` of `list` into `out/<name>.mcap` with `one`, in
/// parallel on the machine's cores, after the checks of a directory output (not a `.mcap` or
/// `.toml` path, every scenario within [`MAX_SIMULATE_S`] unless allowed; the directory is
/// created); the stats are summed.
fn simulate_many<T: Sync>(
    list: &[(T, String)],
    out: &Path,
    opts: &SimulateOptions,
    name: impl Fn(&T) -> &str + Sync,
    duration_s: impl Fn(&T) -> f64,
    one: impl Fn(&T, &str, &Path) -> Result<LogStats, SimulateError> + Sync,
) -> Result<LogStats, SimulateError> {
    if out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap") || e.eq_ignore_ascii_case("toml"))
    {
        return Err(SimulateError::OutputNotDirectory {
            out: out.to_path_buf(),
        });
    }
    for (sc, origin) in list {
        too_long(duration_s(sc), origin, opts)?;
    }
    std::fs::create_dir_all(out).map_err(|source| SimulateError::OutputDir {
        out: out.to_path_buf(),
        source,
    })?;
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(list.len().max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<Result<LogStats, SimulateError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                scope.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some((sc, origin)) = list.get(i) else {
                            break;
                        };
                        tracing::info!("[{}/{}] {}", i + 1, list.len(), name(sc));
                        let file = out.join(format!("{}.mcap", name(sc)));
                        mine.push(one(sc, origin, &file));
                    }
                    mine
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    });
    let mut total = LogStats {
        frames: 0,
        messages: 0,
    };
    for r in results {
        let s = r?;
        total.frames += s.frames;
        total.messages += s.messages;
    }
    Ok(total)
}

/// Wheel scenarios found for an argument of `fdd simulate`.
#[derive(Debug)]
pub enum WheelInput {
    /// One scenario (a file or a bundled fixture), with how errors name it and its file.
    One {
        scenario: Box<WheelScenario>,
        origin: String,
        file: Option<PathBuf>,
    },
    /// Several (a directory): one log each, into a directory.
    Many(Vec<(WheelScenario, String)>),
}

/// The wheel scenarios `arg` names, if it names any: a directory whose `.toml` files say
/// `monitor = "wheel"` (and none `monitor = "turbo"`), a file (or the name with `.toml`) that
/// says `monitor = "wheel"`, or a bundled wheel fixture's name
/// ([`wheel_scenario::BUNDLED`], empty so far). `None` for everything else.
pub fn find_wheel(arg: &str) -> Result<Option<WheelInput>, SimulateError> {
    let path = Path::new(arg);
    if path.is_dir() {
        let (turbo, wheel) = scan_dir(path)?;
        if wheel.is_empty() {
            return Ok(None);
        }
        if !turbo.is_empty() {
            return Err(SimulateError::MixedScenarios { dir: path.into() });
        }
        let mut many = Vec::new();
        for f in wheel {
            many.push((WheelScenario::load(&f)?, f.display().to_string()));
        }
        return Ok(Some(WheelInput::Many(many)));
    }
    let with_ext = PathBuf::from(format!("{arg}.toml"));
    for f in [path, with_ext.as_path()] {
        if f.is_file() {
            let text = fdd_monitor::text_file::read_text(f).map_err(ScenarioError::from)?;
            if !wheel_scenario::is_wheel_text(&text) {
                return Ok(None);
            }
            return Ok(Some(WheelInput::One {
                scenario: Box::new(WheelScenario::load(f)?),
                origin: f.display().to_string(),
                file: Some(f.to_path_buf()),
            }));
        }
    }
    if let Some((name, text)) = wheel_scenario::BUNDLED.iter().find(|(n, _)| *n == arg) {
        let origin = format!("bundled scenario {name}");
        return Ok(Some(WheelInput::One {
            scenario: Box::new(WheelScenario::parse(text, &origin)?),
            origin,
            file: None,
        }));
    }
    Ok(None)
}

/// Simulates one wheel scenario into the log `out` (the simulator is built before the file is
/// created, so a scenario it refuses leaves no file).
fn simulate_one_wheel(
    sc: &WheelScenario,
    origin: &str,
    out: &Path,
    opts: &SimulateOptions,
) -> Result<LogStats, SimulateError> {
    too_long(sc.duration_s, origin, opts)?;
    let sim = WheelSim::from_scenario(sc, origin)?;
    let writer = LogWriter::create_with(out, FIXTURE_WRITE_OPTIONS)?;
    let (_, stats) = wheel_log::write_log(sim, writer)?;
    Ok(stats)
}

/// The wheel branch of [`simulate`]: one scenario into the log `out` (the same refusals as the
/// other monitors' scenarios), or several into the directory `out`, as `out/<name>.mcap`,
/// in parallel.
pub fn simulate_wheel(
    input: WheelInput,
    out: &Path,
    opts: &SimulateOptions,
) -> Result<LogStats, SimulateError> {
    match input {
        WheelInput::One {
            scenario,
            origin,
            file,
        } => {
            check_single_out(file.as_deref(), out)?;
            simulate_one_wheel(&scenario, &origin, out, opts)
        }
        WheelInput::Many(list) => simulate_many(
            &list,
            out,
            opts,
            |sc| sc.name.as_str(),
            |sc| sc.duration_s,
            |sc, origin, file| simulate_one_wheel(sc, origin, file, opts),
        ),
    }
}
