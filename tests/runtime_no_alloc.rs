//! After construction, the runtime's host path (push, queue, advance, drain the event queue,
//! read the DTCs) allocates nothing: a counting global allocator, armed on this thread around
//! the whole loop, proves it over a minute of throttle data (1 kHz) and a crank-synchronous
//! intake log with a leak that raises its DTC, fed at the same time (the intake samples
//! through a ring-buffer queue).

use std::path::Path;

use fdd::replay::RuntimeConfig;
use fdd_monitor::log::LogReader;
use fdd_monitor::runtime::{EventQueue, Runtime};
use fdd_monitor::signal_table::SignalId;

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

/// `(t_ns, signal, value)` of every mapped topic of a fixture, up to `until_ns`.
fn samples(
    rt: &Runtime,
    cfg: &RuntimeConfig,
    name: &str,
    until_ns: u64,
) -> Vec<(u64, SignalId, f64)> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("fixtures/data/{name}.mcap"));
    let mut reader = LogReader::open(&path).expect("fixture");
    let mut out = Vec::new();
    while let Some(m) = reader.next_message() {
        let m = m.expect("readable");
        if m.log_time_ns > until_ns {
            break;
        }
        for s in cfg.signals.iter().filter(|s| s.topic == m.topic) {
            let v = m.field_f64(&s.field).expect("numeric field");
            out.push((m.log_time_ns, rt.signal(&s.name).expect("signal"), v));
        }
    }
    out
}

#[test]
fn push_advance_and_drain_allocate_nothing() {
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let (mut rt, mut producers) = Runtime::builder(cfg.clone())
        .queue("intake", 4096, "P1680-00")
        .build()
        .expect("runtime");
    let throttle = samples(&rt, &cfg, "throttle_nominal", 60_000_000_000);
    let intake = samples(&rt, &cfg, "intake_leak", 60_000_000_000);
    assert!(throttle.len() > 170_000 && intake.len() > 10_000);
    let mut queue = EventQueue::new(256);
    let mut drained = Vec::with_capacity(1024);
    let mut confirmed_or_failed = 0usize;
    let producer = &mut producers[0];
    let mut steps = 0u64;
    rt.start_operation_cycle(0, &mut queue).expect("cycle");

    let allocations = fdd_testkit::allocations_in(|| {
        let mut j = 0;
        let mut i = 0;
        while i < throttle.len() {
            let t = throttle[i].0;
            // Everything stamped before this frame: queued intake samples, then the steps.
            while j < intake.len() && intake[j].0 < t {
                let (ts, id, v) = intake[j];
                assert!(producer.push(id, ts, v), "queue large enough");
                j += 1;
            }
            steps += rt
                .advance_to(t.saturating_sub(1), &mut queue)
                .expect("advance");
            while i < throttle.len() && throttle[i].0 == t {
                let (ts, id, v) = throttle[i];
                rt.push(id, ts, v).expect("sample");
                i += 1;
            }
            if i % 1000 == 0 {
                while let Some(r) = queue.pop() {
                    if drained.len() < drained.capacity() {
                        drained.push(r);
                    }
                }
                confirmed_or_failed = rt.dtcs_by_status_mask(0x09).count();
            }
        }
        steps += rt.advance_to(60_000_000_000, &mut queue).expect("advance");
        while let Some(r) = queue.pop() {
            if drained.len() < drained.capacity() {
                drained.push(r);
            }
        }
    });
    assert_eq!(allocations, 0, "allocations on the host path");
    assert!(steps > 110_000, "{steps} steps");
    assert_eq!(queue.dropped(), 0);
    // The leak was diagnosed during the counted loop, and its freeze frame stored.
    let leak = drained
        .iter()
        .find(|r| r.raised() && r.dtc.to_string() == "P2279-00")
        .expect("leak DTC raised");
    assert!(leak.t_ns > 10_000_000_000);
    assert!(confirmed_or_failed >= 1);
    // Its freeze frame is a snapshot of the moment: a MAP reading of a running engine (the
    // leak is named in a tip-out, 23 kPa) and the pressure estimate beside it.
    let ff = rt.freeze_frame(leak.dtc).expect("stored");
    let value = |name: &str| {
        ff.freeze_frame()
            .find(|(s, _)| *s == name)
            .map(|(_, v)| v)
            .unwrap_or(f64::NAN)
    };
    let map = value("map");
    assert!((10_000.0..110_000.0).contains(&map), "map {map}");
    assert!((value("manifold_pressure") - map).abs() < 5_000.0);
    let st = &rt.queue_stats()[0];
    assert_eq!((st.lost, st.rejected), (0, 0), "{st:?}");
}
