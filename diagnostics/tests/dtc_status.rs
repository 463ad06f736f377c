//! The ISO 14229-1 status byte through the standard sequences, asserting the exact byte after
//! every step: ClearDTC 0x50; first qualified failure 0x27; confirmed after the configured
//! number of failed cycles 0x2F, 0xAF with the MIL; passing cycles clear pending and keep
//! confirmed; the MIL goes off after the configured passing cycles; aging erases the entry;
//! displacement when the memory is full; and the events emitted for each change.

use fdd_diagnostics::dtc::{
    CounterDebounce, DebounceConfig, DemError, DtcGroup, DtcSystem, EventConfig, EventMemory,
    EventMemoryConfig, FreezeFrameUpdate, MilOn, ReportContext, StatusBit, TimeDebounce,
};
use fdd_diagnostics::event::{DiagnosticEvent, MemoryAction, Trigger};
use fdd_diagnostics::{TestResult, Verdict};

/// An event memory under test, its clock and every event it emitted.
struct Bench {
    mem: EventMemory,
    t: f64,
    events: Vec<DiagnosticEvent>,
}

fn result(verdict: Verdict) -> TestResult {
    TestResult {
        value: if verdict.leans_failed() { 7.0 } else { 1.0 },
        min: 0.0,
        max: 5.0,
        verdict,
    }
}

impl Bench {
    fn new(capacity: usize, events: Vec<EventConfig>) -> Self {
        let mem = EventMemory::new(&EventMemoryConfig { capacity, events }).unwrap();
        Bench {
            mem,
            t: 0.0,
            events: Vec::new(),
        }
    }

    fn tick(&mut self) -> f64 {
        self.t += 0.5;
        self.t
    }

    /// Reports `verdict` for `name`; returns the status byte after it.
    fn report(&mut self, name: &str, verdict: Verdict) -> u8 {
        let id = self.mem.event_id(name).unwrap();
        let t = self.tick();
        let events = &mut self.events;
        self.mem
            .report(id, &result(verdict), &ReportContext::at(t), |e| {
                events.push(e)
            })
            .unwrap()
            .byte()
    }

    fn start(&mut self) {
        let t = self.tick();
        let events = &mut self.events;
        self.mem
            .start_operation_cycle(t, |e| events.push(e))
            .unwrap();
    }

    fn end(&mut self) {
        let t = self.tick();
        let events = &mut self.events;
        self.mem.end_operation_cycle(t, |e| events.push(e)).unwrap();
    }

    fn clear(&mut self, group: DtcGroup) -> usize {
        let t = self.tick();
        let events = &mut self.events;
        self.mem.clear_dtc(group, t, |e| events.push(e)).unwrap()
    }

    fn status(&self, name: &str) -> u8 {
        self.mem.status(self.mem.event_id(name).unwrap()).byte()
    }

    fn stored(&self, name: &str) -> bool {
        self.mem.entry(self.mem.event_id(name).unwrap()).is_some()
    }

    /// Events emitted since the last call.
    fn take(&mut self) -> Vec<DiagnosticEvent> {
        std::mem::take(&mut self.events)
    }
}

fn event(name: &str, dtc: &str, priority: u8) -> EventConfig {
    EventConfig::new(name, dtc, priority)
}

use Verdict::*;

