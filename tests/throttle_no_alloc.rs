//! A step of the throttle monitor (three filters' worth of UKF work, its tests, the event
//! memory) must not touch the heap in its steady state. A counting global allocator, armed per
//! thread only around the scheduler's steps, proves it over ten seconds of 1 kHz data.

use fdd::config::ThrottleConfig;
use fdd_estimators::models::throttle::ThrottleModel;
use fdd_fixtures::scenario::Scenario;
use fdd_fixtures::throttle_sim::{ThrottlePlant, ThrottleSim};
use fdd_monitor::monitor::Output;
use fdd_monitor::scheduler::Scheduler;
use fdd_monitor::signal_table::{SignalSpec, SignalTable};
use fdd_monitor::throttle::ThrottleMonitor;

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

#[test]
fn throttle_monitor_steps_allocate_nothing() {
    let cfg = ThrottleConfig::load(None).expect("embedded config");
    let model = ThrottleModel::new(cfg.model).expect("model");
    let mut table = SignalTable::new(
        ["motor_voltage", "tps", "wattmeter"]
            .iter()
            .map(|n| SignalSpec {
                name: n.to_string(),
                max_age_ns: 5_000_000,
            })
            .collect(),
    )
    .expect("table");
    let ids = ["motor_voltage", "tps", "wattmeter"].map(|n| table.id(n).expect("declared"));
    let monitor = ThrottleMonitor::new(
        model,
        cfg.position_sensor.full_scale_v,
        cfg.position_sensor.full_scale_deg,
        &cfg.monitor,
        &table,
    )
    .expect("monitor");
    let mut sched = Scheduler::new(0);
    sched.add(Box::new(monitor)).expect("schedules");
    let mut outputs = 0u64;
    let mut sink = |_: usize, _: u64, _: Output<'_>| outputs += 1;
    sched.start_operation_cycle(0, &mut sink);
    let plant = ThrottlePlant::from_default_config().expect("plant");
    let sc = Scenario::nominal_throttle("alloc", 10.0, 3);
    let mut counted_steps = 0;
    let mut n = 0;
    for (k, f) in ThrottleSim::new(&sc, &plant).expect("sim").enumerate() {
        // The first second is warm-up: the tests complete for the first time (0x50 -> 0x00),
        // and those status changes are events, which may allocate.
        if k >= 1000 {
            let (steps, allocations) =
                fdd_testkit::counted(|| sched.run_until(f.t_ns, &table, &mut sink));
            counted_steps += steps;
            n += allocations;
        } else {
            sched.run_until(f.t_ns, &table, &mut sink);
        }
        table.set(ids[0], f.t_ns, f.motor_voltage_v).expect("u");
        table.set(ids[1], f.t_ns, f.tps_v).expect("tps");
        table.set(ids[2], f.t_ns, f.wattmeter_w).expect("wattmeter");
    }
    assert!(counted_steps >= 8_999, "{counted_steps} steps counted");
    assert!(outputs > counted_steps, "the monitor reported its outputs");
    assert_eq!(
        n, 0,
        "{n} heap allocations in {counted_steps} monitor steps"
    );
    // The counter does count.
    let (v, n) = fdd_testkit::counted(|| Box::new(8u8));
    assert_eq!((*v, n), (8, 1));
}
