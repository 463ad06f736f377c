//! Every function of the ABI with NULL pointers, bad arguments and a poisoned handle gets its
//! documented status code and changes nothing; a panic forced inside a call (the test hook
//! `panic_next`) comes back as `FDD_ERR_PANIC` and poisons the handle.

use std::ffi::{c_char, CStr};
use std::ptr::{null, null_mut};

use super::*;

fn last_error() -> String {
    let mut buf = [0 as c_char; 1024];
    // SAFETY: a 1024-byte buffer.
    unsafe { fdd_last_error(buf.as_mut_ptr(), buf.len()) };
    // SAFETY: NUL-terminated by fdd_last_error.
    unsafe { CStr::from_ptr(buf.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

/// A runtime of the embedded configuration with the throttle monitor only.
fn throttle_runtime() -> *mut fdd_runtime {
    let mut b = null_mut();
    let mut rt = null_mut();
    unsafe {
        assert_eq!(fdd_builder_new(null(), 0, &mut b), FDD_OK);
        assert_eq!(fdd_builder_only_monitors(b, c"throttle".as_ptr()), FDD_OK);
        assert_eq!(fdd_runtime_build(b, &mut rt), FDD_OK, "{}", last_error());
        fdd_builder_free(b);
    }
    assert!(!rt.is_null());
    rt
}

/// Every call that takes a runtime, with valid other arguments; the statuses they return on
/// a live runtime are not checked here, only that a NULL or poisoned one is refused first.
#[allow(clippy::type_complexity)]
fn runtime_calls() -> Vec<(&'static str, Box<dyn Fn(*mut fdd_runtime) -> fdd_status>)> {
    unsafe fn s(f: fdd_status) -> fdd_status {
        f
    }
    vec![
        (
            "fdd_signal",
            Box::new(|rt| unsafe {
                let mut id = 0;
                s(fdd_signal(rt, c"tps".as_ptr(), &mut id))
            }),
        ),
        (
            "fdd_push",
            Box::new(|rt| unsafe { fdd_push(rt, 0, 1, 1.0) }),
        ),
        (
            "fdd_push_batch",
            Box::new(|rt| unsafe {
                let x = fdd_sample {
                    signal: 0,
                    t_ns: 2,
                    value: 1.0,
                };
                let mut n = 0;
                fdd_push_batch(rt, &x, 1, &mut n)
            }),
        ),
        (
            "fdd_advance_to",
            Box::new(|rt| unsafe { fdd_advance_to(rt, 3, null_mut()) }),
        ),
        (
            "fdd_start_operation_cycle",
            Box::new(|rt| unsafe { fdd_start_operation_cycle(rt, 4) }),
        ),
        (
            "fdd_end_operation_cycle",
            Box::new(|rt| unsafe { fdd_end_operation_cycle(rt, 5) }),
        ),
        (
            "fdd_warm_up_completed",
            Box::new(|rt| unsafe { fdd_warm_up_completed(rt) }),
        ),
        (
            "fdd_set_monitor_enabled",
            Box::new(|rt| unsafe { fdd_set_monitor_enabled(rt, c"throttle".as_ptr(), true) }),
        ),
        (
            "fdd_events_drain",
            Box::new(|rt| unsafe {
                let mut n = 0;
                fdd_events_drain(rt, null_mut(), 0, &mut n)
            }),
        ),
        (
            "fdd_events_count",
            Box::new(|rt| unsafe { fdd_events_count(rt, null_mut(), null_mut()) }),
        ),
        (
            "fdd_event_json",
            Box::new(|rt| unsafe {
                let e = sample_event();
                let mut buf = [0 as c_char; 1024];
                let mut len = 0;
                fdd_event_json(rt, &e, buf.as_mut_ptr(), buf.len(), &mut len)
            }),
        ),
        (
            "fdd_event_name",
            Box::new(|rt| unsafe {
                let mut buf = [0 as c_char; 64];
                let mut len = 0;
                fdd_event_name(rt, P0122_16, buf.as_mut_ptr(), buf.len(), &mut len)
            }),
        ),
        (
            "fdd_event_monitor",
            Box::new(|rt| unsafe {
                let mut buf = [0 as c_char; 64];
                let mut len = 0;
                fdd_event_monitor(rt, P0122_16, buf.as_mut_ptr(), buf.len(), &mut len)
            }),
        ),
        (
            "fdd_latest_estimate",
            Box::new(|rt| unsafe {
                let mut e = std::mem::MaybeUninit::<fdd_estimate>::uninit();
                fdd_latest_estimate(rt, c"throttle_angle".as_ptr(), e.as_mut_ptr())
            }),
        ),
        (
            "fdd_dtcs_by_status_mask",
            Box::new(|rt| unsafe {
                let mut n = 0;
                fdd_dtcs_by_status_mask(rt, 0xFF, null_mut(), 0, &mut n)
            }),
        ),
        (
            "fdd_status_availability_mask",
            Box::new(|rt| unsafe {
                let mut m = 0;
                fdd_status_availability_mask(rt, &mut m)
            }),
        ),
        (
            "fdd_dtc_status",
            Box::new(|rt| unsafe {
                let mut st = 0;
                fdd_dtc_status(rt, P0122_16, &mut st)
            }),
        ),
        (
            "fdd_dtc_extended_data",
            Box::new(|rt| unsafe {
                let mut x = std::mem::MaybeUninit::<fdd_extended_data>::uninit();
                fdd_dtc_extended_data(rt, P0122_16, x.as_mut_ptr())
            }),
        ),
        (
            "fdd_dtc_freeze_frame",
            Box::new(|rt| unsafe {
                let mut f = std::mem::MaybeUninit::<fdd_freeze_frame>::uninit();
                fdd_dtc_freeze_frame(rt, P0122_16, f.as_mut_ptr(), null_mut(), 0)
            }),
        ),
        (
            "fdd_clear_dtc",
            Box::new(|rt| unsafe { fdd_clear_dtc(rt, 0xFFFFFF, 6, null_mut()) }),
        ),
        (
            "fdd_persist_now",
            Box::new(|rt| unsafe { fdd_persist_now(rt, null_mut()) }),
        ),
    ]
}

/// The UDS value of P0122-16 (TPS circuit low).
const P0122_16: u32 = 0x0001_2216;

fn sample_event() -> fdd_event {
    fdd_event {
        t_ns: 7,
        time_s: 7e-9,
        dtc: P0122_16,
        dtc_text: types::c_text(b"P0122-16"),
        status_before: 0x50,
        status_after: 0x27,
        fdc: 127,
        occurrence_counter: 1,
        aging_counter: 0,
        trigger: FDD_TRIGGER_TEST_RESULT,
        memory: FDD_MEMORY_STORED,
        has_test_result: true,
        test_verdict: FDD_VERDICT_FAILED,
        test_value: 0.0,
        test_min: 0.1,
        test_max: 4.9,
    }
}

#[test]
fn every_runtime_call_refuses_a_null_handle() {
    for (name, call) in runtime_calls() {
        assert_eq!(call(null_mut()), FDD_ERR_NULL, "{name}");
        assert!(
            last_error().contains("`rt` is NULL"),
            "{name}: {}",
            last_error()
        );
    }
}

#[test]
fn a_forced_panic_is_a_status_and_poisons_the_handle() {
    for (name, call) in runtime_calls() {
        let rt = throttle_runtime();
        // SAFETY: a live handle.
        unsafe { &*rt }.panic_next.set(true);
        assert_eq!(call(rt), FDD_ERR_PANIC, "{name}");
        assert!(
            last_error().contains("test hook: forced panic"),
            "{}",
            last_error()
        );
        // From now on every call is refused, and nothing runs.
        for (other, call2) in runtime_calls() {
            assert_eq!(
                call2(rt),
                FDD_ERR_POISONED,
                "{other} after a panic in {name}"
            );
        }
        assert!(last_error().contains("poisoned"));
        // SAFETY: freeing a poisoned handle is allowed.
        unsafe { fdd_runtime_free(rt) };
    }
}

#[test]
fn construction_refuses_nulls_and_bad_configurations() {
    let mut b = null_mut();
    let mut rt = null_mut();
    unsafe {
        assert_eq!(fdd_builder_new(null(), 0, null_mut()), FDD_ERR_NULL);
        assert_eq!(fdd_builder_from_file(null(), &mut b), FDD_ERR_NULL);
        assert_eq!(
            fdd_builder_from_file(c"x.toml".as_ptr(), null_mut()),
            FDD_ERR_NULL
        );
        assert_eq!(fdd_runtime_new(null(), 0, null_mut()), FDD_ERR_NULL);
        assert_eq!(fdd_runtime_from_file(null(), &mut rt), FDD_ERR_NULL);
        assert_eq!(
            fdd_runtime_from_file(c"x.toml".as_ptr(), null_mut()),
            FDD_ERR_NULL
        );
        assert_eq!(fdd_runtime_build(null(), &mut rt), FDD_ERR_NULL);
        assert_eq!(
            fdd_builder_only_monitors(null_mut(), c"throttle".as_ptr()),
            FDD_ERR_NULL
        );
        assert_eq!(
            fdd_builder_persistence(null_mut(), c"m".as_ptr()),
            FDD_ERR_NULL
        );
        assert_eq!(fdd_builder_event_capacity(null_mut(), 8), FDD_ERR_NULL);
        fdd_builder_free(null_mut());
        fdd_runtime_free(null_mut());
        assert!(
            b.is_null() && rt.is_null(),
            "out-parameters untouched on failure"
        );

        // A missing file, text that is not UTF-8, a key out of range: the message names it.
        assert_eq!(
            fdd_runtime_from_file(c"/nonexistent/fdd.toml".as_ptr(), &mut rt),
            FDD_ERR_CONFIG
        );
        assert!(
            last_error().contains("/nonexistent/fdd.toml"),
            "{}",
            last_error()
        );
        let bytes = [0xFFu8, 0xFE];
        assert_eq!(
            fdd_runtime_new(bytes.as_ptr().cast(), bytes.len(), &mut rt),
            FDD_ERR_CONFIG
        );
        assert!(last_error().contains("not UTF-8"), "{}", last_error());
        let text = include_str!("../../../config/fdd.toml")
            .replace("check_period_s = 0.001", "check_period_s = -1");
        assert_eq!(
            fdd_runtime_new(text.as_ptr().cast(), text.len(), &mut rt),
            FDD_ERR_CONFIG
        );
        assert!(last_error().contains("check_period_s"), "{}", last_error());
        assert!(rt.is_null());

        // The builder's own checks; the builder is still usable after a refused call.
        assert_eq!(fdd_builder_new(null(), 0, &mut b), FDD_OK);
        assert_eq!(fdd_builder_only_monitors(b, null()), FDD_ERR_NULL);
        assert_eq!(
            fdd_builder_only_monitors(b, c"throttle,wheel".as_ptr()),
            FDD_ERR_ARGUMENT
        );
        assert!(last_error().contains("`wheel`"), "{}", last_error());
        assert_eq!(fdd_builder_persistence(b, null()), FDD_ERR_NULL);
        assert_eq!(fdd_builder_persistence(b, c"".as_ptr()), FDD_ERR_ARGUMENT);
        assert_eq!(fdd_builder_event_capacity(b, 0), FDD_ERR_ARGUMENT);
        assert_eq!(fdd_runtime_build(b, null_mut()), FDD_ERR_NULL);
        assert_eq!(fdd_runtime_build(b, &mut rt), FDD_OK);
        fdd_builder_free(b);
        fdd_runtime_free(rt);
    }
}

#[test]
fn null_out_parameters_and_bad_arguments_change_nothing() {
    let rt = throttle_runtime();
    unsafe {
        let mut id = u32::MAX;
        assert_eq!(fdd_signal(rt, c"tps".as_ptr(), null_mut()), FDD_ERR_NULL);
        assert_eq!(fdd_signal(rt, null(), &mut id), FDD_ERR_NULL);
        assert_eq!(fdd_signal(rt, c"nope".as_ptr(), &mut id), FDD_ERR_NOT_FOUND);
        assert_eq!(id, u32::MAX, "out-parameter untouched on failure");
        let bad = [0xC3u8, 0x28, 0]; // invalid UTF-8
        assert_eq!(
            fdd_signal(rt, bad.as_ptr().cast(), &mut id),
            FDD_ERR_ARGUMENT
        );
        assert_eq!(fdd_signal(rt, c"tps".as_ptr(), &mut id), FDD_OK);

        // Time and cycle rules.
        assert_eq!(fdd_advance_to(rt, 0, null_mut()), FDD_ERR_NO_CYCLE);
        assert_eq!(fdd_start_operation_cycle(rt, 1_000), FDD_OK);
        assert_eq!(fdd_push(rt, 999, 1_000, 0.5), FDD_ERR_UNKNOWN_SIGNAL);
        assert_eq!(fdd_push(rt, id, 1_000, f64::NAN), FDD_ERR_SAMPLE);
        assert!(
            last_error().contains("signal `tps` at 1000 ns"),
            "{}",
            last_error()
        );
        assert_eq!(fdd_push(rt, id, 1_000, 0.5), FDD_OK);
        assert_eq!(
            fdd_push(rt, id, 1_000, 0.5),
            FDD_ERR_SAMPLE,
            "repeated time"
        );
        assert_eq!(fdd_advance_to(rt, 2_000, null_mut()), FDD_OK);
        assert_eq!(fdd_advance_to(rt, 1_500, null_mut()), FDD_ERR_TIME);

        // A batch stops at the refused sample and says how many went in.
        let batch = [
            fdd_sample {
                signal: id,
                t_ns: 3_000,
                value: 0.5,
            },
            fdd_sample {
                signal: id,
                t_ns: 4_000,
                value: f64::INFINITY,
            },
            fdd_sample {
                signal: id,
                t_ns: 5_000,
                value: 0.5,
            },
        ];
        let mut accepted = 99;
        assert_eq!(
            fdd_push_batch(rt, batch.as_ptr(), 3, &mut accepted),
            FDD_ERR_SAMPLE
        );
        assert_eq!(accepted, 1);
        assert_eq!(fdd_push_batch(rt, null(), 2, &mut accepted), FDD_ERR_NULL);
        assert_eq!(
            fdd_push_batch(rt, batch.as_ptr(), 3, null_mut()),
            FDD_ERR_NULL
        );
        assert_eq!(fdd_push_batch(rt, null(), 0, &mut accepted), FDD_OK);
        assert_eq!(accepted, 0);

        // Buffers: NULL with a capacity, too small, and the DTC arguments.
        let mut n = 0;
        assert_eq!(fdd_events_drain(rt, null_mut(), 4, &mut n), FDD_ERR_NULL);
        assert_eq!(
            fdd_events_drain(rt, null_mut(), 0, null_mut()),
            FDD_ERR_NULL
        );
        let mut small = [0 as c_char; 4];
        let mut len = 0;
        assert_eq!(
            fdd_event_name(rt, P0122_16, small.as_mut_ptr(), small.len(), &mut len),
            FDD_ERR_BUFFER_TOO_SMALL
        );
        assert_eq!(len, "tps_circuit_low".len());
        assert_eq!(small, [0; 4], "nothing written to a buffer too small");
        assert_eq!(
            fdd_event_name(rt, 0x0100_0000, small.as_mut_ptr(), small.len(), &mut len),
            FDD_ERR_ARGUMENT
        );
        assert_eq!(
            fdd_event_name(rt, 0x09_99_99, small.as_mut_ptr(), small.len(), &mut len),
            FDD_ERR_NOT_FOUND
        );
        let mut st = 0;
        assert_eq!(fdd_dtc_status(rt, P0122_16, null_mut()), FDD_ERR_NULL);
        assert_eq!(fdd_dtc_status(rt, 0x09_99_99, &mut st), FDD_ERR_NOT_FOUND);
        assert_eq!(
            fdd_clear_dtc(rt, 0x09_99_99, 6_000, null_mut()),
            FDD_ERR_NOT_FOUND
        );
        assert_eq!(
            fdd_clear_dtc(rt, 0x0100_0000, 6_000, null_mut()),
            FDD_ERR_ARGUMENT
        );
        let mut f = std::mem::MaybeUninit::<fdd_freeze_frame>::uninit();
        assert_eq!(
            fdd_dtc_freeze_frame(rt, P0122_16, f.as_mut_ptr(), null_mut(), 0),
            FDD_ERR_NOT_FOUND,
            "no entry stored"
        );
        assert_eq!(
            fdd_dtc_freeze_frame(rt, P0122_16, f.as_mut_ptr(), null_mut(), 3),
            FDD_ERR_NULL
        );
        let e = fdd_event {
            trigger: 99,
            ..sample_event()
        };
        let mut buf = [0 as c_char; 1024];
        assert_eq!(
            fdd_event_json(rt, &e, buf.as_mut_ptr(), buf.len(), &mut len),
            FDD_ERR_ARGUMENT
        );
        assert_eq!(
            fdd_event_json(rt, null(), buf.as_mut_ptr(), buf.len(), &mut len),
            FDD_ERR_NULL
        );
        assert_eq!(
            fdd_set_monitor_enabled(rt, c"intake".as_ptr(), false),
            FDD_ERR_NOT_FOUND
        );
        let mut est = std::mem::MaybeUninit::<fdd_estimate>::uninit();
        assert_eq!(
            fdd_latest_estimate(rt, c"wheel_speed".as_ptr(), est.as_mut_ptr()),
            FDD_ERR_NOT_FOUND
        );
        fdd_runtime_free(rt);
    }
}

#[test]
fn the_event_json_is_the_diagnostic_events_shape() {
    let rt = throttle_runtime();
    let e = sample_event();
    let mut buf = [0 as c_char; 1024];
    let mut len = 0;
    unsafe {
        assert_eq!(
            fdd_event_json(rt, &e, buf.as_mut_ptr(), buf.len(), &mut len),
            FDD_OK
        );
        let s = CStr::from_ptr(buf.as_ptr()).to_str().expect("UTF-8");
        assert_eq!(s.len(), len);
        let v: serde_json::Value = serde_json::from_str(s).expect("JSON");
        assert_eq!(v["dtc"], "P0122-16");
        assert_eq!(v["dtc_uds"], P0122_16);
        assert_eq!(v["event"], "tps_circuit_low");
        assert_eq!(v["monitor"], "throttle");
        assert_eq!(v["status_before"], 0x50);
        assert_eq!(v["status_after"], 0x27);
        assert_eq!(v["trigger"], "test_result");
        assert_eq!(v["memory"], "stored");
        assert_eq!(v["test_result"]["verdict"], "FAILED");
        assert_eq!(v["test_result"]["max"], 4.9);
        fdd_runtime_free(rt);
    }
}

#[test]
fn status_names_and_the_version_are_static_strings() {
    for s in 0..=FDD_ERR_POISONED {
        let name = unsafe { CStr::from_ptr(fdd_status_name(s)) }
            .to_str()
            .expect("ASCII");
        assert!(name.starts_with("FDD_"), "{name}");
        assert_ne!(name, "FDD_ERR_UNKNOWN_STATUS", "status {s} has no name");
    }
    let v = unsafe { CStr::from_ptr(fdd_version()) }
        .to_str()
        .expect("ASCII");
    assert_eq!(v, env!("CARGO_PKG_VERSION"));
    // fdd_last_error with no buffer reports the length only.
    error::record(format_args!("twelve chars"));
    assert_eq!(unsafe { fdd_last_error(null_mut(), 0) }, 12);
    let mut three = [1 as c_char; 3];
    assert_eq!(unsafe { fdd_last_error(three.as_mut_ptr(), 3) }, 12);
    assert_eq!(
        three,
        [b't' as c_char, b'w' as c_char, 0],
        "cut and NUL-terminated"
    );
}

#[test]
fn a_confirmed_dtc_persists_across_runtimes_built_through_the_abi() {
    let dir = tempfile::tempdir().expect("tempdir");
    let base =
        std::ffi::CString::new(dir.path().join("memory").to_str().expect("UTF-8")).expect("path");
    let build = || {
        let mut b = null_mut();
        let mut rt = null_mut();
        unsafe {
            assert_eq!(fdd_builder_new(null(), 0, &mut b), FDD_OK);
            assert_eq!(fdd_builder_only_monitors(b, c"throttle".as_ptr()), FDD_OK);
            assert_eq!(fdd_builder_persistence(b, base.as_ptr()), FDD_OK);
            assert_eq!(fdd_runtime_build(b, &mut rt), FDD_OK, "{}", last_error());
            fdd_builder_free(b);
        }
        rt
    };
    const P0123_17: u32 = 0x0001_2317; // TPS circuit high
                                       // Two drives with the TPS shorted to 5 V: pending in the first, confirmed in the second,
                                       // each in a runtime of its own (a power cycle between them).
    for drive in 0..2u64 {
        let rt = build();
        unsafe {
            let ids = ["motor_voltage", "tps", "wattmeter"].map(|n| {
                let n = std::ffi::CString::new(n).expect("name");
                let mut id = 0;
                assert_eq!(fdd_signal(rt, n.as_ptr(), &mut id), FDD_OK);
                id
            });
            let t0 = drive * 1_000_000_000;
            assert_eq!(fdd_start_operation_cycle(rt, t0), FDD_OK);
            for k in 0..300u64 {
                let t = t0 + k * 1_000_000;
                for (id, v) in ids.iter().zip([0.0, 5.0, 0.0]) {
                    assert_eq!(fdd_push(rt, *id, t, v), FDD_OK);
                }
                assert_eq!(fdd_advance_to(rt, t, null_mut()), FDD_OK);
            }
            assert_eq!(fdd_end_operation_cycle(rt, t0 + 300_000_000), FDD_OK);
            let mut st = 0;
            assert_eq!(fdd_dtc_status(rt, P0123_17, &mut st), FDD_OK);
            assert_eq!(
                st & 0x08 != 0,
                drive == 1,
                "drive {drive}: status 0x{st:02X}"
            );
            let mut written = false;
            assert_eq!(fdd_persist_now(rt, &mut written), FDD_OK);
            assert!(written);
            fdd_runtime_free(rt);
        }
    }
    // A third power-up: the confirmed DTC, its freeze frame and counter are back.
    let rt = build();
    unsafe {
        let mut st = 0;
        assert_eq!(fdd_dtc_status(rt, P0123_17, &mut st), FDD_OK);
        assert!(st & 0x08 != 0, "status 0x{st:02X}");
        let mut ext = std::mem::MaybeUninit::<fdd_extended_data>::uninit();
        assert_eq!(
            fdd_dtc_extended_data(rt, P0123_17, ext.as_mut_ptr()),
            FDD_OK
        );
        let ext = ext.assume_init();
        assert!(ext.stored && ext.occurrence_counter >= 1, "{ext:?}");
        let mut values = [fdd_freeze_value {
            name: [0; FDD_NAME_LEN],
            value: 0.0,
        }; 8];
        let mut frame = std::mem::MaybeUninit::<fdd_freeze_frame>::uninit();
        assert_eq!(
            fdd_dtc_freeze_frame(rt, P0123_17, frame.as_mut_ptr(), values.as_mut_ptr(), 8),
            FDD_OK
        );
        let frame = frame.assume_init();
        assert!(frame.value_count >= 3);
        let tps = values[..frame.value_count.min(8)]
            .iter()
            .find(|v| CStr::from_ptr(v.name.as_ptr()).to_bytes() == b"tps")
            .expect("tps in the freeze frame");
        assert_eq!(tps.value, 5.0);
        let mut cleared = 0;
        assert_eq!(
            fdd_clear_dtc(rt, 0xFF_FFFF, 2_000_000_000, &mut cleared),
            FDD_OK
        );
        assert!(cleared >= 1);
        assert_eq!(fdd_dtc_status(rt, P0123_17, &mut st), FDD_OK);
        assert_eq!(st, 0x50);
        fdd_runtime_free(rt);
    }
}