/// The OBD life of one DTC: pending, confirmed with MIL on the 2nd failed cycle, healing,
/// MIL off after 3 passed cycles, aging after 4 more.
#[test]
fn obd_sequence_with_mil_healing_and_aging() {
    let mut ev = event("tps_a_high", "P0123-1C", 2);
    ev.aging_threshold = 4;
    ev.freeze_frame = vec!["tps_a_v".into()];
    let mut b = Bench::new(4, vec![ev]);
    let tps = "tps_a_high";

    assert_eq!(b.status(tps), 0x50, "power-up = after ClearDTC");
    b.start();
    assert_eq!(b.status(tps), 0x50);
    assert!(b.take().is_empty(), "cycle start on 0x50 changes nothing");

    // Cycle 1: first qualified failure -> pending.
    assert_eq!(b.report(tps, Failed), 0x27);
    let e = b.take();
    assert_eq!(e.len(), 1);
    assert_eq!(
        (e[0].status_before.byte(), e[0].status_after.byte()),
        (0x50, 0x27)
    );
    assert_eq!(e[0].trigger, Trigger::TestResult);
    assert_eq!(e[0].memory, MemoryAction::Stored);
    assert_eq!(e[0].occurrence_counter, 1);
    assert_eq!(e[0].fdc, 127);
    assert!(b.stored(tps));
    assert_eq!(b.report(tps, Failed), 0x27, "repeated failure");
    assert!(b.take().is_empty(), "no change, no event");
    b.end();
    assert_eq!(b.status(tps), 0x27, "failed cycle keeps pending");
    assert!(b.take().is_empty());

    // Cycle 2: second failed cycle -> confirmed + MIL.
    b.start();
    assert_eq!(b.status(tps), 0x65, "TFTOC cleared, TNCTOC set");
    let e = b.take();
    assert_eq!(e[0].trigger, Trigger::OperationCycleStart);
    assert_eq!(
        e[0].changed,
        [
            StatusBit::TestFailedThisOperationCycle,
            StatusBit::TestNotCompletedThisOperationCycle
        ]
    );
    assert_eq!(b.report(tps, Failed), 0xAF);
    let e = b.take();
    assert_eq!(e[0].memory, MemoryAction::Unchanged, "entry already stored");
    assert_eq!(
        e[0].occurrence_counter, 1,
        "testFailed stayed 1: same occurrence"
    );
    assert!(e[0].bit_changed(StatusBit::ConfirmedDtc));
    assert!(e[0].bit_changed(StatusBit::WarningIndicatorRequested));
    assert!(b.mem.mil_on());
    assert_eq!(b.report(tps, Passed), 0xAE);
    b.end();
    assert_eq!(b.status(tps), 0xAE, "a cycle with a failure keeps pending");

    // Cycles 3-5: passed cycles; pending clears after the first, MIL off after the third.
    b.start();
    assert_eq!(b.status(tps), 0xEC);
    assert_eq!(b.report(tps, Passed), 0xAC);
    b.end();
    assert_eq!(b.status(tps), 0xA8, "pending cleared, confirmed kept");
    b.take();
    for (cycle, after) in [(4, 0xA8), (5, 0x28)] {
        b.start();
        assert_eq!(b.status(tps), 0xE8, "cycle {cycle}");
        assert_eq!(b.report(tps, Passed), 0xA8);
        b.end();
        assert_eq!(b.status(tps), after, "cycle {cycle}");
    }
    assert!(!b.mem.mil_on());
    let e = b.take();
    let off = e.last().unwrap();
    assert_eq!(off.trigger, Trigger::OperationCycleEnd);
    assert_eq!(off.changed, [StatusBit::WarningIndicatorRequested]);

    // A cycle in which the test does not run counts for nothing.
    b.start();
    assert_eq!(b.status(tps), 0x68);
    b.end();
    assert_eq!(b.status(tps), 0x68);
    let id = b.mem.event_id(tps).unwrap();
    assert_eq!(b.mem.event_info(id).aging_counter, 0);

    // Aging: 4 passed cycles after the MIL went off erase the entry and confirmedDTC.
    for cycle in 1..=4 {
        b.start();
        assert_eq!(b.report(tps, Passed), 0x28);
        assert!(b.stored(tps), "aging cycle {cycle}");
        b.end();
        assert_eq!(b.mem.event_info(id).aging_counter, cycle);
    }
    assert_eq!(
        b.status(tps),
        0x20,
        "testFailedSinceLastClear stays until ClearDTC"
    );
    assert!(!b.stored(tps));
    let e = b.take();
    let aged = e.last().unwrap();
    assert_eq!(aged.memory, MemoryAction::Aged);
    assert_eq!(
        (aged.status_before.byte(), aged.status_after.byte()),
        (0x28, 0x20)
    );
    assert_eq!(
        aged.freeze_frame.len(),
        1,
        "the erased freeze frame is reported"
    );

    // A new failure starts over: pending, not confirmed.
    b.start();
    assert_eq!(b.report(tps, Failed), 0x27);
    assert!(b.stored(tps));
    assert_eq!(b.mem.event_info(id).occurrence_counter, 1);
}

#[test]
fn confirmed_without_mil_is_0x2f() {
    let mut ev = event("maf", "P0101-00", 3);
    ev.mil.enabled = false;
    let mut b = Bench::new(2, vec![ev]);
    b.start();
    assert_eq!(b.report("maf", Failed), 0x27);
    b.end();
    b.start();
    assert_eq!(b.status("maf"), 0x65);
    assert_eq!(b.report("maf", Failed), 0x2F);
    assert!(!b.mem.mil_on());
}

