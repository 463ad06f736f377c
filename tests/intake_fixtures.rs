//! The intake monitor end to end: the committed intake MCAP fixtures replayed through the
//! monitor segment by segment, plus in-memory simulations over several seeds and a 30-minute
//! nominal drive.
//!
//! For every fault fixture: the fault is detected (a residual test fails) within 2 s of driving
//! in which it is observable (the truth's `fault_observable`), the specific DTC raised is the
//! injected fault's and no other (the group DTC `intake_air_path_group` may come first, while
//! isolation is still deciding), and the top-ranked isolation candidate of the specific DTC is
//! the injected fault. The nominal fixture and a generated 30-minute drive raise nothing. The
//! in-memory simulations run the truth simulator's own plant ([`IntakeSim::from_scenario`]).
//!
//! `cargo test --release --test intake_fixtures -- --nocapture` prints the measured delays.

use std::path::{Path, PathBuf};

use fdd_diagnostics::dtc::StatusBit;
use fdd_diagnostics::Verdict;
use fdd_fixtures::intake_profile::{MixedSpec, ProfileSpec, TipInOutSpec};
use fdd_fixtures::intake_sim::{default_intake_model, IntakeFault, IntakeScenario, IntakeSim};
// `default_intake_model` is the *monitor's* model (config/intake.toml); the truth is the
// simulator's plant (fixtures/plants/intake.toml) through `IntakeSim::from_scenario`.
use fdd_monitor::intake::{
    IntakeDecision, IntakeMonitor, IntakeMonitorConfig, Segment, GROUP_EVENT,
};
use fdd_monitor::log::LogReader;
use fdd_monitor::monitor::{Monitor, Output};
use fdd_monitor::signal_table::SignalTable;

/// One segment with what the truth says about the fault.
struct Frame {
    t_ns: u64,
    seg: Segment,
    fault_active: bool,
    observable: bool,
}

/// What a run produced.
#[derive(Debug, Default)]
struct Outcome {
    /// Observable driving time (s) from the onset to the first failed residual test, and to
    /// the DTC.
    detected_after_s: Option<f64>,
    decided_after_s: Option<f64>,
    /// Wall time (s) from the onset to the DTC.
    decided_wall_s: Option<f64>,
    decision: Option<IntakeDecision>,
    /// Events whose testFailed bit was raised.
    raised: Vec<String>,
    /// Top-ranked candidate of the first specific DTC (from the DTC's DiagnosticEvent).
    top_candidate: Option<String>,
    /// The group DTC's candidates, if one was raised.
    group_candidates: Vec<String>,
    /// Observable driving time after the onset, over the whole run (s).
    observable_s: f64,
}

fn table() -> SignalTable {
    // One segment of 100 ms at the slowest speed the model accepts; 250 ms is lost.
    SignalTable::with_names(&IntakeMonitorConfig::default().signal_names(), 250_000_000)
        .expect("table")
}

const RESIDUAL_TESTS: [&str; 7] = [
    "intake_map_frozen",
    "intake_maf_frozen",
    "intake_pressure_consistency",
    "intake_flow_consistency",
    "intake_throttle_model",
    "intake_centralized_nis",
    "intake_federated_nis",
];

