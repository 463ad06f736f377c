//! Cost of the air-path monitor per 20 Hz frame: the three flow balances at the readings, their
//! filters, offsets and CUSUMs, the hypothesis bank's frame (while evidence accumulates) and
//! the event memory, on frames of simulated drives (the turbo truth simulator) of three
//! styles, with the monitor on the TSFS09 parameters (`config/turbo_monitor_tsfs09.toml`).
//!
//! `cargo bench --bench turbo_monitor`. Each iteration is one `process_frame` call on the
//! second half of a 120 s drive, after the first half warmed the monitor up (offsets learned,
//! tests running). `turbo_monitor_fault_frame` times single frames (one per sample) of a
//! faulty city drive from its onset on: the CUSUMs rise, the hypothesis bank takes every
//! tested frame, decides 2 s after the first alarm and the events report; its slowest samples
//! are the decisions (and the machine's interruptions).

use std::path::PathBuf;

use divan::Bencher;
use fdd_estimators::models::turbo::residuals::IntakeReadings;
use fdd_estimators::models::turbo::TurboInput;
use fdd_fixtures::turbo_profile::DriveStyle;
use fdd_fixtures::turbo_scenario::TurboScenario;
use fdd_fixtures::turbo_sim::TurboSim;
use fdd_monitor::monitor::Monitor;
use fdd_monitor::signal_table::SignalTable;
use fdd_monitor::turbo::{TurboConfig, TurboMonitor};

fn main() {
    divan::main();
}

/// One frame: its time (ns), readings and inputs.
type Frame = (u64, IntakeReadings, TurboInput);

fn frames(style: DriveStyle) -> Vec<Frame> {
    scenario_frames(&TurboScenario::new("bench", 120.0, 11, style))
}

fn scenario_frames(sc: &TurboScenario) -> Vec<Frame> {
    TurboSim::from_scenario(sc, "bench")
        .expect("scenario")
        .map(|f| {
            (
                f.t_ns,
                IntakeReadings {
                    p_ic_pa: f.p_ic_pa,
                    t_ic_k: f.t_ic_k,
                    p_im_pa: f.p_im_pa,
                    maf_kg_s: f.maf_kg_s,
                },
                TurboInput {
                    throttle_pct: f.throttle_pct,
                    engine_speed_rad_s: f.engine_speed_rad_s,
                    wastegate_frac: f.wastegate,
                    lambda: 1.0,
                    ambient_pressure_pa: f.ambient_pressure_pa,
                    ambient_temperature_k: f.ambient_temperature_k,
                },
            )
        })
        .collect()
}

fn monitor() -> TurboMonitor {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/turbo_monitor_tsfs09.toml");
    let cfg = TurboConfig::load(Some(&path)).expect("monitor file");
    let table = SignalTable::with_names(
        &[
            "turbo_p_ic",
            "turbo_t_ic",
            "turbo_p_im",
            "turbo_maf",
            "turbo_engine_speed",
            "turbo_throttle",
            "turbo_wastegate",
            "ambient_pressure",
            "ambient_temperature",
        ],
        250_000_000,
    )
    .expect("table");
    TurboMonitor::new(&cfg.params, &cfg.monitor, &table).expect("monitor")
}

/// A monitor that has run the first half of `data` (from an operation cycle's start), and the
/// second half, to time.
fn warmed(data: &[Frame]) -> (TurboMonitor, &[Frame]) {
    let mut mon = monitor();
    mon.start_operation_cycle(0, &mut |_| {});
    let half = data.len() / 2;
    for (t, r, u) in &data[..half] {
        mon.process_frame(*t, r, u, None, &mut |_| {});
    }
    (mon, &data[half..])
}

/// A 300 s city drive with `fault` from 150 s (the seeds of `tests/turbo_monitor.rs`' large
/// faults).
#[divan::bench(args = ["maf_gain_0.85", "leak_im_8mm"], sample_count = 3000, sample_size = 1)]
fn turbo_monitor_fault_frame(bencher: Bencher, fault: &str) {
    use fdd_fixtures::turbo_faults::{TurboFault, TurboFaultSpec};
    let (seed, fault) = match fault {
        "maf_gain_0.85" => (4100, TurboFault::WafGain { gain_pct: 85 }),
        _ => (4200, TurboFault::LeakIm { diameter_mm: 8 }),
    };
    let mut sc = TurboScenario::new("bench", 300.0, seed, DriveStyle::City);
    sc.fault = TurboFaultSpec {
        fault,
        start_s: 150.0,
        end_s: None,
    };
    let data = scenario_frames(&sc);
    let (mut mon, timed) = warmed(&data);
    let mut k = 0usize;
    bencher.bench_local(|| {
        // 3000 samples: the 150 s after the onset, once.
        let (t, r, u) = &timed[k.min(timed.len() - 1)];
        let t = *t + (k.saturating_sub(timed.len() - 1) as u64) * 50_000_000;
        k += 1;
        let mut sink = |o: fdd_monitor::monitor::Output<'_>| {
            divan::black_box(o);
        };
        mon.process_frame(t, divan::black_box(r), divan::black_box(u), None, &mut sink);
    });
}

#[divan::bench(args = ["city", "highway", "tip_in_out"], sample_count = 200, sample_size = 64)]
fn turbo_monitor_frame(bencher: Bencher, style: &str) {
    let style = match style {
        "city" => DriveStyle::City,
        "highway" => DriveStyle::Highway,
        _ => DriveStyle::TipInOut,
    };
    let data = frames(style);
    let (mut mon, timed) = warmed(&data);
    let period = timed.get(1).map_or(50_000_000, |b| b.0 - timed[0].0);
    let mut k = 0u64;
    bencher.bench_local(|| {
        let (t, r, u) = &timed[k as usize % timed.len()];
        // Time keeps moving forward when the timed half repeats.
        let lap = k / timed.len() as u64;
        k += 1;
        let mut sink = |o: fdd_monitor::monitor::Output<'_>| {
            divan::black_box(o);
        };
        mon.process_frame(
            *t + lap * period * timed.len() as u64,
            divan::black_box(r),
            divan::black_box(u),
            None,
            &mut sink,
        );
    });
}