#[test]
fn confirmation_threshold_is_configurable() {
    let mut three = event("three", "P0106-00", 3);
    three.confirmation_threshold = 3;
    let mut one = event("one", "P0107-00", 3);
    one.confirmation_threshold = 1;
    let mut b = Bench::new(4, vec![three, one]);
    b.start();
    assert_eq!(b.report("three", Failed), 0x27);
    assert_eq!(
        b.report("one", Failed),
        0xAF,
        "threshold 1: confirmed at once"
    );
    b.end();
    b.start();
    assert_eq!(b.report("three", Failed), 0x27);
    b.end();
    b.start();
    assert_eq!(b.report("three", Failed), 0xAF);
}

#[test]
fn mil_on_first_failure() {
    let mut ev = event("misfire", "P0300-00", 1);
    ev.mil.on = MilOn::FirstFailure;
    ev.mil.off_after_passing_cycles = 1;
    let mut b = Bench::new(2, vec![ev]);
    b.start();
    assert_eq!(b.report("misfire", Failed), 0xA7);
    b.end();
    b.start();
    assert_eq!(b.report("misfire", Passed), 0xA4);
    b.end();
    assert_eq!(
        b.status("misfire"),
        0x20,
        "pending cleared, MIL off after 1 cycle"
    );
}

/// Pending clears only after a cycle that completed the test without failure; an untested
/// cycle neither clears it nor breaks the count to confirmation.
#[test]
fn pending_needs_a_completed_passing_cycle() {
    let mut b = Bench::new(2, vec![event("egr", "P0401-00", 4)]);
    b.start();
    assert_eq!(b.report("egr", Failed), 0x27);
    b.end();

    // Untested cycle.
    b.start();
    assert_eq!(b.status("egr"), 0x65);
    b.end();
    assert_eq!(b.status("egr"), 0x65, "not tested: pending stays");
    b.start();
    assert_eq!(b.status("egr"), 0x65);
    b.take();
    assert_eq!(
        b.report("egr", Failed),
        0xAF,
        "2nd failed cycle among tested ones"
    );

    // Pass and fail within one cycle: still a failed cycle.
    let mut b = Bench::new(2, vec![event("egr", "P0401-00", 4)]);
    b.start();
    assert_eq!(b.report("egr", Passed), 0x00);
    assert_eq!(b.report("egr", Failed), 0x27);
    assert_eq!(b.report("egr", Passed), 0x26);
    b.end();
    assert_eq!(b.status("egr"), 0x26);

    // A passed cycle clears pending and restarts the count: the next failure is pending again.
    b.start();
    assert_eq!(b.status("egr"), 0x64);
    assert_eq!(b.report("egr", Passed), 0x24);
    b.end();
    assert_eq!(b.status("egr"), 0x20);
    b.start();
    assert_eq!(
        b.report("egr", Failed),
        0x27,
        "sequence broken: not confirmed"
    );
}

#[test]
fn clear_dtc_all_group_and_single() {
    let mut b = Bench::new(
        4,
        vec![
            event("tps", "P0123-1C", 2),
            event("wheel_lf", "C0035-00", 2),
            event("wheel_rf", "C0040-00", 2),
        ],
    );
    b.start();
    for n in ["tps", "wheel_lf", "wheel_rf"] {
        assert_eq!(b.report(n, Failed), 0x27);
    }
    b.end();
    b.start();
    for n in ["tps", "wheel_lf", "wheel_rf"] {
        assert_eq!(b.report(n, Failed), 0xAF);
    }
    b.take();

    // One DTC.
    let d = b.mem.dtc(b.mem.event_id("wheel_rf").unwrap());
    assert_eq!(b.clear(DtcGroup::Dtc(d)), 1);
    assert_eq!(b.status("wheel_rf"), 0x50);
    assert!(!b.stored("wheel_rf"));
    let e = b.take();
    assert_eq!(e.len(), 1);
    assert_eq!(e[0].trigger, Trigger::ClearDtc);
    assert_eq!(e[0].memory, MemoryAction::Cleared);
    assert_eq!(
        (e[0].status_before.byte(), e[0].status_after.byte()),
        (0xAF, 0x50)
    );
    assert_eq!(b.mem.fdc(b.mem.event_id("wheel_rf").unwrap()), 0);

    // A system group: only chassis codes.
    assert_eq!(b.clear(DtcGroup::System(DtcSystem::Chassis)), 2);
    assert_eq!(b.status("wheel_lf"), 0x50);
    assert_eq!(b.status("tps"), 0xAF);
    assert_eq!(b.take().len(), 1, "wheel_rf was already 0x50: no event");

    // Everything (UDS 0xFFFFFF).
    assert_eq!(b.clear(DtcGroup::from_uds(0xFF_FFFF).unwrap()), 3);
    for n in ["tps", "wheel_lf", "wheel_rf"] {
        assert_eq!(b.status(n), 0x50);
    }
    assert_eq!(b.mem.entries_used(), 0);
    assert!(!b.mem.mil_on());

    // Still inside the cycle: a failure now is a first failure again.
    assert_eq!(b.report("tps", Failed), 0x27);

    // Unknown DTC.
    let t = b.tick();
    let err = b
        .mem
        .clear_dtc(
            DtcGroup::Dtc("P0999-00".parse().unwrap()),
            t,
            |_: DiagnosticEvent| {},
        )
        .unwrap_err();
    assert_eq!(err, DemError::UnknownDtc("P0999-00".parse().unwrap()));
}

