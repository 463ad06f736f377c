//! The event memory's steady state allocates nothing on the heap.
//!
//! Steady state = calls that change no status byte and no memory entry: repeated `Failed` on
//! a failed test, repeated `Passed` on a passed one, pre-results that move the fault detection
//! counter without qualifying, `NotTested`, a failing event that could not be stored because
//! the memory is full, operation cycles and ClearDTC on events that are already in the
//! resulting state, and the queries. Everything is allocated in `EventMemory::new`; only the
//! `DiagnosticEvent`s emitted on a change allocate. This binary installs a counting global
//! allocator and asserts exactly 0 allocations over 1000 repetitions of each; a sanity test
//! checks that the counter does see the allocations of a status change.
//!
//! Only allocations made by the measuring thread while a section is open are counted
//! (thread-local flag and counter), so tests running in parallel cannot disturb each other.

use std::hint::black_box;

use fdd_diagnostics::dtc::{
    CounterDebounce, DebounceConfig, DtcGroup, EventConfig, EventId, EventMemory,
    EventMemoryConfig, ReportContext, TimeDebounce,
};
use fdd_diagnostics::event::DiagnosticEvent;
use fdd_diagnostics::{TestResult, Verdict};

const STEPS: usize = 1000;

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

use fdd_testkit::allocations_in;

fn result(verdict: Verdict) -> TestResult {
    TestResult {
        value: 1.0,
        min: 0.0,
        max: 5.0,
        verdict,
    }
}

fn memory() -> EventMemory {
    let ff = |e: &mut EventConfig| e.freeze_frame = vec!["u_v".into(), "speed".into()];
    let mut counter = EventConfig::new("counter", "P0123-1C", 3);
    counter.debounce = DebounceConfig::Counter(CounterDebounce {
        increment_step: 3,
        decrement_step: 2,
        failed_threshold: 30,
        passed_threshold: -30,
        jump_up: true,
        ..Default::default()
    });
    ff(&mut counter);
    let mut time = EventConfig::new("time", "P2279-7A", 3);
    time.debounce = DebounceConfig::Time(TimeDebounce {
        failed_time_s: 0.5,
        passed_time_s: 0.5,
    });
    let mut internal = EventConfig::new("internal", "C0035-00", 3);
    internal.debounce = DebounceConfig::MonitorInternal;
    ff(&mut internal);
    // Capacity 3 with 4 events: "overflow" (lowest priority) cannot be stored once full.
    let overflow = EventConfig::new("overflow", "U0100-00", 9);
    let idle = EventConfig::new("idle", "B1234-00", 5);
    EventMemory::new(&EventMemoryConfig {
        capacity: 3,
        events: vec![counter, time, internal, overflow, idle],
    })
    .unwrap()
}

struct Ids {
    counter: EventId,
    time: EventId,
    internal: EventId,
    overflow: EventId,
}

fn ids(mem: &EventMemory) -> Ids {
    Ids {
        counter: mem.event_id("counter").unwrap(),
        time: mem.event_id("time").unwrap(),
        internal: mem.event_id("internal").unwrap(),
        overflow: mem.event_id("overflow").unwrap(),
    }
}

