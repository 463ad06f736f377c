//! The intake monitor's decisions over time, on simulated drives of the truth simulator's own
//! plant ([`IntakeSim::from_scenario`]): the group DTC then the specific one for a fault that is
//! ambiguous at first, faults that heal (a circuit fault and a residual fault: their DTCs pass
//! again, ISO 14229 testFailed 1 -> 0, while the memory keeps the pending/confirmed history),
//! two faults at once (isolable: two DTCs; not isolable: the group DTC naming both), and a
//! healthy MAP above the circuit-high limit at wide-open throttle (judged against the model).
//!
//! `cargo test --release --test intake_decisions -- --nocapture` prints the event sequences.

use fdd_diagnostics::dtc::StatusBit;
use fdd_fixtures::intake_faults::IntakeFaultSpec;
use fdd_fixtures::intake_profile::{
    IdleBlipsSpec, IdleSpec, PedalRampsSpec, ProfileSpec, TipInOutSpec,
};
use fdd_fixtures::intake_sim::{default_intake_model, IntakeFault, IntakeScenario, IntakeSim};
use fdd_monitor::intake::{IntakeMonitor, IntakeMonitorConfig, Segment, GROUP_EVENT};
use fdd_monitor::monitor::{Monitor, Output};
use fdd_monitor::signal_table::SignalTable;

fn table() -> SignalTable {
    // One segment of 100 ms at the slowest speed the model accepts; 250 ms is lost.
    SignalTable::with_names(&IntakeMonitorConfig::default().signal_names(), 250_000_000)
        .expect("table")
}

/// One testFailed change of an event.
#[derive(Debug, Clone, PartialEq)]
struct Change {
    t_s: f64,
    event: String,
    /// testFailed after the change.
    failed: bool,
    /// The isolation candidates of a raised event.
    candidates: Vec<String>,
    /// The status byte after the change.
    status: u8,
}

fn monitor() -> IntakeMonitor {
    let mut mon = IntakeMonitor::new(
        &default_intake_model(),
        &IntakeMonitorConfig::default(),
        &table(),
    )
    .expect("monitor");
    mon.start_operation_cycle(0, &mut |_| {});
    mon
}

/// Feeds segments to `mon` and returns every testFailed change.
fn feed(mon: &mut IntakeMonitor, segments: impl Iterator<Item = (u64, Segment)>) -> Vec<Change> {
    let mut changes = Vec::new();
    for (t_ns, seg) in segments {
        mon.process_segment(t_ns, &seg, &mut |out| {
            if let Output::Event(ev) = out {
                if ev.bit_changed(StatusBit::TestFailed) {
                    changes.push(Change {
                        t_s: t_ns as f64 * 1e-9,
                        event: ev.event.to_string(),
                        failed: ev.status_after.test_failed(),
                        candidates: ev
                            .candidates
                            .iter()
                            .filter(|c| c.1 > 0.0)
                            .map(|c| c.0.to_string())
                            .collect(),
                        status: ev.status_after.byte(),
                    });
                }
            }
        });
    }
    for c in &changes {
        println!(
            "  {:8.3} {:24} {} 0x{:02x} {:?}",
            c.t_s,
            c.event,
            if c.failed { "FAILED" } else { "passed" },
            c.status,
            c.candidates
        );
    }
    changes
}

fn simulate(sc: &IntakeScenario) -> impl Iterator<Item = (u64, Segment)> {
    IntakeSim::from_scenario(sc).expect("scenario").map(|f| {
        (
            f.t_ns,
            Segment {
                speed_rpm: f.n_rpm,
                throttle_deg: f.throttle_deg,
                egr_cmd: f.egr_cmd,
                map_pa: f.map_pa,
                maf_kg_s: f.maf_kg_s,
            },
        )
    })
}

fn raised(changes: &[Change]) -> Vec<&str> {
    changes
        .iter()
        .filter(|c| c.failed)
        .map(|c| c.event.as_str())
        .collect()
}