fn run(frames: impl Iterator<Item = Frame>) -> Outcome {
    let model = default_intake_model();
    let mut mon =
        IntakeMonitor::new(&model, &IntakeMonitorConfig::default(), &table()).expect("monitor");
    let mut o = Outcome::default();
    mon.start_operation_cycle(0, &mut |_| {});
    let mut onset_ns: Option<u64> = None;
    let mut observable = 0.0;
    for f in frames {
        if f.fault_active && onset_ns.is_none() {
            onset_ns = Some(f.t_ns);
        }
        let mut failed_residual = false;
        let mut raised = Vec::new();
        let mut top = None;
        let mut group: Vec<String> = Vec::new();
        mon.process_segment(f.t_ns, &f.seg, &mut |out| match out {
            Output::Test { test, result }
                if result.verdict == Verdict::Failed && RESIDUAL_TESTS.contains(&test) =>
            {
                failed_residual = true;
            }
            Output::Event(ev)
                if ev.bit_changed(StatusBit::TestFailed) && ev.status_after.test_failed() =>
            {
                raised.push(ev.event.to_string());
                if ev.event == GROUP_EVENT {
                    group = ev.candidates.iter().map(|c| c.0.to_string()).collect();
                } else {
                    if top.is_none() {
                        top = ev.candidates.first().map(|c| c.0.to_string());
                    }
                }
            }
            _ => {}
        });
        if o.group_candidates.is_empty() {
            o.group_candidates = std::mem::take(&mut group);
        }
        if f.observable {
            observable += IntakeModel::segment_dt(f.seg.speed_rpm);
        }
        if onset_ns.is_some() {
            if failed_residual && o.detected_after_s.is_none() {
                o.detected_after_s = Some(observable);
            }
            if !raised.is_empty() && o.decided_after_s.is_none() {
                o.decided_after_s = Some(observable);
                o.decided_wall_s = onset_ns.map(|t0| (f.t_ns - t0) as f64 * 1e-9);
            }
        }
        if !raised.is_empty() {
            o.top_candidate = o.top_candidate.or(top);
        }
        o.raised.extend(raised);
    }
    o.decision = mon.decision();
    o.observable_s = observable;
    o
}

use fdd_estimators::models::intake::IntakeModel;

fn fixture_frames(path: &Path) -> Vec<Frame> {
    let mut reader = LogReader::open(path).expect("open fixture");
    let mut frames: Vec<Frame> = Vec::new();
    let mut cur: Option<Frame> = None;
    while let Some(m) = reader.next_message() {
        let m = m.expect("message");
        let t = m.log_time_ns;
        if cur.as_ref().is_some_and(|c| c.t_ns != t) {
            frames.extend(cur.take());
        }
        let c = cur.get_or_insert(Frame {
            t_ns: t,
            seg: Segment {
                speed_rpm: f64::NAN,
                throttle_deg: f64::NAN,
                egr_cmd: f64::NAN,
                map_pa: f64::NAN,
                maf_kg_s: f64::NAN,
            },
            fault_active: false,
            observable: false,
        });
        let v = |field: &str| m.field_f64(field).expect("numeric field");
        match m.topic {
            "/intake/engine_speed" => c.seg.speed_rpm = v("speed_rpm"),
            "/intake/throttle" => c.seg.throttle_deg = v("angle_deg"),
            "/intake/egr_command" => c.seg.egr_cmd = v("position"),
            "/intake/map" => c.seg.map_pa = v("pressure_pa"),
            "/intake/maf" => c.seg.maf_kg_s = v("flow_kg_s"),
            "/truth/intake" => {
                let j = m.json().expect("truth json");
                c.fault_active = j["fault_active"].as_bool().expect("fault_active");
                c.observable = j["fault_observable"].as_bool().expect("fault_observable");
            }
            other => panic!("{}: unexpected topic {other}", path.display()),
        }
    }
    frames.extend(cur);
    frames
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/data")
        .join(format!("{name}.mcap"))
}

/// (fixture, expected event, expected top candidate)
const FAULTS: [(&str, &str, &str); 5] = [
    ("intake_map_bias", "map_range_performance", "map_sensor"),
    ("intake_maf_gain", "maf_range_performance", "maf_sensor"),
    ("intake_egr_stuck_open", "egr_flow_excessive", "egr_valve"),
    (
        "intake_egr_stuck_closed",
        "egr_flow_insufficient",
        "egr_valve",
    ),
    ("intake_leak", "intake_leak", "manifold_leak"),
];

/// The specific DTCs raised (the group DTC left out), and whether a group DTC came only before
/// the first of them.
fn specific(o: &Outcome) -> (Vec<String>, bool) {
    let first = o.raised.iter().position(|e| e != GROUP_EVENT);
    let group_after = o
        .raised
        .iter()
        .enumerate()
        .any(|(i, e)| e == GROUP_EVENT && first.is_some_and(|f| i > f));
    (
        o.raised
            .iter()
            .filter(|e| *e != GROUP_EVENT)
            .cloned()
            .collect(),
        !group_after,
    )
}

