//! Throughput of the runtime's host path, push + advance, against the monitors' own cost.
//!
//! `cargo bench --bench runtime`. Each benchmark replays 10 s of a committed fixture from
//! memory (samples decoded beforehand): a 1 kHz throttle log (3 samples per 1 ms frame) and a
//! crank-synchronous intake log (5 samples per segment). `runtime_*` goes through
//! `Runtime::push` and `Runtime::advance_to` with a sink that takes every output;
//! `monitors_*` steps the same monitors (the "no signal" monitor and the subsystem monitor)
//! with a bare scheduler and signal table. divan reports samples per second; the difference of
//! the per-sample times is what the runtime adds.
//!
//! `ffi_*` runs the same loop through the C ABI (`fdd_push`, `fdd_advance_to`,
//! `fdd_events_drain`; what a C host pays, without the call's linkage), against `queue_*`,
//! the Rust API with the same event queue and without the detail outputs, as the ABI's
//! runtime is built.

use std::path::Path;

use divan::counter::ItemsCount;
use divan::Bencher;
use fdd::replay::RuntimeConfig;
use fdd_monitor::log::LogReader;
use fdd_monitor::monitor::{Monitor, Output};
use fdd_monitor::runtime::{EventQueue, Runtime, Stamped};
use fdd_monitor::scheduler::Scheduler;
use fdd_monitor::signal_table::{SignalId, SignalTable};
use fdd_monitor::staleness::StalenessMonitor;

fn main() {
    divan::main();
}

/// `(t_ns, signal index, value)` of the first `seconds` of a fixture.
fn samples(fixture: &str, seconds: u64) -> Vec<(u64, usize, f64)> {
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("fixtures/data/{fixture}.mcap"));
    let mut reader = LogReader::open(&path).expect("fixture");
    let mut out = Vec::new();
    while let Some(m) = reader.next_message() {
        let m = m.expect("readable");
        if m.log_time_ns >= seconds * 1_000_000_000 {
            break;
        }
        for (i, s) in cfg.signals.iter().enumerate() {
            if s.topic == m.topic {
                out.push((m.log_time_ns, i, m.field_f64(&s.field).expect("field")));
            }
        }
    }
    out
}

fn runtime(monitor: &str) -> (Runtime, Vec<SignalId>) {
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let (rt, _) = Runtime::builder(cfg.clone())
        .only_monitors(&[monitor])
        .build()
        .expect("runtime");
    let ids = cfg
        .signals
        .iter()
        .map(|s| rt.signal(&s.name).expect("signal"))
        .collect();
    (rt, ids)
}

/// Push + advance over the samples, frame by frame, as `fdd replay` does.
fn run_runtime(rt: &mut Runtime, ids: &[SignalId], data: &[(u64, usize, f64)]) -> u64 {
    let mut outputs = 0u64;
    let mut sink = |o: Stamped<'_>| {
        if matches!(o.output, Output::Event(_) | Output::Estimate { .. }) {
            outputs += 1;
        }
    };
    rt.start_operation_cycle(data[0].0, &mut sink)
        .expect("cycle");
    let mut frame = data[0].0;
    for &(t, i, v) in data {
        if t != frame {
            rt.advance_to(t - 1, &mut sink).expect("advance");
            frame = t;
        }
        let _ = rt.push(ids[i], t, v);
    }
    rt.advance_to(frame, &mut sink).expect("advance");
    outputs
}

/// The same monitors without the runtime: a scheduler, a table, a closure sink.
struct Bare {
    sched: Scheduler,
    table: SignalTable,
    ids: Vec<SignalId>,
}