fn no_mil(name: &str, dtc: &str, priority: u8) -> EventConfig {
    let mut e = event(name, dtc, priority);
    e.mil.enabled = false;
    e.confirmation_threshold = 1;
    e.freeze_frame = vec!["speed".into()];
    e
}

/// Memory full: a new entry displaces a strictly lower-priority one, passive before active,
/// then the oldest; if none qualifies the entry is not stored and the overflow is counted.
#[test]
fn displacement_when_memory_is_full() {
    let mut b = Bench::new(
        2,
        vec![
            no_mil("a", "P0100-00", 5),
            no_mil("b", "P0105-00", 5),
            no_mil("same", "P0110-00", 5),
            no_mil("high", "P0115-00", 3),
            no_mil("top", "P0120-00", 1),
        ],
    );
    b.start();
    assert_eq!(b.report("a", Failed), 0x2F);
    assert_eq!(b.report("b", Failed), 0x2F);
    assert_eq!(b.mem.entries_used(), 2);
    assert_eq!(b.report("b", Passed), 0x2E, "b is now passive");
    b.take();

    // Equal priority: nothing to displace -> not stored, overflow.
    let id = b.mem.event_id("same").unwrap();
    let t = b.tick();
    let mut out = Vec::new();
    let status = b
        .mem
        .report(
            id,
            &result(Failed),
            &ReportContext::at(t).with_freeze_frame(&[42.0]),
            |e| out.push(e),
        )
        .unwrap();
    assert_eq!(status.byte(), 0x2F, "status is per event, stored or not");
    assert!(!b.stored("same"));
    assert!(b.mem.overflow());
    assert_eq!(b.mem.overflow_count(), 1);
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].memory, MemoryAction::NotStored);
    assert_eq!(
        out[0].freeze_frame[0].value,
        Some(42.0),
        "values kept in the event"
    );

    // Higher priority: displaces the passive one (b) although a is older.
    assert_eq!(b.report("high", Failed), 0x2F);
    let e = b.take();
    assert_eq!(e.len(), 2, "displaced event first, then the new one");
    assert_eq!(e[0].event, "b");
    assert_eq!(e[0].trigger, Trigger::Displacement);
    assert_eq!(e[0].memory, MemoryAction::Displaced);
    assert_eq!(
        (e[0].status_before.byte(), e[0].status_after.byte()),
        (0x2E, 0x26),
        "the displaced event loses confirmedDTC"
    );
    assert_eq!(e[1].event, "high");
    assert_eq!(e[1].memory, MemoryAction::Stored);
    assert_eq!(e[1].displaced.unwrap().to_string(), "P0105-00");
    assert!(b.stored("a") && b.stored("high") && !b.stored("b"));
    assert_eq!(b.status("b"), 0x26);
    assert_eq!(
        b.mem.overflow_count(),
        1,
        "a displacement is not a lost entry"
    );

    // Lowest priority first: top (1) displaces a (5, active), not high (3).
    assert_eq!(b.report("top", Failed), 0x2F);
    assert!(b.stored("top") && b.stored("high") && !b.stored("a"));

    // Ties: both active, same priority -> the oldest goes.
    let mut b = Bench::new(
        2,
        vec![
            no_mil("a", "P0100-00", 5),
            no_mil("b", "P0105-00", 5),
            no_mil("high", "P0115-00", 3),
        ],
    );
    b.start();
    b.report("a", Failed);
    b.report("b", Failed);
    b.report("high", Failed);
    assert!(!b.stored("a") && b.stored("b") && b.stored("high"));

    // Priority beats passiveness: a passive prio-5 entry stays, an active prio-9 one goes.
    let mut b = Bench::new(
        2,
        vec![
            no_mil("low", "P0100-00", 9),
            no_mil("mid", "P0105-00", 5),
            no_mil("high", "P0115-00", 3),
        ],
    );
    b.start();
    b.report("mid", Failed);
    b.report("mid", Passed);
    b.report("low", Failed);
    b.report("high", Failed);
    assert!(b.stored("mid") && !b.stored("low") && b.stored("high"));
    let names: Vec<&str> = b.mem.entries().map(|e| e.name).collect();
    assert_eq!(names.len(), 2);

    // A cleared memory accepts again and the overflow indication resets.
    b.clear(DtcGroup::All);
    assert!(!b.mem.overflow());
}