/// A 3 mm leak from 10 s on the tip-in/tip-out drive: it starts in a tip-out, where a leak, an
/// EGR valve stuck open and a MAP offset raise the manifold pressure alike. The group DTC comes
/// first, with the leak and the EGR valve among its candidates; the tip-ins that follow tell the
/// leak apart, the specific leak DTC is raised and the group event passes in the same segment.
/// The leak's lead over the EGR valve grows by about 2 % of the statistics, so with the
/// isolation margin of 300 it is named some 40 s after the onset (with 50, after 3.5 s): the
/// drive is 60 s long.
#[test]
fn an_ambiguous_leak_gets_the_group_dtc_then_the_specific_one() {
    let sc = IntakeScenario::new(
        "ambiguous_leak",
        60.0,
        106,
        ProfileSpec::TipInOut(TipInOutSpec::default()),
        IntakeFault::Leak {
            start_s: 10.0,
            diameter_m: 0.003,
        },
    );
    let mut mon = monitor();
    let changes = feed(&mut mon, simulate(&sc));
    assert_eq!(
        raised(&changes),
        vec![GROUP_EVENT, "intake_leak"],
        "{changes:?}"
    );
    let group = &changes[0];
    assert!(group.t_s > 10.0 && group.t_s < 12.0, "{group:?}");
    for c in ["manifold_leak", "egr_valve"] {
        assert!(group.candidates.iter().any(|g| g == c), "{group:?}");
    }
    let leak = changes
        .iter()
        .find(|c| c.event == "intake_leak")
        .expect("leak DTC");
    assert_eq!(
        leak.candidates.first().map(String::as_str),
        Some("manifold_leak")
    );
    let passed = changes
        .iter()
        .find(|c| c.event == GROUP_EVENT && !c.failed)
        .expect("the group event passes");
    assert_eq!(passed.t_s, leak.t_s, "it passes when the fault is named");
    // ISO 14229: testFailed clear, pending and confirmed-this-cycle history kept.
    assert_eq!(passed.status & 0x01, 0);
    assert_ne!(
        passed.status & 0x04,
        0,
        "pendingDTC kept: 0x{:02x}",
        passed.status
    );
}

/// The same ambiguity at idle, where nothing tells a leak from an EGR valve stuck open (the
/// command is 0, both add unmetered gas): the group DTC naming both, never a specific DTC.
#[test]
fn a_leak_at_idle_stays_a_group_dtc() {
    let sc = IntakeScenario::new(
        "idle_leak",
        60.0,
        7,
        ProfileSpec::Idle(IdleSpec::default()),
        IntakeFault::Leak {
            start_s: 20.0,
            diameter_m: 0.003,
        },
    );
    let mut mon = monitor();
    let changes = feed(&mut mon, simulate(&sc));
    assert_eq!(raised(&changes), vec![GROUP_EVENT], "{changes:?}");
    let g = &changes[0];
    assert!(g.t_s > 20.0 && g.t_s < 22.0, "{g:?}");
    for c in ["manifold_leak", "egr_valve"] {
        assert!(g.candidates.iter().any(|x| x == c), "{g:?}");
    }
    assert!(mon.group_failed(), "still failed at the end");
}

/// A MAP signal line open from 10 s to 20 s: circuit low, then, reading plausibly again for
/// `heal_s`, the DTC passes (testFailed 1 -> 0); the filters start again and nothing else is
/// raised.
#[test]
fn a_circuit_fault_that_ends_passes_again() {
    let mut sc = IntakeScenario::new(
        "map_open_heals",
        40.0,
        3,
        ProfileSpec::TipInOut(TipInOutSpec::default()),
        IntakeFault::None,
    );
    sc.fault = IntakeFaultSpec::ending(IntakeFault::MapOpen { start_s: 10.0 }, 20.0);
    let mut mon = monitor();
    let changes = feed(&mut mon, simulate(&sc));
    assert_eq!(raised(&changes), vec!["map_circuit_low"], "{changes:?}");
    let heal = changes
        .iter()
        .find(|c| c.event == "map_circuit_low" && !c.failed)
        .expect("healed");
    let heal_s = IntakeMonitorConfig::default().heal_s;
    assert!(
        heal.t_s >= 20.0 + heal_s && heal.t_s < 20.0 + heal_s + 1.0,
        "{heal:?}"
    );
    assert_eq!(heal.status & 0x01, 0);
    assert!(mon.decision().is_none());
}

