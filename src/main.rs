//! `fdd`: command-line front end of the fault-detection and diagnosis library.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::{ArgAction, Parser, Subcommand};
use fdd::config::ThrottleConfig;
use fdd::limits;
use fdd::replay::{ReplayOptions, RuntimeConfig};
use fdd::reproduce::{intake, table2, turbo, wheel};
use tracing_subscriber::EnvFilter;

#[derive(Parser)]
#[command(
    name = "fdd",
    version,
    about = "Onboard fault detection and diagnosis: model-based residuals, tests and DTCs"
)]
struct Cli {
    /// More log output on stderr: -v info, -vv debug, -vvv trace (default: warnings only).
    /// RUST_LOG, when set, overrides this (e.g. RUST_LOG=fdd=debug,fdd_monitor=info).
    #[arg(short, long, action = ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a throttle, intake or turbo scenario (truth, sensors, injected fault) and write
    /// it as an MCAP log, with the settings of the committed fixtures (same scenario, same
    /// bytes).
    Simulate {
        /// Scenario: a path to a scenario TOML file, relative to the working directory (its
        /// `monitor` key says throttle, intake or turbo; `.toml` may be left off), the name of a
        /// scenario bundled in fdd (`--list` shows them: e.g. `throttle_tps_stuck`,
        /// `intake_leak`), or, for turbo scenarios, a directory of them or a generated set
        /// (`turbo_tuning`, `turbo_heldout`; `-o` is then a directory).
        #[arg(required_unless_present = "list")]
        scenario: Option<String>,
        /// Output MCAP file.
        #[arg(short, long, required_unless_present = "list")]
        out: Option<PathBuf>,
        /// List the bundled scenarios (name, monitor, duration, fault) and exit.
        #[arg(long, conflicts_with_all = ["scenario", "out"])]
        list: bool,
        /// Simulate a scenario longer than 24 h (a throttle day is about 4 GB of log).
        #[arg(long)]
        allow_long: bool,
    },
    /// Replay an MCAP log through the configured monitors: DTC events, estimates, a summary.
    ///
    /// Streams the log in log-time order, maps its topics to signals as configured, runs every
    /// monitor, writes the outputs asked for and prints a summary table (DTCs raised with times;
    /// with ground truth, detection delays and estimate error). Bad messages are counted and
    /// skipped; the exit status is non-zero only when the log cannot be read to its end (the
    /// summary of what was read is printed first), not a single message of it can be read
    /// (every chunk failed to decode), or an output cannot be written. No output (`--out`,
    /// `--events`, the `--memory` slots) may be the log, the configuration or another output.
    Replay {
        /// The MCAP log.
        log: PathBuf,
        /// Runtime configuration (default: the embedded config/fdd.toml).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Write the monitor outputs (estimates, innovations, tests, DTC status, events) to
        /// this MCAP file.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write the diagnostic events to this file, one JSON object per line.
        #[arg(long)]
        events: Option<PathBuf>,
        /// Write every sample the monitors received to this CSV file (`t_ns,signal,value`, in
        /// the order pushed): the input of a host without an MCAP reader (examples/c/host.c).
        #[arg(long, value_name = "FILE")]
        samples: Option<PathBuf>,
        /// No progress bar (it is only drawn when stderr is a terminal anyway).
        #[arg(long)]
        no_progress: bool,
        /// Keep the event memory (status bytes, counters, freeze frames) in the slot files
        /// FILE.a / FILE.b: restored before the replay, written at its end, so consecutive
        /// replays are consecutive operation cycles (a DTC failing in two logs is confirmed).
        #[arg(long, value_name = "FILE")]
        memory: Option<PathBuf>,
    },
    /// Score the monitors on logs with ground truth: TDR, FAR and FIA (the DX'25 diagnostic
    /// competition's definitions), and per fault type the detection rate, the DTC rates and
    /// the median and worst delays; false alarms per hour of fault-free time.
    ///
    /// Each input is an MCAP log with truth topics, a scenario file (.toml, simulated first
    /// into a temporary log), or a directory of them (its .mcap and .toml files).
    Evaluate {
        /// Logs, scenario files or directories.
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// Runtime configuration (default: the embedded config/fdd.toml).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print the figures as JSON instead of tables.
        #[arg(long)]
        json: bool,
        /// Simulate scenario files longer than 24 h.
        #[arg(long)]
        allow_long: bool,
    },
    /// Calibrate the throttle, the intake or the air-path monitor on fault-free logs of one
    /// plant: its sensors' noise levels, its model (throttle), correction range (intake) or
    /// offset map and residual scales (turbo), and every residual test's threshold for a
    /// false-alarm rate (extreme-value fit to block maxima). Writes DIR/fdd.toml and
    /// DIR/throttle.toml, DIR/intake.toml or DIR/turbo.toml (with its parameter file) for
    /// `fdd replay --config DIR/fdd.toml`. Refuses logs with a fault in them, or too short for
    /// the rate asked.
    Calibrate {
        /// Fault-free logs, scenario files or directories.
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// Directory to write the calibrated configuration to.
        #[arg(short, long)]
        out: PathBuf,
        /// Runtime configuration to start from (default: the embedded config/fdd.toml).
        #[arg(long)]
        config: Option<PathBuf>,
        /// False alarms per hour of each test (above 0, at most 3600). Throttle and intake only:
        /// the air-path monitor's thresholds are a margin on the largest fault-free value.
        #[arg(long, default_value_t = 1e-3, allow_negative_numbers = true, value_parser = |s: &str| limits::CALIBRATE_RATE.parse(s))]
        false_alarms_per_hour: f64,
        /// Length of the blocks whose maxima are fitted (s, 0.1 to 86400).
        #[arg(long, default_value_t = 10.0, allow_negative_numbers = true, value_parser = |s: &str| limits::CALIBRATE_BLOCK.parse(s))]
        block_s: f64,
        /// Keep the starting configuration's throttle model instead of re-identifying it.
        #[arg(long)]
        keep_model: bool,
        /// The monitor to calibrate (`throttle`, `intake` or `turbo`); default: the one the inputs are
        /// for (a scenario's `monitor` key, the monitor whose topics a log carries).
        #[arg(long)]
        monitor: Option<String>,
        /// Simulate scenario files longer than 24 h.
        #[arg(long)]
        allow_long: bool,
    },
    /// Convert a CSV log (one row per sample time) to an MCAP log fdd replays, as a mapping
    /// file says: the time column and its unit, and per output topic the columns it carries
    /// with their scaling into the field's unit (value = column x scale + offset).
    ///
    /// One message per row per topic at the row's time. With a `[truth]` table in the mapping
    /// every row also gets a ground-truth message: no fault, or `--fault NAME` from
    /// `--fault-onset-s T` on, so `fdd evaluate` can score the log. Streams the CSV; errors
    /// name the file, line and column (or the mapping's key). The output may not be the CSV
    /// or the mapping; it is written whole or not at all, and the same inputs give the same
    /// bytes. Mappings of the bundled real-engine data: config/import/*.toml.
    Import {
        /// The CSV file: a header line with the column names, then one row per sample time.
        csv: PathBuf,
        /// The mapping file (TOML; see config/import/ for examples).
        #[arg(long)]
        mapping: PathBuf,
        /// Output MCAP file.
        #[arg(short, long)]
        out: PathBuf,
        /// Mark this fault in the truth topic from --fault-onset-s on (e.g. pim_gain_1.15).
        #[arg(long, requires = "fault_onset_s")]
        fault: Option<String>,
        /// Log time at which the fault starts (s, in the log's time, as the mapping gives it).
        #[arg(long, requires = "fault", allow_negative_numbers = true, value_parser = |s: &str| fdd::import::FAULT_ONSET.parse(s))]
        fault_onset_s: Option<f64>,
        /// No progress bar (it is only drawn when stderr is a terminal anyway).
        #[arg(long)]
        no_progress: bool,
    },
    /// Calibrate a plant model's parameters to measured data.
    Fit {
        #[command(subcommand)]
        what: Fit,
    },
    /// Reproduce a result from one of the source papers.
    Reproduce {
        #[command(subcommand)]
        what: Reproduce,
    },
}