#[test]
fn not_stored_event_gets_an_entry_in_a_later_cycle() {
    let mut b = Bench::new(
        1,
        vec![no_mil("a", "P0100-00", 5), no_mil("b", "P0105-00", 5)],
    );
    b.start();
    b.report("a", Failed);
    b.report("b", Failed);
    assert!(!b.stored("b"));
    b.clear(DtcGroup::Dtc("P0100-00".parse().unwrap()));
    // b is still failed; in the next cycle its first failure stores it.
    assert_eq!(
        b.report("b", Failed),
        0x2F,
        "same cycle: no change, no retry"
    );
    assert!(!b.stored("b"));
    b.end();
    b.start();
    b.take();
    assert_eq!(b.report("b", Failed), 0x2F);
    assert!(b.stored("b"));
    let e = b.take();
    assert_eq!(e[0].memory, MemoryAction::Stored);
}

/// Counter-based debouncing drives the status only when qualified; the FDC and the maximum
/// FDC follow every step.
#[test]
fn counter_debounce_drives_status() {
    let mut ev = event("map", "P0106-00", 3);
    ev.debounce = DebounceConfig::Counter(CounterDebounce {
        increment_step: 40,
        decrement_step: 20,
        failed_threshold: 100,
        passed_threshold: -100,
        jump_up: true,
        jump_up_value: 0,
        ..Default::default()
    });
    let mut b = Bench::new(2, vec![ev]);
    let id = b.mem.event_id("map").unwrap();
    b.start();
    assert_eq!(b.report("map", PreFailed), 0x50);
    assert_eq!(b.mem.fdc(id), 50); // 40 * 127 / 100
    assert_eq!(b.report("map", PreFailed), 0x50);
    assert_eq!(b.mem.fdc(id), 101);
    assert!(b.take().is_empty(), "pre-results emit nothing");
    assert_eq!(b.report("map", PreFailed), 0x27);
    assert_eq!(b.mem.fdc(id), 127);
    assert_eq!(b.take()[0].fdc, 127);
    assert_eq!(b.report("map", NotTested), 0x27);
    assert_eq!(b.mem.fdc(id), 127, "NotTested changes nothing");
    for _ in 0..9 {
        assert_eq!(b.report("map", PrePassed), 0x27);
    }
    assert_eq!(b.mem.fdc(id), -102); // 100 - 9 * 20 = -80 -> -80 * 128 / 100
    assert_eq!(b.report("map", PrePassed), 0x26, "qualified pass at -100");
    assert_eq!(b.mem.fdc(id), -128);
    // Jump-up: from -100 straight to 0, then +40.
    assert_eq!(b.report("map", PreFailed), 0x26);
    assert_eq!(b.mem.fdc(id), 50);
    assert_eq!(b.mem.event_info(id).max_fdc, 127);
    // A new cycle resets the debouncer.
    b.end();
    b.start();
    assert_eq!(b.mem.fdc(id), 0);
}

#[test]
fn time_debounce_drives_status() {
    let mut ev = event("leak", "P2279-7A", 3);
    ev.debounce = DebounceConfig::Time(TimeDebounce {
        failed_time_s: 1.0,
        passed_time_s: 2.0,
    });
    let mut mem = EventMemory::new(&EventMemoryConfig {
        capacity: 1,
        events: vec![ev],
    })
    .unwrap();
    let id = mem.event_id("leak").unwrap();
    let mut out = Vec::new();
    let mut at = |mem: &mut EventMemory, v, t| {
        mem.report(id, &result(v), &ReportContext::at(t), |e| out.push(e))
            .unwrap()
            .byte()
    };
    mem.start_operation_cycle(0.0, |_| {}).unwrap();
    assert_eq!(at(&mut mem, PreFailed, 10.0), 0x50);
    assert_eq!(at(&mut mem, PreFailed, 10.5), 0x50);
    assert_eq!(mem.fdc(id), 63);
    assert_eq!(at(&mut mem, PreFailed, 10.99), 0x50);
    assert_eq!(at(&mut mem, PreFailed, 11.0), 0x27, "persisted 1 s");
    assert_eq!(at(&mut mem, PrePassed, 11.5), 0x27);
    assert_eq!(at(&mut mem, PrePassed, 13.0), 0x27);
    assert_eq!(at(&mut mem, PrePassed, 13.5), 0x26, "good for 2 s");
    assert_eq!(out.len(), 2);
    assert_eq!(out[0].time_s, 11.0);
}