/// A MAP offset of 5 kPa from 10 s to 25 s: the MAP range/performance DTC (after the group DTC
/// where isolation takes longer than `group_after_s`); once the offset is gone the sequential
/// test "gone" against "still there" passes it again, and nothing else is raised.
#[test]
fn a_residual_fault_that_ends_passes_again() {
    let mut sc = IntakeScenario::new(
        "map_bias_heals",
        45.0,
        102,
        ProfileSpec::TipInOut(TipInOutSpec::default()),
        IntakeFault::None,
    );
    sc.fault = IntakeFaultSpec::ending(
        IntakeFault::MapBias {
            start_s: 10.0,
            bias_pa: 5000.0,
        },
        25.0,
    );
    let mut mon = monitor();
    let changes = feed(&mut mon, simulate(&sc));
    let specific: Vec<&str> = raised(&changes)
        .into_iter()
        .filter(|e| *e != GROUP_EVENT)
        .collect();
    assert_eq!(specific, vec!["map_range_performance"], "{changes:?}");
    let heal = changes
        .iter()
        .find(|c| c.event == "map_range_performance" && !c.failed)
        .expect("healed");
    assert!(heal.t_s > 25.0 && heal.t_s < 30.0, "{heal:?}");
    assert!(mon.decision().is_none(), "{:?}", mon.decision());
}

/// Two faults at once that the monitor tells apart: a MAP signal line open from 10 s and a MAF
/// stuck from 12 s. Each sensor's own checks run whatever the other does: two DTCs.
#[test]
fn two_sensor_faults_at_once_get_two_dtcs() {
    let mut sc = IntakeScenario::new(
        "two_sensor_faults",
        30.0,
        5,
        ProfileSpec::TipInOut(TipInOutSpec::default()),
        IntakeFault::MapOpen { start_s: 10.0 },
    );
    sc.second_fault = Some(IntakeFault::MafStuck { start_s: 12.0 }.into());
    let mut mon = monitor();
    let changes = feed(&mut mon, simulate(&sc));
    assert_eq!(
        raised(&changes),
        vec!["map_circuit_low", "maf_range_performance"],
        "{changes:?}"
    );
    assert_eq!(mon.decisions().flatten().count(), 2);
}

/// A MAP short circuit after the MAF has been named stuck: the stuck MAF holds the filters'
/// pressure estimate wherever it stuck, and a MAF stuck in a tip-in would make a shorted MAP
/// look like wide-open throttle, so with the MAF failed the circuit check judges against the
/// model's steady state. The MAF sticks at eight times spread over tip-ins and tip-outs; every
/// run gets the MAF DTC and then P0108 within a second of the short.
#[test]
fn a_map_short_is_named_while_the_maf_is_failed() {
    for k in 0..8 {
        let stuck_s = 10.0 + 0.45 * f64::from(k);
        let mut sc = IntakeScenario::new(
            "maf_stuck_then_map_short",
            stuck_s + 12.0,
            11,
            ProfileSpec::TipInOut(TipInOutSpec::default()),
            IntakeFault::MafStuck { start_s: stuck_s },
        );
        let short_s = stuck_s + 8.0;
        sc.second_fault = Some(IntakeFault::MapShort { start_s: short_s }.into());
        let mut mon = monitor();
        let changes = feed(&mut mon, simulate(&sc));
        let first = |name: &str| {
            changes
                .iter()
                .find(|c| c.failed && c.event == name)
                .map(|c| c.t_s)
        };
        let maf = first("maf_range_performance");
        assert!(
            maf.is_some_and(|t| t < short_s),
            "stuck at {stuck_s}: {changes:?}"
        );
        let map = first("map_circuit_high");
        assert!(
            map.is_some_and(|t| t >= short_s && t < short_s + 1.0),
            "stuck at {stuck_s}, short at {short_s}: {changes:?}"
        );
    }
}

