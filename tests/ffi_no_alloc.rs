//! The C ABI's host path allocates nothing: a counting global allocator, armed on this
//! thread around `fdd_push_batch`, `fdd_push`, `fdd_advance_to` and `fdd_events_drain`, over
//! a minute of 1 kHz throttle data and an intake log whose leak raises its DTC in that time.

use std::ffi::CString;
use std::path::Path;
use std::ptr::{null, null_mut};

use fdd::replay::RuntimeConfig;
use fdd_monitor::ffi::*;
use fdd_monitor::log::LogReader;

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

/// `(t_ns, signal name, value)` of every mapped topic of a fixture, up to `until_ns`.
fn samples(cfg: &RuntimeConfig, name: &str, until_ns: u64) -> Vec<(u64, String, f64)> {
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
            out.push((m.log_time_ns, s.name.clone(), v));
        }
    }
    out
}

#[test]
fn push_advance_and_drain_through_the_abi_allocate_nothing() {
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let mut rt = null_mut();
    // SAFETY: valid pointers throughout; `rt` is live until freed at the end.
    unsafe {
        assert_eq!(fdd_runtime_new(null(), 0, &mut rt), FDD_OK);
    }
    let id = |name: &str| {
        let n = CString::new(name).expect("name");
        let mut id = 0;
        assert_eq!(unsafe { fdd_signal(rt, n.as_ptr(), &mut id) }, FDD_OK);
        id
    };
    let to_samples = |v: Vec<(u64, String, f64)>| -> Vec<fdd_sample> {
        v.into_iter()
            .map(|(t_ns, n, value)| fdd_sample {
                signal: id(&n),
                t_ns,
                value,
            })
            .collect()
    };
    let throttle = to_samples(samples(&cfg, "throttle_nominal", 60_000_000_000));
    let intake = to_samples(samples(&cfg, "intake_leak", 60_000_000_000));
    assert!(throttle.len() > 170_000 && intake.len() > 10_000);
    let mut events = vec![
        fdd_event {
            t_ns: 0,
            time_s: 0.0,
            dtc: 0,
            dtc_text: [0; FDD_DTC_TEXT_LEN],
            status_before: 0,
            status_after: 0,
            fdc: 0,
            occurrence_counter: 0,
            aging_counter: 0,
            trigger: 0,
            memory: 0,
            has_test_result: false,
            test_verdict: 0,
            test_value: 0.0,
            test_min: 0.0,
            test_max: 0.0,
        };
        64
    ];
    let mut raised = Vec::with_capacity(256);
    let mut steps_total = 0u64;
    unsafe { assert_eq!(fdd_start_operation_cycle(rt, 0), FDD_OK) };

    let allocations = fdd_testkit::allocations_in(|| unsafe {
        let (mut i, mut j) = (0, 0);
        while i < throttle.len() {
            let t = throttle[i].t_ns;
            let mut steps = 0;
            assert_eq!(fdd_advance_to(rt, t.saturating_sub(1), &mut steps), FDD_OK);
            steps_total += steps;
            // The intake samples before this frame one by one, the frame in one batch.
            while j < intake.len() && intake[j].t_ns < t {
                let s = intake[j];
                assert_eq!(fdd_push(rt, s.signal, s.t_ns, s.value), FDD_OK);
                j += 1;
            }
            let k = throttle[i..].iter().take_while(|s| s.t_ns == t).count();
            let mut accepted = 0;
            assert_eq!(
                fdd_push_batch(rt, throttle[i..].as_ptr(), k, &mut accepted),
                FDD_OK
            );
            assert_eq!(accepted, k);
            i += k;
            let mut n = events.len();
            while n == events.len() {
                assert_eq!(
                    fdd_events_drain(rt, events.as_mut_ptr(), events.len(), &mut n),
                    FDD_OK
                );
                for e in &events[..n] {
                    if e.status_before & 1 == 0 && e.status_after & 1 == 1 && raised.len() < 256 {
                        raised.push(*e);
                    }
                }
            }
        }
    });
    assert_eq!(allocations, 0, "allocations on the ABI's host path");
    assert!(steps_total > 110_000, "{steps_total} steps");
    // The leak was diagnosed inside the counted loop.
    let leak = raised
        .iter()
        .find(|e| e.dtc == 0x22_79_00)
        .expect("leak DTC P2279-00 raised");
    assert!(leak.t_ns > 10_000_000_000);
    let mut dropped = 1;
    unsafe {
        assert_eq!(fdd_events_count(rt, null_mut(), &mut dropped), FDD_OK);
        fdd_runtime_free(rt);
    }
    assert_eq!(dropped, 0);
}