fn bare(monitor: &str) -> Bare {
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let table = cfg.signal_table().expect("table");
    let ids: Vec<SignalId> = table.ids().collect();
    let m: Box<dyn Monitor> = match monitor {
        "throttle" => {
            let c = fdd::config::ThrottleConfig::load(None).expect("throttle");
            let model =
                fdd_estimators::models::throttle::ThrottleModel::new(c.model).expect("model");
            Box::new(
                fdd_monitor::throttle::ThrottleMonitor::new(
                    model,
                    c.position_sensor.full_scale_v,
                    c.position_sensor.full_scale_deg,
                    &c.monitor,
                    &table,
                )
                .expect("monitor"),
            )
        }
        _ => {
            let c = fdd::config::IntakeConfig::load(None).expect("intake");
            let model = fdd_estimators::models::intake::IntakeModel::new(
                c.model,
                fdd_estimators::models::intake::ThrottleFlow::RandomWalk,
            )
            .expect("model");
            Box::new(
                fdd_monitor::intake::IntakeMonitor::new(&model, &c.monitor, &table)
                    .expect("monitor"),
            )
        }
    };
    let watch = m.inputs().to_vec();
    let staleness = StalenessMonitor::from_config(&cfg, &table, &watch).expect("staleness");
    let mut sched = Scheduler::new(0);
    sched.add(Box::new(staleness)).expect("add");
    sched.add(m).expect("add");
    Bare { sched, table, ids }
}

fn run_bare(b: &mut Bare, data: &[(u64, usize, f64)]) -> u64 {
    let mut outputs = 0u64;
    let mut sink = |_: usize, _: u64, o: Output<'_>| {
        if matches!(o, Output::Event(_) | Output::Estimate { .. }) {
            outputs += 1;
        }
    };
    b.sched.restart(data[0].0);
    b.sched.start_operation_cycle(data[0].0, &mut sink);
    for &(t, i, v) in data {
        b.sched.run_until(t, &b.table, &mut sink);
        let _ = b.table.set(b.ids[i], t, v);
    }
    let last = data[data.len() - 1].0;
    b.sched.run_until(last + 1, &b.table, &mut sink);
    outputs
}

const SECONDS: u64 = 10;

#[divan::bench(sample_count = 10, sample_size = 1)]
fn runtime_throttle(bencher: Bencher) {
    let data = samples("throttle_nominal", SECONDS);
    bencher
        .counter(ItemsCount::new(data.len()))
        .with_inputs(|| runtime("throttle"))
        .bench_local_refs(|(rt, ids)| run_runtime(rt, ids, &data));
}

#[divan::bench(sample_count = 10, sample_size = 1)]
fn monitors_throttle(bencher: Bencher) {
    let data = samples("throttle_nominal", SECONDS);
    bencher
        .counter(ItemsCount::new(data.len()))
        .with_inputs(|| bare("throttle"))
        .bench_local_refs(|b| run_bare(b, &data));
}

#[divan::bench(sample_count = 10, sample_size = 1)]
fn runtime_intake(bencher: Bencher) {
    let data = samples("intake_nominal", SECONDS);
    bencher
        .counter(ItemsCount::new(data.len()))
        .with_inputs(|| runtime("intake"))
        .bench_local_refs(|(rt, ids)| run_runtime(rt, ids, &data));
}

#[divan::bench(sample_count = 10, sample_size = 1)]
fn monitors_intake(bencher: Bencher) {
    let data = samples("intake_nominal", SECONDS);
    bencher
        .counter(ItemsCount::new(data.len()))
        .with_inputs(|| bare("intake"))
        .bench_local_refs(|b| run_bare(b, &data));
}

/// The Rust API as the C ABI uses it: no detail outputs, events into an [`EventQueue`]
/// drained every frame.
fn queue_runtime(monitor: &str) -> (Runtime, Vec<SignalId>, EventQueue) {
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let (rt, _) = Runtime::builder(cfg.clone())
        .only_monitors(&[monitor])
        .detail_outputs(false)
        .build()
        .expect("runtime");
    let ids = cfg
        .signals
        .iter()
        .map(|s| rt.signal(&s.name).expect("signal"))
        .collect();
    (
        rt,
        ids,
        EventQueue::new(fdd_monitor::ffi::FDD_DEFAULT_EVENT_CAPACITY),
    )
}

#[inline(never)]
fn run_queue(
    (rt, ids, q): &mut (Runtime, Vec<SignalId>, EventQueue),
    data: &[(u64, usize, f64)],
) -> u64 {
    let mut events = 0u64;
    rt.start_operation_cycle(data[0].0, q).expect("cycle");
    let mut frame = data[0].0;
    for &(t, i, v) in data {
        if t != frame {
            rt.advance_to(t - 1, q).expect("advance");
            while q.pop().is_some() {
                events += 1;
            }
            frame = t;
        }
        let _ = rt.push(ids[i], t, v);
    }
    rt.advance_to(frame, q).expect("advance");
    events
}