/// Like [`check`], on a random drive: an EGR valve stuck at 0.3 gives too much or too little
/// flow depending on the commands it meets, so either EGR DTC is right; a fault observable for
/// less than 2 s need not be found. The detection bound is 3 s of observable driving here (2 s
/// before the monitor allowed for model error): a valve stuck 0.05..0.1 from a part-load
/// command counts as observable but stays within the residuals' model-error allowance, and
/// the random drives meet such commands first.
fn check_random_drive(label: &str, o: &Outcome, events: &[&str], candidate: &str) {
    println!(
        "{label:28} observable {:>6.2} s, detected after {:>6} s observable, DTC {:22} after {:>6} s observable, top candidate {}",
        o.observable_s,
        o.detected_after_s.map_or("-".into(), |v| format!("{v:.3}")),
        o.raised.first().map_or("none", |s| s.as_str()),
        o.decided_after_s.map_or("-".into(), |v| format!("{v:.3}")),
        o.top_candidate.as_deref().unwrap_or("-"),
    );
    let (spec, group_first) = specific(o);
    if o.observable_s < 2.0 {
        assert!(spec.len() <= 1, "{label}: {:?}", o.raised);
        return;
    }
    let det = o
        .detected_after_s
        .unwrap_or_else(|| panic!("{label}: not detected"));
    assert!(det <= 3.0, "{label}: detected after {det:.3} s observable");
    assert_eq!(spec.len(), 1, "{label}: DTCs raised {:?}", o.raised);
    assert!(group_first, "{label}: {:?}", o.raised);
    assert!(
        events.contains(&spec[0].as_str()),
        "{label}: {:?}",
        o.raised
    );
    assert_eq!(o.top_candidate.as_deref(), Some(candidate), "{label}");
    if !o.group_candidates.is_empty() {
        assert!(
            o.group_candidates.iter().any(|c| c == candidate),
            "{label}: group candidates {:?}",
            o.group_candidates
        );
    }
}

/// The fitted fault size, in words.
fn fitted(o: &Outcome) -> String {
    match o.decision {
        Some(IntakeDecision::Residual { fit, .. }) => match fit.fault.name() {
            "map_sensor" => format!("offset {:.0} Pa, gain error {:.3}", fit.parameter, fit.gain),
            "maf_sensor" => format!("gain {:.3}", 1.0 + fit.parameter),
            "egr_valve" => format!("stuck at {:.2}", fit.parameter),
            _ => format!(
                "hole {:.2} mm",
                (4.0 * fit.parameter / std::f64::consts::PI).sqrt() * 1e3
            ),
        },
        _ => "-".into(),
    }
}

fn check(label: &str, o: &Outcome, event: &str, candidate: &str) {
    println!(
        "{label:28} detected after {:>6} s observable, first DTC {:22} after {:>6} s observable ({:>6} s from onset), top candidate {} ({})",
        o.detected_after_s.map_or("-".into(), |v| format!("{v:.3}")),
        o.raised.first().map_or("none", |s| s.as_str()),
        o.decided_after_s.map_or("-".into(), |v| format!("{v:.3}")),
        o.decided_wall_s.map_or("-".into(), |v| format!("{v:.3}")),
        o.top_candidate.as_deref().unwrap_or("-"),
        fitted(o),
    );
    let det = o
        .detected_after_s
        .unwrap_or_else(|| panic!("{label}: not detected"));
    assert!(det <= 2.0, "{label}: detected after {det:.3} s observable");
    let dtc = o
        .decided_after_s
        .unwrap_or_else(|| panic!("{label}: no DTC"));
    assert!(dtc <= 2.0, "{label}: first DTC after {dtc:.3} s observable");
    let (spec, group_first) = specific(o);
    assert_eq!(
        spec,
        vec![event.to_string()],
        "{label}: DTCs raised {:?}",
        o.raised
    );
    assert!(
        group_first,
        "{label}: group DTC after the specific one: {:?}",
        o.raised
    );
    assert_eq!(
        o.top_candidate.as_deref(),
        Some(candidate),
        "{label}: top-ranked candidate"
    );
    if !o.group_candidates.is_empty() {
        assert!(
            o.group_candidates.iter().any(|c| c == candidate),
            "{label}: group candidates {:?}",
            o.group_candidates
        );
    }
}

