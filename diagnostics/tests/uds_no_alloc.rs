//! Answering UDS DTC requests allocates nothing once the response buffer has room.
//!
//! This binary installs the counting global allocator and sends every supported request
//! (reads of all sub-functions, negative responses, and a ClearDTC of an already clear memory,
//! which emits no event) 1000 times into a buffer reserved with 4095 bytes (the largest ISO-TP
//! message): exactly 0 allocations. A sanity test checks that the counter sees the growth of an
//! unreserved buffer.

use fdd_diagnostics::dtc::{
    DebounceConfig, EventConfig, EventMemory, EventMemoryConfig, ReportContext,
};
use fdd_diagnostics::uds::{handle_request, EventMemoryStore, Reply};
use fdd_diagnostics::{TestResult, Verdict};

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

use fdd_testkit::allocations_in;

fn memory() -> EventMemory {
    let ev = |name: &str, dtc: &str, ff: &[&str]| {
        let mut e = EventConfig::new(name, dtc, 2);
        e.debounce = DebounceConfig::MonitorInternal;
        e.freeze_frame = ff.iter().map(|s| s.to_string()).collect();
        e
    };
    let mut mem = EventMemory::new(&EventMemoryConfig {
        capacity: 4,
        events: vec![
            ev("low", "P0122-16", &["tps_a_v", "engine_speed_rpm"]),
            ev("high", "P0123-17", &["tps_a_v", "throttle_angle_deg"]),
            ev("corr", "P2135-62", &["throttle_angle_deg"]),
        ],
    })
    .unwrap();
    mem.start_operation_cycle(0.0, |_| {}).unwrap();
    let failed = TestResult {
        value: 1.0,
        min: 0.0,
        max: 0.5,
        verdict: Verdict::Failed,
    };
    let id = mem.event_id("low").unwrap();
    mem.report(
        id,
        &failed,
        &ReportContext::at(1.0).with_freeze_frame(&[0.125, 812.5]),
        |_| {},
    )
    .unwrap();
    mem
}

const READS: &[&[u8]] = &[
    &[0x19, 0x01, 0xFF],
    &[0x19, 0x02, 0xFF],
    &[0x19, 0x03],
    &[0x19, 0x04, 0x01, 0x22, 0x16, 0xFF],
    &[0x19, 0x04, 0x21, 0x35, 0x62, 0x01],
    &[0x19, 0x06, 0x01, 0x22, 0x16, 0xFF],
    &[0x19, 0x0A],
    // Negative responses.
    &[0x19, 0x04, 0x01, 0x23, 0x18, 0xFF],
    &[0x19, 0x05, 0x01],
    &[0x19, 0x02],
    &[0x22, 0xF1, 0x90],
];

#[test]
fn requests_allocate_nothing() {
    let mut mem = memory();
    let mut store = EventMemoryStore::new(&mut mem, 2.0, |_| {});
    let mut response = Vec::with_capacity(4095);
    let n = allocations_in(|| {
        for _ in 0..1000 {
            for request in READS {
                let reply = handle_request(&mut store, request, &mut response);
                std::hint::black_box((reply, response.len()));
            }
        }
    });
    assert_eq!(
        n,
        0,
        "allocations answering {} requests",
        1000 * READS.len()
    );

    // ClearDTC: the first one changes the memory (its events allocate); later ones do not.
    assert_eq!(
        handle_request(&mut store, &[0x14, 0xFF, 0xFF, 0xFF], &mut response),
        Reply::Positive
    );
    let n = allocations_in(|| {
        for _ in 0..1000 {
            let reply = handle_request(&mut store, &[0x14, 0xFF, 0xFF, 0xFF], &mut response);
            std::hint::black_box(reply);
        }
    });
    assert_eq!(n, 0, "allocations of ClearDTC on a clear memory");
}

#[test]
fn the_counter_sees_an_unreserved_buffer_grow() {
    let mut mem = memory();
    let mut store = EventMemoryStore::new(&mut mem, 2.0, |_| {});
    let n = allocations_in(|| {
        let mut response = Vec::new();
        handle_request(&mut store, &[0x19, 0x02, 0xFF], &mut response);
        std::hint::black_box(&response);
    });
    assert!(n > 0);
}