/// Both sensors failed (the MAF stuck, then the MAP shorted): every filter leans on a failed
/// reading, and the MAF-local filter, fed by the stuck MAF, put the pressure tens of kPa off
/// (55 kPa std in held-out version 3, log 55; 72.5 kPa rms here). Once both are named, the
/// estimate comes from the throttle model's steady state: 5.6 kPa rms on this tip-in/tip-out
/// drive, the error of a steady state in the transients.
#[test]
fn with_both_sensors_failed_the_pressure_comes_from_the_throttle_model() {
    let stuck_s = 10.0;
    let short_s = stuck_s + 8.0;
    let mut sc = IntakeScenario::new(
        "maf_stuck_then_map_short",
        short_s + 20.0,
        11,
        ProfileSpec::TipInOut(TipInOutSpec::default()),
        IntakeFault::MafStuck { start_s: stuck_s },
    );
    sc.second_fault = Some(IntakeFault::MapShort { start_s: short_s }.into());
    let mut mon = monitor();
    let (mut n, mut sq, mut model_src) = (0usize, 0.0, 0usize);
    for f in IntakeSim::from_scenario(&sc).expect("scenario") {
        let seg = Segment {
            speed_rpm: f.n_rpm,
            throttle_deg: f.throttle_deg,
            egr_cmd: f.egr_cmd,
            map_pa: f.map_pa,
            maf_kg_s: f.maf_kg_s,
        };
        let t_s = f.t_ns as f64 * 1e-9;
        mon.process_segment(f.t_ns, &seg, &mut |out| {
            if let Output::Estimate {
                name: "manifold_pressure",
                value,
                source,
                ..
            } = out
            {
                if t_s > short_s + 2.0 {
                    n += 1;
                    sq += (value - f.truth.p_m).powi(2);
                    model_src += usize::from(source == "throttle_model");
                }
            }
        });
    }
    assert!(n > 100, "{n} estimates");
    assert_eq!(
        model_src, n,
        "every estimate from the model once both are named"
    );
    let rms = (sq / n as f64).sqrt();
    assert!(rms < 10_000.0, "pressure error rms {rms:.0} Pa");
}

/// Two residual faults one after the other: a MAF gain error from 10 s and a 3 mm leak from
/// 25 s. The first is named and taken out of the filters' inputs (its reading corrected), so
/// the residuals go on testing and the leak gets its own DTC, with the MAF's still failed.
#[test]
fn a_second_residual_fault_gets_its_own_dtc() {
    let mut sc = IntakeScenario::new(
        "maf_then_leak",
        45.0,
        103,
        ProfileSpec::TipInOut(TipInOutSpec::default()),
        IntakeFault::MafGain {
            start_s: 10.0,
            gain: 1.1,
        },
    );
    sc.second_fault = Some(
        IntakeFault::Leak {
            start_s: 25.0,
            diameter_m: 0.003,
        }
        .into(),
    );
    let mut mon = monitor();
    let changes = feed(&mut mon, simulate(&sc));
    let specific: Vec<&str> = raised(&changes)
        .into_iter()
        .filter(|e| *e != GROUP_EVENT)
        .collect();
    assert_eq!(
        specific,
        vec!["maf_range_performance", "intake_leak"],
        "{changes:?}"
    );
    let leak = changes
        .iter()
        .find(|c| c.event == "intake_leak")
        .expect("leak");
    assert!(leak.t_s > 25.0, "{leak:?}");
    // Both still failed at the end.
    assert!(!changes
        .iter()
        .any(|c| !c.failed && (c.event == "maf_range_performance" || c.event == "intake_leak")));
}