#[test]
fn every_fault_fixture_is_detected_and_isolated() {
    for (name, event, candidate) in FAULTS {
        let frames = fixture_frames(&fixture(name));
        assert!(frames.len() > 1000, "{name}: {} segments", frames.len());
        let o = run(frames.into_iter());
        assert!(
            o.observable_s > 5.0,
            "{name}: observable {} s",
            o.observable_s
        );
        check(name, &o, event, candidate);
    }
}

#[test]
fn nominal_fixture_raises_nothing() {
    let frames = fixture_frames(&fixture("intake_nominal"));
    assert!(frames.len() > 10_000, "{} segments", frames.len());
    let o = run(frames.into_iter());
    assert!(o.raised.is_empty(), "{:?}", o.raised);
    assert!(o.decision.is_none());
}

fn sim_frames(scenario: IntakeScenario) -> impl Iterator<Item = Frame> {
    let sim = IntakeSim::from_scenario(&scenario).expect("scenario");
    sim.map(|f| Frame {
        t_ns: f.t_ns,
        seg: Segment {
            speed_rpm: f.n_rpm,
            throttle_deg: f.throttle_deg,
            egr_cmd: f.egr_cmd,
            map_pa: f.map_pa,
            maf_kg_s: f.maf_kg_s,
        },
        fault_active: f.fault_active,
        observable: f.fault_observable(),
    })
}

#[test]
fn thirty_minute_nominal_drive_raises_nothing() {
    let sc = IntakeScenario::new(
        "nominal_30min",
        1800.0,
        2026,
        ProfileSpec::Mixed(MixedSpec::default()),
        IntakeFault::None,
    );
    let o = run(sim_frames(sc));
    assert!(o.raised.is_empty(), "{:?}", o.raised);
    assert!(o.decision.is_none());
}

/// 60-s drives: a leak and an EGR valve stuck open differ on tip-outs by about 2 % of their
/// isolation statistics, and the isolation margin of 300 can take tens of seconds to be reached
/// (the committed EGR fixture: 27 s after the onset; the group DTC comes within a second).
#[test]
fn faults_are_isolated_over_several_seeds() {
    let profile = ProfileSpec::TipInOut(TipInOutSpec {
        egr_pos: 0.3,
        ..TipInOutSpec::default()
    });
    let faults = [
        (
            IntakeFault::MapBias {
                start_s: 10.0,
                bias_pa: 5000.0,
            },
            "map_range_performance",
            "map_sensor",
        ),
        (
            IntakeFault::MafGain {
                start_s: 10.0,
                gain: 1.1,
            },
            "maf_range_performance",
            "maf_sensor",
        ),
        (
            IntakeFault::EgrStuckOpen {
                start_s: 10.0,
                position: 0.3,
            },
            "egr_flow_excessive",
            "egr_valve",
        ),
        (
            IntakeFault::EgrStuckClosed { start_s: 10.0 },
            "egr_flow_insufficient",
            "egr_valve",
        ),
        (
            IntakeFault::Leak {
                start_s: 10.0,
                diameter_m: 0.003,
            },
            "intake_leak",
            "manifold_leak",
        ),
        // The simulator's other sensor faults: a MAP gain error shows as a pressure-dependent
        // bias, a MAF offset as a flow error the throttle model sees, a stuck MAP as a frozen
        // reading.
        (
            IntakeFault::MapGain {
                start_s: 10.0,
                gain: 1.08,
            },
            "map_range_performance",
            "map_sensor",
        ),
        (
            IntakeFault::MafBias {
                start_s: 10.0,
                bias_kg_s: 0.002,
            },
            "maf_range_performance",
            "maf_sensor",
        ),
        (
            IntakeFault::MapStuck { start_s: 10.0 },
            "map_range_performance",
            "map_sensor",
        ),
    ];
    for (fault, event, candidate) in faults {
        for seed in 101..=106 {
            let sc = IntakeScenario::new("seeds", 60.0, seed, profile, fault);
            let o = run(sim_frames(sc));
            check(
                &format!("{} seed {seed}", fault.name()),
                &o,
                event,
                candidate,
            );
        }
    }
}