#[derive(Subcommand)]
enum Fit {
    /// Fit the turbocharged air-path model to the TSFS09 engine, compressor and turbine maps
    /// (and the shaft's loss torque to the measured turbo speed of a throttle-step log), check
    /// the whole model's stationary point at every map point, and write a complete parameter
    /// file (commented with what was fitted from what and the error figures).
    ///
    /// Prints the per-quantity error table (all points and the held-out every 5th point). The
    /// same inputs give the same bytes.
    Turbo {
        /// The data directory: engine_map.csv, comp_map.csv, turb_map.csv, and the throttle-step log
        /// grupp1_airstep.mcap (its measured turbo speed fits the shaft's loss torque).
        #[arg(long)]
        data: PathBuf,
        /// The start parameter file (its [model] table; e.g. config/turbo.toml).
        #[arg(long)]
        start: PathBuf,
        /// The output parameter file.
        #[arg(short, long)]
        out: PathBuf,
        /// Print the figures as JSON instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Fit the turbocharged air-path model to a fault-free driving log of the LiU-ICE engine
    /// (volumetric efficiency, throttle area, the turbine flow constant from the boost, the
    /// sensors' noise), judge it on other fault-free logs, and write a complete parameter file.
    ///
    /// Prints the figures per log. The same inputs give the same bytes.
    TurboIce {
        /// The calibration log (MCAP, fault-free, topics of config/import/liu_ice.toml).
        #[arg(long)]
        log: PathBuf,
        /// Another fault-free log to judge the fit on (repeatable); never fitted.
        #[arg(long)]
        judge: Vec<PathBuf>,
        /// The start parameter file (its [model] table; e.g. config/turbo_vep4.toml).
        #[arg(long)]
        start: PathBuf,
        /// The output parameter file.
        #[arg(short, long)]
        out: PathBuf,
        /// Print the figures as JSON instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Design the turbocharged air-path observer's gain table (stationary Kalman gains on a
    /// grid of engine speed x manifold pressure, sensors p_ic, p_im and air flow at 50 ms) for
    /// a parameter file, and write it as a calibration file a monitor loads.
    ///
    /// Q is the model's stationary error on a fault-free LiU-ICE log (--log) or on the TSFS09
    /// engine map (--map); R the [measurement_noise] of a parameter file, floored at the
    /// sensors' accuracy. Refuses to write a table with an unstable node. The same inputs give
    /// the same bytes.
    TurboGains {
        /// The model's parameter file (e.g. config/turbo_liu_ice.toml).
        #[arg(long)]
        params: PathBuf,
        /// The parameter file whose [measurement_noise] table gives R (default: --params).
        #[arg(long)]
        measurement_noise: Option<PathBuf>,
        /// Q from this fault-free LiU-ICE log (MCAP).
        #[arg(long, conflicts_with = "map", required_unless_present = "map")]
        log: Option<PathBuf>,
        /// Q from the engine map in this TSFS09 data directory.
        #[arg(long)]
        map: Option<PathBuf>,
        /// The output gain file.
        #[arg(short, long)]
        out: PathBuf,
    },
}

#[derive(Subcommand)]
enum Reproduce {
    /// Table II of the wattmeter throttle paper: UKF angle error from a wattmeter only.
    Table2 {
        /// Number of 1 ms samples (1 to 10^9).
        #[arg(long, default_value_t = 2_000_000, allow_negative_numbers = true, value_parser = |s: &str| limits::TABLE2_SAMPLES.parse_usize(s))]
        samples: usize,
        /// Seed of excitation, process noise and sensor noise.
        #[arg(long, default_value_t = 1, allow_negative_numbers = true, value_parser = |s: &str| limits::SEED.parse(s))]
        seed: u64,
        /// Standard deviation of the wattmeter noise (A^2, above 0, at most 100).
        #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = |s: &str| limits::TABLE2_WATTMETER_STD.parse(s))]
        wattmeter_std: f64,
        /// Also run a bootstrap particle filter with this many particles (reference bound; 2
        /// to 10^6).
        #[arg(long, allow_negative_numbers = true, value_parser = |s: &str| limits::TABLE2_PARTICLES.parse_usize(s))]
        particles: Option<usize>,
        /// Throttle configuration file (default: the embedded config/throttle.toml).
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// The MAP/MAF EKF paper's Tables 1-2 with known truth: p_m and intake-valve flow RMSE of
    /// the centralized, decentralized and federated EKFs and the raw sensors on a transient
    /// drive, with each filter's cost per step.
    Intake {
        /// Length of the tip-in/tip-out drive (s, 1 to 3600).
        #[arg(long, default_value_t = 120.0, allow_negative_numbers = true, value_parser = |s: &str| limits::INTAKE_DURATION.parse(s))]
        duration: f64,
        /// Seed of the profile, process and sensor noise.
        #[arg(long, default_value_t = 1, allow_negative_numbers = true, value_parser = |s: &str| limits::SEED.parse(s))]
        seed: u64,
        /// EGR command during tip-outs (0..1, 0 = no EGR).
        #[arg(long, default_value_t = 0.3, allow_negative_numbers = true, value_parser = |s: &str| limits::INTAKE_EGR.parse(s))]
        egr: f64,
    },
    /// The air-path observer paper on the real TSFS09 engine: the gain-scheduled observer with
    /// the dC_eta_vol state on the measured transients (tuning log and held-out log): turbo
    /// speed against the measured one, p_im noise and lag against the sensor, the stationary
    /// error a 5 % volumetric-efficiency error leaves with and without dC_eta_vol, nearest-node
    /// against interpolated gains.
    Turbo {
        /// The model's parameter file.
        #[arg(long, default_value = "config/turbo_tsfs09.toml")]
        params: PathBuf,
        /// The TSFS09 data directory (engine map CSVs and the transient MCAP logs).
        #[arg(long, default_value = "fixtures/data/real/liu-tsfs09")]
        data: PathBuf,
        /// Print the figures as JSON.
        #[arg(long)]
        json: bool,
        /// Write each log's samples with the estimates as CSV into this directory.
        #[arg(long)]
        series: Option<PathBuf>,
    },
    /// The slip-control tutorial's experiment on fdd's whole-car truth: stops under a PI slip
    /// controller per wheel closing its loop on the tutorial's quarter-car EKF (surface known)
    /// or on fdd's estimator (surface unknown), on dry, wet, snow and ice from 10, 20 and
    /// 30 m/s: RMSE of speed, slip and friction against the truth, the raw slip's, the time
    /// for the friction to come within 0.05, the stopping distance against the controller fed
    /// the true slip; and the mass learned from 300 and 600 kg over braking events.
    ///
    /// Tuning cases and held-out cases are reported apart (the protocol is in the module
    /// documentation of src/reproduce/wheel.rs). The same inputs give the same output.
    Wheel {
        /// The quarter car's parameter file (default: the embedded config/wheel.toml).
        #[arg(long)]
        params: Option<PathBuf>,
        /// Print the figures as JSON.
        #[arg(long)]
        json: bool,
        /// Write the samples of the 20 m/s stops of the first held-out car (with --tuning-only
        /// the first tuning car), one CSV per surface and loop, into this directory.
        #[arg(long)]
        series: Option<PathBuf>,
        /// Run only the tuning cases (what [estimator] may be tuned on).
        #[arg(long)]
        tuning_only: bool,
    },
}

/// Logs go to stderr: warnings by default, `-v` info, `-vv` debug, `-vvv` trace; `RUST_LOG`
/// overrides.
fn init_tracing(verbose: u8) {
    let level = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    let filter = match std::env::var("RUST_LOG") {
        Ok(v) if !v.trim().is_empty() => EnvFilter::try_new(&v).unwrap_or_else(|e| {
            eprintln!("warning: ignoring RUST_LOG={v:?}: {e}");
            EnvFilter::new(level)
        }),
        _ => EnvFilter::new(level),
    };
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(false)
        .init();
}

/// Writes to stdout; a closed stdout (`fdd replay ... | head`) is reported as
/// [`StdoutClosed`] so that `main` ends quietly instead of panicking.
fn emit(text: &str) -> Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(StdoutClosed.into()),
        Err(e) => Err(anyhow::anyhow!("cannot write to stdout: {e}")),
    }
}

/// The reader of stdout went away.
#[derive(Debug)]
struct StdoutClosed;

impl std::fmt::Display for StdoutClosed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("stdout closed")
    }
}