/// Two faults at once that the data cannot tell apart: at idle a leak and an EGR valve stuck
/// open add unmetered gas alike. The group DTC, naming both.
#[test]
fn two_ambiguous_faults_at_once_get_the_group_dtc() {
    let mut sc = IntakeScenario::new(
        "leak_and_egr",
        60.0,
        11,
        ProfileSpec::Idle(IdleSpec::default()),
        IntakeFault::Leak {
            start_s: 20.0,
            diameter_m: 0.0025,
        },
    );
    sc.second_fault = Some(
        IntakeFault::EgrStuckOpen {
            start_s: 20.0,
            position: 0.2,
        }
        .into(),
    );
    let mut mon = monitor();
    let changes = feed(&mut mon, simulate(&sc));
    assert_eq!(raised(&changes), vec![GROUP_EVENT], "{changes:?}");
    for c in ["manifold_leak", "egr_valve"] {
        assert!(changes[0].candidates.iter().any(|x| x == c), "{changes:?}");
    }
}

/// Circuit high is judged against the model. Wide-open throttle at 3000 rpm where the MAP reads
/// 112 kPa, above 1.1 x the model's ambient (111.5 kPa), and the MAF the flow of a 109 kPa
/// manifold (an ambient higher than the model's, a sensor reading 3 % high): the filters put the
/// sensor's pressure above the limit less its margin, so the reading is not ruled out and no
/// DTC is raised. Then at part load the MAP reads 115 kPa (shorted to the supply) where the MAF
/// says 50 kPa: circuit high after `circuit_persist_segments`.
#[test]
fn circuit_high_only_where_the_model_rules_the_reading_out() {
    let model = default_intake_model();
    let cfg = IntakeMonitorConfig::default();
    let mut mon = monitor();
    let dt_ns = 10_000_000u64; // 3000 rpm: 10 ms per segment
    let mut t = 0u64;
    let mut segs = Vec::new();
    let mut push = |map: f64, p_flow: f64, throttle: f64, n: usize| {
        for k in 0..n {
            t += dt_ns;
            // Sensor noise (a reading repeated exactly is a stuck sensor).
            let wiggle = ((k % 7) as f64 - 3.0) / 3.0;
            let maf = model.intake_valve_flow(p_flow, 3000.0) * (1.0 + 0.004 * wiggle);
            segs.push((
                t,
                Segment {
                    speed_rpm: 3000.0,
                    throttle_deg: throttle,
                    egr_cmd: 0.0,
                    map_pa: map + 300.0 * wiggle,
                    maf_kg_s: maf,
                },
            ));
        }
    };
    // Part load first (the filters and the learned corrections settle), then wide open.
    push(50_000.0, 50_000.0, 12.0, 800);
    push(112_000.0, 109_000.0, 80.0, 300);
    let changes = feed(&mut mon, segs.clone().into_iter());
    assert!(
        !raised(&changes).contains(&"map_circuit_high"),
        "healthy MAP at wide open throttle: {changes:?}"
    );
    let mut segs = Vec::new();
    let mut push2 = |map: f64, p_flow: f64, n: usize| {
        for k in 0..n {
            t += dt_ns;
            let wiggle = ((k % 7) as f64 - 3.0) / 3.0;
            let maf = model.intake_valve_flow(p_flow, 3000.0) * (1.0 + 0.004 * wiggle);
            segs.push((
                t,
                Segment {
                    speed_rpm: 3000.0,
                    throttle_deg: 12.0,
                    egr_cmd: 0.0,
                    map_pa: if map > 114_000.0 {
                        map
                    } else {
                        map + 300.0 * wiggle
                    },
                    maf_kg_s: maf,
                },
            ));
        }
    };
    push2(50_000.0, 50_000.0, 300);
    push2(
        115_000.0,
        50_000.0,
        cfg.circuit_persist_segments as usize + 2,
    );
    let changes = feed(&mut mon, segs.into_iter());
    assert_eq!(raised(&changes), vec!["map_circuit_high"], "{changes:?}");
}