/// A segment at 1500 rpm and 5 deg of throttle with the readings of the model's steady state,
/// with speed and MAP replaced.
fn segment(speed_rpm: f64, map_pa: f64) -> Segment {
    let u = fdd_estimators::models::intake::IntakeInput::new(1500.0, 5.0, 0.0);
    let x = default_intake_model()
        .equilibrium(&u)
        .expect("steady state");
    Segment {
        speed_rpm,
        throttle_deg: 5.0,
        egr_cmd: 0.0,
        map_pa,
        maf_kg_s: x[3],
    }
}

/// Engine speed 0, negative or NaN, NaN readings: the segment is skipped with a failed
/// `intake_input_range` test naming the value, nothing reaches the filters, no DTC, and the
/// filters carry on afterwards with finite states. A MAP reading above what a naturally
/// aspirated manifold can reach is kept out of the filters and, when it persists, is the MAP
/// circuit-high DTC.
#[test]
fn bad_input_is_refused_without_nan_or_panic() {
    let model = default_intake_model();
    let cfg = IntakeMonitorConfig::default();
    let mut mon = IntakeMonitor::new(&model, &cfg, &table()).expect("monitor");
    mon.start_operation_cycle(0, &mut |_| {});
    let mut t = 0u64;
    let mut feed = |mon: &mut IntakeMonitor, mut seg: Segment| {
        t += 10_000_000;
        // Sensor noise (a reading repeated exactly is a stuck sensor): +-100 Pa, +-0.5 %.
        let wiggle = ((t / 10_000_000) % 7) as f64 - 3.0;
        seg.map_pa += 33.0 * wiggle;
        seg.maf_kg_s *= 1.0 + 0.0017 * wiggle;
        let mut refused = Vec::new();
        let mut raised = Vec::new();
        mon.process_segment(t, &seg, &mut |o| match o {
            Output::Test { test, result }
                if test == "intake_input_range" && result.verdict == Verdict::Failed =>
            {
                refused.push(result.value)
            }
            Output::Event(ev)
                if ev.bit_changed(StatusBit::TestFailed) && ev.status_after.test_failed() =>
            {
                raised.push(ev.event.to_string())
            }
            _ => {}
        });
        (refused, raised)
    };
    // A healthy start: the filters run.
    let u = fdd_estimators::models::intake::IntakeInput::new(1500.0, 5.0, 0.0);
    let p_idle = model.equilibrium(&u).expect("steady state")[0];
    for _ in 0..50 {
        let (r, d) = feed(&mut mon, segment(1500.0, p_idle));
        assert!(r.is_empty() && d.is_empty());
    }
    let before = mon.counts();
    for (speed, map) in [
        (0.0, p_idle),
        (-800.0, p_idle),
        (f64::NAN, p_idle),
        (f64::INFINITY, p_idle),
        (1500.0, f64::NAN),
    ] {
        let (refused, raised) = feed(&mut mon, segment(speed, map));
        assert_eq!(refused.len(), 1, "speed {speed}, MAP {map}: {refused:?}");
        let v = refused[0];
        assert!(
            v == speed || v == map || (v.is_nan() && (speed.is_nan() || map.is_nan())),
            "the refused value is named: {v}"
        );
        assert!(raised.is_empty(), "{raised:?}");
        let x = mon.centralized_state().expect("filters run");
        assert!(x.iter().all(|v| v.is_finite()), "{x:?}");
    }
    let after = mon.counts();
    assert_eq!(after.1 - before.1, 5, "five segments skipped");
    assert_eq!(after.2, 0, "no filter refused a step");

    // MAP far above ambient (115 kPa against 101.3 kPa): out of the circuit range, never in
    // the filters; persistent, it is the circuit-high DTC.
    let mut raised_all = Vec::new();
    for _ in 0..cfg.circuit_persist_segments {
        let (_, raised) = feed(&mut mon, segment(1500.0, 115_000.0));
        raised_all.extend(raised);
        let x = mon.centralized_state().expect("filters run");
        assert!(x[0] < 60_000.0, "the filters never saw the reading: {x:?}");
    }
    assert_eq!(raised_all, vec!["map_circuit_high".to_string()]);
    assert!(mon
        .centralized_state()
        .expect("filters")
        .iter()
        .all(|v| v.is_finite()));
}

