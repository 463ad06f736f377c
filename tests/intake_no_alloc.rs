//! A segment of the intake monitor (three filter architectures, residual tests, the hypothesis
//! bank, the event memory) must not touch the heap in its steady state. A counting global
//! allocator, armed per thread only around the scheduler's steps, proves it over a minute of
//! driving.

use fdd::config::IntakeConfig;
use fdd_estimators::models::intake::{IntakeModel, ThrottleFlow};
use fdd_fixtures::intake_profile::{MixedSpec, ProfileSpec};
use fdd_fixtures::intake_sim::{IntakeFault, IntakeScenario, IntakeSim};
use fdd_monitor::intake::IntakeMonitor;
use fdd_monitor::monitor::Output;
use fdd_monitor::scheduler::Scheduler;
use fdd_monitor::signal_table::SignalTable;

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

const NAMES: [&str; 5] = [
    "engine_speed",
    "intake_throttle",
    "egr_command",
    "map",
    "maf",
];

#[test]
fn intake_monitor_segments_allocate_nothing() {
    let cfg = IntakeConfig::load(None).expect("embedded config");
    let model = IntakeModel::new(cfg.model, ThrottleFlow::Nozzle).expect("model");
    let mut table = SignalTable::with_names(&NAMES, 250_000_000).expect("table");
    let ids = NAMES.map(|n| table.id(n).expect("declared"));
    let monitor = IntakeMonitor::new(&model, &cfg.monitor, &table).expect("monitor");
    let mut sched = Scheduler::new(0);
    sched.add(Box::new(monitor)).expect("schedules");
    let mut outputs = 0u64;
    let mut sink = |_: usize, _: u64, _: Output<'_>| outputs += 1;
    sched.start_operation_cycle(0, &mut sink);
    let sc = IntakeScenario::new(
        "alloc",
        60.0,
        5,
        ProfileSpec::Mixed(MixedSpec::default()),
        IntakeFault::None,
    );
    let (mut counted_steps, mut n, mut segments) = (0, 0, 0);
    for f in IntakeSim::from_scenario(&sc).expect("sim") {
        // The first seconds are warm-up: the residual tests start once the learned corrections
        // have learned for `adapt_min_s` (5 s), and then complete for the first time (0x50 ->
        // 0x00); those status changes are events, which may allocate.
        let warm_up_ns = ((cfg.monitor.adapt_min_s + 2.0) * 1e9) as u64;
        if f.t_ns >= warm_up_ns {
            let (steps, allocations) =
                fdd_testkit::counted(|| sched.run_until(f.t_ns + 1, &table, &mut sink));
            counted_steps += steps;
            n += allocations;
        } else {
            sched.run_until(f.t_ns + 1, &table, &mut sink);
        }
        let values = [f.n_rpm, f.throttle_deg, f.egr_cmd, f.map_pa, f.maf_kg_s];
        for (id, v) in ids.iter().zip(values) {
            table.set(*id, f.t_ns, v).expect("sample");
        }
        segments += 1;
    }
    assert!(segments > 3000, "{segments} segments");
    assert!(counted_steps >= 50_000, "{counted_steps} steps counted");
    assert!(outputs > segments * 10, "the monitor reported its outputs");
    assert_eq!(
        n, 0,
        "{n} heap allocations in {counted_steps} monitor steps"
    );
    let (v, n) = fdd_testkit::counted(|| Box::new(8u8));
    assert_eq!((*v, n), (8, 1));
}