/// An open MAF line at idle reads 0, below the circuit-low limit, and leaves the filters: their
/// estimate of the metered flow then rests on the MAP alone and scatters by about 1 g/s per
/// segment around the true 3 g/s, so their 3-sigma rule never ruled the reading out, the frozen
/// check waits for the circuit judgement, and nothing was ever named (tuning log 52). The
/// throttle model's flow at the MAP reading rules it out.
#[test]
fn an_open_maf_line_at_idle_is_named() {
    for seed in [3, 4, 5] {
        let open_s = 20.0;
        let sc = IntakeScenario::new(
            "maf_open_idle",
            30.0,
            seed,
            ProfileSpec::Idle(IdleSpec::default()),
            IntakeFault::MafOpen { start_s: open_s },
        );
        let mut mon = monitor();
        let changes = feed(&mut mon, simulate(&sc));
        let named = changes
            .iter()
            .find(|c| c.failed && c.event == "maf_circuit_low")
            .map(|c| c.t_s);
        println!("seed {seed}: maf_circuit_low at {named:?}");
        assert!(
            named.is_some_and(|t| t >= open_s && t < open_s + 1.0),
            "seed {seed}: {changes:?}"
        );
    }
}

/// A noisy MAP while the pedal moves in even 2-s ramps: the noise test skips only the start and
/// end of each ramp (where the throttle's rate changes), not the ramp itself, and names the
/// sensor within a second; skipping every segment faster than 10 deg/s (the rule before
/// 2026-12-05) left it untested most of the time.
#[test]
fn a_noisy_map_is_named_while_the_pedal_ramps() {
    let spec = ProfileSpec::TipInOut(TipInOutSpec {
        ramp_s: 2.0,
        dwell_s: [2.0, 2.3],
        ..Default::default()
    });
    let noise_s = 30.0;
    let sc = IntakeScenario::new(
        "map_noise_ramps",
        45.0,
        7,
        spec,
        IntakeFault::MapNoise {
            start_s: noise_s,
            std_pa: 2500.0,
        },
    );
    let first = |cfg: IntakeMonitorConfig| {
        let mut mon = IntakeMonitor::new(&default_intake_model(), &cfg, &table()).expect("monitor");
        mon.start_operation_cycle(0, &mut |_| {});
        let changes = feed(&mut mon, simulate(&sc));
        assert!(
            !changes.iter().any(|c| c.failed && c.t_s < noise_s),
            "{changes:?}"
        );
        changes
            .iter()
            .find(|c| c.failed && c.event == "map_range_performance")
            .map(|c| c.t_s)
    };
    let now = first(IntakeMonitorConfig::default());
    let before = first(IntakeMonitorConfig {
        noise_max_throttle_rate_deg_s: 10.0,
        noise_max_throttle_rate_change_deg_s: 1e9,
        ..Default::default()
    });
    println!("map_range_performance at {now:?}; with the old gate at {before:?}");
    assert!(now.is_some_and(|t| t < noise_s + 1.0), "{now:?}");
    assert!(
        before.is_none_or(|t| t > now.unwrap_or(f64::MAX)),
        "{before:?}"
    );
}

/// A MAF drifting by 1.2 g/s per second for 30 s on pedal ramps, then gone (held-out v4 log 39:
/// 120 s of flags after the end). Its compensation then predicts an error of about a hundred
/// deviations that is no longer there: the heal test must favour "gone" (with residuals
/// clipped rather than weighed by Huber's loss it never could above 16 deviations), the raw
/// residuals must read quiet although the compensated filters' prediction misses a few percent
/// of the effect, and once healed the filters start again rather than raise a new fault on
/// their own transient. The DTC passes within 10 s of the end and nothing else is raised.
#[test]
fn a_large_maf_drift_that_ends_heals_within_10_s() {
    for seed in [11, 12] {
        let end_s = 60.0;
        let mut sc = IntakeScenario::new(
            "maf_drift_heals",
            90.0,
            seed,
            ProfileSpec::PedalRamps(PedalRampsSpec::default()),
            IntakeFault::None,
        );
        sc.fault = IntakeFaultSpec::ending(
            IntakeFault::MafDrift {
                start_s: 30.0,
                rate_kg_s_per_s: 0.0012,
            },
            end_s,
        );
        let mon = raised_once_and_healed(&sc, "maf_range_performance", end_s);
        assert!(mon.decision().is_none(), "{:?}", mon.decision());
    }
}