/// A runtime built through the C ABI, and its signal ids in configuration order.
struct Ffi {
    rt: *mut fdd_monitor::ffi::fdd_runtime,
    ids: Vec<u32>,
}

impl Drop for Ffi {
    fn drop(&mut self) {
        // SAFETY: built by ffi_runtime, freed once.
        unsafe { fdd_monitor::ffi::fdd_runtime_free(self.rt) };
    }
}

fn ffi_runtime(monitor: &str) -> Ffi {
    use fdd_monitor::ffi::*;
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let name = std::ffi::CString::new(monitor).expect("name");
    let mut b = std::ptr::null_mut();
    let mut rt = std::ptr::null_mut();
    // SAFETY: valid pointers throughout.
    unsafe {
        assert_eq!(fdd_builder_new(std::ptr::null(), 0, &mut b), FDD_OK);
        assert_eq!(fdd_builder_only_monitors(b, name.as_ptr()), FDD_OK);
        assert_eq!(fdd_runtime_build(b, &mut rt), FDD_OK);
        fdd_builder_free(b);
    }
    let ids = cfg
        .signals
        .iter()
        .map(|s| {
            let n = std::ffi::CString::new(s.name.as_str()).expect("name");
            let mut id = 0;
            // SAFETY: a live runtime and valid pointers.
            assert_eq!(unsafe { fdd_signal(rt, n.as_ptr(), &mut id) }, FDD_OK);
            id
        })
        .collect();
    Ffi { rt, ids }
}

#[inline(never)]
fn run_ffi(f: &mut Ffi, data: &[(u64, usize, f64)]) -> u64 {
    use fdd_monitor::ffi::*;
    let mut buf = [std::mem::MaybeUninit::<fdd_event>::uninit(); 64];
    let mut events = 0u64;
    // SAFETY: a live runtime, valid buffers.
    unsafe {
        assert_eq!(fdd_start_operation_cycle(f.rt, data[0].0), FDD_OK);
        let mut frame = data[0].0;
        for &(t, i, v) in data {
            if t != frame {
                assert_eq!(fdd_advance_to(f.rt, t - 1, std::ptr::null_mut()), FDD_OK);
                let mut n = 64;
                while n == 64 {
                    assert_eq!(
                        fdd_events_drain(f.rt, buf.as_mut_ptr().cast(), 64, &mut n),
                        FDD_OK
                    );
                    events += n as u64;
                }
                frame = t;
            }
            let _ = fdd_push(f.rt, f.ids[i], t, v);
        }
        assert_eq!(fdd_advance_to(f.rt, frame, std::ptr::null_mut()), FDD_OK);
    }
    events
}

#[divan::bench(sample_count = 10, sample_size = 1)]
fn queue_throttle(bencher: Bencher) {
    let data = samples("throttle_nominal", SECONDS);
    bencher
        .counter(ItemsCount::new(data.len()))
        .with_inputs(|| queue_runtime("throttle"))
        .bench_local_refs(|r| run_queue(r, &data));
}

#[divan::bench(sample_count = 10, sample_size = 1)]
fn ffi_throttle(bencher: Bencher) {
    let data = samples("throttle_nominal", SECONDS);
    bencher
        .counter(ItemsCount::new(data.len()))
        .with_inputs(|| ffi_runtime("throttle"))
        .bench_local_refs(|f| run_ffi(f, &data));
}

#[divan::bench(sample_count = 10, sample_size = 1)]
fn queue_intake(bencher: Bencher) {
    let data = samples("intake_nominal", SECONDS);
    bencher
        .counter(ItemsCount::new(data.len()))
        .with_inputs(|| queue_runtime("intake"))
        .bench_local_refs(|r| run_queue(r, &data));
}

#[divan::bench(sample_count = 10, sample_size = 1)]
fn ffi_intake(bencher: Bencher) {
    let data = samples("intake_nominal", SECONDS);
    bencher
        .counter(ItemsCount::new(data.len()))
        .with_inputs(|| ffi_runtime("intake"))
        .bench_local_refs(|f| run_ffi(f, &data));
}
