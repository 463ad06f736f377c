"""Python as a second host of fdd's C ABI: ctypes over libfdd_monitor.so.

Run by tests/c_host.rs: python3 tests/data/ffi_ctypes.py target/release/libfdd_monitor.so

It builds a runtime from the embedded default configuration with the throttle monitor only,
feeds 300 ms of a closed throttle whose position sensor reads 5 V (shorted to its supply), and
checks that the circuit-high DTC goes pending with its JSON form, that the estimate of the
throttle position comes from the wattmeter, and that bad calls get their documented status
codes and messages.
"""

import ctypes as C
import json
import pathlib
import re
import sys

FDD_OK, FDD_ERR_NULL, FDD_ERR_CONFIG, FDD_ERR_SAMPLE, FDD_ERR_NOT_FOUND = 0, 1, 2, 5, 8
FDD_DTC_TEXT_LEN, FDD_NAME_LEN = 12, 48


class Event(C.Structure):
    _fields_ = [
        ("t_ns", C.c_uint64),
        ("time_s", C.c_double),
        ("dtc", C.c_uint32),
        ("dtc_text", C.c_char * FDD_DTC_TEXT_LEN),
        ("status_before", C.c_uint8),
        ("status_after", C.c_uint8),
        ("fdc", C.c_int8),
        ("occurrence_counter", C.c_uint8),
        ("aging_counter", C.c_uint8),
        ("trigger", C.c_uint8),
        ("memory", C.c_uint8),
        ("has_test_result", C.c_bool),
        ("test_verdict", C.c_uint8),
        ("test_value", C.c_double),
        ("test_min", C.c_double),
        ("test_max", C.c_double),
    ]


class Estimate(C.Structure):
    _fields_ = [
        ("t_ns", C.c_uint64),
        ("value", C.c_double),
        ("lower", C.c_double),
        ("upper", C.c_double),
        ("source", C.c_char * FDD_NAME_LEN),
    ]