/// Runs `sc` and checks that `event` is the only specific DTC raised and that it passes within
/// 10 s after the fault's end at `end_s` (s); returns the monitor for further checks.
fn raised_once_and_healed(sc: &IntakeScenario, event: &str, end_s: f64) -> IntakeMonitor {
    let mut mon = monitor();
    let changes = feed(&mut mon, simulate(sc));
    let seed = sc.seed;
    let raised: Vec<&str> = raised(&changes)
        .into_iter()
        .filter(|e| *e != GROUP_EVENT)
        .collect();
    assert_eq!(raised, vec![event], "seed {seed}: {changes:?}");
    let heal = changes
        .iter()
        .find(|c| c.event == event && !c.failed)
        .map(|c| c.t_s);
    println!("seed {seed}: healed at {heal:?}");
    assert!(
        heal.is_some_and(|t| t > end_s && t < end_s + 10.0),
        "seed {seed}: {changes:?}"
    );
    mon
}

/// A MAF drift at idle with blips, 1 g/s per second from 30 s to 60 s. The drift is decided
/// early, from a few seconds of idle, and each later refit of the decided error must describe
/// the whole error since the onset: refits summed from short windows of compensated residuals
/// wandered (a rate of +-50..130 units per second from a 0.3-s window) and the error taken out
/// never matched the sensor's, so the fault did not heal within 10 s of its end (seeds 21 and
/// 24 never healed). One DTC, passed within 10 s of the end.
#[test]
fn a_maf_drift_at_idle_is_refitted_whole_and_heals_after_its_end() {
    for seed in 21..=25 {
        let end_s = 60.0;
        let mut sc = IntakeScenario::new(
            "maf_drift_idle_heals",
            90.0,
            seed,
            ProfileSpec::IdleBlips(IdleBlipsSpec::default()),
            IntakeFault::None,
        );
        sc.fault = IntakeFaultSpec::ending(
            IntakeFault::MafDrift {
                start_s: 30.0,
                rate_kg_s_per_s: 0.001,
            },
            end_s,
        );
        raised_once_and_healed(&sc, "maf_range_performance", end_s);
    }
}

/// A healthy engine under 97.2 kPa of ambient pressure (the monitor's model assumes
/// 101.3 kPa), driven with pedal ramps that reach high load with the EGR valve open, its plant
/// and sensors off the model by the held-out ranges (the plant of held-out version 5's log 61,
/// now a development log). The exhaust back-pressure upstream of the valve falls with the
/// ambient, and near the end of the flow function the EGR flow falls steeply with it (17 % at
/// 94 kPa in the manifold), so the MAF-only filter predicts a manifold pressure 1-2 kPa above
/// the true one. Without an allowance for that in the pressure residual the healthy MAP was
/// named 3 kPa low at 504 s. Nothing is raised.
#[test]
fn a_lower_ambient_pressure_raises_nothing_at_high_load_with_egr() {
    for seed in [70061, 1, 2] {
        let text = format!(
            r#"
name = "low_ambient_pedal_ramps"
monitor = "intake"
duration_s = 900.0
seed = {seed}

[profile]
kind = "pedal_ramps"

[plant]
param_rel_error = 0.015137
ve_error_rel = -0.003136
ve_error_speed = -0.002678
ve_error_pressure = 0.007309
discharge_error_rel = 0.008711
discharge_error_angle = 0.007372
ambient_pressure_pa = 97233.1
ambient_temperature_k = 296.077

[sensors]
map_noise_std_pa = 924.525
maf_noise_rel = 0.015632
map_gain = 0.995883
map_offset_pa = 61.7314
map_time_constant_s = 0.008618
maf_gain = 1.0014
maf_time_constant_s = 0.012039
"#
        );
        let sc = IntakeScenario::from_toml_str(&text, "test").expect("scenario");
        let mut mon = monitor();
        let changes = feed(&mut mon, simulate(&sc));
        assert!(raised(&changes).is_empty(), "seed {seed}: {changes:?}");
    }
}
