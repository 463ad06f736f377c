//! Aging over warm-up cycles (OBD; AUTOSAR `DemAgingCycleRef`): a cycle that is not an aging
//! cycle still clears pendingDTC when the test passed, but does not count towards aging.

use fdd_diagnostics::dtc::{
    DebounceConfig, EventConfig, EventMemory, EventMemoryConfig, MilConfig, ReportContext,
};
use fdd_diagnostics::{TestResult, Verdict};

fn result(verdict: Verdict) -> TestResult {
    TestResult {
        value: 0.0,
        min: 0.0,
        max: 1.0,
        verdict,
    }
}

#[test]
fn only_aging_cycles_age_a_confirmed_dtc() {
    let mut ev = EventConfig::new("a", "P0106-64", 2);
    ev.debounce = DebounceConfig::MonitorInternal;
    ev.confirmation_threshold = 1;
    ev.aging_threshold = 2;
    ev.mil = MilConfig {
        enabled: false,
        ..MilConfig::default()
    };
    let mut m = EventMemory::new(&EventMemoryConfig {
        capacity: 4,
        events: vec![ev],
    })
    .expect("valid");
    let id = m.event_id("a").expect("event");
    let mut t = 0.0;
    let mut cycle = |m: &mut EventMemory, verdict: Verdict, aging: bool| {
        t += 1.0;
        m.start_operation_cycle_view(t, |_| {}).expect("start");
        m.report_view(id, &result(verdict), &ReportContext::at(t + 0.5), |_| {})
            .expect("report");
        m.end_operation_cycle_aging(t + 0.9, aging, |_| {})
            .expect("end");
        (m.status(id), m.event_info(id).aging_counter)
    };
    let (s, _) = cycle(&mut m, Verdict::Failed, true);
    assert!(s.confirmed() && s.pending());
    // A short drive: the test passed, not a warm-up cycle.
    let (s, aging) = cycle(&mut m, Verdict::Passed, false);
    assert!(s.confirmed() && !s.pending(), "{:#04x}", s.byte());
    assert_eq!(aging, 0);
    let (s, aging) = cycle(&mut m, Verdict::Passed, true);
    assert!(s.confirmed());
    assert_eq!(aging, 1);
    let (s, aging) = cycle(&mut m, Verdict::Passed, false);
    assert!(s.confirmed());
    assert_eq!(aging, 1);
    let (s, _) = cycle(&mut m, Verdict::Passed, true);
    assert!(
        !s.confirmed(),
        "aged after 2 aging cycles: {:#04x}",
        s.byte()
    );
    assert!(m.entry(id).is_none());
}