def main(path):
    lib = C.CDLL(path)
    p = C.c_void_p
    lib.fdd_status_name.restype = C.c_char_p
    lib.fdd_version.restype = C.c_char_p
    lib.fdd_last_error.argtypes = [C.c_char_p, C.c_size_t]
    lib.fdd_last_error.restype = C.c_size_t
    lib.fdd_builder_new.argtypes = [C.c_char_p, C.c_size_t, C.POINTER(p)]
    lib.fdd_builder_only_monitors.argtypes = [p, C.c_char_p]
    lib.fdd_runtime_build.argtypes = [p, C.POINTER(p)]
    lib.fdd_builder_free.argtypes = [p]
    lib.fdd_runtime_new.argtypes = [C.c_char_p, C.c_size_t, C.POINTER(p)]
    lib.fdd_runtime_free.argtypes = [p]
    lib.fdd_signal.argtypes = [p, C.c_char_p, C.POINTER(C.c_uint32)]
    lib.fdd_push.argtypes = [p, C.c_uint32, C.c_uint64, C.c_double]
    lib.fdd_advance_to.argtypes = [p, C.c_uint64, C.POINTER(C.c_uint64)]
    lib.fdd_start_operation_cycle.argtypes = [p, C.c_uint64]
    lib.fdd_events_drain.argtypes = [p, C.POINTER(Event), C.c_size_t, C.POINTER(C.c_size_t)]
    lib.fdd_event_json.argtypes = [
        p, C.POINTER(Event), C.c_char_p, C.c_size_t, C.POINTER(C.c_size_t)]
    lib.fdd_latest_estimate.argtypes = [p, C.c_char_p, C.POINTER(Estimate)]
    lib.fdd_dtc_status.argtypes = [p, C.c_uint32, C.POINTER(C.c_uint8)]

    def last_error():
        buf = C.create_string_buffer(1024)
        lib.fdd_last_error(buf, len(buf))
        return buf.value.decode()

    def check(status, what):
        if status != FDD_OK:
            raise SystemExit(
                f"{what}: {lib.fdd_status_name(status).decode()}: {last_error()}")

    print("fdd", lib.fdd_version().decode())
    b, rt = p(), p()
    check(lib.fdd_builder_new(None, 0, C.byref(b)), "fdd_builder_new")
    check(lib.fdd_builder_only_monitors(b, b"throttle"), "fdd_builder_only_monitors")
    check(lib.fdd_runtime_build(b, C.byref(rt)), "fdd_runtime_build")
    lib.fdd_builder_free(b)

    ids = {}
    for name in ("motor_voltage", "tps", "wattmeter"):
        i = C.c_uint32()
        check(lib.fdd_signal(rt, name.encode(), C.byref(i)), f"fdd_signal {name}")
        ids[name] = i.value
    check(lib.fdd_start_operation_cycle(rt, 0), "fdd_start_operation_cycle")
    events = (Event * 256)()
    got = []
    for k in range(300):
        t = k * 1_000_000
        check(lib.fdd_push(rt, ids["motor_voltage"], t, 0.0), "fdd_push")
        check(lib.fdd_push(rt, ids["tps"], t, 5.0), "fdd_push")
        check(lib.fdd_push(rt, ids["wattmeter"], t, 0.0), "fdd_push")
        check(lib.fdd_advance_to(rt, t, None), "fdd_advance_to")
        n = C.c_size_t()
        check(lib.fdd_events_drain(rt, events, len(events), C.byref(n)), "fdd_events_drain")
        got.extend(Event.from_buffer_copy(events[i]) for i in range(n.value))

    raised = [e for e in got if not e.status_before & 1 and e.status_after & 1]
    assert any(e.dtc_text == b"P0123-17" for e in raised), [e.dtc_text for e in raised]
    e = next(e for e in raised if e.dtc_text == b"P0123-17")
    buf, n = C.create_string_buffer(1024), C.c_size_t()
    check(lib.fdd_event_json(rt, C.byref(e), buf, len(buf), C.byref(n)), "fdd_event_json")
    j = json.loads(buf.value.decode())
    assert j["dtc"] == "P0123-17" and j["event"] == "tps_circuit_high", j
    assert j["monitor"] == "throttle" and j["status_after"] == e.status_after, j
    assert n.value == len(buf.value), (n.value, len(buf.value))
    # A buffer one byte short: refused, nothing written, the length reported.
    small = C.create_string_buffer(n.value)
    assert lib.fdd_event_json(rt, C.byref(e), small, len(small), C.byref(n)) == 9
    assert small.value == b"" and n.value == len(buf.value)

    est = Estimate()
    check(lib.fdd_latest_estimate(rt, b"throttle_angle", C.byref(est)), "fdd_latest_estimate")
    assert est.source == b"wattmeter_estimate", est.source

    st = C.c_uint8()
    check(lib.fdd_dtc_status(rt, e.dtc, C.byref(st)), "fdd_dtc_status")
    assert st.value & 0x04, hex(st.value)  # pendingDTC

    # Documented failures.
    assert lib.fdd_push(rt, ids["tps"], 0, 1.0) == FDD_ERR_SAMPLE
    assert "signal `tps` at 0 ns" in last_error(), last_error()
    assert lib.fdd_push(rt, ids["tps"], 10**9, float("nan")) == FDD_ERR_SAMPLE
    assert lib.fdd_signal(rt, b"no_such_signal", C.byref(C.c_uint32())) == FDD_ERR_NOT_FOUND
    assert "no_such_signal" in last_error()
    assert lib.fdd_push(None, 0, 0, 0.0) == FDD_ERR_NULL
    # The default configuration with one value out of range: the message names the key.
    cfg = pathlib.Path(__file__).resolve().parents[2] / "config" / "fdd.toml"
    bad = re.sub(rb"(?m)^check_period_s = .*$", b"check_period_s = -1", cfg.read_bytes())
    rt2 = p()
    assert lib.fdd_runtime_new(bad, len(bad), C.byref(rt2)) == FDD_ERR_CONFIG
    assert "check_period_s" in last_error(), last_error()
    assert rt2.value is None
    lib.fdd_runtime_free(rt)
    print("ok:", len(got), "events,", len(raised), "raised")


if __name__ == "__main__":
    main(sys.argv[1])