#[test]
fn steady_state_reports_do_not_allocate() {
    let mut mem = memory();
    let id = ids(&mem);
    let mut events: Vec<DiagnosticEvent> = Vec::with_capacity(64);
    let ff = [12.0, 33.0];
    let cands = [("stuck", 0.8), ("bias", 0.2)];
    let mut t = 0.0;
    mem.start_operation_cycle(t, |e| events.push(e)).unwrap();
    // Fill the memory and qualify every event once (this allocates: events are emitted).
    for e in [id.counter, id.internal, id.time, id.overflow] {
        let ctx = ReportContext::at(t).with_candidates(&cands);
        let ctx = if mem.event_info(e).name == "time" || e == id.overflow {
            ctx
        } else {
            ctx.with_freeze_frame(&ff)
        };
        mem.report(e, &result(Verdict::Failed), &ctx, |e| events.push(e))
            .unwrap();
    }
    assert_eq!(mem.entries_used(), 3);
    assert!(mem.overflow());
    assert!(mem.entry(id.overflow).is_none());
    events.clear();

    let mut step = |mem: &mut EventMemory, e: EventId, v: Verdict, events: &mut Vec<_>| {
        t += 0.001;
        let ctx = ReportContext::at(t).with_candidates(&cands);
        let ctx = if e == id.counter || e == id.internal {
            ctx.with_freeze_frame(&ff)
        } else {
            ctx
        };
        mem.report(e, &result(v), &ctx, |ev| events.push(ev))
            .unwrap()
    };

    // Repeated FAILED (and saturated PRE_FAILED) on failed tests; a not-stored failing event.
    let n = allocations_in(|| {
        for _ in 0..STEPS {
            black_box(step(&mut mem, id.counter, Verdict::Failed, &mut events));
            black_box(step(&mut mem, id.counter, Verdict::PreFailed, &mut events));
            black_box(step(&mut mem, id.time, Verdict::PreFailed, &mut events));
            black_box(step(&mut mem, id.time, Verdict::Failed, &mut events));
            black_box(step(&mut mem, id.internal, Verdict::Failed, &mut events));
            black_box(step(&mut mem, id.overflow, Verdict::Failed, &mut events));
            black_box(step(&mut mem, id.internal, Verdict::PreFailed, &mut events));
            black_box(step(&mut mem, id.counter, Verdict::NotTested, &mut events));
        }
    });
    assert_eq!(n, 0, "repeated failures allocated {n} times");
    assert!(events.is_empty(), "no status changed");

    // Qualify passes (allocates), then repeated PASSED / saturated PRE_PASSED.
    for e in [id.counter, id.time, id.internal, id.overflow] {
        step(&mut mem, e, Verdict::Passed, &mut events);
    }
    events.clear();
    let n = allocations_in(|| {
        for _ in 0..STEPS {
            black_box(step(&mut mem, id.counter, Verdict::Passed, &mut events));
            black_box(step(&mut mem, id.counter, Verdict::PrePassed, &mut events));
            black_box(step(&mut mem, id.time, Verdict::PrePassed, &mut events));
            black_box(step(&mut mem, id.internal, Verdict::Passed, &mut events));
            black_box(step(&mut mem, id.internal, Verdict::PrePassed, &mut events));
            black_box(step(&mut mem, id.overflow, Verdict::Passed, &mut events));
        }
    });
    assert_eq!(n, 0, "repeated passes allocated {n} times");
    assert!(events.is_empty());

    // Pre-results that move the FDC without qualifying: from -30 the first PRE_FAILED jumps up
    // to 0 and steps to 3; then the counter cycles 3 -> 1 -> -1 -> (jump) 3.
    let n = allocations_in(|| {
        for _ in 0..STEPS {
            black_box(step(&mut mem, id.counter, Verdict::PreFailed, &mut events));
            black_box(step(&mut mem, id.counter, Verdict::PrePassed, &mut events));
            black_box(step(&mut mem, id.counter, Verdict::PrePassed, &mut events));
            black_box(mem.fdc(id.counter));
        }
    });
    assert_eq!(n, 0, "pre-results allocated {n} times");
    assert!(events.is_empty());
    assert!(mem.fdc(id.counter) > -128 && mem.fdc(id.counter) < 127);
}

#[test]
fn unchanged_cycles_clears_and_queries_do_not_allocate() {
    let mut mem = memory();
    let id = ids(&mem);
    let mut events: Vec<DiagnosticEvent> = Vec::with_capacity(64);
    let mut t = 0.0;
    // Never tested events stay 0x50 through cycles; ClearDTC of a cleared memory changes nothing.
    let n = allocations_in(|| {
        for _ in 0..STEPS {
            t += 1.0;
            mem.start_operation_cycle(t, |e| events.push(e)).unwrap();
            mem.end_operation_cycle(t, |e| events.push(e)).unwrap();
            mem.clear_dtc(DtcGroup::All, t, |e| events.push(e)).unwrap();
        }
    });
    assert_eq!(n, 0, "unchanged cycles allocated {n} times");
    assert!(events.is_empty());

    mem.start_operation_cycle(t, |e| events.push(e)).unwrap();
    let ff = [1.0, 2.0];
    mem.report(
        id.counter,
        &result(Verdict::Failed),
        &ReportContext::at(t).with_freeze_frame(&ff),
        |e| events.push(e),
    )
    .unwrap();
    let n = allocations_in(|| {
        for _ in 0..STEPS {
            black_box(mem.status(id.counter));
            black_box(mem.event_info(id.time));
            black_box(mem.dtcs_by_status_mask(0x04).count());
            black_box(mem.mil_on());
            let entry = mem.entry(id.counter).unwrap();
            black_box(entry.freeze_frame().map(|(_, v)| v).sum::<f64>());
            black_box(mem.entries().count());
            black_box(mem.event_id("internal"));
            black_box(mem.dtc(id.internal).to_ascii());
        }
    });
    assert_eq!(n, 0, "queries allocated {n} times");
}

/// The counter works: a status change emits a `DiagnosticEvent`, which allocates.
#[test]
fn counter_sees_the_allocations_of_a_status_change() {
    let mut mem = memory();
    let id = ids(&mem);
    let mut events: Vec<DiagnosticEvent> = Vec::with_capacity(64);
    mem.start_operation_cycle(0.0, |e| events.push(e)).unwrap();
    let n = allocations_in(|| {
        mem.report(
            id.internal,
            &result(Verdict::Failed),
            &ReportContext::at(1.0),
            |e| events.push(e),
        )
        .unwrap();
    });
    assert!(n > 0, "an emitted event must be seen allocating");
    assert_eq!(events.len(), 1);
}