#[test]
fn emitted_events_carry_result_freeze_frame_and_candidates() {
    let mut ev = event("tps_a_high", "P0123-1C", 2);
    ev.freeze_frame = vec!["tps_a_v".into(), "engine_speed_rpm".into()];
    let mut latest = ev.clone();
    latest.name = "latest".into();
    latest.dtc = "P0123-16".into();
    latest.freeze_frame_update = FreezeFrameUpdate::Latest;
    let mut mem = EventMemory::new(&EventMemoryConfig {
        capacity: 2,
        events: vec![ev, latest],
    })
    .unwrap();
    let id = mem.event_id("tps_a_high").unwrap();
    let lid = mem.event_id("latest").unwrap();
    let mut out = Vec::new();
    mem.start_operation_cycle(1.0, |e| out.push(e)).unwrap();
    let r = TestResult {
        value: 4.93,
        min: 0.25,
        max: 4.75,
        verdict: Failed,
    };
    let cands = [("tps_a_short_to_supply", 0.91), ("tps_a_bias", 0.09)];
    let ctx = ReportContext::at(12.5)
        .with_freeze_frame(&[4.93, f64::NAN])
        .with_candidates(&cands);
    mem.report(id, &r, &ctx, |e| out.push(e)).unwrap();
    assert_eq!(out.len(), 1);
    let e = &out[0];
    assert_eq!(e.dtc_uds, 0x01231C);
    assert_eq!(e.test_result, Some(r));
    assert_eq!(e.candidates.len(), 2);
    assert_eq!(e.candidates[0].fault, "tps_a_short_to_supply");
    let json = serde_json::to_value(e).unwrap();
    assert_eq!(json["dtc"], "P0123-1C");
    assert_eq!(json["dtc_uds"], 74524);
    assert_eq!(json["status_before"], 0x50);
    assert_eq!(json["status_after"], 0x27);
    assert_eq!(json["memory"], "stored");
    assert_eq!(json["trigger"], "test_result");
    assert_eq!(
        json["freeze_frame"],
        serde_json::json!([
            {"signal": "tps_a_v", "value": 4.93},
            {"signal": "engine_speed_rpm", "value": null}
        ])
    );
    assert_eq!(json["test_result"]["verdict"], "FAILED");
    assert_eq!(json["candidates"][1]["score"], 0.09);
    let back: DiagnosticEvent = serde_json::from_value(json).unwrap();
    assert_eq!(&back, e);

    // Freeze frame "first" keeps the first values; "latest" takes each new occurrence's.
    for (eid, t0, expect) in [(id, 13.0, 4.93), (lid, 23.0, 3.0)] {
        for (dt, v, value) in [(0.0, Failed, 1.0), (1.0, Passed, 2.0), (2.0, Failed, 3.0)] {
            let r = TestResult { verdict: v, ..r };
            let values = [value, 800.0];
            let ctx = ReportContext::at(t0 + dt).with_freeze_frame(&values);
            mem.report(eid, &r, &ctx, |_| {}).unwrap();
        }
        let entry = mem.entry(eid).unwrap();
        let ff: Vec<_> = entry.freeze_frame().collect();
        assert_eq!(ff[0], ("tps_a_v", expect), "{}", entry.name);
        assert_eq!(ff[1].0, "engine_speed_rpm");
        // "first" still holds the NaN of the first capture; "latest" the recent value.
        assert_eq!(ff[1].1.is_nan(), eid == id, "{}", entry.name);
        assert_eq!(entry.occurrence_counter, 2, "{}", entry.name);
    }

    // Cycle changes carry no test result and no candidates.
    out.clear();
    mem.start_operation_cycle(30.0, |e| out.push(e)).unwrap();
    assert!(!out.is_empty());
    assert!(out
        .iter()
        .all(|e| e.test_result.is_none() && e.candidates.is_empty()));
    assert!(out
        .iter()
        .all(|e| e.trigger == Trigger::OperationCycleStart
            || e.trigger == Trigger::OperationCycleEnd));
}