/// The `[monitor]` table of the embedded config/intake.toml states the defaults, so the file
/// documents what runs; an unknown key there is an error naming it.
#[test]
fn embedded_monitor_table_is_the_default_and_unknown_keys_are_refused() {
    let c = fdd::config::IntakeConfig::load(None).expect("embedded config");
    assert_eq!(c.monitor, IntakeMonitorConfig::default());
    let text = format!(
        "{}\nisolation_margni = 3.0\n",
        fdd::config::DEFAULT_INTAKE_TOML
    );
    let err = fdd::config::IntakeConfig::parse(&text, "bad.toml")
        .expect_err("unknown key")
        .to_string();
    assert!(
        err.contains("bad.toml") && err.contains("isolation_margni"),
        "{err}"
    );
}

/// The same faults on the `mixed` random drive (speed steps over 800..6000 rpm, tip-ins, EGR
/// on at part load with commands of 0.2..0.5): different operating points, EGR commands that
/// move while the valve is stuck.
#[test]
fn faults_are_isolated_on_random_drives() {
    let profile = ProfileSpec::Mixed(MixedSpec::default());
    let egr = ["egr_flow_insufficient", "egr_flow_excessive"];
    let faults: [(IntakeFault, &[&str], &str); 5] = [
        (
            IntakeFault::MapBias {
                start_s: 10.0,
                bias_pa: 5000.0,
            },
            &["map_range_performance"],
            "map_sensor",
        ),
        (
            IntakeFault::MafGain {
                start_s: 10.0,
                gain: 1.1,
            },
            &["maf_range_performance"],
            "maf_sensor",
        ),
        (
            IntakeFault::EgrStuckOpen {
                start_s: 10.0,
                position: 0.3,
            },
            &egr,
            "egr_valve",
        ),
        (
            IntakeFault::EgrStuckClosed { start_s: 10.0 },
            &egr,
            "egr_valve",
        ),
        (
            IntakeFault::Leak {
                start_s: 10.0,
                diameter_m: 0.003,
            },
            &["intake_leak"],
            "manifold_leak",
        ),
    ];
    for (fault, events, candidate) in faults {
        for seed in 201..=205 {
            let sc = IntakeScenario::new("random", 40.0, seed, profile, fault);
            let o = run(sim_frames(sc));
            check_random_drive(
                &format!("{} mixed seed {seed}", fault.name()),
                &o,
                events,
                candidate,
            );
        }
    }
}

/// `primary_filter` chooses whose estimate is the output; all three track the true manifold
/// pressure (the naive decentralized fusion included: its covariance is optimistic, its mean is
/// fine).
#[test]
fn the_primary_filter_gives_the_output() {
    use fdd_monitor::intake::PrimaryFilter;
    for (primary, source) in [
        (PrimaryFilter::Centralized, "centralized_ekf"),
        (PrimaryFilter::Decentralized, "decentralized_ekf"),
        (PrimaryFilter::Federated, "federated_ekf"),
    ] {
        let cfg = IntakeMonitorConfig {
            primary_filter: primary,
            ..IntakeMonitorConfig::default()
        };
        let mut mon = IntakeMonitor::new(&default_intake_model(), &cfg, &table()).expect("monitor");
        mon.start_operation_cycle(0, &mut |_| {});
        let sc = IntakeScenario::new(
            "primary",
            20.0,
            9,
            ProfileSpec::TipInOut(TipInOutSpec::default()),
            IntakeFault::None,
        );
        let (mut n, mut sq) = (0u32, 0.0);
        for f in IntakeSim::from_scenario(&sc).expect("sim") {
            let seg = Segment {
                speed_rpm: f.n_rpm,
                throttle_deg: f.throttle_deg,
                egr_cmd: f.egr_cmd,
                map_pa: f.map_pa,
                maf_kg_s: f.maf_kg_s,
            };
            mon.process_segment(f.t_ns, &seg, &mut |o| {
                if let Output::Estimate {
                    name: "manifold_pressure",
                    value,
                    source: s,
                    ..
                } = o
                {
                    assert_eq!(s, source);
                    n += 1;
                    sq += (value - f.truth.p_m).powi(2);
                }
            });
        }
        let rmse = (sq / f64::from(n)).sqrt();
        println!("{source}: {n} estimates, RMSE {rmse:.1} Pa");
        assert!(
            n > 1000 && rmse < 600.0,
            "{source}: {n} estimates, RMSE {rmse:.1} Pa"
        );
    }
}

