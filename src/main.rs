//! `fdd`: command-line front end of the fault-detection and diagnosis library.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};
use fdd::config::ThrottleConfig;
use fdd::reproduce::table2;

#[derive(Parser)]
#[command(
    name = "fdd",
    version,
    about = "Onboard fault detection and diagnosis: model-based residuals, tests and DTCs"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a scenario (truth, sensors, injected fault) and write it as an MCAP log.
    Simulate {
        /// Scenario: a path to a scenario TOML file, or the name of a file in fixtures/scenarios
        /// (e.g. `throttle_tps_stuck`).
        scenario: String,
        /// Output MCAP file.
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Reproduce a result from one of the source papers.
    Reproduce {
        #[command(subcommand)]
        what: Reproduce,
    },
}

#[derive(Subcommand)]
enum Reproduce {
    /// Table II of the wattmeter throttle paper: UKF angle error from a wattmeter only.
    Table2 {
        /// Number of 1 ms samples.
        #[arg(long, default_value_t = 2_000_000)]
        samples: usize,
        /// Seed of excitation, process noise and sensor noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Standard deviation of the wattmeter noise (A^2).
        #[arg(long, default_value_t = 1.0)]
        wattmeter_std: f64,
        /// Also run a bootstrap particle filter with this many particles (reference bound).
        #[arg(long)]
        particles: Option<usize>,
        /// Throttle configuration file (default: the embedded config/throttle.toml).
        #[arg(long)]
        config: Option<PathBuf>,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Simulate { scenario, out } => {
            let stats = fdd::simulate::simulate(&scenario, &out)?;
            println!(
                "wrote {}: {} frames, {} messages",
                out.display(),
                stats.frames,
                stats.messages
            );
            Ok(())
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
                print!("{}", table2::render(&report));
                Ok(())
            }
        },
    }
}