#[test]
fn bad_calls_are_rejected_and_change_nothing() {
    let mut ev = event("tps", "P0123-1C", 2);
    ev.freeze_frame = vec!["v".into()];
    let mut mem = EventMemory::new(&EventMemoryConfig {
        capacity: 1,
        events: vec![ev],
    })
    .unwrap();
    let id = mem.event_id("tps").unwrap();
    let r = result(Failed);
    let mut out = Vec::new();
    assert_eq!(
        mem.report(id, &r, &ReportContext::at(1.0), |e| out.push(e)),
        Err(DemError::NoOperationCycle)
    );
    assert_eq!(
        mem.end_operation_cycle(1.0, |e| out.push(e)),
        Err(DemError::NoOperationCycle)
    );
    mem.start_operation_cycle(5.0, |e| out.push(e)).unwrap();
    assert!(matches!(
        mem.report(id, &r, &ReportContext::at(4.0), |e| out.push(e)),
        Err(DemError::TimeWentBackwards { .. })
    ));
    assert!(matches!(
        mem.report(id, &r, &ReportContext::at(f64::NAN), |e| out.push(e)),
        Err(DemError::NonFiniteTime(_))
    ));
    assert_eq!(
        mem.report(
            id,
            &r,
            &ReportContext::at(6.0).with_freeze_frame(&[1.0, 2.0]),
            |e| out.push(e)
        ),
        Err(DemError::FreezeFrameLength {
            expected: 1,
            got: 2
        })
    );
    assert!(matches!(
        mem.start_operation_cycle(f64::INFINITY, |e| out.push(e)),
        Err(DemError::NonFiniteTime(_))
    ));
    assert!(out.is_empty());
    assert_eq!(mem.status(id).byte(), 0x50);
    assert_eq!(mem.fdc(id), 0);
    // Equal times are fine.
    assert_eq!(
        mem.report(id, &r, &ReportContext::at(5.0), |e| out.push(e))
            .unwrap()
            .byte(),
        0x27
    );
    // Foreign id.
    let other = EventMemory::new(&EventMemoryConfig {
        capacity: 1,
        events: vec![
            event("x", "P0001-00", 1),
            event("y", "P0002-00", 1),
            event("z", "P0003-00", 1),
        ],
    })
    .unwrap();
    let foreign = other.event_id("z").unwrap();
    assert_eq!(
        mem.report(foreign, &r, &ReportContext::at(6.0), |e| out.push(e)),
        Err(DemError::UnknownEvent(2))
    );
}

/// Starting a cycle while one runs ends it first (a passed cycle clears pending).
#[test]
fn restarting_a_cycle_ends_the_running_one() {
    let mut b = Bench::new(1, vec![event("a", "P0100-00", 1)]);
    b.start();
    b.report("a", Failed);
    b.end();
    b.start();
    assert_eq!(b.report("a", Passed), 0x24);
    b.start();
    assert_eq!(b.status("a"), 0x60, "pending cleared by the implicit end");
    assert_eq!(b.mem.operation_cycles_started(), 3);
    assert!(b.mem.operation_cycle_active());
}

#[test]
fn read_by_status_mask() {
    let mut b = Bench::new(
        4,
        vec![
            event("a", "P0100-00", 1),
            event("b", "P0105-00", 1),
            event("c", "P0110-00", 1),
        ],
    );
    b.start();
    b.report("a", Failed);
    b.report("b", Passed);
    let pending: Vec<String> = b
        .mem
        .dtcs_by_status_mask(0x04)
        .map(|(d, s)| format!("{d} {:02X}", s.byte()))
        .collect();
    assert_eq!(pending, ["P0100-00 27"]);
    assert_eq!(b.mem.dtcs_by_status_mask(0x40).count(), 1, "c not tested");
    assert_eq!(b.mem.dtcs_by_status_mask(0xFF).count(), 2, "b is 0x00");
}