/// Circuit low is judged against the model. Tip-outs from 5000-5800 rpm to a closed plate
/// (simulated: the truth simulator's manifold, pulsation and sensor noise) pull the manifold
/// far below `map_low_pa` for many segments in a row, and the MAF then reads only the plate's
/// leakage, below `maf_low_kg_s`: a healthy pair of sensors, so nothing may be raised. Then, at
/// idle, a MAP reading 0 Pa (open circuit) where the model puts the manifold at idle pressure is
/// the circuit-low DTC after `circuit_persist_segments`.
#[test]
fn circuit_low_only_where_the_model_rules_the_reading_out() {
    let cfg = IntakeMonitorConfig::default();
    let profile = ProfileSpec::TipInOut(TipInOutSpec {
        low_throttle_deg: 0.0,
        speed_rpm: [5000.0, 5800.0],
        ..TipInOutSpec::default()
    });
    let sc = IntakeScenario::new("overrun", 30.0, 7, profile, IntakeFault::None);
    let frames: Vec<Frame> = sim_frames(sc).collect();
    // The longest run of MAP readings below the limit.
    let (mut run_len, mut longest) = (0u32, 0u32);
    for f in &frames {
        run_len = if f.seg.map_pa < cfg.map_low_pa {
            run_len + 1
        } else {
            0
        };
        longest = longest.max(run_len);
    }
    assert!(
        longest >= 5 * cfg.circuit_persist_segments,
        "the drive reaches the circuit-low range: {longest} segments in a row"
    );
    let o = run(frames.into_iter());
    assert!(
        o.raised.is_empty(),
        "healthy sensors at overrun: {:?}",
        o.raised
    );

    let model = default_intake_model();
    let mut mon = IntakeMonitor::new(&model, &cfg, &table()).expect("monitor");
    mon.start_operation_cycle(0, &mut |_| {});
    let mut raised = Vec::new();
    for k in 0..60u64 {
        // Sensor noise (a reading repeated exactly is a stuck sensor): +-100 Pa, +-0.5 %.
        let wiggle = (k % 7) as f64 - 3.0;
        let mut seg = segment(1500.0, 0.0);
        seg.map_pa = if k < 50 {
            seg_idle_map() + 33.0 * wiggle
        } else {
            0.0
        };
        seg.maf_kg_s *= 1.0 + 0.0017 * wiggle;
        mon.process_segment((k + 1) * 10_000_000, &seg, &mut |o| {
            if let Output::Event(ev) = o {
                if ev.bit_changed(StatusBit::TestFailed) && ev.status_after.test_failed() {
                    raised.push(ev.event.to_string());
                }
            }
        });
        if k == 49 {
            assert!(raised.is_empty(), "healthy idle: {raised:?}");
        }
    }
    assert_eq!(raised, vec!["map_circuit_low".to_string()]);
}

/// The model's idle manifold pressure for [`segment`] (1500 rpm, 5 deg).
fn seg_idle_map() -> f64 {
    let u = fdd_estimators::models::intake::IntakeInput::new(1500.0, 5.0, 0.0);
    default_intake_model()
        .equilibrium(&u)
        .expect("steady state")[0]
}