impl std::error::Error for StdoutClosed {}

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_tracing(cli.verbose);
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        // The reader of our output is gone (`| head`): nothing left to say to anyone.
        Err(e) if e.downcast_ref::<StdoutClosed>().is_some() => ExitCode::SUCCESS,
        Err(e) => {
            // fdd's errors name the file, key or setting and include their cause.
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Replay {
            log,
            config,
            out,
            events,
            samples,
            no_progress,
            memory,
        } => {
            let cfg = RuntimeConfig::load(config.as_deref())?;
            let opts = ReplayOptions {
                out,
                events,
                progress: !no_progress,
                memory,
                samples,
            };
            let summary = fdd::replay::replay(&log, &cfg, &opts)?;
            emit(&summary.render())?;
            if let Some(e) = &summary.stopped_early {
                anyhow::bail!(
                    "replay of {} stopped early: {e} (the summary above covers what was read)",
                    log.display()
                );
            }
            Ok(())
        }
        Command::Evaluate {
            inputs,
            config,
            json,
            allow_long,
        } => {
            let cfg = RuntimeConfig::load(config.as_deref())?;
            let sim = fdd::simulate::SimulateOptions { allow_long };
            let summary = fdd::evaluate::evaluate(&inputs, &cfg, &sim, |i, n, file| {
                tracing::info!("[{}/{n}] {}", i + 1, file.display());
            })?;
            if json {
                let mut text = serde_json::to_string_pretty(&summary)?;
                text.push('\n');
                emit(&text)
            } else {
                emit(&summary.render())
            }
        }
        Command::Calibrate {
            inputs,
            out,
            config,
            false_alarms_per_hour,
            block_s,
            keep_model,
            monitor,
            allow_long,
        } => {
            let opts = fdd::calibrate::CalibrateOptions {
                false_alarms_per_hour,
                block_s,
                identify: !keep_model,
                allow_long,
            };
            opts.check()?;
            let cfg = RuntimeConfig::load(config.as_deref())?;
            fdd::calibrate::check_output_dir(&out, &inputs, &cfg)?;
            let cal = fdd::calibrate::calibrate_inputs(&inputs, &cfg, &opts, monitor.as_deref())?;
            let written = cal.write(&out)?;
            emit(&format!(
                "{}wrote {} (use: fdd replay --config {} LOG)\n",
                cal.render(&opts),
                written.display(),
                written.display()
            ))
        }
        Command::Simulate {
            scenario,
            out,
            list,
            allow_long,
        } => {
            if list {
                return emit(&fdd::simulate::list_bundled()?);
            }
            let (Some(scenario), Some(out)) = (scenario, out) else {
                anyhow::bail!("fdd simulate needs a scenario and -o FILE (or --list)");
            };
            let opts = fdd::simulate::SimulateOptions { allow_long };
            let stats = fdd::simulate::simulate(&scenario, &out, &opts)?;
            emit(&format!(
                "wrote {}: {} frames, {} messages\n",
                out.display(),
                stats.frames,
                stats.messages
            ))
        }
        Command::Import {
            csv,
            mapping,
            out,
            fault,
            fault_onset_s,
            no_progress,
        } => {
            let fault = match (fault, fault_onset_s) {
                (Some(name), Some(onset_s)) => Some(fdd::import::FaultSpec { name, onset_s }),
                _ => None,
            };
            let opts = fdd::import::ImportOptions {
                fault,
                progress: !no_progress,
            };
            let stats = fdd::import::import(&csv, &mapping, &out, &opts)?;
            emit(&stats.render(&out, opts.fault.as_ref()))
        }
        Command::Fit {
            what:
                Fit::Turbo {
                    data,
                    start,
                    out,
                    json,
                },
        } => {
            let args = fdd::fit::FitTurboArgs { data, start, out };
            let run = fdd::fit::run(&args)?;
            if json {
                let value = fdd::fit::render::json(&run.outcome, &run.check);
                emit(&format!("{}\n", serde_json::to_string_pretty(&value)?))
            } else {
                emit(&format!(
                    "wrote {}\n{}",
                    args.out.display(),
                    fdd::fit::render::table(&run.check)
                ))
            }
        }
        Command::Fit {
            what:
                Fit::TurboIce {
                    log,
                    judge,
                    start,
                    out,
                    json,
                },
        } => {
            let args = fdd::fit::ice::FitIceArgs {
                log,
                judge,
                start,
                out,
            };
            let run = fdd::fit::ice::run(&args)?;
            if json {
                let value = fdd::fit::ice::json(&run);
                emit(&format!("{}\n", serde_json::to_string_pretty(&value)?))
            } else {
                emit(&format!(
                    "wrote {}\n{}",
                    args.out.display(),
                    fdd::fit::ice::table(&run.checks)
                ))
            }
        }
        Command::Fit {
            what:
                Fit::TurboGains {
                    params,
                    measurement_noise,
                    log,
                    map,
                    out,
                },
        } => {
            let source = match (log, map) {
                (Some(log), _) => fdd::fit::gains::NoiseSource::Log(log),
                (None, Some(map)) => fdd::fit::gains::NoiseSource::Map(map),
                (None, None) => anyhow::bail!("one of --log and --map is needed"),
            };
            let args = fdd::fit::gains::FitGainsArgs {
                measurement_noise: measurement_noise.unwrap_or_else(|| params.clone()),
                params,
                source,
                out,
            };
            let run = fdd::fit::gains::run(&args)?;
            let worst = run
                .design
                .nodes
                .iter()
                .map(|n| n.closed_loop_radius)
                .fold(0.0, f64::max);
            emit(&format!(
                "wrote {} ({} nodes, largest closed-loop spectral radius {worst:.5})\n",
                args.out.display(),
                run.design.nodes.len()
            ))
        }
        Command::Reproduce { what } => match what {
            Reproduce::Table2 {
                samples,
                seed,
                wattmeter_std,
                particles,
                config,
            } => {
                let cfg = ThrottleConfig::load(config.as_deref())?;
                let settings = table2::Table2Settings {
                    samples,
                    seed,
                    wattmeter_std,
                    particles,
                };
                let report = table2::run(&cfg, &settings)?;
                emit(&table2::render(&report))
            }
            Reproduce::Intake {
                duration,
                seed,
                egr,
            } => {
                let settings = intake::IntakeSettings {
                    duration_s: duration,
                    seed,
                    egr_pos: egr,
                };
                let report = intake::run(&settings)?;
                emit(&intake::render(&report))
            }
            Reproduce::Turbo {
                params,
                data,
                json,
                series,
            } => {
                let report = turbo::run(&turbo::TurboSettings {
                    params,
                    data,
                    series,
                })?;
                if json {
                    emit(&format!("{}\n", serde_json::to_string_pretty(&report)?))
                } else {
                    emit(&turbo::render(&report))
                }
            }
            Reproduce::Wheel {
                params,
                json,
                series,
                tuning_only,
            } => {
                let report = wheel::run(&wheel::WheelSettings {
                    params,
                    series,
                    tuning_only,
                    ..Default::default()
                })?;
                if json {
                    emit(&format!("{}\n", serde_json::to_string_pretty(&report)?))
                } else {
                    emit(&wheel::render(&report))
                }
            }
        },
    }
}