#[test]
fn bad_configuration_names_the_field() {
    let base = || EventMemoryConfig {
        capacity: 4,
        events: vec![
            event("a", "P0100-00", 1),
            event("b", "P0105-00", 1),
            event("c", "P0110-00", 1),
        ],
    };
    let check = |cfg: EventMemoryConfig, field: &str, words: &str| {
        let e = EventMemory::new(&cfg).unwrap_err();
        assert_eq!(e.field, field, "{e}");
        assert!(e.to_string().contains(words), "{e}");
    };

    let mut c = base();
    c.events[2].debounce = DebounceConfig::Counter(CounterDebounce {
        failed_threshold: -10,
        passed_threshold: 10,
        ..Default::default()
    });
    check(c, "events[2].debounce.failed_threshold", "wrong order");

    let mut c = base();
    c.events[1].debounce = DebounceConfig::Counter(CounterDebounce {
        failed_threshold: 10,
        passed_threshold: 5,
        ..Default::default()
    });
    check(c, "events[1].debounce.passed_threshold", "must be negative");

    let mut c = base();
    c.events[0].debounce = DebounceConfig::Counter(CounterDebounce {
        increment_step: 0,
        ..Default::default()
    });
    check(c, "events[0].debounce.increment_step", "at least 1");

    let mut c = base();
    c.events[0].debounce = DebounceConfig::Counter(CounterDebounce {
        failed_threshold: 10,
        passed_threshold: -10,
        jump_up: true,
        jump_up_value: 10,
        ..Default::default()
    });
    check(c, "events[0].debounce.jump_up_value", "[-10, 10)");

    let mut c = base();
    c.events[1].debounce = DebounceConfig::Time(TimeDebounce {
        failed_time_s: -1.0,
        passed_time_s: 1.0,
    });
    check(c, "events[1].debounce.failed_time_s", ">= 0");

    let mut c = base();
    c.capacity = 0;
    check(c, "capacity", "at least 1");

    let mut c = base();
    c.events[1].priority = 0;
    check(c, "events[1].priority", "1 (highest) to 255 (lowest)");

    let mut c = base();
    c.events[2].confirmation_threshold = 0;
    check(c, "events[2].confirmation_threshold", "at least 1");

    let mut c = base();
    c.events[2].aging_threshold = 0;
    check(c, "events[2].aging_threshold", "at least 1");

    let mut c = base();
    c.events[0].mil.off_after_passing_cycles = 0;
    check(c, "events[0].mil.off_after_passing_cycles", "at least 1");

    let mut c = base();
    c.events[2].name = "a".into();
    check(c, "events[2].name", "already used by events[0]");

    let mut c = base();
    c.events[1].freeze_frame = vec!["x".into(), "y".into(), "x".into()];
    check(c, "events[1].freeze_frame[2]", "duplicates freeze_frame[0]");

    let mut c = base();
    c.events[1].dtc = "P01".into();
    check(
        c,
        "events[1].dtc",
        "a J2012 code is a letter and 4 characters",
    );
}

#[test]
fn configuration_deserializes_with_defaults_and_rejects_unknown_keys() {
    let json = r#"{
        "capacity": 8,
        "events": [
            {"name": "tps_a_high", "dtc": "P0123-1C", "priority": 2,
             "freeze_frame": ["tps_a_v"],
             "debounce": {"kind": "counter", "increment_step": 10, "failed_threshold": 100,
                          "passed_threshold": -100, "jump_up": true}},
            {"name": "leak", "dtc": "P2279", "priority": 4, "aging_threshold": 10,
             "mil": {"off_after_passing_cycles": 2},
             "freeze_frame_update": "latest",
             "debounce": {"kind": "time", "failed_time_s": 0.5, "passed_time_s": 1.0}},
            {"name": "wheel", "dtc": "C0035-00", "priority": 9,
             "mil": {"enabled": false, "on": "first_failure"},
             "debounce": {"kind": "monitor_internal"}}
        ]
    }"#;
    let cfg: EventMemoryConfig = serde_json::from_str(json).unwrap();
    assert_eq!(cfg.events[0].confirmation_threshold, 2);
    assert_eq!(cfg.events[0].aging_threshold, 40);
    assert_eq!(cfg.events[0].mil.off_after_passing_cycles, 3);
    assert!(cfg.events[0].mil.enabled);
    assert_eq!(cfg.events[1].mil.on, MilOn::Confirmed);
    let DebounceConfig::Counter(c) = cfg.events[0].debounce else {
        panic!("counter")
    };
    assert_eq!((c.decrement_step, c.jump_up_value), (1, 0));
    let mem = EventMemory::new(&cfg).unwrap();
    assert_eq!(
        mem.dtc(mem.event_id("leak").unwrap()).to_string(),
        "P2279-00"
    );

    for bad in [
        r#"{"capacity": 1, "events": [{"name": "a", "dtc": "P0100", "priority": 1, "debounce": {"kind": "counter", "failed_treshold": 5}}]}"#,
        r#"{"capacity": 1, "events": [{"name": "a", "dtc": "P0100", "priority": 1, "prio": 1, "debounce": {"kind": "monitor_internal"}}]}"#,
        r#"{"capacity": 1, "events": [{"name": "a", "dtc": "P0100", "priority": 1, "debounce": {"kind": "fuzzy"}}]}"#,
        r#"{"capacity": 1, "size": 3}"#,
    ] {
        let e = serde_json::from_str::<EventMemoryConfig>(bad).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("unknown field") || msg.contains("unknown variant"),
            "{msg}"
        );
    }
}
